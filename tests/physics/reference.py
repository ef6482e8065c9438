"""Independent reference solutions for testing the radiative-transfer core.

Nothing here imports bayespig: these are textbook closed forms and small numerical solutions
written from the literature, so that the solver can be checked against them.

Conventions: ``omega`` is the single-scattering albedo (``omega = 1 - a``), cosines ``mu`` and
``mu0`` are taken inside the medium, angles in air are in degrees, ``delta_phi = 180`` is the
specular side.  A *reflection function* is ``pi * BRDF``.

References
----------
S. Chandrasekhar, Radiative Transfer, Oxford University Press, 1950, chapter V.
H. C. van de Hulst, Multiple Light Scattering, vol. 1, Academic Press, 1980.
"""

from functools import lru_cache

import numpy as np
from scipy import integrate

# Composite Gauss-Legendre grid on [0, 1], graded geometrically towards mu = 0 where
# H(mu) behaves like 1 + c mu log(mu).
_GRID_BREAKS = np.concatenate(([0.0], np.logspace(-8, 0, 9)))
_GRID_POINTS_PER_PANEL = 20
_NEWTON_TOL = 1e-14
_NEWTON_MAX_STEPS = 50


def _graded_grid():
    """Nodes and weights of the graded composite Gauss-Legendre rule on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(_GRID_POINTS_PER_PANEL)
    lo, hi = _GRID_BREAKS[:-1, None], _GRID_BREAKS[1:, None]
    nodes = 0.5 * (hi - lo) * (x + 1.0) + lo
    weights = 0.5 * (hi - lo) * w
    return nodes.ravel(), weights.ravel()


@lru_cache(maxsize=64)
def _h_on_grid(omega):
    """Solve the H-equation on the graded grid by Newton's method.

    Solves ``H_i (sqrt(1 - omega) + omega/2 sum_j w_j mu_j H_j / (mu_i + mu_j)) = 1``
    (Chandrasekhar 1950, eq. V.(31) form), which converges also for ``omega = 1``.
    """
    mu, w = _graded_grid()
    kernel = 0.5 * omega * w * mu / (mu[:, None] + mu[None, :])
    s = np.sqrt(1.0 - omega)
    h = np.ones_like(mu)
    for _ in range(_NEWTON_MAX_STEPS):
        inv = s + kernel @ h
        residual = h * inv - 1.0
        jacobian = np.diag(inv) + h[:, None] * kernel
        step = np.linalg.solve(jacobian, residual)
        h -= step
        if np.max(np.abs(step)) < _NEWTON_TOL:
            return mu, w, h
    raise RuntimeError(f"H-function Newton iteration did not converge for omega={omega}")


def chandrasekhar_h(mu, omega):
    """Chandrasekhar's H-function for isotropic scattering.

    Parameters
    ----------
    mu : array_like
        Direction cosine(s) in [0, 1] [-].
    omega : float
        Single-scattering albedo in [0, 1] [-].

    Returns
    -------
    numpy.ndarray
        H(mu) [-], evaluated at arbitrary ``mu`` by Nystrom interpolation of the integral
        equation ``1/H(mu) = sqrt(1 - omega) + omega/2 int_0^1 mu' H(mu') / (mu + mu') dmu'``.
    """
    nodes, weights, h = _h_on_grid(float(omega))
    mu = np.asarray(mu, dtype=float)
    integral = np.sum(weights * nodes * h / (mu[..., None] + nodes), axis=-1)
    return 1.0 / (np.sqrt(1.0 - omega) + 0.5 * omega * integral)


def chandrasekhar_h_closed_form(mu, omega):
    """H-function from Chandrasekhar's explicit integral (1950, eq. V.(84) for Psi = omega/2).

    ``ln H(mu) = -(mu/pi) int_0^{pi/2} ln(1 - omega theta cot theta) /
    (cos^2 theta + mu^2 sin^2 theta) dtheta``, evaluated with adaptive quadrature for a
    scalar ``mu``. An independent check of :func:`chandrasekhar_h`.
    """

    def integrand(theta):
        # 1 - theta cot(theta), by its series near 0 to avoid cancellation; the logarithm
        # has an integrable singularity at theta = 0 when omega = 1.
        if theta < 1e-2:
            u = theta**2 / 3.0 + theta**4 / 45.0 + 2.0 * theta**6 / 945.0
        else:
            u = 1.0 - theta / np.tan(theta)
        log_term = np.log((1.0 - omega) + omega * u)
        return log_term / (np.cos(theta) ** 2 + (mu * np.sin(theta)) ** 2)

    if mu == 0.0:
        return 1.0
    value, _ = integrate.quad(integrand, 0.0, 0.5 * np.pi, epsabs=1e-13, epsrel=1e-12, limit=200)
    return float(np.exp(-mu / np.pi * value))


def h_moment(omega, power):
    """``int_0^1 H(mu) mu^power dmu`` on the graded grid."""
    nodes, weights, h = _h_on_grid(float(omega))
    return float(np.sum(weights * h * nodes**power))


def semi_infinite_reflection_function(mu, mu0, omega):
    """Reflection function ``pi * BRDF`` of a semi-infinite isotropic medium, n = 1.

    ``R(mu, mu0) = omega/4 H(mu) H(mu0) / (mu + mu0)`` (Chandrasekhar 1950, eq. IV.(52)).
    """
    return 0.25 * omega * chandrasekhar_h(mu, omega) * chandrasekhar_h(mu0, omega) / (mu + mu0)


def semi_infinite_hemispherical_reflectance(mu0, omega):
    """Directional-hemispherical reflectance ``1 - H(mu0) sqrt(1 - omega)``, n = 1."""
    return 1.0 - chandrasekhar_h(mu0, omega) * np.sqrt(1.0 - omega)


def semi_infinite_diffuse_albedo(omega):
    """Bi-hemispherical (diffuse) albedo ``1 - 2 sqrt(1 - omega) int_0^1 H mu dmu``, n = 1."""
    return 1.0 - 2.0 * np.sqrt(1.0 - omega) * h_moment(omega, 1)


def fresnel_reflectance(mu_i, n_i, n_t):
    """Unpolarised Fresnel reflectance from medium ``n_i`` into medium ``n_t``.

    Parameters
    ----------
    mu_i : array_like
        Cosine of the incidence angle in medium ``n_i`` [-].
    n_i, n_t : float
        Refractive indices of the incident and transmitting media [-].

    Returns
    -------
    numpy.ndarray
        ``(r_s^2 + r_p^2) / 2`` [-]; 1 beyond the critical angle.
    """
    mu_i = np.asarray(mu_i, dtype=float)
    sin_t2 = (n_i / n_t) ** 2 * (1.0 - mu_i**2)
    total = sin_t2 >= 1.0
    mu_t = np.sqrt(np.clip(1.0 - sin_t2, 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        r_perp = (n_i * mu_i - n_t * mu_t) / (n_i * mu_i + n_t * mu_t)
        r_par = (n_t * mu_i - n_i * mu_t) / (n_t * mu_i + n_i * mu_t)
    return np.where(total, 1.0, 0.5 * (r_perp**2 + r_par**2))


def refracted_cosine(theta_deg, n):
    """Cosine inside a medium of index ``n`` of a direction at ``theta_deg`` in air."""
    sin_air = np.sin(np.radians(theta_deg))
    return np.sqrt(1.0 - (sin_air / n) ** 2)


def internal_diffuse_reflectance(n):
    """``2 int_0^1 r_F(mu) mu dmu`` for light inside index ``n`` hitting air (Lambertian)."""
    mu_c = np.sqrt(1.0 - 1.0 / n**2)
    tail, _ = integrate.quad(
        lambda mu: 2.0 * mu * float(fresnel_reflectance(mu, n, 1.0)), mu_c, 1.0,
        epsabs=1e-14, epsrel=1e-13,
    )
    return mu_c**2 + tail


def phase_function(cos_theta, g):
    """Phase function normalised to ``int p dOmega / (4 pi) = 1``.

    Henyey-Greenstein for ``g`` in [-1, 1]; Rayleigh ``3/4 (1 + cos^2)`` otherwise.
    """
    cos_theta = np.asarray(cos_theta, dtype=float)
    if abs(g) > 1.0:
        return 0.75 * (1.0 + cos_theta**2)
    return (1.0 - g**2) / (1.0 + g**2 - 2.0 * g * cos_theta) ** 1.5


def scattering_angle_cosine(mu0, mu, delta_phi_deg):
    """Cosine of the angle between the propagation directions of incident and reflected light.

    The incident beam propagates downwards from azimuth 0 (towards the source), the
    reflected light upwards at azimuth ``delta_phi``; ``delta_phi = 0`` is back towards the
    source (``cos = -1`` at ``mu = mu0``), ``delta_phi = 180`` the specular side.
    """
    sin0 = np.sqrt(1.0 - mu0**2)
    sin1 = np.sqrt(1.0 - mu**2)
    return -mu0 * mu - sin0 * sin1 * np.cos(np.radians(delta_phi_deg))


def single_scattering_brdf(theta_i, theta_o, delta_phi, *, omega, tau, g=0.0, n=1.0):
    """First-order (single-scattering) BRDF from air of a layer on a black substrate [1/sr].

    Inside the medium ``f = omega p(Theta) / (4 pi (mu + mu0)) (1 - exp(-tau (1/mu + 1/mu0)))``
    (van de Hulst 1980, eq. 4.14 divided by pi); with a Fresnel top surface of index ``n`` the
    directions refract, and the air BRDF is ``t_F(mu0) t_F(mu) f / n^2``. Exact to first order
    in ``tau``: light reflected back down by the top surface leaves through the black bottom.
    """
    mu0 = refracted_cosine(theta_i, n)
    mu = refracted_cosine(theta_o, n)
    cos_scat = scattering_angle_cosine(mu0, mu, delta_phi)
    attenuation = -np.expm1(-tau * (1.0 / mu + 1.0 / mu0))
    inside = omega * phase_function(cos_scat, g) / (4.0 * np.pi * (mu + mu0)) * attenuation
    if n == 1.0:
        return inside
    t_in = 1.0 - fresnel_reflectance(np.cos(np.radians(theta_i)), 1.0, n)
    t_out = 1.0 - fresnel_reflectance(np.cos(np.radians(theta_o)), 1.0, n)
    return t_in * t_out * inside / n**2


def clear_binder_brdf(theta_i, theta_o, *, r_s, n):
    """BRDF from air of a Lambertian substrate under a clear binder [1/sr].

    Paper eq. (9) with the azimuth integral restored in the denominator:
    ``f = t_F(v) t_F(u) / n^2 * (r_s / pi) / (1 - r_s r_i)`` with ``r_i`` the internal diffuse
    reflectance of the binder/air surface.
    """
    t_in = 1.0 - fresnel_reflectance(np.cos(np.radians(theta_i)), 1.0, n)
    t_out = 1.0 - fresnel_reflectance(np.cos(np.radians(theta_o)), 1.0, n)
    return t_in * t_out / n**2 * (r_s / np.pi) / (1.0 - r_s * internal_diffuse_reflectance(n))


def gauss_on_unit_interval(num_points):
    """Gauss-Legendre nodes and weights on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(num_points)
    return 0.5 * (x + 1.0), 0.5 * w
