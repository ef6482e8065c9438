"""Outputs of the runs: per-wavelength records, value coordinates and provenance."""

from __future__ import annotations

import datetime
import json

import numpy as np

from .._versions import package_versions

#: CF-style ``long_name`` and ``units`` of the posterior variables (``"1"``: dimensionless).
VARIABLE_ATTRS = {
    "a": {"long_name": "relative absorption k_abs/k_ext", "units": "1"},
    "tau": {"long_name": "optical thickness", "units": "1"},
    "tau_group": {"long_name": "optical thickness per film group", "units": "1"},
    "g": {"long_name": "Henyey-Greenstein asymmetry parameter g", "units": "1"},
    "eps": {"long_name": "relative measurement error eps (eq. 7)", "units": "1"},
    # units of noise_floor: those of the measured values, set per result (noise_floor_units)
    "noise_floor": {"long_name": "additive noise floor sigma0 (sd of a reading of 0)"},
    # units: those of the measured values, as the floor's
    "incidence_offset": {"long_name": "instrument offset b of a BRDF reading at normal incidence "
                                      "(the reading is max(f - b / cos theta_i, 0))"},
    "flake_reflectance": {"long_name": "reflectance c of the effect-pigment flakes (their lobe: "
                                       "bayespig.physics.forward.flake_brdf)", "units": "1"},
}
#: ... and of the wavelength coordinate of every group.
WAVELENGTH_ATTRS = {"long_name": "wavelength", "units": "nm"}
#: Storage type of the per-draw predictions and pointwise log-likelihoods.
STORED_DRAW_DTYPE = np.float32


def _wavelength_outputs(log_post, run, settings):
    """Posterior quantities, predictions and pointwise log-likelihood from one run."""
    theta = run.pop("theta")
    n_chains, n_draws, n_dim = theta.shape
    flat = theta.reshape(-1, n_dim)
    a, tau, g, eps = log_post.unpack(flat)
    model = log_post.evaluate(a, tau, g if log_post.free_g else None)
    pointwise = log_post.log_likelihood(flat, pointwise=True)
    shape = (n_chains, n_draws)
    out = {
        "a": a.reshape(shape),
        "tau": tau.reshape(shape + (tau.shape[1],)),
        "y": model.reshape(shape + (-1,)),
        "log_likelihood": pointwise.reshape(shape + (-1,)),
        **run,
    }
    if log_post.free_g:
        out["g"] = g.reshape(shape)
    if log_post.infer_eps:
        k = 1 + log_post.n_groups + log_post.free_g
        out["eps"] = np.exp(flat[:, k]).reshape(shape)
    floor = None
    if getattr(log_post, "infer_noise_floor", False):
        floor = log_post.noise_floor_of(flat)
        out["noise_floor"] = floor.reshape(shape)
    elif getattr(log_post, "has_noise_floor", False):
        floor = log_post.noise_floor_of(flat)
    if settings.predictive_noise:
        rng = np.random.default_rng(run["predictive_seed"])
        noisy = model * (1.0 + np.broadcast_to(eps, model.shape) * rng.standard_normal(model.shape))
        if floor is not None:  # the additive floor, independent of the multiplicative noise
            noisy = noisy + floor[:, None] * rng.standard_normal(model.shape)
        out["y_rep"] = noisy.reshape(shape + (-1,))
    out.pop("predictive_seed")
    return out


def _value_coordinates(problem):
    """Per measured value: sample, channel, kind, film_group, and r_s (n_wavelengths, n_values)."""
    sample, channel, kind, group, r_s = [], [], [], [], []
    for film in problem.films:
        k = film.observed.shape[1]
        sample += [film.name.split(":")[0]] * k
        kind += [film.kind] * k
        group += [film.group or ""] * k
        if film.kind == "transmittance":
            channel += ["specular_transmittance"] * k
        else:
            channel += list(film.instrument.labels)
        r_s.append(np.repeat(np.asarray(film.r_s, dtype=float)[:, None], k, axis=1))
    return sample, channel, kind, group, np.concatenate(r_s, axis=1)


def noise_floor_units(problem):
    """Units of the noise floor: those of the measured values (``"1/sr"`` for BRDFs, ``"1"`` for
    reflectances, reflectance factors and transmittances; both named for a mix)."""
    kinds = set()
    for film in problem.films:
        if film.kind == "transmittance" or film.instrument is None:
            kinds.add("fraction")
        else:
            kinds.update("brdf" if c.kind == "brdf" else "fraction" for c in film.instrument.channels)
    if kinds == {"brdf"}:
        return "1/sr"
    if kinds == {"fraction"}:
        return "1"
    return "1/sr for BRDF values, 1 for the other values"


def _versions():
    """The posterior's attributes ``<package>_version`` (:func:`bayespig._versions.package_versions`)."""
    return {f"{name}_version": version for name, version in package_versions().items()}


#: InferenceData attribute with the support of every posterior variable's prior (JSON), read by
#: the prior-edge flags (:func:`bayespig.report.quantities.prior_edges`).
PRIOR_BOUNDS_ATTR = "prior_bounds"


def _prior_bounds(priors, posterior, shared=()):
    """The support of the prior of every posterior variable, for the prior-edge flags.

    Parameters
    ----------
    priors : Priors
    posterior : dict
        Posterior variable name -> (dims, draws), as stored.
    shared : sequence
        Specs of parameters shared by all wavelengths (:class:`~bayespig.inference.shared.SharedParameter`):
        ``variable``, ``lower``, ``upper`` (the box of its sampled coordinates), ``physical``
        (coordinates -> stored values) and optionally ``prior_scale`` (``"linear"`` by default).

    Returns
    -------
    dict
        Variable -> ``{"lower", "upper", "scale"}``: the bounds in the variable's own units
        (numbers, or lists along its one dimension other than chain, draw and wavelength,
        e.g. ``card``) and the coordinate in which the prior is flat or sampled (``"linear"``
        or ``"log"``).
    """
    ranges = {"a": (priors.a_range, "linear"), "tau": (priors.tau_range, "log"),
              "tau_group": (priors.tau_range, "log"), "g": (priors.g_range, "linear"),
              "eps": (priors.eps_range, "log"), "noise_floor": (priors.noise_floor_range, "log"),
              "flake_reflectance": (priors.flake_reflectance_range, "log"),
              "incidence_offset": (priors.noise_floor_range, "log")}
    bounds = {name: {"lower": float(low), "upper": float(high), "scale": scale}
              for name, ((low, high), scale) in ranges.items() if name in posterior}
    for spec in shared:
        if getattr(spec, "variable", None) in posterior:
            lower = np.asarray(spec.physical(np.atleast_2d(spec.lower)), dtype=float)[0]
            upper = np.asarray(spec.physical(np.atleast_2d(spec.upper)), dtype=float)[0]
            bounds[spec.variable] = {"lower": lower.tolist(), "upper": upper.tolist(),
                                     "scale": getattr(spec, "prior_scale", "linear")}
    return bounds


def _inference_data(problem, model, results, settings, log_post0, fit, *, seed, g, eps, priors, wall_time,
                    shared=()):
    """The :class:`arviz.InferenceData` of the schema in :mod:`bayespig.inference`.

    Parameters
    ----------
    problem : Problem
    model : ForwardModel
    results : list of dict
        One record per wavelength (:func:`_wavelength_outputs`, or the joint run's).
    settings : InferenceSettings
        As used (the joint run raises the walkers).
    log_post0 : LogPosterior
        Of the first wavelength (parameter layout).
    fit : PointFit
        The point fit (``point_a``, ``point_tau``).
    seed, g, eps, priors
        As given to :func:`~bayespig.inference.infer_problem`.
    wall_time : float
        Sampling wall time [s].
    shared : sequence
        ``(spec, (draws (chain, draw, size), autocorrelation times (size,)))`` per spec of
        parameters shared over wavelengths.
    """
    import arviz as az
    import xarray as xr

    n_wl = problem.n_wavelengths

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
    floor_mode = ("inferred" if getattr(log_post0, "infer_noise_floor", False)
                  else "known" if getattr(log_post0, "has_noise_floor", False) else "none")
    if floor_mode == "inferred":
        posterior["noise_floor"] = (cdw, stack("noise_floor"))
    if "flake_reflectance" in results[0]:
        posterior["flake_reflectance"] = (cdw, stack("flake_reflectance"))
    if "incidence_offset" in results[0]:
        posterior["incidence_offset"] = (cdw, stack("incidence_offset"))
    post_coords = dict(coords)
    if len(groups) > 1:
        post_coords["group"] = groups
    for spec, (draws, _) in shared:
        posterior[spec.variable] = (("chain", "draw", spec.dimension), draws)
        post_coords[spec.dimension] = list(spec.labels)
    # per-draw predictions and pointwise log-likelihoods are most of the file (two values per
    # measured value and draw): single precision (7 digits) is far finer than the noise they
    # describe and halves it
    predictive = {"y": (cdw + ("value",), stack("y").astype(STORED_DRAW_DTYPE))}
    if settings.predictive_noise:
        predictive["y_rep"] = (cdw + ("value",), stack("y_rep").astype(STORED_DRAW_DTYPE))
    parameters = list(log_post0.parameter_names)
    if "flake_reflectance" in results[0]:  # the joint run's block: [a, log tau.., log c, (log sigma0)]
        parameters.insert(1 + len(groups), "log_flake_reflectance")
    if "incidence_offset" in results[0]:  # ... then the incidence offset, last
        parameters.append("log_incidence_offset")
    sample_stats = {
        "lp": (cdw, stack("lp")),
        "acceptance_rate": (("chain", "wavelength"), stack("acceptance_rate", axis=1)),
        "autocorr_time": (("wavelength", "parameter"), stack("autocorr_time", axis=0)),
        "n_steps": (("wavelength",), np.array([r["n_steps"] for r in results])),
        "n_burn_in": (("wavelength",), np.array([r["n_burn_in"] for r in results])),
        "thinning": (("wavelength",), np.array([r["thin"] for r in results])),
        "max_steps_reached": (("wavelength",), np.array([int(r["max_steps_reached"]) for r in results])),
        # runs of the joint sampler's adaptation before its run proper (0: a per-wavelength run)
        "adaptation_rounds": (("wavelength",), np.array([int(r.get("adaptation_rounds", 0)) for r in results])),
        # share of the joint sampler's shared-block proposals accepted (NaN: a per-wavelength run)
        "shared_acceptance": (("wavelength",), np.array([float(r.get("shared_acceptance", np.nan)) for r in results])),
    }
    for spec, (_, autocorr) in shared:
        sample_stats[f"{spec.variable}_autocorr_time"] = ((spec.dimension,), autocorr)
    observed = np.stack([problem.observed(i) for i in range(n_wl)])
    known = problem.known_eps(eps)
    constant = {
        "r_s": (("wavelength", "value"), r_s),
        "eps": (("wavelength", "value"), np.broadcast_to(known, (n_wl, known.size)).copy()),
        # the additive floor per value: 0 without one, NaN where inferred
        "noise_floor": (("wavelength", "value"),
                        np.full((n_wl, known.size), np.nan if floor_mode == "inferred"
                                else getattr(log_post0, "noise_floor", 0.0))),
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
        # the additive noise floor: "none", "known" (its value in noise_floor) or "inferred"
        "noise_floor_mode": floor_mode,
        "noise_floor": float(log_post0.noise_floor) if floor_mode == "known" else (
            float("nan") if floor_mode == "inferred" else 0.0),
        "noise_floor_units": noise_floor_units(problem),
        # observed zeros as readings censored at 0 (log Phi(-m / sigma)) or as Gaussian readings
        "censored_zeros": int(log_post0.censored_zeros),
        "settings": settings.to_json(log_post0.n_dim),
        "priors": json.dumps(priors.describe(), sort_keys=True),
        "table_keys": json.dumps(list(model.table_keys)),
        "table_checksums": json.dumps(model.table_checksums, sort_keys=True),
        "instruments": json.dumps(instruments, sort_keys=True),
        "n": float(problem.n),
        "parameter_names": json.dumps(parameters),
        PRIOR_BOUNDS_ATTR: json.dumps(_prior_bounds(priors, posterior, [spec for spec, _ in shared])),
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "sampling_wall_time_s": float(wall_time),
        # the card factors' record is always there (null without them)
        "substrate_factors": json.dumps(None),
    }
    for spec, _ in shared:
        if spec.attribute:
            attrs[spec.attribute] = json.dumps(spec.describe())
    datasets = {
        "posterior": xr.Dataset(posterior, coords=post_coords),
        "posterior_predictive": xr.Dataset(predictive, coords={**coords, **value_coords}),
        "log_likelihood": xr.Dataset({"y": (cdw + ("value",), stack("log_likelihood").astype(STORED_DRAW_DTYPE))},
                                     coords={**coords, **value_coords}),
        "observed_data": xr.Dataset({"y": (("wavelength", "value"), observed)},
                                    coords={"wavelength": wavelength, **value_coords}),
        "constant_data": xr.Dataset(constant, coords={"wavelength": wavelength, **value_coords}),
        "sample_stats": xr.Dataset(sample_stats, coords={**coords, "parameter": parameters,
                                                         **{spec.dimension: list(spec.labels)
                                                            for spec, _ in shared}}),
    }
    for dataset in datasets.values():
        dataset.attrs.update(attrs)
        if "wavelength" in dataset.coords:
            dataset.coords["wavelength"].attrs.update(WAVELENGTH_ATTRS)
    described = dict(VARIABLE_ATTRS)
    described["noise_floor"] = {**VARIABLE_ATTRS["noise_floor"], "units": noise_floor_units(problem)}
    described["incidence_offset"] = {**VARIABLE_ATTRS["incidence_offset"], "units": noise_floor_units(problem)}
    described.update({spec.variable: {"long_name": spec.long_name, "units": spec.units} for spec, _ in shared})
    for name, variable_attrs in described.items():
        if name in datasets["posterior"]:
            datasets["posterior"][name].attrs.update(variable_attrs)
    return az.InferenceData(attrs=attrs, **datasets)
