"""Shared fixtures."""

import pytest


@pytest.fixture(scope="module")
def private_table_cache(tmp_path_factory):
    """A module's look-up tables are built into a temporary cache (the user's cache is untouched).

    Use with ``pytestmark = pytest.mark.usefixtures("private_table_cache")`` or as an argument.
    """
    path = tmp_path_factory.mktemp("table-cache")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("BAYESPIG_CACHE", str(path))
        yield path
