"""Reports of a posterior whose films are all opaque: only ``a`` is a parameter (end to end).

A set of one opaque film (``bayespig.simulate`` with a one-film opaque design) goes through
``bayespig infer`` and ``bayespig report`` by their own argparse registrations.
"""

import argparse
import csv
import io
import json

import numpy as np
import pytest

from bayespig.commands.infer import add_infer_parser
from bayespig.commands.report import add_report_parser
from bayespig.data import simulate_to_csv
from bayespig.report.write import OPAQUE_ONLY_TEXT

#: Wavelengths of the opaque set [nm]: 7 across the visible range (colorimetry needs >= 6).
WAVELENGTHS_NM = np.linspace(400.0, 700.0, 7)
TRUE_A = np.linspace(0.02, 0.4, 7)
#: Relative measurement error of the simulated set [-].
EPS = 0.02


def _run(argv):
    parser = argparse.ArgumentParser(prog="bayespig")
    subparsers = parser.add_subparsers(dest="command", required=True)
    add_infer_parser(subparsers)
    add_report_parser(subparsers)
    args = parser.parse_args(argv)
    return args.func(args)


@pytest.fixture(scope="module")
def opaque_run(tmp_path_factory):
    """``bayespig infer`` then ``bayespig report`` on a simulated opaque-only set."""
    folder = tmp_path_factory.mktemp("opaque")
    data = folder / "opaque.csv"
    simulate_to_csv(data, a=TRUE_A, tau=1.0, design=[{"name": "opaque", "opaque": True}],
                    wavelengths=WAVELENGTHS_NM, eps=EPS, seed=1)
    assert _run(["infer", str(data), "--out", str(folder / "run"), "--seed", "1", "--no-progress"]) == 0
    assert _run(["report", str(folder / "run" / "posterior.nc"), "--measurements", str(data),
                 "--out", str(folder / "report"), "--no-progress"]) == 0
    return folder


def test_opaque_only_report_is_written_and_says_tau_is_not_identified(opaque_run):
    report = opaque_run / "report"
    markdown = (report / "report.md").read_text()
    html = (report / "report.html").read_text()
    assert (f"**Opaque films only.** {OPAQUE_ONLY_TEXT}") in markdown
    assert OPAQUE_ONLY_TEXT.replace("'", "&#x27;") in html
    assert OPAQUE_ONLY_TEXT == (
        "Every measured film hides its substrate, so its reflectance depends on a (and g when free) "
        "only: the optical thickness tau is not identified by these measurements and is not a parameter "
        "- this report has no tau, no extinction and no ravine. To measure tau too, add a film that does "
        "not hide its substrate (e.g. the same paint on black: the paper's method 2).")
    assert "Prior edge: no posterior is piled against a bound of its prior." in markdown
    assert "No ravine figure: it shows the log-likelihood over (a, tau), and every film here is opaque, " \
           "so tau is not a parameter." in markdown
    assert "- tau: not a parameter (every film is opaque)" in markdown
    figures = sorted(p.name for p in (report / "figures").iterdir())
    assert "ravine.png" not in figures and "parameters.png" in figures
    assert [f for f in figures if f.startswith("corner_")] == ["corner_450nm.png", "corner_550nm.png",
                                                               "corner_650nm.png"]
    assert {"colour_measured.png", "colour_predicted.png"} <= set(figures)


def test_opaque_only_summary_has_no_tau_columns_and_recovers_a(opaque_run):
    rows = list(csv.DictReader(io.StringIO((opaque_run / "report" / "summary.csv").read_text())))
    header = list(rows[0])
    assert not [c for c in header if "tau" in c or c.startswith(("k_ext", "sigma_ext"))]
    assert header[:2] == ["wavelength_nm", "a_mean"] and "point_a" in header and "prior_edge" in header
    assert {r["prior_edge"] for r in rows} == {""}
    # infer writes the same table
    assert (opaque_run / "run" / "summary.csv").read_text().splitlines()[0] == ",".join(header)
    median = np.array([float(r["a_median"]) for r in rows])
    low = np.array([float(r["a_ci90_low"]) for r in rows])
    high = np.array([float(r["a_ci90_high"]) for r in rows])
    # the truth inside the 90 % interval widened by its own width (7 bands: one may miss it)
    width = high - low
    assert np.all((TRUE_A > low - width) & (TRUE_A < high + width)), (low, median, high)
    summary = json.loads((opaque_run / "report" / "summary.json").read_text())
    assert "tau" not in summary["parameters"] and summary["ravine_wavelength_nm"] is None
    assert summary["correlation_a_log_tau"] is None


def test_opaque_only_colour_is_the_opaque_film(opaque_run):
    summary = json.loads((opaque_run / "report" / "summary.json").read_text())
    predicted = summary["colour"]["predicted_films"]
    assert {p["film"] for p in predicted} == {"opaque (hiding)"} and all(p["measured"] for p in predicted)
    measured = {m["channel"]: m["Lab_predicted"] for m in summary["colour"]["measured"]}
    # the opaque film predicted at the measured geometries is the measured film's prediction
    for p in predicted:
        np.testing.assert_allclose(p["Lab"], measured[p["channel"]], atol=0.05)
