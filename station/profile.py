"""One profile record: a fitted correction of one lens on one camera at one focus setting.

A :class:`Profile` is what a calibration produces and what every part of the
station passes around: the executor writes it (model file and store row from the
same record), ``harp calibrate`` writes it, QA judges it, the report shows it and
``harp profile export`` exports it. It holds

* the correction (``model``), the image size it is for, and the
  :class:`~pipeline.fitspec.FitSpec` that was actually fitted (``spec``; how it was
  chosen in ``selection``), so that QA and reports refit exactly that;
* the typed figures of merit (:class:`Merit`): straightness before and after the
  correction (:class:`Figures`), the holdout figure with its hold-out scheme and
  per-orientation values (:class:`Holdout`), the bootstrap field uncertainty
  (:class:`UncertaintySummary`); figures this record does not type are kept as
  written (``Merit.extra``), so nothing read is lost;
* the QA verdict with its checks (:class:`Verdict`, :class:`Check`: value,
  comparison, limit, passed), once judged;
* what it is of (``lens``, ``camera``, ``focus``, and for a zoom lens ``focal``, the focal
  length setting in mm (None: a fixed lens); the configured ``optics``: nominal
  focal length, mount, pixel pitch or sensor width, crop factor, for exports —
  :meth:`Profile.lens_info`) and where it comes from
  (:class:`Provenance`: time, software, command, images with SHA-256, station,
  session, plus free-form ``extra``);
* its store id (``id``), the store's time (``stored_at``) and free-form fit
  diagnostics (``details``);
* the camera matrix measured with this correction held fixed, once measured
  (``intrinsics``: :class:`pipeline.intrinsics.Intrinsics`, values, standard deviations,
  source; ``harp intrinsics``), which every export uses.
* a colour camera's TCA and vignetting from the same shots (``details["colour"]``:
  :mod:`station.session.colour`; the model file's ``colour`` key, the store's details), which
  ``harp profile export`` writes to lensfun and OpenCV.

Conversions: :meth:`Profile.to_model_file` / :meth:`Profile.from_model_file` (the
YAML model file, :mod:`pipeline.model_file`) and :meth:`Profile.to_row` /
:meth:`Profile.from_row` (a row of :mod:`station.store`). Both keep every typed
field; reading an older file or row fills what it holds and leaves the rest empty.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from pipeline.exports.lens import LensInfo
from pipeline.fitspec import FitSpec, parse
from pipeline.intrinsics import Intrinsics
from pipeline.model_file import ModelFile, not_finite
from pipeline.models import model_from_dict
from pipeline.models.base import DistortionModel
from pipeline.plain import finite_or_none, plain
from station.equipment import Identity, Optics

HOLDOUT_LEAVE_ONE_ORIENTATION_OUT = "leave one orientation out"
"""Hold-out scheme of a session: each orientation corrected by the fit on the others."""

HOLDOUT_SHOTS = "held-out shots"
"""Hold-out scheme of ``harp calibrate --holdout``: shots never used in the fit."""


# ------------------------------------------------------------------ merit
@dataclass(frozen=True)
class Figures:
    """Straightness of a set of edges (Tang et al. 2012), pixels: ``d`` (RMS distance of
    the points to their edge's line) and ``d_max`` (RMS over edges of the peak-to-peak)."""

    d: float | None = None
    d_max: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"d": self.d, "d_max": self.d_max}

    @classmethod
    def from_dict(cls, d: Any) -> Figures | None:
        if not isinstance(d, Mapping):
            return None
        return cls(finite_or_none(d.get("d")), finite_or_none(d.get("d_max")))


@dataclass(frozen=True)
class Holdout(Figures):
    """Straightness of edges the fit never saw, after the correction, and how they were held out.

    ``scheme`` is :data:`HOLDOUT_LEAVE_ONE_ORIENTATION_OUT` (a session; then
    ``per_orientation_d`` holds each orientation's figure) or :data:`HOLDOUT_SHOTS`
    (``harp calibrate --holdout``), ``None`` when the source does not say.
    """

    scheme: str | None = None
    per_orientation_d: tuple[float | None, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        d = super().to_dict()
        if self.scheme is not None:
            d["scheme"] = self.scheme
        if self.per_orientation_d:
            d["per_orientation_d"] = list(self.per_orientation_d)
        return d

    @classmethod
    def from_dict(cls, d: Any) -> Holdout | None:
        if not isinstance(d, Mapping):
            return None
        per = d.get("per_orientation_d") or ()
        return cls(
            finite_or_none(d.get("d")),
            finite_or_none(d.get("d_max")),
            str(d["scheme"]) if d.get("scheme") is not None else None,
            tuple(finite_or_none(v) for v in per) if isinstance(per, (list, tuple)) else (),
        )


@dataclass(frozen=True)
class UncertaintySummary:
    """The bootstrap field uncertainty of the correction over the image (px, 1 sigma):
    RMS and max of the per-pixel map, and the number of replicates it came from."""

    rms: float | None = None
    max: float | None = None
    replicates: int | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"rms": self.rms, "max": self.max, "replicates": self.replicates}

    @classmethod
    def from_dict(cls, d: Any) -> UncertaintySummary | None:
        if not isinstance(d, Mapping):
            return None
        n = d.get("replicates")
        return cls(
            finite_or_none(d.get("rms")), finite_or_none(d.get("max")), int(n) if isinstance(n, (int, float)) else None
        )


@dataclass(frozen=True)
class Merit:
    """The figures of merit of a profile (pixels); ``extra`` keeps any other figure as written."""

    fit: Figures | None = None
    holdout: Holdout | None = None
    before: Figures | None = None
    field_uncertainty: UncertaintySummary | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    @property
    def holdout_d(self) -> float | None:
        """The holdout ``d`` (what QA judges), or None."""
        return self.holdout.d if self.holdout is not None else None

    def to_dict(self) -> dict[str, Any]:
        """The ``merit`` mapping of a model file."""
        d: dict[str, Any] = {}
        if self.before is not None:
            d["before"] = self.before.to_dict()
        if self.fit is not None:
            d["fit"] = self.fit.to_dict()
        if self.holdout is not None:
            d["holdout"] = self.holdout.to_dict()
        if self.field_uncertainty is not None:
            d["field_uncertainty"] = self.field_uncertainty.to_dict()
        d.update(self.extra)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Merit:
        typed = ("before", "fit", "holdout", "field_uncertainty")
        return cls(
            fit=Figures.from_dict(d.get("fit")),
            holdout=Holdout.from_dict(d.get("holdout")),
            before=Figures.from_dict(d.get("before")),
            field_uncertainty=UncertaintySummary.from_dict(d.get("field_uncertainty")),
            extra={k: v for k, v in d.items() if k not in typed},
        )


# --------------------------------------------------------------------- QA
@dataclass(frozen=True)
class Check:
    """One QA check: ``value comparison limit`` and whether it held.

    ``passed`` is ``None`` for a figure reported but not judged (no threshold, or
    nothing to compare with). ``text`` is the line shown in tables and reports.
    """

    name: str
    value: float | None
    comparison: str
    limit: float | None
    passed: bool | None
    text: str

    def __str__(self) -> str:
        return self.text

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "value": self.value,
            "comparison": self.comparison,
            "limit": self.limit,
            "passed": self.passed,
            "text": self.text,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Check:
        passed = d.get("passed")
        return cls(
            str(d.get("name", "")),
            finite_or_none(d.get("value")),
            str(d.get("comparison", "")),
            finite_or_none(d.get("limit")),
            passed if isinstance(passed, bool) else None,
            str(d.get("text", "")),
        )


@dataclass(frozen=True)
class Verdict:
    """The QA verdict of one profile.

    ``verdict`` is ``"PASS"`` or ``"FAIL"``; ``reasons`` say why it failed (empty for
    PASS); ``metrics`` (alias ``figures``) holds every figure computed, in pixels;
    ``checks`` what was judged (:class:`Check`); ``thresholds`` the limits it was
    judged against.
    """

    verdict: str
    reasons: tuple[str, ...]
    metrics: Mapping[str, Any] = field(default_factory=dict)
    checks: tuple[Check, ...] = ()
    thresholds: Mapping[str, float | None] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return self.verdict == "PASS"

    @property
    def figures(self) -> Mapping[str, Any]:
        return self.metrics

    def to_dict(self) -> dict[str, Any]:
        """JSON of ``harp qa --json`` and ``results.json``: every check typed (name, value,
        comparison, limit, passed, text), the thresholds it was judged with."""
        return {
            "verdict": self.verdict,
            "passed": self.passed,
            "reasons": list(self.reasons),
            "checks": [c.to_dict() for c in self.checks],
            "thresholds": dict(self.thresholds),
            "figures": dict(self.metrics),
        }

    def to_record(self) -> dict[str, Any]:
        """Everything, typed checks included (stored with the profile)."""
        return {
            "verdict": self.verdict,
            "reasons": list(self.reasons),
            "metrics": dict(self.metrics),
            "checks": [c.to_dict() for c in self.checks],
            "thresholds": dict(self.thresholds),
        }

    @classmethod
    def from_record(cls, d: Mapping[str, Any]) -> Verdict:
        return cls(
            str(d.get("verdict", "FAIL")),
            tuple(d.get("reasons") or ()),
            dict(d.get("metrics") or {}),
            tuple(Check.from_dict(c) for c in d.get("checks") or ()),
            dict(d.get("thresholds") or {}),
        )


# ------------------------------------------------------------ provenance
@dataclass(frozen=True)
class Provenance:
    """Where a profile comes from.

    ``created_utc`` (``YYYY-MM-DDTHH:MM:SSZ``), ``software`` (``harp-station X.Y.Z``),
    ``command`` (the command line), ``t`` (along-edge subsampling), ``images``
    (``(path, sha256)`` of every input shot), ``station`` (station id),
    ``session_dir`` (the session directory, for a session's profile); ``extra``:
    anything else a source records (held-out shots, a note, the profiles an
    interpolated one comes from, the profile a re-processed one replaces, ...).
    """

    created_utc: str | None = None
    software: str | None = None
    command: str | None = None
    t: int | None = None
    images: tuple[tuple[str, str], ...] = ()
    station: str | None = None
    session_dir: str | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    @property
    def software_version(self) -> str | None:
        """The version alone (``0.1.0`` of ``harp-station 0.1.0``)."""
        if self.software is None:
            return None
        return self.software.split(" ", 1)[1] if self.software.startswith("harp-station ") else self.software


_PROVENANCE_KEYS = (
    "created_utc",
    "software",
    "t",
    "command",
    "images",
    "focus",
    "focal",
    "lens",
    "camera",
    "optics",
    "station",
)


# ---------------------------------------------------------------- profile
@dataclass(frozen=True)
class Profile:
    """One fitted correction and everything known about it (see the module docstring)."""

    model: DistortionModel
    width: int
    height: int
    spec: FitSpec | None = None
    selection: Mapping[str, Any] = field(default_factory=dict)
    merit: Merit = field(default_factory=Merit)
    qa: Verdict | None = None
    lens: Identity | None = None
    camera: Identity | None = None
    focus: float | None = None
    provenance: Provenance = field(default_factory=Provenance)
    optics: Optics = field(default_factory=Optics)
    details: Mapping[str, Any] = field(default_factory=dict)
    id: int | None = None
    stored_at: str | None = None
    intrinsics: Intrinsics | None = None
    focal: float | None = None

    def with_(self, **changes: Any) -> Profile:
        """A copy with ``changes`` (e.g. ``qa=verdict`` once judged, ``id=`` once stored)."""
        return replace(self, **changes)

    def lens_info(self) -> LensInfo:
        """What an export needs to know about the lens and camera
        (:class:`pipeline.exports.lens.LensInfo`): identities, optics, focus setting."""
        lens, cam, o = self.lens, self.camera, self.optics
        return LensInfo(
            lens_maker=lens.maker if lens else None,
            lens_model=lens.model if lens else None,
            lens_serial=lens.serial if lens else None,
            camera_maker=cam.maker if cam else None,
            camera_model=cam.model if cam else None,
            mount=o.mount,
            crop_factor=o.crop_factor,
            focal_mm=self.focal if self.focal is not None else o.focal_mm,  # a zoom setting: its focal
            pixel_pitch_um=o.pixel_pitch_um,
            sensor_width_mm=o.sensor_width_mm,
            focus=self.focus,
        )

    # ------------------------------------------------------------ model file
    def to_model_file(self) -> ModelFile:
        """The model file of this profile (every typed field kept)."""
        merit = self.merit.to_dict()
        if self.spec is not None:
            merit["choice"] = {**self.spec.to_dict(), **dict(self.selection)}
        if self.qa is not None:
            merit["qa"] = self.qa.to_record()
        if self.details.get("harp_health"):  # the harp's self-check: QA judges it from the file too
            merit["harp_health"] = plain(dict(self.details["harp_health"]))
        if self.details.get("strings"):  # whether the lens was fitted with the strings' bends separated
            merit["strings"] = plain(dict(self.details["strings"]))
        if self.details.get("own_shift"):  # the held-out orientations' own axis shifts: QA reports them from the file
            merit["own_shift"] = plain(dict(self.details["own_shift"]))
        if self.details.get("twins"):  # two shots at one angle compared: did the lens move between them
            merit["twins"] = plain([dict(t) for t in self.details["twins"]])
        p = self.provenance
        prov: dict[str, Any] = {}
        if p.created_utc is not None:
            prov["created_utc"] = p.created_utc
        if p.software is not None:
            prov["software"] = p.software
        if p.t is not None:
            prov["t"] = p.t
        if p.command is not None:
            prov["command"] = p.command
        if p.images or p.created_utc is not None:
            prov["images"] = [{"path": path, "sha256": sha} for path, sha in p.images]
        if self.focus is not None:
            prov["focus"] = self.focus
        if self.focal is not None:
            prov["focal"] = self.focal
        if self.lens is not None:
            prov["lens"] = [self.lens.maker, self.lens.model, self.lens.serial]
        if self.camera is not None:
            prov["camera"] = [self.camera.maker, self.camera.model, self.camera.serial]
        if self.optics.to_dict():
            prov["optics"] = self.optics.to_dict()
        if p.station is not None:
            prov["station"] = p.station
        if p.session_dir is not None:
            prov["session_dir"] = p.session_dir
        if self.id is not None:
            prov["profile_id"] = self.id
        prov.update(p.extra)
        colour = self.details.get("colour")  # a colour camera's TCA and vignetting (station.session.colour)
        return ModelFile(
            self.model,
            int(self.width),
            int(self.height),
            merit,
            prov,
            intrinsics=self.intrinsics,
            colour=dict(colour) if isinstance(colour, Mapping) else None,
        )

    @classmethod
    def from_model_file(cls, mf: ModelFile) -> Profile:
        """The profile a model file holds (an older file: what it records)."""
        merit_doc = dict(mf.merit or {})
        choice = merit_doc.pop("choice", None)
        qa_doc = merit_doc.pop("qa", None)
        health = merit_doc.pop("harp_health", None)
        strings = merit_doc.pop("strings", None)
        own_shift = merit_doc.pop("own_shift", None)
        twins = merit_doc.pop("twins", None)
        spec, selection = _spec_of_choice(choice)
        prov = dict(mf.provenance or {})
        return cls(
            model=mf.model,
            width=int(mf.width),
            height=int(mf.height),
            spec=spec,
            selection=selection,
            merit=Merit.from_dict(merit_doc),
            qa=Verdict.from_record(qa_doc) if isinstance(qa_doc, Mapping) else None,
            lens=_identity(prov.get("lens")),
            camera=_identity(prov.get("camera")),
            focus=finite_or_none(prov.get("focus")),
            focal=finite_or_none(prov.get("focal")),
            provenance=_provenance_of(prov),
            optics=Optics.from_dict(prov.get("optics")),
            id=int(prov["profile_id"]) if isinstance(prov.get("profile_id"), int) else None,
            details={
                **({"harp_health": dict(health)} if isinstance(health, Mapping) else {}),
                **({"strings": dict(strings)} if isinstance(strings, Mapping) else {}),
                **({"own_shift": dict(own_shift)} if isinstance(own_shift, Mapping) else {}),
                **({"twins": [dict(t) for t in twins if isinstance(t, Mapping)]} if isinstance(twins, list) else {}),
                **({"colour": dict(mf.colour)} if mf.colour else {}),
            },
            intrinsics=mf.intrinsics,
        )

    # -------------------------------------------------------------- store row
    def to_row(self) -> dict[str, Any]:
        """The column values of a row of :mod:`station.store`'s ``profiles`` table
        (``lens`` / ``camera`` as (maker, model, serial); the store resolves their ids).

        Raises ValueError when the profile lacks what a row needs (lens, camera,
        focus, session directory, station).
        """
        missing = [
            name
            for name, v in (
                ("lens", self.lens),
                ("camera", self.camera),
                ("focus", self.focus),
                ("provenance.session_dir", self.provenance.session_dir),
                ("provenance.station", self.provenance.station),
            )
            if v is None
        ]
        if missing:
            raise ValueError(f"a stored profile needs {', '.join(missing)}")
        assert self.lens is not None and self.camera is not None and self.focus is not None
        m = self.merit
        unc = m.field_uncertainty or UncertaintySummary()
        mf = self.to_model_file()
        return {
            "lens": (self.lens.maker, self.lens.model, self.lens.serial),
            "camera": (self.camera.maker, self.camera.model, self.camera.serial),
            "focus": float(self.focus),
            "focal": float(self.focal) if self.focal is not None else None,
            "model_name": self.model.name,
            "model_json": json.dumps(plain(self.model.to_dict())),
            "width": int(self.width),
            "height": int(self.height),
            "fit_d": m.fit.d if m.fit else None,
            "fit_d_max": m.fit.d_max if m.fit else None,
            "holdout_d": m.holdout.d if m.holdout else None,
            "holdout_d_max": m.holdout.d_max if m.holdout else None,
            "field_uncertainty_rms": unc.rms,
            "field_uncertainty_max": unc.max,
            "session_dir": str(self.provenance.session_dir),
            "station_id": str(self.provenance.station),
            "software_version": self.provenance.software_version or "",
            "details_json": json.dumps(plain(dict(self.details))),
            "spec_json": json.dumps(self.spec.to_dict()) if self.spec is not None else None,
            "selection_json": json.dumps(plain(dict(self.selection))),
            "merit_json": json.dumps(plain(self.merit.to_dict())),
            "provenance_json": json.dumps(plain(mf.provenance)),
            "qa_json": json.dumps(plain(self.qa.to_record())) if self.qa is not None else None,
            "verdict": self.qa.verdict if self.qa is not None else None,
            "intrinsics_json": json.dumps(self.intrinsics.to_dict()) if self.intrinsics is not None else None,
        }

    @classmethod
    def from_row(cls, row: Mapping[str, Any]) -> Profile:
        """The profile of a store row (columns as :meth:`to_row` names them, ``id``,
        ``created_at``, and ``lens`` / ``camera`` tuples). A row written before the
        typed columns existed gives what its figures and details hold."""
        details = json.loads(row.get("details_json") or "{}")
        merit_json = row.get("merit_json")
        if merit_json:
            merit = Merit.from_dict(json.loads(merit_json))
        else:  # schema 2: the flat figures, the per-orientation holdout and bootstrap size in details
            per = details.get("holdout_per_orientation") or ()
            merit = Merit(
                fit=Figures(finite_or_none(row.get("fit_d")), finite_or_none(row.get("fit_d_max"))),
                holdout=Holdout(
                    finite_or_none(row.get("holdout_d")),
                    finite_or_none(row.get("holdout_d_max")),
                    HOLDOUT_LEAVE_ONE_ORIENTATION_OUT if per else None,
                    tuple(finite_or_none(v) for v in per),
                ),
                before=(
                    Figures(finite_or_none(details.get("d_before")), finite_or_none(details.get("d_max_before")))
                    if "d_before" in details
                    else None
                ),
                field_uncertainty=(
                    UncertaintySummary(
                        finite_or_none(row.get("field_uncertainty_rms")),
                        finite_or_none(row.get("field_uncertainty_max")),
                        details.get("bootstrap_replicates"),
                    )
                    if row.get("field_uncertainty_rms") is not None or "bootstrap_replicates" in details
                    else None
                ),
            )
        spec_json = row.get("spec_json")
        if spec_json:
            spec: FitSpec | None = FitSpec.from_dict(json.loads(spec_json))
            selection = json.loads(row.get("selection_json") or "{}")
        else:
            spec, selection = _spec_of_details(details)
        prov_doc = json.loads(row.get("provenance_json") or "{}")
        base = _provenance_of(prov_doc)
        provenance = replace(
            base,
            software=base.software
            or (f"harp-station {row['software_version']}" if row.get("software_version") else None),
            station=base.station or row.get("station_id"),
            session_dir=base.session_dir or row.get("session_dir"),
        )
        qa_json = row.get("qa_json")
        intr_json = row.get("intrinsics_json")
        lens, camera = row.get("lens"), row.get("camera")
        model_doc = json.loads(row["model_json"])
        bad = not_finite(model_doc, "model")
        if bad is not None:  # JSON keeps NaN and Infinity: a model that would be exported and applied as such
            raise ValueError(f"{bad[0]} is {bad[1]}")
        return cls(
            model=model_from_dict(model_doc),
            width=int(row["width"]),
            height=int(row["height"]),
            spec=spec,
            selection=selection,
            merit=merit,
            qa=Verdict.from_record(json.loads(qa_json)) if qa_json else None,
            lens=Identity(*lens) if lens else None,
            camera=Identity(*camera) if camera else None,
            focus=finite_or_none(row.get("focus")),
            focal=finite_or_none(row.get("focal")),
            provenance=provenance,
            optics=Optics.from_dict(prov_doc.get("optics")),
            details=details,
            id=int(row["id"]) if row.get("id") is not None else None,
            stored_at=row.get("created_at"),
            intrinsics=Intrinsics.from_dict(json.loads(intr_json)) if intr_json else None,
        )


# ----------------------------------------------------------------- helpers
def _str(v: Any) -> str | None:
    return None if v is None else str(v)


def _provenance_of(prov: Mapping[str, Any]) -> Provenance:
    """The :class:`Provenance` of a model file's ``provenance`` mapping (lens, camera,
    focus and profile id are the profile's own fields, not provenance)."""
    images = tuple(
        (str(i.get("path")), str(i.get("sha256")))
        for i in prov.get("images") or ()
        if isinstance(i, Mapping) and "sha256" in i
    )
    t = prov.get("t")
    known = {*_PROVENANCE_KEYS, "session_dir", "profile_id"}
    return Provenance(
        created_utc=_str(prov.get("created_utc")),
        software=_str(prov.get("software")),
        command=_str(prov.get("command")),
        t=int(t) if isinstance(t, (int, float)) and not isinstance(t, bool) else None,
        images=images,
        station=_str(prov.get("station")),
        session_dir=_str(prov.get("session_dir")),
        extra={k: v for k, v in prov.items() if k not in known},
    )


def _identity(v: Any) -> Identity | None:
    if isinstance(v, (list, tuple)) and len(v) == 3:
        return Identity(*(str(x) for x in v))
    return None


def _spec_of_choice(choice: Any) -> tuple[FitSpec | None, dict[str, Any]]:
    """(spec, selection) of a model file's ``merit.choice``; (None, {}) when absent or unreadable."""
    if not isinstance(choice, Mapping):
        return None, {}
    try:
        spec = FitSpec.from_dict(dict(choice))
    except ValueError:
        return None, {}
    keys = set(spec.to_dict()) | {"kind", "table"}
    return spec, {k: v for k, v in choice.items() if k not in keys}


def _spec_of_details(details: Mapping[str, Any]) -> tuple[FitSpec | None, dict[str, Any]]:
    """(spec, selection) of a schema-2 row: its fit arguments, else its selection's label."""
    fit = details.get("fit")
    sel = details.get("selection") or {}
    selection = {k: sel[k] for k in ("reason", "folds") if k in sel}
    if isinstance(fit, Mapping) and fit.get("model") is not None:
        try:
            return FitSpec.from_fit_arguments(dict(fit)), selection
        except (ValueError, TypeError):
            pass
    if sel.get("choice"):
        try:
            return parse(str(sel["choice"])), selection
        except ValueError:
            pass
    return None, {}
