"""The measurement data model: geometry labels, validation on construction, substrates, methods."""

import pickle

import numpy as np
import pytest

from bayespig.data import (
    BLACK_SUBSTRATE_ALBEDO,
    WHITE_SUBSTRATE_ALBEDO,
    Measurement,
    MeasurementError,
    MeasurementSet,
    Sample,
)
from bayespig.data.model import parse_measurement_geometry

#: Closed forms evaluated two ways (test-side reference vs library), rounding only.
CLOSED_FORM_REL_TOL = 1e-10
#: Midpoint-rule quadrature of the internal diffuse reflectance in the test reference.
QUADRATURE_REL_TOL = 1e-7

WAVELENGTHS = np.array([400.0, 500.0, 600.0])
N_BINDER = 1.45


def brdf(label, values=(0.02, 0.03, 0.04)):
    return Measurement.from_geometry("brdf", label, values)


def film(name, substrate="black", group=None, **kwargs):
    return Sample(
        name,
        "film",
        (brdf("45as15"), brdf("45as45")),
        substrate=substrate,
        film_group=group,
        **kwargs,
    )


# ------------------------------------------------------------------------------- geometry
@pytest.mark.parametrize(
    "label, expected",
    [
        # ASTM E2194: aspecular measured from the specular direction towards the source (DESIGN.md)
        ("45as15", (45.0, 30.0, 180.0, "45as15")),
        ("45as-15", (45.0, 60.0, 180.0, "45as-15")),
        ("45as110", (45.0, 65.0, 0.0, "45as110")),
        ("45/30/180", (45.0, 30.0, 180.0, "45as15")),
        ("45/65/0", (45.0, 65.0, 0.0, "45as110")),
        ("45/30/90", (45.0, 30.0, 90.0, "45/30/90")),
        ("45/0/90", (45.0, 0.0, 180.0, "45as45")),  # azimuth undefined along the normal
    ],
)
def test_brdf_geometry_labels(label, expected):
    g = parse_measurement_geometry("brdf", label)
    assert (g["theta_i"], g["theta_o"], g["delta_phi"], g["label"]) == expected


@pytest.mark.parametrize(
    "kind, text, expected",
    [
        ("hemispherical", "8d-sci", (8.0, "included", "8d-sci")),
        ("hemispherical", "8D-SCE", (8.0, "excluded", "8d-sce")),
        ("reflectance_factor", "45-0", (45.0, None, "45-0")),
        ("specular_transmittance", "", (0.0, None, "normal")),
    ],
)
def test_other_geometries(kind, text, expected):
    g = parse_measurement_geometry(kind, text)
    assert (g["theta_i"], g["specular"], g["label"]) == expected


@pytest.mark.parametrize(
    "kind, text, match",
    [
        ("brdf", "45as0", "specular direction"),
        ("brdf", "45/45/180", "specular direction"),
        ("brdf", "95as15", r"\[0, 90\)"),
        ("brdf", "45as-50", "horizon"),
        ("brdf", "45/30/200", r"\[0, 180\]"),
        ("brdf", "45deg", "E2194"),
        ("hemispherical", "8/d", "8d-sci"),
        ("reflectance_factor", "45-45", "specular direction"),
        ("specular_transmittance", "45", "normal incidence"),
        ("gloss", "60", "measurement must be one of"),
    ],
)
def test_bad_geometries(kind, text, match):
    with pytest.raises(ValueError, match=match):
        parse_measurement_geometry(kind, text)


# ------------------------------------------------------------------------------ validation
@pytest.mark.parametrize(
    "values, match",
    [
        ([0.1, np.nan, 0.1], "NaN"),
        ([0.1, -0.01, 0.1], "negative"),
        ([0.1, np.inf, 0.1], "infinite"),
        ([[0.1, 0.2]], "1-D"),
    ],
)
def test_measurement_rejects_bad_values(values, match):
    with pytest.raises(MeasurementError, match=match) as info:
        Measurement.from_geometry("brdf", "45as15", values)
    assert info.value.problems[0].field == "values"


def test_measurement_detects_percent():
    with pytest.raises(MeasurementError, match="looks like percent"):
        Measurement.from_geometry("hemispherical", "8d-sce", [40.0, 50.0, 60.0])


def test_measurement_values_are_read_only():
    m = brdf("45as15")
    with pytest.raises(ValueError):
        m.values[0] = 1.0


@pytest.mark.parametrize(
    "kwargs, field, match",
    [
        (dict(name="f", role="paint"), "role", "role must be one of"),
        (dict(name="f", role="film", substrate=None), "substrate", "needs a substrate"),
        (dict(name="f", role="film", substrate=1.5), "substrate", "outside"),
        (dict(name="f", role="film", substrate="black", thickness_um=-3.0), "thickness_um", "> 0"),
        (dict(name="card", role="substrate", substrate="black"), "substrate", "no substrate"),
        (dict(name=" f", role="film", substrate="black"), "sample", "surrounding blanks"),
    ],
)
def test_sample_validation(kwargs, field, match):
    with pytest.raises(MeasurementError, match=match) as info:
        Sample(measurements=(brdf("45as15"),), **kwargs)
    assert info.value.problems[0].field == field


def test_sample_rejects_duplicate_geometry():
    with pytest.raises(MeasurementError, match="given twice") as info:
        Sample("f", "film", (brdf("45as15"), brdf("45/30/180")), substrate="black")
    assert info.value.problems[0].field == "geometry"


def test_transmittance_needs_film_on_glass():
    t = Measurement.from_geometry("specular_transmittance", "normal", [0.5, 0.5, 0.5])
    with pytest.raises(MeasurementError, match="film_on_glass"):
        Sample("g", "film", (t,), substrate="black")
    assert Sample("g", "film_on_glass", (t,)).transmittance == t


def test_set_reports_every_problem():
    samples = [
        film("a", substrate="card"),
        film("a"),
        film("b", group="G", opaque=True, substrate=None),
        film("c", group="G"),
    ]
    with pytest.raises(MeasurementError) as info:
        MeasurementSet(WAVELENGTHS, samples)
    fields = sorted(p.field for p in info.value.problems)
    assert fields == ["opaque", "sample", "substrate"]
    assert "substrate sample 'card' is missing" in str(info.value)


def test_set_rejects_wrong_lengths_and_wavelengths():
    with pytest.raises(MeasurementError, match="3 values but the set has 2"):
        MeasurementSet(WAVELENGTHS[:2], [film("a")])
    with pytest.raises(MeasurementError, match="strictly increasing"):
        MeasurementSet(WAVELENGTHS[::-1], [film("a")])


def test_equality_and_metadata_are_json():
    a = MeasurementSet(WAVELENGTHS, [film("a")], metadata={"truth": {"a": np.array([0.1, 0.2])}})
    b = MeasurementSet(WAVELENGTHS, [film("a")], metadata={"truth": {"a": [0.1, 0.2]}})
    assert a == b
    assert a != MeasurementSet(
        WAVELENGTHS, [film("a", substrate="white")], metadata=dict(b.metadata)
    )
    with pytest.raises(MeasurementError, match="JSON"):
        MeasurementSet(WAVELENGTHS, [film("a")], metadata={"bad": object()})


def test_a_set_pickles_as_it_is():
    """Worker processes receive sets as they are (the library build, leave one film out)."""
    original = MeasurementSet(WAVELENGTHS, [film("a")], n=1.5, metadata={"composition": {"W": 1.0}},
                              source="films.csv")
    original.sample("a")  # the name index is built lazily and must not travel
    copy = pickle.loads(pickle.dumps(original))
    assert copy == original
    assert (copy.n, copy.source, dict(copy.metadata)) == (1.5, "films.csv", {"composition": {"W": 1.0}})
    with pytest.raises(TypeError):
        copy.metadata["composition"] = {}  # still read-only
    assert copy.sample("a") == original.sample("a")


# ------------------------------------------------------------------------------ substrates
def _fresnel_unpolarised(cos_i, n):
    """Test-side Fresnel reflectance from air into a medium of index n."""
    sin_t = np.sqrt(1 - cos_i**2) / n
    cos_t = np.sqrt(1 - sin_t**2)
    r_s = (cos_i - n * cos_t) / (cos_i + n * cos_t)
    r_p = (n * cos_i - cos_t) / (n * cos_i + cos_t)
    return 0.5 * (r_s**2 + r_p**2)


def _internal_diffuse_reflectance(n, points=200_000):
    """2 int_0^1 r(mu) mu dmu inside the binder (total reflection beyond the critical angle)."""
    mu = (np.arange(points) + 0.5) / points
    sin_air = n * np.sqrt(1 - mu**2)
    r = np.ones_like(mu)
    inside = sin_air < 1
    r[inside] = _fresnel_unpolarised(np.sqrt(1 - sin_air[inside] ** 2), n)  # reciprocity of r_F
    return 2 * np.sum(r * mu) / points


def test_substrate_albedo_from_a_card_measured_in_air():
    """A card built with the clear-binder law (eq. 9, test-side) gives back its albedo."""
    r_s = np.array([0.05, 0.5, 0.9])
    r_f = _fresnel_unpolarised(np.cos(np.radians(8.0)), N_BINDER)
    r_i = _internal_diffuse_reflectance(N_BINDER)
    sce = (1 - r_f) * r_s * (1 - r_i) / (1 - r_s * r_i)
    cards = [
        Sample(
            "card_sce", "substrate", (Measurement.from_geometry("hemispherical", "8d-sce", sce),)
        ),
        Sample(
            "card_sci",
            "clear_coated_substrate",
            (Measurement.from_geometry("hemispherical", "8d-sci", sce + r_f),),
        ),
    ]
    films = [
        Sample("on_sce", "film", (brdf("45as15"),), substrate="card_sce"),
        Sample("on_sci", "film", (brdf("45as15"),), substrate="card_sci"),
    ]
    ms = MeasurementSet(WAVELENGTHS, cards + films, n=N_BINDER)
    for name in ("on_sce", "on_sci"):
        np.testing.assert_allclose(ms.substrate_albedo(name), r_s, rtol=QUADRATURE_REL_TOL)


def test_constant_and_named_substrates():
    ms = MeasurementSet(
        WAVELENGTHS,
        [
            film("b"),
            film("w", substrate="white"),
            film("g", substrate=0.3),
            film("o", substrate=None, opaque=True),
        ],
    )
    assert np.array_equal(ms.substrate_albedo("b"), np.full(3, BLACK_SUBSTRATE_ALBEDO))
    assert np.array_equal(ms.substrate_albedo("w"), np.full(3, WHITE_SUBSTRATE_ALBEDO))
    assert np.array_equal(ms.substrate_albedo("g"), np.full(3, 0.3))
    assert np.array_equal(ms.substrate_albedo("o"), np.zeros(3))


def test_too_bright_card_is_reported():
    card = Sample(
        "card",
        "substrate",
        (Measurement.from_geometry("hemispherical", "8d-sce", [0.99, 0.99, 0.99]),),
    )
    ms = MeasurementSet(WAVELENGTHS, [card, film("f", substrate="card")])
    with pytest.raises(MeasurementError, match="card") as info:
        ms.substrate_albedo("f")
    assert info.value.problems[0].sample == "card"


# --------------------------------------------------------------------------------- methods
def test_methods_and_missing_samples():
    glass = Sample(
        "glass",
        "film_on_glass",
        (Measurement.from_geometry("specular_transmittance", "normal", [0.5, 0.5, 0.5]),),
    )
    ms = MeasurementSet(
        WAVELENGTHS,
        [
            film("thick", substrate=None, opaque=True),
            glass,
            film("on_black", group="A"),
            film("on_white", substrate="white", group="A"),
        ],
    )
    support = ms.supported_methods()
    assert all(support.values())
    assert support["method1"].samples == ("thick", "glass")
    assert support["method4"].samples == ("on_black", "on_white")

    only_black = ms.select(["on_black"])
    with pytest.raises(MeasurementError, match="film group 'A' has only 'on_black'") as info:
        only_black.require_method("method4")
    assert info.value.problems[0].field == "method"
    with pytest.raises(MeasurementError, match="film_on_glass"):
        ms.select(["thick"]).require_method("method1")
    assert ms.for_method("method2").sample_names == ("thick", "on_black")


def test_select_keeps_referenced_substrates():
    card = Sample(
        "card",
        "substrate",
        (Measurement.from_geometry("hemispherical", "8d-sce", [0.5, 0.5, 0.5]),),
    )
    ms = MeasurementSet(WAVELENGTHS, [card, film("f", substrate="card"), film("g")])
    assert ms.select(["f"]).sample_names == ("card", "f")
    assert ms.select(roles=["film"]).sample_names == ("card", "f", "g")


def test_resample_interpolates_linearly():
    ms = MeasurementSet(WAVELENGTHS, [film("a")])
    out = ms.resample([450.0, 550.0])
    np.testing.assert_allclose(
        out.sample("a").measurements[0].values, [0.025, 0.035], rtol=CLOSED_FORM_REL_TOL
    )
    with pytest.raises(ValueError, match="outside the measured range"):
        ms.resample([390.0])
