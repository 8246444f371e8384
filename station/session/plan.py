"""The capture plan as data: a generator of frozen step dataclasses.

:func:`plan_session` lists every step of a calibration session (per focus
setting: lock focus; per orientation: move, settle, capture and save N frames,
measure; then fit; with an ``intrinsics`` section, the board views at that focus — on the
turntable's wedge, or asked of the operator one by one (:class:`PlaceBoard`) — and the camera
matrix from them; then store) without touching any hardware, so tests can list
it and :mod:`station.session.executor` can perform it. A resumed session passes the
keys of what it already has (:func:`frame_key`, :func:`stored_key`) and the
plan skips them.

An orientation is a turntable angle, or with two-axis capture (``capture.shift_positions_mm``) a pair
(linear-stage position, turntable angle): every angle at the first position, then every angle at the next
(:attr:`station.config.schema.CaptureConfig.orientations`), so that the stage moves once per position.

Re-captures are the plan's decision: the executor sends each ``Measure``'s
:class:`ShotCheck` back into the generator (``plan.send(check)``); a shot that
failed its checks is captured again (locking its focus first if another one is
locked) up to ``capture.checks.max_recaptures`` times, after which the plan yields
:class:`Stop` with the reason. Listing the plan (``list(plan_session(...))``)
sends nothing: every shot is taken to pass.
"""

from __future__ import annotations

from collections.abc import Generator, Iterable, Iterator
from dataclasses import dataclass

from pipeline.board_requests import ViewRequest, wanted_views
from station.config import Config


@dataclass(frozen=True)
class LockFocus:
    focus_idx: int
    focus: float


@dataclass(frozen=True)
class Move:
    """Move to an orientation: the linear stage that carries the turntable to ``shift_mm`` first (two-axis
    capture, ``capture.shift_positions_mm``; None: no stage move), then the turntable to ``degrees``."""

    focus_idx: int
    orientation_idx: int
    degrees: float
    shift_mm: float | None = None


@dataclass(frozen=True)
class Settle:
    seconds: float


@dataclass(frozen=True)
class Capture:
    focus_idx: int
    orientation_idx: int
    frame_idx: int


@dataclass(frozen=True)
class Save:
    focus_idx: int
    orientation_idx: int
    frame_idx: int


@dataclass(frozen=True)
class Measure:
    """Average the orientation's frames, measure, check (re-capture on failure)."""

    focus_idx: int
    orientation_idx: int


@dataclass(frozen=True)
class Fit:
    focus_idx: int


@dataclass(frozen=True)
class Store:
    focus_idx: int


@dataclass(frozen=True)
class PlaceBoard:
    """Ask the operator to place the board as ``request`` says (``intrinsics.placement: operator``; a
    :class:`pipeline.board_requests.ViewRequest`), saying why the last capture was rejected
    (``problems``), and wait for the answer: the executor sends back :data:`CAPTURE`, :data:`SKIP` or
    :data:`STOP`."""

    focus_idx: int
    view_idx: int
    request: ViewRequest
    problems: tuple[str, ...] = ()


@dataclass(frozen=True)
class BoardView:
    """The camera-matrix stage (``intrinsics``): move to ``degrees`` (and the tilt axis to ``tilt_deg``,
    ``placement: stage``) and settle (``degrees`` None: the board where the operator placed it, no move),
    capture the board and save it (view ``view_idx`` of focus setting ``focus_idx``, at the locked focus)."""

    focus_idx: int
    view_idx: int
    degrees: float | None
    tilt_deg: float | None = None


@dataclass(frozen=True)
class CheckBoard:
    """Find the board in the view just saved (found, enough corners, not blurred); the executor sends
    back its :class:`BoardCheck` (an operator-placed view that fails is asked for again)."""

    focus_idx: int
    view_idx: int


@dataclass(frozen=True)
class SkipBoard:
    """The operator skipped this view: recorded, and the camera matrix is fitted without it."""

    focus_idx: int
    view_idx: int


@dataclass(frozen=True)
class EstimateK:
    """Find the board in the focus setting's views and fit its camera matrix, the distortion held fixed."""

    focus_idx: int


@dataclass(frozen=True)
class Stop:
    """The session cannot go on (a shot keeps failing its checks); ``reason`` says why."""

    reason: str


Step = (
    LockFocus | Move | Settle | Capture | Save | Measure | Fit | PlaceBoard | BoardView | CheckBoard | SkipBoard
    | EstimateK | Store | Stop
)  # fmt: skip

CAPTURE, SKIP, STOP = "capture", "skip", "stop"
"""The operator's answers to a :class:`PlaceBoard`: the board is in place, leave this view out, stop the session."""


@dataclass(frozen=True)
class ShotCheck:
    """What measuring a shot found: ``problems`` (empty: accepted) at capture ``attempt``
    (the number of times the shot was rejected before this one)."""

    focus_idx: int
    orientation_idx: int
    attempt: int
    problems: tuple[str, ...] = ()

    @property
    def accepted(self) -> bool:
        return not self.problems


@dataclass(frozen=True)
class BoardCheck:
    """What finding the board in a view gave: ``problems`` (empty: accepted), the corners found."""

    focus_idx: int
    view_idx: int
    problems: tuple[str, ...] = ()
    corners: int = 0

    @property
    def accepted(self) -> bool:
        return not self.problems


Sent = ShotCheck | BoardCheck | str | None
"""What the executor sends back into the plan: a shot's or a board view's check, the operator's answer."""


def frame_key(focus_idx: int, orientation_idx: int, frame_idx: int) -> tuple:
    """Key of a saved frame in ``already_done``."""
    return ("frame", int(focus_idx), int(orientation_idx), int(frame_idx))


def board_key(focus_idx: int, view_idx: int) -> tuple:
    """Key of a saved board view in ``already_done``."""
    return ("board", int(focus_idx), int(view_idx))


def board_unchecked_key(focus_idx: int, view_idx: int) -> tuple:
    """Key of an operator-placed board view saved but not yet checked (the run stopped in between): the
    plan checks it before anything else of that view, and asks for it again with why if it is rejected."""
    return ("board-unchecked", int(focus_idx), int(view_idx))


def stored_key(focus_idx: int) -> tuple:
    """Key meaning the profile of this focus setting is in the store."""
    return ("stored", int(focus_idx))


def capture_steps(
    config: Config, focus_idx: int, orientation_idx: int, frames: Iterable[int] | None = None
) -> Iterator[Step]:
    """Move to an orientation, settle, capture and save ``frames`` (default all)."""
    cap = config.capture
    shift_mm, degrees = cap.orientations[orientation_idx]
    yield Move(focus_idx, orientation_idx, degrees, shift_mm)
    if cap.settle_s > 0:
        yield Settle(cap.settle_s)
    for i in range(cap.frames_per_orientation) if frames is None else frames:
        yield Capture(focus_idx, orientation_idx, i)
        yield Save(focus_idx, orientation_idx, i)


def plan_session(config: Config, already_done: Iterable[tuple] = frozenset()) -> Generator[Step, Sent, None]:
    """Every step of the session described by ``config``, minus ``already_done``.

    Parameters
    ----------
    config : the validated station configuration.
    already_done : keys of finished work (:func:`frame_key`, :func:`board_key`, :func:`stored_key`) and
        of operator-placed board views saved but not yet checked (:func:`board_unchecked_key`).

    Yields
    ------
    Step : in execution order. A focus setting whose profile is stored yields
        nothing; an orientation whose frames are all saved yields only its
        ``Measure``; a board view saved yields nothing (its ``EstimateK`` reads it);
        ``LockFocus`` is emitted only when something is captured.
        After a ``Measure``, the executor sends its :class:`ShotCheck`; a rejected
        shot is re-captured, or ``Stop`` is yielded (see the module docstring).
        With board views placed by the operator, each is a ``PlaceBoard`` (the executor sends the
        operator's answer), ``BoardView`` and ``CheckBoard`` (it sends the :class:`BoardCheck`); a
        rejected view is asked for again with its problems, as long as the operator wants. A view saved
        but not yet checked when the run stopped is checked first (a ``CheckBoard``), and asked for
        again with its problems only if it is rejected.
    """
    done = set(already_done)
    n = config.capture.frames_per_orientation
    max_recaptures = config.capture.checks.max_recaptures
    locked: int | None = None
    for f, focus in enumerate(config.focus_settings):
        if stored_key(f) in done:
            continue
        n_o = len(config.capture.orientations)
        missing = {o: [i for i in range(n) if frame_key(f, o, i) not in done] for o in range(n_o)}
        if any(missing.values()):
            yield LockFocus(f, focus)
            locked = f
        for o in range(n_o):
            if missing[o]:
                yield from capture_steps(config, f, o, missing[o])
            while True:
                check = yield Measure(f, o)
                if check is None or check.accepted:
                    break
                if check.attempt >= max_recaptures:
                    yield Stop(
                        f"shot focus {f} {config.capture.orientation_name(o)} failed its checks {check.attempt + 1} "
                        "times: " + "; ".join(check.problems)
                    )
                    return
                if locked != f:
                    yield LockFocus(f, focus)
                    locked = f
                yield from capture_steps(config, f, o)
        yield Fit(f)
        k = config.intrinsics
        if k is not None:
            views = [v for v in range(k.n_views) if board_key(f, v) not in done]
            if views and locked != f:
                yield LockFocus(f, focus)
                locked = f
            if k.placement == "operator":
                requests = wanted_views(k.n_views)
                for v in views:
                    problems: tuple[str, ...] = ()
                    if board_unchecked_key(f, v) in done:  # saved when the last run stopped, never checked
                        check = yield CheckBoard(f, v)
                        if not isinstance(check, BoardCheck) or check.accepted:
                            continue
                        problems = check.problems
                    while True:
                        answer = yield PlaceBoard(f, v, requests[v], problems)
                        if answer == STOP:
                            yield Stop(f"the operator stopped the session at board view {v + 1} of focus {f}")
                            return
                        if answer == SKIP:
                            yield SkipBoard(f, v)
                            break
                        yield BoardView(f, v, None)
                        check = yield CheckBoard(f, v)
                        if not isinstance(check, BoardCheck) or check.accepted:
                            break
                        problems = check.problems
            else:
                poses = k.stage_views()
                for v in views:
                    yield BoardView(f, v, *poses[v])
            yield EstimateK(f)
        yield Store(f)
