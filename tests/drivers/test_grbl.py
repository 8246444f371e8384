"""GRBL driver: byte-exact command sequences, and the real driver over a real
pty against the GRBL emulator (homing lock, motion, alarms, faults, recovery)."""

import re
import threading
import time

import pytest

from drivers import open_turntable
from drivers.errors import DeviceFault, DeviceRejected, DeviceTimeout, OutOfRange, ProtocolError
from drivers.grbl import GrblTurntable
from drivers.protocols import Range
from drivers.sim.grbl_emulator import GrblEmulator, start_grbl_emulator
from drivers.sim.world import SimWorld
from drivers.testing import ScriptedDevice
from tests.drivers.turntables import FAST, make_driver

BANNER = b"\r\nGrbl 1.1h ['$' for help]\r\n"


def settings_listing(soft_limits: int = 0, homing: int = 0, pulloff: str = "1.000", x: tuple = ()) -> bytes:
    """A GRBL 1.1h reply to ``$$`` as written out by hand from grbl/report.c (report_grbl_settings)
    and the DEFAULTS_GENERIC values of grbl/defaults.h; ``x`` replaces $110, $120, $130."""
    rate, accel, travel = x or ("500.000", "10.000", "200.000")
    lines = (
        "$0=10 $1=25 $2=0 $3=0 $4=0 $5=0 $6=0 $10=1 $11=0.010 $12=0.002 $13=0"
        f" $20={soft_limits} $21=0 $22={homing} $23=0 $24=25.000 $25=500.000 $26=250 $27={pulloff}"
        " $30=1000 $31=0 $32=0 $100=250.000 $101=250.000 $102=250.000"
        f" $110={rate} $111=500.000 $112=500.000 $120={accel} $121=10.000 $122=10.000"
        f" $130={travel} $131=200.000 $132=200.000 ok"
    ).split()
    return b"".join(line.encode() + b"\r\n" for line in lines)


SETTINGS = settings_listing()  # a fresh GRBL: soft limits off


@pytest.fixture
def emu():
    handle = start_grbl_emulator(**FAST)
    yield handle
    handle.stop()


def driver(port, **kw):
    return make_driver(GrblTurntable, port, **kw)


# -- byte-exact ------------------------------------------------------------


def test_open_home_move_and_position_bytes():
    script = [
        (b"\x18", BANNER + b"[MSG:'$H'|'$X' to unlock]\r\n"),
        (b"$$\n", settings_listing(homing=1)),
        (b"$H\n", b"ok\r\n"),
        (b"?", b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>\r\n"),
        (b"G90 G0 X45.000\n", b"ok\r\n"),
        (b"?", b"<Run|MPos:20.512,0.000,0.000|FS:21600,0>\r\n"),
        (b"?", b"<Idle|MPos:45.000,0.000,0.000|FS:0,0>\r\n"),
        (b"?", b"<Idle|MPos:45.000,0.000,0.000|FS:0,0>\r\n"),
        (b"$X\n", b"[MSG:Caution: Unlocked]\r\nok\r\n"),
    ]
    with ScriptedDevice(script, name="grbl") as dev:
        with driver(dev.port) as tt:
            assert tt.version == "1.1h"
            assert tt.settings[22] == 1.0 and tt.settings[130] == 200.0 and len(tt.settings) == 34
            assert tt.device_travel_range() is None  # $20=0: no soft limits
            tt.home()
            assert tt.move_to(45.0) == 45.0
            assert tt.position() == 45.0
            tt.unlock()
    assert "[MSG:'$H'|'$X' to unlock]" not in tt.messages  # read past, not a reply


def test_feed_and_units_per_degree_shape_the_gcode():
    script = [
        (b"\x18", BANNER),
        (b"$$\n", SETTINGS),
        (b"G90 G1 X90.000 F1200\n", b"ok\r\n"),
        (b"?", b"<Idle|MPos:90.000,0.000,0.000|WCO:0.000,0.000,0.000|FS:0,0>\r\n"),
    ]
    with ScriptedDevice(script, name="grbl") as dev:
        with driver(dev.port, feed=1200, units_per_degree=2.0) as tt:
            assert tt.move_to(45.0) == 45.0


def test_wpos_reports_and_malformed_status():
    script = [
        (b"\x18", BANNER),
        (b"$$\n", SETTINGS),
        (b"?", b"<Idle|WPos:12.500,0.000,0.000|FS:0,0>\r\n"),
        (b"?", b"<Idle|MPos:1.0.0>\r\n"),
    ]
    with ScriptedDevice(script, name="grbl") as dev:
        with driver(dev.port) as tt:
            assert tt.position() == 12.5
            with pytest.raises(ProtocolError, match=r"bad coordinates in '<Idle\|MPos:1.0.0>'"):
                tt.position()


def test_soft_limits_read_at_open_are_the_travel():
    """$20=1, $130=360: GRBL accepts machine X in [-360, 0]; a table turning positive as GRBL counts
    down (units_per_degree -1) travels [0, 360]°. Outside it: OutOfRange, nothing sent."""
    script = [
        (b"\x18", BANNER),
        (b"$$\n", settings_listing(soft_limits=1, homing=1, x=("600.000", "50.000", "360.000"))),
    ]
    with ScriptedDevice(script, name="grbl") as dev:
        with driver(dev.port, units_per_degree=-1.0, limits=(0.0, 720.0)) as tt:
            assert tt.device_travel_range() == Range(0.0, 360.0, "°", "GRBL soft limits $20=1, $130=360.000")
            assert tt.limits == (0.0, 360.0)
            with pytest.raises(OutOfRange, match=r"move to 400° is outside the range \[0, 360\]° \(configured limits"):
                tt.move_to(400.0)
    script = [
        (b"\x18", BANNER),
        (b"$$\n", settings_listing(soft_limits=1, homing=1, x=("600.000", "50.000", "90.000"))),
    ]
    with ScriptedDevice(script, name="grbl") as dev:
        with pytest.raises(
            DeviceRejected, match=r"configured limits \[0, 360\]° lie outside the device's travel \[-90, 0\]°"
        ):
            driver(dev.port).open()  # units_per_degree +1: the travel is negative


def test_a_controller_that_refuses_dollar_dollar_keeps_the_configured_limits():
    with ScriptedDevice([(b"\x18", BANNER), (b"$$\n", b"error:3\r\n")], name="grbl") as dev:
        with driver(dev.port) as tt:
            assert tt.settings == {} and tt.device_travel_range() is None
            assert tt.travel_range() == Range(0.0, 360.0, "°", "configured limits")


def test_emulator_lists_and_stores_settings_like_grbl():
    sent = bytearray()
    emu = GrblEmulator(speed_deg_s=10.0, accel_deg_s2=50.0, soft_limits=True, max_travel=360.0)
    emu.server = type("Wire", (), {"write": staticmethod(sent.extend)})()
    emu.on_bytes(b"$$\n", time.monotonic())
    expected = settings_listing(soft_limits=1, homing=1, pulloff="0.000", x=("600.000", "50.000", "360.000"))
    assert bytes(sent) == expected
    sent.clear()
    for line in (b"$130=90\n", b"$200=1\n", b"$120=-5\n", b"$22=0\n", b"$20=1\n"):
        emu.on_bytes(line, time.monotonic())
    assert bytes(sent) == b"ok\r\nerror:3\r\nerror:4\r\nok\r\nerror:10\r\n"
    assert emu.settings[130] == 90.0 and emu.settings[20] == 0 and not emu.homing_enabled  # $22=0 cleared $20


def test_missing_banner_is_a_timeout():
    with ScriptedDevice([(b"\x18", b"ok\r\n")], name="grbl") as dev:
        with pytest.raises(DeviceTimeout, match="no GRBL banner after reset within 0.30 s"):
            driver(dev.port, startup_timeout=0.3).open()


# -- against the emulator --------------------------------------------------


def test_locked_until_homed_then_moves_around_the_circle():
    world = SimWorld()
    with start_grbl_emulator(world=world, **FAST) as h, driver(h.port_path) as tt:
        st = tt.status()
        assert st["state"] == "Alarm" and st["fault"]
        # the controller's state, not the line: a fault the session recovers from (recover, home), not a refusal
        with pytest.raises(
            DeviceFault, match=r"error:9 \(G-code locked out during alarm or jog state\); use recover\(\), then home"
        ):
            tt.move_to(10.0)
        tt.home()
        assert tt.status()["state"] == "Idle"
        for angle in range(0, 360, 45):
            assert tt.move_to(float(angle)) == float(angle)
            assert tt.position() == float(angle)
            assert world.stage_deg == pytest.approx(angle, abs=1e-9)


def test_unlock_without_homing(emu):
    with driver(emu.port_path) as tt:
        tt.unlock()
        assert "[MSG:Caution: Unlocked]" in tt.messages
        assert tt.move_to(30.0) == 30.0


def test_stop_mid_move_holds_and_keeps_the_position():
    # 300 degrees at 100 deg/s: 3 s of travel, so that the stop comes mid-move on a loaded machine too
    with start_grbl_emulator(speed_deg_s=100.0, accel_deg_s2=1000.0) as h, driver(h.port_path) as tt:
        tt.home()
        tt.start_move(300.0)
        time.sleep(0.15)
        tt.stop()
        st = tt.status()
        assert st["state"] == "Idle" and 0.0 < st["position"] < 300.0
        time.sleep(0.05)
        assert tt.position() == st["position"]
        assert tt.move_to(90.0) == 90.0  # no alarm, no re-homing needed


def test_rejected_command_raises_with_the_meaning_and_the_next_one_works(emu):
    with driver(emu.port_path) as tt:
        tt.home()
        emu.emulator.inject("reject", code=20)
        with pytest.raises(DeviceRejected, match=r"'G90 G0 X90.000' rejected: error:20 \(unsupported or invalid"):
            tt.move_to(90.0)
        assert tt.move_to(90.0) == 90.0
        with pytest.raises(DeviceRejected, match=r"error:3 "):
            tt.send("$Q")


def test_hard_limit_alarm_mid_move_then_recover_and_rehome(emu):
    with driver(emu.port_path) as tt:
        tt.home()
        emu.emulator.inject("alarm", at=0.5, code=1)
        t0 = time.monotonic()
        with pytest.raises(DeviceFault, match=r"ALARM:1 \(hard limit triggered"):
            tt.move_to(270.0, timeout=60.0)
        assert time.monotonic() - t0 < 20.0  # at the alarm, not at the move's timeout
        st = tt.status()
        assert st["state"] == "Alarm" and 0.0 < st["position"] < 270.0
        with pytest.raises(DeviceFault, match=r"cannot move, controller in ALARM:1.*recover\(\)"):
            tt.move_to(90.0)
        assert tt.recover() == [
            "ALARM:1 (hard limit triggered; machine position is likely lost, re-homing is recommended)"
        ]
        assert tt.status()["state"] == "Idle"
        tt.home()
        assert tt.move_to(90.0) == 90.0


def test_an_alarm_the_linear_stage_read_is_cleared_by_the_turntables_recover(emu):
    """The controller's alarm is one for all its axes: read while the shift axis moved, the turntable's
    recover() (what a session calls) clears it, and the shift axis moves again. Before, each axis kept its
    own: recover() cleared nothing and the shift axis refused every move until the driver was reopened."""
    with start_grbl_emulator(shift_axis="Z", **FAST) as h, driver(h.port_path, shift_axis="Z") as tt:
        tt.home()
        h.emulator.inject("alarm", at=0.5, code=1, axis="Z")  # the linear stage runs into a limit switch
        with pytest.raises(DeviceFault, match=r"shift axis Z: .*ALARM:1 \(hard limit triggered"):
            tt.shift.move_to(50.0)
        assert tt.last_alarm == 1
        with pytest.raises(DeviceFault, match=r"cannot move, controller in ALARM:1"):
            tt.move_to(90.0)
        assert tt.recover() == [
            "ALARM:1 (hard limit triggered; machine position is likely lost, re-homing is recommended)"
        ]
        tt.home()
        assert tt.shift.move_to(50.0) == 50.0 and tt.move_to(90.0) == 90.0


def test_a_controller_that_restarted_unasked_refuses_moves_until_recovered_and_homed():
    """A power dip or a USB reset reboots the board: GRBL prints its banner unasked and counts from 0
    where it stands, in Alarm (homing on). That is a DeviceFault naming the restart, moves are refused
    before anything is sent until recover() and home(). Before, the banner was filed as a message and the
    next move was refused with error:9, a DeviceRejected that stopped a session at once."""
    unlock = b"[MSG:'$H'|'$X' to unlock]\r\n"
    script = [
        (b"\x18", BANNER + unlock),
        (b"$$\n", settings_listing(homing=1)),
        (b"$H\n", b"ok\r\n"),
        (b"?", b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>\r\n"),
        (b"G90 G0 X45.000\n", b"ok\r\n"),
        (b"?", b"<Idle|MPos:45.000,0.000,0.000|FS:0,0>\r\n"),
        (b"G90 G0 X90.000\n", BANNER + unlock),  # the line is lost: the board restarts
        (b"\x18", BANNER + unlock),  # recover(): reset, still locked, unlock
        (b"?", b"<Alarm|MPos:0.000,0.000,0.000|FS:0,0>\r\n"),
        (b"$X\n", b"[MSG:Caution: Unlocked]\r\nok\r\n"),
        (b"$H\n", b"ok\r\n"),
        (b"?", b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>\r\n"),
        (b"G90 G0 X90.000\n", b"ok\r\n"),
        (b"?", b"<Idle|MPos:90.000,0.000,0.000|FS:0,0>\r\n"),
    ]
    restarted = (
        r"the controller restarted \(its banner came unasked: a power dip or a USB reset\), its position is lost"
    )
    with ScriptedDevice(script, name="grbl") as dev:
        with driver(dev.port) as tt:
            tt.home()
            assert tt.move_to(45.0) == 45.0
            with pytest.raises(DeviceFault, match=restarted):
                tt.move_to(90.0)
            assert tt.restarted
            with pytest.raises(DeviceFault, match=restarted):
                tt.move_to(90.0)  # refused: nothing sent
            assert tt.recover() == ["restart (position lost: home it)"]
            with pytest.raises(DeviceFault, match=restarted):
                tt.move_to(90.0)  # not homed yet: still refused
            tt.home()
            assert not tt.restarted and tt.move_to(90.0) == 90.0


def test_the_emulated_controller_restarts_like_grbl_at_power_up(emu):
    with driver(emu.port_path) as tt:
        tt.home()
        assert tt.move_to(120.0) == 120.0
        emu.emulator.restart()
        with pytest.raises(DeviceFault, match="the controller restarted"):
            tt.move_to(45.0)
        assert tt.status()["fault"] and tt.status()["state"] == "Alarm" and tt.position() == 0.0
        tt.recover()
        tt.home()
        assert tt.move_to(45.0) == 45.0


def test_soft_limit_alarm_when_the_travel_shrinks_behind_the_drivers_back():
    """The driver refuses what the travel read at open excludes; if $130 is changed afterwards
    the controller's own ALARM:2 is a DeviceFault, and reopening reads the new travel."""
    emu = dict(soft_limits=True, max_travel=180.0, units_per_degree=-1.0, **FAST)
    with start_grbl_emulator(**emu) as h, driver(h.port_path, units_per_degree=-1.0) as tt:
        tt.home()
        assert tt.limits == (0.0, 180.0)
        with pytest.raises(OutOfRange):
            tt.move_to(270.0)
        tt.send("$130=90")
        with pytest.raises(DeviceFault, match=r"ALARM:2 \(soft limit alarm"):
            tt.move_to(170.0)
        tt.recover()
        tt.close()
        tt.open()
        assert tt.limits == (0.0, 90.0)
        with pytest.raises(OutOfRange, match=r"move to 170° is outside the range \[0, 90\]°"):
            tt.move_to(170.0)
        tt.home()
        assert tt.move_to(80.0) == 80.0


def test_move_that_does_not_finish_times_out_and_stops():
    with start_grbl_emulator(speed_deg_s=90.0, accel_deg_s2=900.0) as h, driver(h.port_path) as tt:
        tt.home()
        with pytest.raises(DeviceTimeout, match=r"move to 270.0° not finished within 0.30 s"):
            tt.move_to(270.0, timeout=0.3)
        st = tt.status()
        assert st["state"] == "Idle" and 0.0 < st["position"] < 270.0


# -- configuration -------------------------------------------------------------


def test_from_config_with_steps_per_degree_and_a_fourth_axis():
    # motor: 17.7778 steps per table degree; GRBL $103 = 35.5556 steps/unit
    with start_grbl_emulator(axis="A", units_per_degree=0.5, **FAST) as h:
        tt = open_turntable(
            {
                "driver": "grbl",
                "port": h.port_path,
                "axis": "A",
                "steps_per_degree": 17.7778,
                "steps_per_unit": 35.5556,
                "poll_interval": 0.005,
            }
        )
        assert isinstance(tt, GrblTurntable)
        assert tt.units_per_degree == pytest.approx(0.5)
        with tt:
            tt.home()
            assert tt.move_to(90.0) == pytest.approx(90.0, abs=0.002)
            assert b"G90 G0 A45.000" in h.emulator.received


@pytest.mark.parametrize(
    "cfg, message",
    [
        ({"driver": "grbl"}, "missing config key 'port'"),
        ({"driver": "grbl", "port": "x", "speed": 1}, "unknown config key 'speed'"),
        ({"driver": "grbl", "port": "x", "axis": "Q"}, "config key 'axis': expected one of X, Y, Z, A, B, C, x"),
        ({"driver": "grbl", "port": "x", "units_per_degree": 1, "steps_per_degree": 2}, "not both"),
        ({"driver": "grbl", "port": "x", "steps_per_unit": 2}, "'steps_per_unit' needs 'steps_per_degree'"),
        (
            {"driver": "grbl", "port": "x", "feed": -5},
            r"config key 'feed': expected a number in \(0, 10000000\] units/min, got -5",
        ),
    ],
)
def test_bad_config_names_the_problem(cfg, message):
    with pytest.raises(ValueError, match=message):
        open_turntable(cfg)


def test_emulator_fault_names_are_checked():
    with pytest.raises(ValueError, match="unknown fault 'stall'.*alarm"):
        GrblEmulator().inject("stall")


# -- the tilt axis (issue 23: the board tilted by a second axis of the stage) ----------------------------


def test_tilt_axis_bytes():
    """``tilt_axis="Y"``: the second axis of the same controller on the same connection (no second reset:
    the settings read once, a status report at open), moved with its own letter and read from MPos; its
    configured limits (default 0..60°) refuse a move before anything is sent."""
    script = [
        (b"\x18", BANNER),
        (b"$$\n", SETTINGS),
        (b"?", b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>\r\n"),
        (b"G90 G0 Y30.000\n", b"ok\r\n"),
        (b"?", b"<Run|MPos:0.000,12.250,0.000|FS:1800,0>\r\n"),
        (b"?", b"<Idle|MPos:0.000,30.000,0.000|FS:0,0>\r\n"),
        (b"G90 G0 X45.000\n", b"ok\r\n"),
        (b"?", b"<Idle|MPos:45.000,30.000,0.000|FS:0,0>\r\n"),
    ]
    with ScriptedDevice(script, name="grbl") as dev:
        with driver(dev.port, tilt_axis="Y") as tt:
            assert tt.tilt is not None and tt.tilt.travel_range().maximum == 60.0 and tt.tilt.settings is tt.settings
            assert tt.tilt.move_to(30.0) == 30.0
            with pytest.raises(OutOfRange):
                tt.tilt.move_to(61.0)
            assert tt.move_to(45.0) == 45.0


def test_tilt_axis_on_the_emulator_tilts_the_simulated_board():
    world = SimWorld()
    with start_grbl_emulator(world=world, tilt_axis="Y", **FAST) as h, driver(h.port_path, tilt_axis="Y") as tt:
        assert world.tilt_at() == 0.0
        tt.home()
        assert tt.tilt.move_to(25.0) == 25.0 and world.tilt_at() == pytest.approx(25.0, abs=1e-9)
        assert tt.move_to(90.0) == 90.0 and world.tilt_at() == pytest.approx(25.0, abs=1e-9)
        assert world.stage_deg == pytest.approx(90.0, abs=1e-9) and tt.tilt.position() == 25.0
        tt.home()  # $H homes both axes
        assert world.tilt_at() == pytest.approx(0.0, abs=1e-9) and tt.position() == 0.0
    with pytest.raises(ValueError, match="tilt_axis must be another axis than X"):
        driver("/dev/null", tilt_axis="x")


# -- the shift axis (issue 19: a linear stage carries the turntable sideways between groups of shots) ------


def test_shift_axis_bytes_and_millimetres():
    """``shift_axis="Z"``: another axis of the same controller on the same connection, opened like the tilt
    axis (no second reset); positions in mm (``shift_units_per_mm`` default 1: GRBL counts mm), read from
    MPos, its configured limits (default 0..100 mm) refuse a move before anything is sent, messages in mm."""
    script = [
        (b"\x18", BANNER),
        (b"$$\n", SETTINGS),
        (b"?", b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>\r\n"),
        (b"G90 G0 Z12.500\n", b"ok\r\n"),
        (b"?", b"<Run|MPos:0.000,0.000,6.250|FS:3000,0>\r\n"),
        (b"?", b"<Idle|MPos:0.000,0.000,12.500|FS:0,0>\r\n"),
        (b"G90 G0 Z20.000\n", b"ok\r\n"),
        (b"?", b"<Idle|MPos:0.000,0.000,15.000|FS:0,0>\r\n"),
    ]
    with ScriptedDevice(script, name="grbl") as dev:
        with driver(dev.port, shift_axis="Z") as tt:
            assert tt.tilt is None and tt.shift is not None and tt.shift.name == f"{tt.name} shift axis Z"
            assert tt.shift.travel_range() == Range(0.0, 100.0, "mm", "configured limits")
            assert tt.shift.move_to(12.5) == 12.5
            with pytest.raises(OutOfRange, match=r"shift axis Z: move to 101 mm is outside the range \[0, 100\] mm"):
                tt.shift.move_to(101.0)
            with pytest.raises(DeviceFault, match=r"move to 20.0 mm ended idle at 15.000 mm, not at 20.000 mm"):
                tt.shift.move_to(20.0)


def test_shift_axis_on_the_emulator_moves_the_simulated_turntable_sideways():
    world = SimWorld()
    with (
        start_grbl_emulator(world=world, tilt_axis="Y", shift_axis="Z", **FAST) as h,
        driver(h.port_path, tilt_axis="Y", shift_axis="Z") as tt,
    ):
        assert world.shift_at() == 0.0
        tt.home()
        assert tt.shift.move_to(12.5) == 12.5 and world.shift_at() == pytest.approx(12.5, abs=1e-9)
        assert tt.move_to(90.0) == 90.0 and tt.tilt.move_to(10.0) == 10.0
        assert world.shift_at() == pytest.approx(12.5, abs=1e-9) and world.tilt_at() == pytest.approx(10.0, abs=1e-9)
        assert tt.shift.position() == 12.5 and tt.settings[132] == 100.0  # the shift's $13x: its travel
        tt.home()  # $H homes every axis
        assert world.shift_at() == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match="shift_axis must be another axis than X"):
        driver("/dev/null", shift_axis="x")
    with pytest.raises(ValueError, match="shift_axis must be another axis than Y"):
        driver("/dev/null", tilt_axis="Y", shift_axis="y")
    with pytest.raises(ValueError, match="shift_units_per_mm must not be 0"):
        driver("/dev/null", shift_axis="Z", shift_units_per_mm=0)
    with pytest.raises(ValueError, match="shift_axis must be another of X, Y, Z or A"):
        GrblEmulator(tilt_axis="Y", shift_axis="Y")


# -- a feed hold, the safety door (GRBL's suspended states) ----------------------------------------------

SLOW = dict(speed_deg_s=90.0, accel_deg_s2=900.0)  # 270° in about 3 s: the fault comes well within the move


def test_the_safety_door_opened_mid_move_is_a_fault_at_once_not_a_wait_for_the_move_timeout():
    """``Door:1`` while the move is awaited: a DeviceFault naming the device and what to do, long before the
    60 s move timeout (before: the driver polled the door state for 60 s, then said the move timed out).
    Nothing is sent to resume it; a reset after the door is shut, and the move goes through."""
    with start_grbl_emulator(**SLOW) as h, driver(h.port_path, move_timeout=60.0) as tt:
        tt.home()
        h.emulator.inject("door", at=0.3)
        t0 = time.monotonic()
        with pytest.raises(DeviceFault) as err:
            tt.move_to(270.0)
        assert time.monotonic() - t0 < 20.0  # well before move_timeout (60 s)
        assert re.fullmatch(
            rf"{re.escape(tt.name)}: move to 270.0° stopped at \d+\.\d{{3}}°: safety door opened \(Door:1\);"
            r" close it and resume the session",
            str(err.value),
        ), str(err.value)
        st = tt.status()
        assert st["state"] == "Door" and st["fault"] and 0.0 < st["position"] < 270.0
        assert st["warnings"] == ["Door:1 (safety door opened)"]
        assert b"~" not in h.emulator.received  # cycle start is the operator's, not the driver's
        tt.recover()  # a reset with the door still open: GRBL enters the door state again
        with pytest.raises(DeviceFault, match=r"safety door opened \(Door:1\); close it and resume the session"):
            tt.move_to(270.0)
        h.emulator.close_door()
        assert tt.status()["warnings"] == ["Door:0 (safety door opened)"]
        tt.recover()
        assert tt.status()["state"] == "Idle"
        assert tt.move_to(270.0) == 270.0


def test_a_feed_hold_released_in_time_lets_the_move_finish():
    """Someone presses feed hold mid-move, then cycle start while the driver still waits: the move
    finishes at its target (the hold is waited out, hold_timeout 60 s)."""
    with start_grbl_emulator(**SLOW) as h, driver(h.port_path, move_timeout=60.0, hold_timeout=60.0) as tt:
        tt.home()
        h.emulator.inject("hold", at=0.3)
        released = threading.Event()

        def release_once_the_driver_saw_the_hold():
            deadline = time.monotonic() + 30.0
            while time.monotonic() < deadline and not h.emulator.state.startswith("Hold"):
                time.sleep(0.005)
            polls = h.emulator.received.count(b"?")
            while time.monotonic() < deadline and h.emulator.received.count(b"?") < polls + 3:
                time.sleep(0.005)  # the driver polled the held controller three more times
            h.emulator.cycle_start()
            released.set()

        helper = threading.Thread(target=release_once_the_driver_saw_the_hold, daemon=True)
        n = len(h.emulator.received)
        helper.start()
        try:
            assert tt.move_to(270.0) == 270.0
        finally:
            helper.join(30.0)
        assert released.is_set()
        assert b"\x18" not in h.emulator.received[n:] and b"~" not in h.emulator.received[n:]  # no reset, no resume


def test_a_feed_hold_longer_than_hold_timeout_cancels_the_move_and_is_a_fault():
    """Nobody presses cycle start: after hold_timeout the move is cancelled (the hold kept, a soft reset
    flushes the planner, position kept, no alarm) and a DeviceFault says what happened and what to do;
    well before the 60 s move timeout. A cycle start pressed later moves nothing."""
    with start_grbl_emulator(**SLOW) as h, driver(h.port_path, move_timeout=60.0, hold_timeout=0.5) as tt:
        tt.home()
        h.emulator.inject("hold", at=0.3)
        t0 = time.monotonic()
        with pytest.raises(DeviceFault) as err:
            tt.move_to(270.0)
        assert time.monotonic() - t0 < 20.0
        assert re.fullmatch(
            rf"{re.escape(tt.name)}: move to 270.0° held by a feed hold \(Hold:0\) at \d+\.\d{{3}}° for 0.5 s"
            r" without cycle start \(~\); move cancelled, position kept: resume the session",
            str(err.value),
        ), str(err.value)
        st = tt.status()
        assert st["state"] == "Idle" and not st["fault"] and 0.0 < st["position"] < 270.0
        assert tt.last_alarm is None
        h.emulator.cycle_start()
        assert tt.status() == st
        assert tt.move_to(90.0) == 90.0


def test_the_emulated_door_and_hold_speak_like_grbl():
    """Status reports and replies while held or with the door open, as GRBL 1.1 gives them."""
    sent = bytearray()
    wire = type("Wire", (), {"write": staticmethod(sent.extend)})()
    emu, homing = GrblEmulator(homing=False, **FAST), GrblEmulator(**FAST)
    emu.server = homing.server = wire

    def exchange(data: bytes, to: GrblEmulator = emu) -> bytes:
        sent.clear()
        to.on_bytes(data, time.monotonic())
        return bytes(sent)

    assert exchange(b"!?") == b"<Hold:0|MPos:0.000,0.000,0.000|FS:0,0>\r\n"  # a hold while idle too
    assert exchange(b"$$\n") == b"error:8\r\n"
    assert exchange(b"~?") == b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>\r\n"
    emu.open_door()
    assert exchange(b"?") == b"<Door:1|MPos:0.000,0.000,0.000|FS:0,0>\r\n"
    assert exchange(b"~?$1=30\n") == b"<Door:1|MPos:0.000,0.000,0.000|FS:0,0>\r\nerror:8\r\n"  # ajar: no resume
    assert exchange(b"\x18?") == BANNER + b"<Door:1|MPos:0.000,0.000,0.000|FS:0,0>\r\n"  # still open after reset
    emu.close_door()
    assert exchange(b"?~?") == (b"<Door:0|MPos:0.000,0.000,0.000|FS:0,0>\r\n<Idle|MPos:0.000,0.000,0.000|FS:0,0>\r\n")
    assert exchange(b"\x84?") == b"<Door:0|MPos:0.000,0.000,0.000|FS:0,0>\r\n"  # 0x84 with the door shut
    exchange(b"$H\n", homing)
    sent.clear()
    homing.open_door()
    assert bytes(sent) == b"ALARM:7\r\n"  # homing fail: safety door was opened during homing
    assert exchange(b"$H\n", homing) == b"error:13\r\n"  # blocked while the door is ajar
