"""The session's camera-matrix stage (the ``intrinsics`` section, issue 23) on the simulated station: the
camera renders the board with its own true camera matrix (``SimulatedCamera.camera_matrix``), the truth
the stored camera matrix is held against; a killed session resumes with the board views on disk."""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import shutil
from pathlib import Path

import pytest
import yaml

from drivers.sim.camera import SimulatedCamera
from pipeline.intrinsics import MIN_VIEWS
from pipeline.model_file import read_model_file
from station.cli import main
from station.config import load_config
from station.config.schema import BOARD_MIN_VIEWS
from station.session.directory import SessionDir
from station.session.executor import Executor
from station.session.records import BoardSaved, Record
from station.session.simulated import simulated_devices
from station.store import ProfileStore

REPO = Path(__file__).resolve().parents[3]
DEMO_K = REPO / "configs" / "demo-intrinsics.yaml"


def config_file(dirpath: Path, **changes) -> Path:
    """configs/demo-intrinsics.yaml with its store in ``dirpath`` (``changes``: top-level sections replaced)."""
    d = yaml.safe_load(DEMO_K.read_text())
    d["store"] = {"path": "profiles.sqlite", "sessions_dir": "sessions"}
    d.update(changes)
    dirpath.mkdir(parents=True, exist_ok=True)
    p = dirpath / "station.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def true_k(cfg) -> tuple[float, float, float, float]:
    """The simulated camera's own camera matrix (fx, fy, cx, cy): not from the code under test."""
    cam = cfg.station.camera.settings
    k = SimulatedCamera.from_config({"driver": "sim", "width": cam["width"], "height": cam["height"]}).camera_matrix()
    return (k[0, 0], k[1, 1], k[0, 2], k[1, 2])


def records(session: Path, kind: str) -> list[dict]:
    lines = (session / "manifest.jsonl").read_text().splitlines()
    return [r for r in map(json.loads, lines) if r["kind"] == kind]


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """The demo session, run once; its standard output (the summary table) kept."""
    base = tmp_path_factory.mktemp("k")
    cfg = config_file(base)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["session", "run", str(cfg), "--name", "s", "--no-report"])
    return code, load_config(cfg), base, base / "sessions" / "s", out.getvalue()


@pytest.fixture(scope="module")
def demo(demo_run):
    return demo_run[:4]


def test_every_profile_has_the_true_camera_matrix_within_its_two_sigma(demo):
    code, cfg, base, session = demo
    assert code == 0
    truth = true_k(cfg)
    with ProfileStore(base / "profiles.sqlite", create=False) as st:
        profiles = {p.focus: p for p in st.profiles()}
    assert sorted(profiles) == list(cfg.focus_settings)
    n = len(cfg.intrinsics.angles_deg)
    for f, focus in enumerate(cfg.focus_settings):
        k = profiles[focus].intrinsics
        assert k is not None and k.n_views == n
        z = [(got - t) / s for got, t, s in zip((k.fx, k.fy, k.cx, k.cy), truth, k.sd)]
        print(
            f"focus {focus:g}: K - truth in sigmas {[f'{v:+.2f}' for v in z]}, sigma {[f'{s:.2f}' for s in k.sd[:4]]}"
        )
        assert all(abs(v) <= 2 for v in z) and max(k.sd[:4]) < 2.0
        assert k.source.startswith(f"harp session, {n} charuco views of charuco:9x7:24:17")
        assert f"distortion held fixed from the session's fit of focus setting {focus:g}" in k.source
        assert k.distortion == profiles[focus].intrinsics.distortion  # measured with the stored distortion
        # the session's model file holds the same camera matrix (every export of it uses it)
        mf = read_model_file(session / "profiles" / f"focus{f}.yaml")
        assert mf.intrinsics is not None and mf.intrinsics.fx == k.fx
    saved = records(session, "board")
    assert sorted((r["focus_idx"], r["view_idx"]) for r in saved) == [
        (f, v) for f in range(len(cfg.focus_settings)) for v in range(n)
    ]
    for r in saved:
        assert hashlib.sha256((session / r["file"]).read_bytes()).hexdigest() == r["sha256"]
        assert abs(r["stage_deg"] - r["commanded_deg"]) < 0.05
    assert [r["focus_idx"] for r in records(session, "intrinsics")] == [0, 1]


def test_the_summary_has_the_stored_camera_matrix(demo_run):
    """The session's summary table (tab-separated off a terminal) shows each focus setting's camera
    matrix as the store holds it."""
    code, cfg, base, _session, out = demo_run
    assert code == 0
    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("focus\t"))
    header = lines[start].split("\t")
    assert header[-7:] == ["fx (px)", "fy (px)", "cx (px)", "cy (px)", "K sd max (px)", "board views", "profile"]
    rows = [dict(zip(header, line.split("\t"))) for line in lines[start + 1 : start + 1 + len(cfg.focus_settings)]]
    with ProfileStore(base / "profiles.sqlite", create=False) as st:
        profiles = {f"#{p.id}": p for p in st.profiles()}
    for row in rows:
        k = profiles[row["profile"]].intrinsics
        assert k is not None and float(row["focus"]) == profiles[row["profile"]].focus
        assert [float(row[f"{n} (px)"]) for n in ("fx", "fy", "cx", "cy")] == pytest.approx(
            [k.fx, k.fy, k.cx, k.cy], abs=0.006
        )
        assert float(row["K sd max (px)"]) == pytest.approx(max(k.sd[:4]), abs=6e-5)
        assert row["board views"] == str(len(cfg.intrinsics.angles_deg))


def test_a_damaged_board_view_of_a_stored_setting_is_found_and_said(demo, tmp_path, capsys):
    """``harp session resume`` checks the board views against the manifest too; a stored setting's view
    cannot be taken again by itself: repair says so and names --recapture."""
    _code, _cfg, _base, session = demo
    s = tmp_path / "s"
    shutil.copytree(session, s)
    board = next(r for r in records(s, "board") if (r["focus_idx"], r["view_idx"]) == (1, 2))
    (s / board["file"]).write_bytes((s / board["file"]).read_bytes()[:-1] + b"\0")
    assert main(["session", "resume", str(s)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        f"harp session: {s}: damaged: boards/f1_v2.png: checksum does not match the manifest; "
        f"run: harp session repair {s} (it says what cannot be re-derived)"
    )
    assert main(["session", "repair", str(s)]) == 2
    err = capsys.readouterr().err
    assert (
        "cannot re-derive: boards/f1_v2.png: checksum does not match the manifest: cannot be re-derived; the camera "
        f"matrix of focus setting 1 was measured from it and stays valid (the manifest keeps the checksum); to "
        f"capture that setting again: harp session repair {s} --recapture 1"
    ) in err, err


def test_the_plan_lists_the_board_views_after_each_fit(demo, capsys):
    _code, cfg, base, _session = demo
    assert main(["session", "plan", str(base / "station.yaml"), "--json"]) == 0
    steps = json.loads(capsys.readouterr().out)["steps"]
    whats = [(s["focus_idx"], s["what"]) for s in steps]
    n = len(cfg.intrinsics.angles_deg)
    for f in range(len(cfg.focus_settings)):
        mine = [w for g, w in whats if g == f]
        fit = next(i for i, w in enumerate(mine) if w.startswith("fit"))
        assert mine[fit + 1 : fit + 1 + n] == ["board view"] * n
        assert mine[fit + 1 + n] == f"camera matrix ({n} board views)"


class _KillAfter:
    """A subscriber that interrupts the session (as Ctrl-C does) once ``n`` board views are saved."""

    def __init__(self, n: int):
        self.n = n
        self.seen = 0

    def start(self, *args) -> None:
        return None

    def record(self, record: Record) -> None:
        if isinstance(record, BoardSaved):
            self.seen += 1
            if self.seen == self.n:
                raise KeyboardInterrupt

    def note(self, text: str) -> None:
        return None

    def finish(self, *args, **kwargs) -> None:
        return None


def test_interrupted_among_the_board_views_then_resumed(demo, tmp_path, capsys):
    """Stopped after 3 of the 6 board views of the first focus setting, then one of them damaged on disk: the
    resume says so, the repair has that one taken again, the resume keeps the other 2 (not taken again), takes
    the rest and gives the camera matrix of the uninterrupted session."""
    _code, _cfg, base, reference = demo
    cfg = load_config(config_file(tmp_path, focus={"settings": [0.0]}))
    with simulated_devices(cfg) as sim, SessionDir.create(cfg.sessions_dir, cfg, name="r") as s:
        sim.camera.open()
        sim.turntable.open()
        with pytest.raises(KeyboardInterrupt):
            Executor(s, sim.camera, sim.turntable, subscribers=[_KillAfter(3)], sleep=lambda _s: None).run()
    session = cfg.sessions_dir / "r"
    before = {r["view_idx"]: r["sha256"] for r in records(session, "board")}
    assert sorted(before) == [0, 1, 2] and not records(session, "stored")
    # a board view damaged on disk: found before anything is taken again, and repair has it taken again
    damaged = session / "boards" / "f0_v1.png"
    damaged.write_bytes(damaged.read_bytes()[:-1] + b"\0")
    assert main(["session", "resume", str(session), "--quiet", "--no-report"]) == 2
    assert capsys.readouterr().err.strip() == (
        f"harp session: {session}: damaged: boards/f0_v1.png: checksum does not match the manifest; "
        f"run: harp session repair {session}"
    )
    assert main(["session", "repair", str(session)]) == 0
    assert (
        "repaired: boards/f0_v1.png: checksum does not match the manifest: the board view will be taken again by "
        "harp session resume"
    ) in capsys.readouterr().err
    assert main(["session", "resume", str(session), "--quiet", "--no-report"]) == 0
    after = records(session, "board")
    # each view taken once, the damaged one again (attempt 1, its own file)
    assert [(r["view_idx"], r.get("attempt", 0)) for r in after] == [(0, 0), (1, 0), (2, 0), (1, 1), (3, 0), (4, 0),
                                                                      (5, 0)]  # fmt: skip
    assert after[3]["file"] == "boards/f0_v1_a1.png"
    after = [r for r in after if (r["view_idx"], r.get("attempt", 0)) != (1, 0)]
    assert {r["view_idx"]: r["sha256"] for r in after if r["view_idx"] in before} == before
    ref = {r["view_idx"]: r["sha256"] for r in records(reference, "board") if r["focus_idx"] == 0}
    assert {r["view_idx"]: r["sha256"] for r in after} == ref  # the same frames as the uninterrupted session
    with ProfileStore(tmp_path / "profiles.sqlite", create=False) as st:
        (p,) = st.profiles()
    with ProfileStore(base / "profiles.sqlite", create=False) as st:
        q = next(x for x in st.profiles() if x.focus == 0.0)
    assert p.intrinsics is not None and q.intrinsics is not None
    assert p.intrinsics.matrix == pytest.approx(q.intrinsics.matrix, abs=1e-6)


@pytest.mark.parametrize(
    ("section", "field", "says"),
    [
        ({"board": "charuco:9x7"}, "intrinsics.board", "expected a board label"),
        ({"board": "charuco:9x7:24:17", "angles_deg": [0, 120, 240], "min_views": 4}, "intrinsics.min_views",
         "expected at most one view per angle"),
        ({"board": "charuco:9x7:24:17", "angles_deg": [0, 90, 400]}, "intrinsics.angles_deg[2]",
         "expected an angle in [0, 360)"),
        ({"angles_deg": [0, 90, 180]}, "intrinsics.board", "missing"),
        ({"board": "charuco:9x7:24:17", "angles_deg": [0, 90]}, "intrinsics.angles_deg", "at least 3 numbers"),
    ],
)  # fmt: skip
def test_a_bad_intrinsics_section_is_one_line_and_exit_2(tmp_path, capsys, section, field, says):
    cfg = config_file(tmp_path, intrinsics=section)
    assert main(["session", "run", str(cfg), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{cfg}: {field}: " in err[0] and says in err[0], err
    assert not (tmp_path / "sessions").exists()


def test_a_camera_that_cannot_be_shown_the_board_is_refused(tmp_path, capsys):
    d = yaml.safe_load((REPO / "configs" / "v4l2-grbl.yaml").read_text())
    d["intrinsics"] = {"board": "charuco:9x7:24:17"}
    p = tmp_path / "v4l2.yaml"
    p.write_text(yaml.safe_dump(d))
    assert main(["config", "check", str(p)]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{p}: intrinsics: expected a camera the station can show the board" in err and "\n" not in err
    assert "the operator places the board (intrinsics.placement: operator)" in err
    d["intrinsics"]["placement"] = "operator"  # the views asked of the operator: any camera will do
    p.write_text(yaml.safe_dump(d))
    assert main(["config", "check", str(p)]) == 0, capsys.readouterr().err


def test_the_schema_minimum_is_the_fit_minimum():
    assert BOARD_MIN_VIEWS == MIN_VIEWS
