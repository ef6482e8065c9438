"""Mixture rules (section 2) and concentrations (appendix A2)."""

import numpy as np
import pytest

from bayespig.physics.mixtures import concentrations_from_mass_fractions, mixture_properties

#: Closed-form mixing rules evaluated two ways: rounding (measured <= 5.6e-17).
EXACT_TOL = 1e-12


def test_equal_densities_give_mass_fractions():
    W = np.array([[0.1, 0.9], [0.5, 0.5]])
    np.testing.assert_allclose(concentrations_from_mass_fractions(W), W, atol=EXACT_TOL)


def test_concentrations_are_mass_per_dry_volume():
    # Independent bookkeeping: 1 kg of wet paint with pastes W_j and binder 1 - sum W;
    # after drying each part keeps q M of mass and takes q M / rho of volume. D_i is the
    # pure pigment's mass C_pp q_i W_i per dry volume (mu = 1).
    W = np.array([0.3, 0.5])
    q, rho, C_pp = np.array([0.9, 0.8]), np.array([4.0, 1.5]), np.array([0.7, 0.6])
    q_b, rho_b = 0.95, 0.93
    volume = np.sum(q * W / rho) + q_b * (1 - W.sum()) / rho_b
    expected = C_pp * q * W / volume
    got = concentrations_from_mass_fractions(W, paste_density=rho, paste_drying=q, binder_density=rho_b,
                                             binder_drying=q_b, pigment_scale=C_pp)
    np.testing.assert_allclose(got, expected, rtol=EXACT_TOL)


def test_mixture_rules_by_hand():
    D = np.array([0.2, 0.8])
    a = np.array([[0.5], [0.01]])
    sigma = np.array([[3.0], [10.0]])
    g = np.array([[0.2], [0.0]])
    a_mix, k_ext, g_mix = mixture_properties(D, a, sigma, g)
    k = 0.2 * 3.0 + 0.8 * 10.0
    assert k_ext[0] == pytest.approx(k, abs=EXACT_TOL)
    assert a_mix[0] == pytest.approx((0.2 * 3.0 * 0.5 + 0.8 * 10.0 * 0.01) / k, abs=EXACT_TOL)
    k_sc = 0.2 * 3.0 * 0.5 + 0.8 * 10.0 * 0.99
    assert g_mix[0] == pytest.approx(0.2 * 3.0 * 0.5 * 0.2 / k_sc, abs=EXACT_TOL)
    # one pigment alone is itself; a common scale of D cancels in a
    a1, k1 = mixture_properties(np.array([2.0, 0.0]), a, sigma)
    assert a1[0] == pytest.approx(0.5) and k1[0] == pytest.approx(6.0)
    a3, k3 = mixture_properties(3.0 * D, a, sigma)
    assert a3[0] == pytest.approx(a_mix[0], rel=EXACT_TOL) and k3[0] == pytest.approx(3 * k, rel=EXACT_TOL)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: concentrations_from_mass_fractions([0.7, 0.6]), "sum"),
        (lambda: concentrations_from_mass_fractions([-0.1, 0.6]), "mass_fractions"),
        (lambda: concentrations_from_mass_fractions([0.1, 0.6], paste_density=0.0), "paste_density"),
        (lambda: mixture_properties([0.5, 0.5], np.ones((3, 2)), np.ones((3, 2))), "relative_absorption"),
        (lambda: mixture_properties([0.0, 0.0], np.zeros((2, 1)), np.ones((2, 1))), "no extinction"),
        (lambda: mixture_properties([0.5, 0.5], np.full((2, 1), 1.5), np.ones((2, 1))), "<= 1"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(ValueError, match=match):
        call()
