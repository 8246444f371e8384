"""The camera matrix of a profile from board shots: read, find the board, fit with the distortion fixed.

:func:`board_views` reads each shot (:func:`station.inputs.read_image`) and finds the board
(:func:`pipeline.board.detect_board`); a shot that gives no view (unreadable, another size than
the profile's images, no board, too few corners, corners on a line, blurred) is a
:class:`pipeline.board.BoardRejected` with its one-line reason, never an exception.
:func:`measure_intrinsics` then fits the camera matrix with the profile's distortion held fixed
(:func:`pipeline.intrinsics.fit_intrinsics`) and says where it comes from (``source``).
:func:`capture_board_shots` takes the board shots with a station (``harp intrinsics --capture``): the
board on a tilted wedge on the turntable, one view per turntable angle.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

from pipeline.board import MAX_EDGE_WIDTH_PX, MIN_CORNERS, BoardRejected, BoardSpec, BoardView, detect_board
from pipeline.intrinsics import Intrinsics, IntrinsicsFailure, fit_intrinsics
from pipeline.models.base import DistortionModel
from station.files import atomic_write_bytes
from station.inputs import InputError, read_image
from station.session.frame_files import encode_frame


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


DEFAULT_BOARD_ANGLES = (0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0)
"""Turntable angles of the board views (a board on a tilted wedge on the turntable: each angle turns
the tilt's direction, so the views are tilted every way with one axis)."""


def capture_board_shots(
    config: Any,
    spec: BoardSpec,
    out_dir: str | Path,
    *,
    angles: Sequence[float] = DEFAULT_BOARD_ANGLES,
    focus: float | None = None,
    note: Callable[[str], None] = lambda _text: None,
) -> list[str]:
    """Board shots taken by the configured station: the board on a tilted wedge on the turntable
    (in place of the harp), one frame at each turntable angle, at ``focus`` (locked; None: as the
    camera is), saved losslessly into ``out_dir`` (``board-<angle>.png``); their paths.

    A simulated station (a ``simulation`` section, the ``sim`` camera) is told the board is in front
    of it (the camera's ``board`` setting): it renders the board through its lens
    (:meth:`drivers.sim.camera.SimulatedCamera.board_pose`). Raises ConfigError / OSError (one line)."""
    import dataclasses

    from station.session.devices import open_station  # defers drivers

    cam = config.station.camera
    if config.simulation is not None and cam.driver == "sim":
        cam = dataclasses.replace(cam, settings=MappingProxyType({**dict(cam.settings), "board": spec.label}))
        config = dataclasses.replace(config, station=dataclasses.replace(config.station, camera=cam))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: list[str] = []
    with open_station(config, check=False) as (camera, turntable):
        camera.set_exposure(config.capture.exposure_us)
        if focus is not None:
            camera.lock_focus(focus)
        for a in angles:
            got = turntable.move_to(float(a), timeout=config.capture.move_timeout_s)
            frame = camera.capture(timeout=config.capture.timeout_s)
            p = out / f"board-{a:g}.png"
            atomic_write_bytes(p, encode_frame(frame.image))  # lossless PNG at the camera's depth
            paths.append(str(p))
            note(f"board view at turntable {got:.1f} deg: {p}")
    return paths
