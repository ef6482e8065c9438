"""Recipes of paint films as data, and the pigment concentrations of appendix A2.

A film's recipe says which paints were mixed and how much of each: ``Recipe`` holds the mass
fraction of each paint (pigment paste) in the mixture. Readers give a recipe as
``MeasurementSet.metadata["composition"] = {"pigments": [...], "mass_ratios": [...]}``
(:func:`bayespig.data.read_revigo` from the Revigo mixture-specification file, the ``recipe``
column of a bayespig CSV file); :func:`film_recipes` turns those into recipes and
:func:`concentrations` turns a recipe into the concentrations ``D_i`` the mixing rules of
section 2 need.

Mass or volume
--------------
The Revigo ratios (``Vermillion-ZincWhite-BoneBlack|10-90-0``) are taken as mass ratios of
the paints as mixed (the data do not say; paint makers weigh). The mixing rules weight each
pigment by its number of particles per unit volume of dry paint, ``D_i``, so a mass fraction
is not the concentration the optics sees: 50 g of zinc white (5.65 g/cm^3) fill about a third
of the volume of 50 g of Prussian blue (1.83 g/cm^3). Appendix A2 (eq. 10-12,
:func:`bayespig.physics.mixtures.concentrations_from_mass_fractions`) converts mass fractions
``W_i`` into ``D_i`` with the dry densities ``rho_i`` and drying coefficients ``q_i`` of the
paints::

    D_i = (C_pp_i / mu_i) q_i W_i / (q_b / rho_b + sum_j (q_j / rho_j - q_b / rho_b) W_j).

Only ratios between films matter: ``C_pp_i / mu_i`` (mass fraction of pigment in the paste,
mass of one particle) is a constant per pigment that its extinction absorbs (the optics needs
only ``D_i sigma_ext_i``), so it is set to 1 and ``D_i`` is, up to that constant, the volume
fraction of paint ``i`` in the dry film: with ``q = 1`` and no added binder,
``D_i = rho_i phi_i`` with ``phi_i = (W_i / rho_i) / sum_j (W_j / rho_j)``. What the densities
change is how the concentration of one pigment varies *between* films of different recipes,
e.g. in a 50/50 tint with zinc white against its masstone:

>>> from bayespig.library.recipes import Recipe, concentrations
>>> pigments = ["PrussianBlue", "ZincWhite"]
>>> tint = concentrations({"PrussianBlue": 50, "ZincWhite": 50}, pigments)
>>> blue = concentrations({"PrussianBlue": 100}, pigments)
>>> white = concentrations({"ZincWhite": 100}, pigments)
>>> print(f"{tint[0] / blue[0]:.3f} {tint[1] / white[1]:.3f}")  # each against its masstone
0.755 0.245

With equal densities both would be 0.5. Zinc white (5.65 g/cm^3) takes a quarter of the
tint's volume, Prussian blue (1.83 g/cm^3) three quarters, so against their masstones the tint
holds 0.755 / 0.245 = 3.09 (= 5.65 / 1.83) times more blue per white than the mass ratio says.
Within one film ``D_i / D_j`` is still the mass ratio (``tint[0] / tint[1]`` is 1: with
``C_pp / mu = 1``, ``D`` counts mass per volume); the densities act through each film's volume,
which is what a pigment's constants, learned from films of other recipes, see.

Since the densities change every ``D_i`` of one film by one common factor (``1 / V``, the
film's volume per unit mass of paint), they act exactly like a change of that film's thickness
``h`` (``tau = h sum_i D_i sigma_i``; Kubelka-Munk's ``K X``, ``S X`` alike). For films of
*unknown* thickness, each a free nuisance parameter (a library's films, a held-out film whose
``h`` is fitted), they matter only through the prior on ``log h`` (sd 0.5, against factors of
at most 1.4 between the Revigo films of one colour series, 2.1 between zinc white 07A and the
grey 07F); they matter fully where thicknesses are measured
or a prediction is asked at a given thickness. ``reports/revigo.md`` suspected the
mass-for-volume confusion of its tint misses; measured, it is not their cause (issue 17): the
leave-one-out library prediction of the vermilion 50/50 tint 06C gave ΔE00 0.99 / 0.95 (over
black / white) with :data:`DEFAULT_DENSITIES` and 0.96 / 0.99 with equal densities, and the
independent Kubelka-Munk baseline (``benchmarks/km_baseline.py --concentrations volume``) the
same median on the 50/50 tints with volume as with mass fractions (2.60). So the defaults stay
the pigments' densities, the physically right choice when the amounts are pigment masses, and
harmless when they are paste masses of films of unknown thickness, as Revigo's are.

The defaults
------------
``DEFAULT_DENSITIES`` holds the dry density of the pure pigments [g/cm^3]; the source of each
value is in ``DENSITY_SOURCES``. The densities :func:`concentrations` needs are those of the
paints *as mixed* (pigment pastes); the Revigo data do not give the pastes' oil contents, so the
default takes each paste to be its pigment. When a paste's pigment mass fraction ``c`` is known,
:func:`paste_density` gives its dry density, to pass in ``densities``. Drying coefficients
default to 1 (no loss on drying): the Revigo data give none.

A pigment's density is looked up by this rule, first in the user's ``densities`` then in
``DEFAULT_DENSITIES``:

1. its exact name;
2. otherwise its *base pigment*: the longest name in the table that the name starts with,
   followed by an upper-case letter or a digit (CamelCase variants of one pigment:
   ``ZincWhiteLinseed`` -> ``ZincWhite``, ``ChromeYellowPoppyseed`` and ``ChromeYellowOtero``
   -> ``ChromeYellow``, ``Eosin1Wax`` and ``Eosin2PbWax`` -> ``Eosin``). A different oil, a
   different maker or a wax addition changes the paint, not the pigment's density;
3. otherwise :data:`UNKNOWN_PIGMENT_DENSITY`, the median of ``DEFAULT_DENSITIES`` (3.32
   g/cm^3), without a warning. A recipe whose pigments all fall back gets ``D_i`` proportional
   to ``W_i`` (equal densities), the paper's default.

The lakes (``Eosin``, ``Cochineal``): an organic dye precipitated on a substrate; they are
taken to be lakes on hydrated alumina and get the density of aluminium hydrate (the dye, a few
to twenty per cent of the lake by mass, is ignored). ``Eosin2PbWax`` (a lead-precipitated
eosin lake, by its name) is heavier than an alumina lake by an amount the data do not say; it
gets the alumina value by rule 2; give its density in ``densities`` when known.

References
----------
Ershov, Voloboy & Pozdnyakov (2023), section 2 (mixtures) and appendix A2 (concentrations).
R. J. Gettens & G. L. Stout, *Painting Materials: A Short Encyclopaedia* (Dover, 1966),
table "Physical properties of pigments" (specific gravities).
CRC Handbook of Chemistry and Physics, "Physical constants of inorganic compounds".
"""

from __future__ import annotations

import difflib
import math
import numbers
import types
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..physics.mixtures import concentrations_from_mass_fractions

__all__ = [
    "DEFAULT_BINDER_DENSITY",
    "DEFAULT_DENSITIES",
    "DEFAULT_DRYING",
    "DENSITY_SOURCES",
    "FRACTION_SUM_TOLERANCE",
    "UNKNOWN_PIGMENT_DENSITY",
    "Recipe",
    "base_pigment",
    "concentrations",
    "density_of",
    "film_recipes",
    "paste_density",
    "split_film_groups",
]

_GS = "Gettens & Stout, Painting Materials (1966), table of physical properties of pigments"

#: Pigment -> (dry density [g/cm^3], source).
_DENSITY_TABLE = {
    "ZincWhite": (5.65, f"{_GS}: zinc white (ordinary), ZnO (CRC Handbook: ZnO 5.61)"),
    "LeadWhite": (6.70, f"{_GS}: white lead (basic carbonate), 2PbCO3.Pb(OH)2"),
    "BoneBlack": (2.29, f"{_GS}: bone black, C + Ca3(PO4)2"),
    "Vermillion": (8.09, f"{_GS}: vermilion (artificial), HgS (CRC Handbook: cinnabar 8.1)"),
    "Minium": (8.73, f"{_GS}: red lead, Pb3O4 (c. 95 %)"),
    "ChromeYellow": (6.12, "CRC Handbook: lead(II) chromate PbCrO4"),
    "ViridianGreen": (3.32, f"{_GS}: viridian (transparent chromium oxide), Cr2O3.2H2O"),
    "EmeraldGreen": (
        3.3,
        (
            "approximate: copper aceto-arsenite Cu(C2H3O2)2.3Cu(AsO2)2, reported about 3.3 "
            "(E. W. Fitzhugh (ed.), Artists' Pigments vol. 3, 1997); not checked against the "
            "handbook here, override when it matters"
        ),
    ),
    "UltramarineBlue": (2.34, f"{_GS}: ultramarine blue (artificial)"),
    "CobaltBlue": (
        4.4,
        (
            "crystallographic: spinel CoAl2O4, M = 176.9 g/mol, a = 8.104 Angstrom, Z = 8 "
            "-> 4.42 g/cm^3 (commercial cobalt blues reported 3.8-4.5)"
        ),
    ),
    "PrussianBlue": (1.83, f"{_GS}: Prussian blue, Fe4[Fe(CN)6]3"),
    "BariumSulphate": (4.45, f"{_GS}: barytes (natural BaSO4; blanc fixe 4.36; CRC 4.49)"),
    "CalciumCarbonate": (2.70, f"{_GS}: chalk (whiting), CaCO3 (CRC Handbook: calcite 2.71)"),
    "Eosin": (
        2.45,
        f"assumed lake on hydrated alumina: {_GS}: aluminum hydrate Al(OH)3 (dye ignored)",
    ),
    "Cochineal": (
        2.45,
        (
            f"assumed lake on hydrated alumina (carmine lake): {_GS}: aluminum hydrate Al(OH)3 "
            "(dye ignored)"
        ),
    ),
}

#: Dry density of each pure pigment [g/cm^3] (see the module docstring for the rules).
DEFAULT_DENSITIES = types.MappingProxyType({k: v[0] for k, v in _DENSITY_TABLE.items()})
#: Where each value of :data:`DEFAULT_DENSITIES` comes from.
DENSITY_SOURCES = types.MappingProxyType({k: v[1] for k, v in _DENSITY_TABLE.items()})
#: Density of a pigment neither the user nor the table knows [g/cm^3]: the table's median.
UNKNOWN_PIGMENT_DENSITY = float(np.median(list(DEFAULT_DENSITIES.values())))
#: Raw linseed oil [g/cm^3] (CRC Handbook; 0.93 at 15 C). Used for added binder and by
#: :func:`paste_density`; with no added binder (a recipe's fractions sum to 1) the binder
#: terms of appendix A2 cancel.
DEFAULT_BINDER_DENSITY = 0.93
#: Drying coefficient ``q = m_dry / M_wet`` of every paint and of the binder unless given [1].
DEFAULT_DRYING = 1.0
#: Mass fractions given with ``normalise=False`` must sum to 1 within this (absolute); generous
#: for fractions typed with 6 significant digits (rounding error below 1e-6 per pigment).
FRACTION_SUM_TOLERANCE = 1e-5


def _pigment_list(names):
    return ", ".join(sorted(names))


def _check_name(name):
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"recipe: pigment names must be non-empty text, got {name!r}")
    if name != name.strip():
        raise ValueError(f"recipe: pigment name {name!r} has leading or trailing spaces")
    return name


def _check_amount(name, amount):
    if isinstance(amount, bool) or not isinstance(amount, numbers.Real):
        # one error type for every bad amount a user can give (the brief: ValueError)
        raise ValueError(f"recipe: the amount of {name!r} must be a number, got {amount!r}")  # noqa: TRY004
    value = float(amount)
    if math.isnan(value):
        raise ValueError(f"recipe: the amount of {name!r} is NaN; give a number >= 0")
    if math.isinf(value):
        raise ValueError(f"recipe: the amount of {name!r} must be finite, got {value!r}")
    if value < 0:
        raise ValueError(
            f"recipe: the amount of {name!r} is negative ({value:g}); amounts are >= 0"
        )
    return value


def _check_palette(names, palette):
    palette = list(palette)
    known = set(palette)
    for name in names:
        if name not in known:
            close = difflib.get_close_matches(name, palette, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ValueError(
                f"recipe: unknown pigment {name!r}{hint}; the palette has {_pigment_list(palette)}"
            )


def _fractions(mapping, *, normalise, palette):
    """Validated pigment -> mass fraction (zeros dropped, summing to 1), in the given order."""
    if not isinstance(mapping, Mapping):
        raise TypeError(
            f"recipe must be a mapping of pigment name -> amount, got {type(mapping).__name__}"
        )
    if not mapping:
        raise ValueError("recipe: no pigments given")
    amounts = {_check_name(name): _check_amount(name, amount) for name, amount in mapping.items()}
    if palette is not None:
        _check_palette(amounts, palette)
    total = math.fsum(amounts.values())
    if total == 0:
        raise ValueError("recipe: all amounts are zero; a film needs at least one pigment")
    if not normalise and abs(total - 1.0) > FRACTION_SUM_TOLERANCE:
        raise ValueError(
            f"recipe: the mass fractions sum to {total:.6g}, not 1; give fractions that sum "
            "to 1, or relative amounts with normalise=True"
        )
    return {name: value / total for name, value in amounts.items() if value > 0}


@dataclass(frozen=True)
class Recipe:
    """What a film is made of: the mass fraction of each paint in the mixture.

    Parameters
    ----------
    amounts : mapping
        Pigment (paint) name -> mass fraction [1], each > 0, summing to 1 (within
        :data:`FRACTION_SUM_TOLERANCE`). Stored read-only, zeros dropped, renormalised to sum
        to 1 exactly. Build from relative amounts with :meth:`from_mapping`.
    basis : {"mass"}
        What the fractions are fractions of: mass of the paints as mixed.

    Raises
    ------
    ValueError, TypeError
        For amounts that are not a mapping of names to fractions as above, naming the pigment.
    """

    amounts: Mapping
    basis: str = "mass"

    def __post_init__(self):
        if self.basis != "mass":
            raise ValueError(f"recipe: basis must be 'mass', got {self.basis!r}")
        fractions = _fractions(self.amounts, normalise=False, palette=None)
        object.__setattr__(self, "amounts", types.MappingProxyType(fractions))

    @classmethod
    def from_mapping(cls, mapping, *, normalise=True, palette=None):
        """A recipe from pigment -> amount.

        Parameters
        ----------
        mapping : mapping
            Pigment name -> amount >= 0 (mass; any unit, e.g. grams or per cent); zeros mean
            the pigment is absent.
        normalise : bool
            True (default): the amounts are relative and are divided by their sum. False: they
            are mass fractions and must sum to 1.
        palette : iterable of str, optional
            The pigments allowed (e.g. a library's); any other name is an error.

        Raises
        ------
        ValueError
            Naming the pigment: unknown (not in ``palette``), an amount that is negative, NaN,
            infinite or not a number; all amounts zero; fractions not summing to 1 with
            ``normalise=False``.
        TypeError
            When ``mapping`` is not a mapping.
        """
        return cls(_fractions(mapping, normalise=normalise, palette=palette))

    @classmethod
    def from_composition(cls, composition, *, palette=None):
        """A recipe from ``{"pigments": [...], "mass_ratios": [...]}`` (relative amounts).

        The form readers store in ``MeasurementSet.metadata["composition"]``
        (:func:`bayespig.data.read_revigo`, the ``recipe`` column of a bayespig CSV file).

        Raises
        ------
        ValueError
            When the keys are missing, the lists differ in length, a pigment appears twice, or
            an amount is bad (as :meth:`from_mapping`).
        """
        if not isinstance(composition, Mapping):
            raise ValueError(  # noqa: TRY004 -- metadata read from a file: a bad recipe
                "recipe: a composition must be a mapping with 'pigments' and 'mass_ratios', got "
                f"{type(composition).__name__}"
            )
        missing = [key for key in ("pigments", "mass_ratios") if key not in composition]
        if missing:
            raise ValueError(
                f"recipe: the composition lacks {' and '.join(map(repr, missing))} (it needs "
                "'pigments' and 'mass_ratios')"
            )
        pigments, ratios = composition["pigments"], composition["mass_ratios"]
        for key, value in (("pigments", pigments), ("mass_ratios", ratios)):
            if isinstance(value, str) or not isinstance(value, Sequence):
                raise ValueError(f"recipe: the composition's {key!r} must be a list")  # noqa: TRY004
        if len(pigments) != len(ratios):
            raise ValueError(
                f"recipe: the composition has {len(pigments)} pigments but {len(ratios)} "
                "mass_ratios"
            )
        mapping = {}
        for name, ratio in zip(pigments, ratios):
            if name in mapping:
                raise ValueError(f"recipe: pigment {name!r} appears twice in the composition")
            mapping[_check_name(name)] = ratio
        return cls.from_mapping(mapping, normalise=True, palette=palette)

    @property
    def pigments(self):
        """The pigments present (amount > 0), in the recipe's order."""
        return tuple(self.amounts)

    def to_composition(self):
        """``{"pigments": [...], "mass_ratios": [...]}``: the metadata form (fractions)."""
        return {"pigments": list(self.amounts), "mass_ratios": list(self.amounts.values())}

    def __hash__(self):
        return hash((tuple(self.amounts.items()), self.basis))

    def __eq__(self, other):
        if not isinstance(other, Recipe):
            return NotImplemented
        return dict(self.amounts) == dict(other.amounts) and self.basis == other.basis

    def __repr__(self):
        inside = ", ".join(f"{k!r}: {v:.6g}" for k, v in self.amounts.items())
        return f"Recipe({{{inside}}})"


def base_pigment(name, table=DEFAULT_DENSITIES):
    """The name ``name`` is a variant of: itself if in ``table``, else its longest CamelCase prefix.

    ``ZincWhiteLinseed`` -> ``ZincWhite``; ``Eosin2PbWax`` -> ``Eosin``; None when no name of
    ``table`` is a prefix of ``name`` followed by an upper-case letter or a digit.
    """
    if name in table:
        return name
    best = None
    for key in table:
        if len(name) > len(key) and name.startswith(key):
            following = name[len(key)]
            if (following.isupper() or following.isdigit()) and (
                best is None or len(key) > len(best)
            ):
                best = key
    return best


def _value_table(values, what):
    if values is None:
        return {}
    if not isinstance(values, Mapping):
        raise TypeError(
            f"{what} must be a mapping of pigment name -> value, got {type(values).__name__}"
        )
    out = {}
    for name, value in values.items():
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ValueError(f"{what}: the value of {name!r} must be a number, got {value!r}")  # noqa: TRY004
        value = float(value)
        if not math.isfinite(value) or value <= 0:
            raise ValueError(
                f"{what}: the value of {name!r} must be a finite number > 0, got {value!r}"
            )
        out[name] = value
    return out


def density_of(name, densities=None):
    """Dry density of pigment (paint) ``name`` [g/cm^3] by the module's lookup rule.

    Parameters
    ----------
    name : str
    densities : mapping, optional
        User values pigment -> density [g/cm^3], searched before :data:`DEFAULT_DENSITIES`
        (exact name, then base pigment, in each).
    """
    user = _value_table(densities, "densities")
    for table in (user, DEFAULT_DENSITIES):
        base = base_pigment(name, table)
        if base is not None:
            return table[base]
    return UNKNOWN_PIGMENT_DENSITY


def paste_density(pigment_density, pigment_mass_fraction, binder_density=DEFAULT_BINDER_DENSITY):
    """Dry density of a pigment paste from its pigment's density and pigment content [g/cm^3].

    Volumes add: ``1 / rho_paste = c / rho_pigment + (1 - c) / rho_binder``.

    Parameters
    ----------
    pigment_density : float
        [g/cm^3], > 0.
    pigment_mass_fraction : float
        ``c``, mass fraction of pigment in the dry paste [1], in (0, 1].
    binder_density : float
        [g/cm^3], > 0 (default: linseed oil).
    """
    rho = _value_table({"pigment_density": pigment_density}, "pigment_density")["pigment_density"]
    rho_b = _value_table({"binder_density": binder_density}, "binder_density")["binder_density"]
    c = pigment_mass_fraction
    if isinstance(c, bool) or not isinstance(c, numbers.Real) or not 0 < float(c) <= 1:
        raise ValueError(f"pigment_mass_fraction must be a number in (0, 1], got {c!r}")
    return 1.0 / (float(c) / rho + (1.0 - float(c)) / rho_b)


def concentrations(recipe, pigments, *, densities=None, drying=None):
    """Concentrations ``D_i`` of a recipe's pigments in the dry film (appendix A2).

    Parameters
    ----------
    recipe : Recipe or mapping
        A mapping pigment -> relative amount is read with :meth:`Recipe.from_mapping`.
    pigments : sequence of str
        The pigments to return concentrations for, in this order (e.g. a library's palette);
        every pigment of the recipe must be among them.
    densities : mapping, optional
        Pigment -> dry density of its paint [g/cm^3], > 0, overriding :data:`DEFAULT_DENSITIES`
        (also for the variants of that name, see the module docstring).
    drying : mapping, optional
        Pigment -> drying coefficient ``q = m_dry / M_wet`` [1], > 0 (default
        :data:`DEFAULT_DRYING` = 1 for every paint).

    Returns
    -------
    numpy.ndarray, shape (len(pigments),)
        ``D_i`` [g/cm^3 with ``C_pp / mu = 1``: mass of paint ``i`` per dry volume]; 0 for the
        pigments not in the recipe. Only ratios between films carry meaning: a constant factor
        per pigment is absorbed by its extinction (module docstring).

    Raises
    ------
    ValueError
        A recipe pigment not in ``pigments`` (named), ``pigments`` with duplicates, or bad
        ``densities``/``drying`` values (named).
    TypeError
        When ``recipe`` is neither a Recipe nor a mapping.
    """
    if isinstance(pigments, str) or not isinstance(pigments, Sequence | np.ndarray):
        raise TypeError(f"pigments must be a sequence of pigment names, got {pigments!r}")
    pigments = [str(p) for p in pigments]
    if len(set(pigments)) != len(pigments):
        twice = sorted({p for p in pigments if pigments.count(p) > 1})
        raise ValueError(f"pigments: {', '.join(map(repr, twice))} appear more than once")
    if not isinstance(recipe, Recipe):
        recipe = Recipe.from_mapping(recipe, palette=pigments)
    else:
        _check_palette(recipe.pigments, pigments)
    user_densities = _value_table(densities, "densities")
    user_drying = _value_table(drying, "drying")
    names = recipe.pigments
    fractions = np.array([recipe.amounts[p] for p in names])
    rho = np.array([density_of(p, user_densities) for p in names])
    q = np.array([user_drying.get(p, DEFAULT_DRYING) for p in names])
    # The fractions sum to 1 up to rounding; A2's check allows 1e-9.
    d = concentrations_from_mass_fractions(
        fractions / max(1.0, math.fsum(fractions)),
        paste_density=rho,
        paste_drying=q,
        binder_density=DEFAULT_BINDER_DENSITY,
        binder_drying=DEFAULT_DRYING,
    )
    out = np.zeros(len(pigments))
    index = {p: i for i, p in enumerate(pigments)}
    for name, value in zip(names, d):
        out[index[name]] = value
    return out


def split_film_groups(measurements):
    """One measurement set per film group, each with its recipe as ``metadata["composition"]``.

    A bayespig CSV file may hold several films (film groups) with recipes of their own
    (``metadata["compositions"]``, film group -> composition); a film of the library is one
    set whose films share one film group. Each set keeps the substrate samples its films
    refer to and the other metadata.

    Parameters
    ----------
    measurements : MeasurementSet

    Returns
    -------
    dict
        Film group -> MeasurementSet, in the order of the groups; a group without a recipe
        has no ``composition``.
    """
    from_groups = measurements.metadata.get("compositions")
    shared = measurements.metadata.get("composition")
    out = {}
    for group, films in measurements.film_groups.items():
        part = measurements.select([f.name for f in films])
        metadata = {
            k: v for k, v in part.metadata.items() if k not in ("composition", "compositions")
        }
        composition = from_groups.get(group) if isinstance(from_groups, Mapping) else shared
        if composition is not None:
            metadata["composition"] = composition
        out[group] = type(part)(
            part.wavelength_nm, part.samples, n=part.n, metadata=metadata, source=part.source
        )
    return out


def film_recipes(sets):
    """The recipe of each film from its ``metadata["composition"]``.

    Parameters
    ----------
    sets : mapping
        Film id -> :class:`~bayespig.data.MeasurementSet` (e.g. from
        :func:`bayespig.data.read_revigo`, or a bayespig CSV file with a ``recipe`` column).

    Returns
    -------
    dict
        Film id -> :class:`Recipe`, in the order of ``sets``.

    Raises
    ------
    ValueError
        Naming the film: no composition, a set holding several film groups with recipes of
        their own (``metadata["compositions"]``: split it with :func:`split_film_groups`), or
        a bad composition.
    TypeError
        When ``sets`` is not a mapping.
    """
    if not isinstance(sets, Mapping):
        raise TypeError(
            f"sets must be a mapping of film id -> MeasurementSet, got {type(sets).__name__}"
        )
    recipes = {}
    for film_id, measurements in sets.items():
        metadata = getattr(measurements, "metadata", None)
        if not isinstance(metadata, Mapping):
            raise TypeError(
                f"film {film_id!r}: expected a MeasurementSet, got {type(measurements).__name__}"
            )
        if "composition" not in metadata:
            if "compositions" in metadata:
                groups = ", ".join(map(repr, metadata["compositions"]))
                raise ValueError(
                    f"film {film_id!r} has one recipe per film group ({groups}), not one for the "
                    "whole set; split it with split_film_groups"
                )
            raise ValueError(
                f"film {film_id!r} has no recipe (no 'composition' in its metadata): read the "
                "Revigo folder with its mixture-specifications file, or give the film's recipe "
                "in the 'recipe' column of its CSV file"
            )
        try:
            recipes[film_id] = Recipe.from_composition(metadata["composition"])
        except (TypeError, ValueError) as error:
            raise ValueError(f"film {film_id!r}: {error}") from None
    return recipes
