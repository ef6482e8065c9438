"""Card factors on the substrate albedo (bayespig.inference.card_factors, infer(substrate_sd=...))."""

import dataclasses

import numpy as np
import pytest

from bayespig.data import simulate
from bayespig.data.simulate import FilmSpec
from bayespig.inference import InferenceSettings, infer
from bayespig.inference.card_factors import CardFactorLogPosterior, card_indices
from bayespig.likelihood import ForwardModel, Priors, Problem, multiplicative_normal_logpdf
from bayespig.table import load_table

WAVELENGTHS = np.array([450.0, 550.0, 650.0])
TRUE_WHITE, STATED_WHITE = 0.88, 0.80  # the card seen from the binder is 10 % brighter than stated
EPS = 0.002
QUICK = InferenceSettings(target_ess=400.0, draws_per_chain=512, max_steps=20000)
#: Grid reference of the one-wavelength posterior: nodes per axis, and the tolerance of the
#: posterior means and sds against it, in posterior sds: the Monte Carlo error of >= 1000
#: effective draws is ~0.03 sd on a mean and ~0.02 on an sd ratio; the grid's own is smaller.
GRID_NODES = 72
MOMENT_TOL_SD = 0.08


def _simulated(instrument, wavelengths=WAVELENGTHS, eps=EPS, a=(0.3, 0.1, 0.05), tau=(1.0, 1.2, 1.5)):
    n = len(wavelengths)
    ms = simulate(a=np.array(a[:n]), tau=np.array(tau[:n]),
                  design=[FilmSpec("ob", substrate=0.05, film_group="f"),
                          FilmSpec("ow", substrate=TRUE_WHITE, film_group="f")],
                  instrument=instrument, wavelengths=np.asarray(wavelengths), eps=eps, seed=11)
    samples = tuple(dataclasses.replace(s, substrate=STATED_WHITE) if s.name == "ow" else s for s in ms.samples)
    return dataclasses.replace(ms, samples=samples)


def test_r_s_scale_equals_the_forward_model_with_scaled_substrate():
    # WavelengthModel(r_s_scale=f) against ForwardModel.predict of a problem whose r_s is f * r_s.
    ms = _simulated("multi-angle-45")
    problem = Problem.from_measurements(ms, "method4")
    tables = {}
    model = ForwardModel(problem, "isotropic", tables)
    f = np.array([[1.0, 1.1], [0.9, 1.2]])
    scaled = dataclasses.replace(problem, films=tuple(
        dataclasses.replace(film, r_s=film.r_s * f[1, k]) for k, film in enumerate(problem.films)))
    reference = ForwardModel(scaled, "isotropic", tables).predict(0, np.array([0.2]), np.array([[0.8]]))
    fast = model.at_wavelength(0)(np.array([0.2, 0.2]), np.array([[0.8], [0.8]]), None, f)
    np.testing.assert_allclose(fast[1], reference[0], rtol=1e-10)
    # below the table's first tau node the slow path is used, with the same scaling
    tiny = model.at_wavelength(0)(np.array([0.2]), np.array([[1e-4]]), None, f[1:])
    ref_tiny = ForwardModel(scaled, "isotropic", tables).predict(0, np.array([0.2]), np.array([[1e-4]]))
    np.testing.assert_allclose(tiny, ref_tiny, rtol=1e-10)
    # without the keyword nothing changes
    np.testing.assert_allclose(model.at_wavelength(0)(np.array([0.2]), np.array([[0.8]])),
                               ForwardModel(problem, "isotropic", tables).predict(0, [0.2], [[0.8]]), rtol=1e-12)


def test_joint_log_posterior_in_residual_coordinates_is_the_direct_one():
    """The residual coordinates change nothing: log p(u) = log N(log f) + eq. (7) at theta(u), f(u)."""
    ms = _simulated("multi-angle-45")
    problem = Problem.from_measurements(ms, "method4")
    model = ForwardModel(problem, "isotropic", {})
    cards, index = card_indices(ms, problem)
    theta_hat = np.array([[0.3, 0.0], [0.1, 0.2], [0.05, 0.4]])
    post = CardFactorLogPosterior(model, index, theta_hat, Priors(), EPS, 0.1, cards)
    rng = np.random.default_rng(3)
    u = np.concatenate([rng.normal(0, 0.02, (5, 6)), rng.normal(0, 0.05, (5, 2))], axis=1)
    a, tau, f = post.unpack(u)
    expected = -0.5 * np.sum((np.log(f) / 0.1) ** 2, axis=1)
    for w in range(5):
        for i in range(WAVELENGTHS.size):
            scaled = dataclasses.replace(problem, films=tuple(
                dataclasses.replace(film, r_s=film.r_s * f[w, index[k]]) for k, film in enumerate(problem.films)))
            values = ForwardModel(scaled, "isotropic", model.tables).predict(i, a[w, i:i + 1], tau[w, i][None])
            expected[w] += multiplicative_normal_logpdf(problem.observed(i), values[0], EPS).sum()
    np.testing.assert_allclose(post(u), expected, rtol=1e-10)
    # a card brighter than r_s = 1 is outside the support
    u_out = u[:1].copy()
    u_out[0, -1] = np.log(1.3)  # white card 0.8 * 1.3 = 1.04
    assert post(u_out)[0] == -np.inf
    with pytest.raises(ValueError, match="card_index"):
        CardFactorLogPosterior(model, index[:1], theta_hat)
    with pytest.raises(ValueError, match="relative_sd"):
        CardFactorLogPosterior(model, index, theta_hat, relative_sd=0.0)


def test_infer_recovers_a_known_card_factor(tmp_path):
    """Multi-angle (six values per card and wavelength): the data move the white card's factor
    from the prior's 1 to the truth 1.1, and narrow it far below the 10 % prior."""
    ms = _simulated("multi-angle-45")
    idata = infer(ms, method="method4", eps=EPS, seed=5, progress=False, settings=QUICK, substrate_sd=0.1)
    factors = idata.posterior["r_s_factor"]
    assert list(factors.coords["card"].values) == ["0.05", str(STATED_WHITE)]
    white = factors.sel(card=str(STATED_WHITE)).values.ravel()
    low, high = np.quantile(white, [0.05, 0.95])
    truth = TRUE_WHITE / STATED_WHITE
    assert low < truth < high
    assert low > 1.0  # the data move the factor away from the prior's centre
    assert high - low < 0.15  # 90 % prior width ~0.33
    assert int(idata.sample_stats["max_steps_reached"].max()) == 0
    import arviz as az

    assert float(az.rhat(factors).to_array().max()) < 1.01
    assert idata.posterior["a"].shape[-1] == WAVELENGTHS.size
    from bayespig.inference import load_inference, save_inference

    save_inference(idata, tmp_path / "posterior.nc")
    assert load_inference(tmp_path / "posterior.nc").posterior["r_s_factor"].attrs == {
        "long_name": "factor on the card's albedo seen from the binder, r_s / r_s,card", "units": "1"}


def test_infer_with_card_factor_matches_a_grid_posterior():
    """One wavelength, 8°/d (one value per card): the posterior of log f (black card fixed by a
    tiny prior) against a brute-force 3-D grid over (a, log tau, log f_white) of the same density."""
    ms = _simulated("8d-sce", wavelengths=[550.0], eps=0.03, a=(0.1,), tau=(1.0,))
    problem = Problem.from_measurements(ms, "method4")
    table = load_table("8d-sce", progress=False)
    model = ForwardModel(problem, "isotropic", {"8d-sce": table})
    cards, index = card_indices(ms, problem)
    sd = 0.1
    idata = infer(ms, method="method4", eps=0.03, seed=2, progress=False, settings=QUICK, substrate_sd=sd)
    log_f = np.log(idata.posterior["r_s_factor"].values.reshape(-1, 2))
    a_draws = idata.posterior["a"].values.ravel()
    # grid reference of the same posterior: a, log tau uniform (the default Priors), log f normal
    post = CardFactorLogPosterior(model, index, np.array([[0.1, 0.0]]), Priors(), 0.03, sd, cards)
    a_axis = np.linspace(*np.quantile(a_draws, [0.0005, 0.9995]), GRID_NODES)
    t_draws = np.log(idata.posterior["tau"].values.ravel())
    t_axis = np.linspace(*np.quantile(t_draws, [0.0005, 0.9995]), GRID_NODES)
    f_axes = [np.linspace(max(-5 * sd, q0 - 0.05), q1 + 0.05, GRID_NODES // 2)
              for q0, q1 in zip(*np.quantile(log_f, [0.0005, 0.9995], axis=0))]
    A, T, F0, F1 = np.meshgrid(a_axis, t_axis, *f_axes, indexing="ij")
    log_f_grid = np.stack([F0.ravel(), F1.ravel()], axis=1)
    theta = np.stack([A.ravel(), T.ravel()], axis=1)
    u = np.concatenate([theta - post.theta_hat - log_f_grid @ post.sensitivity.T, log_f_grid], axis=1)
    logp = np.concatenate([post(chunk) for chunk in np.array_split(u, 64)])
    weight = np.exp(logp - logp.max())
    weight /= weight.sum()
    marginals = {"log f black": (log_f[:, 0], log_f_grid[:, 0]), "log f white": (log_f[:, 1], log_f_grid[:, 1]),
                 "a": (a_draws, A.ravel()), "log tau": (t_draws, T.ravel())}
    for name, (draws, nodes) in marginals.items():
        mean = np.sum(weight * nodes)
        sd_grid = np.sqrt(np.sum(weight * (nodes - mean) ** 2))
        assert abs(draws.mean() - mean) < MOMENT_TOL_SD * sd_grid, (name, draws.mean(), mean, sd_grid)
        assert abs(draws.std() / sd_grid - 1.0) < MOMENT_TOL_SD, (name, draws.std(), sd_grid)


def test_bad_substrate_arguments():
    ms = _simulated("8d-sce", wavelengths=[550.0], a=(0.1,), tau=(1.0,))
    with pytest.raises(ValueError, match="substrate_sd"):
        infer(ms, method="method4", eps=0.01, progress=False, substrate_sd=-0.1)
    with pytest.raises(ValueError, match="known eps"):
        infer(ms, method="method4", eps="infer", progress=False, substrate_sd=0.1)


def test_cli_infer_and_report_with_card_factors(tmp_path, capsys):
    """``bayespig report FILE --substrate-sd 0.1``: the factors in the report and its summary."""
    from bayespig.cli import main
    from bayespig.data import write_csv

    path = tmp_path / "film.csv"
    write_csv(_simulated("multi-angle-45"), path)
    assert main(["report", str(path), "--out", str(tmp_path / "r"), "--method", "4", "--substrate-sd", "0.1",
                 "--no-progress"]) == 0
    import json

    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    white = next(f for f in summary["substrate_factors"] if f["card"] == str(STATED_WHITE))
    assert white["low"] < TRUE_WHITE / STATED_WHITE < white["high"] and white["relative_sd"] == 0.1
    assert r"r\_s = f r\_s,card" in (tmp_path / "r" / "report.md").read_text()


def test_a_capped_joint_run_says_so():
    """A joint run stopped at max_steps warns once, naming the shared parameters."""
    import warnings

    from bayespig.inference import ConvergenceWarning

    ms = _simulated("8d-sce", wavelengths=[550.0], a=(0.1,), tau=(1.0,))
    short = InferenceSettings(min_steps=100, max_steps=100, check_interval=100, draws_per_chain=64)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        idata = infer(ms, method="method4", eps=0.01, seed=1, progress=False, settings=short, substrate_sd=0.1)
    joint = [str(w.message) for w in caught if issubclass(w.category, ConvergenceWarning)
             and "joint" in str(w.message)]
    assert joint == [("the joint run with substrate factors was capped at max_steps=100 before reaching 50 "
                     "autocorrelation times / ESS 1000")]
    assert idata.sample_stats["max_steps_reached"].values.tolist() == [1]
