"""The capture plan is data: listed without hardware, resumable."""

import dataclasses
from collections import Counter
from pathlib import Path

from station.config import load_config
from station.session.plan import (
    Capture,
    Fit,
    LockFocus,
    Measure,
    Move,
    Save,
    ShotCheck,
    Stop,
    Store,
    capture_steps,
    frame_key,
    plan_session,
    stored_key,
)

DEMO = Path(__file__).resolve().parents[3] / "configs" / "demo.yaml"


def test_full_plan_lists_every_step():
    cfg = load_config(DEMO)
    steps = list(plan_session(cfg))
    kinds = Counter(type(s).__name__ for s in steps)
    n_f, n_o, n_i = 3, 8, cfg.capture.frames_per_orientation
    assert kinds == {
        "LockFocus": n_f,
        "Move": n_f * n_o,
        "Capture": n_f * n_o * n_i,
        "Save": n_f * n_o * n_i,
        "Measure": n_f * n_o,
        "Fit": n_f,
        "Store": n_f,
    }
    assert steps[0] == LockFocus(0, 0.0)
    assert steps[1] == Move(0, 0, 0.0)
    assert steps[2:4] == [Capture(0, 0, 0), Save(0, 0, 0)]
    assert steps[-2:] == [Fit(2), Store(2)]
    # every capture is followed by its save, and every frame appears once
    caps = [(s.focus_idx, s.orientation_idx, s.frame_idx) for s in steps if isinstance(s, Capture)]
    assert len(set(caps)) == len(caps)
    for a, b in zip(steps, steps[1:]):
        if isinstance(a, Capture):
            assert b == Save(a.focus_idx, a.orientation_idx, a.frame_idx)
    moves = [s.degrees for s in steps if isinstance(s, Move)][:8]
    assert moves == [0, 22.5, 45, 67.5, 90, 112.5, 135, 157.5]


def test_resume_skips_done_work():
    cfg = load_config(DEMO)
    n_i = cfg.capture.frames_per_orientation
    done = {stored_key(0)}
    done |= {frame_key(1, o, i) for o in range(3) for i in range(n_i)}
    done.add(frame_key(1, 3, 0))
    steps = list(plan_session(cfg, done))
    assert not any(getattr(s, "focus_idx", None) == 0 for s in steps)
    caps = {(s.focus_idx, s.orientation_idx, s.frame_idx) for s in steps if isinstance(s, Capture)}
    assert (1, 3, 0) not in caps and (1, 3, 1) in caps
    assert not any(c[0] == 1 and c[1] < 3 for c in caps)
    assert steps[0] == LockFocus(1, 0.5)
    assert steps[1:4] == [Measure(1, 0), Measure(1, 1), Measure(1, 2)]
    assert steps[4] == Move(1, 3, 67.5)
    assert Measure(1, 0) in steps and Fit(1) in steps and Store(1) in steps
    assert len(caps) == 2 * 8 * n_i - 3 * n_i - 1


def test_nothing_left():
    cfg = load_config(DEMO)
    assert list(plan_session(cfg, {stored_key(f) for f in range(3)})) == []


def test_a_rejected_shot_is_captured_again_then_the_plan_stops():
    cfg = load_config(DEMO)  # max_recaptures 2, 2 frames per orientation
    plan = plan_session(cfg)
    steps = []
    step = next(plan)
    while not (isinstance(step, Measure) and step.orientation_idx == 1):
        steps.append(step)
        step = plan.send(None)
    for attempt in range(cfg.capture.checks.max_recaptures):
        step = plan.send(ShotCheck(0, 1, attempt, ("over-exposed",)))
        again = []
        while not isinstance(step, Measure):
            again.append(step)
            step = plan.send(None)
        # the focus is still locked: the shot alone, all its frames, then measured again
        assert again == list(capture_steps(cfg, 0, 1)) and step == Measure(0, 1)
    stop = plan.send(ShotCheck(0, 1, 2, ("over-exposed", "only 2 string edges found (need 4)")))
    assert stop == Stop(
        f"shot focus 0 orientation 1 ({cfg.capture.orientations_deg[1]:g} deg) failed its checks 3 times: "
        "over-exposed; only 2 string edges found (need 4)"
    )
    assert list(plan) == []  # nothing after a stop


def test_a_recapture_on_resume_locks_the_focus_first():
    cfg = load_config(DEMO)
    n_i = cfg.capture.frames_per_orientation
    done = {frame_key(0, o, i) for o in range(8) for i in range(n_i)}  # focus 0 captured, nothing locked yet
    plan = plan_session(cfg, done)
    assert next(plan) == Measure(0, 0)
    step = plan.send(ShotCheck(0, 0, 0, ("blank",)))
    assert step == LockFocus(0, 0.0)
    assert plan.send(None) == Move(0, 0, 0.0)
    accepted = plan.send(None)
    while not isinstance(accepted, Measure):
        accepted = plan.send(None)
    assert plan.send(ShotCheck(0, 0, 1)) == Measure(0, 1)  # accepted: on to the next orientation


def test_the_intrinsics_stage_takes_the_board_views_after_each_fit():
    from station.session.plan import BoardView, EstimateK

    cfg = load_config(DEMO.parent / "demo-intrinsics.yaml")
    angles = cfg.intrinsics.angles_deg
    steps = list(plan_session(cfg))
    for f in range(len(cfg.focus_settings)):
        i = steps.index(Fit(f))
        n = len(angles)
        assert steps[i + 1 : i + 1 + n] == [BoardView(f, v, a) for v, a in enumerate(angles)]
        assert steps[i + 1 + n : i + 3 + n] == [EstimateK(f), Store(f)]
    # the views on disk are not taken again; the focus is locked again before the missing ones
    n_i, n_o = cfg.capture.frames_per_orientation, len(cfg.capture.orientations_deg)
    from station.session.plan import board_key

    done = {frame_key(0, o, i) for o in range(n_o) for i in range(n_i)} | {board_key(0, 0), board_key(0, 1)}
    first = list(plan_session(cfg, done))
    first = first[: first.index(Store(0)) + 1]
    assert first[:n_o] == [Measure(0, o) for o in range(n_o)]
    assert first[n_o :] == [Fit(0), LockFocus(0, 0.0)] + [
        BoardView(0, v, angles[v]) for v in range(2, len(angles))
    ] + [EstimateK(0), Store(0)]  # fmt: skip
    every = {board_key(0, v) for v in range(len(angles))}
    assert LockFocus(0, 0.0) not in list(plan_session(cfg, done | every))  # nothing to capture at focus 0


def _two_places(cfg, positions=(-20.0, 20.0)):
    return dataclasses.replace(cfg, capture=dataclasses.replace(cfg.capture, shift_positions_mm=positions))


def test_two_axis_places_take_every_angle_at_each_stage_position_in_turn():
    cfg = load_config(DEMO)
    plain = list(plan_session(cfg))
    assert all(s.shift_mm is None for s in plain if isinstance(s, Move))  # no stage: today's plan, unchanged
    two = _two_places(cfg)
    steps = list(plan_session(two))
    angles = list(cfg.capture.orientations_deg)
    moves = [s for s in steps if isinstance(s, Move) and s.focus_idx == 0]
    # every angle at -20 mm, then every angle at +20 mm: the linear stage moves once per position
    assert [(m.orientation_idx, m.shift_mm, m.degrees) for m in moves] == [
        (p * 8 + a, mm, deg) for p, mm in enumerate((-20.0, 20.0)) for a, deg in enumerate(angles)
    ]
    assert two.capture.orientations[9] == (20.0, 22.5) and len(two.capture.angles_deg) == 16
    n_i = cfg.capture.frames_per_orientation
    kinds = Counter(type(s).__name__ for s in steps)
    assert kinds["Capture"] == 3 * 16 * n_i and kinds["Measure"] == 3 * 16 and kinds["Fit"] == 3


def test_a_resumed_two_axis_session_skips_what_it_has():
    two = _two_places(load_config(DEMO))
    n_i = two.capture.frames_per_orientation
    done = {frame_key(0, o, i) for o in range(10) for i in range(n_i)}  # the first place and two of the second
    steps = list(plan_session(two, done))
    assert steps[0] == LockFocus(0, 0.0)
    assert steps[1:11] == [Measure(0, o) for o in range(10)]
    assert steps[11] == Move(0, 10, 45.0, 20.0)  # the stage goes (back) to the second place first
    caps = {(s.focus_idx, s.orientation_idx) for s in steps if isinstance(s, Capture)}
    assert not any(f == 0 and o < 10 for f, o in caps) and (0, 15) in caps


def test_the_estimate_of_a_two_axis_plan_names_each_place_and_its_stage_moves():
    from station.session.estimate import SHIFT_SPEED_MM_S, estimate_plan

    two = _two_places(load_config(DEMO), (0.0, 40.0))
    one = estimate_plan(load_config(DEMO))
    est = estimate_plan(two)
    rows = [r for r in est.rows if r.focus_idx == 0 and r.what.startswith("capture")]
    assert [r.what for r in rows] == ["capture + measure at 0 mm"] * 8 + ["capture + measure at 40 mm"] * 8
    assert est.frames == 2 * one.frames and f"linear stage speed assumed {SHIFT_SPEED_MM_S:g} mm/s" in " ".join(
        est.assumptions
    )
    # the stage's 40 mm at its assumed speed, on the first shot at the second place (the turntable's way back to 0
    # takes the simulated stage well under a second)
    assert rows[8].seconds - rows[9].seconds > 40.0 / SHIFT_SPEED_MM_S


def test_a_twin_is_the_last_shot_of_each_focus_setting_and_the_estimate_says_so():
    """``capture.twin_deg``: after every other orientation of a focus setting the turntable goes back to the twin's
    angle, captures and measures it, then the setting is fitted; the estimate names the twin's row and the fit holds
    out the fitted orientations only."""
    from station.session.estimate import estimate_plan

    cfg = load_config(DEMO)
    twin = dataclasses.replace(cfg, capture=dataclasses.replace(cfg.capture, twin_deg=45.0))
    steps = list(plan_session(twin))
    moves = [s for s in steps if isinstance(s, Move) and s.focus_idx == 0]
    assert [(m.orientation_idx, m.degrees) for m in moves] == [
        *enumerate(cfg.capture.orientations_deg),
        (8, 45.0),
    ]
    first = steps[: steps.index(Fit(0))]
    assert first[-1] == Measure(0, 8) and sum(isinstance(s, Capture) for s in first) == 9 * 2
    rows = [r for r in estimate_plan(twin).rows if r.focus_idx == 0]
    assert [r.what for r in rows if r.what.startswith("capture")] == ["capture + measure"] * 8 + [
        "capture + measure (the twin: compared, not fitted)"
    ]
    assert rows[-1].what.startswith("fit (8 orientations held out in turn")
    assert [r.twin for r in rows if r.what.startswith("capture")] == [False] * 8 + [True]
