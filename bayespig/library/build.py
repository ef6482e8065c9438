"""Building a pigment library: every pigment's constants from all films that contain it.

Each film (a :class:`~bayespig.data.MeasurementSet` of one film group, e.g. a Revigo drawdown
over its black and white cards) has a recipe (``metadata["composition"]``); its values follow
from the constants of its pigments, mixed by their concentrations, at its thickness ``h``,
through a :class:`FilmModel` (radiative transfer: per pigment and wavelength ``[a_i, log
sigma_i]``; the mixing rules of paper section 2). The posterior is the one joint machinery for
parameters shared over wavelengths (:mod:`bayespig.inference.shared`): per wavelength a block of
the constants being fitted (:class:`LibraryLayout`, ``k = 2 * n_pigments``), and the films'
thicknesses as the shared spec (:class:`bayespig.inference.film_thickness.FilmThickness`, prior
``log h ~ N(0, 0.5^2)`` unless measured): residual coordinates, block moves, one run per stage.

The cards' uncertainty (``substrate_sd=``, as :func:`bayespig.infer`'s): every card each film
is measured over gets a factor on its albedo, ``r_s = f r_s,card`` at every wavelength, ``log f
~ N(0, substrate_sd^2)``, one per card and film (:func:`card_factor_spec`; the spec
:class:`~bayespig.inference.card_factors.CardFactors` of ``infer``, over the cards of all the
stage's films), sampled in the same joint run with the thicknesses and entering every film's
prediction through :meth:`~bayespig.library.film_models.FilmPredictor.values`' ``r_s_scale``
(both film models). Default None as in ``infer``: the cards as converted from their
measurements. Simulated (``tests/library/test_build.py``): a white card 10 % brighter than
measured left its film at 1.5 % rms against 1 % noise and 9 of 12 constants inside their 90 %
intervals without factors; with ``substrate_sd=0.1`` the factor's 90 % interval was [1.04,
1.16] around the true 1.1, the film at 0.1 %, 12 of 12 inside (the stage 20 s against 14 s).
On Revigo series 06 (Vermillion from 06A-06E, on a base library of series 07; 2 shared cores)
the factors mix (not capped, R-hat <= 1.006, ESS >= 1054 for every factor) but cost: 10 shared
coordinates more (15), 60 walkers instead of 20, 9 351 steps and 643 s against 1 701 steps and
65 s without (Kubelka-Munk: 7 730 steps, 211 s against 1 821, 41 s); the base stage (07A,
07C-07F) at a 6 000-step cap: R-hat 1.020 with factors, 1.054 without, 324 s against 187 s;
with :data:`DEFAULT_SETTINGS` and factors it stopped at the 20 000-step cap (940 s, load 3-4)
with R-hat <= 1.006 and ESS >= 791 for every thickness, constant and factor (the run-length
rule's autocorrelation-time multiple, not R-hat or ESS, was unmet).
Most factors stay near their prior (black cards) or within a few per cent of 1 (white cards),
but 06D's white card went to the truncation of its prior (``f = 0.61``, thickness 1.18 -> 0.27,
both film models): the factor absorbed a misfit of that film (its record marks it
``implausible``, :data:`IMPLAUSIBLE_SDS`).

The recipes' uncertainty (``concentration_sd=``): a factor ``f`` on the effective concentration
of each film's minor pigments fixed from an earlier stage, ``D_eff = f D``, ``log f ~ N(0,
concentration_sd^2)`` (:func:`concentration_factor_spec`, the spec
:class:`~bayespig.inference.concentration_factors.ConcentrationFactors`), sampled in the same
joint run; it enters through the film models' log-linear coordinates
(:attr:`~bayespig.library.film_models.FilmModel.log_linear`; the mixing rules are linear in
``D``). Revigo, on the base library of 07A, 07C-07F (leave-one-out settings), ΔE00 over black /
white without -> with ``concentration_sd=0.3``: 12C from 12A, 12B, 12D 2.39 / 5.80 -> 1.18 /
1.80 (Kubelka-Munk 1.28 / 6.06 -> 1.06 / 1.85), 12D's black going to the prior's truncation
(``f = 3.32``; with sd 1.0 to ``f = 9.3``, 12C 1.54 / 1.42): a black acting ~9 x its recipe's
amount in cobalt blue is no weighing error but a bone black that the zinc-white greys do not
describe in this mixture. 14B from 14A, 14C-14E 4.97 / 5.06 -> 5.56 / 5.72 (Kubelka-Munk 5.44
/ 5.46 -> 6.04 / 6.09): 14D's and 14E's black go to ``f`` 0.30 / 0.45 (sd 1.0: 0.12 / 0.31)
and 14A stays at 20 % rms, since no positive amount of black makes chrome yellow lighter, as
14D and 14E are below 500 nm.

Stages: a cut (modular) posterior
---------------------------------
One joint posterior over a whole palette (Revigo: 20 pigments x 2 constants x 31 bands plus 84
thicknesses) is too big for the block sampler, so the library is built in stages
(:func:`stage_plan`), each stage one joint run per independent group of pigments:

1. the *base* pigments (default: those present in at least :data:`BASE_SHARE` of the films;
   Revigo: ZincWhite and BoneBlack; ``base_pigments=`` overrides) jointly, from the films made
   of base pigments only;
2. repeatedly, every pigment that is the only not-yet-fitted pigment of some remaining films,
   from those films, the pigments fitted before *fixed at their own stage's joint least-squares
   point* (``provenance["stage_points"]``, see "Stages" below); pigments of one stage are
   independent groups, run in parallel through the executor;
3. whatever is left (films with two or more unfitted pigments, none of which can be isolated):
   their pigments jointly, per connected group.

This is not the full joint posterior: information flows only forward (a tint film informs the
tinting pigment, never the white it was fitted with), the fixed pigments' uncertainty is not
propagated into the later stages' fits, and a film all of whose pigments were fitted before it
could be used (Revigo: the two-colour mixtures 08D-08G, 16D-16F, 17D, 17F) is not used at all
(marked ``used=False`` in :attr:`PigmentLibrary.films`; a candidate for validation). The
library's draws of each pigment are those of its own stage, independent between stages; a later
stage's draws are valid only *together with the values its fixed pigments were fixed at*
(``provenance["conditioning"]``: each pigment's fixed pigments and those values), and a
prediction must pair them so (:func:`bayespig.library.predict.joint_constants`). Pairing them
with independent draws of the fixed pigments instead mispredicts wherever the earlier stage left
a direction unidentified: Revigo's white and black films hide their cards below ~510 nm, so
there ``log sigma`` of both is bounded only from below (posterior sd 2.4, against 0.3 above), and
a vermilion fitted relative to the fixed white's ``sigma`` predicted its 50/50 tint 06C at ΔE00
10.7 with independent white draws, 1.0 with the fixed one. Where an
earlier pigment's posterior is wide (a nearly opaque white's ``sigma`` is bounded only from
below by its films), its median is a poor point to fix, and the later films it tints can then
be fitted worse than their noise: each film's ``rms_log_deviation`` shows it (simulated: a white
of ``tau ~ 15`` left a 10 % tint at 5.8 % rms against 1 % noise; at ``tau ~ 7`` all films fit
to 0.1-1.3 %).

Which point: each stage's joint least-squares fit (:func:`joint_least_squares_start`, the
constants and thicknesses at the cards as measured; the same fit that starts the stage's
walkers), recorded as ``provenance["stage_points"]`` and inherited from a base library. Until
2026-12-04 it was the stage's draw nearest its marginal medians (:func:`representative_draw`).
Where the earlier films identify the constants the two are a fraction of a posterior sd apart
(simulated, ``tests/library/test_build.py``: at most 0.13 sd). Where they do not, the draw
is one arbitrary point of a flat direction, the fit the one the films' own residuals single
out, and the later pigment fitted on the draw follows it there: Revigo 03D's eosin ``log sigma``
at 400-460 nm went to +2 ... +6 on the draw against -1.3 on the fit, the white's and black's
``log sigma`` being up to 7.7 apart at 410 nm (``benchmarks/stage_fixing.py``). Leave one film
out, ΔE00 over black / white on the draw -> on the fit (10 films, leave-one-out settings):
01C 15.08 / 13.92 -> 10.16 / 9.19, 02C 10.00 / 8.11 -> 7.26 / 6.18, 03C 3.30 / 3.75 -> 1.77 /
2.61, 03D 3.03 / 9.74 -> 1.10 / 1.80, 11D 3.81 / 4.97 -> 2.92 / 1.20; worse: 12C 3.23 / 4.57
-> 1.58 / 5.42, 09C 3.33 / 2.23 -> 3.63 / 3.62. All 54 mixture films of series 01-15 (``bayespig
colour-prediction``, ``reports/colour-prediction.md``), median ΔE00 white tints / black shades /
all, fitted thickness: 2.71 / 2.02 / 2.40 -> 2.52 / 1.77 / 2.28 (Kubelka-Munk 2.49 / 1.84 / 2.32
-> 2.49 / 1.83 / 2.32); 31 films better, 19 worse, the worst 12D (5.88 / 5.94 -> 10.74 /
10.71: the cobalt blue fitted on the point predicts the shade too dark at 400 nm, and its
fitted thickness runs to 29) and 15C (3.94 / 3.52 -> 5.63 / 5.07). The 90 % predictive
regions covered 99 % of the cards against 94 % before, too wide; with the model error's
calibration (:func:`bayespig.library.predict.calibration_factor`) 89 % (Kubelka-Munk 90 %).

Measured on the 84 Revigo films (``benchmarks/library.py``, 2 cores shared with other work, load
average 6-9): stage 1 (ZincWhite, BoneBlack from 07A, 07C-07F) needs 19 576 steps (877 s) to
converge; the 18 groups of stage 2 converge in 656-3 933 steps (25-273 s each; ZincWhiteLinseed,
one film, reached a 5 000-step cap), 854 s on 2 processes; 9 films unused. The fit is not yet
good: median rms of ``log(measured / predicted)`` 6 % per film against ``eps = 2 %``, worst
16A (BariumSulphate masstone, 29 %), 11A, 11D, 14A (20-24 %): the shades and tints of a pigment
pull against its masstone when the fixed white and black are only their medians.

The figures above this paragraph were measured with eq. (7)'s noise scale (``noise_scale="model"``,
the default before the measured scale).

Noise: every value has the known relative error ``eps``, relative to the *measured* value by
default (``noise_scale="measured"``; eq. 7's scale, the predicted value, with ``"model"``). The
two agree where a film is reproduced; where it is not they decide which films give way
(:data:`NOISE_SCALES`). Revigo, leave one film out, median ΔE00 over black and white with the
fitted thickness, eq. (7) -> the measured scale, radiative transfer / Kubelka-Munk:

- series 06, 12, 14 (11 tints and shades; eq. 7 with the per-wavelength start of session 9's
  report, the measured scale with the joint start below): 2.44 / 2.43 -> 1.94 / 1.83; 14B
  (chrome yellow 9 % in zinc white) 4.97 / 5.06 -> 1.04 / 1.28 and 5.44 / 5.46 -> 0.54 / 0.60
  (the joint start alone, with eq. 7, left Kubelka-Munk's 14B at 5.42 / 5.49: the noise scale
  made that change);
- series 09, 13 (8 films, both with the joint start; ``bayespig colour-prediction --series
  09,13 --noise-scale model``, and the full study): 1.82 / 1.94 -> 2.27 / 2.34, worse: the
  viridian shades 09D, 09E lose 0.6-1.3;
- the 19 films together: white tints 2.38 / 2.08 -> 2.07 / 1.69, black shades 1.86 / 2.12 ->
  2.27 / 2.38, all 2.35 / 2.12 -> 2.22 / 2.00; 11 (radiative transfer) and 13 (Kubelka-Munk)
  of the 19 films predicted better. The measured scale helps the tints and costs the shades:
  a shade lighter than its pigments can make is given up rather than followed;
- all 54 mixture films of series 01-15 (``bayespig colour-prediction`` with and without
  ``--noise-scale model``, both with the joint start): white tints 2.81 / 2.52 -> 2.56 / 2.40,
  black shades 1.97 / 1.95 -> 2.18 / 1.83, all 2.44 / 2.27 -> 2.37 / 2.29; 32 (radiative
  transfer) and 34 (Kubelka-Munk) of the 54 films predicted better. A weak preference, chosen
  on the films it is reported on.

The whole palette (``python benchmarks/library.py``, 84 films, default settings, 2 cores): 562 s
(stage 1 274 s, at its 20 000-step cap with R-hat <= 1.009 and ESS >= 668; the 18 groups of
stage 2 in 616-14 163 steps, none capped, 288 s), against 877 + 854 s before.

Start of each run: a per-wavelength least-squares fit of the stage's constants at the nominal
thicknesses (``h = 1``, or the measured ones; best of a few starts per wavelength), then the
constants and the films' thicknesses fitted together (:func:`joint_least_squares_start`; the
thickness prior as a penalty), the walkers in a small ball (:data:`START_BALL_SD`) around that
and the thickness spec's start there; the adaptation run of
:func:`~bayespig.inference.shared.sample_blocks` then spreads them before the run proper.
Convergence: the run-length rule of the per-wavelength runs on the joint vector (R-hat and ESS
of every coordinate on the thinned chain, :data:`DEFAULT_SETTINGS`); each stage's R-hat, ESS,
steps and cap are in :attr:`PigmentLibrary.stages`.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import sys
import time
from concurrent.futures import as_completed
from pathlib import Path

import numpy as np
from scipy import optimize, sparse

from .._pool import executor_or_local_pool
from .._validation import flag
from .._versions import package_versions
from ..inference.arguments import check_substrate_sd
from ..inference.card_factors import FACTOR_PRIOR_SDS, CardFactors, card_indices
from ..inference.concentration_factors import (CONCENTRATION_PRIOR_SDS, ConcentrationFactors,
                                               check_concentration_sd)
from ..inference.film_thickness import FilmThickness
from ..inference.settings import InferenceSettings
from ..inference.shared import BlockLayout, sample_blocks
from .film_models import FILM_MODELS, film_model as _named_film_model
from .library import PigmentLibrary
from .recipes import concentrations, film_recipes

__all__ = [
    "BASE_SHARE",
    "DEFAULT_SETTINGS",
    "IMPLAUSIBLE_SDS",
    "LIBRARY_EPS",
    "START_BALL_SD",
    "DEFAULT_NOISE_SCALE",
    "LibraryLayout",
    "NOISE_SCALES",
    "build_library",
    "check_noise_scale",
    "implausible_factor",
    "joint_least_squares_start",
    "stage_plan",
]

#: What a film value's relative error ``eps`` is relative to (:class:`LibraryLayout`'s
#: ``noise_scale``): ``"measured"``, sd = ``eps`` times the measured value, or ``"model"``, sd =
#: ``eps`` times the predicted value (eq. 7). They agree where the films are reproduced and
#: differ where a film is not: eq. (7)'s cost of a value predicted too low grows without bound as
#: the prediction falls, while predicting it too high costs at most ``1 / (2 eps^2)``; with the
#: measured value as the scale it is the other way round. Unmodelled light in sphere data is
#: mostly *added* light (surface scatter outside the specular port, a film's gloss): a black shade
#: of chrome yellow lighter below 500 nm than any positive amount of bone black can make it
#: (Revigo 14D, 14E). Under eq. (7) such a film is followed at the cost of its pigment's masstone
#: (14A predicted too light, at a bounded cost): the chrome yellow from 14A, 14C-14E then predicts
#: its tint 14B (left out) at ΔE00 5.44 / 5.46 over black / white (Kubelka-Munk; radiative
#: transfer 4.97 / 5.06), with the measured scale at 0.54 / 0.60 (1.04 / 1.28); the module
#: docstring has the medians (``bayespig colour-prediction --series 06,12,14``).
NOISE_SCALES = ("measured", "model")
DEFAULT_NOISE_SCALE = "measured"
#: Default base pigments: those with a nonzero amount in at least this share of the films.
BASE_SHARE = 0.25
#: Default relative error of every film value (:func:`build_library`'s ``eps``).
LIBRARY_EPS = 0.02
#: Sampler settings of every stage's run (the library's draws: n_ensembles * draws_per_chain).
DEFAULT_SETTINGS = InferenceSettings(target_ess=400.0, draws_per_chain=256, max_steps=20000)
#: Sd of the walkers' start ball around the least-squares fit, in the sampled coordinates
#: (``a`` and ``log sigma``); less near the box's edge (0.3 of the distance to it).
START_BALL_SD = 0.01
#: Start points of the per-wavelength least-squares fit: ``(a, sigma)`` of every pigment.
LEAST_SQUARES_STARTS = ((0.01, 3.0), (0.3, 30.0), (0.001, 300.0), (0.6, 3.0))
#: Most residual evaluations of the joint least-squares start (:func:`joint_least_squares_start`).
JOINT_START_NFEV = 400
#: Coordinates named in each stage record's ``slowest_coordinates``.
SLOWEST_REPORTED = 5
#: Points of the start ball (draws of :func:`~bayespig.inference.shared.sample_blocks`).
START_POINTS = 64
#: A card factor whose whole 90 % interval lies beyond this many prior sds of ``log f`` is
#: marked ``implausible`` in the film's record (a card off by that much is not the ~10 % of the
#: paper's section 3.4: the factor absorbs a misfit of the film; Revigo 06D's white card went to
#: the prior's 5-sd truncation, f = 0.61, with its thickness from 1.18 to 0.27).
IMPLAUSIBLE_SDS = 3.0


def check_noise_scale(noise_scale):
    """``noise_scale`` if it is one of :data:`NOISE_SCALES`, else ValueError naming it."""
    if noise_scale not in NOISE_SCALES:
        raise ValueError(f"noise_scale must be one of {', '.join(map(repr, NOISE_SCALES))}, got {noise_scale!r}")
    return noise_scale


def implausible_factor(q05, q95, relative_sd):
    """Whether a nuisance factor ``f`` (a card's, a concentration's; prior ``log f ~ N(0, sd^2)``)
    absorbs a misfit of its film rather than measures what it stands for: its whole 90 % interval
    ``[q05, q95]`` lies beyond :data:`IMPLAUSIBLE_SDS` prior sds (prior mass 0.3 %). Revigo 06D's
    white card (0.61 at sd 0.1) and the black of 12D (3.3 at sd 0.3) and 14D (0.30) are such."""
    return bool(np.log(q05) > IMPLAUSIBLE_SDS * relative_sd or np.log(q95) < -IMPLAUSIBLE_SDS * relative_sd)

def _film_model(name):
    if name not in FILM_MODELS:
        raise ValueError(f"model must be one of {sorted(FILM_MODELS)}, got {name!r}")
    return _named_film_model(name)


class LibraryLayout(BlockLayout):
    """Block per wavelength: the constants ``[a_p, log sigma_p]`` of the pigments being fitted.

    The films' values from the fitted pigments' block, the fixed pigments' constants (earlier
    stages' medians), every film's thickness (model input ``thickness``, (W, n_films)) and,
    with card factors (:class:`~bayespig.inference.card_factors.CardFactors`), the factor on
    every reflectance film's card albedo (model input ``r_s_scale``, (W, n_reflectance): the
    films' reflectance films concatenated in film order, :attr:`scale_slices`).

    Parameters
    ----------
    film_model : FilmModel
    predictors : sequence of FilmPredictor
        One per film (``for_film``), all on the same wavelengths.
    film_concentrations : numpy.ndarray
        ``D`` of every film over ``fitted + fixed`` pigments, (n_films, n_fitted + n_fixed).
    fitted : sequence of str
        The pigments whose constants the block holds.
    fixed_constants : numpy.ndarray, optional
        Constants of the fixed pigments, (n_wl, n_fixed, 2).
    eps : float
        Known relative error of films without their own [-].
    wavelength_nm : numpy.ndarray
    noise_scale : {"measured", "model"}
        What the relative error ``eps`` is relative to (:data:`NOISE_SCALES`): the sd of a
        value is ``eps`` times the measured value (default) or times the predicted value
        (eq. 7 as :func:`bayespig.infer` uses it).
    """

    def __init__(self, film_model, predictors, film_concentrations, fitted, fixed_constants, eps, wavelength_nm,
                 noise_scale=DEFAULT_NOISE_SCALE):
        self.noise_scale = check_noise_scale(noise_scale)
        self.film_model = film_model
        self.predictors = tuple(predictors)
        self.fitted = tuple(fitted)
        self.concentrations = np.asarray(film_concentrations, dtype=float)
        self.wavelength_nm = np.asarray(wavelength_nm, dtype=float)
        n_wl = self.wavelength_nm.size
        self.fixed = (np.zeros((n_wl, 0, 2)) if fixed_constants is None
                      else np.asarray(fixed_constants, dtype=float))
        self.names = tuple(f"{c}[{p}]" for p in self.fitted for c in film_model.constant_names)
        P = len(self.fitted)
        self.lower = np.tile(np.asarray(film_model.lower, dtype=float), (n_wl, P))
        self.upper = np.tile(np.asarray(film_model.upper, dtype=float), (n_wl, P))
        self.observed = np.concatenate([p.observed for p in self.predictors], axis=1)
        self.eps = np.concatenate([np.where(np.isfinite(p.eps), p.eps, eps) * np.ones(p.observed.shape[1])
                                   for p in self.predictors])
        if self.noise_scale == "measured" and not (self.observed > 0).all():
            raise ValueError("noise_scale='measured' needs every measured value > 0 (the sd is eps times it); "
                             "use noise_scale='model'")
        #: (film index, pigment column) of each concentration factor (set by the spec's builder)
        self.factor_index = ()
        self.value_slices, self.scale_slices = [], []
        start = scale_start = 0
        for p in self.predictors:
            self.value_slices.append(slice(start, start + p.observed.shape[1]))
            self.scale_slices.append(slice(scale_start, scale_start + p.n_reflectance_films))
            start += p.observed.shape[1]
            scale_start += p.n_reflectance_films

    @property
    def scale_symmetry(self):
        """``(block mask, "film_thickness")``: the values depend on ``log h`` and the film model's
        log-linear coordinates (:attr:`~bayespig.library.film_models.FilmModel.log_linear`) only
        through their sum (``tau = h sum_i D_i sigma_i``; Kubelka-Munk ``K h``, ``S h``), see
        :attr:`bayespig.inference.shared.JointLogPosterior.scale_direction`. None when pigments of
        an earlier stage are fixed: their constants do not follow, so the symmetry is broken."""
        if self.fixed.shape[1]:
            return None
        return np.tile(np.asarray(self.film_model.log_linear, dtype=float), len(self.fitted)), "film_thickness"

    def constants(self, theta):
        """Every pigment's constants (W, n_wl, n_fitted + n_fixed, 2) from blocks (W, n_wl, k)."""
        W, n_wl = theta.shape[:2]
        fitted = theta.reshape(W, n_wl, len(self.fitted), 2)
        fixed = np.broadcast_to(self.fixed, (W,) + self.fixed.shape)
        return np.concatenate([fitted, fixed], axis=2)

    def film_constants(self, constants, f, log_factor):
        """Film ``f``'s constants with its minor pigments' concentration factors applied.

        ``D_i -> f_i D_i`` is ``+ log f_i`` on the coordinates the mixing rule weights by the
        concentration (:attr:`~bayespig.library.film_models.FilmModel.log_linear`).
        """
        columns = [(k, j) for k, (film, j) in enumerate(self.factor_index) if film == f]
        if log_factor is None or not columns:
            return constants
        shift = np.zeros((constants.shape[0], 1) + constants.shape[2:])
        mask = np.asarray(self.film_model.log_linear, dtype=float)
        for k, j in columns:
            shift[:, 0, j, :] = log_factor[:, k, None] * mask
        return constants + shift

    def standardized_residual(self, values):
        """``(observed - values) / sd`` of every value, the sd ``eps`` times the measured or the
        predicted value (:attr:`noise_scale`); ``values`` (..., n_wl, n_values)."""
        scale = self.observed if self.noise_scale == "measured" else values
        return (self.observed - values) / (self.eps * scale)

    def log_density(self, theta, values):
        """Pointwise log-likelihood (W, n_wl, n_values): normal with sd ``eps`` times the measured
        value, or eq. (7) (sd ``eps`` times the predicted value; :attr:`noise_scale`)."""
        if self.noise_scale == "model":
            return super().log_density(theta, values)
        return -0.5 * self.standardized_residual(values) ** 2 - self._log_sd_measured

    @functools.cached_property
    def _log_sd_measured(self):
        return np.log(self.eps * self.observed) + 0.5 * np.log(2.0 * np.pi)

    def predict(self, theta, inputs):
        """Values of every film, concatenated, (W, n_wl, n_values)."""
        constants = self.constants(theta)
        thickness = inputs["thickness"]
        scale = inputs.get("r_s_scale")
        log_factor = inputs.get("concentration_log_factor")
        return np.concatenate([p.values(self.film_constants(constants, f, log_factor), c, thickness[:, f],
                                        r_s_scale=None if scale is None else scale[:, self.scale_slices[f]])
                               for f, (p, c) in enumerate(zip(self.predictors, self.concentrations))], axis=2)


def card_factor_spec(films, sets, predictors, substrate_sd):
    """The card factors of a stage group's films: one per card and film (the spec of the joint run).

    As :func:`bayespig.infer` with ``substrate_sd`` does for one film
    (:mod:`bayespig.inference.card_factors`): each card ``c`` a film is measured over gets a
    factor, ``r_s = f r_s,card`` at every wavelength, ``log f ~ N(0, substrate_sd^2)``
    truncated at its :data:`~bayespig.inference.card_factors.FACTOR_PRIOR_SDS` sds and at
    ``f r_s <= 1``; here the cards of all the group's films, each film's its own (a card of one
    film is not another's, even if named alike). A film that hides its card (opaque) gets no
    factor there (``r_s = 0``). The largest albedo of a card is that of the film model's view of
    it: ``r_s`` seen from the binder, or Kubelka-Munk's internal card reflectance.

    Parameters
    ----------
    films : sequence of str
        Film ids, in the layout's order.
    sets : sequence of MeasurementSet
    predictors : sequence of FilmPredictor
    substrate_sd : float
        Prior sd of ``log f`` [-].

    Returns
    -------
    tuple
        ``(spec, cards)``: the :class:`~bayespig.inference.card_factors.CardFactors` over the
        cards (labels ``"<film>/<card>"``; None when no film shows a card), and per film the
        names of its cards in the spec's order (tuple of tuples of str).
    """
    index, r_s_max, labels, per_film = [], [], [], []
    for film, ms, predictor in zip(films, sets, predictors):
        names, film_index = card_indices(ms, predictor.problem)
        reflectance = [f for f in predictor.problem.films if f.kind == "reflectance"]
        backgrounds = getattr(predictor, "backgrounds", None)  # Kubelka-Munk: internal card reflectance
        local = {}
        for k, (film_k, c) in enumerate(zip(reflectance, film_index)):
            if film_k.opaque or names[c] == "hidden":
                index.append(-1)
                continue
            if c not in local:
                local[c] = len(labels)
                labels.append(f"{film}/{names[c]}")
                r_s_max.append(0.0)
            j = local[c]
            albedo = float(np.max(film_k.r_s))
            if backgrounds is not None:
                albedo = max(albedo, float(np.max(backgrounds[k])))
            r_s_max[j] = max(r_s_max[j], albedo)
            index.append(j)
        per_film.append(tuple(names[c] for c in sorted(local, key=local.get)))
    if not labels:
        return None, tuple(per_film)
    return CardFactors.over_cards(index, r_s_max, substrate_sd, labels), tuple(per_film)


def concentration_factor_spec(films, film_concentrations, pigments, concentration_sd, n_fitted=0):
    """The concentration factors of a stage group's films: one per minor *fixed* pigment of each film.

    A film's minor pigments are those of nonzero concentration other than its dominant one
    (largest ``D``, the first on a tie; a factor on every pigment would be the film's
    thickness); a film of one pigment gets none
    (:mod:`bayespig.inference.concentration_factors`). Only the pigments fixed from earlier
    stages get one (the black of a shade, the white of a tint where the colour dominates), not
    those being fitted: a factor on the fitted pigment of a tint frees the tint from its
    masstone, which is what the tint is to inform (Revigo 12B's cobalt blue went to ``f = 3.0``
    with one, and 12C was then predicted at ΔE00 6.56 / 7.40 against 2.39 / 5.80 without
    factors).

    Parameters
    ----------
    films : sequence of str
    film_concentrations : numpy.ndarray
        ``D`` of every film over ``pigments``, (n_films, n_pigments).
    pigments : sequence of str
        The layout's pigment order (fitted then fixed).
    concentration_sd : float
        Prior sd of ``log f`` [-].
    n_fitted : int
        The first ``n_fitted`` of ``pigments`` are being fitted (no factor).

    Returns
    -------
    tuple
        ``(spec, index)``: the :class:`~bayespig.inference.concentration_factors.ConcentrationFactors`
        (None when no film has a minor pigment) and its ``(film index, pigment column)`` pairs.
    """
    index = []
    for f, D in enumerate(np.asarray(film_concentrations, dtype=float)):
        dominant = int(np.argmax(D))
        index += [(f, j) for j in np.flatnonzero(D > 0) if j != dominant and j >= n_fitted]
    if not index:
        return None, ()
    spec = ConcentrationFactors([films[f] for f, _ in index], [pigments[j] for _, j in index], concentration_sd)
    return spec, tuple((int(f), int(j)) for f, j in index)


def representative_draw(constants):
    """Index of the draw nearest the marginal medians (every coordinate in units of its sd).

    What a later build fixes a *base library's* pigments at when that library was saved without
    its stage points (``provenance["stage_points"]``, recorded since 2026-12-04; see "Stages" in
    the module docstring). One *joint* draw, so that correlated constants (a white's ``sigma``
    and a black's along their films' thickness ravine) stay consistent with each other, which
    the marginal medians are not (simulated white + black: fixing their marginal medians
    mispredicted a 50/50 tint by 47 %, this draw by ~1 %).

    Parameters
    ----------
    constants : numpy.ndarray
        (n_draws, n_wl, n_pigments, 2) draws of the sampled coordinates.
    """
    flat = constants.reshape(constants.shape[0], -1)
    sd = flat.std(axis=0)
    z = (flat - np.median(flat, axis=0)) / np.where(sd > 0, sd, 1.0)
    return int(np.argmin((z * z).sum(axis=1)))


def _base_pigments(recipes):
    films = len(recipes)
    counts = {}
    for recipe in recipes.values():
        for pigment in recipe.amounts:
            counts[pigment] = counts.get(pigment, 0) + 1
    return tuple(sorted(p for p, n in counts.items() if n >= BASE_SHARE * films))


def _components(films_pigments):
    """Connected groups of pigments over films: list of (pigments, films)."""
    groups = []
    for film, pigments in films_pigments.items():
        merged = [g for g in groups if g[0] & pigments]
        pig, fil = set(pigments), [film]
        for g in merged:
            groups.remove(g)
            pig |= g[0]
            fil += g[1]
        groups.append((pig, fil))
    return [(tuple(sorted(p)), tuple(sorted(f))) for p, f in sorted(groups, key=lambda g: sorted(g[0]))]


def stage_plan(recipes, base_pigments=None, known=()):
    """The stages of the build (see the module docstring).

    Parameters
    ----------
    recipes : dict
        Film id -> Recipe.
    base_pigments : sequence of str, optional
        Default: pigments with a nonzero amount in at least :data:`BASE_SHARE` of the films.
    known : sequence of str
        Pigments fitted already (a base library's): no stage fits them, films made of them only
        are unused.

    Returns
    -------
    tuple
        ``(stages, unused)``: a list of stages, each a list of groups ``(pigments, films)``
        (tuples of str) run independently; and the films used by no stage (tuple of str).
    """
    base = _base_pigments(recipes) if base_pigments is None else tuple(base_pigments)
    base = tuple(p for p in base if p not in set(known))
    known_pigments = {p for r in recipes.values() for p in r.amounts} | set(known)
    unknown_base = sorted(set(base) - known_pigments)
    if unknown_base:
        raise ValueError(f"base_pigments: {unknown_base} are in no film's recipe")
    stages, fitted = [], set(known)
    remaining = {f: set(r.amounts) for f, r in recipes.items()}
    base_films = tuple(sorted(f for f, pig in remaining.items() if pig <= set(base) and pig - fitted)) if base else ()
    if base_films:
        base_used = tuple(sorted(set().union(*(remaining[f] for f in base_films))))
        stages.append([(base_used, base_films)])
        fitted |= set(base_used)
        for f in base_films:
            del remaining[f]
    unused = []
    while True:
        for f in [f for f, pig in remaining.items() if pig <= fitted]:
            unused.append(f)
            del remaining[f]
        singles = {}
        for f, pig in sorted(remaining.items()):
            left = pig - fitted
            if len(left) == 1:
                singles.setdefault(next(iter(left)), []).append(f)
        if not singles:
            break
        stages.append([((p,), tuple(films)) for p, films in sorted(singles.items())])
        fitted |= set(singles)
        for films in singles.values():
            for f in films:
                del remaining[f]
    if remaining:
        stages.append(_components({f: pig - fitted for f, pig in remaining.items()}))
    return stages, tuple(sorted(unused))


def _standardized_residual(layout, theta, inputs):
    """The layout's standardized residual of every value at blocks ``theta`` (n_wl, k), (n_wl,
    n_values) (:meth:`LibraryLayout.standardized_residual`); a value the model cannot give
    (NaN, zero) counts as a huge residual."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        r = layout.standardized_residual(layout.predict(theta[None], inputs)[0])
    return np.nan_to_num(r, nan=1e6, posinf=1e6, neginf=-1e6)


def _least_squares_start(layout, thickness):
    """Per-wavelength least-squares fit of the block at fixed thicknesses, (n_wl, k); best of
    :data:`LEAST_SQUARES_STARTS` per wavelength."""
    n_wl, k = layout.n_wavelengths, layout.size
    inputs = {"thickness": thickness[None]}
    lower, upper = layout.lower.ravel(), layout.upper.ravel()
    margin = 1e-6 * (upper - lower)
    n_values = layout.observed.shape[1]
    sparsity = sparse.kron(sparse.eye(n_wl), np.ones((n_values, k)))

    def residual(x):
        return _standardized_residual(layout, x.reshape(n_wl, k), inputs).ravel()

    best, best_cost = None, None
    for a, sigma in LEAST_SQUARES_STARTS:
        x0 = np.tile(np.array([a, np.log(sigma)]), n_wl * k // 2)
        x0 = np.clip(x0, lower + margin, upper - margin)
        fit = optimize.least_squares(residual, x0, bounds=(lower, upper), jac_sparsity=sparsity, x_scale="jac",
                                     max_nfev=200)
        cost = (residual(fit.x).reshape(n_wl, n_values) ** 2).sum(axis=1)
        x = fit.x.reshape(n_wl, k)
        if best is None:
            best, best_cost = x, cost
        else:
            better = cost < best_cost
            best[better], best_cost[better] = x[better], cost[better]
    return best


def joint_least_squares_start(layout, thickness_spec, centre, max_nfev=JOINT_START_NFEV):
    """The stage's posterior mode in the constants and the films' thicknesses together.

    The per-wavelength fit (:func:`_least_squares_start`) holds every film at its nominal
    thickness; a film drawn thinner or thicker than that (a tint at ``h`` 2.4 among masstones
    at 0.8) is then fitted by bending the constants instead. This fit frees them together:
    standardized residual of every value of every film (:meth:`LibraryLayout.standardized_residual`), and the thickness prior
    ``(log h - mu) / sd`` (:class:`~bayespig.inference.film_thickness.FilmThickness`), minimised
    from ``centre`` at the spec's nominal ``log h`` by :func:`scipy.optimize.least_squares`
    (trust region, sparse Jacobian: a wavelength's constants touch only its own values, a film's
    ``log h`` only that film's). The sampler's walkers start there. Revigo 14B's library
    (Kubelka-Munk; chrome yellow from 14A, 14C-14E on the base of 07A, 07C-07F): the
    leave-one-out settings' run from the per-wavelength start stopped at its cap with the
    yellow's films at a sum of squared relative deviations of 6.3 (14B predicted at ΔE00
    5.4 / 5.5), where this fit reaches 4.0.

    Parameters
    ----------
    layout : LibraryLayout
    thickness_spec : FilmThickness
        The films' thickness prior and nominal (start) ``log h``.
    centre : numpy.ndarray
        Start of the constants, (n_wl, k) (the per-wavelength fit at the nominal thicknesses).
    max_nfev : int
        Most evaluations of the residuals.

    Returns
    -------
    tuple
        ``(constants (n_wl, k), log h (n_films,))``: the minimum, inside the boxes; never
        worse than the start (the start is returned if the fit does not improve it).
    """
    n_wl, k = layout.n_wavelengths, layout.size
    n_values, n_films = layout.observed.shape[1], thickness_spec.size
    lower = np.concatenate([layout.lower.ravel(), thickness_spec.lower])
    upper = np.concatenate([layout.upper.ravel(), thickness_spec.upper])
    margin = 1e-9 * (upper - lower)
    films = np.zeros((n_values, n_films))
    for f, part in enumerate(layout.value_slices):
        films[part, f] = 1.0
    sparsity = sparse.vstack([sparse.hstack([sparse.kron(sparse.eye(n_wl), np.ones((n_values, k))),
                                             sparse.csr_matrix(np.tile(films, (n_wl, 1)))]),
                              sparse.hstack([sparse.csr_matrix((n_films, n_wl * k)), sparse.eye(n_films)])])

    def residual(x):
        log_h = x[n_wl * k:]
        values = _standardized_residual(layout, x[:n_wl * k].reshape(n_wl, k), thickness_spec.model_inputs(log_h[None]))
        return np.concatenate([values.ravel(), (log_h - thickness_spec.mean) / thickness_spec.sd])

    x0 = np.clip(np.concatenate([centre.ravel(), thickness_spec.nominal]), lower + margin, upper - margin)
    fit = optimize.least_squares(residual, x0, bounds=(lower, upper), jac_sparsity=sparsity, x_scale="jac",
                                 max_nfev=max_nfev)
    x = fit.x if np.sum(residual(fit.x) ** 2) < np.sum(residual(x0) ** 2) else x0
    return x[:n_wl * k].reshape(n_wl, k), x[n_wl * k:]


def _fit_group(task):
    """One stage group's joint run (a process-pool task): constants and thickness draws."""
    start_time = time.perf_counter()
    film_model = _film_model(task["model"])
    sets = task["measurements"]
    predictors = [film_model.for_film(ms) for ms in sets]
    wavelength_nm = np.asarray(sets[0].wavelength_nm, dtype=float)
    layout = LibraryLayout(film_model, predictors, task["concentrations"], task["pigments"],
                           task["fixed_constants"], task["eps"], wavelength_nm,
                           noise_scale=task.get("noise_scale", DEFAULT_NOISE_SCALE))
    prior = FilmThickness(task["films"], measured=task["measured"])
    centre, log_h = joint_least_squares_start(layout, prior, _least_squares_start(layout, np.exp(prior.nominal)))
    spec = FilmThickness(task["films"], measured=task["measured"], start=log_h)
    specs = [spec]
    card_spec, film_cards = None, tuple(() for _ in task["films"])
    if task.get("substrate_sd") is not None:
        card_spec, film_cards = card_factor_spec(task["films"], sets, predictors, task["substrate_sd"])
        if card_spec is not None:
            specs.append(card_spec)
    concentration_spec = None
    if task.get("concentration_sd") is not None:
        order = tuple(task["pigments"]) + tuple(task.get("fixed_pigments", ()))
        concentration_spec, layout.factor_index = concentration_factor_spec(
            task["films"], task["concentrations"], order, task["concentration_sd"], n_fitted=len(task["pigments"]))
        if concentration_spec is not None:
            specs.append(concentration_spec)
    start_seq, joint_seq, ball_seq = np.random.SeedSequence(task["seed"], spawn_key=task["spawn_key"]).spawn(3)
    rng = np.random.default_rng(ball_seq)
    # the ball's sd per coordinate: START_BALL_SD, or less near the box's edge (a white's a ~ 1e-4)
    room = np.minimum(centre - layout.lower, layout.upper - centre)
    sd = np.minimum(START_BALL_SD, 0.3 * np.maximum(room, 1e-9))
    draws = np.clip(centre + sd * rng.standard_normal((START_POINTS,) + centre.shape), layout.lower, layout.upper)
    run, used, joint = sample_blocks(layout, specs, draws, task["settings"], joint_seq, start_seq)
    theta = run["theta"]
    n_chains, n_draws, n_dim = theta.shape
    flat = theta.reshape(-1, n_dim)
    blocks, thickness, *factors = joint.unpack(flat)
    constants = blocks.reshape(flat.shape[0], layout.n_wavelengths, len(layout.fitted), 2)
    # fit quality per film at the posterior median prediction
    predicted = np.median(joint.predict(flat), axis=0)  # (n_wl, n_values)
    deviation = np.log(layout.observed / predicted)
    rms = [float(np.sqrt(np.mean(deviation[:, part] ** 2))) for part in layout.value_slices]
    import arviz as az

    chains = thickness.reshape(n_chains, n_draws, -1)
    constant_chains = constants.reshape(n_chains, n_draws, -1)
    rhat_h = np.array([float(az.rhat(chains[..., j])) for j in range(chains.shape[-1])])
    ess_h = np.array([float(az.ess(chains[..., j])) for j in range(chains.shape[-1])])
    rhat_c = np.array([float(az.rhat(constant_chains[..., j])) for j in range(constant_chains.shape[-1])])
    ess_c = np.array([float(az.ess(constant_chains[..., j])) for j in range(constant_chains.shape[-1])])
    card_diagnostics = {}
    card_draws = factors.pop(0) if card_spec is not None else None
    concentration_draws = factors.pop(0) if concentration_spec is not None else None
    for name, spec_k, draws_k in (("card_factor", card_spec, card_draws),
                                  ("concentration_factor", concentration_spec, concentration_draws)):
        if spec_k is None:
            continue
        factor_chains = draws_k.reshape(n_chains, n_draws, -1)
        rhat_f = [float(az.rhat(factor_chains[..., j])) for j in range(spec_k.size)]
        ess_f = [float(az.ess(factor_chains[..., j])) for j in range(spec_k.size)]
        card_diagnostics.update({f"{name}_rhat_max": max(rhat_f), f"{name}_ess_min": min(ess_f)})
    return {
        "pigments": task["pigments"], "films": task["films"], "stage": task["stage"],
        "constants": constants, "thickness": thickness, "rms_log_deviation": rms,
        "point": centre.reshape(layout.n_wavelengths, len(layout.fitted), 2),
        "cards": film_cards, "card_factors": card_draws,
        "concentration_labels": () if concentration_spec is None else tuple(
            zip(concentration_spec.films, concentration_spec.pigments)),
        "concentration_factors": concentration_draws,
        "table_checksums": film_model.table_checksums,
        "diagnostics": {
            "stage": task["stage"], "pigments": list(task["pigments"]), "films": list(task["films"]),
            "n_steps": int(run["n_steps"]), "max_steps_reached": bool(run["max_steps_reached"]),
            "adaptation_rounds": int(run["adaptation_rounds"]),
            "shared_acceptance": float(run["shared_acceptance"]), "block_acceptance": float(run["block_acceptance"]),
            # None where the step does not apply (a later stage: its fixed pigments break the symmetry)
            **{key: (None if np.isnan(run[key]) else float(run[key]))
               for key in ("scale_acceptance", "prior_proposal_acceptance")},
            # the coordinates (of the sampler's residual coordinates) with the longest
            # autocorrelation times [steps]: what the run-length rule waits for
            "slowest_coordinates": [[joint.parameter_names[i], float(run["autocorr_time"][i])]
                                    for i in np.argsort(run["autocorr_time"])[::-1][:SLOWEST_REPORTED]],
            "n_walkers": int(used.n_walkers), "n_ensembles": int(used.n_ensembles),
            "thickness_rhat_max": float(rhat_h.max()), "thickness_ess_min": float(ess_h.min()),
            "constants_rhat_max": float(rhat_c.max()), "constants_ess_min": float(ess_c.min()),
            **card_diagnostics,
            "seconds": time.perf_counter() - start_time,
        },
    }


def _read_measurements(measurements):
    if isinstance(measurements, (str, os.PathLike)):
        from ..data import read_revigo

        path = Path(measurements)
        if not path.exists():
            raise ValueError(f"measurements: '{path}' does not exist")
        return read_revigo(path)
    if not isinstance(measurements, dict) or not measurements:
        raise TypeError("measurements must be a non-empty dict film id -> MeasurementSet, or a path to the "
                        f"Revigo data folder, got {type(measurements).__name__}")
    return measurements


def build_library(measurements, *, model="radiative-transfer", seed=0, executor=None, progress=True,
                  densities=None, eps=LIBRARY_EPS, base_pigments=None, thickness=None, settings=None, base=None,
                  substrate_sd=None, concentration_sd=None, noise_scale=DEFAULT_NOISE_SCALE):
    """A pigment library from films of known recipes (see the module docstring for the stages).

    Parameters
    ----------
    measurements : dict or str or os.PathLike
        Film id -> :class:`~bayespig.data.MeasurementSet` (one film group each, its recipe in
        ``metadata["composition"]``), e.g. from :func:`bayespig.data.read_revigo`; or the path
        of a Revigo data folder.
    model : {"radiative-transfer"}
        The film model.
    seed : int
        Seeds every stage (:class:`numpy.random.SeedSequence` with the stage and group as its
        spawn key: the same seed gives the same library however the groups are scheduled).
    executor : concurrent.futures.Executor, optional
        Runs a stage's independent groups; default a local pool of 2 processes when a stage has
        several groups.
    progress : bool
        One line per stage group on stderr.
    densities : dict, optional
        Pigment -> dry density [g/cm^3] for the concentrations (appendix A2).
    eps : float
        Known relative measurement error of films without their own [-].
    base_pigments : sequence of str, optional
        The pigments of stage 1 (default: present in >= :data:`BASE_SHARE` of the films).
    thickness : dict, optional
        Film id -> measured thickness (one unit for all; the prior's centre); others relative.
    settings : InferenceSettings, optional
        Default :data:`DEFAULT_SETTINGS`.
    base : PigmentLibrary, optional
        A library whose pigments count as fitted (its draws are the new library's for them, its
        medians fix them in the fits of the others): e.g. a white and a black fitted once and
        shared by many libraries (the leave-one-out study), built with the same model.
    substrate_sd : float, optional
        The cards' uncertainty, as :func:`bayespig.infer`'s ``substrate_sd``: every card a film
        is measured over gets a factor on its albedo seen from the binder, ``r_s = f r_s,card``
        at every wavelength, ``log f ~ N(0, substrate_sd^2)`` (e.g. 0.1 for the ~10 % of the
        paper's section 3.4), one per card and film, sampled in each stage's joint run with the
        thicknesses (:func:`card_factor_spec`); the library then holds their draws
        (:attr:`PigmentLibrary.card_factor` over ``(draw, film, card)``). Default None, as
        ``infer``'s: the cards as converted from their measurement (the draws are exactly
        those of a build without the argument).
    concentration_sd : float, optional
        The recipes' uncertainty: every film's minor pigments fixed from an earlier stage (not
        its dominant one, whose factor would be the film's thickness, nor the pigment being
        fitted, see :func:`concentration_factor_spec`) act at an effective concentration ``D_eff = f D``,
        ``log f ~ N(0, concentration_sd^2)`` (e.g. 0.3), one per (film, pigment), sampled in
        each stage's joint run with the thicknesses (:func:`concentration_factor_spec`,
        :mod:`bayespig.inference.concentration_factors`). Physically weighing and dispersion
        errors of a small amount and tinting-strength differences of a pigment in a given
        mixture (flocculation): e.g. a bone black fixed from zinc-white greys that darkens a
        chrome yellow less than its recipe share says. The library then holds their draws
        (:attr:`PigmentLibrary.concentration_factor` over ``(draw, film, component)``, names in
        :attr:`PigmentLibrary.concentration_names`) and each film's record their summary
        (``concentration_factors``). Default None: the recipes' concentrations (the draws are
        exactly those of a build without the argument).
    noise_scale : {"measured", "model"}
        What ``eps`` is relative to: the measured value (default) or the predicted one (eq. 7,
        as in :func:`bayespig.infer`); see :data:`NOISE_SCALES` for why they differ on films
        the model cannot reproduce.

    Returns
    -------
    PigmentLibrary
    """
    progress = flag("progress", progress)
    if not (isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and seed >= 0):
        raise TypeError(f"seed must be a non-negative integer, got {seed!r}")
    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a positive number, got {eps!r}")
    substrate_sd = check_substrate_sd(substrate_sd)
    concentration_sd = check_concentration_sd(concentration_sd)
    noise_scale = check_noise_scale(noise_scale)
    film_model = _film_model(model)
    settings = DEFAULT_SETTINGS if settings is None else settings
    sets = _read_measurements(measurements)
    recipes = film_recipes(sets)
    thickness = {} if thickness is None else dict(thickness)
    unknown = sorted(set(thickness) - set(sets))
    if unknown:
        raise ValueError(f"thickness: films {unknown} are not among the measurements")
    wavelengths = [np.asarray(ms.wavelength_nm, dtype=float) for ms in sets.values()]
    if any(w.shape != wavelengths[0].shape or not np.allclose(w, wavelengths[0]) for w in wavelengths):
        raise ValueError("measurements: every film must be measured at the same wavelengths")
    known = ()
    medians = {}  # pigment -> (n_wl, 2): the values later stages fix it at
    stage_points = {}  # pigment -> (n_wl, 2): its stage's joint least-squares point
    if base is not None:
        if not isinstance(base, PigmentLibrary):
            raise TypeError(f"base must be a PigmentLibrary, got {type(base).__name__}")
        if base.model != model:
            raise ValueError(f"base is a {base.model!r} library; this build is {model!r}")
        if base.wavelength_nm.shape != wavelengths[0].shape or not np.allclose(base.wavelength_nm, wavelengths[0]):
            raise ValueError("base: its wavelengths differ from the measurements'")
        known = tuple(base.pigments)
        if base_pigments is None:  # the base library's pigments are the base: no base stage here
            base_pigments = ()
        inherited_points = base.provenance.get("stage_points") or {}
        k = representative_draw(base.constants)
        for j, p in enumerate(base.pigments):
            medians[p] = (np.asarray(inherited_points[p], dtype=float) if p in inherited_points
                          else base.constants[k, :, j])
            stage_points[p] = medians[p]
    stages, unused = stage_plan(recipes, base_pigments, known=known)
    # what every fitted pigment was conditioned on (the fixed pigments of its group) and the values it was
    # fixed at: a prediction pairs its draws with those values (bayespig.library.predict.joint_constants)
    conditioned_on, fixed_constants = {}, {}
    if base is not None:
        inherited = base.provenance.get("conditioning") or {}
        conditioned_on.update(inherited.get("conditioned_on", {}))
        fixed_constants.update({p: np.asarray(v, dtype=float) for p, v in inherited.get("fixed_constants", {}).items()})
    results = []
    start = time.perf_counter()
    for s, groups in enumerate(stages, start=1):
        tasks = []
        for g, (pigments, films) in enumerate(groups):
            fixed = sorted({p for f in films for p in recipes[f].amounts} - set(pigments))
            for p in pigments:
                conditioned_on[p] = list(fixed)
            for p in fixed:
                fixed_constants[p] = medians[p]
            order = tuple(pigments) + tuple(fixed)
            tasks.append({
                "model": model, "measurements": [sets[f] for f in films], "films": films,
                "pigments": tuple(pigments), "stage": s,
                "concentrations": np.stack([concentrations(recipes[f], order, densities=densities) for f in films]),
                "fixed_constants": (np.stack([medians[p] for p in fixed], axis=1) if fixed else None),
                "measured": np.array([thickness.get(f, np.nan) for f in films], dtype=float),
                "eps": float(eps), "settings": settings, "seed": int(seed), "spawn_key": (s, g),
                "substrate_sd": substrate_sd, "fixed_pigments": tuple(fixed),
                "concentration_sd": concentration_sd, "noise_scale": noise_scale,
            })
        stage_start = time.perf_counter()
        def report(result):
            if progress:
                d = result["diagnostics"]
                print(f"library stage {s}/{len(stages)}: {', '.join(d['pigments'])} from {len(d['films'])} films: "
                      f"{d['n_steps']} steps{' (capped)' if d['max_steps_reached'] else ''}, "
                      f"R-hat <= {max(d['thickness_rhat_max'], d['constants_rhat_max']):.3f}, "
                      f"thickness ESS >= {d['thickness_ess_min']:.0f}"
                      + (f", card factors R-hat <= {d['card_factor_rhat_max']:.3f}, ESS >= "
                         f"{d['card_factor_ess_min']:.0f}" if "card_factor_rhat_max" in d else "")
                      + (f", concentration factors R-hat <= {d['concentration_factor_rhat_max']:.3f}, ESS >= "
                         f"{d['concentration_factor_ess_min']:.0f}" if "concentration_factor_rhat_max" in d else "")
                      + f", {d['seconds']:.1f} s",
                      file=sys.stderr, flush=True)
            return result

        with executor_or_local_pool(executor, needed=len(tasks) > 1, max_workers=min(2, len(tasks))) as pool:
            if pool is None:
                done = [report(_fit_group(t)) for t in tasks]
            else:
                futures = [pool.submit(_fit_group, t) for t in tasks]
                for future in as_completed(futures):
                    report(future.result())
                done = [f.result() for f in futures]
        for result in done:
            for j, p in enumerate(result["pigments"]):
                medians[p] = stage_points[p] = result["point"][:, j]
        if progress:
            print(f"library stage {s}/{len(stages)} done in {time.perf_counter() - stage_start:.1f} s",
                  file=sys.stderr, flush=True)
        results.extend(done)
    library = _assemble(film_model, results, recipes, unused, wavelengths[0], seed, settings, eps, densities,
                        base_pigments, model, stages, time.perf_counter() - start, base, substrate_sd,
                        concentration_sd)
    conditioning = {"conditioned_on": conditioned_on,
                    "fixed_constants": {p: np.asarray(v, dtype=float).tolist() for p, v in fixed_constants.items()}}
    return dataclasses.replace(library, provenance={
        **library.provenance, "conditioning": conditioning, "noise_scale": noise_scale,
        "stage_points": {p: np.asarray(v, dtype=float).tolist() for p, v in stage_points.items()}})


def _assemble(film_model, results, recipes, unused, wavelength_nm, seed, settings, eps, densities,
              base_pigments, model, stages, seconds, base=None, substrate_sd=None, concentration_sd=None):
    """The library from the stage groups' results (and a base library's pigments first)."""
    parts = [r["constants"] for r in results] + ([] if base is None else [base.constants])
    if not parts:
        raise ValueError("measurements: no film has a pigment to fit (all are in the base library)")
    n_draws = min(c.shape[0] for c in parts)
    pigments = tuple(p for r in results for p in r["pigments"]) + (() if base is None else tuple(base.pigments))
    constants = np.concatenate([c[:n_draws] for c in parts], axis=2)  # (N, n_wl, P, 2)
    film_ids = tuple(sorted(recipes))
    thickness = np.full((n_draws, len(film_ids)), np.nan)
    films = {}
    card_factor = card_names = None
    if substrate_sd is not None:
        n_cards = max([len(c) for r in results for c in r["cards"]] + [1])
        card_factor = np.full((n_draws, len(film_ids), n_cards), np.nan)
        card_names = [[""] * n_cards for _ in film_ids]
    concentration_factor = concentration_names = None
    if concentration_sd is not None:
        per_film = {}
        for r in results:
            for film, pigment in r["concentration_labels"]:
                per_film.setdefault(film, []).append(pigment)
        n_components = max([len(v) for v in per_film.values()] + [1])
        concentration_factor = np.full((n_draws, len(film_ids), n_components), np.nan)
        concentration_names = [[""] * n_components for _ in film_ids]
    for r in results:
        if concentration_factor is not None:
            slots = {}
            for k, (film, pigment) in enumerate(r["concentration_labels"]):
                i = film_ids.index(film)
                c = slots.setdefault(film, 0)
                slots[film] += 1
                values = r["concentration_factors"][:n_draws, k]
                concentration_factor[:, i, c] = values
                concentration_names[i][c] = pigment
                q05, q95 = np.quantile(values, [0.05, 0.95])
                films.setdefault(film, {}).setdefault("concentration_factors", []).append(
                    {"pigment": pigment, "median": float(np.median(values)), "q05": float(q05), "q95": float(q95),
                     "implausible": implausible_factor(q05, q95, concentration_sd)})
        column = 0
        for j, f in enumerate(r["films"]):
            h = r["thickness"][:n_draws, j]
            thickness[:, film_ids.index(f)] = h
            films[f] = {**films.get(f, {}), "stage": r["stage"], "used": True, "rms_log_deviation": r["rms_log_deviation"][j],
                        "thickness_median": float(np.median(h)),
                        "thickness_q05": float(np.quantile(h, 0.05)), "thickness_q95": float(np.quantile(h, 0.95))}
            if concentration_factor is not None:
                films[f].setdefault("concentration_factors", [])
            if card_factor is not None:
                factors = []
                for c, card in enumerate(r["cards"][j]):
                    values = r["card_factors"][:n_draws, column]
                    column += 1
                    card_factor[:, film_ids.index(f), c] = values
                    card_names[film_ids.index(f)][c] = card
                    q05, q95 = np.quantile(values, [0.05, 0.95])
                    factors.append({"card": card, "median": float(np.median(values)),
                                    "q05": float(q05), "q95": float(q95),
                                    "implausible": implausible_factor(q05, q95, substrate_sd)})
                films[f]["card_factors"] = factors
    records = []
    for f in film_ids:
        entry = {"id": f, "recipe": dict(recipes[f].amounts), "pigments": sorted(recipes[f].amounts)}
        unused_entry = {"stage": None, "used": False, "rms_log_deviation": None,
                        "thickness_median": None, "thickness_q05": None, "thickness_q95": None}
        if card_factor is not None:
            unused_entry["card_factors"] = []
        if concentration_factor is not None:
            unused_entry["concentration_factors"] = []
        entry.update(films.get(f, unused_entry))
        records.append(entry)
    base_medians = [] if base is None else [f["thickness_median"] for f in base.films
                                            if f.get("used") and f.get("thickness_median")]
    log_h = np.log([films[f]["thickness_median"] for f in films] + base_medians)
    thickness_prior = (float(log_h.mean()), float(log_h.std(ddof=1)) if log_h.size > 1 else 0.5)
    provenance = {
        "seed": int(seed), "eps": float(eps), "base_pigments": None if base_pigments is None else list(base_pigments),
        "settings": dataclasses.asdict(settings), "versions": package_versions(), "seconds": seconds,
        "stage_plan": [[{"pigments": list(p), "films": list(f)} for p, f in groups] for groups in stages],
        "unused_films": list(unused),
        "base_library": None if base is None else {"pigments": list(base.pigments),
                                                   "films": [f["id"] for f in base.films if f.get("used")],
                                                   "provenance": base.provenance},
        "method": "staged (cut) posterior, bayespig.library.build",
        # the look-up tables of every stage (key -> SHA-256 of their arrays; a base's are its own record)
        "table_checksums": dict(sorted({k: v for r in results for k, v in r.get("table_checksums", {}).items()}.items())),
    }
    if substrate_sd is not None:  # absent otherwise: a build without card factors is recorded as before
        provenance["substrate_sd"] = float(substrate_sd)
        provenance["card_factor_prior"] = (f"r_s = f r_s,card per card and film at every wavelength, log f ~ "
                                           f"N(0, {substrate_sd:g}^2), truncated at {FACTOR_PRIOR_SDS:g} sd and at "
                                           "r_s f <= 1 (bayespig.inference.card_factors)")
    if concentration_sd is not None:  # absent otherwise: a build without factors is recorded as before
        provenance["concentration_sd"] = float(concentration_sd)
        provenance["concentration_factor_prior"] = (
            f"D_eff = f D for every minor pigment of a film (the dominant one at f = 1), log f ~ "
            f"N(0, {concentration_sd:g}^2), truncated at {CONCENTRATION_PRIOR_SDS:g} sd "
            "(bayespig.inference.concentration_factors)")
    return PigmentLibrary(
        model=model, pigments=pigments, wavelength_nm=np.asarray(wavelength_nm, dtype=float),
        constants=constants, constant_names=tuple(film_model.constant_names), thickness_prior=thickness_prior,
        films=tuple(records), film_ids=film_ids, thickness=thickness,
        densities=None if densities is None else dict(densities), model_error=None, provenance=provenance,
        stages=tuple(r["diagnostics"] for r in results) + (() if base is None else tuple(base.stages)),
        card_factor=card_factor, card_names=None if card_names is None else tuple(map(tuple, card_names)),
        concentration_factor=concentration_factor,
        concentration_names=None if concentration_names is None else tuple(map(tuple, concentration_names)))

