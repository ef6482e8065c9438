"""Tasks (stacks of wavelengths) and how they are run: serially, a local pool, or an executor.

The local pool (:func:`local_pool`, the default of :func:`bayespig.infer` for more than one
stack) is tied to the process that made it: its workers ignore Ctrl-C (SIGINT reaches the whole
process group; the parent handles it) and die with their parent even when it is killed outright
(``kill -9``): on Linux by ``prctl(PR_SET_PDEATHSIG, SIGKILL)``, everywhere by a daemon thread
in the worker that exits when its parent is gone. On an interrupt (KeyboardInterrupt) or any
other error while tasks run, the pending tasks are cancelled, the local pool's workers are
terminated and the exception is re-raised once (:func:`run_tasks`). The workers of an executor
given by the caller are the caller's: its pending futures are cancelled, nothing else.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from .._pool import executor_or_local_pool
from ..likelihood import ForwardModel, LogPosterior, Priors, Problem
from .outputs import _wavelength_outputs
from .sampler import _sample_stack
from .settings import InferenceSettings

#: Look-up tables per worker process, keyed by (g, n, roughness): instrument -> table.
_WORKER_TABLES = {}


@dataclass(frozen=True)
class _Task:
    problem: Problem
    g: str
    eps: float | None
    priors: Priors
    settings: InferenceSettings
    indices: tuple
    starts: np.ndarray  # (len(indices), n_dim)
    seeds: tuple  # SeedSequence per index
    noise_floor: float | str | None = None  # additive floor: None, known, or "infer"
    roughness: float = 0.0  # GGX alpha of the films' surface (0: smooth, the smooth tables)
    censored_zeros: bool = False  # observed zeros as readings censored at 0 (needs a floor)


def _run_task(task):
    """Sample the wavelengths of one task, one stack in one sampler (runs in a worker process)."""
    tables = _WORKER_TABLES.setdefault((task.g, task.problem.n, task.roughness), {})
    model = ForwardModel(task.problem, g=task.g, tables=tables, roughness=task.roughness)
    noise = {"noise_floor": task.noise_floor, "censored_zeros": task.censored_zeros}
    singles = [LogPosterior(model, index, task.priors, g=task.g, eps=task.eps, **noise) for index in task.indices]
    stacked = LogPosterior(model, list(task.indices), task.priors, g=task.g, eps=task.eps, **noise)
    runs = _sample_stack(stacked, singles, task.starts, task.settings, list(task.seeds))
    return [_wavelength_outputs(single, run, task.settings) for single, run in zip(singles, runs)]


def run_tasks(tasks, executor, progress, max_workers=2):
    """Results of every task in order: serially (``executor`` None and one task), in a local
    pool of ``max_workers`` processes (None and several tasks), or through ``executor``.

    On any exception (KeyboardInterrupt included) the pending tasks are cancelled, a local
    pool's workers terminated, and the exception re-raised.
    """
    with executor_or_local_pool(executor, needed=len(tasks) > 1,
                                max_workers=min(max_workers, len(tasks), os.cpu_count() or 1)) as pool:
        return _map_tasks(tasks, pool, progress)


def _map_tasks(tasks, executor, progress):
    """Results of every task in order, through ``executor`` (None: serial); on any exception
    the futures not yet running are cancelled."""
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=sum(len(t.indices) for t in tasks), desc="inference", unit="λ")
    results = []
    try:
        if executor is None:
            for task in tasks:
                results.append(_run_task(task))
                if bar is not None:
                    bar.update(len(task.indices))
        else:
            futures = []
            try:
                for task in tasks:
                    futures.append(executor.submit(_run_task, task))
                for task, future in zip(tasks, futures):
                    results.append(future.result())
                    if bar is not None:
                        bar.update(len(task.indices))
            except BaseException:
                for future in futures:
                    future.cancel()
                raise
    finally:
        if bar is not None:
            bar.close()
    return results
