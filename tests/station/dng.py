"""A minimal DNG writer (test helper): a Bayer mosaic as an uncompressed CFA DNG that LibRaw reads.

Written from the TIFF 6.0 and DNG 1.4 specifications (baseline little-endian TIFF, one
IFD, one strip; PhotometricInterpretation 32803 = CFA with CFARepeatPatternDim and
CFAPattern; DNGVersion, UniqueCameraModel, WhiteLevel, an identity ColorMatrix1), so
that the tests give ``harp`` a real camera RAW file without shipping one.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

_COLOUR_CODES = {"R": 0, "G": 1, "B": 2}
BYTE, ASCII, SHORT, LONG, SRATIONAL = 1, 2, 3, 4, 10
_SIZES = {BYTE: 1, ASCII: 1, SHORT: 2, LONG: 4, SRATIONAL: 8}
_FORMATS = {BYTE: "B", ASCII: "B", SHORT: "H", LONG: "I", SRATIONAL: "i"}


def write_dng(path: Path, mosaic: np.ndarray, pattern: str = "RGGB", black: int = 0, white: int = 65535) -> Path:
    """Write ``mosaic`` (2-D uint16) as a CFA DNG of the given 2x2 ``pattern``."""
    m = np.ascontiguousarray(mosaic, dtype="<u2")
    h, w = m.shape
    entries: list[tuple[int, int, list[int]]] = []

    def add(tag: int, typ: int, values) -> None:
        if typ == ASCII:
            values = list(values.encode("ascii")) + [0]
        entries.append((tag, typ, list(values)))

    header = 8
    add(254, LONG, [0])
    add(256, LONG, [w])
    add(257, LONG, [h])
    add(258, SHORT, [16])
    add(259, SHORT, [1])
    add(262, SHORT, [32803])
    add(271, ASCII, "Harp")
    add(272, ASCII, "Sim")
    add(273, LONG, [0])  # strip offset, set below
    add(274, SHORT, [1])
    add(277, SHORT, [1])
    add(278, LONG, [h])
    add(279, LONG, [m.nbytes])
    add(284, SHORT, [1])
    add(33421, SHORT, [2, 2])
    add(33422, BYTE, [_COLOUR_CODES[c] for c in pattern.upper()])
    add(50706, BYTE, [1, 4, 0, 0])
    add(50707, BYTE, [1, 1, 0, 0])
    add(50708, ASCII, "Harp Sim")
    add(50714, LONG, [black])
    add(50717, LONG, [white])
    add(50721, SRATIONAL, [1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1])
    add(50778, SHORT, [21])
    entries.sort()
    ifd_size = 2 + 12 * len(entries) + 4
    extra = bytearray()
    extra_at = header + ifd_size
    blobs: list[bytes] = []
    for _tag, typ, values in entries:
        blobs.append(struct.pack("<" + _FORMATS[typ] * len(values), *values))
    data_at = extra_at + sum(len(b) for b in blobs if len(b) > 4) + 16
    ifd = bytearray(struct.pack("<H", len(entries)))
    for (tag, typ, values), blob in zip(entries, blobs):
        count = len(values) // 2 if typ == SRATIONAL else len(values)
        if tag == 273:
            blob = struct.pack("<I", data_at)
        if len(blob) <= 4:
            ifd += struct.pack("<HHI", tag, typ, count) + blob.ljust(4, b"\0")
        else:
            ifd += struct.pack("<HHII", tag, typ, count, extra_at + len(extra))
            extra += blob
    ifd += struct.pack("<I", 0)
    out = bytearray(b"II*\0" + struct.pack("<I", header)) + ifd + extra
    out = out.ljust(data_at, b"\0") + m.tobytes()
    path = Path(path)
    path.write_bytes(bytes(out))
    return path
