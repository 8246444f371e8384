"""``harp devices [--probe] [--json]``: the cameras and serial ports this machine has.

Lists V4L2 capture devices, GenICam cameras (Aravis) and serial ports
(:func:`drivers.discovery.discover`), each with the configuration snippet that would use it
(paste it under ``station.camera`` or ``station.turntable``). Serial ports are not written
to unless ``--probe`` is given (then each is asked whether it is a Zaber or GRBL device).
A listing that cannot run (Aravis not installed) is one line on stderr; the others are
still shown. Exit 0 (also when nothing is found), 2 on bad input.
"""

from __future__ import annotations

import json

from station.cli.commands import COMMANDS
from station.cli.say import say
from station.exit_codes import EXIT_OK
from station.tables import is_terminal, print_table


def register(subparsers) -> None:
    p = subparsers.add_parser("devices", help=COMMANDS["devices"], description=__doc__.split("\n\n")[1])
    p.add_argument("--probe", action="store_true", help="ask each serial port whether it is a Zaber or GRBL device")
    p.add_argument("--port", action="append", default=[], metavar="PORT", help="also list this port (repeatable)")
    p.add_argument("--include-fake", action="store_true", help="also list Aravis' own Fake camera")
    p.add_argument("--v4l2", default="/dev/video*", metavar="PATTERN", help="V4L2 device nodes to look at")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.set_defaults(func=run)


def _snippet(config: dict) -> str:
    """The configuration snippet on one line (YAML flow style)."""
    import yaml

    return yaml.safe_dump(config, default_flow_style=True, sort_keys=False).strip()


def run(args) -> int:
    from drivers.discovery import discover, list_serial_ports  # defers numpy
    from drivers.errors import DriverError  # defers numpy

    found = discover(probe_serial=args.probe, include_fake=args.include_fake, v4l2_pattern=args.v4l2)
    devices, problems = list(found.devices), list(found.problems)
    if args.port:
        known = {d.device for d in devices}
        try:
            extra = list_serial_ports(extra=args.port, probe=args.probe)
        except (DriverError, OSError, ImportError) as exc:
            problems.append(f"--port: not listed: {' '.join(str(exc).split())}")
            extra = []
        devices += [d for d in extra if d.device in args.port and d.device not in known]
    for p in problems:
        say("harp devices", p)
    if args.json:
        out = {
            "devices": [
                {
                    "kind": d.kind,
                    "driver": d.driver,
                    "device": d.device,
                    "description": d.description,
                    "config": d.config,
                    "details": d.details,
                    "problem": d.problem,
                }
                for d in devices
            ],
            "problems": problems,
            "probed": bool(args.probe),
        }
        print(json.dumps(out, indent=1))
        return EXIT_OK
    if not devices:
        say("harp devices", "no cameras or serial ports found")
        return EXIT_OK
    print_table(
        ("kind", "driver", "device", "description", "problem", "config snippet"),
        [(d.kind, d.driver or "", d.device, d.description, d.problem or "", _snippet(d.config)) for d in devices],
        title="devices on this machine",
    )
    if is_terminal() and not args.probe and any(d.kind == "serial port" and d.driver is None for d in devices):
        print("serial ports were not probed: `harp devices --probe` asks each for a Zaber or GRBL reply")
    return EXIT_OK
