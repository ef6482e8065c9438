"""Look-up tables against the direct solver (issue 3, "Must show").

References: the direct adding-doubling solve (:func:`bayespig.predict`, and
:func:`~bayespig.physics.forward.surface_terms` with the substrate added *inside* the
solve, independent of the substrate law eq. 3), energy conservation (a = 0 on a white
substrate reflects everything), monotonicity in a and tau, finite differences, and the
cache's own integrity rules (a damaged or mismatched file is never used).

Tables are built once per session into a temporary cache. The default run tabulates every
built-in instrument isotropically (a few seconds each) and a small two-geometry instrument
with a coarse g axis (the same code path as the full g tables, which take minutes and are
checked in the ``slow`` tests).
"""

import dataclasses
import os
import pickle
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

import bayespig
import bayespig.table as table_module
from bayespig import cli
from bayespig._validation import DEFAULT_TAU_MIN, domain_points
from bayespig.instruments import (
    BUILT_IN_INSTRUMENTS,
    Instrument,
    channel_directions,
    channel_values,
    get_instrument,
    predict,
)
from bayespig.physics.forward import surface_terms
from bayespig.table import (
    CacheError,
    CacheLocationError,
    LookupTable,
    TableSettings,
    build_table,
    load_table,
    read_table,
    save_table,
    table_key,
    table_path,
)

# --- tolerances -----------------------------------------------------------------------------
# Measured values below: the worst case of these tests under OpenBLAS's Haswell, SkylakeX and
# Sandybridge kernels (OPENBLAS_CORETYPE); they agree to two digits on every kernel.
#: Interpolated vs direct values over the whole domain (issue 3: 2e-4 relative, max). Measured
#: 9.4e-5 (multi-angle-45), an interpolation error of the default table (the same on every
#: kernel): below the first tau node, linear towards tau -> 0 (2.75e-5 above it; log2_tau_min
#: = -11 would make it 2.75e-5 for ~6 % build time, reports/benchmarks.md). Margin 2.1x.
INTERPOLATION_REL_TOL = 2e-4
#: The coarse g table of the default run (6 g nodes over 0.6, 12 a nodes, 2 tau nodes per
#: octave; ~1e-2 seen) against the solver: a guard against gross errors, not an accuracy
#: claim (the full g table is checked at 2e-4 in the slow test). Measured 1.0e-2. Margin 2.9x.
COARSE_G_TABLE_REL_TOL = 3e-2
#: Two evaluations of the same cubic in g (the table's stencil and numpy's fit): rounding
#: (measured 5.7e-14).
LOG_IDENTITY_ABS_TOL = 1e-9
#: At grid nodes the substrate law is exact: only the a = 1 node (evaluated at 1 - 1e-9)
#: and the tau -> 0 slice (evaluated at 1e-10) differ from the exact values (issue 3: 1e-6).
#: Measured 3.2e-8 (g table), 1.1e-9 (isotropic); opaque nodes against the direct solver's
#: opaque solution 2.7e-8 (g table), 2.1e-14 (isotropic). Margin 31x.
NODE_REL_TOL = 1e-6
#: Channel values below this are not measurable; they are compared absolutely [1/sr or -].
NEGLIGIBLE_VALUE = 1e-12
#: The same solver asked for a channel alone or among others (zero-weight nodes do not
#: change the quadrature): identical up to rounding (measured 2.0e-15).
SAME_SOLVE_REL_TOL = 1e-11
#: tau = 100 and tau = inf for a >= 0.05: the layer is opaque to far below this (measured
#: 8.7e-11).
OPAQUE_JOIN_REL_TOL = 1e-6
#: Wiggle allowed in monotonicity checks, relative to the value: where the true change
#: between two points is below the interpolation error (saturation), a cubic interpolant
#: may step back by a small fraction of that error (3e-8 seen near tau = 30, a = 0.02).
MONOTONE_SLACK = 1e-6
#: a = 0 on a white substrate, finite tau: SCI reflectance = 1. Measured 1.4e-5 (tau = 3, between
#: tau nodes: the interpolation of the substrate terms; 6e-8 at tau = 1e-4, 1e-11 at tau = 0).
#: Margin 7x.
ENERGY_ABS_TOL = 1e-4
#: a = 0, opaque: SCI reflectance = 1, as the direct solver's discrete-ordinate opaque limit gives
#: (tests/physics/test_reference_values.py, the same tolerance): the table's opaque slice is that
#: solution (issue 18: the doubled slice had lost 1.7e-5). Measured 9.9e-10 (isotropic, n = 1.45),
#: <= 6e-15 (g = 0.5 and 0.9, n = 1.6, the issue's case). Margin 1000x.
OPAQUE_CONSERVATIVE_ENERGY_ABS_TOL = 1e-6
#: Opaque films, table vs direct solver at a in OPAQUE_A (off the a nodes but a = 0): a-node
#: values are the direct solver's own solution (to 2e-11 against a 250-mode sum); what is left is
#: the cubic in v(a) and the direct solver's coarse quadrature of small modes. Measured 2.7e-7
#: (g = 0, every built-in instrument, a = 0.1), 3.1e-7 (g = 0.5) and 3.8e-6 (g = 0.9, a = 0.1;
#: n = 1.6, 32 points). Margin 5x, and 10x inside the issue's 2e-4.
OPAQUE_DIRECT_REL_TOL = 2e-5
#: Analytic derivatives of the interpolant vs its central differences (elasticities). Measured
#: 8.2e-8. Margin 12x.
GRADIENT_INTERPOLANT_TOL = 1e-6
#: Derivatives of the table vs central differences of the direct solver (elasticities
#: d log x / d log p): interpolation error of a derivative is a grid step larger. Measured
#: 3.8e-4 (multi-angle-45). Margin 2.7x.
GRADIENT_SOLVER_TOL = 1e-3
#: Relative step of the central differences.
FD_STEP_INTERPOLANT = 1e-6
FD_STEP_SOLVER = 1e-4
#: Table values vs bayespig.brdf / hemispherical_reflectance for broadcast arguments. Measured
#: 2.4e-6. Margin 85x.
BROADCAST_REL_TOL = INTERPOLATION_REL_TOL

N_RANDOM_POINTS = 2000
#: Opaque films checked against the direct solver: the conservative limit and white pigments'
#: weak absorption (issue 18), and a strong one.
OPAQUE_A = np.array([0.0, 1e-5, 1e-4, 1e-3, 0.1])
#: Distinct g values in the slow full-domain check of a g table (the solver pays per g).
N_G_VALUES_SLOW = 40
BUILT_IN = tuple(BUILT_IN_INSTRUMENTS)

#: A small user-defined instrument for the g-axis and cache tests: one geometry on each
#: side of the specular plane, so azimuthal modes enter with both signs.
SMALL_INSTRUMENT = ("45as15", "45as110")
COARSE_G_SETTINGS = TableSettings(
    g_range=(-0.3, 0.3), n_g=6, n_a=12, log2_tau_min=-4, log2_tau_max=4, per_octave=2
)
#: A quick isotropic table for the cache tests.
SMALL_SETTINGS = TableSettings(n_a=12, log2_tau_min=-4, log2_tau_max=4, per_octave=2)
#: Issue 18's forward-peaked case (g = 0.9, n = 1.6) as g nodes of a table with the default a
#: axis: the SCI channel and two BRDF channels (near specular and far), 32 points per interval as
#: the direct solver takes at g = 0.9 (default_quadrature_points), nodes -0.3, 0.1, 0.5, 0.9,
#: a short tau axis (only the opaque slice is checked).
FORWARD_PEAKED_INSTRUMENT = (BUILT_IN_INSTRUMENTS["8d-sci"][0], "45as15", "45as110")
FORWARD_PEAKED_N = 1.6
FORWARD_PEAKED_G = (0.5, 0.9)
FORWARD_PEAKED_SETTINGS = TableSettings(
    g_range=(-0.3, 0.9), n_g=4, g_axis="uniform", g_stencil=4, n_points=32,
    log2_tau_min=-1, log2_tau_max=2, per_octave=1,
)


# --- helpers --------------------------------------------------------------------------------


def relative_error(values, reference):
    """|values / reference - 1|, absolute where the reference is not measurable."""
    scale = np.maximum(np.abs(reference), NEGLIGIBLE_VALUE)
    return np.abs(values - reference) / scale


def union_instrument():
    """Every built-in channel in one instrument, and each built-in's column slice in it.

    The direct solver costs the same for one channel or for all of them (they are
    zero-weight nodes of one quadrature), so one reference solve serves every instrument.
    """
    channels, columns = [], {}
    for name in BUILT_IN:
        columns[name] = slice(len(channels), len(channels) + len(BUILT_IN_INSTRUMENTS[name]))
        channels.extend(BUILT_IN_INSTRUMENTS[name])
    return Instrument("union", tuple(channels)), columns


def solve_with_substrate_inside(instrument, *, a, tau, g, r_s):
    """Direct solve with the Lambertian substrate added as a layer (not through eq. 3)."""
    theta_in, theta_out, _, _ = channel_directions(instrument)
    terms = surface_terms(
        theta_in, theta_out, a=a, tau=tau, g=g, n=instrument.n, included_substrate=r_s
    )
    return channel_values(instrument, terms, np.zeros_like(r_s))


def solve_at_nodes(instrument, *, a, tau, g, r_s):
    """Direct solve for table nodes: finite films with the substrate inside the solve (doubling),
    opaque ones, which never see it, by the direct solver's discrete-ordinate opaque solution
    (doubling's spurious absorption costs ~1e-5 at a = 0, issue 18)."""
    opaque = np.isinf(tau)
    values = np.empty((a.size, len(instrument)))
    values[~opaque] = solve_with_substrate_inside(
        instrument, a=a[~opaque], tau=tau[~opaque], g=g, r_s=r_s[~opaque]
    )
    values[opaque] = predict(instrument, a=a[opaque], tau=tau[opaque], g=g, r_s=r_s[opaque])
    return values


def node_grid(settings, a_index, tau_index, r_s_values, g=0.0):
    """Flat (a, tau, r_s) over a product of table nodes (plus tau = 0 and inf)."""
    a_values = settings.a_nodes[list(a_index)]
    tau_values = np.concatenate([[0.0], settings.tau_nodes[list(tau_index)], [np.inf]])
    a, tau, r_s = (x.ravel() for x in np.meshgrid(a_values, tau_values, r_s_values, indexing="ij"))
    return a, tau, r_s


def elasticity_error(derivative, reference, value, parameter):
    """|d log x / d log p| mismatch, the form Fisher information uses."""
    return np.abs((derivative - reference) * parameter[..., None]) / np.maximum(
        np.abs(value), NEGLIGIBLE_VALUE
    )


def _tripwire(path):
    """Would run if a cache file were unpickled."""
    Path(path).write_text("unpickled")
    return 0


class _PickleTrap:
    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return _tripwire, (self.path,)


# --- fixtures -------------------------------------------------------------------------------
@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("table-cache")


@pytest.fixture(scope="session")
def tables(cache_dir):
    """The default isotropic table of every built-in instrument, built once into the cache."""
    return {name: load_table(name, cache_dir=cache_dir, progress=False) for name in BUILT_IN}


@pytest.fixture(scope="session")
def reference():
    """Random domain points and their direct-solver values for every built-in channel."""
    rng = np.random.default_rng(20240603)
    a, tau, r_s = domain_points(rng, N_RANDOM_POINTS)
    union, columns = union_instrument()
    values = predict(union, a=a, tau=tau, r_s=r_s)
    return {"a": a, "tau": tau, "r_s": r_s, "values": values, "columns": columns}


@pytest.fixture(scope="session")
def forward_peaked_table(cache_dir):
    """FORWARD_PEAKED_INSTRUMENT tabulated with FORWARD_PEAKED_SETTINGS (~15 s CPU)."""
    table = load_table(list(FORWARD_PEAKED_INSTRUMENT), g="free", n=FORWARD_PEAKED_N,
                       settings=FORWARD_PEAKED_SETTINGS, cache_dir=cache_dir, progress=False)
    # the nodes are those g up to rounding (linspace): the table's values there are its node values
    assert all(np.isclose(table.settings.g_nodes, g, rtol=0, atol=1e-12).any() for g in FORWARD_PEAKED_G)
    return table


@pytest.fixture(scope="session")
def coarse_g_table(cache_dir):
    """A user-defined two-geometry instrument with a coarse g axis (default process pool)."""
    return load_table(
        list(SMALL_INSTRUMENT),
        g="free",
        settings=COARSE_G_SETTINGS,
        cache_dir=cache_dir,
        progress=False,
    )


# --- accuracy -------------------------------------------------------------------------------
@pytest.mark.parametrize("name", BUILT_IN)
def test_interpolation_matches_direct_solver_over_the_domain(tables, reference, name):
    values = tables[name](a=reference["a"], tau=reference["tau"], r_s=reference["r_s"])
    expected = reference["values"][:, reference["columns"][name]]
    error = relative_error(values, expected)
    worst = np.unravel_index(error.argmax(), error.shape)[0]
    assert error.max() <= INTERPOLATION_REL_TOL, (
        f"{name}: max relative error {error.max():.2e} at a={reference['a'][worst]!r}, "
        f"tau={reference['tau'][worst]!r}, r_s={reference['r_s'][worst]!r}"
    )


def test_one_reference_solve_equals_per_instrument_solves(reference):
    """The shared reference solve gives each instrument what its own solve gives."""
    rows = slice(0, 12)
    for name in BUILT_IN:
        alone = predict(
            name, a=reference["a"][rows], tau=reference["tau"][rows], r_s=reference["r_s"][rows]
        )
        shared = reference["values"][rows, reference["columns"][name]]
        np.testing.assert_allclose(alone, shared, rtol=SAME_SOLVE_REL_TOL, atol=0)


@pytest.mark.parametrize("name", BUILT_IN)
def test_opaque_limit_joins_large_finite_tau(tables, name):
    table = tables[name]
    a = np.geomspace(0.05, 0.97, 23)  # off the a nodes
    for r_s in (0.0, 1.0):
        thick = table(a=a, tau=100.0, r_s=r_s)
        opaque = table(a=a, tau=np.inf, r_s=r_s)
        np.testing.assert_allclose(thick, opaque, rtol=OPAQUE_JOIN_REL_TOL, atol=0)
    # the opaque value does not see the substrate at all
    np.testing.assert_array_equal(table(a=a, tau=np.inf, r_s=0.0), table(a=a, tau=np.inf, r_s=1.0))


@pytest.mark.parametrize("name", BUILT_IN)
def test_monotone_towards_the_opaque_limit_and_in_a(tables, name):
    """Over black, more pigment reflects more, and more absorption less (a -> 0 included)."""
    table = tables[name]
    a = np.concatenate([[0.0], np.geomspace(1e-7, 0.3, 30)])
    tau = np.concatenate([np.geomspace(0.01, 100.0, 40), [np.inf]])
    values = table(a=a[:, None], tau=tau[None, :], r_s=0.0)  # (a, tau, channel)
    assert np.isfinite(values).all() and (values > 0).all()
    slack = MONOTONE_SLACK * values
    assert (np.diff(values, axis=1) >= -slack[:, 1:]).all(), (
        "not increasing with tau towards the opaque limit"
    )
    assert (np.diff(values, axis=0) <= slack[1:]).all(), "not decreasing with a"
    # the gap to the opaque value closes faster the more the pigment absorbs
    gap = values[:, -1] - values[:, -2]
    assert (np.diff(gap, axis=0) <= slack[1:, -1]).all()
    assert (gap >= -slack[:, -1]).all() and (
        gap[:3] > 0
    ).all()  # a -> 0 at tau = 100 is not yet opaque


@pytest.mark.parametrize("tau", [0.0, 1e-4, 0.3, 3.0, 60.0])
def test_white_non_absorbing_film_reflects_everything(tables, tau):
    """Energy conservation: a = 0 over r_s = 1, SCI = 1 at any thickness."""
    value = tables["8d-sci"](a=0.0, tau=tau, r_s=1.0)
    np.testing.assert_allclose(value, 1.0, atol=ENERGY_ABS_TOL, rtol=0)


def test_opaque_non_absorbing_film_reflects_everything(tables, forward_peaked_table):
    """Issue 18: a = 0, tau = inf reflects everything (SCI = 1), forward-peaked scattering too."""
    for r_s in (0.0, 1.0):  # an opaque film does not see its substrate
        value = tables["8d-sci"](a=0.0, tau=np.inf, r_s=r_s)
        np.testing.assert_allclose(value, 1.0, atol=OPAQUE_CONSERVATIVE_ENERGY_ABS_TOL, rtol=0)
        value = forward_peaked_table(a=0.0, tau=np.inf, g=np.array(FORWARD_PEAKED_G), r_s=r_s)[:, 0]
        np.testing.assert_allclose(value, 1.0, atol=OPAQUE_CONSERVATIVE_ENERGY_ABS_TOL, rtol=0)


@pytest.mark.parametrize("name", BUILT_IN)
def test_opaque_films_match_the_direct_solver(tables, name):
    """Issue 18: the opaque slice is the direct solver's opaque solution, weak absorption included."""
    values = tables[name](a=OPAQUE_A, tau=np.inf, r_s=0.0)
    expected = predict(name, a=OPAQUE_A, tau=np.inf, r_s=0.0)
    error = relative_error(values, expected).max(axis=1)
    assert error.max() <= OPAQUE_DIRECT_REL_TOL, f"{name}: relative error {error} at a = {OPAQUE_A}"


@pytest.mark.parametrize("g", FORWARD_PEAKED_G)
def test_opaque_forward_peaked_films_match_the_direct_solver(forward_peaked_table, g):
    """Issue 18's case (g = 0.9, n = 1.6): table and direct solver on the same quadrature."""
    instrument = forward_peaked_table.instrument
    theta_in, theta_out, _, _ = channel_directions(instrument)
    terms = surface_terms(theta_in, theta_out, a=OPAQUE_A, tau=np.full(OPAQUE_A.size, np.inf), g=g,
                          n=instrument.n, n_points=FORWARD_PEAKED_SETTINGS.n_points)
    expected = channel_values(instrument, terms, np.zeros(OPAQUE_A.size))
    values = forward_peaked_table(a=OPAQUE_A, tau=np.inf, g=g, r_s=0.0)
    error = relative_error(values, expected).max(axis=1)
    assert error.max() <= OPAQUE_DIRECT_REL_TOL, f"g = {g}: relative error {error} at a = {OPAQUE_A}"


def test_grid_nodes_are_exact_for_any_substrate(tables):
    """At (a, tau) nodes, every r_s equals a solve with the substrate inside the layer stack."""
    settings = TableSettings()
    a, tau, r_s = node_grid(
        settings,
        a_index=(0, 1, 5, 17, 30, settings.n_a - 1),
        tau_index=(0, 13, 40, len(settings.tau_nodes) - 1),
        r_s_values=np.array([0.0, 0.3, 0.9, 1.0]),
    )
    for name in BUILT_IN:
        direct = solve_at_nodes(get_instrument(name), a=a, tau=tau, g=0.0, r_s=r_s)
        values = tables[name](a=a, tau=tau, r_s=r_s)
        error = relative_error(values, direct)
        assert error.max() <= NODE_REL_TOL, f"{name}: {error.max():.2e}"


# --- the g axis -----------------------------------------------------------------------------
def test_g_table_nodes_are_exact(coarse_g_table):
    settings = COARSE_G_SETTINGS
    instrument = get_instrument(list(SMALL_INSTRUMENT))
    a, tau, r_s = node_grid(
        settings,
        a_index=(0, 3, 7, settings.n_a - 1),
        tau_index=(0, 9, 16),
        r_s_values=np.array([0.0, 0.6, 1.0]),
    )
    for g in settings.g_nodes[[0, 2, -1]]:  # both ends and an interior node
        direct = solve_at_nodes(instrument, a=a, tau=tau, g=float(g), r_s=r_s)
        error = relative_error(coarse_g_table(a=a, tau=tau, g=g, r_s=r_s), direct)
        assert error.max() <= NODE_REL_TOL, f"g = {g}: {error.max():.2e}"


def test_g_table_interpolates_log_values_by_the_quintic_through_the_g_nodes(coarse_g_table):
    """Over black, log(x / ((1 - a)(1 - exp(-tau)))) is interpolated by the quintic in
    w = atanh(g) through the six g nodes, whatever a and tau: a rounding-level check of
    the g axis, its transform and its stencil."""
    rng = np.random.default_rng(6)
    a, tau, _ = domain_points(rng, 40, tau_max=16.0)
    a = np.minimum(a, 0.99)
    g_nodes = COARSE_G_SETTINGS.g_nodes
    assert COARSE_G_SETTINGS.g_axis == "atanh" and COARSE_G_SETTINGS.g_stencil == g_nodes.size == 6
    np.testing.assert_allclose(np.diff(np.arctanh(g_nodes)), np.diff(np.arctanh(g_nodes))[0])
    at_nodes = np.log(
        coarse_g_table(a=a, tau=tau, g=g_nodes[:, None], r_s=0.0)
    )  # (g, point, channel)
    for g in rng.uniform(*COARSE_G_SETTINGS.g_range, 5):
        expected = np.empty(at_nodes.shape[1:])
        for index in np.ndindex(expected.shape):
            quintic = np.polynomial.Polynomial.fit(
                np.arctanh(g_nodes), at_nodes[(slice(None),) + index], 5
            )
            expected[index] = quintic(np.arctanh(g))
        np.testing.assert_allclose(
            np.log(coarse_g_table(a=a, tau=tau, g=g, r_s=0.0)),
            expected,
            rtol=0,
            atol=LOG_IDENTITY_ABS_TOL,
        )


def test_g_table_interpolates_between_g_nodes(coarse_g_table):
    rng = np.random.default_rng(7)
    a, tau, r_s = domain_points(rng, 60, tau_max=16.0)
    g = np.repeat(rng.uniform(*COARSE_G_SETTINGS.g_range, 6), 10)
    error = relative_error(
        coarse_g_table(a=a, tau=tau, g=g, r_s=r_s),
        predict(list(SMALL_INSTRUMENT), a=a, tau=tau, g=g, r_s=r_s),
    )
    assert error.max() <= COARSE_G_TABLE_REL_TOL


def test_isotropic_slice_of_a_g_table_is_the_isotropic_table(coarse_g_table):
    """g = 0 is not a node of the coarse g axis: the g table interpolates to the isotropic one."""
    isotropic = build_table(
        list(SMALL_INSTRUMENT), dataclasses.replace(COARSE_G_SETTINGS, g_range=None), progress=False
    )
    rng = np.random.default_rng(8)
    a, tau, r_s = domain_points(rng, 200, tau_max=16.0)
    error = relative_error(
        coarse_g_table(a=a, tau=tau, g=0.0, r_s=r_s), isotropic(a=a, tau=tau, r_s=r_s)
    )
    assert error.max() <= COARSE_G_TABLE_REL_TOL


def test_g_table_build_is_deterministic_across_executors(coarse_g_table):
    """Process pool (default) and threads give bit-identical arrays."""
    with ThreadPoolExecutor(max_workers=2) as executor:
        again = build_table(
            list(SMALL_INSTRUMENT), COARSE_G_SETTINGS, executor=executor, progress=False
        )
    assert again.key == coarse_g_table.key
    for key, array in coarse_g_table.arrays.items():
        assert array.tobytes() == again.arrays[key].tobytes(), key


# --- derivatives ----------------------------------------------------------------------------
def interior_points(rng, size):
    a = rng.uniform(0.02, 0.9, size)
    tau = np.exp(rng.uniform(np.log(0.05), np.log(30.0), size))
    tau[: size // 6] = rng.uniform(0.1, 0.9, size // 6) * DEFAULT_TAU_MIN  # linear blend to tau = 0
    tau[-(size // 6) :] = np.inf
    r_s = rng.uniform(0.0, 1.0, size)
    return a, tau, r_s


def central_difference(function, parameters, name, step):
    h = step * parameters[name]
    up = dict(parameters, **{name: parameters[name] + h})
    down = dict(parameters, **{name: parameters[name] - h})
    return (function(**up) - function(**down)) / (2.0 * h[..., None])


@pytest.mark.parametrize("name", ["multi-angle-45", "8d-sci"])
def test_gradient_matches_differences_of_the_interpolant(tables, name):
    table = tables[name]
    rng = np.random.default_rng(11)
    a, tau, r_s = interior_points(rng, 36)
    value, d_a, d_tau, d_g = table.evaluate(a=a, tau=tau, r_s=r_s, gradient=True)
    np.testing.assert_array_equal(value, table(a=a, tau=tau, r_s=r_s))
    finite = np.isfinite(tau)
    params = {"a": a, "tau": np.where(finite, tau, 1.0), "r_s": r_s}
    fd_a = central_difference(
        lambda **p: table(a=p["a"], tau=tau, r_s=p["r_s"]), params, "a", FD_STEP_INTERPOLANT
    )
    assert elasticity_error(d_a, fd_a, value, a).max() <= GRADIENT_INTERPOLANT_TOL
    fd_tau = central_difference(
        table, {"a": a[finite], "tau": tau[finite], "r_s": r_s[finite]}, "tau", FD_STEP_INTERPOLANT
    )
    assert (
        elasticity_error(d_tau[finite], fd_tau, value[finite], tau[finite]).max()
        <= GRADIENT_INTERPOLANT_TOL
    )
    np.testing.assert_array_equal(d_tau[~finite], 0.0)  # opaque films do not depend on tau
    np.testing.assert_array_equal(d_g, np.zeros_like(d_g))  # no g axis: g = 0 throughout


@pytest.mark.parametrize("name", ["multi-angle-45", "8d-sce"])
def test_gradient_matches_differences_of_the_direct_solver(tables, name):
    table = tables[name]
    rng = np.random.default_rng(12)
    a, tau, r_s = interior_points(rng, 18)
    value, d_a, d_tau, _ = table.evaluate(a=a, tau=tau, r_s=r_s, gradient=True)

    def solver(**parameters):
        return predict(name, **parameters)

    fd_a = central_difference(solver, {"a": a, "tau": tau, "r_s": r_s}, "a", FD_STEP_SOLVER)
    assert elasticity_error(d_a, fd_a, value, a).max() <= GRADIENT_SOLVER_TOL
    finite = np.isfinite(tau)
    fd_tau = central_difference(
        solver, {"a": a[finite], "tau": tau[finite], "r_s": r_s[finite]}, "tau", FD_STEP_SOLVER
    )
    assert (
        elasticity_error(d_tau[finite], fd_tau, value[finite], tau[finite]).max()
        <= GRADIENT_SOLVER_TOL
    )


def test_g_gradient_matches_differences_of_the_interpolant(coarse_g_table):
    rng = np.random.default_rng(13)
    a, tau, r_s = interior_points(rng, 24)
    tau = np.minimum(tau, 15.0)
    g = rng.uniform(-0.25, 0.25, a.size)
    value, d_a, _, d_g = coarse_g_table.evaluate(a=a, tau=tau, g=g, r_s=r_s, gradient=True)
    h = FD_STEP_INTERPOLANT
    fd_g = (
        coarse_g_table(a=a, tau=tau, g=g + h, r_s=r_s)
        - coarse_g_table(a=a, tau=tau, g=g - h, r_s=r_s)
    ) / (2 * h)
    # g is not a scale parameter: compare d log x / dg directly
    assert (np.abs(d_g - fd_g) / np.abs(value)).max() <= GRADIENT_INTERPOLANT_TOL
    fd_a = central_difference(
        lambda **p: coarse_g_table(a=p["a"], tau=tau, g=g, r_s=r_s),
        {"a": a},
        "a",
        FD_STEP_INTERPOLANT,
    )
    assert elasticity_error(d_a, fd_a, value, a).max() <= GRADIENT_INTERPOLANT_TOL


# --- broadcasting and the other forward functions ---------------------------------------------
def test_broadcasting_like_brdf(tables):
    table = tables["multi-angle-45"]
    a = np.array([[0.01], [0.2], [0.7]])  # (3, 1)
    tau = np.array([0.3, 2.0, 9.0, np.inf])  # (4,)
    r_s = np.array([[[0.0]], [[0.8]]])  # (2, 1, 1)
    values = table(a=a, tau=tau, r_s=r_s)
    assert values.shape == (2, 3, 4, len(table.channels))
    assert table(a=0.1, tau=1.0).shape == (len(table.channels),)
    for part in table.evaluate(a=a, tau=tau, r_s=r_s, gradient=True):
        assert part.shape == values.shape
    # the same numbers, one point at a time
    for index in np.ndindex(values.shape[:-1]):
        single = table(a=a[index[1], 0], tau=tau[index[2]], r_s=r_s[index[0], 0, 0])
        np.testing.assert_array_equal(values[index], single)
    # and what bayespig.brdf gives for the same broadcast arguments, channel by channel
    for k, ch in enumerate(table.channels):
        f = bayespig.brdf(ch.theta_i, ch.theta_o, ch.delta_phi, a=a, tau=tau, r_s=r_s)
        assert f.shape == values.shape[:-1]
        np.testing.assert_allclose(values[..., k], f, rtol=BROADCAST_REL_TOL)


def test_hemispherical_and_45_0_channels_match_the_forward_functions(tables):
    a = np.array([0.003, 0.1, 0.6])[:, None]
    tau = np.array([0.02, 1.5, np.inf])
    r_s = 0.5
    for name, specular in (("8d-sci", "included"), ("8d-sce", "excluded")):
        expected = bayespig.hemispherical_reflectance(8.0, a=a, tau=tau, r_s=r_s, specular=specular)
        np.testing.assert_allclose(
            tables[name](a=a, tau=tau, r_s=r_s)[..., 0], expected, rtol=BROADCAST_REL_TOL
        )
    expected = np.pi * bayespig.brdf(45.0, 0.0, 180.0, a=a, tau=tau, r_s=r_s)
    np.testing.assert_allclose(
        tables["45-0"](a=a, tau=tau, r_s=r_s)[..., 0], expected, rtol=BROADCAST_REL_TOL
    )


# --- bad input ------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "arguments, message",
    [
        ({"a": 0.1, "tau": 1.0, "g": 0.2}, r"isotropic \(g = 0\)"),
        ({"a": 0.1, "tau": 200.0}, r"finite tau must be <= 128"),
        ({"a": -0.1, "tau": 1.0}, r"a \(relative absorption\) must lie in \[0, 1\]"),
        ({"a": 1.1, "tau": 1.0}, r"a \(relative absorption\) must lie in \[0, 1\]"),
        ({"a": 0.1, "tau": -1.0}, r"tau \(optical thickness\) must be >= 0"),
        ({"a": 0.1, "tau": 1.0, "r_s": 1.5}, r"r_s \(substrate albedo\) must lie in \[0, 1\]"),
        ({"a": np.nan, "tau": 1.0}, r"^a must not be NaN"),
        ({"a": 0.1, "tau": np.nan}, r"^tau must not be NaN"),
        ({"a": 0.1, "tau": 1.0, "g": np.nan}, r"^g must not be NaN"),
        ({"a": 0.1, "tau": 1.0, "r_s": [0.2, np.nan]}, r"^r_s must not be NaN"),
    ],
)
def test_bad_arguments_name_the_argument(tables, arguments, message):
    table = tables["multi-angle-45"]
    with pytest.raises(ValueError, match=message):
        table(**arguments)
    with pytest.raises(ValueError, match=message):
        table.evaluate(**arguments, gradient=True)


def test_g_outside_the_tables_range(coarse_g_table):
    with pytest.raises(ValueError, match=r"g must lie in the table's range \[-0.3, 0.3\]"):
        coarse_g_table(a=0.1, tau=1.0, g=0.5)


def test_bad_instrument_and_options(cache_dir):
    with pytest.raises(
        ValueError,
        match="unknown instrument 'no-such'; built-in instruments: " + ", ".join(BUILT_IN),
    ):
        load_table("no-such", cache_dir=cache_dir)
    with pytest.raises(ValueError, match="^g must be one of 'isotropic', 'free', got 'anisotropic' \\(str\\)$"):
        load_table("8d-sci", g="anisotropic", cache_dir=cache_dir)
    with pytest.raises(
        ValueError, match=r"n \(binder refractive index\) must be a finite number >= 1"
    ):
        load_table("8d-sci", n=0.9, cache_dir=cache_dir)
    assert not list(cache_dir.glob("*.tmp")), "a failed call left a partial file"


# --- cache ----------------------------------------------------------------------------------
@pytest.fixture
def small_cache(tmp_path):
    """A cache holding one small isotropic table; returns (table, path)."""
    table = load_table(
        list(SMALL_INSTRUMENT), settings=SMALL_SETTINGS, cache_dir=tmp_path, progress=False
    )
    path = table_path(table.key, tmp_path)
    assert path.is_file()
    return table, path


def assert_same_arrays(first, second):
    assert first.keys() == second.keys()
    for key in first:
        assert first[key].dtype == second[key].dtype
        assert first[key].tobytes() == second[key].tobytes(), key


def test_cache_file_loads_back_identical(small_cache):
    table, path = small_cache
    again = read_table(path, list(SMALL_INSTRUMENT), SMALL_SETTINGS)
    assert isinstance(again, LookupTable) and again.key == table.key
    assert_same_arrays(table.arrays, again.arrays)
    assert not list(path.parent.glob("*.tmp"))  # atomic write left nothing behind
    cached = load_table(
        list(SMALL_INSTRUMENT), settings=SMALL_SETTINGS, cache_dir=path.parent, progress=False
    )
    assert_same_arrays(table.arrays, cached.arrays)


def test_the_checksum_is_of_the_tables_contents(small_cache):
    table, path = small_cache
    with np.load(path, allow_pickle=False) as data:
        stored = str(data["__checksum__"])
    loaded = read_table(path, list(SMALL_INSTRUMENT), SMALL_SETTINGS)
    # built, cached and read back: one checksum (the read one is the file's, verified)
    assert table.checksum == stored == loaded.checksum
    # a fresh build has the same numbers, so the same checksum
    assert build_table(list(SMALL_INSTRUMENT), SMALL_SETTINGS, progress=False).checksum == stored
    # one number changed in the last bit: another checksum, the key unchanged
    arrays = {k: v.copy() for k, v in table.arrays.items()}
    arrays["log_q"].flat[7] = np.nextafter(arrays["log_q"].flat[7], np.inf)
    other = LookupTable(table.instrument, table.settings, arrays, table.key)
    assert other.checksum != stored and other.key == table.key


def test_build_is_deterministic(small_cache):
    table, _ = small_cache
    assert_same_arrays(
        table.arrays, build_table(list(SMALL_INSTRUMENT), SMALL_SETTINGS, progress=False).arrays
    )


def _truncate(path):
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _flip_bytes(path):
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 16] = bytes(b ^ 0xFF for b in data[middle : middle + 16])
    path.write_bytes(bytes(data))


def _tamper_keeping_checksum(path):
    """Change one number and rewrite a well-formed file with the old key and checksum."""
    with np.load(path, allow_pickle=False) as data:
        payload = {k: data[k] for k in data.files}
    payload["log_q"] = payload["log_q"].copy()
    payload["log_q"].flat[7] += 1e-9
    with open(path, "wb") as handle:
        np.savez(handle, **payload)


@pytest.mark.parametrize(
    "damage, message",
    [
        (_truncate, "is unreadable"),
        (_flip_bytes, "is unreadable|is corrupt"),
        (_tamper_keeping_checksum, r"is corrupt \(checksum mismatch\)"),
    ],
)
def test_corrupt_cache_file_is_detected_and_rebuilt(small_cache, damage, message):
    table, path = small_cache
    damage(path)
    with pytest.raises(CacheError, match=message):
        read_table(path, list(SMALL_INSTRUMENT), SMALL_SETTINGS)
    with pytest.warns(
        RuntimeWarning, match=f"cached table .*({message}).*; rebuilding it"
    ) as record:
        rebuilt = load_table(
            list(SMALL_INSTRUMENT), settings=SMALL_SETTINGS, cache_dir=path.parent, progress=False
        )
    assert len(record) == 1 and "\n" not in str(record[0].message)
    assert_same_arrays(table.arrays, rebuilt.arrays)
    # the rebuilt file is whole again: loading it warns no more (warnings are errors here)
    assert_same_arrays(
        table.arrays, read_table(path, list(SMALL_INSTRUMENT), SMALL_SETTINGS).arrays
    )
    load_table(
        list(SMALL_INSTRUMENT), settings=SMALL_SETTINGS, cache_dir=path.parent, progress=False
    )


def test_cache_built_with_other_settings_is_detected(small_cache):
    table, path = small_cache
    other_settings = dataclasses.replace(SMALL_SETTINGS, n_a=13)
    other = build_table(list(SMALL_INSTRUMENT), other_settings, progress=False)
    save_table(other, path)  # a well-formed file under the wrong name
    with pytest.raises(CacheError, match="was built with other settings"):
        read_table(path, list(SMALL_INSTRUMENT), SMALL_SETTINGS)
    with pytest.warns(
        RuntimeWarning, match="was built with other settings.*; rebuilding it"
    ) as record:
        rebuilt = load_table(
            list(SMALL_INSTRUMENT), settings=SMALL_SETTINGS, cache_dir=path.parent, progress=False
        )
    assert len(record) == 1
    assert_same_arrays(table.arrays, rebuilt.arrays)


def test_cache_files_are_never_unpickled(small_cache, tmp_path):
    table, path = small_cache
    marker = tmp_path / "marker"
    payload = dict(
        table.arrays,
        __key__=np.array(table.key),
        log_q=np.array([_PickleTrap(marker)], dtype=object),
    )
    with open(path, "wb") as handle:
        np.savez(handle, **payload)
    with pytest.raises(CacheError, match="is unreadable"):
        read_table(path, list(SMALL_INSTRUMENT), SMALL_SETTINGS)
    assert not marker.exists()
    # the trap does fire when unpickled: the check above can fail
    pickle.loads(pickle.dumps(_PickleTrap(marker)))
    assert marker.exists()


def test_key_covers_every_setting_that_changes_the_numbers():
    instrument = get_instrument(list(SMALL_INSTRUMENT))
    base = table_key(instrument, SMALL_SETTINGS)
    assert base == table_key(
        get_instrument(list(SMALL_INSTRUMENT)), TableSettings(**dataclasses.asdict(SMALL_SETTINGS))
    )
    changed = {
        "n_a": 13,
        "a_stretch": 20.0,
        "log2_tau_min": -5,
        "log2_tau_max": 5,
        "per_octave": 3,
        "g_range": (-0.3, 0.3),
        "n_g": 5,
        "g_axis": "uniform",
        "g_stencil": 4,
        "n_points": 12,
        "start_thickness": 2.0**-20,
    }
    assert set(changed) == {field.name for field in dataclasses.fields(TableSettings)}
    keys = {
        table_key(instrument, dataclasses.replace(SMALL_SETTINGS, **{k: v}))
        for k, v in changed.items()
    }
    keys.add(table_key(dataclasses.replace(instrument, n=1.5), SMALL_SETTINGS))
    keys.add(table_key(get_instrument(["45as15", "45as25"]), SMALL_SETTINGS))
    keys.add(table_key(get_instrument(list(reversed(SMALL_INSTRUMENT))), SMALL_SETTINGS))
    assert base not in keys and len(keys) == len(changed) + 3


def test_cache_directory_follows_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("BAYESPIG_CACHE", str(tmp_path / "moved"))
    table = load_table(list(SMALL_INSTRUMENT), settings=SMALL_SETTINGS, progress=False)
    assert table_path(table.key).parent == tmp_path / "moved"
    assert table_path(table.key).is_file()


def test_cache_folder_that_is_a_file_is_named_before_any_build(tmp_path, monkeypatch):
    a_file = tmp_path / "afile"
    a_file.write_text("")
    monkeypatch.setattr(table_module, "build_table", _no_build)
    monkeypatch.setenv("BAYESPIG_CACHE", str(a_file))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    with pytest.raises(CacheLocationError) as excinfo:
        load_table(list(SMALL_INSTRUMENT), settings=SMALL_SETTINGS, progress=False)
    assert str(excinfo.value) == (
        f"the table cache folder '{a_file}' (set by BAYESPIG_CACHE) is a file, not a folder: "
        f"set BAYESPIG_CACHE to a folder you can write, or unset it to use '{tmp_path / 'xdg' / 'bayespig'}'"
    )
    monkeypatch.setenv("BAYESPIG_CACHE", str(a_file / "sub"))
    with pytest.raises(CacheLocationError, match=r"^the table cache folder '.*afile/sub' \(set by "
                       r"BAYESPIG_CACHE\) cannot be created \(Not a directory\): set BAYESPIG_CACHE"):
        load_table(list(SMALL_INSTRUMENT), settings=SMALL_SETTINGS, progress=False)
    with pytest.raises(CacheLocationError) as excinfo:
        load_table(list(SMALL_INSTRUMENT), settings=SMALL_SETTINGS, progress=False, cache_dir=a_file)
    assert str(excinfo.value) == (
        f"the table cache folder '{a_file}' (given as cache_dir) is a file, not a folder: "
        "pass a folder as cache_dir"
    )
    assert isinstance(excinfo.value, OSError)  # bayespig.cli reports OSError in one line


def _no_build(*args, **kwargs):
    raise AssertionError("a table was built")


def test_table_file_name_taken_by_a_folder(tmp_path, monkeypatch):
    key = table_key(get_instrument(list(SMALL_INSTRUMENT)), SMALL_SETTINGS)
    folder = table_path(key, tmp_path)
    folder.mkdir()
    monkeypatch.setattr(table_module, "build_table", _no_build)
    with pytest.raises(CacheLocationError) as excinfo:
        load_table(list(SMALL_INSTRUMENT), settings=SMALL_SETTINGS, progress=False, cache_dir=tmp_path)
    assert str(excinfo.value) == (
        f"the cached table '{folder}' is a folder, not a file: remove or rename that folder "
        "(bayespig writes the table there)"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == [folder.name]  # no temporary left


def test_unwritable_cache_folder_is_said_before_the_build(tmp_path, monkeypatch):
    # (as root every folder is writable, so the permission test is simulated)
    monkeypatch.setattr(table_module.os, "access", lambda path, mode: False)
    monkeypatch.setattr(table_module, "build_table", _no_build)
    with pytest.raises(CacheLocationError) as excinfo:
        load_table(list(SMALL_INSTRUMENT), settings=SMALL_SETTINGS, progress=False, cache_dir=tmp_path)
    assert str(excinfo.value) == (
        "table 45as15+45as110 is not cached and cannot be built: the table cache folder "
        f"'{tmp_path}' (given as cache_dir) is not writable: pass a folder as cache_dir"
    )


def test_without_file_locking_tables_are_built_unlocked(tmp_path, monkeypatch):
    # neither fcntl (POSIX) nor msvcrt (Windows): the build proceeds as before, without a lock
    monkeypatch.setattr(table_module, "fcntl", None)
    monkeypatch.setattr(table_module, "msvcrt", None)
    table = load_table(list(SMALL_INSTRUMENT), settings=SMALL_SETTINGS, cache_dir=tmp_path, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"table-{table.key}.npz"]


#: Seconds a test waits for a child process's next line (generous: 2 shared, loaded cores).
CHILD_LINE_TIMEOUT = 120.0

_BUILDER = """
import pathlib, sys, time
import bayespig.table as table_module
from bayespig.table import TableSettings, load_table

cache, marker, release = map(pathlib.Path, sys.argv[1:4])
real_build = table_module.build_table

def counted_build(*args, **kwargs):
    with open(marker, "a") as handle:
        handle.write("built\\n")
    print("building", flush=True)
    deadline = time.monotonic() + 120
    while not release.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    return real_build(*args, **kwargs)

table_module.build_table = counted_build
settings = TableSettings(n_a=12, log2_tau_min=-4, log2_tau_max=4, per_octave=2)
table = load_table(["45as15", "45as110"], settings=settings, cache_dir=cache, progress=True)
print("loaded", table.key, flush=True)
"""


def _read_line(stream):
    """The child's next line, within CHILD_LINE_TIMEOUT (a reader thread keeps the test from hanging)."""
    pool = ThreadPoolExecutor(1)
    try:
        return pool.submit(stream.readline).result(timeout=CHILD_LINE_TIMEOUT).decode()
    finally:
        pool.shutdown(wait=False)  # on a timeout the reader ends when the child is killed


def test_concurrent_builders_build_once(tmp_path):
    cache, marker, release = tmp_path / "cache", tmp_path / "builds.log", tmp_path / "release"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    command = [sys.executable, "-c", _BUILDER, str(cache), str(marker), str(release)]
    first = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    second = None
    try:
        assert _read_line(first.stdout) == "building\n"
        second = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
        waiting = _read_line(second.stderr)
        key = table_key(get_instrument(list(SMALL_INSTRUMENT)), SMALL_SETTINGS)
        assert waiting == (
            f"bayespig: waiting for another process building table 45as15+45as110 (table-{key}.npz)\n"
        )
        release.touch()  # the first builder may finish now
        outputs = [p.communicate(timeout=CHILD_LINE_TIMEOUT) for p in (first, second)]
        assert [p.returncode for p in (first, second)] == [0, 0], outputs
    finally:
        for process in (first, second):
            if process is not None:
                process.kill()
                process.wait()
    assert marker.read_text() == "built\n", "the table was built more than once"
    assert outputs[0][0].decode() == f"loaded {key}\n" == outputs[1][0].decode()
    assert sorted(p.name for p in cache.iterdir()) == [f".table-{key}.npz.lock", f"table-{key}.npz"]


# --- command line ---------------------------------------------------------------------------
def test_cli_table_build_and_info(tables, cache_dir, monkeypatch, capsys):
    monkeypatch.setenv("BAYESPIG_CACHE", str(cache_dir))
    assert cli.main(["table", "build", "--instrument", "8d-sci"]) == 0  # cached: loads it
    out = capsys.readouterr().out
    assert tables["8d-sci"].key in out and str(table_path(tables["8d-sci"].key)) in out
    assert cli.main(["table", "info"]) == 0
    out = capsys.readouterr().out
    assert f"cache directory: {cache_dir}" in out
    for name in BUILT_IN:
        line = next(line for line in out.splitlines() if line.startswith(tables[name].key))
        assert f"  {name}  " in line and "MB" in line
    assert "isotropic; a: 48 nodes" in out
    assert cli.main(["table", "info", "--instrument", "45-0"]) == 0
    out = capsys.readouterr().out
    assert tables["45-0"].key in out and tables["8d-sci"].key not in out
    assert "1 cached table for instrument '45-0'" in out


def test_cli_table_info_reports_a_damaged_file(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("BAYESPIG_CACHE", str(tmp_path))
    (tmp_path / "table-0123.npz").write_bytes(b"not a table")
    assert cli.main(["table", "info"]) == 0
    assert "table-0123.npz" in capsys.readouterr().out.split("unreadable")[0]


def test_cli_errors_are_one_line_with_status_2(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("BAYESPIG_CACHE", str(tmp_path))
    assert cli.main(["table", "build", "--instrument", "no-such"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bayespig: error: unknown instrument 'no-such'") and "8d-sci" in err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert cli.main(["table", "build", "--instrument", "8d-sci", "--n", "0.5"]) == 2
    assert "n (binder refractive index)" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())  # nothing written


# --- slow: full g axis ----------------------------------------------------------------------
@pytest.mark.slow
def test_free_g_table_over_the_full_domain(cache_dir):
    """The default g table (g in [-0.5, 0.8]) against the direct solver at 2,000 points."""
    table = load_table("multi-angle-45", g="free", cache_dir=cache_dir, progress=False)
    rng = np.random.default_rng(20240604)
    a, tau, r_s = domain_points(rng, N_RANDOM_POINTS)
    g_values = rng.uniform(*table.settings.g_range, N_G_VALUES_SLOW)
    g_values[:2] = table.settings.g_range  # the edges of the g axis
    g = np.repeat(g_values, N_RANDOM_POINTS // N_G_VALUES_SLOW)
    error = relative_error(
        table(a=a, tau=tau, g=g, r_s=r_s), predict("multi-angle-45", a=a, tau=tau, g=g, r_s=r_s)
    )
    per_g = error.reshape(N_G_VALUES_SLOW, -1).max(axis=1)
    assert error.max() <= INTERPOLATION_REL_TOL, (
        f"max relative error {error.max():.2e}; worst g values "
        + ", ".join(f"{g_values[i]:.3f}: {per_g[i]:.1e}" for i in np.argsort(per_g)[-5:])
    )


@pytest.mark.slow
def test_build_on_a_dask_cluster_is_identical(coarse_g_table):
    distributed = pytest.importorskip("distributed")
    with distributed.Client(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as client:
        again = build_table(
            list(SMALL_INSTRUMENT),
            COARSE_G_SETTINGS,
            executor=client.get_executor(),
            progress=False,
        )
    assert_same_arrays(coarse_g_table.arrays, again.arrays)


#: d log x / dg of the full g table against central differences of the direct solver: the
#: interpolation error of a derivative is about the value's (~1e-4) over the node spacing
#: in g (~0.1), times a few.
G_GRADIENT_SOLVER_TOL = 5e-3
#: Step of the solver's central differences in g (truncation error ~ h^2 * d3/dg3 ~ 1e-6).
FD_STEP_G = 1e-3


@pytest.mark.slow
def test_free_g_table_gradient_matches_differences_of_the_direct_solver(cache_dir):
    """d/dg through the atanh(g) axis (chain rule dw/dg = 1 / (1 - g^2)) against the solver."""
    table = load_table("multi-angle-45", g="free", cache_dir=cache_dir, progress=False)
    rng = np.random.default_rng(14)
    a = rng.uniform(0.02, 0.6, 8)
    tau = np.concatenate([rng.uniform(0.3, 20.0, 6), [np.inf, np.inf]])
    r_s = rng.uniform(0.0, 1.0, 8)
    for g in (-0.45, 0.1, 0.7):
        value, _, _, d_g = table.evaluate(a=a, tau=tau, g=g, r_s=r_s, gradient=True)
        up = predict("multi-angle-45", a=a, tau=tau, g=g + FD_STEP_G, r_s=r_s)
        down = predict("multi-angle-45", a=a, tau=tau, g=g - FD_STEP_G, r_s=r_s)
        fd = (up - down) / (2.0 * FD_STEP_G)
        error = np.abs(d_g - fd) / np.abs(value)
        assert error.max() <= G_GRADIENT_SOLVER_TOL, f"g = {g}: {error.max():.2e}"
