"""Many simulated stations writing one profile store at once: each a separate ``harp session run``
process (simulated camera, Zaber emulator on its own pty) calibrating its own lens serial.

Used by ``tests/station/store/test_load.py`` (small) and ``benchmarks/store_load.py`` (the issue's
8 stations into PostgreSQL, 3 into SQLite). Each process appends its store writes to a timings file
(``$HARP_STORE_TIMINGS``, :mod:`station.store.engine`); :func:`check_exactly_once` reads the store back.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[3]
DEMO = REPO / "configs" / "demo.yaml"


def station_config(dirpath: Path, store: str, serial: str, *, seed: int, focus=(0.5,), orientations=(0, 60, 120)):
    """A small demo station (640x480, one frame per orientation, no bootstrap, one process) whose
    store is ``store`` (path or URL) and whose lens is ``serial``."""
    d = yaml.safe_load(DEMO.read_text())
    d["station"]["id"] = f"station-{seed}"
    d["station"]["camera"].update(width=640, height=480, spacing_px=40.0, seed=seed)
    d["lens"]["serial"] = serial
    d["focus"]["settings"] = list(focus)
    d["capture"].update(orientations_deg=list(orientations), frames_per_orientation=1)
    d["pipeline"].update(bootstrap=0, workers=1)
    d["store"] = {"url" if "://" in store else "path": store, "sessions_dir": str(dirpath / "sessions")}
    dirpath.mkdir(parents=True, exist_ok=True)
    p = dirpath / "station.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


@dataclass
class LoadRun:
    """What one load run did: per-station exit codes and stderr, wall time, every store write."""

    returncodes: list[int]
    stderr: list[str]
    wall_s: float
    writes: list[dict]

    def latencies(self, op: str | None = None) -> list[float]:
        return sorted(w["seconds"] for w in self.writes if op is None or w["op"] == op)


def run_stations(
    root: Path, store: str, n: int, *, sessions_per_station: int = 1, focus=(0.5,), timeout: float = 600
) -> LoadRun:
    """Start ``n`` station processes at once, each running ``sessions_per_station`` sessions one
    after the other (lens serials ``LOAD-<station>-<session>``); wait for all."""
    root.mkdir(parents=True, exist_ok=True)
    timings = root / "store-timings.jsonl"
    timings.unlink(missing_ok=True)
    env = {**os.environ, "HARP_STORE_TIMINGS": str(timings)}
    configs = [
        [
            station_config(root / f"st{k}" / f"s{j}", store, f"LOAD-{k}-{j}", seed=k, focus=focus)
            for j in range(sessions_per_station)
        ]
        for k in range(n)
    ]
    # one shell per station: its sessions run in sequence, the stations at the same time
    scripts = [
        " && ".join(f"{sys.executable} -m station.cli session run {c} --quiet --no-report" for c in cfgs)
        for cfgs in configs
    ]
    start = time.monotonic()
    procs = [
        subprocess.Popen(["sh", "-c", s], cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for s in scripts
    ]
    outs = [p.communicate(timeout=timeout) for p in procs]
    wall = time.monotonic() - start
    writes = [json.loads(line) for line in timings.read_text().splitlines()] if timings.exists() else []
    return LoadRun([p.returncode for p in procs], [e for _o, e in outs], wall, writes)


def check_exactly_once(store: str, n: int, sessions_per_station: int, focus=(0.5,)) -> dict[str, int]:
    """Assert every station's every profile and session QA result is in the store exactly once
    (nothing lost, nothing doubled); return the counts."""
    from station.store import ProfileStore

    with ProfileStore(store, create=False) as st:
        profiles = st.profiles()
        qa = list(st.qa_results())
    expected = Counter({f"LOAD-{k}-{j}": len(focus) for k in range(n) for j in range(sessions_per_station)})
    got = Counter(p.lens.serial for p in profiles)
    assert got == expected, f"profiles per lens: {dict(got)} != {dict(expected)}"
    ids = {p.id for p in profiles}
    session_rows = Counter(r["profile_id"] for r in qa if r["origin"] == "session")
    assert set(session_rows) == ids and set(session_rows.values()) == {1}, "session QA results not once each"
    dup = Counter((r["profile_id"], r["origin"], r["session_dir"]) for r in qa)
    assert max(dup.values()) == 1, "a QA result stored twice"
    assert all(p.qa is not None for p in profiles), "a profile without its verdict"
    return {"profiles": len(profiles), "qa_results": len(qa), "lenses": len(got)}
