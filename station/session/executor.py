"""The one executor: performs a session's plan on a camera and a turntable.

It performs each step of :func:`station.session.plan.plan_session`: locks focus,
moves the turntable (``move_to`` returns when idle), captures and saves each frame
atomically in the session directory, averages and checks each shot (exposure,
strings found, string angle = commanded orientation + harp offset within a
tolerance) and sends the check back to the plan, which decides whether to capture
the shot again (:mod:`station.session.shot_checks`); fits each focus setting
(:mod:`station.session.profile_steps`: :func:`station.calibration.calibrate_focus`, leave one
orientation out); with an ``intrinsics`` section, takes the board views at that focus
(:mod:`station.session.boards`) and fits the camera matrix with the distortion held fixed
(:mod:`station.session.camera_matrix`); and stores its profile, with that camera matrix
(:mod:`station.session.profile_steps`: model file and store row from the same
:class:`station.profile.Profile`). This module keeps the order of the steps, the devices and their
faults; the steps' work is in those modules.

Every fact is a typed manifest record (:mod:`station.session.records`) appended to
the session directory and handed to the subscribers (:mod:`station.session.progress`:
the tally behind :class:`SessionResult`, progress bars and the summary). QA and the
report are not the executor's: :func:`station.session_run.run_session` runs them
once the plan is done. Each accepted shot's measured edges and each focus setting's
bootstrap uncertainty map are kept in the session directory
(:mod:`station.session.layout`) so that they need not measure anything again. The
fits run on a :class:`station.pool.WorkerPool` (``pipeline.workers`` processes), started while the
session captures.

A camera with the :class:`drivers.protocols.IndexedCapture` capability (the
simulator) is told before each capture which frame of the shot it is taking
(``attempt * frames_per_orientation + frame_idx``), so that a resumed session
receives the same frames as an uninterrupted one.

Device faults (:class:`drivers.errors.DriverError`) are retried with exponential
back-off (``capture.retries``); a disconnected device is closed and reopened
between attempts; a turntable fault (stall, limit, alarm) is cleared with
``recover()`` (:class:`drivers.protocols.Recoverable`) and the stage re-homed before
the next attempt. A fault that persists, a device refusing a command, or a shot
that keeps failing its checks stops the session cleanly: every saved frame stays
in the session directory, an ``aborted`` record names the cause, and
:class:`SessionResult` carries a one-line message and exit code 2.
``harp session resume`` then continues from there.
"""

from __future__ import annotations

import contextlib
import errno
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from drivers.errors import CaptureError, DeviceDisconnected, DeviceFault, DeviceRejected, DriverError
from drivers.protocols import (
    Camera,
    CameraRanges,
    Frame,
    IndexedCapture,
    Recoverable,
    Turntable,
    TurntableRanges,
)
from pipeline.intrinsics import Intrinsics
from pipeline.plain import json_default
from station import __version__
from station.calibration import Calibration
from station.exit_codes import EXIT_ABORTED, EXIT_OK
from station.files import describe_os_error
from station.pool import WorkerPool
from station.profile import Profile
from station.session import layout
from station.session.boards import save_board_frame
from station.session.camera_matrix import ask_for_board, board_spec, check_board, estimate_k, grab_board_view
from station.session.directory import SessionAborted, SessionDir, SessionError
from station.session.evidence import measurement_arrays
from station.session.operator import OperatorDesk
from station.session.plan import (
    BoardCheck,
    BoardView,
    Capture,
    CheckBoard,
    EstimateK,
    Fit,
    LockFocus,
    Measure,
    Move,
    PlaceBoard,
    Save,
    Sent,
    Settle,
    ShotCheck,
    SkipBoard,
    Step,
    Stop,
    Store,
    plan_session,
)
from station.session.processing import ShotMeasurement, full_scale
from station.session.profile_steps import fit_focus, fitted_record, store_focus
from station.session.progress import Subscriber, Tally
from station.session.records import (
    Aborted,
    BoardRejected,
    BoardSaved,
    Fault,
    FitFailed,
    FocusLocked,
    Record,
    Resumed,
    ShotMeasured,
    ShotRejected,
    Started,
)
from station.session.shot_checks import FrameReference, check_shot
from station.session.states import stop_reason

#: a stage read-back further than this (or than the travel range's tolerance) from the target
#: stops the session (degrees)
POSITION_TOLERANCE_DEG = 0.05
#: a linear-stage read-back (two-axis capture) further than this (or than its travel range's tolerance) from
#: the target stops the session (mm)
POSITION_TOLERANCE_MM = 0.01

PRELOAD = ["station.calibration", "pipeline.fit", "pipeline.uncertainty", "station.qa.report"]
"""Modules the fits' forkserver imports once, so that each worker starts warm (the fits' and the
report's: :func:`station.qa.plots.draw_figures` draws in these processes too)."""

T = TypeVar("T")


@dataclass
class FocusSummary:
    """What one focus setting came to in this run (counts from the records' tally)."""

    focus_idx: int
    focus: float
    shots: int = 0
    recaptures: int = 0
    lines: int = 0
    calibration: Calibration | None = None
    profile: Profile | None = None
    profile_id: int | None = None

    @property
    def failure(self) -> str | None:
        """Why this focus setting has no profile (None: it has one, or was not fitted in this run)."""
        return self.calibration.failure if self.calibration is not None else None


@dataclass
class SessionResult:
    exit_code: int
    message: str
    frames_saved: int = 0
    faults: int = 0
    focus: list[FocusSummary] = field(default_factory=list)
    verdict: str | None = None  # the session's QA verdict, once judged (station.session_run)
    results: dict[str, Any] | None = None  # what DIR/results.json holds (station.qa.results)


class Executor:
    """Performs :func:`station.session.plan.plan_session` for ``session`` on open devices.

    Parameters
    ----------
    session : the session directory (its ``config`` is the plan's input).
    camera, turntable : opened drivers satisfying the protocols.
    store : a :class:`station.store.ProfileStore` (``None``: do not store).
    judge : ``judge(profile, focus_idx)``, the QA verdict of a focus setting's profile, stored with it
        (``None``: stored unjudged; :func:`station.session_run.run_session` passes the QA's).
    subscribers : receive the records and notes (:class:`station.session.progress.Subscriber`).
    sleep : the back-off sleep (tests pass a recorder).
    operator : asked for each board view placed by hand (``intrinsics.placement: operator``;
        :class:`station.session.operator.OperatorDesk`; None: such a session stops at its first view).
    """

    def __init__(
        self,
        session: SessionDir,
        camera: Camera,
        turntable: Turntable,
        *,
        store: Any = None,
        judge: Callable[[Profile, int], Any] | None = None,
        subscribers: Sequence[Subscriber] = (),
        sleep: Callable[[float], None] = time.sleep,
        operator: OperatorDesk | None = None,
    ):
        self.session = session
        self.operator = operator
        self.judge = judge
        self.config = session.config
        self.camera = camera
        self.turntable = turntable
        self.store = store
        self.sleep = sleep
        self.tally = Tally()
        self.subscribers: list[Subscriber] = [self.tally, *subscribers]
        self.workers = WorkerPool(self.config.pipeline.workers, PRELOAD)
        self._pending: dict[tuple[int, int, int], Frame] = {}
        self._shots: dict[tuple[int, int], ShotMeasurement] = {}
        self._calibrations: dict[int, Calibration] = {}
        self._profiles: dict[int, Profile] = {}
        self._intrinsics: dict[int, Intrinsics] = {}
        self._stage_deg: float | None = None
        self._shift_mm: float | None = None  # the linear stage's read-back (two-axis capture)
        self._shift_target: float | None = None  # where it was sent and went (None: not known, after a fault)
        self._focus: float | None = None
        self._size: tuple[int, int] | None = None
        self._frames = FrameReference(session)  # the frame checks' reference
        self._prepared = False

    # ================================================================ run
    def run(self) -> SessionResult:
        """Perform what the session still lacks; QA, the report and ``finished`` are the caller's."""
        s = self.session
        past = list(s.typed)
        resumed = any(isinstance(r, Started) for r in past)
        self._emit(Resumed(__version__) if resumed else Started(__version__))
        done = s.done_keys()
        listed = list(plan_session(self.config, done))  # every shot taken to pass: the totals of the bars
        n_capture = sum(isinstance(x, (Capture, BoardView)) for x in listed)
        n_process = sum(isinstance(x, (Measure, Fit, EstimateK, Store)) for x in listed)
        for sub in self.subscribers:
            sub.start(self.config, past, n_capture, n_process)
        try:
            if any(isinstance(x, Fit) for x in listed):
                self.workers.warm_up()  # the fit's processes start while the session captures
            try:
                plan = plan_session(self.config, done)
                step = next(plan, None)
                while step is not None:
                    outcome = self.perform(step)
                    try:
                        step = plan.send(outcome)
                    except StopIteration:
                        step = None
            except KeyboardInterrupt:
                self._emit(Aborted(stop_reason()))
                self._finish(interrupted=True)
                raise
            except SessionAborted as exc:
                return self._abort(str(exc))
            except OSError as exc:  # the session directory cannot be written (a full disk)
                return self._abort(self.disk_problem(exc))
            except SessionError as exc:  # a session file found damaged while working
                return self._abort(str(exc))
            except Exception as exc:  # a bug: recorded, then the caller says it in one line
                self._abort(f"internal error: {type(exc).__name__}: {' '.join(str(exc).split())}")
                raise
        finally:
            self.workers.close()
        self._finish()
        return self._result(EXIT_OK, f"session finished: {s.path}")

    def disk_problem(self, exc: OSError) -> str:
        """One line for a write the session directory refused, with what to do."""
        full = exc.errno in (errno.ENOSPC, errno.EDQUOT)
        action = f"free some space, then: harp session resume {self.session.path}" if full else None
        return describe_os_error(exc, action)

    def _abort(self, reason: str) -> SessionResult:
        """Record why the session stopped (``aborted``), close the subscribers, return exit 2."""
        s = self.session
        s.release_reserve()  # whatever filled the disk, the record fits in the space held back
        try:
            self._emit(Aborted(reason))
        except OSError as exc:
            reason += f" (not recorded in the manifest: {describe_os_error(exc)})"
        self._finish()
        n = self.tally.frames_saved
        return self._result(EXIT_ABORTED, f"session stopped: {reason}; {n} new frames kept in {s.path}")

    def subscribe(self, subscriber: Subscriber) -> None:
        """Hand ``subscriber`` the records and notes of the run, too."""
        self.subscribers.append(subscriber)

    def _emit(self, record: Record) -> None:
        """Append ``record`` to the manifest and hand it to the subscribers."""
        self.session.append(record)
        self._publish(record)

    def _publish(self, record: Record) -> None:
        for sub in self.subscribers:
            sub.record(record)

    def _note(self, text: str) -> None:
        for sub in self.subscribers:
            sub.note(text)

    def _finish(self, interrupted: bool = False) -> None:
        for sub in self.subscribers:
            sub.finish(self.session.path, interrupted)

    def _result(self, code: int, msg: str) -> SessionResult:
        rows = self.tally.rows
        focus = [
            FocusSummary(
                f,
                r.focus,
                r.shots,
                r.recaptures,
                r.lines,
                self._calibrations.get(f),
                self._profiles.get(f),
                r.profile_id,
            )
            for f, r in rows.items()
        ]
        return SessionResult(code, msg, self.tally.frames_saved, self.tally.faults, focus)

    def _prepare(self) -> None:
        """Exposure, gain, home: before the first step that uses the devices (a resume or a repair
        that only measures and fits again needs none)."""
        if self._prepared:
            return
        self._prepared = True
        cap = self.config.capture
        self._retry("set exposure", lambda: self.camera.set_exposure(cap.exposure_us), self.camera)
        self._retry("set gain", lambda: self.camera.set_gain(cap.gain_db), self.camera)
        self._retry("home turntable", lambda: self.turntable.home(timeout=cap.move_timeout_s), self.turntable)
        w, h = self.camera.sensor_size
        self._size = (int(w), int(h))

    # ============================================================== steps
    def perform(self, step: Step) -> Sent:
        """Perform one step of the plan; a ``Measure`` or ``CheckBoard`` returns its check for the plan, a
        ``PlaceBoard`` the operator's answer."""
        if isinstance(step, (LockFocus, Move, Capture, PlaceBoard, BoardView)):
            self._prepare()
        match step:
            case LockFocus():
                self._lock_focus(step)
            case Move():
                self._move(step)
            case Settle():
                time.sleep(step.seconds)
            case Capture():
                self._capture(step)
            case Save():
                self._save(step)
            case Measure():
                return self._measure(step)
            case Fit():
                self._fit(step)
            case PlaceBoard():
                return ask_for_board(step, self.session, self.config, self.camera, self.operator, self._emit)
            case BoardView():
                self._board_view(step)
            case CheckBoard():
                return self._check_board(step)
            case SkipBoard():
                self._emit(BoardRejected(step.focus_idx, step.view_idx, ["skipped by the operator"], skipped=True))
            case EstimateK():
                self._estimate_k(step)
            case Store():
                self._store(step)
            case Stop():
                raise SessionAborted(step.reason)
        return None

    def _lock_focus(self, step: LockFocus) -> None:
        got = self._retry(f"lock focus {step.focus:g}", lambda: self.camera.lock_focus(step.focus), self.camera)
        self._focus = step.focus
        self._emit(FocusLocked(step.focus_idx, step.focus, got))
        r = self.camera.focus_range() if isinstance(self.camera, CameraRanges) else None
        tol = r.tolerance() if r is not None else 0.0
        if got is not None and abs(float(got) - step.focus) > tol + 1e-9 * max(1.0, abs(step.focus)):
            where = f" (focus range {r}, {r.source})" if r is not None else ""
            raise SessionAborted(
                f"camera read back focus {float(got):g} after focus {step.focus:g} was commanded{where}: "
                "it did not take the setting; check focus.settings against the camera"
            )

    def _move(self, step: Move) -> None:
        if step.shift_mm is not None and step.shift_mm != self._shift_target:  # two-axis capture: the linear stage
            self._shift_to(step.shift_mm)  # under the turntable first, when it is not there already
        self._move_to(step.degrees, "capture.orientations_deg")

    def _shift_to(self, mm: float) -> None:
        """Move the linear stage that carries the turntable (``turntable.shift``) to ``mm`` and check where it
        went (the configuration check makes sure there is one: :func:`station.config.devices.check_the_devices`)."""
        axis = getattr(self.turntable, "shift", None)
        if axis is None:
            raise SessionAborted(
                "capture.shift_positions_mm: the turntable has no linear stage (station.turntable.shift_axis)"
            )
        self._shift_mm = self._shift_target = None
        self._shift_mm = self._checked_move(
            axis, mm, "mm", POSITION_TOLERANCE_MM, "the linear stage", "linear stage",
            "check its limits (station.turntable.shift_limits) against capture.shift_positions_mm",
        )  # fmt: skip
        self._shift_target = mm

    def _move_to(self, degrees: float, field: str) -> None:
        """Move the turntable to ``degrees`` (of configuration ``field``) and check where it went."""
        self._stage_deg = None
        # the driver reported no fault, yet the stage is elsewhere: a device that clamps or is configured
        # differently; capturing there would store frames at the wrong angle
        self._stage_deg = self._checked_move(
            self.turntable, degrees, "deg", POSITION_TOLERANCE_DEG, "turntable", "turntable",
            f"check its limits and steps_per_degree against {field}",
        )  # fmt: skip

    def _checked_move(
        self, axis: Any, target: float, unit: str, tolerance: float, moving: str, name: str, hint: str
    ) -> float:
        """Move ``axis`` (the turntable or its linear stage) to ``target`` (``unit``), retried as any device
        command, and return where it read back; :class:`SessionAborted` (naming it ``name``, with ``hint``) when
        that is further from the target than ``tolerance`` or its travel range's tolerance."""
        timeout = self.config.capture.move_timeout_s
        got = float(
            self._retry(
                f"move {moving} to {target:g} {unit}", lambda: axis.move_to(target, timeout=timeout), self.turntable
            )
        )
        travel = axis.travel_range() if isinstance(axis, TurntableRanges) else None
        tol = max(tolerance, travel.tolerance() if travel is not None else 0.0)
        if abs(got - target) > tol:
            raise SessionAborted(
                f"{name} read back {got:.4f} {unit} after a move to {target:g} {unit} (tolerance {tol:g}): {hint}"
            )
        return got

    def _capture(self, step: Capture) -> None:
        timeout = self.config.capture.timeout_s
        # Frames are numbered per shot and attempt, so a resumed session that captures
        # only the missing frames asks an IndexedCapture camera for the same ones.
        index = (
            self.session.attempt(step.focus_idx, step.orientation_idx) * self.config.capture.frames_per_orientation
            + step.frame_idx
        )

        def grab() -> Frame:
            if isinstance(self.camera, IndexedCapture):
                visit = self.config.capture.visits[step.orientation_idx]
                if visit:  # a twin's return to a pose: frames of their own
                    self.camera.set_capture_index(index, visit)
                else:
                    self.camera.set_capture_index(index)
            frame = self.camera.capture(timeout=timeout)
            img = np.asarray(frame.image)
            if img.ndim != 2 or img.dtype not in (np.uint8, np.uint16):
                raise CaptureError(f"corrupt frame: {img.dtype} array of shape {img.shape}")
            if self._size and img.shape != (self._size[1], self._size[0]):
                raise CaptureError(f"corrupt frame: shape {img.shape}, sensor is {self._size[0]}x{self._size[1]}")
            shot = (step.focus_idx, step.orientation_idx, self.session.attempt(step.focus_idx, step.orientation_idx))
            self._frames.check(shot, img, full_scale(img.dtype, _bit_depth(frame)))
            return frame

        where = f"capture focus {step.focus_idx} orientation {step.orientation_idx} frame {step.frame_idx}"
        self._pending[(step.focus_idx, step.orientation_idx, step.frame_idx)] = self._retry(where, grab, self.camera)

    def _save(self, step: Save) -> None:
        frame = self._pending.pop((step.focus_idx, step.orientation_idx, step.frame_idx))
        meta = {
            "timestamp": frame.timestamp,
            "exposure_us": frame.exposure_us,
            "gain_db": frame.gain_db,
            "focus": frame.focus,
            "counter": frame.counter,
            "camera": [frame.camera.vendor, frame.camera.model, frame.camera.serial],
            "stage_deg": self._stage_deg,
            "commanded_deg": self.config.capture.angles_deg[step.orientation_idx],
            "bit_depth": _bit_depth(frame),
            "extra": _jsonable(frame.extra),
        }
        commanded_mm = self.config.capture.shifts_mm[step.orientation_idx]
        if commanded_mm is not None:  # two-axis capture: where the linear stage was (read back) and was sent
            meta.update(shift_mm=self._shift_mm, commanded_shift_mm=commanded_mm)
        saved = self.session.write_frame(
            step.focus_idx, step.orientation_idx, step.frame_idx, np.asarray(frame.image), meta
        )
        self._publish(saved)

    def _measure(self, step: Measure) -> ShotCheck:
        f, o = step.focus_idx, step.orientation_idx
        attempt = self.session.attempt(f, o)
        problems, m = check_shot(self.session, self.config, f, o)
        if problems or m is None:
            self._emit(ShotRejected(f, o, attempt, list(problems)))
            return ShotCheck(f, o, attempt, tuple(problems))
        self._shots[(f, o)] = m
        self._frames.accept((f, o, attempt))
        saved = self.session.write_arrays(layout.measurement_file(f, o, attempt), measurement_arrays(m.measurement))
        self._emit(ShotMeasured(f, o, attempt, m.n_lines, m.d, m.d_max, m.angle_deg, saved["file"], saved["sha256"]))
        return ShotCheck(f, o, attempt)

    def _fit(self, step: Fit) -> None:
        f = step.focus_idx
        n_o = len(self.config.capture.orientations)
        shots = [self._shots[(f, o)].lines for o in range(n_o)]
        size = self._image_size(f)
        cal = fit_focus(f, self.config, shots, size, self.workers.map, self.session, spec=self.config.pipeline.spec)
        self._calibrations[f] = cal
        if cal.failure or not cal.fit:
            self._emit(FitFailed(f, str(cal.failure)))
            raise SessionAborted(f"fit of focus setting {self.config.focus_settings[f]:g} failed: {cal.failure}")
        self._emit(fitted_record(f, cal, self.session))

    def _board_view(self, step: BoardView) -> None:
        """The camera-matrix stage: one board view at the locked focus (:mod:`station.session.boards`),
        saved and recorded; a resumed session keeps the views on disk (the plan skips them)."""
        cfg = self.config
        spec = board_spec(cfg)
        tilt = None
        if step.tilt_deg is not None:  # placement: stage (config check: the turntable has a tilt axis)
            axis = getattr(self.turntable, "tilt", None)
            if axis is None:
                raise SessionAborted("intrinsics.placement: stage: the turntable has no tilt axis")
            tilt = self._retry(f"tilt the board to {step.tilt_deg:g}°",
                               lambda: axis.move_to(step.tilt_deg, timeout=cfg.capture.move_timeout_s),
                               self.turntable)  # fmt: skip
        if step.degrees is not None:
            self._move_to(step.degrees, "intrinsics.angles_deg")
            if cfg.capture.settle_s > 0:
                time.sleep(cfg.capture.settle_s)
        attempt = self.session.board_attempt(step.focus_idx, step.view_idx)
        grab = grab_board_view(self.camera, spec, step, cfg.capture.timeout_s)
        frame = self._retry(f"capture board view {step.view_idx} at focus {step.focus_idx}", grab, self.camera)
        rel = layout.board_file(step.focus_idx, step.view_idx, attempt)
        digest = save_board_frame(self.session.path / rel, frame)
        self._emit(BoardSaved(step.focus_idx, step.view_idx, rel, digest, step.degrees, self._stage_deg, attempt, tilt))

    def _check_board(self, step: CheckBoard) -> BoardCheck:
        record, check = check_board(step, self.session, self.config, self._image_size(step.focus_idx))
        self._emit(record)
        return check

    def _estimate_k(self, step: EstimateK) -> None:
        """The camera matrix of a focus setting (:func:`station.session.camera_matrix.estimate_k`); without
        one, the profile is stored without it."""
        f = step.focus_idx
        cal = self._calibrations[f]
        assert cal.fit is not None  # a failed fit stopped the session
        record, k = estimate_k(f, self.session, self.config, cal.fit.model, self._image_size(f))
        if k is not None:
            self._intrinsics[f] = k
        self._emit(record)

    def _image_size(self, f: int) -> tuple[int, int]:
        h, w = self.session.read_frame(self.session.frames(f, 0)[0], verify=False).shape
        return w, h

    def _store(self, step: Store) -> None:
        f = step.focus_idx
        profile, stored = store_focus(
            f,
            self.session,
            self.config,
            self._calibrations[f],
            self._image_size(f),
            intrinsics=self._intrinsics.get(f),
            judge=None if self.judge is None else (lambda p: self.judge(p, f)),
            store=self.store,
            emit=self._emit,
        )
        self._profiles[f] = profile
        self._emit(stored)

    # ============================================================ faults
    def _retry(self, what: str, fn: Callable[[], T], device: Any = None) -> T:
        """Call ``fn`` with bounded retries and exponential back-off."""
        rc = self.config.capture.retries
        delay = rc.backoff_s
        for attempt in range(1, rc.attempts + 1):
            try:
                return fn()
            except DeviceRejected as exc:
                self._emit(Fault(what, type(exc).__name__, str(exc), attempt))
                raise SessionAborted(f"{what}: device refused: {exc}") from None
            except (DriverError, OSError) as exc:
                self._emit(Fault(what, type(exc).__name__, str(exc), attempt))
                if attempt == rc.attempts:
                    raise SessionAborted(f"{what} failed {attempt} times, last: {type(exc).__name__}: {exc}") from None
                self._note(
                    f"[yellow]{what}: {type(exc).__name__}: {exc}; retry {attempt}/{rc.attempts - 1} in {delay:g} s"
                )
                self.sleep(delay)
                delay *= 2
                if isinstance(exc, (DeviceDisconnected, OSError)) and device is not None:
                    self._reopen(device)
                elif isinstance(exc, DeviceFault) and device is self.turntable:
                    self._recover_turntable()
        raise AssertionError("unreachable: capture.retries.attempts >= 1")  # pragma: no cover

    def _recover_turntable(self) -> None:
        """After a stall / limit / alarm: clear it (:class:`~drivers.protocols.Recoverable`) and
        re-home, since a stepper that stalled no longer knows where it is (nor is the linear stage taken to be
        where it was sent)."""
        self._shift_target = None
        try:
            if isinstance(self.turntable, Recoverable):
                cleared = self.turntable.recover()
                self._note(f"[yellow]turntable recovered (cleared {cleared or 'nothing'}); homing")
            self.turntable.home(timeout=self.config.capture.move_timeout_s)
        except (DriverError, OSError) as exc:
            self._note(f"[yellow]turntable recovery failed: {type(exc).__name__}: {exc}")

    def _reopen(self, device: Any) -> None:
        if device is self.turntable:
            self._shift_target = None
        with contextlib.suppress(Exception):
            device.close()
        try:
            device.open()
            if device is self.camera:
                cap = self.config.capture
                self.camera.set_exposure(cap.exposure_us)
                self.camera.set_gain(cap.gain_db)
                if self._focus is not None:
                    self.camera.lock_focus(self._focus)
        except (DriverError, OSError) as exc:
            self._note(f"[yellow]reopen failed: {type(exc).__name__}: {exc}")


def _bit_depth(frame: Frame) -> int | None:
    extra = frame.extra if isinstance(frame.extra, dict) else {}
    bd = extra.get("bit_depth")
    return int(bd) if isinstance(bd, (int, float)) and bd > 0 else None


def _jsonable(value: Any) -> Any:
    """``value`` if it survives JSON, else its ``repr`` (driver extras may be anything)."""
    import json

    try:
        return json.loads(json.dumps(value, default=json_default))
    except (TypeError, ValueError):
        return repr(value)
