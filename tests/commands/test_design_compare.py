"""``bayespig design`` and ``bayespig compare`` command modules (issue 8): flags, files, errors."""

import argparse
import json

import pytest

from bayespig.commands.compare import add_compare_parser
from bayespig.commands.design import add_design_parser, design_settings


def _parser():
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    add_design_parser(sub)
    add_compare_parser(sub)
    return parser


def test_design_from_file_and_flags(tmp_path, capsys):
    config = tmp_path / "design.toml"
    config.write_text('a = [0.02, 0.2]\nthicknesses = [5, 20]\nsubstrates = ["black", "white", "grey:0.3"]\n'
                      'draws = 4\nwavelengths = [450, 550, 650]\n')
    args = _parser().parse_args(["design", str(config), "--eps", "0.03", "--out", str(tmp_path / "out")])
    settings = design_settings(args)
    assert settings["eps"] == 0.03 and settings["thicknesses"] == [5, 20]  # flag wins, file kept
    assert args.func(args) == 0
    payload = json.loads((tmp_path / "out" / "design.json").read_text())
    assert payload["settings"]["eps"] == 0.03
    assert len(payload["ranking"]) == len(payload["candidates"]) > 10
    assert "wrote" in capsys.readouterr().out


def test_design_rejects_unknown_keys(tmp_path):
    config = tmp_path / "design.json"
    config.write_text(json.dumps({"thickness": [5]}))
    args = _parser().parse_args(["design", str(config), "--out", str(tmp_path)])
    with pytest.raises(ValueError, match="unknown keys thickness"):
        args.func(args)


def test_compare_fisher_only_paper_points_and_map(tmp_path):
    args = _parser().parse_args(["compare", "--paper-points", "--map", "--fisher-only", "--methods", "1,2,4",
                                 "--out", str(tmp_path)])
    assert args.func(args) == 0
    payload = json.loads((tmp_path / "compare.json").read_text())
    assert payload["maps"]["names"] == ["method1", "method2", "method4"]
    assert "ranking_checks" in payload["paper_points"]


def test_compare_errors(tmp_path):
    parser = _parser()
    for argv, message in ((["--a", "0.1"], "go together"), (["--methods", "5"], "unknown method"),
                          ([], "nothing to compare")):
        args = parser.parse_args(["compare", "--fisher-only", "--out", str(tmp_path), *argv])
        with pytest.raises(ValueError, match=message):
            args.func(args)
