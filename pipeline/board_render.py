r"""Synthetic board shots through an exact lens: the truth of the intrinsics tests and benchmark.

A board (:class:`pipeline.board.BoardSpec`) at pose :math:`(R, t)` (board mm -> camera mm)
seen by a pin-hole camera :math:`K` whose lens records the ideal point :math:`u` at the
distorted pixel :math:`x` with :math:`U(x) = u` (``undistort``: the exact distorted -> ideal
map, the direction every harp model has, so nothing is inverted). Each output pixel is the
mean over ``supersample`` x ``supersample`` points of the pixel's area of the printed board
(:meth:`BoardSpec.texture`, nearest texel: every square's edge is on a texel boundary, so
the squares are exact) at the board point seen there,

.. math::
    \begin{pmatrix} X \\ Y \\ 1 \end{pmatrix} \sim (K [r_1\ r_2\ t])^{-1}
    \begin{pmatrix} U(x) \\ 1 \end{pmatrix},

then blurred by a Gaussian PSF of ``blur_sigma`` px (in the recorded image), lit by a linear
gradient, given Gaussian noise of ``noise_sigma`` grey levels and rounded to 8 bits. Outside
the board (or behind the camera) the background grey. The corners' true distorted positions
are :math:`U^{-1}(K (R X + t))`, given by :func:`true_corners` through ``distort``.

References
----------
.. [1] Z. Zhang, "A flexible new technique for camera calibration", IEEE TPAMI 22(11), 2000
   (the plane-to-image homography :math:`K [r_1\ r_2\ t]`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.board import BoardSpec

Array = npt.NDArray[np.float64]
PointMap = Callable[[Array], Array]


@dataclass(frozen=True)
class BoardPose:
    """Board -> camera: rotation vector ``rvec`` (Rodrigues, rad) and translation ``tvec`` (mm)."""

    rvec: tuple[float, float, float]
    tvec: tuple[float, float, float]

    def rotation(self) -> Array:
        import cv2

        r, _ = cv2.Rodrigues(np.asarray(self.rvec, np.float64))
        return np.asarray(r, np.float64)


def camera_matrix(fx: float, fy: float, cx: float, cy: float, skew: float = 0.0) -> Array:
    """``[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]``."""
    return np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], np.float64)


def ideal_corners(spec: BoardSpec, k: Array, pose: BoardPose) -> tuple[Array, npt.NDArray[np.bool_]]:
    """Ideal (pin-hole) pixels of every corner and whether it is in front of the camera."""
    x = spec.corners() @ pose.rotation().T + np.asarray(pose.tvec, np.float64)
    front = x[:, 2] > 1e-9
    p = x @ np.asarray(k, np.float64).T
    return p[:, :2] / p[:, 2:3], front


def true_corners(spec: BoardSpec, k: Array, pose: BoardPose, distort: PointMap) -> Array:
    """Exact distorted pixels of every corner (``distort`` = the lens's ideal -> distorted map);
    NaN behind the camera."""
    u, front = ideal_corners(spec, k, pose)
    out = np.full_like(u, np.nan)
    out[front] = distort(u[front])
    return out


def _square_wave(x: Array, sigma: float) -> Array:
    """``(-1)^floor(x)`` smoothed by a Gaussian of ``sigma`` (units of ``x``, ``sigma`` << 1): the
    nearest edge's error function."""
    from scipy.special import erf

    f = np.floor(x)
    sign = np.where(f % 2 == 0, 1.0, -1.0)
    d = np.minimum(x - f, f + 1.0 - x)
    return np.asarray(sign * erf(d / (math.sqrt(2.0) * sigma)), np.float64)


def render_board(
    spec: BoardSpec,
    k: Array,
    pose: BoardPose,
    undistort: PointMap,
    width: int,
    height: int,
    *,
    supersample: int = 4,
    blur_sigma: float = 0.6,
    print_sigma_px: float = 0.3,
    noise_sigma: float = 1.0,
    black: float = 35.0,
    white: float = 215.0,
    background: float = 110.0,
    gradient: float = 0.15,
    px_per_square: int = 96,
    seed: int = 0,
) -> npt.NDArray[np.uint8]:
    """An 8-bit grey shot of the board (module docstring); ``seed`` draws the noise.

    The squares are drawn in closed form, smoothed on the board by a Gaussian of
    ``print_sigma_px`` image pixels (at the board's centre): sampled ``supersample`` x
    ``supersample`` times per pixel, a sharper print would put each edge on a 1/``supersample``
    px step (a bias of the corners up to 0.1 px); smoothed, the samples integrate it to
    ~1e-9. The smoothing is symmetric, so it moves no corner. ChArUco markers come from the
    texture (nearest texel; they are not where the corners are measured).
    """
    import cv2

    if width < 8 or height < 8:
        raise ValueError(f"image size must be at least 8x8, got {width}x{height}")
    pps = int(px_per_square)
    tex, ppm = spec.texture(pps)
    margin = pps
    th, tw = tex.shape
    sq = float(spec.square)
    nx, ny = spec.nx, spec.ny
    # which squares are black: the printed board's own (a texel near each square's corner)
    black_sq = tex[margin + np.arange(ny)[:, None] * pps + 2, margin + np.arange(nx)[None, :] * pps + 2] < 128
    parity0 = 1.0 if black_sq[0, 0] else -1.0  # q(X) q(Y) = +1 on the squares of (0, 0)'s colour
    r = pose.rotation()
    tvec = np.asarray(pose.tvec, np.float64)
    kk = np.asarray(k, np.float64)
    h = kk @ np.column_stack([r[:, 0], r[:, 1], tvec])
    hinv = np.linalg.inv(h)
    kinv_t = np.linalg.inv(kk).T
    depth_sign = float(np.dot(r[:, 2], tvec))
    centre_depth = float((r @ np.array([nx * sq / 2, ny * sq / 2, 0.0]) + tvec)[2])
    sigma_sq = max(print_sigma_px, 1e-3) * centre_depth / float(kk[0, 0]) / sq  # in squares
    n = int(supersample)
    offs = (np.arange(n) + 0.5) / n - 0.5
    out = np.zeros((height, width), np.float64)
    rows_per_chunk = max(1, 200_000 // (width * n * n))
    half_gap = 0.5 * float(spec.marker) / sq if spec.kind == "charuco" else 0.0
    for r0 in range(0, height, rows_per_chunk):
        r1 = min(height, r0 + rows_per_chunk)
        yy, xx = np.mgrid[r0:r1, 0:width].astype(np.float64)
        acc = np.zeros(yy.shape, np.float64)
        for oy in offs:
            for ox in offs:
                pts = np.column_stack([(xx + ox).ravel(), (yy + oy).ravel()])
                u1 = np.column_stack([undistort(pts), np.ones(len(pts))])
                q = u1 @ hinv.T
                with np.errstate(divide="ignore", invalid="ignore"):
                    bx, by = q[:, 0] / q[:, 2] / sq, q[:, 1] / q[:, 2] / sq  # in squares
                front = ((u1 @ kinv_t) @ r[:, 2]) * depth_sign > 0
                ok = front & np.isfinite(bx) & np.isfinite(by)
                v = np.full(len(pts), background)
                ci = np.floor(np.where(ok, bx, -1e9) * pps).astype(np.int64) + margin
                ri = np.floor(np.where(ok, by, -1e9) * pps).astype(np.int64) + margin
                on_print = ok & (ci >= 0) & (ci < tw) & (ri >= 0) & (ri < th)
                v[on_print] = white
                on_board = on_print & (bx >= 0) & (bx < nx) & (by >= 0) & (by < ny)
                b_x, b_y = bx[on_board], by[on_board]
                c = 0.5 * (1.0 + parity0 * _square_wave(b_x, sigma_sq) * _square_wave(b_y, sigma_sq))
                val = white + (black - white) * c
                if half_gap > 0:  # inside a white square's marker: the printed marker itself
                    fx_, fy_ = b_x - np.floor(b_x) - 0.5, b_y - np.floor(b_y) - 0.5
                    sx = np.clip(np.floor(b_x).astype(np.int64), 0, nx - 1)
                    sy = np.clip(np.floor(b_y).astype(np.int64), 0, ny - 1)
                    in_marker = (np.abs(fx_) < half_gap) & (np.abs(fy_) < half_gap) & ~black_sq[sy, sx]
                    t = tex[ri[on_board][in_marker], ci[on_board][in_marker]].astype(np.float64) / 255.0
                    val[in_marker] = black + (white - black) * t
                v[on_board] = val
                acc += v.reshape(yy.shape)
        out[r0:r1] = acc / (n * n)
    if blur_sigma > 0:
        out = np.asarray(cv2.GaussianBlur(out, (0, 0), float(blur_sigma), borderType=cv2.BORDER_REFLECT), np.float64)
    if gradient:
        gx = np.linspace(-0.5, 0.5, width)[None, :]
        gy = np.linspace(-0.5, 0.5, height)[:, None]
        out = out * (1.0 + gradient * (0.8 * gx + 0.6 * gy))
    rng = np.random.default_rng(seed)
    if noise_sigma > 0:
        out = out + rng.normal(0.0, float(noise_sigma), out.shape)
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


def random_poses(
    spec: BoardSpec,
    k: Array,
    width: int,
    height: int,
    n: int,
    *,
    seed: int,
    fill: tuple[float, float] = (0.35, 0.7),
    tilt_deg: tuple[float, float] = (15.0, 45.0),
) -> list[BoardPose]:
    """``n`` board poses whose board covers ``fill`` of the image width, tilted by ``tilt_deg``
    about a random axis in the board plane, turned at random about the optical axis and placed
    at random over the image (its centre inside the middle 60 %); drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    bw, bh = spec.size_mm()
    fx = float(k[0, 0])
    poses: list[BoardPose] = []
    centre = np.array([bw / 2.0, bh / 2.0, 0.0])
    while len(poses) < n:
        f = rng.uniform(*fill)
        z = fx * bw / (f * width)
        tilt = math.radians(rng.uniform(*tilt_deg))
        axis_angle = rng.uniform(0, 2 * math.pi)
        spin = rng.uniform(-math.pi / 6, math.pi / 6)
        a = np.array([math.cos(axis_angle), math.sin(axis_angle), 0.0]) * tilt
        import cv2

        r_tilt, _ = cv2.Rodrigues(a)
        r_spin, _ = cv2.Rodrigues(np.array([0.0, 0.0, spin]))
        rot = r_spin @ r_tilt
        px = rng.uniform(0.2, 0.8) * width
        py = rng.uniform(0.2, 0.8) * height
        ray = np.linalg.solve(np.asarray(k, np.float64), np.array([px, py, 1.0]))
        t = ray * z - rot @ centre
        rvec, _ = cv2.Rodrigues(rot)
        pose = BoardPose(tuple(float(v) for v in rvec.ravel()), tuple(float(v) for v in t))  # type: ignore[arg-type]
        u, front = ideal_corners(spec, k, pose)
        inside = front & (u[:, 0] > 2) & (u[:, 0] < width - 3) & (u[:, 1] > 2) & (u[:, 1] < height - 3)
        if inside.mean() >= 0.6:
            poses.append(pose)
    return poses
