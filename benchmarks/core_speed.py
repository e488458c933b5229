"""Speed and memory of the in-memory core against the library calls it is built from.

Each case runs in its own process. The core runs first after the JIT is warmed and the cloud
loaded, with the peak RSS reset to the current one just before it (Linux), so the peak read
right after it is the core's own; the table gives it and the bytes per input point above the
RSS before the call. Peers timed in the same process, after it:
scipy's Qhull 3-D Delaunay and a cKDTree 17-nearest query on the same points — the two library
calls a per-point neighbourhood method cannot avoid — so the table reads as ratios that hold
across machines; and the core's own Delaunay (:mod:`tiledsimplify.core.delaunay`, which
replaced Qhull in the default mode) on the same points, without the guard points (NaN if it
failed: the core would have used Qhull). The JIT is warmed first. Clouds:

* ``scan``: Fandisk seen by the project's line scanner (3 views, lines 4x sparser than samples
  along a line, noise 0.1 x spacing) — a realistic scan of a machined part;
* ``bunny``: the ten real Stanford Bunny range scans registered with ``bun.conf`` (362,272
  points), subsampled;
* ``flat``: Fandisk sampled exactly on its faces (no noise): Eq. (1) is exactly 0 on the flat
  faces, the paper's rule empties them and the points around an emptied face become Voronoi
  neighbours of each other — the worst case for the removal loop (see docs/measurements.md,
  "Mode \"paper\": unbounded neighbourhoods").

    python benchmarks/core_speed.py                        # default cases
    python benchmarks/core_speed.py scan:100000 bunny:300000
"""

import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pipeline_speed import _rss_mb  # noqa: E402  (the process's current RSS, MB)
from speed import _vm_hwm_mb  # noqa: E402  (its peak RSS, MB)

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def cloud(kind, n):
    from tiledsimplify.io import read_mesh
    from tiledsimplify.synthetic import sample_surface, scan, spacing
    if kind == "bunny":
        from real_scans import bunny_range
        P = bunny_range()
        rng = np.random.default_rng(0)
        return P[np.sort(rng.choice(len(P), min(n, len(P)), replace=False))]
    V, F = read_mesh(DATA / "meshes" / "cad_classic" / "fandisk.obj")
    if kind == "flat":
        return sample_surface(V, F, n, seed=0)[0]
    P, _ = scan(V, F, n_points=n, seed=0)
    noise = 0.1 * spacing(P)
    return scan(V, F, n_points=n, noise=noise, seed=0)[0]


def one(kind, n):
    from scipy.spatial import Delaunay, cKDTree

    from tiledsimplify import SimplifyOptions, simplify_points
    from tiledsimplify.core.delaunay import delaunay_tets
    simplify_points(cloud("flat", 2000), ratio=0.2)  # warm the JIT
    X = cloud(kind, n)
    n = len(X)
    # the core first, with the high-water mark reset to the current RSS, so that the peak read
    # right after it is the core's own (loading the cloud may have set a higher one, and Qhull,
    # run next, takes far more memory than the core on the same points)
    rss_before = _rss_mb()
    _reset_peak()
    t = time.perf_counter()
    res = simplify_points(X, ratio=0.2, options=SimplifyOptions(progressive=False))
    t_core = time.perf_counter() - t
    rss_core = _vm_hwm_mb()
    t = time.perf_counter()
    Delaunay(X - X.mean(0), qhull_options="Qbb Qc Qz Q12")
    t_qhull = time.perf_counter() - t
    delaunay_tets(X[:2000])  # warm the JIT
    t = time.perf_counter()
    built = delaunay_tets(X - X.mean(0)) is not None
    t_ours = time.perf_counter() - t if built else float("nan")
    t = time.perf_counter()
    cKDTree(X).query(X, k=17)
    t_knn = time.perf_counter() - t
    t = time.perf_counter()
    simplify_points(X, ratio=0.2)
    t_prog = time.perf_counter() - t
    st = res.stats
    return {"case": kind, "n": n, "qhull": t_qhull, "delaunay": t_ours, "knn17": t_knn, "core": t_core, "progressive": t_prog,
            "neighbours": st["seconds_neighbours_normals"], "removal": st["seconds_removal"],
            "refine": st.get("seconds_refine", 0.0),
            "boundary": st["n_boundary"],
            "rss_before_mb": rss_before, "rss_core_mb": rss_core,
            "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def _reset_peak():
    """Set this process's peak RSS (VmHWM) back to its current RSS (Linux ``clear_refs``)."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:  # not Linux, or not allowed: the peak may then predate the core
        pass


KINDS = ("scan", "bunny", "flat")


def main(cases):
    parsed = []
    for case in cases:
        kind, _, n = case.partition(":")
        if kind not in KINDS or not n.isdigit():
            sys.exit(f"not a case: {case!r}; give CLOUD:POINTS with CLOUD one of {KINDS}, "
                     "e.g. scan:100000 (see the module docstring)")
        parsed.append((kind, n))
    rows = []
    for kind, n in parsed:
        out = subprocess.run([sys.executable, __file__, "--one", kind, n], check=True,
                             capture_output=True, text=True).stdout
        rows.append(json.loads(out.strip().splitlines()[-1]))
    print("| cloud | points | core s | µs/pt | pts/s | neighbours s | removal s | refine s "
          "| progressive s | Qhull s | our Delaunay s | kNN-17 s | core / Qhull "
          "| core peak RSS MB (B/pt above the loaded cloud) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        n = r["n"]
        print(f"| {r['case']} | {n:,} | {r['core']:.2f} | {1e6 * r['core'] / n:.0f} | {n / r['core']:,.0f} "
              f"| {r['neighbours']:.2f} | {r['removal']:.2f} | {r.get('refine', 0.0):.2f} "
              f"| {r['progressive']:.2f} "
              f"| {r['qhull']:.2f} | {r.get('delaunay', float('nan')):.2f} | {r['knn17']:.2f} | {r['core'] / r['qhull']:.1f}x "
              f"| {_core_rss(r)} |")


def _core_rss(r):
    """The core's peak RSS and its bytes per input point above the RSS before the call (runs
    saved before the core was measured on its own have only the process's, Qhull's included)."""
    if "rss_core_mb" not in r:
        return f"{r['rss_mb']:.0f} (with Qhull)"
    per = (r["rss_core_mb"] - r["rss_before_mb"]) * 2**20 / r["n"]
    return f"{r['rss_core_mb']:.0f} ({per:,.0f})"


if __name__ == "__main__":
    if {"-h", "--help"} & set(sys.argv[1:]):  # the usage, not a run of minutes
        sys.exit(print(__doc__))
    if len(sys.argv) == 4 and sys.argv[1] == "--one":
        print(json.dumps(one(sys.argv[2], int(sys.argv[3]))))
    else:
        main(sys.argv[1:] or ["scan:10000", "scan:30000", "scan:100000", "bunny:30000",
                              "bunny:100000", "flat:10000", "flat:30000"])
