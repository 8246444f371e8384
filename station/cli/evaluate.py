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
their straightness reported before and after (:mod:`pipeline.evaluate`).

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
import sys
from pathlib import Path

from pipeline.evaluate import corrected_points
from pipeline.models.base import DistortionModel
from pipeline.models.homography import apply_homography
from pipeline.normalise import corner_homography
from pipeline.straightness import straightness
from station.cli.inputs import NO_STRINGS, InputError, measure_grey, positive_int, read_image


class EvaluateError(InputError):
    """One-line message for the user."""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "evaluate",
        help="measure the residual distortion left by any correction",
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
        "-t", "--t", dest="t", type=positive_int, default=30, help="along-edge subsampling factor (default 30)"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def load_correction(
    path, width: int, height: int, focal: float | None = None, lens_name: str | None = None
) -> tuple[DistortionModel, str]:
    """Any correction file :func:`pipeline.exports.registry.read_correction` reads, as a model
    for ``width`` x ``height`` images: ``(model, kind)``.

    kind is ``harp:<model name>``, ``opencv``, ``opencv-fisheye``, ``ros``, ``ros-equidistant``,
    ``lensfun:<model>``, ``mrcal``, ``maps`` or ``stmap``. Raises EvaluateError (one line,
    naming the file) on any problem.
    """
    from pipeline.exports.registry import read_correction

    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        hint = " ('none' means no correction only with --already-corrected)" if str(path).lower() == "none" else ""
        raise EvaluateError(f"{p}: correction file not found{hint}") from None
    except IsADirectoryError:
        raise EvaluateError(f"{p}: is a directory, not a correction file") from None
    except OSError as exc:
        raise EvaluateError(f"{p}: cannot read correction file ({exc.strerror or type(exc).__name__})") from None
    try:
        c = read_correction(data, str(p), width, height, focal=focal, lens_name=lens_name)
    except ValueError as exc:
        raise EvaluateError(str(exc)) from None
    return c.model, c.kind


def _sd(st) -> dict:
    return {"d": float(st.d), "d_max": float(st.d_max)}


def evaluate(correction_path: str, image_paths, *, already_corrected=False, focal=None, lens_name=None, t=30) -> dict:
    """The JSON report of ``harp evaluate`` (see module docstring); raises InputError (one line)."""
    images, size, errors = [], None, []
    for path in image_paths:  # a bad shot is reported and skipped; the others are evaluated
        try:
            img = read_image(path)
        except InputError as exc:
            errors.append({"path": str(path), "error": str(exc)})
            continue
        if size is None:
            size = (img.shape[1], img.shape[0])
        elif (img.shape[1], img.shape[0]) != size:
            errors.append(
                {
                    "path": str(path),
                    "error": f"{path}: image is {img.shape[1]}x{img.shape[0]}, the "
                    f"first is {size[0]}x{size[1]}; all shots must have the same size",
                }
            )
            continue
        images.append((path, img))
    if not images:
        raise EvaluateError(
            errors[0]["error"] if len(errors) == 1 else "no readable image: " + "; ".join(e["error"] for e in errors)
        )
    w, h = size
    if already_corrected and str(correction_path).lower() == "none":
        model, kind = None, "none"
    else:
        model, kind = load_correction(correction_path, w, h, focal, lens_name)
    before_all, after_all, per_image = [], [], []
    for path, img in images:
        meas = measure_grey(path, img, t, require_strings=False)
        pts = [ln.points for ln in meas.lines]
        entry = {"path": str(path), "n_lines": len(pts)}
        if not pts:
            entry.update(before=None, after=None, note="no string edge found")
            per_image.append(entry)
            errors.append({"path": str(path), "error": f"{path}: {NO_STRINGS}"})
            continue
        try:
            if already_corrected:
                if model is None:
                    after = pts
                else:
                    hc = corner_homography(model, w, h)
                    after = [apply_homography(hc, p) for p in pts]
                before = None
            else:
                after = corrected_points(pts, model, w, h)
                before = pts
        except ValueError as exc:
            raise EvaluateError(f"{correction_path}: {exc}") from None
        entry["before"] = _sd(straightness(before)) if before is not None else None
        entry["after"] = _sd(straightness(after))
        per_image.append(entry)
        after_all += after
        if before is not None:
            before_all += before
    if not after_all:
        raise EvaluateError(
            "no string edge found in any image"
            + "".join(f"; {e['error']}" for e in errors if NO_STRINGS not in e["error"])
        )
    return {
        "correction": str(correction_path),
        "kind": kind,
        "already_corrected": bool(already_corrected),
        "t": t,
        "width": w,
        "height": h,
        "before": _sd(straightness(before_all)) if before_all else None,
        "after": _sd(straightness(after_all)),
        "n_lines": len(after_all),
        "images": per_image,
        "errors": errors,
    }


def _fmt(sd):
    return ("     -", "     -") if sd is None else (f"{sd['d']:.4f}", f"{sd['d_max']:.4f}")


def run(args) -> int:
    try:
        rep = evaluate(
            args.correction,
            args.images,
            already_corrected=args.already_corrected,
            focal=args.focal,
            lens_name=args.lens,
            t=args.t,
        )
    except InputError as exc:
        print(f"harp evaluate: {exc}", file=sys.stderr)
        return 2
    for e in rep["errors"]:
        print(f"harp evaluate: {e['error']}", file=sys.stderr)
    status = 2 if rep["errors"] else 0
    if args.json:
        print(json.dumps(rep, indent=2))
        return status
    print(
        f"correction: {rep['correction']} ({rep['kind']}), {rep['width']}x{rep['height']}, t={rep['t']}"
        + (", images already corrected" if rep["already_corrected"] else "")
    )
    print(f"{'image':40s} {'lines':>5s} {'d before':>9s} {'dmax bef.':>9s} {'d after':>9s} {'dmax aft.':>9s}  (px)")
    for e in rep["images"]:
        b, a = _fmt(e["before"]), _fmt(e["after"])
        print(f"{Path(e['path']).name[:40]:40s} {e['n_lines']:5d} {b[0]:>9s} {b[1]:>9s} {a[0]:>9s} {a[1]:>9s}")
    b, a = _fmt(rep["before"]), _fmt(rep["after"])
    print(f"{'all':40s} {rep['n_lines']:5d} {b[0]:>9s} {b[1]:>9s} {a[0]:>9s} {a[1]:>9s}")
    return status
