"""The likelihood layer: eq. (7) density, priors' support, and the fast per-wavelength model."""

import numpy as np
import pytest
from scipy import stats

from bayespig import predict
from bayespig.data import simulate
from bayespig.likelihood import (
    ForwardModel,
    LogPosterior,
    Priors,
    Problem,
    multiplicative_normal_logpdf,
)

# --- tolerances -----------------------------------------------------------------------------
# Measured values: the worst case under OpenBLAS's Haswell and SkylakeX kernels.
#: Two evaluations of the same Gaussian log-density (scipy and ours): rounding only (measured
#: 8.9e-16 per value, 9.3e-10 summed over a problem's values against n_values times this).
LOGPDF_ABS_TOL = 1e-10
#: The fast path and the table's own interpolation evaluate the same cubic stencils in a
#: different order (and ``log D + log U`` interpolated as one quantity): rounding only
#: (measured 0: identical).
SAME_INTERPOLANT_REL_TOL = 1e-9
#: Look-up table vs direct solve over the domain (issue 3: 2e-4 relative). Measured 6.5e-7 on
#: these points. Margin > 100x.
TABLE_REL_TOL = 2e-4
#: Specular transmittance of eq. (5) vs the closed form: rounding only (measured 0).
TRANSMITTANCE_REL_TOL = 1e-12


@pytest.fixture(scope="module")
def problems():
    """Problems of the paper's four designs (two wavelengths each), simulated noise-free."""
    out = {}
    for method in ("method1", "method2", "method3", "method4"):
        ms = simulate(a=[0.05, 0.3], tau=[0.5, 3.0], design=method, wavelengths=[450.0, 600.0],
                      eps=0.0, seed=0)
        out[method] = Problem.from_measurements(ms, method)
    return out


@pytest.fixture(scope="module")
def models(problems):
    tables = {}
    return {method: ForwardModel(problem, tables=tables) for method, problem in problems.items()}


def _theta_grid(n_groups, rng, n=40, tau_low=0.01, tau_high=100.0):
    a = rng.uniform(0.0, 1.0, n)
    log_tau = rng.uniform(np.log(tau_low), np.log(tau_high), (n, n_groups))
    return np.column_stack([a, log_tau])


def test_multiplicative_normal_logpdf_is_the_gaussian_of_eq7():
    rng = np.random.default_rng(1)
    model = rng.uniform(1e-3, 2.0, 200)
    eps = rng.uniform(0.01, 0.2, 200)
    observed = model * (1 + eps * rng.standard_normal(200))
    expected = stats.norm.logpdf(observed, loc=model, scale=eps * model)
    np.testing.assert_allclose(multiplicative_normal_logpdf(observed, model, eps), expected,
                               rtol=0, atol=LOGPDF_ABS_TOL)


@pytest.mark.parametrize("method", ["method1", "method2", "method3", "method4"])
def test_log_likelihood_is_the_sum_of_normal_logpdfs_of_the_predictions(problems, models, method):
    """Known eps: log L = sum_k log N(x_k | m_k, (eps m_k)^2), with m from ForwardModel.predict."""
    problem, model = problems[method], models[method]
    rng = np.random.default_rng(2)
    log_post = LogPosterior(model, 1, Priors(), eps=0.04)
    theta = _theta_grid(len(problem.groups), rng)
    # noisy observations so that the quadratic term matters
    observed = problem.observed(1) * (1 + 0.04 * rng.standard_normal(problem.n_values))
    log_post.observed = observed
    predicted = model.predict(1, theta[:, 0], np.exp(theta[:, 1:]))
    expected = stats.norm.logpdf(observed, loc=predicted, scale=0.04 * predicted)
    pointwise = log_post.log_likelihood(theta, pointwise=True)
    np.testing.assert_allclose(pointwise, expected, rtol=1e-8, atol=LOGPDF_ABS_TOL)
    np.testing.assert_allclose(log_post(theta), expected.sum(axis=1), rtol=1e-8,
                               atol=LOGPDF_ABS_TOL * problem.n_values)


def test_inferred_eps_enters_as_the_scale_of_every_value(problems, models):
    problem, model = problems["method4"], models["method4"]
    log_post = LogPosterior(model, 0, Priors(), eps=None)
    assert log_post.parameter_names == ("a", "log_tau[film]", "log_eps")
    theta = np.array([[0.05, np.log(0.5), np.log(0.03)], [0.2, np.log(2.0), np.log(0.1)]])
    predicted = model.predict(0, theta[:, 0], np.exp(theta[:, 1:2]))
    scale = np.exp(theta[:, 2:3]) * predicted
    expected = stats.norm.logpdf(problem.observed(0), loc=predicted, scale=scale).sum(axis=1)
    np.testing.assert_allclose(log_post(theta), expected, rtol=1e-10)


def test_prior_support_is_the_box_and_minus_infinity_outside(models):
    priors = Priors(a_range=(0.0, 1.0), tau_range=(0.01, 100.0))
    log_post = LogPosterior(models["method4"], 0, priors, eps=0.05)
    np.testing.assert_allclose(log_post.lower, [0.0, np.log(0.01)])
    np.testing.assert_allclose(log_post.upper, [1.0, np.log(100.0)])
    inside = np.array([[0.0, np.log(0.01)], [0.5, 0.0], [0.999, np.log(100.0)]])
    outside = np.array([[-1e-9, 0.0], [1.0 + 1e-9, 0.0], [0.5, np.log(0.01) - 1e-9],
                        [0.5, np.log(100.0) + 1e-9]])
    assert log_post.in_support(inside).all()
    assert not log_post.in_support(outside).any()
    assert np.isfinite(log_post(inside)).all()
    assert np.all(log_post(outside) == -np.inf)
    mixed = np.vstack([inside, outside])
    assert np.array_equal(np.isfinite(log_post(mixed)), [True] * 3 + [False] * 4)


@pytest.mark.parametrize("kwargs, match", [
    ({"a_range": (0.2, 0.1)}, "a_range"),
    ({"a_range": (-0.1, 1.0)}, "a_range"),
    ({"tau_range": (0.0, 10.0)}, "tau_range"),
    ({"eps_range": (0.1, np.inf)}, "eps_range"),
    ({"g_range": ("x", 1)}, "g_range"),
])
def test_bad_priors_name_the_range(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Priors(**kwargs)


def test_prior_beyond_the_table_is_refused(models):
    with pytest.raises(ValueError, match="tau_range"):
        LogPosterior(models["method4"], 0, Priors(tau_range=(0.01, 1e4)))


@pytest.mark.parametrize("method", ["method1", "method2", "method3", "method4"])
def test_wavelength_model_equals_forward_model_predict(problems, models, method):
    """The fast stencil path is the table's interpolant, also below the first tau node."""
    problem, model = problems[method], models[method]
    rng = np.random.default_rng(3)
    theta = _theta_grid(len(problem.groups), rng, n=60, tau_low=1e-3, tau_high=100.0)
    for index in range(problem.n_wavelengths):
        fast = model.at_wavelength(index)(theta[:, 0], np.exp(theta[:, 1:]))
        slow = model.predict(index, theta[:, 0], np.exp(theta[:, 1:]))
        np.testing.assert_allclose(fast, slow, rtol=SAME_INTERPOLANT_REL_TOL, atol=1e-300)


@pytest.mark.parametrize("method", ["method2", "method4"])
def test_wavelength_model_equals_the_direct_solver(problems, models, method):
    """Against adding-doubling itself (bayespig.predict) within the table's accuracy."""
    problem, model = problems[method], models[method]
    rng = np.random.default_rng(4)
    n = 12
    a = rng.uniform(0.01, 0.9, n)
    tau = np.exp(rng.uniform(np.log(0.05), np.log(50.0), n))
    fast = model.at_wavelength(0)(a, tau[:, None])
    start = 0
    for film in problem.films:
        k = film.observed.shape[1]
        film_tau = np.full(n, np.inf) if film.opaque else tau
        direct = predict(film.instrument, a=a, tau=film_tau, r_s=float(film.r_s[0]))
        np.testing.assert_allclose(fast[:, start:start + k], direct, rtol=TABLE_REL_TOL, atol=0)
        start += k


def test_transmittance_is_the_closed_form_of_eq5(problems, models):
    """Film on glass at normal incidence: T = t_F^2 exp(-tau), t_F = 1 - ((n-1)/(n+1))^2."""
    problem, model = problems["method1"], models["method1"]
    n = problem.n
    t_f = 1.0 - ((n - 1.0) / (n + 1.0)) ** 2
    tau = np.array([0.01, 0.5, 3.0, 40.0])
    values = model.at_wavelength(0)(np.full(4, 0.1), tau[:, None])
    column = next(k for k, f in enumerate(problem.films) if f.kind == "transmittance")
    start = sum(f.observed.shape[1] for f in problem.films[:column])
    np.testing.assert_allclose(values[:, start], t_f ** 2 * np.exp(-tau), rtol=TRANSMITTANCE_REL_TOL)


@pytest.mark.parametrize("eps", [0.04, None])
@pytest.mark.parametrize("method", ["method1", "method3", "method4"])
def test_stacked_log_posterior_equals_one_wavelength_at_a_time(problems, models, method, eps):
    """A stack of wavelengths evaluates each row with its own wavelength's data (r_s, observed),
    with eps known or inferred (one log eps per row); below the tables' first tau node (the
    slow path) too."""
    problem, model = problems[method], models[method]
    rng = np.random.default_rng(7)
    indices = [1, 0, 1]
    stacked = LogPosterior(model, indices, Priors(), eps=eps)
    theta = _theta_grid(len(problem.groups), rng)
    if eps is None:  # a log eps column, inside the prior's box
        theta = np.column_stack([theta, np.log(rng.uniform(0.01, 0.2, theta.shape[0]))])
    member = rng.integers(0, len(indices), theta.shape[0])
    together = stacked.log_likelihood(theta, pointwise=True, member=member)
    for position, index in enumerate(indices):
        rows = member == position
        alone = LogPosterior(model, index, Priors(), eps=eps).log_likelihood(theta[rows], pointwise=True)
        np.testing.assert_array_equal(together[rows], alone)
    with pytest.raises(ValueError, match="member"):
        stacked(theta)
    tiny = np.full((4, len(problem.groups)), 5e-4)  # below tau_min = 2^-10
    a = np.full(4, 0.2)
    values = model.at_wavelength(indices)(a, tiny, member=np.array([0, 1, 2, 1]))
    for row, index in enumerate([1, 0, 1, 0]):
        np.testing.assert_allclose(values[row], model.predict(index, a[row], tiny[row]), rtol=1e-12)
