"""Whole simulated sessions with a twin: does the session tell a lens that moved between shots?

Usage::

    .venv/bin/python benchmarks/session_twins.py [--seeds 0,1,...] [--size 1000x750] [--workers 2]
        [--centre-sd 0,3,6]

``benchmarks/twins.py`` compares twins on rendered shots fitted as ``harp calibrate`` fits four photographs. This
runs the sessions themselves: ``harp session run`` on the simulated station of ``configs/demo.yaml`` with the
realistic camera (``realism_seed`` and the camera's ``seed`` 1000 + seed: bent and kinked strings, field blur, back-light, vignetting, noise, Bayer; one
frame per orientation), a unit of the demo lens drawn from each serial (``simulation.lens_spread: 1``), the session's
own defaults for everything the pipeline does (``model: auto``, ``strings: separate-kinks``, ``field: auto``) but the
bootstrap (0), at one focus setting (0.5): six turntable angles 0..150 by 30 and the twin ``capture.twin_deg: 30``,
taken last and not fitted.

Cameras: the lens's distortion centre moves between poses by N(0, SD) per axis (``simulation.lens_centre_sd_px``;
0: a stable lens); a return to a pose is another pose (:meth:`drivers.sim.camera.SimulatedCamera.set_capture_index`'s
``visit``). Per camera the table gives how often QA's ``twin_move`` failed the session (the move read beyond
:data:`station.moving_lens.TWIN_MOVE_PX`) against how often the move drawn is beyond it, the error of the move read
against the move drawn (truth: the distortion centres the simulator recorded in the two frames, their difference
across the strings at the recorded string angle), the largest move read on a stable lens, the twin's d under the
stored correction (a shot it was not fitted on) and the sessions' wall time (whole processes, two at once with
``--workers 2``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.two_place_sessions import config  # noqa: E402
from station.moving_lens import TWIN_MOVE_PX  # noqa: E402
from station.store import ProfileStore  # noqa: E402

CAPTURE = {"orientations_deg": [0.0, 30.0, 60.0, 90.0, 120.0, 150.0], "twin_deg": 30.0}


def drawn_move(session: Path) -> float:
    """The lens's move between the twin's two frames across their strings, from what the simulator recorded in
    each frame (its lens's distortion centre, the string angle)."""
    rows = [json.loads(ln) for ln in (session / "manifest.jsonl").read_text().splitlines() if ln.strip()]
    sims = {r["orientation_idx"]: r["meta"]["extra"]["sim"] for r in rows if r.get("kind") == "frame"}
    first, twin = sims[1], sims[len(sims) - 1]
    theta = np.radians(first["string_angle_deg"])
    move = np.subtract(twin["lens"]["center"], first["lens"]["center"])
    return float(np.dot(move, [-np.sin(theta), np.cos(theta)]))


def run(job: tuple[int, float, int, int]) -> dict[str, Any]:
    """One session: its exit code and wall time, the twin's record and QA check, and the move drawn."""
    seed, sd, w, h = job
    with tempfile.TemporaryDirectory(prefix="twins-") as tmp:
        root = Path(tmp)
        cfg = config(root, seed, CAPTURE, {}, w, h, serial=f"TWIN-{seed}", defaults=True)
        d = yaml.safe_load(cfg.read_text())
        d["simulation"]["lens_centre_sd_px"] = sd
        d["station"]["camera"]["seed"] = 1000 + seed  # the noise and each pose's lens move (the demo's: 7)
        cfg.write_text(yaml.safe_dump(d))
        t0 = time.perf_counter()
        done = subprocess.run(
            [str(REPO / ".venv" / "bin" / "harp"), "session", "run", str(cfg), "--quiet", "--no-report"],
            capture_output=True, text=True, cwd=root, start_new_session=True, check=False,
        )  # fmt: skip
        out: dict[str, Any] = {"seed": seed, "sd": sd, "wall": time.perf_counter() - t0, "code": done.returncode}
        if done.returncode not in (0, 1):
            out["error"] = (done.stderr.strip().splitlines() or ["?"])[-1]
            return out
        with ProfileStore(root / "profiles.sqlite") as st:
            (p,) = st.profiles()
        (session,) = (root / "sessions").iterdir()
        (twin,) = p.details["twins"]
        check = next(c for c in p.qa.checks if c.name == "twin_move")
        failed = [c.name for c in p.qa.checks if c.passed is False]
        out.update(
            drawn=drawn_move(session), read=float(twin["move_px"]), twin_d=twin.get("twin_d_px"),
            flagged=check.passed is False, failed=failed, model=p.spec.label if p.spec else "?",
        )  # fmt: skip
        return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default=",".join(str(s) for s in range(10)))
    ap.add_argument("--size", default="1000x750")
    ap.add_argument("--workers", type=int, default=2, help="sessions run at once")
    ap.add_argument("--centre-sd", default="0,3,6", help="the lens's centre moves between poses: SD px per axis")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    seeds = [int(s) for s in args.seeds.split(",")]
    sds = [float(s) for s in args.centre_sd.split(",")]
    print(
        f"# Whole simulated sessions with a twin (30 deg taken again last), {w}x{h}, focus 0.5 "
        f"({os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; "
        f"`benchmarks/session_twins.py {' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    jobs = [(s, sd, w, h) for sd in sds for s in seeds]
    with ThreadPoolExecutor(max(1, args.workers)) as pool:
        results = list(pool.map(run, jobs))
    print(
        f"| centre SD px | sessions | twin_move failed | drawn beyond {TWIN_MOVE_PX:g} px | flagged of those | "
        "false alarms | read - drawn RMS px | largest abs(read - drawn) px | largest abs(read) px | twin d median px "
        "| other QA failures | wall s median |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|")
    for sd in sds:
        rs = [r for r in results if r["sd"] == sd]
        ok = [r for r in rs if "error" not in r]
        if not ok:
            print(f"| {sd:g} | 0 of {len(rs)} |" + " |" * 10)
            continue
        err = np.array([abs(r["read"]) - abs(r["drawn"]) for r in ok])
        beyond = [r for r in ok if abs(r["drawn"]) > TWIN_MOVE_PX]
        false = [r for r in ok if r["flagged"] and abs(r["drawn"]) <= TWIN_MOVE_PX]
        others = sorted({n for r in ok for n in r["failed"] if n != "twin_move"})
        twin_d = [r["twin_d"] for r in ok if r["twin_d"] is not None]
        print(
            f"| {sd:g} | {len(ok)} of {len(rs)} | {sum(r['flagged'] for r in ok)} | {len(beyond)} | "
            f"{sum(r['flagged'] for r in beyond)} | {len(false)} | {np.sqrt(np.mean(err**2)):.3f} | "
            f"{np.max(np.abs(err)):.3f} | {max(abs(r['read']) for r in ok):.2f} | {np.median(twin_d):.4f} | "
            f"{', '.join(others) or 'none'} | {np.median([r['wall'] for r in ok]):.0f} |",
            flush=True,
        )
    for r in results:
        if "error" in r:
            print(f"\nseed {r['seed']}, centre SD {r['sd']:g}: failed (exit {r['code']}): {r['error']}")
    print()
    print("| centre SD px | seed | drawn px | read px | twin d px | model | QA failures |")
    print("|---:|---:|---:|---:|---:|---|---|")
    for r in results:
        if "error" not in r:
            print(
                f"| {r['sd']:g} | {r['seed']} | {r['drawn']:+.2f} | {r['read']:+.2f} | "
                f"{r['twin_d'] if r['twin_d'] is None else format(r['twin_d'], '.4f')} | {r['model']} | "
                f"{', '.join(r['failed']) or 'none'} |"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
