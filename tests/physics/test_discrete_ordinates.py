"""The discrete-ordinate solver (the forward model's) against the doubling solver.

Reference: :func:`bayespig.physics.adding_doubling.layer_mode` on the same quadrature and
phase-function modes (itself checked against the H-function, van de Hulst's tables and
iadpython in ``test_reference_values.py``). Both solve the same discrete equations, so they
agree to the doubling's own start error (~1e-8), far below the 1e-5 the forward model needs.
"""

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from bayespig.physics import discrete_ordinates
from bayespig.physics.adding_doubling import layer_mode
from bayespig.physics.discrete_ordinates import SMALL_ABSORPTION, layer_mode_eigen
from bayespig.physics.forward import surface_geometry, surface_terms
from bayespig.physics.phase import normalise_on_quadrature, phase_fourier_modes
from bayespig.physics.quadrature import binder_quadrature, default_quadrature_points

#: Two solutions of the same discrete equations. Measured (tests/physics/test_discrete_ordinates.py
#: cases, OpenBLAS kernels Haswell, SkylakeX, Sandybridge, Prescott): <= 4.1e-8 in modes 0-2 and
#: <= 1.4e-7 in mode 4 (SkylakeX; 4.9e-8 Haswell), where a -> 1 leaves kernel entries ~1e-6 of the
#: batch's largest whose error is the eigen form's absolute round-off, ~6e-14 of the largest entry
#: (it scales exactly as 1 / NEGLIGIBLE). Doubling's own error is smaller: its kernels change by
#: <= 2e-11 from a start of 2^-18 to 2^-22 and by <= 2e-16 between BLAS kernels. Margin 14x.
SAME_EQUATIONS_REL_TOL = 2e-6
#: Kernel entries below this fraction of the batch's largest are compared absolutely (the eigen
#: form's round-off, ~6e-14 of the largest entries, is a large part of entries 1e-8 of them).
NEGLIGIBLE = 1e-6
#: Unscattered transmission: doubling squares exp(-d/mu) n times, doubling its relative round-off
#: each time (~2^n ulp; up to 25 doublings here). Measured <= 3.7e-8 (element-wise, the same on
#: every BLAS kernel). Margin 27x.
DIRECT_REL_TOL = 1e-6


def _modes(mu, weight, g, n_modes):
    p_r = phase_fourier_modes(mu, mu, g, n_modes, reflection=True)
    p_t = phase_fourier_modes(mu, mu, g, n_modes, reflection=False)
    return normalise_on_quadrature(p_r, p_t, weight)


def _close(x, reference):
    """Largest relative difference; entries below NEGLIGIBLE of the batch's largest absolutely."""
    floor = NEGLIGIBLE * np.abs(reference).max()
    return (np.abs(x - reference) / np.maximum(np.abs(reference), floor)).max()


@pytest.mark.parametrize("g, mode", [(0.0, 0), (0.5, 0), (0.5, 1), (0.5, 4), (-0.3, 2)])
@pytest.mark.parametrize("opaque", [False, True])
def test_eigen_layer_equals_doubling(g, mode, opaque):
    mu, weight = binder_quadrature(8, 1.45)
    p_r, p_t = _modes(mu, weight, g, mode + 1)
    rng = np.random.default_rng(5)
    # a across the whole range (below SMALL_ABSORPTION the doubling path is taken), repeated a
    a = np.concatenate([[0.0, 0.5 * SMALL_ABSORPTION, 2 * SMALL_ABSORPTION, 1.0],
                        rng.uniform(0.0, 1.0, 12), [0.3, 0.3, 0.3]])
    tau = np.full(a.size, np.inf) if opaque else np.exp(rng.uniform(np.log(1e-3), np.log(100.0), a.size))
    R_e, T_e, d_e = layer_mode_eigen(mu, weight, a, tau, p_r[mode], p_t[mode])
    R_d, T_d, d_d = layer_mode(mu, weight, a, tau, p_r[mode], p_t[mode])
    # doubling's opaque conservative limit is not a reference: its spurious absorption of ~1e-10
    # per unit tau costs it ~1e-5 there (test_opaque_conservative_eigen_layer_conserves_energy)
    compared = ~((a == 0.0) & opaque)
    assert _close(R_e[compared], R_d[compared]) < SAME_EQUATIONS_REL_TOL
    np.testing.assert_allclose(d_e, d_d, rtol=DIRECT_REL_TOL, atol=0)
    if opaque:
        assert not T_e.any()
    else:
        assert _close(T_e, T_d) < SAME_EQUATIONS_REL_TOL


#: Flux reflected by the opaque conservative kernel, ``sum_i c_i R_ij``, against 1. Measured (the
#: cases below, four OpenBLAS kernels): <= 6.6e-12, and 4.4e-8 at g = 0.95, n = 1 (128 nodes in one
#: interval). Margin 20x. Doubling's opaque limit loses ~1e-5 (g = 0) to ~1e-4 (g = 0.95) here.
CONSERVATIVE_FLUX_ABS_TOL = 1e-6


@pytest.mark.parametrize("n", [1.0, 1.45])
@pytest.mark.parametrize("g", [0.0, 0.5, 0.9, 0.95])
def test_opaque_conservative_eigen_layer_conserves_energy(g, n):
    mu, weight = binder_quadrature(default_quadrature_points(g), n)
    p_r, p_t = _modes(mu, weight, g, 1)
    R, T, direct = layer_mode_eigen(mu, weight, np.array([0.0]), np.array([np.inf]), p_r[0], p_t[0])
    np.testing.assert_allclose((mu * weight) @ R[0], 1.0, rtol=0, atol=CONSERVATIVE_FLUX_ABS_TOL)
    assert not T.any() and not direct.any()


def test_eigen_layer_refuses_zero_weight_nodes_and_mixed_batches():
    mu, weight = binder_quadrature(4, 1.45, extra_nodes=(0.7,))
    p_r, p_t = _modes(mu, weight, 0.0, 1)
    with pytest.raises(ValueError, match="positive quadrature weights"):
        layer_mode_eigen(mu, weight, np.array([0.1]), np.array([1.0]), p_r[0], p_t[0])
    mu, weight = binder_quadrature(4, 1.45)
    p_r, p_t = _modes(mu, weight, 0.0, 1)
    with pytest.raises(ValueError, match="all finite or all infinite"):
        layer_mode_eigen(mu, weight, np.array([0.1, 0.2]), np.array([1.0, np.inf]), p_r[0], p_t[0])


# --- the forward model's path: radiances under the surface at the exact directions -----------
#: Both solvers' forward terms: the doubling's start error (thicker for modes >= 1) and the
#: eigen form's conditioning. Measured (four OpenBLAS kernels) <= 5.7e-9 of each term's largest
#: value over a and tau, 4.9e-8 at the beam's resonance, 2.0e-8 per row of thin layers. Margin 40x.
SOLVERS_REL_TOL = 2e-6
#: One layer solved alone or in a batch: rounding only (measured <= 4.2e-15). Margin > 100x.
SAME_BATCH_REL_TOL = 1e-12
TERMS = ("f0_modes", "t_down", "t_up", "r_up", "h0", "t_up_hemispherical")
#: Incidence and viewing angles in air [deg]: the sphere's 8, the multi-angle set, normal and
#: grazing viewing.
THETA_IN = [8.0, 45.0]
THETA_OUT = [0.0, 8.0, 30.0, 45.0, 60.0, 89.0]


def _largest_difference(eigen, doubling, rows=slice(None)):
    """Largest difference of each SurfaceTerms field over ``rows``, relative to that field's largest value."""
    out = {}
    for name in TERMS:
        x, y = getattr(eigen, name)[rows], getattr(doubling, name)[rows]
        scale = np.abs(y).max()
        out[name] = 0.0 if scale == 0.0 else float(np.abs(x - y).max() / scale)
    return out


@pytest.mark.parametrize("g", [0.0, 0.5, -0.3, 5.0])
@pytest.mark.parametrize("opaque", [False, True])
def test_surface_terms_eigen_equals_doubling(g, opaque):
    """Every term of eq. (3) and every BRDF mode from the boundary-value solution (beam particular
    solution, formal integration, the surface as top boundary) against doubling the kernels and
    adding the surface; a over [0, 1] (finite layers with the smallest through doubling in both),
    tau from 0. Not the opaque a = 0 row: doubling's conservative limit is off by ~1e-5 there
    (test_reference_values.py::test_opaque_conservative_energy)."""
    rng = np.random.default_rng(17)
    a = np.concatenate([[0.0, 0.5 * SMALL_ABSORPTION, 2 * SMALL_ABSORPTION, 1.0], rng.uniform(0.0, 1.0, 20)])
    tau = np.full(a.size, np.inf) if opaque else np.concatenate(
        [[0.0, 1.0, 3.0, 0.0], np.exp(rng.uniform(np.log(1e-3), np.log(100.0), 17)), [1e-12, 1e-9, 2e-6]])
    n_modes = 6 if g not in (0.0, 5.0) else None
    eigen = surface_terms(THETA_IN, THETA_OUT, a=a, tau=tau, g=g, n_modes=n_modes)
    doubling = surface_terms(THETA_IN, THETA_OUT, a=a, tau=tau, g=g, n_modes=n_modes, solver="doubling")
    differences = _largest_difference(eigen, doubling, ~((a == 0.0) & np.isinf(tau)))
    assert max(differences.values()) < SOLVERS_REL_TOL, differences


def _resonant_absorption(g, mode, theta_in):
    """An ``a`` where an eigenvalue of ``mode`` equals ``1/u`` of the refracted incidence ``u``."""
    geometry = surface_geometry([theta_in], [30.0], 1.45, 16)
    q = geometry.n_weighted
    p_r, p_t = _modes(geometry.mu, geometry.weight, g, mode + 1)
    rate = 1.0 / geometry.mu[geometry.idx_in][0]

    def eigenvalues(a):
        return np.sort(discrete_ordinates._eigen_solutions(
            geometry.mu[:q], geometry.weight[:q], np.array([a]), p_r[mode][:q, :q], p_t[mode][:q, :q])[2][0])

    grid = np.geomspace(2 * SMALL_ABSORPTION, 1.0, 200)
    gaps = np.array([eigenvalues(a) for a in grid]) - rate
    for j in range(q):
        crossing = np.flatnonzero(np.diff(np.sign(gaps[:, j])))
        if crossing.size:
            i = crossing[0]
            return brentq(lambda a, j=j: eigenvalues(a)[j] - rate, grid[i], grid[i + 1], xtol=1e-15)
    return None


@pytest.mark.parametrize("opaque", [False, True])
def test_beam_at_the_resonance_of_its_particular_solution(opaque):
    """At ``k = 1/u`` the beam's particular solution is singular (DISORT's resonance); the
    extrapolation across it keeps the radiances those of doubling, which has no such point."""
    a0 = _resonant_absorption(0.5, 1, 45.0)
    assert a0 is not None, "expected an eigenvalue of mode 1 to cross 1/u for some a"
    a = a0 * np.array([1.0, 1.0 + 1e-12, 1.0 - 1e-9, 1.0 + 1e-6, 1.0 + 1e-2])
    tau = np.full(a.size, np.inf if opaque else 0.7)
    eigen = surface_terms([45.0], [30.0, 60.0], a=a, tau=tau, g=0.5, n_modes=2)
    doubling = surface_terms([45.0], [30.0, 60.0], a=a, tau=tau, g=0.5, n_modes=2, solver="doubling")
    mode_1 = np.abs(eigen.f0_modes[:, 1] - doubling.f0_modes[:, 1]) / np.abs(doubling.f0_modes[:, 1]).max()
    assert mode_1.max() < SOLVERS_REL_TOL, mode_1.max()


#: The growing integral against quadrature (scipy's quad, itself within 2e-15 of the closed form
#: in 50-digit arithmetic): just outside the series (|x| = 2e-3, tau = 30) the difference of two
#: attenuations each rounded to ~tau k ulp loses ~1e-16 tau k / |x|, measured 2.3e-12 (element-
#: wise exp, no BLAS). Margin 9x. (pytest.approx's default abs = 1e-12 is off: at tau = 30 the
#: values are ~1e-22.)
GROWING_INTEGRAL_REL_TOL = 2e-11


@pytest.mark.parametrize("tau", [1e-3, 0.7, 30.0])
def test_growing_integral_across_the_resonance(tau):
    """``int_0^tau e^{-t/mu} e^{-k (tau - t)} dt`` against quadrature, k through 1/mu."""
    inv_mu = 1.7
    k = inv_mu + np.array([-3.0, -1e-2, -1e-5, 0.0, 1e-8, 1e-4, 2e-3, 5.0]) / tau
    got = discrete_ordinates._growing_integral(np.exp(-tau * inv_mu), np.exp(-tau * k), k - inv_mu, tau)
    for value, rate in zip(got, k):
        reference = quad(lambda t, rate=rate: np.exp(-t * inv_mu - rate * (tau - t)), 0.0, tau, epsabs=0,
                         epsrel=1e-13)[0]
        assert value == pytest.approx(reference, rel=GROWING_INTEGRAL_REL_TOL, abs=0)


def test_results_do_not_depend_on_the_batch():
    """A layer solved alone or among others (other a, tau, some through doubling, several row
    blocks) gives the same terms."""
    rng = np.random.default_rng(3)
    a = np.concatenate([rng.uniform(0.0, 1.0, 70), [5e-6, 0.3]])
    tau = np.concatenate([np.exp(rng.uniform(np.log(1e-3), np.log(100.0), 70)), [42.0, 0.0]])
    together = surface_terms([45.0], [30.0, 60.0], a=a, tau=tau, g=0.5)
    for i in (0, 40, 70, 71):
        alone = surface_terms([45.0], [30.0, 60.0], a=a[i:i + 1], tau=tau[i:i + 1], g=0.5)
        for name in TERMS:
            x, y = getattr(alone, name)[0], getattr(together, name)[i]
            if name == "f0_modes":  # the batch stores as many modes as its slowest member needs
                x = np.concatenate([x, np.zeros((y.shape[0] - x.shape[0],) + x.shape[1:])])
            np.testing.assert_allclose(x, y, rtol=SAME_BATCH_REL_TOL, atol=1e-300)


def test_thin_layers_keep_their_relative_accuracy():
    """A film of tau ~ 1e-12 reflects ~1e-12: each value to 1e-6 of itself, not of the batch."""
    tau = np.array([1e-12, 1e-9, 1e-7, 3e-6, 1e-4])
    a = np.full(tau.size, 0.3)
    eigen = surface_terms([8.0, 45.0], [0.0, 60.0], a=a, tau=tau, g=0.5)
    doubling = surface_terms([8.0, 45.0], [0.0, 60.0], a=a, tau=tau, g=0.5, solver="doubling")
    for name in ("h0", "f0_modes"):
        x, y = getattr(eigen, name), getattr(doubling, name)
        if name == "f0_modes":
            modes = min(x.shape[1], y.shape[1])
            x, y = x[:, :modes], y[:, :modes]
        per_row = np.abs(x - y).reshape(tau.size, -1).max(axis=1) / np.abs(y).reshape(tau.size, -1).max(axis=1)
        assert per_row.max() < SOLVERS_REL_TOL, (name, per_row)
