"""Measurement geometries: ASTM E2194 aspecular labels and angle conventions.

Angles are in air, in degrees. ``delta_phi = 180`` is the specular side of the
plane of incidence, ``0`` the side of the source (DESIGN.md section 1).
"""

from __future__ import annotations

import re

__all__ = ["aspecular_to_geometry", "geometry_label", "parse_geometry_label"]

_LABEL = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*as\s*([+-]?\d+(?:\.\d+)?)\s*$", re.IGNORECASE)


def aspecular_to_geometry(theta_i, aspecular):
    """Viewing angle and azimuth of a multi-angle (ASTM E2194) geometry.

    The aspecular angle is measured from the specular direction towards the
    source, so ``theta_o = |theta_i - aspecular|`` and ``delta_phi = 180`` when
    ``theta_i - aspecular >= 0``, else 0.

    Parameters
    ----------
    theta_i : float
        Illumination angle [deg].
    aspecular : float
        Aspecular angle [deg]; 0 is the specular direction itself.

    Returns
    -------
    tuple of float
        ``(theta_i, theta_o, delta_phi)`` [deg].
    """
    if not 0.0 <= theta_i < 90.0:
        raise ValueError(f"illumination angle must lie in [0, 90) degrees, got {theta_i}")
    if aspecular == 0.0:
        raise ValueError("aspecular angle 0 is the specular direction, which a BRDF excludes")
    theta_o = abs(theta_i - aspecular)
    if theta_o >= 90.0:
        raise ValueError(f"aspecular angle {aspecular} puts the viewer at or below the horizon")
    return float(theta_i), float(theta_o), 180.0 if theta_i - aspecular >= 0 else 0.0


def parse_geometry_label(label):
    """Parse a multi-angle label such as ``"45as-15"`` or ``"45as110"``.

    Returns
    -------
    tuple of float
        ``(theta_i, theta_o, delta_phi)`` [deg].
    """
    match = _LABEL.match(str(label))
    if not match:
        raise ValueError(f"geometry label {label!r} is not of the form '<illumination>as<aspecular>', e.g. '45as-15'")
    return aspecular_to_geometry(float(match.group(1)), float(match.group(2)))


def geometry_label(theta_i, aspecular):
    """The ASTM E2194 label of an illumination and aspecular angle, e.g. ``"45as-15"``."""
    def fmt(x):
        return f"{x:g}"
    return f"{fmt(theta_i)}as{fmt(aspecular)}"
