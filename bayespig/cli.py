"""The ``bayespig`` command: a thin shell over the Python API."""

from __future__ import annotations

import argparse
import sys

import numpy as np

__all__ = ["main"]


def _demo(args):
    from .instruments import get_instrument, predict

    instrument = get_instrument(args.instrument)
    a_values = np.array([0.01, 0.05, 0.2])
    tau_values = np.array([0.5, 2.0, np.inf])
    print(f"bayespig forward model — instrument {instrument.name!r}, binder n = {instrument.n}")
    print("isotropic pigment on a black (r_s = 0.01) and a white (r_s = 0.95) substrate")
    header = f"{'a':>6} {'tau':>6} {'r_s':>5}  " + " ".join(f"{label:>9}" for label in instrument.labels)
    print(header)
    for a in a_values:
        for tau in tau_values:
            for r_s in (0.01, 0.95):
                values = predict(instrument, a=a, tau=tau, r_s=r_s)
                print(f"{a:6.3f} {tau:6.2f} {r_s:5.2f}  " + " ".join(f"{v:9.5f}" for v in values))
    unit = "1/sr" if instrument.channels[0].kind == "brdf" else "-"
    print(f"values: {instrument.channels[0].kind} [{unit}]")
    return 0


def build_parser():
    """The argument parser of the ``bayespig`` command."""
    parser = argparse.ArgumentParser(prog="bayespig", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run the main job on the bundled example")
    demo.add_argument("--instrument", default="multi-angle-45")
    demo.set_defaults(func=_demo)
    return parser


def main(argv=None):
    """Entry point of the ``bayespig`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ValueError as error:
        print(f"bayespig: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
