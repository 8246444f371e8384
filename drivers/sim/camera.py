r"""A simulated grey camera looking at the calibration harp.

:class:`SimulatedCamera` satisfies :class:`drivers.protocols.Camera`. Each
:meth:`~SimulatedCamera.capture` renders the harp (:func:`pipeline.render.render_harp`)
at the string angle of the shared :class:`~drivers.sim.world.SimWorld` *at
the moment of the exposure* (stage angle + harp offset), through the demo
lens at the world's current focus (:func:`drivers.sim.lens.lens_for_focus`; the unit of
the lens the world holds, ``SimWorld.lens_unit``: one serial of a population),
with the camera's exposure and gain, and sensor noise that is a function of
the physical situation only (see *Noise seeds* below).

The stage angle is the turntable emulator's own motion model evaluated at
the exposure time (:meth:`SimWorld.stage_at`), not a copy of it: a frame
captured after the turntable reported "idle at θ" is rendered at exactly θ
(recorded in ``Frame.extra["sim"]["stage_deg"]``), however the threads are
scheduled.

Noise seeds. The noise of a frame is seeded by a hash of ``(seed, focus,
string angle rounded to 1e-3 deg, capture index at this pose)``
(:func:`noise_seed`). The capture index at a pose is, by default, one more
than the highest index this camera already returned at the same focus and
string angle since it was opened, starting at 0 (so successive frames at one
pose differ, and reopening replays them). A client that knows which frame it is taking — the station
executor, which may capture only the frames missing from an interrupted
session — can say so with the optional hook :meth:`SimulatedCamera.set_capture_index`
before capturing; a resumed session then receives bit-identical frames to an
uninterrupted run. The hook also says on which of the plan's visits of the pose the frame is taken (a twin,
``capture.twin_deg``, returns to a pose): a return's frames have their own noise and, on a lens that moves
between poses, its own move. The hook is *not* part of :class:`drivers.protocols.Camera`:
real cameras have no use for it, and callers look it up with ``getattr``.

Brightness: the rendered intensities are multiplied by the exposure scale
``e = (exposure_us / reference_exposure_us) * 10 ** (gain_db / 20)`` and
saturate at the top of the pixel format: with the default scene (background
200 of 255 at the centre, 30 % vignetting) the centre of the lit sheet clips
from ``e = 255/200 = 1.275`` on and the whole sheet from ``e ≈ 1.8``, so a
longer exposure is how a test makes a frame saturate (``e`` is recorded in
``extra["sim"]["exposure_scale"]``). Gain also lowers the number of
electrons per grey level, so shot noise (when enabled) grows with gain like
on a sensor; the read noise ``noise_sigma`` is in output grey levels (8-bit
scale).

Ranges (:class:`drivers.protocols.CameraRanges`): focus
:data:`drivers.sim.lens.FOCUS_RANGE` (0 to 1, the demo lens's focus
positions), exposure :data:`EXPOSURE_RANGE_US` (20 µs to 1 s), gain
:data:`GAIN_RANGE_DB` (0 to 24 dB). A value outside raises
:class:`~drivers.errors.OutOfRange` (a ``ValueError`` in ``from_config``);
nothing is clamped. Read-back is exact.

Zoom (off by default). With ``zoom: MM`` configured the camera has the simulated zoom lens
(:func:`drivers.sim.lens.zoom_lens`: barrel at 12 mm, pincushion at 36 mm) at that focal length,
driven by :meth:`SimulatedCamera.set_zoom` (:class:`drivers.protocols.Zoomable`); its frames' noise
seeds include the focal length. Without it, the fixed demo lens as before.

Defocus (off by default, so frames are unchanged unless configured). With
``best_focus`` = :math:`f^*` and ``defocus_blur_px`` = :math:`k` the lens is
sharp at focus setting :math:`f^*` and blurs away from it. Optics: a point
of the harp plane is imaged, out of focus, as a blur disc whose radius grows
linearly with the distance between the image plane and the plane of sharp
focus, which over the small travel of a focus ring is linear in the focus
setting, :math:`r = 2k\,|f - f^*|`. A uniform disc of radius :math:`r` has a
standard deviation :math:`r/2` along any direction, and is replaced by the
Gaussian of that standard deviation, convolved with the in-focus PSF (the
scene's ``blur_px`` = :math:`b_0`):

.. math::
    b(f) = \sqrt{b_0^2 + k^2 (f - f^*)^2}

is the ``blur_px`` the harp is rendered with (recorded in
``extra["sim"]["blur_px"]``). The PSF stays symmetric, so the edge
positions, the distortion and the ground truth do not move; only the edge
width (10–90 % width :math:`2.563\,\sqrt{b^2 + 1/12}` px) and the
gradient peak change, and every sharpness score is best at :math:`f^*`. The
demo lens's distortion changes with focus as before
(:func:`drivers.sim.lens.lens_for_focus`).

Realistic rendering (off by default: the demo's frames are unchanged). With
``realism_seed`` = :math:`n` the camera draws, from :math:`n`, a physical harp, its mount
and the camera's effects (:func:`pipeline.realism.realistic_session`: bent strings,
field-dependent blur, an uneven back-light that turns with the harp, vignetting, shot
and read noise, a Bayer sensor with demosaicing and a tone curve), with the scene's
``spacing_px`` and ``string_width_px`` as the harp's pitch and width and
``harp_offset_deg`` as the strings' angle at stage 0; each frame is then
:func:`pipeline.realism.render_shot` at the stage angle of its exposure (the harp's
strings keep their shapes as it turns: the full 360° of the stage matter, not the
string angle modulo 180°), through the demo lens at the current focus, with the
exposure scale and gain applied to the sensor (``exposure`` times the scale; gain
lowers the electrons per grey level) and the defocus model on the drawn PSF.
``jpeg_quality`` (1–100, 8-bit only) adds JPEG compression. The frame's truth is
:attr:`SimulatedCamera.last_rendered` (a :class:`pipeline.realism.Shot`), the seed in
``extra["sim"]["realism_seed"]``. A realistic frame costs several times a clean one
(a half-size conversion renders four samples per pixel).

Colour (off by default). With ``cfa`` (a Bayer pattern, e.g. ``RGGB``) the sensor is a colour one and
each frame a raw mosaic (:func:`pipeline.render_colour.render_mosaic`, its pattern in
``extra["cfa"]``): green through the demo lens, red and blue through their own exact maps
(:class:`drivers.sim.lens.ChannelLens`: ``tca_red``, ``tca_blue`` their magnification against green,
``tca_red_radial``, ``tca_blue_radial`` its growth to the corners), with the channel sensitivities
:data:`CFA_GAINS`; the light is the scene's ``vignetting`` (:func:`drivers.sim.lens.vignetting_factor`,
on the sensor) times a back-light ``1 + backlight_gradient * h_x / R0`` in the harp's own coordinates
(:math:`R_0` the half diagonal), which turns with the harp
(:func:`pipeline.render_colour.backlit_shading`), times the exposure scale.

The turntable carried sideways (issue 19: a linear stage under the turntable, the world's
:meth:`~drivers.sim.world.SimWorld.shift_at`). At a shift of ``s`` mm at the exposure time the harp turns
about the turntable axis moved by :meth:`~drivers.sim.world.SimWorld.shift_offset_px`, ``s`` times the
world's ``shift_px_per_mm`` in its ``shift_direction_deg``: the clean renderer's strings move by that
offset along their normal (``phase_px``), the realistic harp's mount centre by the offset (its strings keep
their shapes about the moved axis). Vignetting, dust and the sensor stay where they are; the colour
renderer's back-light and the board views are not moved. The frame records ``shift_mm`` and
``axis_offset_px`` in ``extra["sim"]`` (when a linear axis drives the world), and its noise seed includes
the shift when it is not 0; without a linear axis, or at 0, every frame is the one it was without it.

Faults for station tests: :meth:`~SimulatedCamera.fail_next`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import time
from collections import deque
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from drivers.config_keys import check_config_keys
from drivers.errors import DeviceDisconnected, DeviceTimeout, DriverError
from drivers.protocols import CameraIdentity, Frame, Range
from drivers.settings import Setting
from drivers.sim.camera_settings import CONFIG_KEYS, EXPOSURE_RANGE_US, GAIN_RANGE_DB, SCENE_SETTINGS, SETTINGS
from drivers.sim.lens import (
    FOCUS_RANGE,
    ZOOM_FOCAL_RANGE_MM,
    ChannelLens,
    lens_for_focus,
    vignetting_factor,
    with_field,
    zoom_lens,
)
from drivers.sim.world import SimWorld
from pipeline.board import parse_board
from pipeline.board_render import BoardPose, render_board
from pipeline.board_render import camera_matrix as board_camera_matrix
from pipeline.board_requests import request_pose
from pipeline.cfa import check_pattern
from pipeline.lens_population import shot_to_shot
from pipeline.render import HarpScene, Rendered, ideal_grid, render_harp
from pipeline.render_colour import backlit_shading, render_mosaic

if TYPE_CHECKING:  # the realistic simulator is imported only by a camera that uses it
    from pipeline.realism import Session, Shot

BOARD_FOCAL_PX_PER_WIDTH = 2.5
"""The simulated camera's true focal length, in image widths (1280 px wide: 3200 px, the demo's nominal
12 mm over 3.75 um pixels); ``focal_px`` overrides it."""

BOARD_PRINCIPAL_OFFSET = (0.006, -0.004)
"""The true principal point's offset from the image centre, in image widths (1280 px: 7.7, -5.1 px)."""

BOARD_FILL = 0.5
"""A board view spans this fraction of the image width (at the board's distance, untilted)."""

BOARD_SWEEP = 0.2
"""A board view's centre is this many image widths from the image centre, in the direction of the
turntable angle, so that the views sweep the field."""

CFA_GAINS = {"R": 0.6, "G": 1.0, "B": 0.5}
"""A colour sensor's channel sensitivities (``cfa``): red and blue below green, as a white balance undoes."""

IDEAL_CACHE_PIXELS = 6_000_000
"""Largest sensor (pixels) whose lens map the camera keeps between frames (16 bytes per pixel: 96 MB)."""
_FOCUS = Range(FOCUS_RANGE[0], FOCUS_RANGE[1], "", "simulated lens focus range")
_ZOOM = Range(ZOOM_FOCAL_RANGE_MM[0], ZOOM_FOCAL_RANGE_MM[1], "mm", "simulated zoom lens")
_EXPOSURE = Range(EXPOSURE_RANGE_US[0], EXPOSURE_RANGE_US[1], "µs", "simulated sensor")
_GAIN = Range(GAIN_RANGE_DB[0], GAIN_RANGE_DB[1], "dB", "simulated sensor")
FAULT_KINDS = ("timeout", "corrupt", "disconnect")
_TIMEOUT_WAIT_S = 0.05  # an injected timeout waits min(timeout, this) before raising


_SCENE_KEYS = tuple(SCENE_SETTINGS)


def noise_seed(
    seed: int,
    focus: float,
    angle_deg: float,
    index: int,
    zoom: float | None = None,
    shift_mm: float | None = None,
    visit: int = 0,
) -> int:
    """Noise seed of the ``index``-th capture at a pose (focus, string angle) on the ``visit``-th time there.

    A 64-bit hash of ``seed``, ``focus`` (to 1e-6), the string angle (to
    1e-3 degree, modulo 180) and ``index``: equal physical situations give
    equal seeds whatever happened before (reopen, resume), different ones
    give unrelated seeds. ``visit`` (0: the first) numbers a plan's returns to a pose (a twin,
    ``capture.twin_deg``): a return is another physical situation, so its frames are other frames.
    """
    angle = round(float(angle_deg) % 180.0, 3) % 180.0
    key = f"{int(seed)}|{round(float(focus), 6):.6f}|{angle:.3f}|{int(index)}".encode()
    if zoom is not None:  # a zoom lens's frames differ by focal length too (the fixed lens's are unchanged)
        key += f"|z{round(float(zoom), 6):.6f}".encode()
    if shift_mm:  # so do frames with the turntable carried sideways (at 0 mm: unchanged)
        key += f"|s{round(float(shift_mm), 6):.6f}".encode()
    if visit:  # so do a return's (the first visit: unchanged)
        key += f"|v{int(visit)}".encode()
    return int.from_bytes(hashlib.sha256(key).digest()[:8], "little")


def _pose(focus: float, angle_deg: float, shift_mm: float | None = None) -> tuple[float, ...]:
    pose = (round(float(focus), 6), round(float(angle_deg) % 180.0, 3) % 180.0)
    return pose + (round(float(shift_mm), 6),) if shift_mm else pose


class SimulatedCamera:
    """Simulated harp camera (see the module docstring).

    Parameters
    ----------
    world : the shared simulated world (a new one if None).
    width, height : sensor size (default 1280 x 960).
    bit_depth : 8 (``Mono8``) or 16 (``Mono16``).
    seed : base seed of the noise (module doc: *Noise seeds*).
    noise_sigma, shot_noise, electrons_per_level : noise model of
        :func:`pipeline.render.render_harp` (at 0 dB gain).
    scene : the harp; its ``angle_deg`` is ignored (taken from the world).
    exposure_us, gain_db : initial settings (``ValueError`` outside the ranges).
    reference_exposure_us : exposure at which the scene has its nominal levels.
    serial : reported in :attr:`identity`.
    best_focus, defocus_blur_px : the defocus model (module docstring);
        ``best_focus=None`` (default) or ``defocus_blur_px=0`` renders every
        focus setting sharp.
    realism_seed : render with the realistic simulator, its harp and effects drawn
        from this seed (module docstring, *Realistic rendering*); None (default): the
        clean renderer.
    jpeg_quality : with ``realism_seed``, JPEG-compress every frame at this quality.
    """

    CONFIG_KEYS: frozenset[str] = frozenset(CONFIG_KEYS)
    """Keys of this driver's configuration section."""
    SETTINGS: Mapping[str, Setting] = SETTINGS
    """Each key's type, unit and range (:mod:`drivers.settings`)."""

    def __init__(
        self,
        world: SimWorld | None = None,
        *,
        width: int = 1280,
        height: int = 960,
        bit_depth: int = 8,
        seed: int = 0,
        noise_sigma: float = 1.5,
        shot_noise: bool = False,
        electrons_per_level: float = 40.0,
        scene: HarpScene = HarpScene(),  # noqa: B008 (frozen, immutable default)
        exposure_us: float = 10_000.0,
        gain_db: float = 0.0,
        reference_exposure_us: float = 10_000.0,
        serial: str = "SIM-0001",
        best_focus: float | None = None,
        defocus_blur_px: float = 0.0,
        realism_seed: int | None = None,
        jpeg_quality: int | None = None,
        board: str | None = None,
        board_tilt_deg: float = 30.0,
        focal_px: float | None = None,
        cfa: str | None = None,
        tca_red: float = 0.0,
        tca_red_radial: float = 0.0,
        tca_blue: float = 0.0,
        tca_blue_radial: float = 0.0,
        backlight_gradient: float = 0.0,
    ):
        if int(width) != width or int(height) != height or width < 16 or height < 16:
            raise ValueError(f"sim camera: width and height must be integers >= 16, got {width}x{height}")
        if bit_depth not in (8, 16):
            raise ValueError(f"sim camera: bit_depth must be 8 or 16, got {bit_depth!r}")
        if not noise_sigma >= 0 or not electrons_per_level > 0 or not reference_exposure_us > 0:
            raise ValueError("sim camera: noise_sigma must be >= 0, electrons_per_level and reference_exposure_us > 0")
        if not defocus_blur_px >= 0:
            raise ValueError(f"sim camera: defocus_blur_px must be >= 0, got {defocus_blur_px!r}")
        if defocus_blur_px > 0 and best_focus is None:
            raise ValueError("sim camera: defocus_blur_px needs best_focus (the focus setting that is sharp)")
        if realism_seed is not None and (
            isinstance(realism_seed, bool) or int(realism_seed) != realism_seed or realism_seed < 0
        ):
            raise ValueError(f"sim camera: realism_seed must be a non-negative integer or null, got {realism_seed!r}")
        if jpeg_quality is not None:
            if realism_seed is None:
                raise ValueError("sim camera: jpeg_quality needs realism_seed (the clean renderer writes no JPEG)")
            if isinstance(jpeg_quality, bool) or int(jpeg_quality) != jpeg_quality or not 1 <= jpeg_quality <= 100:
                raise ValueError(f"sim camera: jpeg_quality must be an integer in 1..100, got {jpeg_quality!r}")
            if bit_depth != 8:
                raise ValueError("sim camera: jpeg_quality needs bit_depth 8 (Mono8)")
        self.cfa = None if cfa is None else check_pattern(str(cfa))
        self.tca = {"R": (float(tca_red), float(tca_red_radial)), "B": (float(tca_blue), float(tca_blue_radial))}
        self.backlight_gradient = float(backlight_gradient)
        if self.cfa is None and (any(any(t) for t in self.tca.values()) or self.backlight_gradient):
            raise ValueError("sim camera: tca_red, tca_blue and backlight_gradient need cfa (a colour sensor)")
        if self.cfa is not None and (int(width) % 2 or int(height) % 2 or realism_seed is not None):
            raise ValueError("sim camera: cfa needs an even width and height and no realism_seed")
        self.board = None
        if board is not None:
            self.board = parse_board(str(board))  # ValueError (one line) naming the label
        self.board_placed: Any = None  # a ViewRequest: the board where a person holds it (show_board)
        if not (0.0 <= float(board_tilt_deg) < 80.0):
            raise ValueError(f"sim camera: board_tilt_deg must be in [0, 80), got {board_tilt_deg!r}")
        self.board_tilt_deg = float(board_tilt_deg)
        self.focal_px = float(focal_px) if focal_px is not None else BOARD_FOCAL_PX_PER_WIDTH * int(width)
        if not (math.isfinite(self.focal_px) and self.focal_px > 0):
            raise ValueError(f"sim camera: focal_px must be > 0, got {focal_px!r}")
        self.realism_seed = None if realism_seed is None else int(realism_seed)
        self.jpeg_quality = None if jpeg_quality is None else int(jpeg_quality)
        self.realism: Session | None = None
        if self.realism_seed is not None:
            from pipeline.realism import realistic_session  # defers pipeline.realism: a clean camera never needs it

            self.realism = realistic_session(
                self.realism_seed,
                int(width),
                int(height),
                spacing_px=scene.spacing_px,
                string_width_px=scene.string_width_px,
                angle0_deg=0.0,
            )
        self.best_focus = None if best_focus is None else _FOCUS.check("sim camera", "best_focus", best_focus)
        self.defocus_blur_px = float(defocus_blur_px)
        self.world = world if world is not None else SimWorld()
        self._size = (int(width), int(height))
        # the lens applied to every pixel, for the (renderer, focus, focal length, lens unit) it was
        # computed at (render saves half its time)
        self._ideal: tuple[tuple[object, ...], np.ndarray] | None = None
        self._bit_depth = int(bit_depth)
        self.seed = int(seed)
        self.noise_sigma = float(noise_sigma)
        self.shot_noise = bool(shot_noise)
        self.electrons_per_level = float(electrons_per_level)
        self.scene = scene
        self.reference_exposure_us = float(reference_exposure_us)
        self._identity = CameraIdentity("harp station", "SimulatedCamera", str(serial))
        self._exposure = _EXPOSURE.check(self.name, "exposure", exposure_us)
        self._gain = _GAIN.check(self.name, "gain", gain_db)
        self._open = False
        self._counter = 0
        self._pose_counts: dict[tuple[float, ...], int] = {}
        self._next_index: int | None = None
        self._next_visit = 0
        self._faults: deque[str] = deque()
        #: the :class:`pipeline.render.Rendered` (clean) or :class:`pipeline.realism.Shot` (realistic)
        #: behind the last frame (exact truth), or None
        self.last_rendered: Rendered | Shot | None = None
        # render once with the scene at angle 0 to validate it now, not at the first capture
        render_harp(16, 16, dataclasses.replace(scene, angle_deg=0.0), noise_sigma=0.0)

    # ------------------------------------------------------------ config
    @classmethod
    def from_config(cls, cfg: dict[str, Any], world: SimWorld | None = None, **context: Any) -> SimulatedCamera:
        """Create from a configuration mapping (keys: :data:`CONFIG_KEYS`).

        ``driver`` is ignored (it selected this class). ``pixel_format``
        (``Mono8``/``Mono16``) is an alternative to ``bit_depth``. ``focus``
        and ``harp_offset_deg`` set the (given or new) world. Other context
        passed by :func:`drivers.open_camera` is ignored. An unknown key or a
        bad value raises ValueError naming the key.
        """
        cfg = dict(cfg)
        check_config_keys("sim camera", cfg, SETTINGS)
        world = world if world is not None else SimWorld()
        kw: dict[str, Any] = {}
        scene_kw: dict[str, Any] = {}
        try:
            for key, value in cfg.items():
                if key in ("realism_seed", "jpeg_quality", "cfa") and value is None:
                    pass
                elif key in (
                    "width",
                    "height",
                    "bit_depth",
                    "seed",
                    "dust",
                    "dust_seed",
                    "frame_side",
                    "realism_seed",
                    "jpeg_quality",
                ):
                    if isinstance(value, bool) or int(value) != value:
                        raise ValueError(f"must be an integer, got {value!r}")
                    value = int(value)
                elif key in ("shot_noise", "frame"):
                    if not isinstance(value, bool):
                        raise ValueError(f"must be true or false, got {value!r}")
                elif key in ("serial", "pixel_format", "driver", "board", "cfa"):
                    value = str(value)
                elif key == "best_focus" and value is None:
                    pass
                else:
                    value = float(value)
                if key in _SCENE_KEYS:
                    scene_kw[key] = value
                elif key == "pixel_format":
                    if value not in ("Mono8", "Mono16"):
                        raise ValueError(f"must be Mono8 or Mono16, got {value!r}")
                    bd = 8 if value == "Mono8" else 16
                    if "bit_depth" in cfg and cfg["bit_depth"] != bd:
                        raise ValueError(f"{value} contradicts bit_depth {cfg['bit_depth']}")
                    kw["bit_depth"] = bd
                elif key == "focus":
                    world.focus = _FOCUS.check("sim camera", "focus", value)
                elif key == "zoom":
                    world.zoom = _ZOOM.check("sim camera", "zoom", value)
                elif key == "harp_offset_deg":
                    world.harp_offset_deg = value
                elif key != "driver":
                    kw[key] = value
            scene = HarpScene(**scene_kw)
        except (TypeError, ValueError) as exc:
            bad = key if "key" in locals() else "?"
            raise ValueError(f"sim camera: config key {bad!r}: {exc}") from None
        try:
            return cls(world, scene=scene, **kw)
        except ValueError as exc:
            raise ValueError(str(exc)) from None

    # ------------------------------------------------------------ lifecycle
    def open(self) -> None:
        self._open = True
        self._counter = 0
        self._pose_counts = {}
        self._next_index, self._next_visit = None, 0

    def close(self) -> None:
        self._open = False

    def __enter__(self) -> SimulatedCamera:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def is_open(self) -> bool:
        return self._open

    def _require_open(self, what: str) -> None:
        if not self._open:
            raise DeviceDisconnected(f"sim camera {self._identity.serial}: cannot {what}, camera is not open")

    # ------------------------------------------------------------ properties
    @property
    def identity(self) -> CameraIdentity:
        return self._identity

    @property
    def sensor_size(self) -> tuple[int, int]:
        return self._size

    @property
    def pixel_format(self) -> str:
        if self.cfa is not None:  # GenICam's name of a raw Bayer mosaic: BayerRG16 for RGGB
            return f"Bayer{self.cfa[:2]}{self._bit_depth}"
        return "Mono8" if self._bit_depth == 8 else "Mono16"

    @property
    def name(self) -> str:
        """How errors name this camera: ``"sim camera SIM-0001"``."""
        return f"sim camera {self._identity.serial}"

    # ------------------------------------------------------------ ranges
    def focus_range(self) -> Range:
        """:data:`drivers.sim.lens.FOCUS_RANGE`, the focus positions of the demo lens."""
        return _FOCUS

    def exposure_range(self) -> Range:
        """:data:`EXPOSURE_RANGE_US`, in µs."""
        return _EXPOSURE

    def gain_range(self) -> Range:
        """:data:`GAIN_RANGE_DB`, in dB."""
        return _GAIN

    # ------------------------------------------------------------ board
    def camera_matrix(self) -> np.ndarray:
        """The simulated camera's true camera matrix (the ideal frame of its lens maps):
        ``fx = fy = focal_px``, principal point :data:`BOARD_PRINCIPAL_OFFSET` from the centre."""
        w, h = self._size
        cx = (w - 1) / 2.0 + BOARD_PRINCIPAL_OFFSET[0] * w
        cy = (h - 1) / 2.0 + BOARD_PRINCIPAL_OFFSET[1] * w
        return board_camera_matrix(self.focal_px, self.focal_px, cx, cy)

    def board_pose(self, stage_deg: float, tilt_deg: float | None = None) -> Any:
        """The board's pose at turntable angle ``stage_deg``: mounted on a wedge of ``board_tilt_deg``
        (or tilted ``tilt_deg`` by the stage's tilt axis) on the turntable, whose axis is the optical axis
        (as the harp's), its centre :data:`BOARD_SWEEP` image widths off the axis in the turntable's
        direction, at the distance where it spans :data:`BOARD_FILL` of the width."""
        import cv2

        assert self.board is not None
        w, _ = self._size
        bw, bh = self.board.size_mm()
        z = self.focal_px * bw / (BOARD_FILL * w)
        th = math.radians(stage_deg)
        r_spin, _ = cv2.Rodrigues(np.array([0.0, 0.0, th]))
        tilt = self.board_tilt_deg if tilt_deg is None else float(tilt_deg)
        r_tilt, _ = cv2.Rodrigues(np.array([math.radians(tilt), 0.0, 0.0]))
        rot = r_spin @ r_tilt
        k = self.camera_matrix()
        u = np.array([k[0, 2] + BOARD_SWEEP * w * math.cos(th), k[1, 2] + BOARD_SWEEP * w * math.sin(th), 1.0])
        t = np.linalg.solve(k, u) * z - rot @ np.array([bw / 2, bh / 2, 0.0])
        rvec, _ = cv2.Rodrigues(rot)
        rv = np.asarray(rvec, np.float64).ravel()
        return BoardPose((float(rv[0]), float(rv[1]), float(rv[2])), (float(t[0]), float(t[1]), float(t[2])))

    def _board_frame(
        self, stage: float, focus: float, index: int, seed: int, stamp: float, tilt: float | None = None
    ) -> Frame:
        """A frame of the board (``board`` configured) through the lens at ``focus``
        (:func:`pipeline.board_render.render_board`)."""
        assert self.board is not None
        w, h = self._size
        lens = self.lens_at(focus)
        if self.board_placed is not None:
            pose = request_pose(self.board_placed, self.camera_matrix(), self.board.size_mm(), w, h)
        else:
            pose = self.board_pose(stage, tilt)
        img8 = render_board(
            self.board, self.camera_matrix(), pose, lens.undistort_points, w, h, supersample=3,
            noise_sigma=self.noise_sigma, seed=seed % (2**32),
        )  # fmt: skip
        img: np.ndarray = img8.astype(np.uint16) * 257 if self._bit_depth == 16 else img8
        extra = {"sim": {"board": self.board.label, "stage_deg": float(stage), "board_pose": [*pose.rvec, *pose.tvec]}}
        frame = Frame(img, stamp, self._exposure, self._gain, float(focus), self._identity, self._counter, extra)
        self._counter += 1
        return frame

    def zoom_range(self) -> Range | None:
        """The simulated zoom lens's focal lengths (mm), or None for the fixed demo lens (no ``zoom`` configured)."""
        return _ZOOM if self.world.zoom is not None else None

    def set_zoom(self, position: float) -> float:
        """Drive the zoom lens to focal length ``position`` (mm); :class:`OutOfRange` outside
        :data:`drivers.sim.lens.ZOOM_FOCAL_RANGE_MM`, DriverError for the fixed lens."""
        self._require_open("set zoom")
        if self.world.zoom is None:
            raise DriverError(f"{self.name}: the fixed demo lens has no zoom (configure zoom: MM for the zoom lens)")
        self.world.zoom = _ZOOM.check(self.name, "zoom", position)
        return self.world.zoom

    def get_zoom(self) -> float | None:
        return self.world.zoom

    def lens_at(self, focus: float, pose_seed: int | None = None) -> Any:
        """The lens the harp is rendered through at ``focus``: the zoom lens at the world's focal length
        (:func:`drivers.sim.lens.zoom_lens`), or the fixed demo lens (:func:`drivers.sim.lens.lens_for_focus`),
        each the unit ``world.lens_unit`` (its manufacturing deviations; None: the nominal lens) with its residual
        field ``world.lens_field`` (:func:`drivers.sim.lens.with_field`; None: none). With
        ``world.lens_centre_sd_px`` > 0 and a ``pose_seed`` (one per turntable pose, :meth:`_pose_seed`) its
        distortion centre is moved by a normal draw of that standard deviation per axis
        (:func:`pipeline.lens_population.shot_to_shot`): a lens whose decentering changes between poses, as an image
        stabiliser that re-centres or a focus group with play does; the frames of one pose share it."""
        w, h = self._size
        if self.world.zoom is not None:
            lens = zoom_lens(self.world.zoom, focus, w, h, self.world.lens_unit)
        else:
            lens = lens_for_focus(focus, w, h, self.world.lens_unit)
        fielded = with_field(lens, self.world.lens_field, w, h)
        if pose_seed is None or self.world.lens_centre_sd_px == 0:
            return fielded
        return shot_to_shot(fielded, np.random.default_rng([pose_seed, 0xCE27]), 0.0, self.world.lens_centre_sd_px)

    def _pose_seed(self, focus: float, angle_deg: float, shift_mm: float | None, visit: int = 0) -> int | None:
        """The seed of the lens's move at a pose on its ``visit``-th visit (:meth:`lens_at`), None for a stable
        lens: equal poses and visits, equal moves (a resumed session's frames are rendered alike)."""
        if self.world.lens_centre_sd_px == 0:
            return None
        return noise_seed(self.seed, focus, angle_deg, -1, self.world.zoom, shift_mm, visit)

    def blur_at(self, focus: float) -> float:
        """The PSF standard deviation (px) the harp is rendered with at ``focus`` (module doc: *Defocus*)."""
        b0 = self.scene.blur_px
        if self.best_focus is None or self.defocus_blur_px == 0:
            return b0
        return math.hypot(b0, self.defocus_blur_px * (float(focus) - self.best_focus))

    def exposure_scale(self) -> float:
        """The factor on the scene's grey levels at the current exposure and gain (module doc)."""
        gain: float = 10.0 ** (self._gain / 20.0)
        return self._exposure / self.reference_exposure_us * gain

    # ------------------------------------------------------------ settings
    def set_exposure(self, microseconds: float) -> float:
        """Set the exposure time (:class:`OutOfRange` outside :data:`EXPOSURE_RANGE_US`); returns it."""
        self._require_open("set exposure")
        self._exposure = _EXPOSURE.check(self.name, "exposure", microseconds)
        return self._exposure

    def get_exposure(self) -> float:
        return self._exposure

    def set_gain(self, db: float) -> float:
        """Set the gain (:class:`OutOfRange` outside :data:`GAIN_RANGE_DB`); returns it."""
        self._require_open("set gain")
        self._gain = _GAIN.check(self.name, "gain", db)
        return self._gain

    def get_gain(self) -> float:
        return self._gain

    def lock_focus(self, position: float) -> float:
        """Set the world's focus (:class:`OutOfRange` outside :data:`drivers.sim.lens.FOCUS_RANGE`); returns it."""
        self._require_open("lock focus")
        self.world.focus = _FOCUS.check(self.name, "focus", position)
        return self.world.focus

    def get_focus(self) -> float | None:
        return float(self.world.focus)

    # ------------------------------------------------------------ faults
    def fail_next(self, n: int = 1, kind: str = "timeout") -> None:
        """Make the next ``n`` captures fail.

        ``kind``: ``"timeout"`` (wait ``min(timeout, 0.05 s)`` then raise
        :class:`~drivers.errors.DeviceTimeout`), ``"corrupt"`` (return a frame
        whose rows from a random row on are garbage, flagged by
        ``extra["corrupt"] = True`` and ``extra["corrupt_rows"] = [first, end)``)
        or ``"disconnect"`` (the camera closes and raises
        :class:`~drivers.errors.DeviceDisconnected`).
        """
        if kind not in FAULT_KINDS:
            raise ValueError(f"fault kind must be one of {', '.join(FAULT_KINDS)}, got {kind!r}")
        if int(n) != n or n < 0:
            raise ValueError(f"fault count must be a non-negative integer, got {n!r}")
        self._faults.extend([kind] * int(n))

    def show_board(self, label: str | None, placed: Any = None) -> None:
        """The board ``label`` in front of the camera from the next capture on (None: the harp again);
        :class:`drivers.protocols.BoardScene`. ``placed``: a :class:`pipeline.board_requests.ViewRequest`,
        the board held where a person was asked to hold it (:func:`pipeline.board_requests.request_pose`)
        instead of on the wedge. ValueError (one line) for a label that is not a board."""
        self.board = None if label is None else parse_board(str(label))
        self.board_placed = None if label is None else placed

    # ------------------------------------------------------------ capture
    def set_capture_index(self, index: int, visit: int = 0) -> None:
        """Optional hook (not in the Camera protocol): the next frame returned is
        capture number ``index`` (>= 0) at the current pose, on the plan's ``visit``-th time there (0: the first;
        a twin, ``capture.twin_deg``, is a return: 1).

        Selects that frame's noise (module doc: *Noise seeds*) instead of the
        count of frames already taken at this pose, and on a return the lens's move there (:meth:`lens_at`) is
        drawn anew: a lens that moves between poses moves between visits of one pose too. Applies to the next
        capture that returns a frame (a timeout or disconnect does not use it
        up); later captures go back to counting, from ``index + 1`` on at this
        pose (or further, if more frames were taken there already), on the first visit.
        """
        if isinstance(index, bool) or int(index) != index or index < 0:
            raise ValueError(f"capture index must be a non-negative integer, got {index!r}")
        if isinstance(visit, bool) or int(visit) != visit or visit < 0:
            raise ValueError(f"visit must be a non-negative integer, got {visit!r}")
        self._next_index = int(index)
        self._next_visit = int(visit)

    def _index_at(self, focus: float, angle_deg: float, shift_mm: float | None = None) -> int:
        if self._next_index is not None:
            return self._next_index
        return self._pose_counts.get(_pose(focus, angle_deg, shift_mm), 0)

    def render(
        self,
        index: int | None = None,
        angle_deg: float | None = None,
        focus: float | None = None,
        stage_deg: float | None = None,
        shift_mm: float | None = None,
        visit: int | None = None,
    ) -> Rendered | Shot:
        """Render what the camera sees (no fault, no counter change).

        ``angle_deg`` and ``focus`` default to the world's current string
        angle and focus; ``index`` (default: the next capture's at that pose)
        is the capture index at the pose, which selects the noise. A realistic
        camera (``realism_seed``) renders the harp at stage angle ``stage_deg``
        (default: ``angle_deg`` minus the harp offset, or the world's stage now).
        ``shift_mm``: the linear stage's position (module doc; default: the world's now, None without one).
        ``visit``: the plan's visit of the pose (:meth:`set_capture_index`; default: the next capture's).
        """
        w, h = self._size
        now = time.monotonic()
        if stage_deg is None and angle_deg is None:
            stage_deg = self.world.stage_at(now)
        if shift_mm is None:
            shift_mm = self.world.shift_at(now)
        axis_px = self._axis_offset(shift_mm)
        if angle_deg is None:
            assert stage_deg is not None
            angle_deg = (stage_deg + self.world.harp_offset_deg) % 180.0
        focus = self.world.focus if focus is None else focus
        index = self._index_at(focus, angle_deg, shift_mm) if index is None else int(index)
        gain_lin = 10.0 ** (self._gain / 20.0)
        visit = self._next_visit if visit is None else int(visit)
        seed = noise_seed(self.seed, focus, angle_deg, index, self.world.zoom, shift_mm, visit)
        pose = self._pose_seed(focus, angle_deg, shift_mm, visit)
        if self.realism is not None:
            stage = float(angle_deg) - self.world.harp_offset_deg if stage_deg is None else float(stage_deg)
            return self._render_realistic(stage, focus, seed, gain_lin, axis_px, pose)
        scene = dataclasses.replace(self.scene, angle_deg=angle_deg)
        if axis_px is not None:  # the strings turn about the moved axis: each moves by the offset along its normal
            nx, ny = scene.normal
            scene = dataclasses.replace(scene, phase_px=scene.phase_px + axis_px[0] * nx + axis_px[1] * ny)
        if self.best_focus is not None and self.defocus_blur_px > 0:
            scene = dataclasses.replace(scene, blur_px=self.blur_at(focus))
        lens = self.lens_at(focus, pose)
        if self.cfa is not None:
            stage = float(angle_deg) - self.world.harp_offset_deg if stage_deg is None else float(stage_deg)
            colour: Rendered = self._render_colour(scene, lens, stage + self.world.harp_offset_deg, seed, gain_lin)
            return colour  # a RenderedColour: image and scene as a Rendered's
        return render_harp(
            w,
            h,
            scene,
            lens=lens,
            ideal=None if pose is not None else self._ideal_grid(float(focus), lens),  # a moved lens: mapped anew
            noise_sigma=self.noise_sigma,
            shot_noise=self.shot_noise,
            bit_depth=self._bit_depth,
            seed=seed,
            exposure=self.exposure_scale(),
            electrons_per_level=self.electrons_per_level / gain_lin,
        )

    def _render_colour(self, scene: HarpScene, lens: Any, harp_deg: float, seed: int, gain_lin: float) -> Any:
        """A raw Bayer mosaic (``cfa``; module docstring, *Colour*): each channel through its own lens map
        (:class:`drivers.sim.lens.ChannelLens`), shaded by the scene's vignetting and the back-light, which
        turns with the harp (at ``harp_deg``, the strings' angle not folded to 180 degrees); a
        :class:`pipeline.render_colour.RenderedColour`."""
        assert self.cfa is not None
        w, h = self._size
        lenses = {"G": lens, **{c: ChannelLens(lens, a, b, w, h) for c, (a, b) in self.tca.items()}}
        r0 = 0.5 * math.hypot(w, h)
        g = self.backlight_gradient

        def vignetting(xy: np.ndarray) -> np.ndarray:
            return vignetting_factor(self.scene.vignetting, w, h, xy)

        def backlight(hxy: np.ndarray) -> np.ndarray:
            return np.asarray(1.0 + g * np.asarray(hxy)[:, 0] / r0, np.float64)

        shading = backlit_shading(w, h, vignetting, backlight if g else None, harp_deg, lens)
        return render_mosaic(
            w, h, scene, cast(Any, lenses), self.cfa, gains=CFA_GAINS, shading=shading * self.exposure_scale(),
            noise_sigma=self.noise_sigma, shot_noise=self.shot_noise,
            electrons_per_level=self.electrons_per_level / gain_lin, bit_depth=self._bit_depth, seed=seed,
        )  # fmt: skip

    def _axis_offset(self, shift_mm: float | None) -> tuple[float, float] | None:
        """Where the linear stage at ``shift_mm`` has moved the turntable axis in the image (px,
        :meth:`SimWorld.axis_offset_px`), None when it has not (no linear axis, or at 0: the frame is the one
        without it); DriverError when the world cannot say (no ``shift_px_per_mm``)."""
        if not shift_mm:
            return None
        try:
            return self.world.axis_offset_px(shift_mm)
        except ValueError as exc:
            raise DriverError(f"{self.name}: {exc}") from None

    def _render_realistic(
        self,
        stage_deg: float,
        focus: float,
        seed: int,
        gain_lin: float,
        axis_px: tuple[float, float] | None = None,
        pose_seed: int | None = None,
    ) -> Shot:
        """One frame of the realistic simulator (module docstring, *Realistic rendering*); ``pose_seed``: the lens's
        move at this pose (:meth:`lens_at`)."""
        from pipeline.harp_scene import HarpMount  # defers pipeline.harp_scene
        from pipeline.realism import raw_ideal_grid, render_shot  # defers pipeline.realism
        from pipeline.sensor import raw_scale  # defers pipeline.sensor

        assert self.realism is not None
        w, h = self._size
        eff = self.realism.effects
        sensor = dataclasses.replace(
            eff.sensor,
            exposure=eff.sensor.exposure * self.exposure_scale(),
            full_well_e=eff.sensor.full_well_e / gain_lin,
        )
        development = dataclasses.replace(eff.development, bit_depth=self._bit_depth, jpeg_quality=self.jpeg_quality)
        blur = eff.blur
        if self.best_focus is not None and self.defocus_blur_px > 0:
            blur = dataclasses.replace(
                blur, sigma_px=math.hypot(blur.sigma_px, self.defocus_blur_px * (focus - self.best_focus))
            )
        effects = dataclasses.replace(eff, sensor=sensor, development=development, blur=blur)
        m = self.realism.mount
        centre = m.centre if axis_px is None else (m.centre[0] + axis_px[0], m.centre[1] + axis_px[1])
        mount = HarpMount(centre, self.world.harp_offset_deg, 1, m.gravity_deg, m.gravity_in_plane)
        lens = self.lens_at(focus, pose_seed)
        ideal = None
        if pose_seed is None and w * h * raw_scale(sensor, development) ** 2 <= IDEAL_CACHE_PIXELS:
            key = (
                "raw",
                float(focus),
                self.world.zoom,
                self.world.lens_unit,
                self.world.lens_field,
            )  # apart from the clean renderer's
            if self._ideal is None or self._ideal[0] != key:
                self._ideal = (key, raw_ideal_grid(lens, w, h, effects))
            ideal = self._ideal[1]
        return render_shot(lens, self.realism.harp, mount, stage_deg, w, h, effects, seed=seed % (2**63), ideal=ideal)

    def _ideal_grid(self, focus: float, lens: Any) -> np.ndarray | None:
        """The lens at ``focus`` applied to every pixel centre, kept for the next frame at that focus
        (sensors up to :data:`IDEAL_CACHE_PIXELS`; larger ones map every frame anew)."""
        w, h = self._size
        if w * h > IDEAL_CACHE_PIXELS:
            return None
        key = ("clean", float(focus), self.world.zoom, self.world.lens_unit, self.world.lens_field)
        if self._ideal is None or self._ideal[0] != key:
            self._ideal = (key, ideal_grid(lens, w, h))
        return self._ideal[1]

    def capture(self, timeout: float = 5.0) -> Frame:
        """Render one frame now; raises DeviceTimeout/DeviceDisconnected on injected faults."""
        self._require_open("capture")
        fault = self._faults.popleft() if self._faults else None
        if fault == "timeout":
            time.sleep(max(0.0, min(float(timeout), _TIMEOUT_WAIT_S)))
            raise DeviceTimeout(f"sim camera {self._identity.serial}: no frame within {timeout:g} s (injected timeout)")
        if fault == "disconnect":
            self._open = False
            raise DeviceDisconnected(
                f"sim camera {self._identity.serial}: device vanished during capture (injected disconnect)"
            )
        stamp = time.time()
        # the world at the moment of this exposure (the stage: the emulator's motion at that time)
        now = time.monotonic()
        stage, shift = self.world.stage_at(now), self.world.shift_at(now)
        offset, focus = self.world.harp_offset_deg, self.world.focus
        angle = (stage + offset) % 180.0
        index, visit = self._index_at(focus, angle, shift), self._next_visit
        seed = noise_seed(self.seed, focus, angle, index, self.world.zoom, shift, visit)  # as render() seeds it
        if self.board is not None:
            return self._board_frame(stage, focus, index, seed, stamp, self.world.tilt_at(now))
        r = self.render(index=index, angle_deg=angle, focus=focus, stage_deg=stage, shift_mm=shift, visit=visit)
        self.last_rendered = r
        image = r.image
        lens_doc = cast(Any, r).lenses["G"].to_dict() if self.cfa is not None else r.lens.to_dict()
        sim: dict[str, Any] = {
            "string_angle_deg": angle,
            "stage_deg": float(stage),
            "harp_offset_deg": float(offset),
            "lens": lens_doc,
            "seed": seed,
            "pose_index": index,
            **({"visit": visit} if visit else {}),
            "blur_px": cast(Any, r).effects.blur.sigma_px if self.realism is not None else cast(Any, r).scene.blur_px,
            "exposure_scale": self.exposure_scale(),
        }
        if self.realism_seed is not None:
            sim["realism_seed"] = self.realism_seed
        if shift is not None:  # a linear axis carries the turntable: where it was, and where it put the axis
            sim["shift_mm"] = shift
            sim["axis_offset_px"] = list(self._axis_offset(shift) or (0.0, 0.0))
        extra: dict[str, Any] = {"sim": sim}
        if self.cfa is not None:
            extra["cfa"] = self.cfa  # a raw mosaic: its pattern (the live page, the session's colour)
        if fault == "corrupt":
            h = image.shape[0]
            rng = np.random.default_rng([seed, 1_000_003])
            first = int(rng.integers(h // 4, 3 * h // 4))
            image = image.copy()
            image[first:] = rng.integers(0, np.iinfo(image.dtype).max, size=image[first:].shape, dtype=image.dtype)
            extra["corrupt"] = True
            extra["corrupt_rows"] = [first, h]
        frame = Frame(
            image=image,
            timestamp=stamp,
            exposure_us=self._exposure,
            gain_db=self._gain,
            focus=float(focus),
            camera=self._identity,
            counter=self._counter,
            extra=extra,
        )
        self._counter += 1
        pose = _pose(focus, angle, shift)
        if not visit:  # a return's frames are counted apart (set_capture_index)
            self._pose_counts[pose] = max(self._pose_counts.get(pose, 0), index + 1)
        self._next_index, self._next_visit = None, 0
        return frame
