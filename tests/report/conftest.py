"""Shared fixtures of the report tests: one quick demo run (simulate -> infer -> report).

The demo is run once per session through the command's own functions
(``bayespig.commands.report.add_demo_parser`` / ``run_demo``), exactly what ``bayespig demo
--quick --out DIR`` does, and every report test reads its output.
"""

import argparse

import pytest


@pytest.fixture(scope="session")
def demo_dir(tmp_path_factory):
    """Output directory of ``bayespig demo --quick --no-progress --seed 3``."""
    from bayespig.commands.report import add_demo_parser

    out = tmp_path_factory.mktemp("demo") / "report"
    parser = argparse.ArgumentParser(prog="bayespig")
    add_demo_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["demo", "--quick", "--no-progress", "--seed", "3", "--out", str(out)])
    status = args.func(args)
    if status != 0:
        raise RuntimeError(f"bayespig demo exited with {status}")
    return out


@pytest.fixture(scope="session")
def demo_idata(demo_dir):
    """The demo's posterior, read back from its netCDF file."""
    from bayespig.inference import load_inference

    idata = load_inference(demo_dir / "posterior.nc")
    return idata


@pytest.fixture(scope="session")
def demo_set():
    """The demo's measurement set (the same seed as ``demo_dir``), at the quick wavelengths."""
    from bayespig.demo import DEMO_WAVELENGTHS_NM, demo_measurements

    return demo_measurements(seed=3, wavelength_nm=DEMO_WAVELENGTHS_NM[::3])
