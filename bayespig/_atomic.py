"""Atomic file output: every file bayespig writes appears whole or not at all."""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

__all__ = ["atomic_path", "write_file_set", "write_text_atomically"]


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


def write_file_set(out_dir, files):
    """Write several files so that none of them appears unless all of them could be written.

    Every file is first written into a temporary folder inside ``out_dir``; only when all
    exist are they moved into place with :func:`os.replace`, in the order given (put the
    pages that link the others last). On any error the temporary folder is removed and
    ``out_dir`` keeps what it had.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Destination folder (created if missing).
    files : dict
        Relative path -> content: ``bytes``, ``str`` (written as UTF-8) or a callable that
        writes the file at the path it is given (e.g. a netCDF writer).

    Returns
    -------
    dict
        Relative path -> final :class:`pathlib.Path`, in the order of ``files``.
    """
    import shutil

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".staging-", dir=out_dir))
    try:
        for relative, content in files.items():
            target = staging / relative
            target.parent.mkdir(parents=True, exist_ok=True)
            if callable(content):
                content(target)
            elif isinstance(content, bytes):
                target.write_bytes(content)
            else:
                target.write_text(content, encoding="utf-8")
        written = {}
        for relative in files:
            final = out_dir / relative
            final.parent.mkdir(parents=True, exist_ok=True)
            os.chmod(staging / relative, 0o666 & ~_umask())
            os.replace(staging / relative, final)
            written[relative] = final
        return written
    finally:
        shutil.rmtree(staging, ignore_errors=True)
