"""Damaged session files: found before a session goes on, repaired from what the session kept.

:func:`check_session` holds every file the manifest names against it: the frames of each
shot's current attempt (present, checksum), the measurements of the accepted shots, the
uncertainty maps and the profile files of the stored focus settings (checksum where the
manifest records one, and readable as a model file), and the board views that count (``intrinsics``:
present, checksum). ``harp session resume`` runs it first
and stops with one line naming the damage and what to do, instead of failing at QA every
time or saying "finished" over a missing frame.

:func:`repair_session` (``harp session repair DIR``) re-derives what the frames and the
manifest allow, and says what they do not:

* ``session.json`` — rebuilt from ``config.yaml`` and the manifest (its ``base_dir``, against
  which the configuration's relative paths resolve, is ``--base-dir`` or taken as the
  session directory's grandparent, as ``harp session run`` lays it out: said so);
* ``config.yaml`` — restored from the configuration the session was made from when that file
  still has the checksum ``session.json`` records; otherwise it cannot be re-derived;
* a manifest line damaged in the middle — the damaged lines are dropped (the original is kept
  beside it as ``manifest.jsonl.damaged``); what they recorded is re-derived as below;
* a measurement, an uncertainty map or a profile of a stored focus setting — the setting is
  reopened (a ``reopened`` record): it is measured, fitted and stored again from its frames,
  the same fit as before (it is seeded), without the devices;
* a damaged frame of a focus setting not stored yet — its shot is superseded (a ``reject``
  record): ``harp session resume`` captures it again;
* a damaged board view of a focus setting not stored yet — superseded (a ``board-reject`` record):
  ``harp session resume`` takes it again;
* a missing or damaged frame or board view of a stored focus setting — cannot be re-derived; the profile made
  from it stays valid (its provenance keeps the frame's checksum). ``--recapture F`` supersedes
  every shot of focus setting ``F`` and reopens it, so that ``resume`` captures it again.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from station.files import atomic_write_bytes
from station.session import layout
from station.session.records import (
    BoardRejected,
    FitFailed,
    Fitted,
    Reopened,
    ShotMeasured,
    ShotRejected,
    Started,
    Stored,
    parse,
)


@dataclass(frozen=True)
class Damage:
    """One damaged file: where (relative path), what is wrong, which focus setting (and shot or board
    view), and whether :func:`repair_session` can re-derive it (``how``: ``"refit"``, ``"recapture"`` or ``""``)."""

    file: str
    problem: str
    focus_idx: int | None = None
    orientation_idx: int | None = None
    how: str = ""
    view_idx: int | None = None  # a board view's (the ``intrinsics`` stage), else None

    def line(self) -> str:
        return f"{self.file}: {self.problem}"


def _digest(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def _file_problem(path: Path, sha256: str | None) -> str | None:
    if not path.is_file():
        return "missing"
    if sha256 is not None:
        got = _digest(path)
        if got is None:
            return "unreadable"
        if got != sha256:
            return "checksum does not match the manifest"
    return None


def check_session(session) -> list[Damage]:
    """Every damaged file of an open :class:`~station.session.directory.SessionDir` (empty: none)."""
    cfg = session.config
    n_o = len(cfg.capture.orientations)
    stored: set[int] = set()
    last_stored: dict[int, Stored] = {}
    for r in session.typed:
        if isinstance(r, Stored):
            stored.add(r.focus_idx)
            last_stored[r.focus_idx] = r
        elif isinstance(r, Reopened):
            stored.discard(r.focus_idx)
    out: list[Damage] = []
    for f in range(len(cfg.focus_settings)):
        for o in range(n_o):
            for frame in session.frames(f, o):
                problem = _file_problem(session.path / frame.file, frame.sha256)
                if problem is None or (problem == "missing" and f not in stored):
                    continue  # a frame missing from a setting not stored yet is simply captured again
                how = "" if f in stored else "recapture"
                out.append(Damage(frame.file, problem, f, o, how))
        for v, b in sorted(session.boards(f).items()):  # the board views that count (``intrinsics``)
            problem = _file_problem(session.path / b.file, b.sha256)
            if problem is None or (problem == "missing" and f not in stored):
                continue  # a board view missing from a setting not stored yet is simply taken again
            out.append(Damage(b.file, problem, f, None, "" if f in stored else "recapture", view_idx=v))
        if f not in stored:
            continue
        attempts = {o: session.attempt(f, o) for o in range(n_o)}
        for m in _last_measured(session, f):
            if m.attempt == attempts.get(m.orientation_idx) and m.file:
                problem = _file_problem(session.path / m.file, m.sha256)
                if problem:
                    out.append(Damage(m.file, problem, f, m.orientation_idx, "refit"))
        fit = session.last((Fitted, FitFailed), focus_idx=f)  # the last fit: a failed one has no map
        if isinstance(fit, Fitted) and fit.uncertainty_file:
            problem = _file_problem(session.path / fit.uncertainty_file, fit.uncertainty_sha256)
            if problem:
                out.append(Damage(fit.uncertainty_file, problem, f, None, "refit"))
        rec = last_stored[f]
        rel = rec.model_file or layout.profile_file(f)
        problem = _file_problem(session.path / rel, rec.sha256)
        if problem is None:
            from pipeline.model_file import read_model_file  # defers cv2, numpy, yaml

            try:
                read_model_file(session.path / rel)
            except (ValueError, OSError) as exc:
                problem = f"not a readable profile ({' '.join(str(exc).split())})"
        if problem:
            out.append(Damage(rel, problem, f, None, "refit"))
    return out


def _last_measured(session, focus_idx: int) -> list[ShotMeasured]:
    """The last ``measure`` record of each orientation of ``focus_idx``."""
    last: dict[int, ShotMeasured] = {}
    for r in session.of_type(ShotMeasured):
        if r.focus_idx == focus_idx:
            last[r.orientation_idx] = r
    return list(last.values())


def summary(session_path: Path, damage: list[Damage]) -> str:
    """One line for ``resume``: the first damaged file, how many more, and what to do."""
    first = damage[0].line()
    more = f" and {len(damage) - 1} more" if len(damage) > 1 else ""
    todo = f"run: harp session repair {session_path}"
    if all(d.how == "" for d in damage):
        todo += " (it says what cannot be re-derived)"
    return f"{session_path}: damaged: {first}{more}; {todo}"


# ------------------------------------------------------------------ repair
@dataclass
class RepairReport:
    """What :func:`repair_session` did (``fixed``), what it could not (``cannot``), and whether
    the session now needs the devices again (``resume``: shots to capture)."""

    fixed: list[str]
    cannot: list[str]
    resume: bool = False
    refit: bool = False


def repair_files(path: Path, *, base_dir: str | None = None) -> list[str]:
    """Repairs that come before the session can be opened: ``session.json``, ``config.yaml`` and
    damaged manifest lines. Returns what was done; raises :class:`SessionError` for what cannot be."""
    from station.session.directory import (  # defers cv2, numpy, yaml
        SessionError,
        SessionFormatError,
        read_manifest,
        read_session_file,
    )

    path = Path(path)
    done: list[str] = []
    if not (path / layout.MANIFEST).is_file() and not (path / layout.SESSION_FILE).is_file():
        raise SessionError(f"{path}: not a session directory (no {layout.SESSION_FILE}, no {layout.MANIFEST})")
    # the manifest: drop lines that are not records (a torn last line is cut when the session opens)
    manifest = path / layout.MANIFEST
    try:
        read_manifest(manifest)
    except SessionError:
        data = manifest.read_bytes()
        lines = data.split(b"\n")
        kept, dropped = [], 0
        for i, line in enumerate(lines):
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
                ok = isinstance(rec, dict) and "kind" in rec
            except ValueError:
                ok = False
            if ok:
                kept.append(line)
            elif i < len(lines) - 1:
                dropped += 1
        atomic_write_bytes(path / (layout.MANIFEST + ".damaged"), data)
        atomic_write_bytes(manifest, b"".join(line + b"\n" for line in kept))
        done.append(
            f"{layout.MANIFEST}: dropped {dropped} damaged line{'s' if dropped != 1 else ''} "
            f"(the original is kept as {layout.MANIFEST}.damaged); what they recorded is checked below"
        )
    records = parse(read_manifest(manifest)[0])
    # session.json
    meta = None
    try:
        meta = read_session_file(path)
    except SessionFormatError:
        raise  # another version's session: not damage, left as it is
    except SessionError:
        meta = None
    if meta is None:
        if not (path / layout.CONFIG_COPY).is_file():
            raise SessionError(
                f"{path}: {layout.SESSION_FILE} and {layout.CONFIG_COPY} are both damaged or missing: "
                "the session cannot be re-derived"
            )
        guess = base_dir if base_dir is not None else str(path.resolve().parent.parent)
        start = next((r for r in records if isinstance(r, Started)), None)
        created = _dt.datetime.fromtimestamp(float(start.t or 0) if start is not None else 0.0, _dt.UTC)
        text = (path / layout.CONFIG_COPY).read_bytes()
        meta = {
            "format": layout.SESSION_FORMAT,
            "created": created.isoformat(timespec="seconds"),
            "config_source": "",
            "base_dir": guess,
            "station_id": "",
            "software_version": (start.software_version if start is not None else None) or "",
            "lens": [],
            "config_sha256": hashlib.sha256(text).hexdigest(),
            "repaired": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        }
        atomic_write_bytes(path / layout.SESSION_FILE, (json.dumps(meta, indent=1) + "\n").encode())
        how = "given with --base-dir" if base_dir is not None else "taken as the session directory's grandparent"
        done.append(
            f"{layout.SESSION_FILE}: re-derived from {layout.CONFIG_COPY} and the manifest; base_dir {guess} "
            f"({how}: the configuration's relative paths, e.g. store.path, resolve against it)"
        )
    # config.yaml
    copy = path / layout.CONFIG_COPY
    want = meta.get("config_sha256")
    if _digest(copy) is None or (want and _digest(copy) != want) or not _config_loads(copy, meta):
        source = Path(meta.get("config_source") or "")
        if want and source.is_file() and _digest(source) == want:
            atomic_write_bytes(copy, source.read_bytes())
            done.append(f"{layout.CONFIG_COPY}: restored from {source} (same checksum as when the session began)")
        else:
            where = f" (the session was made from {source})" if str(source) not in ("", ".") else ""
            raise SessionError(
                f"{copy}: damaged, and cannot be re-derived{where}: copy the configuration this session ran "
                f"to {copy}, then run: harp session repair {path}"
            )
    return done


def _config_loads(copy: Path, meta: dict) -> bool:
    from station.config import ConfigError, load_config  # defers numpy, yaml

    try:
        load_config(copy, base_dir=meta["base_dir"])
    except ConfigError:
        return False
    return True


def repair_session(session, recapture: tuple[int, ...] = ()) -> RepairReport:
    """Supersede or reopen what :func:`check_session` finds in an open session (see the module
    docstring); ``recapture``: focus indices to capture again whole. Appends records only."""
    cfg = session.config
    n_o = len(cfg.capture.orientations)
    report = RepairReport([], [])
    damage = check_session(session)
    reopen: dict[int, str] = {}
    superseded: set[tuple[int, int]] = set()
    for d in damage:
        if d.how == "recapture" and d.view_idx is not None:
            session.append(BoardRejected(d.focus_idx, d.view_idx, [f"{d.file}: {d.problem} (harp session repair)"]))
            report.fixed.append(f"{d.line()}: the board view will be taken again by harp session resume")
            report.resume = True
        elif d.how == "recapture" and (d.focus_idx, d.orientation_idx) not in superseded:
            superseded.add((d.focus_idx, d.orientation_idx))
            session.append(
                ShotRejected(
                    d.focus_idx, d.orientation_idx, session.attempt(d.focus_idx, d.orientation_idx),
                    [f"{d.file}: {d.problem} (harp session repair)"],
                )
            )  # fmt: skip
            report.fixed.append(f"{d.line()}: its shot will be captured again by harp session resume")
            report.resume = True
        elif d.how == "refit":
            reopen.setdefault(d.focus_idx, d.line())
            report.fixed.append(f"{d.line()}: re-derived from the frames (focus setting {d.focus_idx} fitted again)")
        elif d.focus_idx not in recapture:
            made = (
                f"the profile of focus setting {d.focus_idx} was made from it and stays valid (its provenance "
                "keeps the checksum)"
                if d.view_idx is None
                else f"the camera matrix of focus setting {d.focus_idx} was measured from it and stays valid (the "
                "manifest keeps the checksum)"
            )
            report.cannot.append(
                f"{d.line()}: cannot be re-derived; {made}; to capture that setting again: "
                f"harp session repair {session.path} --recapture {d.focus_idx}"
            )
    for f in recapture:
        if not 0 <= f < len(cfg.focus_settings):
            raise ValueError(f"--recapture {f}: the session has focus settings 0..{len(cfg.focus_settings) - 1}")
        for o in range(n_o):
            if (f, o) not in superseded:
                session.append(ShotRejected(f, o, session.attempt(f, o), ["captured again (harp session repair)"]))
        for v in sorted(session.boards(f)):
            session.append(BoardRejected(f, v, ["taken again (harp session repair --recapture)"]))
        reopen[f] = "captured again (harp session repair --recapture)"
        report.fixed.append(f"focus setting {f}: every shot will be captured again by harp session resume")
        report.resume = True
    stored = set(session.stored_ids())
    for f, why in sorted(reopen.items()):
        if f in stored:
            session.append(Reopened(f, why))
            report.refit = True
    return report


def needs_capture(session) -> bool:
    """Whether what the session lacks includes frames or board views (so the devices are needed)."""
    from station.session.plan import BoardView, Capture, plan_session  # defers numpy, yaml

    return any(isinstance(step, (Capture, BoardView)) for step in plan_session(session.config, session.done_keys()))
