r"""The least-squares problem of the fit (:mod:`pipeline.fit`): a model family's free parameters,
the residuals of the corrected points to their edges' TLS lines and their Jacobian, and the normal
equations of the residuals.

A residual is the signed distance of a corrected point :math:`U_\theta(p_i)` to the total-least-squares
line of its own corrected edge; the lines are recomputed from the corrected points at every
evaluation (variable projection), and the Jacobian includes the derivative of the line (centroid and
angle) with respect to :math:`\theta` [2]_. :func:`normal_equations` gives :math:`J^T W J`,
:math:`J^T W r` and :math:`r^T W r` from per-edge moments without forming the Jacobian.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision
   camera distortion measurements with a calibration harp", JOSA A 29(10), 2012.
.. [2] G. H. Golub, V. Pereyra, "The differentiation of pseudo-inverses and
   nonlinear least squares problems whose variables separate", SIAM J. Numer.
   Anal. 10(2), 1973.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from pipeline.edgeset import EdgeSet, tls
from pipeline.fitspec import FitSpec
from pipeline.models.base import DistortionModel
from pipeline.models.polynomial import PolynomialParametrisation
from pipeline.models.radial import RadialParametrisation
from pipeline.models.radial_field import FieldRows, ProjectedRows, RadialFieldParametrisation


class Parametrisation(Protocol):
    """The free parameters ``theta`` of a model family (beside each model in :mod:`pipeline.models`)."""

    n: int

    def theta0(self, init: DistortionModel | None) -> np.ndarray: ...
    def model(self, th: np.ndarray) -> DistortionModel: ...
    def evaluate(self, xy: np.ndarray, th: np.ndarray, jac: bool = True) -> tuple[np.ndarray, np.ndarray | None]: ...
    def regularisation(self, th: np.ndarray, n_points: int) -> tuple[np.ndarray, np.ndarray]: ...
    def project(
        self, xy: np.ndarray, th: np.ndarray, nrm: np.ndarray, tan: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]: ...


def make_parametrisation(
    width: int,
    height: int,
    spec: FitSpec,
    *,
    w_center: float | None = None,
    w_gauge: float = 1e-3,
    ridge: float | None = None,
) -> RadialParametrisation | RadialFieldParametrisation | PolynomialParametrisation:
    """The free parameters of ``spec`` for a ``width x height`` image (see module doc).

    ``w_center`` defaults to the spec's (:attr:`FitSpec.w_center`); ``ridge`` to 0 for
    radial, 1e-4 for poly. A spec with a field: the radial parameters followed by the field's
    (:class:`~pipeline.models.radial_field.RadialFieldParametrisation`).
    """
    if spec.kind == "radial":
        radial = RadialParametrisation(
            width,
            height,
            int(spec.degree or 0),
            spec.tangential,
            spec.prism,
            spec.w_center if w_center is None else w_center,
            w_gauge,
            0.0 if ridge is None else ridge,
            spec.division,
            spec.trefoil,
        )
        if spec.field is None:
            return radial
        return RadialFieldParametrisation(
            radial, width, height, (spec.field[1], spec.field[0]), float(spec.field_penalty or 0)
        )
    return PolynomialParametrisation(width, height, int(spec.degree or 0), 1e-4 if ridge is None else ridge)


# ------------------------------------------------------------- objective
def _projected(
    param: Parametrisation, edges: EdgeSet, th: np.ndarray, jac: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """``(r, a, P, T)``: the residuals, the positions along the lines and (``jac``) the Jacobian of
    the corrected points projected on each point's line normal (``P``) and direction (``T``), one row
    per parameter (``(n, N)``)."""
    u, _ = param.evaluate(edges.xy, th, jac=False)
    r, a, nrm, tan, _ = tls(u, edges.starts, edges.counts, edges.weights)
    if not jac:
        return r, a, None, None
    p_mat, t_mat = param.project(edges.xy, th, nrm, tan)
    return r, a, p_mat, t_mat


def _line_turn(
    p_mat: np.ndarray, t_mat: np.ndarray, r: np.ndarray, a: np.ndarray, st: np.ndarray, q: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per edge (columns, ``(n, E)``): the (``q``-weighted) sums of ``P`` and of ``a P``, and
    ``d phi / d theta``, the rotation of its TLS line (Golub-Pereyra):
    ``d phi = sum_i q_i (a_i (P_i - mean P) + r_i (T_i - mean T)) / sum_i q_i (a_i^2 - r_i^2)``; the
    means drop out because ``sum q a = sum q r = 0`` on each edge (distances from its weighted
    centroid). ``q`` (N,): the points' weights (:attr:`EdgeSet.weights`), None for 1."""
    pq = p_mat if q is None else p_mat * q
    aq, rq = (a, r) if q is None else (a * q, r * q)
    sum_p = np.add.reduceat(pq, st, axis=1)
    sum_ap = np.add.reduceat(pq * a, st, axis=1)
    sum_rt = np.add.reduceat(t_mat * rq, st, axis=1)
    den = np.add.reduceat(aq * a - rq * r, st)
    return sum_p, sum_ap, (sum_ap + sum_rt) / np.where(np.abs(den) > 1e-300, den, 1e-300)


def _weight_sums(edges: EdgeSet) -> np.ndarray:
    """Per edge: the sum of its points' weights (its number of points when unweighted)."""
    if edges.weights is None:
        return edges.counts.astype(np.float64)
    out: np.ndarray = np.add.reduceat(edges.weights, edges.starts)
    return out


def residuals_and_jacobian(
    param: Parametrisation, edges: EdgeSet, th: np.ndarray, jac: bool = True
) -> tuple[np.ndarray, np.ndarray | None]:
    """Signed distances of the corrected points to their own edge's TLS line, and (``jac``)
    their analytic Jacobian ``(N, n)`` in ``theta``, the line's motion included (variable
    projection): ``J_i = P_i - mean_e P - a_i d phi_e`` (``P_i = n_e . du_i``, :func:`_line_turn`).
    With point weights (:attr:`EdgeSet.weights`) the lines are the weighted TLS lines and the means
    weighted; the residuals are not multiplied by the weights (the caller weighs their squares)."""
    r, a, p_mat, t_mat = _projected(param, edges, th, jac)
    if p_mat is None or t_mat is None:
        return r, None
    st, ct = edges.starts, edges.counts
    sum_p, _, dphi = _line_turn(p_mat, t_mat, r, a, st, edges.weights)
    j = p_mat - np.repeat(sum_p / _weight_sums(edges), ct, axis=1)
    j -= np.repeat(dphi, ct, axis=1) * a
    return r, j.T


def normal_equations(
    param: Parametrisation,
    edges: EdgeSet,
    th: np.ndarray,
    groups: Sequence[int] | None = None,
    edge_weights: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``J^T W J``, ``J^T W r`` and ``r^T W r`` of :func:`residuals_and_jacobian` at ``th`` without
    forming ``J`` (``W``: the per-edge ``edge_weights``, default 1, times the points' own weights
    :attr:`EdgeSet.weights`, default 1), per group of edges: ``groups``
    are the edge indices where each group starts (the edges of a group contiguous; default one
    group), the results stacked ``(G, n, n)``, ``(G, n)``, ``(G,)``.

    With ``Pc`` the per-edge centred ``P``, ``J = Pc - a dphi``, so per edge
    ``J^T J = P^T P - n mean P mean P^T - S dphi^T - dphi S^T + (sum a^2) dphi dphi^T`` with
    ``S = sum a Pc`` and ``J^T r = P^T r - mean P sum r - dphi sum a r`` (the last two terms zero to
    rounding). A Gauss-Newton or Levenberg-Marquardt step needs only these (``n x n``), not the
    ``N x n`` Jacobian."""
    project_rows = getattr(param, "project_rows", None)
    if project_rows is not None and groups is None:
        u, _ = param.evaluate(edges.xy, th, jac=False)
        r, a, nrm, tan, _ = tls(u, edges.starts, edges.counts, edges.weights)
        rows = project_rows(edges.xy, th, nrm, tan)
        if rows.field is not None:
            return _field_normal_equations(rows, rows.field, edges, r, a, nrm, tan, edge_weights)
        p_mat, t_mat = rows.p, rows.t  # every row dense, in order
    else:
        r, a, p_mat, t_mat = _projected(param, edges, th, True)
    assert p_mat is not None and t_mat is not None
    st = edges.starts
    q = edges.weights
    sum_p, sum_ap, dphi = _line_turn(p_mat, t_mat, r, a, st, q)
    sum_q, mean_p, sum_r, sum_aa, sum_ar, s_ap, w = _edge_terms(edges, a, r, sum_p, sum_ap, edge_weights)
    w_pt = edges.point_weights(edge_weights)
    bounds = [0] if groups is None else [int(g) for g in groups]
    bounds.append(edges.n_edges)
    n = p_mat.shape[0]
    ata = np.empty((len(bounds) - 1, n, n))
    atb = np.empty((len(bounds) - 1, n))
    ss = np.empty(len(bounds) - 1)
    for g, (e0, e1) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        p0 = int(st[e0]) if e0 < edges.n_edges else len(r)
        p1 = int(st[e1]) if e1 < edges.n_edges else len(r)
        pg, rg = p_mat[:, p0:p1], r[p0:p1]
        if w_pt is not None:
            rw = rg * w_pt[p0:p1]
            pw = pg * w_pt[p0:p1]
        else:
            rw, pw = rg, pg
        we = w[e0:e1]
        mp, dp, sp = mean_p[:, e0:e1], dphi[:, e0:e1], s_ap[:, e0:e1]
        cross = (sp * we) @ dp.T
        ata[g] = pw @ pg.T - (mp * (sum_q[e0:e1] * we)) @ mp.T - cross - cross.T + (dp * (sum_aa[e0:e1] * we)) @ dp.T
        atb[g] = pw @ rg - mp @ (sum_r[e0:e1] * we) - dp @ (sum_ar[e0:e1] * we)
        ss[g] = rw @ rg
    return ata, atb, ss


def _edge_terms(
    edges: EdgeSet,
    a: np.ndarray,
    r: np.ndarray,
    sum_p: np.ndarray,
    sum_ap: np.ndarray,
    edge_weights: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per edge, what the lines' motion adds to :func:`normal_equations` besides ``d phi``: ``sum q``, ``mean P``,
    ``sum q r``, ``sum q a^2``, ``sum q a r``, ``S = sum q a Pc`` and the edge weights (1 by default), from the
    (``q``-weighted) sums ``sum_p`` and ``sum_ap`` of :func:`_line_turn`."""
    st, q = edges.starts, edges.weights
    sum_q = _weight_sums(edges)
    mean_p = sum_p / sum_q
    aq, rq = (a, r) if q is None else (a * q, r * q)
    sum_a = np.add.reduceat(aq, st)
    sum_r = np.add.reduceat(rq, st)
    sum_aa = np.add.reduceat(aq * a, st)
    sum_ar = np.add.reduceat(aq * r, st)
    s_ap = sum_ap - mean_p * sum_a  # sum q a Pc
    w = np.ones(edges.n_edges) if edge_weights is None else np.asarray(edge_weights, dtype=np.float64)
    return sum_q, mean_p, sum_r, sum_aa, sum_ar, s_ap, w


def _field_normal_equations(
    rows: ProjectedRows,
    f: FieldRows,
    edges: EdgeSet,
    r: np.ndarray,
    a: np.ndarray,
    nrm: np.ndarray,
    tan: np.ndarray,
    edge_weights: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`normal_equations` (one group) with a B-spline field's rows of ``P`` and ``T`` kept sparse
    (:class:`~pipeline.models.radial_field.ProjectedRows`): the same sums, each field row's over the points whose
    basis touches it only. Per edge, ``sum q P``, ``sum q a P`` and ``sum q r T`` of a field row by
    ``np.bincount``; ``P^T W P`` of the dense rows one product, of the field rows (and across dense and field rows)
    a product per cell of the grid (its points' 16 basis values per component), added into place. The dense path
    does the same arithmetic on the zeros too: the results agree to rounding."""
    st, ct, q = edges.starts, edges.counts, edges.weights
    n, n_e, m = rows.n, edges.n_edges, f.m
    rd = rows.rows
    pd, td = rows.p, rows.t
    # per edge: sums of q P, q a P, q r T (every row), the line's turn d phi
    aq, rq = (a, r) if q is None else (a * q, r * q)
    pq = pd if q is None else pd * q
    sum_p, sum_ap, sum_rt = np.empty((n, n_e)), np.empty((n, n_e)), np.empty((n, n_e))
    sum_p[rd] = np.add.reduceat(pq, st, axis=1)
    sum_ap[rd] = np.add.reduceat(pq * a, st, axis=1)
    sum_rt[rd] = np.add.reduceat(td * rq, st, axis=1)
    den = np.add.reduceat(aq * a - rq * r, st)
    key = (np.repeat(np.arange(n_e), ct)[:, None] * m + f.idx).ravel()
    qv = f.val if q is None else f.val * q[:, None]
    for c, row in ((0, f.row_x), (1, f.row_y)):
        for out, per_point in ((sum_p, nrm[:, c]), (sum_ap, a * nrm[:, c]), (sum_rt, r * tan[:, c])):
            s = np.bincount(key, (qv * per_point[:, None]).ravel(), minlength=n_e * m)
            out[row : row + m] = s.reshape(n_e, m).T
    dphi = (sum_ap + sum_rt) / np.where(np.abs(den) > 1e-300, den, 1e-300)
    # P W P^T and P W r
    w_pt = edges.point_weights(edge_weights)
    pw = pd if w_pt is None else pd * w_pt
    rw = r if w_pt is None else r * w_pt
    ata = np.zeros((n, n))
    ata[np.ix_(rd, rd)] = pw @ pd.T
    n_cells, k, nd = len(f.cell_idx), f.idx.shape[1], len(rd)
    assert f.row_y == f.row_x + m, "the field's y rows follow its x rows"
    fr = slice(f.row_x, f.row_x + 2 * m)
    no = nrm[f.order]
    local = np.zeros((n_cells * f.size, 2 * k))  # per cell, its points' field values (x then y), zero-padded
    local[f.place, :k] = f.val_sorted * no[:, :1]
    local[f.place, k:] = f.val_sorted * no[:, 1:]
    dense = np.zeros((n_cells * f.size, nd))  # per cell, its points' weighted dense rows, zero-padded
    dense[f.place] = pw.T[f.order]
    weighted = local
    if w_pt is not None:
        weighted = local * np.bincount(f.place, w_pt[f.order], minlength=n_cells * f.size)[:, None]
    local3 = local.reshape(n_cells, f.size, 2 * k)
    ff = np.matmul(weighted.reshape(n_cells, f.size, 2 * k).transpose(0, 2, 1), local3)  # (cells, 2k, 2k)
    df = np.matmul(dense.reshape(n_cells, f.size, nd).transpose(0, 2, 1), local3)  # (cells, dense rows, 2k)
    ata[fr, fr] = np.bincount(f.keys.ravel(), ff.ravel(), minlength=4 * m * m).reshape(2 * m, 2 * m)
    both = np.concatenate([f.cell_idx, m + f.cell_idx], axis=1)
    keys = np.arange(nd)[None, :, None] * (2 * m) + both[:, None, :]
    dfm = np.bincount(keys.ravel(), df.ravel(), minlength=nd * 2 * m).reshape(nd, 2 * m)
    ata[rd, fr] = dfm
    ata[fr, rd] = dfm.T
    atb = np.empty(n)
    atb[rd] = pw @ r
    for c, row in ((0, f.row_x), (1, f.row_y)):
        atb[row : row + m] = np.bincount(f.idx.ravel(), (f.val * (rw * nrm[:, c])[:, None]).ravel(), minlength=m)
    # the lines' motion (as normal_equations)
    sum_q, mean_p, sum_r, sum_aa, sum_ar, s_ap, we = _edge_terms(edges, a, r, sum_p, sum_ap, edge_weights)
    # mean P (sum q) mean P^T + S dphi^T + dphi S^T - (sum a^2) dphi dphi^T (each edge weighted) in one product
    left = np.concatenate([mean_p, s_ap, dphi], axis=1)
    right = np.concatenate([mean_p * (sum_q * we), dphi * we, s_ap * we - dphi * (sum_aa * we)], axis=1)
    ata -= left @ right.T
    atb += -(mean_p @ (sum_r * we)) - dphi @ (sum_ar * we)
    return ata[None], atb[None], np.array([rw @ r])
