"""Benchmark of sample design (issue 8): ranking 100 candidate sample sets over a 31-band prior.

Run from the repository root::

    python benchmarks/design.py            # prints; updates reports/benchmarks.md
    python benchmarks/design.py --no-write # prints only

Ranks the first 100 candidates of ``candidate_designs([5, 10, 20, 40] um, black/white/grey 0.3,
multi-angle-45 and 8d-sci)`` by the Fisher information of eq. (7) at 32 prior draws x 31 bands
(400–700 nm) of ``a`` in [0.01, 0.3] and ``tau`` per um in [0.02, 0.2] (goal <= 10 s on 2 cores;
the computation is one process). The look-up tables are loaded before the clock starts; 3 runs,
best and median wall time, and the CPU time. The machine may be shared: the load average is
printed. The section "## Sample design" of reports/benchmarks.md is replaced (others kept), atomically.
"""

import argparse
import os
import platform
import time

import numpy as np
from _common import REPORT, replace_section

import bayespig
from bayespig.studies.design import DesignPrior, candidate_designs, rank_designs
from bayespig.table import load_table

INSTRUMENTS = ("multi-angle-45", "8d-sci")
N_CANDIDATES = 100
N_DRAWS = 32
N_TIMINGS = 3
GOAL_SECONDS = 10.0
SECTION = "## Sample design"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-write", action="store_true", help="print only")
    args = parser.parse_args(argv)
    tables = {name: load_table(name, progress=False) for name in INSTRUMENTS}
    candidates = candidate_designs([5.0, 10.0, 20.0, 40.0], ["black", "white", "grey:0.3"], INSTRUMENTS)
    candidates = candidates[:N_CANDIDATES]
    prior = DesignPrior(a=(0.01, 0.3), tau_per_um=(0.02, 0.2))
    walls, cpus = [], []
    for _ in range(N_TIMINGS):
        start, cpu = time.perf_counter(), time.process_time()
        result = rank_designs(candidates, prior, n_draws=N_DRAWS, seed=0, tables=dict(tables))
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu)
    load = os.getloadavg()
    best = result.summary()[0]
    lines = [
        (f"{len(candidates)} candidates x {N_DRAWS} draws x {prior.n_bands} bands "
         f"({len(candidates) * N_DRAWS * prior.n_bands} Fisher matrices): "
         f"best {min(walls):.2f} s, median {np.median(walls):.2f} s wall, CPU {np.median(cpus):.2f} s "
         f"(goal <= {GOAL_SECONDS:g} s) -- {'PASS' if min(walls) <= GOAL_SECONDS else 'FAIL'}"),
        (f"best candidate: {best['description']} (mean sd(a)/a {best['mean_rel_sd_a']:.3g}, "
         f"sd(tau)/tau {best['mean_rel_sd_tau']:.3g})"),
        f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores",
    ]
    for line in lines:
        print(line)
    if not args.no_write:
        body = "\n".join([
            SECTION, "",
            ("Regenerate: `python benchmarks/design.py` "
             f"(bayespig {bayespig.__version__}, numpy {np.__version__}, "
             f"Python {platform.python_version()})."),
            "",
            ("Ranking candidate sample sets (`bayespig.studies.design.rank_designs`, Fisher information "
             "of eq. 7 from the look-up tables' derivatives; tables loaded before the clock; one process). "
             "Measured on a shared machine (see the load average)."),
            "", *(f"- {line}" for line in lines), "",
        ])
        replace_section(REPORT, SECTION, body)
        print(f"updated {REPORT}")


if __name__ == "__main__":
    main()
