"""Naive, obviously-correct twins of the core kernels (slow; for tests only)."""

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import Delaunay, Voronoi, cKDTree

from tiledsimplify.core import local_mesh as lm


def facet_width(X, a, b, others, half, reach=np.inf):
    """Largest radius of a disc inside the Voronoi facet of (a, b), clipped to the square of
    half-size ``half`` around their midpoint and to the disc where both points are within
    ``reach`` (a 512-gon around it), by linear programming (negative: no facet)."""
    pa = X[a]
    d = X[b] - pa
    L = np.linalg.norm(d)
    u = d / L
    e1 = np.cross(u, [1.0, 0.0, 0.0])
    if np.linalg.norm(e1) < 0.5:
        e1 = np.cross(u, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    m = d / 2
    A, bb = [], []
    for s in others:
        if s == a or s == b:
            continue
        sp = X[s] - pa
        g = np.array([2 * sp @ e1, 2 * sp @ e2])
        h = sp @ sp - 2 * sp @ m
        gn = np.linalg.norm(g)
        if gn < 1e-12 * L:
            if h < 0:
                return -1.0
            continue
        A.append([g[0] / gn, g[1] / gn, 1.0])
        bb.append(h / gn)
    for gx, gy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        A.append([gx, gy, 1.0])
        bb.append(half)
    if np.isfinite(reach):
        r2 = reach ** 2 - L ** 2 / 4
        if r2 <= 0:
            return -1.0
        for t in np.linspace(0, 2 * np.pi, 512, endpoint=False):
            A.append([np.cos(t), np.sin(t), 1.0])
            bb.append(np.sqrt(r2))
    r = linprog([0, 0, -1], A_ub=np.array(A), b_ub=np.array(bb),
                bounds=[(None, None), (None, None), (None, None)], method="highs")
    return float(r.x[2]) if r.status == 0 else -1.0


def voronoi_edges(X, half, tol, candidates=None, reach=np.inf):
    """Pairs whose facet (against *all* other points, within ``reach``) is wider than
    ``tol``, by LP."""
    n = len(X)
    if candidates is None:
        candidates = [(i, j) for i in range(n) for j in range(i + 1, n)]
    out = set()
    for a, b in candidates:
        if facet_width(X, a, b, range(n), half, reach) > tol:
            out.add((min(a, b), max(a, b)))
    return out


def delaunay_edges(X):
    tri = Delaunay(X)
    e = set()
    for s in tri.simplices:
        for i in range(4):
            for j in range(i + 1, 4):
                a, b = sorted((int(s[i]), int(s[j])))
                e.add((a, b))
    return e


def reference_plane(X, p, vn):
    """Steps 1-2 of the local-mesh rule with numpy: sorted, cut neighbours and plane normal."""
    vn = np.asarray(sorted(vn, key=lambda q: (float(np.sum((X[q] - X[p]) ** 2)), q)))
    d = np.linalg.norm(X[vn] - X[p], axis=1)
    jumps = [j for j in range(3, len(vn)) if d[j] > lm.GAP * d[j - 1]]
    if jumps:
        vn, d = vn[: jumps[0]], d[: jumps[0]]
    m = len(vn)
    if m >= 3:
        m = int(np.sum(d <= lm.FIT * d[2]))
    best, kbest = -1.0, m
    for k in range(2, m + 1):
        P = np.vstack([X[p], X[vn[:k]]])
        w = np.linalg.eigvalsh(np.cov(P.T, bias=True))
        spread = w[1] / w[2] if w[2] > 0 else 0.0
        if k >= lm.MIN_PLANE and spread >= lm.SPREAD:
            kbest = k
            break
        if spread > best:
            best, kbest = spread, k
    P = np.vstack([X[p], X[vn[:kbest]]])
    w, v = np.linalg.eigh(np.cov(P.T, bias=True))
    return vn, v[:, 0], float(d[kbest - 1])


def local_mesh(X, p, vn):
    """``DN_p`` via scipy's 2-D Voronoi of the projected neighbours, or None when ``p``'s cell
    is unbounded or reaches the clipping square (the rule's box then matters)."""
    vn, n0, radius = reference_plane(X, p, vn)
    half = lm.BOX * radius
    rel = X[vn] - X[p]
    dist = np.linalg.norm(rel, axis=1)
    ok = np.abs(rel @ n0) <= np.sin(np.radians(lm.MAX_ELEVATION)) * dist
    cand = vn[ok]
    t1 = np.cross(n0, [1, 0, 0])
    if np.linalg.norm(t1) < 0.5:
        t1 = np.cross(n0, [0, 1, 0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n0, t1)
    P2 = np.vstack([[0.0, 0.0], np.c_[rel[ok] @ t1, rel[ok] @ t2]])
    if len(P2) < 4:
        return None
    try:
        vor = Voronoi(P2)
    except Exception:
        return None
    region = vor.regions[vor.point_region[0]]
    if -1 in region or len(region) == 0:
        return None
    if np.abs(vor.vertices[region]).max() >= half:
        return None
    out = set()
    for (i, j), rv in zip(vor.ridge_points, vor.ridge_vertices):
        if 0 in (i, j) and -1 not in rv:
            length = np.linalg.norm(vor.vertices[rv[0]] - vor.vertices[rv[1]])
            if length > 1e-9 * half:
                out.add(int(cand[(j if i == 0 else i) - 1]))
    return out


def normal(X, p, dn, fallback):
    P = np.vstack([X[p], X[list(dn)]])
    w, v = np.linalg.eigh(np.cov(P.T, bias=True))
    if len(dn) < 2 or w[1] <= lm.SPREAD * w[2]:
        return fallback
    return v[:, 0]


def deviation(X, normals, p, dn):
    """The boundary measure by ``np.linalg.lstsq``: RMS residual of g = W u, W symmetric."""
    if len(dn) < 3:
        return 0.0
    n = normals[p]
    t1 = np.cross(n, [1, 0, 0])
    if np.linalg.norm(t1) < 0.5:
        t1 = np.cross(n, [0, 1, 0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    rel = X[list(dn)] - X[p]
    rel = rel / np.sqrt(np.mean(np.sum(rel ** 2, axis=1)))
    nq = normals[list(dn)] * np.sign(normals[list(dn)] @ n)[:, None]
    u, v = rel @ t1, rel @ t2
    g1, g2 = nq @ t1, nq @ t2
    z = np.zeros_like(u)
    M = np.vstack([np.c_[u, v, z], np.c_[z, u, v]])
    g = np.concatenate([g1, g2])
    x, *_ = np.linalg.lstsq(M, g, rcond=None)
    r = g - M @ x
    return float(np.sqrt(np.sum(r ** 2) / (2 * len(dn))))


def importance(X, normals, boundary, p, dn):
    """Eq. (1), literally."""
    terms = [abs((X[p] - X[q]) @ normals[q]) for q in dn if not boundary[q]]
    return float(np.mean(terms)) if terms else np.inf


def coverage_importance(X, normals, boundary, p, dn, weight):
    """Eq. (1) (0 if every neighbour is a boundary point) + weight * mean squared distance."""
    if not len(dn):
        return np.inf
    e = importance(X, normals, boundary, p, dn)
    e = 0.0 if e == np.inf else e
    rho2 = float(np.mean(np.sum((X[dn] - X[p]) ** 2, axis=1)))
    return e + weight * rho2


def thin_below(X, cand, removable, tie, level, n_remove, scale=None):
    """Gap thinning (:func:`tiledsimplify.core.refine.thin_below`) by brute force: remove the
    removable candidate whose removal leaves the farthest input point nearest to it the least
    far from the other remaining candidates, while that is within ``level``; ties by ``tie``.
    ``scale`` (per input point, default 1): each point's distance counts that many times."""
    scale = np.ones(len(X)) if scale is None else np.asarray(scale, dtype=np.float64)
    alive = np.ones(len(cand), dtype=bool)
    D = np.linalg.norm(X[:, None, :] - X[cand][None, :, :], axis=2)  # input x candidate
    removed = []
    while len(removed) < n_remove:
        best = None
        live = np.flatnonzero(alive)
        own = live[np.argmin(D[:, live], axis=1)]
        for c in np.flatnonzero(alive & removable):
            others = live[live != c]
            mine = own == c
            gap = ((D[np.ix_(mine, others)].min(axis=1) * scale[mine]).max() if mine.any()
                   else 0.0)
            if best is None or (gap, tie[c]) < (best[0], tie[best[1]]):
                best = (gap, c)
        if best is None or not best[0] <= level:
            break
        alive[best[1]] = False
        removed.append(best[1])
    return np.array(removed, dtype=np.int64)


def thin_lists(nbr, nd, removable, tie, level, n_remove, scale=None):
    """Gap thinning on given candidate lists (``nbr``/``nd`` as
    :func:`tiledsimplify.core.refine.thin_below` takes them, id ``m`` = none) by recomputing
    every owner and every gap from scratch at each step. Returns ``(removed, dist)``."""
    scale = np.ones(len(nbr)) if scale is None else np.asarray(scale, dtype=np.float64)
    m = len(removable)
    alive = np.ones(m + 1, dtype=bool)
    alive[m] = False
    removed = []

    def first(x, start):
        live = [j for j in range(start, nbr.shape[1]) if alive[nbr[x, j]]]
        return live[0] if live else -1

    def owners():  # position of each row's owner; a row whose list starts with "none" keeps 0
        return [0 if nbr[x, 0] == m else first(x, 0) for x in range(len(nbr))]

    while len(removed) < n_remove:
        own = owners()
        best = None
        for c in np.flatnonzero(alive[:m] & removable):
            gaps = [0.0]
            for x in range(len(nbr)):
                if own[x] >= 0 and nbr[x, own[x]] == c:
                    j = first(x, own[x] + 1)
                    gaps.append(nd[x, j] * scale[x] if j >= 0 else np.inf)
            if best is None or (max(gaps), tie[c], c) < best:
                best = (max(gaps), tie[c], c)
        if best is None or not best[0] <= level:
            break
        alive[best[2]] = False
        removed.append(best[2])
    own = owners()
    dist = np.array([nd[x, j] if j >= 0 else np.inf for x, j in enumerate(own)])
    return np.array(removed, dtype=np.int64), dist


def exact_order(Q, C, tie, k):
    """The ``k`` nearest candidates ``C`` of every query ``Q``, in the exact order of
    :func:`tiledsimplify.core.cell_grid.nearest` — (squared distance rounded as cKDTree rounds
    it, ``tie``, position) — by brute force: ``(order, squared distances)`` (q, k)."""
    s = np.zeros((len(Q), len(C)))
    for d in range(3):
        e = C[None, :, d] - Q[:, d, None]
        s += e * e  # ((e0² + e1²) + e2²), as cKDTree adds them
    k = min(k, len(C))
    kth = np.partition(s, k - 1, axis=1)[:, k - 1]
    q, c = np.nonzero(s <= kth[:, None])  # the k nearest and every tie of the k-th
    o = np.lexsort((c, tie[c], s[q, c], q))
    q, c = q[o], c[o]
    rank = np.arange(q.size) - np.searchsorted(q, q)
    q, c = q[rank < k], c[rank < k]
    order = c.reshape(len(Q), k)
    return order, np.take_along_axis(s, order, axis=1)


def _fill_dense(X, trial, level):
    """Farthest first by ``np.argmax``, every addition lowering every distance."""
    added = []
    while True:
        x = int(np.argmax(trial))
        if not trial[x] > level:
            break
        added.append(x)
        e = X - X[x]
        trial = np.minimum(trial, np.sqrt(e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1]
                                          + e[:, 2] * e[:, 2]))
        trial[x] = 0.0
    return np.asarray(added, dtype=np.int64)


def refine_coverage(X, keep, fixed, *, addable=None, watch=None, tie=None, step=0.05,
                    min_step=0.002, max_rounds=60, k=16, edges=None, edge_radius=0.0):
    """:func:`tiledsimplify.core.refine.refine_coverage` by brute force: per round a fill that
    lowers every distance, and every input point's candidates sorted by (distance, tie); the
    flags' cover (``edges``) as a fill of the flags alone, then a cap on their rows."""
    from tiledsimplify.core.refine import inputs, thin_below
    X, keep, fixed, addable, ignored, watched, tie = inputs(X, keep, fixed, addable, watch, tie)
    info = {"hausdorff_before": 0.0, "hausdorff_after": 0.0, "rounds": 0, "swaps": 0,
            "edge_swaps": 0}
    if not (keep & ~fixed).any() or not (addable & ~keep).any():
        return keep, info
    dist, _ = cKDTree(X[keep]).query(X)
    dist[ignored] = 0.0
    H = float(dist[~watched].max())
    info["hausdorff_before"] = H
    counted = np.flatnonzero(~ignored)
    cap = np.full(len(X), np.inf)

    def swap(added, level):  # the swap at ``level``: the new distances, or None
        cand = np.concatenate([np.flatnonzero(keep), added])
        removable = ~fixed[cand]
        removable[cand.size - added.size:] = False
        cand_tie = np.ascontiguousarray(tie[cand], dtype=np.uint64)
        order, s = exact_order(X[counted], X[cand], cand_tie, k)
        d1 = np.zeros(len(X))
        d1[counted] = np.sqrt(s[:, 0])
        o1 = np.full(len(X), -1)
        o1[counted] = order[:, 0]
        removable[o1[(d1 >= level) & (o1 >= 0)]] = False  # at or beyond: keeps its nearest
        rows = counted[removable[order[:, 0]]]
        at = np.searchsorted(counted, rows)
        inside = s[at] < level * level
        nd = np.where(inside, np.sqrt(s[at]), np.inf)
        nbr = np.where(inside, order[at], cand.size)
        scale = np.ones(rows.size)
        tight = cap[rows] < level
        scale[tight] = level / cap[rows][tight]
        gone, d_rows = thin_below(*lists_from_dense(nd, nbr, cand.size), removable, cand_tie,
                                  level, added.size, scale)
        if gone.size < added.size:
            return None
        keep[added] = True
        keep[cand[gone]] = False
        d1[rows] = d_rows
        return d1

    if edges is not None and edge_radius > 0:
        edges = np.asarray(edges, dtype=bool)
        cap[edges] = edge_radius
        added = _fill_dense(X, np.where(edges & addable & ~keep, dist, 0.0), edge_radius)
        while added.size:
            d1 = swap(added, H)
            if d1 is not None:
                fixed = fixed.copy()
                fixed[added] = True
                info["edge_swaps"] = int(added.size)
                info["swaps"] += int(added.size)
                dist = d1
                H = float(dist[~watched].max())
                break
            added = added[:added.size // 2]
    while info["rounds"] < max_rounds and step >= min_step and H > 0:
        info["rounds"] += 1
        level = (1.0 - step) * H
        trial = dist.copy()
        trial[watched] = 0.0
        added = _fill_dense(X, trial, level)
        d1 = swap(added, level)
        if d1 is None:
            step *= 0.5
            continue
        info["swaps"] += int(added.size)
        dist = d1
        H = float(dist[~watched].max())
    info["hausdorff_after"] = H
    return keep, info


def lists_from_dense(nd, nbr, none):
    """CSR lists ``(start, idx, dist)`` for :func:`tiledsimplify.core.refine.thin_below` from
    cKDTree's ``query(k=…)`` output ``nd`` / ``nbr`` (r, k), where ``none`` (the tree's size)
    pads the rows with fewer than ``k``."""
    nbr = np.asarray(nbr, dtype=np.int64).reshape(len(nbr), -1)
    nd = np.asarray(nd, dtype=np.float64).reshape(len(nbr), -1)
    valid = nbr != none
    start = np.zeros(len(nbr) + 1, dtype=np.int64)
    start[1:] = np.cumsum(valid.sum(axis=1))
    return start, nbr[valid], nd[valid]


def global_cut_by_sorting(sequences, n_remove):
    """The global cut by its definition: every step of every tile keyed by (running maximum,
    tile, step), sorted, and the ``n_remove`` smallest taken; the steps taken per tile."""
    keys = [(float(r) + 0.0, t, s) for t, seq in sequences.items()
            for s, r in enumerate(np.maximum.accumulate(np.asarray(seq, dtype=float)))]
    keys.sort()
    cut = {t: 0 for t in sequences}
    for _, t, _ in keys[:max(int(n_remove), 0)]:
        cut[t] += 1
    return cut


def disk_sample(X, neighbours, fixed, order, r):
    """:func:`tiledsimplify.core.prethin.disk_sample` by sets: keep the fixed points, then each
    point of ``order`` not reachable from a kept point ``p`` along graph edges through points
    within ``r`` of ``p``."""
    n = len(X)
    keep = np.zeros(n, dtype=bool)
    covered = np.zeros(n, dtype=bool)

    def cover(p):
        seen, todo = {p}, [p]
        while todo:
            a = todo.pop()
            for q in neighbours[a]:
                if q not in seen and np.sum((X[q] - X[p]) ** 2) <= r * r:
                    seen.add(q)
                    todo.append(q)
        covered[list(seen)] = True

    for p in np.flatnonzero(fixed):
        keep[p] = True
        cover(p)
    for p in order:
        if not covered[p]:
            keep[p] = True
            cover(p)
    return keep
