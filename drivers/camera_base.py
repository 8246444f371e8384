"""Code the hardware camera drivers (:mod:`drivers.aravis_camera`,
:mod:`drivers.v4l2_camera`) share around their device-specific parts.

:class:`CameraBase` gives a driver of :class:`drivers.protocols.Camera`:
``from_config`` (unknown keys refused), the context manager, the "not open"
check, the settings applied at ``open()``, the checks of requested values
and the :class:`~drivers.protocols.Frame` numbering. A subclass provides
``open``/``close``/``is_open``, the setters and getters, ``capture`` and
``name``, and keeps ``self._initial`` (``{"exposure_us", "gain_db",
"focus"}``, each None or a value), ``self._identity``, ``self._counter``
(reset to 0 by ``open``) and ``self._ranges`` (``{"exposure", "gain",
"focus"}`` -> :class:`~drivers.protocols.Range` or None, read from the
device by ``open`` before the initial settings are applied).

The base gives :class:`drivers.protocols.CameraRanges` from ``self._ranges``
and :meth:`CameraBase._in_range`, the check every setter makes before it
writes to the device, and :meth:`CameraBase._converted`, a buffer's
conversion (:mod:`drivers.frames`) whose error names the camera.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Callable, Mapping
from typing import Any, Self

import numpy as np

from drivers.config_keys import check_config_keys
from drivers.errors import CaptureError, DeviceRejected, DriverError
from drivers.protocols import CameraIdentity, Frame, Range
from drivers.settings import Setting


class CameraBase(abc.ABC):
    """Base of the hardware camera drivers; see the module docstring."""

    #: every key ``from_config`` accepts (``driver`` included)
    CONFIG_KEYS: frozenset[str] = frozenset({"driver"})
    #: each key's type, unit and range (:mod:`drivers.settings`), checked by ``from_config``
    SETTINGS: Mapping[str, Setting] = {}
    #: how ``from_config`` errors name the driver, e.g. ``"v4l2 camera"``
    CONFIG_NAME = "camera"
    #: ``device`` when the configuration has none
    DEFAULT_DEVICE: str | None = None

    # kept by the subclass (module docstring)
    _initial: dict[str, float | None]
    _identity: CameraIdentity | None
    _counter: int
    _ranges: dict[str, Range | None]

    @classmethod
    def from_config(cls, cfg: dict[str, Any], **ctx: Any) -> Self:
        """Create (not open) from a config mapping; unknown keys and values outside ``SETTINGS`` raise ``ValueError``."""
        check_config_keys(cls.CONFIG_NAME, cfg, cls.SETTINGS)
        kw = {k: v for k, v in cfg.items() if k != "driver"}
        make: Callable[..., Self] = cls  # the subclass's constructor: (device, **settings)
        return make(kw.pop("device", cls.DEFAULT_DEVICE), **kw)

    # -- the device-specific part ---------------------------------------------------
    @property
    @abc.abstractmethod
    def name(self) -> str:
        """Short description starting every error message, e.g. ``"v4l2 camera /dev/video0"``."""

    @property
    @abc.abstractmethod
    def is_open(self) -> bool: ...

    @property
    @abc.abstractmethod
    def identity(self) -> CameraIdentity: ...

    @abc.abstractmethod
    def open(self) -> None: ...

    @abc.abstractmethod
    def close(self) -> None: ...

    @abc.abstractmethod
    def set_exposure(self, microseconds: float) -> float: ...

    @abc.abstractmethod
    def set_gain(self, db: float) -> float: ...

    @abc.abstractmethod
    def lock_focus(self, position: float) -> float: ...

    @abc.abstractmethod
    def get_focus(self) -> float | None: ...

    # -- shared -----------------------------------------------------------------------
    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- ranges (drivers.protocols.CameraRanges) ------------------------------------
    def focus_range(self) -> Range | None:
        """The focus feature's/control's range read at ``open()`` (None: no focus control)."""
        self._require_open()
        return self._ranges.get("focus")

    def exposure_range(self) -> Range | None:
        """The exposure range in µs read at ``open()`` (None: the device gives none)."""
        self._require_open()
        return self._ranges.get("exposure")

    def gain_range(self) -> Range | None:
        """The gain range in dB read at ``open()`` (None: the device gives none)."""
        self._require_open()
        return self._ranges.get("gain")

    def zoom_range(self) -> Range | None:
        """The zoom control's/feature's range read at ``open()`` (None: no zoom; :class:`~drivers.protocols.Zoomable`)."""
        self._require_open()
        return self._ranges.get("zoom")

    def _in_range(self, key: str, what: str, value: float) -> float:
        """``value`` checked against the range ``key`` (``OutOfRange`` outside; unchecked without one)."""
        rng = self._ranges.get(key)
        return float(value) if rng is None else rng.check(self.name, what, value)

    def _require_open(self) -> None:
        if not self.is_open:
            raise DriverError(f"{self.name}: camera is not open")

    def _apply_initial_settings(self) -> None:
        """Exposure, gain, the zoom (a zoom lens's focal length moves its focus), then focus (locked),
        as configured; called by ``open()``."""
        if self._initial["exposure_us"] is not None:
            self.set_exposure(self._initial["exposure_us"])
        if self._initial["gain_db"] is not None:
            self.set_gain(self._initial["gain_db"])
        zoom = self._initial.get("zoom")
        if zoom is not None:
            set_zoom = getattr(self, "set_zoom", None)
            if set_zoom is None:
                raise DeviceRejected(f"{self.name}: this driver cannot drive a zoom")
            set_zoom(zoom)
        if self._initial["focus"] is not None:
            self.lock_focus(self._initial["focus"])

    def _exposure_value(self, microseconds: float) -> float:
        """``microseconds`` as a float; ``ValueError`` unless finite and positive."""
        us = float(microseconds)
        if not math.isfinite(us) or us <= 0:
            raise ValueError(f"{self.name}: exposure must be a positive number of µs, got {microseconds!r}")
        return us

    def _finite_value(self, value: float, what: str) -> float:
        """``value`` as a float; ``ValueError`` naming ``what`` unless finite."""
        v = float(value)
        if not math.isfinite(v):
            raise ValueError(f"{self.name}: {what} must be finite, got {value!r}")
        return v

    def _converted(self, convert: Callable[..., np.ndarray], *args: Any) -> np.ndarray:
        """``convert(*args)``: a buffer's conversion (:mod:`drivers.frames`); its :class:`CaptureError` (a buffer
        that does not hold the frame its format and size say) raised again, one line, with the camera's name first."""
        try:
            return convert(*args)
        except CaptureError as exc:
            raise CaptureError(f"{self.name}: {exc}") from None

    def _frame(
        self, image: np.ndarray, timestamp: float, exposure_us: float, gain_db: float, extra: dict[str, Any]
    ) -> Frame:
        """The next :class:`Frame` (focus read back now, counter advanced)."""
        frame = Frame(
            image=image,
            timestamp=timestamp,
            exposure_us=exposure_us,
            gain_db=gain_db,
            focus=self.get_focus(),
            camera=self.identity,
            counter=self._counter,
            extra=extra,
        )
        self._counter += 1
        return frame
