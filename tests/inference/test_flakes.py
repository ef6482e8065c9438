"""infer(..., flakes=True): the lobe of effect-pigment flakes in the forward model and the joint run.

The simulated film's values come from the direct rough-surface solver (:func:`bayespig.brdf`)
plus ``c(lambda)`` times the flakes' lobe of :func:`bayespig.physics.forward.flake_brdf`
(checked against an independent Monte Carlo in ``tests/physics/test_flake_lobe.py``), not from
the look-up tables the inference uses.
"""

import json

import numpy as np
import pytest

from bayespig import cli
from bayespig.data import simulate
from bayespig.data.simulate import FilmSpec
from bayespig.inference import infer
from bayespig.inference.outputs import PRIOR_BOUNDS_ATTR
from bayespig.instruments import get_instrument
from bayespig.likelihood import ForwardModel, Priors, Problem
from bayespig.physics.forward import brdf, flake_brdf

from .common import FAST

pytestmark = pytest.mark.usefixtures("private_table_cache")

#: Truth of the simulated metallic paint: its surface, its flakes and the relative error.
ALPHA_TRUE = 0.08
FLAKE_ALPHA_TRUE = 0.3
EPS_TRUE = 0.02
A_TRUE = np.array([0.6, 0.3, 0.05])
#: The flakes' reflectance per band: coloured (brightest where the body is), as in a red metallic.
C_TRUE = np.array([0.01, 0.05, 0.2])
WAVELENGTHS = np.array([450.0, 550.0, 650.0])
#: Central posterior interval that must cover each of the 3 + 3 + 2 truths (0.99^8 ~ 0.92 that all
#: do for a calibrated posterior; the seed is fixed, so the test is deterministic).
COVERAGE = 0.99
#: Geometries near the mirror (where the two lobes differ: the surface's is narrow, the flakes'
#: wide and coloured) and away from it (the body), in and out of the plane of incidence.
GEOMETRIES = ["45as5", "45as10", "45as15", "45as25", "45as45", "45as75", "45as110", "45as-15", "45as-25",
              (30.0, 26.0, 180.0), (30.0, 34.0, 180.0), (30.0, 20.0, 160.0), (60.0, 50.0, 180.0),
              (60.0, 40.0, 150.0), (15.0, 5.0, 180.0), (15.0, 30.0, 180.0)]
INSTRUMENT = get_instrument(GEOMETRIES)
#: The film's relative model error: the flake lobe through the tables equals the formula's to
#: round-off (the tables are not in its path; margin 1e3 over ~1e-15).
LOBE_RELATIVE = 1e-12


def _geometry(instrument):
    channels = instrument.channels
    return ([c.theta_i for c in channels], [c.theta_o for c in channels], [c.delta_phi for c in channels])


def _direct_model(*, a, tau, g, r_s):
    """Every channel of INSTRUMENT: the direct rough-surface solver plus the flakes' lobe."""
    a = np.asarray(a, dtype=float)
    theta_i, theta_o, delta_phi = _geometry(INSTRUMENT)
    shape = flake_brdf(theta_i, theta_o, delta_phi, flake_roughness=FLAKE_ALPHA_TRUE)
    out = np.empty(a.shape + (len(theta_i),))
    for index in np.ndindex(a.shape):
        c = C_TRUE[int(np.argmin(np.abs(A_TRUE - a[index])))]  # the band of this a
        out[index] = brdf(theta_i, theta_o, delta_phi, a=float(a[index]), tau=np.inf, roughness=ALPHA_TRUE) + c * shape
    return out


@pytest.fixture(scope="module")
def metallic_set():
    return simulate(a=A_TRUE, tau=1.0, design=[FilmSpec("paint", opaque=True)], instrument=INSTRUMENT,
                    wavelengths=WAVELENGTHS, eps=EPS_TRUE, seed=4, model=_direct_model)


@pytest.fixture(scope="module")
def metallic_idata(metallic_set):
    return infer(metallic_set, eps=EPS_TRUE, settings=FAST, progress=False, roughness="free", flakes=True)


def _interval(values):
    tail = 0.5 * (1.0 - COVERAGE)
    return np.quantile(values, [tail, 1.0 - tail], axis=0)


def test_the_forward_model_adds_c_times_the_flake_lobe_to_every_brdf_channel(metallic_set):
    problem = Problem.from_measurements(metallic_set, "auto")
    model = ForwardModel(problem, roughness=ALPHA_TRUE, flakes=True)
    evaluate = model.at_wavelength([0, 1, 2])
    a, member = np.array([0.2, 0.2, 0.5]), np.array([0, 1, 2])
    c, alpha_f = np.array([0.0, 0.1, 0.4]), np.array([0.2, 0.2, 0.6])
    rows = {"roughness": np.full(3, ALPHA_TRUE), "flake_roughness": alpha_f}
    with_flakes = evaluate(a, np.ones((3, 1)), None, member=member, flake_reflectance=c, **rows)
    without = evaluate(a, np.ones((3, 1)), None, member=member, flake_reflectance=np.zeros(3), **rows)
    theta_i, theta_o, delta_phi = _geometry(INSTRUMENT)
    expected = c[:, None] * np.stack([flake_brdf(theta_i, theta_o, delta_phi, flake_roughness=f) for f in alpha_f])
    np.testing.assert_allclose(with_flakes - without, expected, rtol=LOBE_RELATIVE, atol=1e-15)
    # without flakes, the model is the one of before (the surface and the body)
    plain = ForwardModel(problem, roughness=ALPHA_TRUE).at_wavelength([0, 1, 2])
    np.testing.assert_array_equal(without, plain(a, np.ones((3, 1)), None, member=member,
                                                 roughness=np.full(3, ALPHA_TRUE)))


def test_flakes_and_surface_are_recovered_from_gonio_data_of_a_metallic_paint(metallic_idata):
    post = metallic_idata.posterior
    for name, truth in (("a", A_TRUE), ("flake_reflectance", C_TRUE)):
        low, high = _interval(post[name].values.reshape(-1, WAVELENGTHS.size))
        assert ((low <= truth) & (truth <= high)).all(), (name, low, high)
    for name, truth in (("roughness", ALPHA_TRUE), ("flake_roughness", FLAKE_ALPHA_TRUE)):
        low, high = _interval(post[name].values.reshape(-1))
        assert low <= truth <= high, (name, low, high)
    assert post["flake_reflectance"].dims == ("chain", "draw", "wavelength")
    assert post["flake_roughness"].dims == ("chain", "draw", "surface")
    assert "log_flake_reflectance" in json.loads(post.attrs["parameter_names"]) or \
        "log_flake_reflectance" in metallic_idata.sample_stats["parameter"].values


def test_flake_priors_are_recorded_for_the_prior_edge_flags(metallic_idata):
    bounds = json.loads(metallic_idata.posterior.attrs[PRIOR_BOUNDS_ATTR])
    assert bounds["flake_reflectance"] == {"lower": pytest.approx(1e-5), "upper": pytest.approx(1.0), "scale": "log"}
    assert bounds["flake_roughness"] == {"lower": [pytest.approx(0.02)], "upper": [pytest.approx(1.0)],
                                         "scale": "log"}
    assert json.loads(metallic_idata.posterior.attrs["flake_roughness_prior"])["prior"] == (
        "log-uniform on [0.02, 1], one flake roughness for every film of the set")


def test_bad_flake_arguments_are_refused_with_one_clear_message(metallic_set, monkeypatch):
    with pytest.raises(ValueError) as caught:
        infer(metallic_set, flakes=True, progress=False)
    assert str(caught.value) == ("flakes=True needs roughness='free' (the flakes' roughness is inferred in the "
                                 "joint run with the surface's), got roughness=None")
    with pytest.raises(TypeError) as caught:
        infer(metallic_set, roughness="free", flakes="yes", progress=False)
    assert str(caught.value) == "flakes must be True or False, got 'yes' (str)"
    with pytest.raises(ValueError) as caught:
        Priors(flake_reflectance_range=(0.0, 1.0))
    assert str(caught.value) == ("flake_reflectance_range must start above 0 (a log-uniform prior), "
                                 "got (0.0, 1.0)")
    sphere = simulate(a=[0.2], tau=1.0, design=[FilmSpec("paint", opaque=True)], instrument="8d-sce",
                      wavelengths=[500.0], eps=0.02, seed=1)
    def no_tables(model):
        raise AssertionError("the rough tables were loaded before the flakes' channels were checked")

    with monkeypatch.context() as patch, pytest.raises(ValueError) as caught:
        patch.setattr(ForwardModel, "_rough_tables", no_tables)  # the refusal comes before any table work
        ForwardModel(Problem.from_measurements(sphere, "auto"), roughness=0.1, flakes=True)
    assert str(caught.value) == ("flakes are modelled for BRDF and 45/0 channels only; film(s) 'paint' have "
                                 "hemispherical channels")
    with pytest.raises(ValueError) as caught:
        ForwardModel(Problem.from_measurements(metallic_set, "auto"), flakes=True)
    assert str(caught.value) == ("flakes need roughness > 0 (the flakes' lobe is modelled with the tables of a "
                                 "rough surface)")


def test_cli_flakes_need_a_free_roughness(metallic_set, tmp_path, capsys):
    path = tmp_path / "metallic.csv"
    metallic_set.to_csv(path)
    status = cli.main(["infer", str(path), "--out", str(tmp_path / "out"), "--flakes"])
    err = capsys.readouterr().err
    assert status == 2
    assert err.strip().splitlines()[-1] == ("bayespig: error: --flakes needs --roughness free (the flakes' "
                                            "roughness is inferred with the surface's)")
    assert "Traceback" not in err and not (tmp_path / "out").exists()


def test_the_report_shows_the_surface_and_the_flakes(metallic_idata, tmp_path):
    from bayespig.inference import save_inference

    path = tmp_path / "posterior.nc"
    save_inference(metallic_idata, path)
    assert cli.main(["report", str(path), "--out", str(tmp_path / "report"), "--no-progress"]) == 0
    text = (tmp_path / "report" / "report.md").read_text()
    alpha_f = np.quantile(metallic_idata.posterior["flake_roughness"].values.ravel(), [0.5, 0.05, 0.95])
    row = next(line for line in text.splitlines() if line.startswith("| GGX roughness alpha of the effect-pigment"))
    assert f"{alpha_f[0]:.4g} \\[{alpha_f[1]:.4g}, {alpha_f[2]:.4g}\\]" in row
    assert "| GGX roughness alpha of the films' top surface |" in text


def test_cli_infers_the_flakes_and_prints_their_roughness(metallic_set, tmp_path, capsys):
    from bayespig.inference import load_inference

    path = tmp_path / "metallic.csv"
    metallic_set.to_csv(path)
    status = cli.main(["infer", str(path), "--out", str(tmp_path / "out"), "--eps", str(EPS_TRUE),
                       "--roughness", "free", "--flakes", "--no-progress"])
    out = capsys.readouterr().out
    assert status == 0
    line = next(row for row in out.splitlines() if row.startswith("flake roughness alpha_f "))
    printed = [float(x) for x in line.split(" (90 %")[0][len("flake roughness alpha_f "):]
               .replace("[", "").replace("]", "").replace(",", "").split()]
    stored = load_inference(tmp_path / "out" / "posterior.nc")
    expected = np.quantile(stored.posterior["flake_roughness"].values.ravel(), [0.5, 0.05, 0.95])
    np.testing.assert_allclose(printed, expected, rtol=5e-4)  # 4 significant digits printed
    header = (tmp_path / "out" / "summary.csv").read_text().splitlines()[0].split(",")
    assert "flake_reflectance_median" in header
