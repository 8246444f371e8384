"""station/ctrl_c.py: a Ctrl-C reaches the command once, is never lost, and no worker prints a traceback.

Each case runs in a process of its own, with real signals."""

from __future__ import annotations

import subprocess
import sys

import pytest

# A real SIGINT that arrives while the main thread runs a weakref callback (the import system
# runs one whenever a module lock is dropped): CPython cannot raise the KeyboardInterrupt out of
# the callback, prints "Exception ignored in ..." with a traceback and carries on.
CTRL_C_IN_A_CALLBACK = """
import os, signal, sys, time, weakref
if sys.argv[1] == "harp":
    from station.cli import main
    assert main(["measure", sys.argv[2]]) == 2  # any harp command: the process-wide set-up
class Obj:
    pass
def callback(_ref):
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.05)
obj = Obj()
ref = weakref.ref(obj, callback)
try:
    del obj  # the callback runs here, and the Ctrl-C arrives in it
    for _ in range(300):
        time.sleep(0.01)
    print("lost")
except KeyboardInterrupt:
    print("delivered")
"""


@pytest.mark.parametrize("process", ["plain python", "harp"])
def test_a_ctrl_c_that_cpython_drops_in_a_callback_is_delivered_again_silently(process, tmp_path):
    missing = tmp_path / "missing.png"
    proc = subprocess.run(
        [sys.executable, "-c", CTRL_C_IN_A_CALLBACK, process.split()[-1], str(missing)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    if process == "plain python":  # the premise: without harp's hook the Ctrl-C is lost, with a traceback
        assert proc.stdout.strip() == "lost" and "KeyboardInterrupt" in proc.stderr
        return
    assert proc.stdout.strip() == "delivered", proc.stderr
    assert proc.stderr == f"harp measure: {missing}: no such file\n"  # that command's line, nothing else


# The forkserver started while a Ctrl-C arrives (sent from inside its start), then a pool worker,
# then a Ctrl-C to the whole process group, as a terminal sends it.
FORKSERVER = """
import os, signal, sys, time
import multiprocessing as mp
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import forkserver
from station.ctrl_c import start_forkserver_deaf_to_ctrl_c

def blocked(pid):
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("SigBlk:"):
            return bool(int(line.split()[1], 16) & (1 << (signal.SIGINT - 1)))

if __name__ == "__main__":  # the workers import this file again
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(["station.reprocess"])  # imports that take a while, as in the commands
    start = forkserver.ensure_running
    def ensure_running_with_a_ctrl_c():
        os.kill(os.getpid(), signal.SIGINT)  # pressed while the forkserver is being started
        start()
    forkserver.ensure_running = ensure_running_with_a_ctrl_c
    try:
        start_forkserver_deaf_to_ctrl_c()
        print("lost")
    except KeyboardInterrupt:
        print("delivered")
    print("main blocks SIGINT after:", blocked(os.getpid()))
    print("forkserver blocks SIGINT:", blocked(forkserver._forkserver._forkserver_pid))
    with ProcessPoolExecutor(1, mp_context=ctx) as pool:
        worker = pool.submit(os.getpid).result()
        print("worker blocks SIGINT:", blocked(worker))
        caught = []
        signal.signal(signal.SIGINT, lambda *_: caught.append(1))
        os.killpg(os.getpgid(0), signal.SIGINT)  # Ctrl-C at the terminal
        time.sleep(0.5)
        print("worker still serves:", pool.submit(os.getpid).result() == worker, "main caught:", len(caught))
"""


def test_forkserver_started_deaf_to_ctrl_c_and_a_ctrl_c_during_its_start_is_not_lost(tmp_path):
    script = tmp_path / "forkserver_ctrl_c.py"  # a file: the forkserver's workers re-import __main__ by path
    script.write_text(FORKSERVER)
    proc = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=120, start_new_session=True
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines() == [
        "delivered",
        "main blocks SIGINT after: False",
        "forkserver blocks SIGINT: True",
        "worker blocks SIGINT: True",
        "worker still serves: True main caught: 1",
    ], proc.stderr
    assert proc.stderr == ""  # no traceback from the forkserver or the worker


# A Ctrl-C that leaves an exec() of a string (dataclasses and namedtuples are made that way) and is
# then handled: CPython 3.11 still ends the process by SIGINT when its main code returns (as
# ``python -m station.cli`` does: runpy hands the exit code back), whatever the code said.
CTRL_C_OUT_OF_EXEC = """
import sys
if sys.argv[1] == "harp":
    import station.cli.measure
    from station.cli import main

    def run(args):
        exec("raise KeyboardInterrupt")  # the Ctrl-C lands while a dataclass is being made

    station.cli.measure.run = run
    print(main(["measure", "photo.png"]))
else:
    try:
        exec("raise KeyboardInterrupt")
    except KeyboardInterrupt:
        print(130)
"""


@pytest.mark.parametrize("process", ["plain python", "harp"])
def test_a_handled_ctrl_c_is_not_turned_into_a_death_by_sigint(process):
    proc = subprocess.run(
        [sys.executable, "-c", CTRL_C_OUT_OF_EXEC, process.split()[-1]], capture_output=True, text=True, timeout=60
    )
    assert proc.stdout == "130\n"  # handled, either way
    if process == "plain python":  # the premise: the process then dies by SIGINT all the same
        assert proc.returncode == -2, (proc.returncode, proc.stderr)
        return
    assert proc.returncode == 0, proc.stderr  # the script's own end: main's 130 was printed, not lost
    assert proc.stderr == "harp: interrupted\n"


# SIGTERM and SIGHUP are answered as a Ctrl-C while a command runs (station.ctrl_c.stop_signals_as_ctrl_c), and
# only then: the process's own handlers before and after, an ignored signal left ignored, forked children
# with the signal's own action.
STOP_SIGNALS = """
import os, signal, sys, time
from station.ctrl_c import Stopped, stop_signals_as_ctrl_c, stopped_exit_code, stopped_text

def mine(*_):
    pass

signal.signal(signal.SIGHUP, signal.SIG_IGN if sys.argv[1] == "nohup" else mine)
with stop_signals_as_ctrl_c():
    print("SIGHUP kept:", signal.getsignal(signal.SIGHUP) is (signal.SIG_IGN if sys.argv[1] == "nohup" else mine))
    pid = os.fork()
    if pid == 0:  # a forked worker: SIGTERM's own action (death), never the command's handler
        ok = signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
        os._exit(0 if ok else 3)
    print("child had the default:", os.waitpid(pid, 0)[1] == 0)
    print("before:", stopped_text(), stopped_exit_code())
    try:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
        print("lost")
    except Stopped as exc:
        print("stopped:", isinstance(exc, KeyboardInterrupt), stopped_text(), stopped_exit_code())
print("restored:", signal.getsignal(signal.SIGTERM) is signal.SIG_DFL)
"""


@pytest.mark.parametrize("sighup", ["handled", "nohup"])
def test_stop_signals_are_answered_as_a_ctrl_c_inside_the_command_only(sighup):
    proc = subprocess.run(
        [sys.executable, "-c", STOP_SIGNALS, sighup], capture_output=True, text=True, timeout=60, start_new_session=True
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines() == [
        "SIGHUP kept: True",
        "child had the default: True",
        "before: interrupted 130",
        "stopped: True stopped by SIGTERM 143",
        "restored: True",
    ], proc.stderr
    assert proc.stderr == ""


def test_a_second_sigterm_while_stopping_ends_the_process_by_sigterm():
    """Asked again while it stops (a cleanup that hangs): the signal's own action, as before."""
    script = """
import os, signal, time
from station.ctrl_c import Stopped, stop_signals_as_ctrl_c
with stop_signals_as_ctrl_c():
    try:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
    except Stopped:
        print("stopping", flush=True)
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
        print("not ended")
"""
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, start_new_session=True
    )
    assert proc.returncode == -15 and proc.stdout == "stopping\n", (proc.returncode, proc.stdout, proc.stderr)
