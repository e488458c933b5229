"""One output per input file: a folder of LAS/LAZ tiles simplified as one cloud — tiles of the
run cross the files' borders, so no file's edge is simplified without its neighbours — and its
kept points written back to one file per input file, named by an output pattern with
``{stem}`` (``out/{stem}.laz``: ``tiles/a.laz`` → ``out/a.laz``).

Each output takes its own input file's header as the template (its scales and offsets, so no
point moves to another grid; its CRS, VLRs and way of counting ``gps_time``) and holds exactly
the kept points read from that file, in the order of the run's tiles, as a single output does.
An input file none of whose points is kept gets an output without points.

An output is open from the first tile that keeps one of its file's points to the last: the
tiles' kept input indices are read first (:func:`_tile_files`), so a run over thousands of
tiles holds only the outputs of the files under the tiles being written. Each output is
written to a temporary file and renamed when its last tile is written: a failed run leaves
the outputs it finished, whole, and no partial one (a rerun writes them all again).
"""

import logging
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.las import LAS_SUFFIXES
from ..tiles import TileStore
from .output import _in_tile_order, _kept, _keep, simplify_extra
from .progress import Written

log = logging.getLogger("tiledsimplify")

#: the placeholder of an output pattern: each input file's name less its suffix
STEM = "{stem}"


def _stem(path):
    """``tiles/a.laz`` → ``a``; a COPC file's ``b.copc.laz`` → ``b`` (its output is plain
    LAZ)."""
    stem = Path(path).stem
    return stem[:-5] if stem.lower().endswith(".copc") else stem


def per_file_outputs(output, source):
    """The outputs of a pattern with :data:`STEM`, one per file of ``source`` in its order, or
    None for a plain output name. Refuses what cannot work: a non-LAS input, a non-LAS
    output, another placeholder, or two input files of one name (one output for both)."""
    text = str(output)
    if STEM not in text:
        return None
    rest = text.replace(STEM, "")
    if "{" in rest or "}" in rest:
        raise InputError(f"{output}: the only placeholder of an output name is {STEM} (each "
                         "input file's name less its suffix), e.g. out/{stem}.laz.")
    if Path(text).suffix.lower() not in LAS_SUFFIXES:
        raise InputError(f"{output}: one output per input file ({STEM}) is written as LAS/LAZ "
                         "only; name it *.las or *.laz, e.g. out/{stem}.laz.")
    if not getattr(source, "is_las", False):
        raise InputError(f"{output}: one output per input file ({STEM}) needs LAS/LAZ input "
                         "files; this input is one cloud of another format. Name one output "
                         "instead.")
    outputs, seen = [], {}
    for f in source.files:
        out = Path(text.replace(STEM, _stem(f)))
        if out in seen:
            raise InputError(f"{seen[out]} and {f} would both be written to {out}: input files "
                             f"of one name in different folders. Simplify the folders in "
                             f"separate runs, or rename one of the files.")
        seen[out] = f
        outputs.append(out)
    return outputs


def check_outputs(outputs, inputs):
    """What a run checks of a single output (:func:`.points_out.check_output`,
    :func:`.points_out.check_not_input`, :func:`.output_checks.warn_leftovers`), for each of
    ``outputs``, in time linear in their number: the inputs looked up by name, each folder's
    leftovers listed once (a folder of 10,000 tiles: checked one against the other, 10⁸ name
    comparisons and 10,000 listings of a folder of 10,000 files)."""
    from ..io.points_out import check_not_input, check_output
    from .output_checks import warn_leftovers
    by_name = {}
    for f in inputs:
        by_name.setdefault(Path(f).name, []).append(f)
    folders = {}
    for out in outputs:
        check_output(out, LAS_SUFFIXES)
        if out.name in by_name:
            check_not_input(out, by_name[out.name])
        folders.setdefault(out.parent, []).append(out)
    for folder, outs in folders.items():
        try:
            left = [p.name for p in folder.iterdir()
                    if p.name.startswith(".") and p.name.endswith((".partial", ".records"))]
        except OSError:
            continue
        for out in outs:
            if any(name.startswith(f".{out.name}.") for name in left):
                warn_leftovers(out)


def _file_of(idx, starts):
    """The input file of each global input index (``starts``: each file's first index, and
    the total last)."""
    return np.searchsorted(starts, idx, side="right") - 1


def _tile_files(store_path, tile, prefix, refined, starts):
    """The input files a tile keeps points of (sorted), read where this runs."""
    ts = TileStore.open(store_path)
    idx = ts.core_index(tile)[_keep(ts, tile, prefix, refined)]
    return np.unique(_file_of(idx, starts))


def _tile_file_pieces(store_path, tile, prefix, refined, layouts, starts):
    """A tile's kept core points as pieces of the outputs of their input files:
    ``[(file, piece, boundary count)]``, each packed for ``layouts[file]``
    (:meth:`.LasLayout.pack`, as :func:`.output._tile_piece` packs one output's). Made
    wherever this runs: on a cluster, a worker."""
    ts = TileStore.open(store_path)
    keep, boundary = _kept(ts, tile, prefix, refined)
    if not keep.any():
        return []
    xyz, idx = ts.core(tile)
    xyz, idx, boundary = xyz[keep], idx[keep], boundary[keep]
    attrs = {name: values[keep] for name, values in ts.attrs(tile).items()}
    file_of = _file_of(idx, starts)
    out = []
    for f in np.unique(file_of).tolist():
        rows = file_of == f
        piece = layouts[f].pack(xyz[rows], {name: v[rows] for name, v in attrs.items()},
                                simplify_extra(boundary[rows]))
        out.append((f, piece, int(boundary[rows].sum())))
    return out


def write_per_file(ts, source, outputs, prefix, refined=False, client=None):
    """Write each input file's kept points to its output (``outputs``, of
    :func:`per_file_outputs`; the refined flags if ``refined``, else the cut's ``prefix``):
    see the module notes. Returns ``(points, boundary points, per output)`` — the last a
    ``{"path", "points", "boundary"}`` for each output, in the input files' order."""
    from ..io.las_output import LasOutput, output_layout
    written = Written(sum(ts.count(t) - int(prefix[t]) for t in range(ts.n_tiles)))
    counts = np.zeros((len(outputs), 2), dtype=np.int64)  # points, boundary points
    starts = np.concatenate([[0], np.cumsum([i.point_count for i in source.infos])])
    path, n = str(ts.path), ts.n_tiles
    files = list(_in_tile_order(_tile_files, lambda i: (path, i, prefix, refined, starts), n,
                                client))
    last = np.full(len(outputs), -1)
    for t, fs in enumerate(files):
        last[fs] = t
    layouts = {}  # the layouts of the files of the tiles in flight (made as tiles are asked)

    def layouts_of(i):
        for f in files[i].tolist():
            if f not in layouts:
                layouts[f] = output_layout(outputs[f], source.file_header(f))
        return {f: layouts[f] for f in files[i].tolist()}
    held = {}  # file -> its open LasOutput
    n_out = 0
    try:
        for f in np.flatnonzero(last < 0).tolist():  # no point of the file kept
            with LasOutput(outputs[f], source.file_header(f)):
                pass
        pieces = _in_tile_order(
            _tile_file_pieces, lambda i: (path, i, prefix, refined, layouts_of(i), starts), n,
            client)
        for t, got in enumerate(pieces):
            for f, piece, boundary in got:
                if f not in held:
                    held[f] = LasOutput(outputs[f], source.file_header(f))
                held[f].write_piece(piece)
                counts[f] += (piece.count, boundary)
                n_out += piece.count
                written(n_out)
            for f in files[t].tolist():
                if last[f] == t:  # its last tile: done (no tile in flight needs its layout)
                    held.pop(f).close()
                    layouts.pop(f, None)
    except BaseException:
        for out in held.values():
            out.abort()
        raise
    log.info("wrote %d output files, one per input file (%s)", len(outputs),
             outputs[0].parent)
    return n_out, int(counts[:, 1].sum()), [{"path": str(o), "points": int(m), "boundary": int(b)}
                               for o, (m, b) in zip(outputs, counts.tolist())]
