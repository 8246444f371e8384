"""The harp model file: a readable YAML record of a fitted distortion model.

This module is the format: :func:`model_file_text` writes a :class:`ModelFile`'s
text, :func:`parse_model_text` reads it back, :func:`read_model_file` /
:func:`load_model` read a file (the only file access of :mod:`pipeline`: the entry
point named in every model file's header). Writing a file (atomically) is the
station's (:func:`station.files.write_model_file`), and so is the provenance record
(:func:`station.provenance.make_provenance`: software version, input images with
their SHA-256), passed in here as plain data. Layout (format version 1)::

    format: harp-distortion-model
    format_version: 1
    model: {model: radial, center: [..], k: [..], scale: ..}   # model.to_dict()
    image: {width: 1761, height: 1174}
    merit: {fit: {d: .., d_max: ..}, holdout: {d: .., d_max: ..}, ...}
    provenance: {created_utc: .., software: harp-station 0.1.0, t: 30,
                 command: .., images: [{path: .., sha256: ..}, ..]}
    intrinsics: {fx: .., fy: .., cx: .., cy: .., sd: {..}, source: .., ...}   # optional:
                 # the camera matrix measured with this distortion (pipeline.intrinsics)
    colour: {tca: {..}, vignetting: {..}}   # optional: a colour camera's lateral chromatic aberration
                 # and vignetting from the same shots (station.session.colour: the documents
                 # harp tca --out and harp vignetting --out write), plain data

Any defect (not YAML, not our format, unknown version, unknown model, bad
parameters) raises :class:`ValueError` with a one-line message naming the file and
the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pipeline.intrinsics import Intrinsics
from pipeline.models import MODEL_TYPES, model_from_dict
from pipeline.models.base import DistortionModel
from pipeline.plain import plain

FORMAT_NAME = "harp-distortion-model"
FORMAT_VERSION = 1
SUPPORTED_VERSIONS = (1,)


@dataclass(frozen=True)
class ModelFile:
    """Contents of a model file."""

    model: DistortionModel
    width: int
    height: int
    merit: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    path: str | None = None
    intrinsics: Intrinsics | None = None
    colour: dict[str, Any] | None = None

    def text(self) -> str:
        """The file's text (:func:`model_file_text`)."""
        return model_file_text(
            self.model,
            width=self.width,
            height=self.height,
            merit=self.merit,
            provenance=self.provenance,
            intrinsics=self.intrinsics,
            colour=self.colour,
        )


def model_file_text(
    model: DistortionModel,
    *,
    width: int,
    height: int,
    merit: dict[str, Any] | None = None,
    provenance: dict[str, Any] | None = None,
    intrinsics: Intrinsics | None = None,
    colour: dict[str, Any] | None = None,
) -> str:
    """The text of a model file holding ``model`` for ``width x height`` images, with its
    figures of merit and provenance (plain data: numpy values and tuples are converted)
    and, when measured, the camera matrix (:class:`pipeline.intrinsics.Intrinsics`).

    Raises TypeError for something that is not a model, ValueError for a size <= 0.
    """
    if not isinstance(model, DistortionModel):
        raise TypeError(f"a model file holds a DistortionModel, got {type(model).__name__}")
    if int(width) <= 0 or int(height) <= 0:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    doc = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "model": plain(model.to_dict(), nonfinite_as_none=False),
        "image": {"width": int(width), "height": int(height)},
        "merit": plain(merit or {}, nonfinite_as_none=False),
        "provenance": plain(provenance or {}, nonfinite_as_none=False),
    }
    if intrinsics is not None:
        doc["intrinsics"] = plain(intrinsics.to_dict(), nonfinite_as_none=False)
    if colour:
        doc["colour"] = plain(colour, nonfinite_as_none=False)
    header = (
        "# harp station distortion model (maps distorted -> ideal pixels; x = column, y = row,\n"
        "# pixel centres at integers). Load with pipeline.load_model(path).\n"
    )
    return header + str(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100))


def parse_model_text(text: str, name: str = "<text>") -> ModelFile:
    """Parse model-file text; ``ValueError('<name>: <reason>')`` on any defect."""
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        _raise_if_foreign(text, name)
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"{name}: not a valid YAML model file ({reason})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT_NAME:
        _raise_if_foreign(text, name)
        raise ValueError(f"{name}: not a harp model file (no 'format: {FORMAT_NAME}')")
    version = doc.get("format_version")
    if version not in SUPPORTED_VERSIONS:
        raise ValueError(
            f"{name}: unknown model file format version {version!r} "
            f"(this software reads {', '.join(map(str, SUPPORTED_VERSIONS))})"
        )
    image: Any = doc.get("image")
    try:
        width, height = int(image["width"]), int(image["height"])
        if width <= 0 or height <= 0:
            raise ValueError
    except (TypeError, KeyError, ValueError):
        raise ValueError(f"{name}: missing or invalid image size (image: {{width, height}})") from None
    mdoc = doc.get("model")
    bad = not_finite(mdoc, "model")
    if bad is not None:
        raise ValueError(f"{name}: {bad[0]} is {bad[1]}; every parameter of the model must be a finite number")
    try:
        model = model_from_dict(mdoc)
    except ValueError as exc:
        if isinstance(mdoc, dict) and mdoc.get("model") in MODEL_TYPES:  # a bad parameter value
            raise ValueError(
                f"{name}: invalid parameters for model {mdoc.get('model')!r} ({str(exc).splitlines()[0]})"
            ) from None
        raise ValueError(f"{name}: {str(exc).splitlines()[0]}") from None
    except (TypeError, KeyError, IndexError) as exc:
        raise ValueError(
            f"{name}: invalid parameters for model "
            f"{(doc.get('model') or {}).get('model')!r} ({type(exc).__name__}: {exc})"
        ) from None
    merit = doc.get("merit") or {}
    prov = doc.get("provenance") or {}
    if not isinstance(merit, dict) or not isinstance(prov, dict):
        raise ValueError(f"{name}: 'merit' and 'provenance' must be mappings")
    intrinsics = None
    if doc.get("intrinsics") is not None:
        try:
            intrinsics = Intrinsics.from_dict(doc["intrinsics"])
        except ValueError as exc:
            raise ValueError(f"{name}: {exc}") from None
    colour = doc.get("colour")
    if colour is not None and not isinstance(colour, dict):
        raise ValueError(f"{name}: 'colour' must be a mapping (tca, vignetting)")
    return ModelFile(
        model=model,
        width=width,
        height=height,
        merit=merit,
        provenance=prov,
        path=name,
        intrinsics=intrinsics,
        colour=colour,
    )


def not_finite(node: Any, where: str = "") -> tuple[str, float] | None:
    """The first number in ``node`` (plain data: a model's mapping as read) that is NaN or infinite, with
    where it is (``model.k[1]``), else None. Text a float is made from counts (``nan``, ``inf``: what a
    model's ``float()`` would take)."""
    if isinstance(node, (float, str)) and not isinstance(node, bool):
        try:
            value = float(node)
        except ValueError:
            return None
        return None if math.isfinite(value) else (where, value)
    if isinstance(node, dict):
        for key, value in node.items():
            found = not_finite(value, f"{where}.{key}" if where else str(key))
            if found is not None:
                return found
    elif isinstance(node, list):
        try:  # a long list of numbers (a map, a grid) at once
            values = np.asarray(node, dtype=np.float64)
        except (TypeError, ValueError):
            values = None
        if values is not None and np.isfinite(values).all():
            return None
        for i, value in enumerate(node):
            found = not_finite(value, f"{where}[{i}]")
            if found is not None:
                return found
    return None


def _foreign_format(text: str) -> str | None:
    """What a known non-harp calibration file is (by its opening), else None."""
    head = text.lstrip()[:4096]
    if "!!opencv-matrix" in head or "<opencv_storage>" in head:
        return "an OpenCV FileStorage calibration file"
    if "<lensdatabase" in head:
        return "a lensfun XML profile"
    if "camera_matrix:" in head and "distortion_model:" in head:
        return "a ROS camera_info file"
    return None


def _raise_if_foreign(text: str, name: str) -> None:
    """A clear error for a known calibration file of other software."""
    foreign = _foreign_format(text)
    if foreign:
        raise ValueError(
            f"{name}: {foreign}, not a harp model file (harp evaluate reads it; "
            "this command needs a model written by harp calibrate)"
        )


def read_model_file(path: str | Path) -> ModelFile:
    """Read a model file (as :func:`model_file_text` writes it).

    Raises
    ------
    ValueError
        One line naming the file and the reason: unreadable, corrupt YAML,
        not a harp model file, unknown format version, unknown model.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ValueError(f"{path}: model file not found") from None
    except IsADirectoryError:
        raise ValueError(f"{path}: is a directory, not a model file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read model file ({exc.__class__.__name__}: {exc})") from None
    return parse_model_text(text, str(path))


def load_model(path: str | Path) -> DistortionModel:
    """The model of a saved model file (:func:`read_model_file`); ValueError (one line) if bad."""
    return read_model_file(path).model
