"""One spelling for the options commands share (issue 9 item 3): ``-o/--out`` for what a command
writes, ``-t/--t`` for the along-edge subsampling, focal lengths named with their unit."""

from __future__ import annotations

import argparse

from station.cli import build_parser


def commands(parser: argparse.ArgumentParser, prefix: str = "harp"):
    """Every (sub-)command parser, by its name."""
    yield prefix, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from commands(sub, f"{prefix} {name}")


def test_shared_options_have_one_spelling():
    seen = {"-o": 0, "-t": 0}
    for name, parser in commands(build_parser()):
        for action in parser._actions:
            opts = set(action.option_strings)
            assert not opts & {"--output", "--output-dir", "--focal"}, (name, opts)
            if "-o" in opts:
                seen["-o"] += 1
                assert "--out" in opts, (name, opts)
            if "--out" in opts:
                assert "-o" in opts, (name, opts)
            if "-t" in opts or "--t" in opts:
                seen["-t"] += 1
                assert opts == {"-t", "--t"}, (name, opts)
            for o in opts:
                if o.startswith("--focal"):
                    assert o in ("--focal-mm", "--focal-px"), (name, o)
    assert seen["-o"] >= 4 and seen["-t"] >= 2  # measure/calibrate/undistort/export/profile export use them
