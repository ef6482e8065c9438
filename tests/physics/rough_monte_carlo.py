"""Independent Monte Carlo reference for a pigmented layer under a rough dielectric surface.

Nothing here imports bayespig: the microfacet surface, the Henyey–Greenstein scattering, the
Lambertian substrate and the estimator are written from the physics, so that the project's
deterministic solver can be checked against them (issue 16, "the whole rough-surface BRDF
against an independent code").

Model (``../shared/DESIGN.md`` section 1)
-----------------------------------------
A plane-parallel layer of binder (index ``n``, non-absorbing) holding pigment of optical
thickness ``tau`` (``inf``: semi-infinite), relative absorption ``a = 1 - omega`` and
Henyey–Greenstein parameter ``g`` (|g| < 1), on a Lambertian substrate whose albedo seen from
the binder is ``r_s`` (no interface at the bottom).  The top is the rough dielectric surface of
Walter, Marschner, Li & Torrance (2007): isotropic GGX ``D(m) = alpha^2 / (pi cos^4 m
(alpha^2 + tan^2 m)^2)``, separable Smith ``G = G1(i) G1(o)`` with ``G1(v) = 2 / (1 + sqrt(1 +
alpha^2 tan^2 v))`` and the sidedness factor, unpolarised Fresnel at the facet, no scattering
between facets (energy the single-scattering BSDF does not return is absorbed by the surface:
the *microfacet loss*).  The surface acts on the incident light from air and on light reaching
it from inside (reflection back into the layer, including total internal reflection, and
transmission to air).

Directions in air, in degrees: incidence ``theta_i``, viewing ``theta_o``, azimuth
``delta_phi`` between the planes of incidence and viewing, 180 on the specular side.  The BRDF
is in 1/sr, from air: ``part="surface"`` is the first-surface lobe (Walter's BRDF, analytic),
``part="body"`` everything that has entered the layer, ``part="total"`` their sum.

Estimator
---------
Photons (vectorised, weights, all random numbers from one seeded ``numpy.random.Generator``)
enter through the surface: a microfacet normal is drawn from GGX's distribution of normals
visible from the source (Heitz 2018), and the photon is transmitted with weight
``(1 - F) G1(t)`` (the reflected share is the surface part, kept analytically; it and the
masking loss go to the energy account).  Inside, free paths are exponential, scattering is
Henyey–Greenstein with the weight multiplied by ``omega`` (absorption kept in the account),
the substrate reflects with weight ``r_s`` into a cosine-distributed direction, and at the top
from inside a visible normal is drawn for the photon's direction, the photon reflected with
probability ``F`` (weight ``G1(r)``, TIR when the facet's ``F = 1``) or else transmitted to air
(weight ``G1(t)``, the walk ends there).  Weights below ``ROULETTE_WEIGHT`` play Russian
roulette.

The body BRDF at a fixed air direction ``o`` is scored by next-event estimation at every
scattering event and at every substrate hit: a facet normal ``m`` visible from ``o`` (air side)
is drawn, ``o`` refracted through it into the binder gives the internal direction ``i`` (pointing
down, cosine ``mu_i``), and the event at depth ``t`` scores

    w * S(-i) * exp(-t / mu_i) * (1 - F(o.m)) * G1(i) / (n^2 * mu_i),

where ``S`` is the event's emission per steradian (``omega p_HG(d, -i)`` for scattering,
``r_s mu_i / pi`` at the substrate) — Walter's BTDF over the pdf of ``i`` (the facet's
``D G1(o) |o.m| / mu_o`` times the refraction Jacobian) reduces to ``(1 - F) G1(i) / (n^2
mu_i)``, the ``1 / n^2`` being the radiance's change of solid angle.  Per-photon scores give
the standard error.  Cost: about 0.3–0.6 microseconds per event and view on one core.

Use against the deterministic solver
------------------------------------
::

    import bayespig
    from tests.physics import rough_monte_carlo as rmc

    # one geometry: the body BRDF and its standard errors at views (theta_o, delta_phi) [deg]
    mc = rmc.monte_carlo_brdf(45.0, [(0, 0), (30, 180), (45, 90)], a=0.3, tau=1.0, g=0.6,
                              r_s=0.8, n=1.45, alpha=0.2, n_photons=100_000, seed=1, part="body")
    mc.brdf, mc.standard_error, mc.surface, mc.energy

    # the issue's cases against a solver (one Monte Carlo run per case serves every part)
    rows = rmc.compare_with_solver(bayespig.brdf, rmc.SOLVER_CASES, parts=("body", "total"),
                                   n_photons=100_000)
    worst = max(rows, key=lambda row: abs(row["sigmas"]))

    # directional-hemispherical reflectance of the body (next-event scores over the
    # hemisphere) and the energy account: surface_reflected (first-surface albedo),
    # body_escaped (analog), microfacet_loss, absorbed
    albedo, albedo_error, energy = rmc.monte_carlo_albedo(45.0, a=0.0, tau=1.0, r_s=1.0,
                                                          alpha=0.3, n_photons=100_000)

``compare_with_solver`` calls ``brdf_function(theta_i, theta_o, delta_phi, a=..., tau=...,
g=..., r_s=..., n=..., roughness=alpha, part=...)`` and returns, per case, part and view, the
relative difference and its size in standard errors.  ``python benchmarks/monte_carlo.py``
prints the cost and precision per case (and the comparison when the solver has roughness):
at 1e5 photons 0.1-0.6 % standard error per view, 1-3 s per case of 8 views for a = 0.3 or
tau = 1, 30-60 s for a = 0.01 semi-infinite (80-130 events per photon).

References
----------
B. Walter, S. R. Marschner, H. Li, K. E. Torrance, "Microfacet models for refraction through
rough surfaces", EGSR 2007.
E. Heitz, "Sampling the GGX distribution of visible normals", JCGT 7(4), 2018.
"""

from dataclasses import dataclass, field
from functools import partial

import numpy as np

#: A photon whose weight falls below this plays Russian roulette ...
ROULETTE_WEIGHT = 0.05
#: ... and survives with this probability (its weight divided by it).
ROULETTE_SURVIVAL = 0.25
#: Photons traced together (memory ~ BATCH x views x 8 bytes per score array).
DEFAULT_BATCH = 20_000
#: A walk longer than this many events means a bug (roulette ends every walk far sooner).
MAX_EVENTS = 1_000_000

PARTS = ("total", "body", "surface")


# --------------------------------------------------------------------------------------------
# vectors


def _dot(u, v):
    return np.einsum("...k,...k->...", u, v)


def _normalize(v):
    return v / np.sqrt(_dot(v, v))[..., None]


def air_direction(theta_deg, phi_deg=0.0):
    """Unit vector(s) in air, polar angle ``theta`` from the normal (+z), azimuth ``phi`` [deg]."""
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    t, p = np.broadcast_arrays(t, p)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def _orthonormal_basis(d):
    """Two unit vectors completing ``d`` (..., 3) to an orthonormal basis (Duff et al. 2017)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    sign = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    b1 = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=-1)
    b2 = np.stack([b, sign + y * y * a, -y], axis=-1)
    return b1, b2


# --------------------------------------------------------------------------------------------
# the rough dielectric surface (Walter et al. 2007, GGX)


def fresnel_unpolarised(cos_incidence, eta):
    """Unpolarised Fresnel reflectance of a facet met at ``|cos| = cos_incidence``.

    ``eta`` is the index on the far side over the index on the incident side; 1 beyond the
    critical angle (Walter et al. 2007, eq. 22).
    """
    c = np.abs(cos_incidence)
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        f = 0.5 * ((g - c) / (g + c)) ** 2 * (1.0 + ((c * (g + c) - 1.0) / (c * (g - c) + 1.0)) ** 2)
    return np.where(g2 <= 0.0, 1.0, np.nan_to_num(f, nan=1.0))


def ggx_distribution(cos_m, alpha):
    """GGX density of facet normals ``D(m)`` [1/sr] (zero for normals facing down)."""
    c2 = np.clip(cos_m, 0.0, 1.0) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        tan2 = (1.0 - c2) / c2
        d = alpha**2 / (np.pi * c2 * c2 * (alpha**2 + tan2) ** 2)
    return np.where(cos_m > 0.0, d, 0.0)


def smith_g1(cos_v, alpha):
    """Smith masking of GGX for a direction with cosine ``cos_v`` to the macro normal (either side)."""
    c2 = np.minimum(np.asarray(cos_v, dtype=float) ** 2, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        tan2 = (1.0 - c2) / c2
        g1 = 2.0 / (1.0 + np.sqrt(1.0 + alpha * alpha * tan2))
    return np.where(c2 > 0.0, g1, 0.0)


def sample_visible_normal(v, alpha, u1, u2):
    """Facet normals from GGX's distribution of normals visible from ``v`` (Heitz 2018).

    ``v`` (..., 3) points away from the surface with ``v_z > 0``; ``u1``, ``u2`` uniform on
    [0, 1).  The density of the result is ``G1(v) max(0, v.m) D(m) / v_z``.
    """
    vh = _normalize(np.stack([alpha * v[..., 0], alpha * v[..., 1], v[..., 2]], axis=-1))
    lensq = vh[..., 0] ** 2 + vh[..., 1] ** 2
    safe = lensq > 1e-30
    inv = np.where(safe, 1.0 / np.sqrt(np.where(safe, lensq, 1.0)), 0.0)
    t1 = np.stack([np.where(safe, -vh[..., 1] * inv, 1.0), np.where(safe, vh[..., 0] * inv, 0.0),
                   np.zeros_like(lensq)], axis=-1)
    t2 = np.cross(vh, t1)
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    p1, p2 = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1.0 + vh[..., 2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(1.0 - p1 * p1, 0.0)) + s * p2
    p3 = np.sqrt(np.maximum(1.0 - p1 * p1 - p2 * p2, 0.0))
    nh = p1[..., None] * t1 + p2[..., None] * t2 + p3[..., None] * vh
    return _normalize(np.stack([alpha * nh[..., 0], alpha * nh[..., 1],
                                np.maximum(nh[..., 2], 1e-12)], axis=-1))


def reflect(i, m):
    """Mirror ``i`` (pointing away from the surface) about the facet normal ``m``."""
    return 2.0 * _dot(i, m)[..., None] * m - i


def refract(i, m, eta_ratio):
    """Refract ``i`` (pointing away from the surface, ``i.m > 0``) through ``m``.

    ``eta_ratio`` is the incident index over the far index.  Returns the transmitted direction
    (pointing away from the surface on the far side) and a mask of where it exists (no TIR).
    """
    c = _dot(i, m)
    k = 1.0 - eta_ratio**2 * (1.0 - c * c)
    ok = k > 0.0
    t = (eta_ratio * c - np.sqrt(np.maximum(k, 0.0)))[..., None] * m - eta_ratio * i
    return t, ok


def walter_reflection(i, o, n, alpha):
    """Walter's rough-dielectric BRDF [1/sr] for ``i``, ``o`` on the side of index 1 (air, z > 0).

    ``n`` is the index below.  Use for the first-surface lobe from air.
    """
    mu_i, mu_o = i[..., 2], o[..., 2]
    h = _normalize(i + o)
    c = _dot(i, h)
    f = fresnel_unpolarised(c, n)
    ok = (mu_i > 0) & (mu_o > 0) & (c > 0)
    value = f * ggx_distribution(h[..., 2], alpha) * smith_g1(mu_i, alpha) * smith_g1(mu_o, alpha)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok, value / (4.0 * mu_i * mu_o), 0.0)


def walter_transmission(i, o, eta_i, eta_o, alpha):
    """Walter's rough-dielectric BTDF [1/sr], eq. 21: ``i`` on the side of index ``eta_i``.

    Both vectors point away from the surface, on opposite sides of z = 0.
    """
    h = -(eta_i * i + eta_o * o)
    h = _normalize(h) * np.where(h[..., 2] < 0.0, -1.0, 1.0)[..., None]
    ih, oh = _dot(i, h), _dot(o, h)
    mu_i, mu_o = i[..., 2], o[..., 2]
    ok = (ih * mu_i > 0) & (oh * mu_o > 0) & (mu_i * mu_o < 0)
    denominator = (eta_i * ih + eta_o * oh) ** 2
    value = (np.abs(ih * oh) * eta_o**2 * (1.0 - fresnel_unpolarised(ih, eta_o / eta_i))
             * ggx_distribution(h[..., 2], alpha) * smith_g1(mu_i, alpha) * smith_g1(mu_o, alpha))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok, value / (np.abs(mu_i * mu_o) * denominator), 0.0)


def interface_sample(i, eta_ratio, alpha, rng):
    """Scatter light arriving along ``-i`` at the rough surface, in the local frame (``i_z > 0``).

    ``eta_ratio`` is the index on the incident side (z > 0) over the far side.  Returns
    ``(reflected_direction, reflected_weight, transmitted_direction, transmitted_weight, F)``,
    both directions pointing away from the surface (reflected z > 0, transmitted z < 0), the
    weights ``G1`` of each outgoing direction (0 where it is on the wrong side or, for
    transmission, under TIR), so that reflection with probability ``F`` and weight
    ``reflected_weight`` (else transmission with ``transmitted_weight``) samples Walter's BSDF
    times the cosine exactly.
    """
    shape = i.shape[:-1]
    m = sample_visible_normal(i, alpha, rng.random(shape), rng.random(shape))
    c = _dot(i, m)
    f = fresnel_unpolarised(c, 1.0 / eta_ratio)
    r = reflect(i, m)
    r_weight = np.where(r[..., 2] > 0.0, smith_g1(r[..., 2], alpha), 0.0)
    t, ok = refract(i, m, eta_ratio)
    t_weight = np.where(ok & (t[..., 2] < 0.0), smith_g1(t[..., 2], alpha), 0.0)
    return r, r_weight, t, t_weight, f


# --------------------------------------------------------------------------------------------
# scattering


def henyey_greenstein(cos_theta, g):
    """Henyey–Greenstein phase function [1/sr], normalised to 1 over the sphere."""
    return (1.0 - g * g) / (4.0 * np.pi * (1.0 + g * g - 2.0 * g * cos_theta) ** 1.5)


def _sample_henyey_greenstein(d, g, rng):
    """New propagation directions scattered from ``d`` (P, 3)."""
    p = d.shape[0]
    u = rng.random(p)
    if abs(g) < 1e-6:
        cos_t = 2.0 * u - 1.0
    else:
        s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
        cos_t = np.clip((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0)
    sin_t = np.sqrt(np.maximum(1.0 - cos_t**2, 0.0))
    phi = 2.0 * np.pi * rng.random(p)
    b1, b2 = _orthonormal_basis(d)
    new = (sin_t * np.cos(phi))[:, None] * b1 + (sin_t * np.sin(phi))[:, None] * b2 + cos_t[:, None] * d
    return _normalize(new)


def _sample_cosine_up(p, rng):
    """Cosine-distributed upward directions (Lambertian emission), (p, 3)."""
    r = np.sqrt(rng.random(p))
    phi = 2.0 * np.pi * rng.random(p)
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1.0 - r * r, 0.0))], axis=-1)


def _flip_z(v):
    return v * np.array([1.0, 1.0, -1.0])


# --------------------------------------------------------------------------------------------
# the Monte Carlo


@dataclass
class MonteCarloResult:
    """Estimates at the requested views.

    Attributes
    ----------
    brdf, standard_error : numpy.ndarray
        BRDF [1/sr] of the requested part and its Monte Carlo standard error, shape (V,).
    surface : numpy.ndarray
        The first-surface lobe (Walter, analytic) [1/sr], shape (V,).
    body, body_standard_error : numpy.ndarray
        The body part and its standard error [1/sr], shape (V,).
    body_covariance : numpy.ndarray
        Covariance of the body estimates [1/sr^2], shape (V, V) (the views share photons), so
        that a weighted sum ``w @ body`` has standard error ``sqrt(w @ body_covariance @ w)``.
    energy : dict
        Fractions of the incident power (each with ``<key>_standard_error``):
        ``surface_reflected`` (first-surface reflection into air), ``body_escaped`` (left the
        layer into air), ``microfacet_loss`` (lost by the single-scattering BSDF, at entry and
        at every internal hit), ``absorbed`` (pigment and substrate).
    n_events : int
        Scattering and substrate events traced (the cost).
    """

    brdf: np.ndarray
    standard_error: np.ndarray
    surface: np.ndarray
    body: np.ndarray
    body_standard_error: np.ndarray
    body_covariance: np.ndarray
    energy: dict = field(default_factory=dict)
    n_events: int = 0


def _check(theta_i, views, a, tau, g, r_s, n, alpha, n_photons, part):
    if part not in PARTS:
        raise ValueError(f"part must be one of {PARTS}, got {part!r}")
    if not 0.0 <= theta_i < 90.0:
        raise ValueError(f"theta_i must be in [0, 90) degrees, got {theta_i}")
    if views.ndim != 2 or views.shape[1] != 2:
        raise ValueError("views must be a sequence of (theta_o, delta_phi) pairs [deg]")
    if np.any((views[:, 0] < 0) | (views[:, 0] >= 90)):
        raise ValueError("views: theta_o must be in [0, 90) degrees")
    if not 0.0 <= a <= 1.0:
        raise ValueError(f"a must be in [0, 1], got {a}")
    if not tau > 0.0:
        raise ValueError(f"tau must be > 0 (inf for an opaque layer), got {tau}")
    if not abs(g) < 1.0:
        raise ValueError(f"g must be in (-1, 1) (Henyey-Greenstein only), got {g}")
    if not 0.0 <= r_s <= 1.0:
        raise ValueError(f"r_s must be in [0, 1], got {r_s}")
    if not n >= 1.0:
        raise ValueError(f"n must be >= 1, got {n}")
    if not alpha > 0.0:
        raise ValueError(f"alpha must be > 0 (a rough surface), got {alpha}")
    if not (isinstance(n_photons, (int, np.integer)) and n_photons > 1):
        raise ValueError(f"n_photons must be an integer > 1, got {n_photons!r}")


def monte_carlo_brdf(theta_i, views, *, a, tau, g=0.0, r_s=0.0, n=1.45, alpha,
                     n_photons=100_000, seed=0, part="total", batch_size=DEFAULT_BATCH):
    """BRDF of the rough-surfaced layer at fixed views, by Monte Carlo with next-event estimation.

    Parameters
    ----------
    theta_i : float
        Incidence angle in air [deg], in [0, 90).
    views : array_like, shape (V, 2)
        Viewing directions ``(theta_o, delta_phi)`` in air [deg]; ``delta_phi = 180`` is the
        specular side.
    a : float
        Relative absorption ``1 - omega`` [-].
    tau : float
        Optical thickness [-]; ``numpy.inf`` for a semi-infinite layer.
    g : float, optional
        Henyey–Greenstein parameter, |g| < 1.
    r_s : float, optional
        Lambertian substrate albedo seen from the binder [-] (ignored when ``tau = inf``).
    n : float, optional
        Refractive index of the binder [-], >= 1.
    alpha : float
        GGX roughness of the top surface (> 0).
    n_photons : int, optional
        Photons traced (the standard error falls as ``n_photons ** -0.5``).
    seed : int or numpy.random.SeedSequence, optional
        Seed of the ``numpy.random.Generator`` that draws every random number.
    part : {"total", "body", "surface"}
        Which BRDF ``brdf`` holds (the surface part is analytic, standard error 0).
    batch_size : int, optional
        Photons traced together.

    Returns
    -------
    MonteCarloResult
    """
    views = np.atleast_2d(np.asarray(views, dtype=float))
    theta_i, a, tau, g, r_s, n, alpha = (float(x) for x in (theta_i, a, tau, g, r_s, n, alpha))
    _check(theta_i, views, a, tau, g, r_s, n, alpha, n_photons, part)
    incident = air_direction(theta_i)
    outgoing = air_direction(views[:, 0], views[:, 1])
    surface = walter_reflection(incident[None, :], outgoing, n, alpha)
    if part == "surface":
        zero = np.zeros(len(views))
        return MonteCarloResult(surface.copy(), zero, surface, zero, zero, np.zeros((len(views),) * 2))

    body, covariance, energy, n_events = _run(incident, outgoing, a, tau, g, r_s, n, alpha,
                                              n_photons, seed, batch_size)
    body_error = np.sqrt(np.diag(covariance))
    value = body + surface if part == "total" else body
    return MonteCarloResult(value, body_error, surface, body, body_error, covariance, energy, n_events)


def monte_carlo_albedo(theta_i, *, a, tau, g=0.0, r_s=0.0, n=1.45, alpha, n_photons=100_000,
                       seed=0, batch_size=DEFAULT_BATCH):
    """Body's directional–hemispherical reflectance by next-event estimation, and the energy account.

    Every event scores toward one cosine-distributed air direction of its own (``pi`` times
    the BRDF estimate there), so the estimate integrates the same next-event scores as
    :func:`monte_carlo_brdf` over the hemisphere without a quadrature.  Parameters as
    :func:`monte_carlo_brdf`.

    Returns
    -------
    albedo, standard_error : float
        The body's directional–hemispherical reflectance [-] (fraction of the incident power
        leaving the layer into air, next-event estimate) and its standard error.
    energy : dict
        The analog energy account (see :class:`MonteCarloResult`).
    """
    theta_i, a, tau, g, r_s, n, alpha = (float(x) for x in (theta_i, a, tau, g, r_s, n, alpha))
    _check(theta_i, np.zeros((1, 2)), a, tau, g, r_s, n, alpha, n_photons, "body")
    body, covariance, energy, _ = _run(air_direction(theta_i), None, a, tau, g, r_s, n, alpha,
                                       n_photons, seed, batch_size)
    return float(body[0]), float(np.sqrt(covariance[0, 0])), energy


ENERGY_KEYS = ("surface_reflected", "body_escaped", "microfacet_loss", "absorbed")


def _run(incident, outgoing, a, tau, g, r_s, n, alpha, n_photons, seed, batch_size):
    """Trace ``n_photons`` in batches; mean scores, their covariance, energy account, events."""
    rng = np.random.default_rng(seed)
    v = 1 if outgoing is None else outgoing.shape[0]
    score_sum = np.zeros(v)
    score_products = np.zeros((v, v))
    energy_sum = dict.fromkeys(ENERGY_KEYS, 0.0)
    energy_sq = dict.fromkeys(ENERGY_KEYS, 0.0)
    n_events = 0
    done = 0
    while done < n_photons:
        size = min(batch_size, n_photons - done)
        scores, energy, events = _trace_batch(size, incident, outgoing, a, tau, g, r_s, n, alpha, rng)
        score_sum += scores.sum(axis=0)
        score_products += scores.T @ scores
        for key in ENERGY_KEYS:
            energy_sum[key] += energy[key].sum()
            energy_sq[key] += (energy[key] ** 2).sum()
        n_events += events
        done += size
    mean = score_sum / n_photons
    covariance = (score_products / n_photons - np.outer(mean, mean)) / (n_photons - 1)
    energy_out = {}
    for key in ENERGY_KEYS:
        m = energy_sum[key] / n_photons
        energy_out[key] = m
        energy_out[key + "_standard_error"] = np.sqrt(max(energy_sq[key] / n_photons - m * m, 0.0) / (n_photons - 1))
    return mean, covariance, energy_out, n_events


def _next_event(outgoing, depth, emission, n, alpha, rng):
    """Score of events at ``depth`` (P,) toward the air views ``outgoing`` (V, 3).

    ``emission(up)`` gives each event's emitted weight per steradian (P, V) for upward
    propagation directions ``up`` (P, V, 3).  Returns (P, V).  With ``outgoing=None`` every
    event draws its own cosine-distributed view and scores ``pi`` times its BRDF estimate, an
    estimate of the body's directional-hemispherical reflectance (P, 1).
    """
    p = depth.shape[0]
    if outgoing is None:
        o, factor = _sample_cosine_up(p, rng)[:, None, :], np.pi
    else:
        o, factor = np.broadcast_to(outgoing, (p,) + outgoing.shape), 1.0
    v = o.shape[1]
    m = sample_visible_normal(o, alpha, rng.random((p, v)), rng.random((p, v)))
    f = fresnel_unpolarised(_dot(o, m), n)
    i, ok = refract(o, m, 1.0 / n)
    mu_i = -i[..., 2]
    ok &= mu_i > 0.0
    mu_safe = np.where(ok, mu_i, 1.0)
    weight = factor * (1.0 - f) * smith_g1(mu_safe, alpha) / (n * n * mu_safe)
    return np.where(ok, emission(-i) * weight * np.exp(-depth[:, None] / mu_safe), 0.0)


def _scattered(weight, direction, g, up):
    """Weight per steradian scattered from ``direction`` (P, 3) into ``up`` (P, V, 3)."""
    return weight[:, None] * henyey_greenstein(_dot(direction[:, None, :], up), g)


def _lambertian(weight, up):
    """Weight per steradian a Lambertian surface emits into ``up`` (P, V, 3)."""
    return weight[:, None] * up[..., 2] / np.pi


def _trace_batch(size, incident, outgoing, a, tau, g, r_s, n, alpha, rng):
    """Trace ``size`` photons; per-photon scores (size, V), energy account, events traced.

    ``outgoing`` (V, 3) are the air views, or None for the hemispherical estimate (V = 1).
    """
    v = 1 if outgoing is None else outgoing.shape[0]
    omega = 1.0 - a
    scores = np.zeros((size, v))
    energy = {key: np.zeros(size) for key in ENERGY_KEYS}

    # entry from air: the reflected share is the (analytic) surface part; the body gets the rest
    i_air = np.broadcast_to(incident, (size, 3))
    r, r_w, t, t_w, f = interface_sample(i_air, 1.0 / n, alpha, rng)
    energy["surface_reflected"] += f * r_w
    energy["microfacet_loss"] += f * (1.0 - r_w) + (1.0 - f) * (1.0 - t_w)
    weight = (1.0 - f) * t_w
    direction = t.copy()  # propagation direction, z < 0
    depth = np.zeros(size)
    index = np.arange(size)
    alive = weight > 0.0
    index, weight, direction, depth = index[alive], weight[alive], direction[alive], depth[alive]
    n_events = 0
    for _ in range(MAX_EVENTS):
        if index.size == 0:
            break
        p = index.size
        path = -np.log1p(-rng.random(p))
        mu = direction[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            to_top = np.where(mu > 0.0, depth / mu, np.inf)
            to_bottom = np.where(mu < 0.0, (tau - depth) / -mu, np.inf)
        top = path >= to_top
        bottom = path >= to_bottom
        scatter = ~(top | bottom)

        # scattering: next event toward every view, then the new direction
        k = np.flatnonzero(scatter)
        if k.size:
            new_depth = depth[k] - path[k] * mu[k]
            d = direction[k]
            w = weight[k]
            scores[index[k]] += _next_event(
                outgoing, new_depth, partial(_scattered, w * omega, d, g), n, alpha, rng)
            energy["absorbed"][index[k]] += w * a
            weight[k] = w * omega
            depth[k] = new_depth
            direction[k] = _sample_henyey_greenstein(d, g, rng)
            n_events += k.size

        # substrate: Lambertian re-emission with albedo r_s
        k = np.flatnonzero(bottom)
        if k.size:
            w = weight[k]
            scores[index[k]] += _next_event(
                outgoing, np.full(k.size, tau), partial(_lambertian, w * r_s), n, alpha, rng)
            energy["absorbed"][index[k]] += w * (1.0 - r_s)
            weight[k] = w * r_s
            depth[k] = tau
            direction[k] = _sample_cosine_up(k.size, rng)
            n_events += k.size

        # the top from inside: reflect with probability F, else leave into air
        k = np.flatnonzero(top)
        leaving = np.zeros(p, dtype=bool)
        if k.size:
            w = weight[k]
            i_local = -_flip_z(direction[k])  # toward where the light comes from, z > 0 locally
            r, r_w, t, t_w, f = interface_sample(i_local, n, alpha, rng)
            reflected = rng.random(k.size) < f
            energy["microfacet_loss"][index[k]] += w * np.where(reflected, 1.0 - r_w, 1.0 - t_w)
            energy["body_escaped"][index[k]] += np.where(reflected, 0.0, w * t_w)
            weight[k] = np.where(reflected, w * r_w, 0.0)
            direction[k] = _flip_z(r)  # back into the binder, z < 0
            depth[k] = 0.0
            leaving[k] = ~reflected

        # Russian roulette
        low = (weight < ROULETTE_WEIGHT) & (weight > 0.0)
        if low.any():
            survive = rng.random(p) < ROULETTE_SURVIVAL  # unbiased: survivors carry the killed weight
            weight = np.where(low, np.where(survive, weight / ROULETTE_SURVIVAL, 0.0), weight)
        keep = (weight > 0.0) & ~leaving
        index, weight, direction, depth = index[keep], weight[keep], direction[keep], depth[keep]
    else:
        raise RuntimeError(f"a photon walk exceeded {MAX_EVENTS} steps")
    return scores, energy, n_events


# --------------------------------------------------------------------------------------------
# comparison with a deterministic solver


#: Cases for :func:`compare_with_solver` (issue 16: several alpha, g, a, tau, r_s; in- and
#: out-of-plane views).  ``views`` are (theta_o, delta_phi) pairs [deg].
SOLVER_VIEWS = ((0.0, 0.0), (30.0, 0.0), (60.0, 0.0), (15.0, 180.0), (30.0, 180.0),
                (60.0, 180.0), (45.0, 90.0), (30.0, 135.0))
#: Grazing views (the slow comparison adds them; measured against the rough solver of 59d86c7:
#: within 2.6 standard errors, <= 0.6 %).
GRAZING_VIEWS = ((75.0, 0.0), (80.0, 180.0), (85.0, 90.0))
SOLVER_CASES = tuple(
    {"theta_i": theta_i, "alpha": alpha, "g": g, "a": a, "tau": tau, "r_s": r_s, "n": 1.45, "views": SOLVER_VIEWS}
    for theta_i, alpha, g, a, tau, r_s in (
        (45.0, 0.05, 0.0, 0.3, 1.0, 0.8),
        (45.0, 0.2, 0.0, 0.01, np.inf, 0.0),
        (30.0, 0.2, 0.6, 0.3, 1.0, 0.0),
        (60.0, 0.5, 0.6, 0.01, 1.0, 0.8),
        (45.0, 0.5, 0.0, 0.3, np.inf, 0.0),
        (20.0, 0.05, 0.6, 0.01, np.inf, 0.0),
    )
)


def compare_with_solver(brdf_function, cases=SOLVER_CASES, *, parts=("body", "total"), n_photons=100_000,
                        seed=0):
    """Compare a BRDF function against the Monte Carlo, case by case.

    Parameters
    ----------
    brdf_function : callable
        Called as ``brdf_function(theta_i, theta_o, delta_phi, a=, tau=, g=, r_s=, n=,
        roughness=alpha, part=part)`` with arrays of the views; returns BRDF [1/sr].
    cases : sequence of dict
        Keys ``theta_i, alpha, g, a, tau, r_s, n, views`` (as :data:`SOLVER_CASES`), and
        optionally ``n_photons`` (overrides the argument for that case).
    parts : sequence of {"total", "body", "surface"}
        The parts compared (one Monte Carlo run per case serves them all; "surface" is
        Walter's formula, standard error 0).
    n_photons, seed : int
        Monte Carlo photons per case and the seed (case ``k`` uses ``(seed, k)``).

    Returns
    -------
    list of dict
        One per case, part and view: the case's parameters, ``part``, ``theta_o``,
        ``delta_phi``, ``solver``, ``monte_carlo``, ``standard_error`` [1/sr],
        ``relative_difference`` (solver / MC - 1) and ``sigmas`` (difference in standard
        errors).
    """
    rows = []
    for number, case in enumerate(cases):
        views = np.asarray(case["views"], dtype=float)
        mc = monte_carlo_brdf(case["theta_i"], views, a=case["a"], tau=case["tau"], g=case["g"],
                              r_s=case["r_s"], n=case["n"], alpha=case["alpha"],
                              n_photons=case.get("n_photons", n_photons), seed=(seed, number), part="body")
        reference = {"body": (mc.body, mc.body_standard_error),
                     "surface": (mc.surface, np.zeros_like(mc.surface)),
                     "total": (mc.body + mc.surface, mc.body_standard_error)}
        for part in parts:
            solver = np.asarray(brdf_function(case["theta_i"], views[:, 0], views[:, 1], a=case["a"],
                                              tau=case["tau"], g=case["g"], r_s=case["r_s"], n=case["n"],
                                              roughness=case["alpha"], part=part), dtype=float)
            value, error = reference[part]
            for k, (theta_o, delta_phi) in enumerate(views):
                difference = solver[k] - value[k]
                with np.errstate(divide="ignore", invalid="ignore"):
                    sigmas = (difference / error[k] if error[k] > 0
                              else 0.0 if difference == 0 else np.copysign(np.inf, difference))
                    relative = difference / value[k] if value[k] != 0 else (0.0 if difference == 0 else np.inf)
                rows.append({**{key: case[key] for key in ("theta_i", "alpha", "g", "a", "tau", "r_s", "n")},
                             "part": part, "theta_o": theta_o, "delta_phi": delta_phi,
                             "solver": solver[k], "monte_carlo": value[k], "standard_error": error[k],
                             "relative_difference": relative, "sigmas": sigmas})
    return rows
