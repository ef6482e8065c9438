"""The entries: :func:`infer` (a measurement set) and :func:`infer_problem` (a problem)."""

from __future__ import annotations

import dataclasses
import datetime
import json
import os
import time
import warnings
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from ..likelihood import ForwardModel, LogPosterior, Priors, Problem
from .executors import _WORKER_TABLES, _map_tasks, _Task
from .moves import IndependentEnsemblesMove
from .outputs import STORED_DRAW_DTYPE, _value_coordinates, _versions
from .sampler import _sample_stack
from .settings import ConvergenceWarning, InferenceSettings

__all__ = ["infer", "infer_problem"]


def _resolve_eps(eps, measurements):
    """``(eps for LogPosterior, mode)`` from the ``eps`` argument."""
    if isinstance(eps, str):
        if eps != "infer":
            raise ValueError(f"eps must be a positive number, None or 'infer', got {eps!r}")
        return None, "inferred"
    if eps is None:
        metadata = getattr(measurements, "metadata", None) or {}
        value = metadata.get("eps") if isinstance(metadata, dict) else None
        eps = float(value) if isinstance(value, (int, float)) and value > 0 else 0.05
    eps = float(eps)
    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a positive number, None or 'infer', got {eps!r}")
    return eps, "known"


def _point_starts(problem, g, tables, priors, log_post0, n_wavelengths):
    """Point-fit starts ``[a, log tau.., (g), (log eps)]`` per wavelength, and the fit."""
    from ..fit import FitSettings, fit_problem

    fit_settings = FitSettings(tau_bounds=tuple(float(v) for v in priors.tau_range),
                               a_bounds=tuple(float(v) for v in priors.a_range))
    fit = fit_problem(problem, g=0.0, tables=tables, settings=fit_settings, warn=False)
    columns = [fit.a[:, None], np.log(np.maximum(fit.tau, 1e-300))]
    if g == "free":
        columns.append(np.zeros((n_wavelengths, 1)))
    if log_post0.infer_eps:
        rms = np.clip(fit.rms_relative_deviation, priors.eps_range[0], priors.eps_range[1])
        columns.append(np.log(rms)[:, None])
    return np.concatenate(columns, axis=1), fit


#: Share of whole-vector DE moves among the block moves of the joint run with substrate factors:
#: they follow correlations between the blocks that the residual coordinates leave.
JOINT_DE_WEIGHT = 0.2


def _sample_with_card_factors(problem, model, priors, eps, settings, seed, substrate, executor, progress):
    """Joint run over all wavelengths with one ``r_s`` factor per card (:mod:`bayespig.substrate_nuisance`).

    Returns the per-wavelength result records of the per-wavelength path, the factor draws
    (chain, draw, card), their autocorrelation times, the settings used (walkers raised to
    what the joint vector needs) and the joint log-posterior.
    """
    from ..substrate_nuisance import CardFactorLogPosterior, ConditionalBlocksMove

    cards, card_index, relative_sd = substrate
    G = len(problem.groups)
    # a pilot: every wavelength's posterior at the cards' stated albedo (f = 1), the usual way
    pilot_seed, joint_seed, start_seed = np.random.SeedSequence(int(seed)).spawn(3)
    pilot = infer_problem(problem, seed=int(pilot_seed.generate_state(1)[0]), g="isotropic", eps=eps,
                          executor=executor, progress=progress, priors=priors, settings=settings,
                          tables=model.tables)
    a_pilot = np.asarray(pilot.posterior["a"].values, dtype=float)
    tau_pilot = (np.asarray(pilot.posterior["tau_group"].values, dtype=float) if "tau_group" in pilot.posterior
                 else np.asarray(pilot.posterior["tau"].values, dtype=float)[..., None])
    draws = np.concatenate([a_pilot[..., None], np.log(tau_pilot)], axis=-1)  # (chain, draw, wl, 1 + G)
    draws = draws.reshape(-1, *draws.shape[2:])
    theta_hat = np.median(draws, axis=0)
    joint = CardFactorLogPosterior(model, card_index, theta_hat, priors, eps, relative_sd, cards)
    n_wl = joint.n_wavelengths
    # blocks of 1 + G (a wavelength) and n_cards parameters: DE needs a few walkers per dimension
    n_walkers = max(settings.n_walkers, 4 * max(1 + G, joint.n_cards), 6)
    used = dataclasses.replace(settings, n_walkers=n_walkers + n_walkers % 2)
    # walkers start on the pilot's draws (independently per wavelength) with f ~ 1
    rng = np.random.default_rng(start_seed)
    n_total = used.n_ensembles * used.n_walkers
    picked = draws[rng.integers(0, draws.shape[0], size=(n_total, n_wl)), np.arange(n_wl)]  # (n, wl, 1 + G)
    residual = np.concatenate([picked[..., 0], picked[..., 1:].reshape(n_total, -1)], axis=1) - joint.theta_hat
    start = np.concatenate([residual, rng.normal(0.0, 0.01 * relative_sd, (n_total, joint.n_cards))], axis=1)
    start[:, joint.factor_slice] = np.clip(start[:, joint.factor_slice], joint.log_f_lower, joint.log_f_upper)
    run = _sample_stack(joint, [joint], np.zeros((1, joint.n_dim)), used, [joint_seed],
                        moves=[(ConditionalBlocksMove(joint, used.n_ensembles), 1.0 - JOINT_DE_WEIGHT),
                               (IndependentEnsemblesMove("de", used.n_ensembles), JOINT_DE_WEIGHT)],
                        start_walkers=start)[0]
    theta = run.pop("theta")
    n_chains, n_draws, n_dim = theta.shape
    flat = theta.reshape(-1, n_dim)
    a, tau, factors = joint.unpack(flat)
    model_values = joint.predict(flat)  # (N, n_wl, n_values)
    pointwise = joint.log_likelihood(flat)
    noisy = None
    if used.predictive_noise:
        rng = np.random.default_rng(run["predictive_seed"])
        noisy = model_values * (1.0 + joint.eps * rng.standard_normal(model_values.shape))
    shape = (n_chains, n_draws)
    autocorr = run["autocorr_time"]
    results = []
    for i in range(n_wl):
        record = {
            "a": a[:, i].reshape(shape),
            "tau": tau[:, i].reshape(shape + (G,)),
            "y": model_values[:, i].reshape(shape + (-1,)),
            "log_likelihood": pointwise[:, i].reshape(shape + (-1,)),
            "lp": pointwise[:, i].sum(axis=-1).reshape(shape),
            "acceptance_rate": run["acceptance_rate"],
            "autocorr_time": np.concatenate([[autocorr[i]], autocorr[n_wl + i * G:n_wl + (i + 1) * G]]),
            "n_steps": run["n_steps"], "n_burn_in": run["n_burn_in"], "thin": run["thin"],
            "max_steps_reached": run["max_steps_reached"],
        }
        if noisy is not None:
            record["y_rep"] = noisy[:, i].reshape(shape + (-1,))
        results.append(record)
    factor_draws = factors.reshape(shape + (joint.n_cards,))
    return results, factor_draws, autocorr[joint.factor_slice], used, joint


def infer_problem(problem, *, seed=0, g="isotropic", eps=0.05, executor=None, progress=True,
                  priors=None, settings=None, tables=None, substrate=None):
    """Posterior samples of a :class:`~bayespig.likelihood.Problem` at every wavelength.

    Parameters as :func:`infer`, except ``eps``: a positive number (known, for films without
    their own) or None (inferred); ``tables`` optionally passes look-up tables
    (instrument -> table) for the point fit and serial runs; ``substrate``: ``(cards,
    card_index, relative_sd)`` to sample one ``r_s`` factor per card jointly over all
    wavelengths (:func:`bayespig.substrate_nuisance.card_indices` gives the first two).

    Returns
    -------
    arviz.InferenceData
        See the module docstring for the schema.
    """
    import arviz as az
    import xarray as xr

    if not isinstance(problem, Problem):
        raise TypeError(f"problem must be a bayespig.likelihood.Problem, got {type(problem).__name__}")
    if g not in ("isotropic", "free"):
        raise ValueError(f"g must be 'isotropic' or 'free', got {g!r}")
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    priors = Priors() if priors is None else priors
    settings = InferenceSettings() if settings is None else settings
    if not isinstance(priors, Priors):
        raise TypeError(f"priors must be a bayespig.likelihood.Priors, got {type(priors).__name__}")
    if not isinstance(settings, InferenceSettings):
        raise TypeError(f"settings must be an InferenceSettings, got {type(settings).__name__}")
    started = time.perf_counter()
    tables = {} if tables is None else tables
    model = ForwardModel(problem, g=g, tables=tables)
    log_post0 = LogPosterior(model, 0, priors, g=g, eps=eps)
    n_wl = problem.n_wavelengths
    starts, fit = _point_starts(problem, g, model.tables, priors, log_post0, n_wl)
    joint = None
    if substrate is not None:
        if g != "isotropic" or eps is None:
            raise ValueError("substrate factors need g='isotropic' and a known eps")
        results, factor_draws, factor_autocorr, settings, joint = _sample_with_card_factors(
            problem, model, priors, eps, settings, seed, substrate, executor, progress)
    else:
        seeds = np.random.SeedSequence(int(seed)).spawn(n_wl)
        # the stacks of wavelengths sampled together depend on the settings only (never on the
        # executor), so the samples do not depend on how the tasks are run
        per_run = settings.wavelengths_per_run
        tasks = [_Task(problem, g, eps, priors, settings, tuple(range(i, min(i + per_run, n_wl))),
                       starts[i:i + per_run], tuple(seeds[i:i + per_run]))
                 for i in range(0, n_wl, per_run)]
        own_pool = None
        if executor is None and len(tasks) > 1:
            own_pool = executor = ProcessPoolExecutor(max_workers=min(2, len(tasks), os.cpu_count() or 1))
        if executor is None:
            _WORKER_TABLES.setdefault((g, problem.n), {}).update(model.tables)
        try:
            chunks = _map_tasks(tasks, executor, progress)
        finally:
            if own_pool is not None:
                own_pool.shutdown()
        results = [r for chunk in chunks for r in chunk]

    def stack(name, axis=2):
        return np.stack([r[name] for r in results], axis=axis)

    wavelength = np.asarray(problem.wavelength_nm, dtype=float)
    groups = list(problem.groups)
    n_chains = settings.n_ensembles
    n_draws = settings.steps_kept * settings.n_walkers
    coords = {"chain": np.arange(n_chains), "draw": np.arange(n_draws), "wavelength": wavelength}
    sample, channel, kind, film_group, r_s = _value_coordinates(problem)
    value_coords = {"value": np.arange(len(sample)), "sample": ("value", sample),
                    "channel": ("value", channel), "kind": ("value", kind),
                    "film_group": ("value", film_group)}
    cdw = ("chain", "draw", "wavelength")
    posterior = {"a": (cdw, stack("a"))}
    if groups:
        tau = stack("tau")  # (chain, draw, wavelength, group)
        posterior["tau"] = (cdw, tau[..., 0])
        if len(groups) > 1:
            posterior["tau_group"] = (cdw + ("group",), tau)
    if g == "free":
        posterior["g"] = (cdw, stack("g"))
    if log_post0.infer_eps:
        posterior["eps"] = (cdw, stack("eps"))
    post_coords = dict(coords)
    if len(groups) > 1:
        post_coords["group"] = groups
    if joint is not None:
        posterior["r_s_factor"] = (("chain", "draw", "card"), factor_draws)
        post_coords["card"] = list(joint.cards)
    # per-draw predictions and pointwise log-likelihoods are most of the file (two values per
    # measured value and draw): single precision (7 digits) is far finer than the noise they
    # describe and halves it
    predictive = {"y": (cdw + ("value",), stack("y").astype(STORED_DRAW_DTYPE))}
    if settings.predictive_noise:
        predictive["y_rep"] = (cdw + ("value",), stack("y_rep").astype(STORED_DRAW_DTYPE))
    parameters = list(log_post0.parameter_names)
    sample_stats = {
        "lp": (cdw, stack("lp")),
        "acceptance_rate": (("chain", "wavelength"), stack("acceptance_rate", axis=1)),
        "autocorr_time": (("wavelength", "parameter"), stack("autocorr_time", axis=0)),
        "n_steps": (("wavelength",), np.array([r["n_steps"] for r in results])),
        "n_burn_in": (("wavelength",), np.array([r["n_burn_in"] for r in results])),
        "thinning": (("wavelength",), np.array([r["thin"] for r in results])),
        "max_steps_reached": (("wavelength",), np.array([int(r["max_steps_reached"]) for r in results])),
    }
    if joint is not None:
        sample_stats["r_s_factor_autocorr_time"] = (("card",), factor_autocorr)
    observed = np.stack([problem.observed(i) for i in range(n_wl)])
    known = problem.known_eps(eps)
    constant = {
        "r_s": (("wavelength", "value"), r_s),
        "eps": (("wavelength", "value"), np.broadcast_to(known, (n_wl, known.size)).copy()),
        "point_a": (("wavelength",), fit.a),
        "point_tau": (("wavelength",), fit.tau[:, 0] if groups else np.full(n_wl, np.inf)),
    }
    instruments = {}
    for film in problem.films:
        if film.instrument is not None:
            instruments[str(film.instrument.name)] = list(film.instrument.labels)
    attrs = {
        **_versions(),
        "seed": int(seed),
        "method": problem.method,
        "g": g,
        "eps_mode": "inferred" if log_post0.infer_eps else "known",
        "settings": settings.to_json(log_post0.n_dim),
        "priors": json.dumps(priors.describe(), sort_keys=True),
        "table_keys": json.dumps(list(model.table_keys)),
        "instruments": json.dumps(instruments, sort_keys=True),
        "n": float(problem.n),
        "parameter_names": json.dumps(parameters),
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "sampling_wall_time_s": float(time.perf_counter() - started),
        "substrate_factors": json.dumps(None if joint is None else {
            "relative_sd": joint.relative_sd, "cards": list(joint.cards),
            "prior": joint.describe_prior()}),
    }
    datasets = {
        "posterior": xr.Dataset(posterior, coords=post_coords),
        "posterior_predictive": xr.Dataset(predictive, coords={**coords, **value_coords}),
        "log_likelihood": xr.Dataset({"y": (cdw + ("value",), stack("log_likelihood").astype(STORED_DRAW_DTYPE))},
                                     coords={**coords, **value_coords}),
        "observed_data": xr.Dataset({"y": (("wavelength", "value"), observed)},
                                    coords={"wavelength": wavelength, **value_coords}),
        "constant_data": xr.Dataset(constant, coords={"wavelength": wavelength, **value_coords}),
        "sample_stats": xr.Dataset(sample_stats, coords={**coords, "parameter": parameters,
                                                         **({"card": list(joint.cards)} if joint else {})}),
    }
    for dataset in datasets.values():
        dataset.attrs.update(attrs)
    idata = az.InferenceData(attrs=attrs, **datasets)
    capped = [w for w, r in zip(wavelength, results) if r["max_steps_reached"]]
    if capped and joint is not None:
        warnings.warn(f"the joint run with substrate factors was capped at max_steps={settings.max_steps} "
                      f"before reaching {settings.min_autocorr_multiple:g} autocorrelation times / ESS "
                      f"{settings.target_ess:g}", ConvergenceWarning, stacklevel=2)
    elif capped:
        warnings.warn(
            f"run length capped at max_steps={settings.max_steps} before reaching "
            f"{settings.min_autocorr_multiple:g} autocorrelation times / ESS {settings.target_ess:g} at "
            + ", ".join(f"{w:g} nm" for w in capped), ConvergenceWarning, stacklevel=2)
    return idata


def infer(measurements, *, method="auto", seed=0, g="isotropic", eps=None, executor=None,
          progress=True, priors=None, settings=None, substrate_sd=None):
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
        Relative measurement error of eq. (7) [-] for samples without their own: known
        (default: the set's metadata ``eps`` when it has one, e.g. a simulated set, else 0.05),
        or ``"infer"``: one ``eps`` per wavelength shared by those samples, log-uniform prior.
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
        all wavelengths (:mod:`bayespig.substrate_nuisance`; slower: one run of
        ``n_wavelengths * (1 + groups) + cards`` parameters) and holds ``r_s_factor`` over
        ``(chain, draw, card)``. Needs ``g="isotropic"`` and a known ``eps``.

    Returns
    -------
    arviz.InferenceData
        Posterior ``a``, ``tau`` (chain, draw, wavelength) and the rest of the schema in the
        module docstring.

    Raises
    ------
    ValueError, MeasurementError
        For a file that cannot be read or a method the samples do not support.

    Warns
    -----
    ConvergenceWarning
        When a run reached ``settings.max_steps`` before its length criterion.

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), eq. (7), section 3.
    """
    from ..data import MeasurementSet, read_measurements

    if not isinstance(measurements, MeasurementSet):
        if isinstance(measurements, (str, os.PathLike)):
            measurements = read_measurements(measurements)
        else:
            raise TypeError("measurements must be a MeasurementSet or a path, "
                            f"got {type(measurements).__name__}")
    if isinstance(method, (int, np.integer)) or method in ("1", "2", "3", "4"):
        method = f"method{int(method)}"
    eps_value, _ = _resolve_eps(eps, measurements)
    problem = Problem.from_measurements(measurements, method)
    substrate = None
    if substrate_sd is not None:
        from ..substrate_nuisance import card_indices

        if not (isinstance(substrate_sd, (int, float, np.floating)) and np.isfinite(substrate_sd)
                and substrate_sd > 0):
            raise ValueError(f"substrate_sd must be a positive number, got {substrate_sd!r}")
        if g != "isotropic" or eps_value is None:
            raise ValueError("substrate_sd needs g='isotropic' and a known eps (the joint run over all "
                             "wavelengths does not sample g or eps)")
        cards, card_index = card_indices(measurements, problem)
        substrate = (cards, card_index, float(substrate_sd))
    return infer_problem(problem, seed=seed, g=g, eps=eps_value, executor=executor,
                         progress=progress, priors=priors, settings=settings, substrate=substrate)
