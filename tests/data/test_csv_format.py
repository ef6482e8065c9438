"""The bayespig CSV format: round trips, a test per validation rule, malformed files."""

import textwrap
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bayespig.data import Measurement, MeasurementError, MeasurementSet, Sample, read_csv, simulate

HEADER = "sample,role,substrate,film_group,measurement,geometry,400,500,600"
VALID = textwrap.dedent(f"""\
    # units: fraction
    {HEADER}
    on_black,film,black,A,brdf,45as15,0.010,0.012,0.013
    on_black,film,black,A,brdf,45as45,0.011,0.013,0.014
    on_white,film,white,A,brdf,45as15,0.050,0.060,0.070
    """)


def lines_of(text):
    return text.splitlines()


def write(tmp_path, text, name="measurements.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def replace_line(text, row, new):
    lines = lines_of(text)
    lines[row - 1] = new
    return "\n".join(lines) + "\n"


def problem_at(tmp_path, text, row, field, match, **kwargs):
    """Read ``text``; assert a problem names the file, ``row``, ``field`` and says ``match``."""
    path = write(tmp_path, text)
    with pytest.raises(MeasurementError) as info:
        read_csv(path, **kwargs)
    found = [p for p in info.value.problems if p.row == row and p.field == field]
    assert found, f"no problem at row {row}, field {field!r} in:\n{info.value}"
    message = str(found[0])
    assert str(path) in message and f"row {row}" in message and f"field {field!r}" in message
    assert match in message, message
    assert message in str(info.value)
    return info.value


# ---------------------------------------------------------------------------- round trips
def test_valid_file_reads(tmp_path):
    ms = read_csv(write(tmp_path, VALID))
    assert ms.sample_names == ("on_black", "on_white")
    assert np.array_equal(ms.wavelength_nm, [400.0, 500.0, 600.0])
    assert np.array_equal(ms.sample("on_black").measurements[1].values, [0.011, 0.013, 0.014])
    assert ms.sample("on_white").substrate == "white" and ms.sample("on_white").film_group == "A"


def test_round_trip_simulated(tmp_path):
    ms = simulate(
        a=np.linspace(0.01, 0.5, 31), tau=np.linspace(0.5, 2.0, 31), design="method4", seed=3
    )
    path = tmp_path / "sim.csv"
    ms.to_csv(path)
    back = read_csv(path)
    assert back == ms
    assert dict(back.metadata) == dict(ms.metadata)
    assert back.metadata["truth"]["tau"]["film"] == list(np.linspace(0.5, 2.0, 31))
    for s, t in zip(ms.samples, back.samples):
        for m, k in zip(s.measurements, t.measurements):
            assert np.array_equal(m.values, k.values) and m.label == k.label
    assert back.source == str(path)


def test_round_trip_every_sample_kind(tmp_path):
    wl = np.array([400.0, 550.5, 700.0])
    samples = [
        Sample(
            "card, black",
            "substrate",
            (Measurement.from_geometry("hemispherical", "8d-sci", [0.05, 0.05, 0.06]),),
        ),
        Sample(
            "coated",
            "clear_coated_substrate",
            (Measurement.from_geometry("reflectance_factor", "45-0", [0.8, 0.85, 0.9]),),
        ),
        Sample(
            "thick",
            "film",
            (Measurement.from_geometry("brdf", "45/30/90", [0.1, 0.2, 0.3]),),
            opaque=True,
        ),
        Sample(
            "on_card",
            "film",
            (Measurement.from_geometry("brdf", "45as110", [1 / 3, 0.2, 1e-7]),),
            substrate="card, black",
            film_group="G",
            thickness_um=25.0,
            concentration=0.3,
            eps=0.02,
        ),
        Sample(
            "grey",
            "film",
            (Measurement.from_geometry("hemispherical", "8d-sce", [0.3, 0.3, 0.3]),),
            substrate=0.37,
            film_group="G",
            thickness_um=25.0,
        ),
        Sample(
            "glass",
            "film_on_glass",
            (Measurement.from_geometry("specular_transmittance", "normal", [0.4, 0.5, 0.6]),),
        ),
    ]
    ms = MeasurementSet(
        wl, samples, n=1.5, metadata={"pigment": "Vermillion", "nested": {"x": [1, 2.5, None]}}
    )
    ms.to_csv(tmp_path / "all.csv")
    assert read_csv(tmp_path / "all.csv") == ms


def test_percent_units_and_hand_written_variants(tmp_path):
    text = textwrap.dedent("""\
        # units: percent
        # pigment: Vermillion
        # n: 1.5
        Sample;Role;Substrate;Measurement;Geometry;400 nm;500nm
        card;substrate;;hemispherical;8d-sce;50;60
        film;film;card;brdf;45/30/180;1,0;2.0
        """).replace("1,0", "1.0")
    ms = read_csv(write(tmp_path, text))
    assert np.allclose(ms.sample("card").measurements[0].values, [0.5, 0.6])
    assert ms.sample("film").measurements[0].label == "45as15"
    assert ms.metadata["pigment"] == "Vermillion" and ms.n == 1.5


# ------------------------------------------------------------------- one test per rule
def test_missing_column(tmp_path):
    text = VALID.replace(",geometry", "").replace(",45as15", "").replace(",45as45", "")
    problem_at(tmp_path, text, 2, "geometry", "missing column 'geometry'")


def test_unknown_column(tmp_path):
    problem_at(
        tmp_path,
        VALID.replace("substrate,", "substrat,", 1),
        2,
        "substrat",
        "did you mean 'substrate'",
    )


def test_nan_reflectance(tmp_path):
    problem_at(
        tmp_path, VALID.replace("0.012,0.013\non_black", "nan,0.013\non_black"), 3, "500", "NaN"
    )


def test_negative_reflectance(tmp_path):
    problem_at(tmp_path, VALID.replace("0.050", "-0.050"), 5, "400", "negative")


def test_percent_where_fractions_expected(tmp_path):
    text = VALID.replace("# units: fraction\n", "").replace("0.050,0.060,0.070", "5.0,6.0,7.0")
    error = problem_at(tmp_path, text, 4, "600", "looks like percent")
    assert "# units: percent" in str(error)


def test_non_number(tmp_path):
    problem_at(tmp_path, VALID.replace("0.010", '"0,010"'), 3, "400", "decimal comma")


def test_angle_out_of_range(tmp_path):
    problem_at(tmp_path, VALID.replace("45as45", "95as45"), 4, "geometry", "[0, 90)")


def test_specular_direction(tmp_path):
    problem_at(tmp_path, VALID.replace("45as45", "45as0"), 4, "geometry", "specular direction")


def test_wavelengths_differ_between_samples(tmp_path):
    text = VALID.replace("0.050,0.060,0.070", ",0.060,0.070")
    problem_at(tmp_path, text, 5, "400", "wavelengths differ between samples")


def test_resample_when_asked_with_a_warning(tmp_path):
    text = VALID.replace("0.050,0.060,0.070", ",0.060,0.070")
    with pytest.warns(UserWarning, match="interpolated"):
        ms = read_csv(write(tmp_path, text), resample=True)
    assert np.array_equal(ms.wavelength_nm, [500.0, 600.0])
    assert np.array_equal(ms.sample("on_black").measurements[0].values, [0.012, 0.013])


def test_film_whose_substrate_is_missing(tmp_path):
    text = VALID.replace("on_white,film,white", "on_white,film,white_card")
    error = problem_at(tmp_path, text, 5, "substrate", "substrate sample 'white_card' is missing")
    assert "role 'substrate'" in str(error)


def test_duplicated_rows(tmp_path):
    text = VALID + "on_black,film,black,A,brdf,45/30/180,0.010,0.012,0.013\n"
    problem_at(tmp_path, text, 6, "geometry", "duplicated row")


def test_sample_attributes_that_disagree(tmp_path):
    text = replace_line(VALID, 4, "on_black,film,white,A,brdf,45as45,0.011,0.013,0.014")
    problem_at(tmp_path, text, 4, "substrate", "must agree")


def test_wrong_number_of_fields(tmp_path):
    path = write(tmp_path, replace_line(VALID, 3, "on_black,film,black,A,brdf,45as15,0.010,0.012"))
    with pytest.raises(MeasurementError, match="row 3: has 8 fields but the header has 9"):
        read_csv(path)


def test_unknown_role_and_measurement(tmp_path):
    problem_at(
        tmp_path, VALID.replace("on_white,film", "on_white,flim"), 5, "role", "role must be one of"
    )
    problem_at(
        tmp_path,
        VALID.replace("A,brdf,45as45", "A,brfd,45as45"),
        4,
        "measurement",
        "did you mean 'brdf'",
    )


def test_method_the_samples_cannot_serve(tmp_path):
    path = write(tmp_path, "\n".join(lines_of(VALID)[:4]) + "\n")
    ms = read_csv(path)
    with pytest.raises(MeasurementError) as info:
        ms.require_method("method4")
    message = str(info.value)
    assert str(path) in message and "field 'method'" in message and "'on_black'" in message
    assert not ms.supported_methods()["method1"]
    assert "film on glass" in ms.supported_methods()["method1"].reason


def test_every_problem_is_reported_at_once(tmp_path):
    text = VALID.replace("0.010", "nan").replace("45as45", "45as0").replace("0.050", "-1")
    path = write(tmp_path, text)
    with pytest.raises(MeasurementError) as info:
        read_csv(path)
    assert {(p.row, p.field) for p in info.value.problems} == {
        (3, "400"),
        (4, "geometry"),
        (5, "400"),
    }
    assert str(info.value).startswith("3 problems:")


def test_missing_file_and_binary_file(tmp_path):
    with pytest.raises(MeasurementError, match="file not found"):
        read_csv(tmp_path / "nope.csv")
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(MeasurementError, match="not UTF-8"):
        read_csv(tmp_path / "bin.csv")


def test_nothing_written_on_error(tmp_path):
    ms = read_csv(write(tmp_path, VALID))
    target = tmp_path / "out.csv"
    target.write_text("previous content")
    # Sample refuses such a name; the writer checks again, before writing anything, for
    # objects changed after construction.
    sample = ms.samples[-1]
    object.__setattr__(sample, "name", "on\x00white")
    with pytest.raises(
        ValueError,
        match=r"^sample name 'on\\x00white' contains the control character '\\x00', which a "
        "text file cannot hold; rename it$",
    ):
        ms.to_csv(target)
    assert target.read_text() == "previous content"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["measurements.csv", "out.csv"]


# --------------------------------------------------------------------- malformed files
TOKENS = [
    "",
    " ",
    "nan",
    "NaN",
    "-1",
    "1e999",
    "inf",
    "abc",
    "45as0",
    "45as15",
    "95as15",
    "8d-sci",
    "45-0",
    "normal",
    "black",
    "white",
    "card",
    "0.5",
    "7",
    "150",
    "yes",
    "maybe",
    "film",
    "substrate",
    "brdf",
    "hemispherical",
    "specular_transmittance",
    '"',
    '"a,b"',
    "#",
    "# units: percent",
    "\x00",
    "é",
    ",",
    ";",
    "\t",
    "400",
    "0",
    "-0",
    "1,5",
]


@st.composite
def malformed_csv(draw):
    lines = lines_of(VALID) + ["card,substrate,,,hemispherical,8d-sce,0.05,0.05,0.05"]
    for _ in range(draw(st.integers(1, 4))):
        action = draw(st.sampled_from(["cell", "delete", "duplicate", "insert", "truncate"]))
        row = draw(st.integers(0, len(lines) - 1))
        if action == "cell":
            cells = lines[row].split(",")
            cells[draw(st.integers(0, len(cells) - 1))] = draw(
                st.sampled_from(TOKENS) | st.text(max_size=6)
            )
            lines[row] = ",".join(cells)
        elif action == "delete" and len(lines) > 1:
            del lines[row]
        elif action == "duplicate":
            lines.insert(row, lines[row])
        elif action == "insert":
            lines.insert(row, draw(st.text(max_size=30)))
        else:
            lines[row] = lines[row][: draw(st.integers(0, len(lines[row])))]
    return "\n".join(lines) + draw(st.sampled_from(["\n", "", "\r\n"]))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(text=malformed_csv())
def test_malformed_csv_is_a_set_or_a_measurement_error(tmp_path_factory, text):
    path = tmp_path_factory.getbasetemp() / "malformed.csv"
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            ms = read_csv(path)
        except MeasurementError as error:
            assert all(p.file == str(path) for p in error.problems), str(error)
            return
    assert isinstance(ms, MeasurementSet)
    out = path.with_name("rewritten.csv")
    ms.to_csv(out)
    back = read_csv(out)
    assert back.samples == ms.samples and np.array_equal(back.wavelength_nm, ms.wavelength_nm)


@settings(max_examples=200, deadline=None)
@given(data=st.binary(max_size=300))
def test_arbitrary_bytes_never_crash_the_reader(tmp_path_factory, data):
    path = tmp_path_factory.getbasetemp() / "bytes.csv"
    path.write_bytes(data)
    try:
        assert isinstance(read_csv(path), MeasurementSet)
    except MeasurementError:
        pass
