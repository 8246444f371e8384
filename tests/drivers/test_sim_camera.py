"""The simulated camera: Camera protocol, settings, focus-dependent lens, angle coupling, faults."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy import ndimage

import drivers
from drivers.errors import DeviceDisconnected, DeviceRejected, DeviceTimeout, DriverError, OutOfRange
from drivers.protocols import Camera, CameraIdentity, Frame
from drivers.sim.camera import SimulatedCamera
from drivers.sim.camera_settings import EXPOSURE_RANGE_US, GAIN_RANGE_DB
from drivers.sim.lens import K2, K4, TANGENTIAL, lens_for_focus
from drivers.sim.world import SimWorld
from pipeline.lens_population import UnitSpread
from pipeline.render import HarpScene, true_edge_curves
from tests.pipeline.scanline_fit import scanline_errors

SMALL = {"width": 480, "height": 360}


def string_angle(img: np.ndarray, crop: int = 300, sigma: float = 1.5) -> float:
    """Independent estimate: string direction from the structure tensor of a central crop.

    The dominant gradient direction (Gaussian-derivative gradients) is the
    normal of the strings; near the centre the lens is locally the identity.
    """
    h, w = img.shape
    y0, x0 = (h - crop) // 2, (w - crop) // 2
    a = img[y0 : y0 + crop, x0 : x0 + crop].astype(float)
    gx = ndimage.gaussian_filter(a, sigma, order=(0, 1))
    gy = ndimage.gaussian_filter(a, sigma, order=(1, 0))
    b = int(4 * sigma) + 1
    gx, gy = gx[b:-b, b:-b], gy[b:-b, b:-b]
    normal = 0.5 * np.degrees(np.arctan2(2 * (gx * gy).sum(), (gx * gx).sum() - (gy * gy).sum()))
    return float((normal + 90.0) % 180.0)


def test_satisfies_camera_protocol_and_opens_from_config():
    world = SimWorld()
    cam = drivers.open_camera({"driver": "sim", **SMALL, "bit_depth": 16, "seed": 5}, world=world)
    assert isinstance(cam, SimulatedCamera) and isinstance(cam, Camera)
    assert cam.world is world
    assert cam.sensor_size == (480, 360)
    assert cam.pixel_format == "Mono16"
    assert isinstance(cam.identity, CameraIdentity) and cam.identity.model == "SimulatedCamera"
    with cam as c:
        assert c is cam
        f0, f1 = cam.capture(), cam.capture()
    assert isinstance(f0, Frame)
    assert f0.image.shape == (360, 480) and f0.image.dtype == np.uint16
    assert (f0.counter, f1.counter) == (0, 1)
    assert abs(f0.timestamp - time.time()) < 60
    assert f0.camera == cam.identity and f0.focus == world.focus
    assert f0.exposure_us == cam.get_exposure() and f0.gain_db == cam.get_gain()
    assert not np.array_equal(f0.image, f1.image)  # second capture at the same pose: other noise
    with pytest.raises(DeviceDisconnected, match="not open"):
        cam.capture()
    # reopening restarts the counter and replays the same frames
    with cam:
        again = cam.capture()
    assert again.counter == 0 and np.array_equal(again.image, f0.image)


def test_noise_is_a_function_of_the_physical_situation():
    """Frames depend on (seed, focus, string angle, capture index at the pose), not on history,
    so a resumed session that captures only its missing frames gets the same pixels."""
    world = SimWorld(harp_offset_deg=5.0)
    cam = SimulatedCamera.from_config({"width": 96, "height": 64, "seed": 3}, world=world)

    def shoot(stage, focus, index=None):
        world.set_stage(stage)
        cam.lock_focus(focus)
        if index is not None:
            cam.set_capture_index(index)
        return cam.capture().image

    with cam:  # an uninterrupted run: two poses x two frames
        run = [shoot(0.0, 0.5), shoot(0.0, 0.5), shoot(45.0, 0.5), shoot(45.0, 1.0)]
    with cam:  # a fresh camera visiting the poses in another order, with detours
        late = shoot(45.0, 1.0)
        shoot(90.0, 0.5)
        second = shoot(0.0, 0.5, index=1)  # told which capture it is (the executor's hook)
        third = shoot(0.0, 0.5)  # the hook was used up: counting goes on after index 1
        first = shoot(0.0, 0.5, index=0)
    assert np.array_equal(late, run[3]) and np.array_equal(second, run[1])
    assert np.array_equal(first, run[0])
    assert not any(np.array_equal(third, im) for im in run)
    assert not np.array_equal(run[0], run[1]) and not np.array_equal(run[0], run[2])
    assert not np.array_equal(run[2], run[3])  # same angle, other focus
    with cam:  # a failed capture does not use the index up
        cam.set_capture_index(1)
        cam.fail_next(1, "timeout")
        with pytest.raises(DeviceTimeout):
            cam.capture(timeout=0.01)
        assert np.array_equal(shoot(0.0, 0.5), run[1])
    with pytest.raises(ValueError, match="non-negative"):
        cam.set_capture_index(-1)


def test_config_errors_name_the_key():
    with pytest.raises(ValueError, match="'exposure'"):
        SimulatedCamera.from_config({"driver": "sim", "exposure": 100})
    with pytest.raises(ValueError, match="'width'"):
        SimulatedCamera.from_config({"width": 640.5})
    with pytest.raises(ValueError, match="'pixel_format'"):
        SimulatedCamera.from_config({"pixel_format": "RGB8"})
    with pytest.raises(ValueError, match="'shot_noise'"):
        SimulatedCamera.from_config({"shot_noise": "yes"})
    with pytest.raises(ValueError, match="spacing_px"):
        SimulatedCamera.from_config({"spacing_px": 2.0})
    # each key against its declaration (drivers.settings: the range, the unit, the value)
    with pytest.raises(ValueError, match=r"config key 'focus': expected a number in \[0, 1\], got 7.0"):
        SimulatedCamera.from_config({"focus": 7.0})
    with pytest.raises(ValueError, match=r"config key 'exposure_us': expected a number in \[20, 1000000\] µs, got 5"):
        SimulatedCamera.from_config({"exposure_us": 5})
    with pytest.raises(ValueError, match=r"config key 'bit_depth': expected one of 8, 16, got 12"):
        SimulatedCamera.from_config({"bit_depth": 12})
    with pytest.raises(ValueError, match="needs best_focus"):
        SimulatedCamera.from_config({"defocus_blur_px": 3.0})
    cam = SimulatedCamera.from_config(
        {"pixel_format": "Mono8", "focus": 0.4, "harp_offset_deg": 7.0, "string_width_px": 8, "dust": 3}
    )
    assert cam.pixel_format == "Mono8" and cam.get_focus() == 0.4
    assert cam.world.harp_offset_deg == 7.0 and cam.scene.string_width_px == 8.0 and cam.scene.dust == 3
    assert cam.sensor_size == (1280, 960)


def test_exposure_and_gain_read_back_refuse_out_of_range_and_scale_brightness():
    cam = SimulatedCamera(width=320, height=240, noise_sigma=0.0, bit_depth=16)
    with pytest.raises(DriverError):
        cam.set_exposure(5000)  # not open
    with cam:
        assert cam.set_exposure(5000) == 5000 == cam.get_exposure()
        dim = cam.capture().image.astype(float)
        assert cam.set_gain(6.0) == 6.0 == cam.get_gain()
        gained = cam.capture().image.astype(float)
        assert cam.set_gain(0.0) == 0.0 and cam.set_exposure(10_000) == 10_000
        ref = cam.capture().image.astype(float)
        assert cam.exposure_range().minimum == EXPOSURE_RANGE_US[0] and cam.exposure_range().maximum == 1e6
        assert (cam.gain_range().minimum, cam.gain_range().maximum) == GAIN_RANGE_DB
        with pytest.raises(
            OutOfRange, match=r"^sim camera SIM-0001: exposure 1000000000 µs is outside the range \[20, 1000000\] µs"
        ):
            cam.set_exposure(1e9)
        for bad in (-3, 19.9, float("nan")):
            with pytest.raises(DeviceRejected, match="exposure"):
                cam.set_exposure(bad)
        for bad in (99, -1):
            with pytest.raises(OutOfRange, match=r"gain .* dB is outside the range \[0, 24\] dB"):
                cam.set_gain(bad)
        assert cam.get_exposure() == 10_000 and cam.get_gain() == 0.0  # nothing was changed
        assert cam.set_exposure(EXPOSURE_RANGE_US[0]) == 20.0 and cam.set_gain(GAIN_RANGE_DB[1]) == 24.0
        cam.set_gain(24.0)
        cam.set_exposure(1e6)
        saturated = cam.capture().image
    assert abs(dim.mean() / ref.mean() - 0.5) < 1e-3
    assert abs(gained.mean() / dim.mean() - 10 ** (6 / 20)) < 1e-3
    assert (saturated == 65535).mean() > 0.9


def test_focus_changes_the_lens_as_predicted():
    world = SimWorld(stage_deg=80.0)
    cam = SimulatedCamera(world, width=480, height=360, noise_sigma=0.0, bit_depth=16)
    with cam:
        assert cam.lock_focus(0.0) == 0.0 == cam.get_focus()
        near = cam.capture()
        r_near = cam.last_rendered
        with pytest.raises(OutOfRange, match=r"focus 1.7 is outside the range \[0, 1\] \(simulated lens"):
            cam.lock_focus(1.7)  # refused, not clamped
        assert world.focus == 0.0 and cam.focus_range().minimum == 0.0 and cam.focus_range().maximum == 1.0
        assert cam.lock_focus(1.0) == 1.0 == world.focus
        far = cam.capture()
        r_far = cam.last_rendered
    assert near.focus == 0.0 and far.focus == 1.0
    assert r_near.lens == lens_for_focus(0.0, 480, 360) and r_far.lens == lens_for_focus(1.0, 480, 360)
    assert near.extra["sim"]["lens"] == r_near.lens.to_dict()
    # the predicted edges differ between the two foci by a measurable amount ...
    pts = np.concatenate(true_edge_curves(r_near, margin=12))
    moved = r_far.lens.distort_points(r_near.lens.undistort_points(pts))
    assert np.hypot(*(moved - pts).T).max() > 0.2
    # ... and each frame's edges sit on its own focus's prediction, not on the other one's
    own = np.concatenate([scanline_errors(r_near), scanline_errors(r_far)])
    crossed = scanline_errors(r_far, truth=r_near)
    assert len(own) >= 40
    assert np.abs(own).max() < 0.005
    assert np.abs(crossed).max() > 0.1


@pytest.mark.parametrize("offset", [0.0, 12.5])
def test_string_angle_tracks_the_stage(offset):
    world = SimWorld(harp_offset_deg=offset)
    cam = SimulatedCamera.from_config({**SMALL, "seed": 11, "dust": 4}, world=world)
    with cam:
        cam.lock_focus(0.5)
        for stage in (0.0, 30.0, 45.0, 90.0, 137.0, 200.0, 315.0):
            world.set_stage(stage)
            frame = cam.capture()
            expected = (stage + offset) % 180.0
            assert frame.extra["sim"]["string_angle_deg"] == pytest.approx(expected)
            err = (string_angle(frame.image) - expected + 90.0) % 180.0 - 90.0
            assert abs(err) < 0.1, (stage, err)


def test_injected_faults_raise_quickly_then_recover():
    cam = SimulatedCamera(width=160, height=120)
    with pytest.raises(ValueError, match="fault kind"):
        cam.fail_next(1, "explode")
    with cam:
        cam.fail_next(2, "timeout")
        for _ in range(2):
            t = time.perf_counter()
            with pytest.raises(DeviceTimeout, match="within 3 s"):
                cam.capture(timeout=3.0)
            assert time.perf_counter() - t < 0.5
        ok = cam.capture()
        assert ok.counter == 0 and "corrupt" not in ok.extra
        cam.fail_next(1, "corrupt")
        bad = cam.capture()
        first, end = bad.extra["corrupt_rows"]
        assert bad.extra["corrupt"] is True and 0 < first < end == 120
        clean = cam.render(index=1).image  # the second frame at this pose
        assert np.array_equal(bad.image[:first], clean[:first])
        assert np.mean(bad.image[first:] != clean[first:]) > 0.9
        assert "corrupt" not in cam.capture().extra
        cam.fail_next(1, "disconnect")
        with pytest.raises(DeviceDisconnected):
            cam.capture()
        assert not cam.is_open
        with pytest.raises(DeviceDisconnected, match="not open"):
            cam.capture()


def test_demo_lens_is_a_realistic_decentred_barrel_that_changes_with_focus():
    # issue 9: tens of pixels at the corners of 1280x960 (a 12 mm lens), decentred, radial + tangential,
    # a few pixels less over the focus range
    corner = np.array([[0.0, 0.0], [1279.0, 959.0], [1279.0, 0.0], [0.0, 959.0]])
    moves = []
    for f in np.linspace(0.0, 1.0, 6):
        lens = lens_for_focus(f, 1280, 960)
        ideal = lens.undistort_points(corner)
        centre = np.array(lens.center)
        assert np.hypot(*(centre - (639.5, 479.5))) > 8  # decentred
        assert lens.tangential is not None and min(map(abs, lens.tangential)) > 1e-4
        # barrel: the ideal corner lies farther from the distortion centre than the recorded one
        gain = np.hypot(*(ideal - centre).T) - np.hypot(*(corner - centre).T)
        assert np.all(gain > 0)
        move = np.hypot(*(ideal - corner).T)
        assert np.all(move > 20) and np.all(move < 40), move
        assert np.ptp(move) > 2  # decentring and tangential terms: the corners move unequally
        moves.append(move)
    moves = np.array(moves)
    steps = np.diff(moves.mean(axis=1))
    assert np.all(steps < 0) and np.ptp(steps) < 0.05  # monotonic and near-linear in focus
    assert 2 < moves[0].mean() - moves[-1].mean() < 5  # "changing with focus by a few pixels"
    with pytest.raises(ValueError, match="focus"):
        lens_for_focus(1.2, 1280, 960)


def test_frames_with_the_kept_lens_map_equal_frames_mapped_anew(monkeypatch):
    """The camera keeps the lens map of the focus it renders at; across focus changes every frame
    is the one a camera that maps every pixel anew for each frame renders."""
    import drivers.sim.camera as sim_camera

    def frames(cache_pixels: int) -> list[np.ndarray]:
        monkeypatch.setattr(sim_camera, "IDEAL_CACHE_PIXELS", cache_pixels)
        world = SimWorld(stage_deg=30.0)
        out = []
        with SimulatedCamera(world, **SMALL, seed=3) as cam:
            for k, focus in enumerate((0.0, 1.0, 1.0, 0.0)):
                cam.lock_focus(focus)
                world.set_stage(30.0 + 10.0 * k)
                out.append(cam.capture().image)
        return out

    kept, anew = frames(10**9), frames(0)
    assert all(np.array_equal(a, b) for a, b in zip(kept, anew))
    assert not np.array_equal(kept[0], kept[3])  # the poses differ: the comparison can fail


# -- the turntable carried sideways (issue 19: shots about two places of the turntable axis) ---------------

# the unit of the demo lens whose deviations cancel the design at focus 0: a lens-free camera
LENS_FREE = UnitSpread((-K2[0], -K4[0], 0.0), (0.0, 0.0), (-TANGENTIAL[0], -TANGENTIAL[1]), (0.0,) * 4, False)


def pattern_shift(profile: np.ndarray, periods: int, reference: np.ndarray) -> float:
    """How far (px, towards larger indices) ``profile`` is ``reference`` moved: the phase of their DFT bin
    at the string pitch (a whole number of ``periods`` in the window), by the shift theorem."""
    k = np.exp(-2j * np.pi * periods * np.arange(len(profile)) / len(profile))
    dphi = np.angle(np.sum(profile * k) / np.sum(reference * k))
    return float(-dphi * len(profile) / (2 * np.pi * periods))


def shifted_world(shift_mm: float | None, **kw) -> SimWorld:
    world = SimWorld(lens_unit=LENS_FREE, shift_direction_deg=30.0, shift_px_per_mm=6.0, **kw)
    if shift_mm is not None:
        world.drive_shift(lambda t: shift_mm, "test axis")
    return world


def test_the_harp_turns_about_the_shifted_axis():
    """Through a lens-free camera (no vignetting, no noise) the string pattern at a shift of 1.5 mm (6 px per
    mm, at 30 degrees) is the one at 0 moved by exactly 9 px along (cos 30, sin 30): measured by the phase
    of the string pitch across the strings, along y with the strings along x (stage 0) and along x with
    them along y (stage 90)."""
    scene = HarpScene(vignetting=0.0)
    lens = SimulatedCamera(shifted_world(None), width=240, height=120, scene=scene).lens_at(0.0)
    pts = np.array([[0.0, 0.0], [239.0, 119.0], [17.5, 90.25]])
    assert np.abs(lens.distort_points(pts) - pts).max() < 1e-9  # the camera is lens-free: truth is geometry
    expected = (9.0 * np.cos(np.pi / 6), 9.0 * np.sin(np.pi / 6))
    moved = []
    for stage, axis, periods in ((0.0, 1, 2), (90.0, 0, 4)):  # 60 px pitch: 2 periods in 120 rows, 4 in 240 columns
        profiles = []
        for shift in (None, 1.5):
            world = shifted_world(shift)
            world.set_stage(stage)
            cam = SimulatedCamera(world, width=240, height=120, bit_depth=16, noise_sigma=0.0, scene=scene)
            with cam:
                frame = cam.capture()
            profiles.append(frame.image.astype(float).mean(axis=axis))
        moved.append(pattern_shift(profiles[1], periods, profiles[0]))
        assert frame.extra["sim"]["shift_mm"] == 1.5
        assert frame.extra["sim"]["axis_offset_px"] == pytest.approx(expected, abs=1e-12)
    dy, dx = moved
    print(f"pattern moved ({dx:.5f}, {dy:.5f}) px, expected ({expected[0]:.5f}, {expected[1]:.5f})")
    assert (dx, dy) == pytest.approx(expected, abs=1e-4)


def test_at_shift_zero_the_frames_are_the_ones_without_a_shift_axis():
    frames = []
    for world in (SimWorld(harp_offset_deg=5.0), SimWorld(harp_offset_deg=5.0, shift_px_per_mm=6.0)):
        if world.shift_px_per_mm is not None:
            world.drive_shift(lambda t: 0.0, "test axis")
        world.set_stage(33.0)
        with SimulatedCamera(world, width=96, height=64, seed=4) as cam:
            frames.append(cam.capture())
    assert (
        np.array_equal(frames[0].image, frames[1].image)
        and frames[0].extra["sim"]["seed"] == frames[1].extra["sim"]["seed"]
    )
    assert "shift_mm" not in frames[0].extra["sim"] and frames[1].extra["sim"]["shift_mm"] == 0.0


def test_the_stage_and_the_shift_are_taken_at_the_same_instant_of_the_exposure():
    """Both axes are the world's functions of time, evaluated once at the exposure: a frame taken while the
    stage turns 10 degrees and the stage slides 0.5 mm per second reports both at one time, and is the
    render at that angle and that shift (its noise seeded by both)."""
    world = SimWorld(shift_px_per_mm=6.0)
    t0 = time.monotonic()
    world.drive_stage(lambda t: 10.0 * (t - t0), "test stage")
    world.drive_shift(lambda t: 0.5 * (t - t0), "test axis")
    with SimulatedCamera(world, width=96, height=64, seed=2) as cam:
        frame = cam.capture()
        sim = frame.extra["sim"]
        assert sim["shift_mm"] > 0 and sim["stage_deg"] / 10.0 == pytest.approx(sim["shift_mm"] / 0.5, rel=1e-12)
        again = cam.render(index=0, angle_deg=sim["string_angle_deg"], stage_deg=sim["stage_deg"],
                           shift_mm=sim["shift_mm"])  # fmt: skip
    assert np.array_equal(frame.image, again.image)
    with pytest.raises(DriverError, match="turntable is shifted 2 mm but the world has no shift_px_per_mm"):
        unscaled = SimWorld()
        unscaled.drive_shift(lambda t: 2.0, "test axis")
        with SimulatedCamera(unscaled, width=32, height=32) as cam:
            cam.capture()


def test_the_realistic_harp_turns_about_the_shifted_axis():
    """With the realistic simulator the shifted harp is the harp mounted 9 px along (cos 30, sin 30) from its
    drawn mount: the same pose and the same edges, bends and all, as a camera whose session puts it there."""
    import dataclasses

    shots = []
    for shift, move in ((1.5, (0.0, 0.0)), (None, (9.0 * np.cos(np.pi / 6), 9.0 * np.sin(np.pi / 6)))):
        world = shifted_world(shift)
        world.set_stage(40.0)
        cam = SimulatedCamera(world, width=160, height=120, realism_seed=3)
        m = cam.realism.mount
        mount = dataclasses.replace(m, centre=(m.centre[0] + move[0], m.centre[1] + move[1]))
        cam.realism = dataclasses.replace(cam.realism, mount=mount)
        with cam:
            cam.capture()
        shots.append(cam.last_rendered)
    assert shots[0].pose == shots[1].pose and shots[0].edges == shots[1].edges and len(shots[0].edges) > 4
    assert shots[0].seed != shots[1].seed  # the shifted frame's noise is its own


def test_a_moving_lens_moves_its_distortion_centre_between_poses_and_frames_of_a_pose_agree():
    """``lens_centre_sd_px``: each turntable pose's lens is the stable one with its distortion centre moved (the same
    map about the moved centre: k, tangential unchanged); the frames of one pose see the same lens, another pose
    another; the frames themselves are reproducible (a resumed session renders alike); 0 is the stable lens."""
    still = SimulatedCamera(SimWorld(), width=320, height=240)
    moving = SimulatedCamera(SimWorld(lens_centre_sd_px=5.0), width=320, height=240)
    base = still.lens_at(0.3)
    seeds = [moving._pose_seed(0.3, a, None) for a in (10.0, 40.0, 10.0)]
    assert seeds[0] == seeds[2] != seeds[1] and still._pose_seed(0.3, 10.0, None) is None
    lenses = [moving.lens_at(0.3, s) for s in seeds]
    moves = [np.subtract(m.center, base.center) for m in lenses]
    assert np.all(moves[0] == moves[2]) and not np.allclose(moves[0], moves[1])
    assert all(0 < np.hypot(*m) < 5.0 * 5 for m in moves)  # a normal draw of 5 px per axis, within 5 sigma
    assert all(m.k == base.k and m.tangential == base.tangential for m in lenses)
    assert still.lens_at(0.3, seeds[0]).center == base.center  # a stable world ignores the pose
    a = moving.render(index=0, angle_deg=10.0, focus=0.3).image
    b = moving.render(index=0, angle_deg=10.0, focus=0.3).image
    c = still.render(index=0, angle_deg=10.0, focus=0.3).image
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_a_return_to_a_pose_is_another_visit_with_its_own_frames_and_lens_move():
    """A plan's return to a pose (a twin, ``capture.twin_deg``: ``set_capture_index(index, visit=1)``) renders
    other frames than the first visit's (its own noise; on a lens that moves between poses, its own move), the same
    ones each time it is rendered (a resumed session's twin is bit-identical), and the first visit's are unchanged by
    the hook (visit 0 is the frames of old). The lens of a visit is read from the frame's own record."""
    world = SimWorld(harp_offset_deg=5.0, lens_centre_sd_px=5.0)
    cam = SimulatedCamera.from_config({"width": 96, "height": 64, "seed": 3}, world=world)

    def shoot(index, visit=None):
        world.set_stage(30.0)
        cam.lock_focus(0.5)
        cam.set_capture_index(index) if visit is None else cam.set_capture_index(index, visit)
        f = cam.capture()
        return f.image, f.extra["sim"]["lens"]["center"], f.extra["sim"].get("visit", 0)

    with cam:
        first, c_first, v_first = shoot(0)
        twin, c_twin, v_twin = shoot(0, 1)
        again, c_again, _ = shoot(0, 1)
        first_again, c_first_again, _ = shoot(0, 0)
        after = shoot(1)[0]  # the hook is used up: the next visit-0 frame is frame 1 of the first visit
    assert (v_first, v_twin) == (0, 1)
    assert not np.array_equal(first, twin) and np.array_equal(twin, again) and np.array_equal(first, first_again)
    assert c_first == c_first_again and c_twin == c_again and not np.allclose(c_first, c_twin)
    assert not np.array_equal(after, first) and not np.array_equal(after, twin)
    with pytest.raises(ValueError, match="visit must be a non-negative integer"):
        cam.set_capture_index(0, -1)


def test_a_zoom_cameras_frames_record_the_seed_their_noise_was_drawn_with():
    # the frame's record named a seed without the focal length while its noise was drawn with it: the first frame
    # at one pose recorded one seed at every focal length (truth: a render at the same pose draws the frame's noise,
    # and different focal lengths are different physical situations)
    seeds = []
    for mm in (12.0, 36.0, None):
        world = SimWorld(harp_offset_deg=5.0)
        world.zoom = mm
        world.set_stage(33.0)
        with SimulatedCamera(world, width=96, height=64, seed=4) as cam:
            frame = cam.capture()
            again = cam.render(index=frame.extra["sim"]["pose_index"], stage_deg=33.0)
        assert np.array_equal(frame.image, again.image)
        seeds.append(frame.extra["sim"]["seed"])
    assert len(set(seeds)) == 3
