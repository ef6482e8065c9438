"""Benchmark: layer kernels by doubling vs the discrete-ordinate eigen solution.

Run from the repository root::

    python benchmarks/layer_solvers.py

Times :func:`bayespig.physics.adding_doubling.layer_mode` (the table builder's solver) and
:func:`bayespig.physics.discrete_ordinates.layer_mode_eigen` (one eigen decomposition per
``a``, closed form per ``tau``; the forward model solves the same equations without forming
kernels, see ``benchmarks/forward.py``) on
the default binder quadrature (no measurement nodes) over the forward benchmark's 64 x 64
(a, tau) grid (``benchmarks/forward.py``), for the isotropic mode and for the modes of
Henyey-Greenstein g = 0.5, and prints the largest difference of the reflection and
transmission kernels relative to the largest mode-0 reflection kernel entry (the scale of the
BRDF; high modes are small, and their smallest entries are round-off in both solvers). The
section "## Layer solvers" of reports/benchmarks.md is replaced (``--no-write``: print only).
"""

import argparse
import os
import platform
import sys
import time

import numpy as np
from _common import Transcript, load_average, write_run_section

from bayespig.physics.adding_doubling import (
    START_THICKNESS,
    START_THICKNESS_HIGHER_MODES,
    layer_mode,
)
from bayespig.physics.discrete_ordinates import layer_mode_eigen
from bayespig.physics.phase import n_fourier_modes, normalise_on_quadrature, phase_fourier_modes
from bayespig.physics.quadrature import DEFAULT_QUADRATURE_POINTS, binder_quadrature

GRID_SIZE = 64
A_GRID = np.linspace(0.001, 0.999, GRID_SIZE)
TAU_GRID = np.logspace(-2, 2, GRID_SIZE)
N_BINDER = 1.45
SECTION = "## Layer solvers"


def scaled_difference(x, reference, scale):
    """Largest ``|x - reference|`` over ``scale``."""
    return float(np.abs(x - reference).max() / scale)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--no-write", action="store_true", help="print only")
    args = parser.parse_args(argv)
    say = Transcript()
    say(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, python "
        f"{platform.python_version()}, load average {load_average()}")
    mu, weight = binder_quadrature(DEFAULT_QUADRATURE_POINTS, N_BINDER)
    a, tau = (x.ravel() for x in np.meshgrid(A_GRID, TAU_GRID, indexing="ij"))
    say(f"{mu.size} binder nodes ({DEFAULT_QUADRATURE_POINTS} per interval), {a.size} (a, tau) points")
    for g in (0.0, 0.5):
        n_modes = n_fourier_modes(g)
        p_r = phase_fourier_modes(mu, mu, g, n_modes, reflection=True)
        p_t = phase_fourier_modes(mu, mu, g, n_modes, reflection=False)
        p_r, p_t = normalise_on_quadrature(p_r, p_t, weight)
        times = {"doubling": 0.0, "eigen": 0.0}
        worst, scale = 0.0, None
        for m in range(n_modes):
            start = START_THICKNESS if m == 0 else START_THICKNESS_HIGHER_MODES  # as the forward model
            t0 = time.perf_counter()
            R_d, T_d, _ = layer_mode(mu, weight, a, tau, p_r[m], p_t[m], start)
            t1 = time.perf_counter()
            R_e, T_e, _ = layer_mode_eigen(mu, weight, a, tau, p_r[m], p_t[m], start)
            t2 = time.perf_counter()
            times["doubling"] += t1 - t0
            times["eigen"] += t2 - t1
            scale = np.abs(R_d).max() if scale is None else scale  # mode 0
            worst = max(worst, scaled_difference(R_e, R_d, scale), scaled_difference(T_e, T_d, scale))
        per_d, per_e = (times[k] / a.size * 1e3 for k in ("doubling", "eigen"))
        say(f"g = {g:g}: {n_modes} mode(s); doubling {per_d:.3f} ms/point, eigen {per_e:.3f} ms/point "
            f"(x{per_d / per_e:.1f}); largest difference of R, T / largest mode-0 R {worst:.1e}")
    say(f"load average at end {load_average()}")
    if args.no_write:
        return 0
    write_run_section(SECTION, "python benchmarks/layer_solvers.py", [
        "Layer kernels (no surface, no measurement nodes) on the default binder quadrature over the",
        "forward benchmark's 64 x 64 (a, tau) grid: adding-doubling (`layer_mode`, the table",
        "builder's solver) against the discrete-ordinate eigen solution (`layer_mode_eigen`). The",
        "forward model solves the same equations as a boundary-value problem under the surface",
        "(`radiances_under_surface`), timed in the section \"Forward model\".",
    ], say.lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
