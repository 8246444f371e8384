"""An independent packer for the packed raw pixel formats, the truth the unpacker (drivers/frames.py) is tested
against.

It is written from the standards' byte tables, not from the driver's shifts and masks: each layout below is the
table as the standard prints it, one string per byte, its bits from bit 7 down to bit 0 (``P1[3:0]`` is pixel
1's bits 3 to 0, ``-`` a bit the format leaves zero). The packer spreads every pixel into its bits
(``numpy.unpackbits``), gathers each byte's eight bits from the table, and packs them again
(``numpy.packbits``): a bit-by-bit path that shares nothing with the unpacker's arithmetic.

Sources of the tables:

* GenICam PFNC 2.x, ``Mono10p`` / ``Mono12p`` figures (lsb-first packing);
* GigE Vision 2.x, ``Mono10Packed`` / ``Mono12Packed`` figures (the low bits in the middle byte; with an odd
  number of pixels the next line does not start on a 3-byte boundary);
* Linux kernel documentation, ``V4L2_PIX_FMT_SRGGB10P`` / ``Y10P`` ("each of the first 4 bytes contain the
  8 high order bits of the pixels, and the 5th byte contains the 2 least significant bits of each pixel, in
  the same order": bits 7--6 pixel 3 ... bits 1--0 pixel 0) and ``V4L2_PIX_FMT_SRGGB12P`` (third byte:
  bits 7--4 pixel 1's low bits, bits 3--0 pixel 0's).
"""

from __future__ import annotations

import re

import numpy as np

LAYOUTS = {
    "pfnc10": ["P0[7:0]", "P1[5:0] P0[9:8]", "P2[3:0] P1[9:6]", "P3[1:0] P2[9:4]", "P3[9:2]"],
    "pfnc12": ["P0[7:0]", "P1[3:0] P0[11:8]", "P1[11:4]"],
    "gige10": ["P0[9:2]", "- - P1[1:0] - - P0[1:0]", "P1[9:2]"],
    "gige12": ["P0[11:4]", "P1[3:0] P0[3:0]", "P1[11:4]"],
    "csi10": ["P0[9:2]", "P1[9:2]", "P2[9:2]", "P3[9:2]", "P3[1:0] P2[1:0] P1[1:0] P0[1:0]"],
    "csi12": ["P0[11:4]", "P1[11:4]", "P1[3:0] P0[3:0]"],
}
"""Packing -> the bytes of one group, each from its bit 7 down to bit 0."""

#: format -> (packing, bits)
FORMATS = {
    **{f"Mono{b}p": (f"pfnc{b}", b) for b in (10, 12)},
    **{f"Bayer{xy}{b}p": (f"pfnc{b}", b) for b in (10, 12) for xy in ("RG", "GR", "GB", "BG")},
    **{f"Mono{b}Packed": (f"gige{b}", b) for b in (10, 12)},
    **{f"Bayer{xy}{b}Packed": (f"gige{b}", b) for b in (10, 12) for xy in ("RG", "GR", "GB", "BG")},
    **{f: ("csi10", 10) for f in ("pRAA", "pgAA", "pGAA", "pBAA", "Y10P")},
    **{f: ("csi12", 12) for f in ("pRCC", "pgCC", "pGCC", "pBCC", "Y12P")},
}


def _sources(layout: list[str]) -> tuple[int, list[tuple[int, int]]]:
    """The pixels per group and, for every bit of the group (byte by byte, bit 7 first), its (pixel, bit);
    pixel -1: a zero bit."""
    bits: list[tuple[int, int]] = []
    for byte in layout:
        here: list[tuple[int, int]] = []
        for field in byte.split():
            if field == "-":
                here.append((-1, 0))
                continue
            m = re.fullmatch(r"P(\d)\[(\d+):(\d+)\]", field)
            assert m, field
            p, hi, lo = (int(g) for g in m.groups())
            here += [(p, b) for b in range(hi, lo - 1, -1)]
        assert len(here) == 8, byte
        bits += here
    return 1 + max(p for p, _ in bits), bits


def pack(values: np.ndarray, packing: str, bits: int) -> bytes:
    """Pack ``values`` (a 1-D sequence of ``bits``-bit pixels, a whole number of groups) by the layout table."""
    values = np.asarray(values, dtype=np.uint16).ravel()
    assert values.max(initial=0) < 1 << bits
    per_group, sources = _sources(LAYOUTS[packing])
    assert values.size % per_group == 0, (values.size, per_group)
    # (groups, pixels, 16) bits of each value, column b = bit b
    value_bits = np.unpackbits(values.astype(">u2").view(np.uint8).reshape(-1, 2), axis=1)[:, ::-1]
    value_bits = np.concatenate([value_bits, np.zeros((values.size, 1), np.uint8)], axis=1)  # column 16: a zero
    grouped = value_bits.reshape(-1, per_group, 17)
    pixel = np.array([p if p >= 0 else 0 for p, _ in sources])
    bit = np.array([b if p >= 0 else 16 for p, b in sources])
    out_bits = grouped[:, pixel, bit]  # (groups, 8 * bytes), bit 7 of each byte first
    return np.packbits(out_bits, axis=1, bitorder="big").tobytes()


def pack_stream(values: np.ndarray, fmt: str) -> bytes:
    """A GenICam frame as the camera sends it: all the pixels (row after row) one stream, the last group filled
    with zero pixels and cut to the bytes the pixels occupy (10 bits a pixel for PFNC 10p, 12 for the others)."""
    packing, bits = FORMATS[fmt]
    values = np.asarray(values).ravel()
    per_group, _ = _sources(LAYOUTS[packing])
    n = values.size
    whole = np.concatenate([values, np.zeros(-n % per_group, values.dtype)])
    wire_bits = 8 * len(LAYOUTS[packing]) // per_group
    return pack(whole, packing, bits)[: -(-n * wire_bits // 8)]


def pack_rows(image: np.ndarray, fmt: str, padding: int = 0, fill: int = 0xEE) -> tuple[bytes, int]:
    """A V4L2 frame: each row packed on its own (a whole number of groups), then ``padding`` bytes of ``fill``;
    returns the bytes and the row stride (``bytesperline``)."""
    packing, bits = FORMATS[fmt]
    rows = [pack(row, packing, bits) for row in np.asarray(image)]
    stride = len(rows[0]) + padding
    return b"".join(r + bytes([fill]) * padding for r in rows), stride
