"""A small real session directory for QA / report tests (test helper).

Frames are rendered through the demo's focus-dependent lens
(:func:`drivers.sim.lens.lens_for_focus`) and written with the session
directory's own API; each focus setting is measured and fitted as the executor
does it (:func:`station.calibration.calibrate_shots`, leave one orientation out)
and its profile written as the executor writes it. No turntable moves, so it takes
a few seconds instead of a session's minute.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from drivers.sim.lens import lens_for_focus
from pipeline.render import HarpScene, render_harp
from station.calibration import calibrate_shots
from station.config import load_config
from station.files import write_profile
from station.profile import Provenance
from station.session.directory import SessionDir
from station.session.processing import measure_shot

REPO = Path(__file__).resolve().parents[2]
W, H = 400, 300
FOCUS = (0.0, 0.5, 1.0)
ANGLES = (0.0, 45.0, 90.0, 135.0)
HARP_OFFSET = 5.0


def write_config(
    root: Path, *, qa: dict | None = None, focus=FOCUS, angles=ANGLES, pipeline: dict | None = None
) -> Path:
    d = yaml.safe_load((REPO / "configs" / "demo.yaml").read_text())
    d["station"]["camera"].update(width=W, height=H)
    d["focus"]["settings"] = list(focus)
    d["capture"]["orientations_deg"] = list(angles)
    d["capture"]["frames_per_orientation"] = 1
    d["pipeline"].update({"degree": 4, "bootstrap": 4, "workers": 1, **(pipeline or {})})
    d["qa"] = qa if qa is not None else {"max_holdout_d_px": 0.05, "max_distortion_px": 10.0}
    d["store"] = {"path": "profiles.sqlite", "sessions_dir": "sessions"}
    root.mkdir(parents=True, exist_ok=True)
    path = root / "station.yaml"
    path.write_text(yaml.safe_dump(d))
    return path


def build_session(
    root: Path,
    *,
    qa: dict | None = None,
    focus=FOCUS,
    angles=ANGLES,
    name: str = "s1",
    pipeline: dict | None = None,
    fitted: int | None = None,
) -> Path:
    """A finished session under ``root/sessions/name``; returns its path. ``pipeline``: keys of the
    configuration's ``pipeline`` section set. ``fitted``: only the first so many focus settings captured and
    fitted (a session stopped there, not finished)."""
    config = load_config(write_config(root, qa=qa, focus=focus, angles=angles, pipeline=pipeline))
    s = SessionDir.create(config.sessions_dir, config, name=name)
    with s:
        for fi, f in enumerate(config.focus_settings[:fitted]):
            lens = lens_for_focus(f, W, H)
            shots = []
            for oi, a in enumerate(config.capture.orientations_deg):
                scene = HarpScene(angle_deg=a + HARP_OFFSET, spacing_px=28.0, phase_px=3.0 * oi)
                img = render_harp(W, H, scene, lens=lens, noise_sigma=1.0, seed=100 * fi + oi).image
                s.write_frame(fi, oi, 0, img, {"stage_deg": a, "focus": f})
                shots.append(measure_shot(img.astype(float), config.pipeline))
            cal = calibrate_shots([list(sh.lines) for sh in shots], W, H, config.pipeline.spec, holdout="orientations")
            assert cal.failure is None, cal.failure
            write_profile(
                s.path / "profiles" / f"focus{fi}.yaml",
                cal.profile(W, H, provenance=Provenance(), focus=f, lens=config.lens, camera=config.camera_body),
            )
        if fitted is None:
            s.append({"kind": "finished"})
    return s.path
