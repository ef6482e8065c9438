"""Independent Monte Carlo reference for the lobe of mirror flakes inside a binder.

Nothing here imports bayespig: the Fresnel transmittance, Snell's law, the flake normals'
distribution and Smith's masking are written from the physics, so that
``bayespig.physics.microfacet.flake_reflection_brdf`` (and its wrapper
``bayespig.physics.forward.flake_brdf``) can be checked against photons, in particular its
change of variables from the binder's directions to air's (the refraction Jacobian and the
``1 / n^2`` of the radiance).

Model
-----
A collimated beam in air falls on the smooth, flat surface of a binder of index ``n`` at the
incidence angle ``theta_i``.  Inside, mirror flakes (reflectance 1: the function under test is
per unit flake reflectance) lie with normals ``m`` spread about the layer's normal ``z`` by the
GGX (Walter et al. 2007 eq. 33) or Beckmann (eq. 25) distribution ``D(m)``, normalised so that
``int D(m) (m.z) dw_m = 1``; the flakes mask and shadow each other as Smith's separable
``G1(i') G1(o')`` (Walter eqs. 34 and 27's exact erf form).  A flake-reflected photon going down
(``o'.z <= 0``) or outside the escape cone (``n sin theta_o' >= 1``: it stays inside) is lost;
the others leave through the surface into air, keeping their azimuth.

Estimator (one photon = one flake hit)
--------------------------------------
1. The photon crosses the surface with weight ``T_in = 1 - R(theta_i)`` (unpolarised Fresnel),
   its direction refracted by Snell's law: towards the source ``i' = (sin theta_i / n, 0,
   cos theta_i')``.  The irradiance on the flake population is then ``T_in E``.
2. A flake normal is drawn with pdf ``p(m) = D(m) cos theta_m`` (per solid angle of ``m``),
   exactly by inversion: GGX ``tan^2 theta_m = alpha^2 u / (1 - u)``, Beckmann
   ``tan^2 theta_m = -alpha^2 ln(1 - u)``, ``phi_m`` uniform.
3. Weight.  Per unit area of the layer, the flakes of normal in ``dw_m`` have area
   ``D(m) dw_m``; a beam of irradiance ``E'`` (flux per unit layer area) carries ``E' / mu_i'``
   per unit area across it, so these flakes intercept the fraction
   ``D(m) (i'.m) / mu_i' dw_m`` of the flux (``i'.m > 0``: lit side), of which the fraction
   ``G1(i') G1(o')`` is neither shadowed nor masked.  Divided by ``p(m)`` the photon's weight is
   ``T_in G1(i') G1(o') (i'.m) / (mu_i' cos theta_m)`` (0 if ``i'.m <= 0``), the photon mirrored
   as ``o' = 2 (i'.m) m - i'``.  Nothing of the BRDF formula (its half vector, its ``4 |o.h|``
   Jacobian, its ``1 / n^2``) is used: only the flakes' geometry.
4. Exit: ``sin theta_o = n sin theta_o'`` (lost if ``>= 1``), weight times ``T_out = 1 -
   R(theta_o')`` with the Fresnel reflectance computed *from the binder's side* (so Fresnel's
   reciprocity is not assumed either).  The photon is scored in the air bin of
   ``(theta_o, |delta_phi|)``, ``delta_phi`` the azimuth from the plane of incidence, 180 deg
   on the specular side (the project's convention; ``i`` at azimuth 0).

The expected score of a bin divided by the number of photons is the fraction of the incident
flux reflected into it, ``int_bin f(i, o) cos theta_o dw_o``: what the BRDF under test must
give.  Bins hold both signs of ``delta_phi`` (the lobe is symmetric about the plane of
incidence).  Standard errors come from the per-photon scores (``sqrt((<w^2> - <w>^2) / N)``
per bin, photons independent).

Use::

    from tests.physics import flake_monte_carlo as fmc
    mc = fmc.simulate(50.0, alpha=0.4, n=1.45, n_photons=1_000_000, seed=3)
    mc.fraction, mc.standard_error      # (theta bins, |delta_phi| bins)
    mc.escaped, mc.escaped_error        # total over the air hemisphere (the directional albedo)
"""

from dataclasses import dataclass

import numpy as np
from scipy import special

__all__ = ["THETA_EDGES", "DELTA_PHI_EDGES", "FlakeHistogram", "fresnel_reflectance",
           "smith_g1", "sample_normal_cosines", "simulate"]

#: Default air bins: polar angle [deg] in 7.5-deg rings, |delta_phi| [deg] in 30-deg sectors.
THETA_EDGES = np.linspace(0.0, 90.0, 13)
DELTA_PHI_EDGES = np.linspace(0.0, 180.0, 7)

_CHUNK = 500_000


def fresnel_reflectance(cos_i, n_1, n_2):
    """Unpolarised Fresnel reflectance of a smooth interface, light in medium ``n_1`` [-].

    ``(r_s^2 + r_p^2) / 2`` with ``r_s = (n_1 c_1 - n_2 c_2) / (n_1 c_1 + n_2 c_2)`` and
    ``r_p = (n_2 c_1 - n_1 c_2) / (n_2 c_1 + n_1 c_2)`` (Born & Wolf 1.5.2); 1 beyond the
    critical angle.

    Parameters
    ----------
    cos_i : array_like
        Cosine of the incidence angle in medium 1 [-], in [0, 1].
    n_1, n_2 : float
        Indices of the incident and the transmitting medium [-].
    """
    c_1 = np.asarray(cos_i, dtype=float)
    sin2_2 = (n_1 / n_2) ** 2 * (1.0 - c_1 * c_1)
    tir = sin2_2 >= 1.0
    c_2 = np.sqrt(np.where(tir, 0.0, 1.0 - sin2_2))
    with np.errstate(invalid="ignore", divide="ignore"):
        r_s = (n_1 * c_1 - n_2 * c_2) / (n_1 * c_1 + n_2 * c_2)
        r_p = (n_2 * c_1 - n_1 * c_2) / (n_2 * c_1 + n_1 * c_2)
    return np.where(tir | (c_1 <= 0.0), 1.0, 0.5 * (r_s * r_s + r_p * r_p))


def smith_g1(cos_v, alpha, distribution):
    """Smith's masking ``G1(v) = 1 / (1 + Lambda(v))`` of a direction of cosine ``cos_v`` > 0 [-].

    GGX: ``Lambda = (sqrt(1 + alpha^2 tan^2) - 1) / 2``; Beckmann: ``Lambda = (erf(a) - 1) / 2 +
    exp(-a^2) / (2 a sqrt(pi))`` with ``a = 1 / (alpha tan)`` (Walter et al. 2007 eqs. 34, 27).
    """
    c = np.asarray(cos_v, dtype=float)
    tan = np.sqrt(np.clip(1.0 - c * c, 0.0, None)) / c
    if distribution == "ggx":
        lam = 0.5 * (np.sqrt(1.0 + (alpha * tan) ** 2) - 1.0)
    elif distribution == "beckmann":
        with np.errstate(divide="ignore", invalid="ignore"):
            a = 1.0 / (alpha * tan)
            lam = 0.5 * (special.erf(a) - 1.0) + np.exp(-a * a) / (2.0 * a * np.sqrt(np.pi))
        lam = np.where(tan == 0.0, 0.0, lam)
    else:
        raise ValueError(f"distribution must be 'ggx' or 'beckmann', got {distribution!r}")
    return 1.0 / (1.0 + lam)


def sample_normal_cosines(alpha, distribution, u):
    """``cos theta_m`` drawn with pdf ``D(m) cos theta_m dw_m`` from uniforms ``u`` in [0, 1).

    GGX: the cumulative of ``tan^2`` is ``t / (alpha^2 + t)``, so ``t = alpha^2 u / (1 - u)``;
    Beckmann: ``1 - exp(-t / alpha^2)``, so ``t = -alpha^2 ln(1 - u)``.
    """
    if distribution == "ggx":
        tan2 = alpha * alpha * u / (1.0 - u)
    elif distribution == "beckmann":
        tan2 = -alpha * alpha * np.log1p(-u)
    else:
        raise ValueError(f"distribution must be 'ggx' or 'beckmann', got {distribution!r}")
    return 1.0 / np.sqrt(1.0 + tan2)


@dataclass(frozen=True)
class FlakeHistogram:
    """Flux fractions reflected by the flakes into air bins, with standard errors.

    Attributes
    ----------
    theta_edges, delta_phi_edges : numpy.ndarray
        Bin edges [deg]: air polar angle, ``|delta_phi|`` (180 on the specular side).
    fraction, standard_error : numpy.ndarray
        ``(len(theta_edges) - 1, len(delta_phi_edges) - 1)``: the fraction of the incident flux
        leaving into each bin (both signs of ``delta_phi``) and its standard error [-].
    escaped, escaped_error : float
        The fraction leaving into the whole air hemisphere (the directional albedo per unit
        flake reflectance) and its standard error [-].
    n_photons : int
    """

    theta_edges: np.ndarray
    delta_phi_edges: np.ndarray
    fraction: np.ndarray
    standard_error: np.ndarray
    escaped: float
    escaped_error: float
    n_photons: int


def simulate(theta_i, *, alpha, n, distribution="ggx", n_photons=1_000_000, seed=0,
             theta_edges=THETA_EDGES, delta_phi_edges=DELTA_PHI_EDGES):
    """Photon estimate of the flakes' reflection into air bins (see the module's docstring).

    Parameters
    ----------
    theta_i : float
        Incidence angle in air [deg], in [0, 90).
    alpha : float
        Flake roughness [-] (> 0).
    n : float
        Binder index [-] (> 1).
    distribution : {"ggx", "beckmann"}
    n_photons : int
    seed : int
        Seed of the ``numpy.random.Generator`` (PCG64) that draws every random number.
    theta_edges, delta_phi_edges : array_like
        Air bins [deg].

    Returns
    -------
    FlakeHistogram
    """
    if not (alpha > 0.0 and n > 1.0 and 0.0 <= theta_i < 90.0):
        raise ValueError("need alpha > 0, n > 1 and 0 <= theta_i < 90 deg")
    rng = np.random.default_rng(seed)
    theta_edges = np.asarray(theta_edges, dtype=float)
    delta_phi_edges = np.asarray(delta_phi_edges, dtype=float)
    shape = (theta_edges.size - 1, delta_phi_edges.size - 1)
    sums, squares = np.zeros(shape), np.zeros(shape)
    escaped_sum = escaped_square = 0.0

    # step 1: into the binder (towards the source, azimuth 0)
    sin_i = np.sin(np.radians(theta_i)) / n
    cos_i = np.sqrt(1.0 - sin_i * sin_i)
    t_in = 1.0 - float(fresnel_reflectance(np.cos(np.radians(theta_i)), 1.0, n))
    g1_i = float(smith_g1(cos_i, alpha, distribution))

    done = 0
    while done < n_photons:
        count = min(_CHUNK, n_photons - done)
        done += count
        # step 2: a flake normal
        cos_m = sample_normal_cosines(alpha, distribution, rng.random(count))
        sin_m = np.sqrt(np.clip(1.0 - cos_m * cos_m, 0.0, None))
        phi_m = 2.0 * np.pi * rng.random(count)
        m = np.stack([sin_m * np.cos(phi_m), sin_m * np.sin(phi_m), cos_m])
        i_dot_m = sin_i * m[0] + cos_i * m[2]
        # step 3: mirror reflection and weight
        o = 2.0 * i_dot_m * m - np.array([sin_i, 0.0, cos_i])[:, None]
        keep = (i_dot_m > 0.0) & (o[2] > 0.0)
        # step 4: out through the surface
        sin_o_in = np.sqrt(np.clip(o[0] ** 2 + o[1] ** 2, 0.0, None))
        keep &= n * sin_o_in < 1.0
        o, i_dot_m, cos_m, sin_o_in = o[:, keep], i_dot_m[keep], cos_m[keep], sin_o_in[keep]
        cos_o_in = o[2]
        weight = (t_in * g1_i * smith_g1(cos_o_in, alpha, distribution) * i_dot_m / (cos_i * cos_m)
                  * (1.0 - fresnel_reflectance(cos_o_in, n, 1.0)))
        theta_o = np.degrees(np.arcsin(n * sin_o_in))
        delta_phi = np.abs(np.degrees(np.arctan2(o[1], o[0])))
        sums += np.histogram2d(theta_o, delta_phi, bins=(theta_edges, delta_phi_edges), weights=weight)[0]
        squares += np.histogram2d(theta_o, delta_phi, bins=(theta_edges, delta_phi_edges),
                                  weights=weight * weight)[0]
        escaped_sum += weight.sum()
        escaped_square += (weight * weight).sum()

    fraction = sums / n_photons
    error = np.sqrt(np.clip(squares / n_photons - fraction ** 2, 0.0, None) / n_photons)
    escaped = escaped_sum / n_photons
    escaped_error = float(np.sqrt(max(escaped_square / n_photons - escaped ** 2, 0.0) / n_photons))
    return FlakeHistogram(theta_edges, delta_phi_edges, fraction, error, float(escaped), escaped_error,
                          int(n_photons))
