"""The one executor: performs a session's plan on a camera and a turntable.

Per focus setting it locks focus; per orientation it moves the turntable
(``move_to`` returns when idle), captures N frames, saves each atomically in
the session directory, averages them and checks the shot (exposure, strings
found, string angle = commanded orientation + harp offset within a
tolerance), re-capturing a rejected shot up to ``checks.max_recaptures``
times; then it fits that focus setting's correction with
leave-one-orientation-out cross-validation and stores the profile.

Each accepted shot's measured edges are kept in the session directory
(``measurements/*.npz``, :mod:`station.session.evidence`) and each focus
setting's bootstrap uncertainty map next to its profile, so that the session
report (``report=True``: written into ``DIR/report`` once the session has
finished) and ``harp qa --report`` need not measure anything again. The
cross-validation and bootstrap fits run on a process pool whose workers end
themselves if the session process is killed.

A camera that offers the optional ``set_capture_index(i)`` hook (the
simulator, :class:`drivers.sim.camera.SimulatedCamera`; real drivers need
not) is told before each capture which frame of the shot it is taking
(``attempt * frames_per_orientation + frame_idx``), so that a resumed
session receives the same frames as an uninterrupted one.

Device faults (:class:`drivers.errors.DriverError`) are retried with
exponential back-off (``capture.retries``); a disconnected device is closed
and reopened between attempts; a turntable fault (stall, limit, alarm) is
cleared with the driver's ``recover()`` (when it has one) and the stage
re-homed before the next attempt. A fault that persists, a device refusing a
command, or a shot that keeps failing its checks stops the session cleanly:
every saved frame stays in the session directory, an ``aborted`` record names
the cause, and :class:`SessionResult` carries a one-line message and exit
code 2. ``harp session resume`` then continues from there.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from drivers.errors import CaptureError, DeviceDisconnected, DeviceFault, DeviceRejected, DriverError
from drivers.protocols import Camera, Turntable
from station import __version__
from station.calibration import Calibration, calibrate_shots
from station.profile import Profile
from station.session.directory import SessionDir
from station.session.evidence import measurement_arrays, uncertainty_arrays
from station.session.plan import (
    Capture,
    Fit,
    LockFocus,
    Measure,
    Move,
    Save,
    Settle,
    Step,
    Store,
    capture_steps,
    plan_session,
)
from station.session.processing import (
    ShotMeasurement,
    average_frames,
    exposure_problems,
    full_scale,
    garbage_rows,
    measure_shot,
    shot_problems,
)

#: a stage read-back further than this from the target is a fault (degrees)
POSITION_TOLERANCE_DEG = 0.05

EXIT_OK = 0
EXIT_ABORTED = 2


class SessionAborted(Exception):
    """The session cannot go on; ``str()`` is the one-line reason."""


@dataclass
class FocusSummary:
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


class Executor:
    """Runs :func:`station.plan.plan_session` for ``session`` on open devices.

    Parameters
    ----------
    session : the session directory (its ``config`` is the plan's input).
    camera, turntable : opened drivers satisfying the protocols.
    store : a :class:`station.store.ProfileStore` (``None``: do not store).
    console : a ``rich.console.Console`` for progress and the summary
        (``None``: silent).
    sleep : the back-off sleep (tests pass a recorder).
    report : write the session report into ``DIR/report`` once the session
        has finished (Markdown ``report.md`` and ``index.html`` with PNG plots).
    """

    def __init__(
        self,
        session: SessionDir,
        camera: Camera,
        turntable: Turntable,
        *,
        store=None,
        console=None,
        sleep: Callable[[float], None] = time.sleep,
        report: bool = False,
    ):
        self.session = session
        self.config = session.config
        self.camera = camera
        self.turntable = turntable
        self.store = store
        self.console = console
        self.sleep = sleep
        self.report = report
        self._pending: dict[tuple[int, int, int], object] = {}
        self._shots: dict[tuple[int, int], ShotMeasurement] = {}
        self._stage_deg: float | None = None
        self._focus: float | None = None
        self._summary: dict[int, FocusSummary] = {
            f: FocusSummary(f, v) for f, v in enumerate(self.config.focus_settings)
        }
        self._size: tuple[int, int] | None = None
        self.faults = 0
        self.frames_saved = 0
        self._pool = None

    # ================================================================ run
    def run(self) -> SessionResult:
        s = self.session
        kind = "resume" if any(True for _ in s.of_kind("start")) else "start"
        s.append({"kind": "start" if kind == "start" else "resume", "software_version": __version__})
        steps = list(plan_session(self.config, s.done_keys()))
        for r in s.of_kind("stored"):
            self._summary[r["focus_idx"]].profile_id = r.get("profile_id")
        progress = self._progress()
        try:
            return self._run(s, steps, progress)
        finally:
            if self._pool is not None:
                self._pool.shutdown(cancel_futures=True)
                self._pool = None

    def _run(self, s, steps, progress) -> SessionResult:
        try:
            with progress:
                self._cap_task = progress.add_task("capture", total=sum(isinstance(x, Capture) for x in steps) or 1)
                self._proc_task = progress.add_task(
                    "process", total=sum(isinstance(x, (Measure, Fit, Store)) for x in steps) or 1
                )
                self._prog = progress
                self._prepare()
                for step in steps:
                    self.perform(step)
        except KeyboardInterrupt:
            s.append({"kind": "aborted", "reason": "interrupted by the user"})
            raise
        except SessionAborted as exc:
            msg = f"session stopped: {exc}; {self.frames_saved} new frames kept in {s.path}"
            s.append({"kind": "aborted", "reason": str(exc)})
            self._print_summary()
            return self._result(EXIT_ABORTED, msg)
        self._print_summary()
        quality = self._quality()
        if self.report and quality is not None:
            self._write_report(*quality)
        s.append({"kind": "finished"})
        return self._result(EXIT_OK, f"session finished: {s.path}")

    def _quality(self):
        """QA verdict of every profile of the session, and the focus-interpolation
        error (leave one calibrated focus out) — recorded, stored and printed.
        Returns ``(models, verdicts, overall, interpolation)`` (None: no profile)."""
        from station.qa.verdicts import combine, interpolation_error, qa_verdict, session_profiles

        profiles = session_profiles(self.session.path)
        if not profiles:
            return None
        verdicts = []
        for f, p in profiles:
            focus = p.focus if p.focus is not None else self.config.focus_settings[f]
            v = qa_verdict(p, self.config.qa)
            verdicts.append(v)
            pid = self._summary[f].profile_id if f in self._summary else None
            self.session.append(
                {"kind": "qa", "focus_idx": f, "verdict": v.verdict, "reasons": list(v.reasons), "metrics": v.metrics}
            )
            if self.store is not None:
                self.store.put_qa_result(
                    verdict=v.verdict,
                    reasons=list(v.reasons),
                    metrics=v.metrics,
                    profile_id=pid,
                    session_dir=str(self.session.path.resolve()),
                )
                if pid is not None:
                    self.store.record_verdict(pid, v)
            self._note(
                f"QA focus {focus:g}: [{'green' if v.passed else 'red'}]{v.verdict}[/] "
                + ("; ".join(v.reasons) if v.reasons else "; ".join(c.text for c in v.checks))
            )
        w, h = profiles[0][1].width, profiles[0][1].height
        try:
            loo = interpolation_error(
                {(p.focus if p.focus is not None else self.config.focus_settings[f]): p.model for f, p in profiles},
                w,
                h,
            )
        except ValueError as exc:
            loo = []
            self._note(f"focus interpolation: not available ({exc})")
        for e in loo:
            self.session.append(
                {
                    "kind": "interpolation",
                    "focus": e.focus,
                    "rms_px": e.rms_px,
                    "max_px": e.max_px,
                    "scheme": "leave one focus out",
                }
            )
            self._note(
                f"focus interpolation error at {e.focus:g} (left out, interpolated from the "
                f"others): RMS {e.rms_px:.4f} px, max {e.max_px:.4f} px"
            )
        overall = combine(verdicts)
        self.session.append({"kind": "qa_session", "verdict": overall})
        self._note(f"QA verdict: [{'bold green' if overall == 'PASS' else 'bold red'}]{overall}")
        return profiles, verdicts, overall, loo

    def _write_report(self, profiles, verdicts, overall, interpolation) -> None:
        """The session report (:func:`station.report.write_session_report`) into ``DIR/report``,
        from the measurements and uncertainty maps the session kept (nothing re-measured)."""
        from station.qa.report import write_session_report

        cfg = self.config
        title = f"{cfg.lens.label()} on {cfg.camera_body.label()}, session {self.session.path.name}"
        try:
            path = write_session_report(
                self.session,
                self.session.path / "report",
                title,
                profiles,
                verdicts,
                overall,
                thresholds=cfg.qa,
                interpolation=interpolation,
            )
        except (OSError, ValueError) as exc:  # the profiles are stored; say so, do not lose the session
            self.session.append({"kind": "report", "failure": f"{type(exc).__name__}: {exc}"})
            self._note(f"[red]report not written: {type(exc).__name__}: {exc}")
            return
        rel = path.relative_to(self.session.path)
        self.session.append({"kind": "report", "file": str(rel), "html": str(rel.with_name("index.html"))})
        self._note(f"report: {path} (and {path.with_name('index.html').name})")

    def _result(self, code: int, msg: str) -> SessionResult:
        return SessionResult(code, msg, self.frames_saved, self.faults, list(self._summary.values()))

    def _prepare(self) -> None:
        cap = self.config.capture
        self._retry("set exposure", lambda: self.camera.set_exposure(cap.exposure_us), self.camera)
        self._retry("set gain", lambda: self.camera.set_gain(cap.gain_db), self.camera)
        self._retry("home turntable", lambda: self.turntable.home(timeout=cap.move_timeout_s), self.turntable)
        w, h = self.camera.sensor_size
        self._size = (int(w), int(h))

    # ============================================================== steps
    def perform(self, step: Step) -> None:
        """Perform one step of the plan."""
        handler = getattr(self, "_do_" + type(step).__name__)
        handler(step)

    def _do_LockFocus(self, step: LockFocus) -> None:
        got = self._retry(f"lock focus {step.focus:g}", lambda: self.camera.lock_focus(step.focus), self.camera)
        self._focus = step.focus
        self.session.append({"kind": "focus", "focus_idx": step.focus_idx, "focus": step.focus, "read_back": got})

    def _do_Move(self, step: Move) -> None:
        timeout = self.config.capture.move_timeout_s

        def move():
            got = float(self.turntable.move_to(step.degrees, timeout=timeout))
            if abs(got - step.degrees) > POSITION_TOLERANCE_DEG:
                raise DeviceFault(f"turntable stopped at {got:.3f} deg, commanded {step.degrees:g}")
            return got

        self._stage_deg = None
        self._stage_deg = self._retry(f"move turntable to {step.degrees:g} deg", move, self.turntable)

    def _do_Settle(self, step: Settle) -> None:
        time.sleep(step.seconds)

    def _do_Capture(self, step: Capture) -> None:
        timeout = self.config.capture.timeout_s
        # Optional camera hook (not in the Camera protocol; the simulator has it): which
        # capture at this pose comes next. Frames are numbered per shot and attempt, so a
        # resumed session that captures only the missing frames asks for the same ones.
        set_index = getattr(self.camera, "set_capture_index", None)
        index = (
            self.session.attempt(step.focus_idx, step.orientation_idx) * self.config.capture.frames_per_orientation
            + step.frame_idx
        )

        def grab():
            if set_index is not None:
                set_index(index)
            frame = self.camera.capture(timeout=timeout)
            img = np.asarray(frame.image)
            if img.ndim != 2 or img.dtype not in (np.uint8, np.uint16):
                raise CaptureError(f"corrupt frame: {img.dtype} array of shape {img.shape}")
            if self._size and img.shape != (self._size[1], self._size[0]):
                raise CaptureError(f"corrupt frame: shape {img.shape}, sensor is {self._size[0]}x{self._size[1]}")
            bad = garbage_rows(img, full_scale(img.dtype, _bit_depth(frame)))
            if bad:
                raise CaptureError(f"corrupt frame: {bad} rows of garbage")
            return frame

        where = f"capture focus {step.focus_idx} orientation {step.orientation_idx} frame {step.frame_idx}"
        self._pending[(step.focus_idx, step.orientation_idx, step.frame_idx)] = self._retry(where, grab, self.camera)

    def _do_Save(self, step: Save) -> None:
        frame = self._pending.pop((step.focus_idx, step.orientation_idx, step.frame_idx))
        meta = {
            "timestamp": frame.timestamp,
            "exposure_us": frame.exposure_us,
            "gain_db": frame.gain_db,
            "focus": frame.focus,
            "counter": frame.counter,
            "camera": [frame.camera.vendor, frame.camera.model, frame.camera.serial],
            "stage_deg": self._stage_deg,
            "commanded_deg": self.config.capture.orientations_deg[step.orientation_idx],
            "bit_depth": _bit_depth(frame),
            "extra": _jsonable(frame.extra),
        }
        self.session.write_frame(step.focus_idx, step.orientation_idx, step.frame_idx, np.asarray(frame.image), meta)
        self.frames_saved += 1
        self._advance(self._cap_task)

    def _do_Measure(self, step: Measure) -> None:
        f, o = step.focus_idx, step.orientation_idx
        checks = self.config.capture.checks
        summary = self._summary[f]
        while True:
            problems, m = self._check_shot(f, o)
            if not problems:
                break
            attempt = self.session.attempt(f, o)
            self.session.append(
                {"kind": "reject", "focus_idx": f, "orientation_idx": o, "attempt": attempt, "reasons": problems}
            )
            self._note(f"[yellow]re-capturing focus {f} orientation {o}: {'; '.join(problems)}")
            if attempt >= checks.max_recaptures:
                raise SessionAborted(
                    f"shot focus {f} orientation {o} failed its checks {attempt + 1} times: {'; '.join(problems)}"
                )
            summary.recaptures += 1
            if self._focus != self.config.focus_settings[f]:
                self._do_LockFocus(LockFocus(f, self.config.focus_settings[f]))
            for sub in capture_steps(self.config, f, o):
                self.perform(sub)
        self._shots[(f, o)] = m
        summary.shots += 1
        summary.lines += m.n_lines
        attempt = self.session.attempt(f, o)
        saved = self.session.write_arrays(f"measurements/f{f}_o{o}_a{attempt}.npz", measurement_arrays(m.measurement))
        self.session.append(
            {
                "kind": "measure",
                "focus_idx": f,
                "orientation_idx": o,
                "attempt": attempt,
                "n_lines": m.n_lines,
                "d": m.d,
                "d_max": m.d_max,
                "angle_deg": m.angle_deg,
                **saved,
            }
        )
        self._advance(self._proc_task)

    def _check_shot(self, f: int, o: int) -> tuple[list[str], ShotMeasurement | None]:
        records = self.session.frames(f, o)
        n = self.config.capture.frames_per_orientation
        if len(records) != n:  # cannot happen unless the directory was tampered with
            raise SessionAborted(f"focus {f} orientation {o}: {len(records)} of {n} frames on disk")
        images = [self.session.read_frame(r) for r in records]
        bit_depth = records[0]["meta"].get("bit_depth")
        image = average_frames(images)
        problems = exposure_problems(image, full_scale(images[0].dtype, bit_depth), self.config.capture.checks)
        if problems:
            return problems, None
        m = measure_shot(image, self.config.pipeline)
        stage = records[-1]["meta"].get("stage_deg")
        if stage is None:
            stage = self.config.capture.orientations_deg[o]
        expected = self.config.station.harp.expected_angle(stage)
        return shot_problems(m, expected, self.config.capture.checks), m

    def _do_Fit(self, step: Fit) -> None:
        f = step.focus_idx
        n_o = len(self.config.capture.orientations_deg)
        shots = [self._shots[(f, o)] for o in range(n_o)]
        w, h = self._image_size(f)
        pc = self.config.pipeline
        cal = calibrate_shots(
            [list(s.lines) for s in shots],
            w,
            h,
            pc.spec,
            holdout="orientations",
            bootstrap=pc.bootstrap,
            seed=pc.seed + 1000 * f,
            map_fn=self._map_fn(),
        )
        self._summary[f].calibration = cal
        if cal.failure:
            self.session.append({"kind": "fit", "focus_idx": f, "failure": cal.failure})
            raise SessionAborted(f"fit of focus setting {self.config.focus_settings[f]:g} failed: {cal.failure}")
        unc_file = {}
        if cal.uncertainty is not None:
            saved = self.session.write_arrays(f"profiles/focus{f}_uncertainty.npz", uncertainty_arrays(cal.uncertainty))
            unc_file = {"uncertainty_file": saved["file"], "uncertainty_sha256": saved["sha256"]}
        m = cal.merit
        unc = m.field_uncertainty
        self.session.append(
            {
                "kind": "fit",
                "focus_idx": f,
                "model": cal.fit.model.to_dict(),
                **unc_file,
                "spec": cal.spec.to_dict() if cal.spec is not None else None,
                "fit_d": m.fit.d if m.fit else None,
                "fit_d_max": m.fit.d_max if m.fit else None,
                "holdout_d": m.holdout.d if m.holdout else None,
                "holdout_d_max": m.holdout.d_max if m.holdout else None,
                "holdout_per_orientation": list(m.holdout.per_orientation_d) if m.holdout else [],
                "uncertainty_rms": unc.rms if unc else None,
                "uncertainty_max": unc.max if unc else None,
                "details": dict(cal.details),
            }
        )
        self._advance(self._proc_task)

    def _map_fn(self):
        """``map`` over a process pool when ``pipeline.workers`` > 1 (created once)."""
        n = self.config.pipeline.workers
        if n <= 1:
            return map
        if self._pool is None:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor

            ctx = mp.get_context("forkserver")  # not fork: this process runs device threads
            ctx.set_forkserver_preload(["station.calibration", "pipeline.fit", "pipeline.uncertainty"])
            _start_forkserver_ignoring_sigint()
            self._pool = ProcessPoolExecutor(
                max_workers=n, mp_context=ctx, initializer=_exit_with_session, initargs=(os.getpid(),)
            )
        return self._pool.map

    def _image_size(self, f: int) -> tuple[int, int]:
        h, w = self.session.read_frame(self.session.frames(f, 0)[0], verify=False).shape
        return w, h

    def _do_Store(self, step: Store) -> None:
        from station.files import write_profile
        from station.provenance import make_provenance

        f = step.focus_idx
        cfg = self.config
        cal = self._summary[f].calibration
        w, h = self._image_size(f)
        frames = [
            self.session.path / r["file"]
            for o in range(len(cfg.capture.orientations_deg))
            for r in self.session.frames(f, o)
        ]
        path = self.session.path / "profiles" / f"focus{f}.yaml"
        profile = cal.profile(
            w,
            h,
            provenance=make_provenance(
                frames,
                t=cfg.pipeline.t,
                command="harp session",
                station=cfg.station.id,
                session_dir=str(self.session.path.resolve()),
            ),
            lens=cfg.lens,
            camera=cfg.camera_body,
            focus=cfg.focus_settings[f],
            selection=None if cal.selection is not None else {"reason": "pipeline.model of the configuration"},
        )
        profile = profile.with_(
            details={
                **profile.details,
                "model_file": str(path),
                "orientations_deg": list(cfg.capture.orientations_deg),
                "frames_per_orientation": cfg.capture.frames_per_orientation,
                "t": cfg.pipeline.t,
            }
        )
        write_profile(path, profile)
        profile_id = None
        if self.store is not None:
            profile_id = self.store.put_profile(profile)
            profile = profile.with_(id=profile_id)
        self._summary[f].profile = profile
        self._summary[f].profile_id = profile_id
        self.session.append(
            {"kind": "stored", "focus_idx": f, "profile_id": profile_id, "model_file": f"profiles/{path.name}"}
        )
        self._advance(self._proc_task)

    # ============================================================ faults
    def _retry(self, what: str, fn: Callable, device=None):
        """Call ``fn`` with bounded retries and exponential back-off."""
        rc = self.config.capture.retries
        delay = rc.backoff_s
        for attempt in range(1, rc.attempts + 1):
            try:
                return fn()
            except DeviceRejected as exc:
                self._fault(what, exc, attempt)
                raise SessionAborted(f"{what}: device refused: {exc}") from None
            except (DriverError, OSError) as exc:
                self._fault(what, exc, attempt)
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

    def _fault(self, what: str, exc: Exception, attempt: int) -> None:
        self.faults += 1
        self.session.append(
            {"kind": "fault", "what": what, "error": type(exc).__name__, "message": str(exc), "attempt": attempt}
        )

    def _recover_turntable(self) -> None:
        """After a stall / limit / alarm: clear it (driver ``recover()``) and re-home,
        since a stepper that stalled no longer knows where it is."""
        try:
            recover = getattr(self.turntable, "recover", None)
            if recover is not None:
                cleared = recover()
                self._note(f"[yellow]turntable recovered (cleared {cleared or 'nothing'}); homing")
            self.turntable.home(timeout=self.config.capture.move_timeout_s)
        except (DriverError, OSError) as exc:
            self._note(f"[yellow]turntable recovery failed: {type(exc).__name__}: {exc}")

    def _reopen(self, device) -> None:
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

    # ============================================================= output
    def _progress(self):
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        if self.console is None:
            return _NoProgress()
        return Progress(
            TextColumn("{task.description:>8}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=self.console,
            transient=False,
        )

    def _advance(self, task) -> None:
        self._prog.advance(task)

    def _note(self, text: str) -> None:
        if self.console is not None:
            self.console.print(text)

    def _print_summary(self) -> None:
        if self.console is None:
            return
        from rich.table import Table

        cfg = self.config
        t = Table(title=f"{cfg.lens.label()} on {cfg.camera_body.label()}\n{self.session.path}")
        for col in (
            "focus",
            "shots",
            "recapt.",
            "edges",
            "fit d",
            "fit d_max",
            "holdout d",
            "holdout d_max",
            "unc. rms",
            "unc. max",
            "model",
            "profile",
        ):
            t.add_column(col, justify="right")
        fmt = lambda v: "-" if v is None or not np.isfinite(v) else f"{v:.4f}"  # noqa: E731
        for s in self._summary.values():
            cal = s.calibration
            m = cal.merit if cal is not None else None
            fit, hold, unc = (m.fit, m.holdout, m.field_uncertainty) if m is not None else (None, None, None)
            t.add_row(
                f"{s.focus:g}",
                str(s.shots),
                str(s.recaptures),
                str(s.lines),
                fmt(fit.d if fit else None),
                fmt(fit.d_max if fit else None),
                fmt(hold.d if hold else None),
                fmt(hold.d_max if hold else None),
                fmt(unc.rms if unc else None),
                fmt(unc.max if unc else None),
                cal.fit.model.name if cal is not None and cal.fit else "-",
                f"#{s.profile_id}" if s.profile_id is not None else "-",
            )
        self.console.print(t)
        self.console.print(f"frames saved this run: {self.frames_saved}, device faults: {self.faults}")


class _NoProgress:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None

    def add_task(self, *a, **k):
        return 0

    def advance(self, *a, **k):
        return None


def _start_forkserver_ignoring_sigint() -> None:
    """Start multiprocessing's forkserver with SIGINT ignored (inherited through
    exec): it spends a second or two importing the preloaded modules before it
    ignores SIGINT itself, and a Ctrl-C to the process group in that time would
    print its KeyboardInterrupt traceback. Only the session process handles Ctrl-C."""
    from multiprocessing import forkserver

    if threading.current_thread() is not threading.main_thread():
        forkserver.ensure_running()  # signal handlers can only be set from the main thread
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        forkserver.ensure_running()
    finally:
        signal.signal(signal.SIGINT, old)


def _exit_with_session(pid: int, period_s: float = 0.5) -> None:
    """Process-pool initializer: the worker ends itself once the session process
    ``pid`` is gone. A SIGKILLed session cannot shut its pool down, and its idle
    workers would otherwise wait on the pool's queue (and keep its forkserver) forever.
    Ctrl-C reaches the whole process group: the session process handles it (the
    frames are kept, the pool is shut down), so the workers ignore SIGINT instead
    of each printing a KeyboardInterrupt traceback."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def watch():
        while True:
            time.sleep(period_s)
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                os._exit(0)
            except PermissionError:  # alive, owned by someone else (cannot happen for our parent)
                continue

    threading.Thread(target=watch, name="harp-session-watch", daemon=True).start()


def _bit_depth(frame) -> int | None:
    extra = frame.extra if isinstance(frame.extra, dict) else {}
    bd = extra.get("bit_depth")
    return int(bd) if isinstance(bd, (int, float)) and bd > 0 else None


def _jsonable(value):
    """``value`` if it survives JSON, else its ``repr`` (driver extras may be anything)."""
    import json

    from station.session.directory import json_default

    try:
        return json.loads(json.dumps(value, default=json_default))
    except (TypeError, ValueError):
        return repr(value)
