"""End to end: ``bayespig demo`` writes a report whose files exist and agree with each other."""

import base64
import csv
import json
import re

import numpy as np
import pytest

from bayespig.demo import DEMO_WAVELENGTHS_NM, SYNTHETIC_PIGMENT, synthetic_pigment

# summary.csv has 6 significant digits: a relative rounding error of at most 5e-6 (half a unit
# in the 6th digit of a number whose first digit is 1); summary.json and netCDF keep float64.
CSV_RTOL = 5e-6 * 1.01  # 1 % margin for the binary representation of the written decimals
ROUND_TRIP_RTOL = 1e-12


def _csv_rows(path):
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def test_synthetic_pigment_is_smooth_and_physical():
    wl = np.arange(380.0, 781.0, 1.0)
    a, tau = synthetic_pigment(wl)
    assert np.all((a > 0) & (a < 1)) and np.all(tau > 0)
    # smooth: second differences at 1 nm are tiny against the values (no kinks or noise)
    assert np.abs(np.diff(a, 2)).max() < 1e-3 and np.abs(np.diff(np.log(tau), 2)).max() < 1e-3
    # a red-oxide-like colorant: absorbs blue, not red
    assert a[wl == 450.0][0] > 10 * a[wl == 700.0][0]
    assert "SYNTHETIC" in SYNTHETIC_PIGMENT["name"]


def test_demo_writes_every_file(demo_dir):
    for name in ("report.html", "report.md", "summary.csv", "summary.json", "posterior.nc",
                 "measurements.csv"):
        assert (demo_dir / name).is_file() and (demo_dir / name).stat().st_size > 0, name
    pngs = sorted((demo_dir / "figures").glob("*.png"))
    assert len(pngs) >= 8
    for png in pngs:
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # nothing temporary left behind
    assert not [p for p in demo_dir.iterdir() if p.name.startswith(".")]


def test_summary_agrees_with_the_netcdf_posterior(demo_dir, demo_idata):
    posterior = demo_idata.posterior
    wl = posterior["wavelength"].values
    i550 = int(np.flatnonzero(wl == 550.0)[0])
    a_mean = float(posterior["a"].isel(wavelength=i550).mean())
    tau_median = float(posterior["tau"].isel(wavelength=i550).median())
    rows = _csv_rows(demo_dir / "summary.csv")
    row = next(r for r in rows if float(r["wavelength_nm"]) == 550.0)
    assert float(row["a_mean"]) == pytest.approx(a_mean, rel=CSV_RTOL)
    assert float(row["tau_median"]) == pytest.approx(tau_median, rel=CSV_RTOL)
    assert row["a_mean"] == f"{a_mean:.6g}"
    summary = json.loads((demo_dir / "summary.json").read_text())
    assert summary["wavelength_nm"][i550] == 550.0
    assert summary["parameters"]["a"]["mean"][i550] == pytest.approx(a_mean, rel=ROUND_TRIP_RTOL)
    assert summary["synthetic"] and "SYNTHETIC" in summary["synthetic"]
    assert summary["provenance"]["seed"] == 3
    assert len(rows) == wl.size == len(DEMO_WAVELENGTHS_NM[::3])


def test_html_and_markdown_show_the_same_figures(demo_dir):
    html = (demo_dir / "report.html").read_text()
    markdown = (demo_dir / "report.md").read_text()
    files = sorted(p.name for p in (demo_dir / "figures").glob("*.png"))
    linked = sorted(re.findall(r"\]\(figures/([^)]+\.png)\)", markdown))
    assert linked == files
    embedded = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert len(embedded) == len(files)
    on_disk = {(demo_dir / "figures" / f).read_bytes() for f in files}
    assert {base64.b64decode(e) for e in embedded} == on_disk
    # self-contained: nothing fetched from elsewhere
    assert not re.search(r'(src|href)="(?!data:|#)', html)
    for text in (html, markdown):
        assert "SYNTHETIC" in text
        assert "CIE 1964 10 Degree Standard Observer" in text and "D65" in text


def test_posterior_brackets_the_synthetic_truth(demo_dir):
    """The truth (from the pigment's formula, not from the report) lies in the 90 % intervals.

    With 11 independent wavelengths and two parameters, a calibrated posterior misses the truth
    in about 10 % of the intervals; more than 6 misses of 22 has binomial probability < 0.5 %.
    """
    rows = _csv_rows(demo_dir / "summary.csv")
    wl = np.array([float(r["wavelength_nm"]) for r in rows])
    a, tau = synthetic_pigment(wl)
    misses = 0
    for k, r in enumerate(rows):
        misses += not float(r["a_ci90_low"]) <= a[k] <= float(r["a_ci90_high"])
        misses += not float(r["tau_ci90_low"]) <= tau[k] <= float(r["tau_ci90_high"])
    assert misses <= 6


@pytest.mark.slow
def test_full_demo_converges_everywhere(tmp_path):
    """The default demo (31 wavelengths, default settings): nothing flagged, truth bracketed.

    62 90 % intervals of a calibrated posterior miss the truth about 6 times; more than 14
    misses has binomial probability < 0.2 %.
    """
    from bayespig.demo import run_demo

    result = run_demo(tmp_path / "demo", seed=0, progress=False)
    flags = [f for f in result.summary["diagnostics"]["flags"] if f["wavelength_nm"] is not None]
    assert flags == []
    wl = np.asarray(result.summary["wavelength_nm"])
    a, tau = synthetic_pigment(wl)
    bands = result.summary["parameters"]
    misses = sum(int(not lo <= x <= hi) for name, truth in (("a", a), ("tau", tau))
                 for lo, hi, x in zip(bands[name]["q05"], bands[name]["q95"], truth))
    assert misses <= 14
    assert result.summary["colour"]["good_enough_for_colour_matching"]
