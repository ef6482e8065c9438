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

import ctypes
import ctypes.util
import os
import signal
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..likelihood import ForwardModel, LogPosterior, Priors, Problem
from .outputs import _wavelength_outputs
from .sampler import _sample_stack
from .settings import InferenceSettings

#: Seconds between the checks of a worker's fallback thread that its parent is alive.
PARENT_POLL_S = 0.5
#: Seconds to wait for terminated workers to exit.
TERMINATE_WAIT_S = 5.0
#: ``prctl`` option: the signal the kernel sends when the parent thread exits (linux/prctl.h).
PR_SET_PDEATHSIG = 1

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
    noise_floor: float | str | None = None  # additive floor: None, known, or "infer"


def _run_task(task):
    """Sample the wavelengths of one task, one stack in one sampler (runs in a worker process)."""
    tables = _WORKER_TABLES.setdefault((task.g, task.problem.n), {})
    model = ForwardModel(task.problem, g=task.g, tables=tables)
    singles = [LogPosterior(model, index, task.priors, g=task.g, eps=task.eps, noise_floor=task.noise_floor)
               for index in task.indices]
    stacked = LogPosterior(model, list(task.indices), task.priors, g=task.g, eps=task.eps,
                           noise_floor=task.noise_floor)
    runs = _sample_stack(stacked, singles, task.starts, task.settings, list(task.seeds))
    return [_wavelength_outputs(single, run, task.settings) for single, run in zip(singles, runs)]


def _parent_alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else (the pid was reused): gone for us
        return False
    return True


def _watch_parent(creator, parent):
    """Worker thread: exit the worker when its parent or the pool's creator is gone."""
    while True:
        time.sleep(PARENT_POLL_S)
        if os.getppid() != parent or not _parent_alive(creator):
            os._exit(1)


def _die_with_parent(creator):
    """Arrange for this worker to end when ``creator`` (the process that made the pool) ends.

    Linux: the kernel sends SIGKILL when the parent exits (``PR_SET_PDEATHSIG``; the parent is
    the creator, or the forkserver that ends with it). Everywhere: a daemon thread polls
    :func:`os.getppid` and the creator every :data:`PARENT_POLL_S` s and ends the worker with
    :func:`os._exit`. A creator already gone before either was set up ends the worker at once.
    """
    parent = os.getppid()
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
            libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):  # no libc / no prctl: the thread below still works
            pass
    if not _parent_alive(creator) or os.getppid() != parent:
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(creator, parent), name="bayespig-parent-watch",
                     daemon=True).start()


def _initialize_worker(creator):
    """Initializer of the local pool's workers: ignore Ctrl-C, die with the parent."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent(creator)


def local_pool(max_workers):
    """A :class:`~concurrent.futures.ProcessPoolExecutor` whose workers ignore SIGINT and die
    with this process (see the module docstring); stop it with :func:`stop_pool` on errors."""
    return ProcessPoolExecutor(max_workers=max_workers, initializer=_initialize_worker,
                               initargs=(os.getpid(),))


def stop_pool(pool):
    """Cancel the pending tasks of a local pool and terminate its workers (no waiting for them).

    SIGINT is ignored meanwhile (in the main thread), so that a second Ctrl-C does not interrupt
    the clean-up.
    """
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    try:
        # ProcessPoolExecutor has no public way to end its workers before Python 3.14
        processes = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            if process.is_alive():
                process.terminate()
        deadline = time.monotonic() + TERMINATE_WAIT_S
        for process in processes:
            process.join(max(0.0, deadline - time.monotonic()))
            if process.is_alive():
                process.kill()
    finally:
        if main:
            signal.signal(signal.SIGINT, previous)


def run_tasks(tasks, executor, progress, max_workers=2):
    """Results of every task in order: serially (``executor`` None and one task), in a local
    pool of ``max_workers`` processes (None and several tasks), or through ``executor``.

    On any exception (KeyboardInterrupt included) the pending tasks are cancelled, a local
    pool's workers terminated, and the exception re-raised.
    """
    if executor is not None or len(tasks) <= 1:
        return _map_tasks(tasks, executor, progress)
    pool = local_pool(min(max_workers, len(tasks), os.cpu_count() or 1))
    try:
        results = _map_tasks(tasks, pool, progress)
    except BaseException:
        stop_pool(pool)
        raise
    pool.shutdown()
    return results


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
