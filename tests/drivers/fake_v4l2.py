"""A fake V4L2 capture device at the ioctl level, for testing through real linuxpy.

Only the two kernel entry points linuxpy cannot reach without ``/dev/video*``
are replaced: ``fcntl.ioctl`` (as seen by ``linuxpy.ioctl``) and
``mmap.mmap`` (as seen by ``linuxpy.video.device``), the same seams linuxpy's
own tests patch (tiagocoutinho/linuxpy ``tests/test_video.py``). Everything
else is real: linuxpy opens a real file (a FIFO standing in for the device
node, opened ``O_RDWR | O_NONBLOCK``), builds its real ctypes structures,
and waits for frames with a real ``select()`` on that file descriptor. The
fake signals "a buffer is done" by writing one byte into the FIFO, and
``VIDIOC_DQBUF`` consumes it, so ``select`` with a timeout behaves as with a
real driver (a stalled camera really times out).

The device models a UVC-like camera (``uvcvideo``): formats GREY / Y16 /
YUYV / MJPG (and, offered on request, Y10 / Y12, raw Bayer and MIPI CSI-2 packed ones), controls ``auto_exposure`` (menu: 1 manual, 3 aperture
priority), ``exposure_time_absolute`` (100 µs units, inactive while auto
exposure is on: writing it then fails with ``EACCES``), ``gain``,
``focus_absolute`` (inactive while ``focus_automatic_continuous`` is on) and
``focus_automatic_continuous`` (and, ``with_zoom``, ``zoom_absolute``, 100-500). Control names can be switched to the older
kernels' names (``exposure_auto``, ``exposure_absolute``, ``focus_auto``).
Unsupported ioctls fail with ``ENOTTY`` and every request is logged in
:attr:`FakeV4L2Camera.calls`.

Frames are a deterministic pattern that encodes the frame sequence number,
see :meth:`FakeV4L2Camera.scene`.
"""

from __future__ import annotations

import errno
import mmap as _mmap
import os
import types
from collections import deque
from contextlib import ExitStack
from dataclasses import dataclass, field
from unittest import mock

import numpy as np
from linuxpy.video import raw

from tests.drivers import packing

IOC = raw.IOC
FOURCC = {
    "GREY": raw.PixelFormat.GREY,
    "Y16": raw.PixelFormat.Y16,
    # 10/12 bits in the low bits of a little-endian 16-bit word, the high bits zero (V4L2_PIX_FMT_Y10, Y12)
    "Y10": raw.PixelFormat.Y10,
    "Y12": raw.PixelFormat.Y12,
    "YUYV": raw.PixelFormat.YUYV,
    "MJPG": raw.PixelFormat.MJPEG,
    # raw Bayer mosaics (a colour sensor): 8 bits, 10 bits in 16-bit words, 16 bits
    "RGGB": raw.PixelFormat.SRGGB8,
    "BA81": raw.PixelFormat.SBGGR8,
    "BA10": raw.PixelFormat.SGRBG10,
    "BYR2": raw.PixelFormat.SBGGR16,
    # MIPI CSI-2 packed (V4L2_PIX_FMT_SRGGB10P ...): a Raspberry Pi camera's raw formats
    "pRAA": raw.PixelFormat.SRGGB10P,
    "pgAA": raw.PixelFormat.SGRBG10P,
    "pGAA": raw.PixelFormat.SGBRG10P,
    "pBAA": raw.PixelFormat.SBGGR10P,
    "pRCC": raw.PixelFormat.SRGGB12P,
    "pgCC": raw.PixelFormat.SGRBG12P,
    "pGCC": raw.PixelFormat.SGBRG12P,
    "pBCC": raw.PixelFormat.SBGGR12P,
    "Y10P": raw.PixelFormat.Y10P,
    "Y12P": raw.PixelFormat.Y12P,
}
WORD_GREY_BITS = {"Y10": 10, "Y12": 12}
"""The fake's unpacked 10/12-bit grey formats: the scene's values written as little-endian 16-bit words."""
BAYER_BITS = {"RGGB": 8, "BA81": 8, "BA10": 10, "BYR2": 16}
"""The fake's raw Bayer formats and their sample bits (10: the low bits of a little-endian word)."""
PACKED_BITS = {f: 10 if f.endswith(("AA", "10P")) else 12 for f in FOURCC if f.startswith("p") or f[-1] == "P"}
"""The fake's MIPI CSI-2 packed formats (Bayer ``p...``, grey ``Y10P``/``Y12P``) and their bits: each row of the
scene packed by the independent packer (tests/drivers/packing.py), then the stride padding."""
_NAME = {int(v): k for k, v in FOURCC.items()}
NEXT_FLAGS = int(raw.ControlFlag.NEXT_CTRL | raw.ControlFlag.NEXT_COMPOUND)
CID = raw.ControlID


@dataclass
class Ctrl:
    id: int
    name: str
    type: int
    minimum: int
    maximum: int
    step: int
    default: int
    value: int
    menu: dict = field(default_factory=dict)


class FakeV4L2Camera:
    """Kernel-side behaviour of one UVC-like camera, driven through linuxpy."""

    def __init__(
        self,
        path,
        *,
        formats=("GREY", "Y16", "YUYV", "MJPG"),
        width=64,
        height=48,
        max_size=(640, 480),
        stride_padding=0,
        old_names=False,
        with_focus=True,
        with_zoom=False,
    ):
        self.path = str(path)
        os.mkfifo(self.path)
        self.formats = [FOURCC[f] for f in formats]
        self.max_size = max_size
        self.stride_padding = stride_padding
        self.width, self.height = width, height
        self.pixelformat = self.formats[0]
        self.stalled = False  # True: the sensor delivers no frames (select times out)
        self.unplugged = False  # True: every ioctl fails with ENODEV
        self.calls: list[str] = []
        self.streaming = False
        self.buffers: list[_mmap.mmap] = []
        self.queued: deque[int] = deque()
        self.done: deque[tuple[int, int, int]] = deque()
        self.sequence = 0
        self.jpeg_quality = 95
        C = raw.CtrlType
        names = (
            ("exposure_auto", "exposure_absolute", "focus_auto")
            if old_names
            else ("auto_exposure", "exposure_time_absolute", "focus_automatic_continuous")
        )
        ctrls = [
            Ctrl(int(CID.GAIN), "Gain", C.INTEGER, 0, 100, 1, 0, 0),
            Ctrl(
                int(CID.EXPOSURE_AUTO),
                _title(names[0]),
                C.MENU,
                0,
                3,
                1,
                3,
                3,
                menu={1: b"Manual Mode", 3: b"Aperture Priority Mode"},
            ),
            Ctrl(int(CID.EXPOSURE_ABSOLUTE), _title(names[1]), C.INTEGER, 3, 2047, 1, 156, 156),
        ]
        if with_focus:
            ctrls += [
                Ctrl(int(CID.FOCUS_ABSOLUTE), "Focus, Absolute", C.INTEGER, 0, 250, 5, 0, 30),
                Ctrl(int(CID.FOCUS_AUTO), _title(names[2]), C.BOOLEAN, 0, 1, 1, 1, 1),
            ]
        if with_zoom:  # a UVC zoom lens: zoom_absolute in its own units
            ctrls.append(Ctrl(int(CID.ZOOM_ABSOLUTE), "Zoom, Absolute", C.INTEGER, 100, 500, 1, 100, 100))
        self.controls = {c.id: c for c in sorted(ctrls, key=lambda c: c.id)}
        self._ino = os.stat(self.path).st_ino
        self._stack: ExitStack | None = None

    # -- installing the fake ---------------------------------------------------------
    def __enter__(self) -> FakeV4L2Camera:
        self._stack = ExitStack()
        self._stack.enter_context(mock.patch("linuxpy.ioctl.fcntl", types.SimpleNamespace(ioctl=self.ioctl)))
        self._stack.enter_context(mock.patch("linuxpy.video.device.mmap", types.SimpleNamespace(mmap=self.mmap)))
        return self

    def __exit__(self, *exc) -> None:
        self._stack.close()

    # -- helpers -------------------------------------------------------------------------
    def value(self, cid) -> int:
        return self.controls[int(cid)].value

    def set_value(self, cid, value: int) -> None:
        self.controls[int(cid)].value = int(value)

    def _inactive(self, c: Ctrl) -> bool:
        if c.id == int(CID.EXPOSURE_ABSOLUTE):
            return self.value(CID.EXPOSURE_AUTO) != 1
        if c.id == int(CID.FOCUS_ABSOLUTE) and int(CID.FOCUS_AUTO) in self.controls:
            return bool(self.value(CID.FOCUS_AUTO))
        return False

    def _geometry(self, fourcc, width, height):
        width = max(2, min(int(width), self.max_size[0])) & ~1
        height = max(1, min(int(height), self.max_size[1]))
        bpp = {raw.PixelFormat.GREY: 1, raw.PixelFormat.Y16: 2, raw.PixelFormat.YUYV: 2}.get(fourcc)
        if _NAME.get(int(fourcc)) in WORD_GREY_BITS:
            bpp = 2
        if _NAME.get(int(fourcc)) in BAYER_BITS:
            bpp = 1 if BAYER_BITS[_NAME[int(fourcc)]] == 8 else 2
            height = max(2, height) & ~1  # a whole mosaic
        if _NAME.get(int(fourcc)) in PACKED_BITS:  # whole groups (4 pixels in 5 bytes, 2 in 3), a whole mosaic
            bits = PACKED_BITS[_NAME[int(fourcc)]]
            width = max(4, width) & ~3 if bits == 10 else width
            if _NAME[int(fourcc)].startswith("p"):
                height = max(2, height) & ~1
            bpl = width * bits // 8 + self.stride_padding
            return width, height, bpl, bpl * height
        if bpp is None:  # MJPG: compressed, worst case size
            return width, height, 0, width * height * 2
        bpl = width * bpp + self.stride_padding
        return width, height, bpl, bpl * height

    @staticmethod
    def scene(seq: int, width: int, height: int, bits: int = 8) -> np.ndarray:
        """The image of frame ``seq``: a diagonal ramp shifted by the sequence number (``bits`` 10 or 12: the
        16-bit one's top bits, in the low bits of the word)."""
        y, x = np.mgrid[0:height, 0:width]
        if bits == 8:
            return ((3 * x + 5 * y + seq) % 256).astype(np.uint8)
        return (((257 * x + 1031 * y + 17 * seq) % 65536) >> (16 - bits)).astype(np.uint16)

    def smooth_scene(self, seq: int, width: int, height: int) -> np.ndarray:
        """A band-limited image for MJPG (JPEG is lossy; smooth content decodes closely)."""
        y, x = np.mgrid[0:height, 0:width]
        v = 128 + 60 * np.sin(2 * np.pi * x / width) * np.cos(2 * np.pi * y / height) + (seq % 8)
        return np.clip(np.round(v), 0, 255).astype(np.uint8)

    def encode(self, seq: int) -> bytes:
        """Frame ``seq`` as the bytes the device puts in a buffer."""
        w, h, bpl, _ = self._geometry(self.pixelformat, self.width, self.height)
        fmt = _NAME[int(self.pixelformat)]
        if fmt == "MJPG":
            import cv2

            ok, jpg = cv2.imencode(".jpg", self.smooth_scene(seq, w, h), [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
            assert ok
            return jpg.tobytes()
        if fmt in PACKED_BITS:
            rows = np.frombuffer(
                b"".join(packing.pack(r, *packing.FORMATS[fmt]) for r in self.scene(seq, w, h, bits=PACKED_BITS[fmt])),
                np.uint8,
            ).reshape(h, -1)
        elif fmt == "GREY" or BAYER_BITS.get(fmt) == 8:
            rows = self.scene(seq, w, h)
        elif fmt in BAYER_BITS:
            rows = self.scene(seq, w, h, bits=BAYER_BITS[fmt]).astype("<u2").view(np.uint8).reshape(h, 2 * w)
        elif fmt in WORD_GREY_BITS:
            rows = self.scene(seq, w, h, bits=WORD_GREY_BITS[fmt]).astype("<u2").view(np.uint8).reshape(h, 2 * w)
        elif fmt == "Y16":
            rows = self.scene(seq, w, h, bits=16).astype("<u2").view(np.uint8).reshape(h, 2 * w)
        else:  # YUYV: Y0 U Y1 V, chroma constant 128
            rows = np.full((h, 2 * w), 128, np.uint8)
            rows[:, 0::2] = self.scene(seq, w, h)
        out = np.zeros((h, bpl), np.uint8)
        out[:, : rows.shape[1]] = rows
        out[:, rows.shape[1] :] = 0xEE  # padding bytes must never reach the image
        return out.tobytes()

    def replug(self) -> None:
        """Plug the camera back in after ``unplugged``: a fresh device (no buffers, not
        streaming, nothing pending on the node), with the controls it kept in its own memory,
        as a UVC camera re-enumerated by the kernel."""
        for b in self.buffers:
            if not b.closed:
                b.close()
        self.buffers, self.queued, self.done = [], deque(), deque()
        self.streaming = False
        fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK)
        try:
            while True:  # "frame ready" bytes of the old connection
                try:
                    if not os.read(fd, 4096):
                        break
                except BlockingIOError:
                    break
        finally:
            os.close(fd)
        self.unplugged = False

    def resume(self) -> None:
        """End a stall: the sensor delivers frames again (fills the queued buffers)."""
        self.stalled = False
        self._fill()

    def _fill(self) -> None:
        """The sensor fills every queued buffer at once (infinitely fast camera)."""
        if not self.streaming or self.stalled:
            return
        while self.queued:
            index = self.queued.popleft()
            data = self.encode(self.sequence)
            buf = self.buffers[index]
            buf.seek(0)
            buf.write(data)
            self.done.append((index, len(data), self.sequence))
            self.sequence += 1
            os.write(self._fd, b"F")  # makes the fd readable for select()

    # -- kernel entry points ---------------------------------------------------------
    def mmap(self, fd, length, offset=0, **kw):
        index = offset // _mmap.PAGESIZE
        buf = self.buffers[index]
        assert length == len(buf), (length, len(buf))
        return buf

    def ioctl(self, fd, request, arg=None, *rest):
        fileno = fd if isinstance(fd, int) else fd.fileno()
        if os.fstat(fileno).st_ino != self._ino:
            raise OSError(errno.ENOTTY, "not a video device")
        self._fd = fileno
        try:
            name = IOC(request).name
        except ValueError:
            name = hex(request)
        self.calls.append(name)
        if self.unplugged:
            raise OSError(errno.ENODEV, os.strerror(errno.ENODEV))
        if request == IOC.QUERYCAP:
            arg.driver, arg.card, arg.bus_info = b"uvcvideo", b"Harp Test Cam", b"usb-0000:00:14.0-3"
            arg.version = 6 << 16 | 1 << 8
            caps = raw.Capability.VIDEO_CAPTURE | raw.Capability.STREAMING
            arg.capabilities = caps | raw.Capability.DEVICE_CAPS
            arg.device_caps = caps
        elif request == IOC.ENUM_FMT:
            if arg.type != raw.BufType.VIDEO_CAPTURE or arg.index >= len(self.formats):
                raise OSError(errno.EINVAL, "no such format")
            arg.pixelformat = self.formats[arg.index]
            arg.description = _NAME[int(self.formats[arg.index])].encode()
            arg.flags = raw.ImageFormatFlag.COMPRESSED if self.formats[arg.index] == raw.PixelFormat.MJPEG else 0
        elif request in (IOC.G_FMT, IOC.S_FMT, IOC.TRY_FMT):
            if arg.type != raw.BufType.VIDEO_CAPTURE:
                raise OSError(errno.EINVAL, "buffer type")
            pix = arg.fmt.pix
            if request != IOC.G_FMT:
                if request == IOC.S_FMT and self.buffers:
                    raise OSError(errno.EBUSY, "buffers allocated")
                fourcc = pix.pixelformat if pix.pixelformat in self.formats else self.formats[0]
                w, h, _, _ = self._geometry(fourcc, pix.width, pix.height)
                if request == IOC.S_FMT:
                    self.pixelformat, self.width, self.height = fourcc, w, h
            else:
                fourcc, w, h = self.pixelformat, self.width, self.height
            w, h, bpl, size = self._geometry(fourcc, w, h)
            pix.pixelformat, pix.width, pix.height = fourcc, w, h
            pix.bytesperline, pix.sizeimage, pix.field = bpl, size, raw.Field.NONE
        elif request == IOC.QUERY_EXT_CTRL:
            want = arg.id
            if want & NEXT_FLAGS:
                base = want & ~NEXT_FLAGS
                ids = [i for i in self.controls if i > base]
                if not ids:
                    raise OSError(errno.EINVAL, "no more controls")
                c = self.controls[ids[0]]
            elif want in self.controls:
                c = self.controls[want]
            else:
                raise OSError(errno.EINVAL, "no such control")
            arg.id, arg.type, arg.name = c.id, c.type, c.name.encode()
            arg.minimum, arg.maximum, arg.step, arg.default_value = c.minimum, c.maximum, c.step, c.default
            arg.flags = raw.ControlFlag.INACTIVE if self._inactive(c) else 0
            arg.elem_size, arg.elems, arg.nr_of_dims = 4, 1, 0
        elif request == IOC.QUERYMENU:
            c = self.controls.get(arg.id)
            if c is None or arg.index not in c.menu:
                raise OSError(errno.EINVAL, "no such menu item")
            arg.name = c.menu[arg.index]
        elif request in (IOC.G_EXT_CTRLS, IOC.S_EXT_CTRLS, IOC.TRY_EXT_CTRLS):
            for i in range(arg.count):
                rc = arg.controls[i]
                c = self.controls.get(rc.id)
                if c is None:
                    arg.error_idx = i
                    raise OSError(errno.EINVAL, "no such control")
                if request == IOC.G_EXT_CTRLS:
                    rc.value = c.default if arg.which == raw.ControlWhichValue.DEF_VAL else c.value
                    continue
                if self._inactive(c):  # uvcvideo: inactive controls cannot be written
                    arg.error_idx = i
                    raise OSError(errno.EACCES, os.strerror(errno.EACCES))
                v = rc.value
                if c.menu and v not in c.menu:
                    arg.error_idx = i
                    raise OSError(errno.EINVAL, "invalid menu index")
                v = min(max(v, c.minimum), c.maximum)  # the control framework clamps and
                v = c.minimum + (v - c.minimum + c.step // 2) // c.step * c.step  # rounds to step
                if request == IOC.S_EXT_CTRLS:
                    c.value = v
        elif request == IOC.REQBUFS:
            if self.streaming:
                raise OSError(errno.EBUSY, "streaming")
            for b in self.buffers:
                if not b.closed:
                    b.close()
            self.buffers, self.queued, self.done = [], deque(), deque()
            if arg.count:
                _, _, _, size = self._geometry(self.pixelformat, self.width, self.height)
                self.buffers = [_mmap.mmap(-1, size) for _ in range(arg.count)]
        elif request == IOC.QUERYBUF:
            if arg.index >= len(self.buffers):
                raise OSError(errno.EINVAL, "no such buffer")
            arg.length = len(self.buffers[arg.index])
            arg.m.offset = arg.index * _mmap.PAGESIZE
        elif request == IOC.QBUF:
            if arg.index >= len(self.buffers) or arg.index in self.queued:
                raise OSError(errno.EINVAL, "bad buffer")
            self.queued.append(arg.index)
            self._fill()
        elif request == IOC.DQBUF:
            if not self.done:
                raise OSError(errno.EAGAIN, os.strerror(errno.EAGAIN))
            index, used, seq = self.done.popleft()
            os.read(fileno, 1)
            arg.index, arg.bytesused, arg.sequence = index, used, seq
            arg.flags = raw.BufferFlag.MAPPED | raw.BufferFlag.DONE | raw.BufferFlag.TIMESTAMP_MONOTONIC
            arg.field = raw.Field.NONE
            arg.timestamp.secs, arg.timestamp.usecs = 1000 + arg.sequence, 0
        elif request == IOC.STREAMON:
            self.streaming = True
            self._fill()
        elif request == IOC.STREAMOFF:
            self.streaming = False
            while self.done:  # the kernel returns all buffers to the dequeued state
                self.done.popleft()
                os.read(fileno, 1)
            self.queued.clear()
        else:
            raise OSError(errno.ENOTTY, f"ioctl {name} not supported by the fake")
        return 0


def _title(config_name: str) -> str:
    """Kernel control name whose linuxpy config name is ``config_name``."""
    return {
        "auto_exposure": "Auto Exposure",
        "exposure_auto": "Exposure, Auto",
        "exposure_time_absolute": "Exposure Time, Absolute",
        "exposure_absolute": "Exposure (Absolute)",
        "focus_automatic_continuous": "Focus, Automatic Continuous",
        "focus_auto": "Focus, Auto",
    }[config_name]
