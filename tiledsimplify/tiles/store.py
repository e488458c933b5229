"""A zarr v3 store of overlapping spatial tiles, filled by streaming a huge point cloud.

Layout of the store directory (a zarr v3 group)::

    zarr.json                      root attributes (see below)
    tiles/<id>/xyz                 float64 (r, 3)  core points of tile <id>
    tiles/<id>/index               int64 (r,)      their global index in the input
    tiles/<id>/attributes          uint8 (r, B)    every per-point attribute of the input, each
                                                   point's values packed in one row of bytes
                                                   (format 3, :func:`layout.attribute_layout`;
                                                   formats 1-2: tiles/<id>/attrs/<name>, an
                                                   array each)
    tiles/<id>/result/<name>       (k, ...)        written by :meth:`TileStore.write_result`;
                                                   the result group's attribute ``done`` is
                                                   set true only after all its arrays are written
    tiles/<id>/state/<name>        any shape       scratch state one pass leaves for the next
                                                   (:meth:`TileStore.write_state`), same rule
    tiles/<id>/refined/kept        bool (k,)       final kept flags after the global cut
                                                   (:meth:`TileStore.write_refined`), same rule
    tiles/<id>/halo/<name>         (h, ...)        the tile's halo points and where they are
                                                   stored (:meth:`TileStore.tile_halo`, saved
                                                   the first time it is read), same rule

Root attributes: ``format``/``format_version``, ``complete`` (false until the ingest has
finished), ``plan`` (:meth:`TilePlan.to_dict`), ``halo``, ``halo_is_default``, ``spacing``,
``spacing_estimate`` (how it was obtained), ``n_total``, ``tile_points``, ``tile_counts``,
``bounds``, ``chunk_rows``, ``attributes`` (name -> dtype and trailing shape),
``attribute_stats`` (name -> its least and largest value and whether all are whole numbers,
numeric attributes; since 2026-12-07, stop 66), ``sample_size``, ``seed``, ``ingest_parts``,
``part_starts`` and ``part_counts`` (below), ``config`` (the caller's dict) and
``provenance`` (the caller's dict plus package, zarr and numpy versions and the UTC creation
time).

The ingest reads the input as consecutive parts (one by default; several read by workers at
once, :meth:`TileStore.create`'s ``parts``). Each part owns a region of every tile's
``xyz``/``index``/``attrs`` arrays: ``r`` rows in all, part ``k``'s from row
``part_starts[k]`` (its points rounded up to whole chunks), of which the first
``part_counts[k][id]`` hold its points in tile ``id``. A tile's core is those rows, part after
part: the input order, however many parts. The rest is never written (zarr stores no chunk
for it).

Input is any callable returning a fresh iterable of chunks ``(start_index, xyz, attrs)``:
``xyz`` is a finite float64 ``(m, 3)`` array, ``attrs`` maps names to ``(m, ...)`` arrays and
the chunk holds the points with global indices ``start_index .. start_index + m - 1``. The
chunks together must cover ``0 .. n-1`` exactly once (in any order). The callable is called
twice (sampling pass, then writing pass) and must yield the same chunks both times. Memory use
is bounded by the sample size, two input chunks (one read while the other is sorted) and the
write buffer (``buffer_points``), never by the size of the input.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import zarr
from zarr.core.group import GroupMetadata

from ..errors import InputError, TiledSimplifyError
from .ingest import (ReadOnce, fill_part, lay_out_tiles, map_here, merge_specs, merge_stats,
                     scan_part, value_stats)
from .layout import (NAME_RE, array_templates, attribute_layout, codec, tile_nodes,
                     unpack_attribute)
from .local_store import InlineStore
from .partition import TilePlan, plan_tiles
from .sampling import BottomK, estimate_spacing, key_limit

__all__ = [
    "ChunkSource",
    "IncompleteStoreError",
    "ResultExistsError",
    "StoreError",
    "StoreExistsError",
    "TileStore",
]

ChunkSource = Callable[[], Iterable[tuple[int, np.ndarray, Mapping[str, np.ndarray]]]]

FORMAT = "tiledsimplify.tilestore"
FORMAT_VERSION = 3
#: store versions this code reads (2: each part of the ingest writes its own region of a
#: tile's arrays, ``part_starts`` / ``part_counts``; in 1 the arrays held the rows alone; 3:
#: a tile's attributes packed in one array, :func:`layout.attribute_layout`)
READS_VERSIONS = (1, 2, 3)
DEFAULT_CHUNK_ROWS = 65_536
HALO_SPACINGS = 10.0


class StoreError(TiledSimplifyError, OSError):
    """The tile store on disk is missing, not a tile store, or not usable as it is."""


class IncompleteStoreError(StoreError):
    """The store's ingest never finished (it was interrupted): its tiles are not trustworthy."""


class StoreExistsError(StoreError, FileExistsError):
    """A tile store (or other content) is already at the path given for a new store."""


class ResultExistsError(TiledSimplifyError, FileExistsError):
    """A tile already has a finished result and overwriting was not asked for."""


def _jsonable(obj: Any, what: str) -> Any:
    """Return ``obj`` as plain JSON data (numpy scalars/arrays and paths converted)."""

    def conv(o):
        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, (Path, os.PathLike)):
            return os.fspath(o)
        if isinstance(o, (set, frozenset)):
            return sorted(o)
        raise TypeError(f"{type(o).__name__} is not JSON serialisable")

    try:
        return json.loads(json.dumps(obj, default=conv, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise InputError(f"{what} must be JSON-serialisable (numbers must be finite): {exc}") \
            from None


def _in_box(xyz: np.ndarray, lo, hi) -> np.ndarray:
    """Rows of ``xyz`` with ``lo <= p <= hi`` on every axis, ascending: an axis at a time,
    each on the rows the ones before kept (a neighbouring tile's core mostly fails the first:
    0.19 ms against 2.0 for the three at once, 100k points)."""
    rows = None
    for d in range(3):
        c = xyz[:, d] if rows is None else xyz[rows, d]
        inside = (c >= lo[d]) & (c <= hi[d])
        rows = np.flatnonzero(inside) if rows is None else rows[inside]
        if not rows.size:
            break
    return rows


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def _package_version() -> str:
    try:
        from importlib.metadata import version

        return version("tiledsimplify")
    except Exception:  # noqa: BLE001 - not installed as a distribution
        return "unknown"


# ---------------------------------------------------------------------------- the store
class TileStore:
    """Tiles of a point cloud in a zarr v3 group directory.

    Create one with :meth:`create` (streams the input twice) and reopen it with :meth:`open`.
    Core data is read-only after creation; per-tile results are written with
    :meth:`write_result`. Different processes may write results of *different* tiles at the
    same time (each tile's result lives in its own group); one tile must not be written by two
    processes at once.
    """

    def __init__(self, path, root: zarr.Group):
        """Wrap an opened root group; use :meth:`open` or :meth:`create` instead."""
        self.path = Path(path)
        self._store = root.store
        self._root = root
        a = dict(root.attrs)
        self._attrs = a
        self.plan = TilePlan.from_dict(a["plan"])
        self._arrays: dict[tuple[int, str], Any] = {}
        self._part_counts = np.asarray(a.get("part_counts", []), dtype=np.int64).reshape(
            -1, self.plan.n_tiles)

    # ------------------------------------------------------------------ creation
    @classmethod
    def create(cls, path, chunks: ChunkSource, *, tile_points: int, halo: float | None = None,
               config: dict, provenance: dict, sample_size: int = 200_000, seed: int = 0,
               n_total: int | None = None, chunk_rows: int | None = None,
               buffer_points: int = 2_000_000, overwrite: bool = False,
               progress=None, parts=None, map_parts=None) -> "TileStore":
        """Stream a point cloud into a new tile store.

        Pass 1 reads every chunk once to count the points, check that the chunks cover
        ``0..n-1`` exactly once, take the bounding box and draw a uniform sample of at most
        ``sample_size`` points (bottom-k of a seeded hash of the global index: a reservoir
        sample independent of how the input is chunked). From the sample it estimates the
        point spacing (:func:`sampling.estimate_spacing`) and plans the tiles
        (:func:`plan_tiles`). Pass 2 reads the chunks again (an input of at most
        ``buffer_points`` points read in this process is kept from pass 1 instead,
        :class:`ingest.ReadOnce`), assigns each point to its tile and appends it to the tile's
        arrays. ``complete`` is set in the root attributes only at the very end.

        Parameters
        ----------
        path : str or Path
            Directory of the new store. It must not exist, be empty, or (with ``overwrite``)
            be an existing tile store.
        chunks : callable
            ``chunks()`` returns a fresh iterable of ``(start_index, xyz, attrs)``; it is
            called twice (once if the input fits in ``buffer_points``) and must give the same
            chunks both times. Each chunk's arrays must be its own, not a buffer the source
            fills again for the next chunk: the next chunk is read while this one is used,
            and a small input's chunks are kept for the second pass.
        tile_points : int
            Target maximum number of points per tile core.
        halo : float, optional
            Width of the frozen margin around each tile. Default ``10 * spacing`` (ten typical
            point spacings: enough neighbours around a tile edge for local surface fits).
        config : dict
            The run's configuration (JSON-serialisable), stored as is.
        provenance : dict
            Where the data came from (JSON-serialisable); package/zarr/numpy versions and the
            creation time are added.
        sample_size : int, default 200_000
            Size of the planning sample (memory: ~32 bytes per sample point).
        seed : int, default 0
            Seed of the sample; the plan is deterministic for a given input and seed.
        n_total : int, optional
            Expected number of points, checked against the input when given.
        chunk_rows : int, optional
            Rows per zarr chunk. Default: ``tile_points`` rounded up to a power of two,
            clamped to 4,096..65,536.
        buffer_points : int, default 2_000_000
            Maximum points held in the write buffer across all tiles (each tile's rows are
            buffered until a whole zarr chunk can be written); an input of at most this many
            points is read once.
        overwrite : bool, default False
            Replace an existing tile store at ``path``.
        progress : callable, optional
            ``progress(pass_number, points_read)`` as each pass starts (0 points) and after
            each of its chunks (points read so far in that pass); 100M points took 90 s.
            Only without ``map_parts``, which reports progress itself.
        parts : sequence of callables, optional
            The input cut in consecutive parts, each a chunk source like ``chunks`` over a
            contiguous range of the global index (their chunks, part after part, are the
            input's); picklable if ``map_parts`` runs them in other processes. Default: one
            part, ``chunks``.
        map_parts : callable, optional
            ``map_parts(func, args, pass_number)`` returns ``[func(*a) for a in args]``, run
            anywhere (dask workers, other processes): each pass is one task per part, the
            second writing each part's points of a tile to the part's own region of the
            tile's arrays (read back in part order, so a store ingested in parts holds what
            one ingested whole holds); and, between the passes, ``pass_number`` 0: the
            tiles' groups and arrays laid out in batches of tiles (a ``zarr.json`` each).
            Default: the parts one after another in this process.

        Returns
        -------
        TileStore
            The new store, opened for reading and result writing.

        Raises
        ------
        InputError
            Bad chunks, empty input, inconsistent passes or bad options.
        StoreExistsError
            ``path`` holds something and ``overwrite`` is false (or it is not a tile store).
        """
        if not callable(chunks):
            raise InputError("chunks must be a callable returning a fresh iterable of chunks "
                             "(it is read twice)")
        tile_points = int(tile_points)
        if tile_points < 1:
            raise InputError(f"tile_points must be >= 1, got {tile_points}")
        sample_size = int(sample_size)
        if sample_size < 2:
            raise InputError(f"sample_size must be >= 2, got {sample_size}")
        if halo is not None:
            halo = float(halo)
            if not (np.isfinite(halo) and halo >= 0):
                raise InputError(f"halo must be a finite distance >= 0 in the input's units, "
                                 f"got {halo}; leave it out for the default "
                                 f"({HALO_SPACINGS:g} x the estimated spacing).")
        if chunk_rows is None:
            chunk_rows = int(min(DEFAULT_CHUNK_ROWS, max(4096, 1 << (tile_points - 1)
                                                          .bit_length())))
        chunk_rows = int(chunk_rows)
        if chunk_rows < 1:
            raise InputError(f"chunk_rows must be >= 1, got {chunk_rows}")
        buffer_points = max(int(buffer_points), 1)
        config = _jsonable(config if config is not None else {}, "config")
        provenance = _jsonable(provenance if provenance is not None else {}, "provenance")
        if not isinstance(config, dict) or not isinstance(provenance, dict):
            raise InputError("config and provenance must be dicts")
        path = Path(path)
        cls._prepare_path(path, overwrite)

        if parts is None:
            parts = [chunks]
        else:
            parts = list(parts)
            if not parts or not all(callable(part) for part in parts):
                raise InputError("parts must be a non-empty sequence of chunk sources (each a "
                                 "callable returning a fresh iterable of chunks)")
        n_parts = len(parts)
        in_process = map_parts is None
        if in_process:
            map_parts = map_here(progress)
            parts = [ReadOnce(part, buffer_points) for part in parts]

        # ---- pass 1: count, cover check, bounds, sample (one task per part)
        def scan_parts(limit):
            scans = map_parts(scan_part, [(part, sample_size, seed, limit) for part in parts],
                              1)
            sampler = BottomK(sample_size, seed)
            for scan in scans:
                sampler.merge(scan["keys"], scan["index"], scan["xyz"])
            return scans, sampler

        limit = key_limit(sample_size, n_total) if n_parts > 1 else None
        scans, sampler = scan_parts(limit)
        intervals = [tuple(iv) for scan in scans for iv in scan["intervals"]]
        n = cls._check_cover(intervals, n_total)
        if sampler.keys.size < min(sample_size, n):  # pragma: no cover - odds ~1e-15
            scans, sampler = scan_parts(None)
        lo = np.min([scan["lo"] for scan in scans], axis=0)
        hi = np.max([scan["hi"] for scan in scans], axis=0)
        spec = merge_specs([scan["spec"] for scan in scans]) or {}
        sample = sampler.result()
        spacing, sample_median = estimate_spacing(sample, n)
        halo_is_default = halo is None
        if halo is None:
            halo = HALO_SPACINGS * spacing
        bounds = np.stack([lo, hi])
        plan = plan_tiles(sample, n, tile_points, bounds=bounds, halo=halo)
        del sample, sampler

        attrs = {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "complete": False,
            "plan": plan.to_dict(),
            "n_tiles": plan.n_tiles,
            "halo": float(halo),
            "halo_is_default": halo_is_default,
            "spacing": float(spacing),
            "spacing_estimate": {
                "method": "median nearest-neighbour distance in the sample times "
                          "sqrt(sample_size / n_total) (surface-like cloud)",
                "sample_median": sample_median,
                "sample_size": int(min(sample_size, n)),
            },
            "n_total": n,
            "tile_points": tile_points,
            "bounds": bounds.tolist(),
            "chunk_rows": chunk_rows,
            "attributes": {k: {"dtype": dt.str, "shape": list(tr)} for k, (dt, tr)
                           in spec.items()},
            "attribute_stats": merge_stats(scan["attribute_stats"] for scan in scans),
            "sample_size": sample_size,
            "seed": int(seed),
            "ingest_parts": n_parts,
            "config": config,
            "provenance": {**provenance,
                           "tiledsimplify_version": _package_version(),
                           "zarr_version": zarr.__version__,
                           "numpy_version": np.__version__,
                           "created_utc": _now()},
        }
        # ---- layout: the root (marked incomplete) first, then all tile groups and empty
        # arrays at once (concurrent metadata writes). Each part of the input owns a region
        # of every tile's arrays (its points rounded up to whole chunks, in part order): a
        # tile's rows are the first of each region (``part_counts``), read in part order.
        sizes = [-(-sum(m for _, m in scan["intervals"]) // chunk_rows) * chunk_rows
                 for scan in scans]
        starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        attrs["part_starts"] = starts[:-1].tolist()
        store = InlineStore(path)
        root = zarr.open_group(store, mode="w", attributes=attrs)
        rows = int(starts[-1])
        dict(zarr.create_hierarchy(store=store, nodes={"tiles": GroupMetadata()}))
        if in_process:
            templates = array_templates(spec, chunk_rows, rows)
            made = dict(zarr.create_hierarchy(
                store=store, nodes=tile_nodes(range(plan.n_tiles), templates)))
            here = {(t, key): made[f"tiles/{t}/{key}"] for t in range(plan.n_tiles)
                    for key in templates}
            del made
        else:  # the tiles' nodes laid out by the parts' mapper too: a zarr.json each,
            # 0.67 ms apiece here, 2,000 tiles' worth 24 s serial in the client
            batches = np.array_split(np.arange(plan.n_tiles), min(plan.n_tiles, 4 * n_parts))
            map_parts(lay_out_tiles, [(str(path), batch.tolist(), spec, chunk_rows, rows)
                                       for batch in batches], 0)
            here = None

        # ---- pass 2: assign and append, one task per part
        fills = map_parts(fill_part, [
            (str(path), part, int(starts[k]), scans[k]["intervals"], spec, buffer_points, here)
            for k, part in enumerate(parts)], 2)
        counts = np.array([fill["counts"] for fill in fills], dtype=np.int64).reshape(
            n_parts, plan.n_tiles)
        tile_counts = counts.sum(axis=0)
        if int(tile_counts.sum()) != n:  # pragma: no cover - guarded by the checks above
            raise StoreError(f"internal error: wrote {int(tile_counts.sum())} of {n} points")
        done = {"tile_counts": tile_counts.tolist(), "part_counts": counts.tolist(),
                "complete": True}
        root.update_attributes(done)
        return cls.open(path)

    @staticmethod
    def stored_attributes(path) -> dict:
        """The root attributes saved at ``path`` (``format``, ``config``, ``complete``, …),
        read without opening the store, so also those of one whose ingest was interrupted
        (they are written first); ``{}`` if there are none to read."""
        try:
            meta = json.loads((Path(path) / "zarr.json").read_text())
        except (OSError, ValueError):
            return {}
        attrs = meta.get("attributes") if isinstance(meta, dict) else None
        return attrs if isinstance(attrs, dict) else {}

    @classmethod
    def _prepare_path(cls, path: Path, overwrite: bool):
        if path.exists() and not path.is_dir():
            raise StoreExistsError(f"{path} exists and is not a directory; choose a fresh "
                                   "store path")
        if path.is_dir() and any(path.iterdir()):
            if cls.stored_attributes(path).get("format") != FORMAT:
                raise StoreExistsError(f"{path} is not empty and is not a tile store; refusing "
                                       "to write there. Choose a fresh store path.")
            if not overwrite:
                raise StoreExistsError(f"a tile store already exists at {path}; delete it, "
                                       "pass overwrite=True, or choose a fresh store path")

    @staticmethod
    def _check_cover(intervals: list[tuple[int, int]], n_total: int | None) -> int:
        spans = sorted((s, m) for s, m in intervals if m)
        n = 0
        for s, m in spans:
            if s != n:
                what = "overlap" if s < n else "leave a gap"
                raise InputError(f"chunk start indices {what} at index {min(s, n)}: the chunks "
                                 "must cover 0..n-1 exactly once")
            n += m
        if n == 0:
            raise InputError("the input has no points")
        if n_total is not None and int(n_total) != n:
            raise InputError(f"n_total was given as {n_total} but the chunks hold {n} points")
        return n

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, path) -> "TileStore":
        """Open an existing, completely ingested tile store.

        Raises
        ------
        StoreError
            No store at ``path``, or not a tile store (or of an unsupported version).
        IncompleteStoreError
            The ingest that created the store did not finish.
        """
        path = Path(path)
        if not (path / "zarr.json").is_file():
            raise StoreError(f"no tile store at {path} (no zarr.json there)")
        try:
            root = zarr.open_group(InlineStore(path), mode="r+")
            attrs = dict(root.attrs)
        except (OSError, ValueError, KeyError) as exc:
            raise StoreError(f"{path} could not be opened as a zarr v3 group: {exc}") from exc
        if attrs.get("format") != FORMAT:
            raise StoreError(f"{path} is a zarr group but not a tiledsimplify tile store (it "
                             "may be the remains of a creation interrupted at its very start); "
                             "delete it or use a fresh --store path")
        if attrs.get("format_version") not in READS_VERSIONS:
            raise StoreError(f"{path} has tile store format version "
                             f"{attrs.get('format_version')!r}; this version reads "
                             f"{' and '.join(map(str, READS_VERSIONS))}. Re-create the store.")
        if attrs.get("complete") is not True:
            raise IncompleteStoreError(
                f"the tile store at {path} is incomplete: its ingest was interrupted before "
                "finishing. Delete the directory (or use a fresh --store path) and run again.")
        return cls(path, root)

    # ------------------------------------------------------------------ facts
    @property
    def n_tiles(self) -> int:
        """Number of tiles."""
        return self.plan.n_tiles

    @property
    def halo(self) -> float:
        """Width of the frozen margin used by :meth:`halo_points`."""
        return float(self._attrs["halo"])

    @property
    def spacing(self) -> float:
        """Estimated median nearest-neighbour spacing of the cloud (see
        :func:`sampling.estimate_spacing`)."""
        return float(self._attrs["spacing"])

    @property
    def config(self) -> dict:
        """The configuration dict given at creation."""
        return dict(self._attrs["config"])

    @property
    def provenance(self) -> dict:
        """The provenance dict given at creation, plus versions and creation time."""
        return dict(self._attrs["provenance"])

    @property
    def n_total(self) -> int:
        """Number of points of the input."""
        return int(self._attrs["n_total"])

    @property
    def tile_points(self) -> int:
        """Target maximum tile size given at creation."""
        return int(self._attrs["tile_points"])

    @property
    def tile_counts(self) -> np.ndarray:
        """Number of core points of each tile, shape (n_tiles,)."""
        return np.asarray(self._attrs["tile_counts"], dtype=np.int64)

    @property
    def attribute_names(self) -> list[str]:
        """Names of the per-point attributes stored."""
        return list(self._attrs["attributes"])

    @property
    def attribute_dtypes(self) -> dict[str, np.dtype]:
        """Dtype of each stored attribute."""
        return {k: dt for k, (dt, _) in self.attribute_spec.items()}

    @property
    def attribute_spec(self) -> dict[str, tuple[np.dtype, tuple]]:
        """Each stored attribute's ``(dtype, trailing shape)``."""
        return {k: (np.dtype(v["dtype"]), tuple(v["shape"]))
                for k, v in self._attrs["attributes"].items()}

    @property
    def attribute_stats(self) -> dict[str, tuple]:
        """``(least, largest, whole)`` of each numeric attribute in the input (``whole``: every
        value a whole number; None, None, False for a float attribute with NaN or infinities):
        recorded by the ingest (:func:`.ingest.value_stats`; since 2026-12-07, stop 66); for a
        store made before (a run resumed), worked out once from the tiles' core points (every
        input point once) — without them a resumed run's 8-bit colour in 16-bit fields would
        be written ``v >> 8``, and a LAS output could not tell which values fit a LAS
        dimension."""
        if "attribute_stats" not in self._attrs:
            names = [n for n, d in self.attribute_dtypes.items() if d.kind in "iuf"]
            self._attrs["attribute_stats"] = merge_stats(
                value_stats(self.attrs(t, names)) for t in range(self.n_tiles if names else 0))
        return {k: tuple(v) for k, v in self._attrs["attribute_stats"].items()}

    @property
    def attribute_max(self) -> dict[str, int]:
        """The largest value of each integer attribute in the input (:attr:`attribute_stats`)."""
        kinds = self.attribute_dtypes
        return {k: int(hi) for k, (_, hi, _) in self.attribute_stats.items()
                if kinds[k].kind in "iu"}

    @property
    def root_attrs(self) -> dict:
        """All root attributes (a copy)."""
        return json.loads(json.dumps(self._attrs))

    @property
    def run_attrs(self) -> dict:
        """Values a run stored for itself (:meth:`set_run_attrs`), e.g. a global threshold."""
        return dict(self._attrs.get("run", {}))

    def set_run_attrs(self, values: Mapping[str, Any]) -> None:
        """Merge JSON-serialisable ``values`` into the root attribute ``run``."""
        run = self.run_attrs
        run.update(json.loads(json.dumps(dict(values))))
        root = zarr.open_group(self._store, mode="r+")
        root.update_attributes({"run": run})
        self._attrs["run"] = run

    def _tile(self, tile) -> int:
        return self.plan._check_tile(tile)

    def _array(self, tile: int, key: str):
        arr = self._arrays.get((tile, key))
        if arr is None:
            try:
                arr = self._root[f"tiles/{tile}/{key}"]
            except KeyError:
                raise StoreError(f"tile {tile} of the store at {self.path} has no array "
                                 f"{key!r}; the store is damaged") from None
            self._arrays[(tile, key)] = arr
        return arr

    def _read(self, tile: int, key: str) -> np.ndarray:
        """A tile's whole array ``key``: the rows each part of the ingest wrote in its region,
        in part order (format 2), or the whole array (format 1)."""
        arr = self._array(tile, key)
        starts = self._attrs.get("part_starts")
        if starts is None:
            return arr[:]
        counts = self._part_counts[:, tile]
        pieces = [arr[s:s + c] for s, c in zip(starts, counts.tolist()) if c]
        if len(pieces) == 1:
            return pieces[0]
        if not pieces:
            return arr[0:0]
        return np.concatenate(pieces)

    # ------------------------------------------------------------------ reading
    def count(self, tile: int) -> int:
        """Number of core points of a tile."""
        return int(self.tile_counts[self._tile(tile)])

    def box(self, tile: int) -> tuple[np.ndarray, np.ndarray]:
        """The tile's box ``(lo, hi)`` clipped to the cloud's bounding box."""
        return self.plan.box(tile, clip=True)

    def neighbours(self, tile: int, halo: float | None = None) -> np.ndarray:
        """Tiles within ``halo`` (default :attr:`halo`) of this tile (see
        :meth:`TilePlan.neighbours`)."""
        return self.plan.neighbours(tile, self.halo if halo is None else halo)

    def core(self, tile: int) -> tuple[np.ndarray, np.ndarray]:
        """Read a tile's core points.

        Returns
        -------
        xyz : ndarray of float64, shape (k, 3)
        index : ndarray of int64, shape (k,)
            Global input index of each point, in the order the points were read.
        """
        t = self._tile(tile)
        return self._read(t, "xyz"), self._read(t, "index")

    def core_xyz(self, tile: int) -> np.ndarray:
        """A tile's core points (:meth:`core` without the indices, which a tile's passes do
        not need: one array fewer to read and decompress per pass)."""
        return self._read(self._tile(tile), "xyz")

    def core_index(self, tile: int) -> np.ndarray:
        """A tile's core points' global input indices (:meth:`core` without the points)."""
        return self._read(self._tile(tile), "index")

    def halo_points(self, tile: int, halo: float | None = None, *,
                    owners: bool = False) -> tuple[np.ndarray, ...]:
        """Read the points of other tiles that lie within ``halo`` of this tile's box.

        The test is the expanded box: a point ``p`` of another tile is returned when
        ``lo - halo <= p <= hi + halo`` on every axis (a superset of the points within
        Euclidean distance ``halo``). Only the cores of :meth:`neighbours` are read, one at a
        time, so memory is bounded by one tile plus the result.

        Parameters
        ----------
        tile : int
        halo : float, optional
            Defaults to the store's :attr:`halo`.
        owners : bool, default False
            Also return where each point is stored: its tile and its row in that tile's
            core (so a result of that tile can be looked up).

        Returns
        -------
        xyz : ndarray of float64, shape (h, 3)
        index : ndarray of int64, shape (h,)
            Sorted by global index.
        owner, row : ndarray of int64, shape (h,)
            Only with ``owners``: ``core(owner[p])`` holds point ``p`` at ``row[p]``.
        """
        xyz, owner, row = self.near_points(tile, self.halo if halo is None else halo)
        idx = np.empty(len(row), dtype=np.int64)
        ends = np.flatnonzero(np.diff(owner)) + 1  # near_points gives them owner by owner
        for at in np.split(np.arange(len(row)), ends):
            if at.size:
                idx[at] = self.core_index(int(owner[at[0]]))[row[at]]
        order = np.argsort(idx, kind="stable")
        if owners:
            return xyz[order], idx[order], owner[order], row[order]
        return xyz[order], idx[order]

    def near_points(self, tile: int, width: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The points of other tiles within ``width`` of this tile's box (the expanded-box test
        of :meth:`halo_points`, which adds their indices) and where each is stored: ``(xyz,
        owner, row)``, ``core(owner)`` holding each at ``row`` — ordered by owner, then row,
        so the neighbours' indices are not read.

        A view wider than the saved halo for the gap refinement (:mod:`..pipeline.tile_refine`,
        whose result does not depend on the order of a view's points): on the 1M-point scan
        of ``benchmarks/pipeline_speed.py`` a view 2.7 halos wide took 12–16 ms here against
        28–40 ms by :meth:`halo_points` (its neighbours' indices read and sorted by)."""
        t = self._tile(tile)
        w = float(width)
        lo, hi = self.plan.lo[t] - w, self.plan.hi[t] + w
        xs = [np.zeros((0, 3))]
        ts, rs = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
        for j in self.plan.neighbours(t, w):
            if not self.tile_counts[j]:
                continue
            xyz = self.core_xyz(j)
            sel = _in_box(xyz, lo, hi)
            xs.append(xyz[sel])
            ts.append(np.full(sel.size, j, dtype=np.int64))
            rs.append(sel.astype(np.int64))
        return np.concatenate(xs), np.concatenate(ts), np.concatenate(rs)

    def tile_halo(self, tile: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`halo_points` at the store's halo width, with owners: ``(xyz, index, owner,
        row)``; saved in the tile's group the first time (``tiles/<id>/halo``) and read from
        there after.

        Every pass over a tile reads its halo (the tile pass, the cut's Hausdorff distance,
        the refinement), and :meth:`halo_points` decompresses the whole core of every
        neighbouring tile to pick it (~9 neighbours a tile in a 10M run, 83 % of the cut
        pass's time per tile); the saved halo is ~7 % of a tile's points. Only a tile's own
        tasks read or write its halo, one after another, so the saving needs no lock; a
        partial write is never read (the group's ``done`` rule).
        """
        t = self._tile(tile)
        got = self._read_group(t, "halo")
        if got is not None and got[1].get("halo") == self.halo:
            a = got[0]
            return a["xyz"], a["index"], a["owner"], a["row"]
        xyz, index, owner, row = self.halo_points(t, owners=True)
        self._write_group(t, "halo", {"xyz": xyz, "index": index, "owner": owner, "row": row},
                          {"halo": self.halo})
        return xyz, index, owner, row

    def attrs(self, tile: int, names: Iterable[str] | None = None) -> dict[str, np.ndarray]:
        """Read per-point attributes of a tile's core points.

        Parameters
        ----------
        tile : int
        names : iterable of str, optional
            Attribute names; default all.

        Returns
        -------
        dict
            name -> array of shape (k, ...), in the same order as :meth:`core`.
        """
        t = self._tile(tile)
        if isinstance(names, str):
            names = [names]
        names = self.attribute_names if names is None else list(names)
        unknown = [n for n in names if n not in self._attrs["attributes"]]
        if unknown:
            raise InputError(f"unknown attribute(s) {unknown}; the store has "
                             f"{self.attribute_names}")
        if self._attrs.get("format_version", 1) < 3:  # an array per attribute
            return {n: self._read(t, f"attrs/{n}") for n in names}
        if not names:
            return {}
        layout, _ = attribute_layout(self.attribute_spec)
        rec = self._read(t, "attributes")
        return {n: unpack_attribute(rec, layout[n]) for n in names}

    # ------------------------------------------------------------------ results
    def _result_group(self, tile: int):
        try:
            return zarr.open_group(self._store, path=f"tiles/{tile}/result", mode="r")
        except (FileNotFoundError, KeyError):
            return None

    def is_done(self, tile: int) -> bool:
        """Whether a tile's result was completely written (read fresh from disk)."""
        g = self._result_group(self._tile(tile))
        return g is not None and g.attrs.get("done") is True

    def done_tiles(self) -> list[int]:
        """Ids of the tiles whose result is completely written, ascending."""
        return [t for t in range(self.n_tiles) if self.is_done(t)]

    def pending_tiles(self) -> list[int]:
        """Ids of the tiles still without a complete result, ascending."""
        return [t for t in range(self.n_tiles) if not self.is_done(t)]

    def result_names(self, tile: int) -> list[str]:
        """Names of a done tile's result arrays (empty if not done)."""
        g = self._result_group(self._tile(tile))
        if g is None or g.attrs.get("done") is not True:
            return []
        return list(g.attrs.get("names", []))

    def write_result(self, tile: int, arrays: Mapping[str, Any], *,
                     overwrite: bool = False, attrs: Mapping[str, Any] | None = None) -> None:
        """Write a tile's result arrays, then mark the tile done.

        Each array runs over the tile's core points (first dimension = :meth:`count`). The
        arrays go to ``tiles/<id>/result/<name>``; only when all are written is the result
        group's attribute ``done`` set, so a crash part-way leaves the tile not done and a
        later run simply writes it again. Any earlier (partial or, with ``overwrite``, done)
        result of the tile is removed first.

        Parameters
        ----------
        tile : int
        arrays : mapping name -> array_like
            Numeric or bool arrays of shape (count, ...).
        overwrite : bool, default False
            Replace a tile that is already done.
        attrs : mapping, optional
            JSON-serialisable values stored with the result (:meth:`result_attrs`).

        Raises
        ------
        ResultExistsError
            The tile is done and ``overwrite`` is false.
        InputError
            Bad names or array lengths.
        """
        t = self._tile(tile)
        k = self.count(t)
        data = {}
        for name, arr in arrays.items():
            name = str(name)
            if not NAME_RE.match(name):
                raise InputError(f"result name {name!r} is not usable as a store key (use "
                                 "letters, digits, '_', '-', '.')")
            arr = np.asarray(arr)
            if arr.ndim < 1 or arr.shape[0] != k:
                raise InputError(f"result {name!r} has shape {arr.shape} but tile {t} has {k} "
                                 "core points")
            if arr.dtype.kind not in "biuf":
                raise InputError(f"result {name!r} has dtype {arr.dtype}; only bool, integer "
                                 "and float arrays can be stored")
            data[name] = arr
        if self.is_done(t) and not overwrite:
            raise ResultExistsError(f"tile {t} already has a finished result; pass "
                                    "overwrite=True to replace it")
        self._write_group(t, "result", data, attrs, rows=int(self._attrs["chunk_rows"]))

    def result_attrs(self, tile: int) -> dict:
        """The ``attrs`` stored with a done tile's result (empty if none or not done)."""
        g = self._result_group(self._tile(tile))
        if g is None or g.attrs.get("done") is not True:
            return {}
        return dict(g.attrs.get("attrs", {}))

    # ------------------------------------------------------------------ scratch state
    def write_state(self, tile: int, arrays: Mapping[str, Any],
                    attrs: Mapping[str, Any] | None = None) -> None:
        """Save a tile's intermediate state: arrays of any length, at ``tiles/<id>/state``.

        For work one pass of a run computes and a later pass reuses (the neighbourhoods of
        the tile's points). Like results, the state counts only once all arrays are written;
        an earlier state is replaced.
        """
        self._write_group(self._tile(tile), "state", arrays, attrs)

    def read_state(self, tile: int) -> tuple[dict[str, np.ndarray], dict] | None:
        """A tile's state saved by :meth:`write_state`: ``(arrays, attrs)``, or None."""
        return self._read_group(self._tile(tile), "state")

    def _write_group(self, t: int, group: str, arrays: Mapping[str, Any],
                     attrs: Mapping[str, Any] | None, rows: int | None = None) -> None:
        """Replace ``tiles/<t>/<group>`` with ``arrays`` (chunks of ``rows`` rows, default
        ~1 MiB) and ``attrs``; ``done`` is set only after every array is written, and an old
        group is marked not done before it is deleted, so a crash never leaves one that looks
        complete."""
        tg = zarr.open_group(self._store, path=f"tiles/{t}", mode="r+")
        if group in tg:
            zarr.open_group(self._store, path=f"tiles/{t}/{group}",
                            mode="r+").update_attributes({"done": False})
            del tg[group]
        sg = tg.create_group(group, attributes={"done": False})
        for name, arr in arrays.items():
            arr = np.ascontiguousarray(arr)
            chunk = rows or max(1, (1 << 20) // max(1, arr[:1].nbytes))
            sg.create_array(str(name), data=arr, chunks=(chunk,) + arr.shape[1:],
                            compressors=codec())
        sg.update_attributes({"attrs": json.loads(json.dumps(dict(attrs or {}))),
                              "names": list(arrays), "done": True, "written_utc": _now()})

    def _read_group(self, t: int, group: str) -> tuple[dict[str, np.ndarray], dict] | None:
        try:
            g = zarr.open_group(self._store, path=f"tiles/{t}/{group}", mode="r")
        except (FileNotFoundError, KeyError):
            return None
        if g.attrs.get("done") is not True:
            return None
        return {n: g[n][:] for n in g.attrs["names"]}, dict(g.attrs.get("attrs", {}))

    # ------------------------------------------------------------------ refined kept flags
    def write_refined(self, tile: int, kept, attrs: Mapping[str, Any] | None = None) -> None:
        """Save the kept flags a pass after the global cut chose for a tile's core points
        (the gap refinement), at ``tiles/<id>/refined/kept``; like results, they count only
        once written. Kept apart from the result, which a deeper pass may rewrite;
        ``attrs`` say which cut they refine (:meth:`read_refined`)."""
        t = self._tile(tile)
        kept = np.asarray(kept, dtype=bool)
        if kept.shape != (self.count(t),):
            raise InputError(f"refined kept flags have shape {kept.shape} but tile {t} has "
                             f"{self.count(t)} core points")
        self._write_group(t, "refined", {"kept": kept}, attrs)

    def read_refined(self, tile: int) -> tuple[np.ndarray, dict] | None:
        """A tile's kept flags saved by :meth:`write_refined` and their attrs, or None."""
        got = self._read_group(self._tile(tile), "refined")
        return None if got is None else (got[0]["kept"], got[1])

    def delete_state(self, tile: int) -> None:
        """Remove a tile's state (if any) to free the disk space."""
        tg = zarr.open_group(self._store, path=f"tiles/{self._tile(tile)}", mode="r+")
        if "state" in tg:
            del tg["state"]

    def read_result(self, tile: int, name: str) -> np.ndarray:
        """Read one result array of a done tile.

        Raises
        ------
        InputError
            The tile is not done or has no such result.
        """
        t = self._tile(tile)
        g = self._result_group(t)
        if g is None or g.attrs.get("done") is not True:
            raise InputError(f"tile {t} has no finished result yet")
        names = list(g.attrs.get("names", []))
        if name not in names:
            raise InputError(f"tile {t} has no result {name!r}; it has {names}")
        return g[name][:]

    def __repr__(self) -> str:
        return (f"TileStore({str(self.path)!r}, n_tiles={self.n_tiles}, "
                f"n_total={self.n_total}, halo={self.halo:g})")
