"""Lateral chromatic aberration fitted from rendered colour harps against the exact per-channel maps.

Truth: each channel's exact closed-form shift to green (``tests/pipeline/colour_lenses.py``),
through which the mosaics were rendered; lensfun's own library (lensfunpy) applying the
``<tca>`` element for the lensfun model's meaning.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.edgeset import FitFailure
from pipeline.models.tca_model import ChannelModel, LensfunTca, TcaField, tca_exponents
from pipeline.tca import channel_pairs, field_difference, fit_tca, lensfun_tca
from tests.pipeline.colour_lenses import COLOUR_SIZE, colour_lens, measured_colour_shots

W, H = COLOUR_SIZE


@pytest.fixture(scope="module")
def fits():
    shots = measured_colour_shots()
    return {ch: fit_tca(*channel_pairs(shots, ch), W, H, channel=ch) for ch in "RB"}


@pytest.mark.parametrize("channel", ["R", "B"])
def test_field_matches_the_exact_tca(fits, channel):
    """Per-channel field error over the whole image, corners included: RMS <= 0.01 px (issue 24)."""
    fit = fits[channel]
    assert fit, fit
    truth = colour_lens(W, H)["tca"][channel]
    err = field_difference(fit.field.to_reference, truth.to_reference, W, H)
    size = field_difference(truth.to_reference, lambda g: g, W, H)
    print(f"{channel}: TCA up to {size.max:.3f} px; field error RMS {err.rms:.4f} px, max {err.max:.4f} px")
    assert size.max > 0.5  # a real TCA, 50 times the target
    assert err.rms <= 0.01
    assert err.max <= 0.03
    assert fit.offset_rms > 10 * fit.residual_rms  # the field explains what was seen
    assert fit.n_edges >= 100 and fit.rejected_edges == 0


def test_inverse_and_channel_model(fits):
    fld = fits["R"].field
    g = np.array([[0.0, 0.0], [W - 1.0, H - 1.0], [100.0, 333.0]])
    np.testing.assert_allclose(fld.to_reference(fld.from_reference(g)), g, atol=1e-9)
    green = colour_lens(W, H)["lenses"]["G"]

    class Ref:  # ChannelModel over any reference correction
        def undistort_points(self, xy):
            return green.undistort_points(xy)

        def to_dict(self):
            return {}

    m = ChannelModel(Ref(), fld)  # type: ignore[arg-type]
    np.testing.assert_allclose(m.undistort_points(g), green.undistort_points(fld.to_reference(g)))
    assert TcaField.from_dict(fld.to_dict()) == fld


def test_one_orientation_is_a_failure():
    shots = measured_colour_shots()[:1]
    f = fit_tca(*channel_pairs(shots, "R"), W, H, channel="R")
    assert isinstance(f, FitFailure) and not f
    assert "one orientation" in f.reason


def test_unmatched_edges_are_a_failure():
    shots = measured_colour_shots()
    ch, ref = channel_pairs(shots, "R")
    crossed = ref[2:] + ref[:2]  # the reference of another shot: its strings cross the channel's
    f = fit_tca(ch, crossed, W, H, channel="R")
    assert isinstance(f, FitFailure) and "edges match" in f.reason


def _pure_scale(alpha: float) -> TcaField:
    """The exact field x_g = c + (x_c - c)(1 + alpha), written in TcaField's coefficients."""
    ex = tca_exponents(1)
    coef = [0.0] + [0.0] * (2 * len(ex))  # a_1, then b_ij, then e_ij
    coef[1 + ex.index((1, 0))] = alpha
    coef[1 + len(ex) + ex.index((0, 1))] = alpha
    return TcaField(W, H, 1, tuple(coef))


def test_lensfun_linear_of_a_pure_magnification_is_exact():
    """Lensfun's direction is green -> channel: k = 1 / (1 + alpha), no conversion error."""
    fields = {"R": _pure_scale(-1e-3), "B": _pure_scale(7e-4)}
    lf = lensfun_tca(fields, "linear")
    assert lf.model.red[0] == pytest.approx(1 / (1 - 1e-3), rel=1e-12)
    assert lf.model.blue[0] == pytest.approx(1 / (1 + 7e-4), rel=1e-12)
    assert max(e.max for e in lf.error.values()) < 1e-9
    p3 = lensfun_tca(fields, "poly3")
    assert p3.model.red == pytest.approx((1 / (1 - 1e-3), 0.0, 0.0), abs=1e-12)


def test_lensfun_applies_the_tca_as_the_model_says():
    """liblensfun (lensfunpy) reads a <tca> element and moves red and blue as LensfunTca does."""
    import lensfunpy  # in the test extras: a missing lensfunpy fails, it is not skipped

    w, h = 600, 400
    for kind, red, blue in (("linear", (1.0008,), (0.9993,)), ("poly3", (1.0004, 3e-4, -2e-4), (0.9996, -2e-4, 1e-4))):
        model = LensfunTca(kind, red, blue, w, h)
        attrs = " ".join(f'{k}="{v}"' for k, v in model.element_attributes(50.0).items())
        xml = f"""<lensdatabase version="1"><camera><maker>M</maker><model>C</model><mount>X</mount>
        <cropfactor>1</cropfactor></camera><lens><maker>M</maker><model>L</model><mount>X</mount>
        <cropfactor>1</cropfactor><aspect-ratio>{(w - 1) / (h - 1)!r}</aspect-ratio>
        <calibration><tca {attrs}/></calibration></lens></lensdatabase>"""
        db = lensfunpy.Database(xml=xml, load_common=False, load_bundled=False)
        lens = db.find_lenses(db.find_cameras("M", "C")[0], "M", "L")[0]
        mod = lensfunpy.Modifier(lens, 1.0, w, h)
        mod.initialize(50.0, 2.8, 1000.0, scale=1.0, flags=lensfunpy.ModifyFlags.TCA)
        sub = mod.apply_subpixel_distortion()  # (h, w, 3 channels, xy): where each channel is read
        yy, xx = np.mgrid[0:h, 0:w].astype(float)
        g = np.column_stack([xx.ravel(), yy.ravel()])
        for c, ch in ((0, "R"), (2, "B")):
            got = sub[:, :, c, :].reshape(-1, 2)
            np.testing.assert_allclose(got, model.from_reference(ch, g), atol=2e-3, err_msg=f"{kind} {ch}")
        np.testing.assert_allclose(sub[:, :, 1, :].reshape(-1, 2), g, atol=2e-3)  # green is the reference (float32)


def test_channel_offsets_of_one_shot_are_the_exact_shift_across_the_edges():
    """The live page's figure (issue 24 item 4): each red and blue edge point's offset from green's
    edge, along green's normal, against the exact shift there; outward in the outer ring: red's edges
    lie outside green's, blue's inside, by the exact amount."""
    from pipeline.tca import ChannelOffsets, channel_offsets

    shot = measured_colour_shots()[0]
    truth = colour_lens(W, H)["tca"]
    for ch, got in channel_offsets(shot).items():
        want = np.einsum("ij,ij->i", got.normal, truth[ch].displacement(got.points))
        err = got.offset - want
        print(
            f"{ch}: {len(err)} points, offset error median {np.median(np.abs(err)):.4f} px, RMS {np.sqrt(np.mean(err**2)):.4f}"
        )
        assert len(err) > 500 and np.median(np.abs(err)) < 0.01 and np.sqrt(np.mean(err**2)) < 0.03
        exact = ChannelOffsets(ch, W, H, got.points, got.normal, want).summary()
        summary = got.summary()
        for z, zt in zip(summary["zones"], exact["zones"]):
            assert z["points"] == zt["points"] > 50
            assert abs(z["median_outward_px"] - zt["median_outward_px"]) < 0.02, (ch, z, zt)
        outer = summary["zones"][-1]["median_outward_px"]
        assert (outer > 0.2) if ch == "R" else (outer < -0.15), (ch, outer)
