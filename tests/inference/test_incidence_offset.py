"""infer(incidence_offset=True): a gonioreflectometer's background error ``-b / cos theta_i`` per band
(readings clipped at 0), inferred with the roughness and the noise floor; recovered from readings of the
direct rough-surface solver with a known offset; the layout's readings; bad arguments refused.

The simulated readings come from the direct solver (:func:`bayespig.brdf` with ``roughness=``), not
from the look-up tables the inference uses, and the offset is applied to them here, independently of
:class:`bayespig.inference.roughness.NoiseFloorFilmLayout`.
"""

import csv
import json

import numpy as np
import pytest

from bayespig import cli
from bayespig.data import simulate
from bayespig.data.simulate import FilmSpec
from bayespig.inference import infer
from bayespig.inference.outputs import PRIOR_BOUNDS_ATTR
from bayespig.inference.roughness import incidence_offset_scale
from bayespig.instruments import get_instrument
from bayespig.likelihood import Problem
from bayespig.physics.forward import brdf

from .common import FAST

pytestmark = pytest.mark.usefixtures("private_table_cache")

ALPHA_TRUE = 0.08
EPS_TRUE = 0.02
A_TRUE = np.array([0.3, 0.6])
WAVELENGTHS = np.array([450.0, 600.0])
#: The offset of each band [1/sr]: at 80 deg incidence 5.8 times this, against a BRDF of ~0.03-0.2 1/sr.
OFFSET_TRUE = np.array([0.002, 0.0008])
#: Additive noise of the readings [1/sr] (the instrument's floor; without it the floor's posterior
#: spreads over the whole prior and the run mixes slowly).
FLOOR_TRUE = 2e-3
COVERAGE = 0.90
#: Incidences from 10 to 80 deg (the offset's 1 / cos theta_i tells it from the body's shape), in and
#: out of the plane of incidence, a few near the mirror direction (the roughness).
GEOMETRIES = [(10.0, 30.0, 0.0), (10.0, 50.0, 90.0), (30.0, 26.0, 180.0), (30.0, 34.0, 180.0), (30.0, 60.0, 0.0),
              "45as15", "45as45", "45as75", "45as110", (60.0, 50.0, 180.0), (60.0, 20.0, 0.0), (60.0, 40.0, 120.0),
              (70.0, 30.0, 0.0), (70.0, 50.0, 90.0), (80.0, 20.0, 0.0), (80.0, 40.0, 60.0), (80.0, 60.0, 150.0)]
INSTRUMENT = get_instrument(GEOMETRIES)


def _readings(*, a, tau, g, r_s, offset=OFFSET_TRUE):
    """Every channel's reading: the direct solver's BRDF less ``offset / cos theta_i``, plus additive noise
    of sd FLOOR_TRUE (seeded), clipped at 0 (simulate adds the relative error)."""
    rng = np.random.default_rng(101)
    channels = INSTRUMENT.channels
    theta_i = np.array([c.theta_i for c in channels])
    a = np.asarray(a, dtype=float)
    out = np.empty(a.shape + (len(channels),))
    for index in np.ndindex(a.shape):
        f = brdf(theta_i, [c.theta_o for c in channels], [c.delta_phi for c in channels], a=float(a[index]),
                 tau=np.inf, roughness=ALPHA_TRUE)
        band = index[-1]
        noise = FLOOR_TRUE * rng.standard_normal(f.shape)
        out[index] = np.maximum(f - offset[band] / np.cos(np.radians(theta_i)) + noise, 0.0)
    return out


@pytest.fixture(scope="module")
def offset_set():
    return simulate(a=A_TRUE, tau=1.0, design=[FilmSpec("paint", opaque=True)], instrument=INSTRUMENT,
                    wavelengths=WAVELENGTHS, eps=EPS_TRUE, seed=1, model=_readings)


@pytest.fixture(scope="module")
def offset_idata(offset_set):
    # one seeded realisation; over 6 other seeds the z-scores of a, b and alpha were unbiased (session 24)
    return infer(offset_set, eps=EPS_TRUE, settings=FAST, progress=False, roughness="free", noise_floor="infer",
                 incidence_offset=True, seed=1)


def _interval(values):
    tail = 0.5 * (1.0 - COVERAGE)
    return np.quantile(values, [tail, 1.0 - tail], axis=0)


def test_incidence_offset_a_and_roughness_are_recovered_from_offset_readings(offset_idata):
    post = offset_idata.posterior
    assert post["incidence_offset"].dims == ("chain", "draw", "wavelength")
    for name, truth in (("incidence_offset", OFFSET_TRUE), ("a", A_TRUE)):
        low, high = _interval(post[name].values.reshape(-1, truth.size))
        assert ((low <= truth) & (truth <= high)).all(), (name, low, high)
    low, high = _interval(post["roughness"].values.reshape(-1))
    assert low <= ALPHA_TRUE <= high, (low, high)
    bounds = json.loads(post.attrs[PRIOR_BOUNDS_ATTR])["incidence_offset"]
    assert bounds["scale"] == "log"
    assert list(offset_idata.sample_stats["parameter"].values)[-1] == "log_incidence_offset"


def test_the_stored_predictions_are_the_readings_less_the_offset(offset_idata, offset_set):
    # y at each draw: the direct solver's BRDF at that draw's a and roughness, less its b / cos theta_i,
    # clipped; the tables stand for the solver to their accuracy (2e-4 relative; 1e-3 leaves a margin of 5)
    post = offset_idata.posterior
    y = offset_idata.posterior_predictive["y"].values
    channels = INSTRUMENT.channels
    theta_i = np.array([c.theta_i for c in channels])
    for chain, draw in ((0, 0), (3, 17)):
        alpha = float(post["roughness"].values[chain, draw, 0])
        for k in range(WAVELENGTHS.size):
            a = float(post["a"].values[chain, draw, k])
            b = float(post["incidence_offset"].values[chain, draw, k])
            f = brdf(theta_i, [c.theta_o for c in channels], [c.delta_phi for c in channels], a=a, tau=np.inf,
                     roughness=alpha)
            expected = np.maximum(f - b / np.cos(np.radians(theta_i)), 0.0)
            np.testing.assert_allclose(y[chain, draw, k], expected, rtol=1e-3, atol=1e-6)


def test_offset_scale_is_one_over_cos_theta_i_on_brdf_values_and_zero_on_sphere_values():
    mixed = simulate(a=[0.3], tau=1.0, design=[FilmSpec("gonio", opaque=True)],
                     instrument=get_instrument(["45as15", (80.0, 20.0, 0.0)]), wavelengths=[500.0], seed=1)
    sphere = simulate(a=[0.3], tau=2.0, design="method4", instrument="8d-sce", wavelengths=[500.0], seed=1)
    np.testing.assert_allclose(incidence_offset_scale(Problem.from_measurements(mixed, "general")),
                               [1.0 / np.cos(np.radians(45.0)), 1.0 / np.cos(np.radians(80.0))], rtol=1e-15)
    assert (incidence_offset_scale(Problem.from_measurements(sphere, "general")) == 0.0).all()


@pytest.mark.parametrize("kwargs, message", [
    ({"noise_floor": "infer"}, ("incidence_offset=True needs roughness='free' and noise_floor='infer' (the offset is "
                                "inferred in the joint run with the floor), got roughness=None, noise_floor='infer'")),
    ({"roughness": "free"}, ("incidence_offset=True needs roughness='free' and noise_floor='infer' (the offset is "
                             "inferred in the joint run with the floor), got roughness='free', noise_floor=None")),
])
def test_incidence_offset_needs_the_joint_run_with_a_floor(offset_set, kwargs, message):
    with pytest.raises(ValueError) as caught:
        infer(offset_set, eps=EPS_TRUE, settings=FAST, progress=False, incidence_offset=True, **kwargs)
    assert str(caught.value) == message


def test_incidence_offset_must_be_a_flag(offset_set):
    with pytest.raises(TypeError, match="incidence_offset"):
        infer(offset_set, eps=EPS_TRUE, settings=FAST, progress=False, roughness="free", noise_floor="infer",
              incidence_offset="yes")


@pytest.mark.parametrize("options", [["--roughness", "free"], ["--noise-floor", "infer"]])
def test_cli_offset_needs_a_free_roughness_and_an_inferred_floor(offset_set, tmp_path, capsys, options):
    path = tmp_path / "paint.csv"
    offset_set.to_csv(path)
    status = cli.main(["infer", str(path), "--out", str(tmp_path / "out"), "--incidence-offset", "--no-progress",
                       *options])
    err = capsys.readouterr().err
    assert status == 2
    assert err.strip().splitlines()[-1] == ("bayespig: error: --incidence-offset needs --roughness free and "
                                            "--noise-floor infer (the offset is sampled with the surface and the "
                                            "floor)")
    assert "Traceback" not in err and not (tmp_path / "out").exists()


def test_cli_passes_the_offset_and_summary_csv_has_its_columns(offset_set, offset_idata, tmp_path, monkeypatch):
    # the sampling itself is tested above: here the command's wiring and its table, on the fixture's posterior
    import bayespig.inference

    path = tmp_path / "paint.csv"
    offset_set.to_csv(path)
    passed = {}

    def recorded_infer(measurements, **kwargs):
        passed.update(kwargs)
        return offset_idata

    monkeypatch.setattr(bayespig.inference, "infer", recorded_infer)
    status = cli.main(["infer", str(path), "--out", str(tmp_path / "out"), "--eps", str(EPS_TRUE), "--roughness",
                       "free", "--noise-floor", "infer", "--incidence-offset", "--no-progress"])
    assert status == 0
    assert passed["incidence_offset"] is True and passed["noise_floor"] == "infer" and passed["roughness"] == "free"
    with open(tmp_path / "out" / "summary.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    for variable in ("incidence_offset", "noise_floor"):
        draws = offset_idata.posterior[variable].transpose("chain", "draw", "wavelength").values.reshape(-1, 2)
        for statistic, expected in (("median", np.median(draws, axis=0)),
                                    ("ci90_low", np.quantile(draws, 0.05, axis=0)),
                                    ("ci90_high", np.quantile(draws, 0.95, axis=0))):
            written = [float(row[f"{variable}_{statistic}"]) for row in rows]
            np.testing.assert_allclose(written, expected, rtol=1e-5)  # 6 significant digits written
