"""Exact nearest searches among a changing subset of points, on a grid of cubic cells.

The gap refinement (:mod:`.refine`) asks, round after round, which *candidates* (a subset of
the input points that changes every round) lie nearest each input point, within a radius that
never grows. A kd-tree over each round's candidates answers that, but costs a build and a full
query per round. Here a grid of cubic cells of side ``h`` (at least every radius asked) is
built once over the input points; each round the candidates are sorted into its cells (a
counting sort) and a search visits the (non-empty) cells among the 27 around a point's cell.

**Exact answers, one defined order.** Distances are computed as cKDTree computes them
(``((dx² + dy²) + dz²)``, then the square root), bit for bit, and candidates are ordered by
(squared distance, a tie key per candidate, position): equal distances — everywhere on
quantised LiDAR scans — are decided by the key, not by the layout of a tree. Only a search
whose radius may reach beyond the 27 cells is left to the caller (:func:`exact_search`
answers it by brute force over a kd-tree's superset). Before 2026-12-02 the searches followed
cKDTree's own order of equal distances, which cost a kd-tree over the candidates in every
round for the ~1 % of points with a tie.
"""

import numpy as np

from ._jit import jit, jit_leaf
from .bounds import box

#: a point within (1 - COVER) h of another, in every coordinate, is at most one cell away
#: (rounding of the cell index is far below this for up to MAX_CELLS cells per axis)
COVER = 1e-7
MAX_CELLS = 1 << 20


class CellGrid:
    """Cells of side ``h`` over ``X``, built once (a sort of the cell keys, O(n log n)).

    Attributes
    ----------
    h : float
        Cell side. Every point within ``reach = (1 - COVER) · h`` of a point lies in one of
        the 27 cells around its cell.
    cell_of : int64 (n,)
        Each point's cell (0 … ``n_cells`` − 1).
    near_start, near : int64
        CSR: the non-empty cells among the 27 around each cell (itself included).
    pt_start, pt, pt_xyz
        CSR: the points of each cell (``pt``, ascending), and their coordinates in that order.
    """

    def __init__(self, X, h):
        X = np.ascontiguousarray(X, dtype=np.float64)
        lo, hi = box(X)
        span = float((hi - lo).max())
        self.h = h = max(float(h), span / MAX_CELLS, np.finfo(float).tiny)
        self.reach = (1.0 - COVER) * h
        key, step = _cell_keys(X, lo, h)
        self.pt = np.argsort(key, kind="stable")
        self.cell_of, self.pt_start, self.near_start, self.near = _cells(key, self.pt, step)
        self.n_cells = self.pt_start.size - 1
        self.pt_xyz = np.ascontiguousarray(X[self.pt])

    def load(self, members, queries):
        """How many of ``members`` (point ids; None: every point) a search from each of
        ``queries`` visits, on average. A few queries read only the cells around their own
        (:func:`nearest_other`'s probe: every cell took ~0.7 s at 1e7 points); queries in
        most cells, one pass over all (their gather cost 0.9 s at 1M against 0.04 s)."""
        queries = np.asarray(queries, dtype=np.int64)
        if not queries.size:
            return 0.0
        cnt = (np.diff(self.pt_start) if members is None
               else np.bincount(self.cell_of[members], minlength=self.n_cells))
        weight = np.bincount(self.cell_of[queries], minlength=self.n_cells)
        cells = np.flatnonzero(weight)
        if 4 * cells.size > self.n_cells:  # most cells: one pass over all of them is cheaper
            around = np.add.reduceat(cnt[self.near], self.near_start[:-1])[cells]
        else:
            lo = self.near_start[cells]
            ln = self.near_start[cells + 1] - lo
            first = np.cumsum(ln) - ln
            near = self.near[np.arange(int(ln.sum())) - np.repeat(first - lo, ln)]
            around = np.add.reduceat(cnt[near], first)
        return float((weight[cells] * around).sum() / queries.size)

    def members(self, X, ids):
        """The points ``ids`` sorted into the cells: ``(start, slot, xyz)`` with ``slot`` the
        position in ``ids`` of each, cell by cell, and ``xyz`` their coordinates."""
        start, slot = bucket(self.cell_of[ids], np.arange(ids.size), self.n_cells)
        return start, slot, np.ascontiguousarray(X[ids[slot]])


@jit
def _cell_keys(X, lo, h):
    """Each point's cell as one int64 key (a layer of empty cells around), and the key steps
    to the 27 cells around a cell."""
    n = X.shape[0]
    ijk = np.empty((n, 3), dtype=np.int64)
    top = np.zeros(3, dtype=np.int64)
    for i in range(n):
        for d in range(3):
            ijk[i, d] = np.int64(np.floor((X[i, d] - lo[d]) / h)) + 1
            top[d] = max(top[d], ijk[i, d])
    dims = top + 2
    key = np.empty(n, dtype=np.int64)
    for i in range(n):
        key[i] = (ijk[i, 0] * dims[1] + ijk[i, 1]) * dims[2] + ijk[i, 2]
    step = np.empty(27, dtype=np.int64)
    u = 0
    for a in range(-1, 2):
        for b in range(-1, 2):
            for c in range(-1, 2):
                step[u] = (a * dims[1] + b) * dims[2] + c
                u += 1
    return key, step


@jit
def _cells(key, order, step):
    """From the points' keys and their order by key: ``cell_of``, ``pt_start`` and the CSR of
    the non-empty cells around each cell (one merge of the sorted keys per step)."""
    n = key.size
    cell_of = np.empty(n, dtype=np.int64)
    cells = np.empty(n, dtype=np.int64)
    pt_start = np.empty(n + 1, dtype=np.int64)
    c = -1
    for t in range(n):
        i = order[t]
        if t == 0 or key[i] != cells[c]:
            c += 1
            cells[c] = key[i]
            pt_start[c] = t
        cell_of[i] = c
    n_cells = c + 1
    pt_start[n_cells] = n
    around = np.full((n_cells, step.size), -1, dtype=np.int64)
    for u in range(step.size):
        p = 0
        for c in range(n_cells):  # cells[c] + step[u] grows with c: one pass
            want = cells[c] + step[u]
            while p < n_cells and cells[p] < want:
                p += 1
            if p < n_cells and cells[p] == want:
                around[c, u] = p
    near_start = np.zeros(n_cells + 1, dtype=np.int64)
    for c in range(n_cells):
        cnt = 0
        for u in range(step.size):
            cnt += around[c, u] >= 0
        near_start[c + 1] = near_start[c] + cnt
    near = np.empty(near_start[n_cells], dtype=np.int64)
    for c in range(n_cells):
        j = near_start[c]
        for u in range(step.size):
            if around[c, u] >= 0:
                near[j] = around[c, u]
                j += 1
    return cell_of, pt_start[:n_cells + 1].copy(), near_start, near


@jit
def _bucket(cell, items, n_cells):
    start = np.zeros(n_cells + 1, dtype=np.int64)
    for i in range(cell.size):
        start[cell[i] + 1] += 1
    for c in range(n_cells):
        start[c + 1] += start[c]
    fill = start[:n_cells].copy()
    out = np.empty(items.size, dtype=np.int64)
    for i in range(cell.size):
        out[fill[cell[i]]] = items[i]
        fill[cell[i]] += 1
    return start, out


def bucket(cell, items, n_cells):
    """CSR of ``items`` by ``cell`` (counting sort, stable): ``(start, items in cell order)``."""
    return _bucket(np.ascontiguousarray(cell, dtype=np.int64),
                   np.ascontiguousarray(items, dtype=np.int64), n_cells)


@jit_leaf
def sq_dist(xyz, i, q):
    """Squared distance from row ``i`` of ``xyz`` to ``q``, rounded as cKDTree rounds it."""
    d0 = xyz[i, 0] - q[0]
    d1 = xyz[i, 1] - q[1]
    d2 = xyz[i, 2] - q[2]
    return d0 * d0 + d1 * d1 + d2 * d2


@jit_leaf
def _gather(cell, near_start, near, start, slot, xyz, buf_xyz, buf_id):
    """Copy the members of the cells around ``cell`` into ``buf_xyz`` / ``buf_id`` (room
    enough: :func:`_most_around`); returns the count."""
    cnt = 0
    for u in range(near_start[cell], near_start[cell + 1]):
        v = near[u]
        for i in range(start[v], start[v + 1]):
            buf_xyz[cnt, 0] = xyz[i, 0]
            buf_xyz[cnt, 1] = xyz[i, 1]
            buf_xyz[cnt, 2] = xyz[i, 2]
            buf_id[cnt] = slot[i]
            cnt += 1
    return cnt


@jit_leaf
def _most_around(q_cell, near_start, near, start):
    """The most members the cells around any of ``q_cell`` hold together."""
    most = 0
    for t in range(q_cell.size):
        if t > 0 and q_cell[t] == q_cell[t - 1]:
            continue
        cell = q_cell[t]
        cnt = 0
        for u in range(near_start[cell], near_start[cell + 1]):
            cnt += start[near[u] + 1] - start[near[u]]
        most = max(most, cnt)
    return most


@jit_leaf
def _before(s, c, s2, c2, tie):
    """Whether member ``c`` at squared distance ``s`` comes before ``c2`` at ``s2``: nearer,
    or as near with the smaller ``tie``, or the same tie too and the smaller position."""
    if s != s2:
        return s < s2
    if tie[c] != tie[c2]:
        return tie[c] < tie[c2]
    return c < c2


@jit
def nearest(Q, q_cell, near_start, near, start, slot, xyz, reach2, k, bound, tie):
    """Nearest members of each query point ``Q`` (q, 3): the nearest, and the ``k`` nearest
    closer than ``bound``, nearest first — in the exact order of (squared distance, ``tie``,
    position), ``tie`` (uint64, indexed like ``slot``'s values: one per candidate) breaking
    equal distances.

    ``q_cell``: the cell of each query point; queries in the same cell one after another
    (e.g. in the order of :attr:`CellGrid.pt`) share one gathering of the members around it,
    and reading and writing in that order is cache-friendly. ``start`` / ``slot`` / ``xyz``:
    the members sorted into the cells (:meth:`CellGrid.members`); ``reach2``: the squared
    reach of the cells.

    Returns
    -------
    d1, i1, amb1 : (q,)
        Distance to and position of the nearest member; ``amb1``: none lies surely within
        ``reach`` (a nearer one may be unseen; then undefined).
    start, idx, dist : CSR
        The lists (``idx[start[t]:start[t + 1]]``; at most ``k``, fewer where fewer lie
        within ``bound``).
    amb : (q,)
        ``bound`` is not below ``reach`` (the cells may not hold every member within it); the
        lists are then left empty.

    Notes
    -----
    Each member seen costs one distance and, if closer than ``bound``, an insertion into a
    sorted list of ``k``. Distances are computed as cKDTree computes them, so a kd-tree
    agrees wherever no two distances tie.
    """
    nq = Q.shape[0]
    b2 = bound * bound  # as cKDTree squares its bound
    d1 = np.full(nq, np.inf)
    i1 = np.full(nq, -1, dtype=np.int64)
    amb1 = np.zeros(nq, dtype=np.bool_)
    l_start = np.zeros(nq + 1, dtype=np.int64)
    l_idx = np.empty(nq * k, dtype=np.int64)  # pages only touched as used: ~3 per query
    l_dist = np.empty(nq * k)
    amb = np.zeros(nq, dtype=np.bool_)
    all_amb = not b2 < reach2
    # buffers made once, large enough for every query (an array replaced inside the loop
    # would be counted, atomically, at each use)
    most = max(_most_around(q_cell, near_start, near, start), 1)
    buf_xyz = np.empty((most, 3))
    buf_id = np.empty(most, dtype=np.int64)
    sq = np.empty(most)
    near_ones = np.empty(most, dtype=np.int64)
    cnt = 0
    bs = np.empty(max(k, 1))
    bi = np.empty(max(k, 1), dtype=np.int64)
    for t in range(nq):
        if t == 0 or q_cell[t] != q_cell[t - 1]:
            cnt = _gather(q_cell[t], near_start, near, start, slot, xyz, buf_xyz, buf_id)
        q0, q1, q2 = Q[t, 0], Q[t, 1], Q[t, 2]
        m = 0
        for i in range(cnt):  # branch-free: every distance, and which are within the bound
            e0 = buf_xyz[i, 0] - q0  # as sq_dist rounds it
            e1 = buf_xyz[i, 1] - q1
            e2 = buf_xyz[i, 2] - q2
            s = e0 * e0 + e1 * e1 + e2 * e2
            sq[i] = s
            near_ones[m] = i
            m += s < b2
        nb = 0
        for u in range(m):  # the k nearest of those, sorted
            i = near_ones[u]
            s = sq[i]
            c = buf_id[i]
            if nb == k and (k == 0 or not _before(s, c, bs[k - 1], bi[k - 1], tie)):
                continue  # full (k = 0: no lists, the nearest only)
            j = nb if nb < k else k - 1
            while j > 0 and _before(s, c, bs[j - 1], bi[j - 1], tie):
                bs[j] = bs[j - 1]
                bi[j] = bi[j - 1]
                j -= 1
            bs[j] = s
            bi[j] = c
            if nb < k:
                nb += 1
        if nb >= 1:
            s1 = bs[0]
            c1 = bi[0]
        else:  # the nearest among all seen
            s1 = np.inf
            c1 = -1
            for i in range(cnt):
                if c1 < 0 or _before(sq[i], buf_id[i], s1, c1, tie):
                    s1 = sq[i]
                    c1 = buf_id[i]
        if c1 < 0 or not s1 < reach2:
            amb1[t] = True  # a nearer member may lie beyond the cells around
        else:
            d1[t] = np.sqrt(s1)
            i1[t] = c1
        used = l_start[t]
        if all_amb:
            amb[t] = True
            nb = 0
        for j in range(nb):
            l_dist[used + j] = np.sqrt(bs[j])
            l_idx[used + j] = bi[j]
        l_start[t + 1] = used + nb
    return d1, i1, amb1, l_start, l_idx, l_dist, amb


def _flat(balls):
    """Query and member arrays of a ``query_ball_point`` answer (a list per query)."""
    sizes = np.fromiter((len(b) for b in balls), dtype=np.int64, count=len(balls))
    q = np.repeat(np.arange(len(balls), dtype=np.int64), sizes)
    c = (np.concatenate([np.asarray(b, dtype=np.int64) for b in balls]) if sizes.sum()
         else np.empty(0, dtype=np.int64))
    return q, c


def _sq(Q, C, q, c):
    """Squared distances of the pairs ``(q, c)``, rounded as :func:`sq_dist` rounds them."""
    d = C[c] - Q[q]
    return d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]


def _first(tie, q, c, s, nq):
    """Per query, the pair first in :func:`nearest`'s order: ``(d1, i1)``."""
    d1 = np.full(nq, np.inf)
    i1 = np.full(nq, -1, dtype=np.int64)
    np.minimum.at(d1, q, s)
    at = s == d1[q]
    q, c = q[at], c[at]
    o = np.lexsort((c, tie[c], q))
    q, c = q[o], c[o]
    lead = np.r_[True, q[1:] != q[:-1]]
    i1[q[lead]] = c[lead]
    return np.sqrt(d1), i1


def _lists(tie, q, c, s, nq, k, b2):
    """Per query, the ``k`` pairs first in :func:`nearest`'s order with ``s < b2``, as CSR."""
    inside = s < b2
    q, c, s = q[inside], c[inside], s[inside]
    o = np.lexsort((c, tie[c], s, q))
    q, c, s = q[o], c[o], s[o]
    rank = np.arange(q.size) - np.searchsorted(q, q)  # position within its query's list
    take = rank < k
    q, c, s = q[take], c[take], s[take]
    l_start = np.zeros(nq + 1, dtype=np.int64)
    l_start[1:] = np.cumsum(np.bincount(q, minlength=nq))
    return l_start, c, np.sqrt(s)


#: :func:`exact_search` measures every pair itself up to this many (query, candidate) pairs
BRUTE_PAIRS = 1 << 21
#: ... and in compiled code, whatever the candidates, up to this many queries
FEW_QUERIES = 256


@jit
def _few_queries(Q, C, tie, k, b2):
    """:func:`exact_search` for a few queries: every candidate measured (:func:`sq_dist`) and
    kept in :func:`nearest`'s order — the nearest, and the ``k`` first closer than ``b2``
    (squared) as CSR ``(start, idx, dist)``. The usual case: a tile's few watched halo points
    farther than the cells reach from every candidate, asked again each refinement round
    (40 queries among 62k candidates on a 297k-point tile: a kd-tree over the candidates took
    16 ms a round, as long as the whole cell search)."""
    nq = Q.shape[0]
    m = C.shape[0]
    best = np.full(nq, np.inf)
    i1 = np.full(nq, -1, dtype=np.int64)
    cnt = np.zeros(nq, dtype=np.int64)
    l_idx = np.empty((nq, max(k, 1)), dtype=np.int64)
    l_sq = np.empty((nq, max(k, 1)))
    for c in range(m):  # candidates outside, queries inside: the candidates are read once
        cx, cy, cz = C[c, 0], C[c, 1], C[c, 2]
        for t in range(nq):
            d0 = cx - Q[t, 0]
            e1 = cy - Q[t, 1]
            e2 = cz - Q[t, 2]
            s = d0 * d0 + e1 * e1 + e2 * e2  # as sq_dist rounds it
            if s <= best[t] and (i1[t] < 0 or _before(s, c, best[t], i1[t], tie)):
                best[t] = s
                i1[t] = c
            if s < b2 and k > 0:
                n = cnt[t]
                if n < k or _before(s, c, l_sq[t, n - 1], l_idx[t, n - 1], tie):
                    j = n if n < k else k - 1  # the slot that opens; the last one drops out
                    if n < k:
                        cnt[t] = n + 1
                    while j > 0 and _before(s, c, l_sq[t, j - 1], l_idx[t, j - 1], tie):
                        l_sq[t, j] = l_sq[t, j - 1]
                        l_idx[t, j] = l_idx[t, j - 1]
                        j -= 1
                    l_sq[t, j] = s
                    l_idx[t, j] = c
    d1 = np.sqrt(best)
    start = np.zeros(nq + 1, dtype=np.int64)
    for t in range(nq):
        start[t + 1] = start[t] + cnt[t]
    idx = np.empty(start[nq], dtype=np.int64)
    dist = np.empty(start[nq])
    for t in range(nq):
        for j in range(cnt[t]):
            idx[start[t] + j] = l_idx[t, j]
            dist[start[t] + j] = np.sqrt(l_sq[t, j])
    return d1, i1, start, idx, dist


def exact_search(C, tie, Q, k, bound):
    """:func:`nearest`'s answers for queries the cells cannot settle: ``(d1, i1, start, idx,
    dist)``, ``i1`` -1 where ``C`` is empty.

    Few queries (at most :data:`FEW_QUERIES`; the usual case, a few watched points far from
    every candidate) measure every candidate in compiled code (:func:`_few_queries`), as do
    queries of at most ``BRUTE_PAIRS`` pairs in all (in numpy). Else a kd-tree finds the
    nearest distance ``d`` of each query (to within rounding); every candidate within ``d (1 + 1e-6)``, and within
    ``bound (1 + 1e-6)`` for the lists, is then measured exactly. Either way they are ordered
    as :func:`nearest` orders them.
    """
    from scipy.spatial import cKDTree
    nq, m = Q.shape[0], C.shape[0]
    if m == 0 or nq == 0:
        return (np.full(nq, np.inf), np.full(nq, -1, dtype=np.int64),
                np.zeros(nq + 1, dtype=np.int64), np.empty(0, dtype=np.int64), np.empty(0))
    b2 = bound * bound
    if nq <= FEW_QUERIES:
        return _few_queries(np.ascontiguousarray(Q, dtype=np.float64),
                            np.ascontiguousarray(C, dtype=np.float64),
                            np.ascontiguousarray(tie, dtype=np.uint64), int(k), float(b2))
    if nq * m <= BRUTE_PAIRS:
        S = np.zeros((nq, m))
        for d in range(3):
            e = C[None, :, d] - Q[:, d, None]
            S += e * e  # ((e0² + e1²) + e2²), as sq_dist adds them
        q, c = np.nonzero(S == S.min(axis=1)[:, None])  # the nearest and its ties
        d1, i1 = _first(tie, q, c, S[q, c], nq)
        q, c = np.nonzero(S < b2)
        return (d1, i1) + _lists(tie, q, c, S[q, c], nq, k, b2)
    tree = cKDTree(C)
    dk, _ = tree.query(Q)
    q, c = _flat(tree.query_ball_point(Q, dk * (1.0 + 1e-6) + 1e-300))
    d1, i1 = _first(tie, q, c, _sq(Q, C, q, c), nq)
    if not b2 > 0:
        return d1, i1, np.zeros(nq + 1, dtype=np.int64), np.empty(0, dtype=np.int64), \
            np.empty(0)
    q, c = _flat(tree.query_ball_point(Q, bound * (1.0 + 1e-6)))
    return (d1, i1) + _lists(tie, q, c, _sq(Q, C, q, c), nq, k, b2)


@jit
def _nearest_other(pt, cell_of, near_start, near, pt_start, pt_xyz, reach2, out):
    """``out[i]``: the squared distance from point ``i`` to the nearest other point in the
    cells around its own, or ``inf`` where that is beyond ``reach2`` (a nearer point may lie
    outside them). Points are visited cell by cell."""
    for t in range(pt.size):
        i = pt[t]
        c = cell_of[i]
        q = pt_xyz[t]
        best = np.inf
        for u in range(near_start[c], near_start[c + 1]):
            v = near[u]
            for j in range(pt_start[v], pt_start[v + 1]):
                if j != t:
                    best = min(best, sq_dist(pt_xyz, j, q))
        out[i] = best if best <= reach2 else np.inf


#: :func:`nearest_other` leaves cells for the kd-tree when a search would visit more points
#: than this on average (35-45 on the quality clouds and the 1M scan; a random sample that
#: misses a dense clump guesses cells far too large for it: 2,025 on a cloud with a tenth of
#: its points in a clump, 1.24 s against the kd-tree's 0.24 s at 200k points)
NEAREST_MAX_LOAD = 300.0


def nearest_other(X, sample=4096, seed=0, factor=4.0):
    """Each point's distance to the nearest other point of ``X`` (distinct points), exactly as
    ``cKDTree(X).query(X, k=2)[0][:, 1]`` gives it, bit for bit.

    On a grid of cells ``factor`` times the spacing guessed from a random ``sample`` (its
    own nearest distances times ``sqrt(sample / n)``, as on a surface), with a kd-tree only
    for the points whose nearest lies beyond the cells around them (the kd-tree alone where
    cells would hold too many points: :data:`NEAREST_MAX_LOAD`). On the 1M-point scan of
    ``benchmarks/speed.py`` 0.40 s (no such point) against the kd-tree's 0.9 s (its query
    0.7-0.8 s); at twice the guess 0.75 s, 4 % of the points beyond their cells.
    """
    from scipy.spatial import cKDTree
    X = np.ascontiguousarray(X, dtype=np.float64)
    n = X.shape[0]
    out = np.full(n, np.inf)
    if n < 2:
        return out
    grid = CellGrid(X, factor * _spacing_guess(X, sample, seed))
    probe = np.arange(0, n, max(1, n // int(sample)))  # strided, not the guess's sample
    if grid.load(None, probe) > NEAREST_MAX_LOAD:
        return cKDTree(X).query(X, k=2)[0][:, 1]
    _nearest_other(grid.pt, grid.cell_of, grid.near_start, grid.near, grid.pt_start,
                   grid.pt_xyz, grid.reach * grid.reach, out)
    miss = np.flatnonzero(np.isinf(out))
    out = np.sqrt(out)
    if miss.size:
        out[miss] = cKDTree(X).query(X[miss], k=2)[0][:, 1]
    return out


def _spacing_guess(P, sample, seed):
    """The median distance between nearest points of ``P`` (n ≥ 2), guessed from a random
    ``sample``: its own nearest distances times ``sqrt(sample / n)``, as on a surface."""
    from scipy.spatial import cKDTree
    n = P.shape[0]
    m = min(n, int(sample))
    S = P[np.random.default_rng(seed).choice(n, m, replace=False)] if m < n else P
    return float(np.median(cKDTree(S).query(S, k=2)[0][:, 1])) * np.sqrt(m / n)


#: :func:`distances_to` asks the kd-tree alone below this many members
FEW_MEMBERS = 64


def distances_to(X, members, queries, sample=4096, seed=0, factor=3.0):
    """The distance from each of ``queries`` (point ids) to the nearest of ``members`` (point
    ids, not empty), exactly as ``cKDTree(X[members]).query(X[queries])[0]`` gives it, bit
    for bit.

    On a grid of cells ``factor`` times the members' spacing (guessed as
    :func:`nearest_other` guesses a cloud's), with the kd-tree only for the queries whose
    nearest member lies beyond the cells around them (the kd-tree alone where the cells would
    hold too many members: :data:`NEAREST_MAX_LOAD`). The gap refinement's first distances
    (:func:`.refine.refine_coverage`): a 140k-point tile of the 1M scan at 20 % kept 28-30 ms
    against the kd-tree's 58, at 2 % 27 against 40 (2026-12-05).
    """
    from scipy.spatial import cKDTree
    X = np.ascontiguousarray(X, dtype=np.float64)
    members = np.asarray(members, dtype=np.int64)
    queries = np.asarray(queries, dtype=np.int64)
    if members.size < FEW_MEMBERS or queries.size < FEW_MEMBERS:
        return cKDTree(X[members]).query(X[queries])[0]
    grid = CellGrid(X, factor * _spacing_guess(X[members], sample, seed))
    at = np.zeros(X.shape[0], dtype=bool)
    at[queries] = True
    q = grid.pt[at[grid.pt]]  # the queries cell by cell
    if grid.load(members, q[::max(1, q.size // int(sample))]) > NEAREST_MAX_LOAD:
        return cKDTree(X[members]).query(X[queries])[0]
    start, slot, xyz = grid.members(X, members)
    d1, _, amb1, _, _, _, _ = nearest(X[q], grid.cell_of[q], grid.near_start, grid.near,
                                      start, slot, xyz, grid.reach * grid.reach, 0, 0.0,
                                      np.zeros(members.size, dtype=np.uint64))
    miss = np.flatnonzero(amb1)
    if miss.size:
        d1[miss] = cKDTree(X[members]).query(X[q[miss]])[0]
    out = np.empty(X.shape[0])
    out[q] = d1
    return out[queries]
