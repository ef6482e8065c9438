"""infer(censored_zeros=True) in the joint run: the layout's Tobit density with the incidence offset before
the clip, and the joint run's stored terms of exact zeros against the direct solver (the readings of
:mod:`tests.inference.test_incidence_offset`, with offsets that clip the 80 deg readings to 0)."""

import dataclasses

import numpy as np
import pytest
from scipy import stats

from bayespig.data import simulate
from bayespig.data.simulate import FilmSpec
from bayespig.inference import infer
from bayespig.inference.roughness import NoiseFloorFilmLayout
from bayespig.inference.settings import ConvergenceWarning
from bayespig.likelihood import ForwardModel, Priors, Problem
from bayespig.physics.forward import brdf

from .common import FAST
from .test_incidence_offset import (
    A_TRUE,
    ALPHA_TRUE,
    EPS_TRUE,
    FLOOR_TRUE,
    INSTRUMENT,
    OFFSET_TRUE,
    WAVELENGTHS,
    _readings,
)

pytestmark = pytest.mark.usefixtures("private_table_cache")

#: Offsets that clip the 80 deg readings (BRDF x cos theta_i there 0.0044 and 0.0016 1/sr): exact zeros.
CLIPPING_OFFSET = np.array([0.005, 0.002])


@pytest.fixture(scope="module")
def clipped_set():
    return simulate(a=A_TRUE, tau=1.0, design=[FilmSpec("paint", opaque=True)], instrument=INSTRUMENT,
                    wavelengths=WAVELENGTHS, eps=EPS_TRUE, seed=1, model=lambda **kw: _readings(**kw, offset=CLIPPING_OFFSET))


def test_censored_joint_run_stores_the_censored_terms_of_the_zeros(clipped_set):
    # the joint run's wiring: its stored log-likelihood of each exact zero is log Phi(-mu / sigma) with mu the
    # direct solver's BRDF at the draw less b / cos theta_i (not the Gaussian density at 0, ~ +5 here), and
    # its predictions are the readings max(mu, 0). A short run (capped, warned): readings clipped to zeros
    # make the joint run mix slowly, censored or not (capped at 20000 steps for 2 of 3 seeds, session 28)
    values = np.stack([np.concatenate([m.values[k:k + 1] for film in clipped_set.films for m in film.measurements])
                       for k in range(WAVELENGTHS.size)])  # (n_wl, n_values)
    zero = values == 0
    assert zero.sum() >= 4
    short = dataclasses.replace(FAST, max_steps=400, min_steps=400)
    with pytest.warns(ConvergenceWarning, match="capped"):
        idata = infer(clipped_set, eps=EPS_TRUE, settings=short, progress=False, roughness="free",
                      noise_floor="infer", incidence_offset=True, censored_zeros=True, seed=1)
    post = idata.posterior
    assert post.attrs["censored_zeros"] == 1
    channels = INSTRUMENT.channels
    theta_i = np.array([c.theta_i for c in channels])
    pointwise = idata.log_likelihood["y"].transpose("chain", "draw", "wavelength", ...).values
    predicted = idata.posterior_predictive["y"].transpose("chain", "draw", "wavelength", ...).values
    for chain, draw in ((0, 0), (3, 17)):
        alpha = float(post["roughness"].values[chain, draw, 0])
        for k in range(WAVELENGTHS.size):
            a = float(post["a"].values[chain, draw, k])
            b = float(post["incidence_offset"].values[chain, draw, k])
            floor = float(post["noise_floor"].values[chain, draw, k])
            f = brdf(theta_i, [c.theta_o for c in channels], [c.delta_phi for c in channels], a=a, tau=np.inf,
                     roughness=alpha)
            mu = f - b / np.cos(np.radians(theta_i))
            sd = np.sqrt((EPS_TRUE * f) ** 2 + floor ** 2)
            # the tables stand for the solver to 2e-4 relative: ~1e-5 in mu / sd here, 1e-3 in log L is a wide margin
            np.testing.assert_allclose(pointwise[chain, draw, k][zero[k]],
                                       stats.norm.logcdf(0.0, loc=mu, scale=sd)[zero[k]], rtol=0, atol=1e-3)
            np.testing.assert_allclose(predicted[chain, draw, k], np.maximum(mu, 0.0), rtol=1e-3, atol=1e-6)
    assert (pointwise[..., zero] <= 0).all()


def test_censored_layout_is_tobit_with_the_offset_before_the_clip(clipped_set):
    # zeros: log P(f - b s + noise <= 0) with sd sqrt((eps f)^2 + sigma0^2), scipy's normal cdf; positive
    # readings: the normal density around the unclipped mean; the prediction is the reading max(mu, 0)
    problem = Problem.from_measurements(clipped_set, "general")
    model = ForwardModel(problem, roughness=ALPHA_TRUE)
    layout = NoiseFloorFilmLayout(model, Priors(), EPS_TRUE, incidence_offset=True, censored_zeros=True)
    plain = NoiseFloorFilmLayout(model, Priors(), EPS_TRUE, incidence_offset=True)
    observed = layout.observed.copy()
    observed[:, -3:] = 0.0  # the 80 deg readings
    layout.observed = plain.observed = observed
    assert layout.names == ("a", "log_noise_floor", "log_incidence_offset")  # an opaque film: no tau
    theta = np.empty((2, WAVELENGTHS.size, layout.size))
    theta[..., 0] = A_TRUE
    theta[..., 1] = np.log(FLOOR_TRUE)
    theta[0, :, 2], theta[1, :, 2] = np.log(OFFSET_TRUE), np.log(4.0 * OFFSET_TRUE)  # the second clips at 80 deg
    inputs = {"roughness": np.full(2, ALPHA_TRUE)}
    mean = layout.predict(theta, inputs)
    f = mean + np.exp(theta[..., 2])[..., None] * layout.offset_scale
    assert (mean[1, :, -3:] < 0).all()  # not clipped
    np.testing.assert_array_equal(layout.reading(mean), np.maximum(mean, 0.0))
    np.testing.assert_array_equal(layout.reading(mean), plain.predict(theta, inputs))
    sd = np.sqrt((EPS_TRUE * f) ** 2 + FLOOR_TRUE ** 2)
    expected = np.where(observed == 0, stats.norm.logcdf(0.0, loc=mean, scale=sd),
                        stats.norm.logpdf(observed, loc=mean, scale=sd))
    np.testing.assert_allclose(layout.log_density(theta, mean), expected, rtol=1e-10, atol=1e-10)
