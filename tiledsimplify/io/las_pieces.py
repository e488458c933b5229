"""LAS/LAZ point records packed, and LAZ chunks compressed, away from the file they go to.

A tiled run writes its output in tile order from one process, but turning a tile's points
into the bytes the file holds needs nothing of that file but its layout and, for LAZ, where
the tile's points start in it: a :class:`LasLayout` (the output's header, which pickles)
packs points (:meth:`LasLayout.pack`) into a :class:`LasPiece` — the records' bytes and what
the header needs of them (count, bounds, points by return, the added dimensions' ranges) —
and :meth:`LasLayout.chunked` cuts a piece at the file's LASzip chunk boundaries (every
``chunk_size`` points from the file's first, 50,000 as laspy writes them) and compresses the
whole chunks it holds; the records before its first boundary and from its last on go into the
chunks that straddle two pieces, compressed by :meth:`LasLayout.compress` from the parts of
consecutive pieces. :class:`ChunkWriter`, the LAZ point writer :class:`.las_output.LasOutput` gives
``laspy.LasWriter``, then only appends compressed chunks and writes the chunk table; the
header grows by each piece's summary (:func:`grow_header`). So on a cluster the workers pack
and compress and the client writes bytes (:func:`tiledsimplify.pipeline.output.write_output`);
and the file is the one laspy's own writer makes of the same points, byte for byte: each
chunk is compressed alone either way (tested).

Tried first and dropped: chunks that end with each piece, i.e. variable-size chunks (the
LASzip VLR's chunk size ``2**32 - 1``, a point count per chunk in the table, as COPC files
have). lazrs 0.8.2 (laspy's LAZ backend, the newest on PyPI) reads such files in order but
cannot seek in them (it lands in the wrong chunk past the first), so laspy's ``seek`` could
not read them back (this tool's parallel ingest reads such files by their chunk table since,
:class:`.las.LazChunks`, but other readers would still seek).
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field

import laspy
import numpy as np

from ..core.bounds import box
from ..errors import InputError

_XYZ = ("X", "Y", "Z")
_INT32 = np.iinfo(np.int32)


@dataclass
class LasPiece:
    """Consecutive points of a LAS/LAZ file as packed point records, and what its header
    needs of them.

    ``data``: the point records' bytes (the layout's point format); ``grid_min`` /
    ``grid_max``: the least and largest quantised X, Y, Z; ``returns[r]``: points with return
    number ``r``; ``ranges``: the least and largest raw value of each extra-bytes dimension,
    per element (NaN where none is valid).

    Cut at the file's chunk boundaries (:meth:`LasLayout.chunked`, in place), ``data`` holds
    the whole LASzip chunks the piece spans, ``chunks`` their ``(points, bytes)``, ``head``
    the records before its first boundary (all of them if it holds none) and ``tail`` those
    from its last boundary on (None if it holds none); the summary stays that of every
    point."""

    count: int
    data: bytes
    grid_min: np.ndarray | None = None
    grid_max: np.ndarray | None = None
    returns: np.ndarray | None = None
    ranges: dict = field(default_factory=dict)
    chunks: list = field(default_factory=list)
    head: bytes = b""
    tail: bytes | None = None


def off_grid(path, lo, hi, scales, offsets):
    """The error for coordinates ``lo .. hi`` that do not fit the output's int32 grid."""
    return InputError(
        f"{path}: coordinates {np.asarray(lo)} .. {np.asarray(hi)} do not fit the output's int32 "
        f"grid (scales {np.asarray(scales)}, offsets {np.asarray(offsets)}); points of another "
        "file far from the first one? Rescale the inputs to common offsets first (e.g. `pdal "
        "translate --writers.las.offset_x=auto ...`).")


def fits_grid(lo, hi, scales, offsets):
    """Whether every coordinate within ``lo .. hi`` quantises (``round((x - offset) /
    scale)``, as :meth:`LasLayout.pack` does) into int32."""
    scales = np.asarray(scales, dtype=np.float64)
    offsets = np.asarray(offsets, dtype=np.float64)
    low = np.round((np.asarray(lo, dtype=np.float64) - offsets) / scales)
    high = np.round((np.asarray(hi, dtype=np.float64) - offsets) / scales)
    return bool((low >= _INT32.min).all() and (high <= _INT32.max).all())


class LasLayout:
    """How points become a LAS/LAZ file's bytes: the output header (point format, scales,
    offsets, dimensions) and the names :meth:`pack` expects. Holds only the header and
    names, so it pickles to cluster workers."""

    def __init__(self, path, header: laspy.LasHeader, attribute_names, extra_names):
        self.path = path  # for error messages only
        self.header = header
        self.attribute_names = tuple(attribute_names)
        self.extra_names = tuple(extra_names)

    def vlr(self):
        """The LASzip VLR of this layout's LAZ files (lazrs; chunks of a fixed size, the
        50,000 points laspy writes)."""
        import lazrs
        fmt = self.header.point_format
        return lazrs.LazVlr.new_for_compression(fmt.id, fmt.num_extra_bytes)

    def chunked(self, piece: LasPiece, start: int) -> LasPiece:
        """``piece``, whose first point is the file's point ``start``, cut at the file's
        chunk boundaries, its whole chunks compressed (see :class:`LasPiece`); in place,
        returned."""
        vlr = self.vlr()
        size = self.header.point_format.size
        chunk = vlr.chunk_size()
        first = -start % chunk  # points before the piece's first boundary
        if first >= piece.count:
            piece.head, piece.tail, piece.data = piece.data, None, b""
            return piece
        last = first + (piece.count - first) // chunk * chunk
        raw = piece.data
        piece.head, piece.tail = raw[:first * size], raw[last * size:]
        piece.data, piece.chunks = compress_chunks(vlr, raw[first * size:last * size], size)
        return piece

    def compress(self, parts) -> tuple[bytes, list]:
        """One chunk (or the file's last, shorter one) from the records ``parts`` of
        consecutive pieces (a tail, then heads): ``(bytes, [(points, bytes)])``."""
        return compress_chunks(self.vlr(), b"".join(parts), self.header.point_format.size)

    def pack(self, xyz, attrs=None, extra=None) -> LasPiece:
        """Points as a :class:`LasPiece` (see :meth:`.las_output.LasOutput.write` for the arguments
        and the errors raised)."""
        path = self.path
        xyz = np.asarray(xyz, dtype=np.float64)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise InputError(f"{path}: xyz must have shape (m, 3), got {xyz.shape}")
        m = len(xyz)
        attrs = dict(attrs or {})
        extra = dict(extra or {})
        unknown = sorted(set(attrs) - set(self.attribute_names))
        unknown += sorted(set(extra) - set(self.extra_names))
        if unknown:
            raise InputError(f"{path}: unknown dimension(s) {unknown}; the output has "
                             f"{list(self.attribute_names)}")
        missing = [n for n in self.attribute_names if n not in attrs and n not in extra]
        missing += [n for n in self.extra_names if n not in extra]
        if missing:
            raise InputError(f"{path}: no values given for dimension(s) {missing}; pass "
                             "every input dimension in attrs (from LasSource.chunks) and every "
                             "added one in extra")
        if m == 0:
            return LasPiece(0, b"")
        header = self.header
        scales = np.asarray(header.scales, dtype=np.float64)
        offsets = np.asarray(header.offsets, dtype=np.float64)
        grid = np.round((xyz - offsets) / scales)
        if not np.isfinite(grid).all():
            raise InputError(f"{path}: xyz has NaN or infinite coordinates")
        low, high = box(grid)
        if (low < _INT32.min).any() or (high > _INT32.max).any():
            raise off_grid(path, xyz.min(axis=0), xyz.max(axis=0), scales, offsets)
        rec = laspy.ScaleAwarePointRecord.zeros(m, header=header)
        for axis, dim in enumerate(_XYZ):
            rec[dim] = grid[:, axis].astype(np.int32)
        for name in self.attribute_names + self.extra_names:
            if name in _XYZ:
                continue
            self._set(rec, name, extra[name] if name in extra else attrs[name], m)
        piece = LasPiece(m, b"", grid_min=low.astype(np.int64), grid_max=high.astype(np.int64),
                         returns=np.bincount(np.asarray(rec.return_number, dtype=np.int64),
                                             minlength=16),
                         ranges=_extra_ranges(header, rec))
        piece.data = rec.array.tobytes()
        return piece

    def _set(self, rec, name, values, m):
        values = np.asarray(values)
        if values.shape[:1] != (m,):
            raise InputError(f"{self.path}: dimension {name!r} has {values.shape} values for "
                             f"{m} points")
        dim = self.header.point_format.dimension_by_name(name)
        scaled = dim.scales is not None or dim.offsets is not None
        target = np.dtype(dim.dtype).base if dim.dtype is not None else np.dtype(np.uint8)
        if target.kind in "iu" and not scaled and values.dtype.kind not in "biu":
            raise InputError(f"{self.path}: dimension {name!r} holds integers ({target}) but "
                             f"got {values.dtype} values; convert them first")
        if target.kind in "iu" and not scaled and values.size and values.dtype.kind in "iu":
            info = np.iinfo(target)
            vmin, vmax = int(values.min()), int(values.max())
            if vmin < info.min or vmax > info.max:
                raise InputError(f"{self.path}: dimension {name!r} ({target}) cannot hold "
                                 f"values {vmin} .. {vmax}")
        try:
            rec[name] = values
        except Exception as exc:
            raise InputError(f"{self.path}: cannot store values in dimension {name!r} "
                             f"({type(exc).__name__}: {exc})") from exc


def _extra_ranges(header, rec):
    """The raw least and largest value of every extra-bytes dimension, per element (no-data
    and NaN left out; NaN where nothing is left)."""
    out = {}
    for dim in header.point_format.extra_dimensions:
        raw = np.asarray(rec.array[dim.name]).reshape(len(rec), -1)
        lo = np.full(raw.shape[1], np.nan)
        hi = np.full(raw.shape[1], np.nan)
        for i in range(raw.shape[1]):
            col = raw[:, i]
            if dim.no_data is not None:
                col = col[col != np.asarray(dim.no_data).reshape(-1)[i]]
            if col.dtype.kind == "f":
                col = col[~np.isnan(col)]
            if col.size:
                lo[i], hi[i] = col.min(), col.max()
        out[dim.name] = (lo, hi)
    return out


def straddles(counts, chunk: int):
    """Where a file's LASzip chunks of ``chunk`` points straddle pieces of ``counts`` points
    laid end to end: ``(starts, span)`` — each piece's first point in the file, and for each
    piece that holds a chunk boundary, the pieces after it whose heads the chunk from its last
    boundary takes (:meth:`LasLayout.chunked`): up to the first with a boundary of its own,
    or to the end. Written in order: a piece's whole chunks, then that chunk."""
    n = len(counts)
    starts = np.concatenate([[0], np.cumsum(counts, dtype=np.int64)])
    inside = [counts[t] > 0 and -(-int(starts[t]) // chunk) * chunk < starts[t + 1]
              for t in range(n)]
    span = {}
    for t in range(n):
        if inside[t]:
            u = t + 1
            while u < n and not inside[u]:
                u += 1
            span[t] = range(t + 1, min(u + 1, n))
    return starts, span


def compress_chunks(vlr, raw, size, parallel=False) -> tuple[bytes, list]:
    """The records ``raw`` (``size`` bytes each) compressed in chunks of ``vlr``'s chunk
    size, each alone (all whole but perhaps the last): ``(bytes, [(points, bytes) per
    chunk])``. (:func:`lazrs.compress_points` gives the offset of its chunk table, 8 bytes,
    then the chunks, then the table, which holds their sizes.)"""
    import lazrs
    if not len(raw):
        return b"", []
    done = lazrs.compress_points(vlr, np.frombuffer(raw, np.uint8), parallel)
    end = int.from_bytes(done[:8], "little")
    sizes = lazrs.read_chunk_table_only(io.BytesIO(done[end:]), vlr)
    points = len(raw) // size
    chunk = vlr.chunk_size()
    table = [(min(chunk, points - i * chunk), int(b)) for i, (_, b) in enumerate(sizes)]
    return done[8:end], table


class ChunkWriter:
    """The LAZ point writer of :class:`.las_output.LasOutput`: laspy's point-writer interface
    (``laspy._pointwriter.IPointWriter``), handed to ``laspy.LasWriter`` as its LAZ backend
    (:class:`ChunkBackend`), so laspy still writes and updates the header, VLRs and EVLRs.

    It writes the LASzip VLR with the header, then chunks as they come — point records
    (:meth:`write_points`: buffered until a chunk is whole, then compressed here, whole chunks
    at once in parallel, as laspy's compressor does) or chunks compressed elsewhere
    (:meth:`write_chunks`, at a chunk boundary) — then, at :meth:`done`, the last records and
    the chunk table. The same bytes as laspy's LAZ writer (tested)."""

    def __init__(self, dest, vlr, size):
        self.dest, self.vlr, self.size = dest, vlr, size
        self.chunk_bytes = vlr.chunk_size() * size
        self.pending = bytearray()
        self.table: list = []
        self.table_at = None  # where the offset of the chunk table goes
        self.finished = False

    @property
    def destination(self):
        return self.dest

    def write_initial_header_and_vlrs(self, header, encoding_errors):
        from laspy.vlrs.known import LasZipVlr
        header.vlrs.append(LasZipVlr(self.vlr.record_data()))
        header.write_to(self.dest, encoding_errors=encoding_errors)
        self.table_at = self.dest.tell()
        self.dest.write(bytes(8))  # the offset of the chunk table, once it is written

    def write_updated_header(self, header, encoding_errors):
        self.dest.seek(0, io.SEEK_SET)
        header.write_to(self.dest, ensure_same_size=True, encoding_errors=encoding_errors)

    def write_points(self, points):
        self.pending += points.memoryview()
        whole = len(self.pending) // self.chunk_bytes * self.chunk_bytes
        if whole:
            self._append(*compress_chunks(self.vlr, bytes(self.pending[:whole]), self.size,
                                          parallel=True))
            del self.pending[:whole]

    def write_chunks(self, data, table):
        """Append chunks compressed elsewhere (:func:`compress_chunks`); they must start at a
        chunk boundary and all but the file's last be whole."""
        if not table:
            return
        if self.pending or (self.table and self.table[-1][0] * self.size != self.chunk_bytes):
            raise ValueError("LAZ chunks written after a partial chunk")
        self._append(data, table)

    def _append(self, data, table):
        self.dest.write(data)
        self.table.extend(table)

    def done(self):
        if self.finished:
            return
        self.finished = True
        import lazrs
        if self.pending:
            self._append(*compress_chunks(self.vlr, bytes(self.pending), self.size))
            self.pending = bytearray()
        at = self.dest.tell()
        lazrs.write_chunk_table(self.dest, self.table, self.vlr)
        end = self.dest.tell()
        self.dest.seek(self.table_at, io.SEEK_SET)
        self.dest.write(int(at).to_bytes(8, "little", signed=True))
        self.dest.seek(end, io.SEEK_SET)


class ChunkBackend:
    """The LAZ backend handed to ``laspy.LasWriter`` (``laz_backend=``): laspy asks it
    ``is_available()`` and ``create_writer(dest, header)``; it makes one :class:`ChunkWriter`
    (kept in :attr:`writer`)."""

    def __init__(self, vlr):
        self.vlr = vlr
        self.writer = None

    def is_available(self) -> bool:
        return True

    def create_writer(self, dest, header):
        self.writer = ChunkWriter(dest, self.vlr, header.point_format.size)
        return self.writer


def grow_header(header: laspy.LasHeader, piece: LasPiece) -> None:
    """What ``laspy.LasHeader.grow`` does with the points of ``piece``, from its summary:
    bounds (the same arithmetic: quantised value times scale plus offset), points by return,
    point count. (laspy also tracks a GPS-time range, which no LAS header stores.)"""
    if not piece.count:
        return
    scales, offsets = header.scales, header.offsets
    header.maxs = [max(header.maxs[a], float(piece.grid_max[a]) * scales[a] + offsets[a])
                   for a in range(3)]
    header.mins = [min(header.mins[a], float(piece.grid_min[a]) * scales[a] + offsets[a])
                   for a in range(3)]
    by_return = header.number_of_points_by_return
    for r in range(1, min(len(by_return), len(piece.returns) - 1) + 1):
        by_return[r - 1] += piece.returns[r]
    header.point_count += piece.count
