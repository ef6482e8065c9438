"""The bayespig CSV format: one row per sample × geometry, one column per wavelength.

::

    # units: fraction
    # n: 1.45
    sample,role,substrate,film_group,opaque,measurement,geometry,400,500,600,700
    on_black,film,black,A,no,brdf,45as15,0.0123,0.0145,0.0151,0.0149
    on_white,film,white,A,no,brdf,45as15,0.0712,0.0889,0.0934,0.0940

Lines starting with ``#`` before the column header are ``# key: value``
settings (``units``: ``fraction`` or ``percent``; ``n``: binder refractive
index; ``format``; ``metadata``: a JSON object of metadata, used by the writer for
keys that cannot be ``# key:`` lines of their own; anything else is kept as
metadata, read as JSON when it parses as JSON and as text otherwise); other
``#`` lines are comments. A sample name starting with ``#`` is quoted
(``"#1"``) so that its row is not a comment.
Required columns: ``sample``, ``role``, ``measurement``, ``geometry`` and at
least one wavelength column (a number in nm, e.g. ``400`` or ``400nm``);
optional: ``substrate``, ``film_group``, ``opaque``, ``thickness_um``,
``concentration``, ``eps``, ``recipe``. Comma, tab or semicolon separated. The full
description is in ``docs/file-formats.md``.

A film's **recipe** (``recipe`` column) is ``pigment:amount`` pairs separated by ``;``::

    sample,role,substrate,film_group,recipe,measurement,geometry,400,500
    over_black,film,black,06B,Vermillion:10;ZincWhite:90,hemispherical,8d-sce,0.05,0.06

Amounts are relative masses of the paints as mixed (any unit: ``10;90`` and ``0.1;0.9``
are one recipe), >= 0, a zero meaning the pigment is absent; spaces around names and
amounts are ignored. In a semicolon-separated file quote the cell. Films of one film group
are one paint and must give one recipe (on any of their rows; blank cells mean "not
given"); substrates have none. The set's metadata gets the recipe as
``composition = {"pigments": [...], "mass_ratios": [...]}`` (the form ``read_revigo``
gives) when every film group has the same one, otherwise ``compositions``: film group ->
composition. A ``# composition:`` metadata line is the same information: give one of them.
"""

from __future__ import annotations

import csv
import difflib
import json
import re
from itertools import pairwise

import numpy as np

from ._assemble import SAMPLE_FIELDS, Row, assemble, parse_number
from ._source import load
from .errors import MeasurementError, Problem
from .model import MEASUREMENT_KINDS, PERCENT_THRESHOLD, value_problem, wavelength_problem
from .writers import FORMAT_NAME, METADATA_KEY, RECIPE_FIELD

__all__ = ["FORMAT_NAME", "read_csv"]

REQUIRED_COLUMNS = ("sample", "role", "measurement", "geometry")
OPTIONAL_COLUMNS = (
    "substrate",
    "film_group",
    "opaque",
    "thickness_um",
    "concentration",
    "eps",
    RECIPE_FIELD,
)
UNITS = ("fraction", "percent")

_DIRECTIVE = re.compile(r"^#\s*([A-Za-z_][\w.\-]*)\s*:\s?(.*)$")
_WAVELENGTH = re.compile(r"^\s*(\d+(?:\.\d*)?)\s*(?:nm)?\s*$", re.IGNORECASE)


def _split(line, delimiter):
    if "\x00" in line:
        raise ValueError("the line contains a NUL character")
    try:
        return next(csv.reader([line], delimiter=delimiter))
    except (csv.Error, StopIteration) as error:
        raise ValueError(f"cannot split the line into fields: {error}") from None


def _column_kind(name):
    """``("wavelength", value)``, ``("column", name)`` or ``("unknown", name)``."""
    match = _WAVELENGTH.match(name)
    if match:
        return "wavelength", float(match.group(1))
    key = name.strip().lower()
    if key in REQUIRED_COLUMNS or key in OPTIONAL_COLUMNS:
        return "column", key
    return "unknown", name.strip()


def read_csv(path, *, resample=False, progress=None):
    """Read a bayespig CSV file.

    Parameters
    ----------
    path : str or os.PathLike
    resample : bool
        When rows have blank cells (wavelengths that differ between samples),
        interpolate every row linearly onto the wavelengths they all cover, with
        a warning, instead of raising.
    progress : None, bool or callable
        Progress while reading: None shows a bar on stderr for files larger
        than 20 MB; False nothing; a callable is called as ``progress(lines_read,
        lines_total)``.

    Returns
    -------
    MeasurementSet

    Raises
    ------
    MeasurementError
        Listing every problem, each with the file, row (line number) and field.
    """
    source = load(path)
    name = source.name
    lines = source.take_lines("csv")
    problems, metadata, settings = [], {}, {"units": None, "n": 1.45}
    header_index = None
    for index, line in enumerate(lines):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            match = _DIRECTIVE.match(stripped)
            if match:
                _directive(
                    match.group(1),
                    match.group(2).strip(),
                    name,
                    index + 1,
                    settings,
                    metadata,
                    problems,
                )
            continue
        header_index = index
        break
    if header_index is None:
        problems.append(
            Problem(
                "no column header line (sample,role,measurement,geometry,<wavelengths>...) found",
                file=name,
            )
        )
        raise MeasurementError(problems)

    header_line = lines[header_index]
    header_row = header_index + 1
    delimiter = max(",\t;", key=header_line.count)
    try:
        header = [cell.strip() for cell in _split(header_line, delimiter)]
    except ValueError as error:
        raise MeasurementError(
            problems + [Problem(str(error), file=name, row=header_row)]
        ) from None
    columns, wavelength_columns, seen = {}, [], {}
    for position, cell in enumerate(header):
        kind, key = _column_kind(cell)
        if kind == "unknown":
            known = list(REQUIRED_COLUMNS + OPTIONAL_COLUMNS)
            close = difflib.get_close_matches(cell.lower(), known, n=1)
            hint = (
                f"; did you mean {close[0]!r}?" if close else f"; known columns: {', '.join(known)}"
            )
            problems.append(
                Problem(
                    f"unknown column {cell!r} (neither a known column nor a wavelength in "
                    f"nm){hint}",
                    file=name,
                    row=header_row,
                    field=cell,
                )
            )
            continue
        if key in seen:
            problems.append(
                Problem(
                    f"column {cell!r} appears twice (columns {seen[key] + 1} and {position + 1})",
                    file=name,
                    row=header_row,
                    field=cell,
                )
            )
            continue
        seen[key] = position
        if kind == "wavelength":
            wavelength_columns.append((key, position, cell))
        else:
            columns[key] = position
    for required in REQUIRED_COLUMNS:
        if required not in columns:
            problems.append(
                Problem(
                    f"missing column {required!r}; the header needs "
                    f"{', '.join(REQUIRED_COLUMNS)} and the wavelength columns",
                    file=name,
                    row=header_row,
                    field=required,
                )
            )
    if not wavelength_columns:
        problems.append(
            Problem(
                "no wavelength columns (column names such as 400, 410, ... in nm)",
                file=name,
                row=header_row,
                field="wavelengths",
            )
        )
    elif wavelength_columns[0][0] <= 0:
        problems.append(
            Problem(
                "wavelengths must be > 0 nm",
                file=name,
                row=header_row,
                field=wavelength_columns[0][2],
            )
        )
    elif any(b[0] <= a[0] for a, b in pairwise(wavelength_columns)):
        problems.append(
            Problem(
                "wavelength columns must be in increasing order",
                file=name,
                row=header_row,
                field=next(b[2] for a, b in pairwise(wavelength_columns) if b[0] <= a[0]),
            )
        )
    elif unit := wavelength_problem([w for w, _, _ in wavelength_columns]):
        problems.append(
            Problem(unit[1], file=name, row=header_row, field=wavelength_columns[unit[0]][2])
        )
    if problems:
        raise MeasurementError(problems)

    wavelength_nm = np.array([w for w, _, _ in wavelength_columns])
    wavelength_fields = [cell for _, _, cell in wavelength_columns]
    scale = 0.01 if settings["units"] == "percent" else 1.0
    rows = []
    update = source.progress(progress, len(lines))
    for index in range(header_index + 1, len(lines)):
        line, row_number = lines[index], index + 1
        lines[index] = None  # parsed: free it
        update(index)
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            cells = _split(line, delimiter)
        except ValueError as error:
            problems.append(Problem(str(error), file=name, row=row_number))
            continue
        if len(cells) != len(header):
            problems.append(
                Problem(
                    f"has {len(cells)} fields but the header has {len(header)} "
                    f"(separator {delimiter!r}); check for missing or extra separators",
                    file=name,
                    row=row_number,
                )
            )
            continue
        row = _parse_row(
            cells,
            columns,
            wavelength_columns,
            wavelength_fields,
            settings["units"],
            scale,
            name,
            row_number,
            problems,
        )
        if row is not None:
            rows.append(row)
    update.close()
    if not rows and not problems:
        problems.append(
            Problem("the file has a header but no data rows", file=name, row=header_row)
        )
    if problems and not rows:
        raise MeasurementError(problems)
    return assemble(
        rows,
        wavelength_nm,
        n=settings["n"],
        metadata=metadata,
        source=name,
        resample=resample,
        problems=problems,
    )


def _directive(key, value, name, row, settings, metadata, problems):
    lowered = key.lower()
    if lowered == "format":
        if not value.startswith("bayespig-measurements"):
            problems.append(
                Problem(
                    f"format {value!r} is not a bayespig measurement file ({FORMAT_NAME})",
                    file=name,
                    row=row,
                    field="format",
                )
            )
        elif value != FORMAT_NAME:
            problems.append(
                Problem(
                    f"format {value!r} is newer than this bayespig reads ({FORMAT_NAME}); "
                    "upgrade bayespig",
                    file=name,
                    row=row,
                    field="format",
                )
            )
    elif lowered == "units":
        if value.lower() not in UNITS:
            problems.append(
                Problem(
                    f"units must be 'fraction' or 'percent', got {value!r}",
                    file=name,
                    row=row,
                    field="units",
                )
            )
        else:
            settings["units"] = value.lower()
    elif lowered == "n":
        try:
            settings["n"] = parse_number(value)
            if not settings["n"] >= 1.0 or settings["n"] == float("inf"):
                raise ValueError(f"must be a finite number >= 1, got {value!r}")
        except ValueError as error:
            settings["n"] = 1.45
            problems.append(
                Problem(f"binder refractive index n: {error}", file=name, row=row, field="n")
            )
    elif lowered == METADATA_KEY:
        try:
            value = json.loads(value)
        except (ValueError, RecursionError):
            value = None
        if not isinstance(value, dict):
            problems.append(
                Problem(
                    f"'# {METADATA_KEY}:' must be followed by a JSON object",
                    file=name,
                    row=row,
                    field=key,
                )
            )
            return
        for item, item_value in value.items():
            if item in metadata:
                problems.append(
                    Problem(f"metadata key {item!r} is given twice", file=name, row=row, field=key)
                )
            metadata[item] = item_value
    elif key in metadata:
        problems.append(
            Problem(f"metadata key {key!r} is given twice", file=name, row=row, field=key)
        )
    else:
        try:
            metadata[key] = json.loads(value)
        except ValueError:
            metadata[key] = value
        except RecursionError:
            problems.append(
                Problem("metadata value nested too deeply", file=name, row=row, field=key)
            )


def _fast_values(texts):
    """The values of a row's cells when all are plain numbers >= 0 (else None: check each).

    Blank cells (wavelengths not measured) are NaN.
    """
    try:
        values = np.array([t if t.strip() else "nan" for t in texts], dtype=float)
    except ValueError:
        return None
    blank = np.isnan(values)
    if not (np.isfinite(values) | blank).all() or (values < 0).any():
        return None
    if blank.any() and any(t.strip().lower() == "nan" for t in texts):
        return None  # a written NaN is reported, unlike a blank cell
    return values


def _parse_row(
    cells, columns, wavelength_columns, wavelength_fields, units, scale, name, row_number, problems
):
    get = {key: cells[position].strip() for key, position in columns.items()}
    valid = True
    sample = get["sample"]
    if not sample:
        problems.append(Problem("sample name is empty", file=name, row=row_number, field="sample"))
        return None
    kind = get["measurement"].lower()
    if kind not in MEASUREMENT_KINDS:
        close = difflib.get_close_matches(kind, MEASUREMENT_KINDS, n=1)
        problems.append(
            Problem(
                f"measurement must be one of {', '.join(MEASUREMENT_KINDS)}, got "
                f"{get['measurement']!r}" + (f"; did you mean {close[0]!r}?" if close else ""),
                file=name,
                row=row_number,
                field="measurement",
            )
        )
        valid = False
    values = _fast_values([cells[position] for _, position, _ in wavelength_columns])
    if values is not None:
        values = values * scale
    else:
        values = np.full(len(wavelength_columns), np.nan)
        for k, (_, position, cell) in enumerate(wavelength_columns):
            text = cells[position].strip()
            if not text:
                continue
            try:
                value = parse_number(text)
            except ValueError as error:
                problems.append(Problem(str(error), file=name, row=row_number, field=cell))
                valid = False
                continue
            if np.isnan(value):
                problems.append(
                    Problem(
                        "value is NaN; give a measured value (or leave the cell blank when this "
                        "wavelength was not measured)",
                        file=name,
                        row=row_number,
                        field=cell,
                    )
                )
                valid = False
            elif not np.isfinite(value):
                problems.append(
                    Problem(f"value {text!r} is not finite", file=name, row=row_number, field=cell)
                )
                valid = False
            elif value < 0:
                problems.append(
                    Problem(
                        f"negative value {text}; reflectances and transmittances are >= 0",
                        file=name,
                        row=row_number,
                        field=cell,
                    )
                )
                valid = False
            values[k] = value * scale
    if valid:
        high = np.where(np.isnan(values), -np.inf, values)
        top = int(np.argmax(high))
        # a percent file's reflectances are judged by value_problem below (with its reasons); a
        # BRDF is in 1/sr whatever the units line, so in a percent file a value above 150 % is
        # a BRDF above 1.5 1/sr written as percent
        if high[top] > PERCENT_THRESHOLD and (
            units is None or (units == "fraction") != (kind == "brdf")
        ):
            if units == "percent":
                message = (
                    f"value {high[top] * 100:g} % exceeds {PERCENT_THRESHOLD * 100:g} %: a BRDF is "
                    "given in 1/sr, not in percent; write BRDFs in a file with '# units: fraction'"
                )
            elif units == "fraction":
                message = (
                    f"value {high[top]:g} exceeds {PERCENT_THRESHOLD} although '# units: fraction' "
                    "is set; this looks like percent"
                )
            elif kind == "brdf":
                message = (
                    f"value {high[top]:g} exceeds {PERCENT_THRESHOLD}: this looks like percent "
                    "(divide by 100 or add the line '# units: percent' before the header), or it "
                    f"is a BRDF above {PERCENT_THRESHOLD} 1/sr (a gloss peak), read only when the "
                    "file says so: add the line '# units: fraction' before the header"
                )
            else:
                message = (
                    f"value {high[top]:g} exceeds {PERCENT_THRESHOLD}: this looks like percent; "
                    "divide "
                    "by 100 or add the line '# units: percent' before the header"
                )
            problems.append(
                Problem(message, file=name, row=row_number, field=wavelength_columns[top][2])
            )
            valid = False
        elif kind in MEASUREMENT_KINDS and (
            bad := value_problem(kind, np.fmax(high, 0.0), percent=units == "percent")
        ):
            top, message = bad
            problems.append(
                Problem(message, file=name, row=row_number, field=wavelength_columns[top][2])
            )
            valid = False
    attributes = {key: get[key] for key in (*SAMPLE_FIELDS, RECIPE_FIELD) if key in get}
    return Row(
        name,
        row_number,
        sample,
        kind,
        get["geometry"],
        values,
        attributes,
        wavelength_fields=wavelength_fields,  # shared by all rows, never changed in place
        valid=valid,
    )
