"""``harp qa SESSION_OR_LENS [--reference REF] [--max-... PX] [--report DIR] [--json]``.

Factory QA: a PASS / FAIL verdict, with reasons, for every profile of a
session directory (thresholds from its configuration's ``qa`` section) or of
a lens in the profile store (newest profile per focus; thresholds from
``--config`` or the defaults); ``--max-holdout-d``, ``--max-distortion`` and
``--max-reference-deviation`` override them. REF, the golden reference of the
same lens model, is a harp model file, a stored profile ``#id``, or a lens in
the store (its profile at the same focus, interpolated between its calibrated
focus settings when needed). ``--report DIR`` writes a Markdown report with
plots and its ``index.html`` (for a session: also per-edge residuals,
overlays and the bootstrap uncertainty map, from the measurements and map the
session kept; only an older session without them is measured again). Each result is recorded in the
store's ``qa_results`` (unless ``--no-record``).
Exit 0 PASS, 1 FAIL, 2 error — for production-line scripts.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

from station.session import layout
from station.store import DEFAULT_STORE

REPORT_BOOTSTRAP = 20
"""Bootstrap replicates of the report's uncertainty map when the configuration sets none."""


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
    p = subparsers.add_parser(
        "qa", help="factory QA verdict of a session or a stored lens", description=__doc__.split("\n\n")[1]
    )
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
        f"session's, else $HARP_STORE or {DEFAULT_STORE})",
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
    p.add_argument("--report", type=Path, metavar="DIR", default=None, help="write a Markdown report here")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument("--no-record", action="store_true", help="do not record the result in the store")
    p.set_defaults(func=run)


class _Fail(Exception):
    """A one-line error for the user (exit 2)."""


def _store(args, config, create=False):
    """The store (:mod:`station.store.resolve`): ``--store``, else that of ``config`` (``--config``,
    or the session's), else ``$HARP_STORE``, else the default. For reading unless ``create``."""
    from station.store.resolve import open_store, store_location

    return open_store(store_location(args.store, config), write=create)


def _candidates(args, config, session):
    """[(focus, Profile, profile_id, source)] of what to judge."""
    from station.qa.verdicts import session_profiles

    if session is not None:
        profiles = session_profiles(session.path)
        if not profiles:
            raise _Fail(f"{session.path}: session has no fitted profile yet")
        return [
            (
                p.focus if p.focus is not None else session.config.focus_settings[f],
                p,
                None,
                str(session.path / layout.profile_file(f)),
            )
            for f, p in profiles
        ]
    with _store(args, config) as store:
        lens = store.find_lens(args.target)
        profiles = store.latest_by_focus(lens[0])
    if not profiles:
        raise _Fail(f"lens {args.target!r} has no profile")
    return [(p.focus, p, p.id, f"profile #{p.id}") for p in profiles]


def _reference(args, config, focus, width, height):
    """The reference correction for one profile, or None."""
    if args.reference is None:
        return None
    ref = args.reference
    if Path(ref).is_file():
        from pipeline.model_file import read_model_file

        try:
            mf = read_model_file(ref)
        except ValueError as exc:
            raise _Fail(f"reference {exc}") from None  # the message starts with the file name
        if (mf.width, mf.height) != (width, height):
            raise _Fail(f"reference {ref} is for {mf.width}x{mf.height} images, not {width}x{height}")
        return mf.model
    if "/" in ref or Path(ref).suffix.lower() in (".yaml", ".yml", ".json"):
        raise _Fail(f"reference {ref}: no such model file")
    with _store(args, config) as store:
        if ref.startswith("#") and ref[1:].isdigit():
            p = store.profile(int(ref[1:]))
            if p is None:
                raise _Fail(f"no profile {ref} in {store.path}")
            profiles = [p]
        else:
            lens = store.find_lens(ref)
            profiles = store.latest_by_focus(lens[0])
    sizes = {(p.width, p.height) for p in profiles}
    if sizes != {(width, height)}:
        raise _Fail(
            f"reference {ref!r} is for {', '.join(f'{w}x{h}' for w, h in sorted(sizes))} images, not {width}x{height}"
        )
    if len(profiles) == 1 and ref.startswith("#"):
        return profiles[0].model
    same = [p for p in profiles if math.isclose(p.focus, focus, abs_tol=1e-9)]
    if same:
        return same[0].model
    from pipeline.interpolate import interpolate_correction

    try:
        return interpolate_correction({p.focus: p.model for p in profiles}, focus, width, height)
    except ValueError as exc:
        raise _Fail(f"reference lens {ref!r} at focus {focus:g}: {exc}") from None


def _report(args, title, items, results, overall, thresholds, interpolation, session) -> Path:
    from station.qa.report import FocusEvidence, session_evidence, write_report

    evidence = []
    for (focus, prof, _pid, source), v in zip(items, results):
        if session is not None:
            f_idx = int(Path(source).stem.replace("focus", ""))
            e = session_evidence(
                session,
                f_idx,
                focus,
                prof,
                v,
                source=source,
                bootstrap_if_missing=session.config.pipeline.bootstrap or REPORT_BOOTSTRAP,
            )
        else:
            e = FocusEvidence(
                focus=focus, model=prof.model, width=prof.width, height=prof.height, verdict=v, source=source
            )
            unc = prof.merit.field_uncertainty
            e.uncertainty_note = (
                "stored: RMS {} px, max {} px (no per-pixel map without the session's "
                "frames: run `harp qa SESSION_DIR --report`)"
            ).format(*(f"{x:.4f}" if x is not None else "-" for x in ((unc.rms, unc.max) if unc else (None, None))))
        evidence.append(e)
    return write_report(args.report, title, evidence, overall, thresholds=thresholds, interpolation=interpolation)


def _plain(v):
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


def run(args) -> int:
    from station.config import ConfigError, load_config
    from station.qa.verdicts import combine, interpolation_error, qa_verdict, thresholds_from
    from station.session.directory import SessionDir, SessionError
    from station.store import StoreError

    session = None
    try:
        try:
            config = load_config(args.config) if args.config else None
            target = Path(args.target)
            if (target / layout.SESSION_FILE).is_file():
                session = SessionDir.open(target)
                config = config or session.config
            elif target.exists() and target.is_dir():
                raise _Fail(f"{target}: not a session directory (no {layout.SESSION_FILE})")
            thresholds = thresholds_from(
                config.qa if config is not None else None,
                max_holdout_d_px=args.max_holdout_d,
                max_distortion_px=args.max_distortion,
                max_reference_deviation_px=args.max_reference_deviation,
            )
            if args.reference is not None and thresholds.max_reference_deviation_px is None:
                raise _Fail(
                    "--reference needs a threshold: set qa.max_reference_deviation_px in the "
                    "configuration or give --max-reference-deviation PX"
                )
            items = _candidates(args, config, session)
            results = []
            for focus, prof, _pid, _src in items:
                ref = _reference(args, config, focus, prof.width, prof.height)
                results.append(qa_verdict(prof, thresholds, reference=ref))
            overall = combine(results)
            pds = [p for _f, p, _i, _s in items]
            interpolation = []
            if len({(p.width, p.height) for p in pds}) == 1 and len({f for f, *_ in items}) == len(items):
                interpolation = interpolation_error(
                    {f: p.model for (f, *_), p in zip(items, pds)}, pds[0].width, pds[0].height
                )
            report = None
            if args.report is not None:
                try:
                    report = _report(
                        args, str(args.target), items, results, overall, thresholds, interpolation, session
                    )
                except OSError as exc:
                    raise _Fail(
                        f"{args.report}: cannot write the report "
                        f"({exc.strerror or exc}{': ' + exc.filename if exc.filename else ''})"
                    ) from None
        except (ConfigError, SessionError, StoreError, _Fail, ValueError, OSError) as exc:
            print(f"harp qa: {exc}", file=sys.stderr)
            return 2
    finally:
        if session is not None:
            session.close()

    if not args.no_record:
        try:
            with _store(args, config, create=True) as store:
                for (focus, _p, pid, _src), v in zip(items, results):
                    # one row of QA history, with its checks and thresholds; the verdict a profile was
                    # calibrated under (which decides whether it is current) is the session's, not changed here
                    store.put_qa_result(
                        verdict=v,
                        metrics=_plain({**v.metrics, "focus": focus}),
                        profile_id=pid,
                        session_dir=str(session.path.resolve()) if session else None,
                        focus=focus,
                    )
        except StoreError as exc:
            print(f"harp qa: warning: result not recorded: {exc}", file=sys.stderr)

    if args.json:
        out = {
            "target": str(args.target),
            "verdict": overall,
            "thresholds": dict(thresholds.__dict__),
            "profiles": [
                {"focus": f, "source": src, "profile_id": pid, **v.to_dict()}
                for (f, _p, pid, src), v in zip(items, results)
            ],
            "interpolation": [{"focus": r.focus, "rms_px": r.rms_px, "max_px": r.max_px} for r in interpolation],
            "report": str(report) if report else None,
        }
        print(json.dumps(_plain(out), indent=1))
    else:
        _print_table(args.target, items, results, interpolation, overall, report)
    return 0 if overall == "PASS" else 1


def _print_table(target, items, results, interpolation, overall, report) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console() if sys.stdout.isatty() else Console(width=160)
    t = Table(title=f"QA of {target}")
    for col in ("focus", "verdict", "holdout d", "distortion max", "ref. dev. max", "unc. max", "reasons / checks"):
        t.add_column(col)
    fmt = lambda v: "-" if v is None or not math.isfinite(v) else f"{v:.4f}"  # noqa: E731
    for (focus, *_), v in zip(items, results):
        m = v.metrics
        t.add_row(
            f"{focus:g}",
            v.verdict,
            fmt(m.get("holdout_d_px")),
            fmt(m.get("distortion_max_px")),
            fmt(m.get("reference_max_px")),
            fmt(m.get("field_uncertainty_max_px")),
            "; ".join(v.reasons or [c.text for c in v.checks]),
        )
    console.print(t)
    for r in interpolation:
        console.print(
            f"focus interpolation error at {r.focus:g} (left out): RMS {r.rms_px:.4f} px, max {r.max_px:.4f} px"
        )
    if report:
        console.print(f"report: {report}")
    print(f"QA: {overall}")
