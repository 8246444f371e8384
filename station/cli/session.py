"""``harp session run CONFIG [--out DIR]`` and ``harp session resume DIR``.

``run`` creates a session directory (under ``--out``, default the
configuration's ``store.sessions_dir``), opens the station and performs the
whole plan; ``resume`` reopens an interrupted session and captures only what
is missing. When the session finishes, both write its report into
``DIR/report/`` (``report.md`` and ``index.html`` with PNG plots: distortion
field, residual per edge, one overlay per orientation, uncertainty map,
verdict), from the measurements the session kept; ``--no-report`` skips it.
Exit 0 when the session finished, 2 on bad input or when the session stopped
(the message says why; the frames are kept).
"""

from __future__ import annotations

import sys
from pathlib import Path

from station import __version__


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "session", help="run or resume a calibration session", description=__doc__.split("\n\n")[1]
    )
    sub = p.add_subparsers(dest="session_command", metavar="ACTION")
    run = sub.add_parser("run", help="run a session from a station configuration")
    run.add_argument("config", type=Path, help="station configuration (YAML)")
    run.add_argument(
        "--out", type=Path, default=None, help="parent directory of the session directory (default: store.sessions_dir)"
    )
    run.add_argument("--name", default=None, help="session directory name (default: time + lens serial)")
    run.set_defaults(func=_run)
    res = sub.add_parser("resume", help="continue an interrupted session")
    res.add_argument("session_dir", type=Path, help="the session directory")
    res.set_defaults(func=_resume)
    from station.store.resolve import add_store_options

    for action in (run, res):
        add_store_options(action, config=False)  # --store PATH|URL instead of the configuration's store
        action.add_argument("--quiet", action="store_true", help="no progress bars or summary")
        action.add_argument("--no-report", action="store_true", help="do not write DIR/report at the end")
        action.add_argument(
            "--live",
            action="store_true",
            help="show the session on the live page (http://127.0.0.1:8013/; it stays until Ctrl-C after the end)",
        )
        action.add_argument("--live-port", type=int, default=8013, help="port of the live page (0: any free port)")
    p.set_defaults(func=lambda args: (p.print_help(sys.stderr), 2)[1])


def _error(msg: str) -> int:
    print(f"harp session: {msg}", file=sys.stderr)
    return 2


def _run(args) -> int:
    from station.config import ConfigError, check_port, load_config
    from station.session.directory import SessionDir

    if args.name is not None and (args.name in ("", ".", "..") or Path(args.name).name != args.name):
        return _error(
            f"--name {args.name!r}: expected a plain directory name (no '/'); use --out for the parent directory"
        )
    try:
        config = load_config(args.config)
        check_port(config)  # before creating anything
    except ConfigError as exc:
        return _error(str(exc))
    root = args.out if args.out is not None else config.sessions_dir

    def new_session():  # created only once the devices are open
        s = SessionDir.create(root, config, name=args.name, software_version=__version__)
        print(f"session directory: {s.path}", file=sys.stderr)
        return s

    return _execute(config, new_session, args.quiet, report=not args.no_report, live=_live(args), store_name=args.store)


def _resume(args) -> int:
    from station.config import ConfigError
    from station.session.directory import SessionDir, SessionError

    try:
        session = SessionDir.open(args.session_dir)
    except (ConfigError, SessionError) as exc:
        return _error(str(exc))
    if session.finished:
        session.close()
        print(f"harp session: {args.session_dir}: already finished, nothing to do", file=sys.stderr)
        return 0
    return _execute(
        session.config,
        lambda: session,
        args.quiet,
        opened=session,
        report=not args.no_report,
        live=_live(args),
        store_name=args.store,
    )


def _live(args) -> int | None:
    """The live page's port with ``--live`` (None without)."""
    return args.live_port if getattr(args, "live", False) else None


def _execute(
    config, get_session, quiet: bool, opened=None, report: bool = True, live: int | None = None, store_name=None
) -> int:
    if live is None:
        return _execute_session(config, get_session, quiet, opened, report, store_name=store_name)
    from station.live.session_tap import live_session_page
    from station.web.serve import ServeError

    try:
        page = live_session_page(config, port=live)
        tap = page.__enter__()
    except ServeError as exc:
        if opened is not None:
            opened.close()
        return _error(f"--live: {exc}")
    try:
        code = _execute_session(config, get_session, quiet, opened, report, tap=tap, store_name=store_name)
        if code == 130:
            return code
        print("harp session: the live page shows the result until Ctrl-C", file=sys.stderr, flush=True)
        try:
            import threading

            threading.Event().wait()
        except KeyboardInterrupt:
            pass
        return code
    finally:
        page.__exit__(None, None, None)


def _execute_session(
    config, get_session, quiet: bool, opened=None, report: bool = True, tap=None, store_name=None
) -> int:
    from rich.console import Console

    from station.config import ConfigError
    from station.session.devices import open_station
    from station.session.directory import SessionError
    from station.session.run import run_session
    from station.store import ProfileStore, StoreError
    from station.store.resolve import store_location

    started = []  # the session directory, once there is one
    try:
        with open_station(config) as (camera, turntable), ProfileStore(store_location(store_name, config)) as store:
            with get_session() as session:
                started.append(session.path)
                if tap is not None:
                    session = tap(session)  # the live page subscribes to the session's records and frames
                console = None if quiet else (Console() if sys.stdout.isatty() else Console(width=120))
                result = run_session(session, camera, turntable, store=store, console=console, report=report)
    except (ConfigError, StoreError, SessionError) as exc:
        return _error(str(exc))
    except KeyboardInterrupt:  # Ctrl-C: say where the frames are and how to go on
        if not started:
            _error("interrupted before the session started; nothing was captured")
        else:
            _error(
                f"interrupted; every frame captured so far is kept in {started[0]}; "
                f"continue with: harp session resume {started[0]}"
            )
        return 130
    finally:
        if opened is not None:
            opened.close()
    if result.exit_code:
        return _error(result.message)
    print(result.message, file=sys.stderr)
    return 0
