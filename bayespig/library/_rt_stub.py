"""TEMPORARY minimal radiative-transfer FilmModel for the library build (helper "libcore").

Replaced at merge time by :mod:`bayespig.library.film_models` (helper "filmmodels"), whose
interface (LIBRARY-SPEC.md) this follows exactly for what the build uses: ``name``,
``constant_names``, ``lower``, ``upper``, ``physical``, ``for_film`` -> a predictor with
``observed`` and ``values(constants, concentrations, thickness)``.

Mixing (paper section 2): ``tau = h * sum_i D_i sigma_i``, ``a = sum_i a_i D_i sigma_i /
sum_i D_i sigma_i``, ``g = 0``; the film's values are those of the per-wavelength model of its
problem (:class:`bayespig.likelihood.WavelengthModel`: look-up tables of its instrument, the
card converted from air into the binder), ``tau`` clipped at the tables' largest finite node.
"""

from __future__ import annotations

import numpy as np

from ..likelihood import ForwardModel, Problem

__all__ = ["RadiativeTransferFilmModel", "TemporaryFilmPredictor"]


class TemporaryFilmPredictor:
    """Values of one film (a MeasurementSet of one film group) from pigment constants.

    Attributes
    ----------
    observed : numpy.ndarray
        The film's measured values, (n_wl, n_values).
    """

    def __init__(self, measurements, tables):
        problem = Problem.from_measurements(measurements, "auto")
        if len(problem.groups) != 1:
            raise ValueError(f"a film must be one film group, got groups {list(problem.groups)}")
        model = ForwardModel(problem, "isotropic", tables)
        self.problem = problem
        self.n_wavelengths = problem.n_wavelengths
        self.evaluate = model.at_wavelength(list(range(problem.n_wavelengths)))
        self.observed = np.stack([problem.observed(i) for i in range(problem.n_wavelengths)])
        self.eps = problem.known_eps(None)
        self.tau_max = min(t.tau_max for t in model.film_tables if t is not None)

    def values(self, constants, concentrations, thickness):
        """Predicted values, (W, n_wl, n_values).

        Parameters
        ----------
        constants : numpy.ndarray
            ``[a_i, log sigma_i]`` per pigment, (W, n_wl, P, 2).
        concentrations : numpy.ndarray
            ``D_i`` (P,).
        thickness : numpy.ndarray
            ``h`` per row, (W,).
        """
        constants = np.asarray(constants, dtype=float)
        W, n_wl = constants.shape[:2]
        weight = np.asarray(concentrations, dtype=float) * np.exp(constants[..., 1])  # (W, n_wl, P)
        total = weight.sum(axis=-1)
        a = np.clip((constants[..., 0] * weight).sum(axis=-1) / total, 0.0, 1.0)
        tau = np.clip(np.asarray(thickness, dtype=float)[:, None] * total, 0.0, self.tau_max)
        member = np.tile(np.arange(n_wl), W)
        return self.evaluate(a.reshape(-1), tau.reshape(-1, 1), None, member=member).reshape(W, n_wl, -1)


class RadiativeTransferFilmModel:
    """Isotropic radiative transfer of a pigment mixture (temporary; see the module docstring)."""

    name = "radiative-transfer"
    constant_names = ("a", "log_sigma")
    #: ``a`` in [0, 1]; ``sigma`` (optical thickness per unit concentration and film thickness)
    #: in [1e-2, 1e4].
    lower = np.array([0.0, np.log(1e-2)])
    upper = np.array([1.0, np.log(1e4)])

    def __init__(self):
        self._tables = {}

    def physical(self, constants):
        """``{"a": ..., "sigma": ...}`` from ``[a, log sigma]`` (..., 2)."""
        constants = np.asarray(constants, dtype=float)
        return {"a": constants[..., 0], "sigma": np.exp(constants[..., 1])}

    def for_film(self, measurements):
        """The film's predictor."""
        return TemporaryFilmPredictor(measurements, self._tables)
