"""Atomic file output: every file bayespig writes appears whole or not at all."""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

__all__ = ["atomic_path", "write_text_atomically"]


def _umask():
    """The process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextmanager
def atomic_path(path, *, suffix=".tmp"):
    """A temporary file beside ``path`` that replaces ``path`` when the block succeeds.

    The block writes to the yielded path (by any library: ``savefig``, ``to_netcdf``,
    ``np.savez``...); on success it gets ordinary file permissions (those of an existing
    ``path``, else ``0o666`` less the umask) and is moved onto ``path`` with
    :func:`os.replace`; on any error it is removed and ``path`` is left as it was.

    Parameters
    ----------
    path : str or os.PathLike
        Final location; its folder is created if missing.
    suffix : str
        Suffix of the temporary file (some writers choose the format from it).

    Yields
    ------
    pathlib.Path
        The temporary file to write.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        mode = path.stat().st_mode & 0o777 if path.exists() else 0o666 & ~_umask()
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text_atomically(path, text):
    """Write ``text`` (UTF-8, newlines as given) to ``path`` through :func:`atomic_path`."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="") as handle:
        handle.write(text)
    return path
