"""Instruments: named sets of measurement channels, and exact predictions for them.

A *channel* is one number an instrument reports per wavelength: a BRDF at a
geometry (multi-angle gonio-spectrophotometers, ASTM E2194), a
directional–hemispherical reflectance with the specular component included (SCI)
or excluded (SCE) (8°/d spheres), or a 45°/0° reflectance factor (``pi`` times the
BRDF, relative to a perfect diffuser).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._validation import broadcast, real_array, real_scalar
from .physics.forward import surface_terms, validate_layer_arguments
from .physics.fresnel import fresnel_reflectance
from .physics.geometry import aspecular_to_geometry, geometry_label

__all__ = ["BUILT_IN_INSTRUMENTS", "Channel", "Instrument", "get_instrument", "predict"]

CHANNEL_KINDS = ("brdf", "hemispherical", "reflectance_factor")


@dataclass(frozen=True)
class Channel:
    """One measured quantity.

    Attributes
    ----------
    kind : {"brdf", "hemispherical", "reflectance_factor"}
        BRDF [1/sr]; directional–hemispherical reflectance [-]; ``pi * BRDF`` [-].
    theta_i : float
        Incidence angle in air [deg].
    theta_o : float
        Viewing angle in air [deg] (equal to ``theta_i`` for hemispherical channels).
    delta_phi : float
        Azimuth between the planes of incidence and viewing [deg], 180 = specular side.
    specular : {"excluded", "included"} or None
        For hemispherical channels, SCE or SCI.
    label : str
        Name of the channel, e.g. ``"45as15"`` or ``"8d-sci"``.
    """

    kind: str
    theta_i: float
    theta_o: float
    delta_phi: float = 180.0
    specular: str | None = None
    label: str = ""

    def __post_init__(self):
        if self.kind not in CHANNEL_KINDS:
            raise ValueError(f"channel kind must be one of {CHANNEL_KINDS}, got {self.kind!r}")
        for name in ("theta_i", "theta_o"):
            value = real_scalar(name, getattr(self, name))
            if not 0.0 <= value < 90.0:
                raise ValueError(f"{name} must lie in [0, 90) degrees, got {value}")
        real_scalar("delta_phi", self.delta_phi)
        if not isinstance(self.label, str):
            raise TypeError(f"label must be a string, got {self.label!r} ({type(self.label).__name__})")
        if self.kind == "hemispherical" and self.specular not in ("excluded", "included"):
            raise ValueError("a hemispherical channel needs specular='excluded' or 'included'")


@dataclass(frozen=True)
class Instrument:
    """A named tuple of channels and the binder index they are modelled with."""

    name: str
    channels: tuple
    n: float = 1.45

    @property
    def labels(self):
        """Channel labels, in order."""
        return tuple(channel.label for channel in self.channels)

    def __len__(self):
        return len(self.channels)


def _multi_angle(theta_i, aspeculars):
    channels = []
    for theta, aspecular in ((t, s) for t in theta_i for s in aspeculars[t]):
        _, theta_o, delta_phi = aspecular_to_geometry(theta, aspecular)
        channels.append(Channel("brdf", theta, theta_o, delta_phi, None, geometry_label(theta, aspecular)))
    return tuple(channels)


_ASPECULAR_45 = (-15.0, 15.0, 25.0, 45.0, 75.0, 110.0)
_ASPECULAR_15 = (-45.0, -15.0, 15.0, 45.0, 80.0)

BUILT_IN_INSTRUMENTS = {
    "multi-angle-45": _multi_angle((45.0,), {45.0: _ASPECULAR_45}),
    "multi-angle-45-15": _multi_angle((45.0, 15.0), {45.0: _ASPECULAR_45, 15.0: _ASPECULAR_15}),
    "8d-sci": (Channel("hemispherical", 8.0, 8.0, 0.0, "included", "8d-sci"),),
    "8d-sce": (Channel("hemispherical", 8.0, 8.0, 0.0, "excluded", "8d-sce"),),
    "45-0": (Channel("reflectance_factor", 45.0, 0.0, 180.0, None, "45-0"),),
}


def get_instrument(instrument, n=1.45):
    """An :class:`Instrument` from a built-in name, an instance, or a list of geometries.

    Parameters
    ----------
    instrument : str, Instrument, or sequence
        A built-in name (``"multi-angle-45"``, ``"multi-angle-45-15"``, ``"8d-sci"``,
        ``"8d-sce"``, ``"45-0"``), an :class:`Instrument`, or a sequence of ASTM E2194
        labels (``"45as15"``), ``(theta_i, theta_o, delta_phi)`` tuples [deg] or
        :class:`Channel` objects.
    n : float
        Binder index for instruments built here [-].

    Returns
    -------
    Instrument
    """
    from .physics.geometry import parse_geometry_label

    n = real_scalar("n", n, low=1.0)
    if isinstance(instrument, Instrument):
        return instrument
    if not isinstance(instrument, str) and not hasattr(instrument, "__iter__"):
        raise TypeError(
            "instrument must be a built-in name (" + ", ".join(BUILT_IN_INSTRUMENTS) + "), an "
            f"Instrument or a list of geometries, got {instrument!r} ({type(instrument).__name__})"
        )
    if isinstance(instrument, str):
        if instrument not in BUILT_IN_INSTRUMENTS:
            raise ValueError(
                f"unknown instrument {instrument!r}; built-in instruments: {', '.join(BUILT_IN_INSTRUMENTS)}"
            )
        return Instrument(instrument, BUILT_IN_INSTRUMENTS[instrument], n)
    channels = []
    for item in instrument:
        if isinstance(item, Channel):
            channels.append(item)
        elif isinstance(item, str):
            theta_i, theta_o, delta_phi = parse_geometry_label(item)
            channels.append(Channel("brdf", theta_i, theta_o, delta_phi, None, item.strip()))
        else:
            try:
                theta_i, theta_o, delta_phi = (real_scalar("instrument geometry", x) for x in item)
            except (TypeError, ValueError):
                raise TypeError(
                    "instrument geometries must be labels such as '45as15', Channel objects or "
                    f"(theta_i, theta_o, delta_phi) triples in degrees, got {item!r}"
                ) from None
            channels.append(Channel("brdf", theta_i, theta_o, delta_phi, None, f"{theta_i:g}/{theta_o:g}/{delta_phi:g}"))
    if not channels:
        raise ValueError("an instrument needs at least one channel")
    return Instrument("custom", tuple(channels), n)


def channel_directions(instrument):
    """Unique incidence and viewing angles of an instrument and each channel's index into them."""
    theta_in = np.unique([ch.theta_i for ch in instrument.channels])
    theta_out = np.unique([ch.theta_o for ch in instrument.channels])
    index_in = np.searchsorted(theta_in, [ch.theta_i for ch in instrument.channels])
    index_out = np.searchsorted(theta_out, [ch.theta_o for ch in instrument.channels])
    return theta_in, theta_out, index_in, index_out


def channel_values(instrument, terms, r_s):
    """Channel values from solved :class:`~bayespig.physics.forward.SurfaceTerms`.

    Parameters
    ----------
    instrument : Instrument
    terms : SurfaceTerms
        Solved for ``channel_directions(instrument)``, batch size B.
    r_s : numpy.ndarray
        Substrate albedo, shape (B,) [-].

    Returns
    -------
    numpy.ndarray
        Shape (B, n_channels).
    """
    _, _, index_in, index_out = channel_directions(instrument)
    out = np.empty((r_s.shape[0], len(instrument)))
    gain = terms.substrate_gain(r_s)
    m = np.arange(terms.f0_modes.shape[1])
    for k, ch in enumerate(instrument.channels):
        i, o = index_in[k], index_out[k]
        if ch.kind == "hemispherical":
            value = terms.h0[:, i] + gain * terms.t_down[:, i] * terms.t_up_hemispherical
            if ch.specular == "included":
                value = value + fresnel_reflectance(np.cos(np.radians(ch.theta_i)), 1.0, instrument.n)
        else:
            weights = (2.0 - (m == 0)) * (-1.0) ** m * np.cos(m * np.radians(ch.delta_phi))
            value = terms.f0_modes[:, :, o, i] @ weights + gain * terms.t_down[:, i] * terms.t_up[:, o]
            if ch.kind == "reflectance_factor":
                value = np.pi * value
        out[:, k] = value
    return out


def predict(instrument, *, a, tau, g=0.0, r_s=0.0):
    """Exact channel values of a paint layer (direct adding–doubling solve).

    Parameters
    ----------
    instrument : str, Instrument or sequence
        See :func:`get_instrument`.
    a, tau, g, r_s : array_like
        Relative absorption, optical thickness (``inf`` = opaque), phase-function
        parameter and substrate albedo seen from the binder, broadcast together.

    Returns
    -------
    numpy.ndarray
        Shape ``broadcast(a, tau, g, r_s).shape + (n_channels,)``.
    """
    instrument = get_instrument(instrument)
    a, tau, g, r_s = (
        real_array(name, value, allow_inf=True) for name, value in (("a", a), ("tau", tau), ("g", g), ("r_s", r_s))
    )
    validate_layer_arguments(a=a, tau=tau, g=g, r_s=r_s, n=instrument.n)
    a, tau, g, r_s = broadcast(a=a, tau=tau, g=g, r_s=r_s)
    shape = a.shape
    a, tau, g, r_s = (v.ravel() for v in (a, tau, g, r_s))
    theta_in, theta_out, _, _ = channel_directions(instrument)
    out = np.empty((a.size, len(instrument)))
    for g_value in np.unique(g):
        sel = np.flatnonzero(g == g_value)
        terms = surface_terms(theta_in, theta_out, a=a[sel], tau=tau[sel], g=float(g_value), n=instrument.n)
        out[sel] = channel_values(instrument, terms, r_s[sel])
    return out.reshape(shape + (len(instrument),))
