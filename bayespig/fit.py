"""Point estimates per wavelength: the paper's extraction methods 1–4 (section 3).

Every method is a least-squares fit, per wavelength, of the model's values to the
measured ones. The objective is the sum of squared **relative** deviations over the
values a method uses,

    S(a, tau) = sum_k (x_obs_k / x_model_k(a, tau) - 1)^2 .

Why this objective: under the paper's noise model (eq. 7), ``x_obs = x_true (1 + eps xi)``,
so at the true parameters each term is exactly ``(eps xi_k)^2`` — independent terms of equal
variance, whatever the size of the value. BRDF values that differ by orders of magnitude
between geometries, or between a film on black and on white, then weigh equally (absolute
least squares would let the bright sample decide alone), and ``S / (2 eps^2)`` is minus the
log-likelihood of eq. 7 apart from its ``sum_k log x_model`` term, whose gradient is a factor
``eps^2`` smaller. Log ratios ``log(x_obs / x_model)`` would do as well to first order in
``eps``; relative deviations keep ``S`` a sum of squares of smooth functions for
Gauss–Newton.

The procedures (section 3):

* **method 1** — ``a`` from the opaque film's BRDF alone (eq. 2); ``tau`` of the film on glass
  from its specular transmittance by eq. (6) (the exact minimiser of ``S`` for one value).
* **method 2** — ``a`` from the opaque film, then each thin film's ``tau`` with ``a`` fixed.
* **method 3** — ``a`` and ``tau`` together from one thin film on black.
* **method 4** — ``a`` and ``tau`` together from the same film on black and on white.
* **general** — ``a`` and every film group's ``tau`` together from all films.

Methods 1 and 2 are fitted in two steps as the paper does; the others jointly.

Robust to starting points: every fit starts from a scan of ``S`` over a grid in
``(sqrt(a), log tau)`` — for all rows at once, since the model on the grid is shared and
``S`` over the grid is two matrix products — and is refined by a bounded, vectorised
Levenberg–Marquardt iteration on the table's analytic derivatives. The grid covers the whole
box, so a ravine or a second minimum cannot trap the start. A fit that ends at a bound of
the box is flagged per wavelength and parameter (:attr:`FitResult.at_lower`,
:attr:`FitResult.at_upper`), and so is one whose objective cannot tell its estimate from the
bound (a film indistinguishable from an opaque one, ``tau`` "at infinity"): it is moved onto
the bound, so the reported value says what the data say.

``g`` is fixed (0, isotropic, by default, as the paper recommends) or found by the paper's
outer search (section 3.2): the fit is repeated for ``g`` on the table's ``g`` nodes and the
``g`` minimising ``S`` is refined by golden-section search, per wavelength.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ._validation import choice, flag, integer, real_array, real_scalar
from .instruments import get_instrument
from .likelihood import FilmTerm, Problem
from .physics.forward import specular_transmittance
from .physics.fresnel import normal_transmittance

__all__ = [
    "OBJECTIVES",
    "TWO_STEP_METHODS",
    "FitBoundWarning",
    "FitResult",
    "FitSettings",
    "film_term",
    "fit_batch",
    "fit_measurements",
    "fit_problem",
]

#: Methods fitted in two steps (``a`` from opaque films first), section 3.1 and 3.2.1.
TWO_STEP_METHODS = ("method1", "method2")
_JOINT_METHODS = ("method3", "method4", "general")
#: ``sqrt(a)`` below which derivatives are taken at this value (d/da ~ 1/sqrt(a) at a = 0).
_S_FLOOR = 1e-7
#: Relative increase of S allowed when a parameter is put on its bound for the fit to count as
#: indistinguishable from the bound. Statistically negligible (a change of chi^2 = S / eps^2 of
#: about 1e-4 N for N values) yet above the wiggle that the table's interpolation error
#: (~1e-6 relative near the opaque limit) puts into S, which is ~2e-6 / eps relative.
PLATEAU_RTOL = 1e-4
#: Model values are floored here so that S stays finite where the model vanishes (a = 1, opaque).
MODEL_FLOOR = 1e-30
#: Grid nodes that two local minima must be apart (Chebyshev) to count as separate basins.
BASIN_SEPARATION = 3
#: A local minimum of the grid is a start only if its S is within this factor of the best node's.
BASIN_RTOL = 0.5
#: Lowest local minima of the grid examined per row when choosing the starts.
_BASIN_CANDIDATES = 12
#: Residuals the fit can minimise (see :class:`FitSettings`).
OBJECTIVES = ("relative", "log", "absolute")
#: Absolute distance in a fitted coordinate (sqrt(a) or a, log tau, g) that counts as "on a bound".
BOUND_ATOL = 1e-6


@dataclass(frozen=True)
class FitSettings:
    """Bounds and numerical settings of the point fits.

    Attributes
    ----------
    tau_bounds : tuple of float
        Box of the fitted optical thickness [-]; the upper bound is lowered to the largest
        finite ``tau`` of the look-up table (128 by default).
    a_bounds : tuple of float
        Box of the relative absorption [-].
    n_grid_a, n_grid_tau : int
        Nodes of the starting grid, uniform in ``sqrt(a)`` and in ``log tau``.
    max_iterations : int
        Levenberg–Marquardt iterations before a fit is reported as not converged.
    step_tolerance : float
        Converged when an accepted step moves every coordinate (``sqrt(a)``, ``log tau``)
        less than this,
    cost_tolerance : float
        or lowers S by less than this fraction of S (statistically meaningless: a change of
        ``chi^2 = S / eps^2`` of about ``cost_tolerance * N``; it stops the crawl along a flat
        ravine floor or the opaque plateau, where S varies only by interpolation error).
    max_starts : int
        Starting points per fit: the best grid point and the best points of up to
        ``max_starts - 1`` other basins of S on the grid.
    g_iterations : int
        Golden-section iterations of the outer ``g`` search.
    objective : {"relative", "log", "absolute"}
        Residual per value: ``x_obs / x_model - 1`` (default; see the module docstring),
        ``log(x_obs / x_model)``, or ``x_obs - x_model`` (unweighted, for comparison only:
        it lets the largest values decide).
    start : tuple of float, optional
        ``(a, tau)`` to start every fit from instead of the grid scan: a plain local search,
        for studies of how much the result depends on the start (default: grid scan).
    """

    tau_bounds: tuple = (1e-3, 128.0)
    a_bounds: tuple = (0.0, 1.0)
    n_grid_a: int = 32
    n_grid_tau: int = 48
    max_iterations: int = 100
    step_tolerance: float = 1e-7
    cost_tolerance: float = 1e-7
    max_starts: int = 3
    g_iterations: int = 24
    objective: str = "relative"
    start: tuple | None = None

    def __post_init__(self):
        lo, hi = _pair("tau_bounds", self.tau_bounds)
        if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 < lo < hi):
            raise ValueError(
                f"tau_bounds must be finite with 0 < low < high, got {self.tau_bounds}"
            )
        lo, hi = _pair("a_bounds", self.a_bounds)
        if not 0.0 <= lo < hi <= 1.0:
            raise ValueError(f"a_bounds must satisfy 0 <= low < high <= 1, got {self.a_bounds}")
        integer("n_grid_a", self.n_grid_a, low=4)
        integer("n_grid_tau", self.n_grid_tau, low=4)
        integer("max_iterations", self.max_iterations, low=1)
        integer("max_starts", self.max_starts, low=1)
        integer("g_iterations", self.g_iterations, low=0)
        real_scalar("step_tolerance", self.step_tolerance, low=0.0, low_open=True)
        real_scalar("cost_tolerance", self.cost_tolerance, low=0.0, low_open=True)
        if self.start is not None:
            a, tau = _pair("start", self.start, allow_inf=True)
            if not (0.0 <= a <= 1.0 and 0.0 < tau < np.inf):
                raise ValueError(
                    f"start must be (a, tau) with a in [0, 1] and finite tau > 0, got {self.start}"
                )
        if not isinstance(self.objective, str) or self.objective not in OBJECTIVES:
            raise ValueError(
                f"objective must be one of {', '.join(OBJECTIVES)}, got {self.objective!r}"
            )


def _pair(name, value, allow_inf=False):
    """``(low, high)`` of a setting as two floats, or a TypeError/ValueError naming it."""
    pair = real_array(name, value, allow_inf=allow_inf)
    if pair.shape != (2,):
        raise ValueError(f"{name} must be a pair of numbers, got {value!r}")
    return float(pair[0]), float(pair[1])


class FitBoundWarning(UserWarning):
    """A point fit stopped at a bound of its box (the estimate is a limit, not a value)."""


@dataclass(frozen=True)
class FitResult:
    """Point estimates per wavelength (or per replicate row of a batch).

    Attributes
    ----------
    wavelength_nm : numpy.ndarray
        Shape (n,) [nm] (replicate index for batches of simulated replicates).
    method : str
        ``"method1"`` .. ``"method4"`` or ``"general"``.
    groups : tuple of str
        Film groups, one ``tau`` each (columns of :attr:`tau`).
    a : numpy.ndarray
        Relative absorption, shape (n,) [-].
    tau : numpy.ndarray
        Optical thickness per group, shape (n, n_groups) [-].
    g : numpy.ndarray
        Henyey–Greenstein parameter used or found, shape (n,) [-].
    objective : numpy.ndarray
        ``S``, the sum of squared relative deviations at the estimate, shape (n,).
    n_values : int
        Measured values per row that enter ``S``.
    parameter_names : tuple of str
        ``"a"``, ``"tau[<group>]"`` ..., and ``"g"`` when searched.
    at_lower, at_upper : numpy.ndarray
        Shape (n, n_parameters), bool: the estimate sits on (or cannot be told from) the
        lower / upper bound of that parameter.
    converged : numpy.ndarray
        Shape (n,), bool.
    settings : FitSettings
    """

    wavelength_nm: np.ndarray
    method: str
    groups: tuple
    a: np.ndarray
    tau: np.ndarray
    g: np.ndarray
    objective: np.ndarray
    n_values: int
    parameter_names: tuple
    at_lower: np.ndarray
    at_upper: np.ndarray
    converged: np.ndarray
    settings: FitSettings

    @property
    def at_bound(self):
        """Shape (n,), bool: any parameter at a bound."""
        return self.at_lower.any(axis=1) | self.at_upper.any(axis=1)

    @property
    def rms_relative_deviation(self):
        """``sqrt(S / n_values)``: about ``eps`` for a model that fits the data, shape (n,)."""
        return np.sqrt(self.objective / self.n_values)

    def bound_report(self):
        """One line per row with a parameter at a bound (empty list when none)."""
        lines = []
        for i in np.flatnonzero(self.at_bound):
            hits = [
                f"{name} at {'lower' if self.at_lower[i, j] else 'upper'} bound"
                for j, name in enumerate(self.parameter_names)
                if self.at_lower[i, j] or self.at_upper[i, j]
            ]
            lines.append(f"{self.wavelength_nm[i]:g} nm: " + ", ".join(hits))
        return lines

    def describe(self):
        """A short text summary: method, objective, and every fit at a bound or not converged."""
        lines = [
            (
                f"{self.method}: {self.a.size} fits, median rms relative deviation "
                f"{np.median(self.rms_relative_deviation):.3g} over {self.n_values} values"
            )
        ]
        bound = self.bound_report()
        if bound:
            lines.append(f"{len(bound)} fit(s) at a bound:")
            lines.extend("  " + line for line in bound)
        if not self.converged.all():
            lines.append(
                "not converged at: "
                + ", ".join(f"{w:g} nm" for w in self.wavelength_nm[~self.converged])
            )
        return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# blocks: one film's values, as the fit sees them


@dataclass(frozen=True)
class _Block:
    """One film: its table (None for a transmittance), group index (-1 opaque), r_s and data."""

    table: object
    group: int
    r_s: np.ndarray
    observed: np.ndarray
    n: float

    @property
    def n_values(self):
        return self.observed.shape[1]


class _Box:
    """Bounds of theta = [c, log tau_1, ..., log tau_G], the tau range the tables allow, and the
    coordinate ``c`` of the absorption: ``sqrt(a)`` (opaque films depend on ``sqrt(a)`` near
    0, eq. 2 and diffusion theory) or ``a`` itself (thin films depend smoothly on ``a``; in
    ``sqrt(a)`` their S would be flat at ``a = 0``, and fits ending there crawl)."""

    def __init__(self, settings, n_groups, tau_max_table, sqrt_a=True):
        self.settings, self.n_groups, self.tau_max_table = settings, n_groups, tau_max_table
        self.sqrt_a = sqrt_a
        self.tau_low = settings.tau_bounds[0]
        self.tau_high = min(settings.tau_bounds[1], tau_max_table)
        if not self.tau_low < self.tau_high:
            raise ValueError(
                f"tau_bounds {settings.tau_bounds} leave nothing below the table's "
                f"largest tau {tau_max_table:g}"
            )
        self.a_low, self.a_high = settings.a_bounds
        self.lower = np.array([self.coordinate(self.a_low)] + [np.log(self.tau_low)] * n_groups)
        self.upper = np.array([self.coordinate(self.a_high)] + [np.log(self.tau_high)] * n_groups)

    def with_sqrt_a(self, sqrt_a):
        return (
            self
            if sqrt_a == self.sqrt_a
            else _Box(self.settings, self.n_groups, self.tau_max_table, sqrt_a)
        )

    def coordinate(self, a):
        return np.sqrt(a) if self.sqrt_a else np.asarray(a, dtype=float)

    def a_of(self, c):
        """``a`` where the model is evaluated, and ``da/dc`` (finite at ``a = 0``)."""
        if self.sqrt_a:
            c = np.maximum(c, _S_FLOOR)
            return np.minimum(c * c, 1.0), 2.0 * c
        return np.clip(c, _S_FLOOR**2, 1.0), np.ones_like(c)

    def tau(self, x):
        return np.clip(np.exp(x), self.tau_low, self.tau_high)


def _model(blocks, box, theta, g, rows, gradient):
    """Model values of every block at ``rows`` (one table call per table).

    Returns a list of values (R, K) per block and, with ``gradient``, of ``(d/dc, d/dx)``
    pairs (each (R, K); ``d/dx`` is with respect to the block's own group's ``log tau``).
    """
    x = theta[:, 1:]
    a, da_dc = box.a_of(theta[:, 0])
    values, grads = [None] * len(blocks), [None] * len(blocks)
    for k, block in enumerate(blocks):
        if block.table is None:
            tau = box.tau(x[:, block.group])
            values[k] = np.maximum(specular_transmittance(tau, block.n)[:, None], MODEL_FLOOR)
            grads[k] = (np.zeros_like(values[k]), -values[k] * tau[:, None])
    by_table = {}
    for k, block in enumerate(blocks):
        if block.table is not None:
            by_table.setdefault(id(block.table), []).append(k)
    n = a.size
    for members in by_table.values():
        table = blocks[members[0]].table
        taus = [
            np.full(n, np.inf) if blocks[k].group < 0 else box.tau(x[:, blocks[k].group])
            for k in members
        ]
        args = {
            "a": np.tile(a, len(members)),
            "tau": np.concatenate(taus),
            "g": np.tile(g, len(members)),
            "r_s": np.concatenate([blocks[k].r_s[rows] for k in members]),
        }
        if gradient:
            value, d_a, d_tau, _ = table.evaluate(gradient=True, **args)
        else:
            value = table(**args)
        value = np.maximum(value, MODEL_FLOOR)
        for j, k in enumerate(members):
            part = slice(j * n, (j + 1) * n)
            values[k] = value[part]
            if gradient:
                d_x = (
                    np.zeros_like(values[k])
                    if blocks[k].group < 0
                    else d_tau[part] * taus[j][:, None]
                )
                grads[k] = (d_a[part] * da_dc[:, None], d_x)
    return (values, grads) if gradient else values


def _deviation(observed, model, objective):
    """Residuals of the objective and their derivative with respect to the model value."""
    if objective == "relative":
        ratio = observed / model
        return ratio - 1.0, -ratio / model
    if objective == "log":
        return np.log(observed / model), -1.0 / model
    return observed - model, -np.ones_like(model)


def _residuals(blocks, box, theta, g, rows, free, objective, gradient=False):
    """Residuals r (R, N) and, with gradient, dr/dtheta (R, N, P) (zero for fixed parameters)."""
    n_param = theta.shape[1]
    if not gradient:
        values = _model(blocks, box, theta, g, rows, False)
        return np.concatenate(
            [_deviation(b.observed[rows], v, objective)[0] for b, v in zip(blocks, values)], axis=1
        )
    values, grads = _model(blocks, box, theta, g, rows, True)
    parts, jac = [], []
    for block, value, (d_s, d_x) in zip(blocks, values, grads):
        r, dr_dm = _deviation(block.observed[rows], value, objective)
        parts.append(r)
        j = np.zeros(value.shape + (n_param,))
        if free[0]:
            j[..., 0] = dr_dm * d_s
        if block.group >= 0 and free[1 + block.group]:
            j[..., 1 + block.group] = dr_dm * d_x
        jac.append(j)
    return np.concatenate(parts, axis=1), np.concatenate(jac, axis=1)


def _cost(blocks, box, theta, g, rows, free, objective):
    r = _residuals(blocks, box, theta, g, rows, free, objective)
    return np.einsum("rn,rn->r", r, r)


# ---------------------------------------------------------------------------------------------
# starting grid

_GRID_CACHE = {}
_GRID_CACHE_SIZE = 64
#: Rows per matrix product in the grid scan.
_GRID_ROWS = 32


def _grid_model(block, s_nodes, x_nodes, r_s, g, box):
    """Model values on the grid: (n_s, K) opaque, (n_s, n_x, K) film, (n_x, 1) transmittance."""
    if block.table is None:
        return np.maximum(specular_transmittance(box.tau(x_nodes), block.n)[:, None], MODEL_FLOOR)
    key = (
        block.table.key,
        block.group < 0,
        float(r_s),
        float(g),
        s_nodes.tobytes(),
        x_nodes.tobytes(),
    )
    cached = _GRID_CACHE.get(key)
    if cached is not None:
        return cached
    a = np.minimum(s_nodes * s_nodes, 1.0)
    if block.group < 0:
        model = block.table(a=a, tau=np.inf, g=g, r_s=r_s)
    else:
        model = block.table(a=a[:, None], tau=box.tau(x_nodes)[None, :], g=g, r_s=r_s)
    model = np.maximum(model, MODEL_FLOOR)
    if len(_GRID_CACHE) >= _GRID_CACHE_SIZE:
        _GRID_CACHE.pop(next(iter(_GRID_CACHE)))
    _GRID_CACHE[key] = model
    return model


def _grid_cost(observed, model, objective):
    """S for every row (R, K) and grid point (..., K), as matrix products; shape (R, ...).

    The products run over blocks of ``_GRID_ROWS`` rows: small enough that BLAS stays on one
    thread (threaded BLAS would compete with the other workers of a study) and cache-friendly.
    """
    flat = model.reshape(-1, model.shape[-1])
    if objective == "relative":
        a, b, c = 1.0 / flat**2, -2.0 / flat, np.full(flat.shape[0], float(flat.shape[1]))
        first, second = observed**2, observed
    elif objective == "log":
        log_model = np.log(flat)
        a, b, c = np.ones_like(flat), -2.0 * log_model, (log_model**2).sum(axis=1)
        first = second = np.log(observed)
        first = first**2
    else:
        a, b, c = np.ones_like(flat), -2.0 * flat, (flat**2).sum(axis=1)
        first, second = observed**2, observed
    cost = np.empty((observed.shape[0], flat.shape[0]))
    for start in range(0, observed.shape[0], _GRID_ROWS):
        rows = slice(start, start + _GRID_ROWS)
        cost[rows] = first[rows] @ a.T + second[rows] @ b.T + c
    return np.maximum(cost, 0.0).reshape((observed.shape[0],) + model.shape[:-1])


def _grid_costs(blocks, box, g, settings, s_nodes, x_nodes, n_groups):
    """S on the grid: the opaque films' part (R, n_s) and each group's part (G, R, n_s, n_x)."""
    n_rows = g.size
    opaque = np.zeros((n_rows, s_nodes.size))
    groups = np.zeros((n_groups, n_rows, s_nodes.size, x_nodes.size))
    for block in blocks:
        unique, inverse = np.unique(np.stack([block.r_s, g], axis=1), axis=0, return_inverse=True)
        for u, (r_s, g_value) in enumerate(unique):
            rows = np.flatnonzero(inverse.ravel() == u)
            model = _grid_model(block, s_nodes, x_nodes, r_s, g_value, box)
            cost = _grid_cost(block.observed[rows], model, settings.objective)
            if block.group < 0:
                opaque[rows] += cost
            elif block.table is None:
                groups[block.group, rows] += cost[:, None, :]
            else:
                groups[block.group, rows] += cost
    return opaque, groups


def _basins(cost, max_starts):
    """Grid indices of up to ``max_starts`` local minima of ``cost`` (R, A, B) per row, best first.

    A local minimum is a node no higher than its (up to 8) neighbours and within
    ``BASIN_RTOL`` of the row's best node; minima closer than ``BASIN_SEPARATION`` nodes to a
    better chosen one, and nodes on the opaque plateau (S as at the largest ``tau``, last axis),
    count as the same basin.
    Returns i, j of shape (max_starts, R) and a validity mask of the same shape.
    """
    n_rows, n_a, n_b = cost.shape
    padded = np.pad(cost, ((0, 0), (1, 1), (1, 1)), constant_values=np.inf)
    neighbours = np.full(cost.shape, np.inf)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                neighbours = np.minimum(
                    neighbours, padded[:, 1 + di : 1 + di + n_a, 1 + dj : 1 + dj + n_b]
                )
    # the opaque plateau (S within PLATEAU_RTOL of its value at the largest tau) is one basin
    plateau = np.abs(cost - cost[:, :, -1:]) <= PLATEAU_RTOL * cost[:, :, -1:]
    plateau[:, :, -1] = False
    is_min = (
        (cost <= neighbours)
        & ~plateau
        & (cost <= cost.min(axis=(1, 2), keepdims=True) * (1.0 + BASIN_RTOL))
    )
    ranked = np.where(is_min, cost, np.inf).reshape(n_rows, -1)
    k = min(_BASIN_CANDIDATES, ranked.shape[1])
    top = np.argpartition(ranked, k - 1, axis=1)[:, :k]
    top = np.take_along_axis(
        top, np.argsort(np.take_along_axis(ranked, top, axis=1), axis=1), axis=1
    )
    top_cost = np.take_along_axis(ranked, top, axis=1)
    ci, cj = np.divmod(top, n_b)
    i = np.zeros((max_starts, n_rows), int)
    j = np.zeros((max_starts, n_rows), int)
    valid = np.zeros((max_starts, n_rows), bool)
    i[0], j[0], valid[0] = ci[:, 0], cj[:, 0], True
    count = np.ones(n_rows, int)
    for c in range(1, k):
        far = np.isfinite(top_cost[:, c]) & (count < max_starts)
        for m in range(max_starts):
            near = valid[m] & (
                np.maximum(np.abs(ci[:, c] - i[m]), np.abs(cj[:, c] - j[m])) < BASIN_SEPARATION
            )
            far &= ~near
        rows = np.flatnonzero(far)
        i[count[rows], rows], j[count[rows], rows], valid[count[rows], rows] = (
            ci[rows, c],
            cj[rows, c],
            True,
        )
        count[rows] += 1
    return i, j, valid


def _grid_starts(blocks, box, theta, g, free, settings):
    """Starting points from a scan of S over a grid of the free parameters.

    The grid is uniform in ``sqrt(a)`` and ``log tau``. With one film group (every method of
    the paper) the starts are the distinct local minima of S on the grid, up to
    ``settings.max_starts`` per row, best
    first: a second basin (e.g. the opaque plateau ``tau -> inf`` beside a finite minimum, or
    the ``a = 0`` edge of method 3's ravine) gets its own start. With several groups, S given
    ``a`` separates into one term per group, so the scan minimises each over its ``tau`` nodes
    for every ``a`` node and starts from the best ``a`` node (exact on the grid, one start).
    Fixed parameters keep their values (the grid uses their nearest node).

    Returns starts (M, R, P) and a validity mask (M, R).
    """
    n_rows, n_param = theta.shape
    n_groups = n_param - 1
    s_nodes = np.linspace(np.sqrt(box.a_low), np.sqrt(box.a_high), settings.n_grid_a)
    x_nodes = np.linspace(box.lower[-1], box.upper[-1], settings.n_grid_tau)
    c_nodes = box.coordinate(s_nodes**2)
    opaque, groups = _grid_costs(blocks, box, g, settings, s_nodes, x_nodes, n_groups)
    rows = np.arange(n_rows)
    i_fixed = np.abs(np.sqrt(box.a_of(theta[:, :1])[0]) - s_nodes[None, :]).argmin(axis=1)
    if n_groups <= 1:
        total = opaque[:, :, None] + (groups[0] if n_groups else 0.0)
        s_index = np.arange(s_nodes.size)[None, :].repeat(n_rows, 0)
        x_index = np.arange(total.shape[2])[None, :].repeat(n_rows, 0)
        if not free[0]:
            total = total[rows, i_fixed][:, None, :]
            s_index = i_fixed[:, None]
        if n_groups and not free[1]:
            j_fixed = np.abs(theta[:, 1:2] - x_nodes[None, :]).argmin(axis=1)
            total = total[rows, :, j_fixed][:, :, None]
            x_index = j_fixed[:, None]
        i, j, valid = _basins(total, settings.max_starts)
        starts = np.repeat(theta[None], settings.max_starts, axis=0)
        for m in range(settings.max_starts):
            if free[0]:
                starts[m, :, 0] = c_nodes[s_index[rows, i[m]]]
            if n_groups and free[1]:
                starts[m, :, 1] = x_nodes[x_index[rows, j[m]]]
        return starts, valid
    total = opaque.copy()
    best_x = []
    for k in range(n_groups):
        if free[1 + k]:
            best = groups[k].argmin(axis=2)  # (R, n_s)
        else:
            nearest = np.abs(theta[:, 1 + k, None] - x_nodes[None, :]).argmin(axis=1)
            best = np.repeat(nearest[:, None], s_nodes.size, axis=1)
        best_x.append(best)
        total += np.take_along_axis(groups[k], best[..., None], axis=2)[..., 0]
    i_best = total.argmin(axis=1) if free[0] else i_fixed
    start = theta.copy()
    if free[0]:
        start[:, 0] = c_nodes[i_best]
    for k in range(n_groups):
        if free[1 + k]:
            start[:, 1 + k] = x_nodes[best_x[k][rows, i_best]]
    return start[None], np.ones((1, n_rows), bool)


# ---------------------------------------------------------------------------------------------
# bounded Levenberg–Marquardt, vectorised over rows


def _levenberg_marquardt(blocks, box, theta, g, free, settings, rows):
    """Minimise S from ``theta`` (n, P) for the blocks' ``rows`` (n,) inside the box.

    Marquardt's scaled damping (``H + lambda diag(H)``); a parameter on a bound whose
    gradient points out of the box is held there for that step (active set); trial points
    are projected onto the box. The Jacobian is evaluated at every trial point, so an
    accepted step costs one model evaluation. Returns theta, S and converged, each per row.
    """
    objective = settings.objective
    n_param = theta.shape[1]
    theta = np.clip(theta, box.lower, box.upper)
    r, jac = _residuals(blocks, box, theta, g[rows], rows, free, objective, gradient=True)
    cost = np.einsum("rn,rn->r", r, r)
    damping = np.full(rows.size, 1e-3)
    converged = np.zeros(rows.size, bool)
    active = np.arange(rows.size)  # positions in theta
    eye = np.eye(n_param)
    for _ in range(settings.max_iterations):
        if active.size == 0:
            break
        th = theta[active]
        grad = np.einsum("rnp,rn->rp", jac, r)
        hess = np.einsum("rnp,rnq->rpq", jac, jac)
        held = (
            ~free[None, :]
            | ((th <= box.lower + BOUND_ATOL) & (grad > 0))
            | ((th >= box.upper - BOUND_ATOL) & (grad < 0))
        )
        diag = np.einsum("rpp->rp", hess)
        scale = np.maximum(diag, 1e-30 * diag.max(axis=1, keepdims=True) + 1e-300)
        matrix = hess + (damping[active, None] * scale)[:, :, None] * eye
        moving = ~held
        matrix = (
            np.where(moving[:, :, None] & moving[:, None, :], matrix, 0.0) + held[:, :, None] * eye
        )
        step = np.linalg.solve(matrix, np.where(held, 0.0, -grad)[..., None])[..., 0]
        trial = np.clip(th + step, box.lower, box.upper)
        moved = np.abs(trial - th).max(axis=1)
        block_rows = rows[active]
        r_trial, jac_trial = _residuals(
            blocks, box, trial, g[block_rows], block_rows, free, objective, gradient=True
        )
        trial_cost = np.einsum("rn,rn->r", r_trial, r_trial)
        cost_before = cost[active]
        better = trial_cost < cost_before
        theta[active[better]] = trial[better]
        cost[active[better]] = trial_cost[better]
        r[better] = r_trial[better]
        jac[better] = jac_trial[better]
        damping[active] = np.where(
            better, np.maximum(damping[active] / 3.0, 1e-12), damping[active] * 4.0
        )
        decrease = cost_before - trial_cost
        done = (
            (
                better
                & (
                    (moved < settings.step_tolerance)
                    | (decrease <= settings.cost_tolerance * cost_before)
                )
            )
            | (moved == 0.0)
            | (damping[active] > 1e12)
        )
        converged[active[done]] = True
        active, r, jac = active[~done], r[~done], jac[~done]
    return theta, cost, converged


def _flag_bounds(blocks, box, theta, cost, g, free, objective):
    """Flag free parameters on a bound, or indistinguishable from it (moved onto it).

    Indistinguishable means S at the bound is within ``PLATEAU_RTOL`` of S at the estimate:
    e.g. ``tau`` of a film that the data cannot tell from an opaque one, where S is flat up to
    the table's interpolation error and the estimate would otherwise be set by that error.
    """
    n_rows, n_param = theta.shape
    rows = np.arange(n_rows)
    at_lower = np.zeros((n_rows, n_param), bool)
    at_upper = np.zeros((n_rows, n_param), bool)
    for p in np.flatnonzero(free):
        for bound, flags in ((box.lower[p], at_lower), (box.upper[p], at_upper)):
            on = np.abs(theta[:, p] - bound) <= BOUND_ATOL
            trial = theta.copy()
            trial[:, p] = bound
            trial_cost = _cost(blocks, box, trial, g, rows, free, objective)
            flat = ~on & (trial_cost <= cost * (1.0 + PLATEAU_RTOL))
            theta[flat, p] = bound
            cost[flat] = trial_cost[flat]
            flags[:, p] |= on | flat
    return theta, cost, at_lower, at_upper


def _fit_free(blocks, box, theta, g, free, settings, from_grid):
    """Fit the ``free`` parameters: grid starts (optional), Levenberg–Marquardt from each, the
    best per row, then bound flags."""
    # sqrt(a) when opaque films inform a, else a itself (see _Box); theta[:, 0] is sqrt(a) outside
    box = box.with_sqrt_a(any(b.group < 0 for b in blocks) or not free[0])
    theta = theta.copy()
    theta[:, 0] = box.coordinate(theta[:, 0] ** 2)
    all_rows = np.arange(theta.shape[0])
    if not from_grid:
        theta, cost, converged = _levenberg_marquardt(
            blocks, box, theta, g, free, settings, all_rows
        )
    else:
        starts, valid = _grid_starts(blocks, box, theta, g, free, settings)
        theta, cost, converged = _levenberg_marquardt(
            blocks, box, starts[0], g, free, settings, all_rows
        )
        for m in range(1, starts.shape[0]):
            rows = np.flatnonzero(valid[m])
            if rows.size == 0:
                continue
            th, c, conv = _levenberg_marquardt(
                blocks, box, starts[m, rows], g, free, settings, rows
            )
            better = c < cost[rows]
            theta[rows[better]], cost[rows[better]], converged[rows[better]] = (
                th[better],
                c[better],
                conv[better],
            )
    theta, cost, at_lower, at_upper = _flag_bounds(
        blocks, box, theta, cost, g, free, settings.objective
    )
    # a fit moved onto a bound it cannot be told from has found what the data say
    converged |= (at_lower | at_upper).any(axis=1)
    if not box.sqrt_a:
        theta[:, 0] = np.sqrt(theta[:, 0])
    return theta, cost, converged, at_lower, at_upper


def _eq6_log_tau(blocks, box, group):
    """``log tau`` of a group measured only in specular transmittance, by eq. (6), and bound flags.

    For one value this is eq. (6) exactly; for several, the minimiser of the relative
    objective, ``exp(tau) / t_F^2 = sum T / sum T^2``.
    """
    parts = [b for b in blocks if b.group == group]
    values = np.concatenate([b.observed for b in parts], axis=1)
    t_f2 = normal_transmittance(parts[0].n) ** 2
    tau = np.log(t_f2 * values.sum(axis=1) / (values**2).sum(axis=1))
    return np.log(np.clip(tau, box.tau_low, box.tau_high)), tau <= box.tau_low, tau >= box.tau_high


def _fit_fixed_g(blocks, box, n_groups, method, g, settings, theta=None):
    """One fit of the method at ``g`` (R,); from ``theta`` if given, else from the grid.

    Returns theta (R, P), S (R,), converged (R,), at_lower and at_upper (R, P).
    """
    n_rows, n_param = g.size, 1 + n_groups
    if theta is None and settings.start is not None:
        a_start, tau_start = settings.start
        theta = np.tile([np.sqrt(a_start)] + [np.log(tau_start)] * n_groups, (n_rows, 1))
    from_grid = theta is None
    theta = np.tile(0.5 * (box.lower + box.upper), (n_rows, 1)) if theta is None else theta.copy()
    if method in _JOINT_METHODS:
        return _fit_free(blocks, box, theta, g, np.ones(n_param, bool), settings, from_grid)
    # two steps (section 3.1, 3.2.1): a from the opaque films alone, then each group with a fixed
    opaque = [b for b in blocks if b.group < 0]
    if not opaque:
        raise ValueError(f"{method} takes a from an opaque film, and the problem has none")
    free = np.arange(n_param) == 0
    theta, _, converged, at_lower, at_upper = _fit_free(
        opaque, box, theta, g, free, settings, from_grid
    )
    for k in range(n_groups):
        members = [b for b in blocks if b.group == k]
        if all(b.table is None for b in members):
            theta[:, 1 + k], low, high = _eq6_log_tau(blocks, box, k)
            at_lower[:, 1 + k], at_upper[:, 1 + k] = low, high
            continue
        free = np.arange(n_param) == 1 + k
        theta, _, ok, low, high = _fit_free(members, box, theta, g, free, settings, from_grid)
        converged &= ok
        at_lower |= low
        at_upper |= high
    cost = _cost(
        blocks, box, theta, g, np.arange(n_rows), np.zeros(n_param, bool), settings.objective
    )
    return theta, cost, converged, at_lower, at_upper


def _pick(mask, first, second):
    """Row-wise choice between two fit tuples (``second`` where ``mask``)."""
    return tuple(
        np.where(mask.reshape((-1,) + (1,) * (np.ndim(a) - 1)), b, a) for a, b in zip(first, second)
    )


def _search_g(blocks, box, n_groups, method, g_nodes, settings):
    """The paper's outer search over ``g`` (section 3.2), per row.

    The fit is repeated at every ``g`` node of the table; around each row's best node
    ``[g_{j-1}, g_{j+1}]`` is searched by golden sections (warm-started fits).
    Returns g (R,), the fit tuple at that g, and the g bound flags.
    """
    n_rows = blocks[0].observed.shape[0]
    fits = [
        _fit_fixed_g(blocks, box, n_groups, method, np.full(n_rows, g), settings) for g in g_nodes
    ]
    best = np.stack([f[1] for f in fits], axis=1).argmin(axis=1)
    rows = np.arange(n_rows)
    at_best = tuple(np.stack([f[k] for f in fits])[best, rows] for k in range(len(fits[0])))
    theta = at_best[0]
    lo, hi = g_nodes[np.maximum(best - 1, 0)], g_nodes[np.minimum(best + 1, g_nodes.size - 1)]
    golden = (np.sqrt(5.0) - 1.0) / 2.0

    def cost_at(g):
        return _fit_fixed_g(blocks, box, n_groups, method, g, settings, theta)[1]

    c, d = hi - golden * (hi - lo), lo + golden * (hi - lo)
    f_c, f_d = cost_at(c), cost_at(d)
    for _ in range(settings.g_iterations):
        left = f_c < f_d  # minimum in [lo, d]
        lo, hi = np.where(left, lo, c), np.where(left, d, hi)
        new = np.where(left, hi - golden * (hi - lo), lo + golden * (hi - lo))
        f_new = cost_at(new)
        c, d, f_c, f_d = (
            np.where(left, new, d),
            np.where(left, c, new),
            np.where(left, f_new, f_d),
            np.where(left, f_c, f_new),
        )
    g_mid = 0.5 * (lo + hi)
    refined = _fit_fixed_g(blocks, box, n_groups, method, g_mid, settings, theta)
    use = refined[1] <= at_best[1]
    g_out = np.where(use, g_mid, g_nodes[best])
    fit = _pick(use, at_best, refined)
    return g_out, fit, g_out <= g_nodes[0] + BOUND_ATOL, g_out >= g_nodes[-1] - BOUND_ATOL


# ---------------------------------------------------------------------------------------------
# public entries


def _tables_for(films, g_kind, n, tables):
    from .table import load_table

    tables = {} if tables is None else tables
    out = []
    for film in films:
        if film.kind == "transmittance":
            out.append(None)
            continue
        table = tables.get(film.instrument) or tables.get(film.instrument.name)
        if table is None:
            table = load_table(film.instrument, g=g_kind, n=n, progress=False)
            tables[film.instrument] = table
        if g_kind == "free" and not table.free_g:
            raise ValueError(
                f"g search needs a table with a g axis for {film.instrument.name!r} (g='free')"
            )
        out.append(table)
    return out


def fit_batch(films, groups, *, method, g=0.0, tables=None, settings=None, n=1.45):
    """Fit the rows of a batch of films: per wavelength, or many simulated replicates at once.

    The low-level entry behind :func:`fit_problem`: every film's ``observed`` has one row per
    independent fit (a wavelength, or a replicate of a robustness study), and all rows are
    fitted together (vectorised).

    Parameters
    ----------
    films : sequence of FilmTerm
        Films as in :class:`bayespig.likelihood.Problem`; ``observed`` of shape (R, K) and
        ``r_s`` of shape (R,) [-].
    groups : sequence of str
        Film groups, one ``tau`` parameter each.
    method : {"method1", "method2", "method3", "method4", "general"}
        Procedure (section 3); see the module docstring.
    g : float or "search"
        Fixed Henyey–Greenstein parameter [-] (0 = isotropic, the paper's default), or
        ``"search"`` for the outer search over the tables' ``g`` axis (needs ``g``-free tables).
    tables : dict, optional
        Instrument (or its name) -> :class:`~bayespig.table.LookupTable`; missing ones are
        loaded (isotropic unless ``g`` is not 0).
    settings : FitSettings, optional
    n : float
        Binder refractive index [-] (specular transmittance, eq. 5; table loading).

    Returns
    -------
    FitResult
        ``wavelength_nm`` holds the row index.
    """
    if settings is not None and not isinstance(settings, FitSettings):
        raise TypeError(f"settings must be a FitSettings or None, got {settings!r} ({type(settings).__name__})")
    settings = settings or FitSettings()
    if not isinstance(method, str) or method not in TWO_STEP_METHODS + _JOINT_METHODS:
        raise ValueError(
            f"method must be one of {', '.join(TWO_STEP_METHODS + _JOINT_METHODS)}, got {method!r}"
        )
    search = isinstance(g, str)
    if search and g != "search":
        raise ValueError(f"g must be a number or 'search', got {g!r}")
    if not search:
        try:
            g = real_scalar("g", g, low=-1.0, high=1.0, low_open=True, high_open=True)
        except TypeError:
            raise TypeError(f"g must be a number or 'search', got {g!r} ({type(g).__name__})") from None
    n = real_scalar("n", n, low=1.0)
    if tables is not None and not isinstance(tables, dict):
        raise TypeError(f"tables must be a dict (instrument -> LookupTable) or None, got {type(tables).__name__}")
    films = tuple(films)
    groups = tuple(groups)
    if not films:
        raise ValueError("films must not be empty")
    g_kind = "free" if search or g != 0.0 else "isotropic"
    film_tables = _tables_for(films, g_kind, n, tables)
    n_rows = films[0].observed.shape[0]
    blocks = []
    for film, table in zip(films, film_tables):
        observed = np.asarray(film.observed, dtype=float)
        if observed.ndim != 2 or observed.shape[0] != n_rows:
            raise ValueError(
                f"film {film.name!r}: observed must have shape (n_rows={n_rows}, n_values)"
            )
        if not (np.isfinite(observed).all() and (observed > 0).all()):
            raise ValueError(f"film {film.name!r}: observed values must be finite and > 0")
        if film.group is not None and film.group not in groups:
            raise ValueError(f"film {film.name!r}: group {film.group!r} is not in groups {groups}")
        group = -1 if film.group is None else groups.index(film.group)
        r_s = np.broadcast_to(np.asarray(film.r_s, dtype=float), (n_rows,))
        blocks.append(_Block(table, group, r_s, observed, n))
    for k, name in enumerate(groups):
        if not any(b.group == k for b in blocks):
            raise ValueError(f"group {name!r} has no film")
    tau_max = min([t.settings.tau_nodes[-1] for t in film_tables if t is not None], default=np.inf)
    box = _Box(settings, len(groups), tau_max)
    names = ("a",) + tuple(f"tau[{name}]" for name in groups)
    if search:
        g_tables = [t for t in film_tables if t is not None]
        if not g_tables:
            raise ValueError("g search needs reflectance films")
        low = max(t.settings.g_range[0] for t in g_tables)
        high = min(t.settings.g_range[1] for t in g_tables)
        g_nodes = g_tables[0].settings.g_nodes
        g_nodes = g_nodes[(g_nodes >= low) & (g_nodes <= high)]
        g_values, (theta, cost, converged, at_lower, at_upper), g_lower, g_upper = _search_g(
            blocks, box, len(groups), method, g_nodes, settings
        )
        at_lower = np.column_stack([at_lower, g_lower])
        at_upper = np.column_stack([at_upper, g_upper])
        names = names + ("g",)
    else:
        g_values = np.full(n_rows, float(g))
        theta, cost, converged, at_lower, at_upper = _fit_fixed_g(
            blocks, box, len(groups), method, g_values, settings
        )
    return FitResult(
        wavelength_nm=np.arange(n_rows, dtype=float),
        method=method,
        groups=groups,
        a=np.minimum(theta[:, 0] ** 2, 1.0),
        tau=box.tau(theta[:, 1:]) if groups else np.zeros((n_rows, 0)),
        g=g_values,
        objective=cost,
        n_values=sum(b.n_values for b in blocks),
        parameter_names=names,
        at_lower=at_lower,
        at_upper=at_upper,
        converged=converged,
        settings=settings,
    )


def fit_problem(problem, *, g=0.0, tables=None, settings=None, warn=True):
    """Point estimates of ``a`` and ``tau`` per wavelength by the problem's method (section 3).

    Parameters
    ----------
    problem : Problem
        From :meth:`bayespig.likelihood.Problem.from_measurements`; its ``method`` selects
        the procedure (methods 1–2 in two steps, 3, 4 and ``"general"`` jointly).
    g : float or "search"
        Fixed Henyey–Greenstein parameter [-] (default 0, isotropic) or the paper's outer
        search over ``g`` (section 3.2; needs tables with a ``g`` axis, slow to build).
    tables : dict, optional
        Instrument (or name) -> look-up table; loaded from the cache when missing.
    settings : FitSettings, optional
        Bounds and numerical settings.
    warn : bool
        Emit a :class:`FitBoundWarning` naming the wavelengths where a fit stopped at a bound
        (the flags are in the result either way).

    Returns
    -------
    FitResult

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), section 3 (methods), eqs. (2), (5)–(6).
    """
    if not isinstance(problem, Problem):
        raise TypeError(
            f"problem must be a bayespig.likelihood.Problem, got {type(problem).__name__}"
        )
    flag("warn", warn)
    result = fit_batch(
        problem.films,
        problem.groups,
        method=problem.method,
        g=g,
        tables=tables,
        settings=settings,
        n=problem.n,
    )
    result = _with_wavelengths(result, problem.wavelength_nm)
    if warn and result.at_bound.any():
        warnings.warn(
            f"{problem.method}: fit at a bound — " + "; ".join(result.bound_report()),
            FitBoundWarning,
            stacklevel=2,
        )
    return result


def fit_measurements(measurements, method="auto", **kwargs):
    """:func:`fit_problem` of ``Problem.from_measurements(measurements, method)``."""
    return fit_problem(Problem.from_measurements(measurements, method), **kwargs)


def _with_wavelengths(result, wavelength_nm):
    from dataclasses import replace

    return replace(result, wavelength_nm=np.asarray(wavelength_nm, dtype=float))


def film_term(name, *, observed, group=None, instrument=None, r_s=0.0, kind="reflectance"):
    """A :class:`~bayespig.likelihood.FilmTerm` for batches built in code (replicates as rows).

    Parameters
    ----------
    name : str
        The film's name (in messages).
    observed : array_like, shape (n_rows, n_values)
        Measured values, one row per independent fit [1/sr or -].
    group : str, optional
        The film group sharing one ``tau``; ``None`` for an opaque film.
    instrument : str, Instrument or sequence, optional
        The instrument of reflectance films (see :func:`~bayespig.instruments.get_instrument`).
    r_s : float
        Substrate albedo seen from the binder, in [0, 1] [-].
    kind : {"reflectance", "transmittance"}
        What ``observed`` is.

    Returns
    -------
    FilmTerm
    """
    if not isinstance(name, str):
        raise TypeError(f"name must be a string, got {name!r} ({type(name).__name__})")
    choice("kind", kind, ("reflectance", "transmittance"))
    observed = real_array("observed", observed, ndim=2)
    r_s = real_scalar("r_s", r_s, low=0.0, high=1.0)
    if kind == "reflectance":
        if instrument is None:
            raise ValueError("instrument is needed for a reflectance film")
        instrument = get_instrument(instrument)  # a clear error now rather than at the fit
    return FilmTerm(name, kind, instrument, group, np.full(observed.shape[0], r_s), observed)
