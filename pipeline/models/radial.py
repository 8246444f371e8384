"""Radial polynomial (or rational) correction with free centre, plus Brown–Conrady terms,
and its parametrisation for the fit.

Without a denominator the correction is linear in its coefficients ``k0 … kN, p1, p2,
s1 … s4, t1, t2``: :func:`radial_basis` writes the formula once, as the basis function of each
coefficient, and both the model (:class:`RadialModel`, a sum over the terms) and the
fit (:class:`RadialParametrisation`, the terms as Jacobian columns) use it. The
optional division (rational) denominator ``1 + d1 rho^2 + … + dM rho^2M`` divides the
radial factor; its Jacobian columns follow from the same basis.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, TypedDict, Unpack

import numpy as np

from pipeline.models.base import INVERSE_TOL_PX, DistortionModel
from pipeline.models.inverse import OUTSIDE_DOMAIN, Inverse, monotonic_reach, newton_inverse, radial_start

RADIAL_REACH_LIMIT = 8.0
"""Largest normalised distorted radius (in half image diagonals) :class:`RadialModel` inverts to."""


def radial_basis(
    xi: np.ndarray, eta: np.ndarray, degree: int, tangential: bool, prism: bool, trefoil: bool = False
) -> tuple[list[np.ndarray], list[tuple[np.ndarray, np.ndarray]]]:
    r"""The basis functions of :class:`RadialModel`, in parameter order.

    For normalised offsets ``xi``, ``eta`` (:math:`\rho^2 = \xi^2 + \eta^2`) returns
    ``(powers, extra)``: ``powers[m]`` is :math:`\rho^m` (``m = 0 … degree``), the term of
    :math:`k_m` being :math:`\rho^m (\xi, \eta)`; ``extra`` holds the ``(xi_u part,
    eta_u part)`` of the other terms — with ``tangential``, :math:`p_1`:
    :math:`(2\xi\eta,\ \rho^2 + 2\eta^2)` and :math:`p_2`: :math:`(\rho^2 + 2\xi^2,\ 2\xi\eta)`;
    then, with ``prism``, :math:`s_1`: :math:`(\rho^2, 0)`, :math:`s_2`: :math:`(\rho^4, 0)`,
    :math:`s_3`: :math:`(0, \rho^2)`, :math:`s_4`: :math:`(0, \rho^4)`; then, with ``trefoil``,
    :math:`t_1`: :math:`(\xi^2 - \eta^2,\ -2\xi\eta)`, :math:`t_2`: :math:`(2\xi\eta,\ \xi^2 - \eta^2)`. The corrected
    offsets are the coefficient-weighted sum of the terms (:meth:`RadialModel.undistort_points`),
    the radial part divided by the denominator of :func:`division_basis` when there is one.
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
    if trefoil:
        extra += trefoil_terms(xi, eta)
    return powers, extra


def trefoil_terms(xi: np.ndarray, eta: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    r"""The two three-fold (trefoil) terms of :class:`RadialModel`, ``(xi_u part, eta_u part)`` each:
    :math:`t_1`: :math:`(\xi^2 - \eta^2,\ -2\xi\eta)` and :math:`t_2`: :math:`(2\xi\eta,\ \xi^2 - \eta^2)`,
    in complex form :math:`\bar z^2` and :math:`i\bar z^2` (:math:`z = \xi + i\eta`)."""
    xe2 = 2.0 * xi * eta
    d2 = xi * xi - eta * eta
    return [(d2, -xe2), (xe2, d2)]


def division_basis(rho2: np.ndarray, terms: int) -> list[np.ndarray]:
    r"""The terms :math:`\rho^{2j}` (``j = 1 … terms``) of the division denominator
    :math:`D(\rho) = 1 + d_1\rho^2 + \dots + d_M\rho^{2M}` of :class:`RadialModel`."""
    out = [rho2]
    for _ in range(terms - 1):
        out.append(out[-1] * rho2)
    return out[:terms]


class RadialTerms(TypedDict, total=False):
    """The optional terms of a :class:`RadialModel`, as keywords (:meth:`RadialModel.for_image`)."""

    tangential: tuple[float, float] | None
    prism: tuple[float, float, float, float] | None
    division: tuple[float, ...] | None
    trefoil: tuple[float, float] | None


@dataclass(frozen=True)
class RadialModel(DistortionModel):
    r"""Radial polynomial correction with a free centre (Tang et al. 2012, eq. 1),
    optionally with decentering (tangential) and thin-prism terms (Brown–Conrady) and a
    three-fold (trefoil) term.

    Maps distorted pixels :math:`(x_d, y_d)` to ideal pixels :math:`(x_u, y_u)`.
    With the normalised offsets :math:`\xi = (x_d - c_x)/s`,
    :math:`\eta = (y_d - c_y)/s`, :math:`\rho^2 = \xi^2 + \eta^2`:

    .. math::
        f(\rho) &= \frac{k_0 + k_1 \rho + k_2 \rho^2 + \dots + k_N \rho^N}
                         {1 + d_1 \rho^2 + \dots + d_M \rho^{2M}} \\
        \xi_u &= f(\rho)\,\xi + 2 p_1 \xi\eta + p_2(\rho^2 + 2\xi^2) + s_1\rho^2 + s_2\rho^4
                 + t_1(\xi^2 - \eta^2) + 2 t_2\xi\eta \\
        \eta_u &= f(\rho)\,\eta + p_1(\rho^2 + 2\eta^2) + 2 p_2 \xi\eta + s_3\rho^2 + s_4\rho^4
                 - 2 t_1\xi\eta + t_2(\xi^2 - \eta^2) \\
        x_u &= c_x + s\,\xi_u, \quad y_u = c_y + s\,\eta_u

    ``s`` (``scale``) is a fixed normalisation, by convention half the image
    diagonal, so that the coefficients do not depend on the image size. Without
    ``division`` (``M = 0``) the denominator is 1: the radial polynomial of the paper.
    With it, :math:`f` is a rational function, the *division model* of Fitzgibbon
    (:math:`N = 0, M = 1`) generalised: it follows the strong barrel of wide-angle lenses,
    whose correction grows faster towards the corners than any short polynomial, with
    few coefficients (the pin-hole image of an equidistant fisheye,
    :math:`\tan(a\rho)/(a\rho)`, has its pole inside the image's reach, which a
    denominator can place and a polynomial cannot).

    The trefoil term (``t1, t2``; :func:`trefoil_terms`, :math:`\bar z^2` in complex form) is the
    part of a quadratic distortion field that neither the decentering and thin-prism terms nor a
    homography can express: modulo a homography, the quadratic fields are four-dimensional, the
    thin-prism's :math:`\rho^2` terms two of them, the trefoil the other two. A straight line of
    direction :math:`\theta` sees a quadratic field only as a bow shared by every line of that
    direction, :math:`-s_1\sin\theta + s_3\cos\theta - t_1\sin 3\theta + t_2\cos 3\theta` (times
    the line's half-length squared), so strings of two orientations determine the thin-prism terms
    but not the trefoil as well, and four orientations determine both. The real photographs of
    ``../shared/data/real-harp`` show a bow of this kind (``benchmarks/quadratic_sector.py``): a
    three-fold term, or a bow the whole harp shares, which three photographs cannot tell apart (shots
    180 degrees apart can: the harp's bow turns over with it, the lens's does not). A tilted or decentred
    element gives thin-prism and decentering terms; a three-fold term needs a three-fold cause, such
    as an element or sensor deformed where it is held at three points.

    Parameter order (as in :meth:`params`): ``cx, cy, k0 … kN, p1, p2, s1 … s4, t1, t2,
    d1 … dM`` (``p``, ``s``, ``t`` and ``d`` present only when enabled).

    References
    ----------
    .. [1] Z. Tang et al., "High-precision camera distortion measurements
       with a calibration harp", JOSA A 29(10), 2012.
    .. [2] D. C. Brown, "Decentering distortion of lenses", Photogrammetric
       Engineering 32(3), 1966.
    .. [3] A. W. Fitzgibbon, "Simultaneous linear estimation of multiple view
       geometry and lens distortion", CVPR 2001 (the division model).
    .. [4] R. Hartley, S. B. Kang, "Parameter-free radial distortion correction with
       center of distortion estimation", IEEE TPAMI 29(8), 2007 (rational radial models).
    """

    center: tuple[float, float]
    k: tuple[float, ...] = (1.0,)
    scale: float = 1000.0
    tangential: tuple[float, float] | None = None
    prism: tuple[float, float, float, float] | None = None
    division: tuple[float, ...] | None = None
    trefoil: tuple[float, float] | None = None
    name: str = field(default="radial", init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", tuple(float(v) for v in self.center))
        if len(self.center) != 2:
            raise ValueError(f"RadialModel center needs (x, y), got {len(self.center)} values")
        object.__setattr__(self, "k", tuple(float(v) for v in self.k))
        if self.tangential is not None:
            object.__setattr__(self, "tangential", tuple(float(v) for v in self.tangential))
            if len(self.tangential) != 2:
                raise ValueError(f"RadialModel tangential needs (p1, p2), got {len(self.tangential)} values")
        if self.prism is not None:
            object.__setattr__(self, "prism", tuple(float(v) for v in self.prism))
            if len(self.prism) != 4:
                raise ValueError(f"RadialModel prism needs (s1, s2, s3, s4), got {len(self.prism)} values")
        if self.trefoil is not None:
            object.__setattr__(self, "trefoil", tuple(float(v) for v in self.trefoil))
            if len(self.trefoil) != 2:
                raise ValueError(f"RadialModel trefoil needs (t1, t2), got {len(self.trefoil)} values")
        if self.division is not None:
            object.__setattr__(self, "division", tuple(float(v) for v in self.division))
            if not self.division:
                raise ValueError("RadialModel division needs at least d1 (or None)")
        if not self.k:
            raise ValueError("RadialModel needs at least k0")
        if not self.scale > 0:
            raise ValueError(f"RadialModel scale must be > 0, got {self.scale}")

    @classmethod
    def for_image(
        cls,
        width: int,
        height: int,
        k: Sequence[float] = (1.0,),
        center: tuple[float, float] | None = None,
        **kw: Unpack[RadialTerms],
    ) -> RadialModel:
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
        if self.trefoil is not None:
            p += list(self.trefoil)
        if self.division is not None:
            p += list(self.division)
        return np.asarray(p, dtype=np.float64)

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        s = self.scale
        xi = (xy[:, 0] - self.center[0]) / s
        eta = (xy[:, 1] - self.center[1]) / s
        powers, extra = radial_basis(
            xi, eta, len(self.k) - 1, self.tangential is not None, self.prism is not None, self.trefoil is not None
        )
        f = self.k[0] * powers[0]
        for km, pw in zip(self.k[1:], powers[1:], strict=True):
            f = f + km * pw
        if self.division is not None:
            den = np.ones_like(f)
            for dj, ev in zip(self.division, division_basis(xi * xi + eta * eta, len(self.division)), strict=True):
                den = den + dj * ev
            f = f / den
        xu, yu = f * xi, f * eta
        coefficients = (*(self.tangential or ()), *(self.prism or ()), *(self.trefoil or ()))
        for c, (tx, ty) in zip(coefficients, extra, strict=True):
            xu = xu + c * tx
            yu = yu + c * ty
        return np.stack([self.center[0] + s * xu, self.center[1] + s * yu], axis=1)

    def radial_map(self, rho: np.ndarray) -> np.ndarray:
        r"""The radial part of the correction, :math:`\rho_u = \rho\,f(\rho)` (normalised radii)."""
        rho = np.asarray(rho, dtype=np.float64)
        a = np.abs(rho)
        num = np.zeros_like(a)
        for km in reversed(self.k):
            num = num * a + km
        den = np.ones_like(a)
        if self.division is not None:
            den = np.zeros_like(a)
            for dj in reversed((1.0, *self.division)):
                den = den * a * a + dj
        with np.errstate(divide="ignore", invalid="ignore"):
            out: np.ndarray = np.where(den > 0, rho * num / den, np.nan)
        return out

    @cached_property
    def reach(self) -> float:
        """Normalised distorted radius up to which the radial part increases (its first fold or
        pole; at most ``RADIAL_REACH_LIMIT``): the domain where :meth:`distort_points` looks for
        an inverse."""
        return monotonic_reach(self.radial_map, RADIAL_REACH_LIMIT)

    def distort_inverse(self, xy: np.ndarray, max_iter: int = 50) -> Inverse:
        """Inverse of :meth:`undistort_points` inside the disc of radius :attr:`reach`.

        Starts from the exact inverse of the radial part on the radius (bracketed by
        :func:`~pipeline.models.inverse.radial_start`), then damped Newton on the whole map
        (:func:`~pipeline.models.inverse.newton_inverse`) kept inside the disc. A point whose
        inverse would lie beyond the radial part's fold or pole is NaN (``OUTSIDE_DOMAIN``),
        never a far-away root of the polynomial.
        """
        target = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        s, c = self.scale, np.asarray(self.center)
        off = (target - c) / s
        rt = np.hypot(off[:, 0], off[:, 1])
        reach = self.reach
        rho, ok = radial_start(self.radial_map, rt, reach, tol=0.1 * INVERSE_TOL_PX / s)
        with np.errstate(divide="ignore", invalid="ignore"):
            unit = np.where(rt[:, None] > 0, off / rt[:, None], 0.0)
        pure = self.tangential is None and self.prism is None and self.trefoil is None
        rho = np.minimum(rho, reach * (1 - 1e-9))
        start = c + s * rho[:, None] * unit
        if pure:  # beyond the radial part's range: no inverse in the domain
            start[~ok] = np.nan

        def inside(x: np.ndarray) -> np.ndarray:
            d = (x - c) / s
            out: np.ndarray = np.hypot(d[:, 0], d[:, 1]) < reach
            return out

        inv = newton_inverse(
            self.undistort_points, target, start, tol=INVERSE_TOL_PX, h=1e-4, max_iter=max_iter, inside=inside
        )
        if pure:
            inv.reason[~ok & np.all(np.isfinite(target), axis=1)] = OUTSIDE_DOMAIN
        return inv

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"model": self.name, "center": list(self.center), "k": list(self.k), "scale": self.scale}
        if self.tangential is not None:
            d["tangential"] = list(self.tangential)
        if self.prism is not None:
            d["prism"] = list(self.prism)
        if self.trefoil is not None:
            d["trefoil"] = list(self.trefoil)
        if self.division is not None:
            d["division"] = list(self.division)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RadialModel:
        return cls(
            center=tuple(d["center"]),
            k=tuple(d["k"]),
            scale=float(d["scale"]),
            tangential=tuple(d["tangential"]) if d.get("tangential") is not None else None,
            prism=tuple(d["prism"]) if d.get("prism") is not None else None,
            division=tuple(d["division"]) if d.get("division") is not None else None,
            trefoil=tuple(d["trefoil"]) if d.get("trefoil") is not None else None,
        )


class RadialParametrisation:
    """The free parameters of a :class:`RadialModel` fit, for :func:`pipeline.fit.fit_distortion`.

    ``theta = [dcx, dcy, k1 … kN, (p1, p2), (s1 … s4), (t1, t2), (d1 … dM)]``: centre ``c0 + s * dc``
    (``c0`` the image centre, ``s`` half the image diagonal), ``k0 = 1`` fixed (the
    model can express scale, so the gauge fixes it). Without a denominator the corrected
    points are linear in ``theta[2:]`` (their Jacobian columns are the terms of
    :func:`radial_basis` without ``k0``); with one, the ``k`` columns are divided by
    ``D`` and the column of ``d_j`` is ``-f rho^2j (xi, eta) / D``; the two centre columns
    follow from the derivatives of the corrected offsets in ``xi``, ``eta``: all analytic. ``regularisation`` adds the
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
        division: int = 0,
        trefoil: bool = False,
    ) -> None:
        self.s = 0.5 * float(np.hypot(width, height))
        self.c0 = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
        self.degree, self.tangential, self.prism = int(degree), bool(tangential), bool(prism)
        self.division, self.trefoil = int(division), bool(trefoil)
        self.n = 2 + self.degree + 2 * self.tangential + 4 * self.prism + 2 * self.trefoil + self.division
        self.w_center, self.w_gauge, self.ridge = w_center, w_gauge, ridge

    def theta0(self, init: DistortionModel | None) -> np.ndarray:
        """Start: ``init`` (a RadialModel, rescaled to this normalisation; the terms both have,
        divided by its ``k0``, the others 0) or the identity."""
        th = np.zeros(self.n)
        if isinstance(init, RadialModel):
            scale = self.s / init.scale  # rho_init = rho * s / s_init
            th[:2] = (np.asarray(init.center) - self.c0) / self.s
            k0 = init.k[0]
            for m, km in enumerate(init.k[1 : self.degree + 1], start=1):
                th[1 + m] = km / k0 * scale**m  # rescale to this normalisation
            i = 2 + self.degree
            if self.tangential and init.tangential is not None:
                th[i : i + 2] = np.asarray(init.tangential) / k0 * scale
            i += 2 * self.tangential
            if self.prism and init.prism is not None:
                s1, s2, s3, s4 = init.prism
                th[i : i + 4] = np.array([s1 * scale, s2 * scale**3, s3 * scale, s4 * scale**3]) / k0
            i += 4 * self.prism
            if self.trefoil and init.trefoil is not None:
                th[i : i + 2] = np.asarray(init.trefoil) / k0 * scale
            if init.division is not None and self.division:
                i = self.n - self.division
                for j, dj in enumerate(init.division[: self.division], start=1):
                    th[i + j - 1] = dj * scale ** (2 * j)
        return th

    def model(self, th: np.ndarray) -> RadialModel:
        i = 2 + self.degree
        tang = (float(th[i]), float(th[i + 1])) if self.tangential else None
        i += 2 * self.tangential
        prism = (float(th[i]), float(th[i + 1]), float(th[i + 2]), float(th[i + 3])) if self.prism else None
        i += 4 * self.prism
        trefoil = (float(th[i]), float(th[i + 1])) if self.trefoil else None
        div = tuple(float(v) for v in th[self.n - self.division :]) if self.division else None
        c = self.c0 + self.s * th[:2]
        return RadialModel(
            center=(float(c[0]), float(c[1])),
            k=(1.0, *(float(v) for v in th[2 : 2 + self.degree])),
            scale=self.s,
            tangential=tang,
            prism=prism,
            division=div,
            trefoil=trefoil,
        )

    def _offsets(self, xy: np.ndarray, th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalised offsets ``(xi, eta)`` of ``xy`` from the centre of ``theta``."""
        c = self.c0 + self.s * th[:2]
        return (xy[:, 0] - c[0]) / self.s, (xy[:, 1] - c[1]) / self.s

    def _radial_factor(
        self, xi: np.ndarray, eta: np.ndarray, th: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, list[tuple[np.ndarray, np.ndarray]], np.ndarray | None, list[np.ndarray]]:
        """``(f, powers (degree, N) rho^1..rho^N, extra terms, denominator or None, rho^2j terms)``."""
        rho2 = xi * xi + eta * eta
        rho = np.sqrt(rho2)
        nk = self.degree
        w = np.empty((nk, len(xi)))
        if nk:
            w[0] = rho
            for m in range(1, nk):
                np.multiply(w[m - 1], rho, out=w[m])
        f = 1.0 + th[2 : 2 + nk] @ w
        extra: list[tuple[np.ndarray, np.ndarray]] = []
        if self.tangential:
            xe2 = 2.0 * xi * eta
            extra += [(xe2, rho2 + 2.0 * eta * eta), (rho2 + 2.0 * xi * xi, xe2)]
        if self.prism:
            z = np.zeros_like(rho)
            rho4 = rho2 * rho2
            extra += [(rho2, z), (rho4, z), (z, rho2), (z, rho4)]
        if self.trefoil:
            extra += trefoil_terms(xi, eta)
        den = None
        even: list[np.ndarray] = []
        if self.division:
            even = division_basis(rho2, self.division)
            den = 1.0 + sum((dj * ev for dj, ev in zip(th[self.n - self.division :], even)), np.zeros_like(xi))
            f = f / den
        return f, w, extra, den, even

    def _corrected(
        self, xi: np.ndarray, eta: np.ndarray, th: np.ndarray, f: np.ndarray, extra: list[tuple[np.ndarray, np.ndarray]]
    ) -> np.ndarray:
        c = self.c0 + self.s * th[:2]
        gx, gy = f * xi, f * eta
        i = 2 + self.degree
        for cc, (tx, ty) in zip(th[i : i + len(extra)], extra, strict=True):
            if cc:
                gx += cc * tx
                gy += cc * ty
        return np.stack([c[0] + self.s * gx, c[1] + self.s * gy], axis=1)

    def evaluate(self, xy: np.ndarray, th: np.ndarray, jac: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Corrected points ``(N, 2)`` and, with ``jac``, their Jacobian ``(N, 2, n)``."""
        xi, eta = self._offsets(xy, th)
        f, w, extra, den, even = self._radial_factor(xi, eta, th)
        u = self._corrected(xi, eta, th, f, extra)
        if not jac:
            return u, None
        d = np.empty((len(xy), 2, self.n))
        cols = self._linear_columns(xi, eta, f, w, extra, den, even)
        for j, (cx, cy) in enumerate(cols, start=2):
            d[:, 0, j], d[:, 1, j] = cx, cy
        d[:, :, 2:] *= self.s
        gxx, gxy, gyx, gyy = self._offset_derivatives(xy, th)
        # centre c = c0 + s dc moves xi, eta by -dc: du/d(dc_x) = s ((1, 0) - dg/dxi), likewise for y
        d[:, 0, 0], d[:, 1, 0] = self.s * (1.0 - gxx), -self.s * gyx
        d[:, 0, 1], d[:, 1, 1] = -self.s * gxy, self.s * (1.0 - gyy)
        return u, d

    def _linear_columns(
        self,
        xi: np.ndarray,
        eta: np.ndarray,
        f: np.ndarray,
        w: np.ndarray,
        extra: list[tuple[np.ndarray, np.ndarray]],
        den: np.ndarray | None,
        even: list[np.ndarray],
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """The (x, y) parts of the Jacobian columns of ``theta[2:]``, without the factor ``s``."""
        wk = w if den is None else w / den
        cols = [(wk[m] * xi, wk[m] * eta) for m in range(self.degree)]
        cols += extra
        if den is not None:
            cols += [(-f * ev * xi / den, -f * ev * eta / den) for ev in even]
        return cols

    def project(
        self, xy: np.ndarray, th: np.ndarray, nrm: np.ndarray, tan: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The Jacobian of the corrected points projected on the unit vectors ``nrm`` and ``tan``
        (per point, ``(N, 2)``), one row per parameter: ``(P, T)``, each ``(n, N)``,
        ``P[:, i] = nrm[i] . du_i/dtheta``.

        The radial rows are ``s rho^m (n . (xi, eta))`` (over ``D`` with a denominator): one
        product of the powers with the projected offset, no ``(N, 2, n)`` array."""
        xi, eta = self._offsets(xy, th)
        f, w, extra, den, even = self._radial_factor(xi, eta, th)
        s = self.s
        nx, ny, tx, ty = nrm[:, 0], nrm[:, 1], tan[:, 0], tan[:, 1]
        n_pts, nk = len(xy), self.degree
        p_mat = np.empty((self.n, n_pts))
        t_mat = np.empty((self.n, n_pts))
        pn = s * (nx * xi + ny * eta)
        pt = s * (tx * xi + ty * eta)
        if den is not None:
            pn, pt = pn / den, pt / den
        np.multiply(w, pn, out=p_mat[2 : 2 + nk])
        np.multiply(w, pt, out=t_mat[2 : 2 + nk])
        i = 2 + nk
        snx, sny, stx, sty = s * nx, s * ny, s * tx, s * ty
        for ex, ey in extra:
            np.multiply(snx, ex, out=p_mat[i])
            p_mat[i] += sny * ey
            np.multiply(stx, ex, out=t_mat[i])
            t_mat[i] += sty * ey
            i += 1
        for ev in even:
            fe = -f * ev
            np.multiply(fe, pn, out=p_mat[i])
            np.multiply(fe, pt, out=t_mat[i])
            i += 1
        gxx, gxy, gyx, gyy = self._offset_derivatives(xy, th)
        # centre rows: du/d(dc_x) = s ((1, 0) - dg/dxi), du/d(dc_y) = s ((0, 1) - dg/deta)
        dxx, dxy = s * (1.0 - gxx), -s * gyx
        dyx, dyy = -s * gxy, s * (1.0 - gyy)
        p_mat[0], t_mat[0] = nx * dxx + ny * dxy, tx * dxx + ty * dxy
        p_mat[1], t_mat[1] = nx * dyx + ny * dyy, tx * dyx + ty * dyy
        return p_mat, t_mat

    def _offset_derivatives(
        self, xy: np.ndarray, th: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Partial derivatives ``(dg_x/dxi, dg_x/deta, dg_y/dxi, dg_y/deta)`` of the corrected
        offsets ``g = f(rho) (xi, eta) + extra terms`` (analytic, :class:`RadialModel`'s formula)."""
        c = self.c0 + self.s * th[:2]
        xi = (xy[:, 0] - c[0]) / self.s
        eta = (xy[:, 1] - c[1]) / self.s
        rho2 = xi * xi + eta * eta
        rho = np.sqrt(rho2)
        safe = np.where(rho > 1e-12, rho, 1e-12)
        k = th[2 : 2 + self.degree]
        num = np.ones_like(rho)
        dnum = np.zeros_like(rho)  # d num / d rho
        p = np.ones_like(rho)  # rho^(m-1)
        for m, km in enumerate(k, start=1):
            dnum = dnum + m * km * p
            p = p * rho
            num = num + km * p
        f, df = num, dnum
        if self.division:
            dco = th[self.n - self.division :]
            den = np.ones_like(rho)
            dden = np.zeros_like(rho)
            q = np.ones_like(rho)  # rho^(2j-2)
            for j, dj in enumerate(dco, start=1):
                dden = dden + 2 * j * dj * q * rho
                q = q * rho2
                den = den + dj * q
            f = num / den
            df = (dnum * den - num * dden) / (den * den)
        w = df / safe  # f'(rho) / rho; the k1 term makes it ~1/rho, always multiplied by xi^2 or xi eta
        gxx = f + w * xi * xi
        gxy = w * xi * eta
        gyx = gxy.copy()
        gyy = f + w * eta * eta
        i = 2 + self.degree
        if self.tangential:
            p1, p2 = th[i], th[i + 1]
            gxx += 2 * p1 * eta + 6 * p2 * xi
            gxy += 2 * p1 * xi + 2 * p2 * eta
            gyx += 2 * p1 * xi + 2 * p2 * eta
            gyy += 6 * p1 * eta + 2 * p2 * xi
            i += 2
        if self.prism:
            s1, s2, s3, s4 = th[i : i + 4]
            gxx += 2 * s1 * xi + 4 * s2 * rho2 * xi
            gxy += 2 * s1 * eta + 4 * s2 * rho2 * eta
            gyx += 2 * s3 * xi + 4 * s4 * rho2 * xi
            gyy += 2 * s3 * eta + 4 * s4 * rho2 * eta
            i += 4
        if self.trefoil:  # t1 (xi^2 - eta^2, -2 xi eta) + t2 (2 xi eta, xi^2 - eta^2)
            t1, t2 = th[i : i + 2]
            gxx += 2 * t1 * xi + 2 * t2 * eta
            gxy += -2 * t1 * eta + 2 * t2 * xi
            gyx += -2 * t1 * eta + 2 * t2 * xi
            gyy += -2 * t1 * xi - 2 * t2 * eta
        return gxx, gxy, gyx, gyy

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
