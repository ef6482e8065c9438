"""Measurements: the data model, file formats, validation and the simulator.

Read a file with :func:`read_measurements` (bayespig CSV, ASTM E1392 BRDF text
files, wide spectral tables such as the Revigo data), check it with
:func:`check_report`, simulate one with :func:`simulate`; every problem a file
can have raises :class:`MeasurementError` naming the file, row and field.
"""

from .astm_e1392 import read_astm_e1392
from .csv_format import read_csv
from .errors import MeasurementError, Problem
from .io import check_report, read_measurements
from .model import (
    BLACK_SUBSTRATE_ALBEDO,
    METHODS,
    WHITE_SUBSTRATE_ALBEDO,
    Measurement,
    MeasurementSet,
    MethodSupport,
    Sample,
)
from .simulate import DESIGNS, FilmSpec, simulate, simulate_to_csv
from .spectral_table import read_revigo, read_spectral_table
from .writers import write_astm_e1392, write_csv

__all__ = [
    "BLACK_SUBSTRATE_ALBEDO",
    "DESIGNS",
    "METHODS",
    "WHITE_SUBSTRATE_ALBEDO",
    "FilmSpec",
    "Measurement",
    "MeasurementError",
    "MeasurementSet",
    "MethodSupport",
    "Problem",
    "Sample",
    "check_report",
    "read_astm_e1392",
    "read_csv",
    "read_measurements",
    "read_revigo",
    "read_spectral_table",
    "simulate",
    "simulate_to_csv",
    "write_astm_e1392",
    "write_csv",
]
