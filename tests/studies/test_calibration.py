"""Simulation-based calibration (Talts et al. 2018) of the emcee posteriors."""

import numpy as np
import pytest

from bayespig.inference import InferenceSettings
from bayespig.studies.calibration import (
    ALPHA,
    CalibrationResult,
    plot_rank_histograms,
    simulation_based_calibration,
    write_calibration_report,
)

#: Fewer stored draws and a lower ESS target than the defaults: the fast study checks the
#: machinery, the slow one the default settings.
FAST = InferenceSettings(draws_per_chain=256, target_ess=400)


def synthetic(ranks, inside50, inside90, n_draws=99, n_bins=10):
    ranks = np.asarray(ranks)
    return CalibrationResult(
        method="synthetic", parameters=("a",), truth=np.zeros((ranks.size, 1)),
        ranks=ranks[:, None], inside={0.5: np.asarray(inside50)[:, None], 0.9: np.asarray(inside90)[:, None]},
        n_draws=n_draws, n_bins=n_bins, n_capped=0, seed=0, eps=0.05, instrument="x", settings="{}",
        elapsed_s=0.0)


def test_uniform_ranks_and_right_coverage_pass():
    n = 200
    ranks = np.arange(n) % 100  # exactly uniform over 0..99
    result = synthetic(ranks, np.arange(n) % 2 == 0, np.arange(n) % 10 != 0)
    assert result.uniformity_p_value(0) > 0.99
    assert result.coverage(0.5, 0) == 0.5 and result.coverage(0.9, 0) == 0.9
    assert result.passed()


def test_overconfident_posterior_fails():
    """Ranks piled at the ends (posterior too narrow) and low coverage are detected."""
    rng = np.random.default_rng(0)
    n = 200
    ranks = np.where(rng.random(n) < 0.5, rng.integers(0, 10, n), rng.integers(90, 100, n))
    result = synthetic(ranks, rng.random(n) < 0.3, rng.random(n) < 0.7)
    assert result.uniformity_p_value(0) < ALPHA
    assert result.coverage_p_value(0.9, 0) < ALPHA
    assert not result.passed()


def test_bad_arguments():
    with pytest.raises(ValueError, match="n_bins"):
        simulation_based_calibration("method4", n_replicates=10, n_draws=100, n_bins=10)
    with pytest.raises(ValueError, match="n_replicates"):
        simulation_based_calibration("method4", n_replicates=1)


def test_small_sbc_of_method4(tmp_path):
    """A small SBC through the whole path (prior draws, simulation, infer, ranks, report)."""
    result = simulation_based_calibration("method4", n_replicates=8, n_draws=39, n_bins=4, seed=3,
                                          settings=FAST, executor=None)
    assert result.ranks.shape == (8, 2) and result.truth.shape == (8, 2)
    assert ((result.ranks >= 0) & (result.ranks <= 39)).all()
    assert (0 <= result.truth[:, 0]).all() and (result.truth[:, 0] <= 1).all()
    assert (np.log(0.01) <= result.truth[:, 1]).all() and (result.truth[:, 1] <= np.log(100)).all()
    # 8 replicates have little power; the gross failures (e.g. truth never inside) are excluded
    assert result.passed()
    figure = plot_rank_histograms([result], tmp_path / "ranks.png")
    report = write_calibration_report(tmp_path / "calibration.md", [result], figure=figure)
    text = (tmp_path / "calibration.md").read_text(encoding="utf-8")
    assert report == str(tmp_path / "calibration.md")
    assert "method4" in text and "ranks.png" in text and "pass" in text


@pytest.mark.slow
@pytest.mark.parametrize("method", ["method4", "method3"])
def test_full_sbc(method):
    """Issue 6: >= 200 prior replicates; rank histograms uniform and 50/90 % coverage at 1 %."""
    # the default settings, as in reports/calibration.md (short runs of method 3's ravines,
    # `--short-runs method3`, stop before the chains mix and are not expected to pass)
    result = simulation_based_calibration(method, n_replicates=200, seed=0)
    assert result.passed(), result.rows()
