"""Look-up tables: an instrument's channels tabulated over (a, tau, g), cached on disk.

Fitting and sampling call the forward model millions of times, so, as the paper
does (section 2), it is tabulated once per instrument and interpolated. What is
tabulated are the terms of the substrate law (eq. 3) for every channel, so any
substrate albedo ``r_s`` — a scalar or one per wavelength — is exact::

    x(a, tau, g; r_s) = (1 - a) (1 - exp(-tau)) q(a, tau, g) + r_s D U / (1 - r_s R_up)

``q`` (the black-substrate value divided by its leading behaviour in ``omega`` and
``tau``), the substrate transmission terms ``D`` and ``U`` and ``R_up`` are smooth;
``log q``, ``log D`` and ``log U`` are interpolated by tensor-product Lagrange
stencils: cubic over ``v(a) ~ asinh(s sqrt(a))`` and ``log(tau)``, quintic over
``w = atanh(g)`` (see :class:`TableSettings`). Below ``tau_min`` the values are
linear in ``tau`` towards the exact ``tau -> 0`` slice; ``tau = inf`` (opaque,
eq. 2) is a slice of its own, the direct solver's discrete-ordinate solution of the
semi-infinite layer (exact down to ``a = 0``).

The ``tau`` axis is geometric so that one doubling sequence per base thickness
yields every node (adding–doubling produces ``R(2^k d)`` for free).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import sys
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

try:  # POSIX
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None
try:  # Windows
    import msvcrt
except ImportError:
    msvcrt = None

import numpy as np

from ._atomic import atomic_path
from ._pool import executor_or_local_pool
from ._validation import broadcast, choice, flag, integer, real_array, real_scalar
from ._versions import __version__
from .instruments import Instrument, channel_directions, get_instrument
from .physics.adding_doubling import (
    START_THICKNESS,
    START_THICKNESS_HIGHER_MODES,
    double,
    start_layer,
)
from .physics.forward import (
    surface_geometry,
    surface_mode,
    surface_mode_eigen,
    validate_layer_arguments,
)
from .physics.fresnel import fresnel_reflectance
from .physics.phase import normalise_on_quadrature, phase_fourier_modes
from .physics.quadrature import DEFAULT_QUADRATURE_POINTS

__all__ = [
    "CacheError",
    "CacheLocationError",
    "LookupTable",
    "TableSettings",
    "build_table",
    "cache_directory",
    "load_table",
]

#: Bump when the file layout or the tabulated quantities change (3: the opaque slice from the
#: discrete-ordinate solution, no longer doubled).
FORMAT_VERSION = 3
#: Smallest value kept before taking logarithms (far below any visible contribution).
LOG_FLOOR = 1e-300
#: Largest a evaluated on the a = 1 node (q is a limit there) [-].
A_MAX_EVAL = 1.0 - 1e-9
#: Thickness standing in for tau -> 0 (q is a limit there) [-].
TAU_ZERO_EVAL = 1e-10
#: Fourier modes whose channel contributions stay below this (relative to the sum so far, at
#: every tau of an a-node), twice in a row, end that a-node's sum: the neglected tail is ~1e-6,
#: far below the interpolation error (the direct solver uses the same tolerance).
MODE_TOLERANCE = 1e-6
#: Azimuthal modes m >= 1 of a layer transmitting less than this (per direction, diffuse plus
#: direct) no longer change on doubling (by ~T^2): such rows are not doubled further.
SATURATED_TRANSMITTANCE = 1e-13
#: Coordinates in which the g nodes can be uniform (:attr:`TableSettings.g_axis`).
G_AXES = ("atanh", "uniform")


@dataclass(frozen=True)
class TableSettings:
    """Every setting that changes a table's numbers (hashed into the cache key).

    Attributes
    ----------
    n_a : int
        Nodes on the absorption axis ``v = asinh(s sqrt(a)) / asinh(s)``, uniform over
        [0, 1]. Its nodes crowd towards ``a = 0``, where thick films depend on
        ``sqrt(3 a) tau`` (diffusion) and so vary fast.
    a_stretch : float
        ``s`` of that transform.
    log2_tau_min, log2_tau_max : int
        The ``tau`` axis runs geometrically from ``2^log2_tau_min`` to ``2^log2_tau_max``.
    per_octave : int
        ``tau`` nodes per factor of two.
    g_range : tuple of float
        ``(g_min, g_max)`` of the ``g`` axis; ``None`` for isotropic-only tables.
    n_g : int
        Nodes on the ``g`` axis.
    g_axis : {"atanh", "uniform"}
        Coordinate in which the ``g`` nodes are uniform: ``w = atanh(g)`` (default)
        crowds them towards ``|g| -> 1``, where the channels' dependence on ``g``
        sharpens, or ``w = g``.
    g_stencil : {4, 6}
        Nodes of the Lagrange stencil along ``w`` (cubic or quintic). Measured on
        direct-solver values (multi-angle-45, 28 values of g over [-0.5, 0.8], 35
        (a, tau) pairs), the largest relative error of the ``g`` interpolation alone is
        6.2e-5 for the quintic in ``atanh(g)`` on 16 nodes (1.6e-4 on 14), 1.1e-4 for
        the cubic in ``atanh(g)`` on 20 nodes, and 1.5e-3 for the cubic in ``g`` on 20.
    n_points : int
        Gauss points per quadrature interval of the solver.
    start_thickness : float
        Starting-layer thickness of the doubling.
    """

    n_a: int = 48
    a_stretch: float = 30.0
    log2_tau_min: int = -10
    log2_tau_max: int = 7
    per_octave: int = 4
    g_range: tuple | None = None
    n_g: int = 16
    g_axis: str = "atanh"
    g_stencil: int = 6
    n_points: int = DEFAULT_QUADRATURE_POINTS
    start_thickness: float = START_THICKNESS

    def __post_init__(self):
        integer("n_a", self.n_a, low=4)  # a cubic stencil needs four nodes
        real_scalar("a_stretch", self.a_stretch, low=0.0, low_open=True)
        integer("log2_tau_min", self.log2_tau_min)
        integer("log2_tau_max", self.log2_tau_max, low=self.log2_tau_min + 1)
        integer("per_octave", self.per_octave, low=1)
        integer("n_g", self.n_g, low=1)
        integer("n_points", self.n_points, low=1)
        real_scalar("start_thickness", self.start_thickness, low=0.0, low_open=True)
        if not isinstance(self.g_axis, str) or self.g_axis not in G_AXES:
            raise ValueError(f"g_axis must be one of {', '.join(G_AXES)}, got {self.g_axis!r}")
        if self.g_range is not None:
            try:
                lo, hi = (float(v) for v in self.g_range)
            except (TypeError, ValueError):
                raise ValueError(f"g_range must be None or a pair (g_min, g_max), got {self.g_range!r}") from None
            if not (-1.0 < lo < hi < 1.0):
                raise ValueError(f"g_range must satisfy -1 < g_min < g_max < 1, got {self.g_range!r}")
            if self.g_stencil not in LAGRANGE_MATRICES:
                raise ValueError(f"g_stencil must be one of {sorted(LAGRANGE_MATRICES)}, got {self.g_stencil!r}")
            if self.n_g < self.g_stencil:
                raise ValueError(f"n_g must be at least g_stencil = {self.g_stencil}, got {self.n_g}")

    @property
    def v_nodes(self):
        """Nodes of the absorption coordinate ``v`` [-]."""
        return np.linspace(0.0, 1.0, self.n_a)

    def v_of_a(self, a):
        """Absorption coordinate ``v(a)`` and ``dv/da``."""
        u = np.sqrt(a)
        scale = np.arcsinh(self.a_stretch)
        with np.errstate(divide="ignore"):
            dv_da = self.a_stretch / np.sqrt(1.0 + (self.a_stretch * u) ** 2) / scale * 0.5 / u
        return np.arcsinh(self.a_stretch * u) / scale, dv_da

    @property
    def a_nodes(self):
        """Nodes of ``a`` [-]."""
        u = np.sinh(self.v_nodes * np.arcsinh(self.a_stretch)) / self.a_stretch
        return np.minimum(u * u, 1.0)

    @property
    def tau_nodes(self):
        """Finite ``tau`` nodes, ``tau_min .. tau_max`` geometric [-]."""
        n = (self.log2_tau_max - self.log2_tau_min) * self.per_octave + 1
        return 2.0 ** (self.log2_tau_min + np.arange(n) / self.per_octave)

    def w_of_g(self, g):
        """Coordinate ``w(g)`` of the ``g`` axis (see ``g_axis``) and ``dw/dg``."""
        g = np.asarray(g, dtype=float)
        if self.g_axis == "uniform":
            return g, np.ones_like(g)
        return np.arctanh(g), 1.0 / (1.0 - g * g)

    @property
    def w_nodes(self):
        """Nodes of the ``g`` coordinate ``w``, uniform (a single 0 for isotropic tables)."""
        if self.g_range is None:
            return np.zeros(1)
        lo, hi = self.w_of_g(np.asarray(self.g_range, dtype=float))[0]
        return np.linspace(lo, hi, self.n_g)

    @property
    def g_nodes(self):
        """Nodes of the ``g`` axis (a single 0 for isotropic tables); the ends are exactly ``g_range``."""
        if self.g_range is None:
            return np.zeros(1)
        w = self.w_nodes
        g = w if self.g_axis == "uniform" else np.tanh(w)
        g[0], g[-1] = self.g_range
        return g


def cache_directory():
    """Directory of cached tables: ``$BAYESPIG_CACHE`` or the user cache directory."""
    env = os.environ.get("BAYESPIG_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or (Path.home() / ".cache")
    return Path(base) / "bayespig"


def _instrument_description(instrument):
    return {"n": instrument.n, "channels": [dataclasses.asdict(ch) for ch in instrument.channels]}


def table_description(instrument, settings):
    """JSON text of every setting that changes a table's numbers (hashed by :func:`table_key`)."""
    description = {
        "format": FORMAT_VERSION,
        "version": __version__,
        "instrument": _instrument_description(instrument),
        "settings": dataclasses.asdict(settings),
    }
    return json.dumps(description, sort_keys=True, default=float)


def table_key(instrument, settings):
    """Hash of every setting that changes a table's numbers."""
    return hashlib.sha256(table_description(instrument, settings).encode()).hexdigest()[:32]


def table_path(key, cache_dir=None):
    """Cache file of the table with this key, in ``cache_dir`` or :func:`cache_directory`."""
    return Path(cache_dir or cache_directory()) / f"table-{key}.npz"


# ---------------------------------------------------------------------------------------------
# building


def _build_g_slice(instrument, settings, g):
    """Tabulate one value of ``g``: arrays (n_a, n_tau + 2, K) over a-nodes and tau-nodes.

    The tau index runs: 0 -> tau = 0 limit, 1..n_tau -> ``settings.tau_nodes``, last -> opaque.

    Work shared between nodes: ``per_octave`` doubling chains produce every finite ``tau``
    node (doubling gives ``R(2^k d)`` for free); the opaque slice is the direct solver's
    discrete-ordinate solution of the semi-infinite layer under its surface
    (:func:`~bayespig.physics.forward.surface_mode_eigen`, exact down to ``a = 0``, where
    doubling's spurious absorption would cost ~1e-5 of the conservative reflectance);
    in azimuthal modes m >= 1 rows that no longer transmit stop doubling, and a-nodes whose
    channel values have converged (mode contributions below ``MODE_TOLERANCE`` of the
    sum, twice in a row, at every tau) leave the Fourier sum. Every decision is per
    a-node, so the numbers do not depend on how the work is split.
    """
    theta_in, theta_out, index_in, index_out = channel_directions(instrument)
    geometry = surface_geometry(theta_in, theta_out, instrument.n, settings.n_points)
    mu, weight, c = geometry.mu, geometry.weight, geometry.c
    n_weighted = int(np.count_nonzero(weight))  # weighted nodes first, measurement directions last
    if (weight[:n_weighted] <= 0).any():
        raise RuntimeError("the quadrature's zero-weight nodes must come last")
    a = np.minimum(settings.a_nodes, A_MAX_EVAL)
    albedo = 1.0 - a
    taus = settings.tau_nodes
    P = settings.per_octave
    n_a, n_tau, K = a.size, taus.size, len(instrument)
    max_modes = 1 if g == 0.0 else int(np.ceil(np.log(MODE_TOLERANCE) / np.log(abs(g)))) + 1
    p_refl = phase_fourier_modes(mu, mu, g, max_modes, reflection=True)
    p_trans = phase_fourier_modes(mu, mu, g, max_modes, reflection=False)
    p_refl, p_trans = normalise_on_quadrature(p_refl, p_trans, weight)
    kinds = [ch.kind for ch in instrument.channels]
    if all(kind == "hemispherical" for kind in kinds):
        max_modes = 1  # hemispherical reflectance sees only the azimuthal average
    black = np.zeros((n_a, n_tau + 2, K))
    quiet = np.zeros(n_a, dtype=int)
    rows = np.arange(n_a)  # a-nodes still summing modes
    for m in range(max_modes):
        start = settings.start_thickness if m == 0 else max(settings.start_thickness, START_THICKNESS_HIGHER_MODES)
        # mode 0 doubles exactly as the direct solver's doubling path does (finite weakly
        # absorbing layers); modes m >= 1 skip the zero weights
        q = mu.size if m == 0 else n_weighted
        B = rows.size
        # the finite columns: tau -> 0 and the tau nodes (the opaque one is solved below)
        R_all = np.empty((B, n_tau + 1, mu.size, mu.size))
        # modes m >= 1 enter only through R (their BRDF mode); T and direct serve mode 0's eq. (3) terms
        T_all = np.empty_like(R_all) if m == 0 else None
        e_all = np.empty((B, n_tau + 1, mu.size)) if m == 0 else None
        R_zero, T_zero, e_zero = start_layer(mu, c, albedo[rows], np.full(B, TAU_ZERO_EVAL), p_refl[m], p_trans[m])
        R_all[:, 0] = R_zero
        if m == 0:
            T_all[:, 0], e_all[:, 0] = T_zero, e_zero
        for p in range(P):
            base = taus[p]
            k0 = int(max(0, np.ceil(np.log2(base / start))))
            R, T, e = start_layer(mu, c, albedo[rows], np.full(B, base / 2.0**k0), p_refl[m], p_trans[m])
            for _ in range(k0):
                R, T, e = _double(R, T, e, c, q)
            _doubling_chain(R, T, e, c, q, R_all, T_all, e_all, range(1 + p, 1 + n_tau, P), saturate=m > 0)
        flat = (B * (n_tau + 1), mu.size)
        finite = surface_mode(geometry, R_all.reshape(flat + (mu.size,)),
                              None if T_all is None else T_all.reshape(flat + (mu.size,)),
                              None if e_all is None else e_all.reshape(flat), m == 0)
        opaque = surface_mode_eigen(geometry, a[rows], np.full(B, np.inf), p_refl[m], p_trans[m], m == 0, start)
        # every term with the opaque slice as the last tau column: (B, n_tau + 2, ...)
        mode = {key: np.concatenate([finite[key].reshape((B, n_tau + 1) + opaque[key].shape[1:]),
                                     opaque[key][:, None]], axis=1) for key in finite}
        f_mode = mode.pop("f_mode")
        weight_m = (2.0 - (m == 0)) * (-1.0) ** m
        contribution = np.empty((B, n_tau + 2, K))
        for k, ch in enumerate(instrument.channels):
            f = f_mode[:, :, index_out[k], index_in[k]]
            if ch.kind == "hemispherical":
                contribution[..., k] = mode["h0"].reshape(B, n_tau + 2, -1)[..., index_in[k]] if m == 0 else 0.0
            else:
                factor = np.pi if ch.kind == "reflectance_factor" else 1.0
                contribution[..., k] = factor * weight_m * np.cos(m * np.radians(ch.delta_phi)) * f
        black[rows] += contribution
        if m == 0:
            t_down = mode["t_down"].reshape(n_a, n_tau + 2, -1)[..., index_in]
            t_up = np.empty((n_a, n_tau + 2, K))
            for k, kind in enumerate(kinds):
                if kind == "hemispherical":
                    t_up[..., k] = mode["t_up_hemispherical"].reshape(n_a, n_tau + 2)
                else:
                    factor = np.pi if kind == "reflectance_factor" else 1.0
                    t_up[..., k] = factor * mode["t_up"].reshape(n_a, n_tau + 2, -1)[..., index_out[k]]
            r_up = mode["r_up"].reshape(n_a, n_tau + 2)
        else:
            # every tabulated value of an a-node, dark ones included, must have converged
            small = (np.abs(contribution) <= MODE_TOLERANCE * np.abs(black[rows])).all(axis=(1, 2))
            quiet[rows] = np.where(small, quiet[rows] + 1, 0)
            rows = rows[quiet[rows] < 2]
            if not rows.size:
                break
    leading = albedo[:, None] * -np.expm1(-np.concatenate([[TAU_ZERO_EVAL], taus, [np.inf]]))[None, :]
    log_q = np.log(np.maximum(black / leading[..., None], LOG_FLOOR))
    return {
        "log_q": log_q,
        "log_d": np.log(np.maximum(t_down, LOG_FLOOR)),
        "log_u": np.log(np.maximum(t_up, LOG_FLOOR)),
        "r_up": r_up,
    }


def _double(R, T, direct, c, n_weighted):
    """:func:`~bayespig.physics.adding_doubling.double` for a quadrature whose last nodes
    have zero weight (the measurement directions): the angular sums run over the first
    ``n_weighted`` nodes only, and the system for the radiance between the two layers is
    block-triangular (the zero-weight rows follow from the others), so the linear solve
    is of size ``n_weighted``. The same kernels up to rounding, for ~20 % less work.
    """
    q = n_weighted
    if q == c.size:
        return double(R, T, direct, c)
    cq = c[:q]
    Rc = R[:, :, :q] * cq  # (B, N, q): every angular sum is over the weighted nodes
    RcR = Rc @ R[:, :q, :]
    source = T + RcR * direct[:, None, :]
    coupling = RcR[:, :, :q] * cq  # (B, N, q) = (R c R c) restricted to weighted columns
    between = np.empty_like(source)
    between[:, :q] = np.linalg.solve(np.eye(q) - coupling[:, :q], source[:, :q])
    between[:, q:] = source[:, q:] + coupling[:, q:] @ between[:, :q]
    up = R * direct[:, None, :] + Rc @ between[:, :q]
    Tc = T[:, :, :q] * cq
    R_new = R + direct[:, :, None] * up + Tc @ up[:, :q]
    T_new = T * direct[:, None, :] + direct[:, :, None] * between + Tc @ between[:, :q]
    return R_new, T_new, direct * direct


def _transmitted(T, e, c):
    """Largest fraction of a direction's light a layer still lets through, per batch row."""
    return np.abs(T * c).sum(axis=-1).max(axis=-1) + e.max(axis=-1)


def _doubling_chain(R, T, e, c, q, R_all, T_all, e_all, columns, saturate):
    """Double a layer on and on, storing it at each of ``columns`` of ``R_all`` etc.

    With ``saturate`` (azimuthal modes m >= 1, where only ``R`` is used) a batch row
    stops doubling once it transmits less than ``SATURATED_TRANSMITTANCE``: its ``R``
    no longer changes (by ~ T^2) and is stored as it is, with ``T = direct = 0``.
    Every row is computed on its own, so the result does not depend on the batch.

    Returns the layer at the last column (saturated rows with T, e set to 0).
    """
    active = np.arange(R.shape[0])
    for count, column in enumerate(columns):
        if count:
            R_active, T_active, e_active = _double(R[active], T[active], e[active], c, q)
            R[active], T[active], e[active] = R_active, T_active, e_active
        if saturate:
            done = _transmitted(T[active], e[active], c) < SATURATED_TRANSMITTANCE
            if done.any():
                T[active[done]] = 0.0
                e[active[done]] = 0.0
                active = active[~done]
        R_all[:, column] = R
        if T_all is not None:
            T_all[:, column], e_all[:, column] = T, e
    return R, T, e


def _slice_cost(g):
    """Rough relative cost of a ``g`` slice (for scheduling only): Fourier modes needed."""
    return 1.0 + abs(g) * (2.0 if g < 0 else 1.0)


def _check_index(n):
    n = real_scalar("n", n, allow_inf=True)  # a TypeError for a string, None or a boolean
    if not np.isfinite(n) or n < 1.0:
        raise ValueError(f"n (binder refractive index) must be a finite number >= 1, got {n!r}")


def build_table(instrument, settings=None, *, executor=None, progress=True):
    """Tabulate an instrument's channels (not cached; see :func:`load_table`).

    Parameters
    ----------
    instrument : str, Instrument or sequence
        See :func:`bayespig.instruments.get_instrument`.
    settings : TableSettings, optional
        Axes and solver settings.
    executor : concurrent.futures.Executor, optional
        Runs the ``g`` slices in parallel; by default a local process pool when
        there are several slices.
    progress : bool
        Show a progress bar (tqdm) over the slices.

    Returns
    -------
    LookupTable
    """
    instrument = get_instrument(instrument)
    _check_index(instrument.n)
    if settings is not None and not isinstance(settings, TableSettings):
        raise TypeError(f"settings must be a TableSettings or None, got {settings!r} ({type(settings).__name__})")
    settings = settings or TableSettings()
    g_nodes = settings.g_nodes
    with executor_or_local_pool(executor, needed=g_nodes.size > 1) as pool:
        if pool is None:
            slices = [_build_g_slice(instrument, settings, float(g)) for g in g_nodes]
        else:
            # the dearest slices first (backward scattering needs the most Fourier modes), so
            # that the last ones to finish are cheap; results are gathered in node order
            order = sorted(range(g_nodes.size), key=lambda i: -_slice_cost(g_nodes[i]))
            submitted = {i: pool.submit(_build_g_slice, instrument, settings, float(g_nodes[i])) for i in order}
            futures = [submitted[i] for i in range(g_nodes.size)]
            slices = []
            iterator = futures
            if progress and g_nodes.size > 1:
                from tqdm.auto import tqdm

                iterator = tqdm(futures, desc=f"building table {instrument.name}", unit="g", file=sys.stderr)
            for future in iterator:
                slices.append(future.result())
    arrays = {key: np.stack([s[key] for s in slices]) for key in slices[0]}
    return LookupTable(instrument, settings, arrays, table_key(instrument, settings))


# ---------------------------------------------------------------------------------------------
# interpolation

#: Cubic Lagrange weights on nodes 0, 1, 2, 3 as polynomials in t: ``w = [1, t, t^2, t^3] @ M``.
LAGRANGE_MATRIX = np.array([
    [1.0, 0.0, 0.0, 0.0],
    [-11.0 / 6.0, 3.0, -1.5, 1.0 / 3.0],
    [1.0, -2.5, 2.0, -0.5],
    [-1.0 / 6.0, 0.5, -0.5, 1.0 / 6.0],
])
_OFFSETS = np.arange(4)
#: Points interpolated per block (bounds the gathered (points x 64 x columns) array).
EVALUATION_BLOCK = 2048


def _lagrange_matrix(width):
    """Coefficients of the Lagrange basis on nodes 0 .. width-1: ``w = [1, t, ..., t^(width-1)] @ M``."""
    matrix = np.empty((width, width))
    for i in range(width):
        others = [j for j in range(width) if j != i]
        matrix[:, i] = np.polynomial.polynomial.polyfromroots(others) / np.prod([i - j for j in others])
    return matrix


#: Lagrange basis coefficients per stencil width (4: cubic, 6: quintic).
LAGRANGE_MATRICES = {4: LAGRANGE_MATRIX, 6: _lagrange_matrix(6)}


def lagrange_stencil(position, n, width=4, derivative=False):
    """Start node and Lagrange weights on a uniform axis, in units of its spacing.

    Parameters
    ----------
    position : numpy.ndarray
        Coordinate in node units (node ``k`` at ``k``), shape (..., P).
    n : int or numpy.ndarray
        Nodes on the axis (>= ``width``), or one per leading index of ``position``
        (shape (..., 1)) to treat several axes in one call. The stencil of ``width`` nodes is centred
        on the interval holding ``position`` and clamped to the axis, so positions
        beyond the end nodes extrapolate the end polynomial.
    width : {4, 6}
        Stencil nodes (polynomial degree + 1).
    derivative : bool
        Also return the weights' derivatives with respect to ``position``.

    Returns
    -------
    start : numpy.ndarray
        Shape (..., P), int.
    weights : numpy.ndarray
        Shape (..., P, width); with ``derivative`` a second array of d(weights)/d(position).
    """
    half = width // 2 - 1
    start = np.floor(np.minimum(np.maximum(position, half), n - width + half)).astype(np.intp) - half
    t = (position - start)[..., None]
    # Horner, elementwise: the same numbers whatever else is in the batch
    matrix = LAGRANGE_MATRICES[width]
    weights = matrix[-1]
    for row in matrix[-2::-1]:
        weights = row + t * weights
    if not derivative:
        return start, weights
    d_weights = (width - 1) * matrix[-1]
    for k in range(width - 2, 0, -1):
        d_weights = k * matrix[k] + t * d_weights
    return start, weights, d_weights


class LookupTable:
    """A tabulated instrument: ``table(a=..., tau=..., g=..., r_s=...)`` -> ``(..., n_channels)``.

    Build with :func:`build_table` or, cached, :func:`load_table`.

    The interpolated quantities (``log q``, ``log D + log U`` and ``R_up`` per
    channel, module docstring) are stacked into one array of ``2 K + 1`` columns
    with one row per (g, a, tau) node, so that one evaluation is one gather of the
    4 x 4 (x ``g_stencil`` with a ``g`` axis) stencil rows and one weighted sum. The ``tau``
    stencil covers every case: cubic in ``log tau`` at ``tau >= tau_min``, linear in
    ``tau`` towards the ``tau -> 0`` slice below it, and the opaque slice alone at
    ``tau = inf``.

    Attributes
    ----------
    instrument : Instrument
    channels : tuple of Channel
    settings : TableSettings
    key : str
        Hash of everything that changes the numbers (cache key, recorded in results).
    checksum : str
        SHA-256 of the tabulated arrays (their names and bytes; the cache file's checksum),
        recorded in results next to the key: two runs with the same checksum used the same
        numbers, bit for bit (a table rebuilt on another CPU may differ in the last bits).
    arrays : dict of numpy.ndarray
        The tabulated arrays ``log_q``, ``log_d``, ``log_u`` (n_g, n_a, n_tau + 2, K)
        and ``r_up`` (n_g, n_a, n_tau + 2); tau index 0 is the ``tau -> 0`` limit,
        the last the opaque limit.
    """

    def __init__(self, instrument, settings, arrays, key):
        self.instrument = instrument
        self.settings = settings
        self.key = key
        self.arrays = arrays
        self.channels = instrument.channels
        n_g, n_a, n_rows, n_channels = arrays["log_q"].shape
        self.n_g, self.n_a, self.n_tau_rows, self.n_channels = n_g, n_a, n_rows, n_channels
        r_up = arrays["r_up"].copy()
        r_up[:, :, -1] = 0.0  # an opaque film never sees its substrate (its D U is 0)
        stacked = np.concatenate([arrays["log_q"], arrays["log_d"] + arrays["log_u"], r_up[..., None]], axis=-1)
        #: One row per (g, a, tau) node, columns log q (K), log D + log U (K), R_up.
        self.stacked = np.ascontiguousarray(stacked.reshape(-1, stacked.shape[-1]))
        tau_nodes = settings.tau_nodes
        self.tau_min, self.tau_max = float(tau_nodes[0]), float(tau_nodes[-1])
        self._n_tau = tau_nodes.size
        self._tau_nodes = tau_nodes
        ratio = 2.0 ** (1.0 / settings.per_octave)
        #: Lagrange basis on the nodes 1, r, r^2, r^3 (r the node ratio), rows = powers of tau / tau_start.
        self._tau_basis = np.stack([
            np.polynomial.polynomial.polyfromroots([ratio**j for j in range(4) if j != k])
            / np.prod([ratio**k - ratio**j for j in range(4) if j != k]) for k in range(4)], axis=1)
        #: Columns interpolated cubically in log tau (log q) and in tau (log D + log U, R_up).
        self._column_groups = (slice(0, n_channels), slice(n_channels, 2 * n_channels + 1))
        self._x0 = float(np.log(tau_nodes[0]))
        self._dx = float(np.log(tau_nodes[1]) - np.log(tau_nodes[0]))
        self._du = float(settings.v_nodes[1] - settings.v_nodes[0])
        self._a_stretch = float(settings.a_stretch)
        self._asinh_stretch = float(np.arcsinh(settings.a_stretch))
        w_nodes = settings.w_nodes
        self._n_a_tau = np.array([[n_a], [self._n_tau]])
        #: Row offsets of the 4 x 4 (a, tau) stencil in ``stacked``, a-major.
        self._a_tau_offsets = ((_OFFSETS * n_rows)[:, None] + _OFFSETS).ravel()
        self._w0 = float(w_nodes[0])
        self._dw = float(w_nodes[1] - w_nodes[0]) if w_nodes.size > 1 else 1.0
        self._sci = np.array([
            fresnel_reflectance(np.cos(np.radians(ch.theta_i)), 1.0, instrument.n)
            if ch.kind == "hemispherical" and ch.specular == "included" else 0.0
            for ch in instrument.channels
        ])

    @functools.cached_property
    def checksum(self):
        """SHA-256 of :attr:`arrays` (hex), as the cache file records it."""
        return _checksum(self.arrays)

    @property
    def free_g(self):
        """Whether the table has a ``g`` axis."""
        return self.settings.g_range is not None

    def __repr__(self):
        g = f"g in {self.settings.g_range}" if self.free_g else "isotropic"
        return f"LookupTable({self.instrument.name!r}, {len(self.channels)} channels, {g}, key={self.key})"

    def _check(self, a, tau, g, r_s):
        """Full validation; raises ``ValueError`` naming the bad argument."""
        validate_layer_arguments(a=a, tau=tau, g=g, r_s=r_s, n=self.instrument.n)
        if not self.free_g and (np.asarray(g) != 0.0).any():
            raise ValueError("this table is isotropic (g = 0); load it with g='free' to vary g")
        if self.free_g:
            lo, hi = self.settings.g_range
            if ((np.asarray(g) < lo) | (np.asarray(g) > hi)).any():
                raise ValueError(f"g must lie in the table's range [{lo}, {hi}]")
        if (np.isfinite(tau) & (np.asarray(tau) > self.tau_max)).any():
            raise ValueError(f"finite tau must be <= {self.tau_max:g} (use inf for opaque films)")

    def _valid(self, a, tau, g, r_s):
        """Quick test that every argument lies in its domain (NaN fails); False sends to :meth:`_check`."""
        if not (a.size and tau.size and g.size and r_s.size):
            return False
        if self.free_g:
            lo, hi = self.settings.g_range
            g_ok = lo <= g.min() and g.max() <= hi
        else:
            g_ok = not g.any() and not np.isnan(g).any()
        return bool(g_ok and 0.0 <= a.min() and a.max() <= 1.0 and 0.0 <= r_s.min() and r_s.max() <= 1.0
                    and 0.0 <= tau.min() and tau.max() <= self.tau_max)

    def __call__(self, *, a, tau, g=0.0, r_s=0.0):
        """Channel values for the given pigment and substrate.

        Parameters
        ----------
        a, tau, g, r_s : array_like
            Relative absorption [-], optical thickness [-] (``inf`` = opaque, finite
            values up to ``2^log2_tau_max``), phase-function parameter, substrate
            albedo seen from the binder [-]; broadcast together.

        Returns
        -------
        numpy.ndarray
            Shape ``broadcast.shape + (n_channels,)``: BRDF [1/sr], hemispherical
            reflectance [-] or reflectance factor [-] per channel.
        """
        return self.evaluate(a=a, tau=tau, g=g, r_s=r_s)

    def evaluate(self, *, a, tau, g=0.0, r_s=0.0, gradient=False):
        """Channel values and optionally their derivatives with respect to a, tau and g.

        The substrate enters exactly through the substrate law (eq. 3); the layer's
        terms are interpolated (module docstring), so derivatives are those of the
        interpolant, by the chain rule through the axes' transforms
        (``v(a)``, ``log tau``, ``w(g)``).

        Parameters
        ----------
        a, tau, g, r_s : array_like
            As for :meth:`__call__`.
        gradient : bool
            Also return the derivatives.

        Returns
        -------
        numpy.ndarray or tuple
            Values ``(..., K)``; with ``gradient=True`` also ``d/da``, ``d/dtau``,
            ``d/dg`` of the same shape (``d/dtau`` is 0 for opaque films;
            ``d/da`` is infinite at ``a = 0`` exactly, where the dependence is ``sqrt(a)``).
        """
        for name, value in (("a", a), ("tau", tau), ("g", g), ("r_s", r_s)):
            if not isinstance(value, (np.ndarray, float, int)) or isinstance(value, bool):
                try:
                    real_array(name, value, allow_inf=True)  # a string, None, a boolean: named
                except ValueError:  # NaN: said below in the table's words
                    pass
        args = [np.asarray(v, dtype=float) for v in (a, tau, g, r_s)]
        if not self._valid(*args):
            self._check(*args)
        a, tau, g, r_s = args
        # the layer terms are interpolated once per (a, tau, g); r_s broadcasts afterwards
        if a.shape == tau.shape == g.shape and (r_s.ndim == 0 or r_s.shape == a.shape):
            layer_shape = a.shape
            a, tau, g = a.ravel(), tau.ravel(), g.ravel()
        else:
            try:
                np.broadcast_shapes(a.shape, tau.shape, g.shape, r_s.shape)
            except ValueError:
                broadcast(a=a, tau=tau, g=g, r_s=r_s)  # raises, naming them and their shapes
            layer_shape = np.broadcast_shapes(a.shape, tau.shape, g.shape)
            a, tau, g = (np.broadcast_to(v, layer_shape).ravel() for v in (a, tau, g))
        g = g if self.n_g > 1 else None
        n = a.size
        if n <= EVALUATION_BLOCK:
            terms = self.interpolate(a, tau, g, gradient)
        else:
            terms = np.concatenate([
                self.interpolate(a[i:i + EVALUATION_BLOCK], tau[i:i + EVALUATION_BLOCK],
                                 None if g is None else g[i:i + EVALUATION_BLOCK], gradient)
                for i in range(0, n, EVALUATION_BLOCK)])
        terms = terms.reshape(layer_shape + terms.shape[1:])
        a, tau = a.reshape(layer_shape + (1,)), tau.reshape(layer_shape + (1,))
        r_s = r_s[..., None]
        k = self.n_channels
        omega = np.maximum(1.0 - a, 0.0)
        lead = -np.expm1(-tau)
        if not gradient:
            gain = r_s / (1.0 - r_s * terms[..., 2 * k:])
            return omega * lead * np.exp(terms[..., :k]) + gain * np.exp(terms[..., k:2 * k]) + self._sci
        log_q, log_du, r_up = terms[..., :k], terms[..., k:2 * k], terms[..., 2 * k:]
        q = np.exp(log_q[..., 0, :])
        black = omega * lead * q
        denominator = 1.0 - r_s * r_up[..., 0, :]
        gain = r_s / denominator
        through = np.exp(log_du[..., 0, :])
        substrate = gain * through
        value = black + substrate + self._sci
        # d/dv, d/dtau, d/dw of the value through the interpolated terms
        d_gain = r_s * r_s / (denominator * denominator)
        d_v, d_tau, d_w = (black * log_q[..., i, :] + substrate * log_du[..., i, :] + d_gain * r_up[..., i, :]
                           * through for i in (1, 2, 3))
        with np.errstate(divide="ignore", invalid="ignore"):
            d_a = d_v * self.settings.v_of_a(a)[1] - lead * q
        d_tau = d_tau + omega * np.exp(-tau) * q
        d_g = d_w * self.settings.w_of_g(g.reshape(layer_shape + (1,)))[1] if g is not None else np.zeros_like(value)
        return (value,) + tuple(d if d.shape == value.shape else np.broadcast_to(d, value.shape).copy()
                                for d in (d_a, d_tau, d_g))

    def interpolate(self, a, tau, g=None, derivatives=False):
        """The interpolated layer terms at validated 1-D arguments (the fast path).

        Parameters
        ----------
        a, tau : numpy.ndarray
            Shape (P,); ``a`` in [0, 1], ``tau`` in [0, tau_max] or ``inf``.
        g : numpy.ndarray, optional
            Shape (P,) (None for 0; ignored by isotropic tables).
        derivatives : bool
            Also return the derivatives with respect to ``v(a)``, ``tau`` and ``w(g)``.

        Returns
        -------
        numpy.ndarray
            Shape (P, 2 K + 1): ``log q``, ``log D + log U`` and ``R_up``; with
            ``derivatives`` shape (P, 4, 2 K + 1), the value and its three derivatives.
        """
        u = np.arcsinh(self._a_stretch * np.sqrt(a)) / self._asinh_stretch
        # tau stencil over the rows (0: tau -> 0, 1..n_tau: nodes, last: opaque)
        opaque = np.isinf(tau)
        small = tau < self.tau_min
        special = opaque.any() or small.any()
        tau_cubic = np.where(opaque | small, self.tau_min, tau) if special else tau
        x = (np.log(tau_cubic) - self._x0) / self._dx
        # one stencil call for both axes (a: row 0, log tau: row 1)
        stencil = lagrange_stencil(np.stack([u / self._du, x]), self._n_a_tau, 4, derivatives)
        (su, st), (wu, wt) = stencil[0], stencil[1]
        # the substrate terms: the cubic in tau itself through the same four nodes (geometric
        # nodes: one basis in tau / tau_start for every stencil), exact for the linear
        # attenuation log D ~ -tau / mu of absorbing films
        node = self._tau_nodes[st]
        ratio = (tau_cubic / node)[:, None]
        m0, m1, m2, m3 = self._tau_basis
        wl = m0 + ratio * (m1 + ratio * (m2 + ratio * m3))
        if derivatives:
            dwu, dwt = stencil[2]
            dwt = dwt / (self._dx * tau_cubic)[:, None]
            dwl = (m1 + ratio * (2.0 * m2 + ratio * (3.0 * m3))) / node[:, None]
        st = st + 1
        if special:
            s = np.where(small, tau / self.tau_min, 0.0)
            linear = np.stack([1.0 - s, s, np.zeros_like(s), np.zeros_like(s)], axis=1)
            last = np.zeros((1, 4))
            last[0, 3] = 1.0
            st = np.where(small, 0, np.where(opaque, self.n_tau_rows - 4, st))
            wt = np.where(small[:, None], linear, np.where(opaque[:, None], last, wt))
            wl = np.where(small[:, None], linear, np.where(opaque[:, None], last, wl))
            if derivatives:
                slope = np.array([[-1.0, 1.0, 0.0, 0.0]]) / self.tau_min
                dwt = np.where(small[:, None], slope, np.where(opaque[:, None], 0.0, dwt))
                dwl = np.where(small[:, None], slope, np.where(opaque[:, None], 0.0, dwl))
        rows = (su * self.n_tau_rows + st)[:, None] + self._a_tau_offsets
        if self.n_g > 1:
            w = np.zeros(a.shape) if g is None else self.settings.w_of_g(g)[0]
            width = self.settings.g_stencil
            g_stencil = lagrange_stencil((w - self._w0) / self._dw, self.n_g, width, derivatives)
            sg, wg = g_stencil[0], g_stencil[1]
            block = self.n_a * self.n_tau_rows
            rows = ((sg[:, None] + np.arange(width)) * block)[:, :, None] + rows[:, None, :]
            rows = rows.reshape(rows.shape[0], -1)

        def tensor(w_tau, dw_tau):
            """Weights of the stencil rows (P, S), or (P, 4, S) with d/dv, d/dtau, d/dw."""
            weights = (wu[:, :, None] * w_tau[:, None, :]).reshape(-1, 16)
            if derivatives:
                weights = np.stack([weights, (dwu[:, :, None] * w_tau[:, None, :]).reshape(-1, 16) / self._du,
                                    (wu[:, :, None] * dw_tau[:, None, :]).reshape(-1, 16)], axis=1)
            if self.n_g > 1:
                if derivatives:
                    value_weights = weights[:, 0]
                    weights = (wg[:, None, :, None] * weights[:, :, None, :]).reshape(a.size, 3, -1)
                    d_w = (g_stencil[2][:, :, None] * value_weights[:, None, :]).reshape(a.size, 1, -1) / self._dw
                    weights = np.concatenate([weights, d_w], axis=1)
                else:
                    weights = (wg[:, :, None] * weights[:, None, :]).reshape(a.size, -1)
            elif derivatives:
                weights = np.concatenate([weights, np.zeros_like(weights[:, :1])], axis=1)
            return weights

        weight_groups = (tensor(wt, dwt if derivatives else None), tensor(wl, dwl if derivatives else None))
        gathered = self.stacked.take(rows, axis=0)
        # weighted sums over the stencil rows, per point in a fixed order (einsum's loops, not
        # BLAS): a point's result does not depend on the batch it came in, nor on whether
        # derivatives are asked; log q on the log-tau cubic, the substrate terms on the tau cubic
        parts = []
        for weights, columns in zip(weight_groups, self._column_groups):
            part = gathered[:, :, columns]
            value = np.einsum("ps,psc->pc", weights[:, 0] if derivatives else weights, part)
            if derivatives:
                value = np.concatenate([value[:, None], np.einsum("pds,psc->pdc", weights[:, 1:], part)], axis=1)
            parts.append(value)
        return np.concatenate(parts, axis=-1)


# ---------------------------------------------------------------------------------------------
# cache


def _checksum(arrays):
    """SHA-256 (hex) of named arrays: every name and the array's bytes, in sorted name order."""
    digest = hashlib.sha256()
    for key in sorted(arrays):
        digest.update(key.encode())
        digest.update(np.ascontiguousarray(arrays[key]).tobytes())
    return digest.hexdigest()


def save_table(table, path):
    """Write a table atomically as ``.npz`` (no pickle) with its key, description and checksum."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = dict(table.arrays)
    payload["__key__"] = np.array(table.key)
    payload["__description__"] = np.array(table_description(table.instrument, table.settings))
    payload["__instrument__"] = np.array(table.instrument.name)
    payload["__checksum__"] = np.array(_checksum(table.arrays))
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        np.savez(handle, **payload)


class CacheError(ValueError):
    """A cached table file is truncated, corrupt or built with other settings."""


class CacheLocationError(OSError):
    """The table cache cannot be used where it is (a file where a folder should be, no access)."""


#: Seconds between attempts to take a build lock where only polling is possible (Windows).
LOCK_POLL_INTERVAL = 0.5


def _cache_origin(cache_dir):
    """Where the cache folder came from, and what to do when it cannot be used (plain words)."""
    if cache_dir:
        return "given as cache_dir", "pass a folder as cache_dir"
    if os.environ.get("BAYESPIG_CACHE"):
        default = Path(os.environ.get("XDG_CACHE_HOME") or (Path.home() / ".cache")) / "bayespig"
        return "set by BAYESPIG_CACHE", (
            f"set BAYESPIG_CACHE to a folder you can write, or unset it to use '{default}'"
        )
    return "the default", "set BAYESPIG_CACHE to a folder you can write"


def _cache_folder(cache_dir):
    """The cache folder (created if missing), or :class:`CacheLocationError` in plain words."""
    folder = Path(cache_dir) if cache_dir else cache_directory()
    if folder.exists() and not folder.is_dir():
        origin, remedy = _cache_origin(cache_dir)
        raise CacheLocationError(f"the table cache folder '{folder}' ({origin}) is a file, not a folder: {remedy}")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        origin, remedy = _cache_origin(cache_dir)
        raise CacheLocationError(
            f"the table cache folder '{folder}' ({origin}) cannot be created ({error.strerror}): {remedy}"
        ) from None
    return folder


def _lock_path(path):
    """Lock file of a table's build: ``.table-<key>.npz.lock`` beside the table (kept afterwards)."""
    return path.with_name(f".{path.name}.lock")


def _try_lock(handle):
    """Take an exclusive lock on an open file without waiting; whether it was taken."""
    try:
        if fcntl is not None:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        else:  # pragma: no cover - Windows
            msvcrt.locking(handle.fileno(), msvcrt.LK_NBLCK, 1)
    except BlockingIOError:
        return False
    except OSError:  # pragma: no cover - Windows reports a held lock as EACCES or EDEADLK
        if fcntl is None:
            return False
        raise
    return True


def _wait_for_lock(handle):
    """Take an exclusive lock on an open file, waiting as long as another process holds it."""
    if fcntl is not None:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
        return
    while not _try_lock(handle):  # pragma: no cover - Windows
        time.sleep(LOCK_POLL_INTERVAL)


@contextmanager
def _build_lock(path, instrument_name, progress):
    """Hold the build lock of the table at ``path`` (one builder per table across processes).

    A second process asking for the same table waits here (saying so when ``progress``) until
    the first has written it, then finds it in the cache. Where no file locking is available
    (neither ``fcntl`` nor ``msvcrt``) or the lock file cannot be created (a read-only cache),
    builds proceed unlocked, as before.

    Yields
    ------
    bool
        Whether this process had to wait for another one.
    """
    handle = None
    if fcntl is not None or msvcrt is not None:
        try:
            handle = open(_lock_path(path), "a+b")  # noqa: SIM115 - closed below
        except OSError:
            pass
    if handle is None:
        yield False
        return
    with handle:
        waited = False
        if not _try_lock(handle):
            waited = True
            if progress:
                print(
                    f"bayespig: waiting for another process building table {instrument_name} "
                    f"({path.name})",
                    file=sys.stderr,
                    flush=True,
                )
            _wait_for_lock(handle)
        try:
            yield waited
        finally:
            if fcntl is not None:
                fcntl.flock(handle.fileno(), fcntl.LOCK_UN)
            else:  # pragma: no cover - Windows
                handle.seek(0)
                msvcrt.locking(handle.fileno(), msvcrt.LK_UNLCK, 1)


def read_table(path, instrument, settings):
    """Read a cached table, verifying its key and checksum; raise :class:`CacheError` otherwise."""
    instrument = get_instrument(instrument)
    key = table_key(instrument, settings)
    try:
        # our own handle: np.load leaks the one it opens when the zip directory is damaged
        with open(path, "rb") as handle, np.load(handle, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except Exception as error:  # noqa: BLE001 - zip/npy errors of many kinds mean one thing here
        raise CacheError(f"cached table {path} is unreadable ({type(error).__name__}: {error})") from None
    stored_key = str(arrays.pop("__key__", ""))
    stored_sum = str(arrays.pop("__checksum__", ""))
    arrays.pop("__description__", None)
    arrays.pop("__instrument__", None)
    if stored_key != key:
        raise CacheError(f"cached table {path} was built with other settings (key {stored_key} != {key})")
    if stored_sum != _checksum(arrays):
        raise CacheError(f"cached table {path} is corrupt (checksum mismatch)")
    table = LookupTable(instrument, settings, arrays, key)
    table.checksum = stored_sum  # verified above: not hashed again
    return table


def _table_title(instrument):
    """An instrument's name for messages (its channels when it has no name of its own)."""
    return "+".join(instrument.labels) if instrument.name == "custom" else instrument.name


def _read_cached(path, instrument, settings):
    """The cached table at ``path``, or ``None`` after a warning that it is damaged."""
    try:
        return read_table(path, instrument, settings)
    except CacheError as error:
        warnings.warn(f"{error}; rebuilding it", RuntimeWarning, stacklevel=3)
        return None


def load_table(instrument, *, g="isotropic", n=1.45, settings=None, cache_dir=None, rebuild=False,
               progress=True, executor=None):
    """The cached look-up table of an instrument, built on first use.

    Parameters
    ----------
    instrument : str, Instrument or sequence
        ``"multi-angle-45"``, ``"multi-angle-45-15"``, ``"8d-sci"``, ``"8d-sce"``,
        ``"45-0"``, or a list of geometries (see :func:`~bayespig.instruments.get_instrument`).
    g : {"isotropic", "free"}
        Isotropic scattering only (``g = 0``, the paper's default; cheaper) or a
        ``g`` axis over [-0.5, 0.8].
    n : float
        Refractive index of the binder [-].
    settings : TableSettings, optional
        Overrides the default axes.
    cache_dir : path, optional
        Defaults to :func:`cache_directory` (``$BAYESPIG_CACHE``); created if missing.
    rebuild : bool
        Ignore any cached file.
    progress : bool
        Progress bar while building.
    executor : concurrent.futures.Executor, optional
        For building.

    Returns
    -------
    LookupTable

    Raises
    ------
    CacheLocationError
        The cache folder is a file or cannot be created, or the table's file name is taken
        by a folder; the message names the path and what to do.

    Notes
    -----
    A damaged cached file is reported (``RuntimeWarning``) and rebuilt. One process builds a
    given table at a time: the build holds an exclusive lock on ``.table-<key>.npz.lock``
    beside the table (``fcntl.flock``; ``msvcrt`` on Windows), and a second process asking for
    the same table says "waiting for another process building table ..." (when ``progress``),
    waits, and then loads the table the first one wrote. The lock file stays in the cache.
    """
    choice("g", g, ("isotropic", "free"))
    _check_index(n)
    if settings is not None and not isinstance(settings, TableSettings):
        raise TypeError(f"settings must be a TableSettings or None, got {settings!r} ({type(settings).__name__})")
    if cache_dir is not None and not isinstance(cache_dir, (str, os.PathLike)):
        raise TypeError(f"cache_dir must be a folder path or None, got {cache_dir!r} ({type(cache_dir).__name__})")
    flag("rebuild", rebuild)
    flag("progress", progress)
    if executor is not None and not callable(getattr(executor, "submit", None)):
        raise TypeError(f"executor must be a concurrent.futures.Executor or None, got {executor!r}")
    if isinstance(instrument, Instrument):
        if instrument.n != n:
            instrument = dataclasses.replace(instrument, n=n)
    else:
        instrument = get_instrument(instrument, n=n)
    if settings is None:
        settings = TableSettings(g_range=(-0.5, 0.8)) if g == "free" else TableSettings()
    elif g == "free" and settings.g_range is None:
        raise ValueError("g='free' needs settings with a g_range")
    key = table_key(instrument, settings)
    path = table_path(key, _cache_folder(cache_dir))
    if path.is_dir():
        raise CacheLocationError(
            f"the cached table '{path}' is a folder, not a file: remove or rename that folder "
            "(bayespig writes the table there)"
        )
    if path.exists() and not rebuild:
        table = _read_cached(path, instrument, settings)
        if table is not None:
            return table
        rebuild = True  # the damaged file must not be read again below
    with _build_lock(path, _table_title(instrument), progress) as waited:
        # built by the process waited for, or by another between the first look and the lock
        if (waited or not rebuild) and path.is_file():
            table = _read_cached(path, instrument, settings)
            if table is not None:
                return table
        if not os.access(path.parent, os.W_OK | os.X_OK):
            origin, remedy = _cache_origin(cache_dir)
            raise CacheLocationError(
                f"table {_table_title(instrument)} is not cached and cannot be built: the table cache folder "
                f"'{path.parent}' ({origin}) is not writable: {remedy}"
            )
        table = build_table(instrument, settings, executor=executor, progress=progress)
        save_table(table, path)
    return table
