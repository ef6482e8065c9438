"""``bayespig infer --noise-floor/--exclude-mirror/--max-angle/--wavelengths``: plain errors and
what reaches the posterior."""

import dataclasses

import numpy as np
import pytest

from bayespig.cli import main
from bayespig.data import MeasurementSet, simulate
from bayespig.inference import load_inference


def _write(path, zero=False):
    ms = simulate(a=0.1, tau=1.0, design="method4", wavelengths=[500.0, 550.0, 600.0], eps=0.02, seed=3)
    if zero:  # the last geometry of the film on white reads 0 at 550 nm
        samples = list(ms.samples)
        film = samples[1]
        last = film.measurements[-1]
        values = np.array(last.values)
        values[1] = 0.0
        samples[1] = dataclasses.replace(film, measurements=film.measurements[:-1]
                                         + (dataclasses.replace(last, values=values),))
        ms = MeasurementSet(ms.wavelength_nm, samples, n=ms.n, metadata=dict(ms.metadata))
    ms.to_csv(path)
    return ms


@pytest.mark.parametrize("option, value, message", [
    ("--noise-floor", "abc", "--noise-floor: must be a number >= 0 (the additive noise floor in the units of the values, e.g. 0.001 for 0.001 1/sr) or 'infer', got 'abc'"),
    ("--noise-floor", "-1e-3", "--noise-floor: must be a number >= 0 (the additive noise floor in the units of the values, e.g. 0.001 for 0.001 1/sr) or 'infer', got -0.001"),
    ("--wavelengths", "600-500", ("--wavelengths: expected a range LOW-HIGH (e.g. 420-500) or a list W1,W2,... "
                                 "[nm], got '600-500'")),
    ("--wavelengths", "500,x", ("--wavelengths: expected a range LOW-HIGH (e.g. 420-500) or a list W1,W2,... "
                               "[nm], got '500,x'")),
    ("--max-angle", "95", "max_angle_deg must be None or a number of degrees in [0, 90], got 95.0"),
    ("--wavelengths", "450", "wavelengths 450 nm are not measured (the set has 3 bands, 500–600 nm)"),
])
def test_bad_options_are_plain_errors(tmp_path, capsys, option, value, message):
    data = tmp_path / "film.csv"
    _write(data)
    assert main(["infer", str(data), "--out", str(tmp_path / "out"), "--no-progress", f"{option}={value}"]) == 2
    assert capsys.readouterr().err == f"bayespig: error: {message}\n"
    assert not (tmp_path / "out").exists()


def test_zero_needs_a_noise_floor(tmp_path, capsys):
    data = tmp_path / "film.csv"
    ms = _write(data, zero=True)
    label = ms.samples[1].measurements[-1].label
    n_values = len(ms.samples[1].measurements)
    assert main(["infer", str(data), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    name = ms.samples[1].name
    # the line of the file that holds the zero (the error names it)
    row = next(k for k, line in enumerate(data.read_text().splitlines(), 1)
               if line.startswith(f"{name},") and f",brdf,{label}," in line)
    assert capsys.readouterr().err == (
        f"bayespig: error: {data}, row {row}: film {name!r}: observed value 0 at 550 nm, geometry {label} (value {n_values} of "
        f"{n_values}) must be > 0 without a noise floor (eq. 7 gives a zero reading zero likelihood); give "
        "noise_floor=<number> or 'infer' (--noise-floor on the command line) to take zeros as data\n")
    assert not (tmp_path / "out").exists()


def test_noise_floor_and_selection_reach_the_posterior(tmp_path):
    data = tmp_path / "film.csv"
    _write(data, zero=True)
    out = tmp_path / "out"
    assert main(["infer", str(data), "--out", str(out), "--no-progress", "--method", "4", "--noise-floor", "0.001",
                 "--wavelengths", "540-600", "--exclude-mirror", "20", "--max-angle", "80", "--censored-zeros"]) == 0
    idata = load_inference(out / "posterior.nc")
    np.testing.assert_array_equal(idata.posterior["wavelength"].values, [550.0, 600.0])
    assert idata.posterior.attrs["noise_floor_mode"] == "known"
    assert idata.posterior.attrs["noise_floor"] == 0.001
    assert idata.posterior.attrs["censored_zeros"] == 1
    assert "45as15" not in set(idata.observed_data["channel"].values)  # 15° from the mirror


def test_censored_zeros_need_a_noise_floor(tmp_path, capsys):
    data = tmp_path / "film.csv"
    _write(data, zero=True)
    assert main(["infer", str(data), "--out", str(tmp_path / "out"), "--no-progress", "--censored-zeros"]) == 2
    assert capsys.readouterr().err == ("bayespig: error: --censored-zeros needs --noise-floor (a number > 0 or "
                                       "infer): without a floor a reading of 0 has no probability\n")
    assert not (tmp_path / "out").exists()


def test_exclude_occluded_reaches_infer(tmp_path, monkeypatch):
    import bayespig.inference

    data = tmp_path / "film.csv"
    _write(data)
    passed = {}

    def recorded_infer(measurements, **kwargs):
        passed.update(kwargs)
        raise KeyboardInterrupt  # stop here: the wiring is what is tested

    monkeypatch.setattr(bayespig.inference, "infer", recorded_infer)
    assert main(["infer", str(data), "--out", str(tmp_path / "out"), "--no-progress", "--exclude-occluded"]) != 0
    assert passed["exclude_occluded"] is True
    assert not (tmp_path / "out").exists()


def test_exclude_occluded_must_be_a_flag():
    from bayespig.inference import infer

    with pytest.raises(TypeError) as caught:
        infer("never-read.csv", exclude_occluded="yes")
    assert str(caught.value) == "exclude_occluded must be True or False, got 'yes' (str)"
