"""The tools a user would pick instead of tiledsimplify, each driven to a requested kept count.

Every method is a function ``(X, count, *, seed=0) -> Kept``: ``X`` is an (n, 3) float array,
``count`` the number of points wanted. Methods whose only knob is a size (voxel edge, grid
cell, cluster variation) are driven to the count by bisecting that knob; the closest count
reached is used (exact where the knob allows it, otherwise within a fraction of a percent —
the table prints the count each method really kept). ``Kept.seconds`` is one call of the
library at the final setting (the bisection is calibration, not counted); conversion of the
numpy array into a library's own container is not counted either, which flatters the peers,
not us.

Subset methods return a boolean mask over ``X``. Two peers make new points instead:
WLOP (CGAL; locally optimal projection) and Open3D's voxel grid (voxel centroids). They are
evaluated on their own points (``Kept.subset`` is False), and measures that need a subset
(adaptivity) are left empty.

Peers are optional benchmark dependencies (``pip install -e ".[bench]"``): a peer whose
package cannot be imported is skipped with a printed note, never an error.

    python benchmarks/peers.py            # which peers are available here
"""

from __future__ import annotations

import importlib
import math
import sys
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree


@dataclass
class Kept:
    """What one method kept."""

    points: np.ndarray  # (m, 3) kept coordinates
    keep: np.ndarray | None = None  # bool (n,) for subset methods, else None
    seconds: float = float("nan")  # one call at the final setting
    setting: str = ""  # the final value of the knob, for the record
    boundary: np.ndarray | None = None  # bool (n,) points flagged on sharp edges (ours only)
    extra: dict = field(default_factory=dict)

    @property
    def subset(self) -> bool:
        return self.keep is not None

    @property
    def count(self) -> int:
        return len(self.points)


def _mask(n, idx):
    keep = np.zeros(n, bool)
    keep[np.asarray(idx, dtype=np.int64)] = True
    return keep


def drive(call, lo, hi, count, *, decreasing, iters=60, log=True):
    """Bisect a monotone size knob until ``call(knob)`` keeps ``count`` points.

    ``call(value) -> (kept_count, payload, seconds)``. ``decreasing``: the count falls as the
    knob grows (voxel edge) — otherwise it rises. The bracket [lo, hi] is widened (x4 per step)
    until it contains the count. Returns ``(value, payload, seconds, calls)`` of the closest
    count seen (the first one, if several are equally close).
    """
    best = None
    calls = 0

    def probe(v):
        nonlocal best, calls
        c, payload, sec = call(v)
        calls += 1
        if best is None or abs(c - count) < abs(best[1] - count):
            best = (v, c, payload, sec)
        return c

    def too_many(c):  # the knob must move towards fewer points
        return c > count

    # widen the bracket: at `lo` the count must be on one side, at `hi` on the other
    for _ in range(20):
        c_lo = probe(lo)
        if c_lo == count or too_many(c_lo) == decreasing:
            break
        lo = lo / 4 if log else lo - (hi - lo)
    for _ in range(20):
        c_hi = probe(hi)
        if c_hi == count or too_many(c_hi) != decreasing:
            break
        hi = hi * 4 if log else hi + (hi - lo)
    for _ in range(iters):
        if best[1] == count:
            break
        mid = math.sqrt(lo * hi) if log else 0.5 * (lo + hi)
        if not lo < mid < hi or (hi - lo) <= 1e-12 * abs(hi):
            break
        c = probe(mid)
        if too_many(c) == decreasing:
            lo = mid
        else:
            hi = mid
    value, _, payload, sec = best
    return value, payload, sec, calls


def _bbox_diag(X):
    return float(np.linalg.norm(X.max(0) - X.min(0)))


# ---------------------------------------------------------------------------------------------
# methods that need nothing beyond numpy/scipy
# ---------------------------------------------------------------------------------------------


def random_sample(X, count, *, seed=0):
    """Uniform random subset of exactly ``count`` points."""
    t = time.perf_counter()
    idx = np.random.default_rng(seed).choice(len(X), count, replace=False)
    sec = time.perf_counter() - t
    keep = _mask(len(X), idx)
    return Kept(X[keep], keep, sec, "seed=%d" % seed)


def voxel_nearest(X, voxel):
    """One point per occupied voxel: the point nearest the voxel's centroid (numpy).

    PDAL's ``filters.voxelcentroidnearestneighbor`` rule; the kept points are input points.
    """
    lo = X.min(0)
    cells = np.floor((X - lo) / voxel).astype(np.int64)
    _, inv, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    m = len(counts)
    centroid = np.empty((m, 3))
    for d in range(3):
        centroid[:, d] = np.bincount(inv, weights=X[:, d], minlength=m) / counts
    dist = np.einsum("ij,ij->i", X - centroid[inv], X - centroid[inv])
    order = np.lexsort((dist, inv))  # by cell, then by distance to the cell centroid
    first = np.r_[True, inv[order][1:] != inv[order][:-1]]
    return order[first]


def voxel_grid(X, count, *, seed=0):
    """Voxel grid (numpy): bisect the voxel edge; keep the point nearest each voxel centroid."""
    diag = _bbox_diag(X)

    def call(v):
        t = time.perf_counter()
        idx = voxel_nearest(X, v)
        return len(idx), idx, time.perf_counter() - t

    guess = diag / math.sqrt(count)  # about right for a surface
    v, idx, sec, calls = drive(call, guess / 4, guess * 4, count, decreasing=True)
    keep = _mask(len(X), idx)
    return Kept(X[keep], keep, sec, f"voxel={v:.4g}", extra={"calls": calls})


# ---------------------------------------------------------------------------------------------
# optional peers
# ---------------------------------------------------------------------------------------------


def _open3d_voxel(X, count, *, seed=0):
    """Open3D ``voxel_down_sample``: bisect the voxel edge; output = voxel centroids."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(X)))
    diag = _bbox_diag(X)

    def call(v):
        t = time.perf_counter()
        out = pcd.voxel_down_sample(v)
        sec = time.perf_counter() - t
        P = np.asarray(out.points)
        return len(P), P, sec

    guess = diag / math.sqrt(count)
    v, P, sec, calls = drive(call, guess / 4, guess * 4, count, decreasing=True)
    return Kept(P.copy(), None, sec, f"voxel={v:.4g}", extra={"calls": calls})


def _poisson_disk(X, count, *, seed=0):
    """MeshLab Poisson-disk subsampling of the point cloud (pymeshlab), exact-count mode."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.ascontiguousarray(X, dtype=np.float64)))
    tree = cKDTree(X)
    best = None
    want = count
    for _ in range(8):  # exactnumflag gets within 0.5 %; nudge the request to close the gap
        ms.set_current_mesh(0)
        t = time.perf_counter()
        ms.generate_sampling_poisson_disk(samplenum=int(want), subsample=True,
                                          exactnumflag=True)
        sec = time.perf_counter() - t
        P = ms.current_mesh().vertex_matrix()
        ms.delete_current_mesh()
        if best is None or abs(len(P) - count) < abs(best[0] - count):
            best = (len(P), P, sec, want)
        if len(P) == count:
            break
        want = max(1, want + (count - len(P)))
    _, P, sec, want = best
    d, idx = tree.query(P)
    if d.max() > 1e-9 * _bbox_diag(X):
        raise RuntimeError("pymeshlab returned points that are not input points")
    keep = _mask(len(X), idx)
    return Kept(X[keep], keep, sec, f"samplenum={want}")


def _cgal_point_set(X):
    from CGAL.CGAL_Kernel import Point_3
    from CGAL.CGAL_Point_set_3 import Point_set_3

    ps = Point_set_3()
    ps.reserve(len(X))
    for x, y, z in X.tolist():
        ps.insert(Point_3(x, y, z))
    return ps


def _cgal_kept(ps, n):
    """Indices of the points a CGAL simplification left (indices are insertion order)."""
    idx = np.fromiter(ps.indices(), dtype=np.int64, count=ps.size())
    return _mask(n, idx)


def _cgal_hierarchy(X, count, *, seed=0, size=100):
    """CGAL ``hierarchy_simplify_point_set`` (Pauly et al. 2002 clustering).

    ``size`` (max cluster size) as in CGAL's own example; the ``maximum_variation`` knob
    (surface variation above which a cluster is split — the adaptive part) is bisected.
    If even the largest variation keeps too many points, ``size`` is doubled; if even the
    smallest keeps too few (exactly planar faces have variation 0), it is halved.
    """
    import CGAL.CGAL_Point_set_processing_3 as psp

    ps = _cgal_point_set(X)
    n = len(X)

    def kept_at(size, var):
        psp.hierarchy_simplify_point_set(ps, size=size, maximum_variation=var)
        c = ps.size()
        ps.cancel_removals()
        return c

    # the count must lie between the counts at the largest and the smallest variation; on
    # exactly planar parts the variation is 0 and only `size` splits clusters
    for _ in range(30):
        if kept_at(size, 1 / 3) > count and size < n:
            size *= 2
        elif kept_at(size, 1e-7) < count and size > 2:
            size = max(2, size // 2)
        else:
            break

    def call(var):
        t = time.perf_counter()
        psp.hierarchy_simplify_point_set(ps, size=size, maximum_variation=var)
        sec = time.perf_counter() - t
        keep = _cgal_kept(ps, n)
        ps.cancel_removals()
        return int(keep.sum()), keep, sec

    var, keep, sec, calls = drive(call, 1e-7, 1 / 3, count, decreasing=True)
    return Kept(X[keep], keep, sec, f"size={size}, max_variation={var:.4g}",
                extra={"calls": calls})


def _cgal_grid(X, count, *, seed=0):
    """CGAL ``grid_simplify_point_set``: one point per cell; bisect the cell size."""
    import CGAL.CGAL_Point_set_processing_3 as psp

    ps = _cgal_point_set(X)
    n = len(X)

    def call(eps):
        t = time.perf_counter()
        psp.grid_simplify_point_set(ps, eps)
        sec = time.perf_counter() - t
        keep = _cgal_kept(ps, n)
        ps.cancel_removals()
        return int(keep.sum()), keep, sec

    guess = _bbox_diag(X) / math.sqrt(count)
    eps, keep, sec, calls = drive(call, guess / 4, guess * 4, count, decreasing=True)
    return Kept(X[keep], keep, sec, f"cell={eps:.4g}", extra={"calls": calls})


def _cgal_wlop(X, count, *, seed=0):
    """CGAL ``wlop_simplify_and_regularize_point_set``: new points (projected, regularised).

    ``select_percentage`` = count / n; CGAL's defaults otherwise (35 iterations, neighbour
    radius chosen by CGAL).
    """
    import CGAL.CGAL_Point_set_processing_3 as psp
    from CGAL.CGAL_Point_set_3 import Point_set_3

    ps = _cgal_point_set(X)
    pct = 100.0 * count / len(X)
    for _ in range(4):
        out = Point_set_3()
        t = time.perf_counter()
        psp.wlop_simplify_and_regularize_point_set(ps, out, select_percentage=pct)
        sec = time.perf_counter() - t
        if out.size() == count:
            break
        pct *= count / max(out.size(), 1)  # truncation of n * pct / 100: nudge
    P = np.array([(p.x(), p.y(), p.z()) for p in (out.point(i) for i in out.indices())])
    return Kept(P, None, sec, f"select_percentage={pct:.4g}")


def _fps(X, count, *, seed=0):
    """Farthest point sampling (``fpsample.bucket_fps_kdline_sampling``, QuickFPS)."""
    import fpsample

    n = len(X)
    h = 3 if n < 10_000 else 5 if n < 100_000 else 7 if n < 1_000_000 else 9
    t = time.perf_counter()
    idx = fpsample.bucket_fps_kdline_sampling(np.ascontiguousarray(X, dtype=np.float32),
                                              count, h, start_idx=0)
    sec = time.perf_counter() - t
    keep = _mask(n, idx)
    return Kept(X[keep], keep, sec, f"h={h}")


#: name -> (function, modules it needs, makes new points?)
PEERS = {
    "random": (random_sample, (), False),
    "voxel grid (numpy: nearest to centroid)": (voxel_grid, (), False),
    "voxel grid (Open3D: centroids)": (_open3d_voxel, ("open3d",), True),
    "Poisson disk (MeshLab)": (_poisson_disk, ("pymeshlab",), False),
    "CGAL hierarchy": (_cgal_hierarchy, ("CGAL.CGAL_Point_set_processing_3",), False),
    "CGAL grid": (_cgal_grid, ("CGAL.CGAL_Point_set_processing_3",), False),
    "CGAL WLOP": (_cgal_wlop, ("CGAL.CGAL_Point_set_processing_3",), True),
    "farthest point (fpsample)": (_fps, ("fpsample",), False),
}

_MISSING: dict[str, str] = {}


def _importable(module):
    if module in _MISSING:
        return False
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            importlib.import_module(module)
    except Exception as exc:  # an optional peer: any import failure means "not here"
        _MISSING[module] = f"{type(exc).__name__}: {exc}".splitlines()[0]
        return False
    return True


def available(names=None, *, quiet=False):
    """The peers whose packages import here, as ``{name: function}``; notes for the rest."""
    out = {}
    for name, (fn, modules, _) in PEERS.items():
        if names is not None and name not in names:
            continue
        missing = [m for m in modules if not _importable(m)]
        if missing:
            if not quiet:
                print(f"note: peer '{name}' skipped — cannot import {missing[0]} "
                      f"({_MISSING[missing[0]]}); pip install -e '.[bench]'")
            continue
        out[name] = fn
    return out


def makes_new_points(name):
    return PEERS[name][2]


def ours(mode, options=None):
    """tiledsimplify in one mode as a method ``(X, count) -> Kept`` (boundary flags kept);
    ``options``: other :class:`SimplifyOptions` fields by name (the mode's defaults else)."""
    def method(X, count, *, seed=0):
        from tiledsimplify import BudgetWarning, SimplifyOptions, simplify_points
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BudgetWarning)
            res = simplify_points(X, count=count, options=SimplifyOptions.from_mapping(
                {**(options or {}), "mode": mode}))
        sec = time.perf_counter() - t
        setting = ", ".join(f"{k}={v}" for k, v in {"mode": mode, **(options or {})}.items())
        return Kept(X[res.keep], res.keep, sec, setting, boundary=res.boundary,
                    extra={"reached": res.reached, "message": res.message})
    method.__name__ = f"tiledsimplify_{mode}"
    return method


def our_methods(options=None):
    """``{"tiledsimplify <mode>": method}`` for every mode the core offers (``options``: see
    :func:`ours`)."""
    from tiledsimplify.core.options import MODES
    return {f"tiledsimplify {m}": ours(m, options) for m in MODES}


if __name__ == "__main__":
    if {"-h", "--help"} & set(sys.argv[1:]):  # the usage, not a run of minutes
        sys.exit(print(__doc__))
    have = available()
    print("available peers:", ", ".join(have))
    print("our modes:", ", ".join(our_methods()))
