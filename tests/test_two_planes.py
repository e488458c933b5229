"""Two-plane fits: the line sweep's seed, its eigenvalue bound and the fits' helpers against
numpy (:mod:`tiledsimplify.core.two_planes`)."""

import numpy as np
import pytest

from tiledsimplify.core import two_planes, two_ring
from tiledsimplify.core.linalg import NO_MOMENTS, add_moments

from edge_scenes import roof


def _naive_best_line_split(P, t1, t2, ndir, least):
    """Least total squared plane distance over every line split (direction, offset), eigh."""
    best = np.inf
    for d in range(ndir):
        a = np.pi * d / ndir
        order = np.argsort((P - P[0]) @ (np.cos(a) * t1 + np.sin(a) * t2), kind="stable")
        for k in range(least, len(P) - least + 1):
            sse = 0.0
            for part in (P[order[:k]], P[order[k:]]):
                q = part - part.mean(0)
                sse += max(np.linalg.eigvalsh(q.T @ q)[0], 0.0)
            best = min(best, sse)
    return best


def _split_sse(P, side):
    out = 0.0
    for which in (0, 1):
        q = P[side == which] - P[side == which].mean(0)
        out += max(np.linalg.eigvalsh(q.T @ q)[0], 0.0)
    return out


@pytest.mark.parametrize("shape", ["roof", "rough"])
@pytest.mark.parametrize("seed", range(6))
def test_sweep_seed_is_the_best_line_split(seed, shape):
    """On a rough patch (rock, vegetation: no two planes) the sweep stops each direction
    early, once its left half alone scatters more than the best split: still the best."""
    rng = np.random.default_rng(seed)
    c = int(rng.integers(8, 40))
    if shape == "roof":
        X = roof(rng, c, angle_deg=float(rng.uniform(60, 150)), noise=0.02)
    else:
        X = rng.normal(size=(c, 3)) * [1.0, 0.8, 0.4]
    X = X @ np.linalg.qr(rng.normal(size=(3, 3)))[0] + rng.normal(size=3)  # any pose
    idx = np.arange(c)
    side = np.full(c, -1, np.int64)
    frame = [np.empty(3) for _ in range(3)]
    assert two_planes.seed_by_sweep(X, idx, c, side, np.empty(c), *frame, np.empty(3),
                                   np.empty(c, np.int64))
    assert set(np.unique(side)) == {0, 1}
    least = max(two_planes.MIN_SIDE, int(np.ceil(two_planes.SWEEP_SIDE * c)))
    assert min(np.sum(side == 0), np.sum(side == 1)) >= least
    _, t1, t2 = frame  # the mean-plane frame the sweep used
    naive = _naive_best_line_split(X, t1, t2, two_planes.NDIR, least)
    np.testing.assert_allclose(_split_sse(X, side), naive, rtol=1e-7, atol=1e-12)


@pytest.mark.parametrize("shape", ["plane", "line", "blob", "flat", "exact line"])
def test_scatter_floor_bounds_the_least_eigenvalue(shape):
    """The sweep skips a split's eigenvalues when this bound already rules it out: it must never
    exceed the least eigenvalue, and on points spread in a plane it must be close to it."""
    rng = np.random.default_rng(3)
    scale = {"plane": [1.0, 0.7, 0.02], "line": [1.0, 0.03, 0.02], "blob": [1.0, 0.8, 0.6],
             "flat": [1.0, 0.5, 0.0], "exact line": [1.0, 0.0, 0.0]}[shape]
    for _ in range(200):
        k = int(rng.integers(3, 40))
        P = rng.normal(size=(k + 1, 3)) * scale @ np.linalg.qr(rng.normal(size=(3, 3)))[0]
        P += rng.normal(size=3) * 5.0
        X = np.ascontiguousarray(P)
        m = NO_MOMENTS
        for q in range(1, k + 1):  # moments of points 1..k about point 0, as the sweep sums
            m = add_moments(m, X, q, X[0, 0], X[0, 1], X[0, 2])
        low = two_planes._scatter_floor(*two_planes._scatter(m, k))
        exact = two_planes._smallest_scatter(*two_planes._scatter(m, k))
        q = P[1:] - P[1:].mean(0)
        trace = np.trace(q.T @ q)
        reference = max(np.linalg.eigvalsh(q.T @ q)[0], 0.0)
        assert exact == pytest.approx(reference, abs=1e-9 * trace)
        assert low <= exact + 1e-9 * trace
        if shape == "plane" and exact > 1e-6 * trace:  # (three points lie in a plane exactly)
            assert low >= 0.9 * exact
        if shape == "blob" and exact > 1e-6 * trace:  # Newton's steps: near even off a plane
            assert low >= 0.75 * exact  # (the first step alone, det / minors: about half)


def test_sweep_seed_separates_the_faces_of_a_ridge():
    rng = np.random.default_rng(7)
    X = roof(rng, 30, angle_deg=90.0, noise=0.005)
    X[0] = [0.0, 0.0, 0.0]  # the point itself on the ridge
    side = np.empty(30, np.int64)
    frame = [np.empty(3) for _ in range(3)]
    assert two_planes.seed_by_sweep(X, np.arange(30), 30, side, np.empty(30), *frame, np.empty(3),
                                   np.empty(30, np.int64))
    clear = np.abs(X[:, 0]) > 0.05
    left = side[clear & (X[:, 0] < 0)]
    right = side[clear & (X[:, 0] > 0)]
    assert len(set(left)) == 1 and len(set(right)) == 1 and left[0] != right[0]


def test_the_fits_helpers_equal_numpys_and_their_single_forms():
    """The sort, median and two-plane fit that replaced ``np.argsort``, ``np.median`` and two
    calls of ``_plane_fit`` in the edge fits (speed, not results): the same values to the
    last bit, equal values sorted in their positions' order."""
    rng = np.random.default_rng(11)
    for c in (1, 2, 3, 8, 31, two_ring.MAX_RING + 1):
        a = np.round(rng.normal(size=c + 4), 1)  # many equal values
        order = np.full(c + 4, -1, np.int64)
        keys = a.copy()
        two_planes._sort_order(keys, c, order)
        assert list(order[:c]) == list(np.argsort(a[:c], kind="stable"))
        assert list(keys[:c]) == sorted(a[:c]) and list(keys[c:]) == list(a[c:])
        b = a.copy()
        assert two_ring.median_in_place(b, c) == np.median(a[:c])
        assert list(b[:c]) == sorted(a[:c]) and list(b[c:]) == list(a[c:])
    X = rng.normal(size=(60, 3)) * [1.0, 1.0, 0.1] + rng.normal(size=3) * 10
    for k0 in (2, 3, 17, 30):
        idx = rng.permutation(60)[:33]
        side = (np.arange(33) >= k0).astype(np.int64)
        rng.shuffle(side)
        both = [np.empty(3) for _ in range(5)]  # c1, n1, c2, n2, work
        k0_, k1_, rms0, spread0 = two_planes.plane_fits(X, idx, 33, side, *both)
        assert (k0_, k1_) == (k0, 33 - k0)
        if k0 < two_planes.MIN_SIDE:
            continue
        for which, centre, normal, rms, spread in ((0, both[0], both[1], rms0, spread0),
                                                   (1, both[2], both[3], *both[4][:2])):
            alone = [np.empty(3) for _ in range(3)]
            assert two_planes.plane_fit(X, idx, 33, side, which, *alone) == (k0, 33 - k0)[which]
            assert list(alone[0]) == list(centre) and list(alone[1]) == list(normal)
            assert (alone[2][0], alone[2][1]) == (rms, spread)
