"""A session's fit and store of a focus setting (the plan's ``Fit`` and ``Store`` steps).

Performed by :class:`station.session.executor.Executor`: :func:`fit_focus` fits the setting's accepted
shots (:func:`station.calibration.calibrate_focus`, leave one orientation out) and :func:`fitted_record`
keeps its bootstrap uncertainty map in the session directory (:mod:`station.session.layout`);
:func:`store_focus` measures a colour camera's TCA and vignetting (:mod:`station.session.colour`) and
writes the setting's profile, model file and store row from the same :class:`station.profile.Profile`
(:func:`station.calibration.focus_profile`, judged before it is stored).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from pipeline.fitspec import FitSpec
from pipeline.intrinsics import Intrinsics
from station.axis_places import AxisPlaces
from station.calibration import Calibration, MapFn, calibrate_focus, focus_profile
from station.config import Config
from station.files import sha256_file, write_profile
from station.moving_lens import session_twin_record
from station.profile import Profile
from station.provenance import make_provenance
from station.session import layout
from station.session.colour import KEY as COLOUR
from station.session.colour import colour_summary, session_colour
from station.session.directory import SessionAborted, SessionDir
from station.session.evidence import uncertainty_arrays
from station.session.records import ColourMeasured, Fitted, Record, Stored
from station.store import StoreError


def axis_places(reads: Any, config: Config, f: int) -> AxisPlaces | None:
    """The linear-stage position of each orientation of focus setting ``f`` of a two-axis capture
    (``capture.shift_positions_mm``; None without one): commanded by the plan, and read back as the frames'
    records keep it (``shift_mm`` in a frame's metadata, :class:`station.session.records.FrameSaved`; the commanded
    one where none is recorded). ``reads``: the session directory or an archived one (``frames``; None: none)."""
    cap = config.capture
    if not cap.shift_positions_mm:
        return None
    commanded, read = [], []
    for o in cap.fitted:  # the shots the fit takes (a twin is compared, not fitted)
        mm = cap.shifts_mm[o]
        assert mm is not None  # a two-axis capture: every orientation has its place
        records = reads.frames(f, o) if reads is not None else []
        got = (records[-1].meta or {}).get("shift_mm") if records else None
        commanded.append(mm)
        read.append(float(mm if got is None else got))
    harp = config.station.harp
    return AxisPlaces(tuple(commanded), tuple(read), harp.shift_direction_deg, float(harp.string_spacing_mm))


def fit_focus(
    f: int,
    config: Config,
    shots: Sequence[Sequence[np.ndarray]],
    size: tuple[int, int],
    map_fn: MapFn,
    reads: Any = None,
    *,
    spec: FitSpec | None,
) -> Calibration:
    """The calibration of focus setting ``f`` from its orientations' edges (``shots``, one per
    orientation of the plan) on frames of ``size`` = (width, height); ``reads``: the session (its frames' records
    say where a two-axis capture's stage was, :func:`axis_places`; None: where the plan sent it); ``spec``: what to
    fit (None: chosen by cross-validation). The executor and ``harp reprocess`` both call this.

    The fit takes every shot but a twin (``capture.twin_deg``; :attr:`~station.config.schema.CaptureConfig.fitted`);
    the twin is compared with its first shot under the fitted correction
    (:func:`station.moving_lens.session_twin_record`, kept in ``details["twins"]``; QA judges the lens's move)."""
    w, h = size
    cap = config.capture
    fitted = [list(shots[o]) for o in cap.fitted]
    cal = calibrate_focus(
        fitted,
        w,
        h,
        config.pipeline,
        f,
        spec,
        map_fn=map_fn,
        turntable_deg=cap.fitted_angles_deg,
        axis_places=axis_places(reads, config, f),
    )
    if cap.twin is None or cal.failure is not None or not cal.fit:
        return cal
    first, twin = cap.twin
    names = (cap.orientation_name(first), cap.orientation_name(twin))
    record = session_twin_record(cal.fit.model, shots[first], shots[twin], names)
    return dataclasses.replace(cal, details={**cal.details, "twins": [record]})


def fitted_record(f: int, cal: Calibration, session: SessionDir) -> Fitted:
    """The ``fitted`` record of a successful calibration, its uncertainty map saved in ``session``."""
    assert cal.fit is not None
    saved = {"file": None, "sha256": None}
    if cal.uncertainty is not None:
        saved = session.write_arrays(layout.uncertainty_file(f), uncertainty_arrays(cal.uncertainty))
    m = cal.merit
    unc = m.field_uncertainty
    return Fitted(
        focus_idx=f,
        model=cal.fit.model.to_dict(),
        spec=cal.spec.to_dict() if cal.spec is not None else None,
        fit_d=m.fit.d if m.fit else None,
        fit_d_max=m.fit.d_max if m.fit else None,
        holdout_d=m.holdout.d if m.holdout else None,
        holdout_d_max=m.holdout.d_max if m.holdout else None,
        holdout_per_orientation=list(m.holdout.per_orientation_d) if m.holdout else [],
        uncertainty_rms=unc.rms if unc else None,
        uncertainty_max=unc.max if unc else None,
        details=dict(cal.details),
        uncertainty_file=saved["file"],
        uncertainty_sha256=saved["sha256"],
    )


def store_focus(
    f: int,
    session: SessionDir,
    config: Config,
    cal: Calibration,
    size: tuple[int, int],
    *,
    intrinsics: Intrinsics | None,
    judge: Callable[[Profile], Any] | None,
    store: Any,
    emit: Callable[[Record], None],
) -> tuple[Profile, Stored]:
    """Write the profile of focus setting ``f`` (its model file in ``session``, its row in ``store``
    unless None): the profile (with its store id) and the ``stored`` record to emit. A colour camera's
    TCA and vignetting are measured first (``colour`` record, emitted); a store that refuses the row
    stops the session (:class:`~station.session.directory.SessionAborted`), frames and fits kept."""
    w, h = size
    frames = [session.path / r.file for o in range(len(config.capture.orientations)) for r in session.frames(f, o)]
    rel = layout.profile_file(f)
    path = session.path / rel
    assert cal.fit is not None  # a failed fit stopped the session
    colour = session_colour(session, f, cal.fit.model, config)  # a colour camera's TCA and vignetting (None: grey)
    if colour is not None:
        emit(ColourMeasured(f, colour_summary(colour)))
    # judged here so that the store keeps the profile, its verdict (thresholds, every check) and
    # its lens row in one transaction (issues 9, 12); the QA after the executor says it again
    profile = focus_profile(
        cal,
        w,
        h,
        config,
        f,
        provenance=make_provenance(
            frames,
            t=config.pipeline.t,
            command="harp session",
            station=config.station.id,
            session_dir=str(session.path.resolve()),
        ),
        details={"model_file": str(path), **({COLOUR: colour} if colour is not None else {})},
        intrinsics=intrinsics,
        judge=judge,
    )
    write_profile(path, profile)
    digest = sha256_file(path)
    profile_id = None
    if store is not None:
        try:
            profile_id = store.put_profile(profile)
        except StoreError as exc:  # full disk, damaged store: stop here, frames and fits kept
            raise SessionAborted(f"{exc}; then continue with: harp session resume {session.path}") from None
        profile = profile.with_(id=profile_id)
    return profile, Stored(f, profile_id, rel, digest)
