import contextlib
import json
from pathlib import Path

import cv2
import pytest

from pipeline import load_model
from pipeline.compare import compare_models
from pipeline.models import RadialFieldModel, RadialModel
from pipeline.render import HarpScene, render_harp
from station.cli import main
from tests.station.processes import default_stop_signals, group_members

W, H = 640, 480
LENS = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.03, 0.0, 0.005), center=(330, 230), tangential=(0.001, 0.0))


@pytest.fixture(scope="module")
def shots(tmp_path_factory):
    d = tmp_path_factory.mktemp("shots")
    paths = {}
    for i, ang in enumerate((3.0, 63.0, 123.0, 93.0)):
        img = render_harp(
            W, H, HarpScene(angle_deg=ang, spacing_px=40.0, phase_px=7.0 * i), lens=LENS, noise_sigma=1.5, seed=i
        ).image
        paths[ang] = d / f"shot{i}.pgm"
        assert cv2.imwrite(str(paths[ang]), img)
    same = render_harp(W, H, HarpScene(angle_deg=4.0, spacing_px=40.0, phase_px=20.0), lens=LENS, seed=9).image
    paths["same"] = d / "same_orientation.pgm"
    cv2.imwrite(str(paths["same"]), same)
    noisy = render_harp(
        W, H, HarpScene(angle_deg=33.0, spacing_px=40.0, phase_px=3.0), lens=LENS, noise_sigma=7.5, seed=5
    ).image  # five times the others' noise: a dim or blurred shot
    paths["noisy"] = d / "noisy.pgm"
    cv2.imwrite(str(paths["noisy"]), noisy)
    small = render_harp(320, 240, HarpScene(angle_deg=60.0, spacing_px=40.0), lens=None, seed=3).image
    paths["small"] = d / "small.pgm"
    cv2.imwrite(str(paths["small"]), small)
    return paths


def _run(capsys, *argv):
    code = main(["calibrate", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_radial_fit_with_holdout_json(shots, tmp_path, capsys):
    out_path = tmp_path / "lens.yaml"
    code, out, err = _run(
        capsys,
        shots[3.0],
        shots[63.0],
        shots[123.0],
        "--model",
        "radial",
        "--holdout",
        shots[93.0],
        "--out",
        out_path,
        "--json",
    )
    assert code == 0, err
    rep = json.loads(out)
    assert rep["model"] == str(out_path)
    assert rep["choice"]["label"] == "radial4+tangential+prism"
    assert rep["before"]["d"] > 0.3 and rep["fit"]["d"] < 0.01 and rep["fit"]["d_max"] < 0.05
    assert rep["holdout"]["d"] < 0.01 and rep["holdout"]["images"][0]["d_before"] > 0.2
    assert len(rep["images"]) == 3
    assert not any("far from straight" in w for w in rep["warnings"]), rep["warnings"]  # alike shots: none named
    model = load_model(out_path)
    assert compare_models(model, LENS, W, H).rms < 0.01
    text = out_path.read_text()
    assert "holdout" in text and "sha256" in text
    # issue 21 item 9: the held-out shot's checksum too, as every fitted shot's (hashlib on the file's bytes)
    import hashlib

    import yaml

    prov = yaml.safe_load(text)["provenance"]
    want = hashlib.sha256(Path(shots[93.0]).read_bytes()).hexdigest()
    assert prov["holdout"] == [{"path": str(shots[93.0]), "sha256": want}]


def test_auto_chooses_by_cross_validation_and_says_so(shots, tmp_path, capsys):
    out_path = tmp_path / "auto.yaml"
    code, out, err = _run(capsys, shots[3.0], shots[63.0], shots[123.0], "--out", out_path, "--json")
    assert code == 0, err
    rep = json.loads(out)
    ch = rep["choice"]
    assert ch["folds"] == "images" and "leave-one-shot-out" in ch["reason"]
    assert ch["model"] == "radial"  # poly candidates do not generalise as well from 2 shots
    labels = [r["label"] for r in ch["table"]]
    assert ch["label"] in labels and "poly5" in labels
    assert rep["fit"]["d"] < 0.01 and "holdout" not in rep
    assert compare_models(load_model(out_path), LENS, W, H).rms < 0.01


def test_table_output(shots, tmp_path, capsys):
    code, out, err = _run(
        capsys, shots[3.0], shots[63.0], "--model", "poly", "--degree", "4", "--out", tmp_path / "p.yaml"
    )
    assert code == 0, err
    assert "poly4" in out and "d after" in out and "wrote" in out


@pytest.mark.parametrize(
    "args,needle",
    [
        (("same_a", "same_b"), "orientation"),
        ((3.0, "small"), "different sizes"),
        ((3.0, "missing"), "missing.pgm"),
        ((3.0, 63.0, "--degree", "3"), "need --model radial or poly"),
        ((3.0, 63.0, "--model", "poly", "--degree", "12"), "3..11"),
    ],
)
def test_bad_input_one_line_exit_2(shots, tmp_path, capsys, args, needle):
    resolved = []
    for a in args:
        if a == "same_a":
            a = shots[3.0]
        elif a == "same_b":
            a = shots["same"]
        elif a == "missing":
            a = tmp_path / "missing.pgm"
        elif a in shots:
            a = shots[a]
        resolved.append(a)
    out_path = tmp_path / "x.yaml"
    code, out, err = _run(capsys, *resolved, "--out", out_path)
    assert code == 2
    assert err.startswith("harp calibrate: ") and err.count("\n") == 1 and needle in err, err
    assert not out_path.exists()


def test_table_names_each_shot_readably(shots, tmp_path, capsys):
    # long directories must not turn every row into the same truncated "/tmp/pytest-…"
    code, out, err = _run(
        capsys, shots[3.0], shots[63.0], "--model", "radial", "--holdout", shots[93.0], "--out", tmp_path / "r.yaml"
    )
    assert code == 0, err
    rows = [ln for ln in out.splitlines() if "shot" in ln and ".pgm" in ln]
    assert any("shot0.pgm" in r for r in rows) and any("shot1.pgm" in r for r in rows)
    assert any("holdout shot3.pgm" in r for r in rows), out


def test_warns_when_the_model_makes_the_holdout_worse(real_harp_dir, tmp_path, capsys):
    # a free degree-5 polynomial fitted on two real shots bends the third one further
    r = real_harp_dir
    code, out, err = _run(
        capsys,
        r / "IMG_6931.pgm",
        r / "IMG_6950.pgm",
        "--holdout",
        r / "IMG_6964.pgm",
        "--model",
        "poly",
        "--degree",
        "5",
        "--out",
        tmp_path / "p5.yaml",
        "--json",
    )
    assert code == 0, err
    rep = json.loads(out)
    assert rep["holdout"]["d"] > rep["holdout"]["images"][0]["d_before"]
    assert any("less straight" in w and "does not generalise" in w for w in rep["warnings"]), rep["warnings"]


def test_unwritable_out_is_reported_before_any_work(shots, tmp_path, capsys, monkeypatch):
    import station.cli.calibrate as cc

    def no_measuring(*a, **k):
        raise AssertionError("measured although the model file cannot be written")

    monkeypatch.setattr(cc, "_measure_one", no_measuring)
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    for out, reason in (
        (tmp_path / "no" / "lens.yaml", "no such directory"),
        (blocker / "lens.yaml", "not a directory"),
        (tmp_path, "is a directory"),
    ):
        code, _, err = _run(capsys, shots[3.0], shots[63.0], "--out", out)
        assert code == 2 and err.startswith(f"harp calibrate: {out}: cannot write model file (")
        assert reason in err and err.count("\n") == 1, err


def test_division_option(shots, tmp_path, capsys):
    out_path = tmp_path / "div.yaml"
    code, out, err = _run(
        capsys,
        shots[3.0],
        shots[63.0],
        shots[123.0],
        "--model",
        "radial",
        "--division",
        "1",
        "--out",
        out_path,
        "--json",
    )
    assert code == 0, err
    rep = json.loads(out)
    assert rep["choice"]["label"] == "radial4+tangential+prism+division1" and rep["fit"]["d"] < 0.01
    model = load_model(out_path)
    assert model.division is not None and len(model.division) == 1
    assert compare_models(model, LENS, W, H).rms < 0.01
    code, out, err = _run(capsys, shots[3.0], shots[63.0], "--model", "radial", "--division", "7", "--out", out_path)
    assert code == 2 and err.count("\n") == 1 and "--division" in err and "0..3" in err
    code, out, err = _run(capsys, shots[3.0], shots[63.0], "--division", "1", "--out", out_path)
    assert code == 2 and "need --model radial" in err


def test_trefoil_option_and_a_given_spec_the_shots_do_not_support_says_so(shots, tmp_path, capsys):
    """``--trefoil`` adds the three-fold term (the model file holds it, the label names it); a given spec
    the shots' orientations cannot support (the term needs 4, here 3) is fitted, and the reason in the
    output and in the model file says why it is not well supported. With 4 orientations it is not."""
    out_path = tmp_path / "tref.yaml"
    three = (shots[3.0], shots[63.0], shots[123.0])
    code, out, err = _run(capsys, *three, "--model", "radial", "--trefoil", "--out", out_path, "--json")
    assert code == 0, err
    rep = json.loads(out)
    assert rep["choice"]["label"] == "radial4+tangential+prism+trefoil"
    assert (
        "not well supported" in rep["choice"]["reason"]
        and ">= 4 distinct string orientations" in rep["choice"]["reason"]
    )
    assert load_model(out_path).trefoil is not None
    assert "not well supported" in out_path.read_text()
    code, out, err = _run(capsys, *three, shots[93.0], "--model", "radial", "--trefoil", "--out", out_path, "--json")
    assert code == 0, err
    assert json.loads(out)["choice"]["reason"] == "given on the command line"
    code, out, err = _run(capsys, *three, "--model", "poly", "--trefoil", "--out", out_path)
    assert code == 2 and err.count("\n") == 1 and "--trefoil" in err and "radial only" in err


def test_field_option(shots, tmp_path, capsys):
    """``--field`` adds a residual field to the radial model: the model file holds it, the label names it;
    on this radial lens it stays near the radial fit. A bad grid is one line, exit 2."""
    out_path = tmp_path / "field.yaml"
    four = (shots[3.0], shots[63.0], shots[123.0], shots[93.0])
    code, out, err = _run(capsys, *four, "--model", "radial", "--field", "6x5@0.01", "--out", out_path, "--json")
    assert code == 0, err
    rep = json.loads(out)
    assert rep["choice"]["label"] == "radial4+tangential+prism+field6x5@0.01" and rep["fit"]["d"] < 0.01
    model = load_model(out_path)
    assert isinstance(model, RadialFieldModel) and model.shape == (5, 6)
    assert compare_models(model, LENS, W, H).rms < 0.01
    code, out, err = _run(capsys, *four, "--model", "radial", "--field", "6x2", "--out", out_path)
    assert code == 2 and err.count("\n") == 1 and "--field 6x2" in err and "4..24" in err
    code, out, err = _run(capsys, *four, "--field", "6x5", "--out", out_path)
    assert code == 2 and "need --model radial" in err


def test_field_auto_chooses_knots_and_penalty_by_cross_validation(shots, tmp_path, capsys):
    """``--field auto``: the radial model and it with every field of ``field_candidates`` are
    cross-validated; on this radial lens the radial model wins and the table lists the fields. Without
    ``--model`` the model is chosen first; with fewer than four orientations no field is offered."""
    out_path = tmp_path / "auto-field.yaml"
    four = (shots[3.0], shots[63.0], shots[123.0], shots[93.0])
    code, out, err = _run(capsys, *four, "--model", "radial", "--field", "auto", "--out", out_path, "--json")
    assert code == 0, err
    rep = json.loads(out)
    labels = [r["label"] for r in rep["choice"]["table"]]
    assert labels[0] == "radial4+tangential+prism" and len(labels) == 7
    assert all("+field" in lab for lab in labels[1:])
    assert rep["choice"]["label"] == "radial4+tangential+prism", rep["choice"]["reason"]
    assert rep["choice"]["reason"].startswith("radial4+tangential+prism given; residual field: ")
    assert isinstance(load_model(out_path), RadialModel)
    # with the model chosen too: the choice first, then the field on top of it (pipeline.select.select_field)
    code, out, err = _run(capsys, *four, "--field", "auto", "--out", out_path, "--json")
    assert code == 0, err
    rep = json.loads(out)
    assert "; residual field: " in rep["choice"]["reason"] and "+field" not in rep["choice"]["label"]
    # three orientations cannot tell a field: the model is kept and the reason says why
    code, out, err = _run(capsys, *four[:3], "--model", "radial", "--field", "auto", "--out", out_path, "--json")
    assert code == 0, err
    assert "a field needs >= 4 distinct string orientations, the shots have 3" in json.loads(out)["choice"]["reason"]


def test_workers_give_the_same_choice_and_figures_as_one_process(shots, tmp_path, capsys, monkeypatch):
    """Issue 8 item 6: shots measured and candidates cross-validated by two worker processes; the
    report is the one a single process writes, and hopeless candidates are shown as stopped."""
    import os

    args = [shots[3.0], shots[63.0], shots[123.0], "--json"]
    code, out2, err = _run(capsys, *args, "--out", tmp_path / "two.yaml")
    assert code == 0, err
    monkeypatch.setattr(os, "cpu_count", lambda: 1)
    code, out1, err = _run(capsys, *args, "--out", tmp_path / "one.yaml")
    assert code == 0, err
    two, one = json.loads(out2), json.loads(out1)
    assert two["choice"]["label"] == one["choice"]["label"]
    assert two["fit"] == pytest.approx(one["fit"], rel=1e-9)
    for a, b in zip(two["choice"]["table"], one["choice"]["table"]):
        assert a["label"] == b["label"] and a["failure"] == b["failure"]
        assert (a["cv_d"] is None) == (b["cv_d"] is None)
        if a["cv_d"] is not None:
            assert a["cv_d"] == pytest.approx(b["cv_d"], rel=1e-9)
    stopped = [r for r in two["choice"]["table"] if r["failure"] and r["failure"].startswith("stopped")]
    assert stopped and all(r["cv_d_bound"] > 2 * min(x["cv_d"] or 1e9 for x in two["choice"]["table"]) for r in stopped)
    monkeypatch.undo()
    code, out, err = _run(capsys, shots[3.0], shots[63.0], shots[123.0], "--out", tmp_path / "t.yaml")
    assert code == 0 and "(stopped)" in out


_BARRIER = None


def _meet(_):
    """A job that returns only when three jobs run at once (forked workers inherit the barrier)."""
    return _BARRIER.wait(timeout=30)


def test_three_shots_are_measured_at_once(monkeypatch):
    """Three shots on two cores: three workers, so that no worker measures two shots while another
    waits (with two, the third job could not start before one of the first two returned)."""
    import multiprocessing as mp
    import os

    from station.cli import calibrate

    global _BARRIER
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    _BARRIER = mp.get_context("fork").Barrier(3)
    with calibrate._workers(3, balance=True) as map_fn:
        assert sorted(map_fn(_meet, range(3))) == [0, 1, 2]


def _children(pid: int) -> list[int]:
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            return [int(c) for c in f.read().split()]
    except OSError:
        return []


@pytest.mark.parametrize("moment", ["as its workers are forked", "while they measure"])
def test_ctrl_c_is_one_line_exit_130_and_no_model_file(real_harp_dir, tmp_path, moment):
    """Ctrl-C at the terminal (SIGINT to the whole process group: the command and its forked workers)
    at a moment the process table shows, not after a delay: the command's one line, exit 130, no
    traceback from a worker, no model file, no half-written file, no worker left."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out_path = tmp_path / "lens.yaml"
    photos = sorted(real_harp_dir.glob("*.pgm"))
    cmd = [sys.executable, "-m", "station.cli", "calibrate", *map(str, photos * 2), "--out", str(out_path)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 60
    while not _children(proc.pid) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.001)
    if moment == "while they measure":
        time.sleep(0.1)
    assert proc.poll() is None, proc.communicate()
    os.killpg(proc.pid, signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:  # a hang (as before the workers were forked deaf): fail, leave nothing
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        pytest.fail(f"harp calibrate did not end after Ctrl-C: {err}")
    assert proc.returncode == 130, (out, err)
    assert err == "harp: interrupted\n"
    assert not out_path.exists() and list(tmp_path.iterdir()) == []
    deadline = time.monotonic() + 10
    while group_members(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert group_members(proc.pid) == []  # the workers ended too


@pytest.mark.parametrize(
    "sig, whom",
    [
        ("SIGTERM", "group"),  # systemctl stop (KillMode=control-group), docker stop of a container's processes
        ("SIGTERM", "command"),  # kill PID, timeout(1)
        ("SIGHUP", "group"),  # the terminal or SSH connection closed
    ],
)
def test_a_stop_signal_is_answered_as_a_ctrl_c(real_harp_dir, tmp_path, sig, whom):
    """SIGTERM or SIGHUP while the workers measure, to the whole process group or to the command alone: the
    command's one line naming the signal, exit 128 + signal, no traceback or warning from a worker or from
    multiprocessing (before: the process died where it stood, "leaked semaphore objects" on stderr), no model
    file, no worker left."""
    import os
    import signal
    import subprocess
    import sys
    import time

    signum = getattr(signal, sig)
    out_path = tmp_path / "lens.yaml"
    photos = sorted(real_harp_dir.glob("*.pgm"))
    cmd = [sys.executable, "-m", "station.cli", "calibrate", *map(str, photos * 2), "--out", str(out_path)]
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=default_stop_signals,  # as from a terminal or a service manager, whatever started the tests
    )
    try:
        deadline = time.monotonic() + 60
        while not _children(proc.pid) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.001)
        time.sleep(0.1)
        assert proc.poll() is None, proc.communicate()
        if whom == "group":
            os.killpg(proc.pid, signum)
        else:
            os.kill(proc.pid, signum)
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 128 + signum, (out, err)
        assert err == f"harp: stopped by {sig}\n"
        assert not out_path.exists() and list(tmp_path.iterdir()) == []
        deadline = time.monotonic() + 10
        while group_members(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert group_members(proc.pid) == []  # the workers ended too
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()


def test_a_sighup_the_caller_ignores_stays_ignored(real_harp_dir, tmp_path):
    """Under nohup (SIGHUP ignored) a closed terminal does not stop the command: it fits and writes its model."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out_path = tmp_path / "lens.yaml"
    photos = sorted(real_harp_dir.glob("*.pgm"))
    cmd = [sys.executable, "-m", "station.cli", "calibrate", *map(str, photos), "--out", str(out_path)]

    def nohup() -> None:
        signal.signal(signal.SIGHUP, signal.SIG_IGN)

    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=nohup
    )
    try:
        deadline = time.monotonic() + 60
        while not _children(proc.pid) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.001)
        assert proc.poll() is None, proc.communicate()
        os.killpg(proc.pid, signal.SIGHUP)
        out, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, (out, err)
        assert out_path.is_file()
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()


def test_a_shot_measured_far_worse_than_the_others_is_named_with_what_to_do(shots, tmp_path, capsys):
    """One shot drawn with five times the others' noise: the correction leaves its edges far less straight than the
    median edge, and the warning names that shot (truth: which shot was drawn noisy), not the others."""
    code, out, err = _run(
        capsys, shots[3.0], shots[63.0], shots[123.0], shots["noisy"], "--model", "radial", "--out",
        tmp_path / "lens.yaml", "--json",
    )  # fmt: skip
    assert code == 0, err
    named = [w for w in json.loads(out)["warnings"] if "far from straight" in w]
    assert len(named) == 1 and named[0].startswith(f"{shots['noisy']}: ") and "turn the harp" in named[0], named


def test_shots_through_a_lens_whose_centre_moves_are_told_from_a_stable_lens(shots, tmp_path, capsys):
    """Five shots at five angles through LENS with its distortion centre moved by hand-chosen 6-9 px per shot (what
    an image stabiliser does between shots): each shot held out is bent by its own move, which moving the others'
    correction takes away: ``own_shift`` says ``moving`` and a warning says what to do. The module's stable shots
    (LENS itself, four angles): not moving, no such warning. The profile keeps the record, as a session's."""
    d = tmp_path / "moving"
    d.mkdir()
    paths = []
    for i, (ang, (mx, my)) in enumerate(
        zip((3.0, 39.0, 75.0, 111.0, 147.0), ((0, 0), (8, -5), (-7, 4), (5, 7), (-6, -6)))
    ):
        moved = RadialModel.for_image(W, H, k=LENS.k, center=(330 + mx, 230 + my), tangential=LENS.tangential)
        img = render_harp(W, H, HarpScene(angle_deg=ang, spacing_px=40.0, phase_px=5.0 * i), lens=moved, seed=20 + i)
        paths.append(d / f"m{i}.pgm")
        assert cv2.imwrite(str(paths[-1]), img.image)
    code, out, err = _run(capsys, *paths, "--model", "radial", "--out", tmp_path / "m.yaml", "--json")
    assert code == 0, err
    rep = json.loads(out)
    own = rep["own_shift"]
    assert own["judged"] and own["moving"] and own["ratio_median"] < 0.5 and len(own["per_orientation"]) == 5
    said = [w for w in rep["warnings"] if "wants the correction moved" in w]
    assert len(said) == 1 and "switch stabilisation off" in said[0], rep["warnings"]
    from pipeline.model_file import read_model_file
    from station.profile import Profile

    assert Profile.from_model_file(read_model_file(tmp_path / "m.yaml")).details["own_shift"] == own
    code, out, err = _run(capsys, shots[3.0], shots[63.0], shots[123.0], shots[93.0], "--model", "radial", "--out",
                          tmp_path / "s.yaml", "--json")  # fmt: skip
    rep = json.loads(out)
    assert code == 0 and rep["own_shift"]["judged"] and not rep["own_shift"]["moving"]
    assert rep["own_shift"]["ratio_median"] > 0.9 and not any(
        "wants the correction moved" in w for w in rep["warnings"]
    )


def test_two_shots_at_one_angle_tell_whether_the_lens_moved_between_them(shots, tmp_path, capsys):
    """A fourth shot at the first one's angle, the harp not moved (same angle, same string phase): through LENS with
    its distortion centre moved by (8, -5) px (by hand), ``twins`` reads the move across the strings (at 3 degrees:
    (8, -5) . (-sin 3, cos 3) = -5.41 px) and a warning names both shots; through LENS itself, no move and no
    warning. The profile keeps the record."""
    d = tmp_path / "twins"
    d.mkdir()
    scene = HarpScene(angle_deg=3.0, spacing_px=40.0, phase_px=0.0)  # shots[3.0]'s harp
    moved = RadialModel.for_image(W, H, k=LENS.k, center=(338, 225), tangential=LENS.tangential)
    for name, lens, seed in (("moved", moved, 30), ("still", LENS, 31)):
        path = d / f"{name}.pgm"
        assert cv2.imwrite(str(path), render_harp(W, H, scene, lens=lens, noise_sigma=1.5, seed=seed).image)
    code, out, err = _run(
        capsys, shots[3.0], shots[63.0], shots[123.0], d / "moved.pgm", "--model", "radial", "--out",
        tmp_path / "m.yaml", "--json",
    )  # fmt: skip
    assert code == 0, err
    rep = json.loads(out)
    (pair,) = rep["twins"]
    assert pair["paths"] == [str(shots[3.0]), str(d / "moved.pgm")] and pair["moved"], pair
    assert abs(abs(pair["move_px"]) - 5.41) < 0.1 * 5.41 and pair["ratio"] < 0.8, pair
    said = [w for w in rep["warnings"] if "between these two shots at one angle" in w]
    assert len(said) == 1 and said[0].startswith(f"{shots[3.0]} and {d / 'moved.pgm'} ") and "switch" in said[0]
    from pipeline.model_file import read_model_file
    from station.profile import Profile

    assert Profile.from_model_file(read_model_file(tmp_path / "m.yaml")).details["twins"] == rep["twins"]
    code, out, err = _run(
        capsys, shots[3.0], shots[63.0], shots[123.0], d / "still.pgm", "--model", "radial", "--out",
        tmp_path / "s.yaml", "--json",
    )  # fmt: skip
    assert code == 0, err
    rep = json.loads(out)
    (pair,) = rep["twins"]
    assert not pair["moved"] and abs(pair["move_px"]) < 0.5 and pair["ratio"] > 0.95, pair
    assert not any("at one angle" in w for w in rep["warnings"]), rep["warnings"]
    code, out, err = _run(
        capsys, shots[3.0], shots[63.0], shots[123.0], d / "still.pgm", "--model", "radial", "--out",
        tmp_path / "s.yaml",
    )  # fmt: skip
    assert code == 0, err
    (line,) = [ln for ln in out.splitlines() if ln.startswith("twins: ")]
    assert line.startswith(f"twins: {shots[3.0].name} and still.pgm (strings at ") and "(limit 1 px)" in line, line
    assert f"{abs(pair['move_px']):.2f} px" in line, line
