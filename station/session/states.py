"""What state a session directory is in, from its manifest (for ``harp session list`` and ``results.json``).

=================  ===================================================================
state              meaning
=================  ===================================================================
``complete``       a ``finished`` record: captured, fitted, judged (QA) and reported
``failed``         stopped by a fault: the last stop is an ``aborted`` record with a reason
                   other than the user's interrupt (device fault, a shot that kept failing
                   its checks, a failed fit); ``harp session resume DIR`` continues it
``interrupted``    stopped by the user (Ctrl-C) or killed (no ``finished``, no fault as the
                   last stop); ``harp session resume DIR`` continues it
``running``        another process holds the session directory's lock right now
=================  ===================================================================
"""

from __future__ import annotations

import fcntl
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from station.ctrl_c import stop_signal, stopper
from station.session.layout import MANIFEST, SESSION_FILE
from station.session.records import (
    Aborted,
    FrameSaved,
    Record,
    Resumed,
    SessionVerdict,
    Started,
    Stored,
    finished_in,
    parse,
)

COMPLETE, FAILED, INTERRUPTED, RUNNING = "complete", "failed", "interrupted", "running"
STATES = (COMPLETE, FAILED, INTERRUPTED, RUNNING)

USER_INTERRUPT = "interrupted by the user"
"""The reason of the ``aborted`` record a Ctrl-C leaves (:mod:`station.session.executor`)."""
STOPPED_BY = "stopped by "
"""How the reason of the ``aborted`` record a stop signal leaves starts (``stopped by SIGTERM``,
:func:`station.ctrl_c.stop_signals_as_ctrl_c`): an interruption, as a Ctrl-C."""


def stop_reason() -> str:
    """The reason of the ``aborted`` record the command's interruption leaves: :data:`USER_INTERRUPT` after a
    Ctrl-C, ``stopped by SIGTERM`` (SIGHUP) after a stop signal."""
    return USER_INTERRUPT if stop_signal() is None else f"{STOPPED_BY}{stopper()}"


def is_interruption(reason: str) -> bool:
    """Whether an ``aborted`` record's reason is an interruption (:func:`stop_reason`), not a failure."""
    return reason == USER_INTERRUPT or reason.startswith(STOPPED_BY)


def session_state(records: Iterable[Record]) -> str:
    """``complete``, ``failed`` or ``interrupted`` from a session's manifest records (in order)."""
    records = list(records)
    if finished_in(records):  # finished, nothing taken back since (a repair's setting to capture again)
        return COMPLETE
    last_stop: Aborted | None = None
    for r in records:
        if isinstance(r, Aborted):
            last_stop = r
        elif isinstance(r, (Started, Resumed)):
            last_stop = None  # a later run: its own stop (or none, if killed) counts
    if last_stop is not None and not is_interruption(last_stop.reason):
        return FAILED
    return INTERRUPTED


def in_use(session_dir: str | Path) -> bool:
    """True when another process holds the session directory's lock (a session running in it)."""
    lock = Path(session_dir) / ".lock"
    if not lock.exists():
        return False
    try:
        with open(lock, "a+") as fh:
            try:
                fcntl.flock(fh, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                return True
            fcntl.flock(fh, fcntl.LOCK_UN)
    except OSError:
        return False
    return False


@dataclass(frozen=True)
class SessionSummary:
    """One session directory as ``harp session list`` shows it."""

    name: str
    path: Path
    state: str
    verdict: str | None
    lens: str
    focus_settings: int
    profiles: int
    frames: int
    created: str | None
    last: str | None
    stop_reason: str | None

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "path": str(self.path.resolve()),
            "state": self.state,
            "verdict": self.verdict,
            "lens": self.lens,
            "focus_settings": self.focus_settings,
            "profiles": self.profiles,
            "frames": self.frames,
            "created": self.created,
            "last_activity": self.last,
            "stop_reason": self.stop_reason,
        }


def summarise(session_dir: str | Path) -> SessionSummary:
    """The :class:`SessionSummary` of a session directory, read without locking it (a session may be
    running in it). Raises SessionError (one line) for a directory that is not a readable session."""
    import datetime as _dt

    from station.session.directory import (  # defers cv2, numpy, yaml
        SessionError,
        lost_manifest,
        read_manifest,
        read_session_file,
    )

    path = Path(session_dir)
    try:
        meta = read_session_file(path)  # damaged, or a format this version does not read: one line
    except OSError as exc:
        raise SessionError(f"{path / SESSION_FILE}: cannot be read ({exc})") from None
    lines, _ = read_manifest(path / MANIFEST)
    lost = lost_manifest(path, lines)
    if lost is not None:  # not "interrupted, 0 frames": what it recorded is there, the record of it is not
        raise SessionError(lost)
    records = parse(lines)
    state = RUNNING if in_use(path) else session_state(records)
    verdicts = [r.verdict for r in records if isinstance(r, SessionVerdict)]
    stops = [r.reason for r in records if isinstance(r, Aborted)]
    n_focus = None
    try:
        import yaml

        cfg = yaml.safe_load((path / "config.yaml").read_text(encoding="utf-8")) or {}
        n_focus = len((cfg.get("focus") or {}).get("settings") or [])
    except (OSError, ValueError, AttributeError, yaml.YAMLError):
        pass
    lens = meta.get("lens")
    times = [r["t"] for r in lines if isinstance(r.get("t"), (int, float))]  # lines of any kind count
    last = _dt.datetime.fromtimestamp(max(times), _dt.UTC).isoformat(timespec="seconds") if times else None
    return SessionSummary(
        name=path.name,
        path=path,
        state=state,
        verdict=verdicts[-1] if verdicts else None,
        lens=" ".join(str(x) for x in lens) if isinstance(lens, list) else "",
        focus_settings=n_focus if n_focus is not None else 0,
        profiles=len({r.focus_idx for r in records if isinstance(r, Stored)}),
        frames=sum(1 for r in records if isinstance(r, FrameSaved)),
        created=meta.get("created"),
        last=last,
        stop_reason=stops[-1] if stops and state in (FAILED, INTERRUPTED) else None,
    )


def sessions_in(root: str | Path) -> tuple[list[SessionSummary], list[str]]:
    """Every session directory directly under ``root`` (or ``root`` itself when it is one), oldest first, and one
    line per directory that looks like a session but cannot be read."""
    from station.session.directory import SessionError  # defers cv2, numpy, yaml

    found, problems = [], []
    root = Path(root)
    for d in [root] if (root / SESSION_FILE).is_file() else sorted(root.iterdir()):
        if not (d / SESSION_FILE).is_file():
            continue
        try:
            found.append(summarise(d))
        except SessionError as exc:
            problems.append(str(exc))
    found.sort(key=lambda s: (s.created or "", s.name))
    return found, problems
