"""Growable per-point neighbour lists in one flat pool, usable inside numba kernels.

The Voronoi neighbourhoods change under removal (a removed point's neighbours gain each other,
paper §3.3), so each point owns a block ``pool[start[i] : start[i] + cap[i]]`` of which the first
``cnt[i]`` entries are used. A full block moves to the end of the pool with twice the capacity;
a full pool doubles (:func:`with_room`, called between kernel loops, so that no loop replaces
the pool). :func:`remove` keeps the order of the others and :func:`append_in_place` adds at
the end; the order means nothing to the results, but :func:`.local_mesh.local_mesh` sorts a list
nearest first in place, so lists stay (almost) sorted and its sort has little left to do.
"""

import numpy as np

from ._jit import jit, jit_leaf


@jit
def _fill_sorted(n, edges, slack, room):
    """:func:`from_edges` for edges ``(i, j)``, ``i < j``, sorted by ``(i, j)``, in linear time.

    Row ``i`` then lists the ``j < i`` (first ends of edges ``(j, i)``, met in increasing
    order) followed by the ``j > i`` (edges ``(i, j)``, already sorted): sorted, like the
    general path's lexsort.
    """
    cnt = np.zeros(n, dtype=np.int64)
    for e in range(edges.shape[0]):
        cnt[edges[e, 0]] += 1
        cnt[edges[e, 1]] += 1
    start = np.zeros(n, dtype=np.int64)
    for i in range(1, n):
        start[i] = start[i - 1] + cnt[i - 1] + slack
    used = 0
    for i in range(n):
        used += cnt[i] + slack
    pool = np.full(max(room * used, 16), -1, dtype=np.int32)
    fill = start.copy()
    for e in range(edges.shape[0]):  # smaller neighbours first, in increasing order
        j = edges[e, 1]
        pool[fill[j]] = edges[e, 0]
        fill[j] += 1
    for e in range(edges.shape[0]):
        i = edges[e, 0]
        pool[fill[i]] = edges[e, 1]
        fill[i] += 1
    return start, cnt, cnt + slack, pool, np.array([used], dtype=np.int64)


@jit
def _is_sorted_upper(edges):
    for e in range(edges.shape[0]):
        if edges[e, 0] >= edges[e, 1]:
            return False
        if e > 0 and (edges[e - 1, 0] > edges[e, 0]
                      or (edges[e - 1, 0] == edges[e, 0] and edges[e - 1, 1] >= edges[e, 1])):
            return False
    return True


def from_edges(n, edges, slack=8, room=2):
    """Build ``(start, cnt, cap, pool)`` from undirected ``edges`` (k, 2) on ``n`` points.

    The pool holds ``room`` times the slots the lists take (with their ``slack``): 2 leaves
    as much again for lists that outgrow their capacity (:func:`append_in_place`); 1 for lists that
    are only read (the Voronoi candidates: 44 MB less at 1M points)."""
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if n > 0 and edges.shape[0] and _is_sorted_upper(np.ascontiguousarray(edges)):
        # the Voronoi construction's edges come sorted, each with i < j: no sort needed
        return _fill_sorted(n, np.ascontiguousarray(edges), slack, room)
    src = np.concatenate([edges[:, 0], edges[:, 1]])
    dst = np.concatenate([edges[:, 1], edges[:, 0]])
    order = np.lexsort((dst, src))
    src, dst = src[order], dst[order]
    cnt = np.bincount(src, minlength=n).astype(np.int64)
    cap = cnt + slack
    start = np.zeros(n, dtype=np.int64)
    np.cumsum(cap[:-1], out=start[1:])
    used = int(cap.sum())
    pool = np.full(max(room * used, 16), -1, dtype=np.int32)
    first = np.zeros(n, dtype=np.int64)
    np.cumsum(cnt[:-1], out=first[1:])
    rank_in_src = np.arange(src.size) - first[src]
    pool[start[src] + rank_in_src] = dst
    meta = np.array([used], dtype=np.int64)
    return start, cnt, cap, pool, meta


def from_lists(cnt, flat, slack=8):
    """Build ``(start, cnt, cap, pool, meta)`` from the lists laid end to end: point ``i``'s
    neighbours are the next ``cnt[i]`` entries of ``flat``, in that order. The layout is the
    one :func:`from_edges` makes (same capacities and pool size), so lists saved as
    ``(cnt, flat)`` come back exactly as they were built."""
    cnt = np.asarray(cnt, dtype=np.int64)
    n = cnt.size
    cap = cnt + slack
    start = np.zeros(n, dtype=np.int64)
    np.cumsum(cap[:-1], out=start[1:])
    used = int(cap.sum())
    pool = np.full(max(2 * used, 16), -1, dtype=np.int32)
    pool[_flat_slots(start, cnt)] = flat
    meta = np.array([used], dtype=np.int64)
    return start, cnt, cap, pool, meta


def to_flat(start, cnt, pool):
    """The lists laid end to end (the inverse of :func:`from_lists`), as int32."""
    return pool[_flat_slots(start, cnt)].astype(np.int32)


def _flat_slots(start, cnt):
    """Pool slot of every list entry, the lists laid end to end."""
    first = np.zeros(cnt.size, dtype=np.int64)
    np.cumsum(cnt[:-1], out=first[1:])
    return np.repeat(start - first, cnt) + np.arange(int(cnt.sum()))


def to_sets(start, cnt, pool, alive=None):
    """Neighbour lists as a list of Python sets (for tests and debugging)."""
    n = start.size
    out = []
    for i in range(n):
        if alive is not None and not alive[i]:
            out.append(set())
            continue
        out.append(set(int(j) for j in pool[start[i]:start[i] + cnt[i]]))
    return out


@jit
def grow(mask, start, cnt, pool):
    """``mask`` grown by one step of the lists: true at every point that is in ``mask`` or
    lists a point that is (a new array)."""
    out = mask.copy()
    for i in range(mask.size):
        if out[i]:
            continue
        s = start[i]
        for j in range(cnt[i]):
            if mask[pool[s + j]]:
                out[i] = True
                break
    return out


@jit_leaf
def contains(start, cnt, pool, i, j):
    """True if ``j`` is in the list of ``i``."""
    s = start[i]
    for k in range(cnt[i]):
        if pool[s + k] == j:
            return True
    return False


@jit_leaf
def remove(start, cnt, pool, i, j):
    """Remove ``j`` from the list of ``i``, the later entries moving up one (the order stays).
    True if it was there."""
    s = start[i]
    c = cnt[i]
    for k in range(c):
        if pool[s + k] == j:
            for t in range(s + k, s + c - 1):
                pool[t] = pool[t + 1]
            cnt[i] = c - 1
            return True
    return False


@jit_leaf
def append_in_place(start, cnt, cap, pool, meta, i, j):
    """Append ``j`` to the list of ``i`` within the pool as it is (a full list moves to the
    end of the used part, at twice its capacity). False, and nothing changed, if the pool
    has no room for that: see :func:`with_room`."""
    c = cnt[i]
    if c == cap[i]:
        newcap = max(2 * cap[i], 8)
        used = meta[0]
        if used + newcap > pool.size:
            return False
        s_old = start[i]
        for k in range(c):
            pool[used + k] = pool[s_old + k]
        start[i] = used
        cap[i] = newcap
        meta[0] = used + newcap
    pool[start[i] + c] = j
    cnt[i] = c + 1
    return True


@jit
def with_room(pool, meta, room):
    """The pool, or a copy at least twice as large, with ``room`` free slots past its used
    part (``meta[0]``)."""
    used = meta[0]
    if used + room <= pool.size:
        return pool
    bigger = np.full(max(2 * pool.size, used + room), -1, dtype=pool.dtype)
    bigger[:used] = pool[:used]
    return bigger
