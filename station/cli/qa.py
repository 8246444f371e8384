"""``harp qa SESSION_OR_LENS [--reference REF] [--max-... PX] [--report DIR] [--json]``.

Factory QA: a PASS / FAIL verdict, every check with its value, comparison and limit, for
every profile of a session directory or of a lens in the profile store (the newest
profile of each focus setting, failed ones included). The thresholds are those the
profile was calibrated under (a session's configuration ``qa`` section; a stored
profile's recorded verdict), else ``--config``'s, else the defaults;
``--max-holdout-d``, ``--max-distortion`` and ``--max-reference-deviation`` override them.
The stored model itself is judged, not only its stored figures: where the session's
measurements are at hand (the session directory, or the one a stored profile names), the
model is applied to them and the holdout d is recomputed from them (``--no-recompute``:
not recomputed); the correction must be defined over the whole image, its distortion is
compared with the limit and with what was recorded when it was calibrated. REF, the
golden reference of the same lens model, is a harp model file, a stored profile ``#id``,
or a lens in the store (its profile at the same focus, interpolated between its
calibrated focus settings when needed). ``--report DIR`` writes a Markdown report with
plots and its ``index.html``; ``--overlays all|failed|none`` says which focus settings keep their
per-orientation overlays in it (default: a session's ``report.overlays``, else all). Each result is recorded in the store's QA history (unless
``--no-record``); it does not change the verdict a profile was calibrated with. A session's result
the store cannot take (a server that is down) is warned of, with what to do; its verdict stands. Run
again with the same results after a run whose recording failed, was interrupted or was killed (a
commit that may or may not have been written), it is recorded once: the rows keep that run's key.
A session that is not finished (a focus setting of its plan without a profile: interrupted, or its fit
failed) gets no verdict: one line naming what it lacks and ``harp session resume``, exit 2; ``--partial``
judges the profiles it has and names the others.
Exit 0 PASS, 1 FAIL, 2 error — for production-line scripts.

What is judged, with which thresholds and reference, and the report's evidence:
:mod:`station.qa.targets`; this module parses, calls it and prints.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import sys
import time
import uuid
from pathlib import Path
from typing import Any

from pipeline.plain import plain
from station.cli.commands import COMMANDS
from station.cli.say import say, warn
from station.cli.store_options import open_store, store_location
from station.config import OVERLAY_RETENTION, load_config
from station.errors import HarpError
from station.exit_codes import verdict_exit_code
from station.files import atomic_write_text, describe_os_error
from station.qa.targets import (
    QAInputError,
    judge_targets,
    lens_targets,
    session_targets,
    unfinished,
    unfinished_error,
    write_qa_report,
)
from station.session import layout
from station.session.directory import SessionDir
from station.store import DEFAULT_STORE, StoreError
from station.store.location import user_store_path
from station.tables import cell, is_terminal, print_table


def _positive(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not (math.isfinite(v) and v > 0):
        import argparse

        raise argparse.ArgumentTypeError(f"expected a positive number of pixels, got {text!r}")
    return v


def register(subparsers) -> None:
    p = subparsers.add_parser("qa", help=COMMANDS["qa"], description=__doc__.split("\n\n")[1])
    p.add_argument("target", metavar="SESSION_OR_LENS")
    p.add_argument(
        "--reference",
        metavar="REF",
        default=None,
        help="golden reference: model file, profile #id, or lens in the store",
    )
    p.add_argument(
        "--store",
        metavar="PATH|URL",
        default=None,
        help=f"profile store: a SQLite file or postgresql://user@host:port/db (default: the --config's or the "
        f"session's, else $HARP_STORE, $HARP_CONFIG's store or {DEFAULT_STORE})",
    )
    p.add_argument("--config", type=Path, default=None, help="station configuration: its qa thresholds and its store")
    p.add_argument("--max-holdout-d", type=_positive, metavar="PX", help="threshold on the holdout d")
    p.add_argument(
        "--max-distortion",
        type=_positive,
        metavar="PX",
        help="threshold on the max displacement of the correction (modulo homography)",
    )
    p.add_argument(
        "--max-reference-deviation",
        type=_positive,
        metavar="PX",
        help="threshold on the max deviation from the reference (modulo homography)",
    )
    p.add_argument(
        "--no-recompute",
        action="store_true",
        help="do not recompute the holdout d from the session's measurements (quicker; the stored one is judged)",
    )
    p.add_argument("--report", type=Path, metavar="DIR", default=None, help="write a Markdown report here")
    p.add_argument(
        "--overlays",
        choices=OVERLAY_RETENTION,
        default=None,
        help="which focus settings keep their overlays in the report: all, failed (only those that failed QA), "
        "none (default: the session configuration's report.overlays, else all)",
    )
    p.add_argument(
        "--partial",
        action="store_true",
        help="judge a session that is not finished on the profiles it has (the verdict says nothing of the focus "
        "settings it lacks, which are named); without it such a session is an error (exit 2)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument("--no-record", action="store_true", help="do not record the result in the store's QA history")
    p.set_defaults(func=run)


def _store(args, config, create=False):
    """The store (:mod:`station.cli.store_options`): ``--store``, else that of ``config`` (``--config``,
    or the session's), else ``$HARP_STORE``, else the default. For reading unless ``create``."""
    return open_store(store_location(args.store, config), write=create, prog="harp qa")


def _looks_like_path(text: str) -> bool:
    """Whether a QA target that does not exist was meant as a path (not a lens of the store): it starts
    like one (``/``, ``./``, ``../``, ``~``), ends with ``/``, or its directory part exists — a lens
    name such as ``50mm f/1.8`` is none of these."""
    if text.startswith(("/", "./", "../", "~")) or text.endswith("/"):
        return True
    return "/" in text and Path(text).parent.is_dir()


def run(args) -> int:
    session = None
    missing: list[str] = []  # a session's focus settings without a profile (judged with --partial only)
    opened: dict[str, Any] = {}
    try:
        try:
            cli_config = load_config(args.config) if args.config else None
            config = cli_config
            target = Path(args.target)
            if (target / layout.SESSION_FILE).is_file():
                session = SessionDir.open(target, read_only=True)  # judged, never written: an archive may be read-only
                config = config or session.config
            elif target.exists() and target.is_dir():
                raise QAInputError(f"{target}: not a session directory (no {layout.SESSION_FILE})")
            elif target.exists() and _looks_like_path(args.target):  # a file: not a lens the store lacks either
                raise QAInputError(f"{target}: a file, not a session directory (give a session directory or a lens)")
            elif not target.exists() and _looks_like_path(args.target):
                raise QAInputError(
                    f"{target}: no such session directory (check the path; `harp session list` lists the sessions)"
                )
            if session is not None:
                missing = unfinished(session)
                if missing and not args.partial:
                    raise unfinished_error(session, missing)
                items = session_targets(session)
            else:
                with _store(args, config) as store:
                    items = lens_targets(store, args.target)
            judged = judge_targets(
                items,
                {
                    "max_holdout_d_px": args.max_holdout_d,
                    "max_distortion_px": args.max_distortion,
                    "max_reference_deviation_px": args.max_reference_deviation,
                },
                config=cli_config,
                session=session,
                reference=args.reference,
                open_store=lambda: _store(args, config),
                recompute=not args.no_recompute,
                opened=opened,
            )
            report = None
            if args.report is not None:
                try:
                    report = write_qa_report(
                        args.report, str(args.target), items, judged, session, overlays=args.overlays
                    )
                except OSError as exc:
                    raise QAInputError(
                        f"{args.report}: cannot write the report "
                        f"({exc.strerror or exc}{': ' + exc.filename if exc.filename else ''})"
                    ) from None
        except HarpError:  # ConfigError, SessionError, StoreError, QAInputError: one line (station.cli.main)
            raise
        except OSError as exc:
            raise QAInputError(describe_os_error(exc)) from None
        except ValueError as exc:
            raise QAInputError(str(exc)) from None
    finally:
        if session is not None:
            session.close()
        for s in opened.values():
            if s is not None:
                s.close()

    if not args.no_record:
        _record(args, config, session, items, judged.verdicts)

    if args.json:
        out = {
            "target": str(args.target),
            "verdict": judged.overall,
            "thresholds": dict(judged.thresholds[0].__dict__),
            "profiles": [
                {
                    "focus": it.focus,
                    "source": it.source,
                    "profile_id": it.profile_id,
                    "thresholds_from": it.thresholds_from,
                    "measurements": it.measurements.source if it.measurements is not None else None,
                    "notes": it.notes,
                    **v.to_dict(),
                }
                for it, v in zip(items, judged.verdicts)
            ],
            "interpolation": [{"focus": r.focus, "rms_px": r.rms_px, "max_px": r.max_px} for r in judged.interpolation],
            "report": str(report) if report else None,
            "unfinished": missing,
        }
        print(json.dumps(plain(out), indent=1))
    else:
        _print_checks(items, judged, report)
    for m in missing:
        say("harp qa", f"{m}: not judged (--partial)")
    return verdict_exit_code(judged.overall)


def _record(args, config, session, items, results) -> None:
    """One row of QA history per judged profile (the verdict a profile was calibrated with is not changed).

    The rows of a run carry its key (``record_key``: the run's key and the row's index). The key is kept in a
    pending file (:func:`_pending_file`, named by the store and what was judged) before the first row is
    written, and the file removed once every row is: a run whose recording failed — a commit that may or may
    not have been written among them, a Ctrl-C, or a process killed (SIGKILL, power) after a commit — leaves
    it, and ``harp qa`` run again with the same results (the same verdicts, checks, figures and thresholds,
    of the same profiles, into the same store) takes that key, so that the rows already written are not
    written twice. Any other run (the first recorded one, or one whose results differ) has a new key and adds
    its rows."""
    session_dir = str(session.path.resolve()) if session else None
    rows = [(it, v, plain({**v.metrics, "focus": it.focus})) for it, v in zip(items, results)]
    pending = None
    key = uuid.uuid4().hex
    try:
        pending = _pending_file(store_location(args.store, config), session_dir, rows)
        key = _pending_key(pending) or key
        _keep_pending(pending, key, args.target)  # before any row: a process killed after a commit leaves it
        with _store(args, config, create=True) as store:
            for i, (it, v, metrics) in enumerate(rows):
                store.put_qa_result(
                    verdict=v,
                    metrics=metrics,
                    profile_id=it.profile_id,
                    session_dir=session_dir,
                    focus=it.focus,
                    key=f"{key}/{i}",
                )
    except StoreError as exc:  # the pending file stays (so does it on a Ctrl-C): a run again adds the others
        # the verdict (and its exit code) stands; its row of QA history is what is missing: say how to add it
        warn("harp qa", f"result not recorded: {exc}; the verdict stands: run harp qa {args.target} again to record it")
        return
    if pending is not None:
        with contextlib.suppress(OSError):
            pending.unlink(missing_ok=True)


PENDING_DAYS = 30
"""A pending QA record's key (:func:`_pending_file`) older than this is dropped when another is kept."""


def _pending_file(loc, session_dir: str | None, rows) -> Path:
    """Where a run whose recording failed keeps its key: ``$XDG_DATA_HOME/harp-station/qa-pending/``, a file
    named by the digest of the store (as messages name it: no password) and of every row's content
    (profile, session, focus, verdict with reasons, checks, thresholds and figures)."""
    what = [
        str(loc),
        session_dir,
        [[it.profile_id, it.focus, v.to_record(), metrics] for it, v, metrics in rows],
    ]
    digest = hashlib.sha256(json.dumps(plain(what), sort_keys=True).encode()).hexdigest()
    return user_store_path().parent / "qa-pending" / f"{digest[:32]}.json"


def _pending_key(pending: Path) -> str | None:
    """The key a pending file keeps (None: none there, or unreadable)."""
    try:
        key = json.loads(pending.read_text(encoding="utf-8"))["key"]
    except (OSError, ValueError, TypeError, KeyError):
        return None
    return key if isinstance(key, str) and key else None


def _keep_pending(pending: Path | None, key: str, target: str) -> None:
    """Keep ``key`` in ``pending`` for a run again (atomically; nothing when it cannot be written: a run again
    then adds its rows anew), and drop pending files older than :data:`PENDING_DAYS`."""
    if pending is None:
        return
    with contextlib.suppress(OSError):
        pending.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(pending, json.dumps({"key": key, "target": str(target)}))
        old = time.time() - PENDING_DAYS * 86400
        for f in pending.parent.glob("*.json"):
            with contextlib.suppress(OSError):
                if f.stat().st_mtime < old:
                    f.unlink()


def _print_checks(items, judged, report) -> None:
    """Every check of every profile, one row each (tab-separated when stdout is not a terminal)."""
    rows = []
    for it, v in zip(items, judged.verdicts):
        for c in v.checks:
            result = "reported" if c.passed is None else ("PASS" if c.passed else "FAIL")
            limit = "" if c.limit is None else f"{c.limit:g}"
            rows.append((f"{it.focus:g}", v.verdict, c.name, cell(c.value), c.comparison, limit, result, c.text))
    print_table(
        ("focus", "verdict", "check", "value (px)", "must be", "limit (px)", "result", "what happened"),
        rows,
        title="QA checks",
        right=("focus", "value (px)", "limit (px)"),
    )
    err = sys.stderr
    for it in items:
        print(f"focus {it.focus:g}: {it.source}; thresholds from {it.thresholds_from}", file=err)
        for n in it.notes:
            print(f"focus {it.focus:g}: {n}", file=err)
    for r in judged.interpolation:
        print(
            f"focus interpolation error at {r.focus:g} (left out): RMS {r.rms_px:.4f} px, max {r.max_px:.4f} px",
            file=err,
        )
    if report:
        print(f"report: {report}", file=err)
    # on a terminal the verdict closes the output; a script reads the exit code (and the TSV on stdout)
    print(f"QA: {judged.overall}", file=sys.stdout if is_terminal() else err)
