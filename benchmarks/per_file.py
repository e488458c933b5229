"""One output per input file against one output: the output stage's time and bytes.

A LAS/LAZ file is cut into a K x K grid of files by x and y quantiles (in a temporary folder),
then ``tiledsimplify.run`` simplifies the folder into one LAZ output and into one per file
(``out/{stem}.laz``), alternating, ``--rounds`` times each; the table gives the output stage
(wall and CPU seconds of this process), the whole run, the points kept, the bytes written and
the most outputs open at once (``LasOutput`` counted).

    python benchmarks/per_file.py ../shared/data/lidar/las_with_several_extra_byte_bloc.laz
    python benchmarks/per_file.py tile.laz --grid 12 --rounds 1
"""

import argparse
import shutil
import tempfile
from pathlib import Path

import numpy as np


def cut(path, grid, folder):
    """``path``'s points in ``grid`` x ``grid`` files by x and y quantiles; their paths."""
    import laspy
    src = laspy.read(path)
    x, y = np.asarray(src.x), np.asarray(src.y)
    q = np.linspace(0, 1, grid + 1)[1:-1]
    ix, iy = np.searchsorted(np.quantile(x, q), x), np.searchsorted(np.quantile(y, q), y)
    out = []
    for i in range(grid):
        for j in range(grid):
            m = (ix == i) & (iy == j)
            if m.any():
                las = laspy.LasData(src.header)
                las.points = src.points[m]
                out.append(folder / f"t{i:02d}{j:02d}.laz")
                las.write(out[-1])
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("input", help="a LAS/LAZ file")
    ap.add_argument("--grid", type=int, default=3, help="cut into GRID x GRID files (3)")
    ap.add_argument("--ratio", type=float, default=0.2)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args(argv)

    import tiledsimplify.io.las_output as las_output
    from tiledsimplify import run

    real = las_output.LasOutput
    opened = [0, 0]  # open now, most at once

    class Counted(real):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            opened[0] += 1
            opened[1] = max(opened)

        def close(self):
            opened[0] -= 1
            return super().close()

    las_output.LasOutput = Counted
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "in").mkdir()
        files = cut(args.input, args.grid, tmp / "in")
        for _ in range(args.rounds):
            for how in ("one output", f"one per file ({len(files)})"):
                out = tmp / "out"
                shutil.rmtree(out, ignore_errors=True)
                out.mkdir()
                opened[:] = [0, 0]
                target = out / "one.laz" if how == "one output" else str(out / "{stem}.laz")
                s = run(str(tmp / "in" / "*.laz"), target, ratio=args.ratio,
                        workers=args.workers)
                size = sum(p.stat().st_size for p in out.iterdir())
                rows.append((how, s.seconds["output"], s.cpu_seconds["output"],
                             s.seconds["total"], s.n_output, size, opened[1]))
    las_output.LasOutput = real
    print(f"\n{args.input} cut into {len(files)} files, ratio {args.ratio}, "
          f"{args.workers} workers\n")
    print("| output | output stage s | its CPU s | whole run s | kept | bytes | most open |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for how, wall, cpu, total, kept, size, most in rows:
        print(f"| {how} | {wall:.2f} | {cpu:.2f} | {total:.1f} | {kept:,} | {size:,} | {most} |")


if __name__ == "__main__":
    main()
