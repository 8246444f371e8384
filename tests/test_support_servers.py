"""The real servers the tests use start and answer: PostgreSQL (tests/pg_server.py) and Chromium (tests/browser.py)."""

import contextlib
import http.server
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from tests.pg_server import postgres_bin_dir

REPO = Path(__file__).resolve().parents[1]


def test_postgres_fixture_serves_a_database_on_loopback(postgres):
    psql = str(postgres_bin_dir() / "psql")
    out = subprocess.run(
        [psql, postgres.url, "-tAc", "SELECT current_user, inet_server_addr()"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "harp|127.0.0.1"
    other = postgres.create_database("support_check")
    out = subprocess.run([psql, other, "-tAc", "SELECT current_database()"], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "support_check"


def test_browser_fixture_renders_a_local_page(page, tmp_path):
    (tmp_path / "index.html").write_text(
        "<title>harp</title><p id=x>strings</p><script>document.getElementById"
        "('x').textContent += ' seen by js'</script>"
    )

    class Handler(http.server.SimpleHTTPRequestHandler):
        def __init__(self, *a, **k):
            super().__init__(*a, directory=str(tmp_path), **k)

        def log_message(self, *a):  # quiet
            pass

    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    try:
        page.goto(f"http://127.0.0.1:{srv.server_port}/index.html")
        assert page.title() == "harp"
        assert page.text_content("#x") == "strings seen by js"
    finally:
        srv.shutdown()
        srv.server_close()


# A test run ended by SIGTERM (a cancelled CI job, ``timeout``): the run's PostgreSQL server, which pg_ctl
# daemonised out of the run's process group, is stopped and its directory removed all the same.
WAITING_TEST = """
import os, time
from pathlib import Path

def test_waits(postgres):
    pid = int((postgres.data_dir / "postmaster.pid").read_text().split()[0])
    Path(os.environ["HARP_TEST_SERVER_FILE"]).write_text(f"{pid} {postgres.root}")
    time.sleep(600)
"""


@pytest.mark.parametrize(
    "workers, group",
    [(None, False), (1, False), (1, True)],
    ids=["in process", "xdist worker", "xdist, the whole process group"],
)
def test_a_run_ended_by_sigterm_stops_its_postgres_server(workers, group, tmp_path):
    (tmp_path / "test_waits.py").write_text(WAITING_TEST)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")  # not the repository's options
    told = tmp_path / "server.txt"
    env = {**os.environ, "PYTHONPATH": str(REPO), "HARP_TEST_SERVER_FILE": str(told)}
    argv = [sys.executable, "-m", "pytest", "-q", "-p", "tests.conftest", "-p", "no:cacheprovider", "test_waits.py"]
    if workers:
        argv += ["-n", str(workers)]
    proc = subprocess.Popen(
        argv,
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
        preexec_fn=_as_a_background_job,
    )
    pid, root = None, None
    try:
        deadline = time.monotonic() + 120
        while not told.exists() or not told.read_text():
            assert proc.poll() is None, proc.communicate()[0]
            assert time.monotonic() < deadline, "the server did not start"
            time.sleep(0.1)
        text = told.read_text().split(maxsplit=1)
        pid, root = int(text[0]), Path(text[1])
        assert _alive(pid) and root.is_dir()

        if group:  # to pytest and its workers, as a CI runner cancelling the job sends it
            os.killpg(proc.pid, signal.SIGTERM)
        else:  # to pytest alone, as kill(1) or timeout(1) sends it
            proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + 30
        while (_alive(pid) or root.exists()) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _alive(pid), f"postmaster {pid} still running after SIGTERM to the test run"
        assert not root.exists(), f"{root} still there after SIGTERM to the test run"
        out, _ = proc.communicate(timeout=60)
        assert proc.returncode != 0 and "KeyboardInterrupt" in out, out
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        if root is not None and (root / "data").is_dir():  # never leave one behind, whatever failed
            cmd = [str(postgres_bin_dir() / "pg_ctl"), "-D", str(root / "data"), "-m", "immediate", "-w", "stop"]
            if os.geteuid() == 0:
                cmd = ["runuser", "-u", "postgres", "--", *cmd]
            subprocess.run(cmd, capture_output=True, timeout=60, check=False)
        if root is not None:
            shutil.rmtree(root, ignore_errors=True)


def _as_a_background_job() -> None:
    """The run started as a script's background job (or under nohup) is: SIGINT ignored, SIGTERM heard
    (whatever this run's own dispositions are)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _alive(pid: int) -> bool:
    """Whether a process runs (not a zombie)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"
