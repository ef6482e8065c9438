"""Figures of an uncertainty report (matplotlib, Agg backend; corner for corner plots).

Every function takes plain numbers (from :mod:`bayespig.report.quantities`) and returns a
matplotlib ``Figure`` built with the object-oriented API, never touching pyplot's global
state, so reports can be written from threads and servers without a display.
:func:`to_png` renders a figure to PNG bytes and closes it.
"""

from __future__ import annotations

import io

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = [
    "corner_figure",
    "diagnostics_figure",
    "fit_figure",
    "parameter_figure",
    "plane_of_incidence_figure",
    "ravine_figure",
    "residual_map_figure",
    "residual_figure",
    "swatch_figure",
    "to_png",
]

#: Resolution of the PNG figures [dots per inch].
DPI = 100
_BAND_ALPHA = {"90": 0.18, "50": 0.35}
_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2",
            "#7f7f7f", "#bcbd22", "#17becf")
#: At most this many ticks per corner-plot axis (more collide at 2 inches per panel).
CORNER_MAX_TICKS = 4
_POINT_COLOUR = "#1f77b4"
#: The synthetic truth: red and solid everywhere, never the black dashes of the quantiles.
_TRUTH_COLOUR = "#d62728"
_PANEL_COLOURS = tuple(c for c in _COLOURS if c != _TRUTH_COLOUR)
# Delta log L at the 1, 2, 3 sigma contours of a 2-D Gaussian (chi^2 with 2 dof / 2).
_SIGMA_LEVELS = (-5.914, -3.090, -1.148)


def _figure(width, height):
    fig = Figure(figsize=(width, height), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def to_png(fig):
    """PNG bytes of a figure."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI)
    return buffer.getvalue()


def _band_panel(ax, wl, bands, colour, label, truth=None, point=None, log=False):
    ax.fill_between(wl, bands["q05"], bands["q95"], color=colour, alpha=_BAND_ALPHA["90"], lw=0,
                    label="90 % interval")
    ax.fill_between(wl, bands["q25"], bands["q75"], color=colour, alpha=_BAND_ALPHA["50"], lw=0,
                    label="50 % interval")
    ax.plot(wl, bands["median"], color=colour, lw=1.8, label="posterior median")
    if point is not None and np.isfinite(point).any():
        ax.plot(wl, point, "k+", ms=6, label="point fit")
    if truth is not None:
        ax.plot(wl, truth, color=_TRUTH_COLOUR, ls="-", lw=1.2, marker="*", ms=6, label="truth (synthetic)")
    ax.set_ylabel(label)
    if log and np.nanmax(bands["q95"]) > 10.0 * np.nanmin(bands["q05"]):
        ax.set_yscale("log")
    ax.grid(alpha=0.3)


def parameter_figure(wl, panels):
    """Posterior bands of spectral parameters.

    Parameters
    ----------
    wl : numpy.ndarray
        Wavelengths [nm].
    panels : list of dict
        ``bands`` (from :func:`~bayespig.report.quantities.parameter_bands`), ``label``,
        optional ``point``, ``truth``, ``log``.
    """
    fig = _figure(7.5, 2.4 * len(panels) + 0.4)
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for k, (ax, panel) in enumerate(zip(axes, panels)):
        _band_panel(ax, wl, panel["bands"], _PANEL_COLOURS[k % len(_PANEL_COLOURS)], panel["label"],
                    panel.get("truth"), panel.get("point"), panel.get("log", False))
    axes[0].legend(fontsize=8, ncols=3, loc="best")
    axes[-1].set_xlabel("wavelength [nm]")
    return fig


def corner_figure(samples, labels, *, point=None, truth=None, title=""):
    """Corner plot (corner.corner) of posterior draws with the point fit marked.

    Parameters
    ----------
    samples : numpy.ndarray
        Shape (n_draws, n_parameters).
    labels : list of str
    point : sequence of float, optional
        Point fit, drawn as corner's ``truths`` (blue lines); NaN or None entries are not drawn.
    truth : sequence of float, optional
        Truth of a synthetic pigment, overplotted in black (dashed).
    """
    import corner

    n = samples.shape[1]
    if n == 1:  # corner's truth lines need a grid of axes: one parameter is a histogram
        return _histogram_figure(samples[:, 0], labels[0], point=_marks(point), truth=_marks(truth),
                                 title=title)
    fig = _figure(2.0 * n + 1.0, 2.0 * n + 1.0)
    fig.set_layout_engine(None)
    point = _marks(point)
    truth = _marks(truth)
    corner.corner(samples, labels=labels, truths=point, truth_color=_POINT_COLOUR, fig=fig,
                  quantiles=[0.05, 0.5, 0.95], show_titles=True, title_fmt=".3g",
                  title_kwargs={"fontsize": 9}, label_kwargs={"fontsize": 10},
                  levels=(0.5, 0.9), plot_datapoints=True, smooth=1.0, max_n_ticks=CORNER_MAX_TICKS)
    for ax in fig.axes:
        ax.tick_params(labelsize=8)
    if truth is not None:
        corner.overplot_lines(fig, truth, color=_TRUTH_COLOUR, ls="-", lw=2.0, alpha=0.8)
        corner.overplot_points(fig, [[np.nan if t is None else t for t in truth]], marker="*", ms=10,
                               color=_TRUTH_COLOUR)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color="k", ls="--", lw=1.0, label="5 %, 50 %, 95 % quantiles")]
    if point is not None:
        handles.append(Line2D([], [], color=_POINT_COLOUR, lw=1.5, label="point fit"))
    if truth is not None:
        handles.append(Line2D([], [], color=_TRUTH_COLOUR, lw=2.0, marker="*", ms=8, label="truth (synthetic)"))
    fig.legend(handles=handles, loc="upper right", fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=11, x=0.05, ha="left")
    fig.subplots_adjust(top=0.86 if n <= 2 else 0.92, bottom=0.14 if n <= 2 else 0.1,
                        left=0.16 if n <= 2 else 0.1)
    return fig


def _histogram_figure(draws, label, *, point=None, truth=None, title=""):
    """The posterior of one parameter: histogram, 5/50/95 % quantiles, point fit and truth."""
    fig = _figure(6.0, 3.2)
    ax = fig.subplots()
    ax.hist(draws, bins=40, color="0.35", histtype="step", lw=1.2)
    quantiles = np.quantile(draws, [0.05, 0.5, 0.95])
    for value in quantiles:
        ax.axvline(value, color="k", ls="--", lw=1.0)
    handles_labels = [("5 %, 50 %, 95 % quantiles", {"color": "k", "ls": "--", "lw": 1.0})]
    if point is not None and point[0] is not None:
        ax.axvline(point[0], color=_POINT_COLOUR, lw=1.5)
        handles_labels.append(("point fit", {"color": _POINT_COLOUR, "lw": 1.5}))
    if truth is not None and truth[0] is not None:
        ax.axvline(truth[0], color=_TRUTH_COLOUR, lw=2.0, alpha=0.8)
        ax.plot([truth[0]], [0.0], marker="*", ms=10, color=_TRUTH_COLOUR, clip_on=False)
        handles_labels.append(("truth (synthetic)", {"color": _TRUTH_COLOUR, "lw": 2.0, "marker": "*", "ms": 8}))
    from matplotlib.lines import Line2D

    ax.legend(handles=[Line2D([], [], label=text, **style) for text, style in handles_labels],
              fontsize=8, frameon=False, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_xlabel(label)
    ax.set_ylabel("draws")
    ax.locator_params(axis="x", nbins=CORNER_MAX_TICKS)
    ax.set_title(f"{title}: {label} = {quantiles[1]:.3g} [{quantiles[0]:.3g}, {quantiles[2]:.3g}]",
                 fontsize=10, loc="left")
    return fig


def _marks(values):
    """Marks for corner: non-finite entries become None (no line); None when nothing is left."""
    if values is None:
        return None
    marks = [None if v is None or not np.isfinite(v) else float(v) for v in values]
    return None if all(m is None for m in marks) else marks


def ravine_figure(ravine_wide, ravine_zoom, draws_a, draws_tau, *, point=None, truth=None):
    """Log-likelihood landscape over ``(a, tau)`` with posterior draws over it.

    Two panels: the whole prior box (where a ravine shows as a long valley) and a zoom on the
    posterior. Colour: ``log10(1 + max log L - log L)``, so the valley floor and the far walls
    both stay visible; white contours at Delta log L = -1.15, -3.09, -5.91 (1, 2, 3 sigma of a
    2-D Gaussian) from the grid maximum. The ``tau`` axis is logarithmic.
    """
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    fig = _figure(11.0, 4.6)
    axes = fig.subplots(1, 2)
    tick = FuncFormatter(lambda v, _: f"{10 ** v:.3g}")
    for ax, rv, title in ((axes[0], ravine_wide, "whole prior box"), (axes[1], ravine_zoom, "zoom")):
        ll = rv.log_likelihood
        finite = np.isfinite(ll)
        top = ll[finite].max() if finite.any() else 0.0
        depth = np.where(finite, top - ll, np.inf)
        shown = np.log10(1.0 + np.minimum(depth, 1e6))
        log_tau = np.log10(rv.tau)
        extent = (rv.a[0], rv.a[-1], log_tau[0], log_tau[-1])
        image = ax.imshow(shown, origin="lower", extent=extent, aspect="auto", cmap="viridis_r",
                          vmin=0.0, vmax=6.0, interpolation="nearest")
        ax.contour(rv.a, log_tau, -depth, levels=list(_SIGMA_LEVELS), colors="w", linewidths=0.8, linestyles="solid")
        ax.plot(draws_a, np.log10(draws_tau), ".", ms=1.5, color="#ff7f0e", alpha=0.4,
                label="posterior draws")
        if point is not None and np.all(np.isfinite(point)):
            ax.plot(point[0], np.log10(point[1]), "b+", ms=12, mew=2, label="point fit")
        if truth is not None and np.all(np.isfinite(truth)):
            ax.plot(truth[0], np.log10(truth[1]), "*", color=_TRUTH_COLOUR, mec="w", ms=14,
                    label="truth (synthetic)")
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
        ax.yaxis.set_major_formatter(tick)
        ax.xaxis.set_major_locator(MaxNLocator(6))
        ax.set_xlabel("relative absorption a")
        ax.set_ylabel("optical thickness tau (log scale)")
        ax.set_title(f"{rv.wavelength_nm:g} nm, {title}", fontsize=10)
    axes[1].legend(fontsize=8, loc="best")
    fig.colorbar(image, ax=axes, label="log10(1 + max log L - log L)", shrink=0.9)
    return fig


def fit_figure(wl, residuals, samples, kinds=None):
    """Measured values (points) vs posterior-predictive bands (lines), one panel per sample.

    ``kinds``: per value (column of the residuals), a key of :data:`VALUE_LABELS`, for the
    unit on the y axis (:func:`bayespig.report.quantities.measurement_kind`).
    """
    rows = residuals["rows"]
    fig = _figure(7.5, 2.8 * len(samples) + 0.3)
    axes = fig.subplots(len(samples), 1, sharex=True, squeeze=False)[:, 0]
    for ax, sample in zip(axes, samples):
        columns = [k for k, r in enumerate(rows) if r["sample"] == sample]
        for j, k in enumerate(columns):
            colour = _COLOURS[j % len(_COLOURS)]
            ax.fill_between(wl, residuals["predicted_q05"][:, k], residuals["predicted_q95"][:, k],
                            color=colour, alpha=0.25, lw=0)
            ax.plot(wl, residuals["predicted_mean"][:, k], color=colour, lw=1.2, label=rows[k]["channel"])
            ax.plot(wl, residuals["observed"][:, k], "o", color=colour, ms=3)
        ax.set_yscale("log")
        ax.set_title(f"{sample}: measured (dots), posterior predictive mean and 90 % band (lines)",
                     fontsize=9)
        ax.set_ylabel(_value_axis_label([kinds[k] for k in columns] if kinds is not None else []))
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, ncols=min(len(columns), 6), loc="best")
    axes[-1].set_xlabel("wavelength [nm]")
    return fig


#: Axis label of each kind of measured value, with its unit.
VALUE_LABELS = {
    "brdf": "BRDF [1/sr]",
    "hemispherical": "hemispherical reflectance [fraction]",
    "reflectance_factor": "reflectance factor [fraction]",
    "transmittance": "transmittance [fraction]",
}


def _value_axis_label(kinds):
    """The y label of a panel of measured values: their kind and unit (each, when mixed)."""
    kinds = list(dict.fromkeys(kinds))
    if not kinds or any(k not in VALUE_LABELS for k in kinds):
        return "measured value"
    return " / ".join(VALUE_LABELS[k] for k in kinds)


def residual_figure(wl, residuals, samples):
    """Residuals in units of eps per sample and geometry; +-1, 2, 3 marked."""
    rows = residuals["rows"]
    fig = _figure(7.5, 3.2)
    ax = fig.subplots()
    offsets = np.linspace(-3.0, 3.0, len(rows)) if len(rows) > 1 else np.zeros(1)
    markers = "osD^v<>ph*"
    for k, r in enumerate(rows):
        s = samples.index(r["sample"]) if r["sample"] in samples else 0
        channels = [q["channel"] for q in rows if q["sample"] == r["sample"]]
        colour = _COLOURS[channels.index(r["channel"]) % len(_COLOURS)]
        ax.plot(wl + offsets[k], residuals["z"][:, k], markers[s % len(markers)], color=colour, ms=3,
                label=f"{r['sample']} {r['channel']}")
    for level, alpha in ((1, 0.35), (2, 0.2), (3, 0.12)):
        ax.axhspan(-level, level, color="grey", alpha=alpha * 0.4, lw=0)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel("wavelength [nm]")
    ax.set_ylabel("residual / (eps x predicted)")
    ax.legend(fontsize=6, ncols=4, loc="upper center", bbox_to_anchor=(0.5, -0.22))
    ax.grid(alpha=0.3)
    return fig


def swatch_figure(rows, *, title=""):
    """Colour swatches: one row per entry with ``label`` and one or two sRGB colours.

    Parameters
    ----------
    rows : list of dict
        ``label``, ``colours`` (list of sRGB triples, e.g. measured and predicted),
        ``text`` (annotation on the right).
    """
    n = len(rows)
    fig = _figure(8.0, 0.32 * n + 0.9)
    ax = fig.subplots()
    for i, row in enumerate(rows):
        y = n - 1 - i
        for j, rgb in enumerate(row["colours"]):
            ax.add_patch(_rectangle((j * 1.05, y + 0.08), 1.0, 0.84, rgb))
        ax.text(-0.1, y + 0.5, row["label"], ha="right", va="center", fontsize=8)
        ax.text(len(row["colours"]) * 1.05 + 0.1, y + 0.5, row.get("text", ""), ha="left",
                va="center", fontsize=8)
    width = max(len(r["colours"]) for r in rows) if rows else 1
    ax.set_xlim(-4.2, width * 1.05 + 4.5)
    ax.set_ylim(0, max(n, 1))
    ax.axis("off")
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def _rectangle(xy, width, height, rgb):
    from matplotlib.patches import Rectangle

    return Rectangle(xy, width, height, facecolor=tuple(float(c) for c in rgb), edgecolor="0.5", lw=0.5)


def diagnostics_figure(wl, diag):
    """Bulk ESS and R-hat per wavelength with the flag thresholds."""
    fig = _figure(7.5, 4.2)
    ax_ess, ax_rhat = fig.subplots(2, 1, sharex=True)
    for k, (name, ess) in enumerate(diag["ess"].items()):
        colour = _COLOURS[k % len(_COLOURS)]
        ax_ess.plot(wl, ess, "o-", ms=3, color=colour, label=name)
        ax_rhat.plot(wl, diag["rhat"][name], "o-", ms=3, color=colour, label=name)
    ax_ess.axhline(diag["ess_min"], color="r", ls="--", lw=1, label=f"ESS {diag['ess_min']:g}")
    ax_ess.set_yscale("log")
    ax_ess.set_ylabel("bulk ESS")
    ax_ess.legend(fontsize=8, ncols=4)
    ax_rhat.axhline(diag["rhat_max"], color="r", ls="--", lw=1, label=f"R-hat {diag['rhat_max']:g}")
    ax_rhat.set_ylabel("R-hat")
    ax_rhat.set_xlabel("wavelength [nm]")
    for ax in (ax_ess, ax_rhat):
        ax.grid(alpha=0.3)
    return fig


def plane_of_incidence_figure(wl, gonio, band_indices, incidences):
    """Measured vs fitted BRDF in the plane of incidence, one panel per incidence angle.

    x: the signed viewing angle (``+theta_o`` on the specular side, ``delta_phi = 180``;
    ``-theta_o`` on the source side, ``delta_phi = 0``) [deg]; y: BRDF [1/sr], log scale.
    Lines: posterior median of the noise-free fit, bands: its 90 % interval, points: the
    measurements; one colour per band; a dotted line at the mirror direction.

    Parameters
    ----------
    wl : numpy.ndarray
        Wavelengths [nm].
    gonio : dict
        :func:`bayespig.report.quantities.gonio_residual_summary`.
    band_indices : sequence of int
        Wavelengths shown (indices into ``wl``).
    incidences : sequence of float
        Incidence angles of the panels [deg].
    """
    geometry = gonio["geometry"]
    n = len(incidences)
    ncols = min(n, 3)
    nrows = int(np.ceil(n / ncols))
    fig = _figure(4.2 * ncols + 0.4, 3.4 * nrows + 0.5)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False, sharey=True)).ravel()
    for ax, theta_i in zip(axes, incidences):
        member = np.flatnonzero(np.isclose(geometry["theta_i"], theta_i) & np.isfinite(geometry["signed_theta_o"]))
        order = member[np.argsort(geometry["signed_theta_o"][member])]
        x = geometry["signed_theta_o"][order]
        for j, i in enumerate(band_indices):
            colour = _PANEL_COLOURS[j % len(_PANEL_COLOURS)]
            ax.fill_between(x, gonio["fitted_q05"][i, order], gonio["fitted_q95"][i, order], color=colour,
                            alpha=0.25, lw=0)
            ax.plot(x, gonio["fitted_median"][i, order], color=colour, lw=1.3, label=f"{wl[i]:g} nm fit")
            ax.plot(x, gonio["measured"][i, order], "o", color=colour, ms=3.5, mfc="none",
                    label=f"{wl[i]:g} nm measured")
        ax.axvline(theta_i, color="k", ls=":", lw=1.0, label="mirror direction")
        ax.axvline(0.0, color="0.6", lw=0.6)
        ax.set_yscale("log")
        ax.set_title(f"incidence {theta_i:g}° ({order.size} in-plane geometries)", fontsize=10)
        ax.set_xlabel("signed viewing angle [deg] (+ specular side)")
        ax.grid(alpha=0.3, which="both")
    for ax in axes[::ncols]:
        ax.set_ylabel(VALUE_LABELS["brdf"])
    for ax in axes[n:]:
        ax.set_visible(False)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=min(len(labels), 4), fontsize=8)
    fig.suptitle("BRDF in the plane of incidence: measured (circles), fit median and 90 % band (lines)",
                 fontsize=11)
    return fig


#: The colour scale of the residual map ends at the 98th percentile of |residual|, within
#: these bounds [-] (so a few per cent show as colour, and gloss peaks do not wash out the rest).
RESIDUAL_MAP_LIMITS = (0.02, 1.0)


def residual_map_figure(gonio, incidences, *, title="median over bands"):
    """Relative residual (measured - fitted) / fitted over viewing directions, one polar panel
    per incidence angle.

    Angle of the polar plot: the azimuth of the viewing direction from that of the source
    (``delta_phi``, 180° on the specular side); radius: the viewing angle ``theta_o`` [deg];
    colour: the median over bands of the relative residual (diverging, symmetric, clipped at
    its 98th percentile of magnitude within :data:`RESIDUAL_MAP_LIMITS`); a star marks the
    mirror direction.
    """
    from matplotlib.colors import Normalize

    geometry = gonio["geometry"]
    with np.errstate(invalid="ignore"):
        shown = np.nanmedian(gonio["relative"], axis=0) if gonio["relative"].size else np.zeros(0)
    n = len(incidences)
    ncols = min(n, 3)
    nrows = int(np.ceil(n / ncols))
    fig = _figure(3.8 * ncols + 1.2, 3.8 * nrows + 0.6)
    finite = np.abs(shown[np.isfinite(shown)])
    limit = float(np.clip(np.quantile(finite, 0.98) if finite.size else RESIDUAL_MAP_LIMITS[0],
                          *RESIDUAL_MAP_LIMITS))
    norm = Normalize(-limit, limit)
    image = None
    axes = []
    for k, theta_i in enumerate(incidences):
        ax = fig.add_subplot(nrows, ncols, k + 1, projection="polar")
        axes.append(ax)
        member = np.isclose(geometry["theta_i"], theta_i)
        image = ax.scatter(np.radians(geometry["delta_phi"][member]), geometry["theta_o"][member],
                           c=np.clip(shown[member], -limit, limit), cmap="RdBu_r",
                           norm=norm, s=18, edgecolors="0.3", linewidths=0.3)
        ax.plot([np.pi], [theta_i], "*", color="k", ms=12, mfc="none", label="mirror direction")
        ax.set_rlim(0, 90)
        ax.set_rticks([30, 60, 90])
        ax.set_rlabel_position(247.5)  # in the empty half of isotropic data (delta_phi in 0-180)
        ax.set_yticklabels(["30°", "60°", "90°"], fontsize=7)
        ax.tick_params(axis="x", labelsize=7)
        ax.set_title(f"incidence {theta_i:g}°", fontsize=10)
    if axes:
        axes[0].legend(loc="upper left", bbox_to_anchor=(-0.25, 1.15), fontsize=7, frameon=False)
    if image is not None:
        fig.colorbar(image, ax=axes, shrink=0.8,
                     label=f"(measured - fitted) / fitted, {title} (clipped at +-{limit:.2g})")
    fig.suptitle("Relative residual over viewing directions: azimuth delta_phi from the source "
                 "(180° = specular side), radius theta_o [deg]", fontsize=10)
    return fig
