"""The substrate under the paint: the substrate law (eq. 3) and clear-binder substrates (eq. 9).

A Lambertian substrate of albedo ``r_s`` *seen from the binder* enters the BRDF
analytically (paper eq. 3): ``f(v, u; r_s) = f(v, u; 0) + r_s T_down(v) T_up(u) / (1 - r_s R_up)``.
A bare substrate can only be measured from air; modelled as a Lambertian surface
under a clear binder layer (section 3.4, eq. 9) its albedo from the binder follows
by inverting eq. (9).
"""

from __future__ import annotations

import numpy as np

from .forward import (
    _real_array,
    _validate_angle,
    binder_index,
    surface_terms,
    validate_layer_arguments,
)
from .fresnel import fresnel_reflectance, internal_diffuse_reflectance

__all__ = [
    "clear_binder_brdf",
    "clear_binder_reflectance",
    "substrate_albedo_from_air",
    "substrate_law_terms",
]


def substrate_law_terms(theta_i, theta_o, delta_phi, *, a, tau, g=0.0, n=1.45):
    """The quantities of the substrate law, eq. (3), at one geometry.

    Parameters
    ----------
    theta_i, theta_o, delta_phi : float
        Incidence and viewing angles in air and their azimuth difference [deg]
        (``delta_phi = 180`` on the specular side).
    a, tau, g : float
        Relative absorption [-], optical thickness [-] and phase-function parameter.
    n : float
        Refractive index of the binder [-].

    Returns
    -------
    f0 : float
        BRDF over a black substrate [1/sr].
    t_down : float
        Irradiance reaching the substrate per unit incident irradiance [-].
    t_up : float
        Air radiance per unit exitance leaving the substrate [1/sr].
    r_up : float
        Fraction of the substrate's exitance returned to it by layer and surface [-].

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), eq. (3).
    """
    validate_layer_arguments(a=a, tau=tau, g=g, r_s=0.0, n=n)
    terms = surface_terms([theta_i], [theta_o], a=[a], tau=[tau], g=float(g), n=n)
    f0 = terms.brdf(np.full((1, 1, 1), delta_phi), [0.0])[0, 0, 0]
    return float(f0), float(terms.t_down[0, 0]), float(terms.t_up[0, 0]), float(terms.r_up[0])


def _clear_binder_factor(n):
    return 1.0 / (np.pi * n * n)


def clear_binder_brdf(theta_i, theta_o, *, r_s, n=1.45):
    """BRDF from air of a Lambertian substrate under a clear binder, eq. (9).

    ``f = t_F(v) t_F(u) r_s / (pi n^2 (1 - r_s r_i))`` with ``r_i = 2 int_0^1 r_F(mu) mu dmu``
    the internal diffuse reflectance of the surface (the printed eq. 9 lacks the
    azimuth integral in the denominator; DESIGN.md).

    Parameters
    ----------
    theta_i, theta_o : array_like
        Incidence and viewing angles in air [deg].
    r_s : array_like
        Albedo of the substrate seen from the binder [-].
    n : float
        Refractive index of the binder [-].

    Returns
    -------
    numpy.ndarray
        BRDF [1/sr], surface specular reflection excluded.
    """
    validate_layer_arguments(a=0.0, tau=0.0, g=0.0, r_s=r_s, n=n)
    t_i = 1.0 - fresnel_reflectance(np.cos(np.radians(_validate_angle("theta_i", theta_i))), 1.0, n)
    t_o = 1.0 - fresnel_reflectance(np.cos(np.radians(_validate_angle("theta_o", theta_o))), 1.0, n)
    r_s = np.asarray(r_s, dtype=float)
    return t_i * t_o * _clear_binder_factor(n) * r_s / (1.0 - r_s * internal_diffuse_reflectance(n))


def clear_binder_reflectance(theta_i, *, r_s, n=1.45, specular="excluded"):
    """Directional–hemispherical reflectance of a Lambertian substrate under a clear binder.

    Eq. (9) integrated over the viewing hemisphere:
    ``R = t_F(v) r_s (1 - r_i) / (1 - r_s r_i)`` (+ ``r_F(v)`` when the specular
    component is included).

    Parameters
    ----------
    theta_i : array_like
        Incidence angle in air [deg] (8 for an 8°/d sphere).
    r_s : array_like
        Albedo of the substrate seen from the binder [-].
    n : float
        Refractive index of the binder [-].
    specular : {"excluded", "included"}
        SCE or SCI.

    Returns
    -------
    numpy.ndarray
        Reflectance [-].
    """
    validate_layer_arguments(a=0.0, tau=0.0, g=0.0, r_s=r_s, n=n)
    r_F = fresnel_reflectance(np.cos(np.radians(_validate_angle("theta_i", theta_i))), 1.0, n)
    r_i = internal_diffuse_reflectance(n)
    r_s = np.asarray(r_s, dtype=float)
    value = (1.0 - r_F) * r_s * (1.0 - r_i) / (1.0 - r_s * r_i)
    if specular == "included":
        return value + r_F
    if specular != "excluded":
        raise ValueError(f"specular must be 'excluded' or 'included', got {specular!r}")
    return value


def substrate_albedo_from_air(reflectance_in_air, *, n=1.45, kind="hemispherical", theta_i=8.0,
                              theta_o=None, specular="excluded"):
    """Albedo seen from the binder of a substrate measured from air (section 3.4).

    Inverts eq. (9) (``kind="brdf"``) or its hemispherical integral
    (``kind="hemispherical"``): both have the form ``x = r_s A / (1 - r_s r_i)``,
    so ``r_s = x / (A + x r_i)``.

    Parameters
    ----------
    reflectance_in_air : array_like
        Measured reflectance of the bare substrate [-] (BRDF in 1/sr for ``kind="brdf"``).
    n : float
        Refractive index of the binder assumed over the substrate [-].
    kind : {"hemispherical", "brdf"}
        What was measured.
    theta_i, theta_o : float
        Geometry in air [deg]; ``theta_o`` only for ``kind="brdf"``.
    specular : {"excluded", "included"}
        For hemispherical data: whether the surface reflection is in the measurement.

    Returns
    -------
    numpy.ndarray
        ``r_s`` [-], clipped to [0, 1] only if within 1e-9 of it; otherwise a
        value outside raises ``ValueError``.
    """
    x = _real_array("reflectance_in_air", reflectance_in_air)
    if np.isnan(x).any():
        raise ValueError("reflectance_in_air must not be NaN")
    n = binder_index(n)
    r_i = internal_diffuse_reflectance(n)
    r_F = fresnel_reflectance(np.cos(np.radians(_validate_angle("theta_i", theta_i))), 1.0, n)
    if kind == "hemispherical":
        if specular == "included":
            x = x - r_F
        elif specular != "excluded":
            raise ValueError(f"specular must be 'excluded' or 'included', got {specular!r}")
        A = (1.0 - r_F) * (1.0 - r_i)
    elif kind == "brdf":
        if theta_o is None:
            raise ValueError("theta_o is required for kind='brdf'")
        t_o = 1.0 - fresnel_reflectance(np.cos(np.radians(_validate_angle("theta_o", theta_o))), 1.0, n)
        A = (1.0 - r_F) * t_o * _clear_binder_factor(n)
    else:
        raise ValueError(f"kind must be 'hemispherical' or 'brdf', got {kind!r}")
    if (x < 0).any():
        raise ValueError("reflectance_in_air is below what the surface reflection alone gives")
    r_s = x / (A + x * r_i)
    if (r_s > 1.0 + 1e-9).any():
        raise ValueError("reflectance_in_air is higher than a white (r_s = 1) substrate under binder gives")
    return np.minimum(r_s, 1.0)
