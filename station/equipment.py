"""The lens and the camera body being calibrated: who they are and their nominal optics.

:class:`Identity` (maker, model, serial) names a lens or a camera body; :class:`Optics` holds what
is known of their optics without measuring (nominal focal length, mount, pixel pitch, sensor width,
crop factor), each field declared with its plausible range and unit (:func:`drivers.settings.setting`;
:func:`optic_problem`). The station configuration reads them (``lens``, ``camera_body``:
:mod:`station.config`) and a profile records them (:class:`station.profile.Profile`), so they are
defined here, below both.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from drivers.settings import describe, fields_of, problem, setting


@dataclass(frozen=True)
class Identity:
    maker: str = setting(doc="the maker")
    model: str = setting(doc="the model")
    serial: str = setting(doc="the serial number (quote one that looks like a number)")

    def label(self) -> str:
        return f"{self.maker} {self.model} #{self.serial}"


@dataclass(frozen=True)
class Optics:
    """What the configuration says about the optics, for exports (every field optional).

    The harp measures the *shape* of the distortion, not these: they make an
    export's camera matrix nominal instead of a placeholder
    (:func:`pipeline.exports.lens.camera_matrix_choice`) and let lensfun
    applications find the lens (:mod:`pipeline.exports.lensfun`). In the YAML
    file ``focal_mm``, ``mount`` and ``aperture`` belong to ``lens``, the others to
    ``camera_body`` (each field's ``optics`` metadata); ``pixel_pitch_um`` and
    ``sensor_width_mm`` are alternatives (give one). The ranges are plausible
    values for their unit, which catches a value written in the wrong unit (a
    pitch of 0.0057 is millimetres, not µm).
    """

    focal_mm: float | None = setting(None, "the nominal focal length (at this zoom setting)", "mm", 0.1, 10000.0,
                                     optics="lens")  # fmt: skip
    mount: str | None = setting(None, "the lens mount, as lensfun names it (e.g. 'Canon EF')", optics="lens")
    aperture: float | None = setting(None, "the f-number the harp shots are taken at (lensfun files a vignetting "
                                     "under it)", "", 0.5, 100.0, optics="lens")  # fmt: skip
    pixel_pitch_um: float | None = setting(None, "the pixel pitch of the images (after any binning)", "µm", 0.2,
                                           100.0, optics="camera_body")  # fmt: skip
    sensor_width_mm: float | None = setting(None, "the width of the sensor area the image covers", "mm", 0.5, 200.0,
                                            optics="camera_body")  # fmt: skip
    crop_factor: float | None = setting(None, "the crop factor (35 mm diagonal / sensor diagonal)", "", 0.1, 20.0,
                                        optics="camera_body")  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        """The fields that are set (for a model file's provenance)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if getattr(self, f.name) is not None}

    @classmethod
    def from_dict(cls, d: Any) -> Optics:
        """The optics of a :meth:`to_dict` mapping; a value that is not valid is left out."""
        if not isinstance(d, Mapping):
            return cls()
        kw: dict[str, Any] = {}
        for name, s in fields_of(cls).items():
            v = d.get(name)
            if v is not None and optic_problem(name, v) is None:
                kw[name] = v if s.kind == "text" else float(v)
        return cls(**kw)


def optics_keys(section: str) -> tuple[str, ...]:
    """The :class:`Optics` keys of YAML section ``section`` (``lens`` or ``camera_body``)."""
    return tuple(f.name for f in dataclasses.fields(Optics) if f.metadata["optics"] == section)


def optic_problem(name: str, value: Any) -> str | None:
    """What :class:`Optics` field ``name`` expects (its meaning and :func:`~drivers.settings.describe`),
    when ``value`` is not valid for it; None when it is (or is None)."""
    s = fields_of(Optics)[name]
    if value is None or problem(s, value) is None:
        return None
    return f"{s.doc}, {describe(s)}"
