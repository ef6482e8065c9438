"""Reports of gonio BRDF sets with many geometries: summaries instead of per-geometry listings.

A simulated opaque paint measured at 68 BRDF geometries (four incidence angles, in and out of
the plane of incidence) goes through :func:`bayespig.infer` (eps known, quick settings) and
:func:`bayespig.report.write_report`; a set at the six geometries of a multi-angle instrument
keeps the per-geometry tables and figures.
"""

import csv
import io

import numpy as np
import pytest

import bayespig
from bayespig.demo import QUICK_SETTINGS
from bayespig.inference.settings import InferenceSettings
from bayespig.report.write import write_report

#: Bands of the simulated sets [nm] (colorimetry needs >= 6).
WAVELENGTHS_NM = np.linspace(400.0, 700.0, 6)
TRUE_A = np.linspace(0.05, 0.5, 6)
#: Relative measurement error of the simulated sets [-], given to infer as known.
EPS = 0.03
INCIDENCES_DEG = (15.0, 30.0, 45.0, 60.0)
VIEWING_DEG = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0)
#: The median |relative residual| of a correct fit is ~0.674 eps (half-normal median); the
#: fitted curve's own error and 68 values per band put it within a factor of 2 of that.
MEDIAN_RESIDUAL_RANGE = (0.674 * EPS / 2.0, 0.674 * EPS * 2.0)
#: A report of 68 geometries has about as many lines as one of 6 (~220): listing the geometries
#: in the fit, colour and provenance would add >= 3 x 68.
MAX_REPORT_LINES = 260
#: The CSV writes the mirror distance with 4 decimals [deg]: half a unit of the last one.
MIRROR_ANGLE_TOL_DEG = 5e-5 + 1e-9


def _gonio_geometries():
    """(theta_i, theta_o, delta_phi) [deg] in the plane (both sides) and at delta_phi = 90."""
    geometries = []
    for theta_i in INCIDENCES_DEG:
        for theta_o in VIEWING_DEG:
            for delta_phi in (0.0, 180.0):
                if theta_o == 0.0 and delta_phi == 0.0:
                    continue  # the same direction as delta_phi = 180
                if theta_o == theta_i and delta_phi == 180.0:
                    theta_o += 3.0  # the mirror direction itself has no model value (and 2° is a class edge)
                geometries.append((theta_i, theta_o, delta_phi))
        geometries += [(theta_i, 30.0, 90.0), (theta_i, 60.0, 90.0)]
    return geometries


def _mirror_angle_deg(theta_i, theta_o, delta_phi):
    """Angle between the viewing direction and the mirror image of the source, by arccos [deg]."""
    ti, to, dp = np.radians(theta_i), np.radians(theta_o), np.radians(delta_phi)
    cosine = np.cos(ti) * np.cos(to) - np.sin(ti) * np.sin(to) * np.cos(dp)
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))


def _report(folder, instrument):
    ms = bayespig.simulate(a=TRUE_A, tau=1.0, design=[{"name": "paint", "opaque": True}], instrument=instrument,
                           wavelengths=WAVELENGTHS_NM, eps=EPS, seed=2)
    idata = bayespig.infer(ms, eps=EPS, progress=False, seed=1, settings=InferenceSettings(**QUICK_SETTINGS))
    write_report(idata, folder, measurements=ms)
    return folder


@pytest.fixture(scope="module")
def large(tmp_path_factory):
    return _report(tmp_path_factory.mktemp("gonio") / "report", _gonio_geometries())


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    return _report(tmp_path_factory.mktemp("multi_angle") / "report", "multi-angle-45")


OLD_FIT_HEADER = r"| sample | geometry | rms residual \[eps\] | max \|residual\| \[eps\] |"
OLD_COLOUR_HEADER = (r"| sample | geometry | L\* a\* b\* measured | L\* a\* b\* predicted | dE00 meas-pred | "
                     "dE00 spread (95 %) |")


def test_large_gonio_set_has_the_summary_figures_and_not_the_per_geometry_ones(large):
    figures = {p.name for p in (large / "figures").iterdir()}
    assert {"fit_plane.png", "residual_map.png"} <= figures
    assert not figures & {"fit.png", "residuals.png", "colour_measured.png"}
    markdown = (large / "report.md").read_text()
    assert OLD_FIT_HEADER not in markdown and OLD_COLOUR_HEADER not in markdown
    assert "- Samples: paint (opaque; 68 BRDF geometries at incidence 15, 30, 45, 60°)" in markdown
    assert ("68 BRDF geometries: too many to list, so the fit is shown in the plane of incidence, as a map "
            "over viewing directions and as statistics by distance from the mirror; every geometry's "
            r"residuals are in fit\_by\_geometry.csv.") in markdown
    # predicted colours at a few in-plane geometries at 45°, not at all 68
    assert ("Predicted at 3 of the measured geometries (in the plane of incidence, nearest 45° incidence, "
            "at aspecular angles near 15, 45, 110°).") in markdown
    assert "at the geometries 45as15, 45as45, 45as105." in markdown
    assert '"sample:paint": "68 geometries (listed in summary.json and fit_by_geometry.csv)"' in markdown
    assert len(markdown.splitlines()) < MAX_REPORT_LINES


def test_residual_table_by_distance_from_the_mirror(large):
    distances = [_mirror_angle_deg(*g) for g in _gonio_geometries()]
    counts = [sum(d < 2 for d in distances), sum(2 <= d < 10 for d in distances),
              sum(10 <= d < 30 for d in distances), sum(d >= 30 for d in distances)]
    assert sum(counts) == 68 and counts[0] == 0 and min(counts[1:]) > 0
    lines = (large / "report.md").read_text().splitlines()
    heading = lines.index("### Residuals by distance from the mirror")
    header = (rf"| wavelength \[nm\] | all (68 geometries) | &lt; 2° ({counts[0]} geometries) | "
              rf"2-10° ({counts[1]} geometries) | 10-30° ({counts[2]} geometries) | "
              rf"&gt;= 30° ({counts[3]} geometries) |")
    start = lines.index(header)
    assert start > heading
    rows = [line.strip("|").split("|") for line in lines[start + 2:start + 2 + WAVELENGTHS_NM.size]]
    assert [r[0].strip() for r in rows] == [f"{w:g}" for w in WAVELENGTHS_NM]
    for row in rows:
        assert row[2].strip() == "n/a"  # no geometry within 2° of the mirror
        for cell in (row[1], *row[3:]):
            value = float(cell.strip().removesuffix(" %")) / 100.0
            assert MEDIAN_RESIDUAL_RANGE[0] < value < MEDIAN_RESIDUAL_RANGE[1], row


def test_per_geometry_listing_is_in_the_csv(large):
    rows = list(csv.DictReader(io.StringIO((large / "fit_by_geometry.csv").read_text())))
    assert len(rows) == 68
    for row, geometry in zip(sorted(rows, key=lambda r: (float(r["theta_i_deg"]), float(r["theta_o_deg"]),
                                                          float(r["delta_phi_deg"]))),
                             sorted(_gonio_geometries())):
        assert (float(row["theta_i_deg"]), float(row["theta_o_deg"]), float(row["delta_phi_deg"])) == geometry
        assert float(row["mirror_distance_deg"]) == pytest.approx(_mirror_angle_deg(*geometry), abs=MIRROR_ANGLE_TOL_DEG)
    colour = list(csv.DictReader(io.StringIO((large / "colour_by_geometry.csv").read_text())))
    assert len(colour) == 68


def test_small_set_keeps_the_per_geometry_tables_and_figures(small):
    figures = {p.name for p in (small / "figures").iterdir()}
    assert {"fit.png", "residuals.png", "colour_measured.png"} <= figures
    assert not figures & {"fit_plane.png", "residual_map.png"}
    markdown = (small / "report.md").read_text()
    assert OLD_FIT_HEADER in markdown and OLD_COLOUR_HEADER in markdown
    assert "### Residuals by distance from the mirror" not in markdown
    assert "- Samples: paint (opaque; 45as-15, 45as15, 45as25, 45as45, 45as75, 45as110)" in markdown
    assert '"45as-15",' in markdown  # the provenance lists a few geometries


def test_signed_viewing_angle_and_mirror_distance_of_value_rows():
    """In-plane rows (delta_phi 0, 180 and 180 less a rounding of pi in radians) get a signed viewing angle."""
    from bayespig.report.quantities import gonio_values, is_large_gonio_set

    rows = [{"sample": "s", "channel": label, "kind": "brdf", "film_group": ""}
            for label in ("45/30/180", "45/30/0", "45/60/90", "45/0/0", "30/20/179.99998")]
    rows.append({"sample": "s", "channel": "8d-sce", "kind": "hemispherical", "film_group": ""})
    geometry = gonio_values(rows)
    assert list(geometry["index"]) == [0, 1, 2, 3, 4]
    signed = geometry["signed_theta_o"]
    assert signed[0] == 30.0 and signed[1] == -30.0 and np.isnan(signed[2]) and signed[3] == 0.0
    assert signed[4] == pytest.approx(20.0)
    expected = [_mirror_angle_deg(*g) for g in ((45, 30, 180), (45, 30, 0), (45, 60, 90), (45, 0, 0),
                                                   (30, 20, 179.99998))]
    assert geometry["mirror_distance_deg"] == pytest.approx(expected, abs=1e-9)
    assert not is_large_gonio_set(rows) and is_large_gonio_set(rows, threshold=4)


def test_gonio_figures_have_one_panel_per_incidence_with_labelled_axes():
    """Eight incidences are shown as six spread over them; log BRDF axis in 1/sr."""
    from bayespig.report.figures import plane_of_incidence_figure, residual_map_figure
    from bayespig.report.quantities import gonio_residual_summary

    incidences = (10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0)
    labels = [f"{ti:g}/{to:g}/{dp:g}" for ti in incidences for to in (5.0, 25.0, 45.0) for dp in (0.0, 180.0)]
    rows = [{"sample": "s", "channel": label, "kind": "brdf", "film_group": ""} for label in labels]
    rng = np.random.default_rng(0)
    draws = 0.05 * (1.0 + 0.01 * rng.standard_normal((20, 3, len(rows))))
    gonio = gonio_residual_summary({"rows": rows, "predicted_draws": draws,
                                    "observed": np.median(draws, axis=0) * 1.1})
    assert gonio["relative"] == pytest.approx(np.full((3, len(rows)), 0.1), rel=1e-12)  # fitted: the median
    shown = [10.0, 20.0, 40.0, 50.0, 70.0, 80.0]
    fig = plane_of_incidence_figure(np.array([400.0, 550.0, 700.0]), gonio, [0, 2], shown)
    panels = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title() for ax in panels] == [f"incidence {t:g}° (6 in-plane geometries)" for t in shown]
    assert {ax.get_xlabel() for ax in panels} == {"signed viewing angle [deg] (+ specular side)"}
    assert [ax.get_ylabel() for ax in panels if ax.get_ylabel()] == ["BRDF [1/sr]", "BRDF [1/sr]"]
    assert {ax.get_yscale() for ax in panels} == {"log"}
    assert [t.get_text() for t in fig.legends[0].get_texts()] == [
        "400 nm fit", "400 nm measured", "700 nm fit", "700 nm measured", "mirror direction"]
    polar = residual_map_figure(gonio, shown)
    assert [ax.get_title() for ax in polar.axes if ax.name == "polar"] == [f"incidence {t:g}°" for t in shown]


def test_beyond_surface_lobe_is_the_reading_less_walters_lobe_per_mirror_distance_class():
    """Readings made of Walter's lobe plus a known remainder per class give that remainder back;
    grazing geometries (theta > 60 deg) and empty classes are left out."""
    from bayespig.physics.forward import first_surface_brdf
    from bayespig.report.quantities import (
        BEYOND_LOBE_BINS_DEG,
        beyond_surface_lobe,
        gonio_residual_summary,
        gonio_values,
    )

    angles = [(ti, to, dp) for ti in (10.0, 30.0, 50.0, 70.0) for to in (0.0, 15.0, 35.0, 55.0, 75.0)
              for dp in (0.0, 180.0)]
    rows = [{"sample": "s", "channel": f"{ti:g}/{to:g}/{dp:g}", "kind": "brdf", "film_group": ""}
            for ti, to, dp in angles]
    geometry = gonio_values(rows)
    ti, to, dp = (np.array(v) for v in zip(*angles))
    lobe = first_surface_brdf(ti, to, dp, roughness=0.2, n=1.5)
    bins = np.asarray(BEYOND_LOBE_BINS_DEG)
    classes = np.searchsorted(bins, geometry["mirror_distance_deg"], side="left") - 1  # (low, high]
    remainder = np.array([[0.01], [0.05]]) * (1.0 + classes)  # two bands; one value per class
    measured = lobe + remainder
    fitted = lobe + 0.5 * remainder
    gonio = gonio_residual_summary({"rows": rows, "predicted_draws": np.broadcast_to(fitted, (3,) + fitted.shape),
                                    "observed": measured})
    beyond = beyond_surface_lobe(gonio, roughness=0.2, binder_index=1.5)
    keep = (ti <= 60.0) & (to <= 60.0) & (geometry["mirror_distance_deg"] > bins[0])
    for c, label in enumerate(beyond["classes"]):
        member = keep & (classes == c)
        assert beyond["count"][c] == int(member.sum())
        if member.any():
            assert beyond["measured"][:, c] == pytest.approx([0.01 * (1 + c), 0.05 * (1 + c)], rel=1e-9)
            assert beyond["fitted"][:, c] == pytest.approx([0.005 * (1 + c), 0.025 * (1 + c)], rel=1e-9)
        else:
            assert np.isnan(beyond["measured"][:, c]).all()
    assert sum(beyond["count"]) == int(keep.sum()) < len(rows)  # grazing and near-mirror rows left out
    assert beyond["classes"][0] == "2-10°"
