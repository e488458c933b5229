"""Cell-grid searches (core/cell_grid.py) give cKDTree's answers, bit for bit, or say they
cannot (ties); the refinement built on them equals the kd-tree version."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tiledsimplify.core import cell_grid
from tiledsimplify.core.heap import coordinate_hash
from tiledsimplify.core.refine import lists_from_dense, refine_coverage

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


@pytest.mark.parametrize("name,X", list(_clouds()), ids=lambda v: v if isinstance(v, str) else "")
def test_nearest_equals_kdtree_where_unambiguous(name, X):
    rng = np.random.default_rng(1)
    ids = np.sort(rng.choice(len(X), len(X) // 5, replace=False))
    reach = cKDTree(X[ids]).query(X)[0].max()
    grid = cell_grid.CellGrid(X, reach * 1.01)
    start_c, slot, xyz = grid.members(X, ids)
    order = grid.pt  # queries cell by cell, as the refinement asks them
    tree = cKDTree(X[ids])
    rd, ri = tree.query(X[order])
    n_amb = 0
    for k, bound in ((16, 0.9 * reach), (4, 0.6 * reach), (16, 0.2 * reach), (16, 1.1 * reach)):
        d, i, amb1, start, idx, dist, amb = cell_grid.nearest(
            X[order], grid.cell_of[order], grid.near_start, grid.near, start_c, slot, xyz,
            grid.reach ** 2, k, bound)
        np.testing.assert_array_equal(d[~amb1], rd[~amb1])  # bit for bit
        np.testing.assert_array_equal(i[~amb1], ri[~amb1])
        r_start, r_idx, r_dist = lists_from_dense(
            *tree.query(X[order], k=k, distance_upper_bound=bound), ids.size)
        for t in np.flatnonzero(~amb):
            a, b = start[t], start[t + 1]
            ra, rb = r_start[t], r_start[t + 1]
            assert idx[a:b].tolist() == r_idx[ra:rb].tolist()
            assert dist[a:b].tolist() == r_dist[ra:rb].tolist()  # bit for bit
        assert (start[1:][amb] == start[:-1][amb]).all()  # flagged lists are left empty
        if bound > grid.reach:
            assert amb.all()  # beyond the cells: nothing is claimed
        else:
            n_amb += amb.sum() + amb1.sum()
            # an unflagged list has no two equal distances
            for t in np.flatnonzero(~amb):
                assert (np.diff(dist[start[t]:start[t + 1]]) > 0).all()
    if name in ("random", "wavy"):
        assert n_amb == 0
    else:
        assert n_amb > 0  # ties exist here and are flagged


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
def test_refine_coverage_equals_the_kdtree_version(name, X):
    keep, fixed = _keeps(X, 0)
    tie = coordinate_hash(X)
    got, info = refine_coverage(X, keep, fixed, tie=tie)
    expect, expect_info = naive.refine_coverage(X, keep, fixed, tie=tie)
    assert np.array_equal(got, expect)
    assert info == expect_info
    assert info["swaps"] > 0


@pytest.mark.parametrize("name,X", list(_clouds()), ids=lambda v: v if isinstance(v, str) else "")
def test_refine_coverage_of_a_tile_equals_the_kdtree_version(name, X):
    # a tile's view: the right part belongs to another tile, its removed points are watched
    # (on the quantised cloud one added point's ball is left to the kd-tree: rounding at its
    # edge could decide it)
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


def test_refine_coverage_with_coarse_cells_asks_the_kdtree_and_equals_it(monkeypatch):
    from tiledsimplify.core import refine
    X = list(_clouds())[3][1]
    keep, fixed = _keeps(X, 2)
    expect = naive.refine_coverage(X, keep, fixed)
    monkeypatch.setattr(refine, "MAX_LOAD", 0.0)  # every search by the kd-tree
    got = refine_coverage(X, keep, fixed)
    assert np.array_equal(got[0], expect[0]) and got[1] == expect[1]


def test_load_counts_the_members_around_each_query():
    X = np.array([[0.0, 0, 0], [0.5, 0, 0], [3.0, 0, 0], [3.5, 0, 0], [9.0, 0, 0]])
    grid = cell_grid.CellGrid(X, 1.0)
    # from points 0 and 1 the members 0, 1 are around; from 4 none (members 0, 1, 2)
    assert grid.load(np.array([0, 1, 2]), np.array([0, 1, 4])) == pytest.approx(4 / 3)


@pytest.mark.parametrize("seed", range(4))
def test_refine_coverage_on_small_odd_clouds_equals_the_kdtree_version(seed):
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
        if trial % 3 == 0:
            other = X[:, 0] > np.quantile(X[:, 0], 0.6)
            fixed = fixed | other
            kw.update(addable=~other, watch=other if trial % 2 else None)
        got = refine_coverage(X, keep, fixed, **kw)
        expect = naive.refine_coverage(X, keep, fixed, **kw)
        assert np.array_equal(got[0], expect[0]) and got[1] == expect[1]
