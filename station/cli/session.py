"""``harp session run CONFIG``, ``resume DIR``, ``plan CONFIG``, ``list [DIR]``.

``run`` creates a session directory (under ``--out``, default the configuration's
``store.sessions_dir``), opens the station and performs the whole plan (one estimated longer than
4 h only with ``--yes``); ``resume`` reopens an interrupted session and captures only what is
missing. When the session finishes, both judge it (QA), write its report into ``DIR/report/`` and its results into
``DIR/results.json``; ``--no-report`` skips the report. ``plan`` prints the capture plan
with an estimated duration, touching no device; ``list`` lists the sessions of a
directory with their state (complete / failed / interrupted / running) and verdict.
A configuration with ``zoom.settings`` (a zoom lens's focal lengths) runs one such session per
focal length in one zoom session directory (:mod:`station.zoom_session`); ``resume`` of that
directory goes on with the part that stopped.
Exit codes of ``run`` / ``resume``: 0 finished and PASS, 1 finished and FAIL, 2 bad input
or the session stopped (the frames are kept; the message says how to go on), 130
interrupted. ``--json`` prints the session's results (``results.json``) on stdout and the
progress on stderr.
"""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

from station import __version__
from station.cli.commands import COMMANDS
from station.cli.inputs import port_number
from station.cli.say import say, warn
from station.cli.store_options import (
    CONFIGURED_STORE_HELP,
    add_store_options,
    load_env_config,
    store_location,
    waiting_note,
)
from station.ctrl_c import stopped_text
from station.errors import HarpError, Interrupted, one_line
from station.exit_codes import EXIT_ERROR, EXIT_FAIL, EXIT_OK
from station.files import describe_os_error
from station.qa.results import finished_results, read_results, state_exit_code
from station.session.integrity import check_session, needs_capture, repair_files, repair_session, summary
from station.session.states import sessions_in
from station.store import StoreError
from station.tables import console as text_console
from station.tables import print_table


def register(subparsers) -> None:
    p = subparsers.add_parser("session", help=COMMANDS["session"], description=__doc__.split("\n\n")[1])
    sub = p.add_subparsers(dest="session_command", metavar="ACTION")
    run = sub.add_parser("run", help="run a session from a station configuration")
    run.add_argument("config", type=Path, help="station configuration (YAML)")
    run.add_argument(
        "-o",
        "--out",
        type=Path,
        default=None,
        help="parent directory of the session directory (default: store.sessions_dir)",
    )
    run.add_argument("--name", default=None, help="session directory name (default: time + lens serial)")
    run.add_argument(
        "--yes",
        action="store_true",
        help="start a plan estimated longer than 4 h (harp session plan shows the estimate); without it such a "
        "plan is refused with exit 2",
    )
    run.set_defaults(func=_run)
    res = sub.add_parser("resume", help="continue an interrupted session")
    res.add_argument("session_dir", type=Path, help="the session directory")
    res.set_defaults(func=_resume)
    rep = sub.add_parser(
        "repair",
        help="check a session's files and re-derive what the frames and the manifest allow",
        description="Check every file of a session against its manifest; re-derive what can be re-derived "
        "(session.json, config.yaml from its source, damaged manifest lines, measurements, uncertainty maps and "
        "profiles, fitted again from the frames without the devices) and say what cannot. Exit 0 when nothing is "
        "left damaged (captures still needed are done by harp session resume), 2 otherwise.",
    )
    rep.add_argument("session_dir", type=Path, help="the session directory")
    rep.add_argument("--base-dir", default=None, help="for a rebuilt session.json: where the configuration's "
                     "relative paths resolve (default: the session directory's grandparent)")  # fmt: skip
    rep.add_argument(
        "--recapture", type=int, action="append", default=[], metavar="F",
        help="capture focus setting F (its index) again whole at the next resume (repeatable)",
    )  # fmt: skip
    rep.set_defaults(func=_repair)
    for action, whose in (
        (run, "the configuration's"),
        (res, "the session's configuration's"),
        (rep, "the session's configuration's"),
    ):
        # --store PATH|URL instead of the configuration's store
        add_store_options(action, config=False, store_help=CONFIGURED_STORE_HELP.format(whose=whose))
    for action in (run, res):
        action.add_argument("--quiet", action="store_true", help="no progress bars or summary")
        action.add_argument("--no-report", action="store_true", help="do not write DIR/report at the end")
        action.add_argument(
            "--json",
            action="store_true",
            help="print the session's results (results.json) on stdout; progress on stderr",
        )
        action.add_argument(
            "--live",
            action="store_true",
            help="show the session on the live page (http://127.0.0.1:8013/; it stays until Ctrl-C after the end)",
        )
        action.add_argument(
            "--live-port", type=port_number, default=8013, help="port of the live page (0: any free port)"
        )
    plan = sub.add_parser("plan", help="the capture plan and its estimated duration (touches no device)")
    plan.add_argument("config", type=Path, help="station configuration (YAML)")
    plan.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    plan.set_defaults(func=_plan)
    ls = sub.add_parser("list", help="sessions with their state and verdict")
    ls.add_argument(
        "directory",
        type=Path,
        nargs="?",
        default=None,
        help="where the sessions are (default: the store.sessions_dir of $HARP_CONFIG, else ./sessions)",
    )
    ls.add_argument("--config", type=Path, default=None, help="list the sessions of this configuration's sessions_dir")
    ls.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    ls.set_defaults(func=_list)
    p.set_defaults(func=lambda args: (p.print_help(sys.stderr), EXIT_ERROR)[1])


def _said(exc: HarpError) -> int:
    """A part's or a live session's error said now, as :func:`station.cli.main` would, while the
    command goes on (the next part is not run; the live page stays): its exit code."""
    say("harp session", one_line(exc))
    return exc.exit_code


def _load(path: Path):
    """The configuration at ``path`` and what :func:`station.config.check.check_config` found (its warnings); the
    first of its errors raised (a ConfigError)."""
    from station.config import load_config  # defers numpy, yaml
    from station.config.check import check_config  # defers numpy, yaml

    config = load_config(path)
    checked = check_config(config)
    if checked.errors:
        raise checked.errors[0]
    return config, checked


def _long_plan(config, yes: bool) -> str | None:
    """The refusal of a plan estimated longer than CONFIRM_PLAN_HOURS without ``--yes``; a plan longer
    than WARN_PLAN_HOURS (or a long one with ``--yes``) is warned of on stderr."""
    from station.session.estimate import CONFIRM_PLAN_HOURS, long_plan, plan_summary  # defers numpy, yaml

    long = long_plan(config)
    if long is None:
        return None
    est, warning = long
    if est.seconds > CONFIRM_PLAN_HOURS * 3600 and not yes:
        return (
            f"{config.path}: focus.settings, capture.orientations_deg, capture.frames_per_orientation: "
            f"{plan_summary(config, est)}, more than {CONFIRM_PLAN_HOURS:g} h: run again with --yes to start it, "
            "or plan fewer focus settings, orientations or frames (harp session plan shows the steps)"
        )
    warn("harp session", warning)
    return None


def _run(args) -> int:
    from station.config import check_port  # defers numpy, yaml
    from station.session.directory import SessionDir  # defers cv2, numpy, yaml

    if args.name is not None and (args.name in ("", ".", "..") or Path(args.name).name != args.name):
        raise HarpError(
            f"--name {args.name!r}: expected a plain directory name (no '/'); use --out for the parent directory"
        )
    config, checked = _load(args.config)  # a ConfigError: one line (station.cli.main)
    check_port(config)  # before creating anything
    refused = _long_plan(config, args.yes)
    if refused is not None:
        raise HarpError(refused)
    for w in checked.plan_warnings:  # `harp config check` says them too; the run, once it starts, before it captures
        warn("harp session", w)
    root = args.out if args.out is not None else config.sessions_dir
    if config.zoom_settings:
        return _run_zoom(config, root, args)

    def new_session():  # created only once the devices are open
        s = SessionDir.create(root, config, name=args.name, software_version=__version__)
        say("harp session", f"session directory: {s.path}")
        return s

    return _execute(config, new_session, args, report=not args.no_report)


def _resume(args) -> int:
    from station.session.directory import SessionDir  # defers cv2, numpy, yaml
    from station.zoom_session import is_zoom_session  # defers numpy, yaml

    if is_zoom_session(args.session_dir):
        return _zoom_parts(Path(args.session_dir), args)
    session = SessionDir.open(args.session_dir)  # a ConfigError or SessionError: one line (station.cli.main)
    damage = check_session(session)
    if damage:  # found before anything is captured, fitted or judged again
        session.close()
        raise HarpError(summary(session.path, damage))
    if session.finished:
        with session:
            return _already_finished(session, args)
    return _execute(session.config, lambda: session, args, opened=session, report=not args.no_report)


def _run_zoom(config, root, args) -> int:
    """A zoom session: one session per focal length (:mod:`station.zoom_session`)."""
    from station import zoom_session  # defers numpy, yaml

    try:
        path = zoom_session.create(root, config, name=args.name)
    except OSError as exc:
        raise HarpError(f"cannot create the zoom session: {describe_os_error(exc)}") from None
    say("harp session", f"zoom session directory: {path}")
    return _zoom_parts(path, args)


def _zoom_parts(path: Path, args) -> int:
    """Run or resume every part of the zoom session at ``path``, then its results and summary."""
    import argparse

    from station import zoom_session  # defers numpy, yaml
    from station.session.directory import SessionDir  # defers cv2, numpy, yaml

    part_args = argparse.Namespace(**{**vars(args), "json": False})  # one JSON object: the zoom session's

    def run_part(part, config, session_path) -> int:
        try:
            return _run_part(part, config, session_path)
        except HarpError as exc:  # said now (Ctrl-C too); the zoom session stops at this part
            return _said(exc)

    def _run_part(part, config, session_path) -> int:
        if not session_path.exists():

            def new_session():
                s = SessionDir.create(path, config, name=part.name, software_version=__version__)
                say("harp session", f"session directory: {s.path}")
                return s

            return _execute_session(config, new_session, part_args, report=not args.no_report)
        session = SessionDir.open(session_path)
        if session.finished:
            with session:
                return _already_finished(session, part_args, shown=session_path)
        return _execute_session(session.config, lambda: session, part_args, opened=session, report=not args.no_report)

    note = (lambda text: None) if args.quiet else (lambda text: say("harp session", text))
    try:
        meta, _parts = zoom_session.read_parts(path)
        code, done = zoom_session.run_parts(path, run_part, note)
    except HarpError:  # a ConfigError: one line (station.cli.main)
        raise
    except ValueError as exc:
        raise HarpError(str(exc)) from None
    if code not in (EXIT_OK, EXIT_FAIL):
        raise HarpError(f"zoom session stopped at {done[-1]['name']}; continue with: harp session resume {path}")
    first = zoom_session.part_config(path, meta, zoom_session.read_parts(path)[1][0])
    try:
        with _open_store(first, args.store) as store:
            results = zoom_session.zoom_results(path, done, store, tuple(meta["lens"]))
    except (StoreError, OSError) as exc:  # one line: the parts are stored and reported already
        raise HarpError(f"zoom session results: {exc}") from None
    _zoom_summary(results, args)
    return code


def _zoom_summary(results, args) -> None:
    if args.json:
        print(json.dumps(results, indent=1))
        return
    rows = [
        (f"{s['focal']:g}", f"{s['focus']:g}", f"#{s['profile_id']}", "" if s["holdout_d_px"] is None
         else f"{s['holdout_d_px']:.4f}", s["verdict"] or "")
        for s in results["settings"]
    ]  # fmt: skip
    cols = ("focal (mm)", "focus", "profile", "holdout d (px)", "verdict")
    print_table(cols, rows, title="zoom lens: current profile per focal length and focus", right=cols[:4])
    for e in results["leave_one_out"]:
        print(
            f"interpolation error along the {e['axis']}, leaving focal {e['focal']:g} mm, focus {e['focus']:g} out: "
            f"RMS {e['rms_px']:.4f} px, max {e['max_px']:.4f} px (modulo homography)"
        )
    axes = {e["axis"] for e in results["leave_one_out"]}
    for axis, need in (("focal", "3 focal lengths"), ("focus", "3 focus settings")):
        if axis not in axes:
            print(f"interpolation error along the {axis}: not measurable (needs {need})")


def _already_finished(session, args, shown=None) -> int:
    """A finished session resumed: nothing to capture; its exit code is its verdict's."""
    try:
        results = finished_results(session)
    except (OSError, ValueError) as exc:
        raise HarpError(f"{session.path}: finished, but its results cannot be gathered: {exc}") from None
    code = state_exit_code("complete", results.get("verdict"))
    verdict = results.get("verdict") or "none"
    where = shown if shown is not None else args.session_dir
    say("harp session", f"{where}: already finished (QA verdict {verdict}), nothing to do")
    if args.json:
        print(json.dumps(results, indent=1))
    return EXIT_OK if code is None else code


def _repair(args) -> int:
    from station.session.directory import SessionDir  # defers cv2, numpy, yaml

    done = repair_files(args.session_dir, base_dir=args.base_dir)  # a SessionError: one line (station.cli.main)
    session = SessionDir.open(args.session_dir)
    for line in done:
        say("harp session", f"re-derived: {line}")
    with session:
        try:
            report = repair_session(session, tuple(args.recapture))
        except ValueError as exc:
            raise HarpError(str(exc)) from None
        for line in report.fixed:
            say("harp session", f"repaired: {line}")
        for line in report.cannot:
            say("harp session", f"cannot re-derive: {line}")
        pending = report.refit and needs_capture(session)  # shots still to capture: resume fits it with them
        if report.refit and not pending:
            _refit(session, args.store)
        left = check_session(session)
    if pending:
        say("harp session", "the reopened focus settings are fitted with the shots still to capture")
    if report.resume or pending or (report.refit and left):
        say("harp session", f"then: harp session resume {args.session_dir}")
    elif not done and not report.fixed and not report.cannot:
        say("harp session", f"{args.session_dir}: every file matches the manifest, nothing to repair")
    return EXIT_ERROR if report.cannot else EXIT_OK


def _refit(session, store_name=None) -> None:
    """Measure, fit and store the reopened focus settings again, then QA and the report: no devices.
    A :class:`HarpError` (a StoreError, or the run's message: exit 2) when that does not succeed."""
    from station.session_run import run_session  # defers cv2, numpy, yaml
    from station.store import ProfileStore  # defers sqlalchemy

    with ProfileStore(store_location(store_name, session.config), on_wait=waiting_note("harp session")) as store:
        result = run_session(session, None, None, store=store, console=None)
    if result.exit_code:
        raise HarpError(result.message)
    say("harp session", f"repaired: {result.message}")


def _live(args) -> int | None:
    """The live page's port with ``--live`` (None without)."""
    return args.live_port if getattr(args, "live", False) else None


def _execute(config, get_session, args, opened=None, report: bool = True) -> int:
    """Run the session (with ``--live``: shown on the live page, which stays until Ctrl-C after the end)."""
    live = _live(args)
    if live is None:
        return _execute_session(config, get_session, args, opened, report)
    from station.live.session_tap import live_session_page  # defers numpy
    from station.web.serve import ServeError  # defers jinja2, starlette, markupsafe

    try:
        page = live_session_page(config, port=live)
        tap = page.__enter__()
    except ServeError as exc:
        if opened is not None:
            opened.close()
        raise HarpError(f"--live: {exc}") from None
    try:
        try:
            code = _execute_session(config, get_session, args, opened, report, tap=tap)
        except Interrupted:
            raise
        except HarpError as exc:  # said now; the live page shows how the session ended
            code = _said(exc)
        import threading

        try:  # said inside: a Ctrl-C as soon as the line is read (a script's) ends the wait, not the run
            say("harp session", "the live page shows the result until Ctrl-C", flush=True)
            threading.Event().wait()
        except KeyboardInterrupt:
            pass
        return code
    finally:
        page.__exit__(None, None, None)


def _execute_session(config, get_session, args, opened=None, report: bool = True, tap=None) -> int:
    """Run the session: its exit code (0 PASS, 1 FAIL); a :class:`HarpError` when it stopped (a
    ConfigError, StoreError, SessionError or the run's message; :class:`Interrupted` on Ctrl-C)."""
    from station.session.devices import open_station  # defers numpy, yaml
    from station.session_run import run_session  # defers cv2, numpy, yaml

    started = []  # the session directory, once there is one
    result = None
    try:
        # the devices first: a station that cannot open creates no empty store
        with open_station(config) as (camera, turntable), _open_store(config, args.store) as store:
            with get_session() as session:
                started.append(session.path)
                console = None
                if not args.quiet:
                    out = sys.stderr if args.json else sys.stdout
                    console = text_console(out)  # off a terminal: lines never wrapped (station.tables)
                desk = _operator(config, console)
                if tap is not None:  # the live page subscribes to the session's records and frames
                    session = tap(session, desk)  # and answers the operator's questions too
                result = run_session(
                    session, camera, turntable, store=store, console=console, report=report, operator=desk
                )
    except KeyboardInterrupt:  # Ctrl-C (or SIGTERM, SIGHUP): say where the frames are and how to go on
        if not started:
            raise Interrupted(f"{stopped_text()} before the session started; nothing was captured") from None
        if args.json:
            _print_results_of(started[0])
        raise Interrupted(
            f"{stopped_text()}; every frame captured so far is kept in {started[0]}; "
            f"continue with: harp session resume {started[0]}"
        ) from None
    finally:
        if opened is not None:
            opened.close()
    if args.json:
        out = result.results or {"session": str(started[0]), "exit_code": result.exit_code, "message": result.message}
        print(json.dumps(out, indent=1))
    if result.exit_code == EXIT_ERROR:
        raise HarpError(result.message)
    say("harp session", result.message)
    return result.exit_code


def _operator(config, console):
    """The operator's desk when the board views are placed by hand (``intrinsics.placement: operator``):
    asked on the console (standard error with ``--quiet``), answered on standard input or the live page."""
    if config.intrinsics is None or config.intrinsics.placement != "operator":
        return None
    from station.session.operator import OperatorDesk  # defers numpy, yaml

    return OperatorDesk(say=console.print if console is not None else None, stdin=sys.stdin)


def _open_store(config, store_name=None):
    """The store the session writes (``--store``, else the configuration's; :mod:`station.cli.store_options`)."""
    from station.store import ProfileStore  # defers sqlalchemy

    return ProfileStore(store_location(store_name, config), on_wait=waiting_note("harp session"))


def _print_results_of(session_dir: Path) -> None:
    results = read_results(session_dir)
    if results is not None:
        print(json.dumps(results, indent=1))


# ----------------------------------------------------------------- plan
def _plan(args) -> int:
    from station.session.estimate import board_views, estimate_plan  # defers numpy, yaml

    config, checked = _load(args.config)  # a ConfigError: one line (station.cli.main)
    from station.session.estimate import long_plan  # defers numpy, yaml

    long = long_plan(config)
    for w in [*checked.warnings, *([long[1]] if long else [])]:
        warn("harp session", w)
    est = long[0] if long else estimate_plan(config)
    if args.json:
        print(
            json.dumps(
                {
                    "config": str(config.path),
                    "lens": [config.lens.maker, config.lens.model, config.lens.serial],
                    "focus_settings": list(config.focus_settings),
                    "orientations_deg": list(config.capture.orientations_deg),
                    "twin_deg": config.capture.twin_deg,
                    "shift_positions_mm": list(config.capture.shift_positions_mm),
                    "frames": est.frames,
                    "moves": est.moves,
                    "focus_locks": est.focus_locks,
                    "fits": est.fits,
                    "estimated_seconds": round(est.seconds, 1),
                    "assumptions": est.assumptions,
                    "steps": [
                        {
                            "focus_idx": r.focus_idx if r.focus_idx >= 0 else None,
                            "focus": r.focus if math.isfinite(r.focus) else None,
                            "what": r.what,
                            "orientation_deg": r.orientation_deg,
                            "shift_mm": r.shift_mm,
                            "twin": r.twin,
                            "frames": r.frames,
                            "estimated_seconds": round(r.seconds, 2),
                        }
                        for r in est.rows
                    ],
                },
                indent=1,
            )
        )
        return EXIT_OK
    print_table(
        ("focus", "step", "orientation (deg)", "frames", "estimated (s)"),
        [
            (
                f"{r.focus:g}" if math.isfinite(r.focus) else "",
                r.what,
                f"{r.orientation_deg:g}" if r.orientation_deg is not None else "",
                str(r.frames) if r.frames else "",
                f"{r.seconds:.1f}",
            )
            for r in est.rows
        ],
        title=f"capture plan of {config.path} ({config.lens.label()})",
        right=("focus", "orientation (deg)", "frames", "estimated (s)"),
    )
    minutes, seconds = divmod(int(round(est.seconds)), 60)
    took = f"{minutes} min {seconds:02d} s" if minutes < 60 else f"{est.seconds / 3600:.1f} h"
    say(
        "harp session",
        f"{len(config.focus_settings)} focus settings x {len(config.capture.orientations)} orientations x "
        f"{config.capture.frames_per_orientation} frames{board_views(config)} = {est.frames} frames, {est.moves} moves, "
        f"{est.fits} fits; estimated duration {took}",
    )
    for a in est.assumptions:
        say("harp session", f"assumed: {a}")
    return EXIT_OK


# ----------------------------------------------------------------- list
def _list(args) -> int:
    from station.config import load_config  # defers numpy, yaml

    if args.directory is not None and args.config is not None:
        raise HarpError("give a directory or --config, not both")
    config_path = args.config
    if config_path is None and args.directory is None and os.environ.get("HARP_CONFIG"):
        # the station's configuration, wherever the command runs
        root = load_env_config("a directory or --config").sessions_dir
    elif config_path is not None:
        root = load_config(config_path).sessions_dir  # a ConfigError: one line (station.cli.main)
    else:
        root = args.directory if args.directory is not None else Path("sessions")
    if not root.is_dir():
        raise HarpError(f"{root}: no such directory (name one, or --config CONFIG for its store.sessions_dir)")
    found, problems = sessions_in(root)
    for p in problems:
        warn("harp session", p)
    if args.json:
        print(json.dumps({"directory": str(root.resolve()), "sessions": [s.to_dict() for s in found]}, indent=1))
        return EXIT_OK
    if not found:
        say("harp session", f"no sessions in {root}")
        return EXIT_OK
    print_table(
        ("session", "state", "verdict", "lens", "profiles", "frames", "created", "last activity", "path"),
        [
            (
                s.name,
                s.state,
                s.verdict or "",
                s.lens,
                f"{s.profiles}/{s.focus_settings}",
                str(s.frames),
                s.created or "",
                s.last or "",
                str(s.path),
            )
            for s in found
        ],
        title=f"sessions in {root}",
        right=("frames",),
    )
    return EXIT_OK
