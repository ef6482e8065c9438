"""``summary.csv``: the one per-wavelength table of a posterior, written by ``infer`` and ``report``.

One row per wavelength, columns (``p`` is each per-wavelength parameter: ``a``, ``tau``, and
``tau_<group>`` for every film group when there are several, ``g`` when free, ``eps`` when
inferred, and those of a gonio fit when inferred: ``flake_reflectance`` (the flakes' ``c``),
``noise_floor`` (the additive floor ``sigma0`` [1/sr]) and ``incidence_offset`` (the instrument's
offset ``b`` [1/sr], ``infer(..., incidence_offset=True)``)):

``wavelength_nm``
    Wavelength [nm].
``p_mean``, ``p_sd``, ``p_median``
    Posterior mean, standard deviation and median.
``p_ci50_low``, ``p_ci50_high``, ``p_ci90_low``, ``p_ci90_high``
    Central (equal-tailed) 50 % and 90 % credible intervals: the 25/75 % and 5/95 %
    posterior quantiles -- the bands of the report's figures.
``p_ess_bulk``, ``p_ess_tail``, ``p_r_hat``
    Bulk and tail effective sample size and rank-normalised R-hat (arviz).
``corr_a_log_tau``
    Posterior correlation of ``a`` and ``log tau``.
``point_a``, ``point_tau``
    The least-squares point fit (the paper's procedure).

A parameter the posterior does not have has no columns: when every film is opaque (hides its
substrate) ``tau`` is not identified and not a parameter, so the ``tau_*``, ``corr_a_log_tau``,
``point_tau``, ``k_ext_*`` and ``sigma_ext_*`` columns are absent (not empty); the other
columns are the same.
``k_ext_*``, ``sigma_ext_*``
    Only when the film's thickness (and concentration) are known: the extinction coefficient
    ``tau / H`` [1/µm] and cross-section ``tau / (H D)`` (mean, sd, median, ci90 low/high).
``ppc_p_value``, ``model_check``
    The posterior predictive check (:func:`~bayespig.report.quantities.posterior_predictive_check`):
    its p-value and its verdict: ``pass``, ``misfit (p < 0.01)`` or, where a wavelength has no
    more values than parameters and nothing is flagged, ``not testable (2 values <= 2 parameters)``.
``prior_edge``
    The parameters whose posterior is piled against a bound of its prior at the wavelength
    (:func:`~bayespig.report.quantities.prior_edges`), ``; ``-separated: ``a at 0`` (at the
    bound 0: the data push it outside the prior's range), ``g fills [-0.5, 0.8]`` (the whole
    range: not identified); empty: none.
``flags``
    Convergence and identification problems of the wavelength, ``; ``-separated (empty: none).

Numbers have :data:`SIGNIFICANT_DIGITS` significant digits; a missing number is an empty cell.
"""

from __future__ import annotations

import csv
import io

import numpy as np

from . import quantities as q

__all__ = ["INTERVALS", "SIGNIFICANT_DIGITS", "columns_to_csv", "summary_columns", "summary_csv"]

#: Significant digits of every number in ``summary.csv`` (posterior quantities are known to
#: far fewer digits; 6 keep the table exact enough to recompute differences and ratios).
SIGNIFICANT_DIGITS = 6
#: Central credible intervals of the table: level in percent -> (lower, upper) quantile.
INTERVALS = {"50": (0.25, 0.75), "90": (0.05, 0.95)}


def _parameters(idata):
    """``(column prefix, draws (chain, draw, wavelength))`` per per-wavelength parameter."""
    posterior = idata.posterior
    out = []
    for name in ("a", "tau"):
        if name in posterior:
            out.append((name, posterior[name].transpose("chain", "draw", "wavelength")))
    if "tau_group" in posterior:
        groups = [str(g) for g in posterior["tau_group"].coords["group"].values]
        for k, group in enumerate(groups):
            if k == 0:
                continue  # tau is the first group's
            out.append((f"tau_{group}", posterior["tau_group"].isel(group=k).transpose("chain", "draw", "wavelength")))
    for name in ("g", "eps", "flake_reflectance", "noise_floor", "incidence_offset"):
        if name in posterior:
            da = posterior[name]
            extra = [d for d in da.dims if d not in ("chain", "draw", "wavelength")]
            if extra:
                da = da.isel({d: 0 for d in extra})
            out.append((name, da.transpose("chain", "draw", "wavelength")))
    return out


def summary_columns(idata, *, measurements=None, check=None, diagnostics=None, edges=None):
    """The columns of ``summary.csv``, in order.

    Parameters
    ----------
    idata : arviz.InferenceData
        From :func:`bayespig.infer`.
    measurements : MeasurementSet, optional
        Its film thickness and concentration give the extinction columns.
    check : dict, optional
        :func:`~bayespig.report.quantities.posterior_predictive_check` of ``idata`` (computed
        when not given).
    diagnostics : dict, optional
        :func:`~bayespig.report.quantities.diagnostics` of ``idata`` (computed when not given).
    edges : list of dict, optional
        :func:`~bayespig.report.quantities.prior_edges` of ``idata`` (computed when not given).

    Returns
    -------
    dict
        Column name -> array (n_wavelengths,) of numbers, or list of str for ``model_check``,
        ``prior_edge`` and ``flags``.
    """
    import arviz as az

    wl = q.wavelengths(idata)
    columns = {"wavelength_nm": wl}
    for prefix, da in _parameters(idata):
        draws = np.asarray(da.values, dtype=float)
        pooled = draws.reshape(-1, wl.size)
        columns[f"{prefix}_mean"] = pooled.mean(axis=0)
        columns[f"{prefix}_sd"] = pooled.std(axis=0, ddof=1)
        columns[f"{prefix}_median"] = np.median(pooled, axis=0)
        for level, (low, high) in INTERVALS.items():
            columns[f"{prefix}_ci{level}_low"], columns[f"{prefix}_ci{level}_high"] = np.quantile(
                pooled, [low, high], axis=0)
        dataset = da.to_dataset(name="x")
        columns[f"{prefix}_ess_bulk"] = np.asarray(az.ess(dataset, method="bulk")["x"].values, dtype=float)
        columns[f"{prefix}_ess_tail"] = np.asarray(az.ess(dataset, method="tail")["x"].values, dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            columns[f"{prefix}_r_hat"] = (np.asarray(az.rhat(dataset)["x"].values, dtype=float)
                                          if draws.shape[0] > 1 else np.full(wl.size, np.nan))
    if "tau" in idata.posterior:
        a = q.posterior_draws(idata, "a")
        log_tau = np.log(q.posterior_draws(idata, "tau"))
        da, dt = a - a.mean(axis=0), log_tau - log_tau.mean(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            columns["corr_a_log_tau"] = (da * dt).sum(axis=0) / np.sqrt((da * da).sum(axis=0) * (dt * dt).sum(axis=0))
    constant = getattr(idata, "constant_data", None)
    for name in ("a", "tau") if "tau" in idata.posterior else ("a",):
        columns[f"point_{name}"] = (np.asarray(constant[f"point_{name}"].values, dtype=float)
                                    if constant is not None and f"point_{name}" in constant
                                    else np.full(wl.size, np.nan))
    columns.update(_extinction_columns(idata, measurements))
    check = check if check is not None else q.posterior_predictive_check(idata)
    columns["ppc_p_value"] = check["p_value"]
    columns["model_check"] = q.model_check_status(check)
    columns["prior_edge"] = q.prior_edge_column(idata, edges)
    diagnostics = diagnostics if diagnostics is not None else q.diagnostics(idata)
    flagged = {f["wavelength_nm"]: "; ".join(f["reasons"]) for f in diagnostics["flags"]
               if f["wavelength_nm"] is not None}
    columns["flags"] = [flagged.get(float(w), "") for w in wl]
    return columns


def _extinction_columns(idata, measurements):
    """``k_ext_*`` and ``sigma_ext_*`` of the first film group when its thickness is known."""
    if measurements is None or "tau" not in idata.posterior:
        return {}
    problem = q.problem_from_inference(idata)
    if not problem.groups:
        return {}
    films = measurements.film_groups.get(problem.groups[0], ())
    thickness = next((f.thickness_um for f in films if f.thickness_um is not None), None)
    if thickness is None:
        return {}
    concentration = next((f.concentration for f in films if f.concentration is not None), None)
    out = {}
    for name, draws in q.extinction(q.posterior_draws(idata, "tau"), thickness, concentration).items():
        out[f"{name}_mean"] = draws.mean(axis=0)
        out[f"{name}_sd"] = draws.std(axis=0, ddof=1)
        out[f"{name}_median"] = np.median(draws, axis=0)
        out[f"{name}_ci90_low"], out[f"{name}_ci90_high"] = np.quantile(draws, INTERVALS["90"], axis=0)
    return out


def _number(value):
    value = float(value)
    return f"{value:.{SIGNIFICANT_DIGITS}g}" if np.isfinite(value) else ""


def columns_to_csv(columns):
    """The text of ``summary.csv`` from :func:`summary_columns`' columns."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(list(columns))
    for i in range(len(columns["wavelength_nm"])):
        writer.writerow([v[i] if isinstance(v, list) else _number(v[i]) for v in columns.values()])
    return buffer.getvalue()


def summary_csv(idata, **kwargs):
    """The text of ``summary.csv`` (arguments as :func:`summary_columns`)."""
    return columns_to_csv(summary_columns(idata, **kwargs))
