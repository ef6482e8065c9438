"""A method-4 set and its posterior, shared by the inference tests (computed once)."""

import pytest

from bayespig.data import simulate
from bayespig.inference import infer

from .common import FAST


@pytest.fixture(scope="package")
def method4_set():
    return simulate(a=[0.05, 0.1, 0.2], tau=[0.5, 1.0, 2.0], design="method4",
                    wavelengths=[450.0, 550.0, 650.0], eps=0.05, seed=11)


@pytest.fixture(scope="package")
def method4_idata(method4_set):
    return infer(method4_set, seed=5, progress=False, settings=FAST, executor=None)
