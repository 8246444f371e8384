"""One error path for the command line (issue 22): every error for the user is a
:class:`station.errors.HarpError` carrying its exit code, printed once by the entry point.

* the error classes of the station's modules are HarpErrors, with the exit codes the README's
  table gives (:mod:`station.exit_codes`);
* no command module prints a line on stderr and then returns an exit code itself (an AST check of
  ``station/cli``: a ``print(..., file=sys.stderr)`` directly followed by ``return`` of a non-zero
  number or ``EXIT_*`` name); a command raises instead. Per-file errors of a command that goes on with
  the other files, and warnings, are still printed where they happen.

* an error class of ``station``, ``drivers`` or ``pipeline`` is a HarpError, or it (or the project's
  class it derives from) says in its docstring why not (``Not a HarpError: ...``: where it is turned
  into one, or why it never reaches a command);
* a line on stderr in ``station`` goes through :mod:`station.cli.say` (``harp COMMAND: ...``), or
  the print says why not in a comment on the line above (``# not through say: ...``).

The checkers are tested on made-up source first, so that a broken checker cannot pass the real tree.
"""

from __future__ import annotations

import ast
import builtins
import textwrap
from pathlib import Path

import pytest

from station.errors import HarpError, Interrupted, one_line
from station.exit_codes import EXIT_ERROR, EXIT_FAIL, EXIT_INTERRUPTED

REPO = Path(__file__).resolve().parents[2]


SAYERS = {"say", "warn"}
"""station.cli.say's functions: a line on stderr by another name."""


def _is_stderr_print(node: ast.stmt) -> bool:
    if not (isinstance(node, ast.Expr) and isinstance(node.value, ast.Call)):
        return False
    call = node.value
    if isinstance(call.func, ast.Name) and call.func.id in SAYERS:
        return True
    if not (isinstance(call.func, ast.Name) and call.func.id == "print"):
        return False
    return any(
        k.arg == "file" and isinstance(k.value, ast.Attribute) and k.value.attr == "stderr" for k in call.keywords
    )


def _is_code_return(node: ast.stmt) -> bool:
    """``return 2``, ``return EXIT_ERROR``: a literal number or an ``EXIT_*`` name, not success (a
    note on stderr before ``return EXIT_OK``, "no profiles in STORE", is no error)."""
    if not isinstance(node, ast.Return) or node.value is None:
        return False
    v = node.value
    return (isinstance(v, ast.Constant) and isinstance(v.value, int) and v.value != 0) or (
        isinstance(v, ast.Name) and v.id.startswith("EXIT_") and v.id != "EXIT_OK"
    )


def _printers(tree: ast.Module) -> set[str]:
    """The module's functions that print on stderr (``_error(msg)``: a print by another name)."""
    return {
        f.name
        for f in tree.body
        if isinstance(f, ast.FunctionDef) and any(_is_stderr_print(n) for n in ast.walk(f) if isinstance(n, ast.stmt))
    }


def print_then_return(source: str, name: str = "<source>") -> list[str]:
    """``name:line`` of every ``print(..., file=sys.stderr)`` (or call of a function of the module
    that prints so) directly followed by a code return."""
    tree = ast.parse(source)
    printers = _printers(tree)

    def prints(node: ast.stmt) -> bool:
        if _is_stderr_print(node):
            return True
        call = node.value if isinstance(node, ast.Expr) else None
        return isinstance(call, ast.Call) and isinstance(call.func, ast.Name) and call.func.id in printers

    found = []
    for node in ast.walk(tree):
        for field in ("body", "orelse", "finalbody"):
            body = getattr(node, field, None)
            if not isinstance(body, list):
                continue
            for a, b in zip(body, body[1:]):
                if prints(a) and _is_code_return(b):
                    found.append(a.lineno)
    return [f"{name}:{line}" for line in sorted(found)]


def test_the_checker_finds_a_print_then_return_and_nothing_else():
    bad = textwrap.dedent(
        """
        import sys

        def _error(msg) -> int:
            print(f"harp x: {msg}", file=sys.stderr)
            return EXIT_ERROR

        def run(args):
            try:
                go()
            except ValueError as exc:
                print(f"harp x: {exc}", file=sys.stderr)
                return 2
            if args.n < 1:
                _error("--n must be at least 1")
                return EXIT_ERROR
            return 0
        """
    )
    assert print_then_return(bad) == ["<source>:5", "<source>:12", "<source>:15"]
    fine = textwrap.dedent(
        """
        import sys

        def run(args):
            status = 0
            for path in args.images:  # a bad file is said; the others go on
                try:
                    go(path)
                except InputError as exc:
                    print(f"harp x: {exc}", file=sys.stderr)
                    status = EXIT_ERROR
            print("wrote it", file=sys.stderr)
            print("done")
            if not args.images:
                print("no images", file=sys.stderr)
                return EXIT_OK
            return status
        """
    )
    assert print_then_return(fine) == []


def test_the_checker_sees_the_commands_say_and_warn_as_prints():
    bad = textwrap.dedent(
        """
        from station.cli.say import say, warn

        def _error(msg):
            say("harp x", msg)

        def run(args):
            if args.n < 1:
                say("harp x", "--n must be at least 1")
                return EXIT_ERROR
            if args.m < 1:
                _error("--m must be at least 1")
                return 2
            warn("harp x", "no images")
            return EXIT_OK
        """
    )
    assert print_then_return(bad) == ["<source>:9", "<source>:12"]


def test_no_command_prints_an_error_and_returns_a_code():
    found = []
    for path in sorted((REPO / "station" / "cli").glob("*.py")):
        if path.name == "__init__.py":  # the entry point: where the one line is printed
            continue
        found += print_then_return(path.read_text(encoding="utf-8"), str(path.relative_to(REPO)))
    assert found == [], "raise a station.errors.HarpError instead (printed once by station.cli.main)"


def test_the_station_errors_are_harp_errors_with_their_exit_codes():
    from station.config import ConfigError
    from station.errors import InputError
    from station.imageio import ImageReadError
    from station.profile_choice import ChoiceError, FailedQA
    from station.qa.targets import QAInputError
    from station.reprocess import ReprocessError
    from station.session.directory import SessionError
    from station.session_run import ReportError
    from station.store import StoreError
    from station.web.serve import ServeError

    for cls in (ConfigError, ImageReadError, InputError, ChoiceError, QAInputError, ReprocessError, SessionError):
        assert issubclass(cls, HarpError) and cls.exit_code == EXIT_ERROR, cls
    for cls in (ReportError, StoreError, ServeError):
        assert issubclass(cls, HarpError) and cls.exit_code == EXIT_ERROR, cls
    assert issubclass(FailedQA, HarpError) and FailedQA.exit_code == EXIT_FAIL
    assert Interrupted.exit_code == EXIT_INTERRUPTED
    # the built-in bases they had are kept: callers that catch those still do
    assert issubclass(ConfigError, ValueError) and issubclass(StoreError, RuntimeError)
    assert issubclass(SessionError, RuntimeError) and issubclass(ServeError, ValueError)


@pytest.mark.parametrize(
    ("message", "line"),
    [("a.png: no strings", "a.png: no strings"), ("a\n  b\tc ", "a b c"), ("", "")],
)
def test_one_line(message, line):
    assert one_line(message) == line


NOT_HARP = "Not a HarpError:"
"""How an error class outside :class:`station.errors.HarpError` says why, in its docstring."""

BUILTIN_ERRORS = {n for n, v in vars(builtins).items() if isinstance(v, type) and issubclass(v, BaseException)}


def errors_outside_harp_error(sources: dict[str, str]) -> tuple[list[str], list[str]]:
    """``(unexplained, explained)``: ``path:line: Name`` of every error class of ``sources`` (path ->
    text) that is no HarpError, without and with a :data:`NOT_HARP` reason (its own or a base's)."""
    classes: dict[str, tuple[str, int, set[str], str]] = {}
    for path, text in sources.items():
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef):
                bases = {b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases}
                classes[node.name] = (path, node.lineno, bases, ast.get_docstring(node) or "")

    def chain(name: str, seen: frozenset[str] = frozenset()) -> set[str]:
        """``name`` and the names of every class it derives from."""
        if name not in classes or name in seen:
            return {name}
        return {name}.union(*(chain(b, seen | {name}) for b in classes[name][2]))

    unexplained, explained = [], []
    for name, (path, line, _, _) in classes.items():
        names = chain(name)
        if name == "HarpError" or "HarpError" in names or not names & BUILTIN_ERRORS:
            continue
        says = any(NOT_HARP in classes[n][3] for n in names if n in classes)
        (explained if says else unexplained).append(f"{path}:{line}: {name}")
    return sorted(unexplained), sorted(explained)


def test_the_error_checker_sees_what_it_must():
    source = textwrap.dedent(
        '''
        class HarpError(Exception):
            pass

        class InputError(HarpError, ValueError):
            pass

        class BadInput(InputError):
            pass

        class Lost(LookupError):
            """Gone."""

        class DriverError(Exception):
            """A device's error.

            Not a HarpError: drivers import nothing of station.
            """

        class DeviceTimeout(DriverError):
            pass

        class Settings:
            pass
        '''
    )
    unexplained, explained = errors_outside_harp_error({"m.py": source})
    assert unexplained == ["m.py:11: Lost"]
    assert explained == ["m.py:14: DriverError", "m.py:20: DeviceTimeout"]


def test_every_error_class_is_a_harp_error_or_says_why_not():
    sources = {
        str(p.relative_to(REPO)): p.read_text(encoding="utf-8")
        for pkg in ("station", "drivers", "pipeline")
        for p in sorted((REPO / pkg).rglob("*.py"))
    }
    unexplained, explained = errors_outside_harp_error(sources)
    assert unexplained == [], f"derive from station.errors.HarpError or say in the docstring: {NOT_HARP} ..."
    # the classes that say why (issue 22): the drivers' family, the session's control flow, the web's HTTP
    # answers and the bounded reader's, which each reader turns into its own HarpError; a stop signal's interrupt
    names = sorted(e.rsplit(": ", 1)[1] for e in explained)
    assert names == sorted(
        [
            "BadQuery",
            "Ambiguous",
            "NotFound",
            "Unavailable",
            "BoundedReadError",
            "SessionAborted",
            "NoOperator",
            "DriverError",
            "DeviceTimeout",
            "DeviceRejected",
            "DeviceFault",
            "ProtocolError",
            "DeviceDisconnected",
            "CaptureError",
            "OutOfRange",
            "ConfigKeyError",
            "Stopped",
        ]
    )


AS_IS = "# not through say:"
"""The comment above a ``print(..., file=sys.stderr)`` that is no ``harp COMMAND:`` line, saying why."""


def stderr_prints(source: str, name: str = "<source>") -> tuple[list[str], list[str]]:
    """``(unexplained, explained)``: ``name:line`` of every ``print(..., file=sys.stderr)`` of
    ``source``, without and with an :data:`AS_IS` comment on the line above it."""
    lines = source.splitlines()
    unexplained, explained = [], []
    for node in ast.walk(ast.parse(source)):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print"):
            continue
        if not any(
            k.arg == "file" and isinstance(k.value, ast.Attribute) and k.value.attr == "stderr" for k in node.keywords
        ):
            continue
        above = lines[node.lineno - 2].strip() if node.lineno >= 2 else ""
        (explained if above.startswith(AS_IS) else unexplained).append(f"{name}:{node.lineno}")
    return sorted(unexplained), sorted(explained)


def test_the_stderr_checker_sees_what_it_must():
    source = textwrap.dedent(
        """
        import sys
        print("note", file=sys.stderr)
        # not through say: the address line, read by scripts
        print("serving on ...", file=sys.stderr, flush=True)
        print("to stdout")
        say = lambda text: print(text, file=sys.stderr)
        print("a file", file=out)
        """
    )
    assert stderr_prints(source) == (["<source>:3", "<source>:7"], ["<source>:5"])


def test_every_line_on_stderr_is_said_by_the_command_or_says_why_not():
    unexplained, explained = [], []
    for path in sorted((REPO / "station").rglob("*.py")):
        if path == REPO / "station" / "cli" / "say.py":  # the one print of say()
            continue
        u, e = stderr_prints(path.read_text(encoding="utf-8"), str(path.relative_to(REPO)))
        unexplained += u
        explained += e
    assert unexplained == [], "say it with station.cli.say (say, warn), or say why not: " + AS_IS
    # the two address lines scripts read and the operator's prompt (issue 22)
    assert sorted(e.split(":")[0] for e in explained) == [
        "station/live/session_tap.py",
        "station/session/operator.py",
        "station/web/serve.py",
    ]
