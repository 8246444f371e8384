"""Zaber ASCII driver: byte-exact command sequences, and the real driver over a
real pty against the emulator (motion, faults, recovery)."""

import time

import pytest

from drivers import open_turntable
from drivers.errors import DeviceDisconnected, DeviceFault, DeviceRejected, DeviceTimeout, OutOfRange, ProtocolError
from drivers.protocols import Range
from drivers.sim.world import SimWorld
from drivers.sim.zaber_emulator import ZaberEmulator, start_zaber_emulator, zaber_checksum
from drivers.testing import ScriptedDevice
from drivers.zaber import ZaberTurntable
from tests.drivers.turntables import FAST, make_driver

MSPD = 1536000 / 360.0  # X-RSW60 microsteps per degree
# what open() reads after the status request: the axis travel, in microsteps
LIMITS = [
    (b"/1 1 1 get limit.min\n", b"@01 1 01 OK IDLE -- 0\r\n"),
    (b"/1 1 2 get limit.max\n", b"@01 1 02 OK IDLE -- 1536000\r\n"),
]


@pytest.fixture
def emu():
    handle = start_zaber_emulator(**FAST)
    yield handle
    handle.stop()


def driver(port, **kw):
    return make_driver(ZaberTurntable, port, **kw)


# -- byte-exact ------------------------------------------------------------


def test_home_move_and_position_bytes():
    script = [
        (b"/1 0 0\n", b"@01 0 00 OK IDLE WR 0\r\n"),
        (b"/1 1 1 get limit.min\n", b"@01 1 01 OK IDLE WR 0\r\n"),
        (b"/1 1 2 get limit.max\n", b"@01 1 02 OK IDLE WR 1536000\r\n"),
        (b"/1 1 3 home\n", b"@01 1 03 OK BUSY WR 0\r\n"),
        (b"/1 1 4 get pos\n", b"@01 1 04 OK BUSY WR 51200\r\n"),
        (b"/1 1 5 get pos\n", b"@01 1 05 OK IDLE -- 0\r\n"),
        (b"/1 1 6 move abs 192000\n", b"@01 1 06 OK BUSY -- 0\r\n"),
        (b"/1 1 7 get pos\n", b"@01 1 07 OK BUSY -- 96117\r\n"),
        (b"/1 1 8 get pos\n", b"@01 1 08 OK IDLE -- 192000\r\n"),
        (b"/1 1 9 get pos\n", b"@01 1 09 OK IDLE -- 192000\r\n"),
        (b"/1 1 10 stop\n", b"@01 1 10 OK IDLE -- 0\r\n"),
        (b"/1 0 11 warnings clear\n", b"@01 0 11 OK IDLE FS 01 FS\r\n"),
    ]
    with ScriptedDevice(script, name="zaber") as dev:
        with driver(dev.port) as tt:
            tt.home()
            assert tt.move_to(45.0) == 45.0
            assert tt.position() == 45.0
            tt.stop()
            assert tt.clear_warnings() == ["FS"]


def test_checksummed_replies_and_info_and_alert_lines_are_understood():
    body = b"01 1 03 OK IDLE -- 4267"
    reply = b"@" + body + b":%02X\r\n" % zaber_checksum(body)
    script = [
        (b"/1 0 0\n", b"#01 0 an info line\r\n!01 1 IDLE --\r\n@01 0 00 OK IDLE -- 0\r\n"),
        *LIMITS,
        (b"/1 1 3 get pos\n", reply),
    ]
    with ScriptedDevice(script, name="zaber") as dev:
        with driver(dev.port) as tt:
            assert tt.position() == pytest.approx(4267 / MSPD)
            assert tt.alerts == ["!01 1 IDLE --"] and tt.infos == ["#01 0 an info line"]


def test_a_long_connection_keeps_only_the_most_recent_alert_and_info_lines_and_late_replies():
    from drivers.zaber import KEPT_LINES

    script = [(b"/1 0 0\n", b"@01 0 00 OK IDLE -- 0\r\n"), *LIMITS]
    with ScriptedDevice(script, name="zaber") as dev:
        with driver(dev.port) as tt:
            for k in range(KEPT_LINES + 150):
                assert tt.parse_line(f"!01 1 IDLE -- {k}".encode()) is None
                assert tt.parse_line(f"#01 0 info {k}".encode()) is None
            assert len(tt.alerts) == len(tt.infos) == KEPT_LINES == 100
            assert tt.alerts[0] == "!01 1 IDLE -- 150" and tt.alerts[-1] == f"!01 1 IDLE -- {KEPT_LINES + 149}"
            assert tt.infos[-1] == f"#01 0 info {KEPT_LINES + 149}"


def test_bad_checksum_is_a_protocol_error():
    script = [
        (b"/1 0 0\n", b"@01 0 00 OK IDLE -- 0\r\n"),
        *LIMITS,
        (b"/1 1 3 get pos\n", b"@01 1 03 OK IDLE -- 4267:00\r\n"),
    ]
    with ScriptedDevice(script, name="zaber") as dev:
        with driver(dev.port) as tt:
            with pytest.raises(ProtocolError, match="bad checksum in '@01 1 03 OK IDLE -- 4267:00'"):
                tt.position()


def test_reply_from_another_device_is_a_protocol_error():
    script = [(b"/1 0 0\n", b"@02 0 00 OK IDLE -- 0\r\n")]
    with ScriptedDevice(script, name="zaber") as dev:
        with pytest.raises(ProtocolError, match="reply from device 2, expected 1"):
            driver(dev.port).open()


def test_a_reply_with_another_message_id_or_none_is_dropped_not_returned():
    """A late reply to an earlier command (its id, 02) and a reply without an id arrive before the reply to
    ``get pos`` (id 03): both are set aside in ``dropped``, and the position is the one ``03`` answered."""
    script = [
        (b"/1 0 0\n", b"@01 0 00 OK IDLE -- 0\r\n"),
        *LIMITS,
        (b"/1 1 3 get pos\n", b"@01 1 02 OK IDLE -- 1536000\r\n@01 1 OK IDLE -- 999\r\n@01 1 03 OK IDLE -- 4267\r\n"),
    ]
    with ScriptedDevice(script, name="zaber") as dev:
        with driver(dev.port) as tt:
            assert tt.position() == pytest.approx(4267 / MSPD)
            assert tt.dropped == ["@01 1 02 OK IDLE -- 1536000", "@01 1 OK IDLE -- 999"]


def test_the_emulator_repeats_the_message_id_in_its_reply():
    sent = bytearray()
    emu = ZaberEmulator()
    emu.server = type("Wire", (), {"write": staticmethod(sent.extend)})()
    for line in (b"/1 1 12 get pos\n", b"/1 0 7\n", b"/1 0 99 warnings\n", b"/1 1 get pos\n"):
        emu.on_bytes(line, time.monotonic())
    assert bytes(sent) == (
        b"@01 1 12 OK IDLE WR 0\r\n@01 0 07 OK IDLE WR 0\r\n@01 0 99 OK IDLE WR 01 WR\r\n@01 1 OK IDLE WR 0\r\n"
    )


# -- against the emulator --------------------------------------------------


def test_moves_around_the_circle_read_back_and_drive_the_world():
    world = SimWorld()
    with start_zaber_emulator(world=world, **FAST) as h, driver(h.port_path) as tt:
        assert "WR" in tt.warnings()  # powered up without a reference position
        tt.home()
        assert tt.warnings() == []
        for angle in range(0, 360, 45):
            got = tt.move_to(float(angle))
            assert abs(got - angle) <= 0.5 / MSPD
            assert tt.position() == got
            assert world.stage_deg == pytest.approx(got, abs=1e-9)
        assert h.emulator.position_steps(time.monotonic()) == round(315 * MSPD)


def test_a_late_reply_arriving_while_the_next_command_waits_is_not_its_answer(emu):
    """The reply to ``get limit.max`` misses its timeout and arrives while ``get pos`` waits (the emulator
    holds it back until the next command): it is dropped, and the position read is the stage's (0°), not
    limit.max (1536000 microsteps, 360°)."""
    with driver(emu.port_path, reply_timeout=1.0) as tt:
        emu.emulator.inject("late_reply")
        with pytest.raises(DeviceTimeout, match=r"no reply to '/1 1 3 get limit.max' within 1.00 s"):
            tt.command("get limit.max")
        assert tt.position() == 0.0
        assert tt.dropped == ["@01 1 03 OK IDLE WR 1536000"]
        assert tt.move_to(90.0) == 90.0  # and every later command is answered by its own reply


def test_message_ids_count_to_99_then_start_again_on_every_axis_of_the_connection():
    with start_zaber_emulator(axes=2, **FAST) as h, driver(h.port_path, tilt_axis=2) as tt:
        # open: /1 0 0, limit.min 1, limit.max 2; the tilt axis: /1 0 3, get pos 4, limits 5, 6
        for _ in range(93):
            tt.position()
        tt.tilt.position()  # id 0 again
        tt.position()
        assert h.emulator.received[:7] == [
            b"/1 0 0", b"/1 1 1 get limit.min", b"/1 1 2 get limit.max",
            b"/1 0 3", b"/1 2 4 get pos", b"/1 2 5 get limit.min", b"/1 2 6 get limit.max",
        ]  # fmt: skip
        assert h.emulator.received[98:] == [
            b"/1 1 98 get pos",
            b"/1 1 99 get pos",
            b"/1 2 0 get pos",
            b"/1 1 1 get pos",
        ]


def test_rejected_command_raises_and_the_next_one_works(emu):
    with driver(emu.port_path) as tt:
        tt.home()
        emu.emulator.inject("reject")
        with pytest.raises(DeviceRejected, match=r"'move abs 384000' rejected: BADDATA"):
            tt.move_to(90.0)
        assert tt.move_to(90.0) == 90.0


def test_the_device_travel_read_at_open_bounds_every_move():
    """limit.max of 180° on the device: 270° is refused by the driver, naming device, value and
    range, and never reaches the device (which would answer RJ BADDATA)."""
    with start_zaber_emulator(limit_max=round(180 * MSPD), **FAST) as h, driver(h.port_path) as tt:
        assert tt.device_travel_range() == Range(0.0, 180.0, "°", "device limit.min/limit.max")
        travel = tt.travel_range()
        assert (travel.minimum, travel.maximum) == (0.0, 180.0) == tt.limits
        assert travel.source == "configured limits within device limit.min/limit.max"
        n = len(h.emulator.received)
        with pytest.raises(OutOfRange) as err:
            tt.move_to(270.0)
        assert str(err.value) == (
            f"{tt.name}: move to 270° is outside the range [0, 180]°"
            " (configured limits within device limit.min/limit.max); nothing was sent"
        )
        assert isinstance(err.value, DeviceRejected) and isinstance(err.value, ValueError)
        assert (err.value.value, err.value.minimum, err.value.maximum) == (270.0, 0.0, 180.0)
        assert len(h.emulator.received) == n
        reply = tt.command("fly")
        assert not reply.ok and reply.data == "BADCOMMAND"
        assert tt.move_to(170.0) == pytest.approx(170.0, abs=1e-3)
        assert tt.command(f"move abs {round(270 * MSPD)}").data == "BADDATA"  # what the driver spared us


def test_configured_limits_narrow_the_travel_and_are_refused_before_sending(emu):
    with driver(emu.port_path, limits=(0.0, 180.0)) as tt:
        assert tt.device_travel_range() == Range(0.0, 360.0, "°", "device limit.min/limit.max")
        assert tt.travel_range() == Range(0.0, 180.0, "°", "configured limits")
        n = len(emu.emulator.received)
        with pytest.raises(OutOfRange, match=r"move to 200° is outside the range \[0, 180\]° \(configured limits\)"):
            tt.move_to(200.0)
        assert len(emu.emulator.received) == n


def test_limits_outside_the_device_travel_fail_at_open():
    with start_zaber_emulator(limit_max=round(90 * MSPD), **FAST) as h:
        tt = driver(h.port_path, limits=(100.0, 200.0))
        with pytest.raises(DeviceRejected, match=r"configured limits \[100, 200\]° lie outside the device's travel"):
            tt.open()
        assert not tt.transport.is_open


def test_a_device_without_limit_settings_keeps_the_configured_limits():
    script = [
        (b"/1 0 0\n", b"@01 0 00 OK IDLE -- 0\r\n"),
        (b"/1 1 1 get limit.min\n", b"@01 1 01 RJ IDLE -- BADCOMMAND\r\n"),
    ]
    with ScriptedDevice(script, name="zaber") as dev:
        with driver(dev.port, limits=(-10.0, 370.0)) as tt:
            assert tt.device_travel_range() is None
            assert tt.travel_range() == Range(-10.0, 370.0, "°", "configured limits")


def test_emulator_answers_the_limit_settings_like_the_device():
    sent = bytearray()
    emu = ZaberEmulator(limit_min=-1000, limit_max=768000)
    emu.server = type("Wire", (), {"write": staticmethod(sent.extend)})()
    for line in (b"/1 1 get limit.min\n", b"/1 1 get limit.max\n", b"/1 1 get limit.cycle\n"):
        emu.on_bytes(line, time.monotonic())
    assert bytes(sent) == (b"@01 1 OK IDLE WR -1000\r\n@01 1 OK IDLE WR 768000\r\n@01 1 RJ IDLE WR BADCOMMAND\r\n")


@pytest.mark.parametrize(
    "flag, meaning", [("FS", "stalled and stopped"), ("WL", "unexpected limit trigger"), ("FQ", "encoder error")]
)
def test_fault_flag_raises_and_clearing_warnings_recovers(emu, flag, meaning):
    with driver(emu.port_path) as tt:
        tt.home()
        emu.emulator.inject("stall", at=0.4, flag=flag)
        t0 = time.monotonic()
        with pytest.raises(DeviceFault, match=rf"move to 180.0° stopped at .*warning {flag} \({meaning}\)"):
            tt.move_to(180.0, timeout=60.0)
        assert time.monotonic() - t0 < 20.0  # at the stall, not at the move's timeout
        stopped = tt.position()
        assert 0.0 < stopped < 180.0
        assert tt.status()["warnings"] == [flag] and tt.status()["fault"]
        with pytest.raises(DeviceFault, match=flag):  # the flag stays until cleared
            tt.move_to(180.0)
        tt.close()
        tt.open()  # a faulted device can still be opened, to recover it
        assert tt.recover() == [flag]
        assert tt.move_to(180.0) == 180.0
        assert tt.status()["warnings"] == []


def test_move_that_does_not_finish_times_out_and_stops_the_stage():
    with start_zaber_emulator(speed_deg_s=90.0, accel_deg_s2=900.0) as h, driver(h.port_path) as tt:
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeout, match=r"move to 270.0° not finished within 0.30 s .*stage stopped"):
            tt.move_to(270.0, timeout=0.3)
        assert time.monotonic() - t0 < 2.5  # the move itself takes over 3 s
        st = tt.status()
        assert not st["busy"] and 0.0 < st["position"] < 270.0


def test_alerts_and_checksums_from_the_emulator_do_not_disturb_the_driver():
    with start_zaber_emulator(alerts=True, checksums=True, **FAST) as h, driver(h.port_path) as tt:
        tt.home()
        assert tt.move_to(90.0) == 90.0
        tt.position()  # reads past the alert sent when the move ended
        assert tt.alerts and tt.alerts[-1] == "!01 1 IDLE --"


def test_emulator_ignores_other_addresses_and_refuses_other_axes(emu):
    with pytest.raises(DeviceTimeout, match="no reply to '/2 0 0'"):
        driver(emu.port_path, reply_timeout=0.2, device=2).open()
    with driver(emu.port_path, axis=2) as tt:
        with pytest.raises(DeviceRejected, match="BADAXIS"):
            tt.position()


# -- configuration -------------------------------------------------------------


def test_from_config_through_the_registry(emu):
    tt = open_turntable(
        {
            "driver": "zaber",
            "port": emu.port_path,
            "device_address": 1,
            "steps_per_degree": MSPD / 2,
            "limits": [0, 720],
            "poll_interval": 0.005,
        }
    )
    assert isinstance(tt, ZaberTurntable) and tt.limits == (0.0, 720.0)
    with tt:
        tt.home()
        assert tt.move_to(450.0) == pytest.approx(450.0, abs=1e-9)
        assert emu.emulator.position_steps(time.monotonic()) == round(225 * MSPD)


@pytest.mark.parametrize(
    "cfg, message",
    [
        ({"driver": "zaber"}, "missing config key 'port'"),
        ({"driver": "zaber", "port": "/dev/null", "speed": 3}, "unknown config key 'speed'"),
        ({"driver": "zaber", "port": "x", "steps_per_degree": 1, "microsteps_per_degree": 1}, "not both"),
        ({"driver": "zaber", "port": "x", "limits": [10, 0]}, "min < max"),
    ],
)
def test_bad_config_names_the_problem(cfg, message):
    with pytest.raises(ValueError, match=message):
        open_turntable(cfg)


def test_unopenable_port_and_url_ports():
    with pytest.raises(DeviceDisconnected, match="cannot open /nonexistent/tty"):
        ZaberTurntable("/nonexistent/tty").open()
    # any pyserial URL opens; loop:// echoes the command, which is no Zaber reply
    with pytest.raises(ProtocolError, match=r"not a Zaber ASCII message: b'/1 0 0'"):
        driver("loop://").open()


@pytest.mark.parametrize(
    "url, problem",
    [
        ("loop://?logging=bogus", "logging='bogus': expected one of debug, info, warning, error"),
        ("socket://localhost:http", "expected socket://HOST:PORT (PORT a number from 0 to 65535)"),
        ("socket://localhost", "expected socket://HOST:PORT (PORT a number from 0 to 65535)"),
        ("socket://localhost:70000", "expected socket://HOST:PORT (PORT a number from 0 to 65535)"),
        ("rfc2217://[::1:4000", "expected rfc2217://HOST:PORT (PORT a number from 0 to 65535)"),
        ("socket://localhost:4000?speed=9600", "unknown option 'speed'; a socket:// URL takes logging"),
    ],
)
def test_a_malformed_url_port_says_what_is_wrong_with_it(url, problem):
    """Before, pyserial's own check of these URLs failed formatting its message: loop://?logging=bogus was a
    KeyError out of open() (harp: 'internal error'), socket://localhost:http said only
    ''debug|info|warning|error''."""
    with pytest.raises(DeviceDisconnected) as err:
        ZaberTurntable(url).open()
    assert str(err.value) == f"zaber {url} device 1 axis 1: cannot open {url}: not a valid URL: {problem}"


def test_emulator_fault_names_are_checked():
    with pytest.raises(ValueError, match="unknown fault 'explode'"):
        ZaberEmulator().inject("explode")


def test_reply_parsing_with_message_id_and_garbage():
    tt = ZaberTurntable("loop://")
    reply = tt.parse_line(b"@01 1 05 OK BUSY FS 12\r")
    assert (reply.device, reply.axis, reply.message_id, reply.ok, reply.busy, reply.warning, reply.data) == (
        1,
        1,
        5,
        True,
        True,
        "FS",
        "12",
    )
    assert tt.parse_line(b"@01 0 RJ IDLE -- BADCOMMAND").ok is False
    with pytest.raises(ProtocolError, match=r"not a Zaber ASCII message: b'@01 1 OK'"):
        tt.parse_line(b"@01 1 OK")


# -- the tilt axis (issue 23: the board tilted by a second axis of the stage) ----------------------------


def test_tilt_axis_bytes():
    """``tilt_axis=2``: the second axis of the same device on the same connection, checked at open (its
    position, its travel) and moved like the first; its configured limits (default 0..60°) refuse a
    move before anything is sent."""
    script = [
        (b"/1 0 0\n", b"@01 0 00 OK IDLE -- 0\r\n"),
        *LIMITS,
        (b"/1 0 3\n", b"@01 0 03 OK IDLE -- 0\r\n"),
        (b"/1 2 4 get pos\n", b"@01 2 04 OK IDLE -- 0\r\n"),
        (b"/1 2 5 get limit.min\n", b"@01 2 05 OK IDLE -- 0\r\n"),
        (b"/1 2 6 get limit.max\n", b"@01 2 06 OK IDLE -- 384000\r\n"),
        (b"/1 2 7 move abs 128000\n", b"@01 2 07 OK BUSY -- 0\r\n"),
        (b"/1 2 8 get pos\n", b"@01 2 08 OK BUSY -- 64000\r\n"),
        (b"/1 2 9 get pos\n", b"@01 2 09 OK IDLE -- 128000\r\n"),
        (b"/1 1 10 move abs 192000\n", b"@01 1 10 OK BUSY -- 0\r\n"),
        (b"/1 1 11 get pos\n", b"@01 1 11 OK IDLE -- 192000\r\n"),
    ]
    with ScriptedDevice(script, name="zaber") as dev:
        with driver(dev.port, tilt_axis=2) as tt:
            assert tt.tilt is not None and tt.tilt.travel_range().maximum == 60.0
            assert tt.tilt.move_to(30.0) == pytest.approx(30.0, abs=1e-12)
            with pytest.raises(OutOfRange):
                tt.tilt.move_to(70.0)
            assert tt.move_to(45.0) == pytest.approx(45.0, abs=1e-12)


def test_tilt_axis_on_the_emulator_tilts_the_simulated_board():
    world = SimWorld()
    assert world.tilt_at() is None  # no axis tilts the board: the camera's wedge
    with start_zaber_emulator(world=world, axes=2, **FAST) as h, driver(h.port_path, tilt_axis=2) as tt:
        assert world.tilt_at() == 0.0
        tt.home()
        got = tt.tilt.move_to(25.0)
        assert got == pytest.approx(25.0, abs=0.5 / MSPD) and world.tilt_at() == pytest.approx(got, abs=1e-9)
        assert tt.move_to(90.0) == pytest.approx(90.0, abs=0.5 / MSPD) and world.tilt_at() == pytest.approx(got)
        assert tt.tilt.position() == got
        with pytest.raises(DeviceRejected, match="BADDATA"):  # beyond the device's travel (0..90°)
            tt.tilt._check(tt.tilt.command("move abs 999999999"), "move abs")  # the driver's limits bypassed


def test_a_tilt_axis_the_device_does_not_have_fails_at_open(emu):
    with pytest.raises(DeviceRejected, match="tilt axis 2: 'get pos' rejected: BADAXIS"):
        driver(emu.port_path, tilt_axis=2).open()
    with pytest.raises(ValueError, match="tilt_axis must be another axis than axis 1"):
        driver(emu.port_path, tilt_axis=1)


# -- the shift axis (issue 19: a linear stage carries the turntable sideways between groups of shots) ------

MSPMM = 1.0 / 0.047625e-3  # Zaber X-LSM: 0.047625 um per microstep


def test_shift_axis_bytes_and_millimetres():
    """``shift_axis=3``: another axis of the same device on the same connection, checked at open like the
    tilt axis; positions in mm (``shift_microsteps_per_mm``, default an X-LSM's), its configured limits
    (default 0..100 mm) narrowed to the travel the device reports (here 50 mm), and every message in mm."""
    script = [
        (b"/1 0 0\n", b"@01 0 00 OK IDLE -- 0\r\n"),
        *LIMITS,
        (b"/1 0 3\n", b"@01 0 03 OK IDLE -- 0\r\n"),
        (b"/1 3 4 get pos\n", b"@01 3 04 OK IDLE -- 0\r\n"),
        (b"/1 3 5 get limit.min\n", b"@01 3 05 OK IDLE -- 0\r\n"),
        (b"/1 3 6 get limit.max\n", b"@01 3 06 OK IDLE -- 1049869\r\n"),  # 50.00001 mm
        (b"/1 3 7 move abs 209974\n", b"@01 3 07 OK BUSY -- 0\r\n"),  # 10 mm = 209973.75 microsteps
        (b"/1 3 8 get pos\n", b"@01 3 08 OK BUSY -- 104987\r\n"),
        (b"/1 3 9 get pos\n", b"@01 3 09 OK IDLE -- 209974\r\n"),
        (b"/1 3 10 move abs 104987\n", b"@01 3 10 OK BUSY -- 0\r\n"),  # 5 mm
        (b"/1 3 11 get pos\n", b"@01 3 11 OK IDLE FS 52493\r\n"),  # stalled half-way
    ]
    with ScriptedDevice(script, name="zaber") as dev:
        with driver(dev.port, shift_axis=3) as tt:
            assert tt.tilt is None and tt.shift is not None and tt.shift.name == f"{tt.name} shift axis 3"
            assert tt.shift.travel_range() == Range(0.0, 1049869 / MSPMM, "mm", "configured limits within device "
                                                    "limit.min/limit.max")  # fmt: skip
            assert tt.shift.move_to(10.0) == pytest.approx(209974 / MSPMM, abs=1e-12)
            with pytest.raises(
                OutOfRange, match=r"shift axis 3: move to 60 mm is outside the range \[0, 50\.00\d+\] mm"
            ):
                tt.shift.move_to(60.0)
            with pytest.raises(DeviceFault, match=r"move to 5.0 mm stopped at 2.5000 mm: warning FS"):
                tt.shift.move_to(5.0)


def test_shift_axis_on_the_emulator_moves_the_simulated_turntable_sideways():
    """Axis 3 of a three-axis emulator drives the world's shift (mm) as its own motion; the turntable and
    the tilt axis move independently of it."""
    world = SimWorld()
    assert world.shift_at() is None  # no linear axis
    with (
        start_zaber_emulator(world=world, axes=3, **FAST) as h,
        driver(h.port_path, tilt_axis=2, shift_axis=3) as tt,
    ):
        assert world.shift_at() == 0.0 and world.tilt_at() == 0.0
        tt.home()
        got = tt.shift.move_to(12.5)
        assert got == pytest.approx(12.5, abs=0.5 / MSPMM) and world.shift_at() == pytest.approx(got, abs=1e-9)
        assert tt.move_to(90.0) == pytest.approx(90.0, abs=0.5 / MSPD) and tt.tilt.move_to(10.0)
        assert world.shift_at() == pytest.approx(got, abs=1e-9) and tt.shift.position() == got
        assert world.stage_deg == pytest.approx(90.0, abs=1e-6) and world.tilt_at() == pytest.approx(
            10.0, abs=0.5 / MSPD
        )
        assert tt.shift.travel_range().maximum == 100.0  # the emulated X-LSM100A's travel: 0..100 mm
        with pytest.raises(DeviceRejected, match="BADDATA"):  # beyond the device's travel
            tt.shift._check(tt.shift.command("move abs 999999999"), "move abs")
    # a shift axis alone (no tilt): the board keeps the camera's wedge
    world = SimWorld()
    with (
        start_zaber_emulator(world=world, axes=3, tilt_axis=None, **FAST) as h,
        driver(h.port_path, shift_axis=3) as tt,
    ):
        assert world.tilt_at() is None and tt.shift.move_to(1.0) == pytest.approx(1.0, abs=0.5 / MSPMM)


def test_a_shift_axis_the_device_does_not_have_or_already_used_is_refused(emu):
    with pytest.raises(DeviceRejected, match="shift axis 3: 'get pos' rejected: BADAXIS"):
        driver(emu.port_path, shift_axis=3).open()
    with pytest.raises(ValueError, match="shift_axis must be another axis than axis 1, got 1"):
        driver(emu.port_path, shift_axis=1)
    with pytest.raises(ValueError, match="shift_axis must be another axis than axis 2, got 2"):
        driver(emu.port_path, tilt_axis=2, shift_axis=2)
    with pytest.raises(ValueError, match="config key 'shift_microsteps_per_mm'"):
        ZaberTurntable.from_config({"port": "x", "shift_axis": 3, "shift_microsteps_per_mm": 0})
    with pytest.raises(ValueError, match="tilt_axis and shift_axis must be different axes, both are 2"):
        ZaberEmulator(axes=2, shift_axis=2)
