"""Regenerate the example measurement files in this folder: ``python examples/data/generate.py``.

Every file is simulated by bayespig (exact solver, the paper's noise eq. 7 with
eps = 0.05, seed 0) for one made-up red pigment, then rounded to 4 significant
digits so that the files stay short enough to read and edit by hand. The truth
(``a``, ``tau``) is in each file's metadata.
"""

from pathlib import Path

import numpy as np

from bayespig.data import Measurement, MeasurementSet, Sample, simulate
from bayespig.data.errors import atomic_write_text

HERE = Path(__file__).resolve().parent
WAVELENGTHS = np.arange(400.0, 701.0, 50.0)
#: A red pigment: strong absorption in the blue, weak in the red [-].
A = np.round(0.01 + 0.4 / (1 + np.exp((WAVELENGTHS - 580.0) / 20.0)), 4)
#: Optical thickness of the thin drawdown [-].
TAU = np.round(1.2 - 0.4 * (WAVELENGTHS - 400.0) / 300.0, 4)
SIGNIFICANT_DIGITS = 4


def rounded(ms, percent=False):
    """The same set with values rounded for hand-readable files."""

    def cut(values):
        scale = 100.0 if percent else 1.0
        return np.array([float(f"{v * scale:.{SIGNIFICANT_DIGITS}g}") / scale for v in values])

    samples = [
        Sample(
            s.name,
            s.role,
            tuple(
                Measurement(
                    m.kind, m.label, m.theta_i, m.theta_o, m.delta_phi, m.specular, cut(m.values)
                )
                for m in s.measurements
            ),
            s.substrate,
            s.film_group,
            s.opaque,
            s.thickness_um,
            s.concentration,
            s.eps,
        )
        for s in ms.samples
    ]
    return MeasurementSet(ms.wavelength_nm, samples, n=ms.n, metadata=dict(ms.metadata))


def main():
    common = dict(a=A, tau=TAU, wavelengths=WAVELENGTHS, eps=0.05, seed=0)
    rounded(simulate(design="method4", **common)).to_csv(HERE / "method4-black-white.csv")
    rounded(simulate(design="method1", **common)).to_csv(HERE / "method1-opaque-and-glass.csv")
    on_black = rounded(simulate(design="method3", **common))
    on_black.to_astm_e1392(HERE / "on-black.astm")

    # the same film drawn down over measured cards, read by an 8°/d sphere (SCE), in percent
    cards = simulate(
        design=[
            dict(name="over_black", substrate=0.08, film_group="drawdown", measure_substrate=True),
            dict(name="over_white", substrate=0.9, film_group="drawdown", measure_substrate=True),
        ],
        instrument="8d-sce",
        **common,
    )
    cards = rounded(cards, percent=True)
    lines = [
        "# units: percent",
        "# instrument: 8d-sce",
        "sample,role,substrate,film_group,measurement,geometry,"
        + ",".join(f"{w:g}" for w in WAVELENGTHS),
    ]
    for s in cards.samples:
        for m in s.measurements:
            values = ",".join(f"{v * 100:.{SIGNIFICANT_DIGITS}g}" for v in m.values)
            lines.append(
                f"{s.name},{s.role},{s.substrate or ''},{s.film_group or ''},"
                f"{m.kind},{m.label},{values}"
            )
    atomic_write_text(HERE / "measured-cards-percent.csv", "\n".join(lines) + "\n")

    # the same four spectra as a Revigo-style wide table (Name + wavelengths, percent, tabs)
    names = {
        "over_black_substrate": "R1_b",
        "over_white_substrate": "R1_w",
        "over_black": "R1_ob",
        "over_white": "R1_ow",
    }
    table = ["Name\t" + "\t".join(f"{w:g}" for w in WAVELENGTHS)]
    for s in sorted(cards.samples, key=lambda s: names[s.name]):
        table.append(
            names[s.name]
            + "\t"
            + "\t".join(f"{v * 100:.{SIGNIFICANT_DIGITS}g}" for v in s.measurements[0].values)
        )
    atomic_write_text(HERE / "wide-table-percent.txt", "\n".join(table) + "\n")


if __name__ == "__main__":
    main()
