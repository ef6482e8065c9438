"""Settings of the emcee runs, the move mixtures by name, and the diagnostics thresholds."""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["AUTO_MOVES", "ESS_MIN", "FALLBACK_MOVES", "MOVES", "RHAT_MAX", "ConvergenceWarning",
           "InferenceSettings"]

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
#: Diagnostics thresholds (Vehtari et al. 2021).
RHAT_MAX = 1.01
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
