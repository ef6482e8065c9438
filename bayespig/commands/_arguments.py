"""Command-line values shared by the sub-commands: paths checked before any work, number lists,
method and instrument names, the film of a table, how much is printed."""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from ..instruments import BUILT_IN_INSTRUMENTS, get_instrument
from ..likelihood import method_name

__all__ = [
    "INPUT_KINDS",
    "METHOD_HELP",
    "add_film_argument",
    "add_film_state_arguments",
    "add_input_argument",
    "add_output_argument",
    "add_substrate_argument",
    "add_verbosity_arguments",
    "check_input_path",
    "check_output_path",
    "film_state",
    "instrument_argument",
    "instrument_help",
    "method_argument",
    "paper_method_argument",
    "parse_methods",
    "parse_numbers",
    "read_film",
    "substrate_argument",
]

#: What ``--method`` accepts, for the help texts.
METHOD_HELP = "1, 2, 3, 4 (or method1 .. method4)"
#: What a measurement file may be, for the messages.
INPUT_KINDS = ("a measurement file (bayespig CSV, ASTM E1392 .astm, or a wide spectral table), or a "
               "Revigo data folder containing '*spectral-data*.txt'")
_SPECTRAL_DATA_GLOB = "*spectral-data*.txt"


# ------------------------------------------------------------------------------------ outputs
def check_output_path(path, kind="file"):
    """Say in plain words, before any work, why ``path`` cannot be written.

    Missing parent folders are fine (they are created when the output is written, not before);
    the nearest existing one must be a folder in which files can be created (tried by
    creating and removing an empty temporary folder in it).

    Parameters
    ----------
    path : str or os.PathLike
        The output a command was given.
    kind : {"file", "folder"}
        What the command writes there: one file, or a folder of files.

    Returns
    -------
    pathlib.Path or None
        The outermost folder that does not exist yet (the command creates it: remove it if the
        command does not finish), or None when the parent folder exists.

    Raises
    ------
    ValueError
        ``cannot write the output: ...`` naming the path and the reason.
    """
    if kind not in ("file", "folder"):
        raise ValueError(f"kind must be 'file' or 'folder', got {kind!r}")
    path = Path(path)
    if str(path) == "":
        raise ValueError("cannot write the output: no path given")
    if path.is_dir():
        if kind == "file":
            raise ValueError(f"cannot write the output: '{path}' is a folder; give the name of the file "
                             "to write")
        _check_writable_folder(path, path)
        return None
    if path.exists() or path.is_symlink():
        if kind == "folder":
            raise ValueError(f"cannot write the output: '{path}' exists and is a file, not a folder")
        if not path.is_file() or not os.access(path, os.W_OK):
            raise ValueError(f"cannot write the output: '{path}' exists and cannot be replaced")
    # the folder output itself is created too; a file output creates its missing parents
    missing, parent = (path.absolute() if kind == "folder" else None), path.absolute().parent
    while not (parent.exists() or parent.is_symlink()):
        missing, parent = parent, parent.parent
    if not parent.is_dir():
        raise ValueError(f"cannot write the output '{path}': '{_shown(parent, path)}' is a file, not a folder")
    _check_writable_folder(parent, path)
    return None if missing is None else _shown(missing, path)


def _shown(folder, path):
    """``folder`` as relative as ``path`` was given (for the messages and the clean-up)."""
    return folder if Path(path).is_absolute() else Path(os.path.relpath(folder))


def _check_writable_folder(folder, path):
    try:
        Path(tempfile.mkdtemp(prefix=".bayespig-write-check-", dir=folder)).rmdir()
    except OSError:
        raise ValueError(f"cannot write the output '{path}': the folder '{_shown(folder, path)}' is not "
                         "writable") from None


def add_output_argument(parser, *flags, kind, **kwargs):
    """Add an output option whose path :func:`bayespig.cli.main` checks before the command runs.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    *flags : str
        Option strings, e.g. ``"--out"``.
    kind : {"file", "folder"}
        See :func:`check_output_path`.
    **kwargs
        Passed to ``parser.add_argument``.
    """
    action = parser.add_argument(*flags, **kwargs)
    outputs = dict(parser.get_default("output_paths") or {})
    outputs[action.dest] = kind
    parser.set_defaults(output_paths=outputs)
    return action


# ------------------------------------------------------------------------------------- inputs
def reference_data_folder(path, *, default, variable, name, source, command):
    """The folder of a reference data set: ``path``, else ``$variable``, else ``default``.

    Parameters
    ----------
    path : str or os.PathLike or None
        The folder the user gave.
    default : pathlib.Path
        Where it is looked for otherwise (already resolved from ``$variable`` when set).
    variable, name, source, command : str
        The environment variable (e.g. ``"BAYESPIG_REVIGO"``), the data's name ("Revigo"),
        where they come from, and the command that reads them ("bayespig revigo").

    Raises
    ------
    MeasurementError
        When it does not exist: ``<folder>: file not found``, where it was looked for, where the
        data come from and how to point at them.
    """
    from ..data.errors import MeasurementError, Problem

    folder = Path(path) if path is not None else Path(default)
    if folder.exists():
        return folder
    if path is not None:
        where = "the folder given"
    elif os.environ.get(variable):
        where = f"from ${variable}"
    else:
        where = f"the default, ../shared/data/{folder.name} from the working folder"
    raise MeasurementError(Problem(f"file not found ({where}). The {name} data are {source}; give "
                                   f"their folder as '{command} FOLDER' or set {variable}=FOLDER",
                                   file=str(folder)))


def check_input_path(path):
    """Say in plain words, before any work, why ``path`` is not a measurement input.

    Raises
    ------
    ValueError
        ``'<path>': file not found``, or for a folder that is not a Revigo data folder what
        kinds of input are accepted.
    """
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: file not found")
    if path.is_dir() and not any(path.glob(_SPECTRAL_DATA_GLOB)):
        raise ValueError(f"'{path}' is a folder; give {INPUT_KINDS}")
    return path


def add_input_argument(parser, *flags, **kwargs):
    """Add a measurement-file argument that :func:`bayespig.cli.main` checks before the command runs."""
    action = parser.add_argument(*flags, **kwargs)
    parser.set_defaults(input_paths=(*(parser.get_default("input_paths") or ()), action.dest))
    return action


# ---------------------------------------------------------------------------- how much is said
def add_verbosity_arguments(parser):
    """``-q/--quiet`` (``args.no_progress``) and ``-v/--verbose`` (``args.verbose``).

    ``--quiet``: no progress output (results, warnings and errors are still printed);
    ``--verbose``: on an error, also its traceback. ``--no-progress``, the older spelling of
    ``--quiet``, stays as a hidden alias.
    """
    group = parser.add_mutually_exclusive_group()
    group.add_argument("-q", "--quiet", dest="no_progress", action="store_true",
                       help="no progress output (results, warnings and errors are still printed)")
    group.add_argument("--no-progress", dest="no_progress", action="store_true", help=argparse.SUPPRESS)
    group.add_argument("-v", "--verbose", action="store_true",
                       help="on an error, also print its traceback (for a bug report)")


def progress_printer(args):
    """The progress callback of a study run from the command line: one line per message on stderr.

    ``None`` under ``--quiet`` (:func:`add_verbosity_arguments`). For the APIs that take a
    callable ``progress``; those that take a flag get ``not args.no_progress``.
    """
    return None if args.no_progress else (lambda message: print(message, file=sys.stderr, flush=True))


# ----------------------------------------------------------------------- methods, instruments
def method_argument(text):
    """argparse ``type`` of ``--method``: a method (any spelling), ``auto`` or ``general``."""
    try:
        return method_name(text, argument="--method")
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def paper_method_argument(text):
    """argparse ``type`` of ``--design``: one of the paper's methods (any spelling)."""
    try:
        return method_name(text, also=(), argument="--design")
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def instrument_help(what="instrument", default=None):
    """Help text of an instrument option, listing the built-in names."""
    text = (f"{what}: a built-in name ({', '.join(BUILT_IN_INSTRUMENTS)}) or comma-separated geometry "
            "labels such as 45as15,45as110")
    return text + (f" (default {default})" if default else "")


def instrument_argument(name):
    """A built-in instrument name, or comma-separated geometry labels such as ``45as15,45as110``.

    Returns
    -------
    str or Instrument
        The built-in name, or the instrument of the labels.

    Raises
    ------
    ValueError
        Listing the built-in names.
    """
    if name in BUILT_IN_INSTRUMENTS:
        return name
    try:
        return get_instrument([label for label in name.split(",") if label.strip()])
    except ValueError:
        raise ValueError(
            f"unknown instrument {name!r}; built-in instruments: {', '.join(BUILT_IN_INSTRUMENTS)} "
            "(or comma-separated geometry labels such as 45as15,45as110)"
        ) from None


def parse_numbers(text, flag, *, positive=False):
    """Comma-separated numbers such as ``0.025,0.1,0.2`` -> float array.

    Raises
    ------
    ValueError
        Naming ``flag`` when an item is not a number, the list is empty, or (``positive``)
        a value is not a positive finite number.
    """
    try:
        values = np.array([float(v) for v in str(text).split(",") if v.strip()])
    except ValueError:
        raise ValueError(f"{flag}: expected comma-separated numbers, got {text!r}") from None
    if values.size == 0:
        raise ValueError(f"{flag}: no value given")
    if positive and not np.all(np.isfinite(values) & (values > 0)):
        raise ValueError(f"{flag}: expected positive finite numbers, got {text!r}")
    return values


def parse_methods(text, flag="--method"):
    """``1,4`` or ``method1,method4`` -> a tuple of the paper's method names."""
    names = [method_name(item, also=(), argument=flag)
             for item in (v.strip() for v in str(text).split(",") if v.strip())]
    if not names:
        raise ValueError(f"{flag}: no method given")
    return tuple(names)


def add_film_argument(parser):
    """``--film ID``: which film of a spectral table holding several (Revigo) to use."""
    parser.add_argument("--film", default=None,
                        help="for a spectral table of several films (Revigo): the film id, e.g. 04B")


def read_film(path, film, flag="--film"):
    """The measurement file ``path`` as given (``film`` None) or the set of one film of a table.

    Raises
    ------
    ValueError
        When ``film`` is given for a file that holds one pigment (bayespig CSV, ASTM E1392).
    """
    if film is None:
        return path
    if str(path).endswith(".nc"):
        raise ValueError(f"{flag} selects a film of a measurement table; '{path}' is a posterior, which "
                         f"holds one film already: leave out {flag} {film}")
    from ..data import read_measurements
    from ..data.io import file_format

    # only a regular file is sniffed here: a pipe (<(cat f), /dev/stdin) can be read only once
    kind = file_format(path) if os.path.isfile(path) else "spectral_table"
    if kind != "spectral_table":
        name = {"csv": "a bayespig CSV", "astm_e1392": "an ASTM E1392 file"}[kind]
        raise ValueError(f"{flag} selects a film of a Revigo/wide spectral table; '{path}' is {name} "
                         f"(one pigment, no films to choose from): leave out {flag} {film}")
    return read_measurements(path, film=film)


def add_substrate_argument(parser):
    """``--substrate-sd SD``: the cards' albedo as a nuisance parameter (one factor per card)."""
    parser.add_argument("--substrate-sd", type=float, default=None, metavar="SD",
                        help="treat each card's albedo seen from the binder as uncertain: one factor per "
                        "card, log-normal prior with this sd (e.g. 0.1 for ~10 %%, paper section 3.4); "
                        "samples all wavelengths jointly (slower); needs a known eps")


def substrate_argument(text):
    """``--substrate`` text -> ``"black"``, ``"white"``, an albedo in [0, 1] or a sample name."""
    try:
        value = float(text)
    except ValueError:
        if not text.strip():
            raise argparse.ArgumentTypeError("expected 'black', 'white', an albedo in [0, 1] or a sample "
                                             "name, got ''") from None
        return text.strip()
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"an albedo must be in [0, 1], got {text!r}")
    return value


def add_film_state_arguments(parser):
    """``--opaque`` / ``--substrate X``: what an ASTM E1392 file cannot say (no keyword for it)."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--opaque", action="store_true", default=None,
                       help="ASTM E1392 files: the film hides its substrate (wins over an OPAQUE or "
                       "SUBSTRATE keyword in the file)")
    group.add_argument("--substrate", type=substrate_argument, default=None, metavar="SUBSTRATE",
                       help="ASTM E1392 files: the film's substrate, black (r_s 0.01), white (0.95), an "
                       "albedo in [0, 1] or a substrate sample's name; the film does not hide it (wins over the "
                       "file's SUBSTRATE and OPAQUE)")


def film_state(args):
    """``read_measurements`` keyword arguments from ``--opaque`` / ``--substrate``."""
    opaque = True if getattr(args, "opaque", None) else None
    substrate = getattr(args, "substrate", None)
    if substrate is not None:
        opaque = False  # --substrate: the film lets its substrate show (an OPAQUE keyword yields)
    return {} if opaque is None and substrate is None else {"opaque": opaque, "substrate": substrate}
