"""The bytes of a session's frame files: lossless PNG (written), PNG or binary PGM (read).

A frame is what the camera gave, a 2-D ``uint8`` or ``uint16`` array, and its file holds every
bit of it: :func:`encode_frame` writes a grey PNG of the same depth (8 or 16 bit), compressed with
zlib level :data:`PNG_LEVEL`, the ``filtered`` strategy and libpng's adaptive choice of row filter
per row (on the demo's 1280x960 8-bit frames 0.47 of the PGM's bytes in 0.1 s of CPU a frame:
``benchmarks/session_disk.py``). Camera noise is what is left after any predictor, so no lossless
codec does much better (JPEG 2000 lossless: 0.45 in 0.43 s). :func:`decode_frame` reads a frame
file by its first bytes, so the binary PGM (P5) frames of sessions written before (``.pgm``,
:func:`encode_pgm`) are read, resumed and reprocessed as they are; the manifest names each frame's
file, so a resumed old session simply has frames of both kinds.
"""

from __future__ import annotations

import re

import cv2
import numpy as np

PNG_LEVEL = 4
"""zlib level of a frame PNG: on the demo's frames the smallest files per CPU second (level 3:
9 % larger; level 6: as large, in 3.6 times the time)."""

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _check(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim != 2 or image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"a frame must be a 2-D uint8/uint16 array, got {image.dtype} {image.shape}")
    return np.ascontiguousarray(image)


def encode_frame(image: np.ndarray) -> bytes:
    """Lossless grey PNG of a 2-D ``uint8`` or ``uint16`` frame (16-bit PNG for ``uint16``)."""
    image = _check(image)
    ok, png = cv2.imencode(
        ".png",
        image,
        [
            cv2.IMWRITE_PNG_COMPRESSION,
            PNG_LEVEL,
            cv2.IMWRITE_PNG_STRATEGY,
            cv2.IMWRITE_PNG_STRATEGY_FILTERED,
            cv2.IMWRITE_PNG_FILTER,
            cv2.IMWRITE_PNG_ALL_FILTERS,
        ],
    )
    if not ok:
        raise ValueError(f"a {image.dtype} {image.shape} frame could not be encoded as PNG")
    return png.tobytes()


def decode_frame(data: bytes) -> np.ndarray:
    """The frame array of a frame file's bytes: PNG (:func:`encode_frame`) or binary PGM
    (:func:`encode_pgm`, older sessions); ``ValueError`` naming what is wrong otherwise."""
    if data[:8] == PNG_SIGNATURE:
        if b"IEND" not in data[-32:]:
            raise ValueError("truncated PNG frame")
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ValueError("not a readable PNG frame (corrupt data)")
        if img.ndim != 2 or img.dtype not in (np.uint8, np.uint16):
            raise ValueError(f"not a grey 8- or 16-bit frame ({img.dtype} {img.shape})")
        return img
    if data[:2] == b"P5":
        return decode_pgm(data)
    raise ValueError("not a frame file (neither PNG nor binary PGM)")


def encode_pgm(image: np.ndarray) -> bytes:
    """Binary PGM (P5) of a 2-D uint8 or uint16 array (16-bit big-endian): the frame files of
    sessions written before PNG frames."""
    image = _check(image)
    maxval = 255 if image.dtype == np.uint8 else 65535
    h, w = image.shape
    body = image.astype(">u2").tobytes() if maxval == 65535 else image.tobytes()
    return f"P5\n{w} {h}\n{maxval}\n".encode("ascii") + body


def decode_pgm(data: bytes) -> np.ndarray:
    """Inverse of :func:`encode_pgm` (also reads PGMs with comments)."""
    m = re.match(rb"P5\s+(?:#[^\n]*\n\s*)*(\d+)\s+(?:#[^\n]*\n\s*)*(\d+)\s+(?:#[^\n]*\n\s*)*(\d+)\s", data)
    if not m:
        raise ValueError("not a binary PGM (P5) file")
    w, h, maxval = (int(g) for g in m.groups())
    dtype = np.uint8 if maxval < 256 else np.dtype(">u2")
    n = w * h * (1 if maxval < 256 else 2)
    body = data[m.end() : m.end() + n]
    if len(body) != n:
        raise ValueError(f"truncated PGM: {len(body)} of {n} bytes")
    img = np.frombuffer(body, dtype=dtype).reshape(h, w)
    return img.astype(np.uint16) if maxval >= 256 else img.copy()
