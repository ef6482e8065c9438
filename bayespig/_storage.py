"""Reading bayespig's netCDF files (posteriors) whole, with errors that name the file."""

from __future__ import annotations

from pathlib import Path

__all__ = ["read_netcdf"]


def read_netcdf(path):
    """Read an InferenceData netCDF file completely into memory, or say which file is bad.

    arviz reads lazily by default, so a damaged file (a flipped byte in a compressed chunk)
    would open fine and fail later, deep inside a computation, with HDF5's text ("Can't
    synchronously read data (filter returned failure during read)") and no file name. Here
    every group is loaded at once and the file is closed, so any damage shows now, as one
    ``ValueError`` naming the file.

    Parameters
    ----------
    path : str or os.PathLike
        The netCDF file (e.g. ``run/posterior.nc`` written by :func:`bayespig.save_inference`).

    Returns
    -------
    arviz.InferenceData
        Every group loaded in memory (no file handle is kept open).

    Raises
    ------
    ValueError
        ``'<path>' cannot be read: ...`` when the file is missing, a folder, damaged or not
        an InferenceData netCDF file; the reader's own message follows in parentheses.
    """
    import arviz as az

    path = Path(path)
    if not path.exists():
        raise ValueError(f"'{path}' cannot be read: file not found")
    if path.is_dir():
        raise ValueError(f"'{path}' cannot be read: it is a folder, not a posterior file")
    try:
        with az.rc_context({"data.load": "eager"}):
            idata = az.from_netcdf(path)
    except Exception as error:  # noqa: BLE001 - HDF5, netCDF and xarray fail in many ways
        raise ValueError(
            f"'{path}' cannot be read: it is damaged or not a bayespig posterior "
            f"({type(error).__name__}: {error})"
        ) from None
    return idata
