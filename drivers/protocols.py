"""The two interfaces the station talks to: :class:`Camera` and :class:`Turntable`.

Concrete drivers (V4L2, Aravis, Zaber, GRBL, simulators) satisfy these
``typing.Protocol``\\ s structurally; the station never imports a concrete
driver, it asks :func:`drivers.open_camera` / :func:`drivers.open_turntable`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from drivers.errors import OutOfRange, with_unit


@dataclass(frozen=True)
class CameraIdentity:
    vendor: str
    model: str
    serial: str


@dataclass(frozen=True)
class Frame:
    """One captured image and what was true when it was taken.

    ``image`` is a 2-D grey array (uint8 or uint16), indexed ``image[y, x]``.
    """

    image: np.ndarray
    timestamp: float  # seconds since the epoch (time.time()) at capture
    exposure_us: float
    gain_db: float
    focus: float | None
    camera: CameraIdentity
    counter: int  # frame number since the camera was opened, from 0
    extra: dict[str, Any] = field(default_factory=dict)


@runtime_checkable
class Camera(Protocol):
    """A grey-level camera whose focus can be locked.

    Use as a context manager (``with cam: ...``) or ``open()`` / ``close()``.
    Setters read the value back from the device and return what it accepted.
    """

    def open(self) -> None: ...
    def close(self) -> None: ...
    def __enter__(self) -> Camera: ...
    def __exit__(self, *exc: object) -> None: ...

    @property
    def identity(self) -> CameraIdentity: ...
    @property
    def sensor_size(self) -> tuple[int, int]:  # (width, height) in pixels
        ...
    @property
    def pixel_format(self) -> str: ...

    def set_exposure(self, microseconds: float) -> float: ...
    def get_exposure(self) -> float: ...
    def set_gain(self, db: float) -> float: ...
    def get_gain(self) -> float: ...

    def lock_focus(self, position: float) -> float:
        """Disable autofocus and set the focus position; returns the read-back."""
        ...

    def get_focus(self) -> float | None: ...

    def capture(self, timeout: float = 5.0) -> Frame: ...


@runtime_checkable
class Turntable(Protocol):
    """A rotary stage holding the harp. Angles in degrees."""

    def open(self) -> None: ...
    def close(self) -> None: ...
    def __enter__(self) -> Turntable: ...
    def __exit__(self, *exc: object) -> None: ...

    def home(self, timeout: float = 60.0) -> None: ...
    def move_to(self, degrees: float, timeout: float = 60.0) -> float:
        """Move, return only when idle at the target; returns the position read back."""
        ...

    def position(self) -> float: ...
    def stop(self) -> None: ...
    @property
    def limits(self) -> tuple[float, float]: ...
    def status(self) -> dict[str, Any]:
        """``{"busy": bool, "warnings": [str, ...], ...}``."""
        ...


# -- Device ranges ------------------------------------------------------------------------------
# What a device accepts, read from the device when it is opened, so that a station can validate a
# plan before it creates anything and a driver refuses (OutOfRange) instead of letting the device
# clamp. Capability protocols: every driver in drivers/ has them; check with isinstance().


@dataclass(frozen=True)
class Range:
    """The closed interval ``[minimum, maximum]`` a device accepts for one setting.

    ``unit`` is ``"°"``, ``"µs"``, ``"dB"`` or ``""`` (the device's own units,
    e.g. a V4L2 focus control). ``source`` says where the range came from
    (``"device limit.min/limit.max"``, ``"GRBL $20=1, $130"``, ``"V4L2
    focus_absolute"``, ``"configured limits"``, ...). ``step`` is the
    device's increment when it has one: a commanded value is rounded to a
    multiple of it, so the read-back may differ from the command by up to
    ``step / 2``.
    """

    minimum: float
    maximum: float
    unit: str = ""
    source: str = ""
    step: float | None = None

    def __contains__(self, value: object) -> bool:
        return isinstance(value, int | float) and self.minimum <= float(value) <= self.maximum

    def check(self, device: str, what: str, value: float) -> float:
        """``value`` as a float if inside, else :class:`~drivers.errors.OutOfRange` naming ``device``."""
        v = float(value)
        if not self.minimum <= v <= self.maximum:  # NaN is outside too
            raise OutOfRange(device, what, v, self.minimum, self.maximum, self.unit, self.source)
        return v

    def tolerance(self) -> float:
        """How far a read-back may be from a command inside the range: half a ``step`` (0 without one)."""
        return 0.0 if self.step is None else 0.5 * self.step

    def __str__(self) -> str:
        return f"[{self.minimum:.10g}, {self.maximum:.10g}]{with_unit(self.unit)}"


@runtime_checkable
class TurntableRanges(Protocol):
    """A turntable whose travel is known from the device (Zaber ``limit.min``/``limit.max``,
    GRBL soft limits ``$20``/``$130`` from ``$$``), read at ``open()``."""

    def travel_range(self) -> Range:
        """The angles ``move_to`` accepts: the configured limits intersected with the device's
        (before ``open()``: the configured limits alone). Outside it ``move_to`` raises OutOfRange."""
        ...

    def device_travel_range(self) -> Range | None:
        """The travel the device reported at ``open()``, in degrees; None when it reports none
        (soft limits off, setting unsupported) or before the first ``open()``."""
        ...


@runtime_checkable
class CameraRanges(Protocol):
    """A camera whose setting ranges are read from the device at ``open()``. Each is None when
    the device has no such control; a setter given a value outside raises OutOfRange. Hardware
    drivers raise DriverError ("not open") before ``open()``."""

    def focus_range(self) -> Range | None: ...
    def exposure_range(self) -> Range | None: ...
    def gain_range(self) -> Range | None: ...


# -- Optional capabilities the executor uses -----------------------------------------------------
# Small protocols for what some drivers offer beyond Camera / Turntable; the station checks them
# with isinstance() instead of looking methods up by name.


@runtime_checkable
class Recoverable(Protocol):
    """A device that can clear a fault it stopped on (a stall, a limit, an alarm) without reopening.

    The Zaber and GRBL turntables have it; after ``recover()`` the station re-homes the stage,
    since a stepper that stalled no longer knows where it is.
    """

    def recover(self) -> list[str]:
        """Clear the fault; returns what was cleared (warning flags, alarm codes), empty when nothing was."""
        ...


@runtime_checkable
class IndexedCapture(Protocol):
    """A camera told, before each capture, which frame of the shot it is taking.

    The simulator has it (its noise is seeded per pose and capture index), so that a resumed
    session receives the same frames as an uninterrupted one; real cameras need not.
    """

    def set_capture_index(self, index: int, visit: int = 0) -> None:
        """The next capture is frame ``index`` of this shot (``attempt * frames_per_orientation + frame``), on the
        plan's ``visit``-th time at its pose (0: the first; a twin, ``capture.twin_deg``, returns: 1)."""
        ...


@runtime_checkable
class Tilting(Protocol):
    """A turntable with a second axis that tilts the calibration board (``tilt``: a
    :class:`Turntable` of its own, ``move_to`` in degrees of tilt; None when the stage has none), so that
    the session's camera-matrix stage takes its board views without a person (``intrinsics.placement:
    stage``): :attr:`drivers.zaber.ZaberTurntable.tilt`."""

    tilt: Any


@runtime_checkable
class ShiftingTurntable(Protocol):
    """A turntable carried sideways by a linear stage (``shift``: an axis of the same controller with the
    :class:`Turntable`'s methods, ``move_to`` in millimetres of travel; None when the stage has none), so that
    a session takes its shots about two places of the turntable axis in the image and the harp's own shape
    separates from the lens (:func:`pipeline.harp_shape.fit_harp_shape`, ``axis_groups``):
    :attr:`drivers.zaber.ZaberTurntable.shift`, :attr:`drivers.grbl.GrblTurntable.shift`."""

    shift: Any


@runtime_checkable
class BoardScene(Protocol):
    """A camera that can be shown a calibration board in place of the harp (the simulator: it renders
    the board on its wedge on the turntable, :meth:`drivers.sim.camera.SimulatedCamera.board_pose`).

    A session's camera-matrix stage (the ``intrinsics`` section) takes its board views with it; on a
    real station the board is placed by hand (``intrinsics.placement: operator``, or ``harp intrinsics
    --capture``). With ``placed`` (a :class:`pipeline.board_requests.ViewRequest`) the simulator stands in
    for the person too: it renders the board where the operator was asked to hold it.
    """

    def show_board(self, label: str | None, placed: Any = None) -> None:
        """Render the board ``label`` (:func:`pipeline.board.parse_board`) from the next capture on, on the
        wedge or, with ``placed``, as that request asks; None: the harp."""
        ...


@runtime_checkable
class Zoomable(Protocol):
    """A camera with a zoom lens it can drive (the simulator's zoom lens, V4L2 ``zoom_absolute``,
    GenICam ``Zoom``). Positions are in the device's own units (the simulator's: millimetres of
    focal length); a station maps each calibrated focal length to one (``zoom.positions``)."""

    def zoom_range(self) -> Range | None:
        """The positions ``set_zoom`` accepts, or None when the device has no zoom."""
        ...

    def set_zoom(self, position: float) -> float:
        """Drive the zoom to ``position``; returns the read-back. OutOfRange outside :meth:`zoom_range`."""
        ...

    def get_zoom(self) -> float | None: ...
