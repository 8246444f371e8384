"""The checks of a session's frames and shots before they count (the executor's ``Capture`` and ``Measure``).

:class:`FrameReference` judges each captured frame for damage in transfer, on its own and against the
statistics of a trusted frame (:func:`station.session.processing.frame_damage`); :func:`check_shot`
averages a shot's saved frames and checks its exposure, the strings found and their angle against the
harp's expected one (:func:`station.session.processing.shot_problems`).
"""

from __future__ import annotations

import numpy as np

from drivers.errors import CaptureError
from station.config import Config
from station.session.colour import frames_cfa
from station.session.directory import SessionAborted, SessionDir, SessionError
from station.session.processing import (
    FrameStats,
    ShotMeasurement,
    average_frames,
    exposure_problems,
    frame_damage,
    frame_stats,
    full_scale,
    measure_shot,
    shot_problems,
)
from station.session.records import ShotMeasured

Shot = tuple[int, int, int]
"""A shot's (focus_idx, orientation_idx, attempt)."""


class FrameReference:
    """The statistics of a trusted frame (of an accepted shot, or one that passed against such a frame),
    with its shot; frames of a shot not yet judged against one (the first shot of a session) wait as
    candidates until their shot is accepted. On resume, the last frame of the last accepted shot on disk."""

    def __init__(self, session: SessionDir):
        self.session = session
        self._reference: tuple[Shot, FrameStats] | None = None
        self._loaded = False
        self._candidates: dict[tuple[int, int], FrameStats] = {}

    def check(self, shot: Shot, img: np.ndarray, full: float) -> None:
        """A frame of ``shot`` damaged in transfer raises CaptureError (a device fault: captured again);
        a frame that passes against a reference becomes the reference."""
        stats = frame_stats(img, full)
        ref = self._current()
        same = ref is not None and ref[0] == shot
        damage = frame_damage(stats, ref[1] if ref is not None else None, same_pose=same)
        if damage:
            raise CaptureError(f"corrupt frame: {damage}")
        if ref is not None:
            self._reference = (shot, stats)
        else:
            self._candidates[shot[:2]] = stats

    def accept(self, shot: Shot) -> None:
        """``shot`` passed its checks: the first accepted shot's frames are the reference."""
        candidate = self._candidates.pop(shot[:2], None)
        if self._reference is None and candidate is not None:
            self._reference = (shot, candidate)

    def _current(self) -> tuple[Shot, FrameStats] | None:
        if self._reference is None and not self._loaded:
            self._loaded = True
            for r in reversed(list(self.session.of_type(ShotMeasured))):
                frames = self.session.frames(r.focus_idx, r.orientation_idx)
                if not frames or frames[-1].attempt != r.attempt:
                    continue
                try:
                    img = self.session.read_frame(frames[-1])
                except (OSError, ValueError, SessionError):
                    continue  # damaged or missing: another shot will do, or the next accepted one
                full = full_scale(img.dtype, (frames[-1].meta or {}).get("bit_depth"))
                self._reference = ((r.focus_idx, r.orientation_idx, r.attempt), frame_stats(img, full))
                break
        return self._reference


def check_shot(session: SessionDir, config: Config, f: int, o: int) -> tuple[list[str], ShotMeasurement | None]:
    """The problems of shot (focus ``f``, orientation ``o``) from its saved frames, averaged, and its
    measurement (None when its exposure already fails)."""
    records = session.frames(f, o)
    n = config.capture.frames_per_orientation
    if len(records) != n:  # cannot happen unless the directory was tampered with
        raise SessionAborted(f"focus {f} orientation {o}: {len(records)} of {n} frames on disk")
    images = [session.read_frame(r) for r in records]
    bit_depth = (records[0].meta or {}).get("bit_depth")
    image = average_frames(images)
    problems = exposure_problems(image, full_scale(images[0].dtype, bit_depth), config.capture.checks)
    if problems:
        return problems, None
    m = measure_shot(image, config.pipeline, frames_cfa(records))
    stage = (records[-1].meta or {}).get("stage_deg")
    if stage is None:
        stage = config.capture.angles_deg[o]
    expected = config.station.harp.expected_angle(stage)
    return shot_problems(m, expected, config.capture.checks), m
