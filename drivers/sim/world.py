"""The simulated physical world shared by the turntable emulator and the camera.

The stage angle is not a value one simulator writes and another reads (a
copy is always late by however long the writing thread was descheduled);
it is a *function of time*. A turntable emulator hands the world its own
motion model with :meth:`SimWorld.drive_stage` — the same function from
which it answers position queries — and the camera evaluates it at the
moment of its exposure (:meth:`SimWorld.stage_at`). When the emulator has
replied "idle at θ" for time *t*, the axis is at rest at θ from *t* until
the next command, so any exposure after that reply sees exactly θ: the
frame and the read-back cannot disagree, whatever the thread scheduling.

The calibration board's tilt (:meth:`SimWorld.drive_tilt`) and the linear stage that carries the
turntable sideways (:meth:`SimWorld.drive_shift`, millimetres) are functions of time the same way, each
handed over by the emulator that has the axis. A shift of ``s`` mm moves the turntable axis in the image
by ``s * shift_px_per_mm`` pixels in the direction ``shift_direction_deg``
(:meth:`SimWorld.axis_offset_px`).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from drivers.sim.lens import UnitField
    from pipeline.lens_population import UnitSpread


class SimWorld:
    """Ground truth of the simulated station, shared between simulators.

    Parameters
    ----------
    stage_deg : float
        Stage angle while no emulator drives the stage (see :meth:`set_stage`).
    focus : float
        Focus position; written by the simulated camera's ``lock_focus``.
    harp_offset_deg : float
        Angle of the strings in the image when the stage is at 0°.
    lens_unit : UnitSpread or None
        Which unit of the demo lens is on the camera (:func:`drivers.sim.lens.lens_unit`: its
        manufacturing deviations); None is the nominal lens.
    zoom : float or None
        Focal length (mm) of the simulated zoom lens (:func:`drivers.sim.lens.zoom_lens`), written by
        the camera's ``set_zoom``; None: the camera has the fixed demo lens.
    shift_direction_deg : float
        The image direction (degrees from +x, the columns, towards +y, the rows) in which a positive move
        of the linear stage carries the turntable axis.
    shift_px_per_mm : float or None
        Image pixels per mm of the linear stage's travel, at the harp; None: not known (a camera then
        refuses to render the harp moved off its place, :meth:`shift_offset_px`).
    lens_field : UnitField or None
        That unit's residual field (:func:`drivers.sim.lens.lens_field`); None: none.
    lens_centre_sd_px : float
        How far (standard deviation per axis, px) the lens's distortion centre moves between turntable poses
        (:meth:`drivers.sim.camera.SimulatedCamera.lens_at`); 0: a stable lens.

    Thread-safe: the stage function is called under the emulator's own lock,
    ``focus`` and ``harp_offset_deg`` are plain floats.
    """

    def __init__(
        self,
        stage_deg: float = 0.0,
        focus: float = 0.0,
        harp_offset_deg: float = 0.0,
        lens_unit: UnitSpread | None = None,
        shift_direction_deg: float = 0.0,
        shift_px_per_mm: float | None = None,
        lens_field: UnitField | None = None,
        lens_centre_sd_px: float = 0.0,
    ):
        if shift_px_per_mm is not None and not (math.isfinite(shift_px_per_mm) and shift_px_per_mm > 0):
            raise ValueError(f"shift_px_per_mm must be a positive number or None, got {shift_px_per_mm!r}")
        self._stage_deg = float(stage_deg)
        self.focus = float(focus)
        self.harp_offset_deg = float(harp_offset_deg)
        self.lens_unit = lens_unit
        self.lens_field = lens_field
        if not (math.isfinite(lens_centre_sd_px) and lens_centre_sd_px >= 0):
            raise ValueError(f"lens_centre_sd_px must be a number >= 0, got {lens_centre_sd_px!r}")
        self.lens_centre_sd_px = float(lens_centre_sd_px)
        self.zoom: float | None = None
        self._drive: Callable[[float], float] | None = None
        self._driver_name: str | None = None
        self._tilt: Callable[[float], float] | None = None
        self._shift: Callable[[float], float] | None = None
        self.shift_direction_deg = float(shift_direction_deg)
        self.shift_px_per_mm = None if shift_px_per_mm is None else float(shift_px_per_mm)
        self._lock = threading.Lock()

    # -- the stage ---------------------------------------------------------------
    def drive_stage(self, stage_at: Callable[[float], float], name: str) -> None:
        """Let ``stage_at(t)`` (degrees at ``time.monotonic()`` time ``t``) define the stage.

        Called once by a turntable emulator (``name`` says which, for errors).
        A second emulator on the same world is refused with ``ValueError``.
        """
        with self._lock:
            if self._drive is not None:
                raise ValueError(f"the simulated stage is already driven by the {self._driver_name}; one per world")
            self._drive = stage_at
            self._driver_name = name

    @property
    def driven(self) -> bool:
        """True when a turntable emulator drives the stage."""
        return self._drive is not None

    def stage_at(self, t: float | None = None) -> float:
        """The stage angle in degrees at monotonic time ``t`` (default: now)."""
        drive = self._drive
        if drive is None:
            return self._stage_deg
        return float(drive(time.monotonic() if t is None else t))

    @property
    def stage_deg(self) -> float:
        """The stage angle now, in degrees."""
        return self.stage_at()

    def set_stage(self, deg: float) -> None:
        """Put the stage at ``deg`` by hand (tests of the camera alone).

        ``ValueError`` when an emulator drives the stage: only its motion moves it then.
        """
        if self._drive is not None:
            raise ValueError(f"the simulated stage is driven by the {self._driver_name}; move it through the turntable")
        self._stage_deg = float(deg)

    # -- the board's tilt (a second axis of the stage) ---------------------------------
    def drive_tilt(self, tilt_at: Callable[[float], float], name: str) -> None:
        """Let ``tilt_at(t)`` (degrees at monotonic time ``t``) define the calibration board's tilt (an
        emulator with a tilt axis, ``name`` for errors); a second one is refused with ``ValueError``."""
        with self._lock:
            if self._tilt is not None:
                raise ValueError(f"the simulated board's tilt is already driven; one per world ({name})")
            self._tilt = tilt_at

    def tilt_at(self, t: float | None = None) -> float | None:
        """The board's tilt in degrees at monotonic time ``t`` (default now); None: no axis tilts it (the
        camera's ``board_tilt_deg`` wedge)."""
        tilt = self._tilt
        return None if tilt is None else float(tilt(time.monotonic() if t is None else t))

    # -- the linear stage that carries the turntable sideways (another axis) -------------
    def drive_shift(self, shift_at: Callable[[float], float], name: str) -> None:
        """Let ``shift_at(t)`` (mm at monotonic time ``t``) define where the linear stage has carried the
        turntable (an emulator with a shift axis, ``name`` for errors); a second one is refused with
        ``ValueError``."""
        with self._lock:
            if self._shift is not None:
                raise ValueError(f"the simulated turntable's shift is already driven; one per world ({name})")
            self._shift = shift_at

    def shift_at(self, t: float | None = None) -> float | None:
        """The linear stage's position in mm at monotonic time ``t`` (default now); None: no linear axis
        carries the turntable (its axis stays where the scene puts it)."""
        shift = self._shift
        return None if shift is None else float(shift(time.monotonic() if t is None else t))

    def shift_offset_px(self, t: float | None = None) -> tuple[float, float]:
        """How far the linear stage has moved the turntable axis in the image at time ``t`` (default now):
        :meth:`axis_offset_px` of :meth:`shift_at`, ``(0.0, 0.0)`` when no axis carries the turntable."""
        return self.axis_offset_px(self.shift_at(t) or 0.0)

    def axis_offset_px(self, shift_mm: float) -> tuple[float, float]:
        """The turntable axis's move in the image for the linear stage at ``shift_mm``:
        ``shift_mm * shift_px_per_mm * (cos d, sin d)`` with ``d = shift_direction_deg``; ``(0.0, 0.0)`` at 0.
        ``ValueError`` for a moved axis in a world without ``shift_px_per_mm``."""
        if not shift_mm:
            return (0.0, 0.0)
        if self.shift_px_per_mm is None:
            raise ValueError(
                f"the simulated turntable is shifted {shift_mm:g} mm but the world has no shift_px_per_mm (image "
                "pixels per mm of travel): give it to SimWorld"
            )
        d = math.radians(self.shift_direction_deg)
        r = float(shift_mm) * self.shift_px_per_mm
        return (r * math.cos(d), r * math.sin(d))

    # -- what the camera sees ----------------------------------------------------
    def string_angle_deg(self, t: float | None = None) -> float:
        """Angle of the strings in the ideal image at time ``t`` (default now), in [0, 180)."""
        return (self.stage_at(t) + self.harp_offset_deg) % 180.0

    def __repr__(self) -> str:
        stage = f"driven by the {self._driver_name}" if self._drive else f"{self._stage_deg:g}°"
        return f"SimWorld(stage {stage}, focus {self.focus:g}, harp offset {self.harp_offset_deg:g}°)"
