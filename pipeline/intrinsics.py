r"""The camera matrix from board views, with the harp's distortion held fixed.

A harp measures the lens distortion without the focal length: its correction :math:`U`
takes a recorded (distorted) pixel :math:`x` to the ideal pin-hole pixel :math:`u = U(x)`.
Given board views (:class:`pipeline.board.BoardView`: corners :math:`x_{vi}` of board points
:math:`X_i`), this module estimates the pin-hole camera matrix

.. math::
    K = \begin{pmatrix} f_x & s & c_x \\ 0 & f_y & c_y \\ 0 & 0 & 1 \end{pmatrix}
    \qquad (s = 0 \text{ unless asked for})

by a bundle adjustment over :math:`K` and every view's pose :math:`(R_v, t_v)` with the
distortion fixed:

.. math::
    \min_{K, R_v, t_v} \sum_{v,i} \bigl\| J_{vi}^{-1}\,\bigl(\pi(K, R_v X_i + t_v) - U(x_{vi})\bigr)\bigr\|^2,
    \qquad \pi(K, P) = \bigl(f_x P_x/P_z + s P_y/P_z + c_x,\ f_y P_y/P_z + c_y\bigr)

with :math:`J_{vi} = \partial U/\partial x` at the corner (central differences): the residual
is the ideal-plane error taken back to the recorded image, where the corner noise is, so the
figure is in recorded pixels (exact to first order in the residual). ``scipy.optimize.least_squares``
(Levenberg-Marquardt) runs on the analytic Jacobian (:math:`\partial\pi/\partial K`,
:math:`\partial\pi/\partial P` times :math:`\partial P/\partial r` from ``cv2.Rodrigues``);
the start is ``cv2.initCameraMatrix2D`` on the undistorted corners and each pose from
``cv2.solvePnP`` (IPPE, planar).

Uncertainty: :math:`\mathrm{Cov} = \hat\sigma^2 (J^\top J)^{-1}`, :math:`\hat\sigma^2` the
residual sum of squares over its degrees of freedom; the standard deviations of
:math:`f_x, f_y, c_x, c_y` (and :math:`s`) are the square roots of its diagonal (the poses
marginalised). They assume independent corner errors of equal variance: the benchmark
(``benchmarks/intrinsics.py``) checks them against rendered boards of known :math:`K`.

Held-out error: each view in turn is left out, :math:`K` refitted on the others, the left-out
view's pose alone fitted with that :math:`K`, and its corners' residual (recorded pixels)
pooled over the views (RMS): what a new shot of the calibrated camera shows.

Because the distortion is held fixed there is no trade-off between distortion and focal
length or principal point (what joint calibration, e.g. ``cv2.calibrateCamera``, has to
untangle from the same few views): with an exact :math:`U` the camera matrix's error is the
corners' noise alone.

References
----------
.. [1] Z. Zhang, "A flexible new technique for camera calibration", IEEE TPAMI 22(11), 2000.
.. [2] B. Triggs, P. McLauchlan, R. Hartley, A. Fitzgibbon, "Bundle adjustment - a modern
   synthesis", Vision Algorithms: Theory and Practice, LNCS 1883, 2000 (covariance of the
   estimate, :math:`\hat\sigma^2 (J^\top J)^{-1}`).
.. [3] T. Collins, A. Bartoli, "Infinitesimal plane-based pose estimation", IJCV 109(3), 2014 (IPPE).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from pipeline.models.base import DistortionModel
from pipeline.plain import plain

Array = npt.NDArray[np.float64]

MIN_VIEWS = 3
"""Board views a camera matrix needs (4 parameters; each view's homography gives 2 equations)."""

MIN_TILT_DEG = 10.0
"""Board views all tilted less than this (degrees from facing the camera) are warned of."""

PARAMETERS = ("fx", "fy", "cx", "cy", "skew")
"""The camera matrix's parameters, in the order of :attr:`Intrinsics.covariance`."""

_JACOBIAN_STEP_PX = 1e-3


def distortion_digest(model: DistortionModel) -> str:
    """SHA-256 (hex, first 16) of the model's parameters: which distortion a camera matrix belongs to."""
    text = json.dumps(plain(model.to_dict(), nonfinite_as_none=False), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass(frozen=True)
class Intrinsics:
    """A measured camera matrix, its uncertainty and where it comes from.

    Attributes
    ----------
    fx, fy, cx, cy, skew : float
        The camera matrix (pixels; ``skew`` 0 unless fitted), for ``width`` x ``height`` images,
        in the ideal frame of the distortion it was measured with (``distortion``: its
        :func:`distortion_digest`).
    sd : tuple of 5 floats
        Standard deviations (1 sigma) of ``fx, fy, cx, cy, skew`` (skew's 0 when not fitted).
    covariance : 5 x 5 tuple
        Their covariance (pixels squared), :data:`PARAMETERS` order.
    rms_px : float
        RMS reprojection error of the fit (recorded pixels, per corner).
    holdout_rms_px : float or None
        Leave-one-view-out RMS (module docstring); None with fewer than 4 views.
    holdout_per_view : tuple of float
        Each left-out view's RMS, in view order.
    n_views, n_points : int
        Views and corners fitted.
    source : str
        One line: how it was measured (command, board, views, distortion held fixed from what).
    views : tuple of str
        The views' names (paths), in order.
    warnings : tuple of str
        What the fit found doubtful (e.g. a parameter known to worse than 1 %).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    skew: float
    sd: tuple[float, float, float, float, float]
    covariance: tuple[tuple[float, ...], ...]
    width: int
    height: int
    rms_px: float
    holdout_rms_px: float | None
    n_views: int
    n_points: int
    source: str = ""
    distortion: str = ""
    skew_fitted: bool = False
    holdout_per_view: tuple[float, ...] = ()
    views: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __bool__(self) -> Literal[True]:
        return True

    @property
    def matrix(self) -> Array:
        """The 3 x 3 camera matrix."""
        return np.array([[self.fx, self.skew, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def statement(self) -> str:
        """One line for an export's comments: the values with 1 sigma, the source."""
        parts = [
            f"fx = {self.fx:.3f} +- {self.sd[0]:.3f}",
            f"fy = {self.fy:.3f} +- {self.sd[1]:.3f}",
            f"cx = {self.cx:.3f} +- {self.sd[2]:.3f}",
            f"cy = {self.cy:.3f} +- {self.sd[3]:.3f}",
        ]
        if self.skew_fitted:
            parts.append(f"skew = {self.skew:.4f} +- {self.sd[4]:.4f}")
        held = f", held-out views {self.holdout_rms_px:.3f} px RMS" if self.holdout_rms_px is not None else ""
        return (
            f"camera matrix: MEASURED {', '.join(parts)} px (1 sigma; {self.n_views} board views, "
            f"reprojection {self.rms_px:.3f} px RMS{held}); {self.source}"
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain data (model file ``intrinsics:``, store ``intrinsics_json``)."""
        d: dict[str, Any] = {
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "skew": self.skew,
            "skew_fitted": self.skew_fitted,
            "sd": dict(zip(PARAMETERS, self.sd)),
            "covariance": [list(r) for r in self.covariance],
            "image": {"width": self.width, "height": self.height},
            "rms_px": self.rms_px,
            "holdout_rms_px": self.holdout_rms_px,
            "holdout_per_view": list(self.holdout_per_view),
            "n_views": self.n_views,
            "n_points": self.n_points,
            "source": self.source,
            "distortion": self.distortion,
            "views": list(self.views),
            "warnings": list(self.warnings),
        }
        d.update(self.extra)
        return plain(d, nonfinite_as_none=False)  # type: ignore[no-any-return]

    @classmethod
    def from_dict(cls, d: Any) -> Intrinsics:
        """Inverse of :meth:`to_dict`; ValueError (one line) for a bad record."""
        if not isinstance(d, Mapping):
            raise ValueError("intrinsics: not a mapping")
        try:
            vals = [float(d[k]) for k in ("fx", "fy", "cx", "cy")]
            skew = float(d.get("skew") or 0.0)
            sd_doc = d.get("sd") or {}
            sd = tuple(float(sd_doc.get(k, 0.0) or 0.0) for k in PARAMETERS)
            cov = tuple(tuple(float(v) for v in row) for row in d.get("covariance") or ())
            image = d["image"]
            width, height = int(image["width"]), int(image["height"])
            held = d.get("holdout_rms_px")
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"intrinsics: missing or invalid {exc}") from None
        if not all(math.isfinite(v) for v in vals) or vals[0] <= 0 or vals[1] <= 0:
            raise ValueError(f"intrinsics: fx, fy must be finite and > 0, got {vals[0]}, {vals[1]}")
        known = {
            "fx",
            "fy",
            "cx",
            "cy",
            "skew",
            "skew_fitted",
            "sd",
            "covariance",
            "image",
            "rms_px",
            "holdout_rms_px",
            "holdout_per_view",
            "n_views",
            "n_points",
            "source",
            "distortion",
            "views",
            "warnings",
        }
        return cls(
            fx=vals[0],
            fy=vals[1],
            cx=vals[2],
            cy=vals[3],
            skew=skew,
            sd=sd,  # type: ignore[arg-type]
            covariance=cov,
            width=width,
            height=height,
            rms_px=float(d.get("rms_px") or float("nan")),
            holdout_rms_px=float(held) if isinstance(held, (int, float)) else None,
            n_views=int(d.get("n_views") or 0),
            n_points=int(d.get("n_points") or 0),
            source=str(d.get("source") or ""),
            distortion=str(d.get("distortion") or ""),
            skew_fitted=bool(d.get("skew_fitted", False)),
            holdout_per_view=tuple(float(v) for v in d.get("holdout_per_view") or ()),
            views=tuple(str(v) for v in d.get("views") or ()),
            warnings=tuple(str(v) for v in d.get("warnings") or ()),
            extra={k: v for k, v in d.items() if k not in known},
        )


@dataclass(frozen=True)
class IntrinsicsFailure:
    """No camera matrix could be measured; ``reason`` says why (one line). Falsy."""

    reason: str

    def __bool__(self) -> Literal[False]:
        return False


@dataclass(frozen=True)
class _View:
    """One view ready for the adjustment: board points, ideal points, whitening (J^-1) per point."""

    obj: Array  # (N, 3)
    ideal: Array  # (N, 2)
    jinv: Array  # (N, 2, 2)
    name: str


def _prepare(obj: Array, image_points: Array, model: DistortionModel, name: str) -> _View:
    x = np.asarray(image_points, np.float64).reshape(-1, 2)
    o = np.asarray(obj, np.float64).reshape(-1, 3)
    u = model.undistort_points(x)
    h = _JACOBIAN_STEP_PX
    jx = (model.undistort_points(x + [h, 0.0]) - model.undistort_points(x - [h, 0.0])) / (2 * h)
    jy = (model.undistort_points(x + [0.0, h]) - model.undistort_points(x - [0.0, h])) / (2 * h)
    j = np.stack([jx, jy], axis=2)  # j[i, :, c] = dU/dx_c
    ok = np.all(np.isfinite(u), axis=1) & np.all(np.isfinite(j.reshape(-1, 4)), axis=1)
    det = j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0]
    ok &= np.abs(det) > 1e-9
    jinv = np.zeros_like(j)
    jinv[ok] = np.linalg.inv(j[ok])
    return _View(obj=o[ok], ideal=u[ok], jinv=jinv[ok], name=name)


def _rodrigues(rvec: Array) -> tuple[Array, Array]:
    """``(R, dR)``: rotation and ``dR[k] = dR/d rvec_k`` (3 x 3 x 3)."""
    import cv2

    r, jac = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3))
    return np.asarray(r, np.float64), np.asarray(jac, np.float64).reshape(3, 3, 3)


def _project(
    k: Array, rvec: Array, tvec: Array, obj: Array, want_jac: bool
) -> tuple[Array, Array | None, Array | None]:
    """Ideal pixels ``(N, 2)``; with ``want_jac`` also d/d(fx, fy, cx, cy, s) ``(N, 2, 5)`` and
    d/d(rvec, tvec) ``(N, 2, 6)``."""
    fx, fy, cx, cy, s = k
    r, dr = _rodrigues(rvec)
    p = obj @ r.T + tvec
    z = p[:, 2]
    xn, yn = p[:, 0] / z, p[:, 1] / z
    out = np.column_stack([fx * xn + s * yn + cx, fy * yn + cy])
    if not want_jac:
        return out, None, None
    n = len(obj)
    dk = np.zeros((n, 2, 5))
    dk[:, 0, 0] = xn
    dk[:, 1, 1] = yn
    dk[:, 0, 2] = 1.0
    dk[:, 1, 3] = 1.0
    dk[:, 0, 4] = yn
    dp = np.zeros((n, 2, 3))  # d out / d P
    dp[:, 0, 0] = fx / z
    dp[:, 0, 1] = s / z
    dp[:, 0, 2] = -(fx * xn + s * yn) / z
    dp[:, 1, 1] = fy / z
    dp[:, 1, 2] = -fy * yn / z
    dpr = np.stack([obj @ dr[m].T for m in range(3)], axis=2)  # (N, 3, 3): dP/d rvec_m
    dpose = np.concatenate([np.einsum("nij,njm->nim", dp, dpr), dp], axis=2)
    return out, dk, dpose


def _kvec(k: Array, skew: bool) -> Array:
    return np.array([k[0], k[1], k[2], k[3], k[4] if skew else 0.0])


@dataclass(frozen=True)
class _Solution:
    k: Array  # 5: fx fy cx cy s
    poses: Array  # (V, 6)
    jac: Array
    resid: Array
    nk: int


def _adjust(views: Sequence[_View], k0: Array, poses0: Array, skew: bool, fix_k: bool = False) -> _Solution:
    from scipy.optimize import least_squares

    nk = 0 if fix_k else (5 if skew else 4)
    nv = len(views)
    sizes = [len(v.obj) for v in views]
    rows = 2 * sum(sizes)
    offs = np.concatenate([[0], np.cumsum(sizes)]) * 2

    def unpack(p: Array) -> tuple[Array, Array]:
        if fix_k:
            k = k0.copy()
        else:
            k = np.zeros(5)
            k[:nk] = p[:nk]
        return k, p[nk:].reshape(nv, 6)

    def fun(p: Array) -> Array:
        k, poses = unpack(p)
        out = np.empty(rows)
        for i, v in enumerate(views):
            u, _, _ = _project(k, poses[i, :3], poses[i, 3:], v.obj, False)
            out[offs[i] : offs[i + 1]] = np.einsum("nij,nj->ni", v.jinv, u - v.ideal).ravel()
        return out

    def jac(p: Array) -> Array:
        k, poses = unpack(p)
        jm = np.zeros((rows, nk + 6 * nv))
        for i, v in enumerate(views):
            _, dk, dpose = _project(k, poses[i, :3], poses[i, 3:], v.obj, True)
            assert dk is not None and dpose is not None
            if nk:
                jm[offs[i] : offs[i + 1], :nk] = np.einsum("nij,njm->nim", v.jinv, dk[:, :, :nk]).reshape(-1, nk)
            c = nk + 6 * i
            jm[offs[i] : offs[i + 1], c : c + 6] = np.einsum("nij,njm->nim", v.jinv, dpose).reshape(-1, 6)
        return jm

    p0 = np.concatenate([k0[:nk], poses0.ravel()])
    sol = least_squares(fun, p0, jac=jac, method="lm", x_scale="jac", xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=100)
    k, poses = unpack(np.asarray(sol.x, np.float64))
    return _Solution(k=k, poses=poses.copy(), jac=np.asarray(sol.jac), resid=np.asarray(sol.fun), nk=nk)


def _start(views: Sequence[_View], width: int, height: int) -> tuple[Array, Array]:
    """Start: ``cv2.initCameraMatrix2D`` on the ideal corners, poses by ``cv2.solvePnP`` (IPPE)."""
    import cv2

    objs = [v.obj.astype(np.float32) for v in views]
    imgs = [v.ideal.astype(np.float32).reshape(-1, 1, 2) for v in views]
    k = np.asarray(cv2.initCameraMatrix2D(objs, imgs, (int(width), int(height)), 1.0), np.float64)
    kv = np.array([k[0, 0], k[1, 1], k[0, 2], k[1, 2], 0.0])
    poses = np.array([_pnp(v, kv) for v in views])
    return kv, poses


def _pnp(v: _View, kv: Array) -> Array:
    import cv2

    km = np.array([[kv[0], kv[4], kv[2]], [0.0, kv[1], kv[3]], [0.0, 0.0, 1.0]])
    flag = cv2.SOLVEPNP_IPPE if np.ptp(v.obj[:, 2]) < 1e-9 else cv2.SOLVEPNP_ITERATIVE
    ok, rvec, tvec = cv2.solvePnP(v.obj, v.ideal.reshape(-1, 1, 2), km, None, flags=flag)
    if not ok:
        ok, rvec, tvec = cv2.solvePnP(v.obj, v.ideal.reshape(-1, 1, 2), km, None)
    return np.concatenate([np.asarray(rvec, np.float64).ravel(), np.asarray(tvec, np.float64).ravel()])


def _rms(r: Array) -> float:
    return float(np.sqrt(np.mean(r.reshape(-1, 2) ** 2) * 2)) if r.size else float("nan")


def fit_intrinsics(
    views: Sequence[Any],
    model: DistortionModel,
    width: int,
    height: int,
    *,
    skew: bool = False,
    holdout: bool = True,
    source: str = "",
) -> Intrinsics | IntrinsicsFailure:
    """The camera matrix of board ``views`` with ``model``'s distortion held fixed (module docstring).

    ``views``: objects with ``object_points`` (N, 3), ``image_points`` (N, 2) recorded pixels and
    ``name`` (:class:`pipeline.board.BoardView`). Returns an :class:`IntrinsicsFailure` (falsy)
    with fewer than :data:`MIN_VIEWS` usable views or when the adjustment gives no valid camera.
    """
    prepared = [_prepare(v.object_points, v.image_points, model, getattr(v, "name", "")) for v in views]
    prepared = [v for v in prepared if len(v.obj) >= 4]
    if len(prepared) < MIN_VIEWS:
        return IntrinsicsFailure(f"a camera matrix needs at least {MIN_VIEWS} board views, got {len(prepared)}")
    try:
        k0, poses0 = _start(prepared, width, height)
        sol = _adjust(prepared, k0, poses0, skew)
    except (np.linalg.LinAlgError, ValueError) as exc:
        return IntrinsicsFailure(f"the adjustment failed ({exc})")
    k = sol.k
    if not (np.all(np.isfinite(k)) and k[0] > 0 and k[1] > 0):
        return IntrinsicsFailure(f"the adjustment gave no valid camera (fx {k[0]:.4g}, fy {k[1]:.4g})")
    m, n = sol.resid.size, sol.jac.shape[1]
    dof = max(m - n, 1)
    sigma2 = float(np.sum(sol.resid**2)) / dof
    jtj = sol.jac.T @ sol.jac
    try:
        cov_all = sigma2 * np.linalg.inv(jtj)
    except np.linalg.LinAlgError:
        return IntrinsicsFailure("the board views do not determine the camera matrix (singular normal equations)")
    nk = sol.nk
    cov = np.zeros((5, 5))
    cov[:nk, :nk] = cov_all[:nk, :nk]
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    warnings: list[str] = []
    tilts = [_tilt_deg(pose[:3]) for pose in sol.poses]
    if max(tilts) < MIN_TILT_DEG:
        warnings.append(
            f"every board view is within {max(tilts):.0f} degrees of facing the camera: tilt the board "
            f"{MIN_TILT_DEG:g}-45 degrees (the focal length is seen through the perspective)"
        )
    for name, val, s in zip(PARAMETERS[:4], k[:4], sd[:4]):
        if name in ("fx", "fy") and s > 0.01 * val:
            warnings.append(
                f"{name} known to {100 * s / val:.1f} % only: tilt the board more (30-45 degrees) and vary its tilt"
            )
    held: float | None = None
    per_view: tuple[float, ...] = ()
    if holdout and len(prepared) > MIN_VIEWS:
        res = []
        per = []
        for i in range(len(prepared)):
            rest = [v for j, v in enumerate(prepared) if j != i]
            poses_rest = np.delete(sol.poses, i, axis=0)
            s_i = _adjust(rest, sol.k, poses_rest, skew)
            r_i = _adjust([prepared[i]], s_i.k, sol.poses[i : i + 1], skew, fix_k=True).resid
            res.append(r_i)
            per.append(_rms(r_i))
        held, per_view = _rms(np.concatenate(res)), tuple(per)
    return Intrinsics(
        fx=float(k[0]),
        fy=float(k[1]),
        cx=float(k[2]),
        cy=float(k[3]),
        skew=float(k[4]),
        sd=tuple(float(v) for v in sd),  # type: ignore[arg-type]
        covariance=tuple(tuple(float(v) for v in row) for row in cov),
        width=int(width),
        height=int(height),
        rms_px=_rms(sol.resid),
        holdout_rms_px=held,
        n_views=len(prepared),
        n_points=sum(len(v.obj) for v in prepared),
        source=source,
        distortion=distortion_digest(model),
        skew_fitted=bool(skew),
        holdout_per_view=per_view,
        views=tuple(v.name for v in prepared),
        warnings=tuple(warnings),
        extra={"view_tilts_deg": [round(t, 2) for t in tilts]},
    )


def _tilt_deg(rvec: Array) -> float:
    """The angle (degrees) between a board's normal and the optical axis."""
    r, _ = _rodrigues(rvec)
    return float(np.degrees(np.arccos(np.clip(abs(r[2, 2]), 0.0, 1.0))))


def view_residual(
    intr: Intrinsics | Array, model: DistortionModel, object_points: Array, image_points: Array
) -> tuple[float, Array]:
    """A new view seen by a calibrated camera: its pose alone fitted with the camera matrix and
    distortion fixed; ``(rms_px, pose)`` (recorded pixels per corner; pose = rvec, tvec)."""
    km = intr.matrix if isinstance(intr, Intrinsics) else np.asarray(intr, np.float64)
    kv = np.array([km[0, 0], km[1, 1], km[0, 2], km[1, 2], km[0, 1]])
    v = _prepare(object_points, image_points, model, "")
    pose0 = _pnp(v, kv)
    sol = _adjust([v], kv, pose0[None, :], skew=True, fix_k=True)
    return _rms(sol.resid), sol.poses[0]
