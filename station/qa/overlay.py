"""Overlay PNG of a measurement: what was measured, how bent, what was rejected.

The photograph (contrast-stretched grey, dimmed) with

* every measured edge drawn over its raw sub-pixel points, coloured by the
  signed distance of each point to the edge's regression line (colour bar
  from ``-r`` blue to ``+r`` red, ``r`` the largest distance in the image),
  and its string number written next to it;
* every rejected group drawn in magenta; groups of at least
  ``LABEL_MIN_POINTS`` points get a box and the reason;
* a legend panel under the image with the colour bar, ``d``, ``d_max`` and
  the number of lines and strings.

:func:`write_overlay` writes it full size as PNG (``harp measure --overlay``), or, for a file named
``.jpg`` and a ``max_side``, sized for a screen: shrunk (pixel area averaging) to at most
``max_side`` pixels along its longer side and JPEG-compressed at :data:`JPEG_QUALITY` (the
session report's overlays, :data:`SCREEN_MAX_SIDE`: ~0.2 MB instead of 1.2 MB on the demo).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from pipeline.measure import ImageMeasurement
from pipeline.straightness import fit_line
from station.files import atomic_write_bytes

REJECT_BGR = (255, 0, 255)
LABEL_MIN_POINTS = 100

SCREEN_MAX_SIDE = 1600
"""Longest side (px) of an overlay sized for a screen (a report page is at most ~1100 px wide)."""
JPEG_QUALITY = 85
"""JPEG quality of an overlay sized for a screen."""


def _display_grey(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image, dtype=np.float64)
    lo, hi = np.percentile(img[:: max(1, img.shape[0] // 256), :: max(1, img.shape[1] // 256)], (0.5, 99.5))
    if not hi > lo:
        lo, hi = float(img.min()), float(img.max()) + 1e-9
    g = np.clip((img - lo) / (hi - lo), 0, 1)
    return (40 + 150 * g).astype(np.uint8)  # dimmed so that colours stand out


def _splat(canvas, xy, colors, radius):
    """Paint coloured points (dilated to ``radius``) onto ``canvas`` in place."""
    h, w = canvas.shape[:2]
    ij = np.rint(xy).astype(np.int64)
    ok = (ij[:, 0] >= 0) & (ij[:, 0] < w) & (ij[:, 1] >= 0) & (ij[:, 1] < h)
    ij, colors = ij[ok], colors[ok]
    layer = np.zeros_like(canvas)
    mask = np.zeros((h, w), np.uint8)
    layer[ij[:, 1], ij[:, 0]] = colors
    mask[ij[:, 1], ij[:, 0]] = 255
    if radius > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
        layer = cv2.dilate(layer, k)
        mask = cv2.dilate(mask, k)
    m = mask > 0
    canvas[m] = layer[m]


def _colormap(values: np.ndarray, vmax: float) -> np.ndarray:
    """Blue (-vmax) -> white-ish (0) -> red (+vmax), BGR uint8."""
    u = np.clip(0.5 + 0.5 * values / vmax, 0, 1)
    lut = cv2.applyColorMap(np.arange(256, dtype=np.uint8).reshape(-1, 1), cv2.COLORMAP_JET)[:, 0, :]
    return lut[np.rint(u * 255).astype(np.int64)]


def render_overlay(image: np.ndarray, m: ImageMeasurement, title: str = "") -> np.ndarray:
    """The overlay as a BGR ``uint8`` array (image on top, legend panel below)."""
    h, w = image.shape[:2]
    grey = _display_grey(image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY))
    canvas = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    scale = max(w, h) / 1000.0
    radius = max(1, int(round(1.2 * scale)))
    thick = max(1, int(round(1.5 * scale)))
    font = cv2.FONT_HERSHEY_SIMPLEX
    fs = 0.5 * scale

    if m.rejected_points:
        rxy = np.concatenate(m.rejected_points)
        _splat(canvas, rxy, np.tile(np.array(REJECT_BGR, np.uint8), (len(rxy), 1)), radius)
    labelled = set()
    big = sorted(zip(m.rejected, m.rejected_points), key=lambda rx: -rx[0].n_points)
    for r, _xy in big:
        if r.n_points >= LABEL_MIN_POINTS:
            x0, y0, x1, y1 = (int(round(v)) for v in r.bbox)
            cv2.rectangle(canvas, (x0 - 3, y0 - 3), (x1 + 3, y1 + 3), REJECT_BGR, thick)
            ty = y0 - 8 if y0 > 30 * scale else y1 + int(20 * scale)
            tx = min(max(x0, 2), max(2, w - int(len(r.reason) * 9 * fs)))
            # one label per reason and neighbourhood, to keep it legible
            key = (r.reason, int(x0 // (150 * scale)), int(y0 // (150 * scale)))
            if key not in labelled:
                labelled.add(key)
                cv2.putText(canvas, r.reason, (tx, ty), font, fs, REJECT_BGR, thick, cv2.LINE_AA)

    residuals = []
    for ln in m.lines:
        f = fit_line(ln.points)
        residuals.append((ln.raw_points - f.centroid) @ f.normal)
    vmax = max([float(np.max(np.abs(s))) for s in residuals] + [1e-3])
    if m.lines:
        _splat(
            canvas,
            np.concatenate([ln.raw_points for ln in m.lines]),
            _colormap(np.concatenate(residuals), vmax),
            radius,
        )
    # string numbers, at the middle of the first edge of each string
    seen = set()
    for ln in m.lines:
        if ln.string_id in seen:
            continue
        seen.add(ln.string_id)
        p = ln.raw_points[len(ln.raw_points) // 2]
        org = (int(np.clip(p[0] + 6 * scale, 0, w - 30 * scale)), int(np.clip(p[1] - 6 * scale, 20 * scale, h - 2)))
        cv2.putText(canvas, str(ln.string_id), org, font, 1.2 * fs, (0, 255, 255), thick, cv2.LINE_AA)

    # legend panel
    ph = int(110 * scale)
    panel = np.full((ph, w, 3), 255, np.uint8)
    bar_w = int(0.35 * w)
    x0, y0, bh = int(20 * scale), int(15 * scale), int(20 * scale)
    ramp = _colormap(np.linspace(-vmax, vmax, bar_w), vmax)
    panel[y0 : y0 + bh, x0 : x0 + bar_w] = ramp[None, :, :]
    cv2.rectangle(panel, (x0, y0), (x0 + bar_w, y0 + bh), (0, 0, 0), 1)
    ty = y0 + bh + int(22 * scale)
    for frac, lab in ((0.0, f"-{vmax:.2f}"), (0.5, "0"), (1.0, f"+{vmax:.2f} px")):
        tx = x0 + int(frac * bar_w) - int(10 * scale)
        cv2.putText(panel, lab, (max(tx, 0), ty), font, fs, (0, 0, 0), thick, cv2.LINE_AA)
    cv2.putText(
        panel,
        "signed distance to the edge's regression line",
        (x0, ty + int(28 * scale)),
        font,
        fs,
        (0, 0, 0),
        thick,
        cv2.LINE_AA,
    )
    tx = x0 + bar_w + int(110 * scale)
    d = "n/a" if not np.isfinite(m.d) else f"{m.d:.4f} px"
    dm = "n/a" if not np.isfinite(m.d_max) else f"{m.d_max:.4f} px"
    lines = [
        f"{title}" if title else "",
        f"d = {d}   d_max = {dm}",
        f"{m.n_lines} edges of {m.n_strings} strings, t = {m.t}",
    ]
    yy = y0 + int(12 * scale)
    for text in [t for t in lines if t]:
        cv2.putText(panel, text, (tx, yy), font, fs, (0, 0, 0), thick, cv2.LINE_AA)
        yy += int(25 * scale)
    cv2.rectangle(panel, (tx, yy - int(10 * scale)), (tx + int(20 * scale), yy + int(4 * scale)), REJECT_BGR, -1)
    cv2.putText(
        panel,
        f"rejected: {len(m.rejected)} groups (frame, dust, fragments)",
        (tx + int(28 * scale), yy),
        font,
        fs,
        (0, 0, 0),
        thick,
        cv2.LINE_AA,
    )
    return np.vstack([canvas, panel])


def screen_sized(picture: np.ndarray, max_side: int) -> np.ndarray:
    """``picture`` shrunk (area averaging) so that its longer side is at most ``max_side`` pixels."""
    h, w = picture.shape[:2]
    scale = max_side / max(h, w)
    if scale >= 1:
        return picture
    size = (max(1, int(round(w * scale))), max(1, int(round(h * scale))))
    return cv2.resize(picture, size, interpolation=cv2.INTER_AREA)


def write_overlay(
    path, image: np.ndarray, m: ImageMeasurement, title: str = "", *, max_side: int | None = None
) -> Path:
    """Write the overlay to ``path``: PNG, or JPEG (:data:`JPEG_QUALITY`) for a ``.jpg``/``.jpeg``
    name; ``max_side``: shrunk to at most that many pixels along its longer side. Returns the path."""
    out = Path(path)
    picture = render_overlay(image, m, title)
    if max_side is not None:
        picture = screen_sized(picture, max_side)
    if out.suffix.lower() in (".jpg", ".jpeg"):
        # optimised Huffman tables, progressive: 7 % fewer bytes for the same pixels
        params = [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY, cv2.IMWRITE_JPEG_OPTIMIZE, 1, cv2.IMWRITE_JPEG_PROGRESSIVE, 1]
        ok, data = cv2.imencode(".jpg", picture, params)
    else:
        ok, data = cv2.imencode(".png", picture)
    if not ok:
        raise ValueError(f"{out}: the overlay could not be encoded")
    atomic_write_bytes(out, data.tobytes())  # a full disk is an OSError with its errno, not a libpng message
    return out
