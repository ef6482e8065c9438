"""One entry for every file format, and the report of ``bayespig check``."""

from __future__ import annotations

import os
from pathlib import Path

from ._source import Source, load
from .astm_e1392 import looks_like_astm_e1392, read_astm_e1392
from .csv_format import read_csv
from .errors import MeasurementError, Problem
from .model import MeasurementSet
from .spectral_table import looks_like_spectral_table, read_revigo

__all__ = ["check_report", "file_format", "read_all", "read_measurements"]


def _open(path):
    """A folder as it is, any other path read once into a :class:`Source`."""
    if isinstance(path, Source):
        return path
    try:
        if Path(path).is_dir():
            return Path(path)
    except OSError:
        pass  # a symbolic link loop, ...: load() says so in plain words
    return load(path)


def file_format(path):
    """``"csv"``, ``"astm_e1392"`` or ``"spectral_table"``, from the suffix and the content.

    Parameters
    ----------
    path : str, os.PathLike or Source
        A folder is a spectral table (Revigo layout); a file is read once.
    """
    source = _open(path)
    if isinstance(source, Path) or looks_like_spectral_table(source):
        return "spectral_table"
    if looks_like_astm_e1392(source):
        return "astm_e1392"
    return "csv"


def _read(source, kind, resample):
    if kind == "spectral_table":
        return read_revigo(source)
    reader = read_astm_e1392 if kind == "astm_e1392" else read_csv
    return {Path(str(getattr(source, "name", source))).stem: reader(source, resample=resample)}


def read_all(path, *, resample=False):
    """Every measurement set in a file: film id -> set (CSV and E1392: one, keyed by file name)."""
    source = _open(path)
    return _read(source, file_format(source), resample)


def _film_options(opaque, substrate):
    """``opaque``/``substrate`` arguments checked, as keyword arguments of the E1392 reader."""
    if opaque is not None and not isinstance(opaque, bool):
        raise TypeError(f"opaque must be True, False or None, got {opaque!r}")
    if substrate is not None and (isinstance(substrate, bool) or not isinstance(substrate, (str, int, float))):
        raise TypeError(
            f"substrate must be 'black', 'white', an albedo in [0, 1], a sample name or None, got {substrate!r}"
        )
    return {"opaque": opaque, "substrate": substrate}


def read_measurements(path, *, film=None, resample=False, opaque=None, substrate=None):
    """Read a measurement file of any supported format.

    Parameters
    ----------
    path : str, os.PathLike or sequence of them
        A bayespig CSV file; an ASTM E1392 file (or a list of them, one per
        sample); a wide spectral table or its folder (Revigo convention). The
        file is read once, so a pipe (``<(cat file)``, ``/dev/stdin``) works.
    film : str, optional
        For spectral tables holding several films: the film id to return.
    resample : bool
        Interpolate rows measured at different wavelengths onto the wavelengths
        they share (with a warning) instead of raising.
    opaque : bool, optional
        ASTM E1392 files only (the standard has no keyword for it): True when the
        film hides its substrate, False when it does not (then it needs a
        substrate). Wins over an ``OPAQUE`` keyword in the file.
    substrate : str or float, optional
        ASTM E1392 files only: the film's substrate, ``"black"`` (r_s = 0.01),
        ``"white"`` (0.95), an albedo in [0, 1] or the name of a substrate sample
        in another of the files. Wins over a ``SUBSTRATE`` keyword in the file.

    Returns
    -------
    MeasurementSet

    Raises
    ------
    MeasurementError
        Every problem found, each naming the file, row and field.
    ValueError
        ``opaque`` or ``substrate`` given for a CSV file or a spectral table
        (they state it per sample).
    TypeError
        ``opaque`` or ``substrate`` of the wrong type.
    """
    options = _film_options(opaque, substrate)
    given = [k for k, v in options.items() if v is not None]
    if isinstance(path, MeasurementSet):
        if given:
            raise ValueError(f"{given[0]}= applies when reading an ASTM E1392 file, not to a MeasurementSet")
        return path
    if not isinstance(path, (str, os.PathLike, Source, Path)):
        return read_astm_e1392(list(path), resample=resample, **options)
    path = _open(path)
    kind = file_format(path)
    if given and kind != "astm_e1392":
        raise ValueError(
            f"{given[0]}= applies to ASTM E1392 files, whose header has no standard keyword for it; "
            f"a {kind.replace('_', ' ')} file states it per sample (its {given[0]} column)"
        )
    if kind == "spectral_table":
        sets = read_revigo(path)
        if film is None and len(sets) == 1:
            return next(iter(sets.values()))
        if film not in sets:
            shown = ", ".join(list(sets)[:12]) + (", ..." if len(sets) > 12 else "")
            raise MeasurementError(
                Problem(
                    f"the table holds {len(sets)} films ({shown}); choose one with film=<id> "
                    "(or read them all with bayespig.data.read_revigo)"
                    if film is None
                    else f"no film {film!r} in the table; films: {shown}",
                    file=str(getattr(path, "name", path)),
                    field="film",
                )
            )
        return sets[film]
    if kind == "astm_e1392":
        return read_astm_e1392(path, resample=resample, **options)
    return read_csv(path, resample=resample)


#: A sample with more geometries of one kind than this is summarised (angle ranges, counts per
#: incidence angle) by ``bayespig check`` instead of listing every label.
GEOMETRY_LIST_MAX = 24


def _fmt_deg(x):
    return f"{x:.4g}°"


def _geometry_lines(sample, verbose):
    """What a sample was measured at: every label, or for many geometries a summary."""
    kinds = {}
    for m in sample.measurements:
        kinds.setdefault(m.kind, []).append(m)
    parts, listed = [], []
    for kind, measurements in kinds.items():
        if len(measurements) <= GEOMETRY_LIST_MAX:
            parts.append(f"{kind} at {', '.join(m.label for m in measurements)}")
            continue
        incidence = {}
        for m in measurements:
            incidence[m.theta_i] = incidence.get(m.theta_i, 0) + 1
        in_plane = sum(m.delta_phi in (0.0, 180.0) for m in measurements)
        theta_o = [m.theta_o for m in measurements]
        delta_phi = [m.delta_phi for m in measurements]
        parts.append(
            f"{kind} at {len(measurements)} geometries: theta_i "
            + ", ".join(f"{_fmt_deg(t)} ({c})" for t, c in sorted(incidence.items()))
            + f"; theta_o {_fmt_deg(min(theta_o))}–{_fmt_deg(max(theta_o))}; delta_phi "
            f"{_fmt_deg(min(delta_phi))}–{_fmt_deg(max(delta_phi))}; {in_plane} in the plane of "
            f"incidence, {len(measurements) - in_plane} out of it"
            + ("" if verbose else " (--verbose lists them)")
        )
        if verbose:
            listed.extend(f"    {kind} {m.label}" for m in measurements)
    return parts, listed


def _summary_text(measurements, verbose):
    """The set's summary with the geometry line of each sample condensed when it is long."""
    lines = measurements.summary().split("\n")
    start = lines.index("samples:") + 1
    out = lines[:start]
    for k, sample in enumerate(measurements.samples):
        head, what = lines[start + 2 * k], lines[start + 2 * k + 1]
        parts, listed = _geometry_lines(sample, verbose)
        indent = what[: len(what) - len(what.lstrip())]
        out.append(head)
        out.extend(f"{indent}{part}" for part in parts)
        out.extend(listed)
    out.extend(lines[start + 2 * len(measurements.samples):])
    return "\n".join(out)


def check_report(path, *, opaque=None, substrate=None, verbose=False, notes=None):
    """What a measurement file holds, for ``bayespig check FILE``.

    Parameters
    ----------
    path : str or os.PathLike
    opaque, substrate : optional
        As :func:`read_measurements` (ASTM E1392 files).
    verbose : bool
        List every geometry of a sample measured at many (one per line) besides
        the summary of their angles.
    notes : callable, optional
        ``notes(measurements) -> (accepted, lines)`` for a file holding one set:
        whether inference takes the set as it stands and lines to add (what
        ``bayespig check`` adds: rows near the mirror direction, implausible
        values, zeros). When ``accepted`` is False the file is not called valid.

    Returns
    -------
    str
        The format; per measurement set the samples, roles, substrates (with the
        derived ``r_s`` range), wavelengths, film groups, and which of the
        paper's methods 1–4 the samples support (or what is missing).

    Raises
    ------
    MeasurementError
        Listing every problem found (file, row, field), when the file is invalid.
    """
    source = _open(path)
    kind = file_format(source)
    options = _film_options(opaque, substrate)
    if any(v is not None for v in options.values()):
        sets = {Path(str(getattr(source, "name", source))).stem: read_measurements(source, **options)}
    else:
        sets = _read(source, kind, False)
    lines = [f"{path}: {kind.replace('_', ' ')} file, valid"]
    if len(sets) == 1:
        measurements = next(iter(sets.values()))
        lines.append(_summary_text(measurements, verbose))
        if notes is not None:
            accepted, extra = notes(measurements)
            if not accepted:
                lines[0] = f"{path}: {kind.replace('_', ' ')} file, readable, but not valid for infer as it stands"
            lines.extend(extra)
        return "\n".join(lines)
    lines.append(f"{len(sets)} films (read one with read_measurements(path, film=<id>))")
    for film_id, measurements in sets.items():
        methods = [m for m, s in measurements.supported_methods().items() if s]
        composition = measurements.metadata.get("composition")
        what = ""
        if composition:
            what = " " + "+".join(
                f"{p} {r:g}"
                for p, r in zip(composition["pigments"], composition["mass_ratios"])
                if r
            )
        lines.append(
            f"  {film_id}:{what}; samples {', '.join(measurements.sample_names)}; "
            f"methods: {', '.join(methods) or 'none'}"
        )
    return "\n".join(lines)
