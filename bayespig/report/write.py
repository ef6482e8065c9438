"""Write the uncertainty report of one pigment: HTML, Markdown, figures, CSV/JSON summary.

:func:`write_report` takes a posterior (arviz ``InferenceData`` from :func:`bayespig.infer`,
or its netCDF file) or measurements (a :class:`~bayespig.data.MeasurementSet` or a
measurement file, inferred first) and writes into ``out_dir``:

``report.html``
    Self-contained page, figures embedded as base64 PNG (opens offline).
``report.md`` and ``figures/*.png``
    The Markdown twin with its figures as files.
``summary.csv``
    One row per wavelength (:mod:`bayespig.report.summary_table`, the same table as
    ``bayespig infer``'s): posterior mean, sd, median, 50 % and 90 % central intervals of
    every parameter, ESS, R-hat, correlation of ``a`` with ``log tau``, point fit, the
    model check, flags.
``summary.json``
    The same numbers plus colour, fit quality and model check (the wavelengths the model
    cannot reproduce), the prior edges (``prior_edge``: parameters piled against a bound of
    their prior, :func:`~bayespig.report.quantities.prior_edges`), predicted films,
    diagnostics and provenance.

``fit_by_geometry.csv`` and ``colour_by_geometry.csv``
    Only for sets of more than :data:`~bayespig.report.quantities.GONIO_LARGE_GEOMETRIES` BRDF
    geometries (gonio measurements), whose report shows the fit in the plane of incidence, as a
    residual map over viewing directions and as residual statistics by distance from the
    mirror direction instead of a table row per geometry: every geometry's angles, distance
    from the mirror, residuals and colour.

A posterior of opaque films only (no ``tau``) gets the same report without what needs ``tau``
(its bands and columns, extinction, the ravine, films other than the opaque one), and says why
(:data:`OPAQUE_ONLY_TEXT`).
``posterior.nc``
    The posterior itself (netCDF), so the report's numbers can be recomputed.

The whole report is written into a fresh hidden folder beside ``out_dir`` and swapped into
place once every file exists, so ``out_dir`` holds one complete report -- never a mix with an
earlier one (no stale figures) -- and an error or Ctrl-C leaves it as it was. An existing
``out_dir`` is replaced only when it is empty or an earlier bayespig report
(:func:`check_report_folder`); anything else needs ``overwrite=True`` (``--overwrite``).
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import colorimetry
from .._atomic import write_folder_atomically
from .._json import jsonable as _jsonable
from . import document as doc
from . import figures as figs
from . import quantities as q
from . import summary_table

__all__ = ["NETCDF_SUFFIXES", "REPORT_FILES", "ReportResult", "check_report_folder", "load_posterior",
           "write_report"]

#: Wavelengths [nm] near which corner plots are drawn by default.
CORNER_WAVELENGTHS_NM = (450.0, 550.0, 650.0)
#: What the report says when every film is opaque (a posterior without ``tau``).
OPAQUE_ONLY_TEXT = (
    "Every measured film hides its substrate, so its reflectance depends on a (and g when free) "
    "only: the optical thickness tau is not identified by these measurements and is not a parameter "
    "- this report has no tau, no extinction and no ravine. To measure tau too, add a film that does "
    "not hide its substrate (e.g. the same paint on black: the paper's method 2).")
#: What the report says before the list of parameters at a bound of their prior.
PRIOR_EDGE_TEXT = (
    "Where a posterior is piled against a bound of its prior (its 5 % or 95 % quantile closer to the "
    "bound than a tenth of its 90 % interval), that side of its interval is the prior's cut, not the "
    "data's:")
#: Draws used for colour and predictions of unmeasured films (evenly thinned).
MAX_COLOUR_DRAWS = 400
#: Draws shown in corner plots and the ravine figure.
MAX_PLOT_DRAWS = 4000
#: What a report folder holds (``summary.json`` lists the files of a report written since).
REPORT_FILES = ("report.html", "report.md", "summary.csv", "summary.json", "posterior.nc", "figures")
#: File suffixes read as a posterior netCDF file (anything else is a measurement file).
NETCDF_SUFFIXES = (".nc", ".nc4", ".netcdf", ".h5")


@dataclass
class ReportResult:
    """What :func:`write_report` wrote.

    Attributes
    ----------
    out_dir : pathlib.Path
    files : dict
        Role (``"html"``, ``"markdown"``, ``"csv"``, ``"json"``, ``"netcdf"``, ``"figures"``)
        -> path (a list of paths for figures).
    summary : dict
        The content of ``summary.json``.
    seconds : float
        Time to compute and write the report (without inference) [s].
    replaced : bool
        Whether an earlier report (or, with ``overwrite``, another folder) was replaced.
    """

    out_dir: Path
    files: dict
    summary: dict
    seconds: float
    idata: object = field(default=None, repr=False)
    replaced: bool = False


# ------------------------------------------------------------------------------------------
# inputs


def _is_inference_data(obj):
    return hasattr(obj, "posterior") and hasattr(obj, "groups")


def _read_netcdf(path):
    try:
        from ..inference import load_inference
    except ImportError:  # inference layer not installed: plain arviz
        import arviz as az

        return az.from_netcdf(path)
    return load_inference(path)


def load_posterior(source, *, measurements=None, infer_kwargs=None, progress=False):
    """A posterior and its measurements from any accepted report input.

    Parameters
    ----------
    source : InferenceData, MeasurementSet, str or os.PathLike
        A posterior, its netCDF file (``.nc``), a measurement set or a measurement file
        (read by :func:`bayespig.read_measurements` and inferred with :func:`bayespig.infer`).
    measurements : MeasurementSet, str or os.PathLike, optional
        The measurements of a given posterior (for thickness, concentration, a synthetic
        truth and the pigment's name).
    infer_kwargs : dict, optional
        Passed to :func:`bayespig.infer` when measurements are given; ``eps_given_as`` (not
        passed on) names how the user gave ``eps`` for the report's text (default ``"eps="``).
    progress : bool
        Progress bars while inferring.

    Returns
    -------
    idata : arviz.InferenceData
    measurements : MeasurementSet or None
    inferred : bool
        Whether the posterior was computed here.
    """
    from ..data import MeasurementSet, read_measurements

    if isinstance(measurements, (str, os.PathLike)):
        measurements = read_measurements(measurements)
    if _is_inference_data(source):
        return source, measurements, False
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if not path.exists():
            raise ValueError(f"{path}: file not found")
        if path.suffix.lower() in NETCDF_SUFFIXES:
            try:
                idata = _read_netcdf(path)
            except (OSError, ValueError, KeyError) as error:
                raise ValueError(f"{path}: not a bayespig posterior netCDF file ({error})") from None
            if "posterior" not in idata.groups():
                raise ValueError(f"{path}: the netCDF file has no posterior group")
            return idata, measurements, False
        source = read_measurements(path)
    if isinstance(source, MeasurementSet):
        from ..inference import infer

        kwargs = {"progress": progress, **(infer_kwargs or {})}
        given_as = kwargs.pop("eps_given_as", "eps=")
        idata = infer(source, **kwargs)
        q.record_eps_source(idata, kwargs.get("eps"), source, given_as=given_as)
        return idata, source, True
    raise ValueError("write_report needs an InferenceData, a netCDF posterior, a MeasurementSet "
                     f"or a measurement file; got {type(source).__name__}")


def _truth(measurements, problem):
    """The synthetic truth recorded by :func:`bayespig.simulate`, or None."""
    if measurements is None:
        return None
    meta = dict(measurements.metadata or {})
    truth = meta.get("truth")
    if not isinstance(truth, dict) or "a" not in truth:
        return None
    a = np.asarray(truth["a"], dtype=float)
    taus = truth.get("tau") or {}
    group = problem.groups[0] if problem.groups else None
    tau = np.asarray(taus[group], dtype=float) if group in taus else None
    if a.shape != problem.wavelength_nm.shape or (tau is not None and tau.shape != a.shape):
        return None
    return {"a": a, "tau": tau, "g": truth.get("g")}


def _synthetic_label(measurements):
    if measurements is None:
        return None
    meta = dict(measurements.metadata or {})
    if meta.get("synthetic"):
        return str(meta.get("synthetic")) if not isinstance(meta["synthetic"], bool) else "synthetic"
    if meta.get("generator") == "bayespig.simulate":
        return "simulated with bayespig.simulate"
    return None


# ------------------------------------------------------------------------------------------
# helpers


def _nearest_indices(wl, targets):
    out = []
    for t in targets:
        i = int(np.argmin(np.abs(wl - t)))
        if i not in out:
            out.append(i)
    return out


def _fmt(x, digits=3):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "n/a"
    return f"{x:.{digits}g}"


def _interval(bands, i, digits=3):
    return (f"{_fmt(bands['median'][i], digits)} [{_fmt(bands['q05'][i], digits)}, "
            f"{_fmt(bands['q95'][i], digits)}]")


def _correlation(a, log_tau):
    """Pearson correlation of ``a`` and ``log tau`` per wavelength (draws on axis 0)."""
    da = a - a.mean(axis=0)
    dt = log_tau - log_tau.mean(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (da * dt).sum(axis=0) / np.sqrt((da * da).sum(axis=0) * (dt * dt).sum(axis=0))


def _zoom_limits(draws, lower, upper, log=False):
    x = np.log(draws) if log else draws
    lo, hi = np.quantile(x, [0.002, 0.998])
    pad = max(0.6 * (hi - lo), 1e-3 if not log else 0.02)
    lo, hi = lo - pad, hi + pad
    if log:
        return max(np.exp(lo), lower), min(np.exp(hi), upper)
    return max(lo, lower), min(hi, upper)


def _extinction(measurements, problem, tau_draws):
    """Extinction per film group with known thickness (and concentration), or {}."""
    if measurements is None or not problem.groups:
        return {}
    group = problem.groups[0]
    films = measurements.film_groups.get(group, ())
    thickness = next((f.thickness_um for f in films if f.thickness_um is not None), None)
    if thickness is None:
        return {}
    concentration = next((f.concentration for f in films if f.concentration is not None), None)
    values = q.extinction(tau_draws, thickness, concentration)
    return {"group": group, "thickness_um": thickness, "concentration": concentration,
            **{k: q.parameter_bands(v) for k, v in values.items()}}


# ------------------------------------------------------------------------------------------
# the report


def write_report(posterior_or_measurements, out_dir, *, measurements=None,
                 observer=colorimetry.DEFAULT_OBSERVER, illuminant=colorimetry.DEFAULT_ILLUMINANT,
                 title=None, corner_wavelengths=CORNER_WAVELENGTHS_NM, ravine_wavelength=None,
                 films=None, max_colour_draws=MAX_COLOUR_DRAWS, infer_kwargs=None,
                 progress=False, save_posterior=True, overwrite=False, extra_files=None):
    """Write the uncertainty report of one pigment.

    Parameters
    ----------
    posterior_or_measurements : InferenceData, MeasurementSet, str or os.PathLike
        A posterior from :func:`bayespig.infer` (or its netCDF file), or measurements
        (a set or a file), which are inferred first with :func:`bayespig.infer`.
    out_dir : str or os.PathLike
        Folder of the report: created if missing, replaced whole if it is empty or holds an
        earlier bayespig report; any other existing folder is refused (checked before any work)
        unless ``overwrite``.
    measurements : MeasurementSet, str or os.PathLike, optional
        The measurements of a given posterior: film thickness and concentration (for the
        extinction cross-section, appendix A2), a synthetic truth, the name of the source.
    observer, illuminant : str
        Colorimetric conditions (colour-science names); default CIE 1964 10° and D65.
    title : str, optional
        Report title (default from the measurement source).
    corner_wavelengths : sequence of float
        Corner plots at the wavelengths nearest these [nm].
    ravine_wavelength : float, optional
        Wavelength of the ravine figure [nm]; default the one with the widest ``log tau``
        posterior (where the landscape matters most).
    films : sequence of FilmDesign, optional
        Films to predict the colour of (default
        :func:`~bayespig.report.quantities.default_unmeasured_films`).
    max_colour_draws : int
        Posterior draws used for colour statistics and predicted films.
    infer_kwargs : dict, optional
        Passed to :func:`bayespig.infer` when inferring here.
    progress : bool
        Show progress while inferring and writing.
    save_posterior : bool
        Also write ``posterior.nc``.
    overwrite : bool
        Replace ``out_dir`` whole even when it is not a bayespig report.
    extra_files : dict, optional
        Further files of the report folder: relative path -> bytes, str or a callable that
        writes the file at the path it is given (e.g. ``{"measurements.csv": ms.to_csv}``).

    Returns
    -------
    ReportResult

    Raises
    ------
    ValueError
        For inputs that are not a posterior or measurements, bad colorimetric names, or an
        ``out_dir`` that may not be replaced (:func:`check_report_folder`).
    """
    out_dir = Path(out_dir)
    replacing = check_report_folder(out_dir, overwrite=overwrite)
    if observer not in colorimetry.OBSERVERS:
        raise ValueError(f"observer={observer!r} is not known to colour-science; valid names: "
                         + ", ".join(colorimetry.OBSERVERS))
    if illuminant not in colorimetry.ILLUMINANTS:
        raise ValueError(f"illuminant={illuminant!r} is not known to colour-science; valid names: "
                         + ", ".join(colorimetry.ILLUMINANTS))
    idata, measurements, _ = load_posterior(posterior_or_measurements, measurements=measurements,
                                            infer_kwargs=infer_kwargs, progress=progress)
    netcdf_source = None
    if isinstance(posterior_or_measurements, (str, os.PathLike)) and \
            Path(posterior_or_measurements).suffix.lower() in NETCDF_SUFFIXES:
        netcdf_source = Path(posterior_or_measurements)
    start = time.perf_counter()
    content = _build(idata, measurements, observer=observer, illuminant=illuminant, title=title,
                     corner_wavelengths=corner_wavelengths, ravine_wavelength=ravine_wavelength,
                     films=films, max_colour_draws=max_colour_draws, progress=progress)
    check_report_folder(out_dir, overwrite=overwrite)  # still so after the inference
    files = _write_files(out_dir, content, (netcdf_source or idata) if save_posterior else None,
                         extra_files or {})
    seconds = time.perf_counter() - start
    return ReportResult(out_dir, files, content["summary"], seconds, idata, replacing)


def _say(progress, message):
    if progress:
        print(f"  report: {message}", flush=True)


def _build(idata, measurements, *, observer, illuminant, title, corner_wavelengths,
           ravine_wavelength, films, max_colour_draws, progress):
    """Every number, figure and block of the report (nothing written yet)."""
    has_tau = "tau" in idata.posterior  # False: every film is opaque, tau is not a parameter
    wl = q.wavelengths(idata)
    problem = q.problem_from_inference(idata)
    priors = q.priors_from_inference(idata)
    prov = q.provenance(idata)
    truth = _truth(measurements, problem)
    synthetic = _synthetic_label(measurements)
    source = getattr(measurements, "source", None) if measurements is not None else None
    title = title or f"bayespig uncertainty report: {Path(str(source)).name if source else 'pigment'}"
    blocks, pngs, summary, extra = [], {}, {}, {}

    def add_figure(name, fig, caption):
        pngs[name] = figs.to_png(fig)
        blocks.append(doc.figure(name, caption))

    # ---- parameters
    _say(progress, "parameters")
    a = q.posterior_draws(idata, "a")
    tau = q.posterior_draws(idata, "tau") if has_tau else None
    bands = {"a": q.parameter_bands(a)}
    if has_tau:
        bands["tau"] = q.parameter_bands(tau)
    groups = list(problem.groups)
    if "tau_group" in idata.posterior and len(groups) > 1:
        tau_groups = q.posterior_draws(idata, "tau_group")
        for k, group in enumerate(groups):
            bands[f"tau[{group}]"] = q.parameter_bands(tau_groups[..., k])
    for name in ("g", "eps", "flake_reflectance"):
        if name in idata.posterior:
            draws = q.posterior_draws(idata, name)
            bands[name] = q.parameter_bands(draws.reshape(draws.shape[0], wl.size, -1)[..., 0])
    corr = _correlation(a, np.log(tau)) if has_tau else None
    constant = getattr(idata, "constant_data", None)
    point = {name: (np.asarray(constant[f"point_{name}"].values, dtype=float)
                    if constant is not None and f"point_{name}" in constant else np.full(wl.size, np.nan))
             for name in ("a", "tau")}
    extinction = _extinction(measurements, problem, tau) if has_tau else {}
    diag = q.diagnostics(idata, priors=priors)

    blocks.append(doc.heading(title, 1))
    intro = ("Posterior, per wavelength, of the relative absorption a = 1 - albedo"
             + (" and the optical thickness tau" if has_tau else "")
             + f"{' and the phase parameter g' if 'g' in bands else ''}: "
             f"{wl.size} wavelengths {wl[0]:g}-{wl[-1]:g} nm, from {len(problem.films)} measured "
             f"film spectra ({problem.n_values} values per wavelength), {prov.get('method', problem.method)}.")
    blocks.append(doc.paragraph(intro))
    if not has_tau:
        blocks.append(doc.paragraph(OPAQUE_ONLY_TEXT, lead="Opaque films only."))
    if synthetic:
        blocks.append(doc.paragraph(f"SYNTHETIC DATA - {synthetic}: the measurements were simulated; "
                                    "red lines and stars mark the true values."))
    film_lines = []
    for f in problem.films:
        substrate = "opaque" if f.opaque else f"r_s median {_fmt(float(np.median(f.r_s)))}"
        geometry = _geometry_text(f.instrument) if f.instrument else "specular transmittance"
        film_lines.append(f"{f.name} ({substrate}; {geometry})")
    eps_info = q.eps_origin(idata, measurements)
    eps_text = eps_info["text"]
    blocks.append(doc.bullets([
        f"Source: {source or 'posterior given directly'}",
        "Samples: " + ", ".join(film_lines),
        f"Noise model: x_obs = x_model (1 + eps xi), paper eq. 7; {eps_text}",
        f"Phase function: {_phase_text(idata, prov)}",
        f"Chains x draws: {diag['n_chains']} x {diag['n_draws']}; seed {prov.get('seed', 'n/a')}",
    ]))

    blocks.append(doc.heading("At a glance"))
    glance_idx = _nearest_indices(wl, CORNER_WAVELENGTHS_NM)
    rows = []
    for i in glance_idx:
        row = [f"{wl[i]:g}", _interval(bands["a"], i)]
        if has_tau:
            row += [_interval(bands["tau"], i), _fmt(corr[i], 2)]
        if "g" in bands:
            row.append(_interval(bands["g"], i))
        rows.append(row)
    header = ["wavelength [nm]", "a median [90 %]"]
    if has_tau:
        header += ["tau median [90 %]", "corr(a, log tau)"]
    if "g" in bands:
        header.append("g median [90 %]")
    blocks.append(doc.table(header, rows))
    flagged = [f for f in diag["flags"] if f["wavelength_nm"] is not None]
    blocks.append(doc.paragraph(
        f"Diagnostics: {len(flagged)} of {wl.size} wavelengths flagged"
        + (" (see Diagnostics below)." if flagged else " - every wavelength converged "
           f"(R-hat <= {diag['rhat_max']:g}, bulk ESS >= {diag['ess_min']:g}).")))
    check = q.posterior_predictive_check(idata)  # every draw: the p of summary.csv, as infer writes it
    value_rows = q.value_table(idata)
    misfit = _model_check_rows(wl, check, value_rows)
    untestable = np.flatnonzero(~check["testable"] & ~check["flagged"])
    untestable_text = ""
    if untestable.size:
        where = ("every wavelength" if untestable.size == wl.size else
                 f"{untestable.size} of {wl.size} wavelengths ({', '.join(f'{wl[i]:g}' for i in untestable)} nm)")
        untestable_text = (
            f"The model check cannot test anything at {where}: there are no more measured values "
            f"({int(check['n_values'][untestable[0]])}) than parameters "
            f"({int(check['n_parameters'][untestable[0]])}), so some parameters reproduce exactly any values "
            "the model can produce, and the check passes whatever the model misses"
            + ("; eps cannot be inferred from them either (its posterior there is its prior)"
               if "eps" in bands else "")
            + ". Not testable (n values <= n parameters): measure more geometries, replicates or another "
            "film to test the model.")
    if misfit:
        blocks.append(doc.paragraph(
            f"({', '.join(m['wavelength_nm_text'] for m in misfit)} nm; posterior predictive "
            f"p < {check['level']:g}). There the parameters are the best compromise of a model that does "
            "not fit, not a measurement of the pigment - see Fit quality." + (" " + untestable_text if untestable_text else ""),
            lead=f"Model check: the model cannot reproduce the measurements at {len(misfit)} of {wl.size} "
                 "wavelengths"))
    elif untestable.size == wl.size:
        blocks.append(doc.paragraph(untestable_text, lead="Model check: not testable."))
    else:
        blocks.append(doc.paragraph(
            "Model check: the model reproduces the measurements within their noise at every "
            + ("testable " if untestable.size else "") + "wavelength "
            f"(posterior predictive p >= {check['level']:g})." + (" " + untestable_text if untestable_text else "")))
    edges = q.prior_edges(idata)
    if edges:
        blocks.append(doc.paragraph(PRIOR_EDGE_TEXT, lead="Prior edge."))
        blocks.append(doc.bullets([edge["text"] + "." for edge in edges]))
    else:
        blocks.append(doc.paragraph("Prior edge: no posterior is piled against a bound of its prior."))
    colour_slot = len(blocks)  # the colour verdict goes here once computed

    blocks.append(doc.heading("Optical properties"))
    panels = [{"bands": bands["a"], "label": "a = 1 - albedo", "point": point["a"],
               "truth": truth["a"] if truth else None}]
    if has_tau:
        panels.append({"bands": bands["tau"], "label": "optical thickness tau", "point": point["tau"],
                       "truth": truth["tau"] if truth else None, "log": True})
    for group in groups[1:]:
        panels.append({"bands": bands[f"tau[{group}]"], "label": f"tau [{group}]", "log": True})
    if "g" in bands:
        g_truth = truth.get("g") if truth else None
        panels.append({"bands": bands["g"], "label": "HG parameter g",
                       "truth": None if g_truth is None else np.full(wl.size, float(g_truth))})
    if "eps" in bands:
        panels.append({"bands": bands["eps"], "label": "relative error eps", "log": True})
    if "flake_reflectance" in bands:
        panels.append({"bands": bands["flake_reflectance"], "label": "flake reflectance c", "log": True})
    add_figure("parameters", figs.parameter_figure(wl, panels),
               "Posterior median (line) with 50 % and 90 % central intervals (bands); + point fit"
               + (" (at g = 0, the start of the sampler)" if "g" in bands else "")
               + ("; red line with stars: truth of the synthetic pigment" if truth else "") + "."
               + (f" tau is the optical thickness of film group '{groups[0] if groups else 'n/a'}'." if has_tau
                  else " Every film is opaque: no tau."))
    factors = q.card_factors(idata)
    if factors:
        blocks.append(doc.paragraph(
            "Substrate albedo as a nuisance parameter (paper section 3.4): every card's albedo seen from "
            "the binder is r_s = f r_s,card with one factor f per card at all wavelengths, log f normal "
            f"with sd {factors[0]['relative_sd']:g} a priori; the posterior is joint over the wavelengths, "
            "so the card's uncertainty is in every band above. A factor whose interval is the prior's is "
            "not identified by these measurements."))
        blocks.append(doc.table(["card", "f median [90 %]"],
                                [[f["card"], f"{f['median']:.3f} [{f['low']:.3f}, {f['high']:.3f}]"]
                                 for f in factors]))
    surface = q.surface_parameters(idata)
    if surface:
        blocks.append(doc.paragraph(
            "Parameters of the films' surface, one value at every wavelength (inferred jointly with every "
            "band's parameters; their uncertainty is in every band above)."))
        blocks.append(doc.table(["parameter", "median [90 %]", "prior"],
                                [[p["long_name"], f"{p['median']:.4g} [{p['low']:.4g}, {p['high']:.4g}]", p["prior"]]
                                 for p in surface]))
    if extinction:
        unit = "1/um"
        text = (f"Film group '{extinction['group']}' has a known dry thickness H = "
                f"{extinction['thickness_um']:g} um, so k_ext = tau / H [{unit}]")
        if "sigma_ext" in extinction:
            text += (f"; with concentration D = {extinction['concentration']:g} (appendix A2, up to "
                     "the particle-mass scale) the extinction cross-section sigma_ext = tau / (H D).")
        blocks.append(doc.paragraph(text + "."))
        ext_panels = [{"bands": extinction["k_ext"], "label": "k_ext [1/um]", "log": True}]
        if "sigma_ext" in extinction:
            ext_panels.append({"bands": extinction["sigma_ext"], "label": "sigma_ext [1/um per unit D]",
                               "log": True})
        add_figure("extinction", figs.parameter_figure(wl, ext_panels),
                   "Extinction coefficient (and cross-section) with 50 % and 90 % intervals (appendix A2).")
    if has_tau:
        header = ["wavelength [nm]", "a median", "a 5 %", "a 95 %", "tau median", "tau 5 %", "tau 95 %",
                  "corr(a, log tau)", "point a", "point tau"]
        rows = [[f"{w:g}", _fmt(bands["a"]["median"][i]), _fmt(bands["a"]["q05"][i]), _fmt(bands["a"]["q95"][i]),
                 _fmt(bands["tau"]["median"][i]), _fmt(bands["tau"]["q05"][i]), _fmt(bands["tau"]["q95"][i]),
                 _fmt(corr[i], 2), _fmt(point["a"][i]), _fmt(point["tau"][i])] for i, w in enumerate(wl)]
    else:
        header = ["wavelength [nm]", "a median", "a 5 %", "a 95 %", "point a"]
        rows = [[f"{w:g}", _fmt(bands["a"]["median"][i]), _fmt(bands["a"]["q05"][i]), _fmt(bands["a"]["q95"][i]),
                 _fmt(point["a"][i])] for i, w in enumerate(wl)]
    blocks.append(doc.table(header, rows))

    # ---- posterior shape: corner plots and the ravine
    _say(progress, "corner plots and ravine")
    blocks.append(doc.heading("Posterior shape"))
    blocks.append(doc.paragraph(
        ("Corner plots show the joint posterior at single wavelengths: a long, tilted cloud means "
         "the data constrain a combination of parameters better than each one - the paper's "
         "'ravine'. " if has_tau else
         "Corner plots show the posterior of the parameters that exist at single wavelengths (every film "
         "is opaque: no tau, so no ravine). ")
        + "Blue lines: point fit (least squares, the paper's procedure); black dashes: the 5 %, "
        "50 % and 95 % quantiles; red lines and star: the truth of a synthetic pigment; contours at "
        "50 % and 90 %; titles give the median and the 5 %/95 % quantiles."))
    a_plot = q.posterior_draws(idata, "a", MAX_PLOT_DRAWS)
    tau_plot = q.posterior_draws(idata, "tau", MAX_PLOT_DRAWS) if has_tau else None
    columns = [(a_plot, "a")] + ([(np.log10(tau_plot), "log10 tau")] if has_tau else [])
    if len(groups) > 1:
        tg = q.posterior_draws(idata, "tau_group", MAX_PLOT_DRAWS)
        columns += [(np.log10(tg[..., k]), f"log10 tau[{g}]") for k, g in enumerate(groups) if k > 0]
    for name in ("g", "eps"):
        if name in idata.posterior:
            d = q.posterior_draws(idata, name, MAX_PLOT_DRAWS)
            d = d.reshape(d.shape[0], wl.size, -1)[..., 0]
            columns.append((np.log10(d) if name == "eps" else d, "log10 eps" if name == "eps" else "g"))
    for i in _nearest_indices(wl, corner_wavelengths or ()):
        samples = np.column_stack([c[0][:, i] for c in columns])
        labels = [c[1] for c in columns]
        first = [point["a"][i]] + ([np.log10(point["tau"][i])] if has_tau else [])
        pt = first + [None] * (len(columns) - len(first))
        tr = None
        if truth and (truth["tau"] is not None or not has_tau):
            first = [truth["a"][i]] + ([np.log10(truth["tau"][i])] if has_tau else [])
            tr = first + [None] * (len(columns) - len(first))
            if "g" in labels and truth.get("g") is not None:
                tr[labels.index("g")] = float(truth["g"])
        add_figure(f"corner_{wl[i]:g}nm",
                   figs.corner_figure(samples, labels, point=pt, truth=tr, title=f"{wl[i]:g} nm"),
                   f"Joint posterior at {wl[i]:g} nm" + (" (red: truth)" if tr else "") + ".")

    r_index = None
    if not has_tau:
        blocks.append(doc.paragraph(
            "No ravine figure: it shows the log-likelihood over (a, tau), and every film here is opaque, "
            "so tau is not a parameter."))
    else:
        sd_log_tau = np.log(tau).std(axis=0)
        r_index = (int(np.argmax(sd_log_tau)) if ravine_wavelength is None
                   else _nearest_indices(wl, [ravine_wavelength])[0])
        from ..likelihood import ForwardModel

        model = ForwardModel(problem, "free" if "g" in idata.posterior else "isotropic")
        wide = q.ravine(idata, r_index, problem=problem, model=model, n_grid=151)
        zoom = q.ravine(idata, r_index, problem=problem, model=model, n_grid=121,
                        a_limits=_zoom_limits(a_plot[:, r_index], *priors.a_range),
                        tau_limits=_zoom_limits(tau_plot[:, r_index], *priors.tau_range, log=True))
        held = ", ".join(f"{k} = {v:.3g}" for k, v in wide.held.items())
        blocks.append(doc.paragraph(
            "The ravine: the log-likelihood (eq. 7) over (a, tau) at one wavelength, with posterior "
            "draws over it. Where the measurements cannot separate absorption from thickness the "
            "high-likelihood region is a long curved valley and the posterior follows it; a compact "
            "island means both are identified. White contours: 1, 2, 3 sigma of a 2-D Gaussian "
            "(Delta log L = -1.15, -3.09, -5.91)."
            + (f" Held at posterior medians: {held}." if held else "")))
        rt = (truth["a"][r_index], truth["tau"][r_index]) if truth and truth["tau"] is not None else None
        add_figure("ravine", figs.ravine_figure(wide, zoom, a_plot[:, r_index], tau_plot[:, r_index],
                                                point=(point["a"][r_index], point["tau"][r_index]), truth=rt),
                   f"Log-likelihood landscape at {wl[r_index]:g} nm"
                   + (" (the widest tau posterior of the spectrum)" if ravine_wavelength is None else "")
                   + "; left the whole prior box, right a zoom on the posterior.")

    # ---- fit quality
    _say(progress, "fit quality")
    blocks.append(doc.heading("Fit quality"))
    residuals = q.residuals_in_eps(idata, max_draws=max_colour_draws)
    samples_measured = list(dict.fromkeys(r["sample"] for r in residuals["rows"]))
    large_gonio = q.is_large_gonio_set(residuals["rows"])
    fit_rows = []
    for k, r in enumerate(residuals["rows"]):
        z = residuals["z"][:, k]
        fit_rows.append({"sample": r["sample"], "channel": r["channel"],
                         "rms_z": float(np.sqrt(np.nanmean(z * z))), "max_abs_z": float(np.nanmax(np.abs(z)))})
    gonio_summary, mirror_class = None, {}
    if large_gonio:
        gonio_summary, mirror_class = _gonio_fit_blocks(wl, residuals, fit_rows, blocks, add_figure, extra)
    else:
        add_figure("fit", figs.fit_figure(wl, residuals, samples_measured,
                                          [q.measurement_kind(r) for r in residuals["rows"]]),
                   "Measured values (dots) and the posterior predictive (noise-free model) mean and 90 % "
                   "band (lines), per sample and geometry.")
        add_figure("residuals", figs.residual_figure(wl, residuals, samples_measured),
                   "Residuals in units of the relative error eps: (measured - predicted) / (eps predicted). "
                   "Under the noise model (eq. 7) they scatter like a standard normal; grey bands at "
                   "+-1, 2, 3.")
        blocks.append(doc.table(["sample", "geometry", "rms residual [eps]", "max |residual| [eps]"],
                                [[f["sample"], f["channel"], _fmt(f["rms_z"]), _fmt(f["max_abs_z"])]
                                 for f in fit_rows]))
    inferred_eps = "eps" in idata.posterior
    blocks.append(doc.paragraph(
        "Posterior predictive check per wavelength: the discrepancy is the chi-square of the noise model, "
        "T = sum over the wavelength's values of ((measured - model) / (eps model))^2; replicated "
        "measurements make it chi-square with as many degrees of freedom as values, and p is the "
        "posterior probability that a replicate is at least as discrepant as the measurement (Gelman, "
        f"Meng & Stern 1996). Below p = {check['level']:g} no plausible parameters reproduce the values "
        "within their noise: a term the model lacks, a wrong eps or substrate, or samples that are not the "
        "same paint. The check is conservative (the parameters were fitted to these values)"
        + ("; eps was inferred and grows to absorb misfit, so read its posterior too." if inferred_eps
           else ".")))
    if misfit:
        blocks.append(doc.table(
            ["wavelength [nm]", "p", "T / values", "worst value", "its residual [eps]"],
            [[m["wavelength_nm_text"], f"{m['p_value']:.2g}", f"{m['chi2']:.3g} / {m['n_values']}",
              f"{m['sample']} {m['channel']}", f"{m['z']:+.3g}"] for m in misfit]))
    else:
        blocks.append(doc.paragraph("No wavelength flagged."))

    # ---- colour
    _say(progress, "colour")
    blocks.append(doc.heading("Colour"))
    available, why = q.colour_available(wl)
    colour_summary = {"available": available}
    if not available:
        blocks.append(doc.paragraph(f"No colour: {why}."))
        colour_summary["reason"] = why
    else:
        conditions = colorimetry.colorimetric_metadata(wl, observer=observer, illuminant=illuminant)
        colour_summary["conditions"] = conditions
        blocks.append(doc.paragraph(
            f"CIELAB under {conditions['illuminant']} for the {conditions['observer']} "
            f"(tristimulus weights: {conditions['method']}, colour-science "
            f"{conditions['colour_science_version']}); the white is the perfect reflecting "
            "diffuser. A BRDF f [1/sr] is taken as the reflectance factor pi f at its geometry "
            "(the surface's specular reflection is not part of the model). Delta E00 is CIEDE2000. "
            f"Spread: the {int(q.SPREAD_QUANTILE * 100)}th percentile of Delta E00 between the colour "
            "of posterior draws and the posterior-mean colour - below "
            f"{q.COLOUR_MATCH_DELTA_E:g} the pigment data are good enough for colour matching."))
        measured = q.measured_colour(idata, observer=observer, illuminant=illuminant,
                                     max_draws=max_colour_draws, residuals=residuals)
        blocks.append(doc.heading("Measured samples", 3))
        if large_gonio:
            _gonio_colour_blocks(measured, mirror_class, blocks, extra)
        else:
            blocks.append(doc.table(
                ["sample", "geometry", "L* a* b* measured", "L* a* b* predicted", "dE00 meas-pred",
                 "dE00 spread (95 %)"],
                [[m["sample"], m["channel"], _lab(m["Lab_measured"]), _lab(m["Lab_predicted"]),
                  _fmt(m["dE00_measured_predicted"], 2), _fmt(m["dE00_spread"], 2)] for m in measured]))
            add_figure("colour_measured", figs.swatch_figure(
                [{"label": f"{m['sample']} {m['channel']}", "colours": [m["sRGB_measured"], m["sRGB_predicted"]],
                  "text": f"dE00 {m['dE00_measured_predicted']:.2f}, spread {m['dE00_spread']:.2f}"}
                 for m in measured], title="measured (left) and predicted (right), sRGB for display"),
                "Colour of every measured sample and geometry: measured and predicted (posterior mean).")
        films = list(films) if films is not None else q.default_unmeasured_films(problem)
        predicted = q.film_colour(idata, films, observer=observer, illuminant=illuminant,
                                  max_draws=max_colour_draws,
                                  instrument=_colour_instrument(problem) if large_gonio else None)
        blocks.append(doc.heading("Predicted films", 3))
        instrument_labels = list(dict.fromkeys(p["channel"] for p in predicted))
        if large_gonio:
            blocks.append(doc.paragraph(
                f"Predicted at {len(instrument_labels)} of the measured geometries (in the plane of incidence, "
                "nearest 45° incidence, at aspecular angles near "
                + ", ".join(f"{a:g}" for a in GONIO_COLOUR_ASPECULARS_DEG) + "°)."))
        if has_tau:
            blocks.append(doc.paragraph(
                "Colour of films made with this pigment that were not measured, predicted from the "
                f"posterior through the forward model at the geometries {', '.join(instrument_labels)}; "
                "'x tau' scales the optical thickness of film group "
                f"'{groups[0] if groups else 'n/a'}' (a thicker or thinner drawdown at the same "
                "concentration), black and white substrates have r_s = 0.01 and 0.95."))
        else:
            blocks.append(doc.paragraph(
                "The colour of the opaque (hiding) film, predicted from the posterior through the forward "
                f"model at the geometries {', '.join(instrument_labels)}. Films that do not hide their "
                "substrate cannot be predicted: tau is not known."))
        blocks.append(doc.table(
            ["film", "geometry", "L* a* b*", "dE00 spread (95 %)"],
            [[p["film"] + (" (measured)" if p["measured"] else ""), p["channel"], _lab(p["Lab"]),
              _fmt(p["dE00_spread"], 2)] for p in predicted]))
        per_film = {}
        for p in predicted:
            per_film.setdefault(p["film"], []).append(p)
        add_figure("colour_predicted", figs.swatch_figure(
            [{"label": film, "colours": [p["sRGB"] for p in ps],
              "text": f"max spread {max(p['dE00_spread'] for p in ps):.2f}"} for film, ps in per_film.items()],
            title="predicted films, one swatch per geometry: " + ", ".join(instrument_labels)),
            ("Predicted colour of unmeasured films" if has_tau else "Predicted colour of the opaque film")
            + " (posterior mean), one swatch per geometry.")
        spreads = [m["dE00_spread"] for m in measured] + [p["dE00_spread"] for p in predicted]
        worst_measured = max((m["dE00_spread"] for m in measured), default=np.nan)
        verdict = bool(worst_measured < q.COLOUR_MATCH_DELTA_E)
        colour_summary.update({"measured": measured, "predicted_films": predicted,
                               "max_dE00_spread_measured": worst_measured,
                               "max_dE00_spread_all": max(spreads) if spreads else None,
                               "good_enough_for_colour_matching": verdict})
        colour_summary["verdict_assumes_eps"] = eps_info["assumed"]
        spread_text = (f"Colour: the posterior spread of the predicted colour of the measured samples is at most "
                       f"Delta E00 = {worst_measured:.2f} (95th percentile) - ")
        if eps_info["assumed"]:
            spread_text += (
                ("good enough for colour matching (< 1)" if verdict else "NOT good enough for colour matching (>= 1)")
                + f" if eps really is {eps_info['value']:g}, which was only assumed ({eps_info['why']}). "
                "The spread grows with eps: measure replicates to know your instrument's eps and pass --eps "
                "before judging.")
        else:
            spread_text += ("good enough for colour matching (< 1)." if verdict else
                            "NOT good enough for colour matching (>= 1): measure more samples or geometries.")
        blocks.insert(colour_slot, doc.paragraph(spread_text))

    # ---- diagnostics and provenance
    _say(progress, "diagnostics")
    blocks.append(doc.heading("Diagnostics"))
    add_figure("diagnostics", figs.diagnostics_figure(wl, diag),
               f"Bulk effective sample size and rank-normalised R-hat (arviz) per wavelength; "
               f"flags below ESS {diag['ess_min']:g} or above R-hat {diag['rhat_max']:g}.")
    if diag["flags"]:
        blocks.append(doc.bullets([(f"{f['wavelength_nm']:g} nm: " if f["wavelength_nm"] is not None else "")
                                   + "; ".join(f["reasons"]) for f in diag["flags"]]))
    else:
        blocks.append(doc.paragraph("No wavelength flagged."))

    blocks.append(doc.heading("Priors, settings and provenance"))
    blocks.append(doc.bullets([f"{k}: {v}" if k != "tau" or has_tau else
                               "tau: not a parameter (every film is opaque)" for k, v in priors.describe().items()]))
    prov_text = json.dumps(_jsonable(_shown_provenance(prov)), indent=2, sort_keys=True, default=str)
    blocks.append(doc.preformatted(prov_text))
    created = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    from .._versions import __version__

    blocks.append(doc.paragraph(f"Report written {created} by bayespig {__version__}."))

    summary = {
        "title": title, "synthetic": synthetic, "created": created, "source": str(source) if source else None,
        "wavelength_nm": wl, "method": prov.get("method", problem.method),
        "parameters": bands, "correlation_a_log_tau": corr, "point_fit": point,
        "truth": truth, "extinction": extinction,
        "diagnostics": {k: diag[k] for k in ("ess", "rhat", "flags", "n_chains", "n_draws", "rhat_max", "ess_min")},
        "fit_quality": fit_rows,
        "gonio_residuals": gonio_summary,
        "model_check": {"level": check["level"], "p_value": check["p_value"], "misfit": misfit},
        "prior_edge": edges,
        "substrate_factors": factors,
        "colour": colour_summary, "priors": priors.describe(),
        "ravine_wavelength_nm": None if r_index is None else float(wl[r_index]), "provenance": prov,
    }
    csv_text = summary_table.summary_csv(idata, measurements=measurements, check=check, diagnostics=diag,
                                         edges=edges)
    return {"blocks": blocks, "figures": pngs, "summary": _jsonable(summary), "csv": csv_text,
            "title": title, "extra": extra}


#: Incidence angles shown in the gonio figures (spread over those measured), at most.
GONIO_MAX_INCIDENCES = 6
#: Bands shown in the plane-of-incidence figure (spread over the spectrum), at most.
GONIO_PLANE_BANDS = 3
#: Viewing directions of the predicted films' colour for large gonio sets: aspecular angles
#: [deg] in the plane of incidence at the measured incidence nearest 45 deg.
GONIO_COLOUR_ASPECULARS_DEG = (15.0, 45.0, 110.0)
#: What the report says of a large gonio set before its summary.
GONIO_LARGE_TEXT = (
    "Relative residual (measured - fitted) / fitted, with fitted the posterior median of the noise-free "
    "model; median of its magnitude over the BRDF geometries of each class of angular distance from the "
    "mirror direction (the angle between the viewing direction and the mirror image of the source).")


def _geometry_text(instrument):
    """The geometries of a measured film in words (a count and incidences for large gonio sets)."""
    labels = instrument.labels
    brdf = [ch for ch in instrument.channels if ch.kind == "brdf"]
    if len(brdf) <= q.GONIO_LARGE_GEOMETRIES:
        return ", ".join(labels)
    incidences = ", ".join(f"{t:g}" for t in np.unique([ch.theta_i for ch in brdf]))
    text = f"{len(brdf)} BRDF geometries at incidence {incidences}°"
    others = [ch.label for ch in instrument.channels if ch.kind != "brdf"]
    return text + (" and " + ", ".join(others) if others else "")


def _csv_text(header, rows):
    import csv
    import io

    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return buffer.getvalue()


def _percent(x):
    return "n/a" if x is None or not np.isfinite(x) else f"{100.0 * x:.1f} %"


def _gonio_fit_blocks(wl, residuals, fit_rows, blocks, add_figure, extra):
    """Fit quality of a large gonio set: plane-of-incidence figure, residual map, statistics."""
    gonio = q.gonio_residual_summary(residuals)
    geometry = gonio["geometry"]
    in_plane = np.isfinite(geometry["signed_theta_o"])
    incidences = q.spread_values(geometry["theta_i"][in_plane] if in_plane.any() else geometry["theta_i"],
                              GONIO_MAX_INCIDENCES)
    band_indices = sorted(set(np.linspace(0, wl.size - 1, min(GONIO_PLANE_BANDS, wl.size)).round().astype(int)))
    n = geometry["index"].size
    blocks.append(doc.paragraph(
        f"{n} BRDF geometries: too many to list, so the fit is shown in the plane of incidence, as a map over "
        "viewing directions and as statistics by distance from the mirror; every geometry's residuals are "
        "in fit_by_geometry.csv."))
    if in_plane.any():
        add_figure("fit_plane", figs.plane_of_incidence_figure(wl, gonio, band_indices, list(incidences)),
                   "Measured BRDF (circles) and the fit (posterior median of the noise-free model, line, with its "
                   "90 % band) in the plane of incidence against the signed viewing angle (+ on the specular "
                   "side, delta_phi = 180°; - on the source side, delta_phi = 0°), at "
                   + ", ".join(f"{wl[i]:g}" for i in band_indices) + " nm; dotted: the mirror direction.")
    map_incidences = q.spread_values(geometry["theta_i"], GONIO_MAX_INCIDENCES)
    add_figure("residual_map", figs.residual_map_figure(gonio, list(map_incidences)),
               "Relative residual (measured - fitted) / fitted, median over the bands, at every viewing "
               "direction (polar angle: azimuth delta_phi from the source, 180° = specular side; radius: "
               "viewing angle theta_o); red: the model is too dark, blue: too bright; star: the mirror "
               "direction.")
    blocks.append(doc.heading("Residuals by distance from the mirror", 3))
    blocks.append(doc.paragraph(GONIO_LARGE_TEXT))
    header = ["wavelength [nm]", f"all ({n} geometries)"] + [
        f"{label} ({count} geometries)" for label, count in zip(gonio["classes"], gonio["count"])]
    blocks.append(doc.table(header, [
        [f"{w:g}", _percent(gonio["median_abs_all"][i])] + [_percent(v) for v in gonio["median_abs_by_class"][i]]
        for i, w in enumerate(wl)]))
    index = geometry["index"]
    classes = q.mirror_distance_class(geometry["mirror_distance_deg"])
    rows = []
    for j, k in enumerate(index):
        rows.append([fit_rows[k]["sample"], fit_rows[k]["channel"], f"{geometry['theta_i'][j]:g}",
                     f"{geometry['theta_o'][j]:g}", f"{geometry['delta_phi'][j]:g}",
                     f"{geometry['mirror_distance_deg'][j]:.4f}", classes[j],
                     f"{np.nanmedian(np.abs(gonio['relative'][:, j])):.4g}",
                     f"{fit_rows[k]['rms_z']:.4g}", f"{fit_rows[k]['max_abs_z']:.4g}"])
    extra["fit_by_geometry.csv"] = _csv_text(
        ["sample", "geometry", "theta_i_deg", "theta_o_deg", "delta_phi_deg", "mirror_distance_deg",
         "mirror_distance_class", "median_abs_relative_residual", "rms_residual_eps", "max_abs_residual_eps"],
        rows)
    class_of = {(fit_rows[k]["sample"], fit_rows[k]["channel"]): classes[j] for j, k in enumerate(index)}
    return {"classes": gonio["classes"], "count": gonio["count"], "median_abs_all": gonio["median_abs_all"],
            "median_abs_by_class": gonio["median_abs_by_class"], "incidences_deg": list(incidences),
            "bands_nm": [float(wl[i]) for i in band_indices]}, class_of


def _gonio_colour_blocks(measured, class_of, blocks, extra):
    """The measured colour of a large gonio set: statistics by distance from the mirror, CSV per geometry."""
    labels = q.mirror_distance_labels()
    rows = []
    for label in labels + ["other geometries"]:
        members = [m for m in measured if class_of.get((m["sample"], m["channel"]), "other geometries") == label]
        if not members:
            continue
        delta = np.array([m["dE00_measured_predicted"] for m in members], dtype=float)
        spread = np.array([m["dE00_spread"] for m in members], dtype=float)
        rows.append([label, str(len(members)), _fmt(float(np.median(delta)), 2), _fmt(float(delta.max()), 2),
                     _fmt(float(spread.max()), 2)])
    blocks.append(doc.paragraph(
        f"{len(measured)} measured geometries, summarised by distance from the mirror direction; every "
        "geometry's colour is in colour_by_geometry.csv."))
    blocks.append(doc.table(["distance from the mirror", "geometries", "median dE00 meas-pred",
                             "max dE00 meas-pred", "max dE00 spread (95 %)"], rows))
    extra["colour_by_geometry.csv"] = _csv_text(
        ["sample", "geometry", "mirror_distance_class", "L_measured", "a_measured", "b_measured", "L_predicted",
         "a_predicted", "b_predicted", "dE00_measured_predicted", "dE00_spread"],
        [[m["sample"], m["channel"], class_of.get((m["sample"], m["channel"]), "")]
         + [f"{v:.4g}" for v in np.asarray(m["Lab_measured"]).ravel()]
         + [f"{v:.4g}" for v in np.asarray(m["Lab_predicted"]).ravel()]
         + [f"{m['dE00_measured_predicted']:.4g}", f"{m['dE00_spread']:.4g}"] for m in measured])


def _colour_instrument(problem):
    """A few in-plane channels of the measured gonio instrument for the predicted films' colour."""
    from ..instruments import Instrument
    from ..selection import mirror_distance_deg

    reference = next(f.instrument for f in problem.films if f.instrument is not None)
    channels = [ch for ch in reference.channels if ch.kind == "brdf"]
    theta_i = min({ch.theta_i for ch in channels}, key=lambda t: abs(t - 45.0))
    candidates = [ch for ch in channels if ch.theta_i == theta_i]
    in_plane = [ch for ch in candidates if np.isclose(np.mod(ch.delta_phi, 180.0), 0.0)
                or np.isclose(np.mod(ch.delta_phi, 180.0), 180.0)]
    candidates = in_plane or candidates
    distance = mirror_distance_deg([ch.theta_i for ch in candidates], [ch.theta_o for ch in candidates],
                                   [ch.delta_phi for ch in candidates])
    chosen = []
    for target in GONIO_COLOUR_ASPECULARS_DEG:
        k = int(np.argmin(np.abs(distance - target)))
        if candidates[k] not in chosen:
            chosen.append(candidates[k])
    return Instrument(f"{reference.name} (a few geometries)", tuple(chosen), reference.n)


def _shown_provenance(prov):
    """The provenance as the report prints it: an instrument of more than
    :data:`~bayespig.report.quantities.GONIO_LARGE_GEOMETRIES` geometries as their count
    (``summary.json`` and ``posterior.nc`` keep every label)."""
    instruments = prov.get("instruments")
    if not isinstance(instruments, dict):
        return prov
    shown = {}
    for name, labels in instruments.items():
        if isinstance(labels, (list, tuple)) and len(labels) > q.GONIO_LARGE_GEOMETRIES:
            shown[name] = f"{len(labels)} geometries (listed in summary.json and fit_by_geometry.csv)"
        else:
            shown[name] = labels
    return {**prov, "instruments": shown}


def _phase_text(idata, prov):
    """How the report's posterior treats the Henyey-Greenstein ``g``, in words."""
    if "g" in idata.posterior:
        return "Henyey-Greenstein g is a parameter at every wavelength (inferred, see below)"
    g = prov.get("g", "isotropic")
    if g in (None, "isotropic", 0, 0.0):
        return ("g = 0 fixed (isotropic scattering; not inferred - bayespig infer --g free makes it a "
                "parameter)")
    try:
        return f"Henyey-Greenstein g = {float(g):g} fixed (not inferred)"
    except (TypeError, ValueError):
        return f"g: {g}"


def _lab(lab):
    return " ".join(f"{v:.2f}" for v in np.asarray(lab).ravel())


def _model_check_rows(wl, check, value_rows):
    """The wavelengths flagged by the posterior predictive check, with their worst value."""
    rows = []
    for i in np.flatnonzero(check["flagged"]):
        k = int(check["worst"][i])
        rows.append({"wavelength_nm": float(wl[i]), "wavelength_nm_text": f"{wl[i]:g}",
                     "p_value": float(check["p_value"][i]), "chi2": float(check["chi2"][i]),
                     "n_values": int(check["n_values"][i]), "sample": value_rows[k]["sample"],
                     "channel": value_rows[k]["channel"], "z": float(check["z"][i, k])})
    return rows


def _write_files(out_dir, content, idata, extra_files):
    """Write the whole report into a fresh folder beside ``out_dir``, then swap it into place."""
    contents = {f"figures/{name}.png": png for name, png in content["figures"].items()}
    if idata is not None:
        contents["posterior.nc"] = lambda path: _save_netcdf(idata, path)
    contents.update(content.get("extra", {}))
    contents.update(extra_files)
    contents["summary.csv"] = content["csv"]
    summary = dict(content["summary"])
    summary["files"] = sorted(set(contents) | {"summary.json", "report.md", "report.html"})
    contents["summary.json"] = json.dumps(summary, indent=1, allow_nan=False, default=str) + "\n"
    contents["report.md"] = doc.to_markdown(content["blocks"])
    contents["report.html"] = doc.to_html(content["blocks"], content["figures"], content["title"])
    write_folder_atomically(out_dir, contents)
    content["summary"]["files"] = summary["files"]
    files = {"figures": [out_dir / f"figures/{name}.png" for name in content["figures"]]}
    for role, name in (("netcdf", "posterior.nc"), ("csv", "summary.csv"), ("json", "summary.json"),
                       ("markdown", "report.md"), ("html", "report.html")):
        if name in contents:
            files[role] = out_dir / name
    return files


def _is_report_folder(folder, entries):
    """Whether ``folder`` holds an earlier bayespig report and nothing else."""
    try:
        summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    if not isinstance(summary, dict) or "provenance" not in summary or not (folder / "report.html").is_file():
        return False
    listed = summary.get("files")
    known = ({str(Path(f).parts[0]) for f in listed if isinstance(f, str) and f}
             if isinstance(listed, list) else set(REPORT_FILES) | {"measurements.csv"})
    return all(entry.name in known for entry in entries)


def check_report_folder(out_dir, *, overwrite=False):
    """Check, before any work, that a report may be written to ``out_dir``.

    A missing folder (its parents are created), an empty one and an earlier bayespig report
    (``summary.json`` and ``report.html`` and nothing the report did not write) may be
    replaced; any other existing folder only with ``overwrite``.

    Parameters
    ----------
    out_dir : str or os.PathLike
    overwrite : bool

    Returns
    -------
    bool
        Whether something that exists will be replaced.

    Raises
    ------
    ValueError
        Naming the folder and what to do, e.g. ``run: the folder exists and is not a bayespig
        report (it holds posterior.nc, summary.csv); write the report into a new folder (e.g.
        --out run/report) or pass --overwrite to replace the whole folder``.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"{out_dir}: exists and is not a folder; choose another output folder")
    if out_dir.is_dir():
        try:
            entries = sorted(out_dir.iterdir())
        except OSError as error:
            raise ValueError(f"{out_dir}: cannot read the folder ({error.strerror})") from None
        if Path.cwd().resolve().is_relative_to(out_dir.resolve()):
            raise ValueError(f"{out_dir}: is the current folder (or holds it), which cannot be replaced; "
                             "choose another output folder")
        if entries and not overwrite and not _is_report_folder(out_dir, entries):
            names = [e.name + ("/" if e.is_dir() else "") for e in entries]
            shown = ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
            raise ValueError(f"{out_dir}: the folder exists and is not a bayespig report (it holds {shown}); "
                             f"write the report into a new folder (e.g. --out {out_dir / 'report'}) or pass "
                             "--overwrite to replace the whole folder")
        existing = bool(entries)
    else:
        existing = False
    parent = out_dir.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"{out_dir}: {parent} is not a folder; choose another output folder")
    try:  # the report's staging folder goes beside out_dir: try one there
        os.rmdir(tempfile.mkdtemp(prefix=".bayespig-check.", dir=parent))
    except OSError as error:
        raise ValueError(f"{out_dir}: cannot write into {parent} ({error.strerror or error}); "
                         "choose another output folder") from None
    return existing


def _save_netcdf(idata, path):
    """Write the posterior (or copy the netCDF file it was read from) to ``path``."""
    if isinstance(idata, Path):
        if idata.resolve() != path.resolve():
            shutil.copyfile(idata, path)
        return
    try:
        from ..inference import save_inference
    except ImportError:
        idata.to_netcdf(str(path))
        return
    save_inference(idata, path)
