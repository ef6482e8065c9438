"""Atomic outputs: recognisable temporaries, and stale ones of killed processes cleaned up."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bayespig._atomic import (
    TEMPORARY_MARKER,
    _host_tag,
    atomic_path,
    remove_stale_temporaries,
    write_file_set,
    write_folder_atomically,
    write_text_atomically,
)

#: Seconds allowed for a child Python process to start writing (generous: 2 shared cores).
CHILD_START_TIMEOUT = 60.0


def _dead_pid():
    """The id of a process that has exited (reaped), so nothing runs under it now."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def _temporary_name(name, pid, host=None, suffix=".tmp"):
    return f".{name}.{TEMPORARY_MARKER}-{_host_tag() if host is None else host}-{pid}-abc123{suffix}"


def test_temporary_name_says_whose_it_is(tmp_path):
    with atomic_path(tmp_path / "posterior.nc", suffix=".nc") as tmp:
        assert tmp.parent == tmp_path
        assert tmp.name.startswith(f".posterior.nc.{TEMPORARY_MARKER}-{_host_tag()}-{os.getpid()}-")
        assert tmp.name.endswith(".nc")
        tmp.write_bytes(b"x")
    assert [p.name for p in tmp_path.iterdir()] == ["posterior.nc"]


def test_next_write_removes_temporaries_of_dead_processes_only(tmp_path):
    dead = _dead_pid()
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    try:
        stale_file = tmp_path / _temporary_name("posterior.nc", dead, suffix=".nc")
        stale_file.write_bytes(b"half a posterior")
        stale_dir = tmp_path / f".staging.{TEMPORARY_MARKER}-{_host_tag()}-{dead}-xyz"
        (stale_dir / "figures").mkdir(parents=True)
        (stale_dir / "figures" / "fit.png").write_bytes(b"png")
        live = tmp_path / _temporary_name("summary.csv", sleeper.pid)
        live.write_text("being written")
        other_host = tmp_path / _temporary_name("summary.csv", dead, host="someotherhost")
        other_host.write_text("written on another machine")
        foreign = tmp_path / ".posterior.nc.k3j2_x.nc"  # not ours: an unknown hidden file
        foreign.write_text("user file")

        write_text_atomically(tmp_path / "report.md", "# report\n")

        assert not stale_file.exists()
        assert not stale_dir.exists()
        assert live.exists(), "a running process's temporary was removed"
        assert other_host.exists(), "another host's temporary was removed"
        assert foreign.exists()
        assert (tmp_path / "report.md").read_text() == "# report\n"
    finally:
        sleeper.kill()
        sleeper.wait()


def test_write_file_set_cleans_too(tmp_path):
    stale = tmp_path / _temporary_name("report.html", _dead_pid())
    stale.write_text("partial")
    write_file_set(tmp_path, {"a.txt": "a", "b/c.txt": "c"})
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == ["a.txt", "b", "b/c.txt"]


def test_write_folder_replaces_the_folder_whole_and_cleans_a_killed_runs_staging(tmp_path):
    out = tmp_path / "report"
    (out / "figures").mkdir(parents=True)
    (out / "figures" / "stale.png").write_bytes(b"old")
    killed = tmp_path / _temporary_name("report", _dead_pid())
    (killed / "figures").mkdir(parents=True)  # a staging folder left by SIGKILL
    write_folder_atomically(out, {"report.md": "new", "figures/fit.png": b"png"})
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == [
        "report", "report/figures", "report/figures/fit.png", "report/report.md"]


def test_write_folder_leaves_the_old_folder_on_an_error(tmp_path):
    out = tmp_path / "report"
    out.mkdir()
    (out / "report.md").write_text("old")

    def fail(path):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_folder_atomically(out, {"report.md": "new", "posterior.nc": fail})
    assert [p.name for p in tmp_path.iterdir()] == ["report"] and (out / "report.md").read_text() == "old"


def test_remove_stale_temporaries_reports_what_it_removed(tmp_path):
    stale = tmp_path / _temporary_name("table.npz", _dead_pid())
    stale.write_bytes(b"")
    assert remove_stale_temporaries(tmp_path) == [stale]
    assert remove_stale_temporaries(tmp_path / "missing") == []


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_sigkill_while_writing_leaves_one_temporary_that_the_next_write_removes(tmp_path):
    target = tmp_path / "posterior.nc"
    script = (
        "import sys, time\n"
        "from bayespig._atomic import atomic_path\n"
        "with atomic_path(sys.argv[1], suffix='.nc') as tmp:\n"
        "    tmp.write_bytes(b'partial')\n"
        "    print('writing', flush=True)\n"
        "    time.sleep(120)\n"
    )
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    child = subprocess.Popen([sys.executable, "-c", script, str(target)], stdout=subprocess.PIPE, env=env)
    try:
        start = time.monotonic()
        assert child.stdout.readline() == b"writing\n", "the child did not start writing"
        assert time.monotonic() - start < CHILD_START_TIMEOUT
        child.send_signal(signal.SIGKILL)
        child.wait()
    finally:
        child.kill()
        child.wait()
        child.stdout.close()
    left = [p.name for p in tmp_path.iterdir()]
    assert len(left) == 1 and left[0].startswith(f".posterior.nc.{TEMPORARY_MARKER}-"), left
    assert not target.exists()

    with atomic_path(target, suffix=".nc") as tmp:
        tmp.write_bytes(b"complete")
    assert [p.name for p in tmp_path.iterdir()] == ["posterior.nc"]
    assert target.read_bytes() == b"complete"
