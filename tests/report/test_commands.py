"""``bayespig report`` and ``bayespig demo`` argument handling (bayespig.commands.report)."""

import argparse
import csv
import io
import json

import numpy as np
import pytest

from bayespig.commands.report import add_demo_parser, add_report_parser


def _parser():
    parser = argparse.ArgumentParser(prog="bayespig")
    sub = parser.add_subparsers(dest="command", required=True)
    add_report_parser(sub)
    add_demo_parser(sub)
    return parser


def test_report_from_the_demo_posterior_with_other_colour_conditions(demo_dir, tmp_path, capsys):
    out = tmp_path / "again"
    args = _parser().parse_args(["report", str(demo_dir / "posterior.nc"), "--out", str(out),
                                 "--measurements", str(demo_dir / "measurements.csv"),
                                 "--observer", "CIE 1931 2 Degree Standard Observer",
                                 "--illuminant", "A", "--no-progress"])
    assert args.func(args) == 0
    printed = capsys.readouterr().out
    assert "report.html" in printed and "colour spread" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["colour"]["conditions"]["illuminant"] == "A"
    assert "2 Degree" in summary["colour"]["conditions"]["observer"]
    assert summary["source"].endswith("measurements.csv")
    # the posterior file is carried along unchanged
    assert (out / "posterior.nc").read_bytes() == (demo_dir / "posterior.nc").read_bytes()
    # same posterior, other observer and illuminant: same parameters, other colours
    default = json.loads((demo_dir / "summary.json").read_text())
    assert summary["parameters"]["a"]["mean"] == default["parameters"]["a"]["mean"]
    lab_a = summary["colour"]["measured"][0]["Lab_measured"]
    lab_d65 = default["colour"]["measured"][0]["Lab_measured"]
    assert np.abs(np.subtract(lab_a, lab_d65)).max() > 0.5
    assert "replaced" not in printed
    # the same command again: the earlier report is replaced, and it says so
    assert args.func(args) == 0
    assert capsys.readouterr().out.startswith(f"replaced the earlier contents of {out}\n")


def test_report_of_a_missing_file_is_a_clear_error(tmp_path):
    args = _parser().parse_args(["report", str(tmp_path / "nothing.nc"), "--out", str(tmp_path / "o")])
    with pytest.raises(ValueError, match="nothing.nc: file not found"):
        args.func(args)


def test_demo_defaults_and_bad_seed(tmp_path):
    args = _parser().parse_args(["demo"])
    assert args.out.replace("\\", "/") == "reports/demo" and args.seed == 0 and not args.quick
    args = _parser().parse_args(["demo", "--seed", "-1", "--out", str(tmp_path)])
    with pytest.raises(ValueError, match="seed"):
        args.func(args)


def _infer_parser():
    from bayespig.commands.infer import add_infer_parser

    parser = argparse.ArgumentParser(prog="bayespig")
    add_infer_parser(parser.add_subparsers(dest="command", required=True))
    return parser


def test_infer_then_report_one_summary_schema_no_silent_overwrite_and_an_untestable_check(tmp_path, capsys):
    """An 8°/d film on black and white: 2 values per wavelength for a and tau."""
    import bayespig

    data = tmp_path / "film.csv"
    wl = np.arange(400.0, 701.0, 60.0)
    bayespig.simulate(a=0.1, tau=1.0, design="method4", instrument="8d-sci", wavelengths=wl,
                      seed=2).to_csv(data)
    run = tmp_path / "run"
    args = _infer_parser().parse_args(["infer", str(data), "--out", str(run), "--no-progress"])
    assert args.func(args) == 0
    err = capsys.readouterr().err
    assert ("bayespig: note: the model check cannot test anything at 6 wavelength(s) (400, 460, 520, 580, "
            "640, 700 nm): not more measured values than parameters (2 <= 2)") in err
    infer_csv = (run / "summary.csv").read_text()
    # report into the folder of infer: refused, infer's summary.csv untouched
    args = _parser().parse_args(["report", str(run / "posterior.nc"), "--out", str(run), "--no-progress"])
    with pytest.raises(ValueError) as error:
        args.func(args)
    assert str(error.value) == (
        f"{run}: the folder exists and is not a bayespig report (it holds posterior.nc, summary.csv); "
        f"write the report into a new folder (e.g. --out {run / 'report'}) or pass --overwrite to replace "
        "the whole folder")
    assert (run / "summary.csv").read_text() == infer_csv
    args = _parser().parse_args(["report", str(run / "posterior.nc"), "--out", str(run / "report"),
                                 "--no-progress"])
    assert args.func(args) == 0
    assert (run / "summary.csv").read_text() == infer_csv
    report_csv = (run / "report" / "summary.csv").read_text()
    # one schema: same columns, same numbers (6 significant digits), the level in the names
    assert report_csv == infer_csv
    header = infer_csv.splitlines()[0].split(",")
    assert header[:8] == ["wavelength_nm", "a_mean", "a_sd", "a_median", "a_ci50_low", "a_ci50_high",
                          "a_ci90_low", "a_ci90_high"]
    rows = list(csv.DictReader(io.StringIO(infer_csv)))
    # the model check: not testable, never "pass"
    assert {r["model_check"] for r in rows} == {"not testable (2 values <= 2 parameters)"}
    assert all(float(r["ppc_p_value"]) >= 0.01 for r in rows)  # a p that says nothing here
    markdown = (run / "report" / "report.md").read_text()
    assert ("**Model check: not testable.** The model check cannot test anything at every wavelength: there "
            "are no more measured values (2) than parameters (2), so some parameters reproduce exactly any "
            "values the model can produce, and the check passes whatever the model misses. Not testable (n values &lt;= n parameters): "
            "measure more geometries, replicates or another film to test the model.") in markdown
    assert "reproduces the measurements within their noise" not in markdown
    # values that no parameters reproduce are still flagged there: not hidden as "not testable"
    from bayespig.inference import load_inference
    from bayespig.report import quantities as q

    idata = load_inference(run / "posterior.nc")
    idata.observed_data["y"].values[0, 1] *= 0.2  # the film on white far darker than predicted
    check = q.posterior_predictive_check(idata)
    assert q.model_check_status(check)[:2] == ["misfit (p < 0.01)", "not testable (2 values <= 2 parameters)"]
