"""Time and peak memory of the three readers against the number of rows (linear, not quadratic).

Usage:  python benchmarks/readers.py [ROWS ...]   (default 2000 4000 8000 16000 64000)

Writes synthetic files to a temporary folder: a bayespig CSV (two BRDF geometries per film,
films over black), an ASTM E1392 file (one sample, one row per geometry) and a wide spectral
table (Revigo layout, four spectra per film), all at 31 wavelengths, and reads each in a fresh
process ("check": ``bayespig check``'s report of the CSV file, summary included)
(``bayespig.data`` readers, progress off), printing wall and CPU seconds and the
process's peak resident memory. Doubling the rows should double the time and the memory above
the interpreter's ~85 MB.
"""

import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine_line

WAVELENGTHS = list(range(400, 701, 10))


def write_csv(path, rows):
    lines = ["# units: fraction", "sample,role,substrate,film_group,opaque,measurement,geometry,"
             + ",".join(map(str, WAVELENGTHS))]
    values = ",".join(f"0.0{k % 9 + 1}" for k in range(len(WAVELENGTHS)))
    for r in range(rows):
        lines.append(f"f{r // 2},film,black,,no,brdf,{'45as15' if r % 2 else '45as45'},{values}")
    path.write_text("\n".join(lines) + "\n")


def write_astm(path, rows):
    import math
    lines = ["#FORMAT=ASTM-E1392-96", "NAME film", "SUBSTRATE black", f"NUM_POINTS {rows}",
             "VARS theta_i,phi_i,theta_s,phi_s," + ",".join(f"{w}nm" for w in WAVELENGTHS)]
    values = ",".join(f"0.0{k % 9 + 1}" for k in range(len(WAVELENGTHS)))
    for r in range(rows):  # distinct geometries from 10 to 40 deg (the mirror is at 45)
        theta_s = math.radians(10.0 + 30.0 * r / rows)
        lines.append(f"{math.radians(45.0)},0,{theta_s},{math.pi},{values}")
    path.write_text("\n".join(lines) + "\n")


def write_table(path, rows):
    lines = ["Name\t" + "\t".join(map(str, WAVELENGTHS))]
    level = {"b": 5.0, "w": 80.0, "ob": 20.0, "ow": 40.0}
    for r in range(rows):
        suffix = ("b", "w", "ob", "ow")[r % 4]
        lines.append(f"F{r // 4}_{suffix}\t" + "\t".join(f"{level[suffix]:.2f}" for _ in WAVELENGTHS))
    path.write_text("\n".join(lines) + "\n")


READ = {
    "csv": "from bayespig.data import read_csv as r; r(p, progress=False)",
    "astm": "from bayespig.data import read_astm_e1392 as r; r(p, progress=False)",
    "table": "from bayespig.data import read_revigo as r; r(p, progress=False)",
    "check": "from bayespig.data import check_report as r; r(p)",
}
WRITE = {"csv": write_csv, "astm": write_astm, "table": write_table, "check": write_csv}
SUFFIX = {"csv": ".csv", "astm": ".astm", "table": ".txt", "check": ".csv"}


def measure(kind, path):
    """(wall seconds, CPU seconds, peak resident memory [MB]) of reading ``path`` in a fresh
    interpreter (CPU time is the robust figure on a shared machine)."""
    code = ("import resource, sys, time\nimport bayespig.data\np = sys.argv[1]\n"
            "t, c = time.perf_counter(), time.process_time()\n"
            f"{READ[kind]}\n"
            "print(time.perf_counter() - t, time.process_time() - c, "
            "resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)")
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, check=True)
    return tuple(map(float, out.stdout.split()))


def main(counts):
    print(machine_line())
    print(f"{'reader':6} {'rows':>7} {'MB file':>8} {'wall s':>8} {'CPU s':>8} {'peak MB':>8}")
    with tempfile.TemporaryDirectory() as folder:
        for kind in WRITE:
            for rows in counts:
                path = Path(folder) / f"{kind}-{rows}{SUFFIX[kind]}"
                WRITE[kind](path, rows)
                wall, cpu, peak = measure(kind, path)
                print(f"{kind:6} {rows:7d} {path.stat().st_size / 2**20:8.1f} {wall:8.2f} {cpu:8.2f} "
                      f"{peak:8.0f}", flush=True)
                path.unlink()


if __name__ == "__main__":
    started = time.perf_counter()
    main([int(x) for x in sys.argv[1:]] or [2000, 4000, 8000, 16000, 64000])
    print(f"total {time.perf_counter() - started:.0f} s")
