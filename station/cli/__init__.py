"""The ``harp`` command line (entry point ``harp = station.cli:main``).

Each sub-command lives in its own module ``station.cli.<name>`` (the names and one-line helps:
:data:`station.cli.commands.COMMANDS`) exposing ``register(subparsers)``; the parser it adds sets
``func(args) -> int``. Only the module of the command being run is imported (``harp --help``,
``--version`` and a mistyped command — one line, "did you mean", exit 2 — import none), and every
help text is shown without its reStructuredText markup (:mod:`station.cli.help_text`). A command module parses, calls the domain code
(:mod:`station.calibration`, :mod:`station.session`, :mod:`station.qa`,
:mod:`station.store`, :mod:`pipeline`) and prints — nothing else imports it; the input
helpers they share (one-line input errors, reading and measuring photos) are
:mod:`station.inputs`, their ``argparse`` types :mod:`station.cli.inputs`.
Exit codes (:mod:`station.exit_codes`): 0 success (a verdict of PASS), 1 a verdict of FAIL
(``harp qa``, ``harp session run|resume``; ``harp profile export`` of a failed profile),
2 bad input or an error, 130 interrupted, 141 standard output closed early.

A command's error for the user is a :class:`station.errors.HarpError` it raises: printed here,
once, as ``harp COMMAND: message`` on stderr, and its exit code returned. Whatever else a command
lets through ends here as one line on stderr and exit 2, never a traceback: an ``OSError`` names the
file, the reason and what to do (:func:`station.files.describe_os_error`: a full disk,
permissions), anything else is an internal error (``HARP_DEBUG=1`` shows its traceback).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import sys
from collections.abc import Sequence
from typing import Any

from station.cli.commands import COMMANDS, module_of, unknown_command
from station.cli.help_text import HarpParser
from station.cli.say import say
from station.ctrl_c import (
    deliver_dropped_ctrl_c,
    forget_handled_ctrl_c,
    stop_signals_as_ctrl_c,
    stopped_exit_code,
    stopped_text,
)
from station.errors import HarpError, one_line
from station.exit_codes import EXIT_BROKEN_PIPE, EXIT_ERROR, EXIT_OK


def first_word(argv: Sequence[str]) -> str | None:
    """The word ``argv`` names its sub-command by (the first that is no option), if any."""
    return next((word for word in argv if not word.startswith("-")), None)


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``harp`` parser. Only the sub-command ``argv`` names (:func:`first_word`) is built by its
    module; every other one is listed from :data:`~station.cli.commands.COMMANDS` with its one-line
    help, its module not imported (``harp --help``, ``--version`` import none). ``argv`` None:
    every sub-command built (for what walks the whole command line, as the tests do)."""
    parser = HarpParser(prog="harp", description="calibration-harp lens distortion station")
    parser.add_argument("--version", action=_Version)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    wanted = set(COMMANDS) if argv is None else {first_word(argv)}
    for name, summary in COMMANDS.items():
        if name in wanted:
            importlib.import_module(module_of(name)).register(sub)
        else:
            sub.add_parser(name, help=summary, add_help=False)
    return parser


TOP_PAD_BYTES = 64 << 20
"""Heap growth kept by the C allocator instead of being returned to the system at once (glibc's
``M_TOP_PAD``). The fits allocate and free arrays of about a megabyte at every iteration: returned
and taken again, every page of them is faulted in anew (in harp calibrate's forked workers 3-4x the
page faults of one process, a sixth of its CPU time as system time). At most this much more memory
per process."""


def _keep_freed_memory() -> None:
    """``mallopt(M_TOP_PAD, TOP_PAD_BYTES)`` where the C library is glibc (a no-op elsewhere), unless the
    user set ``MALLOC_TOP_PAD_``; inherited by forked workers."""
    if "MALLOC_TOP_PAD_" in os.environ or not sys.platform.startswith("linux"):
        return
    import ctypes

    m_top_pad = -2  # glibc malloc.h
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).mallopt(m_top_pad, TOP_PAD_BYTES)


class _Version(argparse.Action):
    """``--version``: the installed version, read only when asked (:data:`station.__version__`)."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS, **kw: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help="show the version and exit")

    def __call__(self, parser: argparse.ArgumentParser, *args: Any, **kw: Any) -> None:
        from station import __version__  # defers importlib.metadata

        print(f"harp station {__version__}")
        parser.exit()


def main(argv: list[str] | None = None) -> int:
    """Run the ``harp`` command ``argv`` (default ``sys.argv[1:]``); returns its exit code."""
    try:
        with stop_signals_as_ctrl_c():  # SIGTERM, SIGHUP: answered as a Ctrl-C (exit 143, 129)
            return _main(argv)
    finally:
        # every Ctrl-C reached a command's handler and its exit code says so: not a death by SIGINT
        forget_handled_ctrl_c()


def _main(argv: list[str] | None) -> int:
    # The station's linear algebra is small (fits of <= ~100 parameters): OpenBLAS's own threads only
    # spin against each other and against the worker processes of harp calibrate (1.7x the CPU time
    # there). Set before numpy is first imported (by the command's module); the user's setting wins.
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    deliver_dropped_ctrl_c()  # a Ctrl-C that CPython drops (in a weakref callback) is delivered again
    argv = sys.argv[1:] if argv is None else argv
    word = first_word(argv)
    if word is not None and word not in COMMANDS:
        say("harp", unknown_command(word))
        return EXIT_ERROR
    try:  # Ctrl-C while the sub-command's module imports numpy/scipy/OpenCV: no traceback either
        parser = build_parser(argv)
    except KeyboardInterrupt:
        say("harp", stopped_text())
        return stopped_exit_code()
    args, extra = parser.parse_known_args(argv)
    if extra:  # named by the sub-command they were given to (argparse would say "harp: ...")
        say(_help_prog(args), f"unrecognized arguments: {' '.join(extra)} (see {_help_prog(args)} --help)")
        return EXIT_ERROR
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return EXIT_ERROR
    _keep_freed_memory()
    try:
        return int(args.func(args) or EXIT_OK)
    except HarpError as exc:  # a command's error for the user: printed here, once
        say(_prog(args), one_line(exc))
        return exc.exit_code
    except KeyboardInterrupt:
        say("harp", stopped_text())
        return stopped_exit_code()
    except BrokenPipeError:
        # stdout closed early (``harp measure --json ... | head``): not an error of
        # ours, and no traceback; point stdout at devnull so the interpreter's
        # final flush does not raise again
        with contextlib.suppress(OSError, ValueError):  # stdout may be a test double
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except SystemExit as exc:
        # rich's Console turns a broken stdout pipe into SystemExit(1) after pointing
        # stdout at /dev/null; exit 1 means "QA FAIL" here, so report it as above
        if exc.code == 1 and _stdout_is_devnull():
            return EXIT_BROKEN_PIPE
        raise
    except MemoryError:
        say(_prog(args), "out of memory; give smaller inputs or fewer at once")
        return EXIT_ERROR
    except OSError as exc:  # a file a command did not expect to fail (a full disk, permissions)
        from station.files import describe_os_error  # defers tempfile

        say(_prog(args), describe_os_error(exc))
        return EXIT_ERROR
    except Exception as exc:  # a bug: still one line and exit 2 (never 1, which means QA FAIL)
        if _caused_by_ctrl_c(exc):  # a Ctrl-C that Python wrapped (raised while a class was made)
            say("harp", stopped_text())
            return stopped_exit_code()
        if os.environ.get(DEBUG_ENV):
            raise
        text = " ".join(str(exc).split()) or "(no message)"
        say(
            _prog(args),
            f"internal error: {type(exc).__name__}: {text} (please report it; {DEBUG_ENV}=1 shows the traceback)",
        )
        return EXIT_ERROR


DEBUG_ENV = "HARP_DEBUG"
"""Set to any value to let an unexpected exception print its traceback."""


def _caused_by_ctrl_c(exc: BaseException) -> bool:
    """A ``KeyboardInterrupt`` is in the chain of causes and contexts of ``exc``: Python wraps one
    raised in certain hooks (``__set_name__`` while a class body, e.g. a dataclass, is made, gives
    ``RuntimeError: Error calling __set_name__ ...``), which is still the user's Ctrl-C."""
    seen: set[int] = set()
    e: BaseException | None = exc
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def _prog(args: argparse.Namespace) -> str:
    return f"harp {args.command}" if getattr(args, "command", None) else "harp"


def _help_prog(args: argparse.Namespace) -> str:
    """The command whose ``--help`` lists what ``args`` could take, as argparse names it in its own usage errors:
    ``harp COMMAND``, or with an action ``harp COMMAND ACTION`` (``harp profile show``)."""
    action = getattr(args, f"{getattr(args, 'command', None)}_command", None)
    return f"{_prog(args)} {action}" if action else _prog(args)


def _stdout_is_devnull() -> bool:
    try:
        out, null = os.fstat(sys.stdout.fileno()), os.stat(os.devnull)
    except (OSError, ValueError, AttributeError):  # stdout may be closed or a test double
        return False
    return (out.st_rdev, out.st_ino) == (null.st_rdev, null.st_ino)
