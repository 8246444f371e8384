"""Reading harp photographs from files.

:func:`read_grey` reads PGM/PPM, PNG, TIFF and JPEG files (8 or 16 bit,
grey or colour) into a 2-D grey array, keeping the bit depth: ``uint8`` or
``uint16``; :func:`read_unchanged` reads them as stored (channels and bit
depth kept), with the same checks. Colour is converted to grey with the ITU-R BT.601 luma weights
(``0.299 R + 0.587 G + 0.114 B``, what ``cv2.cvtColor`` does), computed in
float and rounded back to the input depth. An alpha channel is dropped.

Every failure raises :class:`ImageReadError` with a one-line message that
names the file and the reason: missing, a directory, unreadable
(permissions), empty, not an image, truncated, unsupported layout.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np


class ImageReadError(Exception):
    """An image file could not be read; ``str(exc)`` is a one-line message."""

    def __init__(self, path, reason: str):
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")


def _pnm_truncated(data: bytes) -> str | None:
    """For a binary PNM (P5/P6), a reason if the pixel data is short."""
    if len(data) < 2 or data[:1] != b"P" or data[1:2] not in (b"5", b"6"):
        return None
    fields: list[int] = []
    i = 2
    n = len(data)
    while len(fields) < 3 and i < n:
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
                return "malformed PNM header"
            fields.append(int(data[i:j]))
            i = j
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


def read_unchanged(path) -> np.ndarray:
    """Read an image file keeping its channels and bit depth (``cv2.IMREAD_UNCHANGED``).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    ndarray
        ``image[y, x]`` or ``image[y, x, channel]`` (OpenCV's BGR(A) order),
        as stored in the file.

    Raises
    ------
    ImageReadError
        With a one-line reason naming the file: missing, a directory,
        unreadable, empty, truncated, not an image.
    """
    p = Path(path)
    if not p.exists():
        raise ImageReadError(p, "no such file")
    if p.is_dir():
        raise ImageReadError(p, "is a directory, not an image file")
    if not os.access(p, os.R_OK):
        raise ImageReadError(p, "permission denied")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise ImageReadError(p, f"cannot read: {exc.strerror or exc}") from None
    if not data:
        raise ImageReadError(p, "empty file")
    reason = _pnm_truncated(data)
    if reason:
        raise ImageReadError(p, reason)
    # before decoding: libpng prints its own "libpng error: ..." line straight to
    # the C stderr on a short PNG, which would break the one-line error
    if _looks_truncated(data):
        raise ImageReadError(p, "truncated image data")
    buf = np.frombuffer(data, np.uint8)
    with _quiet_opencv():
        img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageReadError(p, "not a readable image (unknown format or corrupt/truncated data)")
    return img


def read_grey(path) -> np.ndarray:
    """Read an image file as a 2-D grey ``image[y, x]``: ``uint8`` or ``uint16``
    (float TIFFs as float32).

    Raises :class:`ImageReadError` as :func:`read_unchanged` does, and for an
    unsupported layout or pixel type, or an image under 16x16.
    """
    return _to_grey(read_unchanged(path), Path(path))


class _quiet_opencv:
    """Silence OpenCV's own log lines (our error message says it all)."""

    def __enter__(self):
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
