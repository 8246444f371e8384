"""``harp`` starts fast (issue 21 item 5): ``--version``, ``--help`` and a mistyped command import
no command module and nothing heavy; a mistype is one line naming the closest command, exit 2;
``--help`` lists every command. Each run as the user runs it: ``python -m station.cli`` in a
process of its own (the timings themselves: benchmarks/startup.py)."""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
from contextlib import suppress
from pathlib import Path

import pytest

from station.cli import build_parser
from station.cli.commands import COMMANDS

REPO = Path(__file__).resolve().parents[3]

HEAVY = ("numpy", "scipy", "cv2", "matplotlib", "sqlalchemy", "yaml", "PIL", "rich", "psycopg", "dask")
"""Packages a command may need and ``--version``/``--help`` must not pay for."""

# every sub-command of the tree, found from the files, not from the table under test
COMMAND_FILES = sorted(
    p.stem
    for p in (REPO / "station" / "cli").glob("*.py")
    if "\ndef register(" in p.read_text() and not p.stem.startswith("_")
)


def harp(*args: str, modules_to: Path | None = None) -> subprocess.CompletedProcess[str]:
    """``python -m station.cli ARGS`` in its own process group, killed with it on every exit; with
    ``modules_to``, the names in the process's ``sys.modules`` as it exits are written there."""
    cmd = [sys.executable, "-m", "station.cli", *args]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    if modules_to is not None:
        cmd = [sys.executable, "-c", MODULES_AT_EXIT, *args]
        env["HARP_TEST_MODULES_TO"] = str(modules_to)
    p = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO, env=env, start_new_session=True
    )
    try:
        out, err = p.communicate(timeout=120)
    finally:
        with suppress(ProcessLookupError):
            os.killpg(p.pid, signal.SIGKILL)
        p.wait()
    return subprocess.CompletedProcess(p.args, p.returncode, out, err)


MODULES_AT_EXIT = """
import atexit, os, runpy, sys
def write():
    with open(os.environ["HARP_TEST_MODULES_TO"], "w") as f:
        f.write("\\n".join(sorted(sys.modules)))
atexit.register(write)
sys.argv[0] = "harp"
runpy.run_module("station.cli", run_name="__main__", alter_sys=True)
"""
"""``python -m station.cli`` (its ``__main__``, as ``harp`` runs it), ``sys.modules`` written at exit."""


def modules_of(args: tuple[str, ...], tmp_path: Path) -> tuple[subprocess.CompletedProcess[str], set[str]]:
    out = tmp_path / "modules.txt"
    run = harp(*args, modules_to=out)
    return run, set(out.read_text().split())


def test_the_files_hold_the_commands_of_the_table():
    assert len(COMMAND_FILES) >= 14
    assert sorted(COMMANDS) == COMMAND_FILES


@pytest.mark.parametrize("args", [("--version",), ("--help",), ("calibrat",)])
def test_version_help_and_a_typo_import_no_command_module_and_nothing_heavy(args, tmp_path):
    run, names = modules_of(args, tmp_path)
    assert run.returncode in (0, 2) and "station.cli" in names and "Traceback" not in run.stderr
    commands = sorted(n for n in names if n.startswith("station.cli.") and n.rsplit(".", 1)[1] in COMMANDS)
    heavy = sorted(n for n in names if n.split(".")[0] in HEAVY)
    assert commands == [] and heavy == []


def test_a_command_imports_its_own_module_only(tmp_path):
    run, names = modules_of(("config", "--help"), tmp_path)
    assert run.returncode == 0 and "usage: harp config" in run.stdout
    assert "station.cli.config" in names
    others = sorted(
        n for n in names if n.startswith("station.cli.") and n.rsplit(".", 1)[1] in set(COMMANDS) - {"config"}
    )
    assert others == []


@pytest.mark.parametrize(
    "typo, line",
    [
        ("calibrat", "harp: unknown command 'calibrat'; did you mean 'calibrate'?"),
        ("sesion", "harp: unknown command 'sesion'; did you mean 'session'?"),
        ("exprot", "harp: unknown command 'exprot'; did you mean 'export'?"),
        ("xyzzy", "harp: unknown command 'xyzzy'; 'harp --help' lists the commands"),
    ],
)
def test_a_mistyped_command_is_one_line_with_the_closest_command_exit_2(typo, line):
    run = harp(typo, "a.pgm", "--json")
    assert run.returncode == 2
    assert run.stderr == line + "\n" and run.stdout == ""


def test_help_lists_every_command_with_its_one_line_help_and_no_markup():
    run = harp("--help")
    assert run.returncode == 0 and run.stderr == ""
    listed = run.stdout.split("COMMAND\n", 1)[1].split("\noptions:", 1)[0]
    words = " ".join(listed.split())
    for name in COMMAND_FILES:
        assert f" {name} " in f" {words} ", name
        assert " ".join(COMMANDS[name].split()) in words, name
    assert "--version" in run.stdout
    for mark in ("``", ":func:", ":mod:", ":class:", ":meth:", ":data:", ".. "):
        assert mark not in run.stdout, mark


def test_version_prints_the_installed_version():
    from importlib.metadata import version

    run = harp("--version")
    assert (run.returncode, run.stdout, run.stderr) == (0, f"harp station {version('harp-station')}\n", "")


def test_no_command_prints_the_help_on_stderr_exit_2():
    run = harp()
    assert run.returncode == 2 and run.stdout == "" and "calibrate" in run.stderr


def test_each_command_module_registers_the_help_of_the_table():
    """The full parser (every module imported) lists the same one-line helps, in the same order."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert [(c.dest, c.help) for c in sub._choices_actions] == list(COMMANDS.items())
    assert list(sub.choices) == list(COMMANDS)
