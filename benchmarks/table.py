"""Benchmark of the look-up tables: build, load, evaluation speed and accuracy.

Run from the repository root::

    /tmp/venv/bin/python benchmarks/table.py            # isotropic and g-axis tables (minutes)
    /tmp/venv/bin/python benchmarks/table.py --skip-g   # isotropic table only (~1 minute)

Prints, for the 6-angle multi-angle instrument (``"multi-angle-45"``): the build time of the
default isotropic table and of the table with a ``g`` axis (goals: <= 10 s and <= 60 s on 2
cores), the time to load a table from the cache (goal: <= 0.2 s), the evaluation throughput
in channel values per second for 16 and for 10,000 parameter sets per call, the speed-up of
one likelihood-sized evaluation (2 samples x 6 channels) over the direct solver
(``bayespig.predict``; goal: >= 1000x), and the largest relative interpolation error seen
at random points against the direct solver. Tables are built into a temporary cache
directory, so the user's cache is neither used nor changed. The machine may be shared:
timings are wall-clock; the load average is printed with them.
"""

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import bayespig
from bayespig.instruments import predict
from bayespig.table import load_table

INSTRUMENT = "multi-angle-45"
SEED = 20240603
#: Random points of the accuracy check (isotropic table; for the g table, groups x size).
ACCURACY_POINTS = 500
G_GROUPS, G_GROUP_SIZE = 12, 10
#: Largest finite tau sampled [-] (the issue's domain).
TAU_MAX = 100.0
LOAD_REPEATS = 5
#: Ensemble size of the amortised likelihood timing.
WALKERS = 64


def best_time(function, min_total=0.5, min_repeats=3):
    """Smallest wall time of one call [s], repeating for at least ``min_total`` seconds."""
    times = []
    start = time.perf_counter()
    while len(times) < min_repeats or time.perf_counter() - start < min_total:
        t0 = time.perf_counter()
        function()
        times.append(time.perf_counter() - t0)
    return min(times)


def random_parameters(rng, size, g_range=None):
    """Random (a, tau, r_s[, g]) over the whole domain, a quarter of them opaque."""
    a = rng.uniform(0.0, 1.0, size) ** 2
    tau = np.exp(rng.uniform(np.log(1e-4), np.log(TAU_MAX), size))
    tau[rng.random(size) < 0.25] = np.inf
    r_s = rng.uniform(0.0, 1.0, size)
    if g_range is None:
        return {"a": a, "tau": tau, "r_s": r_s}
    # few distinct g values: the direct solver pays per distinct g
    g = np.repeat(rng.uniform(*g_range, size // G_GROUP_SIZE), G_GROUP_SIZE)
    return {"a": a, "tau": tau, "r_s": r_s, "g": g}


def max_relative_error(table, parameters):
    values = table(**parameters)
    reference = predict(table.instrument, **parameters)
    return np.abs(values / reference - 1.0).max()


def throughput(table, rng, size):
    """Channel values per second when evaluating ``size`` parameter sets per call."""
    parameters = random_parameters(rng, size)
    seconds = best_time(lambda: table(**parameters))
    return size * len(table.channels) / seconds, seconds


def load_average():
    return "n/a" if not hasattr(os, "getloadavg") else " ".join(f"{x:.2f}" for x in os.getloadavg())


def line(label, text):
    print(f"{label:<42} {text}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-g", action="store_true", help="skip the (slow) table with a g axis")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(SEED)
    n_channels = len(bayespig.get_instrument(INSTRUMENT))
    print(f"bayespig {bayespig.__version__}, numpy {np.__version__}, "
          f"Python {platform.python_version()}, {os.cpu_count()} cores")
    print(f"load average at start: {load_average()}")
    print(f"instrument {INSTRUMENT!r} ({n_channels} channels), n = 1.45")
    with tempfile.TemporaryDirectory(prefix="bayespig-bench-") as cache:
        cache = Path(cache)
        start = time.perf_counter()
        table = load_table(INSTRUMENT, cache_dir=cache, progress=False)
        line("build, isotropic table:", f"{time.perf_counter() - start:8.2f} s   (goal <= 10 s; "
             "includes writing the cache)")
        load_times = []
        for _ in range(LOAD_REPEATS):
            start = time.perf_counter()
            load_table(INSTRUMENT, cache_dir=cache, progress=False)
            load_times.append(time.perf_counter() - start)
        size_mb = sum(p.stat().st_size for p in cache.glob("*.npz")) / 1e6
        line("load from cache:", f"{np.median(load_times):8.3f} s   (goal <= 0.2 s; median of "
             f"{LOAD_REPEATS}; file {size_mb:.1f} MB)")

        for size in (16, 10_000):
            rate, seconds = throughput(table, rng, size)
            line(f"throughput, {size} sets per call:",
                 f"{rate:10.3g} channel values/s   ({seconds * 1e3:.2f} ms per call)")

        # one likelihood-sized evaluation: one (a, tau) on a black and on a white substrate
        one = {"a": 0.05, "tau": 2.0, "r_s": np.array([0.01, 0.95])}
        t_table = best_time(lambda: table(**one))
        t_direct = best_time(lambda: predict(INSTRUMENT, **one), min_total=2.0)
        shape = "x".join(str(n) for n in table(**one).shape)
        line(f"likelihood-sized evaluation ({shape}):",
             f"table {t_table * 1e6:.0f} us, direct solver {t_direct * 1e3:.1f} ms: "
             f"ratio {t_direct / t_table:.0f}x   (goal >= 1000x)")
        # the same evaluation for a whole ensemble in one call (emcee's vectorize=True)
        a, tau = rng.uniform(0.01, 0.5, (WALKERS, 1)), rng.uniform(0.5, 20.0, (WALKERS, 1))
        t_ensemble = best_time(lambda: table(a=a, tau=tau, r_s=one["r_s"])) / WALKERS
        line(f"  the same, {WALKERS} walkers in one call:",
             f"table {t_ensemble * 1e6:.0f} us per walker: ratio {t_direct / t_ensemble:.0f}x")

        error = max_relative_error(table, random_parameters(rng, ACCURACY_POINTS))
        line(f"max relative error, {ACCURACY_POINTS} random points:",
             f"{error:.2e}   (goal <= 2e-4)")

        if not args.skip_g:
            start = time.perf_counter()
            table_g = load_table(INSTRUMENT, g="free", cache_dir=cache, progress=False)
            build_g = time.perf_counter() - start
            settings = table_g.settings
            line(f"build, g table (g in {settings.g_range}, {settings.n_g} nodes):",
                 f"{build_g:8.1f} s   ({'meets' if build_g <= 60 else 'MISSES'} the goal <= 60 s)")
            start = time.perf_counter()
            load_table(INSTRUMENT, g="free", cache_dir=cache, progress=False)
            line("load from cache, g table:", f"{time.perf_counter() - start:8.3f} s")
            rate, _ = throughput_g(table_g, rng)
            line("throughput, g table, 10000 sets per call:", f"{rate:10.3g} channel values/s")
            n_points = G_GROUPS * G_GROUP_SIZE
            error = max_relative_error(table_g, random_parameters(rng, n_points, settings.g_range))
            line(f"max relative error, g table, {n_points} points:",
                 f"{error:.2e}   (goal <= 2e-4; {G_GROUPS} values of g)")
    print(f"load average at end: {load_average()}")
    return 0


def throughput_g(table, rng, size=10_000):
    parameters = random_parameters(rng, size)
    parameters["g"] = rng.uniform(*table.settings.g_range, size)
    seconds = best_time(lambda: table(**parameters))
    return size * len(table.channels) / seconds, seconds


if __name__ == "__main__":
    sys.exit(main())
