r"""Calibration boards: what a board is, its corners in board coordinates, and finding them in a shot.

A board is a planar target of squares, ``nx`` x ``ny`` of side ``square`` (mm):

* ``charuco``: a ChArUco board (OpenCV's ``cv2.aruco.CharucoBoard``; markers of
  side ``marker`` mm from a predefined ArUco dictionary in the white squares); each
  inner corner is named by its id, so partial views count;
* ``chessboard``: a plain chessboard; all ``(nx - 1) x (ny - 1)`` inner corners must
  be seen (``cv2.findChessboardCornersSB``).

A board is written as a label: ``charuco:NXxNY:SQUARE:MARKER[:DICT]`` (``DICT`` an
OpenCV name such as ``DICT_5X5_100``, the default) or ``chessboard:NXxNY:SQUARE``
(:func:`parse_board`). Board coordinates: ``X`` along the ``nx`` squares, ``Y`` along
the ``ny`` squares, origin at the board's outer top-left corner, millimetres, ``Z = 0``;
corner ``i`` of ``(nx - 1) x (ny - 1)`` inner corners is at
``((i mod (nx-1)) + 1, (i div (nx-1)) + 1) * square`` (OpenCV's numbering, for both kinds).

:func:`detect_board` finds the corners of one shot (distorted pixels, ``x`` = column,
``y`` = row, pixel centres at integers: OpenCV's convention too) and either returns a
:class:`BoardView` or a falsy :class:`BoardRejected` saying why: no board, too few
corners, corners on one line, or the shot too blurred (:func:`edge_width`: the board's
edges wider than ``max_edge_width_px``).

References
----------
.. [1] S. Garrido-Jurado, R. Muñoz-Salinas, F. J. Madrid-Cuevas, M. J. Marín-Jiménez,
   "Automatic generation and detection of highly reliable fiducial markers under
   occlusion", Pattern Recognition 47(6), 2014 (ArUco).
.. [2] OpenCV, "Detection of ChArUco Boards" (objdetect, ``cv::aruco::CharucoDetector``).
.. [3] A. Duda, U. Frese, "Accurate detection and localization of checkerboard corners for
   calibration", BMVC 2018 (``findChessboardCornersSB``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

BOARD_KINDS = ("charuco", "chessboard")
"""The board kinds :func:`parse_board` knows."""

DEFAULT_DICTIONARY = "DICT_5X5_100"
"""ArUco dictionary of a ChArUco label that names none."""

MIN_CORNERS = 8
"""A view with fewer corners is rejected (a homography needs 4; 8 leave it over-determined)."""

MAX_EDGE_WIDTH_PX = 4.0
"""A view whose board edges are wider than this (:func:`edge_width`, ~ the 10-90 % width) is
rejected as blurred: a sharp shot is 1.2-2 px, a Gaussian blur of sigma s adds about 2.5 s."""


@dataclass(frozen=True)
class BoardSpec:
    """A calibration board (module docstring): kind, squares ``nx`` x ``ny`` of ``square`` mm,
    the ArUco ``marker`` side (mm) and ``dictionary`` of a ChArUco board."""

    kind: str
    nx: int
    ny: int
    square: float
    marker: float = 0.0
    dictionary: str = DEFAULT_DICTIONARY

    def __post_init__(self) -> None:
        if self.kind not in BOARD_KINDS:
            raise ValueError(f"board kind must be one of {', '.join(BOARD_KINDS)}, got {self.kind!r}")
        if not (int(self.nx) >= 3 and int(self.ny) >= 3):
            raise ValueError(f"a board needs at least 3x3 squares, got {self.nx}x{self.ny}")
        if not (math.isfinite(self.square) and self.square > 0):
            raise ValueError(f"square side must be > 0 mm, got {self.square}")
        if self.kind == "charuco":
            if not (math.isfinite(self.marker) and 0 < self.marker < self.square):
                raise ValueError(f"marker side must be > 0 and < the square ({self.square} mm), got {self.marker}")
            import cv2

            if not self.dictionary.startswith("DICT_") or not hasattr(cv2.aruco, self.dictionary):
                raise ValueError(f"unknown ArUco dictionary {self.dictionary!r} (e.g. {DEFAULT_DICTIONARY})")

    @property
    def label(self) -> str:
        """The label :func:`parse_board` reads back."""
        if self.kind == "charuco":
            return f"charuco:{self.nx}x{self.ny}:{self.square:g}:{self.marker:g}:{self.dictionary}"
        return f"chessboard:{self.nx}x{self.ny}:{self.square:g}"

    @property
    def n_corners(self) -> int:
        """Inner corners of the board."""
        return (self.nx - 1) * (self.ny - 1)

    def corners(self) -> Array:
        """``(n_corners, 3)`` board coordinates (mm, ``Z = 0``) of the inner corners, by id."""
        i = np.arange(self.n_corners)
        cx, cy = i % (self.nx - 1) + 1, i // (self.nx - 1) + 1
        return np.column_stack([cx * self.square, cy * self.square, np.zeros(len(i))]).astype(np.float64)

    def size_mm(self) -> tuple[float, float]:
        """Outer size of the squares (mm)."""
        return self.nx * self.square, self.ny * self.square

    def cv_board(self) -> Any:
        """The ``cv2.aruco.CharucoBoard`` of a ChArUco board (its corners equal :meth:`corners`)."""
        import cv2

        if self.kind != "charuco":
            raise ValueError("only a ChArUco board has an ArUco board object")
        dic = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.nx, self.ny), self.square, self.marker, dic)

    def texture(self, px_per_square: int = 64, margin_squares: float = 1.0) -> tuple[npt.NDArray[np.uint8], float]:
        """The printed board as an image (white margin around the squares) and its scale.

        Returns ``(image, px_per_mm)``: texture pixel ``j`` covers board ``X`` in
        ``[j - m, j + 1 - m) / px_per_mm`` with ``m`` the margin in texture pixels
        (``round(margin_squares * px_per_square)``), so every square's edge lies on a
        texture pixel boundary. ChArUco: ``cv2.aruco.CharucoBoard.generateImage``.
        """
        pps = int(px_per_square)
        m = int(round(margin_squares * pps))
        w, h = self.nx * pps, self.ny * pps
        if self.kind == "charuco":
            inner = self.cv_board().generateImage((w, h), marginSize=0, borderBits=1)
        else:
            iy, ix = np.mgrid[0:h, 0:w] // pps
            inner = np.where((ix + iy) % 2 == 0, 0, 255).astype(np.uint8)
        out = np.full((h + 2 * m, w + 2 * m), 255, np.uint8)
        out[m : m + h, m : m + w] = np.asarray(inner, np.uint8).reshape(h, w)
        return out, pps / float(self.square)


def parse_board(text: str) -> BoardSpec:
    """The board of a label (module docstring); ValueError (one line) naming what is wrong.

    >>> parse_board("charuco:9x7:20:15").label
    'charuco:9x7:20:15:DICT_5X5_100'
    """
    parts = str(text).strip().split(":")
    usage = "charuco:NXxNY:SQUARE_MM:MARKER_MM[:DICT] or chessboard:NXxNY:SQUARE_MM"
    kind = parts[0].lower()
    if kind not in BOARD_KINDS:
        raise ValueError(f"board {text!r}: unknown kind {parts[0]!r} (expected {usage})")
    want = (4, 5) if kind == "charuco" else (3,)
    if len(parts) not in want:
        raise ValueError(f"board {text!r}: expected {usage}")
    try:
        nx_s, ny_s = parts[1].lower().split("x")
        nx, ny = int(nx_s), int(ny_s)
        square = float(parts[2])
        marker = float(parts[3]) if kind == "charuco" else 0.0
    except ValueError:
        raise ValueError(f"board {text!r}: expected {usage}") from None
    dictionary = parts[4].upper() if len(parts) == 5 else DEFAULT_DICTIONARY
    try:
        return BoardSpec(kind, nx, ny, square, marker, dictionary)
    except ValueError as exc:
        raise ValueError(f"board {text!r}: {exc}") from None


@dataclass(frozen=True)
class BoardView:
    """The corners of a board found in one shot.

    ``ids`` (N,) corner ids (:meth:`BoardSpec.corners` rows), ``image_points`` (N, 2)
    distorted pixels, ``object_points`` (N, 3) board mm, ``edge_width_px`` the shot's
    :func:`edge_width`; ``name`` the shot's name (a path) for messages.
    """

    ids: npt.NDArray[np.int64]
    image_points: Array
    object_points: Array
    edge_width_px: float
    name: str = ""

    def __bool__(self) -> Literal[True]:
        return True

    @property
    def n(self) -> int:
        return int(len(self.ids))


@dataclass(frozen=True)
class BoardRejected:
    """A shot that gives no usable view, and why (one line). Falsy."""

    name: str
    reason: str

    def __bool__(self) -> Literal[False]:
        return False


def edge_width(image: npt.NDArray[Any], points: Array) -> float:
    r"""How wide the board's edges are in a shot, pixels: contrast over peak gradient.

    Within the board's outline (the convex hull of its corners ``points``), the contrast
    :math:`C` is the 2-98 % spread of the grey values and the peak gradient :math:`g` the
    median of the strongest gradients (central differences), the top :math:`0.5/s` fraction
    with :math:`s` the median corner spacing (the edges' share of the area is about
    :math:`2/s`). For a step blurred by a Gaussian of :math:`\sigma`,
    :math:`C/g = \sigma\sqrt{2\pi} \approx 2.5\sigma`, close to the 10-90 % width
    (:math:`2.56\sigma`); a sharp edge integrated by the pixels gives 1.2-2.
    """
    import cv2

    img = np.asarray(image, np.float64)
    if img.ndim == 3:
        img = img.mean(axis=2)
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    hull = cv2.convexHull(pts.astype(np.float32))
    mask = np.zeros(img.shape, np.uint8)
    cv2.fillConvexPoly(mask, np.round(hull.reshape(-1, 2)).astype(np.int32), 1)
    gx = np.zeros_like(img)
    gy = np.zeros_like(img)
    gx[:, 1:-1] = 0.5 * (img[:, 2:] - img[:, :-2])
    gy[1:-1, :] = 0.5 * (img[2:, :] - img[:-2, :])
    inside = mask.astype(bool)
    if inside.sum() < 16:
        return float("inf")
    vals = img[inside]
    contrast = float(np.percentile(vals, 98) - np.percentile(vals, 2))
    grad = np.hypot(gx, gy)[inside]
    d = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    spacing = float(np.median(d.min(axis=1))) if len(pts) > 1 else 10.0
    frac = min(0.5, 0.5 / max(spacing, 1.0))
    top = np.sort(grad)[-max(1, int(frac * len(grad))) :]
    g = float(np.median(top))
    return contrast / g if g > 0 else float("inf")


def _detect_charuco(img: npt.NDArray[np.uint8], spec: BoardSpec) -> tuple[npt.NDArray[np.int64], Array]:
    import cv2

    board = spec.cv_board()
    params = cv2.aruco.CharucoParameters()
    params.tryRefineMarkers = True
    det = cv2.aruco.CharucoDetector(board, params)
    corners, ids, _mc, _mi = det.detectBoard(img)
    if ids is None or corners is None or len(ids) == 0:
        return np.zeros(0, np.int64), np.zeros((0, 2))
    return np.asarray(ids, np.int64).ravel(), np.asarray(corners, np.float64).reshape(-1, 2)


def _detect_chessboard(img: npt.NDArray[np.uint8], spec: BoardSpec) -> tuple[npt.NDArray[np.int64], Array]:
    import cv2

    found, corners = cv2.findChessboardCornersSB(
        img, (spec.nx - 1, spec.ny - 1), flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    )
    if not found or corners is None:
        return np.zeros(0, np.int64), np.zeros((0, 2))
    pts = np.asarray(corners, np.float64).reshape(-1, 2)
    # OpenCV may number the corners from either end: a chessboard turned by 180 degrees is the
    # same grid, so either numbering is a valid view of it (another pose).
    return np.arange(len(pts), dtype=np.int64), pts


SADDLE_MAX_RADIUS = 7
"""Largest half-size (px) of the window a corner is refined in."""


def _saddle(smooth: Array, x: float, y: float, r: int) -> tuple[float, float] | None:
    """The saddle point of the quadratic fitted to ``smooth`` around ``(x, y)`` (iterated, the
    window re-centred each time); None when it leaves the window or does not settle."""
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1].astype(np.float64)
    wgt = np.exp(-(xx**2 + yy**2) / (2.0 * (r / 2.0) ** 2)).ravel()
    x0, y0 = x, y
    hgt, wid = smooth.shape
    for _ in range(12):
        xi, yi = int(round(x)), int(round(y))
        if xi - r < 0 or yi - r < 0 or xi + r >= wid or yi + r >= hgt:
            return None
        patch = smooth[yi - r : yi + r + 1, xi - r : xi + r + 1].ravel()
        dx, dy = (xx + xi - x).ravel(), (yy + yi - y).ravel()
        a = np.column_stack([dx * dx, dx * dy, dy * dy, dx, dy, np.ones_like(dx)]) * wgt[:, None]
        c, *_ = np.linalg.lstsq(a, patch * wgt, rcond=None)
        hess = np.array([[2 * c[0], c[1]], [c[1], 2 * c[2]]])
        if np.linalg.det(hess) >= 0:  # not a saddle
            return None
        step = np.linalg.solve(hess, -c[3:5])
        x, y = x + float(step[0]), y + float(step[1])
        if math.hypot(x - x0, y - y0) > 0.5 * r:
            return None
        if math.hypot(*step) < 1e-5:
            return x, y
    return None


def refine_corners(
    img: npt.NDArray[np.uint8], spec: BoardSpec, ids: npt.NDArray[np.int64], pts: Array
) -> tuple[Array, npt.NDArray[np.bool_]]:
    r"""Corners refined to the saddle point of the grey values, each in the largest window that
    sees only its own four squares; ``(points, refined)``.

    Around a corner the board is a clean X-junction only within :math:`g` of it along both
    board axes (ChArUco: :math:`g = (L - m)/2`, the white gap before a marker; chessboard:
    :math:`0.45 L`). The window's half-size :math:`r` (at most :data:`SADDLE_MAX_RADIUS`) is
    such that the image square :math:`[-r, r]^2` maps back inside :math:`0.9 [-g, g]^2` under
    the local affine map of the board-to-image homography of the detected corners (its
    Jacobian :math:`A` at the corner): :math:`r = 0.9 g / \max_{\pm\pm}\|A^{-1}(\pm 1, \pm 1)\|_\infty`.
    The image, smoothed by a Gaussian (0.8, 1, 1.5 or 2 px as the window allows), is fitted by a
    quadratic (Gaussian-weighted) and the corner moved to its saddle point, re-centred until
    it settles [1]_. A point-symmetric junction blurred by a symmetric PSF stays
    point-symmetric about the corner, so the saddle is the corner; unlike ``cv2.cornerSubPix``
    (0.05-0.1 px pixel-phase error on sharp rendered corners) it is smooth in the pixel phase:
    0.005-0.01 px on noise-free renders. A corner with a window under 2 px, or whose saddle
    does not settle, is not refined (``refined`` False; :func:`detect_board` drops it).

    References
    ----------
    .. [1] L. Lucchese, S. K. Mitra, "Using saddle points for subpixel feature detection in
       camera calibration targets", APCCAS 2002.
    """
    import cv2

    refined = np.zeros(len(ids), bool)
    obj = spec.corners()[ids][:, :2]
    if len(ids) < 4:
        return pts, refined
    h, _ = cv2.findHomography(obj, pts, 0)
    if h is None:
        return pts, refined
    g = 0.5 * (spec.square - spec.marker) if spec.kind == "charuco" else 0.45 * spec.square
    out = pts.copy()
    smoothed: dict[float, Array] = {}
    signs = np.array([[1.0, 1.0], [1.0, -1.0]])
    base = np.asarray(img, np.float64)
    for j, (x, y) in enumerate(obj):
        q = h @ np.array([x, y, 1.0])
        a = (h[:2, :2] * q[2] - np.outer(q[:2], h[2, :2])) / q[2] ** 2  # d(image)/d(board) at the corner
        try:
            ainv = np.linalg.inv(a)
        except np.linalg.LinAlgError:
            continue
        reach = float(np.max(np.abs(signs @ ainv.T)))  # board mm per image px at the window's corners
        r = min(int(np.floor(0.9 * g / reach)), SADDLE_MAX_RADIUS) if reach > 0 else 0
        if r < 2:
            continue
        sig = 0.8 if r <= 2 else (1.0 if r <= 4 else (1.5 if r <= 6 else 2.0))
        if sig not in smoothed:
            smoothed[sig] = np.asarray(cv2.GaussianBlur(base, (0, 0), sig), np.float64)
        got = _saddle(smoothed[sig], float(pts[j, 0]), float(pts[j, 1]), r)
        if got is not None:
            out[j] = got
            refined[j] = True
    return out, refined


def detect_board(
    image: npt.NDArray[Any],
    spec: BoardSpec,
    *,
    name: str = "",
    min_corners: int = MIN_CORNERS,
    max_edge_width_px: float = MAX_EDGE_WIDTH_PX,
) -> BoardView | BoardRejected:
    """The board's corners in one shot (8- or 16-bit, grey or colour), or why there are none.

    Rejections (:class:`BoardRejected`, one line each): no board found; fewer than
    ``min_corners`` corners; the corners on one line (no plane's orientation in them);
    edges wider than ``max_edge_width_px`` (blurred: its corners are imprecise).
    """
    import cv2

    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.shape[2] == 3 else img[..., 0]
    if img.dtype != np.uint8:
        top = float(img.max()) if img.size else 0.0
        img = np.clip(np.asarray(img, np.float64) * (255.0 / top if top > 0 else 1.0), 0, 255).astype(np.uint8)
    if spec.kind == "charuco":
        ids, pts = _detect_charuco(img, spec)
    else:
        ids, pts = _detect_chessboard(img, spec)
    if len(ids) == 0:
        return BoardRejected(name, f"no {spec.kind} board {spec.nx}x{spec.ny} found")
    if len(ids) < min_corners:
        return BoardRejected(name, f"too few board corners: {len(ids)} < {min_corners}")
    centred = pts - pts.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    if sv[1] < 1e-3 * sv[0]:
        return BoardRejected(name, f"the {len(ids)} board corners lie on one line")
    pts, refined = refine_corners(img, spec, ids, pts)
    found = len(ids)
    ids, pts = ids[refined], pts[refined]
    if len(ids) < min_corners:
        return BoardRejected(
            name,
            f"too few board corners: {len(ids)} of the {found} found large enough to measure < {min_corners} "
            "(the board too small in the image?)",
        )
    w = edge_width(img, pts)
    if not w <= max_edge_width_px:
        return BoardRejected(name, f"blurred: board edges {w:.1f} px wide > {max_edge_width_px:g} px")
    obj = spec.corners()[ids]
    return BoardView(ids=ids, image_points=pts, object_points=obj, edge_width_px=float(w), name=name)


@dataclass(frozen=True)
class BoardCoverage:
    """Which cells of the image the corners of board views reach (pooled over the views).

    ``covered`` (``ny``, ``nx``) booleans, ``fraction`` of the cells covered; :meth:`missing` names the
    image regions without a corner (what a camera matrix, whose principal point and focal length the
    whole field constrains, is then extrapolated over)."""

    covered: npt.NDArray[np.bool_]
    fraction: float

    def missing(self) -> list[str]:
        """The uncovered cells as regions: ``top-left corner``, ``bottom edge``, ``centre``, ..."""
        ny, nx = self.covered.shape
        out: list[str] = []
        for j in range(ny):
            for i in range(nx):
                if self.covered[j, i]:
                    continue
                v = "top" if j == 0 else ("bottom" if j == ny - 1 else "")
                h = "left" if i == 0 else ("right" if i == nx - 1 else "")
                name = f"{v}-{h} corner" if v and h else (f"{v or h} edge" if v or h else "centre")
                if name not in out:
                    out.append(name)
        return out


def board_coverage(views: list[BoardView], width: int, height: int, nx: int = 8, ny: int = 6) -> BoardCoverage:
    """The image cells (``nx`` x ``ny``) that the corners of ``views`` reach."""
    return corner_coverage([v.image_points for v in views], width, height, nx, ny)


def corner_coverage(
    points: Sequence[npt.ArrayLike], width: int, height: int, nx: int = 8, ny: int = 6
) -> BoardCoverage:
    """The image cells (``nx`` x ``ny``) that corners reach: ``points``, one (N, 2) array of pixels
    ``[x, y]`` per view (the corners of a :class:`BoardView`, or as a session's manifest keeps them)."""
    covered = np.zeros((ny, nx), bool)
    for pts in points:
        p = np.asarray(pts, np.float64).reshape(-1, 2)
        i = np.clip((p[:, 0] / width * nx).astype(int), 0, nx - 1)
        j = np.clip((p[:, 1] / height * ny).astype(int), 0, ny - 1)
        covered[j, i] = True
    return BoardCoverage(covered, float(covered.mean()))
