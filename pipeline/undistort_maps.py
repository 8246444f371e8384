"""Fast ``cv2.remap`` maps for large images: exact inverse on a coarse grid, bicubic spline between.

:meth:`DistortionModel.undistortion_maps` inverts the model at every pixel
(Newton iterations), which costs seconds per megapixel. A distortion field is
smooth, so :func:`fast_undistortion_maps` inverts it exactly only on a grid
of nodes every ``step`` pixels (borders included) and interpolates with a
bicubic spline (``scipy.interpolate.RectBivariateSpline``). The interpolation
error is *measured*, not assumed: the exact inverse is also computed at the
centres of a sample of grid cells (where a spline is least accurate) and the
largest discrepancy is returned with the maps.

References
----------
.. [1] C. de Boor, *A Practical Guide to Splines*, Springer 1978 (tensor-product cubic splines).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import RectBivariateSpline

from pipeline.corrected_frame import CorrectedFrame
from pipeline.models.base import DistortionModel

DEFAULT_STEP_PX = 16
"""Node spacing of :func:`fast_undistortion_maps` (interpolation error ~1e-6 px on smooth lenses)."""


@dataclass(frozen=True)
class RemapMaps:
    """float32 maps for ``cv2.remap`` and their stated accuracy.

    Attributes
    ----------
    map_x, map_y : (H, W) float32
        Source (distorted) position of every corrected pixel.
    interp_error_px : float
        Largest |interpolated - exact| source position found at the check
        points (0.0 when the maps are exact per pixel). float32 storage adds
        up to half an ulp (2.4e-4 px at 4096-8191 px).
    step : int
        Node spacing (0: exact per-pixel maps).
    """

    map_x: np.ndarray
    map_y: np.ndarray
    interp_error_px: float
    step: int


def _nodes(n: int, step: int) -> np.ndarray:
    k = max(int(np.ceil((n - 1) / step)), 3) + 1
    return np.linspace(0.0, n - 1.0, k)


def fast_undistortion_maps(
    model: DistortionModel,
    width: int,
    height: int,
    step: int = DEFAULT_STEP_PX,
    n_check: int = 2000,
    seed: int = 0,
    frame: CorrectedFrame | None = None,
) -> RemapMaps:
    """Maps such that ``cv2.remap(img, map_x, map_y, ...)`` is the corrected image.

    The corrected pixel ``q`` is read from the distorted image at ``model.distort_points(u)``, ``u``
    its ideal position: ``u = q`` for the default frame (the photo's size, ``width`` x ``height``),
    ``frame.to_ideal(q)`` for another corrected image (:mod:`pipeline.corrected_frame`: another size,
    scale or principal point; the maps then have the frame's size). Images smaller than about 4 nodes
    per side, or models whose inverse is undefined somewhere on the node grid, get exact per-pixel maps
    instead (pixels without a source read from -1e6: outside the photo).
    """
    width, height = int(width), int(height)
    if frame is not None and frame.is_identity and (frame.width, frame.height) == (width, height):
        frame = None
    if frame is not None:
        width, height = frame.width, frame.height
        to_ideal = frame.to_ideal
    else:
        to_ideal = _same

    def source(q: np.ndarray) -> np.ndarray:
        return np.asarray(model.distort_points(to_ideal(q)), dtype=np.float64)

    if step <= 1 or width < 4 * step or height < 4 * step:
        return _exact(model, width, height, frame)
    xs, ys = _nodes(width, step), _nodes(height, step)
    gx, gy = np.meshgrid(xs, ys)
    src = source(np.stack([gx.ravel(), gy.ravel()], axis=1))
    if not np.all(np.isfinite(src)):
        return _exact(model, width, height, frame)
    sx = RectBivariateSpline(ys, xs, src[:, 0].reshape(len(ys), len(xs)), kx=3, ky=3)
    sy = RectBivariateSpline(ys, xs, src[:, 1].reshape(len(ys), len(xs)), kx=3, ky=3)
    # accuracy check at cell centres (plus the image corners), exact vs spline
    rng = np.random.default_rng(seed)
    cx = (xs[:-1] + xs[1:]) / 2
    cy = (ys[:-1] + ys[1:]) / 2
    px = np.concatenate([rng.choice(cx, n_check), [0.0, width - 1.0]])
    py = np.concatenate([rng.choice(cy, n_check), [height - 1.0, 0.0]])
    exact = source(np.stack([px, py], axis=1))
    err = np.hypot(sx.ev(py, px) - exact[:, 0], sy.ev(py, px) - exact[:, 1])
    err = float(np.nanmax(err)) if np.all(np.isfinite(exact)) else float("inf")
    rows = np.arange(height, dtype=np.float64)
    cols = np.arange(width, dtype=np.float64)
    map_x = np.empty((height, width), np.float32)
    map_y = np.empty((height, width), np.float32)
    band = max(1, (1 << 22) // width)  # evaluate in bands of ~4 Mpx to bound memory
    for r0 in range(0, height, band):
        r = rows[r0 : r0 + band]
        map_x[r0 : r0 + band] = sx(r, cols, grid=True)
        map_y[r0 : r0 + band] = sy(r, cols, grid=True)
    return RemapMaps(map_x, map_y, err, int(step))


def _same(q: np.ndarray) -> np.ndarray:
    return np.asarray(q, dtype=np.float64).reshape(-1, 2)


def _exact(model: DistortionModel, width: int, height: int, frame: CorrectedFrame | None) -> RemapMaps:
    """Exact per-pixel maps (the model's own for the default frame)."""
    if frame is None:
        mx, my = model.undistortion_maps(width, height)
        return RemapMaps(mx, my, 0.0, 0)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    src = model.distort_points(frame.to_ideal(np.stack([xx.ravel(), yy.ravel()], axis=1)))
    src = np.nan_to_num(src, nan=-1e6)
    return RemapMaps(
        src[:, 0].reshape(height, width).astype(np.float32), src[:, 1].reshape(height, width).astype(np.float32), 0.0, 0
    )
