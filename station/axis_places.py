"""Two turntable-axis places (``capture.shift_positions_mm``): where the stage put the axis, as the joint fit is told.

A session may move the turntable sideways on a linear stage between groups of shots, so that the harp turns about two
axis places or more (what one axis cannot separate, two can: :mod:`pipeline.harp_shape`). :func:`axes_of` turns the
stage's commanded and read-back positions into each shot's axis group and a rough image shift per group;
:func:`axis_record` compares the axes the joint fit found with where the stage's travel puts them (QA's
``axis_places``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.harp_frame import GROUP_AXIS_SEARCH, MIN_GROUP_ANGLES, harp_frame, string_pitch
from pipeline.harp_shape import HarpShapeFit
from pipeline.orientations import distinct_orientations
from pipeline.plain import finite_or_none


@dataclass(frozen=True)
class AxisPlaces:
    """Two-axis capture (``capture.shift_positions_mm``): the linear stage that carries the turntable sideways, per
    shot its position as the plan commanded it (the shot's axis group) and as it read back (mm); how a stage move
    shows in the image: ``direction_deg`` (``station.harp.shift_direction_deg``, from +x towards +y; None: unknown,
    each place's axis searched on its own shots, which needs four turntable angles or more there) and the harp's
    pitch in mm (``station.harp.string_spacing_mm``): the pitch the shots show in px over it is the image scale of
    the harp's plane, in which the stage moves the axis."""

    commanded_mm: tuple[float, ...]
    read_mm: tuple[float, ...]
    direction_deg: float | None
    spacing_mm: float


@dataclass(frozen=True)
class Axes:
    """What the joint fit is told of a two-axis capture (:func:`axes_of`): each shot's axis group (its stage
    position's label, :func:`place_label`), each group's rough image shift of the axis from where the axis is with
    the stage halfway between its outermost positions (px; None: each group's axis searched), the strings' pitch
    in the shots (px) and the image scale (px per mm of stage travel)."""

    places: AxisPlaces
    groups: tuple[str, ...]
    shifts: dict[str, tuple[float, float]] | None
    pitch_px: float
    px_per_mm: float

    def fit_arguments(self) -> dict[str, Any]:
        """``axis_groups`` and ``axis_shifts`` for :func:`pipeline.harp_shape.fit_harp_shape` (and the fits that
        pass them on)."""
        return {"axis_groups": self.groups, "axis_shifts": self.shifts}

    def fold(self, k: int) -> tuple[list[str], dict[str, tuple[float, float]] | None]:
        """``(axis_groups, axis_shifts)`` of the shots without shot ``k`` (a leave-one-orientation-out fold)."""
        return [g for j, g in enumerate(self.groups) if j != k], self.shifts


def place_label(mm: float) -> str:
    """The axis group of the shots taken with the linear stage at ``mm``."""
    return f"{mm:g} mm"


def _read_back(places: AxisPlaces, groups: Sequence[str]) -> dict[str, float]:
    """Each axis group's mean read-back position of the stage (mm), in the order the groups first appear."""
    return {
        g: float(np.mean([r for h, r in zip(groups, places.read_mm, strict=True) if h == g]))
        for g in dict.fromkeys(groups)
    }


def axis_fit_arguments(axes: Axes | None) -> dict[str, Any]:
    """:meth:`Axes.fit_arguments`, or none for one axis place."""
    return {} if axes is None else axes.fit_arguments()


def axes_of(
    places: AxisPlaces | None,
    shots: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    turntable_deg: Sequence[float],
) -> Axes | None:
    """The axis groups and rough shifts of a two-axis capture for :func:`pipeline.harp_shape.fit_harp_shape`
    (None when every shot was taken at one place: nothing changes), from the shots' edges as measured.

    The image scale is the strings' pitch in the shots (:func:`pipeline.harp_frame.string_pitch`; the lens's
    distortion changes it by its local scale only) over the harp's pitch in mm. Each group's shift is its shots'
    mean read-back position less the middle of the commanded positions, times the scale, along ``direction_deg``;
    the axis at that middle is then found, to an eighth of a pitch, on every shot moved back by its group's shift
    (:func:`pipeline.harp_frame.harp_frame` within :data:`pipeline.harp_frame.GROUP_AXIS_SEARCH` pitches of the
    image centre; it needs four turntable angles or more, else it is taken at the image centre) and the shifts are
    given from the image centre to there: :func:`pipeline.harp_frame.group_frames` searches each group's axis
    within a third of a pitch of where its shift puts it. Without ``direction_deg`` no shift is given (each group's
    axis searched on its own shots)."""
    if places is None or len(set(places.commanded_mm)) < 2:
        return None
    raw = [[np.asarray(p, np.float64) for p in s] for s in shots]
    pitch = string_pitch(raw)
    ppm = pitch / places.spacing_mm
    groups = tuple(place_label(m) for m in places.commanded_mm)
    shifts = None
    if places.direction_deg is not None and np.isfinite(ppm):
        mid = 0.5 * (min(places.commanded_mm) + max(places.commanded_mm))
        a = np.radians(places.direction_deg)
        rel = {g: (mm - mid) * ppm * np.array([np.cos(a), np.sin(a)]) for g, mm in _read_back(places, groups).items()}
        ref = np.zeros(2)  # where the axis is with the stage at the middle, from the image centre
        if distinct_orientations(turntable_deg) >= MIN_GROUP_ANGLES:
            back = [[p - rel[g] for p in s] for s, g in zip(raw, groups, strict=True) if s]
            framed = harp_frame(
                back, [float(t) for t, s in zip(turntable_deg, raw, strict=True) if s], width, height,
                reach=GROUP_AXIS_SEARCH, refine=False,
            )  # fmt: skip
            if framed:
                ref = np.asarray(framed[0].centre) - np.array([(width - 1) / 2.0, (height - 1) / 2.0])
        shifts = {g: (float(v[0] + ref[0]), float(v[1] + ref[1])) for g, v in rel.items()}
    return Axes(places, groups, shifts, float(pitch), float(ppm))


def axis_record(axes: Axes, fit: HarpShapeFit) -> dict[str, Any]:
    """Each place's turntable axis as the joint fit found it (``HarpShapeFit.axis_groups``) against where the
    stage's travel puts it, as a profile keeps it (``harp_health["axes"]``): per place its position (mm, the
    commanded one), shots, the axis found (ideal px) and how far it is from where the travel puts it relative to
    the other places (``off_px``: with ``direction_deg`` the difference of the two displacements from their means;
    without, of the distances from the first place's axis). More than half a pitch (``limit_px``) and the strings
    were numbered at the wrong place: ``misplaced`` lists those places (QA fails the profile)."""
    found = {str(g): f for g, f in fit.axis_groups}
    labels = [g for g in dict.fromkeys(axes.groups) if g in found]
    read = _read_back(axes.places, axes.groups)
    mm = {g: read[g] for g in labels}
    centre = {g: np.asarray(found[g].centre, np.float64) for g in labels}
    off: dict[str, float] = {}
    if axes.places.direction_deg is not None:
        a = np.radians(axes.places.direction_deg)
        want = {g: mm[g] * axes.px_per_mm * np.array([np.cos(a), np.sin(a)]) for g in labels}
        mc = np.mean([centre[g] for g in labels], axis=0)
        mw = np.mean([want[g] for g in labels], axis=0)
        off = {g: float(np.hypot(*((centre[g] - mc) - (want[g] - mw)))) for g in labels}
    elif labels:
        first = labels[0]
        off = {
            g: abs(float(np.hypot(*(centre[g] - centre[first]))) - abs(mm[g] - mm[first]) * axes.px_per_mm)
            for g in labels
        }
    limit = 0.5 * axes.pitch_px
    places = [
        {
            "position_mm": float(axes.places.commanded_mm[axes.groups.index(g)]),
            "shots": axes.groups.count(g),
            "centre_px": [float(centre[g][0]), float(centre[g][1])],
            "off_px": finite_or_none(off.get(g, float("nan"))),
        }
        for g in labels
    ]
    worst = max(off.values()) if off else float("nan")
    return {
        "pitch_px": finite_or_none(axes.pitch_px),
        "px_per_mm": finite_or_none(axes.px_per_mm),
        "direction_deg": axes.places.direction_deg,
        "shift_given": axes.shifts is not None,
        "limit_px": finite_or_none(limit),
        "places": places,
        "worst_off_px": finite_or_none(worst),
        "misplaced": [p["position_mm"] for p, g in zip(places, labels, strict=True) if off.get(g, 0.0) > limit],
    }
