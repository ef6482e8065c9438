"""Shared by the benchmark scripts: load average and the sections of reports/benchmarks.md."""

import os

from bayespig._atomic import write_text_atomically


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
