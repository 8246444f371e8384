"""What a session did, from its records: the tally, the progress bars and the summary table.

The executor (:mod:`station.session.executor`) tells its subscribers when it starts
(with the number of capture and processing steps planned and the records the
session already had), hands them every manifest record it writes
(:mod:`station.session.records`) and every transient note (a retry, a recovery), and
tells them when it is done. :class:`Tally` counts, per focus setting, the shots,
re-captures, edges, fit figures, camera matrix and stored profile, and the frames and faults of
this run — every figure derived from the records, so it says what the manifest
says; the executor's result is built from it. :class:`ConsoleProgress` shows a
tally as rich progress bars, the notes and the summary table.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from station.config import Config
from station.session.records import (
    BoardSaved,
    ColourMeasured,
    Fault,
    Fitted,
    FrameSaved,
    IntrinsicsMeasured,
    Record,
    ShotMeasured,
    ShotRejected,
    Stored,
)
from station.tables import print_table


class Subscriber(Protocol):
    """What the executor tells those who follow a session."""

    def start(self, config: Config, past: Iterable[Record], n_capture: int, n_process: int) -> None: ...
    def record(self, record: Record) -> None: ...
    def note(self, text: str) -> None: ...
    def finish(self, session_path: Any, interrupted: bool = False) -> None: ...


@dataclass
class FocusRow:
    """What this run did at one focus setting."""

    focus_idx: int
    focus: float
    shots: int = 0
    recaptures: int = 0
    lines: int = 0
    fit: Fitted | None = None
    intrinsics: IntrinsicsMeasured | None = None
    profile_id: int | None = None
    colour: Mapping[str, str] | None = None  # a colour camera's TCA and vignetting, in short


class Tally:
    """Counts a session's records (see the module docstring)."""

    def __init__(self) -> None:
        self.rows: dict[int, FocusRow] = {}
        self.frames_saved = 0
        self.faults = 0
        self._recaptured: set[tuple[int, int, int]] = set()

    def start(self, config: Config, past: Iterable[Record], n_capture: int, n_process: int) -> None:
        self.rows = {f: FocusRow(f, v) for f, v in enumerate(config.focus_settings)}
        for r in past:  # profiles stored before a resume
            if isinstance(r, Stored) and r.focus_idx in self.rows:
                self.rows[r.focus_idx].profile_id = r.profile_id

    def record(self, record: Record) -> None:
        match record:
            case FrameSaved(focus_idx=f, orientation_idx=o, attempt=a):
                self.frames_saved += 1
                if a > 0 and (f, o, a) not in self._recaptured:  # a shot taken again after failing its checks
                    self._recaptured.add((f, o, a))
                    self.rows[f].recaptures += 1
            case ShotMeasured(focus_idx=f, n_lines=n):
                self.rows[f].shots += 1
                self.rows[f].lines += n
            case Fitted(focus_idx=f):
                self.rows[f].fit = record
            case IntrinsicsMeasured(focus_idx=f):
                self.rows[f].intrinsics = record
            case ColourMeasured(focus_idx=f, summary=cells):
                self.rows[f].colour = cells
            case Stored(focus_idx=f, profile_id=pid):
                self.rows[f].profile_id = pid
            case Fault():
                self.faults += 1

    def note(self, text: str) -> None:
        return None  # a tally keeps no notes

    def finish(self, session_path: Any, interrupted: bool = False) -> None:
        return None


class ConsoleProgress:
    """A :class:`Tally` shown on a ``rich.console.Console``: progress bars (on a terminal only), notes,
    summary table."""

    def __init__(self, console: Any, tally: Tally) -> None:
        self.console = console
        self.tally = tally
        self.config: Config | None = None
        self._progress: Any = None
        self._tasks: dict[str, Any] = {}

    def start(self, config: Config, past: Iterable[Record], n_capture: int, n_process: int) -> None:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self.config = config
        if not getattr(self.console, "is_terminal", False):
            return  # progress bars only on a terminal: a pipe or a file gets the lines and the table
        self._progress = Progress(
            TextColumn("{task.description:>8}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=self.console,
            transient=False,
        )
        self._progress.start()
        self._tasks = {
            "capture": self._progress.add_task("capture", total=n_capture or 1),
            "process": self._progress.add_task("process", total=n_process or 1),
        }

    def record(self, record: Record) -> None:
        match record:
            case FrameSaved() | BoardSaved():
                self._advance("capture")
            case ShotMeasured() | Fitted() | Stored():
                self._advance("process")
            case IntrinsicsMeasured(focus_idx=f, intrinsics=k, failure=why):
                self._advance("process")
                self.note(f"focus {f}: " + (_camera_matrix_line(k) if k else f"[yellow]no camera matrix: {why}"))
            case ShotRejected(focus_idx=f, orientation_idx=o, reasons=reasons):
                self.note(f"[yellow]re-capturing focus {f} orientation {o}: {'; '.join(reasons)}")

    def note(self, text: str) -> None:
        self.console.print(text)

    def finish(self, session_path: Any, interrupted: bool = False) -> None:
        """Stop the bars; print the summary table (unless interrupted: the command says what to do).

        On a terminal a rich table; otherwise tab-separated text with one header line
        (:func:`station.tables.print_table`), units in the headers."""
        if self._progress is not None:
            self._progress.stop()
            self._progress = None
        if interrupted or self.config is None:
            return
        cfg = self.config
        colour = any(row.colour for row in self.tally.rows.values())
        columns = (
            "focus",
            "shots",
            "recaptures",
            "edges",
            "fit d (px)",
            "fit d_max (px)",
            "holdout d (px)",
            "holdout d_max (px)",
            "unc. rms (px)",
            "unc. max (px)",
            "model",
            *(K_COLUMNS if cfg.intrinsics is not None else ()),
            *(COLOUR_COLUMNS if colour else ()),
            "profile",
        )
        figures = ("fit_d", "fit_d_max", "holdout_d", "holdout_d_max", "uncertainty_rms", "uncertainty_max")
        rows = []
        for row in self.tally.rows.values():
            fit = row.fit
            rows.append(
                (
                    f"{row.focus:g}",
                    str(row.shots),
                    str(row.recaptures),
                    str(row.lines),
                    *(_fmt(getattr(fit, name) if fit else None) for name in figures),
                    str(fit.model.get("model", "?")) if fit else "",
                    *(_k_cells(row.intrinsics) if cfg.intrinsics is not None else ()),
                    *((row.colour or {}).get(c, "") for c in (COLOUR_COLUMNS if colour else ())),
                    f"#{row.profile_id}" if row.profile_id is not None else "",
                )
            )
        stream = self.console.file
        print_table(
            columns,
            rows,
            title=f"{cfg.lens.label()} on {cfg.camera_body.label()}\n{session_path}",
            right=tuple(c for c in columns if c not in ("model", "board views", "profile", *COLOUR_COLUMNS)),
            stream=stream,
        )
        self.console.print(f"frames saved this run: {self.tally.frames_saved}, device faults: {self.tally.faults}")

    def _advance(self, task: str) -> None:
        if self._progress is not None:
            self._progress.advance(self._tasks[task])


def _camera_matrix_line(k: Any) -> str:
    """``camera matrix fx 1200.12 ± 0.31, ... px from 6 board views`` of an
    :meth:`pipeline.intrinsics.Intrinsics.to_dict`."""
    sd = k.get("sd") or {}
    vals = ", ".join(f"{n} {float(k[n]):.2f} ± {float(sd.get(n, math.nan)):.2f}" for n in ("fx", "fy", "cx", "cy"))
    return f"camera matrix {vals} px from {k.get('n_views', '?')} board views"


COLOUR_COLUMNS = ("TCA", "vignetting")
"""The summary's colour columns (a colour camera: :func:`station.session.colour.colour_summary`'s cells)."""

K_COLUMNS = ("fx (px)", "fy (px)", "cx (px)", "cy (px)", "K sd max (px)", "board views")
"""The summary's camera-matrix columns (a session with an ``intrinsics`` section)."""


def _k_cells(rec: IntrinsicsMeasured | None) -> tuple[str, ...]:
    """The :data:`K_COLUMNS` cells of a focus setting: its camera matrix, the largest standard deviation of
    fx, fy, cx, cy, the board views used; without one, ``none: <why>`` in the views' cell (empty: not
    measured in this run)."""
    if rec is None:
        return ("",) * len(K_COLUMNS)
    k = rec.intrinsics
    if not k:
        return ("",) * (len(K_COLUMNS) - 1) + (f"none: {rec.failure}",)
    sd = k.get("sd") or {}
    sds = [float(sd.get(n, math.nan)) for n in ("fx", "fy", "cx", "cy")]
    sd_max = max(sds) if all(math.isfinite(v) for v in sds) else math.nan
    return (
        *(f"{float(k[n]):.2f}" for n in ("fx", "fy", "cx", "cy")),
        _fmt(sd_max),
        str(k.get("n_views", "?")),
    )


def _fmt(v: Any) -> str:
    return "" if v is None or not math.isfinite(v) else f"{v:.4f}"
