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
#: Attenuation factors ``e^{-k tau}`` below this are set to zero (their products would be
#: subnormal numbers, slow to compute with, and they are far below any accuracy that matters).
NEGLIGIBLE_ATTENUATION = 1e-100
#: Layers solved together in :func:`radiances_under_surface` (cache-sized blocks).
ROW_BLOCK = 32


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


def _layer_integral(rate_top, rate_bottom, tau):
    """``int_0^tau exp(-rate_top t - rate_bottom (tau - t)) dt`` for rates ``>= 0`` [-].

    Stable for equal rates (the resonance ``k = 1/mu`` of the formal integration), where it is
    ``tau exp(-rate tau)``: written as ``tau e^-lo (1 - e^-d) / d`` with ``lo`` the smaller
    exponent and ``d`` the difference of the two. Arrays broadcast; ``tau`` finite.
    """
    p = rate_top * tau
    q = rate_bottom * tau
    gap = np.abs(p - q)
    small = gap < 1e-10
    safe = np.where(small, 1.0, gap)
    phi = np.where(small, 1.0 - 0.5 * gap, -np.expm1(-safe) / safe)
    return tau * np.exp(-np.minimum(p, q)) * phi


def _beam_particular_solutions(mu, weight, omega, cosines, p_r_beam, p_t_beam, p_reflection, p_transmission):
    """Particular solutions ``Z e^{-tau/u}`` of the quadrature equations for collimated beams.

    A beam of unit ``c I`` (the kernels' normalisation) travelling down along ``u`` scatters
    into the quadrature with the source ``(omega/2) p(mu_i, u) e^{-tau/u} / u``; the diffuse
    field it drives, ``I+- = Z+- e^{-tau/u}``, solves (``M = diag mu``, ``W = diag w``)

        [(omega/2) pT W - 1 + M/u] Z+ + (omega/2) pR W Z-            = -(omega/2) pT(., u) / u
        (omega/2) pR W Z+            + [(omega/2) pT W - 1 - M/u] Z- = -(omega/2) pR(., u) / u

    (Stamnes et al. 1988, eq. 15, in this module's notation). It is singular only where ``1/u``
    equals an eigenvalue ``k``, which a direction off the quadrature meets only by accident.

    Parameters
    ----------
    mu, weight : numpy.ndarray
        Quadrature nodes and positive weights, shape (N,) [-].
    omega : numpy.ndarray
        Single-scattering albedos, shape (G,) [-].
    cosines : numpy.ndarray
        Beam direction cosines in the binder, shape (L,) [-].
    p_r_beam, p_t_beam : numpy.ndarray
        Phase-function mode from each beam into the quadrature nodes, opposite and same
        hemisphere, shape (N, L) [-].
    p_reflection, p_transmission : numpy.ndarray
        The mode between quadrature nodes, shape (N, N) [-].

    Returns
    -------
    z_down, z_up : numpy.ndarray
        ``Z+`` and ``Z-``, shape (G, L, N) [-].
    """
    n = mu.size
    half = 0.5 * omega[:, None, None, None]
    shift = np.eye(n) * (mu / cosines[:, None])[:, None, :]  # (L, N, N): M / u
    same = half * (p_transmission * weight) - np.eye(n)
    cross = np.broadcast_to(half * (p_reflection * weight), same.shape[:1] + (cosines.size, n, n))
    system = np.block([[same + shift, cross], [cross, same - shift]])  # (G, L, 2N, 2N)
    source = np.concatenate([p_t_beam, p_r_beam], axis=0).T / cosines[:, None]  # (L, 2N)
    solution = np.linalg.solve(system, -0.5 * omega[:, None, None, None] * source[None, :, :, None])[..., 0]
    return solution[..., :n], solution[..., n:]


def layer_mode_eigen(mu, weight, a, tau, p_reflection, p_transmission, start_thickness=START_THICKNESS):
    """Kernels of a homogeneous layer for one azimuthal mode, from the eigen solution.

    Same parameters and returns as :func:`bayespig.physics.adding_doubling.layer_mode` (which it
    calls for ``a <`` :data:`SMALL_ABSORPTION`); one eigen decomposition per distinct ``a``.
    Zero-weight nodes (exact measurement directions) are solved as DISORT does (Stamnes et al.
    1988): as incident directions by the particular solution of a collimated beam
    (:func:`_beam_particular_solutions`) with the same boundary conditions, as outgoing
    directions by integrating the source function along them (:func:`_layer_integral`; the
    Nyström extension of the quadrature solution, which is what doubling computes on such
    nodes). Quadrature rows of the zero-weight columns give, by reciprocity of the symmetric
    kernels, the zero-weight rows of the quadrature columns.

    Parameters
    ----------
    mu, weight : numpy.ndarray
        Quadrature nodes and weights, shape (N,) [-]; zero weights mark exact directions.
    a : numpy.ndarray
        Relative absorption, shape (B,) [-].
    tau : numpy.ndarray
        Optical thickness, shape (B,) [-]; all finite or all ``inf``.
    p_reflection, p_transmission : numpy.ndarray
        This mode of the phase function, shape (N, N) [-]; symmetric.
    start_thickness : float
        Passed to the doubling solver for weakly absorbing layers.

    Returns
    -------
    R, T : numpy.ndarray
        Kernels, shape (B, N, N) [-].
    direct : numpy.ndarray
        ``exp(-tau/mu)``, shape (B, N) [-].

    References
    ----------
    Stamnes, Tsay, Wiscombe & Jayaweera (1988), Appl. Opt. 27, 2502 (DISORT: beam particular
    solution, intensities at arbitrary angles).
    """
    weight = np.asarray(weight, dtype=float)
    if (weight < 0).any():
        raise ValueError("quadrature weights must be >= 0 (zero marks an exact direction)")
    a = np.atleast_1d(np.asarray(a, dtype=float))
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    opaque = np.isinf(tau)
    if opaque.any() and not opaque.all():
        raise ValueError("tau must be all finite or all infinite in one batch")
    opaque = bool(opaque.all())
    n_all = mu.size
    R = np.empty((a.size, n_all, n_all))
    T = np.zeros((a.size, n_all, n_all))
    direct = np.zeros((a.size, n_all)) if opaque else np.exp(-tau[:, None] / mu[None, :])
    small = a < SMALL_ABSORPTION
    if small.any():
        R[small], T[small], _ = layer_mode(mu, weight, a[small], tau[small], p_reflection, p_transmission,
                                           start_thickness)
    rows = np.flatnonzero(~small)
    if rows.size == 0:
        return R, T, direct
    exact = weight == 0
    n = int((~exact).sum())
    if exact[:n].any():
        raise ValueError("zero-weight nodes must follow the quadrature nodes (as binder_quadrature puts them)")
    everything = rows.size == a.size
    R_eig = R if everything else np.empty((rows.size, n_all, n_all))
    T_eig = T if everything else np.zeros((rows.size, n_all, n_all))
    mu_q, w_q = mu[:n], weight[:n]
    distinct, which = np.unique(a[rows], return_inverse=True)
    U, W, k = _eigen_solutions(mu_q, w_q, distinct, p_reflection[:n, :n], p_transmission[:n, :n])
    # kernels act on c * L: divide the operators' columns by c
    inv_c = 1.0 / (mu_q * w_q)
    U_inv = np.linalg.inv(U)
    if opaque:
        E = np.zeros((rows.size, n))
        D_inv = U_inv[which]
        R_eig[:, :n, :n] = (W @ U_inv)[which] * inv_c
    else:
        E = np.exp(-tau[rows, None] * k[which])  # (B, N)
        P = U_inv @ W
        Ub, Wb = U[which], W[which]
        EPE = E[:, :, None] * P[which] * E[:, None, :]
        D_inv = np.linalg.inv(Ub - Wb @ EPE)
        R_eig[:, :n, :n] = (Wb - Ub @ EPE) @ D_inv * inv_c
        T_q = ((Ub - (W @ P)[which]) * E[:, None, :]) @ D_inv * inv_c
        T_q[:, np.arange(n), np.arange(n)] -= direct[rows, :n] * inv_c
        T_eig[:, :n, :n] = T_q
    if n < n_all:
        R_z, T_z = _exact_direction_kernels(mu, weight, n, distinct, which, tau[rows], U, W, k, U_inv, E,
                                            D_inv, p_reflection, p_transmission, opaque)
        # columns (incident along an exact direction) and, by reciprocity, rows over the quadrature
        R_eig[:, :, n:] = R_z
        R_eig[:, n:, :n] = np.swapaxes(R_z[:, :n], 1, 2)
        T_eig[:, :, n:] = T_z
        T_eig[:, n:, :n] = np.swapaxes(T_z[:, :n], 1, 2)
    if not everything:
        R[rows], T[rows] = R_eig, T_eig
    return R, T, direct


def _exact_direction_kernels(mu, weight, n, distinct, which, tau, U, W, k, U_inv, E, D_inv,
                             p_reflection, p_transmission, opaque):
    """Kernel columns of beams along the zero-weight nodes ``n:``, on all nodes (quadrature first).

    Returns ``R_z``, ``T_z`` of shape (B, N_q + N_z, N_z) [-]: the quadrature rows from the
    boundary conditions of the beam's diffuse field, the exact-direction rows from the formal
    integration of the source function along each direction (DISORT's intensities at user
    angles).
    """
    mu_q, w_q, u = mu[:n], weight[:n], mu[n:]
    omega = 1.0 - distinct
    z_down, z_up = _beam_particular_solutions(mu_q, w_q, omega, u, p_reflection[:n, n:], p_transmission[:n, n:],
                                              p_reflection[:n, :n], p_transmission[:n, :n])
    z_down = np.swapaxes(z_down, 1, 2)[which]  # (B, N, L)
    z_up = np.swapaxes(z_up, 1, 2)[which]
    Ub, Wb, U_inv_b = U[which], W[which], U_inv[which]
    beam = np.zeros((tau.size, u.size)) if opaque else np.exp(-tau[:, None] / u)  # (B, L)
    # boundary conditions I+(0) = 0, I-(tau) = 0 for Z + U a + W E b (down), Z + W E a + U b (up):
    # a = D^-1 (f - W E U^-1 g), b = U^-1 (g - W E a) with f = -Z+, g = -Z- e^{-tau/u}
    f = -z_down
    g = -z_up * beam[:, None, :]
    WE = Wb * E[:, None, :]
    alpha = D_inv @ (f - WE @ (U_inv_b @ g))
    beta = U_inv_b @ (g - WE @ alpha)
    UE = Ub * E[:, None, :]
    R_q = z_up + Wb @ alpha + UE @ beta
    T_q = z_down * beam[:, None, :] + UE @ alpha + Wb @ beta
    # source function along the exact directions: (omega/2) sum_j w_j p(mu, mu_j) I(mu_j)
    half = 0.5 * omega[:, None, None]
    p_r_zq = p_reflection[n:, :n] * w_q
    p_t_zq = p_transmission[n:, :n] * w_q
    up_decaying = (half * (p_r_zq @ U + p_t_zq @ W))[which]  # (B, L, N); growing: (W, U) swaps
    down_decaying = (half * (p_t_zq @ U + p_r_zq @ W))[which]
    half_b = half[which]
    up_particular = half_b * (p_r_zq @ z_down + p_t_zq @ z_up + p_reflection[n:, n:] / u)
    down_particular = half_b * (p_t_zq @ z_down + p_r_zq @ z_up + p_transmission[n:, n:] / u)
    inv_mu = (1.0 / u)[None, :, None]  # rows: viewing direction
    rate_beam = (1.0 / u)[None, None, :]  # columns: beam direction
    kk = k[which][:, None, :]  # (B, 1, N)
    if opaque:
        R_zz = (up_particular / (rate_beam + inv_mu) + (up_decaying / (kk + inv_mu)) @ alpha) * inv_mu
        T_zz = np.zeros_like(R_zz)
    else:
        t = tau[:, None, None]
        zero = np.zeros(1)
        R_zz = inv_mu * (up_particular * _layer_integral(rate_beam + inv_mu, zero, t)
                         + (up_decaying * _layer_integral(kk + inv_mu, zero, t)) @ alpha
                         + (down_decaying * _layer_integral(inv_mu, kk, t)) @ beta)
        T_zz = inv_mu * (down_particular * _layer_integral(rate_beam, inv_mu, t)
                         + (down_decaying * _layer_integral(kk, inv_mu, t)) @ alpha
                         + (up_decaying * _layer_integral(zero, kk + inv_mu, t)) @ beta)
    return np.concatenate([R_q, R_zz], axis=1), np.concatenate([T_q, T_zz], axis=1)


def _growing_integral(e_view, e_mode, rate_difference, tau):
    """``int_0^tau e^{-t/mu} e^{-k (tau - t)} dt = (e^{-tau/mu} - e^{-k tau}) / (k - 1/mu)`` [-].

    From the attenuations ``e_view = e^{-tau/mu}`` and ``e_mode = e^{-k tau}`` already at hand,
    with ``rate_difference = k - 1/mu``; near the resonance ``k = 1/mu`` (``|x| = |k - 1/mu| tau
    < 1e-3``) as ``tau e^{-tau/mu} (1 - e^{-x}) / x`` by its Taylor series (error ~x^4/120).
    Arrays broadcast.
    """
    x = rate_difference * tau
    near = np.abs(x) < 1e-3
    safe = np.where(near, 1.0, rate_difference)
    series = tau * e_view * (1.0 - x / 2.0 + x * x / 6.0 - x * x * x / 24.0)
    return np.where(near, series, (e_view - e_mode) / safe)


def _up_at_exact_directions(up_decaying, down_decaying, alpha, beta, k, tau, inv_mu, opaque):
    """Upward radiance leaving the top along exact directions from the homogeneous solutions.

    Formal integration of the source function ``sum_k (alpha_k h-_k e^{-k t} + beta_k h+_k
    e^{-k (tau - t)})`` along ``mu``: ``(1/mu) int_0^tau (...) e^{-t/mu} dt``.

    Parameters
    ----------
    up_decaying, down_decaying : numpy.ndarray
        Upward / downward source of each decaying solution along each direction, (B, L, N) [-]
        (a growing solution's upward source is the decaying one's downward source).
    alpha, beta : numpy.ndarray
        Coefficients of the decaying and growing solutions, (B, N, C) for C problems.
    k : numpy.ndarray
        Eigenvalues, (B, 1, N) [-].
    tau : numpy.ndarray
        Optical thickness, (B, 1, 1) [-] (ignored if ``opaque``).
    inv_mu : numpy.ndarray
        ``1/mu`` of the exact directions, (1, L, 1).
    opaque : bool
        Semi-infinite layer (``beta`` is not used).

    Returns
    -------
    numpy.ndarray
        (B, L, C) [-].
    """
    if opaque:
        return inv_mu * (up_decaying / (k + inv_mu)) @ alpha
    zero = np.zeros(1)
    return inv_mu * ((up_decaying * _layer_integral(k + inv_mu, zero, tau)) @ alpha
                     + (down_decaying * _layer_integral(inv_mu, k, tau)) @ beta)


def radiances_under_surface(mu, weight, a, tau, p_reflection, p_transmission, r_top, beams, views,
                            substrate=False):
    """Radiances of a layer under a specularly reflecting top, from one N x N solve per layer.

    The boundary-value problem of one azimuthal mode with the top boundary reflecting the
    upward quadrature radiance back down with reflectance ``r_top`` (the underside of the
    air/binder surface, eq. 8) and a black bottom: for collimated beams of unit ``c I`` along
    the exact directions ``beams`` just under the surface, and optionally (``substrate``) for
    a Lambertian bottom of unit radiance. With the eigen solutions ``I = Z + U alpha + W E beta``
    (down) and ``Z + W E alpha + U beta`` (up), the bottom condition gives
    ``beta = U^-1 (g - W E alpha)`` and the top condition
    ``[(U - r W) - (W - r U) E P E] alpha = f - (W - r U) E U^-1 g`` with
    ``P = U^-1 W`` (beam: ``f = -(Z+ - r Z-)``, ``g = -Z- e^{-tau/u}``; substrate: ``f = 0``,
    ``g = 1``). This replaces forming the layer kernels and adding the surface to them.

    Parameters
    ----------
    mu, weight : numpy.ndarray
        Quadrature nodes and weights, (N_all,), the zero-weight exact directions last [-].
    a, tau : numpy.ndarray
        Relative absorption in [SMALL_ABSORPTION, 1] and optical thickness, (B,) [-];
        ``tau`` all finite or all ``inf``.
    p_reflection, p_transmission : numpy.ndarray
        This mode of the phase function, (N_all, N_all) [-].
    r_top : numpy.ndarray
        Reflectance of the top boundary for upward radiance, at the weighted nodes (N,) [-].
    beams, views : numpy.ndarray
        Indices (into ``mu``) of the exact incidence and viewing directions.
    substrate : bool
        Also solve the problem of the Lambertian bottom (mode 0).

    Returns
    -------
    dict
        ``up_view`` (B, L_views, C): upward radiance under the top along ``views``; with
        ``substrate`` also ``up`` (B, N, C), the same at the weighted nodes, and ``down``
        (B, N, C), the diffuse downward radiance at the bottom (else None). Columns C: the
        beams, then the substrate problem.
    """
    a = np.atleast_1d(np.asarray(a, dtype=float))
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    if (a < SMALL_ABSORPTION).any():
        raise ValueError(f"a must be >= SMALL_ABSORPTION = {SMALL_ABSORPTION} here (use doubling below)")
    opaque = np.isinf(tau)
    if opaque.any() and not opaque.all():
        raise ValueError("tau must be all finite or all infinite in one batch")
    opaque = bool(opaque.all())
    n = int(np.count_nonzero(weight))
    if (weight[:n] <= 0).any():
        raise ValueError("zero-weight nodes must follow the quadrature nodes (as binder_quadrature puts them)")
    mu_q, w_q = mu[:n], weight[:n]
    distinct, which = np.unique(a, return_inverse=True)
    omega = 1.0 - distinct
    U, W, k = _eigen_solutions(mu_q, w_q, distinct, p_reflection[:n, :n], p_transmission[:n, :n])
    U_inv = np.linalg.inv(U)
    P = U_inv @ W
    r = r_top[:, None]
    U_r, W_r = U - r * W, W - r * U  # top condition: I+(0) - r I-(0)
    u = mu[beams]
    z_down, z_up = _beam_particular_solutions(mu_q, w_q, omega, u, p_reflection[:n, beams],
                                              p_transmission[:n, beams], p_reflection[:n, :n],
                                              p_transmission[:n, :n])
    z_down, z_up = np.swapaxes(z_down, 1, 2), np.swapaxes(z_up, 1, 2)  # (G, N, L)
    f = -(z_down - r * z_up)
    g = -z_up
    if substrate:
        f = np.concatenate([f, np.zeros((distinct.size, n, 1))], axis=-1)
        g = np.concatenate([g, np.ones((distinct.size, n, 1))], axis=-1)
    n_beams = u.size
    # source function along the viewing directions, per distinct a
    half = 0.5 * omega[:, None, None]
    p_r_vq = p_reflection[views, :n] * w_q
    p_t_vq = p_transmission[views, :n] * w_q
    up_decaying = half * (p_r_vq @ U + p_t_vq @ W)  # (G, L_views, N)
    down_decaying = half * (p_t_vq @ U + p_r_vq @ W)
    up_particular = half * (p_r_vq @ z_down + p_t_vq @ z_up + p_reflection[np.ix_(views, beams)] / u)
    inv_mu = (1.0 / mu[views])[None, :, None]
    rate_beam = (1.0 / u)[None, None, :]
    if opaque:
        alpha = np.linalg.solve(U_r, f)  # one solve per distinct a serves every row
        up = (W @ alpha + np.concatenate([z_up, np.zeros_like(g[..., n_beams:])], axis=-1))[which]
        up_view = _up_at_exact_directions(up_decaying, None, alpha, None, k[:, None, :], None, inv_mu, True)
        up_view[..., :n_beams] += inv_mu * up_particular / (rate_beam + inv_mu)
        down = np.zeros_like(up)
        if substrate:  # nothing reaches the bottom; what it would send up comes back as R c 1
            down[..., -1] = (W @ U_inv.sum(axis=-1)[..., None])[which, :, 0]
        return {"up": up, "up_view": up_view[which], "down": down}
    n_views, n_columns = inv_mu.size, g.shape[-1]
    out = {"up_view": np.empty((tau.size, n_views, n_columns))}
    if substrate:
        out["up"] = np.empty((tau.size, n, n_columns))
        out["down"] = np.empty((tau.size, n, n_columns))
    # per row, in blocks small enough for the core's cache (a block's (B, N, N) arrays, ~0.25 MB
    # each at N = 32, run 2-3 times faster than the same work on 256 rows at once)
    for start in range(0, tau.size, ROW_BLOCK):
        rows = slice(start, start + ROW_BLOCK)
        block = _rows_under_surface(which[rows], tau[rows], k, U, W, U_inv, P, U_r, W_r, f, g, z_down, z_up, u,
                                    up_decaying, down_decaying, up_particular, 1.0 / mu[views], substrate)
        for key, value in block.items():
            out[key][rows] = value
    return {"up": out.get("up"), "up_view": out["up_view"], "down": out.get("down")}


def _rows_under_surface(which, tau, k, U, W, U_inv, P, U_r, W_r, f, g, z_down, z_up, u, up_decaying, down_decaying,
                        up_particular, inv_mu_view, substrate):
    """The per-layer part of :func:`radiances_under_surface` for finite layers ``tau`` (B,), whose
    distinct-``a`` quantities are picked by ``which``: the N x N solve for ``alpha``, then
    ``beta`` and the radiances."""
    n_beams = u.size
    E = np.exp(-tau[:, None] * k[which])  # (B, N)
    # below ~1e-100 a factor is zero to any accuracy: flushing it keeps E P E and the products
    # that follow out of the subnormal range, where arithmetic is ~100 times slower
    E[E < NEGLIGIBLE_ATTENUATION] = 0.0
    beam = np.exp(-tau[:, None] / u)  # (B, L): the beams' attenuation scales g (and Z+ at the bottom)
    scale = np.concatenate([beam, np.ones((tau.size, g.shape[-1] - n_beams))], axis=-1)[:, None, :]
    U_inv_g = U_inv[which] @ (g[which] * scale)
    P_b = P[which]
    EPE = P_b * E[:, :, None]
    EPE *= E[:, None, :]
    W_r_b = W_r[which]
    system = W_r_b @ EPE
    np.subtract(U_r[which], system, out=system)
    rhs = f[which]
    rhs -= W_r_b @ (E[:, :, None] * U_inv_g)
    alpha = np.linalg.solve(system, rhs)
    beta = U_inv_g - P_b @ (E[:, :, None] * alpha)
    # formal integration along the viewing directions, from the attenuations already at hand
    e_view = np.exp(-tau[:, None] * inv_mu_view)  # (B, L_views)
    k_b = k[which][:, None, :]
    inv_mu = inv_mu_view[None, :, None]
    decaying = (1.0 - E[:, None, :] * e_view[:, :, None]) / (k_b + inv_mu)
    growing = _growing_integral(e_view[:, :, None], E[:, None, :], k_b - inv_mu, tau[:, None, None])
    up_view = inv_mu * ((up_decaying[which] * decaying) @ alpha + (down_decaying[which] * growing) @ beta)
    up_view[..., :n_beams] += (inv_mu * up_particular[which] * (1.0 - e_view[:, :, None] * beam[:, None, :])
                               / (inv_mu + 1.0 / u))
    if not substrate:
        return {"up_view": up_view}
    up_view[..., n_beams:] += e_view[:, :, None]  # the bottom seen through the layer
    Ub, Wb = U[which], W[which]
    zeros = np.zeros((tau.size, E.shape[1], g.shape[-1] - n_beams))
    up = np.concatenate([z_up[which], zeros], axis=-1) + Wb @ alpha + Ub @ (E[:, :, None] * beta)
    down = np.concatenate([z_down[which] * beam[:, None, :], zeros], axis=-1) + Ub @ (E[:, :, None] * alpha) + Wb @ beta
    return {"up_view": up_view, "up": up, "down": down}
