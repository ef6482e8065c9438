"""The simulator: the paper's designs, eq. (7) noise, seeds, truth in metadata, pluggable model."""

import numpy as np
import pytest

import bayespig
from bayespig.data import DESIGNS, FilmSpec, MeasurementSet, read_csv, simulate, simulate_to_csv
from bayespig.instruments import get_instrument

WAVELENGTHS = np.array([450.0, 550.0, 650.0])
N_BINDER = 1.45
#: The same solver reached through two code paths (instrument channels vs the brdf function).
SOLVER_PATHS_REL_TOL = 1e-9
#: Closed forms evaluated in the test and in the library.
CLOSED_FORM_REL_TOL = 1e-12
#: Sample mean and sd of n standard normal deviates: 5 standard errors.
N_NOISE = 60_000
NOISE_SIGMAS = 5.0


def test_noise_free_values_are_the_forward_model():
    a, tau = np.array([0.02, 0.1, 0.3]), np.array([0.5, 1.0, 2.0])
    ms = simulate(a=a, tau=tau, design="method4", wavelengths=WAVELENGTHS, eps=0.0)
    instrument = get_instrument("multi-angle-45")
    for name, r_s in (("on_black", 0.01), ("on_white", 0.95)):
        sample = ms.sample(name)
        assert sample.film_group == "film" and sample.substrate in ("black", "white")
        for m, channel in zip(sample.measurements, instrument.channels):
            assert m.label == channel.label
            expected = bayespig.brdf(
                channel.theta_i, channel.theta_o, channel.delta_phi, a=a, tau=tau, r_s=r_s
            )
            np.testing.assert_allclose(m.values, expected, rtol=SOLVER_PATHS_REL_TOL)


def test_method1_film_on_glass_is_eq5():
    tau = np.array([0.1, 1.0, 3.0])
    ms = simulate(a=0.05, tau=tau, design="method1", wavelengths=WAVELENGTHS, eps=0.0)
    t_f = 1 - ((N_BINDER - 1) / (N_BINDER + 1)) ** 2
    glass = ms.sample("on_glass")
    assert glass.role == "film_on_glass" and glass.transmittance.label == "normal"
    np.testing.assert_allclose(
        glass.transmittance.values, t_f**2 * np.exp(-tau), rtol=CLOSED_FORM_REL_TOL
    )
    assert ms.sample("opaque").opaque
    assert ms.supported_methods()["method1"].samples == ("opaque", "on_glass")


@pytest.mark.parametrize(
    "design, methods",
    [
        ("method1", {"method1"}),
        ("method2", {"method2", "method3"}),
        ("method3", {"method3"}),
        ("method4", {"method3", "method4"}),
    ],
)
def test_designs_serve_their_method(design, methods):
    ms = simulate(a=0.1, tau=1.0, design=design, wavelengths=WAVELENGTHS, instrument="8d-sce")
    assert {m for m, s in ms.supported_methods().items() if s} == methods
    assert ms.sample_names == tuple(spec.name for spec in DESIGNS[design])


def test_noise_is_eq7_and_seeded():
    """x_obs / x_true - 1 = eps * xi with xi standard normal (paper eq. 7)."""
    wavelengths = 200.0 + np.arange(N_NOISE // 6) * (3000.0 / (N_NOISE // 6))
    kwargs = dict(a=0.2, tau=1.0, design="method3", wavelengths=wavelengths, model=_fake_model)
    truth = simulate(eps=0.0, **kwargs).sample("on_black").reflectance
    eps = 0.05
    noisy = simulate(eps=eps, seed=11, **kwargs).sample("on_black").reflectance
    xi = (noisy / truth - 1.0) / eps
    assert abs(xi.mean()) < NOISE_SIGMAS / np.sqrt(xi.size)
    assert abs(xi.std() - 1.0) < NOISE_SIGMAS / np.sqrt(2 * xi.size)
    assert np.array_equal(
        simulate(eps=eps, seed=11, **kwargs).sample("on_black").reflectance, noisy
    )
    assert not np.array_equal(
        simulate(eps=eps, seed=12, **kwargs).sample("on_black").reflectance, noisy
    )


def _fake_model(*, a, tau, g, r_s):
    """A cheap stand-in for the forward model: 6 channels, values depending on a, tau, r_s."""
    base = (1 - np.asarray(a)) * (1 - np.exp(-np.asarray(tau))) + np.asarray(r_s) * np.exp(
        -np.asarray(tau)
    )
    return np.stack([base * (k + 1) / 10 for k in range(6)], axis=-1)


def test_model_argument_is_used_and_checked():
    ms = simulate(
        a=0.2, tau=1.0, design="method3", wavelengths=WAVELENGTHS, eps=0.0, model=_fake_model
    )
    expected = (0.8 * (1 - np.exp(-1.0)) + 0.01 * np.exp(-1.0)) * 0.1
    np.testing.assert_allclose(
        ms.sample("on_black").measurements[0].values, expected, rtol=CLOSED_FORM_REL_TOL
    )

    class WrongTable:
        instrument = get_instrument("8d-sci")

        def __call__(self, **kwargs):
            raise AssertionError("must not be called")

    with pytest.raises(ValueError, match="model is for channels"):
        simulate(a=0.2, tau=1.0, design="method3", wavelengths=WAVELENGTHS, model=WrongTable())


def test_truth_and_settings_in_metadata():
    a = np.array([0.01, 0.02, 0.03])
    ms = simulate(
        a=a,
        tau=2.0,
        design="method2",
        wavelengths=WAVELENGTHS,
        seed=5,
        eps=0.03,
        g=0.2,
        instrument=["45as15", "45as-15"],
        model=_fake_model_2,
    )
    truth = ms.metadata["truth"]
    assert (
        truth["a"] == list(a)
        and truth["tau"] == {"on_black": [2.0, 2.0, 2.0]}
        and truth["g"] == 0.2
    )
    assert (ms.metadata["seed"], ms.metadata["eps"], ms.metadata["design"]) == (5, 0.03, "method2")
    assert ms.metadata["instrument"] == ["45as15", "45as-15"]


def _fake_model_2(*, a, tau, g, r_s):
    return _fake_model(a=a, tau=tau, g=g, r_s=r_s)[..., :2]


def test_custom_design_with_measured_substrate():
    design = [
        FilmSpec("thin", substrate=0.5, tau_scale=0.5, film_group="G", measure_substrate=True),
        {"name": "thin_white", "substrate": "white", "tau_scale": 0.5, "film_group": "G"},
        {"name": "thick", "tau_scale": 3.0},
    ]
    ms = simulate(
        a=0.1, tau=1.0, design=design, wavelengths=WAVELENGTHS, eps=0.0, instrument="8d-sce"
    )
    assert ms.sample_names == ("thin_substrate", "thin", "thin_white", "thick")
    assert ms.sample("thin").substrate == "thin_substrate"
    np.testing.assert_allclose(ms.substrate_albedo("thin"), 0.5, rtol=SOLVER_PATHS_REL_TOL)
    assert ms.metadata["truth"]["tau"] == {"G": [0.5] * 3, "thick": [3.0] * 3}
    assert ms.supported_methods()["method4"].samples == ("thin", "thin_white")


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(a=1.5, tau=1.0, design="method3"), "a .relative absorption"),
        (dict(a=0.1, tau=[1.0, 2.0], design="method3"), "one value per wavelength"),
        (dict(a=0.1, tau=1.0, design="method5"), "design must be one of"),
        (dict(a=0.1, tau=1.0, design=[{"substrate": "grey"}]), "substrate must be"),
        (dict(a=0.1, tau=1.0, design=[{"name": "x", "thickness": 3}]), "design\\[0\\]"),
        (dict(a=0.1, tau=1.0, design="method3", eps=-0.1), "eps must be"),
        (dict(a=0.1, tau=1.0, design="method3", eps=30.0), "negative"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        simulate(wavelengths=WAVELENGTHS, model=_fake_model, instrument="multi-angle-45", **kwargs)


@pytest.mark.parametrize("design", [None, True, 4.0, {"substrate": "black"}])
def test_a_design_of_the_wrong_type_is_a_type_error_naming_it(design):
    with pytest.raises(TypeError, match=r"^design must be a method \(method1, method2, method3, method4, or 1-4\) "
                                        r"or a list of FilmSpec or dict, got "):
        simulate(a=0.1, tau=1.0, design=design, wavelengths=WAVELENGTHS, model=_fake_model,
                 instrument="multi-angle-45")


@pytest.mark.parametrize("design", [4, "4", "method4"])
def test_a_design_is_a_method_in_either_spelling(design):
    films = simulate(a=0.1, tau=1.0, design=design, wavelengths=WAVELENGTHS, model=_fake_model,
                     instrument="multi-angle-45", seed=1)
    assert films == simulate(a=0.1, tau=1.0, design="method4", wavelengths=WAVELENGTHS,
                             model=_fake_model, instrument="multi-angle-45", seed=1)


def test_simulate_to_csv_writes_what_it_returns(tmp_path):
    path = tmp_path / "sim.csv"
    ms = simulate_to_csv(
        path, a=0.1, tau=1.0, design="method4", wavelengths=WAVELENGTHS, model=_fake_model
    )
    assert isinstance(ms, MeasurementSet) and read_csv(path) == ms
    with pytest.raises(ValueError):
        simulate_to_csv(
            tmp_path / "bad.csv", a=0.1, tau=-1.0, design="method4", wavelengths=WAVELENGTHS
        )
    assert not (tmp_path / "bad.csv").exists()


def test_simulate_to_csv_writes_nothing_a_reader_would_refuse(tmp_path):
    """A white film (reflectance ~0.9) with 15 % noise passes 1.05 somewhere: refused before writing."""
    path = tmp_path / "bright.csv"
    with pytest.raises(ValueError, match=r"^the simulated set cannot be written as a measurement file: sample "
                                         r"'.*', geometry 8d-sci, .* nm: reflectance .* exceeds 1.05"):
        simulate_to_csv(path, a=1e-4, tau=1.0, design=[{"name": "white", "opaque": True}], eps=0.15,
                        instrument="8d-sci", wavelengths=[400.0 + 10 * k for k in range(20)], seed=0)
    assert not path.exists()
