"""Speed of the film models (bayespig.library.film_models): one recipe, 200 draws x 31 bands.

Run from the repository root::

    python benchmarks/film_models.py [--revigo FOLDER]   # a few seconds; prints only

Times :meth:`FilmModel.reflectance` (a three-pigment recipe over a card and opaque, for every
instrument of the interface) and :meth:`FilmPredictor.values` (a Revigo film over its two
cards, the call a library's sampler makes) for both models, 200 draws x 31 wavelengths. The
goal (issue 17): one recipe with 200 draws well under 0.1 s for the forward model (the whole
prediction with colour and region <= 0.5 s). Wall-clock minima of repeated calls (the machine
is shared; the load average is printed). Tables are loaded (built on first use) before timing.
"""

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

import bayespig
from bayespig.library.film_models import film_model
from bayespig.studies.revigo import default_revigo_path

N_DRAWS, N_WL, REPEATS = 200, 31, 20
GOAL_S = 0.1
INSTRUMENTS = ("8d-sce", "8d-sci", "45-0")


def best_time(call, repeats=REPEATS):
    call()  # warm-up: tables loaded, caches filled
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return min(times)


def constants_for(model, rng, n_pigments):
    if model.name == "radiative-transfer":
        first = rng.uniform(0.01, 0.9, (N_DRAWS, N_WL, n_pigments))
        second = np.log(rng.uniform(0.3, 30.0, (N_DRAWS, N_WL, n_pigments)))
    else:
        first = np.log(rng.uniform(0.01, 3.0, (N_DRAWS, N_WL, n_pigments)))
        second = np.log(rng.uniform(0.5, 30.0, (N_DRAWS, N_WL, n_pigments)))
    return np.stack([first, second], axis=-1)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--revigo", type=Path, default=default_revigo_path(),
                        help="the Revigo folder (default $BAYESPIG_REVIGO or ../shared/data/revigo)")
    args = parser.parse_args(argv)
    load = " ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "n/a"
    print(f"bayespig {bayespig.__version__}, {os.cpu_count()} cores, load average {load}; "
          f"{N_DRAWS} draws x {N_WL} bands, best of {REPEATS}; goal < {GOAL_S:g} s")
    rng = np.random.default_rng(17)
    D = np.array([0.3, 2.5, 0.05])  # a pigment, a white, a black (relative concentrations)
    h = rng.uniform(0.5, 2.0, N_DRAWS)
    card = np.linspace(0.3, 0.85, N_WL)  # a light card in air
    slowest = 0.0
    for name in ("radiative-transfer", "kubelka-munk"):
        model = film_model(name)
        constants = constants_for(model, rng, D.size)
        for instrument in INSTRUMENTS:
            for label, thickness in (("over a card", h), ("opaque", np.full(N_DRAWS, np.inf))):
                seconds = best_time(lambda m=model, c=constants, t=thickness, i=instrument: m.reflectance(
                    c, D, t, substrate=card, instrument=i))
                slowest = max(slowest, seconds)
                print(f"{name:<19} reflectance {instrument:<7} {label:<12} {1e3 * seconds:7.2f} ms")
    revigo = args.revigo / "revigo-mixture-specifications.txt"
    if revigo.exists():
        ms = bayespig.data.read_revigo(args.revigo)["06B"]
        for name in ("radiative-transfer", "kubelka-munk"):
            model = film_model(name)
            film = model.for_film(ms)
            constants = constants_for(model, rng, 3)
            seconds = best_time(lambda f=film, c=constants: f.values(c, [0.1, 0.9, 0.0], h))
            slowest = max(slowest, seconds)
            print(f"{name:<19} for_film(06B).values (2 films)   {1e3 * seconds:7.2f} ms")
    else:
        print(f"(Revigo data not found at {args.revigo}: for_film not timed)")
    print(f"slowest: {1e3 * slowest:.2f} ms ({'within' if slowest < GOAL_S else 'ABOVE'} the goal of "
          f"{1e3 * GOAL_S:g} ms)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
