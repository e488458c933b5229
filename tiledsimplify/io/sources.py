"""One way to read any supported input in chunks: ``open_source(spec)``.

LAS/LAZ files, folders and globs stream through :class:`~tiledsimplify.io.las.LasSource`,
E57 files through :class:`~tiledsimplify.io.e57.E57Source` (scan by scan, in chunks). NPY
files and binary PLY files are memory-mapped and sliced; ASCII PLY and XYZ/CSV/TXT text is
parsed a chunk of lines at a time. Memory is bounded by the chunk size in all these cases.
Compressed (``.gz``) point files and meshes (OBJ/OFF/STL) are read whole.
"""

import io
import itertools
from pathlib import Path

import numpy as np

from ..core.bounds import finite_rows
from ..errors import FileFormatError, InputError
from .las import LasSource, las_files, part_ranges
from .mesh import _PLY_TYPES, _parse_ply_header, read_ply_vertices, read_points
from .points_out import safe_name

TEXT_SUFFIXES = (".xyz", ".txt", ".csv", ".pts", ".asc")
#: PLY vertex properties read as the LAS colour dimensions (all three, or none)
PLY_COLOURS = {"red": ("red", "diffuse_red"), "green": ("green", "diffuse_green"),
               "blue": ("blue", "diffuse_blue")}


def ply_colours(names):
    """``{"red": property, "green": …, "blue": …}`` of a PLY vertex's property ``names``, or
    {} unless it has all three."""
    found = {}
    for las, candidates in PLY_COLOURS.items():
        name = next((c for c in candidates if c in names), None)
        if name is None:
            return {}
        found[las] = name
    return found


#: PLY vertex properties a source does not carry: the position, and normals (the
#: simplifier's own replace them in every output)
PLY_SKIP = frozenset({"x", "y", "z", "nx", "ny", "nz"})


def _named(names, skip, seen):
    """``(index, dimension)`` for every name of ``names`` whose index is not in ``skip`` nor
    its lower case in :data:`PLY_SKIP`, the dimension its :func:`~.points_out.safe_name`; a
    name that has none, or one of ``seen`` (dimensions already taken) or of a name before it,
    is left out."""
    seen = set(seen)
    out = []
    for i, name in enumerate(names):
        dim = safe_name(name)
        if i in skip or name.lower() in PLY_SKIP or dim is None or dim in seen:
            continue
        seen.add(dim)
        out.append((i, dim))
    return out


def ply_dimensions(names, codes):
    """What a PLY vertex with properties ``names`` (numpy types ``codes``: a mapping, or the
    structured dtype of its records) carries:
    ``[(dimension, property, code, is_colour)]`` — its colour as the LAS colour dimensions
    (:func:`ply_colours`, 16-bit: :func:`colour_uint16`), every other property but
    :data:`PLY_SKIP` under its own name (letters, digits, ``_ . -``) and type, as a scan's
    ``confidence`` and ``intensity`` (the Stanford Bunny's)."""
    found = ply_colours(names)
    out = [(las, name, codes[name], True) for las, name in found.items()]
    colour = {names.index(name) for name in found.values()}
    return out + [(dim, names[i], codes[names[i]], False)
                  for i, dim in _named(names, colour, found)]


def ply_values(values, code, is_colour):
    """One PLY property's values as a dimension (:func:`ply_dimensions`), native byte order."""
    if is_colour:
        return colour_uint16(values, code)
    return np.asarray(values).astype(np.dtype(code).newbyteorder("="))


def to_uint16(values, span):
    """Values as a LAS 16-bit dimension (intensity, colour): scaled from ``span`` = (lo, hi)
    to 0..65535 (0..255 becomes 257 v exactly), or taken as they are where ``span`` is None;
    rounded and clipped."""
    v = np.asarray(values, dtype=np.float64)
    if span is not None:
        lo, hi = span
        v = (v - lo) * (65535.0 / (hi - lo))
    return np.clip(np.rint(v), 0, 65535).astype(np.uint16)


def colour_uint16(values, code):
    """A PLY colour property of numpy type ``code`` as the LAS 16-bit colour (:func:`to_uint16`
    from 0..255 for 8-bit types, 0..65535 for wider integers, 0..1 for floats)."""
    kind = np.dtype(code)
    span = (0.0, 1.0) if kind.kind == "f" else (0.0, 255.0) if kind.itemsize == 1 else None
    return to_uint16(values, span)


def check_finite(xyz, start, files):
    """``xyz`` (a chunk starting at input row ``start``) if every coordinate is finite; else an
    :class:`InputError` naming the file, the first bad point and how many the chunk holds."""
    bad = ~finite_rows(xyz)
    if bad.any():
        rows = np.flatnonzero(bad)
        name = str(files[0]) if files else "the input"
        more = f" ({rows.size} in points {start}-{start + len(xyz) - 1})" if rows.size > 1 else ""
        raise InputError(f"{name}: point {start + rows[0]} has a NaN or infinite coordinate "
                         f"{tuple(float(v) for v in xyz[rows[0]])}{more}; drop or fix those "
                         "points and run again.")
    return xyz


#: height span over horizontal span above which x, y within ±180, ±90 look like degrees
DEGREES_RATIO = 100.0


def degrees_message(name, lo, hi):
    """A warning's text if ``x`` and ``y`` of the bounds ``lo``, ``hi`` look like degrees of
    longitude and latitude — within ±180 and ±90, and spanning less than a hundredth of the
    height's span (an airborne tile of 0.01° is ~1 km across, its heights tens of metres) —
    else None. Distances in such coordinates mix degrees and metres: the Voronoi neighbours,
    normals and edges would be computed in a space stretched ~100,000 times in height."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    if lo.size != 3 or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        return None
    flat = float(max(hi[0] - lo[0], hi[1] - lo[1]))
    tall = float(hi[2] - lo[2])
    if not (-180 <= lo[0] and hi[0] <= 180 and -90 <= lo[1] and hi[1] <= 90):
        return None
    if not (flat > 0 and tall > DEGREES_RATIO * flat):
        return None
    return (f"{name}: x and y look like degrees of longitude and latitude (x {lo[0]:.6g} .. "
            f"{hi[0]:.6g}, y {lo[1]:.6g} .. {hi[1]:.6g}; z spans {tall / flat:,.0f} times "
            "more): distances would mix degrees and metres, and the simplification would "
            "follow the heights alone. Reproject to a projected CRS first (e.g. `pdal "
            "translate in.laz out.laz reprojection --filters.reprojection.out_srs=EPSG:XXXX`, "
            "a UTM zone).")


class ArraySource:
    """Chunks over an in-memory or memory-mapped (n, 3) array (same interface as LasSource).

    Made by :func:`open_source` over a file it maps (``mapped``: how to map it again), it
    also cuts itself into parts another process can read (:meth:`parts`)."""

    is_las = False

    def __init__(self, xyz, chunk_points=1_000_000, files=(), mapped=None):
        self._xyz = xyz
        self.chunk_points = int(chunk_points)
        self.files = list(files)
        self._mapped = mapped  # (path, offset, dtype, shape) of a memory-mapped file

    @property
    def count(self):
        return int(self._xyz.shape[0])

    def __len__(self):
        return self.count

    @staticmethod
    def _rows(arr, start, stop):
        return np.ascontiguousarray(arr[start:stop, :3], dtype=np.float64)

    @staticmethod
    def _attrs(arr, start, stop):
        return {}

    def chunks(self):
        yield from _array_chunks(self._rows, self._xyz, 0, self.count, self.chunk_points,
                                 self.files, self._attrs)

    def parts(self, max_points=None):
        """Consecutive parts of at most ``max_points`` (whole chunks, at least one; None: one
        part), each mapping the file again where it is read, so they pickle to other
        processes; None if the points are not a mapped file (held in memory: read here)."""
        if self._mapped is None:
            return None
        return [MappedPart(type(self), self._mapped, lo, hi, self.chunk_points, self.files)
                for lo, hi in part_ranges(self.count, max_points, self.chunk_points)]


def _array_chunks(rows, arr, lo, hi, chunk_points, files, attrs):
    """The chunks of ``arr`` (the mapped or held points) from point ``lo`` to ``hi - 1``, at
    multiples of ``chunk_points``; ``rows(arr, start, stop)``: their float64 (m, 3) xyz,
    ``attrs(arr, start, stop)``: the dimensions they carry."""
    for start in range(lo, hi, chunk_points):
        stop = min(start + chunk_points, hi)
        xyz = rows(arr, start, stop)
        yield start, check_finite(xyz, start, files), attrs(arr, start, stop)


class ColumnsSource(ArraySource):
    """Chunks from a memory-mapped structured array with fields x, y, z (binary PLY)."""

    @staticmethod
    def _rows(arr, start, stop):
        part = arr[start:stop]
        return np.stack([part["x"], part["y"], part["z"]], axis=1).astype(np.float64)

    @staticmethod
    def _attrs(arr, start, stop):
        """The dimensions a PLY vertex carries (:func:`ply_dimensions`): colour as the LAS
        colour, the other properties as they are."""
        dims = ply_dimensions(arr.dtype.names, arr.dtype)
        part = arr[start:stop] if dims else None
        return {dim: ply_values(part[name], code, colour)
                for dim, name, code, colour in dims}


class MappedPart:
    """Points ``lo`` to ``hi - 1`` of a memory-mapped NPY or binary PLY file, read as its
    source's chunks; holds the file's path and layout, not its points, so it pickles."""

    def __init__(self, kind, mapped, lo, hi, chunk_points, files):
        self.kind, self.mapped = kind, mapped
        self.lo, self.hi = int(lo), int(hi)
        self.chunk_points = int(chunk_points)
        self.files = list(files)

    def __call__(self):
        return self.chunks()

    def __repr__(self):
        return f"MappedPart({Path(self.mapped[0]).name}, points {self.lo}..{self.hi - 1})"

    def chunks(self):
        path, offset, dtype, shape = self.mapped
        arr = np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=shape)
        yield from _array_chunks(self.kind._rows, arr, self.lo, self.hi, self.chunk_points,
                                 self.files, self.kind._attrs)


class TextSource:
    """Chunks of an ASCII point file (XYZ/CSV/TXT, or the vertex block of an ASCII PLY).

    ``offsets[k]``: the byte where chunk ``k``'s first line starts (found by the scan that
    opened the file, :func:`_scan_lines` or :func:`_scan_points`), so a part starts reading
    there; ``lines[k]``: that line's index in the file (0 = the first line), and one more
    entry, the line after the last point (default: ``skip_lines + k * chunk_points``, a file
    without blank or comment lines). ``guessed``: the dimensions whose type was guessed (a
    text file's columns, read as float64; not an ASCII PLY's declared ones), which outputs
    write as integers where all their values are whole numbers
    (:func:`.points_out.whole_dtypes`)."""

    is_las = False

    def __init__(self, path, chunk_points, *, skip_lines, count, delimiter, offsets,
                 dims=None, lines=None, xyz=(0, 1, 2), guessed=()):
        self.files = [Path(path)]
        self.chunk_points = int(chunk_points)
        self._skip = skip_lines
        self._count = int(count)
        self._delimiter = delimiter
        self._offsets = list(offsets)
        if lines is None:  # no blank or comment lines: point k on line skip_lines + k
            lines = [skip_lines + k * self.chunk_points for k in range(len(self._offsets))]
            lines.append(skip_lines + self._count)
        self._lines = list(lines)  # and, last, the line after the last point
        self._dims = dims  # ((column, dimension, type, is colour), ...): text_columns
        self._xyz = tuple(xyz)  # the columns of x, y, z
        self.guessed = tuple(guessed)

    @property
    def count(self):
        return self._count

    def __len__(self):
        return self._count

    def chunks(self):
        for part in self.parts():
            yield from part.chunks()

    def parts(self, max_points=None):
        """Consecutive parts of at most ``max_points`` lines (whole chunks, at least one;
        None: one part), each reading from the byte offset of its first line, so they pickle
        and read independently."""
        path = self.files[0].absolute()
        c = self.chunk_points
        return [TextPart(path, self._offsets[lo // c], lo, hi, c,
                         self._lines[lo // c:-(-hi // c) + 1],
                         self._delimiter, self._count, self._dims, self._xyz)
                for lo, hi in part_ranges(self._count, max_points, c)]


def _scan_lines(path, first, every, count):
    """One pass over ``path``: ``(newlines, last byte, offsets)``, ``offsets[k]`` the byte where
    line ``first + k * every`` starts (line ``L`` starts after the ``L``-th newline) for the
    ``ceil(count / every)`` chunks of ``count`` lines from line ``first`` — the file's size
    where it is shorter (a truncated file then fails where it is read). Stops reading once
    those are found if ``count`` is known, else (None) reads to the end, counting newlines
    for all chunk starts found."""
    need = None if count is None else -(-count // every)
    offsets = []
    target = first  # the next line whose start is wanted
    seen = pos = 0  # newlines and bytes before the current block
    last = b""
    with open(path, "rb") as fh:
        if target == 0:
            offsets.append(0)
            target += every
        for block in iter(lambda: fh.read(1 << 22), b""):
            if need is not None and len(offsets) >= need:
                break
            nl = block.count(b"\n")
            if target <= seen + nl:
                where = np.flatnonzero(np.frombuffer(block, dtype=np.uint8) == 10)
                while target <= seen + nl:
                    offsets.append(pos + int(where[target - seen - 1]) + 1)
                    target += every
            seen += nl
            pos += len(block)
            last = block[-1:]
    if need is not None:
        offsets = offsets[:need] + [pos] * (need - len(offsets))
    return seen, last, offsets


class TextPart:
    """Points ``lo`` to ``hi - 1`` of a text point file, read as its :class:`TextSource`'s
    chunks from byte ``offset``, where point ``lo`` starts; ``lines``: the file's line index
    (0-based) of each chunk's first point, and then of the line after the part's last point
    (line numbers for errors, and where blank or ``#`` comment lines lie between: a chunk of
    ``m`` points on ``m`` lines is read as it is, else its lines are filtered by
    :func:`_is_point_line`, as :func:`_scan_points` counted them); pickles."""

    def __init__(self, path, offset, lo, hi, chunk_points, lines, delimiter, count,
                 dims=None, xyz=(0, 1, 2)):
        self.path, self.offset = Path(path), int(offset)
        self.lo, self.hi = int(lo), int(hi)
        self.chunk_points, self.lines = int(chunk_points), [int(v) for v in lines]
        self.delimiter, self.count = delimiter, int(count)
        self.dims = dims
        self.xyz = tuple(xyz)

    def __call__(self):
        return self.chunks()

    def __repr__(self):
        return f"TextPart({self.path.name}, points {self.lo}..{self.hi - 1})"

    def chunks(self):
        path, start = self.path, self.lo
        with open(path, "rb") as raw:
            raw.seek(self.offset)
            fh = io.TextIOWrapper(raw, encoding="ascii", errors="replace")
            for j in itertools.count():
                if start >= self.hi:
                    break
                m = min(self.chunk_points, self.hi - start)
                first, span = self.lines[j], self.lines[j + 1] - self.lines[j]
                lines = list(itertools.islice(fh, span))
                numbers = None  # line k of the chunk is the file's line first + k
                if span != m:  # blank or comment lines among them
                    numbers = [first + k for k, line in enumerate(lines) if _is_point_line(line)]
                    lines = [line for line in lines if _is_point_line(line)]
                if len(lines) < m:
                    raise FileFormatError(f"{path}: expected {self.count} points but the file "
                                          f"ends after {start + len(lines)}; it is truncated.")
                cols = self.xyz + tuple(c for c, _, _, _ in (self.dims or ()))
                try:
                    got = np.loadtxt(lines[:m], delimiter=self.delimiter, usecols=cols,
                                     dtype=np.float64, ndmin=2)
                except ValueError as exc:
                    i, text, why = _first_bad_line(lines[:m], self.delimiter)
                    line = 0 if i is None else first + i if numbers is None else numbers[i]
                    where = (f"line {line + 1} (point {start + i}): "
                             f"{text.strip()[:80]!r} ({why})" if i is not None
                             else f"the block of points from {start} ({exc})")
                    comma = (" (decimal commas are not read: export with a decimal point)"
                             if text is not None and "," in text and ";" in text else "")
                    raise FileFormatError(f"{path}: unreadable point line at {where}; "
                                          f"each line needs three numbers x y z{comma}; fix or "
                                          "remove it.") from None
                if len(got) != m:  # a line numpy skips that _is_point_line does not
                    raise FileFormatError(f"{path}: {m - len(got)} of the lines {first + 1} to "
                                          f"{first + span} hold no point; remove them.")
                xyz = np.ascontiguousarray(got[:, :3])
                attrs = {dim: ply_values(got[:, 3 + j], code, colour)
                         for j, (_, dim, code, colour) in enumerate(self.dims or ())}
                bad = np.flatnonzero(~finite_rows(xyz))
                if bad.size:  # "nan" and "inf" parse: name the line, as for a bad one
                    i = int(bad[0])
                    line = first + i if numbers is None else numbers[i]
                    raise InputError(f"{path}: line {line + 1} (point {start + i}) has a NaN or "
                                     f"infinite coordinate: {lines[i].strip()[:80]!r}"
                                     + (f" ({bad.size} such lines in lines {first + 1} to "
                                        f"{first + span})" if bad.size > 1 else "")
                                     + "; drop or fix those lines and run again.")
                yield start, xyz, attrs
                start += m


def _is_point_line(line):
    """A line of a text point file that holds a point: not blank, not a ``#`` comment. What
    :func:`_scan_points` counts, byte-wise (the same characters are whitespace: ASCII's)."""
    s = line.lstrip()
    return bool(s) and s[0] != "#"


#: the bytes str.isspace() takes for whitespace in ASCII (a line of only these is blank)
_BLANK = np.zeros(256, dtype=bool)
_BLANK[[9, 10, 11, 12, 13, 28, 29, 30, 31, 32]] = True


def _scan_points(path, first, every):
    """One pass over a text point file: ``(count, offsets, lines)``, ``count`` its point lines
    after its first ``first`` lines (a header): lines neither blank nor a ``#`` comment
    (:func:`_is_point_line`, which the reader skips the same way; a file's blank last lines
    are common); ``offsets[k]`` the byte and ``lines[k]`` the line index (0-based) where point
    ``k * every`` starts, and ``lines[-1]`` the line after the last point. Counting newlines
    alone counted blank and comment lines as points, and the reader, which skips them, then
    found fewer points than the count."""
    count = line_no = base = 0  # points and lines before ``buf``, its first byte in the file
    offsets, lines, after = [], [], first
    carry = b""
    with open(path, "rb") as fh:
        while True:
            block = fh.read(1 << 22)
            buf = carry + block
            if not buf:
                break
            a = np.frombuffer(buf, dtype=np.uint8)
            ends = np.flatnonzero(a == 10)
            if block:  # whole lines only: the rest waits for the next block
                end = int(ends[-1]) + 1 if len(ends) else 0
            else:  # the end of the file: a last line without a newline
                end = len(buf)
                ends = np.append(ends, len(buf))
            if len(ends):
                starts = np.concatenate(([0], ends[:-1] + 1))
                lead = a[np.minimum(starts, end - 1)]  # a line's first byte ("\n": empty)
                point = ~_BLANK[lead] & (lead != 35)
                indented = np.flatnonzero(_BLANK[lead] & (lead != 10))  # look past the blanks
                if len(indented):  # step each over its blanks, all at once
                    at, moving = starts[indented], np.arange(len(indented))
                    while len(moving):
                        c = a[np.minimum(at[moving], end - 1)]
                        moving = moving[_BLANK[c] & (c != 10) & (at[moving] < end)]
                        at[moving] += 1
                    point[indented] = ((at < ends[indented])
                                       & (a[np.minimum(at, end - 1)] != 35))
                index = line_no + np.arange(len(starts))
                point &= index >= first
                at = np.flatnonzero(point)
                pick = at[(count + np.arange(len(at))) % every == 0]
                offsets.extend((base + starts[pick]).tolist())
                lines.extend(index[pick].tolist())
                if len(at):
                    after = int(index[at[-1]]) + 1
                count += len(at)
                line_no += len(starts)
            carry = buf[end:]
            base += end
            if not block:
                break
    return count, offsets, lines + [after]


def _first_bad_line(lines, delimiter):
    """``(index, text, why)`` of the first of ``lines`` that does not parse as x y z, or
    ``(None, None, None)``; run only to name the line in an error, so one line at a time."""
    for i, line in enumerate(lines):
        try:
            np.loadtxt([line], delimiter=delimiter, usecols=(0, 1, 2), dtype=np.float64, ndmin=2)
        except ValueError as exc:
            return i, line, str(exc).split(" at row ")[0]
    return None, None, None


def _text_header(path):
    """(lines to skip, delimiter) of an XYZ/CSV/TXT file, from its first point line (the first
    neither blank nor a ``#`` comment, :func:`_is_point_line`): a header if it does not start
    with three numbers; the delimiter from the first line of numbers — commas if it has any,
    else semicolons if it has any (CloudCompare's and spreadsheets' other CSV; the in-memory
    reader's rule, ``io.mesh``), else whitespace. Until 2026-12-04 only the file's first line
    was looked at, so a header after a ``#`` comment line was read as a point (an error), and
    a comment or header with a comma set the delimiter of whitespace-separated numbers."""
    skip, header, data = 0, None, None
    with open(path, "rb") as fh:
        for index, raw in enumerate(fh):
            line = raw.decode("ascii", errors="replace")
            if not _is_point_line(line):
                continue
            tokens = line.replace(",", " ").replace(";", " ").split()
            try:
                [float(t) for t in tokens[:3]]
                is_header = len(tokens) < 3
            except ValueError:
                is_header = True
            if is_header and header is None and data is None:
                skip, header = index + 1, line  # the one header line: look on for numbers
                continue
            if header is None:
                skip = index
            data = line
            break
    sample = data if data is not None else ""
    delimiter = "," if "," in sample else ";" if ";" in sample else None
    return skip, delimiter, header, data


def _split_line(line):
    """A text line's words: split at commas, semicolons and whitespace, quotes dropped."""
    return line.replace(",", " ").replace(";", " ").replace('"', " ").split()


#: header names (lower case) of a text file's colour columns, the LAS colour dimensions'
_TEXT_COLOURS = ({"red": "red", "green": "green", "blue": "blue"},
                 {"r": "red", "g": "green", "b": "blue"})


def text_columns(header, data):
    """Which columns of a text point file are x, y, z, and what the others carry, from its
    ``header`` line of names and its first ``data`` line: ``((x, y, z columns), dims)``,
    ``dims`` as an ASCII PLY's (``(column, dimension, type, is colour)``, :class:`TextPart`)
    or None. Without a header, or one whose names do not match the data's columns one for
    one: the first three columns, nothing else (as before 2026-12-07). Else x, y, z by name
    (any case; the first three if not named), colour from ``red green blue`` or ``R G B``
    (0..255, or 0..1 where the first line's values have a decimal point and none is above 1:
    CloudCompare's two ways) as the LAS colour, and every other column but the normals
    (``nx ny nz``) as float64 under its name (CloudCompare's ``//X`` header: its leading
    slashes dropped). A PTS file
    (a first line holding the count, then ``x y z intensity [r g b]``) carries its intensity
    and colour. A column whose first value is not a number is not read."""
    if header is None or data is None:
        return (0, 1, 2), None
    names = [n.lstrip("/#") for n in _split_line(header)]
    words = _split_line(data)
    if len(names) == 1 and names[0].isdigit() and len(words) in (4, 7):  # PTS: a count
        colour = [(4 + j, las, "u1", True) for j, las in enumerate(("red", "green", "blue"))]
        return (0, 1, 2), ((3, "intensity", "f8", False),) + tuple(colour[:len(words) - 4])
    if len(names) != len(words) or not all(names):
        return (0, 1, 2), None
    lower = [n.lower() for n in names]
    xyz = tuple(lower.index(a) for a in "xyz") if {"x", "y", "z"} <= set(lower) else (0, 1, 2)
    dims, taken = [], set()
    for col, word in enumerate(words):  # a column of words (labels) stays unread, as before
        try:
            float(word)
        except ValueError:
            taken.add(col)
    for scheme in _TEXT_COLOURS:
        if set(scheme) <= set(lower) and not taken & {lower.index(c) for c in scheme}:
            cols = [lower.index(c) for c in scheme]
            code = ("f4" if any("." in words[c] for c in cols)
                    and all(float(words[c]) <= 1.0 for c in cols) else "u1")
            dims += [(c, las, code, True) for c, las in zip(cols, scheme.values())]
            taken.update(cols)
            break
    dims += [(col, dim, "f8", False)
             for col, dim in _named(names, taken | set(xyz), [d for _, d, _, _ in dims])]
    return xyz, tuple(dims) or None


def _text_layout(path, chunk_points):
    """(lines to skip, number of points, delimiter, chunk offsets, their line indices, its
    columns: :func:`text_columns`) of an XYZ/CSV/TXT file, by one scan
    (:func:`_scan_points`)."""
    skip, delimiter, header, data = _text_header(path)
    count, offsets, lines = _scan_points(path, skip, chunk_points)
    return skip, count, delimiter, offsets, lines, text_columns(header, data)


def _ply_source(path, chunk_points):
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    if b"end_header" not in head:
        return None
    fmt, elements, body_start = _parse_ply_header(path, head)
    if not elements or elements[0].name != "vertex":
        return None
    vertex = elements[0]
    if any(p.is_list for p in vertex.props) or not {"x", "y", "z"} <= {
            p.name for p in vertex.props}:
        return None
    if fmt == "ascii":
        header_lines = head[:body_start].count(b"\n")
        names = [p.name for p in vertex.props]
        if names[:3] != ["x", "y", "z"]:
            return None
        offsets = _scan_lines(path, header_lines, chunk_points, vertex.count)[2]
        codes = {p.name: _PLY_TYPES.get(p.code, p.code) for p in vertex.props}
        dims = tuple((names.index(name), dim, codes[name], colour)
                     for dim, name, _, colour in ply_dimensions(names, codes)) or None
        return TextSource(path, chunk_points, skip_lines=header_lines, count=vertex.count,
                          delimiter=None, offsets=offsets, dims=dims)
    endian = "<" if fmt == "binary_little_endian" else ">"
    dtype = np.dtype([(p.name, endian + _PLY_TYPES.get(p.code, p.code)) for p in vertex.props])
    size = Path(path).stat().st_size
    if body_start + vertex.count * dtype.itemsize > size:
        raise FileFormatError(f"{path}: the PLY vertex data is shorter than its header says "
                              f"({vertex.count} vertices); the file is truncated.")
    mm = np.memmap(path, dtype=dtype, mode="r", offset=body_start, shape=(vertex.count,))
    return ColumnsSource(mm, chunk_points, files=[Path(path)],
                         mapped=(str(Path(path).absolute()), body_start, dtype,
                                 (vertex.count,)))


def _is_las_spec(spec):
    if isinstance(spec, (list, tuple)):
        return True
    p = Path(spec)
    if p.is_dir() or any(ch in str(spec) for ch in "*?["):
        return True
    return p.suffix.lower() in (".las", ".laz")


def _load_npy(path):
    """``np.load(path, mmap_mode="r")``, or a :class:`FileFormatError` naming the file, what is
    wrong and the fix: numpy's own errors for an empty, truncated or non-NPY file name no
    file ("mmap length is greater than file size"; an empty one raised EOFError, a
    traceback)."""
    with open(path, "rb") as fh:
        magic = fh.read(6)
    fix = "save the (n, 3) points with numpy.save(path, points)"
    if magic != b"\x93NUMPY":
        what = "an empty file" if not magic else "it does not start with the .npy signature"
        raise FileFormatError(f"{path}: not a NumPy .npy file ({what}); {fix}.")
    try:
        return np.load(path, mmap_mode="r")
    except (ValueError, OSError, EOFError) as exc:
        raise FileFormatError(f"{path}: not a readable .npy file ({exc}); it may be truncated "
                              f"or hold Python objects: {fix}.") from None


def open_source(spec, chunk_points=1_000_000):
    """A chunked reader for ``spec``: ``.count``, ``.chunks()``, ``.files``, ``.is_las``."""
    from .e57 import E57Source, e57_files
    files = e57_files(spec)  # an E57 file, or a folder, pattern or list of them (no LAS/LAZ)
    if files:
        return E57Source(files, chunk_points)
    if _is_las_spec(spec):
        las_files(spec)  # FileNotFoundError naming the spec if nothing matches
        src = LasSource(spec, chunk_points=chunk_points)
        src.is_las = True
        return src
    p = Path(spec)
    if not p.exists():
        raise FileNotFoundError(2, "No such file", str(p))
    suffix = p.suffix.lower()
    ply = suffix == ".ply" or p.name.lower().endswith(".ply.gz")
    if suffix == ".ply":
        src = _ply_source(p, chunk_points)
        if src is not None:
            return src
    if ply:  # gzipped, or a layout the chunked readers do not take: read whole
        table = read_ply_vertices(p)
        if ply_dimensions(table.dtype.names, table.dtype):
            return ColumnsSource(table, chunk_points, files=[p])
        return ArraySource(np.stack([table[a] for a in "xyz"], axis=1).astype(np.float64),
                           chunk_points, files=[p])
    if suffix in TEXT_SUFFIXES:
        skip, count, delimiter, offsets, lines, (xyz, dims) = _text_layout(p, chunk_points)
        return TextSource(p, chunk_points, skip_lines=skip, count=count, delimiter=delimiter,
                          offsets=offsets, lines=lines, dims=dims, xyz=xyz,
                          guessed=[dim for _, dim, code, colour in dims or ()
                                   if code == "f8" and not colour])
    if suffix == ".npy":
        arr = _load_npy(p)
        mapped = None
        if arr.dtype.names and {"x", "y", "z"} <= set(arr.dtype.names):  # our own output
            if ply_dimensions(arr.dtype.names, arr.dtype):  # fields: carried
                return ColumnsSource(arr, chunk_points, files=[p])  # as a PLY's properties
            arr = np.stack([arr["x"], arr["y"], arr["z"]], axis=1)
        elif arr.dtype.names or arr.ndim != 2 or arr.shape[1] < 3 or arr.dtype.kind not in "fiu":
            arr = read_points(p)  # (n, >3) and the rest, or an error naming what it holds
        elif isinstance(arr, np.memmap) and arr.flags.c_contiguous:
            mapped = (str(p.absolute()), int(arr.offset), arr.dtype, arr.shape)
        return ArraySource(arr, chunk_points, files=[p], mapped=mapped)
    return ArraySource(read_points(p), chunk_points, files=[p])


def read_xyz(spec):
    """Every point of any input :func:`open_source` reads (LAS/LAZ files, folders and globs
    too), at once: ``(xyz (n, 3) float64, source)``. For the commands that hold a cloud in
    memory (``simplify``, ``evaluate``, ``report``); the chunks are checked finite as they
    are read (:func:`check_finite`; LAS/LAZ coordinates are integers)."""
    src = open_source(spec)
    return read_all(src), src


def read_all(src):
    """Every point of an opened source (:func:`open_source`), as one (n, 3) float64 array."""
    parts = [xyz for _, xyz, _ in src.chunks()]
    return np.concatenate(parts) if parts else np.empty((0, 3))


def read_all_dimensions(src):
    """Every point of an opened source and what it carries: ``(xyz, {name: (n, ...)
    array})`` — a LAS file's dimensions, a PLY's vertex properties and a structured NPY's
    fields (:func:`ply_dimensions`), a text file's named columns (:func:`text_columns`), an
    E57 file's point fields (:data:`.e57.OTHER`; intensity and colour with LAS names and
    types); nothing for the other formats."""
    parts, dims = [], {}
    for _, xyz, attrs in src.chunks():
        parts.append(xyz)
        for name, values in attrs.items():
            dims.setdefault(name, []).append(np.asarray(values))
    xyz = np.concatenate(parts) if parts else np.empty((0, 3))
    return xyz, {name: np.concatenate(v) for name, v in dims.items()}
