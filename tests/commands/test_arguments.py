"""Shared command-line values: method spellings (one function for the API and the CLI) and the
output check made before any work."""

import argparse

import numpy as np
import pytest

from bayespig.commands._arguments import add_verbosity_arguments, check_output_path, parse_methods, progress_printer
from bayespig.likelihood import method_name

VALID = "1, 2, 3, 4, method1, method2, method3, method4"


@pytest.mark.parametrize("spelling", [4, np.int64(4), "4", "method4", " method4 "])
def test_every_spelling_of_method_4(spelling):
    assert method_name(spelling) == "method4"
    assert method_name(spelling, also=()) == "method4"


def test_auto_and_general_only_where_they_are_allowed():
    assert method_name("auto") == "auto" and method_name("general") == "general"
    with pytest.raises(ValueError) as error:
        method_name("auto", also=(), argument="method")
    assert str(error.value) == f"unknown method 'auto': method must be one of {VALID}"


@pytest.mark.parametrize("bad", ["method5", "5", 0, 5, "Method4", ""])
def test_an_unknown_method_lists_the_valid_ones(bad):
    with pytest.raises(ValueError) as error:
        method_name(bad)
    assert str(error.value) == f"unknown method {bad!r}: method must be one of {VALID}, auto, general"


@pytest.mark.parametrize("bad", [True, None, 4.0, ["method4"]])
def test_a_method_of_the_wrong_type_is_a_type_error_naming_the_argument(bad):
    with pytest.raises(TypeError, match=r"^design must be a method number or name \(1, 2, 3, 4, "):
        method_name(bad, argument="design")


def test_parse_methods_takes_both_spellings():
    assert parse_methods("1, method4") == ("method1", "method4")
    with pytest.raises(ValueError, match=f"^unknown method 'auto': --methods must be one of {VALID}$"):
        parse_methods("1,auto", "--methods")


def test_check_output_path_returns_the_folder_the_output_will_create(tmp_path):
    assert check_output_path(tmp_path / "a" / "b" / "out.csv", "file") == tmp_path / "a"
    assert check_output_path(tmp_path / "out", "folder") == tmp_path / "out"
    assert check_output_path(tmp_path / "out.csv", "file") is None
    assert check_output_path(tmp_path, "folder") is None
    assert list(tmp_path.iterdir()) == []  # checking creates nothing
    (tmp_path / "f.csv").write_text("x")
    assert check_output_path(tmp_path / "f.csv", "file") is None  # replaced atomically when written
    with pytest.raises(ValueError, match="kind must be 'file' or 'folder'"):
        check_output_path(tmp_path, "dir")


def test_film_of_a_posterior_is_refused(tmp_path):
    from bayespig.commands._arguments import read_film

    with pytest.raises(ValueError, match=r"^--film selects a film of a measurement table; '.*run.nc' is a posterior, "
                                         r"which holds one film already: leave out --film 04B$"):
        read_film(tmp_path / "run.nc", "04B")


def test_progress_printer_prints_each_message_on_stderr_and_nothing_when_quiet(capsys):
    parser = argparse.ArgumentParser()
    add_verbosity_arguments(parser)
    say = progress_printer(parser.parse_args([]))
    say("stage 1 done")
    say("stage 2 done")
    captured = capsys.readouterr()
    assert captured.err == "stage 1 done\nstage 2 done\n" and captured.out == ""
    assert progress_printer(parser.parse_args(["-q"])) is None
