"""Random validation points over the look-up tables' domain (shared by tests and benchmarks).

The table's accuracy is checked against the direct solver at random points of its whole
domain; uniform draws would rarely land where interpolation is hardest (``a -> 0``,
``a -> 1``, ``tau`` below the first node or large, opaque films, ``r_s`` at 0 and 1), so the
sampler mixes uniform draws with shares near every edge.
"""

from __future__ import annotations

import numpy as np

from .table import TableSettings

__all__ = ["domain_points", "mixture"]

#: The default tables' first finite tau node [-].
DEFAULT_TAU_MIN = TableSettings().tau_nodes[0]


def mixture(rng, size, components):
    """``size`` draws from a mixture of ``(weight, sampler(n))`` components, in random order."""
    weights = np.array([w for w, _ in components], dtype=float)
    choice = rng.choice(len(components), size=size, p=weights / weights.sum())
    out = np.empty(size)
    for k, (_, sampler) in enumerate(components):
        out[choice == k] = sampler(int((choice == k).sum()))
    return out


def domain_points(rng, size, tau_max=100.0):
    """Random (a, tau, r_s) over the issue's domain, with shares near every edge.

    a in [0, 1] (also 1e-7..0.1 and 1 - 1e-6..1 - 0.1); tau in [0, tau_max] (also below
    the first tau node, log-uniform from 1e-5, and large), a quarter opaque; r_s in [0, 1]
    with exact 0 and 1.
    """
    a = mixture(
        rng,
        size,
        [
            (0.4, lambda n: rng.uniform(0.0, 1.0, n)),
            (0.2, lambda n: 10.0 ** rng.uniform(-7.0, -1.0, n)),
            (0.15, lambda n: 1.0 - 10.0 ** rng.uniform(-6.0, -1.0, n)),
            (0.25, lambda n: rng.uniform(0.0, 1.0, n) ** 2),
        ],
    )
    tau = mixture(
        rng,
        size,
        [
            (0.3, lambda n: rng.uniform(0.0, tau_max, n)),
            (0.25, lambda n: np.exp(rng.uniform(np.log(1e-5), np.log(tau_max), n))),
            (0.1, lambda n: rng.uniform(0.0, DEFAULT_TAU_MIN, n)),
            (0.1, lambda n: rng.uniform(0.5 * tau_max, tau_max, n)),
            (0.25, lambda n: np.full(n, np.inf)),
        ],
    )
    r_s = mixture(
        rng,
        size,
        [
            (0.7, lambda n: rng.uniform(0.0, 1.0, n)),
            (0.1, lambda n: np.zeros(n)),
            (0.05, lambda n: np.ones(n)),
            (0.15, lambda n: 1.0 - 10.0 ** rng.uniform(-4.0, -1.0, n)),
        ],
    )
    return a, tau, r_s
