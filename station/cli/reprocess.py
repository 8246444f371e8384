"""``harp reprocess SESSION_DIR... [--scheduler tcp://HOST:PORT] [--store PATH|URL] [--json]``.

Re-measures and re-fits archived sessions with the current pipeline
(:mod:`station.reprocess`): every focus setting a session stored a profile for, from the frames
it kept, exactly as the session did (its configuration's measurement, fit, bootstrap and QA
thresholds; ``--model`` fits another model, ``auto`` the cross-validated choice; ``--field none`` or
``auto`` sets ``pipeline.field`` instead of the configuration: a session recorded before the setting
existed has the default, ``auto``, which adds a residual field where it holds on unseen orientations and
costs time). The new
profiles are stored next to the old ones (``--dry-run``: not stored; the store is only read, to name
the old profiles, and neither created nor upgraded); each one's provenance
names the session, the profile it re-processes and the software versions before and now. Then
a table compares the old and new figures per session and focus setting (off a terminal
tab-separated, an old and a new column per figure: :mod:`station.tables`; ``--json``: one JSON
object instead).

Where it runs: a local process pool (``--workers N``, default the number of CPUs; 1: in this
process), or the Dask cluster whose scheduler is ``--scheduler tcp://HOST:PORT`` (its workers
must run this software and read the session directories at the same paths). One job is one
focus setting of one session; the figures do not depend on where it ran.

Store: ``--store PATH|URL`` or ``--config CONFIG``; else the store the first session's
configuration names (else ``$HARP_STORE``, else the default). With ``--dry-run`` a store that is not
there, or was written by an older harp station, is a warning (the old profile ids are then not
shown), and the comparison goes on.

Exit codes: 0 every session was re-processed (and stored); 2 an error — bad arguments, a store
or scheduler that cannot be used, or a session that could not be re-processed (one line each on
stderr; the other sessions are still re-processed and stored); 130 interrupted (sessions already
reported are stored).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import time
from pathlib import Path
from typing import Any

from pipeline.fitspec import FIELD_CHOICES, parse_choice
from pipeline.plain import finite_or_none
from station.cli.commands import COMMANDS
from station.cli.say import say, warn
from station.cli.store_options import add_store_options, location_from_args, open_store
from station.ctrl_c import stopped_text, stopper
from station.errors import HarpError, Interrupted
from station.exit_codes import EXIT_ERROR, EXIT_OK
from station.store.errors import StoreError
from station.tables import console, is_terminal, print_table


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "reprocess",
        help=COMMANDS["reprocess"],
        description="\n\n".join(__doc__.split("\n\n")[1:]),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("sessions", nargs="+", metavar="SESSION_DIR", type=Path, help="archived session directories")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="run on this Dask cluster (default: a local pool)")
    p.add_argument(
        "--workers", type=int, default=None, help="local pool processes (default: the number of CPUs; 1: no pool)"
    )
    p.add_argument("--model", metavar="LABEL", help="fit this model instead of the session's ('auto': cross-validated)")
    p.add_argument(
        "--field",
        choices=FIELD_CHOICES,
        help="pipeline.field instead of the session's configuration (auto: a residual field where it holds on "
        "unseen orientations; none: never)",
    )
    p.add_argument("--dry-run", action="store_true", help="re-process and compare, store nothing")
    p.add_argument("--json", action="store_true", help="print the comparison as one JSON object")
    add_store_options(p)
    p.set_defaults(func=run)


def _error(msg: str) -> None:
    """One session's failure, on stderr as it happens; the others go on (exit 2 at the end)."""
    say("harp reprocess", msg, flush=True)


def run(args: argparse.Namespace) -> int:
    # defers cv2, numpy, yaml
    from station.reprocess import dask_cluster

    if args.workers is not None and args.workers < 1:
        raise HarpError("--workers must be at least 1")
    if args.scheduler is not None and args.workers is not None:
        raise HarpError("--workers is for the local pool; the cluster's workers are the scheduler's")
    if args.model is not None:
        try:
            parse_choice(args.model)
        except ValueError as exc:
            raise HarpError(f"--model {args.model}: {exc}") from None
    missing = [s for s in args.sessions if not s.is_dir()]
    if missing:
        what = "a file, not a session directory" if missing[0].exists() else "no such session directory"
        raise HarpError(f"{missing[0]}: {what}")

    with contextlib.ExitStack() as stack:
        # the cluster connected and its workers checked before the store is opened: a typo, a cluster without
        # workers or with other ones create no store (a ReprocessError: one line, station.cli.main)
        cluster = stack.enter_context(dask_cluster(args.scheduler)) if args.scheduler is not None else None
        return _run(args, cluster)


def _run(args: argparse.Namespace, cluster: Any) -> int:
    # defers cv2, numpy, yaml
    from station.reprocess import ArchivedSession, ClusterLost, SessionCollector, plan_jobs, run_jobs

    jobs, failed = plan_jobs(args.sessions, args.model, args.field)
    for msg in failed.values():
        _error(msg)
    store = None
    outcomes: dict[str, Any] = {}
    try:  # Ctrl-C from the store's opening on: the line says what was stored before it
        if jobs:  # a StoreError or ConfigError: one line (station.cli.main)
            first = ArchivedSession(jobs[0].session_dir).config
            store = _open(location_from_args(args, first), args.dry_run)

        def say_failure(outcome: Any) -> None:
            if not outcome.ok:
                _error(outcome.failure or "failed")

        collect = SessionCollector(jobs, store, on_outcome=say_failure, dry_run=args.dry_run)
        outcomes = collect.outcomes
        t0 = time.perf_counter()

        workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
        run_jobs(jobs, workers=workers, scheduler=cluster, on_result=collect)  # a ReprocessError: one line
    except KeyboardInterrupt:
        raise Interrupted(
            f"{stopped_text()}: {_kept(outcomes, args.dry_run)} before {stopper()}; the others are not (run it again "
            "for them)"
        ) from None
    except ClusterLost as exc:  # the scheduler killed, every worker gone
        raise HarpError(
            f"{exc.what}: {_kept(outcomes, args.dry_run)} before it; {exc.to_do}, then run the same command for "
            "the others"
        ) from None
    finally:
        if store is not None:
            store.close()
    wall = time.perf_counter() - t0
    order = [str(Path(s).resolve()) for s in args.sessions]
    doc = _document(order, outcomes, failed, wall, args)
    doc["store"] = str(store.location) if store is not None else None
    if args.json:
        print(json.dumps(doc, allow_nan=False))
    else:
        _print_table(doc)
    return EXIT_OK if not doc["failed"] else EXIT_ERROR


def _kept(outcomes: dict[str, Any], dry_run: bool) -> str:
    """``N session(s) re-processed and stored``: what a run stopped midway (Ctrl-C, a lost scheduler) kept."""
    done = sum(1 for o in outcomes.values() if o.ok)
    return f"{done} session(s) {'re-processed and stored' if not dry_run else 're-processed'}"


def _open(loc: Any, dry_run: bool) -> Any:
    """The store the new profiles go to (created or upgraded if need be); with ``dry_run`` the store
    read for the old profiles' ids only — never created nor upgraded: None, with a warning, when it is
    not there or is older (a damaged or unreachable store is an error either way)."""
    if not dry_run:
        return open_store(loc, write=True, prog="harp reprocess")
    try:
        return open_store(loc, prog="harp reprocess", upgrade=False)
    except StoreError as exc:
        if exc.kind not in ("missing", "older"):
            raise
        warn("harp reprocess", f"{exc} (--dry-run: the old profiles' store ids are not shown)")
        return None


# ----------------------------------------------------------------- output


def _figures(p: Any, verdict: str | None = None) -> dict[str, Any]:
    if p is None:
        return {}
    m = p.merit
    unc = m.field_uncertainty
    qa = p.qa
    return {
        "model": p.spec.label if p.spec is not None else p.model.name,
        "fit_d_px": finite_or_none(m.fit.d) if m.fit else None,
        "holdout_d_px": finite_or_none(m.holdout.d) if m.holdout else None,
        "holdout_d_max_px": finite_or_none(m.holdout.d_max) if m.holdout else None,
        "distortion_max_px": finite_or_none(qa.metrics.get("distortion_max_px")) if qa is not None else None,
        "field_uncertainty_rms_px": finite_or_none(unc.rms) if unc else None,
        "verdict": qa.verdict if qa is not None else verdict,
        "software": p.provenance.software,
    }


def _document(order: list[str], outcomes: dict[str, Any], failed: dict[str, str], wall: float, args: Any) -> dict:
    sessions = []
    for s in order:
        if s in failed:
            sessions.append({"session": s, "ok": False, "failure": failed[s], "focus": []})
            continue
        o = outcomes.get(s)
        if o is None:
            continue
        focus = []
        for i, r in enumerate(o.results):
            old = r.old.profile if r.old is not None else None
            entry: dict[str, Any] = {
                "focus": r.focus,
                "seconds": round(r.seconds, 3),
                "worker": r.worker,
                "failure": r.failure,
                "old": {
                    "profile_id": o.old_ids[i] if o.ok else (r.old.store_id if r.old else None),
                    **_figures(old, r.old.verdict if r.old else None),
                },
                "new": {"profile_id": o.new_ids[i] if i < len(o.new_ids) else None, **_figures(r.profile)},
            }
            focus.append(entry)
        sessions.append({"session": s, "ok": o.ok, "failure": o.failure, "focus": focus})
    n_failed = sum(1 for s in sessions if not s["ok"])
    return {
        "sessions": sessions,
        "reprocessed": len(sessions) - n_failed,
        "failed": n_failed,
        "stored": not args.dry_run,
        "where": args.scheduler or f"local pool of {args.workers or os.cpu_count() or 1}",
        "wall_s": round(wall, 2),
    }


FIGURES = (  # (column, key, decimals)
    ("fit d (px)", "fit_d_px", 4),
    ("holdout d (px)", "holdout_d_px", 4),
    ("distortion max (px)", "distortion_max_px", 3),
    ("uncertainty rms (px)", "field_uncertainty_rms_px", 4),
)


def _print_table(doc: dict) -> None:
    """Old and new figures per session and focus setting (:func:`station.tables.print_table`): on a
    terminal ``old → new`` in one cell; otherwise tab-separated, an ``old`` and a ``new`` column each,
    the session's whole path."""
    pairs = is_terminal()
    say = console()

    def f(v: Any, nd: int = 4) -> str:
        return "" if v is None else f"{v:.{nd}f}"

    def pid(d: dict) -> str:
        return "" if d.get("profile_id") is None else f"#{d['profile_id']}"

    def both(old: str, new: str) -> tuple[str, ...]:
        return (f"{old or '–'} → {new or '–'}",) if pairs else (old, new)

    names = ("profile", "model", *(c for c, _k, _n in FIGURES), "verdict")
    columns = ["session", "focus", *(names if pairs else (f"{n} {w}" for n in names for w in ("old", "new")))]
    if not pairs:  # the unit after old / new: "fit d old (px)"
        columns = [c.replace(" (px) old", " old (px)").replace(" (px) new", " new (px)") for c in columns]
    rows = []
    width = 2 + len(names) * (1 if pairs else 2)
    for s in doc["sessions"]:
        name = Path(s["session"]).name if pairs else str(s["session"])
        if not s["focus"]:
            rows.append((name, *[""] * (width - 2), "not re-processed"))
        for e in s["focus"]:
            o, n = e["old"], e["new"]
            focus = f"{e['focus']:g}" if e["focus"] is not None else ""
            if e["failure"] or not s["ok"]:
                rows.append((name, focus, *[""] * (width - 3), "failed"))
                continue
            cells: list[str] = [name, focus, *both(pid(o), pid(n)), *both(o.get("model") or "", n.get("model") or "")]
            for _c, key, nd in FIGURES:
                cells += both(f(o.get(key), nd), f(n.get(key), nd))
            cells += both(o.get("verdict") or "", n.get("verdict") or "")
            rows.append(tuple(cells))
    print_table(
        columns,
        rows,
        title=f"re-processed on {doc['where']}: old → new",
        right=[c for c in columns if c.startswith("focus") or "(px)" in c],
    )
    if not pairs:
        print()  # a blank line after the table
    stored = "stored" if doc["stored"] else "not stored (--dry-run)"
    say.print(
        f"{doc['reprocessed']} session(s) re-processed, {doc['failed']} failed, in {doc['wall_s']:.1f} s; "
        f"new profiles {stored}",
        markup=False,
    )
