"""An indexed binary min-heap over point ids, for the removal queue (paper §3.3).

Keys can be raised or lowered in place, so each removal updates the importance of the affected
points without piling up stale entries. Ties are broken by the smaller point id, which makes the
removal order deterministic.
"""

import numpy as np

from ._jit import jit


@jit
def _less(key, a, b):
    ka = key[a]
    kb = key[b]
    return ka < kb or (ka == kb and a < b)


@jit
def _sift_up(heap, pos, key, k):
    item = heap[k]
    while k > 0:
        parent = (k - 1) >> 1
        other = heap[parent]
        if _less(key, item, other):
            heap[k] = other
            pos[other] = k
            k = parent
        else:
            break
    heap[k] = item
    pos[item] = k


@jit
def _sift_down(heap, pos, key, k, size):
    item = heap[k]
    while True:
        child = 2 * k + 1
        if child >= size:
            break
        right = child + 1
        if right < size and _less(key, heap[right], heap[child]):
            child = right
        other = heap[child]
        if _less(key, other, item):
            heap[k] = other
            pos[other] = k
            k = child
        else:
            break
    heap[k] = item
    pos[item] = k


@jit
def build(heap, pos, key, items):
    """Heapify ``items`` (point ids) with priorities ``key[items]``; returns the heap size."""
    size = items.size
    for k in range(size):
        heap[k] = items[k]
        pos[items[k]] = k
    for k in range(size // 2 - 1, -1, -1):
        _sift_down(heap, pos, key, k, size)
    return size


@jit
def update(heap, pos, key, i, value, size):
    """Set ``key[i] = value`` and restore the heap order (``i`` must be in the heap)."""
    old = key[i]
    key[i] = value
    k = pos[i]
    if value < old:
        _sift_up(heap, pos, key, k)
    elif value > old:
        _sift_down(heap, pos, key, k, size)


@jit
def pop(heap, pos, key, size):
    """Remove and return the id with the smallest key; the new size is ``size - 1``."""
    top = heap[0]
    pos[top] = -1
    size -= 1
    if size > 0:
        heap[0] = heap[size]
        pos[heap[0]] = 0
        _sift_down(heap, pos, key, 0, size)
    return top


@jit
def new(n):
    """Empty storage for a heap over ``n`` ids: ``(heap, pos)``."""
    return np.empty(n, dtype=np.int64), np.full(n, -1, dtype=np.int64)
