"""E57 files (ASTM E2807: terrestrial and industrial laser scanners) read in chunks.

An E57 file holds one or more scans, each a compressed vector of points in the scanner's own
frame — Cartesian (``cartesianX/Y/Z``) or spherical (``sphericalRange/Azimuth/Elevation``) —
and a pose (a unit quaternion and a translation) that places it in the file's common frame.
Points a scanner marks invalid (``cartesianInvalidState`` / ``sphericalInvalidState`` not 0:
no return, or a direction only) carry no position and are left out. Every chunk holds
common-frame coordinates, so the scans of a registered project come out as one cloud.

Read through ``pye57`` (libE57Format), an optional dependency: ``pip install
'tiledsimplify[e57]'``. Only positions are read; an output in LAS/LAZ from an E57 input is LAS
1.4 point format 6, as from any input that is not LAS.
"""

from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError

CARTESIAN = ("cartesianX", "cartesianY", "cartesianZ")
SPHERICAL = ("sphericalRange", "sphericalAzimuth", "sphericalElevation")


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


class _Scan:
    """One scan's layout: index, point count, coordinate fields, invalid-state field, pose."""

    def __init__(self, header, index, path):
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


class E57Source:
    """Chunks of an E57 file's valid points in its common frame (the interface of
    :class:`~tiledsimplify.io.sources.ArraySource`: ``count``, ``chunks()``, ``files``).

    ``count`` is exact: where a scan marks invalid points, their states are read once when the
    source is opened (one field, in chunks), so a run knows its target before the ingest.
    """

    is_las = False

    def __init__(self, path, chunk_points=1_000_000):
        self.path = Path(path)
        self.files = [self.path]
        self.chunk_points = max(int(chunk_points), 1)
        self._pye57 = _pye57(self.path)
        with self._open() as f:
            try:
                self._scans = [_Scan(f.get_header(i), i, self.path)
                               for i in range(f.scan_count)]
            except self._pye57.libe57.E57Exception as exc:
                raise self._bad(exc) from None
            self._valid = [self._count_valid(f, s) for s in self._scans]

    def _bad(self, exc):
        return FileFormatError(f"{self.path}: not a readable E57 file ({exc}); check that the "
                               "file is complete (a copy that stopped part-way), or export it "
                               "again.")

    def _open(self):
        try:
            return self._pye57.E57(str(self.path))
        except (self._pye57.libe57.E57Exception, OSError) as exc:
            raise self._bad(exc) from None

    @property
    def count(self):
        return int(sum(self._valid))

    def __len__(self):
        return self.count

    def _read(self, f, scan, fields):
        """The scan's ``fields`` in chunks of at most ``chunk_points``: yields dicts of arrays."""
        n = min(self.chunk_points, max(scan.size, 1))
        arrays, buffers = f.make_buffers(list(fields), n)
        reader = f.get_header(scan.index).points.reader(buffers)
        try:
            while True:
                got = reader.read()
                if got == 0:
                    break
                yield {k: v[:got] for k, v in arrays.items()}
        except self._pye57.libe57.E57Exception as exc:
            raise self._bad(exc) from None
        finally:
            reader.close()

    def _count_valid(self, f, scan):
        if scan.state is None:
            return scan.size
        return sum(int(np.count_nonzero(c[scan.state] == 0))
                   for c in self._read(f, scan, [scan.state]))

    def chunks(self):
        """``(start, xyz, {})`` chunks: ``start`` the first point's position among the valid
        points of the whole file, scan after scan."""
        from .sources import check_finite
        start = 0
        with self._open() as f:
            for scan in self._scans:
                fields = list(scan.coords) + ([scan.state] if scan.state else [])
                for c in self._read(f, scan, fields):
                    a, b, d = (c[k].astype(np.float64) for k in scan.coords)
                    if scan.state is not None:
                        ok = c[scan.state] == 0
                        a, b, d = a[ok], b[ok], d[ok]
                    if not len(a):
                        continue
                    if scan.coords is SPHERICAL:
                        xyz = spherical_to_cartesian(a, b, d)
                    else:
                        xyz = np.stack([a, b, d], axis=1)
                    xyz = xyz @ scan.rotation.T + scan.translation
                    yield start, check_finite(xyz, start, self.files), {}
                    start += len(xyz)
