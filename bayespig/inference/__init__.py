"""Bayesian inference per wavelength (see :mod:`bayespig.inference.sampler`)."""

from .sampler import *  # noqa: F401,F403
from .sampler import (  # noqa: F401
    _autocorr_times,
    _initial_walkers,
    _moves,
    _point_starts,
    _resolve_eps,
    _sample_stack,
    _sample_wavelength,
    _versions,
    _wavelength_outputs,
    ensemble_halves,
    infer_problem,
)
