"""Harp photographs read and measured with one-line errors.

:func:`read_image` and :func:`measure_file` read a harp photograph (:func:`station.imageio.read_grey`) and
measure its strings (:func:`pipeline.measure.measure_image`), turning every failure
into an :class:`~station.errors.InputError` (the one-line "bad input" error every ``harp``
command prints before exiting with code 2) that names the file.
"""

from __future__ import annotations

import numpy as np

from pipeline.measure import MIN_SMOOTHED_POINTS, ImageMeasurement, measure_image
from station import imageio
from station.errors import InputError

NO_STRINGS = "no strings found (no pair of long straight edges a string width apart)"


def read_image(path, *, grey: bool = True) -> np.ndarray:
    """The image at ``path``: 2-D grey (:func:`station.imageio.read_grey`) or, with
    ``grey=False``, as stored (:func:`station.imageio.read_unchanged`).

    Raises :class:`InputError` naming the file and the reason.
    """
    try:
        return imageio.read_grey(path) if grey else imageio.read_unchanged(path)
    except imageio.ImageReadError as exc:
        raise InputError(str(exc)) from None


def measure_grey(
    path, img: np.ndarray, t: int, *, require_strings: bool = True, smoothing: str = "local-quadratic"
) -> ImageMeasurement:
    """:func:`pipeline.measure.measure_image` of the image read from ``path``.

    Raises :class:`InputError` naming ``path`` when the image cannot be
    measured or, with ``require_strings``, holds no string.
    """
    try:
        m = measure_image(img, t=t, smoothing=smoothing)
    except (ValueError, MemoryError) as exc:
        raise InputError(f"{path}: cannot measure: {exc}") from None
    if require_strings and m.n_lines == 0:
        short = [r for r in m.rejected if r.reason == "short edge" and "after smoothing" in r.detail]
        if short:  # strings were found, but t leaves too few points on each edge
            raise InputError(
                f"{path}: {len(short)} string edges found, but each keeps < "
                f"{MIN_SMOOTHED_POINTS} points after smoothing with t={t}: use a smaller --t"
            )
        raise InputError(f"{path}: {NO_STRINGS}")
    return m


def measure_file(path, t: int, *, smoothing: str = "local-quadratic") -> tuple[np.ndarray, ImageMeasurement]:
    """Read and measure one harp photograph: ``(image, measurement with strings)``.

    Raises :class:`InputError` (one line naming the file) on any problem.
    """
    img = read_image(path)
    return img, measure_grey(path, img, t, smoothing=smoothing)
