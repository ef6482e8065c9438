"""``bayespig report`` (uncertainty report of one pigment) and ``bayespig demo`` (the main job)."""

from __future__ import annotations

import os
import sys
import warnings
from pathlib import Path

from ..inference.arguments import DEFAULT_EPS
from ._arguments import (
    METHOD_HELP,
    add_film_argument,
    add_film_state_arguments,
    add_input_argument,
    add_output_argument,
    add_substrate_argument,
    add_verbosity_arguments,
    film_state,
    method_argument,
    read_film,
)
from .infer import eps_argument

__all__ = ["add_demo_parser", "add_report_parser", "run_demo", "run_report"]



def add_report_parser(subparsers):
    """Register ``bayespig report``."""
    from ..colorimetry import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER

    parser = subparsers.add_parser(
        "report",
        help="uncertainty report of one pigment (HTML, Markdown, figures, CSV/JSON summary)",
        description="Write the uncertainty report of one pigment into DIR: report.html (self-"
        "contained, opens offline), report.md with figures/*.png, summary.csv, summary.json and "
        "posterior.nc. Given a measurement file instead of a posterior (.nc), the posterior is "
        "inferred first (bayespig infer's defaults).",
    )
    add_input_argument(parser, "source", metavar="POSTERIOR_OR_MEASUREMENTS",
                       help="posterior netCDF from 'bayespig infer' (.nc) or a measurement file")
    add_output_argument(parser, "--out", kind="folder", required=True,
                        help="output folder (report.html, report.md, figures/, summary files)")
    add_input_argument(parser, "--measurements", default=None,
                       help="the measurement file of a posterior (thickness, concentration, truth)")
    add_film_argument(parser)
    add_film_state_arguments(parser)
    add_substrate_argument(parser)
    parser.add_argument("--method", default="auto", type=method_argument, metavar="METHOD",
                        help=f"when inferring: the paper's method, {METHOD_HELP}, auto (default) or general")
    parser.add_argument("--seed", type=int, default=0, help="when inferring: random seed (default 0)")
    parser.add_argument("--g", default="isotropic", choices=("isotropic", "free"),
                        help="when inferring: g fixed at 0 (default) or a parameter")
    parser.add_argument("--eps", default=None,
                        help="when inferring: relative measurement error of eq. (7), a number (e.g. "
                             "0.02 for 2 %%) or 'infer' (default: the file's eps, else 0.05 - an "
                             "assumption the report says; see the user guide for typical values)")
    parser.add_argument("--observer", default=DEFAULT_OBSERVER,
                        help=f"colour-science observer name (default {DEFAULT_OBSERVER!r})")
    parser.add_argument("--illuminant", default=DEFAULT_ILLUMINANT,
                        help=f"colour-science illuminant name (default {DEFAULT_ILLUMINANT!r})")
    parser.add_argument("--title", default=None, help="report title")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the --out folder whole even when it is not an earlier report "
                             "(without it, only an empty folder or an earlier bayespig report is replaced)")
    add_verbosity_arguments(parser)
    parser.set_defaults(func=run_report)
    return parser


def _print_warnings(caught):
    """Print the user-facing warnings (convergence, fit bounds); library deprecations are not."""
    for warning in caught:
        if not issubclass(warning.category, UserWarning):
            continue
        print(f"bayespig: warning: {warning.message}", file=sys.stderr)


def run_report(args):
    """Run ``bayespig report``; returns the exit status."""
    from ..report import write_report
    from ..report.write import NETCDF_SUFFIXES

    if not os.path.exists(args.source):
        raise ValueError(f"{args.source}: file not found")
    eps = eps_argument(args.eps)
    if eps is not None and Path(args.source).suffix.lower() in NETCDF_SUFFIXES:
        raise ValueError(f"--eps: {args.source} is a posterior, inferred with its own eps; --eps applies "
                         "only when report infers from a measurement file (or run bayespig infer --eps)")
    infer_kwargs = {"method": args.method, "seed": args.seed, "g": args.g,
                    "substrate_sd": args.substrate_sd, "eps": eps, "eps_given_as": "--eps"}
    source = read_film(args.source, args.film)
    if film_state(args) and isinstance(source, (str, os.PathLike)):
        if Path(source).suffix.lower() in NETCDF_SUFFIXES:
            raise ValueError(f"--opaque/--substrate: {source} is a posterior; they apply when report infers "
                             "from an ASTM E1392 file")
        from ..data import read_measurements

        source = read_measurements(source, **film_state(args))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = write_report(source, args.out, measurements=args.measurements,
                              observer=args.observer, illuminant=args.illuminant, title=args.title,
                              infer_kwargs=infer_kwargs, progress=not args.no_progress,
                              overwrite=args.overwrite)
    _print_warnings(caught)
    _print_result(result)
    return 0


def _print_result(result):
    summary = result.summary
    flags = [f for f in summary["diagnostics"]["flags"] if f["wavelength_nm"] is not None]
    if result.replaced:
        print(f"replaced the earlier contents of {result.out_dir}")
    print(f"wrote {result.files['html']} and {result.files['markdown']} "
          f"({len(result.files['figures'])} figures), summary.csv, summary.json"
          + (", posterior.nc" if "netcdf" in result.files else "")
          + f" in {result.seconds:.1f} s")
    colour = summary["colour"]
    if colour.get("available"):
        verdict = "good enough" if colour["good_enough_for_colour_matching"] else "NOT good enough"
        hedge = ""
        if colour.get("verdict_assumes_eps"):
            hedge = f" if eps is the assumed {DEFAULT_EPS:g} (pass --eps with your instrument's value)"
        print(f"colour spread of the measured samples: dE00 <= {colour['max_dE00_spread_measured']:.2f} "
              f"(95th percentile) - {verdict} for colour matching{hedge}")
    for edge in summary.get("prior_edge") or ():
        print(f"bayespig: warning: {edge['text']}", file=sys.stderr)
    if flags:
        print(f"{len(flags)} wavelength(s) flagged: "
              + ", ".join(f"{f['wavelength_nm']:g} nm" for f in flags), file=sys.stderr)


def add_demo_parser(subparsers):
    """Register ``bayespig demo``."""
    from ..demo import DEFAULT_OUT_DIR

    parser = subparsers.add_parser(
        "demo",
        help="the main job on a bundled SYNTHETIC pigment: simulate, infer, report",
        description="Simulate a synthetic red-oxide-like pigment measured the method-4 way (the "
        "same film on black and white, multi-angle-45 instrument, eps 0.05), infer its posterior "
        "and write the uncertainty report.",
    )
    add_output_argument(parser, "--out", kind="folder", default=str(DEFAULT_OUT_DIR),
                        help=f"output folder (default {DEFAULT_OUT_DIR})")
    parser.add_argument("--seed", type=int, default=0, help="seed of the noise and the sampler (default 0)")
    parser.add_argument("--quick", action="store_true",
                        help="shorter runs at every second wavelength (for tests)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the --out folder whole even when it is not an earlier report")
    add_verbosity_arguments(parser)
    parser.set_defaults(func=run_demo)
    return parser


def run_demo(args):
    """Run ``bayespig demo``; returns the exit status."""
    from ..demo import run_demo as demo

    if args.seed < 0:
        raise ValueError(f"--seed must be a non-negative integer, got {args.seed}")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = demo(args.out, seed=args.seed, progress=not args.no_progress, quick=args.quick,
                      overwrite=args.overwrite)
    _print_warnings(caught)
    _print_result(result)
    return 0
