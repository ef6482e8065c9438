"""Convergence and cost of the rough air/binder surface in the forward model (issue 16).

Run from the repository root::

    python benchmarks/rough_surface.py [--quick]

Prints, for GGX roughness alpha from 1e-4 to 1 (binder n = 1.45):

1. the smooth limit: max relative difference of the body's BRDF (and of SCI) at alpha = 1e-4,
   1e-3 from the smooth model (roughness 0), over layers and geometries in and out of the plane;
2. convergence in the binder quadrature: max relative change of the total BRDF against a
   reference with 48 Gauss points per interval (n_points 8, 12, 16, 24, 32), and in the fine
   rules (finest panel halved, points per panel 8 -> 12, azimuth points per panel 8 -> 12);
3. the cost: the interface's weights (once per alpha, n, n_points; cached) and a brdf() call
   once they are cached, against the smooth model;
4. the energy the single-scattering surface loses for a conservative film on white.

Prints only; writes nothing.
"""

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayespig.physics import forward as fw
from bayespig.physics import rough_surface as rs
from benchmarks._common import machine_line

N = 1.45
#: (a, tau, g, r_s) of the layers compared
LAYERS = [(0.1, 1.0, 0.0, 0.0), (0.02, np.inf, 0.5, 0.0), (0.5, 0.3, 0.3, 0.8), (0.0, np.inf, 0.0, 0.0)]
THETA_IN = np.array([0.0, 20.0, 45.0, 70.0])
THETA_OUT = np.array([0.0, 10.0, 30.0, 50.0, 75.0])
DELTA_PHI = np.array([0.0, 60.0, 120.0, 180.0])


def body(alpha, layer, n_points=16, rules=None, terms_only=False):
    """Body BRDF (k_out, k_in, phi) of one layer: the rough solve, or the smooth one at alpha 0."""
    a, tau, g, r_s = layer
    n_points = n_points or 16
    if alpha == 0.0:
        terms = fw.surface_terms(THETA_IN, THETA_OUT, a=[a], tau=[tau], g=g, n=N, n_points=n_points)
    else:
        terms = fw.SurfaceTerms(**rs.rough_surface_terms(THETA_IN, THETA_OUT, a=[a], tau=[tau], g=g, n=N,
                                                         n_points=n_points, alpha=alpha, rules=rules))
    f = np.stack([terms.brdf(phi, np.array([r_s]))[0] for phi in DELTA_PHI], axis=-1)
    return f, terms.hemispherical(np.array([r_s]))[0]


def lobe(alpha):
    mu_i = np.cos(np.radians(THETA_IN))[None, :, None]
    mu_o = np.cos(np.radians(THETA_OUT))[:, None, None]
    return fw.reflection_brdf(mu_i, mu_o, np.radians(DELTA_PHI) - np.pi, alpha=alpha, n_i=1.0, n_t=N)


def main(quick=False):
    print(machine_line())
    print(f"binder n = {N}; layers (a, tau, g, r_s) = {LAYERS}")
    print(f"theta_i = {THETA_IN.tolist()}, theta_o = {THETA_OUT.tolist()}, delta_phi = {DELTA_PHI.tolist()} deg")

    print("\n1. smooth limit: max |rough - smooth| / smooth of the body BRDF and of the body's "
          "hemispherical reflectance (n_points 16)")
    smooth = [body(0.0, layer) for layer in LAYERS]
    for alpha in (1e-4, 1e-3):
        worst_f = worst_h = 0.0
        for layer, (f0, h0) in zip(LAYERS, smooth):
            f, h = body(alpha, layer)
            worst_f = max(worst_f, np.max(np.abs(f - f0) / f0))
            worst_h = max(worst_h, np.max(np.abs(h - h0) / h0))
        print(f"  alpha {alpha:g}: BRDF {worst_f:.1e}, hemispherical {worst_h:.1e}")

    alphas = [0.02, 0.05, 0.1, 0.3, 0.6, 1.0] if not quick else [0.05, 0.3]
    points = [8, 12, 16, 24, 32]
    reference_points = 48
    print(f"\n2. convergence: max relative change of the total BRDF (body + lobe) and of the body's "
          f"hemispherical reflectance against n_points = {reference_points}")
    for alpha in alphas:
        surface = lobe(alpha)
        refs = [body(alpha, layer, reference_points) for layer in LAYERS]
        line = []
        for p in points:
            worst = 0.0
            for layer, (f_ref, h_ref) in zip(LAYERS, refs):
                f, h = body(alpha, layer, p)
                worst = max(worst, np.max(np.abs(f - f_ref) / (f_ref + surface)),
                            np.max(np.abs(h - h_ref) / h_ref))
            line.append(f"{p}: {worst:.1e}")
        print(f"  alpha {alpha:4.2f}: " + ", ".join(line))
    print("   fine rules at n_points 16 (max relative change, total BRDF and hemispherical): "
          "finest panel / 2, 12 points per panel, 12 azimuth points per panel")
    for alpha in alphas:
        surface = lobe(alpha)
        base = [body(alpha, layer) for layer in LAYERS]
        line = []
        for label, rules in (("finest/2", {"finest_panel": rs.FINEST_PANEL / 2}),
                             ("panel 12", {"panel_points": 12}), ("azimuth 12", {"azimuth_points": 12})):
            worst = 0.0
            for layer, (f0, h0) in zip(LAYERS, base):
                f, h = body(alpha, layer, 16, rules)
                worst = max(worst, np.max(np.abs(f - f0) / (f0 + surface)), np.max(np.abs(h - h0) / h0))
            line.append(f"{label}: {worst:.1e}")
        print(f"  alpha {alpha:4.2f}: " + ", ".join(line))

    print("\n3. cost (one brdf() call, 4 x 5 x 4 geometries, one layer; the interface weights cached "
          "per alpha)")
    kwargs = {"a": 0.1, "tau": 1.0, "g": 0.5}
    grid = np.meshgrid(THETA_IN, THETA_OUT, DELTA_PHI, indexing="ij")
    for alpha in [0.0] + alphas:
        rs.rough_interface.cache_clear()
        start = time.perf_counter()
        fw.brdf(*grid, roughness=alpha, **kwargs)
        first = time.perf_counter() - start
        start = time.perf_counter()
        repeats = 5
        for _ in range(repeats):
            fw.brdf(*grid, roughness=alpha, **kwargs)
        again = (time.perf_counter() - start) / repeats
        print(f"  alpha {alpha:4.2f}: first call {first * 1e3:7.0f} ms, cached {again * 1e3:6.1f} ms")


    print("\n4. energy the single-scattering microfacet surface loses (no inter-facet scattering): "
          "1 - SCI at 8 deg of a conservative film (a = 0) on white (r_s = 1)")
    for alpha in [0.02, 0.05, 0.1, 0.3, 0.6, 1.0] if not quick else [0.05, 0.3]:
        lost = [1.0 - float(fw.hemispherical_reflectance(8.0, a=0.0, tau=tau, g=0.0, r_s=1.0, roughness=alpha,
                                                         specular="included")) for tau in (0.0, 1.0, np.inf)]
        print(f"  alpha {alpha:4.2f}: clear binder {lost[0]:.4f}, tau = 1 {lost[1]:.4f}, opaque {lost[2]:.4f}")


if __name__ == "__main__":
    main(quick="--quick" in sys.argv)
