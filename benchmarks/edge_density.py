"""Edge flags against sampling density: how dense a part must be sampled for its edges.

Each CAD case of ``quality.py`` (even sampling, or ``PART-scanNOISE``) at several point
counts, default mode at 20 %: the flagged points' precision, recall and F1 against the points
within one spacing of a sharp edge (DESIGN.md §4), with the spacing and the count of
candidates (two-ring deviation above the threshold). Walls thinner than a few spacings put
both faces in every neighbourhood; this shows at which density a part's walls resolve.

    python benchmarks/edge_density.py tray_bottom 20000 80000 200000
    python benchmarks/edge_density.py fandisk-scan0.1 20000 100000
"""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from quality import load_case  # noqa: E402


def row(name, n_points):
    from tiledsimplify import metrics, simplify_points
    case = load_case(name, n_cad=n_points)
    t = time.perf_counter()
    res = simplify_points(case.X, ratio=0.2)
    seconds = time.perf_counter() - t
    d = metrics.boundary_detection(case.X, res.boundary, edge_segments=case.edge_segments,
                                   spacing=case.spacing)
    return (f"| {name} | {len(case.X):,} | {case.spacing:.4g} | {int(d['n_positive']):,} "
            f"| {int((res.deviation > res.threshold).sum()):,} | {int(d['n_flagged']):,} "
            f"| {d['precision']:.2f} | {d['recall']:.2f} | {d['f1']:.2f} | {seconds:.1f} |")


def main(argv):
    if len(argv) < 2 or not all(a.isdigit() for a in argv[1:]):
        sys.exit("usage: edge_density.py CASE POINTS [POINTS ...]  (cases: quality.py --list)")
    print("| case | points | spacing | true edge points | candidates | flagged | P | R | F1 "
          "| s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n in argv[1:]:
        print(row(argv[0], int(n)), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
