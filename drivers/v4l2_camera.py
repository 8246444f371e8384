"""V4L2 cameras (UVC webcams, industrial USB cameras) through ``linuxpy``.

:class:`V4L2Camera` speaks the :class:`drivers.protocols.Camera` protocol on
top of ``linuxpy.video.device.Device`` (memory-mapped streaming I/O, a
non-blocking file descriptor and ``select`` with a timeout, so a stalled
camera raises :class:`~drivers.errors.DeviceTimeout` instead of hanging).

* Format: ``GREY`` (8 bit), ``Y10`` / ``Y12`` (10/12 bits in the low bits of a little-endian 16-bit word,
  read as the words are, 0..1023 / 0..4095, like the unpacked Bayer ``RG10``), ``Y16`` (16 bit little endian),
  ``YUYV`` (luma plane kept) or ``MJPG`` (decoded to grey) -> 2-D array, see
  :mod:`drivers.frames`; or a colour sensor's raw Bayer mosaic (``RGGB``, ``GRBG``, ``GBRG``, ``BA81``
  8 bit, ``RG10`` ... ``BG12`` unpacked, ``RG16`` ... ``BYR2`` 16 bit, MIPI CSI-2 packed ``pRAA``
  ``pgAA`` ``pGAA`` ``pBAA`` 10 bit and ``pRCC`` ``pgCC`` ``pGCC`` ``pBCC`` 12 bit:
  :data:`drivers.frames.V4L2_BAYER_FORMATS`), kept as it is with its pattern in ``extra["cfa"]``, which
  the colour pipeline reads; a packed one (also the grey ``Y10P``, ``Y12P``) unpacked to ``uint16`` holding
  the 10/12-bit values sent (:func:`drivers.frames.unpack`; rows padded to ``bytesperline`` are fine). The format the driver actually accepted (``G_FMT``)
  is read back; a substituted pixel format is an error, an adjusted size is
  reported by :attr:`V4L2Camera.sensor_size`.
* Controls are found by their standard V4L2 control id (names changed
  between kernels: ``auto_exposure``/``exposure_auto``,
  ``exposure_time_absolute``/``exposure_absolute``,
  ``focus_automatic_continuous``/``focus_auto``), falling back to the names.
* Exposure: auto exposure -> Manual, then ``exposure_time_absolute`` (units of
  100 µs). Gain: ``gain`` (or ``analogue_gain``) in device units;
  ``gain_db_per_unit`` converts to dB (V4L2 does not define gain units).
* Focus: continuous autofocus off, then ``focus_absolute`` (device units).
* Zoom: ``zoom_absolute`` (device units), :meth:`V4L2Camera.set_zoom` (:class:`drivers.protocols.Zoomable`).

Ranges (:class:`drivers.protocols.CameraRanges`) are the controls'
minimum/maximum/step read at ``open()`` (``VIDIOC_QUERY_EXT_CTRL``), in µs
for exposure, dB (``gain_db_per_unit``) for gain and device units for focus.
A value outside is refused with :class:`~drivers.errors.OutOfRange` before
anything is written (never silently clipped, as the kernel would); inside,
the control rounds to its step, so the read-back returned by every setter
may differ from the command by up to half a step
(:meth:`~drivers.protocols.Range.tolerance`).

Configuration (``drivers.open_camera``), e.g.::

    camera:
      driver: v4l2
      device: /dev/video2
      pixel_format: YUYV      # GREY, Y10, Y12, Y16, YUYV, MJPG, Y10P, Y12P or a raw Bayer one (RGGB, pRAA, ...)
      width: 1920
      height: 1080
      exposure_us: 10000      # stored in 100 µs units
      gain_db: 0
      focus: 120              # focus_absolute units, locked at open
      zoom: 300               # zoom_absolute units, set at open before the focus (a zoom lens)

Unknown keys raise ``ValueError`` naming the key.
"""

from __future__ import annotations

import contextlib
import errno
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from drivers.camera_base import CameraBase
from drivers.errors import (
    CaptureError,
    DeviceDisconnected,
    DeviceRejected,
    DeviceTimeout,
    DriverError,
)
from drivers.frames import V4L2_BAYER_FORMATS, V4L2_PACKED_GREY_FORMATS, bayer_pattern, raw_mosaic, to_grey
from drivers.protocols import CameraIdentity, Frame, Range
from drivers.settings import Setting

PIXEL_FORMATS = ("GREY", "Y10", "Y12", "Y16", "YUYV", "MJPG", *V4L2_PACKED_GREY_FORMATS, *V4L2_BAYER_FORMATS)
"""The pixel formats (V4L2 fourccs) a frame is read in, best first (what ``harp devices`` proposes): grey (8 bits,
then the unpacked 10, 12 and 16 bits as the Aravis driver's ``Mono8`` ... ``Mono16``, then ``YUYV``, ``MJPG``, the
MIPI CSI-2 packed ``Y10P`` / ``Y12P`` last), then a raw Bayer mosaic (a colour sensor that offers nothing else),
the unpacked ones before the packed ``pRAA`` ... ``pBCC``, which cost an unpacking."""
EXPOSURE_UNIT_US = 100.0  # V4L2_CID_EXPOSURE_ABSOLUTE is in 100 µs units
_MANUAL_EXPOSURE = 1  # V4L2_EXPOSURE_MANUAL

# (standard control id attribute of linuxpy ControlID, names used by kernels old and new)
_CONTROLS = {
    "exposure_auto": (("EXPOSURE_AUTO",), ("auto_exposure", "exposure_auto")),
    "exposure": (("EXPOSURE_ABSOLUTE",), ("exposure_time_absolute", "exposure_absolute")),
    "gain": (("GAIN", "ANALOGUE_GAIN"), ("gain", "analogue_gain")),
    "focus_auto": (("FOCUS_AUTO",), ("focus_automatic_continuous", "focus_auto")),
    "focus": (("FOCUS_ABSOLUTE",), ("focus_absolute",)),
    "zoom": (("ZOOM_ABSOLUTE",), ("zoom_absolute",)),
}

_DISCONNECT_ERRNOS = {errno.ENODEV, errno.ENXIO, errno.EIO, errno.EBADF}


def _fourcc_code(fmt: str) -> int:
    from linuxpy.video import raw

    return int(raw.v4l2_fourcc(*fmt.ljust(4)))


class V4L2Camera(CameraBase):
    """A V4L2 capture device; satisfies :class:`drivers.protocols.Camera`.

    Parameters
    ----------
    device : str
        Device node, e.g. ``"/dev/video0"``.
    pixel_format : str
        A V4L2 fourcc of :data:`PIXEL_FORMATS`: ``"GREY"``, ``"Y10"``, ``"Y12"``, ``"Y16"``, ``"YUYV"``, ``"MJPG"``,
        the packed grey ``"Y10P"``/``"Y12P"``, or a raw Bayer one (``"RGGB"``, ``"RG10"``, ``"pRAA"``, ``"pRCC"``, ...).
    width, height : int, optional
        Requested frame size; default the device's current size.
    exposure_us, gain_db, focus : float, optional
        Applied at ``open()`` (focus via :meth:`lock_focus`).
    gain_db_per_unit : float
        dB per gain-control unit (V4L2 gain has no defined unit).
    buffers : int
        Memory-mapped buffers.
    discard_frames : int
        Frames thrown away after the queue is flushed in :meth:`capture`,
        so new exposure/gain settings have taken effect.
    """

    SETTINGS: Mapping[str, Setting] = {
        "device": Setting("the video device node", "text"),
        "pixel_format": Setting("the pixel format (FourCC)", "text", choices=PIXEL_FORMATS),
        "width": Setting("requested frame width (with height; default: the device's)", "integer", "px", 1, 16384,
                         nullable=True),
        "height": Setting("requested frame height (with width)", "integer", "px", 1, 16384, nullable=True),
        "exposure_us": Setting("exposure applied at open (null: the device's)", "number", "µs", 0.0, 1e8, low_open=True,
                               nullable=True),
        "gain_db": Setting("gain applied at open (null: the device's)", "number", "dB", -20.0, 60.0, nullable=True),
        "focus": Setting("focus applied at open (null: the device's), in the device's units", "number", "", -1e9, 1e9,
                         nullable=True),
        "zoom": Setting("the zoom lens's position set at open before the focus, in zoom_absolute units (null: none)",
                        "number", "", -1e9, 1e9, nullable=True),
        "gain_db_per_unit": Setting("dB per gain-control unit", "number", "dB", 0.0, 1000.0, low_open=True),
        "buffers": Setting("memory-mapped buffers", "integer", "", 1, 64),
        "discard_frames": Setting("frames thrown away after the queue is flushed", "integer", "", 0, 100),
    }  # fmt: skip
    CONFIG_KEYS = frozenset({"driver", *SETTINGS})
    CONFIG_NAME = "v4l2 camera"
    DEFAULT_DEVICE = "/dev/video0"

    def __init__(
        self,
        device: str = "/dev/video0",
        *,
        pixel_format: str = "GREY",
        width: int | None = None,
        height: int | None = None,
        exposure_us: float | None = None,
        gain_db: float | None = None,
        focus: float | None = None,
        zoom: float | None = None,
        gain_db_per_unit: float = 1.0,
        buffers: int = 2,
        discard_frames: int = 1,
    ):
        if pixel_format not in PIXEL_FORMATS:
            raise ValueError(f"pixel_format {pixel_format!r}: expected one of {', '.join(PIXEL_FORMATS)}")
        if (width is None) != (height is None):
            raise ValueError("width and height must be given together")
        if width is not None and height is not None and (int(width) <= 0 or int(height) <= 0):
            raise ValueError(f"frame size {width}x{height} must be positive")
        if int(buffers) < 1:
            raise ValueError(f"buffers {buffers!r}: expected >= 1")
        if int(discard_frames) < 0:
            raise ValueError(f"discard_frames {discard_frames!r}: expected >= 0")
        if not (gain_db_per_unit > 0):
            raise ValueError(f"gain_db_per_unit {gain_db_per_unit!r}: expected > 0")
        self.path = str(device)
        self._fourcc = pixel_format
        self._req_size = None if width is None or height is None else (int(width), int(height))
        self._initial = {"exposure_us": exposure_us, "gain_db": gain_db, "focus": focus, "zoom": zoom}
        self.gain_db_per_unit = float(gain_db_per_unit)
        self.n_buffers = int(buffers)
        self.discard_frames = int(discard_frames)
        # linuxpy objects (no type information): Device, VideoCapture, its frame reader,
        # the controls found by _find_control (or None), the format read back (G_FMT)
        self._dev: Any = None
        self._video: Any = None
        self._reader: Any = None
        self._ctrl: dict[str, Any] = {}
        self._format: Any = None
        self._ranges: dict[str, Range | None] = {}
        self._identity: CameraIdentity | None = None
        self._counter = 0

    @property
    def name(self) -> str:
        return f"v4l2 camera {self.path}"

    def __repr__(self) -> str:
        return f"<V4L2Camera {self.path!r} {'open' if self._dev else 'closed'}>"

    # -- open / close ---------------------------------------------------------------
    @property
    def is_open(self) -> bool:
        return self._dev is not None

    def _oserror(self, what: str, exc: OSError) -> DriverError:
        text = f"{self.name}: {what}: {exc.strerror or exc}"
        if exc.errno in _DISCONNECT_ERRNOS:
            return DeviceDisconnected(text)
        return DeviceRejected(text)

    def open(self) -> None:
        if self._dev is not None:
            return
        from linuxpy.video.device import Device

        dev = Device(self.path)
        try:
            dev.open()
        except OSError as exc:
            raise DeviceDisconnected(f"{self.name}: cannot open: {exc.strerror or exc}") from None
        self._dev = dev
        try:
            self._configure()
            self._start()
        except OSError as exc:
            self.close()
            raise self._oserror("open", exc) from None
        except BaseException:
            self.close()
            raise

    def _configure(self) -> None:
        from linuxpy.video.device import BufferType, Capability

        dev = self._dev
        info = dev.info
        caps = info.device_capabilities
        if Capability.VIDEO_CAPTURE not in caps or Capability.STREAMING not in caps:
            raise DeviceRejected(f"{self.name}: not a streaming video capture device ({caps!r})")
        self._identity = CameraIdentity(vendor=info.driver, model=info.card, serial=info.bus_info)
        offered = [f.pixel_format for f in info.formats if f.type == BufferType.VIDEO_CAPTURE]
        code = _fourcc_code(self._fourcc)
        if code not in offered:
            names = ", ".join(fourcc_name(int(p)) for p in offered) or "none"
            raise DeviceRejected(f"{self.name}: pixel format {self._fourcc} not offered (device offers {names})")
        if self._req_size is None:
            cur = dev.get_format(BufferType.VIDEO_CAPTURE)
            w, h = cur.width, cur.height
        else:
            w, h = self._req_size
        dev.set_format(BufferType.VIDEO_CAPTURE, w, h, self._fourcc.ljust(4))
        fmt = dev.get_format(BufferType.VIDEO_CAPTURE)
        if int(fmt.pixel_format) != code:
            raise DeviceRejected(
                f"{self.name}: asked for {self._fourcc}, device set {fourcc_name(int(fmt.pixel_format))}"
            )
        if fmt.width <= 0 or fmt.height <= 0:
            raise DeviceRejected(f"{self.name}: device reports frame size {fmt.width}x{fmt.height}")
        self._format = fmt
        try:
            len(dev.controls)  # enumerate (VIDIOC_QUERY_EXT_CTRL) once, here
        except RuntimeWarning as exc:  # linuxpy refuses a control whose claimed range overflows
            raise DeviceRejected(f"{self.name}: cannot enumerate controls: {exc}") from None
        self._ctrl = {key: self._find_control(*spec) for key, spec in _CONTROLS.items()}
        self._ranges = {
            "exposure": self._control_range("exposure", EXPOSURE_UNIT_US, "µs"),
            "gain": self._control_range("gain", self.gain_db_per_unit, "dB"),
            "focus": self._control_range("focus", 1.0, ""),
            "zoom": self._control_range("zoom", 1.0, ""),
        }
        self._apply_initial_settings()

    def _control_range(self, key: str, scale: float, unit: str) -> Range | None:
        ctrl = self._ctrl.get(key)
        if ctrl is None:
            return None
        step = float(ctrl.step) * scale if int(ctrl.step) > 1 else None
        lo, hi = float(ctrl.minimum) * scale, float(ctrl.maximum) * scale
        return Range(lo, hi, unit, f"V4L2 {ctrl.config_name}", step)

    def _find_control(self, ids: tuple[str, ...], names: tuple[str, ...]) -> Any:
        from linuxpy.video.device import ControlID

        controls = self._dev.controls
        for cid in ids:
            with contextlib.suppress(KeyError, AttributeError):  # id unknown to linuxpy or not on this device
                return controls[int(getattr(ControlID, cid))]
        for name in names:
            with contextlib.suppress(KeyError):  # try the next name
                return controls[name]
        return None

    def _start(self) -> None:
        from linuxpy.video.device import VideoCapture

        video = VideoCapture(self._dev, size=self.n_buffers)
        video.open()  # REQBUFS + QUERYBUF + mmap + QBUF, STREAMON
        self._video = video
        self._reader = video.buffer.frame_reader
        self._counter = 0

    def close(self) -> None:
        dev, self._dev = self._dev, None
        video, self._video, self._reader = self._video, None, None
        if video is not None:
            with contextlib.suppress(OSError, ValueError):  # a vanished device may fail to stop; we drop it anyway
                video.close()  # STREAMOFF, unmap, REQBUFS 0
        if dev is not None:
            with contextlib.suppress(OSError):  # as above
                dev.close()

    # -- properties -----------------------------------------------------------------
    # Properties never raise (``isinstance(cam, Camera)`` reads them on Python 3.11):
    # before the first open they report what is known from the configuration.
    @property
    def identity(self) -> CameraIdentity:
        """(driver, card, bus_info) from VIDIOC_QUERYCAP (placeholders before the first open)."""
        return self._identity or CameraIdentity("", "", self.path)

    @property
    def sensor_size(self) -> tuple[int, int]:
        """(width, height) of the delivered frames, as accepted by the driver.

        Before the first open: the requested size, or (0, 0) if none was given.
        """
        if self._format is not None:
            return (int(self._format.width), int(self._format.height))
        return self._req_size or (0, 0)

    @property
    def pixel_format(self) -> str:
        """The V4L2 fourcc name (``GREY``, ``Y10``, ``Y16``, ``YUYV``, ``MJPG``, ``Y10P`` or a raw Bayer one such as
        ``RGGB`` or ``pRAA``)."""
        return self._fourcc

    # -- controls -------------------------------------------------------------------
    def _control(self, key: str, what: str) -> Any:
        ctrl = self._ctrl.get(key)
        if ctrl is None:
            raise DeviceRejected(f"{self.name}: device has no {what} control")
        return ctrl

    def _write(self, ctrl: Any, value: int) -> None:
        if value < ctrl.minimum or value > ctrl.maximum:
            raise DeviceRejected(f"{self.name}: {ctrl.config_name}={value} outside [{ctrl.minimum}, {ctrl.maximum}]")
        try:
            ctrl.value = value
        except OSError as exc:
            raise self._oserror(f"set {ctrl.config_name}={value}", exc) from None
        except (AttributeError, ValueError) as exc:  # linuxpy: read-only / uncoercible
            raise DeviceRejected(f"{self.name}: set {ctrl.config_name}={value}: {exc}") from None

    def _read(self, ctrl: Any) -> int:
        try:
            return int(ctrl.value)
        except OSError as exc:
            raise self._oserror(f"read {ctrl.config_name}", exc) from None

    def set_exposure(self, microseconds: float) -> float:
        self._require_open()
        us = self._in_range("exposure", "exposure", self._exposure_value(microseconds))
        auto = self._ctrl.get("exposure_auto")
        if auto is not None and self._read(auto) != _MANUAL_EXPOSURE:
            self._write(auto, _MANUAL_EXPOSURE)
            if self._read(auto) != _MANUAL_EXPOSURE:
                raise DeviceRejected(f"{self.name}: {auto.config_name} did not switch to manual")
        ctrl = self._control("exposure", "exposure_time_absolute")
        self._write(ctrl, max(1, int(round(us / EXPOSURE_UNIT_US))))
        return self.get_exposure()

    def get_exposure(self) -> float:
        self._require_open()
        return float(self._read(self._control("exposure", "exposure_time_absolute"))) * EXPOSURE_UNIT_US

    def set_gain(self, db: float) -> float:
        self._require_open()
        ctrl = self._control("gain", "gain")
        db = self._in_range("gain", "gain", self._finite_value(float(db), "gain"))
        self._write(ctrl, int(round(db / self.gain_db_per_unit)))
        return self.get_gain()

    def get_gain(self) -> float:
        self._require_open()
        return float(self._read(self._control("gain", "gain"))) * self.gain_db_per_unit

    def lock_focus(self, position: float) -> float:
        """Continuous autofocus off, then ``focus_absolute`` = ``round(position)``."""
        self._require_open()
        ctrl = self._control("focus", "focus_absolute")
        pos = self._in_range("focus", "focus", self._finite_value(position, "focus position"))
        auto = self._ctrl.get("focus_auto")
        if auto is not None:
            if self._read(auto):
                self._write(auto, 0)
            if self._read(auto):
                raise DeviceRejected(f"{self.name}: {auto.config_name} did not switch off")
        self._write(ctrl, int(round(pos)))
        return float(self._read(ctrl))

    def get_focus(self) -> float | None:
        self._require_open()
        ctrl = self._ctrl.get("focus")
        return None if ctrl is None else float(self._read(ctrl))

    def set_zoom(self, position: float) -> float:
        """``zoom_absolute`` = ``round(position)`` (device units); OutOfRange outside its range,
        DeviceRejected for a device without the control."""
        self._require_open()
        ctrl = self._control("zoom", "zoom_absolute")
        pos = self._in_range("zoom", "zoom", self._finite_value(position, "zoom position"))
        self._write(ctrl, int(round(pos)))
        return float(self._read(ctrl))

    def get_zoom(self) -> float | None:
        self._require_open()
        ctrl = self._ctrl.get("zoom")
        return None if ctrl is None else float(self._read(ctrl))

    # -- capture --------------------------------------------------------------------
    def _next(self, deadline: float, timeout: float) -> Any:
        remaining = deadline - time.monotonic()
        frame = self._reader.read(timeout=max(0.0, remaining)) if remaining > 0 else None
        if frame is None:
            raise DeviceTimeout(f"{self.name}: no frame within {timeout:g} s")
        return frame

    def capture(self, timeout: float = 5.0) -> Frame:
        """Flush queued frames, skip ``discard_frames``, return the next frame."""
        self._require_open()
        deadline = time.monotonic() + float(timeout)
        try:
            for _ in range(self.n_buffers):  # frames that were waiting in the queue are stale
                if self._reader.read(timeout=0) is None:
                    break
            for _ in range(self.discard_frames):
                self._next(deadline, timeout)
            raw = self._next(deadline, timeout)
        except OSError as exc:
            raise self._oserror("capture", exc) from None
        now = time.time()
        fmt = self._format
        if raw.buff.bytesused == 0:
            raise CaptureError(f"{self.name}: empty buffer (sequence {raw.frame_nb})")
        buffer = (bytes(raw.data), self._fourcc, int(fmt.width), int(fmt.height), int(fmt.bytes_per_line) or None)
        pattern = bayer_pattern(self._fourcc)
        image = self._converted(to_grey if pattern is None else raw_mosaic, *buffer)
        extra: dict[str, Any] = {
            "sequence": int(raw.frame_nb),
            "device_timestamp": float(raw.timestamp),
            "pixel_format": self._fourcc,
        }
        if pattern is not None:  # a colour sensor's raw mosaic: the colour pipeline reads its pattern here
            extra["cfa"] = pattern
        return self._frame(
            np.asarray(image),
            now,
            self.get_exposure() if self._ctrl.get("exposure") is not None else float("nan"),
            self.get_gain() if self._ctrl.get("gain") is not None else float("nan"),
            extra,
        )


def fourcc_name(code: int) -> str:
    """The four-character code of a V4L2 pixel format, e.g. ``"GREY"`` for 0x59455247."""
    return "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4)).strip()
