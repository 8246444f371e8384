"""The simulated camera's configuration keys: each with its type, unit and range.

:data:`SETTINGS` is the ``camera`` section a configuration gives the simulated camera
(``driver: sim``), read by :meth:`drivers.sim.camera.SimulatedCamera.from_config` and shown by
the configuration reference (:mod:`station.config.reference`, through the class's ``SETTINGS``);
:data:`SCENE_SETTINGS` are the harp scene's keys among them (:class:`pipeline.render.HarpScene`'s
fields).
"""

from __future__ import annotations

from drivers.settings import SEED_MAX, Setting
from drivers.sim.lens import FOCUS_RANGE, ZOOM_FOCAL_RANGE_MM
from pipeline.cfa import CFA_PATTERNS

EXPOSURE_RANGE_US = (20.0, 1_000_000.0)
GAIN_RANGE_DB = (0.0, 24.0)


def _level(doc: str, low_open: bool = False) -> Setting:
    """A grey level on the 8-bit scale."""
    return Setting(doc, "number", "grey levels (8-bit)", 0.0, 255.0, low_open=low_open)


SCENE_SETTINGS: dict[str, Setting] = {
    "spacing_px": Setting("the harp's string pitch in the image", "number", "px", 4.0, 10000.0),
    "string_width_px": Setting(
        "the strings' width in the image (less than spacing_px)", "number", "px", 0.0, 1000.0, low_open=True
    ),
    "phase_px": Setting(
        "offset of string 0 from the image centre, along the normal", "number", "px", -10000.0, 10000.0
    ),
    "background": _level("the lit sheet's level at the image centre", low_open=True),
    "string_level": _level("the level inside a string"),
    "blur_px": Setting("standard deviation of the optical PSF", "number", "px", 0.0, 100.0),
    "vignetting": Setting("fractional fall-off at the image corners", "number", "", 0.0, 1.0, high_open=True),
    "dust": Setting("number of dust shadows on the sensor", "integer", "", 0, 1000),
    "dust_seed": Setting("seed placing the dust shadows", "integer", "", 0, SEED_MAX),
    "frame": Setting("render the dark harp frame (a bar parallel to the strings)", "boolean"),
    "frame_level": _level("the frame's level"),
    "frame_depth_px": Setting("how far the frame enters the image", "number", "px", 0.0, 10000.0),
    "frame_side": Setting("the side the frame enters by (+1: towards +n)", "integer", choices=(1, -1)),
}
"""The scene keys of the simulated camera (:class:`pipeline.render.HarpScene`'s fields): type, unit, range."""

SETTINGS: dict[str, Setting] = {
    "width": Setting("sensor width", "integer", "px", 16, 8192),
    "height": Setting("sensor height", "integer", "px", 16, 8192),
    "bit_depth": Setting("bits per pixel (Mono8, Mono16)", "integer", choices=(8, 16)),
    "pixel_format": Setting("an alternative to bit_depth", "text", choices=("Mono8", "Mono16")),
    "seed": Setting("base seed of the sensor noise", "integer", "", 0, SEED_MAX),
    "noise_sigma": _level("read noise at 0 dB"),
    "shot_noise": Setting("add shot noise (grows with gain)", "boolean"),
    "electrons_per_level": Setting("electrons per grey level at 0 dB (shot noise)", "number", "e-", 0.0, 1e6,
                                   low_open=True),
    "exposure_us": Setting("initial exposure", "number", "µs", *EXPOSURE_RANGE_US),
    "gain_db": Setting("initial gain", "number", "dB", *GAIN_RANGE_DB),
    "reference_exposure_us": Setting("exposure at which the scene has its nominal levels", "number", "µs", 0.0, 1e8,
                                     low_open=True),
    "serial": Setting("the serial number the camera reports", "text"),
    "focus": Setting("initial focus of the simulated lens", "number", "", *FOCUS_RANGE),
    "harp_offset_deg": Setting("the strings' angle at stage 0 (the simulated world's)", "number", "deg", -360.0,
                               360.0),
    "best_focus": Setting("the focus setting that is sharp (null: every setting sharp)", "number", "", *FOCUS_RANGE,
                          nullable=True),
    "defocus_blur_px": Setting("blur growth away from best_focus (needs best_focus)", "number", "px", 0.0, 1000.0),
    "realism_seed": Setting("render with the realistic simulator drawn from this seed (null: clean renderer)",
                            "integer", "", 0, SEED_MAX, nullable=True),
    "jpeg_quality": Setting("JPEG quality of realistic 8-bit frames (null: none)", "integer", "", 1, 100,
                            nullable=True),
    "zoom": Setting("the simulated zoom lens, at this focal length (absent: the fixed demo lens)", "number", "mm",
                    *ZOOM_FOCAL_RANGE_MM),
    "board": Setting("render this calibration board instead of the harp (a label of pipeline.board)", "text"),
    "board_tilt_deg": Setting("the board's tilt on its wedge", "number", "deg", 0.0, 80.0, high_open=True),
    "focal_px": Setting("the camera matrix's focal length of board frames (default: in proportion to width)",
                        "number", "px", 0.0, 1e6, low_open=True),
    "cfa": Setting("a Bayer colour sensor with this pattern: raw mosaics (null: a grey sensor)", "text",
                   choices=CFA_PATTERNS, nullable=True),
    "tca_red": Setting("red's magnification against green (lateral chromatic aberration; needs cfa)", "number", "",
                       -0.01, 0.01),
    "tca_red_radial": Setting("red's magnification growth to the corners (rho^2 term; needs cfa)", "number", "",
                              -0.01, 0.01),
    "tca_blue": Setting("blue's magnification against green (needs cfa)", "number", "", -0.01, 0.01),
    "tca_blue_radial": Setting("blue's magnification growth to the corners (needs cfa)", "number", "", -0.01, 0.01),
    "backlight_gradient": Setting("the back-light's brightness slope across the harp, turning with it (needs cfa)",
                                  "number", "", -0.5, 0.5),
    **SCENE_SETTINGS,
}  # fmt: skip
"""The keys of the simulated camera's configuration section, each with its type, unit and range."""
CONFIG_KEYS = ("driver", *SETTINGS)
"""Keys accepted by :meth:`SimulatedCamera.from_config`."""
