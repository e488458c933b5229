"""Quality at equal kept counts: tiledsimplify (every mode) against the tools users pick instead.

One markdown table per case (DESIGN.md §4; measures from :mod:`tiledsimplify.metrics`).
Distances are in 1e-4 x the original's bounding-box diagonal. Every peer is driven to the
count our modes keep (see ``peers.py``); if a mode keeps more than the target (its boundary
points alone exceed the budget), the peers are run again at that count so that every
comparison is at equal count.

Columns: kept; boundary flagged (ours); edge coverage (fraction of true sharp-edge samples with
a kept point within 1.5 spacings); boundary precision/recall/F1 against the points within one
spacing of a true sharp edge (ours); on scans also F1 with the recall counted over the edge
points the scanner saw from both sides only (a point of another face within 2 spacings — an
edge seen from one side is the end of a scanned face to any local test); surface error mean/max
(distance of every original point to the plane of its 8 nearest kept points, after Pauly et al.
2002); Hausdorff (original -> kept) and Chamfer; adaptivity (kept fraction in the curved half
over the flat half; > 1 = adaptive); seconds (ours: the whole call; peers: one library call at
the final setting).

Cases (``--list``): ``bunny`` (35,947 points, 10 %, paper Fig. 3); ``fandisk`` (evenly sampled to
16,475 points, 20 %, Fig. 2); every other CAD mesh in ``meshes/`` evenly sampled to ~20k points
(20 %) and scanned by the project's line scanner with range noise 0.1 and 0.2 x spacing
(``<part>-scan0.1``, ``<part>-scan0.2``); ``autzen`` (real airborne LiDAR, no edge truth);
``bunny-range`` (the Bunny's ten real range scans registered, 362,272 points, 10 %, no edge
truth: overlapping views, registration residue and scanner noise).

    python benchmarks/quality.py --quick                    # bunny, fandisk, fandisk-scan0.1
    python benchmarks/quality.py --cases fandisk,block-scan0.2 --json out.json
    python benchmarks/quality.py --cases all --skip "CGAL WLOP"
    python benchmarks/quality.py --list
    python benchmarks/quality.py --from-json out.json       # tables + summary, no new run
    python benchmarks/quality.py --cases all --modes coverage --skip all --option edge_width=0.9
    python benchmarks/quality.py --ratio 0.05 --modes coverage --cases bunny,fandisk,autzen

The summary table gives, per case and mode, our value against the best peer's at the same
count (bold where ours is at least as good).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import peers  # noqa: E402

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
MESHES = DATA / "meshes"

#: CAD parts beyond Fandisk: (case name, file). fandisk_libigl.off is Fandisk again
#: (same shape, another tessellation) and is left out.
PARTS = {
    "block": "cad_classic/block.obj",
    "rocker-arm": "cad_classic/rocker-arm.obj.gz",
    "featuretype": "trimesh_cad/featuretype.STL",
    "angle_block": "trimesh_cad/angle_block.STL",
    "idler_riser": "trimesh_cad/idler_riser.STL",
    "octagonal_pocket": "trimesh_cad/octagonal_pocket.stl",
    "plate_holes": "trimesh_cad/plate_holes.STL",
    "ADIS16480": "trimesh_cad/ADIS16480.STL.gz",
    "tray_bottom": "trimesh_cad/1002_tray_bottom.STL.gz",
    "counter": "trimesh_cad/counter.unitsmm.STL.gz",
    "cycloidal": "trimesh_cad/cycloidal.ply.gz",
}
NOISES = (0.1, 0.2)
#: earlier labels of peers, so that older --json files print with today's names
RENAMED = {"voxel grid (numpy, nearest to centroid)": "voxel grid (numpy: nearest to centroid)",
           "voxel grid (Open3D, centroids)": "voxel grid (Open3D: centroids)"}
QUICK = ("bunny", "fandisk", "fandisk-scan0.1")


def case_names(noises=NOISES):
    """Every case: the Bunny, each CAD part sampled evenly and scanned at each of ``noises``
    (times the spacing), the Autzen tile and the Bunny's range scans."""
    names = ["bunny", "fandisk"] + [f"fandisk-scan{s}" for s in noises]
    for part in PARTS:
        names += [part] + [f"{part}-scan{s}" for s in noises]
    return names + ["autzen", "bunny-range"]


def _groups(noises=NOISES):
    names = case_names(noises)
    return {
        "all": names,
        "cad": ["fandisk", *PARTS],
        "scans": [n for n in names if "-scan" in n],
        "quick": list(QUICK),
    }


class Case:
    """One input cloud with its ground truth (None where there is none).

    ``seen``: for a scan, the ground-truth edge points whose edge the scanner saw from both
    sides (:func:`seen_edge_points`); None for an even sampling, where every edge is seen.
    """

    def __init__(self, name, title, X, ratio, edge_segments=None, spacing=None, seen=None):
        self.name, self.title, self.X, self.ratio = name, title, X, ratio
        self.edge_segments, self.spacing, self.seen = edge_segments, spacing, seen


def seen_edge_points(X, normals, truth, spacing, radius=2.0, angle_deg=30.0):
    """Edge points (``truth``) with a point of another face within ``radius`` spacings.

    ``normals``: the true normal of the face each point was sampled from. A scanner sees many
    edges from one side only (the other face faces away or is occluded); there, one face ends
    and no local test can tell an edge from the end of the scan. Recall against these points
    is what a detector can reach on the scan; the edge coverage's ceiling row shows the same
    limit for the kept points.
    """
    from scipy.spatial import cKDTree
    cos_t = math.cos(math.radians(angle_deg))
    on_edge = np.flatnonzero(truth)
    seen = np.zeros(len(X), bool)
    balls = cKDTree(X).query_ball_point(X[on_edge], radius * spacing)
    for i, near in zip(on_edge, balls):
        seen[i] = bool(np.any(np.abs(normals[near] @ normals[i]) < cos_t))
    return seen


def _mesh(rel):
    from tiledsimplify.io import read_mesh
    return read_mesh(MESHES / rel)


def _edges(V, F):
    from tiledsimplify import synthetic
    e = synthetic.sharp_edges(V, F)
    return V[e]  # (k, 2, 3) segments


def load_case(name, n_cad=20_000, lidar_points=None):
    from tiledsimplify import synthetic
    from tiledsimplify.io import read_points
    if name == "bunny":
        X = read_points(MESHES / "stanford_bunny" / "bun_zipper.ply.gz")
        return Case(name, f"Stanford Bunny, {len(X):,} points, 10 %", X, 0.1)
    if name == "bunny-range":
        from real_scans import bunny_range
        X = bunny_range()
        return Case(name, f"Stanford Bunny, ten real range scans registered, {len(X):,} points, "
                          "10 %, no edge truth", X, 0.1)
    if name == "autzen":
        import laspy
        las = laspy.read(DATA / "lidar" / "autzen_trim.laz")
        X = np.c_[las.x, las.y, las.z].astype(np.float64)
        if lidar_points and lidar_points < len(X):  # a spatial crop keeps the density
            c = np.median(X[:, :2], axis=0)
            order = np.argsort(np.max(np.abs(X[:, :2] - c), axis=1), kind="stable")
            X = X[np.sort(order[:lidar_points])]
        return Case(name, f"Autzen airborne LiDAR (autzen_trim.laz), {len(X):,} points, 20 %, "
                          "no edge truth", X, 0.2)
    part, _, scan = name.partition("-scan")
    rel = "cad_classic/fandisk.obj" if part == "fandisk" else PARTS.get(part)
    if rel is None:
        raise SystemExit(f"unknown case {name!r}; --list shows the cases")
    V, F = _mesh(rel)
    seg = _edges(V, F)
    n = 16_475 if part == "fandisk" else n_cad
    if not scan:
        X, _ = synthetic.sample_surface_even(V, F, n, seed=0, tol=0.001)
        s = synthetic.spacing(X)
        return Case(name, f"{part} sampled evenly, {len(X):,} points, 20 %", X, 0.2, seg, s)
    noise = float(scan)
    P, _ = synthetic.scan(V, F, n_points=n, seed=0)
    s = synthetic.spacing(P)
    X, face = synthetic.scan(V, F, n_points=n, noise=noise * s, seed=0)
    from tiledsimplify import metrics
    cross = synthetic._face_cross(V, F)[face]
    truth = metrics.edge_ground_truth(X, edge_segments=seg, spacing=s)
    seen = seen_edge_points(X, cross / np.linalg.norm(cross, axis=1)[:, None], truth, s)
    return Case(name, f"{part} line scan (3 views), noise {noise:g} x spacing, {len(X):,} "
                      f"points, 20 %; {seen.sum() / max(truth.sum(), 1):.0%} of the edge points "
                      "seen from both sides", X, 0.2, seg, s, seen)


# ---------------------------------------------------------------------------------------------


def measure(case, kept, region):
    from tiledsimplify import metrics
    kw = {"feature_region": region}
    if case.edge_segments is not None:
        kw.update(edge_segments=case.edge_segments, spacing=case.spacing)
        if kept.boundary is not None:
            kw["flagged"] = kept.boundary
    out = metrics.evaluate(case.X, kept.keep if kept.subset else kept.points, **kw)
    if case.seen is not None and kept.boundary is not None and case.seen.any():
        flag = np.asarray(kept.boundary, bool)
        recall = float(np.count_nonzero(flag & case.seen) / np.count_nonzero(case.seen))
        precision = out["boundary_precision"]
        out["boundary_recall_seen"] = recall
        out["boundary_f1_seen"] = (2 * precision * recall / (precision + recall)
                                   if precision + recall > 0 else 0.0)
    return out


def run_case(case, methods, ours):
    """Rows (dicts) for one case: our modes, then every peer at each count our modes kept."""
    from tiledsimplify import metrics
    region = metrics.curvature_regions(case.X)
    target = int(round(case.ratio * len(case.X)))
    rows = []

    def add(label, fn, count, note=""):
        t = time.perf_counter()
        try:
            kept = fn(case.X, count)
        except Exception as exc:  # a peer failing on one input is reported, not fatal
            print(f"note: {label} failed on {case.name}: {type(exc).__name__}: {exc}",
                  file=sys.stderr)
            return None
        wall = time.perf_counter() - t
        m = measure(case, kept, region)
        group = kept.count if kept.boundary is not None else count  # ours: where it landed
        row = {"method": label, "count_target": count, "group": group, "kept": kept.count,
               "boundary": int(kept.boundary.sum()) if kept.boundary is not None else None,
               "seconds": kept.seconds, "wall": wall, "setting": kept.setting,
               "new_points": not kept.subset, "note": note, **m}
        rows.append(row)
        print(f"  {label:42s} kept {kept.count:7,d}  {kept.seconds:7.2f} s", file=sys.stderr,
              flush=True)
        return kept

    counts = [target]
    for label, fn in ours.items():
        kept = add(label, fn, target)
        if kept is not None and kept.count != target and kept.count not in counts:
            counts.append(kept.count)
    if case.edge_segments is not None:  # the ceiling of edge coverage for this sampling
        everything = np.ones(len(case.X), bool)
        add("(input: all points)",
            lambda X, c: peers.Kept(X, everything, 0.0, "all"), len(case.X))
    for count in counts:
        for label, fn in methods.items():
            add(label, fn, count)
    return {"case": case.name, "title": case.title, "n": len(case.X), "target": target,
            "counts": counts, "edge_truth": case.edge_segments is not None, "rows": rows}


def _f(v, scale=1e4, digits=0):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    return f"{scale * v:,.{digits}f}"


def table(result):
    lines = [f"### {result['title']}", ""]
    lines.append("| method | kept | boundary flagged | edge cov. | boundary P | boundary R "
                 "| boundary F1 | F1, seen edges | mean err | max err | Hausdorff | Chamfer "
                 "| adaptivity | s |")
    lines.append("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    order = {c: i for i, c in enumerate(result["counts"])}
    rows = sorted(result["rows"], key=lambda r: (order.get(r["group"], -1),
                                                 r["boundary"] is None))
    notes = set()
    group = None
    for r in rows:
        reference = r["method"] == "(input: all points)"
        if len(result["counts"]) > 1 and not reference and r["group"] != group:
            group = r["group"]
            what = ("the target" if group == result["target"]
                    else "the count our mode kept")
            lines.append(f"| *at {group:,} kept ({what})* |" + " |" * 13)
        label = r["method"]
        if r["new_points"]:
            label += " ¹"
            notes.add("¹ makes new points (not a subset): measured on its own points; "
                      "adaptivity needs a subset.")
        if r["boundary"] is not None and r["kept"] != result["target"]:
            label += " ²"
            notes.add(f"² could not reach {result['target']:,}: its boundary points alone "
                      "exceed the budget; the peers are also shown at its count.")
        get = r.get
        lines.append(
            f"| {label} | {r['kept']:,} | {r['boundary'] if r['boundary'] is not None else '–'} "
            f"| {_f(get('edge_coverage'), 1, 3)} | {_f(get('boundary_precision'), 1, 2)} "
            f"| {_f(get('boundary_recall'), 1, 2)} | {_f(get('boundary_f1'), 1, 2)} "
            f"| {_f(get('boundary_f1_seen'), 1, 2)} | {_f(get('surface_error_mean'), 1e4, 1)} "
            f"| {_f(get('surface_error_max'))} "
            f"| {_f(get('hausdorff'))} | {_f(get('chamfer'))} "
            f"| {_f(get('adaptivity'), 1, 2)} | {r['seconds']:.2f} |")
    lines.append("")
    lines += sorted(notes)
    if notes:
        lines.append("")
    return "\n".join(lines)


def _best(rows, key, lower):
    rows = [r for r in rows if r.get(key) is not None and not math.isnan(r[key])]
    if not rows:
        return None, "–"
    r = (min if lower else max)(rows, key=lambda r: r[key])
    return r[key], r["method"]


def summary(results):
    """One row per case and mode: ours against the best peer at the count the mode kept."""
    lines = ["| case | points | mode | kept (target) | edge cov.: ours / best peer "
             "| mean err: ours / best peer | Hausdorff: ours / best peer |",
             "|---|---:|---|---:|---|---|---|"]
    for res in results:
        for r in res["rows"]:
            if r["boundary"] is None:
                continue
            peers_here = [p for p in res["rows"] if p["boundary"] is None
                          and p["method"] != "(input: all points)"
                          and p["count_target"] == r["group"]]
            cells = []
            for key, lower, scale, digits in (("edge_coverage", False, 1, 3),
                                              ("surface_error_mean", True, 1e4, 1),
                                              ("hausdorff", True, 1e4, 0)):
                v, who = _best(peers_here, key, lower)
                mine = r.get(key)
                if mine is None or v is None:
                    cells.append("–")
                    continue
                win = (mine <= v) if lower else (mine >= v)
                mark = "**" if win else ""
                cells.append(f"{mark}{scale * mine:.{digits}f}{mark} / "
                             f"{scale * v:.{digits}f} ({who})")
            lines.append(f"| {res['case']} | {res['n']:,} | {r['method'].split()[-1]} "
                         f"| {r['kept']:,} ({res['target']:,}) | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def merge_results(runs):
    """Cases of several ``--json`` runs, later runs first: a case run again replaces the rows
    of the methods it ran (per method and count group) and keeps the others — so our modes can
    be re-run alone (``--skip all``) and shown beside the peers of an earlier run."""
    by_case = {}
    for run in runs:
        for r in run:
            for row in r["rows"]:
                row["method"] = RENAMED.get(row["method"], row["method"])
            old = by_case.get(r["case"])
            if old is None:
                by_case[r["case"]] = r
                continue
            new = {(row["method"], row["group"]) for row in r["rows"]}
            replaced = {row["method"] for row in r["rows"]}
            rows = [row for row in old["rows"] if row["method"] not in replaced
                    and (row["method"], row["group"]) not in new]
            merged = {**old, **{k: v for k, v in r.items() if k not in ("rows", "counts")}}
            merged["rows"] = r["rows"] + rows
            merged["counts"] = sorted(set(old["counts"]) | set(r["counts"]))
            by_case[r["case"]] = merged
    return list(by_case.values())


def parse_options(items, error):
    """``--option KEY=VALUE`` items as a mapping of ``SimplifyOptions`` fields (each value
    read as JSON where it parses, else kept as the string), checked against the options;
    ``error(message)`` (an argument parser's) is called on a malformed item or an unknown or
    invalid option."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            error(f"--option takes KEY=VALUE (a SimplifyOptions field), got {item!r}")
        try:
            out[key.strip()] = json.loads(value)
        except json.JSONDecodeError:
            out[key.strip()] = value
    from tiledsimplify import InputError, SimplifyOptions
    try:
        SimplifyOptions.from_mapping(out)
    except (InputError, TypeError) as exc:
        error(f"--option: {exc}")
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", default=None,
                   help="comma-separated case names or groups (all, cad, scans, quick)")
    p.add_argument("--quick", action="store_true", help="only " + ", ".join(QUICK))
    p.add_argument("--list", action="store_true", help="print the case names and exit")
    p.add_argument("--only", default=None, help="comma-separated peer names to run")
    p.add_argument("--skip", default="", help="comma-separated peer names to leave out "
                   "('all': no peers, e.g. to re-run our modes and merge with --from-json)")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="a SimplifyOptions field for our modes, e.g. edge_width=0.9 (repeatable)")
    p.add_argument("--modes", default=None,
                   help="comma-separated modes of ours to run (default: every mode)")
    p.add_argument("--cad-points", type=int, default=20_000,
                   help="points of the evenly sampled / scanned CAD parts (default 20000)")
    p.add_argument("--noises", default=None, metavar="N1,N2",
                   help="scanner noise levels of the CAD scan cases, in spacings (default "
                        + ",".join(map(str, NOISES)) + "), e.g. 0.05,0.3 to hold the tuned "
                        "levels out")
    p.add_argument("--lidar-points", type=int, default=None,
                   help="crop the LiDAR file to this many points around its centre")
    p.add_argument("--ratio", type=float, default=None,
                   help="keep this fraction in every case instead of its own (20 %% of the CAD "
                        "parts and Autzen, 10 %% of the Bunny), e.g. 0.05 or 0.02")
    p.add_argument("--json", default=None, help="also write every number to this JSON file")
    p.add_argument("--from-json", nargs="+", default=None, metavar="FILE",
                   help="print the tables and the summary of earlier --json runs; run nothing")
    args = p.parse_args(argv)
    if args.ratio is not None and not 0 < args.ratio <= 1:
        p.error(f"--ratio must be in (0, 1], got {args.ratio}")
    if args.from_json:
        results = merge_results(json.loads(Path(f).read_text()) for f in args.from_json)
        for res in results:
            print(table(res))
        print("### Summary: ours against the best peer at the same count\n")
        print(summary(results))
        return 0
    noises = NOISES
    if args.noises:
        try:
            noises = tuple(float(v) for v in args.noises.split(","))
        except ValueError:
            p.error(f"--noises takes comma-separated numbers, got {args.noises!r}")
        if not all(0 <= v < 10 for v in noises):
            p.error(f"--noises must be in [0, 10) spacings, got {args.noises!r}")
    if args.list:
        print("\n".join(case_names(noises)))
        print("groups:", ", ".join(_groups(noises)))
        return 0
    spec = "quick" if args.quick or not args.cases else args.cases
    groups = _groups(noises)
    names = []
    for item in spec.split(","):
        item = item.strip()
        for name in groups.get(item, [item]):
            if name not in names:
                names.append(name)
    unknown = [n for n in names if n not in case_names(noises)]
    if unknown:
        p.error(f"unknown case(s) {unknown}; --list shows the cases")
    only = set(args.only.split(",")) if args.only else None
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    methods = {} if "all" in skip else {k: v for k, v in peers.available(only).items()
                                          if k not in skip}
    overrides = parse_options(args.option, p.error)
    ours = peers.our_methods(overrides)
    if args.modes:
        modes = [m.strip() for m in args.modes.split(",")]
        unknown = [m for m in modes if f"tiledsimplify {m}" not in ours]
        if unknown:
            p.error(f"unknown mode(s) {unknown}; modes: {[k.split()[1] for k in ours]}")
        ours = {f"tiledsimplify {m}": ours[f"tiledsimplify {m}"] for m in modes}

    from tiledsimplify import simplify_points, synthetic
    from tiledsimplify.io import read_mesh
    V, F = read_mesh(MESHES / "cad_classic" / "fandisk.obj")
    simplify_points(synthetic.sample_surface(V, F, 2000, seed=0)[0], ratio=0.2)  # warm the JIT

    print(f"peers: {', '.join(methods)}; our modes: {', '.join(ours)}\n")
    results = []
    for name in names:
        t = time.perf_counter()
        print(f"{name} ...", file=sys.stderr, flush=True)
        case = load_case(name, args.cad_points, args.lidar_points)
        if args.ratio is not None:
            case.title = re.sub(r"\d+ %", f"{args.ratio:.0%}", case.title)
            case.ratio = args.ratio
        res = run_case(case, methods, ours)
        res["seconds_case"] = time.perf_counter() - t
        results.append(res)
        print(table(res), flush=True)
        if args.json:  # after every case, so a long run that is stopped keeps what it did
            Path(args.json).write_text(json.dumps(results, indent=1, default=float))
    print("### Summary: ours against the best peer at the same count\n")
    print(summary(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
