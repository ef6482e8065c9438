"""Prior-edge flags (bayespig.report.quantities.prior_edges) on posteriors built by hand.

Each posterior is drawn from a known distribution: one piled against a bound of its prior,
one well inside it, one that is the prior itself, so whether each must be flagged is known
without running the sampler.
"""

import json

import arviz as az
import numpy as np
import pytest

from bayespig.report import quantities as q

WAVELENGTHS_NM = np.array([400.0, 450.0, 500.0, 550.0, 600.0])
N_CHAINS, N_DRAWS = 4, 1000
#: Default priors of bayespig.likelihood.Priors, as infer records them.
BOUNDS = {"a": {"lower": 0.0, "upper": 1.0, "scale": "linear"},
          "g": {"lower": -0.5, "upper": 0.8, "scale": "linear"},
          "eps": {"lower": 1e-3, "upper": 0.5, "scale": "log"}}


def _idata(posterior, bounds=BOUNDS, dims=None, coords=None):
    idata = az.from_dict(posterior=posterior, dims=dims or {name: ["wavelength"] for name in posterior},
                         coords={"wavelength": WAVELENGTHS_NM, **(coords or {})})
    idata.posterior.attrs["prior_bounds"] = json.dumps(bounds)
    return idata


def _draws(sampler, size=None):
    rng = np.random.default_rng(7)
    return sampler(rng, (N_CHAINS, N_DRAWS) + ((WAVELENGTHS_NM.size,) if size is None else size))


def test_a_piled_at_zero_is_flagged_and_a_posterior_inside_is_not():
    # 400-500 nm: half-normal against 0 (sd 0.01); 550, 600 nm: normal 0.3 +- 0.01
    half = np.abs(_draws(lambda r, s: r.normal(0.0, 0.01, s)))
    inside = _draws(lambda r, s: r.normal(0.3, 0.01, s))
    a = np.where(WAVELENGTHS_NM <= 500.0, half, inside)
    edges = q.prior_edges(_idata({"a": a}))
    assert [e["text"] for e in edges] == [
        ("a is at its prior bound 0 at 400-500 nm: the data do not tell it from 0 or push it beyond its prior "
        "range [0, 1]; unless it can truly be that close to 0, the model may be wrong for these data (or the "
        "prior too narrow)")]
    assert edges[0]["bound"] == "lower" and edges[0]["value"] == 0.0
    assert edges[0]["wavelength_nm"] == [400.0, 450.0, 500.0]
    assert q.prior_edge_column(_idata({"a": a})) == ["a at 0", "a at 0", "a at 0", "", ""]


def test_flagged_wavelengths_are_named_as_runs_of_the_grid():
    half = np.abs(_draws(lambda r, s: r.normal(0.0, 0.01, s)))
    inside = _draws(lambda r, s: r.normal(0.3, 0.01, s))
    a = np.where(np.isin(WAVELENGTHS_NM, [400.0, 500.0, 550.0]), half, inside)
    assert " at 400, 500-550 nm: " in q.prior_edges(_idata({"a": a}))[0]["text"]


def test_a_pressed_against_zero_far_below_its_spread():
    """The Cornell case: a ~ 1e-15 at every band, the draws a sliver next to the bound."""
    a = _draws(lambda r, s: r.uniform(0.99e-15, 1.01e-15, s))
    edges = q.prior_edges(_idata({"a": a}))
    assert [(e["parameter"], e["bound"], e["wavelength_nm"]) for e in edges] == [
        ("a", "lower", WAVELENGTHS_NM.tolist())]
    assert "at 400-600 nm" in edges[0]["text"]


@pytest.mark.parametrize(("sds_from_bound", "flagged"), [(0.5, True), (1.2, True), (2.0, False), (3.0, False)])
def test_the_threshold_for_a_normal_likelihood_cut_by_the_bound(sds_from_bound, flagged):
    """PRIOR_EDGE_FRACTION = 0.1 flags a normal cut within 1.5 sd of its peak (and none beyond)."""
    from scipy import stats

    sd = 0.02
    cut = stats.truncnorm(-sds_from_bound, np.inf, loc=sds_from_bound * sd, scale=sd)
    a = cut.rvs(size=(N_CHAINS, N_DRAWS, WAVELENGTHS_NM.size), random_state=np.random.default_rng(3))
    assert bool(q.prior_edges(_idata({"a": a}))) is flagged


def test_g_at_its_upper_limit_and_g_that_fills_its_prior():
    g_pinned = 0.8 - np.abs(_draws(lambda r, s: r.normal(0.0, 0.005, s)))  # g='free' pinned at 0.8
    g_prior = _draws(lambda r, s: r.uniform(-0.5, 0.8, s))  # the posterior is the prior
    g = np.where(WAVELENGTHS_NM < 500.0, g_pinned, g_prior)
    a = _draws(lambda r, s: r.normal(0.3, 0.01, s))
    texts = [e["text"] for e in q.prior_edges(_idata({"a": a, "g": g}))]
    assert texts == [
        ("g fills its whole prior range [-0.5, 0.8] at 500-600 nm: the data do not identify it (its "
        "posterior is its prior)"),
        ("g is at its prior bound 0.8 at 400-450 nm: the data do not tell it from 0.8 or push it beyond its "
        "prior range [-0.5, 0.8]; unless it can truly be that close to 0.8, the model may be wrong for these "
        "data (or the prior too narrow)")]
    assert q.prior_edge_column(_idata({"a": a, "g": g})) == [
        "g at 0.8", "g at 0.8", "g fills [-0.5, 0.8]", "g fills [-0.5, 0.8]", "g fills [-0.5, 0.8]"]


def test_eps_is_judged_in_log_where_its_prior_is_flat():
    # log-uniform on [1e-3, 0.5] (its prior): fills the range; in linear units it would look
    # piled at 1e-3 only
    eps_prior = np.exp(_draws(lambda r, s: r.uniform(np.log(1e-3), np.log(0.5), s)))
    a = _draws(lambda r, s: r.normal(0.3, 0.01, s))
    edges = q.prior_edges(_idata({"a": a, "eps": eps_prior}))
    assert [(e["parameter"], e["bound"]) for e in edges] == [("eps", "both")]
    eps_inside = np.exp(_draws(lambda r, s: r.normal(np.log(0.02), 0.1, s)))
    assert q.prior_edges(_idata({"a": a, "eps": eps_inside})) == []


def test_a_shared_parameter_is_flagged_per_label_without_wavelengths():
    a = _draws(lambda r, s: r.normal(0.3, 0.01, s))
    # card "white": r_s f <= 1 cuts the factor at 1 / 0.95; card "black": inside its prior
    upper = 1.0 / 0.95
    white = upper * np.exp(-np.abs(_draws(lambda r, s: r.normal(0.0, 0.003, s), size=())))
    black = np.exp(_draws(lambda r, s: r.normal(0.0, 0.01, s), size=()))
    factor = np.stack([white, black], axis=-1)
    bounds = {**BOUNDS, "r_s_factor": {"lower": [np.exp(-0.15), np.exp(-0.15)], "upper": [upper, np.exp(0.15)],
                                       "scale": "log"}}
    idata = _idata({"a": a, "r_s_factor": factor}, bounds, dims={"a": ["wavelength"], "r_s_factor": ["card"]},
                   coords={"card": ["white", "black"]})
    edges = q.prior_edges(idata)
    assert [e["text"] for e in edges] == [
        ("r_s_factor[white] is at its prior bound 1.05263: the data do not tell it from 1.05263 or push it "
        "beyond its prior range [0.860708, 1.05263]; unless it can truly be that close to 1.05263, the model "
        "may be wrong for these data (or the prior too narrow)")]
    assert edges[0]["wavelength_nm"] is None and edges[0]["label"] == "white"
    assert q.prior_edge_column(idata) == [""] * WAVELENGTHS_NM.size  # not a per-wavelength parameter


def test_any_parameter_with_recorded_bounds_is_checked():
    """A new shared parameter (e.g. a roughness) needs only its bounds in the attribute."""
    a = _draws(lambda r, s: r.normal(0.3, 0.01, s))
    roughness = np.abs(_draws(lambda r, s: r.normal(0.0, 0.01, s), size=()))[..., None]
    bounds = {**BOUNDS, "roughness": {"lower": [0.0], "upper": [1.0], "scale": "linear"}}
    idata = _idata({"a": a, "roughness": roughness}, bounds, dims={"a": ["wavelength"], "roughness": ["film"]},
                   coords={"film": ["paint"]})
    assert [e["parameter"] for e in q.prior_edges(idata)] == ["roughness[paint]"]


def test_a_posterior_without_recorded_bounds_uses_its_priors_text():
    a = np.abs(_draws(lambda r, s: r.normal(0.0, 0.01, s)))
    idata = az.from_dict(posterior={"a": a}, dims={"a": ["wavelength"]}, coords={"wavelength": WAVELENGTHS_NM})
    idata.posterior.attrs["priors"] = json.dumps({"a": "uniform on [0, 1]"})
    assert q.prior_bounds(idata) == {"a": {"lower": 0.0, "upper": 1.0, "scale": "linear"}}
    assert [e["bound"] for e in q.prior_edges(idata)] == ["lower"]


def test_infer_records_the_support_of_every_prior():
    """bayespig.inference._prior_bounds: the box of a, tau, g, eps and of any shared parameter."""
    from bayespig.inference import _prior_bounds
    from bayespig.likelihood import Priors

    class Roughness:  # a shared parameter as the joint sampler's specs describe it
        variable = "roughness"
        lower, upper = np.array([np.log(1e-3)]), np.array([np.log(0.5)])
        prior_scale = "log"

        def physical(self, x):
            return np.exp(x)

    posterior = {name: None for name in ("a", "tau", "g", "roughness")}
    bounds = _prior_bounds(Priors(g_range=(-0.3, 0.9)), posterior, [Roughness()])
    assert bounds["a"] == {"lower": 0.0, "upper": 1.0, "scale": "linear"}
    assert bounds["tau"] == {"lower": 0.01, "upper": 100.0, "scale": "log"}
    assert bounds["g"] == {"lower": -0.3, "upper": 0.9, "scale": "linear"}
    assert "eps" not in bounds  # not a parameter of this posterior
    np.testing.assert_allclose(bounds["roughness"]["lower"], [1e-3])
    np.testing.assert_allclose(bounds["roughness"]["upper"], [0.5])
    assert bounds["roughness"]["scale"] == "log"
