"""Colour prediction on real films: leave one film out, bayespig's library against Kubelka-Munk's.

Protocol (identical for both models; only the film model of the library differs,
:mod:`bayespig.library.film_models`). Data: the Revigo films (Geldof et al. 2018), each
measured over its own black and white card on an 8°/d sphere.

1. **Targets**: every mixture film of series 01-15 (the B-F films: tints with zinc white,
   shades with bone black, and series 07's zinc-white/bone-black greys); masstones are not
   targets (they are what a palette is made of).
2. **Leave one film out**: for each target ``X`` a library is built *without* ``X``
   (:func:`bayespig.build_library`, the same staged joint posterior for both models) from the
   films that carry the pigments ``X`` needs: series 07's zinc-white/bone-black films (the base
   pigments) and the other films of ``X``'s series. Other series only add pigments ``X`` does
   not contain.
3. **Prediction** of ``X`` over both of its measured cards from its recipe (appendix A2
   concentrations with the library's densities), with the library's joint draws
   (:func:`bayespig.library.predict.joint_constants`: the white and the black at the values
   the tinting pigment was fitted with, not their own independent draws). ``X``'s film
   thickness is unknown; three variants:

   * ``fitted`` (headline): the one free scalar, ``h``, fitted to ``X``'s two spectra with the
     median constants, each value's deviation relative to the scale of the library's noise
     model (the measured value by default; everything else is predicted), at the mode of its
     posterior under the library's thickness prior (the prior each of its films had;
     :func:`bayespig.library.validation._fit_thickness`);
   * ``per card``: one ``h`` per card, each fitted to that card's spectrum alone by the same
     rule. A drawdown over a black and a white card is two spots of paint whose thickness
     need not be the same: 91 bands of 13 Revigo films are brighter over the black card than
     over the white one (``reports/revigo.md``), which no layer of one thickness gives. The
     study (series 01-15, thickness prior on) moved the median ΔE00 of all held-out films from
     2.38 to 1.84 (radiative transfer) and from 2.32 to 1.86 (Kubelka-Munk) against one ``h``
     for both cards (point estimates of the same libraries, ``benchmarks/loo_point_estimates.py``:
     2.33 to 1.93 and 2.32 to 1.83); the libraries themselves still give each film one thickness.
     It is a bound on what a difference of thickness between the cards can explain, not a
     measurement of it: the two differ by more than a factor 2 for most of the 54 films
     (``reports/colour-prediction.md`` counts them), far more than a drawdown's
     two halves do, so there the thickness absorbs a model error;
   * ``unknown``: ``h`` drawn from the spread of the library's own films (nothing of ``X``
     used but its recipe and cards).
4. **Score**: CIEDE2000 between the median predicted spectrum and the measured one over each
   card (D65, CIE 1964 10°).
5. **Model error and coverage**: the relative residuals ``measured / predicted - 1`` of all
   held-out films give the model-error covariance over wavelengths
   (:func:`bayespig.library.predict.model_error_from_residuals`), scaled by its split-conformal
   calibration factor (:func:`bayespig.library.predict.calibration_factor`). For the coverage of
   ``X``'s 90 % region the covariance and the factor come from the *other* films only (no film
   calibrates its own region), and the region is that of :func:`bayespig.predict_paint`:
   posterior draws of the constants times the model error.
6. **Matching**: each target matched from its leave-one-out library with its own pigments
   allowed (:func:`bayespig.match_paint`, its over-white spectrum as the target, thickness
   fitted): recovered mass fractions against the recipe and the ΔE00 of the match.

References
----------
Geldof, Proaño Gaibor, Ligterink, Hendriks, Kirchner (2018), Heritage Science 6:17.
Ershov, Voloboy & Pozdnyakov (2023), section 2, appendix A2.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np

from .._versions import RESULT_PACKAGES, format_versions, package_versions
from ..data.spectral_table import read_revigo
from ..library.build import DEFAULT_NOISE_SCALE
from ..library.recipes import film_recipes
from ..library.validation import LOO_SETTINGS, N_DRAWS, coverage, leave_one_out

__all__ = [
    "MODELS",
    "ColourPredictionStudy",
    "film_class",
    "colour_prediction_report",
    "colour_prediction_study",
    "target_films",
]

#: The two film models compared, in the library's names.
MODELS = ("radiative-transfer", "kubelka-munk")
#: The white and the black of the tints and shades.
WHITE, BLACK = "ZincWhite", "BoneBlack"
#: Series of the report (the issue: series 01-15).
SERIES = tuple(f"{i:02d}" for i in range(1, 16))
#: The instrument of the Revigo spectra (SCE; see bayespig.studies.revigo.specular_evidence).
INSTRUMENT = "8d-sce"
#: Probability content of the predictive regions.
LEVEL = 0.9
#: The goal of the issue: bayespig's median ΔE00 at most this share of Kubelka-Munk's per class.
GOAL_RATIO = 0.8
#: ... and at most this overall.
GOAL_OVERALL = 2.0
#: ... and the coverage of the 90 % regions within this range.
GOAL_COVERAGE = (0.80, 0.95)
#: Per-card thicknesses further apart than this factor are counted in the report: more than a
#: drawdown's two halves plausibly differ by.
CARD_THICKNESS_FACTOR = 2.0

_ID = re.compile(r"^(\d\d)([A-Z])$")


def _series(film_id):
    match = _ID.match(film_id)
    return match.group(1) if match else None


def film_class(recipe):
    """``"black shade"`` (bone black in it), ``"white tint"`` (zinc white, no black), or None."""
    if BLACK in recipe.amounts:
        return "black shade"
    if WHITE in recipe.amounts:
        return "white tint"
    return None


def target_films(sets, recipes, series=SERIES):
    """The mixture films of ``series`` (two or more pigments with a class), in id order."""
    out = []
    for film_id in sorted(sets):
        recipe = recipes.get(film_id)
        if _series(film_id) in series and recipe is not None and len(recipe.amounts) >= 2 \
                and film_class(recipe) is not None:
            out.append(film_id)
    return out


@dataclasses.dataclass(frozen=True)
class ColourPredictionStudy:
    """All held-out predictions (:class:`bayespig.library.validation.FilmPrediction`), with the
    coverage of the 90 % regions."""

    predictions: tuple
    classes: dict  # film id -> "white tint" | "black shade"
    coverage: dict  # model -> (inside, total)
    inside: dict  # (model, film_id) -> (bool over black, bool over white)
    radius: dict  # (model, film_id) -> (radius over black, radius over white)
    wavelength_nm: np.ndarray
    settings: dict

    def of(self, model):
        return [p for p in self.predictions if p.model == model]


def colour_prediction_study(path, *, films=None, models=MODELS, seed=0, executor=None, progress=None,
                            n_draws=N_DRAWS, settings=LOO_SETTINGS, noise_scale=DEFAULT_NOISE_SCALE):
    """Run the leave-one-film-out study (see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        The Revigo folder.
    films : sequence of str, optional
        Targets (default :func:`target_films`).
    models : sequence of str
    seed : int
    executor : concurrent.futures.Executor, optional
        Runs the leave-one-out builds (default a local pool of two processes).
    progress : callable, optional
        Called with one line per finished film.
    n_draws : int
    settings : InferenceSettings
        Sampler settings of every build.
    noise_scale : {"measured", "model"}
        What every build's relative error is relative to (:func:`bayespig.build_library`).

    Returns
    -------
    ColourPredictionStudy
    """
    sets = read_revigo(path)
    recipes = film_recipes(sets)
    targets = list(target_films(sets, recipes)) if films is None else list(films)
    unknown = [f for f in targets if f not in sets]
    if unknown:
        raise ValueError(f"films: {unknown[0]!r} is not a film of {path}")
    predictions, info = leave_one_out(sets, targets=targets, models=models, seed=seed, executor=executor,
                                      progress=progress, n_draws=n_draws, settings=settings,
                                      base_pigments=(WHITE, BLACK), noise_scale=noise_scale)
    wl = np.asarray(sets[targets[0]].wavelength_nm, dtype=float) if targets else np.array([])
    counts, inside, radius = coverage(predictions, wl, level=LEVEL, seed=seed)
    record = {"seed": seed, "n_draws": n_draws, "instrument": INSTRUMENT, "level": LEVEL, "models": list(models),
              "sampler": dataclasses.asdict(settings), **info,
              "versions": package_versions((*RESULT_PACKAGES, "colour-science"), python=True)}
    return ColourPredictionStudy(predictions, {f: film_class(recipes[f]) for f in targets}, counts, inside, radius,
                                 wl, record)


def _median(values):
    return float(np.median(values)) if len(values) else float("nan")


def class_medians(study, model, variant="fitted"):
    """Median ΔE00 per class and overall, over both cards of every film of ``model``, for one
    thickness ``variant`` of the module docstring (``"fitted"``, ``"per card"``, ``"unknown"``)."""
    field = {"fitted": "delta_E", "per card": "delta_E_per_card", "unknown": "delta_E_unknown"}[variant]
    out = {}
    for cls in ("white tint", "black shade", None):
        values = []
        for p in study.of(model):
            if cls is None or study.classes.get(p.film_id) == cls:
                values.extend(getattr(p, field))
        out[cls or "overall"] = _median(values)
    return out


def _apart(study, model):
    """How many of ``model``'s films have per-card thicknesses apart by more than
    :data:`CARD_THICKNESS_FACTOR`."""
    return sum(1 for p in study.of(model) if len(p.thickness_per_card) == 2
               and abs(np.log(p.thickness_per_card[0] / p.thickness_per_card[1])) > np.log(CARD_THICKNESS_FACTOR))


def _convergence_row(study, model):
    """Table row: how many of ``model``'s leave-one-out libraries were capped in any stage and in
    their own stages (the shared base library's excluded), and the median ΔE00 (fitted thickness,
    both cards) of the films whose own stages converged and of those whose own stages were capped."""
    predictions = study.of(model)
    capped = [p for p in predictions if not p.converged]
    own_capped = [p for p in predictions if not p.own_stages_converged]
    own_converged = [p for p in predictions if p.own_stages_converged]

    def median_of(group):
        value = _median([d for p in group for d in p.delta_E])
        return "—" if np.isnan(value) else f"{value:.2f} ({len(group)} film{'s' if len(group) != 1 else ''})"

    n = len(predictions)
    return (f"| {model} | {len(capped)} of {n} | {len(own_capped)} of {n} | {median_of(own_converged)} | "
            f"{median_of(own_capped)} |")


def _convergence_remark(prediction):
    """What the worst-film list says of a film's library when a stage was capped ('' when none was)."""
    if not prediction.own_stages_converged:
        return "; its library did not converge (its own stages reached the step cap)"
    if not prediction.converged:
        return "; only the shared base stage of its library reached the step cap"
    return ""


def _per_card(rt, km):
    """``b / w (h_b, h_w)`` of both models' per-card predictions, for the film table."""
    def one(p):
        if p is None or not p.delta_E_per_card:
            return "—"
        return (" / ".join(f"{d:.2f}" for d in p.delta_E_per_card)
                + " (" + ", ".join(f"{h:.3g}" for h in p.thickness_per_card) + ")")
    return f"{one(rt)}; {one(km)}"


def colour_prediction_report(study, *, command="bayespig colour-prediction"):
    """The Markdown of ``reports/colour-prediction.md``."""
    rt, km = MODELS
    lines = ["# Colour prediction on real films: bayespig's pigment library against Kubelka-Munk", "",
             f"Regenerate: `{command}`.", "",
             "Every mixture film of the Revigo series 01-15 (Geldof et al. 2018) is predicted from its recipe by a "
             "library built **without it** (leave one film out), over its black and its white card, by bayespig's "
             "radiative-transfer library and by a two-constant Kubelka-Munk library (Saunderson correction) built "
             "from the same films by the same staged posterior. Protocol: the module docstring of "
             "`bayespig.studies.colour_prediction`. ΔE00 under D65, CIE 1964 10°.", ""]
    lines += ["## Median ΔE00", "", "| thickness | model | white tints | black shades | overall |", "|---|---|---|---|---|"]
    for variant in ("fitted", "per card", "unknown"):
        for model in (rt, km):
            m = class_medians(study, model, variant)
            lines.append(f"| {variant} | {model} | {m['white tint']:.2f} | {m['black shade']:.2f} | {m['overall']:.2f} |")
    m_rt, m_km = class_medians(study, rt), class_medians(study, km)
    goals = []
    for cls in ("white tint", "black shade"):
        ratio = m_rt[cls] / m_km[cls] if m_km[cls] > 0 else float("nan")
        goals.append(f"{cls}s: bayespig / Kubelka-Munk = {ratio:.2f} (goal <= {GOAL_RATIO}) — "
                     f"{'met' if ratio <= GOAL_RATIO else 'not met'}")
    goals.append(f"overall: bayespig {m_rt['overall']:.2f} (goal <= {GOAL_OVERALL}) — "
                 f"{'met' if m_rt['overall'] <= GOAL_OVERALL else 'not met'}")
    m_card = class_medians(study, rt, "per card"), class_medians(study, km, "per card")
    card_ratios = ", ".join(f"{cls}s {m_card[0][cls] / m_card[1][cls]:.2f}" for cls in ("white tint", "black shade")
                            if m_card[1][cls] > 0)
    lines += ["", "Goals (fitted thickness): " + "; ".join(goals) + ".", "",
              "Thickness: *fitted*, one relative thickness per film fitted to both of its spectra, at its "
              "posterior mode under the library's thickness prior (the prior each of the library's films had); "
              "*per card*, one per card fitted to that card's spectrum alone under the same prior (a drawdown's "
              "two halves need not be of one thickness); *unknown*, drawn from the library's films. Everything "
              "else is predicted. With one "
              f"thickness per card, bayespig / Kubelka-Munk: {card_ratios}; overall bayespig "
              f"{m_card[0]['overall']:.2f}. This bounds what a difference of thickness between the cards can "
              f"explain; the two thicknesses differ by more than a factor {CARD_THICKNESS_FACTOR:g} for "
              f"{_apart(study, rt)} of {len(study.of(rt))} films (bayespig) and {_apart(study, km)} of "
              f"{len(study.of(km))} (Kubelka-Munk), where the thickness absorbs a model error rather than "
              "measuring the paint.", ""]
    lines += ["## Coverage of the 90 % predictive regions", "",
              "The model error of film X's region is learned from the other held-out films only: their residuals' "
              "covariance, scaled by its split-conformal calibration factor on the other films' scores "
              "(`bayespig.library.predict.calibration_factor`).", "",
              "| model | inside / total | coverage |", "|---|---|---|"]
    for model, (hits, total) in study.coverage.items():
        lines.append(f"| {model} | {hits} / {total} | {hits / total:.0%} |")
    lo, hi = GOAL_COVERAGE
    lines += ["", f"Goal: between {lo:.0%} and {hi:.0%}.", ""]
    lines += ["## Convergence of the leave-one-out libraries", "",
              ("A build is capped when any stage of its staged posterior reached the sampler's step cap "
               "(`max_steps_reached`); its draws are then those of chains that may not have mixed. Every build "
               "of a series shares the stages of its base library (zinc white and bone black, from the films "
               "of series 07 not held out); the third column counts the builds capped in their own stages "
               "(the held-out film's pigments), and the medians split the films by that."), "",
              "| model | capped builds (any stage) | capped in their own stages | median ΔE00, own stages "
              "converged | median ΔE00, own stages capped |",
              "|---|---|---|---|---|"]
    for model in (rt, km):
        lines.append(_convergence_row(study, model))
    lines += ["", "## Every film", "",
              "| film | class | recipe | bayespig ΔE00 black / white | KM ΔE00 black / white | bayespig h | "
              "per card: bayespig ΔE00 / KM ΔE00 (h black, white) | inside 90 % (bayespig) | worst band (bayespig) |",
              "|---|---|---|---|---|---|---|---|---|"]
    km_of = {p.film_id: p for p in study.of(km)}
    for p in sorted(study.of(rt), key=lambda q: q.film_id):
        k = km_of.get(p.film_id)
        recipe = ", ".join(f"{name} {share:.3f}" for name, share in p.recipe.items())
        flags = study.inside.get((rt, p.film_id), (False, False))
        lines.append(f"| {p.film_id} | {study.classes.get(p.film_id)} | {recipe} | {p.delta_E[0]:.2f} / {p.delta_E[1]:.2f} | "
                     + (f"{k.delta_E[0]:.2f} / {k.delta_E[1]:.2f}" if k else "—")
                     + f" | {p.thickness:.3g} | {_per_card(p, k)} | {'/'.join('yes' if f else 'no' for f in flags)} | "
                     f"{p.worst_band_nm:g} nm |")
    worst = sorted(study.of(rt), key=lambda q: -max(q.delta_E))[:5]
    lines += ["", "## The worst films", ""]
    for p in worst:
        band = p.worst_band_nm
        sign = np.sign(p.residuals[:, np.argmin(np.abs(study.wavelength_nm - band))])
        side = ["darker than predicted" if s < 0 else "lighter than predicted" for s in sign]
        lines.append(f"- **{p.film_id}** ({study.classes.get(p.film_id)}, ΔE00 {p.delta_E[0]:.2f} / {p.delta_E[1]:.2f}): the largest "
                     f"relative residual at {band:g} nm (over black {side[0]}, over white {side[1]}); fitted thickness "
                     f"{p.thickness:.3g}{_convergence_remark(p)}.")
    lines += ["", "## Matching", "",
              "Each target matched from its leave-one-out library with its own pigments allowed (target: its "
              "over-white spectrum; thickness fitted).", "",
              "| model | median abs. error of mass fraction | median ΔE00 of the match |", "|---|---|---|"]
    for model in (rt, km):
        errors, dEs = [], []
        for p in study.of(model):
            for name, share in p.recipe.items():
                errors.append(abs(p.match_fractions.get(name, 0.0) - share))
            dEs.append(p.match_delta_E)
        lines.append(f"| {model} | {_median(errors):.3f} | {_median(dEs):.2f} |")
    s = study.settings
    scale = s.get("noise_scale", "model")
    lines += ["", f"Settings: seed {s['seed']}, {s['n_draws']} draws per prediction, instrument {s['instrument']}, "
              f"level {s['level']}; every build's relative error eps relative to the "
              f"{'measured' if scale == 'measured' else 'predicted (eq. 7)'} value (noise scale {scale!r}, "
              "`bayespig.build_library`); every build's sampler: "
              + ", ".join(f"{k} {v}" for k, v in s.get("sampler", {}).items() if k in ("target_ess", "max_steps"))
              + (f"; {s['seconds'] / 60:.0f} min" if "seconds" in s else "")
              + ("; " + format_versions(s["versions"]) if "versions" in s else "") + ".", ""]
    return "\n".join(lines)
