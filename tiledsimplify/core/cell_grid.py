"""Exact nearest searches among a changing subset of points, on a grid of cubic cells.

The gap refinement (:mod:`.refine`) asks, round after round, which *candidates* (a subset of
the input points that changes every round) lie nearest each input point, within a radius that
never grows. A kd-tree over each round's candidates answers that, but costs a build and a full
query per round. Here a grid of cubic cells of side ``h`` (at least every radius asked) is
built once over the input points; each round the candidates are sorted into its cells (a
counting sort) and a search visits the (non-empty) cells among the 27 around a point's cell.

**Same answers as** ``scipy.spatial.cKDTree`` **on the same candidates.** Distances are
computed as cKDTree computes them (``((dx² + dy²) + dz²)``, then the square root), bit for bit,
so every distance and every comparison with a bound is the same (a test checks it against the
installed scipy). cKDTree orders equal distances by the layout of its tree, and rounding in
its cell bounds could decide between two distances a few ulps apart, so a search whose answer
depends on the order of two distances within a relative ``TOL`` of each other (or of a bound)
is flagged *ambiguous*: the caller asks the kd-tree for those points only (on quantised LiDAR
scans, ~1 % of them).
"""

import numpy as np

from ._jit import jit, jit_inline

#: relative margin under which two squared distances (or one and a bound) count as tied
TOL = 1e-9
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
        lo = X.min(axis=0)
        span = float((X.max(axis=0) - lo).max())
        self.h = h = max(float(h), span / MAX_CELLS, np.finfo(float).tiny)
        self.reach = (1.0 - COVER) * h
        key, step = _cell_keys(X, lo, h)
        self.pt = np.argsort(key, kind="stable")
        self.cell_of, self.pt_start, self.near_start, self.near = _cells(key, self.pt, step)
        self.n_cells = self.pt_start.size - 1
        self.pt_xyz = np.ascontiguousarray(X[self.pt])

    def load(self, members, queries):
        """How many of ``members`` a search from each of ``queries`` visits, on average."""
        if not queries.size:
            return 0.0
        cnt = np.bincount(self.cell_of[members], minlength=self.n_cells)
        around = np.add.reduceat(cnt[self.near], self.near_start[:-1])
        return float(around[self.cell_of[queries]].mean())

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


@jit_inline
def sq_dist(xyz, i, q):
    """Squared distance from row ``i`` of ``xyz`` to ``q``, rounded as cKDTree rounds it."""
    d0 = xyz[i, 0] - q[0]
    d1 = xyz[i, 1] - q[1]
    d2 = xyz[i, 2] - q[2]
    return d0 * d0 + d1 * d1 + d2 * d2


@jit
def _gather(cell, near_start, near, start, slot, xyz, buf_xyz, buf_id):
    """Copy the members of the cells around ``cell`` into ``buf_xyz`` / ``buf_id`` (grown if
    too small); returns the buffers and the count."""
    cnt = 0
    for u in range(near_start[cell], near_start[cell + 1]):
        cnt += start[near[u] + 1] - start[near[u]]
    if cnt > buf_id.size:
        buf_xyz = np.empty((2 * cnt, 3))
        buf_id = np.empty(2 * cnt, dtype=np.int64)
    cnt = 0
    for u in range(near_start[cell], near_start[cell + 1]):
        v = near[u]
        for i in range(start[v], start[v + 1]):
            buf_xyz[cnt, 0] = xyz[i, 0]
            buf_xyz[cnt, 1] = xyz[i, 1]
            buf_xyz[cnt, 2] = xyz[i, 2]
            buf_id[cnt] = slot[i]
            cnt += 1
    return buf_xyz, buf_id, cnt


@jit
def nearest(Q, q_cell, near_start, near, start, slot, xyz, reach2, k, bound):
    """Nearest members of each query point ``Q`` (q, 3), as cKDTree gives them: the nearest
    (``query(k=1)``) and the ``k`` nearest closer than ``bound``, nearest first
    (``query(k=k, distance_upper_bound=bound)``).

    ``q_cell``: the cell of each query point; queries in the same cell one after another
    (e.g. in the order of :attr:`CellGrid.pt`) share one gathering of the members around it,
    and reading and writing in that order is cache-friendly. ``start`` / ``slot`` / ``xyz``:
    the members sorted into the cells (:meth:`CellGrid.members`); ``reach2``: the squared
    reach of the cells.

    Returns
    -------
    d1, i1, amb1 : (q,)
        Distance to and id of the nearest member; ``amb1``: it is not surely nearer than
        ``reach`` (not surely seen) or not clearly nearer than the next (then undefined).
    start, idx, dist : CSR
        The lists (``idx[start[t]:start[t + 1]]``; at most ``k``, fewer where fewer lie
        within ``bound``).
    amb : (q,)
        The list depends on the order of two squared distances within ``TOL`` of each other
        (among the listed ones and the next), a listed one lies within ``TOL`` of
        ``bound²``, or ``bound`` is not surely below ``reach``; then it is left empty.

    Notes
    -----
    Each member seen costs one distance and, if closer than ``bound``, an insertion into a
    sorted list of ``k + 1``.
    """
    nq = Q.shape[0]
    b2 = bound * bound  # as cKDTree squares its bound
    keep2 = b2 * (1.0 + TOL)  # also collect the ones just beyond: they decide ambiguity
    d1 = np.full(nq, np.inf)
    i1 = np.full(nq, -1, dtype=np.int64)
    amb1 = np.zeros(nq, dtype=np.bool_)
    l_start = np.zeros(nq + 1, dtype=np.int64)
    l_idx = np.empty(nq * k, dtype=np.int64)  # pages only touched as used: ~3 per query
    l_dist = np.empty(nq * k)
    amb = np.zeros(nq, dtype=np.bool_)
    all_amb = not keep2 * (1.0 + TOL) < reach2
    buf_xyz = np.empty((64, 3))
    buf_id = np.empty(64, dtype=np.int64)
    sq = np.empty(64)
    near_ones = np.empty(64, dtype=np.int64)
    cnt = 0
    bs = np.empty(k + 1)
    bi = np.empty(k + 1, dtype=np.int64)
    for t in range(nq):
        if t == 0 or q_cell[t] != q_cell[t - 1]:
            buf_xyz, buf_id, cnt = _gather(q_cell[t], near_start, near, start, slot, xyz,
                                           buf_xyz, buf_id)
            if sq.size < buf_id.size:
                sq = np.empty(buf_id.size)
                near_ones = np.empty(buf_id.size, dtype=np.int64)
        q = Q[t]
        m = 0
        for i in range(cnt):  # branch-free: every distance, and which are within keep2
            s = sq_dist(buf_xyz, i, q)
            sq[i] = s
            near_ones[m] = i
            m += s < keep2
        nb = 0
        for u in range(m):  # the k + 1 nearest of those, sorted
            i = near_ones[u]
            s = sq[i]
            if nb == k + 1 and s >= bs[k]:
                continue
            j = nb if nb < k + 1 else k
            while j > 0 and bs[j - 1] > s:
                bs[j] = bs[j - 1]
                bi[j] = bi[j - 1]
                j -= 1
            bs[j] = s
            bi[j] = buf_id[i]
            if nb < k + 1:
                nb += 1
        if nb >= 2:
            s1 = bs[0]
            s2 = bs[1]
            c1 = bi[0]
        else:  # the nearest two among all seen
            s1 = np.inf
            a = -1
            for i in range(cnt):
                if sq[i] < s1:
                    s1 = sq[i]
                    a = i
            s2 = np.inf
            for i in range(cnt):
                if i != a and sq[i] < s2:
                    s2 = sq[i]
            c1 = buf_id[a] if a >= 0 else -1
        if s2 > reach2:
            s2 = reach2  # a member beyond reach may be unseen
        if c1 < 0 or not s2 > s1 * (1.0 + TOL):
            amb1[t] = True
        else:
            d1[t] = np.sqrt(s1)
            i1[t] = c1
        n_in = 0
        while n_in < nb and n_in < k and bs[n_in] < b2:
            n_in += 1
        bad = all_amb or (n_in > 0 and not bs[n_in - 1] < b2 * (1.0 - TOL))  # the bound
        last = n_in if n_in < nb else n_in - 1  # the listed ones and the next, if any
        for j in range(last):
            if not bs[j + 1] > bs[j] * (1.0 + TOL):
                bad = True  # two (nearly) equal: the kd-tree's order is its own
        used = l_start[t]
        if bad:
            amb[t] = True
            n_in = 0
        for j in range(n_in):
            l_dist[used + j] = np.sqrt(bs[j])
            l_idx[used + j] = bi[j]
        l_start[t + 1] = used + n_in
    return d1, i1, amb1, l_start, l_idx, l_dist, amb
