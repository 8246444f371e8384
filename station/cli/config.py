"""``harp config check CONFIG... [--json]``: validate station configurations, opening nothing.

Every field is checked against its declaration (:func:`station.config.load_config`: type, unit and
range, written once beside the field), then what only the whole configuration tells
(:func:`station.config.check.check_config`: a camera that could lock focus on nothing, a
sessions_dir that is a file are errors; a turntable port missing on this machine, a store
directory that cannot be created, strings along the pixel grid at some turntable angle are warnings) and the plan's
estimated duration (:func:`station.session.estimate.long_plan`: a warning beyond an hour). Exit 0 when every
configuration is usable (warnings on stderr), 2 with one line naming the file and field for each
that is not.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from station.cli.commands import COMMANDS
from station.cli.say import say, warn
from station.exit_codes import EXIT_ERROR, EXIT_OK


def register(subparsers) -> None:
    p = subparsers.add_parser("config", help=COMMANDS["config"], description=__doc__.split("\n\n")[1])
    sub = p.add_subparsers(dest="config_command", metavar="ACTION")
    check = sub.add_parser("check", help="validate configurations without opening any device")
    check.add_argument("config", type=Path, nargs="+", metavar="CONFIG")
    check.add_argument("--json", action="store_true", help="print one JSON object (a list of them for several)")
    check.set_defaults(func=_check)
    p.set_defaults(func=lambda args: (p.print_help(sys.stderr), EXIT_ERROR)[1])


def _check(args) -> int:
    docs = [_check_one(path, args.json) for path in args.config]
    if args.json:
        print(json.dumps(docs[0] if len(docs) == 1 else docs, indent=1))
    return EXIT_OK if all(d["ok"] for d in docs) else EXIT_ERROR


def _check_one(path: Path, as_json: bool) -> dict:
    """Check one configuration: its lines printed, its JSON document returned."""
    from station.config import ConfigError, load_config  # defers numpy, yaml
    from station.config.check import check_config  # defers numpy, yaml
    from station.session.estimate import long_plan  # defers numpy, yaml

    try:
        config = load_config(path)
    except ConfigError as exc:
        return _fail(path, str(exc), [])
    checked = check_config(config)
    if checked.errors:
        return _fail(path, str(checked.errors[0]), checked.warnings)
    long = long_plan(config)
    warnings = [*checked.warnings, *([long[1]] if long else [])]
    for w in warnings:
        warn("harp config", w)
    summary = (
        f"{len(config.focus_settings)} focus settings x {len(config.capture.orientations)} orientations x "
        f"{config.capture.frames_per_orientation} frames; camera {config.station.camera.driver}, turntable "
        f"{config.station.turntable.driver}; lens {config.lens.label()}"
    )
    if not as_json:
        print(f"{config.path}: OK ({summary})")
    return {"config": str(config.path), "ok": True, "error": None, "warnings": warnings, "summary": summary}


def _fail(path: Path, message: str, warnings: list[str]) -> dict:
    say("harp config", message)
    return {"config": str(path), "ok": False, "error": message, "warnings": warnings}
