"""QA verdicts on corrections with exact answers."""

import math

from pipeline.models.base import IdentityModel
from pipeline.models.radial import RadialModel
from station.config import QAConfig
from station.qa.verdicts import combine, distortion_magnitude, evaluate

W, H = 400, 300


def test_identity_has_no_distortion():
    rms, mx = distortion_magnitude(IdentityModel(), W, H)
    assert rms < 1e-9 and mx < 1e-9


def test_thresholds():
    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.01))
    _rms, mx = distortion_magnitude(lens, W, H)
    assert 0.1 < mx < 3.0  # 0.01 * s at the corners, less modulo homography
    ok = evaluate(lens, W, H, 0.01, QAConfig(max_holdout_d_px=0.02, max_distortion_px=mx + 0.01))
    assert ok.passed and ok.reasons == () and len(ok.checks) == 2
    bad = evaluate(lens, W, H, 0.03, QAConfig(max_holdout_d_px=0.02, max_distortion_px=mx - 0.01))
    assert bad.verdict == "FAIL" and len(bad.reasons) == 2
    assert bad.reasons[0].startswith("holdout d 0.0300 px > 0.02 px")
    assert math.isclose(bad.metrics["distortion_max_px"], mx)


def test_reference_deviation_and_missing_holdout():
    a = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.01))
    b = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02))
    q = QAConfig(max_holdout_d_px=1.0, max_reference_deviation_px=0.01)
    assert evaluate(a, W, H, 0.01, q, reference=a).passed
    v = evaluate(a, W, H, 0.01, q, reference=b)
    assert not v.passed and "deviates from the reference" in v.reasons[0]
    v = evaluate(a, W, H, None, q)
    assert not v.passed and "no cross-validated" in v.reasons[0]
    assert "not checked (no reference given)" in v.checks[-1].text
    assert combine([]) == "FAIL" and combine([evaluate(a, W, H, 0.0, q)]) == "PASS"
