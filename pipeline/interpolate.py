r"""Focus interpolation of a correction field between calibrated focus settings.

A lens's distortion changes with its focus setting, so a station calibrates a
few settings :math:`f_1 < \dots < f_n`. For a focus :math:`f` in between, this
module interpolates the *correction field* (not the model parameters, which
need not be comparable between fits, and need not even be the same model):

.. math::
    u_i(x) = H_i\big(U_i(x)\big) - x, \qquad
    u(x; f) = \mathcal{I}_f\big[u_1(x), \dots, u_n(x)\big], \qquad
    U_f(x) = x + u(x; f)

where :math:`U_i` is the correction fitted at :math:`f_i`, :math:`H_i` its
*gauge* homography (below), and :math:`\mathcal{I}_f` interpolates, node by
node of a grid covering the image, the values at :math:`f_1..f_n` at
:math:`f`: piecewise linear, PCHIP (Fritsch–Carlson, shape preserving, C¹) or
a not-a-knot cubic spline (C²; through 3 settings it is the parabola).
The result is a :class:`~pipeline.models.grid_field.GridFieldModel` (bicubic
spline of the node values in x, y).

Why a gauge. A straight-line method determines a correction only up to a
homography (Tang et al. 2012, Sect. 2): :math:`U_i` and :math:`H \circ U_i`
straighten the same lines. Each fit fixes that freedom its own way (the
radial fit fixes :math:`k_0 = 1`; the polynomial fit fixes the linear terms),
and a fit at another focus, or of another model, may land on a different
member of the class. Interpolating raw fields of two different members would
mix a homography difference into the result (harmless for straightness but
not for a field that is compared or reported in pixels). So each field is
first brought to the same gauge:

* ``"lsq"`` (default): :math:`H_i` is the homography minimising
  :math:`\sum_p |H_i(U_i(p)) - p|^2` over a grid of the image, i.e. the member
  of the class closest to the identity. It uses every point of the image, so
  it is stable under noise in the fit.
* ``"corners"``: :math:`H_i` maps the 4 corrected image corners back to the
  original corners (the paper's normalisation). Exactly reproducible, but it
  rests on the corners, where a fit is least constrained.

Within one gauge the normalised field is a smooth function of :math:`f` when
the lens is, so its interpolation error is governed by the focus spacing,
and it is measured, not assumed: :func:`leave_one_out_error` interpolates each
interior calibrated setting from the others and compares the result with that
setting's own fit, modulo a homography (:func:`pipeline.compare.compare_models`).
Outside :math:`[f_1, f_n]` nothing was measured: extrapolation is refused.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision
   camera distortion measurements with a calibration harp", JOSA A 29(10), 2012.
.. [2] F. N. Fritsch, R. E. Carlson, "Monotone piecewise cubic interpolation",
   SIAM J. Numer. Anal. 17(2), 1980.
.. [3] C. de Boor, *A Practical Guide to Splines*, Springer 1978 (not-a-knot cubic spline).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline, PchipInterpolator

from pipeline.compare import compare_models, fit_homography, image_grid
from pipeline.models.base import DistortionModel
from pipeline.models.grid_field import GridFieldModel
from pipeline.models.homography import apply_homography
from pipeline.normalise import corner_homography

METHODS = ("auto", "linear", "pchip", "cubic")
GAUGES = ("lsq", "corners")
DEFAULT_STEP_PX = 32.0
"""Grid spacing of the interpolated field (px); the bicubic error is O(step^4)."""

ModelsByFocus: TypeAlias = Mapping[float, DistortionModel] | Iterable[tuple[float, DistortionModel]]
"""Calibrated corrections by focus setting: a mapping focus -> model, or ``(focus, model)`` pairs."""


def _as_pairs(models_by_focus: ModelsByFocus) -> list[tuple[float, DistortionModel]]:
    items = list(models_by_focus.items()) if isinstance(models_by_focus, Mapping) else list(models_by_focus)
    pairs = []
    for item in items:
        try:
            f, m = item
        except (TypeError, ValueError):
            raise ValueError("models_by_focus must map focus -> model or be (focus, model) pairs") from None
        f = float(f)
        if not math.isfinite(f):
            raise ValueError(f"focus setting {f} is not finite")
        if not isinstance(m, DistortionModel):
            raise ValueError(f"focus {f:g}: not a DistortionModel ({type(m).__name__})")
        pairs.append((f, m))
    pairs.sort(key=lambda p: p[0])
    fs = [p[0] for p in pairs]
    if len(set(fs)) != len(fs):
        raise ValueError(f"focus settings must be distinct, got {fs}")
    return pairs


def gauge_homography(
    model: DistortionModel, width: int, height: int, gauge: str = "lsq", step: float = 32.0
) -> np.ndarray:
    """The homography ``H`` bringing ``model`` to the ``gauge`` (see the module doc)."""
    if gauge == "corners":
        return corner_homography(model, width, height)
    if gauge == "lsq":
        grid = image_grid(width, height, step)
        h, _ = fit_homography(model.undistort_points(grid), grid)
        return h
    raise ValueError(f"unknown gauge {gauge!r}; known: {', '.join(GAUGES)}")


def field_grid(width: int, height: int, step: float = DEFAULT_STEP_PX) -> tuple[np.ndarray, np.ndarray]:
    """Node coordinates ``(xs, ys)`` covering the image plus one ``step`` of margin."""
    if int(width) < 2 or int(height) < 2:
        raise ValueError(f"image size must be at least 2x2, got {width}x{height}")
    if not step > 0:
        raise ValueError(f"grid step must be > 0, got {step}")
    nx = int(math.ceil((width - 1 + 2 * step) / step)) + 1
    ny = int(math.ceil((height - 1 + 2 * step) / step)) + 1
    return -step + step * np.arange(nx), -step + step * np.arange(ny)


def normalised_field(
    model: DistortionModel, xs: np.ndarray, ys: np.ndarray, homography: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``u = H(U(p)) - p`` at the nodes ``xs x ys``, as two ``(ny, nx)`` arrays."""
    xx, yy = np.meshgrid(xs, ys)
    p = np.stack([xx.ravel(), yy.ravel()], axis=1)
    u = apply_homography(homography, model.undistort_points(p)) - p
    if not np.all(np.isfinite(u)):
        raise ValueError("the correction is not finite over the image grid")
    return u[:, 0].reshape(xx.shape), u[:, 1].reshape(xx.shape)


class FocusInterpolator:
    """Corrections fitted at several focus settings, ready to be interpolated.

    Parameters
    ----------
    models_by_focus : mapping focus -> DistortionModel, or (focus, model) pairs
        At least two distinct focus settings; all for a ``width x height`` image.
    width, height : int
        Image size.
    method : {'auto', 'linear', 'pchip', 'cubic'}
        Interpolation in focus; ``auto`` is ``pchip`` with >= 3 settings, else linear.
    gauge : {'lsq', 'corners'}
        How each field is brought to a common homography gauge (module doc).
    step : float
        Grid spacing (px) of the interpolated field.
    """

    def __init__(
        self,
        models_by_focus: ModelsByFocus,
        width: int,
        height: int,
        *,
        method: str = "auto",
        gauge: str = "lsq",
        step: float = DEFAULT_STEP_PX,
    ) -> None:
        if method not in METHODS:
            raise ValueError(f"unknown interpolation method {method!r}; known: {', '.join(METHODS)}")
        if gauge not in GAUGES:
            raise ValueError(f"unknown gauge {gauge!r}; known: {', '.join(GAUGES)}")
        pairs = _as_pairs(models_by_focus)
        if len(pairs) < 2:
            raise ValueError(f"focus interpolation needs at least 2 calibrated focus settings, got {len(pairs)}")
        self.width, self.height = int(width), int(height)
        self.gauge, self.step = gauge, float(step)
        self.focus = np.array([f for f, _ in pairs])
        self.models = tuple(m for _, m in pairs)
        if method == "auto":
            method = "pchip" if len(pairs) >= 3 else "linear"
        self.method = method
        self.xs, self.ys = field_grid(self.width, self.height, self.step)
        dx, dy = [], []
        for f, m in pairs:
            try:
                h = gauge_homography(m, self.width, self.height, gauge)
                fx, fy = normalised_field(m, self.xs, self.ys, h)
            except (ValueError, np.linalg.LinAlgError) as exc:
                raise ValueError(f"focus {f:g}: {exc}") from None
            dx.append(fx)
            dy.append(fy)
        self._field = np.stack([np.stack(dx), np.stack(dy)], axis=1)  # (n, 2, ny, nx)
        if method == "linear" or len(pairs) == 2:
            self._interp = None
        elif method == "pchip":
            self._interp = PchipInterpolator(self.focus, self._field, axis=0, extrapolate=False)
        else:
            self._interp = CubicSpline(self.focus, self._field, axis=0, bc_type="not-a-knot", extrapolate=False)

    @property
    def focus_range(self) -> tuple[float, float]:
        return float(self.focus[0]), float(self.focus[-1])

    def field_at(self, focus: float) -> np.ndarray:
        """Interpolated normalised field ``(2, ny, nx)`` at ``focus``; ValueError outside the range."""
        f = float(focus)
        lo, hi = self.focus_range
        tol = 1e-9 * max(1.0, abs(hi - lo))
        if not math.isfinite(f) or f < lo - tol or f > hi + tol:
            raise ValueError(
                f"focus {focus:g} is outside the calibrated range [{lo:g}, {hi:g}]: "
                f"extrapolation refused (calibrate that focus setting)"
            )
        f = min(max(f, lo), hi)
        if self._interp is None:
            k = int(np.clip(np.searchsorted(self.focus, f, side="right") - 1, 0, len(self.focus) - 2))
            a = (f - self.focus[k]) / (self.focus[k + 1] - self.focus[k])
            u: NDArray[np.float64] = (1 - a) * self._field[k] + a * self._field[k + 1]
            return u
        return np.asarray(self._interp(f))

    def at(self, focus: float) -> GridFieldModel:
        """The interpolated correction at ``focus`` (ValueError outside the calibrated range)."""
        u = self.field_at(focus)
        return GridFieldModel(
            origin=(float(self.xs[0]), float(self.ys[0])),
            step=self.step,
            dx=u[0],
            dy=u[1],
            width=self.width,
            height=self.height,
            info={
                "interpolated_focus": float(focus),
                "method": self.method,
                "gauge": self.gauge,
                "calibrated_focus": [float(v) for v in self.focus],
            },
        )


def interpolate_correction(
    models_by_focus: ModelsByFocus,
    focus: float,
    width: int,
    height: int,
    *,
    method: str = "auto",
    gauge: str = "lsq",
    step: float = DEFAULT_STEP_PX,
) -> GridFieldModel:
    """The correction at ``focus`` interpolated between calibrated settings.

    See :class:`FocusInterpolator` for the parameters. Raises ValueError for a
    focus outside the calibrated range (no extrapolation), fewer than 2
    settings, or a correction that is not finite over the image.
    """
    return FocusInterpolator(models_by_focus, width, height, method=method, gauge=gauge, step=step).at(focus)


@dataclass(frozen=True)
class LeaveOneOut:
    """Interpolation error at one calibrated focus left out (pixels, modulo homography)."""

    focus: float
    rms_px: float
    max_px: float

    def __iter__(self) -> Iterator[float]:  # unpacks as (focus, rms_px, max_px)
        return iter((self.focus, self.rms_px, self.max_px))


def leave_one_out_error(
    models_by_focus: ModelsByFocus,
    width: int,
    height: int,
    *,
    method: str = "auto",
    gauge: str = "lsq",
    step: float = DEFAULT_STEP_PX,
    compare_step: float = 10.0,
) -> list[LeaveOneOut]:
    """Interpolation error measured by leaving each interior calibrated focus out.

    For every interior setting :math:`f_i` (the two ends cannot be reached
    without extrapolating), the correction at :math:`f_i` is interpolated from
    the other settings and compared with the fit at :math:`f_i` modulo the
    best homography over a ``compare_step`` grid of the image
    (:func:`pipeline.compare.compare_models`).

    Returns
    -------
    list of LeaveOneOut
        ``(focus, rms_px, max_px)`` per interior setting (empty with only 2
        settings: nothing can be left out without extrapolating).

    Notes
    -----
    Leaving a setting out doubles the local focus spacing, so this estimate is
    pessimistic for the interpolation between the full set of settings
    (for linear interpolation of a field with curvature in focus, about 4 x).
    With 3 settings the middle one is interpolated from the 2 others, i.e.
    linearly, whatever ``method``. The error also contains the fits' own
    noise at the settings compared (the fit is the only truth a station has).
    """
    pairs = _as_pairs(models_by_focus)
    if len(pairs) < 2:
        raise ValueError(f"need at least 2 calibrated focus settings, got {len(pairs)}")
    out = []
    for i in range(1, len(pairs) - 1):
        others = pairs[:i] + pairs[i + 1 :]
        m = interpolate_correction(others, pairs[i][0], width, height, method=method, gauge=gauge, step=step)
        c = compare_models(m, pairs[i][1], width, height, step=compare_step)
        out.append(LeaveOneOut(pairs[i][0], c.rms, c.max))
    return out
