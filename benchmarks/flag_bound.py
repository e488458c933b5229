"""How far the kept edge flags alone bound the Hausdorff distance (README "What this shows").

Kept points of the flags' core band stay (``SimplifyResult.band``: drawn first for the points
sure of being kept, and the refinement never swaps a kept one out), so the rest of the budget
must cover the smooth surface. For each case: the default call's Hausdorff distance (input to
kept points), that of a farthest point sample of the same count *grown from our kept band
points* (greedy k-centre with them as first centres: what a covering of the rest could reach,
within the greedy's factor), the same grown from those and the kept points the gap refinement
may not swap out
(:func:`tiledsimplify.core.refine.protected`: boundary measure above 3x the threshold), and
farthest point sampling from scratch (fpsample, the quality benchmark's best peer on
Hausdorff). When ours is close to a grown sample, the gap to farthest point sampling is what
those fixed points cost, not the refinement's shortfall.

    python benchmarks/flag_bound.py                    # the 12 evenly sampled CAD parts, Bunny
    python benchmarks/flag_bound.py --cases fandisk,block-scan0.1
"""

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))


def grown_from(X, start, total):
    """Farthest point sampling of ``total`` points of ``X`` that starts from the points of the
    bool mask ``start`` (the point 0 if it is empty)."""
    keep = np.asarray(start, dtype=bool).copy()
    if not keep.any():
        keep[0] = True
    d = cKDTree(X[keep]).query(X)[0]
    for _ in range(total - int(keep.sum())):
        i = int(np.argmax(d))  # d is 0 at every kept point: a new one each time
        keep[i] = True
        e = X - X[i]
        d = np.minimum(d, np.sqrt(np.einsum("ij,ij->i", e, e)))
    return keep


def main(argv=None):
    from peers import PEERS
    from quality import PARTS, load_case

    from tiledsimplify import metrics, simplify_points
    from tiledsimplify.core.refine import protected

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", default=",".join(["bunny", "fandisk", *PARTS]),
                   help="comma-separated case names of benchmarks/quality.py")
    args = p.parse_args(argv)
    fps = PEERS["farthest point (fpsample)"][0]
    print("| case | kept | band, kept | protected, kept | Hausdorff: ours | grown from our band | "
          "grown from band + protected | farthest point (fpsample) | ours / grown from band | "
          "ours / fpsample |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in args.cases.split(","):
        case = load_case(name)
        X = case.X
        target = round(case.ratio * len(X))
        res = simplify_points(X, count=target)
        flags = res.band & res.keep  # with edge_share, not every point of the band
        fixed = flags | (protected(res.deviation, res.threshold) & res.keep)
        h = {"ours": metrics.hausdorff_distance(X, res.keep),
             "grown": metrics.hausdorff_distance(X, grown_from(X, flags, target)),
             "fixed": metrics.hausdorff_distance(X, grown_from(X, fixed, target)),
             "fps": metrics.hausdorff_distance(X, fps(X, target).keep)}
        h = {k: 1e4 * v for k, v in h.items()}  # 1e-4 of the bounding-box diagonal
        print(f"| {name} | {target:,} | {int(flags.sum()):,} | "
              f"{int((fixed & ~flags).sum()):,} | {h['ours']:.0f} | {h['grown']:.0f} | "
              f"{h['fixed']:.0f} | {h['fps']:.0f} | {h['ours'] / h['grown']:.2f} | "
              f"{h['ours'] / h['fps']:.2f} |", flush=True)


if __name__ == "__main__":
    main()
