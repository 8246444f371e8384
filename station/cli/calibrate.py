"""``harp calibrate IMAGE... --out MODEL [--model auto|radial|poly] [--degree N] [--holdout IMAGE...]``.

Fits a distortion correction to the string edges of harp shots (all shots at
once, :func:`station.calibration.calibrate_shots`, as a session does) and writes
its profile as a model file (:mod:`pipeline.model_file`) with its figures of merit
and provenance.

``--model auto`` (default) chooses the model kind and degree by
cross-validation over the given shots (:func:`pipeline.select.select_model`:
leave one shot out, correct it with the fit on the others, measure it) and
says what it chose. ``--model radial`` fits the radial model with free centre
(:data:`pipeline.fitspec.FULL_RADIAL`: degree 4, with tangential and thin-prism terms unless
``--no-tangential`` / ``--no-prism``; ``--center-prior`` pulls the centre
towards the image centre); ``--model poly`` the bivariate
polynomial (default degree 5); ``--division M`` adds a division (rational)
denominator to the radial factor (wide-angle lenses); ``--field 8x6[@PENALTY]`` a residual
field of 8 x 6 cubic B-spline control points on top of it (:mod:`pipeline.models.radial_field`),
``--field auto`` the model (given or chosen) or it with the field whose knots and penalty win the
cross-validation (:func:`pipeline.select.select_field`: shots of 4 orientations or more). ``--holdout`` shots are never used in the
fit: they are corrected by the fitted model and measured (the paper's
protocol). On a machine with two cores or more the shots are measured, and the
candidates cross-validated, by two worker processes (three shots, or any odd number,
by three at once: none waits for another's last shot); the results do not depend on
it. ``--json`` prints one object::

    {"model": path, "choice": {"model", "degree", "tangential", "prism", "label", "reason", ...},
     "before": {"d", "d_max"}, "fit": {"d", "d_max"}, "holdout": {"d", "d_max", "images": [...]},
     "images": [{"path", "d_before", "d_max_before", "d", "d_max", "n_edges"}], "rejected": [...],
     "warnings": [...], "own_shift": {"ratio_median", "limit", "judged", "moving", "per_orientation": [...]},
     "twins": [{"paths", "angle_deg", "d_common_px", "d_each_px", "ratio", "move_px", "limit_px", "moved"}]}

(``holdout`` only when given; ``own_shift`` with four shots or more: each shot held out in turn and the correction
fitted on the others moved for it alone, :func:`station.calibration.shot_own_shifts`, with a warning when the shots
each want it moved on their own, as a lens whose decentering changes between shots does; ``twins`` when two shots'
strings run within 2 degrees of each other: compared under the correction, :func:`station.moving_lens.twin_record`,
with a warning when the lens moved between them; distances in pixels). Bad
input (unreadable image, no strings, images of different sizes, one orientation only, too few edges): one line on
stderr, exit 2.
"""

from __future__ import annotations

import contextlib
import json
import sys
from dataclasses import replace
from pathlib import Path

from pipeline.fitspec import DEFAULT_DEGREE, DEGREE_BOUNDS, FIELD_AUTO, FIELD_NONE, FULL_RADIAL, FitSpec, parse
from pipeline.plain import finite_or_none
from pipeline.resample import DEFAULT_T
from station.cli.commands import COMMANDS
from station.cli.inputs import positive_int
from station.errors import InputError
from station.exit_codes import EXIT_OK
from station.files import sha256_file, write_profile
from station.inputs import measure_file
from station.pool import WorkerPool
from station.tables import console, is_terminal, print_table


class CalibrateError(InputError):
    """One-line message for the user."""


def register(subparsers) -> None:
    p = subparsers.add_parser("calibrate", help=COMMANDS["calibrate"], description=__doc__.split("\n\n")[0])
    p.add_argument("images", metavar="IMAGE", nargs="+", help="harp shots used for the fit")
    p.add_argument(
        "--model",
        choices=("auto", "radial", "poly"),
        default="auto",
        help="model kind; auto = chosen by leave-one-shot-out cross-validation (default)",
    )
    p.add_argument(
        "--degree",
        type=positive_int,
        default=None,
        help=(
            f"radial: highest power of r, {'..'.join(map(str, DEGREE_BOUNDS['radial']))} "
            f"(default {DEFAULT_DEGREE['radial']}); poly: total degree "
            f"{'..'.join(map(str, DEGREE_BOUNDS['poly']))} (default {DEFAULT_DEGREE['poly']})"
        ),
    )
    p.add_argument("--no-tangential", action="store_true", help="radial: no decentering terms")
    p.add_argument("--no-prism", action="store_true", help="radial: no thin-prism terms")
    p.add_argument(
        "--trefoil",
        action="store_true",
        help="radial: add the three-fold term t1, t2 (needs >= 4 string orientations; pipeline.models.radial)",
    )
    p.add_argument(
        "--division",
        type=int,
        default=0,
        metavar="M",
        help="radial: M division (rational) denominator terms 1 + d1 r^2 + ... (wide-angle lenses; default 0)",
    )
    p.add_argument(
        "--center-prior",
        action="store_true",
        help="radial: pull the distortion centre towards the image centre (see pipeline.select)",
    )
    p.add_argument(
        "--field",
        default=None,
        metavar="NXxNY[@PENALTY]|auto",
        help=(
            "radial: add a residual field of NX x NY cubic B-spline control points and its roughness penalty "
            "(e.g. 8x6, 12x9@0.0001; pipeline.models.radial_field); auto: the model (given or chosen), or it "
            "with the field whose knots and penalty win the cross-validation (pipeline.select.select_field; "
            "shots of 4 orientations or more)"
        ),
    )
    p.add_argument("-o", "--out", required=True, metavar="MODEL", help="model file to write (YAML)")
    p.add_argument(
        "--holdout",
        nargs="+",
        default=[],
        metavar="IMAGE",
        help="shots never used in the fit: corrected by the model and measured",
    )
    p.add_argument(
        "-t", "--t", type=positive_int, default=DEFAULT_T, help=f"along-edge subsampling factor (default {DEFAULT_T})"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _measure_one(job: tuple[str, int]):
    """``(path, ImageMeasurement)`` of one shot (each shot is measured once)."""
    path, t = job
    return path, measure_file(path, t)[1]


@contextlib.contextmanager
def _workers(n_jobs: int, balance: bool = False):
    """A ``map`` over ``min(2, cores)`` worker processes forked from this process (it runs no
    thread: :class:`station.pool.WorkerPool`), or the built-in ``map`` on one core or for a single
    job. ``balance``: one more worker when the jobs do not divide evenly among them (three shots
    on two workers: all three measured at once take 1.5 shot-times on two cores, not two; one
    more shot's memory at a time)."""
    import os

    n = min(2, os.cpu_count() or 1, n_jobs)
    if n >= 2 and balance and n_jobs > n and n_jobs % n:
        n += 1
    with WorkerPool(n, fork=True) as pool:
        yield pool.map


def _spec(args) -> FitSpec | None:
    """The FitSpec the options ask for (None: --model auto)."""
    field = getattr(args, "field", None)
    if args.model == "auto":
        if (
            args.degree is not None
            or args.no_tangential
            or args.no_prism
            or args.center_prior
            or args.division
            or args.trefoil
            or field not in (None, "auto")
        ):
            raise CalibrateError(
                "--degree/--no-tangential/--no-prism/--trefoil/--center-prior/--division/--field need "
                "--model radial or poly"
            )
        return None
    if args.model == "poly" and (
        args.no_tangential or args.no_prism or args.trefoil or args.center_prior or args.division or field is not None
    ):
        raise CalibrateError(
            "--no-tangential/--no-prism/--trefoil/--center-prior/--division/--field apply to --model radial only"
        )
    grid, penalty = None, None
    if field is not None and field != "auto":
        try:
            with_field = parse(f"radial+field{field}")
        except ValueError as exc:
            raise CalibrateError(f"--field {field}: {str(exc).split(': ', 1)[-1]}") from None
        grid, penalty = with_field.field, with_field.field_penalty
    try:
        if args.model == "poly":
            return FitSpec("poly", args.degree)
        return replace(
            FULL_RADIAL,
            degree=args.degree,
            tangential=not args.no_tangential,
            prism=not args.no_prism,
            trefoil=args.trefoil,
            center_prior=args.center_prior,
            division=args.division,
            field=grid,
            field_penalty=penalty,
        )
    except ValueError as exc:
        option = "--division" if "division" in str(exc) else "--degree"
        raise CalibrateError(f"{option}: {exc}") from None


def calibrate(args) -> dict:
    """Do the work; returns the JSON report. Raises InputError / CalibrateError (one line)."""
    cand = _spec(args)
    field_auto = getattr(args, "field", None) == "auto"  # the field's knots and penalty chosen by cross-validation
    out_dir = Path(args.out).parent
    if not out_dir.is_dir():  # before minutes of measuring and fitting, not after
        reason = "not a directory" if out_dir.exists() else "no such directory"
        raise CalibrateError(f"{args.out}: cannot write model file ({out_dir}: {reason})")
    if Path(args.out).is_dir():
        raise CalibrateError(f"{args.out}: cannot write model file (is a directory)")
    # the shots are measured by worker processes forked now (numpy and OpenCV loaded) while this process
    # imports the fitting; the fits then run in workers forked after that import, which they share
    # instead of importing it each
    paths = list(args.images) + list(args.holdout)
    with _workers(len(paths), balance=True) as map_fn:
        measuring = map_fn(_measure_one, [(path, args.t) for path in paths])  # a pool's map starts at once
        # defers station.calibration (pipeline.select, pipeline.fit): the fitting imported while the shots are measured
        import station.calibration  # noqa: F401

        measured = list(measuring)
    with _workers(2 if cand is None or field_auto else 1) as map_fn:  # a given model alone: one fit, nothing to share
        return _calibrate(args, cand, measured[: len(args.images)], measured[len(args.images) :], map_fn, field_auto)


def _calibrate(args, cand: FitSpec | None, fit_m: list, hold_m: list, map_fn, field_auto: bool = False) -> dict:
    # defers yaml
    from station.calibration import (
        GIVEN_ON_COMMAND_LINE,
        calibrate_shots,
        holdout_warning,
        noisy_shot_warnings,
        shot_count_problem,
        shot_own_shifts,
        size_problem,
    )
    from station.moving_lens import own_shift_warning, twin_record, twin_warnings  # defers pipeline.own_shift
    from station.provenance import make_provenance  # defers yaml

    problem = size_problem([(str(p), m.width, m.height) for p, m in fit_m + hold_m])
    if problem:
        raise CalibrateError(problem)
    width, height = fit_m[0][1].width, fit_m[0][1].height
    shots = [[ln.points for ln in m.lines] for _, m in fit_m]
    problem = shot_count_problem(len(shots), cand)
    if problem:
        raise CalibrateError(problem)
    held = [[ln.points for ln in m.lines] for _, m in hold_m]
    cal = calibrate_shots(
        shots,
        width,
        height,
        cand,
        held_out=held,
        image_sizes=[(m.width, m.height) for _, m in fit_m],
        map_fn=map_fn,
        field=FIELD_AUTO if field_auto else FIELD_NONE,
    )
    res = cal.fit
    if not res:
        raise CalibrateError(f"cannot fit {cal.spec.label}: {res.reason}")
    rejected = [{"path": str(fit_m[e.image][0]), "line": e.line, "reason": e.reason} for e in res.rejected]
    assert cal.spec is not None  # a calibration that fitted has its spec
    # each shot held out, the correction moved for it alone (four shots or more): kept with the profile, as a session's
    own = shot_own_shifts(shots, width, height, cal.spec, res.rejected, map_fn)
    # two shots at one angle: did the lens move between them (under the correction fitted on all)?
    twins = twin_record(res.model, shots, [str(p) for p, _ in fit_m])
    details = {**({"own_shift": own} if own is not None else {}), **({"twins": twins} if twins else {})}
    profile = cal.profile(
        width,
        height,
        provenance=make_provenance(
            args.images,
            t=args.t,
            command=["harp", "calibrate", *sys.argv[2:]],
            holdout=[{"path": str(p), "sha256": sha256_file(p)} for p, _ in hold_m],
        ),
        given_by=GIVEN_ON_COMMAND_LINE,
        merit_extra={"rejected_edges": rejected},
        details=details or None,
    )
    merit = profile.merit
    assert merit.before is not None and merit.fit is not None  # a calibration that fitted has both
    report = {
        "model": str(args.out),
        # how the spec was chosen: the cross-validation's table, or the profile's record of a given spec
        "choice": cal.selection.to_dict()
        if cal.selection is not None
        else {**cal.spec.to_dict(), **profile.selection, "table": []},
        "before": merit.before.to_dict(),
        "fit": merit.fit.to_dict(),
        "images": [
            {
                "path": str(fit_m[im.image][0]),
                "n_edges": im.n_edges,
                "d_before": finite_or_none(im.d_before),
                "d_max_before": finite_or_none(im.d_max_before),
                "d": finite_or_none(im.d_after),
                "d_max": finite_or_none(im.d_max_after),
            }
            for im in res.images
        ],
        "rejected": rejected,
        "warnings": list(res.warnings) + noisy_shot_warnings(res, [str(fit_m[i][0]) for i in range(len(fit_m))]),
    }
    if own is not None:
        report["own_shift"] = own
        warning = own_shift_warning(own)
        if warning:
            report["warnings"].append(warning)
    if twins:
        report["twins"] = twins
        report["warnings"].extend(twin_warnings(twins))
    if hold_m:
        per = [
            {
                "path": str(p),
                "d_before": finite_or_none(m.d),
                "d_max_before": finite_or_none(m.d_max),
                "d": h.after.d,
                "d_max": h.after.d_max,
            }
            for (p, m), h in zip(hold_m, cal.held_out)
        ]
        hold = merit.holdout
        assert hold is not None  # held-out shots given: the holdout figures of the profile
        report["holdout"] = {"d": hold.d, "d_max": hold.d_max, "images": per}
        warning = holdout_warning([ln.points for _, m in hold_m for ln in m.lines], hold.d)
        if warning:
            report["warnings"].append(warning)
    try:
        write_profile(args.out, profile)
    except OSError as exc:
        raise CalibrateError(f"{args.out}: cannot write model file ({exc.strerror or exc})") from None
    return report


def _print(report: dict) -> None:
    """The choice, the cross-validation and straightness tables, the rejected edges and warnings
    (:mod:`station.tables`: off a terminal tab-separated tables, nothing cut short or wrapped), and a line per pair of
    twins (two shots at one angle) with the lens's move between them."""
    con = console()

    def say(text: str) -> None:
        con.print(text, markup=False, highlight=False)

    def gap() -> None:  # off a terminal a blank line separates the tables
        if not is_terminal():
            print()

    def f(v):
        return "" if v is None else f"{v:.4f}"

    ch = report["choice"]
    say(f"model: {ch['label']} ({ch['reason']})")
    if ch.get("table"):
        rows = []
        for r in ch["table"]:
            if r["cv_d"] is not None:
                cv = f"{r['cv_d']:.4f}"
            elif r.get("cv_d_bound") is not None:  # stopped: it cannot be chosen
                cv = f">= {r['cv_d_bound']:.4f} (stopped)"
            else:
                cv = "failed"
            folds = " ".join("-" if v is None else f"{v:.4f}" for v in r["fold_d"])
            rows.append((r["label"], str(r["n_params"]), cv, folds))
        gap()
        print_table(("candidate", "params", "CV d (px)", "per fold (px)"), rows, title="cross-validation (holdout d)")
    hold = report.get("holdout", {}).get("images", [])
    names = [Path(im["path"]).name for im in [*report["images"], *hold]]

    def label(path):  # file names, unless two shots share one (then the whole path)
        return Path(path).name if names.count(Path(path).name) == 1 else str(path)

    rows = [
        (label(im["path"]), str(im["n_edges"]), f(im["d_before"]), f(im["d_max_before"]), f(im["d"]), f(im["d_max"]))
        for im in report["images"]
    ]
    b, fit = report["before"], report["fit"]
    rows.append(("fit (all)", "", f(b["d"]), f(b["d_max"]), f(fit["d"]), f(fit["d_max"])))
    rows += [
        (f"holdout {label(im['path'])}", "", f(im["d_before"]), f(im["d_max_before"]), f(im["d"]), f(im["d_max"]))
        for im in hold
    ]
    if "holdout" in report:
        rows.append(("holdout (all)", "", "", "", f(report["holdout"]["d"]), f(report["holdout"]["d_max"])))
    columns = ("shot", "edges", "d before (px)", "d_max before (px)", "d after (px)", "d_max after (px)")
    gap()
    print_table(columns, rows, title="straightness", right=columns[1:])
    gap()
    for t in report.get("twins", []):  # two shots at one angle: did the lens move between them
        a, b = (label(p) for p in t["paths"])
        move = "-" if t["move_px"] is None else f"{abs(t['move_px']):.2f} px"
        angle = "-" if t["angle_deg"] is None else f"{t['angle_deg']:.1f}"
        say(f"twins: {a} and {b} (strings at {angle} deg): lens move across the strings {move} "
            f"(limit {t['limit_px']:g} px)")  # fmt: skip
    for r in report["rejected"]:
        say(f"rejected edge: {r['path']} line {r['line']}: {r['reason']}")
    for w in report["warnings"]:
        say(f"warning: {w}")
    say(f"wrote {report['model']}")


def run(args) -> int:
    report = calibrate(args)
    if args.json:
        print(json.dumps(report))
    else:
        _print(report)
    return EXIT_OK
