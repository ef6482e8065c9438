"""Summaries and diagnostics."""


import numpy as np
import pytest

from bayespig.inference import (
    ConvergenceWarning,
    diagnose,
    summarize,
)


def test_summary_table(method4_idata):
    summary = summarize(method4_idata)
    assert list(summary.index) == [450.0, 550.0, 650.0]
    post = method4_idata.posterior
    for k, wl in enumerate(summary.index):
        a = post["a"].values[..., k].ravel()
        log_tau = np.log(post["tau"].values[..., k].ravel())
        assert summary.loc[wl, "corr_a_log_tau"] == pytest.approx(np.corrcoef(a, log_tau)[0, 1], abs=1e-12)
        assert summary.loc[wl, "a_hdi_low"] < summary.loc[wl, "a_mean"] < summary.loc[wl, "a_hdi_high"]
        # a 90 % HDI of a near-Gaussian posterior is about 2 x 1.645 sd wide
        width = summary.loc[wl, "tau_hdi_high"] - summary.loc[wl, "tau_hdi_low"]
        assert 2.8 < width / summary.loc[wl, "tau_sd"] < 3.8
    assert (summary["a_r_hat"] < 1.01).all() and (summary["tau_ess_bulk"] > 400).all()
    assert diagnose(method4_idata) == []


def test_diagnose_flags_chains_that_disagree(method4_idata):
    broken = method4_idata.copy()
    a = broken.posterior["a"].values.copy()
    a[0, :, 1] += 3 * a[..., 1].std()  # chain 0 of 550 nm elsewhere
    broken.posterior["a"] = (("chain", "draw", "wavelength"), a)
    with pytest.warns(ConvergenceWarning, match="550 nm"):
        lines = diagnose(broken)
    assert len(lines) == 1 and lines[0].startswith("550 nm") and "R-hat(a)" in lines[0]
