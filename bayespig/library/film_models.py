"""Forward models of a film made of a pigment mixture: radiative transfer and Kubelka-Munk.

A pigment library holds, per pigment and wavelength, two sampled *constants*; a film of a
recipe (concentrations ``D_i``, appendix A2) and a relative thickness ``h`` is then
predicted by one of two models behind one interface (:class:`FilmModel`):

* **Radiative transfer** (bayespig's model, :class:`RadiativeTransferModel`, name
  ``"radiative-transfer"``): constants ``(a_i, log sigma_i)``, the relative absorption and
  the log extinction per unit concentration of each pigment. Mixing by the paper's section 2
  (:func:`bayespig.physics.mixtures.mixture_properties`)::

      tau = h sum_i D_i sigma_i,    a = sum_i a_i D_i sigma_i / sum_i D_i sigma_i,    g = 0

  (isotropic: sphere data do not constrain ``g``). The film's values come from the
  project's look-up tables (:mod:`bayespig.table`) through the very path the inference
  uses: :meth:`RadiativeTransferModel.for_film` builds the film's
  :class:`~bayespig.likelihood.Problem` and :class:`~bayespig.likelihood.ForwardModel` and
  evaluates all wavelengths of all draws in one call of its
  :class:`~bayespig.likelihood.WavelengthModel`, so a film's prediction at given ``(a,
  tau)`` is exactly what :func:`bayespig.infer` computes for it (its posterior predictive
  ``y``). ``tau`` above the tables' largest finite node (``2^7 = 128`` by default) is taken
  as opaque (``tau = inf``): the reflectance then differs by less than 1e-6 for a mixture
  of ``a >= 1e-3`` and by about 1e-3 at ``a = 1e-4`` (measured with the 8d-sce table).

* **Two-constant Kubelka-Munk** with Saunderson's correction
  (:class:`KubelkaMunkModel`, name ``"kubelka-munk"``): constants ``(log K_i, log S_i)``
  per unit concentration and thickness. Mixing by Duncan's rule
  (:func:`bayespig.kubelka_munk.mix_K_S`), ``K = sum_i D_i K_i``, ``S = sum_i D_i S_i``;
  a layer of thickness ``X = h`` (:func:`bayespig.kubelka_munk.layer_reflectance`) over the
  card's internal reflectance, which is the card's measured reflectance through Saunderson's
  inverse (:func:`bayespig.kubelka_munk.saunderson_to_internal`); measured values through
  Saunderson's formula (:func:`bayespig.kubelka_munk.saunderson_to_measured`) with the
  instrument's specular mode (SCI includes ``k1``; SCE and 45/0 exclude it) and the
  constants ``k1 = r_F(theta_i)``, ``k2`` the internal diffuse reflectance of the binder
  surface (:func:`bayespig.kubelka_munk.saunderson_constants`). For an 8/d card these are
  exactly bayespig's albedo seen from the binder ``r_s``
  (:func:`bayespig.physics.substrate.substrate_albedo_from_air`), so both models see the same
  cards.

Shapes (``N`` draws, ``n_wl`` wavelengths, ``P`` pigments): constants ``(N, n_wl, P, 2)``
in the model's sampled coordinates (:attr:`FilmModel.constant_names`), concentrations
``(P,)`` [relative, any fixed scale per pigment: it is absorbed by ``sigma_i`` or ``K_i,
S_i``], thickness ``(N,)`` relative film thickness ``h`` [1] (``inf``: opaque).

Instruments are named as in :mod:`bayespig.instruments`: ``"8d-sce"``, ``"8d-sci"``,
``"45-0"`` (or any single-channel :class:`~bayespig.instruments.Instrument`; Kubelka-Munk
predicts hemispherical and 45/0 values only).

References
----------
Ershov, Voloboy & Pozdnyakov (2023), section 2 (mixtures), appendix A2 (concentrations).
P. Kubelka (1948), J. Opt. Soc. Am. 38, 448. J. L. Saunderson (1942), J. Opt. Soc. Am.
32, 727. D. R. Duncan (1940), Proc. Phys. Soc. 52, 390.
"""

from __future__ import annotations

import abc
import functools

import numpy as np

from .. import kubelka_munk as km
from .._validation import real_array
from ..instruments import Instrument, get_instrument
from ..likelihood import ForwardModel, Problem
from ..physics.mixtures import mixture_properties
from ..physics.substrate import substrate_albedo_from_air
from ..table import load_table

__all__ = [
    "FILM_MODELS",
    "FilmModel",
    "FilmPredictor",
    "KubelkaMunkModel",
    "RadiativeTransferModel",
    "film_model",
]

#: Default box of ``log sigma_i`` (extinction per unit concentration and thickness) [ln 1]:
#: ``sigma`` from 1e-4 to 1e4, wide around the Revigo films' ``tau`` of 0.1..100 at
#: concentrations of order 1 and ``h`` of order 1.
LOG_SIGMA_RANGE = (float(np.log(1e-4)), float(np.log(1e4)))
#: Default box of ``log K_i`` [ln 1]: ``K`` from 1e-6 (a white's near-zero absorption) to 1e4.
LOG_K_RANGE = (float(np.log(1e-6)), float(np.log(1e4)))
#: Default box of ``log S_i`` [ln 1]: ``S`` from 1e-4 to 1e4.
LOG_S_RANGE = (float(np.log(1e-4)), float(np.log(1e4)))


# --------------------------------------------------------------------------- arguments


def _draw_arguments(constants, concentrations, thickness, n_wavelengths=None):
    """``constants`` (N, n_wl, P, 2), ``concentrations`` (P,), ``thickness`` (N,), checked."""
    constants = real_array("constants", constants)
    if constants.ndim != 4 or constants.shape[-1] != 2:
        raise ValueError("constants must have shape (n_draws, n_wavelengths, n_pigments, 2), "
                         f"got {constants.shape}")
    n_draws, n_wl, n_pigments, _ = constants.shape
    if n_wavelengths is not None and n_wl != n_wavelengths:
        raise ValueError(f"constants have {n_wl} wavelengths, the film has {n_wavelengths}")
    D = real_array("concentrations", concentrations, low=0.0)
    if D.shape != (n_pigments,):
        raise ValueError(f"concentrations must have shape ({n_pigments},) (one per pigment of "
                         f"constants), got {D.shape}")
    if not (D > 0).any():
        raise ValueError("concentrations are all zero: the film holds no pigment")
    h = real_array("thickness", thickness, low=0.0, low_open=True, allow_inf=True)
    if h.ndim == 0:
        h = np.full(n_draws, float(h))
    if h.shape != (n_draws,):
        raise ValueError(f"thickness must have shape ({n_draws},) (one per draw of constants), got {h.shape}")
    return constants, D, h


def _single_channel(instrument, n):
    instrument = get_instrument(instrument, n)
    if len(instrument.channels) != 1:
        raise ValueError(f"instrument {instrument.name!r} has {len(instrument.channels)} channels; "
                         "reflectance() predicts one value per wavelength (use '8d-sce', '8d-sci' "
                         "or '45-0', or a single-channel Instrument)")
    return instrument


def _substrate_in_air(substrate, shape):
    """``substrate`` as card reflectances in air, (n_wl,) or (N, n_wl), checked."""
    if substrate is None:
        raise ValueError("substrate is needed for a film that does not hide its card: the card's "
                         "reflectance measured in air, one value per wavelength (fraction)")
    value = real_array("substrate", substrate, low=0.0, high=1.0, unit="(a fraction; percent / 100)")
    n_draws, n_wl = shape
    if value.shape not in ((n_wl,), (n_draws, n_wl)):
        raise ValueError(f"substrate must have shape ({n_wl},) or ({n_draws}, {n_wl}) (card "
                         f"reflectance in air per wavelength), got {value.shape}")
    return value


def _card_factors(r_s_scale, n_draws, n_films):
    if r_s_scale is None:
        return None
    scale = real_array("r_s_scale", r_s_scale, low=0.0)
    if scale.shape != (n_draws, n_films):
        raise ValueError(f"r_s_scale must have shape ({n_draws}, {n_films}) (one factor per draw and "
                         f"reflectance film), got {scale.shape}")
    return scale


def _one_film_group(problem, source):
    if len(problem.groups) > 1:
        raise ValueError(f"{source}: a film is one film group (its samples share the thickness); "
                         f"this set has {len(problem.groups)}: {', '.join(problem.groups)}")


# --------------------------------------------------------------------------- interface


class FilmPredictor(abc.ABC):
    """The values of one measured film (one :class:`~bayespig.data.MeasurementSet`) as predicted.

    Attributes
    ----------
    observed : numpy.ndarray
        Shape (n_wl, n_values): the film's measured values, films of the set concatenated in
        the order of its :class:`~bayespig.likelihood.Problem` (general method: every film).
    wavelength_nm : numpy.ndarray
        Shape (n_wl,) [nm].
    value_films : tuple of str
        The sample each value column belongs to.
    value_channels : tuple of str
        The channel label of each value column.
    eps : numpy.ndarray
        Shape (n_values,): each value's known relative error (its sample's ``eps``), NaN where
        the set does not give one.
    n_reflectance_films : int
        Reflectance films (the columns of ``r_s_scale``), in problem order.
    problem : Problem
        The film's problem (the inference's view of it).
    """

    def __init__(self, measurements):
        problem = Problem.from_measurements(measurements, method="general")
        film_id = measurements.metadata.get("film_id")
        _one_film_group(problem, f"film {film_id!r}" if film_id else (measurements.source or "measurement set"))
        self.problem = problem
        self.wavelength_nm = np.asarray(problem.wavelength_nm, dtype=float)
        self.observed = np.concatenate([np.asarray(f.observed, dtype=float) for f in problem.films], axis=1)
        films, channels = [], []
        for film in problem.films:
            labels = (["specular_transmittance"] if film.kind == "transmittance"
                      else list(film.instrument.labels))
            films.extend([film.name] * len(labels))
            channels.extend(labels)
        self.value_films, self.value_channels = tuple(films), tuple(channels)
        self.n_reflectance_films = sum(f.kind == "reflectance" for f in problem.films)
        self.eps = problem.known_eps(None)

    @property
    def n_wavelengths(self):
        """Number of wavelengths."""
        return self.wavelength_nm.size

    @property
    def n_values(self):
        """Measured values per wavelength."""
        return self.observed.shape[1]

    @abc.abstractmethod
    def values(self, constants, concentrations, thickness, *, r_s_scale=None):
        """Predicted values of the film.

        Parameters
        ----------
        constants : array_like
            Shape (W, n_wl, P, 2): the pigments' constants in the model's sampled coordinates.
        concentrations : array_like
            Shape (P,): ``D_i`` of the film's recipe [relative].
        thickness : array_like
            Shape (W,): relative film thickness ``h`` [1] (``inf``: opaque).
        r_s_scale : array_like, optional
            Shape (W, n_reflectance_films): a factor on each reflectance film's card albedo
            seen from the binder (card factors, :mod:`bayespig.inference.card_factors`).

        Returns
        -------
        numpy.ndarray
            Shape (W, n_wl, n_values), in the units of :attr:`observed`.
        """


class FilmModel(abc.ABC):
    """A forward model of films of pigment mixtures (see the module docstring).

    Attributes
    ----------
    name : str
        ``"radiative-transfer"`` or ``"kubelka-munk"``.
    constant_names : tuple of str
        The two sampled coordinates per pigment and wavelength.
    lower, upper : numpy.ndarray
        Shape (2,): the box of the sampled coordinates (a flat prior on it is the library's).
    log_linear : tuple of float
        Per sampled coordinate 1 where it is the log of a coefficient the mixing rule weights by
        the concentration (so ``D -> f D`` is ``+ log f`` there), else 0: the library's
        concentration factors (:mod:`bayespig.inference.concentration_factors`).
    """

    name = ""
    constant_names = ()
    log_linear = (0.0, 0.0)

    def __init__(self, lower, upper):
        lower = real_array("lower", lower)
        upper = real_array("upper", upper)
        if lower.shape != (2,) or upper.shape != (2,) or not (lower < upper).all():
            raise ValueError(f"lower and upper must be two numbers each with lower < upper, got {lower}, {upper}")
        self.lower, self.upper = lower, upper

    def __repr__(self):
        return f"{type(self).__name__}(lower={self.lower.tolist()}, upper={self.upper.tolist()})"

    @property
    def table_checksums(self):
        """Key -> content checksum of every look-up table the model has used so far (none for a
        model without tables); recorded in a library's provenance."""
        return {}

    @abc.abstractmethod
    def physical(self, constants):
        """The physical constants from the sampled coordinates ``constants`` (..., 2) (dict of arrays)."""

    @abc.abstractmethod
    def mixture(self, constants, concentrations):
        """The mixture's two coefficients per unit thickness, each (N, n_wl)."""

    @abc.abstractmethod
    def for_film(self, measurements):
        """The :class:`FilmPredictor` of a measured film (a MeasurementSet of one film group)."""

    @abc.abstractmethod
    def reflectance(self, constants, concentrations, thickness, *, substrate, instrument, n=1.45):
        """Predicted reflectance of a recipe over a card (or opaque).

        Parameters
        ----------
        constants : array_like
            Shape (N, n_wl, P, 2), the model's sampled coordinates.
        concentrations : array_like
            Shape (P,): ``D_i`` [relative].
        thickness : array_like
            Shape (N,) (or a scalar): relative thickness ``h`` [1], ``inf`` for opaque.
        substrate : array_like or None
            The card's reflectance measured in air with ``instrument`` [fraction], shape
            (n_wl,) or (N, n_wl); ignored (may be None) when every thickness is ``inf``.
        instrument : str or Instrument
            ``"8d-sce"``, ``"8d-sci"``, ``"45-0"`` or a single-channel Instrument.
        n : float
            Binder refractive index [1].

        Returns
        -------
        numpy.ndarray
            Shape (N, n_wl): hemispherical reflectance or 45/0 reflectance factor [fraction].
        """


# --------------------------------------------------------------------------- radiative transfer


class RadiativeTransferModel(FilmModel):
    """bayespig's model of a mixture: section 2 mixing, isotropic, look-up tables.

    Parameters
    ----------
    lower, upper : array_like, optional
        The box of ``(a, log sigma)``; default ``a`` in [0, 1], ``log sigma`` in
        :data:`LOG_SIGMA_RANGE`.
    tables : dict, optional
        Look-up tables to use, keyed by instrument name or Instrument (else loaded from the
        cache, built on first use).
    """

    name = "radiative-transfer"
    constant_names = ("a", "log_sigma")
    log_linear = (0.0, 1.0)  # k_ext = sum D_i sigma_i, a of the mixture weighted by D_i sigma_i (section 2)

    def __init__(self, lower=(0.0, LOG_SIGMA_RANGE[0]), upper=(1.0, LOG_SIGMA_RANGE[1]), tables=None):
        super().__init__(lower, upper)
        if self.lower[0] < 0.0 or self.upper[0] > 1.0:
            raise ValueError(f"the box of a must lie inside [0, 1], got [{self.lower[0]:g}, {self.upper[0]:g}]")
        self._tables = {}
        for key, table in (tables or {}).items():
            instrument = key if isinstance(key, Instrument) else get_instrument(key)
            self._tables[(instrument.channels, instrument.n)] = table

    @property
    def table_checksums(self):
        """Key -> :attr:`bayespig.table.LookupTable.checksum` of every table used so far."""
        return {t.key: t.checksum for t in sorted(self._tables.values(), key=lambda t: t.key)}

    def table(self, instrument):
        """The isotropic look-up table of ``instrument`` (an Instrument), cached per channels and ``n``."""
        key = (instrument.channels, instrument.n)
        if key not in self._tables:
            self._tables[key] = load_table(instrument, g="isotropic", n=instrument.n, progress=False)
        return self._tables[key]

    def physical(self, constants):
        """``{"a": a, "sigma": exp(log sigma)}`` from ``constants`` (..., 2)."""
        constants = np.asarray(constants, dtype=float)
        return {"a": constants[..., 0], "sigma": np.exp(constants[..., 1])}

    def mixture(self, constants, concentrations):
        """``(a, k_ext)`` of the mixture, each (N, n_wl): relative absorption [1] and extinction
        per unit thickness ``sum_i D_i sigma_i`` [1/h] (paper section 2)."""
        constants = np.asarray(constants, dtype=float)
        a_i = constants[..., 0]
        if (a_i < 0).any() or (a_i > 1).any():
            raise ValueError("constants[..., 0] is the relative absorption a and must lie in [0, 1]")
        return mixture_properties(concentrations, np.moveaxis(a_i, -1, 0),
                                  np.exp(np.moveaxis(constants[..., 1], -1, 0)))

    @staticmethod
    def _optical_thickness(h, k_ext, tau_max):
        tau = h[:, None] * k_ext
        return np.where(tau > tau_max, np.inf, tau)

    def for_film(self, measurements):
        """The film's predictor through the inference's ForwardModel (see the module docstring)."""
        return RadiativeTransferFilm(self, measurements)

    def reflectance(self, constants, concentrations, thickness, *, substrate, instrument, n=1.45):
        """Predicted reflectance (N, n_wl) of a recipe (see :meth:`FilmModel.reflectance`).

        The card in air becomes its albedo seen from the binder as the data readers do it
        (:func:`bayespig.physics.substrate.substrate_albedo_from_air`: eq. 9 inverted, for a
        hemispherical channel its hemispherical integral; a 45/0 reflectance factor as
        ``pi`` times the BRDF); the film is the instrument's look-up table at the mixture's
        ``(a, tau)`` over that albedo (the substrate law, eq. 3).
        """
        constants, D, h = _draw_arguments(constants, concentrations, thickness)
        instrument = _single_channel(instrument, n)
        table = self.table(instrument)
        a, k_ext = self.mixture(constants, D)
        tau = self._optical_thickness(h, k_ext, table.tau_max)
        r_s = 0.0
        if np.isfinite(h).any():
            r_s = _albedo_from_air(_substrate_in_air(substrate, a.shape), instrument)
        return table(a=a, tau=tau, r_s=r_s)[..., 0]


def _albedo_from_air(reflectance_in_air, instrument):
    """``r_s`` of a card measured in air with a single-channel instrument (as the data readers do)."""
    channel = instrument.channels[0]
    try:
        if channel.kind == "hemispherical":
            return substrate_albedo_from_air(reflectance_in_air, n=instrument.n, kind="hemispherical",
                                             theta_i=channel.theta_i, specular=channel.specular)
        brdf = reflectance_in_air / np.pi if channel.kind == "reflectance_factor" else reflectance_in_air
        return substrate_albedo_from_air(brdf, n=instrument.n, kind="brdf", theta_i=channel.theta_i,
                                         theta_o=channel.theta_o)
    except ValueError as error:
        raise ValueError(f"substrate: cannot be a Lambertian card under binder measured with "
                         f"{instrument.name!r}: {error}") from None


class RadiativeTransferFilm(FilmPredictor):
    """A measured film predicted by :class:`RadiativeTransferModel` (the inference's fast path).

    Attributes (besides :class:`FilmPredictor`'s)
    ----------
    forward_model : ForwardModel
        The film's forward model, as :func:`bayespig.infer` builds it.
    tau_max : float
        Largest finite ``tau`` of the film's tables; above it the film is opaque.
    """

    def __init__(self, model, measurements):
        super().__init__(measurements)
        tables = {f.instrument: model.table(f.instrument) for f in self.problem.films if f.kind == "reflectance"}
        self.model = model
        self.forward_model = ForwardModel(self.problem, g="isotropic", tables=tables)
        self._evaluate = self.forward_model.at_wavelength(np.arange(self.problem.n_wavelengths))
        self._n_groups = len(self.problem.groups)
        self.tau_max = min((t.tau_max for t in tables.values()), default=np.inf)

    def optical_thickness(self, constants, concentrations, thickness):
        """``(a, tau)`` of the film, each (W, n_wl) (``tau = inf`` above :attr:`tau_max`)."""
        constants, D, h = _draw_arguments(constants, concentrations, thickness, self.problem.n_wavelengths)
        a, k_ext = self.model.mixture(constants, D)
        return a, self.model._optical_thickness(h, k_ext, self.tau_max)

    def values(self, constants, concentrations, thickness, *, r_s_scale=None):
        """Predicted values (W, n_wl, n_values) (see :meth:`FilmPredictor.values`): the mixture's
        ``(a, tau)`` of every draw and wavelength in one call of the inference's evaluator."""
        a, tau = self.optical_thickness(constants, concentrations, thickness)
        n_draws, n_wl = a.shape
        scale = _card_factors(r_s_scale, n_draws, self.n_reflectance_films)
        rows = n_draws * n_wl
        member = np.tile(np.arange(n_wl), n_draws)
        # every film opaque: the evaluator never reads tau, but it must have one column
        tau_rows = tau.reshape(rows, 1) if self._n_groups else np.ones((rows, 1))
        out = self._evaluate(a.reshape(rows), tau_rows, None,
                             r_s_scale=None if scale is None else np.repeat(scale, n_wl, axis=0),
                             member=member)
        return out.reshape(n_draws, n_wl, -1)


# --------------------------------------------------------------------------- Kubelka-Munk


def _saunderson(channel, n, k1=None, k2=None):
    """``(k1, k2, specular)`` for one channel: Fresnel at its incidence, internal diffuse, its mode."""
    if channel.kind == "brdf":
        raise ValueError(f"Kubelka-Munk predicts hemispherical and 45/0 values, not the BRDF channel "
                         f"{channel.label!r}")
    d1, d2 = km.saunderson_constants(n, channel.theta_i)
    specular = channel.specular if channel.kind == "hemispherical" else "excluded"
    return (d1 if k1 is None else float(k1)), (d2 if k2 is None else float(k2)), specular


class KubelkaMunkModel(FilmModel):
    """Two-constant Kubelka-Munk with Saunderson's correction (see the module docstring).

    Parameters
    ----------
    lower, upper : array_like, optional
        The box of ``(log K, log S)``; default :data:`LOG_K_RANGE`, :data:`LOG_S_RANGE`.
    k1, k2 : float, optional
        Saunderson constants overriding the Fresnel values of the binder
        (:func:`bayespig.kubelka_munk.saunderson_constants`; colour-matching practice often
        fits ``k2``).
    """

    name = "kubelka-munk"
    constant_names = ("log_K", "log_S")
    log_linear = (1.0, 1.0)  # Duncan: K = sum D_i K_i, S = sum D_i S_i

    def __init__(self, lower=(LOG_K_RANGE[0], LOG_S_RANGE[0]), upper=(LOG_K_RANGE[1], LOG_S_RANGE[1]),
                 k1=None, k2=None):
        super().__init__(lower, upper)
        for name, value in (("k1", k1), ("k2", k2)):
            if value is not None and not 0.0 <= float(value) < 1.0:
                raise ValueError(f"{name} must lie in [0, 1), got {value!r}")
        self.k1, self.k2 = k1, k2

    def saunderson(self, channel, n=1.45):
        """``(k1, k2, specular)`` of Saunderson's correction for an instrument channel."""
        return _saunderson(channel, n, self.k1, self.k2)

    def physical(self, constants):
        """``{"K": exp(log K), "S": exp(log S)}`` from ``constants`` (..., 2)."""
        constants = np.asarray(constants, dtype=float)
        return {"K": np.exp(constants[..., 0]), "S": np.exp(constants[..., 1])}

    def mixture(self, constants, concentrations):
        """``(K, S)`` of the mixture by Duncan's rule, each (N, n_wl) [1/h]."""
        constants = np.asarray(constants, dtype=float)
        return km.mix_K_S(concentrations, np.exp(np.moveaxis(constants[..., 0], -1, 0)),
                          np.exp(np.moveaxis(constants[..., 1], -1, 0)))

    @staticmethod
    def _measured(K, S, X, background, saunderson):
        k1, k2, specular = saunderson
        R_i = km.layer_reflectance(K, S, X, background)
        return km.saunderson_to_measured(np.minimum(R_i, 1.0), k1, k2, specular=specular)

    def for_film(self, measurements):
        """The film's predictor: each film over its card's internal reflectance."""
        return KubelkaMunkFilm(self, measurements)

    def reflectance(self, constants, concentrations, thickness, *, substrate, instrument, n=1.45):
        """Predicted reflectance (N, n_wl) of a recipe (see :meth:`FilmModel.reflectance`).

        The card in air becomes its internal reflectance by Saunderson's inverse with the
        instrument's constants and specular mode; the film is Kubelka's layer of thickness
        ``X = h`` over it, measured through Saunderson's formula.
        """
        constants, D, h = _draw_arguments(constants, concentrations, thickness)
        instrument = _single_channel(instrument, n)
        saunderson = self.saunderson(instrument.channels[0], instrument.n)
        K, S = self.mixture(constants, D)
        background = 0.0
        if np.isfinite(h).any():
            card = _substrate_in_air(substrate, K.shape)
            k1, k2, specular = saunderson
            background = np.minimum(km.saunderson_to_internal(card, k1, k2, specular=specular), 1.0)
        return self._measured(K, S, h[:, None], background, saunderson)


def _same_geometry(a, b):
    return (a.kind, a.theta_i, a.theta_o, a.delta_phi, a.specular) == (b.kind, b.theta_i, b.theta_o,
                                                                       b.delta_phi, b.specular)


class KubelkaMunkFilm(FilmPredictor):
    """A measured film predicted by :class:`KubelkaMunkModel`.

    Each reflectance film lies over its card's internal reflectance: the card sample's
    measurement at the film's geometry through Saunderson's inverse, or, for a card given as
    an albedo (a number, ``"black"``, ``"white"``) or not measured at that geometry, the
    albedo seen from the binder of the set (:meth:`~bayespig.data.MeasurementSet.substrate_albedo`).

    Attributes (besides :class:`FilmPredictor`'s)
    ----------
    backgrounds : list of numpy.ndarray
        Per reflectance film, shape (n_channels, n_wl): the internal card reflectance per value.
    saunderson : list of list of tuple
        Per reflectance film and channel, ``(k1, k2, specular)``.
    """

    def __init__(self, model, measurements):
        super().__init__(measurements)
        self.model = model
        self.backgrounds, self.saunderson, self._opaque = [], [], []
        for film in self.problem.films:
            if film.kind == "transmittance":
                raise ValueError(f"film {film.name!r}: Kubelka-Munk does not model the specular "
                                 "transmittance of a film on glass")
            sample = measurements.sample(film.name)
            card = (measurements.sample(sample.substrate) if isinstance(sample.substrate, str)
                    and measurements.has_sample(sample.substrate) else None)
            backgrounds, constants = [], []
            for channel in film.instrument.channels:
                saunderson = model.saunderson(channel, self.problem.n)
                constants.append(saunderson)
                match = None if card is None else next(
                    (m for m in card.reflectance_measurements if _same_geometry(m.channel, channel)), None)
                if film.opaque:
                    backgrounds.append(np.zeros(self.problem.n_wavelengths))
                elif match is not None:
                    k1, k2, specular = saunderson
                    backgrounds.append(np.minimum(km.saunderson_to_internal(
                        np.minimum(match.values, 1.0), k1, k2, specular=specular), 1.0))
                else:
                    backgrounds.append(np.asarray(film.r_s, dtype=float))
            self.backgrounds.append(np.array(backgrounds))
            self.saunderson.append(constants)
            self._opaque.append(film.opaque)

    def values(self, constants, concentrations, thickness, *, r_s_scale=None):
        """Predicted values (W, n_wl, n_values) (see :meth:`FilmPredictor.values`); ``r_s_scale``
        multiplies each reflectance film's internal card reflectance."""
        constants, D, h = _draw_arguments(constants, concentrations, thickness, self.problem.n_wavelengths)
        K, S = self.model.mixture(constants, D)
        scale = _card_factors(r_s_scale, K.shape[0], self.n_reflectance_films)
        columns = []
        for k, (backgrounds, saunderson, opaque) in enumerate(zip(self.backgrounds, self.saunderson, self._opaque)):
            X = np.inf if opaque else h[:, None]
            for background, constants_k in zip(backgrounds, saunderson):
                Rg = background if scale is None else background[None, :] * scale[:, k:k + 1]
                columns.append(self.model._measured(K, S, X, Rg, constants_k))
        return np.stack(columns, axis=-1)


# --------------------------------------------------------------------------- by name

#: The film models by name.
FILM_MODELS = {RadiativeTransferModel.name: RadiativeTransferModel, KubelkaMunkModel.name: KubelkaMunkModel}


@functools.cache
def _default_model(name):
    return FILM_MODELS[name]()


def film_model(name, **options):
    """A film model by name: ``"radiative-transfer"`` or ``"kubelka-munk"``.

    Parameters
    ----------
    name : str or FilmModel
        A model name (a FilmModel is returned as it is).
    **options
        Constructor arguments (:class:`RadiativeTransferModel`, :class:`KubelkaMunkModel`);
        without any, one shared instance per name (its look-up tables stay loaded).

    Returns
    -------
    FilmModel
    """
    if isinstance(name, FilmModel):
        if options:
            raise ValueError("options apply to a model name, not to a FilmModel instance")
        return name
    if not isinstance(name, str) or name not in FILM_MODELS:
        raise ValueError(f"unknown film model {name!r}; use one of {', '.join(map(repr, FILM_MODELS))}")
    return FILM_MODELS[name](**options) if options else _default_model(name)
