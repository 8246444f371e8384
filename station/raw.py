"""Camera RAW files read by LibRaw (rawpy): the Bayer mosaic as recorded, never demosaiced.

:func:`read_raw` returns the visible area of the sensor's mosaic (``uint16``, black
level not subtracted: the edge detector sees gradients) and its 2 x 2 CFA pattern
(:data:`pipeline.cfa.CFA_PATTERNS`), read from LibRaw's ``raw_pattern`` and
``color_desc``; the visible area's top-left pixel starts the pattern. What LibRaw cannot
read, or a sensor that is not a 2 x 2 Bayer mosaic (X-Trans, Foveon, a linear DNG
already demosaiced, a monochrome sensor), is an :class:`~station.imageio.ImageReadError`
with one line naming the file and the reason.

:func:`is_raw_path` decides by the file name's suffix (:data:`RAW_SUFFIXES`), so that
``harp`` never hands a PNG to LibRaw nor a RAW file to the image decoders; rawpy is
imported only when a RAW file is read.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.cfa import CFA_PATTERNS
from station.imageio import ImageReadError, max_file_bytes, max_pixels_limit

RAW_SUFFIXES = frozenset(
    ".3fr .ari .arw .cr2 .cr3 .crw .dcr .dng .erf .fff .iiq .k25 .kdc .mef .mos .mrw .nef .nrw .orf .pef "
    ".raf .raw .rw2 .rwl .sr2 .srf .srw .x3f".split()
)
"""File name suffixes of camera RAW formats (LibRaw's)."""


@dataclass(frozen=True)
class RawMosaic:
    """A RAW file's visible mosaic, its CFA pattern and levels."""

    mosaic: np.ndarray
    pattern: str
    black_level: float
    white_level: float


def is_raw_path(path) -> bool:
    """True when ``path``'s suffix is a camera RAW format's."""
    return Path(path).suffix.lower() in RAW_SUFFIXES


def read_raw(path) -> RawMosaic:
    """The Bayer mosaic of a camera RAW file, as recorded (module docstring).

    Raises
    ------
    ImageReadError
        One line naming the file: unreadable by LibRaw, not a 2 x 2 Bayer sensor, too large.
    """
    import rawpy

    p = Path(path)
    limit = max_pixels_limit()
    try:
        size = p.stat().st_size
    except FileNotFoundError:
        raise ImageReadError(p, "no such file") from None
    except OSError as exc:
        raise ImageReadError(p, f"cannot read: {exc.strerror or exc}") from None
    if not p.is_file():
        raise ImageReadError(p, "not a regular file; give a camera RAW file")
    if size > max_file_bytes(limit):
        raise ImageReadError(p, f"file too large for an image: {size} bytes")
    try:
        with rawpy.imread(str(p)) as raw:
            if raw.raw_type != rawpy.RawType.Flat or raw.num_colors != 3:
                raise ImageReadError(
                    p, "not a Bayer mosaic (a sensor LibRaw reads with another layout): give a Bayer RAW"
                )
            pat = np.asarray(raw.raw_pattern)
            desc = raw.color_desc.decode("ascii", "replace")
            if pat.shape != (2, 2):
                raise ImageReadError(
                    p, f"CFA pattern of {pat.shape[0]}x{pat.shape[1]} pixels (X-Trans?): only 2x2 Bayer sensors"
                )
            s = raw.sizes
            if s.height * s.width > limit:
                raise ImageReadError(p, f"image too large: {s.width}x{s.height} pixels, the limit is {limit}")
            vis = np.array(raw.raw_image_visible, dtype=np.uint16, copy=True)
            # raw_pattern is given for the visible area's top-left pixel (LibRaw's COLOR(row, col))
            pattern = "".join(desc[int(pat[r, c])] for r in (0, 1) for c in (0, 1))
            black = float(np.mean(raw.black_level_per_channel))
            white = float(raw.white_level)
    except ImageReadError:
        raise
    except rawpy.LibRawFileUnsupportedError:
        raise ImageReadError(p, "not a camera RAW file LibRaw can read (unsupported or unknown format)") from None
    except (rawpy.LibRawError, rawpy.NotSupportedError, OSError) as exc:
        raise ImageReadError(p, f"LibRaw cannot read it: {exc or type(exc).__name__}") from None
    if pattern not in CFA_PATTERNS:
        raise ImageReadError(p, f"CFA pattern {pattern!r} is not a Bayer pattern ({', '.join(CFA_PATTERNS)})")
    if vis.shape[0] < 8 or vis.shape[1] < 8:
        raise ImageReadError(p, f"mosaic of {vis.shape[1]}x{vis.shape[0]} pixels is too small")
    return RawMosaic(vis, pattern, black, white)
