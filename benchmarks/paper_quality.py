"""Quality of the paper's rule as implemented, with tiledsimplify.metrics (DESIGN §4).

Prints one row per case; errors in 1e-4 x bounding-box diagonal. Random sampling at the same
count is the reference row. The full peer comparison is the quality benchmark of issue 4.

    python benchmarks/paper_quality.py
"""

import time
import warnings
from pathlib import Path

import numpy as np

from tiledsimplify import BudgetWarning, metrics, simplify_points, synthetic
from tiledsimplify.io import read_mesh, read_points

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "meshes"


def cases():
    yield "Bunny 35,947", read_points(DATA / "stanford_bunny" / "bun_zipper.ply.gz"), 0.1, None
    V, F = read_mesh(DATA / "cad_classic" / "fandisk.obj")
    P, _ = synthetic.sample_surface_even(V, F, 16475, seed=0)
    s = synthetic.spacing(P)
    yield f"Fandisk {len(P):,} even", P, 0.2, (synthetic.sample_edges(V, F, s), s)


def row(name, method, m, n_b, seconds):
    f = lambda k: f"{1e4 * m[k]:.0f}" if k in m else "–"  # noqa: E731
    cov = f"{m['edge_coverage']:.3f}" if "edge_coverage" in m else "–"
    f1 = f"{m['boundary_f1']:.2f}" if "boundary_f1" in m else "–"
    print(f"| {name} | {method} | {int(m['n_kept']):,} | {n_b} | {cov} | {f1} "
          f"| {f('surface_error_mean')} | {f('hausdorff')} | {f('chamfer')} | {seconds} |")


def main():
    print("| case | method | kept | boundary | edge cov. | boundary F1 | mean err | Hausdorff "
          "| Chamfer | s |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, X, ratio, edges in cases():
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BudgetWarning)
            res = simplify_points(X, ratio=ratio)
        dt = time.perf_counter() - t
        kw = {}
        if edges is not None:
            kw = {"edge_samples": edges[0], "spacing": edges[1], "flagged": res.boundary}
        row(name, f"paper rule, {ratio:.0%}", metrics.evaluate(X, res.keep, **kw),
            int(res.boundary.sum()), f"{dt:.1f}")
        rnd = np.zeros(len(X), bool)
        rnd[np.random.default_rng(0).choice(len(X), res.count, replace=False)] = True
        kw.pop("flagged", None)
        row(name, "random, same count", metrics.evaluate(X, rnd, **kw), "–", "–")


if __name__ == "__main__":
    main()
