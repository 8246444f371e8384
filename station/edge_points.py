"""The edge-points file of ``harp measure --points FILE``: every string edge's points, for other tools.

Any plumb-line method (the third application of the calibration harp, Tang et al. 2012)
can start from these points: per image and per string edge, the raw sub-pixel edge
points (:func:`pipeline.edges.detect_edges`, grouped by :mod:`pipeline.grouping`) and the
smoothed points, one in ``t`` along the edge (:mod:`pipeline.resample`), which are what
``d``/``d_max`` and the distortion fits use. Coordinates: ``x`` = column, ``y`` = row,
pixel centres at integer coordinates, in pixels of the image as read.

The format is chosen by the file's suffix.

``.json`` (one object)::

    {"format": "harp-edge-points", "version": 1,
     "coordinates": "x = column, y = row, pixel centres at integers, pixels",
     "images": [{"path": str, "width": int, "height": int, "t": int, "smoothing": str,
                 "edges": [{"string": int, "polarity": +1 | -1,
                            "raw": [[x, y], ...], "raw_pieces": [[start, stop], ...],
                            "smoothed": [[x, y], ...], "smoothed_pieces": [[start, stop], ...]},
                           ...]},
                ...]}

``.npz`` (numpy ``savez_compressed``): the array ``meta`` holds the JSON text of the same
object without the four point arrays of each edge, which are the arrays
``img{i}_edge{j}_raw`` / ``_raw_pieces`` / ``_smoothed`` / ``_smoothed_pieces``
(float64 ``(N, 2)`` points, int64 ``(P, 2)`` ranges) of image ``i``, edge ``j``.

An edge is ordered along the harp direction; its points are split into *pieces*
(``[start, stop)`` index ranges, same order in both arrays) where the edge has a gap
(a string leaving the image and coming back, dust): within a piece the points are
contiguous, across pieces they are not. ``polarity`` and ``string`` are those of
:class:`pipeline.measure.LineMeasurement`: the two edges of a string share ``string``
and have opposite polarities. :func:`read_edge_points` reads either form back.
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.measure import ImageMeasurement
from pipeline.plain import json_default

FORMAT = "harp-edge-points"
VERSION = 1
SUFFIXES = (".json", ".npz")
_ARRAYS = ("raw", "raw_pieces", "smoothed", "smoothed_pieces")


def _edges(m: ImageMeasurement) -> list[dict[str, Any]]:
    out = []
    for ln in m.lines:
        raw_pieces = ln.raw_pieces if len(ln.raw_pieces) else np.array([[0, len(ln.raw_points)]])
        pt_pieces = ln.point_pieces if len(ln.point_pieces) else np.array([[0, len(ln.points)]])
        out.append(
            {
                "string": int(ln.string_id),
                "polarity": int(ln.polarity),
                "raw": np.asarray(ln.raw_points, np.float64),
                "raw_pieces": np.asarray(raw_pieces, np.int64).reshape(-1, 2),
                "smoothed": np.asarray(ln.points, np.float64),
                "smoothed_pieces": np.asarray(pt_pieces, np.int64).reshape(-1, 2),
            }
        )
    return out


def edge_points_document(results: list[tuple[str, ImageMeasurement]]) -> dict[str, Any]:
    """The file's object (arrays as numpy arrays) for ``(path, measurement)`` pairs."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "coordinates": "x = column, y = row, pixel centres at integers, pixels",
        "images": [
            {
                "path": str(path),
                "width": int(m.width),
                "height": int(m.height),
                "t": int(m.t),
                "smoothing": m.smoothing,
                "edges": _edges(m),
            }
            for path, m in results
        ],
    }


def edge_points_bytes(results: list[tuple[str, ImageMeasurement]], suffix: str) -> bytes:
    """The file's content for the format of ``suffix`` (``.json`` or ``.npz``)."""
    doc = edge_points_document(results)
    if suffix == ".json":
        return (json.dumps(doc, allow_nan=False, default=json_default) + "\n").encode()
    if suffix == ".npz":
        arrays: dict[str, np.ndarray] = {}
        for i, im in enumerate(doc["images"]):
            for j, e in enumerate(im["edges"]):
                for k in _ARRAYS:
                    arrays[f"img{i}_edge{j}_{k}"] = e.pop(k)
        buf = io.BytesIO()
        np.savez_compressed(buf, meta=np.array(json.dumps(doc)), **arrays)
        return buf.getvalue()
    raise ValueError(f"unknown edge-points format {suffix!r}: use a file name ending in .json or .npz")


def read_edge_points(path: str | Path) -> dict[str, Any]:
    """The object of an edge-points file (JSON or NPZ), points as float64 ``(N, 2)`` arrays and
    pieces as int64 ``(P, 2)`` arrays. ValueError (one line) for anything else."""
    p = Path(path)
    if p.suffix.lower() == ".json":
        doc = json.loads(p.read_text())
        if doc.get("format") != FORMAT:
            raise ValueError(f"{p}: not an edge-points file (format {doc.get('format')!r})")
        for im in doc["images"]:
            for e in im["edges"]:
                e["raw"] = np.asarray(e["raw"], np.float64).reshape(-1, 2)
                e["smoothed"] = np.asarray(e["smoothed"], np.float64).reshape(-1, 2)
                e["raw_pieces"] = np.asarray(e["raw_pieces"], np.int64).reshape(-1, 2)
                e["smoothed_pieces"] = np.asarray(e["smoothed_pieces"], np.int64).reshape(-1, 2)
        return dict(doc)
    if p.suffix.lower() == ".npz":
        with np.load(p, allow_pickle=False) as z:
            doc = json.loads(str(z["meta"]))
            if doc.get("format") != FORMAT:
                raise ValueError(f"{p}: not an edge-points file (format {doc.get('format')!r})")
            for i, im in enumerate(doc["images"]):
                for j, e in enumerate(im["edges"]):
                    for k in _ARRAYS:
                        e[k] = z[f"img{i}_edge{j}_{k}"]
        return dict(doc)
    raise ValueError(f"{p}: unknown edge-points format {p.suffix!r}: use .json or .npz")
