"""Measurements and uncertainty maps kept as .npz arrays in the session directory."""

import json

import numpy as np
import pytest

from drivers.sim.lens import lens_for_focus
from pipeline.measure import measure_image
from pipeline.render import HarpScene, render_harp
from pipeline.uncertainty import FieldUncertainty
from station.config import load_config
from station.session.directory import SessionDir, SessionError
from station.session.evidence import (
    byte_planes,
    from_byte_planes,
    measurement_arrays,
    measurement_from_arrays,
    uncertainty_arrays,
    uncertainty_from_arrays,
)
from tests.station.qa_session import write_config

W, H = 320, 240


@pytest.fixture(scope="module")
def measurement():
    img = render_harp(
        W,
        H,
        HarpScene(angle_deg=30.0, spacing_px=24.0, dust=2, dust_seed=1),
        lens=lens_for_focus(0.5, W, H),
        noise_sigma=1.0,
        seed=4,
    ).image
    return measure_image(img.astype(float), t=30)


def test_measurement_round_trips_exactly_through_a_session_file(measurement, tmp_path):
    m = measurement
    assert m.n_lines > 6
    s = SessionDir.create(tmp_path, load_config(write_config(tmp_path)), name="s")
    with s:
        saved = s.write_arrays("measurements/f0_o0_a0.npz", measurement_arrays(m))
        back = measurement_from_arrays(s.read_arrays(saved["file"], saved["sha256"]))
        (s.path / saved["file"]).write_bytes((s.path / saved["file"]).read_bytes()[:-1] + b"x")
        with pytest.raises(SessionError, match="checksum"):
            s.read_arrays(saved["file"], saved["sha256"])
    assert (back.width, back.height, back.t, back.d, back.d_max) == (m.width, m.height, m.t, m.d, m.d_max)
    assert back.n_strings == m.n_strings and back.dark_strings == m.dark_strings
    for a, b in zip(back.lines, m.lines):
        assert np.array_equal(a.points, b.points) and np.array_equal(a.raw_points, b.raw_points)
        assert a.raw_points.dtype == b.raw_points.dtype and a.raw_points.shape == b.raw_points.shape
        assert a.raw_points.tobytes() == np.asarray(b.raw_points).tobytes()  # every bit
        assert (a.string_id, a.polarity, a.rms, a.angle_deg) == (b.string_id, b.polarity, b.rms, b.angle_deg)
    assert back.rejected == m.rejected
    assert all(np.array_equal(a, b) for a, b in zip(back.rejected_points, m.rejected_points))


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int64, np.int32, np.uint8, np.uint16])
@pytest.mark.parametrize("shape", [(0,), (1,), (7,), (5, 2), (3, 4, 2)])
def test_byte_planes_keep_every_bit(dtype, shape):
    rng = np.random.default_rng(2)
    if np.dtype(dtype).kind == "f":
        a = rng.normal(size=shape).astype(dtype)
        if a.size > 3:
            a.flat[:3] = (np.nan, -0.0, np.inf)
    else:
        a = rng.integers(np.iinfo(dtype).min, np.iinfo(dtype).max, size=shape, dtype=dtype, endpoint=True)
    planes = byte_planes(a)
    assert planes.dtype == np.uint8 and planes.shape == (np.dtype(dtype).itemsize, a.size)
    back = from_byte_planes(planes, a.dtype.str, a.shape)
    assert back.dtype == a.dtype and back.shape == a.shape and back.tobytes() == a.tobytes()


def format1_arrays(m) -> dict:
    """The arrays an older version (format 1) wrote: every array as it is."""
    import dataclasses

    out = {}
    for i, ln in enumerate(m.lines):
        for f in dataclasses.fields(ln):
            v = getattr(ln, f.name)
            if isinstance(v, np.ndarray):
                out[f"line{i}_{f.name}"] = v
    for j, pts in enumerate(m.rejected_points):
        out[f"rejected{j}_points"] = np.asarray(pts, np.float64)
    meta = json.loads(str(measurement_arrays(m)["meta"]))
    meta["format"] = 1
    del meta["byte_planes"]
    out["meta"] = np.array(json.dumps(meta))
    return out


def test_a_measurement_of_format_1_is_read_and_the_new_file_is_smaller(measurement, tmp_path):
    m = measurement
    with SessionDir.create(tmp_path, load_config(write_config(tmp_path)), name="s") as s:
        old = s.write_arrays("measurements/old.npz", format1_arrays(m))
        new = s.write_arrays("measurements/new.npz", measurement_arrays(m))
        back = measurement_from_arrays(s.read_arrays(old["file"], old["sha256"]))
        sizes = [(s.path / r["file"]).stat().st_size for r in (old, new)]
    assert (back.d, back.d_max, back.n_lines) == (m.d, m.d_max, m.n_lines)
    assert all(a.raw_points.tobytes() == np.asarray(b.raw_points).tobytes() for a, b in zip(back.lines, m.lines))
    assert sizes[1] < 0.95 * sizes[0]  # 0.86 here; 0.72 on the demo session's


def test_a_file_from_an_incompatible_version_is_refused(measurement):
    arrays = measurement_arrays(measurement)
    meta = json.loads(str(arrays["meta"]))
    del meta["lines"][0]["polarity"]
    arrays["meta"] = np.array(json.dumps(meta))
    with pytest.raises(ValueError, match="polarity"):
        measurement_from_arrays(arrays)


def test_uncertainty_map_round_trips():
    xs, ys = np.linspace(0, W - 1, 5), np.linspace(0, H - 1, 4)
    std = np.arange(20, dtype=float).reshape(4, 5) / 1000
    u = FieldUncertainty(
        rms=0.01,
        max=0.019,
        xs=xs,
        ys=ys,
        std=std,
        n_boot=7,
        n_failed=1,
        resample="edges",
        model=None,
        failures=("diverged",),
    )
    back = uncertainty_from_arrays(uncertainty_arrays(u), model="m")
    assert np.array_equal(back.std, std) and np.array_equal(back.xs, xs) and back.model == "m"
    assert (back.rms, back.max, back.n_boot, back.n_failed, back.resample, back.failures) == (
        0.01,
        0.019,
        7,
        1,
        "edges",
        ("diverged",),
    )
