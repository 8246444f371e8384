"""VISCA lens controller (issue 23: a zoom lens driven over serial): byte-exact exchanges, and the real driver
over a real pty against the emulator, which drives the simulated zoom lens."""

import pytest

from drivers.errors import DeviceRejected, DeviceTimeout, OutOfRange, ProtocolError
from drivers.sim.camera import SimulatedCamera
from drivers.sim.lens import ZOOM_FOCAL_RANGE_MM
from drivers.sim.visca_emulator import focal_of, position_of, start_visca_emulator
from drivers.sim.world import SimWorld
from drivers.testing import ScriptedDevice
from drivers.visca import ViscaLens, from_nibbles, nibbles

OPEN = [
    (b"\x88\x30\x01\xff", b"\x88\x30\x02\xff"),
    (b"\x88\x01\x00\x01\xff", b"\x88\x01\x00\x01\xff"),
]


def lens(port, **kw):
    kw.setdefault("reply_timeout", 0.5)
    kw.setdefault("move_timeout", 2.0)
    return ViscaLens(port, **kw)


def test_nibbles():
    assert nibbles(0x4000) == b"\x04\x00\x00\x00" and nibbles(0x1A2F) == b"\x01\x0a\x02\x0f"
    assert from_nibbles(b"\x01\x0a\x02\x0f") == 0x1A2F
    with pytest.raises(ValueError):
        from_nibbles(b"\x10\x00\x00\x00")


def test_zoom_and_focus_bytes():
    script = [
        *OPEN,
        # ACK (taken into socket 1), then the completion once the zoom is there
        (b"\x81\x01\x04\x47\x02\x00\x00\x00\xff", b"\x90\x41\xff\x90\x51\xff"),
        (b"\x81\x09\x04\x47\xff", b"\x90\x50\x02\x00\x00\x00\xff"),
        (b"\x81\x01\x04\x38\x03\xff", b"\x90\x41\xff\x90\x51\xff"),
        (b"\x81\x01\x04\x48\x01\x02\x03\x04\xff", b"\x90\x41\xff\x90\x51\xff"),
        (b"\x81\x09\x04\x48\xff", b"\x90\x50\x01\x02\x03\x04\xff"),
        (b"\x81\x01\x04\x47\x03\x00\x00\x00\xff", b"\x90\x61\x41\xff"),
        (b"\x81\x09\x04\x47\xff", b"\x90\x50\x00\x00\x00\x0d\xff"),  # a 0x0D byte is data, not a line end
    ]
    with ScriptedDevice(script, name="visca") as dev:
        with lens(dev.port) as z:
            assert z.zoom_range().maximum == 0x4000
            assert z.set_zoom(0x2000) == 0x2000
            assert z.lock_focus(0x1234) == 0x1234
            with pytest.raises(DeviceRejected, match="zoom to 0x3000 refused: command not executable"):
                z.set_zoom(0x3000)
            with pytest.raises(OutOfRange):
                z.set_zoom(0x4001)  # refused before anything is sent
            assert z.get_zoom() == 0x0D


def test_a_silent_or_foreign_controller():
    with ScriptedDevice([(b"\x88\x30\x01\xff", b"")], name="visca") as dev:
        with pytest.raises(DeviceTimeout):
            lens(dev.port, reply_timeout=0.2).open()
    with ScriptedDevice([*OPEN, (b"\x81\x09\x04\x47\xff", b"\xa0\x50\x00\x00\x00\x00\xff")], name="visca") as dev:
        with lens(dev.port) as z, pytest.raises(ProtocolError, match="not a VISCA reply"):
            z.get_zoom()


def test_the_emulator_zooms_the_simulated_lens():
    world = SimWorld()
    cam = SimulatedCamera.from_config({"driver": "sim", "width": 160, "height": 120}, world=world)
    with start_visca_emulator(world=world, zoom_speed=65536.0) as h, lens(h.port_path) as z:
        assert world.zoom == ZOOM_FOCAL_RANGE_MM[0]  # the wide end at power-up
        p = position_of(24.0)
        assert z.set_zoom(p) == p and world.zoom == pytest.approx(24.0, abs=1e-3) == focal_of(p)
        cam.open()
        assert cam.get_zoom() == world.zoom  # the camera renders the zoom lens at that focal length
        assert z.set_zoom(0) == 0 and world.zoom == ZOOM_FOCAL_RANGE_MM[0]
        z.transport.write(b"\x81\x01\x04\x99\xff")  # not a command it knows: a syntax error
        with pytest.raises(DeviceRejected, match="syntax error"):
            z._check(z._read_packet(0.5, "x"), "x")
        cam.close()


def test_a_camera_whose_zoom_the_controller_drives():
    """``zoom_controller`` in a camera's configuration: the zoom (set at open, before the camera opens and
    locks its focus) and the Zoomable calls go to the controller; the rest is the camera's."""
    from drivers import open_camera

    world = SimWorld()
    with start_visca_emulator(world=world, zoom_speed=65536.0) as h:
        cam = open_camera(
            {"driver": "sim", "width": 160, "height": 120, "focus": 0.5,
             "zoom_controller": {"port": h.port_path, "reply_timeout": 0.5, "zoom": position_of(30.0)}},
            world=world,
        )  # fmt: skip
        with cam:
            assert world.zoom == pytest.approx(30.0, abs=1e-3) and world.focus == 0.5
            assert cam.get_zoom() == position_of(30.0) and cam.zoom_range().maximum == 0x4000
            assert cam.capture(5.0).image.shape == (120, 160)  # the camera's own
            assert cam.set_zoom(0) == 0 and world.zoom == ZOOM_FOCAL_RANGE_MM[0]
    with pytest.raises(ValueError, match="unknown config key 'speed'"):
        open_camera({"driver": "sim", "zoom_controller": {"port": "/dev/null", "speed": 1}})


def test_a_zoom_sessions_part_sets_the_controllers_position(tmp_path):
    """A zoom session's part (:func:`station.zoom_session.part_config_text`) puts its zoom position in the lens
    controller's section when the camera has one (the camera's own zoom otherwise), and the simulated
    station opens with the controller's emulator at that position (the zoom lens at that focal length)."""
    from pathlib import Path

    import yaml

    from station.config import load_config
    from station.session.simulated import simulated_devices
    from station.zoom_session import part_config_text, parts_of

    d = yaml.safe_load((Path(__file__).resolve().parents[2] / "configs" / "demo-zoom.yaml").read_text())
    d["station"]["camera"]["zoom_controller"] = {"port": "emulator"}
    d["zoom"] = {"settings": [12, 24, 36], "positions": [position_of(f) for f in (12, 24, 36)]}
    (tmp_path / "z.yaml").write_text(yaml.safe_dump(d))
    cfg = load_config(tmp_path / "z.yaml")
    part = parts_of(cfg)[1]
    text = part_config_text(cfg, part)
    cam = yaml.safe_load(text)["station"]["camera"]
    assert cam["zoom_controller"] == {"port": "emulator", "zoom": 8192.0} and "zoom" not in cam
    (tmp_path / "p.yaml").write_text(text)
    with simulated_devices(load_config(tmp_path / "p.yaml")) as sim:
        with sim.camera:
            assert sim.world.zoom == pytest.approx(24.0, abs=1e-3) and sim.camera.get_zoom() == 8192
