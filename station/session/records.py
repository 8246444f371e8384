"""The manifest's vocabulary: one frozen dataclass per record kind.

A session directory's ``manifest.jsonl`` (:mod:`station.session.directory`) holds one
JSON object per line, ``{"t": <unix time>, "kind": <kind>, ...fields}``. The executor
(:mod:`station.session.executor`), QA (:mod:`station.qa.judge`) and the session run
(:mod:`station.session.run`) write these records; subscribers
(:mod:`station.session.progress`) receive them as they are written. The JSON of each
record is its fields in order (``None`` fields that are optional are left out).

=================  ===============================================================
kind               record
=================  ===============================================================
``start``          :class:`Started` (``resume``: :class:`Resumed`) — software version
``focus``          :class:`FocusLocked` — focus index, setting, read-back
``frame``          :class:`FrameSaved` — a frame file (name from :mod:`layout`), sha256, metadata
``reject``         :class:`ShotRejected` — a shot failed its checks (its frames superseded)
``measure``        :class:`ShotMeasured` — an accepted shot's figures and measurement file
``fit``            :class:`Fitted` or :class:`FitFailed` — a focus setting's fit
``stored``         :class:`Stored` — the profile file and store id of a focus setting
``fault``          :class:`Fault` — a device error and the attempt it hit
``qa``             :class:`QARecorded` — one profile's verdict
``interpolation``  :class:`InterpolationError` — leave-one-focus-out error
``qa_session``     :class:`SessionVerdict` — the session's verdict
``report``         :class:`ReportWritten` or :class:`ReportFailed`
``aborted``        :class:`Aborted` — why the session stopped
``reopened``       :class:`Reopened` — ``harp session repair``: a stored focus setting is fitted again
``finished``       :class:`Finished` — the session is complete (QA and report included)
=================  ===============================================================
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar


@dataclass(frozen=True)
class Record:
    """Base of the manifest records; ``kind`` names the record in the file."""

    kind: ClassVar[str] = ""
    optional: ClassVar[tuple[str, ...]] = ()
    """Fields left out of the JSON when ``None``."""

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if v is None and f.name in self.optional:
                continue
            out[f.name] = v
        return out


@dataclass(frozen=True)
class Started(Record):
    kind: ClassVar[str] = "start"
    software_version: str


@dataclass(frozen=True)
class Resumed(Record):
    kind: ClassVar[str] = "resume"
    software_version: str


@dataclass(frozen=True)
class FocusLocked(Record):
    kind: ClassVar[str] = "focus"
    focus_idx: int
    focus: float
    read_back: float | None


@dataclass(frozen=True)
class FrameSaved(Record):
    kind: ClassVar[str] = "frame"
    focus_idx: int
    orientation_idx: int
    frame_idx: int
    attempt: int
    file: str
    sha256: str
    meta: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ShotRejected(Record):
    kind: ClassVar[str] = "reject"
    focus_idx: int
    orientation_idx: int
    attempt: int
    reasons: list[str]


@dataclass(frozen=True)
class ShotMeasured(Record):
    kind: ClassVar[str] = "measure"
    focus_idx: int
    orientation_idx: int
    attempt: int
    n_lines: int
    d: float
    d_max: float
    angle_deg: float
    file: str
    sha256: str


@dataclass(frozen=True)
class Fitted(Record):
    kind: ClassVar[str] = "fit"
    optional: ClassVar[tuple[str, ...]] = ("uncertainty_file", "uncertainty_sha256")
    focus_idx: int
    model: Mapping[str, Any]
    spec: Mapping[str, Any] | None
    fit_d: float | None
    fit_d_max: float | None
    holdout_d: float | None
    holdout_d_max: float | None
    holdout_per_orientation: list[float | None]
    uncertainty_rms: float | None
    uncertainty_max: float | None
    details: Mapping[str, Any]
    uncertainty_file: str | None = None  # the bootstrap map (station.session.layout.uncertainty_file)
    uncertainty_sha256: str | None = None


@dataclass(frozen=True)
class FitFailed(Record):
    kind: ClassVar[str] = "fit"
    focus_idx: int
    failure: str


@dataclass(frozen=True)
class Stored(Record):
    kind: ClassVar[str] = "stored"
    optional: ClassVar[tuple[str, ...]] = ("sha256",)
    focus_idx: int
    profile_id: int | None
    model_file: str
    sha256: str | None = None  # of the profile file (sessions before issue 14 have none)


@dataclass(frozen=True)
class Reopened(Record):
    """A stored focus setting whose profile, uncertainty map or measurements were damaged on disk
    (or whose frames are to be captured again): it counts as not stored, so that it is measured,
    fitted and stored again from its frames (:mod:`station.session.integrity`)."""

    kind: ClassVar[str] = "reopened"
    focus_idx: int
    reason: str


@dataclass(frozen=True)
class Fault(Record):
    kind: ClassVar[str] = "fault"
    what: str
    error: str
    message: str
    attempt: int


@dataclass(frozen=True)
class QARecorded(Record):
    kind: ClassVar[str] = "qa"
    focus_idx: int
    verdict: str
    reasons: list[str]
    metrics: Mapping[str, Any]
    checks: list[Mapping[str, Any]] = field(default_factory=list)  # station.profile.Check.to_dict() each
    thresholds: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class InterpolationError(Record):
    kind: ClassVar[str] = "interpolation"
    focus: float
    rms_px: float
    max_px: float
    scheme: str = "leave one focus out"


@dataclass(frozen=True)
class SessionVerdict(Record):
    kind: ClassVar[str] = "qa_session"
    verdict: str


@dataclass(frozen=True)
class ReportWritten(Record):
    kind: ClassVar[str] = "report"
    file: str
    html: str


@dataclass(frozen=True)
class ReportFailed(Record):
    kind: ClassVar[str] = "report"
    failure: str


@dataclass(frozen=True)
class Aborted(Record):
    kind: ClassVar[str] = "aborted"
    reason: str


@dataclass(frozen=True)
class Finished(Record):
    kind: ClassVar[str] = "finished"


_TYPES: tuple[type[Record], ...] = (
    Started,
    Resumed,
    FocusLocked,
    FrameSaved,
    ShotRejected,
    ShotMeasured,
    Fitted,
    FitFailed,
    Stored,
    Fault,
    QARecorded,
    InterpolationError,
    SessionVerdict,
    ReportWritten,
    ReportFailed,
    Aborted,
    Reopened,
    Finished,
)


def from_json(d: Mapping[str, Any]) -> Record | None:
    """The typed record of a manifest line (``None`` for a kind or shape this software does not know)."""
    for cls in _TYPES:
        if cls.kind != d.get("kind"):
            continue
        names = {f.name for f in dataclasses.fields(cls)}
        required = {
            f.name
            for f in dataclasses.fields(cls)
            if f.default is dataclasses.MISSING
            and f.default_factory is dataclasses.MISSING
            and f.name not in cls.optional
        }
        if required <= set(d) and set(d) - {"kind", "t"} <= names:
            return cls(**{k: v for k, v in d.items() if k in names})
    return None
