"""The live view on a configuration's devices.

* :func:`apply_session_settings` -- the session's exposure, gain and first focus setting, as the
  executor sets them;
* :func:`live_station` -- the :class:`~station.live.runner.LiveStation` of a configuration
  (``harp live``, and ``harp session run --live`` with no devices of its own);
* :func:`check_once` -- ``harp live --once``: one shot captured and checked as the session would
  (:func:`station.live.checks.check_shot`), with its assessment (:func:`pipeline.assess.assess_frame`).
"""

from __future__ import annotations

from typing import Any


def apply_session_settings(config: Any, camera: Any) -> None:
    """The session's exposure and gain (focus: the first focus setting), as the executor sets them."""
    cap = config.capture
    camera.set_exposure(cap.exposure_us)
    camera.set_gain(cap.gain_db)
    if config.focus_settings:
        camera.lock_focus(config.focus_settings[0])


def live_station(config: Any, camera: Any, turntable: Any, **kw: Any) -> Any:
    """The :class:`~station.live.runner.LiveStation` of a configuration's devices."""
    from station.live.runner import LiveStation  # defers scipy, cv2, numpy, yaml

    return LiveStation(
        camera,
        turntable,
        orientations=config.capture.orientations_deg,
        checks=config.capture.checks,
        expected_angle=config.station.harp.expected_angle,
        capture_timeout_s=config.capture.timeout_s,
        move_timeout_s=config.capture.move_timeout_s,
        title=f"{config.station.id} · {config.lens.label()}",
        **kw,
    )


def check_once(config: Any, camera: Any, turntable: Any) -> dict[str, Any]:
    """Capture ``frames_per_orientation`` frames with the session's settings at the turntable's
    position, check their average as the session would and assess it: one JSON-able document
    (``pass``, ``problems``, the frames' settings, the session's measurement, the assessment)."""
    import numpy as np

    from pipeline.assess import assess_frame  # defers scipy, cv2, numpy
    from station.live.checks import check_shot, focus_warnings  # defers scipy, cv2, numpy, yaml

    apply_session_settings(config, camera)
    stage = float(turntable.position()) if turntable is not None else None
    n = config.capture.frames_per_orientation
    frames = [camera.capture(config.capture.timeout_s) for _ in range(n)]
    images = [np.asarray(f.image) for f in frames]
    bit_depth = 8 if frames[0].image.dtype == np.uint8 else None
    expected = config.station.harp.expected_angle(stage if stage is not None else 0.0)
    verdict = check_shot(images, config.capture.checks, config.pipeline, expected, bit_depth)
    image = images[0] if n == 1 else np.mean(np.stack(images), axis=0)
    a = assess_frame(image, full_scale=float(np.iinfo(images[0].dtype).max))
    problems = list(verdict.problems) + focus_warnings(a, config.capture.checks)
    return {
        "pass": not problems,
        "problems": problems,
        "frames_averaged": n,
        "stage_deg": stage,
        "expected_angle_deg": expected,
        "focus": frames[-1].focus,
        "exposure_us": frames[-1].exposure_us,
        "gain_db": frames[-1].gain_db,
        "session_measurement": {"string_edges": verdict.n_lines, "angle_deg": verdict.angle_deg, "d_px": verdict.d},
        "assessment": a.to_dict(),
    }
