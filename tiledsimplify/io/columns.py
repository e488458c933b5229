"""Reading points together with their per-point columns (``sharp_edge``, ``simplify_rank``...).

The writers of this package put per-point columns into every output (LAS/LAZ extra dimensions,
PLY vertex properties, NPY structured fields, a header line in XYZ/CSV). :func:`read_columns`
reads them back, e.g. for the report of a finished run. Formats without named columns (meshes,
plain text without a header) give coordinates only.
"""

from pathlib import Path

import numpy as np

from ..errors import FileFormatError
from .las import LasSource
from .mesh import _PLY_TYPES, _parse_ply_header, read_points
from .sources import TEXT_SUFFIXES, _split_line, _text_header

_XYZ = ("x", "y", "z")


def _ply_columns(path):
    data = path.read_bytes()
    fmt, elements, body_start = _parse_ply_header(path, data)
    if not elements or elements[0].name != "vertex" or any(
            p.is_list for p in elements[0].props):
        return None
    vertex = elements[0]
    names = [p.name for p in vertex.props]
    if fmt == "ascii":
        body = data[body_start:].decode("ascii", errors="replace").split("\n", vertex.count)
        table = (np.loadtxt(body[:vertex.count], ndmin=2) if vertex.count
                 else np.empty((0, len(names))))  # loadtxt gives (0, 1): no column past x
        cols = {name: table[:, i] for i, name in enumerate(names)}
    else:
        endian = "<" if fmt == "binary_little_endian" else ">"
        dtype = np.dtype([(p.name, endian + _PLY_TYPES.get(p.code, p.code))
                          for p in vertex.props])
        if body_start + vertex.count * dtype.itemsize > len(data):
            raise FileFormatError(f"{path}: the PLY vertex data is shorter than its header "
                                  f"says ({vertex.count} vertices); the file is truncated.")
        rec = np.frombuffer(data, dtype=dtype, count=vertex.count, offset=body_start)
        cols = {name: np.array(rec[name]) for name in names}
    return cols


def _split(cols):
    xyz = np.column_stack([np.asarray(cols[a], dtype=np.float64) for a in _XYZ]).reshape(-1, 3)
    return xyz, {k: np.asarray(v) for k, v in cols.items() if k not in _XYZ}


def read_columns(path):
    """Read points and their named per-point columns.

    Parameters
    ----------
    path : str or PathLike
        LAS/LAZ (every dimension but X, Y, Z, incl. extra bytes), PLY (vertex properties),
        NPY (structured fields), XYZ/CSV/TXT with a header line (its names); any other
        point or mesh file gives coordinates only.

    Returns
    -------
    xyz : (n, 3) float64
    columns : dict of str -> (n,) ndarray
        ``sharp_edge``, ``simplify_rank``, ``importance``, ``nx``... as present in the file.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(2, "No such file", str(path))
    suffix = path.suffix.lower()
    if suffix in (".las", ".laz"):
        xyz, attrs = LasSource(path).read_all()
        return xyz, {k: np.asarray(v) for k, v in attrs.items()}
    if suffix == ".ply":
        cols = _ply_columns(path)
        if cols is None or not set(_XYZ) <= set(cols):
            return read_points(path), {}
        return _split(cols)
    if suffix == ".npy":
        arr = np.load(path)
        if arr.dtype.names and set(_XYZ) <= set(arr.dtype.names):
            return _split({name: arr[name] for name in arr.dtype.names})
        return read_points(path), {}
    if suffix in TEXT_SUFFIXES:
        skip, delimiter, header, _ = _text_header(path)
        if header is not None:  # the line before the first point (after any comments)
            names = _split_line(header)
            if set(_XYZ) <= set(names):
                table = np.loadtxt(path, delimiter=delimiter, skiprows=skip, ndmin=2)
                if table.shape[1] == len(names):
                    return _split({name: table[:, i] for i, name in enumerate(names)})
    return read_points(path), {}
