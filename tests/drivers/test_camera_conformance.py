"""Every camera driver passes the shared Camera conformance check.

* ``aravis-fake``: Aravis' in-process Fake camera with the focus XML;
* ``aravis-gige``: Aravis' GigE Vision fake camera served on 127.0.0.1,
  reached through the real GVCP/GVSP network protocol;
* ``v4l2``: real linuxpy over a faked ioctl/mmap layer (tests/drivers/fake_v4l2.py);
* ``sim``: the simulated harp camera.
"""

from __future__ import annotations

import pytest

import drivers
from drivers.sim.world import SimWorld
from tests.drivers.aravis_fakes import FOCUS_CFG, gige_fake_camera
from tests.drivers.conformance_camera import run_camera_conformance
from tests.drivers.fake_v4l2 import FakeV4L2Camera


@pytest.fixture(scope="module")
def gige_fake():
    """Aravis' GigE Vision fake camera listening on 127.0.0.1 (GVCP port 3956)."""
    with gige_fake_camera("HARPCONF") as fake:
        yield fake


def test_aravis_fake_conformance():
    cam = drivers.open_camera({"driver": "aravis", "device": "Fake_1", "roi": [0, 0, 96, 64], **FOCUS_CFG})
    frames = run_camera_conformance(cam, exposure_us=20_000.0, gain_db=2.0, focus=417.0)
    assert cam.exposure_feature == "ExposureTime" and cam.gain_feature == "Gain"
    assert frames[0].camera.vendor == "Aravis"


def test_aravis_gige_conformance(gige_fake):
    cam = drivers.open_camera(
        {"driver": "aravis", "device": "127.0.0.1", "roi": [0, 0, 96, 64], "pixel_format": "Mono16", **FOCUS_CFG}
    )
    frames = run_camera_conformance(cam, exposure_us=20_000.0, gain_db=2.0, focus=417.0)
    assert frames[0].camera.serial == "HARPCONF"
    ids = [f.extra["frame_id"] for f in frames]
    assert ids == list(range(ids[0], ids[0] + len(ids))), f"software-triggered frames skipped: {ids}"


def test_v4l2_conformance(tmp_path):
    with FakeV4L2Camera(tmp_path / "video0"):
        cam = drivers.open_camera(
            {"driver": "v4l2", "device": str(tmp_path / "video0"), "pixel_format": "GREY", "width": 80, "height": 60}
        )
        run_camera_conformance(cam, exposure_us=20_000.0, gain_db=2.0, focus=100.0)


def test_sim_conformance():
    cam = drivers.open_camera({"driver": "sim", "width": 96, "height": 64, "seed": 7}, world=SimWorld())
    run_camera_conformance(cam, exposure_us=20_000.0, gain_db=2.0, focus=0.5)
