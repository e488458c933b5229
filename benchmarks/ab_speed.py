"""The core's speed at two revisions, in one process, calls alternating: is a change faster?

On this shared machine a run's speed drifts more than most changes move it (the 1M-point scan
through the pipeline took 8.9 s in a quiet hour of 2026-12-06 and 14.1-17.8 s on 2026-12-07,
old code and new alike; docs/measurements.md "Ten ideas for the lost targets, none kept"), and processes run one
after another see different moments of that drift. Here both revisions run in the same
process on the same cloud: the base revision's package is copied out of git (``git archive``)
under another name, its imports and its ``kernel_signatures.txt`` renamed, and imported
beside the working tree's ``tiledsimplify``; then ``simplify_points`` (or, with ``--pipeline
WORKERS``, ``tiledsimplify.run`` on local threads) runs alternately — A B, B A, A B, ... — so
that both see the same drift. The table gives, per stage (the result's ``seconds_*`` stats,
or the run's stages) and for the whole call, the fastest and the median of each and the
median of the per-round ratios B / A, which is what to read: below 1 the working tree (B) is
faster. It also says whether both kept the same points and flags (tiled runs: the same
output). The same code on both sides gave 0.989 and 0.994 for in-memory calls, 0.94-1.05 for
tiled runs of the 1M scan (docs/measurements.md "Two revisions in one process").

The copy is kept under ``$XDG_CACHE_HOME`` (or ``~/.cache``) ``/tiledsimplify/ab/<sha>``; its
kernels compile on its first call (90 s), into numba's cache beside the working tree's, so a
second run starts at once. The first call of each side on a small cloud warms both.

    python benchmarks/ab_speed.py scan:150000                  # HEAD against the working tree
    python benchmarks/ab_speed.py scan:150000 --base HEAD~3 --rounds 8
    python benchmarks/ab_speed.py case:tray_bottom             # a quality case at its ratio
    python benchmarks/ab_speed.py scan1m.laz --ratio 0.2       # a LAS/LAZ or point file
    python benchmarks/ab_speed.py scan1m.laz --pipeline 2 --tile-points 150000

Clouds: ``scan:N``, ``bunny:N``, ``flat:N`` as in ``core_speed.py`` (Fandisk by the line
scanner; the Bunny's real range scans; Fandisk sampled exactly), ``case:NAME`` a case of
``quality.py`` (its ratio unless ``--ratio`` is given), or a file (LAS/LAZ, or what
:func:`tiledsimplify.io.read_points` reads).
"""

import argparse
import importlib
import os
import re
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))

#: an import of the package, at the start of a line (the copy's are renamed)
IMPORT = re.compile(r"(?m)^(\s*)(from|import) tiledsimplify\b")


def _git(*args):
    try:
        out = subprocess.run(["git", "-C", str(REPO), *args], check=True, capture_output=True)
    except (OSError, subprocess.CalledProcessError) as e:
        err = getattr(e, "stderr", b"") or b""
        sys.exit(f"git {' '.join(args)} failed in {REPO}: {err.decode().strip() or e}. Fix: run "
                 "this from a git checkout of tiledsimplify and give a revision it has.")
    return out.stdout


def package_at(rev):
    """Import the package as it is at git revision ``rev``, under the name ``tsab_<sha>``
    (a copy in the cache directory, its imports renamed; made once per revision). Returns
    ``(module, sha)``."""
    sha = _git("rev-parse", "--verify", f"{rev}^{{commit}}").decode().strip()[:12]
    name = f"tsab_{sha}"
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "tiledsimplify"
    root = cache / "ab" / sha
    pkg = root / name
    if not (pkg / "__init__.py").exists():
        tmp = root / f"{name}.partial"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        with tarfile.open(fileobj=BytesIO(_git("archive", sha, "tiledsimplify"))) as tar:
            tar.extractall(tmp, filter="data")
        for path in (tmp / "tiledsimplify").rglob("*.py"):
            path.write_text(IMPORT.sub(rf"\1\2 {name}", path.read_text()))
        # the kernels the copy compiles ahead and loads (its own, not the working tree's)
        sigs = tmp / "tiledsimplify" / "core" / "kernel_signatures.txt"
        if sigs.exists():
            sigs.write_text(re.sub(r"(?m)^tiledsimplify\.", f"{name}.", sigs.read_text()))
        shutil.rmtree(pkg, ignore_errors=True)
        (tmp / "tiledsimplify").rename(pkg)  # complete or absent: never half a package
        shutil.rmtree(tmp)
    sys.path.insert(0, str(root))
    # its compile processes (``python -m <copy>.core.compile_cache``) import it too
    os.environ["PYTHONPATH"] = os.pathsep.join(
        [str(root), *filter(None, [os.environ.get("PYTHONPATH")])])
    return importlib.import_module(name), sha


def load_cloud(spec):
    """``(points, ratio or None)`` of a cloud spec (see the module notes)."""
    kind, _, rest = spec.partition(":")
    if kind in ("scan", "bunny", "flat") and rest.isdigit():
        from core_speed import cloud
        return cloud(kind, int(rest)), None
    if kind == "case" and rest:
        from quality import load_case
        case = load_case(rest)
        return case.X, case.ratio
    path = Path(spec)
    if not path.exists():
        sys.exit(f"not a cloud: {spec!r} is neither scan:N, bunny:N, flat:N, case:NAME nor an "
                 "existing file. Fix: give one of those (see the module docstring).")
    if path.suffix.lower() in (".las", ".laz"):
        import laspy
        f = laspy.read(path)
        return np.c_[f.x, f.y, f.z].astype(np.float64), None
    from tiledsimplify.io import read_points
    return read_points(path), None


def timed(pkg, X, ratio, options):
    """One call of ``pkg``'s ``simplify_points``: ``(seconds per stage incl. 'total', result)``."""
    t = time.perf_counter()
    res = pkg.simplify_points(X, ratio, options=options or None)
    total = time.perf_counter() - t
    stages = {k[len("seconds_"):]: v for k, v in res.stats.items() if k.startswith("seconds_")}
    stages["total"] = total
    return stages, res


def timed_run(pkg, path, out, ratio, options, workers, tile_points):
    """One tiled run of ``pkg`` (``pkg.run``, local threads) from ``path`` into ``out``:
    ``(seconds per stage incl. 'total', summary)``."""
    summary = pkg.run(path, out, ratio=ratio, options=options or None, workers=workers,
                      tile_points=tile_points)
    return dict(summary.seconds), summary


def same_output(path_a, path_b):
    """Whether two ``.npy`` outputs hold the same rows (in any order)."""
    a, b = np.load(path_a), np.load(path_b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.dtype.names is None:  # rows in lexicographic order (not each column sorted alone)
        return bool(np.array_equal(a[np.lexsort(a.T[::-1])], b[np.lexsort(b.T[::-1])]))
    return bool(np.array_equal(np.sort(a), np.sort(b)))  # structured: by field, then the next


def table(times_a, times_b):
    """Rows ``(stage, A min, A median, B min, B median, median of the rounds' B / A)``."""
    rows = []
    for stage in times_b:
        a = np.array(times_a.get(stage, []))
        b = np.array(times_b[stage])
        if len(a) != len(b) or not len(a):
            continue  # a stage one revision does not time
        ratio = np.median(b / a) if (a > 0).all() else float("nan")
        rows.append((stage, a.min(), np.median(a), b.min(), np.median(b), ratio))
    rows.sort(key=lambda r: r[0] != "total")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cloud", help="scan:N, bunny:N, flat:N, case:NAME or a point file")
    ap.add_argument("--base", default="HEAD", help="git revision A (default HEAD)")
    ap.add_argument("--ratio", type=float, help="fraction kept (default: the case's, else 0.2)")
    ap.add_argument("--rounds", type=int, default=6, help="calls of each (default 6)")
    ap.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                    help="a SimplifyOptions field for both sides")
    ap.add_argument("--pipeline", type=int, metavar="WORKERS",
                    help="time tiled runs (tiledsimplify.run, local threads, this many workers, "
                         ".npy output) instead of in-memory calls")
    ap.add_argument("--tile-points", type=int, help="with --pipeline: points per tile")
    args = ap.parse_args(argv)
    if args.rounds < 2:
        ap.error("--rounds: at least 2, so that each side runs first once")
    from quality import parse_options
    options = parse_options(args.option, ap.error)
    import tiledsimplify as b_pkg
    a_pkg, sha = package_at(args.base)
    X, case_ratio = load_cloud(args.cloud)
    ratio = args.ratio if args.ratio is not None else (case_ratio or 0.2)
    warm = X[np.random.default_rng(0).choice(len(X), min(len(X), 5000), replace=False)]
    what = (f"tiled runs on {args.pipeline} worker(s)" if args.pipeline else "in-memory calls")
    print(f"A: {args.base} ({sha}); B: the working tree ({Path(b_pkg.__file__).parent}); "
          f"{len(X):,} points of {args.cloud}, ratio {ratio}, {args.rounds} rounds of {what}",
          flush=True)
    with tempfile.TemporaryDirectory(prefix="ab_speed_") as tmp:
        tmp = Path(tmp)
        if args.pipeline:
            path = Path(args.cloud)
            if not path.is_file():  # a cloud made here: the runs read it from a file
                path = tmp / "cloud.npy"
                np.save(path, X)
            np.save(tmp / "warm.npy", warm)
            outs = {"A": tmp / "a.npy", "B": tmp / "b.npy"}

            def call(side, pkg):
                return timed_run(pkg, path, outs[side], ratio, options, args.pipeline,
                                 args.tile_points)

            def warm_up(pkg):  # as many workers as the rounds: a run's first C allocator
                # arena cap holds for the whole process (machine.cap_malloc_arenas)
                pkg.run(tmp / "warm.npy", tmp / "warm_out.npy", ratio=0.2,
                        workers=args.pipeline)
        else:
            def call(side, pkg):
                return timed(pkg, X, ratio, options)

            def warm_up(pkg):
                pkg.simplify_points(warm, 0.2)
        t = time.perf_counter()
        for pkg in (a_pkg, b_pkg):
            warm_up(pkg)
        print(f"warmed (kernels loaded or compiled) in {time.perf_counter() - t:.1f} s",
              flush=True)
        times = {"A": {}, "B": {}}
        results = {}
        for r in range(args.rounds):
            order = (("A", a_pkg), ("B", b_pkg)) if r % 2 == 0 else (("B", b_pkg), ("A", a_pkg))
            for side, pkg in order:
                stages, results[side] = call(side, pkg)
                for k, v in stages.items():
                    times[side].setdefault(k, []).append(v)
            print(f"  round {r + 1}: A {times['A']['total'][-1]:.3f} s, "
                  f"B {times['B']['total'][-1]:.3f} s", flush=True)
        print()
        print("| stage | A fastest s | A median s | B fastest s | B median s "
              "| B / A (median of rounds) |")
        print("|---|---:|---:|---:|---:|---:|")
        for stage, a_min, a_med, b_min, b_med, ratio_ in table(times["A"], times["B"]):
            print(f"| {stage} | {a_min:.3f} | {a_med:.3f} | {b_min:.3f} | {b_med:.3f} "
                  f"| {ratio_:.3f} |")
        ra, rb = results["A"], results["B"]
        print()
        if args.pipeline:
            same = same_output(outs["A"], outs["B"])
            print(f"kept points: {ra.n_output:,} (A) and {rb.n_output:,} (B); the outputs are "
                  f"{'the same' if same else 'not the same'}")
            return
        kept = int(np.count_nonzero(ra.keep != rb.keep))
        flags = int(np.count_nonzero(ra.boundary != rb.boundary))
        print(f"kept points: {int(ra.keep.sum()):,} (A) and {int(rb.keep.sum()):,} (B), "
              f"{'the same' if not kept else f'{kept:,} points differ'}; flags "
              f"{'the same' if not flags else f'{flags:,} points differ'}")


if __name__ == "__main__":
    main()
