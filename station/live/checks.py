"""The live view's figures against the session's acceptance checks (:class:`station.config.CheckConfig`).

Two uses:

* :func:`live_warnings` -- per live frame, from the :class:`pipeline.assess.Assessment`: the
  exposure figures against ``max_saturated_fraction`` and ``min_dynamic_range`` (computed as
  the session computes them, :func:`pipeline.assess.exposure_figures`), the string edges found
  against ``min_lines`` and the harp angle against the expected one.
* :func:`check_shot` -- ``harp live --once``: the executor's own checks
  (:func:`station.session.processing.exposure_problems`, :func:`station.session.processing.measure_shot`,
  :func:`station.session.processing.shot_problems`) on the average of ``frames_per_orientation``
  frames, so that its verdict is the session's, and the focus check (:func:`focus_warnings`,
  ``max_edge_width_px``): a set-up whose harp is blurred fails, though the session would take it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pipeline.assess import Assessment, ExposureFigures
from station.config import CheckConfig, PipelineConfig
from station.session.processing import (
    angle_difference,
    average_frames,
    exposure_problems,
    full_scale,
    measure_shot,
    shot_problems,
)


def exposure_warnings(fig: ExposureFigures, checks: CheckConfig) -> list[str]:
    """The session's exposure checks on the live figures (same limits, same wording)."""
    out = []
    if fig.saturated_fraction > checks.max_saturated_fraction:
        out.append(
            f"over-exposed: {100 * fig.saturated_fraction:.2f}% of pixels saturated "
            f"(limit {100 * checks.max_saturated_fraction:.2f}%)"
        )
    if fig.dynamic_range < checks.min_dynamic_range:
        out.append(
            f"under-exposed or blank: dynamic range {fig.dynamic_range:.3f} of full scale "
            f"(minimum {checks.min_dynamic_range:.3f})"
        )
    return out


def focus_warnings(a: Assessment, checks: CheckConfig) -> list[str]:
    """The focus check: the median string edge (10-90 %) against ``max_edge_width_px``."""
    if math.isfinite(a.edge_width_px) and a.edge_width_px > checks.max_edge_width_px:
        return [
            f"out of focus: string edges {a.edge_width_px:.2f} px wide (10-90 %), limit "
            f"{checks.max_edge_width_px:g} px: turn the focus to the through-focus peak (harp live shows it)"
        ]
    return []


def live_warnings(a: Assessment, checks: CheckConfig, expected_angle: float | None = None) -> list[str]:
    """Everything about this frame that would make the session re-capture the shot, and the focus check."""
    out = exposure_warnings(a.exposure, checks) + focus_warnings(a, checks)
    if a.n_edges < checks.min_lines:
        out.append(f"only {a.n_edges} string edges found (need {checks.min_lines})")
    elif expected_angle is not None and math.isfinite(a.angle_deg):
        diff = angle_difference(a.angle_deg, expected_angle)
        if diff > checks.angle_tolerance_deg:
            out.append(
                f"strings at {a.angle_deg:.1f} deg, expected {expected_angle:.1f} deg "
                f"(off by {diff:.1f} > {checks.angle_tolerance_deg:g})"
            )
    return out


@dataclass(frozen=True)
class ShotCheck:
    """The session's verdict on one averaged shot: ``problems`` empty means it passes."""

    problems: tuple[str, ...]
    n_lines: int | None  # string edges the session's measurement found (None: not measured)
    angle_deg: float | None
    d: float | None

    @property
    def passed(self) -> bool:
        return not self.problems


def check_shot(
    images: Sequence[np.ndarray],
    checks: CheckConfig,
    pipeline: PipelineConfig,
    expected_angle: float,
    bit_depth: int | None = None,
) -> ShotCheck:
    """The executor's checks (exposure, then strings found at the expected angle) on the averaged shot."""
    image = average_frames(list(images))
    problems = exposure_problems(image, full_scale(images[0].dtype, bit_depth), checks)
    if problems:
        return ShotCheck(tuple(problems), None, None, None)
    m = measure_shot(image, pipeline)
    angle = m.angle_deg if math.isfinite(m.angle_deg) else None
    d = m.d if math.isfinite(m.d) else None
    return ShotCheck(tuple(shot_problems(m, expected_angle, checks)), m.n_lines, angle, d)
