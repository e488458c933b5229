"""LAS/LAZ point clouds read, with memory bounded by a chunk size (laspy + lazrs).

Public API
----------
las_files(spec) -> list[Path]
    The ``.las``/``.laz`` files named by a file, a folder, a glob pattern or a list of those.
lists_path(spec, path) -> bool
    Whether ``las_files(spec)`` would list ``path`` once it exists (an output written there).
LasSource(spec, chunk_points=1_000_000)
    Describes the input from the file headers alone (files, point count, bounds, point format,
    scales/offsets, CRS, dimension names) and reads it chunk by chunk with :meth:`LasSource.chunks`
    as ``(start_index, xyz float64 (m, 3), attrs dict name -> (m,) array)``.

Writing is :mod:`.las_output`'s.

Decisions
---------
* Reading several files: they are read in order (the order of :func:`las_files`) as one cloud
  with one running point index. Coordinates are returned as float64 (``X * scale + offset``),
  so files with different scales/offsets, and even different point formats, can be read
  together; ``attrs`` then holds only the dimensions (same name and type) common to all files.
  A chunk never spans two files, so the last chunk of each file may be shorter.
* Writing needs one layout: :meth:`LasSource.template_header` raises
  :class:`~tiledsimplify.errors.FileFormatError` when the files differ in point format id or in
  their set of dimensions (names and types, extra bytes included), and tells to merge/convert
  them first (e.g. with PDAL). Differing scales/offsets are accepted: the output uses the first
  file's, so coordinates of the other files are re-quantised to that grid (a change of at most
  half a unit of the first file's scale). Files whose CRS descriptions differ give a warning.
* CRS: :attr:`LasSource.crs` is a plain string without needing pyproj: ``"EPSG:<code>"`` when
  the WKT VLR names a top-level EPSG code or, without WKT, the GeoTIFF keys do; otherwise the
  WKT text; ``None`` when the file has no CRS records. The headers' ``parse_crs()`` (needs
  pyproj) remains available through :meth:`LasSource.template_header`.

Errors
------
A missing input raises :class:`FileNotFoundError` naming it. A file that is not LAS/LAZ, is
truncated or corrupt raises :class:`~tiledsimplify.errors.FileFormatError` (a ``ValueError``)
naming the file and saying what to do; so does an unsupported suffix.
"""

from __future__ import annotations

import copy
import errno
import fnmatch
import glob
import itertools
import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import laspy
import numpy as np

from ..core import bounds
from ..errors import FileFormatError, InputError
from .las_pieces import _XYZ

__all__ = [
    "LAS_SUFFIXES",
    "LasFileInfo",
    "LasSource",
    "las_files",
]

#: File suffixes read and written (case-insensitive); ``.laz`` is LASzip-compressed.
LAS_SUFFIXES = (".las", ".laz")

_GLOB_CHARS = re.compile(r"[*?\[]")
_FIX_READ = ("The file may be truncated or corrupt: compare its size with the original, copy or "
             "export it again, or check it with `pdal info` / `lasinfo`.")


# --------------------------------------------------------------------------------------
# finding files
# --------------------------------------------------------------------------------------

def _is_las(path: Path) -> bool:
    return path.suffix.lower() in LAS_SUFFIXES


#: suffixes of point files that are not LAS/LAZ (named as examples when a folder holds no LAS)
_POINT_SUFFIXES = (".ply", ".gz", ".xyz", ".csv", ".pts", ".asc", ".npy", ".e57", ".pcd",
                   ".obj", ".stl", ".off")


def _files_of_one(spec) -> list[Path]:
    path = Path(spec)
    if path.is_file():
        if not _is_las(path):
            raise FileFormatError(
                f"{path}: unsupported suffix '{path.suffix}' among LAS input; only LAS/LAZ "
                "(and E57) files are read as one cloud from a list, a folder or a glob "
                "pattern. Give one file of another format (PLY, XYZ/CSV/TXT, NPY...), or "
                "merge them first, e.g. `pdal merge a.ply b.ply merged.laz`.")
        return [path]
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.is_file())
        found = [p for p in files if _is_las(p)]
        if not found:
            points = [p for p in files if p.suffix.lower() in _POINT_SUFFIXES] or files
            other = (f" (it holds {len(files)} other file(s), e.g. {points[0].name}: a folder is "
                     "read as LAS/LAZ tiles; give one file of another format, or convert and "
                     "merge them first, e.g. `pdal merge a.ply b.ply merged.laz`)" if files
                     else "")
            raise FileNotFoundError(errno.ENOENT,
                                    f"no .las/.laz files in folder {path}{other}", str(path))
        return found
    text = os.fspath(spec)
    if _GLOB_CHARS.search(text):
        matched = sorted(Path(p) for p in glob.glob(text, recursive=True))
        found = [p for p in matched if p.is_file() and _is_las(p)]
        if not found:
            what = (f"{len(matched)} paths match but none is a .las/.laz file" if matched
                    else "nothing matches")
            raise FileNotFoundError(errno.ENOENT,
                                    f"no LAS/LAZ files for pattern {text!r}: {what}", text)
        return found
    raise FileNotFoundError(errno.ENOENT, f"LAS/LAZ input {text!r} does not exist", text)


def lists_path(spec, path) -> bool:
    """Whether :func:`las_files` on ``spec`` would list ``path`` if it existed: a LAS/LAZ
    file in a folder that ``spec`` names, or matched by a glob pattern of it (or ``path``
    itself named)."""
    path = Path(path)
    if not _is_las(path):
        return False
    target = os.path.abspath(path)
    for one in spec if isinstance(spec, (list, tuple)) else [spec]:
        text = os.fspath(one)
        if os.path.abspath(text) == target:
            return True
        if Path(text).is_dir() and os.path.abspath(text) == os.path.dirname(target):
            return True
        if _GLOB_CHARS.search(text) and fnmatch.fnmatch(target, os.path.abspath(text)):
            return True  # (fnmatch's * also matches across folders: a superset of glob's)
    return False


def las_files(spec) -> list[Path]:
    """List the LAS/LAZ files named by ``spec``.

    Parameters
    ----------
    spec : str, PathLike or sequence of them
        A path to one ``.las``/``.laz`` file, a folder (every ``*.las``/``*.laz`` directly
        inside, suffixes case-insensitive), or a glob pattern string (``**`` recurses). A list or
        tuple of such specs is expanded in its own order.

    Returns
    -------
    list of Path
        Sorted within a folder or pattern, without duplicates.

    Raises
    ------
    FileNotFoundError
        Nothing exists or matches; the message names ``spec``.
    FileFormatError
        ``spec`` is an existing file whose suffix is not ``.las``/``.laz``.
    """
    specs = spec if isinstance(spec, (list, tuple)) else [spec]
    if not specs:
        raise FileNotFoundError(errno.ENOENT, "no LAS/LAZ input given (empty list)", "")
    out: list[Path] = []
    seen = set()
    for one in specs:
        for path in _files_of_one(one):
            key = os.path.abspath(path)
            if key not in seen:
                seen.add(key)
                out.append(path)
    return out


# --------------------------------------------------------------------------------------
# headers
# --------------------------------------------------------------------------------------

def _format_error(path, exc: BaseException, where: str = "") -> FileFormatError:
    return FileFormatError(f"{path}: not a readable LAS/LAZ file{where} "
                           f"({type(exc).__name__}: {exc}). {_FIX_READ}")


def _open_reader(path: Path) -> laspy.LasReader:
    """``laspy.open`` that closes the file on failure and names the file in its errors."""
    fh = open(path, "rb")  # FileNotFoundError / PermissionError pass through as they are
    try:
        reader = laspy.open(fh, closefd=True)
    except BaseException as exc:
        fh.close()
        if isinstance(exc, Exception):
            raise _format_error(path, exc) from exc
        raise
    try:
        _merge_extra_bytes(reader.header)
    except BaseException:
        reader.close()
        raise
    return reader


def _merge_extra_bytes(header: laspy.LasHeader) -> None:
    """Describe the extra bytes from *every* Extra Bytes VLR, keeping no-data values.

    laspy reads only the first Extra Bytes VLR and names the remaining bytes "ExtraBytes"; it
    also drops the no-data values. Rebuild the point format from all of them (in VLR order)
    when their sizes add up to the record length; otherwise keep laspy's reading.
    """
    eb_vlrs = header.vlrs.get("ExtraBytesVlr")
    if not eb_vlrs:
        return
    try:
        params = []
        for vlr in eb_vlrs:
            for struct, param in zip(vlr.extra_bytes_structs, vlr.type_of_extra_dims()):
                no_data = struct.no_data
                if no_data is not None:
                    param.no_data = np.asarray(no_data)
                params.append(param)
        names = [p.name for p in params]
        fmt = laspy.PointFormat(header.point_format.id)
        if len(set(names)) != len(names) or set(names) & set(fmt.dimension_names):
            return
        for param in params:
            fmt.add_extra_dimension(param)
        if fmt.size != header.point_format.size:
            return
    except Exception:  # an odd Extra Bytes VLR: laspy's own reading stands
        return
    header.point_format = fmt  # the setter writes one Extra Bytes VLR describing all of them


_TOP_EPSG = re.compile(r'(?:AUTHORITY|ID)\[\s*"EPSG"\s*,\s*"?(\d+)"?\s*\]\s*\]\s*$',
                       re.IGNORECASE)


def _crs_description(header: laspy.LasHeader) -> tuple[str | None, str | None]:
    """(short CRS string, WKT text or None) from the CRS VLRs/EVLRs, without pyproj."""
    records = list(header.vlrs)
    if header.evlrs:
        records += list(header.evlrs)
    wkt = None
    epsg = None
    for rec in records:
        kind = type(rec).__name__
        if kind == "WktCoordinateSystemVlr" and wkt is None:
            text = rec.string
            if isinstance(text, bytes):
                text = text.decode("ascii", "replace")
            text = text.rstrip("\0").strip()
            wkt = text or None
        elif kind == "GeoKeyDirectoryVlr" and epsg is None:
            keys = {k.id: k for k in rec.geo_keys}
            for key_id in (3072, 2048):  # ProjectedCSTypeGeoKey, GeographicTypeGeoKey
                key = keys.get(key_id)
                if key is not None and key.tiff_tag_location == 0 and \
                        key.value_offset not in (0, 32767):
                    epsg = int(key.value_offset)
                    break
    if wkt is not None:
        match = _TOP_EPSG.search(wkt)
        return (f"EPSG:{match.group(1)}" if match else wkt), wkt
    if epsg is not None:
        return f"EPSG:{epsg}", None
    return None, None


@dataclass(frozen=True)
class LasFileInfo:
    """What the header of one LAS/LAZ file says (no point is read).

    Attributes
    ----------
    path : Path
    version : str
        LAS version, e.g. ``"1.4"``.
    point_format_id : int
    point_count : int
    scales, offsets : (3,) float64
    mins, maxs : (3,) float64
        Bounding box as written in the header.
    dimension_names : tuple of str
        Every dimension, ``X``, ``Y``, ``Z`` and extra bytes included.
    extra_dimensions : tuple of (name, numpy type string, description)
    crs : str or None
        See :attr:`LasSource.crs`.
    compressed : bool
    header : laspy.LasHeader
        The header itself (VLRs, EVLRs, extra-bytes description).
    seekable : bool
        Whether its points can be read from any point on (:meth:`LasSource.parts`): False for
        a LAZ file of chunks of varying size (:func:`variable_chunks`), which is cut at its
        chunks instead (``laz_chunks``).
    laz_chunks : LazChunks or None
        The chunk table of a LAZ file of chunks of varying size (None for any other file).
    """

    path: Path
    version: str
    point_format_id: int
    point_count: int
    scales: np.ndarray
    offsets: np.ndarray
    mins: np.ndarray
    maxs: np.ndarray
    dimension_names: tuple
    extra_dimensions: tuple
    crs: str | None
    compressed: bool
    header: laspy.LasHeader
    seekable: bool = True
    laz_chunks: LazChunks | None = None

    @property
    def signature(self) -> tuple:
        """Point format id and every dimension's (name, dtype): equal ones write alike."""
        return (self.point_format_id,
                tuple((d.name, str(d.dtype)) for d in self.header.point_format.dimensions))


#: user id of the VLR and EVLR that make a LAZ file a COPC file (its octree's info, hierarchy)
COPC_USER_ID = "copc"
#: the LASzip VLR's chunk size of a file whose chunks vary in size (COPC files)
VARIABLE_CHUNKS = 0xFFFFFFFF


def _gps_time_type(info) -> str:
    """How a file counts ``gps_time`` (its header's global encoding bit 0)."""
    standard = int(info.header.global_encoding.gps_time_type) == 1
    return "adjusted standard" if standard else "week"


def variable_chunks(header: laspy.LasHeader) -> bool:
    """Whether a LAZ file's chunks vary in size: its LASzip VLR (user ``laszip encoded``,
    record 22204) gives the chunk size :data:`VARIABLE_CHUNKS` (bytes 12-15 of the record:
    after the compressor, coder, version and options fields), as every COPC file does.

    lazrs (laspy's LAZ backend; 0.8.2, the newest on PyPI on 2026-12-03) reads such a file in
    order, but its seek lands in the wrong chunk past the first: on autzen_trim.laz rewritten
    in 30,000-point chunks, every seek at or after point 30,000 read other points or zeros,
    without an error (still so in 0.8.2 on 2026-12-07). So a part of such a file that does not
    start it is read by its chunk table instead (:class:`LazChunks`): whole chunks, each
    decompressed from its own bytes.
    """
    vlr = _laszip_vlr(header)
    if vlr is None:
        return False
    data = vlr.record_data_bytes()
    return len(data) >= 16 and int.from_bytes(data[12:16], "little") == VARIABLE_CHUNKS


def _laszip_vlr(header: laspy.LasHeader):
    """The LASzip VLR of a LAZ file's header (user ``laszip encoded``, record 22204), or
    None (laspy takes it out of the header once it builds the file's decoder)."""
    return next((v for v in header.vlrs
                 if v.user_id == "laszip encoded" and v.record_id == 22204), None)


@dataclass(frozen=True, eq=False)  # (arrays: compared, they would not give one bool)
class LazChunks:
    """The chunks of a LAZ file whose chunks vary in size (:func:`variable_chunks`), as its
    chunk table gives them: each chunk is compressed alone, so any run of them decompresses
    by itself (``lazrs.decompress_points_with_chunk_table``, as laspy's COPC reader reads an
    octree node) — the way around lazrs's seek in such files.

    ``vlr``: the LASzip VLR's record; ``start``: the byte offset of the first chunk (the
    point data's, past the 8 bytes of the chunk table's offset); ``points``, ``sizes``:
    int64 (k,), each chunk's points and bytes."""

    vlr: bytes
    start: int
    points: np.ndarray
    sizes: np.ndarray

    @classmethod
    def read(cls, path: Path, header: laspy.LasHeader) -> LazChunks:
        """The table of ``path`` (``header``: its header, the LASzip VLR still in it)."""
        import lazrs
        data = bytes(_laszip_vlr(header).record_data_bytes())
        with open(path, "rb") as fh:
            fh.seek(header.offset_to_point_data)
            table = lazrs.read_chunk_table(fh, lazrs.LazVlr(data))
        table = np.array(table, dtype=np.int64).reshape(-1, 2)
        points, sizes = table[:, 0].copy(), table[:, 1].copy()
        count = int(header.point_count)
        if int(points.sum()) != count or np.any(points < 0) or np.any(sizes < 0):
            raise FileFormatError(
                f"{path}: its LAZ chunk table holds {int(points.sum())} points in "
                f"{len(points)} chunks, its header {count}. {_FIX_READ}")
        return cls(data, int(header.offset_to_point_data) + 8, points, sizes)

    def runs(self, max_points: int) -> list[tuple[int, int]]:
        """``(a, b)``: consecutive runs of chunks ``a .. b - 1`` of at most ``max_points``
        points each, or one chunk where a chunk alone holds more."""
        out, a, held = [], 0, 0
        for k, m in enumerate(self.points.tolist()):
            if k > a and held + m > max_points:
                out.append((a, k))
                a, held = k, 0
            held += m
        if len(self.points):
            out.append((a, len(self.points)))
        return out

    def part(self, a: int, b: int) -> LazChunks:
        """Chunks ``a .. b - 1`` alone (``start`` their first's byte offset)."""
        return LazChunks(self.vlr, self.start + int(self.sizes[:a].sum()),
                         self.points[a:b].copy(), self.sizes[a:b].copy())


def _output_template(info: LasFileInfo) -> laspy.LasHeader:
    """A copy of ``info``'s header as an output's template: less a COPC file's ``copc`` VLR
    and EVLR (:data:`COPC_USER_ID`), which describe its octree, not an output (kept, readers
    would take the output for a COPC file)."""
    header = copy.deepcopy(info.header)
    for records in (header.vlrs, header.evlrs):
        if records:
            records[:] = [r for r in records if r.user_id != COPC_USER_ID]
    return header


def _read_info(path: Path) -> LasFileInfo:
    with _open_reader(path) as reader:
        header = reader.header
        count = int(header.point_count)
        # before the decoder is built: laspy then takes the LASzip VLR out of the header
        variable = bool(header.are_points_compressed) and variable_chunks(header)
        laz_chunks = None
        if variable and count > 0:
            try:
                laz_chunks = LazChunks.read(path, header)
            except FileFormatError:
                raise
            except Exception as exc:
                raise _format_error(path, exc, " (LAZ chunk table)") from exc
        if count > 0:
            if header.are_points_compressed:
                try:  # builds the LAZ decoder: reads the LASzip VLR and the chunk table
                    _ = reader.point_source
                except Exception as exc:
                    raise _format_error(path, exc, " (LAZ chunk table)") from exc
            else:
                need = header.offset_to_point_data + count * header.point_format.size
                size = path.stat().st_size
                if size < need:
                    raise FileFormatError(
                        f"{path}: truncated LAS file: the header promises {count} points of "
                        f"{header.point_format.size} bytes ({need} bytes up to the last point) "
                        f"but the file has {size} bytes. {_FIX_READ}")
        fmt = header.point_format
        crs, _ = _crs_description(header)
        return LasFileInfo(
            path=path,
            version=str(header.version),
            point_format_id=int(fmt.id),
            point_count=count,
            scales=np.array(header.scales, dtype=np.float64),
            offsets=np.array(header.offsets, dtype=np.float64),
            mins=np.array(header.mins, dtype=np.float64),
            maxs=np.array(header.maxs, dtype=np.float64),
            dimension_names=tuple(fmt.dimension_names),
            extra_dimensions=tuple((d.name, str(d.dtype), d.description)
                                   for d in fmt.extra_dimensions),
            crs=crs,
            compressed=bool(header.are_points_compressed),
            header=header,
            seekable=not variable,
            laz_chunks=laz_chunks,
        )


# --------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------

def part_ranges(count, max_points, chunk_points):
    """``(lo, hi)`` of consecutive parts of ``count`` points: at most ``max_points`` each,
    rounded down to whole chunks of ``chunk_points`` and at least one chunk, so that a part's
    chunks are the whole input's; one part if ``max_points`` is None, none if ``count`` is
    0. Every chunked source cuts itself with this (``parts``)."""
    step = count if max_points is None else max(1, int(max_points) // chunk_points) * chunk_points
    return list(itertools.pairwise([*range(0, count, max(step, 1)), count]))


def _header_box(header: laspy.LasHeader):
    """``(lo, hi)`` a file's points must lie in, or None where its header's bounds cannot
    be trusted (unset: all zero, or inverted). The header's box grown on every side by its
    diagonal, and by at least 1000 steps of the file's grid: a stale header (points moved or
    cropped without rewriting it) still reads, while a damaged LAZ chunk, which lazrs may
    decode to arbitrary coordinates without an error, does not."""
    mins = np.asarray(header.mins, dtype=np.float64)
    maxs = np.asarray(header.maxs, dtype=np.float64)
    if not (np.all(np.isfinite(mins)) and np.all(np.isfinite(maxs))) or np.any(maxs < mins) \
            or (not mins.any() and not maxs.any()):
        return None
    margin = max(float(np.linalg.norm(maxs - mins)),
                 1000 * float(np.max(np.abs(np.asarray(header.scales, dtype=np.float64)))))
    return mins - margin, maxs + margin


def _check_in_box(path, xyz, box, first):
    """Refuse a chunk (points ``first``… of ``path``) with points far outside the header's
    bounding box (:func:`_header_box`)."""
    if not len(xyz):
        return
    lo, hi = bounds.box(xyz)
    if np.all(lo >= box[0]) and np.all(hi <= box[1]):
        return
    out = np.any((xyz < box[0]) | (xyz > box[1]), axis=1)
    where = int(np.flatnonzero(out)[0])
    raise FileFormatError(
        f"{path}: {int(out.sum()):,} of its points {first:,} to {first + len(xyz) - 1:,} lie far "
        f"outside the bounding box its header gives (point {first + where} at "
        f"{', '.join(f'{v:.6g}' for v in xyz[where])}): the file is most likely corrupt (a "
        "damaged LAZ chunk decodes to wrong points without an error). Copy or export it "
        "again and check it with `lasinfo` / `pdal info`; if only its header's bounds are "
        "wrong, rewrite them (e.g. `lasinfo -repair_bb`).")


class LasPart:
    """Points ``lo`` to ``hi - 1`` of one file of a :class:`LasSource`, read as its chunks
    (global start indices, the source's attribute names) — :meth:`LasSource.parts`. Holds
    paths and numbers only, so it pickles to other processes and cluster workers.

    ``laz``: for a LAZ file of chunks of varying size (COPC), the part's own run of them
    (:class:`LazChunks`), which it decompresses from their bytes; any other part seeks its
    reader to ``lo``.

    Calling it returns :meth:`chunks` (a chunk source for :meth:`.TileStore.create`)."""

    def __init__(self, path, expect, first, lo, hi, chunk_points, names, laz=None):
        self.path = Path(path)
        self.expect = tuple(expect)  # (point record size, point count) when opened
        self.first, self.lo, self.hi = int(first), int(lo), int(hi)
        self.chunk_points = int(chunk_points)
        self.names = tuple(names)
        self.laz = laz

    def __call__(self) -> Iterator[tuple[int, np.ndarray, dict]]:
        return self.chunks()

    def __repr__(self) -> str:
        return f"LasPart({self.path.name}, points {self.lo}..{self.hi - 1})"

    def chunks(self) -> Iterator[tuple[int, np.ndarray, dict]]:
        """This part's chunks, as :meth:`LasSource.chunks` gives them."""
        path = self.path
        with _open_reader(path) as reader:
            header = reader.header
            if (header.point_format.size, int(header.point_count)) != self.expect:
                raise FileFormatError(f"{path}: changed since it was opened; open it again.")
            scales = np.asarray(header.scales, dtype=np.float64)
            offsets = np.asarray(header.offsets, dtype=np.float64)
            box = _header_box(header)
            if self.laz is not None:
                records = self._decompressed(header.point_format, scales, offsets)
            else:
                records = self._read(reader)
            for done, rec in records:
                xyz = np.empty((len(rec), 3), dtype=np.float64)
                for axis, dim in enumerate(_XYZ):
                    np.multiply(rec[dim], scales[axis], out=xyz[:, axis])
                    xyz[:, axis] += offsets[axis]
                if box is not None:
                    _check_in_box(path, xyz, box, done)
                attrs = {name: np.array(rec[name]) for name in self.names}
                del rec
                yield self.first + done, xyz, attrs

    def _read(self, reader):
        """``(first point, records)`` of up to ``chunk_points`` each, from ``reader`` seeked
        to ``lo``."""
        path, done = self.path, self.lo
        if done:
            try:
                reader.seek(done)
            except Exception as exc:
                raise _format_error(path, exc, f" while seeking to point {done}") from exc
        while done < self.hi:
            want = min(self.chunk_points, self.hi - done)
            try:
                rec = reader.read_points(want)
            except Exception as exc:
                raise _format_error(path, exc, f" while reading points {done} to "
                                               f"{done + want - 1}") from exc
            if len(rec) != want:
                raise FileFormatError(
                    f"{path}: truncated: the header promises {self.expect[1]} points "
                    f"but only {done + len(rec)} could be read. {_FIX_READ}")
            yield done, rec
            done += want

    def _decompressed(self, fmt, scales, offsets):
        """As :meth:`_read`, from the part's LAZ chunks: runs of them of at most
        ``chunk_points`` points (one chunk where it holds more) read as bytes and
        decompressed alone, then cut into records of at most ``chunk_points``."""
        import lazrs
        path, laz, done = self.path, self.laz, self.lo
        with open(path, "rb") as fh:
            fh.seek(laz.start)
            for a, b in laz.runs(self.chunk_points):
                m, size = int(laz.points[a:b].sum()), int(laz.sizes[a:b].sum())
                data = fh.read(size)
                if len(data) != size:
                    raise FileFormatError(
                        f"{path}: truncated: its chunk table promises {size} bytes for points "
                        f"{done} to {done + m - 1} but the file ends before. {_FIX_READ}")
                raw = np.zeros(m * fmt.size, dtype=np.uint8)
                table = list(zip(laz.points[a:b].tolist(), laz.sizes[a:b].tolist()))
                try:
                    lazrs.decompress_points_with_chunk_table(data, laz.vlr, raw, table)
                except Exception as exc:
                    raise _format_error(path, exc, f" while reading points {done} to "
                                                   f"{done + m - 1}") from exc
                del data
                packed = laspy.PackedPointRecord.from_buffer(raw, fmt, m)
                rec = laspy.ScaleAwarePointRecord(packed.array, fmt, scales, offsets)
                for lo in range(0, m, self.chunk_points):
                    yield done + lo, rec[lo:lo + self.chunk_points]
                done += m


class LasSource:
    """One or more LAS/LAZ files read as one point cloud, chunk by chunk.

    Only the headers are read on construction; points are read by :meth:`chunks`, so memory
    stays proportional to ``chunk_points``.

    Parameters
    ----------
    spec : str, PathLike or sequence of them
        See :func:`las_files`.
    chunk_points : int, default 1_000_000
        Most points per chunk.

    Attributes
    ----------
    files : list of Path
    infos : list of LasFileInfo
        One per file, in reading order.
    chunk_points : int

    Raises
    ------
    FileNotFoundError
        Nothing matches ``spec``.
    FileFormatError
        A file is not LAS/LAZ, is truncated or corrupt (found from its header and, for LAZ, its
        chunk table), or has an unsupported suffix.
    """

    def __init__(self, spec, chunk_points: int = 1_000_000):
        if int(chunk_points) != chunk_points or chunk_points < 1:
            raise InputError(f"chunk_points must be a positive integer, got {chunk_points!r}")
        self.chunk_points = int(chunk_points)
        self.files = las_files(spec)
        self.infos = [_read_info(p) for p in self.files]
        # files with CRS records and files without count as different too: a LAS/LAZ
        # output takes the first file's records, so a first file without them left the
        # output without a CRS, silently
        crs = {i.crs for i in self.infos}
        if len(crs) > 1:
            warnings.warn("LAS/LAZ files with different CRS descriptions are read as one cloud, "
                          "their coordinates as they are (not reprojected; a LAS/LAZ output "
                          "takes the first file's CRS"
                          + (", here none" if self.infos[0].crs is None else "") + "): "
                          + "; ".join(f"{i.path.name}: {_short(i.crs) or 'no CRS records'}"
                                      for i in self.infos)
                          + ". Reproject them to one CRS first if they differ in more than "
                          "how it is written (e.g. `pdal translate in.laz out.laz reprojection "
                          "--filters.reprojection.out_srs=EPSG:XXXX`), or assign it to "
                          "the files without one (`pdal translate a.laz b.laz "
                          "--writers.las.a_srs=EPSG:XXXX`).",
                          UserWarning, stacklevel=2)
        first = self.infos[0]
        common = []
        kinds = [dict((d.name, str(d.dtype)) for d in i.header.point_format.dimensions)
                 for i in self.infos]
        for name, dtype in kinds[0].items():
            if name not in _XYZ and all(k.get(name) == dtype for k in kinds[1:]):
                common.append(name)
        self._attribute_names = tuple(common)
        self._first = first
        self._one_layout = False  # the files' layouts checked alike (file_header)

    # ---- description from the headers -------------------------------------------------

    @property
    def count(self) -> int:
        """Total number of points, from the headers."""
        return sum(i.point_count for i in self.infos)

    def __len__(self) -> int:
        return self.count

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """``(mins, maxs)``, each (3,) float64: the union of the headers' bounding boxes."""
        infos = [i for i in self.infos if i.point_count > 0] or self.infos
        return (np.min([i.mins for i in infos], axis=0), np.max([i.maxs for i in infos], axis=0))

    @property
    def point_format_id(self) -> int:
        """Point format id of the first file (see :meth:`template_header` for mixed sets)."""
        return self._first.point_format_id

    @property
    def point_format(self) -> laspy.PointFormat:
        """laspy point format of the first file, extra-bytes dimensions included."""
        return self._first.header.point_format

    @property
    def version(self) -> str:
        """LAS version of the first file."""
        return self._first.version

    @property
    def scales(self) -> np.ndarray:
        """(3,) scales of the first file, those an output from :meth:`template_header` uses."""
        return self._first.scales.copy()

    @property
    def offsets(self) -> np.ndarray:
        """(3,) offsets of the first file, those an output from :meth:`template_header` uses."""
        return self._first.offsets.copy()

    @property
    def crs(self) -> str | None:
        """CRS of the first file as a string: ``"EPSG:<code>"``, WKT text, or None.

        Read from the WKT VLR (a top-level EPSG id gives ``"EPSG:<code>"``, otherwise the WKT
        itself) or, without one, from the GeoTIFF keys (projected, then geographic EPSG code).
        It is what the file *says*: nothing checks it against the coordinates.
        """
        return self._first.crs

    @property
    def crs_wkt(self) -> str | None:
        """The WKT text of the first file's WKT CRS record, if it has one."""
        return _crs_description(self._first.header)[1]

    @property
    def dimension_names(self) -> tuple[str, ...]:
        """Every dimension of the first file (``X``, ``Y``, ``Z`` and extra bytes included)."""
        return self._first.dimension_names

    @property
    def extra_dimension_names(self) -> tuple[str, ...]:
        """Names of the first file's extra-bytes dimensions."""
        return tuple(name for name, _, _ in self._first.extra_dimensions)

    @property
    def attribute_names(self) -> tuple[str, ...]:
        """Keys of the ``attrs`` dict of :meth:`chunks`: the dimensions other than X, Y, Z
        that every file has with the same type (all of them for a single file)."""
        return self._attribute_names

    def template_header(self) -> laspy.LasHeader:
        """A copy of the first file's header, to give to :class:`.las_output.LasOutput`.

        Returns
        -------
        laspy.LasHeader
            With VLRs, EVLRs, scales, offsets and the merged extra-bytes description; less a
            COPC file's ``copc`` VLR and EVLR (:data:`COPC_USER_ID`), which describe its
            octree, not an output.

        Raises
        ------
        FileFormatError
            The files differ in point format id or in their dimensions (names/types, extra
            bytes included), so no single output layout keeps all of them; or they count
            ``gps_time`` differently (GPS week time or adjusted standard time).
        """
        self._check_layouts()
        return _output_template(self._first)

    def file_header(self, k: int) -> laspy.LasHeader:
        """A copy of file ``k``'s own header, as :meth:`template_header` makes of the first:
        the template of its output where each input file gets one (it keeps its file's
        scales, offsets, CRS and records, and its own way of counting ``gps_time``).

        Raises
        ------
        FileFormatError
            The files differ in point format id or in their dimensions: the tile store holds
            only the dimensions they have in common (:attr:`attribute_names`).
        """
        if not self._one_layout:  # (once: a folder of thousands of files)
            self._check_layouts(gps_time=False)
            self._one_layout = True
        return _output_template(self.infos[k])

    def _check_layouts(self, gps_time=True):
        """Refuse files of different point formats or dimensions and, with ``gps_time``,
        files that count ``gps_time`` differently (see :meth:`template_header`)."""
        ref = self._first
        for info in self.infos[1:]:
            if info.signature != ref.signature:
                raise FileFormatError(
                    f"{info.path} (point format {info.point_format_id}, dimensions "
                    f"{', '.join(info.dimension_names)}) and {ref.path} (point format "
                    f"{ref.point_format_id}, dimensions {', '.join(ref.dimension_names)}) "
                    "cannot be written to one LAS/LAZ output: they must have the same point "
                    "format and dimensions. Merge or convert them to one layout first, e.g. "
                    "`pdal merge a.laz b.laz merged.laz` or `pdal translate in.laz out.laz "
                    "--writers.las.dataformat_id=<id> --writers.las.extra_dims=all`.")
            if gps_time and "gps_time" in info.dimension_names and \
                    _gps_time_type(info) != _gps_time_type(ref):
                raise FileFormatError(
                    f"{info.path} ({_gps_time_type(info)} GPS time) and {ref.path} "
                    f"({_gps_time_type(ref)} GPS time) count gps_time differently, and one "
                    "LAS/LAZ output has one way: their times would be mixed. Simplify them in "
                    "separate runs (week time cannot be converted without its GPS week), or "
                    "write a PLY/NPY/text output, which has no gps_time, or one output per "
                    "input file (an output name with {stem}); if a header's flag is simply "
                    "wrong, fix that file's global encoding first.")

    def __repr__(self) -> str:
        return (f"LasSource({len(self.files)} file(s), {self.count} points, point format "
                f"{self.point_format_id}, crs={_short(self.crs)!r})")

    # ---- points -------------------------------------------------------------------------

    def chunks(self) -> Iterator[tuple[int, np.ndarray, dict]]:
        """Read the points, at most ``chunk_points`` at a time, in file order.

        Yields
        ------
        start : int
            Global index of the chunk's first point (running across files).
        xyz : (m, 3) float64
            ``X * scale + offset`` with the chunk's file's scales/offsets.
        attrs : dict of str -> ndarray
            One array per name of :attr:`attribute_names`, length ``m`` (shape ``(m, k)`` for
            an extra-bytes dimension of ``k`` elements); scaled extra-bytes dimensions are
            returned scaled (float64).

        Raises
        ------
        FileFormatError
            A file is truncated or corrupt (fewer points than its header promises, or the
            decompressor fails); the message names the file and the point range.
        """
        for part in self.parts():
            yield from part.chunks()

    def parts(self, max_points: int | None = None) -> list[LasPart]:
        """The input cut in consecutive parts: each file, cut into ranges of at most
        ``max_points`` (rounded down to whole chunks, at least one; None: whole files; a LAZ
        file of chunks of varying size, e.g. COPC, :func:`variable_chunks`, cut at its own
        chunks, runs of them of at most ``max_points`` or one chunk, :class:`LazChunks`).
        Their points, part after part, are :meth:`chunks`'s (and their chunks too but where a
        LAZ file of chunks of varying size is cut); each part opens its file itself and
        pickles, so parts can be read at once by threads, processes or cluster workers (a
        parallel ingest, :meth:`.TileStore.create`)."""
        out, first = [], 0
        for info in self.infos:
            count = info.point_count
            expect = (info.header.point_format.size, count)
            laz = info.laz_chunks
            if info.seekable or max_points is None or laz is None:
                cut = max_points if info.seekable else None
                for lo, hi in part_ranges(count, cut, self.chunk_points):
                    out.append(LasPart(info.path.absolute(), expect, first, lo, hi,
                                       self.chunk_points, self._attribute_names))
            else:  # chunks of varying size: lazrs cannot seek in them, cut at them
                ends = np.concatenate([[0], np.cumsum(laz.points)])
                for a, b in laz.runs(int(max_points)):
                    out.append(LasPart(info.path.absolute(), expect, first, int(ends[a]),
                                       int(ends[b]), self.chunk_points,
                                       self._attribute_names, laz.part(a, b)))
            first += count
        return out

    def read_all(self) -> tuple[np.ndarray, dict]:
        """Every point at once (for tests and small inputs).

        Returns
        -------
        xyz : (n, 3) float64
        attrs : dict of str -> ndarray
            As in :meth:`chunks`, concatenated.
        """
        xyzs, parts = [], {name: [] for name in self._attribute_names}
        for _, xyz, attrs in self.chunks():
            xyzs.append(xyz)
            for name, values in attrs.items():
                parts[name].append(values)
        if not xyzs:
            empty = laspy.ScaleAwarePointRecord.zeros(0, header=self._first.header)
            return (np.empty((0, 3)),
                    {name: np.array(empty[name]) for name in self._attribute_names})
        return np.concatenate(xyzs), {n: np.concatenate(v) for n, v in parts.items()}


def _short(text, limit=60):
    if text is None or len(text) <= limit:
        return text
    return text[:limit - 3] + "..."
