"""Board views taken by a station: the board on a tilted wedge on the turntable, one view per turntable
angle, at a locked focus. The one capture code of ``harp intrinsics --capture``
(:func:`capture_board_shots`) and of a session's camera-matrix stage (the ``intrinsics`` section:
:class:`station.session.plan.BoardView`, performed by :mod:`station.session.executor`).

A camera the station can show the board (:class:`drivers.protocols.BoardScene`: the simulator, which
renders the board through its lens with its true camera matrix) is shown it for each board frame and
the harp again after it; any other camera photographs whatever is on the turntable (a board placed by
hand). Frames are saved losslessly at the camera's depth (:func:`station.session.frame_files.encode_frame`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from drivers.protocols import BoardScene, Frame
from pipeline.board import BoardSpec
from station.config import Config
from station.config.schema import DEFAULT_BOARD_ANGLES
from station.files import atomic_write_bytes
from station.session.devices import open_station
from station.session.frame_files import encode_frame


def board_frame(camera: Any, spec: BoardSpec, *, timeout: float) -> Frame:
    """One frame of the board ``spec`` (a :class:`~drivers.protocols.BoardScene` camera is shown it for
    this frame only)."""
    shown = isinstance(camera, BoardScene)
    if shown:
        camera.show_board(spec.label)
    try:
        return camera.capture(timeout=timeout)
    finally:
        if shown:
            camera.show_board(None)


def save_board_frame(path: str | Path, frame: Frame) -> str:
    """Write ``frame``'s image losslessly (PNG at the camera's depth) at ``path``, atomically; its sha256."""
    data = encode_frame(frame.image)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(Path(path), data)
    return hashlib.sha256(data).hexdigest()


def capture_board_shots(
    config: Config,
    spec: BoardSpec,
    out_dir: str | Path,
    *,
    angles: Sequence[float] = DEFAULT_BOARD_ANGLES,
    focus: float | None = None,
    note: Callable[[str], None] = lambda _text: None,
) -> list[str]:
    """Board shots taken by the configured station, one at each turntable angle, at ``focus`` (locked;
    None: as the camera is), saved into ``out_dir`` (``board-<angle>.png``); their paths.
    Raises ConfigError / DriverError / OSError (one line)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: list[str] = []
    with open_station(config, check=False) as (camera, turntable):
        camera.set_exposure(config.capture.exposure_us)
        if focus is not None:
            camera.lock_focus(focus)
        for a in angles:
            got = turntable.move_to(float(a), timeout=config.capture.move_timeout_s)
            frame = board_frame(camera, spec, timeout=config.capture.timeout_s)
            p = out / f"board-{a:g}.png"
            save_board_frame(p, frame)
            paths.append(str(p))
            note(f"board view at turntable {got:.1f} deg: {p}")
    return paths
