"""Tasks (stacks of wavelengths) and how they are run: serially or through an executor."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..likelihood import ForwardModel, LogPosterior, Priors, Problem
from .outputs import _wavelength_outputs
from .sampler import _sample_stack
from .settings import InferenceSettings

#: Look-up tables per worker process, keyed by (g, n): instrument -> table.
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


def _run_task(task):
    """Sample the wavelengths of one task, one stack in one sampler (runs in a worker process)."""
    tables = _WORKER_TABLES.setdefault((task.g, task.problem.n), {})
    model = ForwardModel(task.problem, g=task.g, tables=tables)
    singles = [LogPosterior(model, index, task.priors, g=task.g, eps=task.eps) for index in task.indices]
    stacked = LogPosterior(model, list(task.indices), task.priors, g=task.g, eps=task.eps)
    runs = _sample_stack(stacked, singles, task.starts, task.settings, list(task.seeds))
    return [_wavelength_outputs(single, run, task.settings) for single, run in zip(singles, runs)]


def _map_tasks(tasks, executor, progress):
    """Results of every task in order, through ``executor`` (None: serial)."""
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
            futures = [executor.submit(_run_task, task) for task in tasks]
            for task, future in zip(tasks, futures):
                results.append(future.result())
                if bar is not None:
                    bar.update(len(task.indices))
    finally:
        if bar is not None:
            bar.close()
    return results
