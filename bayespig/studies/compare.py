"""Method comparison: the paper's methods 1–4 (and custom sample sets) on the same pigment.

Two answers side by side, per method:

* **Fisher** (:mod:`bayespig.studies.design`): the predicted posterior sd of ``a`` and of
  ``tau`` and their correlation from ``F = J^T diag((1/eps^2 + 2)/m^2) J`` (eq. 7), cheap
  enough for dense maps over the ``(a0, tau0)`` plane (the paper's Tables 1–2 generalised).
* **Full posteriors** (:func:`bayespig.infer`) on data simulated with the exact solver and
  the noise of eq. (7): the real widths, including ravines (method 3, a thin film on one
  substrate) and nearly opaque films, where the Gaussian approximation fails. Points where
  the two disagree by more than a factor 1.5 are flagged.

The paper's conclusion (section 4.2: method 4 is the most robust unless the film is nearly
opaque, where the opaque film of methods 1–2 carries ``a`` and the transmittance of
method 1 carries ``tau``) is checked on the map (:func:`best_method_map`), not assumed.

References
----------
Ershov, Voloboy & Pozdnyakov (2023), section 3 (methods), section 4 (Tables 1–2), eq. (7).
"""

from __future__ import annotations

import datetime
import io
import json
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..data.simulate import DESIGNS
from .design import (
    Candidate,
    _versions,
    _write_bundle,
    fisher_information,
    method_candidate,
    posterior_sd,
)

__all__ = [
    "PAPER_POINTS",
    "ComparisonResult",
    "MethodMap",
    "best_method_map",
    "compare_methods",
    "method_map",
    "paper_ranking_agreement",
    "write_compare_report",
]

#: The paper's nine ``(a0, tau0)`` pairs (section 4, Tables 1–2).
PAPER_POINTS = tuple((a0, t0) for a0 in (0.025, 0.1, 0.2) for t0 in (0.5, 1.0, 2.0))
#: Factor within which Fisher and posterior widths count as agreeing (issue 8).
AGREEMENT_FACTOR = 1.5


def _candidates(methods, custom, instrument):
    out = []
    for m in methods:
        m = f"method{m}" if str(m) in ("1", "2", "3", "4") else m
        if m not in DESIGNS:
            raise ValueError(f"unknown method {m!r}; use method1..method4")
        out.append(method_candidate(m, 1.0, instrument=instrument, name=m))
    for c in custom or ():
        if not isinstance(c, Candidate):
            raise TypeError(f"custom sample sets must be Candidate, got {type(c).__name__}")
        out.append(c)
    if not out:
        raise ValueError("nothing to compare: give methods or custom sample sets")
    names = [c.name for c in out]
    if len(set(names)) != len(names):
        raise ValueError(f"sample-set names must be unique, got {names}")
    return out


# ---------------------------------------------------------------------------------------------
# maps over the (a0, tau0) plane


@dataclass
class MethodMap:
    """Fisher-predicted widths over an ``(a0, tau0)`` grid, per sample set.

    Attributes
    ----------
    a0, tau0 : numpy.ndarray
        Grid axes [-].
    names : list of str
        Sample sets (methods, custom).
    sd_a, sd_tau, corr : numpy.ndarray
        Shape (n_sets, n_a0, n_tau0): sd of ``a`` [-], sd of ``tau`` [-] (absolute, as the
        paper's Table 2: ``tau0 * sd(log tau)``), correlation of ``a`` and ``log tau``.
    identified : numpy.ndarray
        Same shape, bool: the Fisher sd of ``log tau`` is below a quarter of the prior's
        width and ``|corr| < 0.99`` (else: a ravine or an unidentified ``tau``, where the
        Gaussian approximation is not to be trusted).
    settings : dict
    """

    a0: np.ndarray
    tau0: np.ndarray
    names: list
    sd_a: np.ndarray
    sd_tau: np.ndarray
    corr: np.ndarray
    identified: np.ndarray
    settings: dict


def method_map(methods=("method1", "method2", "method3", "method4"), *, a0=None, tau0=None, custom=(),
               instrument="multi-angle-45", eps=0.05, priors=None, tables=None):
    """Fisher-predicted posterior widths of every method over an ``(a0, tau0)`` grid.

    Parameters
    ----------
    methods : sequence of str
        ``"method1"`` .. ``"method4"`` (or 1..4).
    a0, tau0 : array_like, optional
        Grid axes (default 25 log-spaced ``a0`` in [0.005, 0.5] and 25 ``tau0`` in [0.05, 20]).
    custom : sequence of Candidate
        Further sample sets (``tau_scale`` relative to ``tau0``).
    instrument : str
    eps : float
        Relative error of eq. (7) [-].
    priors : Priors, optional
    tables : dict, optional

    Returns
    -------
    MethodMap
    """
    a0 = np.geomspace(0.005, 0.5, 25) if a0 is None else np.asarray(a0, float)
    tau0 = np.geomspace(0.05, 20.0, 25) if tau0 is None else np.asarray(tau0, float)
    if a0.ndim != 1 or tau0.ndim != 1 or not ((a0 > 0) & (a0 <= 1)).all() or not (tau0 > 0).all():
        raise ValueError("a0 must be 1-D values in (0, 1] and tau0 1-D positive values")
    cands = _candidates(methods, custom, instrument)
    A, T = np.meshgrid(a0, tau0, indexing="ij")
    tables = {} if tables is None else tables
    shape = (len(cands),) + A.shape
    sd_a, sd_tau, corr, ident = np.empty(shape), np.empty(shape), np.empty(shape), np.empty(shape, bool)
    from .design import prior_precision
    prior_sd_log_tau = 1.0 / np.sqrt(prior_precision(["a", "t"], priors)[1, 1])
    for k, c in enumerate(cands):
        fisher, names = fisher_information(c, a=A, tau=T, eps=eps, tables=tables)
        sd, cor = posterior_sd(fisher, names, priors)
        sd_a[k] = sd[..., 0]
        sd_tau[k] = T * sd[..., 1] if len(names) > 1 else np.inf
        corr[k] = cor
        ident[k] = (sd[..., 1] < 0.25 * prior_sd_log_tau if len(names) > 1 else False) & ~(np.abs(cor) >= 0.99)
    settings = {"eps": eps, "instrument": instrument, "versions": _versions(),
                "sets": [c.to_json() for c in cands]}
    return MethodMap(a0, tau0, [c.name for c in cands], sd_a, sd_tau, corr, ident, settings)


def best_method_map(result, quantity="tau", tolerance=1.25):
    """Which sample set is best at every grid point, and where method 4 is (nearly) best.

    Parameters
    ----------
    result : MethodMap
    quantity : {"tau", "a"}
        Compare the sd of ``tau`` or of ``a``.
    tolerance : float
        Method 4 counts as "as good as the best" when its sd is within this factor.

    Returns
    -------
    dict
        ``best`` (n_a0, n_tau0) index into ``result.names``; ``method4_near_best`` (bool map,
        if method 4 is compared); ``fraction_method4_near_best``; ``winners`` name -> fraction.
    """
    sd = result.sd_tau if quantity == "tau" else result.sd_a
    best = np.argmin(sd, axis=0)
    out = {"quantity": quantity, "best": best,
           "winners": {n: float(np.mean(best == k)) for k, n in enumerate(result.names)}}
    if "method4" in result.names:
        k4 = result.names.index("method4")
        near = sd[k4] <= tolerance * sd.min(axis=0)
        out["method4_near_best"] = near
        out["fraction_method4_near_best"] = float(near.mean())
    return out


# ---------------------------------------------------------------------------------------------
# per-wavelength / per-point comparison with full posteriors


def _fisher_identified(fisher, k, priors):
    """The Gaussian approximation is trusted: ``sd(log tau)`` below a quarter of the prior's, ``|corr| < 0.99``."""
    from .design import prior_precision

    limit = 0.25 / np.sqrt(prior_precision(["a", "t"], priors)[1, 1])
    return (fisher["sd_log_tau"][k] < limit) & ~(np.abs(fisher["corr"][k]) >= 0.99)


@dataclass
class ComparisonResult:
    """Widths and correlations of several sample sets on one pigment, per wavelength (or point).

    Attributes
    ----------
    wavelength_nm : numpy.ndarray
        Shape (W,) [nm] (for the paper's points: label wavelengths 400 + 10 k nm, one per point).
    a, tau : numpy.ndarray
        True values, shape (W,).
    names : list of str
    fisher : dict
        ``sd_a``, ``sd_tau`` (absolute), ``sd_log_tau``, ``corr``: arrays (n_sets, W).
    posterior : dict
        The same from full posteriors (empty when not run), plus ``identified`` (n_sets, W):
        Fisher and posterior sd agree within a factor 1.5 and the Fisher matrix itself is well
        conditioned (``sd(log tau)`` below a quarter of the prior's, ``|corr| < 0.99``), and
        ``capped`` (the sampler hit ``max_steps``).
    settings : dict
    """

    wavelength_nm: np.ndarray
    a: np.ndarray
    tau: np.ndarray
    names: list
    fisher: dict
    posterior: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)

    def rows(self):
        """One dict per (set, wavelength)."""
        out = []
        for k, name in enumerate(self.names):
            for j, wl in enumerate(self.wavelength_nm):
                row = {"set": name, "wavelength_nm": float(wl), "a": float(self.a[j]), "tau": float(self.tau[j])}
                for key, values in self.fisher.items():
                    row[f"fisher_{key}"] = float(values[k, j])
                for key, values in self.posterior.items():
                    row[f"posterior_{key}"] = values[k, j].item()
                out.append(row)
        return out


def compare_methods(a, tau, *, methods=("method1", "method2", "method3", "method4"), custom=(),
                    instrument="multi-angle-45", eps=0.05, wavelengths=None, full=True, seed=0,
                    settings=None, priors=None, executor=None, progress=False, tables=None):
    """Posterior widths and correlations of methods 1–4 (and custom sets) on the same pigment.

    Parameters
    ----------
    a, tau : array_like
        The pigment: relative absorption [-] and optical thickness of the thin film [-], one
        value per wavelength (or per point: pass the paper's nine pairs as nine "wavelengths").
    methods : sequence of str
    custom : sequence of Candidate
    instrument : str
    eps : float
        Relative error of eq. (7) [-].
    wavelengths : array_like, optional
        [nm]; default 400, 410, ... (one per value of ``a``).
    full : bool
        Also simulate a measurement set per method (seeded) and sample its posterior with
        :func:`bayespig.infer` (``method="general"``: every film of the set).
    seed : int
        Seed of the simulation and of the sampler.
    settings : InferenceSettings, optional
    priors : Priors, optional
    executor : Executor, optional
    progress : bool
    tables : dict, optional

    Returns
    -------
    ComparisonResult
    """
    from ..data.simulate import simulate

    a = np.atleast_1d(np.asarray(a, float))
    tau = np.broadcast_to(np.asarray(tau, float), a.shape).copy()
    if a.ndim != 1 or ((a <= 0) | (a > 1)).any() or not (tau > 0).all():
        raise ValueError("a must be 1-D values in (0, 1] and tau positive values of the same length")
    wl = 400.0 + 10.0 * np.arange(a.size) if wavelengths is None else np.asarray(wavelengths, float)
    if wl.shape != a.shape:
        raise ValueError(f"wavelengths must have one value per a ({a.size}), got shape {wl.shape}")
    cands = _candidates(methods, custom, instrument)
    tables = {} if tables is None else tables
    started = time.perf_counter()
    shape = (len(cands), a.size)
    fisher = {k: np.full(shape, np.nan) for k in ("sd_a", "sd_tau", "sd_log_tau", "corr")}
    for k, c in enumerate(cands):
        F, names = fisher_information(c, a=a, tau=tau, eps=eps, tables=tables)
        sd, cor = posterior_sd(F, names, priors)
        fisher["sd_a"][k] = sd[:, 0]
        if len(names) > 1:
            fisher["sd_log_tau"][k] = sd[:, 1]
            fisher["sd_tau"][k] = tau * sd[:, 1]
            fisher["corr"][k] = cor
    posterior = {}
    if full:
        from ..inference import ConvergenceWarning, infer

        posterior = {k: np.full(shape, np.nan) for k in ("sd_a", "sd_tau", "sd_log_tau", "corr")}
        posterior["identified"] = np.zeros(shape, bool)
        posterior["capped"] = np.zeros(shape, bool)
        for k, c in enumerate(cands):
            ms = simulate(a=a, tau=tau, design=list(c.films), instrument=c.instrument, wavelengths=wl,
                          eps=eps, seed=seed)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                idata = infer(ms, method="general", seed=seed, eps=eps, progress=progress, settings=settings,
                              priors=priors, executor=executor)
            draws_a = idata.posterior["a"].values.reshape(-1, a.size)
            posterior["sd_a"][k] = draws_a.std(axis=0)
            posterior["capped"][k] = idata.sample_stats["max_steps_reached"].values.astype(bool)
            ratios = [posterior["sd_a"][k] / fisher["sd_a"][k]]
            if "tau" in idata.posterior:
                log_tau = np.log(idata.posterior["tau"].values.reshape(-1, a.size))
                posterior["sd_log_tau"][k] = log_tau.std(axis=0)
                posterior["sd_tau"][k] = np.exp(log_tau).std(axis=0)
                posterior["corr"][k] = [np.corrcoef(draws_a[:, j], log_tau[:, j])[0, 1] for j in range(a.size)]
                ratios.append(posterior["sd_log_tau"][k] / fisher["sd_log_tau"][k])
            ratios = np.array(ratios)
            agree = ((ratios <= AGREEMENT_FACTOR) & (ratios >= 1 / AGREEMENT_FACTOR)).all(0)
            posterior["identified"][k] = agree & _fisher_identified(fisher, k, priors)
    record = {"eps": eps, "instrument": instrument, "seed": int(seed), "full": bool(full),
              "inference_settings": None if settings is None else json.loads(settings.to_json()),
              "sets": [c.to_json() for c in cands], "versions": _versions(),
              "wall_time_s": time.perf_counter() - started,
              "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")}
    return ComparisonResult(wl, a, tau, [c.name for c in cands], fisher, posterior, record)


def paper_ranking_agreement(sd, paper, rounding=0.0005):
    """Pairs of methods the paper ranks (its values differ beyond its rounding) and whether ``sd`` agrees.

    Parameters
    ----------
    sd : dict
        ``(method, a0, tau0) -> sd`` (e.g. Fisher or posterior sd).
    paper : dict
        The paper's values with the same keys (:data:`bayespig.studies.PAPER_A_RMS`,
        :data:`~bayespig.studies.PAPER_TAU_RMS`).
    rounding : float
        Half the paper's last digit (values are given to 3 decimals).

    Returns
    -------
    list of dict
        One per ranked pair at each point: ``better``, ``worse``, ``a0``, ``tau0``, ``agrees``.
    """
    out = []
    points = sorted({(k[1], k[2]) for k in paper})
    methods = sorted({k[0] for k in paper})
    for a0, t0 in points:
        for i, m1 in enumerate(methods):
            for m2 in methods[i + 1:]:
                p1, p2 = paper[(m1, a0, t0)], paper[(m2, a0, t0)]
                if abs(p1 - p2) <= 2 * rounding:
                    continue  # tied within the paper's rounding: no ranking claimed
                better, worse = (m1, m2) if p1 < p2 else (m2, m1)
                out.append({"a0": a0, "tau0": t0, "better": better, "worse": worse,
                            "agrees": bool(sd[(better, a0, t0)] < sd[(worse, a0, t0)])})
    return out


# ---------------------------------------------------------------------------------------------
# report


def _ranges(values, mask):
    """``[lo, hi]`` runs of ``values`` where ``mask`` is true, as text."""
    runs, start = [], None
    for i, flag in enumerate(list(mask) + [False]):
        if flag and start is None:
            start = i
        elif not flag and start is not None:
            runs.append(f"[{values[start]:.3g}, {values[i - 1]:.3g}]")
            start = None
    return ", ".join(runs)


def _map_figure(result, best_tau, best_a):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    n = len(result.names)
    fig = Figure(figsize=(3.2 * n + 1, 6.4), layout="constrained")
    axes = fig.subplots(2, n, squeeze=False)
    for row, (data, label) in enumerate(((result.sd_a, "sd of a [-]"),
                                         (result.sd_tau / result.tau0, "relative sd of tau, sd / tau0 [-]"))):
        finite = data[np.isfinite(data) & (data > 0)]
        norm = LogNorm(vmin=max(finite.min(), 1e-4), vmax=finite.max()) if finite.size else None
        for k, name in enumerate(result.names):
            ax = axes[row, k]
            mesh = ax.pcolormesh(result.tau0, result.a0, data[k], norm=norm, shading="nearest", cmap="viridis")
            bad = ~result.identified[k]
            if bad.any():
                ax.contourf(result.tau0, result.a0, bad.astype(float), levels=[0.5, 1.5], colors="none",
                            hatches=["///"])
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_title(f"{name}: {label}", fontsize=9)
            ax.set_xlabel("tau0 [-]")
            if k == 0:
                ax.set_ylabel("a0 [-]")
        fig.colorbar(mesh, ax=axes[row, :].tolist(), shrink=0.9, label=label + " (Fisher)")
    FigureCanvasAgg(fig)  # the Agg canvas, whatever pyplot's backend is
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    return buffer.getvalue()


def write_compare_report(out_dir, *, comparison=None, maps=None, paper=None, command=None):
    """Write ``compare.html``, ``compare.md``, ``compare.json`` and figures atomically.

    Parameters
    ----------
    out_dir : path
    comparison : ComparisonResult, optional
        Per-wavelength (or per-point) widths.
    maps : MethodMap, optional
        Dense Fisher maps (one panel per set; hatched where not identified).
    paper : ComparisonResult, optional
        The comparison at the paper's nine points (its ranking is checked against Tables 1–2).
    command : str, optional
        The command that regenerates the report (stated at its top).

    Returns
    -------
    dict
        Role -> path.
    """
    from ..report import document as doc
    from .robustness import PAPER_A_RMS, PAPER_TAU_RMS

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    blocks = [doc.heading("Method comparison", 1),
              doc.paragraph("Fisher widths: F = J^T diag((1/eps^2 + 2)/m^2) J from the look-up table's "
                            "derivatives (eq. 7), prior box precision added; posterior widths: bayespig.infer on "
                            "data simulated with the exact solver. 'identified' = the two agree within a factor "
                            f"{AGREEMENT_FACTOR} and the Fisher matrix is well conditioned; elsewhere "
                            "(ravines, nearly opaque films) trust the posterior."),
              doc.paragraph("Caveat: eq. (7) has no absolute noise floor, so a film on glass with "
                            "T = t_F^2 exp(-tau0) is assumed measurable to eps relative even at tau0 = 20; "
                            "method 1's advantage for thick films holds only while the transmittance stays "
                            "well above the instrument's floor.")]
    if command:
        blocks[1:1] = [doc.paragraph("Generated by this command; rerun it to regenerate:"),
                       doc.preformatted(command)]
    figures, payload = {}, {"command": command}

    def width_table(res):
        header = ["set", "nm" if res is comparison else "point", "a", "tau", "sd a (Fisher)", "sd tau (Fisher)",
                  "corr (Fisher)"]
        if res.posterior:
            header += ["sd a (posterior)", "sd tau (posterior)", "corr (posterior)", "identified"]
        rows = []
        for r in res.rows():
            row = [r["set"], f"{r['wavelength_nm']:g}", f"{r['a']:.3g}", f"{r['tau']:.3g}",
                   f"{r['fisher_sd_a']:.3g}", f"{r['fisher_sd_tau']:.3g}", f"{r['fisher_corr']:.2f}"]
            if res.posterior:
                row += [f"{r['posterior_sd_a']:.3g}", f"{r['posterior_sd_tau']:.3g}",
                        f"{r['posterior_corr']:.2f}", "yes" if r["posterior_identified"] else "NO"]
            rows.append(row)
        return doc.table(header, rows)

    if paper is not None:
        blocks.append(doc.heading("The paper's nine points"))
        blocks.append(doc.paragraph(
            "The paper's Tables 1–2 are frequentist RMS errors of point fits; they include fits that end "
            "at a bound of the fit's box (method 3 everywhere, methods 2 and 4 at tau0 = 2), which inflate "
            "an RMS but not a posterior width. A pair counts as ranked by the paper when its values differ "
            "beyond its rounding to 3 decimals; bayespig's own regeneration of the tables "
            "(bayespig robustness --paper) shows which of the paper's values hold such outliers."))
        blocks.append(width_table(paper))
        checks = {}
        for source, res_dict in (("fisher", paper.fisher), ("posterior", paper.posterior)):
            if not res_dict:
                continue
            for q, table in (("a", PAPER_A_RMS), ("tau", PAPER_TAU_RMS)):
                values = {}
                for k, m in enumerate(paper.names):
                    for j, (a0, t0) in enumerate(zip(paper.a, paper.tau)):
                        values[(m, float(a0), float(t0))] = res_dict["sd_a" if q == "a" else "sd_tau"][k, j]
                pairs = paper_ranking_agreement(values, {k: v for k, v in table.items() if k[0] in paper.names})
                checks[f"{source}_{q}"] = pairs
                n_ok = sum(p["agrees"] for p in pairs)
                blocks.append(doc.paragraph(
                    f"{source} sd of {q}: agrees with the paper's ranking in {n_ok} of {len(pairs)} method pairs "
                    "that the paper separates beyond its rounding"
                    + ("" if n_ok == len(pairs) else ": disagreements " + ", ".join(
                        f"{p['better']} < {p['worse']} at ({p['a0']}, {p['tau0']})" for p in pairs
                        if not p["agrees"]))))
        payload["paper_points"] = {"rows": paper.rows(), "settings": paper.settings, "ranking_checks": checks}
    if comparison is not None:
        blocks += [doc.heading("Per wavelength"), width_table(comparison)]
        payload["comparison"] = {"rows": comparison.rows(), "settings": comparison.settings}
    if maps is not None:
        best_t, best_a = best_method_map(maps, "tau"), best_method_map(maps, "a")
        figures["compare_maps"] = _map_figure(maps, best_t, best_a)
        lines = []
        for best in (best_t, best_a):
            winners = ", ".join(f"{n} {100 * f:.0f} %" for n, f in best["winners"].items() if f > 0)
            line = f"smallest sd of {best['quantity']}: {winners} of the plane"
            if "fraction_method4_near_best" in best:
                line += (f"; method 4 within a factor 1.25 of the best on "
                         f"{100 * best['fraction_method4_near_best']:.0f} %")
                columns = best["method4_near_best"].all(axis=0)
                line += (f" (at every a0 for tau0 in {_ranges(maps.tau0, columns)})" if columns.any()
                         else " (at no tau0 for every a0)")
            lines.append(line)
        blocks += [doc.heading("Maps over (a0, tau0)"), doc.bullets(lines),
                   doc.figure("compare_maps", "Fisher-predicted sd of a (top) and relative sd of tau (bottom) per "
                                              "sample set; hatched: not identified (ravine or tau unconstrained).")]
        payload["maps"] = {"a0": maps.a0, "tau0": maps.tau0, "names": maps.names, "sd_a": maps.sd_a,
                           "sd_tau": maps.sd_tau, "corr": maps.corr, "identified": maps.identified,
                           "settings": maps.settings, "best_tau": best_t, "best_a": best_a}
    return _write_bundle(out_dir, "compare", blocks, figures, payload, "bayespig method comparison")


def compare_measurements(measurements, *, methods=None, eps=None, seed=0, settings=None, priors=None,
                         executor=None, progress=False, tables=None):
    """Compare the methods a real measurement set supports: posterior widths from the user's data.

    For every method the set supports (:meth:`bayespig.data.MeasurementSet.supported_methods`)
    the posterior is sampled from the measured values of that method's samples; the Fisher
    widths are evaluated at the posterior median of the first method (the pigment as
    measured) so the two can be put side by side.

    Parameters
    ----------
    measurements : MeasurementSet or path
    methods : sequence of str, optional
        Default: every supported method.
    eps : float, optional
        Relative error of eq. (7) [-] (default: the file's, else 0.05).
    seed : int
    settings, priors, executor, progress, tables
        As :func:`compare_methods`.

    Returns
    -------
    ComparisonResult
    """
    from ..data import MeasurementSet, read_measurements
    from ..inference import ConvergenceWarning, _resolve_eps, infer

    if not isinstance(measurements, MeasurementSet):
        measurements = read_measurements(measurements)
    supported = [m for m, ok in measurements.supported_methods().items() if ok]
    methods = supported if methods is None else [f"method{m}" if str(m) in "1234" else m for m in methods]
    missing = [m for m in methods if m not in supported]
    if missing or not methods:
        raise ValueError(f"the measurement set supports {', '.join(supported) or 'no method'}; "
                         f"cannot compare {', '.join(missing) or 'nothing'}")
    if len(methods) < 2:
        warnings.warn(f"only {methods[0]} is supported by these samples: nothing to compare against",
                      UserWarning, stacklevel=2)
    eps_value, _ = _resolve_eps(eps, measurements)
    eps_value = 0.05 if eps_value is None else eps_value
    started = time.perf_counter()
    wl = np.asarray(measurements.wavelength_nm, float)
    shape = (len(methods), wl.size)
    posterior = {k: np.full(shape, np.nan) for k in ("sd_a", "sd_tau", "sd_log_tau", "corr")}
    posterior["identified"] = np.zeros(shape, bool)
    posterior["capped"] = np.zeros(shape, bool)
    medians = None
    for k, m in enumerate(methods):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            idata = infer(measurements, method=m, seed=seed, eps=eps_value, progress=progress,
                          settings=settings, priors=priors, executor=executor)
        draws_a = idata.posterior["a"].values.reshape(-1, wl.size)
        posterior["sd_a"][k] = draws_a.std(axis=0)
        posterior["capped"][k] = idata.sample_stats["max_steps_reached"].values.astype(bool)
        if "tau" in idata.posterior:
            log_tau = np.log(idata.posterior["tau"].values.reshape(-1, wl.size))
            posterior["sd_log_tau"][k] = log_tau.std(axis=0)
            posterior["sd_tau"][k] = np.exp(log_tau).std(axis=0)
            posterior["corr"][k] = [np.corrcoef(draws_a[:, j], log_tau[:, j])[0, 1] for j in range(wl.size)]
            if medians is None:
                medians = (np.median(draws_a, axis=0), np.exp(np.median(log_tau, axis=0)))
    if medians is None:
        raise ValueError("no compared method has a finite film: tau is not measured")
    a_med, tau_med = np.clip(medians[0], 1e-6, 1.0), medians[1]
    fisher = {k: np.full(shape, np.nan) for k in ("sd_a", "sd_tau", "sd_log_tau", "corr")}
    tables = {} if tables is None else tables
    for k, m in enumerate(methods):
        problem_instrument = _instrument_of(measurements, m)
        F, names = fisher_information(m, a=a_med, tau=tau_med, eps=eps_value, instrument=problem_instrument,
                                      tables=tables, n=measurements.n)
        sd, cor = posterior_sd(F, names, priors)
        fisher["sd_a"][k] = sd[:, 0]
        if len(names) > 1:
            fisher["sd_log_tau"][k], fisher["sd_tau"][k], fisher["corr"][k] = sd[:, 1], tau_med * sd[:, 1], cor
        ratio = np.stack([posterior["sd_a"][k] / fisher["sd_a"][k],
                          posterior["sd_log_tau"][k] / fisher["sd_log_tau"][k]])
        agree = ((ratio <= AGREEMENT_FACTOR) & (ratio >= 1 / AGREEMENT_FACTOR)).all(0)
        posterior["identified"][k] = agree & _fisher_identified(fisher, k, priors)
    record = {"eps": eps_value, "seed": int(seed), "source": "measurements", "methods": list(methods),
              "note": "Fisher widths at the posterior median of the first method, for the paper's layouts "
                      "with r_s = 0.01/0.95 (the measured substrates may differ)",
              "versions": _versions(), "wall_time_s": time.perf_counter() - started,
              "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")}
    return ComparisonResult(wl, a_med, tau_med, list(methods), fisher, posterior, record)


def _instrument_of(measurements, method):
    """The reflectance instrument of a method's films in a measurement set (first one found)."""
    from ..likelihood import Problem

    problem = Problem.from_measurements(measurements, method)
    for film in problem.films:
        if film.instrument is not None:
            return film.instrument
    return "multi-angle-45"
