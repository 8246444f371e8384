"""Non-radial bivariate polynomial correction (Tang et al., ICIP 2011), and its
parametrisation for the fit (:class:`PolynomialParametrisation`, on the same
monomial basis :func:`monomials`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.models.base import INVERSE_TOL_PX, DistortionModel
from pipeline.models.inverse import Inverse, newton_inverse

Floats = NDArray[np.float64]


def monomial_exponents(degree: int) -> list[tuple[int, int]]:
    """Exponents ``(i, j)`` of the monomials ``xi**i * eta**j``, ``i + j <= degree``.

    Order: by total degree ``d = i + j`` ascending, then by ``j`` ascending:
    ``1, xi, eta, xi^2, xi eta, eta^2, xi^3, ...``.
    """
    return [(d - j, j) for d in range(degree + 1) for j in range(d + 1)]


def monomials(xi: np.ndarray, eta: np.ndarray, degree: int) -> np.ndarray:
    """Matrix ``(N, M)`` of the monomials of :func:`monomial_exponents` at the points."""
    xi = np.asarray(xi, dtype=np.float64)
    eta = np.asarray(eta, dtype=np.float64)
    px = [np.ones_like(xi)]
    py = [np.ones_like(eta)]
    for _ in range(degree):
        px.append(px[-1] * xi)
        py.append(py[-1] * eta)
    return np.stack([px[i] * py[j] for i, j in monomial_exponents(degree)], axis=-1)


def poly_eval(coef: np.ndarray, xi: np.ndarray, eta: np.ndarray, degree: int) -> np.ndarray:
    """``sum c_ij xi^i eta^j`` (coefficients in :func:`monomial_exponents` order), nested Horner."""
    idx = {e: k for k, e in enumerate(monomial_exponents(degree))}
    out: np.ndarray | None = None
    for j in range(degree, -1, -1):  # Horner in eta over inner Horner polynomials in xi
        inner = np.full_like(xi, coef[idx[degree - j, j]])
        for i in range(degree - j - 1, -1, -1):
            inner = inner * xi + coef[idx[i, j]]
        out = inner if out is None else out * eta + inner
    if out is None:
        raise ValueError(f"polynomial degree must be >= 0, got {degree}")
    return out


def _derivative_coefficients(coef: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients (same degree and order) of d/dxi and d/deta of the polynomial ``coef``."""
    ex = monomial_exponents(degree)
    idx = {e: k for k, e in enumerate(ex)}
    dx = np.zeros(len(ex))
    dy = np.zeros(len(ex))
    for k, (i, j) in enumerate(ex):
        if i:
            dx[idx[i - 1, j]] += i * coef[k]
        if j:
            dy[idx[i, j - 1]] += j * coef[k]
    return dx, dy


@dataclass(frozen=True)
class PolynomialModel(DistortionModel):
    r"""Bivariate polynomial correction of degree ``n``, separate for x and y.

    Maps distorted pixels :math:`(x_d, y_d)` to ideal pixels :math:`(x_u, y_u)`.
    With the normalised offsets :math:`\xi = (x_d - c_x)/s`, :math:`\eta = (y_d - c_y)/s`:

    .. math::
        x_u = c_x + s \sum_{i+j \le n} a_{ij}\, \xi^i \eta^j, \qquad
        y_u = c_y + s \sum_{i+j \le n} b_{ij}\, \xi^i \eta^j

    The identity is :math:`a_{10} = b_{01} = 1`, all other coefficients 0.
    ``center`` and ``scale`` are a fixed normalisation (by convention the image
    centre and half the image diagonal), not free parameters: a full polynomial
    absorbs any shift of the centre.

    Parameter order (as in :meth:`params`): ``a`` then ``b``, each in the
    monomial order of :func:`monomial_exponents` (``1, xi, eta, xi^2, xi eta,
    eta^2, xi^3, ...``); ``(n + 1)(n + 2)/2`` coefficients each.

    :meth:`distort_points` (the inverse) uses the damped Newton iterations of
    :func:`pipeline.models.inverse.newton_inverse` with the analytic Jacobian, accurate to
    ``INVERSE_TOL_PX`` (1e-9 px) wherever the map is invertible; points where it does not
    converge, or where the map folds, are NaN (:meth:`distort_inverse` says why).

    References
    ----------
    .. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "Lens
       distortion correction with a calibration harp", ICIP 2011.
    .. [2] Z. Tang et al., "High-precision camera distortion measurements
       with a calibration harp", JOSA A 29(10), 2012.
    """

    center: tuple[float, float]
    degree: int
    a: tuple[float, ...]
    b: tuple[float, ...]
    scale: float = 1000.0
    name: str = field(default="poly", init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", tuple(float(v) for v in self.center))
        if len(self.center) != 2:
            raise ValueError(f"PolynomialModel center needs (x, y), got {len(self.center)} values")
        object.__setattr__(self, "degree", int(self.degree))
        object.__setattr__(self, "a", tuple(float(v) for v in self.a))
        object.__setattr__(self, "b", tuple(float(v) for v in self.b))
        m = (self.degree + 1) * (self.degree + 2) // 2
        if self.degree < 1:
            raise ValueError(f"PolynomialModel degree must be >= 1, got {self.degree}")
        if len(self.a) != m or len(self.b) != m:
            raise ValueError(
                f"PolynomialModel of degree {self.degree} needs {m} coefficients "
                f"for x and for y, got {len(self.a)} and {len(self.b)}"
            )
        if not self.scale > 0:
            raise ValueError(f"PolynomialModel scale must be > 0, got {self.scale}")

    @staticmethod
    def n_coefficients(degree: int) -> int:
        """Number of coefficients per coordinate, ``(n + 1)(n + 2)/2``."""
        return (degree + 1) * (degree + 2) // 2

    @classmethod
    def identity(cls, width: int, height: int, degree: int) -> PolynomialModel:
        """The identity of the given degree, normalised for a ``width x height`` image."""
        m = cls.n_coefficients(degree)
        a = np.zeros(m)
        b = np.zeros(m)
        a[1] = 1.0  # xi
        b[2] = 1.0  # eta
        return cls(
            center=((width - 1) / 2.0, (height - 1) / 2.0),
            degree=degree,
            a=tuple(a),
            b=tuple(b),
            scale=0.5 * float(np.hypot(width, height)),
        )

    def params(self) -> np.ndarray:
        """Parameter vector in the documented order (``a`` then ``b``)."""
        return np.asarray(self.a + self.b, dtype=np.float64)

    def _normalised(self, xy: ArrayLike) -> tuple[Floats, Floats]:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return (xy[:, 0] - self.center[0]) / self.scale, (xy[:, 1] - self.center[1]) / self.scale

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        xi, eta = self._normalised(xy)
        s = self.scale
        return np.stack(
            [
                self.center[0] + s * poly_eval(np.asarray(self.a), xi, eta, self.degree),
                self.center[1] + s * poly_eval(np.asarray(self.b), xi, eta, self.degree),
            ],
            axis=1,
        )

    def distort_inverse(self, xy: np.ndarray, max_iter: int = 50) -> Inverse:
        """Inverse of :meth:`undistort_points`: damped Newton with the analytic Jacobian
        (:func:`pipeline.models.inverse.newton_inverse`) from the first-order inverse ``2 t - U(t)``."""
        target = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        a, b = np.asarray(self.a), np.asarray(self.b)
        da_x, da_y = _derivative_coefficients(a, self.degree)
        db_x, db_y = _derivative_coefficients(b, self.degree)

        def jacobian(x: Floats) -> tuple[Floats, Floats, Floats, Floats]:
            xi, eta = self._normalised(x)
            j11, j12, j21, j22 = (poly_eval(c, xi, eta, self.degree) for c in (da_x, da_y, db_x, db_y))
            return j11, j12, j21, j22

        start = 2 * target - self.undistort_points(target)
        return newton_inverse(
            self.undistort_points, target, start, tol=INVERSE_TOL_PX, h=0.0, max_iter=max_iter, jacobian=jacobian
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.name,
            "center": list(self.center),
            "scale": self.scale,
            "degree": self.degree,
            "a": list(self.a),
            "b": list(self.b),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PolynomialModel:
        return cls(
            center=tuple(d["center"]),
            degree=int(d["degree"]),
            a=tuple(d["a"]),
            b=tuple(d["b"]),
            scale=float(d["scale"]),
        )


class PolynomialParametrisation:
    """The free coefficients of a :class:`PolynomialModel` fit, with the gauge fixed.

    The full coefficient vector ``[a, b]`` is ``t0 + T @ theta``: the constant and
    linear terms are the identity's (``t0``; translation, rotation, scale and shear are
    a homography's, which straight lines cannot see), and the first-order projective
    part is removed by tying ``b_11 = -a_20`` and ``b_02 = -a_11`` (see
    :mod:`pipeline.fit`). The corrected points are linear in ``theta``: their Jacobian
    is ``s * monomials @ T``. ``regularisation`` is a ridge of weight ``ridge``.
    """

    def __init__(self, width: int, height: int, degree: int, ridge: float) -> None:
        self.ident = PolynomialModel.identity(width, height, degree)
        self.s = self.ident.scale
        self.degree = int(degree)
        m = PolynomialModel.n_coefficients(degree)
        self.m = m
        self.t0 = self.ident.params()
        cols = []
        for k in range(3, m):  # a_ij, degree >= 2
            e = np.zeros(2 * m)
            e[k] = 1.0
            if k == 3:
                e[m + 4] = -1.0  # b11 = -a20
            if k == 4:
                e[m + 5] = -1.0  # b02 = -a11
            cols.append(e)
        for k in range(3, m):
            if k in (4, 5):
                continue
            e = np.zeros(2 * m)
            e[m + k] = 1.0
            cols.append(e)
        self.T = np.stack(cols, axis=1)
        self.n = self.T.shape[1]
        self.ridge = ridge

    def theta0(self, init: DistortionModel | None) -> np.ndarray:
        """Start: ``init`` (a PolynomialModel of at most this degree, projected) or the identity."""
        if isinstance(init, PolynomialModel) and init.degree <= self.degree:
            full = np.zeros(2 * self.m)
            idx = {e: i for i, e in enumerate(monomial_exponents(self.degree))}
            for i, e in enumerate(monomial_exponents(init.degree)):
                full[idx[e]] = init.a[i]
                full[self.m + idx[e]] = init.b[i]
            theta: Floats = np.linalg.lstsq(self.T, full - self.t0, rcond=None)[0]
            return theta
        return np.zeros(self.n)

    def model(self, th: np.ndarray) -> PolynomialModel:
        full = self.t0 + self.T @ th
        return PolynomialModel(
            center=self.ident.center, degree=self.degree, a=tuple(full[: self.m]), b=tuple(full[self.m :]), scale=self.s
        )

    def _basis(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Monomials ``(N, m)`` of ``xy`` and the (constant) Jacobian's x and y parts as rows
        ``(2, n, N)``, kept for the last ``xy`` (a fit evaluates the same points at every iteration)."""
        cached = getattr(self, "_cached", None)
        if cached is not None and cached[0] is xy:
            return cached[1], cached[2]
        c = self.ident.center
        mon = monomials((xy[:, 0] - c[0]) / self.s, (xy[:, 1] - c[1]) / self.s, self.degree)
        rows = np.empty((2, self.n, len(xy)))
        np.matmul(self.s * self.T[: self.m].T, mon.T, out=rows[0])
        np.matmul(self.s * self.T[self.m :].T, mon.T, out=rows[1])
        rows.setflags(write=False)
        self._cached = (xy, mon, rows)
        return mon, rows

    def evaluate(self, xy: np.ndarray, th: np.ndarray, jac: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Corrected points ``(N, 2)`` and, with ``jac``, their Jacobian ``(N, 2, n)`` (linear in
        ``theta``, it does not change between iterations)."""
        c = self.ident.center
        mon, rows = self._basis(xy)
        full = self.t0 + self.T @ th
        u = np.stack([c[0] + self.s * (mon @ full[: self.m]), c[1] + self.s * (mon @ full[self.m :])], axis=1)
        if not jac:
            return u, None
        return u, rows.transpose(2, 0, 1)

    def project(
        self, xy: np.ndarray, th: np.ndarray, nrm: np.ndarray, tan: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The Jacobian of the corrected points projected on the unit vectors ``nrm`` and ``tan``
        (per point, ``(N, 2)``), one row per parameter: ``(P, T)``, each ``(n, N)``,
        ``P[:, i] = nrm[i] . du_i/dtheta``."""
        _, rows = self._basis(xy)
        p_mat = rows[0] * nrm[:, 0]
        p_mat += rows[1] * nrm[:, 1]
        t_mat = rows[0] * tan[:, 0]
        t_mat += rows[1] * tan[:, 1]
        return p_mat, t_mat

    def regularisation(self, th: np.ndarray, n_points: int) -> tuple[np.ndarray, np.ndarray]:
        """Ridge residuals and their Jacobian rows."""
        if self.ridge <= 0:
            return np.zeros(0), np.zeros((0, self.n))
        e = math.sqrt(max(n_points, 1)) * self.ridge * self.s * np.eye(self.n)
        return e @ th, e
