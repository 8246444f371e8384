"""Raw camera buffers -> 2-D grey ``numpy`` arrays (``image[y, x]``), or raw Bayer mosaics.

One function per wire format, plus :func:`to_grey` that dispatches on the
format name. Names are the V4L2 fourcc (``GREY``, ``Y10``, ``Y12``, ``Y16``, ``YUYV``,
``MJPG``) or the GenICam PFNC name (``Mono8``, ``Mono10``, ``Mono12``,
``Mono16``). Every function copies: the result never aliases a driver
buffer that will be re-queued.

A colour sensor's raw frame (GenICam ``BayerRG8`` ... ``BayerBG16``, ``BayerRG10p`` ...
``BayerBG12Packed``, V4L2 ``RGGB`` ... ``BYR2``, ``pRAA`` ... ``pBCC``, :data:`BAYER_FORMATS`) is kept as
it is: :func:`raw_mosaic` gives the mosaic, nothing interpolated or demosaiced, and :func:`bayer_pattern` its colour filter pattern in :data:`pipeline.cfa.CFA_PATTERNS`' names (``BayerGR8`` -> ``"GRBG"``: the
PFNC name gives the first two pixels of the first row, then the second row follows). The colour
pipeline (:mod:`pipeline.cfa`) takes the mosaic with its pattern in the frame's ``extra["cfa"]``.

Packed 10/12-bit raw formats (:data:`PACKED_FORMATS`) are unpacked to ``uint16`` holding the values the
sensor sent (0..1023, 0..4095: not scaled, as the unpacked ``Mono10``/``Y10``/``RG10`` words are), a Bayer one kept
as its mosaic with its pattern (:func:`bayer_pattern`), a mono one a grey frame. Three packings:

* GenICam PFNC ``Mono10p``, ``Mono12p``, ``Bayer<xy>10p``, ``Bayer<xy>12p``: the pixels' bits one
  continuous LSB-first stream (pixel ``k`` occupies stream bits ``k*n .. k*n+n-1``, stream bit ``i`` is bit
  ``i % 8`` of byte ``i // 8``): 10 bits, four pixels in five bytes (byte 0 ``P0[7:0]``, byte 1
  ``P1[5:0] P0[9:8]``, byte 2 ``P2[3:0] P1[9:6]``, byte 3 ``P3[1:0] P2[9:4]``, byte 4 ``P3[9:2]``); 12 bits,
  two pixels in three bytes (``P0[7:0]``, ``P1[3:0] P0[11:8]``, ``P1[11:4]``).
* GigE Vision ``Mono10Packed``, ``Mono12Packed``, ``Bayer<xy>10Packed``, ``Bayer<xy>12Packed`` (GigE
  Vision 1.x, before the PFNC; 12 bits on the wire per pixel either way): two pixels in three bytes, the
  middle byte holding the low bits, 12 bits ``P0[11:4]``, ``P1[3:0] P0[3:0]``, ``P1[11:4]``; 10 bits
  ``P0[9:2]``, ``0 0 P1[1:0] 0 0 P0[1:0]``, ``P1[9:2]``.
* V4L2 MIPI CSI-2 ``pRAA``/``pgAA``/``pGAA``/``pBAA`` (``V4L2_PIX_FMT_SRGGB10P`` ...) and ``Y10P``: four
  pixels in five bytes, the high eight bits of each first then one byte of the four pairs of low bits
  (``P3[1:0] P2[1:0] P1[1:0] P0[1:0]``); ``pRCC``/``pgCC``/``pGCC``/``pBCC`` (``SRGGB12P`` ...) and ``Y12P``:
  two pixels in three bytes, ``P0[11:4]``, ``P1[11:4]``, ``P1[3:0] P0[3:0]``.

A GenICam frame is one stream over the whole image, as the camera sends it: with an odd width a row may
start inside a group (GigE Vision: "the first pixel of the second line will not start on a 3-byte
boundary"); unless its rows are padded (GenICam ``PaddingX``, the GigE Vision leader's ``padding_x``: bytes
after each line), when each row is a stream of its own, the stride apart (:func:`genicam_image` takes the
stride from the leader's ``padding_x``, else from the buffer's size). A V4L2 frame is rows of whole groups,
``bytes_per_line`` apart.

References
----------
EMVA, "GenICam Pixel Format Naming Convention (PFNC)", version 2.x: Bayer formats ``Bayer<first two
colours of the first row><bits>``; unpacked 10/12-bit formats one little-endian 16-bit word per pixel;
the packed ``p`` formats (``Mono10p`` 0x010A0046, ``Mono12p`` 0x010C0047, ``BayerRG10p`` 0x010A0058,
``BayerRG12p`` 0x010C0059, ...): lsb-first packing, no padding between pixels.
AIA, "GigE Vision" version 2.x, "Pixel formats": ``Mono10Packed`` (0x010C0004), ``Mono12Packed``
(0x010C0006), ``BayerGR10Packed`` ... ``BayerBG12Packed`` (0x010C0026 ... 0x010C002D).
Linux kernel documentation, "V4L2 pixel formats": ``V4L2_PIX_FMT_SRGGB10P`` ('pRAA', "10-bit packed Bayer
formats": "every four consecutive samples are packed into 5 bytes"), ``V4L2_PIX_FMT_SRGGB12P`` ('pRCC'),
``V4L2_PIX_FMT_Y10P`` and ``V4L2_PIX_FMT_Y12P`` ("MIPI RAW10/RAW12 packed"); MIPI Alliance, "CSI-2",
the RAW10 and RAW12 data types.
Linux kernel documentation, "V4L2 pixel formats: Bayer formats" (``V4L2_PIX_FMT_SRGGB8`` ``RGGB``,
``SGRBG8`` ``GRBG``, ``SGBRG8`` ``GBRG``, ``SBGGR8`` ``BA81``; the 10/12-bit ones one little-endian 16-bit
word per sample, high bits zero; ``SBGGR16`` ``BYR2``).
Linux kernel documentation, ``V4L2_PIX_FMT_Y10`` ('Y10 ') and ``V4L2_PIX_FMT_Y12`` ('Y12 '), grey: pixels stored
in 16-bit words, the unused high bits zero, the least significant byte first (little-endian).

``bytes_per_line`` is the row stride in bytes (V4L2 ``bytesperline``); rows
may be padded beyond ``width * bytes_per_pixel`` (a packed format: beyond the packed row).
``0``/``None`` means unpadded: for a GenICam packed format one stream over the whole frame; given, each of
its rows a stream of its own starting ``bytes_per_line`` after the previous one.
"""

from __future__ import annotations

import mmap
from typing import TypeAlias

import numpy as np

from drivers.errors import CaptureError

__all__ = [
    "BAYER_FORMATS",
    "GREY_FORMATS",
    "PACKED_FORMATS",
    "GENICAM_BAYER_FORMATS",
    "GENICAM_PACKED_MONO_FORMATS",
    "V4L2_BAYER_FORMATS",
    "V4L2_PACKED_GREY_FORMATS",
    "bayer_pattern",
    "raw_mosaic",
    "grey8",
    "grey16",
    "unpack",
    "yuyv_luma",
    "mjpeg_grey",
    "to_grey",
    "bytes_per_pixel",
    "genicam_stride",
    "genicam_image",
]

#: format name -> (numpy dtype, bytes per pixel) of the formats with a whole number of bytes per pixel;
#: MJPG is compressed (no fixed size), the packed ones (:data:`PACKED_FORMATS`) share bytes between pixels
_FIXED = {
    "GREY": ("u1", 1),
    "Mono8": ("u1", 1),
    "Y16": ("<u2", 2),
    "Mono16": ("<u2", 2),
    # GenICam unpacked Mono10/Mono12: one little-endian 16-bit word per pixel
    "Mono10": ("<u2", 2),
    "Mono12": ("<u2", 2),
    # V4L2 unpacked Y10/Y12 (V4L2_PIX_FMT_Y10 'Y10 ', Y12 'Y12 '): the same, the value in the low bits
    "Y10": ("<u2", 2),
    "Y12": ("<u2", 2),
    "YUYV": ("u1", 2),
}

_BAYER_ORDER = {"RG": "RGGB", "GR": "GRBG", "GB": "GBRG", "BG": "BGGR"}
_V4L2_BAYER = {  # V4L2 fourcc -> (pattern, bits): V4L2_PIX_FMT_SRGGB8 ... SBGGR16
    **{p: (p, 8) for p in ("RGGB", "GRBG", "GBRG")}, "BA81": ("BGGR", 8),
    "RG10": ("RGGB", 10), "BA10": ("GRBG", 10), "GB10": ("GBRG", 10), "BG10": ("BGGR", 10),
    "RG12": ("RGGB", 12), "BA12": ("GRBG", 12), "GB12": ("GBRG", 12), "BG12": ("BGGR", 12),
    "RG16": ("RGGB", 16), "GR16": ("GRBG", 16), "GB16": ("GBRG", 16), "BYR2": ("BGGR", 16),
}  # fmt: skip

#: packing -> (bytes, pixels) of one group; the layouts are in the module docstring
_GROUPS = {
    "pfnc10": (5, 4), "pfnc12": (3, 2),  # GenICam PFNC "p": one lsb-first bit stream
    "gige10": (3, 2), "gige12": (3, 2),  # GigE Vision "Packed": the low bits in the middle byte
    "csi10": (5, 4), "csi12": (3, 2),  # MIPI CSI-2 RAW10 / RAW12 (V4L2 "P")
}  # fmt: skip
#: packed format -> (packing, bits, Bayer pattern or None for a mono one)
_PACKED_INFO: dict[str, tuple[str, int, str | None]] = {
    "Mono10p": ("pfnc10", 10, None), "Mono12p": ("pfnc12", 12, None),
    "Mono10Packed": ("gige10", 10, None), "Mono12Packed": ("gige12", 12, None),
    **{f"Bayer{first}{bits}p": (f"pfnc{bits}", bits, pattern) for bits in (10, 12)
       for first, pattern in _BAYER_ORDER.items()},
    **{f"Bayer{first}{bits}Packed": (f"gige{bits}", bits, pattern) for bits in (10, 12)
       for first, pattern in _BAYER_ORDER.items()},
    # V4L2_PIX_FMT_SRGGB10P, SGRBG10P, SGBRG10P, SBGGR10P; SRGGB12P ... SBGGR12P; Y10P, Y12P
    "pRAA": ("csi10", 10, "RGGB"), "pgAA": ("csi10", 10, "GRBG"), "pGAA": ("csi10", 10, "GBRG"),
    "pBAA": ("csi10", 10, "BGGR"),
    "pRCC": ("csi12", 12, "RGGB"), "pgCC": ("csi12", 12, "GRBG"), "pGCC": ("csi12", 12, "GBRG"),
    "pBCC": ("csi12", 12, "BGGR"),
    "Y10P": ("csi10", 10, None), "Y12P": ("csi12", 12, None),
}  # fmt: skip
PACKED_FORMATS: dict[str, int] = {name: bits for name, (_packing, bits, _pattern) in _PACKED_INFO.items()}
"""Packed raw format -> its bits per pixel (10 or 12): GenICam PFNC ``Mono10p`` ... ``BayerBG12p``, GigE
Vision ``Mono10Packed`` ... ``BayerBG12Packed``, V4L2 ``pRAA`` ... ``pBCC``, ``Y10P``, ``Y12P`` (module
docstring); :func:`unpack` gives their pixels."""

_BAYER: dict[str, tuple[str, int]] = {
    **{f"Bayer{first}{bits}": (pattern, bits) for first, pattern in _BAYER_ORDER.items() for bits in (8, 10, 12, 16)},
    **_V4L2_BAYER,
    **{name: (pattern, bits) for name, (_packing, bits, pattern) in _PACKED_INFO.items() if pattern is not None},
}
#: raw Bayer format -> its colour filter pattern (row by row from the top-left pixel): the GenICam PFNC names
#: (``BayerRG8`` ... ``BayerBG16``, packed ``BayerRG10p`` ... ``BayerBG12p``, GigE Vision ``BayerRG10Packed`` ...
#: ``BayerBG12Packed``) and the V4L2 fourccs (``RGGB``, ``BA81``, ``RG10``, ``BYR2``, packed ``pRAA`` ... ``pBCC``);
#: 8 bits one byte per pixel, 10/12/16 bits one little-endian 16-bit word per pixel (unpacked) or packed
#: (:data:`PACKED_FORMATS`)
BAYER_FORMATS: dict[str, str] = {name: pattern for name, (pattern, _bits) in _BAYER.items()}
V4L2_BAYER_FORMATS = tuple(n for n in _BAYER if not n.startswith("Bayer"))
"""The V4L2 fourccs of raw Bayer formats (:data:`BAYER_FORMATS`): the unpacked ones first, then the packed
ones (MIPI CSI-2 ``pRAA`` ... ``pBCC``)."""
GENICAM_BAYER_FORMATS = tuple(n for n in _BAYER if n.startswith("Bayer"))
"""The GenICam names of raw Bayer formats (:data:`BAYER_FORMATS`): the unpacked ones first, then the PFNC packed
``BayerRG10p`` ... ``BayerBG12p``, then the GigE Vision ``BayerRG10Packed`` ... ``BayerBG12Packed``."""
GENICAM_PACKED_MONO_FORMATS = ("Mono10p", "Mono12p", "Mono10Packed", "Mono12Packed")
"""The GenICam packed grey formats (PFNC, then GigE Vision)."""
V4L2_PACKED_GREY_FORMATS = ("Y10P", "Y12P")
"""The V4L2 packed grey formats (MIPI CSI-2 RAW10 / RAW12)."""
GREY_FORMATS = (*_FIXED, "MJPG", *GENICAM_PACKED_MONO_FORMATS, *V4L2_PACKED_GREY_FORMATS)
"""The formats :func:`to_grey` converts."""

#: what a driver hands over: the bytes of one frame as the device delivered them
RawFrame: TypeAlias = bytes | bytearray | memoryview | mmap.mmap


def bytes_per_pixel(fmt: str) -> int:
    """Bytes per pixel on the wire (``YUYV`` is 2: Y and one chroma byte)."""
    try:
        return _FIXED[fmt][1]
    except KeyError:
        raise ValueError(f"pixel format {fmt!r} has no fixed pixel size; expected one of {', '.join(_FIXED)}") from None


def _strided(
    data: RawFrame, row: int, width: int, height: int, bytes_per_line: int | None, fmt: str, row_is: str
) -> np.ndarray:
    """View ``data`` as ``height`` rows of ``row`` bytes, ``bytes_per_line`` apart (``row_is`` says what
    ``row`` is, for the message when the stride is shorter)."""
    if width <= 0 or height <= 0:
        raise CaptureError(f"{fmt} frame has invalid size {width}x{height}")
    stride = bytes_per_line or row
    if stride < row:
        raise CaptureError(f"{fmt} frame: bytes_per_line {stride} < {row_is} = {row}")
    buf = np.frombuffer(data, dtype=np.uint8)
    need = stride * (height - 1) + row
    if buf.size < need:
        raise CaptureError(
            f"{fmt} frame truncated: {buf.size} bytes for {width}x{height} (stride {stride}) needs {need}"
        )
    return np.lib.stride_tricks.as_strided(buf, shape=(height, row), strides=(stride, 1))


def _rows(data: RawFrame, width: int, height: int, bpp: int, bytes_per_line: int | None, fmt: str) -> np.ndarray:
    """View ``data`` as ``height`` rows of ``width * bpp`` bytes (stride-aware)."""
    return _strided(data, width * bpp, width, height, bytes_per_line, fmt, f"width*{bpp}")


def _unpack_groups(packed: np.ndarray, packing: str) -> np.ndarray:
    """Rows of whole groups of packed bytes (``uint8``, rows x groups*bytes) -> their pixels, ``uint16``
    (rows x groups*pixels), by the layouts of the module docstring."""
    size, pixels = _GROUPS[packing]
    g = packed.reshape(packed.shape[0], -1, size).astype(np.uint16)  # every pixel fits 16 bits: no wider copy
    b = [g[..., i] for i in range(size)]
    px: list[np.ndarray]
    if packing == "pfnc10":  # lsb-first stream: pixel k is stream bits 10k .. 10k+9, byte j its bits 8j .. 8j+7
        px = [
            b[0] | (b[1] & 0x3) << 8,
            b[1] >> 2 | (b[2] & 0xF) << 6,
            b[2] >> 4 | (b[3] & 0x3F) << 4,
            b[3] >> 6 | b[4] << 2,
        ]
    elif packing == "pfnc12":  # lsb-first stream: pixel 0 stream bits 0..11, pixel 1 bits 12..23
        px = [b[0] | (b[1] & 0xF) << 8, b[1] >> 4 | b[2] << 4]
    elif packing in ("gige10", "gige12"):  # high bits in bytes 0 and 2, the low ones in byte 1's two nibbles
        low = 2 if packing == "gige10" else 4
        mask = (1 << low) - 1
        px = [b[0] << low | (b[1] & mask), b[2] << low | ((b[1] >> 4) & mask)]
    elif packing == "csi10":  # four high bytes, then the low bit pairs P3 P2 P1 P0 from bit 7 down
        px = [b[k] << 2 | ((b[4] >> (2 * k)) & 0x3) for k in range(4)]
    else:  # csi12: two high bytes, then the low nibbles P1 P0
        px = [b[0] << 4 | (b[2] & 0xF), b[1] << 4 | (b[2] >> 4)]
    assert len(px) == pixels
    return np.stack(px, axis=-1).reshape(packed.shape[0], -1)


def unpack(data: RawFrame, fmt: str, width: int, height: int, bytes_per_line: int | None = None) -> np.ndarray:
    """A packed 10/12-bit frame (:data:`PACKED_FORMATS`) -> its pixels, ``uint16`` (height, width), a copy.

    Every pixel is the value the sensor sent, 0..1023 or 0..4095 (not scaled to 16 bits, as the unpacked
    10/12-bit formats are read). The layouts are in the module docstring.

    Parameters
    ----------
    data : bytes-like
        The frame's bytes as the device delivered them.
    fmt : str
        The packed format: a GenICam PFNC (``Mono12p``, ``BayerRG10p``, ...) or GigE Vision
        (``Mono12Packed``, ...) name, or a V4L2 fourcc (``pRAA``, ``pRCC``, ``Y10P``, ...).
    width, height : int
        Pixels per row, rows.
    bytes_per_line : int, optional
        Row stride in bytes. A V4L2 frame's rows are whole groups (``width`` a multiple of 4 at 10 bits, of 2
        at 12 bits) padded to the stride. A GenICam frame without it is one stream over the whole frame;
        with it, every row a stream of its own starting ``bytes_per_line`` after the previous one.

    Returns
    -------
    numpy.ndarray
        ``uint16`` (height, width).

    Raises
    ------
    CaptureError
        An unknown format, a size that is not positive, a V4L2 width that is not a whole number of groups, a
        stride shorter than the packed row, or fewer bytes than the frame needs (one line naming the format,
        the size and the bytes needed).

    References
    ----------
    EMVA, "GenICam Pixel Format Naming Convention (PFNC)" 2.x, packed ``p`` formats (lsb-first packing).
    AIA, "GigE Vision" 2.x, pixel formats ``Mono10Packed``, ``Mono12Packed``, ``Bayer<xy>10/12Packed``.
    Linux kernel documentation, V4L2 pixel formats ``V4L2_PIX_FMT_SRGGB10P``, ``V4L2_PIX_FMT_SRGGB12P``,
    ``V4L2_PIX_FMT_Y10P``, ``V4L2_PIX_FMT_Y12P`` (MIPI CSI-2 RAW10, RAW12).
    """
    info = _PACKED_INFO.get(fmt)
    if info is None:
        raise CaptureError(f"pixel format {fmt!r} is not a packed one; supported: {', '.join(_PACKED_INFO)}")
    packing, bits, _pattern = info
    if width <= 0 or height <= 0:
        raise CaptureError(f"{fmt} frame has invalid size {width}x{height}")
    size, pixels = _GROUPS[packing]
    if packing.startswith("csi"):  # rows of whole groups, stride-aware
        if width % pixels:
            raise CaptureError(
                f"{fmt} frame width {width} is not a multiple of {pixels}: MIPI CSI-2 RAW{bits} packs {pixels} "
                f"pixels in {size} bytes"
            )
        row = width // pixels * size
        rows = _strided(data, row, width, height, bytes_per_line, fmt, f"width {width} packed in {row} bytes")
        return _unpack_groups(np.ascontiguousarray(rows), packing)
    wire_bits = 8 * size // pixels  # 10, or 12 (also GigE Vision's 10-bit Packed)
    groups = -(-width // pixels)
    if bytes_per_line:  # GenICam with a stride: each row its own stream, beginning on the stride
        row = -(-width * wire_bits // 8)
        rows = _strided(data, row, width, height, bytes_per_line, fmt, f"width {width} packed in {row} bytes")
        whole = np.zeros((height, groups * size), np.uint8)
        whole[:, :row] = rows
        return np.ascontiguousarray(_unpack_groups(whole, packing)[:, :width])
    n = width * height  # GenICam: one stream over the frame
    need = -(-n * wire_bits // 8)
    buf = np.frombuffer(data, dtype=np.uint8)
    if buf.size < need:
        raise CaptureError(
            f"{fmt} frame truncated: {buf.size} bytes for {width}x{height} ({n} pixels, {wire_bits} bits each on the "
            f"wire) needs {need}"
        )
    whole = np.zeros((1, -(-n // pixels) * size), np.uint8)
    whole[0, :need] = buf[:need]
    return _unpack_groups(whole, packing)[0, :n].reshape(height, width)


def grey8(data: RawFrame, width: int, height: int, bytes_per_line: int | None = None, fmt: str = "GREY") -> np.ndarray:
    """8-bit grey (V4L2 ``GREY``, GenICam ``Mono8``) -> ``uint8`` (height, width); ``fmt`` names the format in
    an error."""
    return np.ascontiguousarray(_rows(data, width, height, 1, bytes_per_line, fmt))


def grey16(data: RawFrame, width: int, height: int, bytes_per_line: int | None = None, fmt: str = "Y16") -> np.ndarray:
    """16-bit little-endian grey (``Y16``, ``Mono16``, unpacked ``Mono10/12``, ``Y10/12``) -> ``uint16``, the words as
    they are (a 10-bit value stays 0..1023); ``fmt`` names the format in an error."""
    rows = np.ascontiguousarray(_rows(data, width, height, 2, bytes_per_line, fmt))
    return rows.view("<u2").astype(np.uint16, copy=False).reshape(height, width)


def yuyv_luma(data: RawFrame, width: int, height: int, bytes_per_line: int | None = None) -> np.ndarray:
    """Packed 4:2:2 ``YUYV`` (Y0 U Y1 V) -> its luma plane, ``uint8``.

    The luma samples are every even byte; chroma is discarded (no colour
    conversion, so no interpolation error enters the grey image).
    """
    if width % 2:
        raise CaptureError(f"YUYV frame width {width} is odd")
    rows = _rows(data, width, height, 2, bytes_per_line, "YUYV")
    return np.ascontiguousarray(rows[:, 0::2])


def mjpeg_grey(data: RawFrame, width: int | None = None, height: int | None = None) -> np.ndarray:
    """Motion-JPEG frame -> decoded grey ``uint8`` (luma as decoded by libjpeg).

    ``width``/``height``, when given, are checked against the decoded size.
    """
    import cv2

    buf = np.frombuffer(data, dtype=np.uint8)
    img = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE) if buf.size else None
    if img is None:
        raise CaptureError(f"MJPG frame of {buf.size} bytes does not decode")
    if width is not None and height is not None and img.shape != (height, width):
        raise CaptureError(f"MJPG frame decodes to {img.shape[1]}x{img.shape[0]}, expected {width}x{height}")
    return img


def bayer_pattern(fmt: str) -> str | None:
    """The colour filter pattern of a raw Bayer format (``"BayerGR8"`` -> ``"GRBG"``); None: not a Bayer one."""
    return BAYER_FORMATS.get(fmt)


def raw_mosaic(data: RawFrame, fmt: str, width: int, height: int, bytes_per_line: int | None = None) -> np.ndarray:
    """A raw Bayer frame (:data:`BAYER_FORMATS`) -> its mosaic, ``uint8`` (8 bits) or ``uint16``, a copy:
    every pixel the value its photosite gave, nothing interpolated; a packed one (``BayerRG12p``, ``pRAA``, ...)
    unpacked by :func:`unpack`."""
    if fmt not in BAYER_FORMATS:
        raise CaptureError(f"pixel format {fmt!r} is not a raw Bayer one; supported: {', '.join(BAYER_FORMATS)}")
    if width % 2 or height % 2:
        raise CaptureError(f"{fmt} frame has an odd size {width}x{height}: not a whole Bayer mosaic")
    if fmt in _PACKED_INFO:
        return unpack(data, fmt, width, height, bytes_per_line)
    if _BAYER[fmt][1] == 8:
        return grey8(data, width, height, bytes_per_line, fmt)
    return grey16(data, width, height, bytes_per_line, fmt)


def _genicam_sizes(fmt: str, width: int, height: int) -> tuple[int, int] | None:
    """(bytes of one unpadded row, bytes of the unpadded frame) of a GenICam format; None: not one with a fixed
    size per pixel. A packed row or frame ends on the byte its last pixel's bits reach."""
    if fmt in _PACKED_INFO:
        size, pixels = _GROUPS[_PACKED_INFO[fmt][0]]
        wire_bits = 8 * size // pixels
        return -(-width * wire_bits // 8), -(-width * height * wire_bits // 8)
    if fmt in _FIXED:
        bpp = _FIXED[fmt][1]
    elif fmt in _BAYER:
        bpp = 1 if _BAYER[fmt][1] == 8 else 2
    else:
        return None
    return width * bpp, width * height * bpp


def genicam_stride(fmt: str, width: int, height: int, size: int, padding_x: int | None = None) -> int | None:
    """The row stride of a GenICam buffer of ``size`` bytes whose rows are padded, or None: read it unpadded.

    ``padding_x``: the bytes after each row that the buffer's leader states (GigE Vision's ``padding_x``, U3V's
    ``padding_x``; Aravis ``arv_buffer_get_image_padding``): the stride is one unpadded row and that, 0 unpadded,
    whatever the size (a buffer may carry chunk data after the image). None (not stated): padded when ``size`` is
    not the unpadded frame's but ``height`` whole rows of ``size // height`` bytes, at least one unpadded row each.
    Any other size is read unpadded, as a frame without padding is (one stream over the frame for a packed format;
    fewer bytes than it needs: the one-line truncation error).
    """
    sizes = _genicam_sizes(fmt, width, height)
    if sizes is None or width <= 0 or height <= 0:
        return None
    row, frame = sizes
    if padding_x is not None:
        return row + padding_x if padding_x > 0 else None
    if size == frame or size % height or size // height < row:
        return None
    return size // height


def genicam_image(data: RawFrame, fmt: str, width: int, height: int, padding_x: int | None = None) -> np.ndarray:
    """A GenICam buffer (one image, as the camera sent it) -> its grey image (:func:`to_grey`) or, a raw Bayer
    format, its mosaic (:func:`raw_mosaic`), a copy; rows padded beyond the pixels read with the stride
    :func:`genicam_stride` finds from the leader's ``padding_x`` or, not stated, from the buffer's size."""
    stride = genicam_stride(fmt, width, height, memoryview(data).nbytes, padding_x)
    if fmt in BAYER_FORMATS:
        return raw_mosaic(data, fmt, width, height, stride)
    return to_grey(data, fmt, width, height, stride)


def to_grey(data: RawFrame, fmt: str, width: int, height: int, bytes_per_line: int | None = None) -> np.ndarray:
    """Convert one raw frame in format ``fmt`` (:data:`GREY_FORMATS`) to a 2-D grey array (a copy); a packed
    mono one (``Mono12p``, ``Mono12Packed``, ``Y10P``, ...) unpacked by :func:`unpack` to ``uint16``."""
    if fmt in ("GREY", "Mono8"):
        return grey8(data, width, height, bytes_per_line, fmt)
    if fmt in ("Y16", "Mono16", "Mono10", "Mono12", "Y10", "Y12"):
        return grey16(data, width, height, bytes_per_line, fmt)
    if fmt in GENICAM_PACKED_MONO_FORMATS or fmt in V4L2_PACKED_GREY_FORMATS:
        return unpack(data, fmt, width, height, bytes_per_line)
    if fmt == "YUYV":
        return yuyv_luma(data, width, height, bytes_per_line)
    if fmt == "MJPG":
        return mjpeg_grey(data, width, height)
    raise CaptureError(f"pixel format {fmt!r} cannot be converted to grey; supported: {', '.join(GREY_FORMATS)}")
