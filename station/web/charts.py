"""Server-side SVG charts of the QA dashboard: a control chart and verdict bars per day.

Drawn as inline SVG (no script, nothing fetched), so a page shows them as soon as it loads, a
test can count their marks, and the page's Content-Security-Policy stays strict (SVG presentation
attributes are not inline styles). Plain functions over numbers returning ``Markup``.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass

from markupsafe import Markup

OK, BAD, MUTED, ACCENT, LINE, WARN = "#1f7a3d", "#b3261e", "#5d6773", "#1b5fae", "#d9dde3", "#a36100"


@dataclass(frozen=True)
class ChartPoint:
    """One point of a control chart: its label (serial), value, verdict and link."""

    label: str
    value: float | None
    verdict: str | None
    href: str = ""


def _esc(text: object) -> str:
    return html.escape(str(text), quote=True)


def _fmt(v: float) -> str:
    a = abs(v)
    if a == 0:
        return "0"
    if a >= 100:
        return f"{v:.0f}"
    if a >= 1:
        return f"{v:.2f}"
    return f"{v:.4f}"


def control_chart(
    points: Sequence[ChartPoint],
    *,
    mean: float | None = None,
    lower: float | None = None,
    upper: float | None = None,
    unit: str = "px",
    title: str = "",
    css_id: str = "",
    width: int = 760,
    height: int = 230,
) -> Markup:
    """A control chart: the points in order (x = their order, labelled by serial), the mean and the
    control limits as horizontal lines; a point outside the limits is drawn as a red ring."""
    pad_l, pad_r, pad_t, pad_b = 62, 14, 22 if title else 10, 58
    vals = [p.value for p in points if p.value is not None and math.isfinite(p.value)]
    ys = vals + [v for v in (mean, lower, upper) if v is not None and math.isfinite(v)]
    out = [
        f'<svg class="chart control" viewBox="0 0 {width} {height}" width="100%" role="img"'
        + (f' id="{_esc(css_id)}"' if css_id else "")
        + f' aria-label="{_esc(title or "control chart")}" xmlns="http://www.w3.org/2000/svg">'
    ]
    if title:
        out.append(f'<text x="{pad_l}" y="14" font-size="12" fill="{MUTED}">{_esc(title)}</text>')
    x0, x1, y0, y1 = pad_l, width - pad_r, pad_t, height - pad_b
    out.append(f'<rect x="{x0}" y="{y0}" width="{x1 - x0}" height="{y1 - y0}" fill="none" stroke="{LINE}"/>')
    if not ys:
        out.append(f'<text x="{x0 + 8}" y="{y0 + 18}" font-size="12" fill="{MUTED}">no values</text></svg>')
        return Markup("".join(out))
    lo, hi = min(ys), max(ys)
    if hi == lo:
        lo, hi = lo - 0.5 * (abs(lo) or 1), hi + 0.5 * (abs(hi) or 1)
    span = hi - lo
    lo, hi = lo - 0.08 * span, hi + 0.08 * span

    def Y(v: float) -> float:
        return y1 - (v - lo) / (hi - lo) * (y1 - y0)

    n = len(points)

    def X(i: int) -> float:
        return x0 + (i + 0.5) * (x1 - x0) / max(n, 1)

    for v in (lo + 0.08 * span / 1.16, hi - 0.08 * span / 1.16):
        out.append(
            f'<text x="{x0 - 6}" y="{Y(v) + 4:.1f}" font-size="11" text-anchor="end" fill="{MUTED}">{_fmt(v)}</text>'
        )
    out.append(
        f'<text x="12" y="{(y0 + y1) / 2:.1f}" font-size="11" fill="{MUTED}" '
        f'transform="rotate(-90 12 {(y0 + y1) / 2:.1f})" text-anchor="middle">{_esc(unit)}</text>'
    )
    limits = [
        (name, v, colour, dash)
        for name, v, colour, dash in (
            ("ucl", upper, WARN, "5 3"),
            ("mean", mean, ACCENT, ""),
            ("lcl", lower, WARN, "5 3"),
        )
        if v is not None and math.isfinite(v)
    ]
    label_y: list[float] = []  # top to bottom, at least 11 px apart: limits close together stay readable
    for _name, v, _c, _d in limits:
        y = Y(v) - 3
        label_y.append(y if not label_y else max(y, label_y[-1] + 11))
    for (name, v, colour, dash), ly in zip(limits, label_y):
        out.append(
            f'<line class="limit {name}" x1="{x0}" x2="{x1}" y1="{Y(v):.1f}" y2="{Y(v):.1f}" stroke="{colour}"'
            + (f' stroke-dasharray="{dash}"' if dash else "")
            + f' data-value="{v:.6g}"/>'
        )
        label = {"mean": "mean", "lcl": "−3σ", "ucl": "+3σ"}[name]
        out.append(
            f'<text x="{x1 - 4}" y="{ly:.1f}" font-size="10" text-anchor="end" fill="{colour}">{label} {_fmt(v)}</text>'
        )
    prev = None
    for i, p in enumerate(points):
        if p.value is None or not math.isfinite(p.value):
            continue
        if prev is not None:
            out.append(
                f'<line x1="{prev[0]:.1f}" y1="{prev[1]:.1f}" x2="{X(i):.1f}" y2="{Y(p.value):.1f}" stroke="{LINE}"/>'
            )
        prev = (X(i), Y(p.value))
    step = max(1, math.ceil(n / 24))
    for i, p in enumerate(points):
        if i % step == 0:
            out.append(
                f'<text x="{X(i):.1f}" y="{y1 + 10}" font-size="10" fill="{MUTED}" text-anchor="end" '
                f'transform="rotate(-50 {X(i):.1f} {y1 + 10})">{_esc(p.label)}</text>'
            )
        if p.value is None or not math.isfinite(p.value):
            continue
        outside = (upper is not None and p.value > upper) or (lower is not None and p.value < lower)
        colour = BAD if p.verdict == "FAIL" else OK if p.verdict == "PASS" else MUTED
        cls = "point" + (" outside" if outside else "") + (f" {p.verdict.lower()}" if p.verdict else "")
        mark = (
            f'<circle class="{cls}" cx="{X(i):.1f}" cy="{Y(p.value):.1f}" r="4" fill="{colour}"'
            f' data-serial="{_esc(p.label)}" data-value="{p.value:.6g}"><title>{_esc(p.label)}: {_fmt(p.value)} {_esc(unit)}'
            f"{' — outside the control limits' if outside else ''}{f' ({p.verdict})' if p.verdict else ''}</title></circle>"
        )
        if outside:
            mark += (
                f'<circle cx="{X(i):.1f}" cy="{Y(p.value):.1f}" r="7.5" fill="none" stroke="{BAD}" stroke-width="1.5"/>'
            )
        out.append(f'<a href="{_esc(p.href)}">{mark}</a>' if p.href else mark)
    out.append("</svg>")
    return Markup("".join(out))


def verdict_bars(days: Sequence[tuple[str, int, int, int]], *, width: int = 760, height: int = 170) -> Markup:
    """Stacked bars per day: calibrations passed (green), failed (red), not judged (grey);
    ``days`` is ``(day, passed, failed, unjudged)``, oldest first."""
    pad_l, pad_r, pad_t, pad_b = 40, 10, 10, 34
    x0, x1, y0, y1 = pad_l, width - pad_r, pad_t, height - pad_b
    out = [
        f'<svg class="chart days" viewBox="0 0 {width} {height}" width="100%" role="img" aria-label="calibrations per day" xmlns="http://www.w3.org/2000/svg">'
    ]
    out.append(f'<line x1="{x0}" x2="{x1}" y1="{y1}" y2="{y1}" stroke="{LINE}"/>')
    top = max((p + f + u for _, p, f, u in days), default=0)
    if not top:
        out.append(f'<text x="{x0 + 8}" y="{y0 + 18}" font-size="12" fill="{MUTED}">no calibrations</text></svg>')
        return Markup("".join(out))
    n = len(days)
    bw = (x1 - x0) / n
    out.append(f'<text x="{x0 - 6}" y="{y0 + 8}" font-size="11" text-anchor="end" fill="{MUTED}">{top}</text>')
    out.append(f'<text x="{x0 - 6}" y="{y1}" font-size="11" text-anchor="end" fill="{MUTED}">0</text>')
    for i, (day, p, f, u) in enumerate(days):
        x = x0 + i * bw + 0.15 * bw
        y = float(y1)
        for count, colour, cls in ((p, OK, "passed"), (f, BAD, "failed"), (u, MUTED, "unjudged")):
            if not count:
                continue
            h = count / top * (y1 - y0)
            y -= h
            out.append(
                f'<rect class="bar {cls}" x="{x:.1f}" y="{y:.1f}" width="{0.7 * bw:.1f}" height="{h:.1f}" fill="{colour}"'
                f' data-day="{_esc(day)}" data-count="{count}"><title>{_esc(day)}: {count} {cls}</title></rect>'
            )
        out.append(
            f'<text x="{x + 0.35 * bw:.1f}" y="{y1 + 14}" font-size="10" text-anchor="middle" fill="{MUTED}">{_esc(day[5:])}</text>'
        )
    out.append("</svg>")
    return Markup("".join(out))
