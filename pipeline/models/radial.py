"""Radial polynomial correction with free centre, plus Brown–Conrady terms, and its
parametrisation for the fit.

The correction is linear in its coefficients ``k0 … kN, p1, p2, s1 … s4``:
:func:`radial_basis` writes the formula once, as the basis function of each
coefficient, and both the model (:class:`RadialModel`, a sum over the terms) and the
fit (:class:`RadialParametrisation`, the terms as Jacobian columns) use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pipeline.models.base import DistortionModel


def radial_basis(
    xi: np.ndarray, eta: np.ndarray, degree: int, tangential: bool, prism: bool
) -> tuple[list[np.ndarray], list[tuple[np.ndarray, np.ndarray]]]:
    r"""The basis functions of :class:`RadialModel`, in parameter order.

    For normalised offsets ``xi``, ``eta`` (:math:`\rho^2 = \xi^2 + \eta^2`) returns
    ``(powers, extra)``: ``powers[m]`` is :math:`\rho^m` (``m = 0 … degree``), the term of
    :math:`k_m` being :math:`\rho^m (\xi, \eta)`; ``extra`` holds the ``(xi_u part,
    eta_u part)`` of the other terms — with ``tangential``, :math:`p_1`:
    :math:`(2\xi\eta,\ \rho^2 + 2\eta^2)` and :math:`p_2`: :math:`(\rho^2 + 2\xi^2,\ 2\xi\eta)`;
    then, with ``prism``, :math:`s_1`: :math:`(\rho^2, 0)`, :math:`s_2`: :math:`(\rho^4, 0)`,
    :math:`s_3`: :math:`(0, \rho^2)`, :math:`s_4`: :math:`(0, \rho^4)`. The corrected
    offsets are the coefficient-weighted sum of the terms (:meth:`RadialModel.undistort_points`).
    """
    rho2 = xi * xi + eta * eta
    rho = np.sqrt(rho2)
    powers = [np.ones_like(rho)]
    for _ in range(degree):
        powers.append(powers[-1] * rho)
    extra: list[tuple[np.ndarray, np.ndarray]] = []
    if tangential:
        extra += [(2 * xi * eta, rho2 + 2 * eta * eta), (rho2 + 2 * xi * xi, 2 * xi * eta)]
    if prism:
        z = np.zeros_like(rho)
        extra += [(rho2, z), (rho2 * rho2, z), (z, rho2), (z, rho2 * rho2)]
    return powers, extra


@dataclass(frozen=True)
class RadialModel(DistortionModel):
    r"""Radial polynomial correction with a free centre (Tang et al. 2012, eq. 1),
    optionally with decentering (tangential) and thin-prism terms (Brown–Conrady).

    Maps distorted pixels :math:`(x_d, y_d)` to ideal pixels :math:`(x_u, y_u)`.
    With the normalised offsets :math:`\xi = (x_d - c_x)/s`,
    :math:`\eta = (y_d - c_y)/s`, :math:`\rho^2 = \xi^2 + \eta^2`:

    .. math::
        f(\rho) &= k_0 + k_1 \rho + k_2 \rho^2 + \dots + k_N \rho^N \\
        \xi_u &= f(\rho)\,\xi + 2 p_1 \xi\eta + p_2(\rho^2 + 2\xi^2) + s_1\rho^2 + s_2\rho^4 \\
        \eta_u &= f(\rho)\,\eta + p_1(\rho^2 + 2\eta^2) + 2 p_2 \xi\eta + s_3\rho^2 + s_4\rho^4 \\
        x_u &= c_x + s\,\xi_u, \quad y_u = c_y + s\,\eta_u

    ``s`` (``scale``) is a fixed normalisation, by convention half the image
    diagonal, so that the coefficients do not depend on the image size.

    Parameter order (as in :meth:`params`): ``cx, cy, k0 … kN, p1, p2, s1 … s4``
    (``p`` and ``s`` present only when enabled).

    References
    ----------
    .. [1] Z. Tang et al., "High-precision camera distortion measurements
       with a calibration harp", JOSA A 29(10), 2012.
    .. [2] D. C. Brown, "Decentering distortion of lenses", Photogrammetric
       Engineering 32(3), 1966.
    """

    center: tuple[float, float]
    k: tuple[float, ...] = (1.0,)
    scale: float = 1000.0
    tangential: tuple[float, float] | None = None
    prism: tuple[float, float, float, float] | None = None
    name: str = field(default="radial", init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "center", tuple(float(v) for v in self.center))
        object.__setattr__(self, "k", tuple(float(v) for v in self.k))
        if self.tangential is not None:
            object.__setattr__(self, "tangential", tuple(float(v) for v in self.tangential))
        if self.prism is not None:
            object.__setattr__(self, "prism", tuple(float(v) for v in self.prism))
        if not self.k:
            raise ValueError("RadialModel needs at least k0")
        if not self.scale > 0:
            raise ValueError(f"RadialModel scale must be > 0, got {self.scale}")

    @classmethod
    def for_image(cls, width: int, height: int, k=(1.0,), center=None, **kw) -> RadialModel:
        """Model with ``scale`` = half diagonal and centre (default) at the image centre."""
        if center is None:
            center = ((width - 1) / 2.0, (height - 1) / 2.0)
        return cls(center=center, k=tuple(k), scale=0.5 * float(np.hypot(width, height)), **kw)

    def params(self) -> np.ndarray:
        """Parameter vector in the documented order."""
        p = [*self.center, *self.k]
        if self.tangential is not None:
            p += list(self.tangential)
        if self.prism is not None:
            p += list(self.prism)
        return np.asarray(p, dtype=np.float64)

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        s = self.scale
        xi = (xy[:, 0] - self.center[0]) / s
        eta = (xy[:, 1] - self.center[1]) / s
        powers, extra = radial_basis(xi, eta, len(self.k) - 1, self.tangential is not None, self.prism is not None)
        f = self.k[0] * powers[0]
        for km, pw in zip(self.k[1:], powers[1:], strict=True):
            f = f + km * pw
        xu, yu = f * xi, f * eta
        for c, (tx, ty) in zip((*(self.tangential or ()), *(self.prism or ())), extra, strict=True):
            xu = xu + c * tx
            yu = yu + c * ty
        return np.stack([self.center[0] + s * xu, self.center[1] + s * yu], axis=1)

    def to_dict(self) -> dict:
        d = {"model": self.name, "center": list(self.center), "k": list(self.k), "scale": self.scale}
        if self.tangential is not None:
            d["tangential"] = list(self.tangential)
        if self.prism is not None:
            d["prism"] = list(self.prism)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> RadialModel:
        return cls(
            center=tuple(d["center"]),
            k=tuple(d["k"]),
            scale=float(d["scale"]),
            tangential=tuple(d["tangential"]) if d.get("tangential") is not None else None,
            prism=tuple(d["prism"]) if d.get("prism") is not None else None,
        )


class RadialParametrisation:
    """The free parameters of a :class:`RadialModel` fit, for :func:`pipeline.fit.fit_distortion`.

    ``theta = [dcx, dcy, k1 … kN, (p1, p2), (s1 … s4)]``: centre ``c0 + s * dc``
    (``c0`` the image centre, ``s`` half the image diagonal), ``k0 = 1`` fixed (the
    model can express scale, so the gauge fixes it). The corrected points are linear
    in ``theta[2:]`` (their Jacobian columns are the terms of :func:`radial_basis` without ``k0``);
    the two centre columns are central differences. ``regularisation`` adds the
    centre penalty (``w_center``), the first-order projective gauge of tangential +
    prism terms (``w_gauge``) and an optional ridge (see :mod:`pipeline.fit`).
    """

    def __init__(
        self,
        width: int,
        height: int,
        degree: int,
        tangential: bool,
        prism: bool,
        w_center: float,
        w_gauge: float,
        ridge: float,
    ) -> None:
        self.s = 0.5 * float(np.hypot(width, height))
        self.c0 = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
        self.degree, self.tangential, self.prism = int(degree), bool(tangential), bool(prism)
        self.n = 2 + self.degree + 2 * self.tangential + 4 * self.prism
        self.w_center, self.w_gauge, self.ridge = w_center, w_gauge, ridge

    def theta0(self, init: DistortionModel | None) -> np.ndarray:
        """Start: ``init`` (a RadialModel, rescaled to this normalisation) or the identity."""
        th = np.zeros(self.n)
        if isinstance(init, RadialModel):
            scale = self.s / init.scale  # rho_init = rho * s / s_init
            th[:2] = (np.asarray(init.center) - self.c0) / self.s
            k0 = init.k[0]
            for m, km in enumerate(init.k[1 : self.degree + 1], start=1):
                th[1 + m] = km / k0 * scale**m  # rescale to this normalisation
        return th

    def model(self, th: np.ndarray) -> RadialModel:
        i = 2 + self.degree
        tang = (float(th[i]), float(th[i + 1])) if self.tangential else None
        i += 2 * self.tangential
        prism = (float(th[i]), float(th[i + 1]), float(th[i + 2]), float(th[i + 3])) if self.prism else None
        c = self.c0 + self.s * th[:2]
        return RadialModel(
            center=(float(c[0]), float(c[1])),
            k=(1.0, *(float(v) for v in th[2 : 2 + self.degree])),
            scale=self.s,
            tangential=tang,
            prism=prism,
        )

    def _linear_part(self, xy: np.ndarray, th: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        c = self.c0 + self.s * th[:2]
        xi = (xy[:, 0] - c[0]) / self.s
        eta = (xy[:, 1] - c[1]) / self.s
        powers, extra = radial_basis(xi, eta, self.degree, self.tangential, self.prism)
        # k0 = 1 is fixed: the columns of k1..kN, then the extra terms
        bx = np.stack([pw * xi for pw in powers[1:]] + [t[0] for t in extra], axis=1)
        by = np.stack([pw * eta for pw in powers[1:]] + [t[1] for t in extra], axis=1)
        lin = th[2:]
        u = np.stack([c[0] + self.s * (xi + bx @ lin), c[1] + self.s * (eta + by @ lin)], axis=1)
        return u, self.s * bx, self.s * by

    def evaluate(self, xy: np.ndarray, th: np.ndarray, jac: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Corrected points ``(N, 2)`` and, with ``jac``, their Jacobian ``(N, 2, n)``."""
        u, bx, by = self._linear_part(xy, th)
        if not jac:
            return u, None
        d = np.empty((len(xy), 2, self.n))
        d[:, 0, 2:], d[:, 1, 2:] = bx, by
        eps = 1e-6
        for j in range(2):
            tp, tm = th.copy(), th.copy()
            tp[j] += eps
            tm[j] -= eps
            d[:, :, j] = (self._linear_part(xy, tp)[0] - self._linear_part(xy, tm)[0]) / (2 * eps)
        return u, d

    def regularisation(self, th: np.ndarray, n_points: int) -> tuple[np.ndarray, np.ndarray]:
        """Penalty residuals and their Jacobian rows (see the class docstring)."""
        w = math.sqrt(max(n_points, 1))
        rows, jr = [], []
        for j in range(2):  # centre near the image centre
            e = np.zeros(self.n)
            e[j] = w * self.w_center * self.s
            rows.append(e @ th)
            jr.append(e)
        if self.tangential and self.prism:  # first-order projective gauge
            i = 2 + self.degree
            p1, p2, s1, s3 = i, i + 1, i + 2, i + 4
            for a, b in ((p1, s3), (p2, s1)):
                e = np.zeros(self.n)
                e[a], e[b] = w * self.w_gauge * self.s, -w * self.w_gauge * self.s
                rows.append(e @ th)
                jr.append(e)
        if self.ridge > 0:
            for j in range(2, self.n):
                e = np.zeros(self.n)
                e[j] = w * self.ridge * self.s
                rows.append(e @ th)
                jr.append(e)
        return np.asarray(rows), np.asarray(jr).reshape(-1, self.n)
