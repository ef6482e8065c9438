"""Benchmark: which surface lobe describes the Cornell paints near the mirror (issue 16).

Run from the repository root (prints only; ~10 s)::

    python benchmarks/cornell_surface_models.py

At a band where each paint's body is dark (garnet red 500 nm, Krylon blue 600 nm) the BRDF away
from the mirror is nearly all the surface's: each model, Walter's first-surface lobe
(:func:`bayespig.physics.microfacet.reflection_brdf`) plus a constant for the dark body, is fitted
by least squares on ``log((x + F) / (model + F))`` (``F`` = 2e-3 1/sr, about the noise floor) to
the geometries more than 2 deg from the mirror. Printed: the fitted parameters and the median
``|x / model - 1|`` over all, > 30 deg and <= 30 deg from the mirror. The models: GGX and
Beckmann at n = 1.45, GGX with n free, and a mixture of two GGX lobes (n = 1.45 and n free).
"""

import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from bayespig.data import read_measurements
from bayespig.physics.microfacet import reflection_brdf
from bayespig.selection import mirror_distance_deg

FOLDER = next((p for p in (Path(__file__).resolve().parents[k] / "shared" / "data" / "cornell" for k in (1, 2, 3))
               if p.is_dir()), Path("../shared/data/cornell"))
DARK_BANDS = {"garnet_red": 500.0, "krylon_blue": 600.0}
FLOOR = 2e-3


def main():
    if not FOLDER.is_dir():
        print(f"skipped: {FOLDER} not found", file=sys.stderr)
        return 0
    for paint, band in DARK_BANDS.items():
        measurements = read_measurements(FOLDER / f"{paint}.astm", opaque=True)
        rows = measurements.films[0].measurements
        ti, to, dp = (np.array([getattr(m, k) for m in rows]) for k in ("theta_i", "theta_o", "delta_phi"))
        x = np.array([m.values[int(np.argmin(np.abs(np.asarray(measurements.wavelength_nm) - band)))] for m in rows])
        d = mirror_distance_deg(ti, to, dp)
        keep = d > 2.0
        ti, to, dp, x, d = ti[keep], to[keep], dp[keep], x[keep], d[keep]
        mu_i, mu_o, psi = np.cos(np.radians(ti)), np.cos(np.radians(to)), np.radians(180.0 - dp)

        def lobe(alpha, distribution="ggx", n=1.45):
            return reflection_brdf(mu_i, mu_o, psi, alpha=alpha, n_i=1.0, n_t=n, distribution=distribution)

        models = {
            "GGX, n 1.45": (lambda p: lobe(p[0]) + p[1], [0.2, 1e-3], [0.01, 0], [1, 1]),
            "Beckmann, n 1.45": (lambda p: lobe(p[0], "beckmann") + p[1], [0.2, 1e-3], [0.01, 0], [1, 1]),
            "GGX, n free": (lambda p: lobe(p[0], n=p[2]) + p[1], [0.2, 1e-3, 1.5], [0.01, 0, 1.1], [1, 1, 2.5]),
            "two GGX, n 1.45": (lambda p: p[2] * lobe(p[0]) + (1 - p[2]) * lobe(p[3]) + p[1],
                                [0.08, 1e-3, 0.5, 0.3], [0.01, 0, 0, 0.01], [1, 1, 1, 1]),
            "two GGX, n free": (lambda p: p[2] * lobe(p[0], n=p[4]) + (1 - p[2]) * lobe(p[3], n=p[4]) + p[1],
                                [0.08, 1e-3, 0.5, 0.3, 1.5], [0.01, 0, 0, 0.01, 1.1], [1, 1, 1, 1, 2.5]),
        }
        print(f"{paint}, {band:g} nm, {keep.sum()} geometries > 2 deg from the mirror")
        for name, (model, start, low, high) in models.items():
            fit = least_squares(lambda p: np.log((x + FLOOR) / (model(p) + FLOOR)), start, bounds=(low, high))
            rel = np.abs(x / model(fit.x) - 1.0)
            print(f"  {name:17s} params {np.array2string(fit.x, precision=4)}: median |resid| all "
                  f"{np.median(rel):.3f}, > 30 deg {np.median(rel[d > 30]):.3f}, <= 30 deg {np.median(rel[d <= 30]):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
