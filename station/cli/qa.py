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
plots and its ``index.html``. Each result is recorded in the store's QA history (unless
``--no-record``); it does not change the verdict a profile was calibrated with.
Exit 0 PASS, 1 FAIL, 2 error — for production-line scripts.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from station.exit_codes import EXIT_ERROR, verdict_exit_code
from station.plain_json import plain
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
    p.add_argument(
        "--no-recompute",
        action="store_true",
        help="do not recompute the holdout d from the session's measurements (quicker; the stored one is judged)",
    )
    p.add_argument("--report", type=Path, metavar="DIR", default=None, help="write a Markdown report here")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument("--no-record", action="store_true", help="do not record the result in the store's QA history")
    p.set_defaults(func=run)


class _Fail(Exception):
    """A one-line error for the user (exit 2)."""


@dataclass
class Item:
    """One profile to judge: its focus, where it comes from, and what it is judged with."""

    focus: float
    profile: Any  # station.profile.Profile
    profile_id: int | None
    source: str
    focus_idx: int | None = None  # in the session the measurements come from
    measurements: Any = None  # station.qa.verdicts.Measurements, or None
    thresholds_from: str = "defaults"
    notes: list[str] = field(default_factory=list)


def _store(args, config, create=False):
    """The store (:mod:`station.store.resolve`): ``--store``, else that of ``config`` (``--config``,
    or the session's), else ``$HARP_STORE``, else the default. For reading unless ``create``."""
    from station.store.resolve import open_store, store_location

    return open_store(store_location(args.store, config), write=create)


def _latest(store, lens_id: int):
    """The newest profile of each focus setting of a lens, whatever its verdict: QA judges them all."""
    return store.latest_by_focus(lens_id, allow_failed=True)


def _candidates(args, config, session) -> list[Item]:
    """What to judge: every profile of the session, or the newest profiles of the lens."""
    from station.qa.verdicts import session_measurements, session_profiles

    if session is not None:
        profiles = session_profiles(session.path)
        if not profiles:
            raise _Fail(f"{session.path}: session has no fitted profile yet")
        items = []
        for f, p in profiles:
            item = Item(
                p.focus if p.focus is not None else session.config.focus_settings[f],
                p,
                p.id,
                str(session.path / layout.profile_file(f)),
                focus_idx=f,
                measurements=session_measurements(session, f),
            )
            if item.measurements is None:
                item.notes.append("the session kept no measurements for this focus setting: stored figures judged")
            items.append(item)
        return items
    with _store(args, config) as store:
        lens = store.find_lens(args.target)
        profiles = _latest(store, lens[0])
    if not profiles:
        raise _Fail(f"lens {args.target!r} has no profile")
    return [Item(p.focus, p, p.id, f"profile #{p.id}") for p in profiles]


def _lens_measurements(item: Item, opened: dict) -> None:
    """The measurements of the session a stored profile names, when its directory is at hand."""
    from station.config import ConfigError
    from station.qa.verdicts import session_measurements
    from station.session.directory import SessionDir, SessionError

    where = item.profile.provenance.session_dir
    if not where or not (Path(where) / layout.SESSION_FILE).is_file():
        item.notes.append(
            f"its session directory {where or '(none recorded)'} is not at hand: the model is judged without "
            "the measurements it was fitted on"
        )
        return
    if where not in opened:
        try:
            opened[where] = SessionDir.open(Path(where))
        except (SessionError, ConfigError, OSError, ValueError) as exc:
            opened[where] = None
            item.notes.append(f"its session {where} cannot be read ({exc}): judged without its measurements")
            return
    session = opened[where]
    if session is None:
        return
    hits = [f for f, v in enumerate(session.config.focus_settings) if math.isclose(v, item.focus, abs_tol=1e-9)]
    if not hits:
        item.notes.append(f"its session {where} has no focus setting {item.focus:g}: judged without measurements")
        return
    item.focus_idx = hits[0]
    item.measurements = session_measurements(session, hits[0])
    if item.measurements is None:
        item.notes.append(f"its session {where} kept no measurements at focus {item.focus:g}")


def _thresholds(args, cli_config, session, item: Item):
    """The thresholds to judge ``item`` with: the command line's over ``--config``'s over those it was
    calibrated under (the session's configuration, the stored verdict's) over the defaults."""
    from station.qa.verdicts import calibrated_thresholds, thresholds_from

    if cli_config is not None:
        base, origin = cli_config.qa, f"--config {cli_config.path}"
    elif session is not None:
        base, origin = session.config.qa, "the session's configuration"
    elif (cal := calibrated_thresholds(item.profile)) is not None:
        base, origin = cal, "calibration"
    else:
        base, origin = None, "defaults (the profile records none)"
    overrides = {
        "max_holdout_d_px": args.max_holdout_d,
        "max_distortion_px": args.max_distortion,
        "max_reference_deviation_px": args.max_reference_deviation,
    }
    if any(v is not None for v in overrides.values()):
        origin += " and the command line"
    item.thresholds_from = origin
    return thresholds_from(base, **overrides)


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
    from station.qa.report import FocusEvidence, session_context, session_evidence, write_report

    evidence = []
    for it, v in zip(items, results):
        if session is not None and it.focus_idx is not None:
            e = session_evidence(
                session,
                it.focus_idx,
                it.focus,
                it.profile,
                v,
                source=it.source,
                bootstrap_if_missing=session.config.pipeline.bootstrap or REPORT_BOOTSTRAP,
            )
        else:
            prof = it.profile
            e = FocusEvidence(
                focus=it.focus, model=prof.model, width=prof.width, height=prof.height, verdict=v, source=it.source
            )
            unc = prof.merit.field_uncertainty
            e.uncertainty_note = (
                "stored: RMS {} px, max {} px (no per-pixel map without the session's "
                "frames: run `harp qa SESSION_DIR --report`)"
            ).format(*(f"{x:.4f}" if x is not None else "-" for x in ((unc.rms, unc.max) if unc else (None, None))))
        evidence.append(e)
    if session is not None:
        context, warnings = session_context(session)
    else:
        context, warnings = _lens_context(items), []
    notes = [f"focus {it.focus:g}: {n}" for it in items for n in it.notes]
    return write_report(
        args.report,
        title,
        evidence,
        overall,
        thresholds=thresholds,
        interpolation=interpolation,
        notes=notes,
        context=context,
        warnings=warnings,
    )


def _lens_context(items: list[Item]) -> list[tuple[str, str]]:
    """Report rows of a stored lens: each profile's calibration date, station, software and session."""
    from station import __version__

    rows = [("software (this report)", f"harp station {__version__}")]
    for it in items:
        p = it.profile.provenance
        rows.append(
            (
                f"focus {it.focus:g}",
                f"{it.source}, calibrated {p.created_utc or it.profile.stored_at or '-'} on station "
                f"{p.station or '-'} with {p.software or '-'}, session `{p.session_dir or '-'}`; "
                f"thresholds from {it.thresholds_from}",
            )
        )
    return rows


def run(args) -> int:
    from station.config import ConfigError, load_config
    from station.qa.verdicts import combine, interpolation_error, qa_verdict
    from station.session.directory import SessionDir, SessionError
    from station.store import StoreError

    session = None
    opened: dict[str, Any] = {}
    try:
        try:
            cli_config = load_config(args.config) if args.config else None
            config = cli_config
            target = Path(args.target)
            if (target / layout.SESSION_FILE).is_file():
                session = SessionDir.open(target)
                config = config or session.config
            elif target.exists() and target.is_dir():
                raise _Fail(f"{target}: not a session directory (no {layout.SESSION_FILE})")
            items = _candidates(args, config, session)
            results, used = [], []
            for it in items:
                if session is None:
                    _lens_measurements(it, opened)
                thresholds = _thresholds(args, cli_config, session, it)
                used.append(thresholds)
                if args.reference is not None and thresholds.max_reference_deviation_px is None:
                    raise _Fail(
                        "--reference needs a threshold: set qa.max_reference_deviation_px in the "
                        "configuration or give --max-reference-deviation PX"
                    )
                ref = _reference(args, config, it.focus, it.profile.width, it.profile.height)
                v = qa_verdict(
                    it.profile,
                    thresholds,
                    reference=ref,
                    measurements=it.measurements,
                    recompute=not args.no_recompute,
                )
                note = v.metrics.get("holdout_note")
                if note:
                    it.notes.append(f"holdout d {note}")
                results.append(v)
            overall = combine(results)
            pds = [it.profile for it in items]
            interpolation = []
            if len({(p.width, p.height) for p in pds}) == 1 and len({it.focus for it in items}) == len(items):
                interpolation = interpolation_error(
                    {it.focus: it.profile.model for it in items}, pds[0].width, pds[0].height
                )
            report = None
            if args.report is not None:
                try:
                    report = _report(args, str(args.target), items, results, overall, used[0], interpolation, session)
                except OSError as exc:
                    raise _Fail(
                        f"{args.report}: cannot write the report "
                        f"({exc.strerror or exc}{': ' + exc.filename if exc.filename else ''})"
                    ) from None
        except (ConfigError, SessionError, StoreError, _Fail, ValueError, OSError) as exc:
            print(f"harp qa: {exc}", file=sys.stderr)
            return EXIT_ERROR
    finally:
        if session is not None:
            session.close()
        for s in opened.values():
            if s is not None:
                s.close()

    if not args.no_record:
        _record(args, config, session, items, results)

    if args.json:
        out = {
            "target": str(args.target),
            "verdict": overall,
            "thresholds": dict(used[0].__dict__),
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
                for it, v in zip(items, results)
            ],
            "interpolation": [{"focus": r.focus, "rms_px": r.rms_px, "max_px": r.max_px} for r in interpolation],
            "report": str(report) if report else None,
        }
        print(json.dumps(plain(out), indent=1))
    else:
        _print_checks(items, results, interpolation, overall, report)
    return verdict_exit_code(overall)


def _record(args, config, session, items, results) -> None:
    """One row of QA history per judged profile (the verdict a profile was calibrated with is not changed)."""
    from station.store import StoreError

    try:
        with _store(args, config, create=True) as store:
            for it, v in zip(items, results):
                metrics = plain({**v.metrics, "focus": it.focus})
                store.put_qa_result(
                    verdict=v,
                    metrics=metrics,
                    profile_id=it.profile_id,
                    session_dir=str(session.path.resolve()) if session else None,
                    focus=it.focus,
                )
    except StoreError as exc:
        print(f"harp qa: warning: result not recorded: {exc}", file=sys.stderr)


def _print_checks(items, results, interpolation, overall, report) -> None:
    """Every check of every profile, one row each (tab-separated when stdout is not a terminal)."""
    from station.tables import cell, is_terminal, print_table

    rows = []
    for it, v in zip(items, results):
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
    for r in interpolation:
        print(
            f"focus interpolation error at {r.focus:g} (left out): RMS {r.rms_px:.4f} px, max {r.max_px:.4f} px",
            file=err,
        )
    if report:
        print(f"report: {report}", file=err)
    # on a terminal the verdict closes the output; a script reads the exit code (and the TSV on stdout)
    print(f"QA: {overall}", file=sys.stdout if is_terminal() else err)
