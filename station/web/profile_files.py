"""The files the QA dashboard serves for a stored profile: plots and exports.

No path is ever taken from a request: a request names a profile id, and the files are found from
what the store holds for that profile — its session directory (``provenance.session_dir``) and
the names :mod:`station.session.layout` gives the session's files — or made from the stored
record itself:

* **field plot** — the session report's ``report/field_f<i>.png`` when the session's profile file
  of that focus setting holds exactly the stored model (the report then shows this profile);
  otherwise rendered from the stored model (:func:`station.qa.plots.plot_field`);
* **uncertainty plot** — the report's ``report/uncertainty_f<i>.png`` on the same condition, else
  rendered from the bootstrap map the session kept (``profiles/focus<i>_uncertainty.npz``, checked
  against the manifest's SHA-256); a profile whose map is not kept (re-processed, or a session
  without bootstrap) has none, and :class:`Unavailable` says why;
* **exports** — every format of :data:`pipeline.exports.registry.FORMATS`, written from the stored
  profile (:func:`station.export_source.export_source`, :func:`pipeline.exports.registry.write_export`).

Rendered plots and exports are kept in a small in-memory cache (a profile row does not change but
by a resumed session, which replaces it: the cache is keyed by the row's store time too).
matplotlib is not thread-safe: rendering holds a lock.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import tempfile
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.model_file import read_model_file
from station.lensfun_databases import installed_databases
from station.profile import Profile
from station.session import layout
from station.session.directory import read_records
from station.session.evidence import uncertainty_from_arrays
from station.session.layout import MANIFEST
from station.session.records import Fitted

CACHE_ENTRIES = 64


class Unavailable(LookupError):
    """The file cannot be served for this profile; ``str()`` says why in one line.

    Not a HarpError: answered as HTTP 404 by :mod:`station.web.dashboard`; no command raises it."""


@dataclass(frozen=True)
class Served:
    """What to send: a file the store references (``path``) or bytes made now (``data``)."""

    media_type: str
    path: Path | None = None
    data: bytes | None = None
    filename: str | None = None
    source: str = ""


_render_lock = threading.Lock()


class _Cache:
    def __init__(self, n: int = CACHE_ENTRIES) -> None:
        self.n = n
        self._d: OrderedDict[Any, Served] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: Any, make: Callable[[], Served]) -> Served:
        with self._lock:
            if key in self._d:
                self._d.move_to_end(key)
                return self._d[key]
        value = make()
        with self._lock:
            self._d[key] = value
            while len(self._d) > self.n:
                self._d.popitem(last=False)
        return value


def _same_model(a: Any, b: Any) -> bool:
    def plain(d: Any) -> str:
        return json.dumps(d, sort_keys=True, default=str)

    return bool(plain(a.to_dict()) == plain(b.to_dict()))


def session_focus_index(profile: Profile) -> int | None:
    """The focus index of the session profile file that holds exactly this profile's model (same
    focus, same image size, same model parameters), or None (not a session's own profile, the
    session gone, or refitted since)."""
    sd = profile.provenance.session_dir
    if not sd or profile.focus is None:
        return None
    root = Path(sd)
    if not root.is_dir():
        return None
    for f, path in layout.profile_files(root):
        try:
            mf = read_model_file(path)
        except (OSError, ValueError):
            continue
        focus = mf.provenance.get("focus") if isinstance(mf.provenance, dict) else None
        if not isinstance(focus, (int, float)) or not math.isclose(float(focus), profile.focus, abs_tol=1e-9):
            continue
        if (mf.width, mf.height) == (profile.width, profile.height) and _same_model(mf.model, profile.model):
            return f
    return None


def _png(fig_writer: Callable[[Path], Any]) -> bytes:
    with _render_lock, tempfile.TemporaryDirectory(prefix="harp-plot-") as tmp:
        out = Path(tmp) / "plot.png"
        fig_writer(out)
        return out.read_bytes()


def _label(p: Profile) -> str:
    lens = p.lens
    name = f"{lens.maker} {lens.model} {lens.serial}" if lens else "lens"
    return f"{name}, focus {p.focus:g}, profile #{p.id}" if p.focus is not None else f"{name}, profile #{p.id}"


class ProfileFiles:
    """Finds (or makes) the plots and exports of stored profiles (module docstring)."""

    def __init__(self) -> None:
        self._cache = _Cache()

    def _key(self, p: Profile, what: str) -> tuple[Any, ...]:
        return (p.id, p.stored_at, what)

    # -------------------------------------------------------------- plots
    def field_plot(self, p: Profile) -> Served:
        f = session_focus_index(p)
        if f is not None:
            png = Path(str(p.provenance.session_dir)) / "report" / f"field_f{f}.png"
            if png.is_file():
                return Served("image/png", path=png, source="the session report")

        def make() -> Served:
            from station.qa.plots import plot_field  # defers matplotlib, PIL

            data = _png(lambda out: plot_field(p.model, p.width, p.height, out, title=_label(p)))
            return Served("image/png", data=data, source="rendered from the stored model")

        return self._cache.get(self._key(p, "field"), make)

    def uncertainty_plot(self, p: Profile) -> Served:
        f = session_focus_index(p)
        if f is None:
            unc = p.merit.field_uncertainty
            figures = (
                f" (RMS {unc.rms:.4f} px, max {unc.max:.4f} px)"
                if unc and unc.rms is not None and unc.max is not None
                else ""
            )
            raise Unavailable(f"the field-uncertainty map of profile #{p.id} is not kept{figures}")
        root = Path(str(p.provenance.session_dir))
        png = root / "report" / f"uncertainty_f{f}.png"
        if png.is_file():
            return Served("image/png", path=png, source="the session report")

        def make() -> Served:
            from station.qa.plots import plot_uncertainty  # defers matplotlib, PIL

            unc = _session_uncertainty(root, f, p.model)
            if unc is None:
                raise Unavailable(f"profile #{p.id}: its session kept no field-uncertainty map (pipeline.bootstrap: 0)")
            data = _png(lambda out: plot_uncertainty(unc, p.width, p.height, out, title=_label(p)))
            return Served("image/png", data=data, source="rendered from the session's uncertainty map")

        return self._cache.get(self._key(p, "uncertainty"), make)

    # ------------------------------------------------------------ exports
    def export(self, p: Profile, fmt: str) -> Served:
        from pipeline.exports.registry import FORMATS, write_export  # defers scipy

        if fmt not in FORMATS:
            raise Unavailable(f"unknown export format {fmt!r}; known: {', '.join(FORMATS)}")

        def make() -> Served:
            from pipeline.exports.source import ExportOptions  # defers scipy
            from station.export_source import export_source  # defers scipy

            options = ExportOptions()
            if fmt == "lensfun":  # the same name check as harp export (pipeline.exports.lensfun.installed_lens)
                options = ExportOptions(installed_lensfun=installed_databases())
            try:
                ex = write_export(fmt, export_source(p), options)
            except ValueError as exc:
                raise Unavailable(
                    f"profile #{p.id} cannot be exported as {fmt}: {' '.join(str(exc).split())}"
                ) from None
            serial = p.lens.serial if p.lens is not None else "lens"
            safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in serial)
            name = f"{safe}-focus{p.focus:g}-profile{p.id}{FORMATS[ex.format].suffix}"
            return Served("application/octet-stream", data=ex.data, filename=name, source=f"export {ex.format}")

        return self._cache.get(self._key(p, f"export:{fmt}"), make)


def _session_uncertainty(root: Path, f: int, model: Any) -> Any:
    """The bootstrap map a session kept for focus index ``f`` (SHA-256 checked), or None."""
    import numpy as np

    try:
        records = read_records(root / MANIFEST)
    except (OSError, ValueError):
        return None
    fits = [r for r in records if isinstance(r, Fitted) and r.focus_idx == f and r.uncertainty_file]
    if not fits:
        return None
    rec = fits[-1]
    try:
        data = (root / rec.uncertainty_file).read_bytes()
        if hashlib.sha256(data).hexdigest() != rec.uncertainty_sha256:
            return None
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            return uncertainty_from_arrays({k: z[k] for k in z.files}, model)
    except (OSError, ValueError, KeyError):
        return None
