r"""The conversion error of an export: how far a converted correction is from the harp's, and in which frame.

An export (:mod:`pipeline.exports.fit`) is the member of another program's family closest to our
correction; this module measures how far it is. The conversion error is measured in the correction
direction, on a grid denser than the fitting grid, comparing the export's correction
:math:`U_\theta = D_\theta^{-1}` with ours after *both* are normalised by their 4-corner homography
(:mod:`pipeline.normalise`) — the comparison ``harp evaluate`` makes — and modulo the best least-squares
homography (the intrinsic mismatch), the latter in the largest of three frames point by point: the
export's own output pixels (its consumer's), our ideal pixels and the 4-corner normalised frame
(:func:`worst_frame_mod_h`), plus the straightness it leaves on lines our correction makes straight and,
when the fitting shots' edges are given, on those shots.

References
----------
.. [1] Z. Tang et al., "High-precision camera distortion measurements with a
   calibration harp", JOSA A 29(10), 2012, section 2 (corrections modulo homography).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.corrected_frame import CorrectedFrame
from pipeline.evaluate import corrected_points
from pipeline.models.base import DistortionModel
from pipeline.models.homography import apply_homography
from pipeline.normalise import corner_homography, fit_homography, normalise_by_corners
from pipeline.straightness import Straightness, straightness

Array = npt.NDArray[np.float64]

ERROR_GRID_LONG = 121
"""Conversion-error grid: points along the long side (denser than the fitting grid)."""


@dataclass(frozen=True)
class ConversionError:
    """How far an exported correction is from ours, in pixels over the image.

    Attributes
    ----------
    rms_px, max_px : float
        RMS and max over the grid of ``|N(U_export)(x) - N(U_ours)(x)|`` with
        ``N`` the 4-corner homography normalisation (what ``harp evaluate`` sees).
    rms_mod_h_px, max_mod_h_px : float
        The distance after the best least-squares homography between the two, each point's
        largest over the export's own output pixels (where its consumer measures), our ideal
        pixels and the 4-corner normalised frame (:func:`worst_frame_mod_h`).
    n_points : int
        Grid points compared (the whole image, borders included).
    d_px, d_max_px : float
        Straightness (Tang et al. ``d``, ``d_max``) of straight lines that our
        correction makes exactly straight, after the export's correction:
        the residual distortion ``harp evaluate`` would report for the export
        on a noise-free harp (lines every ~1/16 of the image at 0, 45, 90 and
        135 degrees, a point every 4 px). Homography-invariant.
    shots_d_px, shots_d_max_px : float
        Straightness the export leaves on the measured edges of the shots the
        model was fitted on (NaN when they were not given).
    model_shots_d_px, model_shots_d_max_px : float
        Our own correction's straightness on the same edges, for comparison.
    """

    rms_px: float
    max_px: float
    rms_mod_h_px: float
    max_mod_h_px: float
    n_points: int
    d_px: float = float("nan")
    d_max_px: float = float("nan")
    shots_d_px: float = float("nan")
    shots_d_max_px: float = float("nan")
    model_shots_d_px: float = float("nan")
    model_shots_d_max_px: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {
            "rms_px": self.rms_px,
            "max_px": self.max_px,
            "rms_mod_h_px": self.rms_mod_h_px,
            "max_mod_h_px": self.max_mod_h_px,
            "n_points": self.n_points,
            "d_px": self.d_px,
            "d_max_px": self.d_max_px,
            "shots_d_px": self.shots_d_px,
            "shots_d_max_px": self.shots_d_max_px,
            "model_shots_d_px": self.model_shots_d_px,
            "model_shots_d_max_px": self.model_shots_d_max_px,
        }

    def lines(self) -> list[str]:
        """The figures as short human-readable lines (for file comments and the terminal)."""
        out = [
            f"conversion error vs the harp correction, modulo best homography (in the file's camera pixels or "
            f"the harp model's, the larger): RMS {self.rms_mod_h_px:.4f} px, "
            f"max {self.max_mod_h_px:.4f} px; 4-corner normalised: RMS {self.rms_px:.4f} px, "
            f"max {self.max_px:.4f} px ({self.n_points} points over the whole image)",
            f"residual it leaves on a noise-free full-field harp: d {self.d_px:.4f} px, d_max {self.d_max_px:.4f} px",
        ]
        if np.isfinite(self.shots_d_px):
            out.append(
                f"residual on the fitting shots: d {self.shots_d_px:.4f} px, d_max {self.shots_d_max_px:.4f} px "
                f"(the harp correction itself: d {self.model_shots_d_px:.4f} px, "
                f"d_max {self.model_shots_d_max_px:.4f} px)"
            )
        return out


def image_grid(width: int, height: int, n_long: int = 64) -> Array:
    """Grid of pixel positions covering the image (borders included), ``n_long`` along the long side."""
    n_long = max(int(n_long), 2)
    if width >= height:
        nx, ny = n_long, max(2, int(round(n_long * height / width)))
    else:
        nx, ny = max(2, int(round(n_long * width / height))), n_long
    xs = np.linspace(0.0, width - 1.0, nx)
    ys = np.linspace(0.0, height - 1.0, ny)
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def conversion_error(
    ours: DistortionModel,
    theirs: DistortionModel,
    width: int,
    height: int,
    n_long: int = ERROR_GRID_LONG,
    edges: Sequence[Array] | None = None,
    export: str = "the export",
    remedy: str = "try another format (--format auto picks the closest)",
) -> ConversionError:
    """Compare two corrections over the image: 4-corner normalised, and modulo best homography.

    ``edges``: the measured edge points (distorted pixels) of the shots ``ours``
    was fitted on; with them the figures include the straightness the export
    leaves on those shots. ``export`` names the export family (e.g. "the OpenCV
    5-coefficient pin-hole model") in the error raised when its correction is not
    defined over the image, so that the message blames the format, not the harp's model;
    ``remedy`` is what that message tells the user to do.
    """
    g = image_grid(width, height, n_long)
    uo = ours.undistort_points(g)
    ut = theirs.undistort_points(g)
    ok = np.all(np.isfinite(uo), axis=1) & np.all(np.isfinite(ut), axis=1)
    cannot = f"{export} cannot represent this lens over the whole image"
    if ok.sum() < 0.99 * len(g):
        raise ValueError(
            f"{cannot}: its correction is undefined on {np.sum(~ok)} of {len(g)} grid points "
            f"(its polynomial does not invert there); {remedy}"
        )
    no = apply_homography(corner_homography(ours, width, height), uo[ok])
    try:
        hc = corner_homography(theirs, width, height)
    except ValueError:
        raise ValueError(
            f"{cannot}: its correction is not defined at the image corners "
            f"(its polynomial does not invert there); {remedy}"
        ) from None
    nt = apply_homography(hc, ut[ok])
    e = np.linalg.norm(nt - no, axis=1)
    e_h = worst_frame_mod_h(((nt, no), (ut[ok], uo[ok]), (uo[ok], ut[ok])))
    if not ok.all():  # undefined points count as failures of the export
        e = np.concatenate([e, np.full(np.sum(~ok), np.inf)])
        e_h = np.concatenate([e_h, np.full(np.sum(~ok), np.inf)])
    st = conversion_straightness(ours, theirs, width, height)
    shots: tuple[float, float, float, float] = (float("nan"),) * 4
    if edges is not None and len(edges) > 0:
        sh = straightness(corrected_points(list(edges), theirs, width, height))
        so = straightness(corrected_points(list(edges), ours, width, height))
        shots = (sh.d, sh.d_max, so.d, so.d_max)
    return _figures(e, e_h, st, shots)


def _figures(e: Array, e_h: Array, st: Straightness, shots: tuple[float, float, float, float]) -> ConversionError:
    """The :class:`ConversionError` of the per-point distances ``e`` (4-corner normalised) and ``e_h`` (modulo
    homography), the lines' straightness ``st`` and the shots' ``(d, d_max)`` after the export and after ours."""
    return ConversionError(
        rms_px=float(np.sqrt(np.mean(e**2))),
        max_px=float(e.max()),
        rms_mod_h_px=float(np.sqrt(np.mean(e_h**2))),
        max_mod_h_px=float(e_h.max()),
        n_points=int(len(e)),
        d_px=st.d,
        d_max_px=st.d_max,
        shots_d_px=shots[0],
        shots_d_max_px=shots[1],
        model_shots_d_px=shots[2],
        model_shots_d_max_px=shots[3],
    )


def worst_frame_mod_h(pairs: Sequence[tuple[Array, Array]]) -> Array:
    """Per-point distances ``|H(src) - dst|`` after the best homography, the largest over the frames.

    A misfit modulo homography depends on the frame it is measured in: ``H`` scales it by its
    local Jacobian. On a wide lens the 4-corner normalised frame (``harp evaluate``'s) pulls the
    corrected corners, far outside the image, back onto the image corners and so shrinks the
    misfit, by 1.3x (93 degree lens) to 1.6x (115 degree lens) in RMS, against the export's
    own output pixels (``K``'s, where its consumer — ``cv2.undistortPoints`` with ``P=K``,
    ``initUndistortRectifyMap`` — measures it) and the harp model's ideal pixels. Each pair is
    ``(src, dst)`` with ``dst`` in a frame measured in; each point's largest distance is kept,
    so that no one of the frames sees more than stated.
    """
    e: Array = np.max([np.linalg.norm(apply_homography(fit_homography(a, b), a) - b, axis=1) for a, b in pairs], axis=0)
    return e


def _inside(p: Array, width: int, height: int) -> npt.NDArray[np.bool_]:
    ok: npt.NDArray[np.bool_] = (
        np.all(np.isfinite(p), axis=1)
        & (p[:, 0] >= 0)
        & (p[:, 0] <= width - 1)
        & (p[:, 1] >= 0)
        & (p[:, 1] <= height - 1)
    )
    return ok


def conversion_error_in_frame(
    ours: DistortionModel,
    theirs: DistortionModel,
    width: int,
    height: int,
    n_long: int = ERROR_GRID_LONG,
    edges: Sequence[Array] | None = None,
    frame: CorrectedFrame | None = None,
    whole_photo: bool = False,
) -> ConversionError:
    """Conversion error of an export in *our own* corrected image, over the corrected image only.

    For per-pixel maps (``maps``, ``stmap``): they hold our correction itself,
    for the pixels of the corrected image (``[0, W-1] x [0, H-1]``, or ``frame``'s:
    :mod:`pipeline.corrected_frame`, whose pixels ``theirs`` returns); a distorted
    point whose corrected image falls outside is not in the corrected image and is
    not compared (``whole_photo``: every point of the photo is, for a redistort map that holds
    the correction at every photo pixel). No homography is applied (the frames are the same), so both
    the "4-corner" and the "modulo homography" figures are the plain distance
    ``|U_theirs(x) - A(U_ours(x))|``; the straightness figures are on lines of our
    ideal frame inside the corrected image, and on the fitting shots' edge
    points that appear in it.
    """
    fr = frame or CorrectedFrame.identity(width, height)
    ow, oh = fr.width, fr.height

    def ours_q(p: Array) -> Array:
        return fr.from_ideal(ours.undistort_points(p))

    def keep_of(q: Array) -> npt.NDArray[np.bool_]:
        if whole_photo:
            ok: npt.NDArray[np.bool_] = np.all(np.isfinite(q), axis=1)
            return ok
        return _inside(q, ow, oh)

    g = image_grid(width, height, n_long)
    uo = ours_q(g)
    keep = keep_of(uo)
    ut = theirs.undistort_points(g[keep])
    e = np.linalg.norm(ut - uo[keep], axis=1)
    e = np.where(np.isfinite(e), e, np.inf)
    lines = []
    for ln in straight_lines_through(ours, width, height, normalise=False):
        ok = keep_of(ours_q(ln))  # the lines inside the corrected image
        if ok.sum() >= 2:
            lines.append(ln[ok])
    st = straightness([theirs.undistort_points(ln) for ln in lines])
    shots: tuple[float, float, float, float] = (float("nan"),) * 4
    if edges is not None and len(edges) > 0:
        kept = []
        for p in edges:
            p = np.asarray(p, dtype=np.float64).reshape(-1, 2)
            ok = keep_of(ours_q(p))
            if ok.sum() >= 2:
                kept.append(p[ok])
        if kept:
            sh = straightness([theirs.undistort_points(p) for p in kept])
            so = straightness([ours_q(p) for p in kept])
            shots = (sh.d, sh.d_max, so.d, so.d_max)
    return _figures(e, e, st, shots)


def ideal_homography(
    ours: DistortionModel, theirs: DistortionModel, width: int, height: int, n_long: int = ERROR_GRID_LONG
) -> Array:
    """The homography ``H`` taking ``theirs``' ideal pixels to ``ours`` (``U_ours ~ H(U_theirs)``), least
    squares over the image: the one the conversion error modulo homography is measured after."""
    g = image_grid(width, height, n_long)
    uo, ut = ours.undistort_points(g), theirs.undistort_points(g)
    ok = np.all(np.isfinite(uo), axis=1) & np.all(np.isfinite(ut), axis=1)
    return fit_homography(ut[ok], uo[ok])


def mod_h_errors(ours: DistortionModel, theirs: DistortionModel, points: Array) -> Array:
    """``|H(U_theirs(x)) - U_ours(x)|`` at ``points`` after the best least-squares homography (inf where undefined)."""
    uo, ut = ours.undistort_points(points), theirs.undistort_points(points)
    ok = np.all(np.isfinite(uo), axis=1) & np.all(np.isfinite(ut), axis=1)
    e = np.full(len(points), np.inf)
    if ok.sum() >= 4:
        h = fit_homography(ut[ok], uo[ok])
        e[ok] = np.linalg.norm(apply_homography(h, ut[ok]) - uo[ok], axis=1)
    return e


def mod_h_rms(ours: DistortionModel, theirs: DistortionModel, width: int, height: int, n_long: int = 64) -> float:
    """RMS distance of the two corrections modulo the best homography (inf if undefined somewhere)."""
    g = image_grid(width, height, n_long)
    uo, ut = ours.undistort_points(g), theirs.undistort_points(g)
    if not (np.all(np.isfinite(uo)) and np.all(np.isfinite(ut))):
        return float("inf")
    h = fit_homography(ut, uo)
    return float(np.sqrt(np.mean(np.sum((apply_homography(h, ut) - uo) ** 2, axis=1))))


def straight_lines_through(
    model: DistortionModel,
    width: int,
    height: int,
    n_lines: int = 16,
    angles_deg: Sequence[float] = (0.0, 45.0, 90.0, 135.0),
    step_px: float = 4.0,
    min_points: int = 20,
    normalise: bool = True,
) -> list[Array]:
    """Distorted images of ideal straight lines: what ``model`` (4-corner normalised) makes straight.

    Lines at each angle, ``n_lines`` across the image, sampled every
    ``step_px`` in the ideal frame, mapped to the distorted image by the
    model's inverse; points falling outside the image are dropped. With
    ``normalise=False`` the ideal frame is the model's own (not 4-corner normalised).
    """
    norm: DistortionModel = normalise_by_corners(model, width, height) if normalise else model
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    half = 0.5 * float(np.hypot(width, height))
    out = []
    for a in np.radians(np.asarray(angles_deg, dtype=np.float64)):
        d = np.array([np.cos(a), np.sin(a)])
        n = np.array([-d[1], d[0]])
        ext = abs(n[0]) * (width - 1) / 2 + abs(n[1]) * (height - 1) / 2
        for off in np.linspace(-ext, ext, n_lines + 2)[1:-1]:
            s = np.arange(-half, half + step_px, step_px)
            ideal = c + off * n + s[:, None] * d
            inside = (
                (ideal[:, 0] >= -0.5)
                & (ideal[:, 0] <= width - 0.5)
                & (ideal[:, 1] >= -0.5)
                & (ideal[:, 1] <= height - 0.5)
            )
            pts = norm.distort_points(ideal[inside])
            ok = (
                np.all(np.isfinite(pts), axis=1)
                & (pts[:, 0] >= 0)
                & (pts[:, 0] <= width - 1)
                & (pts[:, 1] >= 0)
                & (pts[:, 1] <= height - 1)
            )
            if ok.sum() >= min_points:
                out.append(pts[ok])
    return out


def conversion_straightness(ours: DistortionModel, theirs: DistortionModel, width: int, height: int) -> Straightness:
    """Straightness (``d``, ``d_max``) left by ``theirs`` on lines ``ours`` makes exactly straight."""
    lines = straight_lines_through(ours, width, height)
    return straightness(corrected_points(lines, theirs, width, height))
