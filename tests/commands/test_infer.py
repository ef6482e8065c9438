"""``bayespig infer``: what it writes and prints (through its own argparse registration)."""

import argparse
import json

import numpy as np
import pandas as pd
import pytest

from bayespig.commands.infer import add_infer_parser
from bayespig.data import simulate_to_csv
from bayespig.inference import load_inference


def run(argv):
    parser = argparse.ArgumentParser(prog="bayespig")
    add_infer_parser(parser.add_subparsers())
    args = parser.parse_args(argv)
    return args.func(args)


def test_infer_writes_posterior_and_summary(tmp_path, capsys):
    data = tmp_path / "film.csv"
    simulate_to_csv(data, a=0.1, tau=1.0, design="method4", wavelengths=[500.0, 600.0], seed=3)
    out = tmp_path / "out"
    assert run(["infer", str(data), "--method", "4", "--out", str(out), "--seed", "2",
                "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "method4" in printed and "a_mean" in printed and "posterior.nc" in printed
    idata = load_inference(out / "posterior.nc")
    assert idata.posterior.attrs["seed"] == 2 and idata.posterior.attrs["method"] == "method4"
    summary = pd.read_csv(out / "summary.csv", index_col="wavelength_nm")
    assert list(summary.index) == [500.0, 600.0]
    np.testing.assert_allclose(summary["a_mean"], idata.posterior["a"].mean(("chain", "draw")), rtol=1e-5)
    assert sorted(p.name for p in out.iterdir()) == ["posterior.nc", "summary.csv"]


@pytest.mark.parametrize("eps", ["-1", "abc", "0"])
def test_bad_eps_is_a_clear_error(tmp_path, eps):
    data = tmp_path / "film.csv"
    simulate_to_csv(data, a=0.1, tau=1.0, design="method4", wavelengths=[500.0], seed=3)
    with pytest.raises(ValueError, match="--eps"):
        run(["infer", str(data), "--out", str(tmp_path / "out"), "--eps", eps])
    assert not (tmp_path / "out").exists()


def test_missing_file_writes_nothing(tmp_path):
    with pytest.raises(ValueError, match="file not found"):
        run(["infer", str(tmp_path / "nothing.csv"), "--out", str(tmp_path / "out")])
    assert not (tmp_path / "out").exists()


def test_unsupported_method_is_a_clear_error(tmp_path):
    data = tmp_path / "film.csv"
    simulate_to_csv(data, a=0.1, tau=1.0, design="method3", wavelengths=[500.0], seed=3)
    with pytest.raises(ValueError, match="method4"):
        run(["infer", str(data), "--method", "4", "--out", str(tmp_path / "out"), "--no-progress"])
    assert not (tmp_path / "out").exists()


def test_infer_warns_of_a_posterior_at_its_prior_bound(tmp_path, capsys):
    """An opaque film that absorbs nothing at 400-450 nm: a piles against its prior bound 0 there."""
    from bayespig.report.write import PRIOR_EDGE_TEXT

    data = tmp_path / "film.csv"
    wavelengths = [400.0, 450.0, 500.0, 550.0]
    simulate_to_csv(data, a=[0.0, 0.0, 0.1, 0.2], tau=1.0, design=[{"name": "opaque", "opaque": True}],
                    wavelengths=wavelengths, eps=0.02, seed=3)
    out = tmp_path / "out"
    assert run(["infer", str(data), "--out", str(out), "--seed", "2", "--no-progress"]) == 0
    message = ("a is at its prior bound 0 at 400-450 nm: the data do not tell it from 0 or push it beyond its "
               "prior range [0, 1]; unless it can truly be that close to 0, the model may be wrong for these "
               "data (or the prior too narrow)")
    assert f"bayespig: warning: {message}\n" in capsys.readouterr().err
    summary = pd.read_csv(out / "summary.csv", index_col="wavelength_nm", keep_default_na=False)
    assert list(summary["prior_edge"]) == ["a at 0", "a at 0", "", ""]
    idata = load_inference(out / "posterior.nc")
    assert json.loads(idata.posterior.attrs["prior_bounds"]) == {"a": {"lower": 0.0, "upper": 1.0, "scale": "linear"}}
    # bayespig report prints it too, shows it at the top, and lists it in summary.json
    from bayespig.commands.report import add_report_parser

    parser = argparse.ArgumentParser(prog="bayespig")
    add_report_parser(parser.add_subparsers())
    args = parser.parse_args(["report", str(out / "posterior.nc"), "--out", str(tmp_path / "report"),
                              "--no-progress"])
    assert args.func(args) == 0
    assert f"bayespig: warning: {message}\n" in capsys.readouterr().err
    markdown = (tmp_path / "report" / "report.md").read_text()
    from bayespig.report.document import _md_escape

    assert f"**Prior edge.** {_md_escape(PRIOR_EDGE_TEXT)}\n\n- {_md_escape(message)}." in markdown
    assert markdown.index("Prior edge") < markdown.index("## Optical properties")
    summary_json = json.loads((tmp_path / "report" / "summary.json").read_text())
    assert [e["text"] for e in summary_json["prior_edge"]] == [message]
