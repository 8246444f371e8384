"""Agisoft Metashape's camera models (user manual, appendix "Camera models"), written out for the tests: no
Metashape is installed (commercial software). Frame camera: ``x = X/Z``, ``r^2 = x^2 + y^2``,
``x' = x (1 + K1 r^2 + K2 r^4 + K3 r^6 + K4 r^8) + (P1 (r^2 + 2 x^2) + 2 P2 x y)``,
``y' = y (1 + ...) + (P2 (r^2 + 2 y^2) + 2 P1 x y)``, ``u = w/2 + cx + x' f + x' B1 + y' B2``,
``v = h/2 + cy + y' f``, pixels from the image's top-left corner (the top-left pixel's centre at 0.5, 0.5).
Fisheye camera: ``x`` first replaced by ``x atan(r0) / r0`` (``r0`` its radius), then the same.
"""

import xml.etree.ElementTree as ET

import numpy as np

KEYS = ("f", "cx", "cy", "b1", "b2", "k1", "k2", "k3", "k4", "p1", "p2")


def metashape_camera(data):
    """The calibration parsed with ElementTree: (projection, width, height, {key: value})."""
    root = ET.fromstring(data)
    assert root.tag == "calibration"
    p = {k: float(root.findtext(k, "0")) for k in KEYS}
    return root.findtext("projection"), int(root.findtext("width")), int(root.findtext("height")), p


def project(proj, w, h, p, xy):
    """Points of the plane Z = 1 (N, 2) to Metashape pixels."""
    x, y = xy[:, 0].copy(), xy[:, 1].copy()
    if proj == "fisheye":
        r0 = np.hypot(x, y)
        s = np.where(r0 > 1e-12, np.arctan(r0) / np.maximum(r0, 1e-300), 1.0)
        x, y = x * s, y * s
    r2 = x * x + y * y
    rad = 1 + p["k1"] * r2 + p["k2"] * r2**2 + p["k3"] * r2**3 + p["k4"] * r2**4
    xp = x * rad + (p["p1"] * (r2 + 2 * x * x) + 2 * p["p2"] * x * y)
    yp = y * rad + (p["p2"] * (r2 + 2 * y * y) + 2 * p["p1"] * x * y)
    u = w * 0.5 + p["cx"] + xp * p["f"] + xp * p["b1"] + yp * p["b2"]
    v = h * 0.5 + p["cy"] + yp * p["f"]
    return np.stack([u, v], axis=1)


def unproject(proj, w, h, p, uv, steps=30):
    """Metashape pixels to the plane Z = 1: Gauss-Newton on :func:`project` (numerical Jacobian)."""
    f = p["f"]
    xy = np.stack([(uv[:, 0] - w * 0.5 - p["cx"]) / f, (uv[:, 1] - h * 0.5 - p["cy"]) / f], axis=1)
    eps = 1e-7
    for _ in range(steps):
        e = uv - project(proj, w, h, p, xy)
        jx = (project(proj, w, h, p, xy + [eps, 0]) - project(proj, w, h, p, xy)) / eps
        jy = (project(proj, w, h, p, xy + [0, eps]) - project(proj, w, h, p, xy)) / eps
        j = np.stack([jx, jy], axis=-1)
        xy = xy + np.linalg.solve(j, e[..., None])[..., 0]
    return xy
