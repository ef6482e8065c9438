"""The discrete-ordinate solution of a homogeneous layer (the forward model's layer solver).

The kernels of :mod:`bayespig.physics.adding_doubling` solve, on the same quadrature, the
discrete radiative transfer equation of one azimuthal mode

    mu_i dI+_i/dtau = -I+_i + (omega / 2) sum_j w_j (pT_ij I+_j + pR_ij I-_j)
   -mu_i dI-_i/dtau = -I-_i + (omega / 2) sum_j w_j (pR_ij I+_j + pT_ij I-_j)

(``I+`` downward, ``I-`` upward; the kernel convention of the doubling module, whose thin-layer
limit is the single-scattering kernel). With ``A = M^-1 (omega/2 pT W - 1)`` and
``B = M^-1 (omega/2 pR W)`` the sum ``Z = I+ + I-`` obeys ``Z'' = (A - B)(A + B) Z``; its
eigenvectors ``V`` and eigenvalues ``k^2`` give the decaying solutions ``(U, W) e^{-k tau}``
with ``U = (V + Y) / 2``, ``W = (V - Y) / 2``, ``Y = -(A - B)^-1 V k``, and by symmetry the
growing ones ``(W, U) e^{-k (tau0 - tau)}`` (Stamnes & Swanson 1981). One eigen decomposition
per (``a``, mode) serves every thickness.

Two uses:

- :func:`layer_mode_eigen`: the layer's reflection and transmission kernels on the quadrature,
  ``R = (W - U E P E) (U - W E P E)^-1``, ``T = (U - W P) E (U - W E P E)^-1`` with
  ``E = diag e^{-k tau0}``, ``P = U^-1 W``, and ``R = W U^-1`` when opaque (Flatau & Stephens
  1988); a cross-check of doubling (``benchmarks/layer_solvers.py``).
- :func:`radiances_under_surface`: what the forward model needs of one mode, the radiance under
  the air/binder surface along the exact measurement directions, solved directly as a
  boundary-value problem with the surface's internal reflection as the top boundary
  (DISORT's method, Stamnes et al. 1988): a collimated beam along an exact incidence direction
  enters through the particular solution ``Z e^{-tau/u}``, and the radiance along an exact
  viewing direction follows from integrating the source function along it. No kernel matrix
  is formed; each layer costs one N x N solve per mode.

The conservative limit ``a -> 0`` makes the smallest ``k`` vanish (the diffusion mode). A
semi-infinite layer needs only the decaying solutions, and the reduction of
:func:`_eigen_solutions` stays regular at ``k = 0``, so opaque layers take this form for every
``a``, ``a = 0`` included (where doubling's spurious absorption, ~1e-10 per unit ``tau``, costs
~1e-5 to 1e-4 of the reflectance). In a finite layer the decaying and growing diffusion solutions
merge as ``k -> 0`` (the missing one is linear in ``tau``), and in very thin layers the O(1)
terms cancel to an O(tau) result: such finite layers (``a <`` :data:`SMALL_ABSORPTION`,
``tau <`` :data:`THIN_LAYER`) go through doubling.

References
----------
Stamnes & Swanson (1981), J. Atmos. Sci. 38, 387 (the reduced eigenproblem);
Stamnes, Tsay, Wiscombe & Jayaweera (1988), Appl. Opt. 27, 2502 (DISORT: beam particular
solution, intensities at arbitrary angles);
Flatau & Stephens (1988), J. Geophys. Res. 93, 11037 (layer reflection and transmission).
"""

from __future__ import annotations

import numpy as np

from .adding_doubling import START_THICKNESS, layer_mode

__all__ = ["SMALL_ABSORPTION", "THIN_LAYER", "layer_mode_eigen", "radiances_under_surface"]

#: Below this relative absorption the diffusion mode's ``k ~ sqrt(3 a)`` nears 0 and the eigen
#: form of a finite layer loses accuracy; such finite layers go through doubling.
SMALL_ABSORPTION = 1e-4
#: Below this optical thickness the eigen form's O(1) terms cancel to a reflection of O(tau),
#: losing ~1e-16 / tau of it: such layers go through doubling, whose single-scattering start
#: is exact there (tests/physics/test_discrete_ordinates.py, thin layers to 2e-6 of themselves).
THIN_LAYER = 1e-6
#: Attenuation factors ``e^{-k tau}`` below this are set to zero (their products would be
#: subnormal numbers, slow to compute with, and they are far below any accuracy that matters).
NEGLIGIBLE_ATTENUATION = 1e-100
#: A beam whose rate ``1/u`` lies within this relative distance of an eigenvalue ``k`` is near
#: the resonance of its particular solution (error ~3e-14 / distance).
RESONANCE_GAP = 1e-3
#: Relative steps of the beam's attenuation rate around a resonance: the radiances, smooth in
#: the rate, are extrapolated from rates ``(1 +- STEP) / u`` and ``(1 +- 2 STEP) / u``.
RESONANCE_STEP = 4e-3
#: Richardson weights of those four rates (error O(STEP^4)).
RESONANCE_WEIGHTS = np.array([2.0 / 3.0, 2.0 / 3.0, -1.0 / 6.0, -1.0 / 6.0])
RESONANCE_FACTORS = 1.0 + RESONANCE_STEP * np.array([1.0, -1.0, 2.0, -2.0])
#: A mode whose ``|C+ S 1|`` is below this (relative to ``|C+|``) conserves energy: its smallest
#: ``k`` is 0 (:func:`_eigen_solutions`). Measured <= 2e-15 for ``omega = 1`` in mode 0 (|g| <=
#: 0.95, n 1-1.6, Rayleigh), ~0.2 ``a`` for ``omega = 1 - a`` and >= 0.01 in modes m >= 1; so
#: only ``a`` below ~5e-14 counts as conservative.
CONSERVATIVE_RESIDUAL = 1e-14


def _eigen_solutions(mu, weight, a, p_reflection, p_transmission):
    """``U``, ``W`` (G, N, N) and ``k`` (G, N) of the decaying solutions for every ``a`` (G,).

    The symmetric reduction (Stamnes & Swanson 1981) of ``D = I+ - I-``, which obeys
    ``D'' = (A + B)(A - B) D``: with ``S = w^(1/2)`` and the symmetric
    ``C+- = S (omega/2) (pT +- pR) S - 1``, ``A +- B = M^-1 S^-1 C+- S``, so with
    ``-C- = L L^T`` (Cholesky) ``(A + B)(A - B)`` is similar to ``G = L^T M^-1 (-C+) M^-1 L``: a
    symmetric positive semi-definite matrix, whose eigenvectors ``X`` (``eigh``) stay accurate
    where those of the unsymmetric product do not (high azimuthal modes, grazing nodes).
    ``-C-`` is positive definite for every albedo (its smallest eigenvalue is ~``1 - omega g``),
    while ``-C+`` is singular in the conservative mode 0 (its null vector ``S 1`` is the
    constant radiance, the diffusion mode ``k = 0``). So the reduction holds down to ``a = 0``:
    with ``y = S^-1 L^-T X`` (``(A + B)(A - B) y = k^2 y``) the solutions are
    ``Z = I+ + I- = -(A - B) y`` and ``D = k y``, without any division by ``k``.

    In the conservative mode 0 (``omega = 1``; the phase function normalised on the quadrature,
    :func:`~bayespig.physics.phase.normalise_on_quadrature`) the smallest ``k`` is exactly 0;
    ``eigh`` returns ``k^2`` with an absolute error ~1e-16 of ``|G|`` (up to 2e-14, a ``k`` of
    1.4e-7, which would absorb ~5e-6 of the light of an opaque layer), so it is set to 0.
    """
    n = mu.size
    omega = (1.0 - a)[:, None, None]
    root_w = np.sqrt(weight)
    eye = np.eye(n)
    c_plus = 0.5 * omega * (root_w[:, None] * (p_transmission + p_reflection) * root_w) - eye
    c_minus = 0.5 * omega * (root_w[:, None] * (p_transmission - p_reflection) * root_w) - eye
    chol = np.linalg.cholesky(-c_minus)  # L, lower
    inv_mu = 1.0 / mu
    g_matrix = np.swapaxes(chol, 1, 2) @ ((inv_mu[:, None] * -c_plus * inv_mu) @ chol)
    k2, X = np.linalg.eigh(g_matrix)  # ascending
    k = np.sqrt(np.maximum(k2, 0.0))
    # the conservative mode 0: C+ S 1 = 0 to rounding
    null_residual = np.abs(c_plus @ root_w).max(axis=-1) / np.abs(c_plus).max(axis=(1, 2))
    k[null_residual < CONSERVATIVE_RESIDUAL, 0] = 0.0
    d = np.linalg.solve(np.swapaxes(chol, 1, 2), X)  # L^-T X = S y
    V = -(inv_mu[:, None] * (c_minus @ d)) / root_w[:, None]  # -(A - B) y
    Y = d * k[:, None, :] / root_w[:, None]  # k y
    return 0.5 * (V + Y), 0.5 * (V - Y), k


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


def layer_mode_eigen(mu, weight, a, tau, p_reflection, p_transmission, start_thickness=START_THICKNESS):
    """Kernels of a homogeneous layer for one azimuthal mode, from the eigen solution.

    Same parameters and returns as :func:`bayespig.physics.adding_doubling.layer_mode` (which it
    calls for finite layers with ``a <`` :data:`SMALL_ABSORPTION`); one eigen decomposition per
    distinct ``a``.

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
    # the opaque limit needs no growing solutions, so the eigen form holds down to a = 0 there
    small = (a < SMALL_ABSORPTION) & ~opaque
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


def _beam_particular_solutions(mu, weight, omega, cosines, rates, p_r_beam, p_t_beam, p_reflection,
                               p_transmission):
    """Particular solutions ``Z e^{-r tau}`` of the quadrature equations for collimated beams.

    A beam of unit ``c I`` (the kernels' normalisation) travelling down along ``u`` scatters
    into the quadrature with the source ``(omega/2) p(mu_i, u) e^{-r tau} / u`` (``r = 1/u``; other
    rates serve the extrapolation across a resonance); the diffuse field it drives,
    ``I+- = Z+- e^{-r tau}``, solves (``M = diag mu``, ``W = diag w``)

        [(omega/2) pT W - 1 + r M] Z+ + (omega/2) pR W Z-            = -(omega/2) pT(., u) / u
        (omega/2) pR W Z+            + [(omega/2) pT W - 1 - r M] Z- = -(omega/2) pR(., u) / u

    (Stamnes et al. 1988, eq. 15, in this module's notation), singular where ``r`` equals an
    eigenvalue ``k``.

    Parameters
    ----------
    mu, weight : numpy.ndarray
        Quadrature nodes and positive weights, shape (N,) [-].
    omega : numpy.ndarray
        Single-scattering albedos, shape (G,) [-].
    cosines : numpy.ndarray
        Beam direction cosines in the binder, shape (L,) [-].
    rates : numpy.ndarray
        Attenuation rate of each beam for each albedo, shape (G, L) [-].
    p_r_beam, p_t_beam : numpy.ndarray
        Phase-function mode from each beam into the quadrature nodes, opposite and same
        hemisphere, shape (N, L) [-].
    p_reflection, p_transmission : numpy.ndarray
        The mode between quadrature nodes, shape (N, N) [-].

    Returns
    -------
    z_down, z_up : numpy.ndarray
        ``Z+`` and ``Z-``, shape (G, N, L) [-].
    """
    n = mu.size
    half = 0.5 * omega[:, None, None, None]
    shift = np.eye(n) * (rates[:, :, None, None] * mu)  # (G, L, N, N): r M
    same = half * (p_transmission * weight) - np.eye(n)
    cross = np.broadcast_to(half * (p_reflection * weight), shift.shape)
    system = np.block([[same + shift, cross], [cross, same - shift]])  # (G, L, 2N, 2N)
    source = np.concatenate([p_t_beam, p_r_beam], axis=0).T / cosines[:, None]  # (L, 2N)
    solution = np.linalg.solve(system, -0.5 * omega[:, None, None, None] * source[None, :, :, None])[..., 0]
    return np.swapaxes(solution[..., :n], 1, 2), np.swapaxes(solution[..., n:], 1, 2)


def _beam_columns(k, cosines):
    """Attenuation rates of the beam columns and the weights that make them the beams.

    Away from resonance a beam is one column at its own rate ``1/u``; a beam within
    :data:`RESONANCE_GAP` of an eigenvalue, for any albedo of the batch, gets four columns at
    the rates ``RESONANCE_FACTORS / u`` for the albedos near resonance (its own rate, weight 1,
    for the others), combined with :data:`RESONANCE_WEIGHTS`.

    Returns
    -------
    beam_of_column : numpy.ndarray
        Beam index of each column, (C,).
    rates : numpy.ndarray
        Rate of each column for each albedo, (G, C) [-].
    weights : numpy.ndarray
        Weight of each column in its beam for each albedo, (G, C) [-].
    """
    rate = 1.0 / cosines
    gap = np.min(np.abs(k[:, :, None] / rate - 1.0), axis=1)  # (G, L)
    near = gap < RESONANCE_GAP
    beam_of_column, rates, weights = [], [], []
    for b in range(cosines.size):
        if not near[:, b].any():
            beam_of_column.append(b)
            rates.append(np.full(k.shape[0], rate[b]))
            weights.append(np.ones(k.shape[0]))
            continue
        for factor, weight in zip(RESONANCE_FACTORS, RESONANCE_WEIGHTS):
            beam_of_column.append(b)
            rates.append(np.where(near[:, b], factor * rate[b], rate[b]))
            weights.append(np.where(near[:, b], weight, float(factor == RESONANCE_FACTORS[0])))
    return np.array(beam_of_column), np.stack(rates, axis=1), np.stack(weights, axis=1)


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
    ``g = 1``). This replaces forming the layer kernels and adding the surface to them. A beam
    near the resonance of its particular solution is extrapolated across it
    (:func:`_beam_columns`).

    Parameters
    ----------
    mu, weight : numpy.ndarray
        Quadrature nodes and weights, (N_all,), the zero-weight exact directions last [-].
    a, tau : numpy.ndarray
        Relative absorption and optical thickness, (B,) [-]; ``tau`` all finite (then ``a`` in
        [SMALL_ABSORPTION, 1]) or all ``inf`` (then ``a`` in [0, 1]).
    p_reflection, p_transmission : numpy.ndarray
        This mode of the phase function, (N_all, N_all) [-].
    r_top : numpy.ndarray
        Reflectance of the top boundary for upward radiance, at the weighted nodes (N,) [-].
    beams, views : numpy.ndarray
        Indices (into ``mu``) of the exact incidence and viewing directions.
    substrate : bool
        Also solve the problem of the Lambertian bottom (mode 0), and return the radiances at
        the weighted nodes.

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
    opaque = np.isinf(tau)
    if opaque.any() and not opaque.all():
        raise ValueError("tau must be all finite or all infinite in one batch")
    opaque = bool(opaque.all())
    if not opaque and (a < SMALL_ABSORPTION).any():
        raise ValueError(f"a must be >= SMALL_ABSORPTION = {SMALL_ABSORPTION} for a finite layer here "
                         "(use doubling below)")
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
    beam_of_column, rates, weights = _beam_columns(k, mu[beams])
    columns = np.asarray(beams)[beam_of_column]
    u = mu[columns]
    z_down, z_up = _beam_particular_solutions(mu_q, w_q, omega, u, rates, p_reflection[:n, columns],
                                              p_transmission[:n, columns], p_reflection[:n, :n],
                                              p_transmission[:n, :n])  # (G, N, C)
    f = -(z_down - r * z_up)
    g = -z_up
    if substrate:
        f = np.concatenate([f, np.zeros((distinct.size, n, 1))], axis=-1)
        g = np.concatenate([g, np.ones((distinct.size, n, 1))], axis=-1)
    # source function along the viewing directions, per distinct a
    half = 0.5 * omega[:, None, None]
    p_r_vq = p_reflection[views, :n] * w_q
    p_t_vq = p_transmission[views, :n] * w_q
    per_a = {
        "k": k, "U": U, "W": W, "U_inv": U_inv, "P": P, "U_r": U_r, "W_r": W_r, "f": f, "g": g,
        "z_down": z_down, "z_up": z_up, "rates": rates,
        "up_decaying": half * (p_r_vq @ U + p_t_vq @ W),  # (G, L_views, N); growing: (W, U) swap
        "down_decaying": half * (p_t_vq @ U + p_r_vq @ W),
        "up_particular": half * (p_r_vq @ z_down + p_t_vq @ z_up + p_reflection[np.ix_(views, columns)] / u),
    }
    inv_mu = 1.0 / mu[views]
    if opaque:
        out = _opaque_under_surface(per_a, inv_mu, substrate)
        out = {key: value[which] for key, value in out.items()}
    else:
        out = _rows_under_surface(which, tau, per_a, inv_mu, substrate)
    # the beam columns combined into the beams (with the substrate column passed through)
    n_beams = len(beams)
    combine = np.zeros((distinct.size, g.shape[-1], n_beams + g.shape[-1] - columns.size))
    combine[:, np.arange(columns.size), beam_of_column] = weights
    combine[:, columns.size:, n_beams:] = np.eye(g.shape[-1] - columns.size)
    combine = combine[which]
    return {key: None if out.get(key) is None else out[key] @ combine for key in ("up", "up_view", "down")}


def _opaque_under_surface(per_a, inv_mu, substrate):
    """:func:`radiances_under_surface` for semi-infinite layers, per distinct ``a``: one solve each."""
    k, W, U_inv, f, z_up = (per_a[name] for name in ("k", "W", "U_inv", "f", "z_up"))
    alpha = np.linalg.solve(per_a["U_r"], f)
    n_beams = z_up.shape[-1]
    inv_mu = inv_mu[None, :, None]
    up_view = inv_mu * (per_a["up_decaying"] / (k[:, None, :] + inv_mu)) @ alpha
    up_view[..., :n_beams] += inv_mu * per_a["up_particular"] / (per_a["rates"][:, None, :] + inv_mu)
    if not substrate:
        return {"up_view": up_view}
    up = W @ alpha
    up[..., :n_beams] += z_up
    down = np.zeros_like(up)
    # nothing reaches the bottom; what it would send up comes back as R c 1
    down[..., -1] = (W @ U_inv.sum(axis=-1)[..., None])[..., 0]
    return {"up_view": up_view, "up": up, "down": down}


def _rows_under_surface(which, tau, per_a, inv_mu_view, substrate):
    """The per-layer part of :func:`radiances_under_surface` for finite layers ``tau`` (B,), whose
    distinct-``a`` quantities ``per_a`` are picked by ``which``: the N x N solve for ``alpha``,
    then ``beta`` and the radiances."""
    k, U, W, P, f, g = (per_a[name] for name in ("k", "U", "W", "P", "f", "g"))
    rates = per_a["rates"][which]  # (B, C_beams)
    n_beams = rates.shape[1]
    E = np.exp(-tau[:, None] * k[which])  # (B, N)
    # below ~1e-100 a factor is zero to any accuracy: flushing it keeps E P E and the products
    # that follow out of the subnormal range, where arithmetic is ~100 times slower
    E[E < NEGLIGIBLE_ATTENUATION] = 0.0
    beam = np.exp(-tau[:, None] * rates)  # (B, C): the beams' attenuation scales g (and Z+ at the bottom)
    scale = np.concatenate([beam, np.ones((tau.size, g.shape[-1] - n_beams))], axis=-1)[:, None, :]
    U_inv_g = per_a["U_inv"][which] @ (g[which] * scale)
    P_b = P[which]
    EPE = P_b * E[:, :, None]
    EPE *= E[:, None, :]
    W_r_b = per_a["W_r"][which]
    system = W_r_b @ EPE
    np.subtract(per_a["U_r"][which], system, out=system)
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
    up_view = inv_mu * ((per_a["up_decaying"][which] * decaying) @ alpha
                        + (per_a["down_decaying"][which] * growing) @ beta)
    up_view[..., :n_beams] += (inv_mu * per_a["up_particular"][which]
                               * (1.0 - e_view[:, :, None] * beam[:, None, :]) / (inv_mu + rates[:, None, :]))
    if not substrate:
        return {"up_view": up_view}
    up_view[..., n_beams:] += e_view[:, :, None]  # the bottom seen through the layer
    Ub, Wb = U[which], W[which]
    zeros = np.zeros((tau.size, E.shape[1], g.shape[-1] - n_beams))
    up = np.concatenate([per_a["z_up"][which], zeros], axis=-1) + Wb @ alpha + Ub @ (E[:, :, None] * beta)
    down = (np.concatenate([per_a["z_down"][which] * beam[:, None, :], zeros], axis=-1)
            + Ub @ (E[:, :, None] * alpha) + Wb @ beta)
    return {"up_view": up_view, "up": up, "down": down}
