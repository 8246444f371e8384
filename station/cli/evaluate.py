"""``harp evaluate CORRECTION IMAGE... [--json]``: residual distortion left by any correction.

CORRECTION is any file :func:`pipeline.exports.registry.read_correction` reads
(the format is detected from its content): a harp model file (YAML or JSON), an
OpenCV calibration (FileStorage YAML or XML with ``camera_matrix`` +
``distortion_coefficients``, pin-hole or fisheye), a ROS camera_info YAML
(plumb_bob, rational_polynomial, equidistant), a lensfun XML (``<lensdatabase>``;
``--lens`` picks a lens of a database holding several, ``--focal-mm`` a calibration), a
mrcal ``.cameramodel``, maps ``.npz`` or an STMap ``.exr``. The string edges of the harp
shots (taken through the lens, uncorrected) are measured, corrected by
CORRECTION, normalised by the homography of the 4 corrected image corners and
their straightness reported before and after (:mod:`pipeline.evaluate`), one row per
shot and ``all``; each shot's residual after the correction is split into the part every string edge
shares and each edge's own (``shared after``, ``own after``; JSON ``after_shared``,
:mod:`pipeline.shared_bend`): a large shared part is a term the correction lacks or its shots left
undetermined (add shots at other orientations), a large own part the strings or the measurement (off a terminal tab-separated with a header line, :mod:`station.tables`). Edge
points a maps file or STMap does not cover (outside the corrected image it holds: a wide lens's
borders) are left out, never extrapolated, and their number printed (JSON: ``n_excluded``
of ``n_points``).

``--already-corrected``: the images were corrected by other software; they
are only measured (CORRECTION may be ``none``; when it is known, the
measured points are put in the same 4-corner normalised frame).
A shot that cannot be read, has another size than the first, or holds no
string is named on stderr (one line each) and left out; the others are
evaluated and reported (JSON: ``errors``), and the exit code is 2.
Exit 0 on success, 2 on bad input.
"""

from __future__ import annotations

import json

from pipeline.resample import DEFAULT_T
from station.cli.commands import COMMANDS
from station.cli.inputs import positive_int
from station.cli.say import say
from station.evaluation import evaluate
from station.exit_codes import EXIT_ERROR, EXIT_OK
from station.tables import print_table


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "evaluate",
        help=COMMANDS["evaluate"],
        description=(
            "Residual distortion left by any correction (harp model, OpenCV YAML/XML, ROS "
            "camera_info YAML, lensfun XML, mrcal .cameramodel, maps .npz or STMap .exr), measured on "
            "harp shots: d and d_max before and after, 4-corner normalised."
        ),
    )
    p.add_argument(
        "correction",
        metavar="CORRECTION",
        help="harp model, OpenCV, ROS, lensfun, mrcal, maps or STMap file ('none' with --already-corrected)",
    )
    p.add_argument("images", metavar="IMAGE", nargs="+", help="harp shots")
    p.add_argument(
        "--already-corrected", action="store_true", help="images were corrected by other software: only measure them"
    )
    p.add_argument(
        "--focal-mm",
        dest="focal",
        type=float,
        default=None,
        help="lensfun: focal length (mm) of the calibration entry to use",
    )
    p.add_argument(
        "--lens", default=None, metavar="NAME", help="lensfun: the lens ('maker model' or 'model') of a database"
    )
    p.add_argument(
        "-t",
        "--t",
        dest="t",
        type=positive_int,
        default=DEFAULT_T,
        help=f"along-edge subsampling factor (default {DEFAULT_T})",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _fmt(sd):
    return ("", "") if sd is None else (f"{sd['d']:.4f}", f"{sd['d_max']:.4f}")


def _shared(sb) -> tuple[str, str]:
    """A shot's residual shared by every string edge and each edge's own (:mod:`pipeline.shared_bend`)."""
    return ("-", "-") if sb is None else (f"{sb['shared_px']:.4f}", f"{sb['own_px']:.4f}")


def run(args) -> int:
    rep = evaluate(
        args.correction,
        args.images,
        already_corrected=args.already_corrected,
        focal=args.focal,
        lens_name=args.lens,
        t=args.t,
    )
    for e in rep["errors"]:  # a bad image is named on stderr; the others are still evaluated
        say("harp evaluate", e["error"])
    status = EXIT_ERROR if rep["errors"] else EXIT_OK
    if args.json:
        print(json.dumps(rep, indent=2))
        return status
    print(
        f"correction: {rep['correction']} ({rep['kind']}), {rep['width']}x{rep['height']}, t={rep['t']}"
        + (", images already corrected" if rep["already_corrected"] else "")
    )
    columns = (
        "image",
        "lines",
        "d before (px)",
        "d_max before (px)",
        "d after (px)",
        "d_max after (px)",
        "shared after (px)",
        "own after (px)",
    )
    rows = [
        (str(e["path"]), str(e["n_lines"]), *_fmt(e["before"]), *_fmt(e["after"]), *_shared(e.get("after_shared")))
        for e in rep["images"]
    ]
    rows.append(("all", str(rep["n_lines"]), *_fmt(rep["before"]), *_fmt(rep["after"]), "", ""))
    print_table(columns, rows, title="straightness before and after the correction", right=columns[1:])
    if rep.get("n_excluded"):
        print(
            f"{rep['n_excluded']} of {rep['n_points']} edge points left out: outside the area the correction "
            "defines (a maps file or STMap holds the corrected image only); the after figures are on the others"
        )
    if rep["normalisation"] not in ("4 corrected image corners", "none"):
        print(f"normalised by {rep['normalisation']}")
    return status
