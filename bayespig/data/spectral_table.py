"""Wide spectral tables: one row per spectrum (``Name`` + one column per wavelength).

The layout of spectrophotometer exports and of the Revigo data (Geldof et al.
2018, ``../shared/data/revigo``)::

    Name    400     410     ...
    01A_b   5.09    5.09    ...
    01A_ob  4.44    4.43    ...
    01A_ow  6.73    7.97    ...
    01A_w   54.83   72.98   ...

Values in percent (the default) or fractions, tab or comma separated. Spectra
named by the Revigo convention form one measurement set per film id: ``<id>_b``
and ``<id>_w`` are the bare black and white cards (role ``substrate``),
``<id>_ob`` and ``<id>_ow`` the paint drawn down over them (films of one film
group ``<id>`` whose substrates are the measured cards). All are
directional–hemispherical reflectances of an 8°/d integrating sphere.
"""

from __future__ import annotations

import math
import re
from itertools import pairwise
from pathlib import Path

import numpy as np

from ._assemble import Row, assemble, parse_number
from ._source import Source, load
from .errors import MeasurementError, Problem
from .model import value_problem, wavelength_problem

__all__ = ["REVIGO_SUFFIXES", "looks_like_spectral_table", "read_revigo", "read_spectral_table"]

#: Revigo spectrum suffix -> (role, substrate suffix).
REVIGO_SUFFIXES = {
    "b": ("substrate", None),
    "w": ("substrate", None),
    "ob": ("film", "b"),
    "ow": ("film", "w"),
}
#: Accepted headers of the first column (the spectrum names), lower case.
NAME_COLUMNS = ("name", "sample")
_WAVELENGTH = re.compile(r"^\s*(\d+(?:\.\d*)?)\s*(?:nm)?\s*$", re.IGNORECASE)
_REVIGO_NAME = re.compile(r"^(.+)_(b|w|ob|ow)$")
_DATA_GLOB = "*spectral-data*.txt"
_MIXTURE_GLOB = "*mixture-specifications*.txt"


def _delimiter(header_line):
    return "\t" if "\t" in header_line else ("," if "," in header_line else ";")


def _cells(line, delimiter):
    """The stripped cells of a line, trailing empty cells (a tab at the end) removed."""
    cells = [c.strip() for c in line.split(delimiter)]
    while len(cells) > 1 and not cells[-1]:
        cells.pop()
    return cells


def looks_like_spectral_table(source):
    """True when the first non-blank line is a name column followed by wavelength columns.

    Parameters
    ----------
    source : Source
        The file, read once (:func:`bayespig.data._source.load`).
    """
    for line in source.head().splitlines():
        if line.strip():
            cells = _cells(line, _delimiter(line))
            return (
                len(cells) > 1
                and not _WAVELENGTH.match(cells[0])
                and all(_WAVELENGTH.match(c) for c in cells[1:])
            )
    return False


def _parse_values(cells, header, name, row, problems):
    """The numbers of a data row, or None after reporting its problems."""
    try:
        values = np.array(cells, dtype=float)
        if np.isfinite(values).all() and (values >= 0).all():
            return values
    except ValueError:
        pass
    values, valid = [], True
    for column, cell in zip(header, cells):
        try:
            value = parse_number(cell)
        except ValueError as error:
            problems.append(
                Problem(str(error) if cell else "empty cell", file=name, row=row, field=column)
            )
            valid = False
            continue
        if not np.isfinite(value) or value < 0:
            problems.append(
                Problem(
                    f"value {cell!r} must be a finite number >= 0",
                    file=name,
                    row=row,
                    field=column,
                )
            )
            valid = False
        values.append(value)
    return np.array(values) if valid else None


def read_spectral_table(path, *, units="percent", progress=None):
    """Read a wide spectral table.

    The first column holds the spectrum names (headed ``Name`` or ``Sample``),
    every other column one wavelength [nm]; empty columns at the end of the
    lines (a trailing tab) are ignored.

    Parameters
    ----------
    path : str or os.PathLike
    units : {"percent", "fraction"}
    progress : None, bool or callable
        Progress while reading: None shows a bar on stderr for files larger
        than 20 MB; False nothing; a callable is called as ``progress(lines_read,
        lines_total)``.

    Returns
    -------
    wavelength_nm : numpy.ndarray
        Shape (n_wavelengths,) [nm].
    spectra : dict
        Name -> ``(values, row)``: values as fractions, shape (n_wavelengths,),
        and the row (line number) they were read from.

    Raises
    ------
    MeasurementError
        Naming the file, row and column of every problem.
    """
    if units not in ("percent", "fraction"):
        raise ValueError(f"units must be 'percent' or 'fraction', got {units!r}")
    source = load(path)
    name = source.name
    lines = source.take_lines("spectral_table")
    problems = []
    header_index = next((i for i, line in enumerate(lines) if line.strip()), None)
    if header_index is None:
        raise MeasurementError(Problem("the file is empty", file=name))
    header_line = lines[header_index]
    header_row = header_index + 1
    delimiter = _delimiter(header_line)
    header = _cells(header_line, delimiter)
    if header[0].lower() not in NAME_COLUMNS:
        problems.append(
            Problem(
                f"the first column must be 'Name' (or 'Sample'), got {header[0]!r}",
                file=name,
                row=header_row,
                field=header[0],
            )
        )
    wavelength_nm = []
    for cell in header[1:]:
        match = _WAVELENGTH.match(cell)
        if not match:
            problems.append(
                Problem(
                    f"column {cell!r} is not a wavelength in nm"
                    if cell
                    else "empty column header between wavelength columns",
                    file=name,
                    row=header_row,
                    field=cell,
                )
            )
        else:
            wavelength_nm.append(float(match.group(1)))
    if not wavelength_nm:
        problems.append(Problem("no wavelength columns", file=name, row=header_row, field="Name"))
    elif any(b <= a for a, b in pairwise(wavelength_nm)):
        problems.append(Problem("wavelength columns must be increasing", file=name, row=header_row))
    elif unit := wavelength_problem(wavelength_nm):
        problems.append(Problem(unit[1], file=name, row=header_row, field=header[1 + unit[0]]))
    if problems:
        raise MeasurementError(problems)
    scale = 0.01 if units == "percent" else 1.0
    spectra = {}
    update = source.progress(progress, len(lines))
    for index in range(header_index + 1, len(lines)):
        line, row = lines[index], index + 1
        lines[index] = None  # parsed: free it
        update(index)
        if not line.strip():
            continue
        cells = _cells(line, delimiter)
        if len(cells) != len(header):
            problems.append(
                Problem(
                    f"has {len(cells)} fields but the header has {len(header)}", file=name, row=row
                )
            )
            continue
        spectrum = cells[0]
        if not spectrum:
            problems.append(Problem("empty name", file=name, row=row, field=header[0]))
            continue
        if spectrum in spectra:
            problems.append(
                Problem(
                    f"duplicated row: {spectrum!r} is already in row {spectra[spectrum][1]}",
                    file=name,
                    row=row,
                    field=header[0],
                )
            )
            continue
        values = _parse_values(cells[1:], header[1:], name, row, problems)
        if values is not None:
            spectra[spectrum] = (values * scale, row)
    update.close()
    if not spectra and not problems:
        problems.append(Problem("no spectra", file=name, row=header_row))
    if units == "percent" and spectra and max(v.max() for v, _ in spectra.values()) <= 0.015:
        problems.append(
            Problem(
                "all values are below 1.5 %: they look like fractions; read with units='fraction'",
                file=name,
            )
        )
    for values, row in spectra.values():
        top = int(np.argmax(values))
        if units == "fraction" and values[top] > 1.5:
            message = f"value {values[top]:g} looks like percent; read with units='percent'"
        elif bad := value_problem("hemispherical", values, percent=units == "percent"):
            message = bad[1]
        else:
            continue
        problems.append(Problem(message, file=name, row=row, field=header[1 + top]))
    if problems:
        raise MeasurementError(problems)
    return np.array(wavelength_nm), spectra


_MIXTURE_SYNTAX = "expected '<id><TAB><pigment>-<pigment>|<ratio>-<ratio>'"


def _read_mixtures(path):
    """Revigo ``<id>\\t<pigment>-<pigment>|<ratio>-<ratio>`` lines -> id -> composition dict.

    Raises
    ------
    MeasurementError
        Listing every bad line with the file, row and field (``id``, ``pigments``,
        ``ratios``): a line not in that form, an empty pigment name, a ratio that is not a
        finite number, all ratios zero, as many ratios as pigments, an id given twice.
    """
    compositions, rows, problems = {}, {}, []
    file = str(path)
    for row, line in enumerate(load(path).lines("spectral_table"), start=1):
        if not line.strip():
            continue
        film_id, tab, spec = line.partition("\t")
        names, bar, ratios = spec.strip().partition("|")
        film_id = film_id.strip()
        if not tab or not bar or not film_id:
            field = "id" if not tab or not film_id else "ratios"
            problems.append(
                Problem(
                    f"cannot read composition {line.strip()!r}: {_MIXTURE_SYNTAX}",
                    file=file,
                    row=row,
                    field=field,
                )
            )
            continue
        pigments, parts = [p.strip() for p in names.split("-")], ratios.split("-")
        if not all(pigments):
            problems.append(
                Problem(
                    f"empty pigment name in {names!r}: {_MIXTURE_SYNTAX}",
                    file=file,
                    row=row,
                    field="pigments",
                )
            )
            continue
        try:
            mass_ratios = [parse_number(p) for p in parts]
        except ValueError as error:
            problems.append(Problem(str(error), file=file, row=row, field="ratios"))
            continue
        bad = next((r for r in mass_ratios if not math.isfinite(r)), None)
        if bad is not None:
            problems.append(
                Problem(
                    f"mass ratio {bad!r} in {ratios.strip()!r} is not a finite number",
                    file=file,
                    row=row,
                    field="ratios",
                )
            )
        elif len(pigments) != len(mass_ratios):
            problems.append(
                Problem(
                    f"{len(pigments)} pigments but {len(mass_ratios)} ratios in "
                    f"{line.strip()!r}: {_MIXTURE_SYNTAX}",
                    file=file,
                    row=row,
                    field="ratios",
                )
            )
        elif not any(mass_ratios):
            problems.append(
                Problem(
                    f"all mass ratios of {film_id!r} are zero; a film needs at least one pigment",
                    file=file,
                    row=row,
                    field="ratios",
                )
            )
        elif film_id in compositions:
            problems.append(
                Problem(
                    f"film {film_id!r} is already given in row {rows[film_id]}",
                    file=file,
                    row=row,
                    field="id",
                )
            )
        else:
            compositions[film_id] = {"pigments": pigments, "mass_ratios": mass_ratios}
            rows[film_id] = row
    if problems:
        raise MeasurementError(problems)
    return compositions


def _find(folder, pattern, what):
    found = sorted(Path(folder).glob(pattern))
    if len(found) != 1:
        raise MeasurementError(
            Problem(
                f"expected one {what} file matching {pattern!r}, found {len(found)}",
                file=str(folder),
            )
        )
    return found[0]


def read_revigo(path, *, specular="excluded", theta_i=8.0, units="percent", n=1.45, progress=None):
    """Read a Revigo-style table into one measurement set per film id.

    Parameters
    ----------
    path : str or os.PathLike
        The folder (holding ``*spectral-data*.txt`` and, optionally,
        ``*mixture-specifications*.txt``) or the spectral table itself.
    specular : {"excluded", "included"}
        Whether the sphere excluded (SCE) or included (SCI) the specular
        component. The Revigo data do not say; films as dark as 2 % (below the
        ~3.4 % surface reflection of a binder at 8°) suggest SCE, the default.
    theta_i : float
        Incidence angle of the sphere [deg].
    units : {"percent", "fraction"}
    n : float
        Binder refractive index [-].
    progress : None, bool or callable
        See :func:`read_spectral_table`.

    Returns
    -------
    dict
        Film id -> :class:`~bayespig.data.model.MeasurementSet` with samples
        ``<id>_b``, ``<id>_w`` (substrates) and ``<id>_ob``, ``<id>_ow`` (films
        over them, film group ``<id>``); metadata: ``film_id``, ``composition``
        (pigments and mass ratios, when the mixture file is there), ``source``,
        ``instrument``, ``specular_assumed``.

    Raises
    ------
    MeasurementError
        For unreadable files, names outside the ``<id>_b/_w/_ob/_ow``
        convention, ids without all four spectra.
    """
    if specular not in ("excluded", "included"):
        raise ValueError(f"specular must be 'excluded' or 'included', got {specular!r}")
    if not isinstance(path, Source) and Path(path).is_dir():
        table = _find(path, _DATA_GLOB, "spectral data")
        mixtures = sorted(Path(path).glob(_MIXTURE_GLOB))
    else:
        table = path
        table_name = path.name if isinstance(path, Source) else str(path)
        mixtures = sorted(Path(table_name).parent.glob(_MIXTURE_GLOB))
    compositions = _read_mixtures(mixtures[0]) if len(mixtures) == 1 else {}
    table = load(table)
    wavelength_nm, spectra = read_spectral_table(table, units=units, progress=progress)
    file = table.name
    problems, by_id = [], {}
    for spectrum, (values, row) in spectra.items():
        match = _REVIGO_NAME.match(spectrum)
        if not match:
            problems.append(
                Problem(
                    f"name {spectrum!r} does not follow the convention <id>_b, <id>_w (bare black "
                    "and white cards), <id>_ob, <id>_ow (paint over them)",
                    file=file,
                    row=row,
                    field="Name",
                )
            )
            continue
        by_id.setdefault(match.group(1), {})[match.group(2)] = (spectrum, values, row)
    for film_id, parts in by_id.items():
        missing = [f"{film_id}_{s}" for s in REVIGO_SUFFIXES if s not in parts]
        if missing:
            first_row = min(row for _, _, row in parts.values())
            problems.append(
                Problem(
                    f"film {film_id!r} lacks the spectra {', '.join(missing)}",
                    file=file,
                    row=first_row,
                    field="Name",
                )
            )
    if problems:
        raise MeasurementError(problems)
    geometry = f"{theta_i:g}d-{'sci' if specular == 'included' else 'sce'}"
    sets = {}
    wavelength_fields = [f"{w:g}" for w in wavelength_nm]
    for film_id, parts in by_id.items():
        rows = []
        for suffix, (role, substrate) in REVIGO_SUFFIXES.items():
            spectrum, values, row = parts[suffix]
            attributes = {"role": role}
            if role == "film":
                attributes.update(substrate=f"{film_id}_{substrate}", film_group=film_id)
            rows.append(
                Row(
                    file,
                    row,
                    spectrum,
                    "hemispherical",
                    geometry,
                    values,
                    attributes,
                    {"role": "Name", "substrate": "Name", "film_group": "Name"},
                    wavelength_fields,
                )
            )
        metadata = {
            "film_id": film_id,
            "source": file,
            "instrument": geometry,
            "specular_assumed": specular,
        }
        if film_id in compositions:
            metadata["composition"] = compositions[film_id]
        sets[film_id] = assemble(rows, wavelength_nm, n=n, metadata=metadata, source=file)
    return sets
