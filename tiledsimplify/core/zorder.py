"""Memory order of the points: a Z-order (Morton) curve over the coordinates' bits.

Beyond the paper: where each point sits in memory, not what is computed. Every stage of the
core visits a point's neighbours: the local meshes, the facet tests and heap updates of the
removal loop, the boundary fits, the gap refinement. In lexicographic (x, y, z) order — the
order :func:`numpy.unique` over rows gives, the core's order before — the neighbours of a
point lie a whole x-slab of the cloud apart in every array; along a Z-order curve they are
mostly a few entries apart (the removal loop's times against the lexicographic order are
below).

The key is **consistent across subsets**: it is made from each coordinate's own bits (an
order-preserving map of float64 to uint64, the top ``BITS`` bits of x, y and z interleaved),
not from a bounding box, so two points are in the same relative order in any subset of the
cloud that holds both — a tile orders its points as the whole cloud does, as the lexicographic
order did. Points whose keys tie (equal in the top ``BITS`` bits of every coordinate: within
about 1e-9 of each other, relative to their magnitude) keep the order they came in
(:func:`zorder`) or go in (x, y, z) order (:func:`distinct`, which also groups exact
duplicates).

Results depend on the order only through rounding: sums over a point's neighbours (Eq. (1),
the fits) run in index order. Against the lexicographic order: the same kept points on 100k
and 400k noisy scan points, 2 of 20,000 different on 100k Bunny points; and the removal loop
3.3-3.7 -> 3.0-3.1 s, 5.3-5.4 -> 4.4-4.6 s and 13.1-14.6 -> 11.2-11.5 s on those clouds
(``benchmarks/core_speed.py``'s clouds, one process, old and new alternating).
"""

import numpy as np

from ._jit import jit

#: bits of each coordinate's order-preserving key that go into the curve (2 x 21 per word)
BITS = 42

_SIGN = np.uint64(1 << 63)
_LOW21 = np.uint64((1 << 21) - 1)
_MASKS = tuple(np.uint64(m) for m in (0x1F00000000FFFF, 0x1F0000FF0000FF, 0x100F00F00F00F00F,
                                      0x10C30C30C30C30C3, 0x1249249249249249))


@jit
def _spread(v):
    """The 21 low bits of ``v`` moved to every third bit (bit i to bit 3i)."""
    v &= _LOW21
    v = (v | (v << np.uint64(32))) & _MASKS[0]
    v = (v | (v << np.uint64(16))) & _MASKS[1]
    v = (v | (v << np.uint64(8))) & _MASKS[2]
    v = (v | (v << np.uint64(4))) & _MASKS[3]
    v = (v | (v << np.uint64(2))) & _MASKS[4]
    return v


@jit
def _ordered(b):
    """An order-preserving map of a float64's bits ``b`` to uint64 (not NaN; -0 < +0)."""
    if b & _SIGN:
        return ~b
    return b | _SIGN


@jit
def _keys(bits, hi, lo):
    """``hi``, ``lo``: the curve position of every row of ``bits`` (float64 rows as uint64),
    from the top and the next 21 bits of each coordinate's order-preserving key."""
    shift_hi = np.uint64(64 - 21)
    shift_lo = np.uint64(64 - BITS)
    for i in range(bits.shape[0]):
        h = np.uint64(0)
        w = np.uint64(0)
        for d in range(3):
            k = _ordered(bits[i, d])
            h |= _spread(k >> shift_hi) << np.uint64(2 - d)
            w |= _spread(k >> shift_lo) << np.uint64(2 - d)
        hi[i] = h
        lo[i] = w


def _curve(X):
    """``(hi, lo)`` curve keys of the rows of ``X``; -0.0 counts as +0.0."""
    X = np.ascontiguousarray(X, dtype=np.float64) + 0.0  # -0.0 becomes +0.0
    n = X.shape[0]
    hi = np.empty(n, dtype=np.uint64)
    lo = np.empty(n, dtype=np.uint64)
    _keys(X.view(np.uint64).reshape(n, 3), hi, lo)
    return hi, lo


def _tied_runs(same):
    """In a sorted sequence with ``same[i]`` where entries ``i`` and ``i + 1`` are equal: the
    positions that share their value with a neighbour, and the run of equal values each is
    in (numbered along the sequence)."""
    tie = np.zeros(same.size + 1, dtype=bool)
    tie[1:] |= same
    tie[:-1] |= same
    at = np.flatnonzero(tie)
    return at, np.cumsum(np.r_[True, ~same])[at]


def _by_keys(hi, lo):
    """``np.lexsort((lo, hi))``: the stable order by ``hi``, then ``lo``. One stable sort by
    ``hi``, then the runs of equal ``hi`` (rows closer than ~2**-21 of the box in every
    coordinate: 4 % of a 140k-point tile of the 1M scan) by ``lo``: 4.4 ms against lexsort's
    18.7 ms there (two 64-bit stable sorts of every row)."""
    order = np.argsort(hi, kind="stable")
    hs = hi[order]
    same = hs[1:] == hs[:-1]
    if same.any():
        at, run = _tied_runs(same)
        rows = order[at]
        order[at] = rows[np.lexsort((lo[rows], run))]  # stable: equal lo keep their order
    return order


def zorder(X):
    """Stable permutation of the rows of ``X`` (n, 3) that sorts them along the Z-order curve
    (ties: the order they came in)."""
    hi, lo = _curve(X)
    return _by_keys(hi, lo)


def distinct(X, frozen):
    """Exact-duplicate groups of the rows of ``X`` (n, 3), in Z-order: ``(rep, inverse)``.

    ``rep[g]`` is the representative of group ``g`` — a ``frozen`` member if any, else the
    lowest index; ``inverse[i]`` the group of row ``i``. Groups follow the Z-order curve; rows
    whose curve keys tie go in (x, y, z) order (and -0.0 equals +0.0, as in ``==``). One sort
    along the curve, then only the rows that share a key with another are sorted further:
    the same groups and order as :func:`numpy.unique` over rows followed by :func:`zorder`
    (tested), 0.56-0.59 s instead of 2.2-2.7 s at 1M points.
    """
    n = X.shape[0]
    if n == 0:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)
    hi, lo = _curve(X)
    order = _by_keys(hi, lo)
    hi, lo = hi[order], lo[order]
    same_key = (hi[1:] == hi[:-1]) & (lo[1:] == lo[:-1])
    if same_key.any():  # the sorted rows that share their key with a neighbour, by run
        at, run = _tied_runs(same_key)
        rows = order[at]
        P = X[rows] + 0.0
        # by run, then coordinates, then frozen first; stable, so then the lowest index
        within = np.lexsort((~frozen[rows], P[:, 2], P[:, 1], P[:, 0], run))
        order[at] = rows[within]
    P = X[order]
    first = np.zeros(n, dtype=bool)
    first[:1] = True
    for d in range(P.shape[1]):  # a column at a time: (P[1:] != P[:-1]).any(axis=1), faster
        first[1:] |= P[1:, d] != P[:-1, d]
    inverse = np.empty(n, dtype=np.int64)
    inverse[order] = np.cumsum(first) - 1
    return order[first], inverse
