"""The block layout of the joint machinery (bayespig.inference.shared.BlockLayout) and the
film-thickness spec (bayespig.inference.film_thickness)."""

import numpy as np
import pytest

from bayespig.data import simulate
from bayespig.inference.card_factors import CardFactorLogPosterior, CardFactors, card_indices
from bayespig.inference.film_thickness import RELATIVE_SD, THICKNESS_PRIOR_SDS, FilmThickness
from bayespig.inference.shared import BlockLayout, FilmLayout, JointLogPosterior
from bayespig.likelihood import ForwardModel, Priors, Problem

EPS = 0.01


class _WavelengthMajorFilm(FilmLayout):
    """The film layout with its blocks stored wavelength by wavelength ([a, log tau] of 450 nm, then
    of 650 nm): the same posterior in a permuted flat order."""

    @property
    def flat_index(self):
        return np.arange(self.n_wavelengths * self.size).reshape(self.n_wavelengths, self.size)

    @property
    def parameter_names(self):
        return BlockLayout.parameter_names.fget(self)  # the generic r_<name>[<wavelength>]


@pytest.fixture(scope="module")
def film():
    ms = simulate(a=np.array([0.3, 0.1]), tau=np.array([1.0, 1.5]), design="method4", instrument="multi-angle-45",
                  wavelengths=[450.0, 650.0], eps=EPS, seed=4)
    problem = Problem.from_measurements(ms, "method4")
    return ms, problem, ForwardModel(problem, "isotropic", {})


def test_a_forward_model_is_the_film_layout(film):
    """JointLogPosterior(ForwardModel) and JointLogPosterior(FilmLayout) are one posterior: the
    card factors' density, sensitivity and names are those of the film layout given explicitly."""
    ms, problem, model = film
    cards, index = card_indices(ms, problem)
    theta_hat = np.array([[0.3, 0.0], [0.1, 0.4]])
    spec = CardFactors(problem, index, 0.1, cards)
    implicit = CardFactorLogPosterior(model, index, theta_hat, Priors(), EPS, 0.1, cards)
    explicit = JointLogPosterior(FilmLayout(model, Priors(), EPS), theta_hat, [spec])
    u = np.random.default_rng(3).normal(0, 0.01, (8, implicit.n_dim))
    np.testing.assert_array_equal(explicit(u), implicit(u))
    np.testing.assert_array_equal(explicit.sensitivity, implicit.sensitivity)
    assert explicit.parameter_names == implicit.parameter_names


def test_the_flat_order_of_a_layout_does_not_change_the_posterior(film):
    """A permuted flat order (wavelength-major instead of [a.., log tau..]): the same density at
    the same physical point, the sensitivity's rows permuted alike, the same unpacked values."""
    ms, problem, model = film
    cards, index = card_indices(ms, problem)
    theta_hat = np.array([[0.3, 0.0], [0.1, 0.4]])
    spec = CardFactors(problem, index, 0.1, cards)
    usual = JointLogPosterior(model, theta_hat, [spec], Priors(), EPS)
    permuted = JointLogPosterior(_WavelengthMajorFilm(model, Priors(), EPS), theta_hat, [spec])
    assert permuted.parameter_names[:4] == ("r_a[450]", "r_log_tau[450]", "r_a[650]", "r_log_tau[650]")
    order = usual.blocks.ravel()  # usual flat position of each wavelength-major coordinate
    np.testing.assert_allclose(permuted.sensitivity, usual.sensitivity[order], rtol=1e-12, atol=1e-15)
    rng = np.random.default_rng(9)
    u = rng.normal(0, 0.01, (8, usual.n_dim))
    theta, phi = usual.theta_of(u)
    v = permuted.u_of(theta[:, order], phi)
    np.testing.assert_allclose(permuted(v), usual(u), rtol=1e-12)
    for mine, reference in zip(permuted.unpack(v), usual.unpack(u)):
        np.testing.assert_allclose(mine, reference, rtol=1e-12)


def test_film_thickness_prior_and_model_input():
    """Unknown films: log h ~ N(0, RELATIVE_SD^2) on +-THICKNESS_PRIOR_SDS sd; a measured film
    centred on log of its thickness; the model input is h per film."""
    spec = FilmThickness(["f1", "f2"], measured=[np.nan, 2.0])
    np.testing.assert_allclose(spec.mean, [0.0, np.log(2.0)])
    np.testing.assert_allclose(spec.upper - spec.lower, 2 * THICKNESS_PRIOR_SDS * spec.sd)
    assert spec.sd[0] == RELATIVE_SD
    x = np.array([[0.5, np.log(2.0)], [0.0, np.log(2.0) + spec.sd[1]]])
    np.testing.assert_allclose(spec.log_prior(x), [-0.5 * (0.5 / RELATIVE_SD) ** 2, -0.5])
    np.testing.assert_allclose(spec.model_inputs(x)["thickness"], np.exp(x))


@pytest.mark.parametrize("kwargs, message", [
    (dict(films=[]), "films must name at least one film"),
    (dict(films=["a", "a"]), "films must be distinct"),
    (dict(films=["a"], measured=[-1.0]), "measured thickness must be positive, got -1 for film 'a'"),
    (dict(films=["a"], measured=[1.0, 2.0]), r"measured must have one value per film \(1\)"),
    (dict(films=["a"], relative_sd=0.0), "relative_sd must be a positive number, got 0.0"),
])
def test_film_thickness_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        FilmThickness(**kwargs)


def test_card_factors_over_cards_is_the_spec_of_a_problem(film):
    """CardFactors.over_cards with a problem's cards and their largest albedo is the problem's
    spec (box, prior, model input); a card index -1 (no factor) gives a column of 1."""
    ms, problem, _ = film
    cards, index = card_indices(ms, problem)
    spec = CardFactors(problem, index, 0.1, cards)
    reflectance = [f for f in problem.films if f.kind == "reflectance"]
    r_s_max = [max(float(np.max(f.r_s)) for f, c in zip(reflectance, index) if c == card) for card in range(len(cards))]
    general = CardFactors.over_cards(index, r_s_max, 0.1, cards)
    for name in ("labels", "relative_sd", "n_cards"):
        assert getattr(general, name) == getattr(spec, name)
    for name in ("card_index", "lower", "upper", "nominal", "start_sd"):
        np.testing.assert_array_equal(getattr(general, name), getattr(spec, name))
    x = np.random.default_rng(1).normal(0.0, 0.1, (5, spec.size))
    np.testing.assert_array_equal(general.log_prior(x), spec.log_prior(x))
    np.testing.assert_array_equal(general.model_inputs(x)["r_s_scale"], spec.model_inputs(x)["r_s_scale"])
    partial = CardFactors.over_cards([0, -1, 1], [0.5, 0.9], 0.1, ["a", "b"])
    np.testing.assert_array_equal(partial.model_inputs(x[:, :2])["r_s_scale"],
                                  np.stack([np.exp(x[:, 0]), np.ones(5), np.exp(x[:, 1])], axis=1))
    np.testing.assert_allclose(partial.upper, [0.5, -np.log(0.9)])  # 5 sd, or where f r_s reaches 1


@pytest.mark.parametrize("args, message", [
    (([0, 2], [0.5, 0.5]), r"card_index must be card numbers 0\.\.1 \(or -1: no factor\), got \[0, 2\]"),
    (([0], []), "r_s_max needs one value per card"),
    (([0], [0.5], 0.1, ["a", "b"]), r"cards must name every card \(1\), got 2"),
    (([0], [0.5], -1.0), "relative_sd must be a positive number, got -1.0"),
])
def test_card_factors_over_cards_bad_arguments(args, message):
    with pytest.raises(ValueError, match=message):
        CardFactors.over_cards(*args)
