"""Method comparison (issue 8): the paper's ranking of methods 1–4, maps, full posteriors, report.

References: the paper's Tables 1–2 (:data:`bayespig.studies.PAPER_A_RMS`, ``PAPER_TAU_RMS``;
a pair of methods counts as ranked by the paper only where its values differ beyond its
rounding to 3 decimals), its section 4.2 conclusion (method 4 the most robust, the opaque-film
methods for thick films, method 3 the worst), and full posteriors from :func:`bayespig.infer`.
"""

import json

import numpy as np
import pytest

from bayespig.data.simulate import simulate
from bayespig.inference import InferenceSettings
from bayespig.studies import PAPER_A_RMS, PAPER_TAU_RMS
from bayespig.studies.compare import (
    PAPER_POINTS,
    best_method_map,
    compare_measurements,
    compare_methods,
    method_map,
    paper_ranking_agreement,
    write_compare_report,
)

A0 = np.array([p[0] for p in PAPER_POINTS])
TAU0 = np.array([p[1] for p in PAPER_POINTS])
#: The one ranked pair of the paper's Table 2 that bayespig's own frequentist regeneration
#: (reports/paper-tables.md: method 1 0.0512, method 2 0.0439 at a0 = 0.2, tau0 = 1) also
#: ranks the other way: the paper's 0.075 for method 2 holds outlying fits, not the width.
KNOWN_PAPER_OUTLIER = {("method1", "method2", 0.2, 1.0)}
#: Quick sampler settings: widths to ~5 % (ESS 300), enough to test a factor of 1.5.
QUICK = InferenceSettings(target_ess=300, draws_per_chain=256, max_steps=3000)


def _by_key(result, quantity):
    return {(n, float(a0), float(t0)): result.fisher[quantity][k, j]
            for k, n in enumerate(result.names) for j, (a0, t0) in enumerate(zip(result.a, result.tau))}


def test_fisher_reproduces_the_papers_ranking_at_its_nine_points():
    result = compare_methods(A0, TAU0, full=False)
    for quantity, paper in (("sd_a", PAPER_A_RMS), ("sd_tau", PAPER_TAU_RMS)):
        pairs = paper_ranking_agreement(_by_key(result, quantity), paper)
        assert len(pairs) > 20  # the paper ranks most pairs beyond its rounding
        wrong = {(p["better"], p["worse"], p["a0"], p["tau0"]) for p in pairs if not p["agrees"]}
        assert wrong <= KNOWN_PAPER_OUTLIER, wrong
    # method 3 is the worst everywhere in both tables (the paper's robust finding)
    for quantity in ("sd_a", "sd_tau"):
        worst = np.argmax(result.fisher[quantity], axis=0)
        assert all(result.names[k] == "method3" for k in worst)


def test_paper_ranking_agreement_skips_ties_and_sees_a_swap():
    paper = {("m1", 0.1, 1.0): 0.050, ("m2", 0.1, 1.0): 0.050, ("m3", 0.1, 1.0): 0.100}
    pairs = paper_ranking_agreement({("m1", 0.1, 1.0): 1.0, ("m2", 0.1, 1.0): 2.0, ("m3", 0.1, 1.0): 0.5}, paper)
    assert {(p["better"], p["worse"]) for p in pairs} == {("m1", "m3"), ("m2", "m3")}
    assert not any(p["agrees"] for p in pairs)


def test_map_tests_the_papers_conclusion():
    maps = method_map(a0=np.geomspace(0.01, 0.3, 6), tau0=np.geomspace(0.1, 20, 12))
    best_tau = best_method_map(maps, "tau")
    k4, k1 = maps.names.index("method4"), maps.names.index("method1")
    # method 4 within 1.25 of the best tau at every a0 for tau0 in [0.5, 1] (Table 2's first columns)
    middle = (maps.tau0 >= 0.4) & (maps.tau0 <= 1.2)
    assert best_tau["method4_near_best"][:, middle].all()
    # thick films: the transmittance of method 1 wins tau at every a0
    thick = maps.tau0 >= 5
    assert (best_tau["best"][:, thick] == k1).all()
    assert best_tau["winners"]["method3"] == 0.0
    # method 3 is a ravine (not identified) everywhere; method 4 is identified for tau0 <= 1
    k3 = maps.names.index("method3")
    assert not maps.identified[k3].any()
    assert maps.identified[k4][:, maps.tau0 <= 1].all()
    # and method 4's films turn opaque: its tau is not identified at tau0 = 20, a0 = 0.3
    assert not maps.identified[k4][-1, -1]


def test_fisher_widths_agree_with_full_posteriors_method4(tmp_path):
    # well identified (method 4, tau0 <= 1): posterior / Fisher sd within a factor 1.5 (issue 8)
    a0, tau0 = np.array([0.025, 0.2]), np.array([0.5, 1.0])
    result = compare_methods(a0, tau0, methods=("method4",), full=True, settings=QUICK, seed=1)
    ratio_a = result.posterior["sd_a"] / result.fisher["sd_a"]
    ratio_tau = result.posterior["sd_log_tau"] / result.fisher["sd_log_tau"]
    assert ((ratio_a > 1 / 1.5) & (ratio_a < 1.5)).all(), ratio_a
    assert ((ratio_tau > 1 / 1.5) & (ratio_tau < 1.5)).all(), ratio_tau
    assert result.posterior["identified"].all()
    maps = method_map(("method1", "method4"), a0=[0.05, 0.2], tau0=[0.5, 2.0])
    files = write_compare_report(tmp_path, comparison=result, maps=maps, paper=result)
    text = files["markdown"].read_text()
    assert "Maps over (a0, tau0)" in text and "identified" in text
    payload = json.loads(files["json"].read_text())
    assert payload["comparison"]["settings"]["seed"] == 1
    assert (tmp_path / "figures" / "compare_maps.png").exists()


@pytest.mark.slow  # minutes; test_fisher_widths_agree_with_full_posteriors_method4 covers the code path
def test_full_posteriors_at_the_nine_points_flag_ravines():
    result = compare_methods(A0, TAU0, full=True, settings=QUICK, seed=0)
    k3, k4 = result.names.index("method3"), result.names.index("method4")
    assert not result.posterior["identified"][k3].any()  # the ravine of a film on black alone
    assert result.posterior["identified"][k4][TAU0 <= 1].all()
    for quantity, paper in (("sd_a", PAPER_A_RMS),):
        values = {(n, float(a), float(t)): result.posterior[quantity][k, j]
                  for k, n in enumerate(result.names) for j, (a, t) in enumerate(zip(A0, TAU0))}
        assert all(p["agrees"] for p in paper_ranking_agreement(values, paper))


def test_compare_measurements_of_a_set_serving_two_methods():
    design = [{"name": "opaque", "opaque": True},
              {"name": "on_black", "substrate": "black", "film_group": "film"},
              {"name": "on_white", "substrate": "white", "film_group": "film"}]
    ms = simulate(a=0.1, tau=0.8, design=design, wavelengths=[500.0, 600.0], eps=0.05, seed=4)
    result = compare_measurements(ms, methods=("method2", "method4"), settings=QUICK)
    assert result.names == ["method2", "method4"]
    np.testing.assert_allclose(result.a, 0.1, rtol=0.2)
    assert np.isfinite(result.posterior["sd_a"]).all()


def test_bad_input():
    with pytest.raises(ValueError, match="unknown method"):
        compare_methods([0.1], [1.0], methods=("method5",), full=False)
    with pytest.raises(ValueError, match="a must be"):
        compare_methods([1.5], [1.0], full=False)
    with pytest.raises(ValueError, match="a0"):
        method_map(a0=[-0.1])


def test_compare_page_has_no_literal_backticks(tmp_path):
    maps = method_map(("method1", "method4"), a0=[0.05, 0.2], tau0=[0.5, 2.0])
    files = write_compare_report(tmp_path, maps=maps, command="bayespig compare --maps")
    html = files["html"].read_text()
    assert "`" not in html and "<pre>bayespig compare --maps</pre>" in html
    assert "Generated by this command; rerun it to regenerate:" in files["markdown"].read_text()


def test_robustness_maps_share_the_compare_maps_axes_and_have_human_titles():
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from bayespig.studies.robustness import plot_robustness_map, robustness_map

    grid = robustness_map(("method4",), [0.05, 0.2], [0.5, 1.0, 2.0], n_repeat=10)
    figure = plot_robustness_map(grid)
    FigureCanvasAgg(figure)
    panels = [ax for ax in figure.axes if ax.get_title()]
    assert [ax.get_title() for ax in panels] == ["method4: RMS error of a [-]", "method4: RMS error of tau / tau0 [-]"]
    for ax in panels:  # tau0 across, a0 up: as the compare maps
        assert (ax.get_xlabel(), ax.get_ylabel()) == ("tau0 [-]", "a0 [-]")
        assert [t.get_text() for t in ax.get_xticklabels()] == ["0.5", "1", "2"]
        assert [t.get_text() for t in ax.get_yticklabels()] == ["0.05", "0.2"]
    # the numbers sit where their (a0, tau0) is: a0 = 0.2 (row 1), tau0 = 2 (column 2)
    value = grid.statistic("a_rms")[0, 1, 2]
    texts = {(t.get_position(), t.get_text()) for t in panels[0].texts}
    assert ((2.5, 1.5), f"{value:.2g}") in texts
