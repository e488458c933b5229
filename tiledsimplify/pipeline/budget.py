"""One global budget across tiles: cut every tile at one importance level (DESIGN §3).

Each tile records its removal sequence. Its running maximum of importance-at-removal is
non-decreasing, so "remove every step whose running maximum is below a level" takes a prefix of
every tile's sequence, and a flat tile (low importances) gives up more of its points than a
curved one. Merging the running maxima of all tiles and taking the ``n - target`` smallest
(ties: tile id, then step) hits the requested count exactly.
"""

import numpy as np


def tile_sequence(step, importance):
    """A tile's importance-at-removal in removal order, from its per-point results."""
    removed = step >= 0
    order = np.argsort(step[removed], kind="stable")
    return importance[removed][order]


def global_cut(sequences, n_remove):
    """How many removal steps of each tile to apply.

    Parameters
    ----------
    sequences : dict tile -> float array
        Each tile's importance at removal, in removal order.
    n_remove : int
        Points to remove overall.

    Returns
    -------
    dict tile -> int
        The prefix length per tile; their sum is ``min(n_remove, total available)``.
    """
    tiles = sorted(sequences)
    prefix = {t: 0 for t in tiles}
    if n_remove <= 0 or not tiles:
        return prefix
    runmax = [np.maximum.accumulate(np.asarray(sequences[t], float)) for t in tiles]
    level = np.concatenate(runmax) if runmax else np.empty(0)
    tile_of = np.concatenate([np.full(len(r), i) for i, r in enumerate(runmax)])
    step_of = np.concatenate([np.arange(len(r)) for r in runmax])
    take = np.lexsort((step_of, tile_of, level))[:n_remove]
    counts = np.bincount(tile_of[take], minlength=len(tiles))
    return {t: int(counts[i]) for i, t in enumerate(tiles)}


def store_cut(store, n_remove):
    """:func:`global_cut` over the finished tiles of a :class:`~tiledsimplify.tiles.TileStore`."""
    seqs = {i: tile_sequence(store.read_result(i, "step"), store.read_result(i, "importance"))
            for i in range(store.n_tiles)}
    return global_cut(seqs, n_remove)


def kept_in_tile(store, tile, cut):
    """Bool mask over a tile's core points: kept after the first ``cut[tile]`` removals."""
    step = store.read_result(tile, "step")
    return (step < 0) | (step >= cut[tile])


def kept_mask(store, cut):
    """Bool mask over the whole input (by original index) of the points kept after ``cut``."""
    keep = np.zeros(store.n_total, dtype=bool)
    for i in range(store.n_tiles):
        keep[store.core(i)[1]] = kept_in_tile(store, i, cut)
    return keep
