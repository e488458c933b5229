"""What the pre-thinning (``SimplifyOptions.prethin``, core/prethin.py) saves: the core's default
call against the same call with ``prethin=0``, alternating in one process.

Cases: the Stanford Bunny at 10 % (the whole default call), and a tile of a synthetic LAZ scan
(``make_laz`` of ``pipeline_speed.py``: the ``--tile`` points nearest its centre) run as a tiled
run's first pass runs it — down to half its share, the thinning aimed at the share, no
refinement. Prints one row per run (seconds and the core's stages) and the ratio of medians.

    python benchmarks/prethin_speed.py                      # Bunny, 4 pairs
    python benchmarks/prethin_speed.py --scan 3000000 --tile 300000 --ratio 0.1 --pairs 2
"""

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from tiledsimplify import SimplifyOptions, simplify_points
from tiledsimplify.io import read_points

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
STAGES = ("neighbours_normals", "boundary", "prethin", "removal", "refine")


def bunny():
    X = read_points(DATA / "meshes" / "stanford_bunny" / "bun_zipper.ply.gz")
    X = X[0] if isinstance(X, tuple) else X

    def call(prethin):
        return simplify_points(X, 0.1, options=SimplifyOptions(prethin=prethin))
    return f"Bunny, {len(X):,} points, 10 %", call


def scan_tile(n, tile, ratio):
    import laspy
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from pipeline_speed import make_laz
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scan.laz"
        make_laz(n, path)
        las = laspy.read(path)
    X = np.c_[las.x, las.y, las.z]
    T = X[np.argsort(np.abs(X - X.mean(axis=0)).max(axis=1))[:tile]]

    def call(prethin):
        return simplify_points(
            T, count=int(0.5 * ratio * len(T)), prethin_target=int(ratio * len(T)),
            options=SimplifyOptions(prethin=prethin, progressive=False, refine=False))
    return f"tile of {len(T):,} scan points, first pass at {ratio:g}", call


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scan", type=int, default=None, help="points of the synthetic scan")
    p.add_argument("--tile", type=int, default=300_000, help="points of its tile")
    p.add_argument("--ratio", type=float, default=0.1, help="the tile's share of the target")
    p.add_argument("--pairs", type=int, default=4)
    args = p.parse_args(argv)
    title, call = bunny() if args.scan is None else scan_tile(args.scan, args.tile, args.ratio)
    call(None)  # compile
    print(f"### {title}\n")
    print("| prethin | s | subset | " + " | ".join(STAGES) + " |")
    print("|---|---:|---:|" + "---:|" * len(STAGES))
    seconds = {0: [], None: []}
    for _ in range(args.pairs):
        for prethin in (0, None):
            t = time.perf_counter()
            res = call(prethin)
            seconds[prethin].append(time.perf_counter() - t)
            stages = " | ".join(f"{res.stats.get('seconds_' + s, 0.0):.2f}" for s in STAGES)
            subset = res.stats.get("n_prethin_subset")
            print(f"| {'off' if prethin == 0 else 'default'} | {seconds[prethin][-1]:.2f} | "
                  f"{'–' if subset is None else f'{subset:,}'} | {stages} |", flush=True)
    ratio = statistics.median(seconds[None]) / statistics.median(seconds[0])
    print(f"\ndefault / off, medians: {ratio:.2f}x")


if __name__ == "__main__":
    main()
