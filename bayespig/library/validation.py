"""Cross-validation of a pigment library: each mixture film predicted by a library built without it.

The library's model error (the term of :func:`bayespig.predict_paint`'s credible region beyond
the constants' posterior) is learned here, from how well films the library has *not* seen are
predicted. For each target film ``X`` (default: every film with two or more pigments):

1. a library is built without ``X`` from the films that carry what ``X`` needs: those made only
   of ``X``'s pigments and the base pigments (:func:`training_films`); the base pigments' own
   films are fitted once (a base library, :func:`bayespig.build_library`'s ``base=``) and shared
   by every target that is not one of them;
2. ``X`` is predicted from its recipe over each of its measured cards, its unknown thickness
   the one free scalar (fitted to its spectra in relative deviation under the library's
   thickness prior, median constants), with
   the library's joint draws (:func:`bayespig.library.predict.joint_constants`: the base
   pigments at the values the other pigments were fitted with), and
   also drawn from the library's own films (nothing of ``X`` used but its recipe and cards);
3. the relative residuals ``measured / predicted - 1`` over all targets give the model-error
   covariance over wavelengths (:func:`bayespig.library.predict.model_error_from_residuals`),
   scaled by its split-conformal calibration factor
   (:func:`bayespig.library.predict.calibration_factor`); for the coverage of ``X``'s region
   only the *other* targets' residuals and scores are used.

The films are measured over cards (a film sample whose substrate is a measured substrate sample
of its set, e.g. a Revigo drawdown over its black and white cards), with a hemispherical
instrument (8°/d SCE/SCI) the film models predict.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy import optimize

from .. import colorimetry
from .._pool import executor_or_local_pool
from ..inference.settings import InferenceSettings
from .build import DEFAULT_NOISE_SCALE, LIBRARY_EPS, _base_pigments, build_library, check_noise_scale
from .match import match_paint
from .predict import (
    DEFAULT_LEVEL,
    calibration_factor,
    credible_region,
    joint_constants,
    model_error_from_residuals,
    predict_reflectance,
    with_model_error,
)
from .recipes import film_recipes

__all__ = [
    "LOO_SETTINGS",
    "FilmPrediction",
    "card_spectra",
    "conformal_scores",
    "coverage",
    "cross_validate",
    "leave_one_out",
    "training_films",
]

#: Sampler settings of the leave-one-out builds: shorter runs than a library's default (ESS 100
#: per coordinate instead of 400, 64 stored draws per chain): a study builds ~100 libraries, and
#: a prediction uses the constants' median and a few hundred draws.
LOO_SETTINGS = InferenceSettings(target_ess=100.0, draws_per_chain=64, max_steps=6000)
#: Relative thickness search range of the fitted-thickness prediction.
THICKNESS_RANGE = (1e-2, 1e2)
#: Draws of each prediction.
N_DRAWS = 200


@dataclasses.dataclass(frozen=True)
class FilmPrediction:
    """One held-out film predicted by one film model.

    Attributes
    ----------
    film_id, model : str
    recipe : dict
        Pigment -> mass fraction.
    cards : tuple of str
        The substrate samples, one per predicted spectrum.
    thickness : float
        Fitted relative thickness.
    delta_E, delta_E_unknown : tuple of float
        ΔE00 (D65, CIE 1964 10°) per card: fitted thickness, and thickness drawn from the library's films.
    residuals : numpy.ndarray
        (n_cards, n_wl) ``measured / predicted - 1`` (fitted thickness, median of the draws).
    draws : numpy.ndarray
        (n_cards, n_draws, n_wl) model spectra of the posterior draws (no model error).
    measured : numpy.ndarray
        (n_cards, n_wl).
    match_fractions : dict
        The recipe :func:`bayespig.match_paint` finds for the last card's spectrum (its own pigments allowed).
    match_delta_E : float
    seconds : float
    converged : bool
        No stage of its library reached the step cap (its own stages and those of the base
        library it was built on).
    worst_band_nm : float
        Band of the largest relative residual.
    thickness_per_card, delta_E_per_card : tuple of float
        The thickness fitted to each card's spectrum alone, and the ΔE00 of the prediction there:
        a drawdown over a black and a white card is two spots of paint, not necessarily of one
        thickness (Revigo: 91 bands of 13 films measured brighter over black than over white,
        which no single thickness gives). A bound on what thickness can explain rather than a
        measurement of it: on Revigo the two differ by more than a factor 2 for 43 of 54 films
        (:mod:`bayespig.studies.colour_prediction`), where they absorb a model error.
    own_stages_converged : bool
        No stage of its library's own reached the step cap (the stages inherited from the base
        library, ``provenance["base_library"]``, which every build of a study shares, excluded).
    """

    film_id: str
    model: str
    recipe: dict
    cards: tuple
    thickness: float
    delta_E: tuple
    delta_E_unknown: tuple
    residuals: np.ndarray
    draws: np.ndarray
    measured: np.ndarray
    match_fractions: dict
    match_delta_E: float
    seconds: float
    converged: bool
    worst_band_nm: float
    thickness_per_card: tuple = ()
    delta_E_per_card: tuple = ()
    own_stages_converged: bool = True


def card_spectra(measurements):
    """The film's spectra over its measured cards: ``(instrument, [(card name, card, film)])``.

    Raises
    ------
    ValueError
        When no film sample of the set lies on a measured substrate sample, or the films were
        measured with several instruments.
    """
    pairs, instruments = [], set()
    for sample in measurements.samples:
        if sample.role != "film" or not isinstance(sample.substrate, str):
            continue
        card = measurements.sample(sample.substrate)
        for m in sample.measurements:
            instruments.add(m.label)
            match = [c for c in card.measurements if c.label == m.label]
            if match:
                pairs.append((card.name, np.asarray(match[0].values, dtype=float), np.asarray(m.values, dtype=float)))
    if not pairs or len(instruments) != 1:
        raise ValueError(f"film set {measurements.metadata.get('film_id', measurements.source)!r}: cross-validation "
                         "needs films over measured cards with one hemispherical instrument")
    return instruments.pop(), pairs


def training_films(recipes, target, base_pigments):
    """Films of ``target``'s leave-one-out library, split into ``(base_only, others)``.

    The films made only of ``target``'s pigments and the base pigments, without ``target``;
    ``base_only`` are those of base pigments alone (a base library's films).
    """
    allowed = set(recipes[target].amounts) | set(base_pigments)
    films = [f for f in sorted(recipes) if f != target and set(recipes[f].amounts) <= allowed]
    base_only = tuple(f for f in films if set(recipes[f].amounts) <= set(base_pigments))
    return base_only, tuple(f for f in films if f not in base_only)


def _fit_thickness(library, recipe, constants, instrument, pairs, prior=True):
    """The one free scalar: the held-out film's relative thickness, at the mode of its posterior.

    The misfit is that of the library's own likelihood, each value's deviation standardized by
    ``eps`` (``provenance["eps"]``) relative to the measured value, or to the predicted one for a
    library built with eq. (7)'s scale (``provenance["noise_scale"]``,
    :data:`bayespig.library.build.NOISE_SCALES`; a library saved without it predates the
    measured scale and used eq. 7's), plus, with ``prior``, the library's thickness prior as a
    penalty, ``((log h - mu) / sd)^2`` with ``(mu, sd) = library.thickness_prior`` (the spread of
    its own films' ``log h``): the held-out film gets the prior every film of the library had
    (:class:`bayespig.inference.film_thickness.FilmThickness`), not a free scalar that can run
    to where no drawdown is. Without it, Revigo 12D (cobalt blue with 1 % bone black) went to
    ``h = 29`` in the MCMC study (``bayespig colour-prediction``, 2026-12-04); with it to 3.38,
    at the same ΔE00 (10.74 / 10.71 over black / white): the film hides its card at either
    thickness and its miss is in the constants, not in ``h``.

    Revigo series 01-15, point estimates of every leave-one-out library
    (``benchmarks/loo_point_estimates.py``): the measured scale against eq. (7)'s moved the
    median ΔE00 of all held-out films from 2.30 to 2.22 (radiative transfer) and from 2.36 to
    2.32 (Kubelka-Munk); the prior left the class medians within 0.02 and moved three films by
    more than 0.05 (that script's docstring).
    """
    measured_scale = library.provenance.get("noise_scale", "model") == "measured"
    eps = float(library.provenance.get("eps", LIBRARY_EPS))
    mean, sd = library.thickness_prior

    def misfit(log_h):
        h = np.array([np.exp(log_h)])
        total = ((log_h - mean) / sd) ** 2 if prior else 0.0
        for _, card, values in pairs:
            R = predict_reflectance(library, recipe, constants[None], h, instrument=instrument, substrate=card)[0]
            total += float(np.sum(((values - R) / (eps * (values if measured_scale else R))) ** 2))
        return total
    result = optimize.minimize_scalar(misfit, bounds=np.log(THICKNESS_RANGE), method="bounded",
                                      options={"xatol": 1e-4})
    return float(np.exp(result.x))


def _build(task):
    """A library of the films ``films`` (a process task), on a base library when given."""
    sets, films, model, seed, base, settings, noise_scale = task
    return build_library({f: sets[f] for f in films}, model=model, seed=seed, progress=False, base=base,
                         settings=settings, noise_scale=noise_scale)


def predict_held_out(library, measurements, recipe, *, model, film_id, seed=0, n_draws=N_DRAWS, started=None):
    """Predict one film the library has not seen (see the module docstring, step 2)."""
    started = time.perf_counter() if started is None else started
    instrument, pairs = card_spectra(measurements)
    joint = joint_constants(library, recipe.pigments)  # the fixed pigments at their fixed values
    median = np.median(joint, axis=0)
    h = _fit_thickness(library, recipe, median, instrument, pairs)
    rng = np.random.default_rng(seed)
    index = rng.choice(joint.shape[0], size=n_draws, replace=n_draws > joint.shape[0])
    draws = joint[index]
    mean, sd = library.thickness_prior
    h_unknown = np.exp(rng.normal(mean, sd, n_draws))
    wl = library.wavelength_nm
    # colour needs the visible spectrum: with fewer bands only the spectral residuals are scored
    coloured = wl.size >= colorimetry.MIN_WAVELENGTHS

    def delta_E(R, values):
        if not coloured:
            return float("nan")
        lab = colorimetry.reflectance_to_Lab(values, wl)
        return float(colorimetry.delta_E2000(colorimetry.reflectance_to_Lab(np.median(R, axis=0), wl), lab))

    spectra, dE, dE_unknown, h_card, dE_card = [], [], [], [], []
    for pair in pairs:
        _, card, values = pair
        R = predict_reflectance(library, recipe, draws, np.full(n_draws, h), instrument=instrument, substrate=card)
        Ru = predict_reflectance(library, recipe, draws, h_unknown, instrument=instrument, substrate=card)
        h_card.append(_fit_thickness(library, recipe, median, instrument, [pair]))
        Rc = predict_reflectance(library, recipe, draws, np.full(n_draws, h_card[-1]), instrument=instrument,
                                 substrate=card)
        spectra.append(R)
        dE.append(delta_E(R, values))
        dE_unknown.append(delta_E(Ru, values))
        dE_card.append(delta_E(Rc, values))
    spectra = np.stack(spectra)
    measured = np.stack([values for _, _, values in pairs])
    residuals = measured / np.median(spectra, axis=1) - 1.0
    _, card, values = pairs[-1]
    fractions, match_dE = {}, float("nan")
    if coloured:
        match = match_paint(library, values, pigments=tuple(recipe.amounts), instrument=instrument, thickness="fit",
                            substrate=card, seed=seed, n_spread=0, n_draws=50)
        fractions, match_dE = dict(match.recipe.amounts), match.delta_E
    return FilmPrediction(film_id, model, dict(recipe.amounts), tuple(name for name, _, _ in pairs), h, tuple(dE),
                          tuple(dE_unknown), residuals, spectra, measured, fractions,
                          match_dE, time.perf_counter() - started, not library.step_cap_reached(),
                          float(wl[np.argmax(np.abs(residuals).max(axis=0))]), tuple(h_card), tuple(dE_card),
                          not library.step_cap_reached(inherited=False))


def _predict_film(task):
    """Build the leave-one-out library of one target and predict it (a process task)."""
    sets, film_id, model, seed, n_draws, films, base, settings, noise_scale = task
    started = time.perf_counter()
    library = build_library({f: sets[f] for f in films}, model=model, seed=seed, progress=False, base=base,
                            settings=settings, noise_scale=noise_scale)
    recipe = film_recipes({film_id: sets[film_id]})[film_id]
    return predict_held_out(library, sets[film_id], recipe, model=model, film_id=film_id, seed=seed,
                            n_draws=n_draws, started=started)


def leave_one_out(measurements, *, targets=None, models=("radiative-transfer",), seed=0, executor=None,
                  progress=None, n_draws=N_DRAWS, settings=LOO_SETTINGS, base_pigments=None,
                  noise_scale=DEFAULT_NOISE_SCALE):
    """Every target film predicted by a library built without it (see the module docstring).

    Parameters
    ----------
    measurements : dict
        Film id -> MeasurementSet with its recipe (e.g. :func:`bayespig.data.read_revigo`).
    targets : sequence of str, optional
        Default: every film with two or more pigments.
    models : sequence of str
        Film models (``"radiative-transfer"``, ``"kubelka-munk"``): the same protocol for each.
    seed : int
    executor : concurrent.futures.Executor, optional
        Runs the builds (default a local pool of two processes).
    progress : callable, optional
        Called with one line per finished film.
    n_draws : int
    settings : InferenceSettings
        Sampler settings of every build (default :data:`LOO_SETTINGS`).
    base_pigments : sequence of str, optional
        As for :func:`bayespig.build_library` (default: present in >= a quarter of the films).
    noise_scale : {"measured", "model"}
        As for :func:`bayespig.build_library`: every build's.

    Returns
    -------
    tuple
        ``(predictions, info)``: the :class:`FilmPrediction` of every (model, target), and a dict
        (base pigments and films, seconds).
    """
    noise_scale = check_noise_scale(noise_scale)
    sets = dict(measurements)
    recipes = film_recipes(sets)
    base = tuple(_base_pigments(recipes) if base_pigments is None else base_pigments)
    targets = sorted(f for f, r in recipes.items() if len(r.amounts) >= 2) if targets is None else list(targets)
    unknown = [f for f in targets if f not in sets]
    if unknown:
        raise ValueError(f"targets: {unknown[0]!r} is not among the measurements")
    say = progress or (lambda message: None)
    started = time.perf_counter()
    plans = {f: training_films(recipes, f, base) for f in targets}
    base_films = sorted({g for base_only, others in plans.values() if others for g in base_only})
    results = []
    with executor_or_local_pool(executor) as pool:
        bases = {}
        if base_films:
            pigments = ", ".join(base) or "none"
            say(f"building the base libraries ({pigments} from {len(base_films)} films, {' and '.join(models)}) ...")
            futures = {m: pool.submit(_build, ({f: sets[f] for f in base_films}, base_films, m, seed, None, settings, noise_scale)) for m in models}
            bases = {m: future.result() for m, future in futures.items()}
            say(f"base libraries ({pigments} from {', '.join(base_films)}) built: "
                f"{time.perf_counter() - started:.0f} s")
        tasks = []
        for m in models:
            for f in targets:
                base_only, others = plans[f]
                # the target adds pigments to the base: share the base library; a base-only
                # target: its library is built without it from the other base films
                films, base_library = (others, bases[m]) if others else (base_only, None)
                tasks.append(({g: sets[g] for g in (*films, f)}, f, m, seed, n_draws, films, base_library, settings,
                              noise_scale))
        futures = [pool.submit(_predict_film, task) for task in tasks]
        for i, future in enumerate(futures, 1):
            p = future.result()
            results.append(p)
            say(f"[{i}/{len(tasks)}] {p.model} {p.film_id}: ΔE00 " + " / ".join(f"{d:.2f}" for d in p.delta_E)
                + f" ({', '.join(p.cards)}), {p.seconds:.0f} s; {time.perf_counter() - started:.0f} s in all")
    return tuple(results), {"base_pigments": list(base), "base_films": base_films, "noise_scale": noise_scale,
                            "seconds": time.perf_counter() - started}


def conformal_scores(predictions, wavelength_nm, level, rng):
    """The held-out cards' scores for :func:`~bayespig.library.predict.calibration_factor`.

    Parameters
    ----------
    predictions : sequence of FilmPrediction
        Held-out films of *one* film model.
    wavelength_nm : numpy.ndarray
    level : float
        Probability content of the regions (0 < level < 1).
    rng : numpy.random.Generator
        Draws the model errors.

    Returns
    -------
    tuple
        ``(scores, covariances)``: (film, card index) -> ΔE00 of the measured colour from the
        centre of the film's uncalibrated region (model error from the *other* films' residuals)
        over that region's radius [-]; film -> that covariance.
    """
    scores, covariances = {}, {}
    for p in predictions:
        others = [q.residuals for q in predictions if q.film_id != p.film_id]
        if not others:
            continue
        covariances[p.film_id] = model_error_from_residuals(np.concatenate(others))
        for k in range(p.draws.shape[0]):
            _, _, centre, r = credible_region(with_model_error(p.draws[k], covariances[p.film_id], rng),
                                              wavelength_nm, level)
            measured = colorimetry.reflectance_to_Lab(p.measured[k], wavelength_nm)
            scores[(p.film_id, k)] = float(colorimetry.delta_E2000(measured, centre)) / r
    return scores, covariances


def coverage(predictions, wavelength_nm, *, level=DEFAULT_LEVEL, seed=0):
    """Whether each held-out film lies in its predictive region, the model error learned without it.

    Film ``X``'s region is :func:`bayespig.predict_paint`'s with the model error of a library
    cross-validated on the other films only: their residuals' covariance ``C``
    (:func:`~bayespig.library.predict.model_error_from_residuals`) times ``kappa^2``, ``kappa``
    the calibration factor of the other films' scores
    (:func:`~bayespig.library.predict.calibration_factor`). Each of those scores comes from a
    region whose ``C`` leaves out only its own film, so ``X``'s residuals are one film's share of
    them (Revigo: 1 of 53); a nested leave-one-out would remove that too.

    Returns
    -------
    tuple
        ``(counts, inside, radius)``: model -> (inside, total) over every (film, card);
        (model, film) -> bools per card; (model, film) -> ΔE00 radii per card.
    """
    inside, radius, counts = {}, {}, {}
    rng = np.random.default_rng(seed)
    for model in sorted({p.model for p in predictions}):
        own = [p for p in predictions if p.model == model]
        scores, covariances = conformal_scores(own, wavelength_nm, level, rng)
        hits = total = 0
        for p in own:
            others = [v for (f, _), v in scores.items() if f != p.film_id]
            if not others:
                continue
            covariance = calibration_factor(others, level) ** 2 * covariances[p.film_id]
            flags, radii = [], []
            for k in range(p.draws.shape[0]):
                _, _, centre, r = credible_region(with_model_error(p.draws[k], covariance, rng), wavelength_nm, level)
                measured = colorimetry.reflectance_to_Lab(p.measured[k], wavelength_nm)
                flag = bool(colorimetry.delta_E2000(measured, centre) <= r)
                flags.append(flag)
                radii.append(r)
                hits += flag
                total += 1
            inside[(model, p.film_id)] = tuple(flags)
            radius[(model, p.film_id)] = tuple(radii)
        counts[model] = (hits, total)
    return counts, inside, radius


def cross_validate(library, measurements, *, seed=0, executor=None, progress=None, settings=LOO_SETTINGS,
                   targets=None, level=DEFAULT_LEVEL):
    """``library`` with the model error learned by leaving out each mixture film of ``measurements``.

    The model error is the held-out films' residual covariance times ``kappa^2``, ``kappa`` its
    split-conformal calibration at ``level`` (:func:`~bayespig.library.predict.calibration_factor`;
    recorded in ``provenance["model_error"]["calibration"]``; None, ``kappa = 1``, with fewer
    bands than a colour needs, :data:`bayespig.colorimetry.MIN_WAVELENGTHS`).

    Parameters
    ----------
    library : PigmentLibrary
        Built from ``measurements`` (its model is the one cross-validated).
    measurements : dict
        The films it was built from.
    level : float
        Probability content the calibrated regions of :func:`bayespig.predict_paint` hold.

    Returns
    -------
    tuple
        ``(library with model_error set, predictions)``.
    """
    predictions, _ = leave_one_out(measurements, targets=targets, models=(library.model,), seed=seed,
                                   executor=executor, progress=progress, settings=settings,
                                   base_pigments=library.provenance.get("base_pigments"),
                                   noise_scale=library.provenance.get("noise_scale", "model"))
    if len(predictions) < 2:
        raise ValueError("cross-validation needs at least two mixture films")
    covariance = model_error_from_residuals(np.concatenate([p.residuals for p in predictions]))
    if library.wavelength_nm.size >= colorimetry.MIN_WAVELENGTHS:
        scores, _ = conformal_scores(predictions, library.wavelength_nm, level, np.random.default_rng(seed))
        kappa = calibration_factor(list(scores.values()), level)
        calibration = {"method": "split-conformal, normalised ΔE00 score (bayespig.library.predict."
                                 "calibration_factor)", "factor": kappa, "level": float(level), "cards": len(scores)}
    else:  # too few bands for a colour: no ΔE00 to calibrate on
        kappa, calibration = 1.0, None
    provenance = dict(library.provenance, model_error={
        "method": "leave one film out (bayespig.library.validation)", "films": [p.film_id for p in predictions],
        "seed": int(seed), "settings": dataclasses.asdict(settings), "calibration": calibration})
    covariance = kappa ** 2 * covariance
    return dataclasses.replace(library, model_error=covariance, provenance=provenance), predictions
