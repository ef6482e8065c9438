"""The ``bayespig`` command: a thin shell over the Python API."""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings

import numpy as np

__all__ = ["main"]


def _instrument_argument(name):
    """A built-in instrument name, or comma-separated geometry labels such as ``45as15,45as110``."""
    from .instruments import BUILT_IN_INSTRUMENTS

    if name in BUILT_IN_INSTRUMENTS:
        return name
    try:
        from .instruments import get_instrument

        return get_instrument([label for label in name.split(",") if label.strip()])
    except ValueError:
        raise ValueError(
            f"unknown instrument {name!r}; built-in instruments: {', '.join(BUILT_IN_INSTRUMENTS)} "
            "(or comma-separated geometry labels such as 45as15,45as110)"
        ) from None


def _table_build(args):
    from .table import load_table, table_path

    instrument = _instrument_argument(args.instrument)
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        table = load_table(instrument, g=args.g, n=args.n, rebuild=args.rebuild, progress=True)
    for warning in caught:
        print(f"bayespig: warning: {warning.message}", file=sys.stderr)
    path = table_path(table.key)
    print(f"{table!r}")
    elapsed = time.perf_counter() - start
    print(f"  file {path} ({path.stat().st_size / 1e6:.2f} MB), ready in {elapsed:.1f} s")
    return 0


def _describe_cache_file(path):
    """Key, instrument and settings stored in a cached table (only its small metadata is read)."""
    try:
        with open(path, "rb") as handle, np.load(handle, allow_pickle=False) as data:
            key = str(data["__key__"]) if "__key__" in data.files else "?"
            text = str(data["__description__"]) if "__description__" in data.files else None
            name = str(data["__instrument__"]) if "__instrument__" in data.files else "?"
    except Exception as error:  # any unreadable file is reported, never trusted
        return {"status": f"unreadable ({type(error).__name__}); it will be rebuilt on next use"}
    if text is None:
        return {"key": key, "status": "no description (written by an older bayespig)"}
    description = json.loads(text)
    status = "ok" if path.name == f"table-{key}.npz" else "key does not match the file name"
    return {"key": key, "status": status, "name": name, **description}


def _format_settings(settings):
    s = settings
    g = "isotropic" if s["g_range"] is None else f"g in {s['g_range']} ({s['n_g']} nodes)"
    return (f"{g}; a: {s['n_a']} nodes (stretch {s['a_stretch']:g}); "
            f"tau: 2^{s['log2_tau_min']}..2^{s['log2_tau_max']}, {s['per_octave']}/octave, "
            f"+ opaque; quadrature {s['n_points']} points/interval, "
            f"start thickness {s['start_thickness']:.3g}")


def _table_info(args):
    from .table import cache_directory

    directory = cache_directory()
    print(f"cache directory: {directory} (set BAYESPIG_CACHE to move it)")
    files = sorted(directory.glob("table-*.npz")) if directory.is_dir() else []
    shown = 0
    for path in files:
        info = _describe_cache_file(path)
        name = info.get("name")
        if args.instrument and name != args.instrument:
            continue
        shown += 1
        size = f"{path.stat().st_size / 1e6:.2f} MB"
        if "instrument" not in info:
            print(f"{path.name}  {size}  {info['status']}")
            continue
        instrument = info["instrument"]
        labels = ", ".join(ch["label"] for ch in instrument["channels"])
        print(f"{info['key']}  {size}  {name}  n = {instrument['n']:g}  "
              f"[channels: {labels}]  bayespig {info['version']}")
        status = "" if info["status"] == "ok" else f"  ({info['status']})"
        print(f"    {_format_settings(info['settings'])}{status}")
    what = f" for instrument {args.instrument!r}" if args.instrument else ""
    print(f"{shown} cached table{'s' if shown != 1 else ''}{what}")
    return 0


def _check(args):
    from .data import check_report

    print(check_report(args.file))
    return 0


def _simulate(args):
    from .data import simulate_to_csv

    instrument = _instrument_argument(args.instrument)
    measurements = simulate_to_csv(args.out, a=args.a, tau=args.tau, g=args.g, design=args.design,
                                   instrument=instrument, eps=args.eps, seed=args.seed)
    print(f"wrote {args.out}: {len(measurements.samples)} samples, "
          f"{measurements.n_wavelengths} wavelengths, design {args.design}, eps {args.eps}, seed {args.seed}")
    return 0


def build_parser():
    """The argument parser of the ``bayespig`` command."""
    parser = argparse.ArgumentParser(prog="bayespig", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    from .commands import compare, design, infer, report, revigo, robustness

    report.add_demo_parser(sub)
    infer.add_infer_parser(sub)
    report.add_report_parser(sub)

    table = sub.add_parser("table", help="build and inspect the cached look-up tables")
    table_sub = table.add_subparsers(dest="table_command", required=True)
    build = table_sub.add_parser("build", help="build (or load) the cached table of an instrument")
    build.add_argument("--instrument", required=True,
                       help="built-in name (multi-angle-45, multi-angle-45-15, 8d-sci, 8d-sce, "
                            "45-0) or comma-separated geometry labels such as 45as15,45as110")
    build.add_argument("--g", choices=("isotropic", "free"), default="isotropic",
                       help="isotropic scattering only (default) or a g axis")
    build.add_argument("--n", type=float, default=1.45,
                       help="binder refractive index (default 1.45)")
    build.add_argument("--rebuild", action="store_true", help="ignore any cached file")
    build.set_defaults(func=_table_build)
    info = table_sub.add_parser("info", help="list the cached tables")
    info.add_argument("--instrument", help="only tables of this instrument (name as listed)")
    info.set_defaults(func=_table_info)

    check = sub.add_parser("check", help="say what a measurement file holds, or every problem in it")
    check.add_argument("file", help="bayespig CSV, ASTM E1392 file or wide spectral table")
    check.set_defaults(func=_check)

    simulate = sub.add_parser("simulate", help="simulate a measurement set (paper eq. 7 noise) as CSV")
    simulate.add_argument("--a", type=float, required=True, help="relative absorption a = 1 - omega")
    simulate.add_argument("--tau", type=float, required=True, help="optical thickness of the film group")
    simulate.add_argument("--g", type=float, default=0.0, help="phase-function parameter (default 0)")
    simulate.add_argument("--design", default="method4", choices=("method1", "method2", "method3", "method4"))
    simulate.add_argument("--instrument", default="multi-angle-45")
    simulate.add_argument("--eps", type=float, default=0.05, help="relative measurement error (default 0.05)")
    simulate.add_argument("--seed", type=int, default=0)
    simulate.add_argument("--out", required=True, help="CSV file to write")
    simulate.set_defaults(func=_simulate)

    robustness.add_robustness_parser(sub)
    compare.add_compare_parser(sub)
    design.add_design_parser(sub)
    revigo.add_revigo_parser(sub)
    return parser


def main(argv=None):
    """Entry point of the ``bayespig`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, OSError) as error:
        print(f"bayespig: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
