"""Common base of every distortion model.

A model maps *distorted* pixel coordinates (what the camera recorded) to
*ideal* (undistorted, pin-hole) pixel coordinates: ``undistort_points``.
Its inverse ``distort_points`` is computed by Newton iterations on the
forward map to an accuracy of ``INVERSE_TOL_PX`` unless a subclass has a
closed form. Coordinates follow the convention of :mod:`pipeline`.
"""

from __future__ import annotations

import inspect
from abc import ABC, abstractmethod
from typing import Any

import numpy as np
from numpy.typing import NDArray

INVERSE_TOL_PX = 1e-9
"""Accuracy in pixels to which :meth:`DistortionModel.distort_points` inverts."""


class DistortionModel(ABC):
    """Base class: a named, serialisable map distorted -> ideal pixels."""

    #: short name written to model files; subclasses override
    name: str = "base"

    # ------------------------------------------------------------------ maps
    @abstractmethod
    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        """Map distorted pixel coordinates ``(N, 2)`` to ideal ones."""

    def distort_points(self, xy: np.ndarray, max_iter: int = 50) -> np.ndarray:
        """Inverse of :meth:`undistort_points`, by Newton iterations (Jacobian by
        central differences).

        Accurate to ``INVERSE_TOL_PX`` (1e-9 px, on ``undistort_points(x)``)
        wherever the forward map is invertible (a point where it does not
        converge within ``max_iter`` iterations is returned as NaN).
        """
        target = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        # start: first-order inverse  x0 = 2 t - U(t)
        x: NDArray[np.float64] = 2 * target - self.undistort_points(target)
        h = 1e-4
        done = np.zeros(len(x), bool)
        for _ in range(max_iter):
            fx = self.undistort_points(x)
            r = fx - target
            done = np.all(np.abs(r) < INVERSE_TOL_PX, axis=1)
            if done.all():
                break
            jx = (self.undistort_points(x + [h, 0]) - self.undistort_points(x - [h, 0])) / (2 * h)
            jy = (self.undistort_points(x + [0, h]) - self.undistort_points(x - [0, h])) / (2 * h)
            a, b, c, d = jx[:, 0], jy[:, 0], jx[:, 1], jy[:, 1]
            det = a * d - b * c
            dx = (d * r[:, 0] - b * r[:, 1]) / det
            dy = (-c * r[:, 0] + a * r[:, 1]) / det
            step = np.stack([dx, dy], axis=1)
            step[done] = 0.0
            x = x - step
        x[~done] = np.nan
        return x

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
