"""Posterior widths from one set next to the frequentist RMS (bayespig robustness --posterior)."""

import numpy as np
import pytest

from bayespig.inference import InferenceSettings
from bayespig.studies.posterior_robustness import posterior_robustness, write_posterior_tables

#: Issue 6: method 4 at tau0 <= 1, posterior sd within this factor of the RMS of the refits.
SD_RMS_FACTOR = 1.5
FAST = InferenceSettings(draws_per_chain=512, target_ess=400)


def test_method4_report_agrees_with_the_refits(tmp_path):
    path = tmp_path / "posterior-robustness.md"
    records = write_posterior_tables(path, methods=("method4",), a0_values=(0.1,), tau0_values=(0.5, 1.0),
                                     n_repeat=200, settings=FAST, seed=1, executor=None)
    assert [(r["a0"], r["tau0"]) for r in records] == [(0.1, 0.5), (0.1, 1.0)]
    ratios = np.array([[r["a_sd"] / r["a_rms"], r["tau_sd"] / r["tau_rms"]] for r in records])  # (2, 2)
    assert ((1 / SD_RMS_FACTOR < ratios) & (ratios < SD_RMS_FACTOR)).all(), ratios
    assert not any(r["flagged"] for r in records)
    text = path.read_text(encoding="utf-8")
    assert "## method4" in text and "sd/RMS" in text and "bayespig robustness --posterior" in text


def test_eps_must_be_positive():
    with pytest.raises(ValueError, match="eps"):
        posterior_robustness(("method4",), (0.1,), (1.0,), eps=0.0)
