"""Angular quadrature inside the binder.

The cosine range (0, 1] is split at the critical cosine ``mu_c = sqrt(1 - 1/n^2)``:
below it light is totally internally reflected at the binder/air surface, above
it the Fresnel reflectance behaves like ``sqrt(mu - mu_c)``. Each part gets its
own Gauss–Legendre rule; the upper one in the variable ``s`` with
``mu = mu_c + (1 - mu_c) s^2``, which removes that square root, so the internal
reflectance integrals converge spectrally.

Measurement directions are appended as zero-weight nodes (``extra_nodes``): they
take no part in any angular integral but every kernel is evaluated at them
exactly (Nystrom interpolation), so a BRDF at an instrument geometry is never
interpolated from a coarse grid.
"""

from __future__ import annotations

import numpy as np

from .fresnel import critical_cosine

__all__ = ["DEFAULT_QUADRATURE_POINTS", "MAX_DEFAULT_QUADRATURE_POINTS", "binder_quadrature",
           "default_quadrature_points", "gauss_legendre_barycentric_weights"]

#: Default number of Gauss points per interval (two intervals when n > 1), for |g| <= 0.8.
DEFAULT_QUADRATURE_POINTS = 16
#: Most points per interval :func:`default_quadrature_points` chooses (|g| = 0.95).
MAX_DEFAULT_QUADRATURE_POINTS = 64


def default_quadrature_points(g):
    """Gauss points per interval that converge the BRDF to 1e-4 (relative) for the phase function.

    A Henyey–Greenstein forward peak of width ~(1 - |g|) needs ~3.2 / (1 - |g|) points per
    interval, in steps of 8 and at least :data:`DEFAULT_QUADRATURE_POINTS`: 16 up to
    |g| = 0.8, 24 at 0.85, 32 at 0.9, 64 at 0.95 (measured, reports/validation.md). Beyond
    |g| = 0.95 the choice stops at :data:`MAX_DEFAULT_QUADRATURE_POINTS`, which no longer
    converges to 1e-4 there: pass ``n_points`` explicitly. Rayleigh scattering (|g| > 1) needs
    the default.

    Parameters
    ----------
    g : float
        Phase-function parameter (paper's convention).

    Returns
    -------
    int
    """
    g = abs(float(g))
    if g <= 0.8 or g > 1.0:
        return DEFAULT_QUADRATURE_POINTS
    needed = 8 * int(np.ceil(3.2 / (1.0 - g) / 8.0 - 1e-9))
    return int(min(max(needed, DEFAULT_QUADRATURE_POINTS), MAX_DEFAULT_QUADRATURE_POINTS))


def _gauss(n_points, lo, hi):
    x, w = np.polynomial.legendre.leggauss(n_points)
    return lo + (hi - lo) * (x + 1.0) / 2.0, w * (hi - lo) / 2.0


def binder_quadrature(n_points=DEFAULT_QUADRATURE_POINTS, n=1.45, extra_nodes=()):
    """Quadrature nodes and weights for cosines in (0, 1] inside the binder.

    Parameters
    ----------
    n_points : int
        Gauss points per interval [-].
    n : float
        Refractive index of the binder [-]; ``n = 1`` gives a single interval
        of ``2 n_points`` points (the same cost).
    extra_nodes : sequence of float
        Additional direction cosines evaluated exactly, with zero weight [-].

    Returns
    -------
    mu : numpy.ndarray
        Nodes, the quadrature nodes first, then ``extra_nodes`` [-].
    weight : numpy.ndarray
        Weights for ``int_0^1 h(mu) dmu ~ sum weight * h(mu)`` [-].
    """
    if n_points < 2:
        raise ValueError(f"n_points must be at least 2, got {n_points}")
    mu_c = critical_cosine(n)
    if mu_c > 0.0:
        lower_mu, lower_w = _gauss(n_points, 0.0, mu_c)
        s, s_w = _gauss(n_points, 0.0, 1.0)
        upper_mu = mu_c + (1.0 - mu_c) * s * s
        upper_w = s_w * 2.0 * (1.0 - mu_c) * s
        mu = np.concatenate([lower_mu, upper_mu])
        weight = np.concatenate([lower_w, upper_w])
    else:
        mu, weight = _gauss(2 * n_points, 0.0, 1.0)
    extra = np.asarray(extra_nodes, dtype=float).ravel()
    return np.concatenate([mu, extra]), np.concatenate([weight, np.zeros(extra.size)])


def gauss_legendre_barycentric_weights(n_points):
    """Barycentric weights of the ``n_points`` Gauss-Legendre nodes (ascending, as
    :func:`numpy.polynomial.legendre.leggauss` returns them).

    ``w_j = (-1)^j sqrt((1 - x_j^2) lambda_j)`` with ``lambda_j`` the Gauss weights (Wang,
    Huybrechs & Vandewalle 2014, "Explicit barycentric weights for polynomial interpolation in
    the roots or extrema of classical orthogonal polynomials", Math. Comp. 83, 2893; checked
    against the definition ``1 / prod_{k != j} (x_j - x_k)`` in tests/physics/test_quadrature.py),
    up to a common factor, which the barycentric formula of the second kind divides out, so they
    serve any affine image of the nodes. Closed form, so every process gets the same bits: scipy's
    :class:`~scipy.interpolate.BarycentricInterpolator` computes its weights from products in a
    random order drawn from numpy's unseeded global generator, which made the rough tables (and
    through them the chains of a seeded run) differ in the last bit between processes.

    Parameters
    ----------
    n_points : int
        Number of nodes, >= 1.

    Returns
    -------
    numpy.ndarray
        (n_points,) [-].
    """
    x, weight = np.polynomial.legendre.leggauss(n_points)
    sign = np.where(np.arange(n_points) % 2 == 0, 1.0, -1.0)
    return sign * np.sqrt((1.0 - x * x) * weight)
