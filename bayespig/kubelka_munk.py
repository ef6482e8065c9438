"""Two-constant Kubelka-Munk theory with Saunderson's surface correction.

This is the industry's baseline for paint colour matching and bayespig's reference
method for tint prediction (issue 9). It describes a film by two coefficients per
wavelength: the Kubelka-Munk absorption ``K`` and scattering ``S`` [1/length]. Only the
products with the film thickness ``X`` enter the finite-layer formulas, so a film of
unknown thickness is described by ``K*X`` and ``S*X`` [1] (pass ``thickness=1``).

All reflectances in the Kubelka-Munk functions are *internal* (body) reflectances, i.e.
without the air/binder interface; :func:`saunderson_to_internal` and
:func:`saunderson_to_measured` convert between them and what an instrument measures.

Equations (``a = 1 + K/S``, ``b = sqrt(a^2 - 1)``; Kubelka 1948, eqs. for a layer over a
background of reflectance ``R_g``):

* opaque layer: ``R_inf = a - b = 1 + K/S - sqrt((K/S)^2 + 2 K/S)``, inverse
  ``K/S = (1 - R_inf)^2 / (2 R_inf)``;
* layer over ``R_g``: ``R = (1 - R_g (a - b coth(bSX))) / (a - R_g + b coth(bSX))``;
  equivalently ``R = R_0 + T^2 R_g / (1 - R_0 R_g)`` with the layer's own reflectance
  ``R_0 = sinh(bSX) / (a sinh(bSX) + b cosh(bSX))`` and transmittance
  ``T = b / (a sinh(bSX) + b cosh(bSX))``. Here they are evaluated as
  ``R_0 = SX tanhc(y) / D``, ``T = sech(y) / D`` with ``y = bSX = sqrt(KX (KX + 2 SX))``,
  ``D = (SX + KX) tanhc(y) + 1`` and ``tanhc(y) = tanh(y)/y``, which is the same
  expression divided by ``cosh(y)``, free of overflow for thick films and continuous
  in the limits ``S -> 0`` (``R_0 = 0``, ``T = exp(-KX)``) and ``K -> 0``
  (``R_0 = SX/(1+SX)``, ``T = 1/(1+SX)``);
* Saunderson (1942): ``R_m = k1 [specular included] + (1-k1)(1-k2) R_i / (1 - k2 R_i)``;
* two-constant mixing (Duncan): ``K_mix = sum_i c_i K_i``, ``S_mix = sum_i c_i S_i``.

Baseline for measured films (:func:`saunderson_constants`, :func:`calibrate_film`,
:func:`predict_measured`): a film measured over a dark and a light card is calibrated by
converting both measurements to internal reflectances with Saunderson's formula, then
solving the black/white equations for ``K*X`` and ``S*X`` (:func:`ks_from_black_white`),
or only ``K/S`` where the film hides the card. The cards enter as *internal* background
reflectances, i.e. as seen from inside the binder: :func:`saunderson_to_internal` of the
bare card measured in air. With ``k1 = r_F(theta_i)`` and ``k2`` the internal diffuse
reflectance this is exactly bayespig's substrate albedo ``r_s`` of a Lambertian card
under clear binder (paper section 3.4, eq. 9 integrated over the sphere;
:func:`bayespig.physics.substrate.substrate_albedo_from_air`), so both models see the same
cards. Mixtures of calibrated pigments are predicted with :func:`mix_K_S` and
:func:`predict_measured`; :mod:`bayespig.studies.tints` runs the full tint protocol.

Saunderson constants (documented defaults, both parameters; :func:`saunderson_constants`
gives the pair bayespig uses for a binder of index ``n`` at an incidence angle):

* ``k1`` -- specular (Fresnel) reflectance of the surface for the incident beam, at
  normal incidence ``((n-1)/(n+1))^2``: 0.04 for ``n = 1.5`` (:data:`SAUNDERSON_K1`,
  :func:`saunderson_k1`).
* specular component: an SCI measurement (sphere with the gloss trap closed) contains the
  surface reflection ``k1``, an SCE one (trap open; also 45/0) does not; every Saunderson
  function takes ``specular="included"|"excluded"`` without a default, since a wrong choice
  shifts dark colours by ``k1`` (the Revigo study decides it from the data:
  :func:`bayespig.studies.revigo.specular_evidence`).
* ``k2`` -- internal reflectance of the surface for diffuse light from inside,
  ``2 int_0^1 r_F(mu) mu dmu`` over internal directions (:func:`saunderson_k2`): 0.596
  for ``n = 1.5`` (Judd 1942), about 0.56 for the binder index 1.45 used elsewhere in
  bayespig. Colour-matching practice uses 0.4-0.6, often fitted; the default
  :data:`SAUNDERSON_K2` = 0.6 is the Fresnel value for ``n = 1.5`` rounded.

References
----------
P. Kubelka, F. Munk (1931), Ein Beitrag zur Optik der Farbanstriche, Z. Tech. Phys. 12,
593-601. P. Kubelka (1948), New contributions to the optics of intensely light-scattering
materials. Part I, J. Opt. Soc. Am. 38(5), 448-457. J. L. Saunderson (1942), Calculation
of the color of pigmented plastics, J. Opt. Soc. Am. 32(12), 727-736. D. B. Judd (1942),
Fresnel reflection of diffusely incident light, J. Res. NBS 29, 329-332. D. B. Judd,
G. Wyszecki, Color in Business, Science and Industry, 3rd ed. (Wiley 1975), ch. 3 and 7.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import integrate

from ._validation import broadcast, real_array, real_scalar

__all__ = [
    "SAUNDERSON_K1",
    "SAUNDERSON_K2",
    "KubelkaMunkFilm",
    "calibrate_film",
    "k_over_s_from_reflectance_infinity",
    "ks_from_black_white",
    "layer_reflectance",
    "layer_transmittance",
    "mix_K_S",
    "predict_measured",
    "reflectance_infinity",
    "saunderson_constants",
    "saunderson_k1",
    "saunderson_k2",
    "saunderson_to_internal",
    "saunderson_to_measured",
]

SAUNDERSON_K1 = 0.04
"""Default ``k1``: normal-incidence Fresnel reflectance of an ``n = 1.5`` surface [1]."""

SAUNDERSON_K2 = 0.6
"""Default ``k2``: internal diffuse reflectance of the surface (Fresnel, ``n = 1.5``) [1]."""

SPECULAR_MODES = ("excluded", "included")

_TANHC_SERIES_BELOW = 1e-4  # tanh(y)/y = 1 - y^2/3 + O(y^4): exact to double precision here
_CONSISTENCY_TOL = 1e-9  # rounding slack for the black/white consistency checks


# --------------------------------------------------------------------------- checks


def _as_array(value, argument, *, low=None, high=None, allow_inf=False):
    """``value`` as floats, or a TypeError/ValueError naming ``argument`` (NaN, bounds, types)."""
    return real_array(argument, value, low=low, high=high, allow_inf=allow_inf)


def _check_specular(specular):
    if not isinstance(specular, str) or specular not in SPECULAR_MODES:
        raise ValueError(
            f"specular={specular!r} is not valid; use one of {', '.join(map(repr, SPECULAR_MODES))}"
        )


def _check_k1_k2(k1, k2):
    k1 = _as_array(k1, "k1", low=0.0)
    k2 = _as_array(k2, "k2", low=0.0)
    if (k1 >= 1).any():
        raise ValueError("k1 must be < 1")
    if (k2 >= 1).any():
        raise ValueError("k2 must be < 1")
    return k1, k2


# --------------------------------------------------------------------------- opaque layer


def reflectance_infinity(k_over_s):
    """Reflectance of an opaque layer, ``R_inf = 1 + K/S - sqrt((K/S)^2 + 2 K/S)``.

    Evaluated as ``1 / (1 + K/S + sqrt((K/S)^2 + 2 K/S))`` (the same number, since
    ``(a - b)(a + b) = 1``), which has no cancellation for large ``K/S`` and gives 0 for
    ``K/S = inf``.

    Parameters
    ----------
    k_over_s : array_like
        Ratio of Kubelka-Munk absorption to scattering ``K/S`` [1], >= 0.

    Returns
    -------
    numpy.ndarray
        Internal reflectance of the opaque layer [1], in (0, 1].

    References
    ----------
    Kubelka & Munk (1931); Kubelka (1948), J. Opt. Soc. Am. 38, 448.
    """
    q = _as_array(k_over_s, "k_over_s", low=0.0, allow_inf=True)
    return 1.0 / (1.0 + q + np.sqrt(q * (q + 2.0)))


def k_over_s_from_reflectance_infinity(reflectance_infinity):
    """``K/S = (1 - R_inf)^2 / (2 R_inf)``, the inverse of :func:`reflectance_infinity`.

    Parameters
    ----------
    reflectance_infinity : array_like
        Internal reflectance of an opaque layer [1], in (0, 1].

    Returns
    -------
    numpy.ndarray
        ``K/S`` [1].
    """
    r = _as_array(reflectance_infinity, "reflectance_infinity", high=1.0)
    if (r <= 0).any():
        raise ValueError("reflectance_infinity must be > 0 (K/S is infinite at 0)")
    return (1.0 - r) ** 2 / (2.0 * r)


# --------------------------------------------------------------------------- finite layer


def _tanhc(y):
    """``tanh(y) / y`` for ``y >= 0`` (1 at 0, 0 at inf)."""
    y = np.asarray(y, dtype=float)
    small = y < _TANHC_SERIES_BELOW
    y_small = np.where(small, y, 0.0)
    y_safe = np.where(small, 1.0, y)
    return np.where(small, 1.0 - y_small**2 / 3.0, np.tanh(y_safe) / y_safe)


def _sech(y):
    e = np.exp(-y)
    return 2.0 * e / (1.0 + e * e)


def _layer_R0_T(K, S, thickness):
    """Reflectance over an ideal black and transmittance of a layer (broadcast)."""
    K = _as_array(K, "K", low=0.0)
    S = _as_array(S, "S", low=0.0)
    X = _as_array(thickness, "thickness", low=0.0, allow_inf=True)
    K, S, X = broadcast(K=K, S=S, thickness=X)
    opaque = np.isinf(X)
    if (opaque & (K == 0) & (S == 0)).any():
        raise ValueError("thickness=inf needs K + S > 0 (an empty infinite layer has no R_inf)")
    X_finite = np.where(opaque, 0.0, X)
    KX, SX = K * X_finite, S * X_finite
    y = np.sqrt(KX) * np.sqrt(KX + 2.0 * SX)  # b S X, without overflow in KX^2
    tc = _tanhc(y)
    D = (SX + KX) * tc + 1.0
    R0 = SX * tc / D
    T = _sech(y) / D
    # Opaque: R_0 = R_inf = S / (S + K + sqrt(K^2 + 2KS)), T = 0.
    denominator = np.where(opaque, S + K + np.sqrt(K) * np.sqrt(K + 2.0 * S), 1.0)
    R0 = np.where(opaque, S / denominator, R0)
    T = np.where(opaque, 0.0, T)
    return R0, T


def layer_reflectance(K, S, thickness=1.0, background_reflectance=0.0):
    """Internal reflectance of a Kubelka-Munk layer over a background (Kubelka 1948).

    ``R = (1 - R_g (a - b coth(bSX))) / (a - R_g + b coth(bSX))``, evaluated in the stable
    form ``R = R_0 + T^2 R_g / (1 - R_0 R_g)`` described in the module docstring; exact
    in the limits ``S -> 0`` (``R = R_g exp(-2KX)``), ``K -> 0`` and ``thickness -> inf``
    (``R = R_inf``).

    Parameters
    ----------
    K : array_like
        Kubelka-Munk absorption coefficient [1/length], >= 0.
    S : array_like
        Kubelka-Munk scattering coefficient [1/length], >= 0.
    thickness : array_like
        Layer thickness X [length, the inverse unit of K and S], >= 0, ``inf`` for opaque.
        With ``thickness=1`` the coefficients are the products ``K*X``, ``S*X`` [1].
    background_reflectance : array_like
        Reflectance ``R_g`` of the background under the layer [1], in [0, 1].

    Returns
    -------
    numpy.ndarray
        Internal reflectance [1]; all arguments broadcast.

    References
    ----------
    Kubelka (1948), J. Opt. Soc. Am. 38, 448; Judd & Wyszecki (1975), ch. 7.
    """
    R0, T = _layer_R0_T(K, S, thickness)
    Rg = _as_array(background_reflectance, "background_reflectance", low=0.0, high=1.0)
    R0, T, Rg = broadcast(K=R0, **{"S and thickness": T}, background_reflectance=Rg)
    # 1 - R0 Rg vanishes only for a non-absorbing opaque layer over a perfect white,
    # where T = 0 and the background term is 0.
    denominator = 1.0 - R0 * Rg
    seen = T > 0
    return R0 + np.where(seen, T * T * Rg / np.where(seen, denominator, 1.0), 0.0)


def layer_transmittance(K, S, thickness=1.0):
    """Diffuse transmittance of a Kubelka-Munk layer, ``T = b / (a sinh(bSX) + b cosh(bSX))``.

    Parameters
    ----------
    K, S, thickness : array_like
        As in :func:`layer_reflectance`.

    Returns
    -------
    numpy.ndarray
        Internal diffuse transmittance [1] (``exp(-KX)`` for ``S = 0``, ``1/(1+SX)`` for
        ``K = 0``, 0 for ``thickness = inf``).
    """
    return _layer_R0_T(K, S, thickness)[1]


# --------------------------------------------------------------------------- mixtures


def mix_K_S(concentrations, K, S):
    """Two-constant Kubelka-Munk mixing: ``K_mix = sum_i c_i K_i``, ``S_mix = sum_i c_i S_i``.

    Parameters
    ----------
    concentrations : array_like, shape (..., n_components)
        Concentrations [any consistent unit, e.g. mass or volume fraction], >= 0. They
        need not sum to 1: the scale cancels in ``K/S`` (opaque films) but sets ``K*X``,
        ``S*X`` of finite films.
    K, S : array_like, shape (n_components, ...)
        Unit-concentration coefficients of each component (e.g. per wavelength).

    Returns
    -------
    tuple of numpy.ndarray
        ``(K_mix, S_mix)``, shape ``concentrations.shape[:-1] + K.shape[1:]``.

    References
    ----------
    D. R. Duncan (1940), Proc. Phys. Soc. 52, 390; Judd & Wyszecki (1975), ch. 7.
    """
    c = _as_array(concentrations, "concentrations", low=0.0)
    K = _as_array(K, "K", low=0.0)
    S = _as_array(S, "S", low=0.0)
    if c.ndim == 0:
        raise ValueError("concentrations must have a last axis over components")
    for name, v in (("K", K), ("S", S)):
        if v.ndim == 0 or v.shape[0] != c.shape[-1]:
            raise ValueError(
                f"{name} has shape {v.shape}; its first axis must match the "
                f"{c.shape[-1]} components of concentrations"
            )
    return np.tensordot(c, K, axes=([-1], [0])), np.tensordot(c, S, axes=([-1], [0]))


# --------------------------------------------------------------------------- Saunderson


def saunderson_to_measured(internal_reflectance, k1=SAUNDERSON_K1, k2=SAUNDERSON_K2, *, specular):
    """Measured reflectance from internal reflectance (Saunderson 1942).

    ``R_m = k1 [if specular="included"] + (1 - k1)(1 - k2) R_i / (1 - k2 R_i)``.

    Parameters
    ----------
    internal_reflectance : array_like
        Kubelka-Munk (body) reflectance ``R_i`` [1], in [0, 1].
    k1 : array_like
        Specular reflectance of the surface for the incident beam [1] (default 0.04,
        ``n = 1.5`` at normal incidence; see :func:`saunderson_k1`).
    k2 : array_like
        Internal diffuse reflectance of the surface [1] (default 0.6; see
        :func:`saunderson_k2`).
    specular : {"included", "excluded"}
        Whether the instrument includes the specular component (SCI, sphere 8/d with
        gloss trap closed) or excludes it (SCE, trap open; also 45/0). Required: a wrong
        choice shifts dark colours by about ``k1``.

    Returns
    -------
    numpy.ndarray
        Measured reflectance [1].
    """
    _check_specular(specular)
    k1, k2 = _check_k1_k2(k1, k2)
    Ri = _as_array(internal_reflectance, "internal_reflectance", low=0.0, high=1.0)
    Ri, k1, k2 = broadcast(internal_reflectance=Ri, k1=k1, k2=k2)
    diffuse = (1.0 - k1) * (1.0 - k2) * Ri / (1.0 - k2 * Ri)
    return diffuse + k1 if specular == "included" else diffuse


def saunderson_to_internal(measured_reflectance, k1=SAUNDERSON_K1, k2=SAUNDERSON_K2, *, specular):
    """Internal reflectance from measured reflectance, the inverse of Saunderson's formula.

    ``R_i = R' / ((1 - k1)(1 - k2) + k2 R')`` with ``R' = R_m - k1`` for specular
    included and ``R' = R_m`` for specular excluded.

    Parameters
    ----------
    measured_reflectance : array_like
        Measured reflectance factor [1], in [0, 1] (and >= ``k1`` if specular included).
    k1, k2, specular
        As in :func:`saunderson_to_measured`.

    Returns
    -------
    numpy.ndarray
        Internal reflectance [1] (can slightly exceed 1 for an SCE value near 1, which
        the model cannot produce).
    """
    _check_specular(specular)
    k1, k2 = _check_k1_k2(k1, k2)
    Rm = _as_array(measured_reflectance, "measured_reflectance", low=0.0, high=1.0)
    Rm, k1, k2 = broadcast(measured_reflectance=Rm, k1=k1, k2=k2)
    diffuse = Rm - k1 if specular == "included" else Rm
    if (diffuse < 0).any():
        raise ValueError(
            "measured_reflectance is below k1 with specular='included'; the specular part "
            "alone is k1 -- was the specular component excluded?"
        )
    return diffuse / ((1.0 - k1) * (1.0 - k2) + k2 * diffuse)


def _fresnel_unpolarised(cos_i, n_ratio):
    """Unpolarised Fresnel reflectance for incidence cosine ``cos_i``, ``n_ratio = n2/n1``."""
    sin_t2 = (1.0 - cos_i**2) / n_ratio**2
    if sin_t2 >= 1.0:
        return 1.0  # total internal reflection
    cos_t = np.sqrt(1.0 - sin_t2)
    r_s = (cos_i - n_ratio * cos_t) / (cos_i + n_ratio * cos_t)
    r_p = (n_ratio * cos_i - cos_t) / (n_ratio * cos_i + cos_t)
    return 0.5 * (r_s**2 + r_p**2)


def saunderson_k1(refractive_index):
    """Normal-incidence Fresnel reflectance ``k1 = ((n - 1)/(n + 1))^2``.

    Parameters
    ----------
    refractive_index : float
        Refractive index ``n`` of the binder [1], > 0 (relative to air).

    Returns
    -------
    float
        ``k1`` [1]; 0.04 for ``n = 1.5``. For an 8/d instrument (8 degree incidence) the
        value differs by less than 1e-4.
    """
    n = real_scalar("refractive_index", refractive_index)
    if n <= 0:
        raise ValueError("refractive_index must be > 0")
    return ((n - 1.0) / (n + 1.0)) ** 2


def saunderson_k2(refractive_index):
    """Internal diffuse reflectance ``k2 = 2 int_0^1 r_F(mu) mu dmu`` of a smooth surface.

    ``mu`` is the cosine of the angle inside the binder; light beyond the critical angle
    (``mu < sqrt(1 - 1/n^2)``) is totally reflected. Equals ``1 - (1 - r_e)/n^2`` with
    ``r_e`` the external diffuse reflectance (Judd 1942).

    Parameters
    ----------
    refractive_index : float
        Refractive index ``n`` of the binder [1], >= 1.

    Returns
    -------
    float
        ``k2`` [1]; 0.596 for ``n = 1.5``, about 0.56 for ``n = 1.45``.
    """
    n = real_scalar("refractive_index", refractive_index)
    if n < 1.0:
        raise ValueError("refractive_index must be >= 1 (binder denser than air)")
    mu_critical = np.sqrt(1.0 - 1.0 / n**2)
    # Inside the binder light goes to air: n2/n1 = 1/n. Beyond the critical angle r_F = 1.
    partial, _ = integrate.quad(
        lambda mu: _fresnel_unpolarised(mu, 1.0 / n) * mu, mu_critical, 1.0, epsabs=1e-13
    )
    return mu_critical**2 + 2.0 * partial


# --------------------------------------------------------------------------- calibration


def _artanhc(z):
    """``artanh(z) / z`` for ``0 <= z < 1`` (1 at 0)."""
    z = np.asarray(z, dtype=float)
    small = z < _TANHC_SERIES_BELOW
    z_small = np.where(small, z, 0.0)
    z_safe = np.where(small, 0.5, z)
    return np.where(small, 1.0 + z_small**2 / 3.0, np.arctanh(z_safe) / z_safe)


def ks_from_black_white(
    reflectance_over_black,
    reflectance_over_white,
    background_black,
    background_white,
    *,
    clip_to_physical=False,
):
    """``K*X`` and ``S*X`` of a film from its reflectance over two backgrounds.

    The classic black/white-background calibration (Kubelka 1948; Judd & Wyszecki). With
    ``R_1, R_2`` the internal reflectances of the same film over backgrounds ``g_1, g_2``,
    the Kubelka solution gives ``b coth(bSX) = (1 - a (R + g) + R g) / (R - g)`` for both,
    and equating them yields

    ``a = [(1 + g_1 g_2)(R_1 - R_2) - (1 + R_1 R_2)(g_1 - g_2)] / [2 (R_1 g_2 - R_2 g_1)]``,

    which for an ideal black (``g_1 = 0``) is the textbook
    ``a = (R_w + (R_b - R_w + g_w) / (R_b g_w)) / 2``. Then ``b = sqrt(a^2 - 1)``,
    ``SX = arcoth(b coth(bSX) / b) / b`` (continuous at ``b -> 0``) and ``KX = SX (a - 1)``.
    The film thickness need not be known: it is absorbed in ``K*X`` and ``S*X``.

    Parameters
    ----------
    reflectance_over_black, reflectance_over_white : array_like
        Internal reflectance [1] of the film over the dark and the light background (apply
        :func:`saunderson_to_internal` to measured values first).
    background_black, background_white : array_like
        Reflectance [1] of the dark and light background as seen by the film
        (``background_black < background_white``); all four arguments broadcast, e.g.
        per wavelength.
    clip_to_physical : bool
        Measurement noise can put a nearly non-absorbing film at ``K < 0`` or a nearly
        opaque film beyond opacity. By default this raises ValueError; with ``True`` such
        entries are clipped to ``K = 0`` or to the opaque limit (``K*X = S*X = inf``, only
        ``K/S`` determined).

    Returns
    -------
    tuple of numpy.ndarray
        ``(KX, SX)`` [1]: absorption and scattering per film, i.e. ``K*X`` and ``S*X``.
    """
    R1 = _as_array(reflectance_over_black, "reflectance_over_black", low=0.0, high=1.0)
    R2 = _as_array(reflectance_over_white, "reflectance_over_white", low=0.0, high=1.0)
    g1 = _as_array(background_black, "background_black", low=0.0, high=1.0)
    g2 = _as_array(background_white, "background_white", low=0.0, high=1.0)
    R1, R2, g1, g2 = broadcast(
        reflectance_over_black=R1, reflectance_over_white=R2, background_black=g1, background_white=g2
    )
    if (g2 <= g1).any():
        raise ValueError("background_white must be brighter than background_black")
    opaque = R1 >= R2  # the film hides the background (noise can invert the order)
    if opaque.any() and not clip_to_physical:
        raise ValueError(
            f"{np.count_nonzero(opaque)} entries of reflectance_over_white do not exceed "
            "reflectance_over_black: the film is opaque there (use "
            "k_over_s_from_reflectance_infinity) or pass clip_to_physical=True"
        )
    denominator = 2.0 * (R1 * g2 - R2 * g1)
    if (~opaque & (denominator <= 0)).any():
        raise ValueError(
            "reflectance_over_black/white imply no or negative scattering (S <= 0): the "
            "film over black is, relative to its background, no brighter than over white"
        )
    denominator = np.where(opaque, 1.0, denominator)
    a = ((1.0 + g1 * g2) * (R1 - R2) - (1.0 + R1 * R2) * (g1 - g2)) / denominator
    negative_K = ~opaque & (a < 1.0 - _CONSISTENCY_TOL)
    if negative_K.any() and not clip_to_physical:
        raise ValueError(
            f"{np.count_nonzero(negative_K)} entries of reflectance_over_black/white imply "
            "negative absorption (K < 0); check the data or pass clip_to_physical=True"
        )
    a = np.maximum(a, 1.0)
    b = np.sqrt(a * a - 1.0)
    # b coth(bSX) from whichever background is further from the film's reflectance.
    use_first = np.abs(R1 - g1) >= np.abs(R2 - g2)
    R = np.where(use_first, R1, R2)
    g = np.where(use_first, g1, g2)
    b_coth = (1.0 - a * (R + g) + R * g) / np.where(R == g, 1.0, R - g)
    beyond = ~opaque & ((b_coth <= 0) | (b > b_coth * (1.0 + _CONSISTENCY_TOL)))
    if beyond.any() and not clip_to_physical:
        raise ValueError(
            f"{np.count_nonzero(beyond)} entries of reflectance_over_black/white imply a "
            "film beyond opacity; check the data or pass clip_to_physical=True"
        )
    opaque |= (b_coth <= 0) | (b >= b_coth)
    z = np.where(opaque, 0.0, b / np.where(opaque, 1.0, b_coth))  # tanh(bSX), in [0, 1)
    SX = np.where(opaque, np.inf, _artanhc(z) / np.where(opaque, 1.0, b_coth))
    KX = np.where(opaque, np.inf, np.where(opaque, 1.0, SX) * (a - 1.0))
    return KX, SX


# --------------------------------------------------------------------------- baseline


def saunderson_constants(refractive_index=1.45, theta_i=8.0):
    """Saunderson ``(k1, k2)`` of a smooth binder surface of index ``n``.

    ``k1`` is the unpolarised Fresnel reflectance for the instrument's incidence angle
    (``r_F(theta_i)``: 0.03374 for ``n = 1.45`` at 8 degrees, 0.03374 at 0 degrees too);
    ``k2`` the internal diffuse reflectance :func:`saunderson_k2` (0.5645 for
    ``n = 1.45``). These are the same two numbers bayespig's radiative-transfer model uses
    for the air/binder interface (paper appendix A1), so the two models see the same
    surface; colour-matching practice often fits ``k2`` instead (0.4-0.6).

    Parameters
    ----------
    refractive_index : float
        Binder refractive index ``n`` [1], >= 1 (paper section 2: 1.45).
    theta_i : float
        Incidence angle in air [deg], in [0, 90) (8 for an 8/d sphere).

    Returns
    -------
    tuple of float
        ``(k1, k2)`` [1].
    """
    from .physics.fresnel import fresnel_reflectance

    n = real_scalar("refractive_index", refractive_index)
    if n < 1.0:
        raise ValueError("refractive_index must be >= 1 (binder denser than air)")
    theta = real_scalar("theta_i", theta_i)
    if not 0.0 <= theta < 90.0:
        raise ValueError(f"theta_i must lie in [0, 90) degrees, got {theta:g}")
    k1 = float(fresnel_reflectance(np.cos(np.radians(theta)), 1.0, n))
    return k1, saunderson_k2(n)


@dataclass(frozen=True)
class KubelkaMunkFilm:
    """A film calibrated over black and white (per wavelength).

    Attributes
    ----------
    KX, SX : numpy.ndarray
        Absorption and scattering times thickness [1]; ``inf`` where the film hides the
        card (opaque: only ``K/S`` is known).
    k_over_s : numpy.ndarray
        ``K/S`` [1], finite everywhere (from ``R_inf`` where opaque).
    """

    KX: np.ndarray
    SX: np.ndarray
    k_over_s: np.ndarray

    @property
    def opaque(self):
        """Boolean array: the film hides the card (``K*X``, ``S*X`` unknown)."""
        return np.isinf(self.SX)


def calibrate_film(
    measured_over_black,
    measured_over_white,
    background_black,
    background_white,
    *,
    specular,
    k1=SAUNDERSON_K1,
    k2=SAUNDERSON_K2,
):
    """Kubelka-Munk ``K*X``, ``S*X`` and ``K/S`` of a film measured over two cards.

    Both measurements are converted to internal reflectances (:func:`saunderson_to_internal`)
    and solved by :func:`ks_from_black_white` with ``clip_to_physical=True``: noise that
    implies ``K < 0`` gives ``K = 0``; a film that hides the card gives ``KX = SX = inf``
    and ``K/S`` from the mean internal reflectance as ``R_inf``
    (:func:`k_over_s_from_reflectance_infinity`).

    Parameters
    ----------
    measured_over_black, measured_over_white : array_like
        Reflectance of the film over the dark and the light card as measured [1].
    background_black, background_white : array_like
        Internal reflectance of the cards as seen from the binder [1], e.g.
        ``saunderson_to_internal(card_in_air, k1, k2, specular=...)`` (equal to bayespig's
        ``r_s`` of the card, see the module docstring).
    specular : {"included", "excluded"}
        SCI or SCE measurements.
    k1, k2 : float
        Saunderson constants (:func:`saunderson_constants`).

    Returns
    -------
    KubelkaMunkFilm
    """
    R_b = saunderson_to_internal(measured_over_black, k1, k2, specular=specular)
    R_w = saunderson_to_internal(measured_over_white, k1, k2, specular=specular)
    R_b, R_w = np.minimum(R_b, 1.0), np.minimum(R_w, 1.0)
    KX, SX = ks_from_black_white(R_b, R_w, background_black, background_white, clip_to_physical=True)
    opaque = np.isinf(SX)
    R_inf = np.clip(0.5 * (R_b + R_w), 1e-12, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(opaque, 0.0, KX / np.where(opaque | (SX == 0), 1.0, SX))
    k_over_s = np.where(opaque, k_over_s_from_reflectance_infinity(R_inf), ratio)
    return KubelkaMunkFilm(KX, SX, k_over_s)


def predict_measured(
    KX, SX, background_reflectance, *, specular, k1=SAUNDERSON_K1, k2=SAUNDERSON_K2
):
    """Measured reflectance of a Kubelka-Munk film over a background.

    ``R_m = Saunderson(layer_reflectance(KX, SX, 1, R_g))`` (Kubelka 1948; Saunderson 1942).

    Parameters
    ----------
    KX, SX : array_like
        Absorption and scattering times thickness [1], finite (for an opaque film use
        ``saunderson_to_measured(reflectance_infinity(K/S), ...)``).
    background_reflectance : array_like
        Internal reflectance of the background seen from the binder [1].
    specular, k1, k2
        As in :func:`saunderson_to_measured`.

    Returns
    -------
    numpy.ndarray
        Measured reflectance [1]; arguments broadcast.
    """
    KX = _as_array(KX, "KX", low=0.0)
    SX = _as_array(SX, "SX", low=0.0)
    R_i = layer_reflectance(KX, SX, 1.0, background_reflectance)
    return saunderson_to_measured(np.minimum(R_i, 1.0), k1, k2, specular=specular)
