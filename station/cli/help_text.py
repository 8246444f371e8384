"""Help texts as a user reads them: the reStructuredText of the docstrings they are made from,
plain (:func:`plain`), in every ``harp`` parser's ``--help`` (:class:`HarpParser`).

The command modules write their descriptions once, in their module docstrings (reST, for the
developer documentation); ``--help`` shows the same words without ````literal````, roles
(``:func:`x```), ``**strong**`` or ``.. directive::`` lines, and without the parenthesised
pointers into the code (``(:mod:`station.store`)``) that mean nothing on a terminal.
"""

from __future__ import annotations

import argparse
import functools
import re
from typing import Any, NoReturn

from station.exit_codes import EXIT_ERROR

_POINTER = re.compile(r"(?:[ \t]*\n)?[ \t]*\(:[\w:.-]+:`[^`]*`\)")
"""A parenthesis holding nothing but a role: a pointer for developers, dropped."""
_ROLE = re.compile(r":[\w:.-]+:`([^`]*)`")
_TARGET = re.compile(r"^(.*?)\s*<[^<>]*>$", re.S)
_LITERAL = re.compile(r"``(.+?)``", re.S)
_LINK = re.compile(r"`([^`]+?)`__?")
_DEFAULT_ROLE = re.compile(r"`([^`]+)`")
_STRONG = re.compile(r"(?<![\w*])\*\*(\S(?:[^*]*?\S)?)\*\*(?![\w*])")
_EMPHASIS = re.compile(r"(?<![\w*])\*(\w(?:[\w \-]*\w)?)\*(?![\w*])")
_DIRECTIVE = re.compile(r"^[ \t]*\.\. [\w:-]+::[ \t]*(.*)$", re.M)
_COMMENT_OR_LABEL = re.compile(r"^[ \t]*\.\.(?: _[^:]+:.*| *)$\n?", re.M)
_LITERAL_MARKER = re.compile(r"(\S)[ \t]*::[ \t]*$", re.M)
_LONE_MARKER = re.compile(r"^[ \t]*::[ \t]*$\n?", re.M)


def _role_text(match: re.Match[str]) -> str:
    """``:role:`text``` -> text; ``:role:`title <target>``` -> title; ``:role:`~a.b.c``` -> c."""
    text = match.group(1)
    titled = _TARGET.match(text)
    if titled and titled.group(1):
        return titled.group(1)
    if text.startswith("~"):
        return text[1:].rsplit(".", 1)[-1]
    return text.lstrip("!")


def plain(text: str) -> str:
    """``text`` (reStructuredText) as plain text for a terminal: literals, roles, links and
    emphasis keep their words only; a parenthesis holding only a role is dropped; a directive
    line keeps its argument (``.. note:: x`` -> ``x``), comments and labels go; ``text::``
    before a literal block reads ``text:``. Text without markup comes back unchanged."""
    if not any(mark in text for mark in ("`", "*", ".. ", "::")):
        return text
    text = _POINTER.sub("", text)
    text = _ROLE.sub(_role_text, text)
    text = _LITERAL.sub(r"\1", text)
    text = _LINK.sub(lambda m: _TARGET.sub(r"\1", m.group(1)), text)
    text = _DEFAULT_ROLE.sub(r"\1", text)
    text = _STRONG.sub(r"\1", text)
    text = _EMPHASIS.sub(r"\1", text)
    text = _DIRECTIVE.sub(r"\1", text)
    text = _COMMENT_OR_LABEL.sub("", text)
    text = _LONE_MARKER.sub("", text)
    return _LITERAL_MARKER.sub(r"\1:", text)


class PlainHelp(argparse.HelpFormatter):
    """A help formatter that shows every description, epilog and option help through
    :func:`plain`; mixed into whichever formatter a parser asks for (:func:`plain_formatter`)."""

    def _format_text(self, text: str) -> str:
        return super()._format_text(plain(text))

    def _expand_help(self, action: argparse.Action) -> str:
        return plain(super()._expand_help(action))


@functools.cache
def plain_formatter(formatter: type[argparse.HelpFormatter]) -> type[argparse.HelpFormatter]:
    """``formatter`` (e.g. ``argparse.RawDescriptionHelpFormatter``) with :class:`PlainHelp` mixed in."""
    if issubclass(formatter, PlainHelp):
        return formatter
    if formatter is argparse.HelpFormatter:
        return PlainHelp
    return type(f"Plain{formatter.__name__}", (PlainHelp, formatter), {})


class HarpParser(argparse.ArgumentParser):
    """The parser of ``harp`` and, by argparse's inheritance of the parser class, of every
    sub-command and sub-sub-command: its help is plain text whichever formatter it is given, and a
    usage error is one line (:meth:`error`)."""

    def __init__(self, *args: Any, formatter_class: type[argparse.HelpFormatter] = argparse.HelpFormatter, **kw: Any):
        super().__init__(*args, formatter_class=plain_formatter(formatter_class), **kw)

    def error(self, message: str) -> NoReturn:
        """A usage error (an option's bad value, a missing argument, an unknown option) as one line on
        stderr, ``PROG: message (see PROG --help)``, exit 2, as every other error of ``harp``; argparse's
        own prints the usage block first, several lines."""
        self.exit(EXIT_ERROR, f"{self.prog}: {' '.join(message.split())} (see {self.prog} --help)\n")
