"""bayespig: pigment optical properties from paint-film measurements, with honest uncertainty."""

from .physics.forward import (
    brdf,
    hemispherical_reflectance,
    optical_thickness_from_transmittance,
    specular_transmittance,
)

__version__ = "0.1.0"

from .data import MeasurementError, MeasurementSet, read_measurements, simulate  # noqa: E402
from .fit import fit_measurements, fit_problem  # noqa: E402
from .inference import (  # noqa: E402
    ConvergenceWarning,
    InferenceSettings,
    diagnose,
    infer,
    load_inference,
    save_inference,
    summarize,
)
from .instruments import get_instrument, predict  # noqa: E402  (table needs __version__)
from .library import build_library, load_library, match_paint, predict_paint  # noqa: E402
from .studies.robustness import robustness_study  # noqa: E402
from .table import load_table  # noqa: E402

__all__ = [
    "ConvergenceWarning",
    "InferenceSettings",
    "MeasurementError",
    "MeasurementSet",
    "brdf",
    "build_library",
    "diagnose",
    "fit_measurements",
    "fit_problem",
    "get_instrument",
    "hemispherical_reflectance",
    "infer",
    "load_inference",
    "load_library",
    "match_paint",
    "load_table",
    "optical_thickness_from_transmittance",
    "predict",
    "predict_paint",
    "read_measurements",
    "robustness_study",
    "save_inference",
    "simulate",
    "specular_transmittance",
    "summarize",
]
