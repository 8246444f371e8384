r"""The board views an operator is asked for: which tilt, where in the image, and why.

A camera matrix is measured from board views that (a) are tilted, each about another axis — a board
facing the camera gives the same image for a focal length :math:`f` at distance :math:`Z` and for
:math:`kf` at :math:`kZ`; tilts about several axes break that tie [1]_ [2]_ — and (b) together put
corners over the whole image, which the principal point and the focal length are measured over (where
no corner is, the camera matrix is extrapolated). :func:`wanted_views` asks for ``n`` views whose tilt
direction turns by :math:`360°/n` from one to the next, each placed off the image centre towards the side
that is tilted away, so that the ``n`` views ring the image: the poses the station's own wedge on the
turntable gives (:mod:`station.session.boards`), asked of a person.

:func:`request_pose` is the board's pose when the operator does as asked (the board kept upright,
tilted ``tilt_deg`` about the image-plane axis perpendicular to ``toward_deg``, its centre seen at
``centre``, at the distance where its width spans ``fill`` of the image): the simulator renders the
board there when it stands in for a camera in front of which a person places the board.

Image directions are angles from the image's +x axis (right) towards +y (down), as pixels are.

References
----------
.. [1] Z. Zhang, "A flexible new technique for camera calibration", IEEE TPAMI 22(11), 2000, sec. 5
   (degenerate configurations: parallel board planes).
.. [2] P. Sturm, S. Maybank, "On plane-based camera calibration: a general algorithm, singularities,
   applications", CVPR 1999.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.board_render import BoardPose

REQUEST_TILT_DEG = 30.0
"""How far each view is tilted (a person holds 30° well; under 10° the focal length is hardly seen)."""
REQUEST_OFFSET = 0.22
"""How far off the image centre each view's centre is asked to be, as a fraction of the image's width
(horizontally) and height (vertically)."""
REQUEST_FILL = 0.5
"""The fraction of the image width an untilted board is asked to span (sets the distance)."""

_COMPASS = ("right", "bottom-right", "bottom", "bottom-left", "left", "top-left", "top", "top-right")


def _compass(deg: float) -> str:
    """``right``, ``bottom-right``, ... of an image direction (degrees from +x towards +y)."""
    return _COMPASS[round((deg % 360.0) / 45.0) % 8]


@dataclass(frozen=True)
class ViewRequest:
    """One board view asked for: view ``index`` (0-based) of ``total``; the board tilted ``tilt_deg`` with
    its side in image direction ``toward_deg`` farther from the camera; its centre seen at ``centre``
    (fractions of the image width and height from the top-left); its untilted width ``fill`` of the image's."""

    index: int
    total: int
    tilt_deg: float
    toward_deg: float
    centre: tuple[float, float]
    fill: float = REQUEST_FILL

    def where(self) -> str:
        """The image region of the board's centre: ``top-left``, ``right``, ``centre``, ..."""
        dx, dy = self.centre[0] - 0.5, self.centre[1] - 0.5
        if math.hypot(dx, dy) < 0.05:
            return "centre"
        return _compass(math.degrees(math.atan2(dy, dx)))

    def instruction(self) -> str:
        """What the operator is asked to do, in one line."""
        side = _compass(self.toward_deg)
        edge = f"{side} edge" if "-" not in side else f"{side} corner"
        return (
            f"board view {self.index + 1} of {self.total}: tilt the board {self.tilt_deg:g}° with its {edge} "
            f"farther from the camera, its centre in the {self.where()} of the image (at x {self.centre[0]:.0%}, "
            f"y {self.centre[1]:.0%}), about {self.fill:.0%} of the image wide, held still"
        )

    def why(self) -> str:
        """Why this view is wanted, in one line."""
        return (
            f"a tilt towards the {_compass(self.toward_deg)} (tilts about several axes separate the focal length "
            f"from the board's distance) and corners in the {self.where()} of the image (the camera matrix is "
            "measured over the image the corners reach)"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "total": self.total,
            "tilt_deg": self.tilt_deg,
            "toward_deg": self.toward_deg,
            "centre": [self.centre[0], self.centre[1]],
            "fill": self.fill,
            "instruction": self.instruction(),
            "why": self.why(),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ViewRequest:
        """Inverse of :meth:`to_dict` (the words are derived again)."""
        c = d["centre"]
        return cls(
            int(d["index"]),
            int(d["total"]),
            float(d["tilt_deg"]),
            float(d["toward_deg"]),
            (float(c[0]), float(c[1])),
            float(d.get("fill", REQUEST_FILL)),
        )


def wanted_views(
    n: int, *, tilt_deg: float = REQUEST_TILT_DEG, offset: float = REQUEST_OFFSET, fill: float = REQUEST_FILL
) -> tuple[ViewRequest, ...]:
    """The ``n`` views to ask for (module docstring): view ``i`` tilted towards image direction
    :math:`360° i / n`, its centre ``offset`` off the image centre that way.

    Raises ValueError for ``n`` < 1 or a tilt outside (0, 80) degrees.
    """
    if int(n) != n or n < 1:
        raise ValueError(f"expected a positive number of views, got {n!r}")
    if not 0.0 < tilt_deg < 80.0:
        raise ValueError(f"expected a tilt in (0, 80) degrees, got {tilt_deg!r}")
    out = []
    for i in range(int(n)):
        toward = 360.0 * i / n
        a = math.radians(toward)
        centre = (round(0.5 + offset * math.cos(a), 4), round(0.5 + offset * math.sin(a), 4))
        out.append(ViewRequest(i, int(n), float(tilt_deg), toward, centre, float(fill)))
    return tuple(out)


def request_pose(
    request: ViewRequest, k: npt.NDArray[np.float64], board_mm: tuple[float, float], width: int, height: int
) -> BoardPose:
    """The board's pose (board mm -> camera mm) when ``request`` is done as asked, for a pin-hole camera
    ``k`` and ``width`` x ``height`` images; ``board_mm`` the board's (width, height).

    The board is turned by :math:`-t` about the image-plane axis :math:`a = (-\\sin φ, \\cos φ, 0)`
    (:math:`t` the tilt, :math:`φ` the direction), which takes the board's side towards :math:`φ` away from
    the camera (:math:`R d = d \\cos t + (d \\times a) \\sin t`, whose :math:`z` is :math:`+\\sin t` for
    :math:`d = (\\cos φ, \\sin φ, 0)`); its centre lies on the ray of pixel ``centre`` at the distance
    :math:`Z = f_x b_w / (\\text{fill} \\cdot w)`.
    """
    import cv2

    t = math.radians(request.tilt_deg)
    phi = math.radians(request.toward_deg)
    axis = np.array([-math.sin(phi), math.cos(phi), 0.0])
    rot, _ = cv2.Rodrigues(-t * axis)
    rot = np.asarray(rot, np.float64)
    bw, bh = float(board_mm[0]), float(board_mm[1])
    z = float(k[0, 0]) * bw / (request.fill * width)
    u = np.array([request.centre[0] * width - 0.5, request.centre[1] * height - 0.5, 1.0])
    tvec = np.linalg.solve(k, u) * z - rot @ np.array([bw / 2.0, bh / 2.0, 0.0])
    rvec, _ = cv2.Rodrigues(rot)
    rv = np.asarray(rvec, np.float64).ravel()
    return BoardPose((float(rv[0]), float(rv[1]), float(rv[2])), (float(tvec[0]), float(tvec[1]), float(tvec[2])))
