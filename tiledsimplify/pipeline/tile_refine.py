"""Gap refinement of the tiled output: each tile swaps its kept core points after the global cut.

The untiled core ends with :func:`~tiledsimplify.core.refine.refine_coverage` (equal-count swaps
that lower the Hausdorff distance); tiles cannot (only their removal order is used), so the run
refines after the global cut, one task per tile, in two small stages:

1. :func:`cut_hausdorff`: each tile's Hausdorff distance under the cut (its core points to the
   kept points of core and halo). Their maximum ``G`` is the cut's global Hausdorff distance.
2. :func:`refine_tile`: ``refine_coverage`` on core ∪ halo. Only core points may be added or
   removed, so each tile keeps its own count and the global count stays exact. Fixed: every
   halo point (kept only where the cut keeps it; removed ones take no part), the core's
   boundary and edge-candidate points, and every kept core point within ``G`` (the *band*) of a
   point outside the core.

**Determinism.** A tile reads only the cut (the tiles' stored removal steps and the prefix
lengths saved in the store), never another tile's refined flags, and writes only its own. So
the output does not depend on the order tiles are refined in, the scheduler or the worker
count.

**Seams.** Tiles refine at the same time, each seeing its neighbours as the cut left them. The
band makes that safe: a tile only removes points farther than ``G`` from every other tile's
points, and aims below its own Hausdorff distance (at most ``G``). So a point of another tile
never had a removed point as its nearest kept one (that one lies within ``G``), and no two
tiles remove the two points a point relies on. Hence the output's Hausdorff distance is at most
the largest refined tile's, never above the cut's. This needs ``G`` at most the halo width (a
tile sees every point within ``G`` of its core); otherwise nothing is refined.
"""

import time

import numpy as np
from scipy.spatial import cKDTree

from ..core.heap import coordinate_hash
from ..core.refine import refine_coverage
from ..tiles import TileStore


def _cut(store):
    """The global cut saved in the store: steps applied per tile, and its key."""
    run = store.run_attrs
    return run["cut"], run["cut_key"]


def _kept(store, tile, cut):
    step = store.read_result(tile, "step")
    return (step < 0) | (step >= cut[tile])


def _view(store, tile, cut):
    """Core and halo of a tile with the cut's kept flags: ``(xyz, keep, n_core)``."""
    core_xyz, _ = store.core(tile)
    halo_xyz, _, owner, row = store.halo_points(tile, owners=True)
    keep = np.zeros(len(core_xyz) + len(halo_xyz), dtype=bool)
    keep[:len(core_xyz)] = _kept(store, tile, cut)
    halo_keep = keep[len(core_xyz):]
    for j in np.unique(owner):
        at = owner == j
        halo_keep[at] = _kept(store, int(j), cut)[row[at]]
    return np.concatenate([core_xyz, halo_xyz]), keep, len(core_xyz)


def cut_hausdorff(store_path, tile):
    """The largest distance from a core point of ``tile`` to the cut's kept points (of its
    core and halo; inf if none is kept). Returns ``{"tile", "hausdorff", "seconds"}``."""
    t0 = time.perf_counter()
    store = TileStore.open(store_path)
    cut, _ = _cut(store)
    xyz, keep, n_core = _view(store, tile, cut)
    h = 0.0
    if n_core:
        h = float(cKDTree(xyz[keep]).query(xyz[:n_core])[0].max()) if keep.any() else np.inf
    return {"tile": int(tile), "hausdorff": h, "seconds": time.perf_counter() - t0}


def refine_tile(store_path, tile, band):
    """Refine one tile's kept core points after the global cut; save them in the store.

    Parameters
    ----------
    store_path : str
    tile : int
    band : float
        ``G``, the cut's global Hausdorff distance: kept core points this close to a point
        outside the core stay (see the module notes).

    Returns
    -------
    dict
        ``tile``, ``n_core``, ``n_halo``, ``n_fixed`` (core points that must stay, of those
        kept), ``swaps``, ``hausdorff_before`` and ``hausdorff_after`` (over the tile's core)
        and ``seconds``.

    Notes
    -----
    Reads the cut (:meth:`TileStore.run_attrs` ``cut``, ``cut_key``) and the results of the
    tile and of the tiles its halo comes from; writes :meth:`TileStore.write_refined` with
    attrs ``cut_key`` and ``band``, so that a resumed run keeps exactly the tiles refined for
    the same cut.
    """
    t0 = time.perf_counter()
    store = TileStore.open(store_path)
    cut, key = _cut(store)
    xyz, keep, n_core = _view(store, tile, cut)
    info = {"swaps": 0, "hausdorff_before": 0.0, "hausdorff_after": 0.0}
    fixed = np.ones(len(xyz), dtype=bool)
    fixed[:n_core] = store.read_result(tile, "boundary")
    if "candidate" in store.result_names(tile):
        fixed[:n_core] |= store.read_result(tile, "candidate")
    core_keep = keep[:n_core]
    if len(xyz) > n_core and core_keep.any():
        near, _ = cKDTree(xyz[n_core:]).query(xyz[:n_core][core_keep],
                                               distance_upper_bound=band)
        fixed[np.flatnonzero(core_keep)[np.isfinite(near)]] = True
    if n_core:
        addable = np.zeros(len(xyz), dtype=bool)
        addable[:n_core] = True
        refined, info = refine_coverage(xyz, keep, fixed, addable=addable,
                                        tie=coordinate_hash(xyz))
        core_keep = refined[:n_core]
    store.write_refined(tile, core_keep, {"cut_key": key, "band": float(band)})
    return {"tile": int(tile), "n_core": int(n_core), "n_halo": int(len(xyz) - n_core),
            "n_fixed": int((fixed[:n_core] & keep[:n_core]).sum()), "swaps": int(info["swaps"]),
            "hausdorff_before": float(info["hausdorff_before"]),
            "hausdorff_after": float(info["hausdorff_after"]),
            "seconds": time.perf_counter() - t0}


def is_refined(store, tile, key, band):
    """Whether ``tile`` was refined for the cut ``key`` with this ``band``."""
    got = store.read_refined(tile)
    return got is not None and got[1].get("cut_key") == key and got[1].get("band") == band


def refined_mask(store):
    """Bool mask over the whole input (by original index) of the refined kept points."""
    keep = np.zeros(store.n_total, dtype=bool)
    for i in range(store.n_tiles):
        keep[store.core(i)[1]] = store.read_refined(i)[0]
    return keep
