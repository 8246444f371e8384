"""Every turntable driver passes the shared Turntable conformance check and
handles the same device faults (no reply, garbage, a vanished device) the same
way, talking through a real pty to its device emulator."""

import re
import time

import pytest

from drivers.errors import DeviceDisconnected, DeviceTimeout, ProtocolError
from drivers.grbl import GrblTurntable
from drivers.sim.grbl_emulator import start_grbl_emulator
from drivers.sim.world import SimWorld
from drivers.sim.zaber_emulator import start_zaber_emulator
from drivers.zaber import ZaberTurntable
from tests.drivers.conformance_turntable import DEFAULT_ANGLES, run_turntable_conformance
from tests.drivers.turntables import FAST, TURNTABLES, make_driver


@pytest.mark.parametrize("kind", sorted(TURNTABLES))
def test_turntable_conformance(kind):
    start, cls = TURNTABLES[kind]
    world = SimWorld()
    with start(world=world, **FAST) as handle:
        tt = make_driver(cls, handle.port_path)
        readings = run_turntable_conformance(tt)
    assert [t for t, _ in readings] == list(DEFAULT_ANGLES)
    assert world.stage_deg == pytest.approx(DEFAULT_ANGLES[-1], abs=1e-3)


SHIFT_AXES = {"zaber": ({"axes": 3}, {"shift_axis": 3}), "grbl": ({"shift_axis": "Z"}, {"shift_axis": "Z"})}
"""Emulator and driver options of a shift axis (issue 19): Zaber axis 3, GRBL Z."""


@pytest.mark.parametrize("kind", sorted(TURNTABLES))
def test_the_shift_axis_passes_the_same_check_in_millimetres(kind):
    """``turntable.shift`` keeps the Turntable protocol's promises too (positions in mm), on the connection
    its turntable opened, and moves only the world's shift."""
    start, cls = TURNTABLES[kind]
    emulator, options = SHIFT_AXES[kind]
    world = SimWorld()
    positions = (0.0, 2.5, 7.0, 1.25)
    with start(world=world, **emulator, **FAST) as handle, make_driver(cls, handle.port_path, **options) as tt:
        tt.home()  # GRBL: unlocked; $H homes every axis
        assert tt.shift.travel_range().unit == "mm"
        readings = run_turntable_conformance(tt.shift, angles=positions)
        assert tt.position() == 0.0
    assert [t for t, _ in readings] == list(positions)
    assert world.shift_at() == pytest.approx(positions[-1], abs=1e-3) and world.stage_deg == 0.0


class _ReturnsBeforeArrival(ZaberTurntable):
    """Broken on purpose: move_to does not wait for the stage."""

    def move_to(self, degrees, timeout=None):
        self.start_move(degrees)
        return float(degrees)


class _IgnoresLimits(GrblTurntable):
    """Broken on purpose: limits advertised but not enforced."""

    @property
    def limits(self):
        return (0.0, 315.0)


@pytest.mark.parametrize(
    "start, broken, speed, message",
    [
        (start_zaber_emulator, _ReturnsBeforeArrival, 360.0, "busy after move_to"),
        (start_grbl_emulator, _IgnoresLimits, 3600.0, "differs from limits"),
    ],
)
def test_conformance_check_catches_broken_drivers(start, broken, speed, message):
    with start(speed_deg_s=speed, accel_deg_s2=10 * speed) as handle:
        tt = make_driver(broken, handle.port_path)
        with pytest.raises(AssertionError, match=message):
            run_turntable_conformance(tt)


# -- behaviour both drivers share, beyond the protocol -------------------------------

NO_REPLY_COMMAND = {"zaber": r"/1 1 \d+ move abs 192000", "grbl": re.escape("G90 G0 X45.000")}
"""The command each driver sends for ``move_to(45.0)`` after homing, as a pattern (a Zaber command carries
its message id, which depends on how many polls homing took)."""
BUSY_STATUS = {"grbl": {"state": "Run"}, "zaber": {}}
"""Further ``status()`` items while a move is under way."""
ARRIVAL_TOL_DEG = {"grbl": 0.0, "zaber": 1e-3}


def _driver(kind, port, **kw):
    return make_driver(TURNTABLES[kind][1], port, **kw)


@pytest.mark.parametrize("kind", sorted(TURNTABLES))
def test_position_is_reported_while_moving(kind):
    start = TURNTABLES[kind][0]
    # 300 degrees at 150 deg/s: 2 s of travel, so that a loaded machine still polls it often
    with start(speed_deg_s=150.0, accel_deg_s2=1500.0) as h, _driver(kind, h.port_path) as tt:
        tt.home()
        tt.start_move(300.0)
        seen = []
        while True:
            st = tt.status()
            if not st["busy"]:
                break
            for key, value in BUSY_STATUS[kind].items():
                assert st[key] == value
            seen.append(st["position"])
            time.sleep(0.03)
        assert len(seen) >= 5
        # a controller may report the target while its state still says moving (GRBL's state follows its
        # planner a moment later): at the target, but never beyond it, and rising until there
        assert all(0.0 <= p <= 300.0 for p in seen), seen
        on_the_way = [p for p in seen if p < 300.0]
        assert len(on_the_way) >= 5 and all(b > a for a, b in zip(on_the_way, on_the_way[1:])), seen
        assert abs(tt.wait_idle(timeout=2.0) - 300.0) <= ARRIVAL_TOL_DEG[kind]


@pytest.mark.parametrize("kind", sorted(TURNTABLES))
def test_no_reply_times_out_within_the_reply_timeout_then_recovers(kind):
    start = TURNTABLES[kind][0]
    # the reply timeout is long enough that a loaded machine's scheduling (tenths of a second) stays below
    # the margin, which is less than one more reply timeout (a wait of two would fail)
    with start(**FAST) as h, _driver(kind, h.port_path, reply_timeout=1.5) as tt:
        tt.home()
        h.emulator.inject("no_reply")
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeout, match=rf"no reply to '{NO_REPLY_COMMAND[kind]}' within 1.50 s"):
            tt.move_to(45.0)
        assert 1.49 <= time.monotonic() - t0 < 2.9
        assert tt.move_to(45.0) == 45.0


@pytest.mark.parametrize("kind", sorted(TURNTABLES))
def test_garbage_bytes_are_a_protocol_error_then_recovers(kind):
    start = TURNTABLES[kind][0]
    with start(**FAST) as h, _driver(kind, h.port_path) as tt:
        tt.home()
        h.emulator.inject("garbage")
        with pytest.raises(ProtocolError, match="garbage on the line"):
            tt.position()
        assert tt.move_to(45.0) == 45.0


@pytest.mark.parametrize("kind", sorted(TURNTABLES))
def test_device_vanishing_mid_move_is_a_disconnect_within_the_timeout(kind):
    start = TURNTABLES[kind][0]
    with start(speed_deg_s=600.0, accel_deg_s2=6000.0) as h, _driver(kind, h.port_path) as tt:
        tt.home()
        h.emulator.inject("vanish", at=0.3)
        t0 = time.monotonic()
        with pytest.raises(DeviceDisconnected, match="device gone"):
            tt.move_to(270.0, timeout=60.0)
        assert time.monotonic() - t0 < 20.0  # at once, not at the move's timeout
        with pytest.raises(DeviceDisconnected):
            tt.position()
