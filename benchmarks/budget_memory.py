"""Memory and time of the global cut (one budget across tiles) as the input grows.

The pipeline's cut reads each tile's removal sequence from the store when it needs it
(``budget.StoreSequences``) and finds the level by a radix selection, so its memory is one
tile's sequence, not the input's. Here the tiles' sequences are made on demand (a realistic
shape: sorted gamma-distributed importances with local jitter, scaled per tile, 100k steps per
tile, about a 150k-point tile at ratio 0.2) and the cut is timed against the peer it replaced in
the same process: every sequence in memory, their running maxima concatenated and the level
found by ``np.partition`` (the pipeline's cut before 2026-12-02). Peak memory is Python's
traced allocation peak (``tracemalloc``, which numpy reports to) during each call, the peer's
including the sequences it holds.

    python benchmarks/budget_memory.py                 # 10, 100 and 1000 tiles
    python benchmarks/budget_memory.py 10 100 3000
"""

import sys
import time
import tracemalloc
from collections.abc import Mapping

import numpy as np

from tiledsimplify.pipeline.budget import global_cut

STEPS = 100_000


class Sequences(Mapping):
    """``tiles`` removal sequences of :data:`STEPS` steps, made when asked for (not kept)."""

    def __init__(self, tiles):
        rng = np.random.default_rng(0)
        base = np.sort(rng.gamma(2.0, 1e-3, STEPS))
        self.base = base * (1 + 0.3 * rng.standard_normal(STEPS).clip(-0.9, 3))  # jitter
        self.scale = 1 + rng.random(tiles)
        self.tiles = tiles

    def __getitem__(self, t):
        return self.base * self.scale[t]

    def __iter__(self):
        return iter(range(self.tiles))

    def __len__(self):
        return self.tiles


def in_memory_cut(sequences, n_remove):
    """The peer: every sequence held, the level by one partition, ties by tile (exact)."""
    held = {t: np.asarray(sequences[t], dtype=np.float64) for t in sorted(sequences)}
    runmax = {t: np.maximum.accumulate(s) for t, s in held.items()}
    levels = np.concatenate(list(runmax.values()))
    take = min(n_remove, levels.size)
    levels.partition(take - 1)
    level = levels[take - 1]
    del levels
    prefix, rest = {}, take
    for t, r in runmax.items():
        prefix[t] = int(np.searchsorted(r, level, side="left"))
        rest -= prefix[t]
    for t, r in runmax.items():
        k = min(int(np.searchsorted(r, level, side="right")) - prefix[t], rest)
        prefix[t] += k
        rest -= k
    return prefix


def measure(func, seqs, n_remove):
    tracemalloc.start()
    t = time.perf_counter()
    try:
        cut = func(seqs, n_remove)
        seconds = time.perf_counter() - t
        peak = tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()
    return cut, seconds, peak


def main(argv):
    sizes = [int(a) for a in argv] or [10, 100, 1000]
    print("| tiles | steps | cut s | cut peak MB | in-memory s | in-memory peak MB | same cut |")
    print("|---:|---:|---:|---:|---:|---:|:---:|")
    for tiles in sizes:
        seqs = Sequences(tiles)
        n_remove = int(0.8 * tiles * STEPS)
        ours, s_ours, mb_ours = measure(global_cut, seqs, n_remove)
        peer, s_peer, mb_peer = measure(in_memory_cut, seqs, n_remove)
        print(f"| {tiles:,} | {tiles * STEPS:,} | {s_ours:.2f} | {mb_ours:.1f} | {s_peer:.2f} | "
              f"{mb_peer:.1f} | {'yes' if ours == peer else 'NO'} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
