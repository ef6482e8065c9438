"""A minimal document model rendered twice: self-contained HTML and a Markdown twin.

A report is a list of blocks (headings, paragraphs, lists, tables, figures, preformatted
text). :func:`to_html` embeds every figure as a base64 PNG, so the page opens offline in
any browser; :func:`to_markdown` links the same figures as PNG files next to it.
"""

from __future__ import annotations

import base64
import html
import re
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


def paragraph(text, *, lead=None):
    """A paragraph of plain text, optionally opened by a ``lead`` in bold.

    Both are plain text: every character is shown as written (escaped in HTML and Markdown).
    """
    return Block("p", text, lead)


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
            lead = f"<strong>{esc(block.extra)}</strong> " if block.extra else ""
            parts.append(f"<p>{lead}{esc(block.content)}</p>")
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


#: Characters with an inline meaning in Markdown (CommonMark and GitHub's tables and
#: strikethrough), escaped with a backslash; ``<``, ``>`` and ``&`` become HTML entities,
#: so that no renderer passes an HTML tag through.
_MD_INLINE = set("\\`*_[]|~")
_MD_ENTITIES = {"<": "&lt;", ">": "&gt;", "&": "&amp;"}
#: What opens a block at the start of a line: heading, list item, numbered item.
#: ("#  a", "- a", "+ a", "---", "1. a"; "-0.5" and "1.5" are plain text).
_MD_LINE_START = re.compile(r"^(\s*)([#+\-=](?=\s|$|[#+\-=])|\d+(?=[.)](?:\s|$)))")


def _md_escape(text):
    """Plain text as Markdown that renders to exactly that text (no markup, no raw HTML)."""
    out = []
    for char in str(text):
        if char in _MD_ENTITIES:
            out.append(_MD_ENTITIES[char])
        elif char in _MD_INLINE:
            out.append("\\" + char)
        elif char in "\r\n":
            out.append(" ")  # a line break would end the paragraph, list item or table row
        else:
            out.append(char)
    return _escape_line_start("".join(out))


def _escape_line_start(text):
    """A leading ``#``, ``-``, ``+``, ``=`` or ``1.`` escaped (it would open a heading or a list)."""
    match = _MD_LINE_START.match(text)
    if not match:
        return text
    start = match.start(2)
    if match.group(2).isdigit():  # "1." -> "1\."
        end = match.end(2)
        return text[:end] + "\\" + text[end:]
    return text[:start] + "\\" + text[start:]


def _fence(text):
    """A backtick fence longer than any backtick run inside ``text`` (CommonMark code block)."""
    run = best = 0
    for char in text:
        run = run + 1 if char == "`" else 0
        best = max(best, run)
    return "`" * max(3, best + 1)


def to_markdown(blocks, figure_dir="figures"):
    """Markdown text; figures are linked as ``<figure_dir>/<name>.png``.

    Every text is escaped (:func:`_md_escape`): sample names, titles and file names from
    the user render as written, never as markup or HTML.
    """
    esc = _md_escape
    parts = []
    for block in blocks:
        kind = block.kind
        if kind in ("h1", "h2", "h3"):
            parts.append("#" * int(kind[1]) + " " + esc(block.content))
        elif kind == "p":
            lead = f"**{esc(block.extra)}** " if block.extra else ""
            parts.append(lead + esc(block.content))
        elif kind == "list":
            parts.append("\n".join(f"- {esc(_cell(i))}" for i in block.content))
        elif kind == "table":
            lines = ["| " + " | ".join(esc(_cell(h)) for h in block.content) + " |",
                     "|" + "|".join("---" for _ in block.content) + "|"]
            lines += ["| " + " | ".join(esc(_cell(c)) for c in row) + " |" for row in block.extra]
            parts.append("\n".join(lines))
        elif kind == "figure":
            parts.append(f"![{esc(block.extra)}]({figure_dir}/{block.content}.png)\n\n*{esc(block.extra)}*")
        elif kind == "pre":
            fence = _fence(block.content)
            parts.append(f"{fence}\n{block.content}\n{fence}")
        else:  # pragma: no cover
            raise ValueError(f"unknown block kind {kind!r}")
    return "\n\n".join(parts) + "\n"
