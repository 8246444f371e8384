"""The options of a command that serves a page (``harp live``, ``harp serve``): address, port, token.

Light on purpose (argparse and os only): it is imported when the ``harp`` parser is built.
"""

from __future__ import annotations

import argparse
import os

from station.cli.inputs import port_number


def add_serve_options(p: argparse.ArgumentParser, *, port: int, token_help: str) -> None:
    """``--host`` (default 127.0.0.1), ``--port`` (default ``port``; 0: any free port) and ``--token``
    (default ``$HARP_WEB_TOKEN``; ``token_help`` says what it guards)."""
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1)")
    p.add_argument(
        "--port", type=port_number, default=port, help=f"port to serve on (default {port}; 0: any free port)"
    )
    p.add_argument(
        "--token",
        default=os.environ.get("HARP_WEB_TOKEN"),
        help=f"{token_help} (needed for a --host other than 127.0.0.1; default $HARP_WEB_TOKEN)",
    )
