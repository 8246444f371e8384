"""What an export of a profile is made from: the station's side of :mod:`pipeline.exports`.

:func:`export_source` turns a :class:`~station.profile.Profile` (from a model file or
the profile store) into the :class:`pipeline.exports.source.ExportSource` every
format writes from: the correction and its image size, the lens and camera
(:meth:`~station.profile.Profile.lens_info`, with the user's overrides), the model's
own holdout ``d``, whether the calibration chose a wide-angle model, the edges
of the shots it was fitted on, so that each export states the residual ``d`` it
leaves on them next to the model's own figures, and — for a profile that failed QA,
exported only on the user's override (:func:`station.profile_choice.export_refusal`) —
the ``FAILED QA`` stamp every format states first (:func:`station.profile_choice.failed_stamp`).

:func:`fitting_edges` finds those edges, in this order:

1. a session's profile (``provenance.session_dir``): the measurements the executor
   kept for the profile's focus setting (``measurements/*.npz``,
   :mod:`station.session.evidence`; the current attempt of every orientation the fit took — a twin,
   ``capture.twin_deg``, is compared, not fitted — checked against the manifest's SHA-256) — the very
   edges the fit used. The
   session is only read (no lock, nothing written), so a session still running or
   being resumed is not disturbed;
2. otherwise the provenance images of the model file (``harp calibrate``), when
   they are still there with the SHA-256 recorded: measured again with the
   recorded ``t`` (paths as recorded, else beside the model file);
3. or the shots the user names (:func:`measured_edges`).

When none is available the result says why (``FittingEdges.source``), and the
export states the figures it can without them.
"""

from __future__ import annotations

import hashlib
import io
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.exports.source import ExportSource
from pipeline.measure import measure_image
from pipeline.resample import DEFAULT_T
from station.config import ConfigError, load_config
from station.imageio import ImageReadError, read_grey
from station.profile import Profile
from station.profile_choice import failed_stamp
from station.session.directory import read_records
from station.session.evidence import measurement_from_arrays
from station.session.layout import CONFIG_COPY, MANIFEST
from station.session.records import FocusLocked, ShotMeasured, ShotRejected


@dataclass(frozen=True)
class FittingEdges:
    """The measured edges of a profile's fitting shots (None: not available) and, in one
    line, where they come from or why there are none."""

    edges: tuple[np.ndarray, ...] | None
    source: str
    n_shots: int = 0


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(1 << 20):
            h.update(block)
    return h.hexdigest()


# ------------------------------------------------------------------ session
def session_edges(session_dir: str | os.PathLike, focus: float) -> FittingEdges:
    """The edges a session measured at ``focus`` (see the module docstring, item 1)."""
    root = Path(session_dir)
    if not (root / MANIFEST).is_file():
        return FittingEdges(None, f"session {root} not found (no {MANIFEST})")
    try:
        records = read_records(root / MANIFEST)
    except (OSError, ValueError) as exc:
        return FittingEdges(None, f"session {root}: cannot read its manifest ({exc})")
    idx = {r.focus_idx for r in records if isinstance(r, FocusLocked) and _same(r.focus, focus)}
    if len(idx) != 1:
        return FittingEdges(None, f"session {root}: no focus setting {focus:g} in its manifest")
    (f,) = idx
    try:  # the session's own configuration says which shots the fit took (not a twin: capture.twin_deg)
        fitted = set(load_config(root / CONFIG_COPY).capture.fitted)
    except ConfigError as exc:
        return FittingEdges(None, f"session {root}: cannot tell the shots it fitted ({exc})")
    rejects: dict[int, int] = {}
    for r in records:
        if isinstance(r, ShotRejected) and r.focus_idx == f:
            rejects[r.orientation_idx] = rejects.get(r.orientation_idx, 0) + 1
    kept: dict[int, ShotMeasured] = {}
    for r in records:  # the measurement of each fitted orientation's current attempt (the last one written)
        if not isinstance(r, ShotMeasured) or r.focus_idx != f or r.orientation_idx not in fitted:
            continue
        if r.attempt == rejects.get(r.orientation_idx, 0):
            kept[r.orientation_idx] = r
    if not kept:
        return FittingEdges(None, f"session {root}: no stored measurement at focus {focus:g}")
    edges: list[np.ndarray] = []
    for o in sorted(kept):
        path = root / kept[o].file
        try:
            data = path.read_bytes()
            if hashlib.sha256(data).hexdigest() != kept[o].sha256:
                return FittingEdges(None, f"{path}: checksum does not match the session manifest")
            with np.load(io.BytesIO(data), allow_pickle=False) as z:
                m = measurement_from_arrays({k: z[k] for k in z.files})
        except (OSError, ValueError, KeyError) as exc:
            return FittingEdges(None, f"{path}: cannot read the stored measurement ({exc})")
        edges.extend(np.asarray(ln.points, np.float64) for ln in m.lines)
    return FittingEdges(
        tuple(edges), f"the session's stored measurements ({len(kept)} shots at focus {focus:g})", len(kept)
    )


def _same(a: Any, b: float) -> bool:
    return isinstance(a, (int, float)) and math.isclose(float(a), b, rel_tol=0, abs_tol=1e-9)


# --------------------------------------------------------------- photographs
def measured_edges(
    paths: Iterable[str | os.PathLike], t: int, size: tuple[int, int] | None = None, model: str = "the model"
) -> FittingEdges:
    """Measure the harp shots at ``paths`` (``t``: along-edge subsampling); ValueError naming a bad one, or
    one of another size than ``size`` (the model's width and height, named ``model``), when given."""
    edges: list[np.ndarray] = []
    names = []
    for p in paths:
        try:
            img = read_grey(p)
        except ImageReadError as exc:
            raise ValueError(str(exc)) from None
        if size is not None and (img.shape[1], img.shape[0]) != tuple(size):
            raise ValueError(
                f"{p}: image is {img.shape[1]}x{img.shape[0]} but {model} is for {size[0]}x{size[1]} images: "
                "give the shots the model was fitted on"
            )
        try:
            m = measure_image(img, t=t)
        except (ValueError, MemoryError) as exc:
            raise ValueError(f"{p}: cannot measure: {exc}") from None
        if not m.lines:
            raise ValueError(f"{p}: no strings found")
        edges.extend(np.asarray(ln.points, np.float64) for ln in m.lines)
        names.append(Path(p).name)
    if not names:
        return FittingEdges(None, "no shots given")
    return FittingEdges(tuple(edges), f"{len(names)} shots measured now, t={t} ({', '.join(names)})", len(names))


def provenance_edges(profile: Profile, model_dir: str | os.PathLike | None = None) -> FittingEdges:
    """The profile's provenance images measured again, if all are there unchanged (module docstring, item 2)."""
    prov = profile.provenance
    if not prov.images:
        return FittingEdges(None, "the model file names no fitting shots")
    found: list[Path] = []
    for recorded, sha in prov.images:
        candidates = [Path(recorded)]
        if model_dir is not None and not Path(recorded).is_absolute():
            candidates += [Path(model_dir) / recorded, Path(model_dir) / Path(recorded).name]
        hit = next((c for c in candidates if c.is_file()), None)
        if hit is None:
            return FittingEdges(None, f"fitting shot {recorded} is no longer there")
        try:
            if _sha256(hit) != sha:
                return FittingEdges(None, f"fitting shot {hit} changed since the calibration (SHA-256 differs)")
        except OSError as exc:
            return FittingEdges(None, f"fitting shot {hit}: cannot read ({exc.strerror or exc})")
        found.append(hit)
    try:
        return measured_edges(found, prov.t or DEFAULT_T, (profile.width, profile.height))
    except ValueError as exc:
        return FittingEdges(None, str(exc))


def fitting_edges(profile: Profile, model_dir: str | os.PathLike | None = None) -> FittingEdges:
    """The edges of the shots ``profile`` was fitted on, or why they are not available."""
    if profile.provenance.session_dir is not None and profile.focus is not None:
        # a session fits averaged shots: its frames measured one by one are not the fitting edges
        return session_edges(profile.provenance.session_dir, profile.focus)
    return provenance_edges(profile, model_dir)


# ------------------------------------------------------------------- source
def wide_angle(profile: Profile) -> bool:
    """Whether the calibration fitted a wide-angle model: a radial spec with division
    (denominator) terms, the wide-angle candidate of :mod:`pipeline.fitspec`."""
    return bool(profile.spec is not None and profile.spec.to_dict().get("division"))


def export_source(
    profile: Profile,
    *,
    lens: Mapping[str, Any] | None = None,
    edges: FittingEdges | None = None,
    stamp: tuple[str, ...] | None = None,
) -> ExportSource:
    """The :class:`ExportSource` of ``profile``; ``lens``: :class:`~pipeline.exports.lens.LensInfo`
    fields that override the profile's (None values ignored; a pixel pitch given replaces a
    recorded sensor width and vice versa); ``edges``: the fitting shots' edges; ``stamp``: the
    lines the file states first (default: :func:`~station.profile_choice.failed_stamp` of the
    profile; a correction interpolated from failed profiles gives theirs)."""
    mf = profile.to_model_file()
    over = {k: v for k, v in dict(lens or {}).items() if v is not None}
    info = profile.lens_info()
    # the pixel pitch and the sensor width are alternatives: the one given replaces the other
    if "sensor_width_mm" in over and "pixel_pitch_um" not in over:
        info = replace(info, pixel_pitch_um=None)
    if "pixel_pitch_um" in over and "sensor_width_mm" not in over:
        info = replace(info, sensor_width_mm=None)
    info = info.with_overrides(**over)
    return ExportSource(
        model=profile.model,
        width=int(profile.width),
        height=int(profile.height),
        lens=info,
        holdout_d=profile.merit.holdout_d,
        edges=edges.edges if edges is not None else None,
        merit=mf.merit,
        provenance=mf.provenance,
        wide_angle=wide_angle(profile),
        stamp=failed_stamp(profile) if stamp is None else tuple(stamp),
        intrinsics=profile.intrinsics,
    )
