"""End-to-end speed and memory of ``tiledsimplify run`` on a synthetic LAZ scan.

The scan is made by the project's own line scanner: Fandisk scaled to 1 m, several views,
noise 0.1 x spacing, quantised to 0.1 mm in a LAS 1.2 point format 0 file. Each run is its own
process (peak RSS from the OS; CPU s = user + system time of that process, which other load on
the machine inflates less than wall time). Workers 1 and 2 on the local threaded scheduler.
The run's log (one line per tile) and the RSS every minute go to stderr, so a run stopped
part-way still shows its rate.

    python benchmarks/pipeline_speed.py 200000 1000000
    python benchmarks/pipeline_speed.py --workers 2 --tile-points 150000 10000000
    python benchmarks/pipeline_speed.py --floor 0.25 1000000
    python benchmarks/pipeline_speed.py --one scan.laz 2 150000 0.5 > w2.json  # one run
    python benchmarks/pipeline_speed.py --one scan.laz 2 150000 0.5 0.02       # keep 2 %
    python benchmarks/pipeline_speed.py --table w1.json w2.json                # its table
    python benchmarks/pipeline_speed.py --survey 10 10000000 survey/          # 100M in 10 files
    python benchmarks/pipeline_speed.py --one survey 2 500000 0.5 > w100m.json

``--one`` writes its output into a temporary directory (under ``TMPDIR``) and deletes it at
the end: it used to write ``out_WORKERS.laz`` beside its input, inside the survey folder for
one of the survey's files, where a later run on the folder read it as one more tile.
"""

import json
import logging
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def make_laz(n, path, seed=0, shift=(0.0, 0.0, 0.0)):
    import laspy

    from tiledsimplify.io import read_mesh
    from tiledsimplify.synthetic import scan, spacing
    V, F = read_mesh(DATA / "meshes" / "cad_classic" / "fandisk.obj")
    V = (V - V.min(0)) / (V.max(0) - V.min(0)).max()
    P, _ = scan(V, F, n_points=min(n, 200_000), views=6, seed=0)
    s = spacing(P) * np.sqrt(min(n, 200_000) / n)
    P, _ = scan(V, F, n_points=n, views=6, noise=0.1 * s, seed=seed)
    P = P + np.asarray(shift, dtype=float)
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales = np.array([1e-4, 1e-4, 1e-4])
    header.offsets = np.zeros(3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = P[:, 0], P[:, 1], P[:, 2]
    las.intensity = np.arange(len(P)) % 65536
    las.write(path)
    return len(P)


def make_survey(k, n, folder):
    """A folder of ``k`` LAZ files of ``n`` points each, as a survey delivers them: the
    Fandisk scan of :func:`make_laz` (seeds 0..k-1) on a grid of 1.5 m cells, one part a file."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    side = int(np.ceil(np.sqrt(k)))
    return sum(make_laz(n, folder / f"part_{i:02d}.laz", seed=i,
                        shift=(1.5 * (i % side), 1.5 * (i // side), 0.0)) for i in range(k))


def _rss_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def _watch_memory(t0, every=60.0):
    from tiledsimplify.pipeline.run import _peak_rss_mb  # VmHWM: not the parent's size
    while True:
        time.sleep(every)
        peak = _peak_rss_mb()
        print(f"[{time.perf_counter() - t0:7.0f} s] RSS {_rss_mb():.0f} MB, peak {peak:.0f} MB",
              file=sys.stderr, flush=True)


def one(path, workers, tile_points, floor, ratio=0.2):
    from tiledsimplify.pipeline import run
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(message)s")
    from tiledsimplify import machine
    # as ``run`` does, but before this script's own thread (an arena of its own otherwise: 1
    # worker 515 MB peak instead of the CLI's 390); MALLOC_ARENA_MAX=0: glibc's default
    machine.cap_malloc_arenas(workers)
    with tempfile.TemporaryDirectory(prefix="pipeline_speed-") as tmp:
        t = time.perf_counter()
        threading.Thread(target=_watch_memory, args=(t,), daemon=True).start()
        s = run(path, Path(tmp) / f"out_{workers}.laz", ratio=ratio, workers=workers,
                tile_points=tile_points, floor=floor)
        wall = time.perf_counter() - t
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return {"n": s.n_input, "workers": workers, "ratio": ratio, "wall": wall,
            "tiles": s.n_tiles, "deeper": s.n_deeper, "seconds": s.seconds, "reached": s.reached,
            "kept": s.n_output, "cpu": ru.ru_utime + ru.ru_stime, "cpu_seconds": s.cpu_seconds,
            "rss_mb": s.peak_rss_mb}  # VmHWM: ru_maxrss held the parent's size (make_laz)


def main(sizes, workers=(1, 2), tile_points=None, floor=0.5):
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            path = Path(tmp) / f"scan_{n}.laz"
            n_real = make_laz(n, path)
            for w in workers:
                out = subprocess.run([sys.executable, __file__, "--one", str(path), str(w),
                                      str(tile_points or max(50_000, n_real // 8)), str(floor)],
                                     check=True, stdout=subprocess.PIPE, text=True).stdout
                rows.append(json.loads(out.strip().splitlines()[-1]))
    load = " ".join(Path("/proc/loadavg").read_text().split()[:3])
    print(f"floor {floor}; load average at the end {load}")
    table(rows)


def table(rows):
    """The markdown table of ``--one`` results (speed-up against the first row of each size and
    ratio; a row saved before the ratio was recorded kept 20 %)."""
    print("| points | kept | workers | tiles | wall s | input pts/s | speed-up | ingest s "
          "| neighbours s | tiles s | deeper s (tiles) | refine s | output s | CPU s "
          "| peak RSS MB |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    base = {}
    for r in rows:
        ratio = r.get("ratio", 0.2)
        base.setdefault((r["n"], ratio), r["wall"])
        sec = r["seconds"]
        print(f"| {r['n']:,} | {ratio:.0%} | {r['workers']} | {r['tiles']} | {r['wall']:.1f} "
              f"| {r['n'] / r['wall']:,.0f} | {base[(r['n'], ratio)] / r['wall']:.2f}x "
              f"| {sec['ingest']:.1f} | {sec['neighbours']:.1f} | {sec['tiles']:.1f} "
              f"| {sec['deeper']:.1f} ({r['deeper']}) "
              f"| {sec.get('gaps', 0.0) + sec.get('refine', 0.0):.1f} | {sec['output']:.1f} "
              f"| {r['cpu']:.0f} "
              f"| {r['rss_mb']:.0f} |")


if __name__ == "__main__":
    if {"-h", "--help"} & set(sys.argv[1:]):  # the usage, not a run of minutes
        sys.exit(print(__doc__))
    if len(sys.argv) > 2 and sys.argv[1] == "--table":  # saved --one outputs, one per file
        table([json.loads(Path(f).read_text().strip().splitlines()[-1]) for f in sys.argv[2:]])
    elif len(sys.argv) == 5 and sys.argv[1] == "--survey":
        print(make_survey(int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]))
    elif len(sys.argv) in (6, 7) and sys.argv[1] == "--one":  # [ratio], default 0.2
        print(json.dumps(one(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]),
                             float(sys.argv[5]), *map(float, sys.argv[6:]))))
    else:
        args = sys.argv[1:]
        workers, tile_points, floor = (1, 2), None, 0.5
        while args[:1] in (["--workers"], ["--tile-points"], ["--floor"]):
            if args[0] == "--workers":
                workers = (int(args[1]),)
            elif args[0] == "--tile-points":
                tile_points = int(args[1])
            else:
                floor = float(args[1])
            args = args[2:]
        main([int(a) for a in args] or [200_000, 1_000_000], workers, tile_points, floor)
