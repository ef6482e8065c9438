"""The report's numbers against independent references: colour-science, the likelihood, numpy."""

import warnings

import colour
import numpy as np
import pytest
from colour.utilities import ColourRuntimeWarning
from scipy import stats

from bayespig import colorimetry
from bayespig.likelihood import ForwardModel, LogPosterior, Priors, Problem
from bayespig.report import quantities as q

XYZ_TOL = 1e-6  # the fast colour path vs colour.sd_to_XYZ, XYZ on the 0-1 scale (issue 7)
LAB_TOL = 1e-3  # L* = 116 f(Y) - 16 amplifies an XYZ error of 1e-6 by at most ~500 for dark colours
# the same eq. (7) terms through the same table; the stored ones in single precision (6e-8 of
# values up to ~15 in magnitude)
LOGLIK_TOL = 2e-6
STORED_RTOL = 2e-7  # against the stored single-precision predictions (rounding 6e-8)


def test_parameter_bands_are_exact_quantiles():
    draws = np.linspace(0.0, 1.0, 1001)[:, None] * np.array([1.0, 2.0])
    bands = q.parameter_bands(draws)
    np.testing.assert_allclose(bands["q05"], [0.05, 0.1])
    np.testing.assert_allclose(bands["q25"], [0.25, 0.5])
    np.testing.assert_allclose(bands["median"], [0.5, 1.0])
    np.testing.assert_allclose(bands["q95"], [0.95, 1.9])
    np.testing.assert_allclose(bands["mean"], [0.5, 1.0])


def test_extinction_follows_appendix_a2():
    out = q.extinction(np.array([2.0, 4.0]), thickness_um=4.0, concentration=0.5)
    np.testing.assert_allclose(out["k_ext"], [0.5, 1.0])  # tau / H
    np.testing.assert_allclose(out["sigma_ext"], [1.0, 2.0])  # tau / (H D)
    assert "sigma_ext" not in q.extinction(np.ones(2), thickness_um=1.0)
    with pytest.raises(ValueError, match="thickness_um"):
        q.extinction(np.ones(2), thickness_um=0.0)
    with pytest.raises(ValueError, match="concentration"):
        q.extinction(np.ones(2), thickness_um=1.0, concentration=-1.0)


def test_priors_are_read_back_from_the_recorded_text(demo_idata):
    assert q.priors_from_inference(demo_idata) == Priors()
    custom = Priors(tau_range=(0.05, 50.0), a_range=(0.0, 0.5))
    idata = demo_idata.copy()
    idata.posterior.attrs["priors"] = __import__("json").dumps(custom.describe())
    assert q.priors_from_inference(idata) == custom


def test_rebuilt_problem_reproduces_the_stored_log_likelihood(demo_idata, demo_set):
    """The Problem rebuilt from the netCDF file equals the one inferred from, value by value."""
    rebuilt = q.problem_from_inference(demo_idata)
    original = Problem.from_measurements(demo_set, "method4")
    assert [f.name for f in rebuilt.films] == [f.name for f in original.films]
    assert rebuilt.groups == original.groups and rebuilt.method == original.method
    for mine, theirs in zip(rebuilt.films, original.films):
        assert mine.instrument.labels == theirs.instrument.labels
        np.testing.assert_array_equal(mine.observed, theirs.observed)
        np.testing.assert_array_equal(mine.r_s, theirs.r_s)
    model = ForwardModel(rebuilt, "isotropic")
    assert model.table_keys == tuple(__import__("json").loads(demo_idata.attrs["table_keys"]))
    index = 4
    a = demo_idata.posterior["a"].values[:, :50, index].ravel()
    tau = demo_idata.posterior["tau"].values[:, :50, index].ravel()
    stored = demo_idata.log_likelihood["y"].values[:, :50, index].reshape(a.size, -1)
    log_post = LogPosterior(model, index, Priors(), "isotropic", 0.05)
    mine = log_post.log_likelihood(np.column_stack([a, np.log(tau)]), pointwise=True)
    np.testing.assert_allclose(mine, stored, rtol=0, atol=LOGLIK_TOL)


def _sd_to_Lab(reflectance, wavelength_nm, observer, illuminant, method):
    """colour-science's own path: sd_to_XYZ and XYZ_to_Lab with the white of the same grid."""
    cmfs = colour.MSDS_CMFS[observer]
    sd_illuminant = colour.SDS_ILLUMINANTS[illuminant]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ColourRuntimeWarning)
        XYZ = colour.sd_to_XYZ(colour.SpectralDistribution(reflectance, wavelength_nm), cmfs,
                               sd_illuminant, method=method) / 100.0
        white = colour.sd_to_XYZ(colour.SpectralDistribution(np.ones_like(reflectance), wavelength_nm),
                                 cmfs, sd_illuminant, method=method) / 100.0
    xyY = np.array([white[0] / white.sum(), white[1] / white.sum(), white[1]])
    return XYZ, colour.XYZ_to_Lab(XYZ, illuminant=xyY)


def test_measured_colour_equals_colour_science(demo_idata):
    wl = q.wavelengths(demo_idata)
    rows = q.measured_colour(demo_idata)
    observed = demo_idata.observed_data["y"].values
    assert len(rows) == observed.shape[1]  # every sample and geometry
    method = colorimetry.colorimetric_metadata(wl)["method"]  # 30 nm steps: "Integration"
    for k in (0, 7):
        reflectance = np.pi * observed[:, k]  # BRDF -> reflectance factor
        XYZ, Lab = _sd_to_Lab(reflectance, wl, colorimetry.DEFAULT_OBSERVER,
                              colorimetry.DEFAULT_ILLUMINANT, method)
        fast = colorimetry.reflectance_to_XYZ(reflectance, wl)
        np.testing.assert_allclose(fast, XYZ, rtol=0, atol=XYZ_TOL)
        np.testing.assert_allclose(rows[k]["Lab_measured"], Lab, rtol=0, atol=LAB_TOL)


def test_colour_spread_vanishes_for_a_point_posterior(demo_idata):
    """Every draw predicting the observed values: zero spread and zero measured-predicted Delta E."""
    idata = demo_idata.copy()
    y = idata.posterior_predictive["y"]
    idata.posterior_predictive["y"] = y * 0 + idata.observed_data["y"]
    for row in q.measured_colour(idata):
        assert row["dE00_spread"] == pytest.approx(0.0, abs=1e-9)
        assert row["dE00_measured_predicted"] == pytest.approx(0.0, abs=1e-9)


def test_predicted_films_match_the_posterior_predictive_of_the_measured_film(demo_idata):
    """A predicted '1 x tau on black' is the measured on-black film: same draws, same values."""
    films = [q.FilmDesign("same as measured", 1.0, 0.01), q.FilmDesign("opaque", np.inf)]
    _, values = q.predicted_film_values(demo_idata, films, max_draws=64)
    predictive = q.residuals_in_eps(demo_idata, max_draws=64)["predicted_draws"]
    on_black = [k for k, r in enumerate(q.value_table(demo_idata)) if r["sample"] == "on_black"]
    np.testing.assert_allclose(values[0], predictive[..., on_black], rtol=STORED_RTOL)
    # physics: an opaque layer reflects more than the same layer on black (it adds the
    # light the black substrate would absorb), at every geometry
    assert np.all(values[1] > values[0])


def test_film_colour_covers_every_film_and_geometry(demo_idata):
    films = q.default_unmeasured_films(q.problem_from_inference(demo_idata))
    labels = [f.label for f in films]
    assert "opaque (hiding)" in labels and "2 x tau on white" in labels
    assert "1 x tau on black" not in labels  # measured (method 4): not a prediction
    rows = q.film_colour(demo_idata, films, max_draws=64)
    assert len(rows) == len(films) * 6
    assert all(r["dE00_spread"] >= 0 and 0 <= r["Lab"][0] <= 100 for r in rows)


def test_diagnostics_flag_a_chain_that_disagrees(demo_idata):
    clean = q.diagnostics(demo_idata)
    assert set(clean["ess"]) == {"a", "tau"} and clean["n_chains"] == 4
    idata = demo_idata.copy()
    a = idata.posterior["a"]
    shifted = a.values.copy()
    shifted[0] += 0.05  # chain 0 somewhere else: R-hat must see it
    idata.posterior["a"] = a.copy(data=shifted)
    diag = q.diagnostics(idata)
    assert np.all(diag["rhat"]["a"] > 1.1)
    flagged = {f["wavelength_nm"] for f in diag["flags"]}
    assert flagged == set(q.wavelengths(idata))
    assert all(any("R-hat(a)" in r for r in f["reasons"]) for f in diag["flags"])


def test_ravine_peaks_at_the_posterior(demo_idata):
    index = 5
    rv = q.ravine(demo_idata, index, n_grid=81)
    assert rv.log_likelihood.shape == (81, 81)
    j, i = np.unravel_index(np.nanargmax(rv.log_likelihood), rv.log_likelihood.shape)
    a = demo_idata.posterior["a"].values[..., index]
    tau = demo_idata.posterior["tau"].values[..., index]
    # the grid maximum is within one grid step of the posterior's central 99 % box
    da, dlog = rv.a[1] - rv.a[0], np.log(rv.tau[1] / rv.tau[0])
    assert np.quantile(a, 0.005) - da <= rv.a[i] <= np.quantile(a, 0.995) + da
    assert np.log(np.quantile(tau, 0.005)) - dlog <= np.log(rv.tau[j]) <= np.log(np.quantile(tau, 0.995)) + dlog


# ------------------------------------------------------------------------------------------
# posterior predictive check

PPC_MONTE_CARLO = 20000  # replicates per draw: the Monte Carlo p has sd <= 0.0035
PPC_MC_TOL = 0.02  # ~5 sd of that Monte Carlo error, on p-values of ~0.01-0.9


def _with_observed(idata, observed):
    """A copy of ``idata`` whose observed data are replaced."""
    copy = idata.copy()
    copy.observed_data["y"].values[...] = observed
    return copy


def test_posterior_predictive_p_value_matches_replicated_data(demo_idata):
    """p against replicates x_rep = m (1 + eps xi) drawn from a seeded generator (eq. 7)."""
    check = q.posterior_predictive_check(demo_idata, max_draws=8)
    predicted = q._thin(np.asarray(demo_idata.posterior_predictive["y"].values, dtype=float)
                        .reshape((-1,) + demo_idata.posterior_predictive["y"].shape[2:]), 8)
    observed = np.asarray(demo_idata.observed_data["y"].values, dtype=float)
    eps = q.eps_per_value(demo_idata)
    rng = np.random.default_rng(11)
    p_mc = np.empty(observed.shape[0])
    for i in range(observed.shape[0]):
        m = predicted[:, i]  # (draws, values)
        t_obs = (((observed[i] - m) / (eps[i] * m)) ** 2).sum(axis=-1)
        xi = rng.standard_normal((PPC_MONTE_CARLO,) + m.shape)
        t_rep = (xi ** 2).sum(axis=-1)  # ((m (1 + eps xi) - m) / (eps m))^2 = xi^2
        p_mc[i] = (t_rep >= t_obs).mean()
    np.testing.assert_allclose(check["p_value"], p_mc, atol=PPC_MC_TOL)
    assert check["n_values"].min() == observed.shape[1]


def test_posterior_predictive_check_passes_the_model_and_flags_a_corrupted_band(demo_idata):
    """Simulated from the model: nothing flagged; one value off by 10 eps: exactly that band flagged."""
    check = q.posterior_predictive_check(demo_idata)
    assert not check["flagged"].any(), check["p_value"]
    assert np.median(check["p_value"]) > 0.2  # conservative: p piles up around 0.5 for a fitting model
    observed = np.asarray(demo_idata.observed_data["y"].values, dtype=float).copy()
    eps = q.eps_per_value(demo_idata)
    band, value = 2, 3
    observed[band, value] *= 1.0 + 10.0 * eps[band, value]
    corrupted = q.posterior_predictive_check(_with_observed(demo_idata, observed))
    assert np.flatnonzero(corrupted["flagged"]).tolist() == [band]
    assert corrupted["worst"][band] == value
    assert corrupted["z"][band, value] > 8.0
    with pytest.raises(ValueError, match="level"):
        q.posterior_predictive_check(demo_idata, level=1.5)


def test_randomised_residuals_of_censored_readings_are_standard_normal():
    # Dunn & Smyth (1996): readings max(mu + sigma xi, 0); a zero's residual Phi^-1(u P0), P0 = Phi(-mu / sigma),
    # a positive reading's (x - mu) / sigma: all N(0, 1) under the model. 200 000 values with ~30 % zeros;
    # mean, variance and the 90 % tail fraction within 4.5 sd of their sampling error
    rng = np.random.default_rng(7)
    n = 200_000
    mu = rng.uniform(-1.0, 3.0, n)
    sigma = rng.uniform(0.5, 1.5, n)
    reading = np.maximum(mu + sigma * rng.standard_normal(n), 0.0)
    zero = reading == 0
    assert 0.2 < zero.mean() < 0.4
    z = np.where(zero, q._censored_residual(rng.uniform(size=n) * stats.norm.cdf(-mu / sigma)), (reading - mu) / sigma)
    assert abs(z.mean()) < 4.5 / np.sqrt(n)
    assert abs(z.var() - 1.0) < 4.5 * np.sqrt(2.0 / n)
    tail = (np.abs(z) > stats.norm.ppf(0.95)).mean()
    assert abs(tail - 0.1) < 4.5 * np.sqrt(0.09 / n)
    # an impossible zero (P0 underflows) stays finite and far out
    assert np.isfinite(q._censored_residual(np.array([0.0]))).all() and q._censored_residual(np.array([0.0]))[0] < -30
