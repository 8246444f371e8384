"""Which profile of a lens a command uses at a focus setting, and why.

The **current** profile of a lens at a focus setting is its newest one, unless that one failed
QA: a failed profile is never current, and an older passing one does not stand in for it (the
store decides, :meth:`station.store.database.ProfileStore.latest_by_focus`). From that,
``harp profile show`` and ``harp profile export`` (:mod:`station.cli.profile`) take

* :func:`current_and_left_out` — the profiles used for a lens (its current ones, or with
  ``allow_failed`` the newest of every focus setting) and the newest ones left out;
* :func:`at_focus` — the profile of a list at one calibrated focus setting (of a zoom lens,
  :func:`at_setting`: at one calibrated (focal, focus) setting);
* :func:`interpolate` — the correction at a focus setting between calibrated ones
  (:class:`Interpolated`: the correction field interpolated, its leave-one-out error), of a
  zoom lens :func:`interpolate_zoom` — between calibrated (focal, focus) settings, in both,
  never extrapolated, the leave-one-out error per axis — and
  :meth:`Interpolated.profile` — it as a :class:`~station.profile.Profile` to export;
* :func:`is_failed`, :func:`verdict_text`, :func:`failed_checks`, :func:`failed_line` — what a
  profile's verdict says, in the words every command prints;
* :func:`export_refusal` — the rule every export of a stored profile follows (``harp profile
  export``, the dashboard's downloads): a profile that failed QA is refused unless the user
  overrides, and :func:`failed_stamp` — what the file of a failed profile then states first.

A lens is the store's lens row ``(id, maker, model, serial)`` (:data:`LensRow`; ``id`` is
``None`` for the lens a profile names). Two errors, each one line: :class:`ChoiceError` (no
profile to use; exit 2) and :class:`FailedQA` (the profile asked for failed QA; exit 1).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from pipeline.models.base import DistortionModel
from station.errors import HarpError
from station.exit_codes import EXIT_FAIL
from station.profile import Merit, Profile, Provenance

LensRow = tuple[int | None, str, str, str]
"""A lens: ``(store id or None, maker, model, serial)``."""

FOCUS_TOL = 1e-9
"""Two focus settings closer than this are the same setting."""


class ChoiceError(HarpError):
    """No profile to use (one line naming the lens and focus; exit 2)."""


class FailedQA(HarpError):
    """The profile asked for failed QA and failed ones were not allowed (one line; exit 1)."""

    exit_code = EXIT_FAIL


# ------------------------------------------------------------------ words
def lens_row(p: Profile) -> LensRow:
    """The lens a profile names (``id`` None), ``-`` for what it does not record."""
    lens = p.lens
    return (None, lens.maker, lens.model, lens.serial) if lens is not None else (None, "-", "-", "-")


def lens_label(lens: LensRow) -> str:
    """``lens Acme 50mm serial S1`` of a lens row."""
    return f"lens {lens[1]} {lens[2]} serial {lens[3]}"


def is_failed(p: Profile) -> bool:
    """The profile was judged and failed QA (one not judged has not failed)."""
    return p.qa is not None and not p.qa.passed


def verdict_text(p: Profile) -> str:
    """``PASS``, ``FAIL``, or empty when not judged."""
    return "" if p.qa is None else p.qa.verdict


def failed_checks(p: Profile) -> str:
    """What failed in a profile's verdict, for one line: the failed checks as they were judged."""
    v = p.qa
    if v is None:
        return "not judged"
    texts = [c.text.rsplit(": ", 1)[0] for c in v.checks if c.passed is False]
    return "; ".join(texts or list(v.reasons) or ["failed QA"])


def failed_line(lens: LensRow, p: Profile) -> str:
    """``lens … serial S, focus F: profile #N failed QA (the failed checks)``."""
    focus = f", focus {p.focus:g}" if p.focus is not None else ""
    if p.focal is not None:
        focus = f", focal {p.focal:g} mm{focus}"
    return f"{lens_label(lens)}{focus}: profile #{p.id} failed QA ({failed_checks(p)})"


def export_refusal(lens: LensRow, p: Profile, override: str) -> str | None:
    """Why ``p`` is not exported (one line naming ``override``, the way to export it anyway),
    or None when it did not fail QA. The caller refuses, or on the override says it exported it."""
    if not is_failed(p):
        return None
    return f"{failed_line(lens, p)}; not exported ({override} exports it anyway)"


def failed_stamp(p: Profile) -> tuple[str, ...]:
    """The lines an export of ``p`` states first when it failed QA
    (:attr:`pipeline.exports.source.ExportSource.stamp`); none otherwise."""
    if not is_failed(p):
        return ()
    what = f"profile #{p.id}" if p.id is not None else "this profile"
    focus = f" at focus {p.focus:g}" if p.focus is not None else ""
    return (
        f"FAILED QA: {what}{focus} was judged {verdict_text(p)} ({failed_checks(p)}); "
        "exported anyway: do not use it as a calibration that passed",
    )


# ----------------------------------------------------------------- choice
def current_and_left_out(store: Any, lens_id: int, allow_failed: bool) -> tuple[list[Profile], list[Profile]]:
    """``(used, left_out)``: the profiles a command uses for a lens — its current ones (the store
    decides which, :meth:`~station.store.database.ProfileStore.latest_by_focus`), or with
    ``allow_failed`` the newest of every focus setting — and the newest ones left out (failed QA)."""
    newest = store.latest_by_focus(lens_id, allow_failed=True)
    if allow_failed:
        return newest, []
    current = {p.id for p in store.latest_by_focus(lens_id)}
    return [p for p in newest if p.id in current], [p for p in newest if p.id not in current]


def at_focus(profiles: Iterable[Profile], focus: float) -> Profile | None:
    """The first of ``profiles`` at the focus setting ``focus``, or None."""
    for p in profiles:
        if p.focus is not None and math.isclose(p.focus, focus, rel_tol=0, abs_tol=FOCUS_TOL):
            return p
    return None


def is_zoom(profiles: Iterable[Profile]) -> bool:
    """Some of ``profiles`` are of a zoom lens's settings (they record a focal length)."""
    return any(p.focal is not None for p in profiles)


def at_setting(profiles: Iterable[Profile], focal: float | None, focus: float) -> Profile | None:
    """The first of ``profiles`` at the setting (``focal``, ``focus``); ``focal`` None: a fixed lens's."""
    for p in profiles:
        same_focal = (
            p.focal is None
            if focal is None
            else p.focal is not None and math.isclose(p.focal, focal, rel_tol=0, abs_tol=FOCUS_TOL)
        )
        if same_focal and p.focus is not None and math.isclose(p.focus, focus, rel_tol=0, abs_tol=FOCUS_TOL):
            return p
    return None


def setting_text(focal: float | None, focus: float | None) -> str:
    """``focal 24 mm, focus 0.5`` (or ``focus 0.5`` of a fixed lens)."""
    f = f"focus {focus:g}" if focus is not None else "focus ?"
    return f if focal is None else f"focal {focal:g} mm, {f}"


# ---------------------------------------------------------- interpolation
@dataclass(frozen=True)
class Interpolated:
    """The correction of a lens at an uncalibrated focus setting, interpolated between its profiles.

    ``leave_one_out`` is :func:`pipeline.interpolate.leave_one_out_error` of the profiles
    (empty with fewer than three); ``note`` says what was done, for the user.
    """

    focus: float
    model: DistortionModel
    width: int
    height: int
    method: str
    note: str
    leave_one_out: tuple[Any, ...]
    from_profiles: tuple[Profile, ...]
    focal: float | None = None

    def loo_rows(self) -> list[dict[str, Any]]:
        """The leave-one-out errors as plain rows (a zoom lens's with their ``axis`` and ``focal``)."""
        rows = []
        for e in self.leave_one_out:
            row: dict[str, Any] = {"focus": e.focus, "rms_px": e.rms_px, "max_px": e.max_px}
            if hasattr(e, "axis"):
                row = {"axis": e.axis, "focal": e.focal, **row}
            rows.append(row)
        return rows

    def profile(self) -> Profile:
        """The interpolated correction as a profile to export: the lens, camera and optics of the
        nearest calibrated profile, the leave-one-out error in its merit, the note and the
        profiles it comes from in its provenance."""

        def dist(p: Profile) -> tuple[float, float]:
            dz = 0.0 if self.focal is None or p.focal is None else abs(p.focal - self.focal)
            return dz, abs((p.focus or 0.0) - self.focus)

        nearest = min(self.from_profiles, key=dist)
        loo = self.loo_rows()
        return Profile(
            model=self.model,
            width=self.width,
            height=self.height,
            merit=Merit(extra={"interpolation_leave_one_out": loo}),
            lens=nearest.lens,
            camera=nearest.camera,
            optics=nearest.optics,
            focus=self.focus,
            focal=self.focal,
            provenance=Provenance(extra={"note": self.note, "from_profiles": [p.id for p in self.from_profiles]}),
        )

    def known(self) -> str:
        """The calibrated focus settings it comes from, ``0, 0.5, 1``."""
        return ", ".join(f"{p.focus:g}" for p in self.from_profiles)


def interpolate(
    lens: LensRow, profiles: Sequence[Profile], focus: float, left_out: Sequence[Profile] = ()
) -> Interpolated:
    """The correction at an uncalibrated ``focus``, from the calibrated ``profiles`` around it.

    Never extrapolates: a ``focus`` outside the calibrated ones is a :class:`ChoiceError`, or a
    :class:`FailedQA` when the profiles ``left_out`` (failed QA) would have bracketed it (the line
    names them). Profiles of different image sizes are a :class:`ChoiceError`.
    """
    from pipeline.interpolate import FocusInterpolator, leave_one_out_error  # defers scipy

    sizes = {(p.width, p.height) for p in profiles}
    if len(sizes) > 1:
        raise ChoiceError(f"{lens_label(lens)}: profiles of different image sizes; cannot interpolate")
    models = {p.focus: p.model for p in profiles}
    known = ", ".join(f"{p.focus:g}" for p in profiles) or "none"
    if len(models) < 2 or not min(models) < focus < max(models):
        msg = (
            f"{lens_label(lens)}: no current profile at focus {focus:g} and it is not between "
            f"two calibrated focus settings ({known}); no extrapolation"
        )
        every = [p.focus for p in (*profiles, *left_out) if p.focus is not None]
        if left_out and len(every) >= 2 and min(every) < focus < max(every):
            raise FailedQA(msg + "; left out: " + "; ".join(failed_line(lens, p) for p in left_out))
        raise ChoiceError(msg)
    ((w, h),) = sizes
    interp = FocusInterpolator(models, w, h)
    model = interp.at(focus)
    loo = leave_one_out_error(models, w, h)
    method = getattr(interp, "method", "auto")
    note = f"focus {focus:g} is not calibrated: correction field interpolated ({method}) between the settings {known}"
    return Interpolated(focus, model, w, h, method, note, tuple(loo), tuple(profiles))


def interpolate_zoom(
    lens: LensRow, profiles: Sequence[Profile], focal: float, focus: float, left_out: Sequence[Profile] = ()
) -> Interpolated:
    """The correction of a zoom lens at an uncalibrated setting (``focal``, ``focus``), from the
    calibrated settings around it (:class:`pipeline.zoom.ZoomInterpolator`: along focus at each
    focal length, then along the focal length). Never extrapolates: a setting outside the
    calibrated ranges is a :class:`ChoiceError` naming them, or a :class:`FailedQA` when profiles
    ``left_out`` (failed QA) are at the focal lengths it would need."""
    from pipeline.zoom import ZoomInterpolator, leave_one_out_by_axis  # defers scipy

    zoom = [p for p in profiles if p.focal is not None and p.focus is not None]
    sizes = {(p.width, p.height) for p in zoom}
    if len(sizes) > 1:
        raise ChoiceError(f"{lens_label(lens)}: profiles of different image sizes; cannot interpolate")
    if not zoom:
        raise ChoiceError(f"{lens_label(lens)}: no current profile of a focal length setting")
    models = {(p.focal, p.focus): p.model for p in zoom}
    ((w, h),) = sizes
    interp = ZoomInterpolator(models, w, h)
    known = "; ".join(f"{z:g} mm: focus {', '.join(f'{f:g}' for f in sorted(row))}" for z, row in interp.grid.items())
    try:
        model = interp.at(focal, focus)
    except ValueError as exc:
        msg = f"{lens_label(lens)}: no current profile at {setting_text(focal, focus)} ({exc}); calibrated: {known}"
        near = [p for p in left_out if p.focal is not None]
        if near:
            raise FailedQA(msg + "; left out: " + "; ".join(failed_line(lens, p) for p in near)) from None
        raise ChoiceError(msg) from None
    loo = leave_one_out_by_axis(models, w, h)
    note = (
        f"{setting_text(focal, focus)} is not calibrated: correction field interpolated along focus, then along "
        f"the focal length ({interp.method}), between the settings {known}"
    )
    return Interpolated(focus, model, w, h, interp.method, note, tuple(loo), tuple(zoom), focal=focal)
