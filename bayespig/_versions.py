"""Versions of bayespig, the packages behind a result and Python, for the result's provenance."""

from __future__ import annotations

import importlib.metadata
import platform

__all__ = ["RESULT_PACKAGES", "__version__", "format_versions", "package_versions", "versions_text"]

#: bayespig's version: the one place it is written (``pyproject.toml`` reads it from here).
__version__ = "0.1.0"

#: What a saved result (a posterior, a library, a study's record) names by default.
RESULT_PACKAGES = ("bayespig", "numpy", "scipy", "emcee", "arviz")


def package_versions(names=RESULT_PACKAGES, *, python=False):
    """Name -> installed version of each package of ``names`` (``"unknown"`` when not installed).

    bayespig's own is its ``__version__`` (right in a source tree that is not installed too);
    ``python=True`` adds ``"python"``.
    """
    out = {}
    for name in names:
        if name == "bayespig":
            out[name] = __version__
            continue
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "unknown"
    if python:
        out["python"] = platform.python_version()
    return out


def format_versions(versions):
    """A mapping name -> version (:func:`package_versions`, or one a result recorded) as one line
    of a report: ``"bayespig 0.1.0, numpy 2.4.6, ..., Python 3.11.7"``."""
    return ", ".join(f"{'Python' if name == 'python' else name} {version}" for name, version in versions.items())


def versions_text(names=RESULT_PACKAGES, *, python=True):
    """The installed versions of ``names`` as one line of a report (:func:`format_versions`)."""
    return format_versions(package_versions(names, python=python))
