"""The manifest's vocabulary: one frozen dataclass per record kind.

A session directory's ``manifest.jsonl`` (:mod:`station.session.directory`) holds one
JSON object per line, ``{"t": <unix time>, "kind": <kind>, ...fields}``. The executor
(:mod:`station.session.executor`), QA (:mod:`station.qa.judge`) and the session run
(:mod:`station.session_run`) write these records; subscribers
(:mod:`station.session.progress`) receive them as they are written. The JSON of each
record is its fields in order (``None`` fields that are optional are left out).

Reading is typed too: :func:`from_json` (one line) and :func:`parse` (a manifest's lines)
return these records, each with the time its line was written (``t``); lines of other
versions read for what they hold (unknown keys and kinds left out, missing fields their
defaults or ``None``). :class:`ManifestReads` is what every reader asks of them (records of a
type, the last one matching, a shot's current attempt and frames, the stored focus settings),
for the open session directory (:class:`station.session.directory.SessionDir`) and the
read-only archived session (:mod:`station.reprocess`) alike.

=================  ===============================================================
kind               record
=================  ===============================================================
``start``          :class:`Started` (``resume``: :class:`Resumed`) — software version
``focus``          :class:`FocusLocked` — focus index, setting, read-back
``frame``          :class:`FrameSaved` — a frame file (name from :mod:`layout`), sha256, metadata
``reject``         :class:`ShotRejected` — a shot failed its checks (its frames superseded)
``measure``        :class:`ShotMeasured` — an accepted shot's figures and measurement file
``fit``            :class:`Fitted` or :class:`FitFailed` — a focus setting's fit
``board-ask``      :class:`BoardWanted` — the operator is asked to place the board (which pose, why)
``board``          :class:`BoardSaved` — a board view's file, sha256, turntable angles
``board-ok``       :class:`BoardAccepted` — an operator-placed board view passed its checks (its corners)
``board-reject``   :class:`BoardRejected` — a board view superseded (failed its checks, skipped, damaged)
``intrinsics``     :class:`IntrinsicsMeasured` — a focus setting's camera matrix from its board views
``colour``         :class:`ColourMeasured` — a colour camera's TCA and vignetting of a focus setting, in short
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
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar


@dataclass(frozen=True)
class Record:
    """Base of the manifest records; ``kind`` names the record in the file.

    ``t`` is the time the line was written (unix seconds), set on records read back from a
    manifest (:func:`parse`); a record about to be written has none (the session directory
    stamps the line). It takes no part in comparisons.
    """

    kind: ClassVar[str] = ""
    optional: ClassVar[tuple[str, ...]] = ()
    """Fields left out of the JSON when ``None``."""
    t: float | None = field(default=None, kw_only=True, compare=False)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind}
        for f in dataclasses.fields(self):
            if f.name == "t":
                continue
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
class BoardSaved(Record):
    """A board view of the camera-matrix stage (``intrinsics``): its file (lossless, from
    :mod:`station.session.layout`), sha256, the commanded and read-back turntable angles (commanded None:
    placed by the operator), the capture attempt (the times the view was superseded before), the tilt axis's
    read-back (``placement: stage``; None: no tilt axis)."""

    kind: ClassVar[str] = "board"
    optional: ClassVar[tuple[str, ...]] = ("tilt_deg",)
    focus_idx: int
    view_idx: int
    file: str
    sha256: str
    commanded_deg: float | None
    stage_deg: float | None
    attempt: int = 0
    tilt_deg: float | None = None


@dataclass(frozen=True)
class BoardWanted(Record):
    """The operator is asked to place the board (``intrinsics.placement: operator``): view ``view_idx`` of
    focus setting ``focus_idx``, capture ``attempt`` (the times it was rejected before), ``request`` (a
    :meth:`station.session.board_requests.BoardRequest.to_dict`: pose, where in the image, why) and why
    the last attempt was rejected (``problems``)."""

    kind: ClassVar[str] = "board-ask"
    focus_idx: int
    view_idx: int
    attempt: int
    request: Mapping[str, Any]
    problems: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class BoardAccepted(Record):
    """An operator-placed board view passed its checks: the board's corners found (``corners``, image
    pixels ``[x, y]``, rounded to 0.01 px, in an image of ``size`` [width, height]: the board coverage of
    the live page)."""

    kind: ClassVar[str] = "board-ok"
    focus_idx: int
    view_idx: int
    attempt: int
    corners: list[list[float]]
    size: list[int]


@dataclass(frozen=True)
class BoardRejected(Record):
    """A board view superseded: it failed its checks (no board, too few corners, blurred), the operator
    skipped it, or ``harp session repair`` found its file damaged (``reasons``). Its next capture is
    attempt + 1 (:meth:`ManifestReads.board_attempt`)."""

    kind: ClassVar[str] = "board-reject"
    focus_idx: int
    view_idx: int
    reasons: list[str]
    skipped: bool = False


@dataclass(frozen=True)
class IntrinsicsMeasured(Record):
    """The camera matrix of a focus setting from its board views (``intrinsics``: the
    :meth:`pipeline.intrinsics.Intrinsics.to_dict`; None with ``failure``: the profile is stored
    without one) and the views rejected, ``[file, reason]`` each."""

    kind: ClassVar[str] = "intrinsics"
    optional: ClassVar[tuple[str, ...]] = ("intrinsics", "failure")
    focus_idx: int
    rejected: list[list[str]]
    intrinsics: Mapping[str, Any] | None = None
    failure: str | None = None


@dataclass(frozen=True)
class ColourMeasured(Record):
    """A colour camera's TCA and vignetting of focus setting ``focus_idx`` (:mod:`station.session.colour`),
    in short (``summary``: :func:`station.session.colour.colour_summary`'s cells); the documents are the
    profile's (its model file's ``colour`` key)."""

    kind: ClassVar[str] = "colour"
    focus_idx: int
    summary: Mapping[str, str]


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
    BoardWanted,
    BoardSaved,
    BoardAccepted,
    BoardRejected,
    IntrinsicsMeasured,
    ColourMeasured,
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
    """The typed record of one manifest line (``None`` for a kind this software does not know).

    Lines written by other versions read for what they hold: keys this software does not know
    are left out (the line as written stays in :attr:`ManifestReads.lines`), and a field an
    older line did not write reads as its default, else ``None``. Where two records share a
    kind (``fit``: :class:`Fitted` / :class:`FitFailed`; ``report``), the line is the one whose
    fields it holds.
    """
    best: tuple[tuple[int, int], type[Record], list[str], set[str]] | None = None
    for cls in _TYPES:
        if cls.kind != d.get("kind"):
            continue
        fields = [f for f in dataclasses.fields(cls) if f.name != "t"]
        names = [f.name for f in fields]
        required = {
            f.name
            for f in fields
            if f.default is dataclasses.MISSING
            and f.default_factory is dataclasses.MISSING
            and f.name not in cls.optional
        }
        missing = required - set(d)
        score = (len(missing), -len(set(d) & set(names)))
        if best is None or score < best[0]:
            best = (score, cls, names, missing)
    if best is None:
        return None
    _score, cls, names, missing = best
    values = {k: d[k] for k in names if k in d}
    values.update(dict.fromkeys(missing))
    t = d.get("t")
    return cls(**values, t=float(t) if isinstance(t, (int, float)) and not isinstance(t, bool) else None)


def finished_in(records: Iterable[Record]) -> bool:
    """Whether a session's records (in order) end finished: a ``finished`` record that nothing taken back since
    follows (``harp session repair``'s ``reopened``, ``reject`` and ``board-reject``: a setting to fit or shots and
    views to capture again, which the next resume does)."""
    done = False
    for r in records:
        if isinstance(r, Finished):
            done = True
        elif isinstance(r, (Reopened, ShotRejected, BoardRejected)):
            done = False
    return done


def parse(lines: Iterable[Mapping[str, Any]]) -> list[Record]:
    """The typed records of manifest lines, in order (lines of unknown kinds left out)."""
    return [r for r in map(from_json, lines) if r is not None]


R = TypeVar("R", bound=Record)


class ManifestReads:
    """What a session's manifest says, read as typed records (shared by the session directory,
    :class:`station.session.directory.SessionDir`, and the read-only archived session of
    :mod:`station.reprocess`). ``lines`` are the manifest's lines as written (every key), ``typed``
    their records (:func:`parse`)."""

    lines: list[dict[str, Any]]
    typed: list[Record]

    def of_type(self, cls: type[R] | tuple[type[R], ...]) -> Iterator[R]:
        """The records of one type (or of any of a tuple of types), in the order written."""
        return (r for r in self.typed if isinstance(r, cls))

    def last(self, cls: type[R] | tuple[type[R], ...], **match: Any) -> R | None:
        """The last record of type ``cls`` (or any of a tuple) whose fields equal ``match``, or None."""
        found = None
        for r in self.of_type(cls):
            if all(getattr(r, k, None) == v for k, v in match.items()):
                found = r
        return found

    def attempt(self, focus_idx: int, orientation_idx: int) -> int:
        """Current capture attempt of a shot: the number of times it was rejected."""
        return sum(
            1 for r in self.of_type(ShotRejected) if (r.focus_idx, r.orientation_idx) == (focus_idx, orientation_idx)
        )

    def frames(self, focus_idx: int, orientation_idx: int) -> list[FrameSaved]:
        """Frame records of the shot's current attempt, by frame index (last wins)."""
        a = self.attempt(focus_idx, orientation_idx)
        by_idx = {
            r.frame_idx: r
            for r in self.of_type(FrameSaved)
            if (r.focus_idx, r.orientation_idx, r.attempt) == (focus_idx, orientation_idx, a)
        }
        return [by_idx[i] for i in sorted(by_idx)]

    def board_attempt(self, focus_idx: int, view_idx: int) -> int:
        """Current capture attempt of a board view: the number of times it was superseded."""
        return sum(1 for r in self.of_type(BoardRejected) if (r.focus_idx, r.view_idx) == (focus_idx, view_idx))

    def boards(self, focus_idx: int) -> dict[int, BoardSaved]:
        """``{view_idx: record}`` of the board views of ``focus_idx`` that count: saved at the view's current
        attempt (the last capture wins; a view superseded since, :class:`BoardRejected`, is left out)."""
        out: dict[int, BoardSaved] = {}
        for r in self.typed:
            if getattr(r, "focus_idx", None) != focus_idx:
                continue
            if isinstance(r, BoardSaved):
                out[r.view_idx] = r
            elif isinstance(r, BoardRejected):
                out.pop(r.view_idx, None)
        return out

    def stored_ids(self) -> dict[int, int | None]:
        """``{focus_idx: store id}`` of every ``stored`` record (the last one of a focus setting wins)."""
        return {r.focus_idx: r.profile_id for r in self.of_type(Stored)}
