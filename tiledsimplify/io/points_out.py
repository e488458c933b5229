"""Writing simplified points: NPY (structured), PLY (binary) and XYZ/CSV text.

Every writer goes to a temporary file beside the target and renames it at the end, so a failed
run never leaves a half-written output under the requested name.
"""

import os
import tempfile
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError

SUFFIXES = (".npy", ".ply", ".xyz", ".txt", ".csv")


def _check_suffix(path, known):
    suffix = path.suffix.lower()
    if suffix not in known:
        raise FileFormatError(f"{path}: cannot write '{suffix}' files; use one of "
                              f"{', '.join(known)}.")
    return suffix


def check_output(path, extra_suffixes=()):
    """Fail now, not after the work, if ``path`` cannot be written.

    Checks what the writers would only find at the end of a run: ``path`` is not a
    directory, its suffix is one they write (:data:`SUFFIXES`, plus ``extra_suffixes``), and
    its directory exists and is writable (the output is written beside it and renamed).
    Raises :class:`FileFormatError` or :class:`InputError` naming the path and the fix.
    """
    check_writable(path)
    _check_suffix(Path(path), SUFFIXES + tuple(extra_suffixes))


def check_writable(path):
    """:func:`check_output` without the suffix: ``path`` is not a directory and its
    directory exists and is writable."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a directory; give a file name for the output.")
    directory = path.parent  # Path("out.ply").parent is Path(".")
    if not directory.is_dir():
        raise InputError(f"{path}: the output directory {directory} does not exist; create it "
                         "or write somewhere else.")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise InputError(f"{path}: the output directory {directory} is not writable; choose "
                         "a directory you can write to.")


def _table(xyz, columns):
    n = len(xyz)
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    for name, values in columns.items():
        values = np.asarray(values)
        if values.shape != (n,):
            raise ValueError(f"column {name!r} has shape {values.shape}, expected ({n},)")
        fields.append((name, values.dtype.newbyteorder("<").str))
    table = np.empty(n, dtype=fields)
    table["x"], table["y"], table["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    for name, values in columns.items():
        table[name] = values
    return table


_PLY_TYPES = {"f8": "double", "f4": "float", "i8": "int64", "i4": "int", "u1": "uchar",
              "b1": "uchar", "i2": "short", "u2": "ushort", "u4": "uint", "i1": "char"}


def _write_ply(fh, table):
    props = []
    cast = []
    for name in table.dtype.names:
        kind = table.dtype[name].str[1:]
        if kind == "i8":  # int64 is not a standard PLY type: store as int32
            cast.append((name, "<i4"))
            props.append(f"property int {name}")
        else:
            cast.append((name, "<" + ("u1" if kind == "b1" else kind)))
            props.append(f"property {_PLY_TYPES[kind]} {name}")
    out = np.empty(len(table), dtype=cast)
    for name, _ in cast:
        out[name] = table[name]
    header = ["ply", "format binary_little_endian 1.0", "comment written by tiledsimplify",
              f"element vertex {len(table)}", *props, "end_header"]
    fh.write(("\n".join(header) + "\n").encode("ascii"))
    fh.write(out.tobytes())


def _write_text(fh, table, sep):
    names = table.dtype.names
    fh.write((sep.join(names) + "\n").encode())
    cols = [table[n].astype(np.int64) if table.dtype[n].kind in "bi" else table[n]
            for n in names]
    fmt = sep.join("%d" if c.dtype.kind == "i" else "%.17g" for c in cols)
    np.savetxt(fh, np.column_stack(cols), fmt=fmt)


def _replace(path, write):
    """Call ``write(fh)`` on a temporary file beside ``path``, then rename it to ``path``; on
    any failure remove it, so ``path`` is never half written."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write_json(path, obj):
    """``obj`` as indented JSON (values JSON lacks as strings), written as :func:`_replace`
    writes: a reader never sees half a file."""
    import json
    text = json.dumps(obj, indent=2, default=str) + "\n"
    _replace(Path(path), lambda fh: fh.write(text.encode()))


def write_points(path, xyz, columns=None):
    """Write points and per-point columns to ``path``; the format follows the suffix.

    Parameters
    ----------
    path : str or Path
        ``.npy`` (a structured array with fields x, y, z and one per column), ``.ply`` (binary
        little-endian, one vertex property per column), ``.xyz``/``.txt`` (space separated, with
        a header line) or ``.csv``.
    xyz : (n, 3) array
    columns : dict of name -> (n,) array, optional
    """
    path = Path(path)
    suffix = _check_suffix(path, SUFFIXES)
    table = _table(np.asarray(xyz, dtype=np.float64).reshape(-1, 3), columns or {})

    def write(fh):
        if suffix == ".npy":
            np.save(fh, table)
        elif suffix == ".ply":
            _write_ply(fh, table)
        else:
            _write_text(fh, table, "," if suffix == ".csv" else " ")
    _replace(path, write)
