"""Command line: ``tiledsimplify simplify INPUT OUTPUT --ratio R``.

Exit codes: 0 done; 2 bad usage or bad input (the message names the file and the fix);
3 done, but the requested count could not be reached (more boundary points than the budget);
1 anything unexpected; 128 + the signal's number when stopped by SIGINT (130), SIGTERM (143)
or SIGHUP (129), after the same clean-up as a failure (no partial output, no temporary store).
"""

import argparse
import errno
import logging
import math
import os
import signal
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np

from . import __version__, machine
from .core import SimplifyOptions, compile_cache, simplify_points
from .core.edge_fit import CANDIDATE, MIN_ANGLE
from .core.options import EDGE_SHARE, MODES
from .core.simplify import PEAK_BYTES_PER_POINT
from .errors import BudgetWarning, FileFormatError, InputError, TiledSimplifyError
from .io.las import LAS_SUFFIXES
from .io.points_out import (
    attribute_columns,
    check_not_input,
    check_output,
    check_writable,
    largest_colour,
    whole_dtypes,
    write_json,
    write_points,
)
from .io.sources import degrees_message, open_source, read_all, read_all_dimensions

log = logging.getLogger("tiledsimplify")

EXIT_OK, EXIT_ERROR, EXIT_INPUT, EXIT_BUDGET = 0, 1, 2, 3

#: signals that stop a command the way Ctrl-C does (SIGINT): a scheduler's timeout or a job
#: being cancelled (cron's ``timeout``, Airflow, Slurm, Kubernetes send SIGTERM) and a closed
#: terminal (SIGHUP). Python's default for them ends the process at once, leaving the
#: temporary tile store behind (~43 bytes an input point) and no word in the log.
STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)
EDGE_ANGLE_HELP = ("mode coverage: the least fold of a sharp edge in degrees, above 0 and at "
                   f"most 90 (default {MIN_ANGLE:g}); lower flags shallower chamfers and bevels "
                   "too")
EDGE_SHARE_HELP = ("mode coverage: the most of the count that sharp-edge points are sure of, "
                   f"in (0, 1] (default {EDGE_SHARE:g}): where more are flagged, an even "
                   "sample along the edges of that many is kept for certain and the rest "
                   "compete with the other points (still flagged); inf keeps every flagged "
                   "point whatever the count")
MAX_SPACING_HELP = ("leave no input point farther than DISTANCE (model units) from a kept "
                    "point: removals that would are vetoed, so more than the count may be kept "
                    "(exit 3); alone (no --ratio or --count), keep as few points as that "
                    "allows")
#: the command's words for the budget message's options.boundary_threshold (core/result.py)
BUDGET_HINT = "on the command line, %s sets options.boundary_threshold%s"
#: ... and options.max_spacing, where the run had a guard
MAX_SPACING_HINT = " and --max-spacing DISTANCE options.max_spacing"


class Stopped(BaseException):
    """A stop signal arrived (not an ``Exception``: nothing on the way may swallow it)."""

    def __init__(self, signum):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _stop(signum, frame):
    for s in STOP_SIGNALS:  # once: a second signal must not cut the clean-up short (a temporary
        signal.signal(s, signal.SIG_IGN)  # store half deleted); main() restores the handlers
    raise Stopped(signum)


def _stop_behind(exc):
    """The stop (``Stopped`` or ``KeyboardInterrupt``) that ``exc`` wraps, else None.

    A signal that arrives while a numba kernel runs is handled when the kernel hands its
    result back to Python (numba unpickles the arrays' types there), and numba then raises
    ``SystemError: CPUDispatcher(...) returned a result with an exception set`` from the
    handler's exception: a stop all the same, not a bug."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, (Stopped, KeyboardInterrupt)):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def _number(text):
    """``text`` as a float, NaN if it is none (the parser types below then refuse it)."""
    try:
        return float(text)
    except ValueError:
        return math.nan


def _ratio(text):
    """A fraction of the points to keep, in (0, 1] (the API's own message names ``ratio=``)."""
    value = _number(text)
    if not 0 < value <= 1:
        raise argparse.ArgumentTypeError(f"expected a fraction of the points in (0, 1], got "
                                         f"{text!r}; give --count N for a number of points")
    return value


def _distance(text):
    """A positive, finite length in model units."""
    value = _number(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a positive distance in the input's units, "
                                         f"got {text!r}")
    return value


NO_EDGES_HELP = ("classification codes whose points are never edge points, e.g. 3,4,5,7,18 "
                 "(vegetation, noise): not flagged, not kept like edges, lending no edge line")


def _classes(text):
    """Classification codes: ``3,4,5`` (whole numbers 0-255, comma-separated)."""
    try:
        codes = [int(t) for t in text.replace(" ", "").split(",") if t]
    except ValueError:
        codes = []
    if not codes or not all(0 <= c <= 255 for c in codes):
        raise argparse.ArgumentTypeError(f"expected classification codes 0-255 separated by "
                                         f"commas, e.g. 3,4,5,7,18; got {text!r}")
    return codes


def _count(text):
    """A whole number of points: ``2000000``, ``2_000_000`` or ``2e6``."""
    try:
        return int(text)  # int() and float() read "2_000_000" themselves
    except ValueError:
        pass
    value = _number(text)
    if not (math.isfinite(value) and value.is_integer()):
        raise argparse.ArgumentTypeError(f"expected a whole number (2000000, 2_000_000 or 2e6), "
                                         f"got {text!r}")
    return int(value)


class _Parser(argparse.ArgumentParser):
    """argparse's parser, whose usage errors (exit 2) keep their message for ``--summary``."""

    def error(self, message):
        try:
            super().error(message)
        except SystemExit as exc:
            exc.usage_error = f"{self.prog}: error: {message}"
            raise


def _usage_summary(argv, message):
    """A ``run`` refused by argparse itself (``--ratio 0``, an unknown flag) still writes the
    ``--summary`` it was given, as every other failure does: the file left from an earlier run
    said exit code 0 to a pipeline reading it."""
    q = argparse.ArgumentParser(add_help=False)
    q.add_argument("command", nargs="?")
    q.add_argument("--summary")
    try:
        known, _ = q.parse_known_args(argv)
    except SystemExit:  # e.g. --summary without its value: no file to write
        return
    if known.command == "run" and known.summary:
        _failed_summary(argparse.Namespace(input=None, output=None, summary=known.summary),
                        EXIT_INPUT, message)


def _parser():
    p = _Parser(
        prog="tiledsimplify",
        description="Feature-preserving simplification of 3-D point clouds (Song & Feng).")
    p.add_argument("--version", action="version", version=f"tiledsimplify {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser(
        "simplify", help="simplify one cloud held in memory",
        description="Simplify one point cloud in memory, keeping and flagging sharp-edge "
                    "points. Output columns: the input's dimensions (LAS dimensions, PLY vertex "
                    "properties, E57 point fields; colour 8-bit), sharp_edge, "
                    "importance (at removal; NaN for kept points), simplify_rank (removal "
                    "order; -1 for kept), nx, ny, nz.")
    s.add_argument("input", help="LAS/LAZ (file, folder or glob), E57, PLY, OBJ/OFF/STL "
                                 "(vertices), XYZ/CSV/TXT or NPY; .gz allowed")
    s.add_argument("output", help="output .ply, .npy, .xyz or .csv")
    g = s.add_mutually_exclusive_group()
    g.add_argument("--ratio", type=_ratio, help="fraction of points to keep, in (0, 1]")
    g.add_argument("--count", type=_count, help="number of points to keep")
    s.add_argument("--all-points", action="store_true",
                   help="write every input point with its flags and rank, not only the kept")
    s.add_argument("--boundary-threshold", type=float, default=None,
                   help="fixed threshold on the normal-deviation measure (default: the "
                        f"mode's: {CANDIDATE:g} rad on the two-ring measure in coverage, "
                        "automatic in paper)")
    s.add_argument("--no-boundary", action="store_true", help="do not flag sharp-edge points")
    s.add_argument("--edge-angle", type=float, default=None, metavar="DEGREES",
                   help=EDGE_ANGLE_HELP)
    s.add_argument("--edge-share", type=float, default=None, metavar="SHARE",
                   help=EDGE_SHARE_HELP)
    s.add_argument("--max-spacing", type=_distance, default=None, metavar="DISTANCE",
                   help=MAX_SPACING_HELP)
    s.add_argument("--mode", choices=MODES, default=MODES[0],
                   help="coverage (default): thin edge flags, no emptied faces; paper: the "
                        "published rule")
    s.add_argument("--no-edges-on", dest="no_edge_classes", type=_classes, default=None,
                   metavar="CLASSES", help=NO_EDGES_HELP)
    s.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")

    r = sub.add_parser(
        "run", help="simplify a cloud of any size, tile by tile, in parallel",
        description="Stream the input into a zarr tile store, simplify every tile with the "
                    "points of its halo as neighbours (on dask workers), cut all tiles at one "
                    "global budget, refine the gaps and write one output. LAS/LAZ output keeps "
                    "every input dimension and adds sharp_edge, importance, simplify_rank; "
                    "PLY/NPY/XYZ/CSV output has the input's dimensions (colour 8-bit), then "
                    "sharp_edge, nx, ny, nz.")
    r.add_argument("input", help="LAS/LAZ file, folder or glob of LAS/LAZ tiles; E57 file, "
                                 "folder or glob; or PLY, XYZ/CSV/TXT, NPY")
    r.add_argument("output", help="output .las/.laz (of a non-LAS input: LAS 1.4 point "
                   "format 6, or 7 with colour, its other dimensions as extra bytes), .ply, "
                   ".npy, .xyz or .csv; a LAS/LAZ name with {stem} (out/{stem}.laz) writes one "
                   "output per input LAS/LAZ file, each with that file's kept points")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--ratio", type=_ratio, help="fraction of points to keep, in (0, 1]")
    g.add_argument("--count", type=_count, help="number of points to keep")
    r.add_argument("--config", help="TOML file: [run] ratio/count/tile_points/halo/floor/"
                                    "scheduler/workers/no_edge_classes, [simplify] core "
                                    "options (see "
                                    "configs/)")
    r.add_argument("--scheduler", default=None,
                   help="threads (default), processes, synchronous, or tcp://HOST:PORT (a "
                        "dask.distributed scheduler: its workers must see --store at the same "
                        "path and run this tiledsimplify; checked before the ingest)")
    r.add_argument("--workers", type=int, default=None,
                   help="local workers (default: one per CPU this process may use, by its "
                        "affinity and cgroup quota; fewer if their tiles would not fit in the "
                        "memory left)")
    r.add_argument("--store", default=None,
                   help="zarr tile store directory (default: temporary, under TMPDIR); "
                        "reuse it to resume after a failure or a stop (Ctrl-C, SIGTERM)")
    r.add_argument("--tile-points", type=_count, default=None,
                   help="points per tile (default: an eighth of the input, 100000 to 500000)")
    r.add_argument("--halo", type=float, default=None,
                   help="halo width in model units (default: 10 x estimated spacing)")
    r.add_argument("--mode", choices=MODES, default=None,
                   help="coverage (default) or paper; overrides [simplify] mode")
    r.add_argument("--edge-angle", type=float, default=None, metavar="DEGREES",
                   help=EDGE_ANGLE_HELP + "; overrides [simplify] edge_angle")
    r.add_argument("--edge-share", type=float, default=None, metavar="SHARE",
                   help=EDGE_SHARE_HELP + "; overrides [simplify] edge_share")
    r.add_argument("--max-spacing", type=_distance, default=None, metavar="DISTANCE",
                   help=MAX_SPACING_HELP + "; overrides [simplify] guard and max_spacing")
    r.add_argument("--no-edges-on", dest="no_edge_classes", type=_classes, default=None,
                   metavar="CLASSES", help=NO_EDGES_HELP + "; overrides [run] no_edge_classes")
    r.add_argument("--floor", type=float, default=None,
                   help="each tile first runs down to this fraction of the target ratio "
                        "(0.5); tiles the global cut needs deeper run again. Changes the "
                        "time, never the output")
    r.add_argument("--summary", default=None, metavar="FILE.json",
                   help="also write what the run did as JSON (counts, threshold, spacing, "
                        "seconds per stage, exit code), for pipelines")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")

    e = sub.add_parser(
        "evaluate", help="quality of a simplified cloud against its original",
        description="Surface error (after Pauly et al. 2002), Chamfer and Hausdorff distance "
                    "(divided by the original's bounding-box diagonal), and with --mesh the "
                    "coverage of the mesh's sharp edges (dihedral > 30 degrees).")
    e.add_argument("original", help="the original points (any input format of run, LAS/LAZ "
                                     "included)")
    e.add_argument("simplified", help="the simplified points (any input format of run)")
    e.add_argument("--mesh", help="a CAD mesh of the part: also measure sharp-edge coverage")
    e.add_argument("--spacing", type=float, default=None,
                   help="original point spacing (default: median nearest-neighbour distance)")
    e.add_argument("--json", action="store_true", help="print JSON instead of a table")
    e.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")

    rp = sub.add_parser(
        "report", help="figures and a quality summary of a simplified cloud",
        description="Draw the original cloud, its sharp-edge points (the RESULT's sharp_edge "
                    "flags) and the simplified cloud, like the paper's Figs. 2-3, and write "
                    "report.md with the quality measures of 'tiledsimplify evaluate'. Needs "
                    "matplotlib: pip install 'tiledsimplify[report]'.")
    rp.add_argument("input", help="the original points (any input format of run)")
    rp.add_argument("result", help="the simplified points, ideally a tiledsimplify output "
                                   "(LAS/LAZ, PLY, NPY, XYZ/CSV with columns)")
    rp.add_argument("-o", "--output", required=True, help="directory for the PNGs and "
                                                          "report.md (created if missing)")
    rp.add_argument("--mesh", help="a CAD mesh of the part: also measure sharp-edge coverage "
                                   "and boundary precision/recall")
    rp.add_argument("--spacing", type=float, default=None,
                    help="original point spacing (default: median nearest-neighbour distance)")
    rp.add_argument("--up", choices=("x", "y", "z"), default=None,
                    help="model axis drawn upwards (default: z for LAS/LAZ input, else y)")
    rp.add_argument("--view", default="20,-60",
                    help="camera elevation,azimuth in degrees (default 20,-60)")
    rp.add_argument("--max-plot-points", type=int, default=200_000,
                    help="draw at most this many points per panel (default 200000)")
    rp.add_argument("--dpi", type=int, default=150,
                    help="pixels per inch; a panel is 6 x dpi pixels on its longer side, "
                         "shaped as the view within 3:1, plus a title line (default 150)")
    rp.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")
    c = sub.add_parser(
        "compile", help="compile the kernels into the cache now (once per machine or image)",
        description="Compile every numba kernel into the on-disk cache, in parallel processes, "
                    "so that no later run on this machine (or in an image built with this "
                    "step) spends its first ~40 s compiling. The cache is "
                    "$NUMBA_CACHE_DIR, else ~/.cache/tiledsimplify; a warm cache returns at "
                    "once. 'run' and 'simplify' also do this by themselves on a cold cache.")
    c.add_argument("--jobs", type=int, default=None,
                   help="compile processes (default: one per CPU this process may use)")
    c.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")
    return p


def _compile(args):
    if args.jobs is not None and args.jobs < 1:
        raise TiledSimplifyError(f"--jobs must be at least 1, got {args.jobs}.")
    done = compile_cache.compile_all(args.jobs)
    if not done["compiled"] and not done["failed"]:
        log.info("every kernel is already in the cache (%s)", compile_cache.cache_dir())
    return EXIT_ERROR if done["failed"] else EXIT_OK


def _check_pair(original, simplified, doing, verb):
    """Open both clouds of ``evaluate`` / ``report`` and refuse them now if holding both would
    need more than the memory left (:func:`check_memory`, ``metrics.EVALUATE_BYTES_PER_POINT``
    a point of either). Returns the two sources."""
    from . import metrics
    sources = open_source(original), open_source(simplified)
    for path, source, what in ((original, sources[0], "original"),
                               (simplified, sources[1], "simplified")):
        if source.count == 0:  # metrics would say "`kept` must contain at least 1 point(s)"
            raise InputError(f"{path}: the {what} cloud has no points; nothing to measure. "
                             "Check that it is the file you meant.")
    if sources[1].count > sources[0].count:
        log.warning("%s holds more points (%s) than %s (%s): the original comes first, then "
                    "the simplified cloud; are they swapped?", simplified,
                    f"{sources[1].count:,}", original, f"{sources[0].count:,}")
    check_memory(f"{original} and {simplified}", sum(s.count for s in sources),
                 per_point=metrics.EVALUATE_BYTES_PER_POINT + 24, doing=doing,
                 fix=f"{verb} a part: crop both clouds to "
                     "the same region first (e.g. `pdal translate in.laz part.laz crop "
                     "--filters.crop.bounds=…`), or free memory.")
    return sources


def _report(args):
    from .report import make_report
    if os.path.exists(args.output) and not os.path.isdir(args.output):
        raise InputError(f"{args.output}: exists and is not a directory; give -o a directory "
                         "(new or existing) for the report's files.")
    _check_pair(args.input, args.result, "reporting on", "Report on")
    try:
        elev, azim = (float(v) for v in args.view.split(","))
    except ValueError:
        raise TiledSimplifyError(f"--view must be ELEVATION,AZIMUTH in degrees, e.g. 20,-60; "
                                 f"got {args.view!r}.") from None
    rep = make_report(args.input, args.result, args.output, mesh=args.mesh,
                      spacing=args.spacing, up=args.up, elev=elev, azim=azim,
                      max_plot_points=args.max_plot_points, dpi=args.dpi)
    log.info("wrote %s", ", ".join(str(p) for p in rep.files.values()))
    return EXIT_OK


def _evaluate(args):
    import json

    from . import metrics, synthetic
    from .io import read_mesh
    sources = _check_pair(args.original, args.simplified, "evaluating", "Evaluate")
    original, kept = (read_all(s) for s in sources)
    if len(kept) == len(original) and np.array_equal(kept, original):
        # an --all-points output: every input point with its rank, -1 the kept ones (as
        # `report` reads it); measured whole, it scored a perfect Hausdorff distance of 0
        from .io.columns import read_columns
        rank = read_columns(args.simplified)[1].get("simplify_rank")
        if rank is not None:
            kept = original[np.asarray(rank) == -1]
            log.info("%s: an --all-points output; measuring its %s kept points (rank -1)",
                     args.simplified, f"{len(kept):,}")
            if not len(kept):
                raise InputError(f"{args.simplified}: no point has simplify_rank -1 (kept); "
                                 "nothing to measure.")
    kw = {"spacing": args.spacing}
    if args.mesh:
        V, F = read_mesh(args.mesh)
        s = args.spacing or metrics.spacing(original)
        kw.update(spacing=s, edge_samples=synthetic.sample_edges(V, F, s))
    result = metrics.evaluate(original, kept, **kw)
    if args.json:
        print(json.dumps(metrics.as_json(result), indent=2))
    else:
        for key, value in result.items():
            print(f"{key:22s} {value:.6g}")
    return EXIT_OK


def _load_config(path):
    import tomllib
    try:
        with open(path, "rb") as fh:
            cfg = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise TiledSimplifyError(f"{path}: not valid TOML ({exc}); fix the file.") from None
    unknown = sorted(set(cfg) - {"run", "simplify"})
    if unknown:
        raise TiledSimplifyError(f"{path}: unknown section(s) {unknown}; use [run] and "
                                 "[simplify].")
    return cfg.get("run", {}), cfg.get("simplify", {})


#: the keys of a config file's [run] table and the types they take
RUN_KEYS = {"ratio": (int, float), "count": (int, float), "scheduler": (str,),
            "workers": (int, float), "tile_points": (int, float), "halo": (int, float),
            "floor": (int, float), "no_edge_classes": (list,)}


#: how an error names the type of a [run] key
_KIND = {(str,): "a name", (list,): "a list of classification codes, e.g. [3, 4, 5]"}


def _run(args):
    from .pipeline import run
    run_cfg, simplify_cfg = _load_config(args.config) if args.config else ({}, {})
    unknown = sorted(set(run_cfg) - set(RUN_KEYS))
    if unknown:
        raise TiledSimplifyError(f"{args.config}: unknown [run] key(s) {unknown}; known: "
                                 f"{sorted(RUN_KEYS)}.")
    for key, value in run_cfg.items():
        if isinstance(value, bool) or not isinstance(value, RUN_KEYS[key]):
            raise TiledSimplifyError(
                f"{args.config}: [run] {key} must be "
                f"{_KIND.get(RUN_KEYS[key], 'a number')}, got {value!r}.")
    for key in RUN_KEYS:  # command line wins over the config file
        value = getattr(args, key)
        if value is not None:
            run_cfg[key] = value
    if "ratio" in run_cfg and "count" in run_cfg and (args.ratio is not None
                                                      or args.count is not None):
        run_cfg.pop("count" if args.ratio is not None else "ratio")
    if args.mode is not None:
        simplify_cfg = {**simplify_cfg, "mode": args.mode}
    simplify_cfg = {**simplify_cfg, **_option_flags(args)}
    try:  # before the count: a config's max_spacing without its guard is named as such
        options = SimplifyOptions.from_mapping(simplify_cfg)
    except InputError as exc:
        if not args.config:
            raise
        raise InputError(f"{args.config}: [simplify] {exc}") from None
    if ("ratio" not in run_cfg and "count" not in run_cfg
            and options.guard != "max_spacing"):  # the API says "ratio= or count="
        raise InputError("give --ratio R (a fraction of the points, in (0, 1]) or --count N, "
                         "or ratio / count in the [run] table of --config; or --max-spacing "
                         "DISTANCE alone to keep as few points as that allows.")
    if args.summary:
        check_writable(args.summary)
    summary = run(args.input, args.output, ratio=run_cfg.get("ratio"),
                  count=run_cfg.get("count"), options=options,
                  scheduler=run_cfg.get("scheduler", "threads"), workers=run_cfg.get("workers"),
                  store=args.store, tile_points=run_cfg.get("tile_points"),
                  halo=run_cfg.get("halo"), floor=run_cfg.get("floor", 0.5),
                  no_edge_classes=run_cfg.get("no_edge_classes"),
                  progress=not (args.no_progress or args.quiet))
    code = EXIT_OK if summary.reached else EXIT_BUDGET
    if not summary.reached:
        log.warning(BUDGET_HINT, "a [simplify] boundary_threshold in a --config file",
                    MAX_SPACING_HINT if options.guard == "max_spacing" else "")
    if args.summary:
        write_json(args.summary, {"input": str(args.input), "version": __version__,
                                  **summary.to_dict(), "exit_code": code})
        log.info("wrote the run summary to %s", args.summary)
    return code


def check_memory(name, n, room=None, per_point=PEAK_BYTES_PER_POINT + 24, doing="simplifying",
                 fix=None):
    """Refuse to hold ``n`` points in memory (``per_point`` bytes each at the peak; by default
    :func:`simplify_points`'s and the (n, 3) float64 points themselves) where that would need
    more than the memory left (:func:`.machine.available_memory`, or ``room`` bytes): the OOM
    killer would end the command later without a word. ``fix`` says what to do instead; by
    default ``tiledsimplify run``, which holds a few tiles at a time."""
    need = n * per_point
    if room is None:
        room = machine.available_memory()
    if room is not None and need > room:
        fix = fix or (f"Use `tiledsimplify run {name} OUTPUT --ratio R` instead: it simplifies "
                      "tile by tile in memory bounded by the tile size (LAS/LAZ, PLY, NPY or "
                      "text output), or free memory.")
        raise InputError(f"{name}: {doing} {n:,} points in memory needs about "
                         f"{machine.gb(need)}, but {machine.gb(room)} of memory is available. "
                         f"{fix}")


def _option_flags(args):
    """The core options both commands take as flags: ``--edge-angle``, ``--edge-share``,
    ``--max-spacing``."""
    flags = {} if args.edge_angle is None else {"edge_angle": args.edge_angle}
    if args.edge_share is not None:
        flags["edge_share"] = args.edge_share
    if args.max_spacing is not None:
        flags.update(guard="max_spacing", max_spacing=args.max_spacing)
    return flags


def _simplify(args):
    t0 = time.perf_counter()
    options = SimplifyOptions(mode=args.mode, boundary_threshold=args.boundary_threshold,
                              detect_boundary=not args.no_boundary,
                              **_option_flags(args))  # before reading
    if args.ratio is None and args.count is None and args.max_spacing is None:
        raise InputError("give --ratio R (a fraction of the points, in (0, 1]) or --count N; "
                         "or --max-spacing DISTANCE alone to keep as few points as that allows.")
    if Path(args.output).suffix.lower() in LAS_SUFFIXES:
        raise FileFormatError(f"{args.output}: simplify writes .npy, .ply, .xyz, .txt or .csv; "
                              f"for a LAS/LAZ output that keeps every input dimension use "
                              f"`tiledsimplify run {args.input} {args.output} --ratio R` (the "
                              "same algorithm, tile by tile).")
    check_output(args.output)
    check_not_input(args.output, [args.input])
    source = open_source(args.input)
    check_memory(args.input, source.count)
    xyz, dims = read_all_dimensions(source)
    log.info("read %d points from %s in %.2f s", len(xyz), args.input, time.perf_counter() - t0)
    if len(xyz) == 0:
        raise TiledSimplifyError(f"{args.input}: the input has no points; nothing to simplify. "
                                 "Check that it is the file you meant.")
    degrees = degrees_message(args.input, xyz.min(axis=0), xyz.max(axis=0))
    if degrees:
        log.warning("%s", degrees)
    if machine.cpus() > 1:  # a cold cache: all cores compile (at once if warm)
        compile_cache.compile_all()
    edge_ok = None
    if args.no_edge_classes:
        from .pipeline.tile_task import classes_ok, missing_classification
        if "classification" not in dims:
            raise missing_classification(args.input, dims)
        edge_ok = classes_ok(dims["classification"], args.no_edge_classes)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", BudgetWarning)
        res = simplify_points(xyz, args.ratio, count=args.count, options=options,
                              edge_ok=edge_ok)
    for w in caught:
        log.warning("%s", w.message)
    st = res.stats
    log.info("neighbours %.2f s, boundary %.2f s, removal %.2f s; %d boundary points "
             "(threshold %.3g)", st["seconds_neighbours_normals"], st["seconds_boundary"],
             st["seconds_removal"], st["n_boundary"], res.threshold)
    sel = np.ones(res.n, bool) if args.all_points else res.keep
    own = ("sharp_edge", "importance", "simplify_rank", "nx", "ny", "nz")
    # a text file's columns of whole numbers as integers, as a tiled run writes them
    from .tiles.ingest import value_stats
    guessed = [name for name in getattr(source, "guessed", ()) if name in dims]
    types = whole_dtypes({name: v.dtype for name, v in dims.items()},
                         value_stats({name: dims[name] for name in guessed}), guessed)
    dims = {name: v.astype(types[name], copy=False) for name, v in dims.items()}
    columns = {  # the input's dimensions first (colour 8-bit), then the simplifier's
        **attribute_columns({name: v[sel] for name, v in dims.items()}, largest_colour(dims),
                            own),
        "sharp_edge": res.boundary[sel].astype(np.uint8),
        "importance": res.importance[sel],
        "simplify_rank": res.rank[sel],
        "nx": res.normals[sel, 0], "ny": res.normals[sel, 1], "nz": res.normals[sel, 2],
    }
    write_points(args.output, xyz[sel], columns)
    log.info("wrote %d of %d points to %s (%.2f s in all)", int(sel.sum()), res.n, args.output,
             time.perf_counter() - t0)
    if not res.reached:
        log.warning(BUDGET_HINT, "--boundary-threshold T",
                    MAX_SPACING_HINT if options.guard == "max_spacing" else "")
    return EXIT_OK if res.reached else EXIT_BUDGET


def _stopped_message(args, signum, seconds):
    """What a stopped command leaves, and how to go on."""
    said = f"stopped by {signal.Signals(signum).name} after {seconds:.0f} s"
    if args.command != "run":
        return f"{said}; nothing written."
    if args.store:
        return (f"{said}; no output written. The finished tiles stay in {args.store}: run the "
                "same command (same --store) to go on from them.")
    return (f"{said}; no output written, and the temporary tile store was removed. Give --store "
            "DIR to make a long run resumable.")


def main(argv=None):
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exc:
        if getattr(exc, "usage_error", None):
            _usage_summary(sys.argv[1:] if argv is None else argv, exc.usage_error)
        raise
    logging.basicConfig(level=logging.WARNING if args.quiet else logging.INFO,
                        format="%(asctime)s %(levelname)s %(message)s", stream=sys.stderr)
    # laspy logs a read error before raising it; the error we report quotes it with the file
    logging.getLogger("laspy").setLevel(logging.CRITICAL)
    t0 = time.perf_counter()
    handlers = {}
    if threading.current_thread() is threading.main_thread():  # signals reach it alone
        handlers = {s: signal.signal(s, _stop) for s in STOP_SIGNALS}
    try:
        command = {"run": _run, "simplify": _simplify, "evaluate": _evaluate,
                   "report": _report, "compile": _compile}[args.command]
        return command(args)
    except FileNotFoundError as exc:
        why = exc.strerror if exc.strerror and exc.strerror not in (
            os.strerror(errno.ENOENT), "No such file") else "file not found"  # else ours: says more
        message = f"{exc.filename or exc}: {why}. Check the path."
        code = EXIT_INPUT
    except (TiledSimplifyError, ValueError, ImportError) as exc:
        message, code = str(exc), EXIT_INPUT
    except OSError as exc:  # the machine, not the input: a full disk, a lost mount (the
        # output writers' errors say what to do; "No space left on device" says it itself)
        where = f"{exc.filename}: " if exc.filename else ""
        message, code = f"{where}{exc.strerror or exc}.", EXIT_ERROR
    except (KeyboardInterrupt, Stopped, Exception) as exc:  # a stop (perhaps wrapped by
        # numba), everything on the way cleaned up after it; else a bug: its traceback follows
        # (exit 1), but a pipeline reading --summary must still learn that the run failed
        stop = _stop_behind(exc)
        if stop is None:
            if args.command == "run" and getattr(args, "summary", None):
                _failed_summary(args, EXIT_ERROR,
                                f"unexpected error: {type(exc).__name__}: {exc}")
            raise
        signum = getattr(stop, "signum", signal.SIGINT)
        message, code = _stopped_message(args, signum, time.perf_counter() - t0), 128 + signum
    finally:
        for s, h in handlers.items():
            signal.signal(s, h)
    log.error("%s", message)
    if args.command == "run" and getattr(args, "summary", None):
        _failed_summary(args, code, message)
    return code


def _failed_summary(args, code, message):
    """``--summary`` of a run that failed or was stopped: what was asked, the exit code and
    the message, so a pipeline reading the file learns as much as from the log."""
    try:
        write_json(args.summary, {"input": None if args.input is None else str(args.input),
                                  "output": None if args.output is None else str(args.output),
                                  "version": __version__, "exit_code": code, "error": message})
    except OSError as exc:  # the summary's own path may be what failed
        log.error("could not write the run summary to %s (%s)", args.summary, exc)
    else:
        log.info("wrote the run summary to %s", args.summary)


if __name__ == "__main__":
    sys.exit(main())
