"""``bayespig revigo``: the Revigo real-film study (fits, SCE vs SCI, tint prediction vs Kubelka-Munk)."""

from __future__ import annotations

import numpy as np

from ._arguments import add_output_argument, add_verbosity_arguments, progress_printer, reference_data_folder

__all__ = ["REVIGO_SOURCE", "add_revigo_parser", "revigo_folder", "run_revigo"]

#: Where the Revigo data come from, for the message when they are not found.
REVIGO_SOURCE = ("the CC0 spectra of Geldof et al. (2018), Heritage Science 6:17, from "
                 "https://github.com/fligt/revigo-spectra (data/revigo-aggregated-palette-spectral-data.txt "
                 "and data/revigo-mixture-specifications.txt)")


def add_revigo_parser(subparsers):
    """Register ``bayespig revigo``."""
    parser = subparsers.add_parser(
        "revigo",
        help="real films: black/white fits, SCE vs SCI, tint prediction vs Kubelka-Munk",
        description="Fit the Revigo films (Geldof et al. 2018) by method 4 under SCE and SCI, decide "
        "which the instrument used, predict each pigment's ~50/50 tint with zinc white from its "
        "masstone, the white and the 10/90 tint with bayespig and with Kubelka-Munk (Saunderson), "
        "and write the report (reports/revigo.md). Takes a few minutes.",
    )
    parser.add_argument("path", nargs="?", default=None,
                        help="folder of the Revigo data (default $BAYESPIG_REVIGO, else ../shared/data/revigo "
                        "from the working folder); data: github.com/fligt/revigo-spectra")
    add_output_argument(parser, "--report", kind="file", default="reports/revigo.md",
                        help="Markdown report to write (default reports/revigo.md)")
    parser.add_argument("--specular", choices=("auto", "excluded", "included"), default="auto",
                        help="instrument hypothesis for the tints (default: decide from the evidence)")
    parser.add_argument("--posterior", action="store_true",
                        help="also sample every film's posterior (bayespig infer, method 4), check "
                        "where the model cannot reproduce it, and report 90 %% credible colour "
                        "regions of the predicted tints (about 5 s per film)")
    parser.add_argument("--eps", type=float, default=None,
                        help="relative measurement error assumed for the posteriors (default 0.01)")
    parser.add_argument("--draws", type=int, default=200, help="posterior predictive draws per tint")
    parser.add_argument("--g-sensitivity", type=float, nargs="*", default=None, metavar="G",
                        help="also predict the tints at these fixed phase-function g (default "
                        "0.3 0.6; none to skip; uses the 8d-sce table with a g axis)")
    parser.add_argument("--substrate-sd", type=float, default=None, metavar="SD",
                        help="with --posterior: prior sd of log f of every card's albedo factor (default "
                        "0.1, paper section 3.4); 0 keeps the converted cards fixed")
    parser.add_argument("--substrate-films", default=None, metavar="IDS",
                        help="with --posterior: sample the card factors for these films only (comma-separated "
                        "ids, or 'white-rich': the white and every 10/90 tint; default all, 1-4 min per film)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the posteriors and draws (default 0)")
    add_verbosity_arguments(parser)
    parser.set_defaults(func=run_revigo)
    return parser


def revigo_folder(path=None):
    """The folder of the Revigo data: ``path``, else ``$BAYESPIG_REVIGO``, else the default.

    Raises
    ------
    MeasurementError
        When it does not exist: ``<folder>: file not found``, where it was looked for, where the
        data come from and how to point at them.
    """
    from ..studies.revigo import default_revigo_path

    return reference_data_folder(path, default=default_revigo_path(), variable="BAYESPIG_REVIGO", name="Revigo",
                                 source=REVIGO_SOURCE, command="bayespig revigo")


def run_revigo(args):
    """Run the study and write the report; returns the exit code."""
    from ..studies.revigo import (
        G_SENSITIVITY,
        POSTERIOR_EPS,
        POSTERIOR_SUBSTRATE_SD,
        revigo_study,
        write_revigo_report,
    )

    eps = POSTERIOR_EPS if args.eps is None else args.eps
    if not (eps > 0 and eps < 1):
        raise ValueError(f"--eps must lie in (0, 1), got {args.eps}")
    if args.g_sensitivity and not all(-1.0 < g < 1.0 for g in args.g_sensitivity):
        raise ValueError(f"--g-sensitivity values must lie in (-1, 1), got {args.g_sensitivity}")
    substrate_sd = POSTERIOR_SUBSTRATE_SD if args.substrate_sd is None else args.substrate_sd
    if not (np.isfinite(substrate_sd) and substrate_sd >= 0):
        raise ValueError(f"--substrate-sd must be >= 0, got {args.substrate_sd}")
    if args.draws < 10:
        raise ValueError(f"--draws must be >= 10, got {args.draws}")
    path = revigo_folder(args.path)
    progress = progress_printer(args)
    study = revigo_study(path, specular=args.specular, progress=progress, posterior=args.posterior,
                         posterior_eps=eps, n_draws=args.draws, seed=args.seed,
                         g_sensitivity=G_SENSITIVITY if args.g_sensitivity is None else tuple(args.g_sensitivity),
                         substrate_sd=substrate_sd,
                         substrate_films=(None if args.substrate_films is None else args.substrate_films
                                          if args.substrate_films == "white-rich"
                                          else [f.strip() for f in args.substrate_films.split(",") if f.strip()]))
    path = write_revigo_report(study, args.report)
    print(f"wrote {path}: SCE/SCI decision {study.evidence['decision']}; "
          f"{len(study.series)} tint series")
    return 0
