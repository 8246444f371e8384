"""The QA report (station/qa/report.py): Markdown + PNG plots, written by ``harp qa --report``."""

import re

import cv2
import numpy as np
import pytest

from station.cli import main
from station.config import Identity
from station.profile import Holdout, Merit, Provenance, UncertaintySummary
from station.qa.plots import edge_residual_table
from station.qa.report import session_shots
from station.qa.verdicts import session_profiles
from station.session.directory import SessionDir
from station.store import ProfileStore
from tests.station.qa_session import ANGLES, W, build_session


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    return build_session(tmp_path_factory.mktemp("rep"), focus=(0.3,))


def png(path):
    img = cv2.imread(str(path))
    assert img is not None, f"{path} is not a readable PNG"
    return img


def test_session_report_has_every_plot(session, tmp_path, capsys):
    out = tmp_path / "report"
    code = main(["qa", str(session), "--report", str(out), "--max-distortion", "0.01", "--no-record"])
    capsys.readouterr()
    assert code == 1  # the report of a FAIL says why
    md = (out / "report.md").read_text()
    assert "**Verdict: FAIL**" in md and "distortion " in md and "> 0.01 px" in md
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    expected = {"field_f0.png", "residuals_f0.png", "uncertainty_f0.png"} | {
        f"overlay_f0_o{j}.jpg" for j in range(len(ANGLES))
    }
    assert set(links) == expected
    for name in links:
        img = png(out / name)
        assert min(img.shape[:2]) >= 300 and img.std() > 5  # a real picture, not a blank canvas
    # the overlays are the frames themselves (plus the legend panel)
    assert png(out / "overlay_f0_o0.jpg").shape[1] == W
    assert "bootstrap" in md or "uncertainty" in md
    page = (out / "index.html").read_text()  # the same report as a page embedding the same PNGs
    assert sorted(re.findall(r'<img alt="[^"]*" src="([^"]+)">', page)) == sorted(links)
    assert '<strong class="verdict fail">Verdict: FAIL</strong>' in page and "&gt; 0.01 px" in page
    assert ".verdict.fail{background:#cf222e}" in page  # the verdict in colour


def test_residuals_drop_after_correction(session):
    ((_, prof),) = session_profiles(session)
    with SessionDir.open(session) as s:
        shots = session_shots(s, 0, t=30)
    assert [sh.orientation_deg for sh in shots] == list(ANGLES)
    rows = edge_residual_table(shots, prof.model)
    before = np.array([r[2] for r in rows])
    after = np.array([r[3] for r in rows])
    assert len(rows) > 4 * len(ANGLES)
    assert after.mean() < 0.2 * before.mean() and np.median(after) < 0.01


def test_lens_report_without_frames(session, tmp_path, capsys):
    store = tmp_path / "p.sqlite"
    ((_, prof),) = session_profiles(session)
    with ProfileStore(store) as st:
        st.put_profile(
            prof.with_(
                lens=Identity("Sim", "SIM-12mm", "U1"),
                camera=Identity("c", "m", "s"),
                merit=Merit(holdout=Holdout(prof.merit.holdout_d), field_uncertainty=UncertaintySummary(0.001, 0.004)),
                provenance=Provenance(station="t", session_dir=str(session), software="harp-station 0"),
            )
        )
    out = tmp_path / "r"
    code = main(["qa", "U1", "--store", str(store), "--report", str(out)])
    capsys.readouterr()
    assert code == 0
    md = (out / "report.md").read_text()
    assert "**Verdict: PASS**" in md and "stored: RMS 0.0010 px, max 0.0040 px" in md
    assert sorted(p.name for p in out.glob("*.png")) == ["field_f0.png"]
    png(out / "field_f0.png")


def test_report_of_an_auto_session_bootstraps_exactly_the_stored_spec(session, tmp_path, monkeypatch, capsys):
    # pipeline.model: auto: the report's bootstrap once asked the fit for model 'auto' ("not available");
    # it must refit the spec the profile records, whatever the configuration says
    import shutil

    import pipeline.uncertainty

    auto = tmp_path / "auto"
    shutil.copytree(session, auto)
    cfg = auto / "config.yaml"
    cfg.write_text(cfg.read_text().replace("model: radial", "model: auto"))
    with SessionDir.open(auto) as s:
        assert s.config.pipeline.model == "auto"
    ((_, prof),) = session_profiles(auto)
    assert prof.spec is not None and prof.spec.label == "radial4+tangential"
    real = pipeline.uncertainty.bootstrap_field_uncertainty
    specs = []

    def spy(lines, width, height, spec=None, **kw):
        specs.append(spec)
        return real(lines, width, height, spec, **kw)

    monkeypatch.setattr(pipeline.uncertainty, "bootstrap_field_uncertainty", spy)
    out = tmp_path / "report"
    assert main(["qa", str(auto), "--report", str(out), "--no-record"]) == 0
    capsys.readouterr()
    assert specs == [prof.spec]
    md = (out / "report.md").read_text()
    assert "uncertainty_f0.png" in md and "not available" not in md
    png(out / "uncertainty_f0.png")


def test_figures_drawn_in_worker_processes_are_the_ones_drawn_here(session, tmp_path):
    from station.qa.plots import PARALLEL_MIN_FIGURES, Figure, draw_figures

    ((_, prof),) = session_profiles(session)
    with SessionDir.open(session) as s:
        shots = session_shots(s, 0, t=30)
    rows = edge_residual_table(shots, prof.model)

    def figures(out):
        out.mkdir()
        figs = [Figure("field", (prof.model, prof.width, prof.height, out / "field.png"), {"title": "t"})]
        figs.append(Figure("residuals", (rows, [sh.group for sh in shots], out / "res.png"), {}))
        for k in range(3):  # enough figures for the workers to be used
            figs += [
                Figure("overlay", (sh.image, sh.measurement, out / f"o{k}_{j}.png"), {}) for j, sh in enumerate(shots)
            ]
        return figs

    here, there = figures(tmp_path / "here"), figures(tmp_path / "there")
    assert len(there) >= PARALLEL_MIN_FIGURES  # the workers are used
    draw_figures(here, workers=1)
    draw_figures(there, workers=2)
    for a, b in zip(here, there):
        assert np.array_equal(png(a.path), png(b.path))
    # an error in a worker is raised here, as it would be in this process
    broken = figures(tmp_path / "broken")
    broken[-1] = Figure("overlay", (shots[0].image, shots[0].measurement, tmp_path / "missing" / "o.png"), {})
    with pytest.raises(OSError, match="missing"):
        draw_figures(broken, workers=2)


def test_report_overlays_are_sized_for_a_screen(session, tmp_path):
    # a 5 MP camera's overlay: shrunk to SCREEN_MAX_SIDE along its longer side, JPEG (the drawing is the
    # full-size overlay's, averaged down)
    from station.qa.overlay import SCREEN_MAX_SIDE, render_overlay
    from station.qa.plots import Figure, draw_figure

    with SessionDir.open(session) as s:
        shot = session_shots(s, 0, t=30)[0]
    big = cv2.resize(np.asarray(shot.image, np.float32), (2592, 1944), interpolation=cv2.INTER_LINEAR)
    path = draw_figure(Figure("overlay", (big, shot.measurement, tmp_path / "o.jpg"), {"title": "big"}))
    data = path.read_bytes()
    assert data[:2] == b"\xff\xd8" and len(data) < 400_000  # JPEG; a full-size PNG of it is ~5 MB
    got = png(path)
    full = render_overlay(big, shot.measurement, "big")
    assert max(got.shape[:2]) == SCREEN_MAX_SIDE
    assert got.shape[1] / got.shape[0] == pytest.approx(full.shape[1] / full.shape[0], rel=2e-3)
    # the same picture: the full-size drawing shrunk the same way, within JPEG's error
    want = cv2.resize(full, (got.shape[1], got.shape[0]), interpolation=cv2.INTER_AREA)
    assert np.mean(np.abs(got.astype(float) - want)) < 3.0


def overlay_files(out):
    return sorted(p.name for p in out.glob("overlay_*"))


@pytest.mark.parametrize(
    "overlays, limit, kept",
    [
        ("all", None, True),
        ("none", None, False),
        ("failed", None, False),  # the session passes: nothing failed, no overlay kept
        ("failed", "0.01", True),  # the same focus setting failing QA keeps its overlays
    ],
)
def test_overlay_retention_option(session, tmp_path, capsys, overlays, limit, kept):
    out = tmp_path / "report"
    args = ["qa", str(session), "--report", str(out), "--overlays", overlays, "--no-record"]
    code = main(args + (["--max-distortion", limit] if limit else []))
    capsys.readouterr()
    assert code == (1 if limit else 0)
    md = (out / "report.md").read_text()
    if kept:
        assert overlay_files(out) == [f"overlay_f0_o{j}.jpg" for j in range(len(ANGLES))]
        assert "Not kept" not in md
    else:
        assert overlay_files(out) == [] and "overlay_" not in md
        assert f"Not kept (overlays: {overlays}" in md
    assert sorted(p.name for p in out.glob("*.png")) == ["field_f0.png", "residuals_f0.png", "uncertainty_f0.png"]


def test_overlay_retention_from_the_session_configuration(session, tmp_path, capsys):
    import shutil

    copy = tmp_path / "s"
    shutil.copytree(session, copy)
    with open(copy / "config.yaml", "a") as fh:
        fh.write("report:\n  overlays: none\n")
    out = tmp_path / "r1"
    assert main(["qa", str(copy), "--report", str(out), "--no-record"]) == 0
    assert overlay_files(out) == [] and "Not kept (overlays: none)" in (out / "report.md").read_text()
    out = tmp_path / "r2"  # the option overrides the configuration
    assert main(["qa", str(copy), "--report", str(out), "--overlays", "all", "--no-record"]) == 0
    capsys.readouterr()
    assert len(overlay_files(out)) == len(ANGLES)


def test_overlay_retention_bad_value_is_one_line(session, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["qa", str(session), "--report", str(tmp_path / "r"), "--overlays", "some"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "--overlays" in err and "Traceback" not in err


def test_the_report_says_which_model_was_fitted_and_warns_when_the_shots_do_not_support_it(session, tmp_path, capsys):
    """Each focus setting's model and how it was chosen; a model the shots do not support well (here named by the
    configuration: a free polynomial needs four string orientations, the session has three) is a warning at the top
    of the report and under the model, in the Markdown and the page (issue 19: "says so in the reason and the QA
    report"). Truth: the orientations drawn (three) against what the model needs, not the fit's own words."""
    out = tmp_path / "ok"
    assert main(["qa", str(session), "--report", str(out), "--no-record"]) == 0
    md = (out / "report.md").read_text()
    assert "### Model" in md and "`radial4+tangential`: pipeline.model of the configuration" in md
    assert "not well supported" not in md

    two = build_session(
        tmp_path / "three", focus=(0.3,), angles=(0.0, 60.0, 120.0), pipeline={"model": "poly5", "degree": 5}
    )
    out = tmp_path / "two-report"
    main(["qa", str(two), "--report", str(out), "--no-record"])
    capsys.readouterr()
    md = (out / "report.md").read_text()
    warning = (
        "not well supported: poly5 needs >= 4 distinct string orientations (>= 10 deg apart), "
        "the shots have 3; add shots at other angles"
    )
    assert md.count(warning) == 2, md  # at the top, and under the focus setting's model
    top, below = md.split("## focus 0.3", 1)
    assert f"focus 0.3, poly5: {warning}" in top and "**warning**" in top
    assert "`poly5`: pipeline.model of the configuration" in below
    page = (out / "index.html").read_text()
    assert page.count("not well supported: poly5 needs &gt;= 4") == 2
