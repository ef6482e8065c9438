"""Quadrature convergence of the forward model, and the validation report.

Run from the repository root::

    python benchmarks/quadrature_convergence.py

Prints the relative change of the BRDF at the six multi-angle geometries (45as-15 ... 45as110)
and of the 8°/d hemispherical reflectance against the number of Gauss points per quadrature
interval (``n_points``), relative to a reference run with REFERENCE_POINTS, and writes
``reports/validation.md`` (atomically): every reference comparison of issue 2 (published or
independent value, bayespig, error, tolerance) followed by the convergence table.
The independent references are those of the test suite, ``tests/physics/reference.py``.
"""

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import bayespig
from bayespig._atomic import write_text_atomically
from bayespig.physics import adding_doubling, forward, fresnel, substrate
from bayespig.physics.quadrature import DEFAULT_QUADRATURE_POINTS, default_quadrature_points
from tests.physics import reference as ref

COMMAND = "python benchmarks/quadrature_convergence.py"
REPORT = ROOT / "reports" / "validation.md"

ASPECULAR = np.array([-15.0, 15.0, 25.0, 45.0, 75.0, 110.0])
THETA_I = np.full(ASPECULAR.shape, 45.0)
THETA_O = np.abs(THETA_I - ASPECULAR)
DELTA_PHI = np.where(THETA_I - ASPECULAR >= 0, 180.0, 0.0)
N_BINDER = 1.45
POINTS = [4, 6, 8, 12, 16, 24, 32]
REFERENCE_POINTS = 48
#: (a, tau, g, r_s) cases of the convergence study.
CASES = [
    (0.01, np.inf, 0.0, 0.0),
    (0.1, 1.0, 0.0, 0.0),
    (0.1, 1.0, 0.0, 0.9),
    (0.3, 0.3, 0.5, 0.0),
    (0.05, 3.0, 0.5, 0.5),
    (0.01, 10.0, -0.3, 0.0),
    (0.05, 2.0, 2.0, 0.0),  # Rayleigh
    (0.1, 1.0, 0.9, 0.0),  # strongly forward-peaked: the default quadrature grows with |g|
    (0.1, 1.0, 0.95, 0.0),
]
TARGET = 1e-4


def brdf_and_hemispherical(a, tau, g, r_s, n_points):
    """The six multi-angle BRDFs and the 8°/d SCE reflectance at one quadrature."""
    kwargs = {"a": a, "tau": tau, "g": g, "r_s": r_s, "n": N_BINDER, "n_points": n_points}
    f = bayespig.brdf(THETA_I, THETA_O, DELTA_PHI, **kwargs)
    h = bayespig.hemispherical_reflectance(8.0, **kwargs)
    return np.append(f, h)


def convergence_table():
    """Rows (case, n_points, max rel change of the 6 BRDFs, rel change of 8°/d)."""
    rows = []
    for a, tau, g, r_s in CASES:
        default = default_quadrature_points(g)
        reference = brdf_and_hemispherical(a, tau, g, r_s, max(REFERENCE_POINTS, 2 * default))
        for n_points in sorted(set(POINTS) | {default}):
            values = brdf_and_hemispherical(a, tau, g, r_s, n_points)
            change = np.abs(values / reference - 1.0)
            rows.append(((a, tau, g, r_s), n_points, change[:-1].max(), change[-1]))
    return rows


#: Phase functions of the coarse-quadrature check (2.0: Rayleigh).
COARSE_G = (0.3, 0.5, 0.8, 0.9, -0.3, 2.0)
COARSE_POINTS = 60
COARSE_SEED = 3


def coarse_mode_changes():
    """Per g: the largest relative change of the six BRDFs over COARSE_POINTS random (a, tau)
    when the small azimuthal modes go to the coarse quadrature (the default) instead of the full."""
    rng = np.random.default_rng(COARSE_SEED)
    a = rng.uniform(0.001, 0.999, COARSE_POINTS)
    tau = np.exp(rng.uniform(np.log(0.01), np.log(100.0), COARSE_POINTS))
    geometry = (THETA_I[:, None], THETA_O[:, None], DELTA_PHI[:, None])
    rows = []
    for g in COARSE_G:
        default = bayespig.brdf(*geometry, a=a, tau=tau, g=g, n=N_BINDER)
        saved, forward.COARSE_AFTER = forward.COARSE_AFTER, 0.0
        try:
            full = bayespig.brdf(*geometry, a=a, tau=tau, g=g, n=N_BINDER)
        finally:
            forward.COARSE_AFTER = saved
        rows.append((g, float(np.abs(default / full - 1.0).max())))
    return rows


class Comparisons:
    """Collects (quantity, reference, bayespig, error, tolerance) rows."""

    def __init__(self):
        self.rows = []

    def add(self, quantity, source, expected, got, tolerance, relative=False):
        expected, got = float(expected), float(got)
        error = abs(got / expected - 1.0) if relative else abs(got - expected)
        kind = "rel" if relative else "abs"
        self.rows.append((quantity, source, expected, got, error, f"{tolerance:.0e} {kind}",
                          "ok" if error <= tolerance else "**FAIL**"))


def reference_comparisons():
    c = Comparisons()
    # 1. semi-infinite isotropic, n = 1 (Chandrasekhar H-function)
    for omega in (0.5, 0.9, 0.99, 1.0):
        for theta_i, theta_o in ((0.0, 0.0), (30.0, 60.0), (60.0, 85.0)):
            mu0, mu = np.cos(np.radians([theta_i, theta_o]))
            expected = ref.semi_infinite_reflection_function(mu, mu0, omega)
            got = np.pi * bayespig.brdf(theta_i, theta_o, 0.0, a=1 - omega, tau=np.inf, n=1.0)
            c.add(f"pi f, omega={omega}, {theta_i:g}/{theta_o:g}", "H-function", expected, got,
                  1e-5, relative=True)
    for omega, published in ((0.9, 0.41495), (0.5, 0.11523), (0.99, 0.75272)):
        got = bayespig.hemispherical_reflectance(0.0, a=1 - omega, tau=np.inf, n=1.0)
        c.add(f"R_h(normal), omega={omega}", "REF-VALUES s1", published, got, 1e-5)
    got = bayespig.hemispherical_reflectance(0.0, a=0.0, tau=np.inf, n=1.0)
    c.add("R_h(normal), omega=1", "exact (=1)", 1.0, got, 1e-5)
    # 2. van de Hulst Table 12
    mu0 = np.array([1.0, 0.9, 0.7, 0.5, 0.3, 0.1])
    R, T = adding_doubling.bare_layer_functions([0.5], mu0, a=0.2, tau=2.0)
    for j, (r_pub, t_pub) in enumerate(zip([0.28616, 0.30277, 0.34188, 0.39102, 0.45353, 0.53214],
                                           [0.14864, 0.14731, 0.13963, None, 0.09425, 0.06601])):
        c.add(f"R(0.5, {mu0[j]:g}), omega 0.8, b 2", "vdH Table 12", r_pub, R[0, j], 1e-4)
        if t_pub is not None:
            c.add(f"T(0.5, {mu0[j]:g}), omega 0.8, b 2", "vdH Table 12", t_pub, T[0, j], 1e-4)
    nodes, w = ref.gauss_on_unit_interval(64)
    for a, tau, g, r_pub, t_pub in ((0.01, 1.0, 0.0, 0.48652, 0.49163),
                                    (0.01, 4.0, 0.5, 0.61996, 0.30605)):
        R, T = adding_doubling.bare_layer_functions(nodes, [0.5], a=a, tau=tau, g=g)
        c.add(f"R total mu0 .5, omega .99 b {tau:g} g {g:g}", "vdH vol. 1-2", r_pub,
              2 * np.sum(w * nodes * R[:, 0]), 1e-4)
        c.add(f"T total mu0 .5, omega .99 b {tau:g} g {g:g}", "vdH vol. 1-2", t_pub,
              2 * np.sum(w * nodes * T[:, 0]) + np.exp(-tau / 0.5), 1e-4)
    # 3. slab with Fresnel faces, REFERENCE-VALUES section 3 and iadpython
    from tests.physics.test_reference_values import (
        IADPYTHON_CASES,
        OPAQUE_CONSERVATIVE_ENERGY_ABS_TOL,
        SLAB_G09_ABS_TOL,
        SLAB_TABLE,
        TABLE_ABS_TOL,
        TOTAL_KEYS,
    )
    for omega, b, g, n, *values in SLAB_TABLE:
        totals = adding_doubling.slab_totals(a=1 - omega, tau=b, g=g, n=n)
        # the g = 0.9 rows are good to ~1e-4 only (tests/physics/test_reference_values.py)
        tolerance = SLAB_G09_ABS_TOL if g == 0.9 else TABLE_ABS_TOL
        for key, value in zip(TOTAL_KEYS, values):
            c.add(f"{key}, omega {omega} b {b:g} g {g:g} n {n}", "REF-VALUES s3", value,
                  totals[key], tolerance)
    import iadpython

    for omega, b, g, n in IADPYTHON_CASES:
        expected = iadpython.Sample(a=omega, b=b, g=g, n=n, quad_pts=48).rt()
        totals = adding_doubling.slab_totals(a=1 - omega, tau=b, g=g, n=n)
        for key, value in zip(TOTAL_KEYS, expected):
            c.add(f"{key}, omega {omega} b {b:g} g {g:g} n {n}", "iadpython 48", value,
                  totals[key], 1e-4)
    # 4. constants, clear binder, energy, single scattering
    c.add("r_F(normal), n 1.45", "REF-VALUES s4", 0.033736,
          fresnel.fresnel_reflectance(1.0, 1.0, 1.45), 1e-6)
    c.add("internal diffuse reflectance, n 1.45", "REF-VALUES s4", 0.5645,
          fresnel.internal_diffuse_reflectance(1.45), 5e-5)
    for theta_i, theta_o in ((8.0, 45.0), (45.0, 80.0)):
        expected = ref.clear_binder_brdf(theta_i, theta_o, r_s=0.8, n=1.45)
        c.add(f"eq. 9, r_s .8, {theta_i:g}/{theta_o:g}", "closed form", expected,
              substrate.clear_binder_brdf(theta_i, theta_o, r_s=0.8, n=1.45), 1e-10, True)
        c.add(f"brdf tau=0, r_s .8, {theta_i:g}/{theta_o:g}", "closed form (eq. 9)", expected,
              bayespig.brdf(theta_i, theta_o, 0.0, a=0.3, tau=0.0, r_s=0.8, n=1.45), 1e-6, True)
    for tau, g, n in ((1.0, 0.0, 1.45), (1.0, 0.5, 1.45), (1.0, 0.9, 1.45), (np.inf, 0.0, 1.45),
                      (np.inf, 0.5, 1.0)):
        got = bayespig.hemispherical_reflectance(8.0, a=0.0, tau=tau, g=g, r_s=1.0, n=n,
                                                 specular="included")
        c.add(f"SCI 8°/d, a 0, r_s 1, tau {tau:g} g {g:g} n {n}", "energy (=1)", 1.0, got, 1e-5)
    # the opaque conservative limit for forward-peaked scattering (issue 18)
    for g in (0.9, 0.95):
        for n in (1.0, 1.45, 1.6):
            got = bayespig.hemispherical_reflectance(8.0, a=0.0, tau=np.inf, g=g, n=n, specular="included")
            c.add(f"SCI 8°/d, a 0, opaque, g {g:g} n {n}", "energy (=1)", 1.0, got,
                  OPAQUE_CONSERVATIVE_ENERGY_ABS_TOL)
    for g in (0.0, 0.8, 2.0):
        expected = ref.single_scattering_brdf(45.0, 30.0, 180.0, omega=0.9, tau=1e-4, g=g,
                                              n=1.45)
        got = bayespig.brdf(45.0, 30.0, 180.0, a=0.1, tau=1e-4, g=g, n=1.45)
        c.add(f"45as15 tau 1e-4 g {g:g} n 1.45", "single scattering", expected, got, 3.1e-3,
              relative=True)
    return c.rows


def markdown(comparisons, table, coarse):
    lines = [
        "# Validation of the radiative-transfer core",
        "",
        f"Regenerate with `{COMMAND}` (from the repository root).",
        "",
        (f"bayespig {bayespig.__version__}; default quadrature n_points = "
        f"{DEFAULT_QUADRATURE_POINTS} Gauss points per interval."),
        "",
        "## Reference comparisons",
        "",
        "| quantity | reference | value | bayespig | error | tolerance | |",
        "|---|---|---|---|---|---|---|",
    ]
    for quantity, source, expected, got, error, tolerance, status in comparisons:
        lines.append(f"| {quantity} | {source} | {expected:.6g} | {got:.6g} | {error:.1e} | "
                     f"{tolerance} | {status} |")
    failures = sum(row[-1] != "ok" for row in comparisons)
    lines += ["", f"{len(comparisons) - failures} of {len(comparisons)} within tolerance.", ""]
    lines += [
        "## Quadrature convergence",
        "",
        (f"Relative change against n_points = {REFERENCE_POINTS} (twice the default where that is more): "
        "the largest over the six multi-angle BRDFs (45as-15 ... 45as110, n = 1.45) and the 8°/d "
        f"reflectance (SCE). Target {TARGET:.0e}. The default grows with |g| "
        "(`bayespig.physics.quadrature.default_quadrature_points`: 16 points up to |g| = 0.8, "
        "32 at 0.9, 64 at 0.95)."),
        "",
        "| a | tau | g | r_s | n_points | BRDF (max of 6) | 8°/d |",
        "|---|---|---|---|---|---|---|",
    ]
    for (a, tau, g, r_s), n_points, f_change, h_change in table:
        mark = " (default)" if n_points == default_quadrature_points(g) else ""
        lines.append(f"| {a:g} | {tau:g} | {g:g} | {r_s:g} | {n_points}{mark} | "
                     f"{f_change:.1e} | {h_change:.1e} |")
    lines += [
        "",
        "## Small azimuthal modes on the coarse quadrature",
        "",
        (f"A parameter set's azimuthal modes are solved on half the Gauss points once one of them "
         f"is below {forward.COARSE_AFTER:g} of its mode 0 at every geometry "
         "(`bayespig.physics.forward.COARSE_AFTER`). Largest relative change of the six multi-angle "
         f"BRDFs against every mode on the full quadrature (default n_points), over {COARSE_POINTS} "
         "random (a, tau) with a in (0.001, 0.999), tau log-uniform in (0.01, 100):"),
        "",
        "| g | largest relative change |",
        "|---|---|",
        *(f"| {g:g}{' (Rayleigh)' if abs(g) > 1 else ''} | {change:.1e} |" for g, change in coarse),
    ]
    return "\n".join(lines) + "\n"


def main():
    table = convergence_table()
    print(f"relative change vs n_points={REFERENCE_POINTS} (BRDF: max over 6 geometries)")
    print(f"{'a':>6} {'tau':>6} {'g':>5} {'r_s':>5} {'n_points':>8} {'BRDF':>9} {'8/d':>9}")
    for (a, tau, g, r_s), n_points, f_change, h_change in table:
        print(f"{a:>6g} {tau:>6g} {g:>5g} {r_s:>5g} {n_points:>8d} {f_change:>9.1e} "
              f"{h_change:>9.1e}")
    comparisons = reference_comparisons()
    failures = [row for row in comparisons if row[-1] != "ok"]
    print(f"\nreference comparisons: {len(comparisons) - len(failures)} of {len(comparisons)} "
          "within tolerance")
    for quantity, source, expected, got, error, tolerance, _ in failures:
        print(f"  FAIL {quantity} [{source}]: expected {expected:.6g}, got {got:.6g}, "
              f"error {error:.1e} > {tolerance}")
    coarse = coarse_mode_changes()
    print("\nsmall modes on the coarse quadrature, largest relative change of the BRDFs:")
    for g, change in coarse:
        print(f"  g = {g:g}: {change:.1e}")
    write_text_atomically(REPORT, markdown(comparisons, table, coarse))
    print(f"wrote {REPORT.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
