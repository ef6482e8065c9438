"""One uncertainty report per pigment of a library (the report the design card names).

For each pigment of a :class:`~bayespig.library.library.PigmentLibrary`:

- its two constants per wavelength (radiative transfer: relative absorption ``a`` and the
  extinction ``sigma`` per unit concentration and film thickness; Kubelka-Munk: ``K`` and
  ``S``) with 50 % and 90 % bands (figure and CSV);
- the films it came from (recipe, the stage of the build, the thickness's posterior, the
  posterior of its cards' albedo factors when the library was built with ``substrate_sd``) and
  how well each is reproduced (rms of ``log(measured / predicted)``);
- the correlations between its parameters: per wavelength between its two constants, and a
  corner plot of both constants at the wavelength where they are most correlated;
- the convergence of the stage that fitted it (steps, R-hat, ESS).

Written by :func:`write_pigment_reports` into one folder (``index.md`` plus per pigment
``<name>.md``, ``<name>.png``, ``<name>-corner.png``, ``<name>.csv``), atomically: the folder
holds all of it or what it had before.
"""

from __future__ import annotations

import re

import numpy as np

from .._atomic import write_folder_atomically
from .figures import corner_figure, parameter_figure, to_png
from .quantities import parameter_bands

__all__ = ["pigment_constants", "pigment_report", "write_pigment_reports"]

#: Physical constants shown per film model: (label, transform of the sampled pair, log axis).
_SHOWN = {
    "radiative-transfer": (("a (relative absorption) [-]", lambda c: c[..., 0], False),
                           ("sigma (extinction per unit concentration and thickness) [rel.]",
                            lambda c: np.exp(c[..., 1]), True)),
    "kubelka-munk": (("K per unit concentration [rel.]", lambda c: np.exp(c[..., 0]), True),
                     ("S per unit concentration [rel.]", lambda c: np.exp(c[..., 1]), True)),
}


def _safe(name):
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def pigment_constants(library, pigment):
    """Draws of the pigment's two physical constants, each (n_draws, n_wl), with labels."""
    if pigment not in library.pigments:
        raise ValueError(f"pigment {pigment!r} is not in the library (it has {', '.join(library.pigments)})")
    j = library.pigments.index(pigment)
    draws = library.constants[:, :, j, :]
    shown = _SHOWN.get(library.model)
    if shown is None:
        raise ValueError(f"no report layout for the film model {library.model!r}")
    return [(label, transform(draws), log) for label, transform, log in shown]


def _correlation(x, y):
    x = x - x.mean(axis=0)
    y = y - y.mean(axis=0)
    denominator = np.sqrt((x * x).sum(axis=0) * (y * y).sum(axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(denominator > 0, (x * y).sum(axis=0) / denominator, np.nan)


def _stage_of(library, pigment):
    for stage in library.stages:
        if pigment in stage.get("pigments", ()):
            return stage
    return {}


def _slowest_sentence(slowest):
    """Where a capped stage lost its time: the sampler coordinates with the longest integrated
    autocorrelation times (``[name, steps]`` pairs of the stage record's
    ``slowest_coordinates``; ``r_`` marks a per-wavelength constant's residual coordinate)."""
    named = ", ".join(f"{re.sub(r'^r_', '', str(name))} ({float(tau):.0f})" for name, tau in slowest)
    return ("Slowest to mix (integrated autocorrelation time in steps; the run-length rule waits for "
            "`min_autocorr_multiple`, by default 50, of them): "
            f"{named}. A longer run (`max_steps`) or a film that pins these down helps.")


def pigment_report(library, pigment):
    """Files of one pigment's report: relative path -> content (Markdown, PNG bytes, CSV)."""
    constants = pigment_constants(library, pigment)
    wl = np.asarray(library.wavelength_nm, dtype=float)
    name = _safe(pigment)
    bands = [parameter_bands(values) for _, values, _ in constants]
    figure = parameter_figure(wl, [{"bands": b, "label": label.split(" [")[0], "log": log}
                                   for b, (label, _, log) in zip(bands, constants)])
    raw = library.constants[:, :, library.pigments.index(pigment), :]
    rho = _correlation(raw[..., 0], raw[..., 1])
    k = int(np.nanargmax(np.abs(rho))) if np.isfinite(rho).any() else 0
    corner = corner_figure(raw[:, k, :], list(library.constant_names),
                           title=f"{pigment} at {wl[k]:g} nm (correlation {rho[k]:+.2f})")
    csv = ["wavelength_nm," + ",".join(f"{n}_median,{n}_q05,{n}_q95" for n in ("c1", "c2")) + ",correlation"]
    csv[0] = csv[0].replace("c1", _column(constants[0][0])).replace("c2", _column(constants[1][0]))
    for i, w in enumerate(wl):
        cells = [f"{w:g}"]
        for b in bands:
            cells += [f"{b['median'][i]:.6g}", f"{b['q05'][i]:.6g}", f"{b['q95'][i]:.6g}"]
        cells.append(f"{rho[i]:.3f}")
        csv.append(",".join(cells))
    films = [f for f in library.films if pigment in f.get("pigments", ()) and f.get("used", True)]
    stage = _stage_of(library, pigment)
    lines = [f"# {pigment}: uncertainty report", "",
             f"Library: {library.model} film model, {len(library.pigments)} pigments, "
             f"{wl.size} wavelengths ({wl[0]:g}-{wl[-1]:g} nm), {library.constants.shape[0]} posterior draws.", ""]
    if stage:
        rhat = max(stage.get("thickness_rhat_max", np.nan), stage.get("constants_rhat_max", np.nan))
        lines += [f"Fitted in stage {stage.get('stage', '?')} with {', '.join(stage.get('pigments', ()))} from "
                  f"{len(stage.get('films', ()))} films (pigments of earlier stages fixed at their medians): "
                  f"{stage.get('n_steps', '?')} steps"
                  + (f" after {stage['adaptation_rounds']} adaptation run(s)" if "adaptation_rounds" in stage else "")
                  + (" (capped: NOT converged)" if stage.get("max_steps_reached") else "")
                  + f", R-hat <= {rhat:.3f}, ESS >= {stage.get('constants_ess_min', np.nan):.0f} (constants), "
                  f"{stage.get('thickness_ess_min', np.nan):.0f} (thicknesses)"
                  + (f"; card factors R-hat <= {stage['card_factor_rhat_max']:.3f}, ESS >= "
                     f"{stage['card_factor_ess_min']:.0f}" if "card_factor_rhat_max" in stage else "") + ".", ""]
        if stage.get("max_steps_reached") and stage.get("slowest_coordinates"):
            lines += [_slowest_sentence(stage["slowest_coordinates"]), ""]
    lines += [f"![constants]({name}.png)", "", "## Constants (median and 90 % interval)", "",
              "| wavelength [nm] | " + " | ".join(label for label, _, _ in constants) + " | correlation |",
              "|---|---|---|---|"]
    for i in range(0, wl.size, max(1, -(-wl.size // 16))):
        cells = [f"{b['median'][i]:.4g} [{b['q05'][i]:.4g}, {b['q95'][i]:.4g}]" for b in bands]
        lines.append(f"| {wl[i]:g} | " + " | ".join(cells) + f" | {rho[i]:+.2f} |")
    lines += ["", f"Every wavelength: [{name}.csv]({name}.csv).", "",
              "## Correlations", "",
              f"Between the two constants per wavelength: from {np.nanmin(rho):+.2f} to {np.nanmax(rho):+.2f} "
              f"(strongest at {wl[k]:g} nm, corner plot below). A strong correlation is the paper's ravine: "
              "the films constrain a combination of the two better than each.", "",
              f"![corner]({name}-corner.png)", "",
              "## The films it came from", ""]
    if films:
        cards = any("card_factors" in f for f in films)
        conc = any("concentration_factors" in f for f in films)
        lines += ["| film | recipe (mass fractions) | stage | thickness h, median [90 %] | "
                  + ("card factors f = r_s / r_s,card, median [90 %] | " if cards else "")
                  + ("concentration factors f = D_eff / D, median [90 %] | " if conc else "")
                  + "rms log(measured/predicted) |",
                  "|---|---|---|---|" + ("---|" if cards else "") + ("---|" if conc else "") + "---|"]
        for f in films:
            recipe = ", ".join(f"{p} {w:.3g}" for p, w in f.get("recipe", {}).items())
            h = (f"{f['thickness_median']:.3g} [{f['thickness_q05']:.3g}, {f['thickness_q95']:.3g}]"
                 if f.get("thickness_median") is not None else "—")
            rms = f.get("rms_log_deviation")
            factors = ("; ".join(f"{c['card']} {c['median']:.3f} [{c['q05']:.3f}, {c['q95']:.3f}]"
                                 + (" (beyond 3 prior sd: absorbs a misfit?)" if c.get("implausible") else "")
                                 for c in f.get("card_factors") or ()) or "—") if cards else None
            concentration = ("; ".join(f"{c['pigment']} {c['median']:.3f} [{c['q05']:.3f}, {c['q95']:.3f}]"
                                       + (" (beyond 3 prior sd: absorbs a misfit?)" if c.get("implausible") else "")
                                       for c in f.get("concentration_factors") or ()) or "—") if conc else None
            lines.append(f"| {f['id']} | {recipe} | {f.get('stage', '')} | {h} | "
                         + (f"{factors} | " if cards else "")
                         + (f"{concentration} | " if conc else "")
                         + f"{'—' if rms is None else format(rms, '.3g')} |")
    else:
        lines.append("No film of the library contains it.")
    lines += ["", _provenance(library), ""]
    return {f"{name}.md": "\n".join(lines), f"{name}.png": to_png(figure), f"{name}-corner.png": to_png(corner),
            f"{name}.csv": "\n".join(csv) + "\n"}


def _column(label):
    return label.split(" ")[0]


def _provenance(library):
    p = library.provenance or {}
    items = [f"{key} {p[key]}" for key in ("seed", "eps", "substrate_sd", "concentration_sd") if key in p]
    versions = p.get("versions")
    if isinstance(versions, dict):
        items.append("versions " + ", ".join(f"{k} {v}" for k, v in versions.items()))
    return "Provenance: " + ("; ".join(items) if items else "not recorded") + "."


def write_pigment_reports(library, out_dir):
    """Write every pigment's report and an index into ``out_dir`` (atomically). Returns the report paths."""
    files = {}
    index = ["# Pigment library: uncertainty reports", "",
             f"{library.model} film model; {len(library.pigments)} pigments; {len(library.films)} films.", "",
             "| pigment | films | report |", "|---|---|---|"]
    for pigment in library.pigments:
        files.update(pigment_report(library, pigment))
        n_films = sum(1 for f in library.films if pigment in f.get("pigments", ()) and f.get("used", True))
        index.append(f"| {pigment} | {n_films} | [{_safe(pigment)}.md]({_safe(pigment)}.md) |")
    files["index.md"] = "\n".join(index) + "\n"
    out = write_folder_atomically(out_dir, files)
    return [out / f"{_safe(p)}.md" for p in library.pigments]
