"""The ``max_spacing`` guard: the bound it keeps, the count it costs and its time.

For each case and limit (in spacings: the median nearest-neighbour distance): the in-memory
call with ``guard="max_spacing"`` and no count (the guard decides it) and a tiled run of the
same (``tile_points``, 2 workers) — points kept, the largest distance from an input
point to a kept one over the limit (at most 1: the bound holds), the points beyond it — and,
for scale: the count a farthest point sample needs to bring every input point within the limit
(greedy k-centre, from the flagged points as our runs must keep them, and from scratch), the
Hausdorff distance of the default call (refined) and of the greedy without a guard
(``prethin=0, refine=False``) at the guard's count; the seconds of the guarded call over the
default call's at that count (same process, alternating, best of two), and over the guarded
call's without the pre-thinning (``prethin=0``, as before it was allowed with a guard).

    python benchmarks/max_spacing.py                        # bunny, fandisk-scan0.1
    python benchmarks/max_spacing.py --cases scan:300000 --limits 3,5 --tile-points 60000

Cases: a quality case (``benchmarks/quality.py --list``) or ``scan:N`` / ``bunny:N``
(``benchmarks/core_speed.py``'s clouds: the Fandisk line scan, the Bunny's range scans).
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


#: clouds up to this size get the farthest point sample's counts (each step visits every point)
FPS_POINTS = 60_000


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


def _fps_cell(X, start, limit):
    """:func:`fps_count` for a table cell: "–" above :data:`FPS_POINTS` (it is quadratic)."""
    return "–" if len(X) > FPS_POINTS else f"{fps_count(X, start, limit):,}"


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
    from core_speed import KINDS, cloud

    import tiledsimplify
    from tiledsimplify import SimplifyOptions, simplify_points
    warnings.simplefilter("ignore")
    simplify_points(np.random.default_rng(0).random((3000, 3)), 0.1,
                    options=SimplifyOptions(guard="max_spacing", max_spacing=0.05))  # compile
    print("| case | points | limit (spacings) | kept | farthest / limit | beyond | kept, tiled "
          "| farthest / limit, tiled | FPS from the flags | FPS | default's Hausdorff / limit "
          "| unguarded greedy's / limit | s | s / default's | s / without pre-thinning |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in args.cases.split(","):
        kind, _, size = name.partition(":")
        X = (cloud(kind, int(size)) if kind in KINDS and size.isdigit()
             else quality.load_case(name, n_cad=20000).X)
        s = float(np.median(cKDTree(X).query(X, 2)[0][:, 1]))
        folder = Path(tempfile.mkdtemp())
        np.save(folder / "x.npy", X)
        for factor in (float(f) for f in args.limits.split(",")):
            limit = factor * s
            opts = SimplifyOptions(guard="max_spacing", max_spacing=limit)
            times = {"guard": [], "default": [], "whole": []}
            for _ in range(2):
                t = time.perf_counter()
                res = simplify_points(X, options=opts)  # no count: the guard sets it
                times["guard"].append(time.perf_counter() - t)
                kept = int(res.keep.sum())
                t = time.perf_counter()
                default = simplify_points(X, count=kept)
                times["default"].append(time.perf_counter() - t)
                t = time.perf_counter()
                simplify_points(X, options=SimplifyOptions(guard="max_spacing",
                                                           max_spacing=limit, prethin=0))
                times["whole"].append(time.perf_counter() - t)
            free = simplify_points(X, count=kept, options=SimplifyOptions(prethin=0,
                                                                          refine=False))
            d = cKDTree(X[res.keep]).query(X)[0]
            tiled = tiledsimplify.run(folder / "x.npy", folder / "o.npy",
                                      tile_points=args.tile_points, workers=2, options=opts,
                                      progress=False)
            out = np.load(folder / "o.npy")
            dt = cKDTree(np.c_[out["x"], out["y"], out["z"]]).query(X)[0]
            print(f"| {name} | {len(X):,} | {factor:g} | {kept:,} | {d.max() / limit:.3f} | "
                  f"{int((d > limit).sum())} | {tiled.n_output:,} ({tiled.n_tiles} tiles) | "
                  f"{dt.max() / limit:.3f} | {_fps_cell(X, res.boundary, limit)} | "
                  f"{_fps_cell(X, np.zeros(len(X), bool), limit)} | "
                  f"{_far(X, default.keep, limit):.3f} | {_far(X, free.keep, limit):.3f} | "
                  f"{min(times['guard']):.2f} | "
                  f"{min(times['guard']) / min(times['default']):.2f} | "
                  f"{min(times['guard']) / min(times['whole']):.2f} |", flush=True)


if __name__ == "__main__":
    main()
