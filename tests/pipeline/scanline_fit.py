"""Edge positions in a rendered image measured independently of the pipeline's detector.

Along an image row (or column) crossing a string, the samples are fitted by
least squares with the blurred-string model
``a (1 + g (x - xm)) (1 - k (Phi((x - x1)/s) - Phi((x - x2)/s)))``; the fitted
crossings ``x1``, ``x2`` are compared with the exact distorted edge curves of
:func:`pipeline.render.visible_edges`. Used by the renderer and sim-camera tests.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares
from scipy.special import ndtr

from pipeline.render import Rendered, visible_edges


def _cross(curve: np.ndarray, level: float, along: int) -> float:
    """Coordinate ``1 - along`` where the curve crosses ``coord[along] == level``."""
    v = curve[:, along]
    i = np.flatnonzero(np.diff(np.sign(v - level)) != 0)
    assert len(i) == 1, "curve must cross the scanline once"
    i = int(i[0])
    f = (level - v[i]) / (v[i + 1] - v[i])
    return float(curve[i, 1 - along] + f * (curve[i + 1, 1 - along] - curve[i, 1 - along]))


def _fit_string(profile: np.ndarray, pos: np.ndarray, x1: float, x2: float) -> tuple[float, float]:
    """Least-squares crossings of the blurred-string model on one scanline."""
    c1, c2, _ = fit_string_profile(profile, pos, x1, x2)
    return c1, c2


def fit_string_profile(profile: np.ndarray, pos: np.ndarray, x1: float, x2: float) -> tuple[float, float, float]:
    """Least-squares crossings ``c1``, ``c2`` and blur ``s`` (along the scanline) of the
    blurred-string model on one scanline (module docstring), started at ``x1``, ``x2``."""
    xm = 0.5 * (x1 + x2)

    def model(p):
        a, g, k, c1, c2, s = p
        return a * (1 + g * (pos - xm)) * (1 - k * (ndtr((pos - c1) / s) - ndtr((pos - c2) / s)))

    p0 = [profile.max(), 0.0, 0.8, x1 + 0.3, x2 - 0.3, 1.0]
    fit = least_squares(lambda p: model(p) - profile, p0, x_scale=[100, 1e-3, 0.1, 0.1, 0.1, 0.1])
    return float(fit.x[3]), float(fit.x[4]), abs(float(fit.x[5]))


def scanline_errors(r: Rendered, n_per_edge: int = 3, truth: Rendered | None = None) -> np.ndarray:
    """Fitted minus true edge crossings, in pixels along the normal, at a few places per string.

    ``truth`` (default ``r``) supplies the true curves, e.g. a rendering of
    the same scene through another lens.
    """
    img = r.image.astype(np.float64)
    by_string: dict[int, dict[int, np.ndarray]] = {}
    for e, c in visible_edges(truth if truth is not None else r, margin=12.0):
        by_string.setdefault(e.string_index, {})[e.side] = c
    errs = []
    for sides in by_string.values():
        if len(sides) != 2:
            continue
        a, b = sides[-1], sides[1]
        tang = a[-1] - a[0]
        along = 1 if abs(tang[1]) > abs(tang[0]) else 0  # scan rows for steep strings
        im = img if along == 1 else img.T
        for f in np.linspace(0.2, 0.8, n_per_edge):
            line = int(round(a[int(f * (len(a) - 1)), along]))
            try:
                xa, xb = _cross(a, line, along), _cross(b, line, along)
            except AssertionError:
                continue
            x1, x2 = min(xa, xb), max(xa, xb)
            half = 0.5 * (x2 - x1) + 6.0 / max(abs(tang[along]) / np.hypot(*tang), 0.3)
            pos = np.arange(math.floor(x1 - half), math.ceil(x2 + half) + 1)
            if pos[0] < 0 or pos[-1] >= im.shape[1]:
                continue
            f1, f2 = _fit_string(im[line, pos], pos.astype(float), x1, x2)
            # a scanline at angle alpha to the normal stretches distances by 1/cos(alpha):
            # convert to distances along the normal
            cos_a = abs(tang[along]) / np.hypot(*tang)
            errs += [(f1 - x1) * cos_a, (f2 - x2) * cos_a]
    return np.asarray(errs)
