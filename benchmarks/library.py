"""Time to build the pigment library of the whole Revigo palette on 2 cores (goal <= 10 min).

Usage:  python benchmarks/library.py [REVIGO_FOLDER] [--seed N] [--save PATH] [--max-steps N]

Builds :func:`bayespig.library.build_library` on every Revigo film (default folder
``/work/shared/data/revigo``) with a local pool of 2 processes for each stage's independent
groups, and prints per stage group: pigments, films, steps (capped or not), the largest R-hat
and the smallest ESS of the films' thicknesses and of the constants, and the seconds; then the
stage times, the total and the films no stage used.
"""

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine_line

DEFAULT_FOLDER = "/work/shared/data/revigo"
#: The speed goal of issue 17 [s].
GOAL_S = 600.0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", nargs="?", default=DEFAULT_FOLDER)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--save", default=None, help="write the library here (netCDF)")
    parser.add_argument("--max-steps", type=int, default=None,
                        help="cap of every stage's run (default that of DEFAULT_SETTINGS, 20000)")
    args = parser.parse_args(argv)

    import dataclasses

    from bayespig.data import read_revigo
    from bayespig.library import build_library
    from bayespig.library.build import DEFAULT_SETTINGS

    settings = DEFAULT_SETTINGS if args.max_steps is None else dataclasses.replace(DEFAULT_SETTINGS,
                                                                                   max_steps=args.max_steps)

    print(machine_line(), flush=True)
    sets = read_revigo(args.folder)
    start = time.perf_counter()
    library = build_library(sets, seed=args.seed, progress=True, settings=settings)
    total = time.perf_counter() - start
    print(f"{'stage':>5} {'pigments':<24} {'films':>5} {'steps':>6} {'capped':>6} {'R-hat h':>8} {'ESS h':>7} "
          f"{'R-hat c':>8} {'ESS c':>7} {'s':>7}")
    per_stage = {}
    for d in library.stages:
        per_stage[d["stage"]] = per_stage.get(d["stage"], 0.0) + d["seconds"]
        print(f"{d['stage']:>5} {', '.join(d['pigments']):<24} {len(d['films']):>5} {d['n_steps']:>6} "
              f"{'yes' if d['max_steps_reached'] else 'no':>6} {d['thickness_rhat_max']:>8.4f} "
              f"{d['thickness_ess_min']:>7.0f} {d['constants_rhat_max']:>8.4f} {d['constants_ess_min']:>7.0f} "
              f"{d['seconds']:>7.1f}")
    for stage, seconds in sorted(per_stage.items()):
        print(f"stage {stage}: {seconds:.1f} s of sampling (summed over its groups)")
    converged = all(not d["max_steps_reached"] and d["thickness_rhat_max"] <= 1.01 and d["thickness_ess_min"] >= 400
                    for d in library.stages)
    print(f"total {total:.1f} s (goal <= {GOAL_S:.0f} s: {'met' if total <= GOAL_S else 'missed'}); "
          f"every stage converged: {converged}; unused films: {', '.join(library.provenance['unused_films'])}")
    if args.save:
        library.save(args.save)
        print(f"saved {args.save}")


if __name__ == "__main__":
    main()
