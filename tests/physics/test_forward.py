"""The forward model's quadrature for small azimuthal modes (bayespig.physics.forward).

Reference: the same forward model with every mode on the full quadrature (``COARSE_AFTER = 0``),
itself checked against exact solutions, published tables and iadpython in
``test_reference_values.py``.
"""

import numpy as np
import pytest

import bayespig
from bayespig.physics import forward

#: The coarse quadrature's relative error (~1e-3) on modes below COARSE_AFTER of mode 0, which
#: keep decaying: measured <= 3e-6 of the BRDF for |g| <= 0.8 (reports/validation.md); the
#: issue's budget is 1e-4.
COARSE_MODES_REL_TOL = 1e-5
ASPECULAR = np.array([-15.0, 15.0, 25.0, 45.0, 75.0, 110.0])
THETA_O = np.abs(45.0 - ASPECULAR)
DELTA_PHI = np.where(45.0 - ASPECULAR >= 0, 180.0, 0.0)


@pytest.mark.parametrize("g", [0.3, 0.5, 0.8, -0.3, 2.0])
def test_small_modes_on_the_coarse_quadrature(g, monkeypatch):
    rng = np.random.default_rng(8)
    a = np.concatenate([rng.uniform(0.0, 1.0, 30), [2e-4, 0.999]])
    tau = np.concatenate([np.exp(rng.uniform(np.log(1e-2), np.log(100.0), 30)), [np.inf, 0.5]])
    geometry = (45.0, THETA_O[:, None], DELTA_PHI[:, None])
    coarse = bayespig.brdf(*geometry, a=a, tau=tau, g=g)
    monkeypatch.setattr(forward, "COARSE_AFTER", 0.0)
    full = bayespig.brdf(*geometry, a=a, tau=tau, g=g)
    assert np.abs(coarse / full - 1.0).max() < COARSE_MODES_REL_TOL


def test_coarse_quadrature_points():
    assert forward.coarse_quadrature_points(16) == 8
    assert forward.coarse_quadrature_points(5) == forward.COARSE_MIN_POINTS
