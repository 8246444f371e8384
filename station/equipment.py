"""The lens and the camera body being calibrated: who they are and their nominal optics.

:class:`Identity` (maker, model, serial) names a lens or a camera body; :class:`Optics` holds what
is known of their optics without measuring (nominal focal length, mount, pixel pitch, sensor width,
crop factor), each field with its plausible range and unit (:func:`optic_problem`). The station
configuration reads them (``lens``, ``camera_body``: :mod:`station.config`) and a profile records
them (:class:`station.profile.Profile`), so they are defined here, below both.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Identity:
    maker: str
    model: str
    serial: str

    def label(self) -> str:
        return f"{self.maker} {self.model} #{self.serial}"


def _optic(section: str, check: tuple[float, float] | None, unit: str, doc: str) -> Any:
    """An :class:`Optics` field: which YAML section holds it, its plausible range and unit."""
    return field(default=None, metadata={"section": section, "range": check, "unit": unit, "doc": doc})


@dataclass(frozen=True)
class Optics:
    """What the configuration says about the optics, for exports (every field optional).

    The harp measures the *shape* of the distortion, not these: they make an
    export's camera matrix nominal instead of a placeholder
    (:func:`pipeline.exports.lens.camera_matrix_choice`) and let lensfun
    applications find the lens (:mod:`pipeline.exports.lensfun`). In the YAML
    file ``focal_mm`` and ``mount`` belong to ``lens``, the others to
    ``camera_body`` (each field's ``section`` metadata); ``pixel_pitch_um`` and
    ``sensor_width_mm`` are alternatives (give one).
    """

    focal_mm: float | None = _optic("lens", (0.1, 10000.0), "mm", "the nominal focal length (at this zoom setting)")
    mount: str | None = _optic("lens", None, "", "the lens mount, as lensfun names it (e.g. 'Canon EF')")
    pixel_pitch_um: float | None = _optic(
        "camera_body", (0.2, 100.0), "micrometres", "the pixel pitch of the images (after any binning)"
    )
    sensor_width_mm: float | None = _optic(
        "camera_body", (0.5, 200.0), "mm", "the width of the sensor area the image covers"
    )
    crop_factor: float | None = _optic(
        "camera_body", (0.1, 20.0), "", "the crop factor (35 mm diagonal / sensor diagonal)"
    )

    def to_dict(self) -> dict[str, Any]:
        """The fields that are set (for a model file's provenance)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if getattr(self, f.name) is not None}

    @classmethod
    def from_dict(cls, d: Any) -> Optics:
        """The optics of a :meth:`to_dict` mapping; a value that is not valid is left out."""
        if not isinstance(d, Mapping):
            return cls()
        kw: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            v = d.get(f.name)
            if f.metadata["range"] is None:
                if isinstance(v, str) and v.strip():
                    kw[f.name] = v
            elif optic_problem(f.name, v) is None and v is not None:
                kw[f.name] = float(v)
        return cls(**kw)


def optics_keys(section: str) -> tuple[str, ...]:
    """The :class:`Optics` keys of YAML section ``section`` (``lens`` or ``camera_body``)."""
    return tuple(f.name for f in dataclasses.fields(Optics) if f.metadata["section"] == section)


def optic_problem(name: str, value: Any) -> str | None:
    """Why ``value`` is not valid for :class:`Optics` field ``name`` (the 'expected ...' text), or None.

    Numbers must lie in a plausible range for their unit, which catches a value
    written in the wrong unit (a pitch of 0.0057 is millimetres, not µm).
    """
    (f,) = [f for f in dataclasses.fields(Optics) if f.name == name]
    if value is None:
        return None
    lo_hi = f.metadata["range"]
    if lo_hi is None:
        if isinstance(value, str) and value.strip():
            return None
        return f"{f.metadata['doc']} (a non-empty string)"
    lo, hi = lo_hi
    unit = f" in {f.metadata['unit']}" if f.metadata["unit"] else ""
    expected = f"{f.metadata['doc']}{unit} ({lo:g}..{hi:g})"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return expected
    if not lo <= value <= hi:
        return expected
    return None
