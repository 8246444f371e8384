"""A session's results for scripts: ``DIR/results.json`` and ``harp session run|resume --json``.

:func:`session_results` gathers, from an open session directory and its QA
(:class:`station.qa.judge.SessionQA`), what a production line needs in one JSON
object: the session's state (:func:`station.session.states.session_state`), lens and
camera, station, software, configuration (path and SHA-256 of the copy the session
runs), the devices as they reported themselves (:func:`device_identities`, compared with
the configuration), per focus setting the figures, the verdict with every check
(value, comparison, limit, passed, text) and the stored profile id, the focus-interpolation
error and where the report is. :func:`write_results` writes it atomically as
:data:`station.session.layout.RESULTS`; it is written again whenever QA runs, so it
always says the last verdict.

Format (``format: harp-session-results``, ``format_version: 1``)::

    {"format", "format_version", "session", "state", "verdict", "exit_code",
     "station", "software_version", "created", "config": {"path", "copy", "sha256"},
     "lens": {"maker", "model", "serial"}, "camera": {...},
     "devices": {"camera": {"reported", "configured", "matches"}, "turntable": {...}},
     "thresholds": {...},
     "focus": [{"focus_idx", "focus", "profile_id", "profile_file", "model", "spec",
                "fit": {"d", "d_max"}, "holdout": {"d", "d_max"},
                "field_uncertainty": {"rms", "max", "replicates"},
                "verdict", "reasons", "checks": [...], "figures": {...}}],
     "interpolation": [{"focus", "rms_px", "max_px"}], "report": "report/report.md" | null}
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pipeline.plain import plain
from station.exit_codes import EXIT_ERROR, EXIT_INTERRUPTED, verdict_exit_code
from station.files import atomic_write_text, sha256_file
from station.session import layout
from station.session.records import FrameSaved, InterpolationError, QARecorded, ReportWritten, SessionVerdict
from station.session.states import session_state

FORMAT = "harp-session-results"
FORMAT_VERSION = 1


def _ident(maker: str, model: str, serial: str) -> dict[str, str]:
    return {"maker": maker, "model": model, "serial": serial}


def device_identities(session: Any) -> dict[str, dict[str, Any]]:
    """The devices as they reported themselves during the session, beside the configuration.

    The camera's identity is what every saved frame recorded (``frame`` records' ``meta.camera``,
    vendor / model / serial as the driver read them from the device); it ``matches`` the
    configuration's ``camera_body`` when the serial numbers agree (None: no frame yet). The
    turntable drivers report no identity: its driver and port are given as configured."""
    cfg = session.config
    body = cfg.camera_body
    seen: list[list[str]] = []
    for r in session.of_type(FrameSaved):
        cam = (r.meta or {}).get("camera")
        if isinstance(cam, (list, tuple)) and len(cam) == 3 and list(cam) not in seen:
            seen.append([str(x) for x in cam])
    reported = [_ident(*c) for c in seen]
    matches = None if not seen else all(c[2] == body.serial for c in seen)
    tt = cfg.station.turntable
    return {
        "camera": {
            "driver": cfg.station.camera.driver,
            "reported": reported,
            "configured": _ident(body.maker, body.model, body.serial),
            "matches": matches,
        },
        "turntable": {
            "driver": tt.driver,
            "port": tt.port,
            "reported": None,
            "note": "the turntable drivers report no identity; driver and port as configured",
        },
    }


def identity_warnings(devices: Mapping[str, Any]) -> list[str]:
    """One line per device whose reported identity differs from the configuration."""
    cam = devices.get("camera") or {}
    if cam.get("matches") is not False:
        return []
    conf = cam["configured"]
    got = "; ".join(f"{c['maker']} {c['model']} serial {c['serial']}" for c in cam["reported"])
    return [
        f"the camera reported itself as {got}, but the configuration's camera_body is "
        f"{conf['maker']} {conf['model']} serial {conf['serial']}: check that the right camera is connected "
        f"(or correct camera_body)"
    ]


def config_record(session: Any) -> dict[str, Any]:
    """Path of the configuration the session was started from, its copy in the session and the copy's SHA-256."""
    copy = session.path / layout.CONFIG_COPY
    return {
        "path": session.meta.get("config_source"),
        "copy": layout.CONFIG_COPY,
        "sha256": sha256_file(copy) if copy.is_file() else None,
    }


def session_results(session: Any, qa: Any = None) -> dict[str, Any]:
    """The results of an open session directory (see the module docstring); ``qa`` is the
    :class:`station.qa.judge.SessionQA` of this run (None: taken from the manifest's records,
    or no verdict yet)."""
    from station.profile import Verdict  # defers cv2, numpy, yaml
    from station.qa.verdicts import session_profiles  # defers cv2, numpy, yaml

    cfg = session.config
    state = session_state(session.typed)
    stored = session.stored_ids()
    if qa is not None:
        pairs = list(qa.profiles)
        verdicts: dict[int, Any] = {f: v for (f, _p), v in zip(qa.profiles, qa.verdicts)}
        overall = qa.overall
        interpolation = [{"focus": e.focus, "rms_px": e.rms_px, "max_px": e.max_px} for e in qa.interpolation]
    else:
        pairs = session_profiles(session.path)
        verdicts = {}
        for r in session.of_type(QARecorded):
            verdicts[r.focus_idx] = Verdict(
                r.verdict,
                tuple(r.reasons or ()),
                dict(r.metrics or {}),
                tuple(_checks(r.checks)),
                dict(r.thresholds or {}),
            )
        last = session.last(SessionVerdict)
        overall = last.verdict if last is not None else None
        interpolation = [
            {"focus": r.focus, "rms_px": r.rms_px, "max_px": r.max_px} for r in session.of_type(InterpolationError)
        ]
    focus = []
    for f, p in pairs:
        v = verdicts.get(f)
        m = p.merit
        unc = m.field_uncertainty
        focus.append(
            {
                "focus_idx": f,
                "focus": p.focus if p.focus is not None else cfg.focus_settings[f],
                "profile_id": stored.get(f, p.id),
                "profile_file": layout.profile_file(f),
                "model": p.model.name,
                "spec": p.spec.label if p.spec is not None else None,
                "fit": m.fit.to_dict() if m.fit else None,
                "holdout": m.holdout.to_dict() if m.holdout else None,
                "field_uncertainty": unc.to_dict() if unc else None,
                **(
                    {"verdict": v.verdict, "reasons": list(v.reasons), "checks": [c.to_dict() for c in v.checks]}
                    if v is not None
                    else {"verdict": None, "reasons": [], "checks": []}
                ),
                "figures": dict(v.metrics) if v is not None else {},
            }
        )
    reports = [r for r in session.of_type(ReportWritten) if r.file]
    return plain(
        {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "session": str(session.path.resolve()),
            "state": state,
            "verdict": overall,
            "exit_code": state_exit_code(state, overall),
            "station": cfg.station.id,
            "software_version": session.meta.get("software_version"),
            "created": session.meta.get("created"),
            "config": config_record(session),
            "lens": _ident(cfg.lens.maker, cfg.lens.model, cfg.lens.serial),
            "camera": _ident(cfg.camera_body.maker, cfg.camera_body.model, cfg.camera_body.serial),
            "devices": device_identities(session),
            "thresholds": dict(cfg.qa.__dict__),
            "focus": focus,
            "interpolation": interpolation,
            "report": reports[-1].file if reports else None,
        }
    )


def state_exit_code(state: str, verdict: str | None) -> int | None:
    """The exit code ``harp session run`` / ``resume`` gives a session in ``state`` with ``verdict``
    (:mod:`station.exit_codes`): the verdict's for a complete session, 2 for a failed one, 130 for
    an interrupted one, None for one still running."""
    if state == "complete":
        return verdict_exit_code(verdict)
    if state == "failed":
        return EXIT_ERROR
    if state == "interrupted":
        return EXIT_INTERRUPTED
    return None


def _checks(items: Any):
    from station.profile import Check  # defers cv2, numpy, yaml

    for c in items or ():
        if isinstance(c, Mapping):
            yield Check.from_dict(c)


def write_results(session: Any, results: Mapping[str, Any]) -> Path:
    """Write ``results`` as ``DIR/results.json`` atomically; returns the path."""
    path = session.path / layout.RESULTS
    atomic_write_text(path, json.dumps(results, indent=1) + "\n")
    return path


def finished_results(session: Any) -> dict[str, Any]:
    """The results of a finished session: its ``results.json`` when that says complete, else (killed
    before it was written) gathered again and written. OSError / ValueError when they cannot be."""
    results = read_results(session.path)
    if results is None or results.get("state") != "complete":
        results = session_results(session)
        write_results(session, results)
    return results


def read_results(session_dir: str | Path) -> dict[str, Any] | None:
    """The ``results.json`` of a session directory, or None when it has none (or it cannot be read)."""
    path = Path(session_dir) / layout.RESULTS
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and data.get("format") == FORMAT else None
