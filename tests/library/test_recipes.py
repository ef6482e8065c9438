"""Recipes as data: validation, handbook densities, appendix A2 concentrations, film recipes."""

import doctest
import math
import os
from pathlib import Path

import numpy as np
import pytest

from bayespig.data import MeasurementError, read_csv, read_revigo
from bayespig.library import recipes
from bayespig.library.recipes import (
    DEFAULT_DENSITIES,
    DENSITY_SOURCES,
    UNKNOWN_PIGMENT_DENSITY,
    Recipe,
    base_pigment,
    concentrations,
    density_of,
    film_recipes,
    paste_density,
    split_film_groups,
)

REVIGO = Path(
    os.environ.get(
        "BAYESPIG_REVIGO", Path(__file__).resolve().parents[3] / "shared" / "data" / "revigo"
    )
)
REVIGO_SPECIFICATIONS = REVIGO / "revigo-mixture-specifications.txt"
needs_revigo = pytest.mark.skipif(
    not REVIGO_SPECIFICATIONS.exists(), reason=f"Revigo data not found at {REVIGO}"
)

#: Hand arithmetic and A2 agree to floating-point rounding (a few ulp of numbers ~1).
A2_REL_TOL = 1e-12
#: Handbook densities are quoted to 0.01-0.1 g/cm^3 and differ between handbooks by about
#: that (ZnO: 5.61 CRC, 5.65 Gettens & Stout); allow 0.1 g/cm^3.
HANDBOOK_TOL = 0.1

#: Every pigment name of the Revigo specification file (the brief's list), for when the
#: file is absent.
REVIGO_PIGMENTS = [
    "BariumSulphate",
    "BoneBlack",
    "CalciumCarbonate",
    "ChromeYellow",
    "ChromeYellowOtero",
    "ChromeYellowPoppyseed",
    "CobaltBlue",
    "Cochineal",
    "EmeraldGreen",
    "Eosin",
    "Eosin1Wax",
    "Eosin2PbWax",
    "LeadWhite",
    "Minium",
    "PrussianBlue",
    "UltramarineBlue",
    "Vermillion",
    "ViridianGreen",
    "ZincWhite",
    "ZincWhiteLinseed",
]


def message_of(error_type, call, *args, **kwargs):
    with pytest.raises(error_type) as info:
        call(*args, **kwargs)
    return str(info.value)


# ------------------------------------------------------------------------------ Recipe
def test_relative_amounts_become_mass_fractions_without_zeros():
    recipe = Recipe.from_mapping({"Vermillion": 10, "ZincWhite": 90, "BoneBlack": 0})
    assert dict(recipe.amounts) == {"Vermillion": 0.1, "ZincWhite": 0.9}
    assert recipe.pigments == ("Vermillion", "ZincWhite") and recipe.basis == "mass"
    assert recipe == Recipe.from_mapping({"ZincWhite": 0.9, "Vermillion": 0.1}, normalise=False)
    assert hash(recipe) == hash(Recipe({"Vermillion": 0.1, "ZincWhite": 0.9}))
    with pytest.raises(TypeError):
        recipe.amounts["ZincWhite"] = 1.0  # read-only


@pytest.mark.parametrize(
    "mapping, kwargs, message",
    [
        (
            {"ZincWite": 90, "BoneBlack": 10},
            {"palette": ["ZincWhite", "BoneBlack"]},
            (
                "recipe: unknown pigment 'ZincWite' (did you mean 'ZincWhite'?); the palette has "
                "BoneBlack, ZincWhite"
            ),
        ),
        (
            {"Ochre": 1},
            {"palette": ["ZincWhite", "BoneBlack"]},
            "recipe: unknown pigment 'Ochre'; the palette has BoneBlack, ZincWhite",
        ),
        (
            {"ZincWhite": 90, "BoneBlack": -10},
            {},
            "recipe: the amount of 'BoneBlack' is negative (-10); amounts are >= 0",
        ),
        (
            {"ZincWhite": 90, "BoneBlack": math.nan},
            {},
            "recipe: the amount of 'BoneBlack' is NaN; give a number >= 0",
        ),
        (
            {"ZincWhite": math.inf},
            {},
            "recipe: the amount of 'ZincWhite' must be finite, got inf",
        ),
        (
            {"ZincWhite": "ninety"},
            {},
            "recipe: the amount of 'ZincWhite' must be a number, got 'ninety'",
        ),
        ({"ZincWhite": None}, {}, "recipe: the amount of 'ZincWhite' must be a number, got None"),
        ({"ZincWhite": True}, {}, "recipe: the amount of 'ZincWhite' must be a number, got True"),
        (
            {"ZincWhite": 0, "BoneBlack": 0.0},
            {},
            "recipe: all amounts are zero; a film needs at least one pigment",
        ),
        ({}, {}, "recipe: no pigments given"),
        ({3: 1.0}, {}, "recipe: pigment names must be non-empty text, got 3"),
        (
            {" ZincWhite": 1.0},
            {},
            "recipe: pigment name ' ZincWhite' has leading or trailing spaces",
        ),
        (
            {"ZincWhite": 0.9, "BoneBlack": 0.05},
            {"normalise": False},
            (
                "recipe: the mass fractions sum to 0.95, not 1; give fractions that sum to 1, or "
                "relative amounts with normalise=True"
            ),
        ),
        (
            {"ZincWhite": 90, "BoneBlack": 10},
            {"normalise": False},
            (
                "recipe: the mass fractions sum to 100, not 1; give fractions that sum to 1, or "
                "relative amounts with normalise=True"
            ),
        ),
    ],
)
def test_bad_recipes_are_rejected_naming_the_pigment(mapping, kwargs, message):
    assert message_of(ValueError, Recipe.from_mapping, mapping, **kwargs) == message


def test_recipe_that_is_not_a_mapping():
    assert (
        message_of(TypeError, Recipe.from_mapping, [("ZincWhite", 1.0)])
        == "recipe must be a mapping of pigment name -> amount, got list"
    )


def test_fractions_summing_to_one_within_the_tolerance_are_accepted():
    recipe = Recipe.from_mapping({"A": 0.333333, "B": 0.666667}, normalise=False)
    assert math.isclose(sum(recipe.amounts.values()), 1.0, rel_tol=1e-15)
    assert "sum to 0.99" in message_of(ValueError, Recipe, {"A": 0.5, "B": 0.49})


def test_from_composition_reads_the_readers_form():
    composition = {"pigments": ["Vermillion", "ZincWhite", "BoneBlack"], "mass_ratios": [10, 90, 0]}
    assert Recipe.from_composition(composition) == Recipe({"Vermillion": 0.1, "ZincWhite": 0.9})
    assert Recipe.from_composition(composition).to_composition() == {
        "pigments": ["Vermillion", "ZincWhite"],
        "mass_ratios": [0.1, 0.9],
    }
    cases = [
        (
            {"pigments": ["A"]},
            "recipe: the composition lacks 'mass_ratios' (it needs 'pigments' and 'mass_ratios')",
        ),
        (
            {"pigments": ["A", "B"], "mass_ratios": [1]},
            "recipe: the composition has 2 pigments but 1 mass_ratios",
        ),
        (
            {"pigments": ["A", "A"], "mass_ratios": [1, 2]},
            "recipe: pigment 'A' appears twice in the composition",
        ),
        (
            {"pigments": "AB", "mass_ratios": [1, 2]},
            "recipe: the composition's 'pigments' must be a list",
        ),
        (
            {"pigments": ["A"], "mass_ratios": [-1]},
            "recipe: the amount of 'A' is negative (-1); amounts are >= 0",
        ),
        (
            "A:1",
            "recipe: a composition must be a mapping with 'pigments' and 'mass_ratios', got str",
        ),
    ]
    for composition, message in cases:
        assert message_of(ValueError, Recipe.from_composition, composition) == message
    assert "unknown pigment 'A'" in message_of(
        ValueError, Recipe.from_composition, {"pigments": ["A"], "mass_ratios": [1]}, palette=["B"]
    )


# -------------------------------------------------------------------------- densities
def test_default_densities_are_the_handbook_values_with_a_source_each():
    # CRC Handbook of Chemistry and Physics: ZnO 5.61, HgS (cinnabar) 8.1, PbCrO4 6.12,
    # BaSO4 4.49, CaCO3 (calcite) 2.71, Pb3O4 8.9 (Gettens & Stout's red lead: 8.73).
    crc = {
        "ZincWhite": 5.61,
        "Vermillion": 8.1,
        "ChromeYellow": 6.12,
        "BariumSulphate": 4.49,
        "CalciumCarbonate": 2.71,
    }
    for name, value in crc.items():
        assert abs(DEFAULT_DENSITIES[name] - value) <= HANDBOOK_TOL, name
    assert abs(DEFAULT_DENSITIES["Minium"] - 8.73) <= HANDBOOK_TOL
    assert set(DENSITY_SOURCES) == set(DEFAULT_DENSITIES)
    assert all(len(source) > 20 for source in DENSITY_SOURCES.values())
    assert recipes.DEFAULT_BINDER_DENSITY == 0.93 and recipes.DEFAULT_DRYING == 1.0


def revigo_pigment_names():
    if not REVIGO_SPECIFICATIONS.exists():
        return REVIGO_PIGMENTS
    names = set()
    for line in REVIGO_SPECIFICATIONS.read_text().splitlines():
        if line.strip():
            names.update(line.split("\t")[1].split("|")[0].split("-"))
    return sorted(names)


def test_every_revigo_pigment_has_a_handbook_density_by_the_variant_rule():
    names = revigo_pigment_names()
    assert set(REVIGO_PIGMENTS) <= set(names)
    for name in names:
        assert base_pigment(name) is not None, name
    assert base_pigment("ZincWhiteLinseed") == "ZincWhite"
    assert base_pigment("ChromeYellowPoppyseed") == "ChromeYellow"
    assert base_pigment("ChromeYellowOtero") == "ChromeYellow"
    assert base_pigment("Eosin1Wax") == "Eosin" and base_pigment("Eosin2PbWax") == "Eosin"
    assert base_pigment("Eosinx") is None  # lower case: another word, not a variant
    assert density_of("ZincWhiteLinseed") == DEFAULT_DENSITIES["ZincWhite"]
    # a user value overrides the table, for the name's variants too
    assert density_of("ZincWhiteLinseed", {"ZincWhite": 4.0}) == 4.0
    assert density_of("ZincWhite", {"ZincWhiteLinseed": 4.0}) == DEFAULT_DENSITIES["ZincWhite"]


def test_unknown_pigments_get_the_median_density_without_a_warning():
    assert UNKNOWN_PIGMENT_DENSITY == float(np.median(list(DEFAULT_DENSITIES.values())))
    assert density_of("Smalt") == UNKNOWN_PIGMENT_DENSITY
    # a recipe of unknown pigments only: D proportional to W (equal densities)
    d = concentrations({"Smalt": 1, "Ochre": 3}, ["Smalt", "Ochre"])
    assert math.isclose(d[1] / d[0], 3.0, rel_tol=A2_REL_TOL)


def test_paste_density_adds_volumes():
    # 80 % zinc white (5.65) in linseed oil (0.93) by mass: 1 / (0.8 / 5.65 + 0.2 / 0.93)
    expected = 1.0 / (0.8 / 5.65 + 0.2 / 0.93)
    assert math.isclose(paste_density(5.65, 0.8), expected, rel_tol=A2_REL_TOL)
    assert paste_density(5.65, 1.0) == 5.65
    assert (
        message_of(ValueError, paste_density, 5.65, 0.0)
        == "pigment_mass_fraction must be a number in (0, 1], got 0.0"
    )


# ---------------------------------------------------------------- A2 concentrations
def test_concentrations_follow_appendix_a2_by_hand():
    # Paper A2 with C_pp / mu = 1 and no added binder (sum W = 1: the binder terms cancel):
    # D_i = q_i W_i / sum_j (q_j W_j / rho_j).  W = 0.3, 0.6, 0.1; q = 0.9, 0.8, 1;
    # rho = 5, 2, 2.5:  sum = 0.9*0.3/5 + 0.8*0.6/2 + 1*0.1/2.5 = 0.054 + 0.24 + 0.04 = 0.334.
    recipe = Recipe.from_mapping({"ZincWhite": 3, "PrussianBlue": 6, "BoneBlack": 1})
    pigments = ["LeadWhite", "BoneBlack", "ZincWhite", "PrussianBlue"]
    d = concentrations(
        recipe,
        pigments,
        densities={"ZincWhite": 5.0, "PrussianBlue": 2.0, "BoneBlack": 2.5},
        drying={"ZincWhite": 0.9, "PrussianBlue": 0.8},
    )
    expected = np.array([0.0, 0.1, 0.27, 0.48]) / 0.334
    assert d.shape == (4,) and d[0] == 0.0
    np.testing.assert_allclose(d, expected, rtol=A2_REL_TOL)


def test_default_concentrations_use_the_handbook_densities():
    # 50/50 zinc white (5.65) / Prussian blue (1.83), each against its masstone (D = rho):
    # Prussian blue 0.5 / (0.5/1.83 + 0.5/5.65) / 1.83 = 1 / (1 + 1.83/5.65) = 0.7554;
    # zinc white 1 / (1 + 5.65/1.83) = 0.2446. With equal densities both are 0.5.
    pigments = ["PrussianBlue", "ZincWhite"]
    tint = concentrations({"PrussianBlue": 50, "ZincWhite": 50}, pigments)
    blue = concentrations({"PrussianBlue": 1}, pigments)
    white = concentrations({"ZincWhite": 1}, pigments)
    assert math.isclose(tint[0] / blue[0], 1 / (1 + 1.83 / 5.65), rel_tol=A2_REL_TOL)
    assert math.isclose(tint[1] / white[1], 1 / (1 + 5.65 / 1.83), rel_tol=A2_REL_TOL)
    equal = {"PrussianBlue": 1.0, "ZincWhite": 1.0}
    tint_eq = concentrations({"PrussianBlue": 50, "ZincWhite": 50}, pigments, densities=equal)
    blue_eq = concentrations({"PrussianBlue": 1}, pigments, densities=equal)
    assert math.isclose(tint_eq[0] / blue_eq[0], 0.5, rel_tol=A2_REL_TOL)
    # the docstring's example (the numbers the module documents) runs as written
    result = doctest.testmod(recipes, report=False)
    assert result.attempted >= 5 and result.failed == 0


@pytest.mark.parametrize(
    "kwargs, error, message",
    [
        (
            {"pigments": ["ZincWhite"]},
            ValueError,
            "recipe: unknown pigment 'BoneBlack'; the palette has ZincWhite",
        ),
        (
            {"pigments": ["ZincWhite", "BoneBlack", "ZincWhite"]},
            ValueError,
            "pigments: 'ZincWhite' appear more than once",
        ),
        (
            {"pigments": "ZincWhite"},
            TypeError,
            "pigments must be a sequence of pigment names, got 'ZincWhite'",
        ),
        (
            {"pigments": ["ZincWhite", "BoneBlack"], "densities": {"ZincWhite": -1}},
            ValueError,
            "densities: the value of 'ZincWhite' must be a finite number > 0, got -1.0",
        ),
        (
            {"pigments": ["ZincWhite", "BoneBlack"], "drying": {"BoneBlack": "high"}},
            ValueError,
            "drying: the value of 'BoneBlack' must be a number, got 'high'",
        ),
        (
            {"pigments": ["ZincWhite", "BoneBlack"], "densities": [5.6]},
            TypeError,
            "densities must be a mapping of pigment name -> value, got list",
        ),
    ],
)
def test_concentrations_reject_bad_arguments_naming_them(kwargs, error, message):
    recipe = Recipe.from_mapping({"ZincWhite": 90, "BoneBlack": 10})
    assert message_of(error, concentrations, recipe, **kwargs) == message


# ---------------------------------------------------------------------- film recipes
def small_revigo(tmp_path, specifications):
    table = tmp_path / "x-spectral-data.txt"
    rows = ["Name\t400\t500"]
    for film in ("P1", "P2"):
        rows += [f"{film}_b\t5\t5", f"{film}_w\t80\t85", f"{film}_ob\t20\t30", f"{film}_ow\t40\t50"]
    table.write_text("\n".join(rows) + "\n")
    spec = tmp_path / "x-mixture-specifications.txt"
    spec.write_text(specifications)
    return tmp_path, spec


def test_film_recipes_of_a_revigo_folder(tmp_path):
    folder, _ = small_revigo(
        tmp_path, "P1\tPrussianBlue-ZincWhite-BoneBlack|50.7-49.3-0\nP2\tZincWhiteLinseed|100\n"
    )
    found = film_recipes(read_revigo(folder))
    assert list(found) == ["P1", "P2"]
    assert found["P1"] == Recipe.from_mapping({"PrussianBlue": 50.7, "ZincWhite": 49.3})
    assert found["P2"] == Recipe({"ZincWhiteLinseed": 1.0})
    sets = read_revigo(folder)
    assert split_film_groups(sets["P1"]) == {"P1": sets["P1"]}  # one film: itself, cards kept


def test_film_recipes_name_the_film_when_missing_or_bad(tmp_path):
    folder, _spec = small_revigo(tmp_path, "P1\tPrussianBlue|100\n")
    sets = read_revigo(folder)
    assert message_of(ValueError, film_recipes, sets) == (
        "film 'P2' has no recipe (no 'composition' in its metadata): read the Revigo folder "
        "with its mixture-specifications file, or give the film's recipe in the 'recipe' "
        "column of its CSV file"
    )
    path = tmp_path / "bad.csv"
    path.write_text(
        '# composition: {"pigments": ["ZincWhite"], "mass_ratios": [-1]}\n'
        "sample,role,substrate,measurement,geometry,400\nf,film,black,brdf,45as15,0.01\n"
    )
    assert message_of(ValueError, film_recipes, {"F": read_csv(path)}) == (
        "film 'F': recipe: the amount of 'ZincWhite' is negative (-1); amounts are >= 0"
    )
    path.write_text(
        "sample,role,substrate,film_group,recipe,measurement,geometry,400\n"
        "f,film,black,A,ZincWhite:1,brdf,45as15,0.01\n"
        "g,film,black,B,BoneBlack:1,brdf,45as15,0.01\n"
    )
    assert message_of(ValueError, film_recipes, {"F": read_csv(path)}) == (
        "film 'F' has one recipe per film group ('A', 'B'), not one for the whole set; split "
        "it with split_film_groups"
    )
    films = split_film_groups(read_csv(path))
    assert list(films) == ["A", "B"] and films["B"].sample_names == ("g",)
    assert film_recipes(films) == {"A": Recipe({"ZincWhite": 1.0}), "B": Recipe({"BoneBlack": 1.0})}
    assert (
        message_of(TypeError, film_recipes, [sets["P1"]])
        == "sets must be a mapping of film id -> MeasurementSet, got list"
    )


def test_a_bad_specification_line_names_file_row_and_field(tmp_path):
    folder, spec = small_revigo(tmp_path, "P1\tPrussianBlue|100\nP2\tZincWhite-BoneBlack|90-nan\n")
    with pytest.raises(MeasurementError) as info:
        read_revigo(folder)
    assert str(info.value) == (
        f"{spec}, row 2, field 'ratios': mass ratio nan in '90-nan' is not a finite number"
    )


@needs_revigo
def test_every_revigo_film_has_a_recipe():
    sets = read_revigo(REVIGO)
    found = film_recipes(sets)
    assert len(found) == len(sets) == 84
    assert found["06B"] == Recipe.from_mapping({"Vermillion": 10, "ZincWhite": 90})
    assert found["16D"] == Recipe.from_mapping({"BariumSulphate": 89.95, "Cochineal": 10.05})
    palette = sorted({p for r in found.values() for p in r.pigments})
    assert set(palette) <= set(REVIGO_PIGMENTS)
    for recipe in found.values():
        d = concentrations(recipe, palette)
        assert np.isfinite(d).all() and (d[[palette.index(p) for p in recipe.pigments]] > 0).all()
