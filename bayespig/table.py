"""Look-up tables: an instrument's channels tabulated over (a, tau, g), cached on disk.

Fitting and sampling call the forward model millions of times, so, as the paper
does (section 2), it is tabulated once per instrument and interpolated. What is
tabulated are the terms of the substrate law (eq. 3) for every channel, so any
substrate albedo ``r_s`` — a scalar or one per wavelength — is exact::

    x(a, tau, g; r_s) = (1 - a) (1 - exp(-tau)) q(a, tau, g) + r_s D U / (1 - r_s R_up)

``q`` (the black-substrate value divided by its leading behaviour in ``omega`` and
``tau``), the substrate transmission terms ``D`` and ``U`` and ``R_up`` are smooth;
``log q``, ``log D`` and ``log U`` are interpolated by tensor-product cubic
Lagrange stencils over ``sqrt(a)``, ``log(tau)`` and ``g``. Below ``tau_min`` the
values are linear in ``tau`` towards the exact ``tau -> 0`` slice; ``tau = inf``
(opaque, eq. 2) is a slice of its own.

The ``tau`` axis is geometric so that one doubling sequence per base thickness
yields every node (adding–doubling produces ``R(2^k d)`` for free).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import sys
import tempfile
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import __version__
from .instruments import Instrument, channel_directions, get_instrument
from .physics.adding_doubling import START_THICKNESS, START_THICKNESS_HIGHER_MODES, double, layer_mode, start_layer
from .physics.forward import surface_geometry, surface_mode, validate_layer_arguments
from .physics.fresnel import fresnel_reflectance
from .physics.phase import normalise_on_quadrature, phase_fourier_modes
from .physics.quadrature import DEFAULT_QUADRATURE_POINTS

__all__ = ["TableSettings", "LookupTable", "build_table", "load_table", "cache_directory"]

#: Bump when the file layout or the tabulated quantities change.
FORMAT_VERSION = 1
#: Smallest value kept before taking logarithms (far below any visible contribution).
LOG_FLOOR = 1e-300
#: Largest a evaluated on the a = 1 node (q is a limit there) [-].
A_MAX_EVAL = 1.0 - 1e-9
#: Thickness standing in for tau -> 0 (q is a limit there) [-].
TAU_ZERO_EVAL = 1e-10
#: Fourier modes whose channel contributions stay below this (relative), twice, end the sum.
MODE_TOLERANCE = 1e-7


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
    n_g: int = 14
    n_points: int = DEFAULT_QUADRATURE_POINTS
    start_thickness: float = START_THICKNESS

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

    @property
    def g_nodes(self):
        """Nodes of the ``g`` axis (a single 0 for isotropic tables)."""
        if self.g_range is None:
            return np.zeros(1)
        return np.linspace(self.g_range[0], self.g_range[1], self.n_g)


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
    """
    theta_in, theta_out, index_in, index_out = channel_directions(instrument)
    geometry = surface_geometry(theta_in, theta_out, instrument.n, settings.n_points)
    mu, weight, c = geometry.mu, geometry.weight, geometry.c
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
    quiet = 0
    for m in range(max_modes):
        start = settings.start_thickness if m == 0 else max(settings.start_thickness, START_THICKNESS_HIGHER_MODES)
        R_all = np.empty((n_a, n_tau + 2, mu.size, mu.size))
        T_all = np.empty_like(R_all)
        e_all = np.empty((n_a, n_tau + 2, mu.size))
        R_all[:, 0], T_all[:, 0], e_all[:, 0] = start_layer(mu, c, albedo, np.full(n_a, TAU_ZERO_EVAL),
                                                            p_refl[m], p_trans[m])
        for p in range(P):
            base = taus[p]
            k0 = int(max(0, np.ceil(np.log2(base / start))))
            R, T, e = start_layer(mu, c, albedo, np.full(n_a, base / 2.0**k0), p_refl[m], p_trans[m])
            for _ in range(k0):
                R, T, e = double(R, T, e, c)
            for j in range(p, n_tau, P):
                if j > p:
                    R, T, e = double(R, T, e, c)
                R_all[:, 1 + j], T_all[:, 1 + j], e_all[:, 1 + j] = R, T, e
        R_all[:, -1], T_all[:, -1], e_all[:, -1] = layer_mode(mu, weight, a, np.full(n_a, np.inf),
                                                              p_refl[m], p_trans[m], start)
        flat = (n_a * (n_tau + 2), mu.size)
        mode = surface_mode(geometry, R_all.reshape(flat + (mu.size,)), T_all.reshape(flat + (mu.size,)),
                            e_all.reshape(flat), m == 0)
        f_mode = mode.pop("f_mode").reshape(n_a, n_tau + 2, theta_out.size, theta_in.size)
        weight_m = (2.0 - (m == 0)) * (-1.0) ** m
        contribution = np.empty((n_a, n_tau + 2, K))
        for k, ch in enumerate(instrument.channels):
            f = f_mode[:, :, index_out[k], index_in[k]]
            if ch.kind == "hemispherical":
                contribution[..., k] = mode["h0"].reshape(n_a, n_tau + 2, -1)[..., index_in[k]] if m == 0 else 0.0
            else:
                factor = np.pi if ch.kind == "reflectance_factor" else 1.0
                contribution[..., k] = factor * weight_m * np.cos(m * np.radians(ch.delta_phi)) * f
        black += contribution
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
            # every tabulated value, dark ones included, must have converged
            small = (np.abs(contribution) <= MODE_TOLERANCE * np.abs(black)).all()
            quiet = quiet + 1 if small else 0
            if quiet == 2:
                break
    leading = albedo[:, None] * -np.expm1(-np.concatenate([[TAU_ZERO_EVAL], taus, [np.inf]]))[None, :]
    log_q = np.log(np.maximum(black / leading[..., None], LOG_FLOOR))
    return {
        "log_q": log_q,
        "log_d": np.log(np.maximum(t_down, LOG_FLOOR)),
        "log_u": np.log(np.maximum(t_up, LOG_FLOOR)),
        "r_up": r_up,
    }


def _check_index(n):
    if not np.isscalar(n) or not np.isfinite(n) or n < 1.0:
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
    settings = settings or TableSettings()
    g_nodes = settings.g_nodes
    own_executor = executor is None and g_nodes.size > 1
    if own_executor:
        executor = ProcessPoolExecutor(max_workers=min(2, os.cpu_count() or 1))
    try:
        if executor is None:
            slices = [_build_g_slice(instrument, settings, float(g)) for g in g_nodes]
        else:
            futures = [executor.submit(_build_g_slice, instrument, settings, float(g)) for g in g_nodes]
            slices = []
            iterator = futures
            if progress and g_nodes.size > 1:
                from tqdm.auto import tqdm

                iterator = tqdm(futures, desc=f"building table {instrument.name}", unit="g", file=sys.stderr)
            for future in iterator:
                slices.append(future.result())
    finally:
        if own_executor:
            executor.shutdown()
    arrays = {key: np.stack([s[key] for s in slices]) for key in slices[0]}
    return LookupTable(instrument, settings, arrays, table_key(instrument, settings))


# ---------------------------------------------------------------------------------------------
# interpolation


def _lagrange_stencil(x, x0, dx, n):
    """Start index and 4-point Lagrange weights (and their x-derivatives) on a uniform axis."""
    if n == 1:
        shape = np.shape(x)
        return np.zeros(shape, int), np.ones(shape + (1,)), np.zeros(shape + (1,))
    pos = (x - x0) / dx
    start = np.clip(np.floor(pos).astype(int) - 1, 0, max(n - 4, 0))
    t = pos - start
    if n < 4:
        raise ValueError("an interpolated axis needs at least 4 nodes")
    t0, t1, t2, t3 = t, t - 1.0, t - 2.0, t - 3.0
    w = np.stack([-t1 * t2 * t3 / 6.0, t0 * t2 * t3 / 2.0, -t0 * t1 * t3 / 2.0, t0 * t1 * t2 / 6.0], axis=-1)
    dw = np.stack([
        -(t2 * t3 + t1 * t3 + t1 * t2) / 6.0,
        (t2 * t3 + t0 * t3 + t0 * t2) / 2.0,
        -(t1 * t3 + t0 * t3 + t0 * t1) / 2.0,
        (t1 * t2 + t0 * t2 + t0 * t1) / 6.0,
    ], axis=-1) / dx
    return start, w, dw


class LookupTable:
    """A tabulated instrument: ``table(a=..., tau=..., g=..., r_s=...)`` -> ``(..., n_channels)``.

    Build with :func:`build_table` or, cached, :func:`load_table`.

    Attributes
    ----------
    instrument : Instrument
    channels : tuple of Channel
    settings : TableSettings
    key : str
        Hash of everything that changes the numbers (cache key, recorded in results).
    """

    def __init__(self, instrument, settings, arrays, key):
        self.instrument = instrument
        self.settings = settings
        self.key = key
        self.arrays = arrays
        self.channels = instrument.channels
        self._u = settings.v_nodes
        self._log_tau = np.log(settings.tau_nodes)
        self._g = settings.g_nodes
        self._sci = np.array([
            fresnel_reflectance(np.cos(np.radians(ch.theta_i)), 1.0, instrument.n)
            if ch.kind == "hemispherical" and ch.specular == "included" else 0.0
            for ch in instrument.channels
        ])

    @property
    def free_g(self):
        """Whether the table has a ``g`` axis."""
        return self.settings.g_range is not None

    def __repr__(self):
        g = f"g in {self.settings.g_range}" if self.free_g else "isotropic"
        return f"LookupTable({self.instrument.name!r}, {len(self.channels)} channels, {g}, key={self.key})"

    def _check(self, a, tau, g, r_s):
        validate_layer_arguments(a=a, tau=tau, g=g, r_s=r_s, n=self.instrument.n)
        if not self.free_g and (np.asarray(g) != 0.0).any():
            raise ValueError("this table is isotropic (g = 0); load it with g='free' to vary g")
        if self.free_g:
            lo, hi = self.settings.g_range
            if ((np.asarray(g) < lo) | (np.asarray(g) > hi)).any():
                raise ValueError(f"g must lie in the table's range [{lo}, {hi}]")
        if (np.isfinite(tau) & (np.asarray(tau) > self.settings.tau_nodes[-1])).any():
            raise ValueError(f"finite tau must be <= {self.settings.tau_nodes[-1]:g} (use inf for opaque films)")

    def _interpolate(self, key, u, x, g, tau_index=None, gradient=False):
        """Interpolate ``arrays[key]`` (n_g, n_a, n_tau+2, ...) at u, x=log(tau) (or a fixed tau index), g."""
        table = self.arrays[key]
        su, wu, dwu = _lagrange_stencil(u, 0.0, self._u[1] - self._u[0], self._u.size)
        if self._g.size > 1:
            sg, wg, dwg = _lagrange_stencil(g, self._g[0], self._g[1] - self._g[0], self._g.size)
        else:
            sg, wg, dwg = _lagrange_stencil(g, 0.0, 1.0, 1)
        ng = wg.shape[-1]
        ig = sg[..., None] + np.arange(ng)
        iu = su[..., None] + np.arange(4)
        extra = table.shape[3:]
        if tau_index is not None:
            sub = table[ig[..., :, None], iu[..., None, :], tau_index]  # (..., ng, 4, *extra)
            value = np.einsum("...g,...u,...gu->...", wg, wu, sub) if not extra else np.einsum(
                "...g,...u,...guk->...k", wg, wu, sub)
            if not gradient:
                return value
            grads = [np.einsum("...g,...u,...guk->...k", wg, dwu, sub),
                     np.einsum("...g,...u,...guk->...k", dwg, wu, sub)] if extra else [
                np.einsum("...g,...u,...gu->...", wg, dwu, sub), np.einsum("...g,...u,...gu->...", dwg, wu, sub)]
            return value, grads[0], np.zeros_like(value), grads[1]
        sx, wx, dwx = _lagrange_stencil(x, self._log_tau[0], self._log_tau[1] - self._log_tau[0], self._log_tau.size)
        ix = 1 + sx[..., None] + np.arange(4)
        sub = table[ig[..., :, None, None], iu[..., None, :, None], ix[..., None, None, :]]
        spec = "...g,...u,...x,...gux" + ("k->...k" if extra else "->...")
        value = np.einsum(spec, wg, wu, wx, sub)
        if not gradient:
            return value
        return (value, np.einsum(spec, wg, dwu, wx, sub), np.einsum(spec, wg, wu, dwx, sub),
                np.einsum(spec, dwg, wu, wx, sub))

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

        Returns
        -------
        numpy.ndarray or tuple
            Values ``(..., K)``; with ``gradient=True`` also ``d/da``, ``d/dtau``,
            ``d/dg`` of the same shape (``d/dtau`` is 0 for opaque films;
            ``d/da`` is infinite at ``a = 0`` exactly, where the dependence is ``sqrt(a)``).
        """
        self._check(a, tau, g, r_s)
        a, tau, g, r_s = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (a, tau, g, r_s)))
        u, dv_da = self.settings.v_of_a(a)
        opaque = np.isinf(tau)
        tau_min = self.settings.tau_nodes[0]
        finite_tau = np.where(opaque, 1.0, tau)
        x = np.log(np.clip(finite_tau, tau_min, None))
        omega = np.maximum(1.0 - a, 0.0)
        lead_tau = -np.expm1(-finite_tau)

        def interp(key, **kw):
            return self._interpolate(key, u, x, g, gradient=gradient, **kw)

        # opaque slice
        q_inf = interp("log_q", tau_index=-1)
        # finite tau, with the linear blend to the tau -> 0 slice below tau_min
        parts = {key: interp(key) for key in ("log_q", "log_d", "log_u", "r_up")}
        small = finite_tau < tau_min
        if small.any():
            zero = {key: interp(key, tau_index=0) for key in parts}
            s = (finite_tau / tau_min)
            for key in parts:
                parts[key] = _blend(parts[key], zero[key], s, small, tau_min, gradient)
        if not gradient:
            q = np.exp(parts["log_q"])
            gain = r_s / (1.0 - r_s * parts["r_up"])
            finite = omega[..., None] * lead_tau[..., None] * q + gain[..., None] * np.exp(parts["log_d"] + parts["log_u"])
            opaque_value = omega[..., None] * np.exp(q_inf)
            return np.where(opaque[..., None], opaque_value, finite) + self._sci
        return self._values_and_gradient(parts, q_inf, omega, lead_tau, finite_tau, dv_da, r_s, opaque, small)

    def _values_and_gradient(self, parts, q_inf, omega, lead_tau, tau, dv_da, r_s, opaque, small):
        """Chain rule from the interpolated log-quantities to channel values and d/d(a, tau, g)."""
        (lq, lq_u, lq_x, lq_g) = parts["log_q"]
        (ld, ld_u, ld_x, ld_g) = parts["log_d"]
        (lu, lu_u, lu_x, lu_g) = parts["log_u"]
        (ru, ru_u, ru_x, ru_g) = parts["r_up"]
        q = np.exp(lq)
        black = omega[..., None] * lead_tau[..., None] * q
        denominator = 1.0 - r_s * ru
        gain = r_s / denominator
        sub = np.exp(ld + lu)
        substrate = gain[..., None] * sub
        value = black + substrate
        # d/du of each piece; x = log(tau) above tau_min (the blend below handles its own x-derivative)
        dgain_u = r_s * r_s * ru_u / denominator**2
        dgain_x = r_s * r_s * ru_x / denominator**2
        dgain_g = r_s * r_s * ru_g / denominator**2
        d_u = black * lq_u + substrate * (ld_u + lu_u) + dgain_u[..., None] * sub
        d_x = black * lq_x + substrate * (ld_x + lu_x) + dgain_x[..., None] * sub
        d_g = black * lq_g + substrate * (ld_g + lu_g) + dgain_g[..., None] * sub
        dxdtau = np.where(small, 1.0, 1.0 / tau)
        d_tau = d_x * dxdtau[..., None] + omega[..., None] * np.exp(-tau)[..., None] * q
        d_a = d_u * dv_da[..., None] - lead_tau[..., None] * q
        (oq, oq_u, _, oq_g) = q_inf
        opaque_value = omega[..., None] * np.exp(oq)
        d_a_opaque = opaque_value * oq_u * dv_da[..., None] - np.exp(oq)
        op = opaque[..., None]
        return (np.where(op, opaque_value, value) + self._sci, np.where(op, d_a_opaque, d_a),
                np.where(op, 0.0, d_tau), np.where(op, opaque_value * oq_g, d_g))


def _blend(at_min, at_zero, s, small, tau_min, gradient):
    """Linear in tau between the tau -> 0 slice and the first node, where tau < tau_min."""
    if not gradient:
        extra = at_min.ndim - s.ndim
        s_b = s.reshape(s.shape + (1,) * extra)
        m = small.reshape(small.shape + (1,) * extra)
        return np.where(m, (1.0 - s_b) * at_zero + s_b * at_min, at_min)
    v_min, du_min, dx_min, dg_min = at_min
    v_zero, du_zero, _, dg_zero = at_zero
    extra = v_min.ndim - s.ndim
    s_b = s.reshape(s.shape + (1,) * extra)
    m = small.reshape(small.shape + (1,) * extra)
    value = np.where(m, (1.0 - s_b) * v_zero + s_b * v_min, v_min)
    d_u = np.where(m, (1.0 - s_b) * du_zero + s_b * du_min, du_min)
    d_g = np.where(m, (1.0 - s_b) * dg_zero + s_b * dg_min, dg_min)
    # below tau_min the "x" derivative is reported per unit tau (see dxdtau in the caller)
    d_x = np.where(m, (v_min - v_zero) / tau_min, dx_min)
    return value, d_u, d_x, d_g


# ---------------------------------------------------------------------------------------------
# cache


def _checksum(arrays):
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
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            np.savez(handle, **payload)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


class CacheError(ValueError):
    """A cached table file is truncated, corrupt or built with other settings."""


def read_table(path, instrument, settings):
    """Read a cached table, verifying its key and checksum; raise :class:`CacheError` otherwise."""
    instrument = get_instrument(instrument)
    key = table_key(instrument, settings)
    try:
        # our own handle: np.load leaks the one it opens when the zip directory is damaged
        with open(path, "rb") as handle, np.load(handle, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except Exception as error:  # zip/npy errors of many kinds mean one thing here
        raise CacheError(f"cached table {path} is unreadable ({type(error).__name__}: {error})") from None
    stored_key = str(arrays.pop("__key__", ""))
    stored_sum = str(arrays.pop("__checksum__", ""))
    arrays.pop("__description__", None)
    arrays.pop("__instrument__", None)
    if stored_key != key:
        raise CacheError(f"cached table {path} was built with other settings (key {stored_key} != {key})")
    if stored_sum != _checksum(arrays):
        raise CacheError(f"cached table {path} is corrupt (checksum mismatch)")
    return LookupTable(instrument, settings, arrays, key)


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
        Defaults to :func:`cache_directory` (``$BAYESPIG_CACHE``).
    rebuild : bool
        Ignore any cached file.
    progress : bool
        Progress bar while building.
    executor : concurrent.futures.Executor, optional
        For building.

    Returns
    -------
    LookupTable
    """
    if g not in ("isotropic", "free"):
        raise ValueError(f"g must be 'isotropic' or 'free', got {g!r}")
    _check_index(n)
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
    path = table_path(key, cache_dir)
    if path.exists() and not rebuild:
        try:
            return read_table(path, instrument, settings)
        except CacheError as error:
            warnings.warn(f"{error}; rebuilding it", RuntimeWarning, stacklevel=2)
    table = build_table(instrument, settings, executor=executor, progress=progress)
    save_table(table, path)
    return table
