"""infer(roughness=...): the surface roughness inferred from gonio data of a rough opaque film,
fixed, or 0 (the smooth model exactly); its prior bounds and edge flags; bad values refused.

The simulated film's values come from the direct solver (:func:`bayespig.brdf` with
``roughness=``), not from the look-up tables the inference uses.
"""

import dataclasses
import json

import numpy as np
import pytest

from bayespig import cli
from bayespig.data import MeasurementSet, simulate
from bayespig.data.simulate import FilmSpec
from bayespig.inference import infer, load_inference
from bayespig.inference.outputs import PRIOR_BOUNDS_ATTR
from bayespig.instruments import get_instrument
from bayespig.physics.forward import brdf
from bayespig.report.quantities import prior_edges

from .common import FAST

pytestmark = pytest.mark.usefixtures("private_table_cache")

#: Truth of the simulated paint: GGX roughness of its surface and relative error of its values.
ALPHA_TRUE = 0.08
EPS_TRUE = 0.02
A_TRUE = np.linspace(0.02, 0.6, 5)
WAVELENGTHS = np.linspace(450.0, 650.0, 5)
#: The CLI run fits one band (450 nm, the darkest): its alpha is 0.0818 [0.080x, 0.0836] (90 %),
#: 2.3 % from the truth; the printed median must be within 5 % of it (a gross error, not coverage).
CLI_ALPHA_RELATIVE = 0.05
#: The CLI prints 4 significant digits.
PRINTED_DIGITS_RELATIVE = 5e-4
#: Central posterior interval that must cover each truth.
COVERAGE = 0.90
#: In-plane and out-of-plane geometries, a few near the mirror direction (where the lobe tells
#: the roughness).
GEOMETRIES = ["45as15", "45as25", "45as45", "45as75", "45as110", "45as-15", (30.0, 26.0, 180.0),
              (30.0, 34.0, 180.0), (60.0, 50.0, 180.0), (60.0, 40.0, 150.0)]
INSTRUMENT = get_instrument(GEOMETRIES)
EXPECTED = ("'free' (inferred), or a number >= 0 (the GGX alpha of the top surface, fixed; 0 for a smooth "
            "surface)")


def _direct_model(*, a, tau, g, r_s):
    """Every channel of INSTRUMENT from the direct rough-surface solver (opaque film)."""
    channels = INSTRUMENT.channels
    a = np.asarray(a, dtype=float)
    out = np.empty(a.shape + (len(channels),))
    for index in np.ndindex(a.shape):
        out[index] = brdf([c.theta_i for c in channels], [c.theta_o for c in channels],
                          [c.delta_phi for c in channels], a=float(a[index]), tau=np.inf, roughness=ALPHA_TRUE)
    return out


@pytest.fixture(scope="module")
def rough_set():
    return simulate(a=A_TRUE, tau=1.0, design=[FilmSpec("paint", opaque=True)], instrument=INSTRUMENT,
                    wavelengths=WAVELENGTHS, eps=EPS_TRUE, seed=3, model=_direct_model)


@pytest.fixture(scope="module")
def rough_idata(rough_set):
    # roughness="free" is the default for a set of opaque films with BRDF channels
    return infer(rough_set, eps=EPS_TRUE, settings=FAST, progress=False)


def _interval(values):
    tail = 0.5 * (1.0 - COVERAGE)
    return np.quantile(values, [tail, 1.0 - tail], axis=0)


def test_roughness_is_recovered_from_gonio_data_of_a_rough_opaque_film(rough_idata):
    alpha = rough_idata.posterior["roughness"].values.reshape(-1)
    low, high = _interval(alpha)
    assert low <= ALPHA_TRUE <= high, (low, high)
    a = rough_idata.posterior["a"].values.reshape(-1, A_TRUE.size)
    low, high = _interval(a)
    assert ((low <= A_TRUE) & (A_TRUE <= high)).all(), (low, high)
    assert rough_idata.posterior.attrs["roughness_mode"] == "inferred"
    assert rough_idata.posterior["roughness"].dims == ("chain", "draw", "surface")


def test_roughness_prior_is_recorded_and_its_edges_flagged(rough_idata):
    bounds = json.loads(rough_idata.posterior.attrs[PRIOR_BOUNDS_ATTR])["roughness"]
    assert bounds == {"lower": [pytest.approx(0.01)], "upper": [pytest.approx(1.0)], "scale": "log"}
    assert json.loads(rough_idata.posterior.attrs["roughness_prior"])["prior"] == (
        "log-uniform on [0.01, 1] (the rough look-up tables' range), one alpha for every film of the set")
    assert not [e for e in prior_edges(rough_idata) if e["variable"] == "roughness"]
    piled = rough_idata.copy()
    draws = piled.posterior["roughness"].values
    piled.posterior["roughness"].values = 0.01 * np.exp(np.abs(draws - draws.mean()))  # against 0.01
    flagged = [e for e in prior_edges(piled) if e["variable"] == "roughness"]
    assert [(e["parameter"], e["bound"]) for e in flagged] == [("roughness[surface]", "lower")]


def test_a_fixed_roughness_is_used_as_given(rough_set):
    idata = infer(rough_set, eps=EPS_TRUE, settings=FAST, progress=False, roughness=ALPHA_TRUE,
                  wavelengths=[450.0])
    assert "roughness" not in idata.posterior
    assert idata.posterior.attrs["roughness_mode"] == "fixed"
    assert idata.posterior.attrs["roughness"] == ALPHA_TRUE
    low, high = _interval(idata.posterior["a"].values.reshape(-1))
    assert low <= A_TRUE[0] <= high


def test_roughness_zero_is_todays_smooth_model_bit_for_bit_on_a_sphere_only_set():
    sphere = simulate(a=[0.05, 0.3], tau=2.0, design="method4", instrument="8d-sce", wavelengths=[450.0, 600.0],
                      eps=0.02, seed=5)
    default = infer(sphere, seed=7, settings=FAST, progress=False)
    smooth = infer(sphere, seed=7, settings=FAST, progress=False, roughness=0)
    assert default.posterior.attrs["roughness_mode"] == smooth.posterior.attrs["roughness_mode"] == "smooth"
    assert "roughness" not in default.posterior
    for name in ("a", "tau"):
        np.testing.assert_array_equal(default.posterior[name].values, smooth.posterior[name].values)
    assert default.posterior.attrs["table_keys"] == smooth.posterior.attrs["table_keys"]


@pytest.mark.parametrize("value, error, message", [
    ("rough", ValueError, f"roughness must be {EXPECTED}, got 'rough'"),
    (-0.1, ValueError, f"roughness must be {EXPECTED}, got -0.1"),
    (float("nan"), ValueError, f"roughness must be {EXPECTED}, got nan"),
    (True, TypeError, f"roughness must be {EXPECTED}, got bool True"),
    ([0.1], TypeError, f"roughness must be {EXPECTED}, got list [0.1]"),
    (1.5, ValueError, ("roughness 1.5 is outside the range of the look-up tables of a rough surface [0.01, 1] "
                       "(0 for a smooth surface)")),
])
def test_bad_roughness_is_refused_naming_the_argument(rough_set, value, error, message):
    with pytest.raises(error) as caught:
        infer(rough_set, roughness=value, progress=False)
    assert str(caught.value) == message


def test_free_roughness_needs_a_known_eps_and_opaque_films(rough_set):
    with pytest.raises(ValueError) as caught:
        infer(rough_set, roughness="free", eps="infer", progress=False)
    assert str(caught.value) == (
        "roughness='free' needs g='isotropic', a known eps and no substrate_sd (the joint run over all "
        "wavelengths does not sample g or eps); pass roughness=<number> to fix the roughness")
    with pytest.raises(ValueError) as caught:
        infer(rough_set, roughness="free", noise_floor=0.001, progress=False)
    assert str(caught.value) == (
        "roughness='free' needs noise_floor None or 'infer' (the joint run over all wavelengths infers one floor "
        "per band or has none), got 0.001")
    thin = simulate(a=0.2, tau=2.0, design="method3", instrument=INSTRUMENT, wavelengths=[500.0], eps=0.02, seed=1)
    with pytest.raises(ValueError) as caught:
        infer(thin, roughness=0.1, progress=False)
    assert str(caught.value) == (
        "film 'on_black' does not hide its substrate: roughness > 0 is available for opaque films only (the "
        "look-up tables of a rough surface have no tau axis yet); use roughness=0 for this set")


def test_cli_roughness_is_checked_in_plain_words(tmp_path, capsys):
    path = tmp_path / "set.csv"
    simulate(a=0.2, tau=2.0, design="method4", instrument="8d-sce", wavelengths=[500.0], eps=0.02,
             seed=1).to_csv(path)
    status = cli.main(["infer", str(path), "--out", str(tmp_path / "out"), "--roughness", "shiny"])
    err = capsys.readouterr().err
    assert status == 2
    assert err.strip().splitlines()[-1] == f"bayespig: error: --roughness must be {EXPECTED}, got 'shiny'"
    assert "Traceback" not in err and not (tmp_path / "out").exists()


def test_free_roughness_with_an_inferred_noise_floor_takes_zeros_as_data(rough_set):
    # the darkest readings of the first band set to exact zeros, as a clipping instrument reports them
    sample = rough_set.samples[0]
    first = sample.measurements[0]
    values = np.asarray(first.values, dtype=float).copy()
    values[0] = 0.0
    zeroed = dataclasses.replace(sample, measurements=(dataclasses.replace(first, values=values),)
                                 + tuple(sample.measurements[1:]))
    measurements = MeasurementSet(rough_set.wavelength_nm, [zeroed], n=rough_set.n, metadata={},
                                  source=rough_set.source)
    idata = infer(measurements, eps=EPS_TRUE, noise_floor="infer", settings=FAST, progress=False,
                  wavelengths=[450.0, 550.0, 650.0])
    assert idata.posterior["noise_floor"].dims == ("chain", "draw", "wavelength")
    assert idata.posterior.attrs["noise_floor_mode"] == "inferred"
    low, high = _interval(idata.posterior["roughness"].values.reshape(-1))
    assert low <= ALPHA_TRUE <= high, (low, high)


def test_cli_infers_the_roughness_of_a_rough_set_and_prints_it(rough_set, tmp_path, capsys):
    path = tmp_path / "rough.csv"
    rough_set.to_csv(path)
    status = cli.main(["infer", str(path), "--out", str(tmp_path / "out"), "--eps", str(EPS_TRUE),
                       "--wavelengths", "450", "--roughness", "free", "--no-progress"])
    out = capsys.readouterr().out
    assert status == 0
    line = next(row for row in out.splitlines() if row.startswith("surface roughness alpha "))
    median, low, high = (float(x) for x in line.split(" (90 %")[0][len("surface roughness alpha "):]
                         .replace("[", "").replace("]", "").replace(",", "").split())
    # the printed numbers are the stored posterior's (its coverage is tested above, on every band)
    stored = load_inference(tmp_path / "out" / "posterior.nc").posterior["roughness"].values.ravel()
    expected = np.quantile(stored, [0.5, 0.05, 0.95])
    np.testing.assert_allclose([median, low, high], expected, rtol=PRINTED_DIGITS_RELATIVE)
    assert abs(median / ALPHA_TRUE - 1.0) <= CLI_ALPHA_RELATIVE
