"""Argument checks for the public API, and random validation points over the tables' domain.

Argument checks (:func:`real_scalar`, :func:`real_array`, :func:`integer`, :func:`seed`,
:func:`choice`, :func:`flag`, :func:`broadcast`) turn a wrong type or value into one ``TypeError`` or
``ValueError`` that names the argument, instead of numpy's internal text. They import nothing
of bayespig, so every layer (physics, tables, inference) can use them.

Validation points (shared by tests and benchmarks):

The table's accuracy is checked against the direct solver at random points of its whole
domain; uniform draws would rarely land where interpolation is hardest (``a -> 0``,
``a -> 1``, ``tau`` below the first node or large, opaque films, ``r_s`` at 0 and 1), so the
sampler mixes uniform draws with shares near every edge.
"""

from __future__ import annotations

import numbers
import operator

import numpy as np

__all__ = ["broadcast", "choice", "domain_points", "flag", "integer", "mixture", "real_array", "real_scalar", "seed"]

#: The default tables' first finite tau node, ``2^TableSettings.log2_tau_min`` [-] (not imported
#: from :mod:`bayespig.table`, which uses these checks; tests/test_table.py checks they agree).
DEFAULT_TAU_MIN = 2.0**-10


def mixture(rng, size, components):
    """``size`` draws from a mixture of ``(weight, sampler(n))`` components, in random order."""
    weights = np.array([w for w, _ in components], dtype=float)
    choice = rng.choice(len(components), size=size, p=weights / weights.sum())
    out = np.empty(size)
    for k, (_, sampler) in enumerate(components):
        out[choice == k] = sampler(int((choice == k).sum()))
    return out


def domain_points(rng, size, tau_max=100.0):
    """Random (a, tau, r_s) over the issue's domain, with shares near every edge.

    a in [0, 1] (also 1e-7..0.1 and 1 - 1e-6..1 - 0.1); tau in [0, tau_max] (also below
    the first tau node, log-uniform from 1e-5, and large), a quarter opaque; r_s in [0, 1]
    with exact 0 and 1.
    """
    a = mixture(
        rng,
        size,
        [
            (0.4, lambda n: rng.uniform(0.0, 1.0, n)),
            (0.2, lambda n: 10.0 ** rng.uniform(-7.0, -1.0, n)),
            (0.15, lambda n: 1.0 - 10.0 ** rng.uniform(-6.0, -1.0, n)),
            (0.25, lambda n: rng.uniform(0.0, 1.0, n) ** 2),
        ],
    )
    tau = mixture(
        rng,
        size,
        [
            (0.3, lambda n: rng.uniform(0.0, tau_max, n)),
            (0.25, lambda n: np.exp(rng.uniform(np.log(1e-5), np.log(tau_max), n))),
            (0.1, lambda n: rng.uniform(0.0, DEFAULT_TAU_MIN, n)),
            (0.1, lambda n: rng.uniform(0.5 * tau_max, tau_max, n)),
            (0.25, lambda n: np.full(n, np.inf)),
        ],
    )
    r_s = mixture(
        rng,
        size,
        [
            (0.7, lambda n: rng.uniform(0.0, 1.0, n)),
            (0.1, lambda n: np.zeros(n)),
            (0.05, lambda n: np.ones(n)),
            (0.15, lambda n: 1.0 - 10.0 ** rng.uniform(-4.0, -1.0, n)),
        ],
    )
    return a, tau, r_s


# ---------------------------------------------------------------------------------------------
# argument checks


def _describe(value):
    """``repr`` of a value (shortened) and its type name, for messages."""
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{text} ({type(value).__name__})"


def _bounds_text(low, high, low_open, high_open):
    if low is not None and high is not None:
        return f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    if low is not None:
        return f"{'>' if low_open else '>='} {low:g}"
    return f"{'<' if high_open else '<='} {high:g}"


def real_array(name, value, *, low=None, high=None, low_open=False, high_open=False, allow_inf=False,
               ndim=None, unit="", _noun="a number"):
    """``value`` as a float array, or a ``TypeError``/``ValueError`` naming ``name``.

    Refused: ``None``, strings, booleans, complex or non-numeric entries, ragged nesting, NaN,
    infinities (unless ``allow_inf``), values outside ``[low, high]`` (ends open when
    ``low_open``/``high_open``) and, when ``ndim`` is given, another number of dimensions.

    Parameters
    ----------
    name : str
        The argument's name, as the caller spells it.
    value : array_like
        The argument.
    low, high : float, optional
        Bounds, in the argument's unit.
    low_open, high_open : bool
        Whether the bound itself is excluded.
    allow_inf : bool
        Accept ``+-inf`` (still subject to the bounds).
    ndim : int, optional
        Required number of dimensions.
    unit : str
        Unit shown after the bounds in messages (e.g. ``"nm"``).

    Returns
    -------
    numpy.ndarray
        The values as ``float``.
    """
    if value is None or isinstance(value, (str, bytes)):
        raise TypeError(f"{name} must be {_noun} or an array of numbers, got {_describe(value)}")
    try:
        arr = np.asarray(value)
    except ValueError:  # ragged nesting
        raise TypeError(f"{name} must be a number or a regular array of numbers, got {_describe(value)}") from None
    if arr.dtype.kind not in "iuf":
        what = {"b": "booleans", "c": "complex numbers", "U": "strings", "S": "strings"}.get(arr.dtype.kind)
        if what is None:
            try:
                arr = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                raise TypeError(
                    f"{name} must be {_noun} or an array of numbers, got {_describe(value)}"
                ) from None
        else:
            raise TypeError(f"{name} must be {_noun} or an array of numbers, not {what}: got {_describe(value)}")
    arr = np.asarray(arr, dtype=float)
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} dimension(s), got shape {arr.shape}")
    if np.isnan(arr).any():
        raise ValueError(f"{name} must not {'be' if arr.ndim == 0 else 'contain'} NaN")
    if not allow_inf and np.isinf(arr).any():
        raise ValueError(f"{name} must be finite, got {_describe(value)}")
    too_low = low is not None and ((arr <= low) if low_open else (arr < low)).any()
    too_high = high is not None and ((arr >= high) if high_open else (arr > high)).any()
    if too_low or too_high:
        bounds = _bounds_text(low, high, low_open, high_open) + (f" {unit}" if unit else "")
        got = f"{float(arr):g}" if arr.ndim == 0 else f"values from {arr.min():g} to {arr.max():g}"
        raise ValueError(f"{name} must be {bounds}, got {got}")
    return arr


def real_scalar(name, value, *, low=None, high=None, low_open=False, high_open=False, allow_inf=False,
                unit=""):
    """``value`` as a ``float``, or a ``TypeError``/``ValueError`` naming ``name``.

    As :func:`real_array` (same keywords), for a single number: a list or an array of more
    than one value is refused.

    Returns
    -------
    float
    """
    if value is None or isinstance(value, (str, bytes, bool, np.bool_, complex)):
        raise TypeError(f"{name} must be a number, got {_describe(value)}")
    if np.ndim(value) != 0:
        raise TypeError(f"{name} must be a single number, got {_describe(value)}")
    arr = real_array(name, value, low=low, high=high, low_open=low_open, high_open=high_open,
                     allow_inf=allow_inf, unit=unit, _noun="a number, not an array")
    return float(arr)


def integer(name, value, *, low=None, high=None):
    """``value`` as an ``int``, or a ``TypeError``/``ValueError`` naming ``name``.

    Python and numpy integers are accepted; booleans, floats (also ``3.0``), strings and
    ``None`` are refused, as are values outside ``[low, high]``.

    Returns
    -------
    int
    """
    if isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be an integer, not a boolean: got {value!r}")
    try:
        number = operator.index(value)
    except TypeError:
        raise TypeError(f"{name} must be an integer, got {_describe(value)}") from None
    if (low is not None and number < low) or (high is not None and number > high):
        raise ValueError(f"{name} must be an integer {_bounds_text(low, high, False, False)}, got {number}")
    return number


def seed(value, name="seed"):
    """A random seed: ``None``, an integer ``>= 0``, a :class:`numpy.random.SeedSequence` or
    :class:`numpy.random.Generator`, else a ``TypeError``/``ValueError`` naming ``name``.

    Booleans are refused (``seed=True`` is a mistake, not seed 1).

    Returns
    -------
    None, int, numpy.random.SeedSequence or numpy.random.Generator
        The seed, unchanged (integers as ``int``).
    """
    if value is None or isinstance(value, (np.random.SeedSequence, np.random.Generator)):
        return value
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be None or an integer >= 0, got {_describe(value)}")
    return integer(name, value, low=0)


def flag(name, value):
    """A bool argument (``True``/``False``, numpy's bools too) as ``bool``, else a ``TypeError``
    naming ``name`` (``1`` or ``"yes"`` are refused: a flag is not a number or a word).

    Returns
    -------
    bool
    """
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {_describe(value)}")
    return bool(value)


def choice(name, value, options):
    """``value`` if it is one of ``options``, else a ``ValueError`` naming ``name`` and listing them.

    Returns
    -------
    object
        ``value``.
    """
    try:
        known = value in options
    except TypeError:  # unhashable value tested against a set/dict
        known = False
    if not known:
        listed = ", ".join(repr(o) for o in options)
        raise ValueError(f"{name} must be one of {listed}, got {_describe(value)}")
    return value


def broadcast(**arrays):
    """The named arrays broadcast to one shape, or a ``ValueError`` naming them and their shapes.

    Parameters
    ----------
    **arrays : array_like
        Argument name -> value (already checked, e.g. by :func:`real_array`).

    Returns
    -------
    list of numpy.ndarray
        The broadcast arrays, in the order given.
    """
    values = [np.asarray(v) for v in arrays.values()]
    try:
        return list(np.broadcast_arrays(*values))
    except ValueError:
        shapes = ", ".join(f"{name} {v.shape}" for name, v in zip(arrays, values))
        raise ValueError(f"the shapes of {shapes} do not broadcast together (numpy broadcasting rules)") from None
