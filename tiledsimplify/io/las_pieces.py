"""LAS point records packed away from the file they go to.

A tiled run writes its output in tile order from one process, but turning a tile's points
into the point records the file holds needs nothing of that file but its layout: a
:class:`LasLayout` (the output's header, which pickles) packs points (:meth:`LasLayout.pack`)
into a :class:`LasPiece` — the records' bytes and what the header needs of them (count,
bounds, points by return, the added dimensions' ranges) — and
:class:`.las.LasOutput` only hands the records to laspy's point writer (LASzip compresses
them there, in parallel over the writer's cores) and grows its header by the summary
(:func:`grow_header`). So on a cluster the workers quantise, check and pack every point and
the client compresses and writes (:func:`tiledsimplify.pipeline.run._write_output`).

Tried first and dropped: compressing on the workers too, into LAZ chunks that never span two
pieces, i.e. variable-size chunks. lazrs 0.8.2 (laspy's LAZ backend) reads such files in order
but cannot seek in them (it reads from the wrong chunk past the first), so neither laspy's
``seek`` nor this tool's parallel ingest (:meth:`.las.LasSource.parts`) could read them back.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import laspy
import numpy as np

from ..errors import InputError

_XYZ = ("X", "Y", "Z")
_INT32 = np.iinfo(np.int32)


@dataclass
class LasPiece:
    """Consecutive points of a LAS/LAZ file as packed point records, and what its header
    needs of them.

    ``data``: the point records' bytes (the layout's point format); ``grid_min`` / ``grid_max``: the
    least and largest quantised X, Y, Z; ``returns[r]``: points with return number ``r``;
    ``ranges``: the least and largest
    raw value of each extra-bytes dimension, per element (NaN where none is valid)."""

    count: int
    data: bytes
    grid_min: np.ndarray | None = None
    grid_max: np.ndarray | None = None
    returns: np.ndarray | None = None
    ranges: dict = field(default_factory=dict)


class LasLayout:
    """How points become a LAS/LAZ file's bytes: the output header (point format, scales,
    offsets, dimensions) and the names :meth:`pack` expects. Holds only the header and
    names, so it pickles to cluster workers."""

    def __init__(self, path, header: laspy.LasHeader, attribute_names, extra_names):
        self.path = path  # for error messages only
        self.header = header
        self.attribute_names = tuple(attribute_names)
        self.extra_names = tuple(extra_names)

    def pack(self, xyz, attrs=None, extra=None) -> LasPiece:
        """Points as a :class:`LasPiece` (see :meth:`.las.LasOutput.write` for the arguments
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
        low, high = grid.min(axis=0), grid.max(axis=0)
        if (low < _INT32.min).any() or (high > _INT32.max).any():
            raise InputError(
                f"{path}: coordinates {xyz.min(axis=0)} .. {xyz.max(axis=0)} do not fit "
                f"the output's int32 grid (scales {scales}, offsets {offsets}); points of "
                "another file far from the first one? Rescale the inputs to common offsets "
                "first (e.g. `pdal translate --writers.las.offset_x=auto ...`).")
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
