"""The numbers of an uncertainty report, computed from a posterior (no plotting, no files).

Everything here reads an arviz ``InferenceData`` written by :func:`bayespig.infer`
(schema: ``posterior`` ``a``, ``tau`` (absent when every film is opaque), optional
``tau_group``, ``g``, ``eps`` over ``(chain, draw, wavelength)``; ``posterior_predictive``/``observed_data`` ``y`` over
``(wavelength, value)`` with the coordinates ``sample``, ``channel``, ``kind``,
``film_group`` along ``value``; ``constant_data`` ``r_s``, ``eps``, ``point_a``,
``point_tau``) and turns it into plain arrays and dicts:

* parameter bands: median, 50 % and 90 % central intervals, mean and sd per wavelength;
* the extinction coefficient ``k_ext = tau / H`` and cross-section ``sigma_ext = tau / (H D)``
  when thickness ``H`` and concentration ``D`` are known (paper appendix A2; only
  ``D sigma_ext`` matters, so ``sigma_ext`` is in the user's concentration units);
* convergence diagnostics (bulk ESS and rank-normalised R-hat, arviz) and flagged wavelengths;
* prior edges: the parameters whose posterior is piled against a bound of its prior's support
  (:func:`prior_edges`, over the supports that :func:`bayespig.infer` records);
* fit quality: residuals of every measured value in units of its relative error ``eps``
  (paper eq. 7: ``(x_obs - x_model) / (eps x_model)`` is standard normal at the truth), and
  a posterior predictive check that flags the wavelengths the model cannot reproduce;
* colour (CIELAB, CIEDE2000 through :mod:`bayespig.colorimetry`) of every measured sample
  and geometry, measured and predicted, and the posterior spread of the predicted colour;
* predicted colour, with its posterior spread, of films that were not measured (another
  thickness, another substrate, opaque), through the look-up tables on posterior draws.

Posterior draws at different wavelengths come from independent runs; the per-wavelength
posteriors are independent (the likelihood factorises over wavelengths and so do the
priors), so pairing draw ``k`` of every wavelength is a draw from the joint posterior of
the spectrum -- which is what a colour needs.
"""

from __future__ import annotations

import itertools
import json
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from .. import colorimetry
from ..data.model import BLACK_SUBSTRATE_ALBEDO, WHITE_SUBSTRATE_ALBEDO, parse_measurement_geometry
from ..inference import diagnose
from ..inference.arguments import DEFAULT_EPS
from ..inference.outputs import PRIOR_BOUNDS_ATTR
from ..instruments import Channel, Instrument
from ..likelihood import FilmTerm, Priors, Problem, noise_sd

__all__ = [
    "BEYOND_LOBE_BINS_DEG",
    "COLOUR_MATCH_DELTA_E",
    "DEFAULT_EPS",
    "EPS_SOURCE_ATTR",
    "ESS_MIN",
    "GONIO_LARGE_GEOMETRIES",
    "MIRROR_DISTANCE_BINS_DEG",
    "PPC_LEVEL",
    "PRIOR_BOUNDS_ATTR",
    "PRIOR_EDGE_FLOOR",
    "PRIOR_EDGE_FRACTION",
    "RHAT_MAX",
    "SPREAD_QUANTILE",
    "FilmDesign",
    "Lab_to_sRGB",
    "Ravine",
    "card_factors",
    "colour_available",
    "colour_spectrum",
    "default_unmeasured_films",
    "diagnostics",
    "eps_of_run",
    "eps_origin",
    "eps_per_value",
    "eps_source",
    "extinction",
    "film_colour",
    "gonio_residual_summary",
    "gonio_values",
    "is_large_gonio_set",
    "measured_colour",
    "measurement_kind",
    "mirror_distance_class",
    "mirror_distance_labels",
    "model_check_status",
    "parameter_bands",
    "parameters_per_wavelength",
    "posterior_draws",
    "posterior_predictive_check",
    "predicted_film_values",
    "prior_bounds",
    "prior_edge_column",
    "prior_edges",
    "priors_from_inference",
    "problem_from_inference",
    "provenance",
    "ravine",
    "record_eps_source",
    "residuals_in_eps",
    "spread_values",
    "surface_parameters",
    "value_table",
    "wavelengths",
]

#: Above this many BRDF geometries a report summarises them (plane-of-incidence figure,
#: residual map, residual statistics by distance from the mirror) instead of listing each.
GONIO_LARGE_GEOMETRIES = 40
#: Edges of the distance-from-the-mirror classes of the residual statistics [deg]:
#: < 2, 2-10, 10-30, >= 30.
MIRROR_DISTANCE_BINS_DEG = (0.0, 2.0, 10.0, 30.0, np.inf)

#: R-hat above this flags a wavelength (Vehtari et al. 2021 recommend 1.01).
RHAT_MAX = 1.01
#: Bulk effective sample size below this flags a wavelength (Vehtari et al. 2021: 100 per
#: chain for four chains, i.e. enough for stable 5 %/95 % quantiles).
ESS_MIN = 400
#: A colour difference below this (CIEDE2000) is taken as good enough for colour matching.
COLOUR_MATCH_DELTA_E = 1.0
#: Posterior predictive p-value below which a wavelength is flagged as a misfit: the model,
#: at any plausible parameters, cannot reproduce the measured values within their noise.
PPC_LEVEL = 0.01
#: A posterior is piled against a bound of its prior when its 5 % (95 %) quantile lies closer
#: to the lower (upper) bound than this fraction of its 90 % interval's width, in the
#: coordinate where the prior is flat or sampled (:func:`prior_edges`). For a normal
#: likelihood cut by the bound this is when the cut lies within 1.5 sd of the likelihood's
#: peak (the density at the bound is at least a third of its peak); a posterior equal to a
#: flat prior has 0.05 / 0.9 = 0.056 at both ends.
PRIOR_EDGE_FRACTION = 0.1
#: ... or closer than this fraction of the prior's range (a posterior far narrower than its
#: distance to the bound, pressed against it).
PRIOR_EDGE_FLOOR = 1e-6
#: Central credible intervals shown everywhere, as (lower, upper) quantiles.
BANDS = {"50": (0.25, 0.75), "90": (0.05, 0.95)}
#: Colour spread quantile: ``Delta E00`` of posterior draws from the posterior-mean colour.
SPREAD_QUANTILE = 0.95

_MEASUREMENT_KINDS = ("brdf", "hemispherical", "reflectance_factor")
_RANGE = re.compile(r"\[\s*([-+0-9.eE]+)\s*,\s*([-+0-9.eE]+)\s*\]")


# ------------------------------------------------------------------------------------------
# reading the InferenceData


def _attrs(idata):
    """The posterior's attributes (where :func:`bayespig.infer` records provenance)."""
    attrs = dict(getattr(idata, "attrs", {}) or {})
    attrs.update(idata.posterior.attrs)
    return attrs


def _json_attr(value):
    """An attribute that may be JSON text, parsed; anything else returned as is."""
    if isinstance(value, (bytes, bytearray)):
        value = value.decode()
    if isinstance(value, str):
        try:
            return json.loads(value)
        except ValueError:
            return value
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def provenance(idata):
    """The posterior's attributes with JSON text parsed, for the report's provenance section."""
    return {str(k): _json_attr(v) for k, v in _attrs(idata).items()}


def priors_from_inference(idata):
    """The :class:`~bayespig.likelihood.Priors` recorded in the posterior's attributes.

    Reads the ``priors`` attribute: either the ranges (``a_range``, ``tau_range``, ...) or
    the text of :meth:`Priors.describe` (``"log-uniform on [0.01, 100]"``); parameters it
    does not give keep the defaults of :class:`Priors`.
    """
    recorded = _json_attr(_attrs(idata).get("priors"))
    ranges = {}
    if isinstance(recorded, dict):
        for key, value in recorded.items():
            name = key if key.endswith("_range") else f"{key}_range"
            if name not in ("a_range", "tau_range", "g_range", "eps_range", "noise_floor_range"):
                continue
            if isinstance(value, (list, tuple)) and len(value) == 2:
                ranges[name] = (float(value[0]), float(value[1]))
            elif isinstance(value, str):
                match = _RANGE.search(value)
                if match:
                    ranges[name] = (float(match.group(1)), float(match.group(2)))
    return Priors(**ranges)


def prior_bounds(idata):
    """The support of the prior of every posterior variable.

    Reads the :data:`PRIOR_BOUNDS_ATTR` attribute that :func:`bayespig.infer` records; a
    posterior written before it existed gets the ranges of :func:`priors_from_inference` for
    ``a``, ``tau`` (and ``tau_group``), ``g`` and ``eps``.

    Returns
    -------
    dict
        Posterior variable -> ``{"lower", "upper", "scale"}``: bounds in the variable's units
        (numbers or lists along its non-wavelength dimension) and ``"linear"`` or ``"log"``,
        the coordinate in which the prior is flat or sampled. Only variables of the posterior.
    """
    recorded = _json_attr(_attrs(idata).get(PRIOR_BOUNDS_ATTR))
    if not isinstance(recorded, dict):
        priors = priors_from_inference(idata)
        recorded = {"a": {"lower": priors.a_range[0], "upper": priors.a_range[1], "scale": "linear"},
                    "tau": {"lower": priors.tau_range[0], "upper": priors.tau_range[1], "scale": "log"},
                    "tau_group": {"lower": priors.tau_range[0], "upper": priors.tau_range[1], "scale": "log"},
                    "g": {"lower": priors.g_range[0], "upper": priors.g_range[1], "scale": "linear"},
                    "eps": {"lower": priors.eps_range[0], "upper": priors.eps_range[1], "scale": "log"}}
    return {name: dict(value) for name, value in recorded.items()
            if name in idata.posterior and isinstance(value, dict) and {"lower", "upper"} <= set(value)}


def _wavelength_runs(wl, indices):
    """Wavelengths ``wl[indices]`` as runs of consecutive grid points: ``"400, 450-550 nm"``."""
    runs, start = [], None
    for position, i in enumerate(indices):
        if start is None:
            start = i
        if position + 1 == len(indices) or indices[position + 1] != i + 1:
            runs.append(f"{wl[start]:g}" if start == i else f"{wl[start]:g}-{wl[i]:g}")
            start = None
    return ", ".join(runs) + " nm"


def prior_edges(idata, *, fraction=PRIOR_EDGE_FRACTION, floor=PRIOR_EDGE_FLOOR):
    """Parameters whose posterior is piled against a bound of its prior's support.

    For every posterior variable with recorded bounds ``[L, U]`` (:func:`prior_bounds`), at
    every wavelength (and label of its other dimension, e.g. every card), in the coordinate
    ``x`` where the prior is flat or sampled (``log`` for ``tau`` and ``eps``): with ``q05``
    and ``q95`` the posterior's 5 % and 95 % quantiles and ``w = q95 - q05``, the posterior
    is at the lower bound when ``q05 - L <= max(fraction w, floor (U - L))``, at the upper
    bound when ``U - q95 <= max(fraction w, floor (U - L))``, and fills the prior range
    when both hold (the data do not identify it). At a bound the data do not tell the
    parameter from the bound, or push it beyond: either its true value is that close to the
    bound (a pigment that hardly absorbs: ``a`` near 0), or the model is wrong for these data
    (or the prior too narrow); the interval on that side is the prior's cut, not the data's.

    Parameters
    ----------
    idata : arviz.InferenceData
    fraction : float
        :data:`PRIOR_EDGE_FRACTION`.
    floor : float
        :data:`PRIOR_EDGE_FLOOR`.

    Returns
    -------
    list of dict
        One per (parameter, bound) with ``parameter`` (e.g. ``"a"``, ``"tau[thick]"``,
        ``"r_s_factor[white card]"``), ``variable``, ``label`` (None or the coordinate along
        the variable's other dimension), ``bound`` (``"lower"``, ``"upper"`` or ``"both"``),
        ``value`` (the bound, or ``[L, U]`` for ``"both"``), ``prior_range`` ``[L, U]``,
        ``wavelength_nm`` (the flagged wavelengths; None for a parameter shared by all
        wavelengths) and ``text``, e.g. ``"a is at its prior bound 0 at 450-700 nm: the data do not tell it from 0 or push it beyond its prior
        range [0, 1]; unless it can truly be that close to 0, the model may be wrong for these data (or the
        prior too narrow)"``.
    """
    wl = wavelengths(idata)
    out = []
    for variable, bounds in prior_bounds(idata).items():
        data = idata.posterior[variable]
        other = [d for d in data.dims if d not in ("chain", "draw", "wavelength")]
        if len(other) > 1:
            continue
        per_wavelength = "wavelength" in data.dims
        order = ["chain", "draw"] + (["wavelength"] if per_wavelength else []) + other
        values = np.asarray(data.transpose(*order).values, dtype=float)
        values = values.reshape((-1,) + values.shape[2:])
        if not per_wavelength:
            values = values[:, None]
        if not other:
            values = values[..., None]
        labels = [None] if not other else [str(v) for v in data.coords[other[0]].values]
        lower = np.broadcast_to(np.asarray(bounds["lower"], dtype=float), (len(labels),))
        upper = np.broadcast_to(np.asarray(bounds["upper"], dtype=float), (len(labels),))
        log = bounds.get("scale") == "log"
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.log(values) if log else values
            low, high = (np.log(lower), np.log(upper)) if log else (lower, upper)
        q05, q95 = np.quantile(x, [0.05, 0.95], axis=0)  # (n_wavelengths or 1, n_labels)
        margin = np.maximum(fraction * (q95 - q05), floor * (high - low))
        at_lower = q05 - low <= margin
        at_upper = high - q95 <= margin
        for k, label in enumerate(labels):
            if variable == "tau_group" and k == 0:
                continue  # the first group's tau is "tau"
            name = variable if label is None else f"{'tau' if variable == 'tau_group' else variable}[{label}]"
            prior_range = [float(lower[k]), float(upper[k])]
            for bound, mask in (("both", at_lower[:, k] & at_upper[:, k]),
                                ("lower", at_lower[:, k] & ~at_upper[:, k]),
                                ("upper", at_upper[:, k] & ~at_lower[:, k])):
                where = np.flatnonzero(mask)
                if not where.size:
                    continue
                at = f" at {_wavelength_runs(wl, where)}" if per_wavelength else ""
                if bound == "both":
                    value = prior_range
                    text = (f"{name} fills its whole prior range [{lower[k]:g}, {upper[k]:g}]{at}: the data do "
                            "not identify it (its posterior is its prior)")
                else:
                    value = prior_range[0] if bound == "lower" else prior_range[1]
                    text = (f"{name} is at its prior bound {value:g}{at}: the data do not tell it from {value:g} "
                            f"or push it beyond its prior range [{lower[k]:g}, {upper[k]:g}]; unless it can truly "
                            f"be that close to {value:g}, the model may be wrong for these data (or the prior too "
                            "narrow)")
                out.append({"parameter": name, "variable": variable, "label": label, "bound": bound,
                            "value": value, "prior_range": prior_range,
                            "wavelength_nm": [float(wl[i]) for i in where] if per_wavelength else None,
                            "text": text})
    return out


def prior_edge_column(idata, edges=None):
    """Per wavelength, the parameters at a prior bound in a few words (``summary.csv``).

    Parameters
    ----------
    idata : arviz.InferenceData
    edges : list of dict, optional
        :func:`prior_edges` of ``idata`` (computed when not given).

    Returns
    -------
    list of str
        ``""`` (none) or e.g. ``"a at 0; g fills [-0.5, 0.8]"``; parameters shared by all
        wavelengths are not listed (see :func:`prior_edges`).
    """
    wl = wavelengths(idata)
    edges = prior_edges(idata) if edges is None else edges
    cells = {float(w): [] for w in wl}
    for edge in edges:
        if edge["wavelength_nm"] is None:
            continue
        words = (f"{edge['parameter']} fills [{edge['value'][0]:g}, {edge['value'][1]:g}]"
                 if edge["bound"] == "both" else f"{edge['parameter']} at {edge['value']:g}")
        for w in edge["wavelength_nm"]:
            cells[float(w)].append(words)
    return ["; ".join(cells[float(w)]) for w in wl]


def wavelengths(idata):
    """Wavelengths of the posterior [nm], shape (n_wavelengths,)."""
    return np.asarray(idata.posterior["wavelength"].values, dtype=float)


def posterior_draws(idata, name, max_draws=None):
    """Posterior draws of one variable, chains stacked: shape (n_draws, n_wavelengths, ...).

    Parameters
    ----------
    idata : arviz.InferenceData
    name : str
        Variable of the ``posterior`` group (``"a"``, ``"tau"``, ``"tau_group"``, ``"g"``,
        ``"eps"``).
    max_draws : int, optional
        Keep at most this many draws, evenly spaced (deterministic thinning).

    Returns
    -------
    numpy.ndarray
    """
    values = np.asarray(idata.posterior[name].values, dtype=float)
    values = values.reshape((-1,) + values.shape[2:])
    return _thin(values, max_draws)


def _thin(values, max_draws):
    if max_draws is None or values.shape[0] <= max_draws:
        return values
    keep = np.unique(np.linspace(0, values.shape[0] - 1, max_draws).round().astype(int))
    return values[keep]


def _value_coord(idata, name, group="observed_data"):
    data = getattr(idata, group)["y"]
    if name in data.coords:
        return [str(v) for v in np.asarray(data.coords[name].values).ravel()]
    return None


def _channel_of(label, kind):
    """An instrument :class:`Channel` from a measured value's channel label (and kind)."""
    kinds = (kind,) if kind in _MEASUREMENT_KINDS else _MEASUREMENT_KINDS
    for candidate in kinds:
        try:
            angles = parse_measurement_geometry(candidate, label)
        except ValueError:
            continue
        return Channel(candidate, angles["theta_i"], angles["theta_o"], angles["delta_phi"],
                       angles["specular"], angles["label"])
    raise ValueError(f"channel label {label!r} is not a BRDF, hemispherical or 45/0 geometry")


def value_table(idata):
    """Per measured value: sample, channel, kind and film group (observed-data coordinates).

    Returns
    -------
    list of dict
        One dict per value along the ``value`` dimension.
    """
    n_values = idata.observed_data["y"].shape[-1]
    columns = {}
    for name in ("sample", "channel", "kind", "film_group"):
        values = _value_coord(idata, name)
        columns[name] = values if values is not None else [""] * n_values
    return [{name: columns[name][k] for name in columns} for k in range(n_values)]


def measurement_kind(row):
    """What a measured value is: ``"brdf"`` [1/sr], ``"hemispherical"``, ``"reflectance_factor"``
    or ``"transmittance"`` (fractions), from its row of :func:`value_table`."""
    if _is_transmittance(row):
        return "transmittance"
    return _channel_of(row["channel"], row["kind"]).kind


def _is_transmittance(row):
    return "transmittance" in row["kind"] or row["channel"] in ("normal", "transmittance")


def problem_from_inference(idata):
    """The :class:`~bayespig.likelihood.Problem` that a posterior was inferred from.

    Rebuilt from the observed data, the constant data (``r_s`` and ``eps`` per value) and
    the value coordinates, so that a saved netCDF file alone is enough for the ravine
    figure and the predictions.

    Returns
    -------
    Problem
    """
    wl = wavelengths(idata)
    observed = np.asarray(idata.observed_data["y"].values, dtype=float)
    constant = getattr(idata, "constant_data", None)
    r_s = (np.asarray(constant["r_s"].values, dtype=float)
           if constant is not None and "r_s" in constant else np.zeros_like(observed))
    eps = (np.asarray(constant["eps"].values, dtype=float)
           if constant is not None and "eps" in constant else np.full_like(observed, np.nan))
    rows = value_table(idata)
    attrs = _attrs(idata)
    n = float(_json_attr(attrs.get("n", 1.45)))
    films, groups = [], []
    start = 0
    while start < len(rows):
        stop = start + 1
        while stop < len(rows) and rows[stop]["sample"] == rows[start]["sample"] and \
                _is_transmittance(rows[stop]) == _is_transmittance(rows[start]):
            stop += 1
        first = rows[start]
        group = first["film_group"] or None
        opaque = group is None or group in ("", "none", "None", "opaque")
        group = None if opaque else group
        if group is not None and group not in groups:
            groups.append(group)
        film_eps = eps[:, start]
        known = float(film_eps[0]) if np.isfinite(film_eps).all() and np.ptp(film_eps) == 0 else None
        if _is_transmittance(first):
            films.append(FilmTerm(first["sample"], "transmittance", None, group, np.zeros(wl.size),
                                  observed[:, start:stop], known))
        else:
            channels = tuple(_channel_of(rows[k]["channel"], rows[k]["kind"]) for k in range(start, stop))
            instrument = Instrument(f"sample:{first['sample']}", channels, n)
            films.append(FilmTerm(first["sample"], "reflectance", instrument, group,
                                  np.ascontiguousarray(r_s[:, start]), observed[:, start:stop], known))
        start = stop
    method = str(_json_attr(attrs.get("method", "general")))
    return Problem(wl, tuple(films), tuple(groups), n, method)


# ------------------------------------------------------------------------------------------
# parameters


def parameter_bands(draws):
    """Median, 50 % and 90 % central intervals, mean and sd over the first axis.

    Parameters
    ----------
    draws : numpy.ndarray
        Shape (n_draws, ...).

    Returns
    -------
    dict
        ``mean``, ``sd``, ``median``, ``q05``, ``q25``, ``q75``, ``q95``, each shape (...).
    """
    q = np.quantile(draws, [0.05, 0.25, 0.5, 0.75, 0.95], axis=0)
    return {"mean": draws.mean(axis=0), "sd": draws.std(axis=0, ddof=1), "median": q[2],
            "q05": q[0], "q25": q[1], "q75": q[3], "q95": q[4]}


def extinction(tau_draws, thickness_um, concentration=None):
    """Extinction coefficient and cross-section from optical-thickness draws (appendix A2).

    ``tau = k_ext H = D sigma_ext H``, so ``k_ext = tau / H`` and ``sigma_ext = tau / (D H)``.

    Parameters
    ----------
    tau_draws : numpy.ndarray
        Optical thickness draws [-].
    thickness_um : float
        Dry film thickness ``H`` [µm].
    concentration : float, optional
        Pigment concentration ``D`` (appendix A2, up to the arbitrary scale ``mu``)
        [concentration units].

    Returns
    -------
    dict
        ``k_ext`` [1/µm] and, with a concentration, ``sigma_ext`` [1/µm per concentration unit].

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), appendix A2.
    """
    if not (thickness_um is not None and np.isfinite(thickness_um) and thickness_um > 0):
        raise ValueError(f"thickness_um must be a positive number [µm], got {thickness_um!r}")
    out = {"k_ext": np.asarray(tau_draws) / thickness_um}
    if concentration is not None:
        if not (np.isfinite(concentration) and concentration > 0):
            raise ValueError(f"concentration must be a positive number, got {concentration!r}")
        out["sigma_ext"] = out["k_ext"] / concentration
    return out


def diagnostics(idata, variables=None, *, rhat_max=RHAT_MAX, ess_min=ESS_MIN, priors=None):
    """Bulk ESS and R-hat per wavelength, and the wavelengths that need attention.

    Parameters
    ----------
    idata : arviz.InferenceData
    variables : sequence of str, optional
        Posterior variables to check (default ``a``, ``tau``, and ``g``/``eps`` when present).
    rhat_max, ess_min : float
        Flag thresholds (defaults :data:`RHAT_MAX`, :data:`ESS_MIN`).
    priors : Priors, optional
        A ``tau`` posterior whose 95 % quantile reaches half the prior's upper bound is
        flagged too: the data cannot tell the film from an opaque one there.

    Returns
    -------
    dict
        ``ess`` and ``rhat``: variable -> array (n_wavelengths,); ``flags``: list of
        ``{"wavelength_nm", "reasons"}``; ``n_chains``, ``n_draws``.
    """
    import arviz as az

    posterior = idata.posterior
    if variables is None:
        variables = [v for v in ("a", "tau", "g", "eps") if v in posterior]
    n_chains = posterior.sizes["chain"]
    ess = az.ess(posterior[variables], method="bulk")
    with np.errstate(invalid="ignore", divide="ignore"):
        rhat = az.rhat(posterior[variables]) if n_chains > 1 else None
    ess_out = {v: np.asarray(ess[v].values, dtype=float) for v in variables}
    rhat_out = ({v: np.asarray(rhat[v].values, dtype=float) for v in variables}
                if rhat is not None else {v: np.full(ess_out[v].shape, np.nan) for v in variables})
    wl = wavelengths(idata)
    flags = {}
    for line in diagnose(idata, rhat_max=rhat_max, ess_min=ess_min, warn=False):
        head, _, reasons = line.partition(" nm: ")
        flags.setdefault(float(head), []).extend(reasons.split("; "))
    if "tau" in posterior:
        tau_q95 = np.quantile(posterior_draws(idata, "tau"), 0.95, axis=0)
        tau_limit = (priors or priors_from_inference(idata)).tau_range[1] / 2.0
        for i, w in enumerate(wl):
            if tau_q95[i] >= tau_limit:
                flags.setdefault(float(w), []).append(
                    f"tau reaches {tau_q95[i]:.3g} (95 % quantile): the film is not told from an opaque one")
    flags = [{"wavelength_nm": w, "reasons": flags[w]} for w in sorted(flags)]
    if n_chains < 2:
        flags.insert(0, {"wavelength_nm": None, "reasons": ["one chain only: R-hat is not available"]})
    return {"ess": ess_out, "rhat": rhat_out, "flags": flags, "n_chains": int(n_chains),
            "n_draws": int(posterior.sizes["draw"]), "rhat_max": rhat_max, "ess_min": ess_min}


# ------------------------------------------------------------------------------------------
# fit quality


def eps_per_value(idata):
    """Relative error ``eps`` (eq. 7) of every measured value, shape (n_wavelengths, n_values) [-].

    The known value from ``constant_data``; where ``eps`` was inferred (NaN there), the
    posterior median of that wavelength.
    """
    observed = idata.observed_data["y"]
    eps = np.full(observed.shape, np.nan)
    constant = getattr(idata, "constant_data", None)
    if constant is not None and "eps" in constant:
        eps = np.asarray(constant["eps"].values, dtype=float).copy()
    if np.isnan(eps).any() and "eps" in idata.posterior:
        inferred = np.median(posterior_draws(idata, "eps"), axis=0)
        inferred = np.broadcast_to(inferred.reshape(inferred.shape[0], -1), eps.shape)
        eps = np.where(np.isnan(eps), inferred, eps)
    return eps


#: Posterior attribute recording where a known eps came from (:func:`record_eps_source`).
EPS_SOURCE_ATTR = "eps_source"


def eps_source(eps, measurements, *, given_as="--eps", used=None):
    """Where the ``eps`` of a run of :func:`bayespig.infer` comes from.

    Mirrors ``infer``'s rule: a sample's own ``eps`` (a file column) first, then the ``eps``
    argument, then the measurement set's metadata ``eps``, then :data:`DEFAULT_EPS`.

    Parameters
    ----------
    eps : float, "infer" or None
        The ``eps`` argument of ``infer``.
    measurements : MeasurementSet
    given_as : str
        How the user gave ``eps`` (``"--eps"`` on the command line, ``"eps="`` in Python).
    used : float, optional
        The eps the run actually used (:func:`eps_of_run`): the metadata ``eps`` counts as the
        source only when it is this value.

    Returns
    -------
    dict
        ``kind``: ``"inferred"``, ``"given"``, ``"file"`` or ``"default"``; ``as``: ``given_as``
        for ``"given"``.
    """
    if isinstance(eps, str) and eps == "infer":
        return {"kind": "inferred"}
    samples = tuple(getattr(measurements, "samples", ()) or ())
    if samples and all(getattr(sample, "eps", None) is not None for sample in samples):
        return {"kind": "file"}
    if eps is not None:
        return {"kind": "given", "as": given_as}
    metadata = getattr(measurements, "metadata", None) or {}
    value = metadata.get("eps") if isinstance(metadata, Mapping) else None
    if isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0 and \
            (used is None or np.isclose(used, value)):
        return {"kind": "file"}
    return {"kind": "default"}


def eps_of_run(idata):
    """The known eps a posterior was inferred with (median over its values), or None."""
    if "eps" in idata.posterior:
        return None
    values = eps_per_value(idata)
    values = values[np.isfinite(values)]
    return float(np.median(values)) if values.size else None


def record_eps_source(idata, eps, measurements, *, given_as="--eps"):
    """Store where the posterior's eps came from (:func:`eps_source`) in its attributes (JSON text).

    Parameters
    ----------
    idata : arviz.InferenceData
        From ``infer(measurements, eps=eps)``.
    eps, measurements, given_as
        As :func:`eps_source`.

    Returns
    -------
    dict
        The recorded source.
    """
    source = eps_source(eps, measurements, given_as=given_as, used=eps_of_run(idata))
    idata.posterior.attrs[EPS_SOURCE_ATTR] = json.dumps(source)
    return source


def eps_origin(idata, measurements=None):
    """The report's words for the posterior's ``eps`` and where it came from.

    Parameters
    ----------
    idata : arviz.InferenceData
    measurements : MeasurementSet, optional
        When the posterior does not record its eps source: a metadata ``eps`` of these
        measurements equal to the posterior's eps counts as its source.

    Returns
    -------
    dict
        ``kind`` (as :func:`eps_source`, or ``"unknown"`` when the posterior does not record
        it), ``value`` (the known eps, its median over values; None when inferred),
        ``assumed`` (True when eps is bayespig's default -- or may be: unrecorded and equal to
        it), ``why`` (for an assumed eps) and ``text``, e.g. ``"eps assumed: 0.05 (the default;
        pass --eps)"``, ``"eps given: 0.02 (--eps)"``, ``"eps inferred"``.
    """
    if "eps" in idata.posterior:
        return {"kind": "inferred", "value": None, "assumed": False, "why": "",
                "text": "eps inferred (a parameter per wavelength)"}
    recorded = _json_attr(_attrs(idata).get(EPS_SOURCE_ATTR))
    if not isinstance(recorded, dict) and measurements is not None:
        guess = eps_source(None, measurements, used=eps_of_run(idata))
        recorded = guess if guess["kind"] == "file" else None
    kind = recorded.get("kind", "unknown") if isinstance(recorded, dict) else "unknown"
    values = eps_per_value(idata)
    finite = values[np.isfinite(values)]
    value = float(np.median(finite)) if finite.size else float("nan")
    spread = finite.size and np.ptp(finite) > 0
    shown = (f"{finite.min():g}-{finite.max():g} (per sample)" if spread else f"{value:g}")
    if kind == "default":
        return {"kind": kind, "value": value, "assumed": True, "why": "the default",
                "text": f"eps assumed: {shown} (the default; pass --eps)"}
    if kind == "given":
        return {"kind": kind, "value": value, "assumed": False, "why": "",
                "text": f"eps given: {shown} ({recorded.get('as', '--eps')})"}
    if kind == "file":
        return {"kind": kind, "value": value, "assumed": False, "why": "",
                "text": f"eps given: {shown} (the measurement file)"}
    assumed = bool(np.isclose(value, DEFAULT_EPS) and not spread)
    return {"kind": "unknown", "value": value, "assumed": assumed,
            "why": "the posterior does not record where it came from; it equals the default" if assumed else "",
            "text": f"eps known: {shown} (where it came from is not recorded in the posterior"
                    + ("; it equals the default, so it may only be assumed" if assumed else "") + ")"}


def noise_floor_per_value(idata, draws=False, max_draws=None):
    """Additive noise floor of every measured value [units of the values].

    0 for a posterior without a floor (and for one saved before floors existed); the known
    floor from ``constant_data``; where it was inferred, the posterior median of that
    wavelength, or with ``draws=True`` every (thinned) draw, shape (n_draws, n_wavelengths, 1).
    """
    observed = idata.observed_data["y"]
    constant = getattr(idata, "constant_data", None)
    floor = np.zeros(observed.shape)
    if constant is not None and "noise_floor" in constant:
        floor = np.asarray(constant["noise_floor"].values, dtype=float).copy()
    if np.isnan(floor).any() and "noise_floor" in idata.posterior:
        drawn = posterior_draws(idata, "noise_floor", max_draws)  # (n_draws, n_wavelengths)
        if draws:
            return np.where(np.isnan(floor), drawn[:, :, None], floor)
        floor = np.where(np.isnan(floor), np.median(drawn, axis=0)[:, None], floor)
    return floor


def residuals_in_eps(idata, max_draws=None):
    """Residuals of every measured value in units of its relative error (paper eq. 7).

    ``z = (x_obs - x_pred) / (eps x_pred)`` with ``x_pred`` the posterior-mean noise-free
    prediction (``/ sqrt((eps x_pred)^2 + sigma0^2)`` with a noise floor ``sigma0``,
    :func:`bayespig.likelihood.noise_sd`); at the truth ``z`` is standard normal, so
    ``|z| > 3`` marks a value the model does not explain.

    Returns
    -------
    dict
        ``observed``, ``predicted_mean``, ``predicted_q05``, ``predicted_q95``, ``eps``, ``z``,
        each (n_wavelengths, n_values); ``rows``: the value table.
    """
    observed = np.asarray(idata.observed_data["y"].values, dtype=float)
    predicted = np.asarray(idata.posterior_predictive["y"].values, dtype=float)
    predicted = _thin(predicted.reshape((-1,) + predicted.shape[2:]), max_draws)
    mean = predicted.mean(axis=0)
    q05, q95 = np.quantile(predicted, [0.05, 0.95], axis=0)
    eps = eps_per_value(idata)
    z = (observed - mean) / noise_sd(mean, eps, noise_floor_per_value(idata))
    return {"observed": observed, "predicted_mean": mean, "predicted_q05": q05,
            "predicted_q95": q95, "predicted_draws": predicted, "eps": eps, "z": z,
            "rows": value_table(idata)}


def card_factors(idata, probability=0.9):
    """The cards' albedo factors of a posterior inferred with ``substrate_sd`` (else empty).

    Returns
    -------
    list of dict
        Per card: ``card``, ``median``, ``low``, ``high`` (central ``probability`` interval) of
        ``f`` in ``r_s = f r_s,card`` [-], and the prior's ``relative_sd``.
    """
    if "r_s_factor" not in idata.posterior:
        return []
    factors = idata.posterior["r_s_factor"]
    recorded = _json_attr(_attrs(idata).get("substrate_factors")) or {}
    tail = (1.0 - probability) / 2.0
    out = []
    for card in factors.coords["card"].values:
        draws = np.asarray(factors.sel(card=card).values, dtype=float).ravel()
        median, low, high = np.quantile(draws, [0.5, tail, 1.0 - tail])
        out.append({"card": str(card), "median": float(median), "low": float(low), "high": float(high),
                    "relative_sd": recorded.get("relative_sd")})
    return out


#: Posterior variables of the films' surface (one value for the set) and the attribute with their prior.
SURFACE_PARAMETERS = (("roughness", "roughness_prior"), ("binder_index", "binder_index_prior"),
                      ("flake_roughness", "flake_roughness_prior"))


def surface_parameters(idata, probability=0.9):
    """The surface's parameters of a posterior (roughness, binder index, flake roughness; those inferred).

    Returns
    -------
    list of dict
        Per parameter: ``variable``, ``long_name``, ``median``, ``low``, ``high`` (central
        ``probability`` interval) and ``prior`` (its text, from the posterior's attributes).
    """
    tail = (1.0 - probability) / 2.0
    attrs = _attrs(idata)
    out = []
    for variable, attribute in SURFACE_PARAMETERS:
        if variable not in idata.posterior:
            continue
        draws = np.asarray(idata.posterior[variable].values, dtype=float).ravel()
        median, low, high = np.quantile(draws, [0.5, tail, 1.0 - tail])
        prior = (_json_attr(attrs.get(attribute)) or {}).get("prior", "")
        out.append({"variable": variable,
                    "long_name": idata.posterior[variable].attrs.get("long_name", variable),
                    "median": float(median), "low": float(low), "high": float(high), "prior": prior})
    return out


def posterior_predictive_check(idata, level=PPC_LEVEL, max_draws=None, seed=0):
    """Posterior predictive check per wavelength: can the model reproduce the measured values?

    The discrepancy is the chi-square of the noise model (paper eq. 7),
    ``T(x, theta) = sum_v ((x_v - m_v) / (eps_v m_v))^2`` over the ``n`` values measured at
    the wavelength, with ``m = m(theta)`` the noise-free prediction of a posterior draw
    (with a noise floor ``sigma0`` the denominator is ``sqrt((eps_v m_v)^2 + sigma0^2)``,
    :func:`bayespig.likelihood.noise_sd`, and ``T`` is chi-square all the same).
    Replicated data ``x_rep = m (1 + eps xi)`` give ``T(x_rep, theta) ~ chi2(n)`` exactly, so
    the posterior predictive p-value ``p = P(T(x_rep, theta) >= T(x_obs, theta) | x_obs)``
    is the posterior mean of ``chi2.sf(T(x_obs, theta), n)`` -- no replicated draws needed
    (Gelman, Meng & Stern 1996, Statistica Sinica 6, 733). Posterior predictive p-values
    are conservative (the parameters were fitted to the same data, so ``p`` piles up near
    0.5 and above for a well-fitting model); a small ``p`` is strong evidence of misfit:
    no plausible parameters reproduce the values within their noise -- a term the model
    lacks, a wrong ``eps``, a wrong substrate, or inconsistent samples.

    Where ``eps`` was inferred, each draw uses its own ``eps``; an inferred ``eps`` absorbs
    misfit (it grows until the values fit), so the check then says little: read the ``eps``
    posterior instead.

    A wavelength with no more measured values than parameters (an 8°/d film on black and
    white: 2 values for ``a`` and ``tau``) cannot test the model: some parameters reproduce
    exactly any values the model can produce, so a large ``p`` says nothing there
    (``testable = False``; :func:`model_check_status` calls it "not testable", not "pass").
    A small ``p`` still flags values that no parameters in the prior's support can produce
    (e.g. a film on white darker than on black).

    With censored zeros (``infer(..., censored_zeros=True)``) an exact 0 is the event
    "reading <= 0" of probability ``P0 = Phi(-mu / sigma)`` (its stored log-likelihood), not a
    Gaussian value: its term in ``T`` is ``z^2`` of the randomised quantile residual
    ``z = Phi^-1(u P0)``, ``u ~ U(0, 1)`` (Dunn & Smyth 1996, J. Comput. Graph. Stat. 5, 236),
    which is exactly N(0, 1) under the model, so ``T`` stays ``chi2(n)``; a zero where the draw
    predicts a clearly positive reading (``P0`` tiny) gives a large ``|z|``. The positive readings
    keep their Gaussian ``z`` (with the incidence offset the sd is taken at the reading, as for
    every value here). At the posterior mean (``z``, ``chi2``, ``worst``) a zero's residual is the
    mid-quantile ``Phi^-1(P0 / 2)`` of the draws' mean ``P0``.

    Parameters
    ----------
    idata : arviz.InferenceData
        From :func:`bayespig.infer`.
    level : float
        Wavelengths with ``p < level`` are flagged.
    max_draws : int, optional
        Use at most this many posterior draws (evenly thinned).
    seed : int
        Seeds ``numpy.random.default_rng`` for the randomised residuals of censored zeros (unused
        without censoring).

    Returns
    -------
    dict
        ``p_value`` (n_wavelengths,); ``chi2`` (n_wavelengths,): ``T`` at the posterior-mean
        prediction; ``n_values`` (n_wavelengths,); ``flagged``: bool (n_wavelengths,);
        ``worst``: per wavelength the index of the value with the largest ``|z|``
        (:func:`residuals_in_eps`), and ``z`` (n_wavelengths, n_values); ``level``;
        ``n_parameters`` (n_wavelengths,) from :func:`parameters_per_wavelength` and
        ``testable``: bool (n_wavelengths,), ``n_values > n_parameters``.

    Raises
    ------
    ValueError
        When ``level`` is not in (0, 1).
    """
    from scipy import stats

    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    observed = np.asarray(idata.observed_data["y"].values, dtype=float)
    predicted = np.asarray(idata.posterior_predictive["y"].values, dtype=float)
    predicted = _thin(predicted.reshape((-1,) + predicted.shape[2:]), max_draws)
    eps = np.broadcast_to(eps_per_value(idata), predicted.shape).copy()
    constant = getattr(idata, "constant_data", None)
    inferred = np.ones(observed.shape, dtype=bool)
    if constant is not None and "eps" in constant:
        inferred = np.isnan(np.asarray(constant["eps"].values, dtype=float))
    if inferred.any() and "eps" in idata.posterior:
        drawn = _thin(posterior_draws(idata, "eps"), max_draws)
        drawn = np.broadcast_to(drawn.reshape(drawn.shape[:2] + (-1,)), predicted.shape)
        eps = np.where(inferred, drawn, eps)
    measured = np.isfinite(observed)
    n_values = measured.sum(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = noise_floor_per_value(idata, draws=True, max_draws=max_draws)
        z2 = np.where(measured, ((observed - predicted) / noise_sd(predicted, eps, floor)) ** 2, 0.0)
    zero_p = _censored_zero_probability(idata, measured & (observed == 0), max_draws)
    if zero_p is not None:
        u = np.random.default_rng(seed).uniform(size=zero_p.shape)
        z2 = np.where(np.isnan(zero_p), z2, _censored_residual(u * zero_p) ** 2)
    chi2_draws = z2.sum(axis=-1)  # (n_draws, n_wavelengths)
    p_value = stats.chi2.sf(chi2_draws, np.maximum(n_values, 1)).mean(axis=0)
    p_value = np.where(n_values > 0, p_value, np.nan)
    mean = predicted.mean(axis=0)
    eps_mean = eps_per_value(idata)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (observed - mean) / noise_sd(mean, eps_mean, noise_floor_per_value(idata))
    if zero_p is not None:
        mean_p = zero_p.mean(axis=0)
        z = np.where(np.isnan(mean_p), z, _censored_residual(0.5 * mean_p))
    chi2 = np.nansum(np.where(measured, z * z, 0.0), axis=-1)
    worst = np.argmax(np.where(measured, np.abs(np.nan_to_num(z, nan=np.inf)), -1.0), axis=-1)
    n_parameters = np.full(n_values.shape, parameters_per_wavelength(idata))
    testable = n_values > n_parameters
    return {"p_value": p_value, "chi2": chi2, "n_values": n_values, "flagged": p_value < level,
            "worst": worst, "z": z, "level": float(level), "n_parameters": n_parameters,
            "testable": testable}


def _censored_zero_probability(idata, zero, max_draws):
    """``P0 = P(reading <= 0)`` of every censored zero per draw, NaN elsewhere, from the stored
    log-likelihood (draws, *observed shape); None when the zeros are not censored or none is."""
    attrs = idata.posterior.attrs
    if not (int(attrs.get("censored_zeros", 0)) and zero.any() and "log_likelihood" in idata.groups()):
        return None
    observed = idata.observed_data["y"]
    terms = idata.log_likelihood["y"].transpose("chain", "draw", *observed.dims).values
    terms = _thin(terms.reshape((-1,) + terms.shape[2:]), max_draws)
    return np.where(zero, np.exp(np.minimum(terms, 0.0)), np.nan)


def _censored_residual(probability):
    """``Phi^-1(probability)``, kept finite where ``probability`` underflows to 0 (a zero the draw
    makes impossible: ``|z|`` 38, the double's limit, flags it all the same)."""
    from scipy import special

    return special.ndtri(np.maximum(probability, np.finfo(float).tiny))


def parameters_per_wavelength(idata):
    """How many parameters the posterior has at each wavelength.

    ``a``, one ``tau`` per film group, ``g`` when free, ``eps`` when inferred; parameters
    shared by all wavelengths (the cards' albedo factors) are not counted.

    Returns
    -------
    int
    """
    posterior = idata.posterior
    count = int("a" in posterior)
    if "tau_group" in posterior:
        count += int(posterior["tau_group"].sizes["group"])
    elif "tau" in posterior:
        count += 1
    for name in ("g", "eps"):
        if name in posterior:
            count += int(np.prod([size for dim, size in posterior[name].sizes.items()
                                  if dim not in ("chain", "draw", "wavelength")], dtype=int))
    return count


def model_check_status(check):
    """Per wavelength, the model check's verdict in words.

    Parameters
    ----------
    check : dict
        From :func:`posterior_predictive_check`.

    Returns
    -------
    list of str
        ``"pass"``, ``"misfit (p < 0.01)"`` or ``"not testable (2 values <= 2 parameters)"``.
    """
    out = []
    for i in range(len(check["p_value"])):
        if check["flagged"][i]:
            out.append(f"misfit (p < {check['level']:g})")
        elif not check["testable"][i]:
            out.append(f"not testable ({check['n_values'][i]} values <= {check['n_parameters'][i]} parameters)")
        else:
            out.append("pass")
    return out


# ------------------------------------------------------------------------------------------
# colour


def colour_spectrum(values, channel_kind):
    """A channel's values as a reflectance spectrum for colorimetry.

    BRDF values [1/sr] become reflectance factors ``pi f`` (relative to the perfect
    diffuser); hemispherical reflectances and 45°/0° reflectance factors are used as they are.
    """
    return np.pi * np.asarray(values) if channel_kind == "brdf" else np.asarray(values)


def _colour_stats(wl, spectra, observer, illuminant):
    """Lab of the posterior-mean spectrum and Delta E00 of each draw from it, batched.

    Parameters
    ----------
    spectra : numpy.ndarray
        Shape (..., n_draws, n_wavelengths).

    Returns
    -------
    lab_mean : numpy.ndarray
        Shape (..., 3).
    spread : numpy.ndarray
        Shape (..., n_draws).
    """
    lab_mean = colorimetry.reflectance_to_Lab(spectra.mean(axis=-2), wl, observer=observer,
                                              illuminant=illuminant)
    lab_draws = colorimetry.reflectance_to_Lab(spectra, wl, observer=observer, illuminant=illuminant)
    spread = colorimetry.delta_E2000(lab_draws, lab_mean[..., None, :])
    return lab_mean, spread


def Lab_to_sRGB(Lab, wavelength_nm=None, *, observer=colorimetry.DEFAULT_OBSERVER,
                illuminant=colorimetry.DEFAULT_ILLUMINANT):
    """Display sRGB (0-1, clipped) of CIELAB values, for colour swatches only.

    Lab is converted back to XYZ with the white the Lab values were computed with (that of
    ``wavelength_nm``, ``observer`` and ``illuminant``, :func:`bayespig.colorimetry.white_point_XYZ`)
    and chromatically adapted to sRGB's D65 white (CAT02) by colour-science.
    """
    import colour

    white = colorimetry.white_point_XYZ(wavelength_nm, observer=observer, illuminant=illuminant)
    white_xy = white[:2] / white.sum()
    with colour.domain_range_scale("reference"):
        XYZ = colour.Lab_to_XYZ(np.asarray(Lab, dtype=float), illuminant=white_xy)
        rgb = colour.XYZ_to_sRGB(XYZ, illuminant=white_xy, chromatic_adaptation_transform="CAT02")
    return np.clip(rgb, 0.0, 1.0)


def colour_available(wl):
    """Whether the wavelengths cover enough of the visible range for colorimetry (reason if not)."""
    try:
        colorimetry.weighting_matrix(wl)
    except ValueError as error:
        return False, str(error)
    return True, ""


def measured_colour(idata, *, observer=colorimetry.DEFAULT_OBSERVER,
                    illuminant=colorimetry.DEFAULT_ILLUMINANT, max_draws=400, residuals=None):
    """CIELAB of every measured reflectance (sample and geometry), measured and predicted.

    Returns
    -------
    list of dict
        One per measured reflectance spectrum: ``sample``, ``channel``, ``Lab_measured``,
        ``Lab_predicted`` (of the posterior-mean prediction), ``dE00_measured_predicted``,
        ``dE00_spread`` (the :data:`SPREAD_QUANTILE` quantile of ``Delta E00`` of posterior
        draws from the posterior-mean colour), ``sRGB_measured``, ``sRGB_predicted``.
    """
    wl = wavelengths(idata)
    residuals = residuals or residuals_in_eps(idata, max_draws=max_draws)
    draws = _thin(residuals["predicted_draws"], max_draws)
    columns = [k for k, row in enumerate(residuals["rows"]) if not _is_transmittance(row)]
    if not columns:
        return []
    kinds = [_channel_of(residuals["rows"][k]["channel"], residuals["rows"][k]["kind"]).kind for k in columns]
    measured = np.stack([colour_spectrum(residuals["observed"][:, k], kind) for k, kind in zip(columns, kinds)])
    predicted = np.stack([colour_spectrum(draws[:, :, k], kind) for k, kind in zip(columns, kinds)])
    lab_measured = colorimetry.reflectance_to_Lab(measured, wl, observer=observer, illuminant=illuminant)
    lab_mean, spread = _colour_stats(wl, predicted, observer, illuminant)
    difference = colorimetry.delta_E2000(lab_measured, lab_mean)
    spread_q = np.quantile(spread, SPREAD_QUANTILE, axis=-1)
    rgb_measured = Lab_to_sRGB(lab_measured, wl, observer=observer, illuminant=illuminant)
    rgb_predicted = Lab_to_sRGB(lab_mean, wl, observer=observer, illuminant=illuminant)
    out = []
    for j, k in enumerate(columns):
        row = residuals["rows"][k]
        out.append({
            "sample": row["sample"], "channel": row["channel"],
            "Lab_measured": lab_measured[j], "Lab_predicted": lab_mean[j],
            "dE00_measured_predicted": float(difference[j]),
            "dE00_spread": float(spread_q[j]),
            "sRGB_measured": rgb_measured[j], "sRGB_predicted": rgb_predicted[j],
        })
    return out


@dataclass(frozen=True)
class FilmDesign:
    """A film to predict: the pigment at ``tau_scale`` times the first film group's ``tau``.

    Attributes
    ----------
    label : str
    tau_scale : float
        ``inf`` for an opaque film [-].
    r_s : float
        Substrate albedo seen from the binder [-] (ignored when opaque).
    measured : bool
        Whether a measured film is this one (then the prediction checks the fit).
    """

    label: str
    tau_scale: float
    r_s: float = BLACK_SUBSTRATE_ALBEDO
    measured: bool = False


def default_unmeasured_films(problem):
    """Opaque; the measured film group at twice and half its ``tau`` on black and white; and
    the film on the substrate it was not measured on (e.g. white for method 3). Only the opaque
    film when every film is opaque (no ``tau`` to scale)."""
    group = problem.groups[0] if problem.groups else None
    measured_r_s = [float(np.median(f.r_s)) for f in problem.films
                    if f.kind == "reflectance" and f.group == group and group is not None]
    films = [FilmDesign("opaque (hiding)", np.inf, 0.0, measured=any(f.opaque for f in problem.films
                                                                     if f.kind == "reflectance"))]
    if group is None:
        return films
    for name, r_s in (("black", BLACK_SUBSTRATE_ALBEDO), ("white", WHITE_SUBSTRATE_ALBEDO)):
        if not any(abs(m - r_s) < 0.02 for m in measured_r_s):
            films.append(FilmDesign(f"1 x tau on {name}", 1.0, r_s))
    for scale in (0.5, 2.0):
        for name, r_s in (("black", BLACK_SUBSTRATE_ALBEDO), ("white", WHITE_SUBSTRATE_ALBEDO)):
            films.append(FilmDesign(f"{scale:g} x tau on {name}", scale, r_s))
    return films


def _reference_instrument(problem):
    for film in problem.films:
        if film.kind == "reflectance":
            return film.instrument
    raise ValueError("the posterior has no reflectance measurements to predict films from")


def predicted_film_values(idata, films, *, instrument=None, max_draws=400, tables=None):
    """Channel values of unmeasured films for posterior draws, through the look-up tables.

    Parameters
    ----------
    idata : arviz.InferenceData
    films : sequence of FilmDesign
    instrument : Instrument, optional
        Default: the channels of the first measured reflectance film.
    max_draws : int
    tables : dict, optional
        ``{"isotropic"|"free": LookupTable}`` to reuse.

    Returns
    -------
    instrument : Instrument
    values : numpy.ndarray
        Shape (n_films, n_draws, n_wavelengths, n_channels).
    """
    from ..table import load_table

    problem = problem_from_inference(idata)
    instrument = instrument or _reference_instrument(problem)
    g_kind = "free" if "g" in idata.posterior else "isotropic"
    tables = {} if tables is None else tables
    table = tables.get(g_kind) or load_table(instrument, g=g_kind, n=problem.n, progress=False)
    tables[g_kind] = table
    a = posterior_draws(idata, "a", max_draws)
    if "tau" in idata.posterior:
        tau = posterior_draws(idata, "tau", max_draws)
    elif all(not np.isfinite(film.tau_scale) for film in films):
        tau = np.full(a.shape, np.inf)  # opaque films need no tau
    else:
        raise ValueError("films: the posterior has no tau (every measured film is opaque), so only opaque "
                         "films (tau_scale = inf) can be predicted")
    g = posterior_draws(idata, "g", max_draws) if g_kind == "free" else np.zeros_like(a)
    out = np.empty((len(films), a.shape[0], a.shape[1], len(instrument)))
    for j, film in enumerate(films):
        film_tau = np.full(a.shape, np.inf) if not np.isfinite(film.tau_scale) else film.tau_scale * tau
        # beyond the table's thickest finite film the layer hides its substrate (opaque limit)
        film_tau = np.where(film_tau > table.settings.tau_nodes[-1], np.inf, film_tau)
        r_s = 0.0 if not np.isfinite(film.tau_scale) else film.r_s
        out[j] = table(a=a, tau=film_tau, g=g, r_s=r_s)
    return instrument, out


def film_colour(idata, films, *, observer=colorimetry.DEFAULT_OBSERVER,
                illuminant=colorimetry.DEFAULT_ILLUMINANT, max_draws=400, instrument=None):
    """Predicted colour, with its posterior spread, of films at every channel of an instrument.

    Returns
    -------
    list of dict
        One per (film, channel): ``film``, ``channel``, ``measured`` (bool), ``Lab`` (of the
        posterior-mean spectrum), ``dE00_spread``, ``sRGB``.
    """
    wl = wavelengths(idata)
    instrument, values = predicted_film_values(idata, films, instrument=instrument, max_draws=max_draws)
    spectra = np.stack([colour_spectrum(values[..., k], ch.kind) for k, ch in enumerate(instrument.channels)],
                       axis=1)  # (film, channel, draw, wavelength)
    lab_mean, spread = _colour_stats(wl, spectra, observer, illuminant)
    spread_q = np.quantile(spread, SPREAD_QUANTILE, axis=-1)
    rgb = Lab_to_sRGB(lab_mean, wl, observer=observer, illuminant=illuminant)
    out = []
    for j, film in enumerate(films):
        for k, channel in enumerate(instrument.channels):
            out.append({"film": film.label, "channel": channel.label, "measured": film.measured,
                        "Lab": lab_mean[j, k], "dE00_spread": float(spread_q[j, k]), "sRGB": rgb[j, k]})
    return out


@dataclass
class Ravine:
    """The log-likelihood landscape over ``(a, tau)`` at one wavelength.

    Attributes
    ----------
    wavelength_nm : float
    a : numpy.ndarray
        Grid of ``a``, shape (n_a,) [-].
    tau : numpy.ndarray
        Grid of ``tau`` (log-spaced), shape (n_tau,) [-].
    log_likelihood : numpy.ndarray
        Shape (n_tau, n_a): eq. (7) log-likelihood, other parameters at their posterior medians.
    held : dict
        Parameters held at their posterior medians.
    """

    wavelength_nm: float
    a: np.ndarray
    tau: np.ndarray
    log_likelihood: np.ndarray
    held: dict = field(default_factory=dict)


def ravine(idata, index, *, a_limits=None, tau_limits=None, n_grid=121, problem=None, model=None):
    """Log-likelihood (eq. 7) over a grid of ``(a, tau)`` at wavelength ``index``.

    Uses :class:`~bayespig.likelihood.LogPosterior` (the sampled density) on the problem
    rebuilt from the posterior; further film groups' ``tau``, ``g``, an inferred ``eps`` and noise floor
    are held at their posterior medians.

    Parameters
    ----------
    idata : arviz.InferenceData
    index : int
        Wavelength index.
    a_limits, tau_limits : tuple, optional
        Grid ranges (default: the prior box).
    n_grid : int
        Grid points per axis.

    Returns
    -------
    Ravine
    """
    from ..likelihood import ForwardModel, LogPosterior

    problem = problem or problem_from_inference(idata)
    g_kind = "free" if "g" in idata.posterior else "isotropic"
    model = model or ForwardModel(problem, g_kind)
    priors = priors_from_inference(idata)
    eps = eps_per_value(idata)[index]
    infer_eps = "eps" in idata.posterior
    known = None if infer_eps else (float(eps[0]) if np.all(eps == eps[0]) else None)
    if not infer_eps and known is None:
        # per-film eps: carried by the films of the rebuilt problem
        known = float(np.median(eps))
    floor = noise_floor_per_value(idata)[index]
    floor_inferred = "noise_floor" in idata.posterior
    log_post = LogPosterior(model, index, priors, g_kind, None if infer_eps else known,
                            noise_floor="infer" if floor_inferred else float(np.max(floor, initial=0.0)))
    a_limits = a_limits or priors.a_range
    tau_limits = tau_limits or priors.tau_range
    a_grid = np.linspace(a_limits[0], a_limits[1], n_grid)
    tau_grid = np.geomspace(tau_limits[0], tau_limits[1], n_grid)
    A, T = np.meshgrid(a_grid, tau_grid)
    theta = [A.ravel(), np.log(T.ravel())]
    held = {}
    if len(problem.groups) > 1:
        tau_groups = np.median(posterior_draws(idata, "tau_group")[:, index], axis=0)
        for k in range(1, len(problem.groups)):
            theta.append(np.full(A.size, np.log(tau_groups[k])))
            held[f"tau[{problem.groups[k]}]"] = float(tau_groups[k])
    if log_post.free_g:
        g_med = float(np.median(posterior_draws(idata, "g")[:, index]))
        theta.append(np.full(A.size, g_med))
        held["g"] = g_med
    if log_post.infer_eps:
        eps_med = float(np.median(posterior_draws(idata, "eps")[:, index]))
        theta.append(np.full(A.size, np.log(eps_med)))
        held["eps"] = eps_med
    if floor_inferred:
        floor_med = float(np.median(posterior_draws(idata, "noise_floor")[:, index]))
        theta.append(np.full(A.size, np.log(floor_med)))
        held["noise_floor"] = floor_med
    theta = np.column_stack(theta)
    # keep the grid inside the support (the box edges are inclusive)
    theta = np.clip(theta, log_post.lower, log_post.upper)
    value = log_post.log_likelihood(theta).reshape(A.shape)
    return Ravine(float(problem.wavelength_nm[index]), a_grid, tau_grid, value, held)


# ------------------------------------------------------------------------------------------
# many BRDF geometries (gonio sets)


def gonio_values(rows):
    """The BRDF values of a value table and their angles.

    Parameters
    ----------
    rows : list of dict
        :func:`value_table` (or ``residuals_in_eps(...)["rows"]``).

    Returns
    -------
    dict
        ``index`` (columns of the values that are BRDFs), ``theta_i``, ``theta_o``,
        ``delta_phi`` [deg] (``delta_phi = 180`` on the specular side, DESIGN section 1),
        ``signed_theta_o`` [deg] (``+theta_o`` on the specular side of the plane of incidence,
        ``delta_phi = 180``, ``-theta_o`` on the source side; NaN out of the plane),
        ``mirror_distance_deg`` (:func:`bayespig.selection.mirror_distance_deg`), ``sample``
        and ``channel``; arrays over the BRDF values.
    """
    from ..selection import mirror_distance_deg

    index, angles = [], []
    for k, row in enumerate(rows):
        if _is_transmittance(row):
            continue
        try:
            channel = _channel_of(row["channel"], row["kind"])
        except ValueError:
            continue
        if channel.kind == "brdf":
            index.append(k)
            angles.append((channel.theta_i, channel.theta_o, channel.delta_phi))
    angles = np.asarray(angles, dtype=float).reshape(-1, 3)
    theta_i, theta_o, delta_phi = angles.T
    azimuth = np.mod(delta_phi, 360.0)
    signed = np.where(np.isclose(azimuth, 180.0), theta_o,
                      np.where(np.isclose(azimuth, 0.0) | np.isclose(azimuth, 360.0), -theta_o, np.nan))
    signed = np.where(theta_o == 0.0, 0.0, signed)
    return {"index": np.asarray(index, dtype=int), "theta_i": theta_i, "theta_o": theta_o,
            "delta_phi": delta_phi, "signed_theta_o": signed,
            "mirror_distance_deg": mirror_distance_deg(theta_i, theta_o, delta_phi),
            "sample": [rows[k]["sample"] for k in index], "channel": [rows[k]["channel"] for k in index]}


def spread_values(values, count):
    """Up to ``count`` of the sorted unique ``values`` (e.g. incidence angles), spread evenly
    over them (the first and the last always among them)."""
    values = np.unique(np.asarray(values, dtype=float))
    if values.size <= count:
        return values
    return values[np.unique(np.linspace(0, values.size - 1, count).round().astype(int))]


def is_large_gonio_set(rows, threshold=GONIO_LARGE_GEOMETRIES):
    """Whether a value table has more than ``threshold`` BRDF geometries (over all samples)."""
    return gonio_values(rows)["index"].size > threshold


def mirror_distance_class(distance_deg, bins=MIRROR_DISTANCE_BINS_DEG):
    """The label of the distance-from-the-mirror class of each angle [deg] (e.g. ``"2-10°"``)."""
    labels = mirror_distance_labels(bins)
    classes = np.clip(np.searchsorted(np.asarray(bins[1:-1]), distance_deg, side="right"), 0, len(labels) - 1)
    return [labels[c] for c in np.atleast_1d(classes)]


def mirror_distance_labels(bins=MIRROR_DISTANCE_BINS_DEG):
    """Labels of the distance-from-the-mirror classes: ``< 2°``, ``2-10°``, ..., ``>= 30°``."""
    labels = []
    for k, (low, high) in enumerate(zip(bins[:-1], bins[1:])):
        if k == 0:
            labels.append(f"< {high:g}°")
        elif not np.isfinite(high):
            labels.append(f">= {low:g}°")
        else:
            labels.append(f"{low:g}-{high:g}°")
    return labels


def gonio_residual_summary(residuals, bins=MIRROR_DISTANCE_BINS_DEG):
    """Relative residuals of the BRDF values and their median magnitude per band and class.

    The relative residual is ``(measured - fitted) / fitted`` with ``fitted`` the posterior
    median of the noise-free prediction.

    Parameters
    ----------
    residuals : dict
        :func:`residuals_in_eps` (its ``predicted_draws`` and ``rows``).
    bins : sequence of float
        Edges of the distance-from-the-mirror classes [deg].

    Returns
    -------
    dict
        ``geometry`` (:func:`gonio_values`), ``fitted_median``, ``fitted_q05``, ``fitted_q95``,
        ``measured`` and ``relative`` (n_wavelengths, n_brdf_values); ``classes`` (labels),
        ``count`` (geometries per class), ``median_abs_all`` (n_wavelengths,) and
        ``median_abs_by_class`` (n_wavelengths, n_classes; NaN for an empty class).
    """
    geometry = gonio_values(residuals["rows"])
    index = geometry["index"]
    draws = np.asarray(residuals["predicted_draws"])[..., index]
    median = np.median(draws, axis=0)
    q05, q95 = np.quantile(draws, [0.05, 0.95], axis=0)
    measured = np.asarray(residuals["observed"])[:, index]
    with np.errstate(divide="ignore", invalid="ignore"):
        relative = (measured - median) / median
    magnitude = np.abs(relative)
    labels = mirror_distance_labels(bins)
    classes = np.clip(np.searchsorted(np.asarray(bins[1:-1]), geometry["mirror_distance_deg"], side="right"),
                      0, len(labels) - 1)
    by_class = np.full((magnitude.shape[0], len(labels)), np.nan)
    count = []
    for c in range(len(labels)):
        member = classes == c
        count.append(int(member.sum()))
        if member.any():
            by_class[:, c] = np.nanmedian(magnitude[:, member], axis=1)
    return {"geometry": geometry, "fitted_median": median, "fitted_q05": q05, "fitted_q95": q95,
            "measured": measured, "relative": relative, "classes": labels, "count": count,
            "median_abs_all": np.nanmedian(magnitude, axis=1) if index.size else np.full(magnitude.shape[0], np.nan),
            "median_abs_by_class": by_class}


#: Distance-from-the-mirror classes of :func:`beyond_surface_lobe` [deg].
BEYOND_LOBE_BINS_DEG = (2.0, 10.0, 20.0, 30.0, 45.0, 60.0, 90.0, 180.0)


def beyond_surface_lobe(gonio, *, roughness, binder_index, bins=BEYOND_LOBE_BINS_DEG, max_angle_deg=60.0):
    """The light beyond the first-surface lobe, measured and fitted, by distance from the mirror.

    A rough fit's BRDF is the first-surface lobe (Walter et al. 2007, eq. 20; one GGX
    ``alpha`` for all bands) plus what the layer sends back (the body, effect-pigment flakes).
    Measured less that lobe is what the data say the layer sends back at each geometry: for
    an isotropic body under a rough surface it is nearly flat away from grazing, so a rise
    towards the mirror that follows the body's colour is light the isotropic body does not
    make (flakes, a glossy reflector under a clear coat), and a rise at dark bands is a lobe
    whose shape is not GGX. The fitted column is the posterior-median prediction less the same
    lobe: where it follows the measured one, the model reproduces that light.

    Parameters
    ----------
    gonio : dict
        :func:`gonio_residual_summary` of the fit.
    roughness, binder_index : float
        The surface's GGX ``alpha`` and the binder index of the lobe (e.g. the posterior
        medians) [-].
    bins : sequence of float
        Edges of the distance-from-the-mirror classes [deg] (geometries outside them are left
        out).
    max_angle_deg : float
        Only geometries with ``theta_i`` and ``theta_o`` at most this [deg] (grazing readings
        carry the incidence offset and the lobe's steep shadowing).

    Returns
    -------
    dict
        ``classes`` (labels), ``count`` (geometries per class), ``measured`` and ``fitted``
        (n_wavelengths, n_classes): medians of ``x - f_lobe`` over each class [1/sr] (NaN for
        an empty class).
    """
    from ..physics.forward import first_surface_brdf

    geometry = gonio["geometry"]
    lobe = first_surface_brdf(geometry["theta_i"], geometry["theta_o"], geometry["delta_phi"],
                              roughness=float(roughness), n=float(binder_index))
    distance = geometry["mirror_distance_deg"]
    keep = (geometry["theta_i"] <= max_angle_deg) & (geometry["theta_o"] <= max_angle_deg)
    bins = np.asarray(bins, dtype=float)
    classes = list(itertools.pairwise(bins))
    labels = [f"{low:g}-{high:g}°" for low, high in classes]
    measured = np.asarray(gonio["measured"], dtype=float) - lobe
    fitted = np.asarray(gonio["fitted_median"], dtype=float) - lobe
    out = {"classes": labels, "count": [], "measured": np.full((measured.shape[0], len(labels)), np.nan)}
    out["fitted"] = out["measured"].copy()
    for c, (low, high) in enumerate(classes):
        member = keep & (distance > low) & (distance <= high)
        out["count"].append(int(member.sum()))
        if member.any():
            out["measured"][:, c] = np.median(measured[:, member], axis=1)
            out["fitted"][:, c] = np.median(fitted[:, member], axis=1)
    return out
