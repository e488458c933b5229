"""Readers for triangle meshes (OBJ, OFF, STL, PLY) and point files (PLY, XYZ/CSV/TXT, NPY).

Only numpy is used. Every format may be gzip-compressed (``name.ply.gz``,
``NAME.STL.gz``); the format is chosen from the suffix before ``.gz``, case-insensitively.

Public functions
----------------
read_mesh(path) -> (vertices float64 (n, 3), faces int64 (m, 3))
read_points(path) -> points float64 (n, 3)

Errors
------
A missing file raises :class:`FileNotFoundError`. A file whose content does not match
its format raises :class:`tiledsimplify.errors.FileFormatError` (a ``ValueError``) whose
message names the file, says what is wrong and what to do about it.
"""

from __future__ import annotations

import errno
import gzip
import io
import os
import re
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tiledsimplify.errors import FileFormatError

__all__ = ["read_mesh", "read_points", "MESH_SUFFIXES", "POINT_SUFFIXES"]

#: Suffixes understood by :func:`read_mesh` (each may also carry ``.gz``).
MESH_SUFFIXES = (".obj", ".off", ".stl", ".ply")
#: Suffixes understood by :func:`read_points` in addition to :data:`MESH_SUFFIXES`.
POINT_SUFFIXES = (".xyz", ".csv", ".txt", ".pts", ".asc", ".npy", ".npz")

_GZIP_MAGIC = b"\x1f\x8b"


# --------------------------------------------------------------------------------------
# common helpers
# --------------------------------------------------------------------------------------


def _load(path) -> tuple[Path, bytes, str]:
    """Read a file's bytes (gunzipped if needed) and return (path, data, format suffix)."""
    path = Path(os.fspath(path))
    if not path.exists():
        raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), str(path))
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(path))
    data = path.read_bytes()
    name = path.name.lower()
    gz_suffix = name.endswith(".gz")
    if gz_suffix:
        name = name[:-3]
    if gz_suffix or data[:2] == _GZIP_MAGIC:
        if data[:2] != _GZIP_MAGIC:
            raise FileFormatError(
                f"{path}: the name ends in .gz but the content is not gzip data "
                "(no gzip magic bytes); rename the file without '.gz' or compress it with gzip."
            )
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError, zlib.error) as exc:
            raise FileFormatError(
                f"{path}: the gzip stream is corrupt or truncated ({exc}); "
                "re-download or re-compress the file."
            ) from None
    return path, data, Path(name).suffix


def _fail(path: Path, what: str, fix: str):
    raise FileFormatError(f"{path}: {what}; {fix}")


def _fan_triangulate(counts: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """Triangulate polygons given as per-polygon vertex counts and concatenated indices.

    A polygon (v0, v1, ..., vk-1) becomes the fan (v0, vi, vi+1), i = 1..k-2. Polygons
    with fewer than 3 vertices are dropped.
    """
    counts = np.asarray(counts, dtype=np.int64)
    flat = np.asarray(flat, dtype=np.int64)
    if counts.size == 0:
        return np.zeros((0, 3), dtype=np.int64)
    if np.all(counts == 3):
        return flat.reshape(-1, 3)
    starts = np.zeros(counts.size, dtype=np.int64)
    np.cumsum(counts[:-1], out=starts[1:])
    ntri = np.maximum(counts - 2, 0)
    total = int(ntri.sum())
    poly = np.repeat(np.arange(counts.size), ntri)
    first_tri = np.zeros(counts.size, dtype=np.int64)
    np.cumsum(ntri[:-1], out=first_tri[1:])
    j = np.arange(total, dtype=np.int64) - first_tri[poly]
    s = starts[poly]
    return np.stack([flat[s], flat[s + j + 1], flat[s + j + 2]], axis=1)


def _check_faces(path: Path, faces: np.ndarray, nv: int) -> np.ndarray:
    faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    if faces.size and (faces.min() < 0 or faces.max() >= nv):
        bad = int(faces.min()) if faces.min() < 0 else int(faces.max())
        _fail(
            path,
            f"a face refers to vertex index {bad} but the file has {nv} vertices "
            f"(valid indices are 0..{nv - 1})",
            "the file is truncated or corrupt; re-export it",
        )
    return faces


# --------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------

_PLY_TYPES = {
    "char": "i1", "int8": "i1",
    "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4",
    "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4",
    "double": "f8", "float64": "f8",
}
_STRUCT_CODES = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I", "f4": "f", "f8": "d"}


@dataclass
class _PlyProperty:
    name: str
    code: str  # numpy type code of the value (or of list items)
    count_code: str | None = None  # numpy type code of the list count; None for scalars

    @property
    def is_list(self) -> bool:
        return self.count_code is not None


@dataclass
class _PlyElement:
    name: str
    count: int
    props: list[_PlyProperty] = field(default_factory=list)


def _parse_ply_header(path: Path, data: bytes):
    if not data.startswith(b"ply"):
        _fail(path, "a PLY file must start with the line 'ply'", "check that the file really is PLY")
    m = re.search(rb"end_header[ \t]*\r?\n", data)
    if m is None:
        if data.rstrip().endswith(b"end_header"):
            body_start = len(data)
        else:
            _fail(path, "the PLY header has no 'end_header' line", "the file is truncated or not PLY; re-export it")
        header_end = data.rfind(b"end_header")
    else:
        header_end, body_start = m.start(), m.end()
    header = data[:header_end].decode("ascii", errors="replace")
    fmt = None
    elements: list[_PlyElement] = []
    for lineno, raw in enumerate(header.splitlines()[1:], start=2):
        parts = raw.split()
        if not parts or parts[0] in ("comment", "obj_info"):
            continue
        key = parts[0]
        if key == "format":
            if len(parts) < 2 or parts[1] not in ("ascii", "binary_little_endian", "binary_big_endian"):
                _fail(path, f"unknown PLY format line {raw.strip()!r} (header line {lineno})",
                      "use format ascii, binary_little_endian or binary_big_endian")
            fmt = parts[1]
        elif key == "element":
            try:
                elements.append(_PlyElement(parts[1], int(parts[2])))
            except (IndexError, ValueError):
                _fail(path, f"bad PLY element line {raw.strip()!r} (header line {lineno})",
                      "it must read 'element <name> <count>'")
            if elements[-1].count < 0:
                _fail(path, f"negative element count in {raw.strip()!r}", "the header is corrupt; re-export the file")
        elif key == "property":
            if not elements:
                _fail(path, f"PLY property before any element (header line {lineno})", "the header is corrupt; re-export the file")
            try:
                if parts[1] == "list":
                    ccode, icode, name = _PLY_TYPES[parts[2]], _PLY_TYPES[parts[3]], parts[4]
                    if ccode[0] == "f":
                        raise KeyError(parts[2])
                    elements[-1].props.append(_PlyProperty(name, icode, ccode))
                else:
                    elements[-1].props.append(_PlyProperty(parts[2], _PLY_TYPES[parts[1]]))
            except (IndexError, KeyError):
                _fail(path, f"bad or unsupported PLY property line {raw.strip()!r} (header line {lineno})",
                      f"property types must be one of {sorted(set(_PLY_TYPES))}")
        # other keywords are ignored (lenient)
    if fmt is None:
        _fail(path, "the PLY header has no 'format' line", "the file is corrupt; re-export it")
    return fmt, elements, body_start


def _truncated(path: Path, elem: _PlyElement):
    _fail(path, f"the PLY data ends before all {elem.count} '{elem.name}' elements were read",
          "the file is truncated; re-download or re-export it")


def _read_ply_binary_element(path, buf, offset, elem: _PlyElement, endian: str, wanted: set[str]):
    """Return ({prop name: array or (counts, flat)}, new offset) for one binary element."""
    n = elem.count
    props = elem.props
    lists = [p for p in props if p.is_list]
    out: dict = {}
    if n == 0:
        for p in props:
            if p.name in wanted:
                out[p.name] = (np.zeros(0, np.int64), np.zeros(0, p.code)) if p.is_list else np.zeros(0, p.code)
        return out, offset

    def fields(list_len: int | None):
        spec = []
        for i, p in enumerate(props):
            if p.is_list:
                spec.append((f"c{i}", endian + p.count_code))
                spec.append((f"p{i}", endian + p.code, (list_len,)))
            else:
                spec.append((f"p{i}", endian + p.code))
        return np.dtype(spec)

    if not lists:
        dt = fields(None)
        if offset + n * dt.itemsize > len(buf):
            _truncated(path, elem)
        arr = np.frombuffer(buf, dtype=dt, count=n, offset=offset)
        for i, p in enumerate(props):
            if p.name in wanted:
                out[p.name] = arr[f"p{i}"].astype(p.code)
        return out, offset + n * dt.itemsize

    if len(lists) == 1:
        # Fast path: assume every row has the same list length as the first row and
        # verify it; fall back to the general walk below if not.
        li = props.index(lists[0])
        pre = sum(np.dtype(p.code).itemsize for p in props[:li])
        ccode = endian + lists[0].count_code
        if offset + pre + np.dtype(ccode).itemsize > len(buf):
            _truncated(path, elem)
        c = int(np.frombuffer(buf, dtype=ccode, count=1, offset=offset + pre)[0])
        if 0 <= c <= (len(buf) - offset) // np.dtype(lists[0].code).itemsize:
            dt = fields(c)
            if offset + n * dt.itemsize <= len(buf):
                arr = np.frombuffer(buf, dtype=dt, count=n, offset=offset)
                if np.all(arr[f"c{li}"] == c):
                    for i, p in enumerate(props):
                        if p.name in wanted:
                            if p.is_list:
                                out[p.name] = (np.full(n, c, np.int64), arr[f"p{i}"].reshape(-1).astype(p.code))
                            else:
                                out[p.name] = arr[f"p{i}"].astype(p.code)
                    return out, offset + n * dt.itemsize

    # General case: walk the rows one by one (variable list lengths / several lists).
    e = "<" if endian == "<" else ">"
    collect = {p.name: [] for p in props if p.name in wanted}
    counts = {p.name: [] for p in props if p.name in wanted and p.is_list}
    size = len(buf)
    unpack_from = struct.unpack_from
    steps = []
    for p in props:
        vs = np.dtype(p.code).itemsize
        if p.is_list:
            steps.append((True, e + _STRUCT_CODES[p.count_code], np.dtype(p.count_code).itemsize,
                          _STRUCT_CODES[p.code], vs, p.name in wanted, p.name))
        else:
            steps.append((False, e + _STRUCT_CODES[p.code], vs, None, None, p.name in wanted, p.name))
    pos = offset
    try:
        for _ in range(n):
            for is_list, fmt, sz, icode, isz, want, name in steps:
                if is_list:
                    (c,) = unpack_from(fmt, buf, pos)
                    pos += sz
                    if want:
                        collect[name].extend(unpack_from(f"{e}{c}{icode}", buf, pos))
                        counts[name].append(c)
                    pos += c * isz
                else:
                    if want:
                        collect[name].append(unpack_from(fmt, buf, pos)[0])
                    pos += sz
    except struct.error:
        _truncated(path, elem)
    if pos > size:
        _truncated(path, elem)
    for p in props:
        if p.name in wanted:
            vals = np.asarray(collect[p.name], dtype=p.code)
            out[p.name] = (np.asarray(counts[p.name], np.int64), vals) if p.is_list else vals
    return out, pos


def _read_ply_ascii_element(path, tokens, pos, elem: _PlyElement, wanted: set[str]):
    """Like the binary version, on a list of whitespace-separated tokens."""
    n = elem.count
    props = elem.props
    lists = [p for p in props if p.is_list]
    out: dict = {}
    ntok = len(tokens)

    def number_array(toks, code):
        try:
            a = np.array(toks, dtype=np.float64)
        except ValueError:
            bad = next((t for t in toks if not _is_number(t)), "?")
            _fail(path, f"non-numeric value {bad!r} in the '{elem.name}' element data",
                  "the file is corrupt or its header does not match the data; re-export it")
        return a

    if n == 0:
        for p in props:
            if p.name in wanted:
                out[p.name] = (np.zeros(0, np.int64), np.zeros(0)) if p.is_list else np.zeros(0)
        return out, pos

    if not lists:
        k = len(props)
        if pos + n * k > ntok:
            _truncated(path, elem)
        arr = number_array(tokens[pos:pos + n * k], None).reshape(n, k)
        for i, p in enumerate(props):
            if p.name in wanted:
                out[p.name] = arr[:, i]
        return out, pos + n * k

    if len(lists) == 1:
        li = props.index(lists[0])
        try:
            c = int(tokens[pos + li])
        except (IndexError, ValueError):
            c = -1
        if c >= 0:
            k = len(props) + c  # fixed props + count + c items
            if pos + n * k <= ntok:
                cnt = number_array(tokens[pos + li:pos + n * k:k], None)
                if np.all(cnt == c):
                    arr = number_array(tokens[pos:pos + n * k], None).reshape(n, k)
                    col = 0
                    for p in props:
                        if p.is_list:
                            if p.name in wanted:
                                out[p.name] = (np.full(n, c, np.int64), arr[:, col + 1:col + 1 + c].reshape(-1))
                            col += 1 + c
                        else:
                            if p.name in wanted:
                                out[p.name] = arr[:, col]
                            col += 1
                    return out, pos + n * k

    # General case: walk the rows.
    collect = {p.name: [] for p in props if p.name in wanted}
    counts = {p.name: [] for p in props if p.name in wanted and p.is_list}
    try:
        for _ in range(n):
            for p in props:
                if p.is_list:
                    c = int(tokens[pos])
                    if c < 0:
                        raise ValueError(f"negative list length {c}")
                    if p.name in collect:
                        counts[p.name].append(c)
                        collect[p.name].extend(tokens[pos + 1:pos + 1 + c])
                    pos += 1 + c
                else:
                    if p.name in collect:
                        collect[p.name].append(tokens[pos])
                    pos += 1
    except IndexError:
        _truncated(path, elem)
    except ValueError as exc:
        _fail(path, f"bad list length in the '{elem.name}' element data ({exc})",
              "the file is corrupt or its header does not match the data; re-export it")
    if pos > ntok:
        _truncated(path, elem)
    for p in props:
        if p.name in wanted:
            vals = number_array(collect[p.name], None)
            if p.is_list:
                if sum(counts[p.name]) != vals.size:
                    _truncated(path, elem)
                out[p.name] = (np.asarray(counts[p.name], np.int64), vals)
            else:
                out[p.name] = vals
    return out, pos


def _is_number(tok) -> bool:
    try:
        float(tok)
    except (TypeError, ValueError):
        return False
    return True


def _read_ply(path: Path, data: bytes, want_faces: bool, all_props: bool = False):
    fmt, elements, body_start = _parse_ply_header(path, data)
    names = [e.name for e in elements]
    vname = next((nm for nm in ("vertex", "vertices") if nm in names), None)
    if vname is None:
        _fail(path, f"the PLY file has no 'vertex' element (elements: {names})",
              "export the points/mesh with a 'vertex' element holding x, y, z")
    velem = elements[names.index(vname)]
    vprops = [p.name for p in velem.props]
    for axis in "xyz":
        if axis not in vprops:
            _fail(path, f"the PLY 'vertex' element has no '{axis}' property (properties: {vprops})",
                  "export the vertices with x, y and z properties")
        if velem.props[vprops.index(axis)].is_list:
            _fail(path, f"the PLY vertex property '{axis}' is a list", "x, y, z must be scalar properties")
    fname = None
    face_prop = None
    if want_faces:
        fname = next((nm for nm in ("face", "faces") if nm in names), None)
        if fname is not None:
            felem = elements[names.index(fname)]
            fprops = {p.name: p for p in felem.props}
            face_prop = next((nm for nm in ("vertex_indices", "vertex_index") if nm in fprops), None)
            if face_prop is None:
                lst = [p.name for p in felem.props if p.is_list]
                if len(lst) == 1:
                    face_prop = lst[0]
                else:
                    _fail(path, f"the PLY 'face' element has no list property 'vertex_indices' "
                                f"(properties: {list(fprops)})",
                          "export faces with a 'property list uchar int vertex_indices'")
            elif not fprops[face_prop].is_list:
                _fail(path, f"the PLY face property '{face_prop}' is not a list",
                      "declare it as 'property list uchar int vertex_indices'")
    last_needed = max(names.index(vname), names.index(fname) if fname else -1)
    vwanted = set("xyz") | ({p.name for p in velem.props if not p.is_list} if all_props
                            else set())

    results: dict = {}
    if fmt == "ascii":
        body = data[body_start:].decode("ascii", errors="replace")
        tokens = body.split()
        pos = 0
        for i, elem in enumerate(elements[: last_needed + 1]):
            wanted = (vwanted if elem.name == vname
                      else {face_prop} if elem.name == fname else set())
            res, pos = _read_ply_ascii_element(path, tokens, pos, elem, wanted)
            results[elem.name] = res
    else:
        endian = "<" if fmt == "binary_little_endian" else ">"
        offset = body_start
        for i, elem in enumerate(elements[: last_needed + 1]):
            wanted = (vwanted if elem.name == vname
                      else {face_prop} if elem.name == fname else set())
            res, offset = _read_ply_binary_element(path, data, offset, elem, endian, wanted)
            results[elem.name] = res
    v = results[vname]
    if all_props:  # every scalar property, each of its own type, in the header's order;
        # x, y, z float64, as :func:`read_points` gives them (ASCII: the text's digits)
        props = [p for p in velem.props if not p.is_list]
        table = np.empty(velem.count, dtype=[
            (p.name, np.float64 if p.name in ("x", "y", "z")
             else np.dtype(p.code).newbyteorder("="))
            for p in props])
        for p in props:
            table[p.name] = v[p.name]
        return table, None
    vertices = np.column_stack([np.asarray(v[a], dtype=np.float64) for a in "xyz"]).reshape(-1, 3)
    if not want_faces:
        return vertices, None
    if fname is None:
        return vertices, np.zeros((0, 3), dtype=np.int64)
    counts, flat = results[fname][face_prop]
    flat = np.asarray(flat)
    if flat.dtype.kind == "f":
        if flat.size and not np.all(flat == np.round(flat)):
            _fail(path, "PLY face indices are not integers", "the file is corrupt; re-export it")
    faces = _fan_triangulate(counts, flat.astype(np.int64))
    return vertices, _check_faces(path, faces, len(vertices))


# --------------------------------------------------------------------------------------
# OBJ
# --------------------------------------------------------------------------------------


def _read_obj(path: Path, data: bytes, want_faces: bool = True):
    text = data.decode("utf-8", errors="replace").replace("\\\r\n", " ").replace("\\\n", " ")
    vlines: list[list[str]] = []
    counts: list[int] = []
    flat: list[int] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line:
            continue
        if line[0] in " \t":
            line = line.lstrip()
        if not line or line[0] not in "vf":
            continue
        parts = line.split()
        if not parts:
            continue
        key = parts[0]
        if key == "v":
            if len(parts) < 4:
                _fail(path, f"OBJ vertex line {lineno} has fewer than 3 coordinates: {line.strip()!r}",
                      "each 'v' line needs x y z")
            vlines.append(parts[1:4])
        elif key == "f" and want_faces:
            nv = len(vlines)
            try:
                idx = [int(t.split("/", 1)[0]) for t in parts[1:]]
            except ValueError:
                _fail(path, f"OBJ face line {lineno} is not understood: {line.strip()!r}",
                      "faces must be 'f i j k ...' with 1-based (or negative) vertex indices, "
                      "optionally as i/t/n")
            for k, i in enumerate(idx):
                if i > 0:
                    idx[k] = i - 1
                elif i < 0:
                    idx[k] = nv + i
                else:
                    _fail(path, f"OBJ face line {lineno} uses vertex index 0: {line.strip()!r}",
                          "OBJ indices start at 1; fix the exporter")
            counts.append(len(idx))
            flat.extend(idx)
    try:
        vertices = np.array(vlines, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        _fail(path, "an OBJ vertex line has a non-numeric coordinate", "the file is corrupt; re-export it")
    if not want_faces:
        return vertices, None
    faces = _fan_triangulate(np.array(counts, np.int64), np.array(flat, np.int64))
    return vertices, _check_faces(path, faces, len(vertices))


# --------------------------------------------------------------------------------------
# OFF
# --------------------------------------------------------------------------------------


def _read_off(path: Path, data: bytes, want_faces: bool = True):
    head = data[:64].lstrip()
    m = re.match(rb"(ST)?(C)?(N)?(4)?(n)?OFF", head)
    if m is None:
        _fail(path, "an OFF file must start with 'OFF' (or COFF, NOFF, STOFF, ...)", "check that the file is OFF")
    if m.group(4) or m.group(5):
        _fail(path, "4-D / n-D OFF variants (4OFF, nOFF) are not supported", "convert the file to plain 3-D OFF")
    if re.match(rb"\S*OFF\s+BINARY", head):
        _fail(path, "binary OFF is not supported", "convert it to ASCII OFF, PLY or OBJ")
    text = data.decode("ascii", errors="replace")
    lines = []
    for line in text.splitlines():
        cut = line.find("#")
        if cut >= 0:
            line = line[:cut]
        if line.strip():
            lines.append(line)
    header_rest = lines[0].split()[1:]
    li = 1
    if len(header_rest) >= 2:
        count_tokens = header_rest
    else:
        if len(lines) < 2:
            _fail(path, "the OFF file ends before the vertex/face count line", "the file is truncated")
        count_tokens = lines[1].split()
        li = 2
    try:
        nv, nf = int(count_tokens[0]), int(count_tokens[1])
    except (IndexError, ValueError):
        _fail(path, f"bad OFF count line {' '.join(count_tokens)!r}", "it must read '<n_vertices> <n_faces> <n_edges>'")
    if nv < 0 or nf < 0:
        _fail(path, "negative OFF vertex or face count", "the file is corrupt")
    if len(lines) < li + nv + (nf if want_faces else 0):
        _fail(path, f"the OFF file declares {nv} vertices and {nf} faces but has only "
                    f"{len(lines) - li} data lines", "the file is truncated; re-export it")
    try:
        vertices = np.array([ln.split()[:3] for ln in lines[li:li + nv]], dtype=np.float64).reshape(-1, 3)
    except ValueError:
        _fail(path, "an OFF vertex line has fewer than 3 numbers or a non-numeric value",
              "the file is corrupt; re-export it")
    if not want_faces:
        return vertices, None
    counts = np.empty(nf, dtype=np.int64)
    flat: list[str] = []
    try:
        for k, ln in enumerate(lines[li + nv:li + nv + nf]):
            parts = ln.split()
            c = int(parts[0])
            if c < 0 or len(parts) < 1 + c:
                raise ValueError(ln)
            counts[k] = c
            flat.extend(parts[1:1 + c])
        flat_arr = np.array(flat, dtype=np.int64)
    except ValueError:
        _fail(path, f"OFF face line {li + nv + k + 1} (after comments) is not "
                    "'<k> <i1> ... <ik>' with integer indices",
              "the file is corrupt; re-export it")
    faces = _fan_triangulate(counts, flat_arr)
    return vertices, _check_faces(path, faces, len(vertices))


# --------------------------------------------------------------------------------------
# STL
# --------------------------------------------------------------------------------------


def _merge_exact(corners: np.ndarray):
    """Merge bit-identical corner positions; vertices are ordered by first occurrence."""
    corners = corners.astype(np.float64) + 0.0  # maps -0.0 to +0.0
    if corners.size == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    uniq, first, inverse = np.unique(corners, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    vertices = uniq[order]
    faces = rank[inverse.reshape(-1)].reshape(-1, 3).astype(np.int64)
    return vertices, faces


def _merge_close(vertices: np.ndarray, faces: np.ndarray, tol: float):
    """Merge vertices closer than ``tol`` (transitively); keep the lowest-index one of each group."""
    if tol <= 0 or len(vertices) < 2:
        return vertices, faces
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(vertices).query_pairs(tol, output_type="ndarray")
    if len(pairs) == 0:
        return vertices, faces
    n = len(vertices)
    graph = coo_matrix((np.ones(len(pairs), np.int8), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    ncomp, labels = connected_components(graph, directed=False)
    rep = np.full(ncomp, n, dtype=np.int64)
    np.minimum.at(rep, labels, np.arange(n, dtype=np.int64))
    order = np.argsort(rep, kind="stable")
    rank = np.empty(ncomp, dtype=np.int64)
    rank[order] = np.arange(ncomp)
    return vertices[rep[order]], rank[labels][faces]


def _read_stl(path: Path, data: bytes, want_faces: bool = True, merge_tol: float = 1e-9):
    size = len(data)
    is_binary = False
    if size >= 84:
        (n,) = struct.unpack_from("<I", data, 80)
        if 84 + 50 * n == size:
            is_binary = True
    if is_binary:
        dt = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
        tri = np.frombuffer(data, dtype=dt, count=n, offset=84)
        corners = tri["v"].reshape(-1, 3)
    else:
        if not data.lstrip()[:5].lower() == b"solid":
            if size >= 84:
                (n,) = struct.unpack_from("<I", data, 80)
                _fail(path, f"binary STL header says {n} triangles ({84 + 50 * n} bytes) but the file has "
                            f"{size} bytes", "the file is truncated or corrupt; re-export it")
            _fail(path, "the file is neither ASCII STL (starts with 'solid') nor binary STL",
                  "check that the file is STL")
        nums = re.findall(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)", data)
        try:
            corners = np.array(nums, dtype=np.float64).reshape(-1, 3)
        except ValueError:
            _fail(path, "an ASCII STL 'vertex' line has a non-numeric coordinate", "the file is corrupt; re-export it")
        if corners.shape[0] % 3:
            _fail(path, f"the ASCII STL has {corners.shape[0]} 'vertex' lines, not a multiple of 3",
                  "every facet needs exactly 3 vertices; the file is truncated or corrupt")
        nfacet = len(re.findall(rb"endfacet", data))
        if nfacet * 3 != corners.shape[0]:
            _fail(path, f"the ASCII STL has {nfacet} facets but {corners.shape[0]} vertices",
                  "every facet needs exactly 3 vertices; the file is truncated or corrupt")
    if not np.all(np.isfinite(corners)):
        _fail(path, "the STL has non-finite (NaN or infinite) coordinates", "the file is corrupt; re-export it")
    vertices, faces = _merge_exact(corners)
    if merge_tol and len(vertices):
        diag = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
        vertices, faces = _merge_close(vertices, faces, merge_tol * diag)
    return vertices, faces


# --------------------------------------------------------------------------------------
# text / npy points
# --------------------------------------------------------------------------------------


def _read_text_points(path: Path, data: bytes) -> np.ndarray:
    text = data.decode("utf-8", errors="replace")
    lines = text.splitlines()
    first = None
    for i, line in enumerate(lines):
        s = line.strip()
        if s and not s.startswith("#") and not s.startswith("//"):
            first = i
            break
    if first is None:
        _fail(path, "the file holds no points", "write one point per line as 'x y z' or 'x,y,z'")
    sample = lines[first]
    delim = "," if "," in sample else (";" if ";" in sample else None)

    def fields(s):
        return [t for t in (s.split(delim) if delim else s.split())]

    toks = fields(sample)
    skip = first
    if len(toks) < 3 or not all(_is_number(t) for t in toks[:3]):
        skip = first + 1  # header line (column names, or a point count as in .pts)
        rest = next((ln for ln in lines[skip:] if ln.strip() and not ln.lstrip().startswith("#")), None)
        if rest is not None:
            delim = "," if "," in rest else (";" if ";" in rest else None)
    body = lines[skip:]
    try:
        pts = np.loadtxt(body, delimiter=delim, usecols=(0, 1, 2), comments=("#", "//"), ndmin=2, dtype=np.float64)
    except ValueError as exc:
        where = str(exc)
        for k, ln in enumerate(body, start=skip + 1):
            s = ln.strip()
            if not s or s.startswith(("#", "//")):
                continue
            toks = fields(s.split("#", 1)[0])
            if len(toks) < 3 or not all(_is_number(t) for t in toks[:3]):
                where = f"line {k}: {s[:80]!r}"
                break
        _fail(path, f"could not read three numeric columns ({where})",
              "write one point per line as 'x y z' or 'x,y,z' (the same separator on every line); "
              "only a single header line is allowed")
    if pts.shape[0] == 0:
        _fail(path, "the file holds no points", "write one point per line as 'x y z' or 'x,y,z'")
    return np.ascontiguousarray(pts, dtype=np.float64)


def _read_npy_points(path: Path, data: bytes, suffix: str) -> np.ndarray:
    try:
        obj = np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        _fail(path, f"not a valid {suffix} file ({exc})", "save the points with numpy.save(path, points)")
    if suffix == ".npz":
        keys = list(obj.keys())
        key = "points" if "points" in keys else (keys[0] if len(keys) == 1 else None)
        if key is None:
            _fail(path, f"the .npz archive holds {keys} and none is called 'points'",
                  "store the (n, 3) array under the name 'points'")
        arr = obj[key]
    else:
        arr = obj
    if arr.dtype.names and all(a in arr.dtype.names for a in "xyz"):
        arr = np.column_stack([arr[a].reshape(-1) for a in "xyz"])
    if arr.ndim != 2 or arr.shape[1] < 3 or arr.dtype.kind not in "fiu":
        _fail(path, f"expected a numeric (n, 3) array, found shape {arr.shape} dtype {arr.dtype}",
              "save an (n, 3) float array with numpy.save")
    return np.ascontiguousarray(arr[:, :3], dtype=np.float64)


# --------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------

_MESH_READERS = {".obj": _read_obj, ".off": _read_off, ".stl": _read_stl}


def read_mesh(path, *, merge_tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh from OBJ, OFF, STL or PLY (optionally gzip-compressed).

    Parameters
    ----------
    path : str or os.PathLike
        File name. The format comes from the suffix (case-insensitive), after removing a
        trailing ``.gz``: ``.obj``, ``.off``, ``.stl``, ``.ply``.

    Returns
    -------
    vertices : ndarray, float64, shape (n, 3)
    faces : ndarray, int64, shape (m, 3)
        0-based vertex indices. Polygons are fan-triangulated, so ``m`` can exceed the
        number of polygons in the file. A file with vertices but no faces (a PLY point
        cloud, an OBJ with only ``v`` lines) gives ``m == 0``.
    merge_tol : float, default 1e-9
        STL only: after merging bit-identical corners, also merge vertices closer than
        ``merge_tol`` times the bounding-box diagonal (transitively). CAD exporters
        write e.g. ``3.8e-33`` for some copies of ``0.0``; without this, such meshes
        get cracks along those vertices. ``0`` merges bit-identical corners only.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    tiledsimplify.errors.FileFormatError
        Unknown suffix, or content that does not follow the format.

    Notes
    -----
    * OBJ: ``v`` and ``f`` lines only; face tokens ``v``, ``v/vt``, ``v//vn``, ``v/vt/vn``;
      negative (relative) indices are supported. Other statements are ignored.
    * OFF: ``OFF``/``COFF``/``NOFF``/``STOFF`` headers, ``#`` comments, colours after the
      coordinates or indices are ignored.
    * STL: binary (recognised by its exact size, even when the header starts with
      ``solid``) or ASCII. STL stores three corners per facet; bit-identical corners are
      merged (``-0.0`` equals ``0.0``), then corners within ``merge_tol`` (see above).
      Vertices keep first-occurrence order; facets that collapse after merging are kept.
    * PLY: ascii, binary_little_endian, binary_big_endian; any extra vertex properties or
      extra elements; face list property ``vertex_indices`` or ``vertex_index`` with any
      integer count/index types. Binary elements with a constant list length are decoded
      with a numpy structured dtype; other cases are walked row by row.
    """
    path, data, suffix = _load(path)
    if suffix == ".ply":
        return _read_ply(path, data, want_faces=True)
    if suffix == ".stl":
        return _read_stl(path, data, merge_tol=merge_tol)
    reader = _MESH_READERS.get(suffix)
    if reader is None:
        _fail(path, f"unsupported mesh file type {suffix or '(no suffix)'!r}",
              f"use one of {', '.join(MESH_SUFFIXES)} (optionally with .gz)")
    return reader(path, data)


def read_ply_vertices(path) -> np.ndarray:
    """Every scalar property of a PLY file's vertices (optionally gzip-compressed), as a
    structured array: x, y, z and the rest, each of its own type (the Stanford Bunny's
    ``confidence`` and ``intensity``, a scan's colour). Other elements (faces, a range grid)
    are skipped."""
    path, data, suffix = _load(path)
    if suffix != ".ply":
        _fail(path, f"not a PLY file ({suffix or 'no suffix'})", "give a .ply or .ply.gz file")
    return _read_ply(path, data, want_faces=False, all_props=True)[0]


def read_points(path) -> np.ndarray:
    """Read the 3-D points of a point or mesh file (optionally gzip-compressed).

    Parameters
    ----------
    path : str or os.PathLike
        ``.ply`` (vertex x, y, z; faces and any other elements such as ``range_grid`` are
        skipped), ``.xyz``/``.csv``/``.txt``/``.pts``/``.asc`` (text, one point per line,
        whitespace, comma or semicolon separated, first three columns used, one optional
        header line, ``#`` comments), ``.npy`` ((n, >=3) array, or a structured array
        with x, y, z fields), ``.npz`` (array ``points`` or the only array), or a mesh
        (``.obj``, ``.off``, ``.stl``: its vertices).

    Returns
    -------
    points : ndarray, float64, shape (n, 3)

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    tiledsimplify.errors.FileFormatError
        Unknown suffix, or content that does not follow the format.

    Notes
    -----
    Non-finite coordinates are returned as they are; filter them if needed.
    """
    path, data, suffix = _load(path)
    if suffix == ".ply":
        return _read_ply(path, data, want_faces=False)[0]
    if suffix in (".xyz", ".csv", ".txt", ".pts", ".asc"):
        return _read_text_points(path, data)
    if suffix in (".npy", ".npz"):
        return _read_npy_points(path, data, suffix)
    if suffix in (".obj", ".off"):
        return _MESH_READERS[suffix](path, data, want_faces=False)[0]
    if suffix == ".stl":
        return _read_stl(path, data)[0]
    _fail(path, f"unsupported point file type {suffix or '(no suffix)'!r}",
          f"use one of {', '.join(MESH_SUFFIXES + POINT_SUFFIXES)} (optionally with .gz)")
