"""``harp intrinsics MODEL BOARD_SHOT... --board LABEL [-o OUT] | --id N BOARD_SHOT... --board LABEL``.

The camera matrix (fx, fy, cx, cy; skew with ``--skew``) from photographs of a calibration
board, with the harp's distortion held fixed: the board's corners are found in each shot
(ChArUco or chessboard, ``--board charuco:NXxNY:SQUARE_MM:MARKER_MM[:DICT]`` or
``chessboard:NXxNY:SQUARE_MM``), corrected by the model, and a pin-hole bundle adjustment
over the camera matrix and the board poses fits them (:mod:`pipeline.intrinsics`). Printed:
each view's corners, edge width and held-out error (the view left out, the camera matrix
fitted on the others); the camera matrix with each parameter's standard deviation; the
reprojection and held-out errors. ``-o OUT`` writes the model file with the camera matrix in
it (every export of it then uses it); ``--id N`` keeps it with the stored profile #N instead
(``--store`` / ``--config``), whose exports then use it. ``--json`` prints one JSON object.

A shot that gives no view — unreadable, another size than the model's images, no board, too
few corners, corners on one line, blurred — is one line on stderr naming it and the reason,
and the others are used. Exit 0 with a camera matrix; 2 on bad input (one line): a bad
model, board label or store, or fewer than 3 usable views.
"""

from __future__ import annotations

import json
from pathlib import Path

from station.cli.commands import COMMANDS
from station.cli.say import say, warn
from station.cli.store_options import add_store_options, open_store
from station.errors import HarpError
from station.exit_codes import EXIT_OK
from station.files import describe_os_error, write_profile
from station.tables import is_terminal, print_table


def register(subparsers) -> None:
    p = subparsers.add_parser("intrinsics", help=COMMANDS["intrinsics"], description=__doc__.split("\n\n")[1])
    p.add_argument(
        "inputs",
        metavar="MODEL BOARD_SHOT",
        nargs="*",
        help="the harp model file, then the board shots (--id: shots only; --capture: no shots)",
    )
    p.add_argument(
        "--board",
        required=True,
        metavar="LABEL",
        help="charuco:NXxNY:SQUARE_MM:MARKER_MM[:DICT] (default dictionary DICT_5X5_100) or chessboard:NXxNY:SQUARE_MM",
    )
    p.add_argument("--id", type=int, default=None, metavar="N", help="keep the camera matrix with stored profile #N")
    p.add_argument("-o", "--out", metavar="FILE", help="write the model file with the camera matrix in it")
    p.add_argument("--skew", action="store_true", help="fit the skew too (off by default; no export format holds it)")
    p.add_argument("--min-corners", type=int, default=None, metavar="N", help="fewest corners of a view (default 8)")
    p.add_argument(
        "--max-edge-width",
        type=float,
        default=None,
        metavar="PX",
        help="a view whose board edges are wider is rejected as blurred (default 4 px)",
    )
    p.add_argument(
        "--capture",
        metavar="DIR",
        default=None,
        help="take the board shots with the station of --config (the board on a tilted wedge on the turntable, "
        "one view per --angles), saved into DIR",
    )
    p.add_argument(
        "--angles",
        default=None,
        metavar="DEG,DEG,...",
        help="turntable angles of the captured views (default 0,45,...,315)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_store_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from pipeline.board import MAX_EDGE_WIDTH_PX, MIN_CORNERS, parse_board  # defers numpy
    from pipeline.intrinsics import MIN_VIEWS  # defers cv2, numpy
    from station.intrinsics import measure_intrinsics  # defers cv2, numpy

    try:
        spec = parse_board(args.board)
    except ValueError as exc:
        raise HarpError(f"--board: {exc}") from None
    if args.id is not None and args.out:
        raise HarpError("give either -o FILE (a model file) or --id N (a stored profile), not both")
    min_corners = MIN_CORNERS if args.min_corners is None else args.min_corners
    max_width = MAX_EDGE_WIDTH_PX if args.max_edge_width is None else args.max_edge_width
    if min_corners < 4 or not max_width > 0:
        raise HarpError("--min-corners must be >= 4 and --max-edge-width > 0")
    profile = None
    store = None
    if args.capture is not None and args.config is None:
        raise HarpError("--capture needs --config CONFIG (the station that takes the board shots)")
    if args.id is None and not args.inputs:
        raise HarpError("give the harp MODEL file (or --id N) and the board shots")
    try:
        if args.id is None:
            from pipeline.model_file import read_model_file  # defers cv2, numpy, yaml
            from station.profile import Profile  # defers cv2, numpy, yaml

            model_path, shots = args.inputs[0], list(args.inputs[1:])
            profile = Profile.from_model_file(read_model_file(model_path))
            where = model_path
        else:
            shots = list(args.inputs)
            store = open_store(args, prog="harp intrinsics")
            profile = store.profile(args.id)
            if profile is None:
                raise HarpError(f"{store.location}: no profile #{args.id}; harp profile list shows the stored ones")
            where = f"profile #{args.id} of {store.location}"
    except ValueError as exc:  # a model file that cannot be read (a StoreError goes on: one line)
        raise HarpError(str(exc)) from None
    try:
        if args.capture is not None:
            if shots:
                raise HarpError("--capture takes the board shots itself: give no BOARD_SHOT")
            shots = _capture(args, spec, profile)
        if not shots:
            raise HarpError("no board shots given")
        run_ = measure_intrinsics(
            profile.model,
            profile.width,
            profile.height,
            shots,
            spec,
            distortion_from=where,
            skew=args.skew,
            min_corners=min_corners,
            max_edge_width_px=max_width,
        )
        for r in run_.rejected:
            say("harp intrinsics", f"{r.name}: rejected: {r.reason}")
        result = run_.result
        if not result:
            got = len(run_.views)
            reason = (
                f"only {got} usable board views of {len(shots)} (at least {MIN_VIEWS} needed)"
                if got < MIN_VIEWS
                else result.reason
            )
            raise HarpError(f"{reason}; nothing written")
        for w in result.warnings:
            warn("harp intrinsics", w)
        if args.out:
            write_profile(args.out, profile.with_(intrinsics=result))
        elif store is not None:
            store.set_intrinsics(args.id, result)
    finally:
        if store is not None:
            store.close()
    _report(args, run_, result)
    return EXIT_OK


def _capture(args, spec, profile):
    """The board shots taken by the station of ``--config``; a :class:`HarpError` (one line) on failure."""
    from drivers.errors import DriverError  # defers numpy (the drivers package)
    from station.config import load_config  # defers yaml
    from station.config.schema import DEFAULT_BOARD_ANGLES  # defers yaml
    from station.session.boards import capture_board_shots  # defers cv2, numpy

    try:
        angles = (
            DEFAULT_BOARD_ANGLES
            if args.angles is None
            else tuple(float(a) for a in args.angles.split(",") if a.strip())
        )
    except ValueError:
        raise HarpError(f"--angles {args.angles!r}: expected degrees separated by commas, e.g. 0,45,90") from None
    if len(angles) < 3:
        raise HarpError("--angles: at least 3 views")
    try:
        config = load_config(args.config)
        focus = profile.focus
        note = (lambda text: None) if args.json else (lambda text: say("harp intrinsics", text))
        if focus is None:
            note("the profile records no focus setting: the board shots at the camera's own focus")
        return capture_board_shots(config, spec, args.capture, angles=angles, focus=focus, note=note)
    except DriverError as exc:  # a ConfigError goes on: one line
        raise HarpError(str(exc)) from None
    except OSError as exc:
        raise HarpError(describe_os_error(exc)) from None


def _report(args, run_, result) -> None:
    from pipeline.board import board_coverage  # defers numpy
    from pipeline.intrinsics import PARAMETERS  # defers cv2, numpy

    per_view = dict(zip(result.views, result.holdout_per_view))
    if args.json:
        doc = {
            "intrinsics": result.to_dict(),
            "views": [
                {
                    "path": v.name,
                    "corners": v.n,
                    "edge_width_px": v.edge_width_px,
                    "holdout_rms_px": per_view.get(v.name),
                }
                for v in run_.views
            ],
            "rejected": [{"path": r.name, "reason": r.reason} for r in run_.rejected],
            "coverage": board_coverage(list(run_.views), result.width, result.height).fraction,
            "written": args.out or (f"profile #{args.id}" if args.id is not None else None),
        }
        print(json.dumps(doc))
        return
    rows = [
        (v.name, str(v.n), f"{v.edge_width_px:.2f}", "-" if v.name not in per_view else f"{per_view[v.name]:.4f}")
        for v in run_.views
    ]
    cols = ("board shot", "corners", "edge width (px)", "held-out RMS (px)")
    print_table(cols, rows, title="board views", right=cols[1:])
    if not is_terminal():
        print()
    names = PARAMETERS if result.skew_fitted else PARAMETERS[:4]
    vals = dict(zip(PARAMETERS, (result.fx, result.fy, result.cx, result.cy, result.skew)))
    sds = dict(zip(PARAMETERS, result.sd))
    krows = [(n, f"{vals[n]:.4f}", f"{sds[n]:.4f}") for n in names]
    kcols = ("parameter", "value (px)", "standard deviation (px)")
    print_table(kcols, krows, title="camera matrix", right=kcols[1:])
    cov = board_coverage(list(run_.views), result.width, result.height)
    tilts = result.extra.get("view_tilts_deg") or []
    gaps = cov.missing()
    print(
        f"board corners reach {100 * cov.fraction:.0f} % of the image (8x6 cells)"
        + (f"; none in: {', '.join(gaps)}" if gaps else "")
        + (f"; views tilted {min(tilts):.0f}-{max(tilts):.0f} degrees" if tilts else "")
    )
    held = "-" if result.holdout_rms_px is None else f"{result.holdout_rms_px:.4f} px"
    print(
        f"{result.n_views} views, {result.n_points} corners: reprojection RMS {result.rms_px:.4f} px, "
        f"held-out views RMS {held}"
    )
    if args.out:
        print(f"wrote {Path(args.out)} (the model with its camera matrix)")
    elif args.id is not None:
        print(f"kept with profile #{args.id}: its exports use this camera matrix")
    else:
        print("not written (-o FILE writes the model file with it, --id N keeps it with a stored profile)")
