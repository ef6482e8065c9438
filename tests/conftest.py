"""Shared fixtures."""

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


@pytest.fixture(scope="module")
def private_table_cache(tmp_path_factory):
    """A module's look-up tables are built into a temporary cache (the user's cache is untouched).

    Use with ``pytestmark = pytest.mark.usefixtures("private_table_cache")`` or as an argument.
    """
    path = tmp_path_factory.mktemp("table-cache")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("BAYESPIG_CACHE", str(path))
        yield path
