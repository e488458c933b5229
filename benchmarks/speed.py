"""Speed and peak memory against input size: our core and tiled pipeline, and the peers.

Input: Fandisk seen by the project's line scanner (6 views, range noise 0.1 x spacing) at each
size, simplified to 20 %. Every method runs in its own process, one after another, so the peak
RSS (``VmHWM`` of the process, read by itself at the end; ``os.wait4``'s figure if it died) is
per method and includes the interpreter and the libraries it loads; a baseline row shows what
Python + numpy + loading the cloud already cost. The cloud is made in a separate process too,
so that no child inherits a large parent's high-water mark. Seconds:

* ``tiledsimplify <mode> core``: ``simplify_points`` on the in-memory array (JIT warmed first);
* ``tiledsimplify <mode> pipeline, N workers``: ``tiledsimplify.run`` from the ``.npy`` file to
  an ``.npy`` output (ingest, tiles, global budget, output), local threads;
* ``tiledsimplify <mode> pipeline LocalCluster 2 processes``: the same on a
  ``dask.distributed.LocalCluster`` of two one-thread worker processes (started before the
  clock; peak RSS = the client process's plus both workers');
* peers: one library call at the setting that keeps the same count (bisection and conversion
  into the library's own container not counted — that favours the peers).

Ratios are seconds over CGAL hierarchy's seconds at the same size. The paper's own timings
(Song & Feng, Pentium 4 3.0 GHz, boundary detection + removal) are printed as rows.

    python benchmarks/speed.py                         # 1e5, 3e5, 1e6
    python benchmarks/speed.py --sizes 100000 --skip "CGAL WLOP"
    python benchmarks/speed.py --big                   # also 1e7 (long: hours)
    python benchmarks/speed.py --from-json s.json      # the table of an earlier run
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import peers  # noqa: E402

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
RATIO = 0.2
#: Song & Feng (2006), section 4: boundary identification + removal, Pentium 4 3.0 GHz.
PAPER = [("Fandisk", 16_475, 0.2, 190 + 1_253), ("Bunny", 35_947, 0.1, 373 + 1_720)]
BASELINE = "(baseline: python + numpy + load the cloud)"
#: the pipeline on a dask.distributed LocalCluster of two one-thread worker processes
CLUSTER = "pipeline LocalCluster 2 processes"


def make_cloud(n, path):
    from tiledsimplify.io import read_mesh
    from tiledsimplify.synthetic import scan, spacing
    V, F = read_mesh(DATA / "meshes" / "cad_classic" / "fandisk.obj")
    P, _ = scan(V, F, n_points=min(n, 200_000), views=6, seed=0)
    s = spacing(P) * np.sqrt(min(n, 200_000) / n)
    P, _ = scan(V, F, n_points=n, views=6, noise=0.1 * s, seed=0)
    np.save(path, P)
    return len(P)


def method_names(skip=()):
    from tiledsimplify.core.options import MODES
    names = [BASELINE]
    for m in MODES:
        names += [f"tiledsimplify {m} core", f"tiledsimplify {m} pipeline 1 worker",
                  f"tiledsimplify {m} pipeline 2 workers", f"tiledsimplify {m} {CLUSTER}"]
    names += list(peers.available())
    return [n for n in names if n not in skip]


def _vm_hwm_mb():
    """Peak resident set of this process (its own address space), from /proc."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def one(name, path, count):
    """Run one method in this process; return a JSON-able dict (seconds of the method)."""
    X = np.load(path)
    if name == BASELINE:
        return {"seconds": 0.0, "kept": len(X), "setting": ""}
    if name.startswith("tiledsimplify "):
        from tiledsimplify import SimplifyOptions, simplify_points
        mode = name.split()[1]
        options = SimplifyOptions(mode=mode)
        if name.endswith(" core"):
            rng = np.random.default_rng(0)
            simplify_points(rng.random((500, 3)) * [1, 1, 0.01], ratio=0.2,
                            options=options)  # warm (load the cached kernels)
            k = peers.ours(mode)(X, count)
            return {"seconds": k.seconds, "kept": k.count, "setting": k.setting}
        from tiledsimplify.pipeline import run
        out = Path(path).with_name(f"out_{os.getpid()}.npy")
        kw = dict(count=count, options=options, tile_points=max(50_000, len(X) // 8),
                  progress=False)
        if name.endswith(CLUSTER):
            return _on_cluster(run, path, out, kw)
        workers = int(name.split("pipeline ")[1].split()[0])
        t = time.perf_counter()
        s = run(path, out, workers=workers, **kw)
        sec = time.perf_counter() - t
        out.unlink(missing_ok=True)
        return {"seconds": sec, "kept": s.n_output, "setting": f"{s.n_tiles} tiles"}
    k = peers.available([name], quiet=True)[name](X, count)
    return {"seconds": k.seconds, "kept": k.count, "setting": k.setting}


def _on_cluster(run, path, out, kw):
    """``run`` on a fresh LocalCluster (2 worker processes, 1 thread each); the seconds
    exclude starting the cluster, the workers' peak RSS is reported beside the client's."""
    from dask.distributed import Client, LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        client.run(lambda: None)  # workers up before the clock starts
        t = time.perf_counter()
        s = run(path, out, client=client, **kw)
        sec = time.perf_counter() - t
        workers_mb = sum(client.run(_vm_hwm_mb).values())
    out.unlink(missing_ok=True)
    return {"seconds": sec, "kept": s.n_output, "setting": f"{s.n_tiles} tiles",
            "workers_rss_mb": workers_mb}


def measure(name, path, count, timeout):
    """Run ``one`` in a child process; its wall time, peak RSS (MB) and result."""
    with tempfile.TemporaryFile("w+") as out:
        t = time.perf_counter()
        p = subprocess.Popen([sys.executable, __file__, "--one", name, str(path), str(count)],
                             stdout=out, stderr=subprocess.DEVNULL, start_new_session=True)
        while True:
            pid, status, usage = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - t > timeout:
                os.killpg(p.pid, signal.SIGKILL)  # the child's own process group
                _, status, usage = os.wait4(p.pid, 0)
                p.returncode = -9
                return {"error": f"timeout after {timeout:.0f} s",
                        "rss_mb": usage.ru_maxrss / 1024}
            time.sleep(0.2)
        p.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t
        out.seek(0)
        text = out.read().strip().splitlines()
    if p.returncode != 0 or not text:
        return {"error": f"exit code {p.returncode}", "rss_mb": usage.ru_maxrss / 1024}
    return {"rss_mb": usage.ru_maxrss / 1024, **json.loads(text[-1]), "wall": wall}


def report(rows):
    print("| method | points | kept | seconds | input pts/s | µs / input pt | peak RSS MB "
          "| seconds / CGAL hierarchy |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, n, ratio, secs in PAPER:
        print(f"| Song & Feng 2006 (paper; Pentium 4 3.0 GHz), {name} | {n:,} | "
              f"{round(n * ratio):,} | {secs:,} | {n / secs:,.0f} "
              f"| {1e6 * secs / n:,.0f} | – | – |")
    ref = {r["n"]: r["seconds"] for r in rows
           if r["method"] == "CGAL hierarchy" and "seconds" in r}
    for r in rows:
        if "error" in r:
            print(f"| {r['method']} | {r['n']:,} | – | {r['error']} | – | – "
                  f"| {r['rss_mb']:,.0f} | – |")
            continue
        if r["method"] == BASELINE:
            print(f"| {r['method']} | {r['n']:,} | – | – | – | – | {r['rss_mb']:,.0f} | – |")
            continue
        sec = r["seconds"]
        rss = r["rss_mb"] + r.get("workers_rss_mb", 0.0)  # a cluster's: client + workers
        ratio = f"{sec / ref[r['n']]:,.1f}x" if ref.get(r["n"]) else "–"
        print(f"| {r['method']} | {r['n']:,} | {r['kept']:,} | {sec:,.2f} "
              f"| {r['n'] / sec:,.0f} | {1e6 * sec / r['n']:,.2f} | {rss:,.0f} "
              f"| {ratio} |")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="100000,300000,1000000",
                   help="comma-separated input sizes (default 1e5, 3e5, 1e6)")
    p.add_argument("--big", action="store_true", help="also 1e7 points")
    p.add_argument("--skip", default="", help="comma-separated method names to leave out")
    p.add_argument("--only", default="", help="comma-separated method names to run")
    p.add_argument("--timeout", type=float, default=1800.0, help="seconds per method")
    p.add_argument("--json", default=None, help="also write the rows to this JSON file")
    p.add_argument("--from-json", default=None, metavar="FILE",
                   help="print the table of an earlier --json run (also a partial one)")
    args = p.parse_args(argv)
    if args.from_json:
        report(json.loads(Path(args.from_json).read_text()))
        return 0
    sizes = [int(float(s)) for s in args.sizes.split(",") if s]
    if args.big:
        sizes.append(10_000_000)
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    names = method_names(skip)
    if args.only:
        names = [n for n in names if n in {s.strip() for s in args.only.split(",")}]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            path = Path(tmp) / f"scan_{n}.npy"
            n_real = int(subprocess.run(
                [sys.executable, __file__, "--cloud", str(n), str(path)], check=True,
                capture_output=True, text=True).stdout.split()[-1])
            count = int(round(RATIO * n_real))
            for name in names:
                print(f"{n_real:,} {name} ...", file=sys.stderr, flush=True)
                r = {"method": name, "n": n_real, **measure(name, path, count, args.timeout)}
                rows.append(r)
                print(f"  {json.dumps(r)}", file=sys.stderr, flush=True)
                if args.json:
                    Path(args.json).write_text(json.dumps(rows, indent=1))
            path.unlink()
    report(rows)
    return 0


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "--one":
        result = one(sys.argv[2], sys.argv[3], int(sys.argv[4]))
        print(json.dumps({**result, "rss_mb": _vm_hwm_mb()}))
    elif len(sys.argv) == 4 and sys.argv[1] == "--cloud":
        print(make_cloud(int(sys.argv[2]), sys.argv[3]))
    else:
        sys.exit(main())
