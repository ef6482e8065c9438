"""Summaries and diagnostics of an inference result."""

from __future__ import annotations

import warnings

import numpy as np

from .settings import ESS_MIN, RHAT_MAX, ConvergenceWarning

__all__ = ["diagnose", "summarize"]


def _parameter_views(idata):
    """(name, DataArray over chain, draw, wavelength) of the summarised parameters."""
    posterior = idata.posterior
    views = [("a", posterior["a"])]
    if "tau" in posterior:
        views.append(("tau", posterior["tau"]))
    for name in ("g", "eps", "noise_floor"):
        if name in posterior:
            views.append((name, posterior[name]))
    return views


def summarize(idata, hdi_prob=0.9):
    """Per-wavelength summary of the posterior (arviz): mean, sd, HDI, ESS, R-hat, corr(a, log tau).

    Parameters
    ----------
    idata : arviz.InferenceData
        From :func:`infer`.
    hdi_prob : float
        Probability mass of the highest-density interval.

    Returns
    -------
    pandas.DataFrame
        One row per wavelength (index ``wavelength`` [nm]); per parameter ``p`` in ``a``,
        ``tau`` (and ``g``, ``eps``, ``noise_floor``): ``p_mean``, ``p_sd``, ``p_hdi_low``, ``p_hdi_high``,
        ``p_ess_bulk``, ``p_ess_tail``, ``p_r_hat``; and ``corr_a_log_tau``, the posterior
        correlation of ``a`` with ``log tau`` (pooled draws).
    """
    import arviz as az
    import pandas as pd

    if not 0 < hdi_prob < 1:
        raise ValueError(f"hdi_prob must lie in (0, 1), got {hdi_prob}")
    posterior = idata.posterior
    wavelength = posterior["wavelength"].values
    table = {}
    for name, da in _parameter_views(idata):
        values = da.transpose("chain", "draw", "wavelength").values
        table[f"{name}_mean"] = values.mean(axis=(0, 1))
        table[f"{name}_sd"] = values.std(axis=(0, 1), ddof=1)
        hdi = az.hdi(da, hdi_prob=hdi_prob)[da.name].transpose("wavelength", "hdi").values
        table[f"{name}_hdi_low"], table[f"{name}_hdi_high"] = hdi[:, 0], hdi[:, 1]
        table[f"{name}_ess_bulk"] = az.ess(da, method="bulk")[da.name].values
        table[f"{name}_ess_tail"] = az.ess(da, method="tail")[da.name].values
        table[f"{name}_r_hat"] = az.rhat(da)[da.name].values
    if "tau" in posterior:
        a = posterior["a"].transpose("wavelength", "chain", "draw").values.reshape(wavelength.size, -1)
        log_tau = np.log(posterior["tau"].transpose("wavelength", "chain", "draw").values).reshape(
            wavelength.size, -1)
        a_c = a - a.mean(axis=1, keepdims=True)
        t_c = log_tau - log_tau.mean(axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            table["corr_a_log_tau"] = (a_c * t_c).sum(axis=1) / np.sqrt(
                (a_c ** 2).sum(axis=1) * (t_c ** 2).sum(axis=1))
    frame = pd.DataFrame(table, index=pd.Index(wavelength, name="wavelength"))
    return frame


def diagnose(idata, *, rhat_max=RHAT_MAX, ess_min=ESS_MIN, warn=True):
    """Wavelengths whose sample may not represent the posterior.

    Flags R-hat above ``rhat_max`` or bulk/tail ESS below ``ess_min`` for any summarised
    parameter (Vehtari et al. 2021), and runs that reached ``max_steps``.

    Parameters
    ----------
    idata : arviz.InferenceData
    rhat_max, ess_min : float
    warn : bool
        Emit one :class:`ConvergenceWarning` listing every flagged wavelength.

    Returns
    -------
    list of str
        One line per flagged wavelength, ``"<λ> nm: <reasons>"`` (empty when all pass).
    """
    summary = summarize(idata)
    names = [name for name, _ in _parameter_views(idata)]
    stats = idata.sample_stats if "sample_stats" in idata.groups() else None
    capped = (stats["max_steps_reached"].values.astype(bool)
              if stats is not None and "max_steps_reached" in stats else np.zeros(len(summary), bool))
    lines = []
    for k, (wavelength, row) in enumerate(summary.iterrows()):
        reasons = []
        for name in names:
            r_hat = row[f"{name}_r_hat"]
            if not np.isfinite(r_hat) or r_hat > rhat_max:
                reasons.append(f"R-hat({name}) = {r_hat:.3f} > {rhat_max:g}")
            for kind in ("bulk", "tail"):
                ess = row[f"{name}_ess_{kind}"]
                if not np.isfinite(ess) or ess < ess_min:
                    reasons.append(f"ESS_{kind}({name}) = {ess:.0f} < {ess_min:g}")
        if capped[k]:
            reasons.append("run length capped at max_steps")
        if reasons:
            lines.append(f"{wavelength:g} nm: " + "; ".join(reasons))
    if warn and lines:
        warnings.warn(f"{len(lines)} wavelength(s) not converged:\n  " + "\n  ".join(lines),
                      ConvergenceWarning, stacklevel=2)
    return lines
