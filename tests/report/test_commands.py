"""``bayespig report`` and ``bayespig demo`` argument handling (bayespig.commands.report)."""

import argparse
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


def test_report_of_a_missing_file_is_a_clear_error(tmp_path):
    args = _parser().parse_args(["report", str(tmp_path / "nothing.nc"), "--out", str(tmp_path / "o")])
    with pytest.raises(ValueError, match="nothing.nc: no such file"):
        args.func(args)


def test_demo_defaults_and_bad_seed(tmp_path):
    args = _parser().parse_args(["demo"])
    assert args.out.replace("\\", "/") == "reports/demo" and args.seed == 0 and not args.quick
    args = _parser().parse_args(["demo", "--seed", "-1", "--out", str(tmp_path)])
    with pytest.raises(ValueError, match="seed"):
        args.func(args)
