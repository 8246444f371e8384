"""Raw buffer -> grey array and raw Bayer mosaic conversions (drivers/frames.py), including bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from drivers.errors import CaptureError
from drivers.frames import bayer_pattern, raw_mosaic, to_grey


def test_grey8_with_stride_padding_drops_the_padding():
    img = np.arange(12, dtype=np.uint8).reshape(3, 4)
    raw = np.pad(img, ((0, 0), (0, 2)), constant_values=255).tobytes()
    out = to_grey(raw, "GREY", 4, 3, bytes_per_line=6)
    assert np.array_equal(out, img) and out.flags.c_contiguous


def test_y16_is_little_endian():
    raw = bytes([0x34, 0x12, 0xFF, 0x00])
    assert to_grey(raw, "Mono16", 2, 1).tolist() == [[0x1234, 0x00FF]]


def test_yuyv_keeps_luma_only():
    raw = bytes([10, 200, 20, 100, 30, 0, 40, 255])  # Y0 U Y1 V Y2 U Y3 V
    assert to_grey(raw, "YUYV", 4, 1).tolist() == [[10, 20, 30, 40]]


def test_mjpg_decodes_and_checks_size():
    img = np.full((8, 16), 77, np.uint8)
    jpg = cv2.imencode(".jpg", img)[1].tobytes()
    assert np.array_equal(to_grey(jpg, "MJPG", 16, 8), img)
    with pytest.raises(CaptureError, match="decodes to 16x8, expected 8x16"):
        to_grey(jpg, "MJPG", 8, 16)


@pytest.mark.parametrize(
    "raw, fmt, w, h, match",
    [
        (b"\x00" * 11, "GREY", 4, 3, "truncated"),
        (b"\x00" * 8, "YUYV", 3, 1, "odd"),
        (b"not a jpeg", "MJPG", 4, 4, "does not decode"),
        (b"\x00" * 12, "RGB3", 2, 2, "cannot be converted"),
        (b"\x00" * 12, "GREY", 4, 3, None),
    ],
)
def test_bad_buffers_raise_capture_error(raw, fmt, w, h, match):
    if match is None:
        assert to_grey(raw, fmt, w, h).shape == (h, w)
    else:
        with pytest.raises(CaptureError, match=match):
            to_grey(raw, fmt, w, h)


def test_a_raw_bayer_frame_is_kept_as_its_mosaic_and_named_by_the_pfnc_pattern():
    """GenICam PFNC: ``Bayer<first two colours of the first row><bits>``, the second row the other two;
    8 bits one byte per pixel, 10/12/16 bits one little-endian word (unpacked)."""
    assert {f: bayer_pattern(f) for f in ("BayerRG8", "BayerGR10", "BayerGB12", "BayerBG16")} == {
        "BayerRG8": "RGGB", "BayerGR10": "GRBG", "BayerGB12": "GBRG", "BayerBG16": "BGGR",
    }  # fmt: skip
    assert {f: bayer_pattern(f) for f in ("RGGB", "BA81", "BA10", "GB12", "BYR2")} == {  # V4L2 fourccs
        "RGGB": "RGGB", "BA81": "BGGR", "BA10": "GRBG", "GB12": "GBRG", "BYR2": "BGGR",
    }  # fmt: skip
    assert bayer_pattern("Mono8") is None and bayer_pattern("GREY") is None
    assert raw_mosaic(bytes([1, 2, 3, 4]), "BA81", 2, 2).dtype == np.uint8  # 8 bits, though its name ends in 1
    raw8 = bytes([10, 200, 11, 201, 0, 0, 202, 30, 203, 31, 0, 0])  # 4x2, rows padded to 6 bytes
    m8 = raw_mosaic(raw8, "BayerRG8", 4, 2, bytes_per_line=6)
    assert m8.dtype == np.uint8 and m8.tolist() == [[10, 200, 11, 201], [202, 30, 203, 31]]
    raw12 = bytes([0x34, 0x02, 0xFF, 0x0F, 0x00, 0x00, 0x01, 0x00])  # 2x2 words: 0x234, 0xFFF, 0, 1
    m12 = raw_mosaic(raw12, "BayerGB12", 2, 2)
    assert m12.dtype == np.uint16 and m12.tolist() == [[0x234, 0xFFF], [0, 1]]
    with pytest.raises(CaptureError, match="odd size 3x2"):
        raw_mosaic(bytes(6), "BayerRG8", 3, 2)
    with pytest.raises(CaptureError, match="'Mono8' is not a raw Bayer one"):
        raw_mosaic(bytes(4), "Mono8", 2, 2)
