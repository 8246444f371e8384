"""``harp config check CONFIG [--json]``: validate a station configuration, opening nothing.

Every field is checked (:func:`station.config.load_config`), then what only the whole
configuration tells (:func:`station.config.check.check_config`: a camera that could lock
focus on nothing is an error; a turntable port missing on this machine, a store directory
that cannot be created are warnings). Exit 0 when the configuration is usable (warnings on
stderr), 2 with one line naming the file and field when it is not.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from station.cli.commands import COMMANDS
from station.exit_codes import EXIT_ERROR, EXIT_OK


def register(subparsers) -> None:
    p = subparsers.add_parser("config", help=COMMANDS["config"], description=__doc__.split("\n\n")[1])
    sub = p.add_subparsers(dest="config_command", metavar="ACTION")
    check = sub.add_parser("check", help="validate a configuration without opening any device")
    check.add_argument("config", type=Path, metavar="CONFIG")
    check.add_argument("--json", action="store_true", help="print one JSON object")
    check.set_defaults(func=_check)
    p.set_defaults(func=lambda args: (p.print_help(sys.stderr), EXIT_ERROR)[1])


def _check(args) -> int:
    from station.config import ConfigError, load_config  # defers numpy, yaml
    from station.config.check import check_config  # defers numpy, yaml

    try:
        config = load_config(args.config)
    except ConfigError as exc:
        return _fail(args, str(exc), [])
    checked = check_config(config)
    if checked.errors:
        return _fail(args, str(checked.errors[0]), checked.warnings)
    for w in checked.warnings:
        print(f"harp config: warning: {w}", file=sys.stderr)
    summary = (
        f"{len(config.focus_settings)} focus settings x {len(config.capture.orientations_deg)} orientations x "
        f"{config.capture.frames_per_orientation} frames; camera {config.station.camera.driver}, turntable "
        f"{config.station.turntable.driver}; lens {config.lens.label()}"
    )
    if args.json:
        print(json.dumps({"config": str(config.path), "ok": True, "error": None, "warnings": checked.warnings,
                          "summary": summary}, indent=1))  # fmt: skip
    else:
        print(f"{config.path}: OK ({summary})")
    return EXIT_OK


def _fail(args, message: str, warnings: list[str]) -> int:
    print(f"harp config: {message}", file=sys.stderr)
    if args.json:
        print(json.dumps({"config": str(args.config), "ok": False, "error": message, "warnings": warnings}, indent=1))
    return EXIT_ERROR
