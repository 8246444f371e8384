"""V4L2Camera through real linuxpy, with only the ioctl and mmap layer faked.

The fake (tests/drivers/fake_v4l2.py) answers the V4L2 ioctls like a UVC
camera and signals finished buffers through a real FIFO, so linuxpy's own
code (structures, control enumeration, buffer queue, ``select``) runs
unchanged. Frames carry an exactly known pattern keyed by their sequence
number.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from linuxpy.video.device import ControlID

import drivers
from drivers.errors import CaptureError, DeviceDisconnected, DeviceRejected, DeviceTimeout, DriverError, OutOfRange
from drivers.protocols import CameraRanges, Range
from drivers.v4l2_camera import V4L2Camera
from tests.drivers.fake_v4l2 import FakeV4L2Camera

W, H = 64, 48


@pytest.fixture
def node(tmp_path):
    return tmp_path / "video0"


def camera(node, **cfg) -> V4L2Camera:
    return V4L2Camera.from_config({"driver": "v4l2", "device": str(node), "width": W, "height": H, **cfg})


@pytest.mark.parametrize(
    "fmt, padding, bits",
    [
        ("GREY", 0, 8),
        ("GREY", 24, 8),
        ("Y16", 0, 16),
        ("Y16", 8, 16),
        ("YUYV", 0, 8),
        ("YUYV", 4, 8),
        ("Y10", 0, 10),
        ("Y10", 6, 10),
        ("Y12", 10, 12),
        ("Y10P", 0, 10),
        ("Y10P", 3, 10),
        ("Y12P", 7, 12),
    ],
)
def test_uncompressed_formats_give_the_exact_grey_image(node, fmt, padding, bits):
    """The grey formats; ``Y10``/``Y12`` (the values in the low bits of little-endian 16-bit words) read as the words
    are, 0..1023 / 0..4095 (as the unpacked Bayer ``BA10``); MIPI CSI-2 packed ``Y10P``/``Y12P`` (a mono Raspberry
    Pi camera) unpacked to the 10/12-bit values the scene holds, which the fake packs with the independent packer of
    tests/drivers/packing.py. Rows padded to ``bytesperline`` with 0xEE bytes that must not reach the image."""
    offered = {"formats": ("GREY", fmt)} if fmt in ("Y10", "Y12", "Y10P", "Y12P") else {}
    with FakeV4L2Camera(node, stride_padding=padding, **offered) as hw, camera(node, pixel_format=fmt) as cam:
        assert cam.pixel_format == fmt and cam.sensor_size == (W, H)
        f = cam.capture(timeout=1.0)
        assert f.image.dtype == (np.uint8 if bits == 8 else np.uint16)
        assert np.array_equal(f.image, hw.scene(f.extra["sequence"], W, H, bits=bits))
        assert f.extra["pixel_format"] == fmt


@pytest.mark.parametrize(
    "fmt, pattern, bits, padding",
    [
        ("RGGB", "RGGB", 8, 0), ("BA81", "BGGR", 8, 6), ("BA10", "GRBG", 10, 4), ("BYR2", "BGGR", 16, 0),
        # MIPI CSI-2 packed, rows padded beyond the packed row (bytesperline)
        ("pRAA", "RGGB", 10, 0), ("pgAA", "GRBG", 10, 3), ("pGAA", "GBRG", 10, 16), ("pBAA", "BGGR", 10, 1),
        ("pRCC", "RGGB", 12, 0), ("pgCC", "GRBG", 12, 5), ("pGCC", "GBRG", 12, 2), ("pBCC", "BGGR", 12, 32),
    ],
)  # fmt: skip
def test_a_bayer_sensor_delivers_its_raw_mosaic_with_the_pattern_named(node, fmt, pattern, bits, padding):
    """A colour sensor's raw Bayer format: the frame is the mosaic the device wrote (row padding dropped,
    nothing demosaiced or greyed; a packed one unpacked to the 10/12-bit values the scene holds, which the fake
    packs with the independent packer of tests/drivers/packing.py) and ``extra["cfa"]`` names its pattern as the
    V4L2 fourcc says."""
    with (
        FakeV4L2Camera(node, formats=("GREY", fmt), stride_padding=padding) as hw,
        camera(node, pixel_format=fmt) as cam,
    ):
        f = cam.capture(timeout=1.0)
    assert f.image.dtype == (np.uint8 if bits == 8 else np.uint16) and f.image.shape == (H, W)
    assert np.array_equal(f.image, hw.scene(f.extra["sequence"], W, H, bits=bits))
    assert f.extra["cfa"] == pattern and f.extra["pixel_format"] == fmt


def test_a_grey_frame_names_no_pattern(node):
    with FakeV4L2Camera(node) as hw, camera(node, pixel_format="GREY") as cam:
        f = cam.capture(timeout=1.0)
    assert "cfa" not in f.extra and np.array_equal(f.image, hw.scene(f.extra["sequence"], W, H))


def test_mjpg_frame_is_decoded_to_grey(node):
    with FakeV4L2Camera(node) as hw, camera(node, pixel_format="MJPG") as cam:
        f = cam.capture(timeout=1.0)
        assert f.image.shape == (H, W) and f.image.dtype == np.uint8
        truth = hw.smooth_scene(f.extra["sequence"], W, H).astype(int)
        assert np.abs(f.image.astype(int) - truth).max() <= 3  # JPEG q95 of a smooth image


def test_format_selection_sends_s_fmt_and_reads_back_the_adjusted_size(node):
    with FakeV4L2Camera(node, max_size=(320, 240)) as hw:
        with V4L2Camera(str(node), pixel_format="Y16", width=1000, height=1000) as cam:
            assert cam.sensor_size == (320, 240)  # the driver clamped the request
            assert cam.capture(timeout=1.0).image.shape == (240, 320)
        assert "S_FMT" in hw.calls and hw.pixelformat == 540422489  # 'Y16 '


def test_format_not_offered_is_rejected_and_nothing_left_open(node):
    with FakeV4L2Camera(node, formats=("YUYV", "MJPG")) as hw:
        cam = camera(node, pixel_format="GREY")
        with pytest.raises(DeviceRejected, match="GREY not offered .*YUYV, MJPG"):
            cam.open()
        assert not cam.is_open and not hw.streaming and "S_FMT" not in hw.calls


def test_exposure_switches_auto_exposure_to_manual(node):
    with FakeV4L2Camera(node) as hw, camera(node) as cam:
        assert hw.value(ControlID.EXPOSURE_AUTO) == 3  # aperture priority: exposure control inactive
        assert cam.set_exposure(20_000) == 20_000.0
        assert hw.value(ControlID.EXPOSURE_AUTO) == 1
        assert hw.value(ControlID.EXPOSURE_ABSOLUTE) == 200  # units of 100 µs
        assert cam.set_exposure(12_345) == 12_300.0  # read back what the device holds
        assert cam.capture(timeout=1.0).exposure_us == 12_300.0
        n = hw.calls.count("S_EXT_CTRLS")
        with pytest.raises(OutOfRange, match=r"exposure 300000 µs is outside the range \[300, 204700\] µs"):
            cam.set_exposure(300_000)
        assert hw.calls.count("S_EXT_CTRLS") == n  # refused before anything reached the device
        assert hw.value(ControlID.EXPOSURE_ABSOLUTE) == 123


def test_writing_an_inactive_control_fails_like_uvcvideo(node):
    # guards the fake's realism: without switching auto exposure off first, the write is refused
    with FakeV4L2Camera(node) as hw, camera(node) as cam:
        with pytest.raises(DeviceRejected, match="Permission denied"):
            cam._write(cam._ctrl["exposure"], 100)
        assert hw.value(ControlID.EXPOSURE_ABSOLUTE) == 156


def test_gain_in_db_per_unit(node):
    with FakeV4L2Camera(node) as hw, camera(node, gain_db_per_unit=0.5) as cam:
        assert cam.set_gain(7.0) == 7.0
        assert hw.value(ControlID.GAIN) == 14
        with pytest.raises(OutOfRange, match=r"gain 101 dB is outside the range \[0, 50\] dB \(V4L2 gain\)"):
            cam.set_gain(101)


@pytest.mark.parametrize("old_names", [False, True])
def test_focus_lock_turns_continuous_autofocus_off(node, old_names):
    with FakeV4L2Camera(node, old_names=old_names) as hw, camera(node) as cam:
        names = {c.config_name for c in cam._dev.controls.values()}
        assert ("focus_auto" in names) == old_names and ("focus_automatic_continuous" in names) != old_names
        assert hw.value(ControlID.FOCUS_AUTO) == 1
        assert cam.lock_focus(102) == 100.0  # focus_absolute step is 5
        assert hw.value(ControlID.FOCUS_AUTO) == 0
        assert hw.value(ControlID.FOCUS_ABSOLUTE) == 100
        assert cam.capture(timeout=1.0).focus == 100.0
        with pytest.raises(OutOfRange, match=r"focus 300 is outside the range \[0, 250\] \(V4L2 focus_absolute\)"):
            cam.lock_focus(300)
        assert cam.get_focus() == 100.0 and hw.value(ControlID.FOCUS_ABSOLUTE) == 100


def test_ranges_are_the_controls_read_at_open(node):
    """The fake kernel's controls (tests/drivers/fake_v4l2.py): exposure 3..2047 x 100 µs,
    gain 0..100, focus_absolute 0..250 in steps of 5."""
    with FakeV4L2Camera(node), camera(node, gain_db_per_unit=0.25) as cam:
        assert isinstance(cam, CameraRanges)
        assert cam.exposure_range() == Range(300.0, 204_700.0, "µs", "V4L2 exposure_time_absolute")
        assert cam.gain_range() == Range(0.0, 25.0, "dB", "V4L2 gain")
        focus = cam.focus_range()
        assert focus == Range(0.0, 250.0, "", "V4L2 focus_absolute", step=5.0) and focus.tolerance() == 2.5
        got = cam.lock_focus(117)  # rounded by the control to its step: read back within the tolerance
        assert got == 115.0 and abs(got - 117) <= focus.tolerance()
    cam = camera(node)
    with pytest.raises(DriverError, match="not open"):
        cam.focus_range()


def test_settings_from_config_are_applied_at_open(node):
    with FakeV4L2Camera(node) as hw, camera(node, exposure_us=5000, gain_db=3, focus=50):
        assert hw.value(ControlID.EXPOSURE_ABSOLUTE) == 50
        assert hw.value(ControlID.GAIN) == 3
        assert (hw.value(ControlID.FOCUS_AUTO), hw.value(ControlID.FOCUS_ABSOLUTE)) == (0, 50)


def test_zoom_absolute_is_driven_at_open_and_after(node):
    """A UVC zoom lens (zoom_absolute 100..500 in the fake kernel): the configured zoom is set at open,
    before the focus; set_zoom reads it back; outside its range OutOfRange; without the control one line."""
    from drivers.protocols import Zoomable

    with FakeV4L2Camera(node, with_zoom=True) as hw, camera(node, zoom=300, focus=50) as cam:
        assert isinstance(cam, Zoomable)
        assert hw.value(ControlID.ZOOM_ABSOLUTE) == 300 and cam.get_zoom() == 300.0
        assert cam.zoom_range() == Range(100.0, 500.0, "", "V4L2 zoom_absolute")
        assert cam.set_zoom(120.4) == 120.0 and hw.value(ControlID.ZOOM_ABSOLUTE) == 120
        with pytest.raises(OutOfRange, match=r"zoom 600 is outside the range \[100, 500\] \(V4L2 zoom_absolute\)"):
            cam.set_zoom(600)
    plain = node.with_name("video1")
    with FakeV4L2Camera(plain), camera(plain) as cam:
        assert cam.zoom_range() is None and cam.get_zoom() is None
        with pytest.raises(DeviceRejected, match="no zoom_absolute control"):
            cam.set_zoom(200)


def test_camera_without_focus_control(node):
    with FakeV4L2Camera(node, with_focus=False), camera(node) as cam:
        assert cam.get_focus() is None
        with pytest.raises(DeviceRejected, match="no focus_absolute control"):
            cam.lock_focus(10)
        assert cam.capture(timeout=1.0).focus is None


def test_capture_discards_frames_queued_before_the_call(node):
    with FakeV4L2Camera(node) as hw, camera(node, buffers=3, discard_frames=1) as cam:
        produced = hw.sequence  # frames already sitting in the queue
        f0 = cam.capture(timeout=1.0)
        assert f0.extra["sequence"] >= produced + 1  # never one exposed before capture() began
        f1 = cam.capture(timeout=1.0)
        assert f1.extra["sequence"] > f0.extra["sequence"] and (f0.counter, f1.counter) == (0, 1)
        assert np.array_equal(f1.image, hw.scene(f1.extra["sequence"], W, H))


def test_stalled_camera_times_out_then_recovers(node):
    with FakeV4L2Camera(node) as hw, camera(node) as cam:
        cam.capture(timeout=1.0)
        hw.stalled = True
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeout, match="no frame within 0.2 s"):
            cam.capture(timeout=0.2)
        assert 0.15 <= time.monotonic() - t0 < 10.0  # not hung on
        hw.resume()
        assert cam.capture(timeout=1.0).image.shape == (H, W)


def test_unplugged_camera_raises_disconnected(node):
    with FakeV4L2Camera(node) as hw, camera(node) as cam:
        hw.unplugged = True
        with pytest.raises(DeviceDisconnected, match="No such device"):
            cam.capture(timeout=0.5)


def test_close_stops_streaming_and_releases_buffers(node):
    with FakeV4L2Camera(node) as hw:
        cam = camera(node)
        with cam:
            cam.capture(timeout=1.0)
            assert hw.streaming and len(hw.buffers) == 2
        assert not hw.streaming and hw.buffers == []
        assert hw.calls[-2:] == ["STREAMOFF", "REQBUFS"]
        with pytest.raises(DriverError, match="not open"):
            cam.capture()


def test_missing_device_node(tmp_path):
    with pytest.raises(DeviceDisconnected, match="cannot open"):
        V4L2Camera(str(tmp_path / "video7")).open()


def test_from_config_rejects_unknown_key_and_registry_opens_it(node):
    with pytest.raises(ValueError, match="'exposure'"):
        V4L2Camera.from_config({"driver": "v4l2", "exposure": 100})
    with pytest.raises(ValueError, match="pixel_format"):
        V4L2Camera.from_config({"driver": "v4l2", "pixel_format": "RGB3"})
    cam = drivers.open_camera({"driver": "v4l2", "device": str(node)})
    assert isinstance(cam, V4L2Camera) and not cam.is_open


def test_a_buffer_that_does_not_hold_its_frame_is_one_line_naming_the_camera(node):
    """The device shrinks its frames behind the driver's back (half the rows it set at S_FMT): the capture fails
    with one line naming the camera, the format and the bytes missing, not a traceback from numpy."""
    with FakeV4L2Camera(node) as hw, camera(node, pixel_format="GREY") as cam:
        hw.height = H // 2
        with pytest.raises(CaptureError) as err:
            cam.capture(timeout=1.0)
    assert str(err.value) == (
        f"v4l2 camera {node}: GREY frame truncated: {W * H // 2} bytes for {W}x{H} (stride {W}) needs {W * H}"
    )
