"""Colour matching: the recipe of library pigments whose predicted colour is closest to a target.

The recipe (mass fractions of the allowed pigments, and the film thickness when it is not
fixed) minimises CIEDE2000 between the predicted colour and the target under one illuminant,
the prediction made with the posterior-median constants of the library. The fractions are
``w = softmax(z)`` (any ``z`` is a valid recipe), searched by Nelder-Mead from the even mix and
from each pigment's corner; a fitted thickness is one more coordinate, ``log h``.

Then, for the best recipe:

* the credible ΔE00 of the match: the distribution of ΔE00 between the target and the
  predictive draws (:func:`bayespig.library.predict.predict_paint`, with the library's model
  error), its median and its ``level`` quantile;
* the metamerism index (a spectral target only): ΔE00 between the match and the target under
  a second illuminant (default CIE A), the pair having been matched under the first;
* the spread of recipes that match equally well: the recipe re-optimised for each of
  ``n_spread`` posterior draws of the constants (the recipes the library cannot tell apart),
  as per-pigment ``level`` intervals.

References
----------
Ershov, Voloboy & Pozdnyakov (2023), sections 1 and 5 (colour matching as the goal).
CIE 15:2004 (metamerism index).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import optimize

from .. import colorimetry
from .._validation import integer, seed as check_seed
from ..physics.mixtures import concentrations_from_mass_fractions
from .predict import DEFAULT_LEVEL, _thickness_argument, joint_constants, model_reflectance, predict_paint
from .recipes import DEFAULT_BINDER_DENSITY, Recipe, density_of

__all__ = ["DEFAULT_SECOND_ILLUMINANT", "PaintMatch", "match_paint"]

#: The second illuminant of the metamerism index by default (incandescent, CIE 15).
DEFAULT_SECOND_ILLUMINANT = "A"
#: Draws whose re-optimised recipes give the spread of equally good recipes by default.
DEFAULT_SPREAD_DRAWS = 16
#: Nelder-Mead stopping rule: ΔE00 change below which a search stops [CIELAB units].
MATCH_FATOL = 1e-4
#: Relative thickness range a fitted thickness is kept in (log h is clipped to it).
THICKNESS_RANGE = (1e-2, 1e2)


@dataclasses.dataclass(frozen=True)
class PaintMatch:
    """The best recipe for a target colour, with its credible ΔE00 and the spread of equal matches.

    Attributes
    ----------
    recipe : Recipe
        Mass fractions of the allowed pigments (zeros dropped below 1e-4).
    thickness : float or str
        The fixed or fitted relative thickness, or ``"opaque"``.
    Lab_target, Lab_match : numpy.ndarray
        (3,) under ``illuminant``.
    delta_E : float
        ΔE00 of the match with the posterior-median constants.
    delta_E_median, delta_E_upper : float
        Median and ``level`` quantile of ΔE00 between the target and the predictive draws.
    metamerism_index : float or None
        ΔE00 under ``second_illuminant`` (spectral targets only).
    amounts_interval : dict
        Pigment -> (low, high) ``level`` interval of its fraction over the re-optimised draws.
    spread_recipes : numpy.ndarray
        (n_spread, n_allowed) the re-optimised fractions, columns in ``pigments`` order.
    pigments : tuple of str
    prediction : PaintPrediction
        The prediction of the best recipe.
    """

    recipe: Recipe
    thickness: object
    Lab_target: np.ndarray
    Lab_match: np.ndarray
    delta_E: float
    delta_E_median: float
    delta_E_upper: float
    metamerism_index: float | None
    amounts_interval: dict
    spread_recipes: np.ndarray
    pigments: tuple
    illuminant: str
    second_illuminant: str
    level: float
    prediction: object


def _softmax(z):
    e = np.exp(z - z.max())
    return e / e.sum()


def _target(library, target, illuminant, second, observer):
    """Lab of the target under the two illuminants (the second None for a Lab target)."""
    t = np.asarray(target, dtype=float)
    if not np.isfinite(t).all():
        raise ValueError("target must be finite (a reflectance spectrum or a CIELAB triple)")
    if t.shape == (3,):
        return t, None, None
    if t.shape != library.wavelength_nm.shape:
        raise ValueError(f"target must be a CIELAB triple or a reflectance spectrum [fraction] at the "
                         f"library's {library.wavelength_nm.size} wavelengths, got shape {t.shape}")
    if (t < 0).any() or t.max() > 1.5:
        raise ValueError("target reflectance must be fractions in [0, 1.5] (divide percent by 100)")
    lab = colorimetry.reflectance_to_Lab(t, library.wavelength_nm, illuminant=illuminant, observer=observer)
    lab2 = colorimetry.reflectance_to_Lab(t, library.wavelength_nm, illuminant=second, observer=observer)
    return lab, lab2, t


def match_paint(library, target, *, pigments=None, instrument, thickness="opaque", substrate=None, seed=0,
                illuminant=colorimetry.DEFAULT_ILLUMINANT, second_illuminant=DEFAULT_SECOND_ILLUMINANT,
                observer=colorimetry.DEFAULT_OBSERVER, level=DEFAULT_LEVEL, n_spread=DEFAULT_SPREAD_DRAWS,
                n_draws=200):
    """The recipe of ``pigments`` that best matches ``target`` (CIEDE2000 under ``illuminant``).

    Parameters
    ----------
    library : PigmentLibrary
    target : array_like
        A reflectance spectrum [fraction] at the library's wavelengths, or a CIELAB triple.
    pigments : sequence of str, optional
        The pigments allowed (default all of the library's).
    instrument : str
        The instrument the target was measured with (``"8d-sce"``, ``"8d-sci"``, ``"45-0"``).
    thickness : float, "opaque" or "fit"
        A fixed relative thickness, ``"opaque"`` (default: a film at hiding), or ``"fit"`` to
        match the thickness too (needs ``substrate``).
    substrate : array_like, optional
        Card reflectance in air [fraction] per wavelength (films that do not hide it).
    seed : int
        Seeds the draws of the credible ΔE and of the spread.
    illuminant, second_illuminant, observer : str
    level : float
    n_spread : int
        Posterior draws whose re-optimised recipes give the spread (0: none).
    n_draws : int
        Draws of the credible ΔE00.

    Returns
    -------
    PaintMatch
    """
    seed = check_seed(seed)
    n_spread = integer("n_spread", n_spread, low=0)
    allowed = tuple(library.pigments) if pigments is None else tuple(pigments)
    if not allowed:
        raise ValueError("pigments must name at least one pigment of the library")
    unknown = [p for p in allowed if p not in library.pigments]
    if unknown:
        raise ValueError(f"pigments: {unknown[0]!r} is not in the library (it has {', '.join(library.pigments)})")
    if len(set(allowed)) != len(allowed):
        raise ValueError("pigments must not name a pigment twice")
    fit_thickness = isinstance(thickness, str) and thickness.strip().lower() == "fit"
    if fit_thickness:
        if substrate is None:
            raise ValueError("thickness='fit' needs the substrate (card reflectance) the film is on")
        fixed_h = None
    else:
        kind, fixed_h = _thickness_argument(thickness)
        if kind == "unknown":
            raise ValueError("thickness must be a relative thickness, 'opaque' or 'fit' for a match")
    lab_target, lab_target2, _ = _target(library, target, illuminant, second_illuminant, observer)
    wl = library.wavelength_nm
    joint = joint_constants(library, allowed)  # pigments fitted with others fixed: paired with those values
    median_constants = np.median(joint, axis=0)
    P = len(allowed)
    columns = np.array([library.pigments.index(p) for p in allowed])
    densities = np.array([density_of(p, library.densities) for p in allowed])
    log_range = np.log(THICKNESS_RANGE)
    n_free = P - 1 + (1 if fit_thickness else 0)

    def unpack(x):
        fractions = _softmax(np.concatenate([[0.0], x[:P - 1]]))
        h = float(np.exp(np.clip(x[P - 1], *log_range))) if fit_thickness else fixed_h
        return fractions, h

    def lab_of(x, constants, which=illuminant):
        fractions, h = unpack(x)
        D = np.zeros(len(library.pigments))
        D[columns] = concentrations_from_mass_fractions(fractions, paste_density=densities,
                                                        binder_density=DEFAULT_BINDER_DENSITY)
        R = model_reflectance(library, D, constants[None], np.array([h]), instrument=instrument,
                              substrate=substrate)[0]
        return colorimetry.reflectance_to_Lab(R, wl, illuminant=which, observer=observer)

    def delta_E(x, constants):
        return float(colorimetry.delta_E2000(lab_of(x, constants), lab_target))

    bounds = (np.r_[np.full(P - 1, -np.inf), [log_range[0]] * fit_thickness],
              np.r_[np.full(P - 1, np.inf), [log_range[1]] * fit_thickness])

    def search(constants, starts, polish=True):
        """Gauss-Newton on the CIELAB difference from each start, then Nelder-Mead on ΔE00 from the best."""
        if n_free == 0:
            return starts[0], delta_E(starts[0], constants)
        best_x, best = None, np.inf
        for x0 in starts:
            result = optimize.least_squares(lambda x: lab_of(x, constants) - lab_target, x0, bounds=bounds,
                                            method="trf", x_scale=1.0, max_nfev=50 * (n_free + 1))
            value = delta_E(result.x, constants)
            if value < best:
                best_x, best = result.x, value
        if polish and best > MATCH_FATOL:
            result = optimize.minimize(lambda x: delta_E(np.clip(x, *bounds), constants), best_x, method="Nelder-Mead",
                                       options={"fatol": MATCH_FATOL, "xatol": 1e-4, "maxiter": 100 * n_free})
            if result.fun < best:
                best_x, best = np.clip(result.x, *bounds), float(result.fun)
        return best_x, best

    base = np.zeros(n_free)
    if fit_thickness:
        base[-1] = float(np.clip(library.thickness_prior[0], *log_range))
    starts = [base]
    for i in range(P if P > 1 else 0):
        corner = base.copy()
        if i == 0:
            corner[:P - 1] = -2.0
        else:
            corner[i - 1] = 2.0
        starts.append(corner)
    best_x, best_value = search(median_constants, starts)
    fractions, h = unpack(best_x)
    recipe = Recipe.from_mapping({p: f for p, f in zip(allowed, fractions) if f >= 1e-4})
    h_out = "opaque" if h is not None and np.isinf(h) else h
    prediction = predict_paint(library, recipe, thickness=h_out, instrument=instrument, substrate=substrate,
                               seed=seed, n_draws=n_draws, level=level, illuminant=illuminant,
                               observer=observer)
    dE_draws = colorimetry.delta_E2000(prediction.Lab, lab_target)
    lab_match = lab_of(best_x, median_constants)
    metamerism = None
    if lab_target2 is not None:
        metamerism = float(colorimetry.delta_E2000(lab_of(best_x, median_constants, second_illuminant),
                                                   lab_target2))
    spread = np.empty((0, P))
    intervals = {}
    if n_spread and n_free:
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(
            np.random.SeedSequence(seed).spawn(1)[0])
        picks = rng.choice(joint.shape[0], size=n_spread, replace=n_spread > joint.shape[0])
        spread = np.array([unpack(search(joint[i], [best_x], polish=False)[0])[0] for i in picks])
        tail = (1.0 - level) / 2.0
        for j, p in enumerate(allowed):
            low, high = np.quantile(spread[:, j], [tail, 1.0 - tail])
            intervals[p] = (float(low), float(high))
    return PaintMatch(recipe, h_out, lab_target, lab_match, best_value, float(np.median(dE_draws)),
                      float(np.quantile(dE_draws, level)), metamerism, intervals, spread, allowed, illuminant,
                      second_illuminant, level, prediction)
