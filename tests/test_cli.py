"""The ``bayespig`` command: exit statuses and what it writes."""

import numpy as np

from bayespig import read_measurements
from bayespig.cli import main


def test_simulate_then_check_round_trip(tmp_path, capsys):
    out = tmp_path / "film.csv"
    assert main(["simulate", "--a", "0.1", "--tau", "1.0", "--design", "method4", "--seed", "3",
                 "--out", str(out)]) == 0
    measurements = read_measurements(out)
    assert measurements.metadata["seed"] == 3
    assert np.all(np.asarray(measurements.metadata["truth"]["a"]) == 0.1)
    capsys.readouterr()
    assert main(["check", str(out)]) == 0
    report = capsys.readouterr().out
    assert "method4: yes" in report and "method1: no" in report


def test_check_bad_file_exits_2_naming_row_and_field(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("sample,role,measurement,geometry,400\nfilm,film,brdf,45as15,nan\n")
    assert main(["check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "row 2" in err


def test_unknown_instrument_is_a_clear_error(tmp_path, capsys):
    assert main(["simulate", "--a", "0.1", "--tau", "1", "--instrument", "nope",
                 "--out", str(tmp_path / "x.csv")]) == 2
    assert "multi-angle-45" in capsys.readouterr().err
    assert not (tmp_path / "x.csv").exists()


def test_robustness_grid_prints_every_case_and_writes_json(tmp_path, capsys):
    """Method 1's tau error is eps (paper section 4.1), here through the command line."""
    import json

    out = tmp_path / "cases.json"
    assert main(["robustness", "--method", "1,4", "--a0", "0.1", "--tau0", "0.5", "--n-repeat", "400",
                 "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "method1" in printed and "method4" in printed
    records = {r["method"]: r for r in json.loads(out.read_text())}
    assert set(records) == {"method1", "method4"}
    # sample sd of -log(1 + eps xi) over 400 replicates: standard error ~ eps / sqrt(2 * 400)
    eps, n = 0.05, 400
    assert abs(records["method1"]["tau_rms"] - eps) < 5 * eps / np.sqrt(2 * n)


def test_robustness_rejects_unknown_methods_and_bad_grids(tmp_path, capsys):
    assert main(["robustness", "--method", "5"]) == 2
    assert "unknown method '5'" in capsys.readouterr().err
    assert main(["robustness", "--a0", "0.1,x"]) == 2
    assert "--a0" in capsys.readouterr().err


def test_every_command_is_wired_to_a_function():
    """Each subcommand (and sub-subcommand) the parser knows dispatches to a function: a
    command registered without one fails at run time with an AttributeError, not a usage
    message."""
    import argparse

    from bayespig.cli import build_parser

    def leaves(parser, path=()):
        actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not actions:
            yield path, parser
            return
        for name, child in actions[0].choices.items():
            yield from leaves(child, path + (name,))

    found = list(leaves(build_parser()))
    assert {p[0] for p, _ in found} >= {"demo", "infer", "report", "table", "check", "simulate",
                                       "robustness", "compare", "design", "revigo"}
    for path, parser in found:
        assert callable(parser.get_default("func")), " ".join(path)


def test_revigo_command_on_a_missing_folder_exits_2(tmp_path, capsys):
    assert main(["revigo", str(tmp_path / "nowhere"), "--report", str(tmp_path / "r.md"), "--quiet"]) == 2
    assert "nowhere" in capsys.readouterr().err
    assert not (tmp_path / "r.md").exists()


def test_infer_one_film_of_a_spectral_table_and_warn_where_the_model_cannot_fit(tmp_path, capsys):
    """``--film`` picks a film of a Revigo-style table; a band measured brighter over the black card
    than over the white (no layer model can do that) is named as a misfit, the other band is not."""
    import arviz as az

    rows = [["X_b", 5, 5], ["X_w", 80, 85], ["X_ob", 20, 30], ["X_ow", 40, 50],
            ["Z_b", 5, 5], ["Z_w", 80, 85], ["Z_ob", 45, 30], ["Z_ow", 40, 50]]
    table = tmp_path / "table.txt"
    table.write_text("Name\t400\t500\n" + "\n".join("\t".join(map(str, r)) for r in rows) + "\n")
    out = tmp_path / "posterior"
    assert main(["infer", str(table), "--film", "Z", "--method", "4", "--eps", "0.01", "--out", str(out),
                 "--max-steps", "400", "--no-progress"]) == 0
    captured = capsys.readouterr()
    idata = az.from_netcdf(out / "posterior.nc")
    assert set(np.asarray(idata.observed_data["sample"].values).ravel()) == {"Z_ob", "Z_ow"}
    assert "cannot reproduce the measurements at 1 wavelength(s)" in captured.err
    assert "400 nm (p = " in captured.err and "500 nm" not in captured.err.split("cannot reproduce")[1]
    assert main(["infer", str(table), "--out", str(tmp_path / "none"), "--no-progress"]) == 2
    assert "holds 2 films" in capsys.readouterr().err
