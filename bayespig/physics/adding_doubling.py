"""Adding–doubling for a plane-parallel scattering layer (one azimuthal mode at a time).

Notation
--------
Directions inside the binder are cosines ``mu`` on a quadrature (see
:mod:`bayespig.physics.quadrature`) with weights ``w``; ``c = mu * w``. For an
azimuthal Fourier mode ``m`` a *kernel* ``K[i, j] = 2 pi f_m(mu_i, mu_j)`` maps an
incident radiance mode ``L_in`` to the outgoing one, ``L_out = K @ (c * L_in)``,
where ``f_m`` is the m-th Fourier coefficient of the BRDF (or BTDF) in 1/sr,
``f = f_0 + 2 sum_m f_m cos(m psi)`` with ``psi`` the difference of propagation
azimuths. The unscattered beam (a delta function) is carried separately as the
vector ``direct = exp(-tau / mu)``; it never needs a ``1 / c`` so zero-weight
nodes (the measurement directions) stay exact.

A homogeneous layer reflects and transmits the same from either side, so a layer
is the triple ``(R, T, direct)``. Doubling (van de Hulst 1980; Prahl 1995) builds
thick layers from a thin starting layer of single scattering.

References
----------
van de Hulst, *Multiple Light Scattering* (1980), vol. 1, ch. 4.
Prahl, "The adding-doubling method", in *Optical-Thermal Response of
Laser-Irradiated Tissue* (1995).
"""

from __future__ import annotations

import numpy as np

from .fresnel import fresnel_reflectance
from .phase import n_fourier_modes, normalise_on_quadrature, phase_fourier_modes
from .quadrature import binder_quadrature, default_quadrature_points

__all__ = [
    "START_THICKNESS",
    "START_THICKNESS_HIGHER_MODES",
    "add_lambertian_substrate",
    "bare_layer_functions",
    "double",
    "layer_kernels",
    "layer_mode",
    "single_scattering_layer",
    "slab_totals",
    "start_layer",
]

#: Optical thickness of the starting layer. With the Richardson start the spurious
#: absorption it leaves is ~1e-10 per unit tau; thinner starts lose to round-off
#: (see reports/validation.md).
START_THICKNESS = 2.0**-22
#: Starting thickness for azimuthal modes m >= 1. They carry no energy, so the start
#: error there is only the O(d^3) local error and a much thicker start is as accurate.
START_THICKNESS_HIGHER_MODES = 2.0**-14
#: Doubling of an opaque layer stops once the total transmittance is below this.
OPAQUE_TRANSMITTANCE = 1e-11
#: Upper bound on doublings for the opaque limit (2^-22 * 2^80 is far beyond any film).
MAX_OPAQUE_DOUBLINGS = 80


def _phi(y):
    """``(1 - exp(-y)) / y`` for ``y >= 0``, stable at 0."""
    small = y < 1e-10
    safe = np.where(small, 1.0, y)
    return np.where(small, 1.0 - 0.5 * y, -np.expm1(-safe) / safe)


def single_scattering_layer(mu, albedo, thickness, p_reflection, p_transmission):
    """Kernels of a thin layer in the single-scattering approximation (error O(thickness^2)).

    Parameters
    ----------
    mu : numpy.ndarray
        Direction cosines, shape (N,) [-].
    albedo : numpy.ndarray
        Single-scattering albedo ``omega = 1 - a``, shape (B,) [-].
    thickness : numpy.ndarray
        Optical thickness of the thin layer, shape (B,) [-].
    p_reflection, p_transmission : numpy.ndarray
        Fourier mode of the phase function between opposite / equal hemispheres,
        shape (N, N) [-].

    Returns
    -------
    R, T : numpy.ndarray
        Reflection and diffuse transmission kernels, shape (B, N, N) [-].
    direct : numpy.ndarray
        ``exp(-thickness / mu)``, shape (B, N) [-].
    """
    w = albedo[:, None, None]
    d = thickness[:, None, None]
    mu_i = mu[:, None]
    mu_j = mu[None, :]
    reflection = w * 0.5 * p_reflection / (mu_i + mu_j) * -np.expm1(-d * (1.0 / mu_i + 1.0 / mu_j))
    gap = np.abs(1.0 / mu_i - 1.0 / mu_j)
    transmission = (
        w * 0.5 * p_transmission * np.exp(-d / np.maximum(mu_i, mu_j)) * d / (mu_i * mu_j) * _phi(d * gap)
    )
    direct = np.exp(-thickness[:, None] / mu[None, :])
    return reflection, transmission, direct


def start_layer(mu, c, albedo, thickness, p_reflection, p_transmission):
    """Kernels of the thin starting layer, accurate to third order in its thickness.

    Single scattering misses the light scattered twice, an error of order
    ``thickness^2`` that doubling would turn into a spurious absorption of order
    ``thickness`` (fatal for the opaque, weakly absorbing limit). Richardson
    extrapolation removes it: ``2 double(ss(d/2)) - ss(d)`` is exact to ``O(d^3)``.

    Parameters
    ----------
    mu, c : numpy.ndarray
        Nodes and weights times nodes, shape (N,) [-].
    albedo, thickness : numpy.ndarray
        Single-scattering albedo and optical thickness, shape (B,) [-].
    p_reflection, p_transmission : numpy.ndarray
        This azimuthal mode of the phase function, shape (N, N) [-].

    Returns
    -------
    R, T, direct : numpy.ndarray
        As :func:`single_scattering_layer`.
    """
    R1, T1, direct = single_scattering_layer(mu, albedo, thickness, p_reflection, p_transmission)
    R2, T2, _ = double(*single_scattering_layer(mu, albedo, thickness / 2.0, p_reflection, p_transmission), c)
    return 2.0 * R2 - R1, 2.0 * T2 - T1, direct


def double(R, T, direct, c):
    """Double a homogeneous layer: the kernels of two identical layers stacked.

    Parameters
    ----------
    R, T : numpy.ndarray
        Reflection and diffuse transmission kernels, shape (B, N, N) [-].
    direct : numpy.ndarray
        Unscattered transmission ``exp(-tau/mu)``, shape (B, N) [-].
    c : numpy.ndarray
        Quadrature weights times cosines, shape (N,) [-].

    Returns
    -------
    R, T, direct : numpy.ndarray
        The kernels of the doubled layer.
    """
    eye = np.eye(c.size)
    Rc = R * c
    RcR = Rc @ R
    # downward diffuse radiance between the layers; the unscattered beam enters via R c R e
    between = np.linalg.solve(eye - RcR * c, T + RcR * direct[:, None, :])
    up = R * direct[:, None, :] + Rc @ between
    Tc = T * c
    R_new = R + direct[:, :, None] * up + Tc @ up
    T_new = T * direct[:, None, :] + direct[:, :, None] * between + Tc @ between
    return R_new, T_new, direct * direct


def layer_mode(mu, weight, a, tau, p_reflection, p_transmission, start_thickness=START_THICKNESS):
    """Kernels of a homogeneous layer for one azimuthal mode.

    Parameters
    ----------
    mu, weight : numpy.ndarray
        Quadrature nodes and weights, shape (N,) [-].
    a : numpy.ndarray
        Relative absorption ``k_abs / k_ext``, shape (B,) [-].
    tau : numpy.ndarray
        Optical thickness, shape (B,) [-]; all finite or all ``inf`` (opaque).
    p_reflection, p_transmission : numpy.ndarray
        This mode of the phase function, shape (N, N) [-].
    start_thickness : float
        Largest optical thickness of the single-scattering starting layer [-].

    Returns
    -------
    R, T : numpy.ndarray
        Kernels, shape (B, N, N) [-] (``T`` is zero for an opaque layer).
    direct : numpy.ndarray
        ``exp(-tau/mu)``, shape (B, N) [-].
    """
    a = np.asarray(a, dtype=float)
    tau = np.asarray(tau, dtype=float)
    c = mu * weight
    opaque = np.isinf(tau)
    if opaque.any() and not opaque.all():
        raise ValueError("tau must be all finite or all infinite in one batch")
    if opaque.all():
        R, T, direct = start_layer(mu, c, 1.0 - a, np.full(a.size, start_thickness), p_reflection, p_transmission)
        # the opaque limit: double until nothing leaks through (tau ~ 2^k grows geometrically,
        # so even the conservative case a = 0, where T ~ 1/tau, needs few dozen doublings)
        for _ in range(MAX_OPAQUE_DOUBLINGS):
            R, T, direct = double(R, T, direct, c)
            if np.abs(T * c).sum(axis=-1).max() + direct.max() < OPAQUE_TRANSMITTANCE:
                break
        return R, np.zeros_like(T), np.zeros_like(direct)
    # each layer doubles from its own start in (start_thickness / 2, start_thickness], so its
    # kernels do not depend on the other layers of the batch
    n_doublings = np.ceil(np.log2(np.maximum(tau, 1e-300) / start_thickness)).clip(min=0).astype(int)
    R = np.empty((a.size, c.size, c.size))
    T = np.empty_like(R)
    direct = np.empty((a.size, c.size))
    for count in np.unique(n_doublings):
        rows = np.flatnonzero(n_doublings == count)
        layer = start_layer(mu, c, 1.0 - a[rows], tau[rows] / 2.0**count, p_reflection, p_transmission)
        for _ in range(count):
            layer = double(*layer, c)
        R[rows], T[rows], direct[rows] = layer
    return R, T, direct


def layer_kernels(mu, weight, a, tau, g, n_modes=None, start_thickness=START_THICKNESS):
    """Kernels of a homogeneous layer for the first ``n_modes`` azimuthal modes.

    Parameters are those of :func:`layer_mode`, with the phase-function parameter
    ``g`` (paper convention) instead of its modes, and ``n_modes`` (default: what
    :func:`~bayespig.physics.phase.n_fourier_modes` asks for ``g``).

    Returns
    -------
    R, T : numpy.ndarray
        Kernels, shape (B, M, N, N) [-].
    direct : numpy.ndarray
        ``exp(-tau/mu)``, shape (B, N) [-].
    """
    n_modes = n_fourier_modes(g) if n_modes is None else n_modes
    p_reflection = phase_fourier_modes(mu, mu, g, n_modes, reflection=True)
    p_transmission = phase_fourier_modes(mu, mu, g, n_modes, reflection=False)
    p_reflection, p_transmission = normalise_on_quadrature(p_reflection, p_transmission, weight)
    modes = [
        layer_mode(mu, weight, a, tau, p_reflection[m], p_transmission[m], start_thickness)
        for m in range(n_modes)
    ]
    R = np.stack([mode[0] for mode in modes], axis=1)
    T = np.stack([mode[1] for mode in modes], axis=1)
    return R, T, modes[0][2]


def add_lambertian_substrate(R, T, direct, c, r_s):
    """Reflection kernel (mode 0) of a layer lying on a Lambertian substrate.

    The substrate of albedo ``r_s`` (seen from the binder) has the kernel
    ``2 pi r_s / pi = 2 r_s`` for every pair of directions.

    Parameters
    ----------
    R, T : numpy.ndarray
        Mode-0 kernels of the layer, shape (B, N, N) [-].
    direct : numpy.ndarray
        Unscattered transmission of the layer, shape (B, N) [-].
    c : numpy.ndarray
        Weights times cosines, shape (N,) [-].
    r_s : numpy.ndarray
        Substrate albedo seen from the binder, shape (B,) [-].

    Returns
    -------
    numpy.ndarray
        Reflection kernel of layer plus substrate for light from above, (B, N, N).
    """
    N = c.size
    S = np.broadcast_to(2.0 * np.asarray(r_s, dtype=float)[:, None, None], (R.shape[0], N, N))
    Sc = S * c
    RcSc = (R * c) @ Sc
    between = np.linalg.solve(np.eye(N) - RcSc, T + (R * c) @ S * direct[:, None, :])
    up = S * direct[:, None, :] + Sc @ between
    return R + direct[:, :, None] * up + (T * c) @ up


def bare_layer_functions(mu_out, mu_in, *, a, tau, g=0.0, n_points=None):
    """Reflection and transmission functions of a bare layer (no interfaces, n = 1).

    These are van de Hulst's ``R(mu, mu0)`` and ``T(mu, mu0)``: ``pi`` times the
    azimuth-averaged BRDF and BTDF, the unscattered beam excluded.

    Parameters
    ----------
    mu_out, mu_in : array_like
        Cosines of the viewing and incidence directions, shapes (k,) and (j,) [-].
    a : float
        Relative absorption ``1 - omega`` [-].
    tau : float
        Optical thickness [-]; ``inf`` for a semi-infinite layer.
    g : float
        Phase-function parameter (paper convention).
    n_points : int, optional
        Gauss points of the quadrature (default: ``default_quadrature_points(g)``).

    Returns
    -------
    R, T : numpy.ndarray
        Shapes (k, j) [-].
    """
    mu_out = np.atleast_1d(np.asarray(mu_out, dtype=float))
    mu_in = np.atleast_1d(np.asarray(mu_in, dtype=float))
    n_points = default_quadrature_points(g) if n_points is None else n_points
    mu, weight = binder_quadrature(n_points, 1.0, np.concatenate([mu_out, mu_in]))
    R, T, _ = layer_kernels(mu, weight, np.array([a]), np.array([tau]), g, n_modes=1)
    n0 = mu.size - mu_out.size - mu_in.size
    rows = n0 + np.arange(mu_out.size)
    cols = n0 + mu_out.size + np.arange(mu_in.size)
    return R[0, 0][np.ix_(rows, cols)] / 2.0, T[0, 0][np.ix_(rows, cols)] / 2.0


def slab_totals(*, a, tau, g=0.0, n=1.0, n_points=None):
    """Total reflectance and transmittance of a slab in air with Fresnel faces.

    A test configuration (not a paint layer): both faces are smooth interfaces to
    air, as in the converged adding–doubling values of REFERENCE-VALUES.md §3.

    Parameters
    ----------
    a : float
        Relative absorption ``1 - omega`` [-].
    tau : float
        Optical thickness [-] (finite).
    g : float
        Phase-function parameter (paper convention).
    n : float
        Refractive index of the slab [-].
    n_points : int, optional
        Gauss points per quadrature interval (default: ``default_quadrature_points(g)``).

    Returns
    -------
    dict
        ``UR1``, ``UT1``: total reflectance and transmittance for normal collimated
        incidence (specular reflection and unscattered beam included); ``URU``,
        ``UTU``: the same for diffuse incidence [-].
    """
    n_points = default_quadrature_points(g) if n_points is None else n_points
    mu, weight = binder_quadrature(n_points, n, extra_nodes=[1.0])
    c = mu * weight
    N = mu.size
    v = N - 1
    R, T, direct = layer_kernels(mu, weight, np.array([a]), np.array([float(tau)]), g, n_modes=1)
    R, T, e = R[0, 0], T[0, 0], direct[0]
    r = fresnel_reflectance(mu, n, 1.0)
    t = 1.0 - r
    eye = np.eye(N)
    # diffuse coupling: [U_top; D_bottom] = sources + A [U_top; D_bottom]
    couple_same = (R * c) * r
    couple_through = ((T * c) + np.diag(e)) * r
    system = np.block([[eye - couple_same, -couple_through], [-couple_through, eye - couple_same]])

    def solve(source_up, source_down):
        fields = np.linalg.solve(system, np.concatenate([source_up, source_down]))
        return fields[:N], fields[N:]

    # collimated normal incidence: the unscattered beam bounces between the faces
    t0, r0, e0 = t[v], r[v], e[v]
    down_top = t0 / (1.0 - (r0 * e0) ** 2)  # collimated irradiance going down at the top
    up_bottom = r0 * e0 * down_top  # collimated irradiance going up at the bottom
    scale = 1.0 / (2.0 * np.pi)
    up, down = solve(
        (R[:, v] * down_top + T[:, v] * up_bottom) * scale,
        (T[:, v] * down_top + R[:, v] * up_bottom) * scale,
    )
    exitance = 2.0 * np.pi * c * t
    totals = {
        "UR1": 1.0 - t0 + t0 * e0 * up_bottom + exitance @ up,
        "UT1": t0 * e0 * down_top + exitance @ down,
    }
    # diffuse incidence, unit irradiance: radiance n^2 t / pi enters within the escape cone
    entering = n * n * t / np.pi
    up, down = solve((R * c) @ entering, (T * c) @ entering + e * entering)
    totals["URU"] = 1.0 - n * n * 2.0 * (c * t).sum() + exitance @ up
    totals["UTU"] = exitance @ down
    return totals
