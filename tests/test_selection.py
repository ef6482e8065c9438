"""Selecting geometries (mirror cone, grazing angles) and bands of a measurement set."""

import numpy as np
import pytest

from bayespig.data import Measurement, MeasurementSet, Sample
from bayespig.selection import mirror_distance_deg, occluded_geometries, select_measurements

#: Two computations of the same angle (atan2 of the cross and dot products vs arccos of an
#: explicitly rotated dot product): rounding, amplified by arccos near 0 and 180 degrees.
ANGLE_ABS_TOL_DEG = 1e-6


def _unit(theta_deg, phi_deg):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def test_mirror_distance_against_explicit_vectors():
    """The source at azimuth phi_s (any), the viewer at phi_s + delta_phi; the mirror direction
    is the source direction reflected in the normal: (-s_x, -s_y, s_z)."""
    rng = np.random.default_rng(7)
    theta_i = rng.uniform(0, 89, 500)
    theta_o = rng.uniform(0, 89, 500)
    delta_phi = rng.uniform(0, 180, 500)
    phi_source = rng.uniform(0, 360, 500)
    expected = []
    for ti, to, dp, ps in zip(theta_i, theta_o, delta_phi, phi_source):
        source = _unit(ti, ps)
        mirror = np.array([-source[0], -source[1], source[2]])
        view = _unit(to, ps + dp)
        expected.append(np.degrees(np.arccos(np.clip(mirror @ view, -1, 1))))
    np.testing.assert_allclose(mirror_distance_deg(theta_i, theta_o, delta_phi), expected, atol=ANGLE_ABS_TOL_DEG)


def test_mirror_distance_special_cases():
    # the mirror itself, the plane of incidence (|theta_i - theta_o| on the specular side,
    # theta_i + theta_o on the source side), and the retro direction
    np.testing.assert_allclose(mirror_distance_deg([45, 45, 45, 30], [45, 30, 30, 30], [180, 180, 0, 0]),
                               [0.0, 15.0, 75.0, 60.0], atol=1e-12)
    # a small angle stays accurate (arccos alone would lose half the digits)
    assert mirror_distance_deg(45.0, 45.0, 180.0 - 1e-6) == pytest.approx(np.degrees(np.sin(np.radians(45))
                                                                                    * np.radians(1e-6)), rel=1e-6)


def _gonio_set():
    wavelengths = [450.0, 500.0, 550.0]
    geometries = ["45/45/179", "45/40/180", "45/20/180", "45/0/180", "30/75/180", "80/10/0", "45/45/90"]
    film = Sample("gonio", "film", tuple(Measurement.from_geometry("brdf", g, [0.1, 0.2, 0.3]) for g in geometries),
                  opaque=True)
    return MeasurementSet(wavelengths, [film])


def test_mirror_cone_and_max_angle_drop_the_right_geometries():
    ms = _gonio_set()
    kept = select_measurements(ms, exclude_mirror_deg=6.0)
    # 45/45/179 is 0.71° from the mirror, 45/40/180 is 5°: both inside 6°
    assert [m.label for m in kept.films[0].measurements] == ["45as25", "45as45", "30as-45", "80as90", "45/45/90"]
    kept = select_measurements(ms, max_angle_deg=60.0)
    assert [m.label for m in kept.films[0].measurements] == ["45/45/179", "45as5", "45as25", "45as45", "45/45/90"]
    assert kept.metadata["selection"] == {"exclude_mirror_deg": None, "max_angle_deg": 60.0,
                                          "wavelength_nm": [450.0, 500.0, 550.0], "occluded": {}}


def test_bands_by_list_and_range():
    ms = _gonio_set()
    kept = select_measurements(ms, wavelengths=[550.0, 450.0])
    np.testing.assert_array_equal(kept.wavelength_nm, [450.0, 550.0])
    np.testing.assert_array_equal(kept.films[0].measurements[0].values, [0.1, 0.3])
    kept = select_measurements(ms, wavelength_range=(480, 560))
    np.testing.assert_array_equal(kept.wavelength_nm, [500.0, 550.0])
    assert select_measurements(ms) is ms


def test_substrate_samples_keep_every_geometry():
    values = [0.1, 0.2, 0.3]
    card = Sample("card", "substrate", (Measurement.from_geometry("brdf", "45as110", values),
                                        Measurement.from_geometry("brdf", "45as15", values)))
    film = Sample("thin", "film", (Measurement.from_geometry("brdf", "45as110", values),
                                   Measurement.from_geometry("brdf", "45as15", values)), substrate="card")
    kept = select_measurements(MeasurementSet([450.0, 500.0, 550.0], [card, film]), max_angle_deg=50.0)
    assert [m.label for m in kept.sample("thin").measurements] == ["45as15"]
    assert [m.label for m in kept.sample("card").measurements] == ["45as110", "45as15"]


@pytest.mark.parametrize("kwargs, message", [
    ({"exclude_mirror_deg": 5.0, "max_angle_deg": 10.0},
     ("the mirror cone of 5° and max angle 10° leave no geometry of film 'gonio' (it has 7: 45/45/179, "
     "45as5, 45as25, 45as45, 30as-45, 80as90, ...)")),
    ({"exclude_mirror_deg": 120.0}, ("the mirror cone of 120° leaves no geometry of film 'gonio' (it has 7: "
                                    "45/45/179, 45as5, 45as25, 45as45, 30as-45, 80as90, ...)")),
    ({"wavelengths": [450.0, 600.0]}, "wavelengths 600 nm are not measured (the set has 3 bands, 450–550 nm)"),
    ({"wavelength_range": (600, 700)}, "wavelength_range 600–700 nm leaves no band of the set (450–550 nm)"),
    ({"wavelength_range": (600, 500)}, "wavelength_range must be (low, high) with low <= high [nm], got (600, 500)"),
    ({"max_angle_deg": 95.0}, "max_angle_deg must be None or a number of degrees in [0, 90], got 95.0"),
    ({"wavelengths": []}, "wavelengths must not be empty (None keeps every band)"),
])
def test_selection_errors(kwargs, message):
    with pytest.raises(ValueError) as caught:
        select_measurements(_gonio_set(), **kwargs)
    assert str(caught.value) == message


def test_selection_type_errors():
    with pytest.raises(TypeError) as caught:
        select_measurements(_gonio_set(), exclude_mirror_deg="5")
    assert str(caught.value) == "exclude_mirror_deg must be None or a number of degrees in [0, 180], got str '5'"
    with pytest.raises(TypeError) as caught:
        select_measurements(_gonio_set(), wavelength_range=450.0)
    assert str(caught.value) == ("wavelength_range must be None or a pair (low, high) of wavelengths [nm], "
                                 "got 450.0")


def _ring_set(dark):
    """A film at theta_i = 45°: viewing directions theta_o = 40° every 10° of azimuth 0-180° (6.4° apart:
    neighbours within 15° two either side) and one at theta_i = 20° alone; the readings of ``dark`` (azimuth ->
    values) replace the smooth ones (0.05-0.2 1/sr)."""
    measurements = []
    for phi in range(0, 181, 10):
        values = dark.get(phi, [0.05 + 0.1 * (1 + np.cos(np.radians(phi))) / 2 * k for k in (1.0, 1.5, 2.0)])
        measurements.append(Measurement.from_geometry("brdf", f"45/40/{phi}", values))
    measurements.append(Measurement.from_geometry("brdf", "20/40/0", [1e-4, 1e-4, 1e-4]))
    film = Sample("ring", "film", tuple(measurements), opaque=True)
    return MeasurementSet([450.0, 500.0, 550.0], [film])


def test_occluded_geometries_are_dark_in_every_band_amid_bright_neighbours():
    # 90°: below 2 % of its neighbours in every band (flagged); 180°: dark at 450 and 500 nm only, its
    # brightest band as bright as its neighbours' (kept: a paint's dark band); 130°: 3-4 % of its
    # neighbours (kept: the ratio is 2 %); 20/40/0: no neighbour at its incidence (never flagged)
    ms = _ring_set({90: [1e-3, 1e-3, 1e-3], 180: [1e-4, 1e-4, 0.15], 130: [3e-3, 3e-3, 3e-3]})
    assert occluded_geometries(ms) == {"ring": [9]}
    kept = select_measurements(ms, exclude_occluded=True)
    assert "45/40/90" not in [m.label for m in kept.films[0].measurements]
    assert len(kept.films[0].measurements) == len(ms.films[0].measurements) - 1
    assert kept.metadata["selection"]["occluded"] == {"ring": ["45/40/90"]}
    assert occluded_geometries(ms, ratio=0.05) == {"ring": [9, 13]}
    assert occluded_geometries(_ring_set({})) == {}


def test_occluded_geometries_arguments():
    with pytest.raises(ValueError) as caught:
        occluded_geometries(_ring_set({}), ratio=1.5)
    assert str(caught.value) == "ratio must be a number in (0, 1), got 1.5"
    with pytest.raises(TypeError) as caught:
        select_measurements(_ring_set({}), exclude_occluded="yes")
    assert str(caught.value) == "exclude_occluded must be True or False, got 'yes' (str)"
    with pytest.raises(TypeError):
        occluded_geometries([1, 2])
