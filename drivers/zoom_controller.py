"""A camera whose zoom lens is driven by a lens controller over serial instead of by the camera.

A camera configuration with ``zoom_controller: {port: ..., address: ..., zoom: P}`` (the keys of
:class:`drivers.visca.ViscaLens`, and ``zoom``: the position set at open, in the controller's units) is
created by :func:`drivers.open_camera` as a :class:`ControlledZoom`: the camera as configured, except that
its zoom — ``set_zoom``, ``get_zoom``, ``zoom_range`` (:class:`drivers.protocols.Zoomable`) and the zoom
set at open — goes to the controller (a zoom session writes each part's position there). The zoom is
set before the camera opens (and so before the camera locks its focus: a zoom lens's focal length moves
its focus). Everything else is the camera's.
"""

from __future__ import annotations

from typing import Any

from drivers.protocols import Range
from drivers.settings import Setting

SETTING = Setting(
    "a lens controller over serial that drives the zoom instead of the camera (VISCA: port, address, zoom_max, "
    "baudrate, reply_timeout, move_timeout; port 'emulator': the simulated station's; zoom: the position set at "
    "open, in its units)",
    "mapping",
    nullable=True,
)
"""The ``zoom_controller`` key every camera driver accepts."""


class ControlledZoom:
    """``camera`` with its zoom on ``controller`` (a :class:`drivers.visca.ViscaLens`), set to ``zoom`` at open."""

    def __init__(self, camera: Any, controller: Any, zoom: float | None = None) -> None:
        self.camera = camera
        self.controller = controller
        self.zoom = zoom

    def __getattr__(self, name: str) -> Any:
        return getattr(self.camera, name)

    def open(self) -> None:
        self.controller.open()
        try:
            if self.zoom is not None:
                self.controller.set_zoom(self.zoom)
            self.camera.open()
        except BaseException:
            self.controller.close()
            raise

    def close(self) -> None:
        try:
            self.camera.close()
        finally:
            self.controller.close()

    def __enter__(self) -> ControlledZoom:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def zoom_range(self) -> Range:
        return self.controller.zoom_range()  # type: ignore[no-any-return]

    def set_zoom(self, position: float) -> float:
        return float(self.controller.set_zoom(position))

    def get_zoom(self) -> float:
        return float(self.controller.get_zoom())

    def __repr__(self) -> str:
        return f"ControlledZoom({self.camera!r}, {self.controller!r})"
