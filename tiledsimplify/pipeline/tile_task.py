"""What runs for one tile: read core + halo from the store, run the core, write back.

Tasks take the store's path and a tile id — nothing large passes through the scheduler — and
are plain module-level functions, so threads, processes and dask.distributed workers all run
them the same way and get the same result.
"""

import logging
import time

import numpy as np

from ..core import SimplifyOptions, simplify_points
from ..tiles import TileStore

log = logging.getLogger("tiledsimplify")

#: fixed log-spaced bins for the global boundary threshold (deviation is ~ an angle, radians)
BINS = np.concatenate([[0.0], np.geomspace(1e-7, 4.0, 4095)])


def _tile_cloud(store, tile):
    core_xyz, core_idx = store.core(tile)
    halo_xyz, halo_idx = store.halo_points(tile)
    xyz = np.concatenate([core_xyz, halo_xyz])
    frozen = np.zeros(len(xyz), dtype=bool)
    frozen[len(core_xyz):] = True
    return xyz, frozen, len(core_xyz)


def deviation_histogram(store_path, tile, options):
    """Histogram (over :data:`BINS`) of the boundary measure of the tile's core points."""
    store = TileStore.open(store_path)
    xyz, frozen, n_core = _tile_cloud(store, tile)
    if n_core == 0:
        return np.zeros(len(BINS) - 1, dtype=np.int64)
    opts = SimplifyOptions(**{**options, "progressive": False})
    res = simplify_points(xyz, count=len(xyz), frozen=frozen, options=opts)
    return np.histogram(np.clip(res.deviation[:n_core], 0.0, BINS[-1]), bins=BINS)[0]


def threshold_from_histogram(hist, k, floor):
    """``max(median + k * 1.4826 * MAD, floor)`` from a histogram over :data:`BINS` (bin
    centres; resolution ~0.4 % of the value)."""
    centres = np.r_[0.0, np.sqrt(BINS[1:-1] * BINS[2:])]
    total = hist.sum()
    if total == 0:
        return float(floor)
    med = centres[np.searchsorted(np.cumsum(hist), total / 2.0)]
    dev = np.abs(centres - med)
    order = np.argsort(dev, kind="stable")
    mad = dev[order][np.searchsorted(np.cumsum(hist[order]), total / 2.0)]
    return max(float(med + k * 1.4826 * mad), float(floor))


def _halo_frozen(frozen, options):
    """The halo is frozen in mode "paper"; in mode "coverage" it is simplified with the core.

    The coverage measure sees the spacing of a point's neighbours. A frozen halo keeps full
    density to the end, so core points along the tile border look crowded and go first:
    measured on the Bunny in 8 tiles, the kept density in a band two spacings wide around the
    tile faces fell to 0.47 of the untiled run's. Simplifying the halo too (its results are
    discarded; the neighbouring tile owns those points) lets the border see a neighbourhood
    thinned as the untiled run would thin it.
    """
    return frozen if options.mode == "paper" else None


def simplify_tile(store_path, tile, options, threshold):
    """Simplify one tile with its halo frozen; write the core points' results; mark done.

    Results per core point: ``step`` (position among the core points in the tile's removal
    sequence, -1 if never removed), ``importance`` (at removal, NaN if never removed),
    ``boundary``, ``normal``.
    The tile is run progressively to the end, so the global budget can cut it anywhere.
    """
    t0 = time.perf_counter()
    store = TileStore.open(store_path)
    xyz, frozen, n_core = _tile_cloud(store, tile)
    step = np.full(n_core, -1, dtype=np.int64)
    imp = np.full(n_core, np.nan)
    boundary = np.zeros(n_core, dtype=bool)
    normal = np.zeros((n_core, 3), dtype=np.float32)
    if n_core:
        opts = SimplifyOptions(**{**options, "boundary_threshold": threshold,
                                  "progressive": True})
        res = simplify_points(xyz, count=len(xyz), frozen=_halo_frozen(frozen, opts),
                              options=opts)
        core = res.order < n_core
        step[res.order[core]] = np.arange(int(core.sum()))
        imp[res.order[core]] = res.order_importance[core]
        boundary = res.boundary[:n_core]
        normal = res.normals[:n_core].astype(np.float32)
    store.write_result(tile, {"step": step, "importance": imp, "boundary": boundary,
                              "normal": normal}, overwrite=True)
    seconds = time.perf_counter() - t0
    log.info("tile %d: %d core + %d halo points, %d boundary, %.1f s", tile, n_core,
             len(xyz) - n_core, int(boundary.sum()), seconds)
    return {"tile": int(tile), "n_core": int(n_core), "n_halo": int(len(xyz) - n_core),
            "n_boundary": int(boundary.sum()), "seconds": seconds}
