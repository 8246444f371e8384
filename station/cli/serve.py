"""``harp serve [--store PATH|URL | --config CONFIG] [--host H] [--port P] [--token T]``: the QA dashboard.

Serves the factory QA dashboard (:mod:`station.web.dashboard`) over the profile store, read
only: lens models with pass/fail counts per station and day, each lens's profiles per focus
setting with every QA check, plots and downloads in every export format, each lens model's
distortion and holdout d over its serial numbers with control limits, and the same data as JSON
(``/api/lenses``, ``/api/lenses/{serial}``, ``/api/profiles/{id}``, ``/api/model``).

It binds 127.0.0.1 unless ``--host`` says otherwise, and any other address needs ``--token`` (or
``$HARP_WEB_TOKEN``): every request must then carry it (open the address printed, with
``?token=...``, once). Runs until Ctrl-C (exit 130). Exit 2 on an error (a store that is not
there or cannot be read, an address that cannot be used): one line on stderr.
"""

from __future__ import annotations

import argparse
from typing import Any

from station.cli.commands import COMMANDS
from station.cli.store_options import add_store_options, open_store
from station.cli.web_options import add_serve_options
from station.errors import Interrupted
from station.exit_codes import EXIT_OK

DEFAULT_PORT = 8014


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "serve",
        help=COMMANDS["serve"],
        description=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_store_options(p)
    add_serve_options(p, port=DEFAULT_PORT, token_help="token every request must carry")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from station.web.serve import check_bind  # defers jinja2, starlette, markupsafe

    check_bind(args.host, args.token)  # a ServeError, StoreError or ConfigError: one line (station.cli.main)
    store = open_store(args, prog="harp serve")
    from station.web import serve  # defers jinja2, starlette, markupsafe
    from station.web.dashboard import dashboard_app  # defers cv2, jinja2, starlette, numpy

    try:
        store.lens_models()  # a store that cannot be read says so now, not on the first page
        serve(dashboard_app(store), host=args.host, port=args.port, token=args.token)
    except KeyboardInterrupt:
        raise Interrupted("stopped") from None
    finally:
        store.close()
    return EXIT_OK
