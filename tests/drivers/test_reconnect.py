"""Every driver survives a disconnect: the error is one line naming the device, and once the
device is back ``close()`` + ``open()`` works again (what the live view relies on, issue 13 item 4).

A turntable is re-plugged as udev does it: the device reappears on a new tty and the stable
link (``/dev/serial/by-id/...``; here a symlink in a temporary directory) points to it. The
device keeps its state across the unplug, as a stage keeps its position.
"""

from __future__ import annotations

import contextlib
import os
import time

import pytest

import drivers
from drivers.errors import DeviceDisconnected, DriverError
from drivers.sim.grbl_emulator import start_grbl_emulator
from drivers.sim.pty_server import serve
from drivers.sim.zaber_emulator import start_zaber_emulator
from tests.drivers.aravis_fakes import gige_fake_camera, gige_port
from tests.drivers.fake_v4l2 import FakeV4L2Camera
from tests.drivers.turntables import FAST


def one_line_naming(exc: BaseException, name: str) -> str:
    text = str(exc)
    assert isinstance(exc, DriverError), f"{type(exc).__name__}: {text}"
    assert "\n" not in text and "\r" not in text, repr(text)
    assert text.startswith(f"{name}: "), f"{text!r} does not start with the device name {name!r}"
    return text


@pytest.mark.parametrize("kind", ["zaber", "grbl"])
def test_turntable_reopens_after_the_device_comes_back(kind, tmp_path):
    start = start_zaber_emulator if kind == "zaber" else start_grbl_emulator
    link = tmp_path / "usb-harp-turntable"
    first = start(**FAST)
    os.symlink(first.port_path, link)
    tt = drivers.open_turntable({"driver": kind, "port": str(link), "poll_interval": 0.005, "reply_timeout": 0.5})
    second = None
    try:
        tt.open()
        tt.home()
        assert tt.move_to(120.0) == pytest.approx(120.0, abs=1e-3)
        first.server.vanish()  # cable pulled
        with pytest.raises(DeviceDisconnected) as err:
            tt.position()
        assert "device gone" in one_line_naming(err.value, tt.name)
        tt.close()
        os.unlink(link)  # the tty is gone: its link with it
        with pytest.raises(DeviceDisconnected) as err:
            tt.open()
        assert "cannot open" in one_line_naming(err.value, tt.name)
        second = serve(first.emulator, name=kind)  # plugged back in: the same device on a new tty
        os.symlink(second.port_path, link)
        tt.open()
        assert tt.position() == pytest.approx(120.0, abs=1e-3)  # it kept its place
        assert tt.move_to(45.0) == pytest.approx(45.0, abs=1e-3)
    finally:
        tt.close()
        first.stop()
        if second is not None:
            second.stop()


def test_simulated_camera_reopens_after_a_disconnect():
    cam = drivers.open_camera({"driver": "sim", "width": 64, "height": 48, "serial": "SIM-R"})
    with cam:
        cam.capture()
        cam.fail_next(1, "disconnect")
        with pytest.raises(DeviceDisconnected) as err:
            cam.capture()
        one_line_naming(err.value, "sim camera SIM-R")
        with pytest.raises(DeviceDisconnected) as err:
            cam.capture()
        assert "not open" in one_line_naming(err.value, "sim camera SIM-R")
        cam.close()
        cam.open()
        assert cam.capture().counter == 0


def test_v4l2_camera_reopens_after_unplug_and_replug(tmp_path):
    node = tmp_path / "video0"
    with FakeV4L2Camera(node) as hw:
        cam = drivers.open_camera({"driver": "v4l2", "device": str(node), "exposure_us": 5000, "focus": 50})
        cam.open()
        try:
            cam.capture(timeout=1.0)
            hw.unplugged = True
            with pytest.raises(DeviceDisconnected) as err:
                cam.capture(timeout=1.0)
            one_line_naming(err.value, cam.name)
            cam.close()
            with pytest.raises(DeviceDisconnected) as err:
                cam.open()  # still unplugged
            one_line_naming(err.value, cam.name)
            assert not cam.is_open
            hw.replug()
            cam.open()
            frame = cam.capture(timeout=1.0)
            assert frame.counter == 0 and frame.exposure_us == 5000.0 and frame.focus == 50.0  # settings re-applied
        finally:
            cam.close()


def test_aravis_gige_camera_reopens_after_it_comes_back():
    """A GigE camera that stops answering is DeviceDisconnected (not "rejected"); close() returns at
    once instead of waiting out Aravis' network timeouts; the camera back on the network reopens."""
    cam = drivers.open_camera({"driver": "aravis", "device": "127.0.0.1", "roi": [0, 0, 32, 24]})
    with contextlib.ExitStack() as stack:
        stack.callback(cam.close)
        stack.enter_context(gige_port())  # no other test's fake on the port while this one is gone
        with gige_fake_camera("HARPRECO"):
            cam.open()
            cam.capture(timeout=2.0)
        with pytest.raises(DeviceDisconnected) as err:
            cam.capture(timeout=1.0)
        assert "device not answering" in one_line_naming(err.value, cam.name)
        t = time.monotonic()
        cam.close()
        assert time.monotonic() - t < 1.0
        with gige_fake_camera("HARPRECO"):
            cam.open()
            assert cam.capture(timeout=2.0).counter == 0 and cam.identity.serial == "HARPRECO"
            cam.close()
