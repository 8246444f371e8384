r"""How much of a held-out shot's error is a term of its own: the correction's axis moved for that shot alone.

A correction :math:`U` fitted on other shots corrects a held-out shot's edges to a d of :math:`d_h`. Moving the
whole correction by a vector :math:`t` fitted on that shot alone,

.. math:: U_t(p) = U(p - t) + t,

leaves :math:`d_t \le d_h`. That is what a lens whose distortion centre (or decentering) moved between shots needs:
an image stabiliser that re-centres, a focus or zoom group with play, a lens knocked between shots (consumer lenses'
interior orientation changes between images: Shortis et al. 2006; Sanz-Ablanedo et al. 2010). On one shot's
parallel strings :math:`t` shows mostly as a bow that every string shares (the radial term's gradient across the
strings), so a lens term that bends each orientation its own way or a bow the whole harp shares in that shot lowers
:math:`d_t` as well; two shots at the **same** angle tell them apart (a moving lens bends them differently).

With a stable lens and enough shots the held-out shot has nothing of its own to take, and
:math:`d_t / d_h` stays near 1; on the three real photographs fitted two at a time it is 0.46-0.63
(``benchmarks/own_shift.py``, ``benchmarks/RESULTS-realism.md``).

References
----------
.. [1] Shortis, Bellman, Robson, Johnston, Johnson, "Stability of zoom and fixed lenses used with digital SLR
   cameras", IAPRS vol. 36 part 5, 2006.
.. [2] Tang, Grompone von Gioi, Monasse, Morel, "High-precision camera distortion measurements with a calibration
   harp", JOSA A 29(10), 2012: d, the RMS distance to each edge's regression line.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.edgeset import held_out_edges, tls
from pipeline.models.base import DistortionModel
from pipeline.orientations import shot_orientation

MAX_SHIFT_PX = 50.0
"""Largest axis shift searched (px): a stabiliser's re-centring or a group's play is a few pixels; beyond this the
held-out shot is not the lens's problem."""


@dataclass(frozen=True)
class OwnShift:
    """A held-out shot's own axis shift (:func:`own_axis_shift`).

    ``d_held`` the shot's d under the correction fitted without it, ``d_own`` under the same correction moved by
    ``shift_px`` (x, y), fitted on the shot alone (px); ``points`` the points of the edges measured."""

    d_held: float
    d_own: float
    shift_px: tuple[float, float]
    points: int

    @property
    def ratio(self) -> float:
        """``d_own / d_held``: 1 when the shot has nothing of its own; NaN without a held-out figure."""
        return self.d_own / self.d_held if self.d_held > 0 else float("nan")


def _residuals(
    model: DistortionModel,
    pts: NDArray[np.float64],
    starts: NDArray[np.intp],
    counts: NDArray[np.intp],
    t: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Each point's distance to its edge's line after ``model`` moved by ``t`` (px)."""
    r: NDArray[np.float64] = tls(model.undistort_points(pts - t) + t, starts, counts)[0]
    return r


def _packed(
    edges: Sequence[NDArray[np.float64]],
) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.intp]]:
    """``edges`` as one array of points with each edge's start and count (what :func:`_residuals` takes)."""
    counts = np.array([len(p) for p in edges], dtype=np.intp)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.intp)
    return np.concatenate(edges), starts, counts


def own_axis_shift(model: DistortionModel, lines: Sequence[NDArray[np.float64]]) -> OwnShift:
    """The shift :math:`t` (module docstring) that straightens the edges ``lines`` of one held-out shot best under
    ``model``, by least squares from :math:`t = 0` within :data:`MAX_SHIFT_PX`; the edges taken are those a held-out
    figure takes (:func:`pipeline.edgeset.held_out_edges`). NaN figures when no edge has three points or the
    correction leaves a point non-finite."""
    from scipy.optimize import least_squares

    edges = held_out_edges(lines)
    if not edges:
        return OwnShift(float("nan"), float("nan"), (float("nan"), float("nan")), 0)
    pts, starts, counts = _packed(edges)
    r0 = _residuals(model, pts, starts, counts, np.zeros(2))
    d_held = float(np.sqrt(np.mean(r0**2)))
    if not np.isfinite(d_held):
        return OwnShift(d_held, float("nan"), (float("nan"), float("nan")), len(pts))

    def fun(t: NDArray[np.float64]) -> NDArray[np.float64]:
        r = _residuals(model, pts, starts, counts, t)
        return np.where(np.isfinite(r), r, 1e3)

    sol = least_squares(fun, np.zeros(2), bounds=(-MAX_SHIFT_PX, MAX_SHIFT_PX), x_scale=1.0, diff_step=1e-3)
    d_own = float(np.sqrt(np.mean(sol.fun**2)))
    if not d_own <= d_held:  # the search never does worse than not moving
        return OwnShift(d_held, d_held, (0.0, 0.0), len(pts))
    return OwnShift(d_held, d_own, (float(sol.x[0]), float(sol.x[1])), len(pts))


@dataclass(frozen=True)
class TwinShift:
    r"""Two shots at one angle (twins) under one correction (:func:`twin_shift`).

    ``d_model`` the pair's d under the correction, ``d_common`` under it moved by one shift fitted on both, ``d_each``
    moved by a shift fitted on each; ``move_px`` the two shifts' difference across the strings (the lens's move
    between the twins as the strings show it, signed along ``normal``: :math:`(-\sin\theta, \cos\theta)` of the
    first shot's string direction :math:`\theta` in [0, 180) deg, :func:`pipeline.orientations.shot_orientation`);
    ``points`` the points measured."""

    d_model: float
    d_common: float
    d_each: float
    move_px: float
    normal: tuple[float, float]
    points: int

    @property
    def ratio(self) -> float:
        """``d_each / d_common``: 1 when one shift serves both twins (a stable lens, or a term of the lens at that
        angle); below 1 when each twin wants its own (the lens moved between them); NaN without a figure."""
        return self.d_each / self.d_common if self.d_common > 0 else float("nan")


def twin_shift(
    model: DistortionModel, lines_a: Sequence[NDArray[np.float64]], lines_b: Sequence[NDArray[np.float64]]
) -> TwinShift:
    r"""Whether two shots of the harp at one angle want the correction moved alike.

    One shot per angle cannot tell a lens whose centre moved for that shot from a term of the lens that bends strings
    at that angle its own way: both show as a shift :math:`t` of its own (module docstring). Two shots at the same
    angle can: a term of the lens bends them alike, so one shift fitted on both straightens them as well as a shift
    each (``ratio`` = ``d_each / d_common`` near 1), while a lens that moved between them leaves each its own shift
    (``ratio`` below 1, ``move_px`` the move across the strings). The correction ``model`` may be fitted with both
    shots in it. Each shift is found by least squares from 0 within :data:`MAX_SHIFT_PX`; the edges taken are
    those a held-out figure takes (:func:`pipeline.edgeset.held_out_edges`); NaN figures when a shot has no edge or
    the correction leaves a point non-finite."""
    from scipy.optimize import least_squares

    shots = [held_out_edges(lines_a), held_out_edges(lines_b)]
    nan = float("nan")
    if not shots[0] or not shots[1]:
        return TwinShift(nan, nan, nan, nan, (nan, nan), sum(len(p) for s in shots for p in s))
    packed = [_packed(edges) for edges in shots]
    points = sum(len(p[0]) for p in packed)

    def res(ts: Sequence[NDArray[np.float64]]) -> NDArray[np.float64]:
        r = np.concatenate([_residuals(model, *packed[i], ts[i]) for i in range(2)])
        return np.where(np.isfinite(r), r, 1e3)

    zero = np.zeros(2)
    r0 = np.concatenate([_residuals(model, *packed[i], zero) for i in range(2)])
    d_model = float(np.sqrt(np.mean(r0**2)))
    if not np.isfinite(d_model):
        return TwinShift(d_model, nan, nan, nan, (nan, nan), points)
    opts: dict[str, object] = {"x_scale": 1.0, "diff_step": 1e-3}
    box = (-MAX_SHIFT_PX, MAX_SHIFT_PX)
    common = least_squares(lambda t: res([t, t]), zero, bounds=box, **opts)
    d_common = min(float(np.sqrt(np.mean(common.fun**2))), d_model)
    each = least_squares(lambda t: res([t[:2], t[2:]]), np.concatenate([common.x, common.x]), bounds=box, **opts)
    d_each = min(float(np.sqrt(np.mean(each.fun**2))), d_common)
    # the strings' normal: (-sin, cos) of the first shot's strings' direction in [0, 180)
    a = np.radians(shot_orientation(shots[0]))
    normal = np.array([-np.sin(a), np.cos(a)])
    move = float(np.dot(each.x[2:] - each.x[:2], normal)) if d_each < d_common else 0.0
    return TwinShift(d_model, d_common, d_each, move, (float(normal[0]), float(normal[1])), points)
