"""Command-line values shared by the sub-commands: number lists, method names, the film of a table."""

from __future__ import annotations

import numpy as np

__all__ = ["INFER_METHODS", "METHOD_NAMES", "add_film_argument", "add_substrate_argument", "parse_methods",
           "parse_numbers", "read_film"]

#: ``--method 1,4`` -> the paper's method names.
METHOD_NAMES = {"1": "method1", "2": "method2", "3": "method3", "4": "method4"}
#: ``--method`` of ``infer`` and ``report``: a method, ``auto`` or ``general``.
INFER_METHODS = {**METHOD_NAMES, "auto": "auto", "general": "general"}


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
    names = []
    for item in (v.strip() for v in str(text).split(",") if v.strip()):
        name = METHOD_NAMES.get(item, item)
        if name not in METHOD_NAMES.values():
            raise ValueError(f"{flag}: unknown method {item!r}; use 1, 2, 3, 4 (or method1..method4)")
        names.append(name)
    if not names:
        raise ValueError(f"{flag}: no method given")
    return tuple(names)


def add_film_argument(parser):
    """``--film ID``: which film of a spectral table holding several (Revigo) to use."""
    parser.add_argument("--film", default=None,
                        help="for a spectral table of several films (Revigo): the film id, e.g. 04B")


def read_film(path, film):
    """The measurement file ``path`` as given (``film`` None) or the set of one film of a table."""
    if film is None:
        return path
    from ..data import read_measurements

    return read_measurements(path, film=film)


def add_substrate_argument(parser):
    """``--substrate-sd SD``: the cards' albedo as a nuisance parameter (one factor per card)."""
    parser.add_argument("--substrate-sd", type=float, default=None, metavar="SD",
                        help="treat each card's albedo seen from the binder as uncertain: one factor per "
                        "card, log-normal prior with this sd (e.g. 0.1 for ~10 %%, paper section 3.4); "
                        "samples all wavelengths jointly (slower); needs a known eps")
