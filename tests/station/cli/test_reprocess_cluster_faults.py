"""``harp reprocess --scheduler`` when the Dask cluster fails under it: real ``dask scheduler`` and ``dask worker``
processes, each started in its own process group and killed with it whatever the test does; ``harp reprocess``
run as a process into a real SQLite file, whose rows are counted.

A worker killed mid-job is replaced and its job run again; every worker that ran a job dying is one line naming
the session; the scheduler killed mid-run is one line saying what was stored; a worker that cannot import harp
station, or runs other code under the same version, is one line before any job is sent and before the store is
opened (it was a hang: each job it was sent killed it; other code went undetected), as a port where
something else listens is (a hang in Dask's client); a session directory gone before its job ran is one line
saying that the workers must see it. In each case what was stored is whole, and running the command again
stores the rest, each session once.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from station import __version__
from tests.station.archive import REPO

pytestmark = pytest.mark.filterwarnings("ignore")  # the test's own Dask client on a cluster killed under it

ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), *filter(None, [os.environ.get("PYTHONPATH")])])}
"""Every process of these tests imports this checkout (the scheduler unpickles nothing of it, the workers do)."""

NO_HARP = """
import importlib.util, sys
from pathlib import Path
sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in str(getattr(f, "__module__", ""))]
sys.path[:] = [p for p in sys.path if not (Path(p or ".") / "station").is_dir()]
assert importlib.util.find_spec("station") is None
from distributed.cli.dask_worker import main
sys.argv[0] = "dask worker"
main()
"""
"""A worker process that cannot import harp station (``python -c NO_HARP ADDRESS --no-nanny ...``): its editable
install and any directory holding ``station`` taken off its path."""


class Cluster:
    """A Dask scheduler and its workers as separate process groups; :meth:`close` kills every group."""

    def __init__(self, tmp: Path, env: dict[str, str] | None = None) -> None:
        self.tmp, self.procs = tmp, []
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.scheduler = self._start(
            ["-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", str(self.port)],
            "scheduler",
            {**ENV, **(env or {})},
        )
        deadline = time.monotonic() + 120
        while True:
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", self.port), timeout=1):
                break
            assert time.monotonic() < deadline and self.scheduler.poll() is None, self.log("scheduler")
            time.sleep(0.2)

    def _start(self, args: list[str], name: str, env: dict[str, str]) -> subprocess.Popen:
        with open(self.tmp / f"{name}.log", "wb") as log:
            p = subprocess.Popen(
                [sys.executable, *args, "--no-dashboard"],
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                env=env,
                cwd=self.tmp,
                start_new_session=True,
            )
        self.procs.append(p)
        return p

    def log(self, name: str) -> str:
        return (self.tmp / f"{name}.log").read_text(errors="replace")[-3000:]

    def add_workers(self, n: int, *, harp: bool = True, code: Path | None = None, nanny: bool = True) -> None:
        """``n`` workers: with this checkout on their path, without harp station (``harp=False``), or with the
        packages under ``code`` first on their path; ``nanny=False``: a worker killed stays dead."""
        have = len(self.client().scheduler_info()["workers"])
        started = []
        for _ in range(n):
            k = len(self.procs)
            if harp:
                args = ["-m", "distributed.cli.dask_worker", self.address, "--nthreads", "1"]
                args += [] if nanny else ["--no-nanny"]
                env = ENV if code is None else {**ENV, "PYTHONPATH": os.pathsep.join([str(code), ENV["PYTHONPATH"]])}
                started.append((self._start(args, f"w{k}", env), f"w{k}"))
            else:
                env = {k: v for k, v in ENV.items() if k != "PYTHONPATH"}
                args = ["-c", NO_HARP, self.address, "--nthreads", "1", "--no-nanny"]
                started.append((self._start(args, f"w{k}", env), f"w{k}"))
        deadline = time.monotonic() + 180
        while len(self.client().scheduler_info(n_workers=-1)["workers"]) < have + n:
            for p, name in started:
                assert p.poll() is None, self.log(name)
            assert time.monotonic() < deadline, "the workers did not join in 180 s"
            time.sleep(0.2)

    def client(self):
        from dask.distributed import Client

        if getattr(self, "_client", None) is None:
            self._client = Client(self.address, timeout="60s", set_as_default=False)
        return self._client

    def busy_worker_pid(self, timeout: float = 120) -> int:
        """The pid of a worker process running a job now (its nanny restarts it when it is killed)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            busy = [addr for addr, keys in self.client().processing().items() if keys]
            if busy:
                return self.client().run(os.getpid, workers=busy[:1])[busy[0]]
            time.sleep(0.05)
        raise AssertionError("no worker was running a job")

    def close(self) -> None:
        client, self._client = getattr(self, "_client", None), None
        if client is not None:
            with contextlib.suppress(Exception):
                client.close(timeout=5)
        for p in self.procs:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGKILL)
            p.wait()


@pytest.fixture
def clusters(tmp_path):
    """``make(env=None)``: a new :class:`Cluster`; every one made is killed, group by group, on every exit path."""
    made: list[Cluster] = []

    def make(env: dict[str, str] | None = None) -> Cluster:
        d = tmp_path / f"cluster{len(made)}"
        d.mkdir()
        made.append(Cluster(d, env))
        return made[-1]

    try:
        yield make
    finally:
        for c in made:
            c.close()


def _sessions(factory_archive, tmp_path, n: int) -> list[Path]:
    out = []
    for k in range(n):
        shutil.copytree(factory_archive.session, tmp_path / f"s{k}")
        out.append(tmp_path / f"s{k}")
    return out


def _rows(store: Path) -> tuple[int, int]:
    """(profiles, distinct session and focus) in the SQLite store as another process writes it."""
    try:
        with contextlib.closing(sqlite3.connect(f"file:{store}?mode=ro", uri=True, timeout=0.1)) as con:
            n, distinct = con.execute(
                "SELECT count(*), count(DISTINCT session_dir || '@' || focus) FROM profiles"
            ).fetchone()
            return int(n), int(distinct)
    except sqlite3.Error:
        return 0, 0


BOUNDED = """
import sys
import station.reprocess
station.reprocess.NO_WORKERS_S = float(sys.argv.pop(1))
from station.cli import main
raise SystemExit(main())
"""
"""``harp reprocess`` with :data:`station.reprocess.NO_WORKERS_S` given as the first argument (a test does not wait a
minute for the bound it checks)."""


def _reprocess(sessions, address: str, store: Path, no_workers_s: float | None = None) -> list[str]:
    return [
        sys.executable,
        *(["-m", "station.cli"] if no_workers_s is None else ["-c", BOUNDED, str(no_workers_s)]),
        "reprocess",
        *map(str, sessions),
        "--scheduler",
        address,
        "--store",
        str(store),
    ]


@contextlib.contextmanager
def _started(argv: list[str]):
    """``harp reprocess`` as a process in its own group, killed with its group however the test ends."""
    proc = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV, start_new_session=True
    )
    try:
        yield proc
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def _wait_stored(proc, store: Path, n: int, timeout: float = 180) -> None:
    deadline = time.monotonic() + timeout
    while _rows(store)[0] < n and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert proc.poll() is None, "harp reprocess ended before the fault could be made"
    assert _rows(store)[0] >= n


def _run(argv: list[str], timeout: float = 300) -> subprocess.CompletedProcess:
    with _started(argv) as proc:
        out, err = proc.communicate(timeout=timeout)
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


def test_a_worker_killed_mid_job_is_replaced_and_every_session_is_stored_once(factory_archive, tmp_path, clusters):
    cluster = clusters()
    cluster.add_workers(2)
    sessions, store = _sessions(factory_archive, tmp_path, 4), tmp_path / "st.sqlite"
    with _started(_reprocess(sessions, cluster.address, store)) as proc:
        _wait_stored(proc, store, 2)  # one session stored, three to go
        os.kill(cluster.busy_worker_pid(), signal.SIGKILL)
        out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0 and err == "", err
    assert "4 session(s) re-processed, 0 failed" in out
    assert _rows(store) == (8, 8)  # each session's two focus settings, once


def test_every_worker_dying_on_a_job_is_one_line_naming_the_session_and_a_second_run_stores_the_rest(
    factory_archive, tmp_path, clusters
):
    # was: "harp reprocess: Dask worker failed: KilledWorker: Attempted to run task 'reprocess_focus-8f…-4' on 1
    # different workers, …" twice in a line, naming no session
    cluster = clusters(env={"DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "0"})  # the first death is the last
    cluster.add_workers(1)
    sessions, store = _sessions(factory_archive, tmp_path, 4), tmp_path / "st.sqlite"
    argv = _reprocess(sessions, cluster.address, store)
    with _started(argv) as proc:
        _wait_stored(proc, store, 2)
        os.kill(cluster.busy_worker_pid(), signal.SIGKILL)
        out, err = proc.communicate(timeout=300)
    assert proc.returncode == 2, (out, err)
    assert "Traceback" not in err and "reprocess_focus-" not in err
    lines = err.splitlines()
    assert lines, out
    named = set()
    for line in lines:
        m = re.match(r"harp reprocess: (\S+): focus setting #\d: every Dask worker that ran it died \(1 tried, ", line)
        assert m, line
        assert "run harp reprocess again for this session" in line
        named.add(m.group(1))
    assert named <= {str(s.resolve()) for s in sessions}
    n, distinct = _rows(store)
    assert n == distinct == 2 * (len(sessions) - len(named))  # the others stored whole, each once
    again = _run(argv)  # the worker's nanny started it again
    assert again.returncode == 0 and again.stderr == "", again.stderr
    assert _rows(store) == (8, 8)


def test_the_scheduler_killed_mid_run_is_one_line_saying_what_was_stored(factory_archive, tmp_path, clusters):
    # was: a line per session of "Dask worker failed: FutureCancelledError: reprocess_focus-… cancelled for reason:
    # scheduler-connection-lost. …", then the Dask client's logged traceback
    cluster = clusters()
    cluster.add_workers(2)
    sessions, store = _sessions(factory_archive, tmp_path, 6), tmp_path / "st.sqlite"
    with _started(_reprocess(sessions, cluster.address, store)) as proc:
        _wait_stored(proc, store, 2)
        os.killpg(cluster.scheduler.pid, signal.SIGKILL)
        out, err = proc.communicate(timeout=180)  # bounded: not a wait for a scheduler that will not come back
    assert proc.returncode == 2, (out, err)
    assert err.count("\n") == 1 and "Traceback" not in err, err
    m = re.match(
        rf"harp reprocess: lost the Dask scheduler at {cluster.address} mid-run \(killed, or its machine down\?\): "
        r"(\d+) session\(s\) re-processed and stored before it; start it again, then run the same command for the "
        r"others$",
        err.strip(),
    )
    assert m, err
    assert _rows(store) == (2 * int(m.group(1)),) * 2 and int(m.group(1)) >= 1
    other = clusters()
    other.add_workers(2)
    again = _run(_reprocess(sessions, other.address, store))
    assert again.returncode == 0 and again.stderr == "", again.stderr
    assert _rows(store) == (12, 12)


def test_a_worker_without_harp_station_is_one_line_before_any_job(factory_archive, tmp_path, clusters):
    # was: a hang (each job sent killed the worker as it unpickled it, "No module named 'station'" in its log only)
    cluster = clusters()
    cluster.add_workers(1, harp=False)
    store = tmp_path / "st.sqlite"
    with _started(_reprocess([factory_archive.session], cluster.address, store)) as proc:
        out, err = proc.communicate(timeout=120)
    assert proc.returncode == 2, (out, err)
    assert re.fullmatch(
        r"harp reprocess: Dask worker tcp://127\.0\.0\.1:\d+ cannot import harp station \(ModuleNotFoundError: No "
        r"module named 'station'\); run every worker with harp station \S+ installed, as this command\n",
        err,
    ), err
    assert not store.exists()  # refused before the store was opened: no empty store left behind


def _worker_running_a_copy(tmp_path, clusters, change):
    """A cluster of one worker that runs a copy of the packages with ``change(copy_root)`` applied (another
    checkout), checked to be the code it imports."""
    other = tmp_path / "other-checkout"
    for package in ("pipeline", "station", "drivers"):
        shutil.copytree(REPO / package, other / package, ignore=shutil.ignore_patterns("__pycache__"))
    change(other)
    cluster = clusters()
    cluster.add_workers(1, code=other)
    assert cluster.client().run(eval, "__import__('station').__file__").popitem()[1] == str(
        other / "station" / "__init__.py"
    )  # the worker does run the copy
    return cluster


def _refused_before_any_job(factory_archive, tmp_path, cluster, pattern: str) -> None:
    """``harp reprocess`` on ``cluster``: exit 2, nothing on stdout, stderr one line matching ``pattern``, no
    store created."""
    store = tmp_path / "st.sqlite"
    done = _run(_reprocess([factory_archive.session], cluster.address, store), timeout=120)
    assert done.returncode == 2 and done.stdout == "", done
    assert re.fullmatch(pattern, done.stderr), done.stderr
    assert not store.exists()


def test_a_worker_running_other_code_under_the_same_version_is_one_line_before_any_job(
    factory_archive, tmp_path, clusters
):
    # was: undetected (the worker check compared version numbers only): the profiles stored would have been
    # another checkout's, under this one's version
    def changed_since(other):
        with open(other / "pipeline" / "fit.py", "a") as fh:
            fh.write("\nCHANGED_SINCE = True  # a checkout changed after the release\n")

    _refused_before_any_job(
        factory_archive,
        tmp_path,
        _worker_running_a_copy(tmp_path, clusters, changed_since),
        r"harp reprocess: Dask worker tcp://127\.0\.0\.1:\d+ runs other code than this command under the same "
        r"version \S+ \(its files of harp station differ: another checkout, or one changed since\); run every "
        r"worker with the same code as this command \(its profiles would not be this code's\)\n",
    )


def test_a_worker_running_another_version_is_one_line_before_any_job(factory_archive, tmp_path, clusters):
    """A worker whose harp station says another version (an older release installed there): refused by its
    version before any job is sent, no store created."""

    def older_release(other):
        init = other / "station" / "__init__.py"
        text = init.read_text()
        assert '        v = version("harp-station")\n' in text
        init.write_text(text.replace('        v = version("harp-station")\n', '        v = "0.0.9"\n'))

    cluster = _worker_running_a_copy(tmp_path, clusters, older_release)
    assert cluster.client().run(eval, "__import__('station').__version__").popitem()[1] == "0.0.9"
    _refused_before_any_job(
        factory_archive,
        tmp_path,
        cluster,
        rf"harp reprocess: Dask worker tcp://127\.0\.0\.1:\d+ runs harp station 0\.0\.9, this command "
        rf"{re.escape(__version__)}; run the same version on every worker \(its profiles would be another "
        r"version's\)\n",
    )


def test_a_session_directory_gone_before_its_job_ran_is_one_line_and_the_others_are_stored(
    factory_archive, tmp_path, clusters
):
    # was: "harp reprocess: DIR: not a session directory (no session.json)" of a session the command had planned
    cluster = clusters()
    cluster.add_workers(1)  # one worker, one thread: the jobs run in the order given, the last session's last
    sessions, store = _sessions(factory_archive, tmp_path, 5), tmp_path / "st.sqlite"
    gone = sessions[-1].resolve()
    with _started(_reprocess(sessions, cluster.address, store)) as proc:
        _wait_stored(proc, store, 2)
        gone.rename(tmp_path / "elsewhere")  # as a directory the workers' file system does not hold
        out, err = proc.communicate(timeout=300)
    assert proc.returncode == 2, (out, err)
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"harp reprocess: {gone}: no such directory where the job ran (")
    assert "every worker must see the session directories at the same path (a shared file system)" in err
    assert "4 session(s) re-processed, 1 failed" in out
    assert _rows(store) == (8, 8)


def test_a_port_where_something_else_listens_is_one_line_in_bounded_time_and_creates_no_store(
    factory_archive, tmp_path
):
    # was: a hang in Dask's Client, which waits for the scheduler's handshake forever (here: a socket that accepts
    # and says nothing, as an HTTP server does, e.g. the scheduler's dashboard at 8787 given for 8786)
    store = tmp_path / "st.sqlite"
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(8)
        address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
        t0 = time.monotonic()
        done = _run(_reprocess([factory_archive.session], address, store), timeout=120)
        took = time.monotonic() - t0
    assert done.returncode == 2 and done.stdout == "", done
    assert done.stderr == (
        f"harp reprocess: {address} is not a Dask scheduler (something listens there, but it sent no Dask handshake "
        "in 10 s); give the scheduler's port (8786 unless it was started with another; 8787 is its dashboard)\n"
    )
    assert took < 100
    assert not store.exists()


def test_a_scheduler_without_a_worker_is_one_line_after_the_bound_and_creates_no_store(
    factory_archive, tmp_path, clusters
):
    """A scheduler no worker has joined (none started yet, or all on a machine that is down): one line after
    :data:`station.reprocess.NO_WORKERS_S` (3 s here) saying to start some, before the store is opened."""
    cluster = clusters()  # no worker
    store = tmp_path / "st.sqlite"
    t0 = time.monotonic()
    done = _run(_reprocess([factory_archive.session], cluster.address, store, no_workers_s=3), timeout=120)
    took = time.monotonic() - t0
    assert done.returncode == 2 and done.stdout == "", done
    assert done.stderr == (
        f"harp reprocess: the Dask scheduler at {cluster.address} has no worker (none joined in 3 s); start some: "
        f"dask worker {cluster.address} --nthreads 1\n"
    )
    assert 3 <= took < 60
    assert not store.exists()


def test_every_worker_gone_mid_run_and_none_back_is_one_line_saying_what_was_stored(
    factory_archive, tmp_path, clusters
):
    """The only worker killed mid-run and not started again (no nanny; its machine down): its job waits for a
    worker; after :data:`station.reprocess.NO_WORKERS_S` (3 s here) without one, one line saying how many sessions
    were stored before and to start workers; what was stored is whole, and run again with a worker, the command
    stores the rest, each session once."""
    cluster = clusters()
    cluster.add_workers(1, nanny=False)
    sessions, store = _sessions(factory_archive, tmp_path, 4), tmp_path / "st.sqlite"
    with _started(_reprocess(sessions, cluster.address, store, no_workers_s=3)) as proc:
        _wait_stored(proc, store, 2)
        worker = cluster.busy_worker_pid()
        os.kill(worker, signal.SIGKILL)
        t0 = time.monotonic()
        out, err = proc.communicate(timeout=120)
        took = time.monotonic() - t0
    assert proc.returncode == 2, (out, err)
    assert err.count("\n") == 1 and "Traceback" not in err, err
    m = re.match(
        rf"harp reprocess: every Dask worker of {cluster.address} is gone, and none came back in 3 s: (\d+) "
        rf"session\(s\) re-processed and stored before it; start some \(dask worker {cluster.address} --nthreads 1\), "
        r"then run the same command for the others$",
        err.strip(),
    )
    assert m, err
    assert 3 <= took < 60
    stored = int(m.group(1))
    assert 1 <= stored < len(sessions) and _rows(store) == (2 * stored, 2 * stored)
    cluster.add_workers(1)
    again = _run(_reprocess(sessions, cluster.address, store))
    assert again.returncode == 0 and again.stderr == "", again.stderr
    assert _rows(store) == (8, 8)
