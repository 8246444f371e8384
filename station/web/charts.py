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


@dataclass(frozen=True)
class SpecLimit:
    """The specification a figure was judged against: ``value comparison limit`` (QA's check),
    e.g. ``("<=", (0.05,))``; several limits when the profiles were judged with different ones."""

    comparison: str
    limits: tuple[float, ...]


def _spread(ys: list[float], gap: float, top: float, bottom: float) -> list[float]:
    """Label positions near ``ys`` (sorted top to bottom) at least ``gap`` apart, within [top, bottom]."""
    out: list[float] = []
    for y in ys:
        out.append(max(y, out[-1] + gap) if out else max(y, top))
    over = out[-1] - bottom if out else 0.0
    if over > 0:  # pushed below the bottom: move the stack up, keeping the gaps
        out = [y - over for y in out]
        for i in range(len(out) - 2, -1, -1):
            out[i] = min(out[i], out[i + 1] - gap)
    return out


LEGEND = (
    ("pass", "passed QA"),
    ("fail", "failed QA"),
    ("outside", "outside control limits"),
    ("mean", "mean (passed)"),
    ("control", "±3σ control limits"),
    ("spec", "spec limit (QA)"),
)
"""The control chart's legend: what each mark means."""


def control_chart(
    points: Sequence[ChartPoint],
    *,
    mean: float | None = None,
    lower: float | None = None,
    upper: float | None = None,
    spec: SpecLimit | None = None,
    unit: str = "px",
    title: str = "",
    css_id: str = "",
    width: int = 760,
    height: int = 262,
) -> Markup:
    """A control chart: the points in order (x = their order, labelled by serial; green passed QA,
    red failed), the mean and the control limits as horizontal lines, the spec limit ``spec`` (the
    QA limit the profiles were judged with) as a red line, and a legend. A point outside the
    control limits is ringed in red. The value axis spans the points and the control limits, and
    a spec limit within one such span of them; a spec limit farther away is named at the edge it
    lies beyond. The limits' labels stand right of the plot, moved apart where they would overlap."""
    pad_l, pad_r, pad_t, pad_b = 62, 104, 22 if title else 10, 84
    vals = [p.value for p in points if p.value is not None and math.isfinite(p.value)]
    controls = [v for v in (mean, lower, upper) if v is not None and math.isfinite(v)]
    specs = [v for v in (spec.limits if spec else ()) if math.isfinite(v)]
    out = [
        f'<svg class="chart control" viewBox="0 0 {width} {height}" width="100%" role="img"'
        + (f' id="{_esc(css_id)}"' if css_id else "")
        + f' aria-label="{_esc(title or "control chart")}" xmlns="http://www.w3.org/2000/svg">'
    ]
    if title:
        out.append(f'<text x="{pad_l}" y="14" font-size="12" fill="{MUTED}">{_esc(title)}</text>')
    x0, x1, y0, y1 = pad_l, width - pad_r, pad_t, height - pad_b
    out.append(f'<rect x="{x0}" y="{y0}" width="{x1 - x0}" height="{y1 - y0}" fill="none" stroke="{LINE}"/>')
    if not vals and not controls:
        out.append(f'<text x="{x0 + 8}" y="{y0 + 18}" font-size="12" fill="{MUTED}">no values</text></svg>')
        return Markup("".join(out))
    ys = vals + controls
    lo, hi = min(ys), max(ys)
    reach = max(hi - lo, 0.25 * max(abs(hi), abs(lo)), 1e-12)
    shown_specs = [v for v in specs if lo - reach <= v <= hi + reach]
    ys += shown_specs
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
    cmp = {"<=": "≤", ">=": "≥"}.get(spec.comparison, spec.comparison) if spec else ""
    lines = [(f"spec {cmp}", "spec", v, BAD, "8 3 2 3", 1.6) for v in shown_specs]
    lines += [
        (label, name, v, colour, dash, 1.0)
        for label, name, v, colour, dash in (
            ("+3σ", "ucl", upper, WARN, "5 3"),
            ("mean", "mean", mean, ACCENT, ""),
            ("−3σ", "lcl", lower, WARN, "5 3"),
        )
        if v is not None and math.isfinite(v)
    ]
    lines.sort(key=lambda line: Y(line[2]))
    label_y = _spread([Y(v) + 3.5 for _l, _n, v, _c, _d, _w in lines], 12.5, y0 + 8, y1 + 3)
    for (label, name, v, colour, dash, sw), ly in zip(lines, label_y, strict=True):
        out.append(
            f'<line class="limit {name}" x1="{x0}" x2="{x1}" y1="{Y(v):.1f}" y2="{Y(v):.1f}" stroke="{colour}"'
            + f' stroke-width="{sw:g}"'
            + (f' stroke-dasharray="{dash}"' if dash else "")
            + f' data-value="{v:.6g}"/>'
        )
        out.append(
            f'<text class="limit-label {name}" x="{x1 + 5}" y="{ly:.1f}" font-size="10" fill="{colour}">'
            f"{_esc(label)} {_fmt(v)}</text>"
        )
    for v in specs:
        if v in shown_specs:
            continue
        above = v > hi
        yy = y0 + 11 if above else y1 - 4
        out.append(
            f'<text class="limit-label spec off-chart" x="{x1 - 4}" y="{yy:.1f}" font-size="10" text-anchor="end" '
            f'fill="{BAD}" data-value="{v:.6g}">spec {_esc(cmp)} {_fmt(v)} {_esc(unit)} '
            f"{'above ↑' if above else 'below ↓'}</text>"
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
    out.append(_legend(x0, height - 8, spec is not None))
    out.append("</svg>")
    return Markup("".join(out))


def _legend(x: float, y: float, with_spec: bool) -> str:
    """One row of legend items at baseline ``y`` from ``x`` (class ``legend``, one ``g.item`` per mark)."""
    out = [f'<g class="legend" font-size="10" fill="{MUTED}">']
    for key, text in LEGEND:
        if key == "spec" and not with_spec:
            continue
        cy = y - 3.5
        if key in ("pass", "fail"):
            mark = f'<circle cx="{x + 5:.1f}" cy="{cy:.1f}" r="4" fill="{OK if key == "pass" else BAD}"/>'
        elif key == "outside":
            mark = (
                f'<circle cx="{x + 5:.1f}" cy="{cy:.1f}" r="3" fill="{MUTED}"/>'
                f'<circle cx="{x + 5:.1f}" cy="{cy:.1f}" r="6" fill="none" stroke="{BAD}" stroke-width="1.5"/>'
            )
        else:
            colour, dash, sw = {
                "mean": (ACCENT, "", 1.0),
                "control": (WARN, "5 3", 1.0),
                "spec": (BAD, "8 3 2 3", 1.6),
            }[key]
            mark = (
                f'<line x1="{x:.1f}" x2="{x + 18:.1f}" y1="{cy:.1f}" y2="{cy:.1f}" stroke="{colour}" '
                f'stroke-width="{sw:g}"' + (f' stroke-dasharray="{dash}"' if dash else "") + "/>"
            )
        w_mark = 14 if key in ("pass", "fail", "outside") else 22
        out.append(f'<g class="item {key}">{mark}<text x="{x + w_mark:.1f}" y="{y:.1f}">{_esc(text)}</text></g>')
        x += w_mark + 5.6 * len(text) + 12
    out.append("</g>")
    return "".join(out)


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
