"""The camera-matrix stage of a session (its ``intrinsics`` section): the steps beside the board captures.

Performed by :class:`station.session.executor.Executor` for the plan's board steps
(:mod:`station.session.plan`): the operator asked for a view placed by hand (:func:`ask_for_board`, with a
preview for the live page, :func:`board_preview`), a board frame taken (:func:`grab_board_view`; the
capture code is :mod:`station.session.boards`'), each view saved checked (:func:`check_board`), and each
focus setting's camera matrix fitted from its views with the distortion held fixed
(:func:`estimate_k`, :func:`station.intrinsics.measure_intrinsics`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from drivers.errors import DriverError
from drivers.protocols import BoardScene, Camera, Frame, IndexedCapture
from pipeline.board import BoardSpec, detect_board, parse_board
from pipeline.intrinsics import Intrinsics
from pipeline.models.base import DistortionModel
from station.config import Config
from station.files import sha256_file
from station.intrinsics import board_views, measure_intrinsics
from station.session.boards import board_frame
from station.session.directory import SessionAborted, SessionDir, SessionError
from station.session.operator import NoOperator, OperatorDesk
from station.session.plan import BoardCheck, BoardView, CheckBoard, PlaceBoard
from station.session.records import BoardAccepted, BoardRejected, BoardWanted, IntrinsicsMeasured, Record


def board_spec(config: Config) -> BoardSpec:
    """The board of the configuration's ``intrinsics`` section (the plan yields board steps only with it)."""
    assert config.intrinsics is not None
    return parse_board(config.intrinsics.board)


def grab_board_view(camera: Camera, spec: BoardSpec, step: BoardView, timeout: float) -> Callable[[], Frame]:
    """The capture of one board view, to be retried: on the stage (``step.degrees`` set) the board frame of
    :func:`station.session.boards.board_frame`; else the frame of wherever the operator placed the board."""

    def grab() -> Frame:
        if isinstance(camera, IndexedCapture):
            camera.set_capture_index(step.view_idx)  # the same noise on resume
        if step.degrees is not None:
            return board_frame(camera, spec, timeout=timeout)
        try:  # where the operator placed it (PlaceBoard)
            return camera.capture(timeout=timeout)
        finally:
            if isinstance(camera, BoardScene):  # the stand-in takes the board away: the harp again
                camera.show_board(None)

    return grab


def ask_for_board(
    step: PlaceBoard,
    session: SessionDir,
    config: Config,
    camera: Camera,
    operator: OperatorDesk | None,
    emit: Callable[[Record], None],
) -> str:
    """Ask the operator for a board view (``intrinsics.placement: operator``): a ``board-ask`` record (the
    live page shows it), the request said on the terminal with why the view's last capture was rejected
    (the plan's problems, or on resume the last ``board-reject`` record's), the answer awaited. A camera
    that can be shown the board (the simulator) stands in for the person too: it holds the board as asked."""
    f, v, req = step.focus_idx, step.view_idx, step.request
    attempt = session.board_attempt(f, v)
    problems = list(step.problems)
    if not problems and attempt > 0:  # rejected before the last run stopped (or by a repair): why, said again
        last = session.last(BoardRejected, focus_idx=f, view_idx=v)
        if last is not None and not last.skipped:
            problems = list(last.reasons)
    emit(BoardWanted(f, v, attempt, req.to_dict(), problems))
    if isinstance(camera, BoardScene):
        camera.show_board(board_spec(config).label, req)
    lines = [f"focus {config.focus_settings[f]:g}, {req.instruction()}", f"  why: {req.why()}"]
    if problems:
        lines.insert(0, f"[yellow]board view {v + 1} rejected: {'; '.join(problems)}; once more:")
    if operator is None:
        raise SessionAborted(
            "the board views are placed by the operator (intrinsics.placement: operator) and this run has "
            f"none; continue on a terminal with: harp session resume {session.path}"
        )
    try:
        return operator.ask(lines, board_preview(session, config, camera))
    except NoOperator as exc:
        raise SessionAborted(f"{exc}; then: harp session resume {session.path}") from None


def board_preview(session: SessionDir, config: Config, camera: Camera) -> Callable[[], None] | None:
    """While the operator places the board, and a live page shows the session (its session directory
    has ``show_board_preview``: :class:`station.live.session_tap.SessionTap`): a frame now and then,
    and where the board is found in it, for the page. Best effort: a frame that fails is left out (the
    view's own capture retries)."""
    show = getattr(session, "show_board_preview", None)
    if show is None or config.intrinsics is None:
        return None
    spec = board_spec(config)
    timeout = config.capture.timeout_s

    def preview() -> None:
        try:
            frame = camera.capture(timeout=timeout)
        except (DriverError, OSError):
            return
        image = np.asarray(frame.image)
        show(image, detect_board(image, spec, name="the camera's picture"))

    return preview


def check_board(
    step: CheckBoard, session: SessionDir, config: Config, size: tuple[int, int]
) -> tuple[Record, BoardCheck]:
    """Find the board in the view just saved: accepted (``board-ok`` with its corners, which the live
    page's board coverage pools) or rejected with why (``board-reject``: no board, too few corners,
    blurred, another size than the harp's frames, ``size`` = (width, height)); the record and the plan's
    check."""
    f, v = step.focus_idx, step.view_idx
    rec = session.boards(f)[v]
    w, h = size
    views, rejected = board_views([str(session.path / rec.file)], board_spec(config), w, h)
    if not views:
        problems = [rejected[0].reason]
        return BoardRejected(f, v, problems), BoardCheck(f, v, tuple(problems))
    view = views[0]
    corners = np.round(np.asarray(view.image_points, np.float64).reshape(-1, 2), 2).tolist()
    return BoardAccepted(f, v, rec.attempt, corners, [w, h]), BoardCheck(f, v, (), view.n)


def estimate_k(
    f: int, session: SessionDir, config: Config, model: DistortionModel, size: tuple[int, int]
) -> tuple[IntrinsicsMeasured, Intrinsics | None]:
    """The camera matrix of focus setting ``f`` from its board views, its distortion ``model`` held fixed
    (:func:`station.intrinsics.measure_intrinsics`): the record and the matrix. Too few usable views
    (``intrinsics.min_views``) or a failed adjustment: a record with the failure and no matrix (the
    profile is stored without one)."""
    k = config.intrinsics
    assert k is not None
    views = session.boards(f)  # the last capture of each view, unless superseded since
    paths = []
    for v in sorted(views):
        r = views[v]
        p = session.path / r.file
        if sha256_file(p) != r.sha256:
            raise SessionError(f"{p}: checksum does not match the manifest; run: harp session repair {session.path}")
        paths.append(str(p))
    w, h = size
    run = measure_intrinsics(
        model,
        w,
        h,
        paths,
        parse_board(k.board),
        distortion_from=f"the session's fit of focus setting {config.focus_settings[f]:g}",
        skew=k.skew,
        command="harp session",
    )
    rejected = [[str(Path(r.name).relative_to(session.path)), r.reason] for r in run.rejected]
    result = run.result
    failure = None
    if not result:
        failure = str(getattr(result, "reason", "no camera matrix"))
    elif len(run.views) < k.min_views:
        failure = f"only {len(run.views)} usable board views of {len(paths)} (intrinsics.min_views {k.min_views})"
    if failure is None and isinstance(result, Intrinsics):
        return IntrinsicsMeasured(f, rejected, intrinsics=result.to_dict()), result
    return IntrinsicsMeasured(f, rejected, failure=failure), None
