"""bayespig: the optical properties of a pigment (absorption a and optical thickness tau per
wavelength, with their uncertainty) from measurements of paint films, and the studies of the
paper's methods.

Each command reads measurement files (bayespig CSV, ASTM E1392 or a wide spectral table) or
simulates them, and writes its outputs only when it has finished (Ctrl-C writes nothing).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import sys
import threading
import time
import traceback
import warnings

import numpy as np

from ._versions import __version__
from .commands._arguments import (
    add_film_state_arguments,
    add_input_argument,
    add_output_argument,
    add_verbosity_arguments,
    check_input_path,
    check_output_path,
    film_state,
    instrument_argument,
    instrument_help,
    paper_method_argument,
)

__all__ = ["INTERRUPTED_MESSAGE", "build_parser", "main"]

#: The one line printed when the user interrupts a command (Ctrl-C); the exit status is 130.
INTERRUPTED_MESSAGE = "bayespig: interrupted; nothing written"
#: Exit status after Ctrl-C (128 + SIGINT, the shell convention).
EXIT_INTERRUPTED = 130
#: Exit status when stdout is closed by its reader (128 + SIGPIPE, as the shell's own tools).
EXIT_BROKEN_PIPE = 141
#: Exit status of ``bayespig check`` for a readable file that ``infer`` refuses as it stands.
EXIT_NOT_INFERABLE = 1
#: Exit status of a user's mistake (bad argument, unreadable file), as argparse uses.
EXIT_USAGE = 2
#: ArviZ 0.x announces its 1.0 refactor by a FutureWarning on import (``arviz<1`` is pinned):
#: a notice to developers, not to a user of the command.
ARVIZ_REFACTOR_NOTICE = r"(?s).*ArviZ is undergoing"


def _table_build(args):
    from .table import load_table, table_path

    instrument = instrument_argument(args.instrument)
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        table = load_table(instrument, g=args.g, n=args.n, rebuild=args.rebuild, progress=not args.no_progress)
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


def _instrument_label(channel_labels):
    """A table's instrument as ``--instrument`` names it: the built-in name, else its geometry labels."""
    from .instruments import BUILT_IN_INSTRUMENTS, get_instrument

    for name in BUILT_IN_INSTRUMENTS:
        if [ch.label for ch in get_instrument(name).channels] == list(channel_labels):
            return name
    return ",".join(channel_labels)


def _table_info(args):
    from .table import cache_directory

    directory = cache_directory()
    print(f"cache directory: {directory} (set BAYESPIG_CACHE to move it)")
    files = sorted(directory.glob("table-*.npz")) if directory.is_dir() else []
    shown = 0
    for path in files:
        info = _describe_cache_file(path)
        instrument = info.get("instrument")
        name = None if instrument is None else _instrument_label([ch["label"] for ch in instrument["channels"]])
        if args.instrument and name != args.instrument:
            continue
        shown += 1
        size = f"{path.stat().st_size / 1e6:.2f} MB"
        if instrument is None:
            print(f"{path.name}  {size}  {info['status']}")
            continue
        labels = ", ".join(ch["label"] for ch in instrument["channels"])
        print(f"{info['key']}  {size}  {name}  n = {instrument['n']:g}  "
              f"[channels: {labels}]  bayespig {info['version']}")
        status = "" if info["status"] == "ok" else f"  ({info['status']})"
        print(f"    {_format_settings(info['settings'])}{status}")
    what = f" for instrument {args.instrument!r}" if args.instrument else ""
    print(f"{shown} cached table{'s' if shown != 1 else ''}{what}")
    return 0


#: ``bayespig check`` reports BRDF rows viewed within this angle of the mirror direction [deg]:
#: there the surface's own gloss dominates (--exclude-mirror drops them).
NEAR_MIRROR_DEG = 5.0
#: ``bayespig check`` calls BRDF values above this implausible for a paint's body [1/sr]: a
#: perfectly white Lambertian surface gives 1/pi = 0.32 1/sr, so 10 1/sr is 30x that, gloss.
GLOSS_BRDF_PER_SR = 10.0
#: Rows listed at most per finding of ``bayespig check`` (without --verbose).
CHECK_ROWS_SHOWN = 8


def _rows_text(sources, verbose):
    """``row 12, 15, ...`` of (file, line) sources (their file is the one checked)."""
    rows = sorted({source[1] for source in sources if source is not None})
    if not rows:
        return ""
    shown = rows if verbose or len(rows) <= CHECK_ROWS_SHOWN else rows[:CHECK_ROWS_SHOWN]
    more = "" if len(shown) == len(rows) else f", ... ({len(rows) - len(shown)} more)"
    return f"row{'s' if len(rows) > 1 else ''} {', '.join(map(str, shown))}{more}"


def _check_notes(measurements, verbose=False):
    """What ``bayespig check`` adds to a set's summary: whether infer takes it, and its findings.

    Returns
    -------
    (bool, list of str)
        True when :func:`bayespig.infer` accepts the set as it stands (the same validation:
        :meth:`~bayespig.likelihood.Problem.from_measurements` and
        :func:`~bayespig.likelihood.check_observed`, without a noise floor); the lines.
    """
    from .likelihood import Problem, check_observed
    from .selection import (
        OCCLUSION_RADIUS_DEG,
        OCCLUSION_RATIO,
        mirror_distance_deg,
        occluded_geometries,
    )

    wavelength = np.asarray(measurements.wavelength_nm, dtype=float)
    lines = []
    brdf = [m for s in measurements.samples for m in s.measurements if m.kind == "brdf"]
    if brdf:
        distance = mirror_distance_deg(np.array([m.theta_i for m in brdf]),
                                       np.array([m.theta_o for m in brdf]),
                                       np.array([m.delta_phi for m in brdf]))
        near = np.flatnonzero(distance < NEAR_MIRROR_DEG)
        if near.size:
            closest = int(near[np.argmin(distance[near])])
            lines.append(f"  {near.size} BRDF geometr{'ies' if near.size > 1 else 'y'} within "
                         f"{NEAR_MIRROR_DEG:g}° of the mirror direction (closest {distance[closest]:.2g}°, "
                         f"{brdf[closest].label}): the surface's gloss dominates there; "
                         f"--exclude-mirror {NEAR_MIRROR_DEG:g} leaves them out "
                         f"({_rows_text([brdf[k].source for k in near], verbose)})")
        values = np.array([m.values for m in brdf])
        high = np.argwhere(values > GLOSS_BRDF_PER_SR)
        if high.size:
            k, band = np.unravel_index(int(np.argmax(values)), values.shape)
            lines.append(f"  {len(high)} BRDF value{'s' if len(high) > 1 else ''} above "
                         f"{GLOSS_BRDF_PER_SR:g} 1/sr, implausible for a paint's body (a white "
                         f"Lambertian surface gives 0.32 1/sr): gloss; the largest {values[k, band]:.3g} "
                         f"1/sr at {wavelength[band]:g} nm, {brdf[k].label} "
                         f"({_rows_text([brdf[i].source for i in np.unique(high[:, 0])], verbose)})")
    occluded = occluded_geometries(measurements)
    if occluded:
        rows = [m for name, ks in occluded.items() for m in (measurements.sample(name).measurements[k] for k in ks)]
        brightest = max(float(np.max(m.values)) for m in rows)
        lines.append(f"  {len(rows)} BRDF geometr{'ies' if len(rows) > 1 else 'y'} read at most {brightest:.2g} 1/sr in "
                     f"every band, below {OCCLUSION_RATIO:g} of their neighbours' (same incidence, viewing within "
                     f"{OCCLUSION_RADIUS_DEG:g}°): blocked readings, not the paint "
                     f"({', '.join(m.label for m in rows[:CHECK_ROWS_SHOWN])}"
                     f"{', ...' if len(rows) > CHECK_ROWS_SHOWN else ''}); --exclude-occluded leaves them out "
                     f"({_rows_text([m.source for m in rows], verbose)})")
    reflectance = [m for s in measurements.samples for m in s.measurements]
    zeros = np.array([m.values == 0 for m in reflectance])
    if zeros.any():
        per_band = zeros.sum(axis=0)
        bands = ", ".join(f"{w:g} nm {c}" for w, c in zip(wavelength, per_band) if c)
        rows = [reflectance[k].source for k in np.flatnonzero(zeros.any(axis=1))]
        lines.append(f"  {int(zeros.sum())} exact zero{'s' if zeros.sum() > 1 else ''} in "
                     f"{len(rows)} geometr{'ies' if len(rows) > 1 else 'y'}; per band: {bands} "
                     f"({_rows_text(rows, verbose)})")
    accepted = True
    try:
        check_observed(Problem.from_measurements(measurements))
    except ValueError as error:
        accepted = False
        lines.append(f"  infer refuses it as it stands: {error}")
    if lines:
        lines.insert(0, "findings:")
    return accepted, lines


def _check(args):
    from .data import check_report

    accepted = []

    def notes(measurements):
        result = _check_notes(measurements, args.verbose)
        accepted.append(result[0])
        return result

    print(check_report(args.file, **film_state(args), verbose=args.verbose, notes=notes))
    return EXIT_NOT_INFERABLE if False in accepted else 0


def _simulate(args):
    from .data import simulate_to_csv

    instrument = instrument_argument(args.instrument)
    measurements = simulate_to_csv(args.out, a=args.a, tau=args.tau, g=args.g, design=args.design,
                                   instrument=instrument, eps=args.eps, seed=args.seed)
    print(f"wrote {args.out}: {len(measurements.samples)} samples, "
          f"{measurements.n_wavelengths} wavelengths, design {args.design}, eps {args.eps}, seed {args.seed}")
    return 0


def build_parser():
    """The argument parser of the ``bayespig`` command."""
    from .commands import compare, cornell, design, infer, library, report, revigo, robustness
    from .instruments import BUILT_IN_INSTRUMENTS

    parser = argparse.ArgumentParser(prog="bayespig", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-V", "--version", action="version", version=f"bayespig {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    report.add_demo_parser(sub)
    infer.add_infer_parser(sub)
    report.add_report_parser(sub)

    table = sub.add_parser("table", help="build and inspect the cached look-up tables",
                           description="The look-up tables of the radiative-transfer model, one per "
                           "instrument, g axis and binder index, cached on disk ($BAYESPIG_CACHE).")
    table_sub = table.add_subparsers(dest="table_command", required=True, metavar="ACTION")
    build = table_sub.add_parser("build", help="build (or load) the cached table of an instrument",
                                 description="Build the look-up table of an instrument (minutes the first "
                                 "time) or load it from the cache, and say where it is.")
    build.add_argument("--instrument", required=True, help=instrument_help())
    build.add_argument("--g", choices=("isotropic", "free"), default="isotropic",
                       help="isotropic scattering only (default) or a g axis")
    build.add_argument("--n", type=float, default=1.45,
                       help="binder refractive index (default 1.45)")
    build.add_argument("--rebuild", action="store_true", help="ignore any cached file")
    add_verbosity_arguments(build)
    build.set_defaults(func=_table_build)
    info = table_sub.add_parser("info", help="list the cached tables",
                                description="List the cached look-up tables: instrument, channels, "
                                "settings and size.")
    info.add_argument("--instrument", default=None,
                      help="only the tables of this instrument, named as listed: a built-in name ("
                      + ", ".join(BUILT_IN_INSTRUMENTS) + ") or comma-separated geometry labels")
    add_verbosity_arguments(info)
    info.set_defaults(func=_table_info)

    check = sub.add_parser("check", help="say what a measurement file holds, or every problem in it",
                           description="Read a measurement file and say what it holds (samples, "
                           "wavelengths, which of the paper's methods it supports), or list every "
                           "problem in it with its row and field. Exit status 2 when it cannot be read, 1 when "
                           "it can but 'bayespig infer' refuses it as it stands (e.g. zero readings "
                           "without --noise-floor).")
    add_input_argument(check, "file", help="bayespig CSV, ASTM E1392 file or wide spectral table")
    add_film_state_arguments(check)
    add_verbosity_arguments(check)
    check.set_defaults(func=_check)

    simulate = sub.add_parser("simulate", help="simulate a measurement set (paper eq. 7 noise) as CSV",
                              description="Simulate the films of one of the paper's designs for a "
                              "pigment (a, tau, g), with the multiplicative noise of eq. (7), and "
                              "write them as a bayespig CSV file (the truth in its metadata).")
    simulate.add_argument("--a", type=float, required=True,
                          help="relative absorption a = 1 - omega of the pigment [-]")
    simulate.add_argument("--tau", type=float, required=True,
                          help="optical thickness of the thin film(s) [-]")
    simulate.add_argument("--g", type=float, default=0.0,
                          help="Henyey-Greenstein phase-function parameter (default 0)")
    simulate.add_argument("--design", default="method4", type=paper_method_argument,
                          metavar="{1,2,3,4,method1,...,method4}",
                          help="the films of the paper's method (default method4: one film on black "
                          "and on white)")
    simulate.add_argument("--instrument", default="multi-angle-45",
                          help=instrument_help(default="multi-angle-45"))
    simulate.add_argument("--eps", type=float, default=0.05,
                          help="relative measurement error of eq. (7) (default 0.05)")
    simulate.add_argument("--seed", type=int, default=0, help="seed of the noise (default 0)")
    add_output_argument(simulate, "--out", kind="file", required=True, help="CSV file to write")
    add_verbosity_arguments(simulate)
    simulate.set_defaults(func=_simulate)

    robustness.add_robustness_parser(sub)
    compare.add_compare_parser(sub)
    design.add_design_parser(sub)
    revigo.add_revigo_parser(sub)
    cornell.add_cornell_parser(sub)
    library.add_library_parsers(sub)
    return parser


def _inside_emcee_likelihood(frame):
    """True when ``frame`` runs inside emcee's wrapper of the log-probability function."""
    wrapper = getattr(sys.modules.get("emcee.ensemble"), "_FunctionWrapper", None)
    code = None if wrapper is None else getattr(wrapper.__call__, "__code__", None)
    while code is not None and frame is not None:
        if frame.f_code is code:
            return True
        frame = frame.f_back
    return False


class _InterruptOutsideEmcee:
    """Ctrl-C raises KeyboardInterrupt, but never inside emcee's log-probability wrapper.

    emcee's ``_FunctionWrapper`` prints "emcee: Exception while calling your likelihood
    function", the walkers' positions and a traceback for any exception raised in the
    likelihood, Ctrl-C included. When the interrupt lands there it is retried every
    :attr:`RETRY_S` seconds (SIGALRM) until the wrapper has returned, a few milliseconds later.
    A no-op outside the main thread, where signals cannot be handled, and without SIGALRM.
    """

    #: Retry interval of a deferred interrupt [s].
    RETRY_S = 0.005

    def __enter__(self):
        self._saved = None
        if (threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer")
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
            self._saved = (signal.signal(signal.SIGINT, self._handler),
                           signal.signal(signal.SIGALRM, self._handler))
        return self

    def __exit__(self, *exc):
        if self._saved is not None:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGINT, self._saved[0])
            signal.signal(signal.SIGALRM, self._saved[1])
        return False

    def _handler(self, signum, frame):
        if _inside_emcee_likelihood(frame):
            signal.setitimer(signal.ITIMER_REAL, self.RETRY_S)
            return
        raise KeyboardInterrupt


def _check_paths(args):
    """Check every input and output path of the command before it runs.

    Returns
    -------
    list of pathlib.Path
        Folders the outputs will create (removed again when the command does not finish).
    """
    for dest in getattr(args, "input_paths", ()):
        if getattr(args, dest) is not None:
            check_input_path(getattr(args, dest))
    created = []
    for dest, kind in (getattr(args, "output_paths", None) or {}).items():
        if getattr(args, dest) is not None:
            missing = check_output_path(getattr(args, dest), kind)
            if missing is not None:
                created.append(missing)
    return created


def _remove_created(created):
    """Remove the folders this run created for its outputs (it did not finish)."""
    for folder in created:
        shutil.rmtree(folder, ignore_errors=True)


def main(argv=None):
    """Entry point of the ``bayespig`` command; returns the exit status.

    A user's mistake prints one ``bayespig: error: ...`` line (exit 2); Ctrl-C prints
    :data:`INTERRUPTED_MESSAGE` (exit 130). Either way no output is left behind: the paths are
    checked before any work, every file is written atomically at the end, and folders the
    run created are removed.
    """
    created, verbose = [], False
    # inherited by the local pools' forked workers, which import arviz too
    warnings.filterwarnings("ignore", message=ARVIZ_REFACTOR_NOTICE, category=FutureWarning)
    try:
        args = build_parser().parse_args(argv)
        verbose = getattr(args, "verbose", False)
        created = _check_paths(args)
        with _InterruptOutsideEmcee():
            return args.func(args)
    except BrokenPipeError:  # the reader of stdout went away (``bayespig ... | head``)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except KeyboardInterrupt:
        _remove_created(created)
        print(INTERRUPTED_MESSAGE, file=sys.stderr)
        return EXIT_INTERRUPTED
    except (ValueError, OSError) as error:
        _remove_created(created)
        if verbose:
            traceback.print_exc()
        print(f"bayespig: error: {error}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
