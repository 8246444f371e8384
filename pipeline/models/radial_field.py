r"""A radial correction plus a regularised residual field (tensor-product cubic B-splines), and
its parametrisation for the fit.

The radial + tangential + prism family (:class:`~pipeline.models.radial.RadialModel`) cannot
follow what a real lens adds to it: surface irregularities of the elements, a sensor that is
not flat, moulding errors of aspheres give a smooth but irregular displacement of a few
hundredths of a pixel (:mod:`pipeline.lens_population`'s non-parametric field). This model
adds such a field to the radial correction, as mrcal's *splined stereographic* model does for
chessboard calibrations [1]_: a uniform cubic B-spline surface over the image whose knot
density and smoothness penalty are chosen by cross-validation (:mod:`pipeline.select`), so that
it carries only what the radial model lacks and what held-out shots confirm.

References
----------
.. [1] D. Kogan, mrcal, "Splined stereographic lens model",
   https://mrcal.secretsauce.net/splined-models.html (cubic B-spline surfaces with a
   regularisation penalty on top of a projection).
.. [2] C. de Boor, *A Practical Guide to Splines*, Springer, 1978 (uniform B-splines).
.. [3] P. H. C. Eilers, B. D. Marx, "Flexible smoothing with B-splines and penalties",
   Statistical Science 11(2), 1996 (P-splines: a difference penalty on the coefficients).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.models.base import DistortionModel
from pipeline.models.radial import RadialModel, RadialParametrisation

FIELD_MARGIN = 0.02
"""Margin of the B-spline domain beyond the image, as a fraction of its width and height."""

FIELD_GAUGE_WEIGHT = 1.0
"""Weight of the rows that hold the affine part of the field at zero (:class:`RadialFieldParametrisation`)."""


def field_bounds(width: int, height: int, margin: float = FIELD_MARGIN) -> tuple[float, float, float, float]:
    """``(x0, y0, x1, y1)``: the B-spline domain of a ``width x height`` image (pixel-centre coordinates):
    the image's extent ``[-1/2, width - 1/2] x [-1/2, height - 1/2]`` plus ``margin`` of its size each side."""
    mx, my = margin * width, margin * height
    return (-0.5 - mx, -0.5 - my, width - 0.5 + mx, height - 0.5 + my)


def knot_spacing(bounds: tuple[float, float, float, float], shape: tuple[int, int]) -> tuple[float, float]:
    """``(hx, hy)``: the knot spacing of a ``shape = (ny, nx)`` control grid over ``bounds = (x0, y0, x1, y1)``
    (pixels): the domain cut into ``n - 3`` intervals per axis (:func:`bspline_weights`)."""
    x0, y0, x1, y1 = bounds
    return (x1 - x0) / (shape[1] - 3), (y1 - y0) / (shape[0] - 3)


def bspline_weights(x: np.ndarray, lo: float, hi: float, n: int) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    r"""The uniform cubic B-spline basis of ``n`` control points over ``[lo, hi]`` at ``x``.

    ``[lo, hi]`` is cut into ``n - 3`` intervals of length :math:`h`; a point in interval
    :math:`k` (clamped to ``0 .. n - 4``: beyond the domain the end piece's cubic goes on), at
    :math:`t = (x - lo)/h - k`, has the non-zero basis values of control points
    :math:`k .. k + 3`:

    .. math::
        b_0 = \tfrac{(1-t)^3}{6},\ b_1 = \tfrac{3t^3 - 6t^2 + 4}{6},\
        b_2 = \tfrac{-3t^3 + 3t^2 + 3t + 1}{6},\ b_3 = \tfrac{t^3}{6}

    Returns ``(k (N,), b (N, 4))``. The four sum to 1 and reproduce every cubic polynomial.
    """
    h = (hi - lo) / (n - 3)
    u = (np.asarray(x, dtype=np.float64) - lo) / h
    k = np.clip(np.floor(u), 0, n - 4).astype(np.intp)
    t = u - k
    t2 = t * t
    t3 = t2 * t
    b = np.empty((len(t), 4))
    b[:, 0] = (1.0 - t) ** 3 / 6.0
    b[:, 1] = (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0
    b[:, 2] = (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0
    b[:, 3] = t3 / 6.0
    return k, b


def field_basis(
    xy: np.ndarray, bounds: tuple[float, float, float, float], shape: tuple[int, int]
) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """The 16 non-zero tensor-product basis values of each point: ``(index (N, 16), value (N, 16))``,
    ``index`` into the flattened ``(ny, nx)`` control grid (row ``j`` = y)."""
    ny, nx = shape
    x0, y0, x1, y1 = bounds
    kx, bx = bspline_weights(xy[:, 0], x0, x1, nx)
    ky, by = bspline_weights(xy[:, 1], y0, y1, ny)
    a = np.arange(4)
    idx = (ky[:, None, None] + a[None, :, None]) * nx + (kx[:, None, None] + a[None, None, :])
    val = by[:, :, None] * bx[:, None, :]
    return idx.reshape(-1, 16), val.reshape(-1, 16)


def field_matrix(xy: np.ndarray, bounds: tuple[float, float, float, float], shape: tuple[int, int]) -> np.ndarray:
    """The dense basis matrix ``(ny * nx, N)``: column ``i`` holds every control point's basis value at point ``i``."""
    idx, val = field_basis(xy, bounds, shape)
    return _basis_matrix(idx, val, shape[0] * shape[1])


def _basis_matrix(idx: NDArray[np.intp], val: NDArray[np.float64], n_field: int) -> np.ndarray:
    """:func:`field_matrix` from :func:`field_basis`'s ``(idx, val)``."""
    out = np.zeros((n_field, len(idx)))
    cols = np.broadcast_to(np.arange(len(idx))[:, None], idx.shape)
    np.add.at(out, (idx.ravel(), cols.ravel()), val.ravel())
    return out


@dataclass(frozen=True, eq=False)
class FieldRows:
    """The rows of a fit's projected Jacobian (:func:`pipeline.fit_problem.normal_equations`) that are a B-spline
    field's coefficients, kept sparse: the x coefficients are rows ``row_x + j``, the y coefficients ``row_y + j``
    (``j < m``); at point ``i`` the rows ``idx[i]`` hold ``val[i]`` times the x (resp. y) component of the unit
    vector projected on, the others zero (:func:`field_basis`). The points grouped by the cell of the grid they
    lie in (all of a cell's points have the same 16 rows): ``order`` sorts them by cell, ``place`` gives each
    sorted point's place ``cell * size + slot`` in a zero-padded ``(cells, size)`` layout, ``cell_idx``
    ``(cells, 16)`` each cell's rows, ``size`` the most points of a cell, ``val_sorted`` the values in that order
    and ``keys`` ``(cells, 32, 32)`` where each cell's products of its x and y rows go in the ``(2m, 2m)`` block
    of both components (flattened)."""

    row_x: int
    row_y: int
    m: int
    idx: NDArray[np.intp]
    val: NDArray[np.float64]
    order: NDArray[np.intp]
    place: NDArray[np.intp]
    cell_idx: NDArray[np.intp]
    size: int
    val_sorted: NDArray[np.float64]
    keys: NDArray[np.intp]

    @classmethod
    def of(cls, row_x: int, row_y: int, m: int, idx: NDArray[np.intp], val: NDArray[np.float64]) -> FieldRows:
        order = np.argsort(idx[:, 0], kind="stable").astype(np.intp)
        first = idx[order, 0]
        new = np.flatnonzero(np.r_[True, first[1:] != first[:-1]]) if len(first) else np.zeros(0, np.intp)
        counts = np.diff(np.r_[new, len(first)])
        size = int(counts.max(initial=0))
        place = (np.arange(len(first)) + np.repeat(np.arange(len(new)) * size - new, counts)).astype(np.intp)
        cell_idx = idx[order[new]]
        both = np.concatenate([cell_idx, m + cell_idx], axis=1)
        keys = (both[:, :, None] * (2 * m) + both[:, None, :]).astype(np.intp)
        return cls(row_x, row_y, m, idx, val, order, place, cell_idx, size, val[order], keys)

    def shifted(self, by: int) -> FieldRows:
        """The same rows ``by`` further down (a parametrisation that puts parameters before these)."""
        return replace(self, row_x=self.row_x + by, row_y=self.row_y + by)


@dataclass(frozen=True, eq=False)
class ProjectedRows:
    """A fit's projected Jacobian ``P`` and ``T`` (:meth:`RadialFieldParametrisation.project`), its field rows kept
    sparse (:class:`FieldRows`): the dense rows ``rows`` (indices among the ``n`` parameters) hold ``p`` and ``t``
    ``(len(rows), N)``, the rows of ``field`` the rest."""

    n: int
    rows: NDArray[np.intp]
    p: np.ndarray
    t: np.ndarray
    field: FieldRows | None


@dataclass(frozen=True, eq=False)
class RadialFieldModel(DistortionModel):
    r"""A radial correction followed by a smooth additive field: :math:`x_u = R(x_d) + u(x_d)`.

    :math:`R` is ``base`` (a :class:`~pipeline.models.radial.RadialModel`, its own equation);
    :math:`u = (u_x, u_y)` (pixels) is a tensor-product uniform cubic B-spline surface over the
    image, in image coordinates (not relative to the distortion centre):

    .. math::
        u_x(x, y) = \sum_{j < n_y} \sum_{i < n_x} c^x_{ji}\, B_i\!\left(\tfrac{x - x_0}{h_x}\right)
                    B_j\!\left(\tfrac{y - y_0}{h_y}\right), \qquad
        u_y \text{ likewise with } c^y_{ji},

    :math:`B_i` the cubic B-spline of control point :math:`i` on the uniform knots
    :math:`x_0 + k h_x` (:func:`bspline_weights`), :math:`h_x = (x_1 - x_0)/(n_x - 3)`,
    :math:`h_y = (y_1 - y_0)/(n_y - 3)`; ``bounds`` :math:`= (x_0, y_0, x_1, y_1)` cover the
    image with a margin (:func:`field_bounds`) and beyond them the end pieces' cubics go on.
    The field is C² and reproduces any cubic polynomial exactly; mrcal's splined model [1]_ is
    the same construction on the projection of a camera.

    Parameters: ``base``, ``bounds``, ``cx[j][i]`` = :math:`c^x_{ji}`, ``cy[j][i]`` =
    :math:`c^y_{ji}` (pixels; row ``j`` = y, as an image). ``distort_points`` inverts by
    Newton iterations (:class:`~pipeline.models.base.DistortionModel`).

    References
    ----------
    .. [1] D. Kogan, mrcal, "Splined stereographic lens model",
       https://mrcal.secretsauce.net/splined-models.html
    """

    base: RadialModel
    bounds: tuple[float, float, float, float]
    cx: np.ndarray
    cy: np.ndarray
    name: str = field(default="radial_field", init=False, repr=False)

    def __post_init__(self) -> None:
        cx = np.array(self.cx, dtype=np.float64)
        cy = np.array(self.cy, dtype=np.float64)
        if cx.ndim != 2 or cx.shape != cy.shape or min(cx.shape) < 4:
            raise ValueError(
                f"RadialFieldModel needs two equal (ny, nx) coefficient grids with nx, ny >= 4; "
                f"got {cx.shape} and {cy.shape}"
            )
        if not (np.all(np.isfinite(cx)) and np.all(np.isfinite(cy))):
            raise ValueError("RadialFieldModel field coefficients have non-finite values")
        b = tuple(float(v) for v in self.bounds)
        if len(b) != 4 or not (b[2] > b[0] and b[3] > b[1]):
            raise ValueError(f"RadialFieldModel bounds must be (x0, y0, x1, y1) with x1 > x0, y1 > y0; got {b}")
        cx.setflags(write=False)
        cy.setflags(write=False)
        object.__setattr__(self, "cx", cx)
        object.__setattr__(self, "cy", cy)
        object.__setattr__(self, "bounds", b)

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``: control points per axis."""
        ny, nx = self.cx.shape
        return int(ny), int(nx)

    def displacement(self, xy: np.ndarray) -> np.ndarray:
        """The field :math:`u` at distorted points ``(N, 2)``, pixels."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        idx, val = field_basis(xy, self.bounds, self.shape)
        ux = np.sum(self.cx.ravel()[idx] * val, axis=1)
        uy = np.sum(self.cy.ravel()[idx] * val, axis=1)
        return np.stack([ux, uy], axis=1)

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        out: np.ndarray = self.base.undistort_points(xy) + self.displacement(xy)
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.name,
            "base": self.base.to_dict(),
            "bounds": list(self.bounds),
            "cx": self.cx.tolist(),
            "cy": self.cy.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RadialFieldModel:
        return cls(
            RadialModel.from_dict(d["base"]),
            (float(d["bounds"][0]), float(d["bounds"][1]), float(d["bounds"][2]), float(d["bounds"][3])),
            np.asarray(d["cx"], float),
            np.asarray(d["cy"], float),
        )


def roughness_operator(shape: tuple[int, int], hx: float, hy: float) -> np.ndarray:
    r"""Rows ``D`` with :math:`|Dc|^2 \approx \iint u_{xx}^2 + 2u_{xy}^2 + u_{yy}^2` (the thin-plate
    bending energy) for one component's coefficients ``c`` (flattened ``(ny, nx)``), knot spacings
    ``hx``, ``hy`` (in the units of the integral): second differences along x and y over
    :math:`h^2`, the mixed difference over :math:`h_x h_y`, each times the root of its cell area.
    Its null space is the affine fields (coefficients affine in ``(i, j)``)."""
    ny, nx = shape
    area = math.sqrt(hx * hy)
    rows: list[np.ndarray] = []

    def at(j: int, i: int) -> int:
        return j * nx + i

    for j in range(ny):
        for i in range(1, nx - 1):
            r = np.zeros(ny * nx)
            r[at(j, i - 1)], r[at(j, i)], r[at(j, i + 1)] = 1.0, -2.0, 1.0
            rows.append(r * area / hx**2)
    for j in range(1, ny - 1):
        for i in range(nx):
            r = np.zeros(ny * nx)
            r[at(j - 1, i)], r[at(j, i)], r[at(j + 1, i)] = 1.0, -2.0, 1.0
            rows.append(r * area / hy**2)
    for j in range(ny - 1):
        for i in range(nx - 1):
            r = np.zeros(ny * nx)
            r[at(j, i)], r[at(j + 1, i + 1)], r[at(j, i + 1)], r[at(j + 1, i)] = 1.0, 1.0, -1.0, -1.0
            rows.append(r * math.sqrt(2.0) * area / (hx * hy))
    return np.asarray(rows)


def axis_basis(
    centre: tuple[float, float], bounds: tuple[float, float, float, float], shape: tuple[int, int]
) -> np.ndarray:
    r"""Orthonormal columns ``(2 ny nx, m)`` spanning the coefficients ``[c^x, c^y]`` of the fields that turn with a
    rotation about ``centre`` (pixels, the field's own coordinates): :math:`g(r)\,e_r + h(r)\,e_t`, :math:`r` the
    distance from ``centre``, :math:`e_r, e_t` the radial and tangential unit vectors, :math:`g, h` piecewise linear
    in :math:`r` with a node every knot spacing (the smaller of the two). Each control point stands at its basis
    function's peak (:func:`bspline_weights`: control point ``j`` at ``lo + (j - 1) h``).

    Such a field looks the same in the frame of a harp turning about ``centre`` at every turntable angle: to the
    joint fit of a lens and its strings' bends (:mod:`pipeline.harp_shape`) it is a set of bends, one per string
    at its distance from the axis, and no shot of that one axis can tell the two apart."""
    ny, nx = shape
    x0, y0 = bounds[0], bounds[1]
    hx, hy = knot_spacing(bounds, shape)
    jj, ii = np.mgrid[0:ny, 0:nx].astype(np.float64)
    px = (x0 + (ii - 1.0) * hx).ravel() - float(centre[0])
    py = (y0 + (jj - 1.0) * hy).ravel() - float(centre[1])
    r = np.hypot(px, py)
    with np.errstate(invalid="ignore", divide="ignore"):
        er = np.where(r[:, None] > 1e-9, np.stack([px, py], axis=1) / r[:, None], 0.0)
    et = np.stack([-er[:, 1], er[:, 0]], axis=1)
    step = min(hx, hy)
    nodes = np.arange(0.0, float(r.max()) + step, step)
    hat = np.clip(1.0 - np.abs(r[:, None] - nodes[None, :]) / step, 0.0, None)  # (ny nx, nodes)
    cols = [np.concatenate([hat * e[:, :1], hat * e[:, 1:]]) for e in (er, et)]
    a = np.concatenate(cols, axis=1)
    return orthonormal_columns(a[:, np.linalg.norm(a, axis=0) > 0])


def orthonormal_columns(a: np.ndarray) -> np.ndarray:
    """Orthonormal columns spanning the columns of ``a`` (QR, the columns of rank below 1e-9 of the largest
    dropped)."""
    q, rr = np.linalg.qr(a)
    keep = np.abs(np.diag(rr)) > 1e-9 * max(float(np.abs(np.diag(rr)).max()), 1e-300)
    return np.asarray(q[:, keep])


def affine_basis(shape: tuple[int, int]) -> np.ndarray:
    """Orthonormal columns ``(ny * nx, 3)`` spanning the coefficients of the affine fields (1, i, j)."""
    ny, nx = shape
    jj, ii = np.mgrid[0:ny, 0:nx].astype(np.float64)
    a = np.stack([np.ones(ny * nx), ii.ravel(), jj.ravel()], axis=1)
    q, _ = np.linalg.qr(a)
    return np.asarray(q)


class RadialFieldParametrisation:
    r"""The free parameters of a :class:`RadialFieldModel` fit, for :func:`pipeline.fit.fit_distortion`.

    ``theta = [radial theta (RadialParametrisation's), c^x (ny nx), c^y (ny nx)]``, the field
    coefficients in pixels, row by row. The corrected point is linear in the field
    coefficients: their Jacobian columns are the basis values :func:`field_matrix`.

    Regularisation (rows appended to the residuals, each scaled by :math:`\sqrt{N}`, ``N`` the
    number of points, so that it weighs like a residual on every point):

    * the radial part's own (centre, projective gauge, ridge: :class:`RadialParametrisation`);
    * **roughness**: ``penalty`` times :func:`roughness_operator` of each component, in pixels
      per half-diagonal² (knot spacings in half-diagonals): the field's thin-plate energy
      :math:`\lambda^2 \iint |\nabla^2 u|^2` costs like a residual of its root on every point.
      A field of amplitude :math:`a` and wavelength :math:`L` half-diagonals has curvature
      :math:`a (2\pi/L)^2`;
    * **gauge**: straight lines stay straight under any homography, so an affine field added
      to the correction is (to first order; exactly if ``R`` is the identity) invisible to the
      fit, and it is also the roughness penalty's null space. ``FIELD_GAUGE_WEIGHT`` times its
      projection on :func:`affine_basis` holds it at zero: the field carries no translation,
      rotation, scale or shear. The first-order projective part (quadratic) has curvature and
      is held by the roughness penalty.
    """

    def __init__(
        self,
        radial: RadialParametrisation,
        width: int,
        height: int,
        shape: tuple[int, int],
        penalty: float,
        gauge: float = FIELD_GAUGE_WEIGHT,
    ) -> None:
        self.radial = radial
        self.shape = (int(shape[0]), int(shape[1]))
        self.bounds = field_bounds(width, height)
        self.penalty, self.gauge = float(penalty), float(gauge)
        self.n_radial = radial.n
        self.n_field = self.shape[0] * self.shape[1]
        self.n = self.n_radial + 2 * self.n_field
        hx, hy = knot_spacing(self.bounds, self.shape)
        self._rough = roughness_operator(self.shape, hx / radial.s, hy / radial.s)
        self._affine = affine_basis(self.shape).T
        self._axis = np.zeros((0, 2 * self.n_field))  # with_axis_gauge's rows on [c^x, c^y]
        self._basis: tuple[np.ndarray, NDArray[np.intp], NDArray[np.float64], np.ndarray, FieldRows] | None = None

    def _field_basis(self, xy: np.ndarray) -> tuple[NDArray[np.intp], NDArray[np.float64], np.ndarray, FieldRows]:
        """:func:`field_basis` and :func:`field_matrix` at ``xy``, kept for the last points asked: a fit evaluates the
        field at the same distorted points at every iteration (the basis depends on them only). The points are
        compared by value, so a changed array is never served a stale basis. With them the field's rows of the
        projected Jacobian (:class:`FieldRows`, :meth:`project_rows`)."""
        kept = self._basis
        if kept is not None and kept[0].shape == xy.shape and np.array_equal(kept[0], xy):
            return kept[1], kept[2], kept[3], kept[4]
        idx, val = field_basis(xy, self.bounds, self.shape)
        mat = _basis_matrix(idx, val, self.n_field)
        for a in (idx, val, mat):
            a.setflags(write=False)
        rows = FieldRows.of(self.n_radial, self.n_radial + self.n_field, self.n_field, idx, val)
        self._basis = (np.array(xy, dtype=np.float64, copy=True), idx, val, mat, rows)
        return idx, val, mat, rows

    def project_rows(self, xy: np.ndarray, th: np.ndarray, nrm: np.ndarray, tan: np.ndarray) -> ProjectedRows:
        """:meth:`project` with the field's rows kept sparse (:class:`ProjectedRows`): the radial rows dense."""
        pr, tr = self.radial.project(xy, th[: self.n_radial], nrm, tan)
        return ProjectedRows(self.n, np.arange(self.n_radial), pr, tr, self._field_basis(xy)[3])

    def with_axis_gauge(self, *centres: tuple[float, float]) -> RadialFieldParametrisation:
        """This parametrisation with the field's parts that turn with a rotation about each of ``centres``
        (distorted pixels; :func:`axis_basis`, their union) held at zero as well, at the affine gauge's weight: for
        a joint fit of the lens with the bends of the strings of a harp turning about those axes. About one axis
        such a part imitates a set of string bends exactly (:mod:`pipeline.harp_shape`); the strings take it
        instead. About two, each axis's part is a set of bends in its own shots only, and what the other shots see
        of it is weak where the axes are near each other."""
        out = copy.copy(self)
        if not centres:
            out._axis = np.zeros((0, 2 * self.n_field))
            return out
        out._axis = orthonormal_columns(np.concatenate([axis_basis(c, self.bounds, self.shape) for c in centres], 1)).T
        return out

    # the radial part's settings that pipeline.fit reads
    @property
    def degree(self) -> int:
        return self.radial.degree

    @property
    def w_center(self) -> float:
        return self.radial.w_center

    @property
    def s(self) -> float:
        return self.radial.s

    def theta0(self, init: DistortionModel | None) -> np.ndarray:
        """Start: ``init``'s radial part (a RadialModel or RadialFieldModel) and, from a
        RadialFieldModel of the same grid and bounds, its field; else a zero field."""
        th = np.zeros(self.n)
        base = init.base if isinstance(init, RadialFieldModel) else init
        th[: self.n_radial] = self.radial.theta0(base)
        if (
            isinstance(init, RadialFieldModel)
            and init.shape == self.shape
            and np.allclose(init.bounds, self.bounds)
            and math.isclose(init.base.scale, self.s)
        ):
            k0 = init.base.k[0]
            th[self.n_radial : self.n_radial + self.n_field] = init.cx.ravel() / k0
            th[self.n_radial + self.n_field :] = init.cy.ravel() / k0
        return th

    def model(self, th: np.ndarray) -> RadialFieldModel:
        base = self.radial.model(th[: self.n_radial])
        f = th[self.n_radial :]
        return RadialFieldModel(
            base, self.bounds, f[: self.n_field].reshape(self.shape), f[self.n_field :].reshape(self.shape)
        )

    def evaluate(self, xy: np.ndarray, th: np.ndarray, jac: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Corrected points ``(N, 2)`` and, with ``jac``, their Jacobian ``(N, 2, n)``."""
        u, d = self.radial.evaluate(xy, th[: self.n_radial], jac)
        idx, val, b, _ = self._field_basis(xy)
        f = th[self.n_radial :]
        u = u + np.stack(
            [np.sum(f[: self.n_field][idx] * val, axis=1), np.sum(f[self.n_field :][idx] * val, axis=1)], axis=1
        )
        if not jac:
            return u, None
        assert d is not None
        full = np.zeros((len(xy), 2, self.n))
        full[:, :, : self.n_radial] = d
        full[:, 0, self.n_radial : self.n_radial + self.n_field] = b.T
        full[:, 1, self.n_radial + self.n_field :] = b.T
        return u, full

    def project(
        self, xy: np.ndarray, th: np.ndarray, nrm: np.ndarray, tan: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The Jacobian projected on ``nrm`` and ``tan``, one row per parameter (``(n, N)`` each):
        the radial rows (:meth:`RadialParametrisation.project`), then the basis values times each
        component of the unit vectors."""
        pr, tr = self.radial.project(xy, th[: self.n_radial], nrm, tan)
        _, _, b, _ = self._field_basis(xy)
        nr, nf = self.n_radial, self.n_field
        p_mat = np.empty((self.n, len(xy)))
        t_mat = np.empty((self.n, len(xy)))
        p_mat[:nr], t_mat[:nr] = pr, tr
        np.multiply(b, nrm[:, 0], out=p_mat[nr : nr + nf])
        np.multiply(b, nrm[:, 1], out=p_mat[nr + nf :])
        np.multiply(b, tan[:, 0], out=t_mat[nr : nr + nf])
        np.multiply(b, tan[:, 1], out=t_mat[nr + nf :])
        return p_mat, t_mat

    def regularisation(self, th: np.ndarray, n_points: int) -> tuple[np.ndarray, np.ndarray]:
        """Penalty residuals and their Jacobian rows (see the class docstring)."""
        g_r, j_r = self.radial.regularisation(th[: self.n_radial], n_points)
        w = math.sqrt(max(n_points, 1))
        nr, nf = self.n_radial, self.n_field
        blocks = [self.penalty * w * self._rough, self.gauge * w * self._affine]
        rows_per = sum(b.shape[0] for b in blocks)
        jac = np.zeros((len(g_r) + 2 * rows_per + len(self._axis), self.n))
        jac[: len(g_r), :nr] = j_r
        r0 = len(g_r)
        for comp in range(2):
            c0 = nr + comp * nf
            for b in blocks:
                jac[r0 : r0 + b.shape[0], c0 : c0 + nf] = b
                r0 += b.shape[0]
        jac[r0:, nr:] = self.gauge * w * self._axis
        g = np.concatenate([g_r, jac[len(g_r) :] @ th])
        return g, jac
