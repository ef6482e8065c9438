"""bayespig: pigment optical properties from paint-film measurements, with honest uncertainty."""

from .physics.forward import (
    brdf,
    hemispherical_reflectance,
    optical_thickness_from_transmittance,
    specular_transmittance,
)

__version__ = "0.1.0"

__all__ = [
    "brdf",
    "hemispherical_reflectance",
    "specular_transmittance",
    "optical_thickness_from_transmittance",
]
