"""``harp live CONFIG``: the set-up assistant's page; ``harp live CONFIG --once [--json]``: one check.

``harp live CONFIG`` opens the configured camera and turntable (the simulated ones for a
configuration with a ``simulation`` section) and serves the live page on 127.0.0.1 (``--host``
other than the loopback address needs ``--token``); it runs until Ctrl-C (exit 130).

``harp live CONFIG --once`` captures one shot as the session would (``frames_per_orientation``
frames, averaged), runs the session's acceptance checks on it (exposure, string edges found,
string angle against the turntable's orientation) and prints one assessment: focus score,
exposure figures, strings found, coverage. ``--json`` prints it as one JSON object. Exit 0 when
the shot would pass the session's checks and the focus check (``capture.checks.max_edge_width_px``), 1 when not, 2 on an error (one line on stderr).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from station.cli.commands import COMMANDS
from station.cli.web_options import add_serve_options
from station.errors import HarpError, Interrupted
from station.exit_codes import EXIT_FAIL, EXIT_OK
from station.live.devices import apply_session_settings, check_once, live_station


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "live",
        help=COMMANDS["live"],
        description=__doc__.split("\n\n")[1] + "\n\n" + __doc__.split("\n\n")[2],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("config", type=Path, help="station configuration (YAML)")
    p.add_argument("--once", action="store_true", help="check one shot, print the assessment and exit (0 pass, 1 fail)")
    p.add_argument("--json", action="store_true", help="with --once: print the assessment as one JSON object")
    add_serve_options(p, port=8013, token_help="token the page requires")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from station.config import load_config  # defers numpy, yaml

    if args.json and not args.once:
        raise HarpError("--json needs --once (the live page is served, not printed)")
    config = load_config(args.config)  # a ConfigError or ServeError: one line (station.cli.main)
    if not args.once:
        from station.web.serve import check_bind  # defers jinja2, starlette, markupsafe

        check_bind(args.host, args.token)
    from drivers.errors import DriverError  # defers numpy
    from station.session.devices import open_station  # defers numpy, yaml

    try:
        with open_station(config) as (camera, turntable):
            if args.once:
                return _once(config, camera, turntable, args.json)
            return _serve(config, camera, turntable, args)
    except DriverError as exc:
        raise HarpError(str(exc)) from None


def _serve(config: Any, camera: Any, turntable: Any, args: argparse.Namespace) -> int:
    from station.live.web import live_app  # defers scipy, cv2, jinja2, starlette
    from station.web.serve import serve  # defers jinja2, starlette, markupsafe

    apply_session_settings(config, camera)
    with live_station(config, camera, turntable) as station:
        try:
            serve(live_app(station), host=args.host, port=args.port, token=args.token)
        except KeyboardInterrupt:
            raise Interrupted("stopped") from None
    return EXIT_OK


def _once(config: Any, camera: Any, turntable: Any, as_json: bool) -> int:
    out = check_once(config, camera, turntable)
    if as_json:
        print(json.dumps(out, allow_nan=False))
    else:
        _print_once(out)
    return EXIT_OK if out["pass"] else EXIT_FAIL


def _print_once(o: dict[str, Any]) -> None:
    a = o["assessment"]
    e = a["exposure"]

    def f(v: Any, d: int = 3) -> str:
        return "–" if v is None else f"{v:.{d}f}"

    lines = [
        f"verdict: {'PASS' if o['pass'] else 'FAIL'} (the session's checks and the focus check on "
        f"{o['frames_averaged']} averaged frame(s))",
        *[f"  problem: {p}" for p in o["problems"]],
        f"focus score {f(a['focus_score'])} /px (edge 10-90 % width {f(a['edge_width_px'], 2)} px) at focus {o['focus']}",
        f"exposure {o['exposure_us']:g} us, gain {o['gain_db']:g} dB: saturated {100 * e['saturated_fraction']:.2f} %,"
        f" dark {100 * e['dark_fraction']:.2f} %, dynamic range {e['dynamic_range']:.3f}",
        f"strings found {a['strings_found']} ({a['edges_found']} edges) at {f(a['angle_deg'], 1)} deg"
        f" (expected {o['expected_angle_deg']:.1f} deg at stage {f(o['stage_deg'], 2)} deg)",
        f"coverage of this orientation in two directions: {100 * a['coverage']['covered_fraction']:.0f} %"
        " (turn the harp: the fit needs edges in two directions everywhere, corners included)",
    ]
    print("\n".join(lines))
