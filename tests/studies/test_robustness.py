"""The paper's robustness study (issue 5): analytic method 1, the paper's findings, outliers.

References: the paper's analytic result for method 1 (section 4.1: tau = tau0 - log(1 + eps xi),
so its RMS is eps and its mean tau0 + eps^2/2), the paper's robust findings (section 4.2),
scipy.stats.median_abs_deviation for the robust spread, a serial executor for the parallel
ones, and the exact solver (noise-free replicates must be fitted back to the truth).
"""

import json
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from scipy.stats import median_abs_deviation

from bayespig.fit import FitSettings
from bayespig.studies import (
    PAPER_A0,
    PAPER_A_RMS,
    PAPER_METHODS,
    PAPER_TAU0,
    PAPER_TAU_RMS,
    RobustnessGrid,
    RobustnessResult,
    plot_robustness_map,
    robustness_map,
    robustness_study,
    write_paper_tables,
)
from bayespig.studies.robustness import opacity_contrast

EPS = 0.05
#: Monte-Carlo sigmas allowed for statistics with a known expectation.
MC_SIGMAS = 4.0
#: Noise-free replicates fitted back to the truth (issue 5), absolutely in a and tau.
RECOVERY_ABS_TOL = 1e-4
#: Method 4's tau error may exceed the best method's by this factor for tau0 <= 1 (issue 5).
METHOD4_TAU_FACTOR = 1.25
#: a errors of methods 1, 2 and 4 stay below this (issue 5: "a few 1e-3").
A_ERROR_LIMIT = 0.01
#: bayespig's RMS against the paper's Tables 1-2 where no fit reaches a bound: the paper's
#: own figures come from a different fitter and random draws, so agreement within a factor 3
#: (not more) is what a re-implementation can promise.
PAPER_RMS_FACTOR = 3.0
#: Replicates of the fast default-run studies and of the analytic method 1 check.
N_FAST = 200
N_METHOD1 = 20_000
N_ESCAPE = 4000


@pytest.fixture(scope="module", autouse=True)
def table_cache(private_table_cache):
    """Tables of this module are built into a temporary cache (the user's cache is untouched)."""
    return private_table_cache


@pytest.fixture(scope="module")
def paper_grid(table_cache):
    """The paper's 36 cases with 200 replicates each, through the default pool of 2 processes."""
    return robustness_study(PAPER_METHODS, PAPER_A0, PAPER_TAU0, n_repeat=N_FAST, eps=EPS)


def assert_paper_findings(grid):
    """The paper's robust findings (section 4.2), as the issue states them."""
    for a0 in PAPER_A0:
        for tau0 in PAPER_TAU0:
            cell = {m: grid[m, a0, tau0] for m in PAPER_METHODS}
            worst_tau = max(cell, key=lambda m: cell[m].tau_rms)
            worst_a = max(cell, key=lambda m: cell[m].a_rms)
            assert worst_tau == "method3" and worst_a == "method3", (a0, tau0)
            for m in ("method1", "method2", "method4"):
                assert cell[m].a_rms < A_ERROR_LIMIT, (m, a0, tau0)
            if tau0 <= 1.0:
                best = min(r.tau_rms for r in cell.values())
                assert cell["method4"].tau_rms <= METHOD4_TAU_FACTOR * best, (a0, tau0)


# --- method 1: the paper's analytic result --------------------------------------------------------
def test_method1_tau_error_is_eps_and_its_shift_eps_squared_over_two():
    result = robustness_study("method1", 0.1, 1.0, eps=EPS, n_repeat=N_METHOD1, seed=1)
    assert isinstance(result, RobustnessResult) and result.tau.shape == (N_METHOD1,)
    # tau = tau0 - log(1 + eps xi): sd = eps (1 + O(eps^2)), mean = tau0 + eps^2 / 2 + O(eps^4)
    sd_error = EPS / np.sqrt(2.0 * (N_METHOD1 - 1))
    assert abs(result.tau_rms - EPS) < MC_SIGMAS * sd_error + EPS**3
    mean_error = result.tau_rms / np.sqrt(N_METHOD1)
    assert abs(result.tau_bias - EPS**2 / 2) < MC_SIGMAS * mean_error
    assert result.fraction_at_bound == 0.0 and result.fraction_converged == 1.0


def test_methods_1_and_2_share_the_opaque_film_and_its_a(paper_grid):
    """Common random numbers: the same seed gives the opaque film the same noise in both designs."""
    for a0 in PAPER_A0:
        np.testing.assert_array_equal(
            paper_grid["method1", a0, 0.5].a, paper_grid["method2", a0, 2.0].a
        )


# --- the paper's findings -------------------------------------------------------------------------
def test_the_papers_findings_hold_on_the_fast_study(paper_grid):
    assert isinstance(paper_grid, RobustnessGrid)
    assert paper_grid.tau_rms.shape == (4, 3, 3) and paper_grid.a_bias.shape == (4, 3, 3)
    assert_paper_findings(paper_grid)
    for a0 in PAPER_A0:
        for tau0 in PAPER_TAU0:
            m1 = paper_grid["method1", a0, tau0]
            assert abs(m1.tau_rms - EPS) < MC_SIGMAS * EPS / np.sqrt(2.0 * (N_FAST - 1))


@pytest.mark.slow
def test_the_papers_findings_hold_on_the_full_study():
    """The paper's study as published: 36 cases x 1000 replicates (about 15 s on 2 cores)."""
    grid = robustness_study(PAPER_METHODS, PAPER_A0, PAPER_TAU0, n_repeat=1000, eps=EPS)
    assert_paper_findings(grid)
    method1_tau_rms = np.array([grid["method1", a0, tau0].tau_rms for a0 in PAPER_A0 for tau0 in PAPER_TAU0])
    assert (np.abs(method1_tau_rms - EPS) < MC_SIGMAS * EPS / np.sqrt(2.0 * 999)).all(), method1_tau_rms
    # where no fit reaches a bound, methods 2 and 4 are within a factor 3 of the paper
    cells = [(m, a0, tau0) for m in ("method2", "method4") for a0 in PAPER_A0 for tau0 in PAPER_TAU0
             if grid[m, a0, tau0].fraction_at_bound == 0 and PAPER_TAU_RMS[(m, a0, tau0)] < 1.0]
    # the comparison must not be empty: of the 18 cells of methods 2 and 4, only the tau0 = 2
    # cells with large paper errors (3 of them) or fits at a bound may be left out
    assert len(cells) >= 12, cells
    ratios = np.array([(grid[cell].tau_rms / PAPER_TAU_RMS[cell], grid[cell].a_rms / PAPER_A_RMS[cell])
                       for cell in cells])
    outside = [cell for cell, pair in zip(cells, ratios)
               if not ((1 / PAPER_RMS_FACTOR < pair) & (pair < PAPER_RMS_FACTOR)).all()]
    assert not outside, (outside, ratios)


@pytest.mark.parametrize("method", PAPER_METHODS)
def test_noise_free_replicates_are_fitted_back_to_the_truth(method):
    grid = robustness_study(method, PAPER_A0, PAPER_TAU0, eps=0.0, n_repeat=2)
    for a0 in PAPER_A0:
        for tau0 in PAPER_TAU0:
            result = grid[method, a0, tau0]
            np.testing.assert_allclose(result.a, a0, atol=RECOVERY_ABS_TOL, rtol=0)
            np.testing.assert_allclose(result.tau, tau0, atol=RECOVERY_ABS_TOL, rtol=0)


# --- tau0 = 2: outliers at the bound --------------------------------------------------------------
def test_large_tau_errors_at_tau0_2_are_fits_escaping_to_the_opaque_bound():
    """Method 2, a0 = 0.2, tau0 = 2: a few fits end at tau = 128 and make the RMS; MAD does not."""
    result = robustness_study("method2", 0.2, 2.0, eps=EPS, n_repeat=N_ESCAPE, seed=2)
    p = result.fraction_tau_at_upper
    assert 0 < p < 0.01
    assert np.all(result.tau[result.tau_at_upper] == pytest.approx(128.0))
    assert result.tau_rms > 5 * result.tau_mad and result.tau_rms > 5 * result.tau_half_width_68
    assert result.tau_rms_interior < 0.5
    # the RMS is the escapes times the box: sd of a two-point mixture at tau0 and 128
    expected = np.sqrt(p * (1 - p)) * (128.0 - 2.0)
    assert result.tau_rms == pytest.approx(expected, rel=0.1)
    # a smaller box shrinks the RMS, not the robust spread
    boxed = robustness_study(
        "method2",
        0.2,
        2.0,
        eps=EPS,
        n_repeat=N_ESCAPE,
        seed=2,
        fit_settings=FitSettings(tau_bounds=(1e-3, 20.0)),
    )
    assert boxed.tau_rms < result.tau_rms / 3
    assert boxed.tau_mad == pytest.approx(result.tau_mad, rel=0.05)


def test_opacity_contrast_shrinks_as_the_film_thickens_and_absorbs():
    thin = opacity_contrast("method2", 0.1, 0.5)["on_black"]
    assert (
        thin
        > opacity_contrast("method2", 0.1, 2.0)["on_black"]
        > opacity_contrast("method2", 0.2, 2.0)["on_black"]
    )
    assert opacity_contrast("method2", 0.2, 64.0)["on_black"] < 1e-6
    assert set(opacity_contrast("method4", 0.1, 1.0)) == {"on_black", "on_white"}
    assert opacity_contrast("method1", 0.1, 1.0) == {}


# --- statistics, seeds, executors -----------------------------------------------------------------
def test_statistics_are_the_stated_estimators(paper_grid):
    r = paper_grid["method4", 0.1, 1.0]
    assert r.a_rms == pytest.approx(np.std(r.a, ddof=1), rel=1e-12)
    assert r.tau_bias == pytest.approx(np.mean(r.tau) - 1.0, rel=1e-12)
    assert r.tau_mad == pytest.approx(median_abs_deviation(r.tau, scale="normal"), rel=1e-12)
    assert r.a_mad == pytest.approx(median_abs_deviation(r.a, scale="normal"), rel=1e-12)
    lo, hi = np.sort(r.tau)[[int(0.16 * N_FAST), int(0.84 * N_FAST)]]
    assert r.tau_half_width_68 == pytest.approx((hi - lo) / 2, rel=0.2)
    summary = r.summary()
    assert (
        summary["method"] == "method4"
        and summary["tau_rms"] == r.tau_rms
        and summary["n_repeat"] == N_FAST
    )
    assert len(paper_grid.to_records()) == 36


def test_same_seed_same_result_other_seed_other_result():
    one = robustness_study("method4", 0.1, 1.0, n_repeat=30, seed=4)
    two = robustness_study("method4", 0.1, 1.0, n_repeat=30, seed=4)
    other = robustness_study("method4", 0.1, 1.0, n_repeat=30, seed=5)
    np.testing.assert_array_equal(one.a, two.a)
    np.testing.assert_array_equal(one.tau, two.tau)
    assert not np.array_equal(one.tau, other.tau)


def test_executors_give_identical_results():
    """Default pool of 2 processes, a serial executor and a dask client's executor agree exactly."""
    from dask.distributed import Client, LocalCluster

    cases = {
        "method": ("method2", "method4"),
        "a0": (0.1,),
        "tau0": (0.5, 2.0),
        "n_repeat": 40,
        "seed": 3,
    }
    default = robustness_study(**cases)
    with ThreadPoolExecutor(max_workers=1) as serial:
        reference = robustness_study(**cases, executor=serial)
    with (
        LocalCluster(
            n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        distributed = robustness_study(**cases, executor=client.get_executor())
    for grid in (default, distributed):
        for key in reference.results:
            np.testing.assert_array_equal(grid.results[key].a, reference.results[key].a)
            np.testing.assert_array_equal(grid.results[key].tau, reference.results[key].tau)


def test_a_method_in_any_spelling():
    """``4``, ``"4"`` and ``"method4"`` are the same study (issue 18: ``robustness_study(4, ...)``
    raised ``TypeError: 'int' object is not iterable``)."""
    reference = robustness_study("method4", 0.1, 1.0, n_repeat=8, seed=0)
    for spelling in (4, "4", np.int64(4)):
        result = robustness_study(spelling, 0.1, 1.0, n_repeat=8, seed=0)
        assert result.method == "method4"
        np.testing.assert_array_equal(result.tau, reference.tau)
    grid = robustness_study([1, "method4"], 0.1, (0.5, 1.0), n_repeat=4, seed=0)
    assert grid.methods == ("method1", "method4")
    np.testing.assert_array_equal(grid[4, 0.1, 1.0].tau, grid["method4", 0.1, 1.0].tau)
    assert robustness_map(3, [0.1], [1.0], n_repeat=3).methods == ("method3",)
    assert opacity_contrast(4, 0.1, 1.0) == opacity_contrast("method4", 0.1, 1.0)
    with pytest.raises(TypeError, match="method must be a method number or name"):
        robustness_study(None, 0.1, 1.0, n_repeat=8)


def test_progress_bar_counts_the_refits(capsys):
    robustness_study((1, 4), 0.1, (0.5, 1.0), n_repeat=3, seed=0, progress=True)
    err = capsys.readouterr().err
    assert "robustness: 100%" in err and "12/12" in err  # 2 methods x 2 cases x 3 refits
    robustness_study(1, 0.1, 0.5, n_repeat=3, seed=0)
    assert capsys.readouterr().err == ""


def test_posterior_robustness_shows_its_progress_and_takes_a_method_number(tmp_path, capsys):
    """``bayespig robustness --posterior`` ran 51 s without a word (issue 18)."""
    from bayespig.inference import InferenceSettings
    from bayespig.studies.posterior_robustness import write_posterior_tables

    records = write_posterior_tables(tmp_path / "p.md", methods=(4,), a0_values=(0.1,), tau0_values=(1.0,),
                                     n_repeat=4, settings=InferenceSettings(draws_per_chain=256, target_ess=100),
                                     progress=True)
    assert [r["method"] for r in records] == ["method4"]
    err = capsys.readouterr().err
    assert "robustness: 100%" in err and "4/4" in err  # the refits
    assert "posterior robustness: method4, 1 case\n" in err and "inference: 100%" in err
    assert "## method4" in (tmp_path / "p.md").read_text(encoding="utf-8")


def test_bad_arguments_raise_value_errors():
    for kwargs, match in (
        ({"method": "method5"}, "unknown method .method5.: method must be one of 1, 2, 3, 4, method1, method2, method3, method4$"),
        ({"a0": 1.5}, "a0"),
        ({"tau0": 0.0}, "tau0"),
        ({"tau0": 500.0}, "tau0 must be <= 128"),
        ({"eps": 0.3}, "eps"),
        ({"n_repeat": 1}, "n_repeat"),
        ({"seed": -1}, "seed"),
    ):
        arguments = {"method": "method4", "a0": 0.1, "tau0": 1.0, "n_repeat": 10} | kwargs
        with pytest.raises(ValueError, match=match):
            robustness_study(**arguments)
    with pytest.raises(ValueError, match="unknown statistic"):
        robustness_map("method1", [0.1], [1.0], n_repeat=3).statistic("nope")


# --- map, figure, report --------------------------------------------------------------------------
def test_robustness_map_and_its_figure(tmp_path):
    grid = robustness_map(("method3", "method4"), [0.05, 0.2], [0.5, 2.0], n_repeat=20)
    assert grid.statistic("tau_rms_relative").shape == (2, 2, 2)
    path = tmp_path / "map.png"
    figure = plot_robustness_map(grid, path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(figure.axes) >= 4  # 2 statistics x 2 methods (+ colour bars)
    grid.write_json(tmp_path / "map.json")
    records = json.loads((tmp_path / "map.json").read_text())
    assert len(records) == 8 and records[0]["method"] == "method3"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.json", "map.png"]


def test_paper_tables_report_is_written_with_both_tables(tmp_path, capsys):
    path = tmp_path / "paper-tables.md"
    grids = write_paper_tables(
        path, n_repeat=10, extras=False, command="bayespig robustness --paper", progress=True
    )
    # one progress bar on stderr over every refit: 4 methods x 9 pairs x 2 instruments x 10
    err = capsys.readouterr().err
    assert "robustness: 100%" in err and "720/720" in err
    text = path.read_text()
    assert "`bayespig robustness --paper`" in text
    for heading in (
        "## Table 1",
        "## Table 2",
        "## Systematic errors",
        "## Robust spreads",
        "## What drives the large tau errors at tau0 = 2",
        "## Geometry dependence",
        "## Where bayespig and the paper differ",
    ):
        assert heading in text
    assert "3.77 / " in text and "0.055 / " in text  # the paper's values beside bayespig's
    assert set(grids) == {"main", "alternative"}
    assert [p.name for p in tmp_path.iterdir()] == ["paper-tables.md"]
