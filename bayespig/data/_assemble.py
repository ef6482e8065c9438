"""Rows read from files -> a validated MeasurementSet, with every problem located at its row.

Every reader (bayespig CSV, ASTM E1392, wide spectral tables) turns its file
into :class:`Row` records (one spectrum each, sample attributes as text) and
hands them to :func:`assemble`, which checks what concerns several rows at once
(wavelengths that differ, duplicated rows, sample attributes that disagree,
substrates, film groups) and builds the set.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from .errors import MeasurementError, Problem
from .model import FILM_ROLES, ROLES, Measurement, MeasurementSet, Sample, set_problems
from .writers import RECIPE_FIELD, RECIPE_SYNTAX

#: Per-sample attributes a file can give, in the order they are written.
SAMPLE_FIELDS = (
    "role",
    "substrate",
    "film_group",
    "opaque",
    "thickness_um",
    "concentration",
    "eps",
)

#: Cards below these values cannot have an albedo under binder above 1, so their albedo is not
#: computed for the warning about it: hemispherical/45-0 reflectance [-] and BRDF [1/sr]
#: (eq. 9 inverted exceeds 1 only above about 1 - r_F = 0.96 and 0.35 1/sr at n = 1.45).
#: Two recipes of one film group are the same when their normalised fractions agree this well
#: (relative): ``ZincWhite:90;BoneBlack:10`` and ``ZincWhite:9;BoneBlack:1`` are one recipe.
RECIPE_MATCH_RTOL = 1e-9
CARD_CHECK_REFLECTANCE = 0.8
CARD_CHECK_BRDF = 0.8 / math.pi
_TRUE = ("yes", "y", "true", "1")
_FALSE = ("no", "n", "false", "0")


@dataclass(eq=False, slots=True)
class Row:
    """One spectrum as read from a file.

    Attributes
    ----------
    file : str
    row : int
        1-based line number.
    sample : str
    kind : str
        Measurement kind.
    geometry : str
        Geometry text (see :func:`~bayespig.data.model.parse_measurement_geometry`).
    values : numpy.ndarray
        One value per wavelength of the file, NaN where the cell was blank.
    attributes : dict
        Sample attribute -> text as written (blank = not given); also ``"recipe"``, the
        film's recipe (:func:`parse_recipe`).
    fields : dict
        Sample attribute -> name of the field it came from (column or keyword), for messages.
    wavelength_fields : list of str
        Field names of the wavelength values, for messages.
    valid : bool
        False when the reader already reported a problem with the values.
    field_rows : dict
        Sample attribute -> line number where it is given, when not on this row
        (header keywords of an ASTM E1392 file).
    """

    file: str
    row: int
    sample: str
    kind: str
    geometry: str
    values: np.ndarray
    attributes: dict = field(default_factory=dict)
    fields: dict = field(default_factory=dict)
    wavelength_fields: list = field(default_factory=list)
    valid: bool = True
    field_rows: dict = field(default_factory=dict)

    def locate(self, problem):
        """The problem placed at this row, its field renamed to this file's field name."""
        located = problem.located(self.file, self.field_rows.get(problem.field, self.row))
        return dataclasses.replace(located, field=self.fields.get(problem.field, problem.field))


def parse_number(text):
    """A float from a cell; ``ValueError`` with a hint for decimal commas."""
    text = text.strip()
    try:
        return float(text)
    except ValueError:
        if "," in text and text.replace(",", "", 1).replace("-", "", 1).isdigit():
            raise ValueError(
                f"{text!r} is not a number (decimal comma? use a point: {text.replace(',', '.')})"
            ) from None
        raise ValueError(f"{text!r} is not a number") from None


def parse_recipe(text):
    """A film's recipe from its text (``ZincWhite:90;BoneBlack:10``), as metadata.

    ``pigment:amount`` pairs separated by ``;`` (spaces around names and amounts are ignored,
    a final ``;`` too); amounts are relative masses >= 0 in any unit (they need not sum to 1
    or 100); a zero amount is kept (the pigment is absent, as in the Revigo specifications).

    Returns
    -------
    dict
        ``{"pigments": [str, ...], "mass_ratios": [float, ...]}``, in the written order: the
        form :func:`bayespig.data.read_revigo` gives in ``metadata["composition"]``.

    Raises
    ------
    ValueError
        Saying what is wrong: not ``pigment:amount`` pairs, an amount that is not a number,
        NaN, infinite or negative, a pigment given twice, all amounts zero.
    """
    parts = [part.strip() for part in text.split(";")]
    if len(parts) > 1 and not parts[-1]:
        parts.pop()
    pigments, ratios = [], []
    for part in parts:
        name, colon, amount = part.partition(":")
        name, amount = name.strip(), amount.strip()
        if not colon or not name or not amount or ":" in amount:
            raise ValueError(
                f"cannot read recipe {text!r}: {part!r} is not pigment:amount; {RECIPE_SYNTAX}"
            )
        try:
            value = parse_number(amount)
        except ValueError as error:
            raise ValueError(f"recipe {text!r}: the amount of {name!r}: {error}") from None
        if math.isnan(value):
            raise ValueError(f"recipe {text!r}: the amount of {name!r} is NaN; give a number >= 0")
        if math.isinf(value):
            raise ValueError(
                f"recipe {text!r}: the amount of {name!r} must be finite, got {amount}"
            )
        if value < 0:
            raise ValueError(
                f"recipe {text!r}: the amount of {name!r} is negative ({amount}); amounts are >= 0"
            )
        if name in pigments:
            raise ValueError(f"recipe {text!r}: pigment {name!r} is given twice")
        pigments.append(name)
        ratios.append(value)
    if not any(ratios):
        raise ValueError(
            f"recipe {text!r}: all amounts are zero; a film needs at least one pigment"
        )
    return {"pigments": pigments, "mass_ratios": ratios}


def _same_recipe(first, second):
    """True when two compositions are one recipe (the same normalised fractions)."""

    def fractions(composition):
        total = math.fsum(composition["mass_ratios"])
        return {
            p: r / total for p, r in zip(composition["pigments"], composition["mass_ratios"]) if r
        }

    a, b = fractions(first), fractions(second)
    return a.keys() == b.keys() and all(
        math.isclose(a[p], b[p], rel_tol=RECIPE_MATCH_RTOL) for p in a
    )


def _recipes(by_sample, built, problems):
    """Film group -> (composition, text, row) from the rows' recipe cells (problems appended)."""
    groups = {}
    for name, sample_rows in by_sample.items():
        for r in sample_rows:
            text = r.attributes.get(RECIPE_FIELD, "").strip()
            if not text:
                continue
            try:
                composition = parse_recipe(text)
            except ValueError as error:
                problems.append(r.locate(Problem(str(error), field=RECIPE_FIELD)))
                continue
            sample = built.get(name)
            if sample is None:
                continue  # the sample's own problems are reported
            if sample.role not in FILM_ROLES:
                problems.append(
                    r.locate(
                        Problem(
                            f"sample {name!r} is a {sample.role}; only films have a recipe "
                            "(leave the cell blank)",
                            field=RECIPE_FIELD,
                        )
                    )
                )
                continue
            if sample.group not in groups:
                groups[sample.group] = (composition, text, r)
                continue
            first, first_text, first_row = groups[sample.group]
            if not _same_recipe(first, composition):
                problems.append(
                    r.locate(
                        Problem(
                            f"film group {sample.group!r} has recipe {text!r} here but "
                            f"{first_text!r} in {_where(first_row, r)}; the films of one film "
                            "group are one paint: give them one recipe",
                            field=RECIPE_FIELD,
                        )
                    )
                )
    return groups


def _recipe_metadata(groups, samples, metadata, problems):
    """The metadata with the file's recipes: ``composition``, or ``compositions`` per group.

    One ``composition`` when every film group has a recipe and all are written alike (one
    film, or several films of one paint); otherwise ``compositions``: film group ->
    composition, for the groups that have one.
    """
    if not groups:
        return metadata
    first_row = min((r for _, _, r in groups.values()), key=lambda r: r.row)
    given = [key for key in ("composition", "compositions") if key in metadata]
    if given:
        problems.append(
            first_row.locate(
                Problem(
                    f"the file gives recipes both in the {RECIPE_FIELD!r} column and as "
                    f"'# {given[0]}:' metadata; keep one of them",
                    field=RECIPE_FIELD,
                )
            )
        )
        return metadata
    compositions = {group: composition for group, (composition, _, _) in groups.items()}
    film_groups = {s.group for s in samples if s.role in FILM_ROLES}
    values = list(compositions.values())
    if set(compositions) == film_groups and all(v == values[0] for v in values):
        return {**metadata, "composition": values[0]}
    return {**metadata, "compositions": compositions}


def _convert(name, text, sample_names):
    """Text of a sample attribute -> its value (None when blank)."""
    text = text.strip()
    if name == "role":
        role = text.lower()
        if role not in ROLES:
            raise ValueError(f"role must be one of {', '.join(ROLES)}, got {text!r}")
        return role
    if name == "opaque":
        if text.lower() in _TRUE:
            return True
        if text.lower() in _FALSE:
            return False
        raise ValueError(f"opaque must be 'yes' or 'no', got {text!r}")
    if not text:
        return None
    if name == "substrate":
        if text in sample_names or text.lower() in ("black", "white"):
            return text if text in sample_names else text.lower()
        try:
            value = float(text)
        except ValueError:
            return text  # a sample name that does not exist; the set check says so
        if not math.isfinite(value):
            raise ValueError(f"substrate albedo must be finite, got {text!r}")
        return value
    if name == "film_group":
        return text
    return parse_number(text)


def _missing_value_problems(rows, wavelength_nm, resample, problems):
    """Blank cells: an error naming the rows, or (``resample``) a common grid and a warning."""
    missing = (
        np.array([np.isnan(r.values) for r in rows])
        if rows
        else np.zeros((0, wavelength_nm.size), bool)
    )
    if not missing.any():
        return rows, wavelength_nm
    if not resample:
        empty = missing.all(axis=0)
        for column in np.flatnonzero(empty):
            problems.append(
                Problem(
                    f"no row has a value at {wavelength_nm[column]:g} nm; remove the column",
                    file=rows[0].file,
                    row=_first_row(rows),
                    field=rows[0].wavelength_fields[column],
                )
            )
        for r, row_missing in zip(rows, missing):
            gaps = np.flatnonzero(row_missing & ~empty)
            if gaps.size:
                listed = ", ".join(f"{w:g}" for w in wavelength_nm[gaps][:5]) + (
                    ", ..." if gaps.size > 5 else ""
                )
                problems.append(
                    Problem(
                        f"sample {r.sample!r} has no value at {listed} nm but other rows do: "
                        "wavelengths differ "
                        "between samples; measure on one grid, or read with resample=True to "
                        "interpolate all "
                        "rows onto the wavelengths they share",
                        file=r.file,
                        row=r.row,
                        field=r.wavelength_fields[gaps[0]],
                    )
                )
        return rows, wavelength_nm
    lo = max(wavelength_nm[~m].min() if (~m).any() else np.inf for m in missing)
    hi = min(wavelength_nm[~m].max() if (~m).any() else -np.inf for m in missing)
    grid = wavelength_nm[(wavelength_nm >= lo) & (wavelength_nm <= hi)]
    changed = []
    for r, row_missing in zip(rows, missing):
        good = ~row_missing
        if good.sum() < 2 or grid.size == 0:
            problems.append(
                Problem(
                    "too few values to resample (need two or more on the shared range)",
                    file=r.file,
                    row=r.row,
                    field=r.wavelength_fields[0],
                )
            )
            continue
        if row_missing.any() or grid.size != wavelength_nm.size:
            changed.append(r.row)
        r.values = np.interp(grid, wavelength_nm[good], r.values[good])
        r.wavelength_fields = [
            f for f, w in zip(r.wavelength_fields, wavelength_nm) if lo <= w <= hi
        ]
    if changed and not problems:
        warnings.warn(
            f"{rows[0].file}: wavelengths differ between rows; rows {', '.join(map(str, changed))} "
            f"were linearly interpolated onto the {grid.size} wavelengths "
            f"{grid[0]:g}–{grid[-1]:g} nm "
            "that all rows cover",
            UserWarning,
            stacklevel=4,
        )
    return rows, grid


def _where(first, here):
    """'row 5', or 'row 5 of other.astm' when ``first`` is in another file than ``here``."""
    return f"row {first.row}" if first.file == here.file else f"row {first.row} of {first.file}"


def _first_row(rows):
    return min(r.row for r in rows)


def assemble(
    rows, wavelength_nm, *, n=1.45, metadata=None, source=None, resample=False, problems=None
):
    """A :class:`MeasurementSet` from rows, or one :class:`MeasurementError` with every problem.

    Parameters
    ----------
    rows : list of Row
    wavelength_nm : numpy.ndarray
        Wavelengths of the rows' values [nm].
    n : float
        Binder refractive index [-].
    metadata : dict, optional
    source : str, optional
        File name(s) for messages.
    resample : bool
        Interpolate rows with blank cells onto the wavelengths all rows share
        (with a warning) instead of reporting them.
    problems : list of Problem, optional
        Problems already found by the reader (reported together with these).
    """
    problems = list(problems or [])
    valid_rows, wavelength_nm = _missing_value_problems(
        [r for r in rows if r.valid], np.asarray(wavelength_nm, float), resample, problems
    )
    by_sample = {}
    for r in rows:
        by_sample.setdefault(r.sample, []).append(r)
    names = set(by_sample)

    measurements, where = {}, {}
    valid_ids = {id(r) for r in valid_rows}
    for name, sample_rows in by_sample.items():
        seen = {}
        measurements[name] = []
        for r in sample_rows:
            if id(r) not in valid_ids or np.isnan(r.values).any():
                continue  # already reported
            try:
                m = Measurement.from_geometry(r.kind, r.geometry, r.values, (r.file, r.row))
            except MeasurementError as error:
                problems.extend(r.locate(p) for p in error.problems)
                continue
            if m.geometry_key in seen:
                problems.append(
                    r.locate(
                        Problem(
                            f"duplicated row: sample {name!r} already has {m.kind} at {m.label} in "
                            f"{_where(seen[m.geometry_key], r)}; remove one of them",
                            field="geometry",
                        )
                    )
                )
                continue
            seen[m.geometry_key] = r
            measurements[name].append(m)
            where[(name, len(measurements[name]) - 1)] = r

    samples = []
    for name, sample_rows in by_sample.items():
        values, origin, unreadable = {}, {}, set()
        for attribute in SAMPLE_FIELDS:
            given = []
            for r in sample_rows:
                text = r.attributes.get(attribute, "").strip()
                if not text:
                    continue
                try:
                    given.append((_convert(attribute, text, names), text, r))
                except ValueError as error:
                    problems.append(r.locate(Problem(str(error), field=attribute)))
                    unreadable.add(attribute)
            if not given:
                continue
            values[attribute], first_text, origin[attribute] = given[0]
            for value, text, r in given[1:]:
                if value != values[attribute]:
                    first = origin[attribute]
                    problems.append(
                        r.locate(
                            Problem(
                                f"sample {name!r} has {attribute} {text!r} here but "
                                f"{first_text!r} in "
                                f"{_where(first, r)}; "
                                "a sample's attributes must agree on all its rows",
                                field=attribute,
                            )
                        )
                    )
        if "role" not in values and "role" not in unreadable:
            problems.append(
                sample_rows[0].locate(
                    Problem(
                        f"sample {name!r} has no role; give one of {', '.join(ROLES)}", field="role"
                    )
                )
            )
        origin.setdefault("role", sample_rows[0])
        if values.get("role") is None or not measurements[name]:
            continue
        try:
            samples.append(
                Sample(
                    name,
                    values["role"],
                    tuple(measurements[name]),
                    values.get("substrate"),
                    values.get("film_group"),
                    bool(values.get("opaque")),
                    values.get("thickness_um"),
                    values.get("concentration"),
                    values.get("eps"),
                )
            )
        except MeasurementError as error:
            for p in error.problems:
                r = (
                    where.get((name, p.measurement))
                    if p.measurement is not None
                    else origin.get(p.field)
                )
                problems.append((r or sample_rows[0]).locate(p))

    recipes = _recipes(by_sample, {s.name: s for s in samples}, problems)
    metadata = _recipe_metadata(recipes, samples, dict(metadata or {}), problems)
    built = {s.name for s in samples}
    for p in set_problems(wavelength_nm, samples) if samples else []:
        substrate = next((s.substrate for s in samples if s.name == p.sample), None)
        if p.field == "substrate" and substrate in by_sample and substrate not in built:
            continue  # the substrate's own rows are already reported
        sample_rows = by_sample.get(p.sample) or rows
        r = where.get((p.sample, p.measurement)) if p.measurement is not None else None
        if r is None:
            r = next(
                (x for x in sample_rows if x.attributes.get(p.field, "").strip()), sample_rows[0]
            )
        problems.append(r.locate(p))
    if problems:
        # A header keyword (ASTM E1392 ``ROLE``) is checked on each of its rows: once is enough.
        raise MeasurementError(list(dict.fromkeys(problems)))
    measurement_set = MeasurementSet(wavelength_nm, samples, n=n, metadata=metadata, source=source)
    _warn_implausible(measurement_set, where)
    return measurement_set


def _warn_implausible(measurement_set, where):
    """One warning for values no sample gives but a calibration error can: above 1.

    Hemispherical reflectances and specular transmittances in (1, REFLECTANCE_MAX]
    (larger ones are refused), and bare substrates (cards) whose albedo under
    binder (eq. 9 inverted) would exceed 1, are named with their row and field.
    """
    found = []
    by_name = {s.name: s for s in measurement_set.samples}
    for (name, index), r in where.items():
        m = by_name[name].measurements[index]
        if m.kind in ("hemispherical", "specular_transmittance") and m.values.max() > 1.0:
            top = int(np.argmax(m.values))
            what = "transmittance" if m.kind == "specular_transmittance" else "reflectance"
            found.append(
                f"row {r.row}, field {r.wavelength_fields[top]!r}: {what} "
                f"{m.values[top]:.4g} ({m.values[top] * 100:.4g} %) is above 1"
            )
    cards = {}
    for film in measurement_set.films:
        if isinstance(film.substrate, str) and film.substrate in by_name and not film.opaque:
            cards.setdefault(film.substrate, film)
    # Only bright cards can have an albedo above 1 (eq. 9 inverted needs a reflectance above
    # about 1 - r_F, a BRDF above about 0.3 1/sr); skip the integrals for the others.
    cards = {
        card: film
        for card, film in cards.items()
        if any(
            m.values.max() > (CARD_CHECK_BRDF if m.kind == "brdf" else CARD_CHECK_REFLECTANCE)
            for m in by_name[card].measurements
        )
    }
    for card, film in cards.items():
        try:
            measurement_set.substrate_albedo(film)
        except MeasurementError as error:
            r = where.get((card, error.problems[0].measurement or 0))
            found.append(
                f"row {r.row if r else '?'}: card {card!r}: albedo under binder above 1 "
                "(eq. 9 inverted); it cannot serve as a measured substrate"
            )
    if found:
        more = f" (and {len(found) - 3} more)" if len(found) > 3 else ""
        warnings.warn(
            f"{measurement_set.source}: {'; '.join(found[:3])}{more}: no sample reflects or "
            "transmits more than it receives; values slightly above 1 come from the white "
            "standard's calibration error, which the model does not describe: check the "
            "calibration",
            UserWarning,
            stacklevel=4,
        )
