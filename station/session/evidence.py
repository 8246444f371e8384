"""Evidence kept in the session directory as ``.npz`` arrays: each shot's edge
measurement and each focus setting's bootstrap uncertainty map.

The executor measures every accepted shot once (:func:`pipeline.measure.measure_image`
on the averaged frames) and keeps the result next to the frames, so that the
session report and ``harp qa --report`` reuse it instead of measuring again.

:func:`measurement_arrays` turns a :class:`pipeline.measure.ImageMeasurement`
into plain arrays: every array field of every edge (``line<i>_<field>``) and
of every rejected group (``rejected<j>_points``), plus one JSON string
(``meta``) with all the scalar fields. Each numeric array is kept as its *byte planes*
(:func:`byte_planes`: the array in column order, byte k of every element together), which
the file's deflate compresses to 0.42 of the raw bytes instead of 0.59 (the demo session) (an edge point's integer
coordinate costs almost nothing once apart from its sub-pixel one); every bit is kept
(format 2; files of format 1, the arrays as they are, are read as before).
:func:`measurement_from_arrays` is the inverse; it raises ``ValueError`` when the file lacks a field the current
dataclasses need (written by another software version), and the caller then
measures the frames again.

:func:`uncertainty_arrays` / :func:`uncertainty_from_arrays` do the same for
a :class:`pipeline.uncertainty.FieldUncertainty` (the map behind the stored
RMS / max, shown by the report's uncertainty plot).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np

FORMAT = 2
"""Format of a stored measurement: 2 = numeric arrays as byte planes; 1 (read too) = arrays as they are."""
READ_FORMATS = (1, 2)


def byte_planes(a: np.ndarray) -> np.ndarray:
    """``uint8`` array ``(itemsize, size)``: row k holds byte k (little-endian) of every element of
    ``a`` taken in column (Fortran) order. :func:`from_byte_planes` is the exact inverse."""
    a = np.asarray(a)
    flat = a.astype(a.dtype.newbyteorder("<"), copy=False).ravel(order="F")
    return np.ascontiguousarray(flat.view(np.uint8).reshape(-1, a.dtype.itemsize).T)


def from_byte_planes(planes: np.ndarray, dtype: str, shape) -> np.ndarray:
    """The array :func:`byte_planes` made ``planes`` of (``dtype`` as ``numpy.dtype.str``)."""
    dt = np.dtype(dtype).newbyteorder("<")
    flat = np.ascontiguousarray(np.asarray(planes, np.uint8).T).view(dt).ravel()
    return np.ascontiguousarray(flat.reshape(tuple(shape), order="F").astype(dt.newbyteorder("="), copy=False))


def _split(obj) -> tuple[dict, dict]:
    """(scalar fields, array fields) of a dataclass instance."""
    scalars, arrays = {}, {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray):
            arrays[f.name] = v
        elif isinstance(v, np.generic):
            scalars[f.name] = v.item()
        else:
            scalars[f.name] = v
    return scalars, arrays


def measurement_arrays(m) -> dict[str, np.ndarray]:
    """Arrays of an ``ImageMeasurement`` (for :meth:`station.session_dir.SessionDir.write_arrays`)."""
    out: dict[str, np.ndarray] = {}
    lines = []
    for i, ln in enumerate(m.lines):
        scalars, arrays = _split(ln)
        lines.append(scalars)
        for k, a in arrays.items():
            out[f"line{i}_{k}"] = np.asarray(a)
    rejected = []
    for r in m.rejected:
        scalars, _ = _split(r)
        rejected.append(scalars)
    for j, pts in enumerate(m.rejected_points):
        out[f"rejected{j}_points"] = np.asarray(pts, np.float64)
    planes = {}
    for k, a in out.items():
        if a.dtype.kind in "iuf" and a.size:
            planes[k] = [a.dtype.str, list(a.shape)]
            out[k] = byte_planes(a)
    top = {
        f.name: getattr(m, f.name)
        for f in dataclasses.fields(m)
        if f.name not in ("lines", "rejected", "rejected_points")
    }
    top = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in top.items()}
    meta = {
        "format": FORMAT,
        "image": top,
        "lines": lines,
        "rejected": rejected,
        "n_rejected_points": len(m.rejected_points),
        "byte_planes": planes,
    }
    out["meta"] = np.array(json.dumps(meta))
    return out


def _build(cls, values: dict):
    names = {f.name for f in dataclasses.fields(cls)}
    required = {
        f.name
        for f in dataclasses.fields(cls)
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    }
    missing = required - set(values)
    if missing:
        raise ValueError(f"stored measurement lacks {cls.__name__} field(s) {', '.join(sorted(missing))}")
    return cls(**{k: v for k, v in values.items() if k in names})


def measurement_from_arrays(arrays: dict[str, np.ndarray]):
    """The ``ImageMeasurement`` of :func:`measurement_arrays`'s output."""
    from pipeline.measure import ImageMeasurement, LineMeasurement, Rejection  # defers cv2

    if "meta" not in arrays:
        raise ValueError("stored measurement has no 'meta'")
    meta = json.loads(str(arrays["meta"]))
    if meta.get("format") not in READ_FORMATS:
        raise ValueError(f"stored measurement format {meta.get('format')!r}, expected one of {READ_FORMATS}")
    planes = meta.get("byte_planes", {})
    arrays = {k: (from_byte_planes(a, *planes[k]) if k in planes else a) for k, a in arrays.items()}
    lines = []
    for i, scalars in enumerate(meta["lines"]):
        values = dict(scalars)
        prefix = f"line{i}_"
        values.update({k[len(prefix) :]: np.asarray(v) for k, v in arrays.items() if k.startswith(prefix)})
        lines.append(_build(LineMeasurement, values))
    rejected = []
    for r in meta["rejected"]:
        r = dict(r)
        if isinstance(r.get("bbox"), list):
            r["bbox"] = tuple(r["bbox"])
        rejected.append(_build(Rejection, r))
    rejected_points = tuple(np.asarray(arrays[f"rejected{j}_points"]) for j in range(int(meta["n_rejected_points"])))
    return _build(
        ImageMeasurement,
        {**meta["image"], "lines": tuple(lines), "rejected": tuple(rejected), "rejected_points": rejected_points},
    )


def uncertainty_arrays(u) -> dict[str, np.ndarray]:
    """Arrays of a ``FieldUncertainty`` (its model is the profile's, not stored here)."""
    return {
        "xs": np.asarray(u.xs, np.float64),
        "ys": np.asarray(u.ys, np.float64),
        "std": np.asarray(u.std, np.float64),
        "rms": np.float64(u.rms),
        "max": np.float64(u.max),
        "n_boot": np.int64(u.n_boot),
        "n_failed": np.int64(u.n_failed),
        "resample": np.array(u.resample),
        "failures": np.array(list(u.failures), dtype=str),
    }


def uncertainty_from_arrays(arrays: dict[str, np.ndarray], model):
    """The ``FieldUncertainty`` of :func:`uncertainty_arrays`'s output, for ``model``."""
    from pipeline.uncertainty import FieldUncertainty  # defers cv2

    try:
        return FieldUncertainty(
            rms=float(arrays["rms"]),
            max=float(arrays["max"]),
            xs=arrays["xs"],
            ys=arrays["ys"],
            std=arrays["std"],
            n_boot=int(arrays["n_boot"]),
            n_failed=int(arrays["n_failed"]),
            resample=str(arrays["resample"]),
            model=model,
            failures=tuple(str(x) for x in arrays.get("failures", ())),
        )
    except KeyError as exc:
        raise ValueError(f"stored uncertainty map lacks {exc.args[0]!r}") from None
