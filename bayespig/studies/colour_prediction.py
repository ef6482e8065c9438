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
   concentrations with the library's densities). ``X``'s film thickness is unknown; two
   variants:

   * ``fitted`` (headline): the one free scalar, ``h``, fitted to ``X``'s two spectra by least
     squares in relative deviation with the median constants (everything else is predicted;
     the tint study of issue 9 used the same rule);
   * ``unknown``: ``h`` drawn from the spread of the library's own films (nothing of ``X``
     used but its recipe and cards).
4. **Score**: CIEDE2000 between the median predicted spectrum and the measured one over each
   card (D65, CIE 1964 10°).
5. **Model error and coverage**: the relative residuals ``measured / predicted - 1`` of all
   held-out films give the model-error covariance over wavelengths
   (:func:`bayespig.library.predict.model_error_from_residuals`). For the coverage of ``X``'s
   90 % region the covariance comes from the *other* films only (no film calibrates its own
   region), and the region is that of :func:`bayespig.predict_paint`: posterior draws of the
   constants times the model error.
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
import time

import numpy as np
from scipy import optimize

from .. import colorimetry
from .._pool import executor_or_local_pool
from ..data.spectral_table import read_revigo
from ..inference.settings import InferenceSettings
from ..library.build import build_library
from ..library.match import match_paint
from ..library.predict import model_error_from_residuals, predict_reflectance
from ..library.recipes import film_recipes

__all__ = [
    "BASE_SERIES",
    "MODELS",
    "ColourPredictionStudy",
    "FilmPrediction",
    "colour_prediction_report",
    "colour_prediction_study",
    "target_films",
]

#: The two film models compared, in the library's names.
MODELS = ("radiative-transfer", "kubelka-munk")
#: Series whose films give the base pigments (zinc white and bone black) of every library.
BASE_SERIES = "07"
#: The white and the black of the tints and shades.
WHITE, BLACK = "ZincWhite", "BoneBlack"
#: Series of the report (the issue: series 01-15).
SERIES = tuple(f"{i:02d}" for i in range(1, 16))
#: The instrument of the Revigo spectra (SCE; see bayespig.studies.revigo.specular_evidence).
INSTRUMENT = "8d-sce"
#: Probability content of the predictive regions.
LEVEL = 0.9
#: Draws of each prediction.
N_DRAWS = 200
#: Sampler settings of the leave-one-out builds: shorter runs than a library's default (ESS 100
#: per coordinate instead of 400, 64 stored draws per chain): ~120 builds must fit in an
#: afternoon, and a prediction uses the constants' median and a few hundred draws.
LOO_SETTINGS = InferenceSettings(target_ess=100.0, draws_per_chain=64, max_steps=6000)
#: Relative thickness search range of the fitted-thickness variant.
THICKNESS_RANGE = (1e-2, 1e2)
#: The goal of the issue: bayespig's median ΔE00 at most this share of Kubelka-Munk's per class.
GOAL_RATIO = 0.8
#: ... and at most this overall.
GOAL_OVERALL = 2.0
#: ... and the coverage of the 90 % regions within this range.
GOAL_COVERAGE = (0.80, 0.95)

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


def training_films(recipes, target, base_pigments=(WHITE, BLACK)):
    """Films of ``target``'s leave-one-out library: those made only of its pigments and the base
    pigments, without it; split into ``(base_only, others)``.

    ``base_only`` are the films of base pigments alone (the base library's films); ``others`` the
    films that add ``target``'s own pigments (Revigo: the rest of its series).
    """
    allowed = set(recipes[target].amounts) | set(base_pigments)
    films = [f for f in sorted(recipes) if f != target and set(recipes[f].amounts) <= allowed]
    base_only = tuple(f for f in films if set(recipes[f].amounts) <= set(base_pigments))
    return base_only, tuple(f for f in films if f not in base_only)


def _spectra(ms, film_id):
    """Measured ``(card_black, card_white, over_black, over_white)`` reflectances [fraction]."""
    out = []
    for suffix in ("b", "w", "ob", "ow"):
        sample = ms.sample(f"{film_id}_{suffix}")
        out.append(np.asarray(sample.measurements[0].values, dtype=float))
    return out


@dataclasses.dataclass(frozen=True)
class FilmPrediction:
    """One held-out film predicted by one model."""

    film_id: str
    model: str
    film_class: str
    recipe: dict
    thickness: float
    delta_E: tuple  # (over black, over white), fitted thickness
    delta_E_unknown: tuple  # (over black, over white), thickness from the library's films
    residuals: np.ndarray  # (2, n_wl) measured / predicted - 1 (fitted thickness)
    draws: np.ndarray  # (2, n_draws, n_wl) model spectra of the posterior draws (no model error)
    measured: np.ndarray  # (2, n_wl)
    match_fractions: dict
    match_delta_E: float
    seconds: float
    converged: bool
    worst_band_nm: float


def _fit_thickness(library, recipe, constants, cards, measured):
    """The one free scalar: relative thickness minimising the relative misfit over both cards."""
    def misfit(log_h):
        h = np.array([np.exp(log_h)])
        total = 0.0
        for card, values in zip(cards, measured):
            R = predict_reflectance(library, recipe, constants[None], h, instrument=INSTRUMENT, substrate=card)[0]
            total += float(np.sum((values / R - 1.0) ** 2))
        return total
    result = optimize.minimize_scalar(misfit, bounds=np.log(THICKNESS_RANGE), method="bounded",
                                      options={"xatol": 1e-4})
    return float(np.exp(result.x))


def _build(task):
    """A library of ``films`` (a process task), on a base library when given."""
    path, films, model, seed, base, settings = task
    sets = read_revigo(path)
    return build_library({f: sets[f] for f in films}, model=model, seed=seed, progress=False, base=base,
                         settings=settings)


def _predict_film(task):
    """Build the leave-one-out library of one target and predict it (one process task)."""
    path, film_id, model, seed, n_draws, films, base, settings = task
    started = time.perf_counter()
    sets = read_revigo(path)
    recipes = film_recipes(sets)
    library = build_library({f: sets[f] for f in films}, model=model, seed=seed, progress=False, base=base,
                            settings=settings)
    recipe = recipes[film_id]
    card_b, card_w, over_b, over_w = _spectra(sets[film_id], film_id)
    cards, measured = (card_b, card_w), np.stack([over_b, over_w])
    median = np.median(library.constants, axis=0)
    h = _fit_thickness(library, recipe, median, cards, measured)
    rng = np.random.default_rng(seed)
    index = rng.choice(library.constants.shape[0], size=n_draws, replace=n_draws > library.constants.shape[0])
    draws = library.constants[index]
    mean, sd = library.thickness_prior
    h_unknown = np.exp(rng.normal(mean, sd, n_draws))
    wl = library.wavelength_nm
    spectra, dE, dE_unknown = [], [], []
    for card, values in zip(cards, measured):
        R = predict_reflectance(library, recipe, draws, np.full(n_draws, h), instrument=INSTRUMENT, substrate=card)
        Ru = predict_reflectance(library, recipe, draws, h_unknown, instrument=INSTRUMENT, substrate=card)
        spectra.append(R)
        lab = colorimetry.reflectance_to_Lab(values, wl)
        dE.append(float(colorimetry.delta_E2000(colorimetry.reflectance_to_Lab(np.median(R, axis=0), wl), lab)))
        dE_unknown.append(float(colorimetry.delta_E2000(colorimetry.reflectance_to_Lab(np.median(Ru, axis=0), wl),
                                                        lab)))
    spectra = np.stack(spectra)
    residuals = measured / np.median(spectra, axis=1) - 1.0
    match = match_paint(library, over_w, pigments=tuple(recipe.amounts), instrument=INSTRUMENT, thickness="fit",
                        substrate=card_w, seed=seed, n_spread=0, n_draws=50)
    capped = any(stage.get("max_steps_reached") for stage in library.stages)
    return FilmPrediction(film_id, model, film_class(recipe), dict(recipe.amounts), h, tuple(dE), tuple(dE_unknown),
                          residuals, spectra, measured, dict(match.recipe.amounts), match.delta_E,
                          time.perf_counter() - started, not capped,
                          float(wl[np.argmax(np.abs(residuals).max(axis=0))]))


@dataclasses.dataclass(frozen=True)
class ColourPredictionStudy:
    """All held-out predictions, with the coverage of the 90 % regions."""

    predictions: tuple  # FilmPrediction
    coverage: dict  # model -> (inside, total)
    inside: dict  # (model, film_id) -> (bool over black, bool over white)
    radius: dict  # (model, film_id) -> (radius over black, radius over white)
    wavelength_nm: np.ndarray
    settings: dict

    def of(self, model):
        return [p for p in self.predictions if p.model == model]


def _coverage(predictions, wavelength_nm, seed):
    """Leave-one-out model-error covariance per film, its 90 % regions and whether they hold the film."""
    inside, radius, coverage = {}, {}, {}
    rng = np.random.default_rng(seed)
    for model in {p.model for p in predictions}:
        own = [p for p in predictions if p.model == model]
        hits = total = 0
        for p in own:
            others = np.concatenate([q.residuals for q in own if q.film_id != p.film_id])
            covariance = model_error_from_residuals(others)
            flags, radii = [], []
            for k in range(2):
                R = p.draws[k]
                noise = rng.multivariate_normal(np.zeros(covariance.shape[0]), covariance, R.shape[0], method="eigh")
                R = np.clip(R * (1.0 + noise), 0.0, None)
                lab = colorimetry.reflectance_to_Lab(R, wavelength_nm)
                centre = colorimetry.reflectance_to_Lab(np.median(R, axis=0), wavelength_nm)
                r = float(np.quantile(colorimetry.delta_E2000(lab, centre), LEVEL))
                measured = colorimetry.reflectance_to_Lab(p.measured[k], wavelength_nm)
                flag = bool(colorimetry.delta_E2000(measured, centre) <= r)
                flags.append(flag)
                radii.append(r)
                hits += flag
                total += 1
            inside[(model, p.film_id)] = tuple(flags)
            radius[(model, p.film_id)] = tuple(radii)
        coverage[model] = (hits, total)
    return coverage, inside, radius


def colour_prediction_study(path, *, films=None, models=MODELS, seed=0, executor=None, progress=None,
                            n_draws=N_DRAWS, settings=LOO_SETTINGS):
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
    say = progress or (lambda message: None)
    started = time.perf_counter()
    results = []
    with executor_or_local_pool(executor) as pool:
        # the base libraries (white and black from their own films), once per model
        plans = {f: training_films(recipes, f) for f in targets}
        base_films = sorted({g for base_only, _ in plans.values() for g in base_only})
        bases = {m: pool.submit(_build, (str(path), base_films, m, seed, None, settings)) for m in models}
        bases = {m: future.result() for m, future in bases.items()}
        say(f"base libraries ({', '.join(base_films)}) built: {time.perf_counter() - started:.0f} s")
        tasks = []
        for m in models:
            for f in targets:
                base_only, others = plans[f]
                if others:  # the base films are all there (the target is not one): share the base library
                    tasks.append((str(path), f, m, seed, n_draws, others, bases[m], settings))
                else:  # a base-only target: its library is built without it from the others
                    tasks.append((str(path), f, m, seed, n_draws, base_only, None, settings))
        futures = [pool.submit(_predict_film, task) for task in tasks]
        for i, future in enumerate(futures, 1):
            p = future.result()
            results.append(p)
            say(f"[{i}/{len(tasks)}] {p.model} {p.film_id}: ΔE00 {p.delta_E[0]:.2f} / {p.delta_E[1]:.2f} "
                f"(black / white), {p.seconds:.0f} s; {time.perf_counter() - started:.0f} s in all")
    wl = sets[targets[0]].wavelength_nm if targets else np.array([])
    coverage, inside, radius = _coverage(results, wl, seed)
    record = {"seed": seed, "n_draws": n_draws, "instrument": INSTRUMENT, "level": LEVEL, "models": list(models),
              "thickness_range": list(THICKNESS_RANGE), "sampler": dataclasses.asdict(settings),
              "seconds": time.perf_counter() - started, "base_films": base_films}
    return ColourPredictionStudy(tuple(results), coverage, inside, radius, np.asarray(wl), record)


def _median(values):
    return float(np.median(values)) if len(values) else float("nan")


def class_medians(study, model, variant="fitted"):
    """Median ΔE00 per class and overall, over both cards of every film of ``model``."""
    out = {}
    for cls in ("white tint", "black shade", None):
        values = []
        for p in study.of(model):
            if cls is None or p.film_class == cls:
                values.extend(p.delta_E if variant == "fitted" else p.delta_E_unknown)
        out[cls or "overall"] = _median(values)
    return out


def colour_prediction_report(study, *, command="bayespig study colour-prediction"):
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
    for variant in ("fitted", "unknown"):
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
    lines += ["", "Goals (fitted thickness): " + "; ".join(goals) + ".", ""]
    lines += ["## Coverage of the 90 % predictive regions", "",
              "The model error of film X's region is learned from the residuals of the other held-out films only.", "",
              "| model | inside / total | coverage |", "|---|---|---|"]
    for model, (hits, total) in study.coverage.items():
        lines.append(f"| {model} | {hits} / {total} | {hits / total:.0%} |")
    lo, hi = GOAL_COVERAGE
    lines += ["", f"Goal: between {lo:.0%} and {hi:.0%}.", ""]
    lines += ["## Every film", "",
              "| film | class | recipe | bayespig ΔE00 black / white | KM ΔE00 black / white | bayespig h | "
              "inside 90 % (bayespig) | worst band (bayespig) |", "|---|---|---|---|---|---|---|---|"]
    km_of = {p.film_id: p for p in study.of(km)}
    for p in sorted(study.of(rt), key=lambda q: q.film_id):
        k = km_of.get(p.film_id)
        recipe = ", ".join(f"{name} {share:.3f}" for name, share in p.recipe.items())
        flags = study.inside.get((rt, p.film_id), (False, False))
        lines.append(f"| {p.film_id} | {p.film_class} | {recipe} | {p.delta_E[0]:.2f} / {p.delta_E[1]:.2f} | "
                     + (f"{k.delta_E[0]:.2f} / {k.delta_E[1]:.2f}" if k else "—")
                     + f" | {p.thickness:.3g} | {'/'.join('yes' if f else 'no' for f in flags)} | {p.worst_band_nm:g} nm |")
    worst = sorted(study.of(rt), key=lambda q: -max(q.delta_E))[:5]
    lines += ["", "## The worst films", ""]
    for p in worst:
        band = p.worst_band_nm
        sign = np.sign(p.residuals[:, np.argmin(np.abs(study.wavelength_nm - band))])
        side = ["darker than predicted" if s < 0 else "lighter than predicted" for s in sign]
        lines.append(f"- **{p.film_id}** ({p.film_class}, ΔE00 {p.delta_E[0]:.2f} / {p.delta_E[1]:.2f}): the largest "
                     f"relative residual at {band:g} nm (over black {side[0]}, over white {side[1]}); fitted thickness "
                     f"{p.thickness:.3g}{'; its library did not converge' if not p.converged else ''}.")
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
    lines += ["", f"Settings: seed {s['seed']}, {s['n_draws']} draws per prediction, instrument {s['instrument']}, "
              f"level {s['level']}.", ""]
    return "\n".join(lines)
