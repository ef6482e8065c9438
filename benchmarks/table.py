"""Benchmark of the look-up tables: build, load, evaluation speed and accuracy (issue 3).

Run from the repository root::

    python benchmarks/table.py            # everything (several minutes)
    python benchmarks/table.py --skip-g   # isotropic tables only (~1 minute)

Prints

* the build time of the default isotropic table of every built-in instrument and of the
  table with a ``g`` axis for ``"multi-angle-45"`` (``--g-all``: every instrument) (goals:
  <= 10 s and <= 60 s on 2 cores), with the CPU time the build used (a figure the machine's
  other load does not change much; CPU / 2 is the wall time on 2 free cores);
* the time to load a table from the cache (goal: <= 0.2 s);
* the evaluation time per call and the throughput in channel values per second for 1, 16,
  64 and 10,000 parameter sets per call, and the ratio of one likelihood-sized evaluation
  (one (a, tau) on a black and a white substrate: 2 x 6 values) through the table against the
  direct solver (``bayespig.predict``; goal: >= 1000x), also per walker for a 64-walker
  ensemble in one call, through the table and through the likelihood's fast path
  (``WavelengthModel``, method 4);
* the largest relative error against the direct solver at 2,000 random points over the whole
  domain (the sampler of the table tests, ``bayespig._validation``: shares near a -> 0, a -> 1, tau -> 0, large
  tau, opaque, r_s = 0 and 1), per instrument, and for the g table with 40 values of g.

Tables are built into a temporary cache directory, so the user's cache is neither used nor
changed. The machine may be shared: timings are wall-clock (best of several repeats for the
evaluations); the load average is printed with them.
"""

import argparse
import os
import platform
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import bayespig
from bayespig._validation import domain_points  # the tests' domain sampler
from bayespig.data import simulate
from bayespig.instruments import BUILT_IN_INSTRUMENTS, Instrument, predict
from bayespig.likelihood import ForwardModel, Problem
from bayespig.table import load_table

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import load_average

INSTRUMENT = "multi-angle-45"
SEED = 20240603
N_POINTS = 2000
#: Distinct g values of the g-table accuracy check (the direct solver pays per g).
N_G_VALUES = 40
LOAD_REPEATS = 5
WALKERS = 64
#: One likelihood-sized evaluation: one (a, tau) on black and on white (paper's method 4).
ONE = {"a": 0.05, "tau": 2.0, "r_s": np.array([0.01, 0.95])}


def best_time(function, min_total=0.5, min_repeats=5):
    """Smallest wall time of one call [s], repeating for at least ``min_total`` seconds."""
    times = []
    start = time.perf_counter()
    while len(times) < min_repeats or time.perf_counter() - start < min_total:
        t0 = time.perf_counter()
        function()
        times.append(time.perf_counter() - t0)
    return min(times)


def cpu_seconds():
    """CPU time of this process and its finished children [s]."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def line(label, text):
    print(f"{label:<48} {text}", flush=True)


def relative_error(values, reference):
    return np.abs(values - reference) / np.maximum(np.abs(reference), 1e-12)


def timed_build(name, cache, g):
    start, cpu = time.perf_counter(), cpu_seconds()
    table = load_table(name, g=g, cache_dir=cache, progress=False)
    return table, time.perf_counter() - start, cpu_seconds() - cpu


def evaluation_figures(table, rng, direct_seconds, g=None):
    """Per-call times and throughput of ``table`` for several batch sizes."""
    g_range = table.settings.g_range
    extra = {} if g is None else {"g": g}
    t_one = best_time(lambda: table(**ONE, **extra))
    line("  1 set x 2 substrates (2 x 6 values):",
         f"{t_one * 1e6:7.1f} us per call; direct solver {direct_seconds * 1e3:.1f} ms: "
         f"ratio {direct_seconds / t_one:.0f}x   (goal >= 1000x)")
    a = rng.uniform(0.01, 0.5, (WALKERS, 1))
    tau = rng.uniform(0.5, 20.0, (WALKERS, 1))
    g_w = {} if g_range is None else {"g": rng.uniform(*g_range, (WALKERS, 1))}
    t_ens = best_time(lambda: table(a=a, tau=tau, r_s=ONE["r_s"], **g_w))
    line(f"  {WALKERS} sets x 2 substrates in one call:",
         f"{t_ens * 1e6:7.1f} us per call, {t_ens / WALKERS * 1e6:.2f} us per set: "
         f"ratio {direct_seconds / (t_ens / WALKERS):.0f}x per set")
    for size in (16, 10_000):
        a = rng.uniform(0.0, 1.0, size) ** 2
        tau = np.exp(rng.uniform(np.log(1e-3), np.log(100.0), size))
        r_s = rng.uniform(0.0, 1.0, size)
        g_s = {} if g_range is None else {"g": rng.uniform(*g_range, size)}
        seconds = best_time(lambda a=a, tau=tau, r_s=r_s, g_s=g_s: table(a=a, tau=tau, r_s=r_s, **g_s))
        line(f"  throughput, {size} sets per call:",
             f"{size * len(table.channels) / seconds:10.3g} channel values/s ({seconds * 1e3:.2f} ms per call)")


def likelihood_figures(table, rng, direct_seconds, g_free):
    """Per-walker time of the likelihood's fast path (method 4: one film on black and white)."""
    measurements = simulate(a=0.05, tau=2.0, design="method4", instrument=INSTRUMENT,
                            wavelengths=[550.0], eps=0.0, seed=0, model=table)
    problem = Problem.from_measurements(measurements, method="method4")
    tables = {film.instrument: table for film in problem.films if film.instrument is not None}
    model = ForwardModel(problem, g="free" if g_free else "isotropic", tables=tables)
    fast = model.at_wavelength(0)
    a = rng.uniform(0.01, 0.5, WALKERS)
    tau = rng.uniform(0.5, 20.0, (WALKERS, 1))
    g = rng.uniform(*table.settings.g_range, WALKERS) if g_free else None
    t_fast = best_time(lambda: fast(a, tau, g))
    line(f"  WavelengthModel, {WALKERS} walkers x {problem.n_values} values:",
         f"{t_fast * 1e6:7.1f} us per call, {t_fast / WALKERS * 1e6:.2f} us per walker: "
         f"ratio {direct_seconds / (t_fast / WALKERS):.0f}x per walker")
    t_one = best_time(lambda: fast(a[:1], tau[:1], None if g is None else g[:1]))
    line(f"  WavelengthModel, 1 walker x {problem.n_values} values:",
         f"{t_one * 1e6:7.1f} us per call: ratio {direct_seconds / t_one:.0f}x")


def union_instrument():
    channels, columns = [], {}
    for name in BUILT_IN_INSTRUMENTS:
        columns[name] = slice(len(channels), len(channels) + len(BUILT_IN_INSTRUMENTS[name]))
        channels.extend(BUILT_IN_INSTRUMENTS[name])
    return Instrument("union", tuple(channels)), columns


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-g", action="store_true", help="skip the tables with a g axis")
    parser.add_argument("--g-all", action="store_true",
                        help="build a g table for every built-in instrument (not only multi-angle-45)")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(SEED)
    print(f"bayespig {bayespig.__version__}, numpy {np.__version__}, "
          f"Python {platform.python_version()}, {os.cpu_count()} cores")
    print(f"load average at start: {load_average()}")
    with tempfile.TemporaryDirectory(prefix="bayespig-bench-") as cache:
        cache = Path(cache)
        print("\n-- isotropic tables (n = 1.45) --")
        tables = {}
        for name in BUILT_IN_INSTRUMENTS:
            tables[name], wall, cpu = timed_build(name, cache, "isotropic")
            line(f"build, {name} ({len(tables[name].channels)} channels):",
                 f"{wall:7.2f} s   (CPU {cpu:.1f} s; goal <= 10 s; includes writing the cache)")
        load_times = []
        for _ in range(LOAD_REPEATS):
            start = time.perf_counter()
            load_table(INSTRUMENT, cache_dir=cache, progress=False)
            load_times.append(time.perf_counter() - start)
        line(f"load from cache, {INSTRUMENT}:", f"{np.median(load_times):7.3f} s   (goal <= 0.2 s; median of "
             f"{LOAD_REPEATS})")

        direct = best_time(lambda: predict(INSTRUMENT, **ONE), min_total=2.0)
        print(f"\nevaluation, {INSTRUMENT} isotropic table (direct solver: {direct * 1e3:.1f} ms per "
              "(a, tau) on 2 substrates):")
        evaluation_figures(tables[INSTRUMENT], rng, direct)
        likelihood_figures(tables[INSTRUMENT], rng, direct, g_free=False)

        a, tau, r_s = domain_points(rng, N_POINTS)
        union, columns = union_instrument()
        reference = predict(union, a=a, tau=tau, r_s=r_s)
        print(f"\naccuracy, {N_POINTS} random points over the domain (max |table / solver - 1|; goal <= 2e-4):")
        for name, table in tables.items():
            error = relative_error(table(a=a, tau=tau, r_s=r_s), reference[:, columns[name]])
            line(f"  {name}:", f"max {error.max():.2e}, 99th percentile {np.percentile(error.max(axis=1), 99):.1e}")

        if not args.skip_g:
            names = list(BUILT_IN_INSTRUMENTS) if args.g_all else [INSTRUMENT]
            for name in names:
                table_g, wall, cpu = timed_build(name, cache, "free")
                s = table_g.settings
                print(f"\n-- g table, {name}: g in {s.g_range}, {s.n_g} nodes uniform in {s.g_axis}(g), "
                      f"{s.g_stencil}-node stencil --")
                line("build (2 worker processes):", f"{wall:7.1f} s   (CPU {cpu:.0f} s; goal <= 60 s on 2 cores; "
                     f"load average now {load_average()})")
                start = time.perf_counter()
                load_table(name, g="free", cache_dir=cache, progress=False)
                line("load from cache:", f"{time.perf_counter() - start:7.3f} s")
                g_values = rng.uniform(*s.g_range, N_G_VALUES)
                g_values[:2] = s.g_range  # the ends of the axis
                g = np.repeat(g_values, N_POINTS // N_G_VALUES)
                a, tau, r_s = domain_points(rng, N_POINTS)
                error = relative_error(table_g(a=a, tau=tau, g=g, r_s=r_s),
                                       predict(name, a=a, tau=tau, g=g, r_s=r_s))
                per_g = error.reshape(N_G_VALUES, -1).max(axis=1)
                worst = np.argsort(per_g)[-3:][::-1]
                line(f"accuracy, {N_POINTS} points, {N_G_VALUES} values of g:",
                     f"max {error.max():.2e}, 99th percentile {np.percentile(error.max(axis=1), 99):.1e} "
                     "(goal <= 2e-4); worst g: " + ", ".join(f"{g_values[i]:+.3f} ({per_g[i]:.1e})" for i in worst))
                if name == INSTRUMENT:
                    direct_g = best_time(lambda: predict(INSTRUMENT, **ONE, g=0.3), min_total=2.0)
                    print(f"evaluation, g table (direct solver at g = 0.3: {direct_g * 1e3:.1f} ms per (a, tau) "
                          "on 2 substrates):")
                    evaluation_figures(table_g, rng, direct_g, g=0.3)
                    likelihood_figures(table_g, rng, direct_g, g_free=True)
    print(f"\nload average at end: {load_average()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
