"""``bayespig infer``: posterior of ``a`` and ``tau`` per wavelength (emcee, eq. 7) to netCDF."""

from __future__ import annotations

import json
import os
import sys
import warnings

import numpy as np

from .._atomic import write_file_set
from ..inference.arguments import eps_argument as eps_argument_api
from ..likelihood import noise_floor_argument
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

__all__ = ["add_infer_parser", "eps_argument", "run_infer"]



def add_infer_parser(subparsers):
    """Register ``bayespig infer``."""
    parser = subparsers.add_parser(
        "infer",
        help="posterior of a and tau per wavelength (emcee) -> DIR/posterior.nc, DIR/summary.csv",
        description="Sample the posterior of a, tau (and g, eps) per wavelength from a measurement "
        "file with the exact likelihood of the paper's noise model (eq. 7) and write the arviz "
        "InferenceData (DIR/posterior.nc) and a per-wavelength summary (DIR/summary.csv). "
        "Wavelengths that did not converge (R-hat > 1.01, ESS < 400) are listed.",
    )
    add_input_argument(parser, "measurements",
                       help="measurement file (bayespig CSV, ASTM E1392, wide spectral table)")
    parser.add_argument("--method", default="auto", type=method_argument, metavar="METHOD",
                        help=f"the paper's method whose samples enter the likelihood: {METHOD_HELP}, "
                             "auto (default: the most robust one the samples support) or general "
                             "(every sample)")
    add_output_argument(parser, "--out", kind="folder", required=True,
                        help="output folder (posterior.nc, summary.csv)")
    add_film_argument(parser)
    add_film_state_arguments(parser)
    add_substrate_argument(parser)
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--g", default="isotropic", choices=("isotropic", "free"),
                        help="Henyey-Greenstein g fixed at 0 (default) or a parameter")
    parser.add_argument("--eps", default=None,
                        help="relative measurement error of eq. (7), a number or 'infer' (default: the "
                             "file's eps, else 0.05)")
    parser.add_argument("--noise-floor", default=None,
                        help="additive noise floor of every value, in the values' units (1/sr for BRDF): a "
                             "number >= 0 or 'infer' (one per wavelength); with a floor, zero readings are data "
                             "(default: none, eq. 7 alone)")
    parser.add_argument("--roughness", default=None, metavar="free|NUMBER",
                        help="GGX roughness alpha of the films' top surface: 'free' (inferred, shared by all "
                             "wavelengths) or a number (fixed; 0 = smooth, the default)")
    parser.add_argument("--binder-index", default=None, metavar="free",
                        help="binder index n of the films' surface: 'free' (inferred with the roughness, "
                             "needs --roughness free; prior normal 1.45 +- 0.05 truncated to 1.37-1.77); "
                             "default: the file's n (1.45), fixed")
    parser.add_argument("--flakes", action="store_true",
                        help="the films hold effect pigments (metal or pearlescent flakes): infer their lobe "
                             "around the mirror direction, a flake reflectance per band and one flake "
                             "roughness (needs --roughness free; BRDF or 45/0 channels)")
    parser.add_argument("--incidence-offset", action="store_true",
                        help="infer the gonioreflectometer's offset per band: each BRDF reading is "
                             "max(f - b / cos theta_i, 0), a background subtracted in excess (exact zeros at "
                             "grazing incidence are its sign); needs --roughness free and --noise-floor infer")
    parser.add_argument("--censored-zeros", action="store_true",
                        help="the observed zeros are readings the instrument clipped at 0: their likelihood "
                             "is P(reading <= 0), not the Gaussian density at 0; needs --noise-floor")
    parser.add_argument("--exclude-occluded", action="store_true",
                        help="drop the films' BRDF geometries that read (nearly) nothing in every band amid bright "
                             "neighbours (blocked readings; bayespig check lists them)")
    parser.add_argument("--exclude-mirror", type=float, default=None, metavar="DEG",
                        help="drop the films' geometries within DEG degrees of the mirror direction")
    parser.add_argument("--max-angle", type=float, default=None, metavar="DEG",
                        help="drop the films' geometries with incidence or viewing angle beyond DEG degrees")
    parser.add_argument("--wavelengths", default=None, metavar="NM",
                        help="bands to fit: a range LOW-HIGH (e.g. 420-500) or a list (e.g. 450,550,650) [nm]")
    parser.add_argument("--walkers", type=int, default=None, help="walkers per ensemble (default 16)")
    parser.add_argument("--ensembles", type=int, default=None,
                        help="independent ensembles = arviz chains (default 4)")
    parser.add_argument("--max-steps", type=int, default=None, help="cap on steps per wavelength")
    add_verbosity_arguments(parser)
    parser.set_defaults(func=run_infer)
    return parser


def _number_or_infer(text, flag, check):
    """``text`` of ``flag`` as a number or ``"infer"`` (None when not given), checked by the
    API's own rule ``check`` (one rule and wording for the Python call and the command line)."""
    if text is None:
        return None
    try:
        value = text if text == "infer" else float(text)
    except ValueError:
        value = text
    try:
        return check(value)
    except (TypeError, ValueError) as error:
        text = str(error).replace(", 'infer' or None", " or 'infer'").replace("None (no floor), ", "")
        raise ValueError(f"{flag}: {text.split(' ', 1)[1]}") from None  # the flag for the argument name


def eps_argument(text):
    """``--eps`` text -> a number in (0, 1), ``"infer"`` or None (not given)."""
    return _number_or_infer(text, "--eps", eps_argument_api)


def _noise_floor_argument(text):
    """``--noise-floor`` text -> a number > 0, ``"infer"`` or None (not given or 0)."""
    return _number_or_infer(text, "--noise-floor", noise_floor_argument)


def _roughness_argument(text):
    """``--roughness`` text -> ``"free"``, a number >= 0, or None (not given)."""
    from ..inference.roughness import roughness_argument

    if text is None:
        return None
    try:
        value = text if text.strip() == "free" else float(text)
    except ValueError:
        value = text
    try:
        return roughness_argument(value, name="--roughness")
    except (TypeError, ValueError) as error:
        raise ValueError(str(error)) from None


def _binder_index_argument(text):
    """``--binder-index`` text -> ``"free"`` or None (not given)."""
    from ..inference.roughness import binder_index_argument

    try:
        return binder_index_argument(text, name="--binder-index")
    except (TypeError, ValueError) as error:
        raise ValueError(str(error)) from None


def _wavelengths_argument(text):
    """``(wavelengths, wavelength_range)`` from ``--wavelengths``: ``LOW-HIGH`` or ``W1,W2,...`` [nm]."""
    if text is None:
        return None, None
    expected = f"--wavelengths: expected a range LOW-HIGH (e.g. 420-500) or a list W1,W2,... [nm], got {text!r}"
    try:
        if "-" in text:
            low, high = (float(v) for v in text.split("-"))
            if not low <= high:
                raise ValueError
            return None, (low, high)
        return [float(v) for v in text.split(",")], None
    except ValueError:
        raise ValueError(expected) from None


def run_infer(args):
    """Run ``bayespig infer``; returns the exit status (flagged wavelengths are printed to stderr)."""
    from ..inference import ConvergenceWarning, InferenceSettings, diagnose, infer, save_inference
    from ..report.quantities import (
        card_factors,
        posterior_predictive_check,
        prior_edges,
        record_eps_source,
    )
    from ..report.summary_table import columns_to_csv, summary_columns

    eps = eps_argument(args.eps)
    noise_floor = _noise_floor_argument(args.noise_floor)
    roughness = _roughness_argument(args.roughness)
    binder_index = _binder_index_argument(args.binder_index)
    if binder_index == "free" and roughness != "free":
        raise ValueError("--binder-index free needs --roughness free (the binder index is inferred with the "
                         "surface's roughness)")
    if args.flakes and roughness != "free":
        raise ValueError("--flakes needs --roughness free (the flakes' roughness is inferred with the surface's)")
    if args.incidence_offset and (roughness != "free" or noise_floor != "infer"):
        raise ValueError("--incidence-offset needs --roughness free and --noise-floor infer (the offset is "
                         "sampled with the surface and the floor)")
    if args.censored_zeros and noise_floor is None:
        raise ValueError("--censored-zeros needs --noise-floor (a number > 0 or infer): without a floor a "
                         "reading of 0 has no probability")
    wavelengths, wavelength_range = _wavelengths_argument(args.wavelengths)
    overrides = {name: value for name, value in (("n_walkers", args.walkers),
                                                 ("n_ensembles", args.ensembles),
                                                 ("max_steps", args.max_steps)) if value is not None}
    settings = InferenceSettings(**overrides)
    if not os.path.exists(args.measurements):
        raise ValueError(f"{args.measurements}: file not found")
    measurements = read_film(args.measurements, args.film)
    if isinstance(measurements, (str, os.PathLike)):
        from ..data import read_measurements

        measurements = read_measurements(measurements, **film_state(args))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        idata = infer(measurements, method=args.method, seed=args.seed,
                      g=args.g, eps=eps, progress=not args.no_progress, settings=settings,
                      substrate_sd=args.substrate_sd, noise_floor=noise_floor, roughness=roughness,
                      binder_index=binder_index, flakes=args.flakes, incidence_offset=args.incidence_offset,
                      censored_zeros=args.censored_zeros, exclude_mirror_deg=args.exclude_mirror, exclude_occluded=args.exclude_occluded,
                      max_angle_deg=args.max_angle,
                      wavelengths=wavelengths, wavelength_range=wavelength_range)
        flagged = diagnose(idata, warn=False)
    for warning in caught:
        print(f"bayespig: warning: {warning.message}", file=sys.stderr)
    record_eps_source(idata, eps, measurements, given_as="--eps")
    check = posterior_predictive_check(idata)
    edges = prior_edges(idata)
    summary = summary_columns(idata, measurements=measurements, check=check, edges=edges)
    # both files or neither: a new posterior never sits beside an earlier run's summary
    written = write_file_set(args.out, {"posterior.nc": lambda path: save_inference(idata, path),
                                        "summary.csv": columns_to_csv(summary)})
    posterior_path, summary_path = written["posterior.nc"], written["summary.csv"]
    columns = [c for c in ("a_mean", "a_sd", "tau_mean", "tau_sd", "corr_a_log_tau", "a_r_hat",
                           "tau_r_hat", "a_ess_bulk", "tau_ess_bulk") if c in summary]
    print(f"bayespig infer: {idata.posterior.attrs['method']}, g {args.g}, "
          f"eps {idata.posterior.attrs['eps_mode']}, seed {args.seed}")
    print(_table(summary, columns))
    for factor in card_factors(idata):
        print(f"card {factor['card']}: r_s factor {factor['median']:.3f} [{factor['low']:.3f}, "
              f"{factor['high']:.3f}] (90 %; prior sd {factor['relative_sd']:g} in log f)")
    if "roughness" in idata.posterior:
        alpha = np.asarray(idata.posterior["roughness"].values, dtype=float).ravel()
        low, median, high = np.quantile(alpha, [0.05, 0.5, 0.95])
        print(f"surface roughness alpha {median:.4g} [{low:.4g}, {high:.4g}] (90 %; prior log-uniform on the "
              "rough tables' range)")
    elif idata.posterior.attrs.get("roughness_mode") == "fixed":
        print(f"surface roughness alpha {idata.posterior.attrs['roughness']:g} (fixed)")
    if "binder_index" in idata.posterior:
        n = np.asarray(idata.posterior["binder_index"].values, dtype=float).ravel()
        low, median, high = np.quantile(n, [0.05, 0.5, 0.95])
        print(f"binder index n {median:.4g} [{low:.4g}, {high:.4g}] (90 %; "
              f"prior {json.loads(idata.posterior.attrs['binder_index_prior'])['prior']})")
    if "flake_roughness" in idata.posterior:
        alpha_f = np.asarray(idata.posterior["flake_roughness"].values, dtype=float).ravel()
        low, median, high = np.quantile(alpha_f, [0.05, 0.5, 0.95])
        print(f"flake roughness alpha_f {median:.4g} [{low:.4g}, {high:.4g}] (90 %; "
              f"prior {json.loads(idata.posterior.attrs['flake_roughness_prior'])['prior']}); flake reflectance "
              "per band in the summary")
    print(f"wrote {posterior_path} and {summary_path}")
    sys.stdout.flush()
    untestable = np.flatnonzero(~check["testable"] & ~check["flagged"])
    if untestable.size:
        wl = idata.posterior["wavelength"].values
        print(f"bayespig: note: the model check cannot test anything at {untestable.size} wavelength(s) "
              f"({', '.join(f'{wl[i]:g}' for i in untestable)} nm): not more measured values than "
              f"parameters ({int(check['n_values'][untestable[0]])} <= {int(check['n_parameters'][untestable[0]])})",
              file=sys.stderr)
    misfit = np.flatnonzero(check["flagged"])
    if misfit.size:
        wl = idata.posterior["wavelength"].values
        print(f"bayespig: warning: the model cannot reproduce the measurements at {misfit.size} "
              f"wavelength(s) (posterior predictive p < {check['level']:g}): "
              + ", ".join(f"{wl[i]:g} nm (p = {check['p_value'][i]:.2g})" for i in misfit), file=sys.stderr)
    for edge in edges:
        print(f"bayespig: warning: {edge['text']}", file=sys.stderr)
    if flagged:
        print(f"bayespig: warning: {len(flagged)} wavelength(s) not converged (R-hat > 1.01 or "
              "ESS < 400); do not trust them:", file=sys.stderr)
        for line in flagged:
            print(f"  {line}", file=sys.stderr)
    return 0


def _table(columns, names):
    """The chosen summary columns as an aligned text table, one row per wavelength."""
    header = ["wavelength_nm"] + names
    rows = [[f"{w:g}"] + [f"{columns[n][i]:.4g}" for n in names] for i, w in enumerate(columns["wavelength_nm"])]
    widths = [max(len(r[k]) for r in rows + [header]) for k in range(len(header))]
    return "\n".join("  ".join(cell.rjust(width) for cell, width in zip(row, widths)) for row in [header] + rows)
