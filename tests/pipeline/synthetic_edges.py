"""Analytic synthetic edge images with exact ground truth (for edge tests and benchmarks).

An ideal step edge (dark level ``dark``, bright level ``bright``) blurred by a
Gaussian optical PSF of standard deviation ``blur`` px has the profile
``dark + (bright - dark) * Phi(s / blur)`` where ``s`` is the signed distance to
the edge line. Each pixel integrates that profile over its area (``ss x ss``
supersampling, pixel centres at integers as in pipeline/__init__.py).
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr


def _subsamples(ss: int) -> np.ndarray:
    return (np.arange(ss) + 0.5) / ss - 0.5


def _pixel_integral(profile, ss: int, bright: float, dark: float) -> np.ndarray:
    """``dark + (bright - dark) * mean of profile(ox, oy)`` over the ``ss x ss`` sub-pixel offsets."""
    acc = 0.0
    for oy in _subsamples(ss):
        for ox in _subsamples(ss):
            acc = acc + profile(ox, oy)
    return dark + (bright - dark) * acc / ss**2


def _signed_distance(shape, angle_deg, point):
    """``(n, (p - point) . n)`` at every pixel centre ``p``, ``n = line_normal(angle_deg)``."""
    h, w = shape
    n = line_normal(angle_deg)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    return n, (xs - point[0]) * n[0] + (ys - point[1]) * n[1]


def line_normal(angle_deg: float) -> np.ndarray:
    """Unit normal of a line whose *direction* is ``angle_deg`` (x towards y)."""
    a = np.deg2rad(angle_deg)
    return np.array([-np.sin(a), np.cos(a)])


def render_step(shape, angle_deg, point, bright=200.0, dark=30.0, blur=0.7, ss=4):
    """Straight step edge through ``point`` (x, y) with direction ``angle_deg``.

    The bright side is where ``(p - point) . n > 0`` with ``n = line_normal(angle_deg)``.
    Returns a float64 image (no noise, no quantisation).
    """
    n, base = _signed_distance(shape, angle_deg, point)
    return _pixel_integral(lambda ox, oy: ndtr((base + ox * n[0] + oy * n[1]) / blur), ss, bright, dark)


def render_disk(shape, centre, radius, bright=200.0, dark=30.0, blur=0.7, ss=4):
    """Dark disk on a bright background (edge profile Phi((r - R) / blur))."""
    h, w = shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    return _pixel_integral(
        lambda ox, oy: ndtr((np.hypot(xs + ox - centre[0], ys + oy - centre[1]) - radius) / blur), ss, bright, dark
    )


def render_string(shape, angle_deg, point, width, bright=200.0, dark=30.0, blur=0.7, ss=4):
    """Dark straight string of ``width`` px centred on the line through ``point``."""
    n, base = _signed_distance(shape, angle_deg, point)

    def profile(ox, oy):
        # box of the string's width convolved with the Gaussian PSF (not
        # Phi((|s| - width/2) / blur): that has a kink on the string's axis)
        s = base + ox * n[0] + oy * n[1]
        return 1.0 - (ndtr((s + width / 2) / blur) - ndtr((s - width / 2) / blur))

    return _pixel_integral(profile, ss, bright, dark)


def quantise(img, noise, rng, bits=8):
    """Add Gaussian noise (grey levels of the 8-bit scale) and quantise to ``bits``."""
    scale = 1 if bits == 8 else 257
    out = (img + rng.normal(0.0, noise, img.shape)) * scale
    top = 255 if bits == 8 else 65535
    return np.clip(np.round(out), 0, top).astype(np.uint8 if bits == 8 else np.uint16)
