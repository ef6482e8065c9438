"""Benchmark: one recipe predicted with 200 draws, and one match, from a pigment library.

Run from the repository root (prints only; a few seconds)::

    python benchmarks/predict_match.py

The library is made by hand (three pigments with known constants, 400 draws with a 5 % spread
over 31 bands, radiative-transfer film model) so that the benchmark needs no build; the times are
those of :func:`bayespig.predict_paint` and :func:`bayespig.match_paint` (issue 17's goals:
<= 0.5 s and <= 5 s). Best of 5 for the prediction (the first call, which loads the 8d-sce table,
is printed apart).
"""

import time

import numpy as np

from bayespig import match_paint, predict_paint
from bayespig.library.library import PigmentLibrary


def library(n=400, seed=0):
    wl = np.arange(400.0, 701.0, 10.0)
    rng = np.random.default_rng(seed)
    a = [np.full(31, 0.002), 0.02 + 0.5 / (1 + np.exp(-(wl - 560) / 20)), np.full(31, 0.6)]
    sigma = [1.0, 3.0, 2.0]
    c = np.zeros((n, 31, 3, 2))
    for j in range(3):
        c[:, :, j, 0] = np.clip(a[j] * (1 + 0.05 * rng.standard_normal((n, 1))), 0, 1)
        c[:, :, j, 1] = np.log(sigma[j]) + 0.05 * rng.standard_normal((n, 1))
    return PigmentLibrary(model="radiative-transfer", pigments=("ZincWhite", "PrussianBlue", "BoneBlack"),
                          wavelength_nm=wl, constants=c, constant_names=("a", "log_sigma"),
                          thickness_prior=(np.log(2.0), 0.3), films=(), film_ids=(), thickness=np.zeros((n, 0)),
                          densities=None, model_error=None, provenance={}, stages=())


def main():
    lib = library()
    recipe = {"ZincWhite": 70, "PrussianBlue": 25, "BoneBlack": 5}
    t = time.perf_counter()
    predict_paint(lib, recipe, thickness="opaque", instrument="8d-sce", n_draws=200)
    print(f"predict_paint, 200 draws, first call (table load): {time.perf_counter() - t:.3f} s")
    for thickness, card in (("opaque", None), (2.0, np.full(31, 0.05))):
        times = []
        for _ in range(5):
            t = time.perf_counter()
            p = predict_paint(lib, recipe, thickness=thickness, instrument="8d-sce", substrate=card, n_draws=200)
            times.append(time.perf_counter() - t)
        print(f"predict_paint, 200 draws, thickness {thickness}: best {min(times):.3f} s")
    target = p.reflectance_median
    for kwargs in ({"pigments": ("ZincWhite", "PrussianBlue")}, {}, {"thickness": "fit", "substrate": np.full(31, 0.05)}):
        t = time.perf_counter()
        m = match_paint(lib, target, instrument="8d-sce", **kwargs)
        print(f"match_paint {kwargs.get('pigments', 'all 3 pigments')}, thickness {kwargs.get('thickness', 'opaque')}: "
              f"{time.perf_counter() - t:.2f} s, ΔE00 {m.delta_E:.3f}, 16 spread draws")


if __name__ == "__main__":
    main()
