"""Fresnel reflection and refraction at the smooth air/binder interface.

All functions are unpolarised and take direction *cosines* measured from the
surface normal. ``n_i`` is the refractive index of the medium the light comes
from, ``n_t`` that of the medium it enters.

References
----------
Born & Wolf, *Principles of Optics*, section 1.5.
Ershov, Voloboy & Pozdnyakov (2023), appendix A1 (``t_F``, ``r_F``, eq. 8-9).
"""

from __future__ import annotations

import numpy as np
from scipy import integrate

__all__ = [
    "critical_cosine",
    "fresnel_reflectance",
    "internal_diffuse_reflectance",
    "normal_transmittance",
    "refracted_cosine",
]


def refracted_cosine(mu_i, n_i, n_t):
    """Cosine of the refracted direction (Snell's law).

    Parameters
    ----------
    mu_i : array_like
        Cosine of the incidence angle in the medium of index ``n_i`` [-].
    n_i, n_t : float
        Refractive indices of the incident and transmitting media [-].

    Returns
    -------
    numpy.ndarray
        Cosine of the refraction angle in the medium ``n_t`` [-]; 0 where the
        light is totally internally reflected.
    """
    mu_i = np.asarray(mu_i, dtype=float)
    sin2_t = (n_i / n_t) ** 2 * (1.0 - mu_i**2)
    return np.sqrt(np.clip(1.0 - sin2_t, 0.0, None))


def fresnel_reflectance(mu_i, n_i, n_t):
    """Unpolarised Fresnel reflectance of a smooth interface.

    Parameters
    ----------
    mu_i : array_like
        Cosine of the incidence angle in the medium of index ``n_i`` [-].
    n_i, n_t : float
        Refractive indices of the incident and transmitting media [-].

    Returns
    -------
    numpy.ndarray
        Reflectance ``r_F`` [-]; 1 beyond the critical angle.
    """
    mu_i = np.clip(np.asarray(mu_i, dtype=float), 0.0, 1.0)
    if n_i == n_t:
        return np.zeros_like(mu_i)
    mu_t = refracted_cosine(mu_i, n_i, n_t)
    with np.errstate(divide="ignore", invalid="ignore"):
        r_s = (n_i * mu_i - n_t * mu_t) / (n_i * mu_i + n_t * mu_t)
        r_p = (n_i * mu_t - n_t * mu_i) / (n_i * mu_t + n_t * mu_i)
        r = 0.5 * (r_s**2 + r_p**2)
    tir = (mu_t == 0.0) | (mu_i == 0.0)
    return np.where(tir, 1.0, r)


def critical_cosine(n):
    """Cosine of the critical angle inside the binder, ``sqrt(1 - 1/n^2)``.

    Parameters
    ----------
    n : float
        Refractive index of the binder relative to air [-].

    Returns
    -------
    float
        ``mu_c`` [-]; 0 when ``n <= 1`` (no total internal reflection).
    """
    return float(np.sqrt(1.0 - 1.0 / n**2)) if n > 1.0 else 0.0


def normal_transmittance(n):
    """Fresnel transmittance ``t_F = 1 - ((n - 1)/(n + 1))^2`` at normal incidence [-]."""
    return 1.0 - ((n - 1.0) / (n + 1.0)) ** 2


def internal_diffuse_reflectance(n):
    """Diffuse reflectance of the interface seen from inside the binder.

    ``2 * int_0^1 r_F(mu) mu dmu`` for light in the binder (index ``n``)
    hitting air: the quantity in the denominator of eq. (9) once the azimuth
    integral is done (DESIGN.md, erratum of eq. 9).

    Parameters
    ----------
    n : float
        Refractive index of the binder [-].

    Returns
    -------
    float
        Internal diffuse reflectance [-] (about 0.5645 for ``n = 1.45``).
    """
    mu_c = critical_cosine(n)
    # below the critical cosine everything is reflected: 2 * int_0^mu_c mu dmu = mu_c^2.
    # Above it, r_F ~ sqrt(mu - mu_c); the substitution mu = mu_c + (1 - mu_c) s^2 removes it.

    def integrand(s):
        mu = mu_c + (1.0 - mu_c) * s * s
        return 2.0 * mu * fresnel_reflectance(mu, n, 1.0) * 2.0 * (1.0 - mu_c) * s

    upper, _ = integrate.quad(integrand, 0.0, 1.0, epsabs=1e-14, epsrel=1e-13)
    return mu_c**2 + upper
