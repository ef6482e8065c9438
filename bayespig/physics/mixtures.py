"""Pigment mixtures: the mixing rules of section 2 and the concentrations of appendix A2.

A paint layer of several pigments is one medium whose coefficients are concentration-weighted
sums over the pigments ``i`` (paper section 2):

* extinction ``k_ext = sum_i D_i sigma_ext_i`` (so ``tau = H k_ext``),
* absorption ``k_abs = sum_i D_i sigma_abs_i``, hence the relative absorption
  ``a = sum_i a_i D_i sigma_ext_i / sum_i D_i sigma_ext_i`` with ``a_i = sigma_abs_i / sigma_ext_i``,
* phase function weighted by the scattering cross-sections ``D_i sigma_sc_i``
  (``sigma_sc = (1 - a) sigma_ext``); for Henyey-Greenstein components the mixture's first
  moment is ``g = sum_i g_i D_i sigma_sc_i / sum_i D_i sigma_sc_i`` (exact only when all
  ``g_i`` are equal, the paper's usual case).

Only the products ``D_i sigma_ext_i`` matter, so each pigment's concentration may carry an
arbitrary constant factor (``C_pp / mu``, appendix A2) that its extinction absorbs.

References
----------
Ershov, Voloboy & Pozdnyakov (2023), section 2 (mixtures) and appendix A2 (concentrations).
"""

from __future__ import annotations

import numpy as np

__all__ = ["concentrations_from_mass_fractions", "mixture_properties"]


def _array(value, name, *, positive=False):
    v = np.asarray(value, dtype=float)
    if not np.isfinite(v).all():
        raise ValueError(f"{name} must be finite")
    if (v <= 0 if positive else v < 0).any():
        raise ValueError(f"{name} must be {'> 0' if positive else '>= 0'}, got minimum {v.min():.6g}")
    return v


def concentrations_from_mass_fractions(
    mass_fractions,
    *,
    paste_density=1.0,
    paste_drying=1.0,
    binder_density=1.0,
    binder_drying=1.0,
    pigment_scale=1.0,
):
    """Pigment concentrations ``D_i`` in dry paint from the wet mass fractions of pastes (appendix A2).

    ``D_i = (C_pp_i / mu_i) q_i W_i / (q_b / rho_b + sum_j (q_j / rho_j - q_b / rho_b) W_j)``,

    with ``W_j`` the wet mass fraction of pigment paste ``j`` (``1 - sum_j W_j`` is added
    binder), ``q = m_dry / M_wet`` the drying coefficients, ``rho`` the dry densities and
    ``C_pp / mu`` a per-pigment constant (``pigment_scale``, default 1) that extinction
    absorbs. The paper prints ``q_binder`` in the numerator; the derivation from its eqs.
    (10)-(12) gives the paste's own ``q_i``, used here. With the defaults (equal densities,
    no drying loss) ``D_i = W_i``: concentrations proportional to mass fractions.

    Parameters
    ----------
    mass_fractions : array_like, shape (..., n_pigments)
        Wet mass fractions of the pigment pastes [1], >= 0, summing to <= 1 (mass ratios
        such as Revigo's ``10-90`` must be normalised first).
    paste_density, paste_drying, pigment_scale : array_like, shape (n_pigments,) or scalar
        Dry density of each paste [any unit, consistent with ``binder_density``], its
        drying coefficient ``q`` [1], and ``C_pp / mu`` [any unit].
    binder_density, binder_drying : float
        The same for added binder.

    Returns
    -------
    numpy.ndarray, shape (..., n_pigments)
        ``D_i`` [pigment_scale per unit volume, relative].

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), appendix A2, eqs. (10)-(12).
    """
    W = _array(mass_fractions, "mass_fractions")
    if W.ndim == 0:
        raise ValueError("mass_fractions must have a last axis over pigments")
    if (W.sum(axis=-1) > 1.0 + 1e-9).any():
        raise ValueError("mass_fractions must sum to <= 1 (normalise mass ratios first)")
    rho = _array(paste_density, "paste_density", positive=True)
    q = _array(paste_drying, "paste_drying", positive=True)
    scale = _array(pigment_scale, "pigment_scale", positive=True)
    rho_b = float(_array(binder_density, "binder_density", positive=True))
    q_b = float(_array(binder_drying, "binder_drying", positive=True))
    binder_volume = q_b / rho_b
    denominator = binder_volume + ((q / rho - binder_volume) * W).sum(axis=-1, keepdims=True)
    return scale * q * W / denominator


def mixture_properties(concentrations, relative_absorption, extinction, g=None):
    """Relative absorption, extinction per unit thickness (and ``g``) of a pigment mixture (section 2).

    Parameters
    ----------
    concentrations : array_like, shape (..., n_pigments)
        ``D_i`` [1/volume, any consistent scale], >= 0, not all zero.
    relative_absorption : array_like, shape (n_pigments, ...)
        ``a_i = sigma_abs_i / sigma_ext_i`` of each pigment [1] (e.g. per wavelength).
    extinction : array_like, shape (n_pigments, ...)
        ``sigma_ext_i`` [area, or 1/length per unit concentration], >= 0.
    g : array_like, shape (n_pigments, ...), optional
        Henyey-Greenstein parameter of each pigment [1].

    Returns
    -------
    tuple
        ``(a, k_ext)`` or ``(a, k_ext, g)`` of the mixture, each of shape
        ``concentrations.shape[:-1] + extinction.shape[1:]``: ``a`` [1], ``k_ext`` [1/length],
        so that a film of thickness ``H`` has ``tau = H k_ext``.

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), section 2.
    """
    D = _array(concentrations, "concentrations")
    a = _array(relative_absorption, "relative_absorption")
    sigma = _array(extinction, "extinction")
    if D.ndim == 0:
        raise ValueError("concentrations must have a last axis over pigments")
    if (a > 1).any():
        raise ValueError("relative_absorption must be <= 1")
    for name, v in (("relative_absorption", a), ("extinction", sigma)):
        if v.ndim == 0 or v.shape[0] != D.shape[-1]:
            raise ValueError(f"{name} has shape {v.shape}; its first axis must match the "
                             f"{D.shape[-1]} pigments of concentrations")
    k_ext = np.tensordot(D, sigma, axes=([-1], [0]))
    k_abs = np.tensordot(D, a * sigma, axes=([-1], [0]))
    if (k_ext <= 0).any():
        raise ValueError("the mixture has no extinction (all concentrations or extinctions are 0)")
    a_mix = np.minimum(k_abs / k_ext, 1.0)
    if g is None:
        return a_mix, k_ext
    g = np.asarray(g, dtype=float)
    if g.shape[:1] != (D.shape[-1],) or not np.isfinite(g).all():
        raise ValueError("g must be finite with a first axis over the pigments")
    k_sc = np.tensordot(D, (1.0 - a) * sigma, axes=([-1], [0]))
    with np.errstate(invalid="ignore", divide="ignore"):
        g_mix = np.tensordot(D, g * (1.0 - a) * sigma, axes=([-1], [0])) / k_sc
    return a_mix, k_ext, np.where(k_sc > 0, g_mix, 0.0)
