r"""Convert a harp correction to OpenCV, OpenCV-fisheye or lensfun parameters, with its conversion error.

OpenCV's and lensfun's models cannot represent every lens, so an export is
the member of their family closest to our correction, and the export states
how far it is. Both are defined only up to a homography, so the fit is

.. math::
    \min_{\theta, H} \sum_{x_d \in G} \bigl\| D_\theta\bigl(H(U(x_d))\bigr) - x_d \bigr\|^2

over a grid :math:`G` of distorted pixels covering the whole image, borders
and corners included, with :math:`U` our correction, :math:`D_\theta` the
export's closed-form projection (ideal -> distorted: the direction in which
OpenCV, ROS and lensfun apply their model, e.g. ``cv2.initUndistortRectifyMap``
evaluates :math:`D_\theta` at every ideal pixel) and :math:`H` a free
homography (the output frame of the export need not be ours).

Richer families are fitted *in stages*, each started from the solution of
the one below it padded with zeros (OpenCV: 5 -> 8 -> 12 -> 14 coefficients;
lensfun: poly3 -> ptlens), which is an exact member of the richer family; the
export is the stage with the smallest conversion error, so a richer export is
never worse than a poorer one.

The conversion error of the export chosen (how far it is from our correction, and in which frame) is
:mod:`pipeline.exports.conversion_error`'s.

References
----------
.. [1] Z. Tang et al., "High-precision camera distortion measurements with a
   calibration harp", JOSA A 29(10), 2012, section 2 (corrections modulo homography).
.. [2] J. J. Moré, "The Levenberg-Marquardt algorithm: implementation and theory",
   Numerical Analysis, LNM 630, 1978 (the LM iterations, monotone in the cost).
.. [3] C. L. Lawson, "Contributions to the theory of linear least maximum approximation", PhD thesis,
   UCLA, 1961 (iteratively reweighted least squares towards the minimax fit).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from pipeline.exports.conversion_error import (
    ERROR_GRID_LONG,
    ConversionError,
    conversion_error,
    ideal_homography,
    image_grid,
    mod_h_errors,
    mod_h_rms,
)
from pipeline.exports.opencv_jacobian import homography_jacobian, projection_jacobian
from pipeline.exports.pole_free import (
    EXTRAPOLATION_RADIUS,
    PENALTY_WEIGHT_PX,
    corner_radius,
    radial_fault,
    radial_penalty,
    radial_penalty_jacobian,
)
from pipeline.models.base import DistortionModel
from pipeline.models.homography import apply_homography
from pipeline.models.lensfun_model import LENSFUN_TERMS, LensfunModel
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel
from pipeline.models.thin_prism_fisheye_model import ThinPrismFisheyeModel
from pipeline.normalise import fit_homography

Array = npt.NDArray[np.float64]
M = TypeVar("M", bound=DistortionModel)

OPENCV_STAGES = (5, 8, 12, 14)
"""Coefficient counts of OpenCV's pin-hole model, in the order they are fitted."""

RADTAN_COEFFS = 4
"""``k1 k2 p1 p2`` without ``k3``: the radial-tangential model of Kalibr (and OpenCV's 4), fitted alone."""


def opencv_stages(n_coeffs: int) -> tuple[int, ...]:
    """The stages fitted for ``n_coeffs`` coefficients (ValueError for a count OpenCV has not)."""
    if n_coeffs == RADTAN_COEFFS:
        return (RADTAN_COEFFS,)
    if n_coeffs not in OPENCV_STAGES:
        raise ValueError(
            f"OpenCV export supports {', '.join(map(str, (RADTAN_COEFFS, *OPENCV_STAGES)))} coefficients, got {n_coeffs}"
        )
    return tuple(m for m in OPENCV_STAGES if m <= n_coeffs)


FIT_GRID_LONG = 48
"""Fitting grid: points along the long side of the image (borders and corners included)."""


@dataclass(frozen=True)
class _Problem:
    """The fitting data: distorted grid points, our ideal points, and the homography conditioning."""

    xd: Array
    u: Array
    t: Array
    tinv: Array
    w: Array | None = None
    """Per-point weights of the residuals (None: 1), :func:`_minimax_weights`."""

    @classmethod
    def make(cls, ours: DistortionModel, width: int, height: int, n_long: int) -> _Problem:
        xd = image_grid(width, height, n_long)
        u = ours.undistort_points(xd)
        ok = np.all(np.isfinite(u), axis=1)
        if ok.sum() < 0.9 * len(xd):
            raise ValueError("our correction is undefined over much of the image; cannot convert it")
        # condition H in coordinates centred on the image, unit ~ half diagonal
        c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
        s = 0.5 * float(np.hypot(width, height))
        t = np.array([[1 / s, 0, -c[0] / s], [0, 1 / s, -c[1] / s], [0, 0, 1.0]])
        return cls(xd=xd[ok], u=u[ok], t=t, tinv=np.linalg.inv(t))

    def h0(self) -> Array:
        """Conditioned initial homography (ours -> distorted), flattened 8 values."""
        h = self.t @ fit_homography(self.u, self.xd) @ self.tinv
        return np.asarray((h / h[2, 2]).ravel()[:8], dtype=np.float64)

    def pixel_h(self, hn8: Array) -> Array:
        return np.asarray(self.tinv @ np.append(hn8, 1.0).reshape(3, 3) @ self.t, dtype=np.float64)


FORWARD_DIFFERENCE_NFEV = 200
"""Evaluations of the residuals :func:`_least_squares` gives LM with forward-difference Jacobians (scipy's
default) before it goes on with exact ones (the OpenCV pin-hole fits: :mod:`pipeline.exports.opencv_jacobian`)
or central differences. Forward differences are good to about 1e-8 of each column; in the narrow valleys of
the rational and the pole-free wide-lens fits that error turns the Gauss-Newton step aside, and LM crawled
along them for its whole budget (4000 evaluations of 15-25 residual vectors each, a minute and more on a
wide lens: the 8-coefficient fit of an exact 93 degree lens, 0.1 % lower after 3900 evaluations) where
exact derivatives or central differences (1e-11) converge in a hundred, to a lower cost. Every fit that
converges within this many evaluations (all but those crawls on the lenses of
``benchmarks/export_consumers.py``) is unchanged."""

LM_MAX_NFEV = 4000
"""The evaluation budget of :func:`_least_squares`'s LM once the forward differences are given up (halved
for central differences, which cost twice as much)."""


def _opencv_moves(n_dist: int, scale: Array, centre: float | None) -> Array:
    """How ``theta`` moves ``(cx, cy, dist)`` of an OpenCV pin-hole fit's model: the matrix ``A`` with
    ``d(cx, cy, dist) = A d(theta)``. ``theta`` is ``(cx, cy)`` offsets in units of ``centre`` followed by
    the coefficients (times ``scale``), or, with ``centre`` None, the coefficients alone."""
    k = 0 if centre is None else 2
    a = np.zeros((2 + n_dist, k + n_dist))
    if centre is not None:
        a[0, 0] = a[1, 1] = centre
    a[2:, k:] = np.diag(scale[:n_dist])
    return a


def _least_squares(
    prob: _Problem,
    make: Callable[[Array], M],
    theta0: Array,
    h0: Array,
    *,
    fix_h: bool = False,
    penalty: Callable[[M, Array], Array] | None = None,
    moves: Array | None = None,
) -> tuple[Array, Array, float]:
    """LM over (theta, H) of ``make(theta).distort_points(H(U(x_d))) - x_d``: ``(theta, h8, cost)``.

    With ``fix_h`` only ``theta`` moves (``H = h0``). ``penalty(model, ideal)`` (ideal: the
    grid's ideal points ``H(U(x_d))``) adds residuals, e.g. :func:`~pipeline.exports.pole_free.radial_penalty`
    times :data:`~pipeline.exports.pole_free.PENALTY_WEIGHT_PX`. ``moves`` (OpenCV pin-hole models only,
    :func:`_opencv_moves`): how ``theta`` moves the model, for exact derivatives once the forward differences
    are given up (:data:`FORWARD_DIFFERENCE_NFEV`).
    """
    nt = len(theta0)
    n_pen = 0
    n_res = 2 * len(prob.xd)

    def resid(p: Array) -> Array:
        try:
            m = make(p[:nt])
        except ValueError:
            return np.full(n_res + n_pen, 1e6)
        h8 = h0 if fix_h else p[nt:]
        ideal = apply_homography(prob.pixel_h(h8), prob.u)
        d = m.distort_points(ideal) - prob.xd
        r = (d if prob.w is None else d * prob.w[:, None]).ravel()
        if penalty is not None:
            r = np.concatenate([r, penalty(m, ideal)])
        return np.asarray(np.nan_to_num(r, nan=1e6, posinf=1e6, neginf=-1e6), dtype=np.float64)

    def jac(p: Array) -> Array:
        assert moves is not None
        out = np.zeros((n_res + n_pen, len(p)))
        try:
            m = make(p[:nt])
        except ValueError:
            return out
        assert isinstance(m, OpenCVModel)
        h8 = h0 if fix_h else p[nt:]
        ideal = apply_homography(prob.pixel_h(h8), prob.u)
        j_par, j_ideal = projection_jacobian(m, ideal)
        jw = np.ones(len(ideal)) if prob.w is None else prob.w
        out[:n_res, :nt] = (np.einsum("nij,jk->nik", j_par, moves) * jw[:, None, None]).reshape(n_res, nt)
        j_h = None if fix_h else homography_jacobian(prob.tinv, h8, prob.t, prob.u)
        if j_h is not None:
            out[:n_res, nt:] = (np.einsum("nij,njk->nik", j_ideal, j_h) * jw[:, None, None]).reshape(n_res, 8)
        if penalty is not None:
            pj_par, i_far, pj_ideal = _pole_free_penalty_jacobian(m, ideal)
            out[n_res:, :nt] = pj_par @ moves
            if j_h is not None:
                out[n_res:, nt:] = pj_ideal @ j_h[i_far]
        return np.asarray(np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0), dtype=np.float64)

    p0 = theta0.copy() if fix_h else np.concatenate([theta0, h0])
    n_pen = len(resid(p0)) - n_res
    tol = {"xtol": 1e-12, "ftol": 1e-12, "gtol": 1e-12}
    sol = least_squares(resid, p0, method="lm", x_scale="jac", max_nfev=FORWARD_DIFFERENCE_NFEV, **tol)
    if sol.status == 0:  # the budget spent crawling: on with exact derivatives (see FORWARD_DIFFERENCE_NFEV)
        exact = moves is not None and penalty in (None, _pole_free_penalty)
        j: Any = jac if exact else "3-point"
        budget = LM_MAX_NFEV if exact else LM_MAX_NFEV // 2
        sol = least_squares(resid, sol.x, jac=j, method="lm", x_scale="jac", max_nfev=budget, **tol)
    x = np.asarray(sol.x, dtype=np.float64)
    if not float(sol.cost) <= 0.5 * float(np.sum(resid(p0) ** 2)):  # LM is monotone; keep the start if not
        x = p0
    return x[:nt], (h0.copy() if fix_h else x[nt:]), float(0.5 * np.sum(resid(x) ** 2))


def _pole_free_penalty(m: OpenCVModel, ideal: Array) -> Array:
    """Fit residuals keeping ``m``'s radial map pole-free and monotonic beyond the image (:mod:`.pole_free`)."""
    r_max = EXTRAPOLATION_RADIUS * corner_radius(ideal, m.cx, m.cy, m.fx, m.fy)
    return PENALTY_WEIGHT_PX * radial_penalty(m.dist, r_max)


def _pole_free_penalty_jacobian(m: OpenCVModel, ideal: Array) -> tuple[Array, int, Array]:
    """Derivatives of :func:`_pole_free_penalty`: ``(J_params, i, J_ideal)``, ``J_params`` with respect to
    ``(cx, cy, dist)`` and ``J_ideal`` with respect to the ideal point ``i`` that sets the corner radius."""
    x = (ideal[:, 0] - m.cx) / m.fx
    y = (ideal[:, 1] - m.cy) / m.fy
    rho = np.hypot(x, y)
    i = int(np.argmax(rho))
    r_max = EXTRAPOLATION_RADIUS * float(rho[i])
    jd, jr = radial_penalty_jacobian(m.dist, r_max)
    g = EXTRAPOLATION_RADIUS * np.array([x[i] / m.fx, y[i] / m.fy]) / max(float(rho[i]), 1e-300)
    j_ideal = PENALTY_WEIGHT_PX * jr[:, None] * g[None, :]
    j_par = PENALTY_WEIGHT_PX * np.concatenate([-jr[:, None] * g[None, :], jd], axis=1)
    return j_par, i, j_ideal


MINIMAX_ROUNDS = 2
"""Reweighted refits of the richest OpenCV stage (12 or 14 coefficients) towards the smallest max error
(Lawson's iteration [3]_: each point's weight times the square root of its error over the mean); measured on
the real camera's three pairs of photos, the max error modulo homography fell from 0.020-0.023 px to
0.005-0.009 px with the RMS within 0.0004 px of the plain least squares'."""

MINIMAX_RMS_SLACK = 1.25
"""A reweighted fit is kept only when its max is smaller and its RMS within this factor of the plain fit's."""


def _minimax_weights(w: Array, err: Array) -> Array:
    """Lawson's update of the weights from the errors at the fitting points (normalised to mean 1)."""
    e = np.where(np.isfinite(err), err, np.nanmax(np.where(np.isfinite(err), err, np.nan)))
    out = w * np.sqrt(e / max(float(np.mean(e)), 1e-300))
    return np.asarray(out / np.mean(out), dtype=np.float64)


def placeholder_focal(width: int, height: int) -> float:
    """The focal length (px) used when none is given: the image diagonal (a scale, not a measurement)."""
    return float(np.hypot(width, height))


def focal_rescaling(ratio: float) -> Array:
    r"""Factors taking OpenCV coefficients for a focal :math:`f` to the same distortion for :math:`\lambda f`.

    With :math:`x = \lambda x'` (normalised coordinates at :math:`f` and :math:`\lambda f`):
    :math:`k_{1,4} \lambda^2`, :math:`k_{2,5} \lambda^4`, :math:`k_{3,6} \lambda^6`,
    :math:`p_{1,2} \lambda`, :math:`s_{1,3} \lambda`, :math:`s_{2,4} \lambda^3`; the tilt
    :math:`\tau_{x,y}` is kept (it has no exact equivalent: a different focal tilts differently).
    """
    g = float(ratio)
    return np.array([g**2, g**4, g, g, g**6, g**2, g**4, g**6, g, g**3, g, g**3, 1.0, 1.0])


def fit_opencv(
    model: DistortionModel,
    width: int,
    height: int,
    *,
    n_coeffs: int = 12,
    focal: float | None = None,
    edges: Sequence[Array] | None = None,
    n_long: int = FIT_GRID_LONG,
) -> tuple[OpenCVModel, ConversionError]:
    """Closest OpenCV pin-hole distortion to ``model`` over the whole image.

    Parameters
    ----------
    n_coeffs : 4, 5, 8, 12 or 14
        ``k1 k2 p1 p2`` (radial-tangential, fitted alone), + ``k3`` (plumb_bob), + ``k4 k5 k6``
        (rational), + thin prism ``s1..s4``, + sensor tilt ``taux tauy``. Fitted in stages from 5 up,
        each from the previous solution; the stage with the smallest
        conversion error (modulo homography) is returned, padded with zeros.
    focal : float, optional
        Focal length in pixels (``fx = fy``), e.g. the nominal one from the
        lens and sensor; default :func:`placeholder_focal`. A harp measures
        only the shape of the field, so for the pin-hole model the focal is a
        scale the coefficients are expressed in (any value represents the same
        distortion, except through the tilt terms); the principal point (the
        distortion centre) is fitted.
    edges : sequence of (N, 2) arrays, optional
        Measured edge points of the fitting shots, for the conversion figures.

    Returns
    -------
    (OpenCVModel, ConversionError)
    """
    stages = opencv_stages(n_coeffs)
    f = placeholder_focal(width, height) if focal is None else float(focal)
    if not (np.isfinite(f) and f > 0):
        raise ValueError(f"focal length must be > 0 px, got {focal}")
    cx0, cy0 = (width - 1) / 2.0, (height - 1) / 2.0
    s = 0.5 * float(np.hypot(width, height))
    prob = _Problem.make(model, width, height, n_long)

    scale = focal_rescaling(f / placeholder_focal(width, height))

    def maker(n: int) -> Callable[[Array], OpenCVModel]:
        # theta holds the coefficients for the placeholder focal, whatever f is (the same fit
        # for every focal, tilt apart): the stage-wise LM is sensitive to their scaling
        def make(theta: Array) -> OpenCVModel:
            d = tuple(theta[2 : 2 + n] * scale[:n])
            return OpenCVModel(fx=f, fy=f, cx=cx0 + s * theta[0], cy=cy0 + s * theta[1], dist=d)

        return make

    h8 = prob.h0()
    pen = _pole_free_penalty
    # first the coefficients alone (centre at the image centre, H fixed at its linear start), then with
    # the centre, so that the centre does not wander off along the centre/perspective valley, then everything
    n0 = stages[0]
    k0, _, _ = _least_squares(
        prob,
        lambda k: maker(n0)(np.concatenate([[0.0, 0.0], k])),
        np.zeros(n0),
        h8,
        fix_h=True,
        penalty=pen,
        moves=_opencv_moves(n0, scale, None),
    )
    theta, _, _ = _least_squares(
        prob,
        maker(n0),
        np.concatenate([[0.0, 0.0], k0]),
        h8,
        fix_h=True,
        penalty=pen,
        moves=_opencv_moves(n0, scale, s),
    )
    best: tuple[float, OpenCVModel] | None = None
    faults = []
    for n in stages:
        theta = np.concatenate([theta, np.zeros(2 + n - len(theta))])
        theta, h8, _ = _least_squares(prob, maker(n), theta, h8, penalty=pen, moves=_opencv_moves(n, scale, s))
        cand = maker(n_coeffs)(np.concatenate([theta, np.zeros(2 + n_coeffs - len(theta))]))
        ideal = apply_homography(prob.pixel_h(h8), prob.u)
        fault = radial_fault(cand.dist, EXTRAPOLATION_RADIUS * corner_radius(ideal, cand.cx, cand.cy, f, f))
        if fault is not None:  # the margins are soft: a stage that still has a pole or fold is not exported
            faults.append(f"{n} coefficients: {fault}")
            continue
        score = mod_h_rms(model, cand, width, height)
        if best is None or score < best[0]:
            best = (score, cand)
    if best is not None and n_coeffs >= 12 and best[1] is cand:
        best = (
            best[0],
            _minimax_refits(
                model, width, height, prob, maker(n_coeffs), theta, h8, best[1], _opencv_moves(n_coeffs, scale, s)
            ),
        )
    family = f"the OpenCV {n_coeffs}-coefficient pin-hole model"
    more = [str(n) for n in OPENCV_STAGES if n > n_coeffs]
    remedy = "export it as a fisheye (--format auto picks the closest)"
    if more:
        alts = more[0] if len(more) == 1 else f"{', '.join(more[:-1])} or {more[-1]}"
        remedy = f"export with more coefficients (--coeffs {alts}) or as a fisheye (--format auto picks the closest)"
    return _pole_free_choice(model, best, faults, width, height, edges, family, remedy)


def _pole_free_choice(
    model: DistortionModel,
    best: tuple[float, OpenCVModel] | None,
    faults: Sequence[str],
    width: int,
    height: int,
    edges: Sequence[Array] | None,
    family: str,
    remedy: str,
) -> tuple[OpenCVModel, ConversionError]:
    """The closest pole-free stage ``best`` (score, model) with its conversion error stated as ``family`` with
    ``remedy``; ValueError naming every stage's fault and the remedy when no stage was pole-free."""
    if best is None:
        raise ValueError(
            f"{family} cannot represent this lens without a pole or fold within {EXTRAPOLATION_RADIUS:g}x the "
            f"corner radius ({'; '.join(faults)}); {remedy}"
        )
    out = best[1]
    return out, conversion_error(model, out, width, height, edges=edges, export=family, remedy=remedy)


def _minimax_refits(
    model: DistortionModel,
    width: int,
    height: int,
    prob: _Problem,
    make: Callable[[Array], OpenCVModel],
    theta: Array,
    h8: Array,
    plain: OpenCVModel,
    moves: Array,
) -> OpenCVModel:
    """The plain least-squares fit ``plain`` refitted :data:`MINIMAX_ROUNDS` times with Lawson's weights
    (:func:`_minimax_weights`); the candidate with the smallest max error modulo homography on a 64-point
    grid whose RMS is within :data:`MINIMAX_RMS_SLACK` of ``plain``'s and which is pole-free (``moves``:
    :func:`_opencv_moves` of ``make``)."""
    g = image_grid(width, height, 64)
    e0 = mod_h_errors(model, plain, g)
    rms0 = float(np.sqrt(np.mean(e0**2)))
    best, best_max = plain, float(e0.max())
    w = np.ones(len(prob.xd))
    cand = plain
    for _ in range(MINIMAX_ROUNDS):
        w = _minimax_weights(w, mod_h_errors(model, cand, prob.xd))
        theta, h8, _ = _least_squares(replace(prob, w=w), make, theta, h8, penalty=_pole_free_penalty, moves=moves)
        cand = make(theta)
        ideal = apply_homography(prob.pixel_h(h8), prob.u)
        if radial_fault(cand.dist, EXTRAPOLATION_RADIUS * corner_radius(ideal, cand.cx, cand.cy, cand.fx, cand.fy)):
            break
        e = mod_h_errors(model, cand, g)
        if float(np.sqrt(np.mean(e**2))) <= MINIMAX_RMS_SLACK * rms0 and float(e.max()) < best_max:
            best, best_max = cand, float(e.max())
    return best


FISHEYE_FOCAL_STARTS = (0.2, 0.3, 0.45, 0.7, 1.0, 1.6, 3.0)
"""Starting focal lengths (in image diagonals) tried by :func:`fit_fisheye` when no focal is given."""

FISHEYE_SCAN_GRID_LONG = 16
"""Grid (points along the long side) on which :func:`fit_fisheye` compares the starting focal lengths."""


def fit_fisheye(
    model: DistortionModel,
    width: int,
    height: int,
    *,
    focal: float | None = None,
    edges: Sequence[Array] | None = None,
    n_long: int = FIT_GRID_LONG,
    n_coeffs: int = 4,
) -> tuple[OpenCVFisheyeModel, ConversionError]:
    """Closest OpenCV fisheye (Kannala–Brandt ``k1..k4``) projection to ``model`` over the whole image.

    ``n_coeffs`` 2: ``k1 k2`` alone (``k3 = k4 = 0``), the fisheye model of Adobe's lens profiles
    (:mod:`pipeline.exports.lcp`).

    Unlike the pin-hole polynomial, the fisheye family depends on the focal
    length (the angle of a ray is ``atan(r / f)``): with ``focal`` (px, the
    nominal one) it is kept; without, it is fitted too, from the best of
    :data:`FISHEYE_FOCAL_STARTS` (compared on a coarse grid,
    :data:`FISHEYE_SCAN_GRID_LONG`, then refined on the full one; the fitted focal is then the one that makes
    the lens closest to a Kannala–Brandt lens, not a measured focal length).
    The principal point is fitted.
    """
    cx0, cy0 = (width - 1) / 2.0, (height - 1) / 2.0
    s = 0.5 * float(np.hypot(width, height))
    diag = placeholder_focal(width, height)
    if focal is not None and not (np.isfinite(focal) and focal > 0):
        raise ValueError(f"focal length must be > 0 px, got {focal}")
    prob = _Problem.make(model, width, height, n_long)

    if n_coeffs not in (2, 4):
        raise ValueError(f"the fisheye fit takes 2 or 4 coefficients, got {n_coeffs}")
    nt = 2 + n_coeffs

    def fixed(f: float) -> Callable[[Array], OpenCVFisheyeModel]:
        def make(theta: Array) -> OpenCVFisheyeModel:
            k = [float(v) for v in theta[2:nt]] + [0.0] * (4 - n_coeffs)
            d = (k[0], k[1], k[2], k[3])
            return OpenCVFisheyeModel(fx=f, fy=f, cx=cx0 + s * theta[0], cy=cy0 + s * theta[1], dist=d)

        return make

    def free(theta: Array) -> OpenCVFisheyeModel:
        return fixed(diag * float(np.exp(theta[nt])))(theta)

    def start(p: _Problem, f0: float, th0: Array) -> tuple[Array, Array, float]:
        th, _, _ = _least_squares(p, fixed(f0), th0, p.h0(), fix_h=True)
        return _least_squares(p, fixed(f0), th, p.h0())

    if focal is not None:
        f0 = float(focal)
        th, h8, _ = start(prob, f0, np.zeros(nt))
    else:
        # the starting focal is chosen on a coarse grid (the scan is most of the work), then refined
        coarse = _Problem.make(model, width, height, FISHEYE_SCAN_GRID_LONG)
        best: tuple[float, Array, float] | None = None
        for v in FISHEYE_FOCAL_STARTS:
            th, _, cost = start(coarse, diag * v, np.zeros(nt))
            if best is None or cost < best[0]:
                best = (cost, th, diag * v)
        assert best is not None
        _, th_c, f0 = best
        th, h8, _ = start(prob, f0, th_c)
    if focal is None:
        th, h8, _ = _least_squares(prob, free, np.append(th, np.log(f0 / diag)), h8)
        out = free(th)
    else:
        out = fixed(float(focal))(th)
    family = "the OpenCV fisheye model" if n_coeffs == 4 else f"the fisheye model with {n_coeffs} coefficients"
    return out, conversion_error(model, out, width, height, edges=edges, export=family)


def fit_lensfun(
    model: DistortionModel,
    width: int,
    height: int,
    *,
    kind: str = "ptlens",
    fit_center: bool = True,
    edges: Sequence[Array] | None = None,
    n_long: int = FIT_GRID_LONG,
    lens_type: str = "rectilinear",
    geometry_focal: float = 0.0,
) -> tuple[LensfunModel, ConversionError]:
    """Closest lensfun ``poly3`` / ``poly5`` / ``ptlens`` distortion to ``model``.

    ``lens_type`` other than rectilinear: a fisheye lens whose geometry conversion uses the fixed
    ``geometry_focal`` (:func:`pipeline.models.lensfun_model.geometry_focal` of the nominal focal
    length and crop factor; the file cannot hold another), the polynomial fitted on top of it.

    With ``fit_center`` (default) the distortion centre is fitted too and
    written as the lens' ``<center x y>`` offset (read by lensfun 0.3.x;
    verified with lensfun 0.3.4); without, it is the image centre, so a
    decentred lens shows up in the conversion error. ``ptlens`` starts from
    the ``poly3`` solution (poly3 is the ptlens lens with ``a = c = 0``).
    """
    if kind not in LENSFUN_TERMS:
        raise ValueError(f"lensfun export supports {sorted(LENSFUN_TERMS)}, got {kind!r}")
    prob = _Problem.make(model, width, height, n_long)

    def maker(k: str) -> Callable[[Array], LensfunModel]:
        n = len(LENSFUN_TERMS[k])

        def make(theta: Array) -> LensfunModel:
            center = (float(theta[n]), float(theta[n + 1])) if fit_center else (0.0, 0.0)
            return LensfunModel(
                kind=k,
                terms=tuple(theta[:n]),
                width=width,
                height=height,
                center=center,
                lens_type=lens_type,
                geometry_focal=geometry_focal,
            )

        return make

    nc = 2 if fit_center else 0
    h8 = prob.h0()
    candidates: list[LensfunModel] = []
    if kind == "ptlens":
        th3, _, _ = _least_squares(prob, maker("poly3"), np.zeros(1 + nc), h8, fix_h=True)
        th3, h8, _ = _least_squares(prob, maker("poly3"), th3, h8)
        candidates.append(maker("ptlens")(np.concatenate([[0.0, th3[0], 0.0], th3[1:]])))
        theta0 = np.concatenate([[0.0, th3[0], 0.0], th3[1:]])
    else:
        theta0, _, _ = _least_squares(prob, maker(kind), np.zeros(len(LENSFUN_TERMS[kind]) + nc), h8, fix_h=True)
    th, _, _ = _least_squares(prob, maker(kind), theta0, h8)
    candidates.append(maker(kind)(th))
    out = min(candidates, key=lambda m: mod_h_rms(model, m, width, height))
    family = f"the lensfun {kind} model" + (f" of a {lens_type} lens" if lens_type != "rectilinear" else "")
    return out, conversion_error(model, out, width, height, edges=edges, export=family)


def _in_frame_problem(model: DistortionModel, width: int, height: int, n_long: int) -> tuple[_Problem, Array]:
    """The fitting data and the conditioned identity homography: the export's ideal frame is ours."""
    prob = _Problem.make(model, width, height, n_long)
    return prob, np.array([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])


def frame_error(
    ours: DistortionModel, theirs: DistortionModel, width: int, height: int, n_long: int = ERROR_GRID_LONG
) -> tuple[float, float]:
    """RMS and max (px) of ``|U_theirs(x) - U_ours(x)|`` over the image, no homography: how far an
    export with a measured camera matrix is from the correction in the camera's own ideal frame."""
    g = image_grid(width, height, n_long)
    e = np.linalg.norm(theirs.undistort_points(g) - ours.undistort_points(g), axis=1)
    e = np.where(np.isfinite(e), e, np.inf)
    return float(np.sqrt(np.mean(e**2))), float(e.max())


def fit_opencv_camera(
    model: DistortionModel,
    width: int,
    height: int,
    camera: tuple[float, float, float, float],
    *,
    n_coeffs: int = 12,
    edges: Sequence[Array] | None = None,
    n_long: int = FIT_GRID_LONG,
) -> tuple[OpenCVModel, ConversionError]:
    r"""Closest OpenCV pin-hole distortion to ``model`` *with a measured camera matrix*.

    ``camera = (fx, fy, cx, cy)`` was measured in the ideal frame of ``model``
    (:mod:`pipeline.intrinsics`): the export must then reproduce the correction in that frame,
    so the homography of :func:`fit_opencv` is held at the identity and the camera matrix fixed;
    only the coefficients are fitted (in stages, 5 -> 8 -> 12 -> 14, pole-free as there):

    .. math::
        \min_{\theta} \sum_{x_d \in G} \| D_{\theta, K}(U(x_d)) - x_d \|^2 .

    The conversion error is reported as by :func:`fit_opencv` (the figures ``harp evaluate``
    sees); :func:`frame_error` gives it in the camera's frame.
    """
    stages = opencv_stages(n_coeffs)
    fx, fy, cx, cy = (float(v) for v in camera)
    prob, h_id = _in_frame_problem(model, width, height, n_long)
    scale = focal_rescaling(fx / placeholder_focal(width, height))

    def maker(n: int) -> Callable[[Array], OpenCVModel]:
        def make(theta: Array) -> OpenCVModel:
            return OpenCVModel(fx=fx, fy=fy, cx=cx, cy=cy, dist=tuple(theta[:n] * scale[:n]))

        return make

    pen = _pole_free_penalty
    theta = np.zeros(0)
    best: tuple[float, OpenCVModel] | None = None
    faults = []
    for n in stages:
        theta = np.concatenate([theta, np.zeros(n - len(theta))])
        theta, _, _ = _least_squares(
            prob, maker(n), theta, h_id, fix_h=True, penalty=pen, moves=_opencv_moves(n, scale, None)
        )
        cand = maker(n_coeffs)(np.concatenate([theta, np.zeros(n_coeffs - len(theta))]))
        fault = radial_fault(cand.dist, EXTRAPOLATION_RADIUS * corner_radius(prob.u, cx, cy, fx, fy))
        if fault is not None:
            faults.append(f"{n} coefficients: {fault}")
            continue
        score = frame_error(model, cand, width, height, n_long=64)[0]
        if best is None or score < best[0]:
            best = (score, cand)
    family = f"the OpenCV {n_coeffs}-coefficient pin-hole model with the measured camera matrix"
    remedy = "export with more coefficients (--coeffs) or as a fisheye"
    return _pole_free_choice(model, best, faults, width, height, edges, family, remedy)


def fit_fisheye_camera(
    model: DistortionModel,
    width: int,
    height: int,
    camera: tuple[float, float, float, float],
    *,
    edges: Sequence[Array] | None = None,
    n_long: int = FIT_GRID_LONG,
) -> tuple[OpenCVFisheyeModel, ConversionError]:
    """:func:`fit_fisheye` with a measured camera matrix: ``k1..k4`` alone fitted, the camera matrix
    fixed and the homography held at the identity (as :func:`fit_opencv_camera`)."""
    fx, fy, cx, cy = (float(v) for v in camera)
    prob, h_id = _in_frame_problem(model, width, height, n_long)

    def make(theta: Array) -> OpenCVFisheyeModel:
        return OpenCVFisheyeModel(
            fx=fx, fy=fy, cx=cx, cy=cy, dist=(float(theta[0]), float(theta[1]), float(theta[2]), float(theta[3]))
        )

    th, _, _ = _least_squares(prob, make, np.zeros(4), h_id, fix_h=True)
    out = make(th)
    family = "the OpenCV fisheye model with the measured camera matrix"
    return out, conversion_error(model, out, width, height, edges=edges, export=family)


def fit_thin_prism_fisheye(
    model: DistortionModel,
    width: int,
    height: int,
    start: OpenCVFisheyeModel,
    *,
    edges: Sequence[Array] | None = None,
    n_long: int = FIT_GRID_LONG,
) -> tuple[ThinPrismFisheyeModel, ConversionError]:
    """Closest COLMAP ``THIN_PRISM_FISHEYE`` projection to ``model``, from the fisheye fit ``start``.

    ``start`` (:func:`fit_fisheye`) is the member of the family with ``p = s = 0``; the fit starts at
    it and its homography (:func:`ideal_homography`), the focal length held at its value, and moves
    the principal point, ``k1..k4``, ``p1 p2``, ``sx1 sy1`` and the homography together. LM is
    monotone from that start, so the result is never farther from ``model`` (on the fitting grid)
    than ``start``.
    """
    prob = _Problem.make(model, width, height, n_long)
    s = 0.5 * float(np.hypot(width, height))

    def make(theta: Array) -> ThinPrismFisheyeModel:
        k1, k2, p1, p2, k3, k4, sx, sy = (float(v) for v in theta[2:10])
        return ThinPrismFisheyeModel(
            fx=start.fx,
            fy=start.fy,
            cx=start.cx + s * theta[0],
            cy=start.cy + s * theta[1],
            dist=(k1, k2, p1, p2, k3, k4, sx, sy),
        )

    k = start.dist
    theta0 = np.array([0.0, 0.0, k[0], k[1], 0.0, 0.0, k[2], k[3], 0.0, 0.0])
    h = prob.t @ np.linalg.inv(ideal_homography(model, start, width, height)) @ prob.tinv
    h8 = np.asarray((h / h[2, 2]).ravel()[:8], dtype=np.float64)
    th, _, _ = _least_squares(prob, make, theta0, h8)
    out = make(th)
    return out, conversion_error(model, out, width, height, edges=edges, export="COLMAP's THIN_PRISM_FISHEYE model")
