"""The processes a ``harp`` command left behind, read from /proc (tests started with
``start_new_session=True``: the command's process group is its pid)."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
from pathlib import Path


def group_members(pgid: int) -> list[int]:
    """Live (non-zombie) processes of a process group, from /proc."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            out.append(int(stat.parent.name))
    return out


def run_process(argv: list[str], timeout: float, **kwargs) -> subprocess.CompletedProcess:
    """Run ``argv`` in its own process group to the end (text output captured) and kill that group,
    whatever happens: a timeout, a failed assertion in the caller's ``with``, an interrupt."""
    proc = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True, **kwargs
    )
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


def default_stop_signals() -> None:
    """A child's ``preexec_fn``: SIGTERM and SIGHUP with their default action, as a command started from a terminal
    or by a service manager has them, whatever started the tests (``nohup`` ignores SIGHUP, and an ignored signal
    stays ignored across exec)."""
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)
