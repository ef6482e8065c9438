"""What the report's figures show: units, legible corner plots, a truth that looks like no other line."""

import numpy as np
from matplotlib.colors import to_hex

from bayespig.report import figures as figs
from bayespig.report import quantities as q


def test_fit_figure_names_the_unit_of_each_kind_of_value(demo_idata):
    residuals = q.residuals_in_eps(demo_idata, max_draws=50)
    kinds = [q.measurement_kind(r) for r in residuals["rows"]]
    assert set(kinds) == {"brdf"}  # the demo is a multi-angle (BRDF) instrument
    fig = figs.fit_figure(q.wavelengths(demo_idata), residuals, ["on_black", "on_white"], kinds)
    assert [ax.get_ylabel() for ax in fig.axes] == ["BRDF [1/sr]", "BRDF [1/sr]"]
    assert figs._value_axis_label(["hemispherical", "transmittance"]) == \
        "hemispherical reflectance [fraction] / transmittance [fraction]"


def test_corner_plot_has_few_ticks_and_a_truth_unlike_the_quantiles():
    rng = np.random.default_rng(0)
    samples = np.column_stack([rng.normal(0.28, 0.008, 4000), rng.normal(0.05, 0.015, 4000)])
    fig = figs.corner_figure(samples, ["a", "log10 tau"], point=[0.282, 0.05], truth=[0.281, 0.046])
    fig.canvas.draw()
    for ax in fig.axes:
        low, high = sorted(ax.get_xlim())
        shown = [t for t in ax.get_xticks() if low <= t <= high]
        assert len(shown) <= figs.CORNER_MAX_TICKS  # corner's default (5) collides at 2 inches a panel
    legend = fig.legends[0]
    labels = [t.get_text() for t in legend.get_texts()]
    assert labels == ["5 %, 50 %, 95 % quantiles", "point fit", "truth (synthetic)"]
    quantile, point, truth = legend.legend_handles
    assert quantile.get_linestyle() == "--" and truth.get_linestyle() == "-"
    assert to_hex(truth.get_color()) not in {to_hex(quantile.get_color()), to_hex(point.get_color())}
    # the truth lines drawn on the panels have the legend's colour
    colours = {to_hex(line.get_color()) for ax in fig.axes for line in ax.get_lines()}
    assert to_hex(truth.get_color()) in colours


def test_report_text_says_the_fixed_g(demo_dir):
    markdown = (demo_dir / "report.md").read_text()
    assert ("- Phase function: g = 0 fixed (isotropic scattering; not inferred - bayespig infer --g free "
            "makes it a parameter)") in markdown


def test_corner_plot_of_one_parameter_is_a_histogram_with_the_same_marks():
    """An opaque film has only a: corner's truth lines fail on one parameter, so it is a histogram."""
    rng = np.random.default_rng(0)
    fig = figs.corner_figure(rng.normal(0.21, 0.005, (4000, 1)), ["a"], point=[0.2095], truth=[0.21],
                             title="550 nm")
    fig.canvas.draw()
    (ax,) = fig.axes
    assert ax.get_xlabel() == "a" and ax.get_title(loc="left").startswith("550 nm: a = 0.21 [")
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["5 %, 50 %, 95 % quantiles", "point fit", "truth (synthetic)"]
    vertical = [line for line in ax.get_lines() if len(line.get_xdata()) == 2 and len(set(line.get_xdata())) == 1]
    assert len(vertical) == 5  # three quantiles, the point fit and the truth
    low, high = sorted(ax.get_xlim())
    assert len([t for t in ax.get_xticks() if low <= t <= high]) <= figs.CORNER_MAX_TICKS + 1
