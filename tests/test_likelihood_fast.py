"""The fast likelihood path (``WavelengthModel``) against ``ForwardModel.predict`` for tables
with a ``g`` axis (issue 3: the fast path must follow the table's transformed g axis).

Reference: ``ForwardModel.predict``, which evaluates every film through the look-up
table's own ``__call__`` (tested against the direct solver in ``tests/test_table.py``).
The fast path gathers the same stencils in another order, so the two agree to rounding.
Tables are coarse (the same code path as the default g table, built in seconds).
"""

import numpy as np
import pytest

from bayespig.data import simulate
from bayespig.likelihood import ForwardModel, Problem
from bayespig.table import TableSettings, load_table

#: Two evaluations of the same interpolant summed in different orders: rounding only (measured
#: 0 under OpenBLAS Haswell and SkylakeX).
SAME_INTERPOLANT_REL_TOL = 1e-12
#: The stencil's quintic and numpy's fit through the same six values: rounding only (measured
#: 2.7e-14).
LOG_IDENTITY_ABS_TOL = 1e-9
#: A coarse g axis (atanh-uniform, quintic stencil: the defaults) over the default prior range.
COARSE_G_SETTINGS = TableSettings(
    g_range=(-0.5, 0.8), n_g=7, n_a=12, log2_tau_min=-4, log2_tau_max=7, per_octave=1
)
INSTRUMENT = ["45as15", "45as110"]
N_WALKERS = 64


@pytest.fixture(scope="module")
def free_g_model(tmp_path_factory):
    """An opaque film, a thin film on a grey and on a white substrate and on glass: one
    table, opaque and finite films, two substrates sharing one film group, a transmittance."""
    cache = tmp_path_factory.mktemp("fast-cache")
    design = [
        {"name": "opaque", "opaque": True},
        {"name": "on_grey", "substrate": 0.4, "film_group": "thin"},
        {"name": "on_white", "substrate": "white", "film_group": "thin"},
        {"name": "on_glass", "on_glass": True, "film_group": "thin"},
    ]
    measurements = simulate(
        a=0.1, tau=2.0, g=0.3, design=design, instrument=INSTRUMENT,
        wavelengths=[450.0, 550.0], eps=0.0, seed=1,
    )
    problem = Problem.from_measurements(measurements, method="general")
    tables = {}
    for film in problem.films:
        if film.instrument is not None and film.instrument not in tables:
            tables[film.instrument] = load_table(
                film.instrument, g="free", settings=COARSE_G_SETTINGS, cache_dir=cache,
                progress=False,
            )
    return ForwardModel(problem, g="free", tables=tables)


def walkers(rng, size, tau_low):
    a = np.concatenate([[0.0, 1.0], rng.uniform(0.0, 1.0, size - 2)])
    tau = np.exp(rng.uniform(np.log(tau_low), np.log(100.0), (size, 1)))
    g = np.concatenate([[-0.5, 0.8], rng.uniform(-0.5, 0.8, size - 2)])  # the axis ends too
    return a, tau, g


@pytest.mark.parametrize("tau_low", [0.1, 1e-3])  # 1e-3: below the first tau node (2^-4)
def test_fast_path_equals_predict_for_free_g_tables(free_g_model, tau_low):
    rng = np.random.default_rng(3)
    a, tau, g = walkers(rng, N_WALKERS, tau_low)
    assert len({f.r_s[1] for f in free_g_model.problem.films}) >= 2
    fast = free_g_model.at_wavelength(1)(a, tau, g)
    reference = free_g_model.predict(1, a, tau, g)
    assert fast.shape == reference.shape == (N_WALKERS, free_g_model.problem.n_values)
    np.testing.assert_allclose(fast, reference, rtol=SAME_INTERPOLANT_REL_TOL, atol=0)


def test_fast_path_follows_the_atanh_g_axis(free_g_model):
    """Between g nodes the opaque film's log values are the quintic in atanh(g) through the
    six nearest g nodes (where the table is exact): a stencil placed on a uniform g axis, or
    of another width, would miss by far more than rounding."""
    problem = free_g_model.problem
    opaque = next(i for i, f in enumerate(problem.films) if f.opaque)
    columns = slice(0, problem.films[opaque].observed.shape[1])
    assert opaque == 0  # its values come first
    table = free_g_model.film_tables[opaque]
    settings = table.settings
    g_nodes = settings.g_nodes
    assert settings.g_axis == "atanh" and settings.g_stencil == 6
    assert not np.allclose(np.diff(g_nodes), np.diff(g_nodes)[0])  # really non-uniform in g
    g = np.linspace(g_nodes[1], g_nodes[2], 9)[1:-1]  # the stencil of this interval: nodes 0..5
    a = np.full(g.size, 0.2)
    tau = np.full((g.size, 1), 3.0)
    at_nodes = np.log(free_g_model.predict(0, np.full(6, 0.2), np.full((6, 1), 3.0), g_nodes[:6]))
    fast = np.log(free_g_model.at_wavelength(0)(a, tau, g))
    for k in range(columns.stop):
        quintic = np.polynomial.Polynomial.fit(np.arctanh(g_nodes[:6]), at_nodes[:, k], 5)
        np.testing.assert_allclose(fast[:, k], quintic(np.arctanh(g)), rtol=0, atol=LOG_IDENTITY_ABS_TOL)
