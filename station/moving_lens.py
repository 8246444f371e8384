"""A lens that moves between shots: what a station reads of it and what it says.

A lens whose decentering changes between shots (an image stabiliser that re-centres, a focus or zoom group with play)
has no one correction. Two readings tell it:

* **own shifts** (:func:`own_shift_record`): each held-out shot's correction moved for it alone
  (:func:`pipeline.own_shift.own_axis_shift`); when most held-out shots want it, the lens may be moving, or a term of
  the lens bends each orientation its own way, which one shot per angle cannot tell apart;
* **twins** (:func:`twin_record`, :func:`session_twin_record`): two shots at one angle compared under one correction
  (:func:`pipeline.own_shift.twin_shift`); the move across their strings is the lens's own.

The records are kept in a profile's details and model file; QA judges the twins' move (``twin_move``) and reports the
own shifts (``holdout_own_shift``); ``harp calibrate`` warns (:func:`twin_warnings`, :func:`own_shift_warning`).

References
----------
.. [1] Shortis, Bellman, Robson, Johnston, Johnson, "Stability of zoom and fixed lenses used with digital SLR
   cameras", IAPRS vol. 36 part 5, 2006.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from pipeline.edgeset import corrected_straightness
from pipeline.models.base import DistortionModel
from pipeline.orientations import shot_orientation
from pipeline.own_shift import OwnShift, twin_shift
from pipeline.plain import finite_or_none

OWN_SHIFT_RATIO = 0.7
"""A session's held-out orientations are said to carry a term of their own when moving the correction's axis for
each one alone (:func:`pipeline.own_shift.own_axis_shift`) leaves, in the median over them, less than this part of
its held-out d. Set on realistic sessions of six shots (``benchmarks/own_shift.py --shots 6``, 20 lenses each,
radial4+tangential+prism folds): a stable lens's per-session median is 0.91-1.00 (lens field up to 0.04 px RMS) or
0.78-1.00 (up to 0.1), none below; a lens whose distortion centre moves N(0, 6 px) between shots, or its p1, p2
N(0, 1e-4), is below for 11 of 20, N(0, 5e-5) for 1 of 20."""

MIN_OWN_SHIFT_ORIENTATIONS = 4
"""Fewest orientations for the own-shift figure: with three, each fold is fitted on two orientations, which leave a
quadratic term undetermined that the held-out one then shows (``benchmarks/quadratic_sector.py``); its own shift
takes that away too, so a stable lens can read as low as 0.54 (``benchmarks/own_shift.py``)."""


MOVING_LENS_ADVICE = (
    "the lens's decentering may change between shots (an image stabiliser, a focus or zoom group with play): switch "
    "stabilisation off, lock focus and zoom, and capture again"
)
"""What to do about a lens that moves between shots (QA's and ``harp calibrate``'s warnings)."""

OWN_SHIFT_ADVICE = (
    f"{MOVING_LENS_ADVICE}; two shots at the same angle (a session's capture.twin_deg) tell it from a lens term that "
    "bends each orientation its own way"
)
"""What QA and ``harp calibrate`` say when the held-out shots carry a term of their own (``moving``)."""

TWINNED_ADVICE = "the twin (check twin_move) tells it from a lens term that bends each orientation its own way"
"""What QA says instead of :data:`OWN_SHIFT_ADVICE`'s second half when the session took a twin: look at its check,
not take one."""


def largest_own_shift(record: Mapping[str, Any]) -> float | None:
    """The largest own axis shift (px) of an own-shift record (:func:`own_shift_record`); None when none is known."""
    shifts = [o.get("shift_px") or [] for o in record.get("per_orientation") or []]
    sizes = [float(np.hypot(*v)) for v in shifts if len(v) == 2 and None not in v]
    return max(sizes) if sizes else None


def own_shift_record(own: Sequence[OwnShift]) -> dict[str, Any]:
    """The held-out orientations' own axis shifts as a profile keeps them (``details["own_shift"]``): per
    orientation its held-out d, the d with its own shift and the shift (px); the median ratio; ``moving`` when that
    median is below :data:`OWN_SHIFT_RATIO` with :data:`MIN_OWN_SHIFT_ORIENTATIONS` orientations or more (the lens's
    decentering may change between shots: :mod:`pipeline.own_shift`)."""
    ratios = [o.ratio for o in own if np.isfinite(o.ratio)]
    median = float(np.median(ratios)) if ratios else float("nan")
    return {
        "ratio_median": finite_or_none(median),
        "limit": OWN_SHIFT_RATIO,
        "judged": len(ratios) >= MIN_OWN_SHIFT_ORIENTATIONS,
        "moving": bool(len(ratios) >= MIN_OWN_SHIFT_ORIENTATIONS and median < OWN_SHIFT_RATIO),
        "per_orientation": [
            {
                "d_held_px": finite_or_none(o.d_held),
                "d_own_px": finite_or_none(o.d_own),
                "shift_px": [finite_or_none(v) for v in o.shift_px],
            }
            for o in own
        ],
    }


TWIN_ANGLE_DEG = 2.0
"""Two shots are twins (:func:`twin_record`) when their strings run within this of each other (degrees,
:func:`pipeline.orientations.shot_orientation`): a harp turned back to an angle by hand comes back within a degree or
two, and a term of the lens bends strings 2 degrees apart alike."""

TWIN_MOVE_PX = 1.0
"""The lens is said to have moved between twins when the move across their strings
(:func:`pipeline.own_shift.twin_shift`) is larger than this (px). Set on realistic twins (``benchmarks/twins.py``,
the photographs' set-up plus a shot at the first one's angle, 20 lenses per camera): a stable lens reads at most
0.23 px (40 lenses, fields up to 0.04 and 0.1 px RMS); on lenses whose centre moves N(0, 3 px) or N(0, 6 px) the move
read is within 0.06-0.15 px RMS of the move drawn (at most 0.36 px off), and every one of the 58 drawn beyond 1 px is
read beyond it. Whole realistic sessions with a twin (``benchmarks/session_twins.py``, six angles and the twin, 30
sessions): stable lenses read at most 0.10 px, moves are read within 0.04 px RMS, and all 17 drawn beyond 1 px are
read beyond it."""


def twin_record(
    model: DistortionModel, shots: Sequence[Sequence[np.ndarray]], names: Sequence[str]
) -> list[dict[str, Any]]:
    """Every pair of ``shots`` whose strings run within :data:`TWIN_ANGLE_DEG` of each other, compared under the
    correction ``model`` (:func:`pipeline.own_shift.twin_shift`): per pair the two ``names``, the strings' angle, d
    with one shift for both and with a shift each, ``ratio``, the lens's move across the strings (``move_px``) and
    ``moved`` beyond :data:`TWIN_MOVE_PX`. Two shots at one angle tell a lens that moved between them (a shift each)
    from a term of the lens at that angle (one shift for both), which one shot per angle cannot
    (:mod:`pipeline.own_shift`); the harp must not have been moved otherwise between them. Every edge of both twins
    is compared, those a fit rejected too: the twins see the same strings, and an edge dropped from one twin but
    not from the other reads as a move (a session's twin compared with its first shot less the fit's rejected edges
    read the move 15 % short, ``benchmarks/RESULTS-realism.md``). Empty without such a pair."""
    angles = [shot_orientation(lines) for lines in shots]
    out = []
    for i in range(len(shots)):
        for j in range(i + 1, len(shots)):
            gap = abs(angles[i] - angles[j]) % 180.0
            if min(gap, 180.0 - gap) <= TWIN_ANGLE_DEG:
                out.append(_twin_entry(model, shots[i], shots[j], (names[i], names[j]), angles[i]))
    return out


def session_twin_record(
    model: DistortionModel, first: Sequence[np.ndarray], twin: Sequence[np.ndarray], names: tuple[str, str]
) -> dict[str, Any]:
    """A session's twin (``capture.twin_deg``: the shot ``twin`` taken again, after the others and not fitted, at
    the angle of the shot ``first``) compared with that shot under the session's correction ``model``, as
    :func:`twin_record` compares a pair (every edge of both), with ``twin_d_px``: the twin's straightness under the
    correction, a shot it was not fitted on."""
    entry = _twin_entry(model, first, twin, names, shot_orientation(first))
    return {**entry, "twin_d_px": finite_or_none(corrected_straightness(model, twin)[0])}


def _twin_entry(
    model: DistortionModel, a: Sequence[np.ndarray], b: Sequence[np.ndarray], names: tuple[str, str], angle: float
) -> dict[str, Any]:
    """One pair of twins' record (:func:`twin_record`)."""
    got = twin_shift(model, a, b)
    return {
        "paths": list(names),
        "angle_deg": finite_or_none(angle),
        "d_common_px": finite_or_none(got.d_common),
        "d_each_px": finite_or_none(got.d_each),
        "ratio": finite_or_none(got.ratio),
        "move_px": finite_or_none(got.move_px),
        "limit_px": TWIN_MOVE_PX,
        "moved": bool(np.isfinite(got.move_px) and abs(got.move_px) > TWIN_MOVE_PX),
    }


def twin_warnings(records: Sequence[Mapping[str, Any]]) -> list[str]:
    """``harp calibrate``'s warning for each pair of twins between which the lens moved (:func:`twin_record`)."""
    return [
        f"{r['paths'][0]} and {r['paths'][1]} (strings at {r['angle_deg']:.1f} deg): the lens moved "
        f"{abs(r['move_px']):.1f} px across the strings between these two shots at one angle, beyond "
        f"{r['limit_px']:g} px; the correction is their mean: {MOVING_LENS_ADVICE}"
        for r in records
        if r.get("moved")
    ]


def own_shift_warning(record: Mapping[str, Any] | None) -> str | None:
    """``harp calibrate``'s warning when its held-out shots each want the correction moved on their own (the record's
    ``moving``, :func:`station.calibration.shot_own_shifts`); None otherwise."""
    if not record or not record.get("moving"):
        return None
    size = largest_own_shift(record)
    return (
        f"each shot held out wants the correction moved on its own: {record['ratio_median']:.2f} of its held-out d is "
        f"left (median, below {record['limit']:g})" + (f", by up to {size:.1f} px" if size is not None else "")
        + f": {OWN_SHIFT_ADVICE}"
    )  # fmt: skip
