"""Where a session directory keeps things: the one place that names every path in it.

Layout (paths relative to the session directory ``DIR``)::

    session.json                     what the session is (written once, atomically)
    config.yaml                      verbatim copy of the configuration it runs
    manifest.jsonl                   one JSON record per line (station.session.records)
    frames/f{f}_o{o}_a{a}_i{i}.png   frame i of attempt a of orientation o at focus setting f, lossless
                                     (station.session.frame_files; .pgm in older sessions)
    measurements/f{f}_o{o}_a{a}.npz  the measured edges of that shot (station.session.evidence)
    boards/f{f}_v{v}[_a{a}].png      board view v at focus setting f (the ``intrinsics`` stage), lossless;
                                     _a{a}: its capture attempt a > 0 (after a rejection)
    profiles/focus{f}.yaml           the profile (model file) of focus setting f
    profiles/focus{f}_uncertainty.npz  its bootstrap field-uncertainty map
    report/                          the session report (station.qa.report)
    results.json                     the session's results for scripts (station.qa.results)
    .lock                            flock'ed while a process has the session open
    .reserve                         space held back so that a full disk can still be recorded

``f``, ``o``, ``a``, ``i`` are indices: of the focus setting in ``focus.settings``, of
the orientation in ``capture.orientations_deg`` (with ``capture.shift_positions_mm``, in the plan's orientations:
every angle at each linear-stage position in turn), of the capture attempt (the number of
times the shot was rejected before), of the frame in the shot. Every function returns a
POSIX relative path (as the manifest records it); join it to the session directory.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

SESSION_FILE = "session.json"
SESSION_FORMAT = 1
"""The ``format`` of ``session.json`` (and of the directory it describes) this version writes and reads; one
without a ``format`` is read as this one."""
CONFIG_COPY = "config.yaml"
MANIFEST = "manifest.jsonl"
FRAMES = "frames"
MEASUREMENTS = "measurements"
BOARDS = "boards"
PROFILES = "profiles"
REPORT = "report"
RESULTS = "results.json"
LOCK = ".lock"
RESERVE = ".reserve"
RESERVE_BYTES = 256 * 1024
"""Size of ``.reserve``: released when a write finds the disk full, so the ``aborted`` record still fits."""

WRITTEN_DIRS = (FRAMES, MEASUREMENTS, PROFILES)
"""Subdirectories made with the session and written atomically (a kill may leave a ``.*.tmp*`` temporary there)."""
ATOMIC_DIRS = (*WRITTEN_DIRS, BOARDS)
"""Every subdirectory written atomically (``boards``: made by the first board view of the ``intrinsics`` stage)."""

_PROFILE = re.compile(r"focus(\d+)\.yaml")


def frame_file(focus_idx: int, orientation_idx: int, attempt: int, frame_idx: int) -> str:
    return f"{FRAMES}/f{focus_idx}_o{orientation_idx}_a{attempt}_i{frame_idx}.png"


def board_file(focus_idx: int, view_idx: int, attempt: int = 0) -> str:
    again = f"_a{attempt}" if attempt else ""
    return f"{BOARDS}/f{focus_idx}_v{view_idx}{again}.png"


def measurement_file(focus_idx: int, orientation_idx: int, attempt: int) -> str:
    return f"{MEASUREMENTS}/f{focus_idx}_o{orientation_idx}_a{attempt}.npz"


def profile_file(focus_idx: int) -> str:
    return f"{PROFILES}/focus{focus_idx}.yaml"


def uncertainty_file(focus_idx: int) -> str:
    return f"{PROFILES}/focus{focus_idx}_uncertainty.npz"


def profile_files(session_dir: str | Path) -> Iterator[tuple[int, Path]]:
    """``(focus_idx, path)`` of every profile file in a session directory, by focus index."""
    found = []
    for p in Path(session_dir, PROFILES).glob("focus*.yaml"):
        m = _PROFILE.fullmatch(p.name)
        if m:
            found.append((int(m.group(1)), p))
    yield from sorted(found)
