"""Session directory: atomic frames, durable manifest, torn-line tolerance."""

import json
from pathlib import Path

import numpy as np
import pytest

from station.config import load_config
from station.session.directory import (
    MANIFEST,
    SessionDir,
    SessionError,
    read_manifest,
    read_records,
)
from station.session.frame_files import decode_pgm, encode_pgm
from station.session.plan import frame_key, stored_key
from station.session.records import ShotMeasured, Stored

DEMO = Path(__file__).resolve().parents[3] / "configs" / "demo.yaml"


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_pgm_roundtrip(dtype):
    rng = np.random.default_rng(1)
    img = rng.integers(0, np.iinfo(dtype).max, size=(7, 11), dtype=dtype)
    back = decode_pgm(encode_pgm(img))
    assert back.dtype == dtype and np.array_equal(back, img)


def test_frames_and_manifest(tmp_path):
    cfg = load_config(DEMO)
    img = np.arange(12, dtype=np.uint8).reshape(3, 4)
    with SessionDir.create(tmp_path, cfg, name="s1") as s:
        rec = s.write_frame(0, 1, 0, img, {"exposure_us": 10.0})
        s.write_frame(0, 1, 1, img + 1)
        s.append({"kind": "stored", "focus_idx": 2})
        assert np.array_equal(s.read_frame(rec), img)
        assert not list((tmp_path / "s1" / "frames").glob(".*tmp*"))
    with SessionDir.open(tmp_path / "s1") as s:
        assert s.config.store_path == cfg.store_path  # relative paths keep their meaning
        assert s.done_keys() == {frame_key(0, 1, 0), frame_key(0, 1, 1), stored_key(2)}
        assert [r.frame_idx for r in s.frames(0, 1)] == [0, 1]
        assert s.lines[0]["meta"] == {"exposure_us": 10.0}


def test_records_read_back_typed_beside_the_lines_as_written(tmp_path):
    cfg = load_config(DEMO)
    img = np.zeros((3, 4), np.uint8)
    with SessionDir.create(tmp_path, cfg, name="s") as s:
        s.write_frame(0, 0, 0, img)
        s.append({"kind": "stored", "focus_idx": 0, "profile_id": 5, "model_file": "a.yaml", "future": 1})
        s.append(Stored(1, 6, "b.yaml"))
        s.append({"kind": "from-the-future"})
        s.append(ShotMeasured(0, 0, 0, 8, 1.0, 2.0, 3.0, "m0.npz", "ab"))
        s.append(ShotMeasured(0, 0, 0, 9, 1.5, 2.5, 3.5, "m1.npz", "cd"))
    with SessionDir.open(tmp_path / "s") as s:
        assert [r["kind"] for r in s.lines] == ["frame", "stored", "stored", "from-the-future", "measure", "measure"]
        assert s.lines[1]["future"] == 1  # every key as written
        assert [type(r).__name__ for r in s.typed] == ["FrameSaved", "Stored", "Stored", "ShotMeasured", "ShotMeasured"]
        assert all(r.t is not None for r in s.typed) and s.stored_ids() == {0: 5, 1: 6}
        assert s.last(ShotMeasured, focus_idx=0, orientation_idx=0).file == "m1.npz"
        assert s.last(ShotMeasured, focus_idx=1) is None and s.frames(0, 0)[0].file.endswith("_a0_i0.png")
    assert read_records(tmp_path / "s" / MANIFEST) == s.typed


def test_reject_supersedes_frames(tmp_path):
    cfg = load_config(DEMO)
    img = np.zeros((3, 4), np.uint8)
    with SessionDir.create(tmp_path, cfg, name="s") as s:
        s.write_frame(1, 2, 0, img)
        s.append({"kind": "reject", "focus_idx": 1, "orientation_idx": 2, "reasons": ["dark"]})
        assert s.frames(1, 2) == [] and s.done_keys() == set()
        rec = s.write_frame(1, 2, 0, img + 5)
        assert rec.attempt == 1 and rec.file.endswith("_a1_i0.png")
        assert s.done_keys() == {frame_key(1, 2, 0)}


def test_torn_last_line_is_dropped_and_cut(tmp_path):
    cfg = load_config(DEMO)
    img = np.zeros((3, 4), np.uint8)
    with SessionDir.create(tmp_path, cfg, name="s") as s:
        s.write_frame(0, 0, 0, img)
        s.write_frame(0, 0, 1, img)
    m = tmp_path / "s" / MANIFEST
    with open(m, "ab") as fh:
        fh.write(b'{"kind":"frame","focus_idx":0,"orientation_id')  # killed mid-write
    with SessionDir.open(tmp_path / "s") as s:
        assert len(s.lines) == 2
        s.write_frame(0, 0, 2, img)
    records, _ = read_manifest(m)
    assert [r["frame_idx"] for r in records] == [0, 1, 2]
    assert all(json.loads(line) for line in m.read_text().splitlines())


def test_corrupt_middle_line_is_an_error(tmp_path):
    cfg = load_config(DEMO)
    with SessionDir.create(tmp_path, cfg, name="s") as s:
        s.append({"kind": "x"})
    m = tmp_path / "s" / MANIFEST
    m.write_bytes(b"garbage\n" + m.read_bytes())
    with pytest.raises(SessionError, match="line 1: corrupt manifest record"):
        SessionDir.open(tmp_path / "s")


def test_checksum_detects_damaged_frame(tmp_path):
    cfg = load_config(DEMO)
    with SessionDir.create(tmp_path, cfg, name="s") as s:
        rec = s.write_frame(0, 0, 0, np.zeros((3, 4), np.uint8))
        p = tmp_path / "s" / rec.file
        p.write_bytes(p.read_bytes()[:-1] + b"\x07")
        with pytest.raises(SessionError, match="checksum"):
            s.read_frame(rec)


def test_one_process_per_session(tmp_path):
    cfg = load_config(DEMO)
    with SessionDir.create(tmp_path, cfg, name="s"):
        with pytest.raises(SessionError, match="in use"):
            SessionDir.open(tmp_path / "s")


def test_not_a_session(tmp_path):
    with pytest.raises(SessionError, match="not a session directory"):
        SessionDir.open(tmp_path)
