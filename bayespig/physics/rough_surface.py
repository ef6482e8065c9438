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
basis ``l_j`` (times ``sin(theta) / sin(theta_j)`` in the odd azimuthal modes, whose ``R_m``
and ``U_m`` carry a factor ``sin^m(theta)``, not smooth in ``mu`` at the normal: without it
``alpha = 1e-4`` missed the smooth model by 1.7e-4 at g = 0.5), and the kernels are integrated
against that basis on fine rules graded towards their peaks (product integration; Atkinson, *The Numerical Solution of Integral Equations of
the Second Kind*, 1997, section 4.2):

- ``C t_in -> A_in[j, i] = int t_in(mu, mu_i) l_j(mu) mu dmu``,
- ``t_out C -> A_out[o, j] = int t_out(mu_o, mu) l_j(mu) mu dmu`` (``= A_in`` of the air
  direction ``o``, over ``n^2``: reciprocity of the transmission),
- ``C r_int C -> W[j, k] = int int l_j(mu) r_int(mu, mu') l_k(mu') mu mu' dmu dmu'``,
- the escape weights ``e_j = int T_out(mu) l_j(mu) mu dmu`` with ``T_out`` the surface's
  directional transmittance from the binder, for the hemispherical reflectance: by reciprocity
  ``e_j = int A_in[j](mu_o) mu_o dmu_o / n^2``, an integral of the entering weights over air
  directions (so the hemispherical reflectance is the integral of the BRDF, and independent of
  :func:`~bayespig.physics.microfacet.directional_albedo`, which the tests compare it with).

Energy is exact up to the fine rules (``sum_j l_j = 1``), the delta limit ``alpha -> 0`` is the
smooth model with the measurement directions interpolated instead of added as nodes, and the
accuracy no longer depends on ``alpha`` but on how well the interpolants represent ``R`` and
``U`` (measured in ``benchmarks/rough_surface.py``). The fine rules are composite
Gauss-Legendre panels in the polar angle ``theta`` (the peaks are smooth in ``theta``, not in
``mu`` near the normal), halving in width towards each peak down to :data:`FINEST_PANEL` ``*
min(alpha,`` :data:`FINEST_ALPHA_CAP` ``)``, and split where an integrand is not smooth (graded
there down to :data:`BREAK_FINEST_PANEL`): the critical angle (where the basis changes interval
and the facets start to reflect totally; graded as a peak), where a refracted or reflected ray
grazes its facet at ``psi = 0`` or ``pi``, and (transmission) where the facets refracting into
a direction turn horizontal.

Measured (``benchmarks/rough_surface.py``, n = 1.45, layers with g up to 0.5, finite and
opaque, substrates, in and out of the plane of incidence): ``alpha = 1e-4`` equals the smooth
model to 3e-6; for alpha in [0.02, 1] the BRDF at 16 points per interval is within 2e-6
(relative) of 48 points, and refining the fine rules changes it by < 4e-6.

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
    AZIMUTH_POINTS_PER_PANEL,
    _smoothstep_panels,
    reflection_modes,
    transmission_modes,
)
from .phase import ModeStopping, n_fourier_modes, normalise_on_quadrature, phase_fourier_modes
from .quadrature import binder_quadrature, gauss_legendre_barycentric_weights

__all__ = ["FINEST_PANEL", "MODE_BLOCK", "PANEL_POINTS", "ROUGHNESS_MAX", "RoughInterface", "rough_interface",
           "rough_surface_terms"]

#: Finest panel of the fine rules, as a fraction of ``min(alpha, FINEST_ALPHA_CAP)`` [rad of
#: theta]. The narrowest peak is the transmission's: ``theta_t`` spreads by ~``alpha (n - 1) / n``
#: (~0.3 alpha) around the refracted direction.
FINEST_PANEL = 1.0 / 16.0
#: Above this roughness the finest panel stops growing: the kinks of the kernels (the breaks of
#: the rules) carry more weight, and panels of alpha / 16 there left 1e-4 of the escape weights
#: at alpha = 1 (1e-6 with this cap; benchmarks/rough_surface.py).
FINEST_ALPHA_CAP = 0.25
#: Gauss points per panel of the fine rules.
PANEL_POINTS = 8
#: Azimuthal modes of the surface kernels computed together (the forward model stops at the
#: layer's last significant mode; evaluating the kernels costs more than their Fourier sums).
MODE_BLOCK = 16
#: Finest panel [rad] next to a break of the fine rules (a kink of a kernel, not a peak): the
#: smoothstep map makes a square-root kink smooth, so the panels there need not follow alpha.
BREAK_FINEST_PANEL = 1.0 / 64.0
#: Widest panel [rad] of the rule over air directions of the escape weights.
AIR_WIDEST_PANEL = np.pi / 16.0
#: Largest roughness accepted by the forward model: over [1e-4, 1] the quadrature is verified
#: (benchmarks/rough_surface.py); at alpha = 1 the single-scattering GGX surface already loses
#: 34-66 % of the light from the binder (benchmarks/microfacet.py).
ROUGHNESS_MAX = 1.0
#: Cached sets of interface weights (one per roughness, index, quadrature and distribution).
CACHE_SIZE = 8
_HALF_PI = 0.5 * np.pi


def _graded_rule(peaks, breaks, finest, points=PANEL_POINTS, widest=_HALF_PI):
    """Nodes and weights in ``theta`` over (0, pi/2) for ``int h(theta) dtheta``: panels split at
    ``breaks`` and halving in width towards each of ``peaks`` down to ``finest`` and towards
    each break down to ``max(finest, BREAK_FINEST_PANEL)``, none wider than ``widest``; each
    panel Gauss-Legendre in the smoothstep variable (square-root ends smooth)."""
    edges = [0.0, _HALF_PI]
    centres = [(x, finest) for x in peaks] + [(x, max(finest, BREAK_FINEST_PANEL)) for x in breaks]
    centres = [(x, w) for x, w in centres if 0.0 <= x <= _HALF_PI]
    edges.extend(x for x, _ in centres)
    for centre, width in centres:
        while width < _HALF_PI:
            edges.extend((centre - width, centre + width))
            width *= 2.0
    edges = np.unique(np.concatenate([np.clip(edges, 0.0, _HALF_PI),
                                      np.linspace(0.0, _HALF_PI, int(np.ceil(_HALF_PI / widest)) + 1)]))
    theta, weight = _smoothstep_panels(edges, points)
    keep = weight > 0.0
    return theta[keep], weight[keep]


class _LagrangeBasis:
    """Lagrange basis of the binder quadrature's intervals at arbitrary cosines."""

    def __init__(self, n_points, n):
        self.n_points = n_points
        self.mu_c = critical_cosine(n)
        x, _ = np.polynomial.legendre.leggauss(n_points)
        unit = 0.5 * (x + 1.0)
        weights = gauss_legendre_barycentric_weights(n_points)
        self.lower = BarycentricInterpolator(self.mu_c * unit, np.eye(n_points), wi=weights)
        self.upper = BarycentricInterpolator(unit, np.eye(n_points), wi=weights)
        mu_nodes = np.concatenate([self.mu_c * unit, self.mu_c + (1.0 - self.mu_c) * unit * unit])
        self.sine_nodes = np.sqrt(1.0 - mu_nodes * mu_nodes)

    def __call__(self, mu, odd=False):
        """``l_j(mu)``, shape (F, 2 n_points), for cosines ``mu`` (F,); with ``odd``, the basis
        ``l_j(mu) sin(theta) / sin(theta_j)`` of the odd azimuthal modes."""
        mu = np.asarray(mu, dtype=float)
        p = self.n_points
        out = np.zeros((mu.size, 2 * p))
        low = mu < self.mu_c
        if low.any():
            out[low, :p] = self.lower(mu[low])
        if (~low).any():
            s = np.sqrt(np.clip((mu[~low] - self.mu_c) / (1.0 - self.mu_c), 0.0, None))
            out[~low, p:] = self.upper(s)
        if odd:
            out *= np.sqrt(np.clip(1.0 - mu * mu, 0.0, None))[:, None] / self.sine_nodes
        return out

    def both(self, mu):
        """The even and odd modes' bases at ``mu``."""
        return self(mu), self(mu, odd=True)


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
    finest_panel, panel_points : float, int
        The fine rules' :data:`FINEST_PANEL` and :data:`PANEL_POINTS` (for convergence studies).
    azimuth_points : int
        Gauss points per azimuth panel of the kernels' Fourier integrals
        (:data:`~bayespig.physics.microfacet.AZIMUTH_POINTS_PER_PANEL`).

    Attributes
    ----------
    mu, weight : numpy.ndarray
        The binder quadrature, (q,) [-].
    escape : numpy.ndarray
        ``e_j = int T_out(mu) l_j(mu) mu dmu``, (q,) [-]: upward energy leaving into air.
    """

    def __init__(self, alpha, n, n_points, distribution="ggx", finest_panel=FINEST_PANEL, panel_points=PANEL_POINTS,
                 azimuth_points=AZIMUTH_POINTS_PER_PANEL):
        self.alpha, self.n, self.n_points, self.distribution = float(alpha), float(n), int(n_points), distribution
        self.panel_points, self.azimuth_points = int(panel_points), int(azimuth_points)
        self.mu, self.weight = binder_quadrature(self.n_points, self.n)
        self.c = self.mu * self.weight
        self.basis = _LagrangeBasis(self.n_points, self.n)
        self.theta_c = float(np.arccos(critical_cosine(self.n)))
        # rays refracted through a facet graze it where i.o = -1/n (microfacet.transmission_modes)
        self.theta_graze = float(np.arccos(1.0 / self.n))
        self.finest = finest_panel * min(self.alpha, FINEST_ALPHA_CAP)
        theta, w = _graded_rule([self.theta_c], [], self.finest, self.panel_points)
        self.outer_mu = np.cos(theta)
        self.outer_weight = w * np.sin(theta) * self.outer_mu  # for int h(mu) mu dmu
        self.outer_basis = self.basis.both(self.outer_mu)
        self._internal = {}
        self._entering = {}
        # escape: e_j = int T_out(mu) l_j mu dmu with T_out(mu) = int t_out(mu_o, mu) mu_o dmu_o and
        # t_out(mu_o, mu) = t_in(mu, mu_o) / n^2, so e_j = int A_in[j](mu_o) mu_o dmu_o / n^2 over air
        # directions, on a rule graded towards grazing (where the refracted light meets mu_c)
        theta_air, w_air = _graded_rule([_HALF_PI], [], self.finest, self.panel_points, AIR_WIDEST_PANEL)
        mu_air = np.cos(theta_air)
        entering = np.stack([self._entering_rule(m, 0, 1)[0] for m in mu_air], axis=-1)  # (q, A)
        self.escape = entering @ (w_air * np.sin(theta_air) * mu_air) / (self.n * self.n)

    @property
    def options(self):
        return {"alpha": self.alpha, "distribution": self.distribution, "points_per_panel": self.azimuth_points}

    def internal(self, block, size=MODE_BLOCK):
        """``W[j, k]`` of the modes ``size * block .. size * (block + 1) - 1``: (size, q, q) [-]."""
        if (block, size) not in self._internal:
            first = size * block
            q = self.mu.size
            rows = np.empty((size, self.outer_mu.size, q))
            tc, tg = self.theta_c, 2.0 * self.theta_c
            for f, mu_f in enumerate(self.outer_mu):
                theta = float(np.arccos(mu_f))
                # kinks: facets at the critical angle at psi = 0 (theta + theta' = 2 theta_c) and pi
                theta_in, w_in = _graded_rule([theta, tc], [tg - theta, theta - tg, theta + tg], self.finest,
                                              self.panel_points)
                mu_in = np.cos(theta_in)
                kernel = reflection_modes(mu_in, [mu_f], size, n_i=self.n, n_t=1.0, first_mode=first,
                                          **self.options)[:, :, 0]
                weighted = kernel * (w_in * np.sin(theta_in) * mu_in)
                bases = self.basis.both(mu_in)
                for k in range(size):
                    rows[k, f] = weighted[k] @ bases[(first + k) % 2]
            W = np.stack([np.einsum("f,fj,fk->jk", self.outer_weight, self.outer_basis[(first + k) % 2], rows[k])
                          for k in range(size)])
            self._internal[block, size] = 0.5 * (W + np.swapaxes(W, 1, 2))  # reciprocal; symmetric to round-off
        return self._internal[block, size]

    def entering(self, mu_air, block, size=MODE_BLOCK):
        """``A_in[j, i]`` for air cosines ``mu_air`` (k,), modes of ``block`` (of ``size``):
        (size, q, k) [-]."""
        out = np.empty((size, self.mu.size, len(mu_air)))
        for i, mu_i in enumerate(mu_air):
            key = (float(mu_i), block, size)
            if key not in self._entering:
                self._entering[key] = self._entering_rule(float(mu_i), size * block, size)
            out[:, :, i] = self._entering[key]
        return out

    def _entering_rule(self, mu_i, first, count):
        """``A_in[:, i]`` of one air direction, modes ``first .. first + count - 1``: (count, q)."""
        theta_i = float(np.arccos(min(mu_i, 1.0)))
        theta_t = float(np.arcsin(np.sin(theta_i) / self.n))
        tg = self.theta_graze
        # kinks: the refracted ray grazing its facet at psi = 0 or pi, and the facets that
        # refract into theta turning horizontal (n mu = mu_i: D(m) -> 0 there, not smoothly)
        theta_flat = float(np.arccos(mu_i / self.n))
        theta, w = _graded_rule([theta_t, self.theta_c],
                                [theta_i - tg, tg - theta_i, theta_i + tg, theta_flat],
                                self.finest, self.panel_points)
        mu = np.cos(theta)
        kernel = transmission_modes(mu, [mu_i], count, n_i=1.0, n_t=self.n, first_mode=first,
                                    **self.options)[:, :, 0]
        weighted = kernel * (w * np.sin(theta) * mu)
        bases = self.basis.both(mu)
        return np.stack([weighted[k] @ bases[(first + k) % 2] for k in range(count)])

    def leaving(self, mu_air, block, size=MODE_BLOCK):
        """``A_out[o, j]`` for air viewing cosines ``mu_air`` (k,): (size, k, q) [-]."""
        return np.swapaxes(self.entering(mu_air, block, size), 1, 2) / (self.n * self.n)


@functools.lru_cache(maxsize=CACHE_SIZE)
def rough_interface(alpha, n, n_points, distribution="ggx", **rules):
    """The cached :class:`RoughInterface` of ``(alpha, n, n_points, distribution)`` (and the
    fine rules' settings ``rules``, keywords of :class:`RoughInterface`)."""
    return RoughInterface(alpha, n, n_points, distribution, **rules)


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
                        mode_tolerance=1e-6, distribution="ggx", start_thickness=START_THICKNESS, rules=None):
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
    rules : dict, optional
        Fine-rule settings passed to :class:`RoughInterface` (convergence studies).

    Returns
    -------
    dict
        The fields of :class:`bayespig.physics.forward.SurfaceTerms`.
    """
    interface = rough_interface(float(alpha), float(n), int(n_points), distribution, **(rules or {}))
    mu_in = np.cos(np.radians(np.atleast_1d(np.asarray(theta_in, dtype=float))))
    mu_out = np.cos(np.radians(np.atleast_1d(np.asarray(theta_out, dtype=float))))
    a = np.atleast_1d(np.asarray(a, dtype=float))
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    adaptive = n_modes is None
    max_modes = n_fourier_modes(g) if n_modes is None else int(n_modes)
    size = min(MODE_BLOCK, max_modes)  # one mode only for isotropic scattering and hemispherical values
    mu, weight = interface.mu, interface.weight
    p_refl = phase_fourier_modes(mu, mu, g, max_modes, reflection=True)
    p_trans = phase_fourier_modes(mu, mu, g, max_modes, reflection=False)
    p_refl, p_trans = normalise_on_quadrature(p_refl, p_trans, weight)
    groups = [rows for rows in (np.flatnonzero(np.isfinite(tau)), np.flatnonzero(np.isinf(tau))) if rows.size]
    B, k_in, k_out = a.size, mu_in.size, mu_out.size
    terms = {"t_down": np.zeros((B, k_in)), "t_up": np.zeros((B, k_out)), "r_up": np.zeros(B),
             "h0": np.zeros((B, k_in)), "t_up_hemispherical": np.zeros(B)}
    f_modes = []
    stopping = None
    for m in range(max_modes):
        block, within = divmod(m, size)
        A_in = interface.entering(mu_in, block, size)[within]
        A_out = interface.leaving(mu_out, block, size)[within]
        W = interface.internal(block, size)[within]
        thickness = start_thickness if m == 0 else max(start_thickness, START_THICKNESS_HIGHER_MODES)
        f = np.zeros((B, k_out, k_in))
        active = np.ones(B, dtype=bool) if m == 0 else stopping.active(m)
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
            stopping = ModeStopping(f, max_modes, mode_tolerance, adaptive)
            continue
        if stopping.add(m, f):
            break
    terms["r_up"][np.isinf(tau)] = 0.0
    terms["f0_modes"] = stopping.truncate(f_modes)
    return terms
