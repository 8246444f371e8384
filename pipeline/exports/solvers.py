"""What an OpenCV pin-hole or fisheye export needs of its consumer's point solver.

OpenCV's maps (``cv2.initUndistortRectifyMap``, ``cv2.fisheye.initUndistortRectifyMap``)
evaluate the projection in closed form and hold the conversion error only. Correcting
*points* inverts the projection iteratively: ``cv2.undistortPoints`` with its default
criteria (5 iterations; it is what ROS ``image_geometry``'s ``rectifyPoint`` calls) and
``cv2.fisheye.undistortPoints`` with its default (10 iterations, eps 1e-8) stop before
convergence on a wide lens (2.3 px on a 93 deg lens, 24 px on a 115 deg one through the
pin-hole model). :func:`solver_need` measures, with the real cv2 on a grid over the image,
what the default solver leaves (against the export's exact inverse, and against the harp
correction modulo homography: what the consumer sees) and how many iterations make it exact
to :data:`SOLVER_TOL_PX`; the export states it in the file, and ``--format auto`` judges the
candidates by it.

References
----------
.. [1] OpenCV, ``cv::undistortPoints`` and ``cv::fisheye::undistortPoints`` (calib3d),
   https://docs.opencv.org/master/d9/d0c/group__calib3d.html
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from pipeline.exports.conversion_error import image_grid
from pipeline.models.base import DistortionModel
from pipeline.models.homography import apply_homography
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel
from pipeline.normalise import fit_homography

Array = npt.NDArray[np.float64]

SOLVER_TOL_PX = 1e-3
"""An iterated solver is *exact* when it is within this of the export's exact inverse everywhere."""

ITERATION_STEPS = (5, 10, 20, 50, 100, 200, 500, 1000, 2000)
"""Iteration counts tried, in order, for the least that makes the solver exact."""

SOLVER_GRID_LONG = 61
"""Grid (points along the long side, borders included) on which the solvers are compared."""


@dataclass(frozen=True)
class SolverNeed:
    """What the consumer's iterative point solver does with an export.

    Attributes
    ----------
    solver : str
        ``"cv2.undistortPoints"`` (pin-hole) or ``"cv2.fisheye.undistortPoints"``.
    default_max_px, default_rms_px : float
        Max and RMS over the image of ``|default solver - exact inverse|`` (px).
    iterations : int or None
        Least of :data:`ITERATION_STEPS` with which the solver is within :data:`SOLVER_TOL_PX`
        of the exact inverse everywhere (None: not even with the last).
    consumer_max_px, consumer_rms_px : float
        The default solver's points against the harp correction, modulo the best homography
        (px): what a consumer correcting points with the default sees.
    """

    solver: str
    default_max_px: float
    default_rms_px: float
    iterations: int | None
    consumer_max_px: float
    consumer_rms_px: float

    def lines(self, ros: bool = False) -> list[str]:
        """The statement for the file's comments (``ros``: name ROS's rectifyPoint too)."""
        who = f"{self.solver} with its default criteria" + (
            " (what ROS image_geometry's rectifyPoint calls)" if ros else ""
        )
        first = (
            f"points: {who} leaves up to {self.default_max_px:.4f} px (RMS {self.default_rms_px:.4f} px) on this "
            f"lens against the exact inverse; with it the correction is off the harp's by up to "
            f"{self.consumer_max_px:.4f} px modulo homography"
        )
        if self.iterations is None:
            need = f"no iteration count up to {ITERATION_STEPS[-1]} makes it exact: correct points with the maps"
        else:
            call = (
                "cv2.undistortPointsIter (OpenCV 4) or cv2.undistortPoints(..., criteria=) (OpenCV 5)"
                if self.solver == "cv2.undistortPoints"
                else "cv2.fisheye.undistortPoints(..., criteria=)"
            )
            need = f"it is exact to {SOLVER_TOL_PX:g} px with criteria (COUNT + EPS, {self.iterations}, 1e-12): {call}"
        return [first, f"{need}; the undistortion maps (initUndistortRectifyMap) are closed form and need no solver"]


def _criteria(n: int) -> tuple[int, int, float]:
    return (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, int(n), 1e-12)


def _solve(model: OpenCVModel | OpenCVFisheyeModel, q: Array, iterations: int | None) -> Array:
    """The consumer's solver on distorted pixels ``q`` (None: its default criteria), in pixels of K."""
    k, d = model.camera_matrix, model.dist_coeffs
    src = np.ascontiguousarray(q.reshape(-1, 1, 2))
    if isinstance(model, OpenCVFisheyeModel):
        if iterations is None:
            out = cv2.fisheye.undistortPoints(src, k, d, R=np.eye(3), P=k)
        else:
            out = cv2.fisheye.undistortPoints(src, k, d, R=np.eye(3), P=k, criteria=_criteria(iterations))
    elif iterations is None:
        out = cv2.undistortPoints(src, k, d, P=k)
    elif hasattr(cv2, "undistortPointsIter"):  # OpenCV 4
        out = cv2.undistortPointsIter(src, k, d, None, k, _criteria(iterations))
    else:  # OpenCV 5 takes the criteria directly
        out = cv2.undistortPoints(src, k, d, R=None, P=k, criteria=_criteria(iterations))
    return np.asarray(out, dtype=np.float64).reshape(-1, 2)


def solver_need(ours: DistortionModel, theirs: OpenCVModel | OpenCVFisheyeModel, width: int, height: int) -> SolverNeed:
    """Measure the consumer's default point solver on ``theirs`` over the image (see module docstring)."""
    q = image_grid(width, height, SOLVER_GRID_LONG)
    exact = theirs.undistort_points(q)
    mine = ours.undistort_points(q)
    ok = np.all(np.isfinite(exact), axis=1) & np.all(np.isfinite(mine), axis=1)
    q, exact, mine = q[ok], exact[ok], mine[ok]

    def gap(iterations: int | None) -> Array:
        p = _solve(theirs, q, iterations)
        e = np.linalg.norm(p - exact, axis=1)
        return np.where(np.isfinite(e), e, np.inf)

    e0 = gap(None)
    iterations = next((n for n in ITERATION_STEPS if float(gap(n).max()) <= SOLVER_TOL_PX), None)
    p0 = _solve(theirs, q, None)
    good = np.all(np.isfinite(p0), axis=1)
    if good.sum() >= 4:
        h = fit_homography(p0[good], mine[good])
        c = np.linalg.norm(apply_homography(h, p0[good]) - mine[good], axis=1)
        c = np.concatenate([c, np.full(int(np.sum(~good)), np.inf)])
    else:
        c = np.full(len(q), np.inf)
    return SolverNeed(
        solver="cv2.fisheye.undistortPoints" if isinstance(theirs, OpenCVFisheyeModel) else "cv2.undistortPoints",
        default_max_px=float(e0.max()),
        default_rms_px=float(np.sqrt(np.mean(e0**2))),
        iterations=iterations,
        consumer_max_px=float(c.max()),
        consumer_rms_px=float(np.sqrt(np.mean(c**2))),
    )
