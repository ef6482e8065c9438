"""Likelihoods: the paper's multiplicative noise model over any set of samples, and priors.

Every measured value is ``x_obs = x_true (1 + eps xi)``, ``xi ~ N(0, 1)`` (paper eq. 7),
so the exact likelihood of one value is ``N(x_obs | x_model, (eps x_model)^2)``:

    log L = -1/2 ((x_obs - x_model) / (eps x_model))^2 - log(eps x_model) - 1/2 log(2 pi)

A :class:`Problem` is what a measurement set says about one pigment: for every film
its instrument, substrate albedo ``r_s(λ)``, whether it is opaque, which films
share ``tau`` (film groups), and the observed values. The paper's methods 1–4
(section 3) are subsets of samples; the general case is all of them. Parameters
per wavelength are ``a`` (pigment), one ``tau`` per film group, optionally ``g``
(pigment) and ``eps`` (shared by the samples of that wavelength).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .instruments import Instrument
from .physics.forward import specular_transmittance

__all__ = [
    "METHODS",
    "FilmTerm",
    "Problem",
    "Priors",
    "ForwardModel",
    "LogPosterior",
    "multiplicative_normal_logpdf",
]

#: The paper's methods, in the order ``method="auto"`` prefers them (paper section 4.2:
#: method 4 is the most robust, then method 1).
METHODS = ("method4", "method1", "method2", "method3")
_LOG_2PI = np.log(2.0 * np.pi)


def multiplicative_normal_logpdf(observed, model, eps):
    """Log-density of the paper's noise model (eq. 7), per value.

    Parameters
    ----------
    observed, model : array_like
        Measured and predicted values (same units; ``model > 0``).
    eps : array_like
        Relative measurement error [-].

    Returns
    -------
    numpy.ndarray
        ``log N(observed | model, (eps model)^2)``, broadcast.
    """
    sigma = eps * model
    return -0.5 * ((observed - model) / sigma) ** 2 - np.log(sigma) - 0.5 * _LOG_2PI


@dataclass(frozen=True)
class FilmTerm:
    """One measured film as the likelihood sees it.

    Attributes
    ----------
    name : str
    kind : {"reflectance", "transmittance"}
        Reflectance channels of ``instrument``, or the specular transmittance of a
        film on glass at normal incidence (eq. 5).
    instrument : Instrument or None
        Channels of the reflectance measurements (None for transmittance).
    group : str or None
        Film group sharing ``tau``; None for an opaque film.
    r_s : numpy.ndarray
        Substrate albedo seen from the binder, shape (n_wavelengths,) [-].
    observed : numpy.ndarray
        Shape (n_wavelengths, n_values).
    eps : float or None
        Known relative error of this film's values.
    """

    name: str
    kind: str
    instrument: Instrument | None
    group: str | None
    r_s: np.ndarray
    observed: np.ndarray
    eps: float | None = None

    @property
    def opaque(self):
        """True for an opaque film (``tau = inf``)."""
        return self.group is None


@dataclass(frozen=True)
class Problem:
    """What a measurement set says about one pigment, ready for a likelihood.

    Attributes
    ----------
    wavelength_nm : numpy.ndarray
        Shape (n_wavelengths,) [nm].
    films : tuple of FilmTerm
    groups : tuple of str
        Film groups, one ``tau`` parameter each, in parameter order.
    n : float
        Refractive index of the binder [-].
    method : str
        ``"method1"`` .. ``"method4"`` or ``"general"``.
    """

    wavelength_nm: np.ndarray
    films: tuple
    groups: tuple
    n: float = 1.45
    method: str = "general"

    @property
    def n_wavelengths(self):
        """Number of wavelengths."""
        return self.wavelength_nm.size

    @property
    def n_values(self):
        """Measured values per wavelength."""
        return sum(f.observed.shape[1] for f in self.films)

    def observed(self, index):
        """All observed values at wavelength ``index``, concatenated over films, shape (n_values,)."""
        return np.concatenate([f.observed[index] for f in self.films])

    def known_eps(self, default=None):
        """Per-value relative errors (films' own ``eps``, else ``default``), shape (n_values,)."""
        parts = []
        for f in self.films:
            eps = f.eps if f.eps is not None else default
            parts.append(np.full(f.observed.shape[1], np.nan if eps is None else eps))
        return np.concatenate(parts)

    @classmethod
    def from_measurements(cls, measurements, method="auto"):
        """Build the problem of a :class:`~bayespig.data.MeasurementSet` for one method.

        Parameters
        ----------
        measurements : MeasurementSet
        method : {"auto", "method1", "method2", "method3", "method4", "general"}
            ``"auto"`` picks the most robust of the paper's methods the samples
            support (4, 1, 2, 3), or ``"general"`` (every film) when none applies.
            ``"general"`` uses every film of the set.

        Returns
        -------
        Problem
        """
        if method == "auto":
            supported = measurements.supported_methods()
            method = next((m for m in METHODS if supported[m]), "general")
        if method == "general":
            subset = measurements
        elif method in METHODS:
            subset = measurements.for_method(method)
        else:
            raise ValueError(f"method must be 'auto', 'general' or one of {', '.join(METHODS)}; got {method!r}")
        films, groups = [], []
        for sample in subset.films:
            group = None if sample.opaque else sample.group
            if group is not None and group not in groups:
                groups.append(group)
            if sample.reflectance_measurements:
                films.append(FilmTerm(sample.name, "reflectance", sample.instrument(subset.n), group,
                                      subset.substrate_albedo(sample), sample.reflectance, sample.eps))
            if sample.transmittance is not None:
                films.append(FilmTerm(sample.name + ":transmittance", "transmittance", None, group,
                                      np.zeros(subset.n_wavelengths), sample.transmittance.values[:, None],
                                      sample.eps))
        if not films:
            raise ValueError("the measurement set has no films to fit")
        return cls(np.asarray(subset.wavelength_nm, float), tuple(films), tuple(groups), subset.n, method)


@dataclass(frozen=True)
class Priors:
    """Prior ranges (stated in every report).

    ``a`` uniform on ``a_range``; each ``tau`` log-uniform on ``tau_range``; ``g``
    uniform on ``g_range`` when free; ``eps`` log-uniform on ``eps_range`` when inferred.
    """

    a_range: tuple = (0.0, 1.0)
    tau_range: tuple = (0.01, 100.0)
    g_range: tuple = (-0.5, 0.8)
    eps_range: tuple = (1e-3, 0.5)

    def describe(self):
        """One line per parameter, for reports."""
        return {
            "a": f"uniform on [{self.a_range[0]:g}, {self.a_range[1]:g}]",
            "tau": f"log-uniform on [{self.tau_range[0]:g}, {self.tau_range[1]:g}]",
            "g": f"uniform on [{self.g_range[0]:g}, {self.g_range[1]:g}] (when free)",
            "eps": f"log-uniform on [{self.eps_range[0]:g}, {self.eps_range[1]:g}] (when inferred)",
        }


@dataclass
class ForwardModel:
    """Predictions of every film of a :class:`Problem` through look-up tables.

    Parameters
    ----------
    problem : Problem
    g : {"isotropic", "free"}
        Table type.
    tables : dict, optional
        Instrument name or Instrument -> table; loaded with
        :func:`bayespig.load_table` when missing.
    """

    problem: Problem
    g: str = "isotropic"
    tables: dict = field(default_factory=dict)

    def __post_init__(self):
        from .table import load_table

        self._film_tables = []
        for film in self.problem.films:
            if film.kind == "transmittance":
                self._film_tables.append(None)
                continue
            table = self.tables.get(film.instrument) or self.tables.get(film.instrument.name)
            if table is None:
                table = load_table(film.instrument, g=self.g, n=self.problem.n, progress=False)
                self.tables[film.instrument] = table
            self._film_tables.append(table)
        self.table_keys = tuple(sorted({t.key for t in self._film_tables if t is not None}))

    def predict(self, index, a, tau, g=0.0):
        """Predicted values at wavelength ``index``.

        Parameters
        ----------
        index : int
            Wavelength index.
        a : array_like
            Shape (...,) [-].
        tau : array_like
            Shape (..., n_groups) [-].
        g : array_like
            Shape (...,).

        Returns
        -------
        numpy.ndarray
            Shape (..., n_values), films concatenated in order.
        """
        a = np.asarray(a, dtype=float)
        tau = np.asarray(tau, dtype=float)
        g = np.broadcast_to(np.asarray(g, dtype=float), a.shape)
        groups = self.problem.groups
        parts = []
        for film, table in zip(self.problem.films, self._film_tables):
            film_tau = np.full(a.shape, np.inf) if film.opaque else tau[..., groups.index(film.group)]
            if film.kind == "transmittance":
                parts.append(specular_transmittance(film_tau, self.problem.n)[..., None])
            else:
                parts.append(table(a=a, tau=film_tau, g=g, r_s=film.r_s[index]))
        return np.concatenate(parts, axis=-1)


class LogPosterior:
    """Vectorised log-posterior at one wavelength, over ``theta`` of shape (n_walkers, n_dim).

    Parameters are ``[a, log tau_1, ..., log tau_G, (g), (log eps)]``: with the
    default priors the density is flat in ``a`` and in each ``log tau``.

    Parameters
    ----------
    model : ForwardModel
    index : int
        Wavelength index.
    priors : Priors
    g : {"isotropic", "free"}
        Whether ``g`` is a parameter (otherwise 0).
    eps : float or None
        Known relative error for films without their own; None infers it.
    """

    def __init__(self, model, index, priors=Priors(), g="isotropic", eps=0.05):
        self.model = model
        self.index = index
        self.priors = priors
        self.free_g = g == "free"
        self.observed = model.problem.observed(index)
        known = model.problem.known_eps(eps)
        self.infer_eps = bool(np.isnan(known).any())
        self.eps = known
        self.n_groups = len(model.problem.groups)
        names = ["a"] + [f"log_tau[{g}]" for g in model.problem.groups]
        if self.free_g:
            names.append("g")
        if self.infer_eps:
            names.append("log_eps")
        self.parameter_names = tuple(names)

    @property
    def n_dim(self):
        """Number of parameters."""
        return len(self.parameter_names)

    def unpack(self, theta):
        """``a``, ``tau`` (…, G), ``g``, ``eps`` (…, n_values) from parameter vectors."""
        theta = np.atleast_2d(theta)
        a = theta[:, 0]
        tau = np.exp(theta[:, 1:1 + self.n_groups])
        k = 1 + self.n_groups
        g = theta[:, k] if self.free_g else np.zeros(theta.shape[0])
        k += self.free_g
        eps = np.exp(theta[:, k])[:, None] * np.ones_like(self.eps) if self.infer_eps else self.eps[None, :]
        return a, tau, g, eps

    def in_support(self, theta):
        """Boolean mask of parameter vectors inside the prior's support."""
        theta = np.atleast_2d(theta)
        p = self.priors
        ok = (theta[:, 0] >= p.a_range[0]) & (theta[:, 0] <= p.a_range[1])
        log_tau = theta[:, 1:1 + self.n_groups]
        ok &= ((log_tau >= np.log(p.tau_range[0])) & (log_tau <= np.log(p.tau_range[1]))).all(axis=1)
        k = 1 + self.n_groups
        if self.free_g:
            ok &= (theta[:, k] >= p.g_range[0]) & (theta[:, k] <= p.g_range[1])
            k += 1
        if self.infer_eps:
            ok &= (theta[:, k] >= np.log(p.eps_range[0])) & (theta[:, k] <= np.log(p.eps_range[1]))
        return ok & np.isfinite(theta).all(axis=1)

    def log_likelihood(self, theta):
        """Log-likelihood per parameter vector (``-inf`` outside the support)."""
        theta = np.atleast_2d(theta)
        out = np.full(theta.shape[0], -np.inf)
        ok = self.in_support(theta)
        if ok.any():
            a, tau, g, eps = self.unpack(theta[ok])
            model = self.model.predict(self.index, a, tau, g)
            out[ok] = multiplicative_normal_logpdf(self.observed, model, eps).sum(axis=-1)
        return out

    def __call__(self, theta):
        """Log-posterior (flat priors in the sampled coordinates: equal to the log-likelihood)."""
        return self.log_likelihood(theta)
