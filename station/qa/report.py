"""The QA report of a session: Markdown with PNG plots (matplotlib, Agg backend).

Per focus setting:

* ``field_f<i>.png`` — the correction's displacement field as a vector
  (quiver) plot over the image, modulo homography (after the least-squares
  homography closest to it, as in :func:`station.qa.distortion_magnitude`:
  what is left once the homography a straight-line method cannot see is
  removed), colour = length;
* ``residuals_f<i>.png`` — RMS distance of each edge's points to its
  regression line before and after the correction (log scale), grouped by
  orientation;
* ``overlay_f<i>_o<j>.jpg`` — one per orientation: the averaged frame with its
  edges coloured by their residual (:func:`station.qa.overlay.write_overlay`), sized for a
  screen (at most :data:`~station.qa.overlay.SCREEN_MAX_SIDE` px, JPEG); which focus settings
  keep them is the report's ``overlays`` (``report.overlays`` of the configuration,
  :data:`station.config.OVERLAY_RETENTION`: ``all``, ``failed`` — only a focus setting that
  failed QA —, ``none``);
* ``uncertainty_f<i>.png`` — the bootstrap field uncertainty map
  (:func:`pipeline.uncertainty.bootstrap_field_uncertainty`);

then the verdict with its reasons and figures, and the leave-one-focus-out
interpolation error. ``report.md`` links them all; ``index.html`` is the same
report as a standalone HTML page embedding the same PNGs (for a browser on
the production line).

For a session directory the evidence is what the executor kept: each shot's
measured edges (``measurements/*.npz``) and each focus setting's bootstrap
uncertainty map (``profiles/focus<i>_uncertainty.npz``); only a session
without them (older or hand-made) is measured / bootstrapped again.
"""

from __future__ import annotations

import html
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np

from pipeline.resample import DEFAULT_T

matplotlib.use("Agg")
import matplotlib.pyplot as plt

import pipeline.measure  # measure_image and the bootstrap called through their modules: tests replace them
import pipeline.uncertainty
from pipeline.compare import compare_models
from pipeline.edgeset import edge_figures, tls
from pipeline.models.base import IdentityModel
from station.config import OVERLAY_RETENTION
from station.pool import WorkerPool
from station.profile import Profile, Verdict
from station.qa.evidence import stored_measurement, stored_uncertainty
from station.qa.overlay import SCREEN_MAX_SIDE, write_overlay
from station.qa.results import config_record, device_identities, identity_warnings
from station.qa.verdicts import grid_step
from station.session import layout
from station.session.processing import average_frames

REPORT_MD = "report.md"
"""The report's Markdown file, in its directory."""
REPORT_HTML = "index.html"
"""The same report as a standalone HTML page."""


@dataclass(frozen=True)
class Shot:
    """One averaged shot of a focus setting and its measurement."""

    orientation_deg: float
    image: np.ndarray
    measurement: Any  # pipeline.measure.ImageMeasurement


@dataclass
class FocusEvidence:
    """Everything the report shows about one focus setting."""

    focus: float
    model: Any  # DistortionModel
    width: int
    height: int
    verdict: Verdict
    source: str = ""
    shots: list[Shot] = field(default_factory=list)
    uncertainty: Any = None  # pipeline.uncertainty.FieldUncertainty, or None
    uncertainty_note: str = ""


# ------------------------------------------------------------------ figures
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
    rows: Sequence[tuple[int, int, float, float]], orientations_deg: Sequence[float], path, title: str = ""
) -> Path:
    """Per-edge RMS residual before / after correction, grouped by orientation (log scale).

    ``rows``: :func:`edge_residual_table` of the shots; ``orientations_deg``: the stage angle of
    each shot (the labels of the groups)."""
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
                f"{orientations_deg[o]:g}°",
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
    ax.set_xlabel("edge (grouped by stage orientation)")
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


def keeps_overlays(overlays: str, verdict: Verdict) -> bool:
    """Whether a focus setting of this verdict keeps its overlays under ``overlays`` (all, failed, none)."""
    if overlays not in OVERLAY_RETENTION:
        raise ValueError(f"overlays: expected one of {', '.join(OVERLAY_RETENTION)}, got {overlays!r}")
    return overlays == "all" or (overlays == "failed" and verdict.verdict != "PASS")


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
    pool = WorkerPool(workers, ["station.qa.report"])
    try:
        # the slow plots first, then the overlays: the processes end at about the same time
        order = sorted(figures, key=lambda f: f.kind == "overlay")
        list(pool.map(draw_figure, order))
    finally:
        pool.close()


# ------------------------------------------------------------------ report
def _fmt(v, nd=4) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.{nd}f}" if isinstance(v, float) else str(v)


DEFINITIONS = (
    "Straightness (Tang et al. 2012): d is the root mean square distance of the measured edge points to "
    "their edge's regression line, and d_max the root mean square over the edges of each edge's peak-to-peak "
    "distance to its line, both in pixels (0 for perfectly straight edges); the holdout d is d of edges "
    "the correction was not fitted on, corrected by it."
)
"""The one sentence every report defines d and d_max with."""


def _check_rows(verdict: Verdict) -> list[str]:
    """The checks of a verdict as a Markdown table: what was compared, and what happened."""
    rows = [
        "| check | value (px) | must be | limit (px) | result | what happened |",
        "|:---|---:|:---:|---:|:---:|:---|",
    ]
    for c in verdict.checks:
        result = "reported" if c.passed is None else ("PASS" if c.passed else "**FAIL**")
        limit = "-" if c.limit is None else f"{c.limit:g}"
        rows.append(f"| {c.name} | {_fmt(c.value)} | {c.comparison} | {limit} | {result} | {c.text} |")
    return rows


def write_report(
    out_dir,
    title: str,
    evidence: Sequence[FocusEvidence],
    overall: str,
    *,
    thresholds=None,
    interpolation: Sequence = (),
    notes: Sequence[str] = (),
    context: Sequence[tuple[str, str]] = (),
    warnings: Sequence[str] = (),
    workers: int = 1,
    overlays: str = "all",
) -> Path:
    """Write ``report.md`` and its pictures into ``out_dir`` (created); returns the Markdown path.

    ``context``: (what, value) rows shown under the verdict (date, station, software,
    configuration and its SHA-256, devices); ``warnings``: lines shown as warnings (a device
    that reported another identity than the configuration's); ``workers``: processes that
    draw the pictures (:func:`draw_figures`); ``overlays``: which focus settings keep their
    overlays (:func:`keeps_overlays`)."""
    import datetime as _dt

    out = Path(out_dir)
    figures: list[Figure] = []
    out.mkdir(parents=True, exist_ok=True)
    md = [f"# QA report: {title}", "", f"**Verdict: {overall}**", "", DEFINITIONS, ""]
    written = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    md += ["| | |", "|:---|:---|", f"| report written | {written} |"]
    md += [f"| {k} | {v} |" for k, v in context]
    md.append("")
    for w in warnings:
        md += [f"> **warning**: {w}", ""]
    if thresholds is not None:
        md += [
            "Thresholds: "
            + ", ".join(
                f"{k} = {v:g} px" if v is not None else f"{k}: not judged" for k, v in thresholds.__dict__.items()
            ),
            "",
        ]
    md += [
        "| focus | verdict | holdout d (px) | distortion max (px) | ref. deviation max (px) | "
        "uncertainty RMS / max (px) | reasons |",
        "|---:|:---:|---:|---:|---:|---:|:---|",
    ]
    for e in evidence:
        f = e.verdict.figures
        unc = e.uncertainty
        u = (
            f"{unc.rms:.4f} / {unc.max:.4f}"
            if unc is not None
            else f"{_fmt(f.get('field_uncertainty_rms_px'))} / {_fmt(f.get('field_uncertainty_max_px'))}"
        )
        md.append(
            f"| {e.focus:g} | {e.verdict.verdict} | {_fmt(f.get('holdout_d_px'))} | "
            f"{_fmt(f.get('distortion_max_px'), 3)} | {_fmt(f.get('reference_max_px'))} | {u} | "
            f"{'; '.join(e.verdict.reasons) or '-'} |"
        )
    md.append("")
    if interpolation:
        md += [
            "## Focus interpolation (leave one calibrated focus out)",
            "",
            "Each interior focus setting interpolated from the others and compared with its own fit, "
            "modulo homography.",
            "",
            "| focus left out | RMS (px) | max (px) |",
            "|---:|---:|---:|",
        ]
        md += [f"| {r.focus:g} | {r.rms_px:.4f} | {r.max_px:.4f} |" for r in interpolation]
        md.append("")
    for n in notes:
        md += [f"> {n}", ""]
    for i, e in enumerate(evidence):
        label = f"focus {e.focus:g}"
        md += [f"## {label}", ""]
        if e.source:
            md += [f"Profile: `{e.source}`", ""]
        md += [f"Verdict at focus {e.focus:g}: **{e.verdict.verdict}**", ""]
        md += _check_rows(e.verdict) + [""]
        if e.verdict.reasons:
            md += ["Reasons for FAIL:", ""] + [f"- {r}" for r in e.verdict.reasons] + [""]
        name = f"field_f{i}.png"
        figures.append(Figure("field", (e.model, e.width, e.height, out / name), {"title": f"{title}, {label}"}))
        md += ["### Distortion field", "", f"![distortion field]({name})", ""]
        if e.shots:
            name = f"residuals_f{i}.png"
            rows = edge_residual_table(e.shots, e.model)
            angles = [s.orientation_deg for s in e.shots]
            figures.append(Figure("residuals", (rows, angles, out / name), {"title": f"{title}, {label}"}))
            md += ["### Residual per edge", "", f"![residual per edge]({name})", ""]
        if e.uncertainty is not None:
            name = f"uncertainty_f{i}.png"
            figures.append(
                Figure("uncertainty", (e.uncertainty, e.width, e.height, out / name), {"title": f"{title}, {label}"})
            )
            md += ["### Field uncertainty", "", f"![field uncertainty]({name})", ""]
        elif e.uncertainty_note:
            md += ["### Field uncertainty", "", e.uncertainty_note, ""]
        if e.shots and not keeps_overlays(overlays, e.verdict):
            md += [
                "### Overlays",
                "",
                f"Not kept (overlays: {overlays}"
                + ("; this focus setting passed QA)." if overlays == "failed" else ").")
                + " `harp qa SESSION_DIR --report DIR --overlays all` draws them from the session's frames.",
                "",
            ]
        elif e.shots:
            md += ["### Overlays (edges coloured by their distance to their own line, before correction)", ""]
            for j, s in enumerate(e.shots):
                name = f"overlay_f{i}_o{j}.jpg"
                caption = f"{label}, stage {s.orientation_deg:g} deg"
                # float32 holds an average of a few 8- or 16-bit frames for display (half the bytes to a worker)
                image = np.asarray(s.image, np.float32)
                figures.append(Figure("overlay", (image, s.measurement, out / name), {"title": caption}))
                md += [f"![overlay {s.orientation_deg:g} deg]({name})", ""]
    draw_figures(figures, workers)
    path = out / REPORT_MD
    text = "\n".join(md) + "\n"
    path.write_text(text)
    (out / REPORT_HTML).write_text(markdown_to_html(text, title=f"QA report: {title}"))
    return path


# ------------------------------------------------------------------- HTML
_INLINE = [
    (re.compile(r"!\[([^\]]*)\]\(([^)]+)\)"), r'<img alt="\1" src="\2">'),
    (re.compile(r"\*\*(.+?)\*\*"), r"<strong>\1</strong>"),
    (re.compile(r"`([^`]+)`"), r"<code>\1</code>"),
]


def _inline(text: str) -> str:
    out = html.escape(text, quote=False)
    for rx, rep in _INLINE:
        out = rx.sub(rep, out)
    return out


def markdown_to_html(md: str, title: str = "") -> str:
    """HTML page of the Markdown subset :func:`write_report` writes (headings,
    paragraphs, pipe tables, images, bullet lists, block quotes, bold, code)."""
    body: list[str] = []
    lines = md.splitlines()
    i = 0
    while i < len(lines):
        ln = lines[i]
        if not ln.strip():
            i += 1
        elif ln.startswith("#"):
            level = len(ln) - len(ln.lstrip("#"))
            body.append(f"<h{level}>{_inline(ln[level:].strip())}</h{level}>")
            i += 1
        elif ln.startswith("|"):
            rows = []
            while i < len(lines) and lines[i].startswith("|"):
                rows.append([c.strip() for c in lines[i].strip().strip("|").split("|")])
                i += 1
            aligns = []
            if len(rows) > 1 and all(re.fullmatch(r":?-+:?", c) for c in rows[1]):
                aligns = [
                    "right"
                    if c.endswith(":") and not c.startswith(":")
                    else "center"
                    if c.startswith(":") and c.endswith(":")
                    else "left"
                    for c in rows[1]
                ]
                rows = [rows[0]] + rows[2:]
            t = ["<table>"]
            for r, cells in enumerate(rows):
                tag = "th" if r == 0 and aligns else "td"
                t.append(
                    "<tr>"
                    + "".join(
                        f'<{tag} style="text-align:{aligns[k] if k < len(aligns) else "left"}">{_inline(c)}</{tag}>'
                        for k, c in enumerate(cells)
                    )
                    + "</tr>"
                )
            body.append("\n".join(t + ["</table>"]))
        elif ln.startswith("- "):
            items = []
            while i < len(lines) and lines[i].startswith("- "):
                items.append(f"<li>{_inline(lines[i][2:])}</li>")
                i += 1
            body.append("<ul>" + "".join(items) + "</ul>")
        elif ln.startswith("> "):
            body.append(f"<blockquote>{_inline(ln[2:])}</blockquote>")
            i += 1
        else:
            para = []
            while i < len(lines) and lines[i].strip() and not lines[i].startswith(("#", "|", "- ", "> ")):
                para.append(_inline(lines[i]))
                i += 1
            body.append("<p>" + "<br>\n".join(para) + "</p>")
    style = (
        "body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}"
        ".verdict{padding:2px 8px;border-radius:3px;color:#fff}"
        ".verdict.pass{background:#1a7f37}.verdict.fail{background:#cf222e}"
        "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px}"
        "img{max-width:100%;display:block;margin:0.5em 0}"
        "blockquote{color:#444;border-left:3px solid #bbb;margin-left:0;padding-left:1em}"
    )
    page = "\n".join(body)
    # the verdicts in colour: green PASS, red FAIL (the Markdown says the same in words)
    page = re.sub(
        r"<strong>(Verdict(?: at focus [^:<]*)?: )(PASS|FAIL)</strong>",
        lambda m: f'<strong class="verdict {m.group(2).lower()}">{m.group(1)}{m.group(2)}</strong>',
        page,
    )
    page = page.replace("<strong>FAIL</strong>", '<strong class="verdict fail">FAIL</strong>')
    return (
        f'<!DOCTYPE html>\n<html><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
        f"<style>{style}</style></head>\n<body>\n" + page + "\n</body></html>\n"
    )


# ------------------------------------------------------- session evidence
def session_shots(session, focus_idx: int, t: int = DEFAULT_T) -> list[Shot]:
    """Averaged, measured shots of one focus setting of an open
    :class:`station.session_dir.SessionDir` (orientations with no frames are skipped).

    The measurement is the one the executor kept (:func:`stored_measurement`);
    a shot without one is measured now."""
    cfg = session.config
    shots = []
    for o, deg in enumerate(cfg.capture.orientations_deg):
        records = session.frames(focus_idx, o)
        if not records:
            continue
        image = average_frames([session.read_frame(r) for r in records])
        m = stored_measurement(session, focus_idx, o)
        shots.append(Shot(float(deg), image, m if m is not None else pipeline.measure.measure_image(image, t=t)))
    return shots


def session_evidence(
    session,
    focus_idx: int,
    focus: float,
    profile: Profile,
    verdict: Verdict,
    source: str = "",
    *,
    bootstrap_if_missing: int = 0,
) -> FocusEvidence:
    """The report's evidence on one focus setting of a session.

    Shots and the uncertainty map are those the session kept; a missing map is
    bootstrapped with ``bootstrap_if_missing`` replicates (0: the report says it is
    not available), refitting exactly the spec the profile records (an older
    profile that records none: the configuration's, when it names one)."""
    cfg = session.config
    e = FocusEvidence(
        focus=focus, model=profile.model, width=profile.width, height=profile.height, verdict=verdict, source=source
    )
    e.shots = session_shots(session, focus_idx, t=cfg.pipeline.t)
    e.uncertainty = stored_uncertainty(session, focus_idx, profile.model)
    if e.uncertainty is None:
        spec = profile.spec if profile.spec is not None else cfg.pipeline.spec
        if bootstrap_if_missing < 2 or not e.shots:
            e.uncertainty_note = "not computed in this session (pipeline.bootstrap: 0)"
        elif spec is None:
            e.uncertainty_note = "not available: the profile does not record which model was fitted"
        else:
            e.uncertainty, e.uncertainty_note = shot_uncertainty(
                e.shots, profile.width, profile.height, spec, n_boot=bootstrap_if_missing, seed=cfg.pipeline.seed
            )
    return e


def write_session_report(
    session,
    out_dir,
    title: str,
    profiles: Sequence[tuple[int, Profile]],
    verdicts: Sequence[Verdict],
    overall: str,
    *,
    thresholds=None,
    interpolation: Sequence = (),
    bootstrap_if_missing: int = 0,
    overlays: str | None = None,
) -> Path:
    """Report of a session's profiles: ``(focus_idx, profile)`` as
    :func:`station.qa.session_profiles` returns them, ``verdicts`` in the same order;
    ``overlays``: which keep their overlays (None: the session configuration's ``report.overlays``).
    Returns the Markdown path."""
    evidence = [
        session_evidence(
            session,
            f,
            p.focus if p.focus is not None else session.config.focus_settings[f],
            p,
            v,
            source=layout.profile_file(f),
            bootstrap_if_missing=bootstrap_if_missing,
        )
        for (f, p), v in zip(profiles, verdicts)
    ]
    context, warnings = session_context(session)
    return write_report(
        out_dir,
        title,
        evidence,
        overall,
        thresholds=thresholds,
        interpolation=interpolation,
        context=context,
        warnings=warnings,
        workers=session.config.pipeline.workers,
        overlays=session.config.report.overlays if overlays is None else overlays,
    )


def session_context(session) -> tuple[list[tuple[str, str]], list[str]]:
    """The report's (what, value) rows of a session — started, station, software, configuration
    (path and SHA-256 of the copy the session ran), the devices as they reported themselves
    beside the configuration — and one warning per device that reported another identity."""
    cfg = session.config
    conf = config_record(session)
    devices = device_identities(session)
    cam = devices["camera"]
    reported = "; ".join(f"{c['maker']} {c['model']} serial {c['serial']}" for c in cam["reported"]) or "no frame"
    body = cam["configured"]
    tt = devices["turntable"]
    rows = [
        ("session started", str(session.meta.get("created", "-"))),
        ("session", f"`{session.path}`"),
        ("station", cfg.station.id),
        ("software", f"harp station {session.meta.get('software_version') or '-'}"),
        ("configuration", f"`{conf['path']}` (SHA-256 of the copy it ran, `{conf['copy']}`: `{conf['sha256']}`)"),
        ("lens", cfg.lens.label()),
        (
            "camera",
            f"reported by the device ({cam['driver']}): {reported}; configured: {body['maker']} {body['model']} "
            f"serial {body['serial']}" + {True: " (matches)", False: " (**does not match**)", None: ""}[cam["matches"]],
        ),
        ("turntable", f"{tt['driver']} on `{tt['port']}` (the driver reports no identity)"),
    ]
    return rows, identity_warnings(devices)


def shot_uncertainty(shots: Sequence[Shot], width: int, height: int, spec, *, n_boot: int = 20, seed: int = 0):
    """(FieldUncertainty or None, note) from the shots' edges, refitting ``spec`` (a FitSpec)."""
    lines = [[np.asarray(ln.points, np.float64) for ln in s.measurement.lines] for s in shots]
    res = pipeline.uncertainty.bootstrap_field_uncertainty(lines, width, height, spec, n_boot=n_boot, seed=seed)
    if not res:
        return None, f"not available: {res.reason}"
    return res, ""
