"""The camera matrix of a profile from board shots: read, find the board, fit with the distortion fixed.

:func:`board_views` reads each shot (:func:`station.inputs.read_image`) and finds the board
(:func:`pipeline.board.detect_board`); a shot that gives no view (unreadable, another size than
the profile's images, no board, too few corners, corners on a line, blurred) is a
:class:`pipeline.board.BoardRejected` with its one-line reason, never an exception.
:func:`measure_intrinsics` then fits the camera matrix with the profile's distortion held fixed
(:func:`pipeline.intrinsics.fit_intrinsics`) and says where it comes from (``source``).
The board shots are taken by a station with :func:`station.session.boards.capture_board_shots`
(``harp intrinsics --capture``) or by a session's camera-matrix stage (the ``intrinsics`` section).
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Sequence
from dataclasses import dataclass

from pipeline.board import MAX_EDGE_WIDTH_PX, MIN_CORNERS, BoardRejected, BoardSpec, BoardView, detect_board
from pipeline.intrinsics import Intrinsics, IntrinsicsFailure, fit_intrinsics
from pipeline.models.base import DistortionModel
from station.errors import InputError
from station.inputs import read_image


@dataclass(frozen=True)
class IntrinsicsRun:
    """What :func:`measure_intrinsics` found: the result (falsy on failure), the views, the rejections."""

    result: Intrinsics | IntrinsicsFailure
    views: tuple[BoardView, ...]
    rejected: tuple[BoardRejected, ...]


def board_views(
    paths: Sequence[str],
    spec: BoardSpec,
    width: int,
    height: int,
    *,
    min_corners: int = MIN_CORNERS,
    max_edge_width_px: float = MAX_EDGE_WIDTH_PX,
) -> tuple[list[BoardView], list[BoardRejected]]:
    """The board views of ``paths`` for ``width`` x ``height`` images, and the shots rejected with why."""
    views: list[BoardView] = []
    rejected: list[BoardRejected] = []
    for path in paths:
        name = str(path)
        try:
            img = read_image(path)
        except InputError as exc:
            msg = str(exc)
            rejected.append(BoardRejected(name, msg[len(name) + 2 :] if msg.startswith(name + ": ") else msg))
            continue
        h, w = img.shape[:2]
        if (w, h) != (int(width), int(height)):
            rejected.append(
                BoardRejected(
                    name, f"{w}x{h} image, the distortion model is for {width}x{height}: another camera mode?"
                )
            )
            continue
        got = detect_board(img, spec, name=name, min_corners=min_corners, max_edge_width_px=max_edge_width_px)
        (views if got else rejected).append(got)  # type: ignore[arg-type]
    return views, rejected


def measure_intrinsics(
    model: DistortionModel,
    width: int,
    height: int,
    paths: Sequence[str],
    spec: BoardSpec,
    *,
    distortion_from: str,
    skew: bool = False,
    min_corners: int = MIN_CORNERS,
    max_edge_width_px: float = MAX_EDGE_WIDTH_PX,
    command: str = "harp intrinsics",
) -> IntrinsicsRun:
    """Board views of ``paths`` and the camera matrix they give with ``model`` fixed.

    ``distortion_from`` names where the distortion comes from (a model file, ``profile #N``),
    recorded in the result's ``source`` with the board, the views and the date.
    """
    views, rejected = board_views(
        paths, spec, width, height, min_corners=min_corners, max_edge_width_px=max_edge_width_px
    )
    when = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    source = (
        f"{command}, {len(views)} {spec.kind} views of {spec.label} ({len(rejected)} rejected), "
        f"distortion held fixed from {distortion_from}, {when}"
    )
    result = fit_intrinsics(views, model, width, height, skew=skew, source=source)
    return IntrinsicsRun(result=result, views=tuple(views), rejected=tuple(rejected))
