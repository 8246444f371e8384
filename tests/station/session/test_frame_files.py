"""Frame files: every bit of every captured frame kept (PNG), older PGM sessions still read and resumed."""

import hashlib
from pathlib import Path

import numpy as np
import pytest
import yaml

from station.config import load_config
from station.files import atomic_write_bytes
from station.session import layout
from station.session.directory import SessionDir
from station.session.executor import EXIT_OK, Executor
from station.session.frame_files import PNG_SIGNATURE, decode_frame, decode_pgm, encode_frame, encode_pgm
from station.session.records import FrameSaved
from station.session.simulated import simulated_devices

DEMO = Path(__file__).resolve().parents[3] / "configs" / "demo.yaml"
W, H = 640, 480
ORIENTATIONS = [0, 45, 90, 135]


def small_config(dirpath: Path, bit_depth: int = 8) -> Path:
    """The demo station at test size: 1 focus x 4 orientations x 2 frames, 640x480."""
    d = yaml.safe_load(DEMO.read_text())
    d["station"]["camera"].update(width=W, height=H, spacing_px=40.0, bit_depth=bit_depth)
    d["focus"]["settings"] = [0.5]
    d["capture"]["orientations_deg"] = ORIENTATIONS
    d["capture"]["frames_per_orientation"] = 2
    d["pipeline"] = {"t": 30, "model": "radial", "degree": 2}
    d["store"] = {"path": "profiles.sqlite", "sessions_dir": "sessions"}
    dirpath.mkdir(parents=True, exist_ok=True)
    p = dirpath / "station.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


class RecordingCamera:
    """The simulated camera, keeping a copy of every image it hands out (the truth to compare with)."""

    def __init__(self, camera):
        self.camera = camera
        self.captured: list[np.ndarray] = []

    def __getattr__(self, name):
        return getattr(self.camera, name)

    def capture(self, timeout: float = 5.0):
        frame = self.camera.capture(timeout)
        self.captured.append(np.array(frame.image, copy=True))
        return frame


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("shape", [(1, 1), (3, 4), (7, 11), (480, 640)])
def test_every_bit_of_a_frame_comes_back(dtype, shape):
    rng = np.random.default_rng(11)
    top = np.iinfo(dtype).max
    img = rng.integers(0, top, size=shape, dtype=dtype, endpoint=True)
    img.flat[0], img.flat[-1] = top, 0  # both extremes
    data = encode_frame(img)
    assert data[:8] == PNG_SIGNATURE
    back = decode_frame(data)
    assert back.dtype == dtype and back.shape == shape and np.array_equal(back, img)


def test_a_frame_of_another_kind_is_refused():
    for bad in (np.zeros((4, 4), np.int16), np.zeros((4, 4, 3), np.uint8), np.zeros((4, 4), np.float32)):
        with pytest.raises(ValueError, match="a frame must be a 2-D uint8/uint16 array"):
            encode_frame(bad)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_pgm_frames_of_older_sessions_are_read(dtype):
    rng = np.random.default_rng(3)
    img = rng.integers(0, np.iinfo(dtype).max, size=(9, 13), dtype=dtype, endpoint=True)
    pgm = encode_pgm(img)
    assert pgm.startswith(b"P5\n13 9\n")
    assert np.array_equal(decode_frame(pgm), img) and np.array_equal(decode_pgm(pgm), img)


def test_a_damaged_frame_file_is_one_line():
    data = encode_frame(np.random.default_rng(5).integers(0, 255, size=(64, 64), dtype=np.uint8))
    for damaged, reason in (
        (data[: len(data) // 2], "truncated PNG frame"),
        (data[:40] + b"\0" * 400 + data[440:], "not a readable PNG frame"),
        (b"GIF89a" + bytes(40), "not a frame file"),
    ):
        with pytest.raises(ValueError) as exc:
            decode_frame(damaged)
        assert reason in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize("bit_depth", [8, 16])
def test_a_session_run_keeps_every_frame_bit(tmp_path, bit_depth):
    cfg = load_config(small_config(tmp_path, bit_depth))
    with simulated_devices(cfg) as sim, SessionDir.create(tmp_path / "sessions", cfg, name="s") as s:
        cam = RecordingCamera(sim.camera)
        cam.open()
        sim.turntable.open()
        result = Executor(s, cam, sim.turntable, sleep=lambda _s: None).run()
        assert result.exit_code == EXIT_OK, result.message
        saved = list(s.of_type(FrameSaved))
        back = [s.read_frame(r) for r in saved]
    assert len(saved) == len(cam.captured) == 2 * len(ORIENTATIONS)
    dtype = np.uint8 if bit_depth == 8 else np.uint16
    for rec, got, want in zip(saved, back, cam.captured):
        assert want.dtype == dtype and got.dtype == dtype and np.array_equal(got, want), rec.file
        data = (tmp_path / "sessions" / "s" / rec.file).read_bytes()
        assert rec.file.endswith(".png") and data[:8] == PNG_SIGNATURE
        # compressed, and still every bit (16-bit frames: the low bits are camera noise, barely compressible)
        assert len(data) < (0.8 if bit_depth == 8 else 0.95) * len(encode_pgm(want))
    if bit_depth == 16:
        assert max(int(w.max()) for w in cam.captured) > 255  # the 16-bit range is used, and kept


def test_a_session_written_with_pgm_frames_resumes(tmp_path):
    """A session an older version stopped after two orientations (PGM frames, as it wrote them)
    resumes: only the missing orientations are captured (as PNG), and the fit uses all frames."""
    cfg = load_config(small_config(tmp_path))
    old: dict[str, str] = {}
    with simulated_devices(cfg) as sim:
        sim.camera.open()
        sim.turntable.open()
        sim.camera.set_exposure(cfg.capture.exposure_us)
        sim.camera.set_gain(cfg.capture.gain_db)
        sim.camera.lock_focus(0.5)
        sim.turntable.home()
        with SessionDir.create(tmp_path / "sessions", cfg, name="old") as s:
            for o in (0, 1):
                sim.turntable.move_to(ORIENTATIONS[o] + 0.0)
                for i in range(2):
                    data = encode_pgm(np.asarray(sim.camera.capture().image))
                    rel = f"{layout.FRAMES}/f0_o{o}_a0_i{i}.pgm"  # the older layout's name
                    atomic_write_bytes(s.path / rel, data)
                    s.append(FrameSaved(0, o, i, 0, rel, hashlib.sha256(data).hexdigest(), {"stage_deg": o * 45.0}))
                    old[rel] = hashlib.sha256(data).hexdigest()
        with SessionDir.open(tmp_path / "sessions" / "old") as s:
            cam = RecordingCamera(sim.camera)
            result = Executor(s, cam, sim.turntable, sleep=lambda _s: None).run()
            assert result.exit_code == EXIT_OK, result.message
            saved = list(s.of_type(FrameSaved))
            back = {r.file: s.read_frame(r) for r in saved}
    assert len(cam.captured) == 4  # orientations 2 and 3 only
    assert sorted(r.file for r in saved if r.file.endswith(".png")) == [
        f"frames/f0_o{o}_a0_i{i}.png" for o in (2, 3) for i in (0, 1)
    ]
    for rel, sha in old.items():  # the old frames untouched, and read back exactly
        data = (tmp_path / "sessions" / "old" / rel).read_bytes()
        assert hashlib.sha256(data).hexdigest() == sha and np.array_equal(back[rel], decode_pgm(data))
    new = [back[f"frames/f0_o{o}_a0_i{i}.png"] for o in (2, 3) for i in (0, 1)]
    assert all(np.array_equal(a, b) for a, b in zip(new, cam.captured))
    (fit,) = result.focus
    assert fit.failure is None and len(fit.profile.merit.holdout.per_orientation_d) == 4
