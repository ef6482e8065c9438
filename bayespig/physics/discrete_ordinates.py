"""Closed-form layer kernels from the discrete-ordinate eigen solution (an alternative to doubling).

The kernels of :mod:`bayespig.physics.adding_doubling` solve, on the same quadrature, the
discrete radiative transfer equation of one azimuthal mode

    mu_i dI+_i/dtau = -I+_i + (omega / 2) sum_j w_j (pT_ij I+_j + pR_ij I-_j)
   -mu_i dI-_i/dtau = -I-_i + (omega / 2) sum_j w_j (pR_ij I+_j + pT_ij I-_j)

(``I+`` downward, ``I-`` upward; the kernel convention of the doubling module, whose thin-layer
limit is the single-scattering kernel). With ``A = M^-1 (omega/2 pT W - 1)`` and
``B = M^-1 (omega/2 pR W)`` the sum ``Z = I+ + I-`` obeys ``Z'' = (A - B)(A + B) Z``; its
eigenvectors ``V`` and eigenvalues ``k^2`` give the decaying solutions ``(U, W) e^{-k tau}``
with ``U = (V + Y) / 2``, ``W = (V - Y) / 2``, ``Y = -(A - B)^-1 V k``, and by symmetry the
growing ones ``(W, U) e^{-k (tau0 - tau)}``. The boundary conditions of a slab lit from above
(``I+(0) = f``, ``I-(tau0) = 0``) then give, with ``E = diag e^{-k tau0}`` and ``P = U^-1 W``,

    R = (W - U E P E) (U - W E P E)^-1,     T = (U - W P) E (U - W E P E)^-1,

and the semi-infinite layer ``R = W U^-1`` (Stamnes & Swanson 1981; Flatau & Stephens 1988).
One eigen decomposition per (``a``, mode) serves every ``tau``: a further thickness costs two
N x N products and one solve instead of ~25 doublings (``benchmarks/layer_solvers.py``).

Status: groundwork for issue 2's speed goal, not yet used by the forward model. The operator
form needs positive weights: a zero-weight node (an exact measurement direction) as the
*incident* direction carries no flux in it, so its kernel column needs the particular solution
of a collimated beam, and as an outgoing direction it resonates with its own decoupled eigen
direction (``k = 1/mu``); both call for the formal integration of the source function
(DISORT's intensities at arbitrary angles), which is not written yet.

The conservative limit ``a -> 0`` makes the smallest ``k`` vanish (the diffusion mode, linear
in ``tau``), where this form degenerates: :func:`layer_mode_eigen` therefore hands ``a <``
:data:`SMALL_ABSORPTION` to the doubling solver.

References
----------
Stamnes & Swanson (1981), J. Atmos. Sci. 38, 387 (the reduced eigenproblem);
Flatau & Stephens (1988), J. Geophys. Res. 93, 11037 (layer reflection and transmission).
"""

from __future__ import annotations

import numpy as np

from .adding_doubling import START_THICKNESS, layer_mode

__all__ = ["SMALL_ABSORPTION", "layer_mode_eigen"]

#: Below this relative absorption the diffusion mode's ``k ~ sqrt(3 a)`` nears 0 and the eigen
#: form loses accuracy; such layers go through doubling.
SMALL_ABSORPTION = 1e-4


def _eigen_solutions(mu, weight, a, p_reflection, p_transmission):
    """``U``, ``W`` (G, N, N) and ``k`` (G, N) of the decaying solutions for every ``a`` (G,).

    The symmetric reduction (Stamnes & Swanson 1981): with ``S = w^(1/2)`` and the symmetric
    ``C+- = S (omega/2) (pT +- pR) S - 1``, ``A +- B = M^-1 S^-1 C+- S``, so
    ``(A - B)(A + B)`` is similar to ``G = L^T M^-1 (-C-) M^-1 L`` with ``-C+ = L L^T``
    (Cholesky): a symmetric positive definite matrix, whose eigenvectors ``X`` (``eigh``) stay
    accurate where those of the unsymmetric product do not (high azimuthal modes, grazing
    nodes). Eigenvectors of ``(A - B)(A + B)``: ``S^-1 L^-T X``.
    """
    n = mu.size
    omega = (1.0 - a)[:, None, None]
    root_w = np.sqrt(weight)
    eye = np.eye(n)
    c_plus = 0.5 * omega * (root_w[:, None] * (p_transmission + p_reflection) * root_w) - eye
    c_minus = 0.5 * omega * (root_w[:, None] * (p_transmission - p_reflection) * root_w) - eye
    chol = np.linalg.cholesky(-c_plus)  # L, lower
    inv_mu = 1.0 / mu
    g_matrix = np.swapaxes(chol, 1, 2) @ ((inv_mu[:, None] * -c_minus * inv_mu) @ chol)
    k2, X = np.linalg.eigh(g_matrix)
    k = np.sqrt(np.maximum(k2, 0.0))
    base = np.linalg.solve(np.swapaxes(chol, 1, 2), X)  # L^-T X
    Y = -np.linalg.solve(c_minus, mu[:, None] * base * k[:, None, :])  # -(A-B)^-1 V k, scaled
    V = base / root_w[:, None]
    Y = Y / root_w[:, None]
    return 0.5 * (V + Y), 0.5 * (V - Y), k


def layer_mode_eigen(mu, weight, a, tau, p_reflection, p_transmission, start_thickness=START_THICKNESS):
    """Kernels of a homogeneous layer for one azimuthal mode, from the eigen solution.

    Same parameters and returns as :func:`bayespig.physics.adding_doubling.layer_mode` (which it
    calls for ``a <`` :data:`SMALL_ABSORPTION`); one eigen decomposition per distinct ``a``.

    Parameters
    ----------
    mu, weight : numpy.ndarray
        Quadrature nodes and weights, shape (N,) [-]; weights must be positive.
    a : numpy.ndarray
        Relative absorption, shape (B,) [-].
    tau : numpy.ndarray
        Optical thickness, shape (B,) [-]; all finite or all ``inf``.
    p_reflection, p_transmission : numpy.ndarray
        This mode of the phase function, shape (N, N) [-].
    start_thickness : float
        Passed to the doubling solver for weakly absorbing layers.

    Returns
    -------
    R, T : numpy.ndarray
        Kernels, shape (B, N, N) [-].
    direct : numpy.ndarray
        ``exp(-tau/mu)``, shape (B, N) [-].
    """
    if not (np.asarray(weight) > 0).all():
        raise ValueError("layer_mode_eigen needs positive quadrature weights (no zero-weight "
                         "measurement nodes; use adding_doubling.layer_mode for those)")
    a = np.atleast_1d(np.asarray(a, dtype=float))
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    opaque = np.isinf(tau)
    if opaque.any() and not opaque.all():
        raise ValueError("tau must be all finite or all infinite in one batch")
    n = mu.size
    c = mu * weight
    R = np.empty((a.size, n, n))
    T = np.zeros((a.size, n, n))
    direct = np.zeros((a.size, n)) if opaque.all() else np.exp(-tau[:, None] / mu[None, :])
    small = a < SMALL_ABSORPTION
    if small.any():
        R[small], T[small], _ = layer_mode(mu, weight, a[small], tau[small], p_reflection, p_transmission,
                                           start_thickness)
    rows = np.flatnonzero(~small)
    if rows.size == 0:
        return R, T, direct
    distinct, which = np.unique(a[rows], return_inverse=True)
    U, W, k = _eigen_solutions(mu, weight, distinct, p_reflection, p_transmission)
    U, W, k = U[which], W[which], k[which]
    # kernels act on c * L: divide the operators' columns by c
    inv_c = 1.0 / c
    if opaque.all():
        R[rows] = np.swapaxes(np.linalg.solve(np.swapaxes(U, 1, 2), np.swapaxes(W, 1, 2)), 1, 2) * inv_c
        return R, T, direct
    E = np.exp(-tau[rows, None] * k)  # (G, N)
    P = np.linalg.solve(U, W)
    EPE = E[:, :, None] * P * E[:, None, :]
    D = U - W @ EPE
    numerators = np.concatenate([W - U @ EPE, (U - W @ P) * E[:, None, :]], axis=1)  # (G, 2N, N)
    # X D = numerator  <=>  D^T X^T = numerator^T
    solved = np.swapaxes(np.linalg.solve(np.swapaxes(D, 1, 2), np.swapaxes(numerators, 1, 2)), 1, 2)
    R[rows] = solved[:, :n] * inv_c
    T[rows] = (solved[:, n:] - direct[rows][:, :, None] * np.eye(n)) * inv_c
    return R, T, direct
