"""The Z-order memory order: against a bit-by-bit reference, consistent across subsets, and
without effect on results (the core's output does not depend on the order of its input)."""

import struct

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tiledsimplify import SimplifyOptions, simplify_points, synthetic
from tiledsimplify.core.zorder import BITS, distinct, zorder
from tiledsimplify.io import read_mesh


def _ordered_key(x):
    b = struct.unpack("<Q", struct.pack("<d", x + 0.0))[0]
    return (~b) & (2**64 - 1) if b >> 63 else b | (1 << 63)


def naive_zorder(X):
    """Sort by the interleaved top ``BITS`` bits of each coordinate's order-preserving key,
    built one bit at a time as a Python integer; ties by position."""
    keys = []
    for i, row in enumerate(X):
        k = [_ordered_key(float(v)) >> (64 - BITS) for v in row]
        key = 0
        for bit in range(BITS - 1, -1, -1):
            for d in range(3):
                key = (key << 1) | ((k[d] >> bit) & 1)
        keys.append((key, i))
    return np.array([i for _, i in sorted(keys)], dtype=np.int64)


def clouds():
    rng = np.random.default_rng(7)
    yield "normal", rng.normal(size=(1500, 3))
    # projected LiDAR coordinates: a 1 m patch far from the origin (one key cell of the top bits)
    yield "utm", rng.uniform(0, 1, (1500, 3)) + [635_000.0, 4_800_000.0, 120.0]
    # quantised, with ties in the top bits and exact duplicates
    yield "quantised", np.round(rng.normal(size=(1500, 3)), 1)
    # signed zeros and coordinates either side of zero
    yield "zeros", np.r_[np.zeros((3, 3)), -np.zeros((2, 3)), rng.normal(size=(200, 3)) * 1e-300,
                         rng.normal(size=(200, 3))]


@pytest.mark.parametrize("name,X", list(clouds()), ids=[n for n, _ in clouds()])
def test_zorder_matches_a_bit_by_bit_reference(name, X):
    np.testing.assert_array_equal(zorder(X), naive_zorder(X))


@pytest.mark.parametrize("name,X", list(clouds()), ids=[n for n, _ in clouds()])
def test_zorder_is_consistent_across_subsets(name, X):
    # a tile orders its points as the whole cloud does: the key has no bounding box in it
    whole = zorder(X)
    rng = np.random.default_rng(1)
    for _ in range(3):
        sub = rng.random(len(X)) < 0.3
        ids = np.flatnonzero(sub)
        np.testing.assert_array_equal(ids[zorder(X[sub])], whole[sub[whole]])


def naive_distinct(X, frozen):
    """Exact-duplicate groups by numpy.unique over rows (x-y-z order), each represented by a
    frozen member if any, else the lowest index; then the groups put in Z-order."""
    _, inverse = np.unique(X, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    rep = []
    for g in range(inverse.max() + 1):
        members = np.flatnonzero(inverse == g)
        held = members[frozen[members]]
        rep.append(held[0] if held.size else members[0])
    rep = np.array(rep, dtype=np.int64)
    along = zorder(X[rep])
    group = np.empty(rep.size, dtype=np.int64)
    group[along] = np.arange(rep.size)
    return rep[along], group[inverse]


@pytest.mark.parametrize("seed", range(6))
def test_distinct_groups_duplicates_in_zorder(seed):
    rng = np.random.default_rng(seed)
    n = 800
    # few decimals: exact duplicates; far from the origin: long runs of equal top bits
    X = np.round(rng.normal(size=(n, 3)), seed % 3)
    if seed % 2:
        X = X * 1e-3 + [635_000.0, 4_800_000.0, 120.0]
    X[rng.random((n, 3)) < 0.05] = -0.0  # -0.0 == +0.0: the same point
    X = np.r_[X, X[rng.integers(0, n, 200)]]
    frozen = rng.random(len(X)) < 0.2
    rep, inverse = distinct(X, frozen)
    ref_rep, ref_inverse = naive_distinct(X, frozen)
    np.testing.assert_array_equal(rep, ref_rep)
    np.testing.assert_array_equal(inverse, ref_inverse)
    np.testing.assert_array_equal(X[rep][inverse], X)


def test_distinct_of_no_point_and_one_point():
    rep, inverse = distinct(np.empty((0, 3)), np.empty(0, dtype=bool))
    assert rep.size == 0 and inverse.size == 0
    rep, inverse = distinct(np.ones((3, 3)), np.array([False, True, False]))
    assert rep.tolist() == [1] and inverse.tolist() == [0, 0, 0]


def test_zorder_keeps_neighbours_close_in_memory():
    # points on a grid: the Z curve puts grid neighbours far closer together than x-y-z order
    g = np.stack(np.meshgrid(*[np.arange(32.0)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    g = g[(g[:, 2] == 0) | (g[:, 0] == 0)] + 1.0  # two faces of a cube
    pos = np.empty(len(g), dtype=np.int64)
    pos[zorder(g)] = np.arange(len(g))
    _, nb = cKDTree(g).query(g, k=5)
    z_gap = np.median(np.abs(pos[nb[:, 1:]] - pos[:, None]))
    lex = np.empty(len(g), dtype=np.int64)
    lex[np.lexsort(g.T[::-1])] = np.arange(len(g))
    lex_gap = np.median(np.abs(lex[nb[:, 1:]] - lex[:, None]))
    assert z_gap * 4 < lex_gap


def test_results_do_not_depend_on_the_input_order(data_dir):
    # a noisy line scan of Fandisk: edges flagged, faces thinned, the gap refinement at work
    V, F = read_mesh(data_dir / "meshes" / "cad_classic" / "fandisk.obj")
    P, _ = synthetic.scan(V, F, n_points=4000, seed=0)
    X, _ = synthetic.scan(V, F, n_points=4000, noise=0.1 * synthetic.spacing(P), seed=0)
    perm = np.random.default_rng(3).permutation(len(X))
    X = np.r_[X, X[:50]]  # with exact duplicates too
    perm = np.r_[perm, len(perm) + np.arange(50)]
    options = SimplifyOptions()
    a = simplify_points(X, ratio=0.2, options=options)
    b = simplify_points(X[perm], ratio=0.2, options=options)
    # duplicates' representatives may differ (lowest index), so compare by coordinates
    kept_a = {tuple(p) for p in X[a.keep]}
    kept_b = {tuple(p) for p in X[perm][b.keep]}
    assert kept_a == kept_b
    np.testing.assert_array_equal(a.boundary[perm], b.boundary)
    np.testing.assert_array_equal(a.deviation[perm], b.deviation)


def test_the_order_by_two_keys_is_lexsorts():
    """:func:`_by_keys` (a stable sort by the first key, then the runs of ties by the second)
    against ``np.lexsort``, with few distinct keys so that ties abound."""
    from tiledsimplify.core.zorder import _by_keys
    rng = np.random.default_rng(3)
    for _ in range(200):
        n = int(rng.integers(0, 2000))
        hi = rng.integers(0, int(rng.integers(1, 40)), n).astype(np.uint64)
        lo = rng.integers(0, int(rng.integers(1, 40)), n).astype(np.uint64)
        np.testing.assert_array_equal(_by_keys(hi, lo), np.lexsort((lo, hi)))
