"""Reading harp photographs from files.

:func:`read_grey` reads PGM/PPM, PNG, TIFF and JPEG files (8 or 16 bit,
grey or colour) into a 2-D grey array, keeping the bit depth: ``uint8`` or
``uint16``; :func:`read_unchanged` reads them as stored (channels and bit
depth kept), with the same checks. Colour is converted to grey with the ITU-R BT.601 luma weights
(``0.299 R + 0.587 G + 0.114 B``, what ``cv2.cvtColor`` does), computed in
float and rounded back to the input depth. An alpha channel is dropped.

Every failure raises :class:`ImageReadError` with a one-line message that
names the file and the reason: missing, a directory, unreadable
(permissions), empty, not an image, truncated, unsupported layout, not a
regular file, too large.

Reading is bounded. Only regular files are read: a device (``/dev/zero``), a
FIFO or a socket is refused before it is opened (it could be endless or block
forever). An image whose header claims more than ``max_pixels`` pixels is
refused before anything is decoded (:func:`header_size` reads the width and
height of PNG, TIFF, JPEG, PNM, BMP and WebP headers, by hand: OpenCV reads no header alone,
``cv2.haveImageReader`` only matches a file's signature and its own check before decoding,
``OPENCV_IO_MAX_IMAGE_PIXELS``, is read once per process and fails without the size; Pillow does read
them, at 90-180 ms of imports a process); other formats are checked after decoding, which OpenCV
itself bounds at 2^30 pixels. The default limit is
:data:`MAX_PIXELS` (200 megapixels), or the environment variable
``HARP_MAX_IMAGE_PIXELS``; a file larger than any image of that many pixels
could be (:func:`max_file_bytes`) is refused without reading it all.
"""

from __future__ import annotations

import io
import os
import struct
import sys
from pathlib import Path

import cv2
import numpy as np

from station.bounded_read import BoundedReadError, read_regular_file
from station.errors import HarpError

MAX_PIXELS = 200_000_000
"""Default pixel-count limit of :func:`read_unchanged` (``HARP_MAX_IMAGE_PIXELS`` overrides it)."""

MAX_PIXELS_ENV = "HARP_MAX_IMAGE_PIXELS"


def max_pixels_limit() -> int:
    """The pixel-count limit in force: ``HARP_MAX_IMAGE_PIXELS`` when set to an integer >= 1, else :data:`MAX_PIXELS`."""
    text = os.environ.get(MAX_PIXELS_ENV, "").strip()
    if text:
        try:
            value = int(float(text))
        except ValueError:
            value = 0
        if value >= 1:
            return value
    return MAX_PIXELS


def max_file_bytes(max_pixels: int) -> int:
    """Largest file accepted for ``max_pixels``: 16 bytes a pixel (32-bit float RGBA) plus 1 MiB of headers."""
    return 16 * int(max_pixels) + (1 << 20)


class ImageReadError(HarpError):
    """An image file could not be read; ``str(exc)`` is a one-line message."""

    def __init__(self, path, reason: str):
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")


def _pnm_header_fields(data: bytes, count: int, limit: int) -> tuple[list[int], int] | None:
    """The first ``count`` numbers of a PNM header (after the magic, comments skipped), read from
    ``data[:limit]``, and the index just past the last one; ``None`` when a field is not a number.
    Fewer than ``count`` numbers come back when the header ends before them."""
    fields: list[int] = []
    i, n = 2, min(len(data), limit)
    while len(fields) < count and i < n:
        c = data[i : i + 1]
        if c == b"#":
            while i < n and data[i : i + 1] not in (b"\n", b"\r"):
                i += 1
        elif c.isspace():
            i += 1
        else:
            j = i
            while j < n and data[j : j + 1].isdigit():
                j += 1
            if j == i:
                return None
            fields.append(int(data[i:j]))
            i = j
    return fields, i


def _pnm_truncated(data: bytes) -> str | None:
    """For a binary PNM (P5/P6), a reason if the pixel data is short."""
    if len(data) < 2 or data[:1] != b"P" or data[1:2] not in (b"5", b"6"):
        return None
    n = len(data)
    header = _pnm_header_fields(data, 3, n)
    if header is None:
        return "malformed PNM header"
    fields, i = header
    if len(fields) < 3:
        return "truncated PNM header"
    i += 1  # the single whitespace after maxval
    w, h, maxval = fields
    channels = 3 if data[1:2] == b"6" else 1
    need = w * h * channels * (2 if maxval > 255 else 1)
    have = n - i
    if have < need:
        return f"truncated: {have} of {need} bytes of pixel data"
    return None


def read_unchanged(path, *, max_pixels: int | None = None) -> np.ndarray:
    """Read an image file keeping its channels and bit depth (``cv2.IMREAD_UNCHANGED``).

    Parameters
    ----------
    path : str or Path
    max_pixels : int, optional
        Refuse an image of more pixels than this (default :func:`max_pixels_limit`).

    Returns
    -------
    ndarray
        ``image[y, x]`` or ``image[y, x, channel]`` (OpenCV's BGR(A) order),
        as stored in the file.

    Raises
    ------
    ImageReadError
        With a one-line reason naming the file: missing, a directory, not a
        regular file, unreadable, empty, too large, truncated, not an image.
    """
    p = Path(path)
    limit = max_pixels_limit() if max_pixels is None else int(max_pixels)
    data = _read_regular_file(p, max_file_bytes(limit))
    if not data:
        raise ImageReadError(p, "empty file")
    size = header_size(data)
    if size is not None and size[0] * size[1] > limit:
        raise ImageReadError(p, _too_large(size[0], size[1], limit))
    reason = _pnm_truncated(data)
    if reason:
        raise ImageReadError(p, reason)
    # before decoding: libpng prints its own "libpng error: ..." line straight to
    # the C stderr on a short PNG, which would break the one-line error
    if _looks_truncated(data):
        raise ImageReadError(p, "truncated image data")
    buf = np.frombuffer(data, np.uint8)
    try:
        with quiet_codecs():
            img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    except cv2.error:  # OpenCV's own size limit, or a decoder that gave up
        raise ImageReadError(p, "not a readable image (corrupt, or larger than the decoder allows)") from None
    except MemoryError:
        raise ImageReadError(p, "too large to decode in the memory available") from None
    if img is None:
        raise ImageReadError(p, "not a readable image (unknown format or corrupt/truncated data)")
    if img.shape[0] * img.shape[1] > limit:
        raise ImageReadError(p, _too_large(img.shape[1], img.shape[0], limit))
    return img


def _too_large(w: int, h: int, limit: int) -> str:
    return (
        f"image too large: {w}x{h} = {w * h} pixels, the limit is {limit} (set {MAX_PIXELS_ENV} to read larger images)"
    )


def _read_regular_file(p: Path, max_bytes: int) -> bytes:
    """The bytes of the regular file ``p`` (at most ``max_bytes``), or :class:`ImageReadError`."""
    try:
        return read_regular_file(p, max_bytes, what="an image file")
    except BoundedReadError as exc:
        raise ImageReadError(p, exc.reason) from None


def header_size(data: bytes) -> tuple[int, int] | None:
    """``(width, height)`` claimed by the header of a PNG, TIFF, JPEG, PNM, BMP or WebP file;
    None for another format or a header too short or malformed to tell (the decoder then judges)."""
    try:
        if data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR":
            return struct.unpack(">II", data[16:24])
        if data[:4] in (b"II*\x00", b"MM\x00*"):
            return _tiff_size(data)
        if data[:2] == b"\xff\xd8":
            return _jpeg_size(data)
        if data[:1] == b"P" and data[1:2] in b"123456":
            return _pnm_size(data)
        if data[:2] == b"BM" and len(data) >= 26:
            w, h = struct.unpack("<ii", data[18:26])
            return abs(w), abs(h)
        if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
            return _webp_size(data)
    except (struct.error, IndexError, ValueError):
        return None
    return None


def _tiff_size(data: bytes) -> tuple[int, int] | None:
    """Width and height (tags 256, 257) of the first image file directory."""
    e = "<" if data[:2] == b"II" else ">"
    (ifd,) = struct.unpack(e + "I", data[4:8])
    (n,) = struct.unpack(e + "H", data[ifd : ifd + 2])
    found: dict[int, int] = {}
    for k in range(n):
        entry = data[ifd + 2 + 12 * k : ifd + 14 + 12 * k]
        tag, typ, _count = struct.unpack(e + "HHI", entry[:8])
        if tag in (256, 257):
            found[tag] = struct.unpack(e + ("H" if typ == 3 else "I"), entry[8:10] if typ == 3 else entry[8:12])[0]
    if 256 in found and 257 in found:
        return found[256], found[257]
    return None


def _jpeg_size(data: bytes) -> tuple[int, int] | None:
    """Width and height of the first start-of-frame marker (SOF0..SOF15 but DHT/JPG/DAC)."""
    i = 2
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        (length,) = struct.unpack(">H", data[i + 2 : i + 4])
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            h, w = struct.unpack(">HH", data[i + 5 : i + 9])
            return w, h
        if marker == 0xDA:  # start of scan before any frame header
            return None
        i += 2 + length
    return None


def _pnm_size(data: bytes) -> tuple[int, int] | None:
    header = _pnm_header_fields(data, 2, 4096)
    if header is None:
        return None
    fields = header[0]
    return (fields[0], fields[1]) if len(fields) == 2 else None


def _webp_size(data: bytes) -> tuple[int, int] | None:
    kind = data[12:16]
    if kind == b"VP8X":
        w = int.from_bytes(data[24:27], "little") + 1
        h = int.from_bytes(data[27:30], "little") + 1
        return w, h
    if kind == b"VP8 ":
        w, h = struct.unpack("<HH", data[26:30])
        return w & 0x3FFF, h & 0x3FFF
    if kind == b"VP8L":
        bits = int.from_bytes(data[21:25], "little")
        return (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
    return None


def read_grey(path, *, max_pixels: int | None = None) -> np.ndarray:
    """Read an image file as a 2-D grey ``image[y, x]``: ``uint8`` or ``uint16``
    (float TIFFs as float32).

    Raises :class:`ImageReadError` as :func:`read_unchanged` does, and for an
    unsupported layout or pixel type, or an image under 16x16.
    """
    return _to_grey(read_unchanged(path, max_pixels=max_pixels), Path(path))


class quiet_codecs:
    """Silence OpenCV's own log lines and what its codecs print straight to the C-level
    stderr ("libpng error: ...", "Corrupt JPEG data: ...") while decoding: our one-line error
    says it all. (File descriptor 2 points at /dev/null meanwhile, for the whole process: the
    ``harp`` commands decode in their main thread.) ``stdout=True`` silences file descriptor 1 and
    Python's ``sys.stdout`` too, for a decoder that prints there (OpenEXR's "Warning: Exception raised
    reading pixel data ..." of a damaged file); what the command printed before is flushed first."""

    def __init__(self, *, stdout: bool = False) -> None:
        self._fds = (1, 2) if stdout else (2,)

    def __enter__(self):
        self._saved: list[tuple[int, int]] = []
        for fd, stream in ((1, sys.stdout), (2, sys.stderr)):
            if fd not in self._fds:
                continue
            try:
                stream.flush()
                saved = os.dup(fd)
                null = os.open(os.devnull, os.O_WRONLY)
                try:
                    os.dup2(null, fd)
                finally:
                    os.close(null)
                self._saved.append((fd, saved))
            except (OSError, ValueError, AttributeError):  # no such descriptor to redirect: leave it
                pass
        self._stdout = sys.stdout
        if 1 in self._fds:  # and what a decoder writes through Python's sys.stdout
            sys.stdout = io.StringIO()
        self._lg = getattr(getattr(cv2, "utils", None), "logging", None)
        self._old = None
        if self._lg is not None:
            try:
                self._old = self._lg.getLogLevel()
                self._lg.setLogLevel(self._lg.LOG_LEVEL_SILENT)
            except Exception:  # pragma: no cover - logging API absent
                self._lg = None
        return self

    def __exit__(self, *exc):
        if self._lg is not None and self._old is not None:
            self._lg.setLogLevel(self._old)
        sys.stdout = self._stdout
        for fd, saved in self._saved:
            os.dup2(saved, fd)
            os.close(saved)
        return False


def _looks_truncated(data: bytes) -> bool:
    """PNG and JPEG decoders may fill a short file with grey; check the end markers."""
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return b"IEND" not in data[-32:]
    if data[:2] == b"\xff\xd8":
        return not data.rstrip(b"\x00").endswith(b"\xff\xd9")
    return False


def _to_grey(img: np.ndarray, p: Path) -> np.ndarray:
    if img.ndim == 2:
        out = img
    elif img.ndim == 3 and img.shape[2] == 1:
        out = img[:, :, 0]
    elif img.ndim == 3 and img.shape[2] in (3, 4):
        bgr = img[:, :, :3].astype(np.float64)
        y = 0.114 * bgr[:, :, 0] + 0.587 * bgr[:, :, 1] + 0.299 * bgr[:, :, 2]
        if np.issubdtype(img.dtype, np.integer):
            info = np.iinfo(img.dtype)
            out = np.clip(np.rint(y), info.min, info.max).astype(img.dtype)
        else:
            out = y.astype(np.float32)
    else:
        raise ImageReadError(p, f"unsupported image layout {img.shape}")
    if out.dtype not in (np.uint8, np.uint16, np.float32):
        if np.issubdtype(out.dtype, np.floating):
            out = out.astype(np.float32)
        else:
            raise ImageReadError(p, f"unsupported pixel type {out.dtype}")
    if out.shape[0] < 16 or out.shape[1] < 16:
        raise ImageReadError(p, f"image too small ({out.shape[1]}x{out.shape[0]})")
    return np.ascontiguousarray(out)
