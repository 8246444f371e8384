"""A whole session: the executor, then QA and the report, then ``finished``.

:func:`run_session` is what ``harp session run`` / ``resume`` do once the devices are
open: the executor performs what the session lacks (:mod:`station.session.executor`,
with :class:`station.session.progress.ConsoleProgress` showing it, each focus setting's profile
judged by the QA as it is stored: :func:`judge_focus`); when the plan is
done, QA judges every profile (:func:`station.qa.judge.judge_session`), the report is
written into ``DIR/report`` (:func:`station.qa.report.write_session_report`, from the
measurements the session kept), the results into ``DIR/results.json``
(:mod:`station.qa.results`) and a ``finished`` record closes the session. A session
stopped by a fault skips QA and the report (its ``results.json`` says ``failed``); one
killed during QA or the report is finished by its next ``resume`` (nothing left to
capture, QA and report again). A write that fails there (a full disk, a report figure
that cannot be written) or a store that refuses the verdict stops the session with an
``aborted`` record, "stopped after capture, in QA" or "in the report" and the resume
line, and exit 2, like one during capture: a session whose report is missing or
truncated is never "finished".

It stands above both the session (:mod:`station.session`) and the QA (:mod:`station.qa`, which
reads session directories): the session knows nothing of the QA, whose judging it is handed.

The result's exit code binds (:mod:`station.exit_codes`): 0 when the session finished
and its verdict is PASS, 1 when it finished and its verdict is FAIL, 2 when it stopped.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from drivers.protocols import Camera, Turntable
from station.errors import HarpError
from station.exit_codes import EXIT_ABORTED, EXIT_FAIL, EXIT_OK
from station.files import describe_os_error
from station.qa.judge import foreign_store_problem, judge_session
from station.qa.results import session_results, write_results
from station.qa.verdicts import qa_verdict, session_measurements
from station.session import layout
from station.session.directory import SessionDir
from station.session.executor import Executor, SessionResult
from station.session.progress import ConsoleProgress
from station.session.records import Aborted, Finished, ReportFailed, ReportWritten
from station.store.errors import StoreError

if TYPE_CHECKING:
    from station.profile import Profile, Verdict


def run_session(
    session: SessionDir,
    camera: Camera,
    turntable: Turntable,
    *,
    store: Any = None,
    console: Any = None,
    sleep: Callable[[float], None] = time.sleep,
    report: bool = True,
    operator: Any = None,
) -> SessionResult:
    """Run (or resume) ``session`` on open devices; see the module docstring.

    ``console``: a ``rich.console.Console`` for progress, summary, QA lines (None: silent);
    ``report``: write ``DIR/report`` once the plan is done; ``operator``: asked for the board views placed by
    hand (:class:`station.session.operator.OperatorDesk`).
    """
    if store is not None:  # another store's ids are other lenses' rows there: refused before anything is done
        problem = foreign_store_problem(session, store)
        if problem is not None:
            raise HarpError(problem)
    executor = Executor(
        session, camera, turntable, store=store, judge=judge_focus(session), sleep=sleep, operator=operator
    )
    if console is not None:
        executor.subscribe(ConsoleProgress(console, executor.tally))
    try:
        result = executor.run()
    except KeyboardInterrupt:
        _results(session, None)
        raise
    if result.exit_code != EXIT_OK:
        return dataclasses.replace(result, results=_results(session, None))
    note = console.print if console is not None else (lambda _text: None)
    stage = "QA"
    try:
        qa = judge_session(session, store=store, note=note)
        if report and qa is not None:
            stage = "the report"
            _write_report(session, qa, note)
        stage = "QA"
        session.append(Finished())
    except (OSError, StoreError, ReportError) as exc:  # a full disk, a store refusing the verdict, a report
        # that could not be written: recorded, resumed from there — never "finished"
        if isinstance(exc, OSError):
            reason = executor.disk_problem(exc)
        else:
            reason = f"{exc}; then continue with: harp session resume {session.path}"
        session.release_reserve()
        try:
            session.append(Aborted(reason))
        except OSError as again:
            reason += f" (not recorded in the manifest: {describe_os_error(again)})"
        return dataclasses.replace(
            result,
            exit_code=EXIT_ABORTED,
            message=f"session stopped after capture, in {stage}: {reason}",
            results=_results(session, None),
        )
    results = _results(session, qa)
    if qa is None:
        return dataclasses.replace(result, results=results)
    if qa.overall != "PASS":
        return dataclasses.replace(
            result,
            exit_code=EXIT_FAIL,
            message=f"session finished, QA verdict FAIL: {session.path}",
            verdict=qa.overall,
            results=results,
        )
    return dataclasses.replace(
        result, message=f"session finished, QA verdict PASS: {session.path}", verdict=qa.overall, results=results
    )


def judge_focus(session: SessionDir) -> Callable[[Profile, int], Verdict]:
    """``judge(profile, focus_idx)``: the QA verdict of a focus setting's profile under the session's
    thresholds, the stored model judged on the edges it was fitted on (the measurements the session
    kept), as the QA after the executor judges it (:func:`station.qa.verdicts.qa_verdict`)."""

    def judge(profile: Profile, focus_idx: int) -> Verdict:
        return qa_verdict(profile, session.config.qa, measurements=session_measurements(session, focus_idx))

    return judge


class ReportError(HarpError):
    """The session report could not be written (not for a full disk: that is an ``OSError``)."""


def _results(session: SessionDir, qa: Any) -> dict[str, Any] | None:
    """Write ``DIR/results.json`` (:mod:`station.qa.results`); returns what it holds (None: not written)."""
    try:
        results = session_results(session, qa)
    except (OSError, ValueError):  # a damaged profile file: QA and resume say so; the frames are kept
        return None
    with contextlib.suppress(OSError):
        write_results(session, results)
    return results


def _write_report(session: SessionDir, qa: Any, note: Callable[[str], None]) -> None:
    """The session report into ``DIR/report``; a failure is recorded and said, the session kept."""
    from station.qa.report import REPORT_HTML, write_session_report  # defers matplotlib, PIL, jinja2

    cfg = session.config
    title = f"{cfg.lens.label()} on {cfg.camera_body.label()}, session {session.path.name}"
    try:
        path = write_session_report(
            session,
            session.path / layout.REPORT,
            title,
            qa.profiles,
            qa.verdicts,
            qa.overall,
            thresholds=cfg.qa,
            interpolation=qa.interpolation,
        )
    except (OSError, ValueError) as exc:  # the profiles are stored; the session stops, its resume writes it
        if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise  # a full disk: the session stops and its resume writes the report once space is freed
        what = describe_os_error(exc) if isinstance(exc, OSError) and exc.strerror else f"{type(exc).__name__}: {exc}"
        session.append(ReportFailed(what))
        raise ReportError(f"report not written: {what}") from None
    rel = path.relative_to(session.path)
    session.append(ReportWritten(str(rel), str(rel.with_name(REPORT_HTML))))
    note(f"report: {path} (and {REPORT_HTML})")
