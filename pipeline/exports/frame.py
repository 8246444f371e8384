"""What an export's file says about the corrected image: ``R`` and ``newK`` that reproduce harp undistort's.

Every pin-hole and fisheye export (OpenCV, ROS, mrcal and the formats built on the same models)
writes, besides its own ``K`` and distortion, the rectification ``R`` (a rotation) and the corrected
image's camera matrix ``newK`` and size with which its consumer writes the same corrected image as
``harp undistort`` with the same frame options (:mod:`pipeline.corrected_frame`), to within the
export's conversion error: ``cv2.initUndistortRectifyMap(K, D, R, newK, size)``
(``cv2.fisheye.initUndistortRectifyMap`` for a fisheye file), ROS image_geometry with the file's
``rectification_matrix`` and ``projection_matrix``, or for points ``cv2.undistortPoints(p, K, D, R=R, P=newK)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.corrected_frame import CorrectedFrame, corrected_frame, rectification
from pipeline.corrected_frame import FrameChoice as FrameChoice
from pipeline.exports.conversion_error import ideal_homography
from pipeline.models.base import DistortionModel

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class FrameStatement:
    """``R`` (3x3, near identity), ``new_k`` (3x3) and the corrected image ``frame`` of one export."""

    rotation: Array
    new_k: Array
    frame: CorrectedFrame
    choice: FrameChoice

    @property
    def size(self) -> tuple[int, int]:
        return self.frame.width, self.frame.height

    def lines(self, fisheye: bool = False) -> list[str]:
        """Comment lines: what the file's R and newK are for."""
        fn = "cv2.fisheye.initUndistortRectifyMap" if fisheye else "cv2.initUndistortRectifyMap"
        w, h = self.size
        return [
            f"corrected image = harp undistort's with {self.choice.describe()}: {self.frame.describe()}",
            f"it is written by {fn}(K, D, R, newK, ({w}, {h})) with this file's rectification R and new camera "
            "matrix newK (ROS: rectification_matrix, projection_matrix), to within the conversion error; "
            "newK = K gives another frame",
        ]

    def ray_lines(self, unproject: str) -> list[str]:
        """Comment lines for a format that holds no ``R``/``newK`` fields: both written out, and what
        a point ``(x, y)`` of the consumer's ``unproject`` (normalised image plane) is in the corrected image."""
        return [
            f"corrected image = harp undistort's with {self.choice.describe()}: {self.frame.describe()}",
            f"a point (x, y) of {unproject} is at newK @ R @ (x, y, 1) in it (harp pixels: the centre of "
            "the top-left pixel at 0, 0), to within the conversion error",
            f"R = {_rows(self.rotation)}",
            f"newK = {_rows(self.new_k)}",
        ]


def _rows(m: Array) -> str:
    return "[" + ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in m) + "]"


def frame_statement(
    ours: DistortionModel,
    theirs: DistortionModel,
    camera_matrix: Array,
    width: int,
    height: int,
    choice: FrameChoice,
    focal: float,
) -> FrameStatement:
    """The ``R`` and ``newK`` with which ``theirs`` (an export of ``ours``, camera matrix ``camera_matrix``)
    writes ``ours``' corrected image as ``choice`` asks (ValueError when that frame is undefined)."""
    frame = corrected_frame(ours, width, height, choice)
    rot, new_k = rectification(frame, ideal_homography(ours, theirs, width, height), camera_matrix, focal)
    return FrameStatement(rot, new_k, frame, choice)
