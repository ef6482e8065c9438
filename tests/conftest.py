"""Shared fixtures."""

import os
import signal

import pytest


@pytest.fixture(scope="session", autouse=True)
def ctrl_c_as_in_a_terminal():
    """Ctrl-C raises KeyboardInterrupt in every test process, and children start with SIGINT's default.

    A shell without job control starts background commands (``pytest &``) with SIGINT ignored,
    and a process inherits that through ``exec``: the tests of Ctrl-C would fail, their interrupt
    never arriving.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield


@pytest.fixture(scope="session")
def run_table_cache(tmp_path_factory):
    """One temporary table cache for the whole test run (all xdist workers: their base folders share
    a parent), so a table two modules need is built once (the cache's writes are atomic, so two
    workers building one table at once is safe: one file wins, both are whole)."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    path = root / "table-cache"
    path.mkdir(exist_ok=True)
    return path


@pytest.fixture(scope="module")
def private_table_cache(run_table_cache):
    """A module's look-up tables are built into (or read from) the test run's temporary cache, never
    the user's: ``BAYESPIG_CACHE`` points there while the module runs.

    Use with ``pytestmark = pytest.mark.usefixtures("private_table_cache")`` or as an argument.
    """
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("BAYESPIG_CACHE", str(run_table_cache))
        yield run_table_cache
