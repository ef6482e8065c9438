"""Look-up tables with a roughness axis: opaque films under a rough air/binder surface (issue 16).

Inference with the surface roughness ``alpha`` as a parameter needs the channels of an
instrument at any ``(a, alpha)``. The body (the light that entered the layer) of an opaque,
isotropically scattering film under a rough surface
(:func:`bayespig.physics.forward.surface_terms` with ``roughness=alpha``; DESIGN.md, "Rough top
surface") is tabulated over ``(alpha, a)``; the first-surface lobe is not:

- BRDF and 45°/0° (reflectance-factor) channels: the lobe is Walter's analytic BRDF
  (:func:`bayespig.physics.forward.first_surface_brdf`), evaluated directly at the channels'
  geometries for every ``alpha`` (exact, and cheaper than interpolating a lobe that is ~10^4
  times larger near the mirror than away from it);
- hemispherical channels: the lobe's directional albedo (SCI) minus what falls into the
  specular port (SCE, :func:`bayespig.physics.forward.hemispherical_reflectance`) depends on
  ``alpha`` only; it is tabulated at the ``alpha`` nodes and interpolated.

So a table returns the *total* value (body plus lobe), with ``part="body"`` / ``"surface"`` for
either alone.

A film with effect-pigment flakes adds ``c`` times their lobe
(:meth:`RoughLookupTable.flake_lobe`: :func:`bayespig.physics.microfacet.flake_reflection_brdf`
at the BRDF channels, analytic like the surface's lobe; none for hemispherical channels).

Axes and interpolation
----------------------
``log q = log(f_body / (1 - a))`` (the opaque slice of :mod:`bayespig.table`; ``q`` is smooth
and positive) is interpolated by a tensor-product cubic Lagrange stencil over ``v(a) = asinh(s
sqrt(a)) / asinh(s)`` (the a axis of :class:`~bayespig.table.TableSettings`) and ``log alpha``,
uniform nodes from :attr:`RoughTableSettings.alpha_min` to ``alpha_max``. The body varies slowly
with the roughness (it changes by a few per cent between ``alpha = 0.01`` and 1 away from
grazing), and in ``log alpha`` it is smooth down to the smooth limit, so a cubic in ``log alpha``
on :attr:`RoughTableSettings.per_octave` nodes per factor of two meets the tables' accuracy goal
(tests/test_table_roughness.py: :data:`ROUGH_TABLE_TOLERANCE`).

Scope: opaque films (``tau = inf``), isotropic scattering (``g = 0``), one binder index per
table (the instrument's). Finite films under a rough surface need a ``tau`` axis as well (the
smooth table's doubling chains do not apply to the rough solve): not tabulated yet.

The binder index as a parameter
-------------------------------
With ``n`` inferred (:class:`bayespig.inference.roughness.BinderIndexSpec`) the body is needed
at any ``n`` too: :class:`BinderIndexRoughTables` holds one rough table per node of the uniform
axis :data:`BINDER_INDEX_NODES` (each an ordinary :class:`RoughLookupTable` at that ``n``, cached
as such) and interpolates ``log q`` by a cubic Lagrange stencil in ``n``; the lobe is Walter's
formula at the row's ``n``. Measured against the direct solver (``python benchmarks/rough_tables.py``:
GGX, alpha 0.02 / 0.2 / 0.6, a 0.01 / 0.3 / 0.9, 25 geometries, ``n`` between the nodes): worst
relative error of the n-interpolation 2.4e-4 for a node spacing of 0.1, 3.3e-5 for the axis'
0.08.

A table for a subset of another's geometries (the geometry subsets of a consistency check) is
that table's columns: :func:`derive_rough_table` takes them instead of building it (the body
of one ``(theta_i, theta_o)`` column does not depend on the other columns of the solve) and caches
it under the subset's own key.

Tables are cached on disk like :mod:`bayespig.table`'s (file ``rough-table-<key>.npz``, the key
hashing the instrument, the settings (roughness axis included) and the package version).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._atomic import atomic_path
from ._pool import executor_or_local_pool
from ._validation import integer, real_scalar
from ._versions import __version__
from .instruments import Instrument, channel_directions, get_instrument
from .physics.forward import specular_port_reflectance, surface_terms
from .physics.microfacet import _flake_reflection, _reflection, directional_albedo
from .physics.quadrature import DEFAULT_QUADRATURE_POINTS
from .table import (
    A_MAX_EVAL,
    EVALUATION_BLOCK,
    LOG_FLOOR,
    CacheError,
    CacheLocationError,
    _build_lock,
    _cache_folder,
    _cache_origin,
    _checksum,
    _table_title,
    lagrange_stencil,
)

__all__ = [
    "ROUGHNESS_MAX",
    "ROUGHNESS_MIN",
    "FixedRoughnessTable",
    "RoughLookupTable",
    "RoughTableSettings",
    "BINDER_INDEX_NODES",
    "BinderIndexRoughTables",
    "build_rough_table",
    "derive_rough_table",
    "load_binder_index_tables",
    "load_rough_table",
]

#: Bump when the file layout or the tabulated quantities change.
FORMAT_VERSION = 2
#: Default roughness axis [-]: from a fine gloss (alpha = 0.01, a lobe of ~1 deg half width)
#: to a matt surface (alpha = 1, facets of every slope).
ROUGHNESS_MIN, ROUGHNESS_MAX = 0.01, 1.0
#: Bytes of the stencil rows gathered per block of points (the 16 rows of (alpha, a) nodes per
#: point and channel): bounds the memory of an evaluation of a wide table (1439 Cornell
#: geometries: 173 points per block, 32 MB).
GATHER_BYTES = 32 * 2**20
#: Relative accuracy goal of the table against the direct solver over its domain (that of
#: :mod:`bayespig.table`).
ROUGH_TABLE_TOLERANCE = 2e-4
#: Binder-index nodes of :class:`BinderIndexRoughTables` [-]: uniform, step 0.08, from 1.37 to
#: 1.77 (common paint binders and clear coats, linseed oil ~1.48, alkyds and acrylics ~1.49-1.52,
#: epoxies and polyurethanes ~1.50-1.57, lie inside with room for an effective index of a coated
#: surface), and the default index 1.45 is a node (its table is the one a fixed-``n`` fit uses).
BINDER_INDEX_NODES = (1.37, 1.45, 1.53, 1.61, 1.69, 1.77)


@dataclass(frozen=True)
class RoughTableSettings:
    """Every setting that changes a rough table's numbers (hashed into the cache key).

    Attributes
    ----------
    alpha_min, alpha_max : float
        Ends of the roughness axis (GGX ``alpha``) [-], ``0 < alpha_min < alpha_max``.
    per_octave : int
        Fewest ``log alpha`` nodes per factor of two (the nodes are uniform in ``log alpha``
        from ``alpha_min`` to ``alpha_max``, both nodes).
    n_a : int
        Nodes on the absorption axis ``v(a)`` (that of :class:`bayespig.table.TableSettings`).
    a_stretch : float
        ``s`` of ``v(a) = asinh(s sqrt(a)) / asinh(s)``.
    n_points : int
        Gauss points per quadrature interval of the solver.
    distribution : {"ggx", "beckmann"}
        Microfacet distribution.
    """

    alpha_min: float = ROUGHNESS_MIN
    alpha_max: float = ROUGHNESS_MAX
    per_octave: int = 4
    n_a: int = 48
    a_stretch: float = 30.0
    n_points: int = DEFAULT_QUADRATURE_POINTS
    distribution: str = "ggx"

    def __post_init__(self):
        lo = real_scalar("alpha_min", self.alpha_min, low=0.0, low_open=True)
        real_scalar("alpha_max", self.alpha_max, low=lo, low_open=True)
        integer("per_octave", self.per_octave, low=1)
        integer("n_a", self.n_a, low=4)
        real_scalar("a_stretch", self.a_stretch, low=0.0, low_open=True)
        integer("n_points", self.n_points, low=1)
        if self.distribution not in ("ggx", "beckmann"):
            raise ValueError(f"distribution must be 'ggx' or 'beckmann', got {self.distribution!r}")
        if self.n_alpha < 4:
            raise ValueError("the roughness axis needs at least 4 nodes (a cubic stencil): widen "
                             "[alpha_min, alpha_max] or raise per_octave")

    @property
    def n_alpha(self):
        """Nodes on the roughness axis: at least ``per_octave`` per factor of two."""
        return int(np.ceil(np.log2(self.alpha_max / self.alpha_min) * self.per_octave - 1e-9)) + 1

    @property
    def log_alpha_step(self):
        """Spacing of the ``log alpha`` nodes [-]."""
        return np.log(self.alpha_max / self.alpha_min) / (self.n_alpha - 1)

    @property
    def alpha_nodes(self):
        """Roughness nodes [-], geometric from exactly ``alpha_min`` to exactly ``alpha_max``."""
        nodes = self.alpha_min * np.exp(np.arange(self.n_alpha) * self.log_alpha_step)
        nodes[0], nodes[-1] = self.alpha_min, self.alpha_max
        return nodes

    @property
    def v_nodes(self):
        """Nodes of the absorption coordinate ``v`` [-]."""
        return np.linspace(0.0, 1.0, self.n_a)

    @property
    def a_nodes(self):
        """Nodes of ``a`` [-]."""
        u = np.sinh(self.v_nodes * np.arcsinh(self.a_stretch)) / self.a_stretch
        return np.minimum(u * u, 1.0)


def _description(instrument, settings):
    return json.dumps({
        "format": FORMAT_VERSION,
        "version": __version__,
        "kind": "rough-opaque",
        "instrument": {"n": instrument.n, "channels": [dataclasses.asdict(ch) for ch in instrument.channels]},
        "settings": dataclasses.asdict(settings),
    }, sort_keys=True, default=float)


def rough_table_key(instrument, settings):
    """Hash of everything that changes a rough table's numbers (the roughness axis included)."""
    return hashlib.sha256(_description(instrument, settings).encode()).hexdigest()[:32]


def rough_table_path(key, folder):
    """Cache file of the rough table with this key."""
    return Path(folder) / f"rough-table-{key}.npz"


# ---------------------------------------------------------------------------------------------
# building


def _hemispherical_lobe(channel, alpha, n, distribution):
    """The first-surface part of a hemispherical channel at roughness ``alpha`` [-]: the lobe's
    directional albedo, less what falls into the specular port for SCE (the definitions of
    :func:`~bayespig.physics.forward.hemispherical_reflectance`, its default port cone)."""
    lobe, _ = directional_albedo(np.cos(np.radians(channel.theta_i)), alpha=float(alpha), n_i=1.0, n_t=n,
                                 distribution=distribution)
    if channel.specular == "excluded":
        lobe = lobe - specular_port_reflectance(channel.theta_i, roughness=float(alpha), n=n,
                                                distribution=distribution)
    return float(np.clip(lobe, 0.0, None))


def body_columns(instrument):
    """The distinct body values of an instrument's channels and each channel's column and factor.

    An isotropic opaque body does not depend on the azimuth: it is one value per (hemispherical
    or not, ``theta_i``, ``theta_o``) (1439 Cornell geometries: 80 columns); a reflectance factor
    is ``pi`` times the BRDF column.

    Returns
    -------
    tuple
        ``(keys, column, factor)``: the columns' ``(hemispherical, theta_i, theta_o)``, and per
        channel its column (int) and factor (1 or pi).
    """
    keys, column = [], []
    for ch in instrument.channels:
        key = (ch.kind == "hemispherical", float(ch.theta_i), float(ch.theta_i if ch.kind == "hemispherical"
                                                                   else ch.theta_o))
        if key not in keys:
            keys.append(key)
        column.append(keys.index(key))
    factor = np.array([np.pi if ch.kind == "reflectance_factor" else 1.0 for ch in instrument.channels])
    return keys, np.array(column, dtype=int), factor


def _build_alpha_slice(instrument, settings, alpha):
    """``log q`` (n_a, n_columns) of the body (:func:`body_columns`) and the channels' tabulated
    lobe (K,; the hemispherical ones, 0 elsewhere) at one roughness."""
    theta_in, theta_out, _, _ = channel_directions(instrument)
    a = np.minimum(settings.a_nodes, A_MAX_EVAL)
    terms = surface_terms(theta_in, theta_out, a=a, tau=np.full(a.size, np.inf), g=0.0, n=instrument.n,
                          n_points=settings.n_points, roughness=float(alpha), distribution=settings.distribution)
    keys, _, _ = body_columns(instrument)
    body = np.empty((a.size, len(keys)))
    for j, (hemispherical, theta_i, theta_o) in enumerate(keys):
        i = int(np.searchsorted(theta_in, theta_i))
        if hemispherical:
            body[:, j] = terms.h0[:, i]
        else:  # isotropic: mode 0 only
            body[:, j] = terms.f0_modes[:, 0, int(np.searchsorted(theta_out, theta_o)), i]
    lobe = np.array([_hemispherical_lobe(ch, alpha, instrument.n, settings.distribution)
                     if ch.kind == "hemispherical" else 0.0 for ch in instrument.channels])
    log_q = np.log(np.maximum(body / (1.0 - a)[:, None], LOG_FLOOR))
    return log_q, lobe


def build_rough_table(instrument, settings=None, *, executor=None, progress=True):
    """Tabulate an instrument's channels over ``(alpha, a)`` for opaque films (not cached; see
    :func:`load_rough_table`).

    Parameters
    ----------
    instrument : str, Instrument or sequence
        See :func:`bayespig.instruments.get_instrument`.
    settings : RoughTableSettings, optional
    executor : concurrent.futures.Executor, optional
        Runs the roughness nodes in parallel; by default a local process pool.
    progress : bool
        Progress bar over the roughness nodes.

    Returns
    -------
    RoughLookupTable
    """
    instrument = get_instrument(instrument)
    if settings is not None and not isinstance(settings, RoughTableSettings):
        raise TypeError(f"settings must be a RoughTableSettings or None, got {settings!r}")
    settings = settings or RoughTableSettings()
    alphas = settings.alpha_nodes
    with executor_or_local_pool(executor, needed=alphas.size > 1) as pool:
        if pool is None:
            slices = [_build_alpha_slice(instrument, settings, float(x)) for x in alphas]
        else:
            # the smallest roughness is the dearest (the finest product-integration panels)
            futures = {i: pool.submit(_build_alpha_slice, instrument, settings, float(alphas[i]))
                       for i in range(alphas.size)}
            iterator = [futures[i] for i in range(alphas.size)]
            if progress:
                from tqdm.auto import tqdm

                iterator = tqdm(iterator, desc=f"building rough table {_table_title(instrument)}",
                                unit="alpha", file=sys.stderr)
            slices = [future.result() for future in iterator]
    arrays = {"log_q": np.stack([s[0] for s in slices]), "lobe": np.stack([s[1] for s in slices])}
    return RoughLookupTable(instrument, settings, arrays, rough_table_key(instrument, settings))


# ---------------------------------------------------------------------------------------------
# the table


class RoughLookupTable:
    """An instrument's channels for opaque films under a rough surface, over ``(a, alpha)``.

    ``table(a=..., roughness=...)`` -> ``(..., n_channels)``; see the module docstring.

    Attributes
    ----------
    instrument : Instrument
    settings : RoughTableSettings
    key : str
        Hash of everything that changes the numbers (cache key, recorded in results).
    checksum : str
        SHA-256 of :attr:`arrays` (the cache file's checksum; recorded in results next to the
        key, as :attr:`bayespig.table.LookupTable.checksum`).
    arrays : dict of numpy.ndarray
        ``log_q`` (n_alpha, n_a, n_columns): log of the body over ``1 - a`` per distinct body
        value (:func:`body_columns`); ``lobe`` (n_alpha, K): the hemispherical channels'
        first-surface part (0 for the other channels).
    """

    free_g = False
    opaque_only = True

    def __init__(self, instrument, settings, arrays, key):
        self.instrument, self.settings, self.arrays, self.key = instrument, settings, arrays, key
        self.channels = instrument.channels
        self.n_alpha, self.n_a, self.n_columns = arrays["log_q"].shape
        self.n_channels = len(instrument.channels)
        _, self._column, self._body_factor = body_columns(instrument)
        self._any_factor = bool((self._body_factor != 1.0).any())
        #: One row per (alpha, a) node, one column per distinct body value (:func:`body_columns`).
        self.stacked = np.ascontiguousarray(arrays["log_q"].reshape(-1, self.n_columns))
        self.alpha_min, self.alpha_max = float(settings.alpha_nodes[0]), float(settings.alpha_nodes[-1])
        self._log_alpha0 = float(np.log(self.alpha_min))
        self._d_log_alpha = float(settings.log_alpha_step)
        self._du = float(settings.v_nodes[1] - settings.v_nodes[0])
        self._a_stretch = float(settings.a_stretch)
        self._asinh_stretch = float(np.arcsinh(settings.a_stretch))
        self._n_axes = np.array([[self.n_alpha], [self.n_a]])
        self._offsets = ((np.arange(4) * self.n_a)[:, None] + np.arange(4)).ravel()
        kinds = np.array([ch.kind for ch in instrument.channels])
        #: Channels whose lobe is analytic (BRDF: factor 1, reflectance factor: pi) and their factor.
        self._analytic = np.flatnonzero(kinds != "hemispherical")
        self._factor = np.where(kinds[self._analytic] == "reflectance_factor", np.pi, 1.0)
        self._hemispherical = np.flatnonzero(kinds == "hemispherical")
        ch = [instrument.channels[k] for k in self._analytic]
        self._mu_i = np.cos(np.radians([c.theta_i for c in ch]))
        self._mu_o = np.cos(np.radians([c.theta_o for c in ch]))
        self._cos_psi = np.cos(np.radians([c.delta_phi for c in ch]) - np.pi)

    @functools.cached_property
    def checksum(self):
        """SHA-256 of :attr:`arrays` (hex), as the cache file records it."""
        return _checksum(self.arrays)

    def __repr__(self):
        return (f"RoughLookupTable({self.instrument.name!r}, {len(self.channels)} channels, opaque, "
                f"alpha in [{self.alpha_min:g}, {self.alpha_max:g}], key={self.key})")

    @property
    def nbytes(self):
        """Memory of the tabulated arrays [bytes]."""
        return self.stacked.nbytes + self.arrays["lobe"].nbytes

    def _check(self, a, roughness):
        a, roughness = np.asarray(a, dtype=float), np.asarray(roughness, dtype=float)
        if not np.isfinite(a).all() or (a < 0).any() or (a > 1).any():
            raise ValueError("a (relative absorption) must lie in [0, 1]")
        if (not np.isfinite(roughness).all() or (roughness < self.alpha_min * (1 - 1e-12)).any()
                or (roughness > self.alpha_max * (1 + 1e-12)).any()):
            raise ValueError(f"roughness must lie in the table's range [{self.alpha_min:g}, {self.alpha_max:g}]")
        return a, roughness

    def body(self, a, roughness):
        """The body of every channel at validated 1-D ``a`` and ``roughness`` (P,), (P, K) [channel units]."""
        q = np.exp(self.interpolate_columns(a, roughness))
        q *= np.maximum(1.0 - a, 0.0)[:, None]
        body = q[:, self._column]
        if self._any_factor:
            body *= self._body_factor
        return body

    def interpolate(self, a, roughness):
        """``log q`` of every channel's body at validated 1-D ``a`` and ``roughness`` (P,), (P, K)."""
        return self.interpolate_columns(a, roughness)[:, self._column] + np.log(self._body_factor)

    def interpolate_columns(self, a, roughness):
        """``log q`` of the distinct body columns (:func:`body_columns`), (P, n_columns)."""
        block = max(1, min(EVALUATION_BLOCK, GATHER_BYTES // (16 * 8 * self.n_columns)))
        if a.size > block:
            return np.concatenate([self.interpolate_columns(a[i:i + block], roughness[i:i + block])
                                   for i in range(0, a.size, block)])
        u = np.arcsinh(self._a_stretch * np.sqrt(a)) / self._asinh_stretch
        x = (np.log(roughness) - self._log_alpha0) / self._d_log_alpha
        (sx, su), (wx, wu) = lagrange_stencil(np.stack([x, u / self._du]), self._n_axes, 4)
        rows = (sx * self.n_a + su)[:, None] + self._offsets
        weights = (wx[:, :, None] * wu[:, None, :]).reshape(-1, 16)
        # per point in a fixed order: a point's value does not depend on its batch
        return np.einsum("ps,psc->pc", weights, self.stacked.take(rows, axis=0))

    def lobe(self, roughness):
        """First-surface part of every channel at each roughness (P,), shape (P, K) [channel units]."""
        roughness = np.asarray(roughness, dtype=float).reshape(-1)
        out = np.zeros((roughness.size, self.n_channels))
        if self._analytic.size:
            out[:, self._analytic] = self._factor * _reflection(
                self._mu_i, self._mu_o, self._cos_psi, roughness[:, None], 1.0, self.instrument.n,
                self.settings.distribution)
        if self._hemispherical.size:
            x = (np.log(roughness) - self._log_alpha0) / self._d_log_alpha
            start, weights = lagrange_stencil(x, self.n_alpha, 4)
            rows = start[:, None] + np.arange(4)
            out[:, self._hemispherical] = np.einsum(
                "ps,psc->pc", weights, self.arrays["lobe"][:, self._hemispherical][rows])
        return out

    def flake_lobe(self, flake_roughness, binder_index=None):
        """The effect-pigment flakes' lobe per unit flake reflectance at every BRDF channel, (P, K) [channel units].

        :func:`bayespig.physics.microfacet.flake_reflection_brdf` at each row's flake roughness
        (P,) and binder index (P,; None: the table's ``n``), times ``pi`` for a reflectance
        factor. Hemispherical channels have no flake lobe here (0): a film with flakes is for
        BRDF channels (:class:`bayespig.likelihood.ForwardModel` refuses others).
        """
        flake_roughness = np.asarray(flake_roughness, dtype=float).reshape(-1)
        n = (np.full(flake_roughness.size, self.instrument.n) if binder_index is None
             else np.asarray(binder_index, dtype=float).reshape(-1))
        out = np.zeros((flake_roughness.size, self.n_channels))
        if self._analytic.size:
            for index in np.unique(n):  # one index per call of the formula: one per walker
                rows = np.flatnonzero(n == index)
                out[np.ix_(rows, self._analytic)] = self._factor * _flake_reflection(
                    self._mu_i, self._mu_o, self._cos_psi, flake_roughness[rows, None], float(index),
                    self.settings.distribution)
        return out

    def __call__(self, *, a, roughness, part="total"):
        """Channel values of an opaque film.

        Parameters
        ----------
        a : array_like
            Relative absorption [-], in [0, 1].
        roughness : array_like
            GGX ``alpha`` [-], in the table's range; broadcast with ``a``.
        part : {"total", "body", "surface"}
            Body plus first-surface lobe, or either alone.

        Returns
        -------
        numpy.ndarray
            ``broadcast.shape + (n_channels,)``.
        """
        if part not in ("total", "body", "surface"):
            raise ValueError(f"part must be one of ('total', 'body', 'surface'), got {part!r}")
        a, roughness = self._check(a, roughness)
        shape = np.broadcast_shapes(a.shape, roughness.shape)
        a, roughness = (np.broadcast_to(v, shape).ravel() for v in (a, roughness))
        out = np.zeros((a.size, self.n_channels))
        if part != "surface":
            out += self.body(a, roughness)
        if part != "body":
            out += self.lobe(roughness)
        return out.reshape(shape + (self.n_channels,))


class FixedRoughnessTable:
    """A :class:`RoughLookupTable` at one roughness, with the interface of :class:`bayespig.table.LookupTable`.

    Everything that evaluates look-up tables (the point fit, the per-wavelength posterior and its
    fast path) takes it in place of a smooth table: ``table(a=, tau=inf, g=0, r_s=)`` is the opaque
    film's total value (body plus first-surface lobe), :meth:`interpolate` its body's ``log q``
    and ``table(a=1, tau=inf)`` the lobe (what the fast path adds as the "specular" term). Opaque
    films and isotropic scattering only: a finite ``tau`` or ``g != 0`` is refused, naming it.

    Parameters
    ----------
    rough : RoughLookupTable
    roughness : float
        GGX ``alpha`` [-], in the table's range.
    """

    free_g = False
    n_g = 1

    def __init__(self, rough, roughness):
        roughness = float(roughness)
        if not rough.alpha_min <= roughness <= rough.alpha_max:
            raise ValueError(f"roughness must lie in the look-up table's range [{rough.alpha_min:g}, "
                             f"{rough.alpha_max:g}], got {roughness!r}")
        from .table import TableSettings

        self.rough, self.roughness = rough, roughness
        self.instrument, self.channels, self.n_channels = rough.instrument, rough.channels, rough.n_channels
        self.key = f"{rough.key}@alpha={roughness!r}"
        #: The smooth tables' tau axis (for the checks of the priors' tau range against it).
        self.settings = TableSettings()
        self.tau_min, self.tau_max = float(self.settings.tau_nodes[0]), float(self.settings.tau_nodes[-1])
        self._lobe = rough.lobe(np.array([roughness]))[0]

    @property
    def checksum(self):
        """The rough table's :attr:`RoughLookupTable.checksum` (the roughness is in :attr:`key`)."""
        return self.rough.checksum

    def __repr__(self):
        return f"FixedRoughnessTable({self.rough!r}, roughness={self.roughness:g})"

    def _check(self, tau, g):
        if not np.isinf(np.asarray(tau, dtype=float)).all():
            raise ValueError("tau must be inf: the look-up tables of a rough surface are tabulated for opaque "
                             "films only (a film over a visible substrate is not supported with roughness > 0)")
        if np.any(np.asarray(g, dtype=float) != 0.0):
            raise ValueError("g must be 0: the look-up tables of a rough surface are isotropic")

    def interpolate(self, a, tau=None, g=None, derivatives=False):
        """``log q`` of the body (P, K) (``tau``: inf only; the layout of :meth:`bayespig.table.LookupTable.interpolate`
        without substrate columns, which an opaque film does not use)."""
        if tau is not None:
            self._check(tau, 0.0)
        return self.rough.interpolate(np.asarray(a, dtype=float), np.full(np.shape(a), self.roughness))

    def __call__(self, *, a, tau, g=0.0, r_s=0.0):
        """Channel values of an opaque film (``r_s`` has no effect), ``broadcast.shape + (K,)``."""
        self._check(tau, g)
        shape = np.broadcast_shapes(np.shape(a), np.shape(tau), np.shape(g), np.shape(r_s))
        a = np.broadcast_to(np.asarray(a, dtype=float), shape)
        return self.rough(a=a, roughness=self.roughness)

    def evaluate(self, *, a, tau, g=0.0, r_s=0.0, gradient=False):
        """Values and (with ``gradient``) ``d/da``, ``d/dtau`` (0), ``d/dg`` (0), as
        :meth:`bayespig.table.LookupTable.evaluate`; ``d/da`` by the interpolant's derivative."""
        value = self(a=a, tau=tau, g=g, r_s=r_s)
        if not gradient:
            return value
        a = np.broadcast_to(np.asarray(a, dtype=float), value.shape[:-1])
        flat = a.ravel()
        rough = self.rough
        step = 1e-6
        # d log q / da by a central difference of the interpolant in v(a) (inside the axis)
        u = np.arcsinh(rough._a_stretch * np.sqrt(flat)) / rough._asinh_stretch
        lo, hi = np.clip(u - step, 0.0, 1.0), np.clip(u + step, 0.0, 1.0)
        def a_of(v):
            return (np.sinh(v * rough._asinh_stretch) / rough._a_stretch) ** 2

        alpha = np.full(flat.shape, self.roughness)
        q_lo = np.exp(rough.interpolate(np.clip(a_of(lo), 0.0, 1.0), alpha))
        q_hi = np.exp(rough.interpolate(np.clip(a_of(hi), 0.0, 1.0), alpha))
        with np.errstate(divide="ignore", invalid="ignore"):
            dq_da = (q_hi - q_lo) / (a_of(hi) - a_of(lo))[:, None]
        q = np.exp(rough.interpolate(flat, alpha))
        d_a = (np.maximum(1.0 - flat, 0.0)[:, None] * dq_da - q).reshape(value.shape)
        zeros = np.zeros_like(value)
        return value, d_a, zeros, zeros.copy()


class BinderIndexRoughTables:
    """Rough tables of one instrument at uniform binder-index nodes, interpolated in ``n``.

    ``log q`` of the body (module docstring) is a cubic Lagrange interpolant over the nodes'
    tables (each interpolated in ``(alpha, a)`` as :class:`RoughLookupTable` does); the lobe of
    BRDF and reflectance-factor channels is Walter's formula at the row's ``(alpha, n)``, that of
    hemispherical channels the tables' tabulated lobe interpolated in ``n`` as well.

    Parameters
    ----------
    tables : sequence of RoughLookupTable
        One per node, in node order: the same channels and settings, binder indices ``nodes``.
    nodes : sequence of float
        Uniform binder-index axis [-], at least 4 nodes.

    Attributes
    ----------
    n_min, n_max : float
        The axis' ends [-]: the range of ``binder_index``.
    alpha_min, alpha_max : float
        The roughness range [-] (that of the tables).
    """

    free_g = False
    opaque_only = True

    def __init__(self, tables, nodes):
        tables, nodes = list(tables), np.asarray(nodes, dtype=float)
        if nodes.ndim != 1 or nodes.size < 4 or len(tables) != nodes.size:
            raise ValueError(f"need one table per node and at least 4 nodes, got {len(tables)} tables for "
                             f"{nodes.size} nodes")
        step = np.diff(nodes)
        if not (step > 0).all() or np.ptp(step) > 1e-9 * step.mean():
            raise ValueError(f"binder-index nodes must be uniform and increasing, got {nodes.tolist()}")
        first = tables[0]
        for table, n in zip(tables, nodes):
            if (table.settings != first.settings or table.instrument.channels != first.instrument.channels
                    or abs(table.instrument.n - n) > 1e-12):
                raise ValueError(f"table {table!r} does not belong to node n = {n:g} of the others' channels "
                                 "and settings")
        self.tables, self.nodes = tables, nodes
        self.instrument, self.channels, self.n_channels = first.instrument, first.channels, first.n_channels
        self.settings = first.settings
        self.alpha_min, self.alpha_max = first.alpha_min, first.alpha_max
        self.n_min, self.n_max = float(nodes[0]), float(nodes[-1])
        self._n0, self._dn = float(nodes[0]), float(step.mean())
        self.key = hashlib.sha256(" ".join(t.key for t in tables).encode()).hexdigest()[:32]

    @functools.cached_property
    def checksum(self):
        """SHA-256 (hex) of the node tables' checksums in node order."""
        return hashlib.sha256(" ".join(t.checksum for t in self.tables).encode()).hexdigest()

    def __repr__(self):
        return (f"BinderIndexRoughTables({self.instrument.name!r}, {self.n_channels} channels, n in "
                f"[{self.n_min:g}, {self.n_max:g}] ({self.nodes.size} nodes), alpha in "
                f"[{self.alpha_min:g}, {self.alpha_max:g}])")

    @property
    def nbytes(self):
        """Memory of the tabulated arrays [bytes]."""
        return sum(t.nbytes for t in self.tables)

    def _weights(self, binder_index):
        """Per point the Lagrange weight of every node, (P, n_nodes) (4 non-zero per row)."""
        start, weights = lagrange_stencil((binder_index - self._n0) / self._dn, self.nodes.size, 4)
        full = np.zeros((binder_index.size, self.nodes.size))
        np.put_along_axis(full, start[:, None] + np.arange(4), weights, axis=1)
        return full

    def _check(self, a, roughness, binder_index):
        a, roughness = self.tables[0]._check(a, roughness)
        n = np.asarray(binder_index, dtype=float)
        if not np.isfinite(n).all() or (n < self.n_min - 1e-12).any() or (n > self.n_max + 1e-12).any():
            raise ValueError(f"binder_index must lie in the tables' range [{self.n_min:g}, {self.n_max:g}]")
        return a, roughness, n

    def body(self, a, roughness, binder_index):
        """The body of every channel at validated 1-D ``a``, ``roughness``, ``binder_index`` (P,), (P, K)."""
        weights = self._weights(binder_index)
        first = self.tables[0]
        log_q = np.zeros((a.size, first.n_columns))
        for k, table in enumerate(self.tables):
            rows = np.flatnonzero(weights[:, k])
            if rows.size == a.size:
                log_q += weights[:, k, None] * table.interpolate_columns(a, roughness)
            elif rows.size:
                log_q[rows] += weights[rows, k, None] * table.interpolate_columns(a[rows], roughness[rows])
        q = np.exp(log_q)
        q *= np.maximum(1.0 - a, 0.0)[:, None]
        body = q[:, first._column]
        if first._any_factor:
            body *= first._body_factor
        return body

    def lobe(self, roughness, binder_index):
        """First-surface part of every channel at each ``(roughness, binder_index)`` (P,), (P, K)."""
        roughness = np.asarray(roughness, dtype=float).reshape(-1)
        binder_index = np.asarray(binder_index, dtype=float).reshape(-1)
        first = self.tables[0]
        out = np.zeros((roughness.size, self.n_channels))
        if first._analytic.size:
            # Walter's formula takes one index per call: one call per distinct n (one per walker)
            for n in np.unique(binder_index):
                rows = np.flatnonzero(binder_index == n)
                out[np.ix_(rows, first._analytic)] = first._factor * _reflection(
                    first._mu_i, first._mu_o, first._cos_psi, roughness[rows, None], 1.0, float(n),
                    self.settings.distribution)
        if first._hemispherical.size:
            weights = self._weights(binder_index)
            lobes = np.stack([t.lobe(roughness)[:, first._hemispherical] for t in self.tables], axis=1)
            out[:, first._hemispherical] = np.einsum("pn,pnc->pc", weights, lobes)
        return out

    def __call__(self, *, a, roughness, binder_index, part="total"):
        """Channel values of an opaque film, ``broadcast.shape + (n_channels,)``.

        Parameters
        ----------
        a : array_like
            Relative absorption [-], in [0, 1].
        roughness : array_like
            GGX ``alpha`` [-], in the tables' range.
        binder_index : array_like
            Binder index ``n`` [-], in ``[n_min, n_max]``; broadcast with ``a`` and ``roughness``.
        part : {"total", "body", "surface"}
        """
        if part not in ("total", "body", "surface"):
            raise ValueError(f"part must be one of ('total', 'body', 'surface'), got {part!r}")
        a, roughness, binder_index = self._check(a, roughness, binder_index)
        shape = np.broadcast_shapes(a.shape, roughness.shape, binder_index.shape)
        a, roughness, binder_index = (np.broadcast_to(v, shape).ravel() for v in (a, roughness, binder_index))
        out = np.zeros((a.size, self.n_channels))
        if part != "surface":
            out += self.body(a, roughness, binder_index)
        if part != "body":
            out += self.lobe(roughness, binder_index)
        return out.reshape(shape + (self.n_channels,))


def load_binder_index_tables(instrument, *, nodes=BINDER_INDEX_NODES, settings=None, cache_dir=None,
                             rebuild=False, progress=True, executor=None):
    """The rough tables of an instrument at every binder-index node (each cached as
    :func:`load_rough_table` caches it; built on first use), as :class:`BinderIndexRoughTables`.

    Parameters
    ----------
    instrument : str, Instrument or sequence
    nodes : sequence of float
        Uniform binder-index axis [-] (default :data:`BINDER_INDEX_NODES`).
    settings, cache_dir, rebuild, progress, executor
        As for :func:`load_rough_table`.
    """
    base = instrument if isinstance(instrument, Instrument) else get_instrument(instrument)
    tables = [load_rough_table(base, n=float(n), settings=settings, cache_dir=cache_dir, rebuild=rebuild,
                               progress=progress, executor=executor) for n in nodes]
    return BinderIndexRoughTables(tables, nodes)


def derive_rough_table(parent, instrument, *, cache_dir=None):
    """The rough table of ``instrument`` taken from ``parent``'s columns, and cached as built.

    Every body column of ``instrument`` (:func:`body_columns`) must be one of ``parent``'s and
    every hemispherical channel one of its channels (the same ``theta_i`` and port); the binder
    index is ``parent``'s. The numbers equal a build's: a column's body is the rough solve at
    its own ``(theta_i, theta_o)`` (tests/test_rough_table.py checks one against a build).

    Parameters
    ----------
    parent : RoughLookupTable
    instrument : Instrument
        Its ``n`` is replaced by ``parent``'s.
    cache_dir : path, optional
        Where the derived table is cached (default: the table cache); None-like values as for
        :func:`load_rough_table`.

    Returns
    -------
    RoughLookupTable

    Raises
    ------
    ValueError
        When a column or hemispherical channel of ``instrument`` is not in ``parent``.
    """
    instrument = dataclasses.replace(get_instrument(instrument), n=parent.instrument.n)
    keys, _, _ = body_columns(instrument)
    parent_keys, _, _ = body_columns(parent.instrument)
    missing = [k for k in keys if k not in parent_keys]
    if missing:
        raise ValueError(f"{len(missing)} body columns of {instrument.name!r} are not in the parent table "
                         f"{parent!r}, e.g. (hemispherical, theta_i, theta_o) = {missing[0]}")
    lobe = np.zeros((parent.n_alpha, len(instrument.channels)))
    for j, ch in enumerate(instrument.channels):
        if ch.kind != "hemispherical":
            continue
        match = [i for i, c in enumerate(parent.channels) if c.kind == "hemispherical"
                 and c.theta_i == ch.theta_i and c.specular == ch.specular]
        if not match:
            raise ValueError(f"channel {ch.label!r} of {instrument.name!r} is not in the parent table {parent!r}")
        lobe[:, j] = parent.arrays["lobe"][:, match[0]]
    columns = [parent_keys.index(k) for k in keys]
    arrays = {"log_q": np.ascontiguousarray(parent.arrays["log_q"][:, :, columns]), "lobe": lobe}
    table = RoughLookupTable(instrument, parent.settings, arrays, rough_table_key(instrument, parent.settings))
    path = rough_table_path(table.key, _cache_folder(cache_dir))
    if not path.is_file():
        save_rough_table(table, path)
    return table


# ---------------------------------------------------------------------------------------------
# cache


def save_rough_table(table, path):
    """Write a rough table atomically as ``.npz`` with its key, description and checksum."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = dict(table.arrays)
    payload["__key__"] = np.array(table.key)
    payload["__description__"] = np.array(_description(table.instrument, table.settings))
    payload["__checksum__"] = np.array(_checksum(table.arrays))
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        np.savez(handle, **payload)


def read_rough_table(path, instrument, settings):
    """A cached rough table, its key and checksum verified; :class:`~bayespig.table.CacheError` otherwise."""
    key = rough_table_key(instrument, settings)
    try:
        with open(path, "rb") as handle, np.load(handle, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except Exception as error:  # noqa: BLE001 - zip/npy errors of many kinds mean one thing here
        raise CacheError(f"cached table {path} is unreadable ({type(error).__name__}: {error})") from None
    stored_key, stored_sum = str(arrays.pop("__key__", "")), str(arrays.pop("__checksum__", ""))
    arrays.pop("__description__", None)
    if stored_key != key:
        raise CacheError(f"cached table {path} was built with other settings (key {stored_key} != {key})")
    if stored_sum != _checksum(arrays):
        raise CacheError(f"cached table {path} is corrupt (checksum mismatch)")
    table = RoughLookupTable(instrument, settings, arrays, key)
    table.checksum = stored_sum  # verified above: not hashed again
    return table


def load_rough_table(instrument, *, n=1.45, settings=None, cache_dir=None, rebuild=False, progress=True,
                     executor=None):
    """The cached rough look-up table of an instrument (opaque films), built on first use.

    Parameters
    ----------
    instrument : str, Instrument or sequence
        As for :func:`bayespig.load_table`.
    n : float
        Binder index [-] (used when ``instrument`` is not an :class:`Instrument`, or differs).
    settings : RoughTableSettings, optional
    cache_dir : path, optional
        Defaults to :func:`bayespig.table.cache_directory`.
    rebuild : bool
        Ignore any cached file.
    progress : bool
        Say when a table is built, with a progress bar.
    executor : concurrent.futures.Executor, optional
        For building.

    Returns
    -------
    RoughLookupTable
    """
    if settings is not None and not isinstance(settings, RoughTableSettings):
        raise TypeError(f"settings must be a RoughTableSettings or None, got {settings!r}")
    settings = settings or RoughTableSettings()
    if isinstance(instrument, Instrument):
        if instrument.n != n:
            instrument = dataclasses.replace(instrument, n=n)
    else:
        instrument = get_instrument(instrument, n=n)
    key = rough_table_key(instrument, settings)
    path = rough_table_path(key, _cache_folder(cache_dir))
    if path.is_file() and not rebuild:
        try:
            return read_rough_table(path, instrument, settings)
        except CacheError:
            rebuild = True
    with _build_lock(path, _table_title(instrument), progress) as waited:
        if (waited or not rebuild) and path.is_file():
            try:
                return read_rough_table(path, instrument, settings)
            except CacheError:
                pass
        if not os.access(path.parent, os.W_OK | os.X_OK):
            origin, remedy = _cache_origin(cache_dir)
            raise CacheLocationError(
                f"rough table {_table_title(instrument)} is not cached and cannot be built: the table cache "
                f"folder '{path.parent}' ({origin}) is not writable: {remedy}")
        started = time.perf_counter()
        table = build_rough_table(instrument, settings, executor=executor, progress=progress)
        table.build_seconds = time.perf_counter() - started
        save_rough_table(table, path)
    return table
