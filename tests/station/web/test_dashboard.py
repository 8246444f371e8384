"""The QA dashboard (``harp serve``) over real HTTP (uvicorn on 127.0.0.1), on a real SQLite file and a
real PostgreSQL server: its JSON endpoints, its control limits, the files it serves and the token.

What the pages must show is computed here from the plan of the store (tests/station/web/dashboard_store.py)
and from the stored profiles, not from the dashboard's code.
"""

from __future__ import annotations

import hashlib
import io
import json
import urllib.error
import urllib.request
import uuid

import cv2
import numpy as np
import pytest

from station.store import ProfileStore
from station.web import start
from station.web.dashboard import dashboard_app
from tests.station.web.dashboard_store import LENSES, copy_into

MAKER, MODEL = "Simulated Optics", "SIM-12mm"


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def served(request, dashboard):
    """The dashboard on both backends: the shared SQLite one, and the same profiles copied into a
    PostgreSQL database."""
    srv, store, stored, path = dashboard
    if request.param == "sqlite":
        yield srv, store, stored
        return
    url = request.getfixturevalue("postgres").create_database(f"dash_{uuid.uuid4().hex[:12]}")
    copy_into(path, url)
    with ProfileStore(url, create=False) as pg, start(dashboard_app(pg)) as pg_srv:
        yield pg_srv, pg, stored


@pytest.fixture
def sqlite_served(dashboard):
    srv, store, stored, _path = dashboard
    return srv, store, stored


def _get(srv, path, token=None):
    req = urllib.request.Request(srv.base.rstrip("/") + path)
    if token:
        req.add_header("Authorization", f"Bearer {token}")
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, r.headers, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.headers, e.read()


def _json(srv, path):
    status, _h, body = _get(srv, path)
    return status, json.loads(body)


def _by_serial(store):
    return {serial: lens_id for lens_id, _mk, _md, serial in store.lenses()}


# ------------------------------------------------------------------ JSON
def test_api_lenses_lists_every_lens_and_the_pass_fail_counts(served):
    srv, store, stored = served
    status, doc = _json(srv, "/api/lenses")
    assert status == 200
    assert sorted(l["serial"] for l in doc["lenses"]) == sorted(stored)
    fails = {s for s, _st, _d, hold in LENSES if hold > 10}
    for l in doc["lenses"]:
        assert l["profiles"] == 2 and l["calibrations"] == 1
        assert l["last_verdict"] == ("FAIL" if l["serial"] in fails else "PASS")
        assert l["api"] == f"/api/lenses/{l['serial']}"
    (m,) = doc["models"]
    assert (m["maker"], m["model"]) == (MAKER, MODEL)
    assert (m["lenses"], m["calibrations"], m["passed"], m["failed"]) == (6, 6, 5, 1)
    # a calibration's day is the day its first profile was stored (the store's own record): the
    # fixture may straddle midnight, so each calibration is counted on the day it was stored
    station_of = {"DEMO-0001": "line-1", **{s: st for s, st, _d, _h in LENSES}}  # the real session ran on line-1
    failing = {s for s, _st, _d, hold in LENSES if hold > 10}
    want: dict[tuple[str, str], list[int]] = {}
    for serial, profs in stored.items():
        day = min(p.stored_at for p in profs)[:10]
        want.setdefault((station_of[serial], day), [0, 0])[1 if serial in failing else 0] += 1
    got = {(c["station"], c["day"]): [c["passed"], c["failed"]] for c in doc["counts"]}
    assert got == want


def test_api_lens_has_every_profile_check_plot_and_download(served):
    srv, store, stored = served
    status, doc = _json(srv, "/api/lenses/DEMO-0001")
    assert status == 200
    assert (doc["maker"], doc["model"], doc["serial"]) == (MAKER, MODEL, "DEMO-0001")
    real = {p.focus: p for p in stored["DEMO-0001"]}
    assert [f["focus"] for f in doc["focus"]] == sorted(real)
    from pipeline.exports.registry import FORMATS

    for f in doc["focus"]:
        (p,) = f["profiles"]
        want = real[f["focus"]]
        assert p["current"] is True and p["verdict"] == want.qa.verdict == "PASS"
        assert p["figures"]["holdout_d_px"] == want.merit.holdout.d
        assert {c["name"]: c["value"] for c in p["checks"]} == {c.name: c.value for c in want.qa.checks}
        # the session's QA judged the stored model itself (issue 9, issue 14 item 6)
        assert {c["name"] for c in p["checks"]} == {
            "holdout_d",
            "corrected_d",
            "defined",
            "distortion_max",
            "distortion_recorded",
            "string_bend_max",  # the harp's self-check (issue 19 item 4)
            "holdout_own_shift",  # the held-out orientations' own axis shift (reported)
        }
        assert [d["format"] for d in p["downloads"]] == list(FORMATS)
        assert p["plots"] == {
            "field": f"/profiles/{p['id']}/field.png",
            "uncertainty": f"/profiles/{p['id']}/uncertainty.png",
        }
    status, err = _json(srv, "/api/lenses/NO-SUCH-LENS")
    assert status == 404 and err == {"error": "no lens with serial 'NO-SUCH-LENS' in the store"}


def test_api_profile_is_the_stored_profile(served):
    srv, store, stored = served
    p = next(p for p in store.profiles() if p.lens.serial == "DEMO-0003" and p.focus == 1.0)
    status, doc = _json(srv, f"/api/profiles/{p.id}")
    assert status == 200
    assert doc["distortion_model"] == json.loads(json.dumps(p.model.to_dict()))
    assert doc["lens"] == {"maker": MAKER, "model": MODEL, "serial": "DEMO-0003"}
    assert doc["station"] == "line-2" and doc["focus"] == 1.0
    assert doc["merit"]["holdout"]["d"] == pytest.approx(p.merit.holdout.d, rel=1e-12)
    status, err = _json(srv, "/api/profiles/99999")
    assert status == 404 and err["error"] == "no profile #99999 in the store"


def _limits(values):
    v = np.asarray(values, float)
    m, s = v.mean(), v.std(ddof=1)
    return m - 3 * s, m + 3 * s


def test_model_control_limits_are_mean_3_sigma_of_the_passed_lenses(served):
    srv, store, stored = served
    status, doc = _json(srv, f"/api/model?maker={MAKER.replace(' ', '+')}&model={MODEL}")
    assert status == 200
    fails = {s for s, _st, _d, hold in LENSES if hold > 10}
    for f in doc["focus"]:
        newest = {s: next(p for p in ps if p.focus == f["focus"]) for s, ps in stored.items()}
        passed = [p for s, p in newest.items() if s not in fails]
        assert all(p.qa.verdict == "PASS" for p in passed) and all(newest[s].qa.verdict == "FAIL" for s in fails)
        lo, hi = _limits([p.merit.holdout.d for p in passed])
        lim = f["figures"]["holdout_d"]["limits"]
        assert lim["n"] == 5
        assert lim["lower"] == pytest.approx(lo, rel=1e-9) and lim["upper"] == pytest.approx(hi, rel=1e-9)
        assert f["figures"]["holdout_d"]["outside"] == sorted(fails)  # the failed lens is out of control
        lo, hi = _limits([p.qa.metrics["distortion_max_px"] for p in passed])
        lim = f["figures"]["distortion_max"]["limits"]
        assert lim["lower"] == pytest.approx(lo, rel=1e-9) and lim["upper"] == pytest.approx(hi, rel=1e-9)
        # every lens once, in calibration order (the time each was stored)
        order = sorted(stored, key=lambda s: min((p.stored_at, p.id) for p in stored[s]))
        assert [p["serial"] for p in f["points"]] == order
    status, err = _json(srv, "/api/model?maker=Nobody&model=X")
    assert status == 404 and "no lens model 'Nobody' 'X'" in err["error"]


# ----------------------------------------- filters, failure reasons, CSV, spec limits (issue 21 item 2)
STATION_OF = {"DEMO-0001": "line-1", **{s: st for s, st, _d, _h in LENSES}}  # the real session ran on line-1


def _expected_rows(stored, since=None, until=None, station=None):
    """The lens list a filter must give, from the stored records: each lens calibrated (its first
    profile stored) on a day in [since, until] at the station, with the failed checks of its
    failed profiles (by focus)."""
    rows = {}
    for serial, profs in stored.items():
        day = min(p.stored_at for p in profs)[:10]
        if (since and day < since) or (until and day > until) or (station and STATION_OF[serial] != station):
            continue
        failed = [p for p in sorted(profs, key=lambda p: p.focus) if p.qa.verdict == "FAIL"]
        reason = "; ".join(
            f"focus {p.focus:g}: {c.text.removesuffix(': FAIL')}"
            for p in failed
            for c in p.qa.checks
            if c.passed is False
        )
        rows[serial] = {
            "station": STATION_OF[serial],
            "verdict": "FAIL" if failed else "PASS",
            "failure": reason,
            "day": day,
        }
    return rows


def test_the_lens_list_filters_by_day_and_station_and_says_why_a_lens_failed(served):
    srv, _store, stored = served
    days = sorted({min(p.stored_at for p in ps)[:10] for ps in stored.values()})
    assert len(days) >= 3  # the fixture spreads the lenses over days
    for query in (
        {},
        {"station": "line-2"},
        {"from": days[1]},
        {"to": days[1]},
        {"from": days[1], "to": days[1], "station": "line-1"},
        {"from": days[-1], "station": "line-2"},
    ):
        qs = "&".join(f"{k}={v}" for k, v in query.items())
        status, doc = _json(srv, "/api/lenses" + (f"?{qs}" if qs else ""))
        assert status == 200, doc
        want = _expected_rows(stored, query.get("from"), query.get("to"), query.get("station"))
        got = {l["serial"]: l for l in doc["lenses"]}
        assert sorted(got) == sorted(want), query
        for serial, w in want.items():
            assert (got[serial]["last_station"], got[serial]["last_verdict"]) == (w["station"], w["verdict"])
            assert got[serial]["failure"] == w["failure"]
            assert got[serial]["last_calibrated"][:10] == w["day"]
        assert sum(m["calibrations"] for m in doc["models"]) == len(want)
        assert sum(c["passed"] + c["failed"] for c in doc["counts"]) == len(want)
        assert doc["stations"] == ["line-1", "line-2"]  # the filter offers every station, whatever is shown
        assert doc["filter"] == {"from": query.get("from"), "to": query.get("to"), "station": query.get("station")}
    # the failed lens's reason names its failed check with value and limit, at each focus
    failing = _expected_rows(stored)["DEMO-0006"]["failure"]
    assert failing.startswith("focus 0: holdout d ") and "> 0.05 px" in failing and "focus 1: holdout d " in failing
    for bad, what in (("from=yesterday", "?from= must be a day as YYYY-MM-DD, got 'yesterday'"),
                      (f"from={days[-1]}&to={days[0]}", f"?from={days[-1]} is after ?to={days[0]}")):  # fmt: skip
        status, err = _json(srv, f"/api/lenses?{bad}")
        assert status == 400 and err == {"error": what}
        status, _h, body = _get(srv, f"/?{bad}")
        assert status == 400 and what.encode() in body.replace(b"&#39;", b"'")


def test_the_lens_list_downloads_as_csv(served):
    import csv

    srv, _store, stored = served
    for query in ("", "?station=line-2"):
        status, headers, body = _get(srv, "/lenses.csv" + query)
        assert status == 200 and headers["content-type"] == "text/csv; charset=utf-8"
        assert headers["content-disposition"].startswith('attachment; filename="harp-lenses')
        rows = list(csv.DictReader(io.StringIO(body.decode("utf-8"), newline="")))
        want = _expected_rows(stored, station="line-2" if query else None)
        assert [r["serial"] for r in rows] == sorted(want)
        for r in rows:
            w = want[r["serial"]]
            assert (r["maker"], r["model"], r["station"], r["verdict"]) == (MAKER, MODEL, w["station"], w["verdict"])
            assert r["failure_reason"] == w["failure"] and r["last_calibrated_utc"][:10] == w["day"]
            assert (r["calibrations"], r["profiles"]) == ("1", "2")
    status, _h, body = _get(srv, "/lenses.csv?to=someday")
    assert status == 400 and json.loads(body)["error"].startswith("?to= must be a day")


def test_the_model_charts_carry_the_spec_limits_the_profiles_were_judged_with(served):
    srv, _store, stored = served
    status, doc = _json(srv, f"/api/model?maker={MAKER.replace(' ', '+')}&model={MODEL}")
    assert status == 200
    for f in doc["focus"]:
        newest = [next(p for p in ps if p.focus == f["focus"]) for ps in stored.values()]
        for key in ("holdout_d", "distortion_max"):
            limits = {c.limit for p in newest for c in p.qa.checks if c.name == key}
            assert f["figures"][key]["spec"] == {"comparison": "<=", "limits": sorted(limits)}
        # the session's thresholds (the archive's configuration), as the store kept them
        assert f["figures"]["holdout_d"]["spec"]["limits"] == [newest[0].qa.thresholds["max_holdout_d_px"]]
        assert f["figures"]["distortion_max"]["spec"]["limits"] == [newest[0].qa.thresholds["max_distortion_px"]]


# ------------------------------------------------------------------ files
def _png(body):
    assert body[:8] == b"\x89PNG\r\n\x1a\n"
    img = cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None and img.shape[0] > 200 and img.shape[1] > 200
    return img


def test_plots_come_from_what_the_store_references(sqlite_served):
    srv, store, stored = sqlite_served
    real = stored["DEMO-0001"][0]
    ids = _by_serial(store)
    pid = next(p.id for p in store.profiles(ids["DEMO-0001"]) if p.focus == real.focus)
    status, h, body = _get(srv, f"/profiles/{pid}/field.png")
    assert status == 200 and h["content-type"] == "image/png" and h["x-harp-source"] == "rendered from the stored model"
    _png(body)
    # the session kept its bootstrap map (SHA-256 checked against its manifest): the plot is made from it
    status, h, body = _get(srv, f"/profiles/{pid}/uncertainty.png")
    assert status == 200 and h["x-harp-source"] == "rendered from the session's uncertainty map"
    _png(body)
    # a lens whose session directory is not on this machine: the field from its stored model, no uncertainty map
    other = next(p.id for p in store.profiles(ids["DEMO-0002"]))
    assert _get(srv, f"/profiles/{other}/field.png")[0] == 200
    status, _h, body = _get(srv, f"/profiles/{other}/uncertainty.png")
    assert status == 404 and json.loads(body)["error"].startswith(
        f"the field-uncertainty map of profile #{other} is not kept"
    )


@pytest.mark.parametrize(
    "path",
    [
        "/profiles/{pid}/export/..%2F..%2F..%2Fetc%2Fpasswd",
        "/profiles/{pid}/export/%2Fetc%2Fpasswd",
        "/profiles/{pid}/../../etc/passwd",
        "/profiles/99999/field.png",
        "/static/base/..%2F..%2F..%2F..%2Fetc%2Fpasswd",
        "/profiles/{pid}/field.png?path=/etc/passwd",
    ],
)
def test_no_path_is_taken_from_the_request(sqlite_served, path):
    srv, store, _stored = sqlite_served
    pid = store.profiles()[0].id
    status, _h, body = _get(srv, path.format(pid=pid))
    assert b"root:" not in body
    if "field.png?path" in path:
        assert status == 200 and body[:4] == b"\x89PNG"  # the query is ignored: the profile's own plot
    else:
        assert status == 404


def test_downloads_load_in_opencv(sqlite_served, tmp_path):
    from tests.pipeline.export_support import compare_map, opencv_maps

    srv, store, _stored = sqlite_served
    p = next(p for p in store.profiles() if p.lens.serial == "DEMO-0001" and p.focus == 0.0)
    status, h, body = _get(srv, f"/profiles/{p.id}/export/opencv")
    assert status == 200 and h["content-disposition"] == f'attachment; filename="DEMO-0001-focus0-profile{p.id}.yml"'
    (tmp_path / "c.yml").write_bytes(body)
    mx, my, kind, k = opencv_maps(tmp_path / "c.yml", p.width, p.height)
    assert kind == "pinhole" and k.shape == (3, 3)
    rms, worst, _n = compare_map(p.model, mx, my, step=4)
    assert worst < 0.01  # OpenCV's own undistortion of the download is the stored correction, to the bar
    status, _h, body = _get(srv, f"/profiles/{p.id}/export/maps")
    with np.load(io.BytesIO(body)) as z:
        map_x, map_y = z["map_x"], z["map_y"]
    assert map_x.shape == map_y.shape == (p.height, p.width) and map_x.dtype == map_y.dtype == np.float32
    img = np.tile(np.arange(p.width, dtype=np.float32), (p.height, 1))
    fixed = cv2.remap(img, map_x, map_y, cv2.INTER_LINEAR)  # cv2.remap reads the download as it is
    assert np.allclose(fixed[p.height // 2, 10 : p.width - 10], map_x[p.height // 2, 10 : p.width - 10], atol=1e-3)
    status, _h, body = _get(srv, f"/profiles/{p.id}/export/nonsense")
    assert status == 404 and json.loads(body)["error"].startswith("unknown export format 'nonsense'")


def test_the_dashboard_only_reads(dashboard):
    srv, store, _stored, path = dashboard
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    req = urllib.request.Request(srv.base + "api/lenses", method="POST", data=b"{}")
    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.urlopen(req, timeout=30)
    assert e.value.code == 405
    for p in ("/", "/lenses/DEMO-0006", f"/model?maker={MAKER.replace(' ', '+')}&model={MODEL}", "/api/lenses"):
        assert _get(srv, p)[0] == 200
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before


def test_a_token_is_required_off_localhost(dashboard):
    path = dashboard[3]
    with ProfileStore(path, create=False) as store, start(dashboard_app(store), token="s3cret-token") as srv:
        status, _h, body = _get(srv, "/api/lenses")
        assert status == 401 and b"needs its token" in body
        assert _get(srv, "/api/lenses", token="wrong")[0] == 401
        status, _h, body = _get(srv, "/api/lenses", token="s3cret-token")
        assert status == 200 and len(json.loads(body)["lenses"]) == 6


# ------------------------------------------------------- failed profiles (issue 21 item 1)
def _failed(store):
    """A profile of the lens the plan makes fail QA (DEMO-0006), and the checks it failed as judged."""
    p = next(p for p in store.profiles() if p.lens.serial == "DEMO-0006" and p.focus == 0.0)
    assert p.qa is not None and p.qa.verdict == "FAIL"
    return p, [c for c in p.qa.checks if c.passed is False]


def _stamp_of(fmt, body):
    """The text where each format states the stamp, read the way its consumers read the file."""
    import OpenEXR

    if fmt == "maps":
        with np.load(io.BytesIO(body)) as z:
            return str(z["notes"])
    if fmt in ("stmap", "stmap-redistort"):
        with OpenEXR.File(io.BytesIO(body)) as f:  # the EXR header, as Nuke shows it
            return str(f.header()["comments"])
    if fmt == "json":
        return "\n".join(json.loads(body)["stamp"])
    return body.decode()


def test_an_export_of_a_failed_profile_is_refused_unless_allowed(sqlite_served, caplog):
    from pipeline.exports.registry import FORMATS

    srv, store, _stored = sqlite_served
    p, failed = _failed(store)
    assert failed and failed[0].name == "holdout_d"  # the plan's failing lens: holdout d too large
    for query in ("", "?allow-failed=0", "?allow-failed=yes", "?allow_failed=1"):
        status, h, body = _get(srv, f"/profiles/{p.id}/export/opencv{query}")
        assert status == 409 and h["content-type"] == "application/json" and "content-disposition" not in h
        msg = json.loads(body)["error"]
        assert msg.startswith(f"lens {MAKER} {MODEL} serial DEMO-0006, focus 0: profile #{p.id} failed QA (holdout")
        assert msg.endswith("; not exported (?allow-failed=1 exports it anyway)")
    # allowed: served, logged (profile and client), and every format says FAILED QA where its readers look
    stamp = f"FAILED QA: profile #{p.id} at focus 0 was judged FAIL (holdout"
    for fmt in FORMATS:
        caplog.clear()
        with caplog.at_level("WARNING", logger="station.web"):
            status, h, body = _get(srv, f"/profiles/{p.id}/export/{fmt}?allow-failed=1")
        assert status == 200 and h["content-disposition"].startswith('attachment; filename="DEMO-0006-focus0-')
        assert stamp in _stamp_of(fmt, body), fmt
        (rec,) = [r for r in caplog.records if r.name == "station.web"]
        line = rec.getMessage()
        assert f"profile #{p.id} failed QA" in line and f"exported as {fmt} to client 127.0.0.1:" in line
    # the stamp is the first comment of the text formats, and OpenCV still reads the file
    status, _h, body = _get(srv, f"/profiles/{p.id}/export/opencv?allow-failed=1")
    comments = [line for line in body.decode().splitlines() if line.startswith("#")]
    assert comments[0].startswith("# OpenCV pinhole") and comments[1].startswith(f"# {stamp}")
    fs = cv2.FileStorage(body.decode(), cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    assert fs.getNode("camera_matrix").mat().shape == (3, 3)
    fs.release()
    # a passing profile: served without the parameter, no stamp, nothing logged
    good = next(q for q in store.profiles() if q.lens.serial == "DEMO-0001" and q.focus == 0.0)
    caplog.clear()
    with caplog.at_level("WARNING", logger="station.web"):
        for fmt in ("opencv", "json"):
            status, _h, body = _get(srv, f"/profiles/{good.id}/export/{fmt}")
            assert status == 200 and b"FAILED QA" not in body
    assert not [r for r in caplog.records if r.name == "station.web"]


def test_the_lens_document_offers_no_downloads_of_a_failed_profile(sqlite_served):
    from pipeline.exports.registry import FORMATS

    srv, store, _stored = sqlite_served
    status, doc = _json(srv, "/api/lenses/DEMO-0006")
    assert status == 200
    for f in doc["focus"]:
        for p in f["profiles"]:
            assert p["verdict"] == "FAIL" and p["downloads"] == []
            assert [d["url"] for d in p["downloads_failed_qa"]] == [
                f"/profiles/{p['id']}/export/{name}?allow-failed=1" for name in FORMATS
            ]
    status, doc = _json(srv, "/api/lenses/DEMO-0001")
    assert all(p["downloads_failed_qa"] == [] for f in doc["focus"] for p in f["profiles"])


def test_a_lensfun_download_under_the_name_of_an_installed_lens_is_refused(sqlite_served, tmp_path, monkeypatch):
    """The dashboard's lensfun file is checked against the installed lensfun databases as harp export's is."""
    srv, store, _stored = sqlite_served
    p = next(p for p in store.profiles() if p.focus == 1.0 and p.qa is not None and p.qa.passed)
    installed = tmp_path / "lensfun"
    installed.mkdir()
    (installed / "mine.xml").write_text(
        f"""<lensdatabase version="1"><lens><maker>{p.lens.maker}</maker><model>{p.lens.model}</model>
        <mount>C</mount><cropfactor>7.2</cropfactor></lens></lensdatabase>"""
    )
    monkeypatch.setenv("HARP_LENSFUN_DIRS", str(installed))
    status, _h, body = _get(srv, f"/profiles/{p.id}/export/lensfun")
    assert status == 404
    message = json.loads(body)["error"]
    assert "is in the installed lensfun database" in message and "mine.xml" in message
    monkeypatch.setenv("HARP_LENSFUN_DIRS", str(tmp_path / "none"))
    status, _h, body = _get(srv, f"/profiles/{p.id}/export/lensfun")
    assert status == 200 and b"<lensdatabase" in body


def test_a_lens_whose_serial_holds_a_slash_opens_from_its_link(tmp_path):
    """A serial with a '/' (`SN 12/345`, allowed by the configuration) is linked as %2F; its page and API answered
    404 `Not Found` (the route matched one path segment), so the dashboard's own link to the lens was dead."""
    from tests.station.store.test_database import profile, verdict

    serial = 'SN 12/345 ../ü "x" #1'
    with ProfileStore(tmp_path / "p.sqlite") as st:
        pid = st.put_profile(profile(lens=("Mk", "Md", serial), qa=verdict(0.012)))
    with ProfileStore(tmp_path / "p.sqlite", create=False) as st, start(dashboard_app(st)) as srv:
        status, lenses = _json(srv, "/api/lenses")
        assert status == 200
        (lens,) = lenses["lenses"]
        assert lens["serial"] == serial
        status, _h, body = _get(srv, lens["api"])
        assert status == 200, body
        doc = json.loads(body)
        assert doc["serial"] == serial and [p["id"] for f in doc["focus"] for p in f["profiles"]] == [pid]
        status, _h, body = _get(srv, lens["href"])
        assert status == 200 and "SN 12/345" in body.decode()
        assert _json(srv, "/api/lenses/SN%2012%2F999")[0] == 404  # another serial: not found, as before
