"""Benchmark of the report and of ``bayespig demo``: wall time of each step on the demo pigment.

Run from the repository root::

    python benchmarks/report.py            # demo (simulate -> infer -> report), then 3 reports

Prints the wall time of the demo's steps (31 wavelengths, method 4, multi-angle-45, default
inference settings, the machine's 2 cores) and of ``write_report`` on the demo's posterior
(median of 3 runs; the issue's goal: "a spectrum of 31 bands -> report in seconds once the
posterior exists"; with and without writing ``posterior.nc``). The machine is shared: timings
are wall-clock and noisy, so the load average is printed with them, and so is the CPU time
(this process and its worker processes), which does not depend on the load: CPU / 2 is the
wall time of a quiet 2-core machine if both cores are kept busy.
"""

import os
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path


def cpu_seconds():
    """User + system CPU time of this process and its finished children [s]."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def main():
    from bayespig.demo import demo_measurements, run_demo
    from bayespig.report import write_report

    print(f"load average before: {os.getloadavg()[0]:.2f} (cpus: {os.cpu_count()})")
    with tempfile.TemporaryDirectory() as tmp:
        start, cpu = time.perf_counter(), cpu_seconds()
        result = run_demo(Path(tmp) / "demo", seed=0, progress=False)
        total, cpu = time.perf_counter() - start, cpu_seconds() - cpu
        t = result.summary["timings_s"]
        print(f"bayespig demo (31 wavelengths): total {total:.1f} s wall, {cpu:.1f} s CPU; "
              f"simulate {t['simulate']:.1f} s + infer {t['infer']:.1f} s + report "
              f"{t['report']:.1f} s (incl. posterior.nc)")
        stored = Path(tmp) / "demo" / "posterior.nc"
        print(f"posterior.nc (31 wavelengths, 4 x 1024 draws, 12 values): {stored.stat().st_size / 1e6:.1f} MB")
        idata, measurements = result.idata, demo_measurements(seed=0)
        for save in (True, False):
            times, cpus = [], []
            for k in range(3):
                start, cpu = time.perf_counter(), cpu_seconds()
                write_report(idata, Path(tmp) / f"again-{save}-{k}", measurements=measurements,
                             save_posterior=save)
                times.append(time.perf_counter() - start)
                cpus.append(cpu_seconds() - cpu)
            label = "with posterior.nc" if save else "without posterior.nc"
            print(f"write_report, 31 wavelengths, 4 x 1024 draws, {label}: median "
                  f"{statistics.median(times):.1f} s wall (runs: {', '.join(f'{x:.1f}' for x in times)}), "
                  f"{statistics.median(cpus):.1f} s CPU")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
