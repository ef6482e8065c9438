"""The ``bayespig`` command: exit statuses, what it writes, and what it says."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import bayespig
from bayespig import read_measurements
from bayespig.cli import INTERRUPTED_MESSAGE, build_parser, main


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


# --- a new user's mistakes and interruptions (issue 18) ----------------------------------------
EXAMPLE = Path(__file__).parents[1] / "examples" / "data" / "method4-black-white.csv"
INTERRUPTED = INTERRUPTED_MESSAGE + "\n"
#: ``python -c CLI_MAIN ARGS`` runs ``bayespig ARGS`` (the console script may not be on PATH).
CLI_MAIN = "import sys; from bayespig.cli import main; sys.exit(main())"
#: Every command that writes something, its output option and what it writes there, and the
#: function doing the work (monkeypatched: it must not be reached when the output is wrong).
WRITING_COMMANDS = [
    (["infer", str(EXAMPLE)], "--out", "folder", "bayespig.inference.infer"),
    (["report", str(EXAMPLE)], "--out", "folder", "bayespig.report.write_report"),
    (["demo", "--quick"], "--out", "folder", "bayespig.demo.run_demo"),
    (["compare", "--a", "0.1", "--tau", "1", "--fisher-only"], "--out", "folder",
     "bayespig.studies.compare.compare_methods"),
    (["design"], "--out", "folder", "bayespig.studies.design.rank_designs"),
    (["simulate", "--a", "0.1", "--tau", "1"], "--out", "file", "bayespig.data.simulate_to_csv"),
    (["robustness", "--method", "4", "--a0", "0.1", "--tau0", "1"], "--json", "file",
     "bayespig.studies.robustness.robustness_study"),
    (["robustness", "--method", "4", "--a0", "0.1", "--tau0", "1"], "--map", "file",
     "bayespig.studies.robustness.robustness_map"),
    (["robustness", "--paper", "--quick"], "--out", "file", "bayespig.studies.robustness.write_paper_tables"),
    (["robustness", "--posterior"], "--out", "file",
     "bayespig.studies.posterior_robustness.write_posterior_tables"),
    (["revigo", str(EXAMPLE.parent)], "--report", "file", "bayespig.studies.revigo.revigo_study"),
]
IDS = [" ".join(c[0][:1] + [c[1]]) + (" --paper" if "--paper" in c[0] else " --posterior"
                                      if "--posterior" in c[0] else "") for c in WRITING_COMMANDS]


def _must_not_run(*args, **kwargs):
    raise AssertionError("the command started its work before checking its output")


@pytest.mark.parametrize("argv, flag, kind, work", WRITING_COMMANDS, ids=IDS)
def test_a_folder_where_nothing_can_be_written_is_refused_before_any_work(argv, flag, kind, work,
                                                                           monkeypatch, capsys):
    if not os.path.isdir("/proc"):
        pytest.skip("needs Linux's /proc (a folder nobody can create files in)")
    monkeypatch.setattr(work, _must_not_run)
    assert main([*argv, flag, "/proc/nope"]) == 2
    assert capsys.readouterr().err == ("bayespig: error: cannot write the output '/proc/nope': the folder "
                                       "'/proc' is not writable\n")


@pytest.mark.parametrize("argv, flag, kind, work", WRITING_COMMANDS, ids=IDS)
def test_a_file_in_the_way_is_refused_before_any_work(argv, flag, kind, work, tmp_path, monkeypatch,
                                                      capsys):
    monkeypatch.setattr(work, _must_not_run)
    afile = tmp_path / "afile"
    afile.write_text("mine\n")
    assert main([*argv, flag, str(afile / "sub")]) == 2
    assert capsys.readouterr().err == (f"bayespig: error: cannot write the output '{afile}/sub': "
                                       f"'{afile}' is a file, not a folder\n")
    if kind == "folder":
        assert main([*argv, flag, str(afile)]) == 2
        assert capsys.readouterr().err == (f"bayespig: error: cannot write the output: '{afile}' exists "
                                           "and is a file, not a folder\n")
    else:
        assert main([*argv, flag, str(tmp_path)]) == 2
        assert capsys.readouterr().err == (f"bayespig: error: cannot write the output: '{tmp_path}' is a "
                                           "folder; give the name of the file to write\n")
    assert afile.read_text() == "mine\n" and sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


def test_simulate_into_a_folder_names_no_temporary_file(tmp_path, capsys):
    assert main(["simulate", "--a", "0.1", "--tau", "1", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert ".tmp" not in err and "Errno" not in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv, flag, kind, work", WRITING_COMMANDS, ids=IDS)
def test_ctrl_c_prints_one_line_exits_130_and_leaves_nothing(argv, flag, kind, work, tmp_path,
                                                             monkeypatch, capsys):
    """The work is interrupted after it began writing (as ``report`` used to, leaving an empty
    folder): the folders the run created go, and stderr holds the one line."""
    out = tmp_path / "out" if kind == "folder" else tmp_path / "new" / "out.txt"

    def interrupted(*args, **kwargs):
        folder = out if kind == "folder" else out.parent
        folder.mkdir(parents=True, exist_ok=True)
        (folder / ".partial.tmp").write_text("half")
        raise KeyboardInterrupt

    monkeypatch.setattr(work, interrupted)
    assert main([*argv, flag, str(out)]) == 130
    captured = capsys.readouterr()
    assert captured.err == INTERRUPTED and "Traceback" not in captured.out
    assert list(tmp_path.iterdir()) == []


def test_ctrl_c_into_an_existing_folder_keeps_the_folder_and_what_was_there(tmp_path, monkeypatch, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine\n")
    monkeypatch.setattr("bayespig.inference.infer", lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt))
    assert main(["infer", str(EXAMPLE), "--out", str(out)]) == 130
    assert capsys.readouterr().err == INTERRUPTED
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]


def test_ctrl_c_inside_the_likelihood_prints_no_emcee_traceback(tmp_path, monkeypatch, capsys):
    """emcee prints the walkers and a traceback for any exception in the log-probability, Ctrl-C
    included: an interrupt landing there is raised once the likelihood has returned."""
    import emcee

    calls = []

    def log_prob(x):
        calls.append(1)
        if len(calls) == 3:
            os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C while inside emcee's wrapper
            time.sleep(0.05)
        return -0.5 * float(x @ x)

    def sampling_infer(*args, **kwargs):
        start = np.random.default_rng(0).normal(size=(4, 1))
        emcee.EnsembleSampler(4, 1, log_prob).run_mcmc(start, 1000)

    monkeypatch.setattr("bayespig.inference.infer", sampling_infer)
    assert main(["infer", str(EXAMPLE), "--out", str(tmp_path / "o")]) == 130
    captured = capsys.readouterr()
    assert captured.err == INTERRUPTED and captured.out == ""
    assert 3 < len(calls) < 1000 * 4  # interrupted right after the call that was interrupted
    assert list(tmp_path.iterdir()) == []


def test_ctrl_c_during_a_real_infer_run(tmp_path):
    """SIGINT to ``bayespig infer`` on the bundled example once the sampler runs: exit 130, the
    one line on stderr (besides the progress bar), no traceback, no output folder."""
    out = tmp_path / "posterior"
    # more walkers and ensembles than the defaults: several seconds of sampling to interrupt
    process, err = _start(["infer", str(EXAMPLE), "--out", str(out), "--ensembles", "16", "--walkers", "64"],
                          b"inference:")
    time.sleep(0.3)  # inside the sampling loop
    process.send_signal(signal.SIGINT)
    stdout, rest = process.communicate(timeout=60)
    err = (err + rest).decode()
    assert process.returncode == 130, err
    lines = [line for line in err.replace("\r", "\n").splitlines() if line.strip()]
    assert lines[-1] == INTERRUPTED_MESSAGE
    assert [line for line in lines if not line.startswith("inference:")] == [INTERRUPTED_MESSAGE]
    assert not out.exists() and stdout == b""


def _start(argv, ready, **kwargs):
    """Start ``bayespig argv`` in a new session and return it once stderr shows ``ready``."""
    env = {**os.environ, "PYTHONPATH": str(Path(bayespig.__file__).parents[1])}
    process = subprocess.Popen([sys.executable, "-c", CLI_MAIN, *argv], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, env=env, **kwargs)
    err = b""
    deadline = time.monotonic() + 120
    while ready not in err and time.monotonic() < deadline:
        chunk = os.read(process.stderr.fileno(), 256)
        if not chunk:
            break
        err += chunk
    assert ready in err, err.decode()
    return process, err


def test_ctrl_c_in_a_terminal_during_robustness(tmp_path):
    """Ctrl-C in a terminal signals the whole process group, the pool's workers too: they leave it
    to the parent (no worker traceback), which stops them and prints the one line."""
    out = tmp_path / "cases.json"
    process, err = _start(["robustness", "--method", "1,2,3,4", "--n-repeat", "1000", "--json", str(out)],
                          b"robustness:", start_new_session=True)
    time.sleep(0.5)
    os.killpg(process.pid, signal.SIGINT)
    stdout, rest = process.communicate(timeout=60)
    err = (err + rest).decode()
    assert process.returncode == 130, err
    lines = [line for line in err.replace("\r", "\n").splitlines() if line.strip()]
    assert [line for line in lines if not line.startswith("robustness:")] == [INTERRUPTED_MESSAGE]
    assert not out.exists() and stdout == b""


def test_a_folder_as_input_says_what_is_accepted(tmp_path, capsys):
    for argv in (["infer", str(tmp_path), "--out", str(tmp_path / "o")], ["check", str(tmp_path)],
                 ["report", str(tmp_path), "--out", str(tmp_path / "o")]):
        assert main(argv) == 2
        assert capsys.readouterr().err == (
            f"bayespig: error: '{tmp_path}' is a folder; give a measurement file (bayespig CSV, ASTM E1392 "
            ".astm, or a wide spectral table), or a Revigo data folder containing '*spectral-data*.txt'\n")
    assert list(tmp_path.iterdir()) == []


def test_a_missing_input_reads_file_not_found_in_every_command(tmp_path, capsys):
    missing = tmp_path / "nothing.csv"
    for argv in (["infer", str(missing), "--out", str(tmp_path / "o")], ["check", str(missing)],
                 ["report", str(missing), "--out", str(tmp_path / "o")],
                 ["compare", "--measurements", str(missing), "--out", str(tmp_path / "o")],
                 ["design", str(tmp_path / "nothing.toml"), "--out", str(tmp_path / "o")]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("bayespig: error: ") and err.endswith(": file not found\n"), err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("spelling", ["4", "method4"])
def test_infer_and_report_take_every_method_spelling(spelling, tmp_path, monkeypatch):
    seen = []

    def fake_infer(measurements, *, method, **kwargs):
        seen.append(method)
        raise KeyboardInterrupt  # stop here: only the method matters

    monkeypatch.setattr("bayespig.inference.infer", fake_infer)
    monkeypatch.setattr("bayespig.report.write_report",
                        lambda source, out, *, infer_kwargs, **k: fake_infer(source, **infer_kwargs))
    assert main(["infer", str(EXAMPLE), "--method", spelling, "--out", str(tmp_path / "o")]) == 130
    assert main(["report", str(EXAMPLE), "--method", spelling, "--out", str(tmp_path / "o")]) == 130
    assert seen == ["method4", "method4"]


def test_simulate_and_robustness_take_every_method_spelling(tmp_path, capsys):
    for spelling in ("4", "method4"):
        out = tmp_path / f"film-{spelling}.csv"
        assert main(["simulate", "--a", "0.1", "--tau", "1", "--design", spelling, "--out", str(out)]) == 0
        assert read_measurements(out).supported_methods()["method4"]
    printed = capsys.readouterr().out
    assert printed.count("design method4") == 2
    assert main(["robustness", "--method", "method1,4", "--a0", "0.1", "--tau0", "1", "--n-repeat", "4",
                 "--quiet"]) == 0
    rows = [line.split()[0] for line in capsys.readouterr().out.splitlines()[1:]]
    assert rows == ["method1", "method4"]


def test_an_unknown_method_lists_the_valid_ones(capsys):
    with pytest.raises(SystemExit) as exit_status:
        main(["infer", str(EXAMPLE), "--method", "method5", "--out", "never"])
    assert exit_status.value.code == 2
    assert capsys.readouterr().err.endswith(
        "bayespig infer: error: argument --method: unknown method 'method5': --method must be one of 1, 2, "
        "3, 4, method1, method2, method3, method4, auto, general\n")
    assert not Path("never").exists()


def test_film_on_a_one_pigment_file_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr("bayespig.inference.infer", _must_not_run)
    for path, kind in ((EXAMPLE, "a bayespig CSV"), (EXAMPLE.parent / "on-black.astm", "an ASTM E1392 file")):
        assert main(["infer", str(path), "--film", "04B", "--out", str(tmp_path / "o")]) == 2
        assert capsys.readouterr().err == (
            f"bayespig: error: --film selects a film of a Revigo/wide spectral table; '{path}' is {kind} "
            "(one pigment, no films to choose from): leave out --film 04B\n")
    assert list(tmp_path.iterdir()) == []


def test_version(capsys):
    for flag in ("--version", "-V"):
        with pytest.raises(SystemExit) as exit_status:
            main([flag])
        assert exit_status.value.code == 0
        assert capsys.readouterr().out == f"bayespig {bayespig.__version__}\n"


def _leaves(parser, path=()):
    import argparse

    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not actions:
        yield path, parser
        return
    for name, child in actions[0].choices.items():
        yield from _leaves(child, path + (name,))


def test_every_command_is_described_and_explains_every_option():
    """A description, --quiet and --verbose on every command, help on every option, and the
    built-in instrument names wherever an instrument is asked for."""
    import argparse

    from bayespig.instruments import BUILT_IN_INSTRUMENTS

    parser = build_parser()
    assert "thin shell" not in parser.description and "pigment" in parser.description
    for path, command in _leaves(parser):
        name = " ".join(path)
        assert command.description, name
        options = {s for a in command._actions for s in a.option_strings}
        assert {"--quiet", "-q", "--verbose", "-v"} <= options, name
        for action in command._actions:
            if isinstance(action, argparse._HelpAction) or action.help == argparse.SUPPRESS:
                continue
            assert action.help, (name, action.dest)
            if action.dest == "instrument":
                assert all(n in action.help for n in BUILT_IN_INSTRUMENTS), (name, action.help)


def test_quiet_means_no_progress_and_no_progress_is_its_alias(tmp_path, capsys):
    """The robustness grid shows its progress on stderr unless --quiet (or --no-progress)."""
    argv = ["robustness", "--method", "1", "--a0", "0.1", "--tau0", "0.5,1", "--n-repeat", "5"]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "robustness: 100%" in err and "10/10" in err  # 2 cases x 5 refits
    for flag in ("--quiet", "-q", "--no-progress"):
        assert main([*argv, flag]) == 0
        assert capsys.readouterr().err == ""


@pytest.mark.parametrize("mode, work", [("--paper", "bayespig.studies.robustness.write_paper_tables"),
                                        ("--posterior",
                                         "bayespig.studies.posterior_robustness.write_posterior_tables")])
def test_robustness_paper_and_posterior_show_progress(mode, work, tmp_path, monkeypatch, capsys):
    seen = []
    monkeypatch.setattr(work, lambda path, **kwargs: seen.append(kwargs["progress"]))
    for quiet in ([], ["--quiet"]):
        assert main(["robustness", mode, "--out", str(tmp_path / "r.md"), *quiet]) == 0
    assert seen == [True, False]


def test_revigo_without_its_data_says_where_they_come_from(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("BAYESPIG_REVIGO", raising=False)
    monkeypatch.chdir(tmp_path)
    assert main(["revigo", "--report", "r.md"]) == 2
    hint = ("The Revigo data are the CC0 spectra of Geldof et al. (2018), Heritage Science 6:17, from "
            "https://github.com/fligt/revigo-spectra (data/revigo-aggregated-palette-spectral-data.txt and "
            "data/revigo-mixture-specifications.txt); give their folder as 'bayespig revigo FOLDER' or set "
            "BAYESPIG_REVIGO=FOLDER\n")
    default = tmp_path.parent / "shared" / "data" / "revigo"
    assert capsys.readouterr().err == (f"bayespig: error: {default}: file not found (the default, "
                                       f"../shared/data/revigo from the working folder). {hint}")
    monkeypatch.setenv("BAYESPIG_REVIGO", str(tmp_path / "elsewhere"))
    assert main(["revigo", "--report", "r.md"]) == 2
    assert capsys.readouterr().err == (f"bayespig: error: {tmp_path / 'elsewhere'}: file not found (from "
                                       f"$BAYESPIG_REVIGO). {hint}")
    assert list(tmp_path.iterdir()) == []


def test_table_info_names_tables_by_instrument(tmp_path, monkeypatch, capsys):
    """A table built for a sample of a measurement file is listed under its instrument's name
    (multi-angle-45 here), not the sample's, and ``--instrument`` finds it by that name."""
    import json

    from bayespig.instruments import get_instrument

    monkeypatch.setenv("BAYESPIG_CACHE", str(tmp_path))
    channels = [{"label": ch.label} for ch in get_instrument("multi-angle-45").channels]
    description = {"instrument": {"channels": channels, "n": 1.45}, "version": bayespig.__version__,
                   "settings": {"g_range": None, "n_g": 1, "n_a": 48, "a_stretch": 30.0, "log2_tau_min": -10,
                                "log2_tau_max": 7, "per_octave": 4, "n_points": 16,
                                "start_thickness": 2.4e-7}}
    key = "0" * 32
    np.savez(tmp_path / f"table-{key}.npz", __key__=key, __description__=json.dumps(description),
             __instrument__="sample:on_black")
    assert main(["table", "info", "--instrument", "multi-angle-45"]) == 0
    printed = capsys.readouterr().out
    assert f"{key}  " in printed and "  multi-angle-45  n = 1.45" in printed
    assert "sample:on_black" not in printed and printed.endswith("1 cached table for instrument "
                                                                 "'multi-angle-45'\n")


def test_no_command_module_imports_the_cli():
    """The sub-commands sit below ``bayespig.cli`` (no import circle, lazy imports included)."""
    import ast

    folder = Path(bayespig.__file__).parent / "commands"
    for path in folder.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                module = ("." * node.level) + (node.module or "")
                assert module not in ("..cli", "bayespig.cli"), path.name


def test_a_closed_stdout_ends_quietly(tmp_path):
    """``bayespig ... | head``: when the reader goes away the command stops with status 141
    (128 + SIGPIPE) and no ``[Errno 32] Broken pipe`` message."""
    env = {**os.environ, "PYTHONPATH": str(Path(bayespig.__file__).parents[1]), "BAYESPIG_CACHE": str(tmp_path)}
    process = subprocess.Popen([sys.executable, "-c", CLI_MAIN, "check", str(EXAMPLE.parent / "wide-table-percent.txt")],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    process.stdout.close()  # the reader is gone before anything is printed
    with process:
        err = process.stderr.read().decode()
    assert process.returncode == 141 and err == ""


def test_verbose_adds_the_traceback_of_an_error(tmp_path, capsys):
    missing = tmp_path / "nothing.csv"
    assert main(["check", str(missing)]) == 2
    assert capsys.readouterr().err == f"bayespig: error: {missing}: file not found\n"
    assert main(["check", str(missing), "--verbose"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("Traceback (most recent call last):\n")
    assert err.endswith(f"ValueError: {missing}: file not found\nbayespig: error: {missing}: file not found\n")


@pytest.mark.parametrize("importer", ["main", "worker"])
def test_the_command_does_not_pass_on_arviz_s_refactor_notice(importer, tmp_path):
    """arviz 0.x warns on its first import of the day (stamped in the user cache, here a fresh
    one) that 1.0 is coming; a user of the command sees none of it. The script imports arviz
    after ``main`` ran, in a fresh process (arviz not yet imported) or in a worker forked from
    it, as the local pools' workers are."""
    load = ("import arviz" if importer == "main" else
            "worker = multiprocessing.get_context('fork').Process(target=__import__, args=('arviz',)); "
            "worker.start(); worker.join()")
    script = ("import multiprocessing, sys; from bayespig.cli import main; status = main(sys.argv[1:]); "
              f"assert 'arviz' not in sys.modules; {load}; sys.exit(status)")
    env = {**os.environ, "PYTHONPATH": str(Path(bayespig.__file__).parents[1]), "BAYESPIG_CACHE": str(tmp_path),
           "XDG_CACHE_HOME": str(tmp_path / "user-cache")}
    missing = tmp_path / "nothing.csv"
    done = subprocess.run([sys.executable, "-c", script, "check", str(missing)], capture_output=True, text=True,
                          env=env, timeout=120, check=False)
    assert done.returncode == 2
    assert done.stderr == f"bayespig: error: {missing}: file not found\n"
