"""The two interfaces the station talks to: :class:`Camera` and :class:`Turntable`.

Concrete drivers (V4L2, Aravis, Zaber, GRBL, simulators) satisfy these
``typing.Protocol``\\ s structurally; the station never imports a concrete
driver, it asks :func:`drivers.open_camera` / :func:`drivers.open_turntable`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np


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
