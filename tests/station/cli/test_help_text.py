"""Help texts without reStructuredText markup (issue 21 item 5): :func:`plain` on hand-written
reST, and every ``harp`` parser's ``--help`` — each command and sub-command, the raw-formatted
ones too — free of it."""

from __future__ import annotations

import argparse
import re

import pytest

from station.cli import build_parser
from station.cli.help_text import HarpParser, plain


@pytest.mark.parametrize(
    "rest, text",
    [
        ("``harp measure IMAGE...``: measure", "harp measure IMAGE...: measure"),
        ("the ``--out`` file (:mod:`station.files`) is written", "the --out file is written"),
        ("see :func:`station.store.resolve` first", "see station.store.resolve first"),
        ("by :meth:`~station.store.ProfileStore.latest`", "by latest"),
        (":class:`the store <station.store.ProfileStore>` reads", "the store reads"),
        ("the **current** profile, *not* a failed one", "the current profile, not a failed one"),
        ("a `default role` and a `link <https://x.org>`_", "a default role and a link"),
        ("options of ``harp export``\n(:mod:`station.cli.export`); the", "options of harp export; the"),
        ("Formats (:data:`pipeline.exports.FORMATS`)::\n\n    opencv  YAML", "Formats:\n\n    opencv  YAML"),
        ("a list::\n\n    x", "a list:\n\n    x"),
        ("before\n\n.. note:: kept words\n\nafter", "before\n\nkept words\n\nafter"),
        ("before\n\n.. _label:\n\nafter", "before\n\n\nafter"),
        ("-o *.xml or /dev/video* (glob), 2*3", "-o *.xml or /dev/video* (glob), 2*3"),
        ("nothing to strip: 50% at t=30", "nothing to strip: 50% at t=30"),
    ],
)
def test_plain_keeps_the_words_and_drops_the_markup(rest, text):
    assert plain(rest) == text


def parsers(parser: argparse.ArgumentParser, prog: str = "harp"):
    yield prog, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from parsers(sub, f"{prog} {name}")


MARKUP = re.compile(r"``|:(?:func|mod|class|meth|data|attr|exc|obj|ref):|^\s*\.\. |\*\*\w", re.M)


def test_no_help_of_any_command_shows_markup():
    seen = 0
    for prog, parser in parsers(build_parser()):
        assert isinstance(parser, HarpParser), prog
        text = parser.format_help()
        assert not MARKUP.findall(text), (prog, MARKUP.findall(text))
        seen += 1
    assert seen >= 20  # harp, its 14 commands and their actions (session run, profile export, ...)


def test_the_help_keeps_the_docstrings_words():
    """``harp profile --help``: its docstring's paragraph, the literals' words kept, the pointers gone."""
    shown = " ".join(dict(parsers(build_parser()))["harp profile"].format_help().split())
    assert "Reads the profile store: --store PATH|URL (a SQLite file or postgresql://), or --config CONFIG" in shown
    assert "unless --allow-failed is given" in shown
    assert "the options, figures and warnings of harp export; the profile brings" in shown
