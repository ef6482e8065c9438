"""A real paint: Revigo film 01B (eosin lake tinted with zinc white, 10:90) over black and white cards.

Run from the repository root:  python examples/revigo_report.py [FILM_ID] [OUT_DIR] [EPS|infer]

The Revigo data (Geldof et al. 2018, CC0) are read from ``../shared/data/revigo`` next to the
repository -- never copied into it. Each film id has four 8 deg/d sphere spectra: the bare black
and white cards (``_b``, ``_w``) and the paint drawn down over them (``_ob``, ``_ow``), so the
black/white path applies (method 4: one ``a`` and one ``tau`` per wavelength must explain both
films, with each card's albedo seen from the binder derived from its own measurement, eq. 9).
Whether the sphere included the specular reflection is not stated; SCE is assumed
(``bayespig.data.read_revigo``). Takes a minute or two on 2 cores (31 wavelengths).
"""

import sys
from pathlib import Path

import bayespig
from bayespig.inference import infer
from bayespig.report import write_report

REVIGO = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "revigo"
film = sys.argv[1] if len(sys.argv) > 1 else "01B"
out_dir = sys.argv[2] if len(sys.argv) > 2 else f"revigo-{film}-report"

if not REVIGO.is_dir():
    sys.exit(f"the Revigo data are not at {REVIGO} (see ../shared/data/revigo/README.md)")

measurements = bayespig.read_measurements(REVIGO, film=film)
print(measurements.summary())
print("composition:", dict(measurements.metadata).get("composition"))

# The relative error of a sphere spectrophotometer is about 1 %; the model (a smooth binder surface,
# Lambertian cards) is rougher than that, so the paper's 5 % (the default) is used. Pass
# eps="infer" to make it a parameter per wavelength instead.
eps = sys.argv[3] if len(sys.argv) > 3 else None
idata = infer(measurements, method="method4", eps=eps if eps in (None, "infer") else float(eps), seed=0)
result = write_report(idata, out_dir, measurements=measurements,
                      title=f"Revigo film {film} (black/white drawdowns, 8/d sphere)")
print(f"wrote {result.files['html']}")
flags = [f for f in result.summary["diagnostics"]["flags"] if f["wavelength_nm"] is not None]
print(f"{len(flags)} wavelength(s) flagged; colour spread (Delta E00, 95 %):",
      round(result.summary["colour"]["max_dE00_spread_measured"], 2))
