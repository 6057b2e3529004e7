"""Markdown → HTML for the report page, by markdown-it-py (CommonMark, with its pipe-table rule enabled), plus
what the page adds: GitHub's heading anchors (`slug`, so the contents list works on GitHub and in the HTML page
alike) and images embedded as base64 data URIs (`embedded_image`, only the files the page allows): a
self-contained page, no network.
Raw HTML in a summary.md is shown as text, not passed through."""

from __future__ import annotations

import base64
import html
import mimetypes
import re
from collections.abc import Callable, Collection
from pathlib import Path
from urllib.parse import unquote

from bodyschema.evaluation.report.confined import resolved

# A table never runs past the page's right edge: header words and text cells wrap at spaces first; a cell with a long
# unbroken word (a 64-hex sha256, a models:/ spec, a run id: class LONG_CELL) may break it anywhere, else the models
# table ran 40rem past the 60rem column. Other words stay whole (overflow-wrap:anywhere on every cell let the layout
# shrink a column to one letter: "floo|r", "epoc|hs"), and a number stays on one line (2.48e-05 is not broken at its
# '-'). A table still wider than the text scrolls sideways inside its own box (TABLE_BOX, around every table).
TABLE_BOX = "table-scroll"
LONG_CELL, LONG_WORD = "long", 24      # characters: a sha256 (64), a run id (36); no header word or number is as long
STYLE = ("body{font-family:system-ui,sans-serif;max-width:60rem;margin:2rem auto;padding:0 1rem;line-height:1.45}"
         f".{TABLE_BOX}{{max-width:100%;overflow-x:auto;margin:1rem 0}}"
         "table{border-collapse:collapse;font-size:.9em}"
         "th,td{border:1px solid #ccc;padding:.2rem .45rem;overflow-wrap:break-word}"
         f"td.{LONG_CELL}{{overflow-wrap:anywhere}}"
         "th{background:#f3f3f3;vertical-align:bottom}"
         "td.number{white-space:nowrap;overflow-wrap:normal}img{max-width:100%}"
         "pre{background:#f6f6f6;padding:.6rem;overflow-x:auto}code{background:#f6f6f6}")
NUMBER_CELL = re.compile(r"^[-+−]?(\d[\d.,]*(e[-+]?\d+)?( ?%)?|nan|inf|–)( ± \S+)?$", re.I)   # 1.86 ± 0.45, nan
LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)\)")    # page.py rewrites summary.md links with it


def slug(heading: str) -> str:
    """GitHub's anchor for a heading, so the contents list works on GitHub and in the HTML page alike."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def markdown_to_html(text: str, image_src: Callable[[str], str | None] = lambda src: src) -> str:
    """HTML body of a Markdown text. `image_src` maps an image link to the src to use (None: show the alt text)."""
    return _parser().render(text, {"image_src": image_src})


def _parser():
    from markdown_it import MarkdownIt  # imported when a report is written, not with the CLI

    md = MarkdownIt("commonmark", {"html": False}).enable("table")
    md.add_render_rule("heading_open", _heading_open)
    md.add_render_rule("image", _image)
    md.add_render_rule("td_open", _td_open)
    md.add_render_rule("table_open", lambda self, tokens, idx, options, env:
                       f'<div class="{TABLE_BOX}">\n' + self.renderToken(tokens, idx, options, env))
    md.add_render_rule("table_close", lambda self, tokens, idx, options, env:
                       self.renderToken(tokens, idx, options, env) + "</div>\n")
    return md


def _td_open(self, tokens, idx, options, env) -> str:
    """A cell holding a number gets class="number": it never wraps; one holding a long word class LONG_CELL: that
    word may break anywhere (STYLE)."""
    content = tokens[idx + 1].content.strip()
    if NUMBER_CELL.match(content):
        tokens[idx].attrJoin("class", "number")
    elif any(len(word) >= LONG_WORD for word in content.split()):
        tokens[idx].attrJoin("class", LONG_CELL)
    return self.renderToken(tokens, idx, options, env)


def _heading_open(self, tokens, idx, options, env) -> str:
    plain = re.sub(r"[`*]", "", tokens[idx + 1].content)       # the anchor of the heading's text, as GitHub's
    tokens[idx].attrSet("id", slug(plain))
    return self.renderToken(tokens, idx, options, env)


def _image(self, tokens, idx, options, env) -> str:
    token = tokens[idx]
    alt = self.renderInlineAsText(token.children or [], options, env)
    src = env["image_src"](unquote(token.attrGet("src") or ""))
    if src is None:
        return f"<em>[missing image: {html.escape(alt)}]</em>"
    return f'<img src="{html.escape(src)}" alt="{html.escape(alt)}">'


def html_page(body: str, title: str) -> str:
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n<title>{html.escape(title)}</title>\n'
            f"<style>{STYLE}</style>\n</head>\n<body>\n{body}\n</body>\n</html>\n")


def embedded_image(page_dir: Path, allowed: Collection[Path]) -> Callable[[str], str | None]:
    """Image link → base64 data URI of the file relative to `page_dir`, only when that file (symlinks resolved) is
    one of `allowed`: a link in a summary.md can never make the page read another file. None otherwise."""
    def src(link: str) -> str | None:
        path = resolved(page_dir / link)
        if path not in allowed or not path.is_file():
            return None
        mime = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
        return f"data:{mime};base64,{base64.b64encode(path.read_bytes()).decode('ascii')}"
    return src
