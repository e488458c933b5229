"""An indexed binary min-heap over point ids, for the removal queue (paper §3.3).

Keys can be raised or lowered in place, so each removal updates the importance of the affected
points without piling up stale entries. Ties are broken by a per-point ``tie`` value (a hash of
the point's coordinates, see :func:`coordinate_hash`), then by id: deterministic, and without
the spatial bias of ids — on exactly flat faces Eq. (1) is exactly 0, and breaking those ties by
id (ids sorted by coordinate) sweeps each face empty from one side.
"""

import numpy as np

from ._jit import jit, jit_inline, jit_leaf


@jit_inline
def _less(ka, ta, a, kb, tb, b):
    if ka != kb:
        return ka < kb
    if ta != tb:
        return ta < tb
    return a < b


@jit_leaf
def _sift_up(heap, pos, hkey, htie, k):
    item, ki, ti = heap[k], hkey[k], htie[k]
    while k > 0:
        parent = (k - 1) >> 1
        other = heap[parent]
        if _less(ki, ti, item, hkey[parent], htie[parent], other):
            heap[k], hkey[k], htie[k] = other, hkey[parent], htie[parent]
            pos[other] = k
            k = parent
        else:
            break
    heap[k], hkey[k], htie[k] = item, ki, ti
    pos[item] = k


@jit_leaf
def _sift_down(heap, pos, hkey, htie, k, size):
    item, ki, ti = heap[k], hkey[k], htie[k]
    while True:
        child = 2 * k + 1
        if child >= size:
            break
        right = child + 1
        if right < size and _less(hkey[right], htie[right], heap[right],
                                  hkey[child], htie[child], heap[child]):
            child = right
        other = heap[child]
        if _less(hkey[child], htie[child], other, ki, ti, item):
            heap[k], hkey[k], htie[k] = other, hkey[child], htie[child]
            pos[other] = k
            k = child
        else:
            break
    heap[k], hkey[k], htie[k] = item, ki, ti
    pos[item] = k


@jit_leaf
def build(heap, pos, key, tie, items):
    """Heapify ``items`` (point ids) with priorities ``key[items]``; returns the heap size."""
    hp, hkey, htie = heap
    size = items.size
    for k in range(size):
        hp[k] = items[k]
        hkey[k] = key[items[k]]
        htie[k] = tie[items[k]]
        pos[items[k]] = k
    for k in range(size // 2 - 1, -1, -1):
        _sift_down(hp, pos, hkey, htie, k, size)
    return size


@jit_leaf
def update(heap, pos, key, tie, i, value, size):
    """Set ``key[i] = value`` and restore the heap order (``i`` must be in the heap)."""
    hp, hkey, htie = heap
    old = key[i]
    key[i] = value
    k = pos[i]
    hkey[k] = value
    if value < old:
        _sift_up(hp, pos, hkey, htie, k)
    elif value > old:
        _sift_down(hp, pos, hkey, htie, k, size)


@jit_leaf
def pop(heap, pos, key, tie, size):
    """Remove and return the id with the smallest key; the new size is ``size - 1``."""
    hp, hkey, htie = heap
    top = hp[0]
    pos[top] = -1
    size -= 1
    if size > 0:
        hp[0], hkey[0], htie[0] = hp[size], hkey[size], htie[size]
        pos[hp[0]] = 0
        _sift_down(hp, pos, hkey, htie, 0, size)
    return top


@jit_leaf
def top(heap):
    """The id with the smallest key (the heap must not be empty)."""
    return heap[0][0]


def coordinate_hash(X):
    """A 64-bit hash of each row's coordinate bits (splitmix64 mixing): the tie-breaker.

    It depends only on the point itself, so a point breaks ties the same way in every tile.
    """
    X = np.ascontiguousarray(X, dtype=np.float64)
    bits = X.view(np.uint64).reshape(X.shape[0], X.shape[1] if X.ndim == 2 else 1)
    h = np.zeros(len(X), dtype=np.uint64)
    with np.errstate(over="ignore"):
        for j in range(bits.shape[1]):
            z = h ^ (bits[:, j] + np.uint64(0x9E3779B97F4A7C15))
            z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
            z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
            h = z ^ (z >> np.uint64(31))
    return h


@jit
def new(n):
    """Empty storage for a heap over ``n`` ids: ``(heap, pos)``.

    ``heap`` holds the ids in heap order with copies of their keys and ties beside them
    (``(ids, keys, ties)``), so a sift compares neighbouring entries instead of looking each
    id's key up in the per-point arrays; ``pos`` is each id's slot (``-1``: not in the heap).
    """
    return ((np.empty(n, dtype=np.int64), np.empty(n, dtype=np.float64),
             np.empty(n, dtype=np.uint64)), np.full(n, -1, dtype=np.int64))
