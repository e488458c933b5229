"""Progressive removal of the least important point, with exact local updates (paper §3.3).

Each step removes the point of smallest importance, then updates exactly what the removal
changes (Fig. 1):

1. the Voronoi neighbourhoods around it (:func:`.voronoi.remove_point`: the former neighbours
   of ``p`` may become neighbours of each other);
2. the local meshes ``DN_a`` and normals (unless ``update_normals`` is off, the default in mode
   "coverage") of those former neighbours ``a`` (the first ring) —
   ``DN_a ⊆ VN_a`` depends on nothing else — except boundary points: they are never removed
   and no importance reads their local mesh or normal (Eq. (1) skips boundary neighbours, the
   coverage term reads positions only), so theirs are left as they were (their Voronoi lists
   are kept exact like every other point's);
3. the importance of every point whose local mesh changed, and of every point with a neighbour
   whose normal changed (the second ring: points ``x`` with ``a ∈ DN_x``, found in ``VN_a``).

Boundary and frozen points are never removed but stay in every neighbourhood (the boundary
points here are those sure of being kept, at most ``options.edge_share`` of the count; the
other flagged points are removed like any other). A guard rule
(:data:`GUARDS`) may veto a removal; the vetoed point is then kept. The ``max_spacing`` guard
bounds the gaps (issue #5, "no holes": a maximum spacing in model units): every removed point
is covered by a remaining point within the limit, and a removal must hand the removed point
and everything it covers to covers within the limit (:func:`guard_allows`). The removal order
and the importance at removal are recorded for every step, so one run answers every coarser
count (and a tiled run can cut all tiles at one importance level).
"""

import math

import numpy as np

from . import adjacency, heap
from ._jit import jit, jit_leaf
from .importance import importance_of
from .local_mesh import MAX_DN, local_mesh, unchanged_without
from .normals import normal_at
from .voronoi import removal_room, remove_point


#: name -> code of the guard rules the removal loop knows
GUARDS = {"none": 0, "max_spacing": 1}


@jit_leaf
def _nearest_cover(X, x, p, start, cnt, pool, covers):
    """The point of ``VN_p`` nearest to ``x`` that may cover others (``covers``), and its
    squared distance (``-1``, ``inf`` if there is none)."""
    s = start[p]
    best = math.inf
    arg = -1
    for j in range(cnt[p]):
        q = pool[s + j]
        if not covers[q]:
            continue
        dx, dy, dz = X[q, 0] - X[x, 0], X[q, 1] - X[x, 1], X[q, 2] - X[x, 2]
        d = dx * dx + dy * dy + dz * dz
        if d < best:
            best = d
            arg = q
    return arg, best


@jit_leaf
def guard_allows(guard, value, X, p, start, cnt, pool, covers, owners):
    """May ``p`` be removed now?

    ``none`` (0): always. ``max_spacing`` (1): only if ``p`` and every removed point it
    covers can each be covered by a remaining Voronoi neighbour of ``p`` within ``value``
    (model units). ``owners`` holds the cover lists (:func:`pass_on_cover`): ``owners[0, q]``
    the first point ``q`` covers, ``owners[1, x]`` the next point after ``x`` in its cover's
    list (``-1``: none). Points not in ``covers`` (a tile's halo) neither cover nor need a
    cover. So every removed point of ``covers`` always lies within ``value`` of a remaining
    one: no input point is left farther than ``value`` from the kept points, at every count
    of the sequence. A veto is for good: removals only take covers away (the check looks
    among ``VN_p`` only, so it can be stricter than needed, never looser).
    """
    if guard == 0:
        return True
    limit = value * value  # inf past ~1.3e154: a point with no cover at all still stays
    if covers[p]:
        q, d = _nearest_cover(X, p, p, start, cnt, pool, covers)
        if q < 0 or d > limit:
            return False
    x = owners[0, p]
    while x >= 0:
        q, d = _nearest_cover(X, x, p, start, cnt, pool, covers)
        if q < 0 or d > limit:
            return False
        x = owners[1, x]
    return True


@jit_leaf
def pass_on_cover(X, p, start, cnt, pool, covers, owners):
    """Before ``p`` is removed (its Voronoi list still whole): hand ``p`` and the points it
    covers each to its nearest covering Voronoi neighbour of ``p`` (:func:`guard_allows` has
    checked that one lies within the limit). The nearest remaining point to anything in
    ``p``'s Voronoi cell is a Voronoi neighbour of ``p``; a point a cover holds from outside
    its cell only makes the next check stricter, never wrong — distances are checked, not
    assumed."""
    x = owners[0, p]
    owners[0, p] = -1
    while x >= 0:
        after = owners[1, x]
        q, _ = _nearest_cover(X, x, p, start, cnt, pool, covers)
        owners[1, x] = owners[0, q]
        owners[0, q] = x
        x = after
    if covers[p]:
        q, _ = _nearest_cover(X, p, p, start, cnt, pool, covers)
        owners[1, p] = owners[0, q]
        owners[0, q] = p


@jit
def remove_points(X, start, cnt, cap, pool, meta, dn, dn_cnt, plane_normals, normals, stable,
                  boundary, removable, importance, tie, code, weight, guard, guard_value, covers,
                  owners, cover_xyz, n_steps, half, tol, reach, update_normals=True,
                  stop_above=math.inf):
    """Remove up to ``n_steps`` points, least important first.

    Mutates the neighbour lists, local meshes, normals and importance in place (for the
    remaining points). ``stable`` holds each point's :func:`.local_mesh.local_mesh`
    ``stable[0]`` (kept up to date here): a former neighbour of the removed point whose local
    mesh provably stays as it is (:func:`.local_mesh.unchanged_without`) is not recomputed —
    24-33 % of them on scans, the Bunny and Autzen, for 6-8 % off the loop's time.
    ``removable`` marks the candidates (not boundary, not frozen, alive);
    ``half``, ``tol`` and ``reach`` are the Voronoi rule's (:func:`.voronoi.facet_positive`).
    ``update_normals`` False keeps every normal as it is (``SimplifyOptions.update_normals``):
    no normal changes, so no second-ring importance is recomputed.
    ``tie`` (uint64) breaks importance ties (see :mod:`.heap`); ``code`` and ``weight`` select the
    importance measure (:func:`.importance.importance_of`). ``guard`` / ``guard_value``
    select a guard rule (:data:`GUARDS`) that can veto a removal; a vetoed point is kept.
    ``covers`` (bool (n,)), ``owners`` (int64 (2, N), ``-1`` at the start, kept between calls)
    and ``cover_xyz`` ((N, 3): ``X`` and after it the points a pre-thinning took out, which
    ``owners`` may already hand to covers) are the ``max_spacing`` guard's: which points cover
    and need cover, who covers whom, and where they all are (:func:`guard_allows`).
    The loop also stops right after a removal whose importance exceeds ``stop_above``: the
    recorded sequence then holds every step whose running maximum of importance at removal is
    at most ``stop_above`` (the prefix does not depend on where the loop stops).

    Returns
    -------
    order : int64 (k,)
        Removed point ids, in removal order.
    at : float64 (k,)
        Importance of each at the moment of its removal.
    pool : the (possibly reallocated) neighbour pool.
    """
    n = X.shape[0]
    hp, pos = heap.new(n)
    items = np.nonzero(removable)[0]
    size = heap.build(hp, pos, importance, tie, items)
    n_steps = min(n_steps, size)
    order = np.empty(n_steps, dtype=np.int64)
    at = np.empty(n_steps)
    stamp = np.zeros(n, dtype=np.int64)
    mark = np.full(n, -1, dtype=np.int64)
    mesh_changed = np.zeros(n, dtype=np.bool_)
    normal_changed = np.zeros(n, dtype=np.bool_)
    buf = 64
    link = np.empty(buf, dtype=np.int64)
    cand = np.empty(buf, dtype=np.int64)
    bufs = np.empty((4, buf + 5))
    lbufs = np.empty((2, buf + 5), dtype=np.int64)
    frame = np.empty((3, 3))
    fbufs = np.empty((5, buf + 5))
    mbufs = np.empty((3, buf + 5), dtype=np.int64)
    newdn = np.empty(MAX_DN, dtype=np.int64)
    nvec = np.empty(3)
    wvec = np.empty(3)
    before = np.zeros(n, dtype=np.int64)  # list sizes before the current removal
    state = np.zeros(5, dtype=np.int64)
    state[SIZE] = size
    while True:
        status = _run(X, start, cnt, cap, pool, meta, dn, dn_cnt, plane_normals, normals, stable,
                      boundary, removable, importance, tie, code, weight, guard, guard_value,
                      covers, owners, cover_xyz, n_steps, half, tol, reach, update_normals,
                      stop_above, hp, pos, order, at, stamp, mark, mesh_changed, normal_changed,
                      before, link, cand, bufs, lbufs, frame, fbufs, mbufs, newdn, nvec, wvec,
                      state)
        if status == DONE:
            break
        if status == NO_ROOM:
            raise RuntimeError("remove_points: the neighbour pool ran out of room that "
                               "removal_room promised (a bug)")
        k = state[NEED_LINK]  # room for the next removal: grow what is short, then go on
        if k > link.size:  # link, cand (L) and the clipping scratch (L + 5) grow together
            link = np.empty(2 * k, dtype=np.int64)
            cand = np.empty(2 * k, dtype=np.int64)
            bufs = np.empty((4, 2 * k + 5))
            lbufs = np.empty((2, 2 * k + 5), dtype=np.int64)
        m = state[NEED_MESH]
        if m + 5 > fbufs.shape[1]:
            fbufs = np.empty((5, 2 * m + 10))
            mbufs = np.empty((3, 2 * m + 10), dtype=np.int64)
        pool = adjacency.with_room(pool, meta, state[NEED_POOL])
    step = state[STEP]
    return order[:step], at[:step], pool


#: :func:`_run`'s statuses: done; stopped before a removal that needs more room; the pool
#: had less room than :func:`.voronoi.removal_room` said (a bug: the lists are half updated)
DONE, GROW, NO_ROOM = 0, 1, 2
#: slots of :func:`_run`'s ``state``: steps done, heap size, and the room the next removal
#: needs: its Voronoi degree, the largest degree its former neighbours can reach, pool slots
STEP, SIZE, NEED_LINK, NEED_MESH, NEED_POOL = range(5)


@jit_leaf
def _run(X, start, cnt, cap, pool, meta, dn, dn_cnt, plane_normals, normals, stable, boundary,
         removable, importance, tie, code, weight, guard, guard_value, covers, owners, cover_xyz,
         n_steps, half, tol, reach, update_normals, stop_above, hp, pos, order, at, stamp, mark,
         mesh_changed, normal_changed, before, link, cand, bufs, lbufs, frame, fbufs, mbufs, newdn,
         nvec, wvec, state):
    """The removal loop of :func:`remove_points`, from step ``state[STEP]``.

    It replaces no array: before each removal it checks that the scratch buffers and the pool
    have room for it and, if not, returns :data:`GROW` with the room needed in ``state``
    before anything changes; the caller grows them and calls again. (Arrays replaced inside
    the loop were counted with an atomic increment and decrement at every use.)
    """
    step = state[STEP]
    size = state[SIZE]
    plane = frame[:2]
    while step < n_steps and size > 0:
        # -- room for the next removal, checked before anything changes
        p = heap.top(hp)
        k = cnt[p]
        s = start[p]
        most = 0
        for j in range(k):
            most = max(most, cnt[pool[s + j]] + k)  # at most k - 2 new entries each
        room = removal_room(start, cnt, pool, p)
        if k > link.size or most + 5 > fbufs.shape[1] or meta[0] + room > pool.size:
            state[STEP] = step
            state[SIZE] = size
            state[NEED_LINK] = k
            state[NEED_MESH] = most
            state[NEED_POOL] = room
            return GROW
        p = heap.pop(hp, pos, importance, tie, size)
        size -= 1
        removable[p] = False
        if not guard_allows(guard, guard_value, cover_xyz, p, start, cnt, pool, covers, owners):
            continue  # kept for good: removals only take covers away
        if guard == 1:
            pass_on_cover(cover_xyz, p, start, cnt, pool, covers, owners)
        order[step] = p
        at[step] = importance[p]
        # -- 1. Voronoi neighbourhoods
        for j in range(cnt[p]):
            q = pool[start[p] + j]
            before[q] = cnt[q]
        k = remove_point(X, p, start, cnt, cap, pool, meta, half, tol, reach, link, cand, bufs,
                         lbufs, frame, mark)
        if k < 0:
            return NO_ROOM
        # -- 2. local meshes and normals of the first ring
        for j in range(k):
            a = link[j]
            if boundary[a]:  # never removed, and Eq. (1) ignores its normal: nothing to do
                continue
            s = start[a]
            if cnt[a] == before[a] - 1 and stable[a] > 0:  # lost p, gained nothing
                in_dn = False
                for i in range(dn_cnt[a]):
                    if dn[a, i] == p:
                        in_dn = True
                        break
                if not in_dn and unchanged_without(X, a, pool[s:s + cnt[a]], cnt[a], p,
                                                   stable[a]):
                    mesh_changed[a] = False
                    continue  # the same DN_a and reference plane, so the same normal
            c = local_mesh(X, a, pool[s:s + cnt[a]], cnt[a], newdn, fbufs, mbufs,
                           nvec, plane, stable[a:a + 1])
            same = c == dn_cnt[a]
            if same:
                for i in range(c):
                    if newdn[i] != dn[a, i]:
                        same = False
                        break
            mesh_changed[a] = not same
            if not same:
                for i in range(c):
                    dn[a, i] = newdn[i]
                dn_cnt[a] = c
            # the normal depends on DN_a, and on the reference plane where DN_a is collinear
            if (not same or nvec[0] != plane_normals[a, 0] or nvec[1] != plane_normals[a, 1]
                    or nvec[2] != plane_normals[a, 2]):
                plane_normals[a, 0], plane_normals[a, 1], plane_normals[a, 2] = (
                    nvec[0], nvec[1], nvec[2])
                if not update_normals:
                    continue
                normal_at(X, a, dn[a], c, plane_normals[a], wvec, nvec)
                if (wvec[0] != normals[a, 0] or wvec[1] != normals[a, 1]
                        or wvec[2] != normals[a, 2]):
                    normals[a, 0], normals[a, 1], normals[a, 2] = wvec[0], wvec[1], wvec[2]
                    normal_changed[a] = True
        # -- 3. importance of the points whose mesh or whose neighbours' normals changed
        for j in range(k):
            a = link[j]
            if mesh_changed[a] and removable[a] and stamp[a] != step + 1:
                stamp[a] = step + 1
                heap.update(hp, pos, importance, tie, a,
                            importance_of(code, X, normals, boundary, a, dn[a], dn_cnt[a],
                                          weight),
                            size)
            if not normal_changed[a]:
                continue
            s = start[a]
            for i in range(cnt[a]):
                x = pool[s + i]
                if not removable[x] or stamp[x] == step + 1:
                    continue
                uses = False
                for t in range(dn_cnt[x]):
                    if dn[x, t] == a:
                        uses = True
                        break
                if uses:
                    stamp[x] = step + 1
                    heap.update(hp, pos, importance, tie, x,
                                importance_of(code, X, normals, boundary, x, dn[x], dn_cnt[x],
                                              weight),
                                size)
        for j in range(k):
            mesh_changed[link[j]] = False
            normal_changed[link[j]] = False
        step += 1
        if at[step - 1] > stop_above:
            break  # every later step has a running maximum above stop_above
    state[STEP] = step
    state[SIZE] = size
    return DONE
