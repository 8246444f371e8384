"""A small archive of real sessions for the factory tests (harp reprocess, harp serve): test helper.

:func:`small_station` is the demo station at test size (2 focus settings x 4 orientations x 1
frame, 480x360, bootstrap 3, no fit pool); :func:`run_session` runs one real session on the
simulated station through the command line (Zaber emulator on a pty, simulated camera, QA and
the report), storing into the configuration's store.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
W, H = 480, 360
FOCUS = (0.0, 1.0)
ORIENTATIONS = (0, 45, 90, 135)


def small_station(
    root: Path, *, serial: str = "DEMO-0001", store: str = "profiles.sqlite", station: str = "line-1"
) -> Path:
    d = yaml.safe_load((REPO / "configs" / "demo.yaml").read_text())
    d["station"]["id"] = station
    d["station"]["camera"].update(width=W, height=H, spacing_px=36.0)
    d["lens"]["serial"] = serial
    d["focus"]["settings"] = list(FOCUS)
    d["capture"]["orientations_deg"] = list(ORIENTATIONS)
    d["capture"]["frames_per_orientation"] = 1
    d["capture"]["retries"] = {"attempts": 3, "backoff_s": 0.05}
    d["pipeline"].update(bootstrap=3, workers=1, degree=3)
    d["store"] = (
        {"path": store, "sessions_dir": "sessions"}
        if "://" not in store
        else {"url": store, "sessions_dir": "sessions"}
    )
    root.mkdir(parents=True, exist_ok=True)
    p = root / f"station-{serial}.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def run_session(config: Path, name: str, *, report: bool = False) -> Path:
    """Run one session of ``config`` named ``name`` (without its report unless ``report``); returns
    its directory (asserts it finished)."""
    from station.cli import main

    code = main(["session", "run", str(config), "--name", name, "--quiet", *([] if report else ["--no-report"])])
    assert code == 0, code
    return config.parent / "sessions" / name


@dataclass(frozen=True)
class Archive:
    """One real finished session of lens ``serial`` and the SQLite store it wrote."""

    root: Path
    config: Path
    session: Path
    store: Path
    serial: str


def build_archive(root: Path, serial: str = "DEMO-0001") -> Archive:
    """The factory tests' archive: one real session (module docstring) into ``root/profiles.sqlite``."""
    config = small_station(root, serial=serial)
    session = run_session(config, "s1")
    return Archive(root, config, session, root / "profiles.sqlite", serial)
