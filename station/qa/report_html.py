"""The QA report's Markdown as a standalone HTML page (the subset :func:`station.qa.report.write_report`
writes)."""

from __future__ import annotations

import html
import re

_INLINE = [
    (re.compile(r"!\[([^\]]*)\]\(([^)]+)\)"), r'<img alt="\1" src="\2">'),
    (re.compile(r"\*\*(.+?)\*\*"), r"<strong>\1</strong>"),
    (re.compile(r"`([^`]+)`"), r"<code>\1</code>"),
]


def _inline(text: str) -> str:
    out = html.escape(text, quote=False)
    for rx, rep in _INLINE:
        out = rx.sub(rep, out)
    return out


def markdown_to_html(md: str, title: str = "") -> str:
    """HTML page of the Markdown subset :func:`station.qa.report.write_report` writes (headings,
    paragraphs, pipe tables, images, bullet lists, block quotes, bold, code)."""
    body: list[str] = []
    lines = md.splitlines()
    i = 0
    while i < len(lines):
        ln = lines[i]
        if not ln.strip():
            i += 1
        elif ln.startswith("#"):
            level = len(ln) - len(ln.lstrip("#"))
            body.append(f"<h{level}>{_inline(ln[level:].strip())}</h{level}>")
            i += 1
        elif ln.startswith("|"):
            rows = []
            while i < len(lines) and lines[i].startswith("|"):
                rows.append([c.strip() for c in lines[i].strip().strip("|").split("|")])
                i += 1
            aligns = []
            if len(rows) > 1 and all(re.fullmatch(r":?-+:?", c) for c in rows[1]):
                aligns = [
                    "right"
                    if c.endswith(":") and not c.startswith(":")
                    else "center"
                    if c.startswith(":") and c.endswith(":")
                    else "left"
                    for c in rows[1]
                ]
                rows = [rows[0]] + rows[2:]
            t = ["<table>"]
            for r, cells in enumerate(rows):
                tag = "th" if r == 0 and aligns else "td"
                t.append(
                    "<tr>"
                    + "".join(
                        f'<{tag} style="text-align:{aligns[k] if k < len(aligns) else "left"}">{_inline(c)}</{tag}>'
                        for k, c in enumerate(cells)
                    )
                    + "</tr>"
                )
            body.append("\n".join(t + ["</table>"]))
        elif ln.startswith("- "):
            items = []
            while i < len(lines) and lines[i].startswith("- "):
                items.append(f"<li>{_inline(lines[i][2:])}</li>")
                i += 1
            body.append("<ul>" + "".join(items) + "</ul>")
        elif ln.startswith("> "):
            body.append(f"<blockquote>{_inline(ln[2:])}</blockquote>")
            i += 1
        else:
            para = []
            while i < len(lines) and lines[i].strip() and not lines[i].startswith(("#", "|", "- ", "> ")):
                para.append(_inline(lines[i]))
                i += 1
            body.append("<p>" + "<br>\n".join(para) + "</p>")
    style = (
        "body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}"
        ".verdict{padding:2px 8px;border-radius:3px;color:#fff}"
        ".verdict.pass{background:#1a7f37}.verdict.fail{background:#cf222e}"
        "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px}"
        "img{max-width:100%;display:block;margin:0.5em 0}"
        "blockquote{color:#444;border-left:3px solid #bbb;margin-left:0;padding-left:1em}"
    )
    page = "\n".join(body)
    # the verdicts in colour: green PASS, red FAIL (the Markdown says the same in words)
    page = re.sub(
        r"<strong>(Verdict(?: at focus [^:<]*)?: )(PASS|FAIL)</strong>",
        lambda m: f'<strong class="verdict {m.group(2).lower()}">{m.group(1)}{m.group(2)}</strong>',
        page,
    )
    page = page.replace("<strong>FAIL</strong>", '<strong class="verdict fail">FAIL</strong>')
    return (
        f'<!DOCTYPE html>\n<html><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
        f"<style>{style}</style></head>\n<body>\n" + page + "\n</body></html>\n"
    )
