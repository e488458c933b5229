"""Command line: ``tiledsimplify simplify INPUT OUTPUT --ratio R``.

Exit codes: 0 done; 2 bad usage or bad input (the message names the file and the fix);
3 done, but the requested count could not be reached (more boundary points than the budget);
1 anything unexpected.
"""

import argparse
import logging
import sys
import time
import warnings

import numpy as np

from . import __version__
from .core import SimplifyOptions, simplify_points
from .errors import BudgetWarning, TiledSimplifyError
from .io import read_points
from .io.points_out import write_points

log = logging.getLogger("tiledsimplify")

EXIT_OK, EXIT_ERROR, EXIT_INPUT, EXIT_BUDGET = 0, 1, 2, 3


def _parser():
    p = argparse.ArgumentParser(
        prog="tiledsimplify",
        description="Feature-preserving simplification of 3-D point clouds (Song & Feng).")
    p.add_argument("--version", action="version", version=f"tiledsimplify {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser(
        "simplify", help="simplify one cloud held in memory",
        description="Simplify one point cloud in memory, keeping and flagging sharp-edge "
                    "points. Output columns: sharp_edge, importance (at removal; NaN for kept "
                    "points), simplify_rank (removal order; -1 for kept), nx, ny, nz.")
    s.add_argument("input", help="PLY, OBJ/OFF/STL (vertices), XYZ/CSV/TXT or NPY; .gz allowed")
    s.add_argument("output", help="output .ply, .npy, .xyz or .csv")
    g = s.add_mutually_exclusive_group(required=True)
    g.add_argument("--ratio", type=float, help="fraction of points to keep, in (0, 1]")
    g.add_argument("--count", type=int, help="number of points to keep")
    s.add_argument("--all-points", action="store_true",
                   help="write every input point with its flags and rank, not only the kept")
    s.add_argument("--boundary-threshold", type=float, default=None,
                   help="fixed threshold on the normal-deviation measure (default: automatic)")
    s.add_argument("--no-boundary", action="store_true", help="do not flag sharp-edge points")
    s.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")
    return p


def _simplify(args):
    t0 = time.perf_counter()
    xyz = read_points(args.input)
    log.info("read %d points from %s in %.2f s", len(xyz), args.input, time.perf_counter() - t0)
    options = SimplifyOptions(boundary_threshold=args.boundary_threshold,
                              detect_boundary=not args.no_boundary)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", BudgetWarning)
        res = simplify_points(xyz, args.ratio, count=args.count, options=options)
    for w in caught:
        log.warning("%s", w.message)
    st = res.stats
    log.info("neighbours %.2f s, boundary %.2f s, removal %.2f s; %d boundary points "
             "(threshold %.3g)", st["seconds_neighbours_normals"], st["seconds_boundary"],
             st["seconds_removal"], st["n_boundary"], res.threshold)
    sel = np.ones(res.n, bool) if args.all_points else res.keep
    columns = {
        "sharp_edge": res.boundary[sel].astype(np.uint8),
        "importance": res.importance[sel],
        "simplify_rank": res.rank[sel],
        "nx": res.normals[sel, 0], "ny": res.normals[sel, 1], "nz": res.normals[sel, 2],
    }
    write_points(args.output, xyz[sel], columns)
    log.info("wrote %d of %d points to %s (%.2f s in all)", int(sel.sum()), res.n, args.output,
             time.perf_counter() - t0)
    return EXIT_OK if res.reached else EXIT_BUDGET


def main(argv=None):
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING if args.quiet else logging.INFO,
                        format="%(asctime)s %(levelname)s %(message)s", stream=sys.stderr)
    try:
        return _simplify(args)
    except FileNotFoundError as exc:
        log.error("%s: file not found. Check the path.", exc.filename or exc)
        return EXIT_INPUT
    except (TiledSimplifyError, ValueError) as exc:
        log.error("%s", exc)
        return EXIT_INPUT


if __name__ == "__main__":
    sys.exit(main())
