"""ASTM E1392 files as real gonioreflectometers write them: SAMPLE_NAME, no OPAQUE/SUBSTRATE
keyword, exact zeros, rows near the mirror direction, gloss values; ``bayespig check`` on them
and on the Cornell measurements (``../shared/data/cornell``, skipped when absent)."""

import math
import os
from pathlib import Path

import pytest

from bayespig import read_measurements
from bayespig.cli import main
from bayespig.data import MeasurementError


def _cornell_folder():
    if os.environ.get("BAYESPIG_CORNELL"):
        return Path(os.environ["BAYESPIG_CORNELL"])
    root = Path(__file__).resolve().parents[2]
    for base in (root.parent, root.parent.parent):
        if (base / "shared" / "data" / "cornell").is_dir():
            return base / "shared" / "data" / "cornell"
    return root.parent / "shared" / "data" / "cornell"


CORNELL = _cornell_folder()
GARNET = CORNELL / "garnet_red.astm"
needs_cornell = pytest.mark.skipif(not GARNET.exists(),
                                   reason=f"Cornell data not found at {CORNELL} (set BAYESPIG_CORNELL)")

D = math.radians
#: Rows of the synthetic file: (theta_i, phi_i, theta_s, phi_s) [rad], then BRDFs at 400, 500 nm.
ROWS = [
    (D(45), 0, D(30), math.pi, 0.0123, 0.0145),          # line 4
    (D(45), 0, D(45.3), math.pi, 12.5, 0.0139),          # line 5: 0.3° from the mirror, gloss
    (D(30), 0, D(60), math.pi / 2, 0.0, 0.0141),         # line 6: a zero at 400 nm
]


def _write(tmp_path, header="SAMPLE_NAME Test Red\n"):
    path = tmp_path / "red.astm"
    body = "\n".join(",".join(f"{x:.6f}" for x in row) for row in ROWS)
    path.write_text(f"#FORMAT=ASTM-E1392-96\n{header}VARS theta_i,phi_i,theta_s,phi_s,400nm,500nm\n{body}\n")
    return path


def test_sample_name_and_opaque_from_the_api(tmp_path):
    path = _write(tmp_path)
    ms = read_measurements(path, opaque=True)
    assert ms.sample_names == ("Test Red",) or list(ms.sample_names) == ["Test Red"]
    assert ms.sample("Test Red").opaque
    on_white = read_measurements(path, substrate="white")
    assert on_white.sample("Test Red").substrate == "white" and not on_white.sample("Test Red").opaque


def test_argument_wins_over_the_keyword(tmp_path):
    path = _write(tmp_path, "SAMPLE_NAME Test Red\nOPAQUE no\nSUBSTRATE black\n")
    assert not read_measurements(path).sample("Test Red").opaque
    assert read_measurements(path, opaque=True).sample("Test Red").opaque
    assert read_measurements(path, substrate=0.5).sample("Test Red").substrate == 0.5


def test_opaque_refused_for_csv_and_bad_types(tmp_path):
    path = _write(tmp_path)
    with pytest.raises(TypeError, match=r"^opaque must be True, False or None, got 'yes'$"):
        read_measurements(path, opaque="yes")
    csv = tmp_path / "f.csv"
    read_measurements(path, opaque=True).to_csv(csv)
    with pytest.raises(ValueError) as info:
        read_measurements(csv, opaque=True)
    assert str(info.value) == ("opaque= applies to ASTM E1392 files, whose header has no standard keyword for it; "
                               "a csv file states it per sample (its opaque column)")


def test_no_opaque_keyword_one_error(tmp_path, capsys):
    path = _write(tmp_path)
    with pytest.raises(MeasurementError) as info:
        read_measurements(path)
    assert len(info.value.problems) == 1
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert err == (f"bayespig: error: {path}, field 'OPAQUE': the header says neither OPAQUE nor SUBSTRATE "
                   "(ASTM E1392 has no keyword for them): say whether the film hides its substrate with "
                   "opaque=True (--opaque on the command line) or give substrate='black', 'white' or an "
                   "albedo (--substrate), or add the header line 'OPAQUE yes' or 'SUBSTRATE black'\n")


def test_check_reports_mirror_gloss_zeros_and_refusal(tmp_path, capsys):
    path = _write(tmp_path)
    assert main(["check", str(path), "--opaque"]) == 1
    out = capsys.readouterr().out
    assert out.startswith(f"{path}: astm e1392 file, readable, but not valid for infer as it stands\n")
    assert "valid\n" not in out.splitlines()[0] + "\n"
    findings = out.split("findings:\n", 1)[1].splitlines()
    assert findings[0] == ("  1 BRDF geometry within 5° of the mirror direction (closest 0.3°, 45as-0.3): the "
                           "surface's gloss dominates there; --exclude-mirror 5 leaves them out (row 5)")
    assert findings[1] == ("  1 BRDF value above 10 1/sr, implausible for a paint's body (a white Lambertian "
                           "surface gives 0.32 1/sr): gloss; the largest 12.5 1/sr at 400 nm, 45as-0.3 (row 5)")
    assert findings[2] == "  1 exact zero in 1 geometry; per band: 400 nm 1 (row 6)"
    assert findings[3].startswith(f"  infer refuses it as it stands: {path}, row 6: film 'Test Red': observed "
                                  "value 0 at 400 nm, geometry 30/60/90 ")
    assert "(--noise-floor on the command line) to take zeros as data" in findings[3]


def test_check_clean_file_is_valid(tmp_path, capsys):
    path = tmp_path / "clean.astm"
    path.write_text("#FORMAT=ASTM-E1392-96\nSAMPLE_NAME Clean\nVARS theta_i,phi_i,theta_s,phi_s,400nm,500nm\n"
                    f"{D(45):.6f},0,{D(30):.6f},{math.pi:.6f},0.0123,0.0145\n")
    assert main(["check", str(path), "--substrate", "black"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{path}: astm e1392 file, valid\n") and "findings:" not in out


def test_infer_zero_refusal_names_file_and_row(tmp_path, capsys):
    path = _write(tmp_path)
    assert main(["infer", str(path), "--opaque", "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"bayespig: error: {path}, row 6: film 'Test Red': observed value 0 at 400 nm")
    assert not (tmp_path / "out").exists()


@needs_cornell
def test_cornell_read_with_opaque():
    ms = read_measurements(GARNET, opaque=True)
    sample = ms.sample("Garnet Red")
    assert sample.opaque and len(sample.measurements) == 1439 and ms.n_wavelengths == 31


@needs_cornell
def test_cornell_check_summary_and_not_valid(capsys):
    assert main(["check", str(GARNET), "--opaque"]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"{GARNET}: astm e1392 file, readable, but not valid for infer as it stands"
    assert max(len(line) for line in lines) < 1000  # no 25 kB line of labels
    geometry = next(line for line in lines if "1439 geometries" in line).strip()
    assert geometry.startswith("brdf at 1439 geometries: theta_i 10° (")
    assert "in the plane of incidence" in geometry
    assert any(line.startswith("  infer refuses it as it stands: ") and "--noise-floor" in line for line in lines)
    assert any("of the mirror direction" in line for line in lines)
    assert any("exact zeros" in line for line in lines)


@needs_cornell
def test_cornell_infer_runs_with_a_floor(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["infer", str(GARNET), "--opaque", "--noise-floor", "infer", "--exclude-mirror", "5",
                 "--wavelengths", "600-620", "--max-angle", "30", "--out", str(out), "--no-progress"]) == 0
    assert (out / "posterior.nc").exists() and (out / "summary.csv").exists()
    assert capsys.readouterr().out.startswith("bayespig infer: general, g isotropic")


def test_report_film_state_options_refused_for_a_posterior(tmp_path, capsys):
    posterior = tmp_path / "posterior.nc"
    posterior.write_bytes(b"not read")
    assert main(["report", str(posterior), "--opaque", "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err == (f"bayespig: error: --opaque/--substrate: {posterior} is a posterior; they "
                                       "apply when report infers from an ASTM E1392 file\n")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("value, message", [
    ("1.5", "an albedo must be in [0, 1], got '1.5'"),
    ("", "expected 'black', 'white', an albedo in [0, 1] or a sample name, got ''"),
])
def test_bad_substrate_argument(tmp_path, capsys, value, message):
    path = _write(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(["check", str(path), "--substrate", value])
    assert info.value.code == 2
    assert capsys.readouterr().err.endswith(f"bayespig check: error: argument --substrate: {message}\n")


def test_opaque_and_substrate_exclusive(tmp_path, capsys):
    path = _write(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(["check", str(path), "--opaque", "--substrate", "black"])
    assert info.value.code == 2
    assert "argument --substrate: not allowed with argument --opaque" in capsys.readouterr().err


def test_check_verbose_lists_every_geometry(tmp_path, capsys, monkeypatch):
    from bayespig.data import io

    monkeypatch.setattr(io, "GEOMETRY_LIST_MAX", 2)  # the 3 rows count as many
    path = _write(tmp_path)
    main(["check", str(path), "--opaque"])
    short = capsys.readouterr().out
    assert ("brdf at 3 geometries: theta_i 30° (1), 45° (2); theta_o 30°–60°; delta_phi 90°–180°; 2 in the "
            "plane of incidence, 1 out of it (--verbose lists them)") in short
    main(["check", str(path), "--opaque", "--verbose"])
    lines = capsys.readouterr().out.splitlines()
    assert [line for line in lines if line.startswith("    brdf ")] == [
        "    brdf 45as15", "    brdf 45as-0.3", "    brdf 30/60/90"]


@needs_cornell
def test_cornell_occluded_geometries_are_the_three_grazing_rows_of_both_files(capsys):
    # theta_i = 80°, theta_o = 79°, delta_phi = 160-170°: 10-20° from the mirror, inside the grazing gloss
    # lobe, and dark at every band in both paints (the neighbours read 0.05-5.7 1/sr)
    from bayespig.selection import occluded_geometries

    for path in sorted(CORNELL.glob("*.astm")):
        ms = read_measurements(path, opaque=True)
        found = occluded_geometries(ms)
        film = ms.films[0]
        labels = [film.measurements[k].label for k in found[film.name]]
        assert labels == ["80/79.0472/160", "80/79.0472/165", "80/79.0472/170"], path
        assert max(float(film.measurements[k].values.max()) for k in found[film.name]) < 2e-3
    assert main(["check", str(GARNET), "--opaque"]) == 1
    line = next(line for line in capsys.readouterr().out.splitlines() if "blocked readings" in line)
    assert line == ("  3 BRDF geometries read at most 0.0012 1/sr in every band, below 0.02 of their neighbours' "
                    "(same incidence, viewing within 15°): blocked readings, not the paint (80/79.0472/160, "
                    "80/79.0472/165, 80/79.0472/170); --exclude-occluded leaves them out (rows 1458, 1459, 1460)")
