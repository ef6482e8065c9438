"""bayespig: pigment optical properties from paint-film measurements, with honest uncertainty."""

from .physics.forward import (
    brdf,
    hemispherical_reflectance,
    optical_thickness_from_transmittance,
    specular_transmittance,
)

__version__ = "0.1.0"

from .instruments import get_instrument, predict  # noqa: E402  (table needs __version__)
from .table import load_table  # noqa: E402
from .data import MeasurementError, MeasurementSet, read_measurements, simulate  # noqa: E402
from .fit import fit_measurements, fit_problem  # noqa: E402
from .studies.robustness import robustness_study  # noqa: E402
from .inference import (  # noqa: E402
    ConvergenceWarning,
    InferenceSettings,
    diagnose,
    infer,
    load_inference,
    save_inference,
    summarize,
)

__all__ = [
    "brdf",
    "hemispherical_reflectance",
    "specular_transmittance",
    "optical_thickness_from_transmittance",
    "get_instrument",
    "predict",
    "load_table",
    "read_measurements",
    "simulate",
    "MeasurementSet",
    "MeasurementError",
    "fit_problem",
    "fit_measurements",
    "robustness_study",
    "infer",
    "InferenceSettings",
    "ConvergenceWarning",
    "diagnose",
    "summarize",
    "save_inference",
    "load_inference",
]
