"""What a ``harp`` command says on standard error beside its output: one line each,
``harp COMMAND: text``.

A command's error is not said here: it raises a :class:`station.errors.HarpError`, which the entry
point (:func:`station.cli.main`) says once, with :func:`say`. Here go its warnings (:func:`warn`),
the errors of single items it goes on after (one image of several, one session of a batch) and its
notes.
"""

from __future__ import annotations

import sys


def say(prog: str, text: object, *, flush: bool = False) -> None:
    """``PROG: text`` on standard error (``prog``: ``harp measure``, ``harp session``, ...; ``text``: as
    ``str()`` writes it)."""
    print(f"{prog}: {text}", file=sys.stderr, flush=flush)


def warn(prog: str, text: object) -> None:
    """``PROG: warning: text`` on standard error."""
    say(prog, f"warning: {text}")
