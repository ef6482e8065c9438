"""Point fits of the paper's methods 1–4 (issue 5): recovery, global minimum, bounds, g search.

References: the exact adding–doubling solver (noise-free data from ``bayespig.data.simulate``
must be fitted back to the truth), eq. (6) written out here, scipy.optimize.least_squares
from many starts (an independent optimiser: bayespig's fit must find a minimum at least as
low), the chi-square mean of a least-squares fit under the paper's noise model (eq. 7), and
the table itself as an exact model (g search).
"""

import warnings

import numpy as np
import pytest
from scipy.optimize import least_squares

from bayespig.data import simulate
from bayespig.fit import (
    FitBoundWarning,
    FitSettings,
    film_term,
    fit_batch,
    fit_measurements,
    fit_problem,
)
from bayespig.instruments import get_instrument
from bayespig.likelihood import FilmTerm, Problem
from bayespig.table import TableSettings, load_table

# --- tolerances -----------------------------------------------------------------------------
#: Noise-free data must be fitted back to the truth to this, absolutely, in a and in tau
#: (issue 5); the table's interpolation error (~1e-5 in values) leaves ~1e-5 in tau at most.
RECOVERY_ABS_TOL = 1e-4
#: Eq. (6) written here vs the library: rounding.
EQ6_ABS_TOL = 1e-12
#: bayespig's objective at its estimate vs scipy's best over many starts (relative).
GLOBAL_MIN_REL_TOL = 1e-6
#: Mean of S / (N - P) over replicates vs eps^2: its relative standard error is
#: sqrt(2 / ((N - P) n_rows)) ~ 2.6 % for N - P = 10 and 300 rows; 4 standard errors.
CHI2_MEAN_REL_TOL = 0.11
#: g found by the outer search (golden sections on an exact model).
G_ABS_TOL = 1e-3

#: The (a0, tau0) pairs of the paper's Tables 1–2.
PAIRS = [(a, t) for a in (0.025, 0.1, 0.2) for t in (0.5, 1.0, 2.0)]
WAVELENGTHS = 400.0 + 10.0 * np.arange(len(PAIRS))
N_BINDER = 1.45
INSTRUMENT = "multi-angle-45"


@pytest.fixture(scope="module", autouse=True)
def table_cache(private_table_cache):
    """Tables of this module are built into a temporary cache (the user's cache is untouched)."""
    return private_table_cache


@pytest.fixture(scope="module")
def table(table_cache):
    return load_table(INSTRUMENT, progress=False)


def paper_grid_set(design, eps=0.0, seed=0):
    """One wavelength per (a0, tau0) pair of the paper, from the exact solver."""
    a = np.array([p[0] for p in PAIRS])
    tau = np.array([p[1] for p in PAIRS])
    return (
        simulate(a=a, tau=tau, design=design, wavelengths=WAVELENGTHS, eps=eps, seed=seed),
        a,
        tau,
    )


def batch_films(instrument, table, a, tau, design, rng=None, eps=0.0):
    """Films of a design with values from the table (an exact model for the fit), rows = a.size."""
    specs = {
        "method3": [("on_black", "film", 0.01)],
        "method4": [("on_black", "film", 0.01), ("on_white", "film", 0.95)],
        "method2": [("opaque", None, 0.0), ("on_black", "film", 0.01)],
    }[design]
    films = []
    for name, group, r_s in specs:
        values = table(a=a, tau=np.inf if group is None else tau, r_s=r_s)
        if rng is not None:
            values = values * (1.0 + eps * rng.standard_normal(values.shape))
        films.append(film_term(name, observed=values, group=group, instrument=instrument, r_s=r_s))
    return films


# --- recovery ---------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["method1", "method2", "method3", "method4"])
def test_noise_free_data_are_recovered_across_the_paper_grid(method):
    measurements, a, tau = paper_grid_set(method)
    result = fit_problem(Problem.from_measurements(measurements, method))
    assert result.method == method and result.groups and result.tau.shape == (len(PAIRS), 1)
    np.testing.assert_allclose(result.a, a, atol=RECOVERY_ABS_TOL, rtol=0)
    np.testing.assert_allclose(result.tau[:, 0], tau, atol=RECOVERY_ABS_TOL, rtol=0)
    np.testing.assert_array_equal(result.wavelength_nm, WAVELENGTHS)
    assert result.converged.all() and not result.at_bound.any()


@pytest.mark.parametrize("objective", ["log", "absolute"])
@pytest.mark.parametrize("method", ["method3", "method4"])
def test_every_objective_recovers_noise_free_data(method, objective):
    measurements, a, tau = paper_grid_set(method)
    result = fit_problem(
        Problem.from_measurements(measurements, method), settings=FitSettings(objective=objective)
    )
    np.testing.assert_allclose(result.a, a, atol=RECOVERY_ABS_TOL, rtol=0)
    np.testing.assert_allclose(result.tau[:, 0], tau, atol=RECOVERY_ABS_TOL, rtol=0)


def test_general_problem_with_two_film_groups_and_an_opaque_film():
    """Every film at once: a shared, one tau per film group (here tau and 2 tau)."""
    design = [
        {"name": "thin_black", "substrate": "black", "film_group": "thin"},
        {"name": "thin_white", "substrate": "white", "film_group": "thin"},
        {"name": "thick_black", "substrate": "black", "tau_scale": 2.0, "film_group": "thick"},
        {"name": "opaque", "opaque": True},
    ]
    a, tau = np.array([0.03, 0.15]), np.array([0.4, 1.2])
    measurements = simulate(a=a, tau=tau, design=design, wavelengths=[450.0, 600.0], eps=0.0)
    result = fit_problem(Problem.from_measurements(measurements, "general"))
    assert result.groups == ("thin", "thick") and result.tau.shape == (2, 2)
    np.testing.assert_allclose(result.a, a, atol=RECOVERY_ABS_TOL, rtol=0)
    np.testing.assert_allclose(result.tau, np.column_stack([tau, 2 * tau]), atol=RECOVERY_ABS_TOL)


def test_fit_measurements_picks_method4_for_black_and_white():
    measurements, a, _tau = paper_grid_set("method4")
    result = fit_measurements(measurements)
    assert result.method == "method4"
    np.testing.assert_allclose(result.a, a, atol=RECOVERY_ABS_TOL, rtol=0)


def test_method1_tau_is_eq6_of_the_measured_transmittance():
    measurements, _, _ = paper_grid_set("method1", eps=0.05, seed=3)
    result = fit_problem(Problem.from_measurements(measurements, "method1"))
    transmittance = measurements.sample("on_glass").transmittance.values
    t_f = 1.0 - ((N_BINDER - 1.0) / (N_BINDER + 1.0)) ** 2
    np.testing.assert_allclose(
        result.tau[:, 0], -np.log(transmittance / t_f**2), atol=EQ6_ABS_TOL, rtol=0
    )


def test_method2_takes_a_from_the_opaque_film_alone():
    """Two steps: a of method 2 equals a fitted to the opaque film by itself (method 1's step)."""
    m2, _, _ = paper_grid_set("method2", eps=0.05, seed=5)
    opaque_only = Problem.from_measurements(m2, "method2")
    film = opaque_only.films[0]
    assert film.opaque
    alone = fit_batch([film], (), method="general")
    np.testing.assert_allclose(fit_problem(opaque_only).a, alone.a, rtol=0, atol=1e-10)


# --- the global minimum -------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["method3", "method4"])
def test_fit_finds_the_lowest_minimum_of_many_scipy_starts(method, table):
    """scipy's trust-region least squares from a 3 x 3 grid of starts never beats bayespig."""
    instrument = get_instrument(INSTRUMENT)
    rng = np.random.default_rng(11)
    a0, tau0 = np.full(3, 0.1), np.full(3, 1.0)
    films = batch_films(instrument, table, a0, tau0, method, rng=rng, eps=0.05)
    result = fit_batch(films, ("film",), method=method, tables={instrument: table})
    for row in range(a0.size):
        observed = [f.observed[row] for f in films]
        r_s = [f.r_s[row] for f in films]

        def residuals(p, observed=observed, r_s=r_s):
            return np.concatenate(
                [
                    obs / table(a=p[0], tau=np.exp(p[1]), r_s=rs) - 1.0
                    for obs, rs in zip(observed, r_s)
                ]
            )

        best = np.inf
        for a_start in (0.02, 0.2, 0.6):
            for tau_start in (0.1, 1.5, 20.0):
                fit = least_squares(
                    residuals,
                    [a_start, np.log(tau_start)],
                    bounds=([0.0, np.log(1e-3)], [1.0, np.log(128.0)]),
                )
                best = min(best, 2.0 * fit.cost)
        assert result.objective[row] <= best * (1.0 + GLOBAL_MIN_REL_TOL)


def test_objective_matches_the_noise_level(table):
    """At the minimum, mean S / (N - P) = eps^2 (least squares under eq. 7, P = 2 parameters)."""
    instrument = get_instrument(INSTRUMENT)
    rng = np.random.default_rng(7)
    eps, n_rows = 0.05, 300
    films = batch_films(
        instrument, table, np.full(n_rows, 0.1), np.full(n_rows, 1.0), "method4", rng=rng, eps=eps
    )
    result = fit_batch(films, ("film",), method="method4", tables={instrument: table})
    dof = result.n_values - 2
    assert abs(np.mean(result.objective / dof) / eps**2 - 1.0) < CHI2_MEAN_REL_TOL


# --- bounds -----------------------------------------------------------------------------------
def test_a_film_brighter_than_opaque_is_flagged_at_the_tau_bound(table):
    """Method 2 on data where the 'thin' film is 3 % brighter than the opaque one: tau -> inf."""
    instrument = get_instrument(INSTRUMENT)
    opaque = table(a=np.full(2, 0.2), tau=np.inf, r_s=0.0)
    thin = table(a=np.full(2, 0.2), tau=np.inf, r_s=0.01) * 1.03
    films = (
        FilmTerm("opaque", "reflectance", instrument, None, np.zeros(2), opaque),
        FilmTerm("on_black", "reflectance", instrument, "film", np.full(2, 0.01), thin),
    )
    problem = Problem(np.array([500.0, 600.0]), films, ("film",), method="method2")
    with pytest.warns(FitBoundWarning, match="500 nm: tau\\[film\\] at upper bound"):
        result = fit_problem(problem)
    assert result.at_upper[:, 1].all() and result.at_bound.all()
    assert result.tau[:, 0] == pytest.approx(128.0)
    assert "at a bound" in result.describe()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        quiet = fit_problem(problem, warn=False)
    assert quiet.at_upper[:, 1].all()


def test_a_non_absorbing_pigment_ends_on_the_a_bound_and_says_so():
    measurements = simulate(a=0.0, tau=1.0, design="method4", wavelengths=[500.0], eps=0.0)
    with pytest.warns(FitBoundWarning, match="a at lower bound"):
        result = fit_problem(Problem.from_measurements(measurements, "method4"))
    assert result.a[0] == 0.0 and result.at_lower[0, 0]
    assert result.tau[0, 0] == pytest.approx(1.0, abs=RECOVERY_ABS_TOL)


def test_a_fixed_start_is_a_local_search(table):
    """FitSettings(start=...) skips the grid scan: from the truth it stays there, like the grid."""
    instrument = get_instrument(INSTRUMENT)
    films = batch_films(instrument, table, np.array([0.05]), np.array([0.8]), "method4")
    local = fit_batch(films, ("film",), method="method4", settings=FitSettings(start=(0.05, 0.8)))
    grid = fit_batch(films, ("film",), method="method4")
    np.testing.assert_allclose([local.a[0], local.tau[0, 0]], [0.05, 0.8], atol=RECOVERY_ABS_TOL)
    np.testing.assert_allclose([grid.a[0], grid.tau[0, 0]], [0.05, 0.8], atol=RECOVERY_ABS_TOL)


# --- g ----------------------------------------------------------------------------------------
#: A quick table with a g axis (the full one takes minutes): same code path.
COARSE_G_SETTINGS = TableSettings(
    g_range=(-0.3, 0.6), n_g=6, n_a=12, log2_tau_min=-4, log2_tau_max=4, per_octave=2
)


def test_outer_g_search_recovers_g(table_cache):
    """Data from a g table itself (an exact model for the fit): the search finds g, a and tau."""
    instrument = get_instrument(INSTRUMENT)
    g_table = load_table(instrument, g="free", settings=COARSE_G_SETTINGS, progress=False)
    a0, tau0, g0 = (
        np.array([0.05, 0.1, 0.3]),
        np.array([0.7, 1.5, 3.0]),
        np.array([0.25, -0.1, 0.4]),
    )
    films = [
        film_term(
            name,
            observed=g_table(a=a0, tau=tau0, g=g0, r_s=r_s),
            group="film",
            instrument=instrument,
            r_s=r_s,
        )
        for name, r_s in (("on_black", 0.01), ("on_white", 0.95))
    ]
    result = fit_batch(films, ("film",), method="method4", g="search", tables={instrument: g_table})
    assert result.parameter_names == ("a", "tau[film]", "g")
    np.testing.assert_allclose(result.g, g0, atol=G_ABS_TOL)
    np.testing.assert_allclose(result.a, a0, atol=RECOVERY_ABS_TOL)
    np.testing.assert_allclose(result.tau[:, 0], tau0, atol=RECOVERY_ABS_TOL)
    assert not result.at_bound.any()
    with pytest.raises(ValueError, match="g axis"):
        fit_batch(
            films,
            ("film",),
            method="method4",
            g="search",
            tables={instrument: load_table(instrument)},
        )


# --- bad input --------------------------------------------------------------------------------
def test_bad_arguments_raise_value_errors_naming_them(table):
    instrument = get_instrument(INSTRUMENT)
    films = batch_films(instrument, table, np.array([0.1]), np.array([1.0]), "method4")
    with pytest.raises(ValueError, match="method must be one of"):
        fit_batch(films, ("film",), method="method5")
    with pytest.raises(ValueError, match="g must be a number or 'search'"):
        fit_batch(films, ("film",), method="method4", g="free")
    with pytest.raises(ValueError, match="group 'film' is not in groups"):
        fit_batch(films, ("other_group",), method="method4")
    bad = [
        film_term("x", observed=-films[0].observed, group="film", instrument=instrument, r_s=0.01)
    ]
    with pytest.raises(ValueError, match="film 'x': observed values must be finite and > 0"):
        fit_batch(bad, ("film",), method="method3")
    with pytest.raises(ValueError, match="takes a from an opaque film"):
        fit_batch(films, ("film",), method="method2")
    with pytest.raises(TypeError, match="problem must be a bayespig.likelihood.Problem"):
        fit_problem(films)
    for kwargs, match in (
        ({"tau_bounds": (2.0, 1.0)}, "tau_bounds"),
        ({"a_bounds": (0.0, 1.5)}, "a_bounds"),
        ({"objective": "huber"}, "objective must be one of"),
        ({"max_starts": 0}, "max_starts"),
        ({"start": (0.1, -1.0)}, "start must be"),
    ):
        with pytest.raises(ValueError, match=match):
            FitSettings(**kwargs)
