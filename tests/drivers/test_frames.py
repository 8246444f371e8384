"""Raw buffer -> grey array and raw Bayer mosaic conversions (drivers/frames.py), including bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from drivers import frames
from drivers.errors import CaptureError
from drivers.frames import bayer_pattern, raw_mosaic, to_grey
from tests.drivers import packing


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


# -- packed 10/12-bit formats ------------------------------------------------------------------------------------
# Hand-worked from the standards' byte tables (tests/drivers/packing.py cites them), pixel values
# 0x3FF 0x000 0x155 0x2AA (10 bits) and 0xABC 0x123 (12 bits):
#   PFNC Mono10p, one lsb-first stream: 0x3FF | 0x000 << 10 | 0x155 << 20 | 0x2AA << 30 = 0xAA955003FF,
#     little-endian FF 03 50 95 AA
#   MIPI CSI-2 RAW10 (V4L2 Y10P, pRAA): the high bytes 3FF>>2=FF 0 155>>2=55 2AA>>2=AA, then the low bit
#     pairs P3 P2 P1 P0 = 10 01 00 11 = 0x93
#   GigE Vision Mono10Packed (0x3FF, 0x155): 3FF>>2=FF, then --01--11 = 0x13, then 155>>2=55
#   PFNC Mono12p: 0xABC | 0x123 << 12 = 0x123ABC, little-endian BC 3A 12
#   GigE Vision Mono12Packed: AB, then P1[3:0] P0[3:0] = 3C, then 12
#   MIPI CSI-2 RAW12 (Y12P, pRCC): AB 12, then P1[3:0] P0[3:0] = 3C
HAND_WORKED = [
    ("Mono10p", bytes([0xFF, 0x03, 0x50, 0x95, 0xAA]), [0x3FF, 0x000, 0x155, 0x2AA]),
    ("Y10P", bytes([0xFF, 0x00, 0x55, 0xAA, 0x93]), [0x3FF, 0x000, 0x155, 0x2AA]),
    ("Mono10Packed", bytes([0xFF, 0x13, 0x55]), [0x3FF, 0x155]),
    ("Mono12p", bytes([0xBC, 0x3A, 0x12]), [0xABC, 0x123]),
    ("Mono12Packed", bytes([0xAB, 0x3C, 0x12]), [0xABC, 0x123]),
    ("Y12P", bytes([0xAB, 0x12, 0x3C]), [0xABC, 0x123]),
]


@pytest.mark.parametrize("fmt, raw, values", HAND_WORKED, ids=[c[0] for c in HAND_WORKED])
def test_packed_grey_bytes_worked_by_hand_from_the_standards(fmt, raw, values):
    """One group of each packing, its bytes worked out by hand: the frame is ``uint16`` holding the values
    sent (not scaled, as the unpacked Mono10/Mono12/RG10 words are read). The independent packer of the other
    tests gives the same bytes (its tables are right too)."""
    out = to_grey(raw, fmt, len(values), 1)
    assert out.dtype == np.uint16 and out.tolist() == [values]
    assert packing.pack(np.array(values), *packing.FORMATS[fmt]) == raw


def test_packed_bayer_formats_name_their_pattern_and_keep_the_mosaic():
    """Bayer<xy>10p/12p (PFNC) and Bayer<xy>10Packed/12Packed (GigE Vision) name the pattern as the unpacked
    Bayer<xy>10 do; the V4L2 fourccs as the kernel's V4L2_PIX_FMT_S<pattern>10P/12P."""
    expected = {
        **{f"Bayer{xy}{b}{p}": pat for xy, pat in (("RG", "RGGB"), ("GR", "GRBG"), ("GB", "GBRG"), ("BG", "BGGR"))
           for b in (10, 12) for p in ("p", "Packed")},
        "pRAA": "RGGB", "pgAA": "GRBG", "pGAA": "GBRG", "pBAA": "BGGR",
        "pRCC": "RGGB", "pgCC": "GRBG", "pGCC": "GBRG", "pBCC": "BGGR",
    }  # fmt: skip
    assert {f: bayer_pattern(f) for f in expected} == expected
    assert {f: bayer_pattern(f) for f in ("Mono10p", "Mono12Packed", "Y10P", "Y12P")} == dict.fromkeys(
        ("Mono10p", "Mono12Packed", "Y10P", "Y12P")
    )
    assert set(frames.PACKED_FORMATS) == set(packing.FORMATS)
    raw = bytes([0xAB, 0x12, 0x3C, 0xFF, 0x00, 0x0F])  # pRCC 2x2: AB<<4|C, 12<<4|3; FF<<4|F, 0
    m = raw_mosaic(raw, "pRCC", 2, 2, bytes_per_line=3)
    assert m.dtype == np.uint16 and m.tolist() == [[0xABC, 0x123], [0xFFF, 0x000]]


GENICAM_CASES = [
    (fmt, w, h)
    for fmt in sorted(f for f in packing.FORMATS if not packing.FORMATS[f][0].startswith("csi"))
    for w, h in [(2, 2), (6, 3), (7, 5), (33, 4), (64, 48)]
    if not (fmt.startswith("Bayer") and (w % 2 or h % 2))  # a Bayer mosaic has an even size
]


@pytest.mark.parametrize("fmt, width, height", GENICAM_CASES)
def test_genicam_packed_frames_unpack_exactly_whatever_the_width(fmt, width, height):
    """Seeded random 10/12-bit images packed by the independent packer as one stream over the frame (odd widths:
    a row starts inside a group, as the GigE Vision spec says) unpack to exactly those values."""
    bits = packing.FORMATS[fmt][1]
    image = np.random.default_rng(width * 100 + height).integers(0, 1 << bits, (height, width), dtype=np.uint16)
    image[0, :2] = (1 << bits) - 1, 0  # the extremes
    raw = packing.pack_stream(image, fmt)
    out = raw_mosaic(raw, fmt, width, height) if fmt.startswith("Bayer") else to_grey(raw, fmt, width, height)
    assert out.dtype == np.uint16 and out.shape == (height, width) and out.flags.c_contiguous
    assert np.array_equal(out, image)
    with pytest.raises(CaptureError) as err:  # one byte short: one line naming the format and the sizes
        to_grey(raw[:-1], fmt, width, height) if fmt.startswith("Mono") else raw_mosaic(raw[:-1], fmt, width, height)
    assert str(err.value) == (
        f"{fmt} frame truncated: {len(raw) - 1} bytes for {width}x{height} ({width * height} pixels, "
        f"{10 if fmt.endswith('10p') else 12} bits each on the wire) needs {len(raw)}"
    )


@pytest.mark.parametrize("fmt", ["Mono10p", "Mono12Packed", "BayerGB10Packed", "BayerBG12p"])
def test_a_genicam_packed_frame_with_a_stride_is_a_stream_per_row(fmt):
    bits = packing.FORMATS[fmt][1]
    width, height, stride = 6, 4, 16
    image = np.random.default_rng(7).integers(0, 1 << bits, (height, width), dtype=np.uint16)
    raw = b"".join(packing.pack_stream(row, fmt).ljust(stride, b"\xee") for row in image)
    out = (
        raw_mosaic(raw, fmt, width, height, stride)
        if fmt.startswith("Bayer")
        else to_grey(raw, fmt, width, height, stride)
    )
    assert np.array_equal(out, image)


@pytest.mark.parametrize("fmt", sorted(f for f in packing.FORMATS if packing.FORMATS[f][0].startswith("csi")))
@pytest.mark.parametrize("width, height, padding", [(4, 2, 0), (12, 6, 3), (64, 48, 32), (636, 2, 1)])
def test_v4l2_csi2_packed_frames_unpack_exactly_with_row_padding(fmt, width, height, padding):
    """Seeded random values, each row packed by the independent packer and padded to ``bytesperline`` with 0xEE
    bytes that must never reach the image."""
    bits = packing.FORMATS[fmt][1]
    image = np.random.default_rng(width + padding).integers(0, 1 << bits, (height, width), dtype=np.uint16)
    image[-1, -2:] = 0, (1 << bits) - 1
    raw, stride = packing.pack_rows(image, fmt, padding)
    out = (
        raw_mosaic(raw, fmt, width, height, stride) if fmt.startswith("p") else to_grey(raw, fmt, width, height, stride)
    )
    assert out.dtype == np.uint16 and np.array_equal(out, image)
    short = raw[: stride * (height - 1) + stride - padding - 1]
    with pytest.raises(CaptureError, match=rf"^{fmt} frame truncated: {len(short)} bytes for {width}x{height} "
                       rf"\(stride {stride}\) needs {len(short) + 1}$"):  # fmt: skip
        to_grey(short, fmt, width, height, stride) if fmt.startswith("Y") else raw_mosaic(
            short, fmt, width, height, stride
        )


@pytest.mark.parametrize(
    "call, message",
    [
        (
            lambda: to_grey(bytes(8), "Y10P", 6, 1),
            "Y10P frame width 6 is not a multiple of 4: MIPI CSI-2 RAW10 packs 4 pixels in 5 bytes",
        ),
        (
            lambda: raw_mosaic(bytes(30), "pRAA", 8, 2, bytes_per_line=9),
            r"pRAA frame: bytes_per_line 9 < width 8 "
            r"packed in 10 bytes = 10",
        ),
        (lambda: raw_mosaic(bytes(30), "BayerRG12p", 3, 2), "BayerRG12p frame has an odd size 3x2"),
        (lambda: to_grey(bytes(30), "Mono10p", 0, 2), "Mono10p frame has invalid size 0x2"),
        (lambda: to_grey(bytes(30), "pRAA", 4, 2), "'pRAA' cannot be converted to grey"),
        (lambda: frames.unpack(bytes(30), "Mono14p", 4, 2), "'Mono14p' is not a packed one; supported: Mono10p, "),
        (lambda: to_grey(bytes(3), "Mono12", 2, 1), r"Mono12 frame truncated: 3 bytes for 2x1 \(stride 4\) needs 4"),
    ],
)
def test_bad_packed_input_is_one_line_naming_the_format_and_sizes(call, message):
    with pytest.raises(CaptureError, match=message) as err:
        call()
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("fmt, top", [("Y10", 0x3FF), ("Y12", 0xFFF)])
def test_v4l2_y10_y12_are_little_endian_words_read_as_they_are(fmt, top):
    """V4L2_PIX_FMT_Y10 / Y12 (kernel documentation): one 16-bit word per pixel, least significant byte first, the
    value in the low bits; read as the words are (not scaled), as the unpacked Mono10/Mono12 and RG10 are. Bytes
    worked out by hand, rows padded to the stride with 0xEE."""
    low, high = top & 0xFF, top >> 8
    raw = bytes([low, high, 0x01, 0x00, 0xEE, 0xEE, 0x00, 0x02, 0x34, 0x01, 0xEE, 0xEE])
    out = to_grey(raw, fmt, 2, 2, bytes_per_line=6)
    assert out.dtype == np.uint16 and out.tolist() == [[top, 1], [0x200, 0x134]]


@pytest.mark.parametrize(
    "fmt, width, height, padding",
    [
        ("Mono10p", 7, 5, 3),  # a row of 70 bits: 9 bytes, then 3 of padding
        ("Mono12p", 6, 4, 1),
        ("Mono10Packed", 5, 3, 8),  # GigE Vision: an odd width, the row's last group half used
        ("Mono12Packed", 64, 48, 32),
        ("BayerRG12p", 6, 4, 2),
        ("BayerGB10Packed", 4, 2, 4),
        ("BayerBG10p", 64, 48, 16),
    ],
)
def test_a_genicam_packed_buffer_with_padded_rows_is_read_with_the_stride_its_size_tells(fmt, width, height, padding):
    """A camera that pads each row (GenICam PaddingX): every row its own stream (the independent packer's), then
    ``padding`` bytes of 0xEE that must never reach the image; the buffer holds ``height`` such rows, and the
    stride is its size over the height. Fewer bytes than even the unpadded frame: the one-line truncation error.
    Tested here, at the AravisCamera's own entry point (frames.genicam_image): Aravis' Fake camera cannot send such a
    buffer (0.8.26: its frame is width x height x bytes per pixel, its padding (0, 0), nothing rendered in a packed
    format, and its fill-pattern callback cannot be set from Python: the interpreter crashes)."""
    bits = packing.FORMATS[fmt][1]
    image = np.random.default_rng(width * 1000 + padding).integers(0, 1 << bits, (height, width), dtype=np.uint16)
    image[-1, -2:] = (1 << bits) - 1, 0
    rows = [packing.pack_stream(row, fmt) for row in image]
    stride = len(rows[0]) + padding
    raw = b"".join(r + b"\xee" * padding for r in rows)
    assert len(raw) == height * stride and frames.genicam_stride(fmt, width, height, len(raw)) == stride
    out = frames.genicam_image(raw, fmt, width, height)
    assert out.dtype == np.uint16 and out.shape == (height, width) and np.array_equal(out, image)
    need = len(packing.pack_stream(image, fmt))  # the unpadded frame, one stream
    with pytest.raises(CaptureError) as err:
        frames.genicam_image(raw[: need - 1], fmt, width, height)
    assert str(err.value) == (
        f"{fmt} frame truncated: {need - 1} bytes for {width}x{height} ({width * height} pixels, "
        f"{10 if fmt.endswith('10p') else 12} bits each on the wire) needs {need}"
    )


@pytest.mark.parametrize("fmt, dtype", [("Mono8", "u1"), ("Mono16", "<u2"), ("BayerRG8", "u1"), ("BayerGR12", "<u2")])
def test_a_genicam_unpacked_buffer_with_padded_rows_is_read_with_the_stride_its_size_tells(fmt, dtype):
    """The same for the unpacked formats (one byte, or one little-endian 16-bit word, a pixel)."""
    width, height, padding = 6, 4, 5
    top = 255 if dtype == "u1" else (4095 if fmt.endswith("12") else 65535)
    image = np.random.default_rng(11).integers(0, top + 1, (height, width)).astype(dtype)
    raw = b"".join(row.tobytes() + b"\xee" * padding for row in image)
    out = frames.genicam_image(raw, fmt, width, height)
    assert out.shape == (height, width) and out.dtype == np.dtype(dtype).newbyteorder("=")
    assert np.array_equal(out, image)


@pytest.mark.parametrize("fmt, width, height", [*GENICAM_CASES, ("Mono10p", 3, 2), ("Mono10p", 3, 3)])
def test_an_unpadded_genicam_buffer_is_one_stream_even_when_its_size_is_whole_rows(fmt, width, height):
    """A buffer of exactly the unpadded frame is read as one stream over it, padding or no: 3 pixels of Mono10p are
    30 bits, a 4-byte row, and 3x2 of them one 60-bit stream in 8 bytes, the size of two such rows (the second row
    starts at bit 30, inside the fourth byte, not at the fifth)."""
    bits = packing.FORMATS[fmt][1]
    image = np.random.default_rng(width * 100 + height + 1).integers(0, 1 << bits, (height, width), dtype=np.uint16)
    raw = packing.pack_stream(image, fmt)
    assert frames.genicam_stride(fmt, width, height, len(raw)) is None
    assert np.array_equal(frames.genicam_image(raw, fmt, width, height), image)


@pytest.mark.parametrize(
    "fmt, width, height, padding", [("Mono12p", 6, 4, 3), ("Mono8", 6, 4, 2), ("BayerRG10p", 8, 2, 4)]
)
def test_the_padding_the_leader_states_decides_the_stride_whatever_the_size(fmt, width, height, padding):
    """The padding a buffer's leader states (Aravis ``get_image_padding``) is the stride's, not the size's guess:
    padded rows with padding_x read right; an unpadded frame followed by whole rows' worth of other bytes (chunk data
    after the image) with padding_x 0 read as one stream, where the size alone would take it for padded rows."""
    bits = packing.FORMATS[fmt][1] if fmt in packing.FORMATS else 8
    image = np.random.default_rng(padding).integers(0, 1 << bits, (height, width), dtype=np.uint16)
    if fmt == "Mono8":
        rows = [row.astype(np.uint8).tobytes() for row in image]
        stream = image.astype(np.uint8).tobytes()
    else:
        rows = [packing.pack_stream(row, fmt) for row in image]
        stream = packing.pack_stream(image, fmt)
    padded = b"".join(r + b"\xee" * padding for r in rows)
    assert np.array_equal(frames.genicam_image(padded, fmt, width, height, padding_x=padding), image)
    chunk = b"\xcc" * (height * (len(rows[0]) + padding) - len(stream))  # the size of padded rows, exactly
    assert frames.genicam_stride(fmt, width, height, len(stream + chunk)) is not None  # the size's guess: padded
    assert np.array_equal(frames.genicam_image(stream + chunk, fmt, width, height, padding_x=0), image)
