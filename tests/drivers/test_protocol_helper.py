"""The byte-exact protocol helper: passes the exact exchange, fails precisely otherwise."""

import pytest
import serial

from drivers.errors import DeviceTimeout
from drivers.testing import ScriptedDevice, expect_exchange, first_difference
from drivers.zaber import ZaberTurntable

SCRIPT = [
    (b"/1\n", b"@01 0 OK IDLE -- 0\r\n"),
    (b"/1 1 get pos\n", b"@01 1 OK IDLE -- 42\r\n"),
    (b"?", b"<Idle|MPos:1.000,0.000,0.000|FS:0,0>\r\n"),
]


def _open(port):
    return serial.Serial(port, 115200, timeout=0.3)


def _talk(ser, data, expect_reply=True):
    ser.write(data)
    ser.flush()
    return ser.readline() if expect_reply else b""


def test_exact_exchange_passes_and_replies_byte_exact():
    with ScriptedDevice(SCRIPT, name="zaber") as dev:
        with _open(dev.port) as ser:
            assert _talk(ser, b"/1\n") == b"@01 0 OK IDLE -- 0\r\n"
            assert _talk(ser, b"/1 1 get pos\n") == b"@01 1 OK IDLE -- 42\r\n"
            assert _talk(ser, b"?") == b"<Idle|MPos:1.000,0.000,0.000|FS:0,0>\r\n"
    assert dev.steps_done == 3


def test_mismatch_reports_step_and_first_wrong_byte():
    with pytest.raises(AssertionError) as err:
        with ScriptedDevice(SCRIPT, name="zaber") as dev:
            with _open(dev.port) as ser:
                _talk(ser, b"/1\n")
                ser.write(b"/1 1 get pis\n")
                ser.flush()
                assert ser.readline() == b""  # the device stops answering after a wrong byte
    msg = str(err.value)
    assert "step 2/3" in msg
    assert "first difference at byte 10" in msg
    assert "expected b'o', got b'i'" in msg
    assert "b'/1 1 get pos\\n'" in msg


def test_missing_message_is_a_failure():
    dev = ScriptedDevice(SCRIPT, name="zaber")
    with pytest.raises(AssertionError, match=r"missing message at step 3/3: expected b'\?' never sent"):
        with dev:
            with _open(dev.port) as ser:
                _talk(ser, b"/1\n")
                _talk(ser, b"/1 1 get pos\n")


def test_extra_message_is_a_failure():
    with pytest.raises(AssertionError, match=r"extra message after the last step \(1\): b'/1 1 home\\n'"):
        with ScriptedDevice(SCRIPT[:1], name="zaber") as dev:
            with _open(dev.port) as ser:
                _talk(ser, b"/1\n")
                ser.write(b"/1 1 home\n")
                ser.flush()


def test_truncated_message_is_reported_as_missing_with_partial_bytes():
    with pytest.raises(AssertionError, match=r"step 2/3.*got only b'/1 1 get'"):
        with ScriptedDevice(SCRIPT, name="zaber") as dev:
            with _open(dev.port) as ser:
                _talk(ser, b"/1\n")
                ser.write(b"/1 1 get")
                ser.flush()


def test_mismatch_wins_over_the_driver_timeout_it_causes():
    # The script expects a different target; the driver's own DeviceTimeout
    # is replaced by the precise mismatch report (and chained to it).
    script = [
        (b"/1 0 0\n", b"@01 0 00 OK IDLE -- 0\r\n"),
        (b"/1 1 1 get limit.min\n", b"@01 1 01 OK IDLE -- 0\r\n"),
        (b"/1 1 2 get limit.max\n", b"@01 1 02 OK IDLE -- 1536000\r\n"),
        (b"/1 1 3 move abs 192001\n", b"@01 1 03 OK BUSY -- 0\r\n"),
    ]
    with pytest.raises(AssertionError) as err:
        with expect_exchange(script, name="zaber") as dev:
            with ZaberTurntable(dev.port, reply_timeout=0.3) as tt:
                tt.move_to(45.0)
    assert "step 4/4" in str(err.value) and "first difference at byte 21" in str(err.value)
    assert isinstance(err.value.__cause__, DeviceTimeout)


def test_script_is_validated():
    with pytest.raises(TypeError, match="step 1"):
        ScriptedDevice([(b"/1\n", b""), ("text", b"")])
    with pytest.raises(ValueError, match="step 0"):
        ScriptedDevice([(b"", b"x")])


def test_first_difference():
    assert first_difference(b"abc", b"abc") is None
    assert first_difference(b"abc", b"abd") == 2
    assert first_difference(b"abc", b"ab") == 2
    assert first_difference(b"ab", b"abc") == 2
