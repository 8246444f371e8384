"""AravisCamera against Aravis' own fakes (real libaravis, no mocks).

* ``Fake_1``: the in-process Fake camera, with Aravis' embedded GenICam XML
  (older feature names ExposureTimeAbs / GainRaw) or with our
  ``drivers/data/fake-focus.xml`` (SFNC ExposureTime / Gain plus focus features);
* ``127.0.0.1``: ``Aravis.GvFakeCamera`` served on loopback, reached through
  the real GigE Vision control (GVCP) and stream (GVSP) protocols.

The fake fills frames with a diagonal ramp whose exact value is known::

    Mono8:  min(255,   ((x + y + frame_id) % 255)         * s)
    Mono16: min(65535, ((256 * (x + y + frame_id)) % 65535) * s)
    s = 1 + gain_raw + log10(exposure_us / 10000)

so the tests check pixel values (orientation, dtype, exposure and gain
reaching the sensor) exactly.
"""

from __future__ import annotations

import math
import os
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

import drivers
from drivers.aravis_camera import FAKE_FOCUS_XML, AravisCamera
from drivers.errors import CaptureError, DeviceRejected, DeviceTimeout, DriverError, OutOfRange
from drivers.protocols import CameraRanges, Range
from tests.drivers.aravis_fakes import FOCUS_CFG, gige_fake_camera

W, H = 64, 48


def expected_ramp(frame_id: int, exposure_us: float, gain_raw: int, fmt: str = "Mono8") -> np.ndarray:
    y, x = np.mgrid[0:H, 0:W]
    scale = 1.0 + gain_raw + math.log10(exposure_us / 10000.0)
    if fmt == "Mono8":
        return np.clip(((x + y + frame_id) % 255) * scale, 0, 255).astype(np.uint8)
    return np.clip(((256 * (x + y + frame_id)) % 65535) * scale, 0, 65535).astype(np.uint16)


def fake(**cfg) -> AravisCamera:
    return AravisCamera.from_config({"driver": "aravis", "device": "Fake_1", "roi": [0, 0, W, H], **cfg})


@pytest.fixture(scope="module")
def gige_fake():
    """Aravis' GigE Vision fake camera on 127.0.0.1, with the focus XML."""
    with gige_fake_camera("HARPGV01") as gv:
        yield gv


def test_embedded_fake_xml_uses_the_older_feature_names():
    with fake() as cam:
        assert (cam.exposure_feature, cam.gain_feature) == ("ExposureTimeAbs", "GainRaw")
        assert cam.identity.vendor == "Aravis" and cam.identity.model == "Fake"
        assert cam.sensor_size == (W, H) and cam.pixel_format == "Mono8"
        assert cam.set_exposure(100_000) == 100_000.0
        assert cam.set_gain(0.0) == 0.0
        f = cam.capture(timeout=2.0)
        # exposure x10 doubles the ramp (scale 2): the setting reached the sensor
        assert np.array_equal(f.image, expected_ramp(f.extra["frame_id"], 100_000, 0))
        assert cam.set_gain(1.4) == 1.0  # GainRaw is an integer: read back what was accepted
        f = cam.capture(timeout=2.0)
        assert f.gain_db == 1.0
        assert np.array_equal(f.image, expected_ramp(f.extra["frame_id"], 100_000, 1))


def test_gain_raw_scaled_to_db():
    with fake(gain_db_per_raw=0.5) as cam:
        assert cam.set_gain(3.0) == 3.0
        assert cam._device.get_integer_feature_value("GainRaw") == 6


def test_focus_xml_uses_sfnc_names_and_mono16_is_exact():
    with fake(pixel_format="Mono16", exposure_us=10_000, gain_db=0, **FOCUS_CFG) as cam:
        assert (cam.exposure_feature, cam.gain_feature) == ("ExposureTime", "Gain")
        assert cam.pixel_format == "Mono16"
        f = cam.capture(timeout=2.0)
        assert f.image.dtype == np.uint16 and f.image.shape == (H, W)
        assert np.array_equal(f.image, expected_ramp(f.extra["frame_id"], 10_000, 0, "Mono16"))
        assert f.exposure_us == 10_000.0 and f.gain_db == 0.0


def test_lock_focus_integer_feature_turns_enumeration_autofocus_off():
    with fake(**FOCUS_CFG) as cam:
        dev = cam._device
        dev.set_string_feature_value("FocusAuto", "Continuous")
        assert cam.lock_focus(417.4) == 417.0
        assert dev.get_string_feature_value("FocusAuto") == "Off"
        assert dev.get_integer_feature_value("FocusPosition") == 417
        assert cam.get_focus() == 417.0
        assert cam.capture(timeout=2.0).focus == 417.0


def test_lock_focus_float_feature_turns_boolean_autofocus_off():
    cfg = {
        "fake_genicam_xml": str(FAKE_FOCUS_XML),
        "focus_feature": "FocusDistance",
        "focus_type": "float",
        "autofocus_feature": "LensAutoFocusEnable",
    }
    with fake(**cfg) as cam:
        dev = cam._device
        dev.set_boolean_feature_value("LensAutoFocusEnable", True)
        assert cam.lock_focus(1234.5) == 1234.5
        assert dev.get_boolean_feature_value("LensAutoFocusEnable") is False
        assert dev.get_float_feature_value("FocusDistance") == 1234.5


def test_focus_from_config_is_locked_at_open():
    with fake(focus=250, **FOCUS_CFG) as cam:
        assert cam.get_focus() == 250.0


def test_genicam_zoom_is_driven_at_open_before_the_focus_and_after():
    """Our fake XML's Zoom (Integer 0..2000 at 0x8020, read from the XML itself for the bounds): the
    configured zoom is set at open; set_zoom reads it back; outside its bounds OutOfRange."""
    from drivers.protocols import Zoomable

    with fake(zoom=800, focus=250, **FOCUS_CFG) as cam:
        assert isinstance(cam, Zoomable)
        assert cam.get_zoom() == 800.0 and cam._device.get_integer_feature_value("Zoom") == 800
        lo, hi = _xml_bounds("Zoom")
        assert (cam.zoom_range().minimum, cam.zoom_range().maximum) == (lo, hi)
        assert cam.set_zoom(1500) == 1500.0
        with pytest.raises(OutOfRange, match=r"zoom 2500 is outside the range \[0, 2000\] \(GenICam Zoom\)"):
            cam.set_zoom(2500)
        assert cam.get_zoom() == 1500.0
    with fake() as cam:  # Aravis' own fake XML has no zoom
        assert cam.zoom_range() is None and cam.get_zoom() is None
        with pytest.raises(DeviceRejected, match="no numeric zoom feature 'Zoom'"):
            cam.set_zoom(10)


def _xml_bounds(name: str) -> tuple[float, float]:
    """Min and Max of a feature, read from the GenICam XML itself (not through Aravis)."""
    for node in ET.parse(FAKE_FOCUS_XML).getroot().iter():
        if node.get("Name") == name:
            return float(node.findtext("{*}Min", node.findtext("Min"))), float(
                node.findtext("{*}Max", node.findtext("Max"))
            )
    raise KeyError(name)


def test_ranges_are_the_genicam_bounds_read_at_open():
    with fake(**FOCUS_CFG) as cam:
        assert isinstance(cam, CameraRanges)
        assert cam.focus_range() == Range(*_xml_bounds("FocusPosition"), "", "GenICam FocusPosition")
        assert cam.exposure_range() == Range(*_xml_bounds("ExposureTime"), "µs", "GenICam ExposureTime")
        assert cam.gain_range() == Range(*_xml_bounds("Gain"), "dB", "GenICam Gain")
    with fake(gain_db_per_raw=0.5) as cam:  # the embedded XML: GainRaw in device units
        raw = cam._device.get_integer_feature_bounds("GainRaw")
        assert cam.gain_range() == Range(raw.min * 0.5, raw.max * 0.5, "dB", "GenICam GainRaw")
        assert cam.focus_range() is None  # no focus feature configured
    with pytest.raises(DriverError, match="not open"):
        cam.exposure_range()


def test_focus_out_of_range_is_refused_before_writing_and_unchanged():
    with fake(**FOCUS_CFG) as cam:
        cam.lock_focus(300)
        cam._device.set_string_feature_value("FocusAuto", "Continuous")
        with pytest.raises(OutOfRange) as err:
            cam.lock_focus(5000)
        assert str(err.value) == (
            "aravis camera Fake_1: focus 5000 is outside the range [0, 1000] (GenICam FocusPosition); nothing was sent"
        )
        assert cam.get_focus() == 300.0
        assert cam._device.get_string_feature_value("FocusAuto") == "Continuous"  # not even autofocus was touched


def test_exposure_and_gain_out_of_range_are_rejected():
    with fake(**FOCUS_CFG) as cam:
        cam.set_exposure(15_000)
        with pytest.raises(OutOfRange, match=r"exposure 5 µs is outside the range \[10, 10000000\] µs"):
            cam.set_exposure(5.0)  # min 10 µs
        with pytest.raises(OutOfRange, match=r"gain 50 dB is outside the range \[0, 10\] dB \(GenICam Gain\)"):
            cam.set_gain(50.0)  # max 10
        assert cam.get_exposure() == 15_000.0
        with pytest.raises(ValueError):
            cam.set_exposure(float("nan"))


def test_focus_without_configured_feature():
    with fake() as cam:
        assert cam.get_focus() is None
        with pytest.raises(DeviceRejected, match="no focus feature"):
            cam.lock_focus(10)


@pytest.mark.parametrize(
    "cfg, match",
    [
        ({"focus_feature": "NoSuchFocus"}, "NoSuchFocus"),
        ({"focus_feature": "FocusPosition", "focus_type": "float"}, "is integer"),
        ({"focus_feature": "FocusPosition", "autofocus_feature": "NoAF"}, "NoAF"),
        ({"pixel_format": "Mono12"}, "Mono12"),
    ],
)
def test_misconfiguration_fails_at_open_and_closes(cfg, match):
    cam = fake(fake_genicam_xml=str(FAKE_FOCUS_XML), **cfg)
    with pytest.raises(DeviceRejected, match=match):
        cam.open()
    assert not cam.is_open


def test_free_running_returns_a_frame_taken_after_the_call():
    with fake(trigger="off") as cam:  # embedded XML again, after tests that used the focus XML
        assert cam.exposure_feature == "ExposureTimeAbs"
        time.sleep(0.1)  # let the 25 fps fake queue frames
        t0 = time.time()
        f = cam.capture(timeout=2.0)
        assert f.timestamp >= t0
        assert np.array_equal(f.image, expected_ramp(f.extra["frame_id"], cam.get_exposure(), 0))


def test_gige_fake_over_loopback(gige_fake):
    cfg = {"device": "127.0.0.1", "exposure_us": 10_000, "gain_db": 1, **FOCUS_CFG}
    with fake(**cfg) as cam:
        assert cam.identity.serial == "HARPGV01"
        assert cam._camera.is_gv_device()
        assert cam.lock_focus(42) == 42.0
        f0 = cam.capture(timeout=2.0)
        f1 = cam.capture(timeout=2.0)
        assert (f0.counter, f1.counter) == (0, 1)
        assert f1.extra["frame_id"] == f0.extra["frame_id"] + 1  # one frame per software trigger
        for f in (f0, f1):
            assert np.array_equal(f.image, expected_ramp(f.extra["frame_id"], 10_000, 1))
            assert (f.exposure_us, f.gain_db, f.focus) == (10_000.0, 1.0, 42.0)


def test_gige_buffer_timeout_is_reported_not_hung_on(gige_fake):
    # hardware trigger on Line0 that never fires: no frame can arrive
    with fake(device="127.0.0.1", trigger="Line0", **FOCUS_CFG) as cam:
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeout, match=r"no frame within 0.3 s \(trigger Line0\)"):
            cam.capture(timeout=0.3)
        assert 0.25 <= time.monotonic() - t0 < 10.0  # not hung on


def test_capture_after_close_raises():
    cam = fake()
    with cam:
        cam.capture(timeout=2.0)
    with pytest.raises(DriverError, match="not open"):
        cam.capture()
    with pytest.raises(DriverError, match="not open"):
        cam.set_exposure(1000)


def test_from_config_rejects_unknown_key_and_registry_opens_it():
    with pytest.raises(ValueError, match="'exposure'"):
        AravisCamera.from_config({"driver": "aravis", "exposure": 100})
    with pytest.raises(ValueError, match="pixel_format"):
        AravisCamera.from_config({"driver": "aravis", "pixel_format": "RGB8"})
    cam = drivers.open_camera({"driver": "aravis", "device": "Fake_1"})
    assert isinstance(cam, AravisCamera) and not cam.is_open


def test_packaged_fake_xml_is_shipped():
    text = FAKE_FOCUS_XML.read_text()
    for feature in ("ExposureTime", "Gain", "FocusPosition", "FocusDistance", "FocusAuto"):
        assert f'Name="{feature}"' in text


def aravis_rendering(frame_id: int, fmt: str, exposure_us: int, gain_raw: int) -> np.ndarray:
    """Frame ``frame_id`` as Aravis' own fake renders it (a second, standalone ``Aravis.FakeCamera`` with the
    same registers, filled until its frame counter reaches ``frame_id``): the bytes the camera sent,
    independent of the driver's reading of them."""
    from drivers.aravis_camera import aravis_module

    Aravis = aravis_module()
    ref = Aravis.FakeCamera.new("REFERENCE")
    for register, value in (
        (Aravis.FAKE_CAMERA_REGISTER_WIDTH, W),
        (Aravis.FAKE_CAMERA_REGISTER_HEIGHT, H),
        (Aravis.FAKE_CAMERA_REGISTER_PIXEL_FORMAT, getattr(Aravis, f"PIXEL_FORMAT_BAYER_{fmt[5:7]}_8")),
        (Aravis.FAKE_CAMERA_REGISTER_EXPOSURE_TIME_US, exposure_us),
        (Aravis.FAKE_CAMERA_REGISTER_GAIN_RAW, gain_raw),
    ):
        assert ref.write_register(register, value)
    buf = Aravis.Buffer.new_allocate(ref.get_payload())
    for _ in range(70_000):  # the counter is 16 bits
        ref.fill_buffer(buf)
        if buf.get_frame_id() == frame_id:
            return np.frombuffer(buf.get_data(), np.uint8)[: W * H].reshape(H, W).copy()
    raise AssertionError(f"the reference fake never reached frame {frame_id}")


@pytest.mark.parametrize(
    "fmt, pattern", [("BayerRG8", "RGGB"), ("BayerGR8", "GRBG"), ("BayerGB8", "GBRG"), ("BayerBG8", "BGGR")]
)
def test_a_bayer_camera_delivers_its_raw_mosaic_with_the_pattern_named(fmt, pattern):
    """A colour GenICam camera (Aravis' fake offers the four 8-bit Bayer formats): the frame is the raw mosaic
    exactly as the camera sent it (nothing demosaiced, nothing converted to grey), and ``extra["cfa"]`` names
    its pattern as the PFNC name says (what the colour pipeline reads)."""
    with fake(pixel_format=fmt, exposure_us=10_000, gain_db=0) as cam:
        assert cam.pixel_format == fmt
        f = cam.capture(timeout=2.0)
    assert f.image.dtype == np.uint8 and f.image.shape == (H, W)
    assert f.extra["cfa"] == pattern and f.extra["pixel_format"] == fmt
    assert np.array_equal(f.image, aravis_rendering(f.extra["frame_id"], fmt, 10_000, 0))


def test_a_grey_camera_frame_names_no_pattern_and_a_bayer_format_the_camera_lacks_is_refused():
    with fake() as cam:
        assert "cfa" not in cam.capture(timeout=2.0).extra
    with pytest.raises(DriverError) as err:
        fake(pixel_format="BayerRG16").open()
    assert "\n" not in str(err.value) and "BayerRG16" in str(err.value), err.value
    with pytest.raises(ValueError, match=r"a raw Bayer format \(BayerGR8\) needs an even width and height"):
        AravisCamera.from_config(
            {"driver": "aravis", "device": "Fake_1", "pixel_format": "BayerGR8", "roi": [0, 0, 63, 48]}
        )


def test_the_embedded_xml_written_to_switch_back_is_removed_when_the_process_ends(tmp_path):
    """Going back from our XML to Aravis' embedded one writes the embedded XML to a temporary file (Aravis
    cannot be reset to it otherwise); the process that wrote it removes it when it ends: a test suite or a
    station that opens both kinds of fake leaves nothing in the temporary directory."""
    import subprocess
    import sys

    script = (
        "from drivers.aravis_camera import AravisCamera, FAKE_FOCUS_XML\n"
        "import glob, tempfile\n"
        "for xml in (str(FAKE_FOCUS_XML), None):\n"
        "    cfg = {'driver': 'aravis', 'device': 'Fake_1', 'roi': [0, 0, 64, 48]}\n"
        "    cfg.update({'fake_genicam_xml': xml} if xml else {})\n"
        "    with AravisCamera.from_config(cfg) as cam:\n"
        "        cam.capture(timeout=2.0)\n"
        "        print(cam.exposure_feature)\n"
        "print(len(glob.glob(tempfile.gettempdir() + '/harp-arv-fake-*.xml')))\n"
    )
    root = str(Path(drivers.__file__).resolve().parents[1])
    env = {**os.environ, "TMPDIR": str(tmp_path), "PYTHONPATH": root}
    out = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=60, check=True
    ).stdout.split()
    # our XML's SFNC name, then the embedded XML's older one: the switch back really happened, from one file
    assert out == ["ExposureTime", "ExposureTimeAbs", "1"]
    assert list(tmp_path.glob("harp-arv-fake-*.xml")) == []


# The codes of the packed formats, copied from the standards' value lists (not from Aravis): the PFNC value list
# (PFNC.h, 2020-10-14) for the "p" formats, GigE Vision 2.x for the "Packed" ones
PACKED_CODES = {
    "Mono10p": 0x010A0046, "Mono12p": 0x010C0047,
    "BayerBG10p": 0x010A0052, "BayerGB10p": 0x010A0054, "BayerGR10p": 0x010A0056, "BayerRG10p": 0x010A0058,
    "BayerBG12p": 0x010C0053, "BayerGB12p": 0x010C0055, "BayerGR12p": 0x010C0057, "BayerRG12p": 0x010C0059,
    "Mono10Packed": 0x010C0004, "Mono12Packed": 0x010C0006,
    "BayerGR10Packed": 0x010C0026, "BayerRG10Packed": 0x010C0027, "BayerGB10Packed": 0x010C0028,
    "BayerBG10Packed": 0x010C0029,
    "BayerGR12Packed": 0x010C002A, "BayerRG12Packed": 0x010C002B, "BayerGB12Packed": 0x010C002C,
    "BayerBG12Packed": 0x010C002D,
}  # fmt: skip


def test_packed_formats_are_offered_after_the_unpacked_with_their_standard_codes():
    from drivers.aravis_camera import PIXEL_FORMATS, aravis_module, aravis_pixel_format

    Aravis = aravis_module()
    packed = [f for f in PIXEL_FORMATS if f.endswith(("p", "Packed"))]
    assert sorted(packed) == sorted(PACKED_CODES)
    assert {f: aravis_pixel_format(Aravis, f) for f in packed} == PACKED_CODES
    # grey first, then Bayer; in each, every unpacked format before the packed ones
    assert PIXEL_FORMATS.index("Mono16") < PIXEL_FORMATS.index("Mono10p") < PIXEL_FORMATS.index("Mono10Packed")
    assert PIXEL_FORMATS.index("BayerBG16") < PIXEL_FORMATS.index("BayerRG10p") < PIXEL_FORMATS.index("BayerRG10Packed")
    assert max(PIXEL_FORMATS.index(f) for f in PIXEL_FORMATS if f.startswith("Mono")) < PIXEL_FORMATS.index("BayerRG8")


def packed_fake_xml(tmp_path, formats) -> str:
    """Our fake XML whose PixelFormat also offers ``formats`` (name -> PFNC code)."""
    entries = "".join(f'<EnumEntry Name="{n}" NameSpace="Standard"><Value>{v}</Value></EnumEntry>' for n, v in formats)
    text = FAKE_FOCUS_XML.read_text().replace(
        "<pValue>PixelFormatRegister</pValue>", entries + "<pValue>PixelFormatRegister</pValue>", 1
    )
    path = tmp_path / "fake-packed.xml"
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize(
    "fmt, bits", [("BayerRG12p", 12), ("Mono10p", 10), ("BayerGB10Packed", 12), ("Mono12Packed", 12)]
)
def test_a_packed_format_reaches_the_camera_and_its_buffers_are_named_by_it(tmp_path, fmt, bits):
    """Through real libaravis: the packed format is set on the camera and read back, and the buffers come back
    carrying its code, which the driver names (Mono10p: a code Aravis 0.8 has no constant for). Aravis' Fake
    camera renders nothing in a packed format (its fill pattern knows Mono8, Mono16, the 8-bit Bayer and RGB8
    only: the buffer arrives empty), so the pixels cannot be checked through it (tests/drivers/test_frames.py
    checks the unpacking); the empty buffer is one line naming the format and the sizes."""
    xml = packed_fake_xml(tmp_path, [(fmt, PACKED_CODES[fmt])])
    with fake(pixel_format=fmt, fake_genicam_xml=xml) as cam:
        assert cam.pixel_format == fmt
        with pytest.raises(CaptureError) as err:
            cam.capture(timeout=2.0)
    assert str(err.value) == (
        f"aravis camera Fake_1: {fmt} frame truncated: 0 bytes for {W}x{H} ({W * H} pixels, {bits} bits each on the wire) "
        f"needs {W * H * bits // 8}"
    )
