"""E57 files (ASTM E2807: terrestrial and industrial laser scanners) read in chunks.

An E57 file holds one or more scans, each a compressed vector of points in the scanner's own
frame — Cartesian (``cartesianX/Y/Z``) or spherical (``sphericalRange/Azimuth/Elevation``) —
and a pose (a unit quaternion and a translation) that places it in the file's common frame.
Points a scanner marks invalid (``cartesianInvalidState`` / ``sphericalInvalidState`` not 0:
no return, or a direction only) carry no position and are left out. Every chunk holds
common-frame coordinates, so the scans of a registered project come out as one cloud — from
one file, or from a folder, glob or list of files exported one a scan station (:func:`e57_files`).

Read through ``pye57`` (libE57Format), an optional dependency: ``pip install
'tiledsimplify[e57]'``. Besides positions, intensity and colour (where a scan has them) are
carried as the LAS dimensions ``intensity`` and ``red``/``green``/``blue``, 16-bit, scaled from
the range the scan declares (``intensityLimits``, ``colorLimits``, else its fields' bounds): a
LAS/LAZ output of an E57 input is LAS 1.4 point format 6, or 7 with colour. The other point
fields a scan has come through too (:data:`OTHER`): ``returnIndex`` and ``returnCount`` as
LAS's ``return_number`` (from 1) and ``number_of_returns``, ``rowIndex``, ``columnIndex``,
``timeStamp`` and the ``is…Invalid`` flags under their own names (extra bytes in a LAS
output, :func:`.las_output.carried_layout`).
"""

import functools
import glob
import os
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError
from .las_output import NEW_POINT_DEFAULTS
from .points_out import whole_type
from .sources import check_finite, to_uint16

CARTESIAN = ("cartesianX", "cartesianY", "cartesianZ")
SPHERICAL = ("sphericalRange", "sphericalAzimuth", "sphericalElevation")
#: E57 fields kept as LAS dimensions (16-bit, scaled from the scan's range of the field):
#: LAS name -> (E57 field, the scan's limits group, its minimum and maximum children)
KEPT = {"intensity": ("intensity", "intensityLimits", "intensityMinimum", "intensityMaximum"),
        "red": ("colorRed", "colorLimits", "colorRedMinimum", "colorRedMaximum"),
        "green": ("colorGreen", "colorLimits", "colorGreenMinimum", "colorGreenMaximum"),
        "blue": ("colorBlue", "colorLimits", "colorBlueMinimum", "colorBlueMaximum")}
COLOURS = ("red", "green", "blue")
#: E57's other point fields (ASTM E2807 §8.4.4), carried under their own names: LAS name ->
#: (E57 field, value added, type or None: the smallest signed integer its prototype's bounds
#: fit); returnIndex counts from 0, LAS's return_number from 1
OTHER = {"return_number": ("returnIndex", 1, None), "number_of_returns": ("returnCount", 0, None),
         "rowIndex": ("rowIndex", 0, None), "columnIndex": ("columnIndex", 0, None),
         "timeStamp": ("timeStamp", 0, np.dtype(np.float64)),
         "isTimeStampInvalid": ("isTimeStampInvalid", 0, np.dtype(np.uint8)),
         "isIntensityInvalid": ("isIntensityInvalid", 0, np.dtype(np.uint8)),
         "isColorInvalid": ("isColorInvalid", 0, np.dtype(np.uint8))}

#: the types an integer field is read as, the first that holds its declared bounds (int64 else)
_SIGNED = tuple(np.dtype(t) for t in (np.int8, np.int16, np.int32))


def _pye57(path):
    try:
        import pye57
    except ImportError:
        raise InputError(f"{path}: reading E57 files needs the pye57 package: pip install "
                         "'tiledsimplify[e57]' (or pip install pye57), or convert the file to "
                         "LAS/LAZ first (e.g. `pdal translate in.e57 out.laz`).") from None
    return pye57


def rotation_matrix(w, x, y, z):
    """The rotation of the unit quaternion ``w + xi + yj + zk`` (normalised first, as E57
    writers round it), as a 3x3 matrix acting on column vectors."""
    q = np.array([w, x, y, z], dtype=np.float64)
    norm = np.linalg.norm(q)
    if not norm > 0:
        return np.eye(3)
    w, x, y, z = q / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def spherical_to_cartesian(r, azimuth, elevation):
    """E57's spherical coordinates (range, azimuth from +x towards +y, elevation from the x-y
    plane towards +z; radians) as (m, 3) Cartesian."""
    c = r * np.cos(elevation)
    return np.stack([c * np.cos(azimuth), c * np.sin(azimuth), r * np.sin(elevation)], axis=1)


def _number(node):
    """The value of an E57 number node (float, integer or scaled integer)."""
    scaled = getattr(node, "scaledValue", None)
    return float(scaled() if scaled is not None else node.value())


def _field_range(lib, scan_node, proto, field, group, lo_key, hi_key):
    """``(lo, hi)`` of a field's values: the scan's limits (``intensityLimits``,
    ``colorLimits``), else the bounds its prototype declares; None if neither gives a finite,
    non-empty range (the values are then taken as 16-bit as they are)."""
    found = []
    try:
        if scan_node.isDefined(group):
            limits = scan_node[group]
            found.append((_number(limits[lo_key]), _number(limits[hi_key])))
    except lib.E57Exception:
        pass
    node = proto.get(field)
    kind = node.type()
    typed = {lib.NodeType.E57_FLOAT: lib.FloatNode, lib.NodeType.E57_INTEGER: lib.IntegerNode,
             lib.NodeType.E57_SCALED_INTEGER: lib.ScaledIntegerNode}.get(kind)
    if typed is not None:
        t = typed(node)
        if typed is lib.ScaledIntegerNode:
            found.append((float(t.scaledMinimum()), float(t.scaledMaximum())))
        else:
            found.append((float(t.minimum()), float(t.maximum())))
    for lo, hi in found:
        if np.isfinite(lo) and np.isfinite(hi) and 0 < hi - lo < 1e12:
            return lo, hi
    return None


def _integer_type(lib, proto, field, added):
    """The smallest signed integer type (int8 .. int64) that holds an integer field's values
    plus ``added``, by the bounds its prototype declares; int64 if it declares none."""
    node = proto.get(field)
    if node.type() == lib.NodeType.E57_INTEGER:
        t = lib.IntegerNode(node)
        lo, hi = int(t.minimum()) + added, int(t.maximum()) + added
        return whole_type(lo, hi, _SIGNED) or np.dtype(np.int64)
    return np.dtype(np.int64)


class _Scan:
    """One scan's layout: index, point count, coordinate fields, invalid-state field, pose,
    the fields kept as LAS dimensions with their ranges, and the other fields carried
    (:data:`OTHER`) with their types."""

    def __init__(self, header, index, path, lib):
        self.index = index
        self.size = int(header.point_count)
        fields = set(header.point_fields)
        if set(CARTESIAN) <= fields:
            self.coords, self.state = CARTESIAN, "cartesianInvalidState"
        elif set(SPHERICAL) <= fields:
            self.coords, self.state = SPHERICAL, "sphericalInvalidState"
        else:
            raise FileFormatError(
                f"{path}: scan {index} has neither Cartesian (cartesianX/Y/Z) nor spherical "
                f"(sphericalRange/Azimuth/Elevation) coordinates (its fields: "
                f"{', '.join(sorted(fields))}); export the scan with coordinates.")
        if self.state not in fields:
            self.state = None
        proto = lib.StructureNode(header.points.prototype())
        self.kept = {}  # LAS name -> (E57 field, range)
        for name, (field, group, lo_key, hi_key) in KEPT.items():
            if field in fields and (name not in COLOURS
                                    or all(KEPT[c][0] in fields for c in COLOURS)):
                self.kept[name] = (field, _field_range(lib, header.node, proto, field, group,
                                                       lo_key, hi_key))
        self.other = {}  # name -> (E57 field, value added, type)
        for name, (field, added, dtype) in OTHER.items():
            if field in fields:
                self.other[name] = (field, added,
                                    dtype or _integer_type(lib, proto, field, added))
        self.rotation, self.translation = np.eye(3), np.zeros(3)
        node = header.node
        if node.isDefined("pose"):
            pose = node["pose"]
            if pose.isDefined("rotation"):
                r = pose["rotation"]
                self.rotation = rotation_matrix(*(float(r[k].value()) for k in "wxyz"))
            if pose.isDefined("translation"):
                t = pose["translation"]
                self.translation = np.array([float(t[k].value()) for k in "xyz"])


def e57_files(spec):
    """The E57 files a folder, glob pattern or list of paths names — or None if it names a
    LAS/LAZ file (read as LAS tiles then) or no E57 file. Sorted within a folder or pattern,
    without duplicates."""
    out, seen = [], set()
    for one in spec if isinstance(spec, (list, tuple)) else [spec]:
        path, text = Path(one), os.fspath(one)
        if path.is_file():
            found = [path]
        elif path.is_dir():
            found = sorted(p for p in path.iterdir() if p.is_file())
        elif any(ch in text for ch in "*?["):
            found = sorted(Path(p) for p in glob.glob(text, recursive=True) if Path(p).is_file())
        else:
            return None
        for p in found:
            suffix = p.suffix.lower()
            if suffix in (".las", ".laz"):
                return None
            key = os.path.abspath(p)
            if suffix == ".e57" and key not in seen:
                seen.add(key)
                out.append(p)
    return out or None


class E57Source:
    """Chunks of the valid points of one or more E57 files, each in its common frame, file
    after file and scan after scan (the interface of
    :class:`~tiledsimplify.io.sources.ArraySource`: ``count``, ``chunks()``, ``files``). Files
    exported scan by scan from one registered project share its frame and come out as one
    cloud.

    ``count`` is exact: where a scan marks invalid points, their states are read once when the
    source is opened (one field, in chunks), so a run knows its target before the ingest.
    """

    is_las = False

    def __init__(self, paths, chunk_points=1_000_000):
        paths = paths if isinstance(paths, (list, tuple)) else [paths]
        self.files = [Path(p) for p in paths]
        self.chunk_points = max(int(chunk_points), 1)
        self._pye57 = _pye57(self.files[0])
        self._scans, self._valid = [], []  # per file
        for path in self.files:
            with self._open(path) as f:
                try:
                    scans = [_Scan(f.get_header(i), i, path, self._pye57.libe57)
                             for i in range(f.scan_count)]
                except self._pye57.libe57.E57Exception as exc:
                    raise self._bad(path, exc) from None
                self._scans.append(scans)
                self._valid.append([self._count_valid(f, path, s) for s in scans])
        every = [s for scans in self._scans for s in scans]
        #: the dimensions every chunk carries and their types (where a scan lacks the field 0,
        #: or 1 for its returns): the LAS ones (16-bit), then the other fields (the widest
        #: type of any scan)
        self.attributes = {name: np.dtype(np.uint16) for name in KEPT
                           if any(name in s.kept for s in every)}
        for name in OTHER:
            types = [s.other[name][2] for s in every if name in s.other]
            if types:
                self.attributes[name] = functools.reduce(np.promote_types, types)

    @staticmethod
    def _bad(path, exc):
        return FileFormatError(f"{path}: not a readable E57 file ({exc}); check that the "
                               "file is complete (a copy that stopped part-way), or export it "
                               "again.")

    def _open(self, path):
        try:
            return self._pye57.E57(str(path))
        except (self._pye57.libe57.E57Exception, OSError) as exc:
            raise self._bad(path, exc) from None

    @property
    def count(self):
        return int(sum(sum(v) for v in self._valid))

    def __len__(self):
        return self.count

    def _buffers(self, f, fields, n):
        """Buffers of ``n`` values for ``fields``: float64 for every number (libE57Format
        converts and scales into them: pye57's own buffers hold colour as uint8, which a scan
        of 16-bit colour overflows), int8 for the invalid states."""
        lib = self._pye57.libe57
        arrays, buffers = {}, lib.VectorSourceDestBuffer()
        for name in fields:
            arr = np.empty(n, dtype=np.int8 if name.endswith("InvalidState") else np.float64)
            arrays[name] = arr
            buffers.append(lib.SourceDestBuffer(f.image_file, name, arr, n, True, True))
        return arrays, buffers

    def _read(self, f, path, scan, fields):
        """The scan's ``fields`` in chunks of at most ``chunk_points``: yields dicts of arrays."""
        n = min(self.chunk_points, max(scan.size, 1))
        arrays, buffers = self._buffers(f, list(fields), n)
        reader = f.get_header(scan.index).points.reader(buffers)
        try:
            while True:
                got = reader.read()
                if got == 0:
                    break
                yield {k: v[:got] for k, v in arrays.items()}
        except self._pye57.libe57.E57Exception as exc:
            raise self._bad(path, exc) from None
        finally:
            reader.close()

    def _count_valid(self, f, path, scan):
        if scan.state is None:
            return scan.size
        return sum(int(np.count_nonzero(c[scan.state] == 0))
                   for c in self._read(f, path, scan, [scan.state]))

    def chunks(self):
        """``(start, xyz, attrs)`` chunks: ``start`` the first point's position among the
        valid points of all the files, file after file and scan after scan; ``attrs`` the LAS
        dimensions of :attr:`attributes`, each of its type."""
        start = 0
        for path, scans in zip(self.files, self._scans):
            with self._open(path) as f:
                for scan in scans:
                    for xyz, attrs in self._scan_chunks(f, path, scan):
                        yield start, check_finite(xyz, start, [path]), attrs
                        start += len(xyz)

    def _scan_chunks(self, f, path, scan):
        """``(xyz, attrs)`` of a scan's valid points, chunk by chunk, in the file's frame."""
        extra = [field for field, _ in scan.kept.values()]
        extra += [field for field, _, _ in scan.other.values()]
        fields = list(scan.coords) + extra + ([scan.state] if scan.state else [])
        for c in self._read(f, path, scan, fields):
            ok = c[scan.state] == 0 if scan.state is not None else slice(None)
            a, b, d = (c[k][ok] for k in scan.coords)  # used before the next read
            if not len(a):
                continue
            attrs = {}
            for name, dtype in self.attributes.items():
                if name in scan.kept:
                    field, span = scan.kept[name]
                    attrs[name] = to_uint16(c[field][ok], span)
                elif name in scan.other:  # read as float64: integers exact to 2**53
                    field, added, _ = scan.other[name]
                    attrs[name] = (c[field][ok] + added).astype(dtype)
                else:  # a scan without the field: one return per point, else 0
                    attrs[name] = np.full(len(a), NEW_POINT_DEFAULTS.get(name, 0), dtype=dtype)
            if scan.coords is SPHERICAL:
                xyz = spherical_to_cartesian(a, b, d)
            else:
                xyz = np.stack([a, b, d], axis=1)
            yield xyz @ scan.rotation.T + scan.translation, attrs
