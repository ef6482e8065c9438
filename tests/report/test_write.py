"""write_report: inputs, atomic output, and the HTML page rendered by headless Chromium."""

import os
import re
import shutil
import subprocess

import numpy as np
import pytest

from bayespig.report import document, write_report
from bayespig.report import write as write_module

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"  # Debian's package (.ci/run installs it)
# Coloured pixels (max - min channel > COLOUR_SPREAD) in the screenshot: the page's own styling
# is black, white and grey, so colour comes from rendered figures (bands, corner plots, the
# ravine heat map). The top 4000 px hold the parameter figure, corner plots and the ravine;
# measured on the demo report: about 1 % coloured with images, < 0.05 % without.
COLOUR_SPREAD = 0.1
MIN_COLOURED_FRACTION = 0.002
MIN_COLOURED_RATIO = 5.0


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"observer": "CIE 1931 3 Degree"}, "observer"),
    ({"illuminant": "D66"}, "illuminant"),
])
def test_bad_colour_conditions_are_clear_errors(demo_idata, tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        write_report(demo_idata, tmp_path / "out", **kwargs)
    assert not (tmp_path / "out").exists()


def test_bad_inputs_are_clear_errors(tmp_path):
    with pytest.raises(ValueError, match="file not found"):
        write_report(tmp_path / "missing.nc", tmp_path / "out")
    with pytest.raises(ValueError, match="InferenceData"):
        write_report(42, tmp_path / "out")
    broken = tmp_path / "broken.nc"
    broken.write_text("not netCDF")
    with pytest.raises(ValueError, match="broken.nc"):
        write_report(broken, tmp_path / "out")


def test_an_error_while_writing_leaves_the_previous_report_intact(demo_dir, demo_idata, tmp_path,
                                                                  monkeypatch):
    out = tmp_path / "out"
    shutil.copytree(demo_dir, out)
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}

    def fail(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(document, "to_html", fail)
    with pytest.raises(RuntimeError, match="disk full"):
        write_report(demo_idata, out)
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before  # same files, same bytes, no temporary directory left


def test_report_infers_first_when_given_measurements(tmp_path):
    """A measurement file goes through bayespig.infer before the report (quick settings)."""
    from bayespig.demo import QUICK_SETTINGS, demo_measurements
    from bayespig.inference import InferenceSettings

    path = tmp_path / "film.csv"
    demo_measurements(seed=4, wavelength_nm=np.arange(400.0, 701.0, 60.0)).to_csv(path)
    settings = InferenceSettings(**QUICK_SETTINGS)
    result = write_report(path, tmp_path / "out", infer_kwargs={"settings": settings, "seed": 5},
                          corner_wavelengths=())
    assert result.files["html"].is_file() and result.files["netcdf"].is_file()
    assert result.summary["provenance"]["seed"] == 5
    assert result.summary["source"].endswith("film.csv")


def _screenshot(html, png, width=1200, height=4000):
    command = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
               f"--screenshot={png}", f"--window-size={width},{height}", html.as_uri()]
    env = dict(os.environ, HOME=str(png.parent))  # chromium wants a writable profile home
    return subprocess.run(command, check=False, capture_output=True, text=True, timeout=120,
                          env=env)


@pytest.mark.skipif(not os.path.exists(CHROMIUM),
                    reason="Chromium is not installed (apt-get install -y chromium; .ci/run does)")
def test_chromium_renders_the_figures(demo_dir, tmp_path):
    import matplotlib.image

    shot = tmp_path / "report.png"
    run = _screenshot(demo_dir / "report.html", shot)
    assert run.returncode == 0 and shot.is_file(), run.stderr[-2000:]
    image = matplotlib.image.imread(shot)[..., :3]
    coloured = (image.max(axis=-1) - image.min(axis=-1)) > COLOUR_SPREAD
    # the same page without its images: only text and tables, (almost) no colour
    bare = tmp_path / "bare.html"
    text = (demo_dir / "report.html").read_text()
    bare.write_text(_strip_images(text))
    run = _screenshot(bare, tmp_path / "bare.png")
    assert run.returncode == 0, run.stderr[-2000:]
    bare_image = matplotlib.image.imread(tmp_path / "bare.png")[..., :3]
    bare_coloured = (bare_image.max(axis=-1) - bare_image.min(axis=-1)) > COLOUR_SPREAD
    assert coloured.mean() > MIN_COLOURED_FRACTION
    assert coloured.mean() > MIN_COLOURED_RATIO * bare_coloured.mean()


def _strip_images(html):
    """The page with every embedded image removed."""
    return re.sub(r'<img src="data:image/png;base64,[^"]*"', '<img src=""', html)


def test_write_module_exports():
    assert write_module.write_report is write_report


def test_method1_with_inferred_eps(tmp_path):
    """Opaque film + film on glass (specular transmittance), eps a parameter: every section."""
    import bayespig
    from bayespig.demo import QUICK_SETTINGS
    from bayespig.inference import InferenceSettings, infer

    wl = np.arange(400.0, 701.0, 60.0)  # 6 wavelengths: the fewest colorimetry accepts
    measurements = bayespig.simulate(a=0.1, tau=1.0, design="method1", wavelengths=wl, seed=2)
    idata = infer(measurements, method="method1", eps="infer", seed=2, progress=False,
                  settings=InferenceSettings(**QUICK_SETTINGS))
    result = write_report(idata, tmp_path / "m1", measurements=measurements,
                          corner_wavelengths=(580.0,), save_posterior=False)
    assert "netcdf" not in result.files and not (tmp_path / "m1" / "posterior.nc").exists()
    summary = result.summary
    assert "eps" in summary["parameters"]
    kinds = {(r["sample"], r["channel"]) for r in summary["fit_quality"]}
    assert ("on_glass", "specular_transmittance") in kinds
    # colour only for reflectances; the unmeasured films include the film on black and white
    assert all(m["sample"] == "opaque" for m in summary["colour"]["measured"])
    films = {p["film"] for p in summary["colour"]["predicted_films"]}
    assert {"1 x tau on black", "1 x tau on white"} <= films
    assert any(p["measured"] for p in summary["colour"]["predicted_films"])  # opaque was measured
    assert (tmp_path / "m1" / "figures" / "corner_580nm.png").is_file()


def test_report_shows_where_the_model_cannot_reproduce_the_measurements(demo_idata, tmp_path):
    """A posterior whose observed value at one band is off by 10 eps: named at the top and in the summary."""
    from bayespig.report import quantities as q

    observed = np.asarray(demo_idata.observed_data["y"].values, dtype=float).copy()
    band = 1
    observed[band, 0] *= 1.0 + 10.0 * q.eps_per_value(demo_idata)[band, 0]
    corrupted = demo_idata.copy()
    corrupted.observed_data["y"].values[...] = observed
    result = write_report(corrupted, tmp_path / "misfit", save_posterior=False, corner_wavelengths=())
    wl = q.wavelengths(demo_idata)
    misfit = result.summary["model_check"]["misfit"]
    assert [m["wavelength_nm"] for m in misfit] == [wl[band]]
    markdown = (tmp_path / "misfit" / "report.md").read_text()
    glance = markdown.split("## At a glance")[1].split("\n## ")[0]
    assert f"cannot reproduce the measurements at 1 of {wl.size} wavelengths** ({wl[band]:g} nm" in glance
    csv_header = (tmp_path / "misfit" / "summary.csv").read_text().splitlines()[0]
    assert "ppc_p_value" in csv_header.split(",")


# ------------------------------------------------------------------------------------------
# the output folder: refused unless it is a report, replaced whole, nothing left on errors


def _hidden_siblings(folder):
    return sorted(p.name for p in folder.parent.iterdir() if p.name.startswith("."))


def test_a_folder_that_is_not_a_report_is_refused_before_any_work(demo_idata, tmp_path, monkeypatch):
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")

    def no_inference(*args, **kwargs):
        raise AssertionError("inferred before checking the output folder")

    monkeypatch.setattr(write_module, "load_posterior", no_inference)
    with pytest.raises(ValueError) as error:
        write_report(demo_idata, out)
    assert str(error.value) == (
        f"{out}: the folder exists and is not a bayespig report (it holds notes.txt); write the report "
        f"into a new folder (e.g. --out {out / 'report'}) or pass --overwrite to replace the whole folder")
    assert (out / "notes.txt").read_text() == "mine" and not _hidden_siblings(out)


def test_overwrite_replaces_the_whole_folder(demo_idata, tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    result = write_report(demo_idata, out, overwrite=True, corner_wavelengths=(), save_posterior=False)
    assert result.replaced and not (out / "notes.txt").exists() and (out / "report.html").is_file()
    assert not _hidden_siblings(out)


def test_a_file_as_output_folder_is_refused(demo_idata, tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(ValueError, match=f"^{re.escape(str(afile))}: exists and is not a folder; choose another"):
        write_report(demo_idata, afile)


def test_an_earlier_report_is_replaced_whole_without_stale_figures(demo_dir, demo_idata, tmp_path):
    out = tmp_path / "again"
    shutil.copytree(demo_dir, out)
    old_figures = {p.name for p in (out / "figures").iterdir()}
    assert {"corner_460nm.png", "ravine.png"} <= old_figures
    result = write_report(demo_idata, out, corner_wavelengths=(), save_posterior=False)
    assert result.replaced
    new_figures = {p.name for p in (out / "figures").iterdir()}
    assert not any(name.startswith("corner_") for name in new_figures)  # none left from the old report
    assert not (out / "posterior.nc").exists() and not (out / "measurements.csv").exists()
    assert sorted(p.name for p in out.iterdir()) == ["figures", "report.html", "report.md", "summary.csv",
                                                     "summary.json"]
    assert not _hidden_siblings(out)


def test_an_interrupted_report_leaves_nothing(demo_idata, tmp_path):
    """Ctrl-C while the files are being written: no output folder, no hidden staging folder."""
    def interrupt(path):
        assert path.parent.name.startswith(".report.") and path.parent.name.endswith(".tmp")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_report(demo_idata, tmp_path / "new" / "report", save_posterior=False, corner_wavelengths=(),
                     extra_files={"z.txt": interrupt})
    assert [p.name for p in tmp_path.rglob("*")] == ["new"]  # the parent stays, empty
