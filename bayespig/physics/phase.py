"""Phase functions and their azimuthal Fourier modes.

Phase functions are normalised so that ``int p dOmega / (4 pi) = 1``. The paper's
convention (section 2) is used for the single parameter ``g``: a value in
(-1, 1) is Henyey–Greenstein, a value outside [-1, 1] means Rayleigh, and
``g = 0`` is isotropic.

References
----------
Henyey & Greenstein (1941), ApJ 93, 70.
Ershov, Voloboy & Pozdnyakov (2023), section 2.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "ModeStopping",
    "henyey_greenstein",
    "is_isotropic",
    "is_rayleigh",
    "n_fourier_modes",
    "normalise_on_quadrature",
    "phase_fourier_modes",
    "phase_function",
    "rayleigh",
]

#: Relative size below which a Fourier mode of the phase function is dropped.
FOURIER_TOLERANCE = 1e-7
#: Iterations of :func:`normalise_on_quadrature`: 20 left the discrete mode 0 short of 2 by up to
#: 6e-13 at g = 0.95 (a spurious absorption that costs an opaque conservative layer ~7e-6 of its
#: reflectance); 30 reach rounding (<= 2e-15) for |g| <= 0.95 on the default quadratures.
NORMALISATION_ITERATIONS = 40


def henyey_greenstein(cos_theta, g):
    """Henyey–Greenstein phase function ``(1 - g^2) / (1 + g^2 - 2 g cos)^(3/2)`` [-]."""
    cos_theta = np.asarray(cos_theta, dtype=float)
    return (1.0 - g * g) / (1.0 + g * g - 2.0 * g * cos_theta) ** 1.5


def rayleigh(cos_theta):
    """Rayleigh phase function ``3/4 (1 + cos^2)`` [-]."""
    cos_theta = np.asarray(cos_theta, dtype=float)
    return 0.75 * (1.0 + cos_theta**2)


def is_rayleigh(g):
    """True where ``g`` selects the Rayleigh law (outside [-1, 1], paper section 2)."""
    return np.abs(g) > 1.0


def is_isotropic(g):
    """True where ``g`` selects isotropic scattering."""
    return np.asarray(g) == 0.0


def phase_function(cos_theta, g):
    """Phase function of the paper's single parameter ``g``.

    Parameters
    ----------
    cos_theta : array_like
        Cosine of the scattering angle [-].
    g : float
        Henyey–Greenstein asymmetry in (-1, 1); ``|g| > 1`` means Rayleigh.

    Returns
    -------
    numpy.ndarray
        ``p(cos_theta)`` normalised to ``int p dOmega / (4 pi) = 1`` [-].
    """
    if is_rayleigh(g):
        return rayleigh(cos_theta)
    return henyey_greenstein(cos_theta, g)


def n_fourier_modes(g, tolerance=FOURIER_TOLERANCE):
    """Number of azimuthal modes needed for the phase function ``g``.

    One mode (the azimuthal average) for isotropic scattering, three for
    Rayleigh, and enough for Henyey–Greenstein that ``|g|^m`` falls below
    ``tolerance``.
    """
    if g == 0.0:
        return 1
    if is_rayleigh(g):
        return 3
    return int(np.ceil(np.log(tolerance) / np.log(abs(g)))) + 1


def phase_fourier_modes(mu_out, mu_in, g, n_modes, *, reflection):
    """Azimuthal Fourier modes of the phase function between two direction sets.

    With ``psi`` the difference of the *propagation* azimuths,
    ``p(psi) = p_0 + 2 sum_{m>=1} p_m cos(m psi)``.

    Parameters
    ----------
    mu_out, mu_in : numpy.ndarray
        Direction cosines (positive) of the scattered and incident directions, shapes
        (k,) and (j,) [-].
    g : float
        Phase-function parameter (paper's convention).
    n_modes : int
        Number of modes ``m = 0 .. n_modes - 1`` to return.
    reflection : bool
        True when incident and scattered directions lie in opposite hemispheres
        (``cos theta = -mu mu' + s s' cos psi``), False for the same hemisphere.

    Returns
    -------
    numpy.ndarray
        ``p_m(mu_out, mu_in)``, shape (n_modes, k, j) [-].
    """
    mu_out = np.asarray(mu_out, dtype=float)[:, None]
    mu_in = np.asarray(mu_in, dtype=float)[None, :]
    sign = -1.0 if reflection else 1.0
    if g == 0.0:
        modes = np.zeros((n_modes, mu_out.shape[0], mu_in.shape[1]))
        modes[0] = 1.0
        return modes
    # trapezoidal rule in psi is exact for trigonometric polynomials of degree < n_psi
    # and spectrally accurate for the smooth Henyey-Greenstein law.
    n_psi = 8 if is_rayleigh(g) else max(64, 1 << int(np.ceil(np.log2(4 * n_modes))))
    psi = 2.0 * np.pi * np.arange(n_psi) / n_psi
    sin_out = np.sqrt(np.clip(1.0 - mu_out**2, 0.0, None))
    sin_in = np.sqrt(np.clip(1.0 - mu_in**2, 0.0, None))
    cos_theta = (sign * mu_out * mu_in)[..., None] + (sin_out * sin_in)[..., None] * np.cos(psi)
    spectrum = np.fft.rfft(phase_function(np.clip(cos_theta, -1.0, 1.0), g), axis=-1).real / n_psi
    modes = np.moveaxis(spectrum[..., :n_modes], -1, 0)
    if modes.shape[0] < n_modes:
        modes = np.concatenate([modes, np.zeros((n_modes - modes.shape[0],) + modes.shape[1:])])
    return modes


def normalise_on_quadrature(p_reflection, p_transmission, weight, n_iterations=NORMALISATION_ITERATIONS):
    """Rescale phase-function modes so the discrete mode 0 integrates to exactly 2.

    A sharply peaked Henyey–Greenstein law is not integrated exactly by a modest
    quadrature; the defect acts as a spurious absorption or gain. With factors
    ``s_i`` the kernels become ``s_i s_j p_ij`` (symmetric, so reciprocity holds)
    and ``sum_i w_i s_i s_j (p_R + p_T)_ij = 2`` for every direction ``j``
    (Wiscombe 1976, "On initialization, error and flux conservation in the
    doubling method"). Zero-weight nodes get ``s_j`` from their own column.

    Parameters
    ----------
    p_reflection, p_transmission : numpy.ndarray
        Modes, shape (M, N, N) [-].
    weight : numpy.ndarray
        Quadrature weights, shape (N,), zero for extra nodes [-].

    Returns
    -------
    tuple of numpy.ndarray
        The rescaled ``p_reflection``, ``p_transmission``.
    """
    total = p_reflection[0] + p_transmission[0]
    real = weight > 0
    s = np.ones(weight.size)
    for _ in range(n_iterations):
        column = (weight * s) @ total
        s[real] = s[real] * np.sqrt(2.0 / (s[real] * column[real]))
    column = (weight * s) @ total
    s[~real] = 2.0 / column[~real]
    scale = s[:, None] * s[None, :]
    return p_reflection * scale, p_transmission * scale


class ModeStopping:
    """Where each value's azimuthal Fourier series stops: the solvers' adaptive number of modes.

    A value (parameter set x geometry) stops after two modes in a row below ``tolerance`` times
    ``scale`` (its mode 0, or its mode 0 over black, which bounds every mode of a positive BRDF), so
    its result never depends on which other values share the call. Used by the smooth solver
    (:func:`bayespig.physics.forward.surface_terms`) and the rough one
    (:func:`bayespig.physics.rough_surface.rough_surface_terms`).

    Parameters
    ----------
    scale : numpy.ndarray
        ``|mode 0|`` of every value, shape (B, k_out, k_in).
    max_modes : int
        The most modes any value gets.
    tolerance : float
        Relative size of a negligible mode [-].
    adaptive : bool
        False: every value gets ``max_modes`` (a fixed ``n_modes``).
    """

    def __init__(self, scale, max_modes, tolerance, adaptive=True):
        self.scale = np.abs(scale)
        self.tolerance, self.adaptive = float(tolerance), bool(adaptive)
        self.quiet = np.zeros(self.scale.shape, dtype=int)
        #: The modes every value uses (it stops at its ``n_used - 1``).
        self.n_used = np.full(self.scale.shape, int(max_modes))

    def active(self, m):
        """Parameter sets (B,) with a value that still needs mode ``m``."""
        return (self.n_used > m).any(axis=(1, 2))

    def add(self, m, f_mode):
        """Record mode ``m >= 1`` of every value; True when every value has stopped."""
        if not self.adaptive:
            return False
        small = np.abs(f_mode) <= self.tolerance * self.scale
        self.quiet = np.where(small, self.quiet + 1, 0)
        self.n_used = np.where((self.quiet == 2) & (self.n_used > m), m + 1, self.n_used)
        return bool((self.n_used <= m + 1).all())

    def truncate(self, f_modes):
        """The modes stacked (B, M, k_out, k_in), each value's beyond its stop set to 0."""
        f_modes = np.stack(f_modes, axis=1)
        f_modes[np.arange(f_modes.shape[1])[None, :, None, None] >= self.n_used[:, None]] = 0.0
        return f_modes

