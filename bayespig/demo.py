"""The main job on a bundled example: a SYNTHETIC pigment, simulated, inferred and reported.

The pigment is made up (it is not a measured material): a red-oxide-like colorant whose
relative absorption ``a(λ)`` falls smoothly from about 0.35 in the blue to nearly 0 in the
red (a logistic edge at 575 nm), and whose film has a scattering optical thickness that
decreases with wavelength like ``1/λ`` (fine particles), so that

    a(λ)   = A_RED + (A_BLUE - A_RED) / (1 + exp((λ - EDGE_NM) / EDGE_WIDTH_NM))
    tau(λ) = TAU_SCA_550 (550 / λ) / (1 - a(λ))        (tau = tau_sca + tau_abs)

over 400–700 nm at 10 nm. The film is "measured" the paper's method-4 way (section 3): the
same drawdown on a black (``r_s = 0.01``) and a white (``r_s = 0.95``) substrate, with the
multi-angle instrument (45° illumination, six aspecular angles), with the paper's
multiplicative noise ``eps = 0.05`` (eq. 7); then :func:`bayespig.infer` samples the posterior
and :func:`bayespig.report.write_report` writes the report. Every output says "synthetic".
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

__all__ = ["DEMO_WAVELENGTHS_NM", "QUICK_SETTINGS", "SYNTHETIC_PIGMENT", "demo_measurements", "run_demo",
           "synthetic_pigment"]

#: Wavelengths of the demo [nm].
DEMO_WAVELENGTHS_NM = np.arange(400.0, 701.0, 10.0)
#: Parameters of the synthetic pigment (see the module docstring).
SYNTHETIC_PIGMENT = {
    "name": "synthetic red-oxide-like pigment (SYNTHETIC - not a real material)",
    "A_BLUE": 0.35, "A_RED": 0.004, "EDGE_NM": 575.0, "EDGE_WIDTH_NM": 18.0,
    "TAU_SCA_550": 0.8, "SCATTERING_EXPONENT": 1.0,
}
#: Inference settings of ``run_demo(quick=True)`` (tests only): runs of 20 instead of 50
#: autocorrelation times, ESS target 200 instead of 1000, 256 stored draws per chain.
QUICK_SETTINGS = {"target_ess": 200.0, "draws_per_chain": 256, "min_steps": 100,
                  "min_autocorr_multiple": 20.0}
#: Output directory of ``bayespig demo`` (relative to the working directory).
DEFAULT_OUT_DIR = Path("reports") / "demo"


def synthetic_pigment(wavelength_nm=DEMO_WAVELENGTHS_NM):
    """``a(λ)`` and ``tau(λ)`` of the synthetic demo pigment.

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelengths [nm].

    Returns
    -------
    a : numpy.ndarray
        Relative absorption ``1 - albedo`` [-].
    tau : numpy.ndarray
        Optical thickness of the demo film [-].
    """
    p = SYNTHETIC_PIGMENT
    wl = np.asarray(wavelength_nm, dtype=float)
    a = p["A_RED"] + (p["A_BLUE"] - p["A_RED"]) / (1.0 + np.exp((wl - p["EDGE_NM"]) / p["EDGE_WIDTH_NM"]))
    tau = p["TAU_SCA_550"] * (550.0 / wl) ** p["SCATTERING_EXPONENT"] / (1.0 - a)
    return a, tau


def demo_measurements(*, seed=0, wavelength_nm=DEMO_WAVELENGTHS_NM, instrument="multi-angle-45",
                      eps=0.05):
    """The demo's simulated method-4 measurement set (labelled synthetic in its metadata).

    Parameters
    ----------
    seed : int
        Seed of the simulated noise.
    wavelength_nm : array_like
        Wavelengths [nm].
    instrument : str
        Built-in instrument name.
    eps : float
        Relative measurement error of eq. (7) [-].

    Returns
    -------
    MeasurementSet
    """
    from .data import MeasurementSet, simulate

    a, tau = synthetic_pigment(wavelength_nm)
    measured = simulate(a=a, tau=tau, design="method4", instrument=instrument,
                        wavelengths=wavelength_nm, eps=eps, seed=seed)
    metadata = dict(measured.metadata)
    metadata["synthetic"] = SYNTHETIC_PIGMENT["name"]
    metadata["pigment"] = {k: v for k, v in SYNTHETIC_PIGMENT.items() if k != "name"}
    return MeasurementSet(measured.wavelength_nm, measured.samples, n=measured.n, metadata=metadata,
                          source="bayespig demo (synthetic)")


def run_demo(out_dir=DEFAULT_OUT_DIR, *, seed=0, progress=True, quick=False, executor=None,
             overwrite=False):
    """Simulate the synthetic pigment, infer its posterior and write the report.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Report directory (default ``reports/demo``).
    seed : int
        Seeds the simulated noise and the sampler.
    progress : bool
        Print the steps and show the inference progress bar.
    quick : bool
        Shorter runs (:data:`QUICK_SETTINGS`) at every third wavelength (11 instead of 31), for
        tests; the title says so, and the diagnostics flag the low effective sample sizes.
    executor : concurrent.futures.Executor, optional
        Passed to :func:`bayespig.infer`.
    overwrite : bool
        Replace ``out_dir`` even when it is not an earlier report (as
        :func:`bayespig.report.write_report`; checked before any work).

    Returns
    -------
    ReportResult
        With ``summary["timings_s"]`` (simulation, inference, report).
    """
    from .inference import InferenceSettings, infer
    from .report import write_report
    from .report.quantities import record_eps_source
    from .report.write import check_report_folder

    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    out_dir = Path(out_dir)
    check_report_folder(out_dir, overwrite=overwrite)
    say = print if progress else (lambda *a, **k: None)
    wavelength_nm = DEMO_WAVELENGTHS_NM[::3] if quick else DEMO_WAVELENGTHS_NM
    settings = QUICK_SETTINGS if quick else None
    timings = {}
    start = time.perf_counter()
    say(f"bayespig demo: {SYNTHETIC_PIGMENT['name']}")
    say(f"  simulating method-4 films (black and white substrates), multi-angle-45, eps 0.05, seed {seed}")
    measurements = demo_measurements(seed=seed, wavelength_nm=wavelength_nm)
    timings["simulate"] = time.perf_counter() - start
    say(f"  inferring the posterior at {wavelength_nm.size} wavelengths"
        + (" (quick settings)" if quick else ""))
    start = time.perf_counter()
    settings = InferenceSettings(**settings) if settings else None
    idata = infer(measurements, method="method4", seed=seed, progress=progress, settings=settings,
                  executor=executor)
    timings["infer"] = time.perf_counter() - start
    record_eps_source(idata, None, measurements, given_as="eps=")
    say(f"  writing the report into {out_dir}")
    start = time.perf_counter()
    result = write_report(idata, out_dir, measurements=measurements, progress=progress, overwrite=overwrite,
                          extra_files={"measurements.csv": measurements.to_csv},
                          title="bayespig demo: " + SYNTHETIC_PIGMENT["name"] + (" [quick]" if quick else ""))
    timings["report"] = time.perf_counter() - start
    result.summary["timings_s"] = timings
    say(f"  done: {result.files['html']} (inference {timings['infer']:.1f} s, report "
        f"{timings['report']:.1f} s)")
    return result
