"""Lensfun's radial distortion models (poly3, poly5, ptlens) as a harp :class:`DistortionModel`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.models.base import DistortionModel

Floats = NDArray[np.float64]

#: accuracy (px) to which :meth:`LensfunModel.undistort_points` inverts the radial polynomial
LENSFUN_INVERSE_TOL_PX = 1e-9
LENSFUN_TERMS = {"poly3": ("k1",), "poly5": ("k1", "k2"), "ptlens": ("a", "b", "c")}

LENSFUN_FISHEYE_TYPES: tuple[str, ...] = ("fisheye", "equisolid", "stereographic", "orthographic", "fisheye_thoby")
"""The lensfun lens ``<type>`` values of fisheye projections this model holds (lensfun's database names)."""

LENSFUN_TYPES: tuple[str, ...] = ("rectilinear", *LENSFUN_FISHEYE_TYPES)

FULL_FRAME_HALF_DIAGONAL_MM = float(np.hypot(36.0, 24.0) / 2.0)
"""Half the 35 mm frame's diagonal, lensfun's reference for the focal length of a geometry conversion."""


def fisheye_radius(lens_type: str, f: Floats | float, theta: Floats) -> Floats:
    """Image radius of a ray at ``theta`` (rad) from the axis, focal ``f``: lensfun's fisheye projections."""
    if lens_type == "fisheye":
        return np.asarray(f * theta, dtype=np.float64)
    if lens_type == "equisolid":
        return np.asarray(2 * f * np.sin(theta / 2), dtype=np.float64)
    if lens_type == "stereographic":
        return np.asarray(2 * f * np.tan(theta / 2), dtype=np.float64)
    if lens_type == "orthographic":
        return np.asarray(f * np.sin(theta), dtype=np.float64)
    if lens_type == "fisheye_thoby":
        return np.asarray(1.47 * f * np.sin(0.713 * theta), dtype=np.float64)
    raise ValueError(f"not a lensfun fisheye type: {lens_type!r}")


def fisheye_angle(lens_type: str, f: float, r: Floats) -> Floats:
    """The inverse of :func:`fisheye_radius`: the ray angle (rad) of image radius ``r``; NaN beyond the projection."""
    with np.errstate(invalid="ignore"):
        if lens_type == "fisheye":
            return np.asarray(r / f, dtype=np.float64)
        if lens_type == "equisolid":
            return np.asarray(2 * np.arcsin(r / (2 * f)), dtype=np.float64)
        if lens_type == "stereographic":
            return np.asarray(2 * np.arctan(r / (2 * f)), dtype=np.float64)
        if lens_type == "orthographic":
            return np.asarray(np.arcsin(r / f), dtype=np.float64)
        if lens_type == "fisheye_thoby":
            return np.asarray(np.arcsin(r / (1.47 * f)) / 0.713, dtype=np.float64)
    raise ValueError(f"not a lensfun fisheye type: {lens_type!r}")


def geometry_focal(focal_mm: float, crop_factor: float, aspect_ratio: float) -> float:
    r"""The focal length of lensfun's geometry conversion in lensfun normalised units.

    :math:`f_n = F\,c\,\sqrt{a^2 + 1} / (D_{35}/2)`: ``focal_mm`` :math:`F` (the calibration's
    ``focal``; lensfun 0.3 reads no ``<real-focal>`` or ``<field-of-view>``), the crop factor
    :math:`c`, the lens' aspect ratio :math:`a` and half the 35 mm diagonal :math:`D_{35}/2` —
    lensfun's ``focal / NormalizedInMillimeters`` (``lfModifier`` constructor). Checked with
    lensfun itself (through lensfunpy) for every fisheye type.
    """
    return float(focal_mm * crop_factor * np.sqrt(aspect_ratio**2 + 1) / FULL_FRAME_HALF_DIAGONAL_MM)


@dataclass(frozen=True)
class LensfunModel(DistortionModel):
    r"""A lensfun distortion calibration (``<distortion model=.. />``) for one image size.

    Lensfun's models describe the projection ideal -> distorted as a radial
    polynomial in *lensfun normalised coordinates*: origin at the image
    centre (plus the lens' optional ``<center x y>`` offset), unit length
    half the shorter image side measured between pixel centres,
    :math:`s = \min(W-1, H-1)/(2\kappa)` (lensfun's ``NormScale = 2\kappa/size``).
    :math:`\kappa` (``coord_scale``) is lensfun's coordinate correction for a
    calibration made on a sensor of another aspect ratio
    :math:`\kappa = \sqrt{a_c^2+1}/\sqrt{a_i^2+1}` (calibration and image
    aspect ratios ``>= 1``, same crop factor assumed); 1 when they agree. With
    :math:`R_u` the normalised radius of an ideal point:

    .. math::
        \text{poly3:}\quad & R_d = R_u (1 - k_1 + k_1 R_u^2) \\
        \text{poly5:}\quad & R_d = R_u (1 + k_1 R_u^2 + k_2 R_u^4) \\
        \text{ptlens:}\quad & R_d = R_u (a R_u^3 + b R_u^2 + c R_u + 1 - a - b - c)

    and the distorted point lies on the same ray from the centre at radius
    :math:`R_d`. A fisheye lens (``lens_type`` one of :data:`LENSFUN_FISHEYE_TYPES`, lensfun's
    ``<type>``) is corrected to its ideal projection and converted to rectilinear by lensfun's
    geometry step, applied first: an ideal rectilinear point at normalised radius :math:`\rho`
    is the ray :math:`\theta = \arctan(\rho/f_n)`, seen by the ideal fisheye at
    :math:`R_u = P(f_n, \theta)` (:func:`fisheye_radius`: :math:`f\theta`, :math:`2f\sin(\theta/2)`,
    :math:`2f\tan(\theta/2)`, :math:`f\sin\theta`, :math:`1.47 f\sin(0.713\,\theta)`), which
    the polynomial then distorts; :math:`f_n` is ``geometry_focal`` (:func:`geometry_focal`). Pixels: :math:`x = x_0 + s\,\xi`, :math:`x_0 = (W-1)/2 + s\,c_x`
    (likewise for y). :meth:`distort_points` is the closed form;
    :meth:`undistort_points` (the correction lensfun applies) solves the
    radial polynomial by 1-D Newton iterations to ``LENSFUN_INVERSE_TOL_PX``
    (1e-9 px; NaN where the polynomial is not monotonic up to that radius).
    Checked against lensfun 0.3.4 itself (``lfModifier::ApplyGeometryDistortion``
    through lensfunpy, per pixel): agreement to 6e-5 px, lensfun's float32
    precision, for all three models, with and without a ``<center>`` offset.
    Parameter order: ``terms`` as in ``LENSFUN_TERMS[kind]``.

    References
    ----------
    .. [1] Lensfun, "lfDistortionModel" and the lens database format,
       https://lensfun.github.io/manual/latest/ ; ``lfModifier`` constructor
       (``libs/lensfun/modifier.cpp``) for the coordinate normalisation.
    .. [2] H. Dersch, Panorama Tools ("ptlens" model).
    """

    kind: str
    terms: tuple[float, ...]
    width: int
    height: int
    center: tuple[float, float] = (0.0, 0.0)
    coord_scale: float = 1.0
    lens_type: str = "rectilinear"
    geometry_focal: float = 0.0
    name: str = field(default="lensfun", init=False, repr=False)

    def __post_init__(self) -> None:
        if self.kind not in LENSFUN_TERMS:
            raise ValueError(f"unsupported lensfun distortion model {self.kind!r}; supported: {sorted(LENSFUN_TERMS)}")
        terms = tuple(float(v) for v in self.terms)
        if len(terms) != len(LENSFUN_TERMS[self.kind]):
            raise ValueError(f"lensfun {self.kind} needs terms {LENSFUN_TERMS[self.kind]}, got {len(terms)} values")
        object.__setattr__(self, "terms", terms)
        object.__setattr__(self, "center", tuple(float(v) for v in self.center))
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        object.__setattr__(self, "coord_scale", float(self.coord_scale))
        if not self.coord_scale > 0:
            raise ValueError(f"lensfun coord_scale must be > 0, got {self.coord_scale}")
        if self.lens_type not in LENSFUN_TYPES:
            raise ValueError(f"unsupported lensfun lens type {self.lens_type!r}; supported: {', '.join(LENSFUN_TYPES)}")
        object.__setattr__(self, "geometry_focal", float(self.geometry_focal))
        if self.lens_type != "rectilinear" and not (np.isfinite(self.geometry_focal) and self.geometry_focal > 0):
            raise ValueError(f"a lensfun {self.lens_type} lens needs its geometry focal > 0, got {self.geometry_focal}")
        if self.width < 2 or self.height < 2:
            raise ValueError(f"lensfun model needs an image size >= 2x2, got {self.width}x{self.height}")

    # --------------------------------------------------------- coordinates
    @property
    def unit(self) -> float:
        """Pixels per lensfun normalised unit: half the shorter side between pixel centres."""
        return min(self.width - 1, self.height - 1) / 2.0 / self.coord_scale

    @property
    def origin(self) -> tuple[float, float]:
        """Pixel position of the lensfun distortion centre."""
        s = self.unit
        return ((self.width - 1) / 2.0 + s * self.center[0], (self.height - 1) / 2.0 + s * self.center[1])

    def radial_factor(self, ru: Floats) -> Floats:
        """``R_d / R_u`` as a function of the ideal normalised radius."""
        t = self.terms
        if self.kind == "poly3":
            return 1 - t[0] + t[0] * ru**2
        if self.kind == "poly5":
            r2 = ru**2
            return 1 + t[0] * r2 + t[1] * r2 * r2
        a, b, c = t
        return ((a * ru + b) * ru + c) * ru + 1 - a - b - c

    def _radial_derivative(self, ru: Floats) -> Floats:
        """d R_d / d R_u."""
        t = self.terms
        if self.kind == "poly3":
            return 1 - t[0] + 3 * t[0] * ru**2
        if self.kind == "poly5":
            r2 = ru**2
            return 1 + 3 * t[0] * r2 + 5 * t[1] * r2 * r2
        a, b, c = t
        return ((4 * a * ru + 3 * b) * ru + 2 * c) * ru + 1 - a - b - c

    # ---------------------------------------------------------------- maps
    def _rect_to_fisheye(self, rho: Floats) -> Floats:
        """Normalised radius of the ideal fisheye point of rectilinear radius ``rho`` (the geometry step)."""
        f = self.geometry_focal
        return fisheye_radius(self.lens_type, f, np.arctan(rho / f))

    def _fisheye_to_rect(self, r: Floats) -> Floats:
        """The inverse of :meth:`_rect_to_fisheye`; NaN for rays at or beyond 90 degrees."""
        f = self.geometry_focal
        theta = fisheye_angle(self.lens_type, f, r)
        with np.errstate(invalid="ignore"):
            return np.where(
                (theta >= 0) & (theta < np.pi / 2), f * np.tan(np.clip(theta, 0, np.pi / 2 - 1e-12)), np.nan
            )

    def distort_points(self, xy: np.ndarray, max_iter: int = 50) -> np.ndarray:
        """Closed form ideal -> distorted pixels (the geometry step first for a fisheye type)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        x0, y0 = self.origin
        s = self.unit
        xi, eta = (xy[:, 0] - x0) / s, (xy[:, 1] - y0) / s
        rho = np.hypot(xi, eta)
        if self.lens_type != "rectilinear":
            ru = self._rect_to_fisheye(rho)
            with np.errstate(divide="ignore", invalid="ignore"):
                g = np.where(rho > 0, ru / rho, self._rect_to_fisheye(np.array([1e-9]))[0] / 1e-9)
            xi, eta, rho = xi * g, eta * g, ru
        f = self.radial_factor(rho)
        return np.stack([x0 + s * f * xi, y0 + s * f * eta], axis=1)

    def undistort_points(self, xy: np.ndarray, max_iter: int = 50) -> np.ndarray:
        """Distorted -> ideal pixels, 1-D Newton on the radius to 1e-9 px (then the inverse geometry step)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        x0, y0 = self.origin
        s = self.unit
        xi, eta = (xy[:, 0] - x0) / s, (xy[:, 1] - y0) / s
        rd = np.hypot(xi, eta)
        ru = rd.copy()
        tol = LENSFUN_INVERSE_TOL_PX / s
        done = np.zeros(len(ru), bool)
        for _ in range(max_iter):
            g = ru * self.radial_factor(ru) - rd
            done = np.abs(g) < tol
            if done.all():
                break
            with np.errstate(divide="ignore", invalid="ignore"):
                ru = np.where(done, ru, ru - g / self._radial_derivative(ru))
        ok = done & (self._radial_derivative(ru) > 0) & (ru >= 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(rd > 0, ru / rd, 1.0 / self.radial_factor(np.zeros_like(rd)))
            if self.lens_type != "rectilinear":
                small = 1e-9
                at0 = self._fisheye_to_rect(np.array([small]))[0] / small
                ratio = ratio * np.where(ru > 0, self._fisheye_to_rect(ru) / ru, at0)
        ratio[~ok] = np.nan
        return np.stack([x0 + s * ratio * xi, y0 + s * ratio * eta], axis=1)

    # ----------------------------------------------------------- file form
    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.name,
            "kind": self.kind,
            "terms": dict(zip(LENSFUN_TERMS[self.kind], self.terms)),
            "image_size": [self.width, self.height],
            "center": list(self.center),
            "coord_scale": self.coord_scale,
            **(
                {"lens_type": self.lens_type, "geometry_focal": self.geometry_focal}
                if self.lens_type != "rectilinear"
                else {}
            ),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> LensfunModel:
        kind = d["kind"]
        if kind not in LENSFUN_TERMS:
            raise ValueError(f"unsupported lensfun distortion model {kind!r}")
        terms = d["terms"]
        if isinstance(terms, dict):
            terms = [terms[k] for k in LENSFUN_TERMS[kind]]
        w, h = d["image_size"]
        return cls(
            kind=kind,
            terms=tuple(terms),
            width=w,
            height=h,
            center=tuple(d.get("center", (0.0, 0.0))),
            coord_scale=float(d.get("coord_scale", 1.0)),
            lens_type=str(d.get("lens_type", "rectilinear")),
            geometry_focal=float(d.get("geometry_focal", 0.0)),
        )
