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
import tempfile

from drivers.aravis_camera import FAKE_FOCUS_XML, aravis_module

FOCUS_CFG = {
    "fake_genicam_xml": str(FAKE_FOCUS_XML),
    "focus_feature": "FocusPosition",
    "autofocus_feature": "FocusAuto",
}


@contextlib.contextmanager
def gige_fake_camera(serial: str):
    """Serve Aravis' GigE Vision fake camera with serial number ``serial`` on 127.0.0.1."""
    Aravis = aravis_module()
    lock_path = os.path.join(tempfile.gettempdir(), "harp-station-gige-3956.lock")
    with open(lock_path, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        gv = Aravis.GvFakeCamera.new_full("127.0.0.1", serial, str(FAKE_FOCUS_XML))
        assert gv.is_running(), "GigE Vision fake camera did not start on 127.0.0.1"
        try:
            yield gv
        finally:
            del gv
            gc.collect()
