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


def test_markdown_links_figures_and_escapes_table_pipes():
    markdown = doc.to_markdown(_blocks())
    assert "# Title <1>" in markdown
    assert "![caption & more](figures/fig.png)" in markdown
    assert "| a\\|b | 1.5 |" in markdown
    assert "- x|y" in markdown  # pipes only matter inside tables
    assert "```\n{\n \"k\": 1\n}\n```" in markdown
