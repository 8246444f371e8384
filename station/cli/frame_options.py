"""``--size``, ``--scale``, ``--alpha``, ``--overscan``: the corrected image of ``harp undistort`` and of the exports.

One set of options for every command that writes or describes a corrected image
(:mod:`pipeline.corrected_frame`): the parser's options and their check, giving a
:class:`~pipeline.corrected_frame.FrameChoice`.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

from station.errors import InputError

if TYPE_CHECKING:
    from pipeline.corrected_frame import FrameChoice


def add_frame_options(p) -> None:
    """The corrected-image options (a group of parser ``p``)."""
    g = p.add_argument_group(
        "corrected image (the same for harp undistort and every export: maps, STMaps, and the R / newK of "
        "opencv, ros, mrcal files)"
    )
    g.add_argument("--size", metavar="WxH", help="size of the corrected image (default: the photo's)")
    g.add_argument(
        "--scale",
        metavar="S",
        type=float,
        help="corrected pixels per ideal pixel, about the image centre (default 1: the photo's scale)",
    )
    g.add_argument(
        "--alpha",
        metavar="A",
        type=float,
        help="0..1, as OpenCV's getOptimalNewCameraMatrix: 0 keeps only pixels with a source in the photo, "
        "1 keeps every pixel of the photo",
    )
    g.add_argument(
        "--overscan",
        action="store_true",
        help="enlarge the corrected image to hold every pixel of the photo at the scale (VFX: the canvas a render "
        "must cover for stmap-redistort)",
    )


def frame_choice(args) -> FrameChoice:
    """The :class:`~pipeline.corrected_frame.FrameChoice` of the parsed options (InputError, one line, if bad)."""
    size = None
    raw = getattr(args, "size", None)
    if raw is not None:
        m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", str(raw))
        if m is None:
            raise InputError(f"--size: expected WIDTHxHEIGHT in pixels, e.g. 1920x1080, got {raw!r}")
        size = (int(m.group(1)), int(m.group(2)))
    from pipeline.corrected_frame import FrameChoice  # defers cv2 (the models): the parser's options do not load them

    try:
        return FrameChoice(
            size=size,
            scale=getattr(args, "scale", None),
            alpha=getattr(args, "alpha", None),
            overscan=bool(getattr(args, "overscan", False)),
        )
    except ValueError as exc:
        raise InputError(str(exc)) from None
