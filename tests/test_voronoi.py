"""Voronoi neighbours: construction against Qhull and an LP, maintenance against rebuilding."""

import numpy as np
import pytest
from scipy.spatial import ConvexHull, cKDTree

from tiledsimplify.core import adjacency, voronoi

import naive


def _edges(lists):
    return {(i, j) for i, s in enumerate(lists) for j in s if i < j}


def _build(X, scale=None, reach=np.inf):
    (start, cnt, cap, pool, meta), how = voronoi.voronoi_neighbours(X, scale=scale, reach=reach)
    return (start, cnt, cap, pool, meta), how


def _sphere(rng, n, noise=1e-3):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    return v + noise * rng.normal(size=v.shape)


@pytest.mark.parametrize("kind", ["cube", "sphere"])
def test_construction_equals_delaunay_on_generic_points(kind):
    rng = np.random.default_rng(0)
    X = rng.random((1500, 3)) if kind == "cube" else _sphere(rng, 1500)
    (start, cnt, cap, pool, meta), how = _build(X)
    assert how == "qhull"
    got = _edges(adjacency.to_sets(start, cnt, pool))
    ref = naive.delaunay_edges(X)
    # facets between two convex-hull points may lie farther away than the clipping square
    hull = set(ConvexHull(X).vertices.tolist())
    assert got <= ref
    missing = {e for e in ref - got if not (e[0] in hull and e[1] in hull)}
    assert missing == set()


@pytest.mark.parametrize("reach", [np.inf, 0.25])
def test_facet_rule_equals_linear_programming(reach):
    rng = np.random.default_rng(1)
    X = rng.random((60, 3))
    X -= 0.5
    D = voronoi.scale_of(X)
    (start, cnt, cap, pool, meta), _ = _build(X, reach=reach)
    got = _edges(adjacency.to_sets(start, cnt, pool))
    ref = naive.voronoi_edges(X, voronoi.BOX_FACTOR * D, voronoi.TOL_FACTOR * D,
                              candidates=sorted(naive.delaunay_edges(X)), reach=reach)
    assert got == ref
    if np.isfinite(reach):  # the reach cuts a good share of the edges, not all
        (s0, c0, _, p0, _), _ = _build(X)
        unbounded = _edges(adjacency.to_sets(s0, c0, p0))
        assert got < unbounded and len(got) > 0.3 * len(unbounded)


def test_reach_bounds_the_neighbours_of_a_quantised_flat_face():
    """A flat face quantised like a LAS file lies in a few exact layers. Seen from outside,
    the sparse outermost layer owns the far half-space: without a reach each of its points
    is a Voronoi neighbour of hundreds of face points (thousands on a 10M-point scan, which
    made removal 10-30x slower); within 10 spacings only the nearby ones count."""
    rng = np.random.default_rng(7)
    n = 6000
    face = np.c_[rng.random((n, 2)) * 0.08, rng.normal(0.0, 1e-4, n)]  # spacing ~5e-4
    face[:, 2] = np.round(face[:, 2] / 5e-4) * 5e-4  # layers 0 and +-5e-4 (~1 % each side)
    X = np.vstack([face, np.c_[rng.random((n, 2)) * 0.08, np.full(n, -0.02)]])
    X = np.unique(np.round(X / 1e-4) * 1e-4, axis=0)
    X -= X.mean(0)
    spacing = np.median(cKDTree(X).query(X, k=2)[0][:, 1])
    (s0, c0, _, p0, _), _ = _build(X)
    (s1, c1, _, p1, _), _ = _build(X, reach=10 * spacing)
    assert c0.max() > 300
    assert c1.max() < 50
    # within the surface nothing changes: the same edges up to a few spacings
    e0, e1 = _edges(adjacency.to_sets(s0, c0, p0)), _edges(adjacency.to_sets(s1, c1, p1))
    assert e1 <= e0

    def short(E):
        return {e for e in E if np.linalg.norm(X[e[0]] - X[e[1]]) < 3 * spacing}
    assert short(e1) == short(e0)
    # the guard points that end the far cells for Qhull change no edge within reach, and the
    # candidates no longer hold the far ones
    plain, _ = voronoi.candidate_edges(X)
    guarded, _ = voronoi.candidate_edges(X, 10 * spacing)
    most, most_guarded = np.bincount(plain.ravel()).max(), np.bincount(guarded.ravel()).max()
    assert most > 300 and most_guarded < 0.4 * most
    D = voronoi.scale_of(X)
    s, c, _, p, _ = adjacency.from_edges(len(X), plain, slack=0)
    ref = voronoi.filter_candidates(X, s, c, p, voronoi.BOX_FACTOR * D, voronoi.TOL_FACTOR * D,
                                    10 * spacing)
    assert e1 == {tuple(e) for e in ref.tolist()}
    G = voronoi.guard_points(X, 10 * spacing)
    assert len(G) > 0 and cKDTree(X).query(G)[0].min() > 20 * spacing


def _remove_sequence(X, victims, reach=np.inf):
    D = voronoi.scale_of(X)
    (start, cnt, cap, pool, meta), _ = _build(X, scale=D, reach=reach)
    size = 4096
    link = np.empty(size, np.int64)
    cand = np.empty(size, np.int64)
    bufs = np.empty((4, size + 5))
    lbufs = np.empty((2, size + 5), np.int64)
    frame = np.empty((3, 3))
    mark = np.full(len(X), -1, np.int64)
    for p in victims:
        former = pool[start[p]:start[p] + cnt[p]].copy()
        pool = adjacency.with_room(pool, meta, voronoi.removal_room(start, cnt, pool, p))
        k = voronoi.remove_point(X, p, start, cnt, cap, pool, meta, voronoi.BOX_FACTOR * D,
                                 voronoi.TOL_FACTOR * D, reach, link, cand, bufs, lbufs, frame,
                                 mark)
        assert k == len(former)
        # link[:k]: the former neighbours, nearest to p first (ties by index)
        d2 = ((X[link[:k]] - X[p]) ** 2).sum(axis=1)
        assert sorted(link[:k].tolist()) == sorted(former.tolist())
        assert link[:k].tolist() == [int(q) for _, q in sorted(zip(d2, link[:k]))]
    alive = np.ones(len(X), bool)
    alive[victims] = False
    maintained = adjacency.to_sets(start, cnt, pool, alive)
    keep = np.flatnonzero(alive)
    (s2, c2, _, p2, _), _ = _build(X[keep], scale=D, reach=reach)
    fresh = adjacency.to_sets(s2, c2, p2)
    fresh_global = [set()] * len(X)
    fresh_global = [set() for _ in range(len(X))]
    for i, s in enumerate(fresh):
        fresh_global[keep[i]] = {int(keep[j]) for j in s}
    return maintained, fresh_global


def _candidates(kind, n, side, rng, reach):
    """A centred cloud (``n`` points in a cube or near a sphere, or a ``side``³ grid with 20 %
    missing, full of exact ties), its reach in model units (given in spacings), the facet
    tolerances, and the unfiltered candidate lists."""
    if kind == "cube":
        X = rng.random((n, 3))
    elif kind == "sphere":
        X = _sphere(rng, n)
    else:
        X = np.stack(np.meshgrid(*[np.arange(float(side))] * 3, indexing="ij"), -1)
        X = X.reshape(-1, 3)
        X = X[rng.random(len(X)) < 0.8] * 0.001 + 1000.0
    X = X - X.mean(0)
    if np.isfinite(reach):
        reach *= np.median(cKDTree(X).query(X, k=2)[0][:, 1])
    D = voronoi.scale_of(X)
    edges, _ = voronoi.candidate_edges(X, reach)
    lists = adjacency.from_edges(len(X), edges, slack=0)
    return X, reach, voronoi.BOX_FACTOR * D, voronoi.TOL_FACTOR * D, edges, lists


@pytest.mark.parametrize("reach", [np.inf, 3.0])
@pytest.mark.parametrize("kind", ["cube", "sphere", "grid"])
def test_facet_witness_accepts_only_positive_facets(kind, reach):
    """The cheap witness (midpoint, one round of projections) never accepts a pair the exact
    clipping rejects, and the filter gives the clipping's edges. The grid is full of exact
    ties (four co-circular points per cell face: midpoints on a constraint, degenerate facets
    the clipping drops)."""
    rng = np.random.default_rng(7)
    X, reach, half, tol, edges, (start, cnt, cap, pool, meta) = _candidates(kind, 600, 8, rng,
                                                                            reach)
    size = cnt.max() + 5  # clipping scratch, as filter_candidates sizes it
    bufs, lbufs, frame = np.empty((4, size)), np.empty((2, size), np.int64), np.empty((3, 3))
    clipped, witnessed = set(), set()
    for a in range(len(X)):
        cand = pool[start[a]:start[a] + cnt[a]]
        for b in cand[cand > a]:
            if voronoi.facet_positive(X, a, b, cand, cnt[a], half, tol, reach, bufs[0],
                                      bufs[1], lbufs[0], bufs[2], bufs[3], lbufs[1], frame[0],
                                      frame[1], -1):
                clipped.add((a, int(b)))
            if voronoi.facet_witness(X, a, b, cand, cnt[a], half, tol, reach):
                witnessed.add((a, int(b)))
    assert witnessed <= clipped
    assert len(witnessed) > 0.3 * len(clipped)  # it does the work it is there for
    got = {tuple(e) for e in voronoi.filter_candidates(X, start, cnt, pool, half, tol,
                                                        reach).tolist()}
    assert got == clipped
    if kind == "grid":  # the ties are there: the clipping drops part of the candidates
        assert len(clipped) < 0.9 * len(edges)


@pytest.mark.parametrize("reach", [np.inf, 3.0])
@pytest.mark.parametrize("kind", ["cube", "sphere", "grid"])
def test_polygon_witness_changes_no_answer(kind, reach, monkeypatch):
    """facet_positive returns early when the partly clipped polygon's vertex mean lies well
    inside every constraint; the answer is the one the clipping alone gives (its pure-Python
    version run with the shortcut off), with and without the ``inside`` cut of the removal
    loop, on generic points and on a grid full of exact ties; and the shortcut does decide
    some of them."""
    rng = np.random.default_rng(11)
    X, reach, half, tol, _, (start, cnt, cap, pool, meta) = _candidates(kind, 300, 7, rng, reach)
    # as the removal of p tests a pair (a, b) of its former neighbours, the facet cut to p's
    # old cell; and the same pair with no cut (no tries then). The constraints are p's list
    # (all the removal uses now) and a's, without p: the longer lists give the tries, which
    # come every CENTROID_AFTER constraints, more chances to prove a facet.
    size = 2 * cnt.max() + 5
    bufs, lbufs, frame = np.empty((4, size)), np.empty((2, size), np.int64), np.empty((3, 3))
    args = []
    for p in range(0, len(X), 3):
        link = pool[start[p]:start[p] + cnt[p]]
        for a in link[:6]:
            own = pool[start[a]:start[a] + cnt[a]]
            cons = np.concatenate([link, own[~np.isin(own, link)]])
            cons = cons[cons != p]
            for b in link[link > a][:3]:
                args += [(int(a), int(b), cons, int(p)), (int(a), int(b), cons, -1)]
    fast = [voronoi.facet_positive(X, a, b, c, len(c), half, tol, reach, bufs[0], bufs[1],
                                   lbufs[0], bufs[2], bufs[3], lbufs[1], frame[0], frame[1],
                                   i)
            for a, b, c, i in args]

    def py_run():
        return [voronoi.facet_positive.py_func(X, a, b, c, len(c), half, tol, reach, bufs[0],
                                               bufs[1], lbufs[0], bufs[2], bufs[3], lbufs[1],
                                               frame[0], frame[1], i)
                for a, b, c, i in args]

    # the shortcut does the work it is there for: some tries prove a facet early
    proved = []
    deep_inside = voronoi._deep_inside
    monkeypatch.setattr(voronoi, "_deep_inside",
                        lambda *x: proved.append(deep_inside(*x)) or proved[-1])
    assert py_run() == fast
    assert sum(proved) > 0.05 * len(args)
    monkeypatch.setattr(voronoi, "CENTROID_AFTER", 10**9)
    slow = py_run()
    assert fast == slow
    assert 0.2 * len(args) < sum(slow) < 0.9 * len(args)


def test_polygon_witness_keeps_four_tol_from_every_constraint():
    """The witness check asks for 4 tol between the point and each bisector (the room a
    3 tol disc needs once each half-space is shrunk by tol), for the other points and for the
    removed point's cell alike. Exact ties rarely get that close to a try, so the margin is
    checked here directly: a at 0, b skipped, s whose bisector is x = 1, inside whose
    bisector is x = -1."""
    X = np.array([[0.0, 0, 0], [0, 0, 5], [2, 0, 0], [-2, 0, 0]])
    tol = 1e-3
    cand = np.array([1, 2])
    for d, ok in ((4.04 * tol, True), (3.96 * tol, False), (-tol, False)):
        assert voronoi._beyond_by(X, 0, 1, cand, 0, 2, 1.0 - d, 0.2, 0.0, tol) == ok
        assert voronoi._deep_inside(X, 0, 1, cand[:1], 0, 1, 3, -1.0 - d, 0.2, 0.0, tol) == ok


@pytest.mark.parametrize("reach", [np.inf, 4.0])
@pytest.mark.parametrize("kind", ["cube", "sphere", "plate", "quantised"])
def test_maintenance_equals_rebuild(kind, reach):
    rng = np.random.default_rng(4)
    if kind == "cube":
        X = rng.random((800, 3))
    elif kind == "sphere":
        X = _sphere(rng, 800)
    elif kind == "plate":
        X = np.c_[rng.random((800, 2)), np.zeros(800)]
    else:  # LAS-like: integers times 0.001, many exact co-spherical configurations
        X = np.round(_sphere(rng, 800, noise=0.0) * 8) * 0.001 + 1000.0
        X = np.unique(X, axis=0)
    X = X - X.mean(0)
    victims = rng.choice(len(X), len(X) * 2 // 3, replace=False)
    if np.isfinite(reach):  # in spacings: gaps grow past twice the reach as points go
        reach *= np.median(cKDTree(X).query(X, k=2)[0][:, 1])
    maintained, fresh = _remove_sequence(X, victims, reach)
    diffs = [i for i in range(len(X)) if maintained[i] != fresh[i]]
    assert diffs == []


@pytest.mark.parametrize("dtype", [np.int64, np.int32])  # int32: Qhull's and ours as built
@pytest.mark.parametrize("shape", [(400, 3), (300, 2), (5, 3)])
def test_simplex_edges_equal_unique_of_all_simplex_edges(shape, dtype):
    """The one-pass edge extraction gives exactly the sorted unique edges np.unique gives."""
    from scipy.spatial import Delaunay
    X = np.random.default_rng(1).random(shape)
    S = Delaunay(X).simplices.astype(dtype)
    d = S.shape[1]
    pairs = np.concatenate([np.sort(S[:, [i, j]], axis=1) for i in range(d)
                            for j in range(i + 1, d)])
    assert np.array_equal(voronoi._simplex_edges(S), np.unique(pairs, axis=0))
    assert voronoi._simplex_edges(np.empty((0, 4), np.int64)).shape == (0, 2)
    want = np.unique(pairs, axis=0)
    for n in (shape[0] - 1, shape[0] // 2):  # the points from n on are guards: left out
        assert np.array_equal(voronoi._simplex_edges(S, n), want[want[:, 1] < n])


def test_from_edges_sorted_fast_path_equals_general_path():
    """Sorted upper edges take a linear-time path; it must build exactly the same lists."""
    rng = np.random.default_rng(2)
    n = 500
    a, b = rng.integers(0, n, 4000), rng.integers(0, n, 4000)
    keep = a != b
    E = np.unique(np.stack([np.minimum(a[keep], b[keep]), np.maximum(a[keep], b[keep])], 1),
                  axis=0)
    for slack in (0, 8):
        fast = adjacency.from_edges(n, E, slack=slack)
        general = adjacency.from_edges(n, E[::-1, ::-1], slack=slack)  # unsorted: lexsort path
        for x, y in zip(fast, general):
            assert x.dtype == y.dtype and np.array_equal(x, y)


@pytest.mark.parametrize("cell", [1.0, 1.7])
def test_far_from_points_matches_a_kd_tree(cell):
    """The guards' grid check keeps exactly the queries with no point closer than the radius
    (cells of side ``cell`` x the radius), as a kd-tree query says."""
    rng = np.random.default_rng(11)
    X = rng.random((3000, 3)) * [1.0, 1.0, 0.05]  # a slab: most of the box empty
    r = 0.04
    G = rng.uniform(-0.2, 1.2, (4000, 3))
    h = cell * r * (1.0 + 1e-6)
    lo = G.min(axis=0) - h
    dims = np.ceil((G.max(axis=0) - lo) / h).astype(np.int64) + 2
    far = voronoi.far_from_points(X, G, lo, h, dims, r * r)
    d = cKDTree(X).query(G)[0]
    assert 0 < far.sum() < len(G)
    np.testing.assert_array_equal(far, d >= r)
