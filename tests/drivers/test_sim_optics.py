"""The simulated camera's optics for the set-up assistant (issue 13): defocus blur with a known
best focus, and saturation with exposure. Both are measured in the frames, not read from the code."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drivers.sim.camera import SimulatedCamera, noise_seed
from drivers.sim.lens import lens_for_focus
from drivers.sim.world import SimWorld
from pipeline.render import HarpScene, render_harp

W, H = 320, 240
WIDE = HarpScene(spacing_px=100.0, vignetting=0.0)  # one string across the centre, flat background


def string_sigma(img: np.ndarray) -> float:
    """The Gaussian PSF standard deviation measured on the string through the image centre.

    Model-free: the darkness profile of a string of width w blurred by a symmetric PSF of
    variance s^2 (optics and pixel box together) has variance w^2/12 + s^2; the background
    comes from the flat plateau beside the string, the box of the pixel adds 1/12.
    """
    y = np.arange(img.shape[0], dtype=float)
    profile = img[:, W // 2 - 20 : W // 2 + 20].astype(float).mean(axis=1)
    cy = (H - 1) / 2
    near = np.abs(y - cy) < 40
    plateau = near & (np.abs(y - cy) > 25)
    deficit = profile[plateau].mean() - profile[near]
    yy = y[near]
    c = (deficit * yy).sum() / deficit.sum()
    var = (deficit * (yy - c) ** 2).sum() / deficit.sum()
    return float(np.sqrt(var - WIDE.string_width_px**2 / 12 - 1.0 / 12))


def test_blur_grows_with_the_distance_from_best_focus_as_documented():
    cam = SimulatedCamera(
        SimWorld(), width=W, height=H, bit_depth=16, noise_sigma=0.0, scene=WIDE, best_focus=0.4, defocus_blur_px=6.0
    )
    with cam:
        for focus in (0.0, 0.4, 0.65, 1.0):
            cam.lock_focus(focus)
            frame = cam.capture()
            documented = float(np.hypot(WIDE.blur_px, 6.0 * (focus - 0.4)))  # module docstring: b(f)
            assert frame.extra["sim"]["blur_px"] == pytest.approx(documented, rel=1e-12)
            assert string_sigma(frame.image) == pytest.approx(documented, rel=0.01), focus


def test_a_focus_sweep_peaks_at_best_focus():
    """Gradient energy (a plain sharpness score) over a sweep in steps of 0.01, with sensor noise."""
    cam = SimulatedCamera(SimWorld(), width=W, height=H, seed=4, best_focus=0.37, defocus_blur_px=8.0)
    sweep = np.round(np.arange(0.20, 0.601, 0.01), 2)
    scores = []
    with cam:
        for focus in sweep:
            cam.lock_focus(float(focus))
            img = cam.capture().image.astype(float)[60:180, 80:240]
            gy, gx = np.gradient(img)
            scores.append(float(np.mean(gx**2 + gy**2)))
    assert abs(sweep[int(np.argmax(scores))] - 0.37) <= 0.02
    assert scores[0] < 0.8 * max(scores) and scores[-1] < 0.8 * max(scores)


def test_defocus_is_off_by_default_and_frames_are_unchanged():
    """Without best_focus (or with no blur per unit) every focus renders the scene's own blur:
    the frame is exactly what the renderer gives for that pose, as before defocus existed."""
    world = SimWorld(harp_offset_deg=5.0)
    plain = SimulatedCamera(world, width=96, height=64, seed=7)
    zero = SimulatedCamera(world, width=96, height=64, seed=7, best_focus=0.2, defocus_blur_px=0.0)
    at_best = SimulatedCamera(world, width=96, height=64, seed=7, best_focus=0.8, defocus_blur_px=5.0)
    with plain, zero, at_best:
        for cam in (plain, zero, at_best):
            cam.lock_focus(0.8)
        frames = [cam.capture() for cam in (plain, zero, at_best)]
    angle = frames[0].extra["sim"]["string_angle_deg"]
    direct = render_harp(
        96,
        64,
        dataclasses.replace(HarpScene(), angle_deg=angle),
        lens=lens_for_focus(0.8, 96, 64),
        noise_sigma=1.5,
        seed=noise_seed(7, 0.8, angle, 0),
    ).image
    for frame in frames:
        assert np.array_equal(frame.image, direct)
        assert frame.extra["sim"]["blur_px"] == HarpScene().blur_px


def test_longer_exposure_saturates_the_frame_where_the_scene_says():
    """Default scene: sheet 200/255 at the centre, 30 % darker at the corners. Exposure scale
    e = exposure / reference: nothing clips at e = 1.2, the centre clips from e > 255/200 while the
    corners (0.7 * 200 * e) do not until e > 1.82, and at e = 2 exactly the pixels at or above half
    of full scale at e = 1 clip (a linear sensor)."""
    cam = SimulatedCamera(SimWorld(stage_deg=30.0), width=W, height=H, noise_sigma=0.0, reference_exposure_us=10_000)
    fractions, images = {}, {}
    with cam:
        for e in (1.0, 1.2, 1.5, 2.0):
            cam.set_exposure(10_000 * e)
            frame = cam.capture()
            assert frame.extra["sim"]["exposure_scale"] == pytest.approx(e)
            img = images[e] = frame.image
            fractions[e] = float(np.mean(img == 255))
            centre, corner = img[H // 2 - 3 : H // 2 + 3, W // 2 - 3 : W // 2 + 3], img[:6, :6]
            if e == 1.5:
                assert (centre == 255).any() and corner.max() < 255
    nominal = images[1.0].astype(int)
    clear = nominal != 127  # 127 may be 126.5..127.5 before rounding: either side of 255 / 2
    assert np.array_equal((images[2.0] == 255)[clear], (nominal >= 128)[clear])
    assert fractions[1.0] == fractions[1.2] == 0.0
    assert 0.0 < fractions[1.5] < fractions[2.0]
