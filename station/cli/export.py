"""``harp export MODEL --format opencv|ros|lensfun|json [-o FILE]``: a correction for other software.

OpenCV / ROS / lensfun cannot represent every lens: the export is the closest
member of their model family (least squares over the whole image, see
:mod:`pipeline.exports.fit`) and its conversion error in pixels is printed and
recorded in the exported file. ``json`` writes our own model file as JSON.
Exit 0 on success, 2 on bad input.
"""

from __future__ import annotations

import json
import math
import sys

from pipeline.exports.fit import fit_lensfun, fit_opencv
from pipeline.exports.lensfun import lensfun_text
from pipeline.exports.opencv import opencv_text
from pipeline.exports.ros import ros_text
from pipeline.model_file import FORMAT_NAME, FORMAT_VERSION, read_model_file
from station.files import atomic_write_text

FORMATS = ("opencv", "ros", "lensfun", "json")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "export",
        help="export a fitted model to OpenCV, ROS, lensfun or JSON",
        description=(
            "Export a fitted model to OpenCV FileStorage YAML, ROS camera_info YAML, "
            "lensfun XML or JSON, stating the conversion error in pixels."
        ),
    )
    p.add_argument("model", metavar="MODEL", help="harp model file (from harp calibrate)")
    p.add_argument("--format", required=True, choices=FORMATS)
    p.add_argument("-o", "--output", metavar="FILE", help="write here (default: print to stdout)")
    p.add_argument(
        "--focal",
        type=float,
        default=None,
        help="opencv/ros: nominal focal length in pixels (default: the image diagonal)",
    )
    p.add_argument(
        "--coeffs",
        type=int,
        choices=(5, 8),
        default=5,
        help="opencv/ros: 5 (plumb_bob) or 8 (rational_polynomial) coefficients (default 5)",
    )
    p.add_argument(
        "--lensfun-model",
        choices=("ptlens", "poly5", "poly3"),
        default="ptlens",
        help="lensfun distortion model (default ptlens)",
    )
    p.add_argument(
        "--lensfun-no-center",
        action="store_true",
        help="lensfun: keep the distortion centre at the image centre (no <center> element)",
    )
    p.add_argument(
        "--focal-mm",
        type=float,
        default=50.0,
        help="lensfun: focal length (mm) the calibration entry is filed under (default 50)",
    )
    p.add_argument("--camera-name", default="camera", help="ros: camera_name (default 'camera')")
    p.set_defaults(func=run)


def export_text(
    mf,
    fmt: str,
    *,
    focal=None,
    coeffs=5,
    lensfun_model="ptlens",
    focal_mm=50.0,
    camera_name="camera",
    lensfun_center=True,
):
    """(text, ConversionError or None) of the export of a loaded model file."""
    w, h = mf.width, mf.height
    if fmt == "json":
        doc = {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "model": mf.model.to_dict(),
            "image": {"width": w, "height": h},
            "merit": mf.merit,
            "provenance": mf.provenance,
        }
        return json.dumps(doc, indent=2) + "\n", None
    if fmt in ("opencv", "ros"):
        m, err = fit_opencv(mf.model, w, h, n_coeffs=coeffs, focal=focal)
        text = opencv_text(m, w, h, err) if fmt == "opencv" else ros_text(m, w, h, err, camera_name=camera_name)
        return text, err
    m, err = fit_lensfun(mf.model, w, h, kind=lensfun_model, fit_center=lensfun_center)
    return lensfun_text(m, err, focal=focal_mm), err


def run(args) -> int:
    if args.format == "lensfun" and not (math.isfinite(args.focal_mm) and args.focal_mm > 0):
        print(f"harp export: --focal-mm must be a focal length > 0 mm, got {args.focal_mm:g}", file=sys.stderr)
        return 2
    try:
        mf = read_model_file(args.model)
        text, err = export_text(
            mf,
            args.format,
            focal=args.focal,
            coeffs=args.coeffs,
            lensfun_model=args.lensfun_model,
            focal_mm=args.focal_mm,
            camera_name=args.camera_name,
            lensfun_center=not args.lensfun_no_center,
        )
    except ValueError as exc:
        print(f"harp export: {exc}", file=sys.stderr)
        return 2
    msg = None
    if err is not None:
        msg = (
            f"conversion error ({args.format}): RMS {err.rms_px:.4f} px, max {err.max_px:.4f} px "
            f"(4-corner normalised, {err.n_points} points); modulo best homography: "
            f"RMS {err.rms_mod_h_px:.4f} px, max {err.max_mod_h_px:.4f} px; residual on a noise-free "
            f"full-field harp: d {err.d_px:.4f} px, d_max {err.d_max_px:.4f} px"
        )
    if args.output:
        try:
            atomic_write_text(args.output, text)
        except OSError as exc:
            print(f"harp export: cannot write {args.output}: {exc.strerror or exc}", file=sys.stderr)
            return 2
        print(f"wrote {args.output}")
        if msg:
            print(msg)
    else:
        sys.stdout.write(text)
        if msg:
            print(msg, file=sys.stderr)
    return 0
