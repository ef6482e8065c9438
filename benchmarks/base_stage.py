"""How the base stage of the Revigo libraries mixes: zinc white and bone black from 07A, 07C-07F.

Usage:  python benchmarks/base_stage.py [REVIGO_FOLDER] [--max-steps N] [--seed N] [--write]

Every leave-one-out build of ``bayespig colour-prediction`` shares this stage (its base library,
:func:`bayespig.library.validation.leave_one_out`), built with the study's sampler settings
(:data:`bayespig.library.validation.LOO_SETTINGS`, 6000-step cap). Per film model the script
prints the stage's run (steps, cap, adaptation rounds), the largest R-hat and smallest ESS of
the films' thicknesses and of the constants, the share of the joint sampler's shared-block
(thickness) proposals, wavelength-block updates, steps along the scale symmetry and thicknesses
drawn from their prior accepted, and the coordinates with
the longest autocorrelation times, which the run-length rule (50 of them) waits for. With
``--write`` it replaces its section of ``reports/benchmarks.md``.
"""

import argparse
import dataclasses
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import Transcript, machine_line, write_run_section

DEFAULT_FOLDER = "/work/shared/data/revigo"
BASE_FILMS = ("07A", "07C", "07D", "07E", "07F")
HEADING = "## The base stage of the colour-prediction libraries (`python benchmarks/base_stage.py`)"


def _share(value):
    """A share as a percentage, "n/a" where the move does not apply (None)."""
    return "n/a" if value is None else f"{value:.1%}"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", nargs="?", default=DEFAULT_FOLDER)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-steps", type=int, default=None, help="step cap (default LOO_SETTINGS', 6000)")
    parser.add_argument("--write", action="store_true", help="replace this benchmark's section of reports/benchmarks.md")
    args = parser.parse_args(argv)

    from bayespig.data import read_revigo
    from bayespig.library import build_library
    from bayespig.library.validation import LOO_SETTINGS

    settings = LOO_SETTINGS if args.max_steps is None else dataclasses.replace(LOO_SETTINGS, max_steps=args.max_steps)
    say = Transcript(machine_line(), f"settings: target_ess {settings.target_ess:g}, max_steps {settings.max_steps}, "
                                     f"draws_per_chain {settings.draws_per_chain}, seed {args.seed}")
    sets = read_revigo(args.folder)
    films = {f: sets[f] for f in BASE_FILMS}
    for model in ("radiative-transfer", "kubelka-munk"):
        start = time.perf_counter()
        library = build_library(films, model=model, seed=args.seed, progress=False, settings=settings)
        seconds = time.perf_counter() - start
        for d in library.stages:
            say(f"{model}: {', '.join(d['pigments'])} from {', '.join(d['films'])}: {d['n_steps']} steps"
                f"{' (capped)' if d['max_steps_reached'] else ''}, {d['adaptation_rounds']} adaptation round(s), "
                f"{seconds:.0f} s")
            say(f"  R-hat / ESS: thicknesses {d['thickness_rhat_max']:.3f} / {d['thickness_ess_min']:.0f}, "
                f"constants {d['constants_rhat_max']:.3f} / {d['constants_ess_min']:.0f}")
            say(f"  accepted: shared-block (thickness) proposals {d['shared_acceptance']:.1%}, "
                f"wavelength-block updates {d['block_acceptance']:.1%}, "
                f"scale-symmetry steps {_share(d['scale_acceptance'])}, "
                f"thicknesses drawn from their prior {_share(d['prior_proposal_acceptance'])}")
            say("  longest autocorrelation times [steps]: "
                + ", ".join(f"{name} {tau:.0f}" for name, tau in d["slowest_coordinates"]))
    if args.write:
        write_run_section(HEADING, "python benchmarks/base_stage.py --write",
                          [("The stage every leave-one-out build of `bayespig colour-prediction` shares "
                            "(zinc white and bone black from 07A, 07C-07F), with the study's sampler settings.")],
                          say.lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
