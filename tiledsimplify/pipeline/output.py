"""The run's last stage: the kept core points of every tile written to the output
(:func:`write_output`) — LAS/LAZ tile by tile, other formats in input order — in memory
bounded by a tile, read ahead (and for LAZ compressed) by a cluster's workers."""

import collections
import collections.abc
import dataclasses
import logging

import numpy as np

from ..errors import TiledSimplifyError
from ..io.las import LAS_SUFFIXES
from ..io.points_out import (COLOURS, PointsAt, attribute_columns, attribute_dtypes,
                             whole_dtypes)
from ..tiles import TileStore
from .budget import kept_in_tile
from .input_order import InputRanks
from .progress import Written
from .tile_task import NORMAL_DTYPE

log = logging.getLogger("tiledsimplify")


#: the columns of a non-LAS output after x, y, z and the input's dimensions (normals as the
#: tile store keeps them)
OUTPUT_COLUMNS = {"sharp_edge": np.uint8, "nx": NORMAL_DTYPE, "ny": NORMAL_DTYPE,
                  "nz": NORMAL_DTYPE}
#: dimensions of the input a non-LAS output leaves out: its own columns, and the ones an
#: input simplified before carries from that run
#: (:data:`~tiledsimplify.io.las_output.SIMPLIFY_DIMS`)
RESERVED = frozenset(OUTPUT_COLUMNS) | {"importance", "simplify_rank"}


def carried(ts, guessed=()):
    """What a non-LAS output carries of the input's dimensions (LAS dimensions, PLY
    properties, E57 point fields, text columns): ``(columns' dtypes, the largest colour value
    or None)`` — colour is written 8-bit (:func:`~tiledsimplify.io.points_out.colour_8bit`),
    and the columns named in ``guessed`` (typed by guess: a text file's) as integers where all
    their values are whole numbers (:func:`~tiledsimplify.io.points_out.whole_dtypes`)."""
    top = ts.attribute_max
    colour = max((top[c] for c in COLOURS if c in top), default=None)
    dtypes = attribute_dtypes(ts.attribute_spec, RESERVED)
    return whole_dtypes(dtypes, ts.attribute_stats, guessed), colour


def new_las_header(ts):
    """A LAS output of a non-LAS input: its header (:func:`.las_output.new_header`, with an
    extra-bytes dimension for each dimension the input carried that point format 6 or 7 has
    none for) and where each dimension is filled from (:func:`.las_output.carried_layout`)."""
    from ..io.las_output import carried_layout, new_header
    lo, hi = ts.root_attrs["bounds"]
    header = new_header(lo, hi, ts.spacing,
                        colour=all(c in ts.attribute_names for c in COLOURS))
    params, plan = carried_layout(ts.attribute_spec, header.point_format, RESERVED,
                                  ts.attribute_stats)
    if params:
        header.add_extra_dims(params)
    return header, plan


def _keep(ts, tile, prefix, refined):
    return ts.read_refined(tile)[0] if refined else kept_in_tile(ts, tile, prefix)


def _kept(ts, tile, prefix, refined):
    return _keep(ts, tile, prefix, refined), ts.read_result(tile, "boundary")


def simplify_extra(boundary):
    """The dimensions a LAS/LAZ output adds (:data:`~tiledsimplify.io.las_output.SIMPLIFY_DIMS`)
    for kept points flagged ``boundary``: ``sharp_edge``; ``importance`` NaN and
    ``simplify_rank`` -1 (kept)."""
    k = len(boundary)
    return {"sharp_edge": np.asarray(boundary).astype(np.uint8),
            "importance": np.full(k, np.nan), "simplify_rank": np.full(k, -1, dtype=np.int64)}


def _tile_piece(store_path, tile, prefix, refined, layout, plan, start=None, expect=None):
    """What a LAS/LAZ output takes from one tile: ``(piece, boundary count)`` — its kept core
    points packed as the output's point records (:meth:`.LasLayout.pack`: quantised, checked,
    with the three added dimensions; a LAS input's records as read, a non-LAS input's points
    (``plan`` not None: :func:`new_las_header`'s) the dimensions it carried, the rest
    :data:`~tiledsimplify.io.las_output.NEW_POINT_DEFAULTS`) — or None if it keeps none. Made
    wherever this runs: on a cluster, a worker. With ``start``, the file's point where the
    tile's first kept point goes (a LAZ output on a cluster, :func:`_write_laz_chunks`), the
    piece is cut at the file's chunk boundaries and its whole chunks compressed
    (:meth:`.LasLayout.chunked`); it must then keep ``expect`` points."""
    from ..io.las_output import NEW_POINT_DEFAULTS
    ts = TileStore.open(store_path)
    keep, boundary = _kept(ts, tile, prefix, refined)
    if expect is not None and int(keep.sum()) != expect:
        raise TiledSimplifyError(
            f"{store_path}: tile {tile} keeps {int(keep.sum())} points, not the {expect} its "
            "cut says (a bug: the output's LAZ chunks would be misplaced)")
    if not keep.any():
        return None
    xyz = ts.core_xyz(tile)[keep]
    boundary = boundary[keep]
    k = len(xyz)
    if plan is None:
        attrs = {name: values[keep] for name, values in ts.attrs(tile).items()}
    else:  # a new LAS 1.4 layout: the dimensions the input carried (E57 intensity, colour,
        # PLY properties, text columns), each where the plan puts it
        stored = ts.attrs(tile, sorted({name for name, _ in plan.values()}))
        floats = {d.name for d in layout.header.point_format.dimensions
                  if d.dtype is not None and d.dtype.kind == "f"}
        attrs = {}
        for name in layout.attribute_names:
            if name not in plan:
                attrs[name] = np.full(k, NEW_POINT_DEFAULTS.get(name, 0))
                continue
            source, element = plan[name]
            values = stored[source][keep]
            values = values if element is None else values.reshape(k, -1)[:, element]
            if values.dtype.kind == "f" and name not in floats:  # whole numbers (the plan's)
                values = values.astype(np.int64)
            attrs[name] = values
    piece = layout.pack(xyz, attrs, simplify_extra(boundary))
    if start is not None:
        piece = layout.chunked(piece, start)
    return piece, int(boundary.sum())


def _piece_part(got, part):
    """A part of a cut piece (:func:`_tile_piece` with ``start``): ``"head"`` or ``"tail"``
    (records, for a chunk that straddles pieces), or ``"body"``: the piece without them and
    its boundary count (what the client writes)."""
    if got is None:
        return b"" if part == "head" else None
    piece, boundary = got
    if part != "body":
        return getattr(piece, part)
    # a copy: the same object may be the head's or tail's task's input in this worker
    return dataclasses.replace(piece, head=b"", tail=None), boundary


#: tiles read ahead of the one being written, per worker (each a tile's kept records)
READ_AHEAD = 2


def _in_tile_order(func, args, n, client):
    """``func(*args(i))`` for ``i`` in ``0..n-1``, yielded in that order: on a cluster computed
    by its workers, at most ``READ_AHEAD`` per worker ahead of the consumer, so the client only
    writes; else here, one after another (read ahead in threads here, the output stage of the
    3M-point scan was within noise of this: zarr's reads go through one event loop)."""
    if client is None:
        for i in range(n):
            yield func(*args(i))
        return
    ahead = READ_AHEAD * max(1, sum(client.nthreads().values()))
    pending = collections.deque(client.submit(func, *args(i), pure=False)
                                for i in range(min(ahead, n)))
    for i in range(n):
        fut = pending.popleft()
        if i + ahead < n:
            pending.append(client.submit(func, *args(i + ahead), pure=False))
        yield fut.result()
        del fut


def write_output(ts, source, output, prefix, refined=False, client=None):
    """Write the kept core points of every tile: the refined flags if ``refined``, else the
    cut's. LAS/LAZ tile by tile, the other formats in input order at each point's rank
    (:class:`.input_order.InputRanks`, :class:`~tiledsimplify.io.points_out.PointsAt`), in
    memory bounded by a tile; on a cluster the tiles' kept records are read — and for
    LAS/LAZ packed as point records (:func:`_tile_piece`) — ahead by its workers
    (:func:`_in_tile_order`), which also compress a LAZ output's chunks
    (:func:`_write_laz_chunks`). One LAS/LAZ output per input file:
    :func:`.per_file.write_per_file`."""
    n_out = n_boundary = 0
    path = str(ts.path)
    # a tile keeps its core count less its cut (the refinement swaps at equal count)
    counts = [ts.count(t) - int(prefix[t]) for t in range(ts.n_tiles)]
    written = Written(sum(counts))
    if output.suffix.lower() in LAS_SUFFIXES:
        from ..io.las_output import LasOutput
        if source.is_las:
            template, plan = source.template_header(), None
        else:  # a new LAS 1.4 layout: the input had no point records to keep
            template, plan = new_las_header(ts)
        with LasOutput(output, template) as out:
            if client is not None and output.suffix.lower() == ".laz":
                return _write_laz_chunks(ts, out, prefix, refined, plan, client, counts,
                                         written)
            for got in _in_tile_order(
                    _tile_piece, lambda i: (path, i, prefix, refined, out.layout, plan),
                    ts.n_tiles, client):
                if got is None:
                    continue
                piece, boundary = got
                out.write_piece(piece)
                n_out += piece.count
                n_boundary += boundary
                written(n_out)
        return n_out, n_boundary
    # in input order, a tile at a time
    ranks = InputRanks(ts.n_total)
    for index in _in_tile_order(_tile_kept_index, lambda i: (path, i, prefix, refined),
                                ts.n_tiles, client):
        ranks.add(index)
    n_out = len(ranks)
    done = 0
    dtypes, colour = carried(ts, getattr(source, "guessed", ()))
    with PointsAt(output, n_out, {**dtypes, **OUTPUT_COLUMNS},
                  progress=Written(n_out, "formatted as text")) as out:
        for idx, xyz, boundary, nrm, attrs in _in_tile_order(
                _tile_points, lambda i: (path, i, prefix, refined), ts.n_tiles, client):
            out.write(ranks.rank(idx), xyz, {
                **attribute_columns(attrs, colour, RESERVED),
                "sharp_edge": boundary.astype(np.uint8),
                "nx": nrm[:, 0], "ny": nrm[:, 1], "nz": nrm[:, 2]})
            n_boundary += int(boundary.sum())
            done += len(idx)
            written(done)
    return n_out, n_boundary


def _write_laz_chunks(ts, out, prefix, refined, plan, client, counts, written):
    """A LAZ output on a cluster, compressed by its workers: each tile's kept points
    (``counts``) are packed and cut at the file's chunk boundaries there (:func:`_tile_piece`
    with the file's point where they start), its whole chunks compressed; each chunk that
    straddles tiles is compressed by a task from the tail of one and the heads of the next
    (:meth:`.LasLayout.compress`). The client writes the chunks in order and grows the header
    by each tile's summary: the file laspy would write (:class:`.las_pieces.ChunkWriter`).
    ``READ_AHEAD`` tiles per worker thread are in flight. Returns ``(points, boundary points)``."""
    from ..io.las_pieces import straddles
    n = ts.n_tiles
    starts, span = straddles(counts, out.layout.vlr().chunk_size())
    path = str(ts.path)
    ahead = READ_AHEAD * max(1, sum(client.nthreads().values()))
    pieces, bodies, spans = {}, {}, {}
    straddling = sorted(span)
    made = [0, 0]  # pieces submitted, straddling chunks submitted

    def submit(upto):
        while made[0] < min(upto, n):
            t = made[0]
            pieces[t] = client.submit(_tile_piece, path, t, prefix, refined, out.layout,
                                      plan, int(starts[t]), counts[t], pure=False)
            bodies[t] = client.submit(_piece_part, pieces[t], "body", pure=False)
            made[0] += 1
        while made[1] < len(straddling) and span[straddling[made[1]]].stop <= made[0]:
            t = straddling[made[1]]
            parts = [client.submit(_piece_part, pieces[t], "tail", pure=False)]
            parts += [client.submit(_piece_part, pieces[u], "head", pure=False)
                      for u in span[t]]
            spans[t] = client.submit(out.layout.compress, parts, pure=False)
            made[1] += 1

    n_out = n_boundary = 0
    for t in range(n):
        submit(t + ahead)
        got = bodies.pop(t).result()
        if got is not None:
            piece, boundary = got
            out.write_chunks(piece.data, piece.chunks)
            out.grow(piece)
            n_out += piece.count
            n_boundary += boundary
            written(n_out)
        if t in span:
            submit(span[t].stop)
            out.write_chunks(*spans.pop(t).result())
        del pieces[t]  # its parts are asked for: dask keeps what they still need
    return n_out, n_boundary


def _tile_kept_index(store_path, tile, prefix, refined):
    """The input indices of a tile's kept core points (read where this runs)."""
    ts = TileStore.open(store_path)
    return ts.core_index(tile)[_keep(ts, tile, prefix, refined)]


def _tile_points(store_path, tile, prefix, refined):
    """A tile's kept core points for a non-LAS output: ``(index, xyz, boundary, normals,
    the input's dimensions)`` (read where this runs)."""
    ts = TileStore.open(store_path)
    keep, boundary = _kept(ts, tile, prefix, refined)
    xyz, idx = ts.core(tile)
    attrs = ({name: values[keep] for name, values in ts.attrs(tile).items()}
             if ts.attribute_names and keep.any() else {})
    return (idx[keep], xyz[keep], boundary[keep], ts.read_result(tile, "normal")[keep],
            attrs)
