"""The Cornell study (bayespig.studies.cornell): subset logic, a tiny run, the report's structure."""

import argparse
import os
import re

import numpy as np
import pytest

from bayespig.commands.cornell import add_cornell_parser, cornell_folder
from bayespig.data import MeasurementError, read_measurements
from bayespig.inference import InferenceSettings
from bayespig.selection import mirror_distance_deg, select_measurements
from bayespig.studies.cornell import (
    MIRROR_CUT_DEG,
    SUBSET_MAX_ANGLE_DEG,
    SUBSET_SPLIT_DEG,
    CornellStudySettings,
    cornell_study,
    default_cornell_path,
    interval_overlap,
    mirror_band_subset,
    overlap_goal,
    study_sets,
    write_cornell_report,
)

CORNELL = default_cornell_path()
needs_cornell = pytest.mark.skipif(not (CORNELL / "garnet_red.astm").exists(),
                                   reason=f"Cornell data not found at {CORNELL} (set BAYESPIG_CORNELL)")
#: The tiny run: one incidence (about 10 distinct viewing angles for the rough table), two
#: bands, short chains: it checks the study's plumbing and report, not its numbers.
TINY = CornellStudySettings(
    full_bands=(450.0, 650.0), subset_bands=(450.0, 650.0), smooth_bands=(650.0,), incidences_deg=(30.0,),
    max_geometries=60, binder_index=None,
    inference=InferenceSettings(n_walkers=16, n_ensembles=2, draws_per_chain=32, target_ess=10, min_steps=50,
                                max_steps=80, check_interval=40))


def test_interval_overlap_on_constructed_intervals():
    first = np.array([[0.10, 0.10, 0.10, 0.50, 0.30],
                      [0.20, 0.20, 0.20, 0.60, 0.40]])
    second = np.array([[0.15, 0.20, 0.21, 0.10, 0.32],
                       [0.30, 0.30, 0.30, 0.49, 0.35]])
    # partial overlap, touching ends, disjoint above, disjoint below, one inside the other
    assert interval_overlap(first, second).tolist() == [True, True, False, False, True]
    assert interval_overlap(second, first).tolist() == [True, True, False, False, True]


def test_overlap_goal_counts_only_bands_where_both_runs_mixed():
    """Ten bands, nine overlapping; the near run did not mix at three of them: 6 of 10 count, the
    90 % goal is not met although 90 % of the intervals overlap."""
    overlap = np.array([True] * 9 + [False])
    far = {"a_mixed": np.ones(10, dtype=bool)}
    near = {"a_mixed": np.array([True] * 6 + [False] * 3 + [True])}
    goal = overlap_goal({"overlap": overlap, "far": far, "near": near})
    assert goal == {"bands": 10, "overlapping": 9, "mixed": 7, "counted": 6, "share": 0.6, "met": False}
    # both runs mixed everywhere: the goal is the plain overlap share
    goal = overlap_goal({"overlap": overlap, "far": far, "near": far})
    assert goal["counted"] == 9 and goal["share"] == 0.9 and goal["met"]
    with pytest.raises(ValueError, match=r"the far subset run's a_mixed has shape \(9,\), the overlap \(10,\)"):
        overlap_goal({"overlap": overlap, "far": {"a_mixed": np.ones(9, dtype=bool)}, "near": far})


def test_interval_overlap_refuses_mismatched_shapes():
    with pytest.raises(ValueError, match=r"first and second must both have shape \(2, n_bands\), "
                                         r"got \(2, 3\) and \(2, 2\)"):
        interval_overlap(np.zeros((2, 3)), np.zeros((2, 2)))


def test_missing_folder_is_one_plain_error(tmp_path):
    missing = tmp_path / "nowhere"
    with pytest.raises(MeasurementError, match=r"file not found \(the folder given\)\. The Cornell data are"):
        cornell_folder(missing)


def test_cli_registers_cornell():
    parser = argparse.ArgumentParser()
    add_cornell_parser(parser.add_subparsers())
    args = parser.parse_args(["cornell", "--subset-bands", "450", "650", "--max-steps", "100"])
    assert args.subset_bands == [450.0, 650.0] and args.max_steps == 100 and args.report == "reports/cornell.md"


@needs_cornell
def test_subsets_split_the_geometries_by_mirror_distance():
    measurements = read_measurements(CORNELL / "garnet_red.astm", opaque=True)
    far = select_measurements(measurements, exclude_mirror_deg=SUBSET_SPLIT_DEG, max_angle_deg=SUBSET_MAX_ANGLE_DEG)
    near = mirror_band_subset(measurements, MIRROR_CUT_DEG, SUBSET_SPLIT_DEG, SUBSET_MAX_ANGLE_DEG)

    def distances(m):
        return np.array([mirror_distance_deg(x.theta_i, x.theta_o, x.delta_phi) for x in m.films[0].measurements])

    assert np.all(distances(far) > SUBSET_SPLIT_DEG)
    assert np.all((distances(near) > MIRROR_CUT_DEG) & (distances(near) <= SUBSET_SPLIT_DEG))
    every = [x for x in measurements.films[0].measurements
             if max(x.theta_i, x.theta_o) <= SUBSET_MAX_ANGLE_DEG
             and mirror_distance_deg(x.theta_i, x.theta_o, x.delta_phi) > MIRROR_CUT_DEG]
    assert len(far.films[0].measurements) + len(near.films[0].measurements) == len(every)


@pytest.fixture(scope="module")
def tiny_study():
    if not (CORNELL / "garnet_red.astm").exists():
        pytest.skip(f"Cornell data not found at {CORNELL} (set BAYESPIG_CORNELL)")
    return cornell_study(CORNELL, settings=TINY, paints=["garnet_red"])


def test_tiny_study_report_structure(tiny_study, tmp_path):
    result = tiny_study["paints"]["garnet_red"]
    assert result["full"]["wavelength_nm"].tolist() == [450.0, 650.0]
    assert result["smooth"]["roughness"] is None  # roughness 0: no roughness parameter
    assert 0.01 <= result["full"]["roughness"][1] <= 1.0
    expected = interval_overlap(result["far"]["a"][[0, 2]], result["near"]["a"][[0, 2]])
    assert result["overlap"].tolist() == expected.tolist()

    path = write_cornell_report(tiny_study, tmp_path / "cornell.md")
    text = path.read_text()
    assert text.splitlines()[0] == "# Cornell gonio paints: rough-surface fits (issue 16)"
    assert "    bayespig cornell" in text
    for heading in ("## Summary of the goals", "### Goals", "### Subset consistency", "### Prior-edge flags",
                    "### Smooth surface (roughness 0) for comparison"):
        assert heading in text
    for figure in re.findall(r"!\[[^]]*\]\(([^)]+)\)", text):
        assert (tmp_path / figure).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert {p.name for p in (tmp_path / "cornell").iterdir()} == {
        "garnet_red_a.png", "garnet_red_plane.png", "garnet_red_residual_map.png"}
    # the subset table says "yes" exactly where the recomputed intervals overlap
    table = text.split("### Subset consistency")[1].split("###")[0]
    said = [cells.split("|")[4].strip() == "yes" for cells in table.splitlines() if re.match(r"\| \d", cells)]
    assert said == expected.tolist()
    # the mixing column is the fits' own R-hat / ESS verdict on a, and the goal line counts the
    # overlaps that rest on a run whose a did not mix
    mixed = [tuple(c.strip() for c in cells.split("|")[5].split("/")) for cells in table.splitlines()
             if re.match(r"\| \d", cells)]
    assert mixed == [tuple("yes" if result[fit]["a_mixed"][k] else "**no**" for fit in ("far", "near"))
                     for k in range(2)]
    goal = overlap_goal(result)
    verdict = "met" if goal["met"] else "NOT met"
    assert f"both runs mixed: **{verdict}** ({goal['counted']} of 2 bands overlap with both runs' a mixed" in text
    assert f"{verdict} | " in text.split("## Summary of the goals")[1]
    n = int(expected.sum())
    if goal["mixed"] < 2:  # the plain count of overlaps beside the converged one
        assert f"counting the runs that did not mix, {n} of 2 intervals overlap" in text
    # the data folder is shown as the user would type it, never the machine's absolute path
    assert f"Data: `{os.path.relpath(CORNELL)}`" in text
    assert "Light beyond the surface lobe (full fit)" in text


def test_cli_prints_the_converged_overlap_count(tiny_study, tmp_path, monkeypatch, capsys):
    """``bayespig cornell``'s last line counts the overlaps as the report's goal does (both runs
    mixed), with the plain count beside it (the study itself is the module's tiny one)."""
    import bayespig.studies.cornell as cornell

    monkeypatch.setattr(cornell, "cornell_study", lambda *args, **kwargs: tiny_study)
    parser = argparse.ArgumentParser()
    add_cornell_parser(parser.add_subparsers())
    args = parser.parse_args(["cornell", str(CORNELL), "--report", str(tmp_path / "cornell.md"), "--quiet"])
    assert args.func(args) == 0
    goal = overlap_goal(tiny_study["paints"]["garnet_red"])
    assert (f"subset overlap with both runs mixed at {goal['counted']} of 2 bands ({goal['overlapping']} counting "
            "unmixed runs)") in capsys.readouterr().out
    assert (tmp_path / "cornell.md").exists()


def test_the_paints_fitted_at_once_give_the_same_study(tiny_study):
    """Two paints on two workers: each paint's fits equal its serial fit alone (the garnet red's
    is the module's tiny study), so a paint's draws do not depend on what else is fitted."""
    if not (CORNELL / "krylon_blue.astm").exists():
        pytest.skip(f"Cornell data not found at {CORNELL} (set BAYESPIG_CORNELL)")
    serial = {**tiny_study["paints"], **cornell_study(CORNELL, settings=TINY, paints=["krylon_blue"])["paints"]}
    parallel = cornell_study(CORNELL, settings=TINY, jobs=2)
    assert list(parallel["paints"]) == list(serial) == ["garnet_red", "krylon_blue"]
    for paint, result in serial.items():
        for fit in ("full", "no_flakes", "far", "near", "smooth"):
            np.testing.assert_array_equal(parallel["paints"][paint][fit]["a"], result[fit]["a"])
        np.testing.assert_array_equal(parallel["paints"][paint]["full"]["flake_reflectance"],
                                      result["full"]["flake_reflectance"])


def test_the_report_gives_the_flakes_and_the_fit_without_them(tiny_study, tmp_path):
    text = write_cornell_report(tiny_study, tmp_path / "cornell.md").read_text()
    full = tiny_study["paints"]["garnet_red"]["full"]
    assert full["flake_roughness"] is not None and full["flake_reflectance"].shape == (3, 2)
    assert "**flake roughness: " in text
    assert "| flake reflectance c |" in text and "| residual without flakes |" in text
    assert "Without flakes (the same fit, the surface alone): roughness " in text


@pytest.mark.parametrize("jobs", [0, -1, 1.5, True])
def test_bad_jobs_are_refused(jobs):
    with pytest.raises(ValueError, match=f"jobs must be a positive integer, got {jobs!r}"):
        cornell_study(CORNELL, settings=TINY, jobs=jobs)


@needs_cornell
def test_every_fit_leaves_out_the_occluded_geometries():
    ms = read_measurements(CORNELL / "krylon_blue.astm", opaque=True)
    occluded, full, far, near = study_sets(ms, CornellStudySettings())
    assert occluded == ["80/79.0472/160", "80/79.0472/165", "80/79.0472/170"]
    labels = {m.label for m in full.films[0].measurements}
    assert not labels & set(occluded)
    kept_all = study_sets(ms, CornellStudySettings(exclude_occluded=False))
    assert kept_all[0] == [] and len(kept_all[1].films[0].measurements) == len(full.films[0].measurements) + 3
    # the subsets (theta <= 60°) never held them
    assert len(kept_all[2].films[0].measurements) == len(far.films[0].measurements)
    assert len(kept_all[3].films[0].measurements) == len(near.films[0].measurements)
