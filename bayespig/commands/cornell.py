"""``bayespig cornell``: the Cornell gonio paints (rough-surface fits, subset consistency, report)."""

from __future__ import annotations

from ._arguments import add_output_argument, add_verbosity_arguments, progress_printer, reference_data_folder

__all__ = ["CORNELL_SOURCE", "add_cornell_parser", "cornell_folder", "run_cornell"]

#: Where the Cornell data come from, for the message when they are not found.
CORNELL_SOURCE = ("the Cornell Program of Computer Graphics gonioreflectometer measurements garnet_red.astm and "
                  "krylon_blue.astm (ASTM E1392), redistributed in github.com/chicio/Spectral-Clara-Lux-Tracer "
                  "(Scenes/BRDFs)")


def add_cornell_parser(subparsers):
    """Register ``bayespig cornell``."""
    parser = subparsers.add_parser(
        "cornell",
        help="real gonio paints: rough-surface fits, subset consistency, smooth-model comparison",
        description="Fit the two Cornell gonio paints (garnet red, Krylon blue) as opaque films under a "
        "rough surface (roughness and a noise floor inferred), check that geometry subsets agree, compare "
        "with the smooth surface, and write the report (reports/cornell.md and reports/cornell/*.png). "
        "Takes 30-80 min on 2 cores with --jobs 2 (the paints at once; reports/benchmarks.md, reports/cornell.md).",
    )
    parser.add_argument("path", nargs="?", default=None,
                        help="folder of the Cornell data (default $BAYESPIG_CORNELL, else ../shared/data/cornell "
                        "from the working folder)")
    add_output_argument(parser, "--report", kind="file", default="reports/cornell.md",
                        help="Markdown report to write (default reports/cornell.md; figures beside it)")
    parser.add_argument("--subset-bands", type=float, nargs="*", default=None, metavar="NM",
                        help="bands of the subset-consistency fits [nm] (default all 31)")
    parser.add_argument("--full-bands", type=float, nargs="*", default=None, metavar="NM",
                        help="bands of the full fit [nm] (default all 31)")
    parser.add_argument("--max-steps", type=int, default=None,
                        help="cap of every run's steps per walker (default 8000: with the binder index free "
                             "the subset fits need more than 2000)")
    parser.add_argument("--draws-per-chain", type=int, default=None,
                        help="stored draws per chain (default 256)")
    parser.add_argument("--fixed-binder-index", action="store_true",
                        help="keep the binder index at 1.45 (default: inferred with the roughness; its rough "
                             "tables at six index nodes are built once, minutes each)")
    parser.add_argument("--no-flakes", action="store_true",
                        help="fit the surface alone (default: with an effect-pigment flake lobe, and the full "
                             "set without it for comparison)")
    parser.add_argument("--no-incidence-offset", action="store_true",
                        help="no instrument offset b / cos(theta_i) per band (default: inferred in every rough "
                             "fit; the paints' exact zeros lie at 70-80 deg incidence)")
    parser.add_argument("--keep-occluded", action="store_true",
                        help="keep the geometries that read (nearly) nothing in every band amid bright neighbours "
                             "(default: left out; bayespig check lists them)")
    parser.add_argument("--jobs", type=int, default=1,
                        help="paints fitted at once, one process each (default 1; the results do not depend "
                             "on it)")
    parser.add_argument("--seed", type=int, default=0, help="seed of every fit (default 0)")
    add_verbosity_arguments(parser)
    parser.set_defaults(func=run_cornell)
    return parser


def cornell_folder(path=None):
    """The folder of the Cornell data: ``path``, else ``$BAYESPIG_CORNELL``, else the default.

    Raises
    ------
    MeasurementError
        When it does not exist: where it was looked for, where the data come from and how to
        point at them.
    """
    from ..studies.cornell import default_cornell_path

    return reference_data_folder(path, default=default_cornell_path(), variable="BAYESPIG_CORNELL", name="Cornell",
                                 source=CORNELL_SOURCE, command="bayespig cornell")


def run_cornell(args):
    """Run the study and write the report; returns the exit code."""
    import dataclasses

    from ..studies.cornell import (
        CornellStudySettings,
        cornell_study,
        overlap_goal,
        write_cornell_report,
    )

    for name in ("max_steps", "draws_per_chain"):
        value = getattr(args, name)
        if value is not None and value < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be a positive integer, got {value}")
    if args.jobs < 1:
        raise ValueError(f"--jobs must be a positive integer, got {args.jobs}")
    settings = CornellStudySettings(seed=args.seed, binder_index=None if args.fixed_binder_index else "free",
                                    flakes=not args.no_flakes, incidence_offset=not args.no_incidence_offset,
                                    exclude_occluded=not args.keep_occluded)
    overrides = {k: v for k, v in (("max_steps", args.max_steps), ("draws_per_chain", args.draws_per_chain))
                 if v is not None}
    if overrides:
        settings = dataclasses.replace(settings, inference=dataclasses.replace(settings.inference, **overrides))
    if args.subset_bands is not None:
        settings = dataclasses.replace(settings, subset_bands=tuple(args.subset_bands))
    if args.full_bands is not None:
        settings = dataclasses.replace(settings, full_bands=tuple(args.full_bands))
    folder = cornell_folder(args.path)
    progress = progress_printer(args)
    study = cornell_study(folder, settings=settings, progress=progress, jobs=args.jobs)
    path = write_cornell_report(study, args.report)
    goals = {paint: overlap_goal(result) for paint, result in study["paints"].items()}
    print(f"wrote {path}: " + "; ".join(
        f"{paint} roughness {result['full']['roughness'][1]:.4f}, subset overlap with both runs mixed at "
        f"{goals[paint]['counted']} of {goals[paint]['bands']} bands ({goals[paint]['overlapping']} counting "
        "unmixed runs)"
        for paint, result in study["paints"].items()))
    return 0
