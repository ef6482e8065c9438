"""Simulated measurement sets: the paper's sample designs with its multiplicative noise (eq. 7).

Given a pigment (``a``, ``tau``, ``g``, scalars or spectra) and a sample design,
:func:`simulate` computes every measured value with the forward model and
distorts it as the paper does (section 4.1, eq. 7)::

    x_obs = x_true * (1 + eps * xi),    xi ~ N(0, 1) independently,

with ``xi`` drawn from ``numpy.random.default_rng(seed)``. Substrate albedos
(``"black"`` = 0.01, ``"white"`` = 0.95) are not distorted, as in the paper.
"""

from __future__ import annotations

import dataclasses
import functools
import numbers
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from .._validation import integer
from ..instruments import get_instrument, predict
from ..likelihood import method_name
from ..physics.forward import specular_transmittance
from ..physics.substrate import clear_binder_brdf, clear_binder_reflectance
from .model import (
    BLACK_SUBSTRATE_ALBEDO,
    METHODS,
    WHITE_SUBSTRATE_ALBEDO,
    Measurement,
    MeasurementSet,
    Sample,
    value_problem,
    wavelength_problem,
)

__all__ = ["DESIGNS", "FilmSpec", "simulate", "simulate_to_csv"]

_NAMED = {"black": BLACK_SUBSTRATE_ALBEDO, "white": WHITE_SUBSTRATE_ALBEDO}
#: Default wavelengths of a simulation: 400–700 nm in 10 nm steps [nm].
DEFAULT_WAVELENGTHS_NM = np.arange(400.0, 701.0, 10.0)
DEFAULT_WAVELENGTHS_NM.flags.writeable = False


@dataclass(frozen=True)
class FilmSpec:
    """One film of a custom sample design.

    Attributes
    ----------
    name : str
        Sample name.
    substrate : float or {"black", "white"}
        Albedo of the substrate seen from the binder [-] (ignored for opaque films).
    tau_scale : float
        The film's optical thickness is ``tau_scale * tau`` [-] (a thicker or thinner drawdown).
    opaque : bool
        ``tau = inf`` (eq. 2).
    on_glass : bool
        A film on glass measured in specular transmittance at normal incidence (eq. 5)
        instead of in reflectance.
    film_group : str or None
        Films of one group share ``tau`` (and so must share ``tau_scale``).
    measure_substrate : bool
        Also simulate the bare substrate measured from air with the instrument
        (a Lambertian surface under clear binder, eq. 9), as a sample
        ``"<name>_substrate"`` that the film refers to.
    """

    name: str
    substrate: float | str = "black"
    tau_scale: float = 1.0
    opaque: bool = False
    on_glass: bool = False
    film_group: str | None = None
    measure_substrate: bool = False


#: The paper's designs (section 3): the films each method measures.
DESIGNS = {
    "method1": (FilmSpec("opaque", opaque=True), FilmSpec("on_glass", on_glass=True)),
    "method2": (FilmSpec("opaque", opaque=True), FilmSpec("on_black", substrate="black")),
    "method3": (FilmSpec("on_black", substrate="black"),),
    "method4": (
        FilmSpec("on_black", substrate="black", film_group="film"),
        FilmSpec("on_white", substrate="white", film_group="film"),
    ),
}


def _spectrum(name, value, n_wavelengths):
    array = np.asarray(value, dtype=float)
    if array.ndim == 0:
        array = np.full(n_wavelengths, float(array))
    if array.shape != (n_wavelengths,):
        raise ValueError(
            f"{name} must be a scalar or have one value per wavelength ({n_wavelengths}), "
            f"got shape {array.shape}"
        )
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite")
    return array


def _film_specs(design):
    if isinstance(design, (str, numbers.Integral)) and not isinstance(design, bool):
        try:  # 4, "4" and "method4" alike, as everywhere
            return DESIGNS[method_name(design, also=(), argument="design")]
        except ValueError:
            raise ValueError(
                f"design must be one of {', '.join(METHODS)} (or their numbers 1-4) or a list of "
                f"FilmSpec, got {design!r}"
            ) from None
    if isinstance(design, (bool, Mapping, FilmSpec)) or not isinstance(design, Iterable):
        raise TypeError(
            f"design must be a method ({', '.join(METHODS)}, or 1-4) or a list of FilmSpec or "
            f"dict, got {type(design).__name__} {design!r}"
        )
    specs = []
    for k, item in enumerate(design):
        if isinstance(item, FilmSpec):
            specs.append(item)
        elif isinstance(item, Mapping):
            item = dict(item)
            item.setdefault("name", f"film{k + 1}")
            try:
                specs.append(FilmSpec(**item))
            except TypeError as error:
                raise ValueError(f"design[{k}]: {error}") from None
        else:
            raise TypeError(f"design[{k}] must be a FilmSpec or a dict, got {type(item).__name__}")
    if not specs:
        raise ValueError("design needs at least one film")
    return tuple(specs)


def _substrate_albedo(spec):
    if isinstance(spec.substrate, str):
        if spec.substrate not in _NAMED:
            raise ValueError(
                f"film {spec.name!r}: substrate must be 'black', 'white' or an albedo in [0, 1], "
                f"got {spec.substrate!r}"
            )
        return _NAMED[spec.substrate]
    value = float(spec.substrate)
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"film {spec.name!r}: substrate albedo must lie in [0, 1], got {value}")
    return value


def _substrate_in_air(instrument, r_s):
    """Bare substrate seen from air with every channel: eq. (9) and its hemispherical integral."""
    values = []
    for ch in instrument.channels:
        if ch.kind == "hemispherical":
            values.append(
                clear_binder_reflectance(ch.theta_i, r_s=r_s, n=instrument.n, specular=ch.specular)
            )
        else:
            brdf = clear_binder_brdf(ch.theta_i, ch.theta_o, r_s=r_s, n=instrument.n)
            values.append(np.pi * brdf if ch.kind == "reflectance_factor" else brdf)
    return np.stack(np.broadcast_arrays(*values), axis=-1)


def simulate(
    *,
    a,
    tau,
    design,
    instrument="multi-angle-45",
    wavelengths=DEFAULT_WAVELENGTHS_NM,
    eps=0.05,
    seed=0,
    g=0.0,
    n=1.45,
    model=None,
):
    """A simulated measurement set of one pigment.

    Parameters
    ----------
    a : float or array_like
        Relative absorption ``1 - omega`` [-], a scalar or one value per wavelength.
    tau : float or array_like
        Optical thickness of the (thin) film [-], scalar or per wavelength;
        films of a custom design scale it by their ``tau_scale``.
    design : {"method1", "method2", "method3", "method4"} or list of FilmSpec or dict
        ``"method1"``: an opaque film on the instrument and the film on glass
        (specular transmittance); ``"method2"``: an opaque film and the thin
        film on black; ``"method3"``: the thin film on black; ``"method4"``: the
        same thin film on black (``r_s = 0.01``) and on white (``r_s = 0.95``),
        one film group (section 3). A list describes any other design (see
        :class:`FilmSpec`; dicts take the same keys).
    instrument : str, Instrument or sequence
        See :func:`bayespig.instruments.get_instrument`.
    wavelengths : array_like
        Wavelengths [nm]; default 400, 410, ..., 700.
    eps : float
        Relative measurement error of eq. (7) [-]; 0 gives noise-free values.
    seed : int
        Seed of ``numpy.random.default_rng``; the same seed gives the same set.
    g : float
        Henyey–Greenstein parameter [-].
    n : float
        Binder refractive index [-].
    model : callable, optional
        ``model(a=, tau=, g=, r_s=) -> (..., n_channels)`` for the instrument's
        channels, e.g. a look-up table from :func:`bayespig.load_table`; default
        the exact solver :func:`bayespig.instruments.predict`.

    Returns
    -------
    MeasurementSet
        Metadata records the truth (``a``, ``tau`` per film group, ``g``, ``r_s``
        of measured substrates), ``seed``, ``eps``, ``design``, ``instrument``.

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), section 4.1, eq. (7); eq. (5) for the
    film on glass; eq. (9) for substrates measured from air.
    """
    wavelength_nm = np.asarray(wavelengths, dtype=float)
    if wavelength_nm.ndim != 1 or wavelength_nm.size == 0:
        raise ValueError("wavelengths must be a non-empty 1-D array [nm]")
    if np.isfinite(wavelength_nm).all() and (unit := wavelength_problem(wavelength_nm)):
        raise ValueError(f"argument 'wavelengths': {unit[1]}")
    n_wl = wavelength_nm.size
    a = _spectrum("a", a, n_wl)
    tau = _spectrum("tau", tau, n_wl)
    if ((a < 0) | (a > 1)).any():
        raise ValueError("a (relative absorption) must lie in [0, 1]")
    if (tau <= 0).any():
        raise ValueError("tau must be > 0 (opaque films are part of the design)")
    if not (np.isfinite(eps) and eps >= 0):
        raise ValueError(f"eps must be a finite number >= 0, got {eps!r}")
    instrument = get_instrument(instrument, n=n)
    if instrument.n != n:
        instrument = dataclasses.replace(instrument, n=n)
    if model is None:
        model = functools.partial(predict, instrument)
    elif hasattr(model, "instrument") and tuple(model.instrument.labels) != tuple(
        instrument.labels
    ):
        raise ValueError(
            f"model is for channels {model.instrument.labels}, not the instrument's "
            f"{instrument.labels}"
        )
    specs = _film_specs(design)
    seed = integer("seed", seed, low=0)  # recorded in the metadata; bools refused
    rng = np.random.default_rng(seed)

    def distort(values):
        noisy = values * (1.0 + eps * rng.standard_normal(values.shape))
        if (noisy < 0).any():
            raise ValueError(
                f"eps = {eps} made a simulated value negative (1 + eps * xi < 0); "
                "eq. (7) only makes sense for eps well below 0.2"
            )
        return noisy

    samples, truth_tau, truth_r_s, group_scale = [], {}, {}, {}
    for spec in specs:
        group = spec.film_group or spec.name
        if group in group_scale and (group_scale[group] != (spec.tau_scale, spec.opaque)):
            raise ValueError(
                f"films of group {group!r} must share tau_scale and opaque (they share tau)"
            )
        group_scale[group] = (spec.tau_scale, spec.opaque)
        if not spec.tau_scale > 0:
            raise ValueError(f"film {spec.name!r}: tau_scale must be > 0")
        film_tau = np.full(n_wl, np.inf) if spec.opaque else tau * spec.tau_scale
        if not spec.opaque:
            truth_tau[group] = film_tau
        if spec.on_glass:
            if spec.opaque:
                raise ValueError(f"film {spec.name!r}: a film on glass cannot be opaque")
            values = distort(specular_transmittance(film_tau, n=n))
            samples.append(
                Sample(
                    spec.name,
                    "film_on_glass",
                    (Measurement.from_geometry("specular_transmittance", "normal", values),),
                    film_group=spec.film_group,
                )
            )
            continue
        r_s = 0.0 if spec.opaque else _substrate_albedo(spec)
        substrate = None if spec.opaque else spec.substrate
        if spec.measure_substrate and not spec.opaque:
            card = f"{spec.name}_substrate"
            card_values = distort(
                np.broadcast_to(_substrate_in_air(instrument, r_s), (n_wl, len(instrument)))
            )
            samples.append(
                Sample(
                    card,
                    "substrate",
                    tuple(
                        Measurement.from_channel(ch, card_values[:, k])
                        for k, ch in enumerate(instrument.channels)
                    ),
                )
            )
            substrate = card
            truth_r_s[spec.name] = r_s
        values = np.asarray(model(a=a, tau=film_tau, g=g, r_s=r_s), dtype=float).reshape(
            n_wl, len(instrument)
        )
        values = distort(values)
        samples.append(
            Sample(
                spec.name,
                "film",
                tuple(
                    Measurement.from_channel(ch, values[:, k])
                    for k, ch in enumerate(instrument.channels)
                ),
                substrate=substrate,
                film_group=spec.film_group,
                opaque=spec.opaque,
            )
        )

    metadata = {
        "generator": "bayespig.simulate",
        "design": (method_name(design, also=(), argument="design") if isinstance(design, (str, numbers.Integral))
                   else [dataclasses.asdict(s) for s in specs]),
        "instrument": instrument.name
        if isinstance(instrument.name, str) and instrument.name != "custom"
        else list(instrument.labels),
        "seed": int(seed),
        "eps": float(eps),
        "truth": {
            "a": a,
            "tau": truth_tau,
            "g": float(g),
            **({"r_s": truth_r_s} if truth_r_s else {}),
        },
    }
    return MeasurementSet(wavelength_nm, samples, n=n, metadata=metadata)


def simulate_to_csv(path, **kwargs):
    """Simulate (see :func:`simulate`) and write the set as a bayespig CSV file, atomically.

    Returns
    -------
    MeasurementSet
        What was written.
    """
    measurements = simulate(**kwargs)
    for sample in measurements.samples:  # what the readers would refuse is not written
        for measurement in sample.measurements:
            problem = value_problem(measurement.kind, measurement.values)
            if problem is not None:
                index, message = problem
                raise ValueError(
                    f"the simulated set cannot be written as a measurement file: sample "
                    f"{sample.name!r}, geometry {measurement.label}, "
                    f"{measurements.wavelength_nm[index]:g} nm: {message} (the noise, eps, "
                    "took it there; a reader would refuse it)"
                )
    measurements.to_csv(path)
    return measurements
