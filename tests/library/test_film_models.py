"""Film models of pigment mixtures (bayespig.library.film_models): RT against the inference's
forward model and the direct solver, Kubelka-Munk against the closed forms of Kubelka (1948) and
Saunderson (1942)."""

import numpy as np
import pytest

import bayespig
from bayespig.instruments import get_instrument
from bayespig.library.film_models import (
    FILM_MODELS,
    KubelkaMunkModel,
    RadiativeTransferModel,
    film_model,
)
from bayespig.likelihood import ForwardModel, Problem
from bayespig.physics.substrate import substrate_albedo_from_air
from bayespig.studies.revigo import default_revigo_path

#: The film predictor evaluates the ForwardModel's own fast path and interpolant: equal to
#: rounding (measured 3.1e-15 against ForwardModel.predict on Revigo 06B).
SAME_PATH_REL_TOL = 1e-12
#: infer stores its predictions in single precision: round to nearest, 2^-24 relative (measured
#: 5.4e-8 on Revigo 06B at 550 nm); the bound is one float32 ulp, 2^-23.
FLOAT32_REL_TOL = 2.0**-23
#: Two evaluations of one closed form (or of one interpolant) in a different order: rounding.
CLOSED_FORM_TOL = 1e-12
#: Table against the direct adding-doubling solver: the tables' accuracy claim (issue 3,
#: tests/test_table.py INTERPOLATION_REL_TOL, measured there 9.4e-5).
TABLE_VS_SOLVER_REL_TOL = 2e-4
#: Saunderson's k1 = r_F(8 deg) against the normal-incidence ((n-1)/(n+1))^2 = 0.04 for
#: n = 1.5: the 8 degree value is larger by 1.1e-5 (kubelka_munk.saunderson_k1's docstring:
#: below 1e-4).
K1_8_DEGREES_TOL = 1e-4
#: Judd (1942) tabulates the internal diffuse reflectance to three decimals: 0.596 for n = 1.5.
JUDD_TOL = 5e-4

REVIGO = default_revigo_path()
needs_revigo = pytest.mark.skipif(not (REVIGO / "revigo-mixture-specifications.txt").exists(),
                                  reason=f"Revigo data not found at {REVIGO} (set BAYESPIG_REVIGO)")


@pytest.fixture
def rng():
    return np.random.default_rng(20260217)


@pytest.fixture(scope="module")
def revigo():
    return bayespig.data.read_revigo(REVIGO)


@pytest.fixture(scope="module")
def simulated_film():
    """A method-4 film (one film group over black and white) on the 8d-sce sphere, noise-free."""
    wavelengths = np.linspace(400.0, 700.0, 7)
    return bayespig.simulate(a=np.linspace(0.02, 0.6, 7), tau=np.linspace(0.5, 8.0, 7), design="method4",
                             instrument="8d-sce", wavelengths=wavelengths, eps=0.0)


def rt_constants(rng, n_draws, n_wl, n_pigments, a=(0.01, 0.95), sigma=(0.3, 30.0)):
    a_i = rng.uniform(*a, (n_draws, n_wl, n_pigments))
    log_sigma = np.log(rng.uniform(*sigma, (n_draws, n_wl, n_pigments)))
    return np.stack([a_i, log_sigma], axis=-1)


def km_constants(rng, n_draws, n_wl, n_pigments, K=(0.01, 3.0), S=(0.5, 30.0)):
    log_K = np.log(rng.uniform(*K, (n_draws, n_wl, n_pigments)))
    log_S = np.log(rng.uniform(*S, (n_draws, n_wl, n_pigments)))
    return np.stack([log_K, log_S], axis=-1)


def forward_model_values(measurements, a, tau):
    """What bayespig.infer predicts: the ForwardModel of the film's problem, each wavelength
    through the tables' own interpolation (predict) and through the sampler's evaluator."""
    model = ForwardModel(Problem.from_measurements(measurements), g="isotropic")
    n_wl = a.shape[1]
    direct = np.stack([model.predict(i, a[:, i], tau[:, i:i + 1]) for i in range(n_wl)], axis=1)
    sampler = np.stack([model.at_wavelength(i)(a[:, i], tau[:, i:i + 1]) for i in range(n_wl)], axis=1)
    return direct, sampler


# --------------------------------------------------------------------------- interface


def test_models_by_name_carry_the_spec_attributes():
    rt, km = film_model("radiative-transfer"), film_model("kubelka-munk")
    assert isinstance(rt, RadiativeTransferModel) and isinstance(km, KubelkaMunkModel)
    assert set(FILM_MODELS) == {"radiative-transfer", "kubelka-munk"}
    assert rt.constant_names == ("a", "log_sigma") and km.constant_names == ("log_K", "log_S")
    for model in (rt, km):
        assert model.lower.shape == model.upper.shape == (2,) and (model.lower < model.upper).all()
    assert rt.lower[0] == 0.0 and rt.upper[0] == 1.0
    c = np.array([[0.25, np.log(3.0)]])
    np.testing.assert_allclose(rt.physical(c)["sigma"], 3.0, rtol=CLOSED_FORM_TOL)
    np.testing.assert_allclose(km.physical(c)["K"], np.exp(0.25), rtol=CLOSED_FORM_TOL)
    with pytest.raises(ValueError, match="unknown film model 'mie'; use one of 'radiative-transfer', 'kubelka-munk'"):
        film_model("mie")


def test_bad_arguments_are_named(rng):
    model = film_model("radiative-transfer")
    c = rt_constants(rng, 3, 4, 2)
    card = np.full(4, 0.5)
    call = {"substrate": card, "instrument": "8d-sce"}
    with pytest.raises(ValueError, match=r"constants must have shape \(n_draws, n_wavelengths, n_pigments, 2\)"):
        model.reflectance(c[..., 0], [0.5, 0.5], np.ones(3), **call)
    with pytest.raises(ValueError, match=r"concentrations must have shape \(2,\)"):
        model.reflectance(c, [1.0], np.ones(3), **call)
    with pytest.raises(ValueError, match="concentrations"):
        model.reflectance(c, [-0.5, 1.0], np.ones(3), **call)
    with pytest.raises(ValueError, match="concentrations are all zero"):
        model.reflectance(c, [0.0, 0.0], np.ones(3), **call)
    with pytest.raises(ValueError, match="thickness"):
        model.reflectance(c, [0.5, 0.5], -np.ones(3), **call)
    with pytest.raises(ValueError, match=r"thickness must have shape \(3,\)"):
        model.reflectance(c, [0.5, 0.5], np.ones(2), **call)
    with pytest.raises(ValueError, match=r"substrate must have shape \(4,\) or \(3, 4\)"):
        model.reflectance(c, [0.5, 0.5], np.ones(3), substrate=np.ones(5), instrument="8d-sce")
    for name in FILM_MODELS:  # a card in percent is refused, not clipped to 1
        with pytest.raises(ValueError, match=r"substrate must be in \[0, 1\] \(a fraction; percent / 100\), "
                                             "got values from 50 to 50"):
            film_model(name).reflectance(c, [0.5, 0.5], np.ones(3), substrate=card * 100, instrument="8d-sce")
    with pytest.raises(ValueError, match="substrate is needed for a film that does not hide its card"):
        model.reflectance(c, [0.5, 0.5], np.ones(3), substrate=None, instrument="8d-sce")
    with pytest.raises(ValueError, match="has 6 channels"):
        model.reflectance(c, [0.5, 0.5], np.ones(3), substrate=card, instrument="multi-angle-45")
    with pytest.raises(ValueError, match=r"constants\[..., 0\] is the relative absorption a"):
        model.reflectance(c + np.array([1.0, 0.0]), [0.5, 0.5], np.ones(3), **call)
    km = film_model("kubelka-munk")
    with pytest.raises(ValueError, match="Kubelka-Munk predicts hemispherical and 45/0 values, not the BRDF"):
        km.reflectance(c, [0.5, 0.5], np.ones(3), substrate=card,
                       instrument=get_instrument(["45as15"]))
    # opaque films need no card
    assert model.reflectance(c, [0.5, 0.5], np.full(3, np.inf), substrate=None, instrument="8d-sce").shape == (3, 4)


def test_a_set_of_two_film_groups_is_not_one_film(simulated_film):
    from bayespig.data import MeasurementSet, Sample

    films = [s for s in simulated_film.samples if s.role == "film"]
    renamed = [Sample(s.name, s.role, s.measurements, s.substrate, f"group-{k}", s.opaque)
               for k, s in enumerate(films)]
    other = [s for s in simulated_film.samples if s.role != "film"]
    two_groups = MeasurementSet(simulated_film.wavelength_nm, other + renamed, n=simulated_film.n)
    for name in FILM_MODELS:
        with pytest.raises(ValueError, match="^measurement set: a film is one film group .* this set has 2: "
                                             "group-0, group-1$"):
            film_model(name).for_film(two_groups)


# --------------------------------------------------------------------------- radiative transfer


def _assert_rt_film_is_the_forward_model(measurements, rng, n_draws=6):
    model = film_model("radiative-transfer")
    film = model.for_film(measurements)
    n_wl = measurements.n_wavelengths
    constants = rt_constants(rng, n_draws, n_wl, 1)
    h = rng.uniform(0.2, 3.0, n_draws)
    predicted = film.values(constants, [1.0], h)
    a, tau = constants[..., 0, 0], h[:, None] * np.exp(constants[..., 0, 1])
    direct, sampler = forward_model_values(measurements, a, tau)
    assert predicted.shape == (n_draws, n_wl, 2)
    np.testing.assert_allclose(predicted, direct, rtol=SAME_PATH_REL_TOL, atol=0)
    np.testing.assert_allclose(predicted, sampler, rtol=SAME_PATH_REL_TOL, atol=0)
    problem = Problem.from_measurements(measurements)
    np.testing.assert_array_equal(film.observed, np.stack([problem.observed(i) for i in range(n_wl)]))
    return film


def test_rt_single_pigment_film_is_the_inference_forward_model(simulated_film, rng):
    film = _assert_rt_film_is_the_forward_model(simulated_film, rng)
    assert film.n_reflectance_films == 2 and film.n_wavelengths == simulated_film.n_wavelengths
    assert film.eps.shape == (2,) and np.isnan(film.eps).all()  # the set gives no per-sample eps


@needs_revigo
def test_rt_single_pigment_revigo_film_is_the_inference_forward_model(revigo, rng):
    film = _assert_rt_film_is_the_forward_model(revigo["06B"], rng)
    assert film.value_films == ("06B_ob", "06B_ow") and film.value_channels == ("8d-sce", "8d-sce")


def test_rt_film_reproduces_what_infer_predicted_at_its_draws():
    """infer's posterior predictive y at its own draws (a, tau) is the film's prediction with one
    pigment of a_1 = a, sigma_1 = tau at D = 1, h = 1."""
    film_set = bayespig.simulate(a=0.2, tau=3.0, design="method4", instrument="8d-sce",
                                 wavelengths=[550.0], eps=0.02, seed=3)
    idata = bayespig.infer(film_set, progress=False, seed=1)
    a = idata.posterior["a"].values.reshape(-1)
    tau = idata.posterior["tau"].values.reshape(-1)
    y = idata.posterior_predictive["y"].values.reshape(a.size, -1)
    film = film_model("radiative-transfer").for_film(film_set)
    constants = np.stack([a, np.log(tau)], axis=-1)[:, None, None, :]
    predicted = film.values(constants, [1.0], np.ones(a.size))[:, 0, :]
    np.testing.assert_allclose(predicted, y, rtol=FLOAT32_REL_TOL, atol=0)
    np.testing.assert_array_equal(film.observed, idata.observed_data["y"].values)


def test_rt_card_factors_scale_the_albedo_as_the_inference_does(simulated_film, rng):
    model = film_model("radiative-transfer")
    film = model.for_film(simulated_film)
    constants = rt_constants(rng, 4, simulated_film.n_wavelengths, 1)
    h = rng.uniform(0.5, 2.0, 4)
    scale = rng.uniform(0.8, 1.05, (4, 2))
    predicted = film.values(constants, [1.0], h, r_s_scale=scale)
    forward = ForwardModel(Problem.from_measurements(simulated_film), g="isotropic")
    a, tau = constants[..., 0, 0], h[:, None] * np.exp(constants[..., 0, 1])
    for i in range(simulated_film.n_wavelengths):
        expected = forward.at_wavelength(i)(a[:, i], tau[:, i:i + 1], r_s_scale=scale)
        np.testing.assert_allclose(predicted[:, i], expected, rtol=SAME_PATH_REL_TOL, atol=0)


def test_rt_mixture_of_identical_pigments_is_the_pigment(simulated_film, rng):
    model = film_model("radiative-transfer")
    one = rt_constants(rng, 5, simulated_film.n_wavelengths, 1)
    two = np.concatenate([one, one], axis=2)
    h = rng.uniform(0.5, 2.0, 5)
    film = model.for_film(simulated_film)
    # the concentrations sum to that of the single pigment: the same a and tau
    np.testing.assert_allclose(film.values(two, [0.3, 0.7], h), film.values(one, [1.0], h),
                               rtol=CLOSED_FORM_TOL, atol=0)
    card = np.linspace(0.2, 0.8, simulated_film.n_wavelengths)
    for thickness in (h, np.full(5, np.inf)):
        np.testing.assert_allclose(
            model.reflectance(two, [0.3, 0.7], thickness, substrate=card, instrument="8d-sci"),
            model.reflectance(one, [1.0], thickness, substrate=card, instrument="8d-sci"),
            rtol=CLOSED_FORM_TOL, atol=0)


@pytest.mark.parametrize("instrument, specular", [("8d-sce", "excluded"), ("8d-sci", "included")])
def test_rt_opaque_mixture_is_the_direct_solver(instrument, specular, rng):
    model = film_model("radiative-transfer")
    constants = rt_constants(rng, 3, 4, 2)
    D = np.array([0.8, 2.5])
    predicted = model.reflectance(constants, D, np.full(3, np.inf), substrate=None, instrument=instrument)
    # section 2 written out: a = sum a_i D_i sigma_i / sum D_i sigma_i
    weight = D * np.exp(constants[..., 1])
    a_mix = (constants[..., 0] * weight).sum(axis=-1) / weight.sum(axis=-1)
    direct = bayespig.hemispherical_reflectance(8.0, a=a_mix.ravel(), tau=np.inf, specular=specular)
    np.testing.assert_allclose(predicted.ravel(), direct, rtol=TABLE_VS_SOLVER_REL_TOL, atol=0)


@pytest.mark.parametrize("instrument", ["8d-sce", "8d-sci", "45-0"])
def test_rt_finite_mixture_over_a_card_is_the_direct_solver(instrument, rng):
    model = film_model("radiative-transfer")
    constants = rt_constants(rng, 3, 4, 2, a=(0.02, 0.6), sigma=(0.5, 5.0))
    D = np.array([0.4, 1.6])
    h = np.array([0.3, 1.0, 2.0])
    card = np.array([0.05, 0.3, 0.6, 0.8])
    predicted = model.reflectance(constants, D, h, substrate=card, instrument=instrument)
    weight = D * np.exp(constants[..., 1])
    a_mix = (constants[..., 0] * weight).sum(axis=-1) / weight.sum(axis=-1)
    tau = h[:, None] * weight.sum(axis=-1)
    channel = get_instrument(instrument).channels[0]
    if channel.kind == "hemispherical":
        r_s = substrate_albedo_from_air(card, kind="hemispherical", theta_i=8.0, specular=channel.specular)
    else:
        r_s = substrate_albedo_from_air(card / np.pi, kind="brdf", theta_i=45.0, theta_o=0.0)
    direct = bayespig.predict(instrument, a=a_mix, tau=tau, r_s=np.broadcast_to(r_s, tau.shape))[..., 0]
    np.testing.assert_allclose(predicted, direct, rtol=TABLE_VS_SOLVER_REL_TOL, atol=0)


@needs_revigo
def test_rt_film_and_recipe_prediction_agree_over_the_measured_card(revigo, rng):
    """Two routes (the film's evaluator; the table for any card in air) give one prediction."""
    ms = revigo["06B"]
    model = film_model("radiative-transfer")
    constants = rt_constants(rng, 4, ms.n_wavelengths, 3)
    D, h = np.array([0.1, 0.9, 0.0]), rng.uniform(0.5, 2.0, 4)
    film = model.for_film(ms).values(constants, D, h)
    for column, card in enumerate(("06B_b", "06B_w")):
        card_in_air = ms.sample(card).reflectance[:, 0]
        recipe = model.reflectance(constants, D, h, substrate=card_in_air, instrument="8d-sce")
        np.testing.assert_allclose(film[..., column], recipe, rtol=SAME_PATH_REL_TOL, atol=0)


# --------------------------------------------------------------------------- Kubelka-Munk


def fresnel(cos_i, n):
    """Unpolarised Fresnel reflectance from air into index n (written out for the test)."""
    sin_t = np.sqrt(1.0 - cos_i**2) / n
    cos_t = np.sqrt(1.0 - sin_t**2)
    r_s = (cos_i - n * cos_t) / (cos_i + n * cos_t)
    r_p = (n * cos_i - cos_t) / (n * cos_i + cos_t)
    return 0.5 * (r_s**2 + r_p**2)


def saunderson(R_i, k1, k2, included):
    return (k1 if included else 0.0) + (1.0 - k1) * (1.0 - k2) * R_i / (1.0 - k2 * R_i)


def kubelka_layer(K, S, X, R_g):
    """Kubelka (1948): R = (1 - R_g (a - b coth(bSX))) / (a - R_g + b coth(bSX))."""
    a = 1.0 + K / S
    b = np.sqrt(a * a - 1.0)
    coth = 1.0 / np.tanh(b * S * X)
    return (1.0 - R_g * (a - b * coth)) / (a - R_g + b * coth)


def test_saunderson_constants_of_a_glass_like_binder():
    model = film_model("kubelka-munk")
    channel = get_instrument("8d-sci").channels[0]
    k1, k2, specular = model.saunderson(channel, 1.5)
    assert specular == "included"
    assert abs(k1 - ((1.5 - 1.0) / 2.5) ** 2) < K1_8_DEGREES_TOL  # 0.04: Fresnel at normal incidence
    assert abs(k1 - fresnel(np.cos(np.radians(8.0)), 1.5)) < CLOSED_FORM_TOL
    assert abs(k2 - 0.596) < JUDD_TOL  # Judd (1942), internal diffuse reflectance, n = 1.5
    k1_45, _, specular_45 = model.saunderson(get_instrument("45-0").channels[0], 1.5)
    assert specular_45 == "excluded"
    assert abs(k1_45 - fresnel(np.cos(np.radians(45.0)), 1.5)) < CLOSED_FORM_TOL
    assert film_model(model) is model


@pytest.mark.parametrize("instrument, included", [("8d-sce", False), ("8d-sci", True)])
def test_km_opaque_film_is_kubelka_munk_with_saunderson(instrument, included):
    n = 1.5
    model = film_model("kubelka-munk")
    ratio = np.array([0.01, 0.1, 1.0, 10.0])
    S = np.array([2.0, 5.0, 1.0, 0.3])
    constants = np.stack([np.log(ratio * S), np.log(S)], axis=-1)[None, :, None, :]
    predicted = model.reflectance(constants, [1.0], [np.inf], substrate=None, instrument=instrument, n=n)
    R_inf = 1.0 + ratio - np.sqrt(ratio**2 + 2.0 * ratio)
    np.testing.assert_allclose(R_inf[2], 2.0 - np.sqrt(3.0), rtol=CLOSED_FORM_TOL)  # K/S = 1
    k1, k2 = fresnel(np.cos(np.radians(8.0)), n), 0.5963  # Judd's 0.596 to the digit used here
    expected = saunderson(R_inf, k1, k2, included)
    np.testing.assert_allclose(predicted[0], expected, rtol=0, atol=JUDD_TOL * 0.2)
    # with the model's exact k2 the same closed form to rounding
    _, k2_exact, _ = model.saunderson(get_instrument(instrument).channels[0], n)
    np.testing.assert_allclose(predicted[0], saunderson(R_inf, k1, k2_exact, included), rtol=CLOSED_FORM_TOL)


@pytest.mark.parametrize("instrument, included", [("8d-sce", False), ("8d-sci", True)])
def test_km_layer_over_black_and_white_cards(instrument, included):
    n = 1.45
    model = film_model("kubelka-munk")
    k1, k2, _ = model.saunderson(get_instrument(instrument).channels[0], n)
    K, S = np.array([0.05, 0.5, 2.0]), np.array([4.0, 2.0, 1.0])
    constants = np.stack([np.log(K), np.log(S)], axis=-1)[None, :, None, :]
    X = 0.7
    # cards in air whose internal reflectance is 0 (ideal black) and 1 (ideal white)
    black_in_air = np.full(3, k1 if included else 0.0)
    white_in_air = np.full(3, saunderson(1.0, k1, k2, included))
    over_black = model.reflectance(constants, [1.0], [X], substrate=black_in_air, instrument=instrument, n=n)
    over_white = model.reflectance(constants, [1.0], [X], substrate=white_in_air, instrument=instrument, n=n)
    # over black: R_0 = sinh(bSX) / (a sinh(bSX) + b cosh(bSX)); over white the coth formula at R_g = 1
    a = 1.0 + K / S
    b = np.sqrt(a * a - 1.0)
    R0 = np.sinh(b * S * X) / (a * np.sinh(b * S * X) + b * np.cosh(b * S * X))
    np.testing.assert_allclose(R0, kubelka_layer(K, S, X, 0.0), rtol=CLOSED_FORM_TOL)
    np.testing.assert_allclose(over_black[0], saunderson(R0, k1, k2, included), rtol=CLOSED_FORM_TOL)
    np.testing.assert_allclose(over_white[0], saunderson(kubelka_layer(K, S, X, 1.0), k1, k2, included),
                               rtol=CLOSED_FORM_TOL)
    assert (over_white > over_black).all()


def test_km_mixture_of_identical_pigments_has_the_pigments_ratio(rng):
    model = film_model("kubelka-munk")
    one = km_constants(rng, 4, 5, 1)
    two = np.concatenate([one, one], axis=2)
    K, S = model.mixture(two, [0.25, 0.75])
    ratio = np.exp(one[..., 0, 0] - one[..., 0, 1])
    np.testing.assert_allclose(K / S, ratio, rtol=CLOSED_FORM_TOL)
    # Duncan's sum over two identical pigments: K and S of the one pigment at the total concentration
    np.testing.assert_allclose(K, np.exp(one[..., 0, 0]), rtol=CLOSED_FORM_TOL)
    card = np.linspace(0.1, 0.8, 5)
    for h in (rng.uniform(0.3, 3.0, 4), np.full(4, np.inf)):
        np.testing.assert_allclose(
            model.reflectance(two, [0.25, 0.75], h, substrate=card, instrument="8d-sce"),
            model.reflectance(one, [1.0], h, substrate=card, instrument="8d-sce"), rtol=CLOSED_FORM_TOL)
    # opaque: a function of K/S alone, whatever the mixture
    opaque = model.reflectance(two, [0.25, 0.75], np.full(4, np.inf), substrate=None, instrument="8d-sce")
    k1, k2, _ = model.saunderson(get_instrument("8d-sce").channels[0])
    R_inf = 1.0 + ratio - np.sqrt(ratio**2 + 2.0 * ratio)
    np.testing.assert_allclose(opaque, saunderson(R_inf, k1, k2, False), rtol=CLOSED_FORM_TOL)


def test_km_film_lies_over_its_cards_albedo(simulated_film, rng):
    """Cards given as albedos (black 0.01, white 0.95) are the internal reflectances; the film's
    values are reflectance() over the cards in air with those internal reflectances."""
    model = film_model("kubelka-munk")
    film = model.for_film(simulated_film)
    problem = Problem.from_measurements(simulated_film, method="general")
    for backgrounds, term in zip(film.backgrounds, problem.films):
        np.testing.assert_allclose(backgrounds[0], term.r_s, rtol=CLOSED_FORM_TOL, atol=1e-15)
    constants = km_constants(rng, 3, simulated_film.n_wavelengths, 2)
    D, h = np.array([0.3, 0.9]), rng.uniform(0.5, 2.0, 3)
    values = film.values(constants, D, h)
    assert values.shape == (3, simulated_film.n_wavelengths, 2)
    k1, k2, _ = model.saunderson(get_instrument("8d-sce").channels[0], simulated_film.n)
    for column, term in enumerate(problem.films):
        card_in_air = saunderson(term.r_s, k1, k2, False)  # the card whose internal reflectance is r_s
        expected = model.reflectance(constants, D, h, substrate=card_in_air, instrument="8d-sce",
                                     n=simulated_film.n)
        np.testing.assert_allclose(values[..., column], expected, rtol=CLOSED_FORM_TOL)
    # card factors multiply the internal card reflectance
    scale = np.array([[1.0, 0.9]] * 3)
    scaled = film.values(constants, D, h, r_s_scale=scale)
    np.testing.assert_array_equal(scaled[..., 0], values[..., 0])
    assert (scaled[..., 1] < values[..., 1]).all()


@needs_revigo
def test_km_revigo_film_cards_are_the_inference_albedos(revigo):
    film = film_model("kubelka-munk").for_film(revigo["06B"])
    problem = Problem.from_measurements(revigo["06B"], method="general")
    for backgrounds, term in zip(film.backgrounds, problem.films):
        np.testing.assert_allclose(backgrounds[0], term.r_s, rtol=CLOSED_FORM_TOL, atol=1e-15)
    np.testing.assert_array_equal(film.observed[:, 0], revigo["06B"].sample("06B_ob").reflectance[:, 0])


@needs_revigo
def test_km_revigo_film_is_the_recipe_over_its_measured_cards(revigo, rng):
    """Each measured card in air through Saunderson's inverse: the film's values equal
    reflectance() of the recipe over that card."""
    ms = revigo["06B"]
    model = film_model("kubelka-munk")
    film = model.for_film(ms)
    constants = km_constants(rng, 3, ms.n_wavelengths, 3)
    D, h = np.array([0.1, 0.9, 0.0]), rng.uniform(0.5, 2.0, 3)
    values = film.values(constants, D, h)
    for column, card in enumerate(("06B_b", "06B_w")):
        expected = model.reflectance(constants, D, h, substrate=ms.sample(card).reflectance[:, 0],
                                     instrument="8d-sce")
        np.testing.assert_allclose(values[..., column], expected, rtol=CLOSED_FORM_TOL)


def simulated(design, instrument):
    from bayespig.data.simulate import FilmSpec

    designs = {
        "opaque only": [FilmSpec("opaque", opaque=True)],
        "measured cards": [FilmSpec("on_dark", substrate=0.05, film_group="film", measure_substrate=True),
                           FilmSpec("on_light", substrate=0.8, film_group="film", measure_substrate=True)],
    }
    wavelengths = np.linspace(400.0, 700.0, 4)
    return bayespig.simulate(a=np.linspace(0.05, 0.5, 4), tau=np.linspace(0.5, 4.0, 4),
                             design=designs.get(design, design), instrument=instrument,
                             wavelengths=wavelengths, eps=0.0)


@pytest.mark.parametrize("design, instrument", [("method1", "8d-sce"), ("method2", "8d-sci"),
                                                ("opaque only", "8d-sce"), ("measured cards", "45-0")])
def test_rt_film_of_any_design_is_the_inference_forward_model(design, instrument, rng):
    """Opaque films (tau = inf whatever h), films on glass (specular transmittance) and a set
    without any finite film all go through the inference's evaluator unchanged."""
    measurements = simulated(design, instrument)
    film = film_model("radiative-transfer").for_film(measurements)
    constants = rt_constants(rng, 4, measurements.n_wavelengths, 1)
    h = rng.uniform(0.3, 3.0, 4)
    predicted = film.values(constants, [1.0], h)
    a, tau = constants[..., 0, 0], h[:, None] * np.exp(constants[..., 0, 1])
    direct, _ = forward_model_values(measurements, a, tau)
    np.testing.assert_allclose(predicted, direct, rtol=SAME_PATH_REL_TOL, atol=0)


def test_km_film_over_measured_45_0_cards_is_the_recipe_over_them(rng):
    measurements = simulated("measured cards", "45-0")
    model = film_model("kubelka-munk")
    film = model.for_film(measurements)
    constants = km_constants(rng, 3, measurements.n_wavelengths, 1)
    h = rng.uniform(0.5, 2.0, 3)
    values = film.values(constants, [1.0], h)
    for column, name in enumerate(film.value_films):
        card = measurements.sample(measurements.sample(name).substrate).reflectance[:, 0]
        expected = model.reflectance(constants, [1.0], h, substrate=card, instrument="45-0")
        np.testing.assert_allclose(values[..., column], expected, rtol=CLOSED_FORM_TOL)


def test_km_does_not_model_a_film_on_glass():
    with pytest.raises(ValueError, match="film 'on_glass:transmittance': Kubelka-Munk does not model the "
                                         "specular transmittance of a film on glass"):
        film_model("kubelka-munk").for_film(simulated("method1", "8d-sce"))


@pytest.mark.parametrize("name", sorted(FILM_MODELS))
def test_a_card_per_draw_is_each_draw_over_its_own_card(name, rng):
    model = film_model(name)
    constants = (rt_constants if name == "radiative-transfer" else km_constants)(rng, 3, 4, 2)
    cards = rng.uniform(0.1, 0.8, (3, 4))
    h = rng.uniform(0.5, 2.0, 3)
    together = model.reflectance(constants, [0.5, 0.5], h, substrate=cards, instrument="8d-sce")
    one_by_one = np.array([model.reflectance(constants[j:j + 1], [0.5, 0.5], h[j:j + 1], substrate=cards[j],
                                             instrument="8d-sce")[0] for j in range(3)])
    np.testing.assert_allclose(together, one_by_one, rtol=CLOSED_FORM_TOL, atol=0)
