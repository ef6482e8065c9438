"""Executors: the samples do not depend on how the tasks run."""

from concurrent.futures import Future, ProcessPoolExecutor

import numpy as np

from bayespig.data import simulate
from bayespig.inference import (
    InferenceSettings,
    infer,
)

from .common import FAST


class _InlineExecutor:
    """``submit`` runs the task at once, in this process (a serial executor)."""

    def submit(self, fn, *args):
        future = Future()
        future.set_result(fn(*args))
        return future


def test_same_seed_identical_whatever_the_executor(method4_set, method4_idata):
    """The samples depend on seed and settings only: a process pool, a serial executor and the
    default (one stack, serial) agree bit for bit; a stack of one wavelength per run is a
    different but equally valid grouping."""
    single = InferenceSettings(**{**FAST.__dict__, "wavelengths_per_run": 1})
    with ProcessPoolExecutor(max_workers=2) as pool:
        pooled = infer(method4_set, seed=5, progress=False, settings=single, executor=pool)
    inline = infer(method4_set, seed=5, progress=False, settings=single, executor=_InlineExecutor())
    stacked_inline = infer(method4_set, seed=5, progress=False, settings=FAST, executor=_InlineExecutor())
    for name in ("a", "tau"):
        np.testing.assert_array_equal(pooled.posterior[name].values, inline.posterior[name].values)
        np.testing.assert_array_equal(stacked_inline.posterior[name].values,
                                      method4_idata.posterior[name].values)
    np.testing.assert_array_equal(pooled.posterior_predictive["y"].values,
                                  inline.posterior_predictive["y"].values)


def test_dask_executor_gives_the_same_samples(method4_set, method4_idata):
    from dask.distributed import Client, LocalCluster

    one = simulate(a=0.05, tau=0.5, design="method4", wavelengths=[450.0], eps=0.05, seed=11)
    with (LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None)
          as cluster, Client(cluster) as client):
        distributed = infer(one, seed=5, progress=False, settings=FAST, executor=client.get_executor())
    serial = infer(one, seed=5, progress=False, settings=FAST, executor=None)
    np.testing.assert_array_equal(distributed.posterior["a"].values, serial.posterior["a"].values)
