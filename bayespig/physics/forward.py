"""The paint-layer forward model: BRDF and hemispherical reflectance from air.

The paint is a layer of binder (index ``n``) carrying pigment (relative absorption
``a``, optical thickness ``tau``, phase-function parameter ``g``), under a smooth
air/binder surface and on a Lambertian substrate of albedo ``r_s`` seen from the
binder (paper section 2, eq. 1). Each azimuthal mode of the layer under its surface
is solved by the discrete-ordinate method with the surface's internal reflection as
the top boundary (:func:`surface_mode_eigen`, :mod:`bayespig.physics.discrete_ordinates`),
equivalent to adding the surface to the layer's kernels by the self-consistent
equation (8) of appendix A1; the substrate enters by the exact substrate law,
eq. (3). Adding–doubling (:mod:`bayespig.physics.adding_doubling`) with
:func:`surface_mode` is the cross-check (``solver="doubling"``) and the path for
nearly conservative finite layers.

A rough top surface (``roughness > 0``: Walter et al. 2007 microfacets, DESIGN.md "Rough top
surface") takes :func:`~bayespig.physics.rough_surface.rough_surface_terms` instead: the same
modes and quadrature, the surface's kernels integrated against the quadrature's interpolation
basis (product integration), the same substrate law; the BRDF then includes the surface's own
lobe (``part="total"``; :func:`first_surface_brdf`). ``roughness = 0`` runs the smooth code
unchanged.

Effect pigments (metal or pearlescent flakes) add a coloured lobe around the mirror direction
that neither the body nor the surface has: :func:`flake_brdf` is its shape per unit flake
reflectance (mirror flakes in the binder with GGX orientations, seen through the surface;
:func:`bayespig.physics.microfacet.flake_reflection_brdf`), added by the inference's forward model
with a reflectance per band (``infer(..., flakes=True)``). It is a single-bounce term outside the
layer solve: the body's light reflected by flakes, and the flakes' shading of the body, are not
modelled.

Angles are in degrees, in air: ``theta_i`` incidence, ``theta_o`` viewing and
``delta_phi`` the azimuth between the plane of incidence and the plane of viewing,
``delta_phi = 180`` on the specular side, ``0`` back towards the source.
"""

from __future__ import annotations

import functools
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from threadpoolctl import ThreadpoolController

from .adding_doubling import (
    START_THICKNESS,
    START_THICKNESS_HIGHER_MODES,
    add_lambertian_substrate,
    layer_mode,
)
from .discrete_ordinates import SMALL_ABSORPTION, THIN_LAYER, radiances_under_surface
from .fresnel import fresnel_reflectance, normal_transmittance, refracted_cosine
from .microfacet import DISTRIBUTIONS, directional_albedo, flake_reflection_brdf, reflection_brdf
from .phase import ModeStopping, is_rayleigh, n_fourier_modes, normalise_on_quadrature, phase_fourier_modes
from .quadrature import DEFAULT_QUADRATURE_POINTS, binder_quadrature, default_quadrature_points
from .rough_surface import ROUGHNESS_MAX, rough_surface_terms

__all__ = [
    "BRDF_PARTS",
    "SMOOTH_BELOW",
    "SPECULAR_CONE_HALF_ANGLE",
    "SurfaceGeometry",
    "SurfaceTerms",
    "binder_index",
    "brdf",
    "first_surface_brdf",
    "flake_brdf",
    "hemispherical_reflectance",
    "mode_terms",
    "optical_thickness_from_transmittance",
    "quadrature_points",
    "specular_port_reflectance",
    "specular_transmittance",
    "surface_geometry",
    "surface_mode",
    "surface_mode_eigen",
    "surface_roughness",
    "surface_terms",
    "validate_layer_arguments",
]

#: A Fourier mode is negligible once it is this small relative to mode 0 over black (at the
#: same geometry and parameters), twice in a row; modes of Henyey-Greenstein decay
#: geometrically, so the rest sums to about as much.
MODE_TOLERANCE = 1e-6
#: A parameter set's azimuthal modes move to the coarse quadrature (:func:`coarse_quadrature_points`)
#: once one of them is below this fraction of its mode 0 at every geometry.
COARSE_AFTER = 3e-2
#: Fewest Gauss points per interval of the coarse quadrature.
COARSE_MIN_POINTS = 4
#: Parameter sets solved together, one job per worker thread at a time (chunks of 1024 measured
#: 1.25-1.33x slower isotropic, the same at g = 0.5: benchmarks/forward_settings.py).
CHUNK = 256
#: Threads solving chunks concurrently.
THREADS = min(2, os.cpu_count() or 1)
#: Layer solvers of :func:`surface_terms`.
SOLVERS = ("eigen", "doubling")
#: What :func:`brdf` returns: light that entered the layer plus the first-surface lobe, one of
#: them alone.
BRDF_PARTS = ("total", "body", "surface")
#: A roughness below this is solved as the smooth surface (the body; the first-surface lobe
#: stays Walter's analytic one): there the rough solve equals the smooth one to < 1e-5
#: (tests/physics/test_rough_surface.py), and the fine rules would only grow.
SMOOTH_BELOW = 1e-4
#: Half-angle of the specular port (gloss trap) of an 8 deg/d sphere [deg], the cone around the
#: mirror direction whose first-surface reflection SCE excludes. An assumed default: ports
#: differ between instruments, so pass an instrument's own value as ``specular_cone``.
SPECULAR_CONE_HALF_ANGLE = 5.0
#: Gauss-Legendre points per panel (in the angle from the mirror direction) and azimuth nodes
#: around it of :func:`specular_port_reflectance`.
_PORT_POINTS = 8
_PORT_AZIMUTHS = 96


@functools.cache
def _blas_controller():
    """The process's BLAS libraries, found once (inspecting them takes ~0.4 ms)."""
    return ThreadpoolController()


def _describe(value):
    """Short text of an argument's value for an error message."""
    if isinstance(value, np.ndarray) and value.ndim > 0:
        return f"an array of dtype {value.dtype} and shape {value.shape}"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _real_array(name, value):
    """``value`` as a float array; ``TypeError`` naming ``name`` unless it holds real numbers."""
    message = f"{name} must be a real number or an array of real numbers, got "
    if value is None or isinstance(value, (str, bytes)):
        raise TypeError(message + _describe(value))
    try:
        array = np.asarray(value)
    except ValueError:  # a ragged sequence
        raise TypeError(message + f"a ragged sequence {_describe(value)}") from None
    if array.dtype.kind not in "iuf":  # bool, complex, strings, objects
        raise TypeError(message + _describe(value))
    return array.astype(float, copy=False)


def _first(values, bad):
    """The first offending element, for the message."""
    return f"{np.asarray(values)[bad].flat[0]:g}"


def _check_finite(name, value):
    if np.isnan(value).any():
        raise ValueError(f"{name} must not be NaN")


def binder_index(n):
    """The binder's refractive index as a float; ``TypeError``/``ValueError`` naming ``n``.

    Parameters
    ----------
    n : float
        Refractive index of the binder, a single finite real number ``>= 1`` [-].

    Returns
    -------
    float
    """
    message = "n (binder refractive index) must be a finite real number >= 1, got "
    if n is None or isinstance(n, (str, bytes, bool, np.bool_)):
        raise TypeError(message + _describe(n))
    try:
        value = np.asarray(n)
    except ValueError:
        raise TypeError(message + _describe(n)) from None
    if value.dtype.kind not in "iuf":
        raise TypeError(message + _describe(n))
    if value.ndim != 0:
        raise ValueError(f"n (binder refractive index) must be a single number (one binder per call), "
                         f"got {_describe(n)}")
    if not np.isfinite(value) or value < 1.0:
        raise ValueError(message + f"{float(value):g}")
    return float(value)


def quadrature_points(n_points):
    """Gauss points per quadrature interval, checked; ``None`` (the default) passes through.

    Parameters
    ----------
    n_points : int or None
        An integer ``>= 2``.

    Returns
    -------
    int or None
    """
    if n_points is None:
        return None
    message = "n_points must be an integer >= 2 (Gauss points per quadrature interval) or None, got "
    if isinstance(n_points, (bool, np.bool_)) or not isinstance(n_points, (int, np.integer)):
        raise TypeError(message + _describe(n_points))
    if n_points < 2:
        raise ValueError(message + _describe(n_points))
    return int(n_points)


def validate_layer_arguments(*, a, tau, g, r_s, n):
    """Check the physical parameters of a paint layer; raise ``ValueError`` (a bad value) or
    ``TypeError`` (not real numbers) naming the bad one.

    Parameters
    ----------
    a : array_like
        Relative absorption in [0, 1] [-].
    tau : array_like
        Optical thickness, ``>= 0``, ``inf`` allowed [-].
    g : array_like
        Phase-function parameter: HG in (-1, 1), Rayleigh outside [-1, 1].
    r_s : array_like
        Substrate albedo seen from the binder, in [0, 1] [-].
    n : float
        Refractive index of the binder, ``>= 1`` [-].
    """
    a, tau, g, r_s = (_real_array(name, v) for name, v in (("a", a), ("tau", tau), ("g", g), ("r_s", r_s)))
    for name, value in (("a", a), ("tau", tau), ("g", g), ("r_s", r_s)):
        _check_finite(name, value)
    bad = (a < 0) | (a > 1)
    if bad.any():
        raise ValueError(f"a (relative absorption) must lie in [0, 1], got {_first(a, bad)}")
    if (tau < 0).any():
        raise ValueError(f"tau (optical thickness) must be >= 0, got {_first(tau, tau < 0)}")
    bad = (r_s < 0) | (r_s > 1)
    if bad.any():
        raise ValueError(f"r_s (substrate albedo) must lie in [0, 1], got {_first(r_s, bad)}")
    bad = np.isinf(g) | (np.abs(g) == 1.0)
    if bad.any():
        raise ValueError(f"g must be finite and not +-1 (|g| > 1 selects Rayleigh), got {_first(g, bad)}")
    binder_index(n)


def surface_roughness(roughness):
    """The surface roughness as a float; ``TypeError``/``ValueError`` naming ``roughness``.

    Parameters
    ----------
    roughness : float
        GGX's ``alpha`` of the air/binder surface, one real number in
        [0, :data:`~bayespig.physics.rough_surface.ROUGHNESS_MAX`] [-]; 0 is the smooth surface.

    Returns
    -------
    float
    """
    message = (f"roughness (microfacet alpha of the top surface) must be a finite real number in [0, {ROUGHNESS_MAX:g}], "
               "got ")
    if roughness is None or isinstance(roughness, (str, bytes, bool, np.bool_)):
        raise TypeError(message + _describe(roughness))
    try:
        value = np.asarray(roughness)
    except ValueError:
        raise TypeError(message + _describe(roughness)) from None
    if value.dtype.kind not in "iuf":
        raise TypeError(message + _describe(roughness))
    if value.ndim != 0:
        raise ValueError("roughness (microfacet alpha of the top surface) must be a single number (one surface "
                         f"per call), got {_describe(roughness)}")
    if not np.isfinite(value) or value < 0.0:
        raise ValueError(message + f"{float(value):g}")
    if value > ROUGHNESS_MAX:
        raise ValueError(message + f"{float(value):g} (beyond {ROUGHNESS_MAX:g} the single-scattering microfacet "
                         "model loses a third or more of the light it should scatter between facets, and its "
                         "quadrature is not verified)")
    return float(value)


def _distribution(distribution):
    if not isinstance(distribution, str) or distribution not in DISTRIBUTIONS:
        raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {_describe(distribution)}")
    return distribution


def _is_rough(roughness, n):
    """Whether the rough solve applies (an index-matched surface does not scatter at all)."""
    return roughness >= SMOOTH_BELOW and n > 1.0


def _validate_angle(name, theta):
    theta = _real_array(name, theta)
    _check_finite(name, theta)
    bad = (theta < 0) | (theta >= 90)
    if bad.any():
        raise ValueError(f"{name} must lie in [0, 90) degrees, got {_first(theta, bad)}")
    return theta


@dataclass(frozen=True)
class SurfaceTerms:
    """Everything the layer under its surface contributes, for one ``g``.

    For a batch of ``B`` (a, tau) pairs, incidence directions ``k_in`` and viewing
    directions ``k_out`` (all in air), the quantities of the substrate law (eq. 3):
    ``f(v, u; r_s) = f0(v, u) + r_s t_down(v) t_up(u) / (1 - r_s r_up)``.

    Attributes
    ----------
    f0_modes : numpy.ndarray
        Fourier modes ``f0_m`` of the BRDF over a black substrate, shape
        (B, M, k_out, k_in) [1/sr]; ``f0 = sum_m (2 - delta_m0) f0_m (-1)^m cos(m delta_phi)``.
    t_down : numpy.ndarray
        Irradiance on the substrate per unit incident irradiance, (B, k_in) [-].
    t_up : numpy.ndarray
        Air radiance per unit exitance leaving the substrate, (B, k_out) [1/sr].
    r_up : numpy.ndarray
        Fraction of the substrate's exitance that returns to it, (B,) [-]; 0 for an opaque
        layer, which never sees its substrate (``t_down = t_up = 0``; a conservative one would
        return all of it, and ``r_s / (1 - r_s r_up)`` would be 1/0 at ``r_s = 1``).
    h0 : numpy.ndarray
        Directional–hemispherical reflectance over a black substrate, specular
        reflection of the surface excluded, (B, k_in) [-].
    t_up_hemispherical : numpy.ndarray
        Exitance into air per unit exitance leaving the substrate, (B,) [-].
    """

    f0_modes: np.ndarray
    t_down: np.ndarray
    t_up: np.ndarray
    r_up: np.ndarray
    h0: np.ndarray
    t_up_hemispherical: np.ndarray

    def brdf(self, delta_phi, r_s):
        """BRDF [1/sr], shape (B, k_out, k_in), for ``delta_phi`` [deg] broadcastable to it and ``r_s`` (B,)."""
        m = np.arange(self.f0_modes.shape[1])
        weights = (2.0 - (m == 0)) * (-1.0) ** m * np.cos(m * np.radians(np.asarray(delta_phi, dtype=float))[..., None])
        f0 = (np.moveaxis(self.f0_modes, 1, -1) * weights).sum(axis=-1)
        gain = self.substrate_gain(np.asarray(r_s, dtype=float)[:, None, None])
        return f0 + gain * self.t_up[:, :, None] * self.t_down[:, None, :]

    def substrate_gain(self, r_s):
        """``r_s / (1 - r_s r_up)`` of eq. (3), with ``r_s`` broadcast against (B, ...)."""
        r_up = self.r_up.reshape(self.r_up.shape + (1,) * (np.ndim(r_s) - 1))
        return r_s / (1.0 - r_s * r_up)

    def hemispherical(self, r_s):
        """Directional–hemispherical reflectance (specular excluded) [-], shape (B, k_in)."""
        r = np.asarray(r_s, dtype=float)[:, None]
        return self.h0 + self.substrate_gain(r) * self.t_down * self.t_up_hemispherical[:, None]


def surface_terms(theta_in, theta_out, *, a, tau, g=0.0, n=1.45, n_points=None,
                  n_modes=None, start_thickness=START_THICKNESS, included_substrate=None, solver="eigen",
                  roughness=0.0, distribution="ggx"):
    """Solve the layer under its surface once for a batch of (a, tau) pairs.

    Parameters
    ----------
    theta_in, theta_out : array_like
        Incidence and viewing angles in air [deg], shapes (k_in,) and (k_out,).
    a, tau : array_like
        Relative absorption and optical thickness, shape (B,) [-]; ``tau`` may
        mix finite values and ``inf``.
    g : float
        Phase-function parameter, one value for the batch.
    n : float
        Refractive index of the binder [-].
    n_points : int, optional
        Gauss points per quadrature interval; by default
        :func:`~bayespig.physics.quadrature.default_quadrature_points` for ``g`` (converged to
        1e-4). A parameter set's azimuthal modes below ``COARSE_AFTER`` of its mode 0 go on
        :func:`coarse_quadrature_points` of them.
    n_modes : int, optional
        Number of azimuthal modes; by default as many as needed until a mode adds
        less than ``MODE_TOLERANCE`` (one for isotropic scattering).
    start_thickness : float
        Thickness of the single-scattering starting layer [-].
    included_substrate : array_like, optional
        Substrate albedo, shape (B,), to include *in the solve* (adding the
        substrate as a layer) instead of through eq. (3): ``f0_modes`` is then the
        BRDF over that substrate. An independent check of the substrate law; it
        takes the doubling path.
    solver : {"eigen", "doubling"}
        ``"eigen"``: the discrete-ordinate solution with the surface as its top boundary
        (:func:`surface_mode_eigen`), one N x N solve per layer and mode; ``"doubling"``:
        adding-doubling of the layer's kernels and the surface added by :func:`surface_mode`.
        Both solve the same discrete equations (they agree to ~1e-7 of each term).
        A rough surface has its own solve (:func:`~bayespig.physics.rough_surface.rough_surface_terms`).
    roughness : float
        GGX ``alpha`` of the top surface [-]; 0 (below :data:`SMOOTH_BELOW`, or ``n = 1``) is
        the smooth surface. For a rough one the terms are the *body*'s (the light that entered
        the layer); the first-surface lobe is :func:`brdf`'s ``part="surface"``.
    distribution : {"ggx", "beckmann"}
        Microfacet distribution of a rough surface.

    Returns
    -------
    SurfaceTerms
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    n, n_points = binder_index(n), quadrature_points(n_points)
    roughness, distribution = surface_roughness(roughness), _distribution(distribution)
    if n_points is None:
        n_points = default_quadrature_points(g)
    if _is_rough(roughness, n):
        if included_substrate is not None:
            raise ValueError("included_substrate is a check of the smooth surface's substrate law; "
                             "a rough surface takes the substrate by eq. (3) only")
        # small matrices: a single-threaded BLAS, as below (threads cost more than they give)
        with _blas_controller().limit(limits=1, user_api="blas"):
            return SurfaceTerms(**rough_surface_terms(
                theta_in, theta_out, a=a, tau=tau, g=float(g), n=n, n_points=n_points, alpha=roughness,
                n_modes=n_modes, mode_tolerance=MODE_TOLERANCE, distribution=distribution,
                start_thickness=start_thickness))
    if included_substrate is not None:
        solver = "doubling"
    a = np.atleast_1d(np.asarray(a, dtype=float))
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    max_modes = n_fourier_modes(g) if n_modes is None else n_modes
    levels = []
    for points in dict.fromkeys((n_points, coarse_quadrature_points(n_points) if max_modes > 1 else n_points)):
        level = surface_geometry(theta_in, theta_out, n, points)
        p_refl = phase_fourier_modes(level.mu, level.mu, g, max_modes, reflection=True)
        p_trans = phase_fourier_modes(level.mu, level.mu, g, max_modes, reflection=False)
        levels.append((level, *normalise_on_quadrature(p_refl, p_trans, level.weight)))
    geometry = levels[0][0]
    jobs = []
    for opaque in (False, True):
        select = np.flatnonzero(np.isinf(tau) == opaque)
        jobs.extend(select[start:start + CHUNK] for start in range(0, select.size, CHUNK))
    adaptive = n_modes is None and not is_rayleigh(g)

    def solve(rows):
        substrate = None if included_substrate is None else np.asarray(included_substrate, float)[rows]
        return rows, _solve_chunk(levels, a[rows], tau[rows], adaptive, start_thickness, substrate, solver)

    # numpy's batched linear algebra releases the GIL: one chunk per core, each with a
    # single-threaded BLAS (BLAS threads split 32 x 32 products into pieces too small to pay
    # for their synchronisation and oversubscribe the cores: 1.4-1.6x slower, benchmarks/forward_settings.py)
    with _blas_controller().limit(limits=1, user_api="blas"):
        if len(jobs) > 1 and THREADS > 1:
            with ThreadPoolExecutor(max_workers=THREADS) as pool:
                results = list(pool.map(solve, jobs))
        else:
            results = [solve(rows) for rows in jobs]
    k_in, k_out = geometry.idx_in.size, geometry.idx_out.size
    B = a.size
    M = max(chunk["f0_modes"].shape[1] for _, chunk in results)
    out = {
        "f0_modes": np.zeros((B, M, k_out, k_in)),
        "t_down": np.zeros((B, k_in)),
        "t_up": np.zeros((B, k_out)),
        "r_up": np.zeros(B),
        "h0": np.zeros((B, k_in)),
        "t_up_hemispherical": np.zeros(B),
    }
    for rows, chunk in results:
        for key, value in chunk.items():
            if key == "f0_modes":
                out[key][rows, : value.shape[1]] = value
            else:
                out[key][rows] = value
    out["r_up"][np.isinf(tau)] = 0.0
    return SurfaceTerms(**out)


@dataclass(frozen=True)
class SurfaceGeometry:
    """Quadrature and surface (Fresnel) factors shared by every solve of one direction set."""

    mu: np.ndarray
    weight: np.ndarray
    c: np.ndarray
    r_int: np.ndarray
    t_int: np.ndarray
    idx_in: np.ndarray
    idx_out: np.ndarray
    t_in: np.ndarray
    t_out: np.ndarray
    n: float

    @property
    def n_weighted(self):
        """Number of quadrature nodes with weight; the zero-weight measurement nodes follow them."""
        return int(np.count_nonzero(self.weight))


def surface_geometry(theta_in, theta_out, n=1.45, n_points=DEFAULT_QUADRATURE_POINTS):
    """Quadrature with the refracted measurement directions as zero-weight nodes.

    Parameters
    ----------
    theta_in, theta_out : array_like
        Incidence and viewing angles in air [deg], shapes (k_in,), (k_out,).
    n : float
        Refractive index of the binder [-].
    n_points : int
        Gauss points per quadrature interval.

    Returns
    -------
    SurfaceGeometry
    """
    theta_in = np.atleast_1d(np.asarray(theta_in, dtype=float))
    theta_out = np.atleast_1d(np.asarray(theta_out, dtype=float))
    mu_air = np.cos(np.radians(np.concatenate([theta_in, theta_out])))
    mu, weight = binder_quadrature(n_points, n, refracted_cosine(mu_air, 1.0, n))
    N0 = mu.size - mu_air.size
    r_int = fresnel_reflectance(mu, n, 1.0)
    return SurfaceGeometry(
        mu=mu, weight=weight, c=mu * weight, r_int=r_int, t_int=1.0 - r_int,
        idx_in=N0 + np.arange(theta_in.size), idx_out=N0 + theta_in.size + np.arange(theta_out.size),
        t_in=1.0 - fresnel_reflectance(mu_air[: theta_in.size], 1.0, n),
        t_out=1.0 - fresnel_reflectance(mu_air[theta_in.size:], 1.0, n), n=float(n),
    )


def surface_mode(geometry, R, T, direct, first_mode):
    """Add the air/binder surface (eq. 8) to one azimuthal mode of a layer given by its kernels.

    The system ``(I - R c r_int) X = R[:, in]`` of eq. (8) is block-triangular, because the
    measurement directions (the last nodes) have zero weight: only its weighted block is
    solved, and the measurement rows follow as ``X = R[:, in] + R c r_int X``.

    Parameters
    ----------
    geometry : SurfaceGeometry
    R, T : numpy.ndarray
        Layer kernels of this mode, shape (B, N, N) [-]; ``T`` is used for mode 0 only.
    direct : numpy.ndarray
        Unscattered transmission of the layer, shape (B, N) [-]; mode 0 only.
    first_mode : bool
        True for mode 0, which also yields the substrate-law terms (eq. 3).

    Returns
    -------
    dict
        As :func:`mode_terms`.
    """
    gm = geometry
    q = gm.n_weighted
    c, r_int = gm.c[:q], gm.r_int[:q]
    coupling = c * r_int
    surface = np.eye(q) - R[:, :q, :q] * coupling
    rhs = R[:, :, gm.idx_in]
    if first_mode:
        # the radiance from a Lambertian substrate of unit radiance shares the factorisation
        rhs = np.concatenate([rhs, (direct + (T[:, :, :q] * c).sum(axis=-1))[:, :, None]], axis=-1)
    solved = np.linalg.solve(surface, rhs[:, :q])
    solved = rhs + (R[:, :, :q] * coupling) @ solved  # every row, the measurement directions included
    if not first_mode:
        return mode_terms(gm, solved[:, gm.idx_out], None, None, None, False)
    # light going down at the bottom: transmitted, plus the surface's reflection transmitted
    reflected_down = r_int[None, :, None] * solved[:, :q]
    down = (T[:, :q, :q] * c) @ reflected_down + direct[:, :q, None] * reflected_down
    down[..., :-1] += T[:, :q, gm.idx_in]
    down[..., -1] += (R[:, :q, :q] * c).sum(axis=-1)  # the substrate's light reflected by the layer
    return mode_terms(gm, solved[:, gm.idx_out], solved[:, :q], down, direct[:, gm.idx_in], True)


def mode_terms(geometry, up_view, up, down, direct_in, first_mode):
    """BRDF mode and substrate-law terms (eq. 3) from the radiances under the surface.

    Parameters
    ----------
    geometry : SurfaceGeometry
    up_view : numpy.ndarray
        Upward radiance under the surface along the viewing directions, (B, k_out, C) [-],
        per unit ``c I`` of a beam along each incidence direction (the first ``k_in``
        columns) and, for mode 0, per unit radiance of the substrate (the last column).
    up, down : numpy.ndarray
        Mode 0: the same at the weighted nodes, upward under the surface and downward at the
        substrate (diffuse), (B, N, C) [-].
    direct_in : numpy.ndarray
        Mode 0: unscattered transmission of the layer along the incidence directions, (B, k_in).
    first_mode : bool
        True for mode 0.

    Returns
    -------
    dict
        ``f_mode`` (B, k_out, k_in) [1/sr] and, for mode 0, ``t_down``, ``t_up``,
        ``r_up``, ``h0``, ``t_up_hemispherical`` as in :class:`SurfaceTerms`.
    """
    gm = geometry
    q, n = gm.n_weighted, gm.n
    c, t_int = gm.c[:q], gm.t_int[:q]
    k_in = gm.idx_in.size
    out = {"f_mode": gm.t_out[None, :, None] * up_view[..., :k_in] * gm.t_in[None, None, :] / (2.0 * np.pi * n * n)}
    if not first_mode:
        return out
    out["t_down"] = gm.t_in * (direct_in + np.einsum("j,bjk->bk", c, down[..., :k_in]))
    out["t_up"] = gm.t_out * up_view[..., -1] / (n * n * np.pi)
    out["r_up"] = 2.0 * down[..., -1] @ c
    out["h0"] = gm.t_in * np.einsum("j,bjk->bk", c * t_int, up[..., :k_in])
    out["t_up_hemispherical"] = 2.0 * (up[..., -1] @ (c * t_int))
    return out


def surface_mode_eigen(geometry, a, tau, p_reflection, p_transmission, first_mode, start_thickness):
    """:func:`surface_mode` without forming the layer's kernels: the discrete-ordinate solution
    with the surface as the top boundary (:func:`~bayespig.physics.discrete_ordinates.radiances_under_surface`).

    Finite layers with ``a <`` :data:`~bayespig.physics.discrete_ordinates.SMALL_ABSORPTION`
    (the eigen form of a finite layer degenerates as ``a -> 0``) or ``tau <``
    :data:`~bayespig.physics.discrete_ordinates.THIN_LAYER` (its O(1) terms cancel to an
    O(tau) result) go through doubling and :func:`surface_mode`; opaque layers never do (the
    eigen form is exact there down to ``a = 0``, where doubling loses ~1e-5 to 1e-4).

    Parameters
    ----------
    geometry : SurfaceGeometry
    a, tau : numpy.ndarray
        Relative absorption and optical thickness, (B,) [-]; ``tau`` all finite or all ``inf``.
    p_reflection, p_transmission : numpy.ndarray
        This mode of the phase function on the geometry's nodes, (N, N) [-].
    first_mode : bool
        True for mode 0.
    start_thickness : float
        Start of the doubling for the layers that take that path [-].

    Returns
    -------
    dict
        As :func:`mode_terms`.
    """
    gm = geometry
    doubled = ((a < SMALL_ABSORPTION) & np.isfinite(tau)) | (tau < THIN_LAYER)
    parts = []
    if doubled.any():
        R, T, direct = layer_mode(gm.mu, gm.weight, a[doubled], tau[doubled], p_reflection, p_transmission,
                                  start_thickness)
        parts.append((doubled, surface_mode(gm, R, T, direct, first_mode)))
    if not doubled.all():
        rows = ~doubled
        rad = radiances_under_surface(gm.mu, gm.weight, a[rows], tau[rows], p_reflection, p_transmission,
                                      gm.r_int[: gm.n_weighted], gm.idx_in, gm.idx_out, substrate=first_mode)
        direct_in = np.exp(-tau[rows, None] / gm.mu[gm.idx_in]) if first_mode else None
        parts.append((rows, mode_terms(gm, rad["up_view"], rad["up"], rad["down"], direct_in, first_mode)))
    if len(parts) == 1:
        return parts[0][1]
    out = {}
    for rows, part in parts:
        for key, value in part.items():
            if key not in out:
                out[key] = np.empty((a.size,) + value.shape[1:])
            out[key][rows] = value
    return out


def _solve_mode(level, m, a, tau, thickness, included_substrate, solver):
    """One azimuthal mode of the layer under its surface on the quadrature ``level``
    (geometry, reflection and transmission modes of the phase function): the dict of
    :func:`mode_terms`, and for an included substrate the black-substrate BRDF mode too."""
    geometry, p_refl, p_trans = level
    if solver == "eigen":
        return surface_mode_eigen(geometry, a, tau, p_refl[m], p_trans[m], m == 0, thickness), None
    R, T, direct = layer_mode(geometry.mu, geometry.weight, a, tau, p_refl[m], p_trans[m], thickness)
    black = None
    if m == 0 and included_substrate is not None:
        black = surface_mode(geometry, R, None, None, False)["f_mode"]
        R = add_lambertian_substrate(R, T, direct, geometry.c, included_substrate)
    return surface_mode(geometry, R, T, direct, m == 0), black


def _solve_chunk(levels, a, tau, adaptive, start_thickness, included_substrate, solver):
    """Layer, surface (eq. 8) and substrate-law terms (eq. 3), mode by mode, for one chunk.

    Each value (parameter set x geometry) stops at its own converged mode: after two modes in
    a row below ``MODE_TOLERANCE`` of its mode 0 over black (the azimuthal mean, which bounds
    every mode of a positive BRDF), so a result never depends on which other parameter sets
    or geometries share the call, nor on whether the substrate enters by eq. (3) or by a
    direct solve. Parameter sets whose values have all stopped are not solved further.

    ``levels`` are the full quadrature and a coarser one with the same exact directions. A
    parameter set's modes go to the coarse one once a mode of it is below ``COARSE_AFTER``
    of its mode 0 at every geometry: the modes that follow are smaller still (they decay
    geometrically), so the coarse quadrature's relative error, ~1e-3, costs them < 1e-5 of the
    BRDF (reports/validation.md: measured <= 2e-6 for |g| <= 0.9).
    """
    f_modes = []
    terms = {}
    n_max = levels[0][1].shape[0]
    coarse = np.zeros(a.size, dtype=bool)
    for m in range(n_max):
        thickness = start_thickness if m == 0 else max(start_thickness, START_THICKNESS_HIGHER_MODES)
        if m == 0:
            mode, black = _solve_mode(levels[0], 0, a, tau, thickness, included_substrate, solver)
            f_mode = mode.pop("f_mode")
            terms.update(mode)
            scale = np.abs(f_mode if black is None else black)
            f_modes.append(f_mode)
            stopping = ModeStopping(scale, n_max, MODE_TOLERANCE, adaptive)
            continue
        active = stopping.active(m)
        full = np.zeros_like(f_modes[0])
        for level, rows in ((levels[0], active & ~coarse), (levels[-1], active & coarse)):
            if rows.any():
                full[rows] = _solve_mode(level, m, a[rows], tau[rows], thickness, None, solver)[0]["f_mode"]
        f_modes.append(full)
        coarse |= (np.abs(full) <= COARSE_AFTER * scale).all(axis=(1, 2))
        if stopping.add(m, full):
            break
    terms["f0_modes"] = stopping.truncate(f_modes)
    return terms


def coarse_quadrature_points(n_points):
    """Gauss points per interval for the small azimuthal modes: half the full quadrature's.

    Parameters
    ----------
    n_points : int
        Points per interval of the full quadrature.

    Returns
    -------
    int
    """
    return max(COARSE_MIN_POINTS, n_points // 2)


def _broadcast_arguments(**arrays):
    """The arguments broadcast against each other; ``ValueError`` naming two that do not."""
    arrays = {name: np.asarray(value, dtype=float) for name, value in arrays.items()}
    names = list(arrays)
    for i, name in enumerate(names):
        for other in names[:i]:
            try:
                np.broadcast_shapes(arrays[other].shape, arrays[name].shape)
            except ValueError:
                raise ValueError(f"{other}, {name}: shapes {arrays[other].shape} and {arrays[name].shape} "
                                 "do not broadcast") from None
    return dict(zip(names, np.broadcast_arrays(*arrays.values())))


def _evaluate(kind, theta_i, theta_o, delta_phi, *, a, tau, g, r_s, n, n_points, roughness=0.0,
              distribution="ggx"):
    """Shared driver of :func:`brdf` and :func:`hemispherical_reflectance`."""
    args = _broadcast_arguments(theta_i=theta_i, theta_o=theta_o, delta_phi=delta_phi, a=a, tau=tau, g=g, r_s=r_s)
    shape = args["a"].shape
    flat = {k: v.ravel() for k, v in args.items()}
    result = np.empty(flat["a"].size)
    for g_value in np.unique(flat["g"]):
        sel = np.flatnonzero(flat["g"] == g_value)
        pairs, pair_index = np.unique(np.stack([flat["a"][sel], flat["tau"][sel]], axis=1), axis=0,
                                      return_inverse=True)
        pair_index = pair_index.ravel()
        thetas_in, in_index = np.unique(flat["theta_i"][sel], return_inverse=True)
        thetas_out, out_index = np.unique(flat["theta_o"][sel], return_inverse=True)
        # the hemispherical reflectance is the azimuthal mean: mode 0 alone
        terms = surface_terms(thetas_in, thetas_out, a=pairs[:, 0], tau=pairs[:, 1], g=float(g_value), n=n,
                              n_points=n_points, n_modes=1 if kind == "hemispherical" else None,
                              roughness=roughness, distribution=distribution)
        r = flat["r_s"][sel]
        gain = r / (1.0 - r * terms.r_up[pair_index])
        if kind == "brdf":
            modes = terms.f0_modes[pair_index, :, out_index.ravel(), in_index.ravel()]
            m = np.arange(modes.shape[-1])
            weights = (2.0 - (m == 0)) * (-1.0) ** m * np.cos(m * np.radians(flat["delta_phi"][sel])[:, None])
            f0 = (modes * weights).sum(axis=-1)
            result[sel] = f0 + gain * terms.t_down[pair_index, in_index.ravel()] * terms.t_up[
                pair_index, out_index.ravel()]
        else:
            result[sel] = terms.h0[pair_index, in_index.ravel()] + gain * terms.t_down[
                pair_index, in_index.ravel()] * terms.t_up_hemispherical[pair_index]
    return result.reshape(shape)


def _part(part):
    if not isinstance(part, str) or part not in BRDF_PARTS:
        raise ValueError(f"part must be one of {BRDF_PARTS}, got {_describe(part)}")
    return part


def first_surface_brdf(theta_i, theta_o, delta_phi, *, roughness, n=1.45, distribution="ggx"):
    """The rough surface's own reflection from air (Walter et al. 2007, eq. 20) [1/sr].

    Parameters
    ----------
    theta_i, theta_o, delta_phi : array_like
        Geometry in air [deg], as in :func:`brdf` (``delta_phi = 180`` on the specular side).
    roughness : float
        GGX ``alpha`` [-]; 0 (or ``n = 1``) gives 0 (the smooth surface's mirror reflection is a
        delta, excluded as in :func:`brdf`).
    n : float
        Binder index [-].
    distribution : {"ggx", "beckmann"}

    Returns
    -------
    numpy.ndarray
        The arguments broadcast [1/sr].
    """
    roughness, n, distribution = surface_roughness(roughness), binder_index(n), _distribution(distribution)
    theta_i, theta_o, delta_phi = np.broadcast_arrays(*(np.asarray(x, dtype=float)
                                                        for x in (theta_i, theta_o, delta_phi)))
    if roughness == 0.0 or n == 1.0:
        return np.zeros(theta_i.shape)
    # the viewing azimuth is 180 deg from the propagation-azimuth difference (0 at the mirror)
    return reflection_brdf(np.cos(np.radians(theta_i)), np.cos(np.radians(theta_o)),
                           np.radians(delta_phi) - np.pi, alpha=roughness, n_i=1.0, n_t=n,
                           distribution=distribution)


def flake_brdf(theta_i, theta_o, delta_phi, *, flake_roughness, n=1.45, distribution="ggx"):
    """The lobe of effect-pigment flakes inside the layer, per unit flake reflectance [1/sr].

    :func:`bayespig.physics.microfacet.flake_reflection_brdf` in the project's geometry (angles
    in air [deg], ``delta_phi = 180`` on the specular side). A film with flakes of reflectance
    ``c`` (at a wavelength) adds ``c * flake_brdf(...)`` to its BRDF; the flakes' lobe is
    coloured (``c`` depends on the wavelength) where the surface's own lobe
    (:func:`first_surface_brdf`) is not.

    Parameters
    ----------
    theta_i, theta_o, delta_phi : array_like
        Geometry in air [deg].
    flake_roughness : float or array_like
        Roughness ``alpha`` of the flakes' orientation distribution [-] (> 0).
    n : float
        Binder index [-].
    distribution : {"ggx", "beckmann"}

    Returns
    -------
    numpy.ndarray
        The arguments broadcast [1/sr].
    """
    n, distribution = binder_index(n), _distribution(distribution)
    theta_i, theta_o = _validate_angle("theta_i", theta_i), _validate_angle("theta_o", theta_o)
    delta_phi = _real_array("delta_phi", delta_phi)
    _check_finite("delta_phi", delta_phi)
    flake_roughness = _real_array("flake_roughness", flake_roughness)
    bad = ~(np.isfinite(flake_roughness) & (flake_roughness > 0))
    if bad.any():
        raise ValueError(f"flake_roughness (the flakes' alpha) must be > 0 and finite, got {_first(flake_roughness, bad)}")
    theta_i, theta_o, delta_phi = np.broadcast_arrays(theta_i, theta_o, delta_phi)
    return flake_reflection_brdf(np.cos(np.radians(theta_i)), np.cos(np.radians(theta_o)),
                                 np.radians(delta_phi) - np.pi, alpha=flake_roughness, n=n,
                                 distribution=distribution)


def brdf(theta_i, theta_o, delta_phi, *, a, tau, g=0.0, r_s=0.0, n=1.45, roughness=0.0, part="total",
         n_points=None, distribution="ggx"):
    """BRDF of a paint layer seen from air (paper eq. 1).

    With a smooth surface (``roughness = 0``) the surface's specular (delta) reflection is
    excluded, as always. With a rough one (a microfacet air/binder interface, Walter et al.
    2007; DESIGN.md, "Rough top surface") the light entering and leaving the layer and the
    layer's light reflected back at the surface (total internal reflection included) are
    scattered by the facets, and the BRDF includes the surface's own glossy lobe.

    Parameters
    ----------
    theta_i : array_like
        Incidence angle in air [deg], in [0, 90).
    theta_o : array_like
        Viewing angle in air [deg], in [0, 90).
    delta_phi : array_like
        Azimuth between the planes of incidence and viewing [deg]; 180 on the
        specular side, 0 back towards the source.
    a : array_like
        Relative absorption ``k_abs / k_ext = 1 - omega`` in [0, 1] [-].
    tau : array_like
        Optical thickness ``k_ext H`` [-]; ``numpy.inf`` for an opaque film (eq. 2).
    g : array_like, optional
        Henyey–Greenstein parameter in (-1, 1); ``|g| > 1`` selects Rayleigh; 0 isotropic.
    r_s : array_like, optional
        Lambertian substrate albedo seen from the binder [-].
    n : float, optional
        Refractive index of the (non-absorbing) binder [-].
    roughness : float, optional
        GGX ``alpha`` of the top surface [-] (one value per call); 0 is the smooth surface and
        takes exactly the smooth model's code. Below :data:`SMOOTH_BELOW` the body is the smooth
        model's (they agree to < 1e-5 there); with ``n = 1`` the surface is index-matched and
        scatters nothing. At most :data:`~bayespig.physics.rough_surface.ROUGHNESS_MAX` (1):
        over [1e-4, 1] the BRDF changes by < 2e-6 (relative) from 16 to 48 quadrature points
        and by < 4e-6 when the fine rules are refined (benchmarks/rough_surface.py).
    part : {"total", "body", "surface"}, optional
        ``"body"``: the light that entered the layer; ``"surface"``: the first-surface lobe
        (:func:`first_surface_brdf`, Walter's analytic BRDF; 0 on a smooth surface);
        ``"total"``: their sum. At ``roughness = 0``, ``"total"`` and ``"body"`` are the smooth
        model's BRDF.
    n_points : int, optional
        Gauss points per quadrature interval; by default
        :func:`~bayespig.physics.quadrature.default_quadrature_points` for each ``g``, which
        converges the BRDF to 1e-4 relative for |g| <= 0.95 (reports/validation.md).
    distribution : {"ggx", "beckmann"}, optional
        Microfacet distribution of a rough surface.

    Returns
    -------
    numpy.ndarray
        BRDF [1/sr], the arguments broadcast against each other.

    Raises
    ------
    TypeError
        An argument that is not real numbers (``n``, ``roughness``: not one real number;
        ``n_points``: not an integer), naming it.
    ValueError
        A value out of range, an unknown ``part`` or ``distribution``, or two arguments whose
        shapes do not broadcast, naming them.

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), eqs. (1)-(3), (8); Walter, Marschner, Li & Torrance
    (2007), EGSR, eqs. (20)-(21).
    """
    validate_layer_arguments(a=a, tau=tau, g=g, r_s=r_s, n=n)
    n, n_points = binder_index(n), quadrature_points(n_points)
    roughness, part, distribution = surface_roughness(roughness), _part(part), _distribution(distribution)
    theta_i = _validate_angle("theta_i", theta_i)
    theta_o = _validate_angle("theta_o", theta_o)
    delta_phi = _real_array("delta_phi", delta_phi)
    _check_finite("delta_phi", delta_phi)
    if np.isinf(delta_phi).any():
        raise ValueError("delta_phi must be finite")
    rough = _is_rough(roughness, n)
    if part == "surface":
        shape = np.broadcast_shapes(*(np.shape(x) for x in (theta_i, theta_o, delta_phi, a, tau, g, r_s)))
        lobe = first_surface_brdf(theta_i, theta_o, delta_phi, roughness=roughness, n=n, distribution=distribution)
        return np.broadcast_to(lobe, shape).copy()
    body = _evaluate("brdf", theta_i, theta_o, delta_phi, a=a, tau=tau, g=g, r_s=r_s, n=n, n_points=n_points,
                     roughness=roughness if rough else 0.0, distribution=distribution)
    if part == "body" or roughness == 0.0 or n == 1.0:
        return body
    return body + first_surface_brdf(theta_i, theta_o, delta_phi, roughness=roughness, n=n,
                                     distribution=distribution)


def specular_port_reflectance(theta_i, *, roughness, n=1.45, half_angle=SPECULAR_CONE_HALF_ANGLE,
                              distribution="ggx"):
    """Reflectance of the first-surface lobe into the specular port's cone [-].

    ``int_cone f_r(i, o) cos(theta_o) dw_o`` over the directions within ``half_angle`` of the
    mirror direction (those below the horizon count 0), by Gauss-Legendre panels in the angle
    from the mirror direction graded towards it and a uniform rule in the azimuth around it.
    At ``roughness = 0`` it is the smooth surface's Fresnel reflectance.

    Parameters
    ----------
    theta_i : array_like
        Incidence angle in air [deg].
    roughness : float
        GGX ``alpha`` [-].
    n : float
        Binder index [-].
    half_angle : float
        Half-angle of the cone [deg], in (0, 90].
    distribution : {"ggx", "beckmann"}

    Returns
    -------
    numpy.ndarray
        The shape of ``theta_i`` [-].
    """
    roughness, n, distribution = surface_roughness(roughness), binder_index(n), _distribution(distribution)
    theta_i = np.asarray(theta_i, dtype=float)
    mu_i = np.cos(np.radians(theta_i))
    if roughness == 0.0 or n == 1.0:
        return fresnel_reflectance(mu_i, 1.0, n)
    gamma = np.radians(half_angle)
    finest = min(roughness / 8.0, gamma)
    edges = np.unique(np.concatenate([[0.0, gamma], finest * 2.0 ** np.arange(0, max(1, int(np.ceil(
        np.log2(gamma / finest)))))]).clip(0.0, gamma))
    x, w = np.polynomial.legendre.leggauss(_PORT_POINTS)
    lo, width = edges[:-1, None], np.diff(edges)[:, None]
    beta = (lo + width * 0.5 * (x + 1.0)).ravel()
    w_beta = (width * 0.5 * w).ravel() * np.sin(beta)
    chi = 2.0 * np.pi * (np.arange(_PORT_AZIMUTHS) + 0.5) / _PORT_AZIMUTHS
    s_i = np.sqrt(1.0 - mu_i * mu_i).ravel()[:, None, None]
    m_i = mu_i.ravel()[:, None, None]
    b, ch = beta[None, :, None], chi[None, None, :]
    # directions around the mirror one m = (s_i, 0, mu_i), in the frame (m, e1, e2)
    # with e1 = (mu_i, 0, -s_i), e2 = (0, 1, 0)
    ox = np.cos(b) * s_i + np.sin(b) * np.cos(ch) * m_i
    oy = np.sin(b) * np.sin(ch) + 0.0 * m_i
    oz = np.cos(b) * m_i - np.sin(b) * np.cos(ch) * s_i
    up = oz > 0.0
    mu_o = np.where(up, np.clip(oz, 1e-300, 1.0), 1.0)
    f = reflection_brdf(np.broadcast_to(m_i, mu_o.shape), mu_o, np.arctan2(oy, ox), alpha=roughness,
                        n_i=1.0, n_t=n, distribution=distribution)
    integrand = np.where(up, f * oz, 0.0)
    total = (integrand * w_beta[None, :, None]).sum(axis=(1, 2)) * (2.0 * np.pi / _PORT_AZIMUTHS)
    return total.reshape(theta_i.shape)


def hemispherical_reflectance(theta_i, *, a, tau, g=0.0, r_s=0.0, n=1.45, specular="excluded",
                              n_points=None, roughness=0.0, specular_cone=SPECULAR_CONE_HALF_ANGLE,
                              distribution="ggx"):
    """Directional–hemispherical reflectance of a paint layer (8°/d; d/8 by reciprocity).

    SCI is everything the film reflects into the hemisphere. On a smooth surface SCE excludes the
    surface's mirror (Fresnel) reflection. On a rough surface (``roughness > 0``) the sphere's
    specular port is a cone of half-angle ``specular_cone`` around the mirror direction, and SCE
    excludes the part of the *first-surface lobe* that falls into it
    (:func:`specular_port_reflectance`): ``SCE = SCI - int_cone f_surface cos(theta_o) dw``.
    The body's light inside the cone is kept in SCE, as in the smooth model (which excludes only
    the delta reflection), so that SCE is continuous at ``roughness -> 0``; it is
    ``int_cone f_body cos dw`` ~ 0.02 ``f_body`` for a 5 deg cone, ~0.5 % of a matt body's SCE.

    Parameters
    ----------
    theta_i : array_like
        Incidence angle in air [deg] (8 for the usual sphere geometry).
    a, tau, g, r_s, n, n_points, roughness, distribution
        As in :func:`brdf`.
    specular : {"excluded", "included"}
        SCE or SCI, as defined above.
    specular_cone : float
        Half-angle of the specular port around the mirror direction [deg], in (0, 90]; used
        for SCE of a rough surface. The default, :data:`SPECULAR_CONE_HALF_ANGLE`, is an
        assumption: pass the instrument's own value.

    Returns
    -------
    numpy.ndarray
        Reflectance [-].

    Raises
    ------
    TypeError, ValueError
        As :func:`brdf`; ``specular_cone`` out of range.
    """
    if specular not in ("excluded", "included"):
        raise ValueError(f"specular must be 'excluded' or 'included', got {specular!r}")
    validate_layer_arguments(a=a, tau=tau, g=g, r_s=r_s, n=n)
    n, n_points = binder_index(n), quadrature_points(n_points)
    roughness, distribution = surface_roughness(roughness), _distribution(distribution)
    cone = _real_array("specular_cone", specular_cone)
    if cone.ndim != 0 or not np.isfinite(cone) or not 0.0 < float(cone) <= 90.0:
        raise ValueError(f"specular_cone (half-angle of the specular port) must be one number in (0, 90] "
                         f"degrees, got {_describe(specular_cone)}")
    theta_i = _validate_angle("theta_i", theta_i)
    rough = _is_rough(roughness, n)
    diffuse = _evaluate("hemispherical", theta_i, theta_i, 0.0, a=a, tau=tau, g=g, r_s=r_s, n=n,
                        n_points=n_points, roughness=roughness if rough else 0.0, distribution=distribution)
    if roughness == 0.0 or n == 1.0:
        if specular == "included":
            diffuse = diffuse + fresnel_reflectance(np.cos(np.radians(theta_i)), 1.0, n)
        return diffuse
    # the first-surface lobe: all of it (SCI) or what misses the port (SCE)
    mu_i = np.cos(np.radians(theta_i))
    lobe, _ = directional_albedo(mu_i, alpha=roughness, n_i=1.0, n_t=n, distribution=distribution)
    if specular == "excluded":
        lobe = lobe - specular_port_reflectance(theta_i, roughness=roughness, n=n, half_angle=float(cone),
                                                distribution=distribution)
    return diffuse + np.clip(lobe, 0.0, None)


def specular_transmittance(tau, n=1.45):
    """Specular (unscattered) transmittance of a film at normal incidence, eq. (5).

    ``T = t_F^2 exp(-tau)`` with ``t_F = 1 - ((n - 1)/(n + 1))^2``.

    Parameters
    ----------
    tau : array_like
        Optical thickness of the film [-].
    n : float
        Refractive index of the binder/glass [-].

    Returns
    -------
    numpy.ndarray
        Transmittance [-].
    """
    tau = _real_array("tau", tau)
    _check_finite("tau", tau)
    if (tau < 0).any():
        raise ValueError(f"tau (optical thickness) must be >= 0, got {_first(tau, tau < 0)}")
    return normal_transmittance(binder_index(n)) ** 2 * np.exp(-tau)


def optical_thickness_from_transmittance(transmittance, n=1.45):
    """Invert eq. (5): ``tau = -log(T / t_F^2)``, eq. (6).

    Parameters
    ----------
    transmittance : array_like
        Specular transmittance in (0, t_F^2] [-].
    n : float
        Refractive index [-].

    Returns
    -------
    numpy.ndarray
        Optical thickness [-].
    """
    transmittance = _real_array("transmittance", transmittance)
    _check_finite("transmittance", transmittance)
    clear = normal_transmittance(binder_index(n)) ** 2
    bad = (transmittance <= 0) | (transmittance > clear)
    if bad.any():
        raise ValueError(f"transmittance must lie in (0, {clear:.6g}] (0 to that of a clear film at n = {n:g}), "
                         f"got {_first(transmittance, bad)}")
    return -np.log(transmittance / clear)
