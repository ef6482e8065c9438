"""Substrate factor as a nuisance parameter (bayespig.substrate_nuisance)."""

import dataclasses

import numpy as np
import pytest

from bayespig.data import simulate
from bayespig.data.simulate import FilmSpec
from bayespig.likelihood import ForwardModel, Priors, Problem
from bayespig.substrate_nuisance import (
    SubstrateNuisancePosterior,
    card_indices,
    substrate_factor_posterior,
)
from bayespig.table import load_table

WAVELENGTHS = np.array([450.0, 550.0, 650.0])
TRUE_WHITE, STATED_WHITE = 0.88, 0.80  # the card seen from the binder is 10 % brighter than stated
EPS = 0.002


def _simulated(instrument):
    ms = simulate(a=np.array([0.3, 0.1, 0.05]), tau=np.array([1.0, 1.2, 1.5]),
                  design=[FilmSpec("ob", substrate=0.05, film_group="f"),
                          FilmSpec("ow", substrate=TRUE_WHITE, film_group="f")],
                  instrument=instrument, wavelengths=WAVELENGTHS, eps=EPS, seed=11)
    samples = tuple(dataclasses.replace(s, substrate=STATED_WHITE) if s.name == "ow" else s for s in ms.samples)
    return dataclasses.replace(ms, samples=samples)


def test_r_s_scale_equals_the_forward_model_with_scaled_substrate():
    # WavelengthModel(r_s_scale=f) against ForwardModel.predict of a problem whose r_s is f * r_s.
    ms = _simulated("multi-angle-45")
    problem = Problem.from_measurements(ms, "method4")
    tables = {}
    model = ForwardModel(problem, "isotropic", tables)
    f = np.array([[1.0, 1.1], [0.9, 1.2]])
    scaled = dataclasses.replace(problem, films=tuple(
        dataclasses.replace(film, r_s=film.r_s * f[1, k]) for k, film in enumerate(problem.films)))
    reference = ForwardModel(scaled, "isotropic", tables).predict(0, np.array([0.2]), np.array([[0.8]]))
    fast = model.at_wavelength(0)(np.array([0.2, 0.2]), np.array([[0.8], [0.8]]), None, f)
    np.testing.assert_allclose(fast[1], reference[0], rtol=1e-10)
    # below the table's first tau node the slow path is used, with the same scaling
    tiny = model.at_wavelength(0)(np.array([0.2]), np.array([[1e-4]]), None, f[1:])
    ref_tiny = ForwardModel(scaled, "isotropic", tables).predict(0, np.array([0.2]), np.array([[1e-4]]))
    np.testing.assert_allclose(tiny, ref_tiny, rtol=1e-10)
    # without the keyword nothing changes
    np.testing.assert_allclose(model.at_wavelength(0)(np.array([0.2]), np.array([[0.8]])),
                               ForwardModel(problem, "isotropic", tables).predict(0, [0.2], [[0.8]]), rtol=1e-12)


def test_posterior_recovers_a_known_card_factor():
    ms = _simulated("multi-angle-45")
    result = substrate_factor_posterior(ms, eps=EPS, seed=5, n_steps=1500, thin=5)
    assert result.cards == ("0.05", str(STATED_WHITE))
    _, low, high = result.summary(0.9)[str(STATED_WHITE)]
    truth = TRUE_WHITE / STATED_WHITE
    assert low < truth < high
    assert low > 1.0  # the data move the factor away from the prior's centre
    # the posterior is much narrower than the 10 % prior (90 % prior width ~0.33)
    assert high - low < 0.15


def test_bad_arguments():
    ms = _simulated("8d-sce")
    problem = Problem.from_measurements(ms, "method4")
    model = ForwardModel(problem, "isotropic", {"8d-sce": load_table("8d-sce", progress=False)})
    _, index = card_indices(ms, problem)
    with pytest.raises(ValueError, match="card_index"):
        SubstrateNuisancePosterior(model, index[:1], Priors())
    with pytest.raises(ValueError, match="relative_sd"):
        SubstrateNuisancePosterior(model, index, Priors(), relative_sd=0.0)
    post = SubstrateNuisancePosterior(model, index, Priors())
    n = WAVELENGTHS.size
    theta = post.pack(np.full((1, n), 0.1), np.full((1, n, 1), 1.0), np.array([[1.0, 1.3]]))
    assert post(theta)[0] == -np.inf  # r_s * f = 1.04 > 1 is outside the support
