"""Small kernels against numpy: eigen-solves, polygon clipping, adjacency lists, the heap."""

import numpy as np
import pytest

from tiledsimplify.core import adjacency, heap
from tiledsimplify.core.clip import area, clip, square
from tiledsimplify.core.linalg import smallest_axis, solve_small, sym3_eigvals


def _sym(rng, scale=1.0):
    A = rng.normal(size=(3, 3)) * scale
    return A @ A.T


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e6])
def test_eigvals_and_smallest_axis_match_numpy(scale):
    rng = np.random.default_rng(0)
    out, work = np.empty(3), np.empty(3)
    for _ in range(200):
        C = _sym(rng, scale)
        w, v = np.linalg.eigh(C)
        got = sym3_eigvals(C[0, 0], C[0, 1], C[0, 2], C[1, 1], C[1, 2], C[2, 2])
        np.testing.assert_allclose(got, w, rtol=1e-7, atol=1e-9 * w[-1])
        smallest_axis(C[0, 0], C[0, 1], C[0, 2], C[1, 1], C[1, 2], C[2, 2], out, work)
        if w[1] - w[0] > 1e-6 * w[-1]:
            assert abs(abs(out @ v[:, 0]) - 1.0) < 1e-6


def test_smallest_axis_degenerate_cases():
    out, work = np.empty(3), np.empty(3)
    # points on a plane z = 0: covariance diag(1, 2, 0)
    smallest_axis(1.0, 0.0, 0.0, 2.0, 0.0, 0.0, out, work)
    np.testing.assert_allclose(np.abs(out), [0, 0, 1])
    # points on the x axis: any unit vector perpendicular to x
    smallest_axis(3.0, 0.0, 0.0, 0.0, 0.0, 0.0, out, work)
    assert abs(out[0]) < 1e-12 and abs(np.linalg.norm(out) - 1) < 1e-12
    # a single point: still a unit vector
    smallest_axis(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, out, work)
    assert abs(np.linalg.norm(out) - 1) < 1e-12


def test_solve_small_matches_numpy():
    rng = np.random.default_rng(1)
    for n in (1, 3, 5):
        A = rng.normal(size=(n, n)) + n * np.eye(n)
        b = rng.normal(size=n)
        x = b.copy()
        assert solve_small(A.copy(), x, n)
        np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-10)
    assert not solve_small(np.zeros((2, 2)), np.ones(2), 2)


def test_clip_square_by_half_planes():
    xs, ys, ls = np.empty(16), np.empty(16), np.empty(16, np.int64)
    ox, oy, ol = np.empty(16), np.empty(16), np.empty(16, np.int64)
    n = square(1.0, xs, ys, ls)
    assert area(n, xs, ys) == pytest.approx(4.0)
    # x <= 0.5 keeps 3/4 of the square; the new edge is labelled 7
    m = clip(n, xs, ys, ls, 1.0, 0.0, 0.5, 7, ox, oy, ol)
    assert area(m, ox, oy) == pytest.approx(3.0)
    assert sorted(ol[:m].tolist()) == [-1, -1, -1, 7]
    # x + y <= 0 cuts the square in half along its diagonal
    m = clip(n, xs, ys, ls, 1 / np.sqrt(2), 1 / np.sqrt(2), 0.0, 3, ox, oy, ol)
    assert area(m, ox, oy) == pytest.approx(2.0)
    # a half-plane containing everything is reported as -1, one excluding everything as 0
    assert clip(n, xs, ys, ls, 1.0, 0.0, 5.0, 1, ox, oy, ol) == -1
    assert clip(n, xs, ys, ls, 1.0, 0.0, -5.0, 1, ox, oy, ol) == 0


def test_adjacency_append_remove_and_growth():
    start, cnt, cap, pool, meta = adjacency.from_edges(4, [(0, 1), (1, 2)], slack=0)
    assert adjacency.to_sets(start, cnt, pool) == [{1}, {0, 2}, {1}, set()]
    for j in range(100):
        if not adjacency.append_in_place(start, cnt, cap, pool, meta, 3, j):  # pool full
            pool = adjacency.with_room(pool, meta, 2 * cap[3] + 8)
            assert adjacency.append_in_place(start, cnt, cap, pool, meta, 3, j)
    assert adjacency.to_sets(start, cnt, pool)[3] == set(range(100))
    assert adjacency.to_sets(start, cnt, pool)[:3] == [{1}, {0, 2}, {1}]
    assert adjacency.remove(start, cnt, pool, 1, 0)
    assert not adjacency.remove(start, cnt, pool, 1, 0)
    assert adjacency.contains(start, cnt, pool, 1, 2)
    assert not adjacency.contains(start, cnt, pool, 1, 0)
    # removal keeps the order of the others (the lists stay sorted nearest first)
    for j in (50, 0, 99, 7):
        assert adjacency.remove(start, cnt, pool, 3, j)
    assert pool[start[3]:start[3] + cnt[3]].tolist() == [
        j for j in range(100) if j not in (50, 0, 99, 7)]


def test_heap_pops_in_key_order_with_updates():
    rng = np.random.default_rng(2)
    n = 500
    key = rng.integers(0, 50, n).astype(float)  # many ties: broken by tie, then id
    tie = rng.integers(0, 5, n).astype(np.uint64)
    h, pos = heap.new(n)
    size = heap.build(h, pos, key, tie, np.arange(n))
    for i in rng.choice(n, 200, replace=False):
        heap.update(h, pos, key, tie, i, float(rng.integers(0, 50)), size)
    got = []
    while size:
        top = heap.top(h)
        got.append(heap.pop(h, pos, key, tie, size))
        assert got[-1] == top
        size -= 1
    expected = sorted(range(n), key=lambda i: (key[i], tie[i], i))
    assert got == expected


def test_coordinate_hash_depends_on_the_point_only():
    rng = np.random.default_rng(3)
    X = rng.random((1000, 3))
    h = heap.coordinate_hash(X)
    assert len(np.unique(h)) == 1000
    perm = rng.permutation(1000)
    np.testing.assert_array_equal(heap.coordinate_hash(X[perm]), h[perm])
    # not monotone in the coordinates: no spatial sweep when ties are broken by it
    order = np.argsort(h)
    assert abs(np.corrcoef(X[order, 0], np.arange(1000))[0, 1]) < 0.1
