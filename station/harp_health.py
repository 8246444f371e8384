"""The harp checks itself (issue 19 item 4): each string's own bend, fitted with the lens, as a profile keeps it.

:func:`harp_health` fits every string's deviation from straightness beside the lens
(:func:`pipeline.harp_shape.fit_harp_shape`) with the shots' turntable angles and writes the record QA judges
(``string_bend_max``): per string its bend, its own bend apart from what every string shares, and the standard error;
the strings bent beyond :data:`pipeline.harp_shape.BEND_LIMIT_PX` that stand out and are significant.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from pipeline.edgeset import FitFailure
from pipeline.fitspec import FitSpec
from pipeline.harp_shape import BEND_LIMIT_PX, HarpShapeFit, fit_harp_shape
from pipeline.orientations import distinct_orientations
from pipeline.plain import finite_or_none
from station.axis_places import Axes, axis_fit_arguments, axis_record

OUTLIER_FACTOR = 3.0
"""A string is bent (QA) when its own bend exceeds the limit *and* this many times the median string's.
A lens term the fitted model lacks bends the fits of many strings at once (a test session of straight
strings whose model left d = 0.019 px showed own bends of 0.05-0.06 px on several strings); one bent
string stands out of the others. When the median string itself is beyond the limit the harp cannot be
told from the lens and QA says so without judging."""

BEND_SIGNIFICANCE = 2.0
"""A string is named bent (QA) only when its own bend is also this many standard errors or more
(``bend_se_px``): a bend that cannot be told from none is not a finding. The strings seen over little of their
length (the image's corners) carry standard errors as large as the limit: on ``benchmarks/harp_health.py``'s
harps (seeds 0..19, six angles) one session failed on a string drawn at 0.0032 px, reported at 0.0207 +- 0.0188
px, while the strings named rightly had their own bends 2.4 to 11 standard errors from none (a probe over the same
fits). About two axis places one session of twenty named a string drawn at 0.0003 px, reported at 0.0436 +- 0.0159
px: two of its shots' edges lay along the pixel grid and were measured 3.5 times worse than the others, which the
check now weighs by their noise (:data:`pipeline.harp_shape.SHOT_NOISE_FACTOR`; ``benchmarks/RESULTS-harp-health.md``).
"""

MIN_HEALTH_ORIENTATIONS = 3
"""Turntable angles the harp's self-check needs: with two, a string's bend and the lens's terms
trade (each string is seen along two lines only), and the bends found are not the strings'."""


def harp_health(
    shots: Sequence[Sequence[np.ndarray]],
    turntable_deg: Sequence[float],
    width: int,
    height: int,
    spec: FitSpec,
    *,
    joint: HarpShapeFit | FitFailure | None = None,
    axes: Axes | None = None,
) -> dict[str, Any]:
    """The harp's self-check (issue 19 item 4) as a profile keeps it (``details["harp_health"]``).

    Every string's own bend fitted beside the lens ``spec`` with the shots' turntable angles
    (:func:`pipeline.harp_shape.fit_harp_shape`): per string its bend, its own bend apart from what
    every string shares (:meth:`pipeline.harp_shape.HarpShapeFit.own_bends`: a common part is a whole
    harp's or a lens term's, not one string's fault; judged within half the image's diagonal of the
    axis and, beyond it, where two shots or more see the string: ``seen_twice``) and the standard error
    (px); the worst string and the strings whose own bend exceeds :data:`pipeline.harp_shape.BEND_LIMIT_PX`,
    :data:`OUTLIER_FACTOR` times the median string's and :data:`BEND_SIGNIFICANCE` standard errors, as QA judges
    them (``bent_strings``), and those
    beyond the limit whose bend cannot be told from none (``uncertain_strings``); the shots the check weighed by
    their noise (``noisy_shots``: :data:`pipeline.harp_shape.SHOT_NOISE_FACTOR`, with each one's turntable angle);
    ``d`` with and without the strings' terms; ``{"failure": reason}`` when the joint fit cannot be made.
    ``joint``: that fit when already made (:func:`station.calibration.calibrate_focus` makes it once for this and the lens);
    ``axes``: the shots' turntable-axis places of a two-axis capture (:func:`station.axis_places.axes_of`), each place's axis found
    and compared with where the stage was sent (``"axes"``: :func:`station.axis_places.axis_record`).
    """

    if distinct_orientations(turntable_deg) < MIN_HEALTH_ORIENTATIONS:
        return {
            "limit_px": BEND_LIMIT_PX,
            "failure": f"needs >= {MIN_HEALTH_ORIENTATIONS} turntable angles 10 deg apart to tell a string's bend "
            f"from the lens (the plan has {distinct_orientations(turntable_deg)})",
        }
    hs = (
        joint
        if joint is not None
        else fit_harp_shape(
            [list(s) for s in shots],
            list(turntable_deg),
            width,
            height,
            spec,
            **axis_fit_arguments(axes),
        )  # fmt: skip
    )
    if not hs:
        return {"limit_px": BEND_LIMIT_PX, "failure": str(getattr(hs, "reason", "the joint fit failed"))}
    own = {k: v for k, v in hs.own_bends().items() if np.isfinite(v)}
    worst = max(own, key=lambda k: own[k]) if own else None
    typical = float(np.median(list(own.values()))) if own else float("nan")
    by_index = {s.index: s for s in hs.strings}
    se = {k: float(by_index[k].bend_se_px) for k in own}
    beyond = {k: v for k, v in own.items() if v > BEND_LIMIT_PX and v > OUTLIER_FACTOR * typical}
    return {
        "limit_px": BEND_LIMIT_PX,
        "worst_string": worst,
        "worst_bend_px": None if worst is None else own[worst],
        "worst_bend_se_px": None if worst is None else finite_or_none(by_index[worst].bend_se_px),
        "bent_strings": sorted(k for k, v in beyond.items() if v >= BEND_SIGNIFICANCE * se[k]),
        "uncertain_strings": sorted(k for k, v in beyond.items() if not v >= BEND_SIGNIFICANCE * se[k]),
        "significance": BEND_SIGNIFICANCE,
        "outlier_factor": OUTLIER_FACTOR,
        "typical_bend_px": typical,
        "strings": [
            {
                "index": s.index,
                "bend_px": finite_or_none(s.bend_px),
                "own_bend_px": own.get(s.index),
                "bend_se_px": finite_or_none(s.bend_se_px),
                "shots": s.shots,
                "span": [float(s.span[0]), float(s.span[1])],
                "seen_twice": [finite_or_none(v) for v in s.seen_twice],
            }
            for s in hs.strings
        ],
        "noisy_shots": [
            {"shot": i, "turntable_deg": float(turntable_deg[i]), "noise_ratio": r} for i, r in hs.noisy_shots
        ],
        "d_with_strings_px": finite_or_none(hs.d_after),
        "d_lens_only_px": finite_or_none(hs.d_lens_only),
    } | ({} if axes is None else {"axes": axis_record(axes, hs)})
