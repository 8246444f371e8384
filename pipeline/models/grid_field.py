"""A correction given by its displacement field sampled on a regular grid."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from pipeline.models.base import DistortionModel


class _Spline(Protocol):
    """What the model uses of a ``scipy.interpolate.RectBivariateSpline`` (scipy has no type information)."""

    def ev(self, yi: NDArray[np.float64], xi: NDArray[np.float64]) -> NDArray[np.float64]: ...


@dataclass(frozen=True, eq=False)
class GridFieldModel(DistortionModel):
    r"""Correction :math:`x_u = x_d + u(x_d)` with :math:`u` a bicubic spline on a grid.

    The displacement :math:`u = (u_x, u_y)` (pixels) is known at the nodes
    :math:`(X_i, Y_j) = (x_0 + i\,h,\ y_0 + j\,h)`, :math:`i < n_x`,
    :math:`j < n_y`; between the nodes each component is the interpolating
    bicubic spline (``scipy.interpolate.RectBivariateSpline``, ``kx = ky = 3``,
    ``s = 0``, not-a-knot ends):

    .. math::
        x_u = x_d + S[u_x](x_d, y_d), \qquad y_u = y_d + S[u_y](x_d, y_d)

    with :math:`S[g]` the C² piecewise-cubic spline through the node values
    :math:`g(X_i, Y_j)`. Its error for a smooth field is
    :math:`O(h^4 \max|\partial^4 u|)`. A point outside the grid is clamped to
    the grid's border (FITPACK ``bispev``), so the grid should cover the image
    with a margin. This is the form of
    a correction that has no closed formula, e.g. one interpolated in focus
    between calibrated settings (:mod:`pipeline.interpolate`).

    Parameters, in order: ``origin = (x0, y0)``, ``step = h``, then the node
    values ``dx[j][i] = u_x(X_i, Y_j)`` and ``dy[j][i] = u_y(X_i, Y_j)``
    (row ``j`` = y, as an image). ``width``, ``height``: the image it is for.
    ``info``: free-form provenance (e.g. the focus it was interpolated for).
    """

    origin: tuple[float, float]
    step: float
    dx: np.ndarray
    dy: np.ndarray
    width: int
    height: int
    info: dict[str, Any] = field(default_factory=dict)
    name: str = field(default="grid_field", init=False, repr=False)
    # the splines of dx and dy, built by __post_init__ (derived: not parameters)
    _sx: _Spline = field(init=False, repr=False, compare=False)
    _sy: _Spline = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        dx = np.array(self.dx, dtype=np.float64)
        dy = np.array(self.dy, dtype=np.float64)
        if dx.ndim != 2 or dx.shape != dy.shape or min(dx.shape) < 4:
            raise ValueError(
                f"GridFieldModel needs two equal (ny, nx) grids with nx, ny >= 4; got {dx.shape} and {dy.shape}"
            )
        if not (np.all(np.isfinite(dx)) and np.all(np.isfinite(dy))):
            raise ValueError("GridFieldModel displacement grid has non-finite values")
        if not (np.isfinite(self.step) and self.step > 0):
            raise ValueError(f"GridFieldModel step must be > 0, got {self.step}")
        dx.setflags(write=False)
        dy.setflags(write=False)
        object.__setattr__(self, "dx", dx)
        object.__setattr__(self, "dy", dy)
        object.__setattr__(self, "origin", (float(self.origin[0]), float(self.origin[1])))
        object.__setattr__(self, "step", float(self.step))
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        xs, ys = self.nodes
        from scipy.interpolate import RectBivariateSpline  # here: importing pipeline.models stays light

        object.__setattr__(self, "_sx", RectBivariateSpline(ys, xs, dx, kx=3, ky=3, s=0))
        object.__setattr__(self, "_sy", RectBivariateSpline(ys, xs, dy, kx=3, ky=3, s=0))

    @property
    def nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """Node coordinates ``(xs, ys)``."""
        ny, nx = self.dx.shape
        return (self.origin[0] + self.step * np.arange(nx), self.origin[1] + self.step * np.arange(ny))

    def displacement(self, xy: np.ndarray) -> np.ndarray:
        """The interpolated displacement ``u(xy)`` (N, 2)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return np.stack([self._sx.ev(xy[:, 1], xy[:, 0]), self._sy.ev(xy[:, 1], xy[:, 0])], axis=1)

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        xu: NDArray[np.float64] = xy + self.displacement(xy)
        return xu

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.name,
            "origin": list(self.origin),
            "step": self.step,
            "width": self.width,
            "height": self.height,
            "dx": self.dx.tolist(),
            "dy": self.dy.tolist(),
            "info": dict(self.info),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> GridFieldModel:
        return cls(
            origin=tuple(d["origin"]),
            step=float(d["step"]),
            dx=np.asarray(d["dx"], float),
            dy=np.asarray(d["dy"], float),
            width=int(d["width"]),
            height=int(d["height"]),
            info=dict(d.get("info") or {}),
        )
