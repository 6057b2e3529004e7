"""Markdown → HTML for what benchmark summary.md files contain (headings, paragraphs, pipe tables, lists, code,
links, images), with images embedded as base64 data URIs: a self-contained page, no network, no extra dependency
(the `markdown` package is not installed with bodyschema)."""

from __future__ import annotations

import base64
import html
import mimetypes
import re
from collections.abc import Callable
from pathlib import Path
from urllib.parse import unquote

STYLE = ("body{font-family:system-ui,sans-serif;max-width:60rem;margin:2rem auto;padding:0 1rem;line-height:1.45}"
         "table{border-collapse:collapse;margin:1rem 0}th,td{border:1px solid #ccc;padding:.25rem .6rem}"
         "th{background:#f3f3f3}img{max-width:100%}pre{background:#f6f6f6;padding:.6rem;overflow-x:auto}"
         "code{background:#f6f6f6}")
LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)\)")


def slug(heading: str) -> str:
    """GitHub's anchor for a heading, so the contents list works on GitHub and in the HTML page alike."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


# ---- Markdown → HTML (what summary.md files contain) -------------------------------------------------------
TABLE_RULE = re.compile(r"^\s*\|?\s*:?-+:?\s*(\|\s*:?-+:?\s*)*\|?\s*$")
LIST_ITEM = re.compile(r"^\s*([-*+]|\d+[.)])\s+(.*)")
BLOCK_START = re.compile(r"^\s*(#{1,6}\s|```|([-*+]|\d+[.)])\s)")


def markdown_to_html(text: str, image_src: Callable[[str], str | None] = lambda src: src) -> str:
    """HTML body of a Markdown text. `image_src` maps an image link to the src to use (None: show the alt text)."""
    lines, out, i = text.splitlines(), [], 0
    while i < len(lines):
        line = lines[i]
        if not line.strip():
            i += 1
        elif line.lstrip().startswith("```"):
            end = next((j for j in range(i + 1, len(lines)) if lines[j].lstrip().startswith("```")), len(lines))
            lang = line.strip()[3:].strip()
            cls = f' class="language-{html.escape(lang)}"' if lang else ""
            out.append(f"<pre><code{cls}>{html.escape(chr(10).join(lines[i + 1:end]))}</code></pre>")
            i = end + 1
        elif m := re.match(r"^(#{1,6})\s+(.*?)\s*#*\s*$", line):
            n, body = len(m[1]), m[2]
            out.append(f'<h{n} id="{slug(re.sub(r"[`*]", "", body))}">{_inline(body, image_src)}</h{n}>')
            i += 1
        elif re.match(r"^\s*([-*_])(\s*\1){2,}\s*$", line):
            out.append("<hr>")
            i += 1
        elif _table_starts(lines, i):
            end = next((j for j in range(i + 2, len(lines)) if "|" not in lines[j] or not lines[j].strip()),
                       len(lines))
            out.append(_table(lines[i:end], image_src))
            i = end
        elif LIST_ITEM.match(line):
            ordered = LIST_ITEM.match(line)[1][0].isdigit()
            items = []
            while i < len(lines) and lines[i].strip():
                if m := LIST_ITEM.match(lines[i]):
                    items.append(m[2])
                else:
                    items[-1] += " " + lines[i].strip()              # a wrapped item continues
                i += 1
            tag = "ol" if ordered else "ul"
            out.append(f"<{tag}>" + "".join(f"<li>{_inline(t, image_src)}</li>" for t in items) + f"</{tag}>")
        else:
            end = i + 1
            while end < len(lines) and lines[end].strip() and not (BLOCK_START.match(lines[end])
                                                                  or _table_starts(lines, end)):
                end += 1
            out.append(f"<p>{_inline(' '.join(s.strip() for s in lines[i:end]), image_src)}</p>")
            i = end
    return "\n".join(out)


def _table_starts(lines: list[str], i: int) -> bool:
    return "|" in lines[i] and i + 1 < len(lines) and "-" in lines[i + 1] and bool(TABLE_RULE.match(lines[i + 1]))


def _table(rows: list[str], image_src) -> str:
    cells = [[c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", r.strip().strip("|"))] for r in rows]
    aligns = [("center" if c.startswith(":") and c.endswith(":") else "right" if c.endswith(":")
               else "left" if c.startswith(":") else None) for c in cells[1]]

    def row(values: list[str], tag: str) -> str:
        values = (values + [""] * len(aligns))[:len(aligns)]
        return "<tr>" + "".join(f'<{tag}{f" style={chr(34)}text-align:{a}{chr(34)}" if a else ""}>'
                                f"{_inline(v, image_src)}</{tag}>" for v, a in zip(values, aligns)) + "</tr>"
    body = "".join(row(r, "td") for r in cells[2:])
    return f"<table><thead>{row(cells[0], 'th')}</thead><tbody>{body}</tbody></table>"


def _inline(text: str, image_src) -> str:
    """Code spans, images, links, bold and italics of one line of Markdown, HTML-escaped."""
    held = []

    def hold(fragment: str) -> str:
        held.append(fragment)
        return f"\x00{len(held) - 1}\x00"

    text = re.sub(r"`([^`]+)`", lambda m: hold(f"<code>{html.escape(m[1])}</code>"), text)

    def link(m: re.Match) -> str:
        if not m[1]:
            return hold(f'<a href="{html.escape(m[3])}">{_inline(m[2], image_src)}</a>')
        src, alt = image_src(unquote(m[3])), html.escape(m[2])
        return hold(f'<img src="{html.escape(src)}" alt="{alt}">' if src else f"<em>[missing image: {alt}]</em>")
    text = LINK.sub(link, text)
    text = html.escape(text, quote=False)
    text = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", text)
    text = re.sub(r"(?<![\w*])\*(?!\s)(.+?)(?<!\s)\*(?![\w*])", r"<em>\1</em>", text)
    text = re.sub(r"(?<!\w)_(?!\s)(.+?)(?<!\s)_(?!\w)", r"<em>\1</em>", text)
    return re.sub(r"\x00(\d+)\x00", lambda m: held[int(m[1])], text)


def html_page(body: str, title: str) -> str:
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n<title>{html.escape(title)}</title>\n'
            f"<style>{STYLE}</style>\n</head>\n<body>\n{body}\n</body>\n</html>\n")


def embedded_image(page_dir: Path) -> Callable[[str], str | None]:
    """Image link → base64 data URI of the file relative to `page_dir`; None for URLs (no network) or no file."""
    def src(link: str) -> str | None:
        path = page_dir / link
        if re.match(r"[a-zA-Z][\w+.-]*:", link) or not path.is_file():
            return None
        mime = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
        return f"data:{mime};base64,{base64.b64encode(path.read_bytes()).decode('ascii')}"
    return src
