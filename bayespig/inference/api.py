"""The entries: :func:`infer` (a measurement set) and :func:`infer_problem` (a problem)."""

from __future__ import annotations

import dataclasses
import os
import time
import warnings
from collections.abc import Mapping

import numpy as np

from ..likelihood import (
    ForwardModel,
    LogPosterior,
    Problem,
    censored_zeros_argument,
    check_observed,
    multiplicative_normal_logpdf,
)
from .._validation import flag
from ..rough_table import BINDER_INDEX_NODES, ROUGHNESS_MAX, ROUGHNESS_MIN
from ..selection import select_measurements
from .arguments import (
    DEFAULT_EPS,
    check_executor,
    check_g,
    check_method,
    check_priors,
    check_seed,
    check_selection,
    check_settings,
    check_substrate_sd,
    eps_argument,
    noise_floor_argument,
)
from .card_factors import CardFactors, card_indices
from .executors import _WORKER_TABLES, _Task, run_tasks
from .outputs import _inference_data
from .roughness import (
    PILOT_DRAWS_PER_CHAIN,
    BinderIndexSpec,
    FlakeRoughnessSpec,
    NoiseFloorFilmLayout,
    RoughnessSpec,
    binder_index_argument,
    binder_index_prior_argument,
    roughness_argument,
)
from .settings import ConvergenceWarning
from .shared import FilmLayout, pilot_draws, sample_joint

#: The pilot of a joint run only starts it (the adaptation run and the burn-in follow): it runs
#: to at most this ESS, these autocorrelation times and this minimum of steps (Revigo 07A,
#: 31 wavelengths: 2.4 s against 6.7 s with the study's settings), and its convergence
#: warnings are not the joint run's.
PILOT_TARGET_ESS, PILOT_AUTOCORR_MULTIPLE, PILOT_MIN_STEPS = 100.0, 20.0, 100

__all__ = ["infer", "infer_problem"]


def _resolve_eps(eps, measurements):
    """``(eps for LogPosterior, mode)`` from the ``eps`` argument (checked by
    :func:`~bayespig.inference.arguments.eps_argument`): None is the set's own ``eps`` (metadata,
    e.g. a simulated set) or 0.05."""
    eps = eps_argument(eps)
    if eps == "infer":
        return None, "inferred"
    if eps is None:
        metadata = getattr(measurements, "metadata", None) or {}
        value = metadata.get("eps") if isinstance(metadata, Mapping) else None
        eps = float(value) if isinstance(value, (int, float)) and value > 0 else DEFAULT_EPS
    return eps, "known"


def _check_eps_identifiable(problem, log_post0):
    """Refuse an inferred ``eps`` (or noise floor) where the wavelengths have too few values.

    With ``n_values <= n_parameters`` (``a``, every ``tau``, ``g``) the point fit reproduces
    the data exactly, the likelihood grows without bound as ``eps -> 0`` and the run would go
    to ``max_steps`` at every band with nothing learned; the same holds for an inferred noise
    floor, and inferring both needs one value more. ``n_values`` is the same at every
    wavelength (every film is measured at all of them).
    """
    n_noise = int(log_post0.infer_eps) + int(getattr(log_post0, "infer_noise_floor", False))
    if not n_noise:
        return
    names = [name for name in log_post0.parameter_names if name not in ("log_eps", "log_noise_floor")]
    if problem.n_values >= len(names) + n_noise:
        return
    shown = []
    for name in names:
        if name.startswith("log_tau["):
            name = "tau" if log_post0.n_groups == 1 else name[len("log_"):]
        shown.append(name)
    wl = np.asarray(problem.wavelength_nm, dtype=float)
    where = f"{wl.min():g} nm" if wl.size == 1 or wl.min() == wl.max() else f"{wl.min():g}–{wl.max():g} nm"
    values = f"{problem.n_values} value{'s' if problem.n_values != 1 else ''}"
    are = 'are' if problem.n_values != 1 else 'is'
    counted = f"{len(names)} parameter{'s' if len(names) != 1 else ''} ({', '.join(shown)})"
    if n_noise == 2:
        raise ValueError(f"eps and the noise floor cannot both be inferred: at {where} there {are} only "
                         f"{values} for {counted} and the two noise parameters; give eps or noise_floor "
                         "(e.g. eps=0.02, or --eps 0.02 on the command line)")
    if not log_post0.infer_eps:
        raise ValueError(f"the noise floor cannot be inferred: at {where} there {are} only {values} for "
                         f"{counted}; give noise_floor (e.g. noise_floor=0.001, or --noise-floor 0.001 "
                         "on the command line)")
    raise ValueError(f"eps cannot be inferred: at {where} there {are} "
                     f"only {values} for {counted}; give eps "
                     "(e.g. eps=0.02, or --eps 0.02 on the command line)")


#: Grid points per decade of the (eps, noise floor) scan that starts the noise parameters.
_NOISE_GRID_PER_DECADE = 8


def _point_fit_problem(problem):
    """The problem with observed values floored at a tiny positive number for the point fit
    (whose relative least squares needs values > 0; a zero reading then counts as a relative
    deviation of -1, as it would at any tiny value)."""
    films = []
    for film in problem.films:
        observed = np.asarray(film.observed, dtype=float)
        tiny = 1e-12 * max(float(np.max(observed)), 1e-300)
        films.append(dataclasses.replace(film, observed=np.maximum(observed, tiny)))
    return dataclasses.replace(problem, films=tuple(films))


def _noise_starts(problem, model, fit, priors, log_post0):
    """Start ``(log eps, log noise_floor)`` columns per wavelength (only those inferred).

    The likelihood with the point fit's prediction held fixed is maximised over a
    log-spaced grid of the inferred noise parameters (the known ones at their values):
    cheap, and robust where the relative least squares of the point fit says little about
    a floor.
    """
    def grid(low, high):
        decades = max(np.log10(high / low), 1.0)
        return np.geomspace(low, high, int(np.ceil(decades * _NOISE_GRID_PER_DECADE)) + 1)

    eps_known = np.where(np.isnan(log_post0.eps), 0.0, log_post0.eps)
    unknown = np.isnan(log_post0.eps)
    eps_grid = grid(*priors.eps_range) if log_post0.infer_eps else np.array([np.nan])
    floor_grid = grid(*priors.noise_floor_range) if log_post0.infer_noise_floor else np.array([log_post0.noise_floor])
    E, F = np.meshgrid(eps_grid, floor_grid, indexing="ij")
    columns = []
    for index in range(problem.n_wavelengths):
        m = model.predict(index, fit.a[index:index + 1], fit.tau[index:index + 1], 0.0)[0]
        x = problem.observed(index)
        eps = np.where(unknown[None, :], E.ravel()[:, None], eps_known[None, :])
        with np.errstate(divide="ignore", invalid="ignore"):
            logpdf = multiplicative_normal_logpdf(x, m, eps, F.ravel()[:, None]).sum(axis=1)
        best = int(np.argmax(np.where(np.isfinite(logpdf), logpdf, -np.inf)))
        row = []
        if log_post0.infer_eps:
            row.append(np.log(E.ravel()[best]))
        if log_post0.infer_noise_floor:
            row.append(np.log(F.ravel()[best]))
        columns.append(row)
    return np.array(columns, dtype=float).reshape(problem.n_wavelengths, -1)


def _point_starts(problem, g, tables, priors, log_post0, n_wavelengths):
    """Point-fit starts ``[a, log tau.., (g), (log eps), (log noise_floor)]`` per wavelength, and the fit."""
    from ..fit import FitSettings, fit_problem

    fit_settings = FitSettings(tau_bounds=tuple(float(v) for v in priors.tau_range),
                               a_bounds=tuple(float(v) for v in priors.a_range))
    floored = getattr(log_post0, "has_noise_floor", False)
    fit = fit_problem(_point_fit_problem(problem) if floored else problem, g=0.0, tables=tables,
                      settings=fit_settings, warn=False)
    columns = [fit.a[:, None], np.log(np.maximum(fit.tau, 1e-300))]
    if g == "free":
        columns.append(np.zeros((n_wavelengths, 1)))
    if floored:
        if log_post0.infer_eps or log_post0.infer_noise_floor:
            columns.append(_noise_starts(problem, log_post0.model, fit, priors, log_post0))
    elif log_post0.infer_eps:
        rms = np.clip(fit.rms_relative_deviation, priors.eps_range[0], priors.eps_range[1])
        columns.append(np.log(rms)[:, None])
    return np.concatenate(columns, axis=1), fit


def _pilot_blocks(pilot, problem, floored):
    """Every pooled draw ``[a, log tau_1..G, (log noise_floor)]`` per wavelength of a pilot run,
    (n_draws, n_wl, k) (:func:`~bayespig.inference.shared.pilot_draws`, also for opaque films only)."""
    if problem.groups:
        draws = pilot_draws(pilot)
    else:
        draws = np.asarray(pilot.posterior["a"].values, dtype=float)[..., None]
        draws = draws.reshape(-1, *draws.shape[2:])
    if floored:
        floor = np.log(np.asarray(pilot.posterior["noise_floor"].values, dtype=float))
        draws = np.concatenate([draws, floor.reshape(-1, floor.shape[-1])[..., None]], axis=-1)
    return draws


def _sample_shared(problem, model, priors, eps, settings, seed, specs, executor, progress, noise_floor=None,
                   incidence_offset=False, censored_zeros=False):
    """Joint run over all wavelengths with the shared parameters ``specs`` (:mod:`bayespig.inference.shared`).

    The pilot is a short per-wavelength run of the problem as given (the specs' nominal values,
    e.g. every card at its stated albedo, the model's roughness; :data:`PILOT_TARGET_ESS`).
    With ``noise_floor="infer"`` the blocks carry one floor per wavelength
    (:class:`~bayespig.inference.roughness.NoiseFloorFilmLayout`), and with ``incidence_offset``
    one incidence offset per wavelength after it (its start: :func:`_with_offset_starts`), the
    zeros censored with ``censored_zeros`` (the pilot's too).
    Returns what :func:`~bayespig.inference.shared.sample_joint` returns.
    """
    pilot_seed, joint_seed, start_seed = np.random.SeedSequence(int(seed)).spawn(3)
    pilot_settings = dataclasses.replace(
        settings, target_ess=min(settings.target_ess, PILOT_TARGET_ESS),
        min_autocorr_multiple=min(settings.min_autocorr_multiple, PILOT_AUTOCORR_MULTIPLE),
        min_steps=min(settings.min_steps, PILOT_MIN_STEPS))
    floored = noise_floor == "infer"
    if floored or model.rough:  # the records of the pilot are not kept: few stored draws
        pilot_settings = dataclasses.replace(
            pilot_settings, draws_per_chain=min(pilot_settings.draws_per_chain, PILOT_DRAWS_PER_CHAIN))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        pilot = infer_problem(problem, seed=int(pilot_seed.generate_state(1)[0]), g="isotropic", eps=eps,
                              executor=executor, progress=progress, priors=priors, settings=pilot_settings,
                              tables=model.tables, noise_floor=noise_floor, roughness=model.roughness,
                              censored_zeros=censored_zeros)
    layout = NoiseFloorFilmLayout(model, priors, eps, incidence_offset, censored_zeros) if floored else model
    draws = _pilot_blocks(pilot, problem, floored)
    if model.flakes:
        flake_seed = np.random.SeedSequence(int(seed)).spawn(4)[3]
        draws = _with_flake_starts(draws, model, specs, priors, eps, floored, flake_seed)
    if incidence_offset:
        offset_seed = np.random.SeedSequence(int(seed)).spawn(5)[4]
        draws = _with_offset_starts(draws, layout, specs, priors, offset_seed)
    return sample_joint(layout, specs, draws, priors, eps, settings, joint_seed, start_seed)


#: Spread of the start of ``log c`` (the flakes' reflectance) around its least-squares value [-].
FLAKE_START_SD = 0.1


def _with_flake_starts(draws, model, specs, priors, eps, floored, seed):
    """The pilot's block draws with a start column ``log c`` (the flakes' reflectance) inserted.

    The pilot has no flakes; per band, ``c`` starts at its weighted least-squares value given
    the pilot's median blocks, the specs' nominal values and the flakes' lobe at the nominal
    flake roughness (``x_obs - x_0 ~ c s``, weights ``1 / ((eps x_0)^2 + sigma0^2)``), clipped
    into the prior's box, with a spread :data:`FLAKE_START_SD` in ``log c`` over the draws.
    """
    n_points, n_wl, _ = draws.shape
    G = len(model.problem.groups)
    median = np.median(draws, axis=0)
    inputs = {}
    for spec in specs:
        inputs.update(spec.model_inputs(np.asarray(spec.nominal, dtype=float)[None, :]))
    rows = {key: np.repeat(np.asarray(value, dtype=float), n_wl, axis=0) for key, value in inputs.items()}
    evaluate = model.at_wavelength(list(range(n_wl)))
    member = np.arange(n_wl)
    a, tau = median[:, 0], np.exp(median[:, 1:1 + G]).reshape(n_wl, -1)
    without = evaluate(a, tau, None, member=member, flake_reflectance=np.zeros(n_wl), **rows)
    shape = evaluate(a, tau, None, member=member, flake_reflectance=np.ones(n_wl), **rows) - without
    observed = np.stack([model.problem.observed(i) for i in range(n_wl)])
    floor = np.exp(median[:, -1])[:, None] if floored else 0.0
    weight = 1.0 / ((np.asarray(model.problem.known_eps(eps)) * without) ** 2 + floor * floor)
    c = (weight * shape * (observed - without)).sum(axis=1) / np.maximum((weight * shape * shape).sum(axis=1), 1e-300)
    low, high = (np.log(float(v)) for v in priors.flake_reflectance_range)
    start = np.clip(np.log(np.maximum(c, 1e-300)), low + 3 * FLAKE_START_SD, high - 3 * FLAKE_START_SD)
    rng = np.random.default_rng(seed)
    column = np.clip(start + FLAKE_START_SD * rng.standard_normal((n_points, n_wl)), low, high)
    return np.concatenate([draws[..., :1 + G], column[..., None], draws[..., 1 + G:]], axis=-1)


def _with_offset_starts(draws, layout, specs, priors, seed):
    """The block draws with a start column ``log b`` (the incidence offset) appended.

    The pilot has no offset; per band, ``b`` starts at its weighted least-squares value given
    the median blocks and the specs' nominal values (``x_0 - x_obs ~ b s``, ``s = 1 / cos
    theta_i``: :func:`~bayespig.inference.roughness.incidence_offset_scale`, weights ``1 / ((eps
    x_0)^2 + sigma0^2)``), clipped into the prior's box, with a spread :data:`FLAKE_START_SD` in
    ``log b`` over the draws (as the flakes' start, :func:`_with_flake_starts`).
    """
    n_points, n_wl, _ = draws.shape
    median = np.median(draws, axis=0)
    inputs = {}
    for spec in specs:
        inputs.update(spec.model_inputs(np.asarray(spec.nominal, dtype=float)[None, :]))
    without = FilmLayout.predict(layout, median[None, :, :layout.film_size], inputs)[0]
    floor = np.exp(median[:, layout.film_size])[:, None]
    weight = 1.0 / ((np.asarray(layout.eps) * without) ** 2 + floor * floor)
    scale = layout.offset_scale
    b = (weight * scale * (without - layout.observed)).sum(axis=1) / np.maximum((weight * scale * scale).sum(axis=1),
                                                                               1e-300)
    low, high = (np.log(float(v)) for v in priors.noise_floor_range)
    start = np.clip(np.log(np.maximum(b, 1e-300)), low + 3 * FLAKE_START_SD, high - 3 * FLAKE_START_SD)
    rng = np.random.default_rng(seed)
    column = np.clip(start + FLAKE_START_SD * rng.standard_normal((n_points, n_wl)), low, high)
    return np.concatenate([draws, column[..., None]], axis=-1)


def infer_problem(problem, *, seed=0, g="isotropic", eps=0.05, executor=None, progress=True,
                  priors=None, settings=None, tables=None, shared=None, noise_floor=None, roughness=0.0,
                  incidence_offset=False, censored_zeros=False):
    """Posterior samples of a :class:`~bayespig.likelihood.Problem` at every wavelength.

    Parameters as :func:`infer`, except ``eps``: a positive number (known, for films without
    their own) or None (inferred); ``tables`` optionally passes look-up tables
    (instrument -> table) for the point fit and serial runs; ``shared``: parameters shared
    over wavelengths, a sequence of :class:`~bayespig.inference.shared.SharedParameter` specs
    (e.g. :class:`~bayespig.inference.card_factors.CardFactors`), sampled jointly with every
    wavelength's parameters; ``noise_floor`` as in :func:`infer` (with ``shared``: None or
    ``"infer"``); ``roughness``: the films' surface roughness, a number >= 0 (0: smooth, the
    smooth tables; > 0: the rough tables, opaque films only), the nominal value of a
    :class:`~bayespig.inference.roughness.RoughnessSpec` in ``shared``; ``incidence_offset`` as
    in :func:`infer` (needs ``shared`` and ``noise_floor="infer"``); ``censored_zeros`` as in
    :func:`infer` (needs a noise floor).

    Returns
    -------
    arviz.InferenceData
        See the module docstring for the schema.
    """
    if not isinstance(problem, Problem):
        raise TypeError(f"problem must be a bayespig.likelihood.Problem, got {type(problem).__name__}")
    g, seed = check_g(g), check_seed(seed)
    if eps is not None:
        eps = eps_argument(eps)
        if eps == "infer":
            raise ValueError("eps must be a number in (0, 1) or None (inferred) for infer_problem, got 'infer'")
    check_executor(executor)
    progress = flag("progress", progress)
    priors, settings = check_priors(priors), check_settings(settings)
    noise_floor = noise_floor_argument(noise_floor)
    censored_zeros = censored_zeros_argument(censored_zeros, noise_floor)
    shared = tuple(shared) if shared is not None else ()
    roughness = roughness_argument(roughness)
    if roughness is None or roughness == "free":
        raise ValueError(f"roughness must be a number >= 0 for infer_problem, got {roughness!r} (pass a "
                         "RoughnessSpec in shared= to infer it)")
    if shared and noise_floor is not None and noise_floor != "infer":
        raise ValueError(f"noise_floor is not available with {' and '.join(spec.title for spec in shared)} "
                         "(the joint run over all wavelengths infers one floor per band, noise_floor='infer', "
                         "or has none)")
    incidence_offset = flag("incidence_offset", incidence_offset)
    if incidence_offset and not (shared and noise_floor == "infer"):
        raise ValueError("incidence_offset=True needs the joint run over all wavelengths with an inferred noise "
                         "floor (roughness='free' and noise_floor='infer')")
    check_observed(problem, noise_floor)
    started = time.perf_counter()
    tables = {} if tables is None else tables
    model = ForwardModel(problem, g=g, tables=tables, roughness=roughness,
                         binder_index_free=any(isinstance(spec, BinderIndexSpec) for spec in shared),
                         flakes=any(isinstance(spec, FlakeRoughnessSpec) for spec in shared))
    log_post0 = LogPosterior(model, 0, priors, g=g, eps=eps, noise_floor=noise_floor, censored_zeros=censored_zeros)
    _check_eps_identifiable(problem, log_post0)
    n_wl = problem.n_wavelengths
    starts, fit = _point_starts(problem, g, model.tables, priors, log_post0, n_wl)
    joint = None
    if shared:
        if g != "isotropic" or eps is None:
            raise ValueError(f"{' and '.join(spec.title for spec in shared)} need g='isotropic' and a known eps")
        results, shared_draws, settings, joint = _sample_shared(
            problem, model, priors, eps, settings, seed, shared, executor, progress, noise_floor, incidence_offset,
            censored_zeros)
    else:
        seeds = np.random.SeedSequence(int(seed)).spawn(n_wl)
        # the stacks of wavelengths sampled together depend on the settings only (never on the
        # executor), so the samples do not depend on how the tasks are run
        per_run = settings.wavelengths_per_run
        tasks = [_Task(problem, g, eps, priors, settings, tuple(range(i, min(i + per_run, n_wl))),
                       starts[i:i + per_run], tuple(seeds[i:i + per_run]), noise_floor, roughness, censored_zeros)
                 for i in range(0, n_wl, per_run)]
        if executor is None and len(tasks) == 1:  # runs here: the tables loaded for the point fit
            _WORKER_TABLES.setdefault((g, problem.n, roughness), {}).update(model.tables)
        chunks = run_tasks(tasks, executor, progress)
        results = [r for chunk in chunks for r in chunk]

    idata = _inference_data(problem, model, results, settings, log_post0, fit, seed=seed, g=g, eps=eps,
                            priors=priors, wall_time=time.perf_counter() - started,
                            shared=list(zip(shared, shared_draws)) if joint is not None else [])
    inferred = any(isinstance(spec, RoughnessSpec) for spec in shared)
    for dataset in [idata[group] for group in idata.groups()]:
        # the surface: "smooth" (roughness 0), "fixed" (the value) or "inferred" (posterior roughness)
        dataset.attrs["roughness_mode"] = "inferred" if inferred else "fixed" if model.rough else "smooth"
        dataset.attrs["roughness"] = float("nan") if inferred else float(model.roughness)
    wavelength = np.asarray(problem.wavelength_nm, dtype=float)
    capped = [w for w, r in zip(wavelength, results) if r["max_steps_reached"]]
    if capped and joint is not None:
        warnings.warn(f"the joint run with {' and '.join(spec.title for spec in shared)} was capped at "
                      f"max_steps={settings.max_steps} "
                      f"before reaching {settings.min_autocorr_multiple:g} autocorrelation times / ESS "
                      f"{settings.target_ess:g}", ConvergenceWarning, stacklevel=2)
    elif capped:
        warnings.warn(
            f"run length capped at max_steps={settings.max_steps} before reaching "
            f"{settings.min_autocorr_multiple:g} autocorrelation times / ESS {settings.target_ess:g} at "
            + ", ".join(f"{w:g} nm" for w in capped), ConvergenceWarning, stacklevel=2)
    return idata


def infer(measurements, *, method="auto", seed=0, g="isotropic", eps=None, executor=None,
          progress=True, priors=None, settings=None, substrate_sd=None, noise_floor=None,
          exclude_mirror_deg=None, max_angle_deg=None, wavelengths=None, wavelength_range=None, exclude_occluded=False,
          roughness=None, binder_index=None, binder_index_prior=None, flakes=False, incidence_offset=False,
          censored_zeros=False):
    """Posterior of ``a`` and ``tau`` (and ``g``, ``eps``) per wavelength from a measurement set.

    Parameters
    ----------
    measurements : MeasurementSet or path
        A set, or a file read with :func:`bayespig.read_measurements`.
    method : {"auto", "method1", "method2", "method3", "method4", "general", 1, 2, 3, 4}
        The paper's method (section 3) whose samples enter the likelihood; ``"auto"`` picks the
        most robust one the samples support (4, 1, 2, 3), else ``"general"`` (every film).
    seed : int
        Seeds every random draw (bit-for-bit reproducible, whatever the executor).
    g : {"isotropic", "free"}
        ``g = 0`` (the paper's recommendation) or ``g`` a parameter, uniform on the prior's
        range (needs look-up tables with a ``g`` axis).
    eps : float, "infer" or None
        Relative measurement error of eq. (7) [-] for samples without their own: known, in
        (0, 1) (default: the set's metadata ``eps`` when it has one, e.g. a simulated set, else
        0.05), or ``"infer"``: one ``eps`` per wavelength shared by those samples, log-uniform
        prior (needs more values per wavelength than parameters).
    executor : concurrent.futures.Executor, optional
        Runs the wavelengths in parallel (``submit``); e.g. a ``dask.distributed`` client's
        ``get_executor()``. Default: a local pool of 2 processes (serial for a single stack of
        ``settings.wavelengths_per_run`` wavelengths).
    progress : bool
        Progress bar over wavelengths.
    priors : Priors, optional
        Default: ``a`` uniform on [0, 1], ``tau`` log-uniform on [0.01, 100], ``g`` uniform on
        [-0.5, 0.8], ``eps`` log-uniform on [0.001, 0.5].
    settings : InferenceSettings, optional
    substrate_sd : float, optional
        Treat every card's albedo seen from the binder as uncertain: ``r_s = f_card r_s,card``
        with one factor per card shared by all wavelengths, ``log f ~ N(0, substrate_sd^2)``
        (e.g. 0.1 for the ~10 % of the paper's section 3.4). The posterior is then joint over
        all wavelengths (:mod:`bayespig.inference.card_factors`; slower: one run of
        ``n_wavelengths * (1 + groups) + cards`` parameters) and holds ``r_s_factor`` over
        ``(chain, draw, card)``. Needs ``g="isotropic"`` and a known ``eps``.
    noise_floor : None, float or "infer"
        Additive noise floor ``sigma0`` of every measured value, in the values' units (1/sr
        for a BRDF, a fraction for hemispherical values): ``x_obs ~ N(x, (eps x)^2 +
        sigma0^2)`` (eq. 7 plus a floor; :mod:`bayespig.likelihood`). None or 0: eq. (7)
        alone, every observed value must be > 0; a number: a known floor; ``"infer"``: one
        floor per wavelength shared by all its values, log-uniform on
        ``priors.noise_floor_range`` (1e-6 .. 1 by default), together with ``eps`` when
        ``eps="infer"``. With a floor, observed zeros are data. The posterior then holds
        ``noise_floor`` (chain, draw, wavelength) when inferred; the attributes
        ``noise_floor_mode`` and ``noise_floor`` record it either way. Not with ``substrate_sd``.
    exclude_mirror_deg, max_angle_deg : float, optional
        Drop the films' directional measurements within this angle of the mirror direction,
        and those with ``theta_i`` or ``theta_o`` beyond ``max_angle_deg`` [deg]
        (:func:`bayespig.selection.select_measurements`).
    wavelengths : sequence of float, optional
        Fit these measured bands only [nm].
    wavelength_range : (float, float), optional
        Fit the bands in ``[low, high]`` only [nm].
    exclude_occluded : bool
        Drop the films' BRDF geometries that read (nearly) nothing in every band amid bright
        neighbours (:func:`bayespig.selection.occluded_geometries`: blocked readings, not the
        paint).
    roughness : {"free"} or float, optional
        GGX roughness ``alpha`` of the films' top surface (one surface for every film of the
        set; :mod:`bayespig.physics.rough_surface`). ``"free"``: inferred jointly with every
        wavelength's parameters (:mod:`bayespig.inference.roughness`: log-uniform prior on the
        rough tables' range, 0.01 .. 1; the posterior holds ``roughness`` over ``(chain, draw,
        surface)``; needs ``g="isotropic"`` and a known ``eps``; ``noise_floor`` None or
        ``"infer"``). A number > 0: fixed at that value. 0: the smooth surface, exactly the
        smooth model of before. Default (None): 0, for every set. ``"free"`` is not the default
        for BRDF sets yet (issue 16 asks for it): its prior (the rough tables' 0.01 .. 1) excludes
        the smooth surface, so a smooth film's ``a`` is biased (a simulated smooth opaque film's
        colour moved by 1.8 CIELAB units), and on the real Cornell paints one GGX surface, even
        with the binder index inferred, leaves median residuals of 13-21 % at the red paint's
        body bands and geometry subsets that disagree (``reports/cornell.md``). Rough surfaces need opaque films
        and isotropic scattering.
    binder_index : {None, "free"}, optional
        None: the binder index is the set's ``n`` (``read_measurements(..., n=...)``, 1.45 by
        default), fixed. ``"free"``: one ``n`` for every film of the set, inferred jointly with
        the roughness (needs ``roughness="free"``; :class:`~bayespig.inference.roughness.BinderIndexSpec`:
        normal prior ``binder_index_prior`` truncated to 1.37 .. 1.77, the binder-index tables'
        range). The posterior then holds ``binder_index`` over ``(chain, draw, surface)``. The
        first use on a geometry set builds its rough tables at the six index nodes (minutes
        each; cached).
    binder_index_prior : (float, float), optional
        Mean and sd of the binder index's normal prior [-]; default (1.45, 0.05).
    flakes : bool
        The films hold effect pigments (metal or pearlescent flakes): their lobe around the
        mirror direction (:func:`bayespig.physics.forward.flake_brdf`, coloured, unlike the
        surface's) is added to every BRDF value, with a flake reflectance ``c`` per band
        (log-uniform on ``priors.flake_reflectance_range``, 1e-5 .. 1) and one flake roughness
        for the set (:class:`~bayespig.inference.roughness.FlakeRoughnessSpec`, log-uniform on
        0.02 .. 1), inferred jointly. The posterior then holds ``flake_reflectance`` (chain,
        draw, wavelength) and ``flake_roughness`` (chain, draw, surface). Needs
        ``roughness="free"`` and BRDF or 45°/0° channels. On the Cornell garnet red it takes
        the body-band residuals from 13-21 % to 2.1-3.3 % (``reports/cornell.md``); on the Krylon
        blue, an enamel, the flakes stand in for the body (their reflectance at its prior's upper
        edge, a at 1 outside 440-520 nm): say ``flakes=True`` only for a paint with effect
        pigments. The joint run is slower (the garnet red's 1433 geometries x 31 bands: 8000
        steps, capped, 16 min, against 1112 steps and 2.5 min without flakes).
    incidence_offset : bool
        The instrument's readings of a BRDF carry an offset ``-b / cos theta_i`` per band (a
        gonioreflectometer's background subtracted in excess, in radiance units, divided by the
        irradiance ``E cos theta_i``; readings clipped at 0): the predicted reading is ``max(f -
        b / cos theta_i, 0)`` (:class:`~bayespig.inference.roughness.NoiseFloorFilmLayout`), ``b``
        log-uniform on ``priors.noise_floor_range``, inferred jointly. The posterior then holds
        ``incidence_offset`` (chain, draw, wavelength), and the predictions (``y``) are the
        predicted readings. Needs ``roughness="free"`` and ``noise_floor="infer"``. The Cornell
        paints' exact zeros lie almost all at 70-80 deg incidence (the Krylon blue: 1172 of 1218
        at 80 deg), the signature of such an offset.
    censored_zeros : bool
        Observed values of exactly 0 are readings the instrument clipped at 0 (*censored*):
        their likelihood is the probability of a reading ``<= 0``, ``Phi(-m / sigma)``, not the
        Gaussian density at 0 (:func:`bayespig.likelihood.censored_zero_logpdf`; the module
        docstring of :mod:`bayespig.likelihood` says why the density is wrong for them). With
        ``incidence_offset`` the offset is then subtracted from the reading's mean before the
        clip (:class:`~bayespig.inference.roughness.NoiseFloorFilmLayout`). Needs a noise floor;
        the attribute ``censored_zeros`` records it. Default False (the zeros as Gaussian
        readings, as before).

    Returns
    -------
    arviz.InferenceData
        Posterior ``a``, ``tau`` (chain, draw, wavelength) and the rest of the schema in the
        module docstring.

    Raises
    ------
    TypeError, ValueError
        For an argument of the wrong kind or value (the message names it), for
        ``eps="infer"`` (or ``noise_floor="infer"``) where a wavelength has no more values than
        parameters, for an observed value the noise model cannot take (NaN or infinite; 0
        without a noise floor; negative), naming film, band and geometry, and for a selection
        that leaves a film without geometries or the set without bands.
    ValueError, MeasurementError
        For a file that cannot be read or a method the samples do not support.
    KeyboardInterrupt
        Re-raised once after the workers have been stopped.

    Warns
    -----
    ConvergenceWarning
        When a run reached ``settings.max_steps`` before its length criterion.

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), eq. (7), section 3.
    """
    from ..data import MeasurementSet, read_measurements

    # every argument is checked before any file is read or any sample drawn
    method, seed, g = check_method(method), check_seed(seed), check_g(g)
    eps = eps_argument(eps)
    check_executor(executor)
    progress = flag("progress", progress)
    priors, settings = check_priors(priors), check_settings(settings)
    substrate_sd = check_substrate_sd(substrate_sd)
    noise_floor = noise_floor_argument(noise_floor)
    censored_zeros = censored_zeros_argument(censored_zeros, noise_floor)
    roughness = roughness_argument(roughness)
    binder_index = binder_index_argument(binder_index)
    if binder_index == "free" and roughness != "free":
        raise ValueError("binder_index='free' needs roughness='free' (the binder index is inferred with the "
                         f"surface's roughness, on the tables of a rough surface), got roughness={roughness!r}")
    if binder_index_prior is not None and binder_index != "free":
        raise ValueError("binder_index_prior is used with binder_index='free' only")
    flakes = flag("flakes", flakes)
    incidence_offset = flag("incidence_offset", incidence_offset)
    if incidence_offset and (roughness != "free" or noise_floor != "infer"):
        raise ValueError("incidence_offset=True needs roughness='free' and noise_floor='infer' (the offset is "
                         f"inferred in the joint run with the floor), got roughness={roughness!r}, "
                         f"noise_floor={noise_floor!r}")
    if flakes and roughness != "free":
        raise ValueError("flakes=True needs roughness='free' (the flakes' roughness is inferred in the joint run "
                         f"with the surface's), got roughness={roughness!r}")
    index_prior = binder_index_prior_argument(binder_index_prior)
    if isinstance(roughness, float) and roughness > 0 and not ROUGHNESS_MIN <= roughness <= ROUGHNESS_MAX:
        raise ValueError(f"roughness {roughness:g} is outside the range of the look-up tables of a rough surface "
                         f"[{ROUGHNESS_MIN:g}, {ROUGHNESS_MAX:g}] (0 for a smooth surface)")
    if substrate_sd is not None and (g != "isotropic" or eps == "infer"):
        raise ValueError("substrate_sd needs g='isotropic' and a known eps (the joint run over all "
                         "wavelengths does not sample g or eps)")
    if substrate_sd is not None and noise_floor is not None:
        raise ValueError("noise_floor is not available with substrate_sd (the joint run over all "
                         "wavelengths has no noise floor yet)")
    if roughness == "free" and isinstance(noise_floor, float):
        raise ValueError(f"roughness='free' needs noise_floor None or 'infer' (the joint run over all wavelengths "
                         f"infers one floor per band or has none), got {noise_floor!r}")
    selection = {"exclude_mirror_deg": exclude_mirror_deg, "max_angle_deg": max_angle_deg,
                 "wavelengths": wavelengths, "wavelength_range": wavelength_range, "exclude_occluded": exclude_occluded}
    check_selection(**selection)
    if not isinstance(measurements, MeasurementSet):
        if isinstance(measurements, (str, os.PathLike)):
            measurements = read_measurements(measurements)
        else:
            raise TypeError("measurements must be a MeasurementSet or a path, "
                            f"got {type(measurements).__name__}")
    measurements = select_measurements(measurements, **selection)
    eps_value, _ = _resolve_eps(eps, measurements)
    problem = Problem.from_measurements(measurements, method)
    roughness = _resolve_roughness(roughness, problem, g, eps, substrate_sd)
    shared = []
    if substrate_sd is not None:
        cards, card_index = card_indices(measurements, problem)
        shared.append(CardFactors(problem, card_index, substrate_sd, cards))
    nominal = 0.0
    if roughness == "free":
        nominal, alpha_range = _nominal_roughness(problem, priors, noise_floor)
        shared.append(RoughnessSpec(alpha_range, nominal))
        if binder_index == "free":
            n_range = (BINDER_INDEX_NODES[0], BINDER_INDEX_NODES[-1])
            if not n_range[0] <= problem.n <= n_range[1]:
                raise ValueError(f"binder_index='free' needs the set's binder index n = {problem.n:g} inside the "
                                 f"binder-index tables' range [{n_range[0]:g}, {n_range[1]:g}]")
            shared.append(BinderIndexSpec(n_range, problem.n, index_prior))
        if flakes:
            shared.append(FlakeRoughnessSpec())
    else:
        nominal = roughness
    return infer_problem(problem, seed=seed, g=g, eps=eps_value, executor=executor,
                         progress=progress, priors=priors, settings=settings, shared=shared,
                         noise_floor=noise_floor, roughness=nominal, incidence_offset=incidence_offset,
                         censored_zeros=censored_zeros)


def _resolve_roughness(roughness, problem, g, eps, substrate_sd):
    """``"free"`` or a number >= 0 from the ``roughness`` argument (checked) and the set's default."""
    if roughness is None:  # smooth unless asked: see infer's docstring for why "free" is not the default yet
        return 0.0
    if roughness == "free" and (g != "isotropic" or eps == "infer" or substrate_sd is not None):
        raise ValueError("roughness='free' needs g='isotropic', a known eps and no substrate_sd (the joint "
                         "run over all wavelengths does not sample g or eps); pass roughness=<number> to "
                         "fix the roughness")
    return roughness


#: Roughness values of the point-fit scan that picks the pilot's (nominal) roughness, per decade.
NOMINAL_SCAN_PER_DECADE = 3


def _nominal_roughness(problem, priors, noise_floor):
    """The pilot's roughness: the best of a log-spaced scan by the point fit, and the tables' range.

    At each roughness the point fit (:func:`bayespig.fit.fit_problem`, every wavelength) gives
    its least-squares cost of the relative deviations; the roughness of the smallest total cost
    starts the joint run (which then samples the whole prior range).
    """
    from ..fit import FitSettings, fit_problem

    tables = {}
    model = ForwardModel(problem, tables=tables, roughness=ROUGHNESS_MIN)
    low, high = model.roughness_range
    fitted = _point_fit_problem(problem) if noise_floor is not None else problem
    settings = FitSettings(a_bounds=tuple(float(v) for v in priors.a_range))
    scan = np.geomspace(low, high, round(np.log10(high / low) * NOMINAL_SCAN_PER_DECADE) + 1)
    costs = []
    for alpha in scan:
        ForwardModel(problem, tables=tables, roughness=float(alpha))
        fit = fit_problem(fitted, g=0.0, tables=tables, settings=settings, warn=False)
        costs.append(float(np.sum(fit.rms_relative_deviation ** 2)))
    return float(scan[int(np.argmin(costs))]), (low, high)
