r"""Residual distortion left by a correction (the harp paper's first application).

Given the measured (smoothed, subsampled) string-edge points of harp shots
taken through the lens, and *any* correction :math:`U` (ours, OpenCV's,
lensfun's...), correct the points, normalise by the homography :math:`H`
that maps the 4 corrected image corners back to the original corners (so the
figures are in pixels of an image of the original size, whatever scaling the
correction applies), and measure the straightness :math:`d`, :math:`d_{max}`
of :math:`H(U(p))` (Tang et al. 2012, Sect. 2 and 5).

A correction defined only on part of the distorted image (a maps file or STMap holds the
corrected image ``[0, W-1] x [0, H-1]`` only, which a wide lens's corners fall outside of) is
never extrapolated: :func:`corrected_edges` leaves out the edge points outside its domain
(``OUTSIDE_DOMAIN`` of :meth:`~pipeline.models.base.DistortionModel.undistort_inverse`) and
counts them.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel,
   "High-precision camera distortion measurements with a calibration harp",
   JOSA A 29(10), 2012.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pipeline.models.base import DistortionModel
from pipeline.models.homography import apply_homography
from pipeline.models.inverse import INVERSE_REASONS, OUTSIDE_DOMAIN
from pipeline.normalise import corner_homography


def corrected_points(
    point_sets: Sequence[np.ndarray], correction: DistortionModel, width: int, height: int
) -> list[np.ndarray]:
    """``H(U(p))`` for every edge: corrected and 4-corner normalised points.

    Raises ValueError if the correction is undefined at some edge point.
    """
    h = corner_homography(correction, width, height)
    out = []
    for p in point_sets:
        q = apply_homography(h, correction.undistort_points(np.asarray(p, dtype=np.float64)))
        if not np.all(np.isfinite(q)):
            raise ValueError("the correction is undefined at some edge points (not invertible there)")
        out.append(q)
    return out


MIN_EDGE_POINTS = 3
"""Fewest points an edge keeps after :func:`corrected_edges` leaves some out (else it is left out)."""


@dataclass(frozen=True)
class CorrectedEdges:
    """The corrected, 4-corner normalised edges :func:`corrected_edges` keeps, and what it left out.

    Attributes
    ----------
    points : list of (N_l, 2) arrays
        ``H(U(p))`` of the edges kept (each with at least ``MIN_EDGE_POINTS`` points).
    kept : list of int
        Index in the input of each kept edge.
    n_points : int
        Edge points given.
    n_excluded : int
        Edge points left out: outside the correction's domain, or on an edge left with fewer than
        ``MIN_EDGE_POINTS``.
    """

    points: list[np.ndarray]
    kept: list[int]
    n_points: int
    n_excluded: int


def corrected_edges(
    point_sets: Sequence[np.ndarray], correction: DistortionModel, width: int, height: int
) -> CorrectedEdges:
    """``H(U(p))`` for every edge point inside the correction's domain (see the module docstring).

    Raises ValueError if the correction is undefined at a point *inside* its domain, or the
    4-corner normalisation is undefined.
    """
    h = corner_homography(correction, width, height)
    out, kept, n, n_out = [], [], 0, 0
    for i, p in enumerate(point_sets):
        p = np.asarray(p, dtype=np.float64).reshape(-1, 2)
        inv = correction.undistort_inverse(p)
        n += len(p)
        bad = ~inv.ok & (inv.reason != OUTSIDE_DOMAIN)
        if bad.any():
            why = INVERSE_REASONS[int(inv.reason[bad][0])]
            raise ValueError(f"the correction is undefined at {int(bad.sum())} edge points ({why})")
        keep = inv.ok
        if keep.sum() < MIN_EDGE_POINTS:
            n_out += len(p)
            continue
        n_out += int((~keep).sum())
        out.append(apply_homography(h, inv.points[keep]))
        kept.append(i)
    return CorrectedEdges(points=out, kept=kept, n_points=n, n_excluded=n_out)
