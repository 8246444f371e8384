"""A correction given as per-pixel ``cv2.remap`` maps (an exported maps file or STMap, read back)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.models.base import DistortionModel, image_corners
from pipeline.models.inverse import Inverse, newton_inverse

Array = npt.NDArray[np.float64]

#: accuracy (px) to which :meth:`RemapModel.undistort_points` inverts the bilinear map
REMAP_INVERSE_TOL_PX = 1e-7
#: how far (px) :meth:`RemapModel.undistort_points` reaches beyond the maps' defined area
#: ``[0, W-1] x [0, H-1]``: a point on its border inverts despite the float32 rounding of the maps
REMAP_DOMAIN_MARGIN_PX = 0.01


def _set_maps(model: Any, what: str) -> None:
    """Normalise a maps model's ``map_x`` and ``map_y`` in its ``__post_init__`` (a frozen dataclass): read-only
    float64 arrays of one ``(H, W)`` shape, at least 2 x 2, finite.

    Raises
    ------
    ValueError
        ``"{what} maps must be two equal (H, W) arrays, ..."``; ``"{what} maps hold non-finite values"``.
    """
    mx = np.asarray(model.map_x, dtype=np.float64)
    my = np.asarray(model.map_y, dtype=np.float64)
    if mx.ndim != 2 or mx.shape != my.shape or min(mx.shape) < 2:
        raise ValueError(f"{what} maps must be two equal (H, W) arrays, got {mx.shape} and {my.shape}")
    if not (np.all(np.isfinite(mx)) and np.all(np.isfinite(my))):
        raise ValueError(f"{what} maps hold non-finite values")
    mx.setflags(write=False)
    my.setflags(write=False)
    object.__setattr__(model, "map_x", mx)
    object.__setattr__(model, "map_y", my)


@dataclass(frozen=True, eq=False)
class RemapModel(DistortionModel):
    r"""Correction defined by maps :math:`m_x, m_y` such that ``cv2.remap(img, m_x, m_y)`` corrects ``img``.

    The corrected pixel at integer :math:`(i, j)` (column, row) is read from
    the distorted image at :math:`(m_x[j, i], m_y[j, i])`: the maps sample the
    projection ideal -> distorted at the pixel centres of the output. Between
    pixel centres the projection is the bilinear interpolation of the maps
    (``scipy.ndimage.map_coordinates``, ``order=1``; :meth:`distort_points` extrapolates
    points outside the map from the border cells):

    .. math::
        D(x, y) = \sum_{a, b \in \{0, 1\}} w_a(x)\,w_b(y)\;m[\lfloor y\rfloor + b, \lfloor x\rfloor + a]

    :meth:`distort_points` is :math:`D`; :meth:`undistort_points` (the
    correction) inverts it by damped Newton iterations to ``REMAP_INVERSE_TOL_PX``
    (:func:`pipeline.models.inverse.newton_inverse`) *inside the map's defined area*
    :math:`[0, W-1] \times [0, H-1]` only (to ``REMAP_DOMAIN_MARGIN_PX``): a distorted point whose ideal position lies
    outside (not in the corrected image the maps describe) is NaN, never extrapolated
    (:meth:`undistort_inverse` says why: ``OUTSIDE_DOMAIN``).
    The 4-corner normalisation (:func:`pipeline.normalise.corner_homography`) needs the
    corrected positions of the distorted image's corners, which a wide lens's maps do not
    reach (they hold the corrected image only): ``corners_ideal`` carries them when the maps
    file stores them (harp's exports do: the model's own ``U(q_i)``,
    :meth:`normalisation_points`). Without them the normalisation is that of the maps' own
    corners: their corners ``c_i`` go to where the maps read them, ``m(c_i)``; no point is
    extrapolated either way.

    Parameters: ``map_x``, ``map_y`` (H, W), float32 or float64; ``corners_ideal`` (4, 2) or None,
    the corrected positions of the corners of :func:`pipeline.models.base.image_corners`, in order.
    """

    map_x: Array
    map_y: Array
    corners_ideal: tuple[tuple[float, float], ...] | None = None
    name: str = field(default="remap", init=False, repr=False)

    def __post_init__(self) -> None:
        _set_maps(self, "remap")
        if self.corners_ideal is not None:
            c = np.asarray(self.corners_ideal, dtype=np.float64)
            if c.shape != (4, 2) or not np.all(np.isfinite(c)):
                raise ValueError(f"remap corners_ideal must be 4 finite (x, y) points, got shape {c.shape}")
            object.__setattr__(self, "corners_ideal", tuple((float(x), float(y)) for x, y in c))

    @property
    def width(self) -> int:
        return int(self.map_x.shape[1])

    @property
    def height(self) -> int:
        return int(self.map_x.shape[0])

    def _bilinear(self, m: Array, xy: Array) -> Array:
        x = np.clip(xy[:, 0], 0.0, self.width - 1.0)
        y = np.clip(xy[:, 1], 0.0, self.height - 1.0)
        i = np.minimum(np.floor(x).astype(np.int64), self.width - 2)
        j = np.minimum(np.floor(y).astype(np.int64), self.height - 2)
        # linear extrapolation outside [0, W-1] x [0, H-1] from the border cells
        fx = xy[:, 0] - i
        fy = xy[:, 1] - j
        v00, v10 = m[j, i], m[j, i + 1]
        v01, v11 = m[j + 1, i], m[j + 1, i + 1]
        out: Array = (v00 * (1 - fx) + v10 * fx) * (1 - fy) + (v01 * (1 - fx) + v11 * fx) * fy
        return out

    def distort_points(self, xy: Array, max_iter: int = 50) -> Array:
        """Ideal -> distorted: the bilinear interpolation of the maps."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return np.stack([self._bilinear(self.map_x, xy), self._bilinear(self.map_y, xy)], axis=1)

    def inside(self, xy: Array) -> npt.NDArray[np.bool_]:
        """Where ideal points lie in the map's defined area ``[0, W-1] x [0, H-1]`` (widened by
        ``REMAP_DOMAIN_MARGIN_PX``)."""
        m = REMAP_DOMAIN_MARGIN_PX
        x, y = xy[:, 0], xy[:, 1]
        out: npt.NDArray[np.bool_] = (x >= -m) & (x <= self.width - 1 + m) & (y >= -m) & (y <= self.height - 1 + m)
        return out

    def undistort_points(self, xy: Array, max_iter: int = 50) -> Array:
        """Distorted -> ideal, inside the map's defined area (NaN outside; :meth:`undistort_inverse`)."""
        return self.undistort_inverse(xy, max_iter).points

    def undistort_inverse(self, xy: Array, max_iter: int = 50) -> Inverse:
        """:meth:`undistort_points` with, per point, why there is no inverse (see the class docstring)."""
        target = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        start = np.stack(
            [np.clip(target[:, 0], 0.0, self.width - 1.0), np.clip(target[:, 1], 0.0, self.height - 1.0)], axis=1
        )
        return newton_inverse(
            self.distort_points, target, start, tol=REMAP_INVERSE_TOL_PX, h=0.25, max_iter=max_iter, inside=self.inside
        )

    def normalisation_points(self, width: int, height: int) -> tuple[Array, Array]:
        """The stored corrected corners and the image corners; without them, the maps' own corners
        and where the maps read them (see the class docstring)."""
        q = image_corners(width, height)
        if self.corners_ideal is not None:
            return np.asarray(self.corners_ideal, dtype=np.float64), q
        c = image_corners(self.width, self.height)
        return c, self.distort_points(c)

    def undistortion_maps(self, width: int, height: int) -> tuple[npt.NDArray[Any], npt.NDArray[Any]]:
        """The maps themselves (for their own size)."""
        if (int(width), int(height)) != (self.width, self.height):
            raise ValueError(f"remap maps are {self.width}x{self.height}, asked for {width}x{height}")
        return self.map_x.astype(np.float32), self.map_y.astype(np.float32)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"model": self.name, "map_x": self.map_x.tolist(), "map_y": self.map_y.tolist()}
        if self.corners_ideal is not None:
            d["corners_ideal"] = [list(c) for c in self.corners_ideal]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RemapModel:
        corners = d.get("corners_ideal")
        return cls(
            map_x=np.asarray(d["map_x"], dtype=np.float64),
            map_y=np.asarray(d["map_y"], dtype=np.float64),
            corners_ideal=None if corners is None else tuple((float(x), float(y)) for x, y in corners),
        )


@dataclass(frozen=True, eq=False)
class CorrectionMapModel(DistortionModel):
    r"""Correction sampled at every pixel of the photo: ``map_x[j, i], map_y[j, i]`` is where the photo's
    pixel :math:`(i, j)` lies corrected (a redistort STMap read back).

    :meth:`undistort_points` is the bilinear interpolation of the maps, inside the photo
    :math:`[0, W-1] \times [0, H-1]` (to ``REMAP_DOMAIN_MARGIN_PX``; NaN outside, never extrapolated):

    .. math::
        U(x, y) = \sum_{a, b \in \{0, 1\}} w_a(x)\,w_b(y)\;m[\lfloor y\rfloor + b, \lfloor x\rfloor + a]

    :meth:`distort_points` its inverse by the generic damped Newton iterations of
    :class:`~pipeline.models.base.DistortionModel`.
    """

    map_x: Array
    map_y: Array
    name: str = field(default="correction_map", init=False, repr=False)

    def __post_init__(self) -> None:
        _set_maps(self, "correction")

    def undistort_points(self, xy: Array) -> Array:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        w, h = self.map_x.shape[1], self.map_x.shape[0]
        m = REMAP_DOMAIN_MARGIN_PX
        inside = (xy[:, 0] >= -m) & (xy[:, 0] <= w - 1 + m) & (xy[:, 1] >= -m) & (xy[:, 1] <= h - 1 + m)
        x = np.clip(xy[:, 0], 0.0, w - 1.0)
        y = np.clip(xy[:, 1], 0.0, h - 1.0)
        i = np.minimum(np.floor(x).astype(np.int64), w - 2)
        j = np.minimum(np.floor(y).astype(np.int64), h - 2)
        fx, fy = (x - i)[:, None], (y - j)[:, None]
        out = np.empty((len(xy), 2))
        for k, mp in enumerate((self.map_x, self.map_y)):
            v = (mp[j, i] * (1 - fx[:, 0]) + mp[j, i + 1] * fx[:, 0]) * (1 - fy[:, 0])
            out[:, k] = v + (mp[j + 1, i] * (1 - fx[:, 0]) + mp[j + 1, i + 1] * fx[:, 0]) * fy[:, 0]
        out[~inside] = np.nan
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.name, "map_x": self.map_x.tolist(), "map_y": self.map_y.tolist()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CorrectionMapModel:
        return cls(map_x=np.asarray(d["map_x"], dtype=np.float64), map_y=np.asarray(d["map_y"], dtype=np.float64))
