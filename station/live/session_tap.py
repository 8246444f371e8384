"""The live page during a session (``harp session run ... --live``): a subscriber to the session.

:class:`SessionTap` stands in for the session directory the executor writes to: every record
the executor appends (``focus``, ``frame``, ``reject``, ``measure``, ``fit``, ``stored``, ``qa``,
``finished``, ``aborted``, ...) is appended to the real directory first, then shown on the page
(:meth:`station.live.runner.LiveStation.session_record`), and every frame written is also handed
to the page's assessment thread (:meth:`~station.live.runner.LiveStation.show_frame`, which
never blocks the executor). The executor is unchanged and owns the devices; the page only
shows.

Why at the directory and not as an executor subscriber (:class:`station.session.progress.Subscriber`):
the page also shows what comes after the executor -- QA's verdicts (:mod:`station.qa.judge`),
the report and ``finished`` are appended by :func:`station.session_run.run_session` once the
executor's subscribers have been told it is done -- and the frames themselves, which a
subscriber sees only as file names (``FrameSaved``). Every record passes through
``append`` exactly once, so this sees the manifest as it is written, in order.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from drivers.protocols import CameraIdentity, Frame
from station.live.devices import live_station
from station.session.records import ShotMeasured


class SessionTap:
    """A session directory that also shows the session on a live page (module docstring)."""

    def __init__(self, session: Any, live: Any, config: Any, operator: Any = None) -> None:
        self._session, self._live, self._config = session, live, config
        if operator is not None:  # the page's buttons answer the board views asked of the operator
            live.answer_board = operator.attach_page()
        n_f, n_o = len(config.focus_settings), len(config.capture.orientations)
        self._totals = (n_f, n_o, n_f * n_o)
        self._where = (0, 0)
        live.begin_session({"session": str(session.path), "shots_total": n_f * n_o})
        self._show({"kind": "tap"})

    def __getattr__(self, name: str) -> Any:
        return getattr(self._session, name)

    def __enter__(self) -> SessionTap:
        return self

    def __exit__(self, *exc: object) -> None:
        self._session.__exit__(*exc)

    # -- what the executor calls -----------------------------------------------------------
    def append(self, record: dict[str, Any]) -> dict[str, Any]:
        out: dict[str, Any] = self._session.append(record)
        self._show(out)
        return out

    def write_frame(
        self,
        focus_idx: int,
        orientation_idx: int,
        frame_idx: int,
        image: np.ndarray,
        metadata: dict[str, Any] | None = None,
    ) -> Any:
        out = self._session.write_frame(focus_idx, orientation_idx, frame_idx, image, metadata)
        meta = metadata or {}
        cam = meta.get("camera") or ["", "", ""]
        frame = Frame(
            image=image,
            timestamp=float(meta.get("timestamp", 0.0)),
            exposure_us=float(meta.get("exposure_us", float("nan"))),
            gain_db=float(meta.get("gain_db", float("nan"))),
            focus=meta.get("focus"),
            camera=CameraIdentity(*[str(c) for c in cam[:3]]),
            counter=int(meta.get("counter", 0)),
        )
        stage = meta.get("stage_deg")
        self._live.show_frame(
            frame, stage_deg=stage, focus_idx=focus_idx, orientation_idx=orientation_idx, frame_idx=frame_idx
        )
        self._show(self._session.lines[-1])  # the frame's line as written
        return out

    def show_board_preview(self, image: np.ndarray, found: Any) -> None:
        """A frame taken while the operator places the board, and the board found in it (a
        :class:`pipeline.board.BoardView`, or a falsy :class:`pipeline.board.BoardRejected` saying why not)."""
        corners = np.asarray(found.image_points, np.float64).reshape(-1, 2) if found else None
        self._live.show_board_preview(image, corners, None if found else found.reason)

    # -- what the page shows ---------------------------------------------------------------
    def _show(self, record: dict[str, Any]) -> None:
        kind = record.get("kind")
        if "focus_idx" in record:
            self._where = (int(record["focus_idx"]), int(record.get("orientation_idx", self._where[1])))
        shown = dict(record)
        if kind == "measure":
            shown = {**record, "kind": "shot", "problems": []}
        elif kind == "reject":
            shown = {**record, "kind": "shot", "problems": list(record.get("reasons", []))}
        elif kind == "frame":
            shown = {k: v for k, v in record.items() if k != "meta"}
        n_f, n_o, total = self._totals
        f, o = self._where
        done = sum(1 for _ in self._session.of_type(ShotMeasured))
        focus = self._config.focus_settings[f] if f < n_f else None
        shown["progress"] = {
            "focus_idx": f,
            "focus_total": n_f,
            "focus": focus,
            "orientation_idx": o,
            "orientation_total": n_o,
            "shots_done": done,
            "shots_total": total,
        }
        self._live.session_record(shown)


@contextlib.contextmanager
def live_session_page(
    config: Any, host: str = "127.0.0.1", port: int = 8013, token: str | None = None
) -> Iterator[Callable[[Any], SessionTap]]:
    """Serve the live page for a session; yield ``tap(session, operator=None) -> SessionTap`` (``operator``:
    the :class:`station.session.operator.OperatorDesk` the page's board buttons answer).

    The page's server runs on a background thread (the session runs in the foreground);
    raises :class:`station.web.ServeError` (one line) when the address cannot be used.
    """
    from station.live.web import live_app  # defers scipy, cv2, jinja2, starlette
    from station.web.serve import start  # defers jinja2, starlette, markupsafe

    station = live_station(config, None, None)
    station.start()
    try:
        server = start(live_app(station), host, port, token)
    except BaseException:
        station.stop()
        raise
    # not through say: the address line, read by scripts (and the tests) from the line's start
    print(f"live page: {server.url}", file=sys.stderr, flush=True)
    try:
        yield lambda session, operator=None: SessionTap(session, station, config, operator)
    finally:
        server.stop()
        station.stop()
