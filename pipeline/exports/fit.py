r"""Convert a harp correction to OpenCV or lensfun parameters, with its conversion error.

OpenCV's and lensfun's models cannot represent every lens, so an export is
the member of their family closest to our correction, and the export states
how far it is. Both are defined only up to a homography, so the fit is

.. math::
    \min_{\theta, H} \sum_{x_d \in G} \bigl\| D_\theta\bigl(H(U(x_d))\bigr) - x_d \bigr\|^2

over a dense grid :math:`G` of distorted pixels covering the whole image,
with :math:`U` our correction, :math:`D_\theta` the export's closed-form
projection (ideal -> distorted) and :math:`H` a free homography (the output
frame of the export need not be ours). The conversion error is then measured
in the correction direction, on a denser grid, comparing the export's
correction :math:`U_\theta = D_\theta^{-1}` with ours after *both* are
normalised by their 4-corner homography (:mod:`pipeline.normalise`) — the
comparison ``harp evaluate`` makes — and also modulo the best least-squares
homography (smaller or equal: the intrinsic mismatch).

References
----------
.. [1] Z. Tang et al., "High-precision camera distortion measurements with a
   calibration harp", JOSA A 29(10), 2012, section 2 (corrections modulo homography).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from pipeline.evaluate import corrected_points
from pipeline.models.base import DistortionModel
from pipeline.models.homography import apply_homography
from pipeline.models.lensfun_model import LENSFUN_TERMS, LensfunModel
from pipeline.models.opencv_model import OpenCVModel
from pipeline.normalise import corner_homography, fit_homography, normalise_by_corners
from pipeline.straightness import straightness


@dataclass(frozen=True)
class ConversionError:
    """How far an exported correction is from ours, in pixels over the image.

    Attributes
    ----------
    rms_px, max_px : float
        RMS and max over the grid of ``|N(U_export)(x) - N(U_ours)(x)|`` with
        ``N`` the 4-corner homography normalisation (what ``harp evaluate`` sees).
    rms_mod_h_px, max_mod_h_px : float
        The same after the best least-squares homography between the two.
    n_points : int
        Grid points compared (the whole image, borders included).
    d_px, d_max_px : float
        Straightness (Tang et al. ``d``, ``d_max``) of straight lines that our
        correction makes exactly straight, after the export's correction:
        the residual distortion ``harp evaluate`` would report for the export
        on a noise-free harp (lines every ~1/16 of the image at 0, 45, 90 and
        135 degrees, a point every 4 px). Homography-invariant; compare with
        the measurement noise floor.
    """

    rms_px: float
    max_px: float
    rms_mod_h_px: float
    max_mod_h_px: float
    n_points: int
    d_px: float = float("nan")
    d_max_px: float = float("nan")

    def to_dict(self) -> dict:
        return {
            "rms_px": self.rms_px,
            "max_px": self.max_px,
            "rms_mod_h_px": self.rms_mod_h_px,
            "max_mod_h_px": self.max_mod_h_px,
            "n_points": self.n_points,
            "d_px": self.d_px,
            "d_max_px": self.d_max_px,
        }


def image_grid(width: int, height: int, n_long: int = 64) -> np.ndarray:
    """Grid of pixel positions covering the image (borders included), ``n_long`` along the long side."""
    n_long = max(int(n_long), 2)
    if width >= height:
        nx, ny = n_long, max(2, int(round(n_long * height / width)))
    else:
        nx, ny = max(2, int(round(n_long * width / height))), n_long
    xs = np.linspace(0.0, width - 1.0, nx)
    ys = np.linspace(0.0, height - 1.0, ny)
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def conversion_error(
    ours: DistortionModel, theirs: DistortionModel, width: int, height: int, n_long: int = 121
) -> ConversionError:
    """Compare two corrections over the image: 4-corner normalised, and modulo best homography."""
    g = image_grid(width, height, n_long)
    uo = ours.undistort_points(g)
    ut = theirs.undistort_points(g)
    ok = np.all(np.isfinite(uo), axis=1) & np.all(np.isfinite(ut), axis=1)
    if ok.sum() < 0.99 * len(g):
        raise ValueError(
            f"the export's correction is undefined on {np.sum(~ok)} of {len(g)} grid "
            f"points (its polynomial is not invertible over the image)"
        )
    no = apply_homography(corner_homography(ours, width, height), uo[ok])
    nt = apply_homography(corner_homography(theirs, width, height), ut[ok])
    e = np.linalg.norm(nt - no, axis=1)
    h = fit_homography(nt, no)
    e_h = np.linalg.norm(apply_homography(h, nt) - no, axis=1)
    if not ok.all():  # undefined points count as failures of the export
        e = np.concatenate([e, np.full(np.sum(~ok), np.inf)])
        e_h = np.concatenate([e_h, np.full(np.sum(~ok), np.inf)])
    st = conversion_straightness(ours, theirs, width, height)
    return ConversionError(
        rms_px=float(np.sqrt(np.mean(e**2))),
        max_px=float(e.max()),
        rms_mod_h_px=float(np.sqrt(np.mean(e_h**2))),
        max_mod_h_px=float(e_h.max()),
        n_points=int(len(e)),
        d_px=st.d,
        d_max_px=st.d_max,
    )


def straight_lines_through(
    model: DistortionModel,
    width: int,
    height: int,
    n_lines: int = 16,
    angles_deg=(0.0, 45.0, 90.0, 135.0),
    step_px: float = 4.0,
    min_points: int = 20,
) -> list[np.ndarray]:
    """Distorted images of ideal straight lines: what ``model`` (4-corner normalised) makes straight.

    Lines at each angle, ``n_lines`` across the image, sampled every
    ``step_px`` in the ideal frame, mapped to the distorted image by the
    model's inverse; points falling outside the image are dropped.
    """
    norm = normalise_by_corners(model, width, height)
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    half = 0.5 * float(np.hypot(width, height))
    out = []
    for a in np.radians(np.asarray(angles_deg, dtype=np.float64)):
        d = np.array([np.cos(a), np.sin(a)])
        n = np.array([-d[1], d[0]])
        ext = abs(n[0]) * (width - 1) / 2 + abs(n[1]) * (height - 1) / 2
        for off in np.linspace(-ext, ext, n_lines + 2)[1:-1]:
            s = np.arange(-half, half + step_px, step_px)
            ideal = c + off * n + s[:, None] * d
            inside = (
                (ideal[:, 0] >= -0.5)
                & (ideal[:, 0] <= width - 0.5)
                & (ideal[:, 1] >= -0.5)
                & (ideal[:, 1] <= height - 0.5)
            )
            pts = norm.distort_points(ideal[inside])
            ok = (
                np.all(np.isfinite(pts), axis=1)
                & (pts[:, 0] >= 0)
                & (pts[:, 0] <= width - 1)
                & (pts[:, 1] >= 0)
                & (pts[:, 1] <= height - 1)
            )
            if ok.sum() >= min_points:
                out.append(pts[ok])
    return out


def conversion_straightness(ours: DistortionModel, theirs: DistortionModel, width: int, height: int):
    """Straightness (``d``, ``d_max``) left by ``theirs`` on lines ``ours`` makes exactly straight."""
    lines = straight_lines_through(ours, width, height)
    return straightness(corrected_points(lines, theirs, width, height))


def _fit_with_homography(ours: DistortionModel, width: int, height: int, make, theta0, n_long: int = 40):
    """Least squares over (theta, H) of ``make(theta).distort_points(H(U(x_d))) - x_d``."""
    xd = image_grid(width, height, n_long)
    u = ours.undistort_points(xd)
    ok = np.all(np.isfinite(u), axis=1)
    if ok.sum() < 0.9 * len(xd):
        raise ValueError("our correction is undefined over much of the image; cannot convert it")
    xd, u = xd[ok], u[ok]
    # condition H in coordinates centred on the image, unit ~ half diagonal
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    s = 0.5 * float(np.hypot(width, height))
    t = np.array([[1 / s, 0, -c[0] / s], [0, 1 / s, -c[1] / s], [0, 0, 1.0]])
    tinv = np.linalg.inv(t)
    h0 = t @ fit_homography(u, xd) @ tinv
    h0 = h0 / h0[2, 2]
    theta0 = np.asarray(theta0, dtype=np.float64)
    nt = len(theta0)

    def unpack(p):
        hn = np.append(p[nt:], 1.0).reshape(3, 3)
        return p[:nt], tinv @ hn @ t

    def resid(p):
        theta, h = unpack(p)
        try:
            m = make(theta)
        except ValueError:
            return np.full(2 * len(xd), 1e6)
        r = m.distort_points(apply_homography(h, u)) - xd
        r = np.nan_to_num(r, nan=1e6, posinf=1e6, neginf=-1e6)
        return r.ravel()

    p0 = np.concatenate([theta0, h0.ravel()[:8]])
    sol = least_squares(resid, p0, method="lm", x_scale="jac", xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=2000)
    theta, _ = unpack(sol.x)
    return make(theta)


def fit_opencv(
    model: DistortionModel, width: int, height: int, *, n_coeffs: int = 5, focal: float | None = None
) -> tuple[OpenCVModel, ConversionError]:
    """Closest OpenCV pinhole distortion to ``model`` over the image.

    Parameters
    ----------
    n_coeffs : 5 or 8
        ``k1 k2 p1 p2 k3`` (plumb_bob) or the rational ``k1 k2 p1 p2 k3 k4 k5 k6``.
    focal : float, optional
        Nominal focal length in pixels (``fx = fy``), default the image
        diagonal. A harp gives no focal length: only the shape of the field is
        measured, so the coefficients are those for this nominal focal; the
        principal point (the distortion centre) is fitted.

    Returns
    -------
    (OpenCVModel, ConversionError)
    """
    if n_coeffs not in (5, 8):
        raise ValueError(f"OpenCV export supports 5 or 8 coefficients, got {n_coeffs}")
    f = float(np.hypot(width, height)) if focal is None else float(focal)
    if not f > 0:
        raise ValueError(f"focal length must be > 0 px, got {focal}")
    cx0, cy0 = (width - 1) / 2.0, (height - 1) / 2.0
    s = 0.5 * float(np.hypot(width, height))

    def make(theta):
        return OpenCVModel(fx=f, fy=f, cx=cx0 + s * theta[0], cy=cy0 + s * theta[1], dist=tuple(theta[2:]))

    out = _fit_with_homography(model, width, height, make, np.zeros(2 + n_coeffs))
    return out, conversion_error(model, out, width, height)


def fit_lensfun(
    model: DistortionModel, width: int, height: int, *, kind: str = "ptlens", fit_center: bool = True
) -> tuple[LensfunModel, ConversionError]:
    """Closest lensfun ``poly3`` / ``poly5`` / ``ptlens`` distortion to ``model``.

    With ``fit_center`` (default) the distortion centre is fitted too and
    written as the lens' ``<center x y>`` offset (read by lensfun 0.3.x;
    verified with lensfun 0.3.4); without, it is the image centre, so a
    decentred lens shows up in the conversion error.
    """
    if kind not in LENSFUN_TERMS:
        raise ValueError(f"lensfun export supports {sorted(LENSFUN_TERMS)}, got {kind!r}")
    n = len(LENSFUN_TERMS[kind])

    def make(theta):
        center = (theta[n], theta[n + 1]) if fit_center else (0.0, 0.0)
        return LensfunModel(kind=kind, terms=tuple(theta[:n]), width=width, height=height, center=center)

    out = _fit_with_homography(model, width, height, make, np.zeros(n + 2 if fit_center else n))
    return out, conversion_error(model, out, width, height)
