"""The one error base of every ``harp`` command: :class:`HarpError` carries its exit code.

A command raises a :class:`HarpError` (or one of its subclasses: :class:`InputError`,
:class:`station.config.ConfigError`, :class:`station.store.StoreError`, ...) with a one-line
message naming the file, field or device and what to do; the entry point
(:func:`station.cli.main`) prints it once as ``harp COMMAND: message`` on stderr and exits with the
error's :attr:`~HarpError.exit_code` (:mod:`station.exit_codes`; 2, bad input, unless the class says
otherwise). No command prints an error and returns a code itself.
"""

from __future__ import annotations

from station.ctrl_c import stopped_exit_code
from station.exit_codes import EXIT_ERROR, EXIT_INTERRUPTED


class HarpError(Exception):
    """An error for the user: ``str()`` is one line, :attr:`exit_code` the command's exit code."""

    exit_code: int = EXIT_ERROR


class InputError(HarpError):
    """Bad input; ``str(exc)`` is a one-line message for the user, naming the file."""


class Interrupted(HarpError):
    """Ctrl-C stopped the command; the line says what was kept and how to go on (exit 130); a stop signal
    (SIGTERM, SIGHUP: :func:`station.ctrl_c.stop_signals_as_ctrl_c`), exit ``128 + signal``."""

    exit_code = EXIT_INTERRUPTED

    def __init__(self, *args: object) -> None:
        super().__init__(*args)
        self.exit_code = stopped_exit_code()


def one_line(message: object) -> str:
    """``message`` as one line: every run of white space (newlines included) one space."""
    return " ".join(str(message).split())
