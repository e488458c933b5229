"""The ``max_spacing`` guard: the bound it keeps, the count it costs and its time.

For each case and limit (in spacings: the median nearest-neighbour distance): the in-memory
call at ratio 0.01 with ``guard="max_spacing"`` (the guard then decides the count) and a tiled
run of the same (``tile_points``, 2 workers) — points kept, the largest distance from an input
point to a kept one over the limit (at most 1: the bound holds), the points beyond it — and,
for scale: the count a farthest point sample needs to bring every input point within the limit
(greedy k-centre, from the flagged points as our runs must keep them, and from scratch), the
Hausdorff distance of the default call (refined) and of the greedy without a guard
(``prethin=0, refine=False``, which the guard's sequence otherwise follows) at the guard's
count, and the seconds of the guarded call over the unguarded greedy's at that count (same
process, alternating).

    python benchmarks/max_spacing.py                        # bunny, fandisk-scan0.1
    python benchmarks/max_spacing.py --cases bunny-range --limits 3,5
"""

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))


def fps_count(X, start, limit):
    """How many points a farthest point sample grown from the bool mask ``start`` (point 0 if
    empty) needs before every point of ``X`` lies within ``limit`` of one."""
    keep = np.asarray(start, dtype=bool).copy()
    if not keep.any():
        keep[0] = True
    d = cKDTree(X[keep]).query(X)[0]
    k = int(keep.sum())
    while True:
        i = int(np.argmax(d))
        if d[i] <= limit:
            return k
        e = X - X[i]
        d = np.minimum(d, np.sqrt(np.einsum("ij,ij->i", e, e)))
        k += 1


def _far(X, keep, limit):
    """The largest distance from a point of ``X`` to the nearest kept one, over ``limit``."""
    return cKDTree(X[keep]).query(X)[0].max() / limit


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default="bunny,fandisk-scan0.1",
                    help="quality cases (benchmarks/quality.py --list)")
    ap.add_argument("--limits", default="2,3,5", help="limits in spacings")
    ap.add_argument("--tile-points", type=int, default=5000)
    args = ap.parse_args(argv)
    import quality

    import tiledsimplify
    from tiledsimplify import SimplifyOptions, simplify_points
    warnings.simplefilter("ignore")
    simplify_points(np.random.default_rng(0).random((3000, 3)), 0.1,
                    options=SimplifyOptions(guard="max_spacing", max_spacing=0.05))  # compile
    print("| case | points | limit (spacings) | kept | farthest / limit | beyond | kept, tiled "
          "| farthest / limit, tiled | FPS from the flags | FPS | default's Hausdorff / limit "
          "| unguarded greedy's / limit | s / unguarded greedy's |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in args.cases.split(","):
        X = quality.load_case(name, n_cad=20000).X
        s = float(np.median(cKDTree(X).query(X, 2)[0][:, 1]))
        folder = Path(tempfile.mkdtemp())
        np.save(folder / "x.npy", X)
        for factor in (float(f) for f in args.limits.split(",")):
            limit = factor * s
            opts = SimplifyOptions(guard="max_spacing", max_spacing=limit)
            times = {"guard": [], "free": []}
            for _ in range(2):
                t = time.perf_counter()
                res = simplify_points(X, 0.01, options=opts)
                times["guard"].append(time.perf_counter() - t)
                kept = int(res.keep.sum())
                t = time.perf_counter()
                free = simplify_points(X, count=kept,
                                       options=SimplifyOptions(prethin=0, refine=False))
                times["free"].append(time.perf_counter() - t)
            d = cKDTree(X[res.keep]).query(X)[0]
            tiled = tiledsimplify.run(folder / "x.npy", folder / "o.npy", ratio=0.01,
                                      tile_points=args.tile_points, workers=2, options=opts,
                                      progress=False)
            out = np.load(folder / "o.npy")
            dt = cKDTree(np.c_[out["x"], out["y"], out["z"]]).query(X)[0]
            default = simplify_points(X, count=kept)
            print(f"| {name} | {len(X):,} | {factor:g} | {kept:,} | {d.max() / limit:.3f} | "
                  f"{int((d > limit).sum())} | {tiled.n_output:,} ({tiled.n_tiles} tiles) | "
                  f"{dt.max() / limit:.3f} | {fps_count(X, res.boundary, limit):,} | "
                  f"{fps_count(X, np.zeros(len(X), bool), limit):,} | "
                  f"{_far(X, default.keep, limit):.3f} | {_far(X, free.keep, limit):.3f} | "
                  f"{min(times['guard']) / min(times['free']):.2f} |", flush=True)


if __name__ == "__main__":
    main()
