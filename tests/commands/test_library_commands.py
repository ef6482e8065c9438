"""``bayespig predict`` and ``bayespig match`` on a saved library; the recipe and spectrum arguments."""

import functools

import numpy as np
import pytest

from bayespig.cli import main
from bayespig.commands.library import recipe_argument, spectrum_argument
from bayespig.inference.settings import InferenceSettings
from bayespig.library import load_library
from bayespig.library.library import PigmentLibrary
from bayespig.studies.revigo import default_revigo_path

WL = np.arange(400.0, 701.0, 50.0)
PIGMENTS = ("ZincWhite", "PrussianBlue")


@pytest.fixture(scope="module")
def library_file(tmp_path_factory):
    a = np.stack([np.full(WL.size, 0.002), 0.02 + 0.5 / (1 + np.exp(-(WL - 560) / 20))], axis=1)
    c = np.empty((32, WL.size, 2, 2))
    c[..., 0] = a
    c[..., 1] = np.log([1.0, 3.0])
    library = PigmentLibrary(model="radiative-transfer", pigments=PIGMENTS, wavelength_nm=WL, constants=c,
                             constant_names=("a", "log_sigma"), thickness_prior=(0.0, 0.2), films=(), film_ids=(),
                             thickness=np.zeros((32, 0)), densities=None, model_error=None,
                             provenance={"seed": 0}, stages=())
    path = tmp_path_factory.mktemp("lib") / "library.nc"
    library.save(path)
    return path


def test_recipe_argument():
    assert recipe_argument("ZincWhite:90, PrussianBlue:10") == {"ZincWhite": 90.0, "PrussianBlue": 10.0}
    with pytest.raises(ValueError, match=r"--recipe: cannot read 'ZincWhite'"):
        recipe_argument("ZincWhite")
    with pytest.raises(ValueError, match="--recipe: the amount of 'ZincWhite' is not a number: 'lots'"):
        recipe_argument("ZincWhite:lots")
    with pytest.raises(ValueError, match="--recipe: 'ZincWhite' is given twice"):
        recipe_argument("ZincWhite:1,ZincWhite:2")


def test_spectrum_argument(tmp_path):
    np.testing.assert_array_equal(spectrum_argument("0.05", WL, "--substrate"), np.full(WL.size, 0.05))
    path = tmp_path / "card.csv"
    path.write_text("wavelength_nm,reflectance\n" + "".join(f"{w:g},0.8\n" for w in np.arange(400, 701, 10)))
    np.testing.assert_allclose(spectrum_argument(str(path), WL, "--substrate"), 0.8)
    path.write_text("wavelength_nm,reflectance\n400,0.8\n450,-0.1\n")
    with pytest.raises(ValueError, match=r"card.csv, row 3, field 'reflectance': must be a fraction in \[0, 1.5\], "
                                         "got -0.1"):
        spectrum_argument(str(path), WL, "--substrate")
    with pytest.raises(ValueError, match="--substrate: a reflectance must be a fraction in"):
        spectrum_argument("5", WL, "--substrate")


def test_predict_prints_the_colour_and_its_region(library_file, capsys, tmp_path):
    out = tmp_path / "spectrum.csv"
    assert main(["predict", str(library_file), "--recipe", "ZincWhite:70,PrussianBlue:30", "-q",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "CIELAB L*" in text and "credible region: ΔE00 <=" in text
    assert "the library has no cross-validated model error" in text
    assert out.read_text().splitlines()[1] == "wavelength_nm,reflectance_median,reflectance_q05,reflectance_q95"


def test_predict_refuses_an_unknown_pigment_in_one_line(library_file, capsys):
    assert main(["predict", str(library_file), "--recipe", "Vermillion:1", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["bayespig: error: recipe: pigment 'Vermillion' is not in the library (it has ZincWhite, "
                   "PrussianBlue)"]


def test_match_a_lab_target(library_file, capsys):
    assert main(["match", str(library_file), "--lab", "60,-10,-30", "-q"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("recipe (mass fractions): ")
    assert "equally good matches" in text


@pytest.mark.parametrize("value, message", [
    ("-0.1", "substrate_sd must be a positive number (the prior sd of log f, e.g. 0.1 for 10 %) or None, got -0.1"),
    ("nan", "substrate_sd must be a positive number (the prior sd of log f, e.g. 0.1 for 10 %) or None, got nan"),
])
def test_library_build_refuses_a_bad_substrate_sd_before_reading(tmp_path, capsys, value, message):
    """``--substrate-sd`` as in ``bayespig infer`` (its check and message), before the
    measurements are read (here a file that does not exist as a library input) or a file written."""
    source = tmp_path / "films.csv"
    source.write_text("not read\n")
    out = tmp_path / "library.nc"
    assert main(["library", "build", str(source), "--out", str(out), "--substrate-sd", value]) == 2
    assert capsys.readouterr().err.strip() == f"bayespig: error: {message}"
    assert not out.exists()


def test_library_build_refuses_an_unknown_noise_scale_in_one_line(tmp_path, capsys):
    source = tmp_path / "films.csv"
    source.write_text("not read\n")
    out = tmp_path / "library.nc"
    with pytest.raises(SystemExit) as stop:
        main(["library", "build", str(source), "--out", str(out), "--noise-scale", "data"])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    # argparse's wording of the choices differs between Python versions; the argument and value do not
    assert "argument --noise-scale: invalid choice: 'data'" in err and "measured" in err and "model" in err
    assert not out.exists()


REVIGO = default_revigo_path()
needs_revigo = pytest.mark.skipif(not (REVIGO / "revigo-mixture-specifications.txt").exists(),
                                  reason=f"Revigo data not found at {REVIGO} (set BAYESPIG_REVIGO)")


@needs_revigo
def test_library_build_refuses_to_cross_validate_one_mixture_before_building(tmp_path, capsys):
    """``--cross-validate`` needs two held-out mixture films: said before any build, nothing written
    (07A is zinc white alone, 07C its grey with bone black)."""
    out = tmp_path / "library.nc"
    assert main(["library", "build", str(REVIGO), "--films", "07A,07C", "--cross-validate", "--out", str(out),
                 "-q"]) == 2
    assert capsys.readouterr().err.strip() == (
        f"bayespig: error: --cross-validate needs at least two mixture films (two or more pigments); {REVIGO} "
        "has 1: 07C")
    assert not out.exists()


#: A tiny sampler for the command's path only: convergence and coverage are the API tests'
#: (tests/library/test_build.py, test_validation.py), not this one's.
TINY = InferenceSettings(target_ess=20.0, draws_per_chain=16, min_steps=100, max_steps=300, check_interval=100)


@needs_revigo
def test_library_build_cross_validates_with_progress_and_predict_adds_the_model_error(tmp_path, capsys,
                                                                                      monkeypatch):
    """``bayespig library build --cross-validate`` end to end on real films (07A zinc white, 07C and
    07D its greys with bone black), progress shown (the default; it once stopped the command with a
    TypeError before any build): the stages and held-out films reported on stderr, the library
    written with the model error of both held-out films, and ``bayespig predict`` using it."""
    import bayespig.library as library_api
    import bayespig.library.validation as validation

    monkeypatch.setattr(library_api, "build_library", functools.partial(library_api.build_library, settings=TINY))
    monkeypatch.setattr(validation, "cross_validate", functools.partial(validation.cross_validate, settings=TINY))
    out = tmp_path / "library.nc"
    assert main(["library", "build", str(REVIGO), "--films", "07A,07C,07D", "--cross-validate",
                 "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert "library stage 1/1: BoneBlack, ZincWhite from 3 films: " in captured.err
    assert [line.split(":")[0] for line in captured.err.splitlines() if line.startswith("[")] == [
        "[1/2] radiative-transfer 07C", "[2/2] radiative-transfer 07D"]
    assert "model error from 2 held-out films, calibration factor " in captured.out
    assert captured.out.strip().splitlines()[-1].endswith(", cross-validated model error")
    library = load_library(out)
    assert library.model_error.shape == (library.wavelength_nm.size,) * 2
    assert library.provenance["model_error"]["films"] == ["07C", "07D"]
    assert main(["predict", str(out), "--recipe", "ZincWhite:95,BoneBlack:5", "-q"]) == 0
    text = capsys.readouterr().out
    assert "credible region: ΔE00 <=" in text and "no cross-validated model error" not in text
