"""One global budget across tiles: cut every tile at one importance level (DESIGN §3).

Each tile records its removal sequence. Its running maximum of importance-at-removal is
non-decreasing, so "remove every step whose running maximum is below a level" takes a prefix of
every tile's sequence, and a flat tile (low importances) gives up more of its points than a
curved one. Ordering all steps of all tiles by the key (running maximum, tile, step) and taking
the ``n - target`` smallest hits the requested count exactly.

Tiles are not run to the end of their sequence (its end is wasted work, see ``floor`` in
:func:`~tiledsimplify.pipeline.run`), so a tile may know only a prefix of its sequence, up to a
running maximum ``L_t`` after ``r_t`` steps. Every step it does not know has a key of at least
``(L_t, t, r_t)``. The cut over the known steps is therefore the cut over the full sequences
if its last key is below that bound for every tile that was not run to the end;
:func:`deeper_tiles` names the tiles for which it is not, and the level they must pass.
Running those tiles on past that level can only lower the cut (more steps compete for the same
count), so one deeper pass is enough.
"""

import numpy as np


def tile_sequence(step, importance):
    """A tile's importance-at-removal in removal order, from its per-point results."""
    removed = step >= 0
    order = np.argsort(step[removed], kind="stable")
    return importance[removed][order]


def _cut(sequences, n_remove):
    """The cut over the known steps: ``(prefix, level, last_tile, short)``.

    ``prefix`` maps tile -> steps taken; ``(level, last_tile)`` is the key of the last step
    taken (``(-inf, -1)`` when nothing is removed); ``short`` is True when the known steps
    number fewer than ``n_remove``.
    """
    tiles = sorted(sequences)
    runmax = {t: np.maximum.accumulate(np.asarray(sequences[t], dtype=np.float64))
              for t in tiles}
    prefix = {t: 0 for t in tiles}
    total = sum(r.size for r in runmax.values())
    take = min(max(int(n_remove), 0), total)
    if take == 0:
        return prefix, -np.inf, -1, n_remove > total
    levels = np.concatenate([runmax[t] for t in tiles])
    levels.partition(take - 1)
    level = float(levels[take - 1])
    del levels
    rest = take
    for t in tiles:  # every step below the level, then ties at the level by tile, step
        below = int(np.searchsorted(runmax[t], level, side="left"))
        prefix[t] = below
        rest -= below
    last = -1
    for t in tiles:
        if rest == 0:
            break
        equal = int(np.searchsorted(runmax[t], level, side="right")) - prefix[t]
        k = min(equal, rest)
        if k:
            prefix[t] += k
            rest -= k
            last = t
    if last == -1:  # the last step taken lies below the level: cannot happen, see partition
        raise AssertionError("global cut: no step at the cut level")
    return prefix, level, last, n_remove > total


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

    Notes
    -----
    Memory: one float per known step (a selection, not a sort, finds the level).
    """
    return _cut(sequences, n_remove)[0]


def deeper_tiles(sequences, n_remove, exhausted, known=None):
    """Tiles whose known sequence stops short of the global cut, and how far they must go.

    Parameters
    ----------
    sequences : dict tile -> float array
        As for :func:`global_cut` (the known prefix of each tile's sequence).
    n_remove : int
    exhausted : dict tile -> bool
        True if the tile was run to the end of its sequence.
    known : dict tile -> float, optional
        A level every unknown step of the tile is known to reach (default: the last known
        step's). A tile whose halo is simplified with its core stops on a halo removal as
        often as on a core one; its unknown core steps then lie above that removal's level.

    Returns
    -------
    dict tile -> float
        For each tile that must be run deeper, the level its running maximum must pass
        (``inf``: to the end). Empty when :func:`global_cut` is already exact.
    """
    prefix, level, last, short = _cut(sequences, n_remove)
    if n_remove <= 0:
        return {}
    need = {}
    for t, seq in sequences.items():
        if exhausted[t]:
            continue
        if short:
            need[t] = np.inf
            continue
        top = float(np.max(seq)) if len(seq) else -np.inf  # L_t
        if known is not None:
            top = max(top, float(known.get(t, -np.inf)))
        # the unknown steps have keys >= (top, t, len(seq)); the last taken is (level, last, .)
        if top < level or (top == level and t < last):
            need[t] = level
    return need


def store_sequences(store):
    """Every tile's known sequence, whether it is complete, and the level its unknown steps
    reach (see :func:`deeper_tiles`), from a finished store."""
    seqs, exhausted, known = {}, {}, {}
    for i in range(store.n_tiles):
        seqs[i] = tile_sequence(store.read_result(i, "step"), store.read_result(i, "importance"))
        attrs = store.result_attrs(i)
        exhausted[i] = bool(attrs.get("exhausted", True))
        known[i] = float(attrs.get("known_level", -np.inf))
    return seqs, exhausted, known


def store_cut(store, n_remove):
    """:func:`global_cut` over the finished tiles of a :class:`~tiledsimplify.tiles.TileStore`."""
    return global_cut(store_sequences(store)[0], n_remove)


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
