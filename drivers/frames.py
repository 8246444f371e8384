"""Raw camera buffers -> 2-D grey ``numpy`` arrays (``image[y, x]``), or raw Bayer mosaics.

One function per wire format, plus :func:`to_grey` that dispatches on the
format name. Names are the V4L2 fourcc (``GREY``, ``Y16``, ``YUYV``,
``MJPG``) or the GenICam PFNC name (``Mono8``, ``Mono10``, ``Mono12``,
``Mono16``). Every function copies: the result never aliases a driver
buffer that will be re-queued.

A colour sensor's raw frame (GenICam ``BayerRG8`` ... ``BayerBG16``, V4L2 ``RGGB`` ... ``BYR2``,
:data:`BAYER_FORMATS`) is kept as it is: :func:`raw_mosaic` gives the mosaic, nothing interpolated or demosaiced, and :func:`bayer_pattern`
its colour filter pattern in :data:`pipeline.cfa.CFA_PATTERNS`' names (``BayerGR8`` -> ``"GRBG"``: the
PFNC name gives the first two pixels of the first row, then the second row follows). The colour
pipeline (:mod:`pipeline.cfa`) takes the mosaic with its pattern in the frame's ``extra["cfa"]``.

References
----------
EMVA, "GenICam Pixel Format Naming Convention (PFNC)", version 2.x: Bayer formats ``Bayer<first two
colours of the first row><bits>``; unpacked 10/12-bit formats one little-endian 16-bit word per pixel.
Linux kernel documentation, "V4L2 pixel formats: Bayer formats" (``V4L2_PIX_FMT_SRGGB8`` ``RGGB``,
``SGRBG8`` ``GRBG``, ``SGBRG8`` ``GBRG``, ``SBGGR8`` ``BA81``; the 10/12-bit ones one little-endian 16-bit
word per sample, high bits zero; ``SBGGR16`` ``BYR2``).

``bytes_per_line`` is the row stride in bytes (V4L2 ``bytesperline``); rows
may be padded beyond ``width * bytes_per_pixel``. ``0``/``None`` means
unpadded.
"""

from __future__ import annotations

import mmap
from typing import TypeAlias

import numpy as np

from drivers.errors import CaptureError

__all__ = [
    "BAYER_FORMATS",
    "GREY_FORMATS",
    "bayer_pattern",
    "raw_mosaic",
    "grey8",
    "grey16",
    "yuyv_luma",
    "mjpeg_grey",
    "to_grey",
    "bytes_per_pixel",
]

#: format name -> (numpy dtype, bytes per pixel); MJPG is compressed (no fixed size)
_PACKED = {
    "GREY": ("u1", 1),
    "Mono8": ("u1", 1),
    "Y16": ("<u2", 2),
    "Mono16": ("<u2", 2),
    # GenICam unpacked Mono10/Mono12: one little-endian 16-bit word per pixel
    "Mono10": ("<u2", 2),
    "Mono12": ("<u2", 2),
    "YUYV": ("u1", 2),
}
GREY_FORMATS = tuple(_PACKED) + ("MJPG",)

_BAYER_ORDER = {"RG": "RGGB", "GR": "GRBG", "GB": "GBRG", "BG": "BGGR"}
_V4L2_BAYER = {  # V4L2 fourcc -> (pattern, bits): V4L2_PIX_FMT_SRGGB8 ... SBGGR16
    **{p: (p, 8) for p in ("RGGB", "GRBG", "GBRG")}, "BA81": ("BGGR", 8),
    "RG10": ("RGGB", 10), "BA10": ("GRBG", 10), "GB10": ("GBRG", 10), "BG10": ("BGGR", 10),
    "RG12": ("RGGB", 12), "BA12": ("GRBG", 12), "GB12": ("GBRG", 12), "BG12": ("BGGR", 12),
    "RG16": ("RGGB", 16), "GR16": ("GRBG", 16), "GB16": ("GBRG", 16), "BYR2": ("BGGR", 16),
}  # fmt: skip
_BAYER: dict[str, tuple[str, int]] = {
    **{f"Bayer{first}{bits}": (pattern, bits) for first, pattern in _BAYER_ORDER.items() for bits in (8, 10, 12, 16)},
    **_V4L2_BAYER,
}
#: raw Bayer format -> its colour filter pattern (row by row from the top-left pixel): the GenICam PFNC names
#: (``BayerRG8`` ... ``BayerBG16``) and the V4L2 fourccs (``RGGB``, ``BA81``, ``RG10``, ``BYR2``, ...); 8 bits
#: one byte per pixel, 10/12/16 bits one little-endian 16-bit word per pixel (unpacked)
BAYER_FORMATS: dict[str, str] = {name: pattern for name, (pattern, _bits) in _BAYER.items()}
V4L2_BAYER_FORMATS = tuple(_V4L2_BAYER)
"""The V4L2 fourccs of raw Bayer formats (:data:`BAYER_FORMATS`)."""
GENICAM_BAYER_FORMATS = tuple(n for n in _BAYER if n.startswith("Bayer"))
"""The GenICam PFNC names of raw Bayer formats (:data:`BAYER_FORMATS`)."""

#: what a driver hands over: the bytes of one frame as the device delivered them
RawFrame: TypeAlias = bytes | bytearray | memoryview | mmap.mmap


def bytes_per_pixel(fmt: str) -> int:
    """Bytes per pixel on the wire (``YUYV`` is 2: Y and one chroma byte)."""
    try:
        return _PACKED[fmt][1]
    except KeyError:
        raise ValueError(
            f"pixel format {fmt!r} has no fixed pixel size; expected one of {', '.join(_PACKED)}"
        ) from None


def _rows(data: RawFrame, width: int, height: int, bpp: int, bytes_per_line: int | None, fmt: str) -> np.ndarray:
    """View ``data`` as ``height`` rows of ``width * bpp`` bytes (stride-aware)."""
    if width <= 0 or height <= 0:
        raise CaptureError(f"{fmt} frame has invalid size {width}x{height}")
    row = width * bpp
    stride = bytes_per_line or row
    if stride < row:
        raise CaptureError(f"{fmt} frame: bytes_per_line {stride} < width*{bpp} = {row}")
    buf = np.frombuffer(data, dtype=np.uint8)
    need = stride * (height - 1) + row
    if buf.size < need:
        raise CaptureError(
            f"{fmt} frame truncated: {buf.size} bytes for {width}x{height} (stride {stride}) needs {need}"
        )
    return np.lib.stride_tricks.as_strided(buf, shape=(height, row), strides=(stride, 1))


def grey8(data: RawFrame, width: int, height: int, bytes_per_line: int | None = None) -> np.ndarray:
    """8-bit grey (V4L2 ``GREY``, GenICam ``Mono8``) -> ``uint8`` (height, width)."""
    return np.ascontiguousarray(_rows(data, width, height, 1, bytes_per_line, "GREY"))


def grey16(data: RawFrame, width: int, height: int, bytes_per_line: int | None = None) -> np.ndarray:
    """16-bit little-endian grey (``Y16``, ``Mono16``, unpacked ``Mono10/12``) -> ``uint16``."""
    rows = np.ascontiguousarray(_rows(data, width, height, 2, bytes_per_line, "Y16"))
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
    every pixel the value its photosite gave, nothing interpolated."""
    if fmt not in BAYER_FORMATS:
        raise CaptureError(f"pixel format {fmt!r} is not a raw Bayer one; supported: {', '.join(BAYER_FORMATS)}")
    if width % 2 or height % 2:
        raise CaptureError(f"{fmt} frame has an odd size {width}x{height}: not a whole Bayer mosaic")
    if _BAYER[fmt][1] == 8:
        return grey8(data, width, height, bytes_per_line)
    return grey16(data, width, height, bytes_per_line)


def to_grey(data: RawFrame, fmt: str, width: int, height: int, bytes_per_line: int | None = None) -> np.ndarray:
    """Convert one raw frame in format ``fmt`` to a 2-D grey array (a copy)."""
    if fmt in ("GREY", "Mono8"):
        return grey8(data, width, height, bytes_per_line)
    if fmt in ("Y16", "Mono16", "Mono10", "Mono12"):
        return grey16(data, width, height, bytes_per_line)
    if fmt == "YUYV":
        return yuyv_luma(data, width, height, bytes_per_line)
    if fmt == "MJPG":
        return mjpeg_grey(data, width, height)
    raise CaptureError(f"pixel format {fmt!r} cannot be converted to grey; supported: {', '.join(GREY_FORMATS)}")
