"""A zoom session: a zoom lens calibrated over focal length x focus, one ordinary session per focal length.

A configuration with ``zoom.settings: [F1, F2, ...]`` (focal lengths, mm) is a zoom session. It is
run as one ordinary session per focal length (every focus setting x every orientation, fitted, judged,
stored, reported, resumable like any session), each in ``ZOOMDIR/focal-<F>mm/``: its configuration is
the zoom configuration with ``zoom.focal: F`` instead of the settings and the camera's ``zoom`` set to
that focal length's zoom position (``zoom.positions``, default the focal lengths), written beside it
(``ZOOMDIR/focal-<F>mm.yaml``, relative paths resolved against the original's directory). The camera
drives its zoom when it opens (the simulator's zoom lens, V4L2 ``zoom_absolute``, GenICam ``Zoom``).
Each stored profile records its focal length (:attr:`station.profile.Profile.focal`), so the store
holds the lens per (focal, focus) and ``harp profile show LENS --zoom-mm F --focus D`` interpolates in
both (:mod:`pipeline.zoom`). ``ZOOMDIR/zoom-session.json`` names the parts; once every part has run,
``ZOOMDIR/zoom-results.json`` holds each part's exit code and results and the interpolation's
leave-one-out error per axis (:func:`pipeline.zoom.leave_one_out_by_axis`).

The exit code is the worst part's: 2 when a part stopped (the next parts are not run; ``harp
session resume ZOOMDIR`` goes on), else 1 when a part's verdict is FAIL, else 0.
"""

from __future__ import annotations

import datetime as _dt
import json
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from station.config import Config, load_config
from station.config.reader import load_yaml, read_config_text
from station.files import atomic_write_text
from station.qa.results import read_results

ZOOM_FILE = "zoom-session.json"
RESULTS_FILE = "zoom-results.json"


@dataclass(frozen=True)
class Part:
    """One focal length of a zoom session: its focal length, zoom position, directory and configuration file."""

    focal: float
    position: float
    name: str

    def config_path(self, root: Path) -> Path:
        return root / f"{self.name}.yaml"

    def session_path(self, root: Path) -> Path:
        return root / self.name


def parts_of(config: Config) -> list[Part]:
    """The parts of a zoom configuration, in the order of its ``zoom.settings``."""
    positions = config.zoom_positions or config.zoom_settings
    return [Part(float(f), float(p), f"focal-{f:g}mm") for f, p in zip(config.zoom_settings, positions)]


def is_zoom_session(path: Path) -> bool:
    return (Path(path) / ZOOM_FILE).is_file()


def part_config_text(config: Config, part: Part) -> str:
    """The configuration of one part: the zoom configuration's with ``zoom.focal`` and the camera's ``zoom``."""
    doc = load_yaml(read_config_text(config.path))
    doc["zoom"] = {"focal": part.focal}
    camera = doc["station"]["camera"]
    if isinstance(camera.get("zoom_controller"), dict):  # the lens controller's position (drivers.zoom_controller)
        camera["zoom_controller"] = {**camera["zoom_controller"], "zoom": part.position}
    else:
        camera["zoom"] = part.position
    head = (
        f"# part {part.name} of a zoom session (harp station): {config.path} at focal length {part.focal:g} mm\n"
        f"# (zoom position {part.position:g}); relative paths resolve against {config.base_dir}\n"
    )
    return head + yaml.safe_dump(doc, sort_keys=False)


def create(root: Path, config: Config, name: str | None = None) -> Path:
    """Make the zoom session's directory under ``root`` with its parts' configurations; returns it."""
    now = _dt.datetime.now(_dt.UTC)
    if name is None:
        stem = re.sub(r"[^A-Za-z0-9_.-]+", "-", config.lens.serial)
        name = f"{now:%Y%m%dT%H%M%SZ}-{stem}-zoom"
    path = Path(root) / name
    path.mkdir(parents=True, exist_ok=False)
    parts = parts_of(config)
    for part in parts:
        atomic_write_text(part.config_path(path), part_config_text(config, part))
    meta = {
        "format": 1,
        "created": now.isoformat(timespec="seconds"),
        "config_source": str(config.path),
        "base_dir": str(config.base_dir),
        "lens": [config.lens.maker, config.lens.model, config.lens.serial],
        "parts": [{"name": p.name, "focal": p.focal, "position": p.position} for p in parts],
    }
    atomic_write_text(path / ZOOM_FILE, json.dumps(meta, indent=1) + "\n")
    return path


def read_parts(root: Path) -> tuple[dict[str, Any], list[Part]]:
    """The zoom session file of ``root`` and its parts; ValueError (one line) when it cannot be read."""
    try:
        meta = json.loads((Path(root) / ZOOM_FILE).read_text())
        parts = [Part(float(p["focal"]), float(p["position"]), str(p["name"])) for p in meta["parts"]]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{Path(root) / ZOOM_FILE}: cannot read the zoom session ({exc})") from None
    return meta, parts


def part_config(root: Path, meta: dict[str, Any], part: Part) -> Config:
    """The part's configuration as written at creation (relative paths against the original's directory)."""
    return load_config(part.config_path(root), base_dir=meta["base_dir"])


def run_parts(
    root: Path, run_part: Callable[[Part, Config, Path], int], note: Callable[[str], None]
) -> tuple[int, list[dict[str, Any]]]:
    """Run (or resume) every part with ``run_part(part, config, session_path) -> exit code``; stops at
    the first part that stopped (exit 2 or 130). ``(exit code, per part {name, focal, exit_code})``."""
    meta, parts = read_parts(root)
    worst = 0
    done: list[dict[str, Any]] = []
    for part in parts:
        note(f"zoom session: focal length {part.focal:g} mm (zoom position {part.position:g}): {part.name}")
        code = run_part(part, part_config(root, meta, part), part.session_path(root))
        done.append({"name": part.name, "focal": part.focal, "exit_code": code})
        if code not in (0, 1):
            return code, done
        worst = max(worst, code)
    return worst, done


def zoom_results(
    root: Path, parts_done: list[dict[str, Any]], store: Any, lens: tuple[str, str, str]
) -> dict[str, Any]:
    """The zoom session's results: each part's, the current profiles of the lens by (focal, focus) and
    the leave-one-out interpolation error per axis; written to ``ZOOMDIR/zoom-results.json``."""
    from pipeline.zoom import leave_one_out_by_axis  # defers scipy, cv2

    per_part = []
    for d in parts_done:
        res = read_results(Path(root) / d["name"]) or {}
        per_part.append({**d, "verdict": res.get("verdict")})
    lens_id = store.find_lens("/".join(lens))[0]
    current = [p for p in store.latest_by_focus(lens_id) if p.focal is not None]
    settings = [
        {
            "focal": p.focal,
            "focus": p.focus,
            "profile_id": p.id,
            "holdout_d_px": p.merit.holdout_d,
            "verdict": p.qa.verdict if p.qa is not None else None,
        }
        for p in current
    ]
    loo: list[dict[str, Any]] = []
    sizes = {(p.width, p.height) for p in current}
    if len(current) >= 2 and len(sizes) == 1:
        ((w, h),) = sizes
        models = {(p.focal, p.focus): p.model for p in current}
        loo = [
            {"axis": e.axis, "focal": e.focal, "focus": e.focus, "rms_px": e.rms_px, "max_px": e.max_px}
            for e in leave_one_out_by_axis(models, w, h)
        ]
    out = {"zoom_session": str(root), "parts": per_part, "settings": settings, "leave_one_out": loo}
    atomic_write_text(Path(root) / RESULTS_FILE, json.dumps(out, indent=1) + "\n")
    return out
