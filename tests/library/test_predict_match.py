"""Prediction and matching from a pigment library of known constants.

The library here is made by hand (every draw the same known constants, or a known spread), so
that the prediction can be checked against the direct solver with the mixture's constants
written out from the paper's section 2 (an independent path: the library predicts through the
look-up tables), and matching against the recipe that made the target.
"""

import numpy as np
import pytest

from bayespig import colorimetry
from bayespig.library.library import PigmentLibrary
from bayespig.library.match import match_paint
from bayespig.library.predict import joint_constants, model_error_from_residuals, predict_paint
from bayespig.physics.forward import hemispherical_reflectance
from bayespig.physics.substrate import substrate_albedo_from_air

WL = np.arange(400.0, 701.0, 30.0)
PIGMENTS = ("ZincWhite", "PrussianBlue", "BoneBlack")
#: The tables' stated accuracy (2e-4 relative) with a 2.5x margin for the card conversion.
TABLE_RTOL = 5e-4
#: Fractions recovered from an exactly reachable target: the search stops at ΔE00 ~1e-4.
MATCH_ATOL = 2e-3


def _truth():
    a = np.stack([np.full(WL.size, 0.002), 0.02 + 0.5 / (1 + np.exp(-(WL - 560) / 20)), np.full(WL.size, 0.6)],
                 axis=1)  # (n_wl, P)
    sigma = np.stack([np.full(WL.size, 1.0), np.full(WL.size, 3.0), np.full(WL.size, 2.0)], axis=1)
    return a, sigma


def _library(spread=0.0, n_draws=64, seed=0):
    a, sigma = _truth()
    rng = np.random.default_rng(seed)
    c = np.empty((n_draws, WL.size, len(PIGMENTS), 2))
    c[..., 0] = np.clip(a * (1 + spread * rng.standard_normal((n_draws, 1, len(PIGMENTS)))), 0, 1)
    c[..., 1] = np.log(sigma) + spread * rng.standard_normal((n_draws, 1, len(PIGMENTS)))
    return PigmentLibrary(model="radiative-transfer", pigments=PIGMENTS, wavelength_nm=WL, constants=c,
                          constant_names=("a", "log_sigma"), thickness_prior=(np.log(2.0), 0.2), films=(),
                          film_ids=(), thickness=np.zeros((n_draws, 0)), densities={p: 1.0 for p in PIGMENTS},
                          model_error=None, provenance={}, stages=())


def test_prediction_equals_the_direct_solver_with_the_mixed_constants():
    library = _library()
    a, sigma = _truth()
    fractions = np.array([0.6, 0.3, 0.1])  # equal densities: D proportional to the mass fractions
    card = np.full(WL.size, 0.05)
    h = 1.5
    prediction = predict_paint(library, dict(zip(PIGMENTS, fractions)), thickness=h, instrument="8d-sce",
                               substrate=card, n_draws=8)
    k = sigma @ fractions
    a_mix = (a * sigma) @ fractions / k
    r_s = substrate_albedo_from_air(card, n=1.45, kind="hemispherical", theta_i=8.0, specular="excluded")
    direct = hemispherical_reflectance(8.0, a=a_mix, tau=h * k, r_s=r_s, n=1.45, specular="excluded")
    np.testing.assert_allclose(prediction.reflectance_median, direct, rtol=TABLE_RTOL)
    assert prediction.delta_E_radius < 1e-6  # every draw the same constants, no model error


def _staged_library(n_draws=64, seed=0):
    """A library as a staged build leaves it: the white's own draws spread widely (its sigma only
    bounded from below), the blue and the black fitted with the white fixed at the truth."""
    library = _library(n_draws=n_draws)
    rng = np.random.default_rng(seed)
    c = library.constants.copy()
    fixed_white = c[0, :, 0].copy()
    c[:, :, 0, 1] += 2.0 * rng.standard_normal((n_draws, WL.size))  # sd 2.4 in the Revigo base
    conditioning = {"conditioned_on": {"PrussianBlue": ["ZincWhite"], "BoneBlack": ["PrussianBlue"]},
                    "fixed_constants": {"ZincWhite": fixed_white.tolist(),
                                        "PrussianBlue": c[0, :, 1].tolist()}}
    import dataclasses

    return dataclasses.replace(library, constants=c, provenance={"conditioning": conditioning})


def test_a_pigment_fitted_with_the_white_fixed_is_predicted_with_that_white():
    library = _staged_library()
    a, sigma = _truth()
    fractions = np.array([0.5, 0.5, 0.0])
    card = np.full(WL.size, 0.05)
    prediction = predict_paint(library, {"ZincWhite": 1, "PrussianBlue": 1}, thickness=1.5, instrument="8d-sce",
                               substrate=card, n_draws=8)
    k = sigma @ fractions
    r_s = substrate_albedo_from_air(card, n=1.45, kind="hemispherical", theta_i=8.0, specular="excluded")
    direct = hemispherical_reflectance(8.0, a=(a * sigma) @ fractions / k, tau=1.5 * k, r_s=r_s, n=1.45,
                                       specular="excluded")
    np.testing.assert_allclose(prediction.reflectance_median, direct, rtol=TABLE_RTOL)
    assert prediction.delta_E_radius < 1e-6  # the white's own spread is not in a tint's draws
    # the white alone keeps its own posterior
    alone = predict_paint(library, {"ZincWhite": 1}, thickness=1.5, instrument="8d-sce", substrate=card, n_draws=32)
    assert alone.delta_E_radius > 0.1


def test_joint_constants_follow_the_stages_through_every_pigment():
    library = _staged_library()
    fixed = library.provenance["conditioning"]["fixed_constants"]
    # the black was fitted with the blue fixed, the blue with the white: a grey of white and black
    # needs the white at its fixed value too; the black keeps its own draws
    joint = joint_constants(library, ["ZincWhite", "BoneBlack"])
    np.testing.assert_array_equal(joint[:, :, 0], np.broadcast_to(fixed["ZincWhite"], joint[:, :, 0].shape))
    np.testing.assert_array_equal(joint[:, :, 2], library.constants[:, :, 2])
    # a pigment no recipe pigment depends on keeps its draws; a library without the record is unchanged
    assert joint_constants(library, ["ZincWhite"]) is library.constants
    plain = _library()
    assert joint_constants(plain, ["ZincWhite", "PrussianBlue"]) is plain.constants


def test_the_conditioning_survives_save_and_load(tmp_path):
    from bayespig.library.library import load_library

    library = _staged_library()
    back = load_library(library.save(tmp_path / "staged.nc"))
    np.testing.assert_array_equal(joint_constants(back, PIGMENTS), joint_constants(library, PIGMENTS))


def test_opaque_prediction_equals_the_direct_solver():
    library = _library()
    a, sigma = _truth()
    fractions = np.array([0.8, 0.2, 0.0])
    prediction = predict_paint(library, {"ZincWhite": 4, "PrussianBlue": 1}, thickness="opaque",
                               instrument="8d-sci", n_draws=4)
    a_mix = (a * sigma) @ fractions / (sigma @ fractions)
    direct = hemispherical_reflectance(8.0, a=a_mix, tau=np.inf, n=1.45, specular="included")
    np.testing.assert_allclose(prediction.reflectance_median, direct, rtol=TABLE_RTOL)


def test_region_grows_with_the_model_error_and_is_seeded():
    library = _library(spread=0.02)
    recipe = {"ZincWhite": 0.7, "PrussianBlue": 0.3}
    first = predict_paint(library, recipe, thickness="opaque", instrument="8d-sce", seed=3)
    again = predict_paint(library, recipe, thickness="opaque", instrument="8d-sce", seed=3)
    np.testing.assert_array_equal(first.reflectance, again.reflectance)
    residuals = np.random.default_rng(1).normal(0.0, 0.03, (40, WL.size))
    library_with_error = _library(spread=0.02)
    object.__setattr__(library_with_error, "model_error", model_error_from_residuals(residuals))
    wider = predict_paint(library_with_error, recipe, thickness="opaque", instrument="8d-sce", seed=3)
    assert wider.model_error and not first.model_error
    assert wider.delta_E_radius > 1.5 * first.delta_E_radius
    assert first.contains(first.Lab_median)


@pytest.mark.parametrize("recipe, message", [
    ({"Vermillion": 1.0}, "recipe: pigment 'Vermillion' is not in the library"),
    ({"ZincWhite": -1.0, "PrussianBlue": 2.0},
     r"recipe: the amount of 'ZincWhite' is negative \(-1\); amounts are >= 0"),
    ({"ZincWhite": float("nan")}, "recipe: the amount of 'ZincWhite' is NaN; give a number >= 0"),
    ({"ZincWhite": 0.0}, "recipe: all amounts are zero; a film needs at least one pigment"),
])
def test_bad_recipes_are_refused(recipe, message):
    with pytest.raises(ValueError, match=message):
        predict_paint(_library(), recipe, thickness="opaque", instrument="8d-sce")


def test_film_that_shows_its_card_needs_the_card():
    with pytest.raises(ValueError, match="substrate is needed"):
        predict_paint(_library(), {"ZincWhite": 1.0}, thickness=1.0, instrument="8d-sce")


def test_bad_thickness_is_refused():
    with pytest.raises(ValueError, match="thickness"):
        predict_paint(_library(), {"ZincWhite": 1.0}, thickness="thin", instrument="8d-sce")
    with pytest.raises(ValueError, match="thickness"):
        predict_paint(_library(), {"ZincWhite": 1.0}, thickness=-1.0, instrument="8d-sce")


def test_match_recovers_a_simulated_recipe():
    library = _library()
    truth = {"ZincWhite": 0.62, "PrussianBlue": 0.3, "BoneBlack": 0.08}
    target = predict_paint(library, truth, thickness="opaque", instrument="8d-sce", n_draws=4).reflectance_median
    match = match_paint(library, target, instrument="8d-sce", n_spread=0)
    assert match.delta_E < 0.01
    for pigment, share in truth.items():
        assert match.recipe.amounts.get(pigment, 0.0) == pytest.approx(share, abs=MATCH_ATOL)
    # a metamer-free spectral match: the same spectrum matches under the second illuminant too
    assert match.metamerism_index < 0.01


def test_match_with_a_subset_of_pigments_reports_its_spread_and_credible_delta_e():
    library = _library(spread=0.03)
    target = predict_paint(_library(), {"ZincWhite": 0.7, "PrussianBlue": 0.3}, thickness="opaque",
                           instrument="8d-sce", n_draws=4).reflectance_median
    match = match_paint(library, target, pigments=("ZincWhite", "PrussianBlue"), instrument="8d-sce", n_spread=8)
    low, high = match.amounts_interval["PrussianBlue"]
    assert low <= 0.3 <= high and high - low > 1e-3
    assert match.delta_E_median <= match.delta_E_upper
    lab = colorimetry.reflectance_to_Lab(target, WL)
    assert colorimetry.delta_E2000(match.Lab_target, lab) < 1e-9


def test_match_refuses_unknown_pigments_and_bad_targets():
    library = _library()
    with pytest.raises(ValueError, match="pigments: 'Vermillion' is not in the library"):
        match_paint(library, [50.0, 0.0, 0.0], pigments=("Vermillion",), instrument="8d-sce")
    with pytest.raises(ValueError, match="target must be a CIELAB triple or a reflectance spectrum"):
        match_paint(library, np.ones(5), instrument="8d-sce")
    with pytest.raises(ValueError, match="divide percent by 100"):
        match_paint(library, np.full(WL.size, 50.0), instrument="8d-sce")
