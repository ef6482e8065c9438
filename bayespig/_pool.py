"""Local process pools tied to the process that made them.

Their workers ignore Ctrl-C (SIGINT reaches the whole process group; the parent handles it) and
die with their parent even when it is killed outright (``kill -9``): on Linux by
``prctl(PR_SET_PDEATHSIG, SIGKILL)``, everywhere by a daemon thread in the worker that exits
when its parent is gone. :func:`stop_pool` cancels the pending tasks and terminates the workers
(after an interrupt or an error). Every local pool of bayespig (inference, table builds,
studies) is made by :func:`local_pool`.
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
from contextlib import contextmanager

__all__ = ["executor_or_local_pool", "local_pool", "stop_pool"]

#: Seconds between the checks of a worker's fallback thread that its parent is alive.
PARENT_POLL_S = 0.5
#: Seconds to wait for terminated workers to exit.
TERMINATE_WAIT_S = 5.0
#: ``prctl`` option: the signal the kernel sends when the parent thread exits (linux/prctl.h).
PR_SET_PDEATHSIG = 1

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


def local_pool(max_workers=None):
    """A :class:`~concurrent.futures.ProcessPoolExecutor` whose workers ignore SIGINT and die
    with this process (see the module docstring); stop it with :func:`stop_pool` on errors.

    Parameters
    ----------
    max_workers : int, optional
        Worker processes; default ``min(2, os.cpu_count())``.
    """
    if max_workers is None:
        max_workers = min(2, os.cpu_count() or 1)
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


@contextmanager
def executor_or_local_pool(executor, *, needed=True, max_workers=None):
    """The caller's ``executor``, or for the block a :func:`local_pool` (when ``needed``).

    The local pool is shut down when the block ends, and on any exception (an error or Ctrl-C)
    stopped at once by :func:`stop_pool` before the exception goes on; the caller's executor is
    the caller's to manage. ``needed=False`` (e.g. one task only) yields None: run in-process.
    """
    if executor is not None or not needed:
        yield executor
        return
    pool = local_pool(max_workers)
    try:
        yield pool
    except BaseException:
        stop_pool(pool)
        raise
    pool.shutdown(cancel_futures=True)
