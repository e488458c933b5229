"""Voronoi neighbours: construction against Qhull and an LP, maintenance against rebuilding."""

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from tiledsimplify.core import adjacency, voronoi

import naive


def _edges(lists):
    return {(i, j) for i, s in enumerate(lists) for j in s if i < j}


def _build(X, scale=None):
    (start, cnt, cap, pool, meta), how = voronoi.voronoi_neighbours(X, scale=scale)
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


def test_facet_rule_equals_linear_programming():
    rng = np.random.default_rng(1)
    X = rng.random((60, 3))
    X -= 0.5
    D = voronoi.scale_of(X)
    (start, cnt, cap, pool, meta), _ = _build(X)
    got = _edges(adjacency.to_sets(start, cnt, pool))
    ref = naive.voronoi_edges(X, voronoi.BOX_FACTOR * D, voronoi.TOL_FACTOR * D,
                              candidates=sorted(naive.delaunay_edges(X)))
    assert got == ref


def test_grid_keeps_only_axis_neighbours():
    # quantised coordinates: every cube of 8 grid points is co-spherical; the diagonals'
    # facets are degenerate and must not count, whatever Qhull's tie-breaking
    g = np.arange(6) * 0.001
    X = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3) + 100.0
    (start, cnt, cap, pool, meta), _ = _build(X)
    got = _edges(adjacency.to_sets(start, cnt, pool))
    d = np.linalg.norm(X[[a for a, _ in got]] - X[[b for _, b in got]], axis=1)
    np.testing.assert_allclose(d, 0.001, rtol=1e-9)
    assert len(got) == 3 * 5 * 36


def test_coplanar_and_collinear_and_tiny_inputs():
    rng = np.random.default_rng(3)
    P = np.c_[rng.random((300, 2)), np.zeros(300)] @ np.linalg.qr(rng.normal(size=(3, 3)))[0]
    (start, cnt, cap, pool, meta), how = _build(P)
    assert how.startswith("plane")
    got = _edges(adjacency.to_sets(start, cnt, pool))
    from scipy.spatial import Delaunay
    Q = P - P.mean(0)
    _, _, vt = np.linalg.svd(Q)
    tri = Delaunay(Q @ vt[:2].T)
    ref = {tuple(sorted((int(s[i]), int(s[j])))) for s in tri.simplices
           for i in range(3) for j in range(i + 1, 3)}
    hull = set(ConvexHull(Q @ vt[:2].T).vertices.tolist())
    assert got <= ref
    assert {e for e in ref - got if not (e[0] in hull and e[1] in hull)} == set()

    L = np.outer(rng.permutation(50), [1.0, 2.0, 3.0])
    (start, cnt, cap, pool, meta), how = _build(L)
    assert how == "line"
    lists = adjacency.to_sets(start, cnt, pool)
    order = np.argsort(L[:, 0])
    for a, b in zip(order[:-1], order[1:]):
        assert b in lists[a]
    assert sum(len(s) for s in lists) == 2 * 49

    for n in range(0, 6):
        X = rng.random((n, 3))
        (start, cnt, cap, pool, meta), _ = _build(X)
        if n >= 2:
            ref = naive.voronoi_edges(X, voronoi.BOX_FACTOR * voronoi.scale_of(X),
                                      voronoi.TOL_FACTOR * voronoi.scale_of(X))
            assert _edges(adjacency.to_sets(start, cnt, pool)) == ref


def _remove_sequence(X, victims):
    D = voronoi.scale_of(X)
    (start, cnt, cap, pool, meta), _ = _build(X, scale=D)
    size = 4096
    link = np.empty(size, np.int64)
    cand = np.empty(size, np.int64)
    bufs = np.empty((4, size + 5))
    lbufs = np.empty((2, size + 5), np.int64)
    frame = np.empty((3, 3))
    for p in victims:
        k, pool = voronoi.remove_point(X, p, start, cnt, cap, pool, meta,
                                       voronoi.BOX_FACTOR * D, voronoi.TOL_FACTOR * D,
                                       link, cand, bufs, lbufs, frame)
    alive = np.ones(len(X), bool)
    alive[victims] = False
    maintained = adjacency.to_sets(start, cnt, pool, alive)
    keep = np.flatnonzero(alive)
    (s2, c2, _, p2, _), _ = _build(X[keep], scale=D)
    fresh = adjacency.to_sets(s2, c2, p2)
    fresh_global = [set()] * len(X)
    fresh_global = [set() for _ in range(len(X))]
    for i, s in enumerate(fresh):
        fresh_global[keep[i]] = {int(keep[j]) for j in s}
    return maintained, fresh_global


@pytest.mark.parametrize("kind", ["cube", "sphere", "plate", "quantised"])
def test_maintenance_equals_rebuild(kind):
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
    maintained, fresh = _remove_sequence(X, victims)
    diffs = [i for i in range(len(X)) if maintained[i] != fresh[i]]
    assert diffs == []


@pytest.mark.parametrize("shape", [(400, 3), (300, 2), (5, 3)])
def test_simplex_edges_equal_unique_of_all_simplex_edges(shape):
    """The one-pass edge extraction gives exactly the sorted unique edges np.unique gives."""
    from scipy.spatial import Delaunay
    X = np.random.default_rng(1).random(shape)
    S = Delaunay(X).simplices.astype(np.int64)
    d = S.shape[1]
    pairs = np.concatenate([np.sort(S[:, [i, j]], axis=1) for i in range(d)
                            for j in range(i + 1, d)])
    assert np.array_equal(voronoi._simplex_edges(S), np.unique(pairs, axis=0))
    assert voronoi._simplex_edges(np.empty((0, 4), np.int64)).shape == (0, 2)


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
