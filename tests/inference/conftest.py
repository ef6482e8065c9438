"""A method-4 set and its posterior, shared by the inference tests (computed once)."""

import pytest

from bayespig.inference import infer

from .common import FAST, method4_data


@pytest.fixture(scope="package")
def method4_set():
    return method4_data()


@pytest.fixture(scope="package")
def method4_idata(method4_set):
    return infer(method4_set, seed=5, progress=False, settings=FAST, executor=None)
