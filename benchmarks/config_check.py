"""How long ``harp config check`` takes, from a shipped configuration to the pathological plans of issue 25.

Usage::

    .venv/bin/python benchmarks/config_check.py

Each configuration is checked in this process as ``harp config check`` does (read, every key against its
declaration, across keys, the drivers created, the machine checks, the plan's estimate), best of three,
and printed as a Markdown table with the machine's load average (others' work slows it down). Before
issue 25 the 100000-orientation plan took 13.1 s to read (pure-Python YAML, composed and loaded twice)
and 7.6 s to estimate (every step of every focus setting walked).
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def _variant(root: Path, name: str, focus: list[float] | None = None, orientations: list[float] | None = None) -> Path:
    d = yaml.safe_load((REPO / "configs" / "demo.yaml").read_text())
    d["store"] = {"path": "p.sqlite", "sessions_dir": "sessions"}
    if focus is not None:
        d["focus"]["settings"] = focus
    if orientations is not None:
        d["capture"]["orientations_deg"] = orientations
    p = root / name
    p.write_text(yaml.safe_dump(d, default_flow_style=None))
    return p


def main() -> int:
    from station.config import load_config
    from station.config.check import check_config
    from station.session.estimate import long_plan

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        cases = [
            ("configs/demo.yaml (3 focus x 8 orientations)", REPO / "configs" / "demo.yaml"),
            ("configs/aravis-zaber.yaml", REPO / "configs" / "aravis-zaber.yaml"),
            ("1001 focus settings x 8 orientations", _variant(root, "f.yaml", focus=[i / 1000 for i in range(1001)])),
            ("3 focus x 100000 orientations", _variant(root, "o.yaml",
                                                       orientations=[round(i * 0.0036, 4) for i in range(100000)])),
        ]  # fmt: skip
        print("| configuration | file size | read + check (s) | estimate (s) | estimated plan |")
        print("| --- | --- | --- | --- | --- |")
        for label, path in cases:
            best_load, best_est, summary = float("inf"), float("inf"), ""
            for _ in range(3):
                t0 = time.perf_counter()
                config = load_config(path)
                check_config(config)
                t1 = time.perf_counter()
                long = long_plan(config)
                t2 = time.perf_counter()
                best_load, best_est = min(best_load, t1 - t0), min(best_est, t2 - t1)
                summary = long[1].split(": ")[-1] if long else "under 1 h (no warning)"
            size = path.stat().st_size
            print(f"| {label} | {size / 1024:.0f} KiB | {best_load:.3f} | {best_est:.3f} | {summary} |")
    print(f"\nload average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    return 0


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    sys.exit(main())
