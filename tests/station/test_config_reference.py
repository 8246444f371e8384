"""The configuration reference (issue 25): the README holds what the script prints, and the schema it is
printed from declares a type, a range and a meaning for every key."""

from __future__ import annotations

import sys
from pathlib import Path

from drivers import CAMERA_DRIVERS, TURNTABLE_DRIVERS, driver_settings
from drivers.settings import KINDS, REQUIRED, Setting
from station.config.reference import markdown, readme_block
from station.config.schema import Section, document

REPO = Path(__file__).resolve().parents[2]


def test_the_readme_holds_what_the_script_prints():
    # the script as a user runs it (its own process, killed with its group if it outlives the timeout)
    from tests.station.processes import run_process

    r = run_process([sys.executable, str(REPO / "scripts" / "config_reference.py")], cwd=REPO, timeout=120)
    assert r.returncode == 0, r.stderr
    printed = r.stdout
    assert printed == markdown()
    assert readme_block((REPO / "README.md").read_text(encoding="utf-8")) == printed, (
        "README.md's configuration reference is stale: run .venv/bin/python scripts/config_reference.py "
        "--write README.md"
    )


def _all_settings() -> list[tuple[str, Setting]]:
    out = list(document().leaves())
    for table in (CAMERA_DRIVERS, TURNTABLE_DRIVERS):
        for name in table:
            out += [(f"{name}.{k}", s) for k, s in driver_settings(table, name).items()]
    return out


def test_every_key_has_a_kind_a_meaning_and_a_range():
    settings = _all_settings()
    assert len(settings) > 100
    for where, s in settings:
        assert s.kind in KINDS and s.doc, where
        if s.kind in ("integer", "number", "numbers", "integers") and not s.choices:
            assert s.low is not None and s.high is not None and s.low < s.high, where


def test_the_document_has_the_keys_the_station_reads():
    # written out by hand: the keys the validator accepted before the schema declared them (issue 25),
    # none lost; the emulator's and the drivers' keys are checked with their tables
    station = {
        "station.id", "station.camera.driver", "station.turntable.driver", "station.harp.string_width_mm",
        "station.harp.string_spacing_mm", "station.harp.offset_deg", "station.harp.direction",
        "station.harp.shift_direction_deg", "capture.shift_positions_mm",  # issue 19: two turntable-axis places
        *(f"{part}.{k}" for part in ("lens", "camera_body") for k in ("maker", "model", "serial")),
        "lens.focal_mm", "lens.mount", "camera_body.pixel_pitch_um", "camera_body.sensor_width_mm",
        "camera_body.crop_factor", "focus.settings",
        *(f"capture.{k}" for k in ("orientations_deg", "frames_per_orientation", "exposure_us", "gain_db",
                                   "settle_s", "timeout_s", "move_timeout_s")),
        *(f"capture.checks.{k}" for k in ("min_lines", "angle_tolerance_deg", "max_saturated_fraction",
                                          "min_dynamic_range", "max_recaptures", "max_edge_width_px")),
        "capture.retries.attempts", "capture.retries.backoff_s",
        *(f"pipeline.{k}" for k in ("t", "model", "degree", "tangential", "prism", "center_prior", "bootstrap",
                                    "seed", "workers", "strings", "field", "choice_folds")),  # issue 19
        "qa.max_holdout_d_px", "qa.max_distortion_px", "qa.max_reference_deviation_px", "report.overlays",
        "store.path", "store.url", "store.sessions_dir", "simulation.harp_offset_deg",
        "simulation.lens_spread", "zoom.settings", "zoom.positions", "zoom.focal",  # issues 21 and 23
        "intrinsics.board", "intrinsics.angles_deg", "intrinsics.min_views", "intrinsics.skew",  # issue 23
        "intrinsics.placement", "intrinsics.views", "intrinsics.tilts_deg", "lens.aperture",  # issue 24
        "simulation.shift_direction_deg",  # issue 19: the shift axis
        "simulation.lens_field_px",  # issue 19: whole sessions on lenses with a residual field
        "simulation.lens_centre_sd_px",  # issue 19: a lens whose decentering moves between poses
        "capture.twin_deg",  # issue 19: an angle taken again, to tell a lens that moved
    }  # fmt: skip
    leaves = {p for p, _ in document().leaves() if not p.startswith("simulation.emulator.")}
    assert leaves == station
    from drivers.sim.zaber_emulator import SETTINGS

    assert {p for p, _ in document().leaves() if p.startswith("simulation.emulator.")} == {
        f"simulation.emulator.{k}" for k in SETTINGS
    }


def test_required_keys_are_the_fields_without_a_default():
    required = {p for p, s in document().leaves() if s.default is REQUIRED}
    assert required == {
        "station.id", "station.camera.driver", "station.turntable.driver", "station.harp.string_width_mm",
        "station.harp.string_spacing_mm", "lens.maker", "lens.model", "lens.serial", "camera_body.maker",
        "camera_body.model", "camera_body.serial", "focus.settings", "capture.orientations_deg",
        "capture.frames_per_orientation", "capture.exposure_us",
        "intrinsics.board",  # when the optional intrinsics section is given
    }  # fmt: skip


def test_the_reference_lists_every_key_with_its_range():
    text = markdown()
    for path, s in document().leaves():
        if path.startswith("simulation.emulator."):
            continue
        row = next(line for line in text.splitlines() if line.startswith(f"| `{path}` |"))
        assert s.range_text(with_unit=False) in row or s.kind == "text", (path, row)
    for name in CAMERA_DRIVERS:
        assert f"`station.camera` with `driver: {name}`" in text
        for key in driver_settings(CAMERA_DRIVERS, name):
            assert f"| `station.camera.{key}` |" in text
    sections = [s for s in _sections(document()) if s.drivers]
    assert {s.path for s in sections} == {"station.camera", "station.turntable"}


def _sections(sec: Section) -> list[Section]:
    out = [sec]
    for spec in sec.keys.values():
        if isinstance(spec, Section):
            out += _sections(spec)
    return out
