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
