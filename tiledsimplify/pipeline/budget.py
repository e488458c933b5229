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

Memory is bounded by a tile, not by the input (DESIGN §5): the level is found by a radix
selection over the running maxima, read one tile at a time (:func:`_select`), so a store's
sequences (:class:`StoreSequences`) are never all held at once.
"""

from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

#: bits of the key resolved per pass of the radix selection (a histogram of 2**DIGIT counts)
DIGIT = 16
#: steps in the level's candidate range below which the selection finishes on them in memory
COLLECT = 1 << 22
_SIGN = np.uint64(1 << 63)


def tile_sequence(step, importance):
    """A tile's importance-at-removal in removal order, from its per-point results."""
    removed = step >= 0
    s = step[removed]
    imp = importance[removed]
    if s.size and int(s.max()) == s.size - 1:  # the steps 0..k-1 (the tile task writes these)
        seq = np.empty(s.size, dtype=np.float64)
        seq[s] = imp
        return seq
    return imp[np.argsort(s, kind="stable")]


def _keys(seq):
    """The running maximum of ``seq`` as uint64 keys that sort like the floats (sorted)."""
    runmax = np.maximum.accumulate(np.asarray(seq, dtype=np.float64)) + 0.0  # -0.0 -> 0.0
    bits = runmax.view(np.uint64)
    return np.where(bits & _SIGN, ~bits, bits | _SIGN)


def _float(key):
    key = np.uint64(key)
    bits = key & ~_SIGN if key & _SIGN else ~key
    return float(np.array([bits], dtype=np.uint64).view(np.float64)[0])


def count_pass(sequences, tiles, lo, bits, final):
    """One pass of the selection (:func:`_select`) over ``tiles``, read one at a time from
    ``sequences``: per tile the number of keys (:func:`_keys`) below ``lo`` (``below``), its
    number of keys (``size``) and largest running maximum (``top``, -inf: none), and for the
    keys in ``[lo, lo + 2**bits)``: if ``bits`` is 0, their number (``equal``); else, if
    ``final``, the keys themselves (``kept``); else their histogram by their next
    :data:`DIGIT` bits (``hist``). Passes over separate sets of tiles — on a cluster's workers,
    :func:`store_pass` — combine by :func:`merge_passes`."""
    shift = max(bits - DIGIT, 0)
    hi = lo + (1 << bits)
    out = {"hist": np.zeros(1 << DIGIT, dtype=np.int64) if bits and not final else None,
           "below": {}, "equal": {}, "kept": {}, "size": {}, "top": {}}
    for t in tiles:
        key = _keys(sequences[t])
        out["size"][t] = key.size
        out["top"][t] = _float(key[-1]) if key.size else -np.inf
        a = int(np.searchsorted(key, np.uint64(lo))) if lo else 0
        b = int(np.searchsorted(key, np.uint64(hi))) if hi < 1 << 64 else key.size
        out["below"][t] = a
        if bits == 0:  # a single key: the level
            out["equal"][t] = b - a
        elif final:
            out["kept"][t] = key[a:b].copy()  # not a view: it would hold the tile
        else:
            out["hist"] += np.bincount(((key[a:b] - np.uint64(lo)) >> np.uint64(shift))
                                       .astype(np.intp), minlength=1 << DIGIT)
    return out


def merge_passes(passes):
    """One :func:`count_pass` result from those over separate sets of tiles."""
    passes = list(passes)
    out = {name: {k: v for got in passes for k, v in got[name].items()}
           for name in ("below", "equal", "kept", "size", "top")}
    hists = [got["hist"] for got in passes if got["hist"] is not None]
    out["hist"] = np.sum(hists, axis=0) if hists else None
    return out


def store_pass(store_path, tiles, lo, bits, final):
    """:func:`count_pass` over tiles of the tile store at ``store_path``, read where this
    runs (a cluster worker: the cut's passes then read the tiles in parallel, not in the
    client)."""
    from ..tiles import TileStore
    store = TileStore.open(store_path)
    return count_pass(_TileSequence(store), tiles, lo, bits, final)


class _TileSequence:
    """``[tile]`` -> a tile's known sequence, read from a store (what :func:`count_pass` needs
    of :class:`StoreSequences`, without reading every tile's attributes first)."""

    def __init__(self, store):
        self.store = store

    def __getitem__(self, tile):
        return tile_sequence(self.store.read_result(tile, "step"),
                             self.store.read_result(tile, "importance"))


def _select(scan, rank, counts=None):
    """The ``rank``-th smallest (1-based) running maximum over every tile's sequence.

    Returns ``(key, below, equal)``: its key (:func:`_keys`), and per tile the number of steps
    whose running maximum lies below it and at it. A radix selection: each pass
    (``scan(lo, bits, final)``: :func:`count_pass` over every tile) reads the tiles one at a
    time and counts, by their next :data:`DIGIT` bits, the keys in the range the level is
    known to lie in; the range narrows to the digit holding the ``rank``-th key. Once it
    holds at most :data:`COLLECT` keys, a last pass keeps them and selects in memory. Four
    passes at most (64 bits), two or three on real sequences; memory: one tile's keys, a
    histogram and at most :data:`COLLECT` keys. ``counts`` (the first pass's histogram over
    all keys, if the caller has it) saves a pass.
    """
    lo, bits = 0, 64  # the level's key lies in [lo, lo + 2**bits)
    size = None  # keys in that range (unknown before the first pass)
    while True:
        shift = max(bits - DIGIT, 0)  # the digit of this pass: bits shift .. bits - 1
        if counts is not None:
            hist, counts = counts, None
        else:
            final = bits == 0 or (size is not None and size <= COLLECT)
            got = scan(lo, bits, final)
            below, equal = got["below"], got["equal"]
            if bits == 0:
                return lo, below, equal
            if final:
                return _select_kept(got, rank)
            hist = got["hist"]
        cum = np.cumsum(hist)
        d = int(np.searchsorted(cum, rank, side="left"))
        rank -= int(cum[d - 1]) if d else 0
        size = int(hist[d])
        lo += d << shift
        bits = shift


def _select_kept(got, rank):
    """:func:`_select`'s end: the ``rank``-th smallest of the keys a final pass kept, in
    memory — ``(key, below, equal)`` with ``below`` counting the keys before the pass's range
    too."""
    below, equal, kept = got["below"], got["equal"], got["kept"]
    every = np.concatenate(list(kept.values()))
    level = every[np.argpartition(every, rank - 1)[rank - 1]]
    del every
    for t, k in kept.items():
        i = int(np.searchsorted(k, level, side="left"))
        below[t] += i
        equal[t] = int(np.searchsorted(k, level, side="right")) - i
    return int(level), below, equal


class _Cut(NamedTuple):
    prefix: dict  # tile -> steps taken
    level: float  # the running maximum of the last step taken (-inf: none taken)
    last: int  # the tile of the last step taken (-1: none)
    short: bool  # the known steps number fewer than asked for
    top: dict  # tile -> the largest known running maximum (-inf: no step known)


def _cut(sequences, n_remove, scan=None, most=None):
    """The cut over the known steps (:class:`_Cut`), one tile in memory at a time; ``scan``
    runs a pass of the selection over every tile (default: :func:`count_pass` here).

    ``most``: at most this many steps in all, if known. At most :data:`COLLECT`, the first
    pass keeps every key and the selection ends in memory: one pass over the tiles instead
    of two (the 1M scan's cut: ~0.07 s of each pass a reading of every tile's steps and
    importances)."""
    tiles = sorted(sequences)
    if scan is None:
        def scan(lo, bits, final):
            return count_pass(sequences, tiles, lo, bits, final)
    collect = most is not None and most <= COLLECT
    first = scan(0, 64, collect)  # the first pass of the selection, with each tile's size, top
    size, top, hist = first["size"], first["top"], first["hist"]
    total = sum(size.values())
    take = min(max(int(n_remove), 0), total)
    prefix = {t: 0 for t in tiles}
    if take == 0:
        return _Cut(prefix, -np.inf, -1, n_remove > total, top)
    key, below, equal = (_select_kept(first, take) if collect
                         else _select(scan, take, counts=hist))
    rest = take
    for t in tiles:  # every step below the level, then ties at the level by tile, step
        prefix[t] = below[t]
        rest -= below[t]
    last = -1
    for t in tiles:
        if rest == 0:
            break
        k = min(equal[t], rest)
        if k:
            prefix[t] += k
            rest -= k
            last = t
    if last == -1 or rest:  # the take-th step lies at the level: cannot happen
        raise AssertionError("global cut: no step at the cut level")
    return _Cut(prefix, _float(key), last, n_remove > total, top)


def global_cut(sequences, n_remove):
    """How many removal steps of each tile to apply.

    Parameters
    ----------
    sequences : mapping tile -> float array
        Each tile's importance at removal, in removal order (a :class:`StoreSequences` reads
        them from a store as they are needed).
    n_remove : int
        Points to remove overall.

    Returns
    -------
    dict tile -> int
        The prefix length per tile; their sum is ``min(n_remove, total available)``.

    Notes
    -----
    Memory: one tile's sequence at a time and a 2**16 histogram (:func:`_select`).
    """
    return _cut(sequences, n_remove).prefix


def _deeper(cut, sequences, n_remove, exhausted, known):
    if n_remove <= 0:
        return {}
    need = {}
    for t in sequences:
        if exhausted[t]:
            continue
        if cut.short:
            need[t] = np.inf
            continue
        top = cut.top[t]  # L_t
        if known is not None:
            top = max(top, float(known.get(t, -np.inf)))
        # the unknown steps have keys >= (top, t, len(seq)); the last taken is (level, last, .)
        if top < cut.level or (top == cut.level and t < cut.last):
            need[t] = cut.level
    return need


def deeper_tiles(sequences, n_remove, exhausted, known=None):
    """Tiles whose known sequence stops short of the global cut, and how far they must go.

    Parameters
    ----------
    sequences : mapping tile -> float array
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
    return _deeper(_cut(sequences, n_remove), sequences, n_remove, exhausted, known)


def plan_cut(sequences, n_remove, exhausted, known=None, scan=None, most=None):
    """:func:`global_cut` and :func:`deeper_tiles` from one selection: ``(prefix, need)``;
    ``scan(lo, bits, final)``, if given, runs each pass of the selection over every tile
    (:func:`count_pass`; on a cluster, :func:`store_pass` on its workers, merged by
    :func:`merge_passes`); ``most``: at most this many steps in all, if known (one pass
    where at most :data:`COLLECT`)."""
    cut = _cut(sequences, n_remove, scan, most)
    return cut.prefix, _deeper(cut, sequences, n_remove, exhausted, known)


class StoreSequences(Mapping):
    """Every finished tile's known sequence, read from the store when asked for (not kept).

    ``exhausted`` and ``known`` hold, per tile, whether it ran to the end of its sequence and
    the level its unknown steps reach (see :func:`deeper_tiles`).
    """

    def __init__(self, store):
        self.store = store
        self.exhausted, self.known = {}, {}
        for i in range(store.n_tiles):
            attrs = store.result_attrs(i)
            self.exhausted[i] = bool(attrs.get("exhausted", True))
            self.known[i] = float(attrs.get("known_level", -np.inf))

    def __getitem__(self, tile):
        if tile not in self.exhausted:
            raise KeyError(tile)
        return tile_sequence(self.store.read_result(tile, "step"),
                             self.store.read_result(tile, "importance"))

    def __iter__(self):
        return iter(self.exhausted)

    def __len__(self):
        return len(self.exhausted)


def store_sequences(store):
    """Every tile's known sequence (read lazily, :class:`StoreSequences`), whether it is
    complete, and the level its unknown steps reach (see :func:`deeper_tiles`)."""
    seqs = StoreSequences(store)
    return seqs, seqs.exhausted, seqs.known


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
