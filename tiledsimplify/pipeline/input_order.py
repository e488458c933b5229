"""Where each kept point goes in an output written in input order, in memory of the input/8.

A tiled run keeps a subset of the input, tile by tile, but writes NPY/PLY outputs in input
order: a kept point's record is its rank among the kept points' input indices. The kept set
is a bitmap over the input (one bit per point) with the count of kept points before each
64-bit word, so the rank of an index is that count plus the kept bits below it in its word —
no list or sort of the kept indices (2 bits of memory per input point: 250 MB for a billion).
"""

import numpy as np

_ONE = np.uint64(1)


class InputRanks:
    """Ranks in input order of a subset of ``range(n)``, added in any order, each once."""

    def __init__(self, n):
        self.words = np.zeros((int(n) + 63) // 64, dtype=np.uint64)
        self.before = None

    def add(self, index):
        """Add input indices (distinct, not added before) to the subset."""
        index = np.asarray(index, dtype=np.int64)
        np.bitwise_or.at(self.words, index >> 6, _ONE << (index & 63).astype(np.uint64))
        self.before = None

    def __len__(self):
        return int(np.bitwise_count(self.words).sum(dtype=np.int64))

    def rank(self, index):
        """Position of each index of the subset among the subset's indices, in input order."""
        if self.before is None:
            counts = np.bitwise_count(self.words).astype(np.int64)
            self.before = np.cumsum(counts) - counts
        index = np.asarray(index, dtype=np.int64)
        word = index >> 6
        below = self.words[word] & ((_ONE << (index & 63).astype(np.uint64)) - _ONE)
        return self.before[word] + np.bitwise_count(below)
