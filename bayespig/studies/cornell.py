"""The Cornell gonio paints (issue 16): rough-surface fits, subset consistency, report.

Two real ASTM E1392 files of the Cornell gonioreflectometer (garnet red lacquer and Krylon
blue enamel under a frosted overcoat; 1439 geometries, 31 bands 400-700 nm; see
``../shared/data/cornell/README.md``), read as opaque films
(``read_measurements(path, opaque=True)``). For each paint this module runs

Every fit leaves out the geometries that read (nearly) nothing in every band amid bright
neighbours (:func:`bayespig.selection.occluded_geometries`: on both files theta_i = 80°,
theta_o = 79°, delta_phi = 160-170°, blocked readings inside the grazing gloss lobe), unless
``exclude_occluded=False``.

* the full fit: every geometry more than :data:`MIRROR_CUT_DEG` from the mirror direction,
  every band, the surface roughness ``alpha`` free (one GGX surface shared by all bands), a
  noise floor per band inferred, ``eps`` fixed at :data:`EPS` (the joint roughness sampler
  needs a known ``eps``; the inferred floor takes the dark values' absolute noise, and a
  fixed ``eps`` keeps misfit visible in the model check instead of absorbing it);
* the subset-consistency fits: the geometries more than :data:`SUBSET_SPLIT_DEG` from the
  mirror against those :data:`MIRROR_CUT_DEG`-:data:`SUBSET_SPLIT_DEG` from it (both with
  ``theta_i, theta_o <= SUBSET_MAX_ANGLE_DEG``), the same model, and whether the 90 %
  intervals of ``a`` overlap per band (:func:`interval_overlap`);
* the smooth model (roughness 0) on the full set at a few bands, for comparison;

and :func:`write_cornell_report` writes ``reports/cornell.md`` with its figures in
``reports/cornell/`` (one atomic file set), reusing the report package's figures and checks
(:mod:`bayespig.report.figures`, :mod:`bayespig.report.quantities`).

Goals (issue 16): median ``|x_obs / x_fit - 1|`` over the geometries more than 2 deg from the
mirror <= :data:`RESIDUAL_GOAL` at the bands where the body dominates
(:data:`BODY_BANDS_NM`), and overlapping subset intervals at >= :data:`OVERLAP_GOAL` of the
bands, a band counting only where both subset runs' ``a`` mixed there (:func:`overlap_goal`).
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from .._atomic import write_file_set
from ..data import MeasurementSet, read_measurements
from ..inference import InferenceSettings, diagnose, infer, summarize
from ..report import figures as figs
from ..report import quantities as q
from ..selection import mirror_distance_deg, select_measurements

__all__ = [
    "BODY_BANDS_NM",
    "PAINTS",
    "CornellStudySettings",
    "cornell_study",
    "default_cornell_path",
    "fit_summary",
    "interval_overlap",
    "mirror_band_subset",
    "overlap_goal",
    "rough_fit_arguments",
    "write_cornell_report",
]

#: The paints (file stems in the data folder) and their names in the report.
PAINTS = {"garnet_red": "Garnet red lacquer (Dupli-Color T-345)",
          "krylon_blue": "Krylon blue enamel (7205 True Blue)"}
#: Bands where the paint's body (not its surface) dominates the BRDF away from the mirror [nm].
BODY_BANDS_NM = {"garnet_red": (600.0, 700.0), "krylon_blue": (420.0, 500.0)}
#: Goal of the median |relative residual| at the body bands (issue 16) [-].
RESIDUAL_GOAL = 0.10
#: Goal of the share of bands whose subset intervals overlap (issue 16) [-].
OVERLAP_GOAL = 0.90
#: Geometries within this angle of the mirror direction are left out of every fit [deg].
MIRROR_CUT_DEG = 2.0
#: Distance from the mirror that splits the two consistency subsets [deg].
SUBSET_SPLIT_DEG = 30.0
#: Largest theta_i and theta_o of both consistency subsets [deg].
SUBSET_MAX_ANGLE_DEG = 60.0
#: Relative measurement error of every value (fixed; see the module docstring) [-].
EPS = 0.05
#: Central probability of the reported intervals.
INTERVAL = 0.90
#: Incidence angles of the plane-of-incidence and residual-map figures [deg].
FIGURE_INCIDENCES = (10.0, 30.0, 50.0, 70.0)
#: Bands of the plane-of-incidence figure [nm].
FIGURE_BANDS_NM = (450.0, 550.0, 650.0)
#: Bands of the table of the light beyond the surface lobe [nm].
BEYOND_LOBE_BANDS_NM = (450.0, 500.0, 550.0, 600.0, 650.0, 700.0)


@dataclasses.dataclass(frozen=True)
class CornellStudySettings:
    """What the study fits, and how long it samples.

    Attributes
    ----------
    full_bands : sequence of float or None
        Bands of the full fit [nm] (None: all 31).
    subset_bands : sequence of float or None
        Bands of the subset-consistency fits [nm] (None: all).
    smooth_bands : sequence of float
        Bands of the smooth-model comparison [nm].
    incidences_deg : sequence of float or None
        Keep only the geometries at these incidence angles [deg] (None: all; for tests: each
        incidence has about 10 distinct viewing angles, and the rough table's cost grows with
        the distinct ``(theta_i, theta_o)``).
    max_geometries : int or None
        Keep at most this many geometries per paint (evenly spread; for tests).
    inference : InferenceSettings
        Sampler settings of every fit.
    binder_index : {"free", None}
        The binder index of the rough fits: inferred with the roughness (the default; its
        tables at the six index nodes are built once per geometry set, the subsets' taken from
        the full set's, :func:`bayespig.rough_table.derive_rough_table`) or None (fixed at 1.45).
    flakes : bool
        Fit the paints with an effect-pigment lobe (``infer(..., flakes=True)``: a flake
        reflectance per band, one flake roughness; the default), and the full set without it
        as well, for comparison; False: the surface alone (the model of before).
    incidence_offset : bool
        Infer the instrument's incidence offset ``b / cos theta_i`` per band in every rough fit
        (``infer(..., incidence_offset=True)``; the default): the paints' exact zeros lie almost
        all at 70-80 deg incidence, where a background subtracted in excess takes the readings of
        dark bands to 0.
    exclude_occluded : bool
        Leave out the geometries :func:`bayespig.selection.occluded_geometries` flags (the
        default): each reads below 0.002 1/sr in all bands where the model (any model of a
        paint) has a bright gloss lobe; in the full fit of the Krylon blue the exact zeros among
        them cost -144 (420 nm) and -189 (500 nm) in log-likelihood each, on average
        (``python benchmarks/cornell_censored_zeros.py``), pulling the roughness shared by all bands.
    seed : int
    """

    full_bands: tuple | None = None
    subset_bands: tuple | None = None
    smooth_bands: tuple = (450.0, 550.0, 650.0)
    incidences_deg: tuple | None = None
    max_geometries: int | None = None
    inference: InferenceSettings = dataclasses.field(
        default_factory=lambda: InferenceSettings(draws_per_chain=256, target_ess=400, max_steps=8000))
    binder_index: str | None = "free"
    flakes: bool = True
    incidence_offset: bool = True
    exclude_occluded: bool = True
    seed: int = 0


def default_cornell_path():
    """``$BAYESPIG_CORNELL`` or ``../shared/data/cornell`` relative to the working directory."""
    return Path(os.environ.get("BAYESPIG_CORNELL", Path.cwd().parent / "shared" / "data" / "cornell"))


def interval_overlap(first, second):
    """Whether two sets of intervals overlap, per band.

    Parameters
    ----------
    first, second : array_like, shape (2, n_bands)
        Lower and upper ends of the intervals (e.g. the 5 % and 95 % quantiles of ``a``).

    Returns
    -------
    numpy.ndarray of bool, shape (n_bands,)
        True where ``max(low) <= min(high)`` (touching intervals overlap).
    """
    first, second = np.asarray(first, dtype=float), np.asarray(second, dtype=float)
    if first.shape != second.shape or first.ndim != 2 or first.shape[0] != 2:
        raise ValueError(f"first and second must both have shape (2, n_bands), got {first.shape} and {second.shape}")
    return np.maximum(first[0], second[0]) <= np.minimum(first[1], second[1])


def _mirror_distances(measurement_list):
    return np.array([mirror_distance_deg(m.theta_i, m.theta_o, m.delta_phi) for m in measurement_list])


def mirror_band_subset(measurements, low_deg, high_deg, max_angle_deg=None):
    """The set with only the films' geometries ``low < distance <= high`` from the mirror.

    Parameters
    ----------
    measurements : MeasurementSet
    low_deg, high_deg : float
        Distance from the mirror direction (:func:`bayespig.selection.mirror_distance_deg`) [deg].
    max_angle_deg : float, optional
        Also drop geometries with ``theta_i`` or ``theta_o`` beyond this [deg].
    """
    samples = []
    for sample in measurements.samples:
        distance = _mirror_distances(sample.measurements)
        kept = tuple(m for m, d in zip(sample.measurements, distance)
                     if low_deg < d <= high_deg
                     and (max_angle_deg is None or max(m.theta_i, m.theta_o) <= max_angle_deg))
        samples.append(dataclasses.replace(sample, measurements=kept))
    return MeasurementSet(measurements.wavelength_nm, samples, n=measurements.n)


def _thin_geometries(measurements, count, incidences_deg=None):
    """The geometries at ``incidences_deg`` only (all when None), at most ``count`` of them per
    film (evenly spread over the file's order; all when None)."""
    if count is None and incidences_deg is None:
        return measurements
    samples = []
    for sample in measurements.samples:
        kept = [m for m in sample.measurements
                if incidences_deg is None or np.any(np.isclose(m.theta_i, incidences_deg, atol=0.05))]
        if count is not None and len(kept) > count:
            kept = [kept[i] for i in np.unique(np.linspace(0, len(kept) - 1, count).round().astype(int))]
        samples.append(dataclasses.replace(sample, measurements=tuple(kept)))
    return MeasurementSet(measurements.wavelength_nm, samples, n=measurements.n)


def _n_geometries(measurements):
    return len(measurements.films[0].measurements)


def fit_summary(idata, *, interval=INTERVAL):
    """What the report quotes from one fit.

    Returns
    -------
    dict
        ``wavelength_nm``; ``a`` (3, n_bands: low, median, high of the central ``interval``);
        ``roughness`` (low, median, high) or None; ``noise_floor`` (n_bands,) posterior median
        or None; ``residual`` (n_bands,): median ``|x_obs / x_fit - 1|`` over the fitted BRDF
        geometries (``x_fit`` the posterior median of the noise-free prediction,
        :func:`bayespig.report.quantities.gonio_residual_summary`); ``check``:
        :func:`~bayespig.report.quantities.posterior_predictive_check` and its ``status``;
        ``edges``: :func:`~bayespig.report.quantities.prior_edges`; ``gonio``: the residual
        summary; ``n_steps``, ``max_steps_reached``; ``diagnostics``: lines of
        :func:`bayespig.inference.diagnose`; ``a_mixed`` (n_bands,): whether ``a`` passed
        R-hat <= :data:`~bayespig.report.quantities.RHAT_MAX` and bulk and tail ESS >=
        :data:`~bayespig.report.quantities.ESS_MIN` at that band (its interval represents
        the posterior; a run capped at ``max_steps`` may still pass).
    """
    tail = (1.0 - interval) / 2.0
    wl = q.wavelengths(idata)
    a = q.posterior_draws(idata, "a")
    out = {"wavelength_nm": wl, "a": np.quantile(a, [tail, 0.5, 1.0 - tail], axis=0)}
    post = idata.posterior
    out["roughness"] = (tuple(np.quantile(np.asarray(post["roughness"].values, dtype=float).ravel(),
                                          [tail, 0.5, 1.0 - tail]))
                        if "roughness" in post else None)
    out["binder_index"] = (tuple(np.quantile(np.asarray(post["binder_index"].values, dtype=float).ravel(),
                                             [tail, 0.5, 1.0 - tail]))
                           if "binder_index" in post else None)
    out["noise_floor"] = (np.median(q.posterior_draws(idata, "noise_floor"), axis=0)
                          if "noise_floor" in post else None)
    out["incidence_offset"] = (np.quantile(q.posterior_draws(idata, "incidence_offset"), [tail, 0.5, 1.0 - tail],
                                           axis=0) if "incidence_offset" in post else None)
    out["flake_roughness"] = (tuple(np.quantile(np.asarray(post["flake_roughness"].values, dtype=float).ravel(),
                                                [tail, 0.5, 1.0 - tail]))
                              if "flake_roughness" in post else None)
    out["flake_reflectance"] = (np.quantile(q.posterior_draws(idata, "flake_reflectance"), [tail, 0.5, 1.0 - tail],
                                            axis=0) if "flake_reflectance" in post else None)
    residuals = q.residuals_in_eps(idata)
    gonio = q.gonio_residual_summary(residuals)
    out["gonio"] = gonio
    out["residual"] = gonio["median_abs_all"]
    check = q.posterior_predictive_check(idata)
    check["status"] = q.model_check_status(check)
    out["check"] = check
    out["edges"] = q.prior_edges(idata)
    stats = idata.sample_stats
    out["n_steps"] = [int(n) for n in np.atleast_1d(stats["n_steps"].values)]
    out["max_steps_reached"] = bool(np.any(stats["max_steps_reached"].values))
    out["diagnostics"] = list(diagnose(idata, warn=False))
    table = summarize(idata)
    out["a_mixed"] = ((table["a_r_hat"].values <= q.RHAT_MAX) & (table["a_ess_bulk"].values >= q.ESS_MIN)
                      & (table["a_ess_tail"].values >= q.ESS_MIN))
    return out


def rough_fit_arguments(settings):
    """The keyword arguments of :func:`bayespig.infer` of the study's rough fits (full and subsets).

    One place for them, so a benchmark that refits a set of the study (e.g.
    ``benchmarks/cornell_subsets_few_bands.py``) fits the same model with the same priors,
    sampler settings and seed.

    Parameters
    ----------
    settings : CornellStudySettings

    Returns
    -------
    dict
        ``eps`` (:data:`EPS`), ``noise_floor="infer"``, ``seed``, ``progress=False``, the sampler
        ``settings``, ``roughness="free"``, ``binder_index``, ``flakes`` and ``incidence_offset``.
    """
    return {**_sampler_arguments(settings), **_surface_arguments(settings)}


def _sampler_arguments(settings):
    return {"eps": EPS, "noise_floor": "infer", "seed": settings.seed, "progress": False,
            "settings": settings.inference}


def _surface_arguments(settings):
    return {"roughness": "free", "binder_index": settings.binder_index, "flakes": settings.flakes,
            "incidence_offset": settings.incidence_offset}


def _infer(measurements, settings, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        started = time.perf_counter()
        idata = infer(measurements, **_sampler_arguments(settings), **kwargs)
    summary = fit_summary(idata)
    summary["seconds"] = time.perf_counter() - started
    summary["warnings"] = sorted({str(w.message) for w in caught})
    return summary


def overlap_goal(result):
    """The subset-consistency goal of issue 16 for one paint, counting converged intervals only.

    An interval from a run whose ``a`` did not mix at that band (R-hat or ESS of ``a`` outside
    :data:`bayespig.report.quantities.RHAT_MAX` / ``ESS_MIN``) is not a posterior interval but
    the spread of chains that disagree, and its overlap with the other subset's says nothing;
    so a band counts towards the goal only where the two intervals overlap *and* both runs'
    ``a`` mixed there.

    Parameters
    ----------
    result : dict
        A paint's result of :func:`cornell_study`: ``overlap`` (bool per band) and the subset
        fits ``far`` and ``near`` with ``a_mixed`` (bool per band, :func:`fit_summary`).

    Returns
    -------
    dict
        ``bands`` (number of subset bands), ``overlapping`` (bands whose intervals overlap),
        ``mixed`` (bands where both runs mixed), ``counted`` (overlapping and both mixed),
        ``share`` (``counted / bands``, nan without bands) and ``met``
        (``share >= OVERLAP_GOAL``).
    """
    overlap = np.asarray(result["overlap"], dtype=bool)
    runs = [np.asarray(result[fit]["a_mixed"], dtype=bool) for fit in ("far", "near")]
    for fit, run in zip(("far", "near"), runs):
        if run.shape != overlap.shape:
            raise ValueError(f"the {fit} subset run's a_mixed has shape {run.shape}, the overlap {overlap.shape}")
    mixed = runs[0] & runs[1]
    counted = int(np.sum(overlap & mixed))
    share = counted / overlap.size if overlap.size else float("nan")
    return {"bands": int(overlap.size), "overlapping": int(overlap.sum()), "mixed": int(mixed.sum()),
            "counted": counted, "share": share, "met": bool(share >= OVERLAP_GOAL)}


def _overlap_goal_text(goal):
    """The goal line's count: converged overlaps first, then what the unmixed runs add."""
    text = f"{goal['counted']} of {goal['bands']} bands overlap with both runs' a mixed, {_pct(goal['share'])}"
    if goal["mixed"] < goal["bands"]:
        text += (f"; both runs mixed at {goal['mixed']} of {goal['bands']} bands; counting the runs that did not "
                 f"mix, {goal['overlapping']} of {goal['bands']} intervals overlap")
    return text


def _beyond_lobe_lines(result, wl):
    """The report's table of the light beyond the surface lobe (full fit), at :data:`BEYOND_LOBE_BANDS_NM`."""
    full = result["full"]
    if full["roughness"] is None:
        return []
    n = full["binder_index"][1] if full["binder_index"] is not None else result["instrument_binder_index"]
    beyond = q.beyond_surface_lobe(full["gonio"], roughness=full["roughness"][1], binder_index=n)
    bands = [int(np.argmin(np.abs(wl - b))) for b in _present(wl, BEYOND_LOBE_BANDS_NM)]
    keep = [c for c, count in enumerate(beyond["count"]) if count]
    return [("Light beyond the surface lobe (full fit): measured BRDF less the first-surface lobe at the "
             f"posterior-median roughness {full['roughness'][1]:.4f} and binder index {n:.4f}, median over the "
             "geometries with theta_i, theta_o <= 60° in each class of distance from the mirror [1/sr]; in "
             "brackets the fitted BRDF less the same lobe. For an isotropic body under the rough surface it is "
             "nearly flat over the classes; a rise towards the mirror is light the body does not make (at bright "
             "bands: the flakes' lobe takes it; at dark bands: a lobe whose shape is not GGX)."), "",
            _table(["band [nm]"] + [f"{beyond['classes'][c]} ({beyond['count'][c]})" for c in keep],
                   [[f"{wl[i]:g}"] + [f"{beyond['measured'][i, c]:.4f} ({beyond['fitted'][i, c]:.4f})" for c in keep]
                    for i in bands]), ""]


def _rough_instrument(measurements):
    """The instrument the forward model tabulates for the (one) film of a set."""
    from ..likelihood import Problem

    return Problem.from_measurements(measurements, "auto").films[0].instrument


def _derive_subset_tables(full, subsets, over_n):
    """Cache the subsets' rough tables as columns of the full set's (at the set's ``n``, and at
    every binder-index node when ``over_n``): no build for a subset of geometries."""
    from ..rough_table import BINDER_INDEX_NODES, derive_rough_table, load_rough_table

    parent = _rough_instrument(full)
    indices = sorted({float(full.n)} | (set(BINDER_INDEX_NODES) if over_n else set()))
    for n in indices:
        table = load_rough_table(parent, n=n, progress=False)
        for subset in subsets:
            derive_rough_table(table, _rough_instrument(subset))


def cornell_study(folder=None, settings=None, paints=None, progress=None, jobs=1):
    """Run the fits of every paint (see the module docstring).

    Parameters
    ----------
    folder : path, optional
        The Cornell data (default :func:`default_cornell_path`).
    settings : CornellStudySettings, optional
    paints : sequence of str, optional
        File stems (default :data:`PAINTS`).
    progress : callable, optional
        Called with a line of text before each fit (with ``jobs > 1`` the workers print their
        lines to standard error themselves).
    jobs : int
        Paints fitted at once, each in its own process (1: one after the other, here). Every
        fit is seeded by ``settings.seed`` alone, so the results do not depend on ``jobs``.

    Returns
    -------
    dict
        ``folder``, ``settings``, ``paints``: per paint ``full``, ``smooth``, ``far``, ``near``
        (and ``no_flakes`` with ``settings.flakes``) (:func:`fit_summary`), ``overlap`` (bool per
        subset band), ``counts`` (geometries of each fit), ``instrument_binder_index`` (the
        binder index of the tables, the fits' when it is not inferred) and ``seconds``.
    """
    from .._pool import executor_or_local_pool

    folder = Path(folder) if folder is not None else default_cornell_path()
    settings = settings or CornellStudySettings()
    paints = list(paints or PAINTS)
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be a positive integer, got {jobs!r}")
    started = time.perf_counter()
    out = {"folder": folder, "settings": settings, "paints": {}}
    if jobs == 1 or len(paints) == 1:
        for paint in paints:
            out["paints"][paint] = _study_paint(folder, settings, paint, progress, started)
    else:
        with executor_or_local_pool(None, max_workers=min(jobs, len(paints))) as pool:
            futures = {paint: pool.submit(_study_paint, folder, settings, paint, _print_progress if progress else None,
                                          None) for paint in paints}
            out["paints"] = {paint: future.result() for paint, future in futures.items()}
    out["seconds"] = time.perf_counter() - started
    return out


def _print_progress(message):
    """A worker's progress line (standard error)."""
    print(message, file=sys.stderr, flush=True)


def study_sets(measurements, settings):
    """The geometry sets of one paint's fits.

    Parameters
    ----------
    measurements : MeasurementSet
        The paint's file, read as an opaque film.
    settings : CornellStudySettings

    Returns
    -------
    tuple
        ``(occluded, full, far, near)``: the labels of the geometries left out as occluded
        (``settings.exclude_occluded``; :func:`bayespig.selection.occluded_geometries`), and the
        sets of the full fit (> :data:`MIRROR_CUT_DEG` from the mirror) and of the two subsets
        (> :data:`SUBSET_SPLIT_DEG`, and :data:`MIRROR_CUT_DEG`-:data:`SUBSET_SPLIT_DEG`, both with
        ``theta_i, theta_o <=`` :data:`SUBSET_MAX_ANGLE_DEG`), without the occluded geometries.
    """
    if settings.exclude_occluded:
        measurements = select_measurements(measurements, exclude_occluded=True)
    occluded = [label for labels in measurements.metadata.get("selection", {}).get("occluded", {}).values()
                for label in labels]
    full = select_measurements(measurements, exclude_mirror_deg=MIRROR_CUT_DEG)
    far = select_measurements(measurements, exclude_mirror_deg=SUBSET_SPLIT_DEG,
                              max_angle_deg=SUBSET_MAX_ANGLE_DEG)
    near = mirror_band_subset(measurements, MIRROR_CUT_DEG, SUBSET_SPLIT_DEG, SUBSET_MAX_ANGLE_DEG)
    return occluded, full, far, near


def _study_paint(folder, settings, paint, progress, started):
    """Every fit of one paint (:func:`cornell_study`)."""
    started = time.perf_counter() if started is None else started
    say = ((lambda message: progress(f"[{time.perf_counter() - started:.0f} s] {message}")) if progress
           else (lambda message: None))
    measurements = _thin_geometries(read_measurements(folder / f"{paint}.astm", opaque=True),
                                    settings.max_geometries, settings.incidences_deg)
    n_file = _n_geometries(measurements)
    occluded, full, far, near = study_sets(measurements, settings)
    result = {"occluded": occluded,
              "counts": {"all": n_file, "full": _n_geometries(full),
                         "far": _n_geometries(far), "near": _n_geometries(near)}}
    result["instrument_binder_index"] = _rough_instrument(full).n
    bands = None if settings.full_bands is None else list(settings.full_bands)
    surface = _surface_arguments(settings)
    say(f"{paint}: full fit, {result['counts']['full']} geometries, roughness"
        + (" and binder index" if settings.binder_index else "") + " free"
        + (", with flakes" if settings.flakes else "")
        + (", with the incidence offset" if settings.incidence_offset else ""))
    result["full"] = _infer(full, settings, wavelengths=bands, **surface)
    if settings.flakes:
        say(f"{paint}: full fit without flakes, for comparison")
        result["no_flakes"] = _infer(full, settings, wavelengths=bands, **{**surface, "flakes": False})
    _derive_subset_tables(full, (far, near), settings.binder_index == "free")
    subset_bands = None if settings.subset_bands is None else list(settings.subset_bands)
    for name in ("far", "near"):
        say(f"{paint}: subset '{name}', {result['counts'][name]} geometries")
        result[name] = _infer(far if name == "far" else near, settings, wavelengths=subset_bands, **surface)
    say(f"{paint}: smooth model at {', '.join(f'{b:g}' for b in settings.smooth_bands)} nm")
    result["smooth"] = _infer(full, settings, roughness=0.0, wavelengths=list(settings.smooth_bands))
    result["overlap"] = interval_overlap(result["far"]["a"][[0, 2]], result["near"]["a"][[0, 2]])
    return result


# ------------------------------------------------------------------------------------------
# report


def _table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _shown_folder(folder):
    """The data folder as the report shows it: relative to the working folder (as the user would
    type it), so the report does not record the absolute path of the machine it ran on."""
    try:
        return os.path.relpath(folder)
    except ValueError:  # another drive (Windows)
        return str(folder)


def _pct(x):
    return "n/a" if x is None or not np.isfinite(x) else f"{100.0 * x:.1f} %"


def _interval(lo, mid, hi, digits=3):
    return f"{mid:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"


def _body_residual_goal(paint, fit):
    """(bands in the body range, their residuals, all <= goal)."""
    low, high = BODY_BANDS_NM[paint]
    wl = fit["wavelength_nm"]
    member = (wl >= low - 1e-6) & (wl <= high + 1e-6)
    values = fit["residual"][member]
    return wl[member], values, bool(member.any() and np.all(values <= RESIDUAL_GOAL))


def _spectrum_figure(paint, result):
    """a(lambda) with its 90 % band: full fit, both subsets and the smooth model."""
    fig = figs._figure(7.0, 4.2)
    ax = fig.subplots()
    for key, label, colour in (("full", f"rough, > {MIRROR_CUT_DEG:g}° from the mirror", "k"),
                               ("far", f"rough, > {SUBSET_SPLIT_DEG:g}° (<= {SUBSET_MAX_ANGLE_DEG:g}°)", "C0"),
                               ("near", (f"rough, {MIRROR_CUT_DEG:g}-{SUBSET_SPLIT_DEG:g}° "
                                        f"(<= {SUBSET_MAX_ANGLE_DEG:g}°)"), "C1"),
                               ("smooth", "smooth surface, > 2°", "C3")):
        fit = result[key]
        wl, a = fit["wavelength_nm"], fit["a"]
        style = "-" if wl.size > 3 else "o"
        if wl.size > 3:  # a band between a few scattered bands would suggest values in between
            ax.fill_between(wl, a[0], a[2], color=colour, alpha=0.2, lw=0)
        ax.errorbar(wl, a[1], yerr=[a[1] - a[0], a[2] - a[1]], fmt=style, color=colour, ms=4, lw=1.2,
                    capsize=2, label=label)
    ax.set_xlabel("wavelength [nm]")
    ax.set_ylabel("relative absorption a = 1 - ω [-]")
    ax.set_ylim(-0.02, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"{PAINTS.get(paint, paint)}: a(λ), median and 90 % interval", fontsize=10)
    return fig


def _grouped_diagnostics(diagnostics):
    """``diagnose`` lines (``"<band> nm: <text>"``) with the bands of identical text joined."""
    groups = {}
    for line in diagnostics:
        band, _, text = line.partition(": ")
        groups.setdefault(text if text else band, []).append(band if text else "")
    return [(f"{', '.join(b for b in bands if b)}: " if any(bands) else "") + text
            for text, bands in groups.items()]


def _present(values, wanted):
    values = np.asarray(values, dtype=float)
    return [float(v) for v in wanted if np.any(np.isclose(values, v))] or [float(v) for v in values[:1]]


def cornell_report(study):
    """The report's Markdown and its figures.

    Returns
    -------
    (str, dict)
        The Markdown text and ``{relative path: PNG bytes}`` (paths under ``cornell/``).
    """
    settings = study["settings"]
    files = {}
    lines = ["# Cornell gonio paints: rough-surface fits (issue 16)", "",
             ("Regenerate with one command (from the repository root; data in `../shared/data/cornell` or "
             "`$BAYESPIG_CORNELL`):"), "", "    bayespig cornell", "",
             (f"Data: `{_shown_folder(study['folder'])}` (Cornell Program of Computer Graphics gonioreflectometer, ASTM E1392; "
             "see its README). Each paint is read as an opaque film (`read_measurements(path, opaque=True)`)."),
             "",
             ("Model: opaque isotropic layer under a rough GGX air/binder surface (`bayespig.physics.rough_surface`), "
             "roughness alpha one parameter shared by all bands (log-uniform on 0.01..1), "
             + ("the binder index n another (normal 1.45 +- 0.05 truncated to 1.37..1.77; it sets the lobe's "
                "height), " if settings.binder_index == "free" else "binder index fixed at 1.45, ")
             + ("effect-pigment flakes: their lobe (`bayespig.physics.forward.flake_brdf`: mirror flakes in the "
                "binder, GGX orientations of one flake roughness for all bands, log-uniform on 0.02..1, seen through "
                "the surface) with a flake reflectance per band (log-uniform on 1e-5..1); the same fit without "
                "flakes is shown for comparison; " if settings.flakes else "")
             + ("the instrument's incidence offset: each BRDF reading is max(f - b / cos theta_i, 0) with one "
                "b per band (log-uniform, the floor's range; `infer(..., incidence_offset=True)`), a background "
                "subtracted in excess in radiance units (the paints' exact zeros lie almost all at 70-80 deg "
                "incidence); the residuals and the model check compare the readings with the predicted readings; "
                if settings.incidence_offset else "")
             + "a per-band noise floor "
             f"inferred (log-uniform), eps fixed at {EPS:g}: the joint roughness sampler needs a known eps, the "
             "floor takes the absolute noise of dark values and of the exact zeros, and a fixed eps keeps misfit "
             "visible in the model check rather than absorbed by a growing eps."), "",
             f"Sampler: {settings.inference.n_walkers} walkers x {settings.inference.n_ensembles} ensembles, "
             f"target ESS {settings.inference.target_ess:g}, at most {settings.inference.max_steps} steps, "
             f"{settings.inference.draws_per_chain} stored draws per chain; seed {settings.seed}. "
             f"Full fit bands: {'all' if settings.full_bands is None else ', '.join(f'{b:g}' for b in settings.full_bands)}; "
             f"subset bands: {'all' if settings.subset_bands is None else ', '.join(f'{b:g}' for b in settings.subset_bands)}; "
             f"smooth-model bands: {', '.join(f'{b:g}' for b in settings.smooth_bands)} nm"
             + ("" if settings.incidences_deg is None else
                "; incidences " + ", ".join(f"{t:g}" for t in settings.incidences_deg) + "° only")
             + ("" if settings.max_geometries is None else f"; at most {settings.max_geometries} geometries per paint")
             + f". Whole study: {study['seconds'] / 60:.1f} min.", ""]
    goals = []
    for paint, result in study["paints"].items():
        full, smooth = result["full"], result["smooth"]
        wl = full["wavelength_nm"]
        counts = result["counts"]
        name = PAINTS.get(paint, paint)
        occluded = result.get("occluded", [])
        lines += [f"## {name} (`{paint}.astm`)", "",
                  f"{counts['all']} geometries in the file"
                  + (f"; left out as occluded (dark in every band amid bright neighbours, "
                     f"`selection.occluded_geometries`): {', '.join(occluded)}" if occluded else "")
                  + f"; full fit: {counts['full']} more than "
                  f"{MIRROR_CUT_DEG:g}° from the mirror ({full['seconds']:.0f} s, steps per run "
                  f"{', '.join(map(str, full['n_steps']))}"
                  + (", **max_steps reached**" if full["max_steps_reached"] else "") + ").", ""]
        r, n, r_f = full["roughness"], full["binder_index"], full.get("flake_roughness")
        lines += [f"**Roughness alpha (GGX): {_interval(*r, digits=4)}**"
                  + ("" if n is None else f"; **binder index n: {_interval(*n, digits=4)}**")
                  + ("" if r_f is None else f"; **flake roughness: {_interval(*r_f, digits=4)}**")
                  + " (median [90 % interval]).", ""]
        for line in full["warnings"]:
            lines += [f"- warning: {line}"]
        lines += [f"- not converged: {line}" for line in _grouped_diagnostics(full["diagnostics"])]
        lines += [""] if full["warnings"] or full["diagnostics"] else []
        # goals
        body_wl, body_res, residual_ok = _body_residual_goal(paint, full)
        overlap = result["overlap"]
        overlap_verdict = overlap_goal(result)
        goals.append((name, body_wl, body_res, residual_ok, overlap_verdict,
                      " / ".join(_interval(*result[k]["roughness"], digits=3) for k in ("full", "far", "near")),
                      " / ".join(_interval(*result[k]["binder_index"], digits=3) if result[k]["binder_index"]
                                 else "1.45 (fixed)" for k in ("full", "far", "near"))))
        lines += ["### Goals", "",
                  (f"- Median |residual| <= {_pct(RESIDUAL_GOAL)} at {BODY_BANDS_NM[paint][0]:g}-"
                  f"{BODY_BANDS_NM[paint][1]:g} nm: **{'met' if residual_ok else 'NOT met'}** "
                  f"(worst {_pct(float(np.max(body_res))) if body_res.size else 'n/a'}, "
                  f"{int(np.sum(body_res <= RESIDUAL_GOAL))} of {body_res.size} bands within)."),
                  (f"- Subset intervals overlap at >= {_pct(OVERLAP_GOAL)} of bands, both runs mixed: "
                  f"**{'met' if overlap_verdict['met'] else 'NOT met'}** ({_overlap_goal_text(overlap_verdict)})."),
                  ""]
        # a(lambda) table
        check = full["check"]
        lines += ["### a(λ), noise floor, residuals and the model check (full fit)", "",
                  ("Residual: median |x_obs / x_fit - 1| over the fitted geometries (all > 2° from the mirror), "
                  "x_fit the posterior median of the noise-free BRDF" + (" less the incidence offset (the "
                  "predicted reading)" if settings.incidence_offset else "") + ". Model check: posterior predictive "
                  f"p-value of the chi-square (eps {EPS:g} and the floor; `bayespig.report.quantities."
                  "posterior_predictive_check`)."), ""]
        rows = []
        flake = full.get("flake_reflectance")
        offset = full.get("incidence_offset")
        plain = result.get("no_flakes")
        for i, w in enumerate(wl):
            rows.append([f"{w:g}", _interval(full["a"][0, i], full["a"][1, i], full["a"][2, i])]
                        + ([] if flake is None else [_interval(*flake[:, i], digits=4)])
                        + ([] if offset is None else [f"{offset[1, i]:.2e} [{offset[0, i]:.2e}, {offset[2, i]:.2e}]"])
                        + ["n/a" if full["noise_floor"] is None else f"{full['noise_floor'][i]:.2e}",
                           _pct(full["residual"][i])]
                        + ([] if plain is None else [_pct(plain["residual"][i]), _interval(*plain["a"][:, i])])
                        + [f"{check['p_value'][i]:.3g}", check["status"][i]])
        lines += [_table(["band [nm]", "a median [90 %]"] + ([] if flake is None else ["flake reflectance c"])
                         + ([] if offset is None else ["incidence offset b [1/sr]"])
                         + ["noise floor [1/sr]", "median residual"]
                         + ([] if plain is None else ["residual without flakes", "a without flakes"])
                         + ["p", "model check"], rows), ""]
        if plain is not None:
            lines += [("Without flakes (the same fit, the surface alone): roughness "
                       f"{_interval(*plain['roughness'], digits=4)}"
                       + ("" if plain["binder_index"] is None else
                          f", binder index {_interval(*plain['binder_index'], digits=4)}")
                       + f"; {plain['seconds']:.0f} s"
                       + ("; **max_steps reached**" if plain["max_steps_reached"] else "") + "."), ""]
        spectrum = f"cornell/{paint}_a.png"
        files[spectrum] = figs.to_png(_spectrum_figure(paint, result))
        lines += [f"![a(λ) of {paint}]({spectrum})", "",
                  ("a(λ): full rough fit (black), the two consistency subsets (blue, orange) and the smooth "
                  "model (red), medians and 90 % intervals."), ""]
        # distance classes
        gonio = full["gonio"]
        lines += ["Median |residual| by distance from the mirror (full fit):", "",
                  _table(["band [nm]"] + [f"{c} ({n})" for c, n in zip(gonio["classes"], gonio["count"])],
                         [[f"{w:g}"] + [_pct(v) for v in gonio["median_abs_by_class"][i]]
                          for i, w in enumerate(wl)]), ""]
        lines += _beyond_lobe_lines(result, wl)
        # figures from the report package
        geometry = gonio["geometry"]
        incidences = [t for t in FIGURE_INCIDENCES if np.any(np.isclose(geometry["theta_i"], t))]
        in_plane = [t for t in incidences
                    if np.any(np.isclose(geometry["theta_i"], t) & np.isfinite(geometry["signed_theta_o"]))]
        band_indices = [int(np.argmin(np.abs(wl - b))) for b in _present(wl, FIGURE_BANDS_NM)]
        if in_plane:
            path = f"cornell/{paint}_plane.png"
            files[path] = figs.to_png(figs.plane_of_incidence_figure(wl, gonio, band_indices, in_plane))
            lines += [f"![plane of incidence, {paint}]({path})", "",
                      "Measured BRDF (circles) and the rough fit (posterior median, line; 90 % band) in the plane "
                      "of incidence at " + ", ".join(f"{wl[i]:g}" for i in band_indices) + " nm (dotted: mirror).",
                      ""]
        if incidences:
            path = f"cornell/{paint}_residual_map.png"
            files[path] = figs.to_png(figs.residual_map_figure(gonio, incidences))
            lines += [f"![residual map, {paint}]({path})", "",
                      ("Relative residual (measured - fitted) / fitted, median over the bands, over viewing "
                      "directions (azimuth delta_phi from the source, radius theta_o); red: model too dark."), ""]
        # subset consistency
        far, near = result["far"], result["near"]
        lines += ["### Subset consistency", "",
                  f"Same model on the geometries > {SUBSET_SPLIT_DEG:g}° from the mirror ({counts['far']}) and on "
                  f"those {MIRROR_CUT_DEG:g}-{SUBSET_SPLIT_DEG:g}° from it ({counts['near']}), both with theta_i, "
                  f"theta_o <= {SUBSET_MAX_ANGLE_DEG:g}°. Roughness: far {_interval(*far['roughness'], digits=4)}, "
                  f"near {_interval(*near['roughness'], digits=4)}"
                  + ("" if far["binder_index"] is None else
                     f"; binder index: far {_interval(*far['binder_index'], digits=4)}, "
                     f"near {_interval(*near['binder_index'], digits=4)}")
                  + f"; runs {far['seconds']:.0f} s and "
                  f"{near['seconds']:.0f} s"
                  + ("; **max_steps reached**" if far["max_steps_reached"] or near["max_steps_reached"] else "")
                  + ".", ""]
        rows = []
        for k, w in enumerate(far["wavelength_nm"]):
            rows.append([f"{w:g}", _interval(*far["a"][[0, 1, 2], k]), _interval(*near["a"][[0, 1, 2], k]),
                         "yes" if overlap[k] else "**no**",
                         " / ".join("yes" if fit["a_mixed"][k] else "**no**" for fit in (far, near)),
                         _pct(far["residual"][k]), _pct(near["residual"][k])])
        lines += [(f"a mixed: R-hat(a) <= {q.RHAT_MAX:g} and bulk and tail ESS(a) >= {q.ESS_MIN:g} at that band "
                   "in the far / near run; where it is no, that run's interval is not a converged estimate, and "
                   "an overlap there may rest on chains that disagree."), "",
                  _table(["band [nm]", f"a, > {SUBSET_SPLIT_DEG:g}°", f"a, {MIRROR_CUT_DEG:g}-{SUBSET_SPLIT_DEG:g}°",
                          "90 % intervals overlap", "a mixed: far / near", "residual far", "residual near"], rows), ""]
        # smooth comparison
        lines += ["### Smooth surface (roughness 0) for comparison", "",
                  (f"Same full geometry set, bands {', '.join(f'{b:g}' for b in smooth['wavelength_nm'])} nm. "
                   "An inferred noise floor absorbs misfit as an inferred eps would: where the smooth model's "
                   "floor is far above the rough model's, its model check passes only because the floor "
                   "grew until the residuals fit, and its wide a intervals are that floor's."), ""]
        rows = []
        for k, w in enumerate(smooth["wavelength_nm"]):
            i = int(np.argmin(np.abs(wl - w)))
            rows.append([f"{w:g}", _interval(*smooth["a"][:, k]), _pct(smooth["residual"][k]),
                         f"{smooth['noise_floor'][k]:.2e}", f"{smooth['check']['p_value'][k]:.3g}",
                         _interval(*full["a"][:, i]), _pct(full["residual"][i]), f"{full['noise_floor'][i]:.2e}"])
        lines += [_table(["band [nm]", "a smooth", "residual smooth", "floor smooth [1/sr]", "p smooth", "a rough",
                          "residual rough", "floor rough [1/sr]"], rows), ""]
        # prior edges
        lines += ["### Prior-edge flags", ""]
        for key, label in (("full", "full fit"), ("far", "subset far"), ("near", "subset near"),
                           ("smooth", "smooth model")):
            edges = result[key]["edges"]
            lines += [f"- {label}: " + ("none" if not edges else "; ".join(e["text"] for e in edges))]
        lines += [""]
    summary = ["## Summary of the goals", "",
               _table(["paint", "body bands", "median residual there", "residual goal", "subset overlap",
                       "overlap goal", "roughness: full / far / near subset",
                       "binder index: full / far / near subset"],
                      [[n, f"{bw[0]:g}-{bw[-1]:g} nm" if bw.size else "none fitted",
                        ", ".join(_pct(v) for v in br) or "n/a", "met" if rok else "NOT met",
                        f"{_pct(ov['share'])} of {ov['bands']} bands with both runs mixed "
                        f"({_pct(ov['overlapping'] / ov['bands']) if ov['bands'] else 'n/a'} counting unmixed runs)",
                        "met" if ov["met"] else "NOT met", alphas, indices]
                       for n, bw, br, rok, ov, alphas, indices in goals]), "",
               ("The surface of the two subsets, each one GGX alpha (and binder index) for all bands, tells "
                "whether one microfacet surface describes the paint near and far from the mirror alike: where "
                "their intervals are apart, the surface model (not the pigment) is what the data reject, and "
                "the subsets' a(λ) need not agree either."), ""]
    head = lines[:lines.index(f"## {PAINTS.get(next(iter(study['paints'])), next(iter(study['paints'])))} "
                              f"(`{next(iter(study['paints']))}.astm`)")] if study["paints"] else lines
    text = "\n".join(head + summary + lines[len(head):]) + "\n"
    return text, files


def write_cornell_report(study, path="reports/cornell.md"):
    """Write the Markdown report and its PNG figures (``<folder>/cornell/``) as one atomic set.

    Returns
    -------
    pathlib.Path
        The report.
    """
    path = Path(path)
    text, files = cornell_report(study)
    prefix = path.stem
    renamed = {f"{prefix}/{name.split('/', 1)[1]}": content for name, content in files.items()}
    text = text.replace("](cornell/", f"]({prefix}/")
    written = write_file_set(path.parent, {**renamed, path.name: text})
    return written[path.name]
