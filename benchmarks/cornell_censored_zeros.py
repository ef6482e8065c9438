"""Benchmark: the Cornell paints' exact zeros as censored readings against Gaussian readings (issue 16).

Run from the repository root (prints only; a few minutes per paint once the Cornell rough tables
are cached, e.g. by ``bayespig cornell``)::

    python benchmarks/cornell_censored_zeros.py [krylon_blue,garnet_red] [420,450,600] [exclude-occluded]

The joint fit of the Cornell study (every geometry > 2 deg from the mirror, roughness and binder
index free, flakes, the incidence offset, one noise floor per band; ``bayespig.studies.cornell``)
at a few bands, once with the zeros as Gaussian readings of the clipped mean (the default) and
once with ``censored_zeros=True`` (``P(reading <= 0)`` for every exact zero). Printed per band:
the posterior median and 90 % interval of ``a``, of the floor ``sigma0`` and of the offset ``b``;
the zeros' mean log-likelihood per reading; the median |x / m - 1| of the positive readings
(all, and at 70-80 deg incidence where the zeros are); the model check's p-value
(``bayespig.report.quantities.posterior_predictive_check``: with censoring the zeros enter by their
probability); the run's steps and wall time. ``exclude-occluded`` leaves out the occluded geometries
(``bayespig.selection.occluded_geometries``) as the study does; by default they stay in.
"""
import sys
import time
import warnings

import numpy as np

from bayespig.data import read_measurements
from bayespig.inference import infer
from bayespig.report.quantities import posterior_predictive_check
from bayespig.selection import select_measurements
from bayespig.studies.cornell import (
    MIRROR_CUT_DEG,
    CornellStudySettings,
    default_cornell_path,
    rough_fit_arguments,
)

sys.path.insert(0, "benchmarks")
from _common import machine_line

paints = (sys.argv[1] if len(sys.argv) > 1 else "krylon_blue,garnet_red").split(",")
bands = [float(b) for b in (sys.argv[2] if len(sys.argv) > 2 else "420,450,600").split(",")]
exclude_occluded = "exclude-occluded" in sys.argv[3:]
study = CornellStudySettings()
print(machine_line())
print(f"occluded geometries {'left out' if exclude_occluded else 'kept'}")
for paint in paints:
    ms = select_measurements(read_measurements(default_cornell_path() / f"{paint}.astm", opaque=True),
                             exclude_mirror_deg=MIRROR_CUT_DEG, wavelengths=bands,
                             exclude_occluded=exclude_occluded)
    rows = ms.films[0].measurements
    theta_i = np.array([m.theta_i for m in rows])
    x = np.array([m.values for m in rows])  # (n_geometries, n_bands)
    zero = x == 0
    print(f"{paint}: {len(rows)} geometries, zeros per band "
          + ", ".join(f"{b:g} nm {int(z)}" for b, z in zip(bands, zero.sum(axis=0))))
    for censored in (False, True):
        started = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            idata = infer(ms, censored_zeros=censored, **rough_fit_arguments(study))
        seconds = time.perf_counter() - started
        post = idata.posterior
        steps = int(idata.sample_stats["n_steps"].values.max())
        capped = any("capped" in str(w.message) for w in caught)
        predicted = idata.posterior_predictive["y"].transpose("chain", "draw", "wavelength", ...).values
        y = np.median(predicted.reshape((-1, len(bands), len(rows))), axis=0).T  # (n_geometries, n_bands)
        pointwise = idata.log_likelihood["y"].transpose("chain", "draw", "wavelength", ...).values
        loglik = pointwise.reshape((-1, len(bands), len(rows))).mean(axis=0).T
        p_value = posterior_predictive_check(idata)["p_value"]
        print(f"  {'censored' if censored else 'gaussian'}: {seconds:.0f} s, steps {steps}"
              + (" (capped)" if capped else ""))
        for k, band in enumerate(bands):
            def interval(name, k=k, post=post):
                values = post[name].values.reshape(-1, len(bands))[:, k]
                low, mid, high = np.quantile(values, [0.05, 0.5, 0.95])
                return f"{mid:.3g} [{low:.3g}, {high:.3g}]"
            positive = ~zero[:, k]
            rel = np.abs(x[positive, k] / y[positive, k] - 1.0)
            grazing = theta_i[positive] >= 70.0
            zeros_ll = loglik[zero[:, k], k].mean() if zero[:, k].any() else float("nan")
            print(f"    {band:g} nm: a {interval('a')}, floor {interval('noise_floor')}, "
                  f"b {interval('incidence_offset')}, zeros' log-lik {zeros_ll:.2f}, "
                  f"|res| {np.median(rel):.3f} (70-80 deg {np.median(rel[grazing]):.3f}), "
                  f"model check p {p_value[k]:.3g}")
