"""Selecting geometries and bands of a measurement set: a cone around the mirror direction,
grazing angles, wavelengths.

Real gonio data near the mirror direction are dominated by the surface's own gloss, and those
at grazing angles by edge effects and noise; :func:`select_measurements` returns a new
:class:`~bayespig.data.MeasurementSet` without them (and, optionally, with fewer bands), so
that a fit can be restricted to the geometries the model describes, or repeated on disjoint
subsets to see whether they agree.

Directions (``../shared/DESIGN.md`` section 1): ``theta_i``, ``theta_o`` from the normal,
``delta_phi`` the azimuth of the viewing direction measured from that of the source, with
``delta_phi = 180`` on the specular side. With the source direction ``s = (sin theta_i, 0,
cos theta_i)``, the mirror direction is ``r = (-sin theta_i, 0, cos theta_i)`` and the viewing
direction ``v = (sin theta_o cos delta_phi, sin theta_o sin delta_phi, cos theta_o)``, so the
angle between them is exactly

    cos(angle) = r . v = cos theta_i cos theta_o - sin theta_i sin theta_o cos delta_phi

(:func:`mirror_distance_deg`, computed through ``atan2(|r x v|, r . v)``, accurate at small
angles too).
"""

from __future__ import annotations

import dataclasses
import numbers

import numpy as np

from ._validation import flag
from .data.model import MeasurementSet

__all__ = ["DIRECTIONAL_KINDS", "OCCLUSION_RADIUS_DEG", "OCCLUSION_RATIO", "WAVELENGTH_MATCH_NM",
           "mirror_distance_deg", "occluded_geometries", "select_measurements"]

#: Measurement kinds with one viewing direction (the mirror cone applies to them; the
#: hemispherical ones integrate over all viewing directions, a transmittance has none).
DIRECTIONAL_KINDS = ("brdf", "reflectance_factor")
#: A wavelength asked for matches a measured one within this [nm].
WAVELENGTH_MATCH_NM = 1e-6
#: :func:`occluded_geometries`: the neighbours of a geometry are the film's geometries at the same
#: incidence whose viewing direction lies within this angle of its own [deg] ...
OCCLUSION_RADIUS_DEG = 15.0
#: ... and it is occluded when its brightest band is below this fraction of the median of its
#: neighbours' brightest bands (50 times darker than its surroundings at every wavelength) [-].
OCCLUSION_RATIO = 0.02


def mirror_distance_deg(theta_i, theta_o, delta_phi):
    """Angle between the viewing direction and the mirror direction of the incident light [deg].

    Parameters
    ----------
    theta_i, theta_o : array_like
        Incidence and viewing angles from the normal [deg].
    delta_phi : array_like
        Azimuth of the viewing direction from that of the source [deg]; 180 on the specular
        side (``theta_o = theta_i, delta_phi = 180`` is the mirror direction itself).

    Returns
    -------
    numpy.ndarray
        In [0, 180] [deg], broadcast.
    """
    ti, to, dp = (np.radians(np.asarray(x, dtype=float)) for x in (theta_i, theta_o, delta_phi))
    mirror = np.stack(np.broadcast_arrays(-np.sin(ti), np.zeros_like(ti), np.cos(ti)), axis=-1)
    view = np.stack(np.broadcast_arrays(np.sin(to) * np.cos(dp), np.sin(to) * np.sin(dp), np.cos(to)), axis=-1)
    mirror, view = np.broadcast_arrays(mirror, view)
    cross = np.linalg.norm(np.cross(mirror, view), axis=-1)
    dot = np.sum(mirror * view, axis=-1)
    return np.degrees(np.arctan2(cross, dot))


def _angle_argument(name, value, low, high):
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be None or a number of degrees in [{low:g}, {high:g}], "
                        f"got {type(value).__name__} {value!r}")
    value = float(value)
    if not (np.isfinite(value) and low <= value <= high):
        raise ValueError(f"{name} must be None or a number of degrees in [{low:g}, {high:g}], got {value!r}")
    return value


def _wavelength_mask(measured, wavelengths, wavelength_range):
    keep = np.ones(measured.size, dtype=bool)
    shown = f"{measured[0]:g}–{measured[-1]:g} nm" if measured.size > 1 else f"{measured[0]:g} nm"
    if wavelengths is not None:
        if isinstance(wavelengths, (str, bytes)) or np.ndim(wavelengths) != 1:
            raise TypeError(f"wavelengths must be None or a sequence of wavelengths [nm], got {wavelengths!r}")
        try:
            wanted = np.asarray(wavelengths, dtype=float)
        except (TypeError, ValueError):
            raise TypeError(f"wavelengths must be None or a sequence of wavelengths [nm], "
                            f"got {wavelengths!r}") from None
        if wanted.size == 0:
            raise ValueError("wavelengths must not be empty (None keeps every band)")
        distance = np.abs(wanted[:, None] - measured[None, :])
        missing = wanted[distance.min(axis=1) > WAVELENGTH_MATCH_NM]
        if missing.size:
            raise ValueError(f"wavelengths {', '.join(f'{w:g}' for w in missing)} nm are not measured "
                             f"(the set has {measured.size} bands, {shown})")
        keep &= (distance <= WAVELENGTH_MATCH_NM).any(axis=0)
    if wavelength_range is not None:
        try:
            low, high = (float(v) for v in wavelength_range)
        except (TypeError, ValueError):
            raise TypeError("wavelength_range must be None or a pair (low, high) of wavelengths [nm], "
                            f"got {wavelength_range!r}") from None
        if not (np.isfinite(low) and np.isfinite(high) and low <= high):
            raise ValueError(f"wavelength_range must be (low, high) with low <= high [nm], got {wavelength_range!r}")
        keep &= (measured >= low - WAVELENGTH_MATCH_NM) & (measured <= high + WAVELENGTH_MATCH_NM)
        if not keep.any():
            raise ValueError(f"wavelength_range {low:g}–{high:g} nm leaves no band of the set ({shown})")
    return keep


def _viewing_directions(theta_o, delta_phi):
    """Unit viewing vectors (n, 3) (the module docstring's ``v``)."""
    theta, phi = np.radians(theta_o), np.radians(delta_phi)
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)


def occluded_geometries(measurements, *, radius_deg=OCCLUSION_RADIUS_DEG, ratio=OCCLUSION_RATIO):
    """The BRDF geometries of each film that read (nearly) nothing where their surroundings are bright.

    A gonioreflectometer's reading can be blocked (the detector or sample holder in the beam, a
    shadowed sample edge at grazing angles): it is then near 0 in *every* band, while the paint's
    BRDF varies smoothly with the direction. A geometry is flagged when even its brightest band
    is below ``ratio`` times the median of its neighbours' brightest bands (the neighbours: the
    film's BRDF geometries at the same ``theta_i`` whose viewing direction lies within
    ``radius_deg`` of its own, itself excluded; at least two): darker than its surroundings at
    every wavelength, where a dark band of the paint (a red's blue end) is dark for all of
    them and tells nothing. No model enters: a screen for readings that are not the paint, to be looked at
    (``bayespig check`` lists them) and excluded on purpose (``select_measurements(...,
    exclude_occluded=True)``). On the Cornell paints it flags the three geometries theta_i = 80°,
    theta_o = 79°, delta_phi = 160-170° (10-20° from the mirror, inside the grazing gloss lobe) that
    read below 0.002 1/sr in all 31 bands of both paints, next to neighbours of 0.05-5.7 1/sr.

    Parameters
    ----------
    measurements : MeasurementSet
    radius_deg : float
        Neighbourhood of a viewing direction [deg], in (0, 180].
    ratio : float
        How dark a geometry's brightest band must be, relative to the median of its neighbours'
        brightest bands [-], in (0, 1).

    Returns
    -------
    dict
        Film sample name -> indices into its ``measurements`` (ascending; films without such
        geometries are left out).
    """
    if not isinstance(measurements, MeasurementSet):
        raise TypeError(f"measurements must be a MeasurementSet, got {type(measurements).__name__}")
    radius_deg = _angle_argument("radius_deg", radius_deg, 0.0, 180.0)
    if not (isinstance(ratio, numbers.Real) and 0.0 < ratio < 1.0):
        raise ValueError(f"ratio must be a number in (0, 1), got {ratio!r}")
    cos_radius = np.cos(np.radians(radius_deg))
    found = {}
    for sample in measurements.samples:
        if sample.role not in ("film", "film_on_glass"):
            continue
        index = np.array([k for k, m in enumerate(sample.measurements) if m.kind == "brdf"], dtype=int)
        if index.size < 3:
            continue
        rows = [sample.measurements[k] for k in index]
        theta_i = np.array([m.theta_i for m in rows])
        view = _viewing_directions(np.array([m.theta_o for m in rows]), np.array([m.delta_phi for m in rows]))
        peak = np.array([m.values for m in rows], dtype=float).max(axis=1)  # each geometry's brightest band
        flagged = []
        for j in range(index.size):
            near = (theta_i == theta_i[j]) & (view @ view[j] >= cos_radius)
            near[j] = False
            if near.sum() < 2:
                continue
            if peak[j] < ratio * np.median(peak[near]):
                flagged.append(int(index[j]))
        if flagged:
            found[sample.name] = flagged
    return found


def _describe(exclude_mirror_deg, max_angle_deg, exclude_occluded=False):
    parts = []
    if exclude_mirror_deg is not None:
        parts.append(f"the mirror cone of {exclude_mirror_deg:g}°")
    if max_angle_deg is not None:
        parts.append(f"max angle {max_angle_deg:g}°")
    if exclude_occluded:
        parts.append("the occluded geometries")
    return " and ".join(parts)


def select_measurements(measurements, *, exclude_mirror_deg=None, max_angle_deg=None, wavelengths=None,
                        wavelength_range=None, exclude_occluded=False):
    """A new measurement set without the geometries near the mirror or at grazing angles, and
    with some bands only.

    The geometry selection applies to the films (the samples whose pigment is fitted);
    substrate samples, whose measurements give ``r_s`` (eq. 9 inverted), are kept whole.

    Parameters
    ----------
    measurements : MeasurementSet
    exclude_mirror_deg : float, optional
        Drop every directional measurement (BRDF, 45°/0°) whose viewing direction lies within
        this angle of the mirror direction of its incident light (:func:`mirror_distance_deg`;
        the cone is closed: a geometry exactly on its edge is dropped) [deg, 0–180].
    max_angle_deg : float, optional
        Drop every measurement with ``theta_i`` or ``theta_o`` larger than this (grazing
        incidence or viewing) [deg, 0–90].
    wavelengths : sequence of float, optional
        Keep these bands only; each must be measured (within :data:`WAVELENGTH_MATCH_NM`) [nm].
    wavelength_range : (float, float), optional
        Keep the bands in ``[low, high]`` only [nm].
    exclude_occluded : bool
        Drop the films' BRDF geometries that :func:`occluded_geometries` flags (readings near 0
        in every band amid bright neighbours: blocked, not the paint), found on all bands
        before the band selection.

    Returns
    -------
    MeasurementSet
        The same samples and metadata (with the selection recorded in ``metadata["selection"]``)
        and the same source; the set itself when nothing is asked.

    Raises
    ------
    TypeError, ValueError
        For an argument of the wrong kind or value (named), a wavelength that is not measured,
        a selection that leaves no band, or one that leaves a film without measurements
        (``the mirror cone of 5° and max angle 60° leave no geometry of film 'x'``).
    """
    if not isinstance(measurements, MeasurementSet):
        raise TypeError(f"measurements must be a MeasurementSet, got {type(measurements).__name__}")
    exclude_mirror_deg = _angle_argument("exclude_mirror_deg", exclude_mirror_deg, 0.0, 180.0)
    max_angle_deg = _angle_argument("max_angle_deg", max_angle_deg, 0.0, 90.0)
    measured = np.asarray(measurements.wavelength_nm, dtype=float)
    bands = _wavelength_mask(measured, wavelengths, wavelength_range)
    exclude_occluded = flag("exclude_occluded", exclude_occluded)
    if exclude_mirror_deg is None and max_angle_deg is None and bands.all() and not exclude_occluded:
        return measurements
    occluded = occluded_geometries(measurements) if exclude_occluded else {}
    dropped_labels = {}  # film -> labels of its occluded geometries dropped
    samples = []
    for sample in measurements.samples:
        kept = []
        dropped = set(occluded.get(sample.name, ()))
        for k, m in enumerate(sample.measurements):
            if k in dropped:
                dropped_labels.setdefault(sample.name, []).append(m.label)
                continue
            if sample.role in ("film", "film_on_glass"):
                if max_angle_deg is not None and max(m.theta_i, m.theta_o) > max_angle_deg:
                    continue
                if (exclude_mirror_deg is not None and m.kind in DIRECTIONAL_KINDS
                        and mirror_distance_deg(m.theta_i, m.theta_o, m.delta_phi) <= exclude_mirror_deg):
                    continue
            kept.append(m if bands.all() else dataclasses.replace(m, values=np.asarray(m.values)[bands]))
        if not kept:
            verb = "leaves" if (exclude_mirror_deg is not None) + (max_angle_deg is not None) + bool(
                exclude_occluded) == 1 else "leave"
            raise ValueError(f"{_describe(exclude_mirror_deg, max_angle_deg, exclude_occluded)} {verb} no geometry of "
                             f"film {sample.name!r} (it has {len(sample.measurements)}: "
                             f"{', '.join(m.label for m in sample.measurements[:6])}"
                             f"{', ...' if len(sample.measurements) > 6 else ''})")
        samples.append(dataclasses.replace(sample, measurements=tuple(kept)))
    metadata = dict(measurements.metadata)
    metadata["selection"] = {"exclude_mirror_deg": exclude_mirror_deg, "max_angle_deg": max_angle_deg,
                             "wavelength_nm": [float(w) for w in measured[bands]],
                             "occluded": dropped_labels}
    return MeasurementSet(measured[bands], samples, n=measurements.n, metadata=metadata,
                          source=measurements.source)
