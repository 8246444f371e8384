"""The plots of the QA report (matplotlib, Agg backend) and their drawing, here or in worker
processes: the displacement field, the edge residuals, the bootstrap uncertainty map and the
overlays (:mod:`station.qa.report` lists the files)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from pipeline.compare import compare_models
from pipeline.edgeset import edge_figures, tls
from pipeline.models.base import IdentityModel
from station.pool import WorkerPool
from station.qa.overlay import SCREEN_MAX_SIDE, write_overlay
from station.qa.verdicts import grid_step


@dataclass(frozen=True)
class Shot:
    """One averaged shot of a focus setting and its measurement."""

    orientation_deg: float
    image: np.ndarray
    measurement: Any  # pipeline.measure.ImageMeasurement
    shift_mm: float | None = None
    """Where the linear stage under the turntable was (two-axis capture, ``capture.shift_positions_mm``); None:
    no stage."""
    twin: bool = False
    """The session's twin (``capture.twin_deg``): an angle taken again after the others, compared, not fitted."""

    @property
    def place(self) -> str:
        """Where the shot was taken, for captions: the turntable angle, and the linear stage's position if any."""
        at = "" if self.shift_mm is None else f" at {self.shift_mm:g} mm"
        return f"stage {self.orientation_deg:g} deg{at}" + (" (the twin, not fitted)" if self.twin else "")

    @property
    def group(self) -> str:
        """The shot's short label over its edges in the residual plot: the angle, the stage position if any, and
        ``twin`` for the twin (whose angle another shot has too)."""
        at = "" if self.shift_mm is None else f" {self.shift_mm:g} mm"
        return f"{self.orientation_deg:g}°{at}" + (" twin" if self.twin else "")


def _fig(width: int, height: int, extra_w: float = 1.6):
    aspect = height / width
    fig, ax = plt.subplots(figsize=(7.0 + extra_w, 7.0 * aspect + 0.9), dpi=110)
    return fig, ax


def _save(fig, path) -> Path:
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def _title(title: str, sub: str, width: int = 90) -> str:
    """Plot title: ``title`` wrapped to ``width`` characters so it fits the figure, then ``sub``."""
    import textwrap

    return (textwrap.fill(title, width) + "\n" if title else "") + sub


def _image_axes(ax, width, height):
    ax.set_xlim(-0.5, width - 0.5)
    ax.set_ylim(height - 0.5, -0.5)  # image rows grow downwards
    ax.set_aspect("equal")
    ax.set_xlabel("x (column, px)")
    ax.set_ylabel("y (row, px)")


def plot_field(model, width: int, height: int, path, title: str = "", arrows: int = 24) -> Path:
    """Quiver plot of the correction's displacement modulo homography; returns the path."""
    from pipeline.interpolate import normalised_field  # defers scipy

    # the same homography as the QA figure (station.qa.distortion_magnitude)
    h = compare_models(model, IdentityModel(), width, height, step=grid_step(width, height)).homography
    step = max(width, height) / arrows
    xs = np.linspace(0, width - 1, max(2, int(round((width - 1) / step)) + 1))
    ys = np.linspace(0, height - 1, max(2, int(round((height - 1) / step)) + 1))
    ux, uy = normalised_field(model, xs, ys, h)
    fxs = np.linspace(0, width - 1, 120)
    fys = np.linspace(0, height - 1, max(2, int(120 * height / width)))
    fx, fy = normalised_field(model, fxs, fys, h)
    mag = np.hypot(fx, fy)
    fig, ax = _fig(width, height)
    im = ax.imshow(mag, extent=(-0.5, width - 0.5, height - 0.5, -0.5), cmap="viridis", interpolation="bilinear")
    xx, yy = np.meshgrid(xs, ys)
    vmax = float(np.hypot(ux, uy).max()) or 1.0
    q = ax.quiver(xx, yy, ux, uy, color="white", angles="xy", scale_units="xy", scale=vmax / (0.9 * step), width=0.004)
    key = float(f"{vmax:.1g}")
    ax.quiverkey(q, 0.80, 1.03, key, f"{key:g} px", labelpos="E", coordinates="axes", color="black")
    _image_axes(ax, width, height)
    fig.colorbar(im, ax=ax, label="|displacement| (px)", fraction=0.046, pad=0.03)
    ax.set_title(
        _title(title, "")
        + f"correction modulo homography: max {mag.max():.3f} px, RMS {np.sqrt(np.mean(mag**2)):.3f} px",
        fontsize=10,
        loc="left",
    )
    return _save(fig, path)


def edge_residual_table(shots: Sequence[Shot], model) -> list[tuple[int, int, float, float]]:
    """``(orientation index, edge index, rms before, rms after)`` per measured edge (px)."""
    keys, pts = [], []
    for o, s in enumerate(shots):
        for i, ln in enumerate(s.measurement.lines):
            p = np.asarray(ln.points, np.float64).reshape(-1, 2)
            if len(p) >= 3:
                keys.append((o, i))
                pts.append(p)
    if not pts:
        return []
    # every edge at once: one correction call, one TLS pass (per-edge lines)
    counts = np.array([len(p) for p in pts])
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    u = np.concatenate(pts)
    before = edge_figures(tls(u, starts, counts)[0], starts, counts)[0]
    after = edge_figures(tls(model.undistort_points(u), starts, counts)[0], starts, counts)[0]
    return [(o, i, float(b), float(a)) for (o, i), b, a in zip(keys, before, after)]


def plot_edge_residuals(
    rows: Sequence[tuple[int, int, float, float]], groups: Sequence[str], path, title: str = ""
) -> Path:
    """Per-edge RMS residual before / after correction, grouped by shot (log scale).

    ``rows``: :func:`edge_residual_table` of the shots; ``groups``: each shot's label over its edges
    (:attr:`Shot.group`: the stage angle, the stage position, the twin)."""
    fig, ax = plt.subplots(figsize=(10, 4.2), dpi=110)
    if rows:
        before = np.array([r[2] for r in rows])
        after = np.array([r[3] for r in rows])
        lo = max(min(after.min(), before.min()) / 2, 1e-5)
        # one filled step artist per series (hundreds of bar patches are slow to draw)
        edges = np.arange(len(rows) + 1) - 0.5
        ax.stairs(before, edges, baseline=lo, fill=True, color="#f4a582", label="before correction")
        ax.stairs(after, edges, baseline=lo, fill=True, color="#2166ac", label="after correction")
        ori = np.array([r[0] for r in rows])
        for o in np.unique(ori):
            idx = np.flatnonzero(ori == o)
            if o > 0:
                ax.axvline(idx[0] - 0.5, color="grey", lw=0.6)
            ax.text(
                idx.mean(),
                1.02,
                groups[o],
                transform=ax.get_xaxis_transform(),
                ha="center",
                fontsize=8,
            )
        ax.set_yscale("log")
        ax.set_xlim(-0.5, len(rows) - 0.5)
        ax.set_ylim(lo, before.max() * 2)
        ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
        sub = f"mean RMS per edge: {before.mean():.4f} px before, {after.mean():.4f} px after ({len(rows)} edges)"
    else:
        ax.text(0.5, 0.5, "no measured edges", ha="center", va="center", transform=ax.transAxes)
        sub = "no measured edges"
    ax.set_xlabel("edge (grouped by shot: stage orientation)")
    ax.set_ylabel("RMS distance to the edge's line (px)")
    ax.set_title(_title(title, sub), fontsize=10, loc="left", pad=16)
    return _save(fig, path)


def plot_uncertainty(unc, width: int, height: int, path, title: str = "") -> Path:
    """Map of the bootstrap field uncertainty (px)."""
    fig, ax = _fig(width, height)
    dx = (unc.xs[1] - unc.xs[0]) / 2 if len(unc.xs) > 1 else 0.5
    dy = (unc.ys[1] - unc.ys[0]) / 2 if len(unc.ys) > 1 else 0.5
    im = ax.imshow(
        unc.std,
        extent=(unc.xs[0] - dx, unc.xs[-1] + dx, unc.ys[-1] + dy, unc.ys[0] - dy),
        cmap="magma",
        interpolation="bilinear",
        vmin=0,
    )
    _image_axes(ax, width, height)
    fig.colorbar(im, ax=ax, label="uncertainty of the correction (px, 1 sigma)", fraction=0.046, pad=0.03)
    ax.set_title(
        _title(title, "") + f"bootstrap ({unc.n_boot} replicates, {unc.resample} resampled): "
        f"RMS {unc.rms:.4f} px, max {unc.max:.4f} px",
        fontsize=10,
        loc="left",
    )
    return _save(fig, path)


@dataclass(frozen=True)
class Figure:
    """One PNG of the report: which drawing (a key of :data:`FIGURE_KINDS`), its arguments (the
    PNG's path last)."""

    kind: str
    args: tuple
    kwargs: dict

    @property
    def path(self) -> Path:
        return Path(self.args[-1])


def _write_overlay(image: np.ndarray, m: Any, path, title: str = "") -> Path:
    return write_overlay(path, image, m, title=title, max_side=SCREEN_MAX_SIDE)


FIGURE_KINDS = {
    "field": plot_field,
    "residuals": plot_edge_residuals,
    "uncertainty": plot_uncertainty,
    "overlay": _write_overlay,
}
"""The drawings of the report, by :attr:`Figure.kind`."""

PARALLEL_MIN_FIGURES = 12
"""Fewer figures than this are drawn in this process (handing them to workers would cost more than
it saves; a session of 3 focus settings x 8 orientations has 33)."""


def draw_figure(fig: Figure) -> Path:
    """Draw one figure; returns its path."""
    return FIGURE_KINDS[fig.kind](*fig.args, **fig.kwargs)


def draw_figures(figures: Sequence[Figure], workers: int = 1) -> None:
    """Draw ``figures``, in ``workers`` processes when there are enough of them.

    The figures are independent PNGs (a session of 3 focus settings x 8 orientations has 33),
    so on a machine with several cores they are drawn at once, in the processes of
    a :class:`station.pool.WorkerPool` (forkserver: the session process may still run device
    threads). An error in any figure (a full disk) is raised here, as in this process."""
    if workers <= 1 or len(figures) < PARALLEL_MIN_FIGURES:
        for fig in figures:
            draw_figure(fig)
        return
    pool = WorkerPool(workers, ["station.qa.plots"])
    try:
        # the slow plots first, then the overlays: the processes end at about the same time
        order = sorted(figures, key=lambda f: f.kind == "overlay")
        list(pool.map(draw_figure, order))
    finally:
        pool.close()
