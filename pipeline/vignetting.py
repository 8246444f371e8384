r"""Vignetting from the back-lit sheet between the strings, the back-light separated by the turntable.

Between the strings a harp shot sees the back-lit sheet: a flat field, but not a
uniform one. What a pixel records there is the lens's relative illumination
:math:`V(x)` (vignetting: fixed on the sensor) times the back-light's own
non-uniformity :math:`L` (fixed on the harp: it turns with it) times the shot's
exposure :math:`e_k`. With the harp at the turntable angle :math:`\theta_k`, the
ideal image position :math:`u = U(x)` (the distortion correction; the identity when
none is given) and :math:`a` the image of the turntable's axis:

.. math::
    \log I_k(x) = \log e_k + \log V(x) + \log L\bigl(R(-\theta_k)(u - a)\bigr)

Models
------
* :math:`\log V(x) = \sum_{j=1}^{J} v_j r^{2j} + \sum_{(n, m)} r^n (\gamma_{nm} \cos m\psi
  + \delta_{nm} \sin m\psi)`, :math:`(r, \psi)` the polar coordinates of
  :math:`(x - c) / R` with :math:`c` the image centre and :math:`R` the half-diagonal
  between pixel centres (lensfun's normalisation for vignetting), so :math:`V(c) = 1`:
  a radial fall-off and, up to degree ``lens_harmonics`` (default 2), the non-radial
  part of a decentred or tilted lens (the same harmonics as the back-light's);
* :math:`\log L(h) = \sum_{m \ge 1,\ m \le n \le M,\ n \equiv m \,(2)}
  \rho^n (\alpha_{nm} \cos m\phi + \beta_{nm} \sin m\phi)` in polar coordinates
  :math:`(\rho, \phi)` of :math:`h / R`: every polynomial of degree :math:`\le M`
  except its rotationally symmetric part (the Zernike-like harmonics with
  :math:`m \ge 1`).

Everything is linear in :math:`(\log e_k, v_j, \gamma, \delta, \alpha, \beta)`: one
least-squares solve over the samples of all shots (:func:`fit_vignetting`). In one shot
the lens's non-radial harmonics and the back-light's are the same functions of the
pixel: it is the turntable's rotation (the back-light turns, the lens does not) that
tells them apart, and a fit whose angles leave them confounded is refused.

What the rotation can and cannot separate
-----------------------------------------
A part of the back-light that is symmetric about the turntable's axis looks the
same at every angle: no rotation tells it from a vignetting about the same point.
It is not in :math:`L`'s model, so it is measured as vignetting (with the axis at
the image centre, exactly; otherwise approximately). Every other part (gradients,
a lamp off to one side, an elliptical fall-off) is separated, given angles that
do not share its symmetry: harmonic :math:`m` needs two angles that differ by
other than a multiple of :math:`360°/m` (:func:`fit_vignetting` refuses angles
that leave the system rank-deficient). A back-light brighter in the middle should be
checked on its own, or the harp turned off-centre on the turntable (the axis then
away from the image centre, the symmetric part no longer about the lens's centre).

Samples
-------
:func:`backlit_samples` keeps the pixels of the lit sheet only: farther than a
margin from every measured string edge and bright against their neighbourhood
(inside a string or on the harp's frame they are dark), averaged in blocks of
``block`` x ``block`` pixels (the mean of the kept pixels, at their mean position).

lensfun's ``pa`` model
----------------------
:math:`V = 1 + k_1 r^2 + k_2 r^4 + k_3 r^6` (a correction divides by it; checked
against liblensfun through lensfunpy): :func:`lensfun_pa` fits it to the
estimated :math:`V` over the image.

References
----------
.. [1] D. B. Goldman, "Vignette and exposure calibration and compensation",
   IEEE TPAMI 32(12), 2010 (vignetting and exposure from several images).
.. [2] Lensfun, ``lfVignettingModel`` (``LF_VIGNETTING_MODEL_PA``, Panorama Tools),
   https://lensfun.github.io/manual/latest/
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from pipeline.edgeset import FitFailure
from pipeline.tca import image_grid

Floats = NDArray[np.float64]

DEFAULT_VIGNETTING_DEGREE = 4
"""Powers of :math:`r^2` in :math:`\\log V` (:math:`J`)."""
DEFAULT_BACKLIGHT_DEGREE = 3
"""Total degree :math:`M` of the back-light's harmonics."""
MIN_RANK_RATIO = 1e-6
"""Smallest singular value of the scaled design matrix, relative to the largest, a fit accepts."""


class UndistortsPoints(Protocol):
    def undistort_points(self, xy: np.ndarray) -> np.ndarray: ...


def lensfun_radius(xy: Floats, width: int, height: int, center: tuple[float, float] = (0.0, 0.0)) -> Floats:
    """Lensfun's vignetting radius :math:`r`: the distance to the lens's centre over the half-diagonal.

    The half-diagonal is between pixel centres; the lens's centre is the image centre plus the
    lens's ``<center>`` (``center``, lensfun's normalised units: half the shorter side), about
    which liblensfun applies the vignetting as it does the distortion and the TCA (checked
    through lensfunpy, ``tests/pipeline/test_lensfun_colour.py``).
    """
    p = np.asarray(xy, np.float64).reshape(-1, 2)
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    o = c + float(c.min()) * np.asarray(center, np.float64)
    return np.asarray(np.hypot(*(p - o).T) / float(np.hypot(*c)), np.float64)


def harmonics(degree: int) -> list[tuple[int, int]]:
    """``(n, m)`` of the back-light's terms: ``1 <= m <= n <= degree``, ``n - m`` even."""
    return [(n, m) for n in range(1, degree + 1) for m in range(1, n + 1) if (n - m) % 2 == 0]


def _backlight_basis(h: Floats, degree: int, scale: float) -> Floats:
    q = h / scale
    rho = np.hypot(q[:, 0], q[:, 1])
    phi = np.arctan2(q[:, 1], q[:, 0])
    cols = []
    for n, m in harmonics(degree):
        cols += [rho**n * np.cos(m * phi), rho**n * np.sin(m * phi)]
    return np.column_stack(cols) if cols else np.zeros((len(h), 0))


def _rotate(xy: Floats, angle_deg: float) -> Floats:
    """:math:`R(-\\theta)` applied to points relative to the axis."""
    a = np.radians(angle_deg)
    rot = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])
    return np.asarray(xy @ rot.T, np.float64)


@dataclass(frozen=True)
class BacklitSamples:
    """Block means of the lit sheet of one shot: positions ``xy`` (N, 2), ``value`` (N,), pixels per block."""

    xy: Floats
    value: Floats
    count: NDArray[np.intp]


def backlit_samples(
    image: NDArray[Any],
    edges: Sequence[Floats],
    margin_px: float = 4.0,
    block: int = 8,
    window_px: int = 61,
    bright_fraction: float = 0.75,
    positions: tuple[Floats, Floats] | None = None,
) -> BacklitSamples:
    """The lit sheet between the strings of one shot, as block means (module docstring).

    Parameters
    ----------
    image : 2-D ndarray
        The shot (a grey image, or one CFA plane with ``positions``).
    edges : sequence of (M, 2) arrays
        The measured edge points (raw or smoothed) of every string, in the
        coordinates of ``positions`` (pixels of ``image`` without it).
    margin_px : float
        Pixels nearer an edge than this (in those coordinates) are left out.
    block : int
        Side of the averaging blocks, pixels of ``image``.
    window_px : int
        Window of the local maximum a kept pixel is compared with.
    bright_fraction : float
        A kept pixel is at least this fraction of the local maximum.
    positions : (X, Y) arrays of ``image``'s shape, optional
        Coordinates of each pixel (a CFA plane's mosaic positions); default its
        column and row.
    """
    from scipy import ndimage
    from scipy.spatial import cKDTree

    img = np.asarray(image, np.float64)
    h, w = img.shape
    if positions is None:
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    else:
        xx, yy = (np.asarray(p, np.float64) for p in positions)
    keep = img >= bright_fraction * ndimage.maximum_filter(img, size=int(window_px))
    pts = [np.asarray(e, np.float64).reshape(-1, 2) for e in edges if len(e)]
    if pts:
        allp = np.concatenate(pts)
        # densify: edge points may be t px apart; the distance to the polyline matters
        dense = [allp]
        for e in pts:
            if len(e) > 1:
                seg = np.diff(e, axis=0)
                n = int(np.ceil(np.max(np.hypot(seg[:, 0], seg[:, 1])) / 1.0))
                for f in np.linspace(0, 1, max(n, 1), endpoint=False)[1:]:
                    dense.append(e[:-1] + f * seg)
        tree = cKDTree(np.concatenate(dense))
        cand = np.flatnonzero(keep.ravel())
        d, _ = tree.query(np.column_stack([xx.ravel()[cand], yy.ravel()[cand]]), distance_upper_bound=margin_px)
        flat = keep.ravel()
        flat[cand[np.isfinite(d)]] = False
        keep = flat.reshape(h, w)
    by, bx = h // block, w // block
    k = keep[: by * block, : bx * block].reshape(by, block, bx, block)

    def block_sum(a: Floats) -> Floats:
        return np.asarray(
            np.where(k, a[: by * block, : bx * block].reshape(by, block, bx, block), 0.0).sum(axis=(1, 3)), np.float64
        )

    cnt = k.sum(axis=(1, 3))
    ok = cnt >= max(4, block * block // 4)
    c = np.where(ok, cnt, 1)
    val, sx, sy = block_sum(img) / c, block_sum(xx) / c, block_sum(yy) / c
    return BacklitSamples(np.column_stack([sx[ok], sy[ok]]), val[ok], cnt[ok].astype(np.intp))


@dataclass(frozen=True)
class VignettingFit:
    r"""The lens's relative illumination and the back-light, separated (module docstring).

    ``log_v`` holds :math:`v_1 .. v_J`; ``lens_harmonics`` the :math:`(\gamma, \delta)` pairs of the
    lens's non-radial part (:func:`harmonics` of ``lens_degree``); ``backlight`` the :math:`(\alpha, \beta)` pairs in
    :func:`harmonics` order; ``exposure`` :math:`\log e_k` per shot; ``axis`` the axis
    :math:`a` (ideal pixels); ``residual_rms`` the RMS of the fit's residual in
    :math:`\log I` (about the relative noise of a block mean).
    """

    width: int
    height: int
    log_v: tuple[float, ...]
    backlight_degree: int
    backlight: tuple[float, ...]
    exposure: tuple[float, ...]
    axis: tuple[float, float]
    residual_rms: float
    n_samples: int
    lens_degree: int = 0
    lens_harmonics: tuple[float, ...] = ()

    @property
    def scale(self) -> float:
        return 0.5 * float(np.hypot(self.width - 1, self.height - 1))

    def relative_illumination(self, xy: Floats) -> Floats:
        """:math:`V(x)`, 1 at the image centre."""
        p = np.asarray(xy, np.float64).reshape(-1, 2)
        return np.asarray(np.exp(self.radial_log(p) + self.nonradial_log(p)), np.float64)

    def radial_log(self, xy: Floats) -> Floats:
        r"""The radial part of :math:`\log V` (what lensfun's pa model holds)."""
        r2 = lensfun_radius(xy, self.width, self.height) ** 2
        return np.asarray(sum(v * r2 ** (j + 1) for j, v in enumerate(self.log_v)), np.float64)

    def nonradial_log(self, xy: Floats) -> Floats:
        r"""The non-radial part of :math:`\log V` (decentred or tilted lens)."""
        c = np.array([(self.width - 1) / 2.0, (self.height - 1) / 2.0])
        b = _backlight_basis(np.asarray(xy, np.float64).reshape(-1, 2) - c, self.lens_degree, self.scale)
        return np.asarray(b @ np.asarray(self.lens_harmonics), np.float64)

    def backlight_factor(self, h: Floats) -> Floats:
        """:math:`L(h)` at points ``h`` relative to the axis in the harp's own orientation (angle 0)."""
        b = _backlight_basis(np.asarray(h, np.float64).reshape(-1, 2), self.backlight_degree, self.scale)
        return np.asarray(np.exp(b @ np.asarray(self.backlight)), np.float64)

    def flat_field(self) -> NDArray[np.float32]:
        """:math:`V` on every pixel centre, ``(height, width)`` float32: divide an image by it to correct it."""
        yy, xx = np.mgrid[0 : self.height, 0 : self.width].astype(np.float64)
        v = self.relative_illumination(np.column_stack([xx.ravel(), yy.ravel()]))
        return v.reshape(self.height, self.width).astype(np.float32)

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": "log_radial_vignetting",
            "image_size": [self.width, self.height],
            "log_v": list(self.log_v),
            "backlight_degree": self.backlight_degree,
            "backlight": list(self.backlight),
            "exposure": list(self.exposure),
            "lens_degree": self.lens_degree,
            "lens_harmonics": list(self.lens_harmonics),
            "axis": list(self.axis),
            "residual_rms": self.residual_rms,
            "n_samples": self.n_samples,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> VignettingFit:
        """The fit :meth:`to_dict` wrote (KeyError, TypeError or ValueError when it is not one)."""
        if d.get("model") != "log_radial_vignetting":
            raise ValueError(f"model {d.get('model')!r} is not log_radial_vignetting")
        w, h = (int(v) for v in d["image_size"])
        ax, ay = (float(v) for v in d["axis"])

        def floats(key: str) -> tuple[float, ...]:
            return tuple(float(v) for v in d.get(key) or ())

        fit = cls(
            width=w,
            height=h,
            log_v=floats("log_v"),
            backlight_degree=int(d["backlight_degree"]),
            backlight=floats("backlight"),
            exposure=floats("exposure"),
            axis=(ax, ay),
            residual_rms=float(d["residual_rms"]),
            n_samples=int(d["n_samples"]),
            lens_degree=int(d.get("lens_degree", 0)),
            lens_harmonics=floats("lens_harmonics"),
        )
        for key, degree, got in (
            ("backlight", fit.backlight_degree, fit.backlight),
            ("lens_harmonics", fit.lens_degree, fit.lens_harmonics),
        ):
            if len(got) != 2 * len(harmonics(degree)):
                raise ValueError(f"{key}: {len(got)} values, degree {degree} has {2 * len(harmonics(degree))}")
        if not fit.log_v or not all(np.isfinite(fit.log_v + fit.lens_harmonics)):
            raise ValueError("log_v: no finite radial terms")
        return fit


def _design(
    shots: Sequence[BacklitSamples],
    angles_deg: Sequence[float],
    width: int,
    height: int,
    axis: Floats,
    degree: int,
    backlight_degree: int,
    lens: UndistortsPoints | None,
    lens_degree: int,
) -> tuple[Floats, Floats, Floats]:
    scale = 0.5 * float(np.hypot(width - 1, height - 1))
    rows, rhs, wts = [], [], []
    k = len(shots)
    for i, (s, ang) in enumerate(zip(shots, angles_deg)):
        r2 = lensfun_radius(s.xy, width, height) ** 2
        u = s.xy if lens is None else np.asarray(lens.undistort_points(s.xy), np.float64)
        b = _backlight_basis(_rotate(u - axis, ang), backlight_degree, scale)
        e = np.zeros((len(s.xy), k))
        e[:, i] = 1.0
        v = np.column_stack([r2 ** (j + 1) for j in range(degree)])
        c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
        nr = _backlight_basis(s.xy - c, lens_degree, scale)
        rows.append(np.hstack([e, v, nr, b]))
        rhs.append(np.log(np.clip(s.value, 1e-12, None)))
        wts.append(np.sqrt(s.count.astype(np.float64)))
    return np.vstack(rows), np.concatenate(rhs), np.concatenate(wts)


def fit_vignetting(
    shots: Sequence[BacklitSamples],
    angles_deg: Sequence[float],
    width: int,
    height: int,
    degree: int = DEFAULT_VIGNETTING_DEGREE,
    backlight_degree: int = DEFAULT_BACKLIGHT_DEGREE,
    axis: tuple[float, float] | None = None,
    lens: UndistortsPoints | None = None,
    lens_harmonics: int = 2,
) -> VignettingFit | FitFailure:
    """Fit the lens's vignetting and the back-light from shots at several turntable angles.

    Parameters
    ----------
    shots : per shot, :func:`backlit_samples`
    angles_deg : the turntable angle of each shot (the harp's rotation, degrees, the
        image's orientation: counter-clockwise from +x towards +y)
    width, height : image size
    degree, backlight_degree : :math:`J` and :math:`M` (module docstring)
    lens_harmonics : degree of the lens's non-radial harmonics (0: a radial vignetting only)
    axis : the turntable axis in the image (ideal pixels); default the image centre
    lens : the distortion correction (``undistort_points``) placing samples on the
        harp; default none (identity)

    Returns
    -------
    VignettingFit or FitFailure
        A failure (with the reason) for too few shots or samples, or angles that do
        not separate the back-light from the lens.

    References
    ----------
    .. [1] Goldman, IEEE TPAMI 32(12), 2010.
    """
    if len(shots) != len(angles_deg):
        return FitFailure(f"{len(shots)} shots but {len(angles_deg)} turntable angles")
    if len(shots) < 2:
        return FitFailure("vignetting needs shots at two or more turntable angles (the back-light turns, the lens not)")
    n = sum(len(s.value) for s in shots)
    a = np.array(axis if axis is not None else ((width - 1) / 2.0, (height - 1) / 2.0), np.float64)
    m, y, w = _design(shots, angles_deg, width, height, a, degree, backlight_degree, lens, lens_harmonics)
    if n < 3 * m.shape[1]:
        return FitFailure(f"{n} back-lit samples for {m.shape[1]} parameters: is the sheet between the strings lit?")
    mw = m * w[:, None]
    col = np.sqrt(np.sum(mw * mw, axis=0))
    col[col == 0] = 1.0
    sv = np.linalg.svd(mw / col, compute_uv=False)
    if sv[-1] < MIN_RANK_RATIO * sv[0]:
        return FitFailure(
            "the turntable angles do not separate the back-light from the vignetting "
            f"(angles {', '.join(f'{x:g}' for x in angles_deg)}): add shots at other angles"
        )
    theta, *_ = np.linalg.lstsq(mw / col, y * w, rcond=None)
    theta = theta / col
    res = y - m @ theta
    k = len(shots)
    nl = 2 * len(harmonics(lens_harmonics))
    return VignettingFit(
        width=int(width),
        height=int(height),
        log_v=tuple(float(v) for v in theta[k : k + degree]),
        backlight_degree=int(backlight_degree),
        backlight=tuple(float(v) for v in theta[k + degree + nl :]),
        exposure=tuple(float(v) for v in theta[:k]),
        lens_degree=int(lens_harmonics),
        lens_harmonics=tuple(float(v) for v in theta[k + degree : k + degree + nl]),
        axis=(float(a[0]), float(a[1])),
        residual_rms=float(np.sqrt(np.average(res * res, weights=w * w))),
        n_samples=int(n),
    )


@dataclass(frozen=True)
class LensfunVignetting:
    """Lensfun's ``pa`` vignetting :math:`V = 1 + k_1 r^2 + k_2 r^4 + k_3 r^6` with its conversion error.

    ``error_max`` / ``error_rms``: the largest / RMS relative difference
    :math:`|V_{pa}/V - 1|` over the image.
    """

    k: tuple[float, float, float]
    error_rms: float
    error_max: float

    def factor(self, r: Floats) -> Floats:
        r2 = np.asarray(r, np.float64) ** 2
        k1, k2, k3 = self.k
        return np.asarray(1 + r2 * (k1 + r2 * (k2 + r2 * k3)), np.float64)

    def element_attributes(self, focal: float, aperture: float, distance: float) -> dict[str, str]:
        """The attributes of lensfun's ``<vignetting>`` element."""
        attrs = {"model": "pa", "focal": repr(float(focal)), "aperture": repr(float(aperture))}
        attrs["distance"] = repr(float(distance))
        attrs.update({f"k{i + 1}": repr(float(v)) for i, v in enumerate(self.k)})
        return attrs


def lensfun_pa(fit: VignettingFit, step: float = 8.0, center: tuple[float, float] = (0.0, 0.0)) -> LensfunVignetting:
    """Lensfun's ``pa`` model closest (relative, least squares) to ``fit``'s :math:`V` over the whole image.

    ``center``: the lens's ``<center>`` the file is written with (lensfun applies the
    vignetting about it, :func:`lensfun_radius`); the image centre by default.
    """
    g = image_grid(fit.width, fit.height, step)
    v = fit.relative_illumination(g)
    r2 = lensfun_radius(g, fit.width, fit.height, center) ** 2
    a = np.column_stack([r2, r2**2, r2**3]) / v[:, None]
    k, *_ = np.linalg.lstsq(a, 1.0 / v * (v - 1.0), rcond=None)
    pa = LensfunVignetting((float(k[0]), float(k[1]), float(k[2])), 0.0, 0.0)
    rel = pa.factor(np.sqrt(r2)) / v - 1.0
    return LensfunVignetting(pa.k, float(np.sqrt(np.mean(rel * rel))), float(np.abs(rel).max()))
