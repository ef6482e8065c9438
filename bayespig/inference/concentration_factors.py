"""Effective concentrations of a film's minor pigments: one factor per (film, pigment).

A recipe gives every pigment's concentration ``D_i`` (appendix A2), but the pigment does not
always act at it: weighing and dispersion errors of a small amount, and tinting-strength
differences of a pigment in a given mixture (flocculation, a black dispersing differently in a
yellow than in a white) make its *effective* concentration ``D_i f`` with an unknown factor
``f`` per film. Every mixing rule of the library is linear in ``D`` (paper section 2:
``k_ext = sum_i D_i sigma_i``, ``k_abs = sum_i D_i a_i sigma_i``; Duncan's ``K = sum_i D_i
K_i``, ``S = sum_i D_i S_i``), so ``f`` scales the pigment's per-concentration coefficients in
that film alone.

Identifiability: a factor on *every* pigment of a film equals a factor on its thickness ``h``
(:mod:`bayespig.inference.film_thickness`), so a film's dominant pigment (largest ``D``) keeps
``f = 1`` and only the others (the minor components: the black of a shade, the colour of a
white tint) get one. The factors are a spec of the one joint machinery for shared parameters
(:mod:`bayespig.inference.shared`), entering the forward model through the model input
``concentration_log_factor`` (W, n_factors), in the order of the spec's labels
``"<film>/<pigment>"``.

Prior: ``log f ~ N(0, sd^2)`` per factor, truncated at :data:`CONCENTRATION_PRIOR_SDS` sds.
"""

from __future__ import annotations

import numpy as np

from .shared import SharedParameter

__all__ = ["CONCENTRATION_PRIOR_SDS", "ConcentrationFactors", "check_concentration_sd"]

#: The prior of ``log f`` is truncated at this many sds (a bounded box for the sampler).
CONCENTRATION_PRIOR_SDS = 4.0


def check_concentration_sd(value):
    """``concentration_sd`` checked: None, or a positive finite number (float).

    Raises
    ------
    ValueError
        Naming ``concentration_sd`` for a number that is not positive and finite, or a value
        that is not a number.
    """
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"concentration_sd must be None or a positive number (the prior sd of log f), "
                         f"got {value!r}")
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"concentration_sd must be a positive finite number (the prior sd of log f), got {value!r}")
    return value


class ConcentrationFactors(SharedParameter):
    """A factor ``f`` on the concentration of each minor pigment of each film (see the module docstring).

    Parameters
    ----------
    films : sequence of str
        Film of each factor.
    pigments : sequence of str
        Pigment of each factor (same length as ``films``).
    sd : float
        Prior sd of ``log f`` [-].

    Raises
    ------
    ValueError
        Naming the argument: no factors, lengths that differ, a (film, pigment) pair twice, or
        an sd that is not a positive number.
    """

    title = "concentration factors"
    variable = "concentration_factor"
    dimension = "component"
    long_name = "factor on a minor pigment's recipe concentration in one film, D_eff / D"
    units = "1"
    coordinate_name = "log_concentration_factor"
    attribute = "concentration_factor_prior"
    prior_scale = "log"

    def __init__(self, films, pigments, sd):
        films, pigments = tuple(map(str, films)), tuple(map(str, pigments))
        if not films:
            raise ValueError("films must name at least one factor's film")
        if len(films) != len(pigments):
            raise ValueError(f"films and pigments must have the same length, got {len(films)} and {len(pigments)}")
        labels = tuple(f"{f}/{p}" for f, p in zip(films, pigments))
        if len(set(labels)) != len(labels):
            raise ValueError(f"every (film, pigment) must have one factor, got {list(labels)}")
        self.sd = check_concentration_sd(sd)
        if self.sd is None:
            raise ValueError("concentration_sd must be a positive number, got None")
        self.films, self.pigments, self.labels = films, pigments, labels
        n = len(labels)
        self.lower = np.full(n, -CONCENTRATION_PRIOR_SDS * self.sd)
        self.upper = np.full(n, CONCENTRATION_PRIOR_SDS * self.sd)
        self.nominal = np.zeros(n)
        self.start_sd = np.full(n, 0.01 * self.sd)

    def log_prior(self, x):
        """Normal in ``log f`` (up to a constant), (W,)."""
        return -0.5 * np.sum((x / self.sd) ** 2, axis=1)

    def physical(self, x):
        """The factors ``f = exp(log f)``."""
        return np.exp(x)

    def model_inputs(self, x):
        """``concentration_log_factor``: every factor's ``log f``, (W, n_factors)."""
        return {"concentration_log_factor": np.asarray(x, dtype=float)}

    def describe_prior(self):
        """The prior as text (provenance)."""
        return (f"D_eff = f D for each film's minor pigments (the dominant one at f = 1), log f ~ "
                f"N(0, {self.sd:g}^2), truncated at {CONCENTRATION_PRIOR_SDS:g} sd")

    def describe(self):
        """Labels and prior (JSON-able)."""
        return {"labels": list(self.labels), "sd": self.sd, "prior": self.describe_prior()}
