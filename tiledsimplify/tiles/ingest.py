"""The two passes of the ingest over one part of the input, and what they read and write
with.

Pass 1 (:func:`scan_part`) checks each chunk (:class:`ChunkChecker`), records its
``(start, size)``, the bounds and a sample (:class:`sampling.BottomK`);
pass 2 (:func:`fill_part`) assigns each point to its tile and appends it, in input order, to
the part's own region of the tile's arrays through per-tile buffers (:class:`TileBuffer`)
written one batch behind the reading (:class:`Writes`), the next chunk read in a thread
meanwhile (:func:`read_ahead`). A small input is read once (:class:`ReadOnce`). Between the
passes :func:`lay_out_tiles` lays out the tiles' nodes where the parts run. The passes are
driven by :meth:`store.TileStore.create`, in this process
(:func:`map_here`) or wherever its ``map_parts`` puts them.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import zarr

from ..core.bounds import box
from ..errors import InputError
from .layout import (NAME_RE, array_at, array_templates, attribute_layout, pack_attributes,
                     tile_nodes)
from .local_store import InlineStore
from .partition import TilePlan
from .sampling import BottomK


WRITE_THREADS = 4  # concurrent array writes during ingest (zarr/blosc release the GIL)


class ChunkChecker:
    """Validates chunks and remembers the attribute schema from the first one."""

    def __init__(self):
        self.spec: dict[str, tuple[np.dtype, tuple[int, ...]]] | None = None

    def __call__(self, item) -> tuple[int, np.ndarray, dict[str, np.ndarray]]:
        try:
            start, xyz, attrs = item
        except (TypeError, ValueError):
            raise InputError("each chunk must be a tuple (start_index, xyz, attrs)") from None
        if isinstance(start, (bool, np.bool_)) or not isinstance(start, (int, np.integer)) \
                or start < 0:
            raise InputError(f"a chunk's start_index must be a non-negative integer, got "
                             f"{start!r}")
        xyz = np.asarray(xyz)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise InputError(f"a chunk's xyz must have shape (m, 3), got {xyz.shape} "
                             f"(chunk starting at {start})")
        if xyz.dtype != np.float64:
            if not np.can_cast(xyz.dtype, np.float64, casting="safe"):
                raise InputError(f"a chunk's xyz must be float64, got {xyz.dtype}")
            xyz = xyz.astype(np.float64)
        if not np.isfinite(xyz).all():
            row = start + int(np.flatnonzero(~np.isfinite(xyz).all(axis=1))[0])
            raise InputError(f"point {row} (in the chunk starting at {start}) has a NaN or "
                             "infinite coordinate; drop those points before tiling")
        m = xyz.shape[0]
        if attrs is None:
            attrs = {}
        if not isinstance(attrs, Mapping):
            raise InputError(f"a chunk's attrs must be a mapping name -> array, got "
                             f"{type(attrs).__name__}")
        out = {}
        for name, arr in attrs.items():
            arr = np.asarray(arr)
            if arr.ndim < 1 or arr.shape[0] != m:
                raise InputError(f"attribute {name!r} has shape {arr.shape} but the chunk "
                                 f"starting at {start} has {m} points")
            out[str(name)] = arr
        if self.spec is None:
            spec = {}
            for name, arr in out.items():
                if not NAME_RE.match(name):
                    raise InputError(f"attribute name {name!r} is not usable as a store key "
                                     "(use letters, digits, '_', '-', '.'; no '/')")
                if arr.dtype.kind not in "biuf":
                    raise InputError(f"attribute {name!r} has dtype {arr.dtype}; only bool, "
                                     "integer and float attributes can be stored")
                spec[name] = (arr.dtype, arr.shape[1:])
            self.spec = spec
        if set(out) != set(self.spec):
            raise InputError(f"the chunk starting at {start} has attributes {sorted(out)}, "
                             f"the first chunk had {sorted(self.spec)}")
        for name, (dtype, trail) in self.spec.items():
            arr = out[name]
            if arr.shape[1:] != trail:
                raise InputError(f"attribute {name!r} has per-point shape {arr.shape[1:]} in "
                                 f"the chunk starting at {start}, {trail} in the first chunk")
            if arr.dtype != dtype:
                if not np.can_cast(arr.dtype, dtype, casting="safe"):
                    raise InputError(f"attribute {name!r} is {arr.dtype} in the chunk starting "
                                     f"at {start} but {dtype} in the first chunk")
                out[name] = arr.astype(dtype)
        return int(start), xyz, out


class TileBuffer:
    """Per-tile pending rows, flushed to the zarr arrays in whole chunks where possible.

    Rows go to the arrays from row ``base`` on (a part's region, :func:`fill_part`).
    ``arrays`` is a dict key -> zarr.Array, or a callable returning one at the first flush (a
    part opens only the tiles it has points in)."""

    def __init__(self, arrays, chunk_rows: int, keys: Iterable[str], base: int = 0):
        self._arrays = arrays
        self.rows = chunk_rows
        self.base = int(base)
        self.pieces: dict[str, list[np.ndarray]] = {k: [] for k in keys}
        self.pending = 0
        self.written = 0

    @property
    def arrays(self) -> dict[str, Any]:
        if callable(self._arrays):
            self._arrays = self._arrays()
        return self._arrays

    def add(self, parts: dict[str, np.ndarray]):
        # copies, not views: a view of a few rows would keep the whole input chunk alive, and
        # with many tiles holding remainders, memory would grow with the number of chunks
        for k, v in parts.items():
            self.pieces[k].append(np.array(v, copy=True))
        self.pending += next(iter(parts.values())).shape[0]

    def flush(self, aligned: bool) -> tuple[int, list]:
        """Take pending rows out of the buffer as write jobs.

        With ``aligned``, only rows up to the last whole-chunk boundary are taken, so that
        every write but a tile's last one covers whole zarr chunks (no read-modify-write).

        Returns
        -------
        n : int
            Rows taken.
        jobs : list of (zarr.Array, start, end, data)
            Writes to run (concurrently, each array's in order) with :class:`Writes`.
        """
        if not self.pending:
            return 0, []
        end = self.written + self.pending
        if aligned:
            end = (end // self.rows) * self.rows
        n = end - self.written
        if n <= 0:
            return 0, []
        jobs = []
        for k, arr in self.arrays.items():
            data = np.concatenate(self.pieces[k]) if len(self.pieces[k]) > 1 \
                else self.pieces[k][0]
            jobs.append((arr, self.base + self.written, self.base + end, data[:n]))
            self.pieces[k] = [data[n:].copy()] if n < data.shape[0] else []
        self.written = end
        self.pending -= n
        return n, jobs


def _write_job(job) -> None:
    arr, start, end, data = job
    arr[start:end] = data


class Writes:
    """Write jobs run in ``pool`` one batch behind the caller: :meth:`submit` returns once the
    batch before this one has been written, so the next chunk is read and sorted while this
    one's rows are compressed and written (the 10M scan's ingest waited 3.9 s of its 7.8 s
    second pass for its writes, 2026-12-05). A job starts only after the previous job on the
    same array (a partial chunk's write and the next write to that array may touch one zarr
    chunk). :meth:`drain` waits for the rest; an error of a job is raised by the call that
    waits for it."""

    def __init__(self, pool: ThreadPoolExecutor):
        self.pool = pool
        self.last: dict[int, Any] = {}  # id(array) -> the future of its latest job
        self.batch: list = []  # the futures of the last batch, not waited for yet

    def submit(self, jobs: list) -> None:
        batch = []
        for job in jobs:
            before = self.last.get(id(job[0]))
            if before is not None:
                before.result()  # that array's previous write first
            self.last[id(job[0])] = future = self.pool.submit(_write_job, job)
            batch.append(future)
        older, self.batch = self.batch, batch
        for f in older:
            f.result()

    def drain(self) -> None:
        batch, self.batch, self.last = self.batch, [], {}
        for f in batch:
            f.result()


def map_here(progress):
    """The default ``map_parts`` of :meth:`store.TileStore.create`: the parts one after
    another in this process, reporting ``progress(pass, points read so far in the pass)`` per
    chunk."""

    def run(func, args, pass_number):
        done = 0
        if progress is not None:
            progress(pass_number, 0)
        out = []
        for a in args:
            base = done
            step = None if progress is None else (
                lambda read, base=base: progress(pass_number, base + read))
            result = func(*a, progress=step)
            done += result["points"]
            out.append(result)
        return out

    return run


def read_ahead(chunks: Iterable):
    """``chunks``' items, the next one read in a thread while the caller works on this one:
    the 10M-point LAZ scan's ingest 8.2-8.9 s against 8.7-9.4 (5 alternating pairs,
    2026-12-05; decompression and the LAS fields' copies beside the sorting and writing). At
    most two chunks in memory: the one handed out and the one being read. An error of the
    reader is raised where its item would have come; a caller that stops early stops the
    reader, which closes ``chunks``."""
    import queue
    import threading
    items: queue.Queue = queue.Queue()
    slot = threading.Semaphore(1)  # a chunk may be read: the one before was handed out
    stop = threading.Event()
    end = object()

    def read():
        it = iter(chunks)
        try:
            while True:
                while not slot.acquire(timeout=0.1):
                    if stop.is_set():
                        return
                if stop.is_set():
                    return
                item = next(it, end)
                items.put((item, None))
                if item is end:
                    return
        except BaseException as exc:  # noqa: BLE001 - handed to the caller
            items.put((end, exc))
        finally:
            close = getattr(it, "close", None)
            if close is not None:
                close()

    thread = threading.Thread(target=read, name="tiledsimplify-read-ahead", daemon=True)
    thread.start()
    try:
        while True:
            item, exc = items.get()
            slot.release()
            if item is end:
                if exc is not None:
                    raise exc
                return
            yield item
    finally:
        stop.set()
        slot.release()
        thread.join()


class ReadOnce:
    """A chunk source that a small input is read from once: its first full pass keeps the
    chunks if they hold at most ``max_points`` points together, and the next pass (the
    ingest's second) is handed those instead of reading and decoding the input again; a
    larger input is read again. The kept chunks are released once handed out.

    The 1M-point LAZ scan of ``benchmarks/pipeline_speed.py`` is one chunk, whose reading and
    decompression took ~0.2 s of each pass. Only for an ingest in this process: parts read
    elsewhere (processes, a cluster) are read as before."""

    def __init__(self, source, max_points: int):
        self._source = source
        self._max = int(max_points)
        self._kept = None

    def __call__(self):
        if self._kept is not None:
            kept, self._kept = self._kept, None
            return iter(kept)
        return self._first()

    def _first(self):
        kept, total = [], 0
        for item in self._source():
            if kept is not None:
                try:
                    total += len(item[1])
                except TypeError:  # not a chunk: the ingest's checks name the problem
                    total = self._max + 1
                if total <= self._max:
                    kept.append(item)
                else:
                    kept = None
            yield item
        self._kept = kept  # only once every chunk was read


def scan_part(part, sample_size: int, seed: int, limit: int | None, progress=None) -> dict:
    """Pass 1 of the ingest over one part of the input: its chunks' ``(start, size)``, its
    bounds, its sample (the part's smallest keys, below ``limit`` if given:
    :class:`sampling.BottomK`), the attribute schema of its first chunk and the least and
    largest value of each numeric attribute (:func:`value_stats`). Runs where ``map_parts``
    puts it."""
    check = ChunkChecker()
    sampler = BottomK(sample_size, seed, limit)
    intervals: list[tuple[int, int]] = []
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    read = 0
    stats: dict[str, list] = {}  # each numeric attribute's least, largest value, whole or not
    for item in read_ahead(part()):
        start, xyz, attrs = check(item)
        m = xyz.shape[0]
        intervals.append((start, m))
        read += m
        if progress is not None:
            progress(read)
        if not m:
            continue
        stats = merge_stats([stats, value_stats(attrs)])
        c_lo, c_hi = box(xyz)
        lo = np.minimum(lo, c_lo)
        hi = np.maximum(hi, c_hi)
        sampler.add(start, xyz)
    return {"points": read, "intervals": intervals, "lo": lo, "hi": hi, "keys": sampler.keys,
            "index": sampler.index, "xyz": sampler.xyz, "spec": check.spec,
            "attribute_stats": stats}


def value_stats(attrs):
    """``[least, largest, whole]`` of each numeric attribute of ``attrs`` that holds values,
    ``whole`` whether every value is a whole number — always for integers; a text file's
    float columns may hold a LAS dimension's integers (:func:`.las_output.carried_layout`).
    A float attribute holding NaN or infinities gets ``[None, None, False]``."""
    out = {}
    for name, v in attrs.items():
        if not v.size or v.dtype.kind not in "iuf":
            continue
        if v.dtype.kind in "iu":
            out[name] = [int(v.min()), int(v.max()), True]
            continue
        lo, hi = float(v.min()), float(v.max())  # NaN if any value is
        if np.isfinite(lo) and np.isfinite(hi):
            out[name] = [lo, hi, bool((np.floor(v) == v).all())]
        else:
            out[name] = [None, None, False]
    return out


def merge_stats(stats):
    """The least and largest value of each numeric attribute over ``stats`` (name ->
    ``[least, largest, whole]``: the parts', :func:`scan_part`; the chunks',
    :func:`value_stats`), whole where each is; None where one is."""
    out: dict[str, list] = {}
    for each in stats:
        for name, (lo, hi, whole) in each.items():
            if name in out:
                a, b, w = out[name]
                lo = None if lo is None or a is None else min(lo, a)
                hi = None if hi is None or b is None else max(hi, b)
                whole = bool(whole and w)
            out[name] = [lo, hi, whole]
    return out


def merge_specs(specs):
    """The attribute schema of the whole input from its parts' (None: a part without chunks):
    the first part's, which every other part's must match as a later chunk must match the
    first (:class:`ChunkChecker`)."""
    known = [sp for sp in specs if sp is not None]
    if not known:
        return None
    first = known[0]
    for sp in known[1:]:
        if set(sp) != set(first):
            raise InputError(f"parts of the input have attributes {sorted(sp)} and "
                             f"{sorted(first)}; every chunk must have the same ones")
        for name, (dtype, trail) in first.items():
            d, tr = sp[name]
            if tr != trail or not np.can_cast(d, dtype, casting="safe"):
                raise InputError(f"attribute {name!r} is {d}{list(tr)} in one part of the "
                                 f"input but {dtype}{list(trail)} in the first")
    return first


def lay_out_tiles(path: str, tiles, spec, chunk_rows: int, rows: int, progress=None) -> dict:
    """A ``map_parts`` task of :meth:`store.TileStore.create` (its "pass" 0): lay out the
    nodes of ``tiles`` (:func:`layout.tile_nodes`, arrays of ``rows`` rows in chunks of
    ``chunk_rows``) in the store at ``path``, at once (zarr's concurrent metadata writes),
    where the parts of the input run. Returns ``{"points": 0}``."""
    nodes = tile_nodes(tiles, array_templates(spec, chunk_rows, rows))
    dict(zarr.create_hierarchy(store=InlineStore(path), nodes=nodes))
    return {"points": 0}


def fill_part(path: str, part, base: int, intervals, spec, buffer_points: int,
               arrays=None, progress=None) -> dict:
    """Pass 2 of the ingest over one part: assign each point to its tile and append it, in
    input order, to the tile's arrays from row ``base`` on — the part's own region of every
    tile's arrays, whole chunks that no other part writes, so parts may run at once in any
    processes. ``arrays``: the tiles' arrays by ``(tile, key)`` if the caller made them in
    this process; else made at a tile's first write from tile 0's metadata (every tile's
    array of a key has the same), read once per key. Returns the points read and the rows
    written per tile."""
    store = InlineStore(path)
    root = zarr.open_group(store, mode="r+")
    plan = TilePlan.from_dict(root.attrs["plan"])
    chunk_rows = int(root.attrs["chunk_rows"])
    keys = ["xyz", "index"] + (["attributes"] if spec else [])
    layout, width = attribute_layout(spec)

    metadata = {}

    def tile_arrays(t):
        if arrays is not None:
            return {key: arrays[(t, key)] for key in keys}
        if not metadata:
            metadata.update((key, root[f"tiles/0/{key}"].metadata) for key in keys)
        return {key: array_at(store, f"tiles/{t}/{key}", metadata[key]) for key in keys}

    buffers = [TileBuffer(lambda t=t: tile_arrays(t), chunk_rows, keys, base)
               for t in range(plan.n_tiles)]
    pending_total = 0
    check = ChunkChecker()
    check.spec = spec
    j = 0
    read = 0
    with ThreadPoolExecutor(max_workers=WRITE_THREADS) as pool:
        writes = Writes(pool)
        for item in read_ahead(part()):
            start, xyz, a = check(item)
            m = xyz.shape[0]
            if j >= len(intervals) or tuple(intervals[j]) != (start, m):
                raise InputError(
                    "the chunk source gave different chunks on the second pass (chunk "
                    f"{j}: expected (start, size) "
                    f"{tuple(intervals[j]) if j < len(intervals) else None}, got "
                    f"{(start, m)}); it must be re-iterable and deterministic")
            j += 1
            read += m
            if not m:
                continue
            tile = plan.assign(xyz)
            order = np.argsort(tile, kind="stable")
            counts = np.bincount(tile, minlength=plan.n_tiles)
            edges = np.concatenate([[0], np.cumsum(counts)])
            index = np.arange(start, start + m, dtype=np.int64)[order]
            # take: 2-3x faster than indexing rows with ``order`` (NumPy 2.4, 2026-12-05)
            xyz_s = xyz.take(order, axis=0)
            attrs_s = ({"attributes": pack_attributes(a, layout, width, m).take(order, axis=0)}
                       if spec else {})
            jobs = []
            for t in np.flatnonzero(counts):
                s, e = edges[t], edges[t + 1]
                parts = {"xyz": xyz_s[s:e], "index": index[s:e]}
                for key, v in attrs_s.items():
                    parts[key] = v[s:e]
                buf = buffers[t]
                buf.add(parts)
                pending_total += e - s
                if buf.pending >= chunk_rows:
                    taken, new = buf.flush(aligned=True)
                    pending_total -= taken
                    jobs += new
            if pending_total > buffer_points:
                # Over budget: empty the fullest buffers (partial chunks) to half budget.
                for t in np.argsort([-b.pending for b in buffers], kind="stable"):
                    if pending_total <= buffer_points // 2:
                        break
                    taken, new = buffers[t].flush(aligned=False)
                    pending_total -= taken
                    jobs += new
            writes.submit(jobs)
            del jobs
            if progress is not None:
                progress(read)
        if j != len(intervals):
            raise InputError(f"the chunk source gave {j} chunks on the second pass but "
                             f"{len(intervals)} on the first; it must be re-iterable")
        for b in buffers:  # every tile's last, partial chunk
            writes.submit(b.flush(aligned=False)[1])
        writes.drain()
    return {"points": read, "counts": [b.written for b in buffers]}
