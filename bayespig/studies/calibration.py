"""Simulation-based calibration of the posteriors (Talts et al. 2018).

If the sampler draws from the exact posterior, then for parameters drawn from the prior and
data simulated from them (eq. 7), the rank of the true value among ``L`` posterior draws is
uniform on ``0..L``, and a central ``q`` credible interval contains the truth with probability
``q``. This module checks both for the paper's methods:

1. draw ``(a, tau)`` from the inference prior (:class:`~bayespig.likelihood.Priors`: ``a``
   uniform on [0, 1], ``tau`` log-uniform on [0.01, 100]), one replicate per draw;
2. simulate the method's design with the multiplicative noise of eq. (7) through the same
   look-up table the likelihood uses (SBC checks the computation of the posterior of a model,
   so data and likelihood share it);
3. sample every replicate's posterior with :func:`bayespig.inference.infer_problem` (the
   replicates are the "wavelengths" of one simulated set, so they run in parallel through the
   executor, each with its own child seed);
4. rank the truth among ``L`` draws spread evenly over the pooled chains; test the rank
   histogram for uniformity (chi-square, ``n_bins`` bins) and the 50 % / 90 % central-interval
   coverage against the binomial distribution (two-sided exact test).

Run ``python -m bayespig.studies.calibration`` to regenerate ``reports/calibration.md`` and
its figure.

References
----------
Talts, Betancourt, Simpson, Vehtari & Gelman (2018), Validating Bayesian inference algorithms
with simulation-based calibration, arXiv:1804.06788.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from .._atomic import atomic_path, write_text_atomically
from .._validation import flag, integer, real_scalar
from ..instruments import get_instrument
from ..likelihood import Priors, Problem, method_name

__all__ = [
    "CalibrationResult",
    "plot_rank_histograms",
    "simulation_based_calibration",
    "write_calibration_report",
]

#: Significance level of the uniformity and coverage tests (issue 6: 1 %).
ALPHA = 0.01
#: Central credible intervals whose coverage is checked.
LEVELS = (0.5, 0.9)
#: Shorter runs for slowly mixing posteriors (method 3's ravines, tau_int of 100-500 steps):
#: 20 instead of 50 autocorrelation times and ESS >= 400 instead of 1000 — still well above the
#: L = 199 draws ranked, which is what SBC needs (nearly independent draws).
SHORT_RUNS_KW = {"min_autocorr_multiple": 20.0, "target_ess": 400.0, "draws_per_chain": 256,
                 "max_steps": 5000}


def _short_runs():
    from ..inference import InferenceSettings

    return InferenceSettings(**SHORT_RUNS_KW)


#: Wavelengths labelling the replicates of the simulated set [nm] (any increasing values).
_FIRST_LABEL_NM = 1000.0
#: The designs simulation_based_calibration simulates and fits.
#: Largest relative error simulated: eq. (7) makes sense only well below this (the prior's
#: upper end, Priors.eps_range) [-].
_EPS_MAX = 0.5


@dataclass(frozen=True)
class CalibrationResult:
    """Ranks and coverage of one SBC study.

    Attributes
    ----------
    method : str
    parameters : tuple of str
        ``("a", "log_tau")``.
    truth : numpy.ndarray
        Shape (n_replicates, n_parameters): the prior draws (``a``, ``log tau``).
    ranks : numpy.ndarray
        Shape (n_replicates, n_parameters): rank of the truth among ``n_draws`` posterior
        draws, in ``0..n_draws``.
    inside : dict
        Level -> bool array (n_replicates, n_parameters): the truth inside the central interval.
    n_draws : int
        ``L``, posterior draws ranked against.
    n_bins : int
        Bins of the rank histogram.
    n_capped : int
        Replicates whose run reached ``max_steps``.
    seed, eps, instrument, settings, elapsed_s
        What was run, and how long it took [s].
    """

    method: str
    parameters: tuple
    truth: np.ndarray
    ranks: np.ndarray
    inside: dict
    n_draws: int
    n_bins: int
    n_capped: int
    seed: int
    eps: float
    instrument: str
    settings: str
    elapsed_s: float
    versions: dict = field(default_factory=dict)

    @property
    def n_replicates(self):
        """Number of replicates."""
        return self.ranks.shape[0]

    def histogram(self, k):
        """Counts of parameter ``k``'s ranks in ``n_bins`` equal bins of ``0..n_draws``."""
        edges = np.linspace(0, self.n_draws + 1, self.n_bins + 1)
        return np.histogram(self.ranks[:, k], bins=edges)[0]

    def uniformity_p_value(self, k):
        """Chi-square test of the rank histogram of parameter ``k`` against uniform."""
        from scipy import stats

        counts = self.histogram(k)
        return float(stats.chisquare(counts).pvalue)

    def coverage(self, level, k):
        """Fraction of replicates whose central ``level`` interval of parameter ``k`` holds the truth."""
        return float(self.inside[level][:, k].mean())

    def coverage_p_value(self, level, k):
        """Two-sided exact binomial test of the coverage against ``level``."""
        from scipy import stats

        hits = int(self.inside[level][:, k].sum())
        return float(stats.binomtest(hits, self.n_replicates, level).pvalue)

    def passed(self, alpha=ALPHA):
        """Every uniformity and coverage test passes at ``alpha``."""
        return all(
            self.uniformity_p_value(k) >= alpha
            and all(self.coverage_p_value(level, k) >= alpha for level in LEVELS)
            for k in range(len(self.parameters))
        )

    def rows(self):
        """One dict per parameter: p-values and coverage (for reports)."""
        out = []
        for k, name in enumerate(self.parameters):
            row = {"method": self.method, "parameter": name, "chi2_p": self.uniformity_p_value(k)}
            for level in LEVELS:
                row[f"coverage_{int(level * 100)}"] = self.coverage(level, k)
                row[f"coverage_{int(level * 100)}_p"] = self.coverage_p_value(level, k)
            out.append(row)
        return out


def _draw_prior(priors, n, rng):
    a = rng.uniform(priors.a_range[0], priors.a_range[1], n)
    log_tau = rng.uniform(np.log(priors.tau_range[0]), np.log(priors.tau_range[1]), n)
    return a, log_tau


def simulation_based_calibration(method="method4", *, n_replicates=200, n_draws=199, n_bins=10,
                                 seed=0, eps=0.05, instrument="multi-angle-45", settings=None,
                                 executor=None, progress=False):
    """SBC of the posterior of one of the paper's methods (Talts et al. 2018).

    Parameters
    ----------
    method : {"method3", "method4", "method2", "method1"}
        The design simulated and fitted (section 3); ``4`` or ``"4"`` also mean
        ``"method4"``.
    n_replicates : int
        Prior draws (issue 6: at least 200 for the report).
    n_draws : int
        ``L``: posterior draws the truth is ranked against, spread evenly over the stored draws
        of all chains (well below the ESS, so they are nearly independent).
    n_bins : int
        Bins of the rank histogram (``n_draws + 1`` must be a multiple).
    seed : int
        Seeds the prior draws, the noise and every run.
    eps : float
        Relative measurement error of eq. (7), known to the likelihood, in (0, 0.5] [-].
    instrument : str
        Built-in instrument.
    settings : InferenceSettings, optional
    executor : concurrent.futures.Executor, optional
        As for :func:`bayespig.infer`.
    progress : bool

    Returns
    -------
    CalibrationResult
    """
    from ..data import simulate
    from ..inference import ConvergenceWarning, InferenceSettings, _versions, infer_problem
    from ..table import load_table

    method = method_name(method, also=())  # 4, "4" and "method4" alike
    n_replicates = integer("n_replicates", n_replicates, low=2)
    n_draws = integer("n_draws", n_draws, low=1)
    n_bins = integer("n_bins", n_bins, low=1)
    seed = integer("seed", seed, low=0)
    eps = real_scalar("eps", eps, low=0.0, high=_EPS_MAX, low_open=True)
    if not isinstance(instrument, str):
        raise TypeError(f"instrument must be a built-in instrument name, got {instrument!r} ({type(instrument).__name__})")
    get_instrument(instrument)
    if settings is not None and not isinstance(settings, InferenceSettings):
        raise TypeError(f"settings must be an InferenceSettings or None, got {settings!r} ({type(settings).__name__})")
    flag("progress", progress)
    if (n_draws + 1) % n_bins:
        raise ValueError(f"n_draws + 1 ({n_draws + 1}) must be a positive multiple of n_bins ({n_bins})")
    settings = InferenceSettings() if settings is None else settings
    priors = Priors()
    started = time.perf_counter()
    prior_seed, noise_seed, run_seed = np.random.SeedSequence(seed).generate_state(3)
    a, log_tau = _draw_prior(priors, n_replicates, np.random.default_rng(prior_seed))
    table = load_table(instrument, progress=False)
    measurements = simulate(a=a, tau=np.exp(log_tau), design=method, instrument=instrument,
                            wavelengths=_FIRST_LABEL_NM + np.arange(n_replicates), eps=eps,
                            seed=int(noise_seed), model=table)
    problem = Problem.from_measurements(measurements, method)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # capped runs are counted below
        idata = infer_problem(problem, seed=int(run_seed), eps=eps, executor=executor,
                              progress=progress, priors=priors, settings=settings)
    post = idata.posterior
    samples = np.stack([post["a"].values, np.log(post["tau"].values)], axis=-1)  # chain, draw, rep, P
    pooled = np.moveaxis(samples, 2, 0).reshape(n_replicates, -1, 2)  # rep, chain*draw, P
    pick = np.round(np.linspace(0, pooled.shape[1] - 1, n_draws)).astype(int)
    ranked = pooled[:, pick]
    truth = np.column_stack([a, log_tau])
    ranks = (ranked < truth[:, None, :]).sum(axis=1)
    inside = {}
    for level in LEVELS:
        low = np.quantile(pooled, (1 - level) / 2, axis=1)
        high = np.quantile(pooled, (1 + level) / 2, axis=1)
        inside[level] = (low <= truth) & (truth <= high)
    return CalibrationResult(
        method=method, parameters=("a", "log_tau"), truth=truth, ranks=ranks, inside=inside,
        n_draws=n_draws, n_bins=n_bins,
        n_capped=int(idata.sample_stats["max_steps_reached"].values.sum()), seed=int(seed),
        eps=float(eps), instrument=str(instrument), settings=settings.to_json(),
        elapsed_s=time.perf_counter() - started, versions=_versions(),
    )


def plot_rank_histograms(results, path):
    """Rank histograms (one panel per method and parameter) with the 99 % band of uniform counts.

    Written atomically as PNG.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy import stats

    results = list(results)
    n_rows = len(results)
    fig, axes = plt.subplots(n_rows, 2, figsize=(8, 2.6 * n_rows), squeeze=False)
    for row, result in enumerate(results):
        expected = result.n_replicates / result.n_bins
        p = 1.0 / result.n_bins
        low, high = stats.binom.ppf([ALPHA / 2, 1 - ALPHA / 2], result.n_replicates, p)
        for k, name in enumerate(result.parameters):
            ax = axes[row, k]
            counts = result.histogram(k)
            ax.bar(np.arange(result.n_bins), counts, width=0.9, color="#4c72b0")
            ax.axhspan(low, high, color="0.85", zorder=0)
            ax.axhline(expected, color="0.3", lw=0.8)
            ax.set_title(f"{result.method}: {name}  (chi² p = {result.uniformity_p_value(k):.2f}, "
                         f"N = {result.n_replicates})", fontsize=9)
            ax.set_xlabel(f"rank bin (L = {result.n_draws})")
            ax.set_xticks([])
    fig.tight_layout()
    path = os.fspath(path)
    try:
        with atomic_path(path, suffix=".png") as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
    return path


def write_calibration_report(path, results, *, figure=None, command=None):
    """Markdown report of SBC results (tables, verdicts, figure), written atomically."""
    results = list(results)
    first = results[0]
    lines = [
        "# Simulation-based calibration of the posteriors",
        "",
        "Does `bayespig.infer` draw from the right posterior? Simulation-based calibration (Talts et",
        "al. 2018): parameters drawn from the prior (`a` uniform on [0, 1], `tau` log-uniform on",
        "[0.01, 100] — the inference prior), data simulated from them with the paper's noise",
        f"(eq. 7, eps = {first.eps:g}, known) through the look-up table of the likelihood, one emcee",
        "run per replicate (settings per method below); then the rank of the truth among L posterior",
        "draws must be uniform, and central credible intervals must cover the truth at their level.",
        "Runs that reached max_steps are kept (counted below): SBC then also tests whether such",
        "truncated runs still give calibrated intervals.",
        "",
        f"Regenerate: `{command or 'python -m bayespig.studies.calibration'}`",
        "",
        (f"Instrument `{first.instrument}`; bayespig {first.versions.get('bayespig_version', '?')}, "
        f"emcee {first.versions.get('emcee_version', '?')}, arviz {first.versions.get('arviz_version', '?')}, "
        f"numpy {first.versions.get('numpy_version', '?')}."),
        "",
        ("| method | parameter | replicates | chi² p (uniform ranks) | 50 % coverage (p) | "
        "90 % coverage (p) | verdict at 1 % |"),
        "|---|---|---|---|---|---|---|",
    ]
    for result in results:
        for row in result.rows():
            ok = row["chi2_p"] >= ALPHA and row["coverage_50_p"] >= ALPHA and row["coverage_90_p"] >= ALPHA
            lines.append(
                f"| {row['method']} | {row['parameter']} | {result.n_replicates} | {row['chi2_p']:.3f} | "
                f"{row['coverage_50']:.3f} ({row['coverage_50_p']:.2f}) | "
                f"{row['coverage_90']:.3f} ({row['coverage_90_p']:.2f}) | {'pass' if ok else 'FAIL'} |")
    lines += [""]
    for result in results:
        binomial = [np.sqrt(level * (1 - level) / result.n_replicates) for level in LEVELS]
        lines.append(
            f"- {result.method}: {result.n_replicates} replicates, L = {result.n_draws} draws, "
            f"{result.n_bins} bins; {result.n_capped} run(s) reached max_steps; "
            f"{result.elapsed_s:.0f} s; binomial sd of the coverage "
            f"{binomial[0]:.3f} (50 %) and {binomial[1]:.3f} (90 %); seed {result.seed}; settings "
            f"`{result.settings}`.")
    if figure is not None:
        lines += ["", f"![rank histograms]({os.path.basename(os.fspath(figure))})", "",
                  "Grey band: 99 % range of a bin count under uniform ranks; line: its expectation."]
    lines.append("")
    text = "\n".join(lines)
    path = os.fspath(path)
    write_text_atomically(path, text)
    return path


def main(argv=None):
    """``python -m bayespig.studies.calibration``: SBC of methods 4 and 3, report and figure."""
    parser = argparse.ArgumentParser(description="Simulation-based calibration (Talts et al. 2018)")
    parser.add_argument("--methods", default="method4,method3")
    parser.add_argument("--n-replicates", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="reports/calibration.md")
    parser.add_argument("--figure", default="reports/calibration-ranks.png")
    parser.add_argument("--short-runs", default="",
                        help="methods run with SHORT_RUNS settings (20 tau_int, ESS 400, <= 5000 steps) "
                             "instead of the defaults, e.g. method3")
    parser.add_argument("--json", default=None, help="also write the ranks as JSON")
    args = parser.parse_args(argv)
    short = {m.strip() for m in args.short_runs.split(",") if m.strip()}
    results = []
    for method in (m.strip() for m in args.methods.split(",") if m.strip()):
        result = simulation_based_calibration(method, n_replicates=args.n_replicates, seed=args.seed,
                                              progress=True, settings=_short_runs() if method in short else None)
        for row in result.rows():
            print(json.dumps(row), flush=True)
        results.append(result)
    plot_rank_histograms(results, args.figure)
    command = ("python -m bayespig.studies.calibration"
               + ("" if args.n_replicates == 200 else f" --n-replicates {args.n_replicates}")
               + ("" if args.seed == 0 else f" --seed {args.seed}")
               + (f" --short-runs {args.short_runs}" if short else ""))
    write_calibration_report(args.out, results, figure=args.figure, command=command)
    if args.json:
        record = [{"method": r.method, "truth": r.truth.tolist(), "ranks": r.ranks.tolist()} for r in results]
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(record, handle)
    print(f"wrote {args.out} and {args.figure}")
    return 0 if all(r.passed() for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
