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
    "RECIPE_FIELD",
    "RECIPE_SYNTAX",
    "SETTINGS",
    "format_astm_e1392",
    "format_csv",
    "format_recipe",
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

#: The bayespig CSV column (and sample attribute) holding a film's recipe.
RECIPE_FIELD = "recipe"
#: How a recipe is written, for messages.
RECIPE_SYNTAX = (
    "write pigment:amount pairs separated by ';', e.g. 'ZincWhite:90;BoneBlack:10' "
    "(relative masses)"
)
#: Characters a pigment name in a recipe cell cannot hold.
_RECIPE_SEPARATORS = (":", ";")

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


def format_recipe(composition):
    """``{"pigments": [...], "mass_ratios": [...]}`` as a recipe cell, ``ZincWhite:90;BoneBlack:10``.

    Amounts are written with full precision, so the cell reads back as the same composition.

    Raises
    ------
    ValueError
        When the composition cannot be written as a recipe cell (names with ``:``, ``;``,
        control characters or surrounding spaces, amounts that are not finite numbers >= 0,
        all zero, lists of different lengths, a name twice).
    """
    if not isinstance(composition, dict) or set(composition) != {"pigments", "mass_ratios"}:
        raise ValueError("a composition is a dict with 'pigments' and 'mass_ratios' only")
    pigments, ratios = composition["pigments"], composition["mass_ratios"]
    if not isinstance(pigments, list) or not isinstance(ratios, list) or not pigments:
        raise ValueError("a composition's pigments and mass_ratios are non-empty lists")
    if len(pigments) != len(ratios) or len(set(map(str, pigments))) != len(pigments):
        raise ValueError("a composition needs one mass ratio per pigment, each pigment once")
    cells = []
    for name, ratio in zip(pigments, ratios):
        if (
            not isinstance(name, str)
            or not name
            or name != name.strip()
            or any(c in name for c in _RECIPE_SEPARATORS)
        ):
            raise ValueError(f"pigment name {name!r} cannot be written in a recipe cell")
        _check_text(name, "pigment name")
        if (
            isinstance(ratio, bool)
            or not isinstance(ratio, (int, float))
            or not math.isfinite(ratio)
            or ratio < 0
        ):
            raise ValueError(f"mass ratio {ratio!r} of {name!r} is not a finite number >= 0")
        cells.append(f"{name}:{_fmt(ratio)}")
    if not any(ratios):
        raise ValueError("all mass ratios are zero")
    return ";".join(cells)


def _recipe_cells(measurements):
    """Sample name -> recipe cell, and the metadata left to write as ``#`` lines.

    ``metadata["composition"]`` is the recipe of every film; ``metadata["compositions"]``
    (film group -> composition) that of each group. Written as the ``recipe`` column when
    the file reads back as the same metadata (see ``_assemble._recipe_metadata``), otherwise
    left as metadata.
    """
    metadata = dict(measurements.metadata)
    groups = measurements.film_groups
    keys = [key for key in ("composition", "compositions") if key in metadata]
    if not groups or len(keys) != 1:
        return {}, metadata
    if keys == ["composition"]:
        per_group = {group: metadata["composition"] for group in groups}
    else:
        per_group = metadata["compositions"]
        if not isinstance(per_group, dict) or not set(per_group) <= set(groups):
            return {}, metadata
        values = list(per_group.values())
        if set(per_group) == set(groups) and all(v == values[0] for v in values):
            return {}, metadata  # it would read back as one 'composition'
    try:
        texts = {group: format_recipe(c) for group, c in per_group.items()}
    except ValueError:
        return {}, metadata
    del metadata[keys[0]]
    cells = {film.name: texts[g] for g, films in groups.items() if g in texts for film in films}
    return cells, metadata


def format_csv(measurements):
    """The bayespig CSV text of a :class:`~bayespig.data.model.MeasurementSet`.

    Metadata whose key is a plain identifier (letters, digits, ``_``, ``.``,
    ``-``; not a setting) is written as a ``# key: <JSON>`` line; all other
    keys together as one ``# metadata: <JSON object>`` line, so every key
    reads back. The films' recipes (``metadata["composition"]``, or
    ``metadata["compositions"]`` per film group) are written as the ``recipe``
    column when they read back the same, else as metadata.
    """
    lines = [f"# format: {FORMAT_NAME}\n# units: fraction\n# n: {_fmt(measurements.n)}\n"]
    recipes, metadata = _recipe_cells(measurements)
    others = {}
    for key, value in metadata.items():
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
    header += [RECIPE_FIELD] * bool(recipes) + ["measurement", "geometry"]
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
        fixed += [recipes.get(s.name, "")] * bool(recipes)
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
