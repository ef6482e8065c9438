"""The rough air/binder surface in the forward model (issue 16; DESIGN.md, "Rough top surface").

The layer under a rough surface is solved mode by mode on the binder quadrature of the smooth
model (:func:`~bayespig.physics.quadrature.binder_quadrature`), with the surface's microfacet
kernels (:mod:`bayespig.physics.microfacet`) at the top boundary instead of the smooth
surface's diagonal Fresnel factors. For a beam of unit irradiance along an air direction, the
upward radiance under the surface over a black substrate (kernel units ``2 pi L``, the
convention of :mod:`bayespig.physics.adding_doubling`) solves

    U = R (C t_in + C r_int C U),    so  (I - R C r_int C) U = R C t_in,

and the body's BRDF mode is ``t_out C U / (2 pi)`` (``R`` the layer's reflection kernel,
``C = diag(mu w)``, ``t_in``, ``r_int``, ``t_out`` the surface's transmission into the binder,
internal reflection (total internal reflection at the facets included) and transmission out).

Quadrature: product integration
-------------------------------
For a small roughness these kernels are narrow peaks around the refracted and mirror
directions: the solver's Gauss nodes cannot integrate them (``benchmarks/microfacet.py``: air ->
binder transmission off by 0.86 at alpha = 0.05 on 16 points per interval). But every peaked
kernel appears between smooth functions of the binder direction: the layer's ``R(mu', mu)``
and the radiance ``U(mu)``. Those are represented by their polynomial interpolants on the
Gauss nodes of each quadrature interval (in ``mu`` below the critical cosine, in ``s`` with
``mu = mu_c + (1 - mu_c) s^2`` above it, the variables of the binder quadrature), with Lagrange
basis ``l_j``, and the kernels are integrated against that basis on fine rules graded towards
their peaks (product integration; Atkinson, *The Numerical Solution of Integral Equations of
the Second Kind*, 1997, section 4.2):

- ``C t_in -> A_in[j, i] = int t_in(mu, mu_i) l_j(mu) mu dmu``,
- ``t_out C -> A_out[o, j] = int t_out(mu_o, mu) l_j(mu) mu dmu`` (``= A_in`` of the air
  direction ``o``, over ``n^2``: reciprocity of the transmission),
- ``C r_int C -> W[j, k] = int int l_j(mu) r_int(mu, mu') l_k(mu') mu mu' dmu dmu'``,
- the escape weights ``e_j = int T_out(mu) l_j(mu) mu dmu`` with ``T_out`` the surface's
  directional transmittance from the binder (:func:`~bayespig.physics.microfacet.directional_albedo`),
  for the hemispherical reflectance.

Energy is exact up to the fine rules (``sum_j l_j = 1``), the delta limit ``alpha -> 0`` is the
smooth model with the measurement directions interpolated instead of added as nodes, and the
accuracy no longer depends on ``alpha`` but on how well the interpolants represent ``R`` and
``U`` (measured in ``benchmarks/rough_surface.py``). The fine rules are composite
Gauss-Legendre panels in the polar angle ``theta`` (the peaks are smooth in ``theta``, not in
``mu`` near the normal), halving in width towards each peak down to :data:`FINEST_PANEL` ``*
alpha``, and split where an integrand is not smooth: the critical angle (where the basis
changes interval and the facets start to reflect totally) and where a refracted or reflected
ray grazes its facet at ``psi = 0`` or ``pi``.

The weights depend on ``alpha``, ``n``, the quadrature and (for ``A_in``, ``A_out``) the air
directions only, not on the layer: :func:`rough_interface` caches them.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.interpolate import BarycentricInterpolator

from .adding_doubling import START_THICKNESS, START_THICKNESS_HIGHER_MODES, layer_mode
from .discrete_ordinates import THIN_LAYER, layer_mode_eigen
from .fresnel import critical_cosine
from .microfacet import (
    _smoothstep_panels,
    directional_albedo,
    reflection_modes,
    transmission_modes,
)
from .phase import n_fourier_modes, normalise_on_quadrature, phase_fourier_modes
from .quadrature import binder_quadrature

__all__ = ["FINEST_PANEL", "MODE_BLOCK", "PANEL_POINTS", "RoughInterface", "rough_interface",
           "rough_surface_terms"]

#: Finest panel of the fine rules, as a fraction of ``alpha`` [rad of theta]. The narrowest
#: peak is the transmission's: ``theta_t`` spreads by ~``alpha (n - 1) / n`` (~0.3 alpha) around
#: the refracted direction.
FINEST_PANEL = 1.0 / 16.0
#: Gauss points per panel of the fine rules.
PANEL_POINTS = 8
#: Azimuthal modes of the surface kernels computed together (the forward model stops at the
#: layer's last significant mode).
MODE_BLOCK = 8
#: Cached sets of interface weights (one per roughness, index, quadrature and distribution).
CACHE_SIZE = 8
_HALF_PI = 0.5 * np.pi


def _graded_rule(peaks, breaks, finest):
    """Nodes and weights in ``theta`` over (0, pi/2) for ``int h(theta) dtheta``: panels split at
    ``breaks`` and halving in width towards each of ``peaks`` (and the breaks) down to
    ``finest``; each panel Gauss-Legendre in the smoothstep variable (square-root ends smooth)."""
    edges = [0.0, _HALF_PI]
    inside = [x for x in list(peaks) + list(breaks) if 0.0 <= x <= _HALF_PI]
    edges.extend(inside)
    for centre in inside:
        width = finest
        while width < _HALF_PI:
            edges.extend((centre - width, centre + width))
            width *= 2.0
    edges = np.unique(np.clip(edges, 0.0, _HALF_PI))
    theta, weight = _smoothstep_panels(edges, PANEL_POINTS)
    keep = weight > 0.0
    return theta[keep], weight[keep]


class _LagrangeBasis:
    """Lagrange basis of the binder quadrature's intervals at arbitrary cosines."""

    def __init__(self, n_points, n):
        self.n_points = n_points
        self.mu_c = critical_cosine(n)
        x, _ = np.polynomial.legendre.leggauss(n_points)
        unit = 0.5 * (x + 1.0)
        self.lower = BarycentricInterpolator(self.mu_c * unit, np.eye(n_points))
        self.upper = BarycentricInterpolator(unit, np.eye(n_points))

    def __call__(self, mu):
        """``l_j(mu)``, shape (F, 2 n_points), for cosines ``mu`` (F,)."""
        mu = np.asarray(mu, dtype=float)
        p = self.n_points
        out = np.zeros((mu.size, 2 * p))
        low = mu < self.mu_c
        if low.any():
            out[low, :p] = self.lower(mu[low])
        if (~low).any():
            s = np.sqrt(np.clip((mu[~low] - self.mu_c) / (1.0 - self.mu_c), 0.0, None))
            out[~low, p:] = self.upper(s)
        return out


class RoughInterface:
    """Product-integration weights of the rough air/binder surface on one binder quadrature.

    Parameters
    ----------
    alpha : float
        GGX (or Beckmann) roughness [-], > 0.
    n : float
        Binder refractive index [-], > 1.
    n_points : int
        Gauss points per interval of :func:`~bayespig.physics.quadrature.binder_quadrature`.
    distribution : {"ggx", "beckmann"}

    Attributes
    ----------
    mu, weight : numpy.ndarray
        The binder quadrature, (q,) [-].
    escape : numpy.ndarray
        ``e_j = int T_out(mu) l_j(mu) mu dmu``, (q,) [-]: upward energy leaving into air.
    """

    def __init__(self, alpha, n, n_points, distribution="ggx"):
        self.alpha, self.n, self.n_points, self.distribution = float(alpha), float(n), int(n_points), distribution
        self.mu, self.weight = binder_quadrature(self.n_points, self.n)
        self.c = self.mu * self.weight
        self.basis = _LagrangeBasis(self.n_points, self.n)
        self.theta_c = float(np.arccos(critical_cosine(self.n)))
        # rays refracted through a facet graze it where i.o = -1/n (microfacet.transmission_modes)
        self.theta_graze = float(np.arccos(1.0 / self.n))
        self.finest = FINEST_PANEL * self.alpha
        theta, w = _graded_rule([self.theta_c], [self.theta_c], self.finest)
        self.outer_mu = np.cos(theta)
        self.outer_weight = w * np.sin(theta) * self.outer_mu  # for int h(mu) mu dmu
        self.outer_basis = self.basis(self.outer_mu)
        _, t_out = directional_albedo(self.outer_mu, alpha=self.alpha, n_i=self.n, n_t=1.0,
                                      distribution=distribution)
        self.escape = (self.outer_weight * t_out) @ self.outer_basis
        self._internal = {}
        self._entering = {}

    @property
    def options(self):
        return {"alpha": self.alpha, "distribution": self.distribution}

    def internal(self, block):
        """``W[j, k]`` of the modes ``MODE_BLOCK * block ..`` (MODE_BLOCK, q, q) [-]."""
        if block not in self._internal:
            first = MODE_BLOCK * block
            q = self.mu.size
            rows = np.empty((MODE_BLOCK, self.outer_mu.size, q))
            tc, tg = self.theta_c, 2.0 * self.theta_c
            for f, mu_f in enumerate(self.outer_mu):
                theta = float(np.arccos(mu_f))
                # kinks: facets at the critical angle at psi = 0 (theta + theta' = 2 theta_c) and pi
                theta_in, w_in = _graded_rule([theta, tc], [tc, tg - theta, theta - tg, theta + tg], self.finest)
                mu_in = np.cos(theta_in)
                kernel = reflection_modes(mu_in, [mu_f], MODE_BLOCK, n_i=self.n, n_t=1.0, first_mode=first,
                                          **self.options)[:, :, 0]
                rows[:, f] = (kernel * (w_in * np.sin(theta_in) * mu_in)) @ self.basis(mu_in)
            W = np.einsum("f,fj,mfk->mjk", self.outer_weight, self.outer_basis, rows)
            self._internal[block] = 0.5 * (W + np.swapaxes(W, 1, 2))  # reciprocal; symmetric to round-off
        return self._internal[block]

    def entering(self, mu_air, block):
        """``A_in[j, i]`` for air cosines ``mu_air`` (k,), modes of ``block``: (MODE_BLOCK, q, k) [-]."""
        out = np.empty((MODE_BLOCK, self.mu.size, len(mu_air)))
        for i, mu_i in enumerate(mu_air):
            key = (float(mu_i), block)
            if key not in self._entering:
                theta_i = float(np.arccos(min(mu_i, 1.0)))
                theta_t = float(np.arcsin(np.sin(theta_i) / self.n))
                tg = self.theta_graze
                theta, w = _graded_rule([theta_t, self.theta_c],
                                        [self.theta_c, theta_i - tg, tg - theta_i, theta_i + tg], self.finest)
                mu = np.cos(theta)
                kernel = transmission_modes(mu, [mu_i], MODE_BLOCK, n_i=1.0, n_t=self.n,
                                            first_mode=MODE_BLOCK * block, **self.options)[:, :, 0]
                self._entering[key] = (kernel * (w * np.sin(theta) * mu)) @ self.basis(mu)
            out[:, :, i] = self._entering[key]
        return out

    def leaving(self, mu_air, block):
        """``A_out[o, j]`` for air viewing cosines ``mu_air`` (k,): (MODE_BLOCK, k, q) [-]."""
        return np.swapaxes(self.entering(mu_air, block), 1, 2) / (self.n * self.n)


@functools.lru_cache(maxsize=CACHE_SIZE)
def rough_interface(alpha, n, n_points, distribution="ggx"):
    """The cached :class:`RoughInterface` of ``(alpha, n, n_points, distribution)``."""
    return RoughInterface(alpha, n, n_points, distribution)


def _layer(mu, weight, a, tau, p_reflection, p_transmission, thickness):
    """Layer kernels ``R, T, direct`` on the weighted quadrature: the eigen form, doubling for
    the thinnest finite layers (:data:`~bayespig.physics.discrete_ordinates.THIN_LAYER`)."""
    thin = np.isfinite(tau) & (tau < THIN_LAYER)
    if not thin.any():
        return layer_mode_eigen(mu, weight, a, tau, p_reflection, p_transmission, thickness)
    if thin.all():
        return layer_mode(mu, weight, a, tau, p_reflection, p_transmission, thickness)
    R = np.empty((a.size, mu.size, mu.size))
    T, direct = np.empty_like(R), np.empty((a.size, mu.size))
    for rows, solve in ((thin, layer_mode), (~thin, layer_mode_eigen)):
        R[rows], T[rows], direct[rows] = solve(mu, weight, a[rows], tau[rows], p_reflection, p_transmission,
                                               thickness)
    return R, T, direct


def _mode(interface, R, T, direct, A_in, A_out, W, first_mode):
    """BRDF mode of the body and (mode 0) the substrate-law terms, for one kind of layer."""
    q = interface.mu.size
    system = np.eye(q) - R @ W
    U = np.linalg.solve(system, R @ A_in)  # (B, q, k_in): 2 pi x upward radiance under the surface
    out = {"f_mode": (A_out @ U) / (2.0 * np.pi)}
    if not first_mode:
        return out
    c = interface.c
    reach = c @ T + direct  # (B, q): irradiance at the bottom per unit c L going down at the top
    out["t_down"] = np.einsum("bj,bjk->bk", reach, A_in + W @ U)
    # a Lambertian substrate of unit exitance: 2 pi L = 2 going up at the bottom
    Y = np.linalg.solve(system, (2.0 * (T @ c + direct))[..., None])[..., 0]
    out["t_up"] = (A_out @ Y[..., None])[..., 0] / (2.0 * np.pi)
    out["r_up"] = 2.0 * (R @ c) @ c + np.einsum("bj,bj->b", reach, (W @ Y[..., None])[..., 0])
    out["h0"] = np.einsum("j,bjk->bk", interface.escape, U)
    out["t_up_hemispherical"] = Y @ interface.escape
    return out


def rough_surface_terms(theta_in, theta_out, *, a, tau, g, n, n_points, alpha, n_modes=None,
                        mode_tolerance=1e-6, distribution="ggx", start_thickness=START_THICKNESS):
    """The substrate-law terms of a layer under a rough surface (body only: the first-surface
    lobe is not in them).

    Parameters
    ----------
    theta_in, theta_out : array_like
        Incidence and viewing angles in air [deg], (k_in,), (k_out,).
    a, tau : array_like
        Relative absorption and optical thickness, (B,) [-]; ``tau`` may mix finite and ``inf``.
    g : float
        Phase-function parameter.
    n : float
        Binder index, > 1 [-].
    n_points : int
        Gauss points per binder quadrature interval.
    alpha : float
        Roughness, > 0 [-].
    n_modes : int, optional
        Azimuthal modes; by default until every value's mode is below ``mode_tolerance`` of its
        mode 0 twice in a row (at most :func:`~bayespig.physics.phase.n_fourier_modes`).
    mode_tolerance : float
        That stopping rule's threshold (the smooth model's ``MODE_TOLERANCE``).
    distribution : {"ggx", "beckmann"}
    start_thickness : float
        Start of the doubling, for the layers that take it [-].

    Returns
    -------
    dict
        The fields of :class:`bayespig.physics.forward.SurfaceTerms`.
    """
    interface = rough_interface(float(alpha), float(n), int(n_points), distribution)
    mu_in = np.cos(np.radians(np.atleast_1d(np.asarray(theta_in, dtype=float))))
    mu_out = np.cos(np.radians(np.atleast_1d(np.asarray(theta_out, dtype=float))))
    a = np.atleast_1d(np.asarray(a, dtype=float))
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    adaptive = n_modes is None
    max_modes = n_fourier_modes(g) if n_modes is None else int(n_modes)
    mu, weight = interface.mu, interface.weight
    p_refl = phase_fourier_modes(mu, mu, g, max_modes, reflection=True)
    p_trans = phase_fourier_modes(mu, mu, g, max_modes, reflection=False)
    p_refl, p_trans = normalise_on_quadrature(p_refl, p_trans, weight)
    groups = [rows for rows in (np.flatnonzero(np.isfinite(tau)), np.flatnonzero(np.isinf(tau))) if rows.size]
    B, k_in, k_out = a.size, mu_in.size, mu_out.size
    terms = {"t_down": np.zeros((B, k_in)), "t_up": np.zeros((B, k_out)), "r_up": np.zeros(B),
             "h0": np.zeros((B, k_in)), "t_up_hemispherical": np.zeros(B)}
    f_modes = []
    n_used = np.full((B, k_out, k_in), max_modes)
    quiet = np.zeros((B, k_out, k_in), dtype=int)
    scale = None
    for m in range(max_modes):
        block, within = divmod(m, MODE_BLOCK)
        A_in = interface.entering(mu_in, block)[within]
        A_out = interface.leaving(mu_out, block)[within]
        W = interface.internal(block)[within]
        thickness = start_thickness if m == 0 else max(start_thickness, START_THICKNESS_HIGHER_MODES)
        f = np.zeros((B, k_out, k_in))
        active = np.ones(B, dtype=bool) if m == 0 else (n_used > m).any(axis=(1, 2))
        for rows in groups:
            rows = rows[active[rows]]
            if rows.size == 0:
                continue
            R, T, direct = _layer(mu, weight, a[rows], tau[rows], p_refl[m], p_trans[m], thickness)
            part = _mode(interface, R, T, direct, A_in, A_out, W, m == 0)
            f[rows] = part.pop("f_mode")
            for key, value in part.items():
                terms[key][rows] = value
        f_modes.append(f)
        if m == 0:
            scale = np.abs(f)
            continue
        if adaptive:
            small = np.abs(f) <= mode_tolerance * scale
            quiet = np.where(small, quiet + 1, 0)
            n_used = np.where((quiet == 2) & (n_used > m), m + 1, n_used)
            if (n_used <= m + 1).all():
                break
    f_modes = np.stack(f_modes, axis=1)
    f_modes[np.arange(f_modes.shape[1])[None, :, None, None] >= n_used[:, None]] = 0.0
    terms["r_up"][np.isinf(tau)] = 0.0
    terms["f0_modes"] = f_modes
    return terms
