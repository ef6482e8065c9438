"""Executors: the samples do not depend on how the tasks run; the local pool's workers end
with their parent (kill -9, Ctrl-C)."""

import hashlib
import os
import signal
import subprocess
import sys
import textwrap
import time
from concurrent.futures import Future, ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest

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


def test_same_seed_identical_in_another_process(method4_set, method4_idata):
    """A seeded run repeated in a fresh Python process (another hash seed, other addresses) gives
    the same draws bit for bit: nothing of the run depends on the process (the rough tables'
    weights once did, tests/physics/test_rough_surface.py)."""
    code = textwrap.dedent("""
        import hashlib
        from bayespig.inference import infer
        from tests.inference.common import FAST, method4_data
        idata = infer(method4_data(), seed=5, progress=False, settings=FAST, executor=None)
        print(hashlib.sha256(idata.posterior["a"].values.tobytes()).hexdigest())
        """)
    root = Path(__file__).resolve().parents[2]
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=root,
                          env={**os.environ, "PYTHONHASHSEED": "12345"})
    here = hashlib.sha256(method4_idata.posterior["a"].values.tobytes()).hexdigest()
    assert done.stdout.strip() == here


def test_a_seeded_run_leaves_numpys_global_generator_alone():
    """Every draw of a run comes from its seeded Generator: numpy's global stream (which a
    library left to its defaults draws from, e.g. scipy's BarycentricInterpolator) is not used."""
    one = simulate(a=0.05, tau=0.5, design="method4", wavelengths=[450.0], eps=0.05, seed=11)
    np.random.seed(2024)
    before = np.random.get_state()
    infer(one, seed=5, progress=False, settings=FAST, executor=None)
    after = np.random.get_state()
    assert np.array_equal(before[1], after[1]) and before[2:] == after[2:]


def test_dask_executor_gives_the_same_samples(method4_set, method4_idata):
    from dask.distributed import Client, LocalCluster

    one = simulate(a=0.05, tau=0.5, design="method4", wavelengths=[450.0], eps=0.05, seed=11)
    with (LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None)
          as cluster, Client(cluster) as client):
        distributed = infer(one, seed=5, progress=False, settings=FAST, executor=client.get_executor())
    serial = infer(one, seed=5, progress=False, settings=FAST, executor=None)
    np.testing.assert_array_equal(distributed.posterior["a"].values, serial.posterior["a"].values)


# --- the local pool and its workers ----------------------------------------------------------

#: Seconds allowed for the child to start its pool (imports, tables from the disk cache, the
#: point fit): a few seconds on an idle machine, allowed 30x for a loaded one.
POOL_START_S = 120.0
#: Seconds allowed for the workers to end after their parent was killed: the kernel's
#: PR_SET_PDEATHSIG acts at once, the fallback thread within 0.5 s; 10 s is a wide margin.
WORKERS_END_S = 10.0
#: Seconds allowed for the interrupted child to exit (terminate + join of two workers, < 1 s).
INTERRUPT_EXIT_S = 30.0

#: A child that runs infer() on the default local pool (3 stacks of one wavelength, 2 workers)
#: with a run length that never completes, and says "interrupted" once on KeyboardInterrupt.
_CHILD = textwrap.dedent("""
    import sys
    from bayespig import simulate, infer
    from bayespig.inference import InferenceSettings

    ms = simulate(a=0.1, tau=1.0, design="method4", wavelengths=[450.0, 550.0, 650.0], eps=0.05, seed=1)
    endless = InferenceSettings(wavelengths_per_run=1, target_ess=1e9, min_steps=10**6, max_steps=10**7)
    try:
        infer(ms, progress=False, settings=endless)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.exit(130)
""")


def _live_descendants(pid):
    """Pids of the running (not zombie) descendants of ``pid``."""
    try:
        import psutil
    except ImportError:
        psutil = None
    if psutil is not None:
        try:
            children = psutil.Process(pid).children(recursive=True)
        except psutil.NoSuchProcess:
            return []
        return [c.pid for c in children if _running(c.pid)]
    parents = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            parents.setdefault(int(fields[1]), []).append(int(entry))
    found, todo = [], [pid]
    while todo:
        for child in parents.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return [p for p in found if _running(p)]


def _running(pid):
    """Whether ``pid`` exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _start_child_with_workers():
    """The child process (own session, so that a group signal reaches its workers as Ctrl-C
    does) and its workers' pids once both are running."""
    child = subprocess.Popen([sys.executable, "-c", _CHILD], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True, start_new_session=True)
    deadline = time.monotonic() + POOL_START_S
    while time.monotonic() < deadline and child.poll() is None:
        workers = _live_descendants(child.pid)
        if len(workers) >= 2:
            time.sleep(1.0)  # inside their tasks
            return child, _live_descendants(child.pid)
        time.sleep(0.1)
    _, err = _end(child, [])
    pytest.fail(f"the child did not start its 2 workers within {POOL_START_S:g} s:\n{err}")


def _end(child, workers):
    """Clean up whatever is left (only the child and the workers it made)."""
    for pid in [child.pid] + list(workers):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return child.communicate()


def _wait_until_gone(pids, seconds):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and any(_running(p) for p in pids):
        time.sleep(0.05)
    return [p for p in pids if _running(p)]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_local_pool_workers_die_when_the_parent_is_killed():
    """kill -9 of a process running infer() on its own pool: its two workers (issue 18: left
    running with PPID 1, ~220 MB each) end within seconds."""
    child, workers = _start_child_with_workers()
    try:
        assert len(workers) >= 2
        child.kill()
        child.wait()
        assert _wait_until_gone(workers, WORKERS_END_S) == []
    finally:
        _end(child, workers)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_ctrl_c_stops_the_workers_and_raises_once():
    """SIGINT to the process group (what Ctrl-C does): infer() terminates its workers, which
    print nothing, and raises KeyboardInterrupt once; the process exits promptly."""
    child, workers = _start_child_with_workers()
    try:
        started = time.monotonic()
        os.killpg(child.pid, signal.SIGINT)
        try:
            _, err = child.communicate(timeout=INTERRUPT_EXIT_S)
        except subprocess.TimeoutExpired:
            pytest.fail(f"infer() did not return within {INTERRUPT_EXIT_S:g} s of Ctrl-C")
        assert time.monotonic() - started < INTERRUPT_EXIT_S
        assert "Traceback" not in err
        assert err == "interrupted\n"
        assert child.returncode == 130
        assert _wait_until_gone(workers, WORKERS_END_S) == []
    finally:
        _end(child, workers)


class _Interrupting(Future):
    """A future whose result is a Ctrl-C (the caller waiting on it is interrupted)."""

    def result(self, timeout=None):
        raise KeyboardInterrupt


class _CallersExecutor:
    """An executor of the caller's: the first task is interrupted, the others stay pending."""

    def __init__(self):
        self.futures = []

    def submit(self, fn, *args):
        self.futures.append(_Interrupting() if not self.futures else Future())
        return self.futures[-1]


def test_ctrl_c_cancels_the_pending_tasks_of_the_callers_executor(method4_set):
    single = InferenceSettings(**{**FAST.__dict__, "wavelengths_per_run": 1})
    executor = _CallersExecutor()
    with pytest.raises(KeyboardInterrupt):
        infer(method4_set, progress=False, settings=single, executor=executor)
    assert len(executor.futures) == 3
    assert all(future.cancelled() for future in executor.futures[1:])
