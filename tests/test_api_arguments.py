"""Bad arguments to the public functions of fit, likelihood, table, instruments, colorimetry,
kubelka_munk and the calibration study: one TypeError/ValueError that names the argument,
never numpy's or Python's internal text (issue 18, "API arguments")."""

import numpy as np
import pytest

from bayespig import colorimetry as cm
from bayespig import kubelka_munk as km
from bayespig import robustness_study, simulate
from bayespig.fit import FitSettings, film_term, fit_batch, fit_measurements, fit_problem
from bayespig.instruments import Channel, get_instrument, predict
from bayespig.likelihood import Problem, multiplicative_normal_logpdf
from bayespig.studies.calibration import simulation_based_calibration
from bayespig.table import TableSettings, build_table, load_table

WAVELENGTHS_NM = np.arange(400.0, 701.0, 10.0)
REFLECTANCE = np.full(WAVELENGTHS_NM.size, 0.5)
#: Texts of numpy's and Python's internals that a user must never see for a wrong argument.
INTERNAL_TEXTS = (
    "ufunc",
    "could not convert",
    "could not be broadcast",
    "cannot be broadcast",
    "operands could not",
    "object is not iterable",
    "has no attribute",
    "not supported between",
    "unsupported operand",
    "asdict()",
    "expected str, bytes",
    "deg must be",
)


#: A tiny isotropic table (built in well under a second) for the table's own argument checks.
SMALL_TABLE_SETTINGS = TableSettings(n_a=8, log2_tau_min=-2, log2_tau_max=2, per_octave=1)


def _small_table():
    import os

    return load_table("8d-sci", settings=SMALL_TABLE_SETTINGS, cache_dir=os.environ["BAYESPIG_CACHE"], progress=False)


def _observed():
    return np.full((3, 5), 0.02)


# (call, error type, start of the message: the argument's name and what is wrong)
BAD_CALLS = {
    "simulate seed True": (lambda: simulate(a=0.1, tau=1.0, design=4, seed=True), TypeError,
                           "seed must be an integer, not a boolean: got True"),
    "simulate seed -1": (lambda: simulate(a=0.1, tau=1.0, design=4, seed=-1), ValueError,
                         "seed must be an integer >= 0, got -1"),
    "robustness seed True": (lambda: robustness_study(4, 0.1, 1.0, n_repeat=2, seed=True), TypeError,
                             "seed must be an integer, not a boolean: got True"),
    "robustness n_repeat 2.5": (lambda: robustness_study(4, 0.1, 1.0, n_repeat=2.5), TypeError,
                                "n_repeat must be an integer, got 2.5 (float)"),
    # colorimetry
    "weighting_matrix wavelength str": (lambda: cm.weighting_matrix("400"), TypeError, "wavelength_nm must be a number or an array"),
    "weighting_matrix wavelength None": (lambda: cm.weighting_matrix(None), TypeError, "wavelength_nm must be"),
    "weighting_matrix wavelength 2-D": (lambda: cm.weighting_matrix(np.ones((2, 31))), ValueError, "wavelength_nm must be a 1-D array"),
    "weighting_matrix observer None": (lambda: cm.weighting_matrix(WAVELENGTHS_NM, observer=None), ValueError, "observer=None is not known"),
    "weighting_matrix method": (lambda: cm.weighting_matrix(WAVELENGTHS_NM, method="x"), ValueError, "method='x' is not valid"),
    "reflectance_to_XYZ reflectance str": (lambda: cm.reflectance_to_XYZ("0.5", WAVELENGTHS_NM), TypeError, "reflectance must be"),
    "reflectance_to_XYZ reflectance None": (lambda: cm.reflectance_to_XYZ(None, WAVELENGTHS_NM), TypeError, "reflectance must be"),
    "reflectance_to_XYZ reflectance bool": (lambda: cm.reflectance_to_XYZ(True, WAVELENGTHS_NM), TypeError, "reflectance must be"),
    "reflectance_to_XYZ reflectance NaN": (lambda: cm.reflectance_to_XYZ(REFLECTANCE * np.nan, WAVELENGTHS_NM), ValueError, "reflectance must not contain NaN"),
    "reflectance_to_XYZ shapes": (lambda: cm.reflectance_to_XYZ(np.ones(5), WAVELENGTHS_NM), ValueError, "reflectance has shape (5,)"),
    "white_point_XYZ wavelength str": (lambda: cm.white_point_XYZ("x"), TypeError, "wavelength_nm must be"),
    "XYZ_to_Lab XYZ str": (lambda: cm.XYZ_to_Lab("x"), TypeError, "XYZ must be"),
    "XYZ_to_Lab white str": (lambda: cm.XYZ_to_Lab([1, 2, 3], white_XYZ="x"), TypeError, "white_XYZ must be"),
    "XYZ_to_Lab XYZ NaN": (lambda: cm.XYZ_to_Lab([np.nan, 2, 3]), ValueError, "XYZ must not contain NaN"),
    "reflectance_to_Lab wavelength str": (lambda: cm.reflectance_to_Lab(REFLECTANCE, "x"), TypeError, "wavelength_nm must be"),
    "delta_E2000 Lab_1 str": (lambda: cm.delta_E2000("x", [1, 2, 3]), TypeError, "Lab_1 must be"),
    "delta_E2000 Lab_1 None": (lambda: cm.delta_E2000(None, [1, 2, 3]), TypeError, "Lab_1 must be"),
    "delta_E2000 shapes": (lambda: cm.delta_E2000(np.ones((2, 3)), np.ones((3, 3))), ValueError, "Lab_1 with shape (2, 3) and Lab_2"),
    # Kubelka-Munk
    "reflectance_infinity str": (lambda: km.reflectance_infinity("1"), TypeError, "k_over_s must be a number or an array"),
    "reflectance_infinity None": (lambda: km.reflectance_infinity(None), TypeError, "k_over_s must be"),
    "reflectance_infinity bool": (lambda: km.reflectance_infinity(True), TypeError, "k_over_s must be"),
    "reflectance_infinity negative": (lambda: km.reflectance_infinity(-1), ValueError, "k_over_s must be >= 0, got -1"),
    "k_over_s_from_reflectance_infinity str": (lambda: km.k_over_s_from_reflectance_infinity("x"), TypeError, "reflectance_infinity must be"),
    "layer_reflectance K str": (lambda: km.layer_reflectance("1", 1.0), TypeError, "K must be"),
    "layer_reflectance thickness None": (lambda: km.layer_reflectance(1.0, 1.0, None), TypeError, "thickness must be"),
    "layer_reflectance shapes": (lambda: km.layer_reflectance(np.ones(3), np.ones(2)), ValueError, "the shapes of K (3,), S (2,), thickness ()"),
    "layer_reflectance background shape": (lambda: km.layer_reflectance(np.ones(3), 1.0, 1.0, [0.1, 0.2]), ValueError, "the shapes of K (3,), S and thickness (3,), background_reflectance (2,)"),
    "layer_transmittance shapes": (lambda: km.layer_transmittance(np.ones(3), np.ones(2)), ValueError, "the shapes of K (3,), S (2,)"),
    "mix_K_S concentrations str": (lambda: km.mix_K_S("x", np.ones((2, 5)), np.ones((2, 5))), TypeError, "concentrations must be"),
    "saunderson_to_measured reflectance str": (lambda: km.saunderson_to_measured("x", specular="included"), TypeError, "internal_reflectance must be"),
    "saunderson_to_measured specular None": (lambda: km.saunderson_to_measured(0.5, specular=None), ValueError, "specular=None is not valid"),
    "saunderson_to_measured k1 str": (lambda: km.saunderson_to_measured(0.5, "x", specular="included"), TypeError, "k1 must be"),
    "saunderson_to_measured shapes": (lambda: km.saunderson_to_measured(np.full(3, 0.5), np.full(2, 0.04), specular="included"), ValueError, "the shapes of internal_reflectance (3,), k1 (2,)"),
    "saunderson_to_internal shapes": (lambda: km.saunderson_to_internal(np.full(3, 0.5), 0.04, np.full(2, 0.6), specular="included"), ValueError, "the shapes of measured_reflectance (3,), k1 (), k2 (2,)"),
    "saunderson_k1 str": (lambda: km.saunderson_k1("1.5"), TypeError, "refractive_index must be a number, got '1.5' (str)"),
    "saunderson_k1 None": (lambda: km.saunderson_k1(None), TypeError, "refractive_index must be a number"),
    "saunderson_k2 NaN": (lambda: km.saunderson_k2(np.nan), ValueError, "refractive_index must not be NaN"),
    "saunderson_constants index str": (lambda: km.saunderson_constants("1.5"), TypeError, "refractive_index must be a number"),
    "saunderson_constants theta str": (lambda: km.saunderson_constants(1.5, "8"), TypeError, "theta_i must be a number"),
    "ks_from_black_white str": (lambda: km.ks_from_black_white("x", 0.5, 0.0, 0.9), TypeError, "reflectance_over_black must be"),
    "ks_from_black_white shapes": (lambda: km.ks_from_black_white(np.full(3, 0.3), np.full(2, 0.5), 0.0, 0.9), ValueError, "the shapes of reflectance_over_black (3,), reflectance_over_white (2,)"),
    "predict_measured KX str": (lambda: km.predict_measured("x", 1.0, 0.5, specular="excluded"), TypeError, "KX must be"),
    # instruments
    "get_instrument n str": (lambda: get_instrument("8d-sci", n="1.45"), TypeError, "n must be a number, got '1.45' (str)"),
    "get_instrument n None": (lambda: get_instrument("8d-sci", n=None), TypeError, "n must be a number, got None"),
    "get_instrument n bool": (lambda: get_instrument("8d-sci", n=True), TypeError, "n must be a number, got True"),
    "get_instrument n below 1": (lambda: get_instrument("8d-sci", n=0.5), ValueError, "n must be >= 1, got 0.5"),
    "get_instrument None": (lambda: get_instrument(None), TypeError, "instrument must be a built-in name (multi-angle-45,"),
    "get_instrument int": (lambda: get_instrument(4), TypeError, "instrument must be a built-in name"),
    "get_instrument bad triple": (lambda: get_instrument([(45, "x", 0)]), TypeError, "instrument geometries must be labels"),
    "Channel theta_i str": (lambda: Channel("brdf", "45", 15.0), TypeError, "theta_i must be a number, got '45' (str)"),
    "Channel theta_o None": (lambda: Channel("brdf", 45.0, None), TypeError, "theta_o must be a number, got None"),
    "Channel delta_phi str": (lambda: Channel("brdf", 45.0, 15.0, "180"), TypeError, "delta_phi must be a number"),
    "Channel label": (lambda: Channel("brdf", 45.0, 15.0, 180.0, None, 5), TypeError, "label must be a string, got 5 (int)"),
    "predict a str": (lambda: predict("8d-sci", a="0.1", tau=1.0), TypeError, "a must be a number or an array"),
    "predict a None": (lambda: predict("8d-sci", a=None, tau=1.0), TypeError, "a must be"),
    "predict tau None": (lambda: predict("8d-sci", a=0.1, tau=None), TypeError, "tau must be"),
    "predict shapes": (lambda: predict("8d-sci", a=np.full(3, 0.1), tau=np.ones(2)), ValueError, "the shapes of a (3,), tau (2,), g (), r_s ()"),
    "predict r_s shape": (lambda: predict("8d-sci", a=np.full(3, 0.1), tau=1.0, r_s=[0.1, 0.2]), ValueError, "the shapes of a (3,), tau (), g (), r_s (2,)"),
    # tables
    "build_table settings": (lambda: build_table("8d-sci", settings={"n_a": 8}), TypeError, "settings must be a TableSettings or None, got {'n_a': 8} (dict)"),
    "load_table n str": (lambda: load_table("8d-sci", n="1.45"), TypeError, "n must be a number, got '1.45' (str)"),
    "load_table n None": (lambda: load_table("8d-sci", n=None), TypeError, "n must be a number, got None"),
    "load_table g None": (lambda: load_table("8d-sci", g=None), ValueError, "g must be one of 'isotropic', 'free', got None"),
    "load_table settings str": (lambda: load_table("8d-sci", settings="x"), TypeError, "settings must be a TableSettings or None, got 'x' (str)"),
    "load_table cache_dir int": (lambda: load_table("8d-sci", cache_dir=5), TypeError, "cache_dir must be a folder path or None, got 5 (int)"),
    "load_table rebuild str": (lambda: load_table("8d-sci", rebuild="no"), TypeError, "rebuild must be True or False, got 'no' (str)"),
    "load_table progress None": (lambda: load_table("8d-sci", progress=None), TypeError, "progress must be True or False"),
    "load_table executor str": (lambda: load_table("8d-sci", executor="x"), TypeError, "executor must be a concurrent.futures.Executor or None"),
    "LookupTable a str": (lambda: _small_table()(a="0.1", tau=1.0), TypeError, "a must be a number or an array of numbers, got '0.1' (str)"),
    "LookupTable a None": (lambda: _small_table()(a=None, tau=1.0), TypeError, "a must be"),
    "LookupTable tau bool": (lambda: _small_table().evaluate(a=0.1, tau=True, gradient=True), TypeError, "tau must be a number or an array of numbers, not booleans"),
    "LookupTable shapes": (lambda: _small_table()(a=np.full(3, 0.1), tau=np.ones(2)), ValueError, "the shapes of a (3,), tau (2,), g (), r_s ()"),
    "LookupTable r_s shape": (lambda: _small_table()(a=np.full(2, 0.1), tau=1.0, r_s=[0.1, 0.2, 0.3]), ValueError, "the shapes of a (2,), tau (), g (), r_s (3,)"),
    "TableSettings n_a str": (lambda: TableSettings(n_a="12"), TypeError, "n_a must be an integer, got '12' (str)"),
    "TableSettings n_a float": (lambda: TableSettings(n_a=12.5), TypeError, "n_a must be an integer, got 12.5 (float)"),
    "TableSettings n_points": (lambda: TableSettings(n_points=2.5), TypeError, "n_points must be an integer, got 2.5 (float)"),
    "TableSettings per_octave 0": (lambda: TableSettings(per_octave=0), ValueError, "per_octave must be an integer >= 1, got 0"),
    "TableSettings tau range": (lambda: TableSettings(log2_tau_min=3, log2_tau_max=3), ValueError, "log2_tau_max must be an integer >= 4, got 3"),
    "TableSettings a_stretch None": (lambda: TableSettings(a_stretch=None), TypeError, "a_stretch must be a number"),
    "TableSettings g_axis None": (lambda: TableSettings(g_axis=None), ValueError, "g_axis must be one of"),
    # likelihood and fits
    "multiplicative_normal_logpdf str": (lambda: multiplicative_normal_logpdf("x", 1.0, 0.05), TypeError, "observed must be"),
    "multiplicative_normal_logpdf shapes": (lambda: multiplicative_normal_logpdf(np.ones(3), np.ones(2), 0.05), ValueError, "the shapes of observed (3,), model (2,), eps ()"),
    "Problem.from_measurements None": (lambda: Problem.from_measurements(None), TypeError, "measurements must be a bayespig MeasurementSet, got None"),
    "fit_measurements path": (lambda: fit_measurements("x.csv"), TypeError, "measurements must be a bayespig MeasurementSet, got 'x.csv' (str) (read a file with bayespig.read_measurements first)"),
    "fit_problem None": (lambda: fit_problem(None), TypeError, "problem must be a bayespig.likelihood.Problem"),
    "film_term observed str": (lambda: film_term("w", observed="x", instrument="8d-sci"), TypeError, "observed must be"),
    "film_term observed None": (lambda: film_term("w", observed=None, instrument="8d-sci"), TypeError, "observed must be"),
    "film_term observed 1-D": (lambda: film_term("w", observed=[0.1, 0.2], instrument="8d-sci"), ValueError, "observed must have 2 dimension(s), got shape (2,)"),
    "film_term r_s str": (lambda: film_term("w", observed=_observed(), instrument="8d-sci", r_s="x"), TypeError, "r_s must be a number, got 'x' (str)"),
    "film_term r_s above 1": (lambda: film_term("w", observed=_observed(), instrument="8d-sci", r_s=1.5), ValueError, "r_s must be in [0, 1], got 1.5"),
    "film_term kind": (lambda: film_term("w", observed=_observed(), kind="absorbance"), ValueError, "kind must be one of 'reflectance', 'transmittance'"),
    "film_term instrument missing": (lambda: film_term("w", observed=_observed()), ValueError, "instrument is needed for a reflectance film"),
    "film_term instrument int": (lambda: film_term("w", observed=_observed(), instrument=4), TypeError, "instrument must be a built-in name"),
    "film_term name None": (lambda: film_term(None, observed=_observed(), instrument="8d-sci"), TypeError, "name must be a string"),
    "fit_batch g None": (lambda: fit_batch([], (), method="method4", g=None), TypeError, "g must be a number or 'search', got None"),
    "fit_batch g NaN": (lambda: fit_batch([], (), method="method4", g=np.nan), ValueError, "g must not be NaN"),
    "fit_batch g 1": (lambda: fit_batch([], (), method="method4", g=1.0), ValueError, "g must be in (-1, 1), got 1"),
    "fit_batch n str": (lambda: fit_batch([], (), method="method4", n="1.45"), TypeError, "n must be a number"),
    "fit_batch settings": (lambda: fit_batch([], (), method="method4", settings={}), TypeError, "settings must be a FitSettings or None"),
    "fit_batch tables": (lambda: fit_batch([], (), method="method4", tables=[]), TypeError, "tables must be a dict"),
    "fit_batch method None": (lambda: fit_batch([], (), method=None), ValueError, "method must be one of"),
    "FitSettings tau_bounds str": (lambda: FitSettings(tau_bounds="x"), TypeError, "tau_bounds must be a number or an array"),
    "FitSettings tau_bounds triple": (lambda: FitSettings(tau_bounds=(1, 2, 3)), ValueError, "tau_bounds must be a pair of numbers, got (1, 2, 3)"),
    "FitSettings a_bounds None": (lambda: FitSettings(a_bounds=None), TypeError, "a_bounds must be"),
    "FitSettings n_grid_a float": (lambda: FitSettings(n_grid_a=8.5), TypeError, "n_grid_a must be an integer, got 8.5"),
    "FitSettings max_starts 0": (lambda: FitSettings(max_starts=0), ValueError, "max_starts must be an integer >= 1, got 0"),
    "FitSettings step_tolerance str": (lambda: FitSettings(step_tolerance="1e-7"), TypeError, "step_tolerance must be a number"),
    "FitSettings start str": (lambda: FitSettings(start="x"), TypeError, "start must be"),
    "FitSettings objective None": (lambda: FitSettings(objective=None), ValueError, "objective must be one of"),
    # simulation-based calibration (all refused before any work)
    "sbc method": (lambda: simulation_based_calibration("x"), ValueError, "unknown method 'x': method must be one of 1, 2, 3, 4, method1, method2, method3, method4"),
    "sbc n_replicates str": (lambda: simulation_based_calibration(n_replicates="5"), TypeError, "n_replicates must be an integer, got '5' (str)"),
    "sbc n_replicates float": (lambda: simulation_based_calibration(n_replicates=2.5), TypeError, "n_replicates must be an integer, got 2.5"),
    "sbc n_replicates bool": (lambda: simulation_based_calibration(n_replicates=True), TypeError, "n_replicates must be an integer, not a boolean"),
    "sbc n_draws None": (lambda: simulation_based_calibration(n_draws=None), TypeError, "n_draws must be an integer"),
    "sbc n_bins 0": (lambda: simulation_based_calibration(n_bins=0), ValueError, "n_bins must be an integer >= 1, got 0"),
    "sbc seed bool": (lambda: simulation_based_calibration(seed=True), TypeError, "seed must be an integer, not a boolean: got True"),
    "sbc seed negative": (lambda: simulation_based_calibration(seed=-1), ValueError, "seed must be an integer >= 0, got -1"),
    "sbc eps too large": (lambda: simulation_based_calibration(eps=5.0), ValueError, "eps must be in (0, 0.5], got 5"),
    "sbc eps list": (lambda: simulation_based_calibration(eps=[0.05, 0.05]), TypeError, "eps must be a single number"),
    "sbc instrument": (lambda: simulation_based_calibration(instrument=None), TypeError, "instrument must be a built-in instrument name"),
    "sbc settings": (lambda: simulation_based_calibration(settings="x"), TypeError, "settings must be an InferenceSettings or None"),
    "sbc progress": (lambda: simulation_based_calibration(progress="yes"), TypeError, "progress must be True or False"),
}


@pytest.mark.parametrize("call, error, message", BAD_CALLS.values(), ids=BAD_CALLS.keys())
def test_bad_argument_is_named(call, error, message, tmp_path, monkeypatch):
    monkeypatch.setenv("BAYESPIG_CACHE", str(tmp_path / "cache"))  # a fresh cache: no table needed
    with pytest.raises(error) as excinfo:
        call()
    text = str(excinfo.value)
    assert type(excinfo.value) is error or issubclass(type(excinfo.value), error)
    assert text.startswith(message), text
    assert not any(internal in text for internal in INTERNAL_TEXTS), text


def test_method_spelled_as_a_number_is_accepted_by_the_calibration_study(monkeypatch):
    # 4 and "4" mean "method4" (as on the command line); checked up to the first real work
    import bayespig.table

    def stop(*args, **kwargs):
        raise RuntimeError("arguments accepted")

    monkeypatch.setattr(bayespig.table, "load_table", stop)
    for spelling in (4, "4", "method4"):
        with pytest.raises(RuntimeError, match="arguments accepted"):
            simulation_based_calibration(spelling, n_replicates=2, n_draws=9, n_bins=10)
