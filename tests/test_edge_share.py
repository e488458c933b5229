"""``edge_share``: flagged points are sure of at most a share of the count (beyond the paper).

At small targets the flags alone used to take the whole count and leave the faces empty; now
an even sample along the edges of that share is kept for certain and the other flagged points
compete with the rest, still flagged."""

import math
import warnings

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tiledsimplify import SimplifyOptions, simplify_points
from tiledsimplify.core import prethin
from tiledsimplify.core.heap import coordinate_hash
from tiledsimplify.core.simplify import median_spacing, neighbourhoods
from tiledsimplify.core.voronoi import scale_of
from tiledsimplify.errors import BudgetWarning, InputError
from tiledsimplify.io import read_mesh
from tiledsimplify.synthetic import sample_surface_even


@pytest.fixture(scope="module")
def fandisk(data_dir):
    V, F = read_mesh(data_dir / "meshes" / "cad_classic" / "fandisk.obj")
    return sample_surface_even(V, F, 8000, seed=0, tol=0.001)[0]


def _band():
    """A plane sampled on a jittered grid with a band of flagged points along y = 0."""
    rng = np.random.default_rng(5)
    g = np.stack(np.meshgrid(np.arange(120.0), np.arange(40.0)), -1).reshape(-1, 2)
    g += 0.2 * rng.random(g.shape)
    X = np.c_[g[:, 0], g[:, 1] - 20.0, np.zeros(len(g))]
    flags = np.abs(X[:, 1]) < 1.6
    return X, flags, np.abs(X[:, 1])


@pytest.mark.parametrize("goal", [20, 60, 150])
def test_edge_sample_is_an_even_sample_along_the_edge_nearest_it_first(goal):
    X, flags, distance = _band()
    st = neighbourhoods(X, scale_of(X), reach=12 * median_spacing(X))
    got = prethin.edge_sample(X, st.start, st.cnt, st.pool, flags, distance,
                              coordinate_hash(X), goal, median_spacing(X))
    assert not (got & ~flags).any()
    # at most the goal, and near it (a band of rows of a grid: the count jumps with the radius)
    assert 0.75 * goal <= got.sum() <= goal
    # nearer the line than the flagged points are on average, and spread along all of it
    # (one row where the goal leaves room for one: 120 along the line)
    assert distance[got].mean() < (0.75 if goal <= 120 else 1.0) * distance[flags].mean()
    along = np.sort(X[got, 0])
    gaps = np.diff(along)
    assert along[0] < 2 * gaps.mean() and along[-1] > 119 - 2 * gaps.mean()
    assert gaps.max() < 2.5 * gaps.mean()


def test_edge_sample_keeps_every_flag_within_the_goal_and_none_at_zero():
    X, flags, distance = _band()
    st = neighbourhoods(X, scale_of(X), reach=12 * median_spacing(X))
    args = (X, st.start, st.cnt, st.pool, flags, distance, coordinate_hash(X))
    assert np.array_equal(prethin.edge_sample(*args, int(flags.sum()), 1.0), flags)
    assert not prethin.edge_sample(*args, 0, 1.0).any()


def test_a_small_target_is_met_with_the_faces_covered(fandisk):
    X = fandisk
    target = round(0.05 * len(X))
    with warnings.catch_warnings():
        warnings.simplefilter("error", BudgetWarning)  # the count is met: no warning
        res = simplify_points(X, 0.05)
    with pytest.warns(BudgetWarning, match="boundary"):
        old = simplify_points(X, 0.05, options=SimplifyOptions(edge_share=math.inf))
    flagged = int(old.boundary.sum())
    assert old.band.sum() > target  # the flags' band alone exceeds the count
    # and took all of it (the flags, and the smooth folds' points: features): nothing on the
    # faces
    assert old.keep.sum() == old.stats["n_features"] >= flagged
    assert res.keep.sum() == target and res.reached
    # the same points are flagged; 0.4 of the count at most (the default) is sure of them
    assert np.array_equal(res.boundary, old.boundary) and np.array_equal(res.band, old.band)
    assert 0.3 * target <= res.stats["n_edge_sure"] <= 0.4 * target
    assert (res.keep & res.band).sum() >= res.stats["n_edge_sure"]
    # no holes: the widest gap is a fraction of the flags-only one, at fewer points

    def hausdorff(keep):
        return cKDTree(X[keep]).query(X)[0].max()
    assert hausdorff(res.keep) < 0.4 * hausdorff(old.keep)


def test_a_share_the_flags_stay_under_changes_nothing(fandisk):
    X = fandisk
    res = simplify_points(X, 0.4)
    # the features (flags and smooth folds) under the default share
    assert 0 < res.boundary.sum() <= res.stats["n_features"] < 0.4 * res.target
    old = simplify_points(X, 0.4, options=SimplifyOptions(edge_share=math.inf))
    assert res.stats["n_edge_sure"] == res.stats["n_features"]
    for name in ("keep", "rank", "boundary", "band"):
        assert np.array_equal(getattr(res, name), getattr(old, name))


@pytest.mark.parametrize("bad", [0, -0.5, 1.5, float("nan"), "half"])
def test_edge_share_is_checked(bad):
    with pytest.raises(InputError, match="edge_share"):
        SimplifyOptions(edge_share=bad)


def test_edge_share_defaults_by_mode():
    assert SimplifyOptions().edge_share_value == 0.4
    assert SimplifyOptions(mode="paper").edge_share_value == math.inf
    assert SimplifyOptions(edge_share=math.inf).edge_share_value == math.inf
    assert SimplifyOptions(mode="paper", edge_share=0.3).edge_share_value == 0.3


def test_a_short_run_counts_what_kept_it_with_the_sure_flags(fandisk):
    """With a max_spacing guard too tight for the count, the message splits what had to be
    kept into boundary points sure of being kept and points the guard vetoed. The vetoed ones
    were counted as everything never removed less *every* flagged point, so flagged points
    that were not sure (and were removed, or vetoed) went missing from the sum."""
    import re
    X = fandisk
    with pytest.warns(BudgetWarning):
        res = simplify_points(X, 0.05, options=SimplifyOptions(guard="max_spacing",
                                                               max_spacing=0.02))
    assert not res.reached and res.stats["n_edge_sure"] < res.boundary.sum()
    must = len(X) - res.order.size  # never removed
    got = re.search(r"but (\d+) must be kept \((\d+) boundary, 0 frozen, overlapping ones "
                    r"counted once; (\d+) vetoed", res.message)
    assert got, res.message
    assert int(got[1]) == must
    assert int(got[2]) == res.stats["n_edge_sure"]
    assert int(got[2]) + int(got[3]) == must


def test_a_doubled_cloud_keeps_what_the_cloud_keeps(fandisk):
    """Every point given twice: the copies go first, sure points' copies too, and the cloud
    keeps what it keeps given once. The sure points' copies were kept with them (a fifth of
    the count on the doubled Bunny at 10 %), and the greedy removed as many other points."""
    once = simplify_points(fandisk, ratio=0.1)
    assert once.stats["n_edge_sure"] > 0.1 * once.count
    n = len(fandisk)
    twice = simplify_points(np.vstack([fandisk, fandisk]), count=once.count)
    assert twice.reached and twice.count == once.count
    np.testing.assert_array_equal(twice.keep[:n], once.keep)
    assert not twice.keep[n:].any()
    np.testing.assert_array_equal(twice.order[:n], np.arange(n, 2 * n))
    np.testing.assert_array_equal(twice.boundary[n:], once.boundary)
