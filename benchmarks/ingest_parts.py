"""Where the ingest's work runs: in the client, or in parts on the workers.

A run on a dask cluster used to read the whole input twice in the client process (bounds and
sample, then points to tiles) while every worker waited: ~90 s for the 100M-point survey,
serial however many machines the cluster has. With 4 or more worker threads a LAS/LAZ input is
now ingested in parts, one task per part on the workers (``TileStore.create(parts=...)``).
This prints, for one input, the tile store ingested

- whole, in this process (what every local run with fewer than 4 threads does), and
- in parts on a ``LocalCluster`` of ``W`` one-thread worker processes,

with the wall time, this process's CPU seconds and the workers' CPU seconds (their
``getrusage`` before and after; in all, and the busiest worker's: what a cluster of as many
machines as parts would wait for), and checks that both stores hold the same tiles.

    python benchmarks/ingest_parts.py scan3m.laz [--workers 2] [--part-points 1000000]
    python benchmarks/ingest_parts.py cloud.xyz --chunk-points 250000 --part-points 250000
"""

import argparse
import resource
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np


def _cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _cluster_map(client):
    from tiledsimplify.pipeline.run import IngestProgress, _parts_mapper
    return _parts_mapper(None, None, client, IngestProgress(1, False))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("input", help="a LAS/LAZ file, folder or glob")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--part-points", type=int, default=1_000_000)
    ap.add_argument("--chunk-points", type=int, default=1_000_000)
    ap.add_argument("--tile-points", type=int, default=375_000)
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args(argv)

    import distributed

    from tiledsimplify.io.sources import open_source
    from tiledsimplify.tiles import TileStore

    src = open_source(args.input, chunk_points=args.chunk_points)
    parts = src.parts(args.part_points)
    kw = {"tile_points": args.tile_points, "config": {}, "provenance": {},
          "n_total": src.count}
    rows = []
    with tempfile.TemporaryDirectory() as tmp, distributed.LocalCluster(
            n_workers=args.workers, threads_per_worker=1, processes=True,
            dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        client.run(lambda: __import__("tiledsimplify.tiles.store"))  # imports out of the timing
        stores = {}
        split = f"{len(parts)} parts on {args.workers} workers"
        for _ in range(args.rounds):
            for how in ("whole, in this process", split):
                path = Path(tmp) / f"s{len(rows)}"
                before = client.run(_cpu)
                t, c = time.perf_counter(), _cpu()
                if how.startswith("whole"):
                    ts = TileStore.create(path, src.chunks, **kw)
                else:
                    ts = TileStore.create(path, src.chunks, parts=parts,
                                          map_parts=_cluster_map(client), **kw)
                wall, client_cpu = time.perf_counter() - t, _cpu() - c
                after = client.run(_cpu)
                spent = [after[w] - before[w] for w in after]
                rows.append((how, wall, client_cpu, sum(spent), max(spent)))
                stores[how] = ts
            a, b = stores.values()
            assert a.plan == b.plan and np.array_equal(a.tile_counts, b.tile_counts)
            for t in range(a.n_tiles):
                assert all(np.array_equal(x, y) for x, y in zip(a.core(t), b.core(t)))
            for p in list(stores):
                shutil.rmtree(stores.pop(p).path)
    print(f"\n{src.count:,} points ({args.input}), {args.workers} one-thread worker processes; "
          "the same tiles both ways\n")
    print("| ingest | wall s | client CPU s | workers CPU s | busiest worker CPU s |")
    print("|---|---:|---:|---:|---:|")
    for how, wall, ccpu, wcpu, busiest in rows:
        print(f"| {how} | {wall:.2f} | {ccpu:.2f} | {wcpu:.2f} | {busiest:.2f} |")


if __name__ == "__main__":
    main()
