"""Benchmark: the additive noise floor on the real Cornell gonio paints (``infer(noise_floor=...)``).

Run from the repository root (prints only; ~2 minutes on 2 cores)::

    python benchmarks/noise_floor.py

For each Cornell paint (``../shared/data/cornell``, opaque films under a frosted overcoat) the
geometries >= 30° from the mirror direction with incidence and viewing <= 50° are fitted at two
bands (one where the paint is dark, one where it is bright) with ``eps`` inferred, once with
the noise floor inferred and once without one (eq. 7 alone). Printed per run: wall time, and
per band the 5 / 50 / 95 % quantiles of ``a``, ``eps`` and the floor [1/sr], and the posterior
predictive p-value of the model check (small = the noise model cannot explain the scatter),
the run lengths and any convergence flags.
Also: how many exact zeros the paints have at the geometries > 2° from the mirror (refused
without a floor).

``--subsets``: the issue's consistency test with the floor and ``eps`` inferred (smooth
surface): ``a`` at ``SUBSET_BANDS`` from the geometries >= 30° from the mirror against those
2–30° from it (both <= 50°), and whether their 90 % intervals overlap (runs capped at
``SUBSET_MAX_STEPS``).
"""

import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

CORNELL = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "cornell"
CORNELL = CORNELL if CORNELL.exists() else Path("/work/shared/data/cornell")
PAINTS = {"garnet_red": (450.0, 650.0), "krylon_blue": (450.0, 600.0)}
SELECTION = {"exclude_mirror_deg": 30.0, "max_angle_deg": 50.0}
SUBSET_BANDS = (450.0, 550.0, 650.0)
SUBSET_MAX_STEPS = 4000


def near_mirror(measurements, low_deg, high_deg, max_angle_deg):
    """The set with only the films' geometries in [low, high) degrees from the mirror."""
    import dataclasses

    from bayespig.data import MeasurementSet
    from bayespig.selection import mirror_distance_deg

    samples = []
    for sample in measurements.samples:
        kept = tuple(m for m in sample.measurements
                     if low_deg <= mirror_distance_deg(m.theta_i, m.theta_o, m.delta_phi) < high_deg
                     and max(m.theta_i, m.theta_o) <= max_angle_deg)
        samples.append(dataclasses.replace(sample, measurements=kept))
    return MeasurementSet(measurements.wavelength_nm, samples, n=measurements.n)


def subsets():
    """The subset-consistency table with the noise floor (see the module docstring)."""
    from bayespig.inference import InferenceSettings, infer
    from bayespig.selection import select_measurements

    settings = InferenceSettings(n_walkers=16, n_ensembles=4, draws_per_chain=512, target_ess=400,
                                 max_steps=SUBSET_MAX_STEPS)
    print("paint, band: a [90 %] >= 30° from the mirror | 2–30° | overlap")
    for paint in PAINTS:
        measurements = read_opaque(CORNELL / f"{paint}.astm")
        far = select_measurements(measurements, **SELECTION, wavelengths=list(SUBSET_BANDS))
        near = select_measurements(near_mirror(measurements, 2.0, 30.0, SELECTION["max_angle_deg"]),
                                   wavelengths=list(SUBSET_BANDS))
        intervals = []
        for subset in (far, near):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                idata = infer(subset, eps="infer", noise_floor="infer", seed=1, progress=False, settings=settings,
                              executor=None)
            intervals.append(np.quantile(idata.posterior["a"].values.reshape(-1, len(SUBSET_BANDS)),
                                         [0.05, 0.5, 0.95], axis=0))
        for k, band in enumerate(SUBSET_BANDS):
            (l1, m1, h1), (l2, m2, h2) = intervals[0][:, k], intervals[1][:, k]
            overlap = "yes" if max(l1, l2) <= min(h1, h2) else "no"
            print(f"  {paint} {band:g} nm: {m1:.3f} [{l1:.3f}, {h1:.3f}] ({len(far.films[0].measurements)} geometries)"
                  f" | {m2:.3f} [{l2:.3f}, {h2:.3f}] ({len(near.films[0].measurements)}) | {overlap}")


def read_opaque(path):
    """The file as an opaque film (the E1392 files do not say so; add the reader's OPAQUE line)."""
    from bayespig.data import read_measurements

    text = path.read_text()
    if "\nOPAQUE" not in text:
        text = text.replace("\nMEAS_NAME", "\nOPAQUE yes\nMEAS_NAME", 1)
    with tempfile.TemporaryDirectory() as folder:
        copy = Path(folder) / f"{path.stem}_opaque.astm"
        copy.write_text(text)
        return read_measurements(copy)


def main(argv=None):
    from bayespig.inference import InferenceSettings, diagnose, infer
    from bayespig.report.quantities import posterior_predictive_check
    from bayespig.selection import select_measurements

    if not CORNELL.exists():
        print(f"no Cornell data at {CORNELL}; nothing to measure")
        return 0
    if "--subsets" in (sys.argv[1:] if argv is None else argv):
        subsets()
        return 0
    print(f"bayespig noise floor on Cornell paints; {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}")
    settings = InferenceSettings(n_walkers=16, n_ensembles=4, draws_per_chain=512, target_ess=400)
    for paint, bands in PAINTS.items():
        measurements = read_opaque(CORNELL / f"{paint}.astm")
        near = select_measurements(measurements, exclude_mirror_deg=2.0)
        reflectance = near.films[0].reflectance
        zeros = int((reflectance == 0).sum())
        subset = select_measurements(measurements, **SELECTION)
        print(f"\n{paint}: {len(measurements.films[0].measurements)} geometries; {zeros} exact zeros among "
              f"the {reflectance.size} values (geometry x band) > 2° from the mirror; fitted: "
              f"{len(subset.films[0].measurements)} geometries (>= 30° from the mirror, <= 50°) at "
              f"{bands[0]:g} and {bands[1]:g} nm")
        for floor in ("infer", None):
            started = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                idata = infer(subset, eps="infer", noise_floor=floor, wavelengths=list(bands), seed=1,
                              progress=False, settings=settings, executor=None)
            check = posterior_predictive_check(idata)
            steps = ", ".join(str(int(n)) for n in idata.sample_stats["n_steps"].values)
            print(f"  noise floor {'inferred' if floor else 'none'}: {time.perf_counter() - started:.0f} s, "
                  f"steps {steps}")
            for line in diagnose(idata, warn=False):
                print(f"    not converged: {line}")
            for k, band in enumerate(bands):
                parts = []
                for name in ("a", "eps", "noise_floor"):
                    if name in idata.posterior:
                        q = np.quantile(idata.posterior[name].values[..., k], [0.05, 0.5, 0.95])
                        parts.append(f"{name} {q[1]:.3g} [{q[0]:.3g}, {q[2]:.3g}]")
                print(f"    {band:g} nm: " + ", ".join(parts) + f"; check p = {check['p_value'][k]:.2g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
