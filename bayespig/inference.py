"""Bayesian inference per wavelength: emcee posteriors over ``a``, ``tau`` (and ``g``, ``eps``).

For every wavelength the posterior of :class:`bayespig.likelihood.LogPosterior` (the exact
likelihood of the paper's noise model, eq. 7, with the priors of
:class:`bayespig.likelihood.Priors`) is sampled with emcee 3.1.6, and the result of all
wavelengths is one :class:`arviz.InferenceData`.

Sampling
--------
* **Coordinates**: ``[a, log tau_1..G, (g), (log eps)]``; every prior is flat on a box there.
* **Independent ensembles**: ``n_ensembles`` ensembles of ``n_walkers`` walkers each run in one
  :class:`emcee.EnsembleSampler` (``vectorize=True``) whose moves only combine walkers of the
  same ensemble (:class:`IndependentEnsemblesMove`): the ensembles are independent Markov
  chains (R-hat between them is meaningful) while every log-probability call still evaluates
  the walkers of all ensembles at once (the call overhead dominates the cost).
* **Stacks of wavelengths**: ``wavelengths_per_run`` (16) wavelengths share one sampler, each
  with its own ensembles, start, run length and diagnostics: the look-up tables do not depend
  on the wavelength, so one vectorised call of the stacked log-posterior per half-step
  evaluates the proposals of all of them, and the per-step costs (table interpolation set-up,
  emcee's bookkeeping) are paid once per stack instead of once per wavelength. A wavelength
  whose run is complete is frozen and its draws are taken at that step.
* **Start**: the point fit of :func:`bayespig.fit.fit_problem`, moved inside the prior's box,
  plus Gaussian jitter shaped by the local curvature of the log-posterior (eigenvalues clipped,
  so that ravines give elongated but bounded balls); draws outside the support or with
  ``log p = -inf`` are redrawn, so no walker starts outside the support.
* **Pre-burn**: ``pre_burn_steps`` steps, after which walkers stranded far below their
  ensemble's log-posterior (:data:`STRAGGLER_LOG_P`) are moved onto jittered good walkers of
  the same ensemble; these steps are discarded.
* **Run length**: in chunks, until the chain after burn-in is at least
  ``min_autocorr_multiple`` (50) integrated autocorrelation times ``tau_int`` long (emcee's
  estimator, averaged over the walkers of each ensemble, largest over ensembles and
  parameters), the effective sample size ``n_ensembles * n_walkers * n_kept / tau_int`` of
  every parameter reaches ``target_ess``, *and* the stored draws pass the diagnostics
  (rank-normalised bulk and tail ESS >= ``target_ess``, R-hat <= 1.01; the walkers of an
  ensemble are correlated, which the per-walker ``tau_int`` does not see); capped at
  ``max_steps`` with a :class:`ConvergenceWarning`. Burn-in: the first
  ``burn_in_multiple * tau_int`` steps.
* **Moves**: ``"auto"`` is 80 % Gaussian independence proposals fitted to the complementary
  half-ensemble and 20 % differential evolution (see :class:`IndependentEnsemblesMove`): on
  method 4's compact posteriors it decorrelates in about 3 steps (DE: 8, stretch: 30), and along
  the curved ravines of method 3 it mixes faster than DE and several times faster than the
  stretch move (``benchmarks/inference.py`` measures every mixture); the DE share keeps local
  moves where a Gaussian fits the posterior poorly. ``"stretch"``, ``"de"``, ``"de-snooker"``,
  ``"stretch-de"``, ``"gaussian"`` and ``"gaussian-de"`` are available.
* **Reproducible**: the seed is split with :class:`numpy.random.SeedSequence` into one child
  per wavelength (jitter, stragglers, posterior-predictive noise; the first wavelength's child
  of a stack seeds emcee's random state), so the samples depend on the seed and the settings
  only, not on the executor or the order in which tasks finish.
* **Parallel**: each stack is one task run through a ``concurrent.futures``-style
  ``executor`` (``submit``; a ``dask.distributed`` client's ``get_executor()`` works);
  the default is a local pool of 2 processes, or serial for a single stack.

InferenceData schema
--------------------
Dimensions: ``chain`` (one per independent ensemble), ``draw`` (``draws_per_chain`` rounded up
to a multiple of ``n_walkers``: evenly thinned post-burn-in steps of the ensemble's walkers,
**flattened walker-major**, ``draw = walker * n_steps_kept + step``, so each walker's thinned
trajectory is a contiguous run and arviz's autocorrelation-based ESS and split R-hat see
ordinary Markov chains), ``wavelength`` [nm], ``group`` (film groups), ``value`` (integer index
of the measured values at one wavelength, films concatenated in problem order), ``parameter``.

``posterior``
    ``a`` (chain, draw, wavelength); ``tau`` (chain, draw, wavelength): ``tau`` of the first
    film group (the thin film; for method 1 the film on glass, from its transmittance), absent
    only when every film is opaque; ``tau_group`` (chain, draw, wavelength, group) when there
    is more than one group; ``g`` when ``g="free"``; ``eps`` when inferred; ``r_s_factor``
    (chain, draw, card) with ``substrate_sd`` (one run over all wavelengths: the draws of
    different wavelengths are then joint draws, not independent runs).
``posterior_predictive``
    ``y`` (chain, draw, wavelength, value): the noise-free model prediction of every measured
    value; ``y_rep`` with the noise of eq. (7) added when ``settings.predictive_noise``
    (single precision, as the log-likelihood).
``observed_data``
    ``y`` (wavelength, value).
``log_likelihood``
    ``y`` (chain, draw, wavelength, value): pointwise log-likelihood of eq. (7), single
    precision.
``constant_data``
    ``r_s`` (wavelength, value): substrate albedo seen from the binder per value (0 for
    transmittance and opaque films); ``eps`` (wavelength, value): known relative error (NaN
    where inferred); ``point_a``, ``point_tau`` (wavelength): the point fit (``point_tau`` of
    the first group).
``sample_stats``
    ``lp`` (chain, draw, wavelength): log posterior (= log-likelihood plus a constant);
    ``acceptance_rate`` (chain, wavelength); ``autocorr_time`` (wavelength, parameter) in
    steps; ``n_steps``, ``n_burn_in`` (wavelength); ``thinning`` (wavelength): steps between
    stored draws; ``max_steps_reached`` (wavelength, 0/1).

Non-dimension coordinates along ``value``: ``sample`` (film name), ``channel`` (channel label,
e.g. ``45as15``, ``sci``; ``specular_transmittance`` for a film on glass), ``kind``
(``reflectance``/``transmittance``), ``film_group`` (``""`` for opaque films).

Attributes (on the InferenceData and on every group): ``bayespig_version``,
``numpy_version``, ``scipy_version``, ``emcee_version``, ``arviz_version``, ``seed``,
``method``, ``g``, ``eps_mode`` (``known``/``inferred``), ``settings`` (JSON), ``priors``
(JSON of :meth:`Priors.describe`), ``table_keys`` (JSON list), ``instruments`` (JSON: name ->
channel labels), ``n`` (binder index), ``parameter_names`` (JSON), ``created`` (UTC ISO time).

References
----------
Ershov, Voloboy & Pozdnyakov (2023), eq. (7) (noise model), section 3 (methods).
Foreman-Mackey et al. (2013), emcee; Nelson et al. (2014) and ter Braak & Vrugt (2008),
differential-evolution moves; Vehtari et al. (2021), rank-normalised R-hat and ESS.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import math
import os
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from ._atomic import atomic_path
from .likelihood import ForwardModel, LogPosterior, Priors, Problem

__all__ = [
    "MOVES",
    "ConvergenceWarning",
    "IndependentEnsemblesMove",
    "InferenceSettings",
    "diagnose",
    "infer",
    "infer_problem",
    "load_inference",
    "save_inference",
    "summarize",
]

#: Move mixtures by name: (proposal kind of :class:`IndependentEnsemblesMove`, weight) pairs.
MOVES = {
    "stretch": (("stretch", 1.0),),
    "de": (("de", 1.0),),
    "de-snooker": (("de", 0.8), ("snooker", 0.2)),
    "stretch-de": (("stretch", 0.5), ("de", 0.5)),
    "gaussian": (("gaussian", 1.0),),
    "gaussian-de": (("gaussian", 0.8), ("de", 0.2)),
}
#: What ``moves="auto"`` means (measured in benchmarks/inference.py on method 3's ravines and
#: method 4's compact posteriors).
AUTO_MOVES = "gaussian-de"
#: ``"auto"`` with too few walkers for the Gaussian proposal's covariance (see
#: :meth:`InferenceSettings.move_mixture_for`).
FALLBACK_MOVES = "de-snooker"
#: Width of the ``"gaussian"`` independence proposal relative to the complementary walkers'
#: spread (a proposal somewhat wider than the target keeps the importance ratio bounded).
GAUSSIAN_PROPOSAL_SCALE = 1.5
#: Diagnostics thresholds (Vehtari et al. 2021).
RHAT_MAX = 1.01
#: Storage type of the per-draw predictions and pointwise log-likelihoods.
STORED_DRAW_DTYPE = np.float32
ESS_MIN = 400


class ConvergenceWarning(UserWarning):
    """A posterior sample that may not represent the posterior (R-hat, ESS, run-length cap)."""


@dataclass(frozen=True)
class InferenceSettings:
    """Settings of the emcee runs (recorded as JSON in every result).

    Attributes
    ----------
    n_walkers : int
        Walkers per ensemble (at least ``2 * n_dim``; DE-snooker needs at least 8).
    n_ensembles : int
        Independent ensembles (arviz chains), at least 2 for R-hat.
    moves : str
        ``"auto"`` or a key of :data:`MOVES`.
    min_autocorr_multiple : float
        The post-burn-in chain must be at least this many integrated autocorrelation times
        long (emcee's recommendation: 50).
    burn_in_multiple : float
        Burn-in discarded, in autocorrelation times.
    target_ess : float
        Effective sample size wanted for every parameter (all walkers and ensembles).
    min_steps, max_steps : int
        Shortest run, and the cap (a :class:`ConvergenceWarning` when reached), after the
        pre-burn.
    pre_burn_steps : int
        Steps before stragglers are moved and the run starts afresh (discarded).
    check_interval : int
        Steps between convergence checks (the next chunk is extrapolated from the current
        ``tau_int``, at least this long).
    draws_per_chain : int
        Stored draws per chain (rounded up to a multiple of ``n_walkers``).
    jitter : float
        Scale of the start ball relative to the curvature-based posterior width (0.5 starts the
        walkers in roughly the central half of a Gaussian posterior).
    predictive_noise : bool
        Also store posterior-predictive values with the noise of eq. (7) (``y_rep``).
    wavelengths_per_run : int
        Wavelengths sampled together in one emcee run (one executor task): each keeps its own
        ensembles and run length, but one log-posterior call per half-step serves them all
        (:func:`_sample_stack`). The samples depend on this grouping (shared random stream),
        never on the executor.
    """

    n_walkers: int = 16
    n_ensembles: int = 4
    moves: str = "auto"
    min_autocorr_multiple: float = 50.0
    burn_in_multiple: float = 5.0
    target_ess: float = 1000.0
    min_steps: int = 200
    max_steps: int = 20000
    pre_burn_steps: int = 50
    check_interval: int = 100
    draws_per_chain: int = 1024
    jitter: float = 0.5
    predictive_noise: bool = False
    wavelengths_per_run: int = 16

    def __post_init__(self):
        for name in ("n_walkers", "n_ensembles", "min_steps", "max_steps", "check_interval",
                     "draws_per_chain", "wavelengths_per_run", "pre_burn_steps"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"InferenceSettings.{name} must be a positive integer, got {value!r}")
        if self.n_ensembles < 2:
            raise ValueError(f"InferenceSettings.n_ensembles must be >= 2 (R-hat), got {self.n_ensembles}")
        if self.max_steps < self.min_steps:
            raise ValueError(f"InferenceSettings.max_steps ({self.max_steps}) must be >= min_steps "
                             f"({self.min_steps})")
        if self.max_steps < self.steps_kept:
            raise ValueError(f"InferenceSettings.max_steps ({self.max_steps}) must be >= the stored steps "
                             f"per walker, draws_per_chain / n_walkers = {self.steps_kept}")
        for name in ("min_autocorr_multiple", "burn_in_multiple", "target_ess", "jitter"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"InferenceSettings.{name} must be a non-negative number, got {value!r}")
        if self.jitter <= 0:
            raise ValueError("InferenceSettings.jitter must be > 0")
        if self.moves != "auto" and self.moves not in MOVES:
            raise ValueError(f"InferenceSettings.moves must be 'auto' or one of {', '.join(MOVES)}, "
                             f"got {self.moves!r}")

    @property
    def move_mixture(self):
        """The (move name, weight) pairs of ``moves`` (``"auto"``: :data:`AUTO_MOVES`)."""
        return MOVES[AUTO_MOVES if self.moves == "auto" else self.moves]

    def move_mixture_for(self, n_dim):
        """The (move name, weight) pairs used for ``n_dim`` parameters.

        The ``"gaussian"`` proposal fits a covariance to the ``n_walkers / 2`` complementary
        walkers, which is singular unless they outnumber the parameters by two: ``"auto"`` then
        falls back to :data:`FALLBACK_MOVES`, and an explicit Gaussian mixture is an error.
        """
        enough = self.n_walkers // 2 >= n_dim + 2
        if self.moves == "auto":
            return MOVES[AUTO_MOVES if enough else FALLBACK_MOVES]
        if not enough and any(kind == "gaussian" for kind, _ in MOVES[self.moves]):
            raise ValueError(f"InferenceSettings.moves={self.moves!r} needs n_walkers >= 2 * (n_dim + 2) = "
                             f"{2 * (n_dim + 2)} for {n_dim} parameters, got {self.n_walkers}")
        return MOVES[self.moves]

    @property
    def steps_kept(self):
        """Thinned post-burn-in steps stored per walker."""
        return math.ceil(self.draws_per_chain / self.n_walkers)

    def to_json(self, n_dim=None):
        """The settings as a JSON string, with the move mixture used for ``n_dim`` parameters
        (default: that of :attr:`move_mixture`)."""
        record = dataclasses.asdict(self)
        mixture = self.move_mixture if n_dim is None else self.move_mixture_for(n_dim)
        record["move_mixture"] = [list(m) for m in mixture]
        return json.dumps(record, sort_keys=True)


# ---------------------------------------------------------------------------------------------
# moves: several independent ensembles in one sampler


def _pick(c, index):
    """``c[k, index[k, i]]`` for c of shape (G, h, d) and index of shape (G, m)."""
    return c[np.arange(c.shape[0])[:, None], index]


def ensemble_halves(n_total, n_ensembles, random, blocks=None, owner="a move"):
    """The red-blue split of every ensemble's walkers, at random (Foreman-Mackey et al. 2013).

    Parameters
    ----------
    n_total : int
        Walkers of all ensembles (contiguous blocks of equal width).
    n_ensembles : int
    random : numpy.random.RandomState
        emcee's random state.
    blocks : numpy.ndarray of int, optional
        The ensembles to split (default all).
    owner : str
        Named in the error.

    Returns
    -------
    tuple
        ``((first, second), (second, first))``: walker indices (n_blocks, width / 2) of the half
        that moves and of the half its proposals come from, for the two half-steps.
    """
    width = n_total // n_ensembles
    half = width // 2
    if width * n_ensembles != n_total or width % 2 or half < 3:
        raise RuntimeError(f"{owner} needs an even number (>= 6) of walkers per ensemble")
    blocks = np.arange(n_ensembles) if blocks is None else blocks
    order = np.argsort(random.rand(blocks.size, width), axis=1)
    order += (blocks * width)[:, None]
    return (order[:, :half], order[:, half:]), (order[:, half:], order[:, :half])


class IndependentEnsemblesMove:
    """emcee ensemble moves applied to ``n_ensembles`` disjoint, contiguous blocks of walkers.

    Each block is an ensemble on its own: the proposals of its walkers only use the other half
    of the same block (red-blue update, Foreman-Mackey et al. 2013), so the blocks are
    independent Markov chains (one arviz ``chain`` each), while every half-step evaluates the
    proposals of all blocks in one vectorised log-probability call. The proposals are emcee's,
    vectorised over walkers and blocks:

    ``"stretch"``
        :class:`emcee.moves.StretchMove` (Goodman & Weare 2010), ``a = 2``.
    ``"de"``
        :class:`emcee.moves.DEMove` (ter Braak 2006; Nelson et al. 2014):
        ``q = x + gamma (x_j - x_k)``, ``gamma = gamma0 (1 + 1e-5 N(0, 1))``,
        ``gamma0 = 2.38 / sqrt(2 d)``.
    ``"gaussian"``
        An independence proposal from a Gaussian fitted to the other half of the ensemble,
        ``q ~ N(mean_c, s^2 cov_c)`` with ``s`` = :data:`GAUSSIAN_PROPOSAL_SCALE`, and the
        Hastings factor ``log N(x) - log N(q)`` of that Gaussian: the one-component version of
        emcee's :class:`~emcee.moves.KDEMove` (a kernel density estimate of the complementary
        ensemble). It depends on the complementary walkers only, so the red-blue update keeps
        detailed balance; on compact posteriors it decorrelates in a few steps.
    ``"snooker"``
        The DE snooker update (ter Braak & Vrugt 2008): ``q = x + gamma u (u . (z1 - z2))``
        with ``u`` the unit vector from a third walker ``z`` to ``x``, ``gamma = 1.7``, and the
        Metropolis factor ``(d - 1) log(|q - z| / |x - z|)``. emcee 3.1.6's
        :class:`~emcee.moves.DESnookerMove` normalises ``u`` by ``sqrt|x - z|`` and halves the
        factor, which breaks detailed balance (fixed upstream in dfm/emcee#531, after 3.1.6),
        so it is not used.

    When several wavelengths share one sampler (a stack, see :func:`_sample_stack`), the blocks
    of one wavelength are contiguous and ``log_prob(q, member=...)`` evaluates the proposals of
    all wavelengths in one call; blocks listed in :attr:`frozen` (wavelengths whose run is
    complete) are left where they are and cost nothing.

    Parameters
    ----------
    kind : {"stretch", "de", "snooker"}
    n_ensembles : int
        Number of blocks (ensembles of all wavelengths of the sampler).
    log_prob : callable, optional
        ``log_prob(theta, member=...)`` with ``member`` the stack position of every row
        (:class:`~bayespig.likelihood.LogPosterior` of a stack); default: emcee's
        ``log_prob_fn``.
    walkers_per_member : int, optional
        Walkers per wavelength of the stack (with ``log_prob``).
    """

    KINDS = ("stretch", "de", "snooker", "gaussian")

    def __init__(self, kind, n_ensembles, log_prob=None, walkers_per_member=None):
        if kind not in self.KINDS:
            raise ValueError(f"kind must be one of {', '.join(self.KINDS)}, got {kind!r}")
        if (log_prob is None) != (walkers_per_member is None):
            raise ValueError("log_prob and walkers_per_member go together")
        self.kind = kind
        self.n_ensembles = int(n_ensembles)
        self.log_prob = log_prob
        self.walkers_per_member = walkers_per_member
        #: Boolean per block: True leaves the block's walkers unchanged (None: every block moves).
        self.frozen = None

    def tune(self, state, accepted):
        """No tuning (emcee's interface)."""

    def _proposal(self, s, c, random):
        """Proposals for walkers ``s`` (G, h, d) from their ensembles' other halves ``c``."""
        n_blocks, h, d = s.shape
        m = c.shape[1]
        if self.kind == "stretch":
            z = ((2.0 - 1.0) * random.rand(n_blocks, h) + 1.0) ** 2 / 2.0
            partner = _pick(c, random.randint(0, m, size=(n_blocks, h)))
            return partner + z[..., None] * (s - partner), (d - 1.0) * np.log(z)
        if self.kind == "de":
            first = random.randint(0, m, size=(n_blocks, h))
            second = random.randint(0, m - 1, size=(n_blocks, h))
            second += second >= first
            gamma = 2.38 / np.sqrt(2.0 * d) * (1.0 + 1e-5 * random.randn(n_blocks, h, 1))
            return s + gamma * (_pick(c, first) - _pick(c, second)), np.zeros((n_blocks, h))
        if self.kind == "gaussian":
            mean = c.mean(axis=1, keepdims=True)  # (G, 1, d)
            spread = c - mean
            cov = np.einsum("gmi,gmj->gij", spread, spread) / (m - 1)
            ridge = 1e-12 * np.trace(cov, axis1=1, axis2=2) / d + 1e-300  # coincident walkers
            chol = GAUSSIAN_PROPOSAL_SCALE * np.linalg.cholesky(cov + ridge[:, None, None] * np.eye(d))
            z = random.randn(n_blocks, h, d)
            q = mean + np.einsum("gij,ghj->ghi", chol, z)
            w = np.einsum("gij,ghj->ghi", np.linalg.inv(chol), s - mean)  # whitened current point
            # Hastings factor log N(x) - log N(q) of the proposal (its constants cancel)
            return q, 0.5 * ((z * z).sum(axis=-1) - (w * w).sum(axis=-1))
        order = np.argsort(random.rand(n_blocks, h, m), axis=-1)[..., :3]
        z, z1, z2 = (_pick(c, order[..., k]) for k in range(3))
        delta = s - z
        norm = np.linalg.norm(delta, axis=-1)
        degenerate = norm == 0.0  # x on top of z: no direction; the proposal is rejected
        u = delta / np.where(degenerate, 1.0, norm)[..., None]
        q = s + 1.7 * u * ((u * (z1 - z2)).sum(axis=-1))[..., None]
        with np.errstate(divide="ignore"):
            factor = (d - 1.0) * (np.log(np.linalg.norm(q - z, axis=-1)) - np.log(norm))
        factor[degenerate] = -np.inf
        return q, factor

    def propose(self, model, state):
        """One red-blue update of every walker of every ensemble (emcee's Move interface)."""
        n_total, n_dim = state.coords.shape
        random = model.random
        blocks = np.arange(self.n_ensembles)
        if self.frozen is not None:
            blocks = blocks[~np.asarray(self.frozen, dtype=bool)]
        accepted = np.zeros(n_total, dtype=bool)
        for active, other in ensemble_halves(n_total, self.n_ensembles, random, blocks, type(self).__name__):
            q, factor = self._proposal(state.coords[active], state.coords[other], random)
            q = q.reshape(-1, n_dim)
            index = active.reshape(-1)
            if self.log_prob is None:
                new_log_probs, _ = model.compute_log_prob_fn(q)
            else:
                new_log_probs = self.log_prob(q, member=index // self.walkers_per_member)
            ok = factor.reshape(-1) + new_log_probs - state.log_prob[index] > np.log(random.rand(index.size))
            state.coords[index[ok]] = q[ok]
            state.log_prob[index[ok]] = new_log_probs[ok]
            accepted[index] = ok
        return state, accepted


def _moves(settings, n_dim, n_stack=1, log_prob=None):
    """The move mixture for ``n_stack`` wavelengths of ``settings.n_ensembles`` ensembles each."""
    per_member = None if log_prob is None else settings.n_ensembles * settings.n_walkers
    return [(IndependentEnsemblesMove(kind, n_stack * settings.n_ensembles, log_prob, per_member), weight)
            for kind, weight in settings.move_mixture_for(n_dim)]


# ---------------------------------------------------------------------------------------------
# one wavelength


def _inside(theta, lower, upper, margin=1e-6):
    span = upper - lower
    return np.clip(theta, lower + margin * span, upper - margin * span)


def _start_covariance(log_post, theta0):
    """Covariance of the start ball: inverse of the negative Hessian of log p at ``theta0``.

    Finite differences (one vectorised call); eigenvalues of the covariance are clipped to
    ``[(1e-6 span)^2, (span / 4)^2]`` so that flat directions (ravines, plateaus) give a
    bounded ball and a non-concave point a small one.
    """
    n_dim = theta0.size
    span = log_post.upper - log_post.lower
    h = 1e-4 * span
    points = [theta0]
    for i in range(n_dim):
        for j in range(i, n_dim):
            for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                p = theta0.copy()
                p[i] += si * h[i]
                p[j] += sj * h[j]
                points.append(p)
    points = _inside(np.array(points), log_post.lower, log_post.upper, margin=0.0)
    values = log_post(points)
    hessian = np.zeros((n_dim, n_dim))
    k = 1
    for i in range(n_dim):
        for j in range(i, n_dim):
            pp, pm, mp, mm = values[k:k + 4]
            k += 4
            hessian[i, j] = hessian[j, i] = (pp - pm - mp + mm) / (4.0 * h[i] * h[j])
    scale = np.diag(span)
    if not np.isfinite(hessian).all():
        return scale @ np.eye(n_dim) @ scale * 1e-6
    # in units of the box so that the clipping is meaningful for every coordinate
    precision = -(scale @ hessian @ scale)
    eigval, eigvec = np.linalg.eigh(0.5 * (precision + precision.T))
    variance = 1.0 / np.clip(eigval, 16.0, 1e12)
    return scale @ (eigvec * variance) @ eigvec.T @ scale


def _initial_walkers(log_post, theta0, n_total, jitter, rng):
    """``n_total`` start points inside the support with finite log-posterior."""
    theta0 = _inside(np.asarray(theta0, dtype=float), log_post.lower, log_post.upper, margin=1e-3)
    cov = _start_covariance(log_post, theta0) * jitter ** 2
    chol = np.linalg.cholesky(cov + 1e-18 * np.eye(theta0.size))
    walkers = np.empty((n_total, theta0.size))
    missing = np.arange(n_total)
    for _ in range(100):
        draws = theta0 + rng.standard_normal((missing.size, theta0.size)) @ chol.T
        ok = log_post.in_support(draws)
        if ok.any():
            ok[ok] = np.isfinite(log_post(draws[ok]))
        walkers[missing[ok]] = draws[ok]
        missing = missing[~ok]
        if missing.size == 0:
            return walkers
        chol = chol * 0.5
    raise RuntimeError(f"could not place walkers with finite log-posterior around {theta0}")


def _autocorr_times(chain, n_ensembles):
    """Integrated autocorrelation time per parameter [steps], largest over the ensembles.

    A walker that did not move at all (stuck) makes the estimate undefined; it is then the
    chain length (not converged).
    """
    from emcee.autocorr import integrated_time

    width = chain.shape[1] // n_ensembles
    if (np.ptp(chain, axis=0) == 0).any():
        return np.full(chain.shape[2], float(chain.shape[0]))
    taus = [integrated_time(chain[:, k * width:(k + 1) * width], c=5, tol=0, quiet=True)
            for k in range(n_ensembles)]
    tau = np.max(taus, axis=0)
    return np.where(np.isfinite(tau), tau, float(chain.shape[0]))


#: A walker this far (in log-posterior) below its ensemble's median after the pre-burn is a
#: straggler: for a d-dimensional near-Gaussian posterior the spread of log p is ~ sqrt(d / 2).
STRAGGLER_LOG_P = 25.0


def _replace_stragglers(coords, log_prob, log_post, n_ensembles, rng):
    """Move walkers far below their ensemble's median log p onto (jittered) good walkers.

    ``coords`` (n_walkers, n_dim) and ``log_prob`` (n_walkers,) of one wavelength are
    changed in place.
    """
    width = coords.shape[0] // n_ensembles
    for k in range(n_ensembles):
        block = np.arange(k * width, (k + 1) * width)
        lp = log_prob[block]
        bad = block[lp < np.median(lp) - STRAGGLER_LOG_P]
        good = block[lp >= np.median(lp)]
        if bad.size == 0:
            continue
        spread = coords[good].std(axis=0) + 1e-12
        for walker in bad:
            for _ in range(20):
                candidate = coords[rng.choice(good)] + 1e-2 * spread * rng.standard_normal(coords.shape[1])
                value = log_post(candidate[None])[0] if log_post.in_support(candidate[None])[0] else -np.inf
                if np.isfinite(value):
                    coords[walker], log_prob[walker] = candidate, value
                    break


def _stored_draws_pass(theta, target_ess):
    """Rank-normalised bulk and tail ESS >= target and R-hat <= RHAT_MAX for every parameter."""
    import arviz as az

    for k in range(theta.shape[-1]):
        x = theta[..., k]
        if az.rhat(x) > RHAT_MAX:
            return False
        if min(az.ess(x, method="bulk"), az.ess(x, method="tail")) < target_ess:
            return False
    return True


def _run_verdict(chain, log_prob, settings, steps):
    """Whether the run of one wavelength is complete after ``steps`` steps.

    Parameters
    ----------
    chain, log_prob : numpy.ndarray
        Post-pre-burn chain (steps, walkers, n_dim) and log-posterior (steps, walkers) of the
        wavelength's ensembles.

    Returns
    -------
    dict or int
        The run's results (draws, statistics) when complete (or capped at ``max_steps``), else
        the number of further steps before the next check.
    """
    n_chains, width, kept = settings.n_ensembles, settings.n_walkers, settings.steps_kept
    n_member = n_chains * width

    def per_chain(x):  # (kept, n_member, ...) -> (chains, walkers * kept, ...), walker-major
        x = x.reshape((kept, n_chains, width) + x.shape[2:])
        x = np.moveaxis(x, 0, 2)  # (chains, walkers, kept, ...)
        return x.reshape((n_chains, width * kept) + x.shape[3:])

    # tau_int from the second half (free of the start transient), then burn-in from it
    tau = _autocorr_times(chain[steps // 2:], n_chains)
    tau_max = float(tau.max())
    burn = max(0, min(math.ceil(settings.burn_in_multiple * tau_max), steps - kept))
    ess = n_member * (steps - burn) / tau
    needed = max(settings.min_autocorr_multiple * tau_max, settings.target_ess * tau_max / n_member, kept) + burn
    thin = max(1, (steps - burn) // kept)
    rows = steps - 1 - thin * np.arange(kept)[::-1]
    theta = per_chain(chain[rows])
    complete = False
    if steps >= needed and (ess >= settings.target_ess).all():
        # emcee's criterion met; the stored draws must pass the diagnostics too (walkers of
        # an ensemble are correlated, which the per-walker tau_int does not see)
        complete = _stored_draws_pass(theta, settings.target_ess)
        chunk = max(settings.check_interval, steps // 2)
    else:
        chunk = max(settings.check_interval, int(1.1 * needed) - steps)
    capped = not complete and steps >= settings.max_steps
    if not (complete or capped):
        return chunk
    return {"theta": theta, "lp": per_chain(log_prob[rows]), "autocorr_time": tau, "n_steps": steps,
            "n_burn_in": burn, "thin": thin, "max_steps_reached": capped}


def _sample_stack(stacked, singles, starts, settings, seed_sequences, moves=None, start_walkers=None):
    """emcee run of a stack of wavelengths in one sampler; one run record per wavelength.

    Every wavelength has ``n_ensembles`` ensembles of ``n_walkers`` walkers of its own
    (contiguous blocks; moves never mix blocks), so its chains are those of a run of its own,
    but the proposals of all wavelengths are evaluated in one call of the stacked
    log-posterior per half-step: the table interpolation and emcee's bookkeeping are paid
    once per step for the whole stack. A wavelength whose run is complete is frozen (its
    blocks no longer move or cost anything) and its draws are taken at that step, so its run
    length is its own.

    Parameters
    ----------
    stacked : LogPosterior
        Log-posterior of the stack (``index`` = the wavelengths).
    singles : list of LogPosterior
        The same per wavelength (start, stragglers).
    starts : numpy.ndarray
        Point-fit start per wavelength, (n_stack, n_dim).
    settings : InferenceSettings
    seed_sequences : list of numpy.random.SeedSequence
        One per wavelength (its start jitter, stragglers, predictive noise); the first one's
        also seeds emcee's random state of the stack.
    moves : list, optional
        ``(move, weight)`` pairs replacing the settings' mixture (a stack of one member; e.g.
        :class:`bayespig.substrate_nuisance.ConditionalBlocksMove`, which needs fewer walkers
        than ``2 n_dim``).
    start_walkers : numpy.ndarray, optional
        Every walker's start (n_stack * n_ensembles * n_walkers, n_dim) instead of a ball
        around ``starts``.

    Returns
    -------
    list of dict
    """
    import emcee

    n_stack, n_dim = len(singles), stacked.n_dim
    if settings.n_walkers < 2 * n_dim * (moves is None) or settings.n_walkers % 2 or settings.n_walkers < 6:
        raise ValueError(f"InferenceSettings.n_walkers must be even, >= 6 and >= 2 * n_dim = "
                         f"{2 * n_dim} for parameters {stacked.parameter_names}")
    n_chains = settings.n_ensembles
    per_member = n_chains * settings.n_walkers
    children = [seq.spawn(4) for seq in seed_sequences]  # jitter, emcee, predictive, stragglers
    if start_walkers is None:
        start = np.concatenate([
            _initial_walkers(single, theta0, per_member, settings.jitter, np.random.default_rng(child[0]))
            for single, theta0, child in zip(singles, starts, children)])
    else:
        start = np.array(start_walkers, dtype=float)
    member_of_walker = np.repeat(np.arange(n_stack), per_member)

    def log_prob_of_all(coords):  # emcee's interface: every walker of the stack
        return stacked(coords, member=member_of_walker)

    custom = moves is not None  # may have fewer walkers than dimensions (emcee's start check does not apply)
    moves = _moves(settings, n_dim, n_stack, stacked) if moves is None else moves
    sampler = emcee.EnsembleSampler(n_stack * per_member, n_dim, log_prob_of_all, vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(np.random.MT19937(children[0][1])).get_state()

    # pre-burn: let the ensembles spread out, then move stragglers (walkers stranded far below
    # their ensemble's log-posterior, which ensemble moves cannot bring back), and start afresh
    state = sampler.run_mcmc(start, settings.pre_burn_steps, progress=False, skip_initial_state_check=custom)
    for k, (single, child) in enumerate(zip(singles, children)):
        block = slice(k * per_member, (k + 1) * per_member)
        _replace_stragglers(state.coords[block], state.log_prob[block], single, n_chains,
                            np.random.default_rng(child[3]))
    sampler.reset()
    runs = [None] * n_stack
    steps, chunk = 0, max(settings.min_steps, settings.check_interval)
    while any(run is None for run in runs):
        live = np.array([run is None for run in runs])
        for move, _ in moves:
            move.frozen = np.repeat(~live, n_chains)
        chunk = int(min(chunk, settings.max_steps - steps))
        state = sampler.run_mcmc(state, chunk, progress=False, skip_initial_state_check=True)
        steps += chunk
        chain, log_prob = sampler.get_chain(), sampler.get_log_prob()
        accepted = sampler.backend.accepted
        chunks = []
        for k in np.flatnonzero(live):
            block = slice(k * per_member, (k + 1) * per_member)
            verdict = _run_verdict(chain[:, block], log_prob[:, block], settings, steps)
            if isinstance(verdict, dict):
                verdict["acceptance_rate"] = (accepted[block] / steps).reshape(n_chains, -1).mean(axis=1)
                verdict["predictive_seed"] = children[k][2]
                runs[k] = verdict
            else:
                chunks.append(verdict)
        chunk = min(chunks, default=0)
    return runs


def _sample_wavelength(log_post, theta0, settings, seed_sequence):
    """emcee run at one wavelength (a stack of one); returns its run record."""
    return _sample_stack(log_post, [log_post], np.asarray(theta0, dtype=float)[None], settings,
                         [seed_sequence])[0]


def _wavelength_outputs(log_post, run, settings):
    """Posterior quantities, predictions and pointwise log-likelihood from one run."""
    theta = run.pop("theta")
    n_chains, n_draws, n_dim = theta.shape
    flat = theta.reshape(-1, n_dim)
    a, tau, g, eps = log_post.unpack(flat)
    model = log_post.evaluate(a, tau, g if log_post.free_g else None)
    pointwise = log_post.log_likelihood(flat, pointwise=True)
    shape = (n_chains, n_draws)
    out = {
        "a": a.reshape(shape),
        "tau": tau.reshape(shape + (tau.shape[1],)),
        "y": model.reshape(shape + (-1,)),
        "log_likelihood": pointwise.reshape(shape + (-1,)),
        **run,
    }
    if log_post.free_g:
        out["g"] = g.reshape(shape)
    if log_post.infer_eps:
        k = 1 + log_post.n_groups + log_post.free_g
        out["eps"] = np.exp(flat[:, k]).reshape(shape)
    if settings.predictive_noise:
        rng = np.random.default_rng(run["predictive_seed"])
        noisy = model * (1.0 + np.broadcast_to(eps, model.shape) * rng.standard_normal(model.shape))
        out["y_rep"] = noisy.reshape(shape + (-1,))
    out.pop("predictive_seed")
    return out


# ---------------------------------------------------------------------------------------------
# tasks (run in workers)

#: Look-up tables per worker process, keyed by (g, n): instrument -> table.
_WORKER_TABLES = {}


@dataclass(frozen=True)
class _Task:
    problem: Problem
    g: str
    eps: float | None
    priors: Priors
    settings: InferenceSettings
    indices: tuple
    starts: np.ndarray  # (len(indices), n_dim)
    seeds: tuple  # SeedSequence per index


def _run_task(task):
    """Sample the wavelengths of one task, one stack in one sampler (runs in a worker process)."""
    tables = _WORKER_TABLES.setdefault((task.g, task.problem.n), {})
    model = ForwardModel(task.problem, g=task.g, tables=tables)
    singles = [LogPosterior(model, index, task.priors, g=task.g, eps=task.eps) for index in task.indices]
    stacked = LogPosterior(model, list(task.indices), task.priors, g=task.g, eps=task.eps)
    runs = _sample_stack(stacked, singles, task.starts, task.settings, list(task.seeds))
    return [_wavelength_outputs(single, run, task.settings) for single, run in zip(singles, runs)]


def _map_tasks(tasks, executor, progress):
    """Results of every task in order, through ``executor`` (None: serial)."""
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=sum(len(t.indices) for t in tasks), desc="inference", unit="λ")
    results = []
    try:
        if executor is None:
            for task in tasks:
                results.append(_run_task(task))
                if bar is not None:
                    bar.update(len(task.indices))
        else:
            futures = [executor.submit(_run_task, task) for task in tasks]
            for task, future in zip(tasks, futures):
                results.append(future.result())
                if bar is not None:
                    bar.update(len(task.indices))
    finally:
        if bar is not None:
            bar.close()
    return results


# ---------------------------------------------------------------------------------------------
# entries


def _resolve_eps(eps, measurements):
    """``(eps for LogPosterior, mode)`` from the ``eps`` argument."""
    if isinstance(eps, str):
        if eps != "infer":
            raise ValueError(f"eps must be a positive number, None or 'infer', got {eps!r}")
        return None, "inferred"
    if eps is None:
        metadata = getattr(measurements, "metadata", None) or {}
        value = metadata.get("eps") if isinstance(metadata, dict) else None
        eps = float(value) if isinstance(value, (int, float)) and value > 0 else 0.05
    eps = float(eps)
    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a positive number, None or 'infer', got {eps!r}")
    return eps, "known"


def _point_starts(problem, g, tables, priors, log_post0, n_wavelengths):
    """Point-fit starts ``[a, log tau.., (g), (log eps)]`` per wavelength, and the fit."""
    from .fit import FitSettings, fit_problem

    fit_settings = FitSettings(tau_bounds=tuple(float(v) for v in priors.tau_range),
                               a_bounds=tuple(float(v) for v in priors.a_range))
    fit = fit_problem(problem, g=0.0, tables=tables, settings=fit_settings, warn=False)
    columns = [fit.a[:, None], np.log(np.maximum(fit.tau, 1e-300))]
    if g == "free":
        columns.append(np.zeros((n_wavelengths, 1)))
    if log_post0.infer_eps:
        rms = np.clip(fit.rms_relative_deviation, priors.eps_range[0], priors.eps_range[1])
        columns.append(np.log(rms)[:, None])
    return np.concatenate(columns, axis=1), fit


def _value_coordinates(problem):
    """Per measured value: sample, channel, kind, film_group, and r_s (n_wavelengths, n_values)."""
    sample, channel, kind, group, r_s = [], [], [], [], []
    for film in problem.films:
        k = film.observed.shape[1]
        sample += [film.name.split(":")[0]] * k
        kind += [film.kind] * k
        group += [film.group or ""] * k
        if film.kind == "transmittance":
            channel += ["specular_transmittance"] * k
        else:
            channel += list(film.instrument.labels)
        r_s.append(np.repeat(np.asarray(film.r_s, dtype=float)[:, None], k, axis=1))
    return sample, channel, kind, group, np.concatenate(r_s, axis=1)


#: InferenceData attribute with the support of every posterior variable's prior (JSON).
PRIOR_BOUNDS_ATTR = "prior_bounds"


def _prior_bounds(priors, posterior, shared=()):
    """The support of the prior of every posterior variable, for the prior-edge flags.

    Parameters
    ----------
    priors : Priors
    posterior : dict
        Posterior variable name -> (dims, draws), as stored.
    shared : sequence
        Joint posteriors or specs of parameters shared by all wavelengths: the card factors'
        :class:`~bayespig.substrate_nuisance.CardFactorLogPosterior` (its ``log_f_lower``,
        ``log_f_upper``), or any object with ``variable``, ``lower``, ``upper`` (the box of its
        sampled coordinates), ``physical`` (coordinates -> stored values) and optionally
        ``prior_scale`` (``"linear"`` by default).

    Returns
    -------
    dict
        Variable -> ``{"lower", "upper", "scale"}``: the bounds in the variable's own units
        (numbers, or lists along its one dimension other than chain, draw and wavelength,
        e.g. ``card``) and the coordinate in which the prior is flat or sampled (``"linear"``
        or ``"log"``).
    """
    ranges = {"a": (priors.a_range, "linear"), "tau": (priors.tau_range, "log"),
              "tau_group": (priors.tau_range, "log"), "g": (priors.g_range, "linear"),
              "eps": (priors.eps_range, "log")}
    bounds = {name: {"lower": float(low), "upper": float(high), "scale": scale}
              for name, ((low, high), scale) in ranges.items() if name in posterior}
    for item in shared:
        if hasattr(item, "log_f_lower"):
            bounds["r_s_factor"] = {"lower": np.exp(item.log_f_lower).tolist(),
                                    "upper": np.exp(item.log_f_upper).tolist(), "scale": "log"}
        elif getattr(item, "variable", None) in posterior:
            lower = np.asarray(item.physical(np.atleast_2d(item.lower)), dtype=float)[0]
            upper = np.asarray(item.physical(np.atleast_2d(item.upper)), dtype=float)[0]
            bounds[item.variable] = {"lower": lower.tolist(), "upper": upper.tolist(),
                                     "scale": getattr(item, "prior_scale", "linear")}
    return bounds


def _versions():
    import arviz
    import emcee
    import scipy

    from . import __version__

    return {"bayespig_version": __version__, "numpy_version": np.__version__,
            "scipy_version": scipy.__version__, "emcee_version": emcee.__version__,
            "arviz_version": arviz.__version__}


#: Share of whole-vector DE moves among the block moves of the joint run with substrate factors:
#: they follow correlations between the blocks that the residual coordinates leave.
JOINT_DE_WEIGHT = 0.2


def _sample_with_card_factors(problem, model, priors, eps, settings, seed, substrate, executor, progress):
    """Joint run over all wavelengths with one ``r_s`` factor per card (:mod:`bayespig.substrate_nuisance`).

    Returns the per-wavelength result records of the per-wavelength path, the factor draws
    (chain, draw, card), their autocorrelation times, the settings used (walkers raised to
    what the joint vector needs) and the joint log-posterior.
    """
    from .substrate_nuisance import CardFactorLogPosterior, ConditionalBlocksMove

    cards, card_index, relative_sd = substrate
    G = len(problem.groups)
    # a pilot: every wavelength's posterior at the cards' stated albedo (f = 1), the usual way
    pilot_seed, joint_seed, start_seed = np.random.SeedSequence(int(seed)).spawn(3)
    pilot = infer_problem(problem, seed=int(pilot_seed.generate_state(1)[0]), g="isotropic", eps=eps,
                          executor=executor, progress=progress, priors=priors, settings=settings,
                          tables=model.tables)
    a_pilot = np.asarray(pilot.posterior["a"].values, dtype=float)
    tau_pilot = (np.asarray(pilot.posterior["tau_group"].values, dtype=float) if "tau_group" in pilot.posterior
                 else np.asarray(pilot.posterior["tau"].values, dtype=float)[..., None])
    draws = np.concatenate([a_pilot[..., None], np.log(tau_pilot)], axis=-1)  # (chain, draw, wl, 1 + G)
    draws = draws.reshape(-1, *draws.shape[2:])
    theta_hat = np.median(draws, axis=0)
    joint = CardFactorLogPosterior(model, card_index, theta_hat, priors, eps, relative_sd, cards)
    n_wl = joint.n_wavelengths
    # blocks of 1 + G (a wavelength) and n_cards parameters: DE needs a few walkers per dimension
    n_walkers = max(settings.n_walkers, 4 * max(1 + G, joint.n_cards), 6)
    used = dataclasses.replace(settings, n_walkers=n_walkers + n_walkers % 2)
    # walkers start on the pilot's draws (independently per wavelength) with f ~ 1
    rng = np.random.default_rng(start_seed)
    n_total = used.n_ensembles * used.n_walkers
    picked = draws[rng.integers(0, draws.shape[0], size=(n_total, n_wl)), np.arange(n_wl)]  # (n, wl, 1 + G)
    residual = np.concatenate([picked[..., 0], picked[..., 1:].reshape(n_total, -1)], axis=1) - joint.theta_hat
    start = np.concatenate([residual, rng.normal(0.0, 0.01 * relative_sd, (n_total, joint.n_cards))], axis=1)
    start[:, joint.factor_slice] = np.clip(start[:, joint.factor_slice], joint.log_f_lower, joint.log_f_upper)
    run = _sample_stack(joint, [joint], np.zeros((1, joint.n_dim)), used, [joint_seed],
                        moves=[(ConditionalBlocksMove(joint, used.n_ensembles), 1.0 - JOINT_DE_WEIGHT),
                               (IndependentEnsemblesMove("de", used.n_ensembles), JOINT_DE_WEIGHT)],
                        start_walkers=start)[0]
    theta = run.pop("theta")
    n_chains, n_draws, n_dim = theta.shape
    flat = theta.reshape(-1, n_dim)
    a, tau, factors = joint.unpack(flat)
    model_values = joint.predict(flat)  # (N, n_wl, n_values)
    pointwise = joint.log_likelihood(flat)
    noisy = None
    if used.predictive_noise:
        rng = np.random.default_rng(run["predictive_seed"])
        noisy = model_values * (1.0 + joint.eps * rng.standard_normal(model_values.shape))
    shape = (n_chains, n_draws)
    autocorr = run["autocorr_time"]
    results = []
    for i in range(n_wl):
        record = {
            "a": a[:, i].reshape(shape),
            "tau": tau[:, i].reshape(shape + (G,)),
            "y": model_values[:, i].reshape(shape + (-1,)),
            "log_likelihood": pointwise[:, i].reshape(shape + (-1,)),
            "lp": pointwise[:, i].sum(axis=-1).reshape(shape),
            "acceptance_rate": run["acceptance_rate"],
            "autocorr_time": np.concatenate([[autocorr[i]], autocorr[n_wl + i * G:n_wl + (i + 1) * G]]),
            "n_steps": run["n_steps"], "n_burn_in": run["n_burn_in"], "thin": run["thin"],
            "max_steps_reached": run["max_steps_reached"],
        }
        if noisy is not None:
            record["y_rep"] = noisy[:, i].reshape(shape + (-1,))
        results.append(record)
    factor_draws = factors.reshape(shape + (joint.n_cards,))
    return results, factor_draws, autocorr[joint.factor_slice], used, joint


def infer_problem(problem, *, seed=0, g="isotropic", eps=0.05, executor=None, progress=True,
                  priors=None, settings=None, tables=None, substrate=None):
    """Posterior samples of a :class:`~bayespig.likelihood.Problem` at every wavelength.

    Parameters as :func:`infer`, except ``eps``: a positive number (known, for films without
    their own) or None (inferred); ``tables`` optionally passes look-up tables
    (instrument -> table) for the point fit and serial runs; ``substrate``: ``(cards,
    card_index, relative_sd)`` to sample one ``r_s`` factor per card jointly over all
    wavelengths (:func:`bayespig.substrate_nuisance.card_indices` gives the first two).

    Returns
    -------
    arviz.InferenceData
        See the module docstring for the schema.
    """
    import arviz as az
    import xarray as xr

    if not isinstance(problem, Problem):
        raise TypeError(f"problem must be a bayespig.likelihood.Problem, got {type(problem).__name__}")
    if g not in ("isotropic", "free"):
        raise ValueError(f"g must be 'isotropic' or 'free', got {g!r}")
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    priors = Priors() if priors is None else priors
    settings = InferenceSettings() if settings is None else settings
    if not isinstance(priors, Priors):
        raise TypeError(f"priors must be a bayespig.likelihood.Priors, got {type(priors).__name__}")
    if not isinstance(settings, InferenceSettings):
        raise TypeError(f"settings must be an InferenceSettings, got {type(settings).__name__}")
    started = time.perf_counter()
    tables = {} if tables is None else tables
    model = ForwardModel(problem, g=g, tables=tables)
    log_post0 = LogPosterior(model, 0, priors, g=g, eps=eps)
    n_wl = problem.n_wavelengths
    starts, fit = _point_starts(problem, g, model.tables, priors, log_post0, n_wl)
    joint = None
    if substrate is not None:
        if g != "isotropic" or eps is None:
            raise ValueError("substrate factors need g='isotropic' and a known eps")
        results, factor_draws, factor_autocorr, settings, joint = _sample_with_card_factors(
            problem, model, priors, eps, settings, seed, substrate, executor, progress)
    else:
        seeds = np.random.SeedSequence(int(seed)).spawn(n_wl)
        # the stacks of wavelengths sampled together depend on the settings only (never on the
        # executor), so the samples do not depend on how the tasks are run
        per_run = settings.wavelengths_per_run
        tasks = [_Task(problem, g, eps, priors, settings, tuple(range(i, min(i + per_run, n_wl))),
                       starts[i:i + per_run], tuple(seeds[i:i + per_run]))
                 for i in range(0, n_wl, per_run)]
        own_pool = None
        if executor is None and len(tasks) > 1:
            own_pool = executor = ProcessPoolExecutor(max_workers=min(2, len(tasks), os.cpu_count() or 1))
        if executor is None:
            _WORKER_TABLES.setdefault((g, problem.n), {}).update(model.tables)
        try:
            chunks = _map_tasks(tasks, executor, progress)
        finally:
            if own_pool is not None:
                own_pool.shutdown()
        results = [r for chunk in chunks for r in chunk]

    def stack(name, axis=2):
        return np.stack([r[name] for r in results], axis=axis)

    wavelength = np.asarray(problem.wavelength_nm, dtype=float)
    groups = list(problem.groups)
    n_chains = settings.n_ensembles
    n_draws = settings.steps_kept * settings.n_walkers
    coords = {"chain": np.arange(n_chains), "draw": np.arange(n_draws), "wavelength": wavelength}
    sample, channel, kind, film_group, r_s = _value_coordinates(problem)
    value_coords = {"value": np.arange(len(sample)), "sample": ("value", sample),
                    "channel": ("value", channel), "kind": ("value", kind),
                    "film_group": ("value", film_group)}
    cdw = ("chain", "draw", "wavelength")
    posterior = {"a": (cdw, stack("a"))}
    if groups:
        tau = stack("tau")  # (chain, draw, wavelength, group)
        posterior["tau"] = (cdw, tau[..., 0])
        if len(groups) > 1:
            posterior["tau_group"] = (cdw + ("group",), tau)
    if g == "free":
        posterior["g"] = (cdw, stack("g"))
    if log_post0.infer_eps:
        posterior["eps"] = (cdw, stack("eps"))
    post_coords = dict(coords)
    if len(groups) > 1:
        post_coords["group"] = groups
    if joint is not None:
        posterior["r_s_factor"] = (("chain", "draw", "card"), factor_draws)
        post_coords["card"] = list(joint.cards)
    # per-draw predictions and pointwise log-likelihoods are most of the file (two values per
    # measured value and draw): single precision (7 digits) is far finer than the noise they
    # describe and halves it
    predictive = {"y": (cdw + ("value",), stack("y").astype(STORED_DRAW_DTYPE))}
    if settings.predictive_noise:
        predictive["y_rep"] = (cdw + ("value",), stack("y_rep").astype(STORED_DRAW_DTYPE))
    parameters = list(log_post0.parameter_names)
    sample_stats = {
        "lp": (cdw, stack("lp")),
        "acceptance_rate": (("chain", "wavelength"), stack("acceptance_rate", axis=1)),
        "autocorr_time": (("wavelength", "parameter"), stack("autocorr_time", axis=0)),
        "n_steps": (("wavelength",), np.array([r["n_steps"] for r in results])),
        "n_burn_in": (("wavelength",), np.array([r["n_burn_in"] for r in results])),
        "thinning": (("wavelength",), np.array([r["thin"] for r in results])),
        "max_steps_reached": (("wavelength",), np.array([int(r["max_steps_reached"]) for r in results])),
    }
    if joint is not None:
        sample_stats["r_s_factor_autocorr_time"] = (("card",), factor_autocorr)
    observed = np.stack([problem.observed(i) for i in range(n_wl)])
    known = problem.known_eps(eps)
    constant = {
        "r_s": (("wavelength", "value"), r_s),
        "eps": (("wavelength", "value"), np.broadcast_to(known, (n_wl, known.size)).copy()),
        "point_a": (("wavelength",), fit.a),
        "point_tau": (("wavelength",), fit.tau[:, 0] if groups else np.full(n_wl, np.inf)),
    }
    instruments = {}
    for film in problem.films:
        if film.instrument is not None:
            instruments[str(film.instrument.name)] = list(film.instrument.labels)
    attrs = {
        **_versions(),
        "seed": int(seed),
        "method": problem.method,
        "g": g,
        "eps_mode": "inferred" if log_post0.infer_eps else "known",
        "settings": settings.to_json(log_post0.n_dim),
        "priors": json.dumps(priors.describe(), sort_keys=True),
        "table_keys": json.dumps(list(model.table_keys)),
        "instruments": json.dumps(instruments, sort_keys=True),
        "n": float(problem.n),
        "parameter_names": json.dumps(parameters),
        PRIOR_BOUNDS_ATTR: json.dumps(_prior_bounds(priors, posterior, () if joint is None else (joint,))),
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "sampling_wall_time_s": float(time.perf_counter() - started),
        "substrate_factors": json.dumps(None if joint is None else {
            "relative_sd": joint.relative_sd, "cards": list(joint.cards),
            "prior": joint.describe_prior()}),
    }
    datasets = {
        "posterior": xr.Dataset(posterior, coords=post_coords),
        "posterior_predictive": xr.Dataset(predictive, coords={**coords, **value_coords}),
        "log_likelihood": xr.Dataset({"y": (cdw + ("value",), stack("log_likelihood").astype(STORED_DRAW_DTYPE))},
                                     coords={**coords, **value_coords}),
        "observed_data": xr.Dataset({"y": (("wavelength", "value"), observed)},
                                    coords={"wavelength": wavelength, **value_coords}),
        "constant_data": xr.Dataset(constant, coords={"wavelength": wavelength, **value_coords}),
        "sample_stats": xr.Dataset(sample_stats, coords={**coords, "parameter": parameters,
                                                         **({"card": list(joint.cards)} if joint else {})}),
    }
    for dataset in datasets.values():
        dataset.attrs.update(attrs)
    idata = az.InferenceData(attrs=attrs, **datasets)
    capped = [w for w, r in zip(wavelength, results) if r["max_steps_reached"]]
    if capped and joint is not None:
        warnings.warn(f"the joint run with substrate factors was capped at max_steps={settings.max_steps} "
                      f"before reaching {settings.min_autocorr_multiple:g} autocorrelation times / ESS "
                      f"{settings.target_ess:g}", ConvergenceWarning, stacklevel=2)
    elif capped:
        warnings.warn(
            f"run length capped at max_steps={settings.max_steps} before reaching "
            f"{settings.min_autocorr_multiple:g} autocorrelation times / ESS {settings.target_ess:g} at "
            + ", ".join(f"{w:g} nm" for w in capped), ConvergenceWarning, stacklevel=2)
    return idata


def infer(measurements, *, method="auto", seed=0, g="isotropic", eps=None, executor=None,
          progress=True, priors=None, settings=None, substrate_sd=None):
    """Posterior of ``a`` and ``tau`` (and ``g``, ``eps``) per wavelength from a measurement set.

    Parameters
    ----------
    measurements : MeasurementSet or path
        A set, or a file read with :func:`bayespig.read_measurements`.
    method : {"auto", "method1", "method2", "method3", "method4", "general", 1, 2, 3, 4}
        The paper's method (section 3) whose samples enter the likelihood; ``"auto"`` picks the
        most robust one the samples support (4, 1, 2, 3), else ``"general"`` (every film).
    seed : int
        Seeds every random draw (bit-for-bit reproducible, whatever the executor).
    g : {"isotropic", "free"}
        ``g = 0`` (the paper's recommendation) or ``g`` a parameter, uniform on the prior's
        range (needs look-up tables with a ``g`` axis).
    eps : float, "infer" or None
        Relative measurement error of eq. (7) [-] for samples without their own: known
        (default: the set's metadata ``eps`` when it has one, e.g. a simulated set, else 0.05),
        or ``"infer"``: one ``eps`` per wavelength shared by those samples, log-uniform prior.
    executor : concurrent.futures.Executor, optional
        Runs the wavelengths in parallel (``submit``); e.g. a ``dask.distributed`` client's
        ``get_executor()``. Default: a local pool of 2 processes (serial for a single stack of
        ``settings.wavelengths_per_run`` wavelengths).
    progress : bool
        Progress bar over wavelengths.
    priors : Priors, optional
        Default: ``a`` uniform on [0, 1], ``tau`` log-uniform on [0.01, 100], ``g`` uniform on
        [-0.5, 0.8], ``eps`` log-uniform on [0.001, 0.5].
    settings : InferenceSettings, optional
    substrate_sd : float, optional
        Treat every card's albedo seen from the binder as uncertain: ``r_s = f_card r_s,card``
        with one factor per card shared by all wavelengths, ``log f ~ N(0, substrate_sd^2)``
        (e.g. 0.1 for the ~10 % of the paper's section 3.4). The posterior is then joint over
        all wavelengths (:mod:`bayespig.substrate_nuisance`; slower: one run of
        ``n_wavelengths * (1 + groups) + cards`` parameters) and holds ``r_s_factor`` over
        ``(chain, draw, card)``. Needs ``g="isotropic"`` and a known ``eps``.

    Returns
    -------
    arviz.InferenceData
        Posterior ``a``, ``tau`` (chain, draw, wavelength) and the rest of the schema in the
        module docstring.

    Raises
    ------
    ValueError, MeasurementError
        For a file that cannot be read or a method the samples do not support.

    Warns
    -----
    ConvergenceWarning
        When a run reached ``settings.max_steps`` before its length criterion.

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), eq. (7), section 3.
    """
    from .data import MeasurementSet, read_measurements

    if not isinstance(measurements, MeasurementSet):
        if isinstance(measurements, (str, os.PathLike)):
            measurements = read_measurements(measurements)
        else:
            raise TypeError("measurements must be a MeasurementSet or a path, "
                            f"got {type(measurements).__name__}")
    if isinstance(method, (int, np.integer)) or method in ("1", "2", "3", "4"):
        method = f"method{int(method)}"
    eps_value, _ = _resolve_eps(eps, measurements)
    problem = Problem.from_measurements(measurements, method)
    substrate = None
    if substrate_sd is not None:
        from .substrate_nuisance import card_indices

        if not (isinstance(substrate_sd, (int, float, np.floating)) and np.isfinite(substrate_sd)
                and substrate_sd > 0):
            raise ValueError(f"substrate_sd must be a positive number, got {substrate_sd!r}")
        if g != "isotropic" or eps_value is None:
            raise ValueError("substrate_sd needs g='isotropic' and a known eps (the joint run over all "
                             "wavelengths does not sample g or eps)")
        cards, card_index = card_indices(measurements, problem)
        substrate = (cards, card_index, float(substrate_sd))
    return infer_problem(problem, seed=seed, g=g, eps=eps_value, executor=executor,
                         progress=progress, priors=priors, settings=settings, substrate=substrate)


# ---------------------------------------------------------------------------------------------
# summaries and diagnostics


def _parameter_views(idata):
    """(name, DataArray over chain, draw, wavelength) of the summarised parameters."""
    posterior = idata.posterior
    views = [("a", posterior["a"])]
    if "tau" in posterior:
        views.append(("tau", posterior["tau"]))
    for name in ("g", "eps"):
        if name in posterior:
            views.append((name, posterior[name]))
    return views


def summarize(idata, hdi_prob=0.9):
    """Per-wavelength summary of the posterior (arviz): mean, sd, HDI, ESS, R-hat, corr(a, log tau).

    Parameters
    ----------
    idata : arviz.InferenceData
        From :func:`infer`.
    hdi_prob : float
        Probability mass of the highest-density interval.

    Returns
    -------
    pandas.DataFrame
        One row per wavelength (index ``wavelength`` [nm]); per parameter ``p`` in ``a``,
        ``tau`` (and ``g``, ``eps``): ``p_mean``, ``p_sd``, ``p_hdi_low``, ``p_hdi_high``,
        ``p_ess_bulk``, ``p_ess_tail``, ``p_r_hat``; and ``corr_a_log_tau``, the posterior
        correlation of ``a`` with ``log tau`` (pooled draws).
    """
    import arviz as az
    import pandas as pd

    if not 0 < hdi_prob < 1:
        raise ValueError(f"hdi_prob must lie in (0, 1), got {hdi_prob}")
    posterior = idata.posterior
    wavelength = posterior["wavelength"].values
    table = {}
    for name, da in _parameter_views(idata):
        values = da.transpose("chain", "draw", "wavelength").values
        table[f"{name}_mean"] = values.mean(axis=(0, 1))
        table[f"{name}_sd"] = values.std(axis=(0, 1), ddof=1)
        hdi = az.hdi(da, hdi_prob=hdi_prob)[da.name].transpose("wavelength", "hdi").values
        table[f"{name}_hdi_low"], table[f"{name}_hdi_high"] = hdi[:, 0], hdi[:, 1]
        table[f"{name}_ess_bulk"] = az.ess(da, method="bulk")[da.name].values
        table[f"{name}_ess_tail"] = az.ess(da, method="tail")[da.name].values
        table[f"{name}_r_hat"] = az.rhat(da)[da.name].values
    if "tau" in posterior:
        a = posterior["a"].transpose("wavelength", "chain", "draw").values.reshape(wavelength.size, -1)
        log_tau = np.log(posterior["tau"].transpose("wavelength", "chain", "draw").values).reshape(
            wavelength.size, -1)
        a_c = a - a.mean(axis=1, keepdims=True)
        t_c = log_tau - log_tau.mean(axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            table["corr_a_log_tau"] = (a_c * t_c).sum(axis=1) / np.sqrt(
                (a_c ** 2).sum(axis=1) * (t_c ** 2).sum(axis=1))
    frame = pd.DataFrame(table, index=pd.Index(wavelength, name="wavelength"))
    return frame


def diagnose(idata, *, rhat_max=RHAT_MAX, ess_min=ESS_MIN, warn=True):
    """Wavelengths whose sample may not represent the posterior.

    Flags R-hat above ``rhat_max`` or bulk/tail ESS below ``ess_min`` for any summarised
    parameter (Vehtari et al. 2021), and runs that reached ``max_steps``.

    Parameters
    ----------
    idata : arviz.InferenceData
    rhat_max, ess_min : float
    warn : bool
        Emit one :class:`ConvergenceWarning` listing every flagged wavelength.

    Returns
    -------
    list of str
        One line per flagged wavelength, ``"<λ> nm: <reasons>"`` (empty when all pass).
    """
    summary = summarize(idata)
    names = [name for name, _ in _parameter_views(idata)]
    stats = idata.sample_stats if "sample_stats" in idata.groups() else None
    capped = (stats["max_steps_reached"].values.astype(bool)
              if stats is not None and "max_steps_reached" in stats else np.zeros(len(summary), bool))
    lines = []
    for k, (wavelength, row) in enumerate(summary.iterrows()):
        reasons = []
        for name in names:
            r_hat = row[f"{name}_r_hat"]
            if not np.isfinite(r_hat) or r_hat > rhat_max:
                reasons.append(f"R-hat({name}) = {r_hat:.3f} > {rhat_max:g}")
            for kind in ("bulk", "tail"):
                ess = row[f"{name}_ess_{kind}"]
                if not np.isfinite(ess) or ess < ess_min:
                    reasons.append(f"ESS_{kind}({name}) = {ess:.0f} < {ess_min:g}")
        if capped[k]:
            reasons.append("run length capped at max_steps")
        if reasons:
            lines.append(f"{wavelength:g} nm: " + "; ".join(reasons))
    if warn and lines:
        warnings.warn(f"{len(lines)} wavelength(s) not converged:\n  " + "\n  ".join(lines),
                      ConvergenceWarning, stacklevel=2)
    return lines


# ---------------------------------------------------------------------------------------------
# files


def save_inference(idata, path):
    """Write ``idata`` to a netCDF file atomically (temporary file in the same directory, then
    :func:`os.replace`); nothing is left half-written on failure.

    Returns
    -------
    str
        The path written.
    """
    path = os.fspath(path)
    with atomic_path(path, suffix=".nc") as temporary:
        idata.to_netcdf(temporary)
    return path


def load_inference(path):
    """Read an InferenceData written by :func:`save_inference` (netCDF, no pickle).

    Raises
    ------
    ValueError
        When the file is missing or not an inference result.
    """
    import arviz as az

    path = os.fspath(path)
    if not os.path.exists(path):
        raise ValueError(f"{path}: no such file")
    try:
        idata = az.from_netcdf(path)
    except (OSError, ValueError) as error:
        raise ValueError(f"{path}: not a netCDF inference file ({error})") from None
    if "posterior" not in idata.groups() or "a" not in idata.posterior:
        raise ValueError(f"{path}: no posterior of 'a' — not written by bayespig.infer")
    return idata
