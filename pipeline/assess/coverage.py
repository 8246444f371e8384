"""Two-direction coverage of the image by string edges (:mod:`pipeline.assess`, *Coverage*),
accumulated over orientations."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

Points = NDArray[np.float64]
Floats = NDArray[np.float64]

CELLS_ACROSS = 8
"""Coverage cells along the longer image side (square cells)."""
DIRECTION_BIN_DEG = 15.0
"""Width of a coverage direction bin, degrees (12 bins over 180 degrees)."""
MIN_SEPARATION_DEG = 30.0
"""Two directions at least this far apart cover a cell."""
MIN_CELL_EDGE_FRACTION = 0.25
"""Edge length (fraction of the cell side) that makes a direction present in a cell."""


@dataclass(frozen=True)
class Coverage:
    """Edge length seen per image cell and direction (:mod:`pipeline.assess`, *Coverage*).

    Attributes
    ----------
    width, height : int
        Image size, pixels.
    cell_px : float
        Side of a (square) cell; the last row and column may be cut by the image.
    length_px : (ny, nx, nbins) float ndarray
        Edge length seen in each cell per direction bin (bin ``k`` holds
        angles in ``[k, k + 1) * DIRECTION_BIN_DEG``, angles in ``[0, 180)``).
    """

    width: int
    height: int
    cell_px: float
    length_px: Floats

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)`` cells."""
        return (int(self.length_px.shape[0]), int(self.length_px.shape[1]))

    @property
    def directions(self) -> NDArray[np.bool_]:
        """``(ny, nx, nbins)``: which directions are present in each cell."""
        return self.length_px >= MIN_CELL_EDGE_FRACTION * self.cell_px

    @property
    def present(self) -> NDArray[np.bool_]:
        """``(ny, nx)``: cells holding string edges in at least one direction."""
        return np.asarray(self.directions.any(axis=2))

    @property
    def covered(self) -> NDArray[np.bool_]:
        """``(ny, nx)``: cells holding edges in two directions >= ``MIN_SEPARATION_DEG`` apart."""
        d = self.directions
        nb = d.shape[2]
        sep = int(math.ceil(MIN_SEPARATION_DEG / DIRECTION_BIN_DEG - 1e-9))
        out = np.zeros(d.shape[:2], bool)
        for k in range(sep, nb - sep + 1):  # circular bin distance >= sep
            out |= (d & np.roll(d, k, axis=2)).any(axis=2)
        return out

    @property
    def covered_fraction(self) -> float:
        """Fraction of the cells that are covered."""
        return float(self.covered.mean())

    @property
    def corners_covered(self) -> tuple[bool, bool, bool, bool]:
        """Corner cells covered: top-left, top-right, bottom-left, bottom-right."""
        c = self.covered
        return (bool(c[0, 0]), bool(c[0, -1]), bool(c[-1, 0]), bool(c[-1, -1]))

    def merge(self, other: Coverage) -> Coverage:
        """The coverage of both (cell-wise maximum: a frame seen twice adds nothing)."""
        if (self.width, self.height, self.length_px.shape) != (other.width, other.height, other.length_px.shape):
            raise ValueError("coverages of different image sizes or grids cannot be merged")
        return Coverage(self.width, self.height, self.cell_px, np.maximum(self.length_px, other.length_px))

    def to_dict(self) -> dict[str, Any]:
        return {
            "cells": list(self.shape),
            "cell_px": self.cell_px,
            "present": self.present.astype(int).tolist(),
            "covered": self.covered.astype(int).tolist(),
            "covered_fraction": self.covered_fraction,
            "corners_covered": list(self.corners_covered),
        }


def coverage_grid(width: int, height: int) -> tuple[int, int, float]:
    """``(nx, ny, cell_px)``: square cells, :data:`CELLS_ACROSS` along the longer side."""
    cell = max(width, height) / CELLS_ACROSS
    return max(1, math.ceil(width / cell - 1e-9)), max(1, math.ceil(height / cell - 1e-9)), float(cell)


def empty_coverage(width: int, height: int) -> Coverage:
    """A coverage with no edge seen (the start of an accumulation)."""
    nx, ny, cell = coverage_grid(width, height)
    nb = int(round(180.0 / DIRECTION_BIN_DEG))
    return Coverage(int(width), int(height), cell, np.zeros((ny, nx, nb)))


def edge_coverage(polylines: Sequence[Points], width: int, height: int) -> Coverage:
    """Coverage of an image by edges given as ordered polylines ``(N, 2)`` of ``(x, y)`` points.

    Each segment between consecutive points adds its length to the cell
    holding its midpoint, in the bin of its direction (modulo 180 degrees).
    Segments longer than a quarter cell are ignored (gaps in an edge).
    """
    cov = empty_coverage(width, height)
    ny, nx, nb = cov.length_px.shape
    acc = np.zeros(ny * nx * nb)
    for xy in polylines:
        p = np.asarray(xy, np.float64)
        if len(p) < 2:
            continue
        d = np.diff(p, axis=0)
        seg = np.hypot(d[:, 0], d[:, 1])
        mid = 0.5 * (p[1:] + p[:-1])
        ok = (seg > 0) & (seg <= 0.25 * cov.cell_px)
        ok &= (mid[:, 0] >= -0.5) & (mid[:, 0] < width - 0.5) & (mid[:, 1] >= -0.5) & (mid[:, 1] < height - 0.5)
        if not ok.any():
            continue
        ang = np.degrees(np.arctan2(d[ok, 1], d[ok, 0])) % 180.0
        b = np.minimum((ang / DIRECTION_BIN_DEG).astype(np.int64), nb - 1)
        cx = np.clip(((mid[ok, 0] + 0.5) / cov.cell_px).astype(np.int64), 0, nx - 1)
        cy = np.clip(((mid[ok, 1] + 0.5) / cov.cell_px).astype(np.int64), 0, ny - 1)
        acc += np.bincount((cy * nx + cx) * nb + b, weights=seg[ok], minlength=acc.size)
    return Coverage(cov.width, cov.height, cov.cell_px, acc.reshape(ny, nx, nb))
