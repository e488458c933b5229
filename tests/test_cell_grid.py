"""Cell-grid searches (core/cell_grid.py) are exact, ties decided by a key, bit for bit as
brute force; the refinement built on them equals the brute-force version."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tiledsimplify.core import cell_grid
from tiledsimplify.core.heap import coordinate_hash
from tiledsimplify.core.refine import refine_coverage

import naive


def _clouds():
    rng = np.random.default_rng(0)
    yield "random", rng.random((4000, 3))
    xy = rng.random((4000, 2))
    yield "wavy", np.c_[xy, 0.2 * np.sin(3 * xy[:, 0])]
    # a quantised scan far from the origin: exact and near ties everywhere
    g = np.stack(np.meshgrid(np.arange(40), np.arange(40), np.arange(3)), -1).reshape(-1, 3)
    yield "lattice", g * 0.001 + [612345.678, 4.2e6, 120.0]
    yield "quantised", np.round(rng.random((4000, 3)) * 25) / 25


def _expected(X, ids, tie, order, k, bound):
    """Brute force: nearest and lists of ``X[order]`` among ``X[ids]``, as positions."""
    o, s = naive.exact_order(X[order], X[ids], tie, k)
    inside = s[:, :k] < bound * bound
    return np.sqrt(s[:, 0]), o[:, 0], [o[t, :k][inside[t]].tolist() for t in range(len(o))], \
        [np.sqrt(s[t, :k][inside[t]]).tolist() for t in range(len(o))]


@pytest.mark.parametrize("name,X", list(_clouds()), ids=lambda v: v if isinstance(v, str) else "")
@pytest.mark.parametrize("ties", ["hash", "constant"])
def test_nearest_is_exact_with_ties_by_key(name, X, ties):
    rng = np.random.default_rng(1)
    ids = np.sort(rng.choice(len(X), len(X) // 5, replace=False))
    # a coordinate hash, or one key for all: then equal distances go by position
    tie = (coordinate_hash(X[ids]) if ties == "hash" else np.zeros(ids.size, dtype=np.uint64))
    reach = cKDTree(X[ids]).query(X)[0].max()
    grid = cell_grid.CellGrid(X, reach * 1.01)
    start_c, slot, xyz = grid.members(X, ids)
    order = grid.pt  # queries cell by cell, as the refinement asks them
    n_ties = 0
    for k, bound in ((16, 0.9 * reach), (4, 0.6 * reach), (16, 0.2 * reach), (1, 0.5 * reach),
                     (16, 1.1 * reach)):
        d, i, amb1, start, idx, dist, amb = cell_grid.nearest(
            X[order], grid.cell_of[order], grid.near_start, grid.near, start_c, slot, xyz,
            grid.reach ** 2, k, bound, tie)
        rd, ri, r_idx, r_dist = _expected(X, ids, tie, order, k, bound)
        assert not amb1.any()  # every nearest lies within the cells' reach here
        np.testing.assert_array_equal(d, rd)  # bit for bit
        np.testing.assert_array_equal(i, ri)
        if bound > grid.reach:
            assert amb.all() and start[-1] == 0  # beyond the cells: nothing is claimed
            continue
        assert not amb.any()
        for t in range(len(order)):
            assert idx[start[t]:start[t + 1]].tolist() == r_idx[t]
            assert dist[start[t]:start[t + 1]].tolist() == r_dist[t]  # bit for bit
            n_ties += int((np.diff(r_dist[t]) == 0).sum())
        # the exact search (kd-tree superset) gives the same answers
        e_d1, e_i1, e_start, e_idx, e_dist = cell_grid.exact_search(
            np.ascontiguousarray(X[ids]), tie, X[order], k, bound)
        np.testing.assert_array_equal(e_d1, rd)
        np.testing.assert_array_equal(e_i1, ri)
        used = start[-1]  # the cells' arrays have room for k per query
        assert e_start.tolist() == start.tolist() and e_idx.tolist() == idx[:used].tolist()
        assert e_dist.tolist() == dist[:used].tolist()
    if name in ("random", "wavy"):
        assert n_ties == 0
    else:
        assert n_ties > 0  # ties exist here, and the key decided them


@pytest.mark.parametrize("name,X", list(_clouds()), ids=lambda v: v if isinstance(v, str) else "")
@pytest.mark.parametrize("ties", ["hash", "constant"])
def test_the_exact_search_gives_one_answer_by_every_path(name, X, ties, monkeypatch):
    # few queries (compiled, every candidate), few pairs (numpy), many (a kd-tree's superset)
    rng = np.random.default_rng(2)
    ids = np.sort(rng.choice(len(X), len(X) // 5, replace=False))
    tie = (coordinate_hash(X[ids]) if ties == "hash" else np.zeros(ids.size, dtype=np.uint64))
    order = rng.choice(len(X), 150, replace=False)
    reach = cKDTree(X[ids]).query(X[order])[0].max()
    C = np.ascontiguousarray(X[ids])
    for k, bound in ((16, 0.9 * reach), (4, 2.0 * reach), (1, 0.5 * reach), (16, 0.0)):
        rd, ri, r_idx, r_dist = _expected(X, ids, tie, order, k, bound)
        for few, pairs in ((cell_grid.FEW_QUERIES, cell_grid.BRUTE_PAIRS), (0, 1 << 30),
                           (0, 0)):
            monkeypatch.setattr(cell_grid, "FEW_QUERIES", few)
            monkeypatch.setattr(cell_grid, "BRUTE_PAIRS", pairs)
            d1, i1, start, idx, dist = cell_grid.exact_search(C, tie, X[order], k, bound)
            np.testing.assert_array_equal(d1, rd)  # bit for bit
            np.testing.assert_array_equal(i1, ri)
            assert [idx[start[t]:start[t + 1]].tolist() for t in range(len(order))] == r_idx
            assert [dist[start[t]:start[t + 1]].tolist() for t in range(len(order))] == r_dist


def test_nearest_beyond_the_cells_is_left_to_the_caller():
    X = np.array([[0.0, 0, 0], [0.1, 0, 0], [5.0, 0, 0]])
    ids = np.array([0])
    grid = cell_grid.CellGrid(X, 1.0)
    start_c, slot, xyz = grid.members(X, ids)
    d, i, amb1, start, idx, dist, amb = cell_grid.nearest(
        X, grid.cell_of, grid.near_start, grid.near, start_c, slot, xyz, grid.reach ** 2, 2,
        0.5, np.zeros(1, dtype=np.uint64))
    assert amb1.tolist() == [False, False, True]  # point 2's nearest is 5 away: not seen
    assert i[:2].tolist() == [0, 0] and d[1] == 0.1
    assert start.tolist() == [0, 1, 2, 2] and not amb.any()
    # k = 0: the nearest alone, no lists
    d, i, amb1, start, idx, dist, amb = cell_grid.nearest(
        X, grid.cell_of, grid.near_start, grid.near, start_c, slot, xyz, grid.reach ** 2, 0,
        0.5, np.zeros(1, dtype=np.uint64))
    assert i[:2].tolist() == [0, 0] and amb1.tolist() == [False, False, True]
    assert start.tolist() == [0, 0, 0, 0]


def test_cells_hold_every_pair_within_reach():
    X = np.random.default_rng(2).random((3000, 3)) * [10, 1, 0.1] + [1e5, 0, 0]
    grid = cell_grid.CellGrid(X, 0.05)
    pairs = cKDTree(X).query_pairs(grid.reach, output_type="ndarray")
    nbr = {(c, v) for c in range(grid.n_cells)
           for v in grid.near[grid.near_start[c]:grid.near_start[c + 1]]}
    assert all((grid.cell_of[a], grid.cell_of[b]) in nbr for a, b in pairs)
    assert np.array_equal(np.sort(grid.pt), np.arange(len(X)))


def _keeps(X, seed, frac=0.15):
    rng = np.random.default_rng(seed)
    keep = rng.random(len(X)) < frac
    keep[X[:, 0] < X[:, 0].min() + 0.3 * np.ptp(X[:, 0])] &= rng.random(len(X))[
        X[:, 0] < X[:, 0].min() + 0.3 * np.ptp(X[:, 0])] < 0.3  # a sparse side: big gaps
    fixed = keep & (rng.random(len(X)) < 0.2)
    return keep, fixed


@pytest.mark.parametrize("name,X", list(_clouds()), ids=lambda v: v if isinstance(v, str) else "")
def test_refine_coverage_equals_brute_force(name, X):
    keep, fixed = _keeps(X, 0)
    tie = coordinate_hash(X)
    got, info = refine_coverage(X, keep, fixed, tie=tie)
    expect, expect_info = naive.refine_coverage(X, keep, fixed, tie=tie)
    assert np.array_equal(got, expect)
    assert info == expect_info
    assert info["swaps"] > 0


@pytest.mark.parametrize("name,X", list(_clouds()), ids=lambda v: v if isinstance(v, str) else "")
def test_refine_coverage_of_a_tile_equals_brute_force(name, X):
    # a tile's view: the right part belongs to another tile, its removed points are watched
    keep, fixed = _keeps(X, 1)
    other = X[:, 0] > np.quantile(X[:, 0], 0.7)
    addable = ~other
    for watch in (None, other):
        got, info = refine_coverage(X, keep, fixed | other, addable=addable, watch=watch)
        expect, expect_info = naive.refine_coverage(X, keep, fixed | other, addable=addable,
                                                    watch=watch)
        assert np.array_equal(got, expect)
        assert info == expect_info
        assert info["swaps"] > 0


def _edges(X):
    """A band of flags across the cloud (as sharp-edge flags lie along a line) and a cover
    radius below the kept points' gaps."""
    y = X[:, 1]
    band = np.abs(y - np.median(y)) < 0.03 * np.ptp(y)
    return band, 2.5 * float(np.median(cKDTree(X).query(X, 2)[0][:, 1]))


@pytest.mark.parametrize("name,X", list(_clouds()), ids=lambda v: v if isinstance(v, str) else "")
def test_refine_coverage_with_an_edge_cover_equals_brute_force(name, X):
    keep, fixed = _keeps(X, 3)
    edges, radius = _edges(X)
    other = X[:, 0] > np.quantile(X[:, 0], 0.7)
    for kw in ({}, {"addable": ~other, "watch": other}):
        f = fixed | other if kw else fixed
        got, info = refine_coverage(X, keep, f, edges=edges, edge_radius=radius, **kw)
        expect, expect_info = naive.refine_coverage(X, keep, f, edges=edges,
                                                    edge_radius=radius, **kw)
        assert np.array_equal(got, expect)
        assert info == expect_info
        assert info["edge_swaps"] > 0


def test_refine_coverage_with_coarse_cells_asks_the_exact_search_and_equals_brute_force(monkeypatch):
    from tiledsimplify.core import refine
    X = list(_clouds())[3][1]
    keep, fixed = _keeps(X, 2)
    expect = naive.refine_coverage(X, keep, fixed)
    monkeypatch.setattr(refine, "MAX_LOAD", 0.0)  # every search by the exact search
    got = refine_coverage(X, keep, fixed)
    assert np.array_equal(got[0], expect[0]) and got[1] == expect[1]


def test_load_counts_the_members_around_each_query():
    X = np.array([[0.0, 0, 0], [0.5, 0, 0], [3.0, 0, 0], [3.5, 0, 0], [9.0, 0, 0]])
    grid = cell_grid.CellGrid(X, 1.0)
    # from points 0 and 1 the members 0, 1 are around; from 4 none (members 0, 1, 2)
    assert grid.load(np.array([0, 1, 2]), np.array([0, 1, 4])) == pytest.approx(4 / 3)


@pytest.mark.parametrize("seed", range(4))
def test_refine_coverage_on_small_odd_clouds_equals_brute_force(seed):
    # tiny, flat, collinear far from the origin, coarse lattices; k down to 1; tiles
    rng = np.random.default_rng(seed)
    for trial in range(12):
        n = int(rng.integers(2, 200))
        X = [rng.random((n, 3)),
             np.round(rng.random((n, 3)) * 6) / 6 * [1, 1, 0],
             np.c_[rng.random(n), np.zeros(n), np.zeros(n)] + [5e5, 4e6, 10],
             np.round(rng.random((n, 3)) * 10) / 10][trial % 4]
        X = np.unique(X, axis=0)
        keep = rng.random(len(X)) < rng.uniform(0.05, 0.6)
        fixed = keep & (rng.random(len(X)) < 0.3)
        kw = {"k": int(rng.choice([1, 2, 3, 16]))}
        if trial % 2 == 0:
            kw.update(edges=rng.random(len(X)) < 0.2,
                      edge_radius=float(rng.uniform(0.05, 0.3)))
        if trial % 3 == 0:
            other = X[:, 0] > np.quantile(X[:, 0], 0.6)
            fixed = fixed | other
            kw.update(addable=~other, watch=other if trial % 2 else None)
        got = refine_coverage(X, keep, fixed, **kw)
        expect = naive.refine_coverage(X, keep, fixed, **kw)
        assert np.array_equal(got[0], expect[0]) and got[1] == expect[1]


def _nearest_clouds():
    yield from _clouds()
    rng = np.random.default_rng(1)
    # a dense clump and sparse far points: the sample's guess is far too small for the latter
    yield "clumped", np.unique(np.r_[rng.random((3000, 3)) * 1e-3, rng.random((200, 3)) * 50],
                               axis=0)
    yield "line", np.c_[np.sort(rng.random(500)), np.zeros(500), np.zeros(500)] + [5e5, 4e6, 1]
    yield "two", np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]])


@pytest.mark.parametrize("name,X", list(_nearest_clouds()),
                         ids=lambda v: v if isinstance(v, str) else "")
def test_nearest_other_equals_the_kd_tree_bit_for_bit(name, X):
    X = np.unique(X, axis=0)
    want = cKDTree(X).query(X, k=2)[0][:, 1]
    for sample in (16, 4096):
        np.testing.assert_array_equal(cell_grid.nearest_other(X, sample=sample), want)


def test_nearest_other_leaves_overfull_cells_to_the_kd_tree(monkeypatch):
    """A sample that misses a dense clump guesses cells far too large for it: the kd-tree
    answers instead of a cell search over the whole clump."""
    rng = np.random.default_rng(2)
    X = np.unique(np.r_[rng.random((2000, 3)) * 1e-3, rng.random((2000, 2)) @ np.eye(2, 3)],
                  axis=0)
    want = cKDTree(X).query(X, k=2)[0][:, 1]
    sample = np.flatnonzero(~(X < 1e-3).all(axis=1))[:64]  # none of the clump
    calls = []
    real_grid = cell_grid.CellGrid

    def grid(X, h):
        calls.append(real_grid(X, h))
        return calls[-1]

    def no_cells(*args):
        raise AssertionError("searched the overfull cells")

    class Sample:
        def choice(self, n, m, replace):
            return sample

    monkeypatch.setattr(cell_grid, "CellGrid", grid)
    monkeypatch.setattr(cell_grid, "_nearest_other", no_cells)
    monkeypatch.setattr(cell_grid.np.random, "default_rng", lambda seed: Sample())
    np.testing.assert_array_equal(cell_grid.nearest_other(X, sample=64), want)
    everyone = np.arange(len(X))
    assert calls[0].load(everyone, everyone) > cell_grid.NEAREST_MAX_LOAD


def test_load_counts_the_members_of_the_cells_around_the_queries():
    rng = np.random.default_rng(3)
    X = rng.random((3000, 3)) * [1, 1, 0.1]
    grid = cell_grid.CellGrid(X, 0.07)
    q = rng.choice(len(X), 200, replace=False)
    members = np.flatnonzero(rng.random(len(X)) < 0.3)

    def around(i, among):
        cells = grid.near[grid.near_start[grid.cell_of[i]]:grid.near_start[grid.cell_of[i] + 1]]
        return np.isin(grid.cell_of[among], cells).sum()

    everyone = np.arange(len(X))
    for qs in (q, q[:5]):  # queries in most cells (one pass over all), in a few (their own)
        want = [around(i, everyone) for i in qs]
        assert grid.load(None, qs) == pytest.approx(np.mean(want))
        assert grid.load(everyone, qs) == pytest.approx(np.mean(want))
        assert grid.load(members, qs) == pytest.approx(np.mean([around(i, members) for i in qs]))
    assert grid.load(None, np.zeros(0, dtype=np.int64)) == 0.0


@pytest.mark.parametrize("name,X", list(_nearest_clouds()),
                         ids=lambda v: v if isinstance(v, str) else "")
def test_distances_to_members_equal_the_kd_tree_bit_for_bit(name, X):
    X = np.unique(X, axis=0)
    rng = np.random.default_rng(4)
    n = len(X)
    for share in (0.5, 0.2, 0.02):
        members = np.flatnonzero(rng.random(n) < share)
        if not members.size:
            members = np.array([0])
        queries = np.flatnonzero(rng.random(n) < 0.8)
        want = cKDTree(X[members]).query(X[queries])[0]
        for sample in (16, 4096):
            got = cell_grid.distances_to(X, members, queries, sample=sample)
            np.testing.assert_array_equal(got, want)


def test_distances_to_members_beyond_the_cells_and_in_overfull_cells(monkeypatch):
    """Members in one corner: most queries' nearest lies beyond the cells around them (the
    kd-tree answers those); a sample that guesses cells far too large leaves all to it."""
    rng = np.random.default_rng(5)
    X = np.unique(rng.random((20000, 2)) @ np.eye(2, 3), axis=0)
    members = np.flatnonzero((X[:, :2] < 0.3).all(axis=1))
    queries = np.arange(len(X))
    want = cKDTree(X[members]).query(X)[0]
    asked = []
    real = cell_grid.nearest

    def nearest(*args):
        got = real(*args)
        asked.append(int(got[2].sum()))  # queries whose nearest lies beyond their cells
        return got

    monkeypatch.setattr(cell_grid, "nearest", nearest)
    np.testing.assert_array_equal(cell_grid.distances_to(X, members, queries), want)
    assert asked and asked[0] > len(X) // 2
    asked.clear()
    np.testing.assert_array_equal(cell_grid.distances_to(X, members, queries, factor=400.0),
                                  want)
    assert not asked  # the cells would hold every member: the kd-tree alone
