"""Where the report's eps comes from, the verdict on an assumed eps, and user text in report.md."""

import argparse
import json
import re

import numpy as np
import pytest

from bayespig.commands.report import add_report_parser
from bayespig.demo import demo_measurements
from bayespig.report import quantities as q

HOSTILE_NAMES = ("<script>alert(1)</script>", "*x*|y")
HOSTILE_TITLE = "<b>T</b> *t*"


def _run(argv):
    parser = argparse.ArgumentParser(prog="bayespig")
    add_report_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


def _csv_without_eps(path, names=("on_black", "on_white")):
    """The demo's method-4 set at 6 wavelengths, its eps line removed, samples renamed."""
    demo_measurements(seed=4, wavelength_nm=np.arange(400.0, 701.0, 60.0)).to_csv(path)
    lines = [line for line in path.read_text().splitlines() if not line.startswith("# eps:")]
    text = "\n".join(lines) + "\n"
    for old, new in zip(("on_black", "on_white"), names):
        text = re.sub(rf"^{old},", f"{new},", text, flags=re.MULTILINE)
    path.write_text(text)
    return path


def test_one_step_report_says_eps_is_assumed_hedges_the_verdict_and_escapes_user_text(tmp_path, capsys):
    data = _csv_without_eps(tmp_path / "film.csv", HOSTILE_NAMES)
    out = tmp_path / "report"
    assert _run(["report", str(data), "--out", str(out), "--no-progress", "--title", HOSTILE_TITLE]) == 0
    printed = capsys.readouterr().out
    markdown = (out / "report.md").read_text()
    summary = json.loads((out / "summary.json").read_text())
    # eps: assumed, and where it came from
    assert "eps assumed: 0.05 (the default; pass --eps)" in markdown
    assert "eps known" not in markdown
    # the verdict is conditional on the assumed eps, in the report and on the terminal
    colour = summary["colour"]
    assert colour["verdict_assumes_eps"] is True
    verdict = "good enough for colour matching (&lt; 1)" if colour["good_enough_for_colour_matching"] \
        else "NOT good enough for colour matching (&gt;= 1)"
    assert (f"{verdict} if eps really is 0.05, which was only assumed (the default). The spread grows "
            "with eps: measure replicates to know your instrument's eps and pass --eps before judging.") in markdown
    assert "for colour matching if eps is the assumed 0.05 (pass --eps with your instrument's value)" in printed
    # user text: never raw HTML or markup outside the provenance code block
    body = markdown.split("```")[0] + markdown.split("```")[-1]
    assert "<script" not in body and "<b>" not in body
    assert markdown.startswith("# &lt;b&gt;T&lt;/b&gt; \\*t\\*\n")
    assert "- Samples: &lt;script&gt;alert(1)&lt;/script&gt; (r\\_s median 0.01;" in markdown
    assert "\\*x\\*\\|y (r\\_s median 0.95;" in markdown
    assert "| &lt;script&gt;alert(1)&lt;/script&gt; | 45as15 |" in markdown
    assert "| \\*x\\*\\|y | 45as15 |" in markdown
    html = (out / "report.html").read_text()
    assert "<script" not in html and "&lt;script&gt;alert(1)&lt;/script&gt;" in html


def test_report_passes_eps_on_and_names_it(tmp_path, monkeypatch):
    seen = {}

    def fake_write_report(source, out, **kwargs):
        seen.update(kwargs["infer_kwargs"])
        raise SystemExit(0)

    monkeypatch.setattr("bayespig.report.write_report", fake_write_report)
    data = tmp_path / "film.csv"
    data.write_text("x")
    with pytest.raises(SystemExit):
        _run(["report", str(data), "--out", str(tmp_path / "o"), "--eps", "0.02"])
    assert seen["eps"] == 0.02 and seen["eps_given_as"] == "--eps"
    with pytest.raises(SystemExit):
        _run(["report", str(data), "--out", str(tmp_path / "o"), "--eps", "infer"])
    assert seen["eps"] == "infer"


def test_eps_of_a_posterior_file_is_refused(demo_dir, tmp_path):
    with pytest.raises(ValueError) as error:
        _run(["report", str(demo_dir / "posterior.nc"), "--out", str(tmp_path / "o"), "--eps", "0.02"])
    assert str(error.value) == (
        f"--eps: {demo_dir / 'posterior.nc'} is a posterior, inferred with its own eps; --eps applies only "
        "when report infers from a measurement file (or run bayespig infer --eps)")
    with pytest.raises(ValueError, match=r"^--eps: must be a number in \(0, 1\) \(a relative error, e.g. 0.02 for 2 %\) or 'infer', got 'x'$"):
        _run(["report", str(demo_dir / "posterior.nc"), "--out", str(tmp_path / "o"), "--eps", "x"])


def test_eps_source_follows_infers_rule(demo_set):
    no_eps = type(demo_set)(demo_set.wavelength_nm, demo_set.samples,
                            metadata={k: v for k, v in demo_set.metadata.items() if k != "eps"})
    assert q.eps_source(None, no_eps) == {"kind": "default"}
    assert q.eps_source(None, demo_set) == {"kind": "file"}  # the file's "# eps:" line
    # ... when the run used it (not when infer fell back to its default instead)
    assert q.eps_source(None, demo_set, used=0.05) == {"kind": "file"}
    assert q.eps_source(None, demo_set, used=0.03) == {"kind": "default"}
    assert q.eps_source(0.02, demo_set, given_as="--eps") == {"kind": "given", "as": "--eps"}
    assert q.eps_source("infer", demo_set) == {"kind": "inferred"}


@pytest.mark.parametrize(("source", "text", "assumed"), [
    ({"kind": "default"}, "eps assumed: 0.05 (the default; pass --eps)", True),
    ({"kind": "given", "as": "--eps"}, "eps given: 0.05 (--eps)", False),
    ({"kind": "file"}, "eps given: 0.05 (the measurement file)", False),
    (None, ("eps known: 0.05 (where it came from is not recorded in the posterior; it equals the "
            "default, so it may only be assumed)"), True),
])
def test_eps_origin_words(demo_idata, source, text, assumed):
    idata = demo_idata.copy()
    idata.posterior.attrs = dict(idata.posterior.attrs)
    idata.posterior.attrs.pop(q.EPS_SOURCE_ATTR, None)
    if source is not None:
        idata.posterior.attrs[q.EPS_SOURCE_ATTR] = json.dumps(source)
    origin = q.eps_origin(idata)
    assert origin["text"] == text and origin["assumed"] is assumed
