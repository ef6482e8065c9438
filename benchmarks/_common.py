"""Shared by the benchmark scripts: load average and the sections of reports/benchmarks.md."""

import os
import time
from pathlib import Path

from bayespig._atomic import write_text_atomically

#: The Markdown file every benchmark writes its section of.
REPORT = Path(__file__).resolve().parent.parent / "reports" / "benchmarks.md"


class Transcript:
    """``say(text)``: print a line of a benchmark's output and keep it (``.lines``) for its
    section of the report."""

    def __init__(self, *lines):
        self.lines = list(lines)
        for line in lines:
            print(line, flush=True)

    def __call__(self, text=""):
        print(text, flush=True)
        self.lines.append(text)


def machine_line():
    """bayespig's and Python's versions, the cores and the load average, for a run's first line."""
    import sys

    import bayespig

    return (f"bayespig {bayespig.__version__}, python {sys.version.split()[0]}, {os.cpu_count()} cores, "
            f"load average {load_average()}")


def load_average():
    """The 1, 5 and 15 minute load averages as text (the machine may be shared)."""
    return "n/a" if not hasattr(os, "getloadavg") else " ".join(f"{x:.2f}" for x in os.getloadavg())


def replace_section(path, heading, body):
    """Replace (or append) the section starting at ``heading`` in a Markdown file, atomically."""
    text = path.read_text(encoding="utf-8") if path.exists() else "# Benchmarks\n"
    start = text.find(heading + "\n")
    if start < 0:
        text = text.rstrip("\n") + "\n\n" + body
    else:
        end = text.find("\n## ", start + len(heading))
        text = text[:start] + body + ("" if end < 0 else text[end + 1:])
    write_text_atomically(path, text if text.endswith("\n") else text + "\n")


def write_run_section(heading, regenerate, description, lines, after=(), path=REPORT):
    """Replace ``heading``'s section with the standard layout of a benchmark run.

    Parameters
    ----------
    heading : str
        Markdown heading, e.g. ``"## Inference"``.
    regenerate : str
        The command line that regenerates the section.
    description : sequence of str
        Lines saying what was measured.
    lines : sequence of str
        The printed output of the run (put in a code block, under the run's UTC time).
    after : sequence of str
        Lines after the output (goal tables, figures).
    """
    body = [heading, "", f"Regenerate with `{regenerate}` from the repository root.", *description, "",
            f"Run of {time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC:", "", "```", *lines, "```", "",
            *after]
    replace_section(path, heading, "\n".join(body).rstrip("\n") + "\n")
    print(f"updated {path}")
