"""The paper's robustness question answered the Bayesian way: posterior widths from one set.

The paper (section 4) measures a method's robustness by refitting 1000 noisy replicates of
the same film (:mod:`bayespig.studies.robustness`). The Bayesian answer needs one measurement
set: the posterior's standard deviations of ``a`` and ``tau``, and the correlation of ``a`` with
``log tau`` that shows the paper's "ravines". For every (a0, tau0) pair of the paper's Tables 1
and 2 and every method this module simulates **one** set (eq. 7), samples its posterior with
:func:`bayespig.infer`, and puts the posterior sd next to the frequentist RMS of the point fits.

Where the posterior is well identified and close to Gaussian (method 4, methods 1–2 for ``a``
and ``tau``, small ``tau0``) the two agree; where it is not (method 3, the opaque limit at
``tau0 = 2``), the posterior is wide and skewed and its sd is the honest width of what one set
says, while the RMS of point fits depends on where the fit's box stops them.

``bayespig robustness --posterior`` writes ``reports/posterior-robustness.md`` through
:func:`write_posterior_tables`.
"""

from __future__ import annotations

import datetime
import sys
import time
import warnings
from collections.abc import Iterable

import numpy as np

from .._atomic import write_text_atomically
from ..likelihood import method_name
from .robustness import PAPER_A0, PAPER_METHODS, PAPER_TAU0, robustness_study

__all__ = ["posterior_robustness", "write_posterior_tables"]

#: Label wavelengths of the (a0, tau0) cases packed into one simulated set [nm].
_FIRST_LABEL_NM = 1000.0


def _method_names(methods):
    """One method or a sequence of them, in any spelling -> tuple of ``"method1"`` .. ``"method4"``."""
    one = isinstance(methods, (str, int, np.integer)) or not isinstance(methods, Iterable)
    return tuple(method_name(m, also=()) for m in ((methods,) if one else methods))


def _instrument_name(instrument):
    return instrument if isinstance(instrument, str) else getattr(instrument, "name", str(instrument))


def posterior_robustness(methods=PAPER_METHODS, a0_values=PAPER_A0, tau0_values=PAPER_TAU0, *,
                         eps=0.05, seed=0, instrument="multi-angle-45", n_repeat=1000,
                         executor=None, settings=None, progress=False):
    """Posterior sd of ``a`` and ``tau`` from one simulated set per case, and the frequentist RMS.

    Parameters
    ----------
    methods : str, int or sequence of them
        The paper's method(s), ``"method1"`` .. ``"method4"`` or ``1`` .. ``4``.
    a0_values, tau0_values : sequence of float
        True values; every pair is a case (the paper's 3 x 3 by default).
    eps : float
        Relative error of eq. (7) [-], used to simulate and known to the likelihood (> 0).
    seed : int
        Seed of the simulated sets (one per method; the cases of a method are its wavelengths)
        and of the emcee runs; the refits use the same seed (:func:`robustness_study`).
    instrument : str or Instrument
    n_repeat : int
        Noisy replicates of the frequentist study.
    executor : concurrent.futures.Executor, optional
        For the emcee runs and the refits (default: local pool of 2 processes).
    settings : InferenceSettings, optional
    progress : bool
        Progress on stderr: a bar over the refits, then one line and a bar per method's posterior.

    Returns
    -------
    list of dict
        One record per (method, a0, tau0): ``a_mean``, ``a_sd``, ``tau_mean``, ``tau_sd``,
        ``tau_median``, ``tau_hdi_low``, ``tau_hdi_high``, ``corr_a_log_tau``, ``a_rms``,
        ``tau_rms``, ``fraction_at_bound``, the diagnostics ``r_hat_max``, ``ess_min`` and
        ``flagged``.
    """
    from ..data import simulate
    from ..inference import ConvergenceWarning, infer, summarize

    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be > 0 for the posterior (the likelihood divides by it), got {eps}")
    methods = _method_names(methods)
    pairs = [(float(a0), float(tau0)) for tau0 in tau0_values for a0 in a0_values]
    grid = robustness_study(methods, tuple(a0_values), tuple(tau0_values), eps=eps,
                            n_repeat=n_repeat, seed=seed, instrument=instrument, executor=executor,
                            progress=progress)
    records = []
    for k, method in enumerate(methods):
        if progress:
            print(f"posterior robustness: {method}, {len(pairs)} case{'s' if len(pairs) != 1 else ''}",
                  file=sys.stderr, flush=True)
        a = np.array([p[0] for p in pairs])
        tau = np.array([p[1] for p in pairs])
        measurements = simulate(a=a, tau=tau, design=method, instrument=instrument,
                                wavelengths=_FIRST_LABEL_NM + np.arange(len(pairs)), eps=eps,
                                seed=int(np.random.SeedSequence([seed, k]).generate_state(1)[0]))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)  # flagged per case below
            idata = infer(measurements, method=method, seed=seed, eps=eps, executor=executor,
                          progress=progress, settings=settings)
        capped = idata.sample_stats["max_steps_reached"].values.astype(bool)
        summary = summarize(idata)
        tau_post = idata.posterior["tau"]
        for j, (a0, tau0) in enumerate(pairs):
            row = summary.iloc[j]
            draws = tau_post.values[..., j].ravel()
            frequentist = grid[method, a0, tau0]
            r_hat = max(row["a_r_hat"], row["tau_r_hat"])
            ess = min(row[f"{p}_ess_{kind}"] for p in ("a", "tau") for kind in ("bulk", "tail"))
            records.append({
                "method": method, "a0": a0, "tau0": tau0,
                "a_mean": float(row["a_mean"]), "a_sd": float(row["a_sd"]),
                "tau_mean": float(row["tau_mean"]), "tau_sd": float(row["tau_sd"]),
                "tau_median": float(np.median(draws)),
                "tau_hdi_low": float(row["tau_hdi_low"]), "tau_hdi_high": float(row["tau_hdi_high"]),
                "corr_a_log_tau": float(row["corr_a_log_tau"]),
                "a_rms": frequentist.a_rms, "tau_rms": frequentist.tau_rms,
                "fraction_at_bound": frequentist.fraction_at_bound,
                "r_hat_max": float(r_hat), "ess_min": float(ess),
                "max_steps_reached": bool(capped[j]),
                "flagged": bool(r_hat > 1.01 or ess < 400 or capped[j]),
            })
    return records


def _ratio(x, y):
    return f"{x / y:.2f}" if y > 0 and np.isfinite(x / y) else "–"


def write_posterior_tables(path="reports/posterior-robustness.md", *, seed=0, eps=0.05,
                           instrument="multi-angle-45", n_repeat=1000, executor=None, settings=None,
                           methods=PAPER_METHODS, a0_values=PAPER_A0, tau0_values=PAPER_TAU0,
                           command="bayespig robustness --posterior", progress=False):
    """Run :func:`posterior_robustness` and write the Markdown report atomically.

    ``progress`` shows the progress of the refits and of the posteriors on stderr.

    Returns
    -------
    list of dict
        The records.
    """
    from .._versions import __version__
    from ..inference import InferenceSettings

    started = time.perf_counter()
    methods = _method_names(methods)
    settings = InferenceSettings() if settings is None else settings
    records = posterior_robustness(methods, a0_values, tau0_values, eps=eps, seed=seed,
                                   instrument=instrument, n_repeat=n_repeat, executor=executor,
                                   settings=settings, progress=progress)
    elapsed = time.perf_counter() - started
    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M")
    lines = [
        "# Robustness the Bayesian way: posterior widths from one measurement set",
        "",
        f"Generated by `{command}` — do not edit by hand; rerun the command to regenerate.",
        f"bayespig {__version__}; {now} UTC; {elapsed:.0f} s.",
        "",
        "The paper measures a method's robustness by refitting 1000 noisy replicates of one film",
        "(the frequentist RMS of `reports/paper-tables.md`). The Bayesian answer needs **one** set:",
        "for every case below one set is simulated (eq. 7), its posterior sampled with",
        "`bayespig.infer` (exact likelihood of eq. 7 with eps known; priors `a` uniform on [0, 1],",
        "`tau` log-uniform on [0.01, 100]), and the posterior standard deviation is put next to the",
        "RMS of the point fits. corr is the posterior correlation of `a` with `log tau`: the",
        "paper's ravine shows as corr near 1.",
        "",
        (f"Instrument `{_instrument_name(instrument)}`, eps = {eps:g}, seed {seed}, "
        f"{n_repeat} refits per case for the RMS; sampler settings `{settings.to_json()}`."),
        "",
        "How to read it: where the posterior is well identified (methods 1, 2, 4 at small tau0) the",
        "posterior sd and the RMS agree (ratio near 1; a single set's sd scatters by a few per cent",
        "around its expectation). Where they differ, the posterior is wide or skewed (method 3, the",
        "opaque limit at tau0 = 2): then the RMS of point fits is set by where the fit's box stops",
        "them, while the posterior reports everything the set allows (see the 90 % HDI of tau).",
        "",
    ]
    for method in methods:
        rows = [r for r in records if r["method"] == method]
        lines += [
            f"## {method}",
            "",
            ("| tau0 | a0 | a: post. mean ± sd | a: RMS | sd/RMS | tau: post. median (90 % HDI) | "
            "tau: post. sd | tau: RMS | sd/RMS | corr(a, log tau) | fits at bound |"),
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in rows:
            flag = " ⚠" if r["flagged"] else ""
            flag += " (capped)" if r["max_steps_reached"] else ""
            lines.append(
                f"| {r['tau0']:g} | {r['a0']:g} | {r['a_mean']:.4f} ± {r['a_sd']:.4f} | {r['a_rms']:.4f} | "
                f"{_ratio(r['a_sd'], r['a_rms'])} | {r['tau_median']:.3g} ({r['tau_hdi_low']:.3g}–"
                f"{r['tau_hdi_high']:.3g}) | {r['tau_sd']:.3g} | {r['tau_rms']:.3g} | "
                f"{_ratio(r['tau_sd'], r['tau_rms'])} | {r['corr_a_log_tau']:.2f}{flag} | "
                f"{r['fraction_at_bound']:.1%} |")
        lines.append("")
    if any(r["flagged"] for r in records):
        lines += [("⚠: the sampler's diagnostics flagged this case (R-hat > 1.01, ESS < 400 or a run "
                  "that reached max_steps); its numbers are less certain."), ""]
    text = "\n".join(lines)
    write_text_atomically(path, text)
    return records
