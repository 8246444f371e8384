"""How every ``harp`` command prints a table: a rich table on a terminal, tab-separated text otherwise.

When standard output is a terminal, :func:`print_table` draws a ``rich`` table with its
title; when it is not (a pipe, a file, a script), it writes plain tab-separated text:
one header line, then one line per row, no title, no colours, no padding, a missing
value as an empty field, nothing cut short and nothing wrapped, however long. Column
names carry their unit (``fit d (px)``, ``focus``, ``settle (s)``), so a script reading
the header knows what each field is. :func:`cell` formats a number the way the terminal
table shows it. :func:`console` is the ``rich`` console for the lines a command prints
around its tables: on a terminal as rich draws them, otherwise plain text, one line per
line, never wrapped at any width.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from typing import Any, TextIO


def is_terminal(stream: TextIO | None = None) -> bool:
    """Whether ``stream`` (default standard output) is a terminal."""
    stream = stream if stream is not None else sys.stdout
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # a closed stream or a test double
        return False


def console(stream: TextIO | None = None) -> Any:
    """A ``rich.console.Console`` on ``stream`` (default standard output): off a terminal no colour,
    no highlighting, and no wrapping (each printed line stays one line, whatever its length)."""
    from rich.console import Console

    stream = stream if stream is not None else sys.stdout
    if is_terminal(stream):
        return Console(file=stream)
    return Console(file=stream, soft_wrap=True, no_color=True, highlight=False)


def cell(value: Any, digits: int = 4) -> str:
    """A table cell: floats with ``digits`` decimals, None / non-finite as empty."""
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.{digits}f}" if math.isfinite(value) else ""
    return str(value)


def print_table(
    columns: Sequence[str],
    rows: Sequence[Sequence[Any]],
    *,
    title: str | None = None,
    right: Sequence[str] = (),
    stream: TextIO | None = None,
) -> None:
    """Print ``rows`` under ``columns`` (see the module docstring); ``right``: columns aligned right
    on a terminal, where a cell too long for its column folds onto a second line rather than being
    cut. Cells are strings (None: empty); tabs and line breaks in them become spaces."""
    stream = stream if stream is not None else sys.stdout
    texts = [["" if v is None else str(v) for v in r] for r in rows]
    if not is_terminal(stream):
        clean = lambda s: s.replace("\t", " ").replace("\r", " ").replace("\n", " ")  # noqa: E731
        stream.write("\t".join(clean(c) for c in columns) + "\n")
        for r in texts:
            stream.write("\t".join(clean(c) for c in r) + "\n")
        stream.flush()
        return
    from rich.table import Table
    from rich.text import Text

    t = Table(title=title)
    for c in columns:  # a cell too long for its column folds onto the next line, never cut with an ellipsis
        t.add_column(c, justify="right" if c in right else "left", overflow="fold")
    for r in texts:
        t.add_row(*(Text(c or "-") for c in r))
    console(stream).print(t)  # the one console factory (a terminal here)
