"""Benchmark: how the Cornell readings' noise depends on the angle of incidence (issue 16; data only).

Run from the repository root (prints only, seconds)::

    python benchmarks/cornell_noise_by_incidence.py

A question for the noise model: the additive floor ``sigma0`` of ``infer(..., noise_floor=)`` is one
number per band for every geometry, while a background error that is constant in *radiance* becomes
``sigma0 / cos(theta_i)`` in BRDF units (the BRDF divides by the irradiance ``E cos theta_i``, the
reasoning behind the incidence offset ``b / cos theta_i``). Which do the data say, with no model?
The noise of one reading is estimated from second differences over wavelength,
``sd ~ 1.4826 MAD(x[k-1] - 2 x[k] + x[k+1]) / sqrt(6)`` (robust; the 10 nm spectra are smooth, so
the curvature of the signal is small against the noise at dark readings). Printed per incidence group:
the absolute noise of the dark readings (0 < x < 0.02 1/sr, where the floor dominates: a relative
noise of ~0.5 % is 1e-4 1/sr there at most), that noise times cos(theta_i) at the group's middle
(constant if the floor scales as 1 / cos theta_i), and the relative noise of the bright readings
(x > 0.1 1/sr, eq. 7's eps). Last, the ratio of the 71-80 deg group's dark noise to the 0-30 deg
group's, against the ratios a constant floor (1), ``cos^-1/2`` and ``1 / cos`` would give.
"""
import sys

import numpy as np

from bayespig.data import read_measurements
from bayespig.studies.cornell import default_cornell_path

sys.path.insert(0, "benchmarks")
from _common import machine_line

#: Incidence groups [deg] (the files' theta_i are 0-80 deg in steps of 10, plus off-grid values).
GROUPS = ((0, 31), (31, 51), (51, 61), (61, 71), (71, 81))
DARK_MAX = 0.02  # 1/sr
BRIGHT_MIN = 0.1  # 1/sr


def robust_sd(values):
    """1.4826 x the median absolute value (the values have median ~0)."""
    return 1.4826 * float(np.median(np.abs(values)))


print(machine_line())
for paint in ("krylon_blue", "garnet_red"):
    rows = read_measurements(default_cornell_path() / f"{paint}.astm", opaque=True).films[0].measurements
    theta_i = np.array([m.theta_i for m in rows])
    x = np.array([m.values for m in rows])  # (n_geometries, n_bands)
    middle = x[:, 1:-1]
    second = (x[:, :-2] - 2.0 * middle + x[:, 2:]) / np.sqrt(6.0)
    positive = (x[:, :-2] > 0) & (middle > 0) & (x[:, 2:] > 0)  # exact zeros are clipped, not noise
    print(f"{paint}: {len(rows)} geometries")
    dark_sd = {}
    for low, high in GROUPS:
        group = ((theta_i >= low) & (theta_i < high))[:, None]
        dark = group & positive & (middle < DARK_MAX)
        bright = group & (middle > BRIGHT_MIN)
        dark_sd[low] = robust_sd(second[dark])
        cos = np.cos(np.radians(0.5 * (low + high - 1)))
        print(f"  theta_i {low:2d}-{high - 1:2d} deg: dark readings {int(dark.sum()):5d}, noise {dark_sd[low]:.2e} 1/sr, "
              f"x cos theta_i {dark_sd[low] * cos:.2e}; bright readings {int(bright.sum()):4d}, relative noise "
              f"{robust_sd(second[bright] / middle[bright]):.4f}")
    c_low, c_high = np.cos(np.radians(15.0)), np.cos(np.radians(75.5))
    print(f"  dark noise 71-80 / 0-30 deg: {dark_sd[71] / dark_sd[0]:.2f} (constant floor 1, cos^-1/2 "
          f"{np.sqrt(c_low / c_high):.2f}, 1 / cos {c_low / c_high:.2f})")
