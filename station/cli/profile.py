"""``harp profile list | show LENS [--focus F] | show --id N | export LENS --focus F | export --id N``.

Reads the profile store: ``--store PATH|URL`` (a SQLite file or ``postgresql://``), or
``--config CONFIG`` (that station's store), else ``$HARP_STORE``, else ``$HARP_CONFIG``'s store, else
the per-user ``~/.local/share/harp-station/harp-profiles.sqlite`` (:mod:`station.cli.store_options`); a store that is not there is an
error, never created. LENS is a lens serial, ``maker/model/serial``, ``#id``, or any unambiguous
part of "maker model serial"; ``--id N`` names one stored profile. The **current** profile of a
lens at a focus setting is its newest one, unless that one failed QA: a failed profile is never
current (:meth:`station.store.database.ProfileStore.latest_by_focus`; what a command uses and
why, and the focus interpolation: :mod:`station.profile_choice`). ``show`` and ``export`` use
only current profiles, for one focus setting or the correction interpolated between the
calibrated ones, unless ``--allow-failed`` is given (then each failed profile used is said on
stderr). ``export`` converts with the options, figures and warnings of ``harp export``
(:mod:`station.cli.export`); the profile brings the lens, camera body and optics of its
session's configuration and the session's measured edges of its fitting shots. ``--json``
prints one JSON object; off a terminal the tables are tab-separated text with a header.
``show --id N`` (and ``show LENS --focus F``) prints the profile's table, its image size,
session, station and software, every QA check and its model on stdout; stderr has only warnings.
Exit 0 on success; 1 when the profile asked for failed QA (``export``, ``show --focus``: one line
naming the lens, focus and failed check; ``--allow-failed`` to use it anyway); 2 on bad input or
a damaged store.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

from pipeline.plain import plain
from station.cli.commands import COMMANDS
from station.cli.export import ExportError, add_export_options, export_profile, formats_epilog, report, write_output
from station.cli.say import say, warn
from station.cli.store_options import add_store_options, open_store
from station.errors import HarpError, InputError
from station.exit_codes import EXIT_ERROR, EXIT_FAIL, EXIT_OK
from station.profile_choice import (
    at_focus,
    at_setting,
    current_and_left_out,
    export_refusal,
    failed_line,
    failed_stamp,
    interpolate,
    interpolate_zoom,
    is_failed,
    is_zoom,
    lens_row,
    setting_text,
    verdict_text,
)
from station.store import StoreError
from station.tables import console as text_console
from station.tables import is_terminal, print_table

ALLOW_FAILED_HELP = "also use profiles that failed QA (each one is said on stderr)"
FOCAL_HELP = (
    "a zoom lens's focal length setting (mm), with --focus (interpolated in both if needed); lensfun "
    "export of a zoom lens without it: one calibration per calibrated focal length"
)


def register(subparsers) -> None:
    p = subparsers.add_parser("profile", help=COMMANDS["profile"], description=__doc__.split("\n\n")[1])
    add_store_options(p)
    sub = p.add_subparsers(dest="profile_command", metavar="ACTION")
    store_opt = argparse.ArgumentParser(add_help=False)  # --store / --config also after the action
    add_store_options(store_opt, suppress=True)
    ls = sub.add_parser(
        "list", help="every stored profile, with its verdict and whether it is current", parents=[store_opt]
    )
    ls.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    ls.set_defaults(func=_list)
    show = sub.add_parser("show", help="the current profiles of one lens (or one profile by --id)", parents=[store_opt])
    show.add_argument("lens", metavar="LENS", nargs="?", default=None)
    show.add_argument("--focus", type=float, default=None, help="one focus setting in detail (interpolated if needed)")
    show.add_argument("--zoom-mm", dest="focal", type=float, default=None, metavar="MM", help=FOCAL_HELP)
    show.add_argument("--id", type=int, default=None, metavar="N", help="the stored profile #N, whatever its verdict")
    show.add_argument("--allow-failed", action="store_true", help=ALLOW_FAILED_HELP)
    show.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    show.set_defaults(func=_show)
    ex = sub.add_parser(
        "export",
        help="export a lens profile for other software",
        parents=[store_opt],
        epilog=formats_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Export the current profile of LENS at --focus (interpolated between calibrated focus "
        "settings when it is not one), or the stored profile --id N: the formats, options, figures and exit "
        "codes of harp export. A profile that failed QA is refused (exit 1) unless --allow-failed.",
    )
    ex.add_argument("lens", metavar="LENS", nargs="?", default=None)
    ex.add_argument("--focus", type=float, default=None, help="the focus setting (with LENS)")
    ex.add_argument("--zoom-mm", dest="focal", type=float, default=None, metavar="MM", help=FOCAL_HELP)
    ex.add_argument("--id", type=int, default=None, metavar="N", help="export the stored profile #N")
    ex.add_argument("--allow-failed", action="store_true", help="export a profile that failed QA (said on stderr)")
    add_export_options(ex)
    ex.set_defaults(func=_export)
    p.set_defaults(func=lambda args: (p.print_help(sys.stderr), EXIT_ERROR)[1])


class _Refused(HarpError):
    """A profile that failed QA was asked for without ``--allow-failed`` (one line, exit 1)."""

    exit_code = EXIT_FAIL


def _error(msg: str) -> None:
    """A damaged row of the store, on stderr; the others are still listed (exit 2 at the end)."""
    say("harp profile", msg)


def _warn(msg: str) -> None:
    warn("harp profile", msg)


def _open(args):
    return open_store(args, prog="harp profile")  # for reading: never creates a store


def _num(v, nd=4) -> str:
    return "" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{nd}f}"


def _with_store(fn):
    """``fn(args, store)`` with the store open; its errors (a StoreError, ConfigError, ChoiceError:
    exit 2; FailedQA: exit 1) are one line each, printed by :func:`station.cli.main`."""

    def wrapped(args) -> int:
        with _open(args) as store:
            return fn(args, store)

    return wrapped


# ------------------------------------------------------------------ helpers
def _ident(identity) -> str:
    return "-" if identity is None else f"{identity.maker} {identity.model} {identity.serial}"


def _profile_json(p, current: bool | None = None) -> dict[str, Any]:
    """One stored profile as plain data (``--json``)."""
    fit, hold, unc = p.merit.fit, p.merit.holdout, p.merit.field_uncertainty
    ident = lambda i: None if i is None else {"maker": i.maker, "model": i.model, "serial": i.serial}  # noqa: E731
    return plain(
        {
            "id": p.id,
            "lens": ident(p.lens),
            "camera": ident(p.camera),
            "focus": p.focus,
            "focal": p.focal,
            "intrinsics": p.intrinsics.to_dict() if p.intrinsics is not None else None,
            "width": p.width,
            "height": p.height,
            "model": p.model.name,
            "spec": p.spec.label if p.spec is not None else None,
            "fit": fit.to_dict() if fit else None,
            "holdout": hold.to_dict() if hold else None,
            "field_uncertainty": unc.to_dict() if unc else None,
            "verdict": verdict_text(p) or None,
            "current": current,
            "qa": p.qa.to_dict() if p.qa is not None else None,
            "created": p.stored_at,
            "station": p.provenance.station,
            "session_dir": p.provenance.session_dir,
            "software_version": p.provenance.software_version,
        }
    )


def _say_used(lens, used, left_out) -> None:
    for p in used:
        if is_failed(p):
            _warn(f"{failed_line(lens, p)}: used because of --allow-failed")
    for p in left_out:
        say("harp profile", f"{failed_line(lens, p)}: not current, left out (--allow-failed uses it)")


# --------------------------------------------------------------------- list
@_with_store
def _list(args, store) -> int:
    errors: list = []
    profiles = store.profiles(errors=errors)  # the readable rows; each damaged one reported below
    current: set[int] = set()
    for lens in store.lenses():
        try:
            current.update(p.id for p in store.latest_by_focus(lens[0]))
        except StoreError:
            pass  # a damaged row of this lens: reported with the listing's errors
    if args.json:
        out = {
            "store": str(store.path),
            "profiles": [_profile_json(p, p.id in current) for p in profiles],
            "errors": [str(e) for e in errors],
        }
        print(json.dumps(out, indent=1))
    elif not profiles and not errors:
        say("harp profile", f"no profiles in {store.path}")
        return EXIT_OK
    else:
        rows = []
        for p in profiles:
            hold = p.merit.holdout
            dist = (p.qa.metrics if p.qa is not None else {}).get("distortion_max_px")
            rows.append(
                (
                    f"#{p.id}",
                    _ident(p.lens),
                    _ident(p.camera),
                    f"{p.focus:g}",
                    p.model.name,
                    verdict_text(p),
                    "yes" if p.id in current else "no",
                    _num(hold.d if hold else None),
                    _num(hold.d_max if hold else None),
                    _num(dist, 2),
                    p.stored_at or "",
                    p.provenance.station or "",
                )
            )
        columns = (
            "id",
            "lens",
            "camera",
            "focus",
            "model",
            "verdict",
            "current",
            "holdout d (px)",
            "holdout d_max (px)",
            "distortion max (px)",
            "created (UTC)",
            "station",
        )
        print_table(
            columns,
            rows,
            title=f"profiles in {store.path}",
            right=("id", "focus", "holdout d (px)", "holdout d_max (px)", "distortion max (px)"),
        )
    for exc in errors:
        _error(str(exc))
    return EXIT_ERROR if errors else EXIT_OK


# --------------------------------------------------------------------- show
PROFILE_COLUMNS = (
    "focus",
    "id",
    "verdict",
    "camera",
    "model",
    "fit d (px)",
    "fit d_max (px)",
    "holdout d (px)",
    "holdout d_max (px)",
    "field unc. rms (px)",
    "field unc. max (px)",
    "created (UTC)",
)


def _profile_row(p) -> tuple[str, ...]:
    fit, hold, unc = p.merit.fit, p.merit.holdout, p.merit.field_uncertainty
    return (
        f"{p.focus:g}",
        f"#{p.id}",
        verdict_text(p),
        _ident(p.camera),
        p.model.name,
        _num(fit.d if fit else None),
        _num(fit.d_max if fit else None),
        _num(hold.d if hold else None),
        _num(hold.d_max if hold else None),
        _num(unc.rms if unc else None),
        _num(unc.max if unc else None),
        p.stored_at or "",
    )


@_with_store
def _show(args, store) -> int:
    if args.id is not None:
        if args.lens is not None or args.focus is not None:
            raise HarpError("--id N names one profile: give no LENS or --focus with it")
        p = store.profile(args.id)
        if p is None:
            raise HarpError(f"no profile #{args.id} in {store.path}")
        lens = lens_row(p)
        if is_failed(p):
            _warn(f"{failed_line(lens, p)}: it is not a current profile")
        return _print_profiles(args, lens, [p], [], detail=True)
    if args.lens is None:
        raise HarpError("name a LENS (serial, maker/model/serial, #lens-id) or a profile with --id N")
    lens = store.find_lens(args.lens)
    used, left_out = current_and_left_out(store, lens[0], args.allow_failed)
    zoom = _zoom_setting(args, lens, used + left_out)
    if args.focus is None:
        _say_used(lens, used, left_out)
        return _print_profiles(args, lens, used, left_out)
    if zoom:
        return _show_zoom(args, lens, used, left_out)
    p = at_focus(used, args.focus)
    if p is not None:
        _say_used(lens, [p], [])
        return _print_profiles(args, lens, [p], [], detail=True)
    failed_here = at_focus(left_out, args.focus)
    if failed_here is not None:
        raise _Refused(f"{failed_line(lens, failed_here)}: no current profile at this focus (--allow-failed shows it)")
    interp = interpolate(lens, used, args.focus, left_out)
    model, w, h, note, loo = interp.model, interp.width, interp.height, interp.note, interp.leave_one_out
    _say_used(lens, used, left_out)
    if args.json:
        out = {
            "lens": {"id": lens[0], "maker": lens[1], "model": lens[2], "serial": lens[3]},
            "focus": args.focus,
            "interpolated": {
                "method": interp.method,
                "note": note,
                "from_profiles": [q.id for q in used],
                "width": w,
                "height": h,
                "leave_one_out": [{"focus": e.focus, "rms_px": e.rms_px, "max_px": e.max_px} for e in loo],
                "model": model.to_dict(),
            },
            "left_out": [_profile_json(q, False) for q in left_out],
        }
        print(json.dumps(plain(out), indent=1))
        return EXIT_OK
    console = text_console()
    console.print(f"lens #{lens[0]}: {lens[1]} {lens[2]} serial {lens[3]}, image {w}x{h}")
    console.print(note)
    for e in loo:
        console.print(
            f"interpolation error measured by leaving focus {e.focus:g} out: "
            f"RMS {e.rms_px:.4f} px, max {e.max_px:.4f} px (modulo homography)"
        )
    if not loo:
        console.print("interpolation error: not measurable (needs >= 3 calibrated settings)")
    return EXIT_OK


def _zoom_setting(args, lens, profiles) -> bool:
    """Whether the lens is a zoom lens (its profiles record focal lengths); a setting asked for it
    needs both --zoom-mm and --focus, and --zoom-mm is refused for a fixed lens."""
    zoom = is_zoom(profiles)
    if getattr(args, "focal", None) is not None and not zoom:
        raise HarpError(f"{lens_label_of(lens)} has no focal length settings (not a zoom lens): give no --zoom-mm")
    if zoom and args.focus is not None and args.focal is None:
        raise HarpError(f"{lens_label_of(lens)} is a zoom lens: give --zoom-mm MM with --focus")
    if zoom and args.focal is not None and args.focus is None:
        raise HarpError("--zoom-mm needs --focus D (the setting is a focal length and a focus)")
    return zoom


def lens_label_of(lens) -> str:
    return f"lens {lens[1]} {lens[2]} serial {lens[3]}"


def _show_zoom(args, lens, used, left_out) -> int:
    p = at_setting(used, args.focal, args.focus)
    if p is not None:
        _say_used(lens, [p], [])
        return _print_profiles(args, lens, [p], [], detail=True)
    failed_here = at_setting(left_out, args.focal, args.focus)
    if failed_here is not None:
        raise _Refused(
            f"{failed_line(lens, failed_here)}: no current profile at this setting (--allow-failed shows it)"
        )
    interp = interpolate_zoom(lens, used, args.focal, args.focus, left_out)
    _say_used(lens, used, left_out)
    if args.json:
        out = {
            "lens": {"id": lens[0], "maker": lens[1], "model": lens[2], "serial": lens[3]},
            "focal": args.focal,
            "focus": args.focus,
            "interpolated": {
                "method": interp.method,
                "note": interp.note,
                "from_profiles": [q.id for q in interp.from_profiles],
                "width": interp.width,
                "height": interp.height,
                "leave_one_out": interp.loo_rows(),
                "model": interp.model.to_dict(),
            },
            "left_out": [_profile_json(q, False) for q in left_out],
        }
        print(json.dumps(plain(out), indent=1))
        return EXIT_OK
    console = text_console()
    console.print(f"lens #{lens[0]}: {lens[1]} {lens[2]} serial {lens[3]}, image {interp.width}x{interp.height}")
    console.print(interp.note)
    for e in interp.leave_one_out:
        console.print(
            f"interpolation error along the {e.axis}, leaving {setting_text(e.focal, e.focus)} out: "
            f"RMS {e.rms_px:.4f} px, max {e.max_px:.4f} px (modulo homography)"
        )
    axes = {e.axis for e in interp.leave_one_out}
    for axis, need in (("focal", "3 focal lengths"), ("focus", "3 focus settings at a focal length")):
        if axis not in axes:
            console.print(f"interpolation error along the {axis}: not measurable (needs {need})")
    return EXIT_OK


def _print_profiles(args, lens, profiles, left_out, *, detail: bool = False) -> int:
    if args.json:
        out = {
            "lens": {"id": lens[0], "maker": lens[1], "model": lens[2], "serial": lens[3]},
            "profiles": [_profile_json(p, not is_failed(p) if not detail else None) for p in profiles],
            "left_out": [_profile_json(p, False) for p in left_out],
        }
        if detail:
            out["profiles"][0]["model_parameters"] = plain(profiles[0].model.to_dict())
            if profiles[0].details.get("colour"):  # a colour camera's TCA and vignetting, as stored
                out["profiles"][0]["colour"] = plain(dict(profiles[0].details["colour"]))
        print(json.dumps(out, indent=1))
        return EXIT_OK
    who = f"lens #{lens[0]}: " if lens[0] is not None else "lens "
    zoom = is_zoom(profiles)
    columns = (("focal (mm)",) if zoom else ()) + PROFILE_COLUMNS
    print_table(
        columns,
        [((f"{p.focal:g}" if p.focal is not None else "",) if zoom else ()) + _profile_row(p) for p in profiles],
        title=f"{who}{lens[1]} {lens[2]} serial {lens[3]}"
        + ("" if detail else " (current profile per focal and focus)" if zoom else " (current profile per focus)"),
        right=(("focal (mm)",) if zoom else ()) + PROFILE_COLUMNS[:2] + PROFILE_COLUMNS[5:11],
    )
    if detail:  # the profile itself, on stdout with its table (warnings alone go to stderr)
        p = profiles[0]
        if not is_terminal():
            print()  # off a terminal a blank line after the table
        print(
            f"image {p.width}x{p.height}, session {p.provenance.session_dir}, station {p.provenance.station}, "
            f"software {p.provenance.software_version}"
        )
        for c in p.qa.checks if p.qa is not None else ():
            print(f"check: {c.text}")
        if p.intrinsics is not None:
            print(p.intrinsics.statement())
        if p.details.get("colour"):
            # defers pipeline.cfa, pipeline.vignetting: only a colour profile loads them
            from station.session.colour import colour_summary

            for what, cell in colour_summary(p.details["colour"]).items():
                print(f"{what}: {cell}")
        print(json.dumps(plain(p.model.to_dict())))
    return EXIT_OK


# ------------------------------------------------------------------- export
def _allowed(args, lens, p) -> None:
    """Refuse a profile that failed QA (exit 1) unless ``--allow-failed`` (then say so)."""
    refusal = export_refusal(lens, p, "--allow-failed")
    if refusal is None:
        return
    if not args.allow_failed:
        raise _Refused(refusal)
    _warn(f"{failed_line(lens, p)}: exported because of --allow-failed (the file is stamped FAILED QA)")


@_with_store
def _export(args, store) -> int:
    from station.export_source import FittingEdges  # defers scipy

    edges = stamp = None
    if args.id is not None:
        if args.lens is not None or args.focus is not None or args.focal is not None:
            raise HarpError("--id N names one profile: give no LENS, --focus or --zoom-mm with it")
        profile = store.profile(args.id)
        if profile is None:
            raise HarpError(f"no profile #{args.id} in {store.path}")
        _allowed(args, lens_row(profile), profile)
        what = f"profile #{profile.id}"
    else:
        if args.lens is None or args.focus is None:
            raise HarpError("name LENS and --focus F, or a stored profile with --id N")
        lens = store.find_lens(args.lens)
        newest = store.latest_by_focus(lens[0], allow_failed=True)
        if is_zoom(newest) and args.focal is None and args.format in ("lensfun", "lcp"):
            return _export_lensfun_zoom(args, store, lens)
        if _zoom_setting(args, lens, newest):
            return _export_zoom(args, store, lens, newest)
        hit = at_focus(newest, args.focus)
        if hit is not None:
            _allowed(args, lens, hit)
            profile, what = hit, f"profile #{hit.id}"
        else:
            used, left_out = current_and_left_out(store, lens[0], args.allow_failed)
            interp = interpolate(lens, used, args.focus, left_out)
            _say_used(lens, used, left_out)
            profile = interp.profile()
            stamp = tuple(line for q in used for line in failed_stamp(q))  # interpolated from failed ones
            what = f"interpolated focus {args.focus:g}"
            edges = FittingEdges(
                None, f"none: the correction is interpolated between the focus settings {interp.known()}"
            )
    return _write_profile(args, profile, what, edges, stamp)


def _write_profile(args, profile, what: str, edges, stamp) -> int:
    """Export ``profile`` (``what``: how it was found; ``edges``, ``stamp``: see :func:`export_profile`), write it
    where ``args`` asks and report it (HarpError for bad input)."""
    try:
        ex, fig = export_profile(args, profile, what=what, edges=edges, stamp=stamp)
        write_output(args, ex)
    except InputError as exc:
        raise HarpError(str(exc)) from None
    report(args, ex, fig, "harp profile")
    return EXIT_OK


def _zoom_profile(args, store, lens, newest, focal: float):
    """The profile of a zoom lens at (``focal``, ``args.focus``): a current one, or interpolated;
    ``(profile, what, edges, stamp)``."""
    from station.export_source import FittingEdges  # defers scipy

    hit = at_setting(newest, focal, args.focus)
    if hit is not None:
        _allowed(args, lens, hit)
        return hit, f"profile #{hit.id}", None, None
    used, left_out = current_and_left_out(store, lens[0], args.allow_failed)
    interp = interpolate_zoom(lens, used, focal, args.focus, left_out)
    _say_used(lens, used, left_out)
    stamp = tuple(line for q in interp.from_profiles for line in failed_stamp(q))
    edges = FittingEdges(None, f"none: the correction is interpolated ({interp.note})")
    return interp.profile(), f"interpolated {setting_text(focal, args.focus)}", edges, stamp


def _export_zoom(args, store, lens, newest) -> int:
    profile, what, edges, stamp = _zoom_profile(args, store, lens, newest, args.focal)
    return _write_profile(args, profile, what, edges, stamp)


def _export_lensfun_zoom(args, store, lens) -> int:
    """lensfun (or lcp) of a zoom lens: one calibration per calibrated focal length, at the one focus asked for
    (lensfun has no focus axis for distortion: a focus range cannot be written; an LCP profile adds the
    other focus settings by exporting them into the same file, each with its --distance), in one file;
    each focal's profile at that focus is a current one or interpolated along focus. Written whole or
    not at all: into a copy of ``-o`` (when it is a database), moved over it once every focal is in."""
    import argparse
    import os
    import shutil
    import tempfile
    from pathlib import Path

    newest = store.latest_by_focus(lens[0], allow_failed=True)
    focals = sorted({p.focal for p in newest if p.focal is not None})
    suffix = ".lcp" if args.format == "lcp" else ".xml"
    if not args.output:
        raise HarpError(f"{args.format} export of a zoom lens: give -o FILE{suffix} (one calibration per focal length)")
    if getattr(args, "tca", None) or getattr(args, "vignetting", None):
        raise HarpError(
            f"{args.format} export of a zoom lens: --tca and --vignetting hold one focal length's; export that focal "
            "alone (--focal MM) with them"
        )
    out = Path(args.output)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=suffix, dir=out.parent if str(out.parent) else ".")
    os.close(fd)
    os.unlink(tmp)
    try:
        if out.is_file():
            shutil.copyfile(out, tmp)
        part = argparse.Namespace(**{**vars(args), "output": tmp})
        done = []
        for z in focals:
            profile, what, edges, stamp = _zoom_profile(part, store, lens, newest, z)
            try:
                ex, fig = export_profile(part, profile, what=what, edges=edges, stamp=stamp)
                write_output(part, ex)
            except (InputError, ExportError) as exc:
                raise HarpError(f"focal {z:g} mm: {str(exc).replace(tmp, str(out))}; {out} not written") from None
            report(args, ex, fig, "harp profile")
            done.append(f"{z:g} mm")
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    print(f"{args.format}: {len(done)} calibrations (focal {', '.join(done)}) at focus {args.focus:g} in {out}")
    return EXIT_OK
