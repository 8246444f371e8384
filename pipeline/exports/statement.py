"""What every pin-hole and fisheye export states about itself, in one order.

The OpenCV, ROS, mrcal, COLMAP, Kalibr, Basalt and Metashape files each say, in their own comment
mechanism (``#`` lines, FileStorage comments, XML comments, a JSON list), the same things: the
stamp first (what a reader must know before using the file, e.g. that the profile failed QA), what
the consumer must know before the figures (e.g. which ROS versions read the file), the conversion
error (:meth:`~pipeline.exports.conversion_error.ConversionError.lines`), what its point solver needs, the model
chosen and why, what the camera matrix means, the format's own conventions (pixel origin, a
consumer's fixed step counts), the corrected image (``R``, ``newK``) and notes (lens, holdout ``d``).
A :class:`Statement` holds what the export states whatever the format (made by
:meth:`~pipeline.exports.fitted.Fitted.statement`) and is passed whole to every writer; its
:meth:`Statement.lines` is that list, given the lines the format words itself, and each writer only
puts it into its file. The lensfun, LCP, maps and harp files state other things in shapes of their own
(a lens entry, profile comments, map notes, a model file's stamp) and do not take a :class:`Statement`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from pipeline.exports.conversion_error import ConversionError
from pipeline.exports.frame import FrameStatement
from pipeline.exports.lens import CameraMatrixChoice
from pipeline.exports.solvers import SolverNeed

OPENCV_PIXELS = "pixel convention: OpenCV's (the centre of the top-left pixel at 0, 0)"
"""The statement of a file whose pixel coordinates are OpenCV's (and harp's)."""


@dataclass(frozen=True)
class Statement:
    """What an export states whatever its format, passed whole to every pin-hole and fisheye writer.

    Attributes
    ----------
    error : the conversion error (:class:`~pipeline.exports.conversion_error.ConversionError`); formats with
        fields for it (OpenCV) write those too.
    stamp : lines stated first (:attr:`~pipeline.exports.source.ExportSource.stamp`).
    camera : what the camera matrix means (:class:`~pipeline.exports.lens.CameraMatrixChoice`).
    choice : the model chosen and why.
    solver : what the consumer's point solver needs (:class:`~pipeline.exports.solvers.SolverNeed`), for the
        formats that state it (OpenCV, ROS).
    frame : the corrected image's ``R`` and ``newK`` (:class:`~pipeline.exports.frame.FrameStatement`).
    notes : the rest (lens, holdout ``d``, measured-camera figures).
    """

    error: ConversionError | None = None
    stamp: tuple[str, ...] = ()
    camera: CameraMatrixChoice | None = None
    choice: str | None = None
    solver: SolverNeed | None = None
    frame: FrameStatement | None = None
    notes: tuple[str, ...] = ()

    def lines(
        self,
        *,
        caveats: Sequence[str] = (),
        solver: Sequence[str] = (),
        conventions: Sequence[str] = (),
        frame: Sequence[str] = (),
        notes: Sequence[str] = (),
    ) -> list[str]:
        """The lines the export states, in the order every format uses (see module docstring), with those
        the format words itself.

        Parameters
        ----------
        caveats : what the consumer must know before the figures (e.g. which readers read the file).
        solver : :attr:`solver` as the format words it (:meth:`~pipeline.exports.solvers.SolverNeed.lines`).
        conventions : the format's own conventions (pixel origin, the consumer's step counts).
        frame : :attr:`frame` as the format words it (:meth:`~pipeline.exports.frame.FrameStatement.lines`,
            :meth:`~pipeline.exports.frame.FrameStatement.ray_lines`).
        notes : the format's own notes, after :attr:`notes`.
        """
        return [
            *self.stamp,
            *caveats,
            *(self.error.lines() if self.error is not None else []),
            *solver,
            *([self.choice] if self.choice else []),
            *([self.camera.statement] if self.camera is not None else []),
            *conventions,
            *frame,
            *self.notes,
            *notes,
        ]


def hash_comments(lines: Sequence[str]) -> str:
    """``lines`` as ``# `` comment lines (COLMAP, Kalibr, ROS, mrcal), each ending in a newline."""
    return "".join(f"# {s}\n" for s in lines)
