"""``harp export --format lcp``: the Adobe lens profile through the command, a second setting added to the
same file, and bad input (one line, exit 2, nothing written or changed). The profile is applied by
RawTherapee's equations (:mod:`tests.pipeline.lcp_equations`) against the lens of the model file."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest

from station.cli import main
from station.files import write_model_file
from tests.pipeline.export_support import compare_points, wide_radial
from tests.pipeline.lcp_equations import correct_distortion, mapper, read_profiles

W, H = 400, 300
LENS = wide_radial(60.0, W, H)
OPTICS = ["--lens-maker", "Sim", "--lens-model", "L60", "--focal-mm", "4", "--pixel-pitch-um", "12"]


def run_main(*argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    path = tmp_path_factory.mktemp("lcp") / "lens.yaml"
    write_model_file(path, LENS, width=W, height=H)
    return path


def test_two_focus_distances_in_one_profile_each_within_its_stated_error(model, tmp_path):
    out = tmp_path / "lens.lcp"
    stated = []
    for dist in ("0.5", "3"):
        code, stdout, stderr = run_main(
            "export", model, "--format", "lcp", *OPTICS, "--distance", dist, "-o", out, "--json"
        )
        assert code == 0, stderr
        fig = json.loads(stdout)
        assert fig["format"] == "lcp" and "SensorFormatFactor 7.2111 derived" in " ".join(fig["notes"])
        stated.append(fig["conversion"])
    prof = read_profiles(out.read_bytes())
    assert [(m["focal"], m["focus"]) for m in prof["models"]] == [(4.0, 0.5), (4.0, 3.0)]
    assert prof["sensor_format_factor"] == pytest.approx(7.2111) and prof["lens"] == "L60"
    xs, ys = np.linspace(0, W - 1, 40), np.linspace(0, H - 1, 30)
    p = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    for m, conv in zip(prof["models"], stated, strict=True):
        q = correct_distortion(mapper(m, W, H, m["focal"]), p, prof["fisheye"])
        rms, mx = compare_points(LENS, p, q, W, H)
        stated_fig = f"RMS {conv['rms_mod_h_px']:.4f} / max {conv['max_mod_h_px']:.4f} px"
        print(
            f"\nlcp at {m['focus']:g} m in RawTherapee's equations: RMS {rms:.4f} / max {mx:.4f} px; stated {stated_fig}"
        )
        assert rms <= 1.3 * conv["rms_mod_h_px"] + 5e-4 and mx <= 1.3 * conv["max_mod_h_px"] + 5e-4


@pytest.mark.parametrize(
    "args, message",
    [
        (["--distance", "-1"], "--distance: expected a positive number, got -1"),
        (["--coeffs", "5"], "--coeffs 5: the lcp export has no choice of coefficients"),
    ],
)
def test_bad_options_exit_2_with_one_line_and_nothing_written(model, tmp_path, args, message):
    out = tmp_path / "lens.lcp"
    code, stdout, stderr = run_main("export", model, "--format", "lcp", *OPTICS, *args, "-o", out)
    assert code == 2 and stdout == "" and not out.exists()
    assert stderr.startswith("harp export: ") and message in stderr and stderr.count("\n") == 1, stderr


def test_a_profile_of_another_lens_at_o_is_refused_and_left_as_it_was(model, tmp_path):
    out = tmp_path / "other.lcp"
    text = (
        '<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">'
        '<rdf:Description xmlns:photoshop="http://ns.adobe.com/photoshop/1.0/" '
        'xmlns:stCamera="http://ns.adobe.com/photoshop/1.0/camera-profile"><photoshop:CameraProfiles><rdf:Seq>'
        '<rdf:li><rdf:Description stCamera:Lens="EF24mm f/1.4L II USM" stCamera:FocalLength="24">'
        '<stCamera:PerspectiveModel><rdf:Description stCamera:FocalLengthX="0.7" stCamera:RadialDistortParam1="-0.1"/>'
        "</stCamera:PerspectiveModel></rdf:Description></rdf:li></rdf:Seq></photoshop:CameraProfiles>"
        "</rdf:Description></rdf:RDF></x:xmpmeta>"
    )
    out.write_text(text)
    code, stdout, stderr = run_main("export", model, "--format", "lcp", *OPTICS, "-o", out)
    assert code == 2 and stdout == "" and stderr.count("\n") == 1, stderr
    assert f"{out}: a profile of lens 'EF24mm f/1.4L II USM', not 'L60'; an LCP file holds one lens" in stderr
    assert out.read_text() == text
