"""Checks of the arguments of :func:`bayespig.infer` and :func:`bayespig.inference.infer_problem`.

Each check raises one :class:`TypeError` (wrong kind of value) or :class:`ValueError` (right
kind, impossible value) whose message names the argument, says what is expected and shows what
was given; it runs before any file is read or any sample drawn. ``noise_floor`` is checked by
:func:`bayespig.likelihood.noise_floor_argument` (re-exported here; the likelihood takes the
same values).
"""

from __future__ import annotations

import numbers

import numpy as np

from .._validation import flag
from ..likelihood import Priors, method_name, noise_floor_argument
from .settings import InferenceSettings

__all__ = [
    "DEFAULT_EPS",
    "EPS_RANGE",
    "check_executor",
    "check_g",
    "check_method",
    "check_priors",
    "check_seed",
    "check_selection",
    "check_settings",
    "check_substrate_sd",
    "eps_argument",
    "noise_floor_argument",
]

#: Open interval of a known relative error ``eps`` [-]: a relative standard deviation of the
#: measured values (eq. 7), 0.02 for 2 %; 1 or more would be noise as large as the signal.
EPS_RANGE = (0.0, 1.0)
#: bayespig.infer's eps when neither the call nor the file gives one [-] (the paper's 5 %, eq. 7).
DEFAULT_EPS = 0.05


def _shown(value):
    """``type value`` of a given argument, for the messages."""
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{type(value).__name__} {text}"


def _is_number(value):
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def check_seed(seed):
    """``seed`` as an int: a non-negative integer (not a bool)."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (numbers.Integral, np.integer)):
        raise TypeError(f"seed must be a non-negative integer, got {_shown(seed)}")
    if seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def check_g(g):
    """``g``: ``"isotropic"`` or ``"free"``."""
    if not isinstance(g, str) or g not in ("isotropic", "free"):
        raise ValueError(f"g must be 'isotropic' or 'free', got {g!r}")
    return g


def check_method(method):
    """``method`` as the name :meth:`bayespig.likelihood.Problem.from_measurements` takes.

    Accepts ``"auto"``, ``"general"``, ``"method1"`` ... ``"method4"``, and the numbers 1 ... 4
    (int or their digits as str): :func:`bayespig.likelihood.method_name`, the one normaliser
    every entry point shares.
    """
    return method_name(method)


def eps_argument(eps):
    """``eps``: None (the set's own or the default), ``"infer"``, or a float in :data:`EPS_RANGE`."""
    low, high = EPS_RANGE
    expected = f"a number in ({low:g}, {high:g}) (a relative error, e.g. 0.02 for 2 %), 'infer' or None"
    if eps is None:
        return None
    if isinstance(eps, str):
        if eps != "infer":
            raise ValueError(f"eps must be {expected}, got {eps!r}")
        return eps
    if not _is_number(eps):
        raise TypeError(f"eps must be {expected}, got {_shown(eps)}")
    value = float(eps)
    if not (np.isfinite(value) and low < value < high):
        raise ValueError(f"eps must lie in ({low:g}, {high:g}) (a relative error, e.g. 0.02 for 2 %), "
                         f"got {eps!r}")
    return value


def check_executor(executor):
    """``executor``: None, or an object with a callable ``submit`` (``concurrent.futures``-style)."""
    if executor is not None and not callable(getattr(executor, "submit", None)):
        raise TypeError("executor must be None (a local pool of 2 processes) or a concurrent.futures-style "
                        "executor with a submit method (e.g. ProcessPoolExecutor, a dask client's "
                        f"get_executor()), got {_shown(executor)}")
    return executor


def check_priors(priors):
    """``priors``: None (the defaults) or a :class:`~bayespig.likelihood.Priors`."""
    priors = Priors() if priors is None else priors
    if not isinstance(priors, Priors):
        raise TypeError(f"priors must be a bayespig.likelihood.Priors, got {type(priors).__name__}")
    return priors


def check_settings(settings):
    """``settings``: None (the defaults) or an :class:`~bayespig.inference.InferenceSettings`."""
    settings = InferenceSettings() if settings is None else settings
    if not isinstance(settings, InferenceSettings):
        raise TypeError(f"settings must be an InferenceSettings, got {type(settings).__name__}")
    return settings


def check_substrate_sd(substrate_sd):
    """``substrate_sd``: None or a positive number (prior sd of ``log f``)."""
    if substrate_sd is None:
        return None
    expected = "a positive number (the prior sd of log f, e.g. 0.1 for 10 %) or None"
    if not _is_number(substrate_sd):
        raise TypeError(f"substrate_sd must be {expected}, got {_shown(substrate_sd)}")
    if not (np.isfinite(substrate_sd) and substrate_sd > 0):
        raise ValueError(f"substrate_sd must be {expected}, got {substrate_sd!r}")
    return float(substrate_sd)


def check_selection(*, exclude_mirror_deg=None, max_angle_deg=None, wavelengths=None, wavelength_range=None,
                    exclude_occluded=False):
    """The selection arguments of :func:`bayespig.infer` checked without a measurement set:
    the angles (None or degrees in [0, 180] and [0, 90]), ``exclude_occluded`` a flag, ``wavelengths`` a non-empty sequence
    of numbers, ``wavelength_range`` a pair ``(low, high)`` with ``low <= high``.

    What needs the set (a wavelength that is not measured, a selection that leaves nothing) is
    checked by :func:`bayespig.selection.select_measurements`.
    """
    flag("exclude_occluded", exclude_occluded)
    for name, value, high in (("exclude_mirror_deg", exclude_mirror_deg, 180.0),
                              ("max_angle_deg", max_angle_deg, 90.0)):
        if value is None:
            continue
        if not _is_number(value):
            raise TypeError(f"{name} must be None or a number of degrees in [0, {high:g}], got {_shown(value)}")
        if not (np.isfinite(value) and 0.0 <= value <= high):
            raise ValueError(f"{name} must be None or a number of degrees in [0, {high:g}], got {value!r}")
    if wavelengths is not None:
        if isinstance(wavelengths, (str, bytes)) or np.ndim(wavelengths) != 1 or not all(
                _is_number(w) for w in wavelengths):
            raise TypeError(f"wavelengths must be None or a sequence of wavelengths [nm], got {_shown(wavelengths)}")
        if len(wavelengths) == 0:
            raise ValueError("wavelengths must not be empty (None keeps every band)")
    if wavelength_range is not None:
        if (isinstance(wavelength_range, (str, bytes)) or np.ndim(wavelength_range) != 1
                or len(wavelength_range) != 2 or not all(_is_number(w) for w in wavelength_range)):
            raise TypeError("wavelength_range must be None or a pair (low, high) of wavelengths [nm], "
                            f"got {_shown(wavelength_range)}")
        low, high = (float(w) for w in wavelength_range)
        if not (np.isfinite(low) and np.isfinite(high) and low <= high):
            raise ValueError(f"wavelength_range must be (low, high) with low <= high [nm], got {wavelength_range!r}")
