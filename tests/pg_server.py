"""A real PostgreSQL server for the tests: ``initdb`` + ``pg_ctl`` in a temporary directory.

Debian's ``postgresql`` package (installed by ``scripts/setup.sh``) provides the
server binaries under ``/usr/lib/postgresql/<version>/bin``. The server refuses to
run as root, so when the tests run as root the data directory is owned by, and
every server command runs as, the ``postgres`` system user (``runuser``); as any
other user it runs as that user. It listens on 127.0.0.1 on a free port, with
``trust`` authentication for the role ``harp`` and a database ``harp``, and
``fsync=off`` (a test server: speed over durability). The server is stopped and
its directory removed when the :class:`PostgresServer` context ends.

``pg_ctl`` daemonises the server out of the test run's process group, so nothing that ends the run's
processes ends it: every server this process started and has not stopped is also stopped (``immediate``) and
its directory removed by an ``atexit`` hook, :func:`stop_all` — reached when the run ends by an exception
(a SIGTERM turned into KeyboardInterrupt by tests/conftest.py) without its finalizers having stopped it.

No mock and no skip: when the binaries are missing, :func:`postgres_bin_dir`
raises with the command that installs them.
"""

from __future__ import annotations

import atexit
import contextlib
import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path


def postgres_bin_dir() -> Path:
    """The newest installed PostgreSQL server binary directory."""
    env = os.environ.get("HARP_PG_BINDIR")
    candidates = [env] if env else sorted(glob.glob("/usr/lib/postgresql/*/bin"), key=_version_key)
    for d in reversed(candidates):
        if d and (Path(d) / "initdb").is_file() and (Path(d) / "pg_ctl").is_file():
            return Path(d)
    raise RuntimeError(
        "PostgreSQL server binaries not found (no /usr/lib/postgresql/*/bin/initdb): "
        "run scripts/setup.sh, or apt-get install postgresql, or set HARP_PG_BINDIR"
    )


def _version_key(path: str) -> tuple[int, ...]:
    part = Path(path).parent.name
    return tuple(int(p) for p in part.split(".") if p.isdigit())


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class PostgresServer:
    """One running server; ``url`` is the SQLAlchemy/psycopg URL of its ``harp`` database."""

    root: Path
    port: int
    bindir: Path
    run_as: str | None

    @property
    def data_dir(self) -> Path:
        return self.root / "data"

    @property
    def url(self) -> str:
        return f"postgresql://harp@127.0.0.1:{self.port}/harp"

    def _cmd(self, *argv: str, check: bool = True) -> subprocess.CompletedProcess[str]:
        cmd = list(argv)
        if self.run_as:
            cmd = ["runuser", "-u", self.run_as, "--", *cmd]
        return subprocess.run(cmd, check=check, capture_output=True, text=True, timeout=120)

    def create_database(self, name: str) -> str:
        """Create another empty database on this server; return its URL."""
        self._psql(f'CREATE DATABASE "{name}"')
        return f"postgresql://harp@127.0.0.1:{self.port}/{name}"

    def _psql(self, sql: str) -> None:
        psql = shutil.which("psql") or str(self.bindir / "psql")
        self._cmd(psql, "-h", "127.0.0.1", "-p", str(self.port), "-U", "harp", "-d", "postgres", "-c", sql)

    def start(self) -> None:
        """Start the server (again, after :meth:`stop`: the same data, port and URL); waits until it takes connections."""
        opts = f"-p {self.port} -k {self.root} -c listen_addresses=127.0.0.1 -c fsync=off -c full_page_writes=off"
        try:
            self._cmd(
                str(self.bindir / "pg_ctl"),
                "-D",
                str(self.data_dir),
                "-o",
                opts,
                "-l",
                str(self.root / "server.log"),
                "-w",
                "-t",
                "60",
                "start",
            )
        except subprocess.CalledProcessError as exc:
            log = (self.root / "server.log").read_text(errors="replace") if (self.root / "server.log").exists() else ""
            raise RuntimeError(f"PostgreSQL did not start: {exc.stderr.strip()} {log[-2000:]}") from None

    def running(self) -> bool:
        return self._cmd(str(self.bindir / "pg_ctl"), "-D", str(self.data_dir), "status", check=False).returncode == 0

    def stop(self, mode: str = "immediate") -> None:
        """Stop the server: ``immediate`` (as a crash or a power cut: every connection dropped at once, recovery
        on the next start) or ``fast`` (an administrator's restart: each backend ends its connection with
        ``terminating connection due to administrator command``)."""
        self._cmd(str(self.bindir / "pg_ctl"), "-D", str(self.data_dir), "-m", mode, "-w", "stop", check=False)

    @contextlib.contextmanager
    def frozen(self) -> Iterator[None]:
        """The server stopped answering without closing a connection (SIGSTOP to the postmaster and every
        backend: as a hung machine, or one the network no longer reaches); it answers again when the block
        ends, on every exit path."""
        import signal

        postmaster = int((self.data_dir / "postmaster.pid").read_text().split()[0])
        pids = [postmaster, *_children(postmaster)]
        try:
            for pid in pids:
                os.kill(pid, signal.SIGSTOP)
            yield
        finally:
            for pid in pids:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGCONT)


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    found = []
    for stat in glob.glob("/proc/[0-9]*/stat"):
        with contextlib.suppress(OSError):
            fields = Path(stat).read_text().rsplit(")", 1)[1].split()
            if int(fields[1]) == pid:
                found.append(int(Path(stat).parent.name))
    return found


_started: dict[Path, PostgresServer] = {}
"""The servers this process started and has not yet stopped and removed (by their directory)."""
_started_lock = threading.Lock()
_owner = os.getpid()


def _discard(server: PostgresServer) -> None:
    """Stop ``server`` and remove its directory (whatever state it is in), and forget it; interrupted (a
    second SIGTERM), the server is still known to :func:`stop_all` and its directory still there."""
    if server.data_dir.exists():  # running, starting, or left by a crash: pg_ctl stop says which
        server.stop()
    shutil.rmtree(server.root, ignore_errors=True)
    with _started_lock:
        _started.pop(server.root, None)


def stop_all() -> None:
    """Stop every server this process started and has not stopped, and remove its directory (``atexit``:
    a run that ended without its finalizers). Not in a forked child: the servers are its parent's."""
    if os.getpid() != _owner:
        return
    with _started_lock:
        left = list(_started.values())
    for server in left:
        with contextlib.suppress(Exception):
            _discard(server)


atexit.register(stop_all)


@contextlib.contextmanager
def postgres_server() -> Iterator[PostgresServer]:
    """Start a throw-away PostgreSQL server; stop and delete it afterwards (and at exit: :func:`stop_all`)."""
    bindir = postgres_bin_dir()
    run_as = "postgres" if os.geteuid() == 0 else None
    root = Path(tempfile.mkdtemp(prefix="harp-pg-"))
    server = PostgresServer(root=root, port=free_port(), bindir=bindir, run_as=run_as)
    with _started_lock:
        _started[root] = server
    try:
        if run_as:
            pw = pwd.getpwnam(run_as)
            os.chown(root, pw.pw_uid, pw.pw_gid)
        server._cmd(
            str(bindir / "initdb"), "-D", str(server.data_dir), "-U", "harp", "--auth=trust", "-E", "UTF8", "--no-sync"
        )
        server.start()
        server._psql("CREATE DATABASE harp")
        yield server
    finally:
        _discard(server)
