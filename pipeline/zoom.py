r"""Zoom lenses: corrections at (focal length, focus) settings, interpolated in both, never extrapolated.

A zoom lens's distortion changes with its focal length (barrel at the wide end, pincushion at the
long end is common) and, less, with focus. A station calibrates a grid of settings
:math:`(z_j, f_{jk})` — at each focal length :math:`z_j` some focus settings :math:`f_{jk}` —
and a setting :math:`(z, f)` in between is interpolated as a tensor product of the focus
interpolation (:class:`pipeline.interpolate.FocusInterpolator`, gauge-normalised fields):

.. math::
    u(x; z, f) = \mathcal{I}_z\bigl[u_j(x; f)\bigr]_j, \qquad
    u_j(x; f) = \mathcal{I}_f\bigl[u_{jk}(x)\bigr]_k

first along focus at each calibrated focal length (a focal length with one focus setting gives
its field only at that setting), then along the focal length between them (piecewise linear with
two focal lengths, PCHIP with three or more). Nothing outside the calibrated ranges is returned:
a focal length outside :math:`[z_1, z_n]`, or a focus outside the range calibrated at a focal
length it needs, raises ValueError naming the range.

Measured, not assumed: :func:`leave_one_out_by_axis` leaves each interior focus setting out at
each focal length (the focus axis) and each interior focal length out at each focus setting all
its neighbours share (the focal axis), and compares the interpolation with that setting's own fit
modulo a homography (:func:`pipeline.compare.compare_models`).

References
----------
.. [1] F. N. Fritsch, R. E. Carlson, "Monotone piecewise cubic interpolation", SIAM J. Numer.
   Anal. 17(2), 1980 (PCHIP).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.compare import compare_models
from pipeline.interpolate import DEFAULT_STEP_PX, FocusInterpolator, field_grid, gauge_homography, normalised_field
from pipeline.models.base import DistortionModel
from pipeline.models.grid_field import GridFieldModel

Setting = tuple[float, float]
"""A lens setting: (focal length, focus)."""

_TOL = 1e-9


def _pairs(
    models: Mapping[Setting, DistortionModel] | Iterable[tuple[Setting, DistortionModel]],
) -> dict[float, dict[float, DistortionModel]]:
    items = list(models.items()) if isinstance(models, Mapping) else list(models)
    out: dict[float, dict[float, DistortionModel]] = {}
    for (z, f), m in items:
        z, f = float(z), float(f)
        if not (math.isfinite(z) and math.isfinite(f)):
            raise ValueError(f"setting ({z}, {f}) is not finite")
        if not isinstance(m, DistortionModel):
            raise ValueError(f"setting (focal {z:g}, focus {f:g}): not a DistortionModel")
        row = out.setdefault(z, {})
        if f in row:
            raise ValueError(f"setting (focal {z:g}, focus {f:g}) given twice")
        row[f] = m
    return dict(sorted(out.items()))


class ZoomInterpolator:
    """Corrections at (focal length, focus) settings, interpolated in both (module docstring).

    Parameters
    ----------
    models : mapping ``(focal, focus) -> DistortionModel`` (or pairs)
        Every model for ``width x height`` images; at least one setting.
    method : {'auto', 'linear', 'pchip'}
        Along the focal length (``auto``: PCHIP with >= 3 focal lengths, else linear); along focus
        :class:`~pipeline.interpolate.FocusInterpolator`'s ``auto``.
    """

    def __init__(
        self,
        models: Mapping[Setting, DistortionModel] | Iterable[tuple[Setting, DistortionModel]],
        width: int,
        height: int,
        *,
        method: str = "auto",
        step: float = DEFAULT_STEP_PX,
    ) -> None:
        if method not in ("auto", "linear", "pchip"):
            raise ValueError(f"unknown focal interpolation method {method!r}; known: auto, linear, pchip")
        self.grid = _pairs(models)
        if not self.grid:
            raise ValueError("zoom interpolation needs at least one calibrated setting")
        self.width, self.height, self.step = int(width), int(height), float(step)
        self.focals = np.array(list(self.grid))
        self.method = ("pchip" if len(self.focals) >= 3 else "linear") if method == "auto" else method
        self.xs, self.ys = field_grid(self.width, self.height, self.step)
        self._focus: dict[float, FocusInterpolator | None] = {
            z: (FocusInterpolator(row, self.width, self.height, step=self.step) if len(row) >= 2 else None)
            for z, row in self.grid.items()
        }

    @property
    def focal_range(self) -> tuple[float, float]:
        return float(self.focals[0]), float(self.focals[-1])

    def focus_range(self, focal: float) -> tuple[float, float]:
        """The focus range calibrated at the calibrated focal length ``focal``."""
        fs = sorted(self.grid[float(focal)])
        return fs[0], fs[-1]

    def _field_at_focal(self, z: float, focus: float) -> NDArray[np.float64]:
        row = self.grid[z]
        lo, hi = min(row), max(row)
        tol = _TOL * max(1.0, abs(hi - lo))
        if not (lo - tol <= focus <= hi + tol):
            span = f"[{lo:g}, {hi:g}]" if hi > lo else f"{lo:g} only"
            raise ValueError(
                f"focus {focus:g} is outside the range calibrated at focal {z:g} ({span}): extrapolation refused "
                "(calibrate that setting)"
            )
        interp = self._focus[z]
        if interp is None:
            m = row[lo]
            h = gauge_homography(m, self.width, self.height, "lsq")
            return np.stack(normalised_field(m, self.xs, self.ys, h))
        return np.asarray(interp.field_at(focus), np.float64)

    def field_at(self, focal: float, focus: float) -> NDArray[np.float64]:
        """The interpolated normalised field ``(2, ny, nx)`` at ``(focal, focus)``; ValueError outside."""
        z, f = float(focal), float(focus)
        lo, hi = self.focal_range
        tol = _TOL * max(1.0, abs(hi - lo))
        if not (math.isfinite(z) and math.isfinite(f)) or z < lo - tol or z > hi + tol:
            raise ValueError(
                f"focal {focal:g} is outside the calibrated range [{lo:g}, {hi:g}]: extrapolation refused "
                "(calibrate that focal length)"
            )
        z = min(max(z, lo), hi)
        exact = [q for q in self.focals if abs(q - z) <= tol]
        if exact:
            return self._field_at_focal(float(exact[0]), f)
        if self.method == "linear" or len(self.focals) < 3:
            k = int(np.clip(np.searchsorted(self.focals, z, side="right") - 1, 0, len(self.focals) - 2))
            a = (z - self.focals[k]) / (self.focals[k + 1] - self.focals[k])
            lo_f = self._field_at_focal(float(self.focals[k]), f)
            hi_f = self._field_at_focal(float(self.focals[k + 1]), f)
            return np.asarray((1 - a) * lo_f + a * hi_f, np.float64)
        from scipy.interpolate import PchipInterpolator

        fields = np.stack([self._field_at_focal(float(q), f) for q in self.focals])
        return np.asarray(PchipInterpolator(self.focals, fields, axis=0)(z), np.float64)

    def at(self, focal: float, focus: float) -> GridFieldModel:
        """The interpolated correction at ``(focal, focus)`` (ValueError outside the calibrated ranges)."""
        u = self.field_at(focal, focus)
        return GridFieldModel(
            origin=(float(self.xs[0]), float(self.ys[0])),
            step=self.step,
            dx=u[0],
            dy=u[1],
            width=self.width,
            height=self.height,
            info={
                "interpolated_focal": float(focal),
                "interpolated_focus": float(focus),
                "focal_method": self.method,
                "calibrated": [[float(z), sorted(float(f) for f in row)] for z, row in self.grid.items()],
            },
        )


@dataclass(frozen=True)
class AxisLeaveOneOut:
    """Interpolation error at one calibrated setting left out along one axis (px, modulo homography)."""

    axis: str  # "focus" or "focal"
    focal: float
    focus: float
    rms_px: float
    max_px: float


def leave_one_out_by_axis(
    models: Mapping[Setting, DistortionModel] | Iterable[tuple[Setting, DistortionModel]],
    width: int,
    height: int,
    *,
    step: float = DEFAULT_STEP_PX,
    compare_step: float = 10.0,
) -> list[AxisLeaveOneOut]:
    """Leave-one-out interpolation error along each axis (module docstring): ``focus`` rows for each
    interior focus setting of a focal length, ``focal`` rows for each interior focal length at each
    focus setting its two neighbours have. Ends are never left out (that would extrapolate)."""
    grid = _pairs(models)
    out: list[AxisLeaveOneOut] = []
    for z, row in grid.items():
        fs = sorted(row)
        for i in range(1, len(fs) - 1):
            others = {(z, f): row[f] for f in fs if f != fs[i]}
            m = ZoomInterpolator(others, width, height, step=step).at(z, fs[i])
            c = compare_models(m, row[fs[i]], width, height, step=compare_step)
            out.append(AxisLeaveOneOut("focus", z, fs[i], c.rms, c.max))
    zs = list(grid)
    for j in range(1, len(zs) - 1):
        for f in sorted(grid[zs[j]]):
            if not any(f in grid[q] for q in zs[:j]) or not any(f in grid[q] for q in zs[j + 1 :]):
                continue
            others = {(q, g): m for q in zs if q != zs[j] for g, m in grid[q].items() if g == f}
            m = ZoomInterpolator(others, width, height, step=step).at(zs[j], f)
            c = compare_models(m, grid[zs[j]][f], width, height, step=compare_step)
            out.append(AxisLeaveOneOut("focal", zs[j], f, c.rms, c.max))
    return out
