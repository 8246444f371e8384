"""The simulated station's shift axis (issue 19): a turntable with ``shift_axis`` gets an emulator with that
axis, over the real pty, and moving it moves the turntable axis in the simulated world; a shift axis the
configuration or the device cannot have is a one-line configuration error naming the field. The simulated lens
is the unit of its serial with the residual field ``simulation.lens_field_px`` asks for."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from drivers.sim.lens import lens_field, lens_for_focus, lens_unit, with_field
from station.cli import main
from station.config import ConfigError, load_config
from station.session.devices import open_station
from station.session.simulated import simulated_devices

DEMO = Path(__file__).resolve().parents[3] / "configs" / "demo.yaml"


def shift_config(tmp_path: Path, turntable: dict, emulator: dict | None = None, direction: float = 30.0):
    return load_config(shift_config_file(tmp_path, turntable, emulator, direction))


GRBL = {"driver": "grbl", "steps_per_degree": None}


@pytest.mark.parametrize(
    "turntable", [{"shift_axis": 3}, {**GRBL, "shift_axis": "Z", "tilt_axis": "Y"}], ids=["zaber", "grbl"]
)
def test_the_shift_axis_moves_the_turntable_in_the_simulated_world(tmp_path, turntable):
    cfg = shift_config(tmp_path, turntable)
    with simulated_devices(cfg) as sim:
        world, tt = sim.world, sim.turntable
        px_per_mm = sim.camera.scene.spacing_px / cfg.station.harp.string_spacing_mm  # 60 px / 10 mm
        assert world.shift_px_per_mm == px_per_mm == 6.0 and world.shift_direction_deg == 30.0
        assert (world.tilt_at() is None) == (turntable.get("tilt_axis") is None)  # no tilt axis: the wedge's
        with tt:
            tt.home()  # GRBL starts locked until homed
            assert world.shift_at() == 0.0 and world.shift_offset_px() == (0.0, 0.0)
            got = tt.shift.move_to(4.0)
            assert got == pytest.approx(4.0, abs=1e-4) and world.shift_at() == pytest.approx(got, abs=1e-9)
            dx, dy = world.shift_offset_px()
            assert (dx, dy) == pytest.approx((got * 6.0 * math.cos(math.pi / 6), got * 6.0 * math.sin(math.pi / 6)))
            assert tt.move_to(45.0) == pytest.approx(45.0, abs=1e-3) and world.shift_at() == pytest.approx(got)
            with sim.camera as cam:  # the frame is taken with the turntable where the shift axis put it
                sim_extra = cam.capture().extra["sim"]
            assert sim_extra["shift_mm"] == pytest.approx(got, abs=1e-9) and sim_extra["axis_offset_px"] == [dx, dy]


def shift_config_file(tmp_path: Path, turntable: dict, emulator: dict | None = None, direction: float = 30.0):
    d = yaml.safe_load(DEMO.read_text())
    d["station"]["turntable"].update(turntable)
    d["station"]["camera"].update(width=480, height=360)  # small frames: fast
    d["simulation"]["shift_direction_deg"] = direction
    d["simulation"]["emulator"] = {"speed_deg_s": 3600.0, "accel_deg_s2": 72000.0, **(emulator or {})}
    p = tmp_path / "station.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


@pytest.mark.parametrize(
    "turntable, expected",
    [
        ({"shift_axis": 1}, "station.turntable.shift_axis: expected settings the zaber turntable accepts: "
                            "shift_axis must be another axis than axis 1, got 1"),
        ({"shift_axis": 2, "tilt_axis": 2}, "station.turntable.shift_axis: expected settings the zaber turntable "
                                            "accepts: shift_axis must be another axis than axis 2, got 2"),
        ({**GRBL, "shift_axis": "x"}, "station.turntable.shift_axis: expected settings the grbl turntable accepts: "
                                      "grbl turntable: shift_axis must be another axis than X, got 'x'"),
        ({**GRBL, "shift_axis": "Z", "shift_units_per_mm": 2.0}, "station.turntable.shift_units_per_mm: the GRBL "
                                                                 "emulator's shift axis counts mm"),
    ],
)  # fmt: skip
def test_a_shift_axis_on_the_turntables_own_axis_is_a_config_error(tmp_path, turntable, expected):
    p = shift_config_file(tmp_path, turntable)
    with pytest.raises(ConfigError) as info:
        with simulated_devices(load_config(p)):
            pass
    text = str(info.value)
    assert text.startswith(f"{p}: {expected}") and "\n" not in text


def test_a_misplaced_shift_axis_is_one_line_from_the_command_line(tmp_path, capsys):
    p = shift_config_file(tmp_path, {"shift_axis": 1})
    assert main(["config", "check", str(p)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        f"harp config: {p}: station.turntable.shift_axis: expected settings the zaber turntable accepts: "
        "shift_axis must be another axis than axis 1, got 1"
    )


def test_a_shift_axis_the_device_does_not_have_is_a_config_error(tmp_path):
    """A two-axis device (``simulation.emulator.axes: 2``) has no axis 3: opening the station names the
    shift axis, not the port."""
    cfg = shift_config(tmp_path, {"shift_axis": 3}, {"axes": 2})
    with pytest.raises(ConfigError) as info, open_station(cfg):
        pass
    text = str(info.value)
    assert text.startswith(f"{cfg.path}: station.turntable.shift_axis: cannot open the turntable at 'emulator': ")
    assert "shift axis 3: 'get pos' rejected: BADAXIS" in text and "\n" not in text


def test_the_simulated_lens_is_the_serials_unit_with_the_configured_field(tmp_path, capsys):
    d = yaml.safe_load(DEMO.read_text())
    d["station"]["camera"].update(width=480, height=360)
    d["simulation"].update(lens_spread=1.0, lens_field_px=0.02)
    d["lens"]["serial"] = "FIELD-7"
    p = tmp_path / "station.yaml"
    p.write_text(yaml.safe_dump(d))
    with simulated_devices(load_config(p)) as sim:
        assert sim.world.lens_field == lens_field("FIELD-7", 0.02) and sim.world.lens_unit == lens_unit("FIELD-7", 1.0)
        pts = np.stack(np.meshgrid(np.arange(0.0, 480, 40), np.arange(0.0, 360, 40)), -1).reshape(-1, 2)
        truth = with_field(
            lens_for_focus(0.5, 480, 360, lens_unit("FIELD-7", 1.0)), lens_field("FIELD-7", 0.02), 480, 360
        )
        np.testing.assert_array_equal(sim.camera.lens_at(0.5).undistort_points(pts), truth.undistort_points(pts))
    d["simulation"]["lens_field_px"] = 2
    p.write_text(yaml.safe_dump(d))
    assert main(["config", "check", str(p)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{p}: simulation.lens_field_px: expected a number in [0, 1] px, got 2" in err, err
