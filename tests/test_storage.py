"""bayespig._storage.read_netcdf: a damaged posterior file is named at once, not deep in a computation."""

import arviz as az
import h5py
import numpy as np
import pytest

from bayespig._storage import read_netcdf
from bayespig.inference import save_inference

#: Bytes inverted inside the first compressed chunk of posterior/a (any damage to a gzip
#: stream of this size makes the HDF5 filter fail).
FLIPPED_BYTES = 16


@pytest.fixture
def posterior_file(tmp_path):
    rng = np.random.default_rng(3)
    idata = az.from_dict(posterior={"a": rng.random((2, 50, 3)), "tau": rng.random((2, 50, 3))})
    path = tmp_path / "run" / "posterior.nc"
    path.parent.mkdir()
    save_inference(idata, path)
    return idata, path


def _flip_first_chunk(path, variable="posterior/a"):
    with h5py.File(path, "r") as handle:
        dataset = handle[variable]
        assert dataset.compression == "gzip"  # else the flip would change numbers silently
        chunk = dataset.id.get_chunk_info(0)
    data = bytearray(path.read_bytes())
    start = chunk.byte_offset + chunk.size // 2
    data[start : start + FLIPPED_BYTES] = bytes(b ^ 0xFF for b in data[start : start + FLIPPED_BYTES])
    path.write_bytes(bytes(data))


def test_intact_file_reads_back_in_memory(posterior_file):
    idata, path = posterior_file
    again = read_netcdf(path)
    np.testing.assert_array_equal(again.posterior["a"].values, idata.posterior["a"].values)
    path.unlink()  # nothing is read lazily from the file any more
    np.testing.assert_array_equal(again.posterior["tau"].values, idata.posterior["tau"].values)


def test_byte_flipped_posterior_names_the_file(posterior_file, monkeypatch):
    _, path = posterior_file
    _flip_first_chunk(path)
    # arviz's own (lazy) reader opens it and fails later, without the file name
    with pytest.raises(OSError, match=r"^Can't synchronously read data \(filter returned failure during read\)"):
        float(az.from_netcdf(path).posterior["a"].mean())
    monkeypatch.chdir(path.parent.parent)
    with pytest.raises(ValueError) as excinfo:
        read_netcdf("run/posterior.nc")
    assert str(excinfo.value) == (
        "'run/posterior.nc' cannot be read: it is damaged or not a bayespig posterior "
        "(OSError: Can't synchronously read data (filter returned failure during read))"
    )


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: p.write_text("wavelength,a\n400,0.1\n"), "it is damaged or not a bayespig posterior (OSError: "),
        (lambda p: p.write_bytes(p.read_bytes()[:1000]), "it is damaged or not a bayespig posterior ("),
        (lambda p: p.unlink(), "file not found"),
        (lambda p: (p.unlink(), p.mkdir()), "it is a folder, not a posterior file"),
    ],
    ids=["text", "truncated", "missing", "folder"],
)
def test_other_bad_files(posterior_file, make, message):
    _, path = posterior_file
    make(path)
    with pytest.raises(ValueError) as excinfo:
        read_netcdf(path)
    assert str(excinfo.value).startswith(f"'{path}' cannot be read: {message}")
