"""Speed of the core against the Voronoi reach (``SimplifyOptions.reach``), paired in one process.

The reach bounds the Voronoi neighbourhoods (see :mod:`tiledsimplify.core.voronoi`); a removal's
facet tests go with the square of the number of neighbours, so it sets much of the removal
loop's cost. Each cloud is run at every reach in turn, ``--rounds`` times round (alternating,
so a busy spell of this shared machine hits every reach alike), and the table gives the fastest
run of each, with the mean Voronoi degree before the removal and the kept and flagged counts.
Clouds as in ``core_speed.py`` (``scan:N``, ``bunny:N``, ratio 0.2), plus ``zipper``: the
Stanford Bunny file of the paper (35,947 points) at 10 %. ``progressive=False``: the removal
stops at the target.

    python benchmarks/reach_speed.py                                # 20 and 12, three clouds
    python benchmarks/reach_speed.py --reach 20,14,12,10 zipper scan:100000
"""

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from core_speed import DATA, cloud  # noqa: E402


def load(spec):
    """Points and ratio of a cloud spec."""
    if spec == "zipper":
        from tiledsimplify.io import read_points
        return read_points(DATA / "meshes" / "stanford_bunny" / "bun_zipper.ply.gz"), 0.1
    kind, n = spec.split(":")
    return cloud(kind, int(n)), 0.2


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("clouds", nargs="*", default=["zipper", "scan:100000", "bunny:35947"])
    p.add_argument("--reach", default="20,12", help="comma-separated reaches, in spacings")
    p.add_argument("--rounds", type=int, default=2)
    args = p.parse_args(argv)
    reaches = [float(r) for r in args.reach.split(",")]

    from tiledsimplify import SimplifyOptions, simplify_points
    simplify_points(cloud("scan", 3000), ratio=0.2)  # compile outside the timings
    print("| cloud | points | reach | mean degree | whole call s | neighbours s | removal s "
          "| kept | flagged |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for spec in args.clouds:
        X, ratio = load(spec)
        best = {r: {} for r in reaches}
        for _ in range(args.rounds):
            for r in reaches:
                t = time.perf_counter()
                res = simplify_points(X, ratio=ratio, options=SimplifyOptions(
                    progressive=False, reach=r))
                row = {"total": time.perf_counter() - t,
                       "neighbours": res.stats["seconds_neighbours_normals"],
                       "removal": res.stats["seconds_removal"]}
                b = best[r]
                for k, v in row.items():
                    b[k] = min(b.get(k, v), v)
                b["kept"], b["flagged"] = int(res.keep.sum()), int(res.boundary.sum())
                b["degree"] = res.stats["mean_voronoi_degree"]
        for r in reaches:
            b = best[r]
            print(f"| {spec} | {len(X):,} | {r:g} | {b['degree']:.2f} | {b['total']:.2f} "
                  f"| {b['neighbours']:.2f} | {b['removal']:.2f} | {b['kept']:,} "
                  f"| {b['flagged']:,} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
