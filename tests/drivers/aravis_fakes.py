"""Aravis fake cameras shared by the Aravis driver tests and the conformance tests.

``FOCUS_CFG``: the driver settings that select our GenICam XML
(``drivers/data/fake-focus.xml``: SFNC ExposureTime / Gain plus focus
features) and its focus features. :func:`gige_fake_camera`: Aravis' GigE
Vision fake camera served on 127.0.0.1 (GVCP port 3956) with that XML, for a
``with`` block or a fixture. Only one process on a machine can serve port 3956,
so the fake holds an exclusive lock file while it runs: two test suites run at
once (two checkouts, or CI beside a developer) take turns instead of colliding.
"""

from __future__ import annotations

import contextlib
import fcntl
import gc
import os
import socket
import tempfile
import time

from drivers.aravis_camera import FAKE_FOCUS_XML, aravis_module

FOCUS_CFG = {
    "fake_genicam_xml": str(FAKE_FOCUS_XML),
    "focus_feature": "FocusPosition",
    "autofocus_feature": "FocusAuto",
}


_HELD = {"depth": 0}


@contextlib.contextmanager
def gige_port():
    """Hold 127.0.0.1's GVCP port for this process (an exclusive lock file; re-entrant): no fake of another test
    process starts meanwhile. :func:`gige_fake_camera` holds it while its fake serves; a test that checks what
    the driver meets once its fake is gone holds it across both."""
    if _HELD["depth"]:
        _HELD["depth"] += 1
        try:
            yield
        finally:
            _HELD["depth"] -= 1
        return
    lock_path = os.path.join(tempfile.gettempdir(), "harp-station-gige-3956.lock")
    with open(lock_path, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        _HELD["depth"] = 1
        try:
            yield
        finally:
            _HELD["depth"] = 0


@contextlib.contextmanager
def gige_fake_camera(serial: str):
    """Serve Aravis' GigE Vision fake camera with serial number ``serial`` on 127.0.0.1."""
    Aravis = aravis_module()
    with gige_port():
        _wait_port_free()  # the last fake's socket gone: GVCP packets reach this one only
        gv = Aravis.GvFakeCamera.new_full("127.0.0.1", serial, str(FAKE_FOCUS_XML))
        assert gv.is_running(), "GigE Vision fake camera did not start on 127.0.0.1"
        try:
            yield gv
        finally:
            del gv
            gc.collect()  # a fixture's value lives on in pytest's cache until its teardown ends: the next fake waits


GVCP_PORT = 3956


def _wait_port_free(timeout: float = 10.0) -> None:
    """Wait until no socket is bound to 127.0.0.1's GVCP port: the last fake, in this process or another, may hold it
    a moment after its lock was released (a fixture's value is freed only after its teardown). While it does, a new
    fake binds beside it and the driver's packets can reach the old one, which no longer answers ("Can't connect to
    device at address '127.0.0.1'": a failure seen once in CI)."""
    deadline = time.monotonic() + timeout
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(("127.0.0.1", GVCP_PORT))
                return
            except OSError:
                if time.monotonic() > deadline:
                    raise AssertionError(f"UDP 127.0.0.1:{GVCP_PORT} still bound after {timeout:g} s") from None
        time.sleep(0.05)
