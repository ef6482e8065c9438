"""ASTM E1392 BRDF text files: header keywords, then one row per geometry.

The layout is the one of the Cornell reflectance database and of BRDF tools
that read "ASTM E1392-96" files::

    #FORMAT=ASTM-E1392-96
    NAME on_black
    SUBSTRATE black
    NUM_POINTS 2
    VARS theta_i,phi_i,theta_s,phi_s,400nm,500nm,600nm
    0.7853981633974483,0,0.5235987755982988,3.141592653589793,0.0123,0.0145,0.0151
    0.7853981633974483,0,1.0471975511965976,3.141592653589793,0.0118,0.0139,0.0144

Angles are in radians: ``theta_i``, ``phi_i`` the direction towards the source,
``theta_s``, ``phi_s`` the direction towards the detector, both measured from
the sample normal, azimuths in the sample plane. The mirror direction of the
source is ``theta_s = theta_i``, ``phi_s = phi_i + pi``. bayespig's azimuth
difference, 180° on the specular side and 0° back towards the source
(DESIGN.md), is therefore ``delta_phi = |phi_s - phi_i|`` folded into [0°, 180°].
Angles are rounded to 1e-4° when read. Values are BRDF in 1/sr.

One file holds one sample, named by the standard's ``SAMPLE_NAME`` (else ``NAME``,
else the file name). Besides the standard's free-form keywords (kept as
metadata), bayespig reads and writes ``NAME``, ``ROLE``, ``SUBSTRATE``,
``FILM_GROUP``, ``OPAQUE``, ``THICKNESS_UM``, ``CONCENTRATION``, ``EPS``, ``N``
(binder refractive index) and ``BAYESPIG_METADATA`` (JSON). The standard has no
keyword for ``OPAQUE``/``SUBSTRATE``: a film whose header gives neither is refused
unless the reader is told (``opaque=``/``substrate=``, which win over the file).
Several files (the
same film over black and over white, a substrate card) read together form one
measurement set.
"""

from __future__ import annotations

import json
import math
import os
import re
from itertools import pairwise
from pathlib import Path

import numpy as np

from ._assemble import Row, assemble, parse_number
from ._source import Source, load
from .errors import MeasurementError, Problem
from .model import value_problem, wavelength_problem
from .writers import ANGLE_COLUMNS, KEYWORDS, _fmt

__all__ = ["looks_like_astm_e1392", "read_astm_e1392"]
#: Sample attributes whose argument to :func:`read_astm_e1392` wins over the file's keyword.
OVERRIDES = ("opaque", "substrate")
#: Decimals of a degree kept when converting angles from radians.
ANGLE_DECIMALS = 4

_WAVELENGTH = re.compile(r"^\s*(\d+(?:\.\d*)?)\s*(?:nm)?\s*$", re.IGNORECASE)
_KEYWORD = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)(?:\s+(.*))?$")


def looks_like_astm_e1392(source):
    """True for ASTM E1392 text (``.astm`` suffix, a ``#FORMAT=ASTM`` or ``VARS`` line).

    Parameters
    ----------
    source : Source
        The file, read once (:func:`bayespig.data._source.load`).
    """
    if Path(source.name).suffix.lower() == ".astm":
        return True
    head = source.head().splitlines()[:200]
    return any(line.upper().startswith(("#FORMAT=ASTM", "VARS ")) for line in head)


def _fold_azimuth(phi_i, phi_s):
    """``|phi_s - phi_i|`` folded into [0, 180] [deg]."""
    difference = abs(math.degrees(phi_s - phi_i)) % 360.0
    return 360.0 - difference if difference > 180.0 else difference


def _split(line):
    return [cell.strip() for cell in (line.split(",") if "," in line else line.split())]


def _fast_numbers(cells):
    """The numbers of a data row when all are finite and the BRDFs >= 0 (else None: check each)."""
    try:
        numbers = np.array(cells, dtype=float)
    except ValueError:
        return None
    if not np.isfinite(numbers).all() or (numbers[4:] < 0).any():
        return None
    return numbers.tolist()


def _read_one(path, defaults, problems, progress):
    """Rows, wavelengths, binder index and metadata of one file."""
    source = load(path)
    name = source.name
    lines = source.take_lines("astm_e1392")
    header, header_rows, vars_index = {}, {}, None
    for index, line in enumerate(lines):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        match = _KEYWORD.match(stripped)
        if not match:
            problems.append(
                Problem(
                    f"expected a header line 'KEYWORD value' before VARS, got {stripped[:40]!r}",
                    file=name,
                    row=index + 1,
                )
            )
            continue
        key, value = match.group(1).upper(), (match.group(2) or "").strip()
        if key == "VARS":
            vars_index = index
            break
        if key in header:
            problems.append(
                Problem(f"header keyword {key} is given twice", file=name, row=index + 1, field=key)
            )
        header[key], header_rows[key] = value, index + 1
    if vars_index is None:
        problems.append(
            Problem(
                "no VARS line (VARS theta_i,phi_i,theta_s,phi_s,<wavelength>nm,...)",
                file=name,
                field="VARS",
            )
        )
        return None
    vars_row = vars_index + 1
    names = _split(lines[vars_index].strip()[4:])
    if [v.lower() for v in names[:4]] != list(ANGLE_COLUMNS):
        problems.append(
            Problem(
                f"VARS must start with {','.join(ANGLE_COLUMNS)}, got {','.join(names[:4])}",
                file=name,
                row=vars_row,
                field="VARS",
            )
        )
        return None
    wavelength_nm = []
    for column in names[4:]:
        match = _WAVELENGTH.match(column)
        if not match:
            problems.append(
                Problem(
                    f"column {column!r} is not a wavelength such as '550nm' (bayespig reads "
                    "spectral BRDFs, not RGB or XYZ)",
                    file=name,
                    row=vars_row,
                    field=column,
                )
            )
        else:
            wavelength_nm.append(float(match.group(1)))
    if not wavelength_nm:
        problems.append(
            Problem(
                "no wavelength columns after the four angles", file=name, row=vars_row, field="VARS"
            )
        )
    if any(w <= 0 for w in wavelength_nm) or any(b <= a for a, b in pairwise(wavelength_nm)):
        problems.append(
            Problem(
                "wavelength columns must be > 0 nm and in increasing order",
                file=name,
                row=vars_row,
                field="VARS",
            )
        )
    elif unit := wavelength_problem(wavelength_nm):
        wavelength_columns = [c for c in names[4:] if _WAVELENGTH.match(c)]
        problems.append(
            Problem(unit[1], file=name, row=vars_row, field=wavelength_columns[unit[0]])
        )
    if problems and any(p.file == name for p in problems):
        return None

    # SAMPLE_NAME is the standard's keyword, NAME bayespig's own; the one not used (and
    # SAMPLE_NAME always) stays in the metadata with the other free-form keywords
    sample = header.get("SAMPLE_NAME", "") or header.pop("NAME", "")
    sample = sample or defaults.get("name") or Path(name).stem
    n_text = header.pop("N", None)
    n = 1.45
    if n_text is not None:
        try:
            n = parse_number(n_text)
            if not 1.0 <= n < math.inf:
                raise ValueError(f"must be a finite number >= 1, got {n_text!r}")
        except ValueError as error:
            n = 1.45
            problems.append(
                Problem(
                    f"binder refractive index N: {error}",
                    file=name,
                    row=header_rows["N"],
                    field="N",
                )
            )
    metadata = {}
    if "BAYESPIG_METADATA" in header:
        try:
            metadata = json.loads(header.pop("BAYESPIG_METADATA"))
        except (ValueError, RecursionError):
            metadata = None
        if not isinstance(metadata, dict):
            problems.append(
                Problem(
                    "BAYESPIG_METADATA must be a JSON object",
                    file=name,
                    row=header_rows["BAYESPIG_METADATA"],
                    field="BAYESPIG_METADATA",
                )
            )
            metadata = {}
    num_points = header.pop("NUM_POINTS", None)
    attributes, fields, field_rows = {}, {"geometry": "theta_i,phi_i,theta_s,phi_s"}, {}
    for keyword, attribute in KEYWORDS.items():
        fields[attribute] = keyword
        field_rows[attribute] = header_rows.get(keyword, vars_row)
        value = defaults.get(attribute)
        if keyword in header and (attribute not in OVERRIDES or value is None):
            attributes[attribute] = header.pop(keyword)
        elif value is not None:
            header.pop(keyword, None)  # opaque=/substrate= win over the file's keyword
            attributes[attribute] = (
                ("yes" if value else "no") if isinstance(value, bool) else str(value)
            )
    attributes.setdefault("role", "film")
    undecided = (
        attributes["role"] == "film"
        and not attributes.get("substrate", "").strip()
        and not attributes.get("opaque", "").strip()
    )
    if undecided:
        problems.append(
            Problem(
                "the header says neither OPAQUE nor SUBSTRATE (ASTM E1392 has no keyword for "
                "them): say whether the film hides its substrate with opaque=True (--opaque on "
                "the command line) or give substrate='black', 'white' or an albedo "
                "(--substrate), or add the header line 'OPAQUE yes' or 'SUBSTRATE black'",
                file=name,
                field="OPAQUE",
            )
        )
    if header:
        metadata.setdefault("astm_e1392_header", {})[sample] = header

    rows = []
    n_columns = 4 + len(wavelength_nm)
    wavelength_fields = [f"{_fmt(w)}nm" for w in wavelength_nm]
    update = source.progress(progress, len(lines))
    for index in range(vars_index + 1, len(lines)):
        line, row_number = lines[index].strip(), index + 1
        lines[index] = None  # parsed: free it
        update(index)
        if not line or line.startswith("#"):
            continue
        cells = _split(line)
        if len(cells) != n_columns:
            problems.append(
                Problem(
                    f"has {len(cells)} fields but VARS names {n_columns}", file=name, row=row_number
                )
            )
            continue
        numbers, valid = _fast_numbers(cells), True
        if numbers is None:
            numbers = []
            for column, cell in zip(names, cells):
                try:
                    value = parse_number(cell)
                except ValueError as error:
                    problems.append(Problem(str(error), file=name, row=row_number, field=column))
                    valid = False
                    continue
                if not math.isfinite(value):
                    problems.append(
                        Problem(
                            f"value {cell!r} is not finite", file=name, row=row_number, field=column
                        )
                    )
                    valid = False
                elif len(numbers) >= 4 and value < 0:
                    problems.append(
                        Problem(f"negative BRDF {cell}", file=name, row=row_number, field=column)
                    )
                    valid = False
                numbers.append(value)
        if valid and (bad := value_problem("brdf", numbers[4:])):
            problems.append(Problem(bad[1], file=name, row=row_number, field=names[4 + bad[0]]))
            valid = False
        if not valid:
            continue
        angles = numbers[:4]
        if max(abs(x) for x in angles) > 2 * math.pi + 1e-9:
            problems.append(
                Problem(
                    "angles look like degrees; ASTM E1392 files give them in radians",
                    file=name,
                    row=row_number,
                    field=names[int(np.argmax(np.abs(angles)))],
                )
            )
            continue
        theta_i, phi_i, theta_s, phi_s = angles
        bad = [
            (c, v)
            for c, v in (("theta_i", theta_i), ("theta_s", theta_s))
            if not 0.0 <= v < math.pi / 2
        ]
        if bad:
            column, value = bad[0]
            problems.append(
                Problem(
                    f"{column} = {value:g} rad ({math.degrees(value):.4g} deg) is outside [0, "
                    "pi/2)",
                    file=name,
                    row=row_number,
                    field=column,
                )
            )
            continue
        geometry = "/".join(
            str(round(x, ANGLE_DECIMALS))
            for x in (math.degrees(theta_i), math.degrees(theta_s), _fold_azimuth(phi_i, phi_s))
        )
        rows.append(
            Row(
                name,
                row_number,
                sample,
                "brdf",
                geometry,
                np.array(numbers[4:]),
                dict(attributes),
                dict(fields),
                wavelength_fields,
                True,
                dict(field_rows),
            )
        )
    update.close()
    if num_points is not None:
        try:
            expected = int(num_points)
        except ValueError:
            expected = None
        if (
            expected is None
            or expected != len(rows)
            and not any(p.file == name and p.row for p in problems)
        ):
            problems.append(
                Problem(
                    f"NUM_POINTS says {num_points} but the file has {len(rows)} data rows",
                    file=name,
                    row=header_rows["NUM_POINTS"],
                    field="NUM_POINTS",
                )
            )
    if not rows and not any(p.file == name for p in problems):
        problems.append(Problem("no data rows after VARS", file=name, row=vars_row))
    if undecided:
        return None  # said once above, not once more per sample by the set's checks
    return name, rows, np.array(wavelength_nm), n, metadata


def read_astm_e1392(
    paths,
    *,
    name=None,
    role=None,
    substrate=None,
    opaque=None,
    film_group=None,
    resample=False,
    progress=None,
):
    """Read one or several ASTM E1392 BRDF files into one measurement set.

    Parameters
    ----------
    paths : path or sequence of paths
        One file per sample.
    name, role, film_group : optional
        Used when a file's header does not give ``SAMPLE_NAME`` (the standard's
        keyword) or ``NAME``, ``ROLE`` (default ``"film"``) or ``FILM_GROUP``.
    substrate, opaque : optional
        ``SUBSTRATE`` (``"black"``, ``"white"``, an albedo or the name of a
        substrate sample in another of the files) and ``OPAQUE`` (True when the
        film hides its substrate). ASTM E1392 has no keyword for either, so a
        film whose header gives neither is refused unless one is passed here.
        When given, the argument wins over the file's keyword (the keyword is
        then dropped, not kept as metadata).
    resample : bool
        Interpolate files with different wavelengths onto the wavelengths all
        cover (with a warning) instead of raising.
    progress : None, bool or callable
        Progress while reading: None shows a bar on stderr for files larger
        than 20 MB; False nothing; a callable is called as ``progress(lines_read,
        lines_total)`` for each file.

    Returns
    -------
    MeasurementSet

    Raises
    ------
    MeasurementError
        Listing every problem with file, row (line number) and field.
    """
    if isinstance(paths, (str, os.PathLike, Source)):
        paths = [paths]
    paths = list(paths)
    if not paths:
        raise ValueError("paths must name at least one file")
    defaults = dict(name=name, role=role, substrate=substrate, opaque=opaque, film_group=film_group)
    problems, files = [], []
    for path in paths:
        result = _read_one(
            path, defaults if len(paths) == 1 else {**defaults, "name": None}, problems, progress
        )
        if result is not None:
            files.append((result[0], *result[1:]))
    if not files:
        raise MeasurementError(problems)
    grid = np.unique(np.concatenate([f[2] for f in files]))
    rows, metadata, n_values = [], {}, {}
    for file, file_rows, wavelength_nm, n, file_metadata in files:
        position = np.searchsorted(grid, wavelength_nm)
        fields = [f"{_fmt(w)}nm" for w in grid]
        for row in file_rows:
            values = np.full(grid.size, np.nan)
            values[position] = row.values
            row.values, row.wavelength_fields = values, fields
            rows.append(row)
        n_values[file] = n
        for key, value in file_metadata.items():
            if key == "astm_e1392_header":
                metadata.setdefault(key, {}).update(value)
            elif key in metadata and metadata[key] != value:
                problems.append(
                    Problem(
                        f"BAYESPIG_METADATA key {key!r} differs from the other files'",
                        file=file,
                        field="BAYESPIG_METADATA",
                    )
                )
            else:
                metadata[key] = value
    if len(set(n_values.values())) > 1:
        problems.append(
            Problem(f"files give different binder refractive indices N: {n_values}", field="N")
        )
    return assemble(
        rows,
        grid,
        n=next(iter(n_values.values())),
        metadata=metadata,
        source=", ".join(f[0] for f in files),
        resample=resample,
        problems=problems,
    )
