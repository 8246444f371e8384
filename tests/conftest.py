import os
from pathlib import Path

import pytest

from tests.grouping import pytest_collection_modifyitems  # noqa: F401  (a hook: pytest finds it by name)

REPO = Path(__file__).resolve().parents[1]
REAL_HARP = Path(os.environ.get("HARP_REAL_DATA", REPO.parent / "shared" / "data" / "real-harp"))


@pytest.fixture(scope="session")
def real_harp_dir() -> Path:
    if not REAL_HARP.is_dir():
        pytest.fail(f"real harp photos not found at {REAL_HARP} (set HARP_REAL_DATA)")
    return REAL_HARP


@pytest.fixture(scope="session")
def postgres():
    """A real PostgreSQL server (Debian's ``postgresql``) for this test session: see tests/pg_server.py."""
    from tests.pg_server import postgres_server

    with postgres_server() as server:
        yield server


@pytest.fixture(scope="session")
def browser():
    """Headless Debian Chromium under Playwright, shared by the session's browser tests (tests/browser.py)."""
    from playwright.sync_api import sync_playwright

    from tests.browser import CHROMIUM_FLAGS, chromium_path

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(chromium_path()), headless=True, args=CHROMIUM_FLAGS)
        try:
            yield b
        finally:
            b.close()


@pytest.fixture
def page(browser):
    """A fresh browser page (own context: no cookies or storage shared between tests)."""
    ctx = browser.new_context(viewport={"width": 1280, "height": 900})
    pg = ctx.new_page()
    try:
        yield pg
    finally:
        ctx.close()


def pytest_configure(config):
    """The per-user directories the commands default to (the profile store, lensfun's user
    databases) are a temporary directory for the whole run, never the user's own; the variables a
    station sets for its commands are unset; Ctrl-C has its default disposition; SIGTERM interrupts the run
    as Ctrl-C does (:func:`_sigterm_is_an_interrupt`)."""
    import signal
    import tempfile

    # Started with Ctrl-C ignored or blocked (under nohup, or as a background job of a script), this
    # process would hand that on to every command a test starts, and the tests that press Ctrl-C (a real
    # SIGINT to the command's process group) would see it ignored: give the run the default disposition.
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    _sigterm_is_an_interrupt()

    # One BLAS thread per process, as the station's commands and workers run (station.cli, station.reprocess):
    # two test workers on two cores would otherwise each start a BLAS thread per core, and OpenBLAS's threads
    # spin waiting for work, so the small solves of the fits ran several times slower on a busy machine.
    import threadpoolctl

    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")  # the commands and pools the tests start
    config._harp_blas_limits = threadpoolctl.threadpool_limits(1)  # this process (numpy may be loaded already)

    data_home = tempfile.mkdtemp(prefix="harp-tests-xdg-")
    config._harp_data_home = data_home
    os.environ["XDG_DATA_HOME"] = data_home
    for name in ("HARP_STORE", "HARP_CONFIG", "HARP_LENSFUN_DIRS"):
        os.environ.pop(name, None)


def _sigterm_is_an_interrupt() -> None:
    """SIGTERM (a CI job cancelled, ``timeout``, ``kill``) ends this run as Ctrl-C does — a KeyboardInterrupt,
    so that pytest's finalizers run — in the main process and in each xdist worker (this hook runs in both):
    by default it would end the process at once, and the servers a fixture started outside the run's process
    group (PostgreSQL, daemonised by ``pg_ctl``: tests/pg_server.py) would stay. A process forked from this one
    (a pool worker) takes SIGTERM as before: it dies of it. Left alone when something set SIGTERM's disposition."""
    import contextlib
    import signal

    if signal.getsignal(signal.SIGTERM) != signal.SIG_DFL:
        return
    owner = os.getpid()

    def interrupt(signum, _frame):
        if os.getpid() != owner:  # a forked child: SIGTERM's default, death by the signal
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        raise KeyboardInterrupt(f"signal {signum} (SIGTERM)")

    def default_in_child():
        if signal.getsignal(signal.SIGTERM) is interrupt:
            with contextlib.suppress(ValueError):  # not the main thread: interrupt() hands it on
                signal.signal(signal.SIGTERM, signal.SIG_DFL)

    signal.signal(signal.SIGTERM, interrupt)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM})
    os.register_at_fork(after_in_child=default_in_child)


def pytest_unconfigure(config):
    import shutil

    data_home = getattr(config, "_harp_data_home", None)
    if data_home:
        shutil.rmtree(data_home, ignore_errors=True)
