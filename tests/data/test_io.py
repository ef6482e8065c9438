"""read_measurements dispatch, check_report, and the example files in examples/data."""

from pathlib import Path

import numpy as np
import pytest

from bayespig.data import MeasurementError, check_report, read_measurements
from bayespig.data.io import file_format

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "data"
#: Substrate albedo from noisy card measurements (eps = 0.05 per value, one value per band) vs the
#: albedo they were simulated with: the inversion damps the relative error, 4 sigma is < 20 %.
CARD_ALBEDO_REL_TOL = 0.2


@pytest.mark.parametrize(
    "name, kind, samples, methods",
    [
        ("method4-black-white.csv", "csv", ("on_black", "on_white"), {"method3", "method4"}),
        ("method1-opaque-and-glass.csv", "csv", ("opaque", "on_glass"), {"method1"}),
        (
            "measured-cards-percent.csv",
            "csv",
            ("over_black_substrate", "over_black", "over_white_substrate", "over_white"),
            {"method3", "method4"},
        ),
        ("on-black.astm", "astm_e1392", ("on_black",), {"method3"}),
        (
            "wide-table-percent.txt",
            "spectral_table",
            ("R1_b", "R1_w", "R1_ob", "R1_ow"),
            {"method3", "method4"},
        ),
    ],
)
def test_examples_read_and_report(name, kind, samples, methods):
    path = EXAMPLES / name
    assert file_format(path) == kind
    ms = read_measurements(path)
    assert ms.sample_names == samples
    assert {m for m, s in ms.supported_methods().items() if s} == methods
    report = check_report(path)
    assert report.startswith(f"{path}: {kind.replace('_', ' ')} file, valid")
    for sample in samples:
        assert sample in report
    for method in methods:
        assert f"{method}: yes" in report


def test_example_cards_give_their_albedo():
    ms = read_measurements(EXAMPLES / "measured-cards-percent.csv")
    np.testing.assert_allclose(ms.substrate_albedo("over_black"), 0.08, rtol=CARD_ALBEDO_REL_TOL)
    np.testing.assert_allclose(ms.substrate_albedo("over_white"), 0.9, rtol=CARD_ALBEDO_REL_TOL)


def test_check_report_lists_every_problem(tmp_path):
    text = (EXAMPLES / "method4-black-white.csv").read_text()
    text = text.replace("45as25", "45as0", 1).replace("0.02009", "nan").replace(",black,", ",blak,")
    path = tmp_path / "broken.csv"
    path.write_text(text)
    with pytest.raises(MeasurementError) as info:
        check_report(path)
    message = str(info.value)
    assert message.startswith("3 problems:")
    assert "row 11, field '400': value is NaN" in message
    assert "row 13, field 'geometry'" in message and "specular direction" in message
    assert "row 11, field 'substrate': substrate sample 'blak' is missing" in message


def test_read_measurements_accepts_a_set_and_lists_of_e1392_files(tmp_path):
    ms = read_measurements(EXAMPLES / "method4-black-white.csv")
    assert read_measurements(ms) is ms
    ms.to_astm_e1392(tmp_path / "b.astm", sample="on_black")
    ms.to_astm_e1392(tmp_path / "w.astm", sample="on_white")
    assert read_measurements([tmp_path / "b.astm", tmp_path / "w.astm"]) == ms
    with pytest.raises(MeasurementError, match="file not found"):
        read_measurements(tmp_path / "missing.csv")


DOCS = Path(__file__).resolve().parents[2] / "docs" / "file-formats.md"


def _doc_examples():
    """The ```text blocks of docs/file-formats.md that are files (not the error listing)."""
    blocks = DOCS.read_text().split("```text\n")[1:]
    return [
        block.split("```")[0] for block in blocks if not block.startswith(("3 problems", "#FORMAT"))
    ], [block.split("```")[0] for block in blocks if block.startswith("#FORMAT")]


def test_documented_examples_are_valid_files(tmp_path):
    tables, e1392_files = _doc_examples()
    assert len(tables) == 5 and len(e1392_files) == 1
    for k, text in enumerate(tables):
        path = tmp_path / f"example{k}.{'txt' if text.startswith('Name') else 'csv'}"
        path.write_text(text)
        assert read_measurements(path).samples
    path = tmp_path / "example.astm"
    path.write_text(e1392_files[0])
    labels = [m.label for m in read_measurements(path).sample("on_black").measurements]
    assert labels == ["45as15", "45as110"]
