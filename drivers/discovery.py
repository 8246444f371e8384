"""What cameras and serial ports this machine has, each with the configuration that would use it.

For ``harp devices`` (issue 9): three listings, one per kind of device, each
returning :class:`FoundDevice` records whose ``config`` is the mapping a
``station.camera`` / ``station.turntable`` section would hold
(:func:`drivers.open_camera` / :func:`drivers.open_turntable` accept it as is):

* :func:`list_v4l2_devices` -- ``/dev/video*`` nodes that are streaming video
  capture devices (linuxpy: ``VIDIOC_QUERYCAP``, the formats offered, the
  current frame size, whether there is a focus control). Nodes that are not
  capture devices (metadata nodes of UVC cameras) are left out; a node that
  cannot be opened or queried is listed with its ``problem``.
* :func:`list_aravis_cameras` -- GenICam cameras Aravis finds (GigE Vision,
  USB3 Vision; Aravis' own Fake camera only when asked for).
* :func:`list_serial_ports` -- pyserial's ``list_ports`` (plus ports named
  by the caller, such as a pseudo-terminal or a by-id link). Without
  probing the port's driver is unknown (``driver`` None, ``config`` has only
  the ``port``); with ``probe=True`` each port is asked, at 115200 baud,
  ``/`` (every Zaber ASCII device on the chain answers ``@NN 0 OK ...``) and
  then the realtime ``?`` (GRBL answers its status ``<Idle|...>``). Probing
  writes those few bytes to every port listed: it is opt-in.

Each listing raises :class:`~drivers.errors.DriverError` (one line) when its
subsystem is missing (Aravis not installed); :func:`discover` runs all
three and collects such problems instead of raising.
"""

from __future__ import annotations

import glob
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from drivers.aravis_camera import aravis_module
from drivers.errors import DriverError
from drivers.v4l2_camera import PIXEL_FORMATS as V4L2_FORMATS
from drivers.v4l2_camera import fourcc_name

PROBE_BAUDRATE = 115200

_ZABER_REPLY = re.compile(rb"^@(\d+) (\d+)(?: \d+)? (OK|RJ) (IDLE|BUSY) ")
_GRBL_STATUS = re.compile(rb"^<([A-Za-z]+)(?::\d+)?\|")


@dataclass(frozen=True)
class FoundDevice:
    """One device found on this machine.

    ``kind``: ``"camera"`` or ``"serial port"``; ``driver``: the config
    ``driver`` name (``v4l2``, ``aravis``, ``zaber``, ``grbl``) or None when
    unknown (an unprobed serial port); ``device``: what identifies it
    (``/dev/video0``, an Aravis device id, ``/dev/ttyUSB0``);
    ``description``: one line for a table; ``config``: the driver
    configuration that would use it; ``details``: further facts as text
    (bus, formats, frame size, vendor, serial number, ...); ``problem``:
    why it could not be queried fully, or None.
    """

    kind: str
    driver: str | None
    device: str
    description: str
    config: dict[str, Any]
    details: dict[str, str] = field(default_factory=dict)
    problem: str | None = None


@dataclass(frozen=True)
class Discovery:
    """Everything :func:`discover` found, and one line per listing that could not run."""

    devices: list[FoundDevice]
    problems: list[str]


# -- V4L2 ------------------------------------------------------------------------------------


def _natural_key(path: str) -> tuple[str, int]:
    m = re.search(r"(\d+)$", path)
    return (path[: m.start()] if m else path, int(m.group(1)) if m else -1)


def list_v4l2_devices(pattern: str = "/dev/video*") -> list[FoundDevice]:
    """Every V4L2 streaming capture device whose node matches ``pattern`` (see the module doc)."""
    found = []
    for path in sorted(glob.glob(pattern), key=_natural_key):
        item = _describe_v4l2(path)
        if item is not None:
            found.append(item)
    return found


def _describe_v4l2(path: str) -> FoundDevice | None:
    from linuxpy.video.device import BufferType, Capability, ControlID, Device

    config: dict[str, Any] = {"driver": "v4l2", "device": path}
    dev = Device(path)
    try:
        dev.open()
    except OSError as exc:
        return FoundDevice("camera", "v4l2", path, path, config, problem=f"cannot open: {exc.strerror or exc}")
    try:
        info = dev.info
        caps = info.device_capabilities
        if Capability.VIDEO_CAPTURE not in caps or Capability.STREAMING not in caps:
            return None  # a metadata or output node, not a camera
        offered = [fourcc_name(int(f.pixel_format)) for f in info.formats if f.type == BufferType.VIDEO_CAPTURE]
        usable = [f for f in V4L2_FORMATS if f in offered]
        fmt = dev.get_format(BufferType.VIDEO_CAPTURE)
        width, height = int(fmt.width), int(fmt.height)
        try:
            dev.controls[int(ControlID.FOCUS_ABSOLUTE)]
            has_focus = True
        except (KeyError, OSError, RuntimeWarning):  # no such control, or controls cannot be enumerated
            has_focus = False
        details = {
            "card": str(info.card),
            "driver": str(info.driver),
            "bus": str(info.bus_info),
            "formats": ", ".join(offered) or "none",
            "size": f"{width}x{height}",
            "focus control": "focus_absolute" if has_focus else "none",
        }
        problem = None
        if usable:
            config.update(pixel_format=usable[0], width=width, height=height)
        else:
            problem = (
                f"offers no format harp station reads ({details['formats']}); supported: {', '.join(V4L2_FORMATS)}"
            )
        return FoundDevice("camera", "v4l2", path, f"{info.card} ({info.bus_info})", config, details, problem)
    except OSError as exc:
        problem = f"not a V4L2 device (VIDIOC_QUERYCAP: {exc.strerror or exc})"
        return FoundDevice("camera", "v4l2", path, path, config, problem=problem)
    finally:
        dev.close()


# -- Aravis ----------------------------------------------------------------------------------


def list_aravis_cameras(include_fake: bool = False) -> list[FoundDevice]:
    """The GenICam cameras Aravis finds; ``include_fake`` also lists its in-process Fake camera.

    :class:`~drivers.errors.DriverError` when Aravis is not installed.
    """
    Aravis = aravis_module()
    if include_fake:
        Aravis.enable_interface("Fake")
    Aravis.update_device_list()
    found = []
    for i in range(Aravis.get_n_devices()):
        protocol = str(Aravis.get_device_protocol(i) or "")
        if protocol == "Fake" and not include_fake:
            continue
        device_id = str(Aravis.get_device_id(i))
        vendor, model = str(Aravis.get_device_vendor(i) or ""), str(Aravis.get_device_model(i) or "")
        serial = str(Aravis.get_device_serial_nbr(i) or "")
        details = {
            "vendor": vendor,
            "model": model,
            "serial": serial,
            "protocol": protocol,
            "address": str(Aravis.get_device_address(i) or ""),
            "physical id": str(Aravis.get_device_physical_id(i) or ""),
        }
        description = f"{vendor} {model} (serial {serial}, {protocol} {details['address']})".strip()
        config = {"driver": "aravis", "device": device_id}
        found.append(FoundDevice("camera", "aravis", device_id, description, config, details))
    return found


# -- serial ports ------------------------------------------------------------------------------


def list_serial_ports(extra: Sequence[str] = (), probe: bool = False, timeout: float = 0.3) -> list[FoundDevice]:
    """pyserial's ports (and ``extra`` ones), identified as Zaber or GRBL when ``probe`` (module doc)."""
    from serial.tools import list_ports
    from serial.tools.list_ports_linux import SysFS

    ports = {p.device: p for p in list_ports.comports(include_links=True)}
    for name in extra:
        if name not in ports:
            ports[name] = SysFS(name)
    found = []
    for name, info in ports.items():
        details = {
            k: str(v)
            for k, v in (
                ("description", info.description),
                ("hwid", info.hwid),
                ("manufacturer", info.manufacturer),
                ("product", info.product),
                ("serial", info.serial_number),
                ("usb", f"{info.vid:04x}:{info.pid:04x}" if info.vid is not None and info.pid is not None else None),
            )
            if v not in (None, "", "n/a")
        }
        description = details.get("description", name)
        if not probe:
            found.append(FoundDevice("serial port", None, name, description, {"port": name}, details))
            continue
        try:
            identified = probe_serial_port(name, timeout=timeout)
        except DriverError as exc:
            found.append(FoundDevice("serial port", None, name, description, {"port": name}, details, str(exc)))
            continue
        if identified is None:
            problem = f"no Zaber ASCII or GRBL answer at {PROBE_BAUDRATE} baud"
            found.append(FoundDevice("serial port", None, name, description, {"port": name}, details, problem))
        else:
            driver, config, what = identified
            found.append(FoundDevice("serial port", driver, name, f"{what} ({description})", config, details))
    return found


def probe_serial_port(port: str, timeout: float = 0.3) -> tuple[str, dict[str, Any], str] | None:
    """Ask ``port`` whether it is a Zaber ASCII chain or a GRBL controller.

    Returns ``(driver, config, description)`` or None when nothing answers
    like either. Sends ``/\\n`` (Zaber: every device replies with its
    address), then ``?`` (GRBL realtime status, which changes nothing).
    :class:`~drivers.errors.DeviceDisconnected` if the port cannot be opened.
    """
    from drivers.transport import SerialTransport  # defers serial

    transport = SerialTransport(port, PROBE_BAUDRATE, name=f"serial port {port}")
    transport.open()
    try:
        transport.pending()
        transport.write(b"/\n")
        addresses = sorted({int(m.group(1)) for line in _lines(transport, timeout) if (m := _ZABER_REPLY.match(line))})
        if addresses:
            config: dict[str, Any] = {"driver": "zaber", "port": port}
            if addresses[0] != 1:
                config["device"] = addresses[0]
            chain = ", ".join(str(a) for a in addresses)
            return "zaber", config, f"Zaber ASCII device{'s' if len(addresses) > 1 else ''} {chain}"
        transport.write(b"?")
        for line in _lines(transport, timeout):
            m = _GRBL_STATUS.match(line)
            if m:
                return "grbl", {"driver": "grbl", "port": port}, f"GRBL controller ({m.group(1).decode()})"
        return None
    finally:
        transport.close()


def _lines(transport: Any, timeout: float) -> list[bytes]:
    """Every line that arrives within ``timeout`` seconds (a probe waits the whole time: a chain of
    Zaber devices answers one after another)."""
    deadline = time.monotonic() + timeout
    lines = []
    while (remaining := deadline - time.monotonic()) > 0:
        try:
            lines.append(transport.readline(remaining, "a probe reply").strip())
        except DriverError:  # nothing more within the time (DeviceTimeout), or the port went away
            break
    return lines


# -- everything ---------------------------------------------------------------------------------


def discover(probe_serial: bool = False, include_fake: bool = False, v4l2_pattern: str = "/dev/video*") -> Discovery:
    """All three listings; a listing that cannot run (Aravis missing) becomes one line in ``problems``."""
    devices: list[FoundDevice] = []
    problems: list[str] = []
    listings: list[tuple[str, Callable[[], list[FoundDevice]]]] = [
        ("V4L2 cameras", lambda: list_v4l2_devices(v4l2_pattern)),
        ("GenICam cameras (Aravis)", lambda: list_aravis_cameras(include_fake)),
        ("serial ports", lambda: list_serial_ports(probe=probe_serial)),
    ]
    for what, listing in listings:
        try:
            devices.extend(listing())
        except (DriverError, ImportError, OSError) as exc:
            problems.append(f"{what}: not listed: {' '.join(str(exc).split())}")
    return Discovery(devices, problems)
