"""The residual distortion any correction leaves on harp shots (``harp evaluate``, :mod:`station.cli.evaluate`).

:func:`load_correction` reads any correction file :func:`pipeline.exports.registry.read_correction`
reads (the format detected from its content) as a model for the shots' image size;
:func:`evaluate` measures the string edges of the shots (taken through the lens, uncorrected),
corrects them (:func:`pipeline.evaluate.corrected_edges`), normalises them by the homography of
the 4 corrected image corners and reports their straightness before and after; edge points a
maps file or STMap does not cover (their ideal position is outside the corrected image it holds,
as at a wide lens's borders) are left out, never extrapolated, and counted (``n_excluded`` of
``n_points``, per image and in all; the after figures are on the points kept); with
``already_corrected`` the shots were corrected by other software and are only measured. Each shot's
residual after the correction is also split into the profile every string edge shares and each edge's
own part (``after_shared``, :func:`pipeline.shared_bend.shared_bend`): a large shared part is a term
the correction lacks or its shots left undetermined (shots at other orientations help), a large own
part the strings or the measurement. A shot
that cannot be read, has another size than the first, or holds no string is reported in
``errors`` and left out. Every other problem is an :class:`EvaluateError` (one line naming the file).
"""

from __future__ import annotations

from pathlib import Path

from pipeline.evaluate import corrected_edges
from pipeline.models.base import DistortionModel
from pipeline.models.homography import apply_homography
from pipeline.models.remap_model import RemapModel
from pipeline.normalise import corner_homography
from pipeline.resample import DEFAULT_T
from pipeline.shared_bend import shared_bend
from pipeline.straightness import straightness
from station.errors import InputError
from station.imageio import quiet_codecs
from station.inputs import NO_STRINGS, measure_grey, read_image


class EvaluateError(InputError):
    """One-line message for the user."""


def load_correction(
    path, width: int, height: int, focal: float | None = None, lens_name: str | None = None
) -> tuple[DistortionModel, str]:
    """Any correction file :func:`pipeline.exports.registry.read_correction` reads, as a model
    for ``width`` x ``height`` images: ``(model, kind)``.

    kind is ``harp:<model name>``, ``opencv``, ``opencv-fisheye``, ``ros``, ``ros-equidistant``,
    ``lensfun:<model>``, ``mrcal``, ``maps`` or ``stmap``. Raises EvaluateError (one line,
    naming the file) on any problem.
    """
    from pipeline.exports.registry import read_correction  # defers scipy, yaml

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
        # what OpenCV's FileStorage and OpenEXR print of a damaged file (OpenEXR on stdout too): the line says it;
        # nothing is printed before the correction is read
        with quiet_codecs(stdout=True):
            c = read_correction(data, str(p), width, height, focal=focal, lens_name=lens_name)
    except ValueError as exc:
        raise EvaluateError(str(exc)) from None
    return c.model, c.kind


def _sd(st) -> dict:
    return {"d": float(st.d), "d_max": float(st.d_max)}


def _normalisation(model: DistortionModel | None) -> str:
    """How the corrected points were normalised (what the figures are in)."""
    if isinstance(model, RemapModel) and model.corners_ideal is None:
        return (
            "the maps' own corners (the file stores no corrected image corners: "
            "figures not comparable with a model file's 4-corner ones)"
        )
    return "4 corrected image corners" if model is not None else "none"


def evaluate(
    correction_path: str, image_paths, *, already_corrected=False, focal=None, lens_name=None, t=DEFAULT_T
) -> dict:
    """The JSON report of ``harp evaluate`` (see the module docstring); raises InputError (one line)."""
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
    n_points = n_excluded = 0
    for path, img in images:
        meas = measure_grey(path, img, t, require_strings=False)
        pts = [ln.points for ln in meas.lines]
        entry: dict = {"path": str(path), "n_lines": len(pts)}
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
                ce = corrected_edges(pts, model, w, h)
                after, before = ce.points, pts
                entry.update(n_points=ce.n_points, n_excluded=ce.n_excluded)
                n_points += ce.n_points
                n_excluded += ce.n_excluded
        except ValueError as exc:
            raise EvaluateError(f"{correction_path}: {exc}") from None
        entry["before"] = _sd(straightness(before)) if before is not None else None
        entry["after"] = _sd(straightness(after)) if after else None
        shared = shared_bend(after) if after else None
        entry["after_shared"] = shared.to_dict() if shared is not None else None
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
        "n_points": n_points,
        "n_excluded": n_excluded,
        "normalisation": _normalisation(model),
        "images": per_image,
        "errors": errors,
    }
