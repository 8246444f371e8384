"""What the live page receives: the assessment as JSON figures in display pixels, and the frame as JPEG."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from pipeline.assess import Assessment
from pipeline.plain import finite_or_none

MAX_POINTS_PER_EDGE = 160
"""An edge drawn on the page is decimated to at most this many points."""
JPEG_QUALITY = 80


def display_size(width: int, height: int, display_width: int) -> tuple[int, int, float]:
    """``(w, h, factor)`` of the displayed frame: at most ``display_width`` wide, never enlarged."""
    f = min(1.0, display_width / float(width))
    return max(1, round(width * f)), max(1, round(height * f)), f


def encode_frame(image: NDArray[Any], display_width: int, full_scale: float) -> bytes:
    """The frame downscaled (area average) to the display size, 8-bit, as JPEG."""
    img = np.asarray(image)
    h, w = img.shape
    dw, dh, _ = display_size(w, h, display_width)
    small = cv2.resize(
        img if img.dtype in (np.uint8, np.uint16) else img.astype(np.float32), (dw, dh), interpolation=cv2.INTER_AREA
    )
    if small.dtype != np.uint8:
        small = np.clip(np.asarray(small, np.float64) * (255.0 / full_scale) + 0.5, 0, 255).astype(np.uint8)
    ok, buf = cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:  # cannot happen for a 2-D uint8 array
        raise ValueError("JPEG encoding failed")
    return bytes(buf.tobytes())


def _poly(xy: NDArray[np.float64], f: float) -> list[list[float]]:
    step = max(1, math.ceil(len(xy) / MAX_POINTS_PER_EDGE))
    pts = xy[::step]
    if len(xy) and (len(xy) - 1) % step:
        pts = np.vstack([pts, xy[-1:]])
    return np.round((pts + 0.5) * f - 0.5, 1).tolist()


def view_of(a: Assessment, warnings: list[str], display_width: int) -> dict[str, Any]:
    """The page's figures for one assessed frame; point coordinates in display pixels."""
    dw, dh, f = display_size(a.width, a.height, display_width)
    figures = a.to_dict()
    return {
        "display": {"width": dw, "height": dh, "factor": f},
        "figures": figures,
        "warnings": list(warnings),
        "ok": not warnings,
        "edges": [{"string": e.string_id, "polarity": e.polarity, "xy": _poly(e.xy, f)} for e in a.edges],
        "rejected": [
            {"reason": r.reason, "detail": r.detail, "xy": _poly(r.xy, f), "bbox": [round(v * f, 1) for v in r.bbox]}
            for r in a.rejected
        ],
        "strings": [
            {
                **s.to_dict(),
                "label_xy": [round((s.centre[0] + 0.5) * f - 0.5, 1), round((s.centre[1] + 0.5) * f - 0.5, 1)],
            }
            if math.isfinite(s.centre[0])
            else {**s.to_dict(), "label_xy": None}
            for s in a.strings
        ],
        "focus_score": finite_or_none(a.focus_score),
    }


def channels_view(offsets: dict[str, Any], pattern: str, counter: int) -> dict[str, Any]:
    """The colour panel's figures: per channel (red, blue) the edge points compared with green's, their RMS
    offset and the median outward offset per ring (:meth:`pipeline.tca.ChannelOffsets.summary`), of the
    frame ``counter`` whose ``pattern`` (a Bayer mosaic's) they were measured on."""
    return {
        "pattern": pattern,
        "frame": int(counter),
        "channels": [
            {k: finite_or_none(v) if isinstance(v, float) else v for k, v in o.summary().items()}
            for o in offsets.values()
        ],
    }
