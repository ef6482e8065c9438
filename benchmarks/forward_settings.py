"""Benchmark: what each of the forward model's performance settings is worth.

Run from the repository root::

    python benchmarks/forward_settings.py              # ~1 minute; rewrites its section of reports/benchmarks.md
    python benchmarks/forward_settings.py --no-write   # print only

Times ``bayespig.brdf`` on the forward benchmark's task (six multi-angle geometries, the 64 x 64
(a, tau) grid in one call; ``benchmarks/forward.py``) with the defaults and with one setting
undone at a time: the BLAS left multi-threaded, one worker thread, chunks of 1024 sets instead of 256,
and (g = 0.5) every azimuthal mode on the full quadrature.
The variants take turns over several rounds and each keeps its median: the machine is shared.
"""

import argparse
import contextlib
import sys

import numpy as np
from _common import Transcript, load_average, machine_line, write_run_section
from forward import A_GRID, TAU_GRID, bayespig_time

from bayespig.physics import forward

SECTION = "## Forward model settings"
ROUNDS = 5


class _UnlimitedBlas:
    """Stands in for the threadpoolctl controller: leaves the BLAS threads as loaded."""

    @staticmethod
    def limit(**_):
        return contextlib.nullcontext()


#: (label, module, attribute, value, only for anisotropic scattering)
VARIANTS = [
    ("defaults", None, None, None, False),
    ("BLAS threads not limited", forward, "_blas_controller", lambda: _UnlimitedBlas(), False),
    ("one worker thread", forward, "THREADS", 1, False),
    ("chunks of 1024 sets", forward, "CHUNK", 1024, False),
    ("every mode on the full quadrature", forward, "COARSE_AFTER", 0.0, True),
]


def time_call(g):
    """Wall time per (a, tau) point of forward.py's batched brdf call, default quadrature [ms]."""
    return bayespig_time(g, None) / (A_GRID.size * TAU_GRID.size) * 1e3


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-write", action="store_true", help="print only; leave reports/benchmarks.md")
    args = parser.parse_args(argv)
    say = Transcript(machine_line())
    say(f"task: brdf at 6 multi-angle geometries over a 64 x 64 (a, tau) grid in one call; median of {ROUNDS} rounds")
    for g in (0.0, 0.5):
        variants = [v for v in VARIANTS if g != 0.0 or not v[4]]
        times = {label: [] for label, *_ in variants}
        for _ in range(ROUNDS):
            for label, module, name, value, _ in variants:
                saved = None if module is None else getattr(module, name)
                if module is not None:
                    setattr(module, name, value)
                try:
                    times[label].append(time_call(g))
                finally:
                    if module is not None:
                        setattr(module, name, saved)
        default = float(np.median(times["defaults"]))
        say()
        say(f"g = {g}")
        for label, values in times.items():
            median = float(np.median(values))
            say(f"  {label:<36} {median:6.3f} ms/point   x{median / default:4.2f} of the defaults")
    say()
    say(f"load average at the end {load_average()}")
    if args.no_write:
        return 0
    write_run_section(SECTION, "python benchmarks/forward_settings.py", [
        "The forward benchmark's task with the defaults and with one performance setting undone at a",
        "time (a factor above 1: the setting saves that much). The variants take turns; medians.",
    ], say.lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
