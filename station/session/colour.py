"""Colour and light of a focus setting, from the session's own harp shots (issue 24).

A colour camera's frames are raw Bayer mosaics, their pattern in the frame's ``extra["cfa"]``
(kept in every ``frame`` record's meta: :func:`frames_cfa`). Its distortion is measured on the
mosaic's luma (:func:`pipeline.cfa.mosaic_luma`: no checkerboard, no shift;
:func:`station.session.processing.measure_shot`), and, once the focus setting is fitted, the very
same shots — one averaged mosaic per turntable orientation, at known angles — give
(:func:`focus_colour`):

* the **TCA**: every string edge measured per CFA channel on the mosaic (no demosaicing,
  :func:`pipeline.cfa.measure_mosaic`), red and blue fitted against green
  (:func:`station.colour.fit_channels`, as ``harp tca``): the ``harp tca --out`` document;
* the **vignetting**: the lit sheet between the strings on the first green plane
  (:func:`station.vignetting.mosaic_samples`, black level 0: a camera's raw output), the shots'
  turntable angles separating the back-light, which turns with the harp, from the lens's
  vignetting, which does not; the samples placed on the harp through the focus setting's fitted
  distortion (:func:`station.vignetting.fit_shots`, as ``harp vignetting --model``): the
  ``harp vignetting --out`` document.

Both are kept with the profile (``details["colour"]``: the model file's ``colour`` key and the
store's details), shown in the session summary and the QA report, and exported by ``harp profile
export`` (lensfun ``<tca>`` and ``<vignetting>``, OpenCV per-channel files) without ``--tca`` and
``--vignetting`` files. A measurement that fails is kept as its one-line reason (``failure``): the
distortion profile is stored all the same. A grey camera's frames have no ``cfa``: no colour, no
error.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from pipeline.cfa import measure_mosaic
from pipeline.models.base import DistortionModel
from pipeline.vignetting import lensfun_pa
from station.colour import fit_channels, tca_document
from station.errors import InputError
from station.session.processing import average_frames, full_scale
from station.vignetting import (
    MAX_SATURATED_FRACTION,
    ShotSamples,
    check_angles,
    fit_shots,
    mosaic_samples,
    vignetting_document,
)

KEY = "colour"
"""The profile's ``details`` key (and the model file's) of :func:`focus_colour`'s document."""


def frames_cfa(records: Sequence[Any]) -> str | None:
    """The CFA pattern of a shot's frames (``meta.extra.cfa`` of the ``frame`` records), None: grey."""
    for r in records:
        extra = (getattr(r, "meta", None) or {}).get("extra")
        if isinstance(extra, Mapping) and isinstance(extra.get("cfa"), str):
            return str(extra["cfa"])
    return None


def focus_colour(
    mosaics: Sequence[np.ndarray],
    pattern: str,
    angles_deg: Sequence[float],
    names: Sequence[str],
    model: DistortionModel,
    t: int,
    full_scale: float | None = None,
) -> dict[str, Any]:
    """The TCA and vignetting of one focus setting's shots (module docstring).

    Parameters
    ----------
    mosaics : each orientation's averaged raw mosaic (black level 0).
    pattern : their Bayer pattern (:data:`pipeline.cfa.CFA_PATTERNS`).
    angles_deg : the turntable angle of each shot (the stage's read-back, else the commanded one).
    names : how the documents name the shots (session-relative frame files).
    model : the focus setting's fitted distortion (distorted -> ideal).
    t : the along-edge subsampling (``pipeline.t``).
    full_scale : the frames' largest value: a shot with more than
        :data:`station.vignetting.MAX_SATURATED_FRACTION` of its pixels there has no vignetting (None: not checked).

    Returns
    -------
    ``{"tca": ..., "vignetting": ...}``: each the document ``harp tca --out`` / ``harp vignetting
    --out`` writes, or ``{"failure": reason}`` when it cannot be measured from these shots.
    """
    out: dict[str, Any] = {}
    shots = [measure_mosaic(m, pattern, t=t) for m in mosaics]
    try:
        fits, lensfun = fit_channels(shots, names)
        out["tca"] = tca_document(fits, lensfun, names)
    except (InputError, ValueError) as exc:
        out["tca"] = {"failure": " ".join(str(exc).split())}
    try:
        check_angles(names, angles_deg)
        samples = []
        for m, a, name, shot in zip(mosaics, angles_deg, names, shots):
            clipped = 0.0 if full_scale is None else float(np.mean(np.asarray(m) >= full_scale))
            if clipped > MAX_SATURATED_FRACTION:
                raise InputError(f"{name}: {100 * clipped:.1f} % of the pixels saturated: lower the exposure")
            w, h, n, s = mosaic_samples(np.asarray(m, np.float64), pattern, 0.0, t, name, shot.planes["G1"])
            if len(s.value) == 0:
                raise InputError(f"{name}: no lit sheet found between the strings")
            samples.append(ShotSamples(name, float(a), w, h, n, s))
        fit = fit_shots(samples, model)
        out["vignetting"] = vignetting_document(fit, lensfun_pa(fit), samples, model=model)
    except (InputError, ValueError) as exc:
        out["vignetting"] = {"failure": " ".join(str(exc).split())}
    return out


def session_colour(session: Any, focus_idx: int, model: DistortionModel, config: Any) -> dict[str, Any] | None:
    """:func:`focus_colour` of a session's focus setting from its stored frames (None: a grey camera).

    ``session``: a :class:`station.session.directory.SessionDir` or an archived one
    (:class:`station.reprocess.ArchivedSession`: ``frames`` and ``read_frame``); each orientation's current
    frames averaged, its angle the stage's read-back (else the commanded one); ``model`` the focus setting's
    fitted distortion; ``config`` the session's.
    """
    fitted = config.capture.fitted  # the shots the distortion was fitted on (a twin is compared, not fitted)
    records = [session.frames(focus_idx, o) for o in fitted]
    pattern = frames_cfa([r for rs in records for r in rs])
    if pattern is None:
        return None
    mosaics, angles, names = [], [], []
    for rs, commanded in zip(records, config.capture.fitted_angles_deg):
        mosaics.append(average_frames([session.read_frame(r) for r in rs]))
        stage = (rs[-1].meta or {}).get("stage_deg")
        angles.append(float(commanded if stage is None else stage))
        names.append(str(rs[0].file))
    first = records[0][0]
    top = full_scale(session.read_frame(first).dtype, (first.meta or {}).get("bit_depth"))
    return focus_colour(mosaics, pattern, angles, names, model, config.pipeline.t, top)


def colour_summary(doc: Mapping[str, Any] | None) -> dict[str, str]:
    """Short cells of a focus setting's colour for the session summary and the QA report:
    ``{"TCA": ..., "vignetting": ...}`` (empty: a grey camera).

    TCA: the largest red and blue shift against green over the image (px); vignetting: the relative illumination at the darkest corner and the back-light's unevenness.
    """
    if not doc:
        return {}
    cells: dict[str, str] = {}
    tca = doc.get("tca") or {}
    if "failure" in tca:
        cells["TCA"] = f"none: {tca['failure']}"
    elif tca:
        parts = []
        for ch in ("R", "B"):
            mag = ((tca.get("channels") or {}).get(ch) or {}).get("field_max_px")
            parts.append(f"{ch} {float(mag):.2f} px" if isinstance(mag, (int, float)) else ch)
        cells["TCA"] = ", ".join(parts)
    vig = doc.get("vignetting") or {}
    if "failure" in vig:
        cells["vignetting"] = f"none: {vig['failure']}"
    elif vig:
        ri = vig.get("relative_illumination") or {}
        cells["vignetting"] = (
            f"{float(ri.get('min', float('nan'))):.3f} at the darkest, back-light "
            f"±{100 * float(vig.get('backlight_unevenness', float('nan'))) / 2:.1f} %"
        )
    return cells
