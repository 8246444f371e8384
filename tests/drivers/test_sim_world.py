"""The shared simulated world: the stage is the emulator's motion model, not a copy of it."""

from __future__ import annotations

import time

import pytest

from drivers.sim.world import SimWorld
from drivers.sim.zaber_emulator import ZaberEmulator

MSPD = 1536000 / 360.0


def test_a_world_without_emulator_is_set_by_hand():
    world = SimWorld(stage_deg=80.0, harp_offset_deg=120.0)
    assert not world.driven and world.stage_deg == 80.0 == world.stage_at(123.0)
    world.set_stage(-30.5)
    assert world.stage_deg == -30.5 and world.string_angle_deg() == pytest.approx(89.5)


def test_an_emulator_drives_the_stage_as_a_function_of_time():
    """The world's angle at any instant is the emulator's axis at that instant, during
    and after a move: there is no sampled copy that could lag behind."""
    world = SimWorld()
    emu = ZaberEmulator(world, speed_deg_s=90.0, accel_deg_s2=900.0, homed=True)
    assert world.driven and "Zaber emulator" in repr(world)
    t0 = time.monotonic()
    emu.handle_line(b"/1 1 move abs %d" % round(45 * MSPD), t0)
    move = emu.axis.move
    assert move is not None
    for frac in (0.0, 0.1, 0.5, 0.9):
        t = t0 + frac * move.duration
        assert world.stage_at(t) == pytest.approx(move.position(t) / MSPD, abs=1e-12)
    end = t0 + move.duration + 1e-9
    assert 0.0 < world.stage_at(t0 + 0.5 * move.duration) < 45.0
    assert world.stage_at(end) == world.stage_at(end + 100.0) == round(45 * MSPD) / MSPD
    # the emulator's replies are built from the same axis: idle at `end`, at the target
    assert not emu.axis.busy(end) and emu.position_steps(end) == round(45 * MSPD)


def test_one_emulator_per_world_and_no_hand_moves_while_driven():
    world = SimWorld()
    ZaberEmulator(world)
    with pytest.raises(ValueError, match="already driven by the Zaber emulator"):
        ZaberEmulator(world)
    with pytest.raises(ValueError, match="move it through the turntable"):
        world.set_stage(10.0)


def test_the_shift_is_a_function_of_time_and_moves_the_axis_along_its_direction():
    world = SimWorld(shift_direction_deg=90.0, shift_px_per_mm=4.0)
    assert world.shift_at() is None and world.shift_offset_px() == (0.0, 0.0)  # no linear axis
    world.drive_shift(lambda t: 0.5 * t, "test axis")  # 0.5 mm per second of monotonic time
    assert world.shift_at(10.0) == 5.0 and world.shift_offset_px(10.0) == pytest.approx((0.0, 20.0), abs=1e-12)
    with pytest.raises(ValueError, match="already driven"):
        world.drive_shift(lambda t: 0.0, "another")
    unscaled = SimWorld()
    unscaled.drive_shift(lambda t: 0.0 if t < 1 else 2.0, "test axis")
    assert unscaled.shift_offset_px(0.0) == (0.0, 0.0)  # at 0: the axis where the scene puts it
    with pytest.raises(ValueError, match="shifted 2 mm but the world has no shift_px_per_mm"):
        unscaled.shift_offset_px(5.0)
    with pytest.raises(ValueError, match="shift_px_per_mm must be a positive number"):
        SimWorld(shift_px_per_mm=0.0)
