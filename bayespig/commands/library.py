"""``bayespig library build|report``, ``bayespig predict``, ``bayespig match``, ``bayespig colour-prediction``.

A pigment library (constants per pigment from all its films, :func:`bayespig.build_library`) and
what it is for: the colour of any recipe with a credible ΔE00 (:func:`bayespig.predict_paint`)
and the recipe that matches a target (:func:`bayespig.match_paint`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._atomic import atomic_path
from ..library.build import DEFAULT_NOISE_SCALE, NOISE_SCALES
from ._arguments import (add_input_argument, add_output_argument, add_substrate_argument, add_verbosity_arguments,
                         progress_printer)

__all__ = ["add_library_parsers", "recipe_argument", "spectrum_argument"]

INSTRUMENT_CHOICES = ("8d-sce", "8d-sci", "45-0")
#: Why the multi-angle built-ins are not among the choices (every instrument option names them all).
_NOT_MULTI_ANGLE = ("; the multi-angle-45 and multi-angle-45-15 BRDF instruments are not supported by the "
                    "library's film models")


def recipe_argument(text, flag="--recipe"):
    """``"ZincWhite:90,PrussianBlue:10"`` -> {"ZincWhite": 90.0, "PrussianBlue": 10.0}."""
    recipe = {}
    for part in text.replace(";", ",").split(","):
        if not part.strip():
            continue
        name, sep, amount = part.partition(":")
        if not sep or not name.strip():
            raise ValueError(f"{flag}: cannot read {part.strip()!r}: write PIGMENT:AMOUNT, separated by commas "
                             "(e.g. ZincWhite:90,PrussianBlue:10)")
        try:
            value = float(amount)
        except ValueError:
            raise ValueError(f"{flag}: the amount of {name.strip()!r} is not a number: {amount.strip()!r}") from None
        if name.strip() in recipe:
            raise ValueError(f"{flag}: {name.strip()!r} is given twice")
        recipe[name.strip()] = value
    if not recipe:
        raise ValueError(f"{flag}: no pigment given (write PIGMENT:AMOUNT,...)")
    return recipe


def spectrum_argument(text, wavelength_nm, flag):
    """A reflectance spectrum [fraction] at ``wavelength_nm`` from the command line.

    ``text`` is a number (the same reflectance at every wavelength, fraction), ``FILE`` (a CSV
    with columns ``wavelength_nm`` and ``reflectance``, fractions) or ``FILE:NAME`` (the row
    ``NAME`` of a wide spectral table in percent, e.g. the Revigo data's ``06B_w``). The file's
    wavelengths must include the library's.
    """
    try:
        value = float(text)
    except ValueError:
        pass
    else:
        if not (np.isfinite(value) and 0.0 <= value <= 1.5):
            raise ValueError(f"{flag}: a reflectance must be a fraction in [0, 1.5], got {text}")
        return np.full(len(wavelength_nm), value)
    path, sep, name = text.rpartition(":") if ":" in text and not Path(text).exists() else (text, "", "")
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{flag}: {path}: file not found")
    if sep:
        from ..data.spectral_table import read_spectral_table

        wl, spectra = read_spectral_table(path)
        if name not in spectra:
            raise ValueError(f"{flag}: {path} has no spectrum named {name!r}")
        values = spectra[name][0]
    else:
        import csv

        with open(path, newline="", encoding="utf-8") as handle:
            rows = list(csv.DictReader(row for row in handle if not row.lstrip().startswith("#")))
        if not rows or not {"wavelength_nm", "reflectance"} <= set(rows[0]):
            raise ValueError(f"{flag}: {path} needs the columns wavelength_nm and reflectance (fractions)")
        try:
            wl = np.array([float(r["wavelength_nm"]) for r in rows])
            values = np.array([float(r["reflectance"]) for r in rows])
        except ValueError as error:
            raise ValueError(f"{flag}: {path}: {error}") from None
        bad = np.flatnonzero(~np.isfinite(values) | (values < 0) | (values > 1.5))
        if bad.size:
            raise ValueError(f"{path}, row {bad[0] + 2}, field 'reflectance': must be a fraction in [0, 1.5], "
                             f"got {values[bad[0]]:g}")
    wl = np.asarray(wl, dtype=float)
    out = []
    for w in wavelength_nm:
        hit = np.flatnonzero(np.isclose(wl, w, atol=1e-6))
        if not hit.size:
            raise ValueError(f"{flag}: {path} has no value at {w:g} nm (the library's wavelengths are "
                             f"{wavelength_nm[0]:g}-{wavelength_nm[-1]:g} nm)")
        out.append(values[hit[0]])
    return np.array(out)


def _thickness_text(text):
    word = text.strip().lower()
    if word in ("opaque", "unknown", "fit"):
        return word
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"--thickness must be a relative thickness > 0, 'opaque' or 'unknown', got {text!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"--thickness must be > 0, got {text}")
    return value


def add_library_parsers(subparsers):
    """Register ``library``, ``predict``, ``match`` and ``colour-prediction``."""
    library = subparsers.add_parser("library", help="pigment libraries: build one from films, report on it",
                                    description="A pigment library: each pigment's constants per wavelength "
                                    "with their posterior, from every film that contains it.")
    actions = library.add_subparsers(dest="library_command", required=True, metavar="ACTION")
    build = actions.add_parser("build", help="build a library from films with recipes -> LIBRARY.nc",
                               description="Build a pigment library from measured films whose recipes are "
                               "known (a Revigo data folder, or a bayespig CSV with a recipe column).")
    add_input_argument(build, "measurements", help="Revigo data folder or bayespig CSV file with recipes")
    add_output_argument(build, "--out", kind="file", required=True, help="library file to write (.nc)")
    build.add_argument("--model", choices=("radiative-transfer", "kubelka-munk"), default="radiative-transfer",
                       help="film model (default radiative-transfer; kubelka-munk: the two-constant baseline)")
    build.add_argument("--films", default=None, help="only these films (comma-separated ids)")
    build.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    add_substrate_argument(build)  # as 'bayespig infer --substrate-sd': one factor per card and film
    build.add_argument("--concentration-sd", type=float, default=None, metavar="SD",
                       help="the recipes' uncertainty: a factor on the concentration of each film's minor pigments "
                       "fixed from an earlier stage, log f ~ N(0, SD^2) (e.g. 0.3; default: the recipes as given)")
    build.add_argument("--noise-scale", choices=NOISE_SCALES, default=DEFAULT_NOISE_SCALE,
                       help="what the relative error eps is relative to: the measured value (default) or the "
                       "predicted one (eq. 7); they differ on films the model cannot reproduce")
    build.add_argument("--cross-validate", action="store_true",
                       help="also predict each mixture film by a library built without it and store the model "
                       "error learned from those predictions (calibrated to hold 90 %% of them), which 'bayespig "
                       "predict' adds to its region; one more build per mixture film (leave-one-out sampler "
                       "settings, without card or concentration factors)")
    add_verbosity_arguments(build)
    build.set_defaults(func=run_library_build)

    report = actions.add_parser("report", help="one uncertainty report per pigment -> DIR/",
                                description="Write one uncertainty report per pigment of a library: its "
                                "constants with 90 %% bands, the films it came from and how well each is "
                                "reproduced, the correlations between its parameters.")
    report.add_argument("library", help="library file (.nc) from 'bayespig library build'")
    add_output_argument(report, "--out", kind="folder", required=True, help="folder to write")
    add_verbosity_arguments(report)
    report.set_defaults(func=run_library_report)

    predict = subparsers.add_parser("predict", help="colour of a recipe from a library, with a credible ΔE00",
                                    description="Predict the spectrum and CIELAB of a recipe from a pigment "
                                    "library, with the 90 %% credible ΔE00 region (posterior of the constants "
                                    "and the library's cross-validated model error).")
    predict.add_argument("library", help="library file (.nc)")
    predict.add_argument("--recipe", required=True, help="PIGMENT:AMOUNT,... (mass; normalised)")
    predict.add_argument("--thickness", default="opaque", help="relative film thickness, 'opaque' (default) or "
                         "'unknown' (drawn from the library's films)")
    predict.add_argument("--substrate", default=None, help="card reflectance in air: a fraction, a CSV "
                         "(wavelength_nm, reflectance) or SPECTRAL_TABLE:NAME; needed unless opaque")
    predict.add_argument("--instrument", choices=INSTRUMENT_CHOICES, default="8d-sce",
                         help="instrument of the prediction: 8d-sce (default), 8d-sci or 45-0" + _NOT_MULTI_ANGLE)
    predict.add_argument("--illuminant", default="D65", help="illuminant of the CIELAB values (default D65)")
    predict.add_argument("--draws", type=int, default=200, help="predictive draws (default 200)")
    predict.add_argument("--seed", type=int, default=0, help="seed of the draws (default 0)")
    add_output_argument(predict, "--out", kind="file", default=None, help="CSV of the predicted spectrum")
    add_verbosity_arguments(predict)
    predict.set_defaults(func=run_predict)

    match = subparsers.add_parser("match", help="the recipe of library pigments that matches a target",
                                  description="Find the amounts of the allowed pigments (and the thickness "
                                  "with --thickness fit) whose predicted colour is closest to the target "
                                  "(CIEDE2000), with the metamerism index under a second illuminant, the "
                                  "credible ΔE00 of the match and the spread of equally good recipes.")
    match.add_argument("library", help="library file (.nc)")
    target = match.add_mutually_exclusive_group(required=True)
    target.add_argument("--target", help="target spectrum: a CSV (wavelength_nm, reflectance) or "
                        "SPECTRAL_TABLE:NAME")
    target.add_argument("--lab", help="target CIELAB: L,a,b")
    match.add_argument("--pigments", default=None, help="allowed pigments, comma-separated (default all)")
    match.add_argument("--thickness", default="opaque", help="'opaque' (default), 'fit', or a relative thickness")
    match.add_argument("--substrate", default=None, help="card reflectance (as for predict)")
    match.add_argument("--instrument", choices=INSTRUMENT_CHOICES, default="8d-sce",
                       help="instrument the target was measured with: 8d-sce (default), 8d-sci or 45-0"
                       + _NOT_MULTI_ANGLE)
    match.add_argument("--illuminant", default="D65", help="illuminant of the match (default D65)")
    match.add_argument("--second-illuminant", default="A",
                       help="illuminant of the metamerism index (default A)")
    match.add_argument("--seed", type=int, default=0, help="seed of the credible ΔE00 and the spread (default 0)")
    add_verbosity_arguments(match)
    match.set_defaults(func=run_match)

    study = subparsers.add_parser("colour-prediction", help="leave-one-film-out colour prediction vs Kubelka-Munk",
                                  description="Predict every mixture film of the Revigo series 01-15 by a library "
                                  "built without it, with bayespig's and with Kubelka-Munk's film model, and write "
                                  "reports/colour-prediction.md (50-80 minutes on 2 cores).")
    study.add_argument("path", nargs="?", default=None, help="Revigo data folder (default as 'bayespig revigo')")
    add_output_argument(study, "--report", kind="file", default="reports/colour-prediction.md",
                        help="Markdown report to write")
    study.add_argument("--films", default=None, help="only these targets (comma-separated ids)")
    study.add_argument("--series", default=None, help="only the targets of these series (comma-separated, e.g. 06,12)")
    study.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    study.add_argument("--noise-scale", choices=NOISE_SCALES, default=DEFAULT_NOISE_SCALE,
                       help="every build's noise scale, as 'bayespig library build --noise-scale' (default measured)")
    add_verbosity_arguments(study)
    study.set_defaults(func=run_colour_prediction)


def run_library_build(args):
    from ..data.spectral_table import read_revigo
    from ..inference.arguments import check_substrate_sd
    from ..inference.concentration_factors import check_concentration_sd
    from ..library import build_library
    from ..library.recipes import film_recipes
    from ..library.validation import cross_validate

    substrate_sd = check_substrate_sd(args.substrate_sd)  # before any file is read: infer's message
    concentration_sd = check_concentration_sd(args.concentration_sd)
    path = Path(args.measurements)
    sets = read_revigo(path) if path.is_dir() or args.cross_validate else path
    if args.films and isinstance(sets, dict):
        wanted = [f.strip() for f in args.films.split(",") if f.strip()]
        missing = [f for f in wanted if f not in sets]
        if missing:
            raise ValueError(f"--films: {missing[0]!r} is not a film of {path}")
        sets = {f: sets[f] for f in wanted}
    if args.cross_validate:  # before any build: the held-out films it needs
        mixtures = [f for f, recipe in film_recipes(sets).items() if len(recipe.amounts) >= 2]
        if len(mixtures) < 2:
            raise ValueError(f"--cross-validate needs at least two mixture films (two or more pigments); "
                             f"{path} has {len(mixtures)}{': ' + mixtures[0] if mixtures else ''}")
    library = build_library(sets, model=args.model, seed=args.seed, progress=not args.no_progress,
                            substrate_sd=substrate_sd, concentration_sd=concentration_sd,
                            noise_scale=args.noise_scale)
    if args.cross_validate:
        library, predictions = cross_validate(library, sets, seed=args.seed, progress=progress_printer(args))
        calibration = library.provenance["model_error"]["calibration"]
        print(f"model error from {len(predictions)} held-out films"
              + (f", calibration factor {calibration['factor']:.2f} at {calibration['level']:.0%}"
                 if calibration else " (too few bands for a colour: not calibrated)"))
    library.save(args.out)
    print(f"wrote {args.out}: {len(library.pigments)} pigments ({', '.join(library.pigments)}), "
          f"{library.wavelength_nm.size} wavelengths, model {library.model}"
          + ("" if substrate_sd is None else f", card factors (prior sd {substrate_sd:g} in log f)")
          + ("" if concentration_sd is None else f", concentration factors (prior sd {concentration_sd:g} in log f)")
          + ("" if library.model_error is None else ", cross-validated model error"))
    return 0


def run_library_report(args):
    from ..library import load_library
    from ..report.pigment import write_pigment_reports

    library = load_library(args.library)
    paths = write_pigment_reports(library, args.out)
    print(f"wrote {len(paths)} pigment reports to {args.out}")
    return 0


def run_predict(args):
    from ..library import load_library, predict_paint

    library = load_library(args.library)
    recipe = recipe_argument(args.recipe)
    thickness = _thickness_text(args.thickness)
    if thickness == "fit":
        raise ValueError("--thickness fit is for 'bayespig match'; give a thickness, 'opaque' or 'unknown'")
    substrate = None if args.substrate is None else spectrum_argument(args.substrate, library.wavelength_nm,
                                                                      "--substrate")
    prediction = predict_paint(library, recipe, thickness=thickness, instrument=args.instrument,
                               substrate=substrate, seed=args.seed, n_draws=args.draws, illuminant=args.illuminant)
    L, a, b = prediction.Lab_median
    print(f"recipe {', '.join(f'{p} {w:.3f}' for p, w in prediction.recipe.amounts.items())} (mass fractions), "
          f"thickness {prediction.thickness}, {args.instrument}, {args.illuminant}")
    print(f"CIELAB L* {L:.2f} a* {a:.2f} b* {b:.2f}; {prediction.level:.0%} credible region: ΔE00 <= "
          f"{prediction.delta_E_radius:.2f}" + ("" if prediction.model_error else
                                                " (constants only: the library has no cross-validated model error)"))
    if args.out:
        low, high = np.quantile(prediction.reflectance, [0.05, 0.95], axis=0)
        with atomic_path(args.out) as tmp:
            with open(tmp, "w", encoding="utf-8") as handle:
                handle.write(f"# bayespig predict {args.library} --recipe {args.recipe} --seed {args.seed}\n")
                handle.write("wavelength_nm,reflectance_median,reflectance_q05,reflectance_q95\n")
                for row in zip(library.wavelength_nm, prediction.reflectance_median, low, high):
                    handle.write(",".join(f"{v:.6g}" for v in row) + "\n")
        print(f"wrote {args.out}")
    return 0


def run_match(args):
    from ..library import load_library, match_paint

    library = load_library(args.library)
    if args.lab is not None:
        try:
            target = np.array([float(v) for v in args.lab.split(",")])
        except ValueError:
            raise ValueError(f"--lab must be three numbers L,a,b, got {args.lab!r}") from None
        if target.shape != (3,):
            raise ValueError(f"--lab must be three numbers L,a,b, got {args.lab!r}")
    else:
        target = spectrum_argument(args.target, library.wavelength_nm, "--target")
    pigments = None if args.pigments is None else [p.strip() for p in args.pigments.split(",") if p.strip()]
    substrate = None if args.substrate is None else spectrum_argument(args.substrate, library.wavelength_nm,
                                                                      "--substrate")
    thickness = _thickness_text(args.thickness)
    if thickness == "unknown":
        raise ValueError("--thickness for a match is 'opaque', 'fit' or a relative thickness")
    result = match_paint(library, target, pigments=pigments, instrument=args.instrument, thickness=thickness,
                         substrate=substrate, seed=args.seed, illuminant=args.illuminant,
                         second_illuminant=args.second_illuminant)
    print("recipe (mass fractions): " + ", ".join(f"{p} {w:.3f}" for p, w in result.recipe.amounts.items())
          + (f"; thickness {result.thickness:.3g}" if isinstance(result.thickness, float) else ""))
    print(f"ΔE00 {result.delta_E:.2f} under {result.illuminant}; credible ΔE00 median {result.delta_E_median:.2f}, "
          f"{result.level:.0%} <= {result.delta_E_upper:.2f}")
    if result.metamerism_index is not None:
        print(f"metamerism index (ΔE00 under {result.second_illuminant}): {result.metamerism_index:.2f}")
    for p, (low, high) in result.amounts_interval.items():
        print(f"  {p}: equally good matches {low:.3f}-{high:.3f}")
    return 0


def run_colour_prediction(args):
    from ..studies.colour_prediction import colour_prediction_report, colour_prediction_study
    from .revigo import revigo_folder

    path = revigo_folder(args.path)
    films = None if args.films is None else [f.strip() for f in args.films.split(",") if f.strip()]
    command = "bayespig colour-prediction"
    if args.series is not None:
        from ..data.spectral_table import read_revigo
        from ..library.recipes import film_recipes
        from ..studies.colour_prediction import target_films

        series = [s.strip() for s in args.series.split(",") if s.strip()]
        sets = read_revigo(path)
        films = [f for f in target_films(sets, film_recipes(sets)) if f[:2] in series and (films is None or f in films)]
        if not films:
            raise ValueError(f"--series {args.series}: no mixture film of series 01-15 among them")
        command += f" --series {','.join(series)}"
    if args.noise_scale != DEFAULT_NOISE_SCALE:
        command += f" --noise-scale {args.noise_scale}"
    study = colour_prediction_study(path, films=films, seed=args.seed, progress=progress_printer(args),
                                    noise_scale=args.noise_scale)
    text = colour_prediction_report(study, command=command)
    with atomic_path(args.report) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    print(f"wrote {args.report}: {len(study.predictions)} predictions")
    return 0
