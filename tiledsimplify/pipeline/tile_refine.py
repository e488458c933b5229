"""Gap refinement of the tiled output: each tile swaps its kept core points after the global cut.

The untiled core ends with :func:`~tiledsimplify.core.refine.refine_coverage` (equal-count swaps
that lower the Hausdorff distance); tiles cannot (only their removal order is used), so the run
refines after the global cut, one task per tile, in two stages:

1. :func:`cut_hausdorff`: each tile's Hausdorff distance under the cut (its core points to the
   kept points of core and halo). Their maximum ``G`` is the cut's global Hausdorff distance;
   refinement needs a view of each tile at least ``G`` wide (below): the halo, or where the
   gaps are wider (small ratios) a view of their maximum's width read from the neighbours'
   cores (:func:`refine_width`). A gap measured in a view the halo wide is exact if within
   it; one beyond may be overstated (its nearest kept point beyond the view), never
   understated, so the maximum is then a bound of ``G`` — and views that wide are safe.
   (Until 2026-12-05 a second pass measured ``G`` exactly in views that wide first: at 5–1 %
   kept it cost more than the bound's extra width, which was 5–10 % on the 1M-point scan.)
   Where the cut's gaps are expected within the halo (the kept share not too small,
   :func:`gaps_expected_within`) this stage is folded into the next: each tile measures its
   own gap under the cut in its view first (``refine_tile(..., hausdorff=None)``) and the run
   checks afterwards that every gap lay within the halo — then ``G`` is their maximum and the
   flags are those the two stages give (the same views, phases and flags: ``G`` only sets the
   width) — or else measures the gaps of the tiles that did not (none measured twice) and
   refines every tile again in views as wide as their maximum.
2. :func:`refine_tile`, in **phases** (:func:`refine_phases`): a greedy colouring, tiles with
   the most neighbours first, of the graph that joins two tiles when one's view reaches the
   other's core. A tile
   starts once its neighbours of earlier phases are refined (not every tile of earlier phases:
   no barrier between phases), so tiles of one phase, and of different phases that are not
   neighbours, run in parallel. A tile sees its halo as the tiles of earlier phases refined it
   and the rest as the cut left it, and runs ``refine_coverage``
   on core ∪ halo: only core points are added or removed (each tile keeps its count, so the
   global count stays exact), only core points count in its Hausdorff distance and are
   filled for, kept halo points and the core's fixed points stay (the flags' core band and the
   protected points, :func:`~tiledsimplify.core.refine.protected`, as in the untiled core), and
   removed halo points are *watched*: a round at level ``τ`` leaves none farther than
   ``max(τ, its distance before)``. The core's flagged points are brought and kept within the
   run's edge cover radius of a kept point, as in the untiled core.

**Determinism.** A tile reads the cut and the refined flags of its neighbours of earlier
phases, which are saved before it starts; its neighbours of later phases start only after it
ends, and tiles that run beside it are not its neighbours (they do not see each other's
points). The phases are a fixed function of the tile plan and the view's width (the halo, or
``G``). So each tile's flags
are a fixed function of the cut, whatever the scheduler, worker count or order, and a resumed
run may keep every tile already refined for the same cut.

**Safety.** A tile removes a point ``c`` only if every point whose nearest kept point is ``c``
keeps another within ``τ`` (or, for a watched point farther than ``τ``, not at all). That point
lies within ``G`` of ``c`` (no distance ever exceeds ``G``: each round aims below the tile's
Hausdorff distance), so within the view: the tile sees it and every kept point it sees is really
kept while it runs. Points a tile running beside it removes are not in its view, so no
two tiles remove the two points a point relies on. Hence no point ends farther than ``G``: the
output's Hausdorff distance is never above the cut's.

**Seams.** The cut's worst gaps lie at tile faces. In phases a gap across a face is filled
once (the later tile sees the earlier tile's fill; each fills only for its own core) and faces
are thinned like the interior. Tiles refined concurrently with a frozen band of width ``G`` at
their faces instead filled such gaps from both sides and never thinned near faces (kept density
at faces 1.17x the untiled run's on the Bunny; in phases 1.03x, README "Seams", history in
docs/measurements.md). A wider halo does not close the cut's face gaps.
"""

import collections
import math
import threading
import time

import numpy as np
from scipy.spatial import cKDTree

from ..core import cell_grid, compile_cache
from ..core.bounds import row_min
from ..core.heap import coordinate_hash
from ..core.refine import refine_coverage
from ..tiles import IncompleteStoreError, TileStore

#: saved with the refined flags: flags of another scheme are redone ("phases" until 2026-12-05:
#: without the flags' cover, :data:`~tiledsimplify.core.refine.EDGE_COVER`; "phases, edge
#: cover" until that afternoon: phases coloured by tile index, :func:`refine_phases`)
SCHEME = "phases by neighbours, edge cover"


def _cut(store):
    """The global cut saved in the store: steps applied per tile, and its key."""
    run = store.run_attrs
    return run["cut"], run["cut_key"]


#: bytes of the cut's kept flags (one byte a point) a process keeps for its next tasks
#: (:func:`_kept`; about 440 tiles of 150k points)
KEPT_CACHE_BYTES = 64 * 2 ** 20
_kept_cache: collections.OrderedDict = collections.OrderedDict()
_kept_lock = threading.Lock()


def _kept(store, tile, cut):
    """The cut's kept flags of ``tile``'s core (read-only), from the process's cache of
    recently read tiles or its step array.

    Both passes read each tile's flags for its own view and for the view of every tile its
    halo reaches (the 1M-point scan: 89 reads of 10 step arrays, 0.60 s of the 2 worker
    threads; zarr's reads do not overlap). The flags are a fixed function of the store's
    input and settings (its fingerprint) and the cut (its key, and the tile's step), which
    name them here; the least recently used go beyond :data:`KEPT_CACHE_BYTES`."""
    key = (str(store.path), store.config.get("fingerprint"), store.run_attrs.get("cut_key"),
           int(tile), int(cut[tile]))
    with _kept_lock:
        got = _kept_cache.get(key)
        if got is not None:
            _kept_cache.move_to_end(key)
            return got
    step = store.read_result(tile, "step")
    got = (step < 0) | (step >= cut[tile])
    got.flags.writeable = False
    with _kept_lock:
        _kept_cache[key] = got
        total = sum(a.nbytes for a in _kept_cache.values())
        while total > KEPT_CACHE_BYTES and len(_kept_cache) > 1:
            total -= _kept_cache.popitem(last=False)[1].nbytes
    return got


def clear_kept():
    """Empty this process's cache of kept flags (:func:`_kept`): the end of a refinement."""
    with _kept_lock:
        _kept_cache.clear()


def _view_points(store, tile, width=None):
    """Core and halo points of a tile's view: ``(xyz, n_core, owner, row)`` — the halo's
    points are ``core(owner)[row]``. ``width``: the halo's (default the store's,
    :meth:`TileStore.tile_halo`; a wider one is read from the neighbours' cores,
    :meth:`TileStore.near_points`, :func:`refine_width`)."""
    core_xyz = store.core_xyz(tile)
    if width is None or width <= store.halo:
        halo_xyz, _, owner, row = store.tile_halo(tile)
    else:
        halo_xyz, owner, row = store.near_points(tile, width)
    return np.concatenate([core_xyz, halo_xyz]), len(core_xyz), owner, row


def _view_keep(store, tile, cut, n_core, owner, row, refined=(), width=None):
    """The kept flags a tile's view sees (:func:`_view_points`): halo points of the tiles in
    ``refined`` (earlier phases) as they refined them in views ``width`` wide, the rest as
    the cut keeps them."""
    keep = np.zeros(n_core + len(owner), dtype=bool)
    keep[:n_core] = _kept(store, tile, cut)
    halo_keep = keep[n_core:]
    refined = {int(j) for j in refined}
    for j in np.unique(owner):
        at = owner == j
        halo_keep[at] = (_refined(store, int(j), width) if int(j) in refined
                         else _kept(store, int(j), cut))[row[at]]
    return keep


def _view(store, tile, cut, refined=(), width=None):
    """Core and halo of a tile with the kept flags it sees: ``(xyz, keep, n_core)``
    (:func:`_view_points`, :func:`_view_keep`)."""
    xyz, n_core, owner, row = _view_points(store, tile, width)
    return xyz, _view_keep(store, tile, cut, n_core, owner, row, refined, width), n_core


def _refined(store, tile, width=None):
    """A tile's refined kept flags, which a tile of a later phase reads: they must have been
    made for this cut, in views as wide (``width``; the store's halo by default)."""
    got = store.read_refined(tile)
    key = store.run_attrs["cut_key"]
    if got is None or got[1].get("cut_key") != key or \
            got[1].get("width") != _width(store, width):
        raise IncompleteStoreError(
            f"{store.path}: tile {tile} has no refined kept flags for this cut, but a tile of "
            "a later phase reads them; refine the phases in order (run again to resume).")
    return got[0]


def _width(store, width):
    """The width of a view as saved with the refined flags: the store's halo by default."""
    return float(store.halo if width is None else width)


def largest_gap(xyz, keep, n_core):
    """The largest distance from a core point (the first ``n_core`` of ``xyz``) to the kept
    points (inf if none is kept; 0 if every core point is kept)."""
    gone = np.flatnonzero(~keep[:n_core])  # a kept core point is 0 from the kept points
    if not gone.size:
        return 0.0
    if not keep.any():
        return np.inf
    return float(cell_grid.distances_to(xyz, np.flatnonzero(keep), gone).max())


def refine_phases(plan, halo):
    """The phase of every tile: a greedy colouring of the graph of tiles whose halo reaches
    the other's core (:meth:`TilePlan.neighbours`), so no two tiles of one phase see each
    other's points; tiles with the most neighbours are coloured first (Welsh & Powell 1967),
    ties by index. A fixed function of the plan and the halo.

    A tile waits for its neighbours of earlier phases, so the phases make chains of tasks.
    Coloured by index (until 2026-12-05) a tile that neighbours most others could land in a
    late phase behind a chain of them; by neighbour count such a tile is coloured first and
    the chains come out shorter (docs/measurements.md, "The refinement's phases by neighbour
    count")."""
    phase = np.full(plan.n_tiles, -1, dtype=np.int64)
    nbrs = [plan.neighbours(i, halo) for i in range(plan.n_tiles)]
    for i in sorted(range(plan.n_tiles), key=lambda i: (-len(nbrs[i]), i)):
        used = {int(phase[j]) for j in nbrs[i] if phase[j] >= 0}
        phase[i] = next(c for c in range(len(used) + 1) if c not in used)
    return phase


#: the cut's gaps are expected within the halo when this many times the kept points' spacing
#: (the cloud's over the square root of the kept share) is within it
#: (:func:`gaps_expected_within`). Measured ``G``: 5.4 / 8.1 / 12.2 / 31 spacings at 20 / 10 /
#: 5 / 2 % kept on the 1M-point scan of ``benchmarks/speed.py`` (:func:`refine_width`), 2.4 /
#: 2.6 / 2.7 / 4.4 times the kept points' spacing; 5.2 spacings (2.3 times) on the 1M-point
#: scan of ``benchmarks/pipeline_speed.py`` at 20 %. At 3, a default halo (10 spacings)
#: expects them within it from 9 % kept
GAP_SPACINGS = 3.0


def gaps_expected_within(halo, spacing, share):
    """Whether the cut's gaps are expected within ``halo`` (model units) for a cloud of
    ``spacing`` keeping ``share`` of its points: :data:`GAP_SPACINGS` times the kept points'
    spacing within it. Only a guess — which way the run measures ``G`` (see the module
    notes); a wrong one costs time, never a wrong result."""
    return bool(share > 0 and spacing > 0
                and GAP_SPACINGS * spacing / math.sqrt(share) <= halo)


def refine_width(halo, hausdorff):
    """The width of the view a tile refines in: the store's ``halo``, or the cut's Hausdorff
    distance ``G`` (or a bound of it, see the module notes) where that is wider (the
    refinement must see every point within ``G`` of a point it removes). None: beyond
    :data:`MAX_WIDTH` halos (or infinite), too wide a view to read; there is no refinement
    then.

    Below ~7 % kept the cut's ``G`` outgrows the default halo of 10 spacings (the 1M-point
    scan of ``benchmarks/speed.py``: ``G`` 5.4 / 8.1 / 12.2 / 31 spacings at 20 / 10 / 5 / 2
    %); until 2026-12-04 (late night) such runs were not refined at all (at 5 %: Hausdorff
    0.0423 against 0.0296 refined). The tile pass keeps the store's halo, so runs whose ``G``
    fits in it give the same output as before."""
    if not hausdorff <= MAX_WIDTH * halo:
        return None
    return max(float(halo), float(hausdorff))


#: a tile refines in a view at most this many halos wide (:func:`refine_width`): at 10 halos
#: (100 spacings by default) a square tile of 100,000 points on a surface (the least default
#: tile, ~316 spacings across) would read ~2.7x its core, one of 500,000 ~1.7x (geometry, not
#: measured). The cut's gap at 1 % kept: 22-43 spacings on the inputs of docs/measurements.md
#: ("Small ratios")
MAX_WIDTH = 10.0


def cut_hausdorff(store_path, tile, width=None):
    """The largest distance from a core point of ``tile`` to the cut's kept points (of its
    core and halo — ``width`` wide, by default the store's; inf if none is kept: a distance
    beyond the width may be overstated, never understated). Returns ``{"tile",
    "hausdorff", "seconds"}``."""
    t0 = time.perf_counter()
    compile_cache.wait()  # a compile ahead running on this machine
    store = TileStore.open(store_path)
    cut, _ = _cut(store)
    xyz, keep, n_core = _view(store, tile, cut, width=width)
    return {"tile": int(tile), "hausdorff": largest_gap(xyz, keep, n_core),
            "seconds": time.perf_counter() - t0}


def refine_tile(store_path, tile, hausdorff, earlier=(), width=None, edge_radius=0.0,
                after=()):
    """Refine one tile's kept core points after the global cut; save them in the store.

    Parameters
    ----------
    store_path : str
    tile : int
    hausdorff : float or None
        ``G``, the cut's global Hausdorff distance, if it was measured (:func:`cut_hausdorff`
        over every tile). None: not measured — the tile first measures its own gap under the
        cut in its view, and refines only if that lies within the view's width; the run
        checks afterwards that every tile's did (:func:`~tiledsimplify.pipeline.run` refines
        so when the cut's gaps are expected within the halo, see the module notes).
    earlier : sequence of int
        The neighbours of ``tile`` in earlier phases: their refined flags are read (they must
        be saved, for the same cut and width), the cut's for every other neighbour.
    width : float, optional
        The view's halo width, :func:`refine_width` (default: the store's halo).
    edge_radius : float
        The tile's flagged core points are brought and kept within this distance of a kept
        point (:func:`~tiledsimplify.core.refine.edge_cover_radius` of the run's spacing and
        ratio; 0: no cover), as the untiled core does.
    after : sequence
        The results of the tasks that refine ``earlier`` (passed by the scheduler, so that
        this one runs after them). With ``hausdorff`` None, if one of them was not refined
        (its gap lay beyond the view), neither is this tile: it would read their flags.

    Returns
    -------
    dict
        ``tile``, ``n_core``, ``n_halo``, ``n_fixed`` (core points that must stay, of those
        kept), ``swaps``, ``hausdorff_before`` and ``hausdorff_after`` (over the tile's core),
        ``gap`` (the tile's largest gap under the cut, with ``hausdorff`` None; else None),
        ``beyond`` (True: not refined, as the gap, or an earlier neighbour's, lay beyond the
        view; ``n_halo`` 0 where the view was not read) and ``seconds``.

    Notes
    -----
    Reads the cut (:meth:`TileStore.run_attrs` ``cut``, ``cut_key``), the results of the
    tile and of the tiles its halo comes from, and the refined flags of ``earlier``; writes
    :meth:`TileStore.write_refined` with attrs ``cut_key``, ``width``, ``gap`` and
    ``scheme``: the flags are a fixed function of the cut and the width, so a resumed run
    keeps exactly the tiles refined for the same cut in views as wide.
    """
    t0 = time.perf_counter()
    compile_cache.wait()  # a compile ahead running on this machine
    store = TileStore.open(store_path)
    cut, key = _cut(store)
    view_width = _width(store, width)
    out = {"tile": int(tile), "n_core": store.count(tile), "n_halo": 0, "n_fixed": 0,
           "swaps": 0, "hausdorff_before": 0.0, "hausdorff_after": 0.0, "gap": None,
           "beyond": False}
    if hausdorff is None and any(r.get("beyond") for r in after if isinstance(r, dict)):
        out.update(beyond=True, seconds=time.perf_counter() - t0)  # its view is not read
        return out
    xyz, n_core, owner, row = _view_points(store, tile, width)
    out["n_halo"] = int(len(xyz) - n_core)
    keep = _view_keep(store, tile, cut, n_core, owner, row, earlier, width)
    fixed = np.ones(len(xyz), dtype=bool)
    fixed[:n_core] = store.read_result(tile, "fixed")
    core_keep = keep[:n_core]
    info = {"swaps": 0, "hausdorff_before": 0.0, "hausdorff_after": 0.0}
    before = np.zeros(len(xyz)) if hausdorff is None else None
    if n_core:
        addable = np.zeros(len(xyz), dtype=bool)
        addable[:n_core] = True
        edges = np.zeros(len(xyz), dtype=bool)
        edges[:n_core] = store.read_result(tile, "feature")
        refined, info = refine_coverage(xyz, keep, fixed, addable=addable, watch=~addable,
                                        tie=coordinate_hash(xyz), edges=edges,
                                        edge_radius=edge_radius, before_out=before)
        core_keep = refined[:n_core]
    if hausdorff is None:  # the tile's gap under the cut: within the view, it is exact
        out["gap"] = gap = _cut_gap(store, tile, cut, xyz, n_core, owner, row, before,
                                    earlier, width)
        if not gap <= view_width:  # the refinement may have been unsafe: not saved
            out.update(beyond=True, seconds=time.perf_counter() - t0)
            return out
    store.write_refined(tile, core_keep, {"cut_key": key, "width": view_width,
                                          "gap": out["gap"], "scheme": SCHEME})
    out.update(n_fixed=int((fixed[:n_core] & keep[:n_core]).sum()), swaps=int(info["swaps"]),
               hausdorff_before=float(info["hausdorff_before"]),
               hausdorff_after=float(info["hausdorff_after"]),
               seconds=time.perf_counter() - t0)
    return out


def _cut_gap(store, tile, cut, xyz, n_core, owner, row, before, earlier, width):
    """The tile's largest gap under the cut (:func:`largest_gap` of the cut's view) from
    ``before``, the distances in the view the refinement started from (its earlier
    neighbours' halo points as they refined them).

    Without earlier neighbours the two views are the same. Else they differ in halo points
    alone, which lie outside the tile's box: a core point nearer to its nearest kept point
    in ``before`` than to the box's faces has that nearest in the core, kept in both views,
    and no halo point nearer (nor, by the same argument, under the cut), so its distance is
    the same under the cut; only the others — a band along the faces — are measured again.
    """
    d = before[:n_core]
    if not len(earlier) or not n_core:
        return float(d.max(initial=0.0))
    t = store._tile(tile)
    lo, hi = store.plan.lo[t], store.plan.hi[t]
    core = xyz[:n_core]
    to_face = row_min(np.minimum(core - lo, hi - core))
    band = np.flatnonzero(~(d < to_face))
    inner = float(np.delete(d, band).max(initial=0.0))
    if not band.size:
        return inner
    cut_keep = _view_keep(store, tile, cut, n_core, owner, row, (), width)
    if not cut_keep.any():
        return np.inf
    return max(inner, float(cKDTree(xyz[cut_keep]).query(core[band])[0].max()))


def is_refined(store, tile, key, width):
    """Whether ``tile`` was refined, by this scheme, for the cut ``key`` in a view ``width``
    wide."""
    got = store.read_refined(tile)
    return got is not None and got[1].get("cut_key") == key and \
        got[1].get("width") == float(width) and got[1].get("scheme") == SCHEME


def refined_gap(store, tile):
    """The tile's largest gap under the cut, as saved with its refined flags when it was
    measured there (None otherwise)."""
    got = store.read_refined(tile)
    return None if got is None else got[1].get("gap")


def refined_mask(store):
    """Bool mask over the whole input (by original index) of the refined kept points."""
    keep = np.zeros(store.n_total, dtype=bool)
    for i in range(store.n_tiles):
        keep[store.core(i)[1]] = store.read_refined(i)[0]
    return keep
