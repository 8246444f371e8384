"""GRBL driver: byte-exact command sequences, and the real driver over a real
pty against the GRBL emulator (homing lock, motion, alarms, faults, recovery)."""

import time

import pytest

from drivers import open_turntable
from drivers.errors import DeviceFault, DeviceRejected, DeviceTimeout, ProtocolError
from drivers.grbl import GrblTurntable
from drivers.sim.grbl_emulator import GrblEmulator, start_grbl_emulator
from drivers.sim.world import SimWorld
from drivers.testing import ScriptedDevice
from tests.drivers.turntables import FAST, make_driver

BANNER = b"\r\nGrbl 1.1h ['$' for help]\r\n"


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
            tt.home()
            assert tt.move_to(45.0) == 45.0
            assert tt.position() == 45.0
            tt.unlock()
    assert "[MSG:'$H'|'$X' to unlock]" not in tt.messages  # read past, not a reply


def test_feed_and_units_per_degree_shape_the_gcode():
    script = [
        (b"\x18", BANNER),
        (b"G90 G1 X90.000 F1200\n", b"ok\r\n"),
        (b"?", b"<Idle|MPos:90.000,0.000,0.000|WCO:0.000,0.000,0.000|FS:0,0>\r\n"),
    ]
    with ScriptedDevice(script, name="grbl") as dev:
        with driver(dev.port, feed=1200, units_per_degree=2.0) as tt:
            assert tt.move_to(45.0) == 45.0


def test_wpos_reports_and_malformed_status():
    script = [(b"\x18", BANNER), (b"?", b"<Idle|WPos:12.500,0.000,0.000|FS:0,0>\r\n"), (b"?", b"<Idle|MPos:1.0.0>\r\n")]
    with ScriptedDevice(script, name="grbl") as dev:
        with driver(dev.port) as tt:
            assert tt.position() == 12.5
            with pytest.raises(ProtocolError, match=r"bad coordinates in '<Idle\|MPos:1.0.0>'"):
                tt.position()


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
        with pytest.raises(DeviceRejected, match=r"error:9 \(G-code locked out during alarm or jog state\)"):
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
    with start_grbl_emulator(speed_deg_s=600.0, accel_deg_s2=6000.0) as h, driver(h.port_path) as tt:
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
            tt.move_to(270.0, timeout=2.0)
        assert time.monotonic() - t0 < 1.0
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


def test_soft_limit_alarm_when_target_exceeds_travel():
    with start_grbl_emulator(soft_limits=(0.0, 180.0), **FAST) as h, driver(h.port_path) as tt:
        tt.home()
        with pytest.raises(DeviceFault, match=r"ALARM:2 \(soft limit alarm"):
            tt.move_to(270.0)
        tt.recover()
        assert tt.move_to(170.0) == 170.0


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
        ({"driver": "grbl", "port": "x", "axis": "Q"}, "axis must be one of"),
        ({"driver": "grbl", "port": "x", "units_per_degree": 1, "steps_per_degree": 2}, "not both"),
        ({"driver": "grbl", "port": "x", "steps_per_unit": 2}, "'steps_per_unit' needs 'steps_per_degree'"),
        ({"driver": "grbl", "port": "x", "feed": -5}, "feed must be positive"),
    ],
)
def test_bad_config_names_the_problem(cfg, message):
    with pytest.raises(ValueError, match=message):
        open_turntable(cfg)


def test_emulator_fault_names_are_checked():
    with pytest.raises(ValueError, match="unknown fault 'stall'.*alarm"):
        GrblEmulator().inject("stall")
