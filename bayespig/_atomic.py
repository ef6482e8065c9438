"""Atomic file output: every file bayespig writes appears whole or not at all.

Every file is written under a temporary name beside its destination and moved into place
with :func:`os.replace` once complete. Temporary names say whose they are::

    .<name>.bayespig-tmp-<host>-<pid>-<random><suffix>      (one file, :func:`atomic_path`)
    .staging.bayespig-tmp-<host>-<pid>-<random>             (a file set, :func:`write_file_set`)
    .<folder>.bayespig-tmp-<host>-<pid>-<random>            (a whole folder, :func:`write_folder_atomically`)

A process that is killed outright (``SIGKILL``, power loss) cannot remove its temporary file,
so at most one such file per interrupted write is left behind; the next atomic write into the
same folder removes every bayespig temporary whose process (same host, by process id) no
longer runs (:func:`remove_stale_temporaries`). Temporaries of running processes and of other
hosts (a shared folder) are left alone.
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import tempfile
from contextlib import contextmanager
from pathlib import Path

__all__ = [
    "atomic_path",
    "remove_stale_temporaries",
    "write_file_set",
    "write_folder_atomically",
    "write_text_atomically",
]

#: Marker in the name of every temporary file or folder written by this module.
TEMPORARY_MARKER = "bayespig-tmp"
_TEMPORARY_NAME = re.compile(rf"^\..*\.{TEMPORARY_MARKER}-(?P<host>[A-Za-z0-9]*)-(?P<pid>[0-9]+)-")


def _host_tag():
    """This machine's name reduced to letters and digits (at most 16), for temporary names."""
    return re.sub(r"[^A-Za-z0-9]", "", socket.gethostname())[:16]


def _temporary_prefix(name):
    """Prefix of a temporary for ``name``: hidden, marked, with this host and process id."""
    return f".{name}.{TEMPORARY_MARKER}-{_host_tag()}-{os.getpid()}-"


def _process_running(pid):
    """Whether a process with this id runs on this machine (``True`` when it cannot be told)."""
    if pid == os.getpid():
        return True
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):  # another user's process, or no signal 0 (Windows)
        return True
    return True


def remove_stale_temporaries(folder):
    """Remove the bayespig temporaries in ``folder`` whose writing process no longer runs.

    Only names of the form written by this module are considered (see the module notes); a
    temporary of a running process or of another host is kept. Errors (a file that vanishes
    meanwhile, a folder that cannot be listed) are ignored: cleaning is a courtesy.

    Parameters
    ----------
    folder : str or os.PathLike
        The folder to clean (not recursed into).

    Returns
    -------
    list of pathlib.Path
        The temporaries removed.
    """
    removed = []
    host = _host_tag()
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        match = _TEMPORARY_NAME.match(entry.name)
        if match is None or match["host"] != host or _process_running(int(match["pid"])):
            continue
        try:
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            else:
                os.unlink(entry.path)
        except OSError:
            continue
        removed.append(Path(entry.path))
    return removed


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
    remove_stale_temporaries(path.parent)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=_temporary_prefix(path.name), suffix=suffix)
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
    ``out_dir`` keeps what it had. Stale temporaries of killed processes in ``out_dir`` are
    removed first (:func:`remove_stale_temporaries`).

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
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(out_dir)
    staging = Path(tempfile.mkdtemp(prefix=_temporary_prefix("staging"), dir=out_dir))
    try:
        _write_contents(staging, files)
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


def _write_contents(folder, files):
    """Write ``files`` (relative path -> bytes, UTF-8 text or a callable writing the path it is
    given) below ``folder``, creating subfolders."""
    for relative, content in files.items():
        target = Path(folder) / relative
        target.parent.mkdir(parents=True, exist_ok=True)
        if callable(content):
            content(target)
        elif isinstance(content, bytes):
            target.write_bytes(content)
        else:
            target.write_text(content, encoding="utf-8")


def _swap_into_place(staging, out_dir):
    """Move the complete folder ``staging`` to ``out_dir``, replacing what is there whole.

    Two renames in the same parent folder; if the second fails the old folder is put back.
    """
    if not (out_dir.exists() or out_dir.is_symlink()):
        os.rename(staging, out_dir)
        return
    old = Path(tempfile.mkdtemp(prefix=_temporary_prefix(out_dir.name), suffix=".old", dir=out_dir.parent))
    os.rmdir(old)
    os.rename(out_dir, old)
    try:
        os.rename(staging, out_dir)
    except BaseException:
        os.rename(old, out_dir)
        raise
    if old.is_symlink() or not old.is_dir():
        old.unlink()
    else:
        shutil.rmtree(old, ignore_errors=True)


def write_folder_atomically(out_dir, files):
    """Write a whole folder: ``out_dir`` ends up holding exactly ``files``, or is left as it was.

    The files are written into a hidden temporary folder beside ``out_dir`` (named as the module
    docstring says, so a killed run's leftover is removed by the next write), which then
    replaces ``out_dir`` whole: nothing of an earlier content (stale figures) survives.

    Parameters
    ----------
    out_dir : str or os.PathLike
        The folder to write (its parent is created if missing).
    files : dict
        Relative path -> content, as for :func:`write_file_set`.

    Returns
    -------
    pathlib.Path
        ``out_dir``.
    """
    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(out_dir.parent)
    staging = Path(tempfile.mkdtemp(prefix=_temporary_prefix(out_dir.name), suffix=".tmp", dir=out_dir.parent))
    try:
        _write_contents(staging, files)
        for folder in [staging, *(p for p in staging.rglob("*") if p.is_dir())]:
            os.chmod(folder, 0o777 & ~_umask())
        _swap_into_place(staging, out_dir)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return out_dir
