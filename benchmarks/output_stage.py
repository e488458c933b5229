"""Where the output stage's work runs: the client's share of writing a LAS/LAZ output.

A tiled run writes its output from one process, in tile order. On a cluster the tiles' kept
points are read by its workers, which also pack them as the output's point records
(quantised, checked, the three added dimensions; :func:`tiledsimplify.pipeline.run._tile_piece`,
:meth:`tiledsimplify.io.las.LasLayout.pack`); the client then only compresses (LASzip, in
parallel over its cores) and writes. Whatever the cluster's size, that share is serial: at a
billion input points it is the client's time for two hundred million kept ones.

This runs one pipeline to a kept tile store (or takes ``--store``), then writes its output
``--rounds`` times in this process and on a ``LocalCluster`` of ``W`` one-thread worker
processes, alternating, and prints wall time, this process's CPU seconds and the workers' CPU
seconds (their ``getrusage`` before and after); the outputs are checked to be the same bytes.

    python benchmarks/output_stage.py scan3m.laz [--workers 2] [--rounds 3]
    python benchmarks/output_stage.py scan3m.laz --store st3m.zarr   # a store of that input
"""

import argparse
import importlib
import resource
import tempfile
import time
from pathlib import Path


def _cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("input", help="a LAS/LAZ file, folder or glob (the store's input)")
    ap.add_argument("--store", help="a finished tile store of that input (kept by a run)")
    ap.add_argument("--suffix", default=".laz", help="the output's suffix (.laz or .las)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--ratio", type=float, default=0.2)
    args = ap.parse_args(argv)

    import distributed

    import tiledsimplify
    from tiledsimplify.io.sources import open_source
    from tiledsimplify.tiles import TileStore

    run_module = importlib.import_module("tiledsimplify.pipeline.run")
    src = open_source(args.input)
    with tempfile.TemporaryDirectory() as tmp:
        store = args.store
        if store is None:
            store = Path(tmp) / "store.zarr"
            tiledsimplify.run(args.input, Path(tmp) / f"first{args.suffix}", ratio=args.ratio,
                              store=store, workers=args.workers)
        ts = TileStore.open(store)
        prefix = dict(enumerate(ts.run_attrs["cut"]))
        refined = ts.read_refined(0) is not None
        rows, outputs = [], {}
        with distributed.LocalCluster(
                n_workers=args.workers, threads_per_worker=1, processes=True,
                dashboard_address=None) as cluster, distributed.Client(cluster) as client:
            client.run(lambda: __import__("tiledsimplify.pipeline.run"))  # out of the timing
            on_cluster = f"on {args.workers} workers"
            for r in range(args.rounds):
                for how in ("in this process", on_cluster):
                    out = Path(tmp) / f"out{r}{len(rows)}{args.suffix}"
                    before = client.run(_cpu)
                    t, c = time.perf_counter(), _cpu()
                    n_out, _ = run_module._write_output(
                        ts, src, out, prefix, refined, client if how == on_cluster else None)
                    wall, client_cpu = time.perf_counter() - t, _cpu() - c
                    after = client.run(_cpu)
                    rows.append((how, wall, client_cpu, sum(after[w] - before[w] for w in after)))
                    outputs[how] = out.read_bytes()
                    out.unlink()
                assert len(set(outputs.values())) == 1, "the outputs differ"
    print(f"\n{src.count:,} input points ({args.input}), {n_out:,} kept, {args.suffix} output; "
          f"{args.workers} one-thread worker processes; the same bytes both ways\n")
    print("| output written | wall s | client CPU s | workers CPU s |")
    print("|---|---:|---:|---:|")
    for how, wall, ccpu, wcpu in rows:
        print(f"| {how} | {wall:.2f} | {ccpu:.2f} | {wcpu:.2f} |")


if __name__ == "__main__":
    main()
