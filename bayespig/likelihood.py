"""Likelihoods: the paper's multiplicative noise model with an additive floor, over any set of samples, and priors.

Every measured value is ``x_obs = x_true (1 + eps xi)``, ``xi ~ N(0, 1)`` (paper eq. 7),
so the exact likelihood of one value is ``N(x_obs | x_model, (eps x_model)^2)``:

    log L = -1/2 ((x_obs - x_model) / (eps x_model))^2 - log(eps x_model) - 1/2 log(2 pi)

Real instruments (gonioreflectometers above all) also have an additive noise floor: a
reading of a dark direction is ``x_obs = x_true (1 + eps xi) + sigma0 zeta`` with ``zeta ~
N(0, 1)`` independent of ``xi`` (detector and stray-light noise that does not scale with the
signal). The sum of two independent zero-mean Gaussians is Gaussian with the summed
variances, so

    x_obs ~ N(x_model, sigma^2),   sigma^2 = (eps x_model)^2 + sigma0^2,
    log L = -1/2 (x_obs - x_model)^2 / sigma^2 - 1/2 log(sigma^2) - 1/2 log(2 pi)

(:func:`multiplicative_normal_logpdf`). ``sigma0`` (the *noise floor*) is in the units of
the value: 1/sr for a BRDF, a fraction for hemispherical reflectances, 45°/0° reflectance
factors and transmittances. At ``sigma0 = 0`` this is eq. (7) exactly (``hypot(x, 0) = |x|``
in floating point). With ``sigma0 > 0`` an observed zero, or a value far below the model,
has a finite likelihood: zeros and near-zero readings are data. Observed values must then be
``>= 0`` (bayespig's measurement model refuses negative readings, and an instrument that
clips its readings at 0 reports exact zeros, which the Gaussian density at 0 describes to
within the floor); without a floor they must be ``> 0`` (eq. 7 gives an observed 0 the
likelihood 0 for any model value). NaN and infinite values are refused either way
(:func:`check_observed`, naming film, value and band). The model value must be ``> 0``.

Censored zeros
--------------
An instrument that clips its readings at 0 reports ``max(x, 0)``: an exact 0 then says only
``x <= 0``, whose probability is ``Phi(-x_model / sigma)`` (:func:`censored_zero_logpdf`; Tobit's
censored normal model). With ``censored_zeros=True`` (needs a floor) every observed value of
exactly 0 enters with that probability instead of the Gaussian density at 0; the positive
readings keep their density. The density at 0 is not the probability of a 0: it carries a
factor ``1 / sigma``, so many zeros fitted by a model value near 0 pull the floor towards its
prior's lower edge, and it makes readings below a clipped model value indistinguishable.

A :class:`Problem` is what a measurement set says about one pigment: for every film
its instrument, substrate albedo ``r_s(λ)``, whether it is opaque, which films
share ``tau`` (film groups), and the observed values. The paper's methods 1–4
(section 3) are subsets of samples; the general case is all of them. Parameters
per wavelength are ``a`` (pigment), one ``tau`` per film group, optionally ``g``
(pigment), ``eps`` and the noise floor (each shared by the samples of that wavelength).
"""

from __future__ import annotations

import numbers
import os
from dataclasses import dataclass, field

import numpy as np
from scipy.special import log_ndtr

from ._validation import broadcast, flag, real_array
from .instruments import Instrument
from .physics.forward import specular_transmittance, surface_roughness
from .rough_table import FixedRoughnessTable, load_binder_index_tables, load_rough_table
from .table import load_table

__all__ = [
    "METHODS",
    "FilmTerm",
    "ForwardModel",
    "LogPosterior",
    "Priors",
    "Problem",
    "WavelengthModel",
    "censored_zero_logpdf",
    "censored_zeros_argument",
    "check_observed",
    "method_name",
    "multiplicative_normal_logpdf",
    "noise_floor_argument",
    "noise_sd",
]

#: The paper's methods, in the order ``method="auto"`` prefers them (paper section 4.2:
#: method 4 is the most robust, then method 1).
METHODS = ("method4", "method1", "method2", "method3")
#: What a method may be called wherever one is asked for: the paper's number or its name.
PAPER_METHOD_SPELLINGS = {**{str(k): f"method{k}" for k in range(1, 5)},
                          **{f"method{k}": f"method{k}" for k in range(1, 5)}}
_LOG_2PI = np.log(2.0 * np.pi)


def method_name(method, *, also=("auto", "general"), argument="method"):
    """The canonical name of a method, whichever way it is spelled.

    ``4``, ``"4"`` and ``"method4"`` all mean the paper's method 4 (section 3); every entry
    point (the Python API and the command line) goes through this function.

    Parameters
    ----------
    method : int or str
        1..4, ``"1"``..``"4"``, ``"method1"``..``"method4"``, or one of ``also``.
    also : tuple of str
        Names accepted besides the paper's methods (default ``"auto"`` and ``"general"``;
        ``()`` where only the paper's methods make sense).
    argument : str
        Name of the argument, for the error message.

    Returns
    -------
    str
        ``"method1"`` .. ``"method4"`` or the member of ``also``.

    Raises
    ------
    TypeError
        When ``method`` is neither an integer nor a string (``True`` is not a method).
    ValueError
        For an unknown method, listing the valid ones.
    """
    valid = ", ".join([*PAPER_METHOD_SPELLINGS, *also])
    if isinstance(method, (bool, np.bool_)) or not isinstance(method, (int, np.integer, str)):
        raise TypeError(f"{argument} must be a method number or name ({valid}), "
                        f"got {type(method).__name__} {method!r}")
    key = str(int(method)) if isinstance(method, (int, np.integer)) else method.strip()
    if key in also:
        return key
    if key not in PAPER_METHOD_SPELLINGS:
        raise ValueError(f"unknown method {method!r}: {argument} must be one of {valid}")
    return PAPER_METHOD_SPELLINGS[key]


def noise_sd(model, eps, noise_floor=0.0):
    """Standard deviation of a measured value: ``sqrt((eps model)^2 + noise_floor^2)``.

    Parameters
    ----------
    model : array_like
        Noise-free predicted values (units of the measurement: 1/sr for BRDF, a fraction
        for reflectances and transmittances).
    eps : array_like
        Relative measurement error of eq. (7) [-].
    noise_floor : array_like
        Additive noise floor ``sigma0`` [units of the values]; 0 gives ``eps * model``
        exactly.

    Returns
    -------
    numpy.ndarray
        Broadcast.
    """
    return np.hypot(np.multiply(eps, model), noise_floor)


def multiplicative_normal_logpdf(observed, model, eps, noise_floor=0.0):
    """Log-density of the paper's noise model (eq. 7), with an optional additive floor, per value.

    ``log N(observed | model, sigma^2)`` with ``sigma^2 = (eps model)^2 + noise_floor^2``
    (see the module docstring for the derivation); ``noise_floor = 0`` is eq. (7) exactly.

    Parameters
    ----------
    observed, model : array_like
        Measured and predicted values (same units; ``model > 0``).
    eps : array_like
        Relative measurement error [-].
    noise_floor : array_like
        Additive noise floor ``sigma0`` in the units of the values (1/sr for a BRDF, a
        fraction for hemispherical values) [default 0].

    Returns
    -------
    numpy.ndarray
        ``log N(observed | model, (eps model)^2 + noise_floor^2)``, broadcast.

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), eq. (7).
    """
    try:
        sigma = noise_sd(model, eps, noise_floor)
        return -0.5 * ((observed - model) / sigma) ** 2 - np.log(sigma) - 0.5 * _LOG_2PI
    except (TypeError, ValueError):  # checked only on failure: this runs in the sampler's loop
        checked = {name: real_array(name, value) for name, value in
                   (("observed", observed), ("model", model), ("eps", eps), ("noise_floor", noise_floor))}
        broadcast(**checked)
        raise


def censored_zero_logpdf(mean, variance):
    """Log-probability that a reading clipped at 0 is exactly 0: ``log Phi(-mean / sigma)``.

    An instrument that reports ``max(x, 0)`` of a Gaussian reading ``x ~ N(mean, sigma^2)``
    (``sigma^2 = (eps f)^2 + sigma0^2``, the module docstring) records an exact 0 with
    probability ``P(x <= 0) = Phi(-mean / sigma)``: the reading is *censored* at 0 (Tobit's
    model), and that probability, not the density at 0, is its likelihood. Unlike the density
    it has no ``1 / sigma`` factor, so a set with many zeros does not pull the floor to 0, and
    it keeps falling as the mean rises above 0 and tends to 1 as the mean falls below it
    (the Gaussian density of a clipped mean is flat there).

    Parameters
    ----------
    mean : array_like
        Mean of the reading before clipping [units of the values]; any sign.
    variance : array_like
        Its variance ``sigma^2 > 0`` [units squared].

    Returns
    -------
    numpy.ndarray
        ``log Phi(-mean / sqrt(variance))``, broadcast; accurate far in the tail
        (:func:`scipy.special.log_ndtr`).
    """
    return log_ndtr(-np.asarray(mean, dtype=float) / np.sqrt(variance))


def censored_zeros_argument(censored_zeros, noise_floor, name="censored_zeros"):
    """``censored_zeros`` checked: a bool, True only with a noise floor (``noise_floor`` checked).

    Raises
    ------
    TypeError, ValueError
        Naming ``name``.
    """
    censored_zeros = flag(name, censored_zeros)
    if censored_zeros and noise_floor is None:
        raise ValueError(f"{name}=True needs a noise floor (noise_floor a number > 0 or 'infer'): without one "
                         "eq. (7) gives a reading of 0 no probability")
    return censored_zeros


def noise_floor_argument(noise_floor, name="noise_floor"):
    """``noise_floor`` checked: None (no floor), a finite number >= 0, or ``"infer"``.

    Returns
    -------
    None, float or "infer"
        None for no floor (None or 0: the multiplicative model of eq. 7), the known floor
        ``sigma0 > 0`` [units of the values], or ``"infer"``.

    Raises
    ------
    TypeError, ValueError
        Naming ``name``, for anything else.
    """
    expected = ("None (no floor), a number >= 0 (the additive noise floor in the units of the values, "
                "e.g. 0.001 for 0.001 1/sr) or 'infer'")
    if noise_floor is None:
        return None
    if isinstance(noise_floor, str):
        if noise_floor != "infer":
            raise ValueError(f"{name} must be {expected}, got {noise_floor!r}")
        return "infer"
    if isinstance(noise_floor, (bool, np.bool_)) or not isinstance(noise_floor, numbers.Real):
        raise TypeError(f"{name} must be {expected}, got {type(noise_floor).__name__} {noise_floor!r}")
    value = float(noise_floor)
    if not (np.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be {expected}, got {noise_floor!r}")
    return value if value > 0 else None


def _value_names(film):
    """Geometry label of every value of a film (its instrument's channels)."""
    if film.kind == "transmittance" or film.instrument is None:
        return ["specular transmittance"] * film.observed.shape[1]
    return list(film.instrument.labels)


def check_observed(problem, noise_floor=None):
    """Refuse observed values the noise model cannot take, naming film, value and band.

    NaN and infinite values are always refused; without a noise floor every value must be
    ``> 0`` (eq. 7 gives an observed 0 zero likelihood), with a floor (known or inferred)
    ``>= 0`` (see the module docstring).

    Parameters
    ----------
    problem : Problem
    noise_floor : None, float or "infer"
        As from :func:`noise_floor_argument`.

    Raises
    ------
    ValueError
        For the first offending value: ``film 'x': observed value 0 at 450 nm, geometry
        30as20 (value 3 of 12) ...``.
    """
    wavelength = np.asarray(problem.wavelength_nm, dtype=float)
    floor = noise_floor is not None
    for film in problem.films:
        observed = np.asarray(film.observed, dtype=float)
        bad_finite = ~np.isfinite(observed)
        bad = bad_finite | ((observed < 0) if floor else (observed <= 0))
        if not bad.any():
            continue
        row, column = (int(v[0]) for v in np.nonzero(bad))
        value = observed[row, column]
        count = int(bad.sum())
        source = film.sources[column] if film.sources is not None else None
        read_from = f"{source[0]}, row {source[1]}: " if source else ""
        where = (f"{read_from}film {film.name!r}: observed value {value:g} at {wavelength[row]:g} nm, geometry "
                 f"{_value_names(film)[column]} (value {column + 1} of {observed.shape[1]})")
        more = f"; {count - 1} more value{'s' if count > 2 else ''} of this film as well" if count > 1 else ""
        if bad_finite[row, column]:
            raise ValueError(f"{where} is not a finite number{more}")
        if floor:
            raise ValueError(f"{where} is negative; measured values must be >= 0{more}")
        raise ValueError(f"{where} must be > 0 without a noise floor (eq. 7 gives a zero reading zero "
                         f"likelihood){more}; give noise_floor=<number> or 'infer' "
                         "(--noise-floor on the command line) to take zeros as data")


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
    sources : tuple or None
        Per value (column of ``observed``): the ``(file, line)`` it was read from, or None;
        for messages only.
    """

    name: str
    kind: str
    instrument: Instrument | None
    group: str | None
    r_s: np.ndarray
    observed: np.ndarray
    eps: float | None = None
    sources: tuple | None = field(default=None, compare=False, repr=False)

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
        if not callable(getattr(measurements, "supported_methods", None)):
            hint = " (read a file with bayespig.read_measurements first)" if isinstance(measurements, (str, os.PathLike)) else ""
            raise TypeError(
                "measurements must be a bayespig MeasurementSet, got "
                f"{measurements!r} ({type(measurements).__name__}){hint}"
            )
        if method == "auto":
            supported = measurements.supported_methods()
            method = next((m for m in METHODS if supported[m]), "general")
        if method == "general":
            subset = measurements
        elif isinstance(method, str) and method in METHODS:
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
                                      subset.substrate_albedo(sample), sample.reflectance, sample.eps,
                                      tuple(m.source for m in sample.reflectance_measurements)))
            if sample.transmittance is not None:
                films.append(FilmTerm(sample.name + ":transmittance", "transmittance", None, group,
                                      np.zeros(subset.n_wavelengths), sample.transmittance.values[:, None],
                                      sample.eps, (sample.transmittance.source,)))
        if not films:
            raise ValueError("the measurement set has no films to fit")
        return cls(np.asarray(subset.wavelength_nm, float), tuple(films), tuple(groups), subset.n, method)


@dataclass(frozen=True)
class Priors:
    """Prior ranges (stated in every report).

    ``a`` uniform on ``a_range``; each ``tau`` log-uniform on ``tau_range``; ``g``
    uniform on ``g_range`` when free; ``eps`` log-uniform on ``eps_range`` when inferred;
    the additive noise floor ``sigma0`` log-uniform on ``noise_floor_range`` when inferred
    (in the units of the values: 1/sr for BRDF, a fraction for hemispherical values; the
    default 1e-6 .. 1 spans a floor far below any paint's BRDF to one above the brightest
    diffuse body, ~0.3 1/sr); the reflectance ``c`` of effect-pigment flakes per band
    log-uniform on ``flake_reflectance_range`` when the films have flakes
    (:func:`bayespig.physics.forward.flake_brdf`; 1e-5 .. 1: from a lobe far below the noise
    floor of any gonio reading to flakes that return all the light reaching them). In the
    sampled coordinates ``[a, log tau, g, log eps, log sigma0]`` (and ``log c``) every prior is
    flat on a box.

    Raises
    ------
    ValueError
        Naming the range that is empty or outside the parameter's domain.
    """

    a_range: tuple = (0.0, 1.0)
    tau_range: tuple = (0.01, 100.0)
    g_range: tuple = (-0.5, 0.8)
    eps_range: tuple = (1e-3, 0.5)
    noise_floor_range: tuple = (1e-6, 1.0)
    flake_reflectance_range: tuple = (1e-5, 1.0)

    def __post_init__(self):
        domains = {"a_range": (0.0, 1.0, True), "tau_range": (0.0, np.inf, False),
                   "g_range": (-1.0, 1.0, False), "eps_range": (0.0, np.inf, False),
                   "noise_floor_range": (0.0, np.inf, False), "flake_reflectance_range": (0.0, 1.0, True)}
        for name, (low, high, closed) in domains.items():
            try:
                lo, hi = (float(v) for v in getattr(self, name))
            except (TypeError, ValueError):
                raise ValueError(f"{name} must be a pair of numbers (low, high)") from None
            inside = (low <= lo and hi <= high) if closed else (low < lo and hi < high)
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi and inside):
                bracket = "[{}, {}]" if closed else "({}, {})"
                raise ValueError(f"{name} must satisfy low < high inside {bracket.format(low, high)}, "
                                 f"got {getattr(self, name)}")
        if not float(self.flake_reflectance_range[0]) > 0.0:  # log-uniform: its low end must be > 0
            raise ValueError(f"flake_reflectance_range must start above 0 (a log-uniform prior), "
                             f"got {self.flake_reflectance_range}")

    def describe(self):
        """One line per parameter, for reports."""
        return {
            "a": f"uniform on [{self.a_range[0]:g}, {self.a_range[1]:g}]",
            "tau": f"log-uniform on [{self.tau_range[0]:g}, {self.tau_range[1]:g}]",
            "g": f"uniform on [{self.g_range[0]:g}, {self.g_range[1]:g}] (when free)",
            "eps": f"log-uniform on [{self.eps_range[0]:g}, {self.eps_range[1]:g}] (when inferred)",
            "noise_floor": (f"log-uniform on [{self.noise_floor_range[0]:g}, {self.noise_floor_range[1]:g}] "
                            "in the units of the values (when inferred)"),
            "flake_reflectance": (f"log-uniform on [{self.flake_reflectance_range[0]:g}, "
                                  f"{self.flake_reflectance_range[1]:g}] (films with flakes)"),
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
    roughness : float
        GGX ``alpha`` of the films' top surface [-]. 0 (the default) is the smooth surface and
        the smooth tables, exactly as before. A value > 0 takes the rough-surface tables
        (:func:`bayespig.rough_table.load_rough_table`, opaque films and isotropic scattering
        only, the roughness in their range), held in ``tables`` under ``("rough",
        instrument)`` and, at this roughness, under the instrument
        (:class:`~bayespig.rough_table.FixedRoughnessTable`); :class:`WavelengthModel` then
        also takes a roughness per row.
    flakes : bool
        The films hold effect-pigment flakes: :class:`WavelengthModel` then adds ``c *``
        :func:`bayespig.physics.forward.flake_brdf` to every BRDF channel, with the flake
        reflectance ``c`` and the flakes' roughness per row (inputs ``flake_reflectance``,
        ``flake_roughness``). Needs ``roughness > 0`` (a gonio paint's surface) and BRDF or
        45°/0° channels only (the flakes' directional albedo for hemispherical channels is not
        tabulated).
    binder_index_free : bool
        Also load the rough tables at every binder-index node
        (:func:`bayespig.rough_table.load_binder_index_tables`, held in ``tables`` under
        ``("rough-n", instrument)``), so that :class:`WavelengthModel` takes a binder index per
        row as well (the index as a parameter, :mod:`bayespig.inference.roughness`). Needs
        ``roughness > 0``.
    """

    problem: Problem
    g: str = "isotropic"
    tables: dict = field(default_factory=dict)
    roughness: float = 0.0
    binder_index_free: bool = False
    flakes: bool = False

    def __post_init__(self):
        if self.g not in ("isotropic", "free"):
            raise ValueError(f"g must be 'isotropic' or 'free', got {self.g!r}")
        self.roughness = surface_roughness(self.roughness)
        if self.binder_index_free and not self.rough:
            raise ValueError("a binder index per row needs roughness > 0 (the look-up tables over n are those "
                             "of a rough surface)")
        if self.flakes:  # both checked before the tables are loaded (a build can take a minute)
            if not self.rough:
                raise ValueError("flakes need roughness > 0 (the flakes' lobe is modelled with the tables of a "
                                 "rough surface)")
            hemispherical = [film.name for film in self.problem.films
                             if any(ch.kind == "hemispherical" for ch in film.instrument.channels)]
            if hemispherical:
                raise ValueError(f"flakes are modelled for BRDF and 45/0 channels only; film(s) "
                                 f"{', '.join(map(repr, hemispherical))} have hemispherical channels")
        if self.rough:
            self._rough_tables()
            return
        self._film_tables = []
        for film in self.problem.films:
            if film.kind == "transmittance":
                self._film_tables.append(None)
                continue
            table = self.tables.get(film.instrument) or self.tables.get(film.instrument.name)
            if getattr(table, "roughness", 0.0):
                table = None  # a rough table at the instrument's key: not for the smooth model
            if table is None:
                table = load_table(film.instrument, g=self.g, n=self.problem.n, progress=False)
                self.tables[film.instrument] = table
            if table.free_g != (self.g == "free"):
                raise ValueError(f"tables: the table for {film.instrument.name!r} is "
                                 f"{'g-free' if table.free_g else 'isotropic'}, the model g={self.g!r}")
            self._film_tables.append(table)
        self.table_keys = tuple(sorted({t.key for t in self._film_tables if t is not None}))
        self._stencils = {}

    @property
    def table_checksums(self):
        """Key -> content checksum (SHA-256 of the tabulated arrays) of every table the films use,
        the binder-index families included: what saved results record next to
        :attr:`table_keys`, so that two runs can be told to have used the same numbers (the key
        says the settings were the same; tables rebuilt on another CPU may still differ in the
        last bits, and seeded chains with them)."""
        tables = [t for t in self._film_tables if t is not None]
        tables += list(getattr(self, "binder_index_tables", {}).values())
        return {t.key: t.checksum for t in sorted(tables, key=lambda t: t.key)}

    @property
    def rough(self):
        """Whether the films' surface is rough (``roughness > 0``: the rough-surface tables)."""
        return self.roughness > 0.0

    def _rough_tables(self):
        """The rough-surface tables of every film at :attr:`roughness` (opaque films only)."""
        if self.g != "isotropic":
            raise ValueError("roughness > 0 needs g='isotropic' (the look-up tables of a rough surface are "
                             "isotropic)")
        self._film_tables, self._rough = [], []
        self.binder_index_tables = {}  # rough table key -> BinderIndexRoughTables of its instrument
        for film in self.problem.films:
            if film.kind == "transmittance" or not film.opaque:
                raise ValueError(f"film {film.name!r} does not hide its substrate: roughness > 0 is available "
                                 "for opaque films only (the look-up tables of a rough surface have no tau "
                                 "axis yet); use roughness=0 for this set")
            rough = self.tables.get(("rough", film.instrument))
            if rough is None:
                rough = load_rough_table(film.instrument, n=self.problem.n, progress=False)
                self.tables[("rough", film.instrument)] = rough
            table = self.tables.get(film.instrument)
            if getattr(table, "roughness", None) != self.roughness or getattr(table, "rough", None) is not rough:
                table = FixedRoughnessTable(rough, self.roughness)
                self.tables[film.instrument] = table
            self._film_tables.append(table)
            self._rough.append(rough)
            if self.binder_index_free:
                family = self.tables.get(("rough-n", film.instrument))
                if family is None:
                    family = load_binder_index_tables(film.instrument, progress=False)
                    self.tables[("rough-n", film.instrument)] = family
                self.binder_index_tables[rough.key] = family
        self.table_keys = tuple(sorted({t.key for t in self._film_tables}))
        self._stencils = {}

    @property
    def roughness_range(self):
        """``(alpha_min, alpha_max)`` the rough tables of every film cover (None for a smooth model)."""
        if not self.rough:
            return None
        return (max(t.alpha_min for t in self._rough), min(t.alpha_max for t in self._rough))

    @property
    def binder_index_range(self):
        """``(n_min, n_max)`` the binder-index tables of every film cover (None unless
        ``binder_index_free``)."""
        if not (self.rough and self.binder_index_free):
            return None
        families = self.binder_index_tables.values()
        return (max(f.n_min for f in families), min(f.n_max for f in families))

    @property
    def film_tables(self):
        """The look-up table of every film (None for a transmittance), in film order."""
        return tuple(self._film_tables)

    def predict(self, index, a, tau, g=0.0):
        """Predicted values at wavelength ``index`` (through each table's own interpolation).

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

    def at_wavelength(self, index):
        """The fast evaluator of :meth:`predict` at one wavelength (see :class:`WavelengthModel`)."""
        return WavelengthModel(self, index)

    def _stencil_table(self, table):
        if table.key not in self._stencils:
            self._stencils[table.key] = _StencilTable(table)
        return self._stencils[table.key]


# ---------------------------------------------------------------------------------------------
# fast path: one wavelength; interpolation stencils shared by the films of one table and group


class _StencilTable:
    """A look-up table's interpolation, shared by the films of one table and film group.

    The table interpolates ``log q``, ``log D + log U`` and ``R_up`` from one stacked
    array with one stencil gather per call (:meth:`bayespig.table.LookupTable.interpolate`,
    the code path of the table itself, so the fast path follows every axis transform and
    stencil of :class:`~bayespig.table.TableSettings`); this wrapper splits the result and
    keeps what the likelihood needs per table (``tau_min``, the specular term).
    """

    def __init__(self, table):
        self.table = table
        self.n_channels = table.n_channels
        self.free_g = table.n_g > 1
        self.tau_min, self.tau_max = table.tau_min, table.tau_max
        # an opaque film of a = 1 reflects only what the table adds for specular-included channels
        self.specular = table(a=1.0, tau=np.inf)

    def interpolate_finite(self, a, tau, g):
        """``log q``, ``log D + log U`` (W, K each) and ``R_up`` (W,) at finite tau."""
        terms = self.table.interpolate(a, tau, g if self.free_g else None)
        k = self.n_channels
        return terms[:, :k], terms[:, k:2 * k], terms[:, 2 * k]

    def interpolate_opaque(self, a, g):
        """``log q`` of the opaque slice, (W, K)."""
        terms = self.table.interpolate(a, np.full(a.shape, np.inf), g if self.free_g else None)
        return terms[:, :self.n_channels]


def _stack_members(member, n_rows, n_stack):
    """Stack position of every row (checked); zeros for a single wavelength."""
    if member is None:
        if n_stack > 1:
            raise ValueError("a stack of wavelengths needs member= (the stack position of every row)")
        return np.zeros(n_rows, dtype=int)
    member = np.asarray(member)
    if member.shape != (n_rows,):
        raise ValueError(f"member must have shape ({n_rows},), got {member.shape}")
    return member


class WavelengthModel:
    """Fast predictions of every film at one wavelength (or a stack of them), equal to
    :meth:`ForwardModel.predict`.

    Everything that does not depend on the parameters is prepared once: the
    stacked table arrays, each film's substrate albedo ``r_s`` at these wavelengths
    and the films that share a table and a film group (the same film on black and
    on white, method 4), which share one interpolation. Values below the tables'
    first ``tau`` node (outside the default prior) go through the tables themselves.

    The tables do not depend on the wavelength, only ``r_s`` does, so the walkers of
    several wavelengths can be evaluated in one call (``member`` says which wavelength of
    the stack each row belongs to): one table interpolation serves them all, which is
    what makes sampling several wavelengths in one emcee run cheap.

    Parameters
    ----------
    model : ForwardModel
    index : int or sequence of int
        Wavelength index, or the indices of a stack of wavelengths.
    """

    def __init__(self, model, index):
        problem = model.problem
        indices = np.atleast_1d(np.asarray(index))
        if indices.ndim != 1 or indices.size == 0 or not np.issubdtype(indices.dtype, np.integer):
            raise ValueError(f"index must be an integer or a non-empty sequence of integers, got {index!r}")
        if ((indices < 0) | (indices >= problem.n_wavelengths)).any():
            raise ValueError(f"index must lie in [0, {problem.n_wavelengths}), got {index}")
        self.model = model
        self.indices = indices.astype(int)
        self.index = int(indices[0]) if np.ndim(index) == 0 else None
        self.n_values = problem.n_values
        self._units = {}
        self._rough_units = {}  # rough table key -> (RoughLookupTable, value slices of its films)
        self._film_of_part = {}  # first value index -> index among the reflectance films
        self._transmittance = []
        self._t_normal = float(specular_transmittance(0.0, problem.n))
        start = 0
        for film, table in zip(problem.films, model.film_tables):
            stop = start + film.observed.shape[1]
            column = -1 if film.opaque else problem.groups.index(film.group)
            if film.kind == "transmittance":
                self._transmittance.append((slice(start, stop), column))
            else:
                stencil = model._stencil_table(table)
                if model.rough:
                    self._rough_units.setdefault(table.rough.key, (table.rough, []))[1].append(
                        slice(start, stop))
                unit = self._units.setdefault((table.key, column), (stencil, column, []))
                unit[2].append((slice(start, stop), np.asarray(film.r_s, dtype=float)[self.indices]))
                self._film_of_part[start] = len(self._film_of_part)
            start = stop
        self._tau_min = min([u[0].tau_min for u in self._units.values() if u[1] >= 0], default=0.0)

    def __call__(self, a, tau, g=None, r_s_scale=None, member=None, roughness=None, binder_index=None,
                 flake_reflectance=None, flake_roughness=None):
        """Predicted values, shape (W, n_values).

        Parameters
        ----------
        a : numpy.ndarray
            Shape (W,) [-].
        tau : numpy.ndarray
            Shape (W, n_groups) [-], finite.
        g : numpy.ndarray, optional
            Shape (W,) [-]; None for 0 (isotropic).
        r_s_scale : numpy.ndarray, optional
            Shape (W, n_reflectance_films): factor on each reflectance film's substrate
            albedo, in problem film order (substrate albedo as a nuisance parameter, see
            :mod:`bayespig.inference.card_factors`); ``r_s * factor`` must stay in [0, 1].
        member : numpy.ndarray of int, optional
            Shape (W,): position in the stack of wavelengths of every row (required for a
            stack, None for a single wavelength).
        roughness : numpy.ndarray, optional
            Shape (W,) or (W, 1): GGX ``alpha`` of the films' surface per row [-] (one surface
            for every film of the set; the roughness as a parameter, see
            :mod:`bayespig.inference.roughness`), in the rough tables' range; None for the
            model's own :attr:`ForwardModel.roughness`. Needs a rough model (``roughness > 0``).
        binder_index : numpy.ndarray, optional
            Shape (W,) or (W, 1): binder index ``n`` of the films per row [-] (the index as a
            parameter), in the binder-index tables' range; with ``roughness``. None for the
            problem's own ``n``. Needs ``ForwardModel(binder_index_free=True)``.
        flake_reflectance, flake_roughness : numpy.ndarray, optional
            Shape (W,) each: the reflectance ``c`` of the films' effect-pigment flakes at the
            row's wavelength [-] and their roughness [-]; both or neither, with
            ``roughness``. Needs ``ForwardModel(flakes=True)``, which needs them.
        """
        if binder_index is not None and roughness is None:
            raise ValueError("binder_index per row needs roughness per row as well")
        if (flake_reflectance is None) != (flake_roughness is None):
            raise ValueError("flake_reflectance and flake_roughness go together (both per row, or neither)")
        if (flake_reflectance is not None) != self.model.flakes:
            raise ValueError("a ForwardModel with flakes=True needs flake_reflectance and flake_roughness per row "
                             "(and one without flakes takes neither)")
        if flake_reflectance is not None and roughness is None:
            raise ValueError("flake_reflectance per row needs roughness per row as well")
        if roughness is not None:
            return self._call_rough(a, roughness, member, binder_index, flake_reflectance, flake_roughness)
        a = np.asarray(a, dtype=float)
        tau = np.asarray(tau, dtype=float).reshape(a.shape[0], -1)
        g = None if g is None else np.asarray(g, dtype=float)
        member = _stack_members(member, a.shape[0], self.indices.size)
        out = np.empty((a.shape[0], self.n_values))
        omega = np.maximum(1.0 - a, 0.0)[:, None]
        small = None
        if self._tau_min > 0 and tau.size and tau.min() < self._tau_min:
            small = (tau < self._tau_min).any(axis=1)
            tau_fast = np.where(small[:, None], 1.0, tau)
        else:
            tau_fast = tau
        for stencil, column, films in self._units.values():
            if column < 0:
                base = omega * np.exp(stencil.interpolate_opaque(a, g)) + stencil.specular
                for part, _ in films:
                    out[:, part] = base
                continue
            film_tau = tau_fast[:, column]
            log_q, log_du, r_up = stencil.interpolate_finite(a, film_tau, g)
            black = (omega * -np.expm1(-film_tau)[:, None]) * np.exp(log_q) + stencil.specular
            through = np.exp(log_du)
            for part, r_s_stack in films:
                r_s = r_s_stack[member]
                if r_s_scale is not None:
                    r_s = r_s * r_s_scale[:, self._film_of_part[part.start]]
                out[:, part] = black + (r_s / (1.0 - r_s * r_up))[:, None] * through
        for part, column in self._transmittance:
            out[:, part] = self._t_normal * np.exp(-tau[:, column])[:, None]
        if small is not None:
            # rows below the first tau node, one wavelength at a time through the tables
            for position in np.unique(member[small]):
                rows = np.flatnonzero(small & (member == position))
                g_rows = np.zeros(rows.size) if g is None else g[rows]
                if r_s_scale is None:
                    out[rows] = self.model.predict(self.indices[position], a[rows], tau[rows], g_rows)
                else:
                    out[rows] = self._predict_scaled(self.indices[position], a[rows], tau[rows], g_rows,
                                                     r_s_scale[rows])
        return out

    @staticmethod
    def _per_row(name, value, n_rows):
        """A per-row input (W,) from shape (W,) or (W, 1), checked."""
        column = np.asarray(value, dtype=float).reshape(n_rows, -1)
        if column.shape[1] != 1:
            raise ValueError(f"{name} must have one value per row, shape ({n_rows},) or ({n_rows}, 1), "
                             f"got {np.shape(value)}")
        return column[:, 0]

    def _call_rough(self, a, roughness, member, binder_index=None, flake_reflectance=None, flake_roughness=None):
        """Predictions with a roughness (and a binder index, and flakes) per row (opaque films under a rough
        surface)."""
        if not self.model.rough:
            raise ValueError("roughness per row needs a ForwardModel with roughness > 0 (the look-up tables "
                             "of a rough surface)")
        if binder_index is not None and not self.model.binder_index_free:
            raise ValueError("binder_index per row needs a ForwardModel with binder_index_free=True (the "
                             "look-up tables over n)")
        a = np.asarray(a, dtype=float)
        alpha = self._per_row("roughness", roughness, a.shape[0])
        n = None if binder_index is None else self._per_row("binder_index", binder_index, a.shape[0])
        _stack_members(member, a.shape[0], self.indices.size)
        out = np.empty((a.shape[0], self.n_values)) if len(self._rough_units) > 1 or any(
            len(parts) > 1 for _, parts in self._rough_units.values()) else None
        # the lobe depends on the surface alone: once per distinct value (one per walker)
        surface = alpha[:, None] if n is None else np.stack([alpha, n], axis=1)
        if flake_reflectance is not None:
            flake_c = self._per_row("flake_reflectance", flake_reflectance, a.shape[0])
            flake_alpha = self._per_row("flake_roughness", flake_roughness, a.shape[0])
            surface = np.concatenate([surface, flake_alpha[:, None]], axis=1)
        distinct, inverse = np.unique(surface, axis=0, return_inverse=True)
        inverse = inverse.ravel()
        units = list(self._rough_units.values())
        for rough, parts in units:
            if n is None:
                values = rough.body(a, alpha)
                values += rough.lobe(distinct[:, 0])[inverse]
            else:
                family = self.model.binder_index_tables[rough.key]
                values = family.body(a, alpha, n)
                values += family.lobe(distinct[:, 0], distinct[:, 1])[inverse]
            if flake_reflectance is not None:
                # the flakes' lobe: Walter's shape once per distinct (flake roughness, n), times c per row
                values += flake_c[:, None] * rough.flake_lobe(
                    distinct[:, -1], None if n is None else distinct[:, 1])[inverse]
            if len(units) == 1 and len(parts) == 1 and parts[0] == slice(0, self.n_values):
                return values  # one film: no copy
            for part in parts:
                out[:, part] = values
        return out

    def _predict_scaled(self, index, a, tau, g, r_s_scale):
        """:meth:`ForwardModel.predict` at wavelength ``index`` with every reflectance film's
        ``r_s`` scaled (slow path)."""
        problem, parts, k = self.model.problem, [], 0
        for film, table in zip(problem.films, self.model.film_tables):
            film_tau = np.full(a.shape, np.inf) if film.opaque else tau[:, problem.groups.index(film.group)]
            if film.kind == "transmittance":
                parts.append(self._t_normal * np.exp(-film_tau)[:, None])
                continue
            parts.append(table(a=a, tau=film_tau, g=g, r_s=film.r_s[index] * r_s_scale[:, k]))
            k += 1
        return np.concatenate(parts, axis=-1)


class LogPosterior:
    """Vectorised log-posterior at one wavelength, over ``theta`` of shape (n_walkers, n_dim).

    Built for a stack of wavelengths (``index`` a sequence), one call evaluates walkers of
    all of them: ``member`` gives the stack position of every row of ``theta``. The
    wavelengths share the parameter layout, priors and known errors; only the observed
    values and the substrate albedos differ.

    Parameters are ``[a, log tau_1, ..., log tau_G, (g), (log eps), (log noise_floor)]``:
    with the priors of :class:`Priors` the density is flat in every sampled coordinate on a
    box, so the log-posterior equals the log-likelihood of eq. (7) (with the additive floor
    when there is one, see the module docstring) inside the box (up to the prior's
    normalising constant) and ``-inf`` outside.

    Parameters
    ----------
    model : ForwardModel
    index : int or sequence of int
        Wavelength index, or the indices of a stack of wavelengths.
    priors : Priors
    g : {"isotropic", "free"}
        Whether ``g`` is a parameter (otherwise 0).
    eps : float or None
        Known relative error for films without their own; None infers one ``eps``
        (shared by the samples of this wavelength) for the films without their own.
    noise_floor : None, float or "infer"
        Additive noise floor ``sigma0`` of every value [units of the values]: None or 0 for
        none (eq. 7 alone, the exact code path of before), a known number, or ``"infer"``:
        one floor per wavelength shared by all its values, log-uniform on
        ``priors.noise_floor_range``.
    censored_zeros : bool
        Observed values of exactly 0 are readings censored at 0: their term is
        ``log Phi(-m / sigma)`` (:func:`censored_zero_logpdf`) instead of the density at 0.
        Needs a noise floor.

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), eq. (7) (noise model).
    """

    def __init__(self, model, index, priors=Priors(), g="isotropic", eps=0.05, noise_floor=None,
                 censored_zeros=False):
        if g not in ("isotropic", "free"):
            raise ValueError(f"g must be 'isotropic' or 'free', got {g!r}")
        if g == "free" and model.g != "free":
            raise ValueError("g='free' needs a ForwardModel with g='free' (tables with a g axis)")
        if eps is not None and not (np.isfinite(eps) and eps > 0):
            raise ValueError(f"eps must be a positive number or None (inferred), got {eps!r}")
        noise_floor = noise_floor_argument(noise_floor)
        for table in model.film_tables:
            if table is None:
                continue
            tau_max = table.settings.tau_nodes[-1]
            if priors.tau_range[1] > tau_max:
                raise ValueError(f"priors.tau_range reaches {priors.tau_range[1]:g}, beyond the look-up "
                                 f"table's largest finite tau {tau_max:g}")
            if g == "free" and not (table.settings.g_range[0] <= priors.g_range[0]
                                    and priors.g_range[1] <= table.settings.g_range[1]):
                raise ValueError(f"priors.g_range {priors.g_range} must lie inside the table's "
                                 f"g range {table.settings.g_range}")
        self.model = model
        self.index = index
        self.priors = priors
        self.free_g = g == "free"
        self.evaluate = model.at_wavelength(index)
        self._observed = np.stack([model.problem.observed(i) for i in self.evaluate.indices])
        known = model.problem.known_eps(eps)
        self.infer_eps = bool(np.isnan(known).any())
        self.eps = known
        self._unknown = np.isnan(known)
        self._inv_known = np.where(self._unknown, 0.0, 1.0 / np.where(self._unknown, 1.0, known))
        self._log_known = np.log(np.where(self._unknown, 1.0, known))
        self.n_groups = len(model.problem.groups)
        names = ["a"] + [f"log_tau[{g}]" for g in model.problem.groups]
        if self.free_g:
            names.append("g")
        if self.infer_eps:
            names.append("log_eps")
        self.infer_noise_floor = noise_floor == "infer"
        #: Known floor [units of the values], 0.0 for none or when inferred.
        self.noise_floor = 0.0 if noise_floor in (None, "infer") else float(noise_floor)
        self.has_noise_floor = noise_floor is not None
        self.censored_zeros = censored_zeros_argument(censored_zeros, noise_floor)
        #: Where the observed values are exactly 0 (censored readings when ``censored_zeros``).
        self._zero = self._observed == 0
        if self.infer_noise_floor:
            names.append("log_noise_floor")
        self.parameter_names = tuple(names)
        low = [priors.a_range[0]] + [np.log(priors.tau_range[0])] * self.n_groups
        high = [priors.a_range[1]] + [np.log(priors.tau_range[1])] * self.n_groups
        if self.free_g:
            low.append(priors.g_range[0])
            high.append(priors.g_range[1])
        if self.infer_eps:
            low.append(np.log(priors.eps_range[0]))
            high.append(np.log(priors.eps_range[1]))
        if self.infer_noise_floor:
            low.append(np.log(priors.noise_floor_range[0]))
            high.append(np.log(priors.noise_floor_range[1]))
        self.lower = np.array(low)
        self.upper = np.array(high)

    @property
    def observed(self):
        """Observed values, (n_values,) at one wavelength, (n_stack, n_values) for a stack."""
        return self._observed[0] if self.evaluate.index is not None else self._observed

    @observed.setter
    def observed(self, values):
        self._observed = np.asarray(values, dtype=float).reshape(self._observed.shape).copy()
        self._zero = self._observed == 0

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
        if self.infer_eps:
            eps = np.where(self._unknown, np.exp(theta[:, k])[:, None], self.eps)
        else:
            eps = self.eps[None, :]
        return a, tau, g, eps

    def noise_floor_of(self, theta):
        """The noise floor of each parameter vector, shape (n,) [units of the values] (the
        known one, or 0, when it is not inferred)."""
        theta = np.atleast_2d(theta)
        if self.infer_noise_floor:
            return np.exp(theta[:, -1])
        return np.full(theta.shape[0], self.noise_floor)

    def in_support(self, theta):
        """Boolean mask of parameter vectors inside the prior's support."""
        theta = np.atleast_2d(theta)
        return ((theta >= self.lower) & (theta <= self.upper)).all(axis=1)

    def log_likelihood(self, theta, pointwise=False, member=None):
        """Log-likelihood of eq. (7) per parameter vector (``-inf`` outside the support).

        With a noise floor, that of :func:`multiplicative_normal_logpdf` with the floor (the
        variance ``(eps m)^2 + sigma0^2``), the observed zeros censored with ``censored_zeros``;
        without one the code path of eq. (7) alone.

        With ``pointwise=True`` the terms per measured value, shape (n, n_values).
        ``member`` (n,) is the stack position of every row (required for a stack).
        """
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        n_values = self._observed.shape[1]
        member = _stack_members(member, theta.shape[0], self._observed.shape[0])
        if theta.shape[0] == 0:  # no walkers (e.g. every start draw left the support)
            return np.empty((0, n_values) if pointwise else 0)
        ok = self.in_support(theta)
        everywhere = ok.all()
        if not (everywhere or ok.any()):
            return np.full((theta.shape[0], n_values) if pointwise else theta.shape[0], -np.inf)
        inside = theta if everywhere else theta[ok]
        member = member if everywhere else member[ok]
        observed = self._observed[0] if self._observed.shape[0] == 1 else self._observed[member]
        k = 1 + self.n_groups
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            model = self.evaluate(inside[:, 0], np.exp(inside[:, 1:k]), inside[:, k] if self.free_g else None,
                                  member=None if self._observed.shape[0] == 1 else member)
            inv_eps, log_eps = self._inv_known, self._log_known
            if self.infer_eps:
                log_eps_free = inside[:, k + self.free_g][:, None]
                inv_eps = np.where(self._unknown, np.exp(-log_eps_free), inv_eps)
                log_eps = log_eps + log_eps_free * self._unknown
            if self.has_noise_floor:
                # N(x | m, (eps m)^2 + sigma0^2); the model value must stay > 0
                floor = np.exp(inside[:, -1])[:, None] if self.infer_noise_floor else self.noise_floor
                variance = (model * np.exp(log_eps)) ** 2 + floor * floor
                residual = observed - model
                value = -0.5 * (residual * residual / variance + np.log(variance) + _LOG_2PI)
                if self.censored_zeros:  # a reading of exactly 0: log P(reading <= 0)
                    zero = self._zero[0] if self._zero.shape[0] == 1 else self._zero[member]
                    value = np.where(zero, censored_zero_logpdf(model, variance), value)
                value = np.where(model > 0, value, -np.inf)
                if not pointwise:
                    value = value.sum(axis=1)
            else:
                z = (observed / model - 1.0) * inv_eps
                if pointwise:
                    value = -0.5 * z * z - np.log(model) - log_eps - 0.5 * _LOG_2PI
                else:
                    value = (-0.5 * (z * z).sum(axis=1) - np.log(model).sum(axis=1)
                             - (log_eps.sum(axis=-1) + 0.5 * _LOG_2PI * z.shape[1]))
        value[~np.isfinite(value)] = -np.inf
        if everywhere:
            return value
        out = np.full((theta.shape[0],) + value.shape[1:], -np.inf)
        out[ok] = value
        return out

    def __call__(self, theta, member=None):
        """Log-posterior (flat priors in the sampled coordinates: equal to the log-likelihood)."""
        return self.log_likelihood(theta, member=member)
