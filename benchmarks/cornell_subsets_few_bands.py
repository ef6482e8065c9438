"""Benchmark: the Cornell subset-consistency fits at a few bands, chain by chain (issue 16).

Run from the repository root (prints only; ~10-20 min per subset on one core once the Cornell
rough tables are cached, e.g. by ``bayespig cornell``)::

    python benchmarks/cornell_subsets_few_bands.py [garnet_red] [600,650,700] [near,far]

The subset fits of ``bayespig cornell`` (the same geometry sets, model, priors, sampler
settings and seed; ``bayespig.studies.cornell``) at a few bands only. With all 31 bands the
near-mirror subset's ``a`` did not mix at any band in the committed report, so its 90 %
intervals there are the spread of chains that disagree; a run on fewer bands has fewer
per-band ravines to travel and shows what the near subset's posterior is when it does mix.
Printed per subset: wall time and steps, then per band the median and 90 % interval of ``a``,
its R-hat and bulk / tail ESS, and the four chains' medians; then the shared parameters the same
way; with both subsets, whether their 90 % intervals of ``a`` overlap at each band.
"""
import sys
import time
import warnings

import arviz as az
import numpy as np

from bayespig.data import read_measurements
from bayespig.inference import infer
from bayespig.studies.cornell import (
    CornellStudySettings,
    default_cornell_path,
    interval_overlap,
    rough_fit_arguments,
    study_sets,
)

sys.path.insert(0, "benchmarks")
from _common import machine_line

paint = sys.argv[1] if len(sys.argv) > 1 else "garnet_red"
bands = [float(b) for b in (sys.argv[2] if len(sys.argv) > 2 else "600,650,700").split(",")]
subsets = (sys.argv[3] if len(sys.argv) > 3 else "near,far").split(",")
study = CornellStudySettings()
print(machine_line())
_, _, far, near = study_sets(read_measurements(default_cornell_path() / f"{paint}.astm", opaque=True), study)
intervals = {}
for name in subsets:
    measurements = {"far": far, "near": near}[name]
    started = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the cap and convergence warnings: the diagnostics below say it
        idata = infer(measurements, wavelengths=bands, **rough_fit_arguments(study))
    seconds = time.perf_counter() - started
    n_geometries = len(measurements.films[0].measurements)
    steps = idata.sample_stats["n_steps"].values
    print(f"{paint} subset '{name}': {n_geometries} geometries, {seconds:.0f} s, steps per run "
          f"{', '.join(str(int(s)) for s in np.atleast_1d(steps))}")
    table = az.summary(idata, kind="diagnostics")
    post = idata.posterior
    a = np.asarray(post["a"].values, dtype=float)  # (chain, draw, band)
    intervals[name] = np.quantile(a.reshape(-1, a.shape[-1]), [0.05, 0.95], axis=0)
    for k, band in enumerate(bands):
        row = table.loc[f"a[{band}]"]
        low, mid, high = np.quantile(a[..., k], [0.05, 0.5, 0.95])
        print(f"  a {band:g} nm: {mid:.3f} [{low:.3f}, {high:.3f}], R-hat {row['r_hat']:.3f}, ESS bulk "
              f"{row['ess_bulk']:.0f} tail {row['ess_tail']:.0f}; chain medians "
              + " ".join(f"{v:.3f}" for v in np.median(a[..., k], axis=1)))
    for variable in ("roughness", "binder_index", "flake_roughness"):
        if variable in post:
            values = np.asarray(post[variable].values, dtype=float).reshape(a.shape[0], a.shape[1])
            row = table.loc[[label for label in table.index if label.startswith(variable + "[")][0]]
            low, mid, high = np.quantile(values, [0.05, 0.5, 0.95])
            print(f"  {variable}: {mid:.4f} [{low:.4f}, {high:.4f}], R-hat {row['r_hat']:.3f}, ESS bulk "
                  f"{row['ess_bulk']:.0f}; chain medians " + " ".join(f"{v:.4f}" for v in np.median(values, axis=1)))
if {"far", "near"} <= set(intervals):
    overlap = interval_overlap(intervals["far"], intervals["near"])
    print("90 % intervals of a overlap: " + ", ".join(f"{b:g} nm {'yes' if o else 'no'}"
                                                      for b, o in zip(bands, overlap)))
