"""Writing simplified points: NPY (structured), PLY (binary) and XYZ/CSV text.

Every writer goes to a temporary file beside the target and renames it at the end, so a failed
run never leaves a half-written output under the requested name. :class:`PointsAt` writes
record by record at given positions (memory-mapped), so a tiled run writes its output in input
order one tile at a time.
"""

import contextlib
import errno
import os
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError

SUFFIXES = (".npy", ".ply", ".xyz", ".txt", ".csv")


def check_space(path, need, what="the output", fix="write elsewhere", name=None):
    """Fail now, not after the work, if the directory of ``path`` has less than ``need``
    bytes free (a lower bound of what ``what`` will take there); the error starts with
    ``name``, else ``path``."""
    path = Path(path)
    where = existing_parent(path)
    free = shutil.disk_usage(where).free
    if free < need:
        raise InputError(f"{name or path}: {what} needs at least {_size(need)} but {where} "
                         f"has {_size(free)} free; free disk space or {fix}.")


def existing_parent(path):
    """The nearest existing directory above ``path`` (where it would be made)."""
    where = Path(path).absolute().parent
    while not where.exists() and where != where.parent:
        where = where.parent
    return where


def _size(n):
    return f"{n / 2**20:,.1f} MB" if n >= 2**20 else f"{n / 2**10:,.0f} KB"


def record_bytes(dtypes):
    """Bytes of one output record with these columns after x, y, z (NPY and PLY: exactly;
    text: its fixed-size records, written before the lines)."""
    return _fields(dtypes).itemsize


#: the LAS colour dimensions, which the tile store and the sources carry 16-bit; a points
#: file gets them 8-bit (:func:`colour_8bit`), as PLY and text readers expect colour
COLOURS = ("red", "green", "blue")

_UNSAFE = re.compile(r"[^A-Za-z0-9_.\-]")


def safe_name(name):
    """``name`` as a column or store key takes it: letters, digits, ``_ . -`` (others become
    ``_``), starting with a letter, digit or ``_``; None if it cannot."""
    name = _UNSAFE.sub("_", str(name))
    return name if name[:1].isalnum() or name[:1] == "_" else None


def _is_colour(name, dtype):
    """A LAS colour dimension as the store and the sources carry it: 16-bit ``red``,
    ``green`` or ``blue`` (a lone ``red`` of another type, a PLY's, is written as it is)."""
    return name in COLOURS and np.dtype(dtype) == np.uint16


def colour_8bit(values, colour_max=None):
    """16-bit LAS colour as 8 bits: ``v >> 8``, so 8-bit colour read as 257 v (a PLY's, an
    E57's) or written as 256 v (many LAS writers) comes back as v. Where no colour value of
    the input exceeds 255 (``colour_max``), the input held 8-bit values in 16-bit fields, as
    some LAS writers do: kept as they are."""
    v = np.asarray(values)
    if colour_max is not None and colour_max <= 255:
        return v.astype(np.uint8)
    return (v.astype(np.uint16) >> 8).astype(np.uint8)


def _attribute_names(name, trail):
    """The columns of one attribute: its name (letters, digits, ``_ . -``: a PLY property
    or a header word), one per element (``name_0``...) if it has a trailing shape."""
    name = safe_name(name) or "_"
    size = int(np.prod(tuple(trail), dtype=np.int64))
    return [name] if not tuple(trail) else [f"{name}_{i}" for i in range(size)]


#: the integer types a column typed by guess (a text file's, read as float64) whose values
#: are all whole numbers is written as, the first that holds them: PLY has no 64-bit integers,
#: so a column beyond int32 stays float64
WHOLE_TYPES = tuple(np.dtype(t) for t in ("u1", "i1", "u2", "i2", "u4", "i4"))


def whole_type(lo, hi, types=WHOLE_TYPES):
    """The first of ``types`` (integer dtypes) that holds ``lo .. hi``, or None."""
    for t in types:
        info = np.iinfo(t)
        if info.min <= lo and hi <= info.max:
            return t
    return None


def whole_dtypes(dtypes, stats, guessed):
    """``dtypes`` (column -> dtype) with each float column named in ``guessed`` (the input's
    columns typed by guess, ``TextSource.guessed``) whose values are all whole numbers as
    :func:`whole_type` of its range. ``stats``: name -> ``(least, largest, whole)`` over the
    whole input (:attr:`~tiledsimplify.tiles.store.TileStore.attribute_stats`, or
    :func:`~tiledsimplify.tiles.ingest.value_stats` of the values held in memory)."""
    out = dict(dtypes)
    for name in guessed:
        lo, hi, whole = stats.get(name, (None, None, False))
        if name in out and out[name].kind == "f" and whole and lo is not None:
            out[name] = whole_type(lo, hi) or out[name]
    return out


def attribute_dtypes(spec, reserved=()):
    """The columns (name -> dtype) a points file gets from the input's per-point attributes,
    given as ``{name: (dtype, trailing shape)}``: the columns :func:`attribute_columns` makes.
    Attributes named in ``reserved`` (x, y, z, the simplifier's own columns: an input
    simplified before carries its old ones) are left out; bool becomes uint8."""
    empty = {name: np.empty((0,) + tuple(trail), dtype=dtype)
             for name, (dtype, trail) in spec.items()}
    return {col: v.dtype for col, v in attribute_columns(empty, reserved=reserved).items()}


def attribute_columns(attrs, colour_max=None, reserved=()):
    """The columns (name -> (n,) array) a points file gets from per-point attributes
    ``attrs`` (name -> (n, ...) array): each as it is, colour 8-bit (:func:`colour_8bit`),
    one column per element of a trailing shape (:func:`attribute_dtypes` gives their
    dtypes)."""
    out = {}
    for name, values in attrs.items():
        if name in reserved or name in ("x", "y", "z"):
            continue
        v = np.asarray(values)
        if _is_colour(name, v.dtype):
            v = colour_8bit(v, colour_max)
        elif v.dtype == bool:
            v = v.astype(np.uint8)
        cols = _attribute_names(name, v.shape[1:])
        flat = v.reshape(len(v), len(cols))
        for i, col in enumerate(cols):
            out[col] = flat[:, i]
    return out


def largest_colour(attrs):
    """The largest colour value in ``attrs`` (:data:`COLOURS`), None if it has no colour."""
    found = [np.asarray(attrs[c]) for c in COLOURS if c in attrs]
    if not found:
        return None
    return max((int(v.max()) for v in found if v.size), default=0)


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


def check_not_input(path, inputs):
    """Refuse an output that is one of the ``inputs`` files — the same name in the same
    directory, however spelled (``..``, a linked directory): the finished output would replace
    the input (another name of the file, a link, keeps it: only that name is replaced).
    Raises :class:`InputError` naming both."""
    path = Path(path)
    for f in inputs:
        f = Path(f)
        if path.name != f.name:
            continue
        try:
            same = os.path.samefile(path.absolute().parent, f.absolute().parent)
        except OSError:  # a directory missing: not the same
            same = False
        if same:
            raise InputError(f"{path}: is the input file {f}; the output would replace it at "
                             "the end of the run. Write the output to another file.")


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
    why = cannot_write_in(directory)
    if why:
        raise InputError(f"{path}: the output directory {directory} is not writable ({why}); "
                         "choose a directory you can write to.")


def cannot_write_in(directory):
    """Why no file can be made in ``directory`` (the OS's words), or None: its permissions
    are asked, then a file is made and removed there. ``os.access`` alone says yes to root (a
    container's usual user) where the write then fails — a read-only or SELinux-labelled bind
    mount, an immutable directory, /proc — and the run failed only at its end, exit 1."""
    if not os.access(directory, os.W_OK | os.X_OK):
        return "permission denied"
    try:
        fd, probe = tempfile.mkstemp(dir=directory, prefix=".tiledsimplify.", suffix=".probe")
    except OSError as exc:
        return (exc.strerror or str(exc)).lower()
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)
    return None


def _fields(dtypes):
    """The records' dtype: x, y, z (little-endian float64), then one field per column."""
    return np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
                    + [(name, np.dtype(d).newbyteorder("<").str) for name, d in dtypes.items()])


def _table(xyz, columns):
    n = len(xyz)
    values = {name: np.asarray(v) for name, v in columns.items()}
    for name, v in values.items():
        if v.shape != (n,):
            raise ValueError(f"column {name!r} has shape {v.shape}, expected ({n},)")
    table = np.empty(n, dtype=_fields({name: v.dtype for name, v in values.items()}))
    table["x"], table["y"], table["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    for name, v in values.items():
        table[name] = v
    return table


_PLY_TYPES = {"f8": "double", "f4": "float", "i8": "int64", "i4": "int", "u1": "uchar",
              "b1": "uchar", "i2": "short", "u2": "ushort", "u4": "uint", "i1": "char"}


def _ply_layout(dtype, n):
    """The PLY header for ``n`` records of ``dtype`` and the dtype of its binary records."""
    props = []
    cast = []
    for name in dtype.names:
        kind = dtype[name].str[1:]
        if kind == "i8":  # int64 is not a standard PLY type: store as int32
            cast.append((name, "<i4"))
            props.append(f"property int {name}")
        else:
            cast.append((name, "<" + ("u1" if kind == "b1" else kind)))
            props.append(f"property {_PLY_TYPES[kind]} {name}")
    header = ["ply", "format binary_little_endian 1.0", "comment written by tiledsimplify",
              f"element vertex {n}", *props, "end_header"]
    return ("\n".join(header) + "\n").encode("ascii"), np.dtype(cast)


def _write_ply(fh, table):
    header, cast = _ply_layout(table.dtype, len(table))
    out = np.empty(len(table), dtype=cast)
    for name in cast.names:
        out[name] = table[name]
    fh.write(header)
    fh.write(out.tobytes())


#: rows formatted as text at once (:func:`_write_text`): ~2 MB of Python floats a column
TEXT_BLOCK = 1 << 16


#: the significant digits that give a float32 or float16 back exactly
_DIGITS = {2: 5, 4: 9}


def _text_format(dtype):
    """How :func:`_write_text` writes a column of ``dtype``: integers (and bools) as
    integers, exactly (int64 and uint64 too); float64 by Python's ``repr``, the shortest text
    that gives the value back exactly (a LAS coordinate ``0.5396``, not ``%.17g``'s
    ``0.53960000000000008``), as integers where a block's are whole (:func:`_whole`);
    float32 and float16 with the digits that give them back (the normals: ``0.300000012``,
    not ``0.30000001192092896``)."""
    if dtype.kind in "biu":
        return "%d"
    if dtype.kind == "f" and dtype.itemsize in _DIGITS:
        return f"%.{_DIGITS[dtype.itemsize]}g"
    return "%r"


def _write_text(fh, table, sep, header=True):
    """``table``'s rows as text lines, each column as :func:`_text_format` says, formatted as
    Python numbers a block at a time (each column's own: no int64 goes through a float), not
    as NumPy scalars row by row as ``np.savetxt`` did (200k rows of x, y, z, an integer and
    a float32, best of 3: 0.87 against 1.17 s for full-precision coordinates, 0.54 against
    0.90 s for coordinates of four decimals)."""
    names = table.dtype.names
    if header:
        fh.write((sep.join(names) + "\n").encode())
    for start in range(0, len(table), TEXT_BLOCK):
        block = table[start:start + TEXT_BLOCK]
        line = sep.join(_whole(block[n], _text_format(table.dtype[n])) for n in names) + "\n"
        rows = zip(*(block[n].tolist() for n in names))
        fh.write("".join(map(line.__mod__, rows)).encode())


def _whole(values, fmt):
    """``%d`` for a float64 column whose values in this block are all whole numbers below
    2**53 and not -0 (a text file's integer columns, read as float64: ``123``, not
    ``123.0``), else ``fmt``."""
    if fmt != "%r" or not values.size:
        return fmt
    with np.errstate(invalid="ignore"):
        whole = bool((np.floor(values) == values).all() and (np.abs(values) < 2**53).all())
    return "%d" if whole and not np.signbit(values[values == 0]).any() else fmt


def publish(tmp, path):
    """Rename the finished temporary file ``tmp`` to ``path``, with the permissions a new file
    gets (``0o666`` less the umask): ``mkstemp`` makes it readable by its owner alone, and an
    output a pipeline writes for others must not stay so."""
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(tmp, 0o666 & ~mask)
    os.replace(tmp, path)


def write_failed(path, detail, code=None):
    """The OSError for an output whose write failed (a full disk, mostly; writers report it
    in their own words, ``detail``): names ``path`` and the fix; ``errno`` ``code``, EIO if
    none. Every writer raises it, so the command line exits 1 for all of them."""
    return OSError(code if code is not None else errno.EIO,
                   f"writing the output failed ({detail}); check that {Path(path).parent} has "
                   "free space, or write elsewhere", str(path))


@contextlib.contextmanager
def _temporary(path):
    """A temporary file beside ``path`` (yields its open binary handle and its name), renamed
    to ``path`` when the block ends; removed instead on any failure, so ``path`` is never half
    written."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
    try:
        try:
            with os.fdopen(fd, "wb") as fh:
                yield fh, tmp
        except OSError as e:  # numpy's short write says "N requested and M written", no file
            raise write_failed(path, str(e), e.errno) from e
        publish(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _replace(path, write):
    """Call ``write(fh)`` on a temporary file beside ``path``, then rename it to ``path``
    (:func:`_temporary`)."""
    with _temporary(path) as (fh, _):
        write(fh)


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


def _reserve(fh, offset, size, path):
    """Extend the file to ``offset + size`` bytes with its disk space allocated now: a full
    disk is then an error here, naming the output, not a SIGBUS on a mapped write later."""
    fh.truncate(offset + size)
    if size and hasattr(os, "posix_fallocate"):
        try:
            os.posix_fallocate(fh.fileno(), offset, size)
        except OSError as e:
            if e.errno in (errno.EOPNOTSUPP, errno.EINVAL):  # the file system cannot: as is
                return
            raise InputError(f"{path}: cannot reserve {_size(size)} for the output "
                             f"({e.strerror}); free disk space or write elsewhere.") from e


#: records formatted per chunk when :class:`PointsAt` writes text at the end
TEXT_CHUNK = 1 << 20


class PointsAt:
    """A points file of ``n`` records written record by record at given positions.

    The same bytes as :func:`write_points` on the points in position order, but a caller
    holds only the block it writes: NPY and binary PLY records go straight to a
    memory-mapped temporary file (renamed to ``path`` when the ``with`` block ends, removed
    on failure); for XYZ/CSV text, whose lines vary in length, the records go to a temporary
    file of fixed-size records first and are formatted, :data:`TEXT_CHUNK` at a time, at the
    end::

        with PointsAt("out.ply", n, {"sharp_edge": np.uint8}) as out:
            out.write(positions, xyz, {"sharp_edge": flags})   # any order, each position once

    Parameters
    ----------
    path : str or Path
        Any suffix :func:`write_points` writes (:data:`SUFFIXES`).
    n : int
        Number of records.
    dtypes : dict of name -> dtype
        The columns after x, y, z, in order.
    progress : callable, optional
        ``progress(records)`` after each :data:`TEXT_CHUNK` records formatted as text.
    """

    def __init__(self, path, n, dtypes, progress=None):
        self.path = Path(path)
        self.suffix = _check_suffix(self.path, SUFFIXES)
        self.n = int(n)
        self.progress = progress
        self.dtype = _fields(dtypes)
        self._stack = None
        self._records = None

    def __enter__(self):
        stack = contextlib.ExitStack()
        try:
            if self.suffix in (".npy", ".ply"):
                fh, tmp = stack.enter_context(_temporary(self.path))
                if self.suffix == ".npy":
                    header = {"descr": np.lib.format.dtype_to_descr(self.dtype),
                              "fortran_order": False, "shape": (self.n,)}
                    np.lib.format.write_array_header_1_0(fh, header)
                    dtype = self.dtype
                else:
                    head, dtype = _ply_layout(self.dtype, self.n)
                    fh.write(head)
            else:  # text: fixed-size records now, lines at the end
                fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".records",
                                           dir=self.path.parent)
                stack.callback(os.unlink, tmp)
                fh = stack.enter_context(os.fdopen(fd, "wb"))
                dtype = self.dtype
            fh.flush()
            offset = fh.tell()
            _reserve(fh, offset, self.n * dtype.itemsize, self.path)
            if self.n:
                self._records = np.memmap(tmp, dtype=dtype, mode="r+", offset=offset,
                                          shape=(self.n,))
        except BaseException as e:  # the temporary file goes, not renamed: pass the error on
            stack.__exit__(type(e), e, e.__traceback__)
            raise
        self._stack = stack
        return self

    def write(self, positions, xyz, columns):
        """Write points ``xyz`` with their ``columns`` at record ``positions``."""
        xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        positions = np.asarray(positions, dtype=np.int64)
        if len(positions) != len(xyz):
            raise ValueError(f"{len(positions)} positions for {len(xyz)} points")
        if not len(xyz):
            return
        block = np.empty(len(xyz), dtype=self._records.dtype)
        block["x"], block["y"], block["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        for name in self.dtype.names[3:]:
            block[name] = columns[name]
        self._records[positions] = block

    def _format_text(self):
        records = self._records if self._records is not None else np.empty(0, self.dtype)
        sep = "," if self.suffix == ".csv" else " "
        with _temporary(self.path) as (fh, _):
            fh.write((sep.join(self.dtype.names) + "\n").encode())
            for start in range(0, self.n, TEXT_CHUNK):
                _write_text(fh, np.asarray(records[start:start + TEXT_CHUNK]), sep, header=False)
                if self.progress is not None:
                    self.progress(min(start + TEXT_CHUNK, self.n))

    def __exit__(self, kind, value, tb):
        try:
            if self._records is not None and kind is None:
                self._records.flush()
            if kind is None and self.suffix not in (".npy", ".ply"):
                self._format_text()
            self._records = None  # its map closes with its last reference
        except BaseException as e:
            self._records = None
            stack, self._stack = self._stack, None
            stack.__exit__(type(e), e, e.__traceback__)
            raise
        stack, self._stack = self._stack, None
        stack.__exit__(kind, value, tb)
        return False
