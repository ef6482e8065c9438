"""The radiative-transfer core against independent references (issue 2, "Must show").

References: Chandrasekhar's H-function (exact, semi-infinite, n = 1), van de Hulst's tables,
the single-scattering limit, energy conservation, reciprocity, the clear-binder formula,
converged adding-doubling totals (REFERENCE-VALUES.md section 3) and iadpython.
The reference implementations live in :mod:`tests.physics.reference` and do not use bayespig.
"""

import numpy as np
import pytest

import bayespig
from bayespig.physics import adding_doubling, forward, fresnel, substrate

from . import reference as ref

# --- tolerances -----------------------------------------------------------------------------
# Each states what was measured: the worst case of its tests run under OpenBLAS's Haswell,
# SkylakeX, Sandybridge and Prescott kernels (OPENBLAS_CORETYPE), and the margin over it.
#: Exact H-function solution vs solver (issue 2: 1e-5 relative). Measured <= 3.6e-9 (BRDF,
#: omega = 1 included), 1.1e-9 (hemispherical). Margin > 1000x.
H_FUNCTION_REL_TOL = 1e-5
#: Reference H-function vs Chandrasekhar's closed-form integral (both exact). Measured 1.8e-14.
H_CLOSED_FORM_REL_TOL = 1e-10
#: Published 5-decimal values. Their rounding alone differs by up to 5e-6 from the exact value
#: (measured 4.9e-6, the same on every machine: the reference and the solver are exact to
#: <= 4e-9 here); the remaining 5e-6 is what the solver may add. Margin > 1000x on that part.
PUBLISHED_5_DECIMALS_ABS_TOL = 1e-5
#: Tables the issue asks to match to 1e-4 (van de Hulst, REFERENCE-VALUES section 3, iadpython).
#: Measured: van de Hulst <= 4.0e-6 (25x); REFERENCE-VALUES section 3 for g <= 0.5 <= 1.1e-5
#: (9x); iadpython <= 3.1e-5 (3.2x: iadpython's own quadrature error, ~2-4e-5 at 48 to 64
#: points, it breaks down above ~90; bayespig changes by < 3e-10 from the default to 64 points).
TABLE_ABS_TOL = 1e-4
#: REFERENCE-VALUES section 3's g = 0.9, n = 1 row only (the n = 1.45 row keeps TABLE_ABS_TOL:
#: measured 2.8e-5, 3.6x). That published row is good to ~1e-4 only: bayespig's totals are
#: converged (they change by < 1e-6 from 32 to 96 points, SLAB_QUADRATURE_CONVERGED_ABS_TOL) and
#: differ from it by 8.2e-5 (URU, UTU), 1.2x inside 1e-4, a difference that is the table's, not
#: the machine's; iadpython, the kind of code such tables come from, moves by 2e-3 from 16 to 32
#: points there and fails at 48. Margin 6x over 8.2e-5.
SLAB_G09_ABS_TOL = 5e-4
#: The slab totals at g = 0.9 at the default quadrature and at 64 points: measured <= 1e-6
#: (n = 1 and 1.45). Margin 10x.
SLAB_QUADRATURE_CONVERGED_ABS_TOL = 1e-5
#: Two converged discretisations of the same physics (the issue's accuracy target). Measured
#: <= 9.5e-9 (n = 1 planetary problem, substrate terms). Margin > 1000x.
CONVERGED_REL_TOL = 1e-4
#: a = 0, r_s = 1, finite tau: everything is reflected. Measured <= 7.3e-9. Margin > 1000x.
ENERGY_ABS_TOL = 1e-5
#: An opaque layer with no absorption at all (omega = 1, tau = inf) reflects everything. The
#: discrete-ordinate solution has the diffusion mode k = 0 exactly there; measured (g in {0, 0.5,
#: 0.9, 0.95}, n in {1, 1.45, 1.6}, 7 incidences) <= 9.6e-8 (g = 0.95, n = 1: 128 nodes in one
#: interval), <= 1.1e-9 otherwise. Margin 10x. (Doubling to the opaque limit lost 1.4e-5 to
#: 2.6e-4 here: its start layer's spurious absorption of ~2e-10 per unit tau, which a
#: conservative opaque layer turns into ~sqrt(eps / (1 - g)).)
OPAQUE_CONSERVATIVE_ENERGY_ABS_TOL = 1e-6
#: Opaque weakly absorbing layers (a = 1e-5 ... 1e-3) against a finite layer thick enough
#: (e^{-12} of the diffusion mode left) doubled to that thickness: measured <= 2.9e-7 (g = 0.95,
#: a = 1e-5: doubling's spurious absorption, ~1e-10 per unit tau over 16384). Margin 10x.
OPAQUE_EQUALS_THICK_REL_TOL = 3e-6
#: f(v, u) = f(u, v). Measured <= 2.0e-11. Margin > 1000x.
RECIPROCITY_REL_TOL = 1e-6
#: Algebraic identities that hold to rounding (eq. 3 as stated in the contract). Measured
#: <= 4.1e-13. Margin > 1000x.
IDENTITY_REL_TOL = 1e-9
#: The eigen and doubling solvers solve the same discrete equations; they differ by the
#: doubling's start error and the eigen form's conditioning. Measured <= 1.6e-9. Margin > 100x.
SOLVERS_REL_TOL = 1e-6
#: tau = 1e-9 against the clear-binder formula: corrections are O(tau). Measured <= 8.8e-10
#: (tau = 1e-9). Margin > 1000x.
CLEAR_BINDER_REL_TOL = 1e-6
#: Fresnel reference values (REFERENCE-VALUES section 4), given to 6 digits: rounding 5e-7
#: (measured 5.7e-8). Margin 17x.
FRESNEL_PUBLISHED_ABS_TOL = 1e-6
#: Internal diffuse reflectance "about 0.5645": measured 2.7e-6. Margin 18x.
INTERNAL_DIFFUSE_PUBLISHED_ABS_TOL = 5e-5
#: Two implementations of the same closed form. Measured <= 1.2e-14.
CLOSED_FORM_REL_TOL = 1e-10
#: tau -> specular transmittance -> tau: rounding (measured 5.9e-17).
ROUND_TRIP_ABS_TOL = 1e-12
#: Single scattering: the neglected second order is about (omega tau / 2)(ln(1/tau) + O(1))
#: relative; this allows three times ``tau (1 + ln(1/tau))``. Measured 1.1 times it (physics, the
#: same on every machine). Margin 2.7x.
SINGLE_SCATTERING_REL_TOL_FACTOR = 3.0
#: Gauss points for integrating solver output over a hemisphere in tests (the integrands are
#: smooth but for mu log mu terms at mu -> 0: 24 points integrate the exact H-function albedo
#: to 5e-10).
TEST_GAUSS_POINTS = 24
#: iadpython quadrature: its totals are converged to ~2-4e-5 at 48 points (also at 64; it fails
#: above ~90).
IADPYTHON_QUAD_POINTS = 48

MULTI_ANGLE_ASPECULAR = np.array([-15.0, 15.0, 25.0, 45.0, 75.0, 110.0])
MULTI_THETA_I = np.full(6, 45.0)
MULTI_THETA_O = np.abs(45.0 - MULTI_ANGLE_ASPECULAR)
MULTI_DELTA_PHI = np.where(45.0 - MULTI_ANGLE_ASPECULAR >= 0, 180.0, 0.0)

RAYLEIGH = 2.0  # any |g| > 1 selects the Rayleigh phase function


def rel_err(got, expected):
    return np.abs(np.asarray(got) / np.asarray(expected) - 1.0)


# === 1. Reference implementation self-tests ===================================================

H_OMEGA_1 = [1.00000, 1.24735, 1.45035, 1.64252, 1.82928, 2.01278,
             2.19413, 2.37397, 2.55270, 2.73059, 2.90781]
H_AT_1 = {0.99: 2.47279, 0.9: 1.85010, 0.8: 1.59822, 0.5: 1.25126}


def test_reference_h_function_published_conservative():
    mu = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(ref.chandrasekhar_h(mu, 1.0), H_OMEGA_1,
                               rtol=0, atol=PUBLISHED_5_DECIMALS_ABS_TOL)


@pytest.mark.parametrize("omega, h1", sorted(H_AT_1.items()))
def test_reference_h_function_published_at_mu_1(omega, h1):
    assert abs(ref.chandrasekhar_h(1.0, omega) - h1) < PUBLISHED_5_DECIMALS_ABS_TOL
    zeroth_moment = (2.0 / omega) * (1.0 - np.sqrt(1.0 - omega))
    assert abs(ref.h_moment(omega, 0) / zeroth_moment - 1.0) < H_CLOSED_FORM_REL_TOL


@pytest.mark.parametrize("omega", [1.0, 0.999, 0.9, 0.3])
def test_reference_h_function_equals_closed_form(omega):
    mu = np.array([0.0, 0.013, 0.2, 0.5, 0.77, 1.0])
    closed = [ref.chandrasekhar_h_closed_form(m, omega) for m in mu]
    np.testing.assert_allclose(ref.chandrasekhar_h(mu, omega), closed,
                               rtol=H_CLOSED_FORM_REL_TOL)


@pytest.mark.parametrize("omega, hemispherical, albedo", [
    (0.9, 0.41495, 0.47802), (0.5, 0.11523, 0.14654), (0.99, 0.75272, 0.79456)])
def test_reference_semi_infinite_totals_published(omega, hemispherical, albedo):
    assert abs(ref.semi_infinite_hemispherical_reflectance(1.0, omega) - hemispherical) \
        < PUBLISHED_5_DECIMALS_ABS_TOL
    assert abs(ref.semi_infinite_diffuse_albedo(omega) - albedo) < PUBLISHED_5_DECIMALS_ABS_TOL


def test_reference_fresnel_and_internal_reflectance():
    assert abs(ref.fresnel_reflectance(1.0, 1.0, 1.45) - 0.033736) < FRESNEL_PUBLISHED_ABS_TOL
    assert abs(ref.internal_diffuse_reflectance(1.45) - 0.5645) < INTERNAL_DIFFUSE_PUBLISHED_ABS_TOL
    # Stokes/Helmholtz: the same reflectance from both sides along a refracted pair.
    mu_air = np.linspace(0.05, 1.0, 7)
    mu_binder = ref.refracted_cosine(np.degrees(np.arccos(mu_air)), 1.45)
    np.testing.assert_allclose(ref.fresnel_reflectance(mu_air, 1.0, 1.45),
                               ref.fresnel_reflectance(mu_binder, 1.45, 1.0), rtol=CLOSED_FORM_REL_TOL)


# === 2. Semi-infinite, isotropic, n = 1: the H-function solution =============================

H_TEST_OMEGAS = [0.5, 0.9, 0.99, 0.999, 1.0 - 1e-4, 1.0 - 1e-5, 1.0]
H_TEST_ANGLES = np.array([0.0, 20.0, 45.0, 60.0, 75.0, 85.0])


@pytest.mark.parametrize("omega", H_TEST_OMEGAS)
def test_semi_infinite_brdf_equals_h_function(omega):
    theta_i, theta_o = np.meshgrid(H_TEST_ANGLES, H_TEST_ANGLES, indexing="ij")
    mu0, mu = np.cos(np.radians(theta_i)), np.cos(np.radians(theta_o))
    expected = ref.semi_infinite_reflection_function(mu, mu0, omega) / np.pi
    for delta_phi in (0.0, 70.0, 180.0):  # isotropic: no azimuth dependence
        got = bayespig.brdf(theta_i, theta_o, delta_phi, a=1.0 - omega, tau=np.inf, n=1.0)
        np.testing.assert_allclose(got, expected, rtol=H_FUNCTION_REL_TOL)


@pytest.mark.parametrize("omega", H_TEST_OMEGAS)
def test_semi_infinite_hemispherical_equals_h_function(omega):
    got = bayespig.hemispherical_reflectance(H_TEST_ANGLES, a=1.0 - omega, tau=np.inf, n=1.0)
    expected = ref.semi_infinite_hemispherical_reflectance(np.cos(np.radians(H_TEST_ANGLES)),
                                                           omega)
    np.testing.assert_allclose(got, expected, rtol=H_FUNCTION_REL_TOL)


@pytest.mark.parametrize("omega, hemispherical, albedo, r11", [
    (0.9, 0.41495, 0.47802, 0.38507), (0.5, 0.11523, 0.14654, None),
    (0.99, 0.75272, 0.79456, None)])
def test_semi_infinite_published_totals(omega, hemispherical, albedo, r11):
    a = 1.0 - omega
    got_h = bayespig.hemispherical_reflectance(0.0, a=a, tau=np.inf, n=1.0)
    assert abs(got_h - hemispherical) < PUBLISHED_5_DECIMALS_ABS_TOL
    # diffuse albedo = 2 int_0^1 R_h(mu0) mu0 dmu0
    mu0, w = ref.gauss_on_unit_interval(TEST_GAUSS_POINTS)
    r_h = bayespig.hemispherical_reflectance(np.degrees(np.arccos(mu0)), a=a, tau=np.inf, n=1.0)
    assert abs(2.0 * np.sum(w * mu0 * r_h) - albedo) < PUBLISHED_5_DECIMALS_ABS_TOL
    if r11 is not None:
        assert abs(np.pi * bayespig.brdf(0.0, 0.0, 0.0, a=a, tau=np.inf, n=1.0) - r11) \
            < PUBLISHED_5_DECIMALS_ABS_TOL


# === 3. Finite slab, n = 1: van de Hulst =====================================================

VDH_MU0 = np.array([1.0, 0.9, 0.7, 0.5, 0.3, 0.1])
VDH_R = np.array([0.28616, 0.30277, 0.34188, 0.39102, 0.45353, 0.53214])
VDH_T = np.array([0.14864, 0.14731, 0.13963, np.nan, 0.09425, 0.06601])


def test_van_de_hulst_table_12():
    R, T = adding_doubling.bare_layer_functions(np.array([0.5]), VDH_MU0, a=0.2, tau=2.0)
    assert R.shape == T.shape == (1, VDH_MU0.size)
    np.testing.assert_allclose(R[0], VDH_R, rtol=0, atol=TABLE_ABS_TOL)
    known = ~np.isnan(VDH_T)
    np.testing.assert_allclose(T[0, known], VDH_T[known], rtol=0, atol=TABLE_ABS_TOL)


def test_bare_layer_reflection_via_brdf_at_n_1():
    """pi * azimuth-averaged BRDF at n = 1 is the reflection function (isotropic)."""
    mu0 = VDH_MU0[:-1]
    got = np.pi * bayespig.brdf(np.degrees(np.arccos(mu0)), 60.0, 0.0, a=0.2, tau=2.0, n=1.0)
    np.testing.assert_allclose(got, VDH_R[:-1], rtol=0, atol=TABLE_ABS_TOL)


@pytest.mark.parametrize("a, tau, g, r_total, t_total", [
    (0.01, 1.0, 0.0, 0.48652, 0.49163),
    (0.01, 4.0, 0.5, 0.61996, 0.30605)])
def test_van_de_hulst_hemispherical_totals(a, tau, g, r_total, t_total):
    mu0 = 0.5
    mu, w = ref.gauss_on_unit_interval(TEST_GAUSS_POINTS)
    R, T = adding_doubling.bare_layer_functions(mu, np.array([mu0]), a=a, tau=tau, g=g)
    r_hemi = 2.0 * np.sum(w * mu * R[:, 0])
    t_hemi = 2.0 * np.sum(w * mu * T[:, 0]) + np.exp(-tau / mu0)
    assert abs(r_hemi - r_total) < TABLE_ABS_TOL
    assert abs(t_hemi - t_total) < TABLE_ABS_TOL
    r_public = bayespig.hemispherical_reflectance(60.0, a=a, tau=tau, g=g, n=1.0)
    assert abs(r_public - r_total) < TABLE_ABS_TOL


# === 4. Single-scattering limit ===============================================================

SS_GEOMETRIES = [  # (theta_i, theta_o, delta_phi) in air
    *zip(MULTI_THETA_I, MULTI_THETA_O, MULTI_DELTA_PHI),
    (30.0, 50.0, 0.0), (30.0, 50.0, 60.0), (30.0, 50.0, 120.0), (30.0, 50.0, 180.0),
    (0.0, 70.0, 90.0), (60.0, 20.0, 150.0),
]


@pytest.mark.parametrize("n", [1.0, 1.45])
@pytest.mark.parametrize("g", [0.0, 0.5, -0.3, 0.8, RAYLEIGH])
@pytest.mark.parametrize("tau", [1e-4, 1e-3])
def test_single_scattering_limit(tau, g, n):
    theta_i, theta_o, delta_phi = (np.array(v) for v in zip(*SS_GEOMETRIES))
    omega = 0.9
    got = bayespig.brdf(theta_i, theta_o, delta_phi, a=1.0 - omega, tau=tau, g=g, n=n)
    expected = ref.single_scattering_brdf(theta_i, theta_o, delta_phi, omega=omega, tau=tau,
                                          g=g, n=n)
    tolerance = SINGLE_SCATTERING_REL_TOL_FACTOR * tau * (1.0 + np.log(1.0 / tau))
    assert np.all(rel_err(got, expected) < tolerance), (got, expected)


@pytest.mark.parametrize("n", [1.0, 1.45])
def test_forward_scattering_is_brighter_on_the_specular_side(n):
    """delta_phi convention: g > 0 sends a thin layer's light to delta_phi = 180."""
    tau = 1e-3
    azimuths = np.array([0.0, 180.0])
    for g in (0.5, -0.5):
        got = bayespig.brdf(45.0, 45.0, azimuths, a=0.1, tau=tau, g=g, n=n)
        expected = ref.single_scattering_brdf(45.0, 45.0, azimuths, omega=0.9, tau=tau, g=g, n=n)
        assert (got[1] > got[0]) == (g > 0)
        ratio_tolerance = 2 * SINGLE_SCATTERING_REL_TOL_FACTOR * tau * (1.0 + np.log(1.0 / tau))
        assert abs((got[1] / got[0]) / (expected[1] / expected[0]) - 1.0) < ratio_tolerance


# === 5. Energy conservation and reciprocity ==================================================

ENERGY_THETA_I = np.array([0.0, 8.0, 45.0, 75.0])


@pytest.mark.parametrize("n", [1.0, 1.45, 1.6])
@pytest.mark.parametrize("g", [0.0, 0.5, -0.3, 0.9, RAYLEIGH])
@pytest.mark.parametrize("tau", [0.1, 1.0, 10.0, np.inf])
def test_energy_conservation(tau, g, n):
    total = bayespig.hemispherical_reflectance(ENERGY_THETA_I, a=0.0, tau=tau, g=g, r_s=1.0, n=n,
                                               specular="included")
    atol = OPAQUE_CONSERVATIVE_ENERGY_ABS_TOL if np.isinf(tau) else ENERGY_ABS_TOL
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=atol)


OPAQUE_ENERGY_THETA_I = np.array([0.0, 8.0, 30.0, 45.0, 60.0, 75.0, 85.0])


@pytest.mark.parametrize("n", [1.0, 1.45, 1.6])
@pytest.mark.parametrize("g", [0.0, 0.5, 0.9, 0.95])
def test_opaque_conservative_energy(g, n):
    """A semi-infinite layer that absorbs nothing reflects all the light (the substrate unseen)."""
    for r_s in (0.0, 1.0):
        total = bayespig.hemispherical_reflectance(OPAQUE_ENERGY_THETA_I, a=0.0, tau=np.inf, g=g, r_s=r_s,
                                                   n=n, specular="included")
        np.testing.assert_allclose(total, 1.0, rtol=0, atol=OPAQUE_CONSERVATIVE_ENERGY_ABS_TOL)


@pytest.mark.parametrize("g", [0.0, 0.9, 0.95])
@pytest.mark.parametrize("a", [1e-5, 1e-4, 1e-3])
def test_opaque_weak_absorption_equals_thick_layer(a, g):
    """White pigments (a ~ 1e-4): the opaque limit is that of a finite layer doubled to a thickness
    where e^{-12} of the diffusion mode (k ~ sqrt(3 a (1 - g))) is left."""
    thick = 2.0 ** np.ceil(np.log2(12.0 / np.sqrt(3.0 * a * (1.0 - g))))
    kwargs = {"g": g, "n": 1.45, "n_modes": 1}
    opaque = forward.surface_terms([8.0, 45.0], [0.0, 30.0, 60.0], a=[a], tau=[np.inf], **kwargs)
    finite = forward.surface_terms([8.0, 45.0], [0.0, 30.0, 60.0], a=[a], tau=[thick], solver="doubling",
                                   **kwargs)
    np.testing.assert_allclose(opaque.h0, finite.h0, rtol=OPAQUE_EQUALS_THICK_REL_TOL)
    np.testing.assert_allclose(opaque.f0_modes, finite.f0_modes, rtol=OPAQUE_EQUALS_THICK_REL_TOL)


RECIPROCITY_PAIRS = np.array([(10.0, 60.0), (30.0, 75.0), (0.0, 45.0), (45.0, 85.0),
                              (20.0, 50.0)])
RECIPROCITY_AZIMUTHS = np.array([0.0, 45.0, 90.0, 135.0, 180.0])


@pytest.mark.parametrize("g", [0.5, -0.4, 0.8, RAYLEIGH])
@pytest.mark.parametrize("tau, r_s", [(0.5, 0.0), (3.0, 0.7), (np.inf, 0.0)])
def test_reciprocity(g, tau, r_s):
    u = RECIPROCITY_PAIRS[:, 0, None]
    v = RECIPROCITY_PAIRS[:, 1, None]
    kwargs = {"a": 0.05, "tau": tau, "g": g, "r_s": r_s, "n": 1.45}
    f_uv = bayespig.brdf(u, v, RECIPROCITY_AZIMUTHS, **kwargs)
    f_vu = bayespig.brdf(v, u, RECIPROCITY_AZIMUTHS, **kwargs)
    np.testing.assert_allclose(f_uv, f_vu, rtol=RECIPROCITY_REL_TOL)


# === 6. Substrate law, clear binder ===========================================================

SUBSTRATE_ALBEDOS = [0.01, 0.3, 0.7, 0.95, 1.0]


@pytest.mark.parametrize("g", [0.0, 0.5])
@pytest.mark.parametrize("tau", [0.3, 2.0])
def test_substrate_law_identity(g, tau):
    """Eq. (3) as stated in the contract, for several r_s from one set of terms."""
    theta_i, theta_o, delta_phi = MULTI_THETA_I, MULTI_THETA_O, MULTI_DELTA_PHI
    kwargs = {"a": 0.1, "tau": tau, "g": g, "n": 1.45}
    # substrate_law_terms takes one geometry at a time
    terms = [substrate.substrate_law_terms(*geometry, **kwargs)
             for geometry in zip(theta_i, theta_o, delta_phi)]
    f0, t_down, t_up, r_up = (np.array(column) for column in zip(*terms))
    for r_s in SUBSTRATE_ALBEDOS:
        direct = bayespig.brdf(theta_i, theta_o, delta_phi, r_s=r_s, **kwargs)
        law = f0 + r_s * t_down * t_up / (1.0 - r_s * r_up)
        np.testing.assert_allclose(direct, law, rtol=IDENTITY_REL_TOL)


@pytest.mark.parametrize("g", [0.0, 0.5, RAYLEIGH])
@pytest.mark.parametrize("tau", [0.3, 2.0, np.inf])
def test_substrate_law_equals_direct_solve(g, tau):
    """brdf (eq. 3) against a solve with the substrate added as a layer at n = 1.45."""
    r_s = np.array(SUBSTRATE_ALBEDOS)
    batch = {"a": np.full(r_s.size, 0.1), "tau": np.full(r_s.size, tau)}
    solved = forward.surface_terms([45.0], MULTI_THETA_O, g=g, n=1.45, included_substrate=r_s,
                                   **batch)
    direct = solved.brdf(MULTI_DELTA_PHI[None, :, None], np.zeros(r_s.size))[:, :, 0]
    # the identity, on the same (doubling) kernels as the direct solve
    doubling = forward.surface_terms([45.0], MULTI_THETA_O, g=g, n=1.45, solver="doubling", **batch)
    law = doubling.brdf(MULTI_DELTA_PHI[None, :, None], r_s)[:, :, 0]
    np.testing.assert_allclose(law, direct, rtol=IDENTITY_REL_TOL)
    # and what users get (the eigen solver): the same discrete equations, solved otherwise
    public = bayespig.brdf(45.0, MULTI_THETA_O, MULTI_DELTA_PHI, a=0.1, tau=tau, g=g, r_s=r_s[:, None])
    np.testing.assert_allclose(public, direct, rtol=SOLVERS_REL_TOL)


@pytest.mark.parametrize("g", [0.0, 0.5])
@pytest.mark.parametrize("tau", [0.3, 2.0])
def test_substrate_at_n_1_equals_planetary_problem(g, tau):
    """n = 1: Chandrasekhar's planetary problem (1950, section 72) built from the bare layer.

    ``pi f(mu, mu0; r) = R(mu, mu0) + r t(mu0) t(mu) / (1 - r s)`` with ``t`` the total
    (diffuse + direct) transmittance and ``s`` the spherical albedo of the layer from below.
    Isotropic: the whole BRDF; HG: the substrate increment, which has no azimuth dependence.
    """
    a = 0.1
    nodes, w = ref.gauss_on_unit_interval(TEST_GAUSS_POINTS)
    view = np.array([1.0, 0.8, 0.5, 0.2])
    R_nodes, T_nodes = adding_doubling.bare_layer_functions(nodes, np.concatenate([view, nodes]),
                                                            a=a, tau=tau, g=g)
    t_total = 2.0 * (w * nodes) @ T_nodes + np.exp(-tau / np.concatenate([view, nodes]))
    t_view = t_total[: view.size]
    spherical_albedo = 4.0 * (w * nodes) @ R_nodes[:, view.size:] @ (w * nodes)
    R_view, _ = adding_doubling.bare_layer_functions(view, view, a=a, tau=tau, g=g)
    theta = np.degrees(np.arccos(view))
    azimuths = np.array([0.0, 90.0, 180.0])
    geometry = (theta[:, None, None], theta[None, :, None], azimuths)
    f_black = bayespig.brdf(*geometry, a=a, tau=tau, g=g, r_s=0.0, n=1.0)
    for r_s in SUBSTRATE_ALBEDOS:
        increment = r_s * np.outer(t_view, t_view) / (1.0 - r_s * spherical_albedo)
        f = bayespig.brdf(*geometry, a=a, tau=tau, g=g, r_s=r_s, n=1.0)
        # the substrate term carries no azimuth dependence
        np.testing.assert_allclose(np.pi * (f - f_black),
                                   np.broadcast_to(increment[..., None], f.shape),
                                   rtol=CONVERGED_REL_TOL)
        if g == 0.0:
            np.testing.assert_allclose(np.pi * f[..., 0], R_view + increment,
                                       rtol=CONVERGED_REL_TOL)


@pytest.mark.parametrize("n", [1.45, 1.6])
@pytest.mark.parametrize("tau", [0.3, 3.0])
def test_substrate_terms_physics(n, tau):
    """t_down, t_up, r_up against energy balance (a = 0) and reciprocity (any a)."""
    mu_air, w = ref.gauss_on_unit_interval(TEST_GAUSS_POINTS)
    theta = np.degrees(np.arccos(mu_air))
    kwargs = {"tau": tau, "g": 0.3, "n": n}
    # a = 0, black substrate: what is not reflected (specular included) reaches the substrate.
    terms = [substrate.substrate_law_terms(t, t, 180.0, a=0.0, **kwargs) for t in theta]
    _, t_down, t_up, r_up = (np.array(column) for column in zip(*terms))
    reflected = bayespig.hemispherical_reflectance(theta, a=0.0, r_s=0.0, specular="included",
                                                   **kwargs)
    np.testing.assert_allclose(t_down, 1.0 - reflected, rtol=CONVERGED_REL_TOL)
    # reciprocity: t_up(u) = t_down(u) / (pi n^2) (air radiance per unit exitance)
    np.testing.assert_allclose(np.pi * n**2 * t_down * t_up, t_down**2, rtol=CONVERGED_REL_TOL)
    # a = 0: exitance from the substrate either returns to it or escapes to air
    escaped = 2.0 * np.pi * np.sum(w * mu_air * t_up)
    np.testing.assert_allclose(r_up, 1.0 - escaped, rtol=CONVERGED_REL_TOL)


CLEAR_BINDER_GEOMETRIES = (np.array([0.0, 8.0, 45.0, 45.0, 60.0, 80.0]),
                           np.array([0.0, 30.0, 45.0, 80.0, 10.0, 85.0]))


@pytest.mark.parametrize("n", [1.45, 1.6])
@pytest.mark.parametrize("r_s", SUBSTRATE_ALBEDOS)
def test_clear_binder_formula(r_s, n):
    theta_i, theta_o = CLEAR_BINDER_GEOMETRIES
    expected = ref.clear_binder_brdf(theta_i, theta_o, r_s=r_s, n=n)
    got = substrate.clear_binder_brdf(theta_i, theta_o, r_s=r_s, n=n)
    np.testing.assert_allclose(got, expected, rtol=CLOSED_FORM_REL_TOL)


@pytest.mark.parametrize("tau", [0.0, 1e-9])
@pytest.mark.parametrize("r_s", SUBSTRATE_ALBEDOS)
def test_solver_at_zero_thickness_is_clear_binder(tau, r_s):
    theta_i, theta_o = CLEAR_BINDER_GEOMETRIES
    expected = ref.clear_binder_brdf(theta_i, theta_o, r_s=r_s, n=1.45)
    for g in (0.0, 0.5):
        got = bayespig.brdf(theta_i, theta_o, 90.0, a=0.3, tau=tau, g=g, r_s=r_s, n=1.45)
        np.testing.assert_allclose(got, expected, rtol=CLEAR_BINDER_REL_TOL)


def test_internal_diffuse_reflectance():
    assert abs(fresnel.internal_diffuse_reflectance(1.45) - 0.5645) \
        < INTERNAL_DIFFUSE_PUBLISHED_ABS_TOL
    for n in (1.2, 1.45, 1.6):
        assert abs(fresnel.internal_diffuse_reflectance(n) / ref.internal_diffuse_reflectance(n)
                   - 1.0) < CLOSED_FORM_REL_TOL
    # (1 - r_internal) n^2 = 1 - r_external (energy and etendue across the interface)
    mu, w = ref.gauss_on_unit_interval(TEST_GAUSS_POINTS)
    r_external = 2.0 * np.sum(w * mu * ref.fresnel_reflectance(mu, 1.0, 1.45))
    assert abs((1.0 - fresnel.internal_diffuse_reflectance(1.45)) * 1.45**2
               - (1.0 - r_external)) < CONVERGED_REL_TOL


# === 7. Fresnel and specular transmittance ====================================================


def test_fresnel_reference_values():
    assert abs(fresnel.fresnel_reflectance(1.0, 1.0, 1.45) - 0.033736) < FRESNEL_PUBLISHED_ABS_TOL
    assert abs(fresnel.fresnel_reflectance(1.0, 1.45, 1.0) - 0.033736) < FRESNEL_PUBLISHED_ABS_TOL
    mu_c = 0.72414
    inside = np.array([0.0, 0.3, mu_c - 1e-5])
    np.testing.assert_array_equal(fresnel.fresnel_reflectance(inside, 1.45, 1.0), 1.0)
    assert fresnel.fresnel_reflectance(mu_c + 1e-5, 1.45, 1.0) < 1.0
    mu = np.linspace(0.0, 1.0, 41)
    for n_i, n_t in ((1.0, 1.45), (1.45, 1.0), (1.0, 1.6)):
        np.testing.assert_allclose(fresnel.fresnel_reflectance(mu, n_i, n_t),
                                   ref.fresnel_reflectance(mu, n_i, n_t),
                                   rtol=CLOSED_FORM_REL_TOL, atol=1e-15)


@pytest.mark.parametrize("n", [1.45, 1.5, 1.6])
def test_specular_transmittance(n):
    t_normal = 1.0 - ((n - 1.0) / (n + 1.0)) ** 2
    assert abs(bayespig.specular_transmittance(0.0, n=n) - t_normal**2) < 1e-15
    tau = np.array([0.0, 0.01, 0.5, 2.0, 7.0])
    transmittance = bayespig.specular_transmittance(tau, n=n)
    np.testing.assert_allclose(transmittance, t_normal**2 * np.exp(-tau),
                               rtol=CLOSED_FORM_REL_TOL)
    np.testing.assert_allclose(bayespig.optical_thickness_from_transmittance(transmittance, n=n),
                               tau, rtol=0, atol=ROUND_TRIP_ABS_TOL)


# === 8. Slab with Fresnel faces: converged tables and iadpython ===============================

SLAB_TABLE = [  # (omega, b, g, n, UR1, UT1, URU, UTU), REFERENCE-VALUES.md section 3
    (0.9, 0.5, 0.0, 1.0, .16904, .76538, .24749, .65992),
    (0.9, 0.5, 0.0, 1.45, .17075, .69013, .23647, .61365),
    (0.9, 1.0, 0.0, 1.0, .26741, .59163, .35271, .47475),
    (0.9, 1.0, 0.0, 1.45, .22226, .51652, .28052, .44966),
    (0.9, 2.0, 0.0, 1.0, .36165, .35650, .43715, .26558),
    (0.9, 2.0, 0.0, 1.45, .25815, .29728, .30900, .25313),
    (0.975, 0.5, 0.0, 1.0, .19365, .78898, .28306, .69243),
    (0.975, 0.5, 0.0, 1.45, .21825, .73743, .28765, .66460),
    (0.975, 1.0, 0.0, 1.0, .32078, .63990, .42059, .53133),
    (0.975, 1.0, 0.0, 1.45, .30898, .60172, .37019, .53756),
    (0.975, 2.0, 0.0, 1.0, .46975, .44271, .55750, .35051),
    (0.975, 2.0, 0.0, 1.45, .39906, .42741, .44847, .38064),
    (0.9, 1.0, 0.5, 1.0, .12979, .73909, .22795, .59855),
    (0.9, 1.0, 0.5, 1.45, .15575, .60449, .22111, .51731),
    (0.9, 1.0, 0.9, 1.0, .01820, .87788, .06682, .76134),
    (0.9, 1.0, 0.9, 1.45, .07379, .78096, .14672, .65319),
]
TOTAL_KEYS = ("UR1", "UT1", "URU", "UTU")


@pytest.mark.parametrize("omega, b, g, n, expected",
                         [(*row[:4], row[4:]) for row in SLAB_TABLE])
def test_slab_totals_reference_table(omega, b, g, n, expected):
    # the default quadrature (default_quadrature_points) grows with |g|: 32 points at g = 0.9
    totals = adding_doubling.slab_totals(a=1.0 - omega, tau=b, g=g, n=n)
    got = [totals[key] for key in TOTAL_KEYS]
    np.testing.assert_allclose(got, expected, rtol=0, atol=SLAB_G09_ABS_TOL if (g, n) == (0.9, 1.0) else TABLE_ABS_TOL)


@pytest.mark.parametrize("n", [1.0, 1.45])
def test_slab_totals_converged_in_the_quadrature_at_g_09(n):
    """Where the published g = 0.9 values are good to ~1e-4 only, bayespig's own are converged."""
    default = adding_doubling.slab_totals(a=0.1, tau=1.0, g=0.9, n=n)
    finer = adding_doubling.slab_totals(a=0.1, tau=1.0, g=0.9, n=n, n_points=64)
    np.testing.assert_allclose([default[key] for key in TOTAL_KEYS], [finer[key] for key in TOTAL_KEYS],
                               rtol=0, atol=SLAB_QUADRATURE_CONVERGED_ABS_TOL)


IADPYTHON_CASES = [  # (omega, b, g, n): away from the table
    (0.5, 3.0, 0.3, 1.45), (0.99, 0.3, 0.7, 1.45), (0.7, 10.0, -0.3, 1.45),
    (0.9, 1.0, 0.5, 1.33), (0.8, 0.7, 0.0, 1.6),
]


@pytest.mark.parametrize("omega, b, g, n", IADPYTHON_CASES)
def test_slab_totals_equal_iadpython(omega, b, g, n):
    iadpython = pytest.importorskip("iadpython")
    sample = iadpython.Sample(a=omega, b=b, g=g, n=n, n_above=1.0, n_below=1.0,
                              quad_pts=IADPYTHON_QUAD_POINTS)
    expected = sample.rt()  # UR1, UT1, URU, UTU
    totals = adding_doubling.slab_totals(a=1.0 - omega, tau=b, g=g, n=n)
    got = [totals[key] for key in TOTAL_KEYS]
    np.testing.assert_allclose(got, expected, rtol=0, atol=TABLE_ABS_TOL)


# === 9. Broadcasting and bad arguments ========================================================


def test_brdf_broadcasts_geometries_against_absorption():
    a = np.linspace(0.001, 0.999, 50)
    got = bayespig.brdf(MULTI_THETA_I[:, None], MULTI_THETA_O[:, None], MULTI_DELTA_PHI[:, None],
                        a=a, tau=1.5, g=0.5, r_s=0.2)
    assert got.shape == (6, 50)
    for i in (0, 3, 5):
        for j in (0, 17, 49):
            single = bayespig.brdf(MULTI_THETA_I[i], MULTI_THETA_O[i], MULTI_DELTA_PHI[i], a=a[j],
                                   tau=1.5, g=0.5, r_s=0.2)
            assert np.shape(single) == ()
            assert abs(got[i, j] / single - 1.0) < IDENTITY_REL_TOL


def test_brdf_broadcasts_all_arguments():
    a = np.array([0.1, 0.5])[:, None, None]
    tau = np.array([0.5, 2.0, np.inf])[None, :, None]
    r_s = np.array([0.0, 0.9])[None, None, None, :]
    geometry = (v[:, None, None, None] for v in (MULTI_THETA_I, MULTI_THETA_O, MULTI_DELTA_PHI))
    got = bayespig.brdf(*geometry, a=a, tau=tau, r_s=r_s)
    assert got.shape == (6, 2, 3, 2)
    single = bayespig.brdf(MULTI_THETA_I[4], MULTI_THETA_O[4], MULTI_DELTA_PHI[4], a=0.5, tau=2.0,
                           r_s=0.9)
    assert abs(got[4, 1, 1, 1] / single - 1.0) < IDENTITY_REL_TOL


def test_hemispherical_broadcasts():
    a = np.linspace(0.001, 0.999, 50)
    got = bayespig.hemispherical_reflectance(np.array([8.0, 45.0])[:, None], a=a, tau=2.0)
    assert got.shape == (2, 50)
    sci = bayespig.hemispherical_reflectance(8.0, a=a, tau=2.0, specular="included")
    specular = ref.fresnel_reflectance(np.cos(np.radians(8.0)), 1.0, 1.45)
    np.testing.assert_allclose(sci - got[0], specular, rtol=CLOSED_FORM_REL_TOL)


GOOD = {"theta_i": 45.0, "theta_o": 30.0, "delta_phi": 180.0, "a": 0.1, "tau": 1.0}
BAD_ARGUMENTS = [
    ("a", -0.1), ("a", 1.1), ("a", np.nan), ("a", np.array([0.2, np.nan])),
    ("tau", -1.0), ("tau", np.nan),
    ("theta_i", 90.0), ("theta_i", -1.0), ("theta_i", np.nan),
    ("theta_o", 95.0), ("theta_o", np.array([10.0, 90.0])), ("theta_o", np.nan),
    ("delta_phi", np.nan),
    ("r_s", 1.5), ("r_s", -0.2),
]


@pytest.mark.parametrize("name, value", BAD_ARGUMENTS)
def test_brdf_bad_arguments(name, value):
    kwargs = {**GOOD, name: value}
    with pytest.raises(ValueError, match=name):
        bayespig.brdf(kwargs.pop("theta_i"), kwargs.pop("theta_o"), kwargs.pop("delta_phi"),
                      **kwargs)


@pytest.mark.parametrize("name, value", [
    (n, v) for n, v in BAD_ARGUMENTS if n not in ("theta_o", "delta_phi")])
def test_hemispherical_bad_arguments(name, value):
    kwargs = {"theta_i": 8.0, "a": 0.1, "tau": 1.0, name: value}
    with pytest.raises(ValueError, match=name):
        bayespig.hemispherical_reflectance(kwargs.pop("theta_i"), **kwargs)


def test_hemispherical_bad_specular_option():
    with pytest.raises(ValueError, match="specular"):
        bayespig.hemispherical_reflectance(8.0, a=0.1, tau=1.0, specular="sometimes")


@pytest.mark.parametrize("value", [-0.5, np.nan])
def test_specular_transmittance_bad_tau(value):
    with pytest.raises(ValueError, match="tau"):
        bayespig.specular_transmittance(value)
