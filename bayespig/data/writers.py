"""Writers of the bayespig CSV and ASTM E1392 formats, and the format constants readers share.

The writers take a :class:`~bayespig.data.model.MeasurementSet` (any object with
its attributes) and need nothing else of the data model, so the model's
``to_csv`` / ``to_astm_e1392`` methods can use them while the readers, which
build measurement sets, sit on top of both: ``model -> writers``, ``readers ->
model, writers``, no circle.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
import unicodedata

from .errors import atomic_write_text

__all__ = [
    "ANGLE_COLUMNS",
    "FORMAT_LINE",
    "FORMAT_NAME",
    "KEYWORDS",
    "METADATA_KEY",
    "SETTINGS",
    "format_astm_e1392",
    "format_csv",
    "write_astm_e1392",
    "write_csv",
]

#: Value of the ``# format:`` line of a bayespig CSV file.
FORMAT_NAME = "bayespig-measurements-1"
#: The ``# key:`` line that holds, as one JSON object, the metadata whose keys cannot be
#: ``# key:`` lines of their own.
METADATA_KEY = "metadata"
#: ``# key:`` settings with a meaning in a bayespig CSV file; any other key is metadata.
SETTINGS = ("format", "units", "n", METADATA_KEY)
#: A metadata key that can be a ``# key: value`` line of its own.
METADATA_LINE_KEY = re.compile(r"[A-Za-z_][\w.\-]*", re.ASCII)

#: First line of an ASTM E1392 file.
FORMAT_LINE = "#FORMAT=ASTM-E1392-96"
#: The first four VARS columns of an ASTM E1392 file [rad].
ANGLE_COLUMNS = ("theta_i", "phi_i", "theta_s", "phi_s")
#: ASTM E1392 header keywords bayespig interprets -> sample attribute.
KEYWORDS = {
    "ROLE": "role",
    "SUBSTRATE": "substrate",
    "FILM_GROUP": "film_group",
    "OPAQUE": "opaque",
    "THICKNESS_UM": "thickness_um",
    "CONCENTRATION": "concentration",
    "EPS": "eps",
}


def _fmt(x):
    """Shortest text that reads back as the same float (``400`` for 400.0)."""
    text = repr(float(x))
    return text.removesuffix(".0")


def _csv_row(cells):
    """One CSV line; a first cell starting with ``#`` is quoted so it is not read as a comment."""
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerow(cells)
    line = out.getvalue()
    if line.lstrip().startswith("#"):
        first = '"' + cells[0].replace('"', '""') + '"'
        rest = io.StringIO()
        csv.writer(rest, lineterminator="\n").writerow(cells[1:])
        line = f"{first},{rest.getvalue()}"
    return line


def _check_text(text, what):
    """ValueError when ``text`` has characters a line-based text file cannot hold."""
    bad = [c for c in text if unicodedata.category(c) == "Cc"]
    if bad:
        raise ValueError(
            f"{what} {text!r} contains the control character {bad[0]!r}, which a text file "
            "cannot hold; rename it"
        )


def format_csv(measurements):
    """The bayespig CSV text of a :class:`~bayespig.data.model.MeasurementSet`.

    Metadata whose key is a plain identifier (letters, digits, ``_``, ``.``,
    ``-``; not a setting) is written as a ``# key: <JSON>`` line; all other
    keys together as one ``# metadata: <JSON object>`` line, so every key
    reads back.
    """
    lines = [f"# format: {FORMAT_NAME}\n# units: fraction\n# n: {_fmt(measurements.n)}\n"]
    others = {}
    for key, value in measurements.metadata.items():
        if METADATA_LINE_KEY.fullmatch(key) and key.lower() not in SETTINGS:
            lines.append(f"# {key}: {json.dumps(value)}\n")
        else:
            others[key] = value
    if others:
        lines.append(f"# {METADATA_KEY}: {json.dumps(others)}\n")
    optional = [
        c
        for c in ("thickness_um", "concentration", "eps")
        if any(getattr(s, c) is not None for s in measurements.samples)
    ]
    header = ["sample", "role", "substrate", "film_group", "opaque", *optional]
    header += ["measurement", "geometry"]
    lines.append(_csv_row(header + [_fmt(w) for w in measurements.wavelength_nm]))
    for s in measurements.samples:
        _check_text(s.name, "sample name")
        substrate = (
            ""
            if s.substrate is None
            else (_fmt(s.substrate) if isinstance(s.substrate, float) else s.substrate)
        )
        _check_text(substrate, "substrate")
        _check_text(s.film_group or "", "film group")
        fixed = [s.name, s.role, substrate, s.film_group or "", "yes" if s.opaque else "no"]
        fixed += ["" if getattr(s, c) is None else _fmt(getattr(s, c)) for c in optional]
        for m in s.measurements:
            lines.append(_csv_row(fixed + [m.kind, m.label] + [_fmt(v) for v in m.values]))
    return "".join(lines)


def write_csv(measurements, path):
    """Write a measurement set as a bayespig CSV file, atomically (nothing is written on error).

    Values are written with full precision, so reading the file back gives
    identical arrays and metadata.

    Parameters
    ----------
    measurements : MeasurementSet
    path : str or os.PathLike

    Raises
    ------
    ValueError
        When a name holds a control character (NUL, carriage return, ...), before
        anything is written.
    """
    atomic_write_text(path, format_csv(measurements))


def format_astm_e1392(measurements, sample=None):
    """ASTM E1392 text of one sample's BRDFs (see :func:`write_astm_e1392`)."""
    if sample is None:
        if len(measurements.samples) != 1:
            raise ValueError(
                "an ASTM E1392 file holds one sample; choose one with sample= from "
                f"{', '.join(measurements.sample_names)}"
            )
        chosen = measurements.samples[0]
    else:
        chosen = measurements.sample(sample) if isinstance(sample, str) else sample
    other = [m.kind for m in chosen.measurements if m.kind != "brdf"]
    if other or not chosen.measurements:
        raise ValueError(
            f"sample {chosen.name!r} has {', '.join(sorted(set(other))) or 'no BRDF'} "
            "measurements; "
            "ASTM E1392 files hold BRDFs only: write it as bayespig CSV instead"
        )
    _check_text(chosen.name, "sample name")
    out = io.StringIO()
    out.write(f"{FORMAT_LINE}\n")
    out.write(
        "# bayespig: BRDF [1/sr] without the surface's specular reflection; angles in radians; "
        "phi_s = phi_i + pi is the specular side\n"
    )
    out.write(f"NAME {chosen.name}\nROLE {chosen.role}\n")
    for keyword, attribute in KEYWORDS.items():
        value = getattr(chosen, attribute)
        if attribute in ("role",) or value is None:
            continue
        if attribute == "opaque":
            out.write(f"OPAQUE {'yes' if value else 'no'}\n")
        else:
            text = _fmt(value) if isinstance(value, float) else value
            _check_text(text, attribute)
            out.write(f"{keyword} {text}\n")
    out.write(f"N {_fmt(measurements.n)}\n")
    if measurements.metadata:
        out.write(f"BAYESPIG_METADATA {json.dumps(dict(measurements.metadata))}\n")
    out.write(f"NUM_POINTS {len(chosen.measurements)}\n")
    out.write(
        "VARS "
        + ",".join([*ANGLE_COLUMNS, *(f"{_fmt(w)}nm" for w in measurements.wavelength_nm)])
        + "\n"
    )
    for m in chosen.measurements:
        angles = (math.radians(m.theta_i), 0.0, math.radians(m.theta_o), math.radians(m.delta_phi))
        out.write(",".join(_fmt(x) for x in (*angles, *m.values)) + "\n")
    return out.getvalue()


def write_astm_e1392(measurements, path, *, sample=None):
    """Write one sample's BRDFs as an ASTM E1392 text file, atomically.

    Parameters
    ----------
    measurements : MeasurementSet
    path : str or os.PathLike
    sample : str, optional
        The sample to write (required when the set has several). A film whose
        substrate is a substrate sample needs that sample's file too when read
        back: ``read_astm_e1392([film_file, card_file])``.

    Raises
    ------
    ValueError
        When the sample has measurements other than BRDFs.
    """
    atomic_write_text(path, format_astm_e1392(measurements, sample))
