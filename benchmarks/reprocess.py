"""Re-processing an archive (issue 12 item 6): sessions per minute, local pool vs Dask LocalCluster.

Usage::

    .venv/bin/python benchmarks/reprocess.py [--sessions 6] [--workers 2] [--width 640 --height 480]
        [--focus 2] [--orientations 4] [--frames 1] [--bootstrap 4] [--archive DIR]

First records an archive: ``--sessions`` real sessions of the simulated demo station (``harp session
run`` without its report: simulated camera, Zaber emulator on a pty; each its own lens serial) at
the size given — or reuses the archive in ``--archive DIR`` when it holds them. Then re-processes
the whole archive with ``harp reprocess`` as a separate process (whole-process wall time: start,
imports, planning, every job, storing into a fresh SQLite store, the table):

* on the local process pool (``--workers N``);
* on a Dask ``LocalCluster`` of N worker processes with one thread each (``--scheduler``), started
  before the command (its start-up time is its own column), twice: workers cold (their first
  imports of numpy, scipy, OpenCV and the pipeline count) and warm (a cluster that has already
  worked, as a standing one is); then the same on a cluster whose workers start without Dask's
  ``MALLOC_TRIM_THRESHOLD_=65536`` (``distributed.nanny.pre-spawn-environ: {}``): that setting
  returns freed memory to the system at once, and the pipeline's many large temporary arrays then
  cost page faults each time;
* on the local pool again (the machine's other work changes while the benchmark runs: the two
  local runs say by how much).

Each run's profiles are checked to be the same as the local pool's (every figure of every focus
setting); "jobs per worker" says how the jobs were spread over the worker processes and "job s" is
the sum of the jobs' own wall times (their work, without start-up and scheduling). Prints a Markdown table and the machine's load average (other work on the machine slows
every run down).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
HARP = [sys.executable, "-m", "station.cli"]


def _config(root: Path, serial: str, args: argparse.Namespace) -> Path:
    d = yaml.safe_load((REPO / "configs" / "demo.yaml").read_text())
    d["station"]["id"] = "bench-line"
    d["station"]["camera"].update(width=args.width, height=args.height, spacing_px=0.075 * args.width)
    d["lens"]["serial"] = serial
    d["focus"]["settings"] = [round(i / max(args.focus - 1, 1), 3) for i in range(args.focus)]
    d["capture"]["orientations_deg"] = [i * 180.0 / args.orientations for i in range(args.orientations)]
    d["capture"]["frames_per_orientation"] = args.frames
    d["pipeline"].update(bootstrap=args.bootstrap, workers=1)
    d["store"] = {"path": "archive.sqlite", "sessions_dir": "sessions"}
    p = root / f"station-{serial}.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def _archive(root: Path, args: argparse.Namespace) -> list[Path]:
    root.mkdir(parents=True, exist_ok=True)
    sessions = []
    for i in range(args.sessions):
        name = f"bench-{i:03d}"
        d = root / "sessions" / name
        if not (d / "session.json").is_file() or '"finished"' not in (d / "manifest.jsonl").read_text():
            cfg = _config(root, f"BENCH-{i:04d}", args)
            t = time.perf_counter()
            subprocess.run([*HARP, "session", "run", str(cfg), "--name", name, "--quiet", "--no-report"], check=True)
            print(f"recorded {name} in {time.perf_counter() - t:.1f} s", file=sys.stderr, flush=True)
        sessions.append(d)
    return sessions


def _reprocess(sessions: list[Path], store: Path, extra: list[str]) -> tuple[float, dict]:
    t = time.perf_counter()
    p = subprocess.run(
        [*HARP, "reprocess", *map(str, sessions), "--store", str(store), "--json", *extra],
        capture_output=True,
        text=True,
    )
    wall = time.perf_counter() - t
    if p.returncode != 0:
        raise SystemExit(f"harp reprocess failed ({p.returncode}): {p.stderr.strip()}")
    return wall, json.loads(p.stdout)


def _figures(doc: dict) -> list[tuple]:
    keys = ("fit_d_px", "holdout_d_px", "holdout_d_max_px", "distortion_max_px", "field_uncertainty_rms_px", "verdict")
    return [(s["session"], e["focus"], *(e["new"][k] for k in keys)) for s in doc["sessions"] for e in s["focus"]]


def _spread(doc: dict) -> tuple[str, float]:
    """Jobs per worker process (most first) and the sum of the jobs' own seconds."""
    per: dict[str, int] = {}
    busy = 0.0
    for s in doc["sessions"]:
        for e in s["focus"]:
            per[e["worker"]] = per.get(e["worker"], 0) + 1
            busy += e["seconds"]
    return " + ".join(str(n) for n in sorted(per.values(), reverse=True)), busy


def _cluster_rows(sessions: list[Path], tmp: Path, args: argparse.Namespace, ref: dict, trim: bool) -> list[tuple]:
    """Cold and warm runs on a new LocalCluster: Dask's worker environment as it comes
    (``MALLOC_TRIM_THRESHOLD_=65536``), or without it (``trim=False``: glibc's own malloc)."""
    import dask
    from dask.distributed import LocalCluster

    rows = []
    what = "" if trim else ", no MALLOC_TRIM_THRESHOLD_"
    environ = dask.config.get("distributed.nanny.pre-spawn-environ") if trim else {}
    t = time.perf_counter()
    with (
        dask.config.set({"distributed.nanny.pre-spawn-environ": environ}),
        LocalCluster(
            n_workers=args.workers, threads_per_worker=1, processes=True, dashboard_address=":0", host="127.0.0.1"
        ) as cluster,
    ):
        start = time.perf_counter() - t
        for i, state in enumerate(("cold", "warm")):
            wall, doc = _reprocess(
                sessions, tmp / f"dask{int(trim)}{i}.sqlite", ["--scheduler", cluster.scheduler_address]
            )
            same = "same" if _figures(doc) == _figures(ref) else "DIFFERENT"
            shown = f"{start:.1f}" if state == "cold" else "(already up)"
            name = f"Dask LocalCluster, {args.workers} workers x 1 thread{what}, {state}"
            rows.append((name, shown, wall, same, *_spread(doc)))
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sessions", type=int, default=6)
    ap.add_argument("--workers", type=int, default=2, help="local pool processes = Dask worker processes")
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--focus", type=int, default=2, help="focus settings per session")
    ap.add_argument("--orientations", type=int, default=4)
    ap.add_argument("--frames", type=int, default=1, help="frames per orientation")
    ap.add_argument("--bootstrap", type=int, default=4)
    ap.add_argument("--archive", type=Path, default=None, help="keep (or reuse) the archive here")
    args = ap.parse_args()

    with tempfile.TemporaryDirectory(prefix="harp-reprocess-bench-") as tmp:
        root = args.archive or Path(tmp) / "archive"
        sessions = _archive(root, args)
        jobs = len(sessions) * args.focus
        print(subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
        print(
            f"re-processing {len(sessions)} sessions ({args.width}x{args.height}, {args.focus} focus x "
            f"{args.orientations} orientations x {args.frames} frame, bootstrap {args.bootstrap}; {jobs} jobs), "
            f"{os.cpu_count()} cores; whole-process wall time of `harp reprocess`\n"
        )
        rows = []
        wall, ref = _reprocess(sessions, Path(tmp) / "local.sqlite", ["--workers", str(args.workers)])
        rows.append((f"local process pool, {args.workers} processes", "–", wall, "same (reference)", *_spread(ref)))
        for trim in (True, False):
            rows += _cluster_rows(sessions, Path(tmp), args, ref, trim)
        wall, doc = _reprocess(sessions, Path(tmp) / "local2.sqlite", ["--workers", str(args.workers)])
        same = "same" if _figures(doc) == _figures(ref) else "DIFFERENT"
        rows.append((f"local process pool, {args.workers} processes, again", "–", wall, same, *_spread(doc)))
        print(
            "| runner | cluster start s | sessions | jobs | wall s | sessions/min | jobs per worker | job s (sum) "
            "| profiles vs local pool |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        for name, st, wall, same, spread, busy in rows:
            print(
                f"| {name} | {st} | {len(sessions)} | {jobs} | {wall:.1f} | {60 * len(sessions) / wall:.1f} "
                f"| {spread} | {busy:.1f} | {same} |"
            )
        print()
        print(subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
