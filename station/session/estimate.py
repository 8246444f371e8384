"""How long a session will take, from its plan alone (``harp session plan CONFIG``; no device touched).

:func:`estimate_plan` walks :func:`station.session.plan.plan_session` (every shot taken to
pass) and adds up, per step:

* a move: the angle to travel at the turntable's speed (trapezoidal profile: speed and
  acceleration), plus :data:`MOVE_OVERHEAD_S` for the commands and the idle poll; the speed
  is the emulator's for a simulated station, else :data:`TURNTABLE_SPEED_DEG_S` (an
  assumption the output states: real stages are configured per installation);
* settling: ``capture.settle_s``;
* a frame: the exposure plus :data:`FRAME_OVERHEAD_S` (trigger, read-out, transfer, the
  atomic write) plus, for the simulated camera, rendering (:data:`RENDER_S_PER_MPX`);
* measuring a shot: :data:`MEASURE_S_PER_MPX` per megapixel of the frame;
* a fit: the full fit and one leave-one-orientation-out refit per orientation
  (:data:`FIT_S_PER_ORIENTATION` each), then the bootstrap replicates (as many refits) spread
  over ``pipeline.workers`` processes;
* the camera-matrix stage (``intrinsics``): each board view a move and a frame (placed by the
  operator: :data:`PLACE_BOARD_S` and a frame), then :data:`KFIT_S_PER_VIEW` per megapixel and view for
  the board and the adjustment;
* once at the end: QA and the report (:data:`REPORT_S_PER_FOCUS` per focus setting).

Every focus setting has the same steps when every shot passes, so the plan of the first is walked
and repeated for the others; only their first move differs (from the previous focus setting's last
orientation instead of the home position). A plan of 100000 orientations is estimated in a second
or two, not the minutes walking every one of its steps would take.

A plan longer than :data:`WARN_PLAN_HOURS` is warned of by ``harp config check`` and
``harp session plan`` (:func:`long_plan`); one longer than :data:`CONFIRM_PLAN_HOURS` is started by
``harp session run`` only with ``--yes``.

The processing constants were measured on the demo session (``benchmarks/station_demo.py``
prints the estimate beside the measured wall time); a slower machine, a busy one, or a lens
with more strings takes longer. It is an estimate for planning a line, not a promise.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from station.config import Config
from station.session.plan import (
    BoardView,
    Capture,
    EstimateK,
    Fit,
    LockFocus,
    Measure,
    Move,
    Settle,
    Store,
    plan_session,
)

TURNTABLE_SPEED_DEG_S = 20.0
"""Assumed speed of a real turntable (deg/s) when the configuration does not simulate one."""
TURNTABLE_ACCEL_DEG_S2 = 40.0
"""Assumed acceleration of a real turntable (deg/s²)."""
SHIFT_SPEED_MM_S = 10.0
"""Assumed speed of the linear stage that carries the turntable (two-axis capture, mm/s)."""
MOVE_OVERHEAD_S = 0.05
FOCUS_OVERHEAD_S = 0.2
FRAME_OVERHEAD_S = 0.05
RENDER_S_PER_MPX = 0.10
MEASURE_S_PER_MPX = 0.35
FIT_S_PER_ORIENTATION = 0.12
REPORT_S_PER_FOCUS = 2.0
KFIT_S_PER_VIEW = 0.3
"""The camera-matrix stage: finding the board in a view and its share of the adjustment (s per megapixel)."""
PLACE_BOARD_S = 20.0
"""Assumed time an operator takes to place the board as a view asks (``intrinsics.placement: operator``)."""

WARN_PLAN_HOURS = 1.0
"""A plan estimated longer than this is warned of (``harp config check``, ``harp session plan``)."""
CONFIRM_PLAN_HOURS = 4.0
"""A plan estimated longer than this is started by ``harp session run`` only with ``--yes``."""


@dataclass(frozen=True)
class PlanRow:
    """One orientation of one focus setting (or a fit): what happens and how long it takes (s)."""

    focus_idx: int
    focus: float
    what: str
    orientation_deg: float | None = None
    frames: int = 0
    seconds: float = 0.0
    shift_mm: float | None = None
    """The linear stage's position of a capture row (``capture.shift_positions_mm``); None: no stage."""
    twin: bool = False
    """A capture row of the twin (``capture.twin_deg``): compared with the first shot at its angle, not fitted."""


@dataclass(frozen=True)
class PlanEstimate:
    """The plan as rows, its totals and the assumptions behind the duration."""

    rows: list[PlanRow]
    frames: int
    moves: int
    focus_locks: int
    fits: int
    seconds: float
    assumptions: list[str] = field(default_factory=list)


def move_seconds(distance_deg: float, speed: float, accel: float) -> float:
    """Time of a trapezoidal (or triangular) move over ``distance_deg``."""
    d = abs(distance_deg)
    if d == 0:
        return 0.0
    d_ramp = speed * speed / accel  # accelerating to full speed and back
    if d <= d_ramp:
        return 2.0 * math.sqrt(d / accel)
    return 2.0 * speed / accel + (d - d_ramp) / speed


def _sensor_mpx(config: Config) -> float | None:
    s = config.station.camera.settings
    w, h = s.get("width"), s.get("height")
    if isinstance(w, (int, float)) and isinstance(h, (int, float)) and w > 0 and h > 0:
        return float(w) * float(h) / 1e6
    roi = s.get("roi")
    if isinstance(roi, (list, tuple)) and len(roi) == 4:
        return float(roi[2]) * float(roi[3]) / 1e6
    return None


def estimate_plan(config: Config) -> PlanEstimate:
    """The capture plan of ``config`` with an estimated duration (see the module docstring)."""
    cap = config.capture
    assumptions = []
    if config.simulation is not None:
        emu = config.simulation.emulator
        speed = float(emu.get("speed_deg_s", 360.0))
        accel = float(emu.get("accel_deg_s2", 3600.0))
        assumptions.append(f"simulated turntable: {speed:g} deg/s, {accel:g} deg/s²")
    else:
        speed, accel = TURNTABLE_SPEED_DEG_S, TURNTABLE_ACCEL_DEG_S2
        assumptions.append(f"turntable speed assumed {speed:g} deg/s, acceleration {accel:g} deg/s² (not configured)")
    if config.intrinsics is not None and config.intrinsics.placement == "operator":
        assumptions.append(f"the operator places each board view in {PLACE_BOARD_S:g} s (assumed)")
    mpx = _sensor_mpx(config)
    if mpx is None:
        mpx = 5.0
        assumptions.append("sensor size not in the configuration: 5 megapixels assumed")
    render = RENDER_S_PER_MPX * mpx if config.station.camera.driver == "sim" else 0.0
    frame_s = cap.exposure_us / 1e6 + FRAME_OVERHEAD_S + render
    n_o = len(cap.fitted)  # the fit's shots (a twin is compared, not fitted)
    fitted = frozenset(cap.fitted)  # asked of every row: a tuple would make a long plan quadratic
    pc = config.pipeline
    fit_s = FIT_S_PER_ORIENTATION * mpx / 1.23 * ((n_o + 1) + pc.bootstrap / max(1, pc.workers))
    first: list[PlanRow] = []  # the first focus setting's rows; the others repeat them
    stage = 0.0  # a session homes the turntable first
    tilt = 0.0  # the tilt axis (intrinsics.placement: stage) starts at rest at 0
    shift: float | None = None  # the linear stage (capture.shift_positions_mm): where it is, unknown at first
    if cap.shift_positions_mm:
        assumptions.append(f"linear stage speed assumed {SHIFT_SPEED_MM_S:g} mm/s (not configured)")
    frames = moves = locks = fits = 0
    current: dict[str, float] = {}
    for step in plan_session(dataclasses.replace(config, focus_settings=config.focus_settings[:1])):
        match step:
            case LockFocus():
                locks += 1
                current["extra"] = current.get("extra", 0.0) + FOCUS_OVERHEAD_S
            case Move(focus_idx=f, orientation_idx=o, degrees=deg, shift_mm=mm):
                moves += 1
                current = {"f": f, "o": o, "deg": deg, "frames": 0, "s": current.get("extra", 0.0)}
                current["s"] += MOVE_OVERHEAD_S + move_seconds(deg - stage, speed, accel)
                stage = deg
                if mm is not None and mm != shift:  # the linear stage under the turntable (two-axis capture)
                    current["s"] += MOVE_OVERHEAD_S + abs(mm - (mm if shift is None else shift)) / SHIFT_SPEED_MM_S
                    shift = mm
            case Settle(seconds=sec):
                current["s"] = current.get("s", 0.0) + sec
            case Capture():
                frames += 1
                current["frames"] = current.get("frames", 0) + 1
                current["s"] = current.get("s", 0.0) + frame_s
            case Measure(focus_idx=f, orientation_idx=o):
                current["s"] = current.get("s", 0.0) + MEASURE_S_PER_MPX * mpx
                first.append(
                    PlanRow(
                        f,
                        config.focus_settings[f],
                        "capture + measure"
                        + ("" if cap.shifts_mm[o] is None else f" at {cap.shifts_mm[o]:g} mm")
                        + ("" if o in fitted else " (the twin: compared, not fitted)"),
                        cap.angles_deg[o],
                        int(current.get("frames", 0)),
                        float(current["s"]),
                        cap.shifts_mm[o],
                        o not in fitted,
                    )
                )
                current = {}
            case Fit(focus_idx=f):
                fits += 1
                what = f"fit ({n_o} orientations held out in turn" + (
                    f", {pc.bootstrap} bootstrap replicates)" if pc.bootstrap else ")"
                )
                first.append(PlanRow(f, config.focus_settings[f], what, seconds=fit_s))
            case BoardView(focus_idx=f, degrees=None):
                frames += 1
                s = current.pop("extra", 0.0) + PLACE_BOARD_S + frame_s
                first.append(PlanRow(f, config.focus_settings[f], "board view placed by the operator", None, 1, s))
            case BoardView(focus_idx=f, degrees=float(deg), tilt_deg=t):
                moves += 1
                frames += 1
                s = current.pop("extra", 0.0) + MOVE_OVERHEAD_S + move_seconds(deg - stage, speed, accel)
                stage = deg
                if t is not None:  # the tilt axis, at the turntable's speed
                    s += MOVE_OVERHEAD_S + move_seconds(t - tilt, speed, accel)
                    tilt = t
                s += cap.settle_s + frame_s
                what = "board view" if t is None else f"board view tilted {t:g}°"
                first.append(PlanRow(f, config.focus_settings[f], what, deg, 1, s))
            case EstimateK(focus_idx=f):
                assert config.intrinsics is not None
                n_v = config.intrinsics.n_views
                first.append(
                    PlanRow(
                        f,
                        config.focus_settings[f],
                        f"camera matrix ({n_v} board views)",
                        seconds=KFIT_S_PER_VIEW * mpx * n_v,
                    )
                )
            case Store(focus_idx=f):
                pass
    o = cap.angles_deg
    back = move_seconds(o[0] - stage, speed, accel) - move_seconds(o[0] - 0.0, speed, accel)  # from the last move
    rows: list[PlanRow] = []
    for f, focus in enumerate(config.focus_settings):
        for k, r in enumerate(first):
            extra = back if f and k == 0 else 0.0
            rows.append(dataclasses.replace(r, focus_idx=f, focus=focus, seconds=r.seconds + extra))
    n_f = len(config.focus_settings)
    frames, moves, locks, fits = frames * n_f, moves * n_f, locks * n_f, fits * n_f
    report_s = REPORT_S_PER_FOCUS * len(config.focus_settings) * mpx / 1.23
    rows.append(PlanRow(-1, math.nan, "QA, report, results.json", seconds=report_s))
    total = sum(r.seconds for r in rows)
    return PlanEstimate(rows, frames, moves, locks, fits, total, assumptions)


def plan_summary(config: Config, est: PlanEstimate) -> str:
    """``3 focus settings x 8 orientations x 2 frames = 48 frames, an estimated 37 s``."""
    cap = config.capture
    return (
        f"{len(config.focus_settings)} focus settings x {len(cap.orientations)} orientations x "
        f"{cap.frames_per_orientation} frames{board_views(config)} = {est.frames} frames, an estimated "
        f"{duration(est.seconds)}"
    )


def board_views(config: Config) -> str:
    """`` + 3 x 6 board views`` of the camera-matrix stage (``intrinsics``), or nothing without it."""
    if config.intrinsics is None:
        return ""
    by = " placed by the operator" if config.intrinsics.placement == "operator" else ""
    return f" + {len(config.focus_settings)} x {config.intrinsics.n_views} board views{by}"


def duration(seconds: float) -> str:
    """``37 s``, ``12 min 5 s``, ``3.4 h``."""
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        minutes, sec = divmod(int(round(seconds)), 60)
        return f"{minutes} min {sec} s"
    return f"{seconds / 3600:.1f} h"


def long_plan(config: Config) -> tuple[PlanEstimate, str] | None:
    """The estimate and a warning naming the fields when the plan is estimated longer than
    :data:`WARN_PLAN_HOURS`; None when it is not."""
    est = estimate_plan(config)
    if est.seconds <= WARN_PLAN_HOURS * 3600:
        return None
    confirm = (
        f"; harp session run starts a plan longer than {CONFIRM_PLAN_HOURS:g} h only with --yes"
        if est.seconds > CONFIRM_PLAN_HOURS * 3600
        else ""
    )
    return est, (
        f"{config.path}: focus.settings, capture.orientations_deg, capture.frames_per_orientation: "
        f"{plan_summary(config, est)} (more than {WARN_PLAN_HOURS:g} h){confirm}"
    )
