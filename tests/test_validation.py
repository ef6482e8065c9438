"""The shared argument checks of bayespig._validation: one TypeError/ValueError naming the argument."""

import math

import numpy as np
import pytest

from bayespig._validation import (
    DEFAULT_TAU_MIN,
    broadcast,
    choice,
    flag,
    integer,
    real_array,
    real_scalar,
    seed,
)
from bayespig.table import TableSettings


def test_default_tau_min_is_the_tables_first_node():
    # _validation cannot import bayespig.table (the table uses these checks): the copy must agree
    assert DEFAULT_TAU_MIN == TableSettings().tau_nodes[0]


@pytest.mark.parametrize(
    "value, error, message",
    [
        ("1.45", TypeError, "n must be a number, got '1.45' (str)"),
        (None, TypeError, "n must be a number, got None (NoneType)"),
        (True, TypeError, "n must be a number, got True (bool)"),
        (1 + 2j, TypeError, "n must be a number, got (1+2j) (complex)"),
        (np.array([1.5]), TypeError, "n must be a single number, got array("),
        (math.nan, ValueError, "n must not be NaN"),
        (math.inf, ValueError, "n must be finite, got inf (float)"),
        (0.5, ValueError, "n must be >= 1, got 0.5"),
        ([1.5, 1.6], TypeError, "n must be a single number, got [1.5, 1.6] (list)"),
    ],
)
def test_real_scalar_refusals(value, error, message):
    with pytest.raises(error) as excinfo:
        real_scalar("n", value, low=1.0)
    assert str(excinfo.value).startswith(message)


def test_real_scalar_accepts_numbers():
    assert real_scalar("n", 1.45, low=1.0) == 1.45
    assert real_scalar("n", np.float32(2.0), low=1.0) == 2.0
    assert real_scalar("n", 3, low=1.0) == 3.0
    assert real_scalar("tau", math.inf, low=0.0, allow_inf=True) == math.inf


def test_real_array_refusals():
    with pytest.raises(TypeError, match=r"^a must be a number or an array of numbers, got None"):
        real_array("a", None)
    with pytest.raises(TypeError, match=r"^a must be a number or an array of numbers, not booleans"):
        real_array("a", [True, False])
    with pytest.raises(ValueError, match=r"^a must not contain NaN$"):
        real_array("a", [0.1, math.nan])


def test_real_array_bounds_and_shapes():
    with pytest.raises(ValueError, match=r"^a must be in \[0, 1\], got values from -0.1 to 0.5$"):
        real_array("a", [-0.1, 0.5], low=0.0, high=1.0)
    with pytest.raises(ValueError, match=r"^eps must be in \(0, 1\), got 0$"):
        real_array("eps", 0.0, low=0.0, high=1.0, low_open=True, high_open=True)
    with pytest.raises(ValueError, match=r"^wavelength_nm must have 1 dimension\(s\), got shape \(\)$"):
        real_array("wavelength_nm", 500.0, ndim=1)
    with pytest.raises(TypeError, match=r"^a must be a number or a regular array of numbers"):
        real_array("a", [[0.1, 0.2], [0.3]])
    with pytest.raises(TypeError, match=r"^a must be a number or an array of numbers, not strings: got \[0.1, 'x'\]"):
        real_array("a", [0.1, "x"])
    np.testing.assert_array_equal(real_array("a", [0, 1]), [0.0, 1.0])


@pytest.mark.parametrize(
    "value, error, message",
    [
        (2.5, TypeError, "n_points must be an integer, got 2.5 (float)"),
        (3.0, TypeError, "n_points must be an integer, got 3.0 (float)"),
        (True, TypeError, "n_points must be an integer, not a boolean: got True"),
        ("4", TypeError, "n_points must be an integer, got '4' (str)"),
        (None, TypeError, "n_points must be an integer, got None (NoneType)"),
        (0, ValueError, "n_points must be an integer >= 1, got 0"),
    ],
)
def test_integer_refusals(value, error, message):
    with pytest.raises(error) as excinfo:
        integer("n_points", value, low=1)
    assert str(excinfo.value) == message


def test_integer_accepts_numpy_integers():
    assert integer("n_points", np.int64(4), low=1) == 4


@pytest.mark.parametrize(
    "value, error, message",
    [
        (True, TypeError, "seed must be None or an integer >= 0, got True (bool)"),
        (1.0, TypeError, "seed must be None or an integer >= 0, got 1.0 (float)"),
        ("1", TypeError, "seed must be None or an integer >= 0, got '1' (str)"),
        (-1, ValueError, "seed must be an integer >= 0, got -1"),
    ],
)
def test_seed_refusals(value, error, message):
    with pytest.raises(error) as excinfo:
        seed(value)
    assert str(excinfo.value) == message


def test_seed_accepts():
    assert seed(None) is None
    assert seed(np.int32(7)) == 7
    generator = np.random.default_rng(1)
    assert seed(generator) is generator


def test_choice_lists_the_options():
    with pytest.raises(ValueError) as excinfo:
        choice("executor", "x", ("serial", "process"))
    assert str(excinfo.value) == "executor must be one of 'serial', 'process', got 'x' (str)"
    with pytest.raises(ValueError, match="^executor must be one of"):
        choice("executor", [1], {"serial"})  # unhashable


@pytest.mark.parametrize("value", [True, False, np.bool_(True), np.bool_(False)])
def test_flag_accepts_bools_as_bool(value):
    result = flag("warn", value)
    assert type(result) is bool and result == bool(value)


@pytest.mark.parametrize(("value", "shown"), [(1, "1 (int)"), ("yes", "'yes' (str)"), (None, "None (NoneType)"),
                                               (np.array([1, 0]), "array([1, 0]) (ndarray)")])
def test_flag_refuses_numbers_words_and_arrays(value, shown):
    # 1 and "yes" are not flags: truthiness would make flag("progress", "no") mean True
    with pytest.raises(TypeError) as excinfo:
        flag("progress", value)
    assert str(excinfo.value) == f"progress must be True or False, got {shown}"


def test_broadcast_names_the_arguments():
    with pytest.raises(ValueError) as excinfo:
        broadcast(a=np.zeros(3), tau=np.zeros(2))
    assert str(excinfo.value) == (
        "the shapes of a (3,), tau (2,) do not broadcast together (numpy broadcasting rules)"
    )
    a, tau = broadcast(a=np.zeros(3), tau=1.0)
    assert a.shape == tau.shape == (3,)
