"""The colour of any recipe from a pigment library: spectra as draws, CIELAB, a credible ΔE00 region.

A prediction pushes joint posterior draws of the library's constants (:func:`joint_constants`: a
pigment fitted with others fixed is paired with their fixed values) through the library's film model
(radiative transfer or Kubelka-Munk, :mod:`bayespig.library.film_models`) for the recipe's
concentrations (appendix A2, :func:`bayespig.library.recipes.concentrations`), a film
thickness (given, opaque, or unknown: then drawn from the thickness distribution of the
library's own films) and a card, then adds the model error the library learned from its own
cross-validation (:func:`model_error_from_residuals`):

    R_draw(λ) = R_model(λ; constants_draw, h_draw) * (1 + e(λ)),   e ~ N(0, C_model),

with ``C_model = kappa^2 C``: ``C`` the covariance over wavelengths of the relative residuals
of held-out films, ``kappa`` its calibration factor (:func:`calibration_factor`). The credible
region is a ball in CIEDE2000 around the colour of the median spectrum, of the radius that holds
``level`` of the draws. Without the model-error term the region holds only the uncertainty of
the constants; with it, a measured film of that recipe should fall inside at the nominal rate
(checked by the leave-one-film-out study, :mod:`bayespig.studies.colour_prediction`).

Why a calibration factor: the held-out films' misses are heavy-tailed (Revigo: rms relative
residual per card 2 % ... 87 %, median 8 %; ΔE00 median 2.3, a few films 9-11), so a normal
model error with their mean-square covariance is too wide for most films and too narrow for
the worst: 90 % regions held 98-99 % of the held-out Revigo cards. ``kappa`` rescales it by
split-conformal calibration with a normalised score: each held-out card's ΔE00 from its
region's centre over the region's radius at ``kappa = 1``, ``kappa`` the score quantile that
holds ``level`` of the held-out cards with the finite-sample correction (Vovk, Gammerman &
Shafer 2005; Lei et al. 2018, section 5.2). Point-estimate libraries of series 01-15
(``benchmarks/loo_point_estimates.py``, 16 draws per card): kappa 0.84 (radiative transfer) and
0.83 (Kubelka-Munk); the held-out cards inside their 90 % regions 103 of 108 (95 %) for both at
``kappa = 1``, 98 and 96 (91 % and 89 %) calibrated (each film's ``kappa`` from the other
films); the median score 0.36 and 0.31: most films lie well inside, the worst few set
``kappa``. The MCMC study (``bayespig colour-prediction``, ``reports/colour-prediction.md``):
107 of 108 cards inside for both models uncalibrated, 96 (89 %, radiative transfer) and 97
(90 %, Kubelka-Munk) calibrated; the cards outside are those of the worst films (01B, 01C, 02B,
11E, 12D, 15C). A region calibrated at one level
is calibrated at that level only.

References
----------
Ershov, Voloboy & Pozdnyakov (2023), section 2 (mixtures), appendix A2 (concentrations).
Vovk, Gammerman & Shafer (2005), Algorithmic Learning in a Random World, Springer.
Lei, G'Sell, Rinaldo, Tibshirani & Wasserman (2018), J. Am. Stat. Assoc. 113:1094 (split
conformal prediction, locally weighted scores).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .. import colorimetry
from .._validation import integer, real_scalar
from .._validation import seed as check_seed
from .film_models import film_model
from .recipes import Recipe, concentrations

__all__ = [
    "DEFAULT_DRAWS",
    "DEFAULT_LEVEL",
    "PaintPrediction",
    "calibration_factor",
    "credible_region",
    "joint_constants",
    "model_error_from_residuals",
    "model_reflectance",
    "predict_paint",
    "predict_reflectance",
    "thickness_draws",
    "with_model_error",
]

#: Draws of a prediction by default (the issue's speed goal is stated for 200).
DEFAULT_DRAWS = 200
#: Probability content of the credible ΔE00 region by default.
DEFAULT_LEVEL = 0.9
#: Ways to say "the film hides its card".
OPAQUE_WORDS = ("opaque", "inf", "infinite")
#: Ways to say "thickness unknown: draw it from the library's films".
UNKNOWN_WORDS = ("unknown",)


@dataclasses.dataclass(frozen=True)
class PaintPrediction:
    """A predicted paint colour: spectra as draws, CIELAB and the credible ΔE00 region.

    Attributes
    ----------
    recipe : Recipe
    wavelength_nm : numpy.ndarray
        (n_wl,) [nm].
    reflectance : numpy.ndarray
        (n_draws, n_wl) predictive draws [fraction], model error included when the library has one.
    reflectance_median : numpy.ndarray
        (n_wl,) the median spectrum over the draws [fraction].
    Lab : numpy.ndarray
        (n_draws, 3) CIELAB of the draws.
    Lab_median : numpy.ndarray
        (3,) CIELAB of the median spectrum: the predicted colour.
    delta_E_radius : float
        CIEDE2000 radius around ``Lab_median`` holding ``level`` of the draws.
    level : float
    thickness : str or float
        As asked (a relative thickness, ``"opaque"`` or ``"unknown"``).
    instrument, illuminant, observer : str
    model_error : bool
        Whether the library's cross-validated model error is in the draws.
    seed : int
    """

    recipe: Recipe
    wavelength_nm: np.ndarray
    reflectance: np.ndarray
    reflectance_median: np.ndarray
    Lab: np.ndarray
    Lab_median: np.ndarray
    delta_E_radius: float
    level: float
    thickness: object
    instrument: str
    illuminant: str
    observer: str
    model_error: bool
    seed: int

    def delta_E(self, Lab):
        """CIEDE2000 between ``Lab`` (..., 3) and the predicted colour."""
        return colorimetry.delta_E2000(Lab, self.Lab_median)

    def contains(self, Lab):
        """Whether ``Lab`` (..., 3) lies inside the credible region."""
        return self.delta_E(Lab) <= self.delta_E_radius


def _thickness_argument(thickness):
    """``("opaque", inf)``, ``("unknown", None)`` or ``("given", h)`` from the user's value."""
    if isinstance(thickness, str):
        word = thickness.strip().lower()
        if word in OPAQUE_WORDS:
            return "opaque", np.inf
        if word in UNKNOWN_WORDS:
            return "unknown", None
        raise ValueError(f"thickness must be a relative film thickness > 0, 'opaque' or 'unknown', "
                         f"got {thickness!r}")
    if thickness is None:
        return "unknown", None
    h = real_scalar("thickness", thickness, low=0.0, low_open=True, allow_inf=True)
    return ("opaque", np.inf) if np.isinf(h) else ("given", h)


def thickness_draws(library, thickness, n_draws, rng):
    """Film thickness per draw: the value given, ``inf`` (opaque), or draws of the library's films' spread.

    An unknown thickness is drawn from the log-normal ``library.thickness_prior`` (mean and sd
    of ``log h`` over the library's films): a film made the way the library's films were.
    """
    kind, h = _thickness_argument(thickness)
    if kind == "unknown":
        mean, sd = library.thickness_prior
        return np.exp(rng.normal(mean, sd, n_draws))
    return np.full(n_draws, h)


def _recipe(library, recipe):
    if not isinstance(recipe, Recipe):
        recipe = Recipe.from_mapping(recipe)
    unknown = [p for p in recipe.amounts if p not in library.pigments]
    if unknown:
        raise ValueError(f"recipe: pigment {unknown[0]!r} is not in the library (it has "
                         f"{', '.join(library.pigments)})")
    return recipe


def joint_constants(library, pigments):
    """The library's draws as joint draws for a recipe of ``pigments``: fixed pigments paired right.

    A library is a staged (cut) posterior (:mod:`bayespig.library.build`): a pigment of a later
    stage was fitted with the pigments of its films fitted before it *fixed* at one value each
    (``library.provenance["conditioning"]``), so its draws are draws given those values. A
    recipe that holds such a pigment and one it was conditioned on (directly or through another
    pigment) is predicted with the latter at its fixed value in every draw; the other pigments
    keep their own draws. Without this, the draws of a white (independent of the tinting
    pigment's) would be mixed with a tinting pigment fitted relative to another white.

    Parameters
    ----------
    library : PigmentLibrary
    pigments : iterable of str
        The pigments of the recipe (or those a match may use).

    Returns
    -------
    numpy.ndarray
        (n_draws, n_wl, n_pigments, 2), ``library.constants`` or a copy with the conditioning
        pigments replaced. A library without ``"conditioning"`` in its provenance (written before
        it was recorded) is returned unchanged.
    """
    info = (library.provenance or {}).get("conditioning") or {}
    parents = info.get("conditioned_on") or {}
    values = info.get("fixed_constants") or {}
    pigments = [str(p) for p in pigments]
    # every pigment a recipe pigment depends on, through any chain of stages
    todo, ancestors = list(pigments), set()
    while todo:
        for parent in parents.get(todo.pop(), ()):
            if parent not in ancestors:
                ancestors.add(parent)
                todo.append(parent)
    replace = [p for p in sorted(ancestors) if p in set(pigments) and p in values and p in library.pigments]
    if not replace:
        return library.constants
    constants = np.array(library.constants, dtype=float, copy=True)
    for p in replace:
        fixed = np.asarray(values[p], dtype=float)
        if fixed.shape != constants.shape[1:2] + constants.shape[3:]:
            raise ValueError(f"library: the fixed constants of {p!r} have shape {fixed.shape}, expected "
                             f"{constants.shape[1:2] + constants.shape[3:]} (wavelengths, constants)")
        constants[:, :, library.pigments.index(p)] = fixed
    return constants


def predict_reflectance(library, recipe, constants, thickness, *, instrument, substrate=None):
    """Model spectra of ``recipe`` for given constant draws (no model error).

    Parameters
    ----------
    library : PigmentLibrary
    recipe : Recipe or mapping
    constants : numpy.ndarray
        (N, n_wl, n_pigments, 2) sampled coordinates of the library's pigments.
    thickness : numpy.ndarray
        (N,) relative thickness (``inf``: opaque).
    instrument : str
    substrate : array_like, optional
        Card reflectance in air [fraction], (n_wl,) or (N, n_wl); needed unless opaque.

    Returns
    -------
    numpy.ndarray
        (N, n_wl) reflectance [fraction].
    """
    recipe = _recipe(library, recipe)
    D = concentrations(recipe, library.pigments, densities=library.densities)
    return model_reflectance(library, D, constants, thickness, instrument=instrument, substrate=substrate)


def model_reflectance(library, concentrations, constants, thickness, *, instrument, substrate=None):
    """:func:`predict_reflectance` from the concentrations ``D`` (n_pigments,) of the library's pigments."""
    D = np.asarray(concentrations, dtype=float)
    present = np.flatnonzero(D > 0)
    model = film_model(library.model)
    if substrate is None:
        if np.isfinite(thickness).any():
            raise ValueError("substrate is needed for a film that does not hide it (a card reflectance "
                             "in air, one value per wavelength); or pass thickness='opaque'")
        substrate = np.zeros(library.wavelength_nm.size)
    return model.reflectance(constants[:, :, present], D[present], thickness, substrate=substrate,
                             instrument=instrument, n=getattr(library, "n", 1.45))


def predict_paint(library, recipe, *, thickness, instrument, substrate=None, seed=0, n_draws=DEFAULT_DRAWS,
                  level=DEFAULT_LEVEL, illuminant=colorimetry.DEFAULT_ILLUMINANT,
                  observer=colorimetry.DEFAULT_OBSERVER, model_error=True):
    """Predict the colour of a recipe from a pigment library, with a credible ΔE00 region.

    Parameters
    ----------
    library : PigmentLibrary
        From :func:`bayespig.build_library` or :func:`bayespig.load_library`.
    recipe : mapping or Recipe
        Pigment name -> amount (mass; normalised to fractions), e.g. ``{"ZincWhite": 70,
        "PrussianBlue": 30}``; every pigment must be in the library.
    thickness : float, "opaque" or "unknown"
        Film thickness in the library's units (relative to its films' unless they had measured
        thicknesses); ``"opaque"`` for a film that hides its card; ``"unknown"`` draws it from
        the spread of the library's films.
    instrument : str
        ``"8d-sce"``, ``"8d-sci"`` or ``"45-0"`` (:mod:`bayespig.instruments`).
    substrate : array_like, optional
        Card reflectance measured in air [fraction] per library wavelength; needed unless opaque.
    seed : int
        Seeds the choice of draws, thicknesses and model errors (numpy Generator).
    n_draws : int
    level : float
        Probability content of the region (0 < level < 1).
    illuminant, observer : str
        colour-science names (:data:`bayespig.colorimetry.ILLUMINANTS`, ``OBSERVERS``).
    model_error : bool
        Include the library's cross-validated model error (when it has one).

    Returns
    -------
    PaintPrediction
    """
    recipe = _recipe(library, recipe)
    n_draws = integer("n_draws", n_draws, low=2)
    level = real_scalar("level", level, low=0.0, high=1.0, low_open=True, high_open=True)
    seed = check_seed(seed)
    rng = np.random.default_rng(seed)
    kind, _ = _thickness_argument(thickness)
    n_total = library.constants.shape[0]
    index = rng.choice(n_total, size=n_draws, replace=n_draws > n_total)
    h = thickness_draws(library, thickness, n_draws, rng)
    if substrate is not None:
        substrate = np.asarray(substrate, dtype=float)
        if substrate.shape[-1:] != library.wavelength_nm.shape or not np.isfinite(substrate).all():
            raise ValueError(f"substrate must be finite card reflectances, one per library wavelength "
                             f"({library.wavelength_nm.size}), got shape {substrate.shape}")
    draws = joint_constants(library, recipe.pigments)[index]
    R = predict_reflectance(library, recipe, draws, h, instrument=instrument, substrate=substrate)
    use_error = bool(model_error) and library.model_error is not None
    if use_error:
        covariance = np.asarray(library.model_error, dtype=float)
        if covariance.ndim == 1:
            covariance = np.diag(covariance ** 2)
        R = with_model_error(R, covariance, rng)
    median, Lab, Lab_median, radius = credible_region(R, library.wavelength_nm, level,
                                                      illuminant=illuminant, observer=observer)
    return PaintPrediction(recipe, library.wavelength_nm, R, median, Lab, Lab_median, radius, level,
                           "opaque" if kind == "opaque" else ("unknown" if kind == "unknown" else float(h[0])),
                           instrument, illuminant, observer, use_error, seed)


def with_model_error(reflectance, covariance, rng):
    """Predicted spectra times a draw of the relative model error each, clipped at 0.

    Parameters
    ----------
    reflectance : numpy.ndarray
        (n_draws, n_wl) predicted reflectances [fraction].
    covariance : numpy.ndarray
        (n_wl, n_wl) covariance of the relative error ``measured / predicted - 1``
        (:func:`model_error_from_residuals`).
    rng : numpy.random.Generator

    Returns
    -------
    numpy.ndarray
        ``reflectance * (1 + e)``, ``e ~ N(0, covariance)`` one draw per row, clipped at 0.
    """
    R = np.asarray(reflectance, dtype=float)
    error = rng.multivariate_normal(np.zeros(covariance.shape[0]), covariance, R.shape[0], method="eigh")
    return np.clip(R * (1.0 + error), 0.0, None)


def credible_region(reflectance, wavelength_nm, level, **colour_options):
    """The median spectrum of draws and the ΔE00 radius around its colour holding ``level`` of them.

    Parameters
    ----------
    reflectance : numpy.ndarray
        (n_draws, n_wl) predicted reflectances [fraction].
    wavelength_nm : numpy.ndarray
    level : float
        Probability content of the region (0 < level < 1).
    **colour_options
        ``illuminant``, ``observer`` of :func:`bayespig.colorimetry.reflectance_to_Lab`.

    Returns
    -------
    tuple
        ``(median spectrum, CIELAB of every draw, CIELAB of the median, radius)``: the radius is
        the ``level`` quantile of the draws' CIEDE2000 from the median's colour.
    """
    median = np.median(reflectance, axis=0)
    Lab = colorimetry.reflectance_to_Lab(reflectance, wavelength_nm, **colour_options)
    Lab_median = colorimetry.reflectance_to_Lab(median, wavelength_nm, **colour_options)
    return median, Lab, Lab_median, float(np.quantile(colorimetry.delta_E2000(Lab, Lab_median), level))


def calibration_factor(scores, level=DEFAULT_LEVEL):
    """The split-conformal factor on a region's radius that holds ``level`` of held-out cards.

    Parameters
    ----------
    scores : array_like
        Per held-out card, ΔE00 of the measured colour from its region's centre over the region's
        radius (both at the uncalibrated model error) [-].
    level : float
        Probability content the regions should have (0 < level < 1).

    Returns
    -------
    float
        The ``ceil((n + 1) level)``-th smallest of the ``n`` scores: a region of that many times
        the radius holds a new exchangeable card with probability >= ``level``. With fewer than
        ``level / (1 - level)`` scores (9 at 0.9) that rank exceeds ``n`` and the largest score
        is returned (the guarantee then does not hold).
    """
    s = np.sort(np.asarray(scores, dtype=float).ravel())
    if s.size == 0 or not np.isfinite(s).all() or (s < 0).any():
        raise ValueError(f"scores must be finite and >= 0, at least one, got {s.size} values")
    rank = int(np.ceil((s.size + 1) * level))
    return float(s[min(rank, s.size) - 1])


def model_error_from_residuals(residuals, *, shrinkage=0.1):
    """Covariance over wavelengths of relative model residuals (the cross-validated model error).

    Parameters
    ----------
    residuals : array_like
        (n_films, n_wl) relative residuals ``measured / predicted - 1`` of held-out films.
    shrinkage : float
        Weight of the diagonal in the shrunk estimate ``(1 - s) C + s diag(C)`` (a few films
        estimate a 31 x 31 covariance poorly; the shrinkage keeps it positive definite).

    Returns
    -------
    numpy.ndarray
        (n_wl, n_wl) covariance [1], about zero mean (residuals are not centred: a systematic
        bias of the model is part of its error).
    """
    r = np.asarray(residuals, dtype=float)
    if r.ndim != 2 or r.shape[0] < 2 or not np.isfinite(r).all():
        raise ValueError(f"residuals must be finite, (n_films >= 2, n_wavelengths), got shape {r.shape}")
    C = r.T @ r / r.shape[0]
    return (1.0 - shrinkage) * C + shrinkage * np.diag(np.diag(C))
