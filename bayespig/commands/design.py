"""``bayespig design``: which films to make — candidate sample sets ranked by expected precision."""

from __future__ import annotations

import json
import shlex
import sys
import tomllib
from pathlib import Path

from ..instruments import BUILT_IN_INSTRUMENTS
from ._arguments import add_output_argument, add_verbosity_arguments, parse_numbers

__all__ = ["add_design_parser", "run_design"]


def _command():
    """The command line, when run as ``bayespig design ...`` (for the report's header)."""
    argv = sys.argv[1:]
    return shlex.join(["bayespig", *argv]) if argv[:1] == ["design"] else None


#: Keys of a design file (JSON or TOML) and their defaults; flags override the file.
DEFAULTS = {
    "a": [0.01, 0.3],
    "tau_per_um": [0.02, 0.2],
    "thicknesses": [5.0, 10.0, 20.0],
    "substrates": ["black", "white"],
    "instruments": ["multi-angle-45"],
    "eps": 0.05,
    "draws": 32,
    "seed": 0,
    "objective": "both",
    "opaque": True,
    "glass": True,
    "spread": 0.3,
    "check": 0,
}


def _number_list(text, flag):
    return parse_numbers(text, flag).tolist()


def _words(text):
    return [v.strip() for v in str(text).split(",") if v.strip()]


def add_design_parser(subparsers):
    """Register ``bayespig design``."""
    parser = subparsers.add_parser(
        "design",
        help="rank candidate sample sets (films, thicknesses, substrates, instruments) by expected precision",
        description="Rank candidate sample sets by the expected posterior sd of a and tau over a prior of the "
        "pigment (Fisher information of eq. 7 from the look-up table's derivatives), optionally check the "
        "best ones by full posteriors on simulated data, and write OUT/design.html, design.md, design.json "
        "and figures/design.png. Settings come from an optional JSON/TOML file (keys: "
        + ", ".join(DEFAULTS) + ") and flags (flags win).",
    )
    parser.add_argument("config", nargs="?", default=None, help="design file (.json or .toml)")
    parser.add_argument("--a-range", default=None, help="range of a, e.g. 0.01,0.3 (log-uniform)")
    parser.add_argument("--tau-per-um", default=None,
                        help="range of the optical thickness of 1 um of film [1/um], e.g. 0.02,0.2")
    parser.add_argument("--thicknesses", default=None, help="film thicknesses you can make [um], e.g. 5,10,20")
    parser.add_argument("--substrates", default=None, help="substrates, e.g. black,white,grey:0.3")
    parser.add_argument("--instrument", default=None,
                        help="comma-separated instruments to consider, built-in names: "
                        + ", ".join(BUILT_IN_INSTRUMENTS) + " (default multi-angle-45)")
    parser.add_argument("--eps", type=float, default=None, help="relative error of eq. (7) (default 0.05)")
    parser.add_argument("--draws", type=int, default=None, help="prior draws per band (default 32)")
    parser.add_argument("--seed", type=int, default=None, help="seed of the prior draws (default 0)")
    parser.add_argument("--objective", choices=("both", "a", "tau"), default=None,
                        help="score: mean relative sd of a, of tau, or both (default)")
    parser.add_argument("--no-opaque", action="store_true", help="no opaque film can be made")
    parser.add_argument("--no-glass", action="store_true", help="no film on glass (transmittance)")
    parser.add_argument("--check", type=int, default=None,
                        help="check the best N candidates by full posteriors on simulated data (default 0)")
    add_output_argument(parser, "--out", kind="folder", required=True,
                        help="output folder (design.html, design.md, design.json, figures)")
    add_verbosity_arguments(parser)
    parser.set_defaults(func=run_design)
    return parser


def read_design_file(path):
    """Settings from a JSON or TOML design file (unknown keys are an error)."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: file not found")
    try:
        text = path.read_bytes()
    except OSError as error:
        raise ValueError(f"{path}: cannot read the design file ({error.strerror})") from None
    try:
        data = tomllib.loads(text.decode()) if path.suffix.lower() == ".toml" else json.loads(text)
    except (ValueError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: not a valid {'TOML' if path.suffix.lower() == '.toml' else 'JSON'} "
                         f"file: {error}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: the design file must hold a table/object of settings")  # noqa: TRY004 -- user input, printed by the CLI
    unknown = sorted(set(data) - set(DEFAULTS) - {"wavelengths"})
    if unknown:
        raise ValueError(f"{path}: unknown keys {', '.join(unknown)}; known: {', '.join(DEFAULTS)}, wavelengths")
    return data


def design_settings(args):
    """Merged settings: defaults, then the design file, then flags."""
    settings = dict(DEFAULTS)
    if args.config:
        settings.update(read_design_file(args.config))
    if args.a_range is not None:
        settings["a"] = _number_list(args.a_range, "--a-range")
    if args.tau_per_um is not None:
        settings["tau_per_um"] = _number_list(args.tau_per_um, "--tau-per-um")
    if args.thicknesses is not None:
        settings["thicknesses"] = _number_list(args.thicknesses, "--thicknesses")
    if args.substrates is not None:
        settings["substrates"] = _words(args.substrates)
    if args.instrument is not None:
        settings["instruments"] = _words(args.instrument)
    for name in ("eps", "draws", "seed", "objective", "check"):
        if getattr(args, name) is not None:
            settings[name] = getattr(args, name)
    if args.no_opaque:
        settings["opaque"] = False
    if args.no_glass:
        settings["glass"] = False
    return settings


def run_design(args):
    """Run ``bayespig design``; returns the exit status."""
    from ..inference import InferenceSettings
    from ..studies import design

    s = design_settings(args)
    prior_kwargs = {"a": s["a"], "tau_per_um": s["tau_per_um"], "spread": float(s["spread"])}
    if "wavelengths" in s:
        prior_kwargs["wavelengths"] = tuple(float(w) for w in s["wavelengths"])
    prior = design.DesignPrior(**prior_kwargs)
    candidates = design.candidate_designs(s["thicknesses"], s["substrates"], s["instruments"],
                                          opaque=bool(s["opaque"]), glass=bool(s["glass"]))
    draws = s["draws"]
    if not isinstance(draws, int) or draws < 1:
        raise ValueError(f"draws must be a positive integer, got {draws!r}")
    result = design.rank_designs(candidates, prior, eps=float(s["eps"]), n_draws=draws, seed=int(s["seed"]),
                                 objective=s["objective"])
    result.settings["design_input"] = {k: v for k, v in s.items()}
    if int(s["check"]) > 0:
        n_bands = prior.n_bands
        bands = sorted({0, n_bands // 2, n_bands - 1})
        design.check_designs(result, top=int(s["check"]), bands=bands, seed=int(s["seed"]),
                             settings=InferenceSettings(target_ess=400, draws_per_chain=512))
    files = design.write_design_report(result, args.out, command=_command())
    for row in result.summary()[:5]:
        print(f"{row['rank']:>3}  {row['description']}: sd(a)/a {100 * row['mean_rel_sd_a']:.2g} %, "
              f"sd(tau)/tau {100 * row['mean_rel_sd_tau']:.2g} %")
    print(f"wrote {files['html']}")
    return 0
