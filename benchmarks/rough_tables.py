"""Benchmark: accuracy of the rough look-up tables over roughness and binder index (issue 16).

Run from the repository root (prints only; a few minutes on 2 cores, the default rough table of
the test instrument is built once into the table cache)::

    python benchmarks/rough_tables.py [--quick]

1. **n-interpolation** (:class:`bayespig.rough_table.BinderIndexRoughTables`): the body by a cubic
   Lagrange stencil in ``n`` on nodes ``step`` apart (the direct solver's values at the nodes),
   against the direct solver between them (n = 1.38 .. 1.71), at alpha 0.02 / 0.2 / 0.6 and
   a 0.01 / 0.3 / 0.9 on 25 geometries: worst relative error per node spacing.
2. **Smoothness in alpha**: the direct solver's ``log`` body on 13 roughness values uniform in
   ``log alpha`` over [0.3, 0.9]: largest second difference at each inner value (a smooth
   function gives slowly varying values; panel-layout jumps would show as spikes).
3. **Default table against the direct solver** (``tests/test_table_roughness.py``'s instrument,
   5 BRDF + SCE + SCI channels): worst relative error of the total on 6 random points per range
   alpha in [0.01, 0.1] and [0.1, 1] (seed 5).
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from bayespig import brdf, hemispherical_reflectance
from bayespig.physics.rough_surface import rough_surface_terms
from bayespig.rough_table import load_rough_table

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.test_table_roughness import CHANNELS, INSTRUMENT  # noqa: E402  (the test's instrument)

THETA_IN = np.array([10.0, 30.0, 50.0, 70.0, 80.0])
THETA_OUT = np.array([0.0, 40.0, 60.0, 75.0, 79.0])


def _body(a, alpha, n):
    ti, to = np.meshgrid(THETA_IN, THETA_OUT)
    return brdf(ti.ravel(), to.ravel(), 0.0, a=a, tau=np.inf, n=n, roughness=alpha, part="body")


def n_interpolation(steps, alphas):
    targets = (1.38, 1.47, 1.55, 1.62, 1.71)
    grids = {step: 1.3 + step * np.arange(int(round(0.5 / step)) + 1) for step in steps}
    indices = sorted({round(float(n), 6) for nodes in grids.values() for n in nodes} | set(targets))
    worst = dict.fromkeys(steps, 0.0)
    for alpha in alphas:
        # one rough solve per (alpha, n), every a after it (the interface weights are cached per (alpha, n))
        log_b = {(n, a): np.log(_body(a, alpha, n)) for n in indices for a in (0.01, 0.3, 0.9)}
        for step, nodes in grids.items():
            for a in (0.01, 0.3, 0.9):
                for t in targets:
                    k = int(np.clip(np.floor((t - nodes[0]) / step) - 1, 0, len(nodes) - 4))
                    x = nodes[k:k + 4]
                    w = [np.prod([(t - x[m]) / (x[l] - x[m]) for m in range(4) if m != l]) for l in range(4)]
                    approx = sum(w[l] * log_b[round(float(x[l]), 6), a] for l in range(4))
                    worst[step] = max(worst[step], float(np.max(np.abs(np.exp(approx - log_b[t, a]) - 1.0))))
    for step in steps:
        print(f"  n node step {step:g}: worst relative error {worst[step]:.2e}", flush=True)


def alpha_smoothness():
    alphas = np.exp(np.linspace(np.log(0.3), np.log(0.9), 13))
    values = np.array([np.log(rough_surface_terms(THETA_IN[[0, 2, 3]], THETA_OUT[[0, 1, 2, 4]], a=np.array([0.01, 0.3]),
                                                  tau=np.array([np.inf, np.inf]), g=0.0, n=1.45, n_points=16,
                                                  alpha=al)["f0_modes"][:, 0]) for al in alphas])
    d2 = np.abs(values[2:] - 2 * values[1:-1] + values[:-2]).max(axis=(1, 2, 3))
    print("  largest second difference of log body (step log(3)/12):", " ".join(f"{v:.4f}" for v in d2))


def direct(a, alpha):
    brdfs = [ch for ch in CHANNELS if ch.kind == "brdf"]
    values = list(brdf([c.theta_i for c in brdfs], [c.theta_o for c in brdfs], [c.delta_phi for c in brdfs],
                       a=a, tau=np.inf, roughness=alpha))
    values += [float(hemispherical_reflectance(ch.theta_i, a=a, tau=np.inf, roughness=alpha, specular=ch.specular))
               for ch in CHANNELS[len(brdfs):]]
    return np.array(values)


def table_accuracy(points):
    table = load_rough_table(INSTRUMENT, progress=False)
    rng = np.random.default_rng(5)
    for low, high in ((0.01, 0.1), (0.1, 1.0)):
        worst = 0.0
        for _ in range(points):
            a = float(rng.uniform(0.0, 1.0) ** 2)
            alpha = float(np.exp(rng.uniform(np.log(low), np.log(high))))
            worst = max(worst, float(np.max(np.abs(table(a=a, roughness=alpha) / direct(a, alpha) - 1.0))))
        print(f"  alpha in [{low:g}, {high:g}], {points} points: worst relative error {worst:.2e}", flush=True)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one roughness in part 1, 3 points per range in part 3")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    print("1. binder-index interpolation against the direct solver")
    n_interpolation((0.1, 0.08), (0.02,) if args.quick else (0.02, 0.2, 0.6))
    print("2. the direct solver's body over roughness")
    alpha_smoothness()
    print("3. the default rough table against the direct solver")
    table_accuracy(3 if args.quick else 6)
    print(f"{time.perf_counter() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
