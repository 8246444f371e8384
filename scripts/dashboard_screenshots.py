"""Re-make the README's dashboard pictures (docs/dashboard-*.png) from a simulated lens population.

    .venv/bin/python scripts/dashboard_screenshots.py            # about 3 minutes on 2 cores

What it does, as a user would:

1. Runs ``harp session run`` (a subprocess each) for :data:`LENSES` simulated lenses of one lens
   model, serials ``LINE-0001`` ... on two stations (``line-1``, ``line-2``), with the demo
   configuration (``configs/demo.yaml``) at 640x480, focus 0 and 1, one frame per orientation,
   and ``simulation.lens_spread: 1`` — each serial its own unit of the demo lens, with the
   manufacturing spread of a production line (k1 spread, decentre, tilt, one bad unit in 20;
   ``drivers/sim/lens.py``). The line's QA spec (:data:`QA`): distortion magnitude <= 7.4 px at
   640x480 (the nominal lens: 6.9 px at focus 0) and holdout d <= 0.01 px, so the units whose
   k1 came out high fail on their distortion.
2. Stores their profiles in a new store, dated as if calibrated over four working days
   (:data:`FIRST_DAY`, three lenses a day, ``ProfileStore.put_profile(stored_at=...)``): the
   sessions themselves run now, one after the other; the dates only spread them so that the
   per-day bars and the date filter have days to show.
3. Serves it with ``harp serve --store`` (a subprocess on 127.0.0.1, any free port) and takes
   the pictures in headless Chromium (Playwright, ``tests/browser.py``): the lens list,
   one lens's page, the lens model's control charts.

Options: ``--out DIR`` (default ``docs``), ``--work DIR`` (kept; default a temporary directory,
removed), ``--lenses N``. Exit 0 when the pictures are written, 2 on an error (one line).
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

LENSES = 12
"""How many lenses (serial numbers) the population has."""
FIRST_DAY = dt.datetime(2026, 11, 23, 7, 30, tzinfo=dt.UTC)
"""The first calibration's time; three lenses a day from it."""
PER_DAY = 3
SIZE = (640, 480)
QA = {"max_holdout_d_px": 0.01, "max_distortion_px": 7.4}
"""The line's QA spec (px at 640x480)."""
STATIONS = ("line-1", "line-2")


def serial(i: int) -> str:
    return f"LINE-{i:04d}"


def station_config(work: Path, i: int) -> Path:
    """The configuration of lens ``i`` (1-based): the demo's, at the population's settings."""
    d = yaml.safe_load((REPO / "configs" / "demo.yaml").read_text())
    d["station"]["id"] = STATIONS[(i - 1) % len(STATIONS)]
    d["station"]["camera"].update(width=SIZE[0], height=SIZE[1])
    d["simulation"]["lens_spread"] = 1.0
    d["lens"]["serial"] = serial(i)
    d["focus"]["settings"] = [0.0, 1.0]
    d["capture"]["frames_per_orientation"] = 1
    d["pipeline"].update(bootstrap=3, workers=1)
    d["qa"] = dict(QA)
    d["store"] = {"path": "sessions.sqlite", "sessions_dir": "sessions"}
    path = work / f"{serial(i)}.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def run_sessions(work: Path, n: int) -> None:
    for i in range(1, n + 1):
        if (work / "sessions" / serial(i) / "results.json").is_file():
            print(f"{serial(i)}: session already run", file=sys.stderr)
            continue
        t = time.monotonic()
        cmd = [sys.executable, "-m", "station.cli", "session", "run", str(station_config(work, i))]
        r = subprocess.run([*cmd, "--name", serial(i), "--quiet", "--no-report"], cwd=work, stdin=subprocess.DEVNULL)
        if r.returncode not in (0, 1):  # 1: finished, FAIL (a lens out of spec)
            raise SystemExit(f"dashboard_screenshots: harp session run for {serial(i)} exited {r.returncode}")
        verdict = "PASS" if r.returncode == 0 else "FAIL"
        print(f"{serial(i)}: {verdict} in {time.monotonic() - t:.1f} s", file=sys.stderr)


def dated_store(work: Path) -> Path:
    """The population's store: every profile of the sessions' store, calibration ``i`` dated
    :data:`FIRST_DAY` + ``(i - 1) // PER_DAY`` days + 40 minutes per lens of that day."""
    from station.store import ProfileStore

    path = work / "population.sqlite"
    path.unlink(missing_ok=True)
    with ProfileStore(work / "sessions.sqlite", create=False) as src, ProfileStore(path) as dst:
        for p in sorted(src.profiles(), key=lambda p: p.id or 0):
            assert p.lens is not None
            i = int(p.lens.serial.rsplit("-", 1)[1])
            when = FIRST_DAY + dt.timedelta(days=(i - 1) // PER_DAY, minutes=40 * ((i - 1) % PER_DAY) + 2 * p.focus)
            dst.put_profile(p.with_(id=None), stored_at=when.isoformat())
    return path


def serve(store: Path) -> tuple[subprocess.Popen, str]:
    """``harp serve --store STORE --port 0`` in its own process group; its address."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "station.cli", "serve", "--store", str(store), "--port", "0"],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    assert proc.stderr is not None
    line = proc.stderr.readline()
    m = re.search(r"serving on (http://\S+)", line)
    if not m:
        stop(proc)
        raise SystemExit(f"dashboard_screenshots: harp serve did not start: {line.strip()}")
    return proc, m.group(1)


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def screenshots(url: str, out: Path) -> list[Path]:
    from playwright.sync_api import sync_playwright

    from tests.browser import CHROMIUM_FLAGS, chromium_path

    out.mkdir(parents=True, exist_ok=True)
    shots = []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(chromium_path()), args=CHROMIUM_FLAGS)
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        page.goto(url)
        page.wait_for_selector("#lenses tr.lens")
        shots.append(out / "dashboard-lenses.png")
        page.screenshot(path=str(shots[-1]), full_page=True)
        page.click('#lenses tr.lens[data-serial="LINE-0002"] a')
        page.wait_for_selector("#serial")
        for img in page.locator("img.plot").all():
            img.scroll_into_view_if_needed()
        page.wait_for_function(
            "() => [...document.querySelectorAll('img.plot')].every(i => i.complete && i.naturalWidth > 200)",
            timeout=300_000,
        )
        shots.append(out / "dashboard-lens.png")
        page.screenshot(path=str(shots[-1]), full_page=True)
        page.goto(url)
        page.click("#models tr.model a")
        page.wait_for_selector("#model-name")
        shots.append(out / "dashboard-model.png")
        page.screenshot(path=str(shots[-1]), full_page=True)
        browser.close()
    return shots


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=REPO / "docs", help="where the pictures go (default docs/)")
    ap.add_argument("--work", type=Path, default=None, help="keep the sessions and stores here (default: removed)")
    ap.add_argument("--lenses", type=int, default=LENSES, help=f"lenses in the population (default {LENSES})")
    args = ap.parse_args(argv)
    if args.lenses < 2:
        print("dashboard_screenshots: --lenses must be at least 2", file=sys.stderr)
        return 2
    work = args.work.resolve() if args.work else Path(tempfile.mkdtemp(prefix="harp-population-"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        run_sessions(work, args.lenses)
        store = dated_store(work)
        proc, url = serve(store)
        try:
            for shot in screenshots(url, args.out.resolve()):
                print(f"wrote {shot}", file=sys.stderr)
        finally:
            stop(proc)
    except SystemExit as exc:
        print(exc, file=sys.stderr)
        return 2
    finally:
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
