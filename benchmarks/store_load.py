"""Many stations writing one profile store at once (issue 12 item 3): PostgreSQL and SQLite.

Usage::

    .venv/bin/python benchmarks/store_load.py [--pg-stations 8] [--sqlite-stations 3] [--sessions 1]

Starts a throw-away PostgreSQL server (Debian's ``postgresql``, tests/pg_server.py: initdb +
pg_ctl on a free loopback port) and, for each backend, N simulated stations at once — separate
processes, each a full ``harp session run`` (simulated camera, Zaber emulator on its own pty,
640x480, 1 focus x 3 orientations, no bootstrap) on its own lens serial, ``--sessions`` sessions
one after the other per station — all into one store. Then it checks that every profile and every
QA result is in the store exactly once and that no station's stderr mentions a locked database,
and prints a Markdown table: stations, sessions, wall time of the whole run, store writes, their
latency (p50 / p99 / max, seconds, from ``$HARP_STORE_TIMINGS``: each write transaction of a
session — the profile with its verdict, the verdict again after the session's QA — from its first
attempt to its commit, retries included; the one-off creation of the schema is not counted), retries, and the machine's load average (other
work on the machine slows sessions and writes down).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


WRITES = ("storing the profile", "recording the verdict", "recording the QA result")
"""The writes whose latency is reported (a session's; not the one-off schema creation at first open)."""


def _pct(values: list[float], q: float) -> float:
    """The q-quantile (nearest rank) of sorted values."""
    if not values:
        return float("nan")
    k = min(len(values) - 1, max(0, int(round(q * len(values) + 0.5)) - 1))
    return values[k]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pg-stations", type=int, default=8)
    ap.add_argument("--sqlite-stations", type=int, default=3)
    ap.add_argument("--sessions", type=int, default=1, help="sessions per station, one after the other")
    args = ap.parse_args()

    from tests.pg_server import postgres_server
    from tests.station.store.stations import check_exactly_once, run_stations

    rows = []
    with tempfile.TemporaryDirectory(prefix="harp-store-load-") as tmp, postgres_server() as pg:
        for backend, n in (("postgresql", args.pg_stations), ("sqlite", args.sqlite_stations)):
            if n <= 0:
                continue
            store = pg.create_database("load") if backend == "postgresql" else str(Path(tmp) / "load.sqlite")
            load_before = os.getloadavg()[0]
            run = run_stations(Path(tmp) / backend, store, n, sessions_per_station=args.sessions, timeout=3600)
            failed = [(k, e.strip()[-300:]) for k, (rc, e) in enumerate(zip(run.returncodes, run.stderr)) if rc]
            if failed:
                print(f"{backend}: stations failed: {failed}", file=sys.stderr)
                return 2
            locked = [e for e in run.stderr if "locked" in e.lower()]
            if locked:
                print(f"{backend}: 'locked' reached a station's stderr: {locked[0][-300:]}", file=sys.stderr)
                return 2
            counts = check_exactly_once(store, n, args.sessions)
            lat = sorted(w["seconds"] for w in run.writes if w["op"] in WRITES)
            rows.append(
                (
                    backend,
                    n,
                    n * args.sessions,
                    run.wall_s,
                    len(lat),
                    _pct(lat, 0.5),
                    _pct(lat, 0.99),
                    lat[-1] if lat else float("nan"),
                    sum(w["retries"] for w in run.writes if w["op"] in WRITES),
                    counts,
                    load_before,
                    os.getloadavg()[0],
                )
            )
    print(
        "| backend | stations | sessions | wall time (s) | store writes | write latency p50 (s) "
        "| p99 (s) | max (s) | retries | stored exactly once | load avg before / after |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for b, n, s, wall, nw, p50, p99, mx, retries, counts, l0, l1 in rows:
        once = f"{counts['profiles']} profiles, {counts['qa_results']} QA results"
        print(
            f"| {b} | {n} | {s} | {wall:.1f} | {nw} | {p50:.4f} | {p99:.4f} | {mx:.4f} | {retries} | {once} "
            f"| {l0:.1f} / {l1:.1f} |"
        )
    print(f"\n{os.cpu_count()} cores; each session: 640x480, 1 focus x 3 orientations x 1 frame, no bootstrap")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
