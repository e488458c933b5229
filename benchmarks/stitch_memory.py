"""Memory and time of the stitch: the global cut (one budget across tiles) as the input grows,
and writing a tiled run's NPY output in input order.

The pipeline's cut reads each tile's removal sequence from the store when it needs it
(``budget.StoreSequences``) and finds the level by a radix selection, so its memory is one
tile's sequence, not the input's. Here the tiles' sequences are made on demand (a realistic
shape: sorted gamma-distributed importances with local jitter, scaled per tile, 100k steps per
tile, about a 150k-point tile at ratio 0.2) and the cut is timed against the peer it replaced in
the same process: every sequence in memory, their running maxima concatenated and the level
found by ``np.partition`` (the pipeline's cut before 2026-12-02). Each call is timed, then run
again for its peak memory: Python's traced allocation peak (``tracemalloc``, which numpy
reports to), the peer's including the sequences it holds.

Output (``--store DIR``, a finished tile store, e.g. ``tiledsimplify run ... --store DIR``):
the pipeline's writer (``pipeline.output.write_output``: each kept point written at its rank in
input order, a tile at a time) against the peer it replaced: every tile's kept points gathered,
sorted into input order and written whole (``write_points``); the same bytes, both timed and
traced.

    python benchmarks/stitch_memory.py                 # 10, 100 and 1000 tiles
    python benchmarks/stitch_memory.py 10 100 3000
    python benchmarks/stitch_memory.py --store DIR --ratio 0.2
"""

import argparse
import tempfile
import time
import tracemalloc
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from tiledsimplify.io.points_out import write_points
from tiledsimplify.pipeline.budget import global_cut, kept_in_tile, store_cut
from tiledsimplify.pipeline.output import write_output
from tiledsimplify.tiles import TileStore

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


def measure(func, *args):
    """``(result, seconds, peak MB)``: timed untraced (tracing slows numpy calls unevenly),
    then run again under tracemalloc for the peak."""
    t = time.perf_counter()
    out = func(*args)
    seconds = time.perf_counter() - t
    tracemalloc.start()
    try:
        func(*args)
        peak = tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()
    return out, seconds, peak


def gathered_output(ts, output, prefix):
    """The peer: every tile's kept points gathered, sorted into input order, written whole."""
    parts, flags, normals, index = [], [], [], []
    for i in range(ts.n_tiles):
        keep = kept_in_tile(ts, i, prefix)
        xyz, idx = ts.core(i)
        parts.append(xyz[keep])
        flags.append(ts.read_result(i, "boundary")[keep])
        normals.append(ts.read_result(i, "normal")[keep])
        index.append(idx[keep])
    xyz = np.concatenate(parts)
    order = np.argsort(np.concatenate(index), kind="stable")
    b = np.concatenate(flags)[order]
    nrm = np.concatenate(normals)[order]
    write_points(output, xyz[order], {
        "sharp_edge": b.astype(np.uint8), "nx": nrm[:, 0], "ny": nrm[:, 1], "nz": nrm[:, 2]})
    return len(xyz)


def cut_table(sizes):
    print("| tiles | steps | cut s | cut peak MB | in-memory s | in-memory peak MB | same cut |")
    print("|---:|---:|---:|---:|---:|---:|:---:|")
    for tiles in sizes:
        seqs = Sequences(tiles)
        n_remove = int(0.8 * tiles * STEPS)
        ours, s_ours, mb_ours = measure(global_cut, seqs, n_remove)
        peer, s_peer, mb_peer = measure(in_memory_cut, seqs, n_remove)
        print(f"| {tiles:,} | {tiles * STEPS:,} | {s_ours:.2f} | {mb_ours:.1f} | {s_peer:.2f} | "
              f"{mb_peer:.1f} | {'yes' if ours == peer else 'NO'} |", flush=True)


def output_table(store, ratio):
    ts = TileStore.open(store)
    prefix = store_cut(ts, ts.n_total - round(ratio * ts.n_total))
    print("| input points | tiles | kept | writer s | writer peak MB | gathered s | "
          "gathered peak MB | same bytes |")
    print("|---:|---:|---:|---:|---:|---:|---:|:---:|")
    with tempfile.TemporaryDirectory() as tmp:
        a, b = Path(tmp) / "a.npy", Path(tmp) / "b.npy"
        (n_out, _), s_ours, mb_ours = measure(write_output, ts, None, a, prefix)
        _, s_peer, mb_peer = measure(gathered_output, ts, b, prefix)
        same = a.read_bytes() == b.read_bytes()
    print(f"| {ts.n_total:,} | {ts.n_tiles} | {n_out:,} | {s_ours:.2f} | {mb_ours:.1f} | "
          f"{s_peer:.2f} | {mb_peer:.1f} | {'yes' if same else 'NO'} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tiles", nargs="*", type=int, help="tile counts of the cut table")
    ap.add_argument("--store", help="a finished tile store: the output table instead")
    ap.add_argument("--ratio", type=float, default=0.2, help="kept fraction for --store")
    args = ap.parse_args()
    if args.store:
        output_table(args.store, args.ratio)
    else:
        cut_table(args.tiles or [10, 100, 1000])


if __name__ == "__main__":
    main()
