"""Start-up of ``harp`` as a whole process (issue 21 item 5): ``--version``, ``--help``, a mistyped
command and ``session --help``, against the code of an earlier commit.

Usage::

    .venv/bin/python benchmarks/startup.py [--repeat 9] [--before e0960ba]

Each command is run as the user runs it (``python -m station.cli ARGS``, started with
``subprocess``): interpreter start-up, imports, parsing, output. Per command, after one uncounted
warm-up run, the minimum, median and maximum over ``--repeat`` runs of the wall time and of the
process's user + system CPU time (``os.wait4``), the runs of ``HEAD`` and of ``--before`` (the
code before the change, unpacked by ``git archive`` into a temporary directory and put first on
``PYTHONPATH``) taking turns, A B A B ..., so a drifting machine load falls on both alike; the
ratio is HEAD's median over the earlier one's. Twice: with Python's bytecode cache (in a
temporary ``PYTHONPYCACHEPREFIX``, written by the warm-up) and without
(``PYTHONDONTWRITEBYTECODE=1``, as in the development sandbox: every module of the tree compiled
at each start, the standard library's and the installed packages' bytecode read as installed).
Both trees are commits unpacked by ``git archive`` (this one: ``HEAD``), so neither holds bytecode
of its own.
Then, per command, how many modules the process held at exit and which heavy ones among them
(numpy, scipy, cv2, matplotlib, sqlalchemy, yaml, PIL). Target (issue 21): <= 0.25 s for
``--version``, ``--help`` and a typo.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = (("--version",), ("--help",), ("calibrat", "a.pgm"), ("session", "--help"))
HEAVY = ("numpy", "scipy", "cv2", "matplotlib", "sqlalchemy", "yaml", "PIL")
MODULES_AT_EXIT = """
import atexit, os, runpy, sys
atexit.register(lambda: open(os.environ["STARTUP_MODULES_TO"], "w").write("\\n".join(sorted(sys.modules))))
sys.argv[0] = "harp"
runpy.run_module("station.cli", run_name="__main__", alter_sys=True)
"""


def run_once(cmd: list[str], env: dict[str, str], cwd: Path) -> tuple[float, float]:
    """Wall and CPU (user + system) seconds of one run of ``cmd``, its output thrown away."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, cwd=cwd)
    _, _, usage = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    p.returncode = 0  # reaped by wait4
    return wall, usage.ru_utime + usage.ru_stime


def bytecode_environment(pycache: Path | None, **extra: str) -> dict[str, str]:
    """This process's environment with ``extra``; the bytecode cache in ``pycache``, or (None) none
    written, as in a sandbox with ``PYTHONDONTWRITEBYTECODE=1``."""
    env = dict(os.environ, **extra)
    if pycache is None:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
        env.pop("PYTHONPYCACHEPREFIX", None)
    else:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(pycache)
    return env


def environment(tree: Path, pycache: Path | None) -> dict[str, str]:
    """``tree`` first on the path; the bytecode cache in ``pycache``, or (None) none written, as
    in a sandbox with ``PYTHONDONTWRITEBYTECODE=1``: the installed packages' and the standard
    library's bytecode read as installed, every module of the tree compiled at each start."""
    return bytecode_environment(pycache, PYTHONPATH=str(tree))


def paired(args: tuple[str, ...], trees: dict[str, Path], repeat: int, cache: Path | None) -> dict[str, list]:
    """Wall and CPU seconds of ``harp ARGS`` for each tree, the trees taking turns."""
    cmd = [sys.executable, "-m", "station.cli", *args]
    envs = {name: environment(tree, cache and cache / name) for name, tree in trees.items()}
    for name, tree in trees.items():  # warm-up: file cache, bytecode cache
        run_once(cmd, envs[name], tree)
    got: dict[str, list] = {name: [] for name in trees}
    for _ in range(repeat):
        for name, tree in trees.items():
            got[name].append(run_once(cmd, envs[name], tree))
    return got


def spread(xs: list[float]) -> str:
    return f"{statistics.median(xs):.3f} ({min(xs):.3f}-{max(xs):.3f})"


def modules(args: tuple[str, ...], tree: Path) -> set[str]:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "modules.txt"
        env = dict(environment(tree, Path(tmp) / "pyc"), STARTUP_MODULES_TO=str(out))
        subprocess.run([sys.executable, "-c", MODULES_AT_EXIT, *args], env=env, cwd=tree, capture_output=True)
        return set(out.read_text().split())


def unpack(rev: str, into: Path) -> Path:
    """The tree of commit ``rev`` in ``into`` (``git archive``: no worktree, nothing in the repository changed)."""
    into.mkdir(parents=True)
    archive = subprocess.run(["git", "archive", rev], cwd=ROOT, capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    return into


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=9)
    ap.add_argument("--before", default="e0960ba", help="commit of the code before the change (default e0960ba)")
    opt = ap.parse_args()
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout
    load = os.getloadavg()[0]
    print(
        f"# harp start-up, whole process (`benchmarks/startup.py --repeat {opt.repeat}`; HEAD {head.strip()}"
        f" against {opt.before}; Python {platform.python_version()}, {os.cpu_count()} CPUs, load {load:.1f})\n"
    )
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"now": unpack("HEAD", Path(tmp) / "now"), "before": unpack(opt.before, Path(tmp) / "before")}
        caches = (
            ("bytecode cache in use", Path(tmp) / "pyc"),
            ("no bytecode written (PYTHONDONTWRITEBYTECODE=1)", None),
        )
        for title, cache in caches:
            print(f"## {title}: median (min-max) of {opt.repeat} runs, seconds\n")
            print("| command | wall now | wall before | CPU now | CPU before | wall now/before |")
            print("|---|---:|---:|---:|---:|---:|")
            for args in COMMANDS:
                got = paired(args, trees, opt.repeat, cache)
                wall = {k: [w for w, _ in v] for k, v in got.items()}
                cpu = {k: [c for _, c in v] for k, v in got.items()}
                ratio = statistics.median(wall["now"]) / statistics.median(wall["before"])
                print(
                    f"| `harp {' '.join(args)}` | {spread(wall['now'])} | {spread(wall['before'])} | "
                    f"{spread(cpu['now'])} | {spread(cpu['before'])} | {ratio:.2f} |"
                )
            print()
        print("## modules held at exit\n")
        print("| command | modules now | modules before | heavy now | heavy before |")
        print("|---|---:|---:|---|---|")
        for args in COMMANDS:
            now, before = modules(args, trees["now"]), modules(args, trees["before"])

            def heavy(names: set[str]) -> str:
                return ", ".join(h for h in HEAVY if h in names) or "none"

            print(f"| `harp {' '.join(args)}` | {len(now)} | {len(before)} | {heavy(now)} | {heavy(before)} |")


if __name__ == "__main__":
    main()
