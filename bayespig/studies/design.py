"""Sample design: which films pin a pigment down, from the Fisher information of eq. (7).

Noise model and Fisher information
----------------------------------
Every measured value is ``x = m(theta) (1 + eps xi)``, ``xi ~ N(0, 1)`` (paper eq. 7), i.e.
``x ~ N(m, sigma^2)`` with ``sigma = eps m``. For a normal law whose mean *and* standard
deviation depend on ``theta`` the Fisher information is

    F_ij = (dm/dtheta_i)(dm/dtheta_j) / sigma^2 + 2 (dsigma/dtheta_i)(dsigma/dtheta_j) / sigma^2.

The first term is the usual mean term; the second comes from the ``-log sigma`` term of the
log-density (the score of ``-log sigma - (x - m)^2 / (2 sigma^2)`` with respect to
``sigma`` is ``(z^2 - 1) / sigma`` with ``z = (x - m) / sigma``, and ``Var(z^2 - 1) = 2``).
With ``sigma = eps m``, ``dsigma = eps dm``, so both terms are proportional to
``dm dm^T / m^2``:

    F = J^T diag((1 / eps^2 + 2) / m^2) J,

``J`` the derivatives of every measured value with respect to the parameters
``theta = (a, log tau_1, ..., log tau_G)`` (one ``tau`` per film group, as in
:class:`bayespig.likelihood.LogPosterior`; or a single ``log tau`` per micrometre when the
thickness ratios are known, ``tau_link="proportional"``). ``J`` comes from
:meth:`bayespig.table.LookupTable.evaluate` (``gradient=True``: ``d/da`` and ``d/dtau``; the
film's ``d/dlog tau = tau d/dtau``) and, for a film on glass, from eq. (5)
(``d log T / d log tau = -tau``). An opaque film (eq. 2) informs ``a`` only.

The predicted posterior covariance is ``inv(F + P)``, ``P`` the precision of the Gaussian
with the same variance as the flat prior box of :class:`bayespig.likelihood.Priors`
(``12 / width^2`` in ``a`` and in each ``log tau``): it keeps unidentified directions (a
ravine, an opaque film's ``tau``) at the prior's width instead of infinity. The predicted sd
is ``sqrt(diag(inv(F + P)))``. This is the Laplace (Gaussian) approximation: it is good where
the posterior is well identified and says nothing about ravines or bimodality -- those are
what the full posteriors (:func:`check_designs`) are for.

Ranking
-------
:func:`rank_designs` evaluates every candidate sample set at the same seeded prior draws of
``a`` and ``tau`` per micrometre per wavelength band and scores it by the expected relative
posterior sd of ``a`` (``sd(a) / a``) and of ``tau`` (``sd(log tau)``), averaged over the
draws. Films that several candidates share (same instrument, substrate, thickness) are
evaluated once.

References
----------
Ershov, Voloboy & Pozdnyakov (2023): eq. (7) (noise), eq. (2) (opaque film), eq. (3)
(substrate), eq. (5) (film on glass), section 3 (methods 1–4), section 3.2.2 (a thin film on
white alone is a poor design).
"""

from __future__ import annotations

import dataclasses
import datetime
import io
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._atomic import write_file_set
from .._json import jsonable as _jsonable
from .._versions import package_versions
from ..data.model import BLACK_SUBSTRATE_ALBEDO, WHITE_SUBSTRATE_ALBEDO
from ..data.simulate import DESIGNS, FilmSpec
from ..likelihood import Priors
from ..table import load_table

__all__ = [
    "Candidate",
    "DesignPrior",
    "DesignResult",
    "candidate_designs",
    "check_designs",
    "fisher_information",
    "method_candidate",
    "parse_substrate",
    "posterior_sd",
    "prior_precision",
    "rank_designs",
    "write_design_report",
]

_NAMED_SUBSTRATES = {"black": BLACK_SUBSTRATE_ALBEDO, "white": WHITE_SUBSTRATE_ALBEDO}
OBJECTIVES = ("both", "a", "tau")


def parse_substrate(text):
    """A substrate albedo seen from the binder [-] from ``"black"``, ``"white"``, ``"grey:0.3"`` or ``"0.3"``."""
    if isinstance(text, (int, float, np.floating)):
        value = float(text)
    else:
        key = str(text).strip().lower()
        if key in _NAMED_SUBSTRATES:
            return _NAMED_SUBSTRATES[key]
        if key.startswith(("grey:", "gray:")):
            key = key.split(":", 1)[1]
        try:
            value = float(key)
        except ValueError:
            raise ValueError(f"substrate must be 'black', 'white', 'grey:<albedo>' or an albedo, "
                             f"got {text!r}") from None
    if not 0.0 <= value < 1.0:
        raise ValueError(f"substrate albedo must lie in [0, 1), got {value}")
    return value


def _substrate_label(r_s):
    for name, value in _NAMED_SUBSTRATES.items():
        if r_s == value:
            return name
    return f"grey {r_s:g}"


@dataclass(frozen=True)
class Candidate:
    """One candidate sample set.

    Attributes
    ----------
    name : str
    films : tuple of FilmSpec
        The films (see :class:`bayespig.data.simulate.FilmSpec`); ``tau_scale`` is the film's
        thickness in the unit of the prior's ``tau`` (micrometres for :class:`DesignPrior`).
        Substrates are albedos or ``"black"``/``"white"``.
    instrument : str
        Instrument of the reflectance measurements (see :func:`bayespig.get_instrument`).
    """

    name: str
    films: tuple
    instrument: str = "multi-angle-45"

    def __post_init__(self):
        if not self.films:
            raise ValueError(f"candidate {self.name!r} has no films")
        for film in self.films:
            if not isinstance(film, FilmSpec):
                raise TypeError(f"candidate {self.name!r}: films must be FilmSpec, got {type(film).__name__}")
            if not (np.isfinite(film.tau_scale) and film.tau_scale > 0):
                raise ValueError(f"candidate {self.name!r}, film {film.name!r}: tau_scale must be > 0")

    def describe(self):
        """One line per film, e.g. ``10 um on black``."""
        parts = []
        for film in self.films:
            if film.opaque:
                parts.append("opaque film")
            elif film.on_glass:
                parts.append(f"{film.tau_scale:g} um on glass (transmittance)")
            else:
                parts.append(f"{film.tau_scale:g} um on {_substrate_label(parse_substrate(film.substrate))}")
        return "; ".join(parts) + f" [{self.instrument}]"

    def to_json(self):
        """JSON-ready dict."""
        return {"name": self.name, "instrument": self.instrument,
                "films": [dataclasses.asdict(f) for f in self.films], "description": self.describe()}


def method_candidate(method, thickness=1.0, *, instrument="multi-angle-45", name=None):
    """The paper's method layout (section 3) with its thin film ``thickness`` times the reference.

    Parameters
    ----------
    method : {"method1", "method2", "method3", "method4"}
    thickness : float
        ``tau_scale`` of the thin film(s) [um for :class:`DesignPrior`, or 1 for ``tau`` itself].
    instrument : str
    name : str, optional

    Returns
    -------
    Candidate
    """
    if method not in DESIGNS:
        raise ValueError(f"method must be one of {', '.join(DESIGNS)}, got {method!r}")
    films = tuple(f if f.opaque else dataclasses.replace(f, tau_scale=float(thickness)) for f in DESIGNS[method])
    return Candidate(name or f"{method} {thickness:g}", films, instrument)


def candidate_designs(thicknesses, substrates=("black", "white"), instruments=("multi-angle-45",), *,
                      opaque=True, glass=True):
    """Candidate sample sets a lab can make from its thicknesses, substrates and instruments.

    For every instrument and thickness ``t``: the paper's methods 1–4 (method 4 with every
    pair of distinct substrates), ``t`` on one substrate alone (e.g. the poor "thin film on
    white only", section 3.2.2), ``t`` on every substrate, method 4 plus an opaque film; for
    every pair of thicknesses: both on black, and both on black and white.

    Parameters
    ----------
    thicknesses : sequence of float
        Film thicknesses the lab can draw down [um].
    substrates : sequence of str or float
        ``"black"``, ``"white"``, ``"grey:0.3"``, or albedos seen from the binder [-].
    instruments : sequence of str
    opaque, glass : bool
        Whether an opaque film / a film on glass (specular transmittance) can be made.

    Returns
    -------
    list of Candidate
    """
    thicknesses = [float(t) for t in thicknesses]
    if not thicknesses or not all(np.isfinite(t) and t > 0 for t in thicknesses):
        raise ValueError(f"thicknesses must be positive numbers, got {thicknesses}")
    albedos = sorted({parse_substrate(s) for s in substrates})
    if not albedos:
        raise ValueError("at least one substrate is needed")
    out = []
    for instrument in instruments:
        def film(t, r_s, group, name):
            return FilmSpec(name, substrate=r_s, tau_scale=t, film_group=group)

        for t in thicknesses:
            group = f"t{t:g}"
            if opaque and glass:
                out.append(Candidate(f"method1 {t:g}um", (FilmSpec("opaque", opaque=True),
                                     FilmSpec(f"glass_{t:g}", on_glass=True, tau_scale=t)), instrument))
            for r_s in albedos:
                label = _substrate_label(r_s)
                out.append(Candidate(f"{t:g}um on {label} only", (film(t, r_s, group, f"{t:g}_{label}"),), instrument))
                if opaque:
                    out.append(Candidate(f"opaque + {t:g}um on {label}",
                                         (FilmSpec("opaque", opaque=True), film(t, r_s, group, f"{t:g}_{label}")),
                                         instrument))
            for i, r1 in enumerate(albedos):
                for r2 in albedos[i + 1:]:
                    pair = (film(t, r1, group, f"{t:g}_{_substrate_label(r1)}"),
                            film(t, r2, group, f"{t:g}_{_substrate_label(r2)}"))
                    out.append(Candidate(f"{t:g}um on {_substrate_label(r1)} + {_substrate_label(r2)}",
                                         pair, instrument))
                    if opaque:
                        out.append(Candidate(f"opaque + {t:g}um on {_substrate_label(r1)} + {_substrate_label(r2)}",
                                             (FilmSpec("opaque", opaque=True),) + pair, instrument))
            if len(albedos) > 2:
                out.append(Candidate(f"{t:g}um on all substrates",
                                     tuple(film(t, r, group, f"{t:g}_{_substrate_label(r)}") for r in albedos),
                                     instrument))
        lo, hi = albedos[0], albedos[-1]
        for i, t1 in enumerate(thicknesses):
            for t2 in thicknesses[i + 1:]:
                out.append(Candidate(f"{t1:g}um + {t2:g}um on {_substrate_label(lo)}",
                                     (film(t1, lo, f"t{t1:g}", f"{t1:g}_a"), film(t2, lo, f"t{t2:g}", f"{t2:g}_a")),
                                     instrument))
                if hi != lo:
                    out.append(Candidate(
                        f"{t1:g}um + {t2:g}um on {_substrate_label(lo)} + {_substrate_label(hi)}",
                        tuple(film(t, r, f"t{t:g}", f"{t:g}_{k}") for t in (t1, t2)
                              for k, r in enumerate((lo, hi))), instrument))
    names = [c.name + c.instrument for c in out]
    if len(set(names)) != len(names):  # same description twice (duplicate thickness/substrate input)
        seen, unique = set(), []
        for c, n in zip(out, names):
            if n not in seen:
                seen.add(n)
                unique.append(c)
        out = unique
    return out


# ---------------------------------------------------------------------------------------------
# Fisher information


def _film_groups(films, tau_link):
    """Parameter index (1-based, after ``a``) of every film's ``log tau``, or None if opaque."""
    if tau_link not in ("groups", "proportional"):
        raise ValueError(f"tau_link must be 'groups' or 'proportional', got {tau_link!r}")
    groups, index = [], []
    for f in films:
        if f.opaque:
            index.append(None)
            continue
        key = "tau" if tau_link == "proportional" else (f.film_group or f.name)
        if key not in groups:
            groups.append(key)
        index.append(1 + groups.index(key))
    return groups, index


class _Responses:
    """Cache of one film's weighted Fisher blocks at fixed parameter draws (shared by candidates)."""

    def __init__(self, a, tau, eps, n, tables):
        self.a, self.tau, self.eps, self.n = a, tau, eps, n
        self.weight = 1.0 / eps**2 + 2.0
        self.tables = tables
        self.cache = {}

    def table(self, instrument):
        if instrument not in self.tables:
            self.tables[instrument] = load_table(instrument, n=self.n, progress=False)
        return self.tables[instrument]

    def blocks(self, film, instrument):
        """``(F_aa, F_at, F_tt)``: the film's Fisher information in ``(a, log tau_film)``, shape of ``a``."""
        key = ("glass", film.tau_scale) if film.on_glass else (
            instrument, film.opaque, None if film.opaque else film.tau_scale,
            None if film.opaque else parse_substrate(film.substrate))
        if key in self.cache:
            return self.cache[key]
        if film.on_glass:
            tau = self.tau * film.tau_scale
            # eq. (5): T = t_F^2 exp(-tau); dlog T / dlog tau = -tau, independent of a
            f_tt = self.weight * tau * tau
            zero = np.zeros_like(tau)
            out = (zero, zero, f_tt)
        else:
            table = self.table(instrument)
            if film.opaque:
                tau = np.full_like(self.a, np.inf)
                r_s = 0.0
            else:
                # films thicker than the table's largest finite tau behave as opaque; clip there
                tau = np.minimum(self.tau * film.tau_scale, table.tau_max)
                r_s = parse_substrate(film.substrate)
            a = np.clip(self.a, 1e-9, 1.0)
            value, d_a, d_tau, _ = table.evaluate(a=a, tau=tau, r_s=r_s, gradient=True)
            rel_a = d_a / value
            rel_t = np.zeros_like(value) if film.opaque else d_tau * tau[..., None] / value
            out = (self.weight * (rel_a * rel_a).sum(-1), self.weight * (rel_a * rel_t).sum(-1),
                   self.weight * (rel_t * rel_t).sum(-1))
        self.cache[key] = out
        return out


def _assemble(films, instrument, responses, tau_link):
    groups, index = _film_groups(films, tau_link)
    p = 1 + len(groups)
    fisher = np.zeros(responses.a.shape + (p, p))
    for film, k in zip(films, index):
        f_aa, f_at, f_tt = responses.blocks(film, instrument)
        fisher[..., 0, 0] += f_aa
        if k is not None:
            fisher[..., 0, k] += f_at
            fisher[..., k, 0] += f_at
            fisher[..., k, k] += f_tt
    return fisher, ["a"] + [f"log_tau[{g}]" for g in groups]


def fisher_information(films, *, a, tau, instrument="multi-angle-45", eps=0.05, n=1.45,
                       tau_link="groups", tables=None):
    """Fisher information of a sample set under the noise model of eq. (7).

    ``F = J^T diag((1/eps^2 + 2) / m^2) J`` (module docstring: the ``2 / m^2`` is the
    information in the spread, ``sigma = eps m``, of the measured values).

    Parameters
    ----------
    films : Candidate, str or sequence of FilmSpec
        A candidate, a method name (``"method1"`` .. ``"method4"``), or films.
    a : array_like
        Relative absorption [-], any shape S.
    tau : array_like
        Optical thickness per unit ``tau_scale`` [-] (a film has ``tau_scale * tau``),
        broadcast with ``a``.
    instrument : str
        Instrument of the reflectance measurements (ignored for a Candidate, which has its own).
    eps : float
        Relative error of eq. (7) [-].
    n : float
        Binder index [-].
    tau_link : {"groups", "proportional"}
        ``"groups"``: one ``log tau`` per film group, as the likelihood has; ``"proportional"``:
        one ``log tau`` for all films (thickness ratios known exactly).
    tables : dict, optional
        Instrument -> look-up table (loaded when missing).

    Returns
    -------
    fisher : numpy.ndarray
        Shape S + (P, P), parameters ``(a, log tau_1, ..., log tau_G)``.
    names : list of str
    """
    films, instrument = _resolve_films(films, instrument)
    eps = _check_eps(eps)
    a, tau = np.broadcast_arrays(np.asarray(a, float), np.asarray(tau, float))
    if ((a < 0) | (a > 1)).any() or not (tau > 0).all():
        raise ValueError("a must lie in [0, 1] and tau be > 0")
    responses = _Responses(a, tau, eps, n, {} if tables is None else tables)
    return _assemble(films, instrument, responses, tau_link)


def _resolve_films(films, instrument):
    if isinstance(films, Candidate):
        return films.films, films.instrument
    if isinstance(films, str):
        return method_candidate(films).films, instrument
    films = tuple(films)
    Candidate("films", films, instrument)  # validates
    return films, instrument


def _check_eps(eps):
    eps = float(eps)
    if not (np.isfinite(eps) and 0 < eps < 1):
        raise ValueError(f"eps must be a number in (0, 1), got {eps!r}")
    return eps


def prior_precision(names, priors=None):
    """Diagonal precision of the Gaussian with the variance of the flat prior box (``12 / width^2``).

    Parameters
    ----------
    names : list of str
        Parameter names from :func:`fisher_information`.
    priors : Priors, optional
        Default :class:`bayespig.likelihood.Priors` (as :func:`bayespig.infer` uses).

    Returns
    -------
    numpy.ndarray
        Shape (P, P).
    """
    priors = Priors() if priors is None else priors
    width = [priors.a_range[1] - priors.a_range[0]] + [np.log(priors.tau_range[1] / priors.tau_range[0])] * (
        len(names) - 1)
    return np.diag(12.0 / np.square(width))


def posterior_sd(fisher, names, priors=None, *, use_prior=True):
    """Predicted posterior sd and the ``a``–``log tau_1`` correlation from Fisher matrices.

    Parameters
    ----------
    fisher : numpy.ndarray
        Shape S + (P, P).
    names : list of str
    priors : Priors, optional
        For the prior precision (:func:`prior_precision`).
    use_prior : bool
        Add the prior precision (otherwise a singular ``F`` gives infinite sd).

    Returns
    -------
    sd : numpy.ndarray
        Shape S + (P,): sd of ``a`` [-] and of each ``log tau`` (relative sd of ``tau``).
    corr : numpy.ndarray
        Shape S: correlation of ``a`` and ``log tau_1`` (NaN without a finite film).
    """
    matrix = fisher + (prior_precision(names, priors) if use_prior else 0.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        try:
            cov = np.linalg.inv(matrix)
        except np.linalg.LinAlgError:
            cov = np.linalg.pinv(matrix)
            cov[np.linalg.matrix_rank(matrix) < matrix.shape[-1]] = np.inf
        diag = np.diagonal(cov, axis1=-2, axis2=-1)
        sd = np.sqrt(np.where(diag > 0, diag, np.inf))
        if len(names) > 1:
            corr = cov[..., 0, 1] / (sd[..., 0] * sd[..., 1])
        else:
            corr = np.full(sd.shape[:-1], np.nan)
    return sd, corr


# ---------------------------------------------------------------------------------------------
# prior over the pigment


@dataclass(frozen=True)
class DesignPrior:
    """What the user knows about the pigment before making samples.

    Attributes
    ----------
    a : (low, high) or array_like
        Range of ``a`` [-] (log-uniform draws, independently per band) or a rough spectrum
        (one value per band; draws scatter it by ``spread``).
    tau_per_um : (low, high) or array_like
        Range or rough spectrum of the optical thickness of a 1 um film [1/um].
    wavelengths : array_like
        Bands [nm] (default 400, 410, ..., 700: 31 bands).
    spread : float
        Relative (log-normal) scatter of a rough spectrum [-].
    """

    a: object = (0.01, 0.3)
    tau_per_um: object = (0.02, 0.2)
    wavelengths: object = tuple(np.arange(400.0, 701.0, 10.0))
    spread: float = 0.3

    def __post_init__(self):
        wl = np.asarray(self.wavelengths, float)
        if wl.ndim != 1 or wl.size == 0 or not np.isfinite(wl).all():
            raise ValueError("DesignPrior.wavelengths must be a non-empty 1-D array of numbers [nm]")
        for name, upper in (("a", 1.0), ("tau_per_um", np.inf)):
            value = np.asarray(getattr(self, name), float)
            if value.shape == (2,) and wl.size != 2:
                if not (0 < value[0] < value[1] <= upper):
                    raise ValueError(f"DesignPrior.{name} range must satisfy 0 < low < high <= {upper:g}, "
                                     f"got {tuple(value)}")
            elif value.shape != wl.shape:
                raise ValueError(f"DesignPrior.{name} must be a (low, high) range or one value per band "
                                 f"({wl.size}), got shape {value.shape}")
            elif not ((value > 0) & (value <= upper)).all():
                raise ValueError(f"DesignPrior.{name} spectrum must lie in (0, {upper:g}]")
        if not (np.isfinite(self.spread) and self.spread >= 0):
            raise ValueError(f"DesignPrior.spread must be >= 0, got {self.spread!r}")

    @property
    def n_bands(self):
        """Number of wavelength bands."""
        return len(np.asarray(self.wavelengths))

    def _draw(self, name, n_draws, rng, upper):
        value = np.asarray(getattr(self, name), float)
        shape = (n_draws, self.n_bands)
        if value.shape == (2,) and self.n_bands != 2:
            return np.exp(rng.uniform(np.log(value[0]), np.log(value[1]), shape))
        return np.minimum(value * np.exp(self.spread * rng.standard_normal(shape)), upper)

    def draw(self, n_draws, rng):
        """``a`` and ``tau_per_um`` draws, each shape (n_draws, n_bands).

        Parameters
        ----------
        n_draws : int
        rng : numpy.random.Generator
        """
        return self._draw("a", n_draws, rng, 0.999), self._draw("tau_per_um", n_draws, rng, np.inf)

    def to_json(self):
        """JSON-ready dict."""
        return {k: np.asarray(v, float).tolist() if not isinstance(v, float) else v
                for k, v in dataclasses.asdict(self).items()}


# ---------------------------------------------------------------------------------------------
# ranking


@dataclass
class DesignResult:
    """Ranked candidates with their predicted precision.

    Attributes
    ----------
    candidates : list of Candidate
        In rank order (best first).
    score : numpy.ndarray
        The ranking score per candidate (lower is better).
    rel_sd_a, sd_log_tau : numpy.ndarray
        Shape (n_candidates, n_draws, n_bands): predicted ``sd(a)/a`` and ``sd(log tau)``
        (``tau`` relative sd; of the best-determined film group).
    corr : numpy.ndarray
        Same shape: correlation of ``a`` and ``log tau`` of that group.
    a, tau_per_um : numpy.ndarray
        The prior draws, shape (n_draws, n_bands).
    settings : dict
        Everything needed to rerun (seed, eps, prior, objective, versions).
    checks : list of dict
        Full-posterior checks (:func:`check_designs`), if run.
    """

    candidates: list
    score: np.ndarray
    rel_sd_a: np.ndarray
    sd_log_tau: np.ndarray
    corr: np.ndarray
    a: np.ndarray
    tau_per_um: np.ndarray
    settings: dict
    checks: list = dataclasses.field(default_factory=list)

    def identified(self, k):
        """Where the Gaussian approximation is trusted for candidate ``k`` (shape (n_draws, n_bands)).

        ``sd(log tau)`` below a quarter of the prior box's sd and ``|corr(a, log tau)| < 0.99``;
        elsewhere (a ravine, a nearly opaque film) the posterior is wider or non-Gaussian.
        """
        limit = 0.25 * self.settings["prior_sd_log_tau"]
        return (self.sd_log_tau[k] < limit) & ~(np.abs(self.corr[k]) >= 0.99)

    def summary(self):
        """Per candidate (rank order): name, description, score, mean and 90 % quantile of the sds."""
        rows = []
        for k, c in enumerate(self.candidates):
            rows.append({
                "rank": k + 1, "name": c.name, "description": c.describe(), "n_films": len(c.films),
                "instrument": c.instrument, "score": float(self.score[k]),
                "mean_rel_sd_a": float(np.mean(self.rel_sd_a[k])),
                "q90_rel_sd_a": float(np.quantile(self.rel_sd_a[k], 0.9)),
                "mean_rel_sd_tau": float(np.mean(self.sd_log_tau[k])),
                "q90_rel_sd_tau": float(np.quantile(self.sd_log_tau[k], 0.9)),
                "median_abs_corr": (float(np.nanmedian(np.abs(self.corr[k])))
                                    if np.isfinite(self.corr[k]).any() else None),
                "fraction_identified": float(np.mean(self.identified(k))),
            })
        return rows


def _versions():
    """The versions a design or comparison record names."""
    return package_versions(("bayespig", "numpy", "scipy"), python=True)


def rank_designs(candidates, prior=None, *, eps=0.05, n_draws=32, seed=0, objective="both",
                 tau_link="groups", priors=None, n=1.45, tables=None):
    """Rank candidate sample sets by their expected posterior precision over the prior.

    Parameters
    ----------
    candidates : sequence of Candidate
    prior : DesignPrior, optional
        What is known of ``a`` and ``tau`` per um (default :class:`DesignPrior`).
    eps : float
        Relative error of eq. (7) [-].
    n_draws : int
        Prior draws per band (the same draws for every candidate).
    seed : int
        Seed of the ``numpy.random.default_rng`` of the draws.
    objective : {"both", "a", "tau"}
        Score = mean over draws and bands of ``sd(a)/a``, of ``sd(log tau)``, or their mean.
    tau_link : {"groups", "proportional"}
        See :func:`fisher_information`.
    priors : Priors, optional
        Box of the inference (its precision regularises the Fisher matrix).
    n : float
        Binder index [-].
    tables : dict, optional
        Instrument -> look-up table.

    Returns
    -------
    DesignResult
    """
    candidates = list(candidates)
    if not candidates or not all(isinstance(c, Candidate) for c in candidates):
        raise ValueError("candidates must be a non-empty list of Candidate")
    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
    if not isinstance(n_draws, (int, np.integer)) or n_draws < 1:
        raise ValueError(f"n_draws must be a positive integer, got {n_draws!r}")
    eps = _check_eps(eps)
    prior = DesignPrior() if prior is None else prior
    started = time.perf_counter()
    rng = np.random.default_rng(seed)
    a, tau = prior.draw(int(n_draws), rng)
    responses = _Responses(a, tau, eps, n, {} if tables is None else tables)
    shape = (len(candidates),) + a.shape
    rel_sd_a, sd_tau, corr = np.empty(shape), np.empty(shape), np.empty(shape)
    for k, c in enumerate(candidates):
        fisher, names = _assemble(c.films, c.instrument, responses, tau_link)
        sd, cor = posterior_sd(fisher, names, priors)
        rel_sd_a[k] = sd[..., 0] / a
        if len(names) > 1:
            best = np.argmin(sd[..., 1:], axis=-1)
            sd_tau[k] = np.take_along_axis(sd[..., 1:], best[..., None], -1)[..., 0]
            # correlation of a with that group's log tau
            corr[k] = cor if len(names) == 2 else _group_corr(fisher, names, priors, best)
        else:  # opaque films only: tau stays at the prior's width
            sd_tau[k] = np.sqrt(1.0 / prior_precision(["a", "t"], priors)[1, 1])
            corr[k] = np.nan
    mean_a, mean_t = rel_sd_a.mean(axis=(1, 2)), sd_tau.mean(axis=(1, 2))
    score = {"a": mean_a, "tau": mean_t, "both": 0.5 * (mean_a + mean_t)}[objective]
    order = np.argsort(score, kind="stable")
    settings = {"eps": eps, "n_draws": int(n_draws), "seed": int(seed), "objective": objective,
                "tau_link": tau_link, "n": n, "prior": prior.to_json(),
                "inference_priors": (priors or Priors()).describe(), "versions": _versions(),
                "n_candidates": len(candidates),
                "prior_sd_log_tau": float(1.0 / np.sqrt(prior_precision(["a", "t"], priors)[1, 1])), "wall_time_s": time.perf_counter() - started,
                "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")}
    return DesignResult([candidates[i] for i in order], score[order], rel_sd_a[order], sd_tau[order],
                        corr[order], a, tau, settings)


def _group_corr(fisher, names, priors, best):
    matrix = fisher + prior_precision(names, priors)
    cov = np.linalg.inv(matrix)
    idx = 1 + best
    c_at = np.take_along_axis(cov[..., 0, :], idx[..., None], -1)[..., 0]
    c_tt = np.take_along_axis(np.diagonal(cov, axis1=-2, axis2=-1), idx[..., None], -1)[..., 0]
    return c_at / np.sqrt(cov[..., 0, 0] * c_tt)


# ---------------------------------------------------------------------------------------------
# full-posterior checks


def check_designs(result, *, top=3, bands=(0, None), draw=0, seed=0, settings=None, tables=None,
                  progress=False, extra=()):
    """Check the Fisher prediction of the top candidates against full posteriors on simulated data.

    For each checked candidate a measurement set is simulated (:func:`bayespig.simulate`, the
    exact solver, noise of eq. 7) at one prior draw and a few bands, :func:`bayespig.infer`
    samples its posterior (``method="general"``: every film), and the posterior sd of ``a``
    and of ``log tau`` (first film group) is compared with the Fisher prediction at the truth.

    Parameters
    ----------
    result : DesignResult
    top : int
        How many of the best candidates to check.
    bands : sequence of int or None
        Band indices to check (None: the last band).
    draw : int
        Which prior draw is the simulated pigment.
    seed : int
    settings : InferenceSettings, optional
    tables : dict, optional
    progress : bool
    extra : sequence of Candidate
        More candidates to check (e.g. a poor one).

    Returns
    -------
    list of dict
        Per candidate and band: truth, Fisher sd, posterior sd, their ratios, and a flag
        ``well_identified`` (ratio within 1.5 and no pile-up at the prior's bounds).
    """
    from ..data.simulate import simulate
    from ..inference import infer

    bands = [b if b is not None else result.a.shape[1] - 1 for b in bands]
    wl = np.asarray(result.settings["prior"]["wavelengths"], float)
    eps = result.settings["eps"]
    out = []
    for cand in list(result.candidates[:top]) + list(extra):
        a_true = result.a[draw, bands]
        tau_true = result.tau_per_um[draw, bands]
        ms = simulate(a=a_true, tau=tau_true, design=list(cand.films), instrument=cand.instrument,
                      wavelengths=wl[bands], eps=eps, seed=seed)
        idata = infer(ms, method="general", seed=seed, eps=eps, progress=progress, settings=settings,
                      executor=None)
        fisher, names = fisher_information(cand, a=a_true, tau=tau_true, eps=eps,
                                           tau_link=result.settings["tau_link"], tables=tables)
        sd, corr = posterior_sd(fisher, names)
        post = idata.posterior
        for j, b in enumerate(bands):
            a_draws = post["a"].values[:, :, j].ravel()
            row = {"candidate": cand.name, "wavelength_nm": float(wl[b]), "a_true": float(a_true[j]),
                   "tau_per_um_true": float(tau_true[j]), "fisher_sd_a": float(sd[j, 0]),
                   "posterior_sd_a": float(a_draws.std())}
            row["ratio_a"] = row["posterior_sd_a"] / row["fisher_sd_a"]
            if "tau" in post:
                lt = np.log(post["tau"].values[:, :, j].ravel())
                row["fisher_sd_log_tau"] = float(sd[j, 1])
                row["posterior_sd_log_tau"] = float(lt.std())
                row["ratio_tau"] = row["posterior_sd_log_tau"] / row["fisher_sd_log_tau"]
                row["posterior_corr"] = float(np.corrcoef(a_draws, lt)[0, 1])
                row["fisher_corr"] = float(corr[j])
            ratios = [row[k] for k in ("ratio_a", "ratio_tau") if k in row]
            row["well_identified"] = bool(all(1 / 1.5 <= r <= 1.5 for r in ratios))
            out.append(row)
    result.checks = out
    return out


# ---------------------------------------------------------------------------------------------
# report


#: Candidates shown in the design figure (the best ones).
FIGURE_CANDIDATES = 12


def _figure_png(result, n_show=FIGURE_CANDIDATES):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    k = min(n_show, len(result.candidates))
    fig = Figure(figsize=(9, 0.45 * k + 1.6), layout="constrained")
    ax = fig.subplots()
    y = np.arange(k)[::-1]
    for data, offset, label, color in ((result.rel_sd_a, -0.18, "sd(a)/a", "C0"),
                                       (result.sd_log_tau, 0.18, "sd(tau)/tau", "C1")):
        lo, mid, hi = np.quantile(data[:k].reshape(k, -1), [0.1, 0.5, 0.9], axis=1)
        ax.errorbar(mid, y + offset, xerr=[mid - lo, hi - mid], fmt="o", color=color, label=label, capsize=2)
    ax.set_yticks(y, [c.name for c in result.candidates[:k]], fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("predicted relative posterior sd (median, 10–90 % over the prior)")
    fig.legend(loc="outside upper center", ncols=2)
    ax.grid(alpha=0.3)
    FigureCanvasAgg(fig)  # the Agg canvas, whatever pyplot's backend is
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    return buffer.getvalue()


def write_design_report(result, out_dir, *, n_rows=20, command=None):
    """Write ``design.html``, ``design.md``, ``design.json`` and ``figures/design.png`` atomically.

    Parameters
    ----------
    result : DesignResult
    out_dir : path
        Created if missing.
    n_rows : int
        Candidates listed in the tables.
    command : str, optional
        The command that regenerates the report (stated at its top).

    Returns
    -------
    dict
        Role -> path.
    """
    from ..report import document as doc

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = result.summary()
    best = rows[0]
    s = result.settings
    blocks = [
        doc.heading("Sample design", 1),
        doc.paragraph(
            f"Make: {best['description']}. Expected relative posterior sd over the prior: a "
            f"{100 * best['mean_rel_sd_a']:.2g} % (90 % of draws below {100 * best['q90_rel_sd_a']:.2g} %), "
            f"tau {100 * best['mean_rel_sd_tau']:.2g} % (90 % below {100 * best['q90_rel_sd_tau']:.2g} %)."),
        doc.paragraph(
            f"{len(rows)} candidate sample sets scored by the Fisher information of the noise model of "
            f"eq. (7) (eps = {s['eps']:g}), F = J^T diag((1/eps^2 + 2)/m^2) J, with the prior box's "
            f"precision added; averaged over {s['n_draws']} prior draws x {result.a.shape[1]} bands "
            f"(seed {s['seed']}); objective '{s['objective']}' (lower is better). "
            "This is the Gaussian (Laplace) approximation: it is reliable where the posterior is well "
            "identified and optimistic in ravines (a thin film on one substrate) and for nearly opaque "
            "films, where the full-posterior checks below are the answer. Column 'identified': the share "
            "of prior draws where the approximation is trusted (sd(log tau) below a quarter of the prior's, "
            "|corr(a, log tau)| < 0.99)."),
        doc.heading("Ranking"),
        doc.paragraph(f"The best {min(n_rows, len(rows))} of {len(rows)} candidate sample sets"
                      + (f" (all {len(rows)} in design.json)." if len(rows) > n_rows else ".")),
        doc.table(["rank", "candidate", "films", "n films", "score", "sd(a)/a mean", "sd(a)/a q90", "sd(tau)/tau mean",
                   "sd(tau)/tau q90", "|corr| median", "identified"],
                  [[r["rank"], r["name"], r["description"], r["n_films"], f"{r['score']:.3g}", f"{r['mean_rel_sd_a']:.3g}",
                    f"{r['q90_rel_sd_a']:.3g}", f"{r['mean_rel_sd_tau']:.3g}", f"{r['q90_rel_sd_tau']:.3g}",
                    "-" if r["median_abs_corr"] is None else f"{r['median_abs_corr']:.2f}",
                    f"{100 * r['fraction_identified']:.0f} %"] for r in rows[:n_rows]]),
        doc.figure("design", f"Predicted relative posterior sd of a and tau of the best "
                             f"{min(FIGURE_CANDIDATES, len(result.candidates))} of {len(result.candidates)} "
                             "candidates."),
    ]
    if result.checks:
        blocks += [doc.heading("Full-posterior checks"),
                   doc.paragraph("Posterior sd from bayespig.infer on simulated data vs the Fisher prediction "
                                 "at the truth; 'well identified' = both ratios within a factor 1.5."),
                   doc.table(["candidate", "nm", "a", "tau/um", "sd a Fisher", "sd a posterior",
                              "sd log tau Fisher", "sd log tau posterior", "well identified"],
                             [[c["candidate"], f"{c['wavelength_nm']:g}", f"{c['a_true']:.3g}",
                               f"{c['tau_per_um_true']:.3g}", f"{c['fisher_sd_a']:.3g}",
                               f"{c['posterior_sd_a']:.3g}", f"{c.get('fisher_sd_log_tau', np.nan):.3g}",
                               f"{c.get('posterior_sd_log_tau', np.nan):.3g}",
                               "yes" if c["well_identified"] else "NO (ravine/opaque: trust the posterior)"]
                              for c in result.checks])]
    if command:
        blocks[1:1] = [doc.paragraph("Generated by this command; rerun it to regenerate:"),
                       doc.preformatted(command)]
    blocks += [doc.heading("Settings"), doc.preformatted(json.dumps(s, indent=1, default=str))]
    payload = {"command": command, "settings": s, "ranking": rows,
               "candidates": [c.to_json() for c in result.candidates], "checks": result.checks}
    figures = {"design": _figure_png(result)}
    return _write_bundle(out_dir, "design", blocks, figures, payload, "bayespig sample design")


def _write_bundle(out_dir, stem, blocks, figures, payload, title):
    """Write ``<stem>.html/.md/.json`` and ``figures/*.png`` via a temporary directory and ``os.replace``."""
    from ..report import document as doc

    contents = {f"figures/{name}.png": png for name, png in figures.items()}
    contents[f"{stem}.json"] = json.dumps(_jsonable(payload), indent=1, allow_nan=True) + "\n"
    contents[f"{stem}.md"] = doc.to_markdown(blocks)
    contents[f"{stem}.html"] = doc.to_html(blocks, figures, title)
    written = write_file_set(out_dir, contents)
    files = {"figures": [written[f"figures/{name}.png"] for name in figures]}
    for role, suffix in (("json", "json"), ("markdown", "md"), ("html", "html")):
        files[role] = written[f"{stem}.{suffix}"]
    return files
