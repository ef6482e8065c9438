"""ASTM E1392 BRDF files: simulated, written and read back; azimuth convention; errors."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bayespig.data import (
    MeasurementError,
    MeasurementSet,
    read_astm_e1392,
    read_measurements,
    simulate,
)

WAVELENGTHS = np.array([400.0, 550.0, 700.0])


def e1392(
    rows,
    header="NAME film\nSUBSTRATE black\n",
    vars_line="VARS theta_i,phi_i,theta_s,phi_s,400nm,500nm",
):
    body = "\n".join(",".join(str(x) for x in row) for row in rows)
    return f"#FORMAT=ASTM-E1392-96\n{header}{vars_line}\n{body}\n"


def test_simulated_file_written_and_read_back(tmp_path):
    ms = simulate(
        a=[0.02, 0.1, 0.4], tau=[0.5, 1.0, 3.0], design="method3", wavelengths=WAVELENGTHS, seed=7
    )
    path = tmp_path / "on_black.astm"
    ms.to_astm_e1392(path)
    text = path.read_text()
    assert text.startswith("#FORMAT=ASTM-E1392-96\n") and "\nNUM_POINTS 6\n" in text
    assert "VARS theta_i,phi_i,theta_s,phi_s,400nm,550nm,700nm" in text
    back = read_measurements(path)
    assert back == ms
    assert dict(back.metadata) == dict(ms.metadata)


def test_film_and_its_card_in_two_files(tmp_path):
    ms = simulate(
        a=0.05,
        tau=1.0,
        wavelengths=WAVELENGTHS,
        eps=0.0,
        design=[dict(name="film", substrate=0.6, measure_substrate=True)],
    )
    ms.to_astm_e1392(tmp_path / "film.astm", sample="film")
    ms.to_astm_e1392(tmp_path / "card.astm", sample="film_substrate")
    back = read_astm_e1392([tmp_path / "card.astm", tmp_path / "film.astm"])
    assert back == ms
    with pytest.raises(MeasurementError, match="substrate sample 'film_substrate' is missing"):
        read_astm_e1392(tmp_path / "film.astm")


@pytest.mark.parametrize(
    "phi_i, phi_s, label",
    [
        # E1392: phi_s = phi_i + pi is the specular side, our delta_phi = 180
        (0.0, math.pi, "45as15"),
        (0.0, -math.pi, "45as15"),
        (math.pi / 2, 3 * math.pi / 2, "45as15"),
        (math.pi, 0.0, "45as15"),
        # phi_s = phi_i: back towards the source, delta_phi = 0 (aspecular 45 + 30 = 75)
        (0.0, 0.0, "45as75"),
        (1.0, 1.0 - 2 * math.pi, "45as75"),
        # out of the plane of incidence
        (0.0, math.pi / 2, "45/30/90"),
        (0.0, -math.pi / 2, "45/30/90"),
    ],
)
def test_azimuth_convention(tmp_path, phi_i, phi_s, label):
    path = tmp_path / "f.astm"
    path.write_text(e1392([[math.radians(45), phi_i, math.radians(30), phi_s, 0.01, 0.02]]))
    m = read_astm_e1392(path).sample("film").measurements[0]
    assert m.label == label


def test_plain_file_with_defaults(tmp_path):
    path = tmp_path / "plain.txt"
    path.write_text(
        "#FORMAT=ASTM-E1392-96\nSOURCE some gonioreflectometer\nVARS theta_i,phi_i,theta_s,phi_s,"
        "400nm,500nm\n0.785398,0,0.523599,3.141593,0.01,0.02\n"
    )
    with pytest.raises(MeasurementError) as info:
        read_measurements(path)
    assert str(info.value) == (
        f"{path}, field 'OPAQUE': the header says neither OPAQUE nor SUBSTRATE (ASTM E1392 has "
        "no keyword for them): say whether the film hides its substrate with opaque=True "
        "(--opaque on the command line) or give substrate='black', 'white' or an albedo "
        "(--substrate), or add the header line 'OPAQUE yes' or 'SUBSTRATE black'"
    )
    ms = read_astm_e1392(path, substrate="white")
    assert ms.sample("plain").substrate == "white"
    assert ms.sample("plain").measurements[0].label == "45as15"
    assert ms.metadata["astm_e1392_header"] == {"plain": {"SOURCE": "some gonioreflectometer"}}


@pytest.mark.parametrize(
    "rows, row, field, match",
    [
        ([[45, 0, 30, 180, 0.01, 0.02]], 5, "phi_s", "look like degrees"),
        (
            [[math.radians(45), 0, math.radians(45), math.pi, 0.01, 0.02]],
            5,
            "theta_i,phi_i,theta_s,phi_s",
            "specular direction",
        ),
        ([[math.radians(45), 0, 1.6, math.pi, 0.01, 0.02]], 5, "theta_s", "outside [0, pi/2)"),
        ([[math.radians(45), 0, 0.5, math.pi, -0.01, 0.02]], 5, "400nm", "negative"),
        ([[math.radians(45), 0, 0.5, math.pi, "x", 0.02]], 5, "400nm", "not a number"),
        (
            [
                [math.radians(45), 0, 0.5, math.pi, 0.01, 0.02],
                [math.radians(45), 0, 0.5, -math.pi, 0.01, 0.02],
            ],
            6,
            "theta_i,phi_i,theta_s,phi_s",
            "duplicated row",
        ),
    ],
)
def test_row_errors_name_file_row_and_field(tmp_path, rows, row, field, match):
    path = tmp_path / "bad.astm"
    path.write_text(e1392(rows))
    with pytest.raises(MeasurementError) as info:
        read_astm_e1392(path)
    found = [p for p in info.value.problems if p.row == row and p.field == field]
    assert found, str(info.value)
    assert match in str(found[0]) and str(path) in str(found[0])


def test_header_errors(tmp_path):
    path = tmp_path / "bad.astm"
    path.write_text(
        e1392([[0.7, 0, 0.5, 3.14, 0.01, 0.02]], header="NAME f\nSUBSTRATE black\nNUM_POINTS 3\n")
    )
    with pytest.raises(MeasurementError, match="NUM_POINTS says 3 but the file has 1") as info:
        read_astm_e1392(path)
    assert info.value.problems[0].row == 4
    path.write_text(
        e1392([[0.7, 0, 0.5, 3.14, 1, 2, 3]], vars_line="VARS theta_i,phi_i,theta_s,phi_s,R,G,B")
    )
    with pytest.raises(MeasurementError, match="not a wavelength") as info:
        read_astm_e1392(path)
    assert info.value.problems[0].field == "R"


def test_files_with_different_wavelengths(tmp_path):
    a, b = tmp_path / "a.astm", tmp_path / "b.astm"
    a.write_text(e1392([[0.7, 0, 0.5, 3.14, 0.01, 0.02]], header="NAME a\nSUBSTRATE black\n"))
    b.write_text(
        e1392(
            [[0.7, 0, 0.5, 3.14, 0.02, 0.03]],
            header="NAME b\nSUBSTRATE white\n",
            vars_line="VARS theta_i,phi_i,theta_s,phi_s,450nm,500nm",
        )
    )
    with pytest.raises(MeasurementError, match="wavelengths differ between samples"):
        read_astm_e1392([a, b])
    with pytest.warns(UserWarning, match="interpolated"):
        ms = read_astm_e1392([a, b], resample=True)
    assert np.array_equal(ms.wavelength_nm, [450.0, 500.0])
    np.testing.assert_allclose(ms.sample("a").measurements[0].values, [0.015, 0.02])


def test_writer_refuses_non_brdf(tmp_path):
    ms = simulate(a=0.05, tau=1.0, design="method1", wavelengths=WAVELENGTHS)
    with pytest.raises(ValueError, match="specular_transmittance"):
        ms.to_astm_e1392(tmp_path / "glass.astm", sample="on_glass")
    with pytest.raises(ValueError, match="choose one with sample="):
        ms.to_astm_e1392(tmp_path / "x.astm")
    assert not list(tmp_path.iterdir())


LINE_TOKENS = [
    "",
    "VARS theta_i,phi_i,theta_s,phi_s,400nm",
    "NAME",
    "SUBSTRATE",
    "SUBSTRATE 2",
    "N 0.5",
    "OPAQUE x",
    "NUM_POINTS x",
    "BAYESPIG_METADATA [1]",
    "0.7,0,0.5,3.14,0.01",
    "0.7 0 0.5 3.14 0.01",
    "1,2",
    "#",
]


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(lines=st.lists(st.sampled_from(LINE_TOKENS) | st.text(max_size=20), max_size=8))
def test_malformed_e1392_is_a_set_or_a_measurement_error(tmp_path_factory, lines):
    path = tmp_path_factory.getbasetemp() / "malformed.astm"
    path.write_text("\n".join(lines), encoding="utf-8", errors="surrogatepass")
    try:
        assert isinstance(read_astm_e1392(path), MeasurementSet)
    except MeasurementError:
        pass
