"""``harp measure IMAGE... [--t 30] [--json] [--overlay DIR] [--points FILE]``: straightness of the strings.

Each image is read (PGM/PNG/TIFF/JPEG, 8 or 16 bit, colour converted to
grey), its string edges are found and measured
(:func:`pipeline.measure.measure_image`); the command prints ``d`` and
``d_max`` per image and over all images (all edges of all images pooled, as
in Tang et al. 2012) as two tables — every edge, then each image and ``all`` — on a
terminal drawn by rich, otherwise tab-separated text with a header line each and a
blank line between (:mod:`station.tables`); or with ``--json`` exactly one JSON
object on stdout::

    {"d": float, "d_max": float, "n_lines": int,
     "images": [{"path": str, "width": int, "height": int, "d": float, "d_max": float,
                 "n_lines": int, "smoothing": str,
                 "lines": [{"points": int, "rms": float, "p2p": float,
                            "angle_deg": float, "length_px": float, "hf_rms": float,
                            "start": [x, y], "end": [x, y], "pieces": int, ...}], ...}],
     "errors": [{"path": str, "error": str}]}

(distances in pixels; ``d``/``d_max`` are ``null`` when nothing was measured;
``start``/``end`` are the first and last smoothed points of the edge, its two ends as
measured). ``--overlay DIR`` writes ``DIR/<image name>.overlay.png`` per image.
``--points FILE`` writes every edge's raw sub-pixel points and smoothed points, per
image (``FILE`` ending in ``.json`` or ``.npz``; the format is :mod:`station.edge_points`),
for any other plumb-line method. ``--smoothing gaussian`` uses the paper's plain
Gaussian along the edges (3 sigma lost at both ends of every piece) instead of the
local quadratic regression that keeps every edge to its ends (:mod:`pipeline.resample`).

Bad input (missing or unreadable file, truncated data, a directory, an image
without strings): one line on stderr naming the file and the reason; the
other images are still measured and reported; exit code 2. Exit 0 when
every image was measured.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from pipeline.measure import ImageMeasurement
from pipeline.resample import DEFAULT_T
from pipeline.straightness import straightness
from station.cli.commands import COMMANDS
from station.cli.inputs import positive_int
from station.cli.say import say
from station.errors import InputError
from station.exit_codes import EXIT_ERROR, EXIT_OK
from station.files import atomic_write_bytes
from station.inputs import measure_file
from station.qa.overlay import write_overlay
from station.tables import is_terminal, print_table


def register(subparsers) -> None:
    p = subparsers.add_parser("measure", help=COMMANDS["measure"], description=__doc__.split("\n\n")[0])
    p.add_argument("images", metavar="IMAGE", nargs="+", help="harp photographs (PGM/PNG/TIFF/JPEG)")
    p.add_argument(
        "-t",
        "--t",
        type=positive_int,
        default=DEFAULT_T,
        help=f"along-edge subsampling factor; blur sigma 0.8*sqrt(t^2-1) px (default {DEFAULT_T})",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    p.add_argument("--overlay", metavar="DIR", help="write an overlay PNG per image into DIR")
    p.add_argument(
        "--points",
        metavar="FILE",
        help="write every edge's raw and smoothed points to FILE (.json or .npz, see station.edge_points)",
    )
    p.add_argument(
        "--smoothing",
        choices=("local-quadratic", "gaussian"),
        default="local-quadratic",
        help="along-edge smoothing: local quadratic regression to the ends (default) or the paper's Gaussian",
    )
    p.set_defaults(func=run)


def _overlay_names(paths: list[str]) -> dict[str, str]:
    """Unique overlay file names (``<name>.overlay.png``, numbered on clashes)."""
    names: dict[str, str] = {}
    used: set[str] = set()
    for p in paths:
        base = Path(p).name or "image"
        name, k = f"{base}.overlay.png", 1
        while name in used:
            k += 1
            name = f"{base}.{k}.overlay.png"
        used.add(name)
        names[p] = name
    return names


def _fmt(v) -> str:
    return "" if v is None or not np.isfinite(v) else f"{v:.4f}"  # a missing figure: an empty field


EDGE_COLUMNS = (
    "image",
    "string",
    "edge",
    "points",
    "rms (px)",
    "p2p (px)",
    "angle (deg)",
    "length (px)",
    "hf_rms (px)",
)
IMAGE_COLUMNS = ("image", "size", "string width (px)", "strings", "edges", "d (px)", "d_max (px)", "rejected groups")


def _print_tables(results: list[tuple[str, ImageMeasurement]], overall: dict) -> None:
    """Every edge of every image, then d and d_max per image and over all of them
    (:func:`station.tables.print_table`: off a terminal two tab-separated tables, a blank line between)."""
    edges = [
        (
            path,
            str(ln.string_id),
            "+" if ln.polarity > 0 else "-",
            str(len(ln.points)),
            f"{ln.rms:.4f}",
            f"{ln.p2p:.4f}",
            f"{ln.angle_deg:.2f}",
            f"{ln.length_px:.1f}",
            f"{ln.hf_rms:.4f}",
        )
        for path, m in results
        for ln in m.lines
    ]
    print_table(EDGE_COLUMNS, edges, title="edges", right=EDGE_COLUMNS[1:])
    if not is_terminal():
        print()
    rows = []
    for path, m in results:
        rej = m.to_dict()["rejected"]
        rows.append(
            (
                path,
                f"{m.width}x{m.height}",
                f"{m.string_width_px:.2f}",
                str(m.n_strings),
                str(m.n_lines),
                _fmt(m.d),
                _fmt(m.d_max),
                ", ".join(f"{k}: {v}" for k, v in sorted(rej.items())),
            )
        )
    rows.append(("all", "", "", "", str(overall["n_lines"]), _fmt(overall["d"]), _fmt(overall["d_max"]), ""))
    print_table(
        IMAGE_COLUMNS, rows, title="per image and overall (all edges of all images pooled)", right=IMAGE_COLUMNS[2:7]
    )


def run(args) -> int:
    t = int(args.t)
    overlay_dir = None
    status = EXIT_OK
    points_path = Path(args.points) if args.points else None
    if points_path is not None and points_path.suffix.lower() not in (".json", ".npz"):
        raise InputError(
            f"{points_path}: unknown points format {points_path.suffix or '(none)'!r}: "
            "give a file name ending in .json or .npz"
        )
    if args.overlay:
        overlay_dir = Path(args.overlay)
        try:
            overlay_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            reason = (
                "exists and is not a directory"
                if overlay_dir.exists() and not overlay_dir.is_dir()
                else exc.strerror or exc
            )
            raise InputError(f"{overlay_dir}: cannot create overlay directory: {reason}") from None
    names = _overlay_names(list(args.images))
    results: list[tuple[str, ImageMeasurement]] = []
    errors: list[dict] = []
    for path in args.images:
        try:
            img, m = measure_file(path, t, smoothing=args.smoothing)
        except InputError as exc:
            say("harp measure", exc)
            errors.append({"path": path, "error": str(exc)})
            status = EXIT_ERROR
            continue
        results.append((path, m))
        if overlay_dir is not None:
            try:
                write_overlay(overlay_dir / names[path], img, m, title=Path(path).name)
            except OSError as exc:
                say("harp measure", f"{path}: cannot write overlay: {exc}")
                status = EXIT_ERROR

    all_points = [ln.points for _, m in results for ln in m.lines]
    if all_points:
        st = straightness(all_points)
        overall = {"d": st.d, "d_max": st.d_max, "n_lines": st.n_lines}
    else:
        overall = {"d": None, "d_max": None, "n_lines": 0}

    if points_path is not None:
        from station.edge_points import edge_points_bytes  # defers station.edge_points: --points only

        try:
            atomic_write_bytes(points_path, edge_points_bytes(results, points_path.suffix.lower()))
        except OSError as exc:
            say("harp measure", f"{points_path}: cannot write the points file: {exc.strerror or exc}")
            status = EXIT_ERROR

    if args.json:
        images = []
        for path, m in results:
            d = m.to_dict()
            images.append({"path": path, **d})
        doc = {**overall, "t": t, "images": images, "errors": errors}
        json.dump(doc, sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    elif results:
        _print_tables(results, overall)
    return status
