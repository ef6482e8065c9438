"""Benchmark of Bayesian inference (issue 6): time per wavelength, full spectrum, moves.

Run from the repository root::

    python benchmarks/inference.py            # prints; updates reports/benchmarks.md
    python benchmarks/inference.py --no-write # prints only

Measures, for method 4 (one film on black and on white, 2 samples x 6 geometries of the
``multi-angle-45`` instrument, a0 = 0.1, tau0 = 1, eps = 0.05):

1. wall time per wavelength (goal <= 0.3 s) with the default settings (4 ensembles x 16
   walkers per wavelength, run until >= 50 tau_int and ESS >= 1000 for every parameter):
   a. ``bayespig.infer`` end to end (point fits, sampling, posterior predictive, pointwise
      log-likelihood, InferenceData) of a 31-band spectrum on ONE core (an in-process
      executor), divided by 31: the wavelengths run in stacks of ``wavelengths_per_run`` (16)
      in one sampler each, so this is the cost per wavelength of a real job;
   b. one wavelength on its own (a stack of one: start, sampling, predictive), serially, at
      N_SINGLE wavelengths, with the arviz ESS reached;
2. wall time of ``bayespig.infer`` on a 31-band spectrum (400-700 nm) with the default
   executor (a local pool of 2 processes), end to end (goal <= 10 s);
3. the same sampler with the direct adding-doubling solver (``bayespig.predict``) in the
   likelihood instead of the look-up table: time per log-probability call of the 32 walkers
   of a half-step, and of a fixed number of steps, for two wavelengths (the ratio);
4. mixing of the moves on method 3's ravine and on method 4: integrated autocorrelation
   times (steps) of ``a`` and ``log tau`` for a fixed run of every move mixture (same start,
   same seed), and a figure of the autocorrelation functions
   (``reports/inference-moves.png``).

The look-up table is loaded before the clock starts. The machine may be shared: timings are
wall-clock with the load average printed. The section "## Inference" of reports/benchmarks.md
is replaced (other sections kept), atomically.
"""

import argparse
import os
import platform
import sys
import time
from concurrent.futures import Future
from pathlib import Path

import numpy as np
from _common import Transcript, load_average, write_run_section

import bayespig
from bayespig._atomic import atomic_path
from bayespig.data import simulate
from bayespig.inference import (
    MOVES,
    InferenceSettings,
    _autocorr_times,
    _initial_walkers,
    _moves,
    _point_starts,
    _sample_wavelength,
    _wavelength_outputs,
    infer,
    summarize,
)
from bayespig.likelihood import ForwardModel, LogPosterior, Priors, Problem
from bayespig.physics.forward import specular_transmittance

ROOT = Path(__file__).resolve().parent.parent
FIGURE = ROOT / "reports" / "inference-moves.png"
SECTION = "## Inference"
GOAL_PER_WAVELENGTH = 0.3
GOAL_SPECTRUM = 10.0
A0, TAU0, EPS = 0.1, 1.0, 0.05
N_SINGLE = 8  # wavelengths timed one at a time
MOVE_STEPS = 6000  # fixed run per move mixture for the tau_int comparison


def problem_of(design, wavelengths, seed=1):
    ms = simulate(a=A0, tau=TAU0, design=design, wavelengths=wavelengths, eps=EPS, seed=seed)
    return Problem.from_measurements(ms, design)


def per_wavelength(settings):
    """Serial wall time of complete runs at N_SINGLE wavelengths, and the ESS reached."""
    import arviz as az

    problem = problem_of("method4", np.linspace(400.0, 700.0, N_SINGLE))
    model = ForwardModel(problem)
    log_post0 = LogPosterior(model, 0, Priors(), eps=EPS)
    starts, _ = _point_starts(problem, "isotropic", model.tables, Priors(), log_post0, N_SINGLE)
    seeds = np.random.SeedSequence(0).spawn(N_SINGLE)
    times, ess, steps = [], [], []
    # warm-up (imports, first-call overheads)
    _sample_wavelength(LogPosterior(model, 0, Priors(), eps=EPS), starts[0], settings, seeds[0])
    for i in range(N_SINGLE):
        start = time.perf_counter()
        log_post = LogPosterior(model, i, Priors(), eps=EPS)
        run = _sample_wavelength(log_post, starts[i], settings, seeds[i])
        steps.append(run["n_steps"])
        out = _wavelength_outputs(log_post, run, settings)
        times.append(time.perf_counter() - start)
        ess.append(min(az.ess(out["a"], method=m) for m in ("bulk", "tail")))
        ess.append(min(az.ess(np.log(out["tau"][..., 0]), method=m) for m in ("bulk", "tail")))
    return np.array(times), np.array(ess), np.array(steps)


class InlineExecutor:
    """``submit`` runs the task at once in this process: one core."""

    def submit(self, fn, *args):
        future = Future()
        future.set_result(fn(*args))
        return future


def spectrum(executor=None):
    """End-to-end ``infer`` of a 31-band method-4 spectrum (default: the 2-process pool)."""
    ms = simulate(a=A0, tau=TAU0, design="method4", eps=EPS, seed=2)
    start = time.perf_counter()
    idata = infer(ms, seed=0, progress=False, executor=executor)
    elapsed = time.perf_counter() - start
    summary = summarize(idata)
    worst = min(summary[[f"{p}_ess_{k}" for p in ("a", "tau") for k in ("bulk", "tail")]].min())
    return elapsed, worst, float(summary[["a_r_hat", "tau_r_hat"]].max().max()), ms.n_wavelengths


class DirectPredictions:
    """Every film's values from the adding-doubling solver itself (no table)."""

    def __init__(self, problem, index):
        self.problem, self.index = problem, index

    def __call__(self, a, tau, g=None, member=None):
        parts = []
        groups = self.problem.groups
        for film in self.problem.films:
            film_tau = np.full(a.shape, np.inf) if film.opaque else tau[:, groups.index(film.group)]
            if film.kind == "transmittance":
                parts.append(specular_transmittance(film_tau, self.problem.n)[:, None])
            else:
                parts.append(bayespig.predict(film.instrument, a=a, tau=film_tau,
                                              r_s=float(film.r_s[self.index])))
        return np.concatenate(parts, axis=1)


def direct_ratio(settings, n_steps=20, wavelengths=(450.0, 650.0)):
    """Per-call and per-step time of the table and of the direct solver in the likelihood."""
    import emcee

    problem = problem_of("method4", list(wavelengths))
    model = ForwardModel(problem)
    rows = []
    for index in range(len(wavelengths)):
        table_post = LogPosterior(model, index, Priors(), eps=EPS)
        direct_post = LogPosterior(model, index, Priors(), eps=EPS)
        direct_post.evaluate = DirectPredictions(problem, index)
        starts, _ = _point_starts(problem, "isotropic", model.tables, Priors(), table_post, len(wavelengths))
        n_total = settings.n_walkers * settings.n_ensembles
        walkers = _initial_walkers(table_post, starts[index], n_total, settings.jitter,
                                   np.random.default_rng(0))
        half = walkers[: n_total // 2]
        timing = {}
        for name, post in (("table", table_post), ("direct", direct_post)):
            repeats = 200 if name == "table" else 3
            post(half)
            start = time.perf_counter()
            for _ in range(repeats):
                post(half)
            per_call = (time.perf_counter() - start) / repeats
            sampler = emcee.EnsembleSampler(n_total, post.n_dim, post, vectorize=True, moves=_moves(settings, post.n_dim))
            sampler.random_state = np.random.RandomState(0).get_state()
            start = time.perf_counter()
            sampler.run_mcmc(walkers, n_steps, progress=False)
            per_step = (time.perf_counter() - start) / n_steps
            timing[name] = (per_call, per_step)
        rows.append((wavelengths[index], timing))
    return rows


def moves_comparison(settings):
    """tau_int (steps) of a and log tau per move mixture, method 3 and method 4; ACF curves."""
    import emcee

    out = {}
    curves = {}
    for design in ("method3", "method4"):
        problem = problem_of(design, [550.0], seed=21)
        model = ForwardModel(problem)
        post = LogPosterior(model, 0, Priors(), eps=EPS)
        starts, _ = _point_starts(problem, "isotropic", model.tables, Priors(), post, 1)
        n_total = settings.n_walkers * settings.n_ensembles
        for moves in MOVES:
            s = InferenceSettings(**{**settings.__dict__, "moves": moves})
            walkers = _initial_walkers(post, starts[0], n_total, s.jitter, np.random.default_rng(0))
            sampler = emcee.EnsembleSampler(n_total, post.n_dim, post, vectorize=True, moves=_moves(s, post.n_dim))
            sampler.random_state = np.random.RandomState(1).get_state()
            start = time.perf_counter()
            sampler.run_mcmc(walkers, MOVE_STEPS, progress=False)
            elapsed = time.perf_counter() - start
            chain = sampler.get_chain(discard=MOVE_STEPS // 5)
            tau = _autocorr_times(chain, s.n_ensembles)
            acceptance = float(sampler.acceptance_fraction.mean())
            out[(design, moves)] = (tau, acceptance, elapsed)
            acf = np.mean([emcee.autocorr.function_1d(chain[:, w, 0]) for w in range(n_total)], axis=0)
            curves[(design, moves)] = acf[:1000]
    return out, curves


def plot_moves(curves, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4), sharey=True)
    for ax, design in zip(axes, ("method3", "method4")):
        for moves in MOVES:
            acf = curves[(design, moves)]
            ax.plot(np.arange(acf.size), acf, label=moves)
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_xscale("symlog", linthresh=10)
        ax.set_xlim(0, max(c.size for c in curves.values()))
        ax.set_xlabel("lag [steps]")
        ax.set_title(f"{design}: autocorrelation of a (a0={A0:g}, tau0={TAU0:g})", fontsize=9)
    axes[0].set_ylabel("normalised autocorrelation")
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as temporary:
        fig.savefig(temporary, dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--no-write", action="store_true", help="print only")
    parser.add_argument("--skip-moves", action="store_true", help="skip the move comparison")
    args = parser.parse_args(argv)
    settings = InferenceSettings()
    say = Transcript(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
                     f"python {platform.python_version()}, load average at start {load_average()}")
    spectrum()  # warm-up: imports, tables in this process and in the pool's
    one_core, one_core_ess, one_core_rhat, n_bands = spectrum(InlineExecutor())
    per_band = one_core / n_bands
    say(f"method 4, {n_bands}-band spectrum, infer() on one core (stacks of "
        f"{settings.wavelengths_per_run}): {one_core:.2f} s = {per_band:.3f} s per wavelength "
        f"(min ESS {one_core_ess:.0f}, max R-hat {one_core_rhat:.4f})")
    times, ess, steps = per_wavelength(settings)
    say(f"method 4, one wavelength on its own, serial ({N_SINGLE} wavelengths): median "
        f"{np.median(times):.3f} s, max {times.max():.3f} s; steps median {int(np.median(steps))}; "
        f"min ESS (bulk/tail, a and log tau) {ess.min():.0f}")
    elapsed, worst_ess, worst_rhat, _ = spectrum()
    say(f"method 4, 31-band spectrum, infer() on the default 2-process pool: {elapsed:.2f} s "
        f"(min ESS {worst_ess:.0f}, max R-hat {worst_rhat:.4f}); load average {load_average()}")
    for wavelength, timing in direct_ratio(settings):
        (tc, ts), (dc, ds) = timing["table"], timing["direct"]
        say(f"{wavelength:g} nm: log-prob call of 32 walkers: table {tc * 1e3:.3f} ms, direct solver "
            f"{dc * 1e3:.1f} ms (x{dc / tc:.0f}); per step: table {ts * 1e3:.2f} ms, direct {ds * 1e3:.0f} "
            f"ms (x{ds / ts:.0f}); a run of {int(np.median(steps))} steps would take "
            f"{ds * np.median(steps):.0f} s with the direct solver")
    move_rows = []
    if not args.skip_moves:
        results, curves = moves_comparison(settings)
        for (design, moves), (tau, acceptance, run_time) in results.items():
            line = (f"{design} {moves:>11}: tau_int a {tau[0]:7.1f}, log tau {tau[1]:7.1f} steps; "
                    f"acceptance {acceptance:.2f}; {MOVE_STEPS} steps in {run_time:.1f} s")
            say(line)
            move_rows.append((design, moves, tau, acceptance))
        plot_moves(curves, FIGURE)
        print(f"wrote {FIGURE}")
    say(f"load average at end {load_average()}")
    if args.no_write:
        return 0
    median = float(np.median(times))
    description = [
        "Method 4 (one film on black and on white, 2 samples x 6 geometries of `multi-angle-45`,",
        f"a0 = {A0:g}, tau0 = {TAU0:g}, eps = {EPS:g}); default `InferenceSettings` (4 independent",
        "ensembles x 16 walkers per wavelength, moves \"auto\" (80 % Gaussian, 20 % DE), run until",
        ">= 50 tau_int and bulk and tail ESS >= 1000 for every parameter; up to 16 wavelengths",
        "share one sampler and one log-posterior call per half-step, each with its own ensembles",
        "and run length). The spectrum figures are `infer()` end to end; a run on its own includes",
        "the start, sampling, posterior predictive and pointwise log-likelihood. Wall-clock times",
        "with the load average.",
    ]
    after = [
        "| goal (issue 6) | measured | |",
        "|---|---|---|",
        (f"| per wavelength, method 4, ESS >= 1000 for a and tau: <= {GOAL_PER_WAVELENGTH:g} s "
         f"(31-band spectrum on one core, end to end, / 31) | {per_band:.2f} s | "
         f"{'met' if per_band <= GOAL_PER_WAVELENGTH else 'not met'} |"),
        (f"| the same for one wavelength on its own (a stack of one) | median {median:.2f} s | "
         f"{'met' if median <= GOAL_PER_WAVELENGTH else 'not met'} |"),
        (f"| 31-band spectrum on 2 cores <= {GOAL_SPECTRUM:g} s | {elapsed:.1f} s | "
         f"{'met' if elapsed <= GOAL_SPECTRUM else 'not met'} |"),
        "",
    ]
    if move_rows:
        after += [
            ("Mixing of the moves (fixed runs of "
             f"{MOVE_STEPS} steps, same start and seed; tau_int in steps, largest over the 4 ensembles):"),
            "",
            "| design | moves | tau_int(a) | tau_int(log tau) | acceptance |",
            "|---|---|---|---|---|",
            *[f"| {d} | {m} | {t[0]:.1f} | {t[1]:.1f} | {acc:.2f} |" for d, m, t, acc in move_rows],
            "",
            "![autocorrelation of a per move mixture](inference-moves.png)",
        ]
    write_run_section(SECTION, "python benchmarks/inference.py", description, say.lines, after)
    return 0


if __name__ == "__main__":
    sys.exit(main())
