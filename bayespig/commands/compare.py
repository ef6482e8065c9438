"""``bayespig compare``: methods 1–4 (and custom sets) on the same pigment, side by side."""

from __future__ import annotations

import shlex
import sys

import numpy as np

from ._arguments import (
    METHOD_HELP,
    add_input_argument,
    add_output_argument,
    add_verbosity_arguments,
    instrument_help,
    parse_methods,
    parse_numbers,
)

__all__ = ["add_compare_parser", "run_compare"]


def _command():
    """The command line, when run as ``bayespig compare ...`` (for the report's header)."""
    argv = sys.argv[1:]
    return shlex.join(["bayespig", *argv]) if argv[:1] == ["compare"] else None




def add_compare_parser(subparsers):
    """Register ``bayespig compare``."""
    parser = subparsers.add_parser(
        "compare",
        help="posterior widths of methods 1-4 on one pigment, per wavelength and as (a0, tau0) maps",
        description="Compare the paper's methods on the same pigment: simulated from --a/--tau (one value or "
        "one per wavelength) or from your --measurements (every method they support); Fisher and full-"
        "posterior widths and correlations side by side; --paper-points adds the paper's nine (a0, tau0) "
        "pairs and checks its ranking of the methods; --map adds Fisher maps over the (a0, tau0) plane. "
        "Writes OUT/compare.html, compare.md, compare.json and figures.",
    )
    add_input_argument(parser, "--measurements", default=None,
                       help="measurement file (compare the methods it supports)")
    parser.add_argument("--a", default=None, help="true a, one value or comma-separated per wavelength")
    parser.add_argument("--tau", default=None, help="true tau of the thin film, likewise")
    parser.add_argument("--wavelengths", default=None, help="wavelengths [nm] for --a/--tau lists")
    parser.add_argument("--methods", default="1,2,3,4",
                        help=f"comma-separated methods, each {METHOD_HELP}, e.g. 1,4 (default all)")
    parser.add_argument("--instrument", default="multi-angle-45", help=instrument_help(default="multi-angle-45"))
    parser.add_argument("--eps", type=float, default=0.05, help="relative error of eq. (7) (default 0.05)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulations and the sampler (default 0)")
    parser.add_argument("--paper-points", action="store_true", help="the paper's nine (a0, tau0) pairs")
    parser.add_argument("--map", action="store_true", help="Fisher maps over the (a0, tau0) plane")
    parser.add_argument("--fisher-only", action="store_true", help="skip the full posteriors (seconds, not minutes)")
    add_output_argument(parser, "--out", kind="folder", required=True,
                        help="output folder (compare.html, compare.md, compare.json, figures)")
    add_verbosity_arguments(parser)
    parser.set_defaults(func=run_compare)
    return parser


def run_compare(args):
    """Run ``bayespig compare``; returns the exit status."""
    from ..inference import InferenceSettings
    from ..studies import compare

    methods = parse_methods(args.methods, "--methods")
    if not (np.isfinite(args.eps) and 0 < args.eps < 1):
        raise ValueError(f"--eps must be a number in (0, 1), got {args.eps}")
    settings = InferenceSettings(target_ess=400, draws_per_chain=512)
    common = {"methods": methods, "instrument": args.instrument, "eps": args.eps, "seed": args.seed,
              "full": not args.fisher_only, "settings": settings}
    comparison = paper = maps = None
    if args.measurements is not None:
        if args.a is not None or args.tau is not None:
            raise ValueError("give either --measurements or --a/--tau, not both")
        if args.fisher_only:
            raise ValueError("--fisher-only needs --a/--tau (measurements are compared by their posteriors)")
        comparison = compare.compare_measurements(args.measurements, methods=methods, eps=args.eps,
                                                  seed=args.seed, settings=settings)
    elif args.a is not None or args.tau is not None:
        if args.a is None or args.tau is None:
            raise ValueError("--a and --tau go together")
        a, tau = parse_numbers(args.a, "--a"), parse_numbers(args.tau, "--tau")
        n = max(a.size, tau.size)
        if {a.size, tau.size} - {1, n}:
            raise ValueError(f"--a and --tau must have one value or the same number of values ({a.size} vs {tau.size})")
        wl = parse_numbers(args.wavelengths, "--wavelengths") if args.wavelengths else None
        comparison = compare.compare_methods(np.broadcast_to(a, n), np.broadcast_to(tau, n), wavelengths=wl,
                                             **common)
    if args.paper_points:
        a0 = np.array([p[0] for p in compare.PAPER_POINTS])
        tau0 = np.array([p[1] for p in compare.PAPER_POINTS])
        paper = compare.compare_methods(a0, tau0, **common)  # one label wavelength (400 + 10 k nm) per point
    if args.map:
        maps = compare.method_map(methods, instrument=args.instrument, eps=args.eps)
    if comparison is None and paper is None and maps is None:
        raise ValueError("nothing to compare: give --measurements, --a/--tau, --paper-points or --map")
    files = compare.write_compare_report(args.out, comparison=comparison, maps=maps, paper=paper,
                                         command=_command())
    print(f"wrote {files['html']}")
    return 0
