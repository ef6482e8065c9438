"""Leave one film out: the held-out film's one free scalar, its thickness."""

import dataclasses

import numpy as np
import pytest

from bayespig.library.predict import predict_reflectance
from bayespig.library.validation import _fit_thickness

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
    h = _fit_thickness(library, RECIPE, library.constants[0], "8d-sce", pairs)

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
