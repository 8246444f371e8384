"""A correction followed by a plane homography (e.g. the 4-corner normalisation)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.models.base import DistortionModel, model_from_dict


def apply_homography(h: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Apply the 3x3 homography ``h`` to points ``(N, 2)`` (pixels)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    h = np.asarray(h, dtype=np.float64)
    w = h[2, 0] * xy[:, 0] + h[2, 1] * xy[:, 1] + h[2, 2]
    return np.stack(
        [
            (h[0, 0] * xy[:, 0] + h[0, 1] * xy[:, 1] + h[0, 2]) / w,
            (h[1, 0] * xy[:, 0] + h[1, 1] * xy[:, 1] + h[1, 2]) / w,
        ],
        axis=1,
    )


@dataclass(frozen=True)
class HomographyModel(DistortionModel):
    r"""A base correction followed by a homography: :math:`x_u = H(U_{base}(x_d))`.

    Lines stay lines under a homography, so composing a correction with one
    changes none of its straightness; it only changes which of the
    (homography-)equivalent corrections is reported. Used to normalise a
    correction by the homography that maps its 4 corrected image corners back
    to the original corners (Tang et al. 2012, Sect. 2).

    Parameters: ``base`` (any model, stored as its dict) and ``homography``
    (3x3, row-major, ``H[2,2] = 1``).
    """

    base: DistortionModel
    homography: tuple[tuple[float, float, float], ...]
    name: str = field(default="homography", init=False, repr=False)

    def __post_init__(self) -> None:
        h = np.asarray(self.homography, dtype=np.float64)
        if h.shape != (3, 3) or not np.all(np.isfinite(h)) or abs(np.linalg.det(h)) < 1e-15:
            raise ValueError("HomographyModel needs a finite, invertible 3x3 homography")
        h = h / h[2, 2]
        object.__setattr__(self, "homography", tuple(tuple(float(v) for v in row) for row in h))

    @property
    def matrix(self) -> np.ndarray:
        return np.asarray(self.homography, dtype=np.float64)

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        return apply_homography(self.matrix, self.base.undistort_points(xy))

    def distort_points(self, xy: np.ndarray, max_iter: int = 50) -> np.ndarray:
        return self.base.distort_points(apply_homography(np.linalg.inv(self.matrix), xy), max_iter)

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.name, "base": self.base.to_dict(), "homography": [list(r) for r in self.homography]}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> HomographyModel:
        return cls(base=model_from_dict(d["base"]), homography=tuple(tuple(r) for r in d["homography"]))
