"""Board shots rendered through an exact lens, with their truth, cached for the whole test run (test helper).

The lens is :class:`tests.pipeline.lenses.ExactLens` (closed form, nothing from :mod:`pipeline.models`);
the camera matrix :data:`K_TRUE` and the poses are given; the truth of each corner is the exact
inverse of the lens map at its ideal pixel, found here by Newton's method on the closed form
(:func:`exact_distort`). The harp model a test holds fixed is :func:`harp_model`, the same lens
written as a :class:`~pipeline.models.RadialModel` (equal to the closed form to 1e-12 px, checked).
Small images (640x480) and few views keep the suite fast.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from pipeline.board import BoardSpec, parse_board
from pipeline.board_render import BoardPose, camera_matrix, ideal_corners, random_poses, render_board
from tests.pipeline.lenses import ExactLens

W, H = 640, 480
BOARD = "charuco:7x5:30:21"
K_TRUE = camera_matrix(560.0, 556.0, 323.5, 236.0)
CENTRE = (329.0, 233.0)
K2, K4 = 0.05, 0.006
TANGENTIAL = (4e-4, -3e-4)
LENS = ExactLens("board-lens", W, H, center=CENTRE, k=(K2, K4), tangential=TANGENTIAL)
N_VIEWS = 6


def spec() -> BoardSpec:
    return parse_board(BOARD)


def harp_model():
    """The lens as a harp model (what ``harp intrinsics`` holds fixed)."""
    from pipeline.models import RadialModel

    return RadialModel.for_image(W, H, k=(1.0, 0.0, K2, 0.0, K4), center=CENTRE, tangential=TANGENTIAL)


def exact_distort(ideal: np.ndarray, lens: ExactLens = LENS) -> np.ndarray:
    """The lens's exact inverse at ideal pixels: Newton on the closed form (Jacobian by central differences)."""
    u = np.asarray(ideal, np.float64).reshape(-1, 2)
    x = u.copy()
    h = 1e-4
    for _ in range(50):
        f = lens.undistort_points(x) - u
        jx = (lens.undistort_points(x + [h, 0]) - lens.undistort_points(x - [h, 0])) / (2 * h)
        jy = (lens.undistort_points(x + [0, h]) - lens.undistort_points(x - [0, h])) / (2 * h)
        j = np.stack([jx, jy], axis=2)
        step = np.linalg.solve(j, f[:, :, None])[:, :, 0]
        x = x - step
        if np.max(np.abs(step)) < 1e-11:
            break
    return x


def exact_corners(pose: BoardPose) -> np.ndarray:
    """Exact recorded pixels of every corner of the board in ``pose`` (rows by corner id)."""
    u, _ = ideal_corners(spec(), K_TRUE, pose)
    return exact_distort(u)


@cache
def poses(n: int = N_VIEWS, seed: int = 7) -> tuple[BoardPose, ...]:
    return tuple(random_poses(spec(), K_TRUE, W, H, n, seed=seed))


@cache
def shot(i: int, *, blur: float = 0.6, noise: float = 1.0) -> np.ndarray:
    """View ``i`` of :func:`poses` rendered (8-bit grey)."""
    return render_board(
        spec(),
        K_TRUE,
        poses()[i],
        LENS.undistort_points,
        W,
        H,
        blur_sigma=blur,
        noise_sigma=noise,
        seed=i,
        supersample=3,
    )


@cache
def off_image_shot() -> np.ndarray:
    """The board mostly outside the image: a few corners only."""
    pose = BoardPose((0.2, -0.3, 0.1), (180.0, 60.0, 420.0))
    return render_board(spec(), K_TRUE, pose, LENS.undistort_points, W, H, seed=99)


def blank_shot() -> np.ndarray:
    rng = np.random.default_rng(5)
    return np.clip(110 + rng.normal(0, 2.0, (H, W)), 0, 255).astype(np.uint8)
