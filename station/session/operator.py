"""The operator of a session whose board views are placed by hand (``intrinsics.placement: operator``).

The plan asks for each view (:class:`station.session.plan.PlaceBoard`: which tilt, where in the image,
why; after a rejected capture, why it was rejected); the executor hands the request to an
:class:`OperatorDesk`, which says it and waits for the answer. Answers come from the terminal (a line
on standard input: Enter when the board is in place, ``s`` to leave the view out, ``q`` to stop the
session) and from the live page (``harp session run --live``: its buttons POST ``{"action": "board",
"value": "capture" | "skip" | "stop"}``, :meth:`station.live.runner.LiveStation.command`), whichever
answers first. With neither (standard input closed and no live page) the session stops with
:class:`NoOperator`, its frames kept, to be resumed where an operator is.
"""

from __future__ import annotations

import queue
import sys
import threading
from collections.abc import Callable, Sequence
from typing import Any, TextIO

from station.session.plan import CAPTURE, SKIP, STOP

ANSWERS = {"": CAPTURE, "c": CAPTURE, "capture": CAPTURE, "s": SKIP, "skip": SKIP, "q": STOP, "stop": STOP}
"""What the operator may type (or the page send), and what it means."""
PROMPT = "press Enter when the board is in place (s: skip this view, q: stop the session)"


class NoOperator(Exception):
    """Nobody can answer (standard input closed, no live page); ``str()`` is the one-line reason.

    Not a HarpError: :func:`station.session.camera_matrix.ask_for_board` turns it into a
    :class:`~station.session.directory.SessionAborted` naming how to resume, recorded by the executor."""


def parse_answer(text: str) -> str:
    """:data:`~station.session.plan.CAPTURE`, ``SKIP`` or ``STOP`` of a typed line or a page's value;
    ValueError (one line) for anything else."""
    key = str(text).strip().lower()
    if key not in ANSWERS:
        raise ValueError(f"expected Enter (capture), s (skip) or q (stop), got {text.strip()!r}")
    return ANSWERS[key]


class OperatorDesk:
    """Says each wanted view and waits for the operator's answer (module docstring).

    Parameters
    ----------
    say : shows a line to the operator (the session's console; default: standard error).
    stdin : the terminal to read answers from (None: none; a thread reads it from the first question on).
    """

    def __init__(self, say: Callable[[str], None] | None = None, stdin: TextIO | None = None) -> None:
        # not through say: the prompt to the person placing the board (like input()'s), not a note of a command
        self.say = say if say is not None else (lambda text: print(text, file=sys.stderr, flush=True))
        self._stdin = stdin
        self._answers: queue.Queue[str] = queue.Queue()
        self._reader: threading.Thread | None = None
        self._stdin_open = stdin is not None
        self._pages = 0
        self._lock = threading.Lock()

    # -- where answers come from -----------------------------------------------------------
    def attach_page(self) -> Callable[[Any], dict[str, Any]]:
        """A live page answers too: the function its ``board`` command calls (ValueError for a bad value)."""
        with self._lock:
            self._pages += 1

        def from_page(value: Any) -> dict[str, Any]:
            answer = parse_answer(str(value))
            self._answers.put(answer)
            return {"ok": True, "board": answer}

        return from_page

    def answer(self, text: str) -> None:
        """An answer typed on the terminal (a bad one is said, and the desk goes on waiting)."""
        try:
            self._answers.put(parse_answer(text))
        except ValueError as exc:
            self.say(f"[yellow]{exc}")

    def _read_terminal(self) -> None:
        stream = self._stdin
        try:
            assert stream is not None
            for line in iter(stream.readline, ""):
                self.answer(line)
        except (OSError, ValueError):  # a closed or unreadable stream: as at its end
            pass
        with self._lock:
            self._stdin_open = False
        self._answers.put("")  # wakes the waiting question, which finds whether anyone is left

    def _listening(self) -> bool:
        with self._lock:
            return self._stdin_open or self._pages > 0

    # -- the question ----------------------------------------------------------------------
    def ask(self, lines: Sequence[str], idle: Callable[[], None] | None = None) -> str:
        """Say ``lines`` (the wanted view, why, what was wrong) and the prompt; the operator's answer.
        ``idle`` is called while no answer has come (the live page's preview of the camera).

        Raises :class:`NoOperator` when nobody can answer; Ctrl-C (KeyboardInterrupt) goes through.
        """
        with self._lock:
            start = self._stdin is not None and self._reader is None and self._stdin_open
            where = [PROMPT] if self._stdin_open else []
            if self._pages:
                where.append("or answer on the live page")
        for line in lines:
            self.say(line)
        if where:
            self.say(", ".join(where))
        if start:  # the terminal is read from the first question on (what was typed before waits in it)
            self._reader = threading.Thread(target=self._read_terminal, name="harp-operator", daemon=True)
            self._reader.start()
        while True:
            try:
                got = self._answers.get(timeout=0.2)  # short waits: Ctrl-C is seen at once
            except queue.Empty:
                got = ""
                if idle is not None:
                    idle()
            if got:
                return got  # answers given ahead (lines typed or piped in advance) are taken in turn
            if self._answers.empty() and not self._listening():
                raise NoOperator(
                    "a board view placed by the operator is wanted, and nobody can answer (standard input closed, "
                    "no live page): run the session on a terminal or with --live"
                )
