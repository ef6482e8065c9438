"""Feasibility of the rough surface on the solver's quadrature (issue 16 groundwork).

Run from the repository root::

    python benchmarks/microfacet.py

Prints, for GGX roughness alpha = 0.05, 0.1, 0.3 (binder n = 1.45), how many polar quadrature
points the rough surface's m = 0 kernels (bayespig.physics.microfacet) need for the directional
albedos they imply to converge to 1e-4 (absolute, in units of the incident energy):

- air -> binder transmission and binder internal reflection summed over the binder quadrature
  (``binder_quadrature``: Gauss in the lower interval [0, mu_c], Gauss in s with
  mu = mu_c + (1 - mu_c) s^2 above, the critical cosine mu_c as the boundary; "n_points" per
  interval, 2 n_points nodes in all), and for comparison over Gauss nodes in the polar angle
  theta with the same boundary;
- air reflection (the first-surface lobe) and binder -> air transmission over a Gauss rule in
  mu on [0, 1] in air with 2 n_points nodes (the solver has no air quadrature today).

The reference is :func:`~bayespig.physics.microfacet.directional_albedo` (a quadrature over
microfacet normals, independent of the kernels; 256 panels, error ~1e-7). Then the azimuth
rule's convergence (points per panel) and the number of Fourier modes that reproduce the
first-surface lobe point by point. Prints only; writes nothing.
"""

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayespig.physics import microfacet as mf
from bayespig.physics.fresnel import critical_cosine
from bayespig.physics.quadrature import binder_quadrature
from benchmarks._common import machine_line

N = 1.45
ALPHAS = [0.05, 0.1, 0.3]
POINTS = [8, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384]
GOAL = 1e-4
THETA_AIR = np.array([0.0, 30.0, 60.0, 80.0])
MU_BINDER = np.array([1.0, 0.9, 0.8, 0.75, 0.5, 0.2])  # mu_c = 0.724: 0.75 just above, 0.5 and 0.2 in TIR


def _gauss(n, lo, hi):
    x, w = np.polynomial.legendre.leggauss(n)
    return lo + (hi - lo) * (x + 1.0) / 2.0, w * (hi - lo) / 2.0


def theta_quadrature(n_points, n):
    """Gauss in theta on [0, theta_c] and [theta_c, pi/2], as weights for int h(mu) dmu."""
    theta_c = np.arccos(critical_cosine(n))
    parts = [_gauss(n_points, 0.0, theta_c), _gauss(n_points, theta_c, 0.5 * np.pi)]
    theta = np.concatenate([p[0] for p in parts])
    weight = np.concatenate([p[1] for p in parts]) * np.sin(theta)
    return np.cos(theta), weight


def air_quadrature(n_points):
    return _gauss(2 * n_points, 0.0, 1.0)


def smallest(errors):
    """First n_points from which every error stays <= GOAL ('>' the largest tried otherwise)."""
    errors = np.asarray(errors)
    for k in range(len(POINTS)):
        if (errors[k:] <= GOAL).all():
            return str(POINTS[k])
    return f">{POINTS[-1]}"


def albedo_errors(alpha):
    mu_air = np.cos(np.radians(THETA_AIR))
    r_air, t_air = mf.directional_albedo(mu_air, alpha=alpha, n_i=1.0, n_t=N, n_panels=256)
    r_bin, t_bin = mf.directional_albedo(MU_BINDER, alpha=alpha, n_i=N, n_t=1.0, n_panels=256)
    rows = {"T air->binder (binder quad)": [], "T air->binder (theta quad)": [],
            "R internal (binder quad)": [], "R internal (theta quad)": [],
            "R air lobe (air Gauss)": [], "T binder->air (air Gauss)": []}
    for n_points in POINTS:
        for label, (mu_b, w_b) in (("binder quad", binder_quadrature(n_points, N)),
                                   ("theta quad", theta_quadrature(n_points, N))):
            c = mu_b * w_b
            t_in = mf.transmission_modes(mu_b, mu_air, 1, alpha=alpha, n_i=1.0, n_t=N)[0]
            r_int = mf.reflection_modes(mu_b, MU_BINDER, 1, alpha=alpha, n_i=N, n_t=1.0)[0]
            rows[f"T air->binder ({label})"].append(np.abs(c @ t_in - t_air))
            rows[f"R internal ({label})"].append(np.abs(c @ r_int - r_bin))
        mu_a, w_a = air_quadrature(n_points)
        c = mu_a * w_a
        rows["R air lobe (air Gauss)"].append(np.abs(c @ mf.reflection_modes(mu_a, mu_air, 1, alpha=alpha, n_i=1.0,
                                                                              n_t=N)[0] - r_air))
        rows["T binder->air (air Gauss)"].append(np.abs(c @ mf.transmission_modes(mu_a, MU_BINDER, 1, alpha=alpha,
                                                                                   n_i=N, n_t=1.0)[0] - t_bin))
    return rows, (r_air, t_air, r_bin, t_bin)


def main():
    print(machine_line())
    print(f"binder n = {N}, GGX; goal: directional albedo to {GOAL:g} (absolute); n_points per interval "
          f"(2 n_points nodes); columns: incidence directions")
    for alpha in ALPHAS:
        start = time.perf_counter()
        rows, (r_air, t_air, r_bin, t_bin) = albedo_errors(alpha)
        print(f"\nalpha = {alpha}  ({time.perf_counter() - start:.1f} s)")
        print(f"  reference from air, theta_i = {THETA_AIR.tolist()} deg: R = {np.round(r_air, 5).tolist()}, "
              f"T = {np.round(t_air, 5).tolist()}")
        print(f"  reference from the binder, mu = {MU_BINDER.tolist()}: R = {np.round(r_bin, 5).tolist()}, "
              f"T = {np.round(t_bin, 5).tolist()}")
        for name, errors in rows.items():
            errors = np.array(errors)  # (points, directions)
            needed = [smallest(errors[:, j]) for j in range(errors.shape[1])]
            at16 = errors[POINTS.index(16)]
            print(f"  {name:28s} n_points needed: {' '.join(f'{x:>5s}' for x in needed)}"
                  f"   | error at 16: {' '.join(f'{e:.1e}' for e in at16)}")

    print("\nenergy lost by the single-scattering model, 1 - R - T (GGX), at theta_i = 0 30 60 75 84 deg")
    mu = np.cos(np.radians([0.0, 30.0, 60.0, 75.0, 84.0]))
    for side, (n_i, n_t) in (("from air", (1.0, N)), ("from the binder", (N, 1.0))):
        for alpha in (0.05, 0.1, 0.3, 0.5, 1.0):
            r, t = mf.directional_albedo(mu, alpha=alpha, n_i=n_i, n_t=n_t)
            print(f"  {side:15s} alpha {alpha:4.2f}: " + " ".join(f"{x:6.4f}" for x in 1.0 - r - t))

    print("\nazimuth rule (mode 0, alpha = 0.05): relative change of the kernels against 32 points per panel")
    mu_b, _ = binder_quadrature(32, N)
    mu_air = np.cos(np.radians(THETA_AIR))
    for kind, call in (("T air->binder", lambda p: mf.transmission_modes(mu_b, mu_air, 1, alpha=0.05, n_i=1.0, n_t=N,
                                                                          points_per_panel=p)),
                       ("R internal", lambda p: mf.reflection_modes(mu_b, mu_b, 1, alpha=0.05, n_i=N, n_t=1.0,
                                                                    points_per_panel=p))):
        ref = call(32)
        scale = np.abs(ref).max()
        print(f"  {kind:14s}" + "".join(f"  {p} pts: {np.abs(call(p) - ref).max() / scale:.1e}" for p in (4, 8, 16)))

    print("\nFourier modes for the first-surface lobe point by point (theta_i = 45 deg, theta_o 30..60 deg, "
          "all azimuths): max |series - f| / max f")
    mu_i = np.array([np.cos(np.radians(45.0))])
    mu_o = np.cos(np.radians(np.linspace(30.0, 60.0, 7)))
    psi = np.linspace(0.0, np.pi, 181)
    for alpha in ALPHAS:
        direct = mf.reflection_brdf(mu_i[None, :, None], mu_o[:, None, None], psi, alpha=alpha, n_i=1.0, n_t=N)
        line = []
        for n_modes in (16, 32, 64, 128, 256):
            m = np.arange(n_modes)
            modes = mf.reflection_modes(mu_o, mu_i, n_modes, alpha=alpha, n_i=1.0, n_t=N)
            weights = (2.0 - (m == 0))[:, None] * np.cos(m[:, None] * psi) / (2.0 * np.pi)
            series = np.einsum("moi,mp->oip", modes, weights)
            line.append(f"{n_modes}: {np.abs(series - direct).max() / direct.max():.1e}")
        print(f"  alpha {alpha}: " + ", ".join(line))


if __name__ == "__main__":
    main()
