"""The QA report as a document: a list of blocks (headings, paragraphs, verdicts, tables,
images, lists, quotes) that :func:`station.qa.report.write_report` builds once and the Jinja
templates ``templates/report.md.j2`` and ``templates/report.html.j2`` write as ``report.md`` and
as the standalone HTML page ``index.html``.

Texts are Markdown inline text (``**bold**`` and ```code``` only: what the report's own texts and
the rows handed to it, such as :func:`station.qa.report.session_context`'s, hold); the page
writes those two marks as ``<strong>`` and ``<code>`` (:func:`inline_html`). The structure itself
is never parsed back out of Markdown.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import jinja2
from markupsafe import Markup, escape

TEMPLATES = Path(__file__).with_name("templates")
"""The report's templates."""


@dataclass(frozen=True)
class Heading:
    """``#`` .. ``######`` heading."""

    level: int
    text: str
    kind: ClassVar[str] = "heading"


@dataclass(frozen=True)
class Paragraph:
    """One paragraph of inline text."""

    text: str
    kind: ClassVar[str] = "paragraph"


@dataclass(frozen=True)
class VerdictLine:
    """A verdict, PASS or FAIL: the session's (``focus`` None: "**Verdict: FAIL**") or one focus
    setting's ("Verdict at focus 0.5: **FAIL**"); coloured on the page."""

    verdict: str
    focus: str | None = None
    kind: ClassVar[str] = "verdict"


@dataclass(frozen=True)
class Marked:
    """A table cell's word in bold, coloured on the page as a verdict (a check's FAIL)."""

    word: str
    kind: ClassVar[str] = "marked"


@dataclass(frozen=True)
class Table:
    """A table: ``align`` of each column ``left``, ``right`` or ``center``; cells are inline text
    or :class:`Marked`."""

    header: tuple[str, ...]
    align: tuple[str, ...]
    rows: tuple[tuple[str | Marked, ...], ...]
    kind: ClassVar[str] = "table"


@dataclass(frozen=True)
class Image:
    """A picture beside the report (``src`` relative to it)."""

    alt: str
    src: str
    kind: ClassVar[str] = "image"


@dataclass(frozen=True)
class Bullets:
    """A bulleted list."""

    items: tuple[str, ...]
    kind: ClassVar[str] = "bullets"


@dataclass(frozen=True)
class Quote:
    """A block quote, led by ``label`` in bold when given ("**warning**: ...")."""

    text: str
    label: str = ""
    kind: ClassVar[str] = "quote"


Block = Heading | Paragraph | VerdictLine | Table | Image | Bullets | Quote

_BOLD = re.compile(r"\*\*(.+?)\*\*")
_CODE = re.compile(r"`([^`]+)`")


def inline_html(text: str) -> Markup:
    """Inline text on the page: escaped, ``**bold**`` as ``<strong>``, ```code``` as ``<code>``."""
    out = str(escape(text))
    out = _BOLD.sub(r"<strong>\1</strong>", out)
    return Markup(_CODE.sub(r"<code>\1</code>", out))


def _environment(fmt: str) -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(TEMPLATES)),
        autoescape=fmt == "html",
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )
    env.filters["inline"] = inline_html if fmt == "html" else str
    return env


def render(blocks: list[Block], fmt: str, title: str = "") -> str:
    """The report's text: ``fmt`` ``md`` (Markdown) or ``html`` (a standalone page titled ``title``)."""
    return _environment(fmt).get_template(f"report.{fmt}.j2").render(blocks=blocks, title=title)
