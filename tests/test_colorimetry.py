"""Tests for bayespig.colorimetry against colour-science and published CIEDE2000 data."""

import warnings

import colour
import numpy as np
import pytest
from colour.utilities import ColourRuntimeWarning

from bayespig import colorimetry as cm

SD_TO_XYZ_TOL = 1e-6  # fast path vs colour.sd_to_XYZ, XYZ on the 0-1 scale (issue 7)
SHARMA_TOL = 1e-4  # published Delta E 2000 values are given to 4 decimals
CIE_WHITE_XY_TOL = 5e-5  # colour tabulates D65 xy to 5 (10 deg) or 4 (2 deg) decimals
LAB_TOL = 1e-9

GRID_10NM = np.arange(400.0, 701.0, 10.0)


@pytest.fixture
def rng():
    return np.random.default_rng(20240607)


def smooth_spectra(wavelength_nm, n, rng):
    """Smooth, varied reflectance spectra in (0, 1): logistic of random low-order curves."""
    x = (np.asarray(wavelength_nm) - 550.0) / 150.0
    coefficients = rng.normal(0.0, 2.0, size=(n, 4))
    logits = coefficients @ np.stack([np.ones_like(x), x, x**2, x**3])
    return 1.0 / (1.0 + np.exp(-logits))


def reference_XYZ(reflectance, wavelength_nm, observer, illuminant, method):
    """colour.sd_to_XYZ on each spectrum, as a colour scientist would call it; 0-1 scale."""
    cmfs = colour.MSDS_CMFS[observer]
    illuminant_sd = colour.SDS_ILLUMINANTS[illuminant]
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ColourRuntimeWarning)
        for r in np.atleast_2d(reflectance):
            sd = colour.SpectralDistribution(r, wavelength_nm)
            out.append(colour.sd_to_XYZ(sd, cmfs, illuminant_sd, method=method) / 100.0)
    return np.array(out)


GRIDS = {
    "10nm 400-700": (GRID_10NM, "ASTM E308"),
    "20nm 400-700": (np.arange(400.0, 701.0, 20.0), "ASTM E308"),
    "5nm 380-780": (np.arange(380.0, 781.0, 5.0), "ASTM E308"),
    "1nm 360-780": (np.arange(360.0, 781.0, 1.0), "ASTM E308"),
    "10nm 400-700 integration": (GRID_10NM, "Integration"),
    "15nm 405-705": (np.arange(405.0, 706.0, 15.0), "Integration"),
    "irregular": (np.array([400, 410, 425, 450, 480, 500, 550, 600, 640, 700.0]), "Integration"),
}


@pytest.mark.parametrize("grid", GRIDS)
def test_weighting_matrix_equals_sd_to_XYZ(grid, rng):
    wavelength_nm, method = GRIDS[grid]
    R = smooth_spectra(wavelength_nm, 4, rng)
    R[0] = rng.uniform(0.0, 1.0, wavelength_nm.size)  # a rough spectrum too
    fast = cm.reflectance_to_XYZ(R, wavelength_nm, method=method)
    slow = reference_XYZ(R, wavelength_nm, cm.DEFAULT_OBSERVER, cm.DEFAULT_ILLUMINANT, method)
    np.testing.assert_allclose(fast, slow, rtol=0, atol=SD_TO_XYZ_TOL)


@pytest.mark.parametrize(
    ("observer", "illuminant"),
    [("CIE 1931 2 Degree Standard Observer", "A"), ("CIE 1964 10 Degree Standard Observer", "D50")],
)
def test_other_observer_and_illuminant_equal_sd_to_XYZ(observer, illuminant, rng):
    R = smooth_spectra(GRID_10NM, 3, rng)
    fast = cm.reflectance_to_XYZ(R, GRID_10NM, observer=observer, illuminant=illuminant)
    slow = reference_XYZ(R, GRID_10NM, observer, illuminant, "ASTM E308")
    np.testing.assert_allclose(fast, slow, rtol=0, atol=SD_TO_XYZ_TOL)
    default = cm.reflectance_to_XYZ(R, GRID_10NM)
    assert np.abs(fast - default).max() > 1e-3  # the choice matters


def test_auto_method_is_what_sd_to_XYZ_would_accept():
    assert cm.colorimetric_metadata(GRID_10NM)["method"] == "ASTM E308"
    assert cm.colorimetric_metadata(GRIDS["irregular"][0])["method"] == "Integration"
    assert cm.colorimetric_metadata(np.arange(405.0, 706.0, 10.0))["method"] == "Integration"


def test_white_point_matches_cie_tabulated_chromaticity():
    for observer in ("CIE 1931 2 Degree Standard Observer", "CIE 1964 10 Degree Standard Observer"):
        white = cm.white_point_XYZ(observer=observer, illuminant="D65")
        assert white[1] == pytest.approx(1.0, abs=1e-12)
        xy_cie = colour.CCS_ILLUMINANTS[observer]["D65"]
        np.testing.assert_allclose(white[:2] / white.sum(), xy_cie, atol=CIE_WHITE_XY_TOL)


def test_perfect_white_and_black():
    XYZ = cm.reflectance_to_XYZ(np.ones(GRID_10NM.size), GRID_10NM)
    assert XYZ[1] == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(
        cm.reflectance_to_Lab(np.ones(31), GRID_10NM), [100, 0, 0], atol=LAB_TOL
    )
    np.testing.assert_allclose(
        cm.reflectance_to_Lab(np.zeros(31), GRID_10NM), [0, 0, 0], atol=LAB_TOL
    )


def test_grey_has_no_chroma_and_cie_lightness():
    # Y = 0.18 exactly for a flat 18 % grey; CIE L* = 116 * 0.18^(1/3) - 16 = 49.496...
    Lab = cm.reflectance_to_Lab(np.full(31, 0.18), GRID_10NM)
    assert Lab[0] == pytest.approx(116.0 * 0.18 ** (1.0 / 3.0) - 16.0, abs=1e-9)
    np.testing.assert_allclose(Lab[1:], 0.0, atol=LAB_TOL)


def test_XYZ_to_Lab_matches_colour_with_tabulated_white(rng):
    XYZ = cm.reflectance_to_XYZ(smooth_spectra(GRID_10NM, 5, rng), GRID_10NM)
    xy = colour.CCS_ILLUMINANTS[cm.DEFAULT_OBSERVER]["D65"]
    # The default white (1 nm integration) and the CIE-tabulated xy agree to 1e-5,
    # so Lab agrees to a few 1e-3.
    np.testing.assert_allclose(cm.XYZ_to_Lab(XYZ), colour.XYZ_to_Lab(XYZ, xy), atol=5e-3)


def test_broadcasting_over_leading_axes(rng):
    R = smooth_spectra(GRID_10NM, 24, rng).reshape(2, 3, 4, 31)
    XYZ = cm.reflectance_to_XYZ(R, GRID_10NM)
    Lab = cm.reflectance_to_Lab(R, GRID_10NM)
    assert XYZ.shape == Lab.shape == (2, 3, 4, 3)
    np.testing.assert_allclose(Lab[1, 2, 3], cm.reflectance_to_Lab(R[1, 2, 3], GRID_10NM))
    dE = cm.delta_E2000(Lab, Lab[0, 0, 0])
    assert dE.shape == (2, 3, 4)
    assert dE[0, 0, 0] == 0.0


def test_weighting_matrix_is_cached_and_read_only():
    W1 = cm.weighting_matrix(GRID_10NM)
    W2 = cm.weighting_matrix(list(GRID_10NM))
    assert W1 is W2
    with pytest.raises(ValueError, match="read-only"):
        W1[0, 0] = 1.0


# Sharma, Wu & Dalal (2005), Table 1: (L1, a1, b1), (L2, a2, b2), Delta E 2000.
SHARMA_2005 = [
    ((50.0000, 2.6772, -79.7751), (50.0000, 0.0000, -82.7485), 2.0425),
    ((50.0000, -1.3802, -84.2814), (50.0000, 0.0000, -82.7485), 1.0000),
    ((50.0000, 0.0000, 0.0000), (50.0000, -1.0000, 2.0000), 2.3669),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0009), 7.1792),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0011), 7.2195),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0011, -2.4900), 4.7461),
    ((50.0000, 2.5000, 0.0000), (73.0000, 25.0000, -18.0000), 27.1492),
    ((50.0000, 2.5000, 0.0000), (56.0000, -27.0000, -3.0000), 31.9030),
    ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
    ((22.7233, 20.0904, -46.6940), (23.0331, 14.9730, -42.5619), 2.0373),
    ((90.8027, -2.0831, 1.4410), (91.1528, -1.6435, 0.0447), 1.4441),
    ((2.0776, 0.0795, -1.1350), (0.9033, -0.0636, -0.5514), 0.9082),
]


def test_delta_E2000_sharma_table():
    Lab_1 = np.array([row[0] for row in SHARMA_2005])
    Lab_2 = np.array([row[1] for row in SHARMA_2005])
    expected = np.array([row[2] for row in SHARMA_2005])
    np.testing.assert_allclose(cm.delta_E2000(Lab_1, Lab_2), expected, atol=SHARMA_TOL)
    np.testing.assert_allclose(cm.delta_E2000(Lab_2, Lab_1), expected, atol=SHARMA_TOL)


def test_results_ignore_colour_domain_range_scale(rng):
    R = smooth_spectra(GRID_10NM, 2, rng)
    expected = cm.reflectance_to_Lab(R, GRID_10NM)
    with colour.domain_range_scale("1"):
        np.testing.assert_allclose(cm.reflectance_to_Lab(R, GRID_10NM), expected)
        Lab = np.array(SHARMA_2005[0][:2])
        assert cm.delta_E2000(Lab[0], Lab[1]) == pytest.approx(2.0425, abs=SHARMA_TOL)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"reflectance": np.full(30, 0.5)}, "reflectance"),
        ({"reflectance": np.r_[np.nan, np.full(30, 0.5)]}, "reflectance"),
        ({"reflectance": np.r_[-0.1, np.full(30, 0.5)]}, "reflectance"),
        ({"wavelength_nm": GRID_10NM[::-1]}, "wavelength_nm"),
        ({"wavelength_nm": np.r_[GRID_10NM[:-1], np.nan]}, "wavelength_nm"),
        ({"wavelength_nm": np.arange(1000.0, 1310.0, 10.0)}, "wavelength_nm"),
        ({"observer": "CIE 1931 3 Degree"}, "CIE 1964 10 Degree Standard Observer"),
        ({"illuminant": "D66"}, "D65"),
        ({"method": "ASTM E309"}, "Integration"),
        ({"wavelength_nm": np.arange(405.0, 706.0, 10.0), "method": "ASTM E308"}, "Integration"),
    ],
)
def test_bad_input_raises(kwargs, match):
    arguments = {"reflectance": np.full(31, 0.5), "wavelength_nm": GRID_10NM} | kwargs
    reflectance = arguments.pop("reflectance")
    wavelength_nm = arguments.pop("wavelength_nm")
    with pytest.raises(ValueError, match=match):
        cm.reflectance_to_XYZ(reflectance, wavelength_nm, **arguments)


def test_small_negative_reflectance_is_accepted():
    R = np.full(31, 0.02)
    R[0] = -0.5 * cm.NEGATIVE_REFLECTANCE_TOLERANCE
    assert np.isfinite(cm.reflectance_to_Lab(R, GRID_10NM)).all()


def test_bad_Lab_input_raises():
    with pytest.raises(ValueError, match="Lab_1"):
        cm.delta_E2000([50.0, 0.0], [50.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="Lab_2"):
        cm.delta_E2000([50.0, 0.0, 0.0], [np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="broadcast"):
        cm.delta_E2000(np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="white_XYZ"):
        cm.XYZ_to_Lab([0.2, 0.2, 0.2], white_XYZ=[0.95, 0.0, 1.08])
