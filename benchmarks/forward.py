"""Benchmark of the forward model: time per (a, tau) point, bayespig against iadpython.

Run from the repository root::

    python benchmarks/forward.py              # ~1 minute; rewrites its section of reports/benchmarks.md
    python benchmarks/forward.py --no-write   # print only

bayespig computes the BRDF at the six multi-angle geometries (45as-15 ... 45as110, ASTM E2194)
for a 64 x 64 grid of (a, tau) in one batched call. iadpython 0.5.3 can only give totals at
normal incidence (UR1, UT1, URU, UTU) and loops over points in Python; it is timed on a seeded
random subset of the same grid and scaled per point, through its array interface, both with
the BLAS as loaded and limited to one thread (the faster counts). The two codes take turns over
several rounds and each setting keeps its best time. Both are timed at several
quadratures; the accuracy of each is its largest relative change against a much finer
quadrature over 400 random grid points (the BRDFs; UR1 and UT1), so the comparison can be made
at equal quadrature (32 binder nodes) and at equal accuracy (the fastest setting of each
within 1e-4). The machine is shared: timings are wall-clock minima of
repeated runs; the load average is printed.
"""

import argparse
import sys
import time

import numpy as np
from _common import Transcript, load_average, machine_line, write_run_section
from threadpoolctl import threadpool_limits

import bayespig
from bayespig.physics.quadrature import DEFAULT_QUADRATURE_POINTS

SECTION = "## Forward model"
ASPECULAR = np.array([-15.0, 15.0, 25.0, 45.0, 75.0, 110.0])
THETA_I = np.full(ASPECULAR.shape, 45.0)
THETA_O = np.abs(THETA_I - ASPECULAR)
DELTA_PHI = np.where(THETA_I - ASPECULAR >= 0, 180.0, 0.0)
N_BINDER = 1.45
GRID_SIZE = 64
A_GRID = np.linspace(0.001, 0.999, GRID_SIZE)
TAU_GRID = np.logspace(-2, 2, GRID_SIZE)
IADPYTHON_SUBSET = 48
#: bayespig Gauss points per interval timed (two intervals in the binder: twice as many nodes).
BAYESPIG_POINTS = (DEFAULT_QUADRATURE_POINTS, 14, 12)
#: iadpython quadrature points timed (its quad_pts: nodes in the slab).
IADPYTHON_POINTS = (40, 2 * DEFAULT_QUADRATURE_POINTS, 24)
#: Reference quadratures for the accuracy columns.
BAYESPIG_REFERENCE_POINTS = 32
IADPYTHON_REFERENCE_POINTS = 48
#: Random grid points of the accuracy columns (both codes; a few dozen understate the largest
#: error: at g = 0.5, 10 points per interval measured 8e-5 on 24 points and 3e-4 on 400).
ACCURACY_SUBSET = 400
GOAL_ACCURACY = 1e-4
#: UT1 below this (thick films) is left out of iadpython's relative accuracy.
SIGNIFICANT_TRANSMITTANCE = 1e-3
REPEATS = 5
SEED = 20240602


def bayespig_time(g, n_points):
    """Wall time of one batched brdf call over the whole grid [s]."""
    start = time.perf_counter()
    f = bayespig.brdf(THETA_I[:, None, None], THETA_O[:, None, None], DELTA_PHI[:, None, None],
                      a=A_GRID[:, None], tau=TAU_GRID[None, :], g=g, n=N_BINDER, n_points=n_points)
    elapsed = time.perf_counter() - start
    if not np.all(np.isfinite(f)):
        raise RuntimeError("bayespig returned non-finite BRDF values")
    return elapsed


def bayespig_accuracy(g, n_points, a, tau):
    """Max relative change of the six BRDFs at (a, tau) from ``n_points`` to BAYESPIG_REFERENCE_POINTS."""
    geometry = (THETA_I[:, None], THETA_O[:, None], DELTA_PHI[:, None])
    value = bayespig.brdf(*geometry, a=a, tau=tau, g=g, n=N_BINDER, n_points=n_points)
    fine = bayespig.brdf(*geometry, a=a, tau=tau, g=g, n=N_BINDER, n_points=BAYESPIG_REFERENCE_POINTS)
    return float(np.max(np.abs(value / fine - 1.0)))


def iadpython_run(points, g, quad_pts):
    """Time per point [s] of iadpython totals (normal incidence) and the UR1/UT1 values.

    One ``Sample`` whose redistribution function is computed once and reused for every point,
    iadpython's fastest way to do many points.
    """
    import iadpython

    start = time.perf_counter()
    sample = iadpython.Sample(a=1.0 - points[:, 0], b=points[:, 1], g=g, n=N_BINDER,
                              n_above=1.0, n_below=1.0, quad_pts=quad_pts)
    ur1, ut1, _, _ = sample.rt()
    return (time.perf_counter() - start) / len(points), np.column_stack([ur1, ut1])


def iadpython_time(points, g, quad_pts):
    """Time per point, the faster of the BLAS as loaded and limited to one thread [s]."""
    best = iadpython_run(points, g, quad_pts)[0]
    with threadpool_limits(limits=1, user_api="blas"):
        return min(best, iadpython_run(points, g, quad_pts)[0])


def iadpython_accuracy(values, reference):
    """Largest relative change of UR1, and of UT1 where it exceeds SIGNIFICANT_TRANSMITTANCE.

    Relative, as bayespig's accuracy is: an absolute 1e-4 on a total of 0.01 would be 1 %.
    """
    change = np.abs(values / reference - 1.0)
    significant = reference[:, 1] > SIGNIFICANT_TRANSMITTANCE
    return float(max(change[:, 0].max(), change[significant, 1].max(initial=0.0)))


def fastest_within(rows):
    """The (label, seconds, accuracy) row of least time whose accuracy meets GOAL_ACCURACY."""
    good = [row for row in rows if row[2] <= GOAL_ACCURACY]
    return min(good, key=lambda row: row[1]) if good else None


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-write", action="store_true", help="print only; leave reports/benchmarks.md")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(SEED)
    say = Transcript(machine_line())
    say(f"geometries: 45as{', 45as'.join(f'{x:g}' for x in ASPECULAR)} (theta_o = {THETA_O.tolist()}, "
        f"delta_phi = {DELTA_PHI.tolist()}); n = {N_BINDER}")
    say(f"grid: a in [{A_GRID[0]}, {A_GRID[-1]}] x tau log-spaced [{TAU_GRID[0]}, {TAU_GRID[-1]}], "
        f"{GRID_SIZE} x {GRID_SIZE}, in one call")
    summary = []
    for g in (0.0, 0.5):
        say()
        say(f"g = {g}")
        say(f"{'code':>10} {'quadrature':>22} {'ms/point':>9} {'accuracy':>9}")
        subset = np.column_stack([rng.choice(A_GRID, IADPYTHON_SUBSET), rng.choice(TAU_GRID, IADPYTHON_SUBSET)])
        accuracy_points = rng.choice(A_GRID, ACCURACY_SUBSET), rng.choice(TAU_GRID, ACCURACY_SUBSET)
        iad_accuracy_points = np.column_stack(accuracy_points)
        _, reference = iadpython_run(iad_accuracy_points, g, IADPYTHON_REFERENCE_POINTS)
        # the two codes take turns, REPEATS rounds, and each setting keeps its best time: a
        # slow spell of the shared machine does not fall on one code only
        iad_best = dict.fromkeys(IADPYTHON_POINTS, np.inf)
        bp_best = dict.fromkeys(BAYESPIG_POINTS, np.inf)
        for _ in range(REPEATS):
            for quad in IADPYTHON_POINTS:
                iad_best[quad] = min(iad_best[quad], iadpython_time(subset, g, quad))
            for n_points in BAYESPIG_POINTS:
                per_point = bayespig_time(g, n_points) / (A_GRID.size * TAU_GRID.size)
                bp_best[n_points] = min(bp_best[n_points], per_point)
        iad_rows = [(f"quad_pts {quad}", iad_best[quad],
                     iadpython_accuracy(iadpython_run(iad_accuracy_points, g, quad)[1], reference))
                    for quad in IADPYTHON_POINTS]
        bp_rows = [(f"{n_points}/interval = {2 * n_points} nodes", bp_best[n_points],
                    bayespig_accuracy(g, n_points, *accuracy_points)) for n_points in BAYESPIG_POINTS]
        for code, rows in (("bayespig", bp_rows), ("iadpython", iad_rows)):
            for label, per_point, accuracy in rows:
                say(f"{code:>10} {label:>22} {1e3 * per_point:>9.3f} {accuracy:>9.1e}")
        same_nodes = IADPYTHON_POINTS.index(2 * DEFAULT_QUADRATURE_POINTS)
        equal_quadrature = iad_rows[same_nodes][1] / bp_rows[0][1]
        say(f"speed-up at equal quadrature (32 nodes): {equal_quadrature:.1f}x")
        bp_best, iad_best = fastest_within(bp_rows), fastest_within(iad_rows)
        if bp_best and iad_best:
            ratio = iad_best[1] / bp_best[1]
            say(f"speed-up at equal accuracy (fastest within {GOAL_ACCURACY:g}): bayespig {bp_best[0]} vs "
                f"iadpython {iad_best[0]}: {ratio:.1f}x")
        else:
            ratio = float("nan")
            say(f"speed-up at equal accuracy: no setting within {GOAL_ACCURACY:g} for one of the codes")
        summary.append((g, equal_quadrature, ratio))
    say()
    say(f"load average at the end {load_average()}")
    if args.no_write:
        return 0
    write_run_section(SECTION, "python benchmarks/forward.py", [
        "Time per (a, tau) point of the forward model, the BRDF at six multi-angle geometries, over a",
        "64 x 64 grid in one batched call (default 2 worker threads), against iadpython's adding-doubling",
        "for normal-incidence totals (all it can compute). Accuracy: bayespig, largest relative change of",
        f"the BRDFs at {ACCURACY_SUBSET} random grid points against {BAYESPIG_REFERENCE_POINTS} points per interval; iadpython,",
        f"largest relative change of UR1 (and of UT1 where above {SIGNIFICANT_TRANSMITTANCE:g}) at the same points against",
        f"quad_pts {IADPYTHON_REFERENCE_POINTS}. iadpython is timed on {IADPYTHON_SUBSET} of the points.",
        "Goal (issue 2): at least 10x faster per point at equal accuracy (1e-4).",
    ], say.lines, after=[
        "| g | speed-up, equal quadrature | speed-up, equal accuracy | goal |",
        "|---|---|---|---|",
        *(f"| {g:g} | {q:.1f}x | {r:.1f}x | {'met' if r >= 10 and q >= 10 else 'not met'} (>= 10x) |"
          for g, q, r in summary),
    ])
    return 0


if __name__ == "__main__":
    sys.exit(main())
