"""The QA report of a session: Markdown with PNG plots (drawn by :mod:`station.qa.plots`), and the
same report as an HTML page; both written from one document by Jinja templates
(:mod:`station.qa.report_doc`).

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

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import pipeline.measure  # measure_image and the bootstrap called through their modules: tests replace them
import pipeline.uncertainty
from pipeline.resample import DEFAULT_T
from station.config import OVERLAY_RETENTION
from station.profile import Profile, Verdict
from station.qa.evidence import stored_measurement, stored_uncertainty
from station.qa.plots import Figure, Shot, draw_figures, edge_residual_table
from station.qa.report_doc import Block, Bullets, Heading, Image, Marked, Paragraph, Quote, Table, VerdictLine, render
from station.qa.results import config_record, device_identities, identity_warnings
from station.session import layout
from station.session.processing import average_frames

REPORT_MD = "report.md"
"""The report's Markdown file, in its directory."""
REPORT_HTML = "index.html"
"""The same report as a standalone HTML page."""


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
    colour: Any = None  # a colour camera's TCA and vignetting (station.session.colour), or None
    choice: str = ""
    """The model fitted (its label, ``radial4+tangential+prism``), as the profile records it; "" when it does not."""
    choice_reason: str = ""
    """How it was chosen (the profile's selection reason: the cross-validation's, or the configuration's name)."""
    support: str | None = None
    """Why the shots do not support that model well (too few string orientations), or None: a warning."""


def focus_evidence(profile: Profile, focus: float, verdict: Verdict, source: str = "") -> FocusEvidence:
    """A focus setting's evidence from its profile alone (the model, its choice and support, the verdict):
    :func:`session_evidence` adds the session's shots and uncertainty map."""
    sel = dict(profile.selection or {})
    return FocusEvidence(
        focus=focus,
        model=profile.model,
        width=profile.width,
        height=profile.height,
        verdict=verdict,
        source=source,
        choice=profile.spec.label if profile.spec is not None else "",
        choice_reason=str(sel.get("reason") or ""),
        support=sel.get("support") or None,
    )


def _colour_blocks(colour: Any) -> list[Block]:
    """The report's *Colour and light* of a focus setting: per channel the TCA against green (largest shift
    over the image, RMS residual, lensfun poly3), the relative illumination at the centre, edges and corners,
    the back-light's unevenness and lensfun's pa terms; a measurement that failed, its reason."""
    blocks: list[Block] = [Heading(3, "Colour and light (from the same shots)")]
    tca = colour.get("tca") or {}
    if "failure" in tca:
        blocks.append(Paragraph(f"TCA: not measured: {tca['failure']}"))
    elif tca:
        poly3 = (tca.get("lensfun") or {}).get("poly3") or {}
        rows = []
        for ch, name in (("R", "red"), ("B", "blue")):
            c = (tca.get("channels") or {}).get(ch) or {}
            terms = ", ".join(f"{v:.6g}" for v in poly3.get(name) or ())
            rows.append(
                (ch, _fmt(c.get("field_max_px")), _fmt(c.get("residual_rms_px")), str(c.get("n_edges", "-")), terms)
            )
        blocks.append(
            Table(
                ("channel", "TCA max (px)", "residual RMS (px)", "edges", "lensfun poly3"),
                ("center", "right", "right", "right", "left"),
                tuple(rows),
            )
        )
    vig = colour.get("vignetting") or {}
    if "failure" in vig:
        blocks.append(Paragraph(f"Vignetting: not measured: {vig['failure']}"))
    elif vig:
        points = (vig.get("relative_illumination") or {}).get("points") or ()
        rows = tuple((str(p["where"]), _fmt(p.get("fit")), _fmt(p.get("lensfun_pa"))) for p in points)
        blocks.append(Table(("where", "relative illumination", "lensfun pa"), ("left", "right", "right"), rows))
        lf = vig.get("lensfun") or {}
        blocks.append(
            Paragraph(
                f"Back-light unevenness (separated by the turntable) {_fmt(vig.get('backlight_unevenness'))}; "
                f"lensfun pa k1 {_fmt(lf.get('k1'))}, k2 {_fmt(lf.get('k2'))}, k3 {_fmt(lf.get('k3'))}."
            )
        )
    return blocks


def keeps_overlays(overlays: str, verdict: Verdict) -> bool:
    """Whether a focus setting of this verdict keeps its overlays under ``overlays`` (all, failed, none)."""
    if overlays not in OVERLAY_RETENTION:
        raise ValueError(f"overlays: expected one of {', '.join(OVERLAY_RETENTION)}, got {overlays!r}")
    return overlays == "all" or (overlays == "failed" and verdict.verdict != "PASS")


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


def _check_table(verdict: Verdict) -> Table:
    """The checks of a verdict as a table: what was compared, and what happened."""
    rows = []
    for c in verdict.checks:
        result: str | Marked = "reported" if c.passed is None else ("PASS" if c.passed else Marked("FAIL"))
        limit = "-" if c.limit is None else f"{c.limit:g}"
        rows.append((c.name, _fmt(c.value), c.comparison, limit, result, c.text))
    return Table(
        ("check", "value (px)", "must be", "limit (px)", "result", "what happened"),
        ("left", "right", "center", "right", "center", "left"),
        tuple(rows),
    )


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
    """Write ``report.md``, its HTML page ``index.html`` and their pictures into ``out_dir``
    (created); returns the Markdown path. Both are written from one document
    (:mod:`station.qa.report_doc`).

    ``context``: (what, value) rows shown under the verdict (date, station, software,
    configuration and its SHA-256, devices); ``warnings``: lines shown as warnings (a device
    that reported another identity than the configuration's); ``workers``: processes that
    draw the pictures (:func:`draw_figures`); ``overlays``: which focus settings keep their
    overlays (:func:`keeps_overlays`)."""
    import datetime as _dt

    out = Path(out_dir)
    figures: list[Figure] = []
    out.mkdir(parents=True, exist_ok=True)
    doc: list[Block] = [Heading(1, f"QA report: {title}"), VerdictLine(overall), Paragraph(DEFINITIONS)]
    written = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    doc.append(Table(("", ""), ("left", "left"), (("report written", written), *((k, v) for k, v in context))))
    doc += [Quote(w, label="warning") for w in warnings]
    doc += [
        Quote(f"focus {e.focus:g}, {e.choice or 'the model'}: {e.support}", label="warning")
        for e in evidence
        if e.support
    ]
    if thresholds is not None:
        doc.append(
            Paragraph(
                "Thresholds: "
                + ", ".join(
                    f"{k} = {v:g} px" if v is not None else f"{k}: not judged" for k, v in thresholds.__dict__.items()
                )
            )
        )
    summary = []
    for e in evidence:
        f = e.verdict.figures
        unc = e.uncertainty
        u = (
            f"{unc.rms:.4f} / {unc.max:.4f}"
            if unc is not None
            else f"{_fmt(f.get('field_uncertainty_rms_px'))} / {_fmt(f.get('field_uncertainty_max_px'))}"
        )
        summary.append(
            (
                f"{e.focus:g}",
                e.verdict.verdict,
                _fmt(f.get("holdout_d_px")),
                _fmt(f.get("distortion_max_px"), 3),
                _fmt(f.get("reference_max_px")),
                u,
                "; ".join(e.verdict.reasons) or "-",
            )
        )
    doc.append(
        Table(
            (
                "focus",
                "verdict",
                "holdout d (px)",
                "distortion max (px)",
                "ref. deviation max (px)",
                "uncertainty RMS / max (px)",
                "reasons",
            ),
            ("right", "center", "right", "right", "right", "right", "left"),
            tuple(summary),
        )
    )
    if interpolation:
        doc += [
            Heading(2, "Focus interpolation (leave one calibrated focus out)"),
            Paragraph(
                "Each interior focus setting interpolated from the others and compared with its own fit, "
                "modulo homography."
            ),
            Table(
                ("focus left out", "RMS (px)", "max (px)"),
                ("right", "right", "right"),
                tuple((f"{r.focus:g}", f"{r.rms_px:.4f}", f"{r.max_px:.4f}") for r in interpolation),
            ),
        ]
    doc += [Quote(n) for n in notes]
    for i, e in enumerate(evidence):
        label = f"focus {e.focus:g}"
        doc.append(Heading(2, label))
        if e.source:
            doc.append(Paragraph(f"Profile: `{e.source}`"))
        doc += [VerdictLine(e.verdict.verdict, focus=f"{e.focus:g}"), _check_table(e.verdict)]
        if e.verdict.reasons:
            doc += [Paragraph("Reasons for FAIL:"), Bullets(tuple(e.verdict.reasons))]
        if e.choice or e.choice_reason:
            # the reason ends with the support problem when there is one (station.calibration.selection_record,
            # pipeline.select): said once, as the warning under it
            why = e.choice_reason.replace(f"; {e.support}", "") if e.support else e.choice_reason
            doc += [Heading(3, "Model"), Paragraph(f"`{e.choice or '?'}`: {why or 'no reason recorded'}")]
            if e.support:
                doc.append(Quote(e.support, label="warning"))
        name = f"field_f{i}.png"
        figures.append(Figure("field", (e.model, e.width, e.height, out / name), {"title": f"{title}, {label}"}))
        doc += [Heading(3, "Distortion field"), Image("distortion field", name)]
        if e.colour:
            doc += _colour_blocks(e.colour)
        if e.shots:
            name = f"residuals_f{i}.png"
            rows = edge_residual_table(e.shots, e.model)
            groups = [s.group for s in e.shots]
            figures.append(Figure("residuals", (rows, groups, out / name), {"title": f"{title}, {label}"}))
            doc += [Heading(3, "Residual per edge"), Image("residual per edge", name)]
        if e.uncertainty is not None:
            name = f"uncertainty_f{i}.png"
            figures.append(
                Figure("uncertainty", (e.uncertainty, e.width, e.height, out / name), {"title": f"{title}, {label}"})
            )
            doc += [Heading(3, "Field uncertainty"), Image("field uncertainty", name)]
        elif e.uncertainty_note:
            doc += [Heading(3, "Field uncertainty"), Paragraph(e.uncertainty_note)]
        if e.shots and not keeps_overlays(overlays, e.verdict):
            doc += [
                Heading(3, "Overlays"),
                Paragraph(
                    f"Not kept (overlays: {overlays}"
                    + ("; this focus setting passed QA)." if overlays == "failed" else ").")
                    + " `harp qa SESSION_DIR --report DIR --overlays all` draws them from the session's frames."
                ),
            ]
        elif e.shots:
            doc.append(Heading(3, "Overlays (edges coloured by their distance to their own line, before correction)"))
            for j, s in enumerate(e.shots):
                name = f"overlay_f{i}_o{j}.jpg"
                caption = f"{label}, {s.place}"
                # float32 holds an average of a few 8- or 16-bit frames for display (half the bytes to a worker)
                image = np.asarray(s.image, np.float32)
                figures.append(Figure("overlay", (image, s.measurement, out / name), {"title": caption}))
                doc.append(Image(f"overlay, {s.place}", name))
    draw_figures(figures, workers)
    path = out / REPORT_MD
    path.write_text(render(doc, "md"))
    (out / REPORT_HTML).write_text(render(doc, "html", title=f"QA report: {title}"))
    return path


# ------------------------------------------------------- session evidence
def session_shots(session, focus_idx: int, t: int = DEFAULT_T) -> list[Shot]:
    """Averaged, measured shots of one focus setting of an open
    :class:`station.session_dir.SessionDir` (orientations with no frames are skipped).

    The measurement is the one the executor kept (:func:`stored_measurement`);
    a shot without one is measured now."""
    cfg = session.config
    shots = []
    for o, (mm, deg) in enumerate(cfg.capture.orientations):
        records = session.frames(focus_idx, o)
        if not records:
            continue
        image = average_frames([session.read_frame(r) for r in records])
        m = stored_measurement(session, focus_idx, o)
        measured = m if m is not None else pipeline.measure.measure_image(image, t=t)
        twin = o not in cfg.capture.fitted  # the twin: compared, not fitted
        shots.append(Shot(float(deg), image, measured, None if mm is None else float(mm), twin))
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
    e = focus_evidence(profile, focus, verdict, source)
    e.colour = profile.details.get("colour")
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
                [s for s in e.shots if not s.twin],
                profile.width,
                profile.height,
                spec,
                n_boot=bootstrap_if_missing,
                seed=cfg.pipeline.seed,
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
