"""The additive noise floor of the likelihood: reduction to eq. (7), the combined Gaussian, and
which observed values it takes (zeros with a floor; NaN never)."""

import dataclasses

import numpy as np
import pytest
from scipy import stats

from bayespig.data import simulate
from bayespig.likelihood import (
    ForwardModel,
    LogPosterior,
    Priors,
    Problem,
    censored_zero_logpdf,
    censored_zeros_argument,
    check_observed,
    multiplicative_normal_logpdf,
    noise_floor_argument,
    noise_sd,
)

#: The floor-0 path against eq. (7)'s own formula: rounding of two evaluation orders only.
REDUCTION_ABS_TOL = 1e-12
#: Two evaluations of the same Gaussian log-density (scipy and ours): rounding only.
LOGPDF_ABS_TOL = 1e-10
#: The fast path and ForwardModel.predict evaluate the same interpolant (see test_likelihood).
SAME_INTERPOLANT_REL_TOL = 1e-8


@pytest.fixture(scope="module")
def method3():
    ms = simulate(a=[0.05, 0.3], tau=[0.5, 3.0], design="method3", wavelengths=[450.0, 600.0], eps=0.0, seed=0)
    problem = Problem.from_measurements(ms, "method3")
    return problem, ForwardModel(problem)


def _eq7(observed, model, eps):
    """Eq. (7) written out independently: N(x | m, (eps m)^2)."""
    return -0.5 * ((observed - model) / (eps * model)) ** 2 - np.log(eps * model) - 0.5 * np.log(2 * np.pi)


def test_logpdf_with_floor_zero_is_eq7():
    rng = np.random.default_rng(3)
    model = rng.uniform(1e-3, 2.0, 300)
    eps = rng.uniform(0.01, 0.2, 300)
    observed = model * (1 + eps * rng.standard_normal(300))
    np.testing.assert_allclose(multiplicative_normal_logpdf(observed, model, eps, 0.0), _eq7(observed, model, eps),
                               rtol=0, atol=REDUCTION_ABS_TOL)
    assert np.array_equal(noise_sd(model, eps, 0.0), eps * model)


def test_logpdf_with_floor_is_the_gaussian_of_the_summed_variances():
    rng = np.random.default_rng(4)
    model = np.geomspace(1e-5, 0.5, 300)
    eps = rng.uniform(0.01, 0.2, 300)
    floor = rng.uniform(1e-3, 1e-2, 300)
    scale = np.sqrt((eps * model) ** 2 + floor ** 2)
    observed = np.maximum(model + scale * rng.standard_normal(300), 0.0)  # zeros included
    assert (observed == 0).any()
    expected = stats.norm.logpdf(observed, loc=model, scale=scale)
    np.testing.assert_allclose(multiplicative_normal_logpdf(observed, model, eps, floor), expected,
                               rtol=0, atol=LOGPDF_ABS_TOL)


def test_log_posterior_without_floor_is_unchanged_by_a_zero_floor(method3):
    problem, model = method3
    rng = np.random.default_rng(5)
    theta = np.column_stack([rng.uniform(0, 1, 30), rng.uniform(np.log(0.01), np.log(100), 30)])
    plain = LogPosterior(model, 1, Priors(), eps=0.04)
    zero = LogPosterior(model, 1, Priors(), eps=0.04, noise_floor=0.0)
    assert not zero.has_noise_floor and zero.parameter_names == plain.parameter_names
    assert np.array_equal(zero(theta), plain(theta))
    predicted = model.predict(1, theta[:, 0], np.exp(theta[:, 1:]))
    np.testing.assert_allclose(plain.log_likelihood(theta, pointwise=True),
                               _eq7(problem.observed(1), predicted, 0.04), rtol=1e-9, atol=REDUCTION_ABS_TOL)


def test_log_posterior_with_a_known_floor_is_the_sum_of_scipy_logpdfs(method3):
    problem, model = method3
    rng = np.random.default_rng(6)
    floor = 2e-3
    post = LogPosterior(model, 0, Priors(), eps=0.04, noise_floor=floor)
    theta = np.column_stack([rng.uniform(0, 1, 30), rng.uniform(np.log(0.01), np.log(100), 30)])
    observed = np.maximum(problem.observed(0) * (1 + 0.04 * rng.standard_normal(problem.n_values))
                          + floor * rng.standard_normal(problem.n_values), 0.0)
    post.observed = observed
    predicted = model.predict(0, theta[:, 0], np.exp(theta[:, 1:]))
    expected = stats.norm.logpdf(observed, loc=predicted, scale=np.sqrt((0.04 * predicted) ** 2 + floor ** 2))
    np.testing.assert_allclose(post.log_likelihood(theta, pointwise=True), expected, rtol=SAME_INTERPOLANT_REL_TOL,
                               atol=LOGPDF_ABS_TOL)
    np.testing.assert_allclose(post(theta), expected.sum(axis=1), rtol=SAME_INTERPOLANT_REL_TOL)


def test_inferred_eps_and_floor_are_the_last_two_parameters(method3):
    problem, model = method3
    post = LogPosterior(model, 0, Priors(noise_floor_range=(1e-5, 0.1)), eps=None, noise_floor="infer")
    assert post.parameter_names == ("a", "log_tau[on_black]", "log_eps", "log_noise_floor")
    np.testing.assert_allclose(post.lower[-1], np.log(1e-5))
    np.testing.assert_allclose(post.upper[-1], np.log(0.1))
    theta = np.array([[0.05, np.log(0.5), np.log(0.03), np.log(1e-3)],
                      [0.2, np.log(2.0), np.log(0.1), np.log(3e-2)]])
    predicted = model.predict(0, theta[:, 0], np.exp(theta[:, 1:2]))
    scale = np.sqrt((np.exp(theta[:, 2:3]) * predicted) ** 2 + np.exp(theta[:, 3:4]) ** 2)
    expected = stats.norm.logpdf(problem.observed(0), loc=predicted, scale=scale).sum(axis=1)
    np.testing.assert_allclose(post(theta), expected, rtol=SAME_INTERPOLANT_REL_TOL)
    np.testing.assert_allclose(post.noise_floor_of(theta), [1e-3, 3e-2], rtol=1e-12)


@pytest.mark.parametrize("value, error, message", [
    ("estimate", ValueError, ("noise_floor must be None (no floor), a number >= 0 (the additive noise floor in "
                             "the units of the values, e.g. 0.001 for 0.001 1/sr) or 'infer', got 'estimate'")),
    (-1e-3, ValueError, ("noise_floor must be None (no floor), a number >= 0 (the additive noise floor in "
                        "the units of the values, e.g. 0.001 for 0.001 1/sr) or 'infer', got -0.001")),
    (float("nan"), ValueError, "got nan"),
    (True, TypeError, "got bool True"),
    ([1e-3], TypeError, "got list [0.001]"),
])
def test_noise_floor_argument_refuses_with_the_argument_named(value, error, message):
    with pytest.raises(error) as caught:
        noise_floor_argument(value)
    assert str(caught.value).startswith("noise_floor must be") and str(caught.value).endswith(message)


def test_noise_floor_argument_values():
    assert noise_floor_argument(None) is None
    assert noise_floor_argument(0) is None
    assert noise_floor_argument(0.002) == 0.002
    assert noise_floor_argument("infer") == "infer"


def _with_observed(problem, film_index, row, column, value):
    film = problem.films[film_index]
    observed = np.array(film.observed, dtype=float)
    observed[row, column] = value
    films = list(problem.films)
    films[film_index] = dataclasses.replace(film, observed=observed)
    return dataclasses.replace(problem, films=tuple(films))


def test_zero_refused_without_floor_naming_film_value_and_band(method3):
    problem, _ = method3
    zero = _with_observed(problem, 0, 1, 2, 0.0)
    label = problem.films[0].instrument.labels[2]
    with pytest.raises(ValueError) as caught:
        check_observed(zero, None)
    assert str(caught.value) == (
        f"film 'on_black': observed value 0 at 600 nm, geometry {label} (value 3 of {problem.n_values}) must be > 0 "
        "without a noise floor (eq. 7 gives a zero reading zero likelihood); give noise_floor=<number> or "
        "'infer' (--noise-floor on the command line) to take zeros as data")
    check_observed(zero, 1e-3)
    check_observed(zero, "infer")


def test_nan_refused_even_with_a_floor(method3):
    problem, _ = method3
    bad = _with_observed(problem, 0, 0, 0, np.nan)
    label = problem.films[0].instrument.labels[0]
    for floor in (None, 1e-3, "infer"):
        with pytest.raises(ValueError) as caught:
            check_observed(bad, floor)
        assert str(caught.value) == (f"film 'on_black': observed value nan at 450 nm, geometry {label} "
                                     f"(value 1 of {problem.n_values}) is not a finite number")


def test_negative_refused_with_a_floor(method3):
    problem, _ = method3
    bad = _with_observed(_with_observed(problem, 0, 0, 1, -1e-4), 0, 1, 1, -2e-4)
    label = problem.films[0].instrument.labels[1]
    with pytest.raises(ValueError) as caught:
        check_observed(bad, 1e-3)
    assert str(caught.value) == (f"film 'on_black': observed value -0.0001 at 450 nm, geometry {label} "
                                 f"(value 2 of {problem.n_values}) is negative; measured values must be >= 0; "
                                 "1 more value of this film as well")


def test_zero_model_value_has_zero_likelihood_with_a_floor(method3):
    """The model value must stay > 0: an a = 1 opaque film reflects nothing (diffusely)."""
    ms = simulate(a=0.3, tau=1.0, design="method2", wavelengths=[500.0], eps=0.0, seed=0)
    problem = Problem.from_measurements(ms, "method2")
    model = ForwardModel(problem)
    post = LogPosterior(model, 0, Priors(), eps=0.05, noise_floor=1e-3)
    predicted = model.predict(0, np.array([1.0]), np.array([[1.0]]))
    if (predicted > 0).all():
        pytest.skip("the instrument's channels include a specular term: the model is never 0")
    assert post(np.array([[1.0, 0.0]]))[0] == -np.inf


def test_priors_refuse_an_empty_floor_range():
    with pytest.raises(ValueError, match="noise_floor_range must satisfy low < high inside"):
        Priors(noise_floor_range=(0.0, 1.0))


def test_censored_zero_is_the_normal_cdf_at_zero_deep_into_both_tails():
    # scipy's normal log-cdf is the independent reference; log_ndtr keeps its accuracy where
    # Phi underflows (a model 40 sigma above 0: log Phi = -804.6)
    mean = np.array([-3e-3, -1e-4, 0.0, 1e-4, 2e-3, 0.04])
    variance = np.full(mean.shape, 1e-3) ** 2
    expected = stats.norm.logcdf(0.0, loc=mean, scale=1e-3)
    np.testing.assert_allclose(censored_zero_logpdf(mean, variance), expected, rtol=1e-12, atol=LOGPDF_ABS_TOL)
    assert censored_zero_logpdf(0.0, 1.0) == pytest.approx(np.log(0.5), abs=LOGPDF_ABS_TOL)
    assert np.isfinite(censored_zero_logpdf(0.04, 1e-6))


def test_censored_zero_is_the_probability_of_a_clipped_reading_by_monte_carlo():
    # readings max(m + sigma xi, 0): the fraction of exact zeros is Phi(-m / sigma)
    rng = np.random.default_rng(11)
    n = 200_000
    for m, sigma in ((0.002, 0.003), (-0.001, 0.002), (0.01, 0.004)):
        zeros = np.mean(np.maximum(m + sigma * rng.standard_normal(n), 0.0) == 0.0)
        expected = np.exp(censored_zero_logpdf(m, sigma ** 2))
        # binomial sd of the fraction; 4.5 sd (see tests/inference/common.py MC_Z)
        assert abs(zeros - expected) <= 4.5 * np.sqrt(expected * (1 - expected) / n), (m, sigma, zeros, expected)


def test_log_posterior_censors_the_zeros_and_leaves_the_rest(method3):
    problem, model = method3
    rng = np.random.default_rng(12)
    floor = 2e-3
    theta = np.column_stack([rng.uniform(0, 1, 30), rng.uniform(np.log(0.01), np.log(100), 30)])
    plain = LogPosterior(model, 0, Priors(), eps=0.04, noise_floor=floor)
    censored = LogPosterior(model, 0, Priors(), eps=0.04, noise_floor=floor, censored_zeros=True)
    observed = np.array(problem.observed(0), dtype=float)
    observed[[0, 2]] = 0.0
    plain.observed = censored.observed = observed
    predicted = model.predict(0, theta[:, 0], np.exp(theta[:, 1:]))
    scale = np.sqrt((0.04 * predicted) ** 2 + floor ** 2)
    expected = stats.norm.logpdf(observed, loc=predicted, scale=scale)
    expected[:, [0, 2]] = stats.norm.logcdf(0.0, loc=predicted[:, [0, 2]], scale=scale[:, [0, 2]])
    terms = censored.log_likelihood(theta, pointwise=True)
    np.testing.assert_allclose(terms, expected, rtol=SAME_INTERPOLANT_REL_TOL, atol=LOGPDF_ABS_TOL)
    positive = observed > 0
    assert np.array_equal(terms[:, positive], plain.log_likelihood(theta, pointwise=True)[:, positive])
    assert censored.censored_zeros and not plain.censored_zeros


def test_censored_zeros_argument():
    assert censored_zeros_argument(True, "infer") is True
    assert censored_zeros_argument(False, None) is False
    with pytest.raises(ValueError) as caught:
        censored_zeros_argument(True, None)
    assert str(caught.value) == ("censored_zeros=True needs a noise floor (noise_floor a number > 0 or 'infer'): "
                                 "without one eq. (7) gives a reading of 0 no probability")
    with pytest.raises(TypeError) as caught:
        censored_zeros_argument("yes", "infer")
    assert str(caught.value) == "censored_zeros must be True or False, got 'yes' (str)"
