"""Wide spectral tables; the 84 Revigo films over black and white with their cards."""

import csv
import os
from pathlib import Path

import numpy as np
import pytest

from bayespig.data import (
    MeasurementError,
    check_report,
    read_measurements,
    read_revigo,
    read_spectral_table,
)

REVIGO = Path(
    os.environ.get(
        "BAYESPIG_REVIGO", Path(__file__).resolve().parents[3] / "shared" / "data" / "revigo"
    )
)
REVIGO_TABLE = REVIGO / "revigo-aggregated-palette-spectral-data.txt"
needs_revigo = pytest.mark.skipif(
    not REVIGO_TABLE.exists(), reason=f"Revigo data not found at {REVIGO}"
)

#: Percent -> fraction is one division; allow its rounding.
PERCENT_REL_TOL = 1e-12


def small_table(tmp_path, rows, header="Name\t400\t500"):
    path = tmp_path / "table.txt"
    path.write_text(header + "\n" + "\n".join("\t".join(map(str, r)) for r in rows) + "\n")
    return path


FOUR = [["X_b", 5, 5], ["X_w", 80, 85], ["X_ob", 20, 30], ["X_ow", 40, 50]]


def test_small_table_becomes_one_black_white_set(tmp_path):
    ms = read_measurements(small_table(tmp_path, FOUR))
    assert ms.sample_names == ("X_b", "X_w", "X_ob", "X_ow")
    assert [s.role for s in ms.samples] == ["substrate", "substrate", "film", "film"]
    assert ms.sample("X_ob").substrate == "X_b" and ms.sample("X_ow").film_group == "X"
    assert np.allclose(ms.sample("X_ow").measurements[0].values, [0.4, 0.5], rtol=PERCENT_REL_TOL)
    assert ms.sample("X_ow").measurements[0].label == "8d-sce"
    assert ms.supported_methods()["method4"].samples == ("X_ob", "X_ow")
    sci = read_revigo(small_table(tmp_path, FOUR), specular="included")["X"]
    assert sci.sample("X_b").measurements[0].label == "8d-sci"


@pytest.mark.parametrize(
    "rows, row, field, match",
    [
        (FOUR + [["Y_film", 1, 2]], 6, "Name", "does not follow the convention"),
        (FOUR[:3], 2, "Name", "lacks the spectra X_ow"),
        (FOUR + [["X_ob", 1, 2]], 6, "Name", "duplicated row"),
        ([["X_b", 5, -5]] + FOUR[1:], 2, "500", "must be a finite number >= 0"),
        ([["X_b", 5, "nan"]] + FOUR[1:], 2, "500", "must be a finite number >= 0"),
        ([["X_b", 5]] + FOUR[1:], 2, None, "has 2 fields but the header has 3"),
    ],
)
def test_table_errors_name_file_row_and_field(tmp_path, rows, row, field, match):
    path = small_table(tmp_path, rows)
    with pytest.raises(MeasurementError) as info:
        read_revigo(path)
    found = [p for p in info.value.problems if p.row == row and p.field == field]
    assert found, str(info.value)
    assert match in str(found[0]) and str(path) in str(found[0])


def test_units_are_checked(tmp_path):
    with pytest.raises(MeasurementError, match="look like fractions"):
        read_spectral_table(small_table(tmp_path, [[r[0], r[1] / 100, r[2] / 100] for r in FOUR]))
    with pytest.raises(MeasurementError, match="looks like percent"):
        read_spectral_table(small_table(tmp_path, FOUR), units="fraction")


def test_table_with_several_films_needs_a_film_id(tmp_path):
    rows = FOUR + [[name.replace("X", "Z"), a, b] for name, a, b in FOUR]
    path = small_table(tmp_path, rows)
    with pytest.raises(MeasurementError, match="holds 2 films"):
        read_measurements(path)
    assert read_measurements(path, film="Z").sample_names == ("Z_b", "Z_w", "Z_ob", "Z_ow")


@needs_revigo
def test_revigo_84_films_over_black_and_white_with_measured_cards():
    with open(REVIGO_TABLE, newline="") as handle:
        table = {
            row[0]: [float(v) / 100 for v in row[1:]]
            for row in csv.reader(handle, delimiter="\t")
            if row[0] != "Name"
        }
    sets = read_revigo(REVIGO)
    assert len(sets) == 84
    for film_id, ms in sets.items():
        black, white, over_black, over_white = (
            ms.sample(f"{film_id}_{s}") for s in ("b", "w", "ob", "ow")
        )
        assert black.role == white.role == "substrate"
        assert (over_black.substrate, over_white.substrate) == (black.name, white.name)
        assert over_black.film_group == over_white.film_group == film_id
        assert ms.supported_methods()["method4"].samples == (over_black.name, over_white.name)
        for sample in ms.samples:
            np.testing.assert_allclose(
                sample.measurements[0].values, table[sample.name], rtol=PERCENT_REL_TOL
            )
        r_black, r_white = ms.substrate_albedo(over_black), ms.substrate_albedo(over_white)
        assert (0 < r_black).all() and (r_black < r_white).all() and (r_white < 1).all()
    assert sets["06B"].metadata["composition"] == {
        "pigments": ["Vermillion", "ZincWhite", "BoneBlack"],
        "mass_ratios": [10.0, 90.0, 0.0],
    }
    assert np.array_equal(sets["01A"].wavelength_nm, np.arange(400.0, 701.0, 10.0))


@needs_revigo
def test_revigo_check_report_and_single_film():
    report = check_report(REVIGO)
    assert "84 films" in report and "06B: Vermillion 10+ZincWhite 90" in report
    ms = read_measurements(REVIGO, film="14A")
    assert "method4: yes" in ms.summary()
