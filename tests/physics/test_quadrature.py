"""The default quadrature for a phase function (bayespig.physics.quadrature).

Reference: the same solver on twice as many points (convergence), the issue's 1e-4 budget.
"""

import numpy as np
import pytest

import bayespig
from bayespig.physics.quadrature import (
    DEFAULT_QUADRATURE_POINTS,
    MAX_DEFAULT_QUADRATURE_POINTS,
    default_quadrature_points,
    gauss_legendre_barycentric_weights,
)

#: Issue 2: the default quadrature converged to 1e-4 relative. Measured <= 2.3e-5 (g = 0.9; the
#: quadrature's own error, the same under OpenBLAS Haswell, SkylakeX, Sandybridge, Prescott).
#: Margin 4.4x.
CONVERGED_REL_TOL = 1e-4
ASPECULAR = np.array([-15.0, 15.0, 25.0, 45.0, 75.0, 110.0])
THETA_O = np.abs(45.0 - ASPECULAR)
DELTA_PHI = np.where(45.0 - ASPECULAR >= 0, 180.0, 0.0)


def test_default_points_grow_with_the_forward_peak():
    assert default_quadrature_points(0.0) == DEFAULT_QUADRATURE_POINTS
    assert default_quadrature_points(-0.8) == DEFAULT_QUADRATURE_POINTS
    assert default_quadrature_points(2.0) == DEFAULT_QUADRATURE_POINTS  # Rayleigh
    assert default_quadrature_points(0.85) == 24
    assert default_quadrature_points(0.9) == default_quadrature_points(-0.9) == 32
    assert default_quadrature_points(0.99) == MAX_DEFAULT_QUADRATURE_POINTS


@pytest.mark.parametrize("g", [0.85, 0.9])
def test_default_quadrature_is_converged_for_peaked_phase_functions(g):
    """The six multi-angle BRDFs at the default points against twice as many."""
    rng = np.random.default_rng(4)
    a = rng.uniform(0.001, 0.999, 12)
    tau = np.exp(rng.uniform(np.log(0.01), np.log(100.0), 12))
    geometry = (45.0, THETA_O[:, None], DELTA_PHI[:, None])
    default = bayespig.brdf(*geometry, a=a, tau=tau, g=g)
    finer = bayespig.brdf(*geometry, a=a, tau=tau, g=g, n_points=2 * default_quadrature_points(g))
    assert np.abs(default / finer - 1.0).max() < CONVERGED_REL_TOL


#: Barycentric weights against their definition 1 / prod_{k != j} (x_j - x_k): the products,
#: scaled by the capacity 4 / (b - a) as Berrut & Trefethen advise, lose ~n ulps; measured
#: spread of the ratio 7e-14 at n = 24 (against scipy's products). Margin 14x.
BARYCENTRIC_REL_TOL = 1e-12


@pytest.mark.parametrize("n_points", [2, 5, 12, 24])
def test_gauss_legendre_barycentric_weights_are_the_definition(n_points):
    x, _ = np.polynomial.legendre.leggauss(n_points)
    difference = 2.0 * (x[:, None] - x[None, :])  # capacity 4 / (1 - (-1)) = 2
    np.fill_diagonal(difference, 1.0)
    definition = 1.0 / np.prod(difference, axis=1)
    ratio = gauss_legendre_barycentric_weights(n_points) / definition
    assert np.ptp(ratio) <= BARYCENTRIC_REL_TOL * abs(ratio.mean())


def test_gauss_legendre_barycentric_weights_interpolate_polynomials_exactly():
    from scipy.interpolate import BarycentricInterpolator

    n_points = 16
    x, _ = np.polynomial.legendre.leggauss(n_points)
    nodes = 0.3 + 0.2 * x  # an affine image: the common factor of the weights divides out
    polynomial = np.polynomial.Polynomial(np.linspace(1.0, -2.0, n_points))  # degree n - 1
    at = np.linspace(0.1, 0.5, 37)
    interpolant = BarycentricInterpolator(nodes, polynomial(nodes),
                                          wi=gauss_legendre_barycentric_weights(n_points))
    # degree 15 on [0.1, 0.5]: values O(1), rounding of the barycentric sums ~1e-15; margin 1000x
    assert np.max(np.abs(interpolant(at) - polynomial(at))) <= 1e-12
