"""What limits the realistic simulator's field error (issue 19 item 5): one effect switched off at a time.

Usage::

    .venv/bin/python benchmarks/lens_limits.py [--seeds 38,37,39,6,16] [--size 1000x750] [--workers 2]
        [--exact-only | --kink-trim | --point-robust [--cache DIR] | --point-robust-exact]
    .venv/bin/python benchmarks/lens_limits.py --choice [--seeds ...] [--cache /tmp/lines]
    .venv/bin/python benchmarks/lens_limits.py --stored [--seeds ...] [--cache /tmp/lines]
    .venv/bin/python benchmarks/lens_limits.py --kinks [--kink-z Z] [--cache DIR] | --kinks-exact [--seeds ...]

Per seed: the lens, harp, mount and camera effects of ``benchmarks/strings_separated.py`` (six shots at
0..150 degrees, ``radial4+tangential+prism`` fitted with every string's own bend separated,
``pipeline.harp_shape.fit_harp_shape``: what a session stores), rendered again with one thing changed:

* **render ablations** (measured as ``harp measure`` does): the strings made straight (sag, bows, kink,
  twist all zero), the kinks alone removed, the blur made uniform (the drawn isotropic PSF, no defocus
  growing to the corners), no colour filter array (a monochrome sensor: no demosaicing), no shot or read
  noise, no vignetting and a uniform back-light, a linear tone curve;
* **exact points**: the true edges traced through the exact lens every 2 px (``pipeline.render.visible_edges``),
  no image at all, with the strings as drawn ("bent") or straight; the straight ones fitted by
  ``radial4+tangential+prism`` and by ``radial6+tangential+prism`` are the model family's own limit;
* **chosen**: the candidate ``pipeline.select.select_model`` chooses on the realistic shots (what a session
  with no ``pipeline.model`` fits), fitted with the strings separated.

A second table (exact points only, no image; ``--exact-only`` prints it alone) asks whether the strings'
shapes could be told from the lens by the set-up or the fit: the turntable axis moved 150 and 300 px (and half
that down) from where it was drawn (the harp widened by copies of its strings so that it still fills the
image), each fitted with the lens alone and with the strings separated; and the kinks alone (every other
shape zero), fitted with ``fit_distortion``'s outlier rejection (edges above 5 x the median edge RMS) and
without it.

A third table (``--kink-trim``) tries, on the full realistic shots, what would keep a kink out of the lens
without a per-point weight in the fit (a prototype in this script, not the pipeline's behaviour): after the
fit, each edge's residual about the fitted lens minus its own smooth trend (Legendre degree 4 along the edge:
what the lens's misfit and a string's bow leave) is a kink's signature; the points where it exceeds
``c`` times its robust standard deviation over all edges (1.4826 x median absolute value) are dropped and the
lens fitted again.

``--point-robust`` prints the per-point robust fit of the pipeline (``fit_distortion(point_loss=...)``,
``pipeline.robust_points``) on the full realistic shots: none (the fit as it is), Tukey's biweight and Huber's
weight with each point's scale from its edge's detrended residuals, and the same two with each point's own
standard deviation as its scale (``point_scale``: ``pipeline.measure.point_sigmas``), each fitted with the lens
alone and with the strings separated (``fit_harp_shape`` weighs the plain fit's robust point weights); the
measured lines and sigmas are kept in ``--cache`` (npz) when given. ``--point-robust-exact``: the exact points
of the kinks alone (every other string shape zero) fitted as they are and with Tukey's biweight, without and
with 0.02 px of independent noise per point (enough that a kinked edge no longer stands out as a whole), and
the straight strings with the same noise (the kink-free reference).

``--kinks`` (issue 19 items 4-5): the full realistic shots fitted with the strings separated as a session
does, without and with each string's kinks found and modelled (``fit_harp_shape(kinks=True)``,
``pipeline.harp_kinks``), against the drawn truth: kinks modelled within 24 px of a drawn one on the same string
("true") or elsewhere ("false", with the largest detection significance of those: ``--kink-z 3`` shows how high
the scan goes on kink-free strings), and the drawn kinks on strings seen in two shots or more (inside the
stretch shown) with how many of them were found. ``--kinks-exact``: the same on the exact points of the strings
with their kinks alone, smoothed along the edge as ``harp measure`` does (``pipeline.resample.smooth_subsample``),
as they are and with 0.003 px of noise per point.

A fourth table (``--choice``, issue 19 item 2) compares the automatic choice without and with the turntable
angles (``select_model(..., turntable_deg=...)``: folds fitted with the strings separated, the held-out shot
judged with its strings' fitted bends removed, :mod:`pipeline.separated_cv`) on the full realistic render of
the six shots; every candidate is fitted with the strings separated (what a session stores) and judged by its
field error and by the d of three unseen shots (17, 77, 137 degrees) with their strings' bends, as that fit
found them, removed; ratios over the best candidate by the same measure. ``--cache DIR`` keeps the measured
edges of each seed (a render takes minutes).

``--stored`` (issue 19 item 5) gives each lens as a session with its default settings stores it: the model
``select_model`` chooses on the six shots (plain folds, ``pipeline.choice_folds: plain``), fitted with the
strings' bends separated (``pipeline.strings: separate``) and with each string's kinks found and modelled as
well (``separate-kinks``, the default since 2026-12-06), beside radial4+tangential+prism fitted both ways.

Every figure is the field error against the exact lens, RMS modulo homography over the whole image
(``pipeline.compare.compare_models``, 20 px grid), px. JPEG is off and the lens has no non-parametric field
in this population (``realistic_session(jpeg=False)``, ``lens_population(field=False)``), as in
``benchmarks/strings_separated.py``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # point_robust's losses

import numpy as np
from point_robust import LOSSES as POINT_LOSS_ROWS
from point_robust import fit_loss

from pipeline.compare import compare_models
from pipeline.edgeset import FitFailure, FitResult
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.harp_kinks import KINK_Z
from pipeline.harp_scene import Harp
from pipeline.harp_shape import fit_harp_shape
from pipeline.lens_population import lens_population
from pipeline.measure import measure_image, point_sigmas
from pipeline.models.base import DistortionModel
from pipeline.optics import FieldBlur
from pipeline.realism import Effects, Session, realistic_session, render_shots, shot_edges
from pipeline.render import visible_edges
from pipeline.resample import DEFAULT_T, smooth_subsample
from pipeline.select import select_model
from pipeline.separated_cv import held_out_without_strings

FITTED = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0)
SPEC = FitSpec("radial", 4, True, True)
SPEC6 = FitSpec("radial", 6, True, True)
STRAIGHT = {"sag_px": 0.0, "bow_px": (0.0, 0.0, 0.0), "kink_px": 0.0, "ovality_px": 0.0, "offcentre_px": 0.0}
STRAIGHT |= {"pick_px": 0.0}
RENDERS = ("full", "straight", "no kinks", "uniform blur", "no Bayer", "no noise", "flat light", "linear tone")


def reshaped(harp: Harp, zero: dict[str, object]) -> Harp:
    """``harp`` with the string-shape fields in ``zero`` set to those values (positions and widths kept)."""
    strings = tuple(dataclasses.replace(s, **zero) for s in harp.strings)  # type: ignore[arg-type]
    return Harp(strings, harp.spacing_px, harp.material, harp.mm_per_px, harp.tension_n, harp.transmission)


def variant(ses: Session, name: str) -> tuple[Harp, Effects]:
    """The harp and effects of render ablation ``name`` (module docstring)."""
    e, rep = ses.effects, dataclasses.replace
    return {
        "full": (ses.harp, e),
        "straight": (reshaped(ses.harp, STRAIGHT), e),
        "no kinks": (reshaped(ses.harp, {"kink_px": 0.0}), e),
        "uniform blur": (ses.harp, rep(e, blur=FieldBlur(sigma_px=e.blur.sigma_px))),
        "no Bayer": (ses.harp, rep(e, sensor=rep(e.sensor, cfa=None))),
        "no noise": (ses.harp, rep(e, sensor=rep(e.sensor, shot_noise=False, read_noise_e=0.0))),
        "flat light": (ses.harp, rep(e, vignetting=None, backlight=None)),
        "linear tone": (ses.harp, rep(e, development=rep(e.development, tone="linear"))),
    }[name]


def field(
    lines: list[list],
    lens: DistortionModel,
    w: int,
    h: int,
    spec: FitSpec,
    joint: bool = True,
    plain: FitResult | FitFailure | None = None,
    kinks: bool = False,
    angles: Sequence[float] = FITTED,
) -> float:
    """Field error of ``spec`` fitted on ``lines`` (with the strings separated when ``joint``, and their kinks
    modelled as well with ``kinks``; the shots at turntable ``angles``); ``plain``: the fit of ``spec`` on ``lines``
    alone when already made."""
    if plain is None:
        plain = fit_distortion(lines, w, h, **spec.fit_arguments())
    if not plain:
        return float("nan")
    model = plain.model
    if joint:
        sep = fit_harp_shape(lines, list(angles), w, h, spec, plain=plain, kinks=kinks)
        if not sep:
            return float("nan")
        model = sep.model
    return float(compare_models(model, lens, w, h, step=20).rms)


def both(lines: list[list], lens: DistortionModel, w: int, h: int, spec: FitSpec) -> tuple[float, float]:
    """Field errors of ``spec`` fitted on ``lines`` alone and with the strings separated (one plain fit)."""
    plain = fit_distortion(lines, w, h, **spec.fit_arguments())
    return field(lines, lens, w, h, spec, joint=False, plain=plain), field(lines, lens, w, h, spec, plain=plain)


def exact_lines(lens: DistortionModel, harp: Harp, ses: Session, w: int, h: int) -> list[list]:
    """The true edges of every shot, traced through the exact lens every 2 px."""
    out = []
    for ang in FITTED:
        edges = shot_edges(lens, harp, ses.mount.pose(ang), w, h)
        out.append([c for _, c in visible_edges(edges, lens, w, h, step=2.0)])
    return out


def seed_lens(
    seed: int, w: int, h: int, lens_field: bool = False
) -> tuple[DistortionModel, Session, dict[str, object]]:
    """The population's lens ``seed``, its realistic session and the start of its table row; with ``lens_field``
    the same lens with a non-parametric field added (``lens_population(field=True)``: its parametric part is the
    same draw, the field RMS drawn in the documented 0.005-0.04 px)."""
    member = lens_population(seed, 1, w, h, field=lens_field)[0]
    ses = realistic_session(seed, w, h)
    row: dict[str, object] = {"seed": seed, "lens": member.design, "strings": ses.harp.material}
    if lens_field:
        row["field_rms"] = member.field_rms_px
    return member.model, ses, row


UNSEEN = (17.0, 77.0, 137.0)


def realistic_measured(
    seed: int, w: int, h: int, cache: Path | None = None, lens_field: bool = False
) -> tuple[list[list], list[list], list[list]]:
    """Seed ``seed``'s full realistic render measured as ``harp measure`` does: the six fitted shots' edges
    (``FITTED``, the same as :func:`one`'s "full" row: shot ``i`` is seeded by its index), the three unseen
    shots' edges (``UNSEEN``, as in ``benchmarks/strings_separated.py``) and each fitted point's standard
    deviation (``pipeline.measure.point_sigmas``). Kept in ``cache`` (a directory, one ``.npz`` per seed and
    size) when given, read from there when present (a render takes minutes; the file only saves time).
    ``lens_field``: the lens of :func:`seed_lens` with its non-parametric field (kept as ``..._field.npz``)."""
    name = f"measured_{seed}_{w}x{h}{'_field' if lens_field else ''}.npz"
    path = None if cache is None else cache / name
    if path is not None and path.exists():
        with np.load(path) as z:
            counts = [int(v) for v in z["counts"]]
            lines = [[z[f"s{i}_{j}"] for j in range(k)] for i, k in enumerate(counts)]
            sigmas = [[z[f"g{i}_{j}"] for j in range(k)] for i, k in enumerate(counts)]
    else:
        lens, ses, _ = seed_lens(seed, w, h, lens_field)
        shots = render_shots(lens, ses.harp, ses.mount, FITTED + UNSEEN, w, h, ses.effects, seed=seed)
        ms = [measure_image(s.image) for s in shots]
        lines = [[ln.points for ln in m.lines] for m in ms]
        sigmas = [point_sigmas(m) for m in ms]
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            arrays = {f"s{i}_{j}": p for i, shot in enumerate(lines) for j, p in enumerate(shot)}
            arrays |= {f"g{i}_{j}": g for i, shot in enumerate(sigmas) for j, g in enumerate(shot)}
            tmp = path.with_suffix(".tmp.npz")
            np.savez(tmp, counts=np.array([len(shot) for shot in lines]), **arrays)
            os.replace(tmp, path)
    n = len(FITTED)
    return lines[:n], lines[n:], sigmas[:n]


def one(args: tuple[int, int, int]) -> dict[str, object]:
    seed, w, h = args
    lens, ses, row = seed_lens(seed, w, h)
    t0 = time.perf_counter()
    full_lines: list[list] = []
    for name in RENDERS:
        harp, eff = variant(ses, name)
        shots = render_shots(lens, harp, ses.mount, FITTED, w, h, eff, seed=seed)
        lines = [[ln.points for ln in measure_image(s.image).lines] for s in shots]
        if name == "full":
            full_lines = lines
            row["full alone"], row[name] = both(lines, lens, w, h, SPEC)
        else:
            row[name] = field(lines, lens, w, h, SPEC)
    row["exact bent"] = field(exact_lines(lens, ses.harp, ses, w, h), lens, w, h, SPEC)
    straight = exact_lines(lens, reshaped(ses.harp, STRAIGHT), ses, w, h)
    row["exact straight r4"] = field(straight, lens, w, h, SPEC, joint=False)
    row["exact straight r6"] = field(straight, lens, w, h, SPEC6, joint=False)
    choice = select_model(full_lines, w, h).choice
    row["chosen"] = choice.label
    row["chosen field"] = field(full_lines, lens, w, h, choice)
    row["t"] = time.perf_counter() - t0
    return row


def choice(args: tuple[int, int, int, Path | None]) -> dict[str, object]:
    """Seed ``seed``'s choice without and with the turntable angles (``--choice``, module docstring)."""
    seed, w, h, cache = args
    lens, ses, row = seed_lens(seed, w, h)
    fitted, unseen, _ = realistic_measured(seed, w, h, cache)
    t0 = time.perf_counter()
    plain_sel = select_model(fitted, w, h)
    row["t plain"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    sep_sel = select_model(fitted, w, h, turntable_deg=FITTED)
    row["t separated"] = time.perf_counter() - t0
    fields, unseen_d = {}, {}
    for r in sep_sel.table:  # every candidate as a session stores it: fitted with the strings separated
        plain = r.full_fit or fit_distortion(fitted, w, h, **r.candidate.fit_arguments())
        joint = fit_harp_shape(fitted, FITTED, w, h, r.candidate, plain=plain) if plain else plain
        if not joint:
            continue
        fields[r.candidate] = float(compare_models(joint.model, lens, w, h, step=20).rms)
        held = [held_out_without_strings(joint, shot, a) for shot, a in zip(unseen, UNSEEN, strict=True)]
        unseen_d[r.candidate] = float(np.sqrt(np.mean(np.concatenate([x.residuals for x in held]) ** 2)))
    best = min(fields, key=lambda c: fields[c])
    best_u = min(unseen_d, key=lambda c: unseen_d[c])
    # two rules for comparison, not the pipeline's: the lowest CV d of the separated folds, and no choice at all
    # (the fallback radial4+tangential+prism, what the rest of this benchmark fits)
    lowest = min((r for r in sep_sel.table if np.isfinite(r.cv_d)), key=lambda r: r.cv_d).candidate
    row["lowest cv field"] = fields.get(lowest, float("nan"))
    row["fixed field"] = fields.get(SPEC, float("nan"))
    row.update(best=best.label, best_field=fields[best], best_unseen=best_u.label, best_unseen_d=unseen_d[best_u])
    for key, sel in (("plain", plain_sel), ("separated", sep_sel)):
        row[key] = sel.choice.label
        row[f"{key} field"] = fields.get(sel.choice, float("nan"))
        row[f"{key} unseen"] = unseen_d.get(sel.choice, float("nan"))
    return row


def stored(args: tuple[int, int, int, Path | None]) -> dict[str, object]:
    """Seed ``seed``'s lens as a session stores it (``--stored``, module docstring)."""
    seed, w, h, cache = args
    lens, _, row = seed_lens(seed, w, h)
    fitted, _, _ = realistic_measured(seed, w, h, cache)
    t0 = time.perf_counter()
    sel = select_model(fitted, w, h)
    row["chosen"] = sel.choice.label
    for name, spec in (("chosen", sel.choice), ("fixed", SPEC)):
        full = next((r.full_fit for r in sel.table if r.candidate == spec and r.full_fit), None)
        full = full or fit_distortion(fitted, w, h, **spec.fit_arguments())
        for kinks in (False, True):
            row[f"{name} {kinks}"] = field(fitted, lens, w, h, spec, plain=full, kinks=kinks)
    row["t"] = time.perf_counter() - t0
    return row


def print_stored(results: Iterable[dict[str, object]]) -> None:
    print(
        "| seed | lens | strings | chosen (plain folds) | chosen: bends / bends + kinks px | "
        "radial4+tangential+prism: bends / bends + kinks px | s |"
    )
    print("|---:|---|---|---|---:|---:|---:|")
    rows = []
    for r in results:
        rows.append(r)
        print(
            f"| {r['seed']} | {r['lens']} | {r['strings']} | {r['chosen']} | {r['chosen False']:.4f} / "
            f"{r['chosen True']:.4f} | {r['fixed False']:.4f} / {r['fixed True']:.4f} | {r['t']:.0f} |",
            flush=True,
        )
    print()
    for key, name in (("chosen", "the chosen model"), ("fixed", "radial4+tangential+prism")):
        a = np.array([float(r[f"{key} False"]) for r in rows])  # type: ignore[arg-type]
        b = np.array([float(r[f"{key} True"]) for r in rows])  # type: ignore[arg-type]
        print(
            f"{name}: at or below 0.005 px {int(np.sum(a <= 0.005))} (bends) -> {int(np.sum(b <= 0.005))} (bends + "
            f"kinks) of {len(rows)}; with the kinks lower by > 5 % for {int(np.sum(b < 0.95 * a))}, higher by > 5 % "
            f"for {int(np.sum(b > 1.05 * a))} (largest rise {np.max(b - a):+.4f} px); median {np.median(a):.4f} -> "
            f"{np.median(b):.4f} px"
        )


def print_choice(results: Iterable[dict[str, object]]) -> None:
    print(
        "| seed | lens | strings | chosen (plain folds) | field px | chosen, strings separated (angles known) | "
        "field px | best candidate | field px | field ratio plain / separated | unseen d ratio plain / separated "
        "| choice s plain / separated |"
    )
    print("|---:|---|---|---|---:|---|---:|---|---:|---:|---:|---:|")
    rows = []
    for r in results:  # each row as it comes
        rows.append(r)
        bf, bu = float(r["best_field"]), float(r["best_unseen_d"])  # type: ignore[arg-type]
        print(
            f"| {r['seed']} | {r['lens']} | {r['strings']} | {r['plain']} | {r['plain field']:.4f} | {r['separated']} | "
            f"{r['separated field']:.4f} | {r['best']} | {bf:.4f} | {float(r['plain field']) / bf:.3f} / "  # type: ignore[arg-type]
            f"{float(r['separated field']) / bf:.3f} | {float(r['plain unseen']) / bu:.3f} / "  # type: ignore[arg-type]
            f"{float(r['separated unseen']) / bu:.3f} | {r['t plain']:.0f} / {r['t separated']:.0f} |",  # type: ignore[arg-type]
            flush=True,
        )
    print()
    for key, name in (("plain", "plain folds"), ("separated", "strings separated")):
        fr = np.array([float(r[f"{key} field"]) / float(r["best_field"]) for r in rows])  # type: ignore[arg-type]
        ur = np.array([float(r[f"{key} unseen"]) / float(r["best_unseen_d"]) for r in rows])  # type: ignore[arg-type]
        print(
            f"{name}: field error over the best candidate's worst {fr.max():.3f}, median {np.median(fr):.3f}, "
            f"> 1.05 for {int(np.sum(fr > 1.05))} / {len(fr)}; unseen d (strings removed) worst {ur.max():.3f}, "
            f"median {np.median(ur):.3f}, > 1.05 for {int(np.sum(ur > 1.05))} / {len(ur)}"
        )
    for key, name in (
        ("lowest cv field", "for comparison, the lowest CV d of the separated folds (no one-SE rule)"),
        ("fixed field", f"for comparison, no choice ({SPEC.label})"),
    ):
        fr = np.array([float(r[key]) / float(r["best_field"]) for r in rows])  # type: ignore[arg-type]
        print(
            f"{name}: field error over the best candidate's worst {fr.max():.3f}, median {np.median(fr):.3f}, "
            f"> 1.05 for {int(np.sum(fr > 1.05))} / {len(fr)}"
        )
    sp = np.array([float(r["separated field"]) / float(r["plain field"]) for r in rows])  # type: ignore[arg-type]
    print(
        f"separated over plain choice, field error: lower by > 5 % for {int(np.sum(sp < 0.95))}, within 5 % for "
        f"{int(np.sum(np.abs(sp - 1) <= 0.05))}, higher by > 5 % for {int(np.sum(sp > 1.05))} of {len(sp)}; "
        f"median choice time plain {np.median([float(r['t plain']) for r in rows]):.0f} s, separated "  # type: ignore[arg-type]
        f"{np.median([float(r['t separated']) for r in rows]):.0f} s"  # type: ignore[arg-type]
    )


def widened(harp: Harp, extra: int) -> Harp:
    """``harp`` with ``extra`` copies of its strings (shapes and all) added on each side at its pitch."""
    n, p = len(harp.strings), harp.spacing_px
    strings = tuple(
        dataclasses.replace(
            harp.strings[j % n], index=j + extra, position_px=harp.strings[j % n].position_px + (j - j % n) * p
        )
        for j in range(-extra, n + extra)
    )
    return Harp(strings, harp.spacing_px, harp.material, harp.mm_per_px, harp.tension_n, harp.transmission)


AXIS_SHIFTS = (0.0, 150.0, 300.0)


def exact_only(args: tuple[int, int, int]) -> dict[str, object]:
    seed, w, h = args
    lens, ses, row = seed_lens(seed, w, h)
    for off in AXIS_SHIFTS:
        harp = widened(ses.harp, int(off // ses.harp.spacing_px) + 1)
        c = ses.mount.centre
        moved = dataclasses.replace(ses, mount=dataclasses.replace(ses.mount, centre=(c[0] + off, c[1] + off / 2)))
        lines = exact_lines(lens, harp, moved, w, h)
        row[f"axis {off:.0f}"] = both(lines, lens, w, h, SPEC)
    kinks = reshaped(ses.harp, {k: v for k, v in STRAIGHT.items() if k != "kink_px"})
    lines = exact_lines(lens, kinks, ses, w, h)
    for robust in (True, False):
        fit = fit_distortion(lines, w, h, robust=robust, **SPEC.fit_arguments())
        row[f"kinks {robust}"] = (
            (compare_models(fit.model, lens, w, h, step=20).rms, len(fit.rejected)) if fit else None
        )
    return row


def print_exact(rows: Iterable[dict[str, object]]) -> None:
    print(
        "| seed | lens | strings | "
        + " | ".join(f"axis moved {off:.0f} px: lens alone / separated" for off in AXIS_SHIFTS)
        + " | kinks only, outlier edges rejected (edges) | kinks only, none rejected |"
    )
    print("|---:|---|---|" + "---:|" * (len(AXIS_SHIFTS) + 2))
    for r in rows:
        axis = " | ".join("{:.4f} / {:.4f}".format(*r[f"axis {off:.0f}"]) for off in AXIS_SHIFTS)  # type: ignore[str-format]
        k1, k0 = r["kinks True"], r["kinks False"]
        kink = f"{k1[0]:.4f} ({k1[1]}) | {k0[0]:.4f}" if k1 and k0 else "failed | failed"  # type: ignore[index]
        print(f"| {r['seed']} | {r['lens']} | {r['strings']} | {axis} | {kink} |", flush=True)


def kink_points(lines: list[list], model: DistortionModel, c: float, degree: int = 4) -> tuple[list[list], int]:
    """``lines`` without the points whose residual about ``model``, less its smooth trend along the edge,
    exceeds ``c`` robust standard deviations (module docstring); also how many were dropped."""
    detrended = []
    for shot in lines:
        per_shot = []
        for p in shot:
            u = model.undistort_points(p)
            m = u.mean(0)
            r = (u - m) @ np.linalg.svd(u - m, full_matrices=False)[2][1]
            s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])
            s = 2.0 * s / max(float(s[-1]), 1e-9) - 1.0
            if len(p) >= 3 * (degree + 1):
                v = np.polynomial.legendre.legvander(s, degree)
                r = r - v @ np.linalg.lstsq(v, r, rcond=None)[0]
            else:
                r = np.zeros_like(r)
            per_shot.append(r)
        detrended.append(per_shot)
    sigma = 1.4826 * float(np.median(np.abs(np.concatenate([r for shot in detrended for r in shot]))))
    out, dropped = [], 0
    for shot, rs in zip(lines, detrended, strict=True):
        keep = [np.abs(r) <= c * sigma for r in rs]
        dropped += sum(int(np.sum(~k)) for k in keep)
        out.append([p[k] for p, k in zip(shot, keep, strict=True) if np.sum(k) >= 5])
    return out, dropped


KINK_C = (5.0, 8.0)


def kink_trim(args: tuple[int, int, int]) -> dict[str, object]:
    seed, w, h = args
    lens, ses, row = seed_lens(seed, w, h)
    shots = render_shots(lens, ses.harp, ses.mount, FITTED, w, h, ses.effects, seed=seed)
    lines = [[ln.points for ln in measure_image(s.image).lines] for s in shots]
    row["n"] = sum(len(p) for shot in lines for p in shot)
    plain = fit_distortion(lines, w, h, **SPEC.fit_arguments())
    row["base"] = (
        field(lines, lens, w, h, SPEC, joint=False, plain=plain),
        field(lines, lens, w, h, SPEC, plain=plain),
    )
    for c in KINK_C:
        if not plain:
            row[c] = None
            continue
        kept, dropped = kink_points(lines, plain.model, c)
        row[c] = (*both(kept, lens, w, h, SPEC), dropped)
    return row


def print_kink_trim(rows: Iterable[dict[str, object]]) -> None:
    print(
        "| seed | lens | strings | points | lens alone / separated | "
        + " | ".join(f"points > {c:g} sigma dropped: lens alone / separated (dropped)" for c in KINK_C)
        + " |"
    )
    print("|---:|---|---|---:|---:|" + "---:|" * len(KINK_C))
    for r in rows:
        cells = " | ".join("{:.4f} / {:.4f} ({})".format(*r[c]) if r[c] else "failed" for c in KINK_C)  # type: ignore[str-format]
        print(
            f"| {r['seed']} | {r['lens']} | {r['strings']} | {r['n']} | {{:.4f}} / {{:.4f}}".format(*r["base"])
            + f" | {cells} |",  # type: ignore[str-format]
            flush=True,
        )


def point_robust(args: tuple[int, int, int, Path | None]) -> dict[str, object]:
    seed, w, h, cache = args
    lens, ses, row = seed_lens(seed, w, h)
    row["kinks"] = sum(1 for s in ses.harp.strings if s.kink_px != 0.0)
    lines, _, sigmas = realistic_measured(seed, w, h, cache)
    for name, _ in POINT_LOSS_ROWS:
        plain = fit_loss(lines, sigmas, name, w, h, SPEC)
        row[name] = (
            field(lines, lens, w, h, SPEC, joint=False, plain=plain),
            field(lines, lens, w, h, SPEC, plain=plain),
        )
    return row


def print_point_robust(rows: Iterable[dict[str, object]]) -> None:
    print(
        "| seed | lens | strings | kinked strings | "
        + " | ".join(f"point loss {n}: lens alone / separated" for n, _ in POINT_LOSS_ROWS)
        + " |"
    )
    print("|---:|---|---|---:|" + "---:|" * len(POINT_LOSS_ROWS))
    for r in rows:
        cells = " | ".join("{:.4f} / {:.4f}".format(*r[n]) for n, _ in POINT_LOSS_ROWS)  # type: ignore[str-format]
        print(f"| {r['seed']} | {r['lens']} | {r['strings']} | {r['kinks']} | {cells} |", flush=True)


def kink_truth(fit: Any, harp: Harp, ses: Session) -> tuple[int, int, int, int, float, list[float]]:
    """How many kinks ``fit`` modelled on a string that has one within 24 px (one smoothing sigma) of its place
    (harp coordinates of the drawing: strings matched by their distance from the axis, the sense of ``a`` and
    ``b`` from the frame's direction), how many elsewhere, how many drawn kinks lie on strings the fit saw in
    two shots or more, inside the stretch they show, how many of those were found, and the largest detection
    significance ``|z|`` of a kink modelled elsewhere (0 when none: with ``--kink-z 3``, how high the scan goes
    on strings without a kink, what ``pipeline.harp_kinks.KINK_Z`` was set from), and for each true one its fitted
    area over the drawn cusp's, :math:`2h\\lambda` (sign included)."""
    sense = 1 if np.dot(fit.frame.direction(0.0), ses.mount.pose(0.0).direction) > 0 else -1
    pos = np.array([st.position_px for st in harp.strings])
    by_index = {x.index: x for x in fit.strings}
    true = false = 0
    false_z = 0.0
    areas: list[float] = []
    hit: set[int] = set()
    for k in fit.kinks:
        j = int(np.argmin(np.abs(pos - sense * by_index[k.string].offset_px)))
        st = harp.strings[j]
        if st.kink_px != 0.0 and abs(sense * k.at_px - st.kink_at_px) < 24.0:
            true += 1
            hit.add(j)
            areas.append(sense * k.area_px2 / (2.0 * st.kink_px * st.kink_length_px))
        else:
            false += 1
            false_z = max(false_z, abs(k.z))
    seen = 0
    for x in fit.strings:
        j = int(np.argmin(np.abs(pos - sense * x.offset_px)))
        st = harp.strings[j]
        a = sense * st.kink_at_px / fit.frame.scale_px
        if st.kink_px != 0.0 and x.shots >= 2 and x.span[0] + 0.05 <= a <= x.span[1] - 0.05:
            seen += 1
    return true, false, seen, len(hit), false_z, areas


def kink_fields(
    lines: list[list], lens: DistortionModel, harp: Harp, ses: Session, w: int, h: int, z: float
) -> dict[str, Any]:
    """Field errors of the separated fit without and with the kinks of significance ``z`` or more modelled, and
    :func:`kink_truth`."""
    plain = fit_distortion(lines, w, h, **SPEC.fit_arguments())
    if not plain:
        return {"failed": plain.reason}
    t0 = time.perf_counter()
    sep = fit_harp_shape(lines, FITTED, w, h, SPEC, plain=plain)
    t1 = time.perf_counter()
    kinked = fit_harp_shape(lines, FITTED, w, h, SPEC, plain=plain, kinks=True, kink_z=z)
    t2 = time.perf_counter()
    if not sep:
        return {"failed": sep.reason}
    if not kinked:
        return {"failed": kinked.reason}
    return {
        "without": float(compare_models(sep.model, lens, w, h, step=20).rms),
        "with": float(compare_models(kinked.model, lens, w, h, step=20).rms),
        "truth": kink_truth(kinked, harp, ses),
        "t": (t1 - t0, t2 - t1),
    }


def kinks_realistic(args: tuple[int, int, int, Path | None, float]) -> dict[str, object]:
    """``--kinks``: the full realistic render, strings separated, without and with the kinks modelled."""
    seed, w, h, cache, z = args
    lens, ses, row = seed_lens(seed, w, h)
    row["kinks"] = sum(1 for s in ses.harp.strings if s.kink_px != 0.0)
    lines, _, _ = realistic_measured(seed, w, h, cache)
    row |= kink_fields(lines, lens, ses.harp, ses, w, h, z)
    return row


def smoothed(lines: list[list]) -> list[list]:
    """Exact edges smoothed along themselves as ``harp measure`` does (``pipeline.resample.smooth_subsample``,
    t = 30, 1 px samples): what a noise-free measurement gives."""
    return [[smooth_subsample(p, t=DEFAULT_T) for p in shot] for shot in lines]


KINK_NOISE_PX = 0.003
"""Noise per point added to the smoothed exact points in ``--kinks-exact`` (what the smoothing leaves of a
measurement's noise, as ``tests/pipeline/harp_points.py``)."""


def kinks_exact(args: tuple[int, int, int, Path | None, float]) -> dict[str, object]:
    """``--kinks-exact``: exact points of the strings with their kinks alone (every other shape zero), smoothed
    as measured, fitted without and with the kinks modelled; the same with :data:`KINK_NOISE_PX` of noise."""
    seed, w, h, _, z = args
    lens, ses, row = seed_lens(seed, w, h)
    row["kinks"] = sum(1 for s in ses.harp.strings if s.kink_px != 0.0)
    harp = reshaped(ses.harp, {k: v for k, v in STRAIGHT.items() if k != "kink_px"})
    lines = smoothed(exact_lines(lens, harp, ses, w, h))
    row["exact"] = kink_fields(lines, lens, harp, ses, w, h, z)
    rng = np.random.default_rng(seed)
    noisy = [[p + rng.normal(0.0, KINK_NOISE_PX, p.shape) for p in shot] for shot in lines]
    row["noisy"] = kink_fields(noisy, lens, harp, ses, w, h, z)
    return row


def kink_cells(r: dict[str, Any]) -> str:
    """A row's cells: field without / with, kinks modelled true / false, drawn ones seen / found."""
    if "failed" in r:
        return "failed | | | "
    true, false, seen, hit, false_z, _ = r["truth"]
    return f"{r['without']:.4f} / {r['with']:.4f} | {true} / {false} | {false_z:.1f} | {seen} / {hit}"


def kink_summary(results: list[dict[str, Any]], name: str) -> None:
    """Counts at or below 0.005 px, better / worse by more than 5 %, worst ratio, kinks true / false."""
    ok = [r for r in results if "failed" not in r]
    a = np.array([(r["without"], r["with"]) for r in ok])
    ratio = a[:, 1] / a[:, 0]
    tf = np.array([r["truth"][:5] for r in ok])
    areas = np.array([v for r in ok for v in r["truth"][5]])
    print(
        f"{name}: at or below 0.005 px {int(np.sum(a[:, 0] <= 0.005))} -> {int(np.sum(a[:, 1] <= 0.005))} of "
        f"{len(a)} ({len(results) - len(ok)} failed); median {np.median(a[:, 0]):.4f} -> {np.median(a[:, 1]):.4f} "
        f"px; lower by > 5 % for {int(np.sum(ratio < 0.95))}, higher by > 5 % for {int(np.sum(ratio > 1.05))} "
        f"(worst ratio {ratio.max():.3f}, largest rise {np.max(a[:, 1] - a[:, 0]):+.4f} px); kinks modelled "
        f"{tf[:, 0].sum():.0f} true, {tf[:, 1].sum():.0f} false (largest |z| of a false one {tf[:, 4].max():.1f}); "
        f"drawn kinks seen twice {tf[:, 2].sum():.0f}, found {tf[:, 3].sum():.0f}"
    )
    if len(areas):
        q = np.percentile(areas, [0, 10, 50, 90, 100])
        print(
            f"  true kinks' fitted area over the drawn 2 h lambda: median {q[2]:.2f}, 10-90 % {q[1]:.2f}-{q[3]:.2f}, "
            f"range {q[0]:.2f}-{q[4]:.2f}, within 30 % for {int(np.sum(np.abs(areas - 1) <= 0.3))} of {len(areas)}"
        )


KINK_HEAD = (
    "field without / with kinks px | kinks modelled: true / false | largest z of a false one | "
    "drawn kinks seen twice / found"
)


def print_kinks(rows: Iterable[dict[str, Any]]) -> None:
    print(f"| seed | lens | strings | kinked strings | {KINK_HEAD} | s without / with |")
    print("|---:|---|---|---:|---:|---:|---:|---:|---:|")
    done = []
    for r in rows:
        done.append(r)
        t = "{:.1f} / {:.1f}".format(*r["t"]) if "t" in r else ""
        print(f"| {r['seed']} | {r['lens']} | {r['strings']} | {r['kinks']} | {kink_cells(r)} | {t} |", flush=True)
    print()
    kink_summary(done, "strings separated, kinks modelled")


def print_kinks_exact(rows: Iterable[dict[str, Any]]) -> None:
    print(
        f"| seed | lens | strings | kinked strings | exact kinks, smoothed: {KINK_HEAD} | "
        f"+ {KINK_NOISE_PX:g} px noise: {KINK_HEAD} |"
    )
    print("|---:|---|---|---:|" + "---:|" * 8)
    done = []
    for r in rows:
        done.append(r)
        print(
            f"| {r['seed']} | {r['lens']} | {r['strings']} | {r['kinks']} | {kink_cells(r['exact'])} | "
            f"{kink_cells(r['noisy'])} |",
            flush=True,
        )
    print()
    for key in ("exact", "noisy"):
        kink_summary([r[key] for r in done], key)


EXACT_NOISE_PX = 0.02
"""Noise added to the exact points in ``--point-robust-exact`` (px, per point, independent): enough to lift
the median edge RMS as a real measurement's noise and bows do, so that whole kinked edges no longer stand out."""


def point_robust_exact(args: tuple[int, int, int]) -> dict[str, object]:
    seed, w, h = args
    lens, ses, row = seed_lens(seed, w, h)
    row["kinks"] = sum(1 for s in ses.harp.strings if s.kink_px != 0.0)
    kinks = exact_lines(lens, reshaped(ses.harp, {k: v for k, v in STRAIGHT.items() if k != "kink_px"}), ses, w, h)
    straight = exact_lines(lens, reshaped(ses.harp, STRAIGHT), ses, w, h)
    rng = np.random.default_rng(seed)
    noisy = [[p + rng.normal(0.0, EXACT_NOISE_PX, p.shape) for p in shot] for shot in kinks]
    noisy_straight = [[p + rng.normal(0.0, EXACT_NOISE_PX, p.shape) for p in shot] for shot in straight]
    for tag, pts in (("exact", kinks), ("noisy", noisy)):
        for name, kw in POINT_LOSS_ROWS[:2]:
            fit = fit_distortion(pts, w, h, **kw, **SPEC.fit_arguments())  # type: ignore[arg-type]
            row[f"{tag} {name}"] = field(pts, lens, w, h, SPEC, joint=False, plain=fit)
    row["noisy straight"] = field(noisy_straight, lens, w, h, SPEC, joint=False)
    return row


def print_point_robust_exact(rows: Iterable[dict[str, object]]) -> None:
    print(
        "| seed | lens | strings | kinked strings | exact kinks: point loss edges / tukey | "
        f"kinks + {EXACT_NOISE_PX:g} px noise: edges / tukey | straight + {EXACT_NOISE_PX:g} px noise: edges |"
    )
    print("|---:|---|---|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['seed']} | {r['lens']} | {r['strings']} | {r['kinks']} | {r['exact none']:.4f} / "
            f"{r['exact tukey']:.4f} | {r['noisy none']:.4f} / {r['noisy tukey']:.4f} | {r['noisy straight']:.4f} |",
            flush=True,
        )


COLUMNS = (
    ("full alone", "full, lens alone"),
    ("full", "full"),
    ("straight", "straight strings"),
    ("no kinks", "no kinks"),
    ("uniform blur", "uniform blur"),
    ("no Bayer", "no Bayer"),
    ("no noise", "no noise"),
    ("flat light", "flat light"),
    ("linear tone", "linear tone"),
    ("exact bent", "exact points, bent"),
    ("exact straight r4", "exact points, straight"),
    ("exact straight r6", "exact straight, radial6+t+p (lens alone)"),
)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="38,37,39,6,16")
    ap.add_argument("--size", default="1000x750")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--exact-only", action="store_true", help="print only the exact-point table (no rendering)")
    ap.add_argument("--kink-trim", action="store_true", help="print only the kinked-points prototype's table")
    ap.add_argument("--choice", action="store_true", help="print only the model choice's table (no ablations)")
    ap.add_argument("--stored", action="store_true", help="print only the table of the lens a session stores")
    ap.add_argument(
        "--point-robust",
        action="store_true",
        help="print only the per-point robust fit's table (fit_distortion point_loss)",
    )
    ap.add_argument(
        "--point-robust-exact", action="store_true", help="print only the per-point robust fit on exact kinked points"
    )
    ap.add_argument("--kinks", action="store_true", help="print only the kinks-modelled table (realistic shots)")
    ap.add_argument("--kinks-exact", action="store_true", help="print only the kinks-modelled table on exact points")
    ap.add_argument("--kink-z", type=float, default=KINK_Z, help="--kinks, --kinks-exact: the kinks' threshold")
    ap.add_argument(
        "--cache",
        type=Path,
        default=None,
        help="--choice, --stored, --point-robust, --kinks: directory keeping the measured edges (npz)",
    )
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    seeds = [int(s) for s in args.seeds.split(",")]
    cmd = " ".join(argv if argv is not None else sys.argv[1:])
    print(
        f"# What limits the field error: strings separated, radial4+tangential+prism unless said, {w}x{h}, six "
        f"shots ({os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}; `benchmarks/lens_limits.py {cmd}`)"
    )
    pool = ProcessPoolExecutor(max(1, args.workers))
    jobs = [(s, w, h) for s in seeds]
    cached = [(s, w, h, args.cache) for s in seeds]
    kink_jobs = [(s, w, h, args.cache, args.kink_z) for s in seeds]
    only: tuple[
        tuple[bool, Callable[[Any], dict[str, object]], list[Any], Callable[[Iterable[dict[str, object]]], None]], ...
    ] = (
        (args.kink_trim, kink_trim, jobs, print_kink_trim),
        (args.choice, choice, cached, print_choice),
        (args.stored, stored, cached, print_stored),
        (args.point_robust, point_robust, cached, print_point_robust),
        (args.point_robust_exact, point_robust_exact, jobs, print_point_robust_exact),
        (args.exact_only, exact_only, jobs, print_exact),
        (args.kinks, kinks_realistic, kink_jobs, print_kinks),
        (args.kinks_exact, kinks_exact, kink_jobs, print_kinks_exact),
    )
    for wanted, job, job_args, printer in only:
        if wanted:
            print()
            with pool:
                printer(pool.map(job, job_args))
            print(f"# load average at end {os.getloadavg()[0]:.1f}")
            return 0
    print()
    print("| seed | lens | strings | " + " | ".join(c for _, c in COLUMNS) + " | chosen model | chosen, px | s |")
    print("|---:|---|---|" + "---:|" * len(COLUMNS) + "---|---:|---:|")
    with pool:
        for r in pool.map(one, jobs):
            cells = " | ".join(f"{r[k]:.4f}" for k, _ in COLUMNS)
            print(
                f"| {r['seed']} | {r['lens']} | {r['strings']} | {cells} | {r['chosen']} | "
                f"{r['chosen field']:.4f} | {r['t']:.0f} |",
                flush=True,
            )
        print()
        print_exact(list(pool.map(exact_only, jobs)))
    print(f"# load average at end {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
