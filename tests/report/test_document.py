"""The document model renders one report twice: self-contained HTML and Markdown."""

import base64

from bayespig.report import document as doc

PNG = b"\x89PNG\r\n\x1a\n" + b"\x00" * 16  # a stand-in: only the bytes' round trip matters


def _blocks():
    return [doc.heading("Title <1>", 1), doc.paragraph("a < b & c"), doc.bullets(["x|y", "z"]),
            doc.table(["name", "value"], [["a|b", 1.5], ["<c>", "2"]]),
            doc.figure("fig", "caption & more"), doc.preformatted("{\n \"k\": 1\n}")]


def test_html_escapes_text_and_embeds_figures():
    html = doc.to_html(_blocks(), {"fig": PNG}, "T & t")
    assert "<title>T &amp; t</title>" in html
    assert "a &lt; b &amp; c" in html and "&lt;c&gt;" in html
    assert "Title &lt;1&gt;" in html
    data = html.split('src="data:image/png;base64,')[1].split('"')[0]
    assert base64.b64decode(data) == PNG
    assert html.startswith("<!DOCTYPE html>") and html.rstrip().endswith("</html>")


def test_markdown_links_figures_and_escapes_every_text():
    markdown = doc.to_markdown(_blocks())
    assert "# Title &lt;1&gt;" in markdown
    assert "![caption &amp; more](figures/fig.png)" in markdown
    assert "| a\\|b | 1.5 |" in markdown
    assert "- x\\|y" in markdown
    assert "```\n{\n \"k\": 1\n}\n```" in markdown


HOSTILE = ("<script>alert(1)</script>", "*x*|y")


def test_markdown_shows_user_text_as_written_never_as_markup():
    """Sample names, titles, file names: no raw HTML tag and no emphasis or table markup survives."""
    blocks = [doc.heading(HOSTILE[0], 1), doc.paragraph(f"Samples: {HOSTILE[0]}, {HOSTILE[1]}", lead=HOSTILE[1]),
              doc.bullets([HOSTILE[0], "# not a heading", "1. not a list"]),
              doc.table(["sample"], [[HOSTILE[0]], [HOSTILE[1]]]), doc.figure("f", HOSTILE[1]),
              doc.preformatted("```\n" + HOSTILE[0])]
    markdown = doc.to_markdown(blocks)
    assert "<script" not in markdown.replace("```\n<script", "")  # only inside the code block
    assert "# &lt;script&gt;alert(1)&lt;/script&gt;\n" in markdown
    assert "**\\*x\\*\\|y** Samples: &lt;script&gt;alert(1)&lt;/script&gt;, \\*x\\*\\|y" in markdown
    assert "- \\# not a heading\n- 1\\. not a list" in markdown
    assert "| \\*x\\*\\|y |" in markdown and "![\\*x\\*\\|y](figures/f.png)" in markdown
    # a fence longer than any backtick run inside keeps the code block closed
    assert "````\n```\n<script>alert(1)</script>\n````" in markdown
    html = doc.to_html(blocks, {"f": PNG}, HOSTILE[0])
    assert "<script>" not in html and "<strong>*x*|y</strong> Samples" in html
