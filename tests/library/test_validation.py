"""Leave one film out: the held-out film's one free scalar, its thickness, and the coverage of the
predictive regions whose model error is learned from the other films."""

import dataclasses

import numpy as np
import pytest
from scipy import stats

from bayespig.library.predict import calibration_factor, predict_reflectance
from bayespig.library.validation import FilmPrediction, _fit_thickness, conformal_scores, coverage

from .test_predict_match import PIGMENTS, WL, _library

RECIPE = dict(zip(PIGMENTS, (0.6, 0.3, 0.1)))
#: The bounded scalar search stops at 1e-4 in log h; this much more is its margin.
LOG_H_ATOL = 1e-3


def _spectra(library, h, card):
    return predict_reflectance(library, RECIPE, library.constants[:1], np.array([h]), instrument="8d-sce",
                               substrate=card)[0]


@pytest.mark.parametrize("noise_scale", ["measured", "model"])
def test_the_thickness_minimises_the_misfit_of_the_library_s_own_noise_scale(noise_scale):
    """A film the model cannot reproduce exactly (measured 20 % brighter over both cards, which
    ask for a thicker and a thinner film): its thickness is the minimum of the misfit relative to the library's noise scale, found
    again here by a grid, and the two scales' minima are apart."""
    library = dataclasses.replace(_library(), provenance={"noise_scale": noise_scale})
    black, white = np.full(WL.size, 0.05), np.full(WL.size, 0.8)
    pairs = [(name, card, 1.2 * _spectra(library, 1.5, card)) for name, card in (("black", black), ("white", white))]
    h = _fit_thickness(library, RECIPE, library.constants[0], "8d-sce", pairs, prior=False)

    def misfit(h_value, scale):
        total = 0.0
        for _, card, values in pairs:
            R = _spectra(library, h_value, card)
            total += np.sum(((values - R) / (values if scale == "measured" else R)) ** 2)
        return total

    grid = np.exp(np.linspace(np.log(0.3), np.log(8.0), 801))
    best = {scale: grid[np.argmin([misfit(g, scale) for g in grid])] for scale in ("measured", "model")}
    assert abs(np.log(best["measured"] / best["model"])) > 10 * LOG_H_ATOL  # the choice matters here
    assert grid[0] < min(best.values()) and max(best.values()) < grid[-1]  # inside the grid
    # the grid's spacing is 4.1e-3 in log h: half of it plus the search's tolerance
    assert abs(np.log(h / best[noise_scale])) < LOG_H_ATOL + 2.1e-3


@pytest.mark.parametrize("eps", [0.02, 0.2])
def test_the_thickness_is_the_mode_under_the_library_s_thickness_prior(eps):
    """A film drawn at h = 6, far outside the library's films (prior log h ~ N(log 2, 0.2^2)):
    without the prior its thickness comes back exactly; with it, the fit is the minimum of the
    standardized misfit (eps from the provenance) plus the prior's penalty, found again here by a
    grid, and lies between the prior's centre and the truth."""
    library = dataclasses.replace(_library(), provenance={"noise_scale": "measured", "eps": eps})
    mean, sd = library.thickness_prior
    black, white = np.full(WL.size, 0.05), np.full(WL.size, 0.8)
    pairs = [(name, card, _spectra(library, 6.0, card)) for name, card in (("black", black), ("white", white))]
    free = _fit_thickness(library, RECIPE, library.constants[0], "8d-sce", pairs, prior=False)
    h = _fit_thickness(library, RECIPE, library.constants[0], "8d-sce", pairs)
    assert abs(np.log(free / 6.0)) < LOG_H_ATOL

    def posterior(h_value):
        total = ((np.log(h_value) - mean) / sd) ** 2
        for _, card, values in pairs:
            total += np.sum(((values - _spectra(library, h_value, card)) / (eps * values)) ** 2)
        return total

    grid = np.exp(np.linspace(np.log(1.0), np.log(8.0), 801))
    best = grid[np.argmin([posterior(g) for g in grid])]
    assert grid[0] < best < grid[-1]
    # the grid's spacing is 2.6e-3 in log h: half of it plus the search's tolerance
    assert abs(np.log(h / best)) < LOG_H_ATOL + 1.3e-3
    assert np.exp(mean) < h < 6.0
    assert abs(np.log(h / 6.0)) > 10 * LOG_H_ATOL  # the prior moved it


#: Films and draws of the coverage test: 2 cards a film, the count inside Binomial(120, 0.9).
COVERAGE_FILMS, COVERAGE_DRAWS = 60, 200


def _held_out(n_films, error_sd_factor, seed):
    """Held-out predictions whose measured spectra are the prediction times ``1 + e``, ``e`` drawn
    from one true relative model error (5 % per band, correlated over ~50 nm) times
    ``error_sd_factor``; the draws carry no posterior spread, so the region is the model error's."""
    rng = np.random.default_rng(seed)
    wl = np.arange(400.0, 701.0, 10.0)
    distance = np.abs(wl[:, None] - wl[None, :])
    true_covariance = 0.05 ** 2 * np.exp(-distance / 50.0)
    spectrum = 0.2 + 0.4 * (wl - 400.0) / 300.0
    predictions = []
    for f in range(n_films):
        error = error_sd_factor * rng.multivariate_normal(np.zeros(wl.size), true_covariance, 2)
        measured = spectrum * (1.0 + error)
        draws = np.broadcast_to(spectrum, (2, COVERAGE_DRAWS, wl.size)).copy()
        predictions.append(FilmPrediction(f"F{f}", "radiative-transfer", {}, ("b", "w"), 1.0, (0.0, 0.0), (0.0, 0.0),
                                          measured / spectrum - 1.0, draws, measured, {}, 0.0, 0.0, True, 400.0))
    return predictions, wl


def test_the_regions_cover_at_their_level_when_the_model_error_is_learned_right():
    """The measured spectra scatter about the predictions as the other films' residuals do: the
    90 % regions hold them at the nominal rate (the count inside within the central 99.8 % of
    Binomial(120, 0.9), 99 .. 115; the learned covariance and the 200-draw radius add a little
    spread; measured 108-109 over three seeds)."""
    predictions, wl = _held_out(COVERAGE_FILMS, 1.0, seed=7)
    counts, inside, radius = coverage(predictions, wl, level=0.9, seed=1)
    hits, total = counts["radiative-transfer"]
    assert total == 2 * COVERAGE_FILMS and len(inside) == COVERAGE_FILMS
    low, high = stats.binom(total, 0.9).ppf([0.001, 0.999])
    assert low <= hits <= high, (hits, total)
    assert all(r > 0 for radii in radius.values() for r in radii)


def test_the_calibration_widens_a_model_error_learned_too_small():
    """The residuals the covariance is learned from half the films' true errors (a model error
    4 x too small in variance): the uncalibrated regions hold far fewer than 90 % (measured 48-52
    of 120 over three seeds; the bound 60 %), the calibrated ones the nominal rate again (the
    binomial bounds of the test above; measured 108-109)."""
    predictions, wl = _held_out(COVERAGE_FILMS, 1.0, seed=7)
    halved = [dataclasses.replace(p, residuals=0.5 * p.residuals) for p in predictions]
    scores, _ = conformal_scores(halved, wl, 0.9, np.random.default_rng(1))
    assert np.mean(np.array(list(scores.values())) <= 1.0) < 0.6
    counts, _, _ = coverage(halved, wl, level=0.9, seed=1)
    hits, total = counts["radiative-transfer"]
    low, high = stats.binom(total, 0.9).ppf([0.001, 0.999])
    assert low <= hits <= high, (hits, total)


def test_the_calibration_factor_is_the_conformal_rank():
    """The ceil((n + 1) level)-th smallest score: for 19 scores at 0.9 the 18th; fewer than 9 at
    0.9: the largest; bad scores refused."""
    scores = np.random.default_rng(3).permutation(np.arange(1.0, 20.0))
    assert calibration_factor(scores, 0.9) == 18.0
    assert calibration_factor(scores, 0.5) == 10.0
    assert calibration_factor([0.2, 0.5, 0.1], 0.9) == 0.5
    for bad in ([], [np.nan, 1.0], [-1.0, 1.0]):
        with pytest.raises(ValueError, match="scores must be finite and >= 0"):
            calibration_factor(bad, 0.9)
