"""One held-out film's leave-one-out library, by MCMC and by point estimates: where they part.

Run from the repository root::

    python benchmarks/stage_fixing.py [FILM] [--revigo FOLDER]   # default 03D; about 6 min on 2 cores

Builds the library that :func:`bayespig.library.validation.leave_one_out` builds for ``FILM``
(radiative transfer; base pigments zinc white and bone black from series 07, then the film's
tinting pigment from the other films of its series; the leave-one-out sampler settings) twice:
with the MCMC of :func:`bayespig.build_library`, and with each stage's posterior replaced by its
joint least-squares start (``benchmarks/loo_point_estimates.py``). Prints both predictions of
the film, the tinting pigment's constants per band (point fit; MCMC median and 90 % interval),
and how far the MCMC's fixed white and black (what the later stage is conditioned on) lie from
the point fit's.

Since the MCMC build fixes each earlier stage at its joint least-squares point
(``provenance["stage_points"]``, :mod:`bayespig.library.build`, "Stages"), the two builds fix the
same white and black and the last lines read 0: what remains is the held-out film's stage, its
posterior against its point. Measured before that, when the MCMC build fixed the draw nearest
the marginal medians (session 17; ΔE00 over black / white):

- 03D (this script, about 6 min on 2 cores): MCMC 3.03 / 9.74, point 1.17 / 1.80; Eosin2PbWax
  ``log sigma`` at 400-460 nm MCMC median +2.1 ... +6.0 (90 % interval as narrow as [5.99,
  6.08]) against the point fit's -1.3 ... -1.5; the zinc white and the bone black it was
  conditioned on: ``a`` within 0.02 of the point fit's, ``log sigma`` up to 7.7 from it (410
  nm), where the base films hide their cards;
- 01C (a scratch run of the same builds): MCMC 15.1 / 13.9, point 10.1 / 9.1; Eosin1Wax
  ``log sigma`` at 460 nm +3.2 against -1.6.
"""

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

import bayespig.inference.shared as shared
import bayespig.library.build as build
from bayespig.data.spectral_table import read_revigo
from bayespig.library.recipes import film_recipes
from bayespig.library.validation import LOO_SETTINGS, predict_held_out, training_films

sys.path.insert(0, str(Path(__file__).resolve().parent))
from loo_point_estimates import DEFAULT_REVIGO, point_estimate  # noqa: E402

BASE = ("ZincWhite", "BoneBlack")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("film", nargs="?", default="03D")
    parser.add_argument("--revigo", type=Path, default=DEFAULT_REVIGO)
    args = parser.parse_args()
    warnings.filterwarnings("ignore", category=FutureWarning)
    warnings.filterwarnings("ignore", category=RuntimeWarning, module="arviz")
    sets = read_revigo(args.revigo, progress=False)
    recipes = film_recipes(sets)
    base_only, others = training_films(recipes, args.film, BASE)
    pigment = next(p for p in recipes[args.film].amounts if p not in BASE)
    libraries = {}
    for kind, sampler in (("point", point_estimate), ("mcmc", shared.sample_blocks)):
        build.sample_blocks = sampler
        base = build.build_library({f: sets[f] for f in base_only}, progress=False, settings=LOO_SETTINGS)
        library = build.build_library({f: sets[f] for f in others}, progress=False, settings=LOO_SETTINGS, base=base)
        p = predict_held_out(library, sets[args.film], recipes[args.film], model="radiative-transfer",
                             film_id=args.film)
        libraries[kind] = library
        print(f"{kind:5s} {args.film}: ΔE00 {p.delta_E[0]:.2f} / {p.delta_E[1]:.2f}, h {p.thickness:.3g}; stages "
              + ", ".join(f"{'+'.join(s['pigments'])} {s['n_steps']} steps{' (capped)' if s['max_steps_reached'] else ''}"
                          for s in library.stages))
    point, mcmc = libraries["point"], libraries["mcmc"]
    wl = point.wavelength_nm
    i, j = point.pigments.index(pigment), mcmc.pigments.index(pigment)
    print(f"{pigment}: band [nm], a point | MCMC median [5 %, 95 %], log sigma point | MCMC median [5 %, 95 %]")
    for w in range(0, wl.size, 2):
        a_p, s_p = np.median(point.constants[:, w, i], axis=0)
        q = np.quantile(mcmc.constants[:, w, j], [0.05, 0.5, 0.95], axis=0)
        print(f"{wl[w]:4.0f}  {a_p:.4f} | {q[1, 0]:.4f} [{q[0, 0]:.4f}, {q[2, 0]:.4f}]   {s_p:6.2f} | "
              f"{q[1, 1]:6.2f} [{q[0, 1]:6.2f}, {q[2, 1]:6.2f}]")
    for name in BASE:
        fixed_mcmc = np.asarray(mcmc.provenance["conditioning"]["fixed_constants"][name])
        fixed_point = np.asarray(point.provenance["conditioning"]["fixed_constants"][name])
        d = np.abs(fixed_mcmc - fixed_point)
        print(f"{name} as fixed for {pigment}: MCMC - point, max |a| {d[:, 0].max():.4f}, "
              f"max |log sigma| {d[:, 1].max():.2f} (at {wl[np.argmax(d[:, 1])]:.0f} nm)")


if __name__ == "__main__":
    main()
