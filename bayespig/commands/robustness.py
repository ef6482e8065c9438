"""``bayespig robustness``: the paper's robustness study (section 4) and its generalisations."""

from __future__ import annotations

import sys

import numpy as np

from ._arguments import (
    METHOD_HELP,
    add_output_argument,
    add_verbosity_arguments,
    check_output_path,
    instrument_argument,
    instrument_help,
    parse_methods,
    parse_numbers,
)

__all__ = ["add_robustness_parser", "run_robustness"]



def add_robustness_parser(subparsers):
    """Register ``bayespig robustness``."""
    parser = subparsers.add_parser(
        "robustness",
        help="the paper's robustness study (noisy refits, eq. 7) on its tables or any grid",
        description="Frequentist robustness of the paper's methods: BRDFs of (a0, tau0) distorted by "
        "eq. (7) and refitted n times. --paper regenerates reports/paper-tables.md (Tables 1 and 2 "
        "beside the paper's); --posterior adds the Bayesian answer (posterior sd from one set); "
        "otherwise the grid given by --method/--a0/--tau0 is run and printed.",
    )
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--paper", action="store_true", help="regenerate the paper's Tables 1 and 2")
    mode.add_argument("--posterior", action="store_true",
                      help="posterior sd and correlation of a and tau from one simulated set per case")
    parser.add_argument("--method", default="1,2,3,4",
                        help=f"comma-separated methods, each {METHOD_HELP}, e.g. 1,4 (default all)")
    parser.add_argument("--a0", default=None, help="true a values, e.g. 0.025,0.1,0.2")
    parser.add_argument("--tau0", default=None, help="true tau values, e.g. 0.5,1,2")
    parser.add_argument("--eps", type=float, default=0.05, help="relative error of eq. (7) (default 0.05)")
    parser.add_argument("--n-repeat", type=int, default=None,
                        help="noisy replicates per case (default 1000; 200 for a map)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the noise (default 0)")
    parser.add_argument("--instrument", default="multi-angle-45", help=instrument_help(default="multi-angle-45"))
    add_output_argument(parser, "--map", kind="file", metavar="PNG", default=None,
                        help="also draw the (a0, tau0) map, one panel per method (default grid: "
                             "6 x 5 points when --a0/--tau0 are not given)")
    add_output_argument(parser, "--json", kind="file", metavar="FILE", default=None,
                        help="write every case's statistics as JSON")
    add_output_argument(parser, "--out", kind="file", default=None,
                        help="Markdown report for --paper/--posterior (default reports/paper-tables.md "
                             "or reports/posterior-robustness.md)")
    parser.add_argument("--quick", action="store_true",
                        help="--paper without the variant studies (fit box, objective, starts)")
    add_verbosity_arguments(parser)
    parser.set_defaults(func=run_robustness)
    return parser


def _print_grid(grid):
    header = (f"{'method':>8} {'a0':>6} {'tau0':>6} {'a_bias':>9} {'a_rms':>8} {'a_mad':>8} "
              f"{'tau_bias':>9} {'tau_rms':>8} {'tau_mad':>8} {'at_bound':>8}")
    print(header)
    for record in grid.to_records():
        def f(name, width, fmt):
            value = record.get(name)
            return f"{'-':>{width}}" if value is None else f"{value:{width}{fmt}}"
        print(f"{record['method']:>8} {record['a0']:6.3g} {record['tau0']:6.3g} "
              f"{f('a_bias', 9, '.4f')} {f('a_rms', 8, '.4f')} {f('a_mad', 8, '.4f')} "
              f"{f('tau_bias', 9, '.4f')} {f('tau_rms', 8, '.4f')} {f('tau_mad', 8, '.4f')} "
              f"{f('fraction_at_bound', 8, '.1%')}")


def run_robustness(args):
    """Run ``bayespig robustness``; returns the exit status."""
    from ..studies import robustness

    instrument = instrument_argument(args.instrument)
    progress = not args.no_progress
    if args.n_repeat is not None and args.n_repeat < 2:
        raise ValueError(f"--n-repeat must be at least 2, got {args.n_repeat}")
    if not (np.isfinite(args.eps) and args.eps >= 0):
        raise ValueError(f"--eps must be a non-negative number, got {args.eps}")
    if args.paper:
        out = args.out or "reports/paper-tables.md"
        check_output_path(out, "file")
        command = "bayespig robustness --paper" + (" --quick" if args.quick else "")
        robustness.write_paper_tables(out, n_repeat=args.n_repeat or 1000, seed=args.seed,
                                      eps=args.eps, instrument=instrument, extras=not args.quick,
                                      command=command, progress=progress)
        print(f"wrote {out}")
        return 0
    if args.posterior:
        from ..studies.posterior_robustness import write_posterior_tables

        out = args.out or "reports/posterior-robustness.md"
        check_output_path(out, "file")
        write_posterior_tables(out, seed=args.seed, eps=args.eps, instrument=instrument, progress=progress)
        print(f"wrote {out}")
        return 0
    methods = parse_methods(args.method)
    a0 = tuple(parse_numbers(args.a0, "--a0", positive=True)) if args.a0 else None
    tau0 = tuple(parse_numbers(args.tau0, "--tau0", positive=True)) if args.tau0 else None
    common = {"eps": args.eps, "seed": args.seed, "instrument": instrument, "progress": progress}
    if args.map is not None:
        grid = robustness.robustness_map(methods, a0, tau0, n_repeat=args.n_repeat or 200, **common)
        robustness.plot_robustness_map(grid, args.map)
    else:
        grid = robustness.robustness_study(methods, a0 or robustness.PAPER_A0, tau0 or robustness.PAPER_TAU0,
                                           n_repeat=args.n_repeat or 1000, **common)
    _print_grid(grid)
    if args.map is not None:
        print(f"wrote {args.map}")
    if args.json is not None:
        grid.write_json(args.json)
        print(f"wrote {args.json}")
    sys.stdout.flush()
    return 0
