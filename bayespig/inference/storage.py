"""Inference results as netCDF files: atomic writes, checked reads."""

from __future__ import annotations

import os

from .._atomic import atomic_path
from .._storage import read_netcdf

__all__ = ["load_inference", "save_inference"]


def save_inference(idata, path):
    """Write ``idata`` to a netCDF file atomically (temporary file in the same directory, then
    :func:`os.replace`); nothing is left half-written on failure.

    Returns
    -------
    str
        The path written.
    """
    path = os.fspath(path)
    with atomic_path(path, suffix=".nc") as temporary:
        idata.to_netcdf(temporary)
    return path


def load_inference(path):
    """Read an InferenceData written by :func:`save_inference` (netCDF, no pickle).

    Raises
    ------
    ValueError
        When the file is missing or not an inference result.
    """
    idata = read_netcdf(path)
    if "posterior" not in idata.groups() or "a" not in idata.posterior:
        raise ValueError(f"'{path}': no posterior of 'a' — not written by bayespig.infer")
    return idata
