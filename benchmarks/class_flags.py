"""Where the flags fall by LAS class, with and without ``no_edge_classes``.

``tiledsimplify.run`` on a classified LAS/LAZ file, once flagging every class and once with
``--no-edges-on`` (default 3,4,5,7,18: vegetation and noise), alternating, ``--rounds`` times;
for each class of the input the points kept and flagged, and each run's tile stage and whole
time.

    python benchmarks/class_flags.py ../shared/data/lidar/las_with_several_extra_byte_bloc.laz
    python benchmarks/class_flags.py tile.laz --classes 3,4,5 --ratio 0.1
"""

import argparse
import tempfile
from pathlib import Path

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("input", help="a classified LAS/LAZ file")
    ap.add_argument("--classes", default="3,4,5,7,18", help="the codes never edge points")
    ap.add_argument("--ratio", type=float, default=0.2)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args(argv)

    import laspy

    from tiledsimplify import run

    classes = [int(c) for c in args.classes.split(",")]
    codes = np.unique(np.asarray(laspy.read(args.input).classification)).tolist()
    settings = (("every class", None), (f"no edges on {args.classes}", classes))
    counts, times = {}, []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.laz"
        for _ in range(args.rounds):
            for name, no_edge in settings:
                s = run(args.input, out, ratio=args.ratio, workers=args.workers,
                        no_edge_classes=no_edge)
                got = laspy.read(out)
                c, e = np.asarray(got.classification), np.asarray(got.sharp_edge) > 0
                counts[name] = [(int((c == k).sum()), int(e[c == k].sum())) for k in codes]
                times.append((name, s.seconds["tiles"], s.seconds["total"], int(e.sum())))
    print(f"\n{args.input}, ratio {args.ratio}, {args.workers} workers: kept / flagged by class\n")
    print("| class | " + " | ".join(name for name, _ in settings) + " |")
    print("|---:|" + "---:|" * len(settings))
    for i, k in enumerate(codes):
        print(f"| {k} | " + " | ".join(f"{counts[n][i][0]:,} / {counts[n][i][1]:,}"
                                       for n, _ in settings) + " |")
    print("\n| run | tiles s | whole s | flags |")
    print("|---|---:|---:|---:|")
    for name, tiles, total, flags in times:
        print(f"| {name} | {tiles:.2f} | {total:.2f} | {flags:,} |")


if __name__ == "__main__":
    main()
