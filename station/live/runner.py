"""The live view's engine: :class:`LiveStation` captures, assesses and keeps what the page shows.

Two threads, one per device, so that a turntable move never stops the picture:

* the **camera thread** captures a frame, assesses it (:func:`pipeline.assess.assess_frame`, the
  edge thresholds reused while exposure and gain stay the same), checks it against the
  session's limits (:func:`station.live.checks.live_warnings`), encodes the downscaled frame,
  and applies the camera settings asked for from the page (focus, exposure, gain) between frames;
* the **turntable thread** performs the moves asked for ("next orientation" of the plan, ...)
  and reads the position while idle.

Coverage is accumulated per orientation: a frame counts for the orientation the turntable was
idle at during the whole capture (never during a move). The through-focus history keeps the
(focus setting, score) of recent frames; the peak is :func:`pipeline.assess.focus_peak`.

Device errors: every :class:`~drivers.errors.DriverError` becomes one line on the page, naming
the device (the drivers' messages already start with the device name). After
:class:`~drivers.errors.DeviceDisconnected` the device is closed and reopened every
``reconnect_s`` until it answers; the line then stays, greyed, saying since when it works again.

A Bayer camera's frame (a raw mosaic, its pattern in ``frame.extra["cfa"]``, e.g. ``"RGGB"``) is
assessed on its luma (:func:`pipeline.cfa.mosaic_luma`), and every :data:`COLOUR_REFRESH_S` its
planes are measured and each red and blue edge compared with green's (lateral chromatic
aberration: :func:`pipeline.tca.channel_offsets`), for the page's colour panel.

During a session (``harp session run --live``) the devices belong to the executor: a
:class:`LiveStation` created with ``camera=None`` captures nothing; it assesses the frames the
session passes to :meth:`LiveStation.show_frame` and shows the session's records
(:meth:`LiveStation.session_record`).
"""

from __future__ import annotations

import contextlib
import math
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers import CameraRanges, TurntableRanges
from drivers.errors import DeviceDisconnected, DriverError
from pipeline.assess import Assessment, Coverage, analysis_scale, assess_frame, empty_coverage, focus_peak
from pipeline.board import corner_coverage
from pipeline.cfa import measure_mosaic, mosaic_luma
from pipeline.tca import channel_offsets
from station.config import CheckConfig
from station.live.checks import live_warnings
from station.live.view import channels_view, display_size, encode_frame, view_of

HISTORY = 400
"""Frames kept in the through-focus history."""
THRESHOLD_REFRESH_S = 5.0
"""Edge thresholds are re-estimated at least this often (and whenever exposure, gain or scale change)."""
RESEARCH_S = 1.0
"""The strings are searched again at least this often; between searches they are tracked
(:func:`pipeline.assess.assess_frame` ``previous``): their figures measured afresh on every frame."""
MAX_TRACK_OFFSET_PX = 0.5
"""A tracked string further than this from where it was found: search again."""
COLOUR_REFRESH_S = 2.0
"""The per-channel edge offsets of a Bayer camera's frames are measured again at most this often
(every plane of the mosaic measured: several times a frame's assessment)."""


@dataclass
class DeviceProblem:
    """One device error line: ``active`` until the device works again (then ``recovered_at``)."""

    device: str
    message: str
    active: bool
    since: float
    recovered_at: float | None = None

    def to_dict(self) -> dict[str, Any]:
        stamp = time.strftime("%H:%M:%S", time.localtime(self.recovered_at)) if self.recovered_at else None
        return {"device": self.device, "message": self.message, "active": self.active, "recovered_at": stamp}


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


class LiveStation:
    """Live capture and assessment for the set-up page (module docstring).

    Parameters
    ----------
    camera, turntable : opened drivers (``turntable`` may be None; ``camera`` None: session mode,
        frames come from :meth:`show_frame`).
    orientations : the plan's orientations (stage degrees), for "next orientation".
    checks : the session's acceptance checks.
    expected_angle : stage degrees -> expected string angle in the image (the harp's offset and
        direction), or None.
    display_width : width of the frame sent to the page, px.
    reconnect_s : wait between attempts to reopen a disconnected device.
    """

    def __init__(
        self,
        camera: Any | None,
        turntable: Any | None = None,
        *,
        orientations: Sequence[float] = (),
        checks: CheckConfig = CheckConfig(),  # noqa: B008 (frozen)
        expected_angle: Callable[[float], float] | None = None,
        display_width: int = 960,
        reconnect_s: float = 0.5,
        capture_timeout_s: float = 5.0,
        move_timeout_s: float = 60.0,
        title: str = "live view",
    ) -> None:
        self.camera, self.turntable = camera, turntable
        self.orientations = tuple(float(o) for o in orientations)
        self.checks = checks
        self.expected_angle = expected_angle
        self.display_width = int(display_width)
        self.reconnect_s = float(reconnect_s)
        self.capture_timeout_s = float(capture_timeout_s)
        self.move_timeout_s = float(move_timeout_s)
        self.title = title
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._cam_jobs: queue.Queue[tuple[str, Any, Future[Any]]] = queue.Queue()
        self._tt_jobs: queue.Queue[tuple[str, Any, Future[Any]]] = queue.Queue()
        self._incoming: queue.Queue[tuple[Any, dict[str, Any]]] = queue.Queue(maxsize=1)
        self._problems: dict[str, DeviceProblem] = {}
        self._view: dict[str, Any] = {"frame_id": 0}
        self._jpeg: bytes | None = None
        self._frame_id = 0
        self._history: deque[tuple[float, float | None, float]] = deque(maxlen=HISTORY)
        self._coverage_by_stage: dict[float, Coverage] = {}
        self._coverage: Coverage | None = None
        self._thresholds: tuple[tuple[float, float, float], tuple[float, float], float] | None = None
        self._string_width: float | None = None
        self._cam_settings: dict[str, Any] = {}
        self._searched: tuple[Assessment, tuple[int, int, float | None], float] | None = None
        self._stage: float | None = None
        self._moving = False
        self._target: float | None = None
        self._move_epoch = 0  # incremented at every move start and end
        self._orientation_idx: int | None = None
        self._session: dict[str, Any] | None = None
        self.answer_board: Callable[[Any], dict[str, Any]] | None = None
        """During a session whose board views the operator places: what the page's ``board`` command calls
        (:meth:`station.session.operator.OperatorDesk.attach_page`)."""
        self._fps: deque[float] = deque(maxlen=10)
        self._assess_s: deque[float] = deque(maxlen=10)
        self.frames_assessed = 0
        self._channels: dict[str, Any] | None = None
        self._channels_at = -math.inf

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> LiveStation:
        self._spawn(self._frames_loop, "harp-live-assess")
        if self.camera is not None:
            self._spawn(self._camera_loop, "harp-live-camera")
        if self.turntable is not None:
            self._spawn(self._turntable_loop, "harp-live-turntable")
        return self

    def _spawn(self, fn: Callable[[], None], name: str) -> None:
        t = threading.Thread(target=fn, name=name, daemon=True)
        t.start()
        self._threads.append(t)

    def stop(self, timeout: float = 10.0) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout)
        self._threads = []

    def __enter__(self) -> LiveStation:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ what the page reads
    def state(self) -> dict[str, Any]:
        """The page's JSON: the last frame's figures plus devices, coverage, history, session."""
        with self._lock:
            v = dict(self._view)
            v["title"] = self.title
            v["errors"] = [p.to_dict() for p in self._problems.values()]
            v["turntable"] = self._turntable_state()
            v["camera"] = self._camera_state()
            v["coverage_total"] = self._coverage_total()
            v["focus_history"] = self._history_state()
            v["session"] = dict(self._session) if self._session is not None else None
            v["channels"] = self._channels
            if v["session"] is not None and v["session"].get("board"):  # the coverage, not every corner
                v["session"]["board"] = {k: x for k, x in v["session"]["board"].items() if k != "corners"}
            v["checks"] = {
                "min_lines": self.checks.min_lines,
                "max_saturated_fraction": self.checks.max_saturated_fraction,
                "min_dynamic_range": self.checks.min_dynamic_range,
                "angle_tolerance_deg": self.checks.angle_tolerance_deg,
            }
            v["rate_hz"] = self._rate(self._fps)
            v["assess_s"] = float(np.median(self._assess_s)) if self._assess_s else None
        return v

    def frame_jpeg(self) -> tuple[int, bytes | None]:
        with self._lock:
            return self._frame_id, self._jpeg

    @staticmethod
    def _rate(stamps: deque[float]) -> float | None:
        if len(stamps) < 2 or stamps[-1] <= stamps[0]:
            return None
        return (len(stamps) - 1) / (stamps[-1] - stamps[0])

    def _turntable_state(self) -> dict[str, Any] | None:
        if self.turntable is None:
            return None
        travel = None
        with contextlib.suppress(Exception):
            if isinstance(self.turntable, TurntableRanges):
                r = self.turntable.travel_range()
                travel = [r.minimum, r.maximum]
        return {
            "position_deg": self._stage,
            "moving": self._moving,
            "target_deg": self._target,
            "orientation_idx": self._orientation_idx,
            "orientations_deg": list(self.orientations),
            "travel_deg": travel,
            "controls": self._session is None,
        }

    def _camera_state(self) -> dict[str, Any] | None:
        if self.camera is None:
            return None
        return {"controls": self._session is None, **self._cam_settings}

    def _read_camera_settings(self) -> None:
        """Settings and ranges as the camera thread last read them (the web thread never touches the device)."""
        cam = self.camera
        out: dict[str, Any] = {}
        with contextlib.suppress(Exception):
            out.update(focus=cam.get_focus(), exposure_us=cam.get_exposure(), gain_db=cam.get_gain())
        if isinstance(cam, CameraRanges):
            ranges = (("focus", cam.focus_range), ("exposure_us", cam.exposure_range), ("gain_db", cam.gain_range))
            for name, fn in ranges:
                with contextlib.suppress(Exception):
                    r = fn()
                    out[f"{name}_range"] = None if r is None else [r.minimum, r.maximum]
        with self._lock:
            self._cam_settings = out

    def _coverage_total(self) -> dict[str, Any] | None:
        if self._coverage is None:
            return None
        d = self._coverage.to_dict()
        d["orientations_seen_deg"] = sorted(self._coverage_by_stage)
        return d

    def _history_state(self) -> dict[str, Any]:
        hist = list(self._history)
        t0 = hist[0][0] if hist else 0.0
        out: dict[str, Any] = {
            "t": [h[0] - t0 for h in hist],
            "focus": [h[1] for h in hist],
            "score": [h[2] if math.isfinite(h[2]) else None for h in hist],
            "peak": None,
        }
        known = [(f, s) for _, f, s in hist if f is not None and math.isfinite(s)]
        if known:
            peak = focus_peak([f for f, _ in known], [s for _, s in known])
            out["peak"] = None if peak is None else peak.to_dict()
        elif hist:
            scores = [h[2] for h in hist if math.isfinite(h[2])]
            if scores:
                out["peak"] = {"focus": None, "score": max(scores), "bracketed": False, "samples": len(scores)}
        return out

    # ------------------------------------------------------------------ commands from the page
    def command(self, action: str, value: Any = None) -> Future[Any]:
        """Queue an action; the Future resolves with its result or the one-line error.

        Actions: ``next``, ``previous`` (orientation of the plan), ``goto`` (degrees), ``home``,
        ``focus``, ``exposure_us``, ``gain_db`` (a value), ``reset_coverage``, ``reset_focus``; during a
        session, ``board`` (``capture``, ``skip`` or ``stop``: the answer to the board view asked for).
        """
        fut: Future[Any] = Future()
        if action == "board":
            wanted = self._session is not None and (self._session.get("board") or {}).get("wanted")
            if self.answer_board is None or not wanted:
                fut.set_exception(ValueError("no board view is asked for"))
                return fut
            try:
                fut.set_result(self.answer_board(value))
            except ValueError as exc:
                fut.set_exception(exc)
            return fut
        if self._session is not None and action not in ("reset_focus",):
            fut.set_exception(ValueError("a session is running: it drives the camera and the turntable"))
            return fut
        if action in ("next", "previous", "goto", "home"):
            if self.turntable is None:
                fut.set_exception(ValueError("no turntable is configured"))
            else:
                self._tt_jobs.put((action, value, fut))
        elif action in ("focus", "exposure_us", "gain_db"):
            if self.camera is None:
                fut.set_exception(ValueError("no camera"))
            else:
                self._cam_jobs.put((action, value, fut))
        elif action == "reset_coverage":
            with self._lock:
                self._coverage_by_stage.clear()
                self._coverage = None
            fut.set_result({"ok": True})
        elif action == "reset_focus":
            with self._lock:
                self._history.clear()
            fut.set_result({"ok": True})
        else:
            fut.set_exception(ValueError(f"unknown action {action!r}"))
        return fut

    # ------------------------------------------------------------------ device problems
    def _problem(self, device: str, exc: BaseException) -> None:
        with self._lock:
            old = self._problems.get(device)
            msg = _one_line(exc)
            if old is None or not old.active or old.message != msg:
                self._problems[device] = DeviceProblem(device, msg, True, time.time())

    def _recovered(self, device: str) -> None:
        with self._lock:
            p = self._problems.get(device)
            if p is not None and p.active:
                p.active, p.recovered_at = False, time.time()

    def _reopen(self, name: str, device: Any) -> bool:
        """Close and reopen a disconnected device; False (and its error on the page) while it stays away."""
        with contextlib.suppress(Exception):
            device.close()
        try:
            device.open()
        except (DriverError, OSError) as exc:
            self._problem(name, exc)
            return False
        return True

    # ------------------------------------------------------------------ camera thread
    def _camera_loop(self) -> None:
        cam = self.camera
        lost = False
        self._read_camera_settings()
        while not self._stop.is_set():
            if self._camera_jobs():
                self._read_camera_settings()
            if lost:
                if not self._reopen("camera", cam):
                    self._stop.wait(self.reconnect_s)
                    continue
                lost = False
                self._read_camera_settings()
            epoch, stage, moving = self._move_epoch, self._stage, self._moving
            try:
                frame = cam.capture(self.capture_timeout_s)
            except DeviceDisconnected as exc:
                self._problem("camera", exc)
                lost = True
                self._stop.wait(self.reconnect_s)
                continue
            except DriverError as exc:
                self._problem("camera", exc)
                self._stop.wait(min(self.reconnect_s, 0.2))
                continue
            self._recovered("camera")
            idle_stage = stage if (not moving and not self._moving and epoch == self._move_epoch) else None
            # hand the frame to the assessment thread; wait while it is busy with the previous one
            # (capture and assessment overlap, and no frame is rendered only to be dropped)
            while not self._stop.is_set():
                try:
                    self._incoming.put((frame, {"stage_deg": idle_stage}), timeout=0.1)
                    break
                except queue.Full:
                    continue

    def _camera_jobs(self) -> bool:
        """Apply the settings asked for; True when there were any."""
        did = False
        while True:
            try:
                action, value, fut = self._cam_jobs.get_nowait()
            except queue.Empty:
                return did
            did = True
            try:
                v = float(value)
                setter = {
                    "focus": self.camera.lock_focus,
                    "exposure_us": self.camera.set_exposure,
                    "gain_db": self.camera.set_gain,
                }
                fut.set_result({"ok": True, action: setter[action](v)})
            except (TypeError, ValueError, DriverError) as exc:
                fut.set_exception(ValueError(_one_line(exc)))

    def _colour(self, frame: Any, mosaic: np.ndarray, pattern: str) -> None:
        """A Bayer frame's per-channel edge offsets from green (:func:`pipeline.tca.channel_offsets`), at most
        every :data:`COLOUR_REFRESH_S`; a pattern that is not a Bayer one is a camera line on the page."""
        if time.monotonic() - self._channels_at < COLOUR_REFRESH_S:
            return
        self._channels_at = time.monotonic()
        try:
            m = measure_mosaic(mosaic, pattern)
        except ValueError as exc:
            self._problem("camera", ValueError(f"frame {frame.counter}: {exc}"))
            return
        view = channels_view(channel_offsets(m), m.pattern, frame.counter)
        with self._lock:
            self._channels = view

    def _process(self, frame: Any, idle_stage: float | None, session: dict[str, Any] | None = None) -> None:
        img = np.asarray(frame.image)
        h, w = img.shape
        t0 = time.perf_counter()
        pattern = (getattr(frame, "extra", None) or {}).get("cfa")
        if pattern is not None:  # a Bayer camera's raw mosaic: per-channel offsets; the figures on its luma
            self._colour(frame, img, str(pattern))
            img = np.rint(mosaic_luma(img)).astype(img.dtype)
        scale = analysis_scale(w, h, self._string_width)
        key = (float(frame.exposure_us), float(frame.gain_db), scale)
        th = None
        if (
            self._thresholds is not None
            and self._thresholds[0] == key
            and time.monotonic() - self._thresholds[2] < THRESHOLD_REFRESH_S
        ):
            th = self._thresholds[1]
        pose = (w, h, None if idle_stage is None else round(idle_stage, 3))
        prev = None
        if self._searched is not None and idle_stage is not None:
            last, last_pose, t_found = self._searched
            if last_pose == pose and time.monotonic() - t_found < RESEARCH_S and last.n_strings > 0:
                prev = last
        try:
            a: Assessment = assess_frame(img, scale=scale, thresholds=th, previous=prev)
            if prev is not None and not a.offset_px <= MAX_TRACK_OFFSET_PX:  # moved (or lost): search again
                a = assess_frame(img, scale=scale, thresholds=th)
        except ValueError as exc:
            self._problem("camera", ValueError(f"frame {frame.counter}: {exc}"))
            return
        if not a.tracked:
            self._searched = (a, pose, time.monotonic())
        if th is None and not a.tracked:
            self._thresholds = (key, a.thresholds, time.monotonic())
        if math.isfinite(a.string_width_px):
            self._string_width = a.string_width_px
        elif a.n_strings == 0:
            self._string_width = None  # search at the size-based scale again
        expected = None
        if self.expected_angle is not None and idle_stage is not None:
            expected = self.expected_angle(idle_stage)
        warnings = live_warnings(a, self.checks, expected)
        view = view_of(a, warnings, self.display_width)
        view["frame"] = {
            "counter": int(frame.counter),
            "timestamp": float(frame.timestamp),
            "exposure_us": float(frame.exposure_us),
            "gain_db": float(frame.gain_db),
            "focus": None if frame.focus is None else float(frame.focus),
            "stage_deg": idle_stage,
            "expected_angle_deg": expected,
        }
        if session:
            view["frame"].update(session)
        jpeg = encode_frame(img, self.display_width, a.exposure.full_scale)
        dt = time.perf_counter() - t0
        with self._lock:
            if idle_stage is not None:
                key_deg = round(idle_stage, 1)
                prev = self._coverage_by_stage.get(key_deg)
                self._coverage_by_stage[key_deg] = a.coverage if prev is None else prev.merge(a.coverage)
                total = self._coverage if self._coverage is not None else empty_coverage(w, h)
                if (total.width, total.height) != (w, h):
                    total, self._coverage_by_stage = empty_coverage(w, h), {key_deg: a.coverage}
                self._coverage = total.merge(a.coverage)
            self._history.append((time.time(), None if frame.focus is None else float(frame.focus), a.focus_score))
            self._frame_id += 1
            view["frame_id"] = self._frame_id
            self._view, self._jpeg = view, jpeg
            self._fps.append(time.monotonic())
            self._assess_s.append(dt)
            self.frames_assessed += 1

    # ------------------------------------------------------------------ turntable thread
    def _turntable_loop(self) -> None:
        tt = self.turntable
        lost = False
        last_poll = 0.0
        while not self._stop.is_set():
            if lost:
                if not self._reopen("turntable", tt):
                    self._stop.wait(self.reconnect_s)
                    continue
                lost = False
                last_poll = 0.0
            try:
                job = self._tt_jobs.get(timeout=0.05)
            except queue.Empty:
                job = None
            try:
                if job is not None:
                    self._turntable_job(*job)
                elif time.monotonic() - last_poll > 0.5:
                    pos = float(tt.position())
                    last_poll = time.monotonic()
                    with self._lock:
                        self._stage = pos
                        if self._orientation_idx is None:
                            self._orientation_idx = self._nearest_orientation(pos)
                    self._recovered("turntable")
            except DeviceDisconnected as exc:
                self._problem("turntable", exc)
                lost = True
                if job is not None and not job[2].done():
                    job[2].set_exception(ValueError(_one_line(exc)))
            except DriverError as exc:
                self._problem("turntable", exc)
                if job is not None and not job[2].done():
                    job[2].set_exception(ValueError(_one_line(exc)))
                self._stop.wait(0.2)

    def _nearest_orientation(self, pos: float) -> int | None:
        if not self.orientations:
            return None
        return int(np.argmin([abs(o - pos) for o in self.orientations]))

    def _turntable_job(self, action: str, value: Any, fut: Future[Any]) -> None:
        tt = self.turntable
        idx = self._orientation_idx
        if action in ("next", "previous"):
            if not self.orientations:
                fut.set_exception(ValueError("the configuration plans no orientations"))
                return
            n = len(self.orientations)
            if idx is None:
                idx = self._nearest_orientation(self._stage if self._stage is not None else self.orientations[0]) or 0
                idx = idx if action == "next" else (idx + 1) % n
            idx = (idx + (1 if action == "next" else -1)) % n
            target = self.orientations[idx]
        elif action == "goto":
            try:
                target = float(value)
            except (TypeError, ValueError):
                fut.set_exception(ValueError(f"goto: expected degrees, got {value!r}"))
                return
            idx = None
        else:  # home
            target = 0.0
        with self._lock:
            self._moving, self._target = True, target
            self._move_epoch += 1
        try:
            if action == "home":
                tt.home(self.move_timeout_s)
                pos = float(tt.position())
            else:
                pos = float(tt.move_to(target, self.move_timeout_s))
        except ValueError as exc:  # OutOfRange (a DeviceRejected and a ValueError): nothing moved
            fut.set_exception(ValueError(_one_line(exc)))
            return
        finally:
            with self._lock:
                self._moving = False
                self._move_epoch += 1
        with self._lock:
            self._stage = pos
            self._orientation_idx = idx if idx is not None else self._nearest_orientation(pos)
        self._recovered("turntable")
        fut.set_result({"ok": True, "position_deg": pos})

    # ------------------------------------------------------------------ session mode
    def session_record(self, record: dict[str, Any]) -> None:
        """Show a session record (progress, shot checks, fit figures, verdict) on the page."""
        with self._lock:
            s = self._session if self._session is not None else {"records": [], "shots": [], "fits": [], "qa": []}
            kind = record.get("kind")
            s["last"] = record
            s["records"] = (s["records"] + [record])[-30:]
            if kind == "shot":
                s["shots"] = (s["shots"] + [record])[-200:]
            elif kind == "fit":
                s["fits"] = s["fits"] + [record]
            elif kind == "qa":
                s["qa"] = s["qa"] + [record]
            elif kind in ("finished", "aborted"):
                s["state"] = kind
            if kind in ("board-ask", "board", "board-ok", "board-reject"):
                s["board"] = _board_state(s.get("board"), record)
            if "progress" in record:
                s["progress"] = record["progress"]
            self._session = s

    def begin_session(self, info: dict[str, Any]) -> None:
        with self._lock:
            self._session = {"records": [], "shots": [], "fits": [], "qa": [], "state": "running", **info}

    def show_board_preview(self, image: Any, corners: Any, reason: str | None) -> None:
        """A frame taken while the operator places the board (a session's camera-matrix stage), shown as
        the page's picture with the board's corners found in it (``corners`` (N, 2) pixels, or None and
        why not: ``reason``); no harp assessment."""
        img = np.asarray(image)
        h, w = img.shape[:2]
        full = 65535.0 if img.dtype == np.uint16 else 255.0
        dw, dh, f = display_size(w, h, self.display_width)
        jpeg = encode_frame(img, self.display_width, full)
        pts = [] if corners is None else np.round((np.asarray(corners) + 0.5) * f - 0.5, 1).tolist()
        with self._lock:
            self._frame_id += 1
            self._view = {
                "frame_id": self._frame_id,
                "display": {"width": dw, "height": dh, "factor": f},
                "board_preview": {"corners": pts, "found": corners is not None, "reason": reason},
                "warnings": [],
                "ok": corners is not None,
            }
            self._jpeg = jpeg

    def show_frame(self, frame: Any, stage_deg: float | None = None, **info: Any) -> None:
        """A frame the session captured, to assess on this station's thread.

        Never blocks the caller: a frame still waiting is replaced by the newer one.
        ``stage_deg``: the stage angle the frame was taken at, at rest (None: moving or unknown).
        """
        with contextlib.suppress(queue.Empty):
            self._incoming.get_nowait()
        with contextlib.suppress(queue.Full):
            self._incoming.put_nowait((frame, {"stage_deg": stage_deg, "session": info}))
        if self.camera is None:
            with self._lock:
                self._stage = stage_deg

    def _frames_loop(self) -> None:
        while not self._stop.is_set():
            try:
                frame, info = self._incoming.get(timeout=0.1)
            except queue.Empty:
                continue
            self._process(frame, info.get("stage_deg"), info.get("session"))


def _board_state(board: dict[str, Any] | None, record: dict[str, Any]) -> dict[str, Any]:
    """The page's board panel after a session record (``intrinsics.placement: operator``): the view asked
    for (``wanted``: instruction, why, the last rejection's problems; None while none is), the last
    verdict, and the board coverage of the focus setting's accepted views
    (:func:`pipeline.board.corner_coverage`: which cells of the image their corners reach)."""
    b = dict(board) if board else {"wanted": None, "last": None, "coverage": None, "focus_idx": None}
    f = record.get("focus_idx")
    if b.get("focus_idx") != f:  # a new focus setting: its own views
        b.update(focus_idx=f, corners=[], size=None, accepted=0, coverage=None)
    kind = record.get("kind")
    if kind == "board-ask":
        req = record.get("request") or {}
        b["wanted"] = {
            "view_idx": record.get("view_idx"),
            "attempt": record.get("attempt"),
            "instruction": req.get("instruction"),
            "why": req.get("why"),
            "centre": req.get("centre"),
            "problems": list(record.get("problems") or []),
        }
    elif kind == "board":
        b["wanted"] = None  # captured: being checked
    elif kind == "board-reject":
        b["wanted"] = None
        b["last"] = {
            "view_idx": record.get("view_idx"),
            "accepted": False,
            "reasons": list(record.get("reasons") or []),
        }
    elif kind == "board-ok":
        b["wanted"] = None
        pts = record.get("corners") or []
        b["corners"] = [*b.get("corners", []), pts]
        b["size"] = record.get("size")
        b["accepted"] = b.get("accepted", 0) + 1
        b["last"] = {"view_idx": record.get("view_idx"), "accepted": True, "corners": len(pts)}
    if b.get("size") and b.get("corners"):
        w, h = b["size"]
        cov = corner_coverage(b["corners"], int(w), int(h))
        b["coverage"] = {
            "nx": int(cov.covered.shape[1]),
            "ny": int(cov.covered.shape[0]),
            "covered": cov.covered.astype(int).tolist(),
            "fraction": cov.fraction,
            "missing": cov.missing(),
        }
    return b
