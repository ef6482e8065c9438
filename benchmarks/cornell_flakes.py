"""Benchmark: does a coloured flake lobe describe the Cornell paints where the surface alone cannot? (issue 16)

Run from the repository root (prints only; ~7 s)::

    python benchmarks/cornell_flakes.py

For each paint, at its body bands (garnet red 600-700 nm, Krylon blue 420-500 nm) and one dark
band, the BRDF over every geometry more than 2 deg from the mirror is fitted by least squares on
``log((x + F) / (model + F))`` (``F`` = 2e-3 1/sr, about the noise floor) with

- *surface*: the body of an opaque isotropic layer under the rough GGX surface (the direct
  solver, :func:`bayespig.physics.forward.surface_terms`, on the file's 8 x 10 grid of
  ``(theta_i, theta_o)``; ``a`` per band by spline interpolation over 23 solves in ``log a``)
  plus the surface's own lobe (:func:`bayespig.physics.forward.first_surface_brdf`);
- *surface + flakes*: the same plus ``c(lambda)`` times the flakes' lobe
  (:func:`bayespig.physics.forward.flake_brdf`), ``c`` per band and one flake roughness;

at the surface of the paint's full fit without flakes (``reports/cornell.md``: alpha and n, the
defaults below; ``--alpha``/``--n`` to change them). Printed per model: the fitted parameters and
the median ``|x / model - 1|`` over all geometries, those > 30 deg and <= 30 deg from the mirror,
and, per band, the same residuals and the fitted ``a`` of the two consistency subsets (> 30 deg
and 2-30 deg from the mirror, both with theta_i, theta_o <= 60 deg) fitted on their own. Then,
for the surface-only fit: its residual by azimuth side and by incidence angle far from the mirror,
its residual with g = 0.8 instead of 0, and the body's fall from 40 to 80 deg incidence under the
rough and the smooth surface.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import least_squares

from bayespig.data import read_measurements
from bayespig.physics.forward import first_surface_brdf, flake_brdf, surface_terms
from bayespig.selection import mirror_distance_deg

FOLDER = next((p for p in (Path(__file__).resolve().parents[k] / "shared" / "data" / "cornell" for k in (1, 2, 3))
               if p.is_dir()), Path("../shared/data/cornell"))
#: Bands fitted per paint [nm] (a dark band first, then the body bands).
BANDS = {"garnet_red": (500.0, 600.0, 650.0, 700.0), "krylon_blue": (600.0, 420.0, 450.0, 500.0)}
#: Surface of each paint's full fit without flakes (reports/cornell.md, session 9): GGX alpha, n.
SURFACE = {"garnet_red": (0.188, 1.617), "krylon_blue": (0.169, 1.525)}
FLOOR = 2e-3
A_NODES = np.concatenate([np.geomspace(0.01, 0.5, 14), np.linspace(0.55, 0.99, 9)])


def _fit(x, body, lobe, shape, select, flakes):
    nb = x.shape[1]

    def model(p):
        la, lc = p[:nb], p[nb:2 * nb]
        flake = shape(p[-1]) if flakes else 0.0
        return np.stack([np.exp(body(la[k])) + lobe + (np.exp(lc[k]) * flake if flakes else 0.0)
                         for k in range(nb)], axis=1)

    start = np.r_[np.log(np.full(nb, 0.1)), np.log(np.full(nb, 0.01)), 0.3]
    low = np.r_[np.full(nb, np.log(A_NODES[0])), np.full(nb, -12.0), 0.02]
    high = np.r_[np.full(nb, np.log(A_NODES[-1])), np.full(nb, 2.0), 2.0]
    if not flakes:
        start, low, high = start[:nb], low[:nb], high[:nb]
    fit = least_squares(lambda p: np.log((x[select] + FLOOR) / (model(p)[select] + FLOOR)).ravel(), start,
                        bounds=(low, high))
    return fit.x, model(fit.x)


def _structure(x, body, lobe, shape, ti, to, dp, d, grid_i, grid_o, bands, alpha, n):
    """What the surface-only fit leaves: the residual by azimuth side and by incidence, g's effect,
    and the body's fall to grazing incidence under a rough and a smooth surface."""
    p, m = _fit(x, body, lobe, shape, np.ones(x.shape[0], dtype=bool), False)
    ratio = x / m
    k = len(bands) - 2  # the second-last body band (red 650 nm, blue 450 nm)
    far = d > 30.0
    sides = [(0, 30), (30, 60), (60, 90), (90, 120), (120, 150), (150, 181)]
    print(f"    surface-only fit at {bands[k]:g} nm, median x / model > 30 deg from the mirror, by |delta_phi| "
          "(0: back towards the source, 180: specular side): "
          + ", ".join(f"{lo}-{min(hi, 180)} deg {np.median(ratio[far & (np.abs(dp) >= lo) & (np.abs(dp) < hi), k]):.2f}"
                      for lo, hi in sides))
    print(f"    by theta_i: " + ", ".join(f"{t:g} deg {np.median(ratio[far & (ti == t), k]):.2f}" for t in grid_i))
    # g = 0.8 instead of isotropic scattering: the body's angular shape barely changes
    nodes = surface_terms(grid_i, grid_o, a=A_NODES, tau=np.full(A_NODES.size, np.inf), g=0.8, n=n, roughness=alpha)
    columns = (np.searchsorted(grid_o, to), np.searchsorted(grid_i, ti))
    modes = np.arange(nodes.f0_modes.shape[1])
    weights = (2.0 - (modes == 0)) * (-1.0) ** modes * np.cos(modes * np.radians(dp)[:, None])
    body_g = np.einsum("bmg,gm->bg", nodes.f0_modes[:, :, columns[0], columns[1]], weights)
    spline = CubicSpline(np.log(A_NODES), np.log(body_g), axis=0)
    _, m_g = _fit(x, spline, lobe, shape, np.ones(x.shape[0], dtype=bool), False)
    print(f"    median |resid| at {bands[k]:g} nm with g = 0: {np.median(np.abs(ratio[:, k] - 1)):.3f}; "
          f"with g = 0.8: {np.median(np.abs(x[:, k] / m_g[:, k] - 1)):.3f}")
    # the body at grazing incidence relative to 40 deg, a = 0.08, viewing 8.1, 32.9, 50.2 deg
    for roughness in (0.0, alpha):
        terms = surface_terms(np.array([40.0, 80.0]), np.array([8.1, 32.9, 50.2]), a=np.array([0.08]),
                              tau=np.array([np.inf]), n=n, roughness=roughness)
        falls = terms.f0_modes[0, 0, :, 1] / terms.f0_modes[0, 0, :, 0]
        print(f"    body at theta_i 80 / 40 deg (a 0.08), roughness {roughness:g}: "
              + ", ".join(f"{v:.3f}" for v in falls))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--paints", default=",".join(BANDS))
    args = parser.parse_args(argv)
    if not FOLDER.is_dir():
        print(f"skipped: {FOLDER} not found", file=sys.stderr)
        return 0
    for paint in args.paints.split(","):
        started = time.perf_counter()
        alpha, n = SURFACE[paint]
        measurements = read_measurements(FOLDER / f"{paint}.astm", opaque=True)
        rows = measurements.films[0].measurements
        ti, to, dp = (np.array([getattr(m, k) for m in rows]) for k in ("theta_i", "theta_o", "delta_phi"))
        wl = np.asarray(measurements.wavelength_nm, dtype=float)
        bands = BANDS[paint]
        x = np.array([[m.values[int(np.argmin(np.abs(wl - b)))] for b in bands] for m in rows])
        d = mirror_distance_deg(ti, to, dp)
        keep = d > 2.0
        ti, to, dp, x, d = ti[keep], to[keep], dp[keep], x[keep], d[keep]
        grid_i, grid_o = np.unique(ti), np.unique(to)
        column_i, column_o = np.searchsorted(grid_i, ti), np.searchsorted(grid_o, to)
        terms = surface_terms(grid_i, grid_o, a=A_NODES, tau=np.full(A_NODES.size, np.inf), g=0.0, n=n,
                              roughness=alpha)
        body_nodes = terms.f0_modes[:, 0, column_o, column_i]  # isotropic: mode 0, (n_a, n_geometries)
        body = CubicSpline(np.log(A_NODES), np.log(body_nodes), axis=0)
        lobe = first_surface_brdf(ti, to, dp, roughness=alpha, n=n)

        def shape(alpha_f):
            return flake_brdf(ti, to, dp, flake_roughness=alpha_f, n=n)

        far = (d > 30.0) & (ti <= 60.0) & (to <= 60.0)
        near = (d <= 30.0) & (ti <= 60.0) & (to <= 60.0)
        print(f"{paint}: {keep.sum()} geometries > 2 deg from the mirror; surface alpha {alpha:g}, n {n:g}; "
              f"bands {', '.join(f'{b:g}' for b in bands)} nm")
        for flakes in (False, True):
            p, m = _fit(x, body, lobe, shape, np.ones(x.shape[0], dtype=bool), flakes)
            rel = np.abs(x / m - 1.0)
            nb = len(bands)
            head = f"  {'surface + flakes' if flakes else 'surface':16s}"
            if flakes:
                head += f" flake roughness {p[-1]:.3f}, c {np.array2string(np.exp(p[nb:2 * nb]), precision=4)}"
            print(head)
            subset = {}
            for name, select in (("far", far), ("near", near)):
                q, _ = _fit(x, body, lobe, shape, select, flakes)
                subset[name] = np.exp(q[:nb])
            for k, b in enumerate(bands):
                print(f"    {b:5.0f} nm: a {np.exp(p[k]):.4f}; median |resid| all {np.median(rel[:, k]):.3f}, "
                      f"> 30 deg {np.median(rel[d > 30, k]):.3f}, <= 30 deg {np.median(rel[d <= 30, k]):.3f}; "
                      f"subsets alone: a far {subset['far'][k]:.4f}, near {subset['near'][k]:.4f}")
        _structure(x, body, lobe, shape, ti, to, dp, d, grid_i, grid_o, bands, alpha, n)
        print(f"  ({time.perf_counter() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
