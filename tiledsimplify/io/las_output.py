"""LAS/LAZ point clouds written, as the input's layout or a new one, in memory bounded by
what is written at once (laspy + lazrs; the point records are packed by :mod:`.las_pieces`).

Public API
----------
LasOutput(path, template_header, extra_dims=SIMPLIFY_DIMS)
    Streaming writer (a context manager): ``out.write(xyz, attrs, extra)`` per chunk, or
    ``out.write_piece(piece)`` for points packed elsewhere by ``out.layout.pack(...)``, or
    (LAZ) ``out.write_chunks(...)`` and ``out.grow(piece)`` for LASzip chunks compressed
    elsewhere (:mod:`.las_pieces`); the file appears under ``path`` only when the ``with``
    block ends without an exception.
write_las(path, template_header, xyz, attrs, *, extra, extra_dims=SIMPLIFY_DIMS)
    One-shot wrapper of :class:`LasOutput`.
output_header(template_header, extra_dims=SIMPLIFY_DIMS, path=None)
    The layout :class:`LasOutput` would write, without a file: a run checks it before the work.
SIMPLIFY_DIMS
    The three extra-bytes dimensions the simplifier adds: ``sharp_edge`` (uint8, 1 on or near a
    sharp edge), ``importance`` (float64, importance at removal, NaN for kept points) and
    ``simplify_rank`` (int64, removal order, -1 for kept points).
new_header(lo, hi, spacing, colour=False)
    A LAS 1.4 point format 6 (7 with colour) header for points without a LAS origin.
carried_layout(attributes, point_format, reserved=())
    Where such an output puts each dimension the input carried (extra bytes where LAS has
    no place for it).

Decisions
---------
* The output keeps the template's LAS version, point format, every standard and extra-bytes
  dimension, scales, offsets, global encoding, file source id, system identifier and every
  VLR/EVLR (CRS included). The LASzip VLR is rewritten by the compressor (``.laz``) or dropped
  (``.las``). Extra-bytes descriptions are written as the single Extra Bytes VLR the LAS 1.4
  specification allows: several Extra Bytes VLRs in the input (laspy only reads the first one
  and calls the rest "ExtraBytes") are merged when read (:mod:`.las`), so their real names
  survive. The header's
  generating software becomes ``tiledsimplify <version>`` and the creation date today; counts,
  bounds and points-by-return are recomputed as laspy's writer computes them, from each
  written piece's summary (:mod:`.las_pieces`: points are packed into point records apart
  from the writer, on a cluster's workers in a tiled run). Waveform data
  packets stored inside a file (point formats 4, 5, 9, 10) are not copied.
* :meth:`LasOutput.write` is strict: ``attrs`` must hold every dimension of the template
  except ``X``, ``Y``, ``Z`` (given as float ``xyz``), ``extra`` every added dimension; unknown
  names, wrong lengths, floats for integer dimensions and coordinates that do not fit the
  int32 grid raise :class:`~tiledsimplify.errors.InputError`. A dimension of the template that
  already has the name of an added one (re-simplifying our own output) is reused, and the
  value in ``extra`` wins.

Errors
------
A suffix other than ``.las``/``.laz`` raises :class:`~tiledsimplify.errors.FileFormatError`,
a missing output folder :class:`FileNotFoundError`, bad values
:class:`~tiledsimplify.errors.InputError`, each naming the file.
"""

from __future__ import annotations

import copy
import datetime
import errno
import os
import re
import tempfile
from pathlib import Path
from typing import Mapping

import laspy
import numpy as np

from .. import __version__
from ..errors import FileFormatError, InputError
from .las import LAS_SUFFIXES, _short
from .las_pieces import _INT32, _XYZ, ChunkBackend, LasLayout, LasPiece, grow_header
from .points_out import publish, write_failed

__all__ = [
    "NEW_POINT_DEFAULTS",
    "SIMPLIFY_DIMS",
    "LasOutput",
    "carried_layout",
    "new_header",
    "output_header",
    "write_las",
]

#: Extra-bytes dimensions added by the simplifier: (name, numpy type, description <= 32 chars).
SIMPLIFY_DIMS = (
    ("sharp_edge", "uint8", "1 = on/near a sharp edge"),
    ("importance", "float64", "Importance at removal; NaN=kept"),
    ("simplify_rank", "int64", "Removal order; -1 = kept"),
)

#: what a LAS output of a non-LAS input gives each point besides x, y, z and the added
#: dimensions (every other dimension of point format 6 is 0)
NEW_POINT_DEFAULTS = {"return_number": 1, "number_of_returns": 1}


def new_header(lo, hi, spacing, colour=False) -> laspy.LasHeader:
    """A LAS 1.4 point format 6 header for points without a LAS origin (PLY, NPY, text, E57);
    point format 7 (format 6 with red, green, blue) if ``colour``.

    Scales: the largest power of ten at most a thousandth of ``spacing`` (the quantisation
    then moves a point by at most 0.0005 spacings), coarser only if the extent would not fit
    int32 otherwise; offsets: ``lo``. No CRS (the input had none to give).
    """
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    extent = float(np.max(hi - lo)) if lo.size else 0.0
    fine = spacing * 1e-3 if np.isfinite(spacing) and spacing > 0 else max(extent, 1.0) * 1e-9
    need = extent / (0.9 * _INT32.max)  # the extent must fit the int32 grid
    scale = 10.0 ** np.floor(np.log10(max(fine, need, 1e-300)))
    if scale < need:
        scale *= 10.0
    header = laspy.LasHeader(point_format=7 if colour else 6, version="1.4")
    header.scales = np.full(3, scale)
    header.offsets = lo
    return header


#: LAS's extra-bytes name field, in bytes
_NAME_BYTES = 32
#: the most extra-bytes dimensions a LAS file describes: its Extra Bytes VLR (192 bytes a
#: dimension) holds at most 65,535 bytes
EXTRA_BYTES_MAX = 65_535 // 192
#: the longest point record LAS holds, in bytes
RECORD_MAX = 65_535


def _key(name):
    """A dimension name as PDAL and CloudCompare spellings of LAS's match it: lower case,
    letters and digits only (``NumberOfReturns``, ``Number Of Returns``,
    ``number_of_returns``)."""
    return re.sub(r"[^a-z0-9]", "", name.lower())


def _free_name(name, taken):
    """``name`` cut to the LAS name field, with a number added until no name in ``taken``
    (as :func:`_key` gives them: PDAL's dimension names ignore case) is the same."""
    base = name.encode("utf-8")[:_NAME_BYTES].decode("utf-8", "ignore")
    out, i = base, 1
    while _key(out) in taken:
        tail = f"_{i}"
        out = base.encode("utf-8")[:_NAME_BYTES - len(tail)].decode("utf-8", "ignore") + tail
        i += 1
    return out


def _fits(dim, dtype, stats):
    """Whether an input dimension of type ``dtype`` and ``stats`` (``(least, largest,
    whole)`` or None: unknown) goes into the standard LAS dimension ``dim``."""
    if dtype.kind == "b":
        return True
    if dim.dtype is not None and dim.dtype.kind == "f":
        return dtype.kind in "iuf"
    if dtype.kind in "iu" and stats is None:
        return True  # the range is not known (a caller without it): the values are checked
    if dtype.kind not in "iuf" or stats is None:
        return False
    lo, hi, whole = stats
    return bool(whole) and lo is not None and dim.min <= lo and hi <= dim.max


def carried_layout(attributes, point_format, reserved=(), stats=None):
    """Where a LAS output of a non-LAS input puts each dimension the input carried
    (``attributes``: name -> ``(dtype, trailing shape)``, PLY properties, text columns, E57
    point fields), nothing dropped.

    A dimension named as one of ``point_format``'s standard dimensions — in any case, with or
    without ``_`` and spaces, as PDAL (``Classification``, ``NumberOfReturns``) and
    CloudCompare name them — goes there if its values fit it, by ``stats`` (name -> the
    input's least and largest value and whether all are whole numbers:
    :attr:`.TileStore.attribute_stats`): integers within its range — a PLY's int
    ``classification`` of -1 .. 40 would fail the output at the end of a run — or a text
    file's float column of whole numbers within it; any number into a float dimension
    (``gps_time``). Without ``stats``, integers go there as they are and floats do not. Every
    other becomes an extra-bytes dimension of its own type (bool as uint8, float16 as
    float32), one per element of a trailing shape (``name_0``...), under its own name, or
    with its type added where that name is taken (PDAL ignores case): the Bunny PLY's float
    ``intensity`` (0..0.5) is kept as ``intensity_float32``, LAS's 16-bit ``intensity`` left 0;
    a number is added if that is taken too. Names in ``reserved`` are left out (the
    simplifier's own dimensions, which the output adds anew).

    Returns
    -------
    (list of laspy.ExtraBytesParams, dict)
        The extra-bytes dimensions to add to the header, and for each dimension filled from
        the input, ``{output name: (input name, element index or None)}`` (a float's whole
        numbers are cast to the standard dimension's integers where they are packed).
    """
    standard = {_key(d.name): d for d in point_format.dimensions if d.name not in _XYZ}
    stats = stats or {}
    taken = {_key(n) for n in list(_XYZ) + [d[0] for d in SIMPLIFY_DIMS]} | set(standard)
    params, plan = [], {}
    for name, (dtype, trail) in attributes.items():
        dtype, trail = np.dtype(dtype), tuple(trail)
        if name in reserved or name in ("x", "y", "z"):
            continue
        dim = standard.get(_key(name))
        if dim is not None and not trail and dim.name not in plan \
                and _fits(dim, dtype, stats.get(name)):
            plan[dim.name] = (name, None)
            continue
        if dtype.kind not in "biuf":
            continue  # not a number: no LAS type holds it
        kind = np.dtype(np.uint8) if dtype.kind == "b" else dtype
        if kind.kind == "f":  # LAS holds float32 and float64
            kind = np.dtype(np.float32 if kind.itemsize <= 4 else np.float64)
        label = name if _key(name) not in taken else f"{name}_{dtype.name}"
        size = int(np.prod(trail, dtype=np.int64))
        for i in range(size) if trail else (None,):
            out = _free_name(label if i is None else f"{label}_{i}", taken)
            taken.add(_key(out))
            params.append(laspy.ExtraBytesParams(
                name=out, type=kind.newbyteorder("<"),
                description=_short(f"input {name}" + ("" if i is None else f"[{i}]"), 32)))
            plan[out] = (name, i)
    return params, plan


def _as_params(dim) -> laspy.ExtraBytesParams:
    if isinstance(dim, laspy.ExtraBytesParams):
        return dim
    name, dtype, *rest = dim
    return laspy.ExtraBytesParams(name=name, type=np.dtype(dtype),
                                  description=rest[0] if rest else "")


def _attribute_names(header):
    """The dimensions of an output layout other than X, Y, Z (what :meth:`LasOutput.write`
    and :meth:`.LasLayout.pack` take as ``attrs``)."""
    return tuple(n for n in header.point_format.dimension_names if n not in _XYZ)


def output_layout(path, template_header: laspy.LasHeader, extra_dims=SIMPLIFY_DIMS):
    """The :class:`.las_pieces.LasLayout` a :class:`LasOutput` of ``path`` and
    ``template_header`` will have, made without touching a file: pieces for it can be packed
    (on a cluster's workers) before it is opened."""
    header, names = output_header(template_header, extra_dims, path)
    return LasLayout(Path(path), header, _attribute_names(header), names)


def output_header(template_header: laspy.LasHeader, extra_dims=SIMPLIFY_DIMS, path=None):
    """The layout :class:`LasOutput` writes: a copy of ``template_header`` with ``extra_dims``
    added (one the template already has with the same type is reused). No file is touched, so
    a run can check its output's layout before the work (``path`` only names it in errors).

    Returns
    -------
    (laspy.LasHeader, list of str)
        The header and the added dimensions' names.

    Raises
    ------
    InputError
        Repeated names, an added dimension that clashes with a standard dimension or with an
        extra dimension of another type, or more extra-bytes dimensions than a LAS file holds
        (:data:`EXTRA_BYTES_MAX`; laspy would fail only when the file is written).
    """
    header = copy.deepcopy(template_header)
    params = [_as_params(d) for d in extra_dims]
    names = [p.name for p in params]
    if len(set(names)) != len(names):
        raise InputError(f"extra_dims has repeated names: {names}")
    existing = {d.name: d for d in header.point_format.dimensions}
    new = []
    for p in params:
        dim = existing.get(p.name)
        if dim is None:
            new.append(p)
        elif dim.is_standard or np.dtype(dim.dtype) != p.type:
            raise InputError(
                f"cannot add dimension {p.name!r} ({p.type}) to {path or 'the output'}: the "
                f"template already has {'a standard' if dim.is_standard else 'an extra'} "
                f"dimension of that name of type {dim.dtype}; rename the added dimension.")
    if new:
        header.add_extra_dims(new)
    described = len(list(header.point_format.extra_dimension_names))
    if described > EXTRA_BYTES_MAX or header.point_format.size > RECORD_MAX:
        raise InputError(
            f"{path or 'the output'}: a LAS file describes at most {EXTRA_BYTES_MAX} "
            f"extra-bytes dimensions in a point record of at most {RECORD_MAX:,} bytes, and "
            f"this one would need {described} ({header.point_format.size:,} bytes: the "
            f"input's dimensions and the {len(names)} the simplifier adds). Write .ply or "
            ".npy, which take any number of columns, or leave dimensions out of the input "
            "first.")
    return header, names


class LasOutput:
    """Stream points into a LAS/LAZ file laid out like a template header, plus extra dims.

    Points go to a temporary file beside ``path`` (``.<name>.<random>.partial``), renamed to
    ``path`` by :meth:`close` — which the ``with`` statement calls when its block ends without
    an exception. On an exception (or :meth:`abort`) the temporary file is deleted and nothing
    is left under ``path``; an existing ``path`` is replaced only on success.

    Parameters
    ----------
    path : str or PathLike
        ``.laz`` (LASzip via lazrs) or ``.las`` (uncompressed), case-insensitive.
    template_header : laspy.LasHeader
        Usually :meth:`LasSource.template_header`. Its version, point format, dimensions,
        scales, offsets, VLRs and EVLRs are kept (not modified: a copy is used).
    extra_dims : sequence of laspy.ExtraBytesParams or (name, dtype, description)
        Dimensions to add, by default :data:`SIMPLIFY_DIMS`. One whose name the template
        already has with the same type is reused.

    Attributes
    ----------
    path : Path
    header : laspy.LasHeader
        The output layout (template plus added dimensions).
    attribute_names : tuple of str
        Names :meth:`write` expects in ``attrs``.
    extra_names : tuple of str
        Names :meth:`write` expects in ``extra``.
    count : int
        Points written so far.

    Raises
    ------
    FileFormatError
        Unsupported suffix.
    FileNotFoundError
        The output folder does not exist.
    InputError
        An added dimension clashes with a standard dimension or with an extra dimension of
        another type.

    Examples
    --------
    >>> src = LasSource("tiles/")                                  # doctest: +SKIP
    >>> with LasOutput("out.laz", src.template_header()) as out:  # doctest: +SKIP
    ...     for start, xyz, attrs in src.chunks():
    ...         keep = ...
    ...         out.write(xyz[keep], {k: v[keep] for k, v in attrs.items()},
    ...                   {"sharp_edge": ..., "importance": ..., "simplify_rank": ...})
    """

    def __init__(self, path, template_header: laspy.LasHeader, extra_dims=SIMPLIFY_DIMS):
        self.path = Path(path)
        suffix = self.path.suffix.lower()
        if suffix not in LAS_SUFFIXES:
            raise FileFormatError(f"{self.path}: cannot write '{self.path.suffix}' as LAS; "
                                  "name the output *.las (uncompressed) or *.laz (compressed).")
        directory = self.path.parent if str(self.path.parent) else Path(".")
        if not directory.is_dir():
            raise FileNotFoundError(errno.ENOENT, f"output folder {directory} does not exist "
                                                  f"(for {self.path}); create it first",
                                    str(directory))
        compress = suffix == ".laz"
        if compress and not laspy.LazBackend.detect_available():
            raise ImportError(f"{self.path}: writing .laz needs a LAZ backend: "
                              "pip install 'laspy[lazrs]'")

        header, names = output_header(template_header, extra_dims, self.path)
        header.generating_software = f"tiledsimplify {__version__}"[:32]
        header.creation_date = datetime.date.today()
        evlrs = header.evlrs if header.version.minor >= 4 else None
        self._evlrs = evlrs if evlrs else None
        self.header = header
        self.attribute_names = _attribute_names(header)
        self.extra_names = tuple(names)
        self.count = 0
        self._finished = False
        self._writer = None
        self._ranges: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.layout = LasLayout(self.path, header, self.attribute_names, self.extra_names)
        self._backend = ChunkBackend(self.layout.vlr()) if compress else None

        fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".partial",
                                   dir=directory)
        self._tmp = Path(tmp)
        try:
            fh = os.fdopen(fd, "w+b")
        except BaseException:
            os.close(fd)
            self._unlink_tmp()
            raise
        try:
            self._writer = laspy.LasWriter(fh, header, do_compress=compress,
                                           laz_backend=self._backend, closefd=True)
        except BaseException as exc:
            fh.close()
            self._unlink_tmp()
            self._finished = True
            if isinstance(exc, Exception) and not isinstance(exc, (OSError, MemoryError)):
                raise FileFormatError(f"{self.path}: cannot write this header as LAS/LAZ "
                                      f"({type(exc).__name__}: {exc})") from exc
            raise

    # ---- context manager ----------------------------------------------------------------

    def __enter__(self) -> "LasOutput":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.close()
        else:
            self.abort()
        return False

    def __del__(self):  # never leave a temporary file behind, even if close() was forgotten
        try:
            if not self._finished:
                self.abort()
        except Exception:
            pass

    # ---- writing ------------------------------------------------------------------------

    def write(self, xyz, attrs: Mapping | None = None, extra: Mapping | None = None) -> None:
        """Append one chunk of points.

        Parameters
        ----------
        xyz : (m, 3) array_like of float
            Coordinates; quantised to the output's scales/offsets (``round((x - offset) /
            scale)``), which must fit int32.
        attrs : dict of str -> (m,) array, optional
            Every name of :attr:`attribute_names` (the template's dimensions except X, Y, Z),
            e.g. the ``attrs`` of :meth:`LasSource.chunks` restricted to the written points.
        extra : dict of str -> (m,) array, optional
            Every name of :attr:`extra_names`.

        Raises
        ------
        InputError
            Missing or unknown names, wrong lengths, non-finite or out-of-range coordinates,
            values that do not fit a dimension.
        ValueError
            The output is already closed or aborted.
        """
        if self._finished:
            raise ValueError(f"{self.path}: LasOutput is closed")
        self.write_piece(self.layout.pack(xyz, attrs, extra))

    def write_piece(self, piece: LasPiece) -> None:
        """Append points packed by :meth:`.LasLayout.pack` of :attr:`layout` — here or
        anywhere else, e.g. on a cluster worker. The point records go to the point writer
        (for LAZ, compressed here as their chunks fill); the header grows by the piece's
        summary, as laspy's ``LasHeader.grow`` would by its points (:meth:`grow`).

        Raises
        ------
        ValueError
            The output is closed, or the piece was packed for another point format.
        InputError
            The file would hold more points than its LAS version can count.
        """
        if self._finished:
            raise ValueError(f"{self.path}: LasOutput is closed")
        if not piece.count:
            return
        fmt = self._writer.header.point_format
        if len(piece.data) != piece.count * fmt.size:
            raise ValueError(f"{self.path}: a piece of {piece.count} points holds "
                             f"{len(piece.data)} bytes, not {piece.count} records of "
                             f"{fmt.size}: packed for another layout")
        self.grow(piece)  # checks the room first; a failed write below aborts the file
        records = laspy.PackedPointRecord(np.frombuffer(piece.data, fmt.dtype()), fmt)
        try:
            self._writer.point_writer.write_points(records)
        except Exception as exc:
            raise self._write_error(exc) from exc

    def write_chunks(self, data: bytes, table) -> None:
        """Append LASzip chunks compressed elsewhere (a LAZ output; see
        :meth:`.LasLayout.chunked` and :meth:`.LasLayout.compress`), with ``table`` their
        ``(points, bytes)``. They must start at a chunk boundary and all but the file's last
        be whole; their points count only through :meth:`grow` of the pieces they came
        from."""
        if self._finished:
            raise ValueError(f"{self.path}: LasOutput is closed")
        if self._backend is None:
            raise ValueError(f"{self.path}: LASzip chunks for a LAS (uncompressed) output")
        try:
            self._backend.writer.write_chunks(data, table)
        except ValueError:
            raise
        except Exception as exc:
            raise self._write_error(exc) from exc

    def grow(self, piece: LasPiece) -> None:
        """Count a piece's points in the header (count, bounds, points by return: as laspy's
        ``LasHeader.grow`` would, :func:`.las_pieces.grow_header`) and the added dimensions'
        ranges; :meth:`write_piece` calls it, a caller of :meth:`write_chunks` calls it once
        per piece whose chunks it writes."""
        if not piece.count:
            return
        header = self._writer.header
        if header.max_point_count() - header.point_count < piece.count:
            raise InputError(f"{self.path}: {header.point_count + piece.count} points do not "
                             f"fit a LAS {header.version} file (at most "
                             f"{header.max_point_count()}); write LAS 1.4.")
        grow_header(header, piece)
        for name, (lo, hi) in piece.ranges.items():
            old = self._ranges.get(name)
            if old is not None:
                lo, hi = np.fmin(old[0], lo), np.fmax(old[1], hi)
            self._ranges[name] = (lo, hi)
        self.count += piece.count

    def _write_error(self, exc):
        """The error to raise when the writer fails: :func:`.points_out.write_failed`, as for
        every output (lazrs reports a full disk as ``IoError: Failed to call write``, not as
        an OSError); other OSErrors as they are."""
        if isinstance(exc, OSError) and exc.errno != errno.ENOSPC:
            return exc
        return write_failed(self.path, f"{type(exc).__name__}: {exc}",
                            exc.errno if isinstance(exc, OSError) else None)

    def _set_extra_bytes_ranges(self):
        """Store the tracked min/max in the Extra Bytes VLR (laspy 2.7 records, for one-element
        dimensions, the first point's value); without valid values, claim no min/max (and
        store zeros there, not what the header was reset to)."""
        for vlr in self._writer.header.vlrs.get("ExtraBytesVlr"):
            for struct in vlr.extra_bytes_structs:
                if struct.data_type == 0:
                    continue
                bits = struct.MIN_BIT_MASK | struct.MAX_BIT_MASK
                lo, hi = self._ranges.get(struct.format_name(), (None, None))
                try:
                    if lo is None or np.isnan(lo).any() or np.isnan(hi).any():
                        raise ValueError("no valid value")
                    struct.options |= bits
                    struct._raw_min()[:] = lo
                    struct._raw_max()[:] = hi
                except Exception:
                    struct.options &= ~bits
                    for raw in (struct._min, struct._max):
                        np.frombuffer(raw, np.uint8)[:] = 0

    # ---- finishing ----------------------------------------------------------------------

    def close(self) -> Path:
        """Finish the file (header counts and bounds, EVLRs) and rename it to :attr:`path`.

        Returns
        -------
        Path
            :attr:`path`. Calling again does nothing. On failure the temporary file is
            deleted and the error is raised.
        """
        if self._finished:
            return self.path
        self._finished = True
        try:
            self._set_extra_bytes_ranges()
            if self._evlrs:
                self._writer.write_evlrs(self._evlrs)
            try:
                self._writer.close()
            except Exception as exc:
                raise self._write_error(exc) from exc
            publish(self._tmp, self.path)
        except BaseException:
            self._discard_writer()
            self._unlink_tmp()
            raise
        return self.path

    def abort(self) -> None:
        """Drop everything written: close and delete the temporary file; ``path`` untouched."""
        self._finished = True
        self._discard_writer()
        self._unlink_tmp()

    def _discard_writer(self):
        writer, self._writer = self._writer, None
        if writer is None:
            return
        try:
            writer.dest.close()
        except Exception:
            pass

    def _unlink_tmp(self):
        try:
            os.unlink(self._tmp)
        except (OSError, AttributeError):
            pass


def write_las(path, template_header: laspy.LasHeader, xyz, attrs: Mapping | None = None, *,
              extra: Mapping | None = None, extra_dims=SIMPLIFY_DIMS) -> Path:
    """Write one LAS/LAZ file in one call: :class:`LasOutput` with a single
    :meth:`~LasOutput.write`.

    Parameters
    ----------
    path, template_header, extra_dims
        See :class:`LasOutput`.
    xyz, attrs, extra
        See :meth:`LasOutput.write`.

    Returns
    -------
    Path
    """
    with LasOutput(path, template_header, extra_dims) as out:
        out.write(xyz, attrs, extra)
    return out.path
