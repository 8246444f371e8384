"""``harp profile list | show LENS [--focus F] | export LENS --focus F --format ...``.

Reads the profile store: ``--store PATH|URL`` (a SQLite file or ``postgresql://``), or
``--config CONFIG`` (that station's store), else ``$HARP_STORE``, else
``profiles/harp-profiles.sqlite`` (:mod:`station.store.resolve`); a store that is not there is an
error, never created. LENS is a lens serial, ``maker/model/serial``, ``#id``, or any unambiguous
part of "maker model serial". ``export`` converts the newest profile at that focus (or the
correction interpolated between the calibrated focus settings) with the options,
figures and warnings of ``harp export`` (:mod:`station.cli.export`); the profile
brings the lens, camera body and optics of its session's configuration and the
session's measured edges of its fitting shots. Exit 0 on success, 2 on bad input or a damaged store.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

from station.cli.export import add_export_options, formats_epilog
from station.store.resolve import add_store_options


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "profile", help="list, show and export stored lens profiles", description=__doc__.split("\n\n")[1]
    )
    add_store_options(p)
    sub = p.add_subparsers(dest="profile_command", metavar="ACTION")
    store_opt = argparse.ArgumentParser(add_help=False)  # --store / --config also after the action
    add_store_options(store_opt, suppress=True)
    ls = sub.add_parser("list", help="every stored profile", parents=[store_opt])
    ls.set_defaults(func=_list)
    show = sub.add_parser("show", help="the profiles of one lens", parents=[store_opt])
    show.add_argument("lens", metavar="LENS")
    show.add_argument("--focus", type=float, default=None, help="one focus setting in detail")
    show.set_defaults(func=_show)
    ex = sub.add_parser(
        "export",
        help="export a lens profile for other software",
        parents=[store_opt],
        epilog=formats_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Export the newest profile of LENS at --focus (interpolated between calibrated focus "
        "settings when it is not one): the formats, options, figures and exit codes of harp export.",
    )
    ex.add_argument("lens", metavar="LENS")
    ex.add_argument("--focus", type=float, required=True)
    add_export_options(ex)
    ex.set_defaults(func=_export)
    p.set_defaults(func=lambda args: (p.print_help(sys.stderr), 2)[1])


class _Fail(Exception):
    """A one-line error for the user (printed by :func:`_error`, exit 2)."""


def _error(msg: str) -> int:
    print(f"harp profile: {msg}", file=sys.stderr)
    return 2


def _open(args):
    from station.store.resolve import open_store

    return open_store(args)  # for reading: never creates a store


def _console():
    from rich.console import Console

    return Console() if sys.stdout.isatty() else Console(width=160)


def _num(v, nd=4) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{nd}f}"


def _with_store(fn):
    def wrapped(args) -> int:
        from station.config import ConfigError
        from station.store import StoreError

        try:
            with _open(args) as store:
                return fn(args, store)
        except (StoreError, ConfigError, _Fail) as exc:
            return _error(str(exc))

    return wrapped


@_with_store
def _list(args, store) -> int:
    from rich.table import Table

    errors: list = []
    profiles = store.profiles(errors=errors)  # the readable rows; each damaged one reported below
    if not profiles and not errors:
        print(f"no profiles in {store.path}")
        return 0
    t = Table(title=f"profiles in {store.path}")
    for col in ("id", "lens", "camera", "focus", "model", "holdout d", "holdout d_max", "created", "station"):
        t.add_column(col, justify="right" if col in ("id", "focus", "holdout d", "holdout d_max") else "left")
    for p in profiles:
        hold = p.merit.holdout
        t.add_row(
            f"#{p.id}",
            _ident(p.lens),
            _ident(p.camera),
            f"{p.focus:g}",
            p.model.name,
            _num(hold.d if hold else None),
            _num(hold.d_max if hold else None),
            p.stored_at or "-",
            p.provenance.station or "-",
        )
    _console().print(t)
    for exc in errors:
        _error(str(exc))
    return 2 if errors else 0


def _ident(identity) -> str:
    return "-" if identity is None else f"{identity.maker} {identity.model} {identity.serial}"


def _select(store, lens_query: str, focus: float | None):
    lens = store.find_lens(lens_query)
    latest = store.latest_by_focus(lens[0])
    if focus is None:
        return lens, latest
    hits = [p for p in latest if math.isclose(p.focus, focus, rel_tol=0, abs_tol=1e-9)]
    if not hits:
        known = ", ".join(f"{p.focus:g}" for p in latest) or "none"
        raise _Fail(f"lens {' '.join(lens[1:])}: no profile at focus {focus:g} (calibrated focus settings: {known})")
    return lens, hits


def _interpolated(lens, profiles, focus: float):
    """The correction at an uncalibrated ``focus``: (model, width, height, note, loo)."""
    from pipeline.interpolate import FocusInterpolator, leave_one_out_error

    sizes = {(p.width, p.height) for p in profiles}
    if len(sizes) != 1:
        raise _Fail(f"lens {' '.join(lens[1:])}: profiles of different image sizes; cannot interpolate")
    ((w, h),) = sizes
    models = {p.focus: p.model for p in profiles}
    known = ", ".join(f"{p.focus:g}" for p in profiles)
    if len(models) < 2 or not min(models) < focus < max(models):
        raise _Fail(
            f"lens {' '.join(lens[1:])}: no profile at focus {focus:g} and it is not between "
            f"two calibrated focus settings ({known}); no extrapolation"
        )
    interp = FocusInterpolator(models, w, h)
    model = interp.at(focus)
    loo = leave_one_out_error(models, w, h)
    note = (
        f"focus {focus:g} is not calibrated: correction field interpolated "
        f"({getattr(interp, 'method', 'auto')}) between the calibrated settings {known}"
    )
    return model, w, h, note, loo


@_with_store
def _show(args, store) -> int:
    from rich.table import Table

    console = _console()
    if args.focus is not None:
        lens, latest = _select(store, args.lens, None)
        if not any(math.isclose(p.focus, args.focus, abs_tol=1e-9) for p in latest):
            model, w, h, note, loo = _interpolated(lens, latest, args.focus)
            console.print(f"lens #{lens[0]}: {lens[1]} {lens[2]} serial {lens[3]}, image {w}x{h}")
            console.print(note)
            for e in loo:
                console.print(
                    f"interpolation error measured by leaving focus {e.focus:g} out: "
                    f"RMS {e.rms_px:.4f} px, max {e.max_px:.4f} px (modulo homography)"
                )
            if not loo:
                console.print("interpolation error: not measurable (needs >= 3 calibrated settings)")
            return 0
    lens, profiles = _select(store, args.lens, args.focus)
    t = Table(title=f"lens #{lens[0]}: {lens[1]} {lens[2]} serial {lens[3]} (newest profile per focus)")
    for col in (
        "focus",
        "id",
        "camera",
        "model",
        "fit d",
        "fit d_max",
        "holdout d",
        "holdout d_max",
        "field unc. rms",
        "field unc. max",
        "created",
    ):
        t.add_column(col, justify="right")
    for p in profiles:
        fit, hold, unc = p.merit.fit, p.merit.holdout, p.merit.field_uncertainty
        t.add_row(
            f"{p.focus:g}",
            f"#{p.id}",
            _ident(p.camera),
            p.model.name,
            _num(fit.d if fit else None),
            _num(fit.d_max if fit else None),
            _num(hold.d if hold else None),
            _num(hold.d_max if hold else None),
            _num(unc.rms if unc else None),
            _num(unc.max if unc else None),
            p.stored_at or "-",
        )
    console.print(t)
    if args.focus is not None:
        p = profiles[0]
        console.print(
            f"image {p.width}x{p.height}, session {p.provenance.session_dir}, station {p.provenance.station}, "
            f"software {p.provenance.software_version}"
        )
        console.print_json(json.dumps(p.model.to_dict()))
    return 0


@_with_store
def _export(args, store) -> int:
    from station.cli.export import export_profile, report, write_output
    from station.cli.inputs import InputError
    from station.export_source import FittingEdges
    from station.profile import Merit, Profile, Provenance

    lens, latest = _select(store, args.lens, None)
    if not any(math.isclose(p.focus, args.focus, abs_tol=1e-9) for p in latest):
        model, w, h, note, loo = _interpolated(lens, latest, args.focus)
        nearest = min(latest, key=lambda p: abs(p.focus - args.focus))
        profile = Profile(
            model=model,
            width=w,
            height=h,
            merit=Merit(
                extra={
                    "interpolation_leave_one_out": [
                        {"focus": e.focus, "rms_px": e.rms_px, "max_px": e.max_px} for e in loo
                    ]
                }
            ),
            lens=nearest.lens,
            camera=nearest.camera,
            optics=nearest.optics,
            focus=args.focus,
            provenance=Provenance(extra={"note": note, "from_profiles": [p.id for p in latest]}),
        )
        what = f"interpolated focus {args.focus:g}"
        known = ", ".join(f"{p.focus:g}" for p in latest)
        edges = FittingEdges(None, f"none: the correction is interpolated between the focus settings {known}")
    else:
        _lens, (profile,) = _select(store, args.lens, args.focus)
        what, edges = f"profile #{profile.id}", None
    try:
        ex, fig = export_profile(args, profile, what=what, edges=edges)
        write_output(args, ex)
    except InputError as exc:
        raise _Fail(str(exc)) from None
    report(args, ex, fig, "harp profile")
    return 0
