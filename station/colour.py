"""Colour harp shots read and measured per channel, with one-line errors (``harp tca``).

A camera RAW file (:func:`station.raw.is_raw_path`) is read by LibRaw and measured per
CFA plane on its mosaic (:func:`pipeline.cfa.measure_mosaic`: no demosaicing); an 8- or
16-bit colour PNG/TIFF/PPM/JPEG per channel (:func:`pipeline.cfa.measure_channels`). A
grey image is refused: it has no colour channels (a monochrome camera has no lateral
chromatic aberration to measure). Every failure is an :class:`~station.errors.InputError`
naming the file.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pipeline.cfa import MosaicMeasurement, measure_channels, measure_mosaic
from pipeline.edgeset import FitFailure
from pipeline.models.tca_model import TcaField
from pipeline.resample import DEFAULT_T
from pipeline.tca import DEFAULT_TCA_DEGREE, LensfunTcaFit, TcaFit, channel_pairs, fit_tca, lensfun_tca
from station.bounded_read import BoundedReadError, read_regular_file
from station.errors import InputError
from station.imageio import ImageReadError
from station.inputs import NO_STRINGS, read_image
from station.raw import is_raw_path, read_raw

MONO = "a grey image has one channel: TCA needs a colour image or a camera RAW file (a monochrome camera has no TCA)"


def measure_colour_file(path, t: int = DEFAULT_T) -> MosaicMeasurement:
    """Read one colour shot and measure it per channel (module docstring); InputError naming the file."""
    try:
        if is_raw_path(path):
            raw = read_raw(path)
            m = measure_mosaic(raw.mosaic, raw.pattern, t=t)
        else:
            img = read_image(path, grey=False)
            if img.ndim == 2 or img.shape[2] == 1:
                raise InputError(f"{path}: {MONO}")
            if img.shape[2] == 2:
                raise InputError(f"{path}: a grey image with alpha: {MONO}")
            m = measure_channels(img, t=t, order="BGR")
    except ImageReadError as exc:
        raise InputError(str(exc)) from None
    except (ValueError, MemoryError) as exc:
        raise InputError(f"{path}: cannot measure: {exc}") from None
    missing = [n for n, pm in m.planes.items() if pm.n_lines == 0]
    if missing:
        raise InputError(f"{path}: channel {', '.join(missing)}: {NO_STRINGS}")
    return m


def fit_channels(
    shots: Sequence[MosaicMeasurement], paths: Sequence[Any], degree: int = DEFAULT_TCA_DEGREE
) -> tuple[dict[str, TcaFit], dict[str, LensfunTcaFit]]:
    """The red and blue fields against green, and lensfun's linear and poly3 conversions."""
    sizes = {(m.width, m.height) for m in shots}
    if len(sizes) != 1:
        listed = ", ".join(f"{Path(str(p)).name} {m.width}x{m.height}" for p, m in zip(paths, shots))
        raise InputError(f"the shots have different sizes ({listed}): give shots of one camera")
    w, h = sizes.pop()
    fits: dict[str, TcaFit] = {}
    for ch in "RB":
        f = fit_tca(*channel_pairs(shots, ch), w, h, channel=ch, degree=degree)
        if isinstance(f, FitFailure):
            raise InputError(f.reason)
        fits[ch] = f
    fields = {c: f.field for c, f in fits.items()}
    return fits, {k: lensfun_tca(fields, k) for k in ("linear", "poly3")}


def tca_document(fits: dict[str, TcaFit], lensfun: dict[str, LensfunTcaFit], paths: Sequence[Any]) -> dict[str, Any]:
    """What ``harp tca --out`` writes and ``--json`` prints."""
    any_fit = next(iter(fits.values()))
    return {
        "format": "harp-tca",
        "version": 1,
        "image_size": [any_fit.field.width, any_fit.field.height],
        "reference": "G",
        "images": [str(p) for p in paths],
        "channels": {c: f.to_dict() for c, f in fits.items()},
        "lensfun": {
            k: {
                "model": k,
                "red": list(v.model.red),
                "blue": list(v.model.blue),
                "conversion_error_px": {c: {"rms": e.rms, "max": e.max} for c, e in v.error.items()},
            }
            for k, v in lensfun.items()
        },
    }


def read_document(path, fmt: str, what: str, command: str) -> dict[str, Any]:
    """A harp result file (YAML or JSON by the suffix) whose ``format`` is ``fmt``.

    ``what`` names it (``"a harp TCA file"``), ``command`` writes it (``"harp tca --out"``);
    an :class:`~station.errors.InputError` naming the file when it cannot be read or is not one.
    """
    import json

    import yaml

    p = Path(path)
    try:
        text = read_regular_file(p, 1 << 22, what=what).decode("utf-8")
        doc = json.loads(text) if p.suffix.lower() == ".json" else yaml.safe_load(text)
    except BoundedReadError as exc:
        raise InputError(f"{p}: {exc.reason}") from None
    except (ValueError, yaml.YAMLError) as exc:
        raise InputError(f"{p}: not {what} ({type(exc).__name__}); write one with {command}") from None
    if not isinstance(doc, dict) or doc.get("format") != fmt:
        raise InputError(f"{p}: not {what} (no 'format: {fmt}'); write one with {command}")
    return doc


def read_tca_file(path, width: int, height: int) -> dict[str, Any]:
    """The red and blue :class:`~pipeline.models.tca_model.TcaField` of a ``harp tca --out`` file.

    Returns ``{"R": field, "B": field}``; an :class:`~station.errors.InputError` naming the file when
    it is not a harp TCA file (YAML or JSON), lacks a channel, or is for another image size.
    """
    p = Path(path)
    return tca_fields(read_document(p, "harp-tca", "a harp TCA file", "harp tca --out"), str(p), width, height)


def tca_fields(doc: dict[str, Any], p: str, width: int, height: int) -> dict[str, Any]:
    """:func:`read_tca_file` of a document already read (a profile's stored one); ``p`` names it."""
    fields: dict[str, Any] = {}
    for ch in "RB":
        try:
            fields[ch] = TcaField.from_dict(doc["channels"][ch]["field"])
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{p}: channels.{ch}.field: missing or malformed ({exc})") from None
        if (fields[ch].width, fields[ch].height) != (width, height):
            raise InputError(
                f"{p}: the TCA is for {fields[ch].width}x{fields[ch].height} images, the model for {width}x{height}"
            )
    return fields
