"""A film's recipe in a bayespig CSV file (the ``recipe`` column) and in the Revigo specifications."""

import textwrap

import pytest

from bayespig.data import MeasurementError, read_csv, read_revigo

from .test_csv_format import problem_at, replace_line, write

HEADER = "sample,role,substrate,film_group,recipe,measurement,geometry,400,500,600"
RECIPE_FILE = textwrap.dedent(f"""\
    # units: fraction
    {HEADER}
    on_black,film,black,A,ZincWhite:90;BoneBlack:10,brdf,45as15,0.010,0.012,0.013
    on_black,film,black,A,,brdf,45as45,0.011,0.013,0.014
    on_white,film,white,A, ZincWhite : 9 ; BoneBlack:1 ,brdf,45as15,0.050,0.060,0.070
    """)
SYNTAX = (
    "write pigment:amount pairs separated by ';', e.g. 'ZincWhite:90;BoneBlack:10' "
    "(relative masses)"
)


def test_recipe_column_becomes_the_composition(tmp_path):
    ms = read_csv(write(tmp_path, RECIPE_FILE))
    # the first recipe as written; '9;1' on the other film of the group is the same recipe
    assert ms.metadata["composition"] == {
        "pigments": ["ZincWhite", "BoneBlack"],
        "mass_ratios": [90.0, 10.0],
    }
    assert "compositions" not in ms.metadata


def test_recipe_column_round_trip(tmp_path):
    ms = read_csv(write(tmp_path, RECIPE_FILE))
    out = tmp_path / "out.csv"
    ms.to_csv(out)
    text = out.read_text()
    assert "opaque,recipe,measurement" in text.splitlines()[3]
    assert text.count(",ZincWhite:90;BoneBlack:10,") == 3 and "# composition" not in text
    back = read_csv(out)
    assert back == ms and dict(back.metadata) == dict(ms.metadata)


def test_films_of_different_groups_with_different_recipes(tmp_path):
    text = (
        RECIPE_FILE + "tint,film,white,B,ZincWhite:50;PrussianBlue:50,brdf,45as15,0.05,0.06,0.07\n"
    )
    ms = read_csv(write(tmp_path, text))
    assert "composition" not in ms.metadata
    assert ms.metadata["compositions"] == {
        "A": {"pigments": ["ZincWhite", "BoneBlack"], "mass_ratios": [90.0, 10.0]},
        "B": {"pigments": ["ZincWhite", "PrussianBlue"], "mass_ratios": [50.0, 50.0]},
    }
    out = tmp_path / "out.csv"
    ms.to_csv(out)
    assert ",ZincWhite:50;PrussianBlue:50," in out.read_text()
    assert read_csv(out) == ms


def test_a_revigo_film_round_trips_through_csv_with_its_recipe(tmp_path):
    table = tmp_path / "x-spectral-data.txt"
    table.write_text("Name\t400\t500\nP_b\t5\t5\nP_w\t80\t85\nP_ob\t20\t30\nP_ow\t40\t50\n")
    (tmp_path / "x-mixture-specifications.txt").write_text(
        "P\tVermillion-ZincWhite-BoneBlack|9.7-90.3-0\n"
    )
    ms = read_revigo(tmp_path)["P"]
    out = tmp_path / "P.csv"
    ms.to_csv(out)
    assert ",Vermillion:9.7;ZincWhite:90.3;BoneBlack:0," in out.read_text()
    back = read_csv(out)
    assert back == ms and back.metadata["composition"] == ms.metadata["composition"]


def test_semicolon_separated_file_with_a_quoted_recipe(tmp_path):
    text = RECIPE_FILE.replace(",", ";").replace(
        "A;ZincWhite:90;BoneBlack:10;", 'A;"ZincWhite:90;BoneBlack:10";'
    )
    text = text.replace("A; ZincWhite : 9 ; BoneBlack:1 ;", "A;;")
    ms = read_csv(write(tmp_path, text))
    assert ms.metadata["composition"]["pigments"] == ["ZincWhite", "BoneBlack"]


def test_a_composition_the_column_cannot_hold_stays_metadata(tmp_path):
    text = (
        '# composition: {"pigments": ["Zinc;White"], "mass_ratios": [1]}\n'
        + RECIPE_FILE.replace(",recipe", "")
        .replace(",ZincWhite:90;BoneBlack:10", "")
        .replace(", ZincWhite : 9 ; BoneBlack:1 ", "")
        .replace("A,,", "A,")
    )
    ms = read_csv(write(tmp_path, text))
    out = tmp_path / "out.csv"
    ms.to_csv(out)
    assert "recipe" not in out.read_text().splitlines()[-4]
    assert read_csv(out) == ms


ROW = 3  # the first data row of RECIPE_FILE


@pytest.mark.parametrize(
    "cell, message",
    [
        (
            "ZincWhite=90",
            f"cannot read recipe 'ZincWhite=90': 'ZincWhite=90' is not pigment:amount; {SYNTAX}",
        ),
        (
            "ZincWhite 90;BoneBlack:10",
            (
                "cannot read recipe 'ZincWhite 90;BoneBlack:10': 'ZincWhite 90' is not "
                f"pigment:amount; {SYNTAX}"
            ),
        ),
        (":90", f"cannot read recipe ':90': ':90' is not pigment:amount; {SYNTAX}"),
        (
            "ZincWhite:lots",
            "recipe 'ZincWhite:lots': the amount of 'ZincWhite': 'lots' is not a number",
        ),
        (
            "ZincWhite:90;BoneBlack:-10",
            (
                "recipe 'ZincWhite:90;BoneBlack:-10': the amount of 'BoneBlack' is negative (-10); "
                "amounts are >= 0"
            ),
        ),
        (
            "ZincWhite:nan",
            "recipe 'ZincWhite:nan': the amount of 'ZincWhite' is NaN; give a number >= 0",
        ),
        (
            "ZincWhite:inf",
            "recipe 'ZincWhite:inf': the amount of 'ZincWhite' must be finite, got inf",
        ),
        (
            "ZincWhite:90;ZincWhite:10",
            "recipe 'ZincWhite:90;ZincWhite:10': pigment 'ZincWhite' is given twice",
        ),
        (
            "ZincWhite:0;BoneBlack:0",
            (
                "recipe 'ZincWhite:0;BoneBlack:0': all amounts are zero; a film needs at least one "
                "pigment"
            ),
        ),
    ],
)
def test_bad_recipe_cells_name_file_row_and_field(tmp_path, cell, message):
    line = RECIPE_FILE.splitlines()[ROW - 1].replace("ZincWhite:90;BoneBlack:10", cell)
    error = problem_at(tmp_path, replace_line(RECIPE_FILE, ROW, line), ROW, "recipe", message)
    found = [p for p in error.problems if p.field == "recipe"]
    assert [p.message for p in found] == [message]


def test_two_recipes_in_one_film_group(tmp_path):
    text = RECIPE_FILE.replace(" ZincWhite : 9 ; BoneBlack:1 ", "ZincWhite:50;BoneBlack:50")
    error = problem_at(
        tmp_path,
        text,
        5,
        "recipe",
        "film group 'A' has recipe 'ZincWhite:50;BoneBlack:50' here but "
        "'ZincWhite:90;BoneBlack:10' in row 3; the films of one film group are one paint: give "
        "them one recipe",
    )
    assert len(error.problems) == 1


def test_a_substrate_has_no_recipe(tmp_path):
    text = RECIPE_FILE + "card,substrate,,,ZincWhite:1,hemispherical,8d-sce,0.9,0.9,0.9\n"
    problem_at(
        tmp_path,
        text,
        6,
        "recipe",
        "sample 'card' is a substrate; only films have a recipe (leave the cell blank)",
    )


def test_recipe_column_and_composition_line_together(tmp_path):
    text = '# composition: {"pigments": ["ZincWhite"], "mass_ratios": [1]}\n' + RECIPE_FILE
    problem_at(
        tmp_path,
        text,
        4,
        "recipe",
        "the file gives recipes both in the 'recipe' column and as '# composition:' metadata; "
        "keep one of them",
    )


def test_nothing_is_read_from_a_file_with_a_bad_recipe(tmp_path):
    text = RECIPE_FILE.replace("BoneBlack:10", "BoneBlack:-10")
    with pytest.raises(MeasurementError):
        read_csv(write(tmp_path, text))


# ------------------------------------------------------- Revigo specification file
def revigo_folder(tmp_path, specifications):
    (tmp_path / "x-spectral-data.txt").write_text(
        "Name\t400\t500\nP_b\t5\t5\nP_w\t80\t85\nP_ob\t20\t30\nP_ow\t40\t50\n"
    )
    spec = tmp_path / "x-mixture-specifications.txt"
    spec.write_text(specifications)
    return spec


SPEC_SYNTAX = "expected '<id><TAB><pigment>-<pigment>|<ratio>-<ratio>'"


@pytest.mark.parametrize(
    "line, field, message",
    [
        ("Q ZincWhite|100", "id", f"cannot read composition 'Q ZincWhite|100': {SPEC_SYNTAX}"),
        (
            "Q\tZincWhite 100",
            "ratios",
            f"cannot read composition 'Q\\tZincWhite 100': {SPEC_SYNTAX}",
        ),
        ("Q\tZincWhite-|100-0", "pigments", f"empty pigment name in 'ZincWhite-': {SPEC_SYNTAX}"),
        ("Q\tZincWhite|ten", "ratios", "'ten' is not a number"),
        (
            "Q\tZincWhite-BoneBlack|90-inf",
            "ratios",
            "mass ratio inf in '90-inf' is not a finite number",
        ),
        (
            "Q\tZincWhite-BoneBlack|100",
            "ratios",
            f"2 pigments but 1 ratios in 'Q\\tZincWhite-BoneBlack|100': {SPEC_SYNTAX}",
        ),
        (
            "Q\tZincWhite|0",
            "ratios",
            "all mass ratios of 'Q' are zero; a film needs at least one pigment",
        ),
        ("P\tZincWhite|100", "id", "film 'P' is already given in row 1"),
    ],
)
def test_bad_specification_lines_name_file_row_and_field(tmp_path, line, field, message):
    spec = revigo_folder(tmp_path, f"P\tPrussianBlue|100\n{line}\n")
    with pytest.raises(MeasurementError) as info:
        read_revigo(tmp_path)
    assert str(info.value) == f"{spec}, row 2, field {field!r}: {message}"


def test_a_final_semicolon_and_spaces_are_accepted(tmp_path):
    text = RECIPE_FILE.replace("ZincWhite:90;BoneBlack:10,", " ZincWhite: 90 ;BoneBlack :10; ,")
    ms = read_csv(write(tmp_path, text))
    assert ms.metadata["composition"] == {
        "pigments": ["ZincWhite", "BoneBlack"],
        "mass_ratios": [90.0, 10.0],
    }
