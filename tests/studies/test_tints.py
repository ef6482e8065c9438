"""Tint protocol (bayespig.studies.tints) on simulated mixtures with a known truth."""

import numpy as np
import pytest

from bayespig import kubelka_munk as km
from bayespig.data import simulate
from bayespig.data.simulate import FilmSpec
from bayespig.physics.mixtures import concentrations_from_mass_fractions, mixture_properties
from bayespig.studies.tints import (
    KubelkaMunkTintModel,
    RadiativeTransferTintModel,
    mixture_weight_ratio,
    predict_tint,
)
from bayespig.table import load_table

WAVELENGTHS = np.array([400.0, 460.0, 520.0, 580.0, 640.0, 700.0])
CARDS = (0.11, 0.90)  # r_s of the Revigo cards seen from the binder, roughly
THICKNESS = {"A": 1.2, "W": 1.0, "B": 0.8, "C": 1.3}  # relative to the white film
MASS_B, MASS_C = (0.1, 0.9), (0.5, 0.5)
# Noise-free data: what is left is the look-up table's interpolation error (~1e-5
# relative) propagated through the black/white fits and the fitted thickness.
THICKNESS_RTOL = 2e-3
SPECTRUM_RTOL = 2e-3
DELTA_E_TOL = 0.05  # far below a visible difference (~1)


def _design():
    return [FilmSpec("ob", substrate=CARDS[0], film_group="f"), FilmSpec("ow", substrate=CARDS[1], film_group="f")]


def _films(model_callable, intensive, extensive_per_thickness):
    """Simulated masstone A, white W and tints B, C (dict of MeasurementSet)."""
    return {
        name: simulate(a=intensive[name], tau=THICKNESS[name] * extensive_per_thickness[name], design=_design(),
                       instrument="8d-sce", wavelengths=WAVELENGTHS, eps=0.0, model=model_callable)
        for name in "AWBC"
    }


def _truth_bayespig():
    a_P = np.array([0.45, 0.40, 0.20, 0.05, 0.02, 0.015])
    sigma_P = np.array([6.0, 5.0, 4.0, 3.5, 3.0, 2.5])
    a_W = np.array([0.01, 0.003, 0.002, 0.002, 0.002, 0.002])
    sigma_W = np.array([12.0, 10.0, 9.0, 8.0, 7.5, 7.0])
    D_B = concentrations_from_mass_fractions(np.array(MASS_B))
    D_C = concentrations_from_mass_fractions(np.array(MASS_C))
    a_B, k_B = mixture_properties(D_B, np.stack([a_P, a_W]), np.stack([sigma_P, sigma_W]))
    a_C, k_C = mixture_properties(D_C, np.stack([a_P, a_W]), np.stack([sigma_P, sigma_W]))
    intensive = {"A": a_P, "W": a_W, "B": a_B, "C": a_C}
    extensive = {"A": sigma_P, "W": sigma_W, "B": k_B, "C": k_C}
    return intensive, extensive, D_B, D_C


@pytest.fixture(scope="module")
def table():
    return load_table("8d-sce", progress=False)


def test_weight_ratio_inverts_the_mixing_rule():
    u_P, u_W, y = np.array([0.5, 2.0, 0.1]), np.array([0.01, 0.02, 0.3]), np.array([0.2, 3.0, 0.7])
    u_B = (y * u_P + u_W) / (y + 1.0)
    ratio, determined = mixture_weight_ratio(u_P, u_W, u_B)
    np.testing.assert_allclose(ratio, y, rtol=1e-12)
    assert determined.all()
    # A tint outside [u_W, u_P] (noise) is not determined there and is interpolated in log y.
    u_B_bad = u_B.copy()
    u_B_bad[1] = u_P[1] * 1.1
    ratio, determined = mixture_weight_ratio(u_P, u_W, u_B_bad)
    assert determined.tolist() == [True, False, True]
    assert ratio[1] == pytest.approx(np.sqrt(y[0] * y[2]), rel=1e-12)
    with pytest.raises(ValueError, match="does not determine"):
        mixture_weight_ratio(u_P, u_W, u_W)


def test_bayespig_protocol_recovers_simulated_tint(table):
    intensive, extensive, D_B, D_C = _truth_bayespig()
    films = _films(table, intensive, extensive)
    model = RadiativeTransferTintModel("8d-sce", table=table)
    p = predict_tint(model, masstone=films["A"], white=films["W"], tint_b=films["B"], tint_c=films["C"],
                     concentrations_b=tuple(D_B), concentrations_c=tuple(D_C))
    assert p.thickness == pytest.approx(THICKNESS["C"] / THICKNESS["W"], rel=THICKNESS_RTOL)
    np.testing.assert_allclose(p.predicted, p.measured, rtol=SPECTRUM_RTOL)
    np.testing.assert_allclose(p.intensive, intensive["C"], rtol=SPECTRUM_RTOL, atol=1e-4)
    assert p.determined.all()
    assert np.all(p.delta_E < DELTA_E_TOL)


def test_kubelka_munk_protocol_recovers_simulated_tint():
    k1, k2 = km.saunderson_constants(1.45, 8.0)
    K_P, S_P = np.array([3.0, 2.5, 1.2, 0.3, 0.1, 0.08]), np.array([4.0, 3.5, 3.0, 3.0, 2.8, 2.5])
    K_W, S_W = np.array([0.1, 0.03, 0.02, 0.02, 0.02, 0.02]), np.array([6.0, 5.5, 5.0, 4.5, 4.2, 4.0])
    D_B = concentrations_from_mass_fractions(np.array(MASS_B))
    D_C = concentrations_from_mass_fractions(np.array(MASS_C))
    K = {"A": K_P, "W": K_W}
    S = {"A": S_P, "W": S_W}
    for name, D in (("B", D_B), ("C", D_C)):
        K[name], S[name] = km.mix_K_S(D, np.stack([K_P, K_W]), np.stack([S_P, S_W]))

    def km_model(*, a, tau, g=0.0, r_s=0.0):
        # a carries K/S and tau carries S*X for the simulator's (a, tau) interface
        return km.predict_measured(a * tau, tau, r_s, specular="excluded", k1=k1, k2=k2)[..., None]

    intensive = {n: K[n] / S[n] for n in "AWBC"}
    assert max(v.max() for v in intensive.values()) <= 1.0  # the simulator checks a <= 1
    films = _films(km_model, intensive, S)
    p = predict_tint(KubelkaMunkTintModel("excluded"), masstone=films["A"], white=films["W"],
                     tint_b=films["B"], tint_c=films["C"], concentrations_b=tuple(D_B),
                     concentrations_c=tuple(D_C))
    # exact closed forms throughout: only rounding and the scalar optimiser's tolerance remain
    assert p.thickness == pytest.approx(THICKNESS["C"], rel=1e-5)
    np.testing.assert_allclose(p.predicted, p.measured, rtol=1e-6)
    np.testing.assert_allclose(p.intensive, intensive["C"], rtol=1e-8)


def test_anisotropic_tint_model_needs_a_g_table(table):
    with pytest.raises(ValueError, match="g axis"):
        RadiativeTransferTintModel("8d-sce", table=table, g=0.5)


def test_protocol_rejects_bad_concentrations(table):
    intensive, extensive, _, D_C = _truth_bayespig()
    films = _films(table, intensive, extensive)
    with pytest.raises(ValueError, match="concentrations_b"):
        predict_tint(KubelkaMunkTintModel("excluded"), masstone=films["A"], white=films["W"],
                     tint_b=films["B"], tint_c=films["C"], concentrations_b=(0.0, 1.0),
                     concentrations_c=tuple(D_C))
    with pytest.raises(ValueError, match="specular"):
        KubelkaMunkTintModel("sce")


def test_credible_region_coverage():
    from bayespig.studies.tints import credible_region_contains

    rng = np.random.default_rng(90)
    cov = np.array([[1.0, 0.5, 0.0], [0.5, 2.0, 0.3], [0.0, 0.3, 0.5]])
    draws = rng.multivariate_normal(np.zeros(3), cov, size=4000)
    fresh = rng.multivariate_normal(np.zeros(3), cov, size=400)
    covered = np.mean([credible_region_contains(draws, x, 0.9) for x in fresh])
    # binomial sd of a 90 % coverage over 400 points is 1.5 %; allow ~3 sd
    assert covered == pytest.approx(0.9, abs=0.045)
    assert not credible_region_contains(draws, [6.0, 0.0, 0.0], 0.9)
    with pytest.raises(ValueError, match="probability"):
        credible_region_contains(draws, [0, 0, 0], 1.0)


def _synthetic_tints(rng, n_series, model_cov, n_draws=200, param_sd=0.2):
    """TintPosteriors whose measured colour misses the prediction by N(0, model_cov)."""
    from bayespig.studies.tints import TintPosterior

    out = {}
    for k in range(n_series):
        centre = rng.uniform([20, -30, -30], [90, 30, 30], size=(2, 3))
        draws = centre + param_sd * rng.standard_normal((n_draws, 2, 3))
        measured = centre + rng.multivariate_normal(np.zeros(3), model_cov, size=2)
        out[f"{k:03d}"] = TintPosterior(draws, measured, np.ones(n_draws), np.zeros((n_draws, 2)),
                                        np.zeros(2, bool), 0.9)
    return out


def test_cross_validated_model_error_covers_at_the_nominal_level():
    """Exchangeable series with Gaussian model error: the leave-one-out regions cover the
    measured colours 90 % of the time (binomial sd 1.2 % over 600 cards), where the
    parameter-only regions (sd 0.2 against a model error of ~2 ΔE) almost never do."""
    from bayespig.studies.tints import credible_region_contains, cross_validated_model_error

    rng = np.random.default_rng(17)
    model_cov = np.array([[4.0, 1.0, 0.0], [1.0, 2.0, -0.5], [0.0, -0.5, 3.0]])
    posteriors = _synthetic_tints(rng, 300, model_cov)
    regions = cross_validated_model_error(posteriors, probability=0.9, seed=1)
    covered = np.mean([r.inside for r in regions.values()])
    assert covered == pytest.approx(0.9, abs=4.5 * np.sqrt(0.09 / 600))
    narrow = np.mean([[credible_region_contains(p.lab_draws[:, j], p.lab_measured[j]) for j in (0, 1)]
                      for p in posteriors.values()])
    assert narrow < 0.1
    one = next(iter(regions.values()))
    np.testing.assert_allclose(one.covariance, model_cov, rtol=0.25, atol=0.4)
    assert one.n_residuals == 2 * 299


def test_cross_validated_model_error_leaves_the_series_out():
    """A series' own measurement does not enter its own model error."""
    from bayespig.studies.tints import TintPosterior, cross_validated_model_error

    rng = np.random.default_rng(3)
    posteriors = _synthetic_tints(rng, 5, np.eye(3))
    before = cross_validated_model_error(posteriors, seed=0)
    first = next(iter(posteriors))
    post = posteriors[first]
    posteriors[first] = TintPosterior(post.lab_draws, post.lab_measured + 50.0, post.thickness,
                                      post.delta_E, post.inside, post.probability)
    after = cross_validated_model_error(posteriors, seed=0)
    np.testing.assert_array_equal(before[first].covariance, after[first].covariance)
    assert not after[first].inside.any()  # 50 ΔE away: outside its own region
    assert all((after[k].covariance != before[k].covariance).any() for k in posteriors if k != first)
    with pytest.raises(ValueError, match="at least 3"):
        cross_validated_model_error(dict(list(posteriors.items())[:2]))


def test_posterior_predictive_region_contains_the_simulated_tint(table):
    import arviz as az

    from bayespig.studies.tints import tint_posterior_predictive

    rng = np.random.default_rng(7)
    intensive, extensive, D_B, D_C = _truth_bayespig()
    films = _films(table, intensive, extensive)

    def posterior(name, spread=0.02):  # stand-in posteriors: 2 % relative scatter about the truth
        a = intensive[name] * (1.0 + spread * rng.standard_normal((2, 100, WAVELENGTHS.size)))
        tau = THICKNESS[name] * extensive[name] * np.exp(spread * rng.standard_normal((2, 100, WAVELENGTHS.size)))
        return az.from_dict(posterior={"a": np.clip(a, 0.0, 1.0), "tau": tau})

    posteriors = {"masstone": posterior("A"), "white": posterior("W"), "tint_b": posterior("B")}
    model = RadiativeTransferTintModel("8d-sce", table=table)
    result = tint_posterior_predictive(model, posteriors, tint_c=films["C"], concentrations_b=tuple(D_B),
                                       concentrations_c=tuple(D_C), n_draws=60, seed=1)
    assert result.lab_draws.shape == (60, 2, 3)
    assert result.inside.all()
    assert np.median(result.thickness) == pytest.approx(THICKNESS["C"], rel=0.05)
    # a colour far from the prediction (C measured 15 % brighter) is outside the region
    from bayespig.colorimetry import reflectance_to_Lab
    from bayespig.studies.tints import credible_region_contains

    brighter = reflectance_to_Lab(np.minimum(1.15 * films["C"].sample("ow").reflectance[:, 0], 1.0), WAVELENGTHS)
    assert not credible_region_contains(result.lab_draws[:, 1], brighter)
