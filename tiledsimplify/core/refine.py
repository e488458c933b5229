"""Gap refinement: swaps at equal count that lower the Hausdorff distance (beyond the paper).

The greedy removal (:mod:`.removal`) decides each step on local information, so the kept set
it reaches can leave a few holes wider than a farthest-point sample of the same size would
(issue 5: Hausdorff 1.3–2× farthest point sampling's). This pass takes the kept set at the
requested count and trades points, keeping the count exact and every fixed (boundary, frozen)
point:

1. ``H`` = the Hausdorff distance from the input to the kept set (the largest distance from an
   input point to its nearest kept point); aim at a level ``τ = (1 − step) · H``.
2. **Fill**: add back input points, farthest first (as farthest point sampling does), until
   every input point lies within ``τ`` of the kept set; say ``a`` were added.
3. **Thin**: remove ``a`` kept points that are neither fixed nor just added, each only if every
   input point it is the nearest kept point of has another kept point within ``τ`` — so the
   bound ``τ`` survives every removal. Candidates go smallest gap (the one their removal would
   open) first, as in sample elimination.
4. If ``a`` removals were found, commit the swap and aim lower; otherwise halve ``step`` and
   try again, and stop when it falls below ``min_step`` or after ``max_rounds`` tries.

**The flags' cover** (``edges``, ``edge_radius``; 2026-12-05 — the caller's edge points, which
:func:`.simplify.simplify_points` gives as its features since that night: the flagged points and
those on narrow smooth folds, :attr:`.result.SimplifyResult.features`): before the rounds,
flagged points farther than the radius from the kept set are added (farthest first, among the
flags alone) and as many kept points thinned at the level ``H`` itself, so ``H`` does not rise;
the flags added stay fixed. In every round a flagged point's distance counts ``τ / radius``
times in the thinning (its *scale*), so no removal leaves it beyond the radius. Without it the
rounds traded the flags outside the core band for the Hausdorff distance and opened gaps along
the edges (:data:`EDGE_COVER`).

Every committed round lowers the Hausdorff distance by at least ``min_step · H``; a failed one
changes nothing. So the result never has a larger Hausdorff distance than the input kept set.

Nearest kept points are searched among each input point's ``k`` nearest candidates; a point
with no candidate left among them counts as uncovered, so a removal that would need a farther
one is refused (never wrongly allowed).

**Searches.** Every search is exact, with equal distances decided by the candidates' tie key
(``tie``) and then their position: "nearest" means smallest (distance, tie), so the result is a
function of the points and keys alone (:mod:`.cell_grid`). The candidates change every round
but the input points do not, so one grid of cells (side ≥ the first Hausdorff distance, which
bounds every radius asked) is built once and each round only sorts the candidates into it.
Where a few wide gaps would make the cells hold hundreds of candidates (``MAX_LOAD``), or a
watched point's nearest candidate lies beyond the cells, a kd-tree's superset measured exactly
answers instead (:func:`.cell_grid.exact_search`). Tests compare the whole pass with a brute
force version (``tests/naive.py``). Until 2026-12-02 the searches followed cKDTree's own order
of equal distances: a kd-tree over the candidates in every round for the ~1 % of points with a
tie, a fifth of a pipeline tile's refinement time.
"""

import numpy as np
from scipy.spatial import cKDTree

from . import adjacency, cell_grid, heap
from ._jit import jit
from .bounds import box

#: kept points whose boundary measure exceeds this many times the boundary threshold are never
#: swapped out, besides boundary and frozen points (:func:`protected`). Edge candidates just
#: above the threshold are mostly rows beside a flagged edge or noise on a scan; swapping them
#: for fills lowers the Hausdorff distance. Measured on the 38 quality cases
#: (``benchmarks/quality.py``, with ``edge_fit.MAX_RMS`` still 0.4; geometric mean against
#: protecting every candidate, 1x): 3x — Hausdorff -3.5 % (lower on 38 of 38), Chamfer -2.0 %,
#: mean surface error +0.3 %, edge coverage -0.2 %; within 1.2x of the best peer's Hausdorff
#: on 32 cases against 27, best edge coverage on 26 against 25, lowest mean error on 31 as
#: before. No protection: Hausdorff -6.2 %, but mean error +1.3 % (Autzen 3.15 -> 3.34, above
#: CGAL's 3.23) and coverage -2.5 % (counter scan 0.417 -> 0.353); 4x: between the two.
PROTECT = 3.0
#: ... unless every point within this many steps of the Voronoi lists is above that level too:
#: such a point stands out from nothing around it (the inside of a thin-walled stack whose
#: two-rings all cross its walls, a stretch of rough rock). On cycloidal (a cycloidal drive's
#: stack of thin discs, 20k points) 83.5 % of the points were above it and 90 % of the kept
#: count fixed: the refinement could move a tenth. Measured on the 39 quality cases (ours
#: only, against protecting all; docs/measurements.md "Protected only beside a point below
#: the level"): 2 — cycloidal's mean error 44.89 -> 43.40 (below every peer's: MeshLab's
#: Poisson disk 44.45), edge coverage 0.712 -> 0.729, Hausdorff -5.4 %; Autzen's mean error
#: +1.6 %, Hausdorff -2.9 %; the other 37: edge coverage, mean error and Hausdorff within
#: 1 %. 1: cycloidal's mean error won too (43.74), but mean error +0.7 % in geometric mean
#: (up to +3.6 % on scans); 3: cycloidal 44.83, lost.
PROTECT_HOPS = 2

#: flagged points (sharp-edge flags) the refinement brings and keeps within
#: :func:`edge_cover_radius` of a kept point (:func:`refine_coverage`'s ``edges``): this many
#: point spacings at a count of 20 % of the points, growing as ``(0.2 / ratio) **
#: EDGE_COVER_POWER`` at smaller counts. The benchmark's edge coverage counts an edge sample
#: covered within 1.5 spacings; a flag lies within about one spacing of its edge. Measured on
#: the 38 quality cases at 20 % (ours only, against no cover; geometric means;
#: docs/measurements.md): 1.35 — mean surface error -1.1 %, edge coverage +0.9 %, Hausdorff
#: +0.9 %; edge coverage >= 0.95 and above every peer on 6 even CAD parts instead of 3, above
#: every peer on rocker-arm too, no target lost. 1.5: -0.7 / +0.8 / +0.5 %, 4 parts; 1.2: 7
#: parts, but three Hausdorff targets lost (featuretype 152 -> 182).
EDGE_COVER = 1.35
#: how the cover radius grows at smaller counts (see :data:`EDGE_COVER`). The kept points'
#: spacing grows as ``ratio ** -0.5``; a cover that follows it (0.5) spends the count on the
#: edges where the faces need it — on the README's eight small-ratio cases at 5 %, Hausdorff
#: +7.4 % and 4 of 8 Hausdorff targets lost (mean error -8.8 %); 0.75: Hausdorff +1.0 % at 5
#: % and +2.1 % at 2 %, mean error -1.3 / -2.9 %, edge coverage +2.8 / +5.5 %, no target lost;
#: 1.0: almost no change below 10 %.
EDGE_COVER_POWER = 0.75


def edge_cover_radius(spacing, ratio):
    """The distance within which :func:`refine_coverage` keeps every flagged point from a
    kept point (model units): :data:`EDGE_COVER` point ``spacing`` at ``ratio`` (kept over
    input points) 0.2, ``(0.2 / ratio) ** EDGE_COVER_POWER`` times that at others; 0 (no
    cover) without a spacing or a count."""
    if not spacing or not spacing > 0 or not ratio > 0:
        return 0.0
    return EDGE_COVER * float(spacing) * (0.2 / ratio) ** EDGE_COVER_POWER


def protected(deviation, threshold, start, cnt, pool):
    """The points the gap refinement may not swap out for their boundary measure: ``deviation
    > PROTECT * threshold`` (strongly non-planar neighbourhoods: edges, corners, rough or
    curved detail), ``threshold`` being the boundary threshold the run used — but for those
    with no point below that level within :data:`PROTECT_HOPS` steps of the lists ``start``,
    ``cnt``, ``pool`` (the Voronoi neighbours, :mod:`.adjacency`)."""
    above = np.asarray(deviation) > PROTECT * threshold
    beside = ~above
    for _ in range(PROTECT_HOPS):
        beside = adjacency.grow(beside, start, cnt, pool)
    return above & beside


#: mean candidates per search (the 27 cells around a point) above which a kd-tree answers
#: instead. Both cost about the same at ~600 (100k scan points, cells 7x the usual side); the
#: usual is ~10, as the first Hausdorff distance, the cells' side, is ~1.3x the 99th
#: percentile of the distances (10 cases: CAD parts, scans, pipeline tiles)
MAX_LOAD = 512


@jit
def _first_alive(nbr, alive, j, end):
    """Position of the first ``alive`` candidate in ``nbr[j:end]`` (-1: none)."""
    while j < end:
        if alive[nbr[j]]:
            return j
        j += 1
    return -1


@jit
def _gap(c, start, nbr, nd, owner, alive, head, nxt, scale):
    """The largest distance an input point owned by ``c`` would have to its next candidate if
    ``c`` were removed (inf if one has none in its list)."""
    worst = 0.0
    x = head[c]
    while x >= 0:
        j = _first_alive(nbr, alive, owner[x] + 1, start[x + 1])
        if j < 0:
            return np.inf
        g = nd[j] * scale[x]
        if g > worst:
            worst = g
        x = nxt[x]
    return worst


@jit
def thin_below(start, nbr, nd, removable, tie, level, n_remove, scale):
    """Remove up to ``n_remove`` candidates, smallest gap first, never leaving an input point
    farther than ``level`` from its nearest remaining candidate.

    ``start`` / ``nbr`` / ``nd`` (CSR: row ``x``'s entries at ``start[x]:start[x + 1]``, as
    :func:`.cell_grid.nearest` returns them): for each input point that
    may change owner (a *row*), its nearest candidates (ids into the candidate set, nearest
    first; at most ``k``, those within the search radius) and their distances. ``removable``
    (m,) marks the candidates that may go; ``tie`` (uint64, m) breaks equal gaps. A row is
    *owned* by its nearest remaining candidate; the gap of a candidate is the largest distance
    a row it owns would have to its next candidate. Gaps only grow as candidates go, so the
    queue is kept up to date lazily: a candidate's gap is recomputed when it reaches the top.

    Each candidate's owned rows are a linked list (``head`` / ``nxt``; a row is in one list at
    a time), so a gap costs the few rows a candidate owns, not every row that lists it; the
    first gaps come from one pass over the rows.

    ``scale`` (float64, one per row): a row's distances count that many times in the gaps
    (1 for every row: the plain thinning; ``level / radius`` keeps a row within ``radius``).

    Returns
    -------
    removed : int64
        The removed candidates, in order.
    dist : float64 (r,)
        Each row's distance to its nearest remaining candidate (inf if none is left in its
        list; cannot happen to a row that started with one within ``level``).
    """
    r = start.size - 1
    m = removable.size
    alive = np.ones(m, dtype=np.bool_)
    owner = np.full(r, -1, dtype=np.int64)  # position of the row's owner in nbr; -1: none
    head = np.full(m, -1, dtype=np.int64)
    nxt = np.full(r, -1, dtype=np.int64)
    key = np.zeros(m)
    for x in range(r - 1, -1, -1):
        if start[x] == start[x + 1]:
            continue
        owner[x] = start[x]
        c = nbr[start[x]]
        nxt[x] = head[c]
        head[c] = x
        if removable[c]:
            g = nd[start[x] + 1] * scale[x] if start[x] + 1 < start[x + 1] else np.inf
            if g > key[c]:
                key[c] = g
    items = np.nonzero(removable)[0]
    hp, pos = heap.new(m)
    size = heap.build(hp, pos, key, tie, items)
    out = np.empty(min(n_remove, items.size), dtype=np.int64)
    done = 0
    while done < out.size and size > 0:
        c = heap.top(hp)
        g = _gap(c, start, nbr, nd, owner, alive, head, nxt, scale)
        if g > key[c]:  # stale: the gap grew since it was queued
            heap.update(hp, pos, key, tie, c, g, size)
            continue
        if not g <= level:
            break  # every other gap is at least as large
        heap.pop(hp, pos, key, tie, size)
        size -= 1
        alive[c] = False
        out[done] = c
        done += 1
        x = head[c]
        head[c] = -1
        while x >= 0:  # its rows move to their next remaining candidate
            after = nxt[x]
            j = _first_alive(nbr, alive, owner[x] + 1, start[x + 1])
            owner[x] = j
            if j >= 0:
                d = nbr[j]
                nxt[x] = head[d]
                head[d] = x
            x = after
    dist = np.empty(r)
    for x in range(r):
        dist[x] = nd[owner[x]] if owner[x] >= 0 else np.inf
    return out[:done], dist


@jit
def _fill_cells(X, dist, level, cell_of, near_start, near, pt_start, pt, pt_xyz, reach):
    """Add points, farthest first, while ``dist`` exceeds ``level`` (in place), by the cells.

    The farthest point ``x`` (the first of equals, as ``np.argmax``) is added: every point
    nearer to it than its distance so far takes that distance (all lie within ``dist[x]``, the
    largest, so in the cells around it while that is below ``reach``). Returns the added
    points and ``-1``, or stops before a point whose distance reaches beyond the cells and
    returns it instead of ``-1``.

    The points above ``level`` wait in a heap keyed by their distance (ties by id, so the
    first of equals comes first, as ``np.argmax``); a distance that drops is updated in place.
    A scan of them all for the largest before each addition made this quadratic: 0.75 s of a
    1M-point core run against 0.007 s at 100k points.
    """
    far = np.nonzero(dist > level)[0]  # only these can be added: distances only drop
    m = far.size
    out = np.empty(m, dtype=np.int64)
    slot = np.full(dist.size, -1, dtype=np.int64)  # a point's index in ``far``
    key = np.empty(m)
    for t in range(m):
        slot[far[t]] = t
        key[t] = -dist[far[t]]
    tie = np.zeros(m, dtype=np.uint64)
    hp, pos = heap.new(m)
    size = heap.build(hp, pos, key, tie, np.arange(m))
    done = 0
    while size > 0:
        x = far[heap.top(hp)]
        r = dist[x]
        if not r > level:
            break
        if not r < reach:
            return out[:done], x
        heap.pop(hp, pos, key, tie, size)
        size -= 1
        dist[x] = 0.0
        q = X[x]
        cell = cell_of[x]
        for u in range(near_start[cell], near_start[cell + 1]):
            v = near[u]
            for i in range(pt_start[v], pt_start[v + 1]):
                y = pt[i]
                d = np.sqrt(cell_grid.sq_dist(pt_xyz, i, q))
                if d < dist[y]:
                    dist[y] = d
                    t = slot[y]
                    if t >= 0 and pos[t] >= 0:
                        heap.update(hp, pos, key, tie, t, -d, size)
        out[done] = x
        done += 1
    return out[:done], -1


def _fill(X, grid, tree_x, dist, level):
    """Input points to add, farthest first, until all of ``dist`` is within ``level``
    (``dist`` is updated in place): each added point lowers the distance of the points nearer
    to it to their distance from it. By the cells; a point whose distance reaches beyond them
    by the kd-tree (``tree_x()`` builds it once) and the same exact distances."""
    added = []
    while True:
        got, x = _fill_cells(X, dist, level, grid.cell_of, grid.near_start, grid.near,
                             grid.pt_start, grid.pt, grid.pt_xyz, grid.reach)
        added.append(got)
        if x < 0:
            return np.concatenate(added)
        near = np.asarray(tree_x().query_ball_point(X[x], dist[x] * (1.0 + 1e-6)),
                          dtype=np.int64)
        if near.size:
            e = X[near] - X[x]
            d = np.sqrt(e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1] + e[:, 2] * e[:, 2])
            np.minimum.at(dist, near, d)
        dist[x] = 0.0
        added.append(np.array([x], dtype=np.int64))


def _nearest(X, grid, cand, cand_tie, counted, k, level, removable):
    """The nearest candidate of every input point, and the ``k`` nearest within ``level`` of
    each row (a point whose nearest is removable), in :func:`.cell_grid.nearest`'s order
    (distance, then ``cand_tie``): by the cells, the few they cannot settle (a nearest beyond
    them) by :func:`.cell_grid.exact_search`; all by it if ``grid`` is None.

    ``counted``: ``(ids, xyz, cell)`` of the points that take part, cell by cell. Marks the
    nearest candidate of each point at or beyond ``level`` not ``removable`` (in place): a
    watched point's, and one at the level itself — its list (candidates nearer than the
    level) is empty, so no gap would count it. (The rounds' fill leaves no point beyond the
    level but watched ones; the flags' cover thins at the level of the Hausdorff distance,
    where the farthest points lie at the level. Until 2026-12-05 only watched points beyond
    it were marked: there the farthest point's nearest could go, the distance became
    infinite, and the next round searched every pair — Autzen at 2 %, 380 s.)

    Returns ``d1`` (n,) (0 where not counted), the lists for :func:`thin_below`, ``rows`` and
    ``at`` (the rows' positions among the lists). The lists are those of every counted point,
    in the order of ``ids``. The lists of points that are not rows start with their nearest
    candidate, which is not removable, so they never change owner and take no part in any
    gap.
    """
    ids, Q, q_cell = counted
    if grid is not None:
        start, slot, xyz = grid.members(X, cand)
        d, o, amb1, l_start, l_idx, l_dist, amb = cell_grid.nearest(
            Q, q_cell, grid.near_start, grid.near, start, slot, xyz, grid.reach * grid.reach,
            k, level, cand_tie)
        if amb.any():  # the level reaches beyond the cells (never: it stays below H < reach)
            grid = None
        elif amb1.any():  # a nearest beyond the cells, so beyond the level: no list
            a = np.flatnonzero(amb1)
            d[a], o[a] = cell_grid.exact_search(X[cand], cand_tie, Q[a], k, 0.0)[:2]
    if grid is None:
        d, o, l_start, l_idx, l_dist = cell_grid.exact_search(X[cand], cand_tie, Q, k, level)
    removable[o[d >= level]] = False  # a point at or beyond the level keeps its nearest
    sel = np.flatnonzero(removable[o])
    d1 = np.zeros(X.shape[0])
    d1[ids] = d
    return d1, (l_start, l_idx, l_dist), ids[sel], sel


def _once(make):
    """A function that calls ``make()`` the first time and returns its result ever after."""
    got = []

    def get():
        if not got:
            got.append(make())
        return got[0]
    return get


def inputs(X, keep, fixed, addable, watch, tie):
    """:func:`refine_coverage`'s arguments as arrays: ``(X, keep, fixed, addable, ignored,
    watched, tie)`` — ``keep`` a copy, ``fixed`` only where kept, ``ignored`` the points that
    take no part (neither kept nor addable nor watched; stays so, as only addable points are
    ever added), ``watched`` only among the points not kept and not addable."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    keep = np.asarray(keep, dtype=bool).copy()
    fixed = np.asarray(fixed, dtype=bool) & keep
    n = X.shape[0]
    addable = np.ones(n, dtype=bool) if addable is None else np.asarray(addable, dtype=bool)
    ignored = ~(keep | addable)
    watched = np.zeros(n, dtype=bool)
    if watch is not None:
        watched = np.asarray(watch, dtype=bool) & ignored
        ignored &= ~watched
    if tie is None:
        tie = np.arange(n, dtype=np.uint64)
    return X, keep, fixed, addable, ignored, watched, tie


def refine_coverage(X, keep, fixed, *, addable=None, watch=None, tie=None, step=0.05,
                    min_step=0.002, max_rounds=60, k=16, edges=None, edge_radius=0.0,
                    before_out=None):
    """Swap kept points at equal count so that the Hausdorff distance to the input drops.

    Parameters
    ----------
    X : float64 (n, 3)
        The input points (distinct).
    keep : bool (n,)
        The kept set to refine.
    fixed : bool (n,)
        Kept points that must stay (boundary and frozen points); ``fixed & ~keep`` is ignored.
    addable : bool (n,), optional
        Points that may be added (default: all). A point neither kept nor addable takes no
        part: it is never added and its distance does not count (a tile's removed halo
        points, which another tile owns). The Hausdorff distance is over ``keep | addable``.
    watch : bool (n,), optional
        Points neither kept nor addable whose coverage must not suffer (removed points of
        other tiles): they do not count in the Hausdorff distance and are never added, but a
        round at level ``τ`` never leaves one farther than ``max(τ, its distance before)``
        (one within ``τ`` stays within ``τ``; the nearest kept point of one beyond stays).
    tie : uint64 (n,), optional
        Tie-breaker of equal gaps (default: the point index; the core passes
        :func:`.heap.coordinate_hash`).
    step, min_step : float
        Each round aims at ``(1 − step) ×`` the current Hausdorff distance; a failed round
        halves ``step``; the pass stops below ``min_step``.
    max_rounds : int
        Upper bound on rounds, committed or failed.
    k : int
        Kept points searched per input point when thinning.
    edges : bool (n,), optional
        Flagged points (sharp-edge flags) to bring and keep within ``edge_radius`` of a kept
        point (the module's "flags' cover"); a flag that the fill before the rounds could not
        bring within it (where too few kept points could go) keeps its nearest kept point.
    edge_radius : float
        Model units; 0 (or no ``edges``): no cover, the rounds as without it bit for bit.
    before_out : float64 (n,), optional
        Filled with each point's distance to the kept set before any swap, as the kd-tree
        gives it (0 where the point takes no part; inf if nothing is kept): a tiled run
        reads its tile's gaps under the cut from it
        (:func:`~tiledsimplify.pipeline.tile_refine.refine_tile`).

    Returns
    -------
    keep : bool (n,)
        The refined kept set: same count, every kept ``fixed`` point still kept.
    info : dict
        ``hausdorff_before``, ``hausdorff_after`` (model units), ``rounds``, ``swaps``
        (``edge_swaps`` of them by the cover's fill).

    Notes
    -----
    Cost: once, a kd-tree nearest query of every input point and a grid of cells (O(n log n)).
    Per round, O(n): the candidates sorted into the cells, for every input point the
    candidates in the 27 cells around it (a few dozen), the ball of each added point the same
    way; an indexed heap over the kept points. One core: ~0.04 s for
    Fandisk (16k points at 20 %), ~0.3 s for 100k scan points, 3-5x less than the kd-tree
    version's.
    """
    X, keep, fixed, addable, ignored, watched, tie = inputs(X, keep, fixed, addable, watch, tie)
    info = {"hausdorff_before": 0.0, "hausdorff_after": 0.0, "rounds": 0, "swaps": 0,
            "edge_swaps": 0}
    dist = None
    if before_out is not None:
        dist = _distances(X, keep, ignored)
        before_out[:] = dist
    if not (keep & ~fixed).any() or not (addable & ~keep).any():
        return keep, info  # nothing may go, or nothing to add
    if dist is None:
        dist = _distances(X, keep, ignored)
    H = float(dist[~watched].max())
    info["hausdorff_before"] = H
    if not H > 0:
        return keep, info
    _drop_inert(X, keep, fixed, addable, ignored, watched, dist)
    # cells that hold every radius asked below: H only drops, and levels are below it
    grid = cell_grid.CellGrid(X, H * (1.0 + 4.0 * cell_grid.COVER))
    tree_x = _once(lambda: cKDTree(X))
    ids = grid.pt[~ignored[grid.pt]]  # the points that count, cell by cell
    counted = (ids, np.ascontiguousarray(X[ids]), grid.cell_of[ids])
    # a few wide gaps make cells that hold hundreds of candidates: a kd-tree is then faster
    search_grid = grid if grid.load(np.flatnonzero(keep), ids) <= MAX_LOAD else None
    # beyond the swaps for the Hausdorff distance: every flag within ``edge_radius`` of a kept
    # point, first by a fill of the flags alone at the level H, then kept so by every round
    cap = None
    if edges is not None and edge_radius > 0:
        edges = np.asarray(edges, dtype=bool)
        cap = np.where(edges[ids], float(edge_radius), np.inf)
        added = _fill(X, grid, tree_x, np.where(edges & addable & ~keep, dist, 0.0), edge_radius)
        while added.size:  # where fewer kept points can go, the last additions are not made
            d1 = _swap(X, keep, fixed, added, H, cap, search_grid, tie, counted, k)
            if d1 is not None:
                fixed[added] = True  # not traded for the Hausdorff (``fixed``: inputs' copy)
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
        trial[watched] = 0.0  # not filled for: another tile's
        added = _fill(X, grid, tree_x, trial, level)
        d1 = _swap(X, keep, fixed, added, level, cap, search_grid, tie, counted, k)
        if d1 is None:
            step *= 0.5
            continue
        info["swaps"] += int(added.size)
        dist = d1
        H = float(dist[~watched].max())
    info["hausdorff_after"] = H
    return keep, info


def _drop_inert(X, keep, fixed, addable, ignored, watched, dist):
    """Take out of the pass (in place: ``ignored``, not ``watched``, distance 0) the watched
    points nearer to their nearest kept point than to the box of every point that may be
    added or removed: that nearest is fixed, and nothing added can come nearer, so they never
    change owner nor hold back a removal — the result is the same without them.

    A tile's view wider than its halo (small ratios, :mod:`..pipeline.tile_refine`) is
    mostly such points: other tiles' removed points, covered by kept points of their own
    tile. Each round searched their nearest candidates all the same."""
    w = np.flatnonzero(watched)
    active = addable | (keep & ~fixed)
    if not w.size or not active.any():
        return
    A = X[active]
    lo, hi = box(A)
    out = np.maximum(np.maximum(lo - X[w], X[w] - hi), 0.0)  # per axis, beyond the box
    inert = w[np.sqrt((out * out).sum(axis=1)) > dist[w]]
    ignored[inert] = True
    watched[inert] = False
    dist[inert] = 0.0


def _distances(X, keep, ignored):
    """Every point's distance to the kept points (inf if none is kept), 0 where ignored, as
    the kd-tree gives it (:func:`.cell_grid.distances_to`)."""
    if not keep.any():
        dist = np.full(X.shape[0], np.inf)
    else:
        dist = np.zeros(X.shape[0])
        counted = np.flatnonzero(~ignored)
        dist[counted] = cell_grid.distances_to(X, np.flatnonzero(keep), counted)
    dist[ignored] = 0.0
    return dist


def _swap(X, keep, fixed, added, level, cap, search_grid, tie, counted, k):
    """Add ``added`` to the kept set and remove as many kept points that are not ``fixed``,
    smallest gap first, none leaving a counted point farther than ``level`` from the kept set
    — nor a flagged one farther than its ``cap`` (None: none) — (:func:`thin_below`): changes
    ``keep`` in place and returns every point's distance to the new kept set (0 where not
    counted); None, and ``keep`` unchanged, if fewer can go."""
    cand = np.concatenate([np.flatnonzero(keep), added])
    removable = ~fixed[cand]
    removable[cand.size - added.size:] = False
    cand_tie = np.ascontiguousarray(tie[cand], dtype=np.uint64)
    d1, lists, rows, at = _nearest(X, search_grid, cand, cand_tie, counted,
                                   min(k, cand.size), level, removable)
    # a flagged row may end no farther than its cap: its distances count level / cap times
    scale = np.ones(counted[0].size)
    if cap is not None:
        tight = cap < level
        scale[tight] = level / cap[tight]
    gone, d_lists = thin_below(*lists, removable, cand_tie, level, added.size, scale)
    if gone.size < added.size:
        return None
    keep[added] = True
    keep[cand[gone]] = False
    d1[rows] = d_lists[at]
    return d1
