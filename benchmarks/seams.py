"""Do the tiles show? Tiled vs untiled on the same cloud, same threshold, same count.

Kept density in a band two spacings wide around internal tile faces, mean surface error,
Hausdorff, sharp-edge coverage, and the share of feature points (the flags' edges and smooth
folds: what the refinement covers) within its edge cover radius of a kept point
(``refine.edge_cover_radius``; tiled: each tile's core features). Cases: the Bunny (35,947
points, 10 %) and a noisy line scan of Fandisk (~200k points, 20 %), each cut into >= 8 tiles; ``--scan-ratios`` runs the scan
at other ratios too (small ones: the cut's gaps outgrow the halo, see
``pipeline.tile_refine.refine_width``).

    python benchmarks/seams.py [--bunny-ratios 0.1] [--scan-ratios 0.2,0.05,0.02]
"""

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from tiledsimplify import BudgetWarning, metrics, simplify_points, synthetic
from tiledsimplify.core.refine import edge_cover_radius
from tiledsimplify.io import read_mesh, read_points
from tiledsimplify.pipeline import run
from tiledsimplify.pipeline.budget import kept_mask, store_cut
from tiledsimplify.pipeline.tile_refine import refined_mask
from tiledsimplify.tiles import TileStore

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def case(name, X, ratio, tile_points, edges=None):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "in.npy"
        np.save(path, X)
        t = time.perf_counter()
        s = run(path, Path(tmp) / "out.npy", ratio=ratio, tile_points=tile_points,
                store=Path(tmp) / "store", workers=2)
        t_tiled = time.perf_counter() - t
        ts = TileStore.open(Path(tmp) / "store")
        # the output: the cut, refined per tile if the run refined (mode "coverage")
        keep_t = refined_mask(ts) if s.refined else kept_mask(ts, store_cut(ts, len(X) - s.target))
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BudgetWarning)
            res_u = simplify_points(X, ratio=ratio,
                                    options={"boundary_threshold": s.threshold,
                                             "spacing": s.spacing})
        keep_u = res_u.keep
        t_untiled = time.perf_counter() - t
        sp = metrics.spacing(X)
        band = ts.plan.face_distance(X) < 2 * sp
        # the features (flags' edges and smooth folds) each run keeps within the refinement's
        # edge cover radius of a kept point
        flags_t = np.zeros(len(X), dtype=bool)
        for i in range(ts.n_tiles):
            flags_t[ts.core(i)[1]] = ts.read_result(i, "feature")
        radius = edge_cover_radius(s.spacing, ratio)
        rows = []
        for label, k, secs, flags in (("untiled", keep_u, t_untiled, res_u.features),
                                      ("tiled", keep_t, t_tiled, flags_t)):
            d = cKDTree(X[k]).query(X[flags])[0] if flags.any() else np.zeros(0)
            covered = f"{np.mean(d <= radius):.4f} of {int(flags.sum()):,}" if d.size else "–"
            err = metrics.surface_error(X, k)[0]
            hd = metrics.hausdorff_distance(X, k)
            cov = metrics.edge_coverage(X, k, edges, sp) if edges is not None else float("nan")
            rows.append((label, int(k.sum()), k[band].mean(), err, hd, cov, covered, secs))
        u = rows[0]
        for label, kept, dens, err, hd, cov, covered, secs in rows:
            print(f"| {name} | {label} ({ts.n_tiles} tiles) | {kept:,} | {dens / u[2]:.3f} "
                  f"| {1e4 * err:.1f} ({err / u[3]:.3f}) | {1e4 * hd:.0f} "
                  f"| {cov:.3f} | {covered} | {secs:.0f} |")


def _ratios(text):
    return [float(r) for r in text.split(",") if r.strip()]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--bunny-ratios", type=_ratios, default=[0.1],
                   help="comma-separated ratios of the Bunny case (default 0.1; none: '')")
    p.add_argument("--scan-ratios", type=_ratios, default=[0.2],
                   help="comma-separated ratios of the Fandisk scan case (default 0.2)")
    args = p.parse_args(argv)
    print("| cloud | run | kept | band density / untiled | mean err (ratio) | Hausdorff "
          "| edge cov. | features within the cover radius | s |")
    print("|---|---|---:|---:|---:|---:|---:|---|---:|")
    X = read_points(DATA / "meshes" / "stanford_bunny" / "bun_zipper.ply.gz")
    for ratio in args.bunny_ratios:
        case(f"Bunny 35,947, {ratio:.0%}", X, ratio, 6000)
    V, F = read_mesh(DATA / "meshes" / "cad_classic" / "fandisk.obj")
    P, _ = synthetic.scan(V, F, n_points=200_000, seed=2)
    sp = synthetic.spacing(P)
    X = synthetic.scan(V, F, n_points=200_000, noise=0.1 * sp, seed=2)[0]
    for ratio in args.scan_ratios:
        case(f"Fandisk scan {len(X):,}, {ratio:.0%}", X, ratio, 25_000,
             edges=synthetic.sample_edges(V, F, metrics.spacing(X)))


if __name__ == "__main__":
    main(sys.argv[1:])
