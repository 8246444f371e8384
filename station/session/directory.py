"""A session directory: atomically written frames plus an append-only manifest.

What lives where is :mod:`station.session.layout`'s (the one module naming the
paths); what the manifest says is :mod:`station.session.records`' (one dataclass
per record kind; :meth:`SessionDir.append` takes a record, or a plain mapping).

The manifest is the truth: a frame file counts only once its ``frame``
record is in the manifest (it is renamed into place, fsync'ed, *then*
recorded). A torn last line, left by a kill in the middle of a write, is
dropped when the manifest is read and cut off before the next append, so a
resumed session continues exactly where the last complete record left it.
Records are read back typed (:class:`~station.session.records.ManifestReads`:
:meth:`~station.session.records.ManifestReads.of_type`, ``frames``, ``attempt``;
:func:`read_records` without opening the session), the lines as written beside them
(``lines``); a ``reject`` record supersedes the shot's frames (the next attempt captures
it again).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import errno
import fcntl
import hashlib
import io
import json
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.plain import json_default
from station import __version__
from station.config import Config, ConfigError, load_config
from station.errors import HarpError
from station.files import atomic_write_bytes, describe_os_error
from station.session import layout
from station.session.frame_files import decode_frame, encode_frame
from station.session.layout import CONFIG_COPY, MANIFEST, SESSION_FILE
from station.session.plan import board_key, board_unchecked_key, frame_key, stored_key
from station.session.records import (
    BoardAccepted,
    FrameSaved,
    ManifestReads,
    Record,
    Reopened,
    ShotRejected,
    Stored,
    finished_in,
    from_json,
    parse,
)


class SessionError(HarpError, RuntimeError):
    """A session directory that cannot be used; message is one line."""


class SessionAborted(Exception):
    """The session cannot go on; ``str()`` is the one-line reason (the executor records it as ``aborted``).

    Not a HarpError: it never leaves the session's executor, which catches it, records the abort in the
    manifest and ends the run with a :class:`~station.session.executor.SessionResult` of exit code
    :data:`station.exit_codes.EXIT_ABORTED`, which ``harp session`` raises as a HarpError with the
    result's message (said once by the entry point)."""


def read_session_file(path: Path) -> dict:
    """The mapping in ``DIR/session.json``; a damaged one is a :class:`SessionError` saying what to do."""
    f = Path(path) / SESSION_FILE
    try:
        meta = json.loads(f.read_text(encoding="utf-8"))
        if not isinstance(meta, dict) or not isinstance(meta.get("base_dir"), str):
            raise ValueError("not a session description (no base_dir)")
    except (ValueError, UnicodeDecodeError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SessionError(f"{f}: damaged ({reason}); run: harp session repair {path}") from None
    fmt = meta.get("format", layout.SESSION_FORMAT)
    if fmt != layout.SESSION_FORMAT:
        raise SessionFormatError(
            f"{f}: session format {fmt!r}, but harp station {__version__} reads format {layout.SESSION_FORMAT}"
            f"{' (written by a newer version)' if isinstance(fmt, int) and fmt > layout.SESSION_FORMAT else ''}: "
            "open it with the version that wrote it (its software_version); nothing was changed"
        )
    return meta


class SessionFormatError(SessionError):
    """A ``session.json`` of a format this version does not read (:data:`layout.SESSION_FORMAT`): not damage,
    so a repair leaves it as it is."""


# --------------------------------------------------------------- manifest
def read_manifest(path: Path) -> tuple[list[dict], int]:
    """Complete records of a manifest and the byte length they occupy.

    A last line without its newline, or one that is not valid JSON, is a torn
    write: it is not returned and not counted in the length. A corrupt line
    *before* the last one is an error (the file was damaged, not torn).
    """
    if not path.exists():
        return [], 0
    data = path.read_bytes()
    records: list[dict] = []
    good = 0
    pos = 0
    while pos < len(data):
        nl = data.find(b"\n", pos)
        if nl < 0:
            break  # torn: no newline
        line = data[pos:nl]
        try:
            rec = json.loads(line)
            if not isinstance(rec, dict):
                raise ValueError("not an object")
        except ValueError:
            if data[nl + 1 :].strip():
                raise SessionError(
                    f"{path}: line {len(records) + 1}: corrupt manifest record; run: harp session repair {path.parent}"
                ) from None
            break  # torn last line
        records.append(rec)
        pos = good = nl + 1
    return records, good


def read_records(path: Path) -> list[Record]:
    """The typed records of a manifest file (:func:`read_manifest`, :func:`station.session.records.parse`)."""
    return parse(read_manifest(path)[0])


def lost_manifest(path: Path, lines: Sequence[Any]) -> str | None:
    """The one line for a session whose manifest is missing or holds no record (``lines``: what was read of it)
    while its directories hold files (frames, measurements, profiles, board views) that only a manifest records,
    else None.

    A session records its ``start`` before it writes any of them, so this is damage (a manifest deleted,
    emptied or replaced), never a kill. Without the manifest the files cannot be checked against their
    checksums, and a resume would capture the whole plan again over the frames of the same names."""
    if lines:
        return None
    path = Path(path)
    written = {
        sub: n
        for sub in layout.ATOMIC_DIRS
        if (n := sum(1 for p in _listing(path / sub) if not p.name.startswith(".")))
    }
    if not written:
        return None
    state = "missing" if not (path / MANIFEST).exists() else "empty"
    held = ", ".join(f"{sub}/ {n} file{'s' if n != 1 else ''}" for sub, n in written.items())
    return (
        f"{path / MANIFEST}: {state}, but the session holds what it recorded ({held}); without it "
        f"they cannot be checked and a resume would capture over them: restore {MANIFEST} from a backup "
        "(nothing was changed), or start a new session with harp session run"
    )


def _listing(directory: Path) -> list[Path]:
    try:
        return list(directory.iterdir())
    except (FileNotFoundError, NotADirectoryError):
        return []


class SessionDir(ManifestReads):
    """One session's directory. Create with :meth:`create`, reopen with :meth:`open`.

    Holds an exclusive ``flock`` on the directory while open, so two processes
    cannot resume the same session at once. Opened ``read_only`` (:meth:`open`, for ``harp qa``) it
    holds a shared one where the lock file can be read (several readers at once, none while a
    session runs in it) and writes nothing: no torn line cut, no temporary removed, no space held
    back, :meth:`append` refused; a session on a read-only file system, or one another user's
    station wrote, can be judged.
    """

    def __init__(self, path: Path, records: list[dict], good_len: int, *, read_only: bool = False):
        self.path = Path(path)
        self.meta = read_session_file(self.path)
        self.read_only = read_only
        self._lock_fh = None
        self._manifest = None
        if read_only:
            with contextlib.suppress(OSError):  # no lock file, or one this user cannot read: nothing to share
                self._lock_fh = open(self.path / layout.LOCK, "rb")
        else:
            self._lock_fh = open(self.path / layout.LOCK, "a+")
        if self._lock_fh is not None:
            try:
                fcntl.flock(self._lock_fh, (fcntl.LOCK_SH if read_only else fcntl.LOCK_EX) | fcntl.LOCK_NB)
            except BlockingIOError:
                self._lock_fh.close()
                raise SessionError(
                    f"{self.path}: session is in use by another process (a session running in it, or another harp "
                    "command using it); wait until it ends, then run again"
                ) from None
        self.lines = records
        self.typed = parse(records)
        self.config: Config | None = None
        if read_only:
            return
        manifest = self.path / MANIFEST
        if manifest.exists() and manifest.stat().st_size != good_len:
            with open(manifest, "r+b") as fh:  # cut a torn last line
                fh.truncate(good_len)
                fh.flush()
                os.fsync(fh.fileno())
        self._manifest = open(manifest, "ab", buffering=0)  # unbuffered: a failed append is cut back whole
        self._manifest_size = good_len
        # temporary files of writes a kill interrupted (never renamed into place)
        for sub in layout.ATOMIC_DIRS:
            if (self.path / sub).is_dir():
                for tmp in (self.path / sub).glob(".*.tmp*"):
                    tmp.unlink(missing_ok=True)
        try:
            self.hold_reserve()
        except SessionError:
            self.close()
            raise

    # ------------------------------------------------------------ space
    def hold_reserve(self) -> None:
        """Hold :data:`~station.session.layout.RESERVE_BYTES` of disk in ``.reserve`` (allocated,
        not sparse), so that when a write finds the disk full, :meth:`release_reserve` makes room for
        the ``aborted`` record. A disk too full for it is a :class:`SessionError` naming what to do."""
        p = self.path / layout.RESERVE
        with contextlib.suppress(OSError):
            if p.stat().st_size >= layout.RESERVE_BYTES:
                return
        try:
            fd = os.open(p, os.O_WRONLY | os.O_CREAT, 0o600)
            try:
                os.posix_fallocate(fd, 0, layout.RESERVE_BYTES)
                os.fsync(fd)
            finally:
                os.close(fd)
        except OSError as exc:
            p.unlink(missing_ok=True)
            raise SessionError(
                describe_os_error(
                    OSError(exc.errno, exc.strerror, str(self.path)),
                    f"free some space, then: harp session resume {self.path}"
                    if exc.errno in (errno.ENOSPC, errno.EDQUOT)
                    else None,
                )
            ) from None

    def release_reserve(self) -> None:
        """Give the reserved space back (a write found the disk full); :meth:`hold_reserve` at the next open."""
        (self.path / layout.RESERVE).unlink(missing_ok=True)

    # ------------------------------------------------------------ lifecycle
    @classmethod
    def create(cls, root: Path, config: Config, *, name: str | None = None, software_version: str = "") -> SessionDir:
        """Make a new session directory under ``root`` for ``config``."""
        root = Path(root)
        now = _dt.datetime.now(_dt.UTC)
        if name is None:
            stem = re.sub(r"[^A-Za-z0-9_.-]+", "-", config.lens.serial)
            name = f"{now:%Y%m%dT%H%M%SZ}-{stem}"
        path = root / name
        try:
            path.mkdir(parents=True, exist_ok=False)
        except FileExistsError:
            raise SessionError(f"{path}: already exists") from None
        except OSError as exc:
            raise SessionError(f"{path}: cannot create session directory: {exc.strerror}") from None
        try:
            return cls._fill(path, config, now, software_version)
        except OSError as exc:
            raise SessionError(f"cannot create the session: {describe_os_error(exc)}") from None

    @classmethod
    def _fill(cls, path: Path, config: Config, now: _dt.datetime, software_version: str) -> SessionDir:
        for sub in layout.WRITTEN_DIRS:
            (path / sub).mkdir()
        config_bytes = config.path.read_bytes()
        atomic_write_bytes(path / CONFIG_COPY, config_bytes)
        meta = {
            "format": layout.SESSION_FORMAT,
            "created": now.isoformat(timespec="seconds"),
            "config_source": str(config.path),
            "base_dir": str(config.base_dir),
            "station_id": config.station.id,
            "software_version": software_version,
            "lens": [config.lens.maker, config.lens.model, config.lens.serial],
            "config_sha256": hashlib.sha256(config_bytes).hexdigest(),
        }
        atomic_write_bytes(path / SESSION_FILE, (json.dumps(meta, indent=1) + "\n").encode())
        s = cls(path, [], 0)
        s.config = config
        return s

    @classmethod
    def open(cls, path: Path, *, read_only: bool = False) -> SessionDir:
        """Reopen an existing session (for resume; ``read_only``: to judge it, nothing written, see the
        class); reloads and validates its config. A manifest missing or empty while the session holds
        files it recorded is a :class:`SessionError` (:func:`lost_manifest`): nothing is opened,
        created or captured over."""
        path = Path(path)
        if not (path / SESSION_FILE).is_file():
            raise SessionError(f"{path}: not a session directory (no {SESSION_FILE})")
        records, good = read_manifest(path / MANIFEST)
        lost = lost_manifest(path, records)
        if lost is not None:
            raise SessionError(lost)
        s = cls(path, records, good, read_only=read_only)
        try:
            s.config = load_config(path / CONFIG_COPY, base_dir=s.meta["base_dir"])
        except ConfigError as exc:
            s.close()
            raise SessionError(
                f"{exc} (the session's copy of its configuration; harp session repair {path} says what can be done)"
            ) from None
        except Exception:
            s.close()
            raise
        return s

    def close(self) -> None:
        for fh in (getattr(self, "_manifest", None), getattr(self, "_lock_fh", None)):
            if fh is not None and not fh.closed:
                fh.close()

    def __enter__(self) -> SessionDir:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --------------------------------------------------------------- writes
    def append(self, record: Record | Mapping[str, Any]) -> dict:
        """Append one record to the manifest, durably (flush + fsync); returns the line's mapping."""
        if self._manifest is None:
            raise SessionError(f"{self.path}: opened read-only; nothing can be recorded in it")
        data = record.to_json() if isinstance(record, Record) else dict(record)
        record = {"t": round(_dt.datetime.now(_dt.UTC).timestamp(), 3), **data}
        line = (json.dumps(record, separators=(",", ":"), default=json_default) + "\n").encode()
        fd = self._manifest.fileno()
        start = self._manifest_size
        try:
            view = memoryview(line)
            while view:
                view = view[os.write(fd, view) :]
            os.fsync(fd)
        except OSError as exc:  # a full disk: cut the part written, so the manifest stays whole
            with contextlib.suppress(OSError):
                os.ftruncate(fd, start)
            raise OSError(exc.errno, exc.strerror, str(self.path / MANIFEST)) from None
        self._manifest_size = start + len(line)
        self.lines.append(record)
        typed = from_json(record)
        if typed is not None:
            self.typed.append(typed)
        return record

    def write_frame(
        self,
        focus_idx: int,
        orientation_idx: int,
        frame_idx: int,
        image: np.ndarray,
        metadata: dict[str, Any] | None = None,
    ) -> FrameSaved:
        """Write a frame atomically, then record it in the manifest; returns its record (with its time)."""
        attempt = self.attempt(focus_idx, orientation_idx)
        rel = layout.frame_file(focus_idx, orientation_idx, attempt, frame_idx)
        data = encode_frame(image)
        atomic_write_bytes(self.path / rel, data)
        line = self.append(
            FrameSaved(
                focus_idx, orientation_idx, frame_idx, attempt, rel, hashlib.sha256(data).hexdigest(), metadata or {}
            )
        )
        return FrameSaved(**{k: v for k, v in line.items() if k != "kind"})

    def write_arrays(self, relpath: str, arrays: dict[str, np.ndarray]) -> dict:
        """Write ``arrays`` as an ``.npz`` at ``relpath`` (inside the session) atomically;
        returns ``{"file": relpath, "sha256": ...}`` for the record that uses it."""
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)  # deflate: lossless, what np.load reads
        data = buf.getvalue()
        path = self.path / relpath
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, data)
        return {"file": relpath, "sha256": hashlib.sha256(data).hexdigest()}

    def read_arrays(self, relpath: str, sha256: str | None = None) -> dict[str, np.ndarray]:
        """Arrays of an ``.npz`` written by :meth:`write_arrays` (checked against ``sha256``)."""
        data = (self.path / relpath).read_bytes()
        if sha256 is not None and hashlib.sha256(data).hexdigest() != sha256:
            raise SessionError(f"{self.path / relpath}: checksum does not match the manifest")
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            return {k: z[k] for k in z.files}

    # ---------------------------------------------------------------- reads
    def read_frame(self, record: FrameSaved, verify: bool = True) -> np.ndarray:
        """The frame of a record, exactly as captured (a PNG frame, or a PGM of an older session:
        :func:`~station.session.frame_files.decode_frame`), checked against the manifest's SHA-256."""
        data = (self.path / record.file).read_bytes()
        if verify and hashlib.sha256(data).hexdigest() != record.sha256:
            raise SessionError(f"{self.path / record.file}: checksum does not match the manifest")
        return decode_frame(data)

    def done_keys(self) -> set[tuple]:
        """Keys for :func:`station.plan.plan_session` of what this session already has."""
        keys = set()
        attempts: dict[tuple, int] = {}
        for rej in self.of_type(ShotRejected):
            k = (rej.focus_idx, rej.orientation_idx)
            attempts[k] = attempts.get(k, 0) + 1
        for r in self.of_type(FrameSaved):
            if r.attempt == attempts.get((r.focus_idx, r.orientation_idx), 0) and (self.path / r.file).is_file():
                keys.add(frame_key(r.focus_idx, r.orientation_idx, r.frame_idx))
        k = self.config.intrinsics
        checked = k is not None and k.placement == "operator"  # each view checked as it is saved
        accepted = {(r.focus_idx, r.view_idx, r.attempt) for r in self.of_type(BoardAccepted)}
        for f in range(len(self.config.focus_settings)):
            for b in self.boards(f).values():  # a view superseded since (board-reject) is taken again
                if not (self.path / b.file).is_file():
                    continue
                if checked and (b.focus_idx, b.view_idx, b.attempt) not in accepted:
                    keys.add(board_unchecked_key(b.focus_idx, b.view_idx))  # the run stopped before its check
                else:
                    keys.add(board_key(b.focus_idx, b.view_idx))
        for rec in self.typed:  # a later ``reopened`` record takes a stored focus setting back
            if isinstance(rec, Stored):
                keys.add(stored_key(rec.focus_idx))
            elif isinstance(rec, Reopened):
                keys.discard(stored_key(rec.focus_idx))
        return keys

    @property
    def finished(self) -> bool:
        """Finished, and nothing taken back since (:func:`station.session.records.finished_in`)."""
        return finished_in(self.typed)
