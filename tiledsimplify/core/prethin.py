"""Pre-thinning: a cheap even subset before the greedy removal (beyond the paper).

At a small target most of the greedy's removals happen on smooth surface, where the coverage
measure (:mod:`.importance`) orders points by little more than their spacing: it thins them
evenly, as Poisson-disk sample elimination would. Each such removal still pays for an exact
local update of the Voronoi neighbourhoods and local meshes (~20 µs, :mod:`.removal`). This
step reaches a subset of about ``prethin`` times the target first, by passes over the
neighbourhood graph (each ~0.1 s on a 300k-point tile):

1. every *fixed* point (frozen, and boundary up to ``edge_share`` of the count: the greedy
   never removes them) is kept;
2. the other points, block by block (:data:`BLOCK` consecutive points; the core's points
   come along a Z-order curve, so a block is a compact patch) and in the order of a
   coordinate hash within each (no direction preferred), are kept unless a kept point lies
   within the radius ``r`` along the neighbourhood graph — a Poisson-disk sample of radius
   ``r`` around the fixed points. The points the gap refinement
   protects (:func:`.refine.protected`: strongly non-planar neighbourhoods) come first in
   that order, so they win their disks, but are thinned like the rest: on a noisy scan they
   can be a large share of the cloud (28 % of the tray scan at noise 0.1), and keeping them
   all (as until 2026-12-04) filled 88 % of its subset of 2x the target with them — a
   subset the greedy and the refinement could not space out (Hausdorff 93 -> 113);
3. ``r`` is found by a few secant steps on ``log(count)`` against ``log(r)``, from the guess
   that the count goes with ``1 / r²`` as on an evenly sampled surface (scan lines, ~4x
   closer along than across, are not: 3 passes instead of 6 on a scan tile, within 10 %).

The greedy then runs on the subset alone — a new triangulation, neighbourhoods and
importance — so its removals, and their cost, fall by the share thinned here. Edge flags and
normals stay those of the whole cloud (they are computed before, at full density); the gap
refinement still sees every input point. The thinned points come first in the removal order,
with importance 0 (like exact duplicates).
"""

import math

import numpy as np

from ._jit import jit

#: with a ``max_spacing`` guard, the sample's radius is at most this share of the limit (and
#: just that when no count is asked): every thinned point then starts covered, and the greedy
#: still chooses among points closer than the limit. Measured (2026-12-04, no count asked, the
#: 300k-point scan of ``benchmarks/core_speed.py`` at limits of 3 / 5 spacings): 0.35 — 7.41 /
#: 4.97 s, mean surface error 0.758 / 1.013 (1e-4 of the diagonal; at 3 spacings the subset
#: would be above ``MAX_SHARE``: not thinned); 0.5 — 5.05 / 4.52 s, 0.768 / 1.018; 0.7 — 4.20
#: / 4.28 s, 0.775 / 1.037; counts within 0.7 %; on the Bunny mean error within ±1 % either way
GUARD_RADIUS = 0.5
#: the largest subset, as a share of the cloud, worth thinning to: the subset's own
#: neighbourhoods cost ~10 µs a point and the sample ~2 µs a point of the cloud, against ~20 µs
#: for each removal saved, so the pre-thinning pays below ~0.6 of the cloud. Measured at 0.6
#: (ratio 0.2 at 3x; 2026-12-04, one pair each, 2 workers, 150k-point tiles): the 1M scan of
#: ``benchmarks/pipeline_speed.py`` 20.6 -> 19.6 s, its 10M scan 208 -> 221 s. At the default
#: 2x a 20 % target is a subset of 0.4, where it pays (docs/measurements.md)
MAX_SHARE = 0.5
#: names the rule above in a tiled run's store fingerprint (a store thinned by another rule is
#: not resumed)
SCHEME = "protected-first, blocks"
#: consecutive points sampled together, each block in the hash order. One hash order over
#: the whole cloud visited its points at random: a pass over the 1M-point scan of
#: ``benchmarks/speed.py`` took 0.41 s (22x the 100k-point pass), by blocks of 4,096 (a
#: patch of ~4,000 spacings², whose lists stay in cache) 0.11 s, keeping 0.2 % more
#: points at the same radius (256: 0.10 s, +0.4 %; 65,536: 0.19 s, +0.1 %)
BLOCK = 4096
#: secant steps on the radius at most; each is one pass over the graph
MAX_STEPS = 8
#: relative distance from the goal count that ends the search (the goal is a rough multiple)
TOLERANCE = 0.1


@jit
def disk_sample(X, start, cnt, pool, fixed, order, r, keep, stamp, stack):
    """Keep every ``fixed`` point, then each point of ``order`` not yet within ``r`` of a kept
    point along the graph ``(start, cnt, pool)`` (a path of graph edges whose points all lie
    within ``r`` of the kept point). Fills ``keep`` (bool); returns the count kept.

    ``stamp`` (int64, n) and ``stack`` (int64, n) are scratch.
    """
    n = X.shape[0]
    covered = np.zeros(n, dtype=np.bool_)
    r2 = r * r
    kept = 0
    for i in range(n):
        stamp[i] = -1
        keep[i] = False
    for phase in range(2):
        m = n if phase == 0 else order.size
        for t in range(m):
            p = t if phase == 0 else order[t]
            if phase == 0 and not fixed[p]:
                continue
            if phase == 1 and (covered[p] or fixed[p]):
                continue
            keep[p] = True
            covered[p] = True
            kept += 1
            stamp[p] = p
            top = 1
            stack[0] = p
            while top > 0:
                top -= 1
                a = stack[top]
                s = start[a]
                for j in range(cnt[a]):
                    q = pool[s + j]
                    if stamp[q] == p:
                        continue
                    stamp[q] = p
                    dx, dy, dz = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
                    if dx * dx + dy * dy + dz * dz > r2:
                        continue
                    covered[q] = True
                    stack[top] = q
                    top += 1
    return kept


def _secant(r, k, last, aim, model):
    """The next radius of a search for the one whose sample holds ``aim`` points: ``k`` at
    ``r`` now, ``last`` the ``(radius, count)`` before (or None). A secant step on ``log(count)``
    against ``log(r)``, its slope clamped to [-4, -0.5]; the ``model``'s slope (-2 on a
    surface, -1 along a line) where there is no earlier count to take it from. Half the
    radius if nothing was kept."""
    if k <= 0:
        return 0.5 * r
    slope = model
    if last is not None and last[1] > 0 and last[1] != k:
        slope = min(-0.5, max(-4.0, math.log(k / last[1]) / math.log(r / last[0])))
    return r * (aim / k) ** (1.0 / slope)


def _block_order(tie):
    """``np.lexsort((tie, np.arange(n) // BLOCK))``: each block of :data:`BLOCK` consecutive
    points in the order of ``tie`` (stable), a block at a time: 6.4 ms for a 140k-point tile
    against the lexsort's 15.6 (its two keys each a stable sort of every point)."""
    n = tie.size
    order = np.empty(n, dtype=np.int64)
    for s in range(0, n, BLOCK):
        order[s:s + BLOCK] = s + np.argsort(tie[s:s + BLOCK], kind="stable")
    return order


def subset(X, start, cnt, pool, fixed, goal, spacing, tie, least=0, first=None,
           max_radius=math.inf):
    """About ``goal`` points of ``X``: every ``fixed`` one and a disk sample of the rest, in
    blocks of :data:`BLOCK` consecutive points, each in the order of ``tie``
    (:func:`disk_sample` over the graph ``(start, cnt, pool)``), the points of ``first``
    (bool, optional) before the others. The disk's radius is at most ``max_radius`` (a
    ``max_spacing`` guard's share: then every thinned point lies within it of a kept one);
    with ``goal`` None it is that radius.

    Returns the bool mask of the subset, or None — nothing is thinned — when the goal (or the
    sample at ``max_radius``) is above :data:`MAX_SHARE` of the cloud (it would not pay), when
    the fixed points alone reach it, or when the closest sample found keeps fewer than
    ``least`` points.
    """
    n = X.shape[0]
    n_fixed = int(fixed.sum())
    by_radius = goal is None
    if by_radius:
        if not (math.isfinite(max_radius) and max_radius > 0):
            return None
        goal = n_fixed + 1  # as far as the radius goes
    free_goal = goal - n_fixed
    if free_goal <= 0 or goal > MAX_SHARE * n or not spacing > 0:
        return None
    order = _block_order(tie)
    if first is not None:
        order = np.concatenate([order[first[order]], order[~first[order]]])
    keep = np.zeros(n, dtype=bool)
    stamp = np.empty(n, dtype=np.int64)
    stack = np.empty(n, dtype=np.int64)
    # first guess: a disk of radius r on a surface of spacing s holds ~ pi (r / s)^2 points;
    # then secant steps on log(count) against log(r) (scan lines are far from that model)
    r = min(spacing * math.sqrt((n - n_fixed) / (math.pi * free_goal)), max_radius)
    best, last = None, None
    for _ in range(MAX_STEPS):
        k = disk_sample(X, start, cnt, pool, fixed, order, r, keep, stamp, stack) - n_fixed
        if best is None or abs(k - free_goal) < abs(best[0] - free_goal):
            best = (k, keep.copy())
        if abs(k - free_goal) <= TOLERANCE * free_goal or (r == max_radius and k >= free_goal):
            break  # near the goal, or as far as the radius may go
        r, last = min(_secant(r, k, last, free_goal, -2.0), max_radius), (r, k)
    k, mask = best
    if n_fixed + k < least or (by_radius and n_fixed + k > MAX_SHARE * n):
        return None
    return mask


def edge_sample(X, start, cnt, pool, flags, distance, tie, goal, spacing):
    """At most about ``goal`` of the ``flags``: an even sample along the edges, each flagged
    point taken, nearest its fitted edge line first (``distance``, ties by ``tie``), unless a
    point taken lies within the radius along the graph (:func:`disk_sample` of the flagged
    points alone). The radius is found as :func:`subset` finds its own, from the model of a
    line (the count goes with ``1 / r``); of the samples tried, the largest at most ``goal``
    wins (the smallest if none is). Returns the bool mask (all of ``flags`` if they are no
    more than ``goal``; none if ``goal`` is 0).

    Beyond the paper (the option ``edge_share``): kept whatever the count, as the paper
    keeps its boundary points, flagged points alone would take small targets — the Fandisk at
    5 %, 1,524 flags for a count of 824 — and leave the faces empty.
    """
    n = X.shape[0]
    ids = np.flatnonzero(flags)
    if ids.size <= goal:
        return flags.copy()
    if goal <= 0 or not spacing > 0:
        return np.zeros(n, dtype=bool)
    order = ids[np.lexsort((tie[ids], distance[ids]))].astype(np.int64)
    none = np.zeros(n, dtype=bool)
    keep = np.zeros(n, dtype=bool)
    stamp = np.empty(n, dtype=np.int64)
    stack = np.empty(n, dtype=np.int64)
    aim = (1.0 - 0.5 * TOLERANCE) * goal  # the middle of the band accepted
    r = spacing * ids.size / aim  # a band of rows at the spacing, thinned along its line
    best, last = None, None
    for _ in range(MAX_STEPS):
        k = disk_sample(X, start, cnt, pool, none, order, r, keep, stamp, stack)
        rank = (k > goal, abs(k - goal))  # at most the goal first, then the nearest to it
        if best is None or rank < best[0]:
            best = (rank, keep.copy())
        if goal * (1.0 - TOLERANCE) <= k <= goal:
            break
        r, last = _secant(r, k, last, aim, -1.0), (r, k)  # along a line: count ~ 1 / r
    return best[1]


def covered_by(X, keep, covers, limit):
    """For a ``max_spacing`` guard: the cover of every thinned point (``~keep``) that needs one
    (``covers``, bool or None for all) — its nearest kept point that may cover, within
    ``limit`` — as an index into ``X``, ``-1`` elsewhere. A thinned point with none within
    the limit (a tile's point whose disk was a halo point's) goes back into ``keep``
    (changed in place) and covers itself."""
    from scipy.spatial import cKDTree

    n = X.shape[0]
    owner = np.full(n, -1, dtype=np.int64)
    can = keep if covers is None else keep & covers
    need = ~keep if covers is None else ~keep & covers
    ids = np.flatnonzero(need)
    pool = np.flatnonzero(can)
    if ids.size == 0:
        return owner
    if pool.size == 0:
        keep[ids] = True
        return owner
    d, j = cKDTree(X[pool]).query(X[ids])
    ok = d <= limit
    owner[ids[ok]] = pool[j[ok]]
    keep[ids[~ok]] = True
    return owner


def link_covers(owners, members, cover):
    """Hand each of ``members`` to its ``cover`` (``-1``: none) in the guard's cover lists
    ``owners`` (:func:`tiledsimplify.core.removal.guard_allows`): ``owners[0, c]`` the first
    point ``c`` covers, ``owners[1, x]`` the next after ``x``."""
    has = cover >= 0
    members, cover = members[has], cover[has]
    order = np.argsort(cover, kind="stable")
    members, cover = members[order], cover[order]
    same = cover[1:] == cover[:-1]
    after = np.full(members.size, -1, dtype=np.int64)
    after[:-1][same] = members[1:][same]
    owners[1, members] = after
    first = np.r_[True, ~same] if members.size else np.zeros(0, dtype=bool)
    owners[0, cover[first]] = members[first]
