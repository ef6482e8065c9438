"""netCDF files: round trip, atomic writes, checked reads."""


import numpy as np
import pytest

from bayespig.inference import (
    load_inference,
    save_inference,
    summarize,
)


def test_netcdf_round_trip(method4_idata, tmp_path):
    path = tmp_path / "sub" / "posterior.nc"
    save_inference(method4_idata, path)
    assert [p.name for p in path.parent.iterdir()] == ["posterior.nc"]  # no temporary left
    back = load_inference(path)
    for group in ("posterior", "posterior_predictive", "log_likelihood", "observed_data",
                  "constant_data", "sample_stats"):
        original, loaded = getattr(method4_idata, group), getattr(back, group)
        for name in original.data_vars:
            np.testing.assert_array_equal(loaded[name].values, original[name].values)
    assert list(back.observed_data["channel"].values) == list(method4_idata.observed_data["channel"].values)
    assert back.posterior.attrs["settings"] == method4_idata.posterior.attrs["settings"]
    assert summarize(back).equals(summarize(method4_idata))


def test_load_inference_rejects_other_files(tmp_path):
    with pytest.raises(ValueError, match="file not found"):
        load_inference(tmp_path / "missing.nc")
    bad = tmp_path / "bad.nc"
    bad.write_text("not netcdf")
    with pytest.raises(ValueError, match="bad.nc"):
        load_inference(bad)


def test_saved_posterior_has_units_and_long_names(method4_idata, tmp_path):
    """netCDF readers (ncdump, xarray) see what every variable is: long names and units."""
    path = tmp_path / "posterior.nc"
    save_inference(method4_idata, path)
    back = load_inference(path)
    post = back.posterior
    assert post["a"].attrs["long_name"] == "relative absorption k_abs/k_ext"
    assert post["tau"].attrs["long_name"] == "optical thickness"
    assert post["a"].attrs["units"] == post["tau"].attrs["units"] == "1"
    for group in ("posterior", "posterior_predictive", "log_likelihood", "observed_data", "constant_data",
                  "sample_stats"):
        wavelength = getattr(back, group)["wavelength"]
        assert wavelength.attrs["units"] == "nm" and wavelength.attrs["long_name"] == "wavelength", group

