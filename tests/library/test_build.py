"""The pigment library build (bayespig.library.build): recovery of known constants from
simulated films of known recipes, the stage plan, save/load, the cards' factors (substrate_sd)."""

import contextlib
import dataclasses
import io
import re

import numpy as np
import pytest
from scipy import stats

from bayespig.data import simulate
from bayespig.data.simulate import FilmSpec
from bayespig.inference import InferenceSettings
from bayespig.inference.shared import MAX_ADAPTATION_ROUNDS
from bayespig.library import PigmentLibrary, build_library, load_library, stage_plan
from bayespig.library.build import IMPLAUSIBLE_SDS, SLOWEST_REPORTED, implausible_factor
from bayespig.library.recipes import Recipe
from bayespig.table import load_table, table_path

WAVELENGTHS = np.array([450.0, 550.0, 650.0])
EPS = 0.01
#: The true constants per pigment and wavelength: a (relative absorption) and sigma (optical
#: thickness per unit concentration at h = 1).
TRUTH = {
    "White": (np.array([0.004, 0.002, 0.003]), np.array([5.0, 4.5, 4.0])),
    "Black": (np.array([0.85, 0.82, 0.80]), np.array([150.0, 140.0, 130.0])),
    "Red": (np.array([0.70, 0.40, 0.03]), np.array([25.0, 20.0, 12.0])),
    "Blue": (np.array([0.10, 0.50, 0.80]), np.array([8.0, 15.0, 30.0])),
}
#: Recipes (mass fractions): masstones, tints with the white, shades with the black.
RECIPES = {
    "W": {"White": 1.0},
    "WB1": {"White": 0.97, "Black": 0.03},
    "WB2": {"White": 0.90, "Black": 0.10},
    "R": {"Red": 1.0},
    "RW1": {"Red": 0.1, "White": 0.9},
    "RW2": {"Red": 0.5, "White": 0.5},
    "RB": {"Red": 0.9, "Black": 0.1},
    "U": {"Blue": 1.0},
    "UW": {"Blue": 0.3, "White": 0.7},
}
#: Films' measured thicknesses: the truth is the measurement times exp(N(0, MEASURED_SD^2)),
#: the prior's own spread (FilmThickness, MEASURED_RELATIVE_SD), so that the truth is a draw
#: from the prior.
MEASURED_SD = 0.1
#: Unit densities: the simulation's concentrations are the mass fractions (appendix A2 with equal
#: densities; the handbook fallback for unknown names would scale every sigma by 1 / 3.32).
DENSITIES = {p: 1.0 for p in TRUTH}
QUICK = InferenceSettings(target_ess=400.0, draws_per_chain=256, max_steps=20000)
#: Nominal coverage of the 90 % intervals and the tolerance: with n constants the count inside is
#: Binomial(n, 0.9) for independent constants; we accept any count above the binomial's 0.1 %
#: quantile (the constants of one pigment share its films' thicknesses, so the count is more
#: spread than binomial; the cut posterior's fixed earlier pigments make it somewhat narrower).
COVERAGE, COVERAGE_QUANTILE = 0.9, 0.001


def _film(name, recipe, h, seed, table, white_factor=1.0, stated=None):
    """A film over a black (albedo 0.05) and a white card (0.85), both cards measured.

    ``white_factor``: the film lies on ``r_s = white_factor * 0.85`` while its white card's
    measurement is that of the 0.85 card (the same noise draws: one seed), i.e. the true card
    factor of :mod:`bayespig.inference.card_factors` is ``white_factor``. ``stated``: the recipe
    the film's metadata gives (default ``recipe``, the one it is simulated with).
    """
    weight = {p: f * TRUTH[p][1] for p, f in recipe.items()}
    total = sum(weight.values())
    a = sum(TRUTH[p][0] * w for p, w in weight.items()) / total

    def measured(white):
        return simulate(a=a, tau=h * total, design=[
            FilmSpec(f"{name}_ob", substrate=0.05, film_group=name, measure_substrate=True),
            FilmSpec(f"{name}_ow", substrate=white, film_group=name, measure_substrate=True)],
            instrument="8d-sce", wavelengths=WAVELENGTHS, eps=EPS, seed=seed, model=table)

    ms = measured(0.85)
    if white_factor != 1.0:
        card = f"{name}_ow_substrate"
        ms = dataclasses.replace(ms, samples=tuple(ms.sample(card) if s.name == card else s
                                                   for s in measured(0.85 * white_factor).samples))
    stated = recipe if stated is None else stated
    pigments = sorted(stated)
    metadata = dict(ms.metadata, composition={"pigments": pigments, "mass_ratios": [stated[p] for p in pigments]})
    return dataclasses.replace(ms, metadata=metadata)


def _assert_constants_covered(library):
    """Every pigment's a and log sigma against their truth: the 90 % intervals hold them at the
    nominal rate (at least the COVERAGE_QUANTILE quantile of the binomial count)."""
    inside = []
    for j, pigment in enumerate(library.pigments):
        a, sigma = TRUTH[pigment]
        for c, truth in enumerate((a, np.log(sigma))):
            low, high = np.quantile(library.constants[:, :, j, c], [0.05, 0.95], axis=0)
            inside.extend((low <= truth) & (truth <= high))
    assert sum(inside) >= stats.binom(len(inside), COVERAGE).ppf(COVERAGE_QUANTILE), (sum(inside), len(inside))


@pytest.fixture(scope="module")
def simulated():
    table = load_table("8d-sce", progress=False)
    rng = np.random.default_rng(2024)
    measured = {name: float(np.exp(rng.normal(0.0, 0.3))) for name in RECIPES}
    truth_h = {name: h * float(np.exp(rng.normal(0.0, MEASURED_SD))) for name, h in measured.items()}
    sets = {name: _film(name, recipe, truth_h[name], 100 + k, table) for k, (name, recipe) in enumerate(RECIPES.items())}
    return sets, measured, truth_h


@pytest.fixture(scope="module")
def built(simulated):
    """The library and its progress lines (stderr)."""
    sets, measured, _ = simulated
    lines = io.StringIO()
    with contextlib.redirect_stderr(lines):
        library = build_library(sets, seed=3, progress=True, eps=EPS, thickness=measured, settings=QUICK,
                                base_pigments=["White", "Black"], densities=DENSITIES)
    return library, lines.getvalue().splitlines()


@pytest.fixture(scope="module")
def library(built):
    return built[0]


def test_progress_says_each_stage(built):
    """One line per stage group (pigments, films, steps, R-hat, ESS, time), as it completes (stage
    2's two groups run in a local pool of 2 processes), and one per stage."""
    library, lines = built
    assert len(lines) == 5
    group_lines = lines[:1] + lines[2:4]
    expected = []
    for stage in library.stages:
        expected.append(f"library stage {stage['stage']}/2: {', '.join(stage['pigments'])} from "
                        f"{len(stage['films'])} films: {stage['n_steps']} steps, R-hat <= "
                        f"{max(stage['thickness_rhat_max'], stage['constants_rhat_max']):.3f}, thickness ESS >= "
                        f"{stage['thickness_ess_min']:.0f}, {stage['seconds']:.1f} s")
    assert group_lines[0] == expected[0] and sorted(group_lines[1:]) == sorted(expected[1:])
    assert re.fullmatch(r"library stage 1/2 done in [0-9.]+ s", lines[1])
    assert re.fullmatch(r"library stage 2/2 done in [0-9.]+ s", lines[4])


def test_the_stage_plan_fits_the_base_then_each_pigment_alone():
    """Base White and Black from their films, then Red and Blue (two groups) from the films
    where each is the only unknown; a film whose pigments were all fitted before it is unused.
    By default every pigment in >= 1/4 of the films is base: here White, Black and Red."""
    recipes = {name: Recipe(recipe) for name, recipe in RECIPES.items()}
    stages, unused = stage_plan(recipes, ["White", "Black"])
    assert stages == [[(("Black", "White"), ("W", "WB1", "WB2"))],
                      [(("Blue",), ("U", "UW")), (("Red",), ("R", "RB", "RW1", "RW2"))]]
    assert unused == ()
    assert stage_plan(recipes) == ([[(("Black", "Red", "White"), ("R", "RB", "RW1", "RW2", "W", "WB1", "WB2"))],
                                    [(("Blue",), ("U", "UW"))]], ())
    recipes["RU"] = Recipe({"Red": 0.5, "Blue": 0.5})  # Red and Blue are fitted in stage 2 without it
    assert stage_plan(recipes, ["White", "Black"])[1] == ("RU",)
    del recipes["U"], recipes["UW"]  # now RU is the one film of the unknown Blue: a third stage
    assert stage_plan(recipes, ["White", "Black"])[0][2] == [(("Blue",), ("RU",))]
    with pytest.raises(ValueError, match=r"base_pigments: \['Green'\] are in no film's recipe"):
        stage_plan(recipes, ["Green"])


def test_the_library_recovers_known_constants(library, simulated):
    """Every true constant (a and log sigma of 4 pigments at 3 wavelengths) inside its 90 %
    interval at the nominal rate; every stage converged (not capped, R-hat <= 1.01, the
    thicknesses' ESS >= 400); the thicknesses' 90 % intervals hold the truth at the nominal rate."""
    _, _, truth_h = simulated
    assert isinstance(library, PigmentLibrary)
    assert library.constants.shape == (QUICK.n_ensembles * QUICK.draws_per_chain, WAVELENGTHS.size, 4, 2)
    _assert_constants_covered(library)
    for stage in library.stages:
        assert not stage["max_steps_reached"]
        assert stage["thickness_rhat_max"] <= 1.01 and stage["thickness_ess_min"] >= 400
        assert 1 <= stage["adaptation_rounds"] <= MAX_ADAPTATION_ROUNDS
        assert 0.0 < stage["shared_acceptance"] < 1.0 and 0.0 < stage["block_acceptance"] < 1.0
        taus = [tau for _, tau in stage["slowest_coordinates"]]
        assert len(taus) == SLOWEST_REPORTED and taus == sorted(taus, reverse=True) and taus[-1] > 0
    low, high = np.quantile(library.thickness, [0.05, 0.95], axis=0)
    truth = np.array([truth_h[f] for f in library.film_ids])
    assert ((low <= truth) & (truth <= high)).sum() >= stats.binom(truth.size, COVERAGE).ppf(COVERAGE_QUANTILE)
    for film in library.films:
        assert film["used"] and film["rms_log_deviation"] < 3 * EPS


def test_save_and_load_round_trip(library, tmp_path):
    path = library.save(tmp_path / "library.nc")
    back = load_library(path)
    np.testing.assert_array_equal(back.constants, library.constants)
    np.testing.assert_array_equal(back.thickness, library.thickness)
    np.testing.assert_array_equal(back.wavelength_nm, library.wavelength_nm)
    for field in ("model", "pigments", "constant_names", "thickness_prior", "films", "film_ids", "densities",
                  "provenance", "stages", "model_error"):
        assert getattr(back, field) == getattr(library, field), field
    assert [p.name for p in tmp_path.iterdir()] == ["library.nc"]  # no temporary left behind


def test_load_library_names_a_file_that_is_not_a_library(tmp_path):
    with pytest.raises(ValueError, match="'.*nothing.nc' cannot be read: file not found"):
        load_library(tmp_path / "nothing.nc")
    import arviz as az
    import xarray as xr

    other = tmp_path / "posterior.nc"
    az.InferenceData(posterior=xr.Dataset({"a": (("chain", "draw"), np.zeros((1, 3)))})).to_netcdf(str(other))
    with pytest.raises(ValueError, match="posterior.nc' is not a bayespig pigment library"):
        load_library(other)


def test_bad_arguments():
    with pytest.raises(TypeError, match="measurements must be a non-empty dict"):
        build_library([], progress=False)
    with pytest.raises(ValueError, match="model must be one of"):
        build_library({"x": None}, model="nonsense", progress=False)


def test_a_base_library_serves_later_builds(simulated):
    """The white and black fitted once (a base library) and shared: a later build fits only the
    pigment its films add, keeps the base's draws for the base pigments, and recovers the truth."""
    sets, measured, _ = simulated
    options = {"seed": 5, "progress": False, "eps": EPS, "settings": QUICK, "densities": DENSITIES}
    base = build_library({f: sets[f] for f in ("W", "WB1", "WB2")}, thickness={f: measured[f] for f in ("W", "WB1", "WB2")},
                         **options)
    assert set(base.pigments) == {"White", "Black"}
    red_films = ("R", "RW1", "RW2", "RB")
    library = build_library({f: sets[f] for f in red_films}, thickness={f: measured[f] for f in red_films}, base=base,
                            **options)
    assert library.pigments[0] == "Red" and set(library.pigments) == {"Red", "White", "Black"}
    n = library.constants.shape[0]
    for pigment in ("White", "Black"):
        np.testing.assert_array_equal(library.constants[:, :, library.pigments.index(pigment)],
                                      base.constants[:n, :, base.pigments.index(pigment)])
    assert [sorted(s["pigments"]) for s in library.stages] == [["Red"], ["Black", "White"]]
    assert all(f["used"] for f in library.films), library.films  # every Red film fits Red (none left over)
    # The base pigments are fixed at the base library's own stage points, not refitted.
    for pigment in ("White", "Black"):
        np.testing.assert_array_equal(library.provenance["conditioning"]["fixed_constants"][pigment],
                                      base.provenance["stage_points"][pigment])
    # The Red films are reproduced (the base pigments fixed at the base library's point).
    # Not asserted: the truth inside Red's intervals. With the base fixed at a point its uncertainty
    # does not reach Red's posterior (the staged posterior's known limit, bayespig.library.build):
    # measured, 3 of Red's 6 true constants inside their 98 % intervals.
    for film in library.films:
        if film["id"] in red_films:
            assert film["rms_log_deviation"] < 3 * EPS, film
    with pytest.raises(ValueError, match="base is a 'radiative-transfer' library; this build is 'kubelka-munk'"):
        build_library({"R": sets["R"]}, base=base, model="kubelka-munk", progress=False)


def test_cross_validation_learns_a_model_error(simulated):
    """Leave one film out on simulated films (the model is exact here): each held-out film within
    its predictive spread, and the learned model error the size of the residuals."""
    from bayespig.library.validation import cross_validate

    sets, _, _ = simulated
    films = {f: sets[f] for f in ("W", "WB1", "WB2", "R", "RW1", "RW2", "RB")}
    library = build_library(films, seed=1, progress=False, settings=QUICK, base_pigments=["White", "Black"])
    said = []
    validated, predictions = cross_validate(library, films, targets=["RW2", "RB"], seed=2, settings=QUICK,
                                            executor=None, progress=said.append)
    assert [p.film_id for p in predictions] == ["RW2", "RB"]
    # the long first step is announced before it starts, then each held-out film as it ends
    assert said[0] == "building the base libraries (White, Black from 3 films, radiative-transfer) ..."
    assert said[1].startswith("base libraries (White, Black from ") and " built: " in said[1]
    assert [m.split(":")[0] for m in said[2:]] == ["[1/2] radiative-transfer RW2", "[2/2] radiative-transfer RB"]
    residuals = []
    for p in predictions:
        assert len(p.cards) == 2 and np.isnan(p.delta_E).all()  # three bands: no colour
        # measured = model * (1 + eps xi): within 4 sd of the prediction, the sd from the noise and
        # the spread of the predictive draws (constants from the other films)
        spread = p.draws.std(axis=1) / np.median(p.draws, axis=1)
        assert (np.abs(p.residuals) <= 4.0 * np.hypot(EPS, spread)).all(), (p.residuals, spread)
        residuals.append(p.residuals)
    assert validated.model_error.shape == (WAVELENGTHS.size,) * 2
    rms = np.sqrt(np.mean(np.concatenate(residuals) ** 2, axis=0))
    np.testing.assert_allclose(np.sqrt(np.diag(validated.model_error)), rms, rtol=1e-12)
    assert validated.provenance["model_error"]["films"] == ["RW2", "RB"]
    assert validated.provenance["model_error"]["calibration"] is None  # three bands: no ΔE00 to calibrate on
    assert validated.model_error is not None and library.model_error is None


#: True factor of the white card of film W (its film lies on 1.1 x the albedo its card measures).
CARD_FACTOR = 1.1
CARD_SD = 0.1
BASE_FILMS = ("W", "WB1", "WB2")
#: Small settings where only equality of two runs is checked (not convergence).
TINY = InferenceSettings(target_ess=20.0, draws_per_chain=16, min_steps=100, max_steps=200, check_interval=100)


@pytest.fixture(scope="module")
def carded(simulated):
    """The base films with W's white card 10 % brighter than measured, built with card factors."""
    _, measured, truth_h = simulated
    table = load_table("8d-sce", progress=False)
    seeds = {name: 100 + k for k, name in enumerate(RECIPES)}
    sets = {f: _film(f, RECIPES[f], truth_h[f], seeds[f], table, CARD_FACTOR if f == "W" else 1.0)
            for f in BASE_FILMS}
    library = build_library(sets, seed=3, progress=False, eps=EPS, thickness={f: measured[f] for f in BASE_FILMS},
                            settings=QUICK, densities=DENSITIES, substrate_sd=CARD_SD)
    return sets, library


def test_card_factors_recover_a_known_card_and_the_constants(carded):
    """A film on a white card 10 % brighter than its measurement: the card's factor is learned
    (its 90 % interval holds 1.1 and is less than half as wide as the prior's, 2 x 1.645 x sd in
    log f), every other card's holds its truth 1; the pigments' constants hold their truth at the
    nominal rate (the rule of test_the_library_recovers_known_constants) and every film is fitted
    within its noise (rms < 3 eps); the run converged (not capped, R-hat <= 1.01, ESS >= 400 for
    every factor)."""
    _, library = carded
    assert library.card_factor.shape == (library.constants.shape[0], 3, 2)
    assert library.card_names == tuple((f"{f}_ob_substrate", f"{f}_ow_substrate") for f in BASE_FILMS)
    assert library.film_ids == BASE_FILMS
    for i, film in enumerate(library.film_ids):
        for c, card in enumerate(library.card_names[i]):
            truth = CARD_FACTOR if card == "W_ow_substrate" else 1.0
            low, high = np.quantile(library.card_factor[:, i, c], [0.05, 0.95])
            assert low <= truth <= high, (card, low, high)
            if truth != 1.0:
                assert np.log(high / low) < 0.5 * 2 * 1.645 * CARD_SD, (low, high)
    _assert_constants_covered(library)
    for film in library.films:
        assert film["rms_log_deviation"] < 3 * EPS, film
        assert [c["card"] for c in film["card_factors"]] == [f"{film['id']}_ob_substrate", f"{film['id']}_ow_substrate"]
        assert not any(c["implausible"] for c in film["card_factors"])  # 1.1 is one prior sd off
    (stage,) = library.stages
    assert not stage["max_steps_reached"]
    assert stage["card_factor_rhat_max"] <= 1.01 and stage["card_factor_ess_min"] >= 400
    assert library.provenance["substrate_sd"] == CARD_SD and "log f ~ N(0, 0.1^2)" in library.provenance[
        "card_factor_prior"]


def test_card_factors_are_saved_and_reported(carded, tmp_path):
    """card_factor over (chain, draw, film, card) in the file, read back whole; the pigment
    report's film table names every card's factor."""
    import xarray as xr

    from bayespig.report.pigment import pigment_report

    _, library = carded
    path = library.save(tmp_path / "library.nc")
    with xr.open_dataset(path, group="posterior") as posterior:
        assert posterior["card_factor"].dims == ("chain", "draw", "film", "card")
        assert posterior["card_factor"].attrs["units"] == "1"
    back = load_library(path)
    np.testing.assert_array_equal(back.card_factor, library.card_factor)
    assert back.card_names == library.card_names and back.films == library.films
    text = pigment_report(library, "White")["White.md"]
    film = next(f for f in library.films if f["id"] == "W")
    factor = film["card_factors"][1]
    assert (f"W_ow_substrate {factor['median']:.3f} [{factor['q05']:.3f}, {factor['q95']:.3f}]") in text
    assert "card factors R-hat <=" in text and "substrate_sd 0.1" in text


def test_the_report_of_a_capped_stage_names_its_slowest_coordinates(carded):
    """A pigment fitted in a stage that hit its step cap: its report says so and names the
    coordinates the run-length rule waited for, with their autocorrelation times; a stage
    that converged names none."""
    import copy

    from bayespig.report.pigment import pigment_report

    _, library = carded
    capped = copy.deepcopy(library)
    for stage in capped.stages:
        stage["max_steps_reached"] = True
        stage["slowest_coordinates"] = [["r_log_sigma[White][500]", 90.4], ["log_h[W]", 71.0]]
    text = pigment_report(capped, "White")["White.md"]
    assert "(capped: NOT converged)" in text
    assert "Slowest to mix" in text and "log_sigma[White][500] (90), log_h[W] (71)." in text
    for stage in capped.stages:
        stage["max_steps_reached"] = False
    text = pigment_report(capped, "White")["White.md"]
    assert "(capped: NOT converged)" not in text and "Slowest to mix" not in text


@pytest.fixture(scope="module")
def default_builds(simulated):
    """``model -> (films, options, library)``: the base films built with the default options,
    once per model for the module."""
    sets, _, _ = simulated
    films = {f: sets[f] for f in BASE_FILMS}
    built = {}

    def build(model):
        if model not in built:
            options = {"seed": 2, "progress": False, "eps": EPS, "settings": TINY, "densities": DENSITIES,
                       "model": model}
            built[model] = (films, options, build_library(films, **options))
        return built[model]

    return build


@pytest.mark.parametrize("model", ["radiative-transfer", "kubelka-munk"])
@pytest.mark.parametrize("option, fields, record", [
    ("substrate_sd", ("card_factor", "card_names"), "card_factors"),
    ("concentration_sd", ("concentration_factor", "concentration_names"), "concentration_factors"),
])
def test_without_the_nuisance_options_the_build_is_unchanged(default_builds, model, option, fields, record):
    """substrate_sd=None and concentration_sd=None are the defaults: the same draws for the same
    seed, no factors and no trace of them in the provenance or the film records (the draws also
    equal those of the build before either existed: checked against that code when they were
    added, not repeatable here)."""
    films, options, default = default_builds(model)
    explicit = build_library(films, **{option: None}, **options)
    np.testing.assert_array_equal(explicit.constants, default.constants)
    np.testing.assert_array_equal(explicit.thickness, default.thickness)
    assert all(getattr(explicit, name) is None for name in fields)
    assert option not in explicit.provenance and all(record not in f for f in explicit.films)
    assert all(not any(key.startswith(record[:-1]) for key in stage) for stage in explicit.stages)


@pytest.mark.parametrize("bad", [-0.1, 0.0, float("nan"), float("inf"), "0.1", True])
def test_a_bad_substrate_sd_is_refused_as_infer_refuses_it(simulated, bad):
    """The same exception and message as bayespig.infer's, before any sampling."""
    import bayespig

    sets, _, _ = simulated
    with pytest.raises((TypeError, ValueError)) as expected:
        bayespig.infer(sets["W"], substrate_sd=bad, progress=False)
    with pytest.raises(expected.type, match=re.escape(str(expected.value))):
        build_library({"W": sets["W"]}, substrate_sd=bad, progress=False)


def test_the_build_records_what_each_later_stage_was_conditioned_on(library):
    """Red and Blue were fitted with the base pigments of their films fixed: the record names them
    (from the recipes of the films each was fitted from) and the values they were fixed at, which
    are the base stage's joint least-squares point (``provenance["stage_points"]``); predictions
    pair the draws by them (``bayespig.library.predict.joint_constants``)."""
    conditioning = library.provenance["conditioning"]
    films = {s["pigments"][0]: s["films"] for s in library.stages if s["stage"] == 2}
    for pigment, names in films.items():
        expected = sorted({p for name in names for p in RECIPES[name]} - {pigment})
        assert sorted(conditioning["conditioned_on"][pigment]) == expected
    assert sorted(library.provenance["stage_points"]) == sorted(library.pigments)
    for pigment in ("White", "Black"):
        fixed = np.asarray(conditioning["fixed_constants"][pigment])
        np.testing.assert_array_equal(fixed, library.provenance["stage_points"][pigment])


#: Posterior sds a stage point may lie from its stage's median (see the test below; measured at
#: most 0.13, so a margin of ~8x).
POINT_SDS = 1.0


def test_a_stage_point_is_where_its_posterior_is(library):
    """Each stage's point (the joint least-squares fit the later stages are fixed at) lies in the
    bulk of that stage's posterior wherever the films identify the constants, as they do here:
    within POINT_SDS posterior sds of the median at every band and constant (the least-squares
    point of a near-normal posterior with a flat prior is its mode, a fraction of a sd from the
    median; a point from a failed or unconverged fit lies tens of sds away)."""
    for j, pigment in enumerate(library.pigments):
        point = np.asarray(library.provenance["stage_points"][pigment])
        draws = library.constants[:, :, j]
        z = np.abs(point - np.median(draws, axis=0)) / draws.std(axis=0)
        assert z.max() <= POINT_SDS, (pigment, z)


#: True factor on the black of the shade RB: it acts as 0.14 of black where its recipe says 0.1.
CONCENTRATION_FACTOR = 1.4
CONCENTRATION_SD = 0.3
RED_FILMS = ("R", "RW1", "RW2", "RB")


@pytest.fixture(scope="module")
def concentrated(simulated):
    """Red's films on a base library of the white and black, the shade RB's black 1.4 x its recipe's,
    built with concentration factors."""
    sets, measured, truth_h = simulated
    table = load_table("8d-sce", progress=False)
    seeds = {name: 100 + k for k, name in enumerate(RECIPES)}
    base = build_library({f: sets[f] for f in BASE_FILMS}, seed=3, progress=False, eps=EPS, settings=QUICK,
                         thickness={f: measured[f] for f in BASE_FILMS}, densities=DENSITIES)
    red = {f: sets[f] for f in RED_FILMS}
    red["RB"] = _film("RB", {"Red": 0.9, "Black": 0.1 * CONCENTRATION_FACTOR}, truth_h["RB"], seeds["RB"], table,
                      stated=RECIPES["RB"])
    library = build_library(red, seed=3, progress=False, eps=EPS, settings=QUICK, base=base, densities=DENSITIES,
                            thickness={f: measured[f] for f in RED_FILMS}, concentration_sd=CONCENTRATION_SD)
    return library


def test_concentration_factors_recover_a_shade_whose_black_is_off(concentrated):
    """A shade whose black acts at 1.4 x its recipe's concentration: the factor's 90 % interval
    holds 1.4; every other factor's holds its truth 1; only the minor fixed pigments get one (R, a
    masstone, and RW1, whose minor pigment Red is being fitted, none; RW2's 50/50 tie leaves the
    first pigment, Red, as dominant); the constants
    hold their truth at the nominal rate (the rule of test_the_library_recovers_known_constants);
    each film fits within its noise (rms < 3 eps)."""
    library = concentrated
    names = dict(zip(library.film_ids, library.concentration_names))
    assert library.concentration_factor.shape[:2] == (library.constants.shape[0], len(library.film_ids))
    records = {f["id"]: f for f in library.films}
    assert [c["pigment"] for c in records["R"]["concentration_factors"]] == []
    assert [c["pigment"] for c in records["RB"]["concentration_factors"]] == ["Black"]
    assert [c["pigment"] for c in records["RW1"]["concentration_factors"]] == []  # Red is being fitted
    assert [c["pigment"] for c in records["RW2"]["concentration_factors"]] == ["White"]
    # a factor of 1.4 at this prior is plausible (log 1.4 < 3 sd); the flag's own logic is below
    assert not any(c["implausible"] for r in records.values() for c in r["concentration_factors"])
    for i, film in enumerate(library.film_ids):
        for c, pigment in enumerate(names[film]):
            if not pigment:
                continue
            truth = CONCENTRATION_FACTOR if (film, pigment) == ("RB", "Black") else 1.0
            low, high = np.quantile(library.concentration_factor[:, i, c], [0.05, 0.95])
            assert low <= truth <= high, (film, pigment, low, high)
    _assert_constants_covered(library)
    for film in library.films:
        if film["used"]:
            assert film["rms_log_deviation"] < 3 * EPS, film
    assert library.provenance["concentration_sd"] == CONCENTRATION_SD


def test_concentration_factors_are_saved(concentrated, tmp_path):
    """concentration_factor over (chain, draw, film, component) in the file, read back whole; the
    pigment report's film table names each factor."""
    back = load_library(concentrated.save(tmp_path / "library.nc"))
    np.testing.assert_array_equal(back.concentration_factor, concentrated.concentration_factor)
    assert back.concentration_names == concentrated.concentration_names
    from bayespig.report.pigment import pigment_report

    text = pigment_report(concentrated, "Red")["Red.md"]
    factor = next(f for f in concentrated.films if f["id"] == "RB")["concentration_factors"][0]
    assert f"Black {factor['median']:.3f} [{factor['q05']:.3f}, {factor['q95']:.3f}]" in text
    assert "concentration_sd 0.3" in text


@pytest.mark.parametrize("bad", [-0.3, 0.0, float("nan"), float("inf"), "0.3", True])
def test_a_bad_concentration_sd_is_refused_naming_it(simulated, bad):
    sets, _, _ = simulated
    with pytest.raises(ValueError, match="concentration_sd"):
        build_library({"W": sets["W"]}, concentration_sd=bad, progress=False)


def test_a_factor_whose_interval_lies_beyond_three_prior_sds_is_implausible():
    sd = 0.3
    edge = np.exp(IMPLAUSIBLE_SDS * sd)
    assert implausible_factor(edge * 1.01, edge * 1.2, sd) and implausible_factor(1 / (edge * 1.2), 1 / (edge * 1.01), sd)
    assert not implausible_factor(edge * 0.99, edge * 1.2, sd) and not implausible_factor(0.9, 1.1, sd)



# --------------------------------------------------------------------------- the run's start, the noise scale

def _layout(sets, fitted, noise_scale="measured"):
    """The stage layout of ``sets`` with every pigment in ``fitted`` (as _fit_group builds it)."""
    from bayespig.library.build import LibraryLayout
    from bayespig.library.film_models import film_model
    from bayespig.library.recipes import concentrations, film_recipes

    model = film_model("radiative-transfer")
    recipes = film_recipes(sets)
    D = np.stack([concentrations(recipes[f], fitted, densities=DENSITIES) for f in sets])
    return LibraryLayout(model, [model.for_film(ms) for ms in sets.values()], D, fitted, None, EPS, WAVELENGTHS,
                         noise_scale=noise_scale)


def test_the_joint_least_squares_start_frees_the_films_thicknesses():
    """Two white masstones drawn at 0.4 and 2 x the nominal thickness and three greys at 0.6-2.5:
    at the nominal thickness no constants reproduce both masstones, and the per-wavelength fit
    stays far above the noise; fitting the constants and the thicknesses together reaches the
    noise (chi^2 per value ~ 1) and the masstones' thickness ratio."""
    from bayespig.inference.film_thickness import FilmThickness
    from bayespig.library.build import _least_squares_start, _standardized_residual, joint_least_squares_start

    table = load_table("8d-sce", progress=False)
    films = {"W": ({"White": 1.0}, 0.4), "W2": ({"White": 1.0}, 2.0), "WB1": (RECIPES["WB1"], 1.0),
             "WB2": (RECIPES["WB2"], 2.5), "WB3": ({"White": 0.95, "Black": 0.05}, 0.6)}
    sets = {name: _film(name, recipe, h, 300 + k, table) for k, (name, (recipe, h)) in enumerate(films.items())}
    layout = _layout(sets, ("White", "Black"))
    prior = FilmThickness(tuple(sets))
    n_values = layout.observed.size

    def chi2(theta, log_h):
        return float(np.sum(_standardized_residual(layout, theta, prior.model_inputs(log_h[None])) ** 2)) / n_values

    centre = _least_squares_start(layout, np.exp(prior.nominal))
    theta, log_h = joint_least_squares_start(layout, prior, centre)
    before, after = chi2(centre, prior.nominal), chi2(theta, log_h)
    # 1 % noise gives chi^2 ~ 1 per value (30 values, 4 x 3 constants and 5 thicknesses fitted:
    # below 1; 2 is ~3 sd of chi^2 / n above it)
    assert after < 2.0, after
    assert before > 10.0 * after, (before, after)
    # the masstones (tau 2 and 10) show their cards, so their ratio is fixed by the data (the
    # greys hide theirs, tau >= 9, and keep the prior's thickness): 15 % is ~3 sd at 1 % noise
    np.testing.assert_allclose(np.exp(log_h[1] - log_h[0]), 2.0 / 0.4, rtol=0.15)
    # the start of the run: FilmThickness(start=...) moves the pilot, not the prior
    spec = FilmThickness(tuple(sets), start=log_h)
    np.testing.assert_allclose(spec.nominal, log_h)
    np.testing.assert_array_equal(spec.mean, prior.mean)
    np.testing.assert_array_equal(spec.log_prior(log_h[None]), prior.log_prior(log_h[None]))


def test_a_film_thickness_start_is_clipped_into_the_prior_box_and_checked():
    from bayespig.inference.film_thickness import THICKNESS_PRIOR_SDS, FilmThickness

    spec = FilmThickness(("a", "b"), start=[10.0, -0.2])
    assert spec.lower[0] < spec.nominal[0] < spec.upper[0] and spec.nominal[0] > THICKNESS_PRIOR_SDS * 0.5 * 0.99
    assert spec.nominal[1] == -0.2
    with pytest.raises(ValueError, match=r"start must be one finite log h per film \(2\)"):
        FilmThickness(("a", "b"), start=[0.0])
    with pytest.raises(ValueError, match="start must be one finite log h per film"):
        FilmThickness(("a", "b"), start=[0.0, np.nan])


@pytest.mark.parametrize("noise_scale", ["measured", "model"])
def test_the_noise_scale_sets_the_sd_of_each_value(noise_scale):
    """The layout's log-likelihood against scipy's normal density with sd = eps x the measured
    value or eps x the predicted value (eq. 7), at predictions 30 % off."""
    table = load_table("8d-sce", progress=False)
    sets = {"W": _film("W", RECIPES["W"], 1.0, 7, table)}
    layout = _layout(sets, ("White",), noise_scale=noise_scale)
    values = np.concatenate([layout.observed[None] * 0.7, layout.observed[None] * 1.3])
    scale = layout.observed if noise_scale == "measured" else values
    expected = stats.norm.logpdf(layout.observed, loc=values, scale=EPS * scale)
    np.testing.assert_allclose(layout.log_density(None, values), expected, rtol=1e-12)
    np.testing.assert_allclose(layout.standardized_residual(values), (layout.observed - values) / (EPS * scale),
                               rtol=1e-12)


def test_an_unknown_noise_scale_is_refused_before_any_work(simulated):
    sets, _, _ = simulated
    with pytest.raises(ValueError, match="noise_scale must be one of 'measured', 'model', got 'data'"):
        build_library(sets, noise_scale="data", progress=False)


def test_the_noise_scale_is_recorded(library):
    assert library.provenance["noise_scale"] == "measured"


def test_the_library_records_the_contents_of_the_tables_it_was_fitted_with(library, default_builds):
    # the simulated films are 8d-sce films: the radiative-transfer stages used that one table
    table = load_table("8d-sce", progress=False)
    assert library.provenance["table_checksums"] == {table.key: table.checksum}
    with np.load(table_path(table.key), allow_pickle=False) as data:
        assert table.checksum == str(data["__checksum__"])
    # Kubelka-Munk has no look-up tables
    assert default_builds("kubelka-munk")[2].provenance["table_checksums"] == {}
