"""A real headless browser for the tests: Debian's Chromium driven by Playwright.

``scripts/setup.sh`` installs Debian's ``chromium`` package (``/usr/bin/chromium``)
and the ``playwright`` Python package; Playwright never downloads a browser here
(``executable_path`` names the system one). The flags keep Chromium off the
network it cannot reach on a closed machine (background networking, component
updates, sync, QUIC) and let it run as root in a container (``--no-sandbox``).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

CHROMIUM_FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def chromium_path() -> Path:
    """The system Chromium binary (``HARP_CHROMIUM`` overrides)."""
    for cand in (os.environ.get("HARP_CHROMIUM"), shutil.which("chromium"), "/usr/bin/chromium"):
        if cand and Path(cand).is_file():
            return Path(cand)
    raise RuntimeError("Chromium not found: run scripts/setup.sh (apt-get install chromium) or set HARP_CHROMIUM")
