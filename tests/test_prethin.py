"""Pre-thinning (core/prethin.py): the disk sample against a naive twin, the subset's count,
and a thinned run against the greedy run on the subset alone."""

import naive
import numpy as np
import pytest

from tiledsimplify import SimplifyOptions, simplify_points
from tiledsimplify.core import prethin
from tiledsimplify.core.simplify import median_spacing, neighbourhoods
from tiledsimplify.core.voronoi import scale_of
from tiledsimplify.errors import InputError


def _plane(n, seed=0, noise=0.0):
    rng = np.random.default_rng(seed)
    X = np.c_[rng.random((n, 2)), noise * rng.standard_normal(n)]
    return X - 0.5 * (X.min(0) + X.max(0))


def _graph(X):
    st = neighbourhoods(X, scale_of(X), reach=12 * median_spacing(X))
    lists = [st.pool[st.start[i]:st.start[i] + st.cnt[i]].tolist() for i in range(len(X))]
    return st, lists


@pytest.mark.parametrize("r_spacings", [0.5, 1.5, 3.0])
def test_disk_sample_matches_naive(r_spacings):
    X = _plane(1500, seed=1)
    st, lists = _graph(X)
    rng = np.random.default_rng(2)
    fixed = rng.random(len(X)) < 0.05
    order = rng.permutation(len(X)).astype(np.int64)
    r = r_spacings * median_spacing(X)
    keep = np.zeros(len(X), dtype=bool)
    k = prethin.disk_sample(X, st.start, st.cnt, st.pool, fixed, order, r, keep,
                            np.empty(len(X), dtype=np.int64), np.empty(len(X), dtype=np.int64))
    want = naive.disk_sample(X, lists, fixed, order, r)
    assert np.array_equal(keep, want)
    assert k == want.sum()
    assert keep[fixed].all()
    # a sample: no two kept free points within r of each other along one graph edge
    free = keep & ~fixed
    for p in np.flatnonzero(free):
        for q in lists[p]:
            if free[q]:
                assert np.sum((X[q] - X[p]) ** 2) > r * r


def test_subset_count_and_fixed():
    X = _plane(6000, seed=3)
    st, _ = _graph(X)
    fixed = np.zeros(len(X), dtype=bool)
    fixed[::97] = True
    tie = np.random.default_rng(4).integers(0, 2**63, len(X)).astype(np.uint64)
    for goal in (600, 1500, 3000):
        mask = prethin.subset(X, st.start, st.cnt, st.pool, fixed, goal, median_spacing(X), tie)
        assert mask is not None and mask[fixed].all()
        assert abs(mask.sum() - goal) <= 0.1 * goal
    # nothing worth thinning: the goal is most of the cloud, or the fixed points fill it
    assert prethin.subset(X, st.start, st.cnt, st.pool, fixed, 5800, median_spacing(X),
                          tie) is None
    assert prethin.subset(X, st.start, st.cnt, st.pool, fixed, int(fixed.sum()),
                          median_spacing(X), tie) is None


@pytest.mark.parametrize("block", [500, 10**9])
def test_subset_draws_first_points_first_block_by_block(block, monkeypatch):
    """``first`` points come before the others in the sample's order, and are thinned like
    them; each group goes block by block (``BLOCK`` consecutive points), in the order of
    ``tie`` within a block: the same subset as one block ordered by a key whose top bit puts
    the first points first and whose next bits are the block."""
    X = _plane(6000, seed=10)
    st, _ = _graph(X)
    rng = np.random.default_rng(11)
    fixed = rng.random(len(X)) < 0.01
    first = ~fixed & (rng.random(len(X)) < 0.3)
    tie = rng.integers(0, 2**57, len(X)).astype(np.uint64)
    blocks = (np.arange(len(X)) // block).astype(np.uint64)  # at most 12: 5 bits
    key = (tie | (blocks << np.uint64(57))
           | (np.uint64(1) << np.uint64(62)) * (~first).astype(np.uint64))
    spacing = median_spacing(X)
    for goal in (900, 1500):
        monkeypatch.setattr(prethin, "BLOCK", block)
        got = prethin.subset(X, st.start, st.cnt, st.pool, fixed, goal, spacing, tie,
                             first=first)
        plain = prethin.subset(X, st.start, st.cnt, st.pool, fixed, goal, spacing, tie)
        monkeypatch.setattr(prethin, "BLOCK", 10**9)
        want = prethin.subset(X, st.start, st.cnt, st.pool, fixed, goal, spacing, key)
        assert np.array_equal(got, want)
        assert got[fixed].all() and 0 < got[first].sum() < first.sum()  # thinned too
        assert got[first].mean() > plain[first].mean()  # but they win their disks


def test_protected_points_are_thinned_boundary_points_are_not():
    """The points the refinement protects may be thinned (a noisy scan has many); the flags
    sure of being kept (here the whole band: it fits the share) never are."""
    X = _plane(8000, seed=12, noise=0.004)
    X[:, 2] += np.where(X[:, 0] > 0, X[:, 0], 0.0)  # a crease along x = 0
    res = simplify_points(X, 0.1)
    k = len(X) - res.stats["n_prethin_subset"]
    guarded = res.protected & ~res.band
    assert res.band.sum() > 0 and guarded.sum() > 0
    assert not res.band[res.order[:k]].any()
    assert guarded[res.order[:k]].any()


def test_thinned_run_is_the_greedy_on_the_subset():
    """The removal after thinning is exactly the greedy run on the subset (same spacing, same
    centre and scale: the corners are frozen so the subset keeps the bounding box), the thinned
    points first with importance 0. On a plane every normal is the same from the whole cloud
    as from the subset (the thinned run reads the whole cloud's)."""
    X = _plane(5000, seed=5)
    lo, hi = X.min(0), X.max(0)
    frozen = np.zeros(len(X), dtype=bool)
    for d in range(3):
        frozen[np.argmin(X[:, d])] = frozen[np.argmax(X[:, d])] = True
    spacing = median_spacing(X)
    opts = {"detect_boundary": False, "refine": False, "spacing": spacing, "progressive": False}
    res = simplify_points(X, 0.1, frozen=frozen, options=SimplifyOptions(prethin=3, **opts))
    k = len(X) - res.stats["n_prethin_subset"]
    assert 0 < k < len(X)
    thinned = res.order[:k]
    assert np.all(res.order_importance[:k] == 0)
    assert not frozen[thinned].any()
    sub = np.setdiff1d(np.arange(len(X)), thinned)
    assert np.allclose(X[sub].min(0), lo) and np.allclose(X[sub].max(0), hi)
    alone = simplify_points(X[sub], count=int(res.keep.sum()), frozen=frozen[sub],
                            options=SimplifyOptions(prethin=0, **opts))
    assert np.array_equal(res.order[k:], sub[alone.order])
    assert np.array_equal(res.order_importance[k:], alone.order_importance)
    assert np.array_equal(res.keep[sub], alone.keep)
    assert res.keep.sum() == 500


def test_prethin_keeps_flags_and_count():
    X = _plane(8000, seed=6, noise=0.001)
    X[:, 2] += np.where(X[:, 0] > 0, X[:, 0], 0.0)  # a crease along x = 0
    res = simplify_points(X, 0.1)
    off = simplify_points(X, 0.1, options=SimplifyOptions(prethin=0))
    assert "n_prethin_subset" in res.stats and "n_prethin_subset" not in off.stats
    assert res.keep.sum() == off.keep.sum() == 800
    assert np.array_equal(res.boundary, off.boundary)  # flags from the whole cloud
    assert np.array_equal(res.band, off.band)
    assert res.band.sum() > 0 and res.keep[res.band].all()
    assert np.allclose(res.normals, off.normals)


def test_prethin_off_when_the_subset_would_be_most_of_the_cloud():
    X = _plane(3000, seed=7)
    a = simplify_points(X, 0.3)  # 2 x 0.3 > prethin.MAX_SHARE: it would not pay
    b = simplify_points(X, 0.3, options=SimplifyOptions(prethin=0))
    assert "n_prethin_subset" not in a.stats
    assert np.array_equal(a.order, b.order)


@pytest.mark.parametrize("bad", [0.5, -1.0, float("nan")])
def test_prethin_option_checked(bad):
    with pytest.raises(InputError, match="prethin"):
        SimplifyOptions(prethin=bad)


def test_prethin_with_a_guard_starts_every_thinned_point_covered():
    """With a ``max_spacing`` guard the disks are at most half the limit and every thinned
    point starts in the cover list of its nearest kept point: the bound holds as without the
    pre-thinning (and about as many points are kept), but the greedy removes a fraction."""
    from scipy.spatial import cKDTree
    X = _plane(6000, seed=9)
    limit = 4 * median_spacing(X)
    runs = {}
    for factor in (0, None):
        runs[factor] = simplify_points(X, options=SimplifyOptions(
            guard="max_spacing", max_spacing=limit, prethin=factor))
        assert cKDTree(X[runs[factor].keep]).query(X)[0].max() <= limit
    thinned, whole = runs[None], runs[0]
    assert "n_prethin_subset" not in whole.stats
    assert thinned.stats["n_prethin_subset"] < 0.5 * len(X)
    assert abs(thinned.count - whole.count) < 0.05 * whole.count
    # a subset point that may not cover (a tile's halo) leaves its disk's points uncovered:
    # they go back into the subset (prethin.covered_by)
    keep = np.array([True, False, False, True, False])
    P = np.c_[np.arange(5.0), np.zeros(5), np.zeros(5)]
    owner = prethin.covered_by(P, keep, np.array([False, True, True, True, True]), 1.5)
    assert keep.tolist() == [True, True, False, True, False]  # 1: 2 from 3, and 0 may not
    assert owner.tolist() == [-1, -1, 3, -1, 3]


def test_prethin_defaults_by_mode():
    assert SimplifyOptions().prethin_factor == 2.0
    assert SimplifyOptions(mode="paper").prethin_factor == 0.0
    assert SimplifyOptions(mode="paper", prethin=2).prethin_factor == 2.0


def test_refinement_runs_when_the_count_is_above_the_subset():
    """A count above the subset (a tiled pass aims the thinning lower) is still met exactly
    and refined: the first of the thinned points stay, then the gaps are filled."""
    X = _plane(4000, seed=8, noise=0.001)
    res = simplify_points(X, 0.5, prethin_target=300)
    assert res.stats["n_prethin_subset"] < 2000
    assert res.keep.sum() == 2000
    assert "refine_rounds" in res.stats


def test_the_block_order_is_lexsorts():
    """:func:`_block_order` (each block of BLOCK consecutive points by its tie keys, a block
    at a time) against one ``np.lexsort`` over every point, ties included."""
    from tiledsimplify.core.prethin import BLOCK, _block_order
    rng = np.random.default_rng(5)
    for n in (0, 1, BLOCK - 1, BLOCK, BLOCK + 1, 3 * BLOCK + 17):
        for top in (5, 2 ** 63):
            tie = rng.integers(0, top, n, dtype=np.uint64)
            np.testing.assert_array_equal(_block_order(tie),
                                          np.lexsort((tie, np.arange(n) // BLOCK)))


def test_given_normals_replace_only_the_normals():
    """The pre-thinned subset's neighbourhoods take the whole cloud's normals instead of
    computing their own: every other list the same as without."""
    rng = np.random.default_rng(4)
    X = rng.random((1500, 3)) * [1.0, 1.0, 0.01]
    X -= X.mean(0)
    given = rng.normal(size=(1500, 3))
    a = neighbourhoods(X, scale_of(X))
    b = neighbourhoods(X, scale_of(X), normals=given)
    np.testing.assert_array_equal(b.normals, given)
    np.testing.assert_array_equal(b.initial_normals, given)
    assert b.normals is not given and b.initial_normals is not b.normals
    for name in ("start", "cnt", "pool", "dn", "dn_cnt", "plane_normals", "stable"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.normals, given)
