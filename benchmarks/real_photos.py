"""The shared real photographs measured as ``harp measure`` measures them, for the benchmarks that split them.

``../shared/data/real-harp`` (or ``$HARP_REAL_DATA``) holds three photographs of one real harp; the benchmarks
fit on two and hold the third out (``benchmarks/model_choice.py``, ``point_weights.py``, ``point_robust.py``,
``stacking.py``). Each photograph is measured twice: whole strings (``harp measure``'s points and point sigmas)
and interior only (``smoothing="gaussian"``: 72 px dropped at both ends of every piece, the paper's measure).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.measure import measure_image

Measured = tuple[str, list[str], dict[str, Any], dict[str, list[np.ndarray]], tuple[int, int]]
"""A folder's name, its photographs' names, each one's measurement (whole strings) and interior-only edges by
name, and the image size."""


def real_measurements(directory: Path) -> Measured | None:
    """The photographs in ``directory`` measured as ``harp measure`` does (the measurements: whole strings,
    point sigmas) and interior only (``smoothing="gaussian"``, points), the folder's and their names and the
    size; None, and a line saying so, when there are fewer than three."""
    import cv2

    names = sorted(p.name for p in directory.glob("*.pgm"))
    if len(names) < 3:
        print(f"(no real photographs in {directory}: part skipped)")
        return None
    whole, interior = {}, {}
    size = (0, 0)
    for n in names:
        img = cv2.imread(str(directory / n), cv2.IMREAD_UNCHANGED)
        size = (img.shape[1], img.shape[0])
        whole[n] = measure_image(img)
        interior[n] = [ln.points for ln in measure_image(img, smoothing="gaussian").lines]
    return directory.name, names, whole, interior, size


def real_points(
    directory: Path,
) -> tuple[list[str], dict[str, list[np.ndarray]], dict[str, list[np.ndarray]], tuple[int, int]] | None:
    """:func:`real_measurements` as edge points only: the names, each photograph's edges (whole strings)
    and interior-only edges by name, and the size; None (and the line saying so) as there."""
    measured = real_measurements(directory)
    if measured is None:
        return None
    _, names, whole, interior, size = measured
    return names, {n: [ln.points for ln in m.lines] for n, m in whole.items()}, interior, size
