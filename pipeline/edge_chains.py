"""Chaining and hysteresis of the edge detector's sub-pixel points (steps 5-6 of
:mod:`pipeline.edges`).

Every edge point looks for the nearest point that continues the curve *forward* and the nearest
that continues it *backward*, among its 8 neighbours and, where none is found there, in the
outer ring of its 5x5 neighbourhood (:func:`link_points`); the linked points are then ordered along
their chains (:func:`order_chains`). :func:`pipeline.edges.detect_edges` keeps a chain when one
of its points has a modulus above the high threshold.

References
----------
.. [1] R. Grompone von Gioi, G. Randall, "A Sub-Pixel Edge Detector: an
   Implementation of the Canny/Devernay Algorithm", Image Processing On Line
   7 (2017), pp. 347-372. https://doi.org/10.5201/ipol.2017.216
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Floats = NDArray[np.float64]
Ints = NDArray[np.int64]

# 5x5 neighbourhood used for chaining (centre excluded), as in the IPOL code.
_NEIGH = [(dx, dy) for dy in range(-2, 3) for dx in range(-2, 3) if (dx, dy) != (0, 0)]
LINK_BAND_PX = 4_000_000
"""Pixels of one band of the chaining's label map (int32)."""


def link_points(xy: Floats, grad: Floats, idx: NDArray[np.intp], shape: tuple[int, int]) -> tuple[Ints, Ints]:
    """Vectorised IPOL chaining; returns next/prev arrays (-1 = none).

    Every point looks for the nearest compatible neighbour forward and
    backward, first among its 8 neighbours and, only where none is found
    there, in the outer ring of its 5x5 neighbourhood (the IPOL code scans
    the whole 5x5 window; a closer point in the outer ring is rare and both
    are valid links). Mutual choices (``fwd[e] = f`` and ``bck[f] = e``) are
    linked first, the remaining candidates greedily by decreasing
    ``1/distance`` so that every point keeps at most one successor and one
    predecessor.
    """
    h, w = shape
    n = xy.shape[0]
    ex, ey = xy[:, 0], xy[:, 1]
    gx, gy = grad[:, 0], grad[:, 1]
    fwd = np.full(n, -1, np.int64)
    bck = np.full(n, -1, np.int64)
    fwd_d = np.full(n, np.inf)
    bck_d = np.full(n, np.inf)
    ring1 = [(ox, oy) for ox, oy in _NEIGH if max(abs(ox), abs(oy)) == 1]
    ring2 = [(ox, oy) for ox, oy in _NEIGH if max(abs(ox), abs(oy)) == 2]
    # label map of the points by bands of rows (with the 2 rows around each band), not of the whole image
    rows = max(8, LINK_BAND_PX // max(w, 1))
    lab_buf = np.empty(min(h, rows + 4) * w, np.int32)
    for b0 in range(0, h, rows):
        b1 = min(h, b0 + rows)
        p0, p1 = (int(v) for v in np.searchsorted(idx, [b0 * w, b1 * w]))
        if p0 == p1:
            continue
        l0, l1 = max(0, b0 - 2) * w, min(h, b1 + 2) * w
        q0, q1 = (int(v) for v in np.searchsorted(idx, [l0, l1]))
        lab = lab_buf[: l1 - l0]
        lab.fill(-1)
        lab[idx[q0:q1] - l0] = np.arange(q0, q1, dtype=np.int32)
        pts = np.arange(p0, p1)
        for ring in (ring1, ring2):
            if ring is ring2:
                pts = pts[(fwd[pts] < 0) | (bck[pts] < 0)]
            base = idx[pts] - l0
            for ox, oy in ring:  # IPOL scan order; ties keep the first
                nb = lab[base + (oy * w + ox)]
                has = nb >= 0
                e = pts[has]
                t = nb[has].astype(np.int64)
                dx = ex[t] - ex[e]
                dy = ey[t] - ey[e]
                cf = gy[e] * dx - gx[e] * dy  # side of the gradient of e w.r.t. e -> t
                ct = gy[t] * dx - gx[t] * dy  # same for the gradient of t
                d2 = dx * dx + dy * dy
                comp = cf * ct > 0
                f = comp & (cf > 0) & (d2 < fwd_d[e])
                fwd_d[e[f]] = d2[f]
                fwd[e[f]] = t[f]
                b = comp & (cf < 0) & (d2 < bck_d[e])
                bck_d[e[b]] = d2[b]
                bck[e[b]] = t[b]
    del lab_buf
    nxt = np.full(n, -1, np.int64)
    prv = np.full(n, -1, np.int64)
    # 1. mutual choices: consistent by construction (one out-link, one in-link each)
    e = np.nonzero(fwd >= 0)[0]
    mutual = bck[fwd[e]] == e
    e = e[mutual]
    nxt[e] = fwd[e]
    prv[fwd[e]] = e
    # 2. the other candidate links src -> dst, greedily by decreasing score
    hf = np.nonzero((fwd >= 0) & (nxt < 0))[0]
    hf = hf[prv[fwd[hf]] < 0]
    hb = np.nonzero((bck >= 0) & (prv < 0))[0]
    hb = hb[nxt[bck[hb]] < 0]
    src = np.concatenate([hf, bck[hb]])
    dst = np.concatenate([fwd[hf], hb])
    sc = 1.0 / np.sqrt(np.concatenate([fwd_d[hf], bck_d[hb]]))
    key, first = np.unique(src * n + dst, return_index=True)  # dedupe
    src, dst, sc = src[first], dst[first], sc[first]
    while src.size:  # rounds: accept each source's best if also best for its destination
        order = np.lexsort((dst, src, -sc))
        _, fs = np.unique(src[order], return_index=True)
        cand = np.sort(order[fs])
        o2 = cand[np.lexsort((src[cand], -sc[cand]))]
        _, fd = np.unique(dst[o2], return_index=True)
        acc = o2[fd]
        nxt[src[acc]] = dst[acc]
        prv[dst[acc]] = src[acc]
        keep = (nxt[src] < 0) & (prv[dst] < 0)
        src, dst, sc = src[keep], dst[keep], sc[keep]
    return nxt, prv


def _path_components(cn: np.ndarray, cp: np.ndarray) -> tuple[int, np.ndarray]:
    """Components of a graph where every node has at most one successor ``cn`` and one
    predecessor ``cp`` (-1: none), i.e. disjoint paths and cycles: ``(count, labels 0..count-1)``.

    Each node's label is the smallest index of its component, found by pointer doubling
    (after round ``k`` a node holds the minimum over the ``2**k`` nodes following it),
    first along the successors, then along the predecessors; on a cycle the first pass
    already covers the whole cycle within ``ceil(log2(m))`` rounds.
    """
    m = cn.size
    rounds = max(1, int(np.ceil(np.log2(max(m, 2))))) + 1
    lab = np.arange(m, dtype=np.int64)
    for ptr0 in (cn, cp):
        ptr = ptr0.copy()
        active = np.nonzero(ptr >= 0)[0]
        for _ in range(rounds):
            if not active.size:
                break
            p = ptr[active]
            lab[active] = np.minimum(lab[active], lab[p])
            ptr[active] = ptr[p]
            active = active[ptr[active] >= 0]
    uniq, clab = np.unique(lab, return_inverse=True)
    return int(uniq.size), clab.astype(np.int64)


def _rank_to_tail(cn: Ints) -> tuple[Ints, Ints]:
    """List ranking of disjoint paths (``cn``: successor, -1 at a path's last node) by pointer
    jumping with saturating pointers (Wyllie): each node's distance to its path's last node
    and that node. Nodes on a cycle (no last node) end with a pointer to a node that has a
    successor; their distances are then meaningless."""
    m = cn.size
    has = cn >= 0
    ptr = np.where(has, cn, np.arange(m, dtype=np.int64))
    dist = has.astype(np.int64)
    active = np.flatnonzero(has)
    for _ in range(max(1, int(np.ceil(np.log2(max(m, 2))))) + 1):
        if not active.size:
            break
        p = ptr[active]
        dist[active] += dist[p]
        pp = ptr[p]
        ptr[active] = pp
        active = active[ptr[pp] != pp]
    return dist, ptr


def order_chains(nxt: Ints, prv: Ints) -> tuple[Ints, NDArray[np.intp]]:
    """Label linked components and order their points along the links.

    Returns ``(labels, order)`` where ``order`` sorts points by (label,
    position along the chain). Linked components are labelled ``0, 1, ...`` in the
    order of their smallest point index, unlinked points (singleton components) after
    them. Cycles are opened at their smallest index.
    """
    n = nxt.size
    linked = np.flatnonzero((nxt >= 0) | (prv >= 0))
    m = linked.size
    lab = np.empty(n, np.int64)
    single = np.ones(n, bool)
    single[linked] = False
    pos = np.zeros(n, np.int64)
    ncomp = 0
    if m:
        # compact numbering of the linked points
        comp_of = np.full(n, -1, np.int64)
        comp_of[linked] = np.arange(m)
        cn = comp_of[nxt[linked]]
        cn[nxt[linked] < 0] = -1  # (index -1 picked the last entry)
        cp = comp_of[prv[linked]]
        cp[prv[linked] < 0] = -1
        # paths: distance to the last point, which names the component
        dist, tail = _rank_to_tail(cn)
        cyc = np.flatnonzero(cn[tail] >= 0)
        if cyc.size:  # cycles: opened at their smallest index, ranked again
            loc = np.full(m, -1, np.int64)
            loc[cyc] = np.arange(cyc.size)
            ncyc, clab = _path_components(loc[cn[cyc]], loc[cp[cyc]])
            first = np.full(ncyc, cyc.size, np.int64)
            np.minimum.at(first, clab, np.arange(cyc.size))
            hd = cyc[first]
            cn[cp[hd]] = -1
            cp[hd] = -1
            sub = cn[cyc]
            d2, t2 = _rank_to_tail(np.where(sub >= 0, loc[np.maximum(sub, 0)], -1))
            dist[cyc] = d2
            tail[cyc] = cyc[t2]
        # label = rank of the component's smallest index
        key = np.full(m, m, np.int64)
        np.minimum.at(key, tail, np.arange(m))
        uniq, clab = np.unique(key[tail], return_inverse=True)
        ncomp = int(uniq.size)
        lab[linked] = clab.ravel()
        pos[linked] = -dist
    lab[single] = ncomp + np.arange(int(single.sum()))
    order = np.lexsort((pos, lab))
    return lab, order
