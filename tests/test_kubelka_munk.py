"""Tests for bayespig.kubelka_munk against textbook values, limits and an ODE solution."""

import numpy as np
import pytest
from scipy import integrate, linalg

from bayespig import kubelka_munk as km

EXACT_TOL = 1e-12  # closed forms that must agree to rounding
ODE_TOL = 1e-10  # hyperbolic solution vs matrix exponential of the two-flux equations
ROUND_TRIP_TOL = 1e-10  # black/white calibration, Saunderson inversions
JUDD_TOL = 5e-4  # Judd (1942) tabulates diffuse Fresnel reflectances to 3 decimals
THIN_LAYER_REL_TOL = 1e-3  # R = SX (1 + O(SX, KX)) for SX, KX ~ 1e-4
QUAD_TOL = 1e-8  # scipy.integrate.quad of the diffuse Fresnel reflectance (its own error ~1e-10)


@pytest.fixture
def rng():
    return np.random.default_rng(19480501)


def two_flux_reference(K, S, thickness, background):
    """R and T from the Kubelka-Munk differential equations, integrated by expm.

    d/dz (i, j) = A (i, j) with i the downward and j the upward diffuse flux,
    A = [[-(K+S), S], [-S, K+S]]; boundary conditions i(0) = 1, j(X) = R_g i(X).
    """
    A = np.array([[-(K + S), S], [-S, K + S]])
    M = linalg.expm(A * thickness)
    R = (background * M[0, 0] - M[1, 0]) / (M[1, 1] - background * M[0, 1])
    T = M[0, 0] + M[0, 1] * R
    return R, T


def kubelka_coth_formula(K, S, thickness, background):
    """Kubelka (1948) hyperbolic solution as printed, for moderate arguments."""
    a = 1.0 + K / S
    b = np.sqrt(a * a - 1.0)
    coth = 1.0 / np.tanh(b * S * thickness)
    return (1.0 - background * (a - b * coth)) / (a - background + b * coth)


# ------------------------------------------------------------------ opaque layers


def test_reflectance_infinity_textbook_values():
    # K/S = 1: R_inf = 2 - sqrt(3); K/S = 0.25 <-> R_inf = 0.5; K/S = 0: perfect white.
    np.testing.assert_allclose(
        km.reflectance_infinity([1.0, 0.25, 0.0, np.inf]),
        [2.0 - np.sqrt(3.0), 0.5, 1.0, 0.0],
        atol=EXACT_TOL,
    )
    assert km.k_over_s_from_reflectance_infinity(0.5) == pytest.approx(0.25, abs=EXACT_TOL)
    assert km.k_over_s_from_reflectance_infinity(1.0) == 0.0


def test_reflectance_infinity_matches_printed_formula_and_round_trips(rng):
    q = np.exp(rng.uniform(np.log(1e-4), np.log(1e3), 200))
    printed = 1.0 + q - np.sqrt(q**2 + 2.0 * q)
    np.testing.assert_allclose(km.reflectance_infinity(q), printed, rtol=1e-9)
    np.testing.assert_allclose(
        km.k_over_s_from_reflectance_infinity(km.reflectance_infinity(q)), q, rtol=1e-8
    )


# ------------------------------------------------------------------ finite layers


@pytest.mark.parametrize(
    ("K", "S", "thickness", "background"),
    [
        (0.3, 1.0, 1.0, 0.0),
        (0.3, 1.0, 1.0, 0.8),
        (2.0, 0.2, 0.7, 0.5),
        (0.01, 3.0, 1.5, 0.9),
        (1.0, 1.0, 0.05, 0.3),
    ],
)
def test_layer_matches_two_flux_equations(K, S, thickness, background):
    R_ref, _ = two_flux_reference(K, S, thickness, background)
    assert km.layer_reflectance(K, S, thickness, background) == pytest.approx(R_ref, abs=ODE_TOL)
    assert km.layer_reflectance(K, S, thickness, background) == pytest.approx(
        kubelka_coth_formula(K, S, thickness, background), abs=EXACT_TOL
    )
    _, T_black = two_flux_reference(K, S, thickness, 0.0)
    assert km.layer_transmittance(K, S, thickness) == pytest.approx(T_black, abs=ODE_TOL)


def test_layer_thickness_limits():
    K, S = np.array([0.2, 1.0, 3.0]), np.array([2.0, 1.0, 0.5])
    background = 0.7
    R_inf = km.reflectance_infinity(K / S)
    np.testing.assert_allclose(km.layer_reflectance(K, S, 200.0, background), R_inf, atol=EXACT_TOL)
    np.testing.assert_allclose(
        km.layer_reflectance(K, S, np.inf, background), R_inf, atol=EXACT_TOL
    )
    np.testing.assert_allclose(
        km.layer_reflectance(K, S, 0.0, background), background, atol=EXACT_TOL
    )
    np.testing.assert_allclose(km.layer_transmittance(K, S, 0.0), 1.0, atol=EXACT_TOL)
    np.testing.assert_allclose(km.layer_transmittance(K, S, np.inf), 0.0, atol=EXACT_TOL)
    # Over a background equal to R_inf the thickness does not matter.
    np.testing.assert_allclose(km.layer_reflectance(K, S, 0.3, R_inf), R_inf, atol=EXACT_TOL)


def test_thin_layer_over_black_reflects_S_X():
    S, K, thickness = 2.0, 1.0, 5e-5
    R = km.layer_reflectance(K, S, thickness, 0.0)
    assert R == pytest.approx(S * thickness, rel=THIN_LAYER_REL_TOL)


def test_non_absorbing_layer_conserves_energy(rng):
    S = rng.uniform(0.01, 50.0, 100)
    thickness = rng.uniform(0.0, 3.0, 100)
    R = km.layer_reflectance(0.0, S, thickness, 0.0)
    T = km.layer_transmittance(0.0, S, thickness)
    np.testing.assert_allclose(R + T, 1.0, atol=EXACT_TOL)
    np.testing.assert_allclose(R, S * thickness / (1.0 + S * thickness), atol=EXACT_TOL)
    # And with absorption energy is lost.
    assert np.all(
        km.layer_reflectance(0.1, S, thickness + 0.1)
        + km.layer_transmittance(0.1, S, thickness + 0.1)
        < 1.0
    )


def test_non_scattering_layer_is_beer_lambert():
    K, thickness, background = 0.8, np.array([0.0, 0.5, 2.0]), 0.6
    np.testing.assert_allclose(
        km.layer_transmittance(K, 0.0, thickness), np.exp(-K * thickness), atol=EXACT_TOL
    )
    np.testing.assert_allclose(
        km.layer_reflectance(K, 0.0, thickness, background),
        background * np.exp(-2.0 * K * thickness),
        atol=EXACT_TOL,
    )


def test_limits_are_continuous():
    # Tiny but non-zero K or S must approach the K = 0 and S = 0 formulas smoothly.
    for K, S in [(1e-9, 2.0), (0.0, 2.0), (1.5, 1e-9), (1.5, 0.0)]:
        R_ref, _ = two_flux_reference(K, S, 0.8, 0.4)
        assert km.layer_reflectance(K, S, 0.8, 0.4) == pytest.approx(R_ref, abs=1e-8)
        _, T_ref = two_flux_reference(K, S, 0.8, 0.0)
        assert km.layer_transmittance(K, S, 0.8) == pytest.approx(T_ref, abs=1e-8)


def test_thick_films_do_not_overflow():
    R = km.layer_reflectance([1.0, 0.0], [1.0, 1.0], [1e6, 1e6], 1.0)
    np.testing.assert_allclose(R, [2.0 - np.sqrt(3.0), 1.0 - 1.0 / (1.0 + 1e6)], rtol=1e-6)
    assert km.layer_reflectance(0.0, 1.0, np.inf, 1.0) == 1.0


def test_layer_broadcasts_over_wavelengths_and_samples(rng):
    K = rng.uniform(0.0, 2.0, 31)
    S = rng.uniform(0.1, 2.0, 31)
    thickness = np.array([[0.5], [1.0], [2.0]])
    background = np.array([0.05, 0.9])[:, None, None]
    R = km.layer_reflectance(K, S, thickness, background)
    assert R.shape == (2, 3, 31)
    R_ref, _ = two_flux_reference(K[7], S[7], 2.0, 0.9)
    assert R[1, 2, 7] == pytest.approx(R_ref, abs=ODE_TOL)


# ------------------------------------------------------------------ mixtures


def test_mixing_is_concentration_weighted(rng):
    K = rng.uniform(0.0, 5.0, (3, 31))
    S = rng.uniform(0.1, 5.0, (3, 31))
    c = np.array([0.2, 0.0, 0.8])
    K_mix, S_mix = km.mix_K_S(c, K, S)
    np.testing.assert_allclose(K_mix, 0.2 * K[0] + 0.8 * K[2], atol=EXACT_TOL)
    np.testing.assert_allclose(S_mix, 0.2 * S[0] + 0.8 * S[2], atol=EXACT_TOL)
    batch = np.array([[1.0, 0.0, 0.0], [0.5, 0.5, 0.0]])
    K_b, S_b = km.mix_K_S(batch, K, S)
    assert K_b.shape == S_b.shape == (2, 31)
    np.testing.assert_allclose(S_b[0], S[0], atol=EXACT_TOL)
    # Opaque colour depends on relative concentrations only.
    np.testing.assert_allclose(np.divide(*km.mix_K_S(3.0 * c, K, S)), K_mix / S_mix, rtol=1e-12)


# ------------------------------------------------------------------ Saunderson


def fresnel_unpolarised(cos_i, n1, n2):
    sin_t = n1 / n2 * np.sqrt(1.0 - cos_i**2)
    if sin_t >= 1.0:
        return 1.0
    cos_t = np.sqrt(1.0 - sin_t**2)
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)
    return 0.5 * (rs**2 + rp**2)


def test_saunderson_constants_from_refractive_index():
    n = 1.5
    assert km.saunderson_k1(n) == pytest.approx(0.04, abs=EXACT_TOL)
    assert km.SAUNDERSON_K1 == pytest.approx(km.saunderson_k1(1.5), abs=EXACT_TOL)
    k2 = km.saunderson_k2(n)
    assert k2 == pytest.approx(0.596, abs=JUDD_TOL)  # Judd (1942), n = 1.5
    assert km.SAUNDERSON_K2 == pytest.approx(k2, abs=0.01)
    # External diffuse reflectance (from air, no total reflection): Judd's 0.092, and the
    # reciprocity relation 1 - r_i = (1 - r_e) / n^2.
    r_e = 2.0 * integrate.quad(lambda mu: fresnel_unpolarised(mu, 1.0, n) * mu, 0.0, 1.0)[0]
    assert r_e == pytest.approx(0.092, abs=JUDD_TOL)
    indices = np.array([1.33, 1.45, 1.5, 1.7])
    external = np.array([2.0 * integrate.quad(lambda mu, n=index: fresnel_unpolarised(mu, 1.0, n) * mu, 0, 1)[0]
                         for index in indices])
    internal = np.array([km.saunderson_k2(index) for index in indices])
    np.testing.assert_allclose(1.0 - internal, (1.0 - external) / indices**2, rtol=0, atol=QUAD_TOL)
    assert km.saunderson_k2(1.0) == pytest.approx(0.0, abs=EXACT_TOL)


@pytest.mark.parametrize("specular", ["included", "excluded"])
def test_saunderson_round_trip_and_end_points(specular, rng):
    R_i = rng.uniform(0.0, 1.0, (4, 31))
    k1, k2 = 0.045, 0.55
    R_m = km.saunderson_to_measured(R_i, k1, k2, specular=specular)
    np.testing.assert_allclose(
        km.saunderson_to_internal(R_m, k1, k2, specular=specular), R_i, atol=ROUND_TRIP_TOL
    )
    offset = k1 if specular == "included" else 0.0
    # A black body shows only the specular part; a white body returns everything.
    assert km.saunderson_to_measured(0.0, k1, k2, specular=specular) == offset
    assert km.saunderson_to_measured(1.0, k1, k2, specular=specular) == pytest.approx(
        1.0 - k1 + offset, abs=EXACT_TOL
    )
    assert np.all(np.diff(km.saunderson_to_measured(np.linspace(0, 1, 11), specular=specular)) > 0)


def test_saunderson_matches_hand_value():
    # R_i = 0.5, k1 = 0.04, k2 = 0.6: R_m = 0.04 + 0.96 * 0.4 * 0.5 / 0.7 = 0.314285714...
    value = km.saunderson_to_measured(0.5, 0.04, 0.6, specular="included")
    assert value == pytest.approx(0.04 + 0.96 * 0.4 * 0.5 / 0.7, abs=EXACT_TOL)


# ------------------------------------------------------------------ black/white calibration


def test_black_white_calibration_recovers_KX_SX(rng):
    KX = np.r_[0.0, rng.uniform(0.0, 3.0, 30)]
    SX = np.r_[0.5, rng.uniform(0.05, 4.0, 30)]
    g_black = np.linspace(0.0, 0.04, 31)  # real black cards are not ideal
    g_white = np.linspace(0.80, 0.90, 31)
    R_b = km.layer_reflectance(KX, SX, 1.0, g_black)
    R_w = km.layer_reflectance(KX, SX, 1.0, g_white)
    KX_fit, SX_fit = km.ks_from_black_white(R_b, R_w, g_black, g_white)
    np.testing.assert_allclose(KX_fit, KX, atol=ROUND_TRIP_TOL * 10, rtol=1e-8)
    np.testing.assert_allclose(SX_fit, SX, rtol=1e-8)


def test_black_white_textbook_formula_for_ideal_black():
    # Judd & Wyszecki: a = (R_w + (R_b - R_w + g_w) / (R_b g_w)) / 2 for g_b = 0.
    KX, SX, g_w = 0.4, 1.3, 0.85
    R_b = km.layer_reflectance(KX, SX, 1.0, 0.0)
    R_w = km.layer_reflectance(KX, SX, 1.0, g_w)
    a_textbook = 0.5 * (R_w + (R_b - R_w + g_w) / (R_b * g_w))
    assert a_textbook == pytest.approx(1.0 + KX / SX, abs=1e-12)
    KX_fit, SX_fit = km.ks_from_black_white(R_b, R_w, 0.0, g_w)
    assert KX_fit / SX_fit == pytest.approx(a_textbook - 1.0, rel=1e-10)


def test_black_white_opaque_and_noisy_films():
    R_inf = km.reflectance_infinity(0.5)
    with pytest.raises(ValueError, match="opaque"):
        km.ks_from_black_white(R_inf, R_inf, 0.01, 0.85)
    KX, SX = km.ks_from_black_white(
        [R_inf, R_inf + 1e-4], [R_inf, R_inf], 0.01, 0.85, clip_to_physical=True
    )
    assert np.all(np.isinf(KX))
    assert np.all(np.isinf(SX))
    # A white film over black and white, pushed to slightly negative K by noise.
    R_b = km.layer_reflectance(0.0, 2.0, 1.0, 0.01)
    R_w = km.layer_reflectance(0.0, 2.0, 1.0, 0.85) + 2e-3
    with pytest.raises(ValueError, match="negative absorption"):
        km.ks_from_black_white(R_b, R_w, 0.01, 0.85)
    KX, SX = km.ks_from_black_white(R_b, R_w, 0.01, 0.85, clip_to_physical=True)
    assert KX == 0.0
    assert 0.0 < SX < np.inf


# ------------------------------------------------------------------ bad input


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: km.reflectance_infinity(-0.1), "k_over_s"),
        (lambda: km.reflectance_infinity(np.nan), "k_over_s"),
        (lambda: km.k_over_s_from_reflectance_infinity(0.0), "reflectance_infinity"),
        (lambda: km.k_over_s_from_reflectance_infinity(1.2), "reflectance_infinity"),
        (lambda: km.layer_reflectance(-1.0, 1.0), "K"),
        (lambda: km.layer_reflectance(1.0, [1.0, np.nan]), "S"),
        (lambda: km.layer_reflectance(1.0, 1.0, -2.0), "thickness"),
        (lambda: km.layer_reflectance(1.0, 1.0, 1.0, 1.5), "background_reflectance"),
        (lambda: km.layer_transmittance(0.0, 0.0, np.inf), "thickness"),
        (lambda: km.saunderson_to_measured(0.5, specular="sci"), "specular"),
        (lambda: km.saunderson_to_measured(0.5, 0.04, 1.0, specular="included"), "k2"),
        (lambda: km.saunderson_to_internal(0.02, 0.04, 0.6, specular="included"), "excluded"),
        (lambda: km.saunderson_to_internal(-0.1, specular="excluded"), "measured_reflectance"),
        (lambda: km.saunderson_k2(0.9), "refractive_index"),
        (lambda: km.mix_K_S([0.5, 0.5], np.ones((3, 31)), np.ones((3, 31))), "K"),
        (lambda: km.mix_K_S([0.5, -0.5], np.ones((2, 31)), np.ones((2, 31))), "concentrations"),
        (lambda: km.ks_from_black_white(0.3, 0.5, 0.9, 0.1), "background_white"),
        (lambda: km.ks_from_black_white(0.3, 0.5, 0.0, 1.1), "background_white"),
        (lambda: km.ks_from_black_white(0.05, 0.5, 0.1, 0.8), "scattering"),
    ],
)
def test_bad_input_raises(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_saunderson_requires_stating_the_specular_mode():
    with pytest.raises(TypeError):
        km.saunderson_to_internal(0.5)  # a wrong default would shift dark colours by k1


# ------------------------------------------------------------------ baseline for measured films


def test_saunderson_constants_for_the_binder():
    # REFERENCE-VALUES.md section 4 (n = 1.45): normal-incidence Fresnel 0.033736, internal
    # diffuse reflectance 0.5645; at 8 degrees r_F differs from normal incidence by < 1e-5.
    k1_normal, k2 = km.saunderson_constants(1.45, 0.0)
    assert k1_normal == pytest.approx(0.033736, abs=1e-6)
    assert k2 == pytest.approx(0.5645, abs=1e-4)
    k1_8, _ = km.saunderson_constants(1.45, 8.0)
    assert k1_8 == pytest.approx(k1_normal, abs=1e-5)
    assert k1_8 > k1_normal  # Fresnel reflectance grows with the angle
    with pytest.raises(ValueError, match="theta_i"):
        km.saunderson_constants(1.45, 90.0)


@pytest.mark.parametrize("specular", ["excluded", "included"])
def test_saunderson_internal_of_a_card_is_bayespig_substrate_albedo(specular, rng):
    # Saunderson's inversion with k1 = r_F(8 deg), k2 = r_i is eq. (9) integrated over the
    # sphere, inverted by a separate implementation in bayespig.physics.substrate.
    from bayespig.physics.substrate import substrate_albedo_from_air

    k1, k2 = km.saunderson_constants(1.45, 8.0)
    card = rng.uniform(0.04, 0.85, 31)
    r_s = substrate_albedo_from_air(card, n=1.45, kind="hemispherical", theta_i=8.0, specular=specular)
    np.testing.assert_allclose(
        km.saunderson_to_internal(card, k1, k2, specular=specular), r_s, rtol=1e-12
    )


@pytest.mark.parametrize("specular", ["excluded", "included"])
def test_calibrate_film_recovers_KX_SX_and_predicts_it_back(specular, rng):
    k1, k2 = km.saunderson_constants(1.45, 8.0)
    KX = rng.uniform(0.01, 2.0, 31)
    SX = rng.uniform(0.2, 4.0, 31)
    cards = (np.full(31, 0.11), np.linspace(0.80, 0.93, 31))
    measured = [km.predict_measured(KX, SX, g, specular=specular, k1=k1, k2=k2) for g in cards]
    film = km.calibrate_film(*measured, *cards, specular=specular, k1=k1, k2=k2)
    np.testing.assert_allclose(film.KX, KX, rtol=1e-8)
    np.testing.assert_allclose(film.SX, SX, rtol=1e-8)
    np.testing.assert_allclose(film.k_over_s, KX / SX, rtol=1e-8)
    assert not film.opaque.any()


def test_predict_measured_textbook_layer_over_black():
    # Non-absorbing layer over an ideal black: R_i = SX / (1 + SX) (Kubelka 1948), then
    # Saunderson with k1 = 0.04, k2 = 0.6 by hand.
    R_i = 2.0 / 3.0
    expected = 0.04 + 0.96 * 0.4 * R_i / (1.0 - 0.6 * R_i)
    assert km.predict_measured(0.0, 2.0, 0.0, specular="included", k1=0.04, k2=0.6) == pytest.approx(
        expected, abs=EXACT_TOL
    )


def test_calibrate_opaque_film_gives_k_over_s_from_R_inf():
    # K/S = 0.25 <-> R_inf = 0.5 (textbook); an opaque film looks the same over both cards.
    k1, k2 = 0.04, 0.6
    R_m = km.saunderson_to_measured(0.5, k1, k2, specular="excluded")
    film = km.calibrate_film([R_m], [R_m], [0.05], [0.85], specular="excluded", k1=k1, k2=k2)
    assert film.opaque.all()
    assert film.k_over_s[0] == pytest.approx(0.25, abs=1e-12)
