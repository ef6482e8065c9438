"""Film thicknesses as parameters shared over wavelengths: one ``log h`` per film.

A film's optical thickness at every wavelength is its thickness ``h`` times what the pigments
give per unit thickness (``tau(λ) = h * sum_i D_i sigma_i(λ)`` in a pigment library,
:mod:`bayespig.library`). ``h`` is the same at every wavelength, so it couples them: it is a
spec (:class:`FilmThickness`) of the one joint machinery for shared parameters
(:mod:`bayespig.inference.shared`) and enters the forward model through the model input
``thickness`` (one value per film, in the order of the spec's labels).

Prior
-----
``log h ~ N(mu, sd^2)`` per film, truncated at :data:`THICKNESS_PRIOR_SDS` sds:

- a film with a measured thickness ``h_m`` (in the unit the library uses for all its films):
  ``mu = log h_m`` and ``sd`` = the measurement's relative sd (default
  :data:`MEASURED_RELATIVE_SD`);
- a film of unknown thickness: ``mu = 0`` (a relative thickness, 1 = the nominal film) and
  ``sd`` = :data:`RELATIVE_SD` (0.5: drawdowns made with one applicator differ by tens of per
  cent, not by factors of several; the prior keeps ``h * sigma`` identifiable, which the data
  alone do not: only the product enters the optics).

The scale of the extinction per unit thickness is therefore relative to the nominal film unless
thicknesses are measured; with several films the products ``h_f sigma(λ)`` are learned
precisely and the common scale to ``sd / sqrt(n_films)`` by the prior.
"""

from __future__ import annotations

import numpy as np

from .shared import SharedParameter

__all__ = ["MEASURED_RELATIVE_SD", "RELATIVE_SD", "THICKNESS_PRIOR_SDS", "FilmThickness"]

#: Prior sd of ``log h`` of a film of unknown thickness (relative thickness; drawdowns with one
#: applicator have similar thickness).
RELATIVE_SD = 0.5
#: Prior sd of ``log h`` of a film whose thickness is measured (about 10 % relative).
MEASURED_RELATIVE_SD = 0.1
#: The prior of ``log h`` is truncated at this many sds (a bounded box for the sampler).
THICKNESS_PRIOR_SDS = 4.0


class FilmThickness(SharedParameter):
    """One thickness ``h`` per film, shared by all wavelengths (a spec of :mod:`bayespig.inference.shared`).

    Parameters
    ----------
    films : sequence of str
        Film ids (the labels; the order of the model input ``thickness``).
    measured : sequence of float, optional
        Measured thickness per film (same unit for all films of a library), NaN where unknown;
        default all unknown.
    relative_sd : float
        Prior sd of ``log h`` of a film of unknown thickness [-].
    measured_sd : float
        Prior sd of ``log h`` of a film with a measured thickness [-].
    start : sequence of float, optional
        ``log h`` per film where the run starts (the pilot's and the walkers' ``nominal``;
        e.g. a least-squares fit, :func:`bayespig.library.build.joint_least_squares_start`),
        clipped into the prior's box; default the prior's centre. The prior does not change.

    Raises
    ------
    ValueError
        Naming the argument: no films, duplicated ids, a measured thickness that is not
        positive, or an sd that is not a positive number.
    """

    title = "film thicknesses"
    variable = "film_thickness"
    dimension = "film"
    long_name = "film thickness h (relative to the nominal film unless measured)"
    units = "1"
    coordinate_name = "log_film_thickness"
    attribute = "film_thickness_prior"
    prior_scale = "log"
    #: Drawn from the prior as well (:attr:`~bayespig.inference.shared.SharedParameter.prior_proposals`):
    #: a film that hides its cards bounds its thickness only from below.
    prior_proposals = True

    def __init__(self, films, measured=None, relative_sd=RELATIVE_SD, measured_sd=MEASURED_RELATIVE_SD, start=None):
        films = tuple(str(f) for f in films)
        if not films:
            raise ValueError("films must name at least one film")
        if len(set(films)) != len(films):
            raise ValueError(f"films must be distinct, got {list(films)}")
        for name, value in (("relative_sd", relative_sd), ("measured_sd", measured_sd)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        measured = np.full(len(films), np.nan) if measured is None else np.asarray(measured, dtype=float)
        if measured.shape != (len(films),):
            raise ValueError(f"measured must have one value per film ({len(films)}), got shape {measured.shape}")
        known = np.isfinite(measured)
        if (measured[known] <= 0).any():
            bad = int(np.flatnonzero(known & (measured <= 0))[0])
            raise ValueError(f"measured thickness must be positive, got {measured[bad]:g} for film {films[bad]!r}")
        self.labels = self.films = films
        self.measured = measured
        self.relative_sd, self.measured_sd = float(relative_sd), float(measured_sd)
        self.mean = np.where(known, np.log(np.where(known, measured, 1.0)), 0.0)
        self.sd = np.where(known, self.measured_sd, self.relative_sd)
        self.lower = self.mean - THICKNESS_PRIOR_SDS * self.sd
        self.upper = self.mean + THICKNESS_PRIOR_SDS * self.sd
        if start is None:
            self.nominal = self.mean.copy()
        else:
            start = np.asarray(start, dtype=float)
            if start.shape != (len(films),) or not np.isfinite(start).all():
                raise ValueError(f"start must be one finite log h per film ({len(films)}), got {start!r}")
            # strictly inside the box: the walkers' start ball must not leave it
            margin = 1e-3 * self.sd
            self.nominal = np.clip(start, self.lower + margin, self.upper - margin)
        self.start_sd = 0.01 * self.sd

    @property
    def prior_mean(self):
        """Mean of every film's normal prior of ``log h``."""
        return self.mean

    @property
    def prior_sd(self):
        """Sd of every film's normal prior of ``log h``."""
        return self.sd

    def log_prior(self, x):
        """Normal in ``log h`` (up to a constant), (W,)."""
        return -0.5 * np.sum(((x - self.mean) / self.sd) ** 2, axis=1)

    def physical(self, x):
        """The thicknesses ``h = exp(log h)``."""
        return np.exp(x)

    def model_inputs(self, x):
        """``thickness``: every film's ``h``, (W, n_films)."""
        return {"thickness": np.exp(x)}

    def describe_prior(self):
        """The prior as text (provenance)."""
        return (f"log h ~ N(log h_measured, {self.measured_sd:g}^2) for a measured film, else "
                f"N(0, {self.relative_sd:g}^2) (relative thickness), truncated at {THICKNESS_PRIOR_SDS:g} sd")

    def describe(self):
        """Films, measured thicknesses and prior (JSON-able)."""
        return {"films": list(self.films),
                "measured": [None if not np.isfinite(v) else float(v) for v in self.measured],
                "relative_sd": self.relative_sd, "measured_sd": self.measured_sd, "prior": self.describe_prior()}
