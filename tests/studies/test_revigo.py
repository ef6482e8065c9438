"""Revigo study (bayespig.studies.revigo): series, SCE/SCI evidence, report; real data when present."""

import argparse

import numpy as np
import pytest

from bayespig.commands.revigo import add_revigo_parser, run_revigo
from bayespig.data import MeasurementError
from bayespig.studies.revigo import (
    FilmFit,
    RevigoStudy,
    default_revigo_path,
    revigo_report,
    revigo_study,
    specular_evidence,
    tint_series,
    write_revigo_report,
)
from bayespig.studies.tints import TintPrediction

REVIGO = default_revigo_path()
#: C's thickness relative to 07A for series 06: both were drawn down the same way and C holds
#: half as much white, so the ratio is of order one; this bracket excludes a fit escaping to
#: its bounds (1e-2, 1e2) or collapsing onto 07A's thickness.
SAME_DRAWDOWN_THICKNESS = (1.0, 2.0)
needs_revigo = pytest.mark.skipif(not (REVIGO / "revigo-mixture-specifications.txt").exists(),
                                  reason=f"Revigo data not found at {REVIGO} (set BAYESPIG_REVIGO)")


def _fit(film_id, mode, rms, below=0, inverted=False):
    rms = np.asarray(rms, dtype=float)
    return FilmFit(film_id, mode, rms, np.zeros_like(rms), np.ones_like(rms), below,
                   np.full(rms.shape, inverted))


@needs_revigo
def test_tint_series_of_the_revigo_collection():
    from bayespig.data.spectral_table import read_revigo

    series = {s.series: s for s in tint_series(read_revigo(REVIGO))}
    # 12 pigments have a masstone, a ~10/90 and a ~50/50 tint with zinc white (the mixture
    # file); 15 (ChromeYellowOtero) has no 50/50 tint, 04F/13G (~1 %) are not 10/90 tints.
    assert sorted(series) == ["01", "02", "03", "04", "05", "06", "09", "10", "11", "12", "13", "14"]
    assert {s.white for s in series.values()} == {"07A"}
    s13 = series["13"]
    assert (s13.masstone, s13.tint_b, s13.tint_c) == ("13A", "13B", "13C")
    assert s13.mass_fractions_b == pytest.approx((0.063, 0.937))
    assert series["04"].tint_b == "04B"


def test_specular_evidence_rules_out_sci_below_the_surface_reflection():
    fits = {"excluded": {"x": _fit("x", "excluded", [0.0, 0.0])},
            "included": {"x": _fit("x", "included", [0.0, 0.0], below=3)}}
    evidence = specular_evidence(fits)
    assert evidence["decision"] == "excluded"
    assert "below" in evidence["reason"]
    # without impossible values the better fit wins: log BF = (S_SCI - S_SCE) / (2 eps^2)
    fits = {"excluded": {"x": _fit("x", "excluded", [0.02, 0.0])},
            "included": {"x": _fit("x", "included", [0.0, 0.0])}}
    evidence = specular_evidence(fits)
    assert evidence["decision"] == "included"
    assert evidence["log_bayes_factor"] == pytest.approx(-(2 * 0.02**2) / (2 * 0.01**2))


def _prediction(model, delta_E):
    wl = np.array([400.0, 500.0])
    return TintPrediction(model, wl, np.full((2, 2), 0.5), np.full((2, 2), 0.5), 1.0, np.zeros(2),
                          np.ones(2), np.array([True, True]), np.asarray(delta_E, float), 0.0)


def test_report_medians_and_atomic_write(tmp_path):
    from bayespig.studies.revigo import TintSeries

    series = [TintSeries(f"0{i}", "Pigment", f"0{i}A", "07A", f"0{i}B", f"0{i}C", (0.1, 0.9), (0.5, 0.5))
              for i in range(1, 4)]
    tints = {}
    for s, (p, k) in zip(series, [([1, 2], [3, 1]), ([2, 4], [1, 1]), ([3, 6], [2, 5])]):
        tints[(s.series, "bayespig")] = _prediction("bayespig", p)
        tints[(s.series, "kubelka-munk")] = _prediction("kubelka-munk", k)
    fits = {m: {"07A": _fit("07A", m, [0.0, 0.02], inverted=True, below=2 if m == "included" else 0)}
            for m in ("excluded", "included")}
    study = RevigoStudy(fits, specular_evidence(fits), "excluded", series, tints,
                        {"specular_requested": "auto", "kubelka_munk": {"k1": 0.034, "k2": 0.56}})
    text = revigo_report(study)
    # medians by hand: bayespig (2, 4), KM (2, 1)
    assert "| **median** | | | | **2.00** | **4.00** | **2.00** | **1.00** |" in text
    assert "1 (1)" in text  # one misfit band, inverted
    assert "films 07A are, which rules SCI out" in text
    assert "1 of the 1 misfit bands are **inverted**" in text
    path = write_revigo_report(study, tmp_path / "sub" / "revigo.md")
    assert path.read_text(encoding="utf-8") == text
    assert [p.name for p in path.parent.iterdir()] == ["revigo.md"]  # no temporary file left


def test_report_with_posteriors_states_both_region_coverages():
    """Posterior regions with and without the cross-validated model error, per series and in
    the summary, as the regions say."""
    from bayespig.studies.revigo import TintSeries
    from bayespig.studies.tints import TintPosterior, cross_validated_model_error

    rng = np.random.default_rng(4)
    series = [TintSeries(f"0{i}", "Pigment", f"0{i}A", "07A", f"0{i}B", f"0{i}C", (0.1, 0.9), (0.5, 0.5))
              for i in range(1, 6)]
    tints, posteriors = {}, {}
    for s in series:
        tints[(s.series, "bayespig")] = _prediction("bayespig", [1, 1])
        tints[(s.series, "kubelka-munk")] = _prediction("kubelka-munk", [1, 1])
        centre = rng.uniform(20, 80, size=(2, 3))
        draws = centre + 0.1 * rng.standard_normal((100, 2, 3))
        posteriors[s.series] = TintPosterior(draws, centre + rng.normal(0, 2.0, (2, 3)), np.ones(100),
                                             np.ones((100, 2)), np.zeros(2, bool), 0.9)
    regions = cross_validated_model_error(posteriors, seed=0)
    fits = {m: {"07A": _fit("07A", m, [0.0, 0.0])} for m in ("excluded", "included")}
    study = RevigoStudy(fits, specular_evidence(fits), "excluded", series, tints,
                        {"specular_requested": "auto", "kubelka_munk": {"k1": 0.034, "k2": 0.56}},
                        posteriors=posteriors, model_error=regions)
    text = revigo_report(study)
    inside = np.array([regions[s.series].inside for s in series])
    assert "widened by the other series' model error" in text
    assert (f"widened 90 % region for {inside[:, 0].mean():.0%} of the series over black and "
            f"{inside[:, 1].mean():.0%} over white") in text
    assert "90 % credible region for 0% of the series over black and 0% over white" in text
    for s in series:
        r = regions[s.series]
        assert (f"| {'yes' if r.inside[0] else 'no'}, {'yes' if r.inside[1] else 'no'} | {r.rms:.2f} |"
                in text)


def test_report_states_the_model_checks_and_the_phase_function_medians():
    """Per-film posterior checks (counts, flagged bands, posterior at 550 nm) and the g medians."""
    from bayespig.studies.revigo import FilmCheck, TintSeries

    wl = np.array([400.0, 550.0, 700.0])
    fits = {m: {"01A": _fit("01A", m, [0.0, 0.02, 0.0], inverted=True), "07A": _fit("07A", m, [0.0] * 3)}
            for m in ("excluded", "included")}
    checks = {"01A": FilmCheck("01A", wl, np.array([0.4, 0.003, 0.5]), np.array([False, True, False]),
                               (0.5, 0.49, 0.51), (2.4, 2.3, 2.5)),
              "07A": FilmCheck("07A", wl, np.full(3, 0.5), np.zeros(3, bool), (0.001, 0.0, 0.002),
                               (100.0, 30.0, 127.0), ((1.01, 0.87, 1.19), (1.05, 1.02, 1.08)), True, 1.004)}
    series = [TintSeries(f"0{i}", "Pigment", f"0{i}A", "07A", f"0{i}B", f"0{i}C", (0.1, 0.9), (0.5, 0.5))
              for i in range(1, 4)]
    tints = {}
    for s, iso, g3 in zip(series, ([1, 2], [2, 4], [3, 6]), ([0.5, 2], [2, 5], [4, 6])):
        tints[(s.series, "bayespig")] = _prediction("bayespig", iso)
        tints[(s.series, "bayespig (g = 0.3)")] = _prediction("bayespig (g = 0.3)", g3)
        tints[(s.series, "kubelka-munk")] = _prediction("kubelka-munk", [1, 1])
    study = RevigoStudy(fits, specular_evidence(fits), "excluded", series, tints,
                        {"specular_requested": "auto", "kubelka_munk": {"k1": 0.034, "k2": 0.56},
                         "posterior": {"eps": 0.01, "n_draws": 10, "seed": 0, "substrate_sd": 0.1,
                                       "substrate_films": ["07A"]}},
                        card_in_air={"07A": (0, 23, 0.043)}, checks=checks)
    text = revigo_report(study)
    # card factors: per film in the table, summarised from the same numbers
    assert "| 1.01 [0.87, 1.19] / 1.05 [1.02, 1.08] (capped) |" in text
    assert "**1 of these 1 joint runs stopped at the step cap** (07A;" in text
    assert "the largest R-hat of a factor is 1.004." in text
    assert "| fixed |" in text  # 01A was run with fixed cards
    assert "The posteriors of 1 films (07A) treat the cards as uncertain (the other 1 take" in text
    assert "the median 90 % interval is 0.320 wide for the black card and 0.060 for the white (prior 0.330)" in text
    assert "narrower than half the prior's for 0 black and 1 white cards of 1 films" in text
    assert "excludes 1 for 1 cards (07A white)" in text
    assert "--substrate-films 07A" in text
    assert "**Flagged: 1 of 6 bands, in 1 of 2 films (01A)**; inverted bands among the flagged: 1." in text
    assert "| 550 | 0.5 [0.49, 0.51] | 2.4 [2.3, 2.5] |" in text
    assert "| none | 0.001 [0, 0.002] | 100 [30, 127] |" in text
    # medians by hand: isotropic (2, 4), g = 0.3 (2, 5); g = 0.3 better on 1 (black) and 0 (white) series
    assert "| bayespig | 2.00 | 4.00 | — |" in text
    assert "| bayespig (g = 0.3) | 2.00 | 5.00 | 1, 0 of 3 |" in text
    assert "move by up to 1.00 ΔE00" in text


def test_cli_reports_a_missing_folder(tmp_path):
    parser = argparse.ArgumentParser()
    add_revigo_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["revigo", str(tmp_path / "nowhere"), "--report", str(tmp_path / "r.md"), "--quiet"])
    with pytest.raises(MeasurementError, match="not found"):
        run_revigo(args)
    assert not (tmp_path / "r.md").exists()
    args = parser.parse_args(["revigo", str(tmp_path), "--eps", "0", "--quiet"])
    with pytest.raises(ValueError, match="--eps"):
        run_revigo(args)
    args = parser.parse_args(["revigo", str(tmp_path), "--g-sensitivity", "0.3", "1.2", "--quiet"])
    with pytest.raises(ValueError, match="--g-sensitivity"):
        run_revigo(args)


@needs_revigo
@pytest.mark.slow
def test_revigo_study_one_series(tmp_path):
    study = revigo_study(REVIGO, films=["06A", "06B", "06C", "07A", "11A"], series=["06"], g_sensitivity=())
    assert study.evidence["decision"] == "excluded"  # 11A is darker than r_F(8°)
    p, k = study.tints[("06", "bayespig")], study.tints[("06", "kubelka-munk")]
    # vermilion tints are predicted well by both models (report: ΔE00 < 0.5)
    assert p.delta_E.max() < 1.0 and k.delta_E.max() < 1.0
    # C and the white film 07A were drawn down the same way, so C's thickness relative to
    # 07A is of order one; two independent models (adding-doubling and Kubelka-Munk) fitting
    # that one scalar to the same spectra of C must agree on it
    assert SAME_DRAWDOWN_THICKNESS[0] < p.thickness < SAME_DRAWDOWN_THICKNESS[1]
    assert abs(np.log(p.thickness / k.thickness)) < np.log(1.05), (p.thickness, k.thickness)
    text = write_revigo_report(study, tmp_path / "revigo.md").read_text(encoding="utf-8")
    assert "Vermillion" in text
