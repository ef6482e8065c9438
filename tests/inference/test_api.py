"""infer and infer_problem: schema, reproducibility, parameters, argument checks, calibration."""

import json
import warnings

import numpy as np
import pytest

from bayespig.data import simulate
from bayespig.inference import (
    ConvergenceWarning,
    InferenceSettings,
    diagnose,
    infer,
    load_inference,
    save_inference,
    summarize,
)
from bayespig.likelihood import Priors
from bayespig.table import table_path

from .common import FAST, MC_Z

# --- tolerances -----------------------------------------------------------------------------
#: Posterior sd vs the frequentist RMS of the point fits where the posterior is well
#: identified. Issue 6 asks for a factor 1.5, but that band would pass an eps wrong by 40 %;
#: the sampling errors are ~5 % (an rms over 200 replicates, 1/sqrt(400)) and ~3 % (the mean
#: posterior sd of four bands), so 1.2 is ~4 combined sd (measured: 0.96 for a, 1.00 for tau).
SD_RMS_FACTOR = 1.2
#: The paper's ravine (issue 6): method 3's corr(a, log tau) above this ...
RAVINE_CORRELATION = 0.5
#: ... and its tau spread this many times method 4's for the same film.
RAVINE_SPREAD_RATIO = 10.0

#: Draw-wise predictions and log-likelihoods are stored in single precision.
SINGLE_PRECISION_TOL = 1e-5


def test_inference_data_schema(method4_idata, method4_set):
    idata = method4_idata
    post = idata.posterior
    n_draws = FAST.steps_kept * FAST.n_walkers
    assert dict(post["a"].sizes) == {"chain": 4, "draw": n_draws, "wavelength": 3}
    assert post["tau"].dims == ("chain", "draw", "wavelength")
    assert "tau_group" not in post and "g" not in post and "eps" not in post
    np.testing.assert_array_equal(post["wavelength"].values, [450.0, 550.0, 650.0])
    assert ((post["a"] >= 0) & (post["a"] <= 1)).all()
    assert ((post["tau"] >= 0.01) & (post["tau"] <= 100)).all()
    # every measured value: 2 films x 6 channels
    y = idata.posterior_predictive["y"]
    assert y.dims == ("chain", "draw", "wavelength", "value") and y.sizes["value"] == 12
    assert idata.log_likelihood["y"].shape == y.shape
    observed = idata.observed_data["y"]
    assert list(observed["sample"].values) == ["on_black"] * 6 + ["on_white"] * 6
    assert list(observed["channel"].values[:2]) == ["45as-15", "45as15"]
    assert set(observed["kind"].values) == {"reflectance"}
    assert set(observed["film_group"].values) == {"film"}
    np.testing.assert_array_equal(observed.values[:, :6], method4_set.sample("on_black").reflectance)
    np.testing.assert_array_equal(observed.values[:, 6:], method4_set.sample("on_white").reflectance)
    const = idata.constant_data
    np.testing.assert_allclose(const["r_s"].values[:, :6], 0.01)
    np.testing.assert_allclose(const["r_s"].values[:, 6:], 0.95)
    np.testing.assert_allclose(const["eps"].values, 0.05)
    assert const["point_a"].dims == ("wavelength",) and const["point_tau"].dims == ("wavelength",)
    stats = idata.sample_stats
    assert stats["lp"].shape == post["a"].shape
    assert stats["acceptance_rate"].dims == ("chain", "wavelength")
    assert ((stats["acceptance_rate"] > 0.05) & (stats["acceptance_rate"] < 0.95)).all()
    for key in ("bayespig_version", "numpy_version", "scipy_version", "emcee_version",
                "arviz_version", "created"):
        assert isinstance(post.attrs[key], str) and post.attrs[key]
    assert post.attrs["seed"] == 5 and post.attrs["method"] == "method4"
    assert post.attrs["g"] == "isotropic" and post.attrs["eps_mode"] == "known"
    assert json.loads(post.attrs["settings"])["n_walkers"] == 16
    assert "log-uniform" in json.loads(post.attrs["priors"])["tau"]
    assert len(json.loads(post.attrs["table_keys"])) == 1
    checksums = json.loads(post.attrs["table_checksums"])
    assert list(checksums) == json.loads(post.attrs["table_keys"])
    for key, checksum in checksums.items():  # the cache file's own record of the table's contents
        with np.load(table_path(key), allow_pickle=False) as data:
            assert checksum == str(data["__checksum__"])
    assert post.attrs["n"] == 1.45


def test_log_likelihood_group_is_eq7_at_the_draws(method4_idata):
    """log_likelihood = log N(y_obs | y_pred, (eps y_pred)^2) with the stored predictions."""
    from scipy import stats

    pred = method4_idata.posterior_predictive["y"].values[:, :50].astype(float)
    obs = method4_idata.observed_data["y"].values
    expected = stats.norm.logpdf(obs, loc=pred, scale=0.05 * pred)
    # both are stored in single precision: the predictions' rounding (6e-8 relative) moves the
    # log-density of a value z sd away by ~z * 6e-8 / eps, ~5e-6 at z = 4, eps = 0.05
    stored = method4_idata.log_likelihood["y"].values[:, :50]
    np.testing.assert_allclose(stored, expected, rtol=SINGLE_PRECISION_TOL, atol=SINGLE_PRECISION_TOL)
    # lp (double precision) is the log-likelihood summed over values (flat priors in the
    # sampled coordinates)
    np.testing.assert_allclose(method4_idata.sample_stats["lp"].values[:, :50],
                               expected.sum(axis=-1), rtol=SINGLE_PRECISION_TOL, atol=12 * SINGLE_PRECISION_TOL)


def test_posterior_contains_the_truth(method4_idata):
    """Method 4 is well identified: the truth lies within a few posterior sd at every wavelength."""
    summary = summarize(method4_idata)
    z_a = (summary["a_mean"] - [0.05, 0.1, 0.2]) / summary["a_sd"]
    z_tau = (np.log(summary["tau_mean"]) - np.log([0.5, 1.0, 2.0])) / (summary["tau_sd"] / summary["tau_mean"])
    assert (np.abs(z_a) < 4).all() and (np.abs(z_tau) < 4).all()


def test_different_seeds_give_statistically_equal_summaries(method4_set, method4_idata):
    other = infer(method4_set, seed=6, progress=False, settings=FAST, executor=None)
    assert not np.array_equal(other.posterior["a"].values, method4_idata.posterior["a"].values)
    s1, s2 = summarize(method4_idata), summarize(other)
    for name in ("a", "tau"):
        se = np.hypot(s1[f"{name}_sd"] / np.sqrt(s1[f"{name}_ess_bulk"]),
                      s2[f"{name}_sd"] / np.sqrt(s2[f"{name}_ess_bulk"]))
        assert (np.abs(s1[f"{name}_mean"] - s2[f"{name}_mean"]) < MC_Z * se).all()
        # sd of a sample sd ~ sd / sqrt(2 n_eff)
        se_sd = np.hypot(s1[f"{name}_sd"] / np.sqrt(2 * s1[f"{name}_ess_bulk"]),
                         s2[f"{name}_sd"] / np.sqrt(2 * s2[f"{name}_ess_bulk"]))
        assert (np.abs(s1[f"{name}_sd"] - s2[f"{name}_sd"]) < MC_Z * se_sd).all()


def test_run_length_cap_warns():
    one = simulate(a=0.1, tau=1.0, design="method4", wavelengths=[500.0], eps=0.05, seed=1)
    settings = InferenceSettings(min_steps=100, max_steps=100, check_interval=100, draws_per_chain=64)
    with pytest.warns(ConvergenceWarning, match="max_steps=100"):
        idata = infer(one, progress=False, settings=settings)
    assert idata.sample_stats["max_steps_reached"].values.tolist() == [1]
    with pytest.warns(ConvergenceWarning):
        assert diagnose(idata)


def test_inferred_eps_and_method1_groups(tmp_path):
    """eps inferred: a posterior variable near the simulated eps; method 1: tau from T."""
    ms = simulate(a=0.1, tau=1.0, design="method1", wavelengths=[500.0], eps=0.05, seed=4)
    idata = infer(ms, method=1, eps="infer", progress=False, settings=FAST)
    post = idata.posterior
    assert post.attrs["method"] == "method1" and post.attrs["eps_mode"] == "inferred"
    assert np.isnan(idata.constant_data["eps"].values).all()
    eps = post["eps"].values
    assert 0.001 <= eps.min() and eps.max() <= 0.5
    # 7 values: eps is weakly identified, but the simulated 0.05 is well inside the posterior
    assert np.quantile(eps, 0.01) < 0.05 < np.quantile(eps, 0.99)
    assert list(idata.observed_data["kind"].values) == ["reflectance"] * 6 + ["transmittance"]
    assert list(idata.observed_data["film_group"].values) == [""] * 6 + ["on_glass"]
    save_inference(idata, tmp_path / "posterior.nc")
    eps_back = load_inference(tmp_path / "posterior.nc").posterior["eps"]
    assert eps_back.attrs == {"long_name": "relative measurement error eps (eq. 7)", "units": "1"}


#: A coarse g table over the default prior range of g, [-0.5, 0.8] (the default table's code path,
#: built in seconds; its interpolation error is far below the tests' eps).
COARSE_G = dict(g_range=(-0.5, 0.8), n_g=9, n_a=16, log2_tau_min=-4, log2_tau_max=7, per_octave=2)


@pytest.fixture(scope="module")
def coarse_g_cache(tmp_path_factory):
    """One table cache for the module's g-free runs (the coarse table is built once)."""
    return tmp_path_factory.mktemp("coarse-g-cache")


def _coarse_g_tables(problem, cache_dir):
    from bayespig.table import TableSettings, load_table

    instrument = problem.films[0].instrument
    return {instrument: load_table(instrument, g="free", settings=TableSettings(**COARSE_G), cache_dir=cache_dir,
                                   progress=False)}


def test_free_g_posterior_recovers_the_simulated_g(coarse_g_cache):
    """g="free" end to end: a g axis in the posterior, its diagnostics, and the simulated
    (a, tau, g) inside the posterior at every wavelength of a stack. The data come from the
    direct solver, the likelihood from a coarse g table (the default table's code path, built
    in seconds), whose interpolation error is far below eps."""
    from bayespig.inference import infer_problem
    from bayespig.likelihood import Problem

    design = [{"name": "opaque", "opaque": True},
              {"name": "on_black", "substrate": "black", "film_group": "thin"},
              {"name": "on_white", "substrate": "white", "film_group": "thin"}]
    truth = {"a": 0.1, "tau": 1.5, "g": 0.3}
    ms = simulate(**truth, design=design, instrument="multi-angle-45", wavelengths=[500.0, 600.0],
                  eps=0.02, seed=8)
    problem = Problem.from_measurements(ms, method="general")
    idata = infer_problem(problem, seed=3, g="free", eps=0.02, executor=None, progress=False,
                          settings=FAST, tables=_coarse_g_tables(problem, coarse_g_cache))
    post = idata.posterior
    assert post["g"].dims == ("chain", "draw", "wavelength")
    assert "g" in json.loads(post.attrs["parameter_names"]) and post.attrs["g"] == "free"
    assert post["g"].attrs == {"long_name": "Henyey-Greenstein asymmetry parameter g", "units": "1"}
    assert (-0.5 <= post["g"].values).all() and (post["g"].values <= 0.8).all()
    assert idata.sample_stats["autocorr_time"].sel(parameter="g").notnull().all()
    summary = summarize(idata)
    assert (summary["g_r_hat"] <= 1.01).all()
    # the data pin g down: posterior sd well below the prior's (1.3 / sqrt(12) = 0.375)
    assert (summary["g_sd"] < 0.5 * 1.3 / np.sqrt(12.0)).all()
    for name, transform in (("a", lambda x: x), ("tau", np.log), ("g", lambda x: x)):
        draws = transform(post[name].values.reshape(-1, 2))
        z = (draws.mean(axis=0) - transform(truth[name])) / draws.std(axis=0)
        assert (np.abs(z) < 4).all(), (name, z)


def test_g_beyond_its_prior_piles_at_the_bound_and_is_flagged(coarse_g_cache):
    """An opaque gonio film scattering with g = 0.9, beyond the prior's 0.8 (data from the direct
    solver): g piles at 0.8, and the prior-edge flags (the warning infer and report print, the
    summary's prior_edge column) say so at both wavelengths."""
    from bayespig.inference import infer_problem
    from bayespig.likelihood import Problem
    from bayespig.report.quantities import prior_edge_column, prior_edges

    ms = simulate(a=[0.05, 0.2], tau=1.0, g=0.9, design=[{"name": "opaque", "opaque": True}],
                  instrument="multi-angle-45", wavelengths=[450.0, 600.0], eps=0.01, seed=1)
    problem = Problem.from_measurements(ms, method="general")
    idata = infer_problem(problem, seed=0, g="free", eps=0.01, executor=None, progress=False, settings=FAST,
                          tables=_coarse_g_tables(problem, coarse_g_cache))
    assert [e["text"] for e in prior_edges(idata) if e["variable"] == "g"] == [
        "g is at its prior bound 0.8 at 450-600 nm: the data do not tell it from 0.8 or push it beyond its prior "
        "range [-0.5, 0.8]; unless it can truly be that close to 0.8, the model may be wrong for these data (or "
        "the prior too narrow)"]
    assert list(prior_edge_column(idata)) == ["g at 0.8", "g at 0.8"]


def test_general_problem_with_two_groups_has_tau_group():
    from bayespig.data import FilmSpec

    design = [FilmSpec("thin", substrate="black", film_group="thin"),
              FilmSpec("thin_white", substrate="white", film_group="thin"),
              FilmSpec("thick", substrate="white", tau_scale=3.0, film_group="thick")]
    ms = simulate(a=0.1, tau=0.5, design=design, wavelengths=[500.0], eps=0.05, seed=2)
    idata = infer(ms, method="general", progress=False, settings=FAST)
    post = idata.posterior
    assert post["tau_group"].dims == ("chain", "draw", "wavelength", "group")
    assert list(post["group"].values) == ["thin", "thick"]
    np.testing.assert_array_equal(post["tau"].values, post["tau_group"].values[..., 0])


_EPS_RANGE = "(0, 1) (a relative error, e.g. 0.02 for 2 %)"
_EPS_KIND = f"eps must be a number in {_EPS_RANGE}, 'infer' or None, got "
_VALID_METHODS = "1, 2, 3, 4, method1, method2, method3, method4, auto, general"
_SUBSTRATE_SD = "substrate_sd must be a positive number (the prior sd of log f, e.g. 0.1 for 10 %) or None, got "


@pytest.mark.parametrize("kwargs, error, message", [
    ({"eps": -1.0}, ValueError, f"eps must lie in {_EPS_RANGE}, got -1.0"),
    ({"eps": 5.0}, ValueError, f"eps must lie in {_EPS_RANGE}, got 5.0"),
    ({"eps": [0.05, 0.05]}, TypeError, _EPS_KIND + "list [0.05, 0.05]"),
    ({"eps": True}, TypeError, _EPS_KIND + "bool True"),
    ({"eps": "guess"}, ValueError, _EPS_KIND + "'guess'"),
    ({"g": "rayleigh"}, ValueError, "g must be 'isotropic' or 'free', got 'rayleigh'"),
    ({"seed": -1}, ValueError, "seed must be a non-negative integer, got -1"),
    ({"seed": True}, TypeError, "seed must be a non-negative integer, got bool True"),
    ({"seed": 1.5}, TypeError, "seed must be a non-negative integer, got float 1.5"),
    ({"method": "method9"}, ValueError, f"unknown method 'method9': method must be one of {_VALID_METHODS}"),
    ({"method": 5}, ValueError, f"unknown method 5: method must be one of {_VALID_METHODS}"),
    ({"method": True}, TypeError, f"method must be a method number or name ({_VALID_METHODS}), got bool True"),
    ({"executor": "x"}, TypeError, ("executor must be None (a local pool of 2 processes) or a concurrent.futures-style "
                                   "executor with a submit method (e.g. ProcessPoolExecutor, a dask client's "
                                   "get_executor()), got str 'x'")),
    ({"progress": "yes"}, TypeError, "progress must be True or False, got 'yes' (str)"),
    ({"priors": 3}, TypeError, "priors must be a bayespig.likelihood.Priors, got int"),
    ({"settings": {}}, TypeError, "settings must be an InferenceSettings, got dict"),
    ({"substrate_sd": True}, TypeError, _SUBSTRATE_SD + "bool True"),
    ({"substrate_sd": "0.1"}, TypeError, _SUBSTRATE_SD + "str '0.1'"),
    ({"substrate_sd": -0.1}, ValueError, _SUBSTRATE_SD + "-0.1"),
])
def test_bad_arguments_are_clear_errors(method4_set, tmp_path, kwargs, error, message):
    """One TypeError/ValueError naming the argument, for a set and, before the file is read,
    for a path that does not exist."""
    kwargs = {"progress": False, **kwargs}
    with pytest.raises(error) as caught:
        infer(method4_set, **kwargs)
    assert str(caught.value) == message
    with pytest.raises(error) as caught:
        infer(tmp_path / "not-read.csv", **kwargs)
    assert str(caught.value) == message


def test_measurements_of_another_kind_are_a_type_error():
    with pytest.raises(TypeError) as caught:
        infer(3, progress=False)
    assert str(caught.value) == "measurements must be a MeasurementSet or a path, got int"


def test_eps_cannot_be_inferred_from_as_many_values_as_parameters():
    """An 8°/d black/white pair has 2 values per band for a and tau: the fit is exact at every
    eps, so eps="infer" would run to max_steps at every band; it is refused before sampling."""
    pair = simulate(a=0.1, tau=1.0, design="method4", instrument="8d-sce", wavelengths=[400.0, 550.0, 700.0],
                    eps=0.02, seed=1)
    with pytest.raises(ValueError) as caught:
        infer(pair, eps="infer", progress=False, settings=FAST)
    assert str(caught.value) == ("eps cannot be inferred: at 400–700 nm there are only 2 values for 2 "
                                 "parameters (a, tau); give eps (e.g. eps=0.02, or --eps 0.02 on the "
                                 "command line)")


def test_odd_walkers_refused(method4_set):
    one = simulate(a=0.1, tau=1.0, design="method4", wavelengths=[500.0], eps=0.05, seed=1)
    with pytest.raises(ValueError, match="n_walkers"):
        infer(one, progress=False, settings=InferenceSettings(n_walkers=7))


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(Exception, match="nothing.csv"):
        infer(tmp_path / "nothing.csv", progress=False)


def test_method3_posterior_shows_the_ravine():
    """Method 3 (one thin film on black): a strongly correlated with log tau, and a tau spread
    more than ten times method 4's for the same film (issue 6; paper section 4.2)."""
    kwargs = {"a": 0.1, "tau": 1.0, "wavelengths": [550.0], "eps": 0.05, "seed": 21}
    # a shorter run than the default 50 tau_int (tau_int ~ 100 steps here): the shape of the
    # posterior is tested, not the run-length rule
    shorter = InferenceSettings(**{**FAST.__dict__, "min_autocorr_multiple": 20.0})
    m3 = infer(simulate(design="method3", **kwargs), progress=False, settings=shorter)
    m4 = infer(simulate(design="method4", **kwargs), progress=False, settings=FAST)
    s3, s4 = summarize(m3).iloc[0], summarize(m4).iloc[0]
    assert s3["corr_a_log_tau"] > RAVINE_CORRELATION
    assert s3["tau_sd"] > RAVINE_SPREAD_RATIO * s4["tau_sd"]
    assert diagnose(m3, warn=False) == []


def test_method4_posterior_sd_matches_the_frequentist_rms():
    """Where the posterior is well identified (method 4, tau0 <= 1) its sd is the spread of
    the point fits over noisy replicates (issue 6: within a factor 1.5)."""
    from bayespig.studies.robustness import robustness_study

    a0, tau0 = 0.1, 1.0
    result = robustness_study("method4", a0, tau0, n_repeat=200, seed=3)
    # one simulated set; its 4 wavelengths are 4 independent sets of the same pigment
    ms = simulate(a=a0, tau=tau0, design="method4", wavelengths=[450.0, 500.0, 550.0, 600.0],
                  eps=0.05, seed=8)
    summary = summarize(infer(ms, progress=False, settings=FAST, executor=None))
    a_ratio = summary["a_sd"].mean() / result.a_rms
    tau_ratio = summary["tau_sd"].mean() / result.tau_rms
    assert 1 / SD_RMS_FACTOR < a_ratio < SD_RMS_FACTOR
    assert 1 / SD_RMS_FACTOR < tau_ratio < SD_RMS_FACTOR


def test_priors_are_recorded_and_respected():
    one = simulate(a=0.1, tau=1.0, design="method4", wavelengths=[500.0], eps=0.05, seed=1)
    priors = Priors(a_range=(0.05, 0.5), tau_range=(0.2, 20.0))
    idata = infer(one, progress=False, settings=FAST, priors=priors)
    assert json.loads(idata.posterior.attrs["priors"])["a"] == "uniform on [0.05, 0.5]"
    assert idata.posterior["a"].min() >= 0.05 and idata.posterior["tau"].max() <= 20.0


def test_no_stray_warnings_on_a_clean_run(method4_set):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        infer(simulate(a=0.1, tau=1.0, design="method4", wavelengths=[500.0], eps=0.05, seed=1),
              progress=False, settings=FAST)
