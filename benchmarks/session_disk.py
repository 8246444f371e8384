"""Disk use of the demo session, by kind of file: as written now, and in the earlier format.

Usage::

    .venv/bin/python benchmarks/session_disk.py [--config configs/demo.yaml]

Runs ``harp session run`` on the configuration (a copy whose profile store and sessions live
in a temporary directory) and sums the session directory's files by kind: frames, measured
edges, profiles, report overlays, the rest of the report, the rest. The "before" column is the
same session in the format written before issue 21 item 6, computed from these very files:
each frame as the binary PGM it was (:func:`station.session.frame_files.encode_pgm`), each
``.npz`` uncompressed (``np.savez``), each overlay a full-size PNG
(:func:`station.qa.overlay.render_overlay`). Every frame is checked to read back, bit for bit,
as the PGM it replaces holds it. Then ``harp qa SESSION --report DIR`` once per
``--overlays`` value, and the time a frame takes to encode, PNG against PGM.
"""

from __future__ import annotations

import argparse
import io
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

KINDS = ("frames", "measurements", "profiles", "report overlays", "report, other", "other")


def kind_of(rel: Path) -> str:
    top = rel.parts[0]
    if top == "frames":
        return "frames"
    if top == "measurements":
        return "measurements"
    if top == "profiles":
        return "profiles"
    if top == "report":
        return "report overlays" if rel.name.startswith("overlay_") else "report, other"
    return "other"


def sizes_now(session: Path) -> dict[str, int]:
    out: dict[str, int] = defaultdict(int)
    for p in session.rglob("*"):
        if p.is_file() and p.name != ".reserve":
            out[kind_of(p.relative_to(session))] += p.stat().st_size
    return out


def sizes_before(session: Path) -> dict[str, int]:
    """The same session in the earlier format (module docstring)."""
    from station.qa.overlay import render_overlay
    from station.qa.report import session_shots
    from station.session.directory import SessionDir
    from station.session.frame_files import decode_frame, encode_pgm
    from station.session.records import FrameSaved

    out: dict[str, int] = defaultdict(int)
    for p in session.rglob("*"):
        if not p.is_file() or p.name == ".reserve":
            continue
        rel = p.relative_to(session)
        kind = kind_of(rel)
        if kind == "frames":
            continue  # below, from the manifest
        if p.suffix == ".npz":
            with np.load(p, allow_pickle=False) as z:
                buf = io.BytesIO()
                np.savez(buf, **{k: z[k] for k in z.files})
            out[kind] += len(buf.getvalue())
        elif kind == "report overlays":
            continue  # below, drawn again full size
        else:
            out[kind] += p.stat().st_size
    import cv2

    with SessionDir.open(session) as s:
        for r in s.of_type(FrameSaved):
            img = s.read_frame(r)
            pgm = encode_pgm(img)
            assert np.array_equal(decode_frame(pgm), img), r.file  # every bit, as the PGM held it
            out["frames"] += len(pgm)
        for f in range(len(s.config.focus_settings)):
            for shot in session_shots(s, f, t=s.config.pipeline.t):
                ok, png = cv2.imencode(".png", render_overlay(np.asarray(shot.image, np.float32), shot.measurement))
                out["report overlays"] += len(png)
    return out


def mb(n: int) -> str:
    return f"{n / 1e6:.1f}"


def report_size(d: Path) -> tuple[int, int]:
    files = [p for p in d.rglob("*") if p.is_file()]
    return sum(p.stat().st_size for p in files), sum(1 for p in files if p.name.startswith("overlay_"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, default=REPO / "configs" / "demo.yaml")
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        d = yaml.safe_load(args.config.read_text())
        d["store"] = {"path": str(Path(tmp) / "profiles.sqlite"), "sessions_dir": str(Path(tmp) / "s")}
        cfg = Path(tmp) / "config.yaml"
        cfg.write_text(yaml.safe_dump(d))
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-m", "station.cli", "session", "run", str(cfg), "--quiet", "--name", "demo"],
            cwd=REPO,
            capture_output=True,
            text=True,
        )
        wall = time.perf_counter() - t0
        if proc.returncode not in (0, 1):
            print(proc.stderr, file=sys.stderr)
            return 1
        session = Path(tmp) / "s" / "demo"
        now, before = sizes_now(session), sizes_before(session)
        cam = d["station"]["camera"]
        n_frames = (
            len(d["focus"]["settings"]) * len(d["capture"]["orientations_deg"]) * d["capture"]["frames_per_orientation"]
        )
        print(
            f"## `harp session run {args.config.relative_to(REPO)}`: disk use by kind "
            f"({cam['width']}x{cam['height']}, {n_frames} frames, report overlays: "
            f"{d.get('report', {}).get('overlays', 'all')}; session {wall:.0f} s, exit {proc.returncode})\n"
        )
        print("| kind | before (MB) | now (MB) | now / before |")
        print("|:---|---:|---:|---:|")
        for k in KINDS:
            b, n = before.get(k, 0), now.get(k, 0)
            print(f"| {k} | {mb(b)} | {mb(n)} | {n / b:.2f} |" if b else f"| {k} | - | {mb(n)} | - |")
        tb, tn = sum(before.values()), sum(now.values())
        print(f"| **session** | **{mb(tb)}** | **{mb(tn)}** | **{tn / tb:.2f}** |\n")
        print("Every frame reads back bit for bit as the PGM it replaces held it (checked above).\n")

        print("## `harp qa SESSION --report DIR`\n")
        print("| --overlays | report (MB) | overlays kept | seconds |")
        print("|:---|---:|---:|---:|")
        for keep in ("all", "failed", "none"):
            out = Path(tmp) / f"qa-{keep}"
            t0 = time.perf_counter()
            r = subprocess.run(
                [sys.executable, "-m", "station.cli", "qa", str(session), "--report", str(out)]
                + ["--overlays", keep, "--no-record", "--store", str(Path(tmp) / "profiles.sqlite")],
                cwd=REPO,
                capture_output=True,
                text=True,
            )
            dt = time.perf_counter() - t0
            if r.returncode not in (0, 1):
                print(r.stderr, file=sys.stderr)
                return 1
            size, n = report_size(out)
            print(f"| {keep} | {mb(size)} | {n} | {dt:.0f} |")
        print()

        from station.session.directory import SessionDir
        from station.session.frame_files import encode_frame, encode_pgm
        from station.session.records import FrameSaved

        with SessionDir.open(session) as s:
            frames = [s.read_frame(r) for r in list(s.of_type(FrameSaved))[:8]]
        times = {}
        for name, enc in (("PGM", encode_pgm), ("PNG", encode_frame)):
            t0 = time.process_time()
            n = sum(len(enc(f)) for f in frames)
            times[name] = ((time.process_time() - t0) / len(frames), n / len(frames))
        print("| frame file | CPU seconds per frame | bytes per frame |")
        print("|:---|---:|---:|")
        for name, (sec, size) in times.items():
            print(f"| {name} | {sec:.3f} | {size:.0f} |")
        print(f"\nload average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
