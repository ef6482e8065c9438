"""Benchmark: cost and precision of the independent rough-surface Monte Carlo (issue 16).

Run from the repository root (prints only, writes nothing)::

    python benchmarks/monte_carlo.py [n_photons]     # default 100000

For each case of ``tests/physics/rough_monte_carlo.SOLVER_CASES`` (alpha 0.05–0.5, g 0 and
0.6, a 0.01 and 0.3, tau 1 and inf, r_s 0 and 0.8; 8 views in and out of the plane of
incidence), the wall time, the events traced per photon, the time per event and view, and
the body BRDF's relative standard errors over the views (median and largest).  When
``bayespig.brdf`` takes ``roughness``, also the solver's relative difference from the Monte
Carlo per view and its size in standard errors (``compare_with_solver``), parts "body",
"total" and "surface" (Walter's formula, analytic in both).
"""

import inspect
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.physics import rough_monte_carlo as rmc


def main(n_photons):
    print(f"{os.cpu_count()} cores, load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}; "
          f"{n_photons} photons per case", flush=True)
    for number, case in enumerate(rmc.SOLVER_CASES):
        start = time.perf_counter()
        mc = rmc.monte_carlo_brdf(case["theta_i"], case["views"], a=case["a"], tau=case["tau"], g=case["g"],
                                  r_s=case["r_s"], n=case["n"], alpha=case["alpha"], n_photons=n_photons,
                                  seed=(0, number), part="body")
        seconds = time.perf_counter() - start
        relative = mc.standard_error / mc.body
        print(f"case {number}: theta_i {case['theta_i']:g}, alpha {case['alpha']:g}, g {case['g']:g}, "
              f"a {case['a']:g}, tau {case['tau']:g}, r_s {case['r_s']:g}: {seconds:.1f} s, "
              f"{mc.n_events / n_photons:.1f} events/photon, "
              f"{1e6 * seconds / (mc.n_events * len(case['views'])):.2f} us per event and view; "
              f"relative standard error median {100 * np.median(relative):.2f} %, "
              f"max {100 * relative.max():.2f} %", flush=True)
    import bayespig

    if "roughness" not in inspect.signature(bayespig.brdf).parameters:
        print("bayespig.brdf has no roughness keyword: no solver comparison")
        return
    all_rows = rmc.compare_with_solver(bayespig.brdf, rmc.SOLVER_CASES, parts=("body", "total", "surface"),
                                       n_photons=n_photons)
    for part in ("body", "total", "surface"):
        rows = [row for row in all_rows if row["part"] == part]
        worst = max(rows, key=lambda row: abs(row["relative_difference"]))
        print(f"solver vs Monte Carlo, part {part!r}: largest |relative difference| "
              f"{100 * abs(worst['relative_difference']):.3f} % ({worst['sigmas']:+.1f} standard errors) at "
              f"theta_i {worst['theta_i']:g}, view ({worst['theta_o']:g}, {worst['delta_phi']:g}), "
              f"alpha {worst['alpha']:g}", flush=True)
        for row in rows:
            print(f"  theta_i {row['theta_i']:4g} alpha {row['alpha']:4g} g {row['g']:3g} a {row['a']:4g} "
                  f"tau {row['tau']:3g} r_s {row['r_s']:3g} view ({row['theta_o']:2g}, {row['delta_phi']:3g}): "
                  f"solver {row['solver']:.5g}, MC {row['monte_carlo']:.5g} +- {row['standard_error']:.2g}, "
                  f"{100 * row['relative_difference']:+.2f} % ({row['sigmas']:+.1f} sigma)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100_000)
