"""Benchmark: the whole Cornell garnet-red file with the roughness inferred (issue 16, "Scale").

Run from the repository root (prints only; loads both cores for a few minutes)::

    /usr/bin/time -v python benchmarks/cornell_scale.py [--max-steps N] [--binder-index free] [--exclude-mirror DEG]

The file ``../shared/data/cornell/garnet_red.astm`` (1439 geometries x 31 bands, an opaque paint
under a frosted overcoat) read with ``read_measurements(path, opaque=True)``, all geometries and
bands, ``infer(..., roughness="free", noise_floor="infer")`` (zeros are data; ``eps`` the
default 0.05), :data:`DRAWS_PER_CHAIN` stored draws per chain; ``--binder-index free`` infers the
binder index too (its rough tables at the six index nodes: built once per geometry set;
``--exclude-mirror 2`` uses the geometry set of ``bayespig cornell``'s full fit, whose tables that
command builds). Goal: <= 5 min on 2 cores and <= 2 GB peak memory.

Printed: the rough look-up table's build (or load) time and size, the wall time of ``infer``,
peak resident memory of this process and of its worker processes (``resource.getrusage``),
the run length, and per band ``a`` (5 / 50 / 95 %), the noise floor (median) and the median
``|x_obs / x_model - 1|`` over the geometries more than 2 deg from the mirror direction
(``x_model`` the posterior mean prediction), then ``alpha`` (5 / 50 / 95 %).
"""

import argparse
import resource
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import bayespig
from bayespig.inference import InferenceSettings, infer
from bayespig.likelihood import Problem
from bayespig.rough_table import load_rough_table
from bayespig.selection import mirror_distance_deg, select_measurements

#: ``../shared/data/cornell`` beside the checkout (a worktree under ``wt/`` looks one level up too).
CANDIDATES = [Path(__file__).resolve().parents[k] / "shared" / "data" / "cornell" / "garnet_red.astm"
              for k in (2, 3)]
PATH = next((p for p in CANDIDATES if p.is_file()), CANDIDATES[0])
#: Stored draws per chain (4 chains: 1024 draws, the target ESS). The default 1024 stores a
#: prediction and a pointwise log-likelihood per draw and value: 4096 x 31 x 1439 x 2 x 4 bytes
#: = 1.5 GB of output alone for this file, beyond the 2 GB goal once stacked.
DRAWS_PER_CHAIN = 256
#: Geometries at least this far from the mirror direction enter the printed residuals [deg].
MIRROR_CUT_DEG = 2.0


def peak_rss_mb():
    """Peak resident memory of this process and of its (waited-for) children [MB]."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    return own, children


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--path", default=str(PATH))
    parser.add_argument("--max-steps", type=int, default=None)
    parser.add_argument("--draws-per-chain", type=int, default=DRAWS_PER_CHAIN)
    parser.add_argument("--binder-index", choices=["free"], default=None)
    parser.add_argument("--exclude-mirror", type=float, default=None, metavar="DEG")
    args = parser.parse_args(argv)
    path = Path(args.path)
    if not path.is_file():
        print(f"skipped: {path} not found", file=sys.stderr)
        return 0
    started = time.perf_counter()
    measurements = bayespig.read_measurements(path, opaque=True)
    if args.exclude_mirror is not None:
        measurements = select_measurements(measurements, exclude_mirror_deg=args.exclude_mirror)
    problem = Problem.from_measurements(measurements)
    film = problem.films[0]
    t = time.perf_counter()
    table = load_rough_table(film.instrument, n=problem.n, progress=False)
    print(f"rough table: {len(table.channels)} channels x {table.n_alpha} alpha x {table.n_a} a nodes, "
          f"{table.nbytes / 1e6:.1f} MB, {'built' if hasattr(table, 'build_seconds') else 'loaded'} in "
          f"{time.perf_counter() - t:.1f} s")
    overrides = {} if args.max_steps is None else {"max_steps": args.max_steps}
    settings = InferenceSettings(draws_per_chain=args.draws_per_chain, **overrides)
    t = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        idata = infer(measurements, roughness="free", noise_floor="infer", progress=False, settings=settings,
                      binder_index=args.binder_index)
    wall = time.perf_counter() - t
    own, children = peak_rss_mb()
    for warning in caught:
        print(f"warning: {warning.message}")
    print(f"infer: {wall:.1f} s wall ({time.perf_counter() - started:.1f} s with reading and the table); "
          f"peak RSS {own:.0f} MB (this process), {children:.0f} MB (largest worker)")
    stats = idata.sample_stats
    print(f"run: {int(stats['n_steps'].values[0])} steps, burn-in {int(stats['n_burn_in'].values[0])}, "
          f"max_steps reached: {bool(stats['max_steps_reached'].values[0])}")
    wl = idata.posterior["wavelength"].values
    a = idata.posterior["a"].values.reshape(-1, wl.size)
    floor = idata.posterior["noise_floor"].values.reshape(-1, wl.size)
    y = idata.posterior_predictive["y"].values.reshape(-1, wl.size, film.observed.shape[1]).mean(axis=0)
    observed = np.stack([problem.observed(i) for i in range(wl.size)])
    ch = film.instrument.channels
    away = mirror_distance_deg(np.array([c.theta_i for c in ch]), np.array([c.theta_o for c in ch]),
                               np.array([c.delta_phi for c in ch])) > MIRROR_CUT_DEG
    residual = np.median(np.abs(observed[:, away] / y[:, away] - 1.0), axis=1)
    print(f"{away.sum()} of {away.size} geometries > {MIRROR_CUT_DEG:g} deg from the mirror")
    print("band_nm  a_q05    a_q50    a_q95    floor_1/sr  median|resid|")
    q = np.quantile(a, [0.05, 0.5, 0.95], axis=0)
    for i, w in enumerate(wl):
        print(f"{w:6.0f}  {q[0, i]:.4f}  {q[1, i]:.4f}  {q[2, i]:.4f}  {np.median(floor[:, i]):.2e}    "
              f"{residual[i]:.3f}")
    alpha = idata.posterior["roughness"].values.ravel()
    lo, mid, hi = np.quantile(alpha, [0.05, 0.5, 0.95])
    print(f"alpha: {mid:.4f} [{lo:.4f}, {hi:.4f}] (90 %)")
    if "binder_index" in idata.posterior:
        lo, mid, hi = np.quantile(idata.posterior["binder_index"].values.ravel(), [0.05, 0.5, 0.95])
        print(f"binder index n: {mid:.4f} [{lo:.4f}, {hi:.4f}] (90 %)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
