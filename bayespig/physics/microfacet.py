"""A rough dielectric interface: the microfacet BSDF of Walter et al. (2007) and its azimuthal modes.

The rough air/binder surface (issue 16; DESIGN.md, "Rough top surface"): the surface's
scattering functions, point by point and as the azimuthal Fourier kernels that
:mod:`bayespig.physics.rough_surface` integrates against the binder quadrature's basis at the top
boundary of the layer, instead of the smooth surface's diagonal Fresnel reflectance ``r_F``.

Model
-----
A surface of randomly oriented mirror facets between two dielectrics (Walter, Marschner, Li &
Torrance 2007, "Microfacet models for refraction through rough surfaces", EGSR; equation numbers
below are that paper's): an isotropic microfacet distribution ``D`` (GGX / Trowbridge-Reitz by
default, eq. 33, or Beckmann, eq. 25), separable Smith masking-shadowing ``G = G1(i) G1(o)``
(eq. 23; GGX's exact ``G1``, eq. 34; Beckmann's exact erf form, eq. 26, not its rational
approximation eq. 27), unpolarised Fresnel reflectance at the microfacet
(:func:`bayespig.physics.fresnel.fresnel_reflectance`, total internal reflection included), and
no light scattered between facets: such light is lost, so the interface's directional albedo is
below one at large roughness (:func:`directional_albedo` measures it).

- Reflection (eq. 20): ``f_r = F(i.h) G1(i) G1(o) D(h) / (4 |i.n| |o.n|)`` with the half vector
  ``h = (i + o) / |i + o|`` (eq. 13).
- Transmission (eq. 21): ``f_t = |i.h| |o.h| n_o^2 (1 - F(i.h)) G1(i) G1(o) D(h) /
  (|i.n| |o.n| (n_i i.h + n_o o.h)^2)`` with the refraction half vector ``h ~ -(n_i i + n_o o)``
  (eq. 16) turned to the side of the macro normal ``n``.

Conventions
-----------
``i`` and ``o`` point away from the surface, ``i`` into the medium the light comes from (index
``n_i``), ``o`` into the medium it leaves into (``n_i`` for reflection, ``n_t`` for
transmission). Every polar angle is measured from the normal on its own side, so both cosines
``mu_i``, ``mu_o`` lie in (0, 1]. The azimuth ``psi`` [rad] is the difference of the
*propagation* azimuths of the incident and scattered light, as in
:mod:`bayespig.physics.adding_doubling` and :mod:`bayespig.physics.phase`: ``psi = 0`` is where
a smooth surface would send the light (the mirror direction for reflection, the refracted one
for transmission). The project's viewing azimuth ``delta_phi`` (180 deg on the specular side,
DESIGN.md section 1) is ``psi + 180 deg`` for reflection from air.

All functions are *radiance* BSDFs [1/sr]: scattered radiance per unit irradiance. Transmission
is not reciprocal in radiance: ``f_t(i -> o) / n_o^2 = f_t(o -> i) / n_i^2`` (reciprocity holds
for the "basic radiance" ``L / n^2``), so the kernel from binder to air is the transpose of the
one from air to binder divided by ``n^2`` (:class:`RoughSurfaceModes`). Reflection is
reciprocal on either side.

References
----------
Walter, Marschner, Li & Torrance (2007), Eurographics Symposium on Rendering, 195-206.
Heitz (2014), "Understanding the masking-shadowing function in microfacet-based BRDFs",
J. Comput. Graph. Tech. 3(2), 48-107 (the Smith ``Lambda`` functions; the masking
normalisation ``int G1(o, m) max(0, o.m) D(m) dw_m = o.n``, eq. 3 there).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from .fresnel import fresnel_reflectance, refracted_cosine

__all__ = [
    "ALBEDO_PANELS",
    "AZIMUTH_POINTS_PER_PANEL",
    "DISTRIBUTIONS",
    "RoughSurfaceModes",
    "directional_albedo",
    "flake_reflection_brdf",
    "microfacet_distribution",
    "reflection_brdf",
    "reflection_modes",
    "rough_surface_modes",
    "smith_g1",
    "transmission_btdf",
    "transmission_modes",
]

#: Microfacet distributions: GGX (Trowbridge-Reitz; Walter eq. 33) and Beckmann (eq. 25).
DISTRIBUTIONS = ("ggx", "beckmann")
#: Gauss-Legendre points per azimuth panel of the Fourier-mode integrals.
AZIMUTH_POINTS_PER_PANEL = 8
#: The finest azimuth panel is this fraction of ``min(alpha, 1)`` [rad] (times
#: ``min(1, mu_i + mu_o)`` for reflection): panels halve in width from ``pi`` towards
#: ``psi = 0``, where every kernel peaks, down to it. The peak's width in ``psi`` is >~ alpha / 4
#: for transmission, and ~alpha (mu_i + mu_o) / (s_i s_o) for reflection, which narrows between
#: grazing directions (``tan theta_h ~ psi s_i s_o / (mu_i + mu_o)``).
AZIMUTH_FINEST_PANEL = 1.0 / 32.0
#: Panels in the polar variable of :func:`directional_albedo`'s integral over normals.
ALBEDO_PANELS = 64
#: Gauss-Legendre points per panel of that polar integral.
_ALBEDO_POINTS = 8
#: Gauss-Legendre points per azimuth panel of :func:`directional_albedo` (the panels end at the
#: integrand's kinks, so within them it is smooth).
_ALBEDO_AZIMUTH_POINTS = 24
#: Largest number of (row, column, azimuth node) evaluations held at once by the mode integrals.
_CHUNK_ELEMENTS = 1 << 21


# ---------------------------------------------------------------------------------------------
# argument checks


def _check_alpha(alpha):
    if isinstance(alpha, bool) or not np.isscalar(alpha) or not np.isreal(alpha):
        raise TypeError(f"alpha (microfacet roughness) must be a real number, got {alpha!r}")
    alpha = float(alpha)
    if not np.isfinite(alpha) or alpha <= 0.0:
        raise ValueError(f"alpha (microfacet roughness) must be a finite number > 0, got {alpha}; "
                         "alpha = 0 is the smooth surface of bayespig.physics.fresnel")
    return alpha


def _check_distribution(distribution):
    if distribution not in DISTRIBUTIONS:
        raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {distribution!r}")
    return distribution


def _check_indices(n_i, n_t):
    for name, value in (("n_i", n_i), ("n_t", n_t)):
        if isinstance(value, bool) or not np.isscalar(value) or not np.isreal(value):
            raise TypeError(f"{name} (refractive index) must be a real number, got {value!r}")
        if not np.isfinite(value) or value <= 0.0:
            raise ValueError(f"{name} (refractive index) must be a finite number > 0, got {value}")
    if n_i == n_t:
        raise ValueError(f"n_i and n_t must differ (both {n_i}): an index-matched interface does not "
                         "scatter")
    return float(n_i), float(n_t)


def _check_cosines(name, mu):
    mu = np.asarray(mu, dtype=float)
    if not np.isfinite(mu).all() or (mu <= 0.0).any() or (mu > 1.0).any():
        raise ValueError(f"{name} (direction cosine) must lie in (0, 1]")
    return mu


def _check_psi(psi):
    psi = np.asarray(psi, dtype=float)
    if not np.isfinite(psi).all():
        raise ValueError("psi (azimuth difference, rad) must be finite")
    return psi


# ---------------------------------------------------------------------------------------------
# distribution, masking


def _tan2(cos):
    """``tan^2`` of the angle whose cosine is ``cos`` in (0, 1]."""
    return (1.0 - cos * cos) / (cos * cos)


def _distribution(cos_m, alpha, distribution):
    up = cos_m > 0.0
    c2 = np.where(up, cos_m * cos_m, 1.0)
    a2 = alpha * alpha
    if distribution == "ggx":
        # alpha^2 / (pi cos^4 (alpha^2 + tan^2)^2) = alpha^2 / (pi (cos^2 (alpha^2 - 1) + 1)^2)
        d = a2 / (np.pi * (c2 * (a2 - 1.0) + 1.0) ** 2)
    else:
        d = np.exp(-(1.0 - c2) / (c2 * a2)) / (np.pi * a2 * c2 * c2)
    return np.where(up, d, 0.0)


def microfacet_distribution(cos_m, alpha, distribution="ggx"):
    """Isotropic microfacet normal distribution ``D(m)``.

    Normalised so that ``int D(m) (m.n) dw_m = 1`` over the hemisphere of normals.

    Parameters
    ----------
    cos_m : array_like
        Cosine of the angle between the microfacet normal ``m`` and the macro normal ``n`` [-];
        ``D = 0`` for ``cos_m <= 0``.
    alpha : float
        Roughness [-]: GGX's ``alpha_g`` or Beckmann's ``alpha_b`` (the rms slope over sqrt 2).
    distribution : {"ggx", "beckmann"}
        GGX: ``alpha^2 / (pi cos^4 (alpha^2 + tan^2)^2)`` (Walter eq. 33); Beckmann:
        ``exp(-tan^2 / alpha^2) / (pi alpha^2 cos^4)`` (eq. 25).

    Returns
    -------
    numpy.ndarray
        ``D`` [1/sr].
    """
    return _distribution(np.asarray(cos_m, dtype=float), _check_alpha(alpha), _check_distribution(distribution))


def _g1(mu, alpha, distribution):
    """Smith ``G1`` of a direction of cosine ``mu`` in [0, 1] for facets that face it [-]."""
    grazing = mu <= 0.0
    mu = np.where(grazing, 1.0, mu)
    tan2 = _tan2(mu)
    if distribution == "ggx":
        g = 2.0 / (1.0 + np.sqrt(1.0 + alpha * alpha * tan2))
    else:
        # Lambda = (erf(a) - 1) / 2 + exp(-a^2) / (2 a sqrt(pi)), a = 1 / (alpha tan): eq. 26
        tan = np.sqrt(tan2)
        normal = tan == 0.0
        a = 1.0 / (alpha * np.where(normal, 1.0, tan))
        lam = -0.5 * special.erfc(a) + np.exp(-a * a) / (2.0 * a * np.sqrt(np.pi))
        g = np.where(normal, 1.0, 1.0 / (1.0 + lam))
    return np.where(grazing, 0.0, g)


def smith_g1(cos_vn, cos_vm, alpha, distribution="ggx"):
    """Smith masking function ``G1(v, m)`` of a direction ``v`` for microfacets of normal ``m``.

    ``G1(v, m) = chi+(v.m / v.n) / (1 + Lambda(v))``: GGX's exact form
    ``2 / (1 + sqrt(1 + alpha^2 tan^2 theta_v))`` (Walter eq. 34) or Beckmann's exact erf form
    ``2 / (1 + erf(a) + exp(-a^2) / (a sqrt(pi)))``, ``a = 1 / (alpha tan theta_v)`` (eq. 26;
    the rational approximation of eq. 27 is not used).

    Parameters
    ----------
    cos_vn : array_like
        ``v.n``, cosine between ``v`` and the macro normal [-], in [-1, 1].
    cos_vm : array_like
        ``v.m``, cosine between ``v`` and the microfacet normal [-]; a facet seen from its back
        side (``v.m`` and ``v.n`` of opposite signs) gives 0.
    alpha : float
        Roughness [-].
    distribution : {"ggx", "beckmann"}

    Returns
    -------
    numpy.ndarray
        ``G1`` [-], in [0, 1].
    """
    alpha = _check_alpha(alpha)
    distribution = _check_distribution(distribution)
    cos_vn = np.asarray(cos_vn, dtype=float)
    cos_vm = np.asarray(cos_vm, dtype=float)
    facing = cos_vn * cos_vm > 0.0
    return np.where(facing, _g1(np.clip(np.abs(cos_vn), 0.0, 1.0), alpha, distribution), 0.0)


# ---------------------------------------------------------------------------------------------
# the BSDF, point by point


def _reflection(mu_i, mu_o, cos_psi, alpha, n_i, n_t, distribution):
    """``f_r`` [1/sr] (eq. 20) on checked, broadcastable arrays."""
    s_i = np.sqrt(np.clip(1.0 - mu_i * mu_i, 0.0, None))
    s_o = np.sqrt(np.clip(1.0 - mu_o * mu_o, 0.0, None))
    i_dot_o = mu_i * mu_o - s_i * s_o * cos_psi
    half_norm = np.sqrt(2.0 * (1.0 + i_dot_o))  # |i + o| > 0 for two upward directions
    cos_h = (mu_i + mu_o) / half_norm
    cos_ih = 0.5 * half_norm  # i.h = o.h
    fresnel = fresnel_reflectance(cos_ih, n_i, n_t)
    g = _g1(mu_i, alpha, distribution) * _g1(mu_o, alpha, distribution)
    return fresnel * g * _distribution(cos_h, alpha, distribution) / (4.0 * mu_i * mu_o)


def _flake_reflection(mu_i, mu_o, cos_psi, alpha, n, distribution):
    """Flake lobe per unit flake reflectance [1/sr] on checked, broadcastable arrays (air cosines)."""
    mu_i_in = refracted_cosine(mu_i, 1.0, n)
    mu_o_in = refracted_cosine(mu_o, 1.0, n)
    through = (1.0 - fresnel_reflectance(mu_i, 1.0, n)) * (1.0 - fresnel_reflectance(mu_o, 1.0, n))
    s_i = np.sqrt(np.clip(1.0 - mu_i_in * mu_i_in, 0.0, None))
    s_o = np.sqrt(np.clip(1.0 - mu_o_in * mu_o_in, 0.0, None))
    i_dot_o = mu_i_in * mu_o_in - s_i * s_o * cos_psi
    half_norm = np.sqrt(2.0 * (1.0 + i_dot_o))
    cos_h = (mu_i_in + mu_o_in) / half_norm
    g = _g1(mu_i_in, alpha, distribution) * _g1(mu_o_in, alpha, distribution)
    return through * g * _distribution(cos_h, alpha, distribution) / (4.0 * mu_i_in * mu_o_in * n * n)


def flake_reflection_brdf(mu_i, mu_o, psi, *, alpha, n, distribution="ggx"):
    """Angular shape of the light reflected by flakes inside the layer (effect pigments), seen from air [1/sr].

    Platelets (metal or pearlescent flakes) lying nearly parallel to the surface inside the
    binder reflect like mirror facets whose normals spread around the layer's normal. Seen
    from air through the (mean, smooth) surface, per unit *flake reflectance* ``c``:

    ``f_flake = T(mu_i) T(mu_o) / n^2 * G1(i') G1(o') D(h') / (4 mu_i' mu_o')``

    with ``i'``, ``o'`` the directions refracted into the binder (Snell; the azimuth is kept),
    ``h'`` their half vector, ``D`` and ``G1`` the microfacet distribution of the flake normals
    and Smith's masking of this module (Walter et al. 2007, eqs. 20, 23, 33/25) with the
    flakes' roughness ``alpha`` and no Fresnel factor (``c`` is the flakes' reflectance), and
    ``T = 1 - r_F`` the smooth surface's Fresnel transmittance in and out; ``1 / n^2`` is the
    radiance's change across the interface (``L / n^2`` is invariant), so that a Lambertian
    ``f'`` inside would give ``T T f' / n^2`` in air. Light reflected by flakes beyond the
    critical angle stays in the layer (no air direction maps onto it).

    Scope (stated, not modelled): the flakes' depth in the layer (the attenuation of the light
    on its way to them, and what the pigment does to it, is in ``c(lambda)`` and not in the
    shape), light that the body scatters onto flakes and back, and the rough surface's
    blurring of the lobe (that widens it: it is in the fitted ``alpha``). Reciprocal
    (``f(i, o) = f(o, i)``); its directional albedo is at most ``c``.

    Parameters
    ----------
    mu_i, mu_o : array_like
        Cosines of the incidence and viewing angles in air [-], in (0, 1].
    psi : array_like
        Difference of the propagation azimuths [rad] (0 at the mirror direction; the project's
        ``delta_phi = psi + pi``).
    alpha : float or array_like
        Roughness of the flakes' orientation distribution [-] (> 0).
    n : float
        Binder index [-] (> 1).
    distribution : {"ggx", "beckmann"}

    Returns
    -------
    numpy.ndarray
        ``f_flake / c`` [1/sr], the arguments broadcast.
    """
    if alpha is None or isinstance(alpha, (str, bytes, bool, np.bool_)):
        raise TypeError(f"alpha (flake roughness) must be a real number or an array of them, got {alpha!r}")
    alpha = np.asarray(alpha)
    if alpha.dtype.kind not in "iuf":
        raise TypeError(f"alpha (flake roughness) must be a real number or an array of them, got {alpha!r}")
    alpha = alpha.astype(float)
    if not (np.isfinite(alpha).all() and (alpha > 0).all()):
        raise ValueError(f"alpha must be > 0, got {alpha!r}")
    _, n = _check_indices(1.0, n)
    if n < 1.0:
        # light from air would be totally reflected at the surface for most angles (nan below)
        raise ValueError(f"n (binder index) must be > 1 (a binder denser than air), got {n}")
    return _flake_reflection(_check_cosines("mu_i", mu_i), _check_cosines("mu_o", mu_o), np.cos(_check_psi(psi)),
                             alpha, n, _check_distribution(distribution))


def _transmission(mu_i, mu_o, cos_psi, alpha, n_i, n_t, distribution):
    """``f_t`` [1/sr] (eq. 21) on checked, broadcastable arrays.

    With ``i = (s_i, 0, mu_i)`` and ``o = (-s_o cos psi, -s_o sin psi, -mu_o)``, the refraction
    half vector ``H = -(n_i i + n_t o)`` (eq. 16) has ``|H|^2 = n_i^2 + n_t^2 + 2 n_i n_t i.o``,
    ``H.z = n_t mu_o - n_i mu_i`` (its sign turns it to the side of ``n``), and the denominator
    of eq. 21, ``(n_i i.h + n_t o.h)^2``, is ``|H|^2``.
    """
    s_i = np.sqrt(np.clip(1.0 - mu_i * mu_i, 0.0, None))
    s_o = np.sqrt(np.clip(1.0 - mu_o * mu_o, 0.0, None))
    i_dot_o = -s_i * s_o * cos_psi - mu_i * mu_o
    h_z = n_t * mu_o - n_i * mu_i
    h_norm2 = n_i * n_i + n_t * n_t + 2.0 * n_i * n_t * i_dot_o
    h_norm = np.sqrt(np.clip(h_norm2, 0.0, None))
    safe = np.where(h_norm > 0.0, h_norm, 1.0)
    side = np.sign(h_z)
    cos_im = side * -(n_i + n_t * i_dot_o) / safe
    cos_om = side * -(n_i * i_dot_o + n_t) / safe
    cos_m = np.abs(h_z) / safe
    # chi+ of both masking functions: i.m > 0 (i.n > 0) and o.m < 0 (o.n < 0)
    valid = (cos_im > 0.0) & (cos_om < 0.0) & (h_norm > 0.0)
    fresnel = fresnel_reflectance(np.clip(cos_im, 0.0, 1.0), n_i, n_t)
    g = _g1(mu_i, alpha, distribution) * _g1(mu_o, alpha, distribution)
    f = (cos_im * -cos_om * n_t * n_t * (1.0 - fresnel) * g * _distribution(cos_m, alpha, distribution)
         / (mu_i * mu_o * np.where(h_norm > 0.0, h_norm2, 1.0)))
    return np.where(valid, f, 0.0)


def reflection_brdf(mu_i, mu_o, psi, *, alpha, n_i, n_t, distribution="ggx"):
    """Reflection by the rough interface on the side of the medium ``n_i`` (Walter eq. 20).

    From air (``n_i = 1``, ``n_t = n``) this is the first-surface glossy lobe; from inside
    (``n_i = n``, ``n_t = 1``) the internal reflection, total where a facet is met beyond the
    critical angle.

    Parameters
    ----------
    mu_i, mu_o : array_like
        Cosines of the incidence and reflection angles, both in medium ``n_i``, in (0, 1] [-].
    psi : array_like
        Difference of the propagation azimuths [rad]; 0 is the mirror direction.
    alpha : float
        Roughness [-] (GGX's ``alpha``).
    n_i, n_t : float
        Refractive indices of the medium of the light and of the other side [-].
    distribution : {"ggx", "beckmann"}

    Returns
    -------
    numpy.ndarray
        BRDF ``f_r`` [1/sr], the arguments broadcast; reciprocal, ``f_r(mu_i, mu_o, psi) =
        f_r(mu_o, mu_i, psi)``.
    """
    alpha = _check_alpha(alpha)
    distribution = _check_distribution(distribution)
    n_i, n_t = _check_indices(n_i, n_t)
    mu_i, mu_o = _check_cosines("mu_i", mu_i), _check_cosines("mu_o", mu_o)
    return _reflection(mu_i, mu_o, np.cos(_check_psi(psi)), alpha, n_i, n_t, distribution)


def transmission_btdf(mu_i, mu_t, psi, *, alpha, n_i, n_t, distribution="ggx"):
    """Transmission through the rough interface from medium ``n_i`` into ``n_t`` (Walter eq. 21).

    Parameters
    ----------
    mu_i : array_like
        Cosine of the incidence angle in medium ``n_i``, in (0, 1] [-].
    mu_t : array_like
        Cosine of the transmission angle in medium ``n_t`` (from the normal on that side), in
        (0, 1] [-].
    psi : array_like
        Difference of the propagation azimuths [rad]; 0 is the smooth surface's refracted
        direction's azimuth.
    alpha : float
        Roughness [-].
    n_i, n_t : float
        Refractive indices of the incident and transmitting media [-] (they must differ).
    distribution : {"ggx", "beckmann"}

    Returns
    -------
    numpy.ndarray
        Radiance BTDF ``f_t`` [1/sr]: transmitted radiance in ``n_t`` per unit irradiance in
        ``n_i``. Reciprocity holds for ``f_t / n_t^2``: ``f_t(n_i -> n_t) / n_t^2 =
        f_t(n_t -> n_i) / n_i^2`` with the two cosines swapped.
    """
    alpha = _check_alpha(alpha)
    distribution = _check_distribution(distribution)
    n_i, n_t = _check_indices(n_i, n_t)
    mu_i, mu_t = _check_cosines("mu_i", mu_i), _check_cosines("mu_t", mu_t)
    return _transmission(mu_i, mu_t, np.cos(_check_psi(psi)), alpha, n_i, n_t, distribution)


# ---------------------------------------------------------------------------------------------
# directional albedo by quadrature over the microfacet normals


def _smoothstep_panels(edges, n_points):
    """Composite Gauss-Legendre nodes and weights on the panels ``edges`` (..., E), each panel
    mapped by ``x = lo + width (3 t^2 - 2 t^3)``: a panel end where the integrand goes like
    ``sqrt(x - x_end)`` (a facet at its critical angle) becomes smooth. Returns (..., P)."""
    lo, width = edges[..., :-1], np.diff(edges, axis=-1)
    x, w = np.polynomial.legendre.leggauss(n_points)
    t = 0.5 * (x + 1.0)
    step, slope = t * t * (3.0 - 2.0 * t), 6.0 * t * (1.0 - t) * 0.5 * w
    nodes = lo[..., None] + width[..., None] * step
    return nodes.reshape(edges.shape[:-1] + (-1,)), (width[..., None] * slope).reshape(edges.shape[:-1] + (-1,))


def _albedo_azimuths(mu, s, cos_m, sin_m, eta, n_i, n_t):
    """Azimuths of the normals over [0, pi] for :func:`directional_albedo`, per incidence ``mu``
    (K, 1, 1) and polar angle of the normal (``cos_m``, ``sin_m``: (U, 1)), on panels split where
    the integrand has a kink: ``i.m`` at 0 (facets seen edge-on), at ``mu / (2 cos theta_m)``
    (the reflected ray at the horizon), at the critical cosine (from the denser side) and where
    the refracted ray reaches the horizon. ``i.m = s sin theta_m cos phi + mu cos theta_m`` is
    linear in ``cos phi``. Returns ``phi`` and weights, (K, U, P)."""
    cos_crit = np.sqrt(1.0 - (n_t / n_i) ** 2) if n_i > n_t else 0.0
    a = eta * mu / cos_m  # o_t.n = 0 <=> eta i.m - sqrt(1 - eta^2 + eta^2 (i.m)^2) = a; (K, U, 1)
    critical = [np.zeros_like(a), mu / (2.0 * cos_m), np.full_like(a, cos_crit),
                (a * a - 1.0 + eta * eta) / (2.0 * a * eta)]
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_phi = [(c - mu * cos_m) / (s * sin_m) for c in critical]
    kinks = [np.where(np.abs(c) < 1.0, np.arccos(np.clip(c, -1.0, 1.0)), np.pi) for c in cos_phi]
    edges = np.sort(np.concatenate([np.zeros_like(a), np.full_like(a, np.pi)] + kinks, axis=-1), axis=-1)
    return _smoothstep_panels(edges, _ALBEDO_AZIMUTH_POINTS)


def _albedo_polar_events(mu, eta, n_i, n_t, n_grid=4097):
    """Polar angles of the normal [rad] where a kink curve of :func:`directional_albedo`'s
    integrand touches the plane of incidence (``phi = 0`` or ``pi``), per incidence ``mu`` (K,):
    sign changes of ``i.m``, ``o_r.n``, ``i.m - cos_crit`` and ``o_t.n`` along a grid in
    ``theta_m``, located by linear interpolation. Returns (K, E), padded with ``pi / 2``."""
    theta = np.linspace(0.0, 0.5 * np.pi, n_grid)
    cos_crit = np.sqrt(1.0 - (n_t / n_i) ** 2) if n_i > n_t else -2.0
    mu = mu[:, None, None]
    s = np.sqrt(np.clip(1.0 - mu * mu, 0.0, None))
    side = np.array([1.0, -1.0])[None, :, None]  # phi = 0, pi
    cos_m, sin_m = np.cos(theta), side * np.sin(theta)
    cos_im = s * sin_m + mu * cos_m  # (K, 2, G)
    k = 1.0 - eta * eta * (1.0 - cos_im * cos_im)
    cos_ot = np.where(k > 0.0, (eta * cos_im - np.sqrt(np.clip(k, 0.0, None))) * cos_m - eta * mu, -1.0)
    found = []
    for event in (cos_im, 2.0 * cos_im * cos_m - mu, cos_im - cos_crit, cos_ot):
        a, b = event[..., :-1], event[..., 1:]
        change = (a > 0.0) != (b > 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            root = theta[:-1] + (theta[1] - theta[0]) * np.where(change, a / (a - b), 0.0)
        found.append(np.where(change, root, 0.5 * np.pi).reshape(mu.shape[0], -1))
    found = np.sort(np.concatenate(found, axis=-1), axis=-1)
    most = int((found < 0.5 * np.pi).sum(axis=-1).max())
    return found[:, :max(most, 1)]


def directional_albedo(mu_i, *, alpha, n_i, n_t, distribution="ggx", n_panels=ALBEDO_PANELS):
    """Directional reflectance and transmittance of the rough interface, by quadrature over normals.

    With the Jacobians of the half-vector maps (Walter eqs. 14 and 17) the hemispherical
    integrals ``R = int f_r mu_o dw_o`` and ``T = int f_t mu_t dw_t`` become one integral over
    microfacet normals,
    ``int D(m) G1(i, m) (i.m) / (i.n) [F G1(o_r, m) + (1 - F) G1(o_t, m)] dw_m``, with ``o_r``
    and ``o_t`` the directions the facet reflects and refracts ``i`` into (eq. 40). It is done
    in the variable ``xi`` that makes ``D(m) (m.n) dw_m`` uniform (``tan^2 theta_m = alpha^2 xi
    / (1 - xi)`` for GGX, eq. 35; ``-alpha^2 log(1 - xi)`` for Beckmann, eq. 28), with
    ``xi = 1 - (1 - u)^2`` removing the ``1 / cos theta_m`` end-point singularity: a composite
    rule in ``u``, and in the azimuth of ``m`` Gauss-Legendre panels split where the integrand
    has a kink (:func:`_albedo_azimuths`), both with the smoothstep map that makes a panel
    end's square-root behaviour smooth. Independent of
    :func:`reflection_brdf` and :func:`transmission_btdf` (it uses ``D``, ``G1`` and ``F``
    only). ``1 - R - T`` is the light the single-scattering model loses (it would be scattered
    again by other facets).

    Parameters
    ----------
    mu_i : array_like
        Cosines of the incidence angle in medium ``n_i``, in (0, 1] [-].
    alpha : float
        Roughness [-].
    n_i, n_t : float
        Refractive indices of the incident and other medium [-].
    distribution : {"ggx", "beckmann"}
    n_panels : int
        Panels of the composite rule in ``u`` (each :data:`_ALBEDO_POINTS` points); the
        default's error is ~1e-6 at ``alpha = 0.05`` and ~1e-8 at 0.5 (measured against 256
        panels; tests/physics/test_microfacet.py also checks it against adaptive quadrature of
        the BSDF over outgoing directions, and against the m = 0 kernels).

    Returns
    -------
    reflectance, transmittance : numpy.ndarray
        ``R`` and ``T`` [-], the shape of ``mu_i``.
    """
    alpha = _check_alpha(alpha)
    distribution = _check_distribution(distribution)
    n_i, n_t = _check_indices(n_i, n_t)
    mu_i = _check_cosines("mu_i", mu_i)
    if isinstance(n_panels, bool) or not isinstance(n_panels, (int, np.integer)) or n_panels < 1:
        raise ValueError(f"n_panels must be an integer >= 1, got {n_panels!r}")
    shape = mu_i.shape
    mu = mu_i.reshape(-1, 1, 1)
    s = np.sqrt(np.clip(1.0 - mu * mu, 0.0, None))
    eta = n_i / n_t
    g1_i = _g1(mu, alpha, distribution)
    # the polar panels also end where a kink curve of the (theta_m, phi) plane touches phi = 0 or pi
    events = _albedo_polar_events(mu[:, 0, 0], eta, n_i, n_t)  # (K, E) theta_m [rad]
    tan2_events = np.tan(events) ** 2
    if distribution == "ggx":
        xi_events = tan2_events / (alpha * alpha + tan2_events)
    else:
        xi_events = -np.expm1(-tan2_events / (alpha * alpha))
    u_events = 1.0 - np.sqrt(np.clip(1.0 - xi_events, 0.0, 1.0))
    uniform = np.broadcast_to(np.linspace(0.0, 1.0, int(n_panels) + 1), (mu.shape[0], int(n_panels) + 1))
    u, w_u = _smoothstep_panels(np.sort(np.concatenate([uniform, u_events], axis=-1), axis=-1), _ALBEDO_POINTS)
    u = np.where(w_u > 0.0, u, 0.5)  # nodes of empty panels (events padded at the horizon)
    one_minus_xi = (1.0 - u) ** 2  # (K, U)
    xi_weight = 2.0 * (1.0 - u) * w_u  # xi = 1 - (1 - u)^2
    with np.errstate(divide="ignore"):
        if distribution == "ggx":
            tan2 = alpha * alpha * (1.0 - one_minus_xi) / one_minus_xi
        else:
            tan2 = -alpha * alpha * np.log(one_minus_xi)
    cos_m = (1.0 / np.sqrt(1.0 + tan2))[..., None]  # (K, U, 1)
    sin_m = np.sqrt(np.clip(1.0 - cos_m * cos_m, 0.0, None))
    reflectance = np.zeros(mu.shape[0])
    transmittance = np.zeros(mu.shape[0])
    per_chunk = max(1, _CHUNK_ELEMENTS // (u.shape[1] * 5 * _ALBEDO_AZIMUTH_POINTS))
    for start in range(0, mu.shape[0], per_chunk):
        rows = slice(start, start + per_chunk)
        m, sm, g1 = mu[rows], s[rows], g1_i[rows]
        c_m, s_m = cos_m[rows], sin_m[rows]
        phi, w_phi = _albedo_azimuths(m, sm, c_m, s_m, eta, n_i, n_t)  # (K, U, P)
        cos_im = sm * s_m * np.cos(phi) + m * c_m
        seen = cos_im > 0.0
        cos_im = np.where(seen, np.minimum(cos_im, 1.0), 0.0)
        # dxi dphi / (2 pi) with phi over [0, pi] counted twice
        visible = (np.where(seen, g1 * cos_im / (m * c_m), 0.0) * w_phi
                   * xi_weight[rows, :, None] / np.pi)
        fresnel = fresnel_reflectance(cos_im, n_i, n_t)
        cos_or = 2.0 * cos_im * c_m - m
        g_r = np.where(cos_or > 0.0, _g1(np.clip(cos_or, 0.0, 1.0), alpha, distribution), 0.0)
        k = 1.0 - eta * eta * (1.0 - cos_im * cos_im)
        cos_ot = (eta * cos_im - np.sqrt(np.clip(k, 0.0, None))) * c_m - eta * m  # o_t.n < 0: it leaves
        g_t = np.where((cos_ot < 0.0) & (k > 0.0), _g1(np.clip(-cos_ot, 0.0, 1.0), alpha, distribution), 0.0)
        reflectance[rows] = (visible * fresnel * g_r).sum(axis=(1, 2))
        transmittance[rows] = (visible * (1.0 - fresnel) * g_t).sum(axis=(1, 2))
    return reflectance.reshape(shape), transmittance.reshape(shape)


# ---------------------------------------------------------------------------------------------
# azimuthal Fourier modes


def _azimuth_panels(alpha, points_per_panel, n_modes, narrowing=1.0):
    """Panel edges in ``psi`` over [0, pi] shared by every pair: halving in width from ``pi``
    down to :data:`AZIMUTH_FINEST_PANEL` ``* min(alpha, 1) * narrowing`` at ``psi = 0`` (where
    the kernels peak), and none wider than ``points_per_panel / (2 n_modes)`` so that
    ``cos(m psi)`` of every mode asked for is resolved."""
    finest = AZIMUTH_FINEST_PANEL * min(alpha, 1.0) * narrowing
    levels = int(np.ceil(np.log2(np.pi / finest)))
    graded = np.pi * 2.0 ** -np.arange(levels, -1, -1, dtype=float)
    uniform = np.linspace(0.0, np.pi, int(np.ceil(2.0 * np.pi * n_modes / points_per_panel)) + 1)
    return np.unique(np.concatenate([[0.0], graded, uniform]))


def _azimuth_rule(bounds, kink_cos_psi, points_per_panel):
    """Per-pair Gauss-Legendre nodes and weights in ``psi`` over [0, pi] on the panels
    ``bounds``, the panel holding the pair's ``kink_cos_psi`` (the azimuth where the integrand
    stops being smooth: a facet's critical angle, where the internal reflection goes like
    ``sqrt(psi - psi_c)``) split there, each panel in the smoothstep variable of
    :func:`_smoothstep_panels`. Returns ``psi`` and ``weight`` of shape
    ``kink_cos_psi.shape + (P,)``."""
    kink = np.where(np.abs(kink_cos_psi) < 1.0, np.arccos(np.clip(kink_cos_psi, -1.0, 1.0)), np.pi)
    edges = np.sort(np.concatenate([np.broadcast_to(bounds, kink.shape + bounds.shape), kink[..., None]],
                                   axis=-1), axis=-1)
    return _smoothstep_panels(edges, points_per_panel)


def _check_mode_arguments(mu_out, mu_in, n_modes, points_per_panel):
    mu_out = np.atleast_1d(_check_cosines("mu_out", mu_out)).ravel()
    mu_in = np.atleast_1d(_check_cosines("mu_in", mu_in)).ravel()
    for name, value, least in (("n_modes", n_modes, 1), ("points_per_panel", points_per_panel, 2)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
            raise ValueError(f"{name} must be an integer >= {least}, got {value!r}")
    return mu_out, mu_in, int(n_modes), int(points_per_panel)


def _first_mode(first_mode):
    if isinstance(first_mode, bool) or not isinstance(first_mode, (int, np.integer)) or first_mode < 0:
        raise ValueError(f"first_mode must be an integer >= 0, got {first_mode!r}")
    return int(first_mode)


def _modes(kernel, mu_out, mu_in, n_modes, alpha, kink, points_per_panel, narrowing=1.0, first_mode=0):
    """``K_m[o, i] = int_0^{2 pi} kernel(mu_i, mu_o, psi) cos(m psi) dpsi``, for
    ``m = first_mode .. first_mode + n_modes - 1``.

    ``kernel(mu_in_col, mu_out_row, cos_psi)`` is a radiance BSDF [1/sr]; ``kink(mu_in, mu_out)``
    the cosine of its non-smooth azimuth per pair (``inf`` for none); ``narrowing`` scales the
    finest azimuth panel (:data:`AZIMUTH_FINEST_PANEL`).
    """
    modes = np.empty((n_modes, mu_out.size, mu_in.size))
    bounds = _azimuth_panels(alpha, points_per_panel, first_mode + n_modes, narrowing)
    per_row = max(1, _CHUNK_ELEMENTS // (mu_in.size * points_per_panel * bounds.size))
    for start in range(0, mu_out.size, per_row):
        rows = slice(start, start + per_row)
        m_o = mu_out[rows, None]
        m_i = mu_in[None, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            kink_cos = kink(m_i, m_o)
        psi, weight = _azimuth_rule(bounds, np.broadcast_to(kink_cos, (m_o.size, m_i.size)), points_per_panel)
        cos_psi = np.cos(psi)
        # f even in psi: int over [0, 2 pi] = 2 int over [0, pi]
        weighted = 2.0 * weight * kernel(m_i[..., None], m_o[..., None], cos_psi)
        # Chebyshev: cos((m+1) psi) = 2 cos(psi) cos(m psi) - cos((m-1) psi)
        previous, current = np.cos((first_mode - 1) * psi), np.cos(first_mode * psi)
        for m in range(n_modes):
            modes[m, rows] = (weighted * current).sum(axis=-1)
            previous, current = current, 2.0 * cos_psi * current - previous
    return modes


def reflection_modes(mu_out, mu_in, n_modes, *, alpha, n_i, n_t, distribution="ggx",
                     points_per_panel=AZIMUTH_POINTS_PER_PANEL, first_mode=0):
    """Azimuthal Fourier kernels of the reflection on the side of medium ``n_i``.

    ``K_m[o, i] = int_0^{2 pi} f_r(mu_i, mu_o, psi) cos(m psi) dpsi = 2 pi f_m`` with
    ``f_r = f_0 + 2 sum_{m>=1} f_m cos(m psi)``: the kernel convention of
    :mod:`bayespig.physics.adding_doubling` (``L_out = K @ (c * L_in)``, ``c = mu w``; for a
    collimated beam of unit irradiance along ``mu_i``, ``K[:, i]`` is the mode of the reflected
    radiance times ``2 pi``). The azimuth integral is Gauss-Legendre on panels graded towards
    ``psi = 0`` (:data:`AZIMUTH_FINEST_PANEL`) and split at the azimuth where facets reach the
    critical angle (reflection from the denser side).

    Parameters
    ----------
    mu_out, mu_in : array_like
        Cosines of the reflected and incident directions in medium ``n_i``, in (0, 1] [-];
        shapes (k_out,), (k_in,).
    n_modes : int
        Modes ``m = 0 .. n_modes - 1``.
    alpha : float
        Roughness [-].
    n_i, n_t : float
        Refractive indices of the medium of the light and of the other side [-].
    distribution : {"ggx", "beckmann"}
    points_per_panel : int
        Gauss points per azimuth panel.
    first_mode : int
        The first mode computed: ``m = first_mode .. first_mode + n_modes - 1`` (blocks of
        modes, as the forward model asks for them).

    Returns
    -------
    numpy.ndarray
        ``K_m``, shape (n_modes, k_out, k_in) [-] (1/sr times rad); symmetric in its last two
        axes when ``mu_out`` and ``mu_in`` are the same nodes.
    """
    alpha = _check_alpha(alpha)
    distribution = _check_distribution(distribution)
    n_i, n_t = _check_indices(n_i, n_t)
    mu_out, mu_in, n_modes, points_per_panel = _check_mode_arguments(mu_out, mu_in, n_modes, points_per_panel)

    def kernel(m_i, m_o, cos_psi):
        return _reflection(m_i, m_o, cos_psi, alpha, n_i, n_t, distribution)

    def kink(m_i, m_o):
        if n_i <= n_t:
            return np.full(np.broadcast(m_i, m_o).shape, np.inf)
        # facets at the critical angle: i.h = cos_c, i.o = 2 cos_c^2 - 1 = 1 - 2 (n_t/n_i)^2
        r2 = (n_t / n_i) ** 2
        return (m_i * m_o - 1.0 + 2.0 * r2) / (np.sqrt(1.0 - m_i * m_i) * np.sqrt(1.0 - m_o * m_o))

    narrowing = min(1.0, float(mu_out.min() + mu_in.min()))  # the lobe narrows between grazing directions
    return _modes(kernel, mu_out, mu_in, n_modes, alpha, kink, points_per_panel, narrowing, _first_mode(first_mode))


def transmission_modes(mu_out, mu_in, n_modes, *, alpha, n_i, n_t, distribution="ggx",
                       points_per_panel=AZIMUTH_POINTS_PER_PANEL, first_mode=0):
    """Azimuthal Fourier kernels of the transmission from medium ``n_i`` into ``n_t``.

    ``K_m[o, i] = int_0^{2 pi} f_t(mu_i, mu_o, psi) cos(m psi) dpsi`` in radiance units, as in
    :func:`reflection_modes`; the azimuth panel holding the edge of the transmitting azimuths
    (``i.o = -min(n) / max(n)``, where the refracted ray grazes its facet) is split there.

    Parameters
    ----------
    mu_out : array_like
        Cosines of the transmitted directions in medium ``n_t``, in (0, 1] [-], shape (k_out,).
    mu_in : array_like
        Cosines of the incident directions in medium ``n_i``, in (0, 1] [-], shape (k_in,).
    n_modes : int
    alpha : float
    n_i, n_t : float
    distribution : {"ggx", "beckmann"}
    points_per_panel : int
    first_mode : int
        As in :func:`reflection_modes`.

    Returns
    -------
    numpy.ndarray
        ``K_m``, shape (n_modes, k_out, k_in) [-]. Reciprocity:
        ``transmission_modes(a, b, n_i=n1, n_t=n2) / n2^2`` is the transpose of
        ``transmission_modes(b, a, n_i=n2, n_t=n1) / n1^2``.
    """
    alpha = _check_alpha(alpha)
    distribution = _check_distribution(distribution)
    n_i, n_t = _check_indices(n_i, n_t)
    mu_out, mu_in, n_modes, points_per_panel = _check_mode_arguments(mu_out, mu_in, n_modes, points_per_panel)
    ratio = min(n_i, n_t) / max(n_i, n_t)

    def kernel(m_i, m_o, cos_psi):
        return _transmission(m_i, m_o, cos_psi, alpha, n_i, n_t, distribution)

    def kink(m_i, m_o):
        # i.o = -s_i s_o cos psi - mu_i mu_o = -ratio
        return (ratio - m_i * m_o) / (np.sqrt(1.0 - m_i * m_i) * np.sqrt(1.0 - m_o * m_o))

    return _modes(kernel, mu_out, mu_in, n_modes, alpha, kink, points_per_panel, first_mode=_first_mode(first_mode))


@dataclass(frozen=True)
class RoughSurfaceModes:
    """The rough air/binder surface as azimuthal Fourier kernels on given direction sets.

    Every kernel is ``K_m = 2 pi f_m`` of a radiance BSDF in the convention of
    :mod:`bayespig.physics.adding_doubling`: outgoing radiance mode ``L_out = K_m @ (c * L_in)``
    with ``c = mu w`` the cosine-weighted quadrature of the *incident* medium (for a collimated
    beam of unit irradiance, the column of its direction). A discrete-ordinate solver would use
    them at the top boundary instead of the smooth surface: the downward radiance under the
    surface becomes ``I+(0) = r_internal @ (c I-(0)) + t_in[:, beam]`` (the smooth surface's
    ``r_F(mu) I-(0)`` with a refracted beam), and the air radiance
    ``L_air = r_air[:, beam] + t_out @ (c I-(0))`` (the smooth surface's
    ``t_F L / n^2`` along one refracted direction). Azimuths are propagation-azimuth
    differences: the BRDF from air at the viewing azimuth ``delta_phi`` is
    ``sum_m (2 - delta_m0) (-1)^m cos(m delta_phi) K_m / (2 pi)``, as ``f0_modes`` in
    :mod:`bayespig.physics.forward`.

    Attributes
    ----------
    r_air : numpy.ndarray
        Reflection from air into air (the first-surface lobe), (M, k_out, k_in) [-].
    t_in : numpy.ndarray
        Transmission from air into the binder, (M, N, k_in) [-]: radiance in the binder.
    t_out : numpy.ndarray
        Transmission from the binder into air, (M, k_out, N) [-]: radiance in air.
    r_internal : numpy.ndarray
        Reflection inside the binder, total internal reflection at the facets included,
        (M, N, N) [-].
    n : float
        Refractive index of the binder [-].
    """

    r_air: np.ndarray
    t_in: np.ndarray
    t_out: np.ndarray
    r_internal: np.ndarray
    n: float


def rough_surface_modes(mu_air_in, mu_air_out, mu_binder, n_modes, *, alpha, n=1.45, distribution="ggx",
                        points_per_panel=AZIMUTH_POINTS_PER_PANEL):
    """Fourier kernels of the rough air/binder surface for the directions of one solve.

    Parameters
    ----------
    mu_air_in, mu_air_out : array_like
        Cosines of the incidence and viewing directions in air, in (0, 1] [-], (k_in,), (k_out,).
    mu_binder : array_like
        Cosines of the binder directions (e.g. :func:`~bayespig.physics.quadrature.binder_quadrature`
        nodes), in (0, 1] [-], (N,).
    n_modes : int
        Azimuthal modes ``m = 0 .. n_modes - 1``.
    alpha : float
        Roughness [-] (GGX's alpha).
    n : float
        Refractive index of the binder, > 1 [-].
    distribution : {"ggx", "beckmann"}
    points_per_panel : int
        Gauss points per azimuth panel (:func:`reflection_modes`).

    Returns
    -------
    RoughSurfaceModes
        ``t_out`` is computed as ``t_in``'s reciprocal (transpose over ``n^2``) when the air
        direction sets are the same, else directly.
    """
    options = {"alpha": alpha, "distribution": distribution, "points_per_panel": points_per_panel}
    if isinstance(n, bool) or not np.isscalar(n) or not np.isreal(n) or not np.isfinite(n) or n <= 1.0:
        raise ValueError(f"n (binder refractive index) must be a finite number > 1, got {n!r}")
    n = float(n)
    mu_air_in = np.atleast_1d(np.asarray(mu_air_in, dtype=float)).ravel()
    mu_air_out = np.atleast_1d(np.asarray(mu_air_out, dtype=float)).ravel()
    r_air = reflection_modes(mu_air_out, mu_air_in, n_modes, n_i=1.0, n_t=n, **options)
    t_in = transmission_modes(mu_binder, mu_air_in, n_modes, n_i=1.0, n_t=n, **options)
    if mu_air_out.shape == mu_air_in.shape and np.array_equal(mu_air_out, mu_air_in):
        t_out = np.swapaxes(t_in, 1, 2) / (n * n)
    else:
        t_out = transmission_modes(mu_air_out, mu_binder, n_modes, n_i=n, n_t=1.0, **options)
    r_internal = reflection_modes(mu_binder, mu_binder, n_modes, n_i=n, n_t=1.0, **options)
    return RoughSurfaceModes(r_air=r_air, t_in=t_in, t_out=t_out, r_internal=r_internal, n=n)
