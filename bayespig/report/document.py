"""A minimal document model rendered twice: self-contained HTML and a Markdown twin.

A report is a list of blocks (headings, paragraphs, lists, tables, figures, preformatted
text). :func:`to_html` embeds every figure as a base64 PNG, so the page opens offline in
any browser; :func:`to_markdown` links the same figures as PNG files next to it.
"""

from __future__ import annotations

import base64
import html
from dataclasses import dataclass

__all__ = [
    "Block",
    "bullets",
    "figure",
    "heading",
    "paragraph",
    "preformatted",
    "table",
    "to_html",
    "to_markdown",
]


@dataclass(frozen=True)
class Block:
    """One block: ``kind`` in {"h1", "h2", "h3", "p", "list", "table", "figure", "pre"}."""

    kind: str
    content: object
    extra: object = None


def heading(text, level=2):
    """A heading of level 1-3."""
    return Block(f"h{level}", text)


def paragraph(text):
    """A paragraph of plain text."""
    return Block("p", text)


def bullets(items):
    """A bulleted list of plain-text items."""
    return Block("list", list(items))


def table(header, rows):
    """A table: ``header`` is a list of column titles, ``rows`` lists of cells (str or numbers)."""
    return Block("table", list(header), [list(r) for r in rows])


def figure(name, caption):
    """A figure: ``name`` is the key of its PNG bytes (file ``figures/<name>.png``)."""
    return Block("figure", name, caption)


def preformatted(text):
    """Preformatted text (settings, versions)."""
    return Block("pre", text)


_CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 0 auto;
       max-width: 1100px; padding: 1.5em; color: #222; line-height: 1.45; }
h1 { font-size: 1.6em; border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { font-size: 1.3em; border-bottom: 1px solid #bbb; margin-top: 2em; }
h3 { font-size: 1.1em; }
table { border-collapse: collapse; font-size: .85em; margin: .8em 0; }
th, td { border: 1px solid #ccc; padding: .25em .55em; text-align: right; }
th { background: #f2f2f2; }
td:first-child, th:first-child { text-align: left; }
figure { margin: 1em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: .88em; color: #444; margin-top: .3em; }
pre { background: #f6f6f6; padding: .8em; overflow-x: auto; font-size: .8em; }
"""


def _cell(value):
    return value if isinstance(value, str) else f"{value}"


def to_html(blocks, figures, title):
    """Self-contained HTML text.

    Parameters
    ----------
    blocks : list of Block
    figures : dict
        Figure name -> PNG bytes.
    title : str
    """
    esc = html.escape
    parts = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
             '<meta name="viewport" content="width=device-width, initial-scale=1">',
             f"<title>{esc(title)}</title>", f"<style>{_CSS}</style>", "</head>", "<body>"]
    for block in blocks:
        kind = block.kind
        if kind in ("h1", "h2", "h3"):
            anchor = "".join(c if c.isalnum() else "-" for c in block.content.lower()).strip("-")
            parts.append(f'<{kind} id="{esc(anchor)}">{esc(block.content)}</{kind}>')
        elif kind == "p":
            parts.append(f"<p>{esc(block.content)}</p>")
        elif kind == "list":
            parts.append("<ul>" + "".join(f"<li>{esc(_cell(i))}</li>" for i in block.content) + "</ul>")
        elif kind == "table":
            head = "".join(f"<th>{esc(_cell(h))}</th>" for h in block.content)
            body = "".join("<tr>" + "".join(f"<td>{esc(_cell(c))}</td>" for c in row) + "</tr>"
                           for row in block.extra)
            parts.append(f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")
        elif kind == "figure":
            data = base64.b64encode(figures[block.content]).decode("ascii")
            parts.append(f'<figure><img src="data:image/png;base64,{data}" alt="{esc(block.extra)}">'
                         f"<figcaption>{esc(block.extra)}</figcaption></figure>")
        elif kind == "pre":
            parts.append(f"<pre>{esc(block.content)}</pre>")
        else:  # pragma: no cover - blocks are built by this package only
            raise ValueError(f"unknown block kind {kind!r}")
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


def _md_escape(text):
    return str(text).replace("|", "\\|")


def to_markdown(blocks, figure_dir="figures"):
    """Markdown text; figures are linked as ``<figure_dir>/<name>.png``."""
    parts = []
    for block in blocks:
        kind = block.kind
        if kind in ("h1", "h2", "h3"):
            parts.append("#" * int(kind[1]) + " " + block.content)
        elif kind == "p":
            parts.append(block.content)
        elif kind == "list":
            parts.append("\n".join(f"- {_cell(i)}" for i in block.content))
        elif kind == "table":
            lines = ["| " + " | ".join(_md_escape(_cell(h)) for h in block.content) + " |",
                     "|" + "|".join("---" for _ in block.content) + "|"]
            lines += ["| " + " | ".join(_md_escape(_cell(c)) for c in row) + " |" for row in block.extra]
            parts.append("\n".join(lines))
        elif kind == "figure":
            parts.append(f"![{block.extra}]({figure_dir}/{block.content}.png)\n\n*{block.extra}*")
        elif kind == "pre":
            parts.append("```\n" + block.content + "\n```")
        else:  # pragma: no cover
            raise ValueError(f"unknown block kind {kind!r}")
    return "\n\n".join(parts) + "\n"
