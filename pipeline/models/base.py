"""Common base of every distortion model.

A model maps *distorted* pixel coordinates (what the camera recorded) to
*ideal* (undistorted, pin-hole) pixel coordinates: ``undistort_points``.
Its inverse ``distort_points`` is computed by the safeguarded Newton iterations of
:mod:`pipeline.models.inverse` on the forward map to an accuracy of ``INVERSE_TOL_PX``
unless a subclass has a closed form; ``distort_inverse`` also says, per point, why there is
no inverse (NaN) where there is none. Coordinates follow the convention of :mod:`pipeline`.
"""

from __future__ import annotations

import inspect
from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from pipeline.models.inverse import INVERTED, NOT_CONVERGED, Inverse, newton_inverse

INVERSE_TOL_PX = 1e-9
"""Accuracy in pixels to which :meth:`DistortionModel.distort_points` inverts."""


def image_corners(width: int, height: int) -> np.ndarray:
    """The 4 corner pixel centres ``(4, 2)``: top-left, top-right, bottom-right, bottom-left
    (pixel centres at integers; :mod:`pipeline.normalise` normalises by them)."""
    w, h = float(width - 1), float(height - 1)
    return np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]])


def set_pinhole_fields(model: Any, counts: tuple[int, ...], count_text: str, name: str) -> None:
    """Normalise a camera-matrix model's fields in its ``__post_init__`` (a frozen dataclass): ``fx, fy, cx,
    cy`` to floats, ``dist`` to a flat tuple of floats whose length is one of ``counts``.

    Raises
    ------
    ValueError
        ``"{count_text}, got N"`` for another number of coefficients; ``"{name} camera matrix needs fx, fy > 0"``.
    """
    for a in ("fx", "fy", "cx", "cy"):
        object.__setattr__(model, a, float(getattr(model, a)))
    dist = tuple(float(v) for v in np.asarray(model.dist, dtype=np.float64).ravel())
    if len(dist) not in counts:
        raise ValueError(f"{count_text}, got {len(dist)}")
    object.__setattr__(model, "dist", dist)
    if not (model.fx > 0 and model.fy > 0):
        raise ValueError(f"{name} camera matrix needs fx, fy > 0, got {model.fx}, {model.fy}")


class DistortionModel(ABC):
    """Base class: a named, serialisable map distorted -> ideal pixels."""

    #: short name written to model files; subclasses override
    name: str = "base"

    # ------------------------------------------------------------------ maps
    @abstractmethod
    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        """Map distorted pixel coordinates ``(N, 2)`` to ideal ones."""

    def distort_points(self, xy: np.ndarray, max_iter: int = 50) -> np.ndarray:
        """Inverse of :meth:`undistort_points`: :attr:`Inverse.points` of :meth:`distort_inverse`.

        Accurate to ``INVERSE_TOL_PX`` (1e-9 px, on ``undistort_points(x)``) wherever the
        forward map is invertible; NaN elsewhere (:meth:`distort_inverse` says why).
        """
        return self.distort_inverse(xy, max_iter).points

    def distort_inverse(self, xy: np.ndarray, max_iter: int = 50) -> Inverse:
        """:meth:`distort_points` with, per point, why there is no inverse
        (:data:`pipeline.models.inverse.INVERSE_REASONS`).

        Generic: damped Newton (:func:`pipeline.models.inverse.newton_inverse`, Jacobian by
        central differences) from the first-order inverse ``2 t - U(t)``; a model that knows
        the domain where it is invertible overrides this (:class:`~pipeline.models.radial.RadialModel`).
        """
        target = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        with np.errstate(invalid="ignore", over="ignore"):
            start = 2 * target - self.undistort_points(target)
        start = np.where(np.isfinite(start), start, target)
        return newton_inverse(self.undistort_points, target, start, tol=INVERSE_TOL_PX, h=1e-4, max_iter=max_iter)

    def undistort_inverse(self, xy: np.ndarray) -> Inverse:
        """:meth:`undistort_points` with, per point, why it is NaN where it is
        (:data:`pipeline.models.inverse.INVERSE_REASONS`). Generic: NaN is ``NOT_CONVERGED``;
        models whose correction is itself an inverse say more (``OUTSIDE_DOMAIN``: a maps file's
        point outside the corrected image it holds)."""
        u = np.asarray(self.undistort_points(xy), dtype=np.float64).reshape(-1, 2)
        ok = np.all(np.isfinite(u), axis=1)
        return Inverse(points=u, reason=np.where(ok, INVERTED, NOT_CONVERGED).astype(np.int8))

    def normalisation_points(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """``(u, q)``: 4 corrected points and the 4 distorted-image points the 4-corner
        normalisation (:func:`pipeline.normalise.corner_homography`) maps them to: the corrected
        image corners ``U(q_i)`` and the corners ``q_i`` (a maps file overrides this with the
        corners it stores)."""
        q = image_corners(width, height)
        return self.undistort_points(q), q

    def undistortion_maps(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """float32 maps for ``cv2.remap`` producing the corrected image.

        The corrected image has the same size; its pixel ``(x, y)`` (ideal
        coordinates) is read from the distorted image at ``distort_points``.
        Exact per pixel, hence slow for large images (seconds per megapixel):
        :func:`pipeline.undistort_maps.fast_undistortion_maps` (what ``harp
        undistort`` uses) inverts on a coarse grid and interpolates, stating
        its interpolation error.
        """
        yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
        src = self.distort_points(np.stack([xx.ravel(), yy.ravel()], axis=1))
        src = np.nan_to_num(src, nan=-1e6)
        return (
            src[:, 0].reshape(height, width).astype(np.float32),
            src[:, 1].reshape(height, width).astype(np.float32),
        )

    # ------------------------------------------------------------- file form
    @abstractmethod
    def to_dict(self) -> dict[str, Any]:
        """Parameters as plain YAML/JSON-able data, with ``"model": name``."""

    @classmethod
    @abstractmethod
    def from_dict(cls, d: dict[str, Any]) -> DistortionModel:
        """Inverse of :meth:`to_dict`."""


def pinhole_from_matrix(camera_matrix: Any) -> tuple[float, float, float, float]:
    """``(fx, fy, cx, cy)`` of a 3x3 camera matrix without skew.

    Raises
    ------
    ValueError
        For another shape, a skew or a last row other than ``[0 0 1]``.
    """
    k = np.asarray(camera_matrix, dtype=np.float64)
    if k.shape != (3, 3):
        raise ValueError(f"camera matrix must be 3x3, got shape {k.shape}")
    if abs(k[0, 1]) > 1e-12 * abs(k[0, 0]) or np.any(np.abs(k[2] - [0, 0, 1]) > 1e-12):
        raise ValueError("camera matrix with skew or a non-[0 0 1] last row is not supported")
    return k[0, 0], k[1, 1], k[0, 2], k[1, 2]


class CameraMatrixModel(DistortionModel):
    """A model whose ideal pixels are those of a pin-hole camera matrix without skew (``fx, fy, cx, cy``
    fields, normalised by :func:`set_pinhole_fields`): OpenCV's, OpenCV's fisheye and COLMAP's
    ``THIN_PRISM_FISHEYE``."""

    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...]

    @property
    def camera_matrix(self) -> np.ndarray:
        """:math:`K = [[f_x, 0, c_x], [0, f_y, c_y], [0, 0, 1]]` (3x3 float64)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        """The coefficients ``dist`` as a float64 array (OpenCV's ``distCoeffs``)."""
        return np.asarray(self.dist, dtype=np.float64)

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.name,
            "camera_matrix": self.camera_matrix.tolist(),
            "distortion_coefficients": list(self.dist),
        }


class IdentityModel(DistortionModel):
    """The identity map ``x_u = x_d`` (a perfect lens)."""

    name = "identity"

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        return np.asarray(xy, dtype=np.float64).reshape(-1, 2).copy()

    def distort_points(self, xy: np.ndarray, max_iter: int = 50) -> np.ndarray:
        return np.asarray(xy, dtype=np.float64).reshape(-1, 2).copy()

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.name}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> IdentityModel:
        return cls()


def model_types() -> dict[str, type[DistortionModel]]:
    """Every concrete model class by its ``name``: the subclasses of :class:`DistortionModel`
    defined so far (importing :mod:`pipeline.models` defines them all; the first class of a
    name wins)."""
    found: dict[str, type[DistortionModel]] = {}
    todo = list(DistortionModel.__subclasses__())
    while todo:
        cls = todo.pop(0)
        todo.extend(cls.__subclasses__())
        name = getattr(cls, "name", None)
        if isinstance(name, str) and name != DistortionModel.name and not inspect.isabstract(cls):
            found.setdefault(name, cls)
    return found


def model_from_dict(d: Any) -> DistortionModel:
    """Rebuild a model from :meth:`DistortionModel.to_dict` output (ValueError for an unknown name)."""
    types = model_types()
    name = d.get("model") if isinstance(d, dict) else None
    if name not in types:
        raise ValueError(f"unknown distortion model {name!r}; known: {sorted(types)}")
    return types[name].from_dict(d)
