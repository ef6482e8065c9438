"""Benchmark of the forward model: time per (a, tau) point, bayespig against iadpython.

Run from the repository root::

    python benchmarks/forward.py          # ~2-3 minutes
    python benchmarks/forward.py --full   # every grid point, also for g = 0.5

bayespig computes the BRDF at the six multi-angle geometries (45as-15 ... 45as110, ASTM E2194)
for a 64 x 64 grid of (a, tau) in one batched call. iadpython 0.5.3 can only give totals at
normal incidence (UR1, UT1, URU, UTU) and loops over points in Python; it is timed on a seeded
random subset of the same grid and scaled per point, at equal quadrature (the same number of
angular nodes in the binder) and at 16 points, where its UR1/UT1 already reach 1e-4.
The machine is shared: timings are wall-clock and noisy; the load average is printed.
"""

import argparse
import os
import sys
import time

import numpy as np

import bayespig
from bayespig.physics.quadrature import DEFAULT_QUADRATURE_POINTS

ASPECULAR = np.array([-15.0, 15.0, 25.0, 45.0, 75.0, 110.0])
THETA_I = np.full(ASPECULAR.shape, 45.0)
THETA_O = np.abs(THETA_I - ASPECULAR)
DELTA_PHI = np.where(THETA_I - ASPECULAR >= 0, 180.0, 0.0)
N_BINDER = 1.45
GRID_SIZE = 64
A_GRID = np.linspace(0.001, 0.999, GRID_SIZE)
TAU_GRID = np.logspace(-2, 2, GRID_SIZE)
#: Every k-th tau column for the partial-grid run of anisotropic scattering.
TAU_STRIDE = 8
IADPYTHON_SUBSET = 48
#: bayespig quadratures timed: the default (converged far below 1e-4) and the smallest
#: that still reaches 1e-4, for the comparison "at equal accuracy".
BAYESPIG_POINTS = (DEFAULT_QUADRATURE_POINTS, 10)
#: Reference quadrature for the accuracy column (bayespig: points per interval).
ACCURACY_POINTS = 32
ACCURACY_SUBSET = 24
SEED = 20240602


def bayespig_time(g, tau_values, n_points=DEFAULT_QUADRATURE_POINTS):
    """Wall time of one batched brdf call over A_GRID x tau_values, and the result."""
    start = time.perf_counter()
    f = bayespig.brdf(THETA_I[:, None, None], THETA_O[:, None, None], DELTA_PHI[:, None, None],
                      a=A_GRID[:, None], tau=tau_values[None, :], g=g, n=N_BINDER,
                      n_points=n_points)
    return time.perf_counter() - start, f


def iadpython_time(points, g, quad_pts):
    """Wall time per point of iadpython totals (normal incidence) and the UR1/UT1 values.

    Uses iadpython's own array interface (one ``Sample`` whose redistribution function is
    computed once and reused for every point), its fastest way to do many points.
    """
    import iadpython

    start = time.perf_counter()
    sample = iadpython.Sample(a=1.0 - points[:, 0], b=points[:, 1], g=g, n=N_BINDER,
                              n_above=1.0, n_below=1.0, quad_pts=quad_pts)
    ur1, ut1, _, _ = sample.rt()
    return (time.perf_counter() - start) / len(points), np.column_stack([ur1, ut1])


def bayespig_accuracy(g, rng, n_points=DEFAULT_QUADRATURE_POINTS):
    """Max relative change of the BRDF from ``n_points`` per interval to ACCURACY_POINTS."""
    a = rng.choice(A_GRID, ACCURACY_SUBSET)
    tau = rng.choice(TAU_GRID, ACCURACY_SUBSET)
    geometry = (THETA_I[:, None], THETA_O[:, None], DELTA_PHI[:, None])
    default = bayespig.brdf(*geometry, a=a, tau=tau, g=g, n=N_BINDER, n_points=n_points)
    fine = bayespig.brdf(*geometry, a=a, tau=tau, g=g, n=N_BINDER, n_points=ACCURACY_POINTS)
    return float(np.max(np.abs(default / fine - 1.0)))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true",
                        help="time the full 64 x 64 grid also for g = 0.5 (about 4 minutes more)")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(SEED)
    quad_equal = 2 * DEFAULT_QUADRATURE_POINTS  # two Gauss intervals in the binder (n > 1)

    print(f"bayespig {bayespig.__version__}, python {sys.version.split()[0]}, "
          f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(f"geometries: 45as{', 45as'.join(f'{x:g}' for x in ASPECULAR)} "
          f"(theta_o = {THETA_O.tolist()}, delta_phi = {DELTA_PHI.tolist()})")
    print(f"grid: a in [{A_GRID[0]}, {A_GRID[-1]}] x tau log-spaced [{TAU_GRID[0]}, "
          f"{TAU_GRID[-1]}], {GRID_SIZE} x {GRID_SIZE}; n = {N_BINDER}; bayespig default "
          f"n_points = {DEFAULT_QUADRATURE_POINTS} per interval = {quad_equal} binder nodes")
    print()
    header = (f"{'g':>4} {'bayespig points':>16} {'wall [s]':>9} {'ms/point':>9} "
              f"{'bayespig acc':>13} {'iad quad':>9} {'iad ms/pt':>10} {'iad UR1/UT1 acc':>16} "
              f"{'speed-up':>9}")
    print(header)
    print("-" * len(header))
    for g in (0.0, 0.5):
        taus = TAU_GRID if (g == 0.0 or args.full) else TAU_GRID[::TAU_STRIDE]
        subset = np.column_stack([rng.choice(A_GRID, IADPYTHON_SUBSET),
                                  rng.choice(TAU_GRID, IADPYTHON_SUBSET)])
        _, iad_reference = iadpython_time(subset, g, 48)
        iad_runs = []
        for quad in (quad_equal, 16):
            iad_per_point, iad_values = iadpython_time(subset, g, quad)
            iad_runs.append((quad, iad_per_point, float(np.max(np.abs(iad_values - iad_reference)))))
        for bp_points in BAYESPIG_POINTS:
            wall, f = bayespig_time(g, taus, bp_points)
            if not np.all(np.isfinite(f)):
                raise RuntimeError("bayespig returned non-finite BRDF values")
            per_point = wall / (A_GRID.size * taus.size)
            accuracy = bayespig_accuracy(g, rng, bp_points)
            label = f"{GRID_SIZE}x{taus.size} n{bp_points}"
            for quad, iad_per_point, iad_accuracy in iad_runs:
                print(f"{g:>4} {label:>16} {wall:>9.2f} {1e3 * per_point:>9.3f} {accuracy:>13.1e} "
                      f"{quad:>9d} {1e3 * iad_per_point:>10.3f} {iad_accuracy:>16.1e} "
                      f"{iad_per_point / per_point:>8.2f}x")
    print()
    print("bayespig: one batched brdf call per g; 'points' = (a, tau) pairs, each giving the BRDF at")
    print(f"  all 6 geometries. With g = 0.5 only every {TAU_STRIDE}th tau column is timed unless "
          "--full")
    print("  (per-point cost is set by the doublings, so the columns span the whole tau range).")
    print(f"bayespig acc: max relative change of the 6 BRDFs, 'nK' = K points per interval, vs "
          f"n_points={ACCURACY_POINTS}, {ACCURACY_SUBSET} random grid points.")
    print(f"iadpython: totals at normal incidence only (it cannot do oblique incidence), timed on "
          f"{IADPYTHON_SUBSET} random grid points")
    print("  (seeded) and scaled per point; 'iad UR1/UT1 acc' = max |change| vs quad_pts=48.")
    print("  iadpython is called through its array interface (redistribution computed once per g).")
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    print("speed-up = iadpython time per point / bayespig time per point (goal: >= 10x).")


if __name__ == "__main__":
    main()
