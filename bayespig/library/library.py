"""A pigment library: posterior draws of every pigment's constants, saved as one netCDF file.

Made by :func:`bayespig.library.build_library`; read back by :func:`load_library`. The file
is an arviz InferenceData netCDF (:func:`bayespig.inference.save_inference`'s format): group
``posterior`` holds ``constants`` over ``(chain, draw, wavelength, pigment, constant)`` (one
chain: the draws of each pigment come from its own stage, see :mod:`bayespig.library.build`)
and ``film_thickness`` over ``(chain, draw, film)`` (NaN for films no stage used); a library
built with card factors (``build_library(..., substrate_sd=...)``) also ``card_factor`` over
``(chain, draw, film, card)``, ``card`` the card's place among its film's cards (0, 1, ...; NaN
where a film has fewer cards or was unused) and the cards' names in the attribute
``card_names``; the rest (films, stages, provenance, densities, model error) is JSON in the
posterior's attributes.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from .._atomic import atomic_path
from .._storage import read_netcdf

__all__ = ["LIBRARY_FORMAT", "PigmentLibrary", "load_library"]

#: Format tag of a saved library (attribute ``bayespig_library``).
LIBRARY_FORMAT = 1


@dataclasses.dataclass(frozen=True, eq=False)
class PigmentLibrary:
    """Posterior of every pigment's constants from films of known recipes.

    Attributes
    ----------
    model : str
        Film model name (``"radiative-transfer"``).
    pigments : tuple of str
    wavelength_nm : numpy.ndarray
        (n_wl,) [nm].
    constants : numpy.ndarray
        Posterior draws of the sampled coordinates per pigment, (n_draws, n_wl, n_pigments, 2)
        (radiative transfer: ``[a, log sigma]``; ``sigma`` is the optical thickness per unit
        concentration and unit film thickness).
    constant_names : tuple of str
        The two coordinates' names.
    thickness_prior : tuple of float
        ``(mean, sd)`` of ``log h`` over the library's films (posterior medians): the thickness
        of a new film of unknown thickness made the same way.
    films : tuple of dict
        Per film: ``id``, ``recipe`` (pigment -> mass fraction), ``pigments``, ``stage``,
        ``used``, ``thickness_median``/``_q05``/``_q95`` and ``rms_log_deviation`` (rms of
        ``log(measured / predicted)`` at the posterior median prediction; fit quality); with
        card factors also ``card_factors``, per card ``card``, ``median``, ``q05``, ``q95`` and
        ``implausible`` (the 90 % interval beyond 3 prior sds, :data:`bayespig.library.build.IMPLAUSIBLE_SDS`).
    film_ids : tuple of str
        The ``film`` axis of :attr:`thickness`.
    thickness : numpy.ndarray
        Draws of every film's thickness ``h``, (n_draws, n_films); NaN for unused films.
    densities : dict or None
        Pigment densities given to the build [g/cm^3].
    model_error : numpy.ndarray or None
        The model error learned by cross-validation (:func:`bayespig.library.validation.cross_validate`):
        the covariance over wavelengths of relative residuals (n_wl, n_wl), scaled by its
        calibration factor (``provenance["model_error"]["calibration"]``), or a per-wavelength
        relative sd (n_wl,); None until then (predictions then hold the constants' uncertainty only).
    provenance : dict
        Seed, settings, package versions, stage plan, the look-up tables used (``table_checksums``:
        key -> SHA-256 of their arrays).
    stages : tuple of dict
        Per stage group: pigments, films, steps, cap, R-hat and ESS of thicknesses and constants
        (and of the card factors when sampled).
    card_factor : numpy.ndarray or None
        Draws of the factor ``f`` of every film's cards, ``r_s = f r_s,card`` [-], (n_draws,
        n_films, n_cards) (``n_cards`` the most cards of one film; NaN where a film has fewer or
        was unused); None for a library built without card factors.
    card_names : tuple of tuple of str or None
        Per film (the order of :attr:`film_ids`) the names of its cards along ``card`` (``""``
        where it has fewer).
    concentration_factor : numpy.ndarray or None
        Draws of the factor ``f`` on each film's minor pigments' concentrations, ``D_eff = f D``
        [-], (n_draws, n_films, n_components) (NaN where a film has fewer); None for a library
        built without them (``build_library(..., concentration_sd=...)``).
    concentration_names : tuple of tuple of str or None
        Per film the pigment of each ``component`` (``""`` where it has fewer).
    """

    model: str
    pigments: tuple
    wavelength_nm: np.ndarray
    constants: np.ndarray
    constant_names: tuple
    thickness_prior: tuple
    films: tuple
    film_ids: tuple
    thickness: np.ndarray
    densities: dict | None
    model_error: np.ndarray | None
    provenance: dict
    stages: tuple
    card_factor: np.ndarray | None = None
    card_names: tuple | None = None
    concentration_factor: np.ndarray | None = None
    concentration_names: tuple | None = None

    def __repr__(self):
        return (f"PigmentLibrary({self.model!r}, {len(self.pigments)} pigments, {len(self.film_ids)} films, "
                f"{self.constants.shape[0]} draws, {self.wavelength_nm.size} wavelengths)")

    def step_cap_reached(self, *, inherited=True):
        """Whether a stage of the library's staged posterior reached its sampler's step cap.

        Parameters
        ----------
        inherited : bool
            Count the stages inherited from the base library it was built on
            (``provenance["base_library"]``: stages whose pigments are all the base's); with
            False only the library's own stages.

        Returns
        -------
        bool
        """
        base = self.provenance.get("base_library")
        base_pigments = set(base["pigments"]) if base and not inherited else None
        return any(stage.get("max_steps_reached") for stage in self.stages
                   if base_pigments is None or not set(stage.get("pigments", ())) <= base_pigments)

    def to_inference_data(self):
        """The library as an :class:`arviz.InferenceData` (what :meth:`save` writes)."""
        import arviz as az
        import xarray as xr

        attrs = {
            "bayespig_library": LIBRARY_FORMAT, "model": self.model,
            "constant_names": json.dumps(list(self.constant_names)),
            "thickness_prior": json.dumps(list(self.thickness_prior)),
            "films": json.dumps(list(self.films)), "stages": json.dumps(list(self.stages)),
            "densities": json.dumps(self.densities), "provenance": json.dumps(self.provenance),
        }
        data = {
            "constants": (("chain", "draw", "wavelength", "pigment", "constant"), self.constants[None]),
            "film_thickness": (("chain", "draw", "film"), self.thickness[None]),
        }
        coords = {"chain": [0], "draw": np.arange(self.constants.shape[0]), "wavelength": self.wavelength_nm,
                  "pigment": list(self.pigments), "constant": list(self.constant_names), "film": list(self.film_ids)}
        if self.card_factor is not None:
            data["card_factor"] = (("chain", "draw", "film", "card"), np.asarray(self.card_factor, dtype=float)[None])
            coords["card"] = np.arange(self.card_factor.shape[2])
            attrs["card_names"] = json.dumps([list(names) for names in self.card_names])
        if self.concentration_factor is not None:
            data["concentration_factor"] = (("chain", "draw", "film", "component"),
                                            np.asarray(self.concentration_factor, dtype=float)[None])
            coords["component"] = np.arange(self.concentration_factor.shape[2])
            attrs["concentration_names"] = json.dumps([list(names) for names in self.concentration_names])
        if self.model_error is not None:
            error = np.asarray(self.model_error, dtype=float)
            if error.ndim == 2:  # a covariance over wavelengths
                data["model_error"] = (("wavelength", "wavelength_other"), error)
                coords["wavelength_other"] = self.wavelength_nm
            else:
                data["model_error"] = (("wavelength",), error)
        posterior = xr.Dataset(data, coords=coords, attrs=attrs)
        posterior["wavelength"].attrs["units"] = "nm"
        if "card_factor" in posterior:
            posterior["card_factor"].attrs.update(
                long_name="factor on the card's albedo seen from the binder, r_s / r_s,card", units="1")
        return az.InferenceData(posterior=posterior)

    def save(self, path):
        """Write the library to one netCDF file, atomically (whole or not at all).

        Parameters
        ----------
        path : str or os.PathLike

        Returns
        -------
        pathlib.Path
        """
        idata = self.to_inference_data()
        with atomic_path(path, suffix=".nc") as tmp:
            idata.to_netcdf(str(tmp))
        from pathlib import Path

        return Path(path)


def load_library(path):
    """Read a library written by :meth:`PigmentLibrary.save`.

    Raises
    ------
    ValueError
        Naming the file when it is missing, damaged, or not a bayespig pigment library.
    """
    idata = read_netcdf(path)
    posterior = getattr(idata, "posterior", None)
    if posterior is None or posterior.attrs.get("bayespig_library") != LIBRARY_FORMAT:
        raise ValueError(f"'{path}' is not a bayespig pigment library (no 'bayespig_library' = "
                         f"{LIBRARY_FORMAT} attribute)")
    attrs = posterior.attrs
    model_error = posterior["model_error"].values if "model_error" in posterior else None
    card_factor = (np.asarray(posterior["card_factor"].values[0], dtype=float) if "card_factor" in posterior
                   else None)
    card_names = (tuple(tuple(str(c) for c in names) for names in json.loads(attrs["card_names"]))
                  if card_factor is not None else None)
    concentration_factor = (np.asarray(posterior["concentration_factor"].values[0], dtype=float)
                            if "concentration_factor" in posterior else None)
    concentration_names = (tuple(tuple(str(c) for c in names) for names in json.loads(attrs["concentration_names"]))
                           if concentration_factor is not None else None)
    return PigmentLibrary(
        model=str(attrs["model"]), pigments=tuple(str(p) for p in posterior["pigment"].values),
        wavelength_nm=np.asarray(posterior["wavelength"].values, dtype=float),
        constants=np.asarray(posterior["constants"].values[0], dtype=float),
        constant_names=tuple(json.loads(attrs["constant_names"])),
        thickness_prior=tuple(json.loads(attrs["thickness_prior"])),
        films=tuple(json.loads(attrs["films"])), film_ids=tuple(str(f) for f in posterior["film"].values),
        thickness=np.asarray(posterior["film_thickness"].values[0], dtype=float),
        densities=json.loads(attrs["densities"]), model_error=model_error,
        provenance=json.loads(attrs["provenance"]), stages=tuple(json.loads(attrs["stages"])),
        card_factor=card_factor, card_names=card_names,
        concentration_factor=concentration_factor, concentration_names=concentration_names)
