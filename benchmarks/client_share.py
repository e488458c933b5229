"""The client's serial share of a cluster run after the tiles: the global cut and the output.

Whatever a cluster's size, what its client does alone is serial: at a billion input points,
every pass of the global cut over the tiles' removal sequences and the writing of two hundred
million kept points. On a cluster both now read the tiles on its workers: the cut's passes
(:func:`tiledsimplify.pipeline.budget.store_pass`, batches of tiles, merged in the client) and
the output's tiles, which the workers also pack as the output's point records (quantised,
checked, the three added dimensions; :func:`tiledsimplify.pipeline.output._tile_piece`,
:meth:`tiledsimplify.io.las.LasLayout.pack`) and, for LAZ, compress into the file's LASzip
chunks, those that straddle tiles too (:func:`tiledsimplify.pipeline.output._write_laz_chunks`)
— the client then only writes bytes. With ``--scheduler-process`` the scheduler runs in a
process of its own (as on a real cluster); a ``LocalCluster`` runs it in this one, whose CPU
then includes the scheduler's work.

This runs one pipeline to a kept tile store (or takes ``--store``), then ``--rounds`` times
computes the global cut and writes the output, in this process and on a ``LocalCluster`` of
``W`` one-thread worker processes, alternating, and prints wall time, this process's CPU
seconds and the workers' CPU seconds (their ``getrusage`` before and after); the cuts are
checked to be equal and the outputs the same bytes.

    python benchmarks/client_share.py scan3m.laz [--workers 2] [--rounds 3]
    python benchmarks/client_share.py scan3m.laz --store st3m.zarr   # a store of that input
"""

import argparse
import importlib
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ingest_parts import _cpu  # this process's CPU seconds, user + system


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("input", help="a LAS/LAZ file, folder or glob (the store's input)")
    ap.add_argument("--store", help="a finished tile store of that input (kept by a run)")
    ap.add_argument("--suffix", default=".laz", help="the output's suffix (.laz or .las)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--ratio", type=float, default=0.2)
    ap.add_argument("--scheduler-process", action="store_true",
                    help="the scheduler in a process of its own (distributed's "
                         "SubprocessCluster), as on a real cluster; a LocalCluster runs it in "
                         "this process, whose CPU then includes it")
    args = ap.parse_args(argv)

    import distributed

    import tiledsimplify
    from tiledsimplify.io.sources import open_source
    from tiledsimplify.pipeline.budget import kept_in_tile, plan_cut, store_sequences
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
        if args.scheduler_process:
            from distributed.deploy.subprocess import SubprocessCluster
            make = SubprocessCluster(n_workers=args.workers, threads_per_worker=1,
                                     dashboard_address=":0")
        else:
            make = distributed.LocalCluster(n_workers=args.workers, threads_per_worker=1,
                                            processes=True, dashboard_address=None)
        with make as cluster, distributed.Client(cluster) as client:
            client.wait_for_workers(args.workers)
            client.run(lambda: __import__("tiledsimplify.pipeline.run"))  # out of the timing
            on_cluster = f"on {args.workers} workers"
            n_remove = ts.n_total - sum(int(kept_in_tile(ts, t, prefix).sum())
                                        for t in range(ts.n_tiles))
            for r in range(args.rounds):
                for how in ("in this process", on_cluster):
                    here = how != on_cluster
                    before = client.run(_cpu)
                    t, c = time.perf_counter(), _cpu()
                    seqs, exhausted, known = store_sequences(ts)
                    got, _ = plan_cut(seqs, n_remove, exhausted, known, None if here else
                                      run_module._cut_scan(str(ts.path), sorted(seqs), client))
                    wall, client_cpu = time.perf_counter() - t, _cpu() - c
                    after = client.run(_cpu)
                    assert got == prefix, "the cut differs from the store's"
                    rows.append(("global cut", how, wall, client_cpu,
                                 sum(after[w] - before[w] for w in after)))
                for how in ("in this process", on_cluster):
                    out = Path(tmp) / f"out{r}{len(rows)}{args.suffix}"
                    before = client.run(_cpu)
                    t, c = time.perf_counter(), _cpu()
                    n_out, _ = run_module.write_output(
                        ts, src, out, prefix, refined, client if how == on_cluster else None)
                    wall, client_cpu = time.perf_counter() - t, _cpu() - c
                    after = client.run(_cpu)
                    rows.append(("output", how, wall, client_cpu,
                                 sum(after[w] - before[w] for w in after)))
                    outputs[how] = out.read_bytes()
                    out.unlink()
                assert len(set(outputs.values())) == 1, "the outputs differ"
    print(f"\n{src.count:,} input points ({args.input}), {n_out:,} kept, {args.suffix} output; "
          f"{args.workers} one-thread worker processes, the scheduler "
          f"{'in a process of its own' if args.scheduler_process else 'in this one'}; the same "
          "cut and output bytes both ways\n")
    print("| stage | run | wall s | client CPU s | workers CPU s |")
    print("|---|---|---:|---:|---:|")
    for stage, how, wall, ccpu, wcpu in sorted(rows, key=lambda row: row[0]):
        print(f"| {stage} | {how} | {wall:.2f} | {ccpu:.2f} | {wcpu:.2f} |")


if __name__ == "__main__":
    main()
