"""What runs for one tile: read core + halo from the store, run the core, write back.

Two tasks per tile: :func:`deviation_histogram` (threshold pass) builds the tile's
neighbourhoods, saves them in the store and returns the histogram of its boundary measure;
:func:`simplify_tile` restores them (or builds them, if that pass did not run) and runs the
removal down to the depth it is given. Tasks take the store's path and a tile id — nothing
large passes through the scheduler — and are plain module-level functions, so threads,
processes and dask.distributed workers all run them the same way and get the same result.
"""

import math
import time
import warnings

import numpy as np

from ..core import SimplifyOptions, compile_cache, simplify_points
from ..core.simplify import Neighbourhoods, neighbourhood_state
from ..errors import BudgetWarning, InputError
from ..tiles import TileStore

#: dtype of the normals a tile stores (and the output writes)
NORMAL_DTYPE = np.float32
#: what a tile's results hold, saved in the store's settings: a store whose tiles saved other
#: results is refused, not misread (until 2026-12-05 ``boundary`` was also what the gap
#: refinement keeps, and ``protected`` the rest of it; then the flags reached one spacing from
#: the edge and ``fixed`` held what the refinement keeps; since that night ``feature`` holds
#: the points the refinement keeps covered, and ``boundary`` only the flags reported)
TILE_RESULTS = "step, importance, boundary, feature, fixed, normal"


def _ignore_tile_budget_warnings():
    """A tile that cannot reach its floor is exhausted, not short of a budget: the global cut
    says whether the run reaches its count. A filter matching only warnings raised from calls
    in this module (``catch_warnings`` is not thread-safe), set again by every task because a
    caller's ``catch_warnings`` may have dropped it."""
    warnings.filterwarnings("ignore", category=BudgetWarning,
                            module=__name__.replace(".", r"\."))


#: fixed log-spaced bins for the global boundary threshold (deviation is ~ an angle, radians)
BINS = np.concatenate([[0.0], np.geomspace(1e-7, 4.0, 4095)])


def _tile_cloud(store, tile):
    core_xyz = store.core_xyz(tile)
    halo_xyz = store.tile_halo(tile)[0]
    xyz = np.concatenate([core_xyz, halo_xyz])
    frozen = np.zeros(len(xyz), dtype=bool)
    frozen[len(core_xyz):] = True
    return xyz, frozen, len(core_xyz)


def classes_ok(classification, no_edge):
    """The points whose ``classification`` is not one of the codes ``no_edge``: those that
    may be edge points (``simplify_points``' ``edge_ok``)."""
    return ~np.isin(classification, np.asarray(no_edge))


def missing_classification(input, names):
    """The error for ``no_edge_classes`` on an input whose dimensions ``names`` hold no
    ``classification``."""
    return InputError(f"{input}: no_edge_classes (--no-edges-on) names classification codes, "
                      f"but the input has no classification dimension (it has: "
                      f"{', '.join(names) or 'coordinates only'}); leave it out.")


def edge_ok(store, tile, no_edge):
    """The tile's points (core, then halo, as :func:`_tile_cloud` stacks them) that may be edge
    points: those whose ``classification`` is not one of ``no_edge`` (``simplify_points``'s
    ``edge_ok``), each halo point's read from its own tile, so that a point is judged alike in
    every tile it is part of; None where ``no_edge`` is empty."""
    if not no_edge:
        return None
    core = store.attrs(tile, ["classification"])["classification"]
    _, _, owner, row = store.tile_halo(tile)
    halo = np.empty(len(row), dtype=core.dtype)
    for u in np.unique(owner).tolist():
        at = owner == u
        halo[at] = store.attrs(u, ["classification"])["classification"][row[at]]
    return classes_ok(np.concatenate([core, halo]), no_edge)


def _save_state(store, tile, state, n_points):
    arrays, how = state.to_arrays()
    store.write_state(tile, arrays, {"how": how, "n_points": int(n_points)})


def _state(store, tile, n_points):
    """The tile's neighbourhood state: restored from the store if the threshold pass saved
    it there (mode "paper"), else None — :func:`simplify_points` builds it (the same state,
    without the paper's deviation measure that :func:`neighbourhood_state` adds, and no
    reference held here while the pre-thinning builds its subset's) — and not saved.

    Saving it for a deeper pass cost more than it saved: the state is ~70 B a point on disk
    (zarr, compressed; ~120 B in memory), so every tile's state at once — they all live
    until the global cut — made the store's peak ~2.5x its final size (~110 B a point: 110
    GB for a billion points), and writing it took 7-12 % of the time to build it, on every
    tile, while a deeper pass (which rebuilds it now) runs on few tiles or none (0 of 10 on
    the 1M scan of ``benchmarks/pipeline_speed.py``, 0 of 9 on lone-star.laz at the default
    floor; alternating in one process, the whole run took 0.93-0.96x the time). Mode
    "paper" must build every state before its threshold is known, so there the threshold
    pass saves them and the later passes restore them.
    """
    saved = store.read_state(tile)
    if saved is not None and saved[1].get("n_points") == n_points:
        return Neighbourhoods.from_arrays(saved[0], saved[1]["how"])
    return None


def deviation_histogram(store_path, tile, options, no_edge=()):
    """Threshold pass for one tile: build and save its neighbourhoods (paper steps 1-2; their
    reach from ``options``, a :class:`SimplifyOptions` dict with the run's spacing), and
    return the histogram (over :data:`BINS`) of its core points' boundary measure — of those
    that may be edge points (:func:`edge_ok`: not of the classes ``no_edge``).

    Returns ``{"tile", "hist", "n_points", "n_core", "seconds"}`` (``n_points``: core + halo).
    """
    t0 = time.perf_counter()
    compile_cache.wait()  # a compile ahead running on this machine
    store = TileStore.open(store_path)
    xyz, frozen, n_core = _tile_cloud(store, tile)
    hist = np.zeros(len(BINS) - 1, dtype=np.int64)
    if n_core:
        state, deviation = neighbourhood_state(xyz, frozen, SimplifyOptions(**options))
        _save_state(store, tile, state, len(xyz))
        core = deviation[:n_core]
        if no_edge:  # (the core's classes alone: the halo's are other tiles' to count)
            classes = store.attrs(tile, ["classification"])["classification"]
            core = core[classes_ok(classes, no_edge)]
        hist = np.histogram(np.clip(core, 0.0, BINS[-1]), bins=BINS)[0]
    return {"tile": int(tile), "hist": hist, "n_points": int(len(xyz)), "n_core": int(n_core),
            "seconds": time.perf_counter() - t0}


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


def _halo_frozen(frozen, mode):
    """The halo is frozen in mode "paper"; in mode "coverage" it is simplified with the core.

    The coverage measure sees the spacing of a point's neighbours. A frozen halo keeps full
    density to the end, so core points along the tile border look crowded and go first:
    measured on the Bunny in 8 tiles, the kept density in a band two spacings wide around the
    tile faces fell to 0.47 of the untiled run's. Simplifying the halo too (its results are
    discarded; the neighbouring tile owns those points) lets the border see a neighbourhood
    thinned as the untiled run would thin it.
    """
    return frozen if mode == "paper" else None


def simplify_tile(store_path, tile, options, threshold, depth, share=None, no_edge=()):
    """Simplify one tile (halo frozen in mode "paper", simplified with the core otherwise, see
    :func:`_halo_frozen`) down to ``depth``; write the core points' results; mark it done.

    Parameters
    ----------
    store_path : str
    tile : int
    options : dict
        :class:`SimplifyOptions` fields (``progressive``, ``progressive_until`` and
        ``refine`` are set here).
    threshold : float or None
        The global boundary threshold.
    depth : ("keep", k) or ("level", L)
        How far the tile's removal sequence is run. ``("keep", k)``: until ``k`` core points
        remain (the first pass; with a simplified halo, until the same share of the whole
        tile remains). ``("level", L)``: until the running maximum of importance at
        removal exceeds ``L`` (a deeper pass asked for by the global cut; ``inf`` runs to
        the end). Either way the recorded sequence is a prefix of the full one.
    share : float or None
        The global target's share of the input (target / points). The pre-thinning
        (``prethin``) aims at this share of the tile in every pass, so the passes thin a
        tile the same way and the deeper pass's sequence extends the first one's. None: the
        pass's own count.
    no_edge : sequence of int
        LAS classification codes whose points are never edge points (:func:`edge_ok`).

    Returns
    -------
    dict
        ``tile``, ``n_core``, ``n_halo``, ``n_boundary``, ``steps`` (core removals recorded),
        ``exhausted`` (every removable point was removed), ``level`` (running maximum at
        the last recorded removal) and ``seconds``.

    Notes
    -----
    Results per core point: ``step`` (position among the core points in the tile's removal
    sequence, -1 if not reached), ``importance`` (at removal, NaN if not reached; with a
    simplified halo, the running maximum over the whole tile's sequence at that removal — the
    level the global cut compares, and a prefix of it is known exactly when the run stops at a
    level), ``boundary`` (the flags), ``feature``
    (:attr:`~tiledsimplify.core.result.SimplifyResult.features`: what the gap refinement keeps
    within its edge cover radius of a kept point), ``fixed`` (the features' core band,
    :attr:`~tiledsimplify.core.result.SimplifyResult.band`, and the points whose boundary
    measure is above :data:`~tiledsimplify.core.refine.PROTECT` times the threshold, with a
    point that is not within two steps, :func:`~tiledsimplify.core.refine.protected`: points
    the gap refinement keeps where the cut does, as the untiled core does), ``normal``; the
    result attributes ``exhausted``, ``steps`` and ``depth`` tell the global cut how far the
    sequence is known.
    """
    t0 = time.perf_counter()
    compile_cache.wait()  # a compile ahead running on this machine
    store = TileStore.open(store_path)
    xyz, frozen, n_core = _tile_cloud(store, tile)
    step = np.full(n_core, -1, dtype=np.int64)
    imp = np.full(n_core, np.nan)
    boundary = np.zeros(n_core, dtype=bool)
    feature = np.zeros(n_core, dtype=bool)
    fixed = np.zeros(n_core, dtype=bool)
    normal = np.zeros((n_core, 3), dtype=NORMAL_DTYPE)
    kind, value = depth
    _ignore_tile_budget_warnings()
    exhausted, n_steps = True, 0
    known_level = float("-inf")
    if n_core:
        tile_options = SimplifyOptions(**options)
        tile_frozen = _halo_frozen(frozen, tile_options.mode)
        soft = tile_frozen is None
        state = _state(store, tile, len(xyz))
        if kind == "keep":
            n_remove = max(n_core - int(value), 0)
            if soft:  # the halo thins with the core: remove the same share of the whole tile
                n_remove = min(int(np.ceil(n_remove * len(xyz) / n_core)), len(xyz))
            opts = {**options, "progressive": False, "progressive_until": None}
            count = len(xyz) - n_remove
        elif kind == "level":
            level = float(value)
            opts = {**options, "progressive": True,
                    "progressive_until": level if np.isfinite(level) else None}
            count = len(xyz)
        else:
            raise InputError(f"depth must be ('keep', count) or ('level', value), got {depth!r}")
        opts["boundary_threshold"] = threshold
        opts["refine"] = False  # only the order is used here; the kept set is the global cut's
        aim = None if share is None else math.ceil(share * len(xyz))
        res = simplify_points(xyz, count=count, frozen=tile_frozen,
                              options=SimplifyOptions(**opts), state=state, prethin_target=aim,
                              covered=~frozen,  # a halo point's own tile may remove it
                              edge_ok=edge_ok(store, tile, no_edge))
        n_all = int(res.order.size)
        if kind == "keep":
            exhausted = n_all < n_remove
        else:
            exhausted = n_all == 0 or not res.order_importance[-1] > level
        at = np.maximum.accumulate(res.order_importance) if soft else res.order_importance
        if soft and n_all:  # later core steps come after the last removal (maybe a halo one)
            known_level = float(at[-1])
        core = res.order < n_core
        n_steps = int(core.sum())
        step[res.order[core]] = np.arange(n_steps)
        imp[res.order[core]] = at[core]
        boundary = res.boundary[:n_core]
        feature = res.features[:n_core]
        fixed = res.band[:n_core] | res.protected[:n_core]
        normal = res.normals[:n_core].astype(NORMAL_DTYPE)
    store.write_result(tile, {"step": step, "importance": imp, "boundary": boundary,
                              "feature": feature, "fixed": fixed, "normal": normal}, overwrite=True,
                       attrs={"exhausted": bool(exhausted), "steps": n_steps,
                              "known_level": known_level,
                              "depth": [kind, float(value)]})
    return {"tile": int(tile), "n_core": int(n_core), "n_halo": int(len(xyz) - n_core),
            "n_boundary": int(boundary.sum()), "steps": n_steps, "exhausted": bool(exhausted),
            "level": float(np.max(res.order_importance)) if n_steps else float("-inf"),
            "seconds": time.perf_counter() - t0}
