"""GenICam cameras (GigE Vision, USB3 Vision, Aravis' own fakes) through Aravis 0.8.

:class:`AravisCamera` speaks the :class:`drivers.protocols.Camera` protocol
through Aravis' GObject introspection bindings (``gi.repository.Aravis``,
Debian packages ``gir1.2-aravis-0.8`` + ``libaravis-0.8-0``; pip
``PyGObject<3.51``).

GenICam features used, chosen by what the device's XML declares:

* exposure: ``ExposureTime`` (SFNC, float, µs) else ``ExposureTimeAbs``
  (older float name); ``ExposureAuto`` is switched ``Off`` when present;
* gain: ``Gain`` (SFNC, float, dB) else ``GainRaw`` (integer device units,
  converted with ``gain_db_per_raw`` dB per unit); ``GainAuto`` -> ``Off``;
* pixel format ``Mono8`` / ``Mono16`` (also unpacked ``Mono10`` / ``Mono12``; packed PFNC ``Mono10p`` /
  ``Mono12p`` and GigE Vision ``Mono10Packed`` / ``Mono12Packed``, unpacked to ``uint16`` with the 10/12-bit
  values sent, :func:`drivers.frames.unpack`), or a colour sensor's raw Bayer mosaic (``BayerRG8``,
  ``BayerGR12``, ... ``BayerBG16``, packed ``BayerRG10p`` ... ``BayerBG12p`` and ``BayerRG10Packed`` ...
  ``BayerBG12Packed``, :data:`drivers.frames.GENICAM_BAYER_FORMATS`):
  the frame is the mosaic as the sensor gave it (nothing demosaiced) with its pattern in
  ``extra["cfa"]`` (``"RGGB"`` ...), read from each buffer's own pixel format, which the colour
  pipeline measures (lateral chromatic aberration, vignetting per channel); a camera that pads its rows
  (``PaddingX``) is read with the stride its buffer's leader states (``padding_x``;
  :func:`drivers.frames.genicam_stride`);
* trigger: ``software`` (``TriggerSource=Software`` + ``TriggerSoftware``),
  ``off`` (free running; frames older than the ``capture()`` call are
  dropped) or any other ``TriggerSource`` name such as ``Line0`` (capture
  waits for the external pulse);
* focus is not standardised: ``focus_feature`` names it (Integer or Float
  node, ``focus_type`` ``auto``/``integer``/``float``) and the optional
  ``autofocus_feature`` (Enumeration/String set to ``autofocus_off``, default
  ``"Off"``; Boolean set to false; Integer set to ``autofocus_off``, default 0).

Ranges (:class:`drivers.protocols.CameraRanges`) are the GenICam ``Min`` /
``Max`` (and ``Inc``) of the exposure, gain and focus features, read at
``open()``; a setter given a value outside raises
:class:`~drivers.errors.OutOfRange` before anything is written. Every setter
writes with Aravis' range checking on too and returns the value read back
from the device. A buffer that does not arrive within the
``capture`` timeout raises :class:`~drivers.errors.DeviceTimeout`; a buffer
with a non-success status raises :class:`~drivers.errors.CaptureError`.

Device ids are what ``arv-tool-0.8`` lists (``"<vendor>-<model>-<serial>"``),
an IP address for GigE Vision, or ``"Fake_1"`` for Aravis' in-process fake
camera (the ``Fake`` interface is enabled automatically; ``fake_genicam_xml``
replaces its GenICam description, see ``drivers/data/fake-focus.xml``).

Configuration (``drivers.open_camera``), e.g.::

    camera:
      driver: aravis
      device: "192.168.10.20"      # or "Basler-acA2440-40123456", "Fake_1"
      pixel_format: Mono16
      exposure_us: 20000
      gain_db: 0
      trigger: software            # or "off", "Line0", ...
      focus_feature: FocusPos      # vendor feature name (Integer or Float)
      autofocus_feature: FocusAuto # optional, set to autofocus_off ("Off")
      zoom: 800                    # a zoom lens: its Zoom feature (zoom_feature) set at open
      focus: 412                   # optional: locked at open

Unknown keys raise ``ValueError`` naming the key.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import os
import tempfile
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from drivers.camera_base import CameraBase
from drivers.errors import (
    CaptureError,
    DeviceDisconnected,
    DeviceRejected,
    DeviceTimeout,
    DriverError,
)
from drivers.frames import (
    BAYER_FORMATS,
    GENICAM_BAYER_FORMATS,
    GENICAM_PACKED_MONO_FORMATS,
    bayer_pattern,
    genicam_image,
)
from drivers.protocols import CameraIdentity, Frame, Range
from drivers.settings import Setting

#: GenICam XML for Aravis' fake camera with SFNC exposure/gain names and focus features
FAKE_FOCUS_XML = Path(__file__).resolve().parent / "data" / "fake-focus.xml"

GREY_PIXEL_FORMATS = ("Mono8", "Mono10", "Mono12", "Mono16", *GENICAM_PACKED_MONO_FORMATS)
PIXEL_FORMATS = (*GREY_PIXEL_FORMATS, *GENICAM_BAYER_FORMATS)
"""The pixel formats a frame is read in: grey, or a raw Bayer mosaic (GenICam PFNC names, and the GigE Vision
``...Packed`` ones); in each kind the unpacked ones first, then the packed (PFNC ``Mono10p`` ... ``BayerBG12p``,
then GigE Vision ``Mono10Packed`` ... ``BayerBG12Packed``), which the camera sends in fewer bytes and the
driver unpacks (:func:`drivers.frames.unpack`)."""
#: PFNC codes of the packed formats Aravis 0.8 has no constant for (PFNC value list: ``Mono10p``, ``Mono12p``)
PFNC_CODES = {"Mono10p": 0x010A0046, "Mono12p": 0x010C0047}
EXPOSURE_FEATURES = ("ExposureTime", "ExposureTimeAbs")
GAIN_FEATURES = ("Gain", "GainRaw")


T = TypeVar("T")

_ARAVIS: Any = None  # the gi.repository.Aravis module, once imported
_FAKE_XML_STATE: dict[str, str | None] = {"current": None, "embedded": None}


def aravis_pixel_format(Aravis: Any, name: str) -> int:
    """Aravis' constant of a PFNC pixel format name (``"Mono12"`` -> ``PIXEL_FORMAT_MONO_12``, ``"BayerGR8"`` ->
    ``PIXEL_FORMAT_BAYER_GR_8``, ``"BayerRG12p"`` -> ``PIXEL_FORMAT_BAYER_RG_12P``, ``"Mono12Packed"`` ->
    ``PIXEL_FORMAT_MONO_12_PACKED``); the PFNC code itself (:data:`PFNC_CODES`) where Aravis has none."""
    kind, rest = ("BAYER_" + name[5:7].upper(), name[7:]) if name.startswith("Bayer") else ("MONO", name[4:])
    rest = rest.replace("Packed", "_PACKED").upper()
    constant = getattr(Aravis, f"PIXEL_FORMAT_{kind}_{rest}", None)
    if constant is None and name in PFNC_CODES:
        return PFNC_CODES[name]
    if constant is None:
        raise ValueError(f"Aravis has no pixel format {name!r} (PIXEL_FORMAT_{kind}_{rest})")
    return int(constant)


@functools.cache
def _format_names(Aravis: Any) -> dict[int, str]:
    """Aravis' pixel format code -> the name of :data:`PIXEL_FORMATS` (built once: every buffer asks)."""
    return {aravis_pixel_format(Aravis, n): n for n in PIXEL_FORMATS}


def aravis_module() -> Any:
    """Import ``gi.repository.Aravis`` 0.8 once, with an installation hint on failure."""
    global _ARAVIS
    if _ARAVIS is None:
        try:
            import gi

            gi.require_version("Aravis", "0.8")
            from gi.repository import Aravis
        except (ImportError, ValueError) as exc:
            raise DriverError(
                "Aravis 0.8 is not available (install gir1.2-aravis-0.8 and PyGObject<3.51; "
                f"see scripts/setup.sh): {exc}"
            ) from None
        _ARAVIS = Aravis
    return _ARAVIS


def _gerror_text(exc: BaseException) -> str:
    return getattr(exc, "message", None) or str(exc)


# ArvDeviceError codes that mean the device stopped answering (unplugged, powered off, cable cut),
# as opposed to refusing a value: NOT_CONNECTED, TRANSFER_ERROR, TIMEOUT
_GONE_CODES = frozenset({2, 4, 5})


def _device_gone(exc: BaseException) -> bool:
    return getattr(exc, "domain", None) == "arv-device-error-quark" and getattr(exc, "code", None) in _GONE_CODES


def _release_in_background(doomed: list[Any]) -> None:
    """Drop the Aravis objects in ``doomed`` (the only references left to them) in a daemon
    thread: the finalizers of a device that no longer answers wait out Aravis' GVCP timeouts
    (about 7 s for a GigE camera), which would otherwise block ``close()``; they wait without
    holding the GIL."""
    threading.Thread(target=doomed.clear, name="aravis-release", daemon=True).start()


def _remove_quietly(path: str) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


def _select_fake_xml(Aravis: Any, path: str | None) -> None:
    """Make the next ``Fake_*`` device use ``path`` (or Aravis' embedded XML when None).

    ``arv_set_fake_camera_genicam_filename`` is process-global and cannot be
    reset to NULL from Python, so "embedded" is restored by writing the
    embedded resource to a temporary file once.
    """
    if path is None:
        if _FAKE_XML_STATE["current"] is None:
            return
        if _FAKE_XML_STATE["embedded"] is None:
            from gi.repository import Gio

            data = Gio.resources_lookup_data("/org/aravis/arv-fake-camera.xml", Gio.ResourceLookupFlags.NONE).get_data()
            with tempfile.NamedTemporaryFile("wb", prefix="harp-arv-fake-", suffix=".xml", delete=False) as fh:
                fh.write(data)
            _FAKE_XML_STATE["embedded"] = fh.name
            atexit.register(_remove_quietly, fh.name)  # one per process, gone when it ends
        path = _FAKE_XML_STATE["embedded"]
    else:
        path = str(Path(path).resolve())
        if not Path(path).is_file():
            raise ValueError(f"fake_genicam_xml: no such file {path}")
    if _FAKE_XML_STATE["current"] != path:
        Aravis.set_fake_camera_genicam_filename(path)
        _FAKE_XML_STATE["current"] = path


class AravisCamera(CameraBase):
    """A GenICam camera opened through Aravis; satisfies :class:`drivers.protocols.Camera`.

    Parameters
    ----------
    device : str or None
        Aravis device id (``"Fake_1"``, ``"192.168.1.20"``,
        ``"Basler-acA1300-12345678"``); None opens the first device found.
    pixel_format : str
        ``"Mono8"``, ``"Mono16"``, ``"Mono10"``, ``"Mono12"``, a packed ``"Mono12p"`` or ``"Mono12Packed"``,
        or a raw Bayer format such as ``"BayerRG8"`` or ``"BayerRG12p"`` (:data:`PIXEL_FORMATS`).
    exposure_us, gain_db, focus : float, optional
        Applied at ``open()`` (focus via :meth:`lock_focus`).
    trigger : str
        ``"software"`` (default), ``"off"`` (free running) or a
        ``TriggerSource`` name such as ``"Line0"``.
    roi : (x, y, width, height), optional
        Image region; default the full sensor.
    focus_feature, focus_type, autofocus_feature, autofocus_off
        Vendor focus features (see module docstring).
    zoom, zoom_feature : optional
        A zoom lens: the ``zoom_feature`` (default ``"Zoom"``; Integer or Float, device units) set to
        ``zoom`` at ``open()`` before the focus; :meth:`set_zoom` (:class:`drivers.protocols.Zoomable`).
    gain_db_per_raw : float
        dB per unit when the device only has ``GainRaw``.
    buffers : int
        Stream buffers queued to Aravis.
    fake_genicam_xml : str, optional
        GenICam XML for ``Fake_*`` devices (Aravis' embedded XML when None).
    packet_size : int, optional
        GigE Vision stream packet size in bytes.
    """

    SETTINGS: Mapping[str, Setting] = {
        "device": Setting("the camera id, e.g. Basler-40012345 (see harp devices); null: the first camera found",
                          "text", nullable=True),
        "pixel_format": Setting("the pixel format", "text", choices=PIXEL_FORMATS),
        "exposure_us": Setting("exposure applied at open (null: the device's)", "number", "µs", 0.0, 1e8, low_open=True,
                               nullable=True),
        "gain_db": Setting("gain applied at open (null: the device's)", "number", "dB", -20.0, 60.0, nullable=True),
        "focus": Setting("focus applied at open (null: the device's), in the device's units", "number", "", -1e9, 1e9,
                         nullable=True),
        "trigger": Setting("'software', 'off' or a TriggerSource name such as Line0", "text"),
        "roi": Setting("image region [x, y, width, height] (null: the full sensor)", "integers", "px", 0, 100000,
                       length=(4, 4), nullable=True),
        "zoom": Setting("the zoom lens's position set at open before the focus, in the device's units (null: none)",
                        "number", "", -1e9, 1e9, nullable=True),
        "zoom_feature": Setting("the zoom feature (Integer or Float node)", "text"),
        "focus_feature": Setting("the vendor's focus feature (Integer or Float node)", "text", nullable=True),
        "focus_type": Setting("how the focus feature is written", "text", choices=("auto", "integer", "float")),
        "autofocus_feature": Setting("the autofocus feature, switched off before focus is set", "text",
                                     nullable=True),
        "autofocus_off": Setting("the value that switches autofocus off (default: Off or false)", "value",
                                 nullable=True),
        "gain_db_per_raw": Setting("dB per unit when the device only has GainRaw", "number", "dB", 0.0, 1000.0,
                                   low_open=True),
        "buffers": Setting("stream buffers queued to Aravis", "integer", "", 1, 256),
        "fake_genicam_xml": Setting("GenICam XML for Fake_* devices", "text", nullable=True),
        "packet_size": Setting("GigE Vision stream packet size", "integer", "bytes", 576, 65535, nullable=True),
    }  # fmt: skip
    CONFIG_KEYS = frozenset({"driver", *SETTINGS})
    CONFIG_NAME = "aravis camera"

    def __init__(
        self,
        device: str | None = None,
        *,
        pixel_format: str = "Mono8",
        exposure_us: float | None = None,
        gain_db: float | None = None,
        focus: float | None = None,
        trigger: str = "software",
        roi: tuple[int, int, int, int] | None = None,
        focus_feature: str | None = None,
        zoom: float | None = None,
        zoom_feature: str = "Zoom",
        focus_type: str = "auto",
        autofocus_feature: str | None = None,
        autofocus_off: Any = None,
        gain_db_per_raw: float = 1.0,
        buffers: int = 3,
        fake_genicam_xml: str | None = None,
        packet_size: int | None = None,
    ):
        if pixel_format not in PIXEL_FORMATS:
            raise ValueError(f"pixel_format {pixel_format!r}: expected one of {', '.join(PIXEL_FORMATS)}")
        if focus_type not in ("auto", "integer", "float"):
            raise ValueError(f"focus_type {focus_type!r}: expected auto, integer or float")
        if not isinstance(trigger, str) or not trigger:
            raise ValueError(f"trigger {trigger!r}: expected 'software', 'off' or a TriggerSource name")
        if roi is not None:
            xywh = tuple(int(v) for v in roi)
            if len(xywh) != 4 or xywh[2] <= 0 or xywh[3] <= 0 or xywh[0] < 0 or xywh[1] < 0:
                raise ValueError(f"roi {xywh!r}: expected [x, y, width, height] with positive size")
            roi = (xywh[0], xywh[1], xywh[2], xywh[3])
        if pixel_format in BAYER_FORMATS and roi is not None and (roi[2] % 2 or roi[3] % 2):
            raise ValueError(f"roi {list(roi)!r}: a raw Bayer format ({pixel_format}) needs an even width and height")
        if int(buffers) < 1:
            raise ValueError(f"buffers {buffers!r}: expected >= 1")
        if not (gain_db_per_raw > 0):
            raise ValueError(f"gain_db_per_raw {gain_db_per_raw!r}: expected > 0")
        if autofocus_feature and not focus_feature:
            raise ValueError("autofocus_feature given without focus_feature")
        self.device_id = device
        self._pixel_format = pixel_format
        self._initial = {"exposure_us": exposure_us, "gain_db": gain_db, "focus": focus, "zoom": zoom}
        self.zoom_feature = str(zoom_feature)
        self.trigger = trigger
        self._roi = roi
        self.focus_feature = focus_feature
        self._focus_type = focus_type
        self.autofocus_feature = autofocus_feature
        self.autofocus_off = autofocus_off
        self.gain_db_per_raw = float(gain_db_per_raw)
        self.n_buffers = int(buffers)
        self.fake_genicam_xml = fake_genicam_xml
        self.packet_size = packet_size
        # Aravis objects (GObject introspection, no type information) while open
        self._camera: Any = None  # Aravis.Camera
        self._device: Any = None  # Aravis.Device
        self._stream: Any = None  # Aravis.Stream
        self._identity: CameraIdentity | None = None
        self._size: tuple[int, int] | None = None
        self._counter = 0
        self._exposure_feature: str | None = None
        self._gain_feature: str | None = None
        self._focus_kind: str | None = None
        self._zoom_kind: str | None = None
        self._ranges: dict[str, Range | None] = {}
        self._lost = False  # the device stopped answering (close() then sends nothing)

    @property
    def name(self) -> str:
        return f"aravis camera {self.device_id or '<first>'}"

    def __repr__(self) -> str:
        return f"<AravisCamera {self.device_id!r} {'open' if self._camera else 'closed'}>"

    # -- open / close ---------------------------------------------------------------
    @property
    def is_open(self) -> bool:
        return self._camera is not None

    def open(self) -> None:
        if self._camera is not None:
            return
        Aravis = aravis_module()
        if self.device_id and self.device_id.startswith("Fake_"):
            Aravis.enable_interface("Fake")
            _select_fake_xml(Aravis, self.fake_genicam_xml)
        try:
            camera = Aravis.Camera.new(self.device_id)
        except Exception as exc:  # GLib.Error
            raise DeviceDisconnected(f"{self.name}: cannot open: {_gerror_text(exc)}") from None
        self._lost = False
        self._camera = camera
        self._device = camera.get_device()
        try:
            self._device.set_range_check_policy(Aravis.RangeCheckPolicy.ENABLE)
            self._configure(Aravis)
            self._start_stream(Aravis)
        except BaseException:
            self.close()
            raise

    def _has(self, feature: str) -> bool:
        try:
            return bool(self._device.is_feature_available(feature))
        except Exception:
            return False

    def _call(self, what: str, fn: Callable[..., T], *args: Any) -> T:
        """Call an Aravis function, mapping GLib errors to driver errors.

        A device that does not answer (``ArvDeviceError`` TIMEOUT, TRANSFER_ERROR,
        NOT_CONNECTED) is :class:`DeviceDisconnected` and marks the connection lost;
        anything else the device refuses is :class:`DeviceRejected`.
        """
        try:
            return fn(*args)
        except DriverError:
            raise
        except Exception as exc:
            if _device_gone(exc):
                self._lost = True
                raise DeviceDisconnected(
                    f"{self.name}: {what}: device not answering ({_gerror_text(exc)}); close() and open() again"
                ) from None
            raise DeviceRejected(f"{self.name}: {what}: {_gerror_text(exc)}") from None

    def _configure(self, Aravis: Any) -> None:
        cam, dev = self._camera, self._device
        self._identity = CameraIdentity(
            vendor=str(cam.get_vendor_name() or ""),
            model=str(cam.get_model_name() or ""),
            serial=str(cam.get_device_serial_number() or cam.get_device_id() or ""),
        )
        self._exposure_feature = next((f for f in EXPOSURE_FEATURES if self._has(f)), None)
        self._gain_feature = next((f for f in GAIN_FEATURES if self._has(f)), None)
        if self._exposure_feature is None:
            raise DeviceRejected(f"{self.name}: device has no {' / '.join(EXPOSURE_FEATURES)} feature")
        if self._gain_feature is None:
            raise DeviceRejected(f"{self.name}: device has no {' / '.join(GAIN_FEATURES)} feature")
        for auto in ("ExposureAuto", "GainAuto"):  # automatic control would defeat set values
            if self._has(auto) and self._call(f"read {auto}", dev.get_string_feature_value, auto) != "Off":
                self._call(f"{auto}=Off", dev.set_string_feature_value, auto, "Off")
        self._check_focus_features(Aravis)
        self._ranges = self._read_ranges()

        # image format: pixel format, region (full sensor unless configured)
        pf = aravis_pixel_format(Aravis, self._pixel_format)
        self._call(f"PixelFormat={self._pixel_format}", cam.set_pixel_format, pf)
        got = cam.get_pixel_format_as_string()
        if got != self._pixel_format:
            raise DeviceRejected(f"{self.name}: PixelFormat {self._pixel_format} not accepted (device has {got})")
        if self._roi is None:
            sensor = cam.get_sensor_size()
            sw, sh = (sensor.width, sensor.height) if hasattr(sensor, "width") else sensor
            roi = (0, 0, int(sw), int(sh))
        else:
            roi = self._roi
        self._call(f"region {roi}", cam.set_region, *roi)
        region = cam.get_region()
        rx, ry, rw, rh = (region.x, region.y, region.width, region.height) if hasattr(region, "width") else region
        if (rw, rh) != roi[2:]:
            raise DeviceRejected(f"{self.name}: region {roi} not accepted (device has {rx},{ry},{rw},{rh})")
        self._size = (int(rw), int(rh))

        # acquisition: continuous, trigger as configured
        self._call("AcquisitionMode=Continuous", cam.set_acquisition_mode, Aravis.AcquisitionMode.CONTINUOUS)
        trig = self.trigger.lower()
        if trig == "software":
            if not cam.is_software_trigger_supported():
                raise DeviceRejected(f"{self.name}: software trigger not supported")
            self._call("trigger Software", cam.set_trigger, "Software")
        elif trig == "off":
            self._call("clear triggers", cam.clear_triggers)
        else:
            self._call(f"trigger {self.trigger}", cam.set_trigger, self.trigger)
        if self.packet_size is not None and cam.is_gv_device():
            self._call(f"packet size {self.packet_size}", cam.gv_set_packet_size, int(self.packet_size))

        self._apply_initial_settings()

    def _check_focus_features(self, Aravis: Any) -> None:
        if not self.focus_feature:
            return
        if not self._has(self.focus_feature):
            raise DeviceRejected(f"{self.name}: focus_feature {self.focus_feature!r} not found on device")
        node = self._device.get_feature(self.focus_feature)
        kind = (
            "float" if isinstance(node, Aravis.GcFloat) else "integer" if isinstance(node, Aravis.GcInteger) else None
        )
        if kind is None:
            raise DeviceRejected(
                f"{self.name}: focus_feature {self.focus_feature!r} is a {type(node).__name__}, not an Integer or Float"
            )
        if self._focus_type not in ("auto", kind):
            raise DeviceRejected(
                f"{self.name}: focus_feature {self.focus_feature!r} is {kind}, "
                f"configured focus_type is {self._focus_type}"
            )
        self._focus_kind = kind
        if self.autofocus_feature and not self._has(self.autofocus_feature):
            raise DeviceRejected(f"{self.name}: autofocus_feature {self.autofocus_feature!r} not found on device")

    def _bounds(self, feature: str, kind: str, unit: str, scale: float = 1.0) -> Range:
        """The GenICam Min/Max (and Inc) of ``feature``, times ``scale``, as a Range."""
        dev = self._device
        if kind == "integer":
            lo, hi = self._call(f"bounds of {feature}", dev.get_integer_feature_bounds, feature)
            inc = self._call(f"increment of {feature}", dev.get_integer_feature_increment, feature)
            step: float | None = float(inc) * scale if inc and inc > 1 else None
        else:
            lo, hi = self._call(f"bounds of {feature}", dev.get_float_feature_bounds, feature)
            try:
                inc = float(dev.get_float_feature_increment(feature))
            except Exception:  # GLib.Error: the feature has no <Inc>
                inc = 0.0
            step = inc * scale if inc >= 1e-9 else None  # Aravis answers DBL_MIN for "any value"
        return Range(float(lo) * scale, float(hi) * scale, unit, f"GenICam {feature}", step)

    def _read_ranges(self) -> dict[str, Range | None]:
        exposure, gain = self._exposure_feature, self._gain_feature
        assert exposure is not None and gain is not None  # _configure checked them
        ranges: dict[str, Range | None] = {"exposure": self._bounds(exposure, "float", "µs")}
        if gain == "GainRaw":
            ranges["gain"] = self._bounds(gain, "integer", "dB", self.gain_db_per_raw)
        else:
            ranges["gain"] = self._bounds(gain, "float", "dB")
        if self.focus_feature and self._focus_kind is not None:
            ranges["focus"] = self._bounds(self.focus_feature, self._focus_kind, "")
        else:
            ranges["focus"] = None
        self._zoom_kind = self._feature_kind(self.zoom_feature) if self._has(self.zoom_feature) else None
        ranges["zoom"] = self._bounds(self.zoom_feature, self._zoom_kind, "") if self._zoom_kind else None
        return ranges

    def _feature_kind(self, feature: str) -> str | None:
        """``"integer"`` or ``"float"`` for a numeric GenICam feature, None otherwise."""
        Aravis = aravis_module()
        node = self._device.get_feature(feature)
        if isinstance(node, Aravis.GcInteger) and not isinstance(node, Aravis.GcEnumeration):
            return "integer"
        if isinstance(node, Aravis.GcFloat):
            return "float"
        return None

    def _start_stream(self, Aravis: Any) -> None:
        cam = self._camera
        stream = self._call("create stream", cam.create_stream, None, None)
        if stream is None:
            raise DriverError(f"{self.name}: cannot create stream")
        payload = cam.get_payload()
        for _ in range(self.n_buffers):
            stream.push_buffer(Aravis.Buffer.new_allocate(payload))
        self._stream = stream
        self._call("start acquisition", cam.start_acquisition)
        self._counter = 0

    def close(self) -> None:
        """Stop acquisition and release the device; idempotent.

        After the device stopped answering (a :class:`DeviceDisconnected` was raised) nothing
        more is sent to it and its Aravis objects are released in the background, so that
        closing and reopening a re-plugged camera does not wait for network timeouts.
        """
        cam = self._camera
        if cam is None:
            return
        if self._lost:
            doomed = [self._camera, self._stream, self._device]
            cam = self._camera = self._stream = self._device = None
            _release_in_background(doomed)
            return
        self._camera = self._stream = self._device = None
        with contextlib.suppress(Exception):  # a camera that vanished since its last answer: dropped anyway
            cam.stop_acquisition()

    # -- properties -----------------------------------------------------------------
    # Properties never raise (``isinstance(cam, Camera)`` reads them on Python 3.11):
    # before the first open they report what is known from the configuration.
    @property
    def identity(self) -> CameraIdentity:
        """Vendor, model and serial read from the device (placeholders before the first open)."""
        return self._identity or CameraIdentity("", "", self.device_id or "")

    @property
    def sensor_size(self) -> tuple[int, int]:
        """(width, height) of the delivered images (the region; full sensor by default).

        Before the first open: the configured region size, or (0, 0) if unknown.
        """
        if self._size is not None:
            return self._size
        return (self._roi[2], self._roi[3]) if self._roi else (0, 0)

    @property
    def pixel_format(self) -> str:
        """The PFNC pixel format name (``Mono8`` ...), as read back from the device when open."""
        if self._camera is None:
            return self._pixel_format
        return str(self._camera.get_pixel_format_as_string())

    @property
    def exposure_feature(self) -> str | None:
        return self._exposure_feature

    @property
    def gain_feature(self) -> str | None:
        return self._gain_feature

    # -- exposure / gain ------------------------------------------------------------
    def set_exposure(self, microseconds: float) -> float:
        self._require_open()
        us = self._in_range("exposure", "exposure", self._exposure_value(microseconds))
        f = self._exposure_feature
        self._call(f"{f}={us:g}", self._device.set_float_feature_value, f, us)
        return self.get_exposure()

    def get_exposure(self) -> float:
        self._require_open()
        f = self._exposure_feature
        return float(self._call(f"read {f}", self._device.get_float_feature_value, f))

    def set_gain(self, db: float) -> float:
        self._require_open()
        db = self._in_range("gain", "gain", self._finite_value(float(db), "gain"))
        f, dev = self._gain_feature, self._device
        if f == "GainRaw":
            raw = int(round(db / self.gain_db_per_raw))
            self._call(f"GainRaw={raw}", dev.set_integer_feature_value, f, raw)
        else:
            self._call(f"{f}={db:g}", dev.set_float_feature_value, f, db)
        return self.get_gain()

    def get_gain(self) -> float:
        self._require_open()
        f, dev = self._gain_feature, self._device
        if f == "GainRaw":
            return float(self._call("read GainRaw", dev.get_integer_feature_value, f)) * self.gain_db_per_raw
        return float(self._call(f"read {f}", dev.get_float_feature_value, f))

    # -- focus ----------------------------------------------------------------------
    def lock_focus(self, position: float) -> float:
        """Switch the configured autofocus feature off, then set the focus feature."""
        self._require_open()
        if not self.focus_feature:
            raise DeviceRejected(f"{self.name}: no focus feature configured (set focus_feature)")
        pos = self._in_range("focus", "focus", self._finite_value(position, "focus position"))
        dev = self._device
        if self.autofocus_feature:
            self._autofocus_off()
        f = self.focus_feature
        if self._focus_kind == "integer":
            self._call(f"{f}={round(pos)}", dev.set_integer_feature_value, f, int(round(pos)))
        else:
            self._call(f"{f}={pos:g}", dev.set_float_feature_value, f, pos)
        return self._read_focus()

    def _autofocus_off(self) -> None:
        Aravis = aravis_module()
        dev, f = self._device, self.autofocus_feature
        node = dev.get_feature(f)
        want: bool | int | str
        if isinstance(node, Aravis.GcBoolean):
            want = bool(self.autofocus_off) if self.autofocus_off is not None else False
            self._call(f"{f}={want}", dev.set_boolean_feature_value, f, want)
            ok = self._call(f"read {f}", dev.get_boolean_feature_value, f) == want
        elif isinstance(node, Aravis.GcInteger) and not isinstance(node, Aravis.GcEnumeration):
            want = int(self.autofocus_off) if self.autofocus_off is not None else 0
            self._call(f"{f}={want}", dev.set_integer_feature_value, f, want)
            ok = self._call(f"read {f}", dev.get_integer_feature_value, f) == want
        else:  # Enumeration / String
            want = str(self.autofocus_off) if self.autofocus_off is not None else "Off"
            self._call(f"{f}={want}", dev.set_string_feature_value, f, want)
            ok = self._call(f"read {f}", dev.get_string_feature_value, f) == want
        if not ok:
            raise DeviceRejected(f"{self.name}: {f} did not switch to {want!r}")

    def get_focus(self) -> float | None:
        self._require_open()
        if not self.focus_feature:
            return None
        return self._read_focus()

    def _read_focus(self) -> float:
        dev, f = self._device, self.focus_feature
        if self._focus_kind == "integer":
            return float(self._call(f"read {f}", dev.get_integer_feature_value, f))
        return float(self._call(f"read {f}", dev.get_float_feature_value, f))

    # -- zoom -----------------------------------------------------------------------
    def set_zoom(self, position: float) -> float:
        """Set the zoom feature (``zoom_feature``, device units); OutOfRange outside its GenICam bounds,
        DeviceRejected when the device has no such numeric feature."""
        self._require_open()
        kind = self._zoom_kind
        if kind is None:
            raise DeviceRejected(
                f"{self.name}: no numeric zoom feature {self.zoom_feature!r} on the device (zoom_feature)"
            )
        pos = self._in_range("zoom", "zoom", self._finite_value(position, "zoom position"))
        dev, f = self._device, self.zoom_feature
        if kind == "integer":
            self._call(f"{f}={round(pos)}", dev.set_integer_feature_value, f, int(round(pos)))
        else:
            self._call(f"{f}={pos:g}", dev.set_float_feature_value, f, pos)
        got = self.get_zoom()
        assert got is not None
        return got

    def get_zoom(self) -> float | None:
        self._require_open()
        dev, f, kind = self._device, self.zoom_feature, self._zoom_kind
        if kind is None:
            return None
        if kind == "integer":
            return float(self._call(f"read {f}", dev.get_integer_feature_value, f))
        return float(self._call(f"read {f}", dev.get_float_feature_value, f))

    # -- capture --------------------------------------------------------------------
    def capture(self, timeout: float = 5.0) -> Frame:
        """Trigger (if software-triggered) and return the next frame.

        Frames already waiting in the stream are discarded first, so the
        image is exposed after this call started.
        """
        self._require_open()
        Aravis = aravis_module()
        stream, cam = self._stream, self._camera
        while (old := stream.try_pop_buffer()) is not None:  # drop frames taken before now
            stream.push_buffer(old)
        t0_ns = time.time_ns()
        deadline = time.monotonic() + float(timeout)
        if self.trigger.lower() == "software":
            self._call("TriggerSoftware", cam.software_trigger)
        while True:
            remaining = deadline - time.monotonic()
            buf = stream.timeout_pop_buffer(max(1, int(remaining * 1e6))) if remaining > 0 else None
            if buf is None:
                raise DeviceTimeout(f"{self.name}: no frame within {timeout:g} s (trigger {self.trigger})")
            status = buf.get_status()
            if status != Aravis.BufferStatus.SUCCESS:
                stream.push_buffer(buf)
                raise CaptureError(f"{self.name}: buffer status {status.value_nick}")
            sys_ts = buf.get_system_timestamp()
            if self.trigger.lower() == "off" and sys_ts and sys_ts < t0_ns:
                stream.push_buffer(buf)  # free-running frame exposed before the call
                continue
            try:
                image, fmt = self._to_array(Aravis, buf)
                extra: dict[str, Any] = {
                    "frame_id": int(buf.get_frame_id()),
                    "device_timestamp_ns": int(buf.get_timestamp()),
                    "pixel_format": fmt,
                }
                pattern = bayer_pattern(fmt)
                if pattern is not None:  # a colour sensor's raw mosaic: the colour pipeline reads its pattern here
                    extra["cfa"] = pattern
            finally:
                stream.push_buffer(buf)
            break
        return self._frame(
            image, (sys_ts / 1e9) if sys_ts else time.time(), self.get_exposure(), self.get_gain(), extra
        )

    def _to_array(self, Aravis: Any, buf: Any) -> tuple[np.ndarray, str]:
        """The buffer's image (grey, or a raw Bayer mosaic) and the PFNC name of its pixel format."""
        w, h = buf.get_image_width(), buf.get_image_height()
        pf = buf.get_image_pixel_format()
        names = _format_names(Aravis)
        if pf not in names:
            raise CaptureError(f"{self.name}: buffer pixel format 0x{pf:08x} is not one of {', '.join(PIXEL_FORMATS)}")
        fmt = names[pf]
        # rows padded (PaddingX): the leader's padding_x tells the stride (drivers.frames.genicam_stride), else
        # (an Aravis without arv_buffer_get_image_padding) the buffer's size
        get_padding = getattr(buf, "get_image_padding", None)
        padding_x = None if get_padding is None else int(get_padding()[0])
        return self._converted(genicam_image, buf.get_data(), fmt, w, h, padding_x), fmt
