"""bayespig: pigment optical properties from paint-film measurements, with honest uncertainty."""

from ._versions import __version__
from .data import MeasurementError, MeasurementSet, read_measurements, simulate
from .fit import fit_measurements, fit_problem
from .inference import (
    ConvergenceWarning,
    InferenceSettings,
    diagnose,
    infer,
    load_inference,
    save_inference,
    summarize,
)
from .instruments import get_instrument, predict
from .library import build_library, load_library, match_paint, predict_paint
from .physics.forward import (
    brdf,
    hemispherical_reflectance,
    optical_thickness_from_transmittance,
    specular_transmittance,
)
from .studies.robustness import robustness_study
from .table import load_table

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
