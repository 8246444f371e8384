"""Discovery for ``harp devices``: each listing finds the fakes and its config snippet opens them.

The fakes are the real thing below the library: linuxpy over the faked ioctl layer
(tests/drivers/fake_v4l2.py), Aravis' Fake and GigE Vision fake cameras, and the emulators on
real pseudo-terminals opened by pyserial.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import drivers
from drivers.discovery import FoundDevice, discover, list_aravis_cameras, list_serial_ports, list_v4l2_devices
from drivers.errors import DeviceDisconnected
from drivers.sim.grbl_emulator import start_grbl_emulator
from drivers.sim.pty_server import PtyServer
from drivers.sim.zaber_emulator import start_zaber_emulator
from tests.drivers.aravis_fakes import gige_fake_camera
from tests.drivers.fake_v4l2 import FakeV4L2Camera
from tests.drivers.turntables import FAST


def test_v4l2_capture_nodes_are_listed_with_a_snippet_that_opens_them(tmp_path):
    os.mkfifo(tmp_path / "video1")  # a node that is no V4L2 device at all
    with FakeV4L2Camera(tmp_path / "video0", formats=("YUYV", "MJPG"), width=80, height=60):
        found = list_v4l2_devices(str(tmp_path / "video*"))
        assert [f.device for f in found] == [str(tmp_path / "video0"), str(tmp_path / "video1")]
        cam, other = found
        assert cam.kind == "camera" and cam.driver == "v4l2" and cam.problem is None
        assert cam.config == {
            "driver": "v4l2",
            "device": str(tmp_path / "video0"),
            "pixel_format": "YUYV",
            "width": 80,
            "height": 60,
        }
        assert cam.details["card"] == "Harp Test Cam" and cam.details["formats"] == "YUYV, MJPG"
        assert cam.details["focus control"] == "focus_absolute" and "Harp Test Cam" in cam.description
        assert other.problem is not None and "not a V4L2 device" in other.problem
        with drivers.open_camera(cam.config) as opened:
            assert opened.capture(timeout=1.0).image.shape == (60, 80)


def test_v4l2_formats_are_preferred_grey_first_and_an_empty_pattern_finds_nothing(tmp_path):
    with FakeV4L2Camera(tmp_path / "video0", formats=("MJPG", "Y16", "GREY"), with_focus=False):
        (cam,) = list_v4l2_devices(str(tmp_path / "video*"))
    assert cam.config["pixel_format"] == "GREY" and cam.details["focus control"] == "none"
    assert list_v4l2_devices(str(tmp_path / "nothing*")) == []


def test_a_colour_sensor_offering_only_raw_bayer_is_listed_with_a_snippet_that_opens_it(tmp_path):
    """A camera that offers only raw Bayer mosaics is usable (the colour pipeline reads them); the snippet names
    its format and opens it, the frame carrying its pattern."""
    with FakeV4L2Camera(tmp_path / "video0", formats=("BA81",)):
        (cam,) = list_v4l2_devices(str(tmp_path / "video*"))
        assert cam.problem is None and cam.config["pixel_format"] == "BA81"
        with drivers.open_camera(cam.config) as opened:
            assert opened.capture(timeout=1.0).extra["cfa"] == "BGGR"


@pytest.mark.parametrize(
    "offered, proposed",
    [
        (("pBAA", "BA10"), "BA10"),
        (("pRCC", "BA81"), "BA81"),
        (("Y10P", "GREY"), "GREY"),
        (("pgAA",), "pgAA"),
        (("Y12P", "YUYV", "Y12"), "Y12"),
    ],
)
def test_packed_raw_formats_come_after_the_unpacked_ones(tmp_path, offered, proposed):
    """``harp devices`` proposes the driver's PIXEL_FORMATS best first: an unpacked format (no unpacking) before
    a MIPI CSI-2 packed one; a camera offering only a packed one (a Raspberry Pi camera's ``pgAA``) is usable,
    its snippet opening it to 10-bit frames with their pattern."""
    with FakeV4L2Camera(tmp_path / "video0", formats=offered):
        (cam,) = list_v4l2_devices(str(tmp_path / "video*"))
        assert cam.problem is None and cam.config["pixel_format"] == proposed
        if proposed == "pgAA":
            with drivers.open_camera(cam.config) as opened:
                f = opened.capture(timeout=1.0)
            assert f.extra["cfa"] == "GRBG" and f.image.dtype == np.uint16 and 0 < f.image.max() < 1024


def test_aravis_fake_is_listed_only_when_asked_and_opens():
    assert all(f.details["protocol"] != "Fake" for f in list_aravis_cameras())
    (fake,) = [f for f in list_aravis_cameras(include_fake=True) if f.details["protocol"] == "Fake"]
    assert fake.config == {"driver": "aravis", "device": "Fake_1"} and fake.details["vendor"] == "Aravis"
    with drivers.open_camera({**fake.config, "roi": [0, 0, 32, 24]}) as cam:
        assert cam.capture(timeout=2.0).image.shape == (24, 32)


def test_aravis_gige_camera_on_loopback_is_found_by_its_id():
    with gige_fake_camera("HARPDISC"):
        (gv,) = [f for f in list_aravis_cameras() if f.details["serial"] == "HARPDISC"]
        assert gv.details["protocol"] == "GigEVision" and gv.details["address"] == "127.0.0.1"
        assert gv.config == {"driver": "aravis", "device": "Aravis-Fake-HARPDISC"}
        with drivers.open_camera({**gv.config, "roi": [0, 0, 32, 24]}) as cam:
            assert isinstance(cam.capture(timeout=5.0).image, np.ndarray)


@pytest.mark.parametrize("kind", ["zaber", "grbl"])
def test_probed_pty_is_identified_and_its_snippet_opens_the_turntable(kind):
    start = start_zaber_emulator if kind == "zaber" else start_grbl_emulator
    with start(**FAST) as handle:
        plain = [f for f in list_serial_ports(extra=[handle.port_path]) if f.device == handle.port_path]
        assert plain == [
            FoundDevice("serial port", None, handle.port_path, handle.port_path, {"port": handle.port_path})
        ]
        (probed,) = [f for f in list_serial_ports(extra=[handle.port_path], probe=True) if f.device == handle.port_path]
        assert probed.driver == kind and probed.problem is None
        assert probed.config == {"driver": kind, "port": handle.port_path}
        assert ("Zaber ASCII device 1" if kind == "zaber" else "GRBL controller (Alarm)") in probed.description
        with drivers.open_turntable({**probed.config, "poll_interval": 0.005}) as tt:
            tt.home()
            assert tt.move_to(30.0) == pytest.approx(30.0, abs=1e-3)


def test_a_zaber_at_another_address_gets_it_in_the_snippet():
    with start_zaber_emulator(address=3, **FAST) as handle:
        (probed,) = list_serial_ports(extra=[handle.port_path], probe=True)[-1:]
    assert probed.config == {"driver": "zaber", "port": handle.port_path, "device": 3}


class _Mute:
    """A serial device that answers nothing and records what it was sent."""

    def __init__(self):
        self.received = bytearray()

    def attach(self, server):
        """Nothing to keep: it never writes."""

    def on_bytes(self, data, now):
        self.received += data

    def tick(self, now):
        """Nothing happens by itself."""


def test_a_silent_port_gets_exactly_the_two_probes_and_a_vanished_one_its_error():
    mute = _Mute()
    with PtyServer(mute, name="mute") as server:
        (silent,) = [
            f for f in list_serial_ports(extra=[server.port], probe=True, timeout=0.2) if f.device == server.port
        ]
    assert bytes(mute.received) == b"/\n?"  # a Zaber status request, then GRBL's realtime status query
    assert silent.driver is None and silent.problem == "no Zaber ASCII or GRBL answer at 115200 baud"
    nowhere = "/dev/pts/does-not-exist"
    (gone,) = [f for f in list_serial_ports(extra=[nowhere], probe=True, timeout=0.05) if f.device == nowhere]
    assert gone.problem.startswith("serial port /dev/pts/does-not-exist: cannot open")


def test_a_port_a_turntable_holds_is_in_use_for_a_probe_and_for_another_driver():
    """A device port is this process's alone while a driver holds it (an flock, pyserial's exclusive): a
    probe or another driver is told it is in use and writes nothing. Before, ``harp devices --probe`` run
    beside a session wrote to its turntable and took replies the session waited for (a DeviceTimeout for
    the session's 'get pos'), and a second session on the same port could run at once."""
    with start_zaber_emulator(**FAST) as handle:
        port = handle.port_path
        with drivers.open_turntable({"driver": "zaber", "port": port, "poll_interval": 0.005}) as tt:
            tt.home()
            sent = list(handle.emulator.received)
            (busy,) = [f for f in list_serial_ports(extra=[port], probe=True, timeout=0.05) if f.device == port]
            with pytest.raises(DeviceDisconnected) as other:
                drivers.open_turntable({"driver": "zaber", "port": port}).open()
            assert handle.emulator.received == sent  # neither wrote a byte
            in_use = (
                f"cannot open {port}: it is in use by another program (another harp session or live view,"
                " harp devices --probe, a serial terminal); close that one first"
            )
            assert busy.driver is None and busy.problem == f"serial port {port}: {in_use}"
            assert str(other.value) == f"zaber {port} device 1 axis 1: {in_use}"
            assert tt.move_to(30.0) == pytest.approx(30.0, abs=1e-3)
        (free,) = [f for f in list_serial_ports(extra=[port], probe=True) if f.device == port]
        assert free.driver == "zaber"  # closed: the port is free again


def test_discover_runs_every_listing(tmp_path):
    found = discover(v4l2_pattern=str(tmp_path / "video*"))
    assert found.problems == []  # Aravis, linuxpy and pyserial are installed here
    assert all(isinstance(f, FoundDevice) for f in found.devices)
