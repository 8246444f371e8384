"""What every pin-hole and fisheye export states about itself, in one order.

The OpenCV, ROS, mrcal, COLMAP, Kalibr, Basalt and Metashape files each say, in their own comment
mechanism (``#`` lines, FileStorage comments, XML comments, a JSON list), the same things: the
stamp first (what a reader must know before using the file, e.g. that the profile failed QA), what
the consumer must know before the figures (e.g. which ROS versions read the file), the conversion
error (:meth:`~pipeline.exports.conversion_error.ConversionError.lines`), what its point solver needs, the model
chosen and why, what the camera matrix means, the format's own conventions (pixel origin, a
consumer's fixed step counts), the corrected image (``R``, ``newK``) and notes (lens, holdout ``d``).
:func:`statement_lines` is that list; each writer only puts it into its file.
"""

from __future__ import annotations

from collections.abc import Sequence

from pipeline.exports.conversion_error import ConversionError
from pipeline.exports.lens import CameraMatrixChoice

OPENCV_PIXELS = "pixel convention: OpenCV's (the centre of the top-left pixel at 0, 0)"
"""The statement of a file whose pixel coordinates are OpenCV's (and harp's)."""


def statement_lines(
    stamp: Sequence[str] = (),
    error: ConversionError | None = None,
    *,
    caveats: Sequence[str] = (),
    solver: Sequence[str] = (),
    choice: str | None = None,
    camera: CameraMatrixChoice | None = None,
    conventions: Sequence[str] = (),
    frame: Sequence[str] = (),
    notes: Sequence[str] = (),
) -> list[str]:
    """The lines an export states, in the order every format uses (see module docstring).

    Parameters
    ----------
    stamp : lines stated first (:attr:`~pipeline.exports.source.ExportSource.stamp`).
    error : the conversion error, stated by its :meth:`~pipeline.exports.conversion_error.ConversionError.lines`.
    caveats : what the consumer must know before the figures (e.g. which readers read the file).
    solver : what the consumer's point solver needs (:meth:`~pipeline.exports.solvers.SolverNeed.lines`).
    choice : the model chosen and why.
    camera : what the camera matrix means (its :attr:`~pipeline.exports.lens.CameraMatrixChoice.statement`).
    conventions : the format's own conventions (pixel origin, the consumer's step counts).
    frame : the corrected image's lines (:class:`~pipeline.exports.frame.FrameStatement`).
    notes : the rest (lens, holdout ``d``, measured-camera figures).
    """
    return [
        *stamp,
        *caveats,
        *(error.lines() if error is not None else []),
        *solver,
        *([choice] if choice else []),
        *([camera.statement] if camera is not None else []),
        *conventions,
        *frame,
        *notes,
    ]


def hash_comments(lines: Sequence[str]) -> str:
    """``lines`` as ``# `` comment lines (COLMAP, Kalibr, ROS, mrcal), each ending in a newline."""
    return "".join(f"# {s}\n" for s in lines)
