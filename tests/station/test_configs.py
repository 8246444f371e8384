"""Every configuration shipped in configs/ is usable (issue 9 item 6).

Each file is loaded and checked as ``harp config check`` does, then its devices are opened
through ``station.session.devices.open_station`` against the fake matching its drivers —
Aravis' Fake camera with our GenICam focus XML, the V4L2 ioctl fake under real linuxpy, the
Zaber and GRBL emulators on real pseudo-terminals, the simulated station of the demo — and a
session's first steps are performed on them: focus locked at every ``focus.settings`` value
(read back), the turntable moved to every orientation, one frame captured. Only what names
the hardware of this machine is replaced (device id, port, store paths); every other setting is
the file's own.
"""

from __future__ import annotations

import contextlib
import math
from pathlib import Path

import pytest
import yaml

from station.config import parse_config
from station.config.check import check_config
from station.session.devices import open_station

REPO = Path(__file__).resolve().parents[2]
CONFIGS = sorted((REPO / "configs").glob("*.yaml"))


def test_every_shipped_config_is_covered():
    assert {p.name for p in CONFIGS} == {
        "demo.yaml",
        "demo-zoom.yaml",
        "demo-intrinsics.yaml",
        "demo-operator-board.yaml",
        "live-demo.yaml",
        "aravis-zaber.yaml",
        "v4l2-grbl.yaml",
    }


@contextlib.contextmanager
def on_fakes(name: str, data: dict, tmp_path: Path):
    """``data`` (a config file's mapping) pointed at the fakes of its drivers; yields the mapping."""
    cam, tt = data["station"]["camera"], data["station"]["turntable"]
    with contextlib.ExitStack() as stack:
        if cam["driver"] == "aravis":
            from drivers.aravis_camera import FAKE_FOCUS_XML

            cam.update(device="Fake_1", fake_genicam_xml=str(FAKE_FOCUS_XML))
        elif cam["driver"] == "v4l2":
            from tests.drivers.fake_v4l2 import FakeV4L2Camera

            node = tmp_path / "video0"
            w, h = cam.get("width", 640), cam.get("height", 480)
            stack.enter_context(FakeV4L2Camera(node, width=w, height=h, max_size=(w, h)))
            cam["device"] = str(node)
        if tt["driver"] == "zaber" and tt["port"] != "emulator":
            from drivers.sim.zaber_emulator import start_zaber_emulator

            emu = start_zaber_emulator(
                address=tt.get("device_address", 1),
                microsteps_per_degree=tt["steps_per_degree"],
                speed_deg_s=3600.0,
                accel_deg_s2=72000.0,
            )
            stack.callback(emu.stop)
            tt["port"] = emu.port_path
        elif tt["driver"] == "grbl":
            from drivers.sim.grbl_emulator import start_grbl_emulator

            emu = start_grbl_emulator(axis=tt.get("axis", "X"), speed_deg_s=3600.0, accel_deg_s2=72000.0)
            stack.callback(emu.stop)
            tt["port"] = emu.port_path
        data["store"] = {"path": str(tmp_path / "p.sqlite"), "sessions_dir": str(tmp_path / "sessions")}
        yield data


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_shipped_config_opens_its_devices_and_locks_focus(path, tmp_path):
    data = yaml.safe_load(path.read_text())
    assert check_config(parse_config(path.read_text(), path)).ok  # as shipped
    with on_fakes(path.name, data, tmp_path) as data:
        config = parse_config(yaml.safe_dump(data), path)
        checked = check_config(config)
        assert checked.ok and checked.warnings == [], checked
        with open_station(config) as (camera, turntable):
            camera.set_exposure(config.capture.exposure_us)
            for focus in config.focus_settings:
                got = camera.lock_focus(focus)
                assert got is not None and math.isclose(got, focus, abs_tol=1e-6), (focus, got)
            turntable.home(timeout=30)
            for deg in config.capture.orientations_deg:
                assert abs(turntable.move_to(deg, timeout=30) - deg) < 0.05
            frame = camera.capture(timeout=5)
            assert frame.image.ndim == 2 and min(frame.image.shape) > 0


def test_a_config_that_can_lock_focus_on_nothing_is_refused_in_one_line(tmp_path, capsys):
    # issue 9: configs/aravis-zaber.yaml listed focus settings but no focus_feature, so a real
    # session failed at its first focus step, after opening the devices
    from station.cli import main

    src = REPO / "configs" / "aravis-zaber.yaml"
    data = yaml.safe_load(src.read_text())
    del data["station"]["camera"]["focus_feature"]
    del data["station"]["camera"]["autofocus_feature"]  # (which needs a focus feature)
    data["store"] = {"path": "p.sqlite", "sessions_dir": "sessions"}
    bad = tmp_path / "no-focus.yaml"
    bad.write_text(yaml.safe_dump(data))
    assert main(["config", "check", str(bad)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1
    assert err.startswith(f"harp config: {bad}: station.camera.focus_feature: expected the camera's focus feature")
    # and a session refuses it before anything is opened or created
    assert main(["session", "run", str(bad), "--quiet"]) == 2
    assert "station.camera.focus_feature" in capsys.readouterr().err
    assert not (tmp_path / "sessions").exists()
