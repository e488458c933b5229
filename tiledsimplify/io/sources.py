"""One way to read any supported input in chunks: ``open_source(spec)``.

LAS/LAZ files, folders and globs stream through :class:`~tiledsimplify.io.las.LasSource`.
NPY files are memory-mapped and sliced. Other point formats (PLY, XYZ/CSV, meshes) are read
whole and served in chunks (they are rarely the huge inputs; LAS/LAZ are).
"""

from pathlib import Path

import numpy as np

from .las import LasSource, las_files
from .mesh import read_points


class ArraySource:
    """Chunks over an in-memory or memory-mapped (n, 3) array (same interface as LasSource)."""

    is_las = False

    def __init__(self, xyz, chunk_points=1_000_000, files=()):
        self._xyz = xyz
        self.chunk_points = int(chunk_points)
        self.files = list(files)

    @property
    def count(self):
        return int(self._xyz.shape[0])

    def __len__(self):
        return self.count

    def chunks(self):
        for start in range(0, self.count, self.chunk_points):
            stop = min(start + self.chunk_points, self.count)
            yield start, np.ascontiguousarray(self._xyz[start:stop, :3], dtype=np.float64), {}


def _is_las_spec(spec):
    if isinstance(spec, (list, tuple)):
        return True
    p = Path(spec)
    if p.is_dir() or any(ch in str(spec) for ch in "*?["):
        return True
    return p.suffix.lower() in (".las", ".laz")


def open_source(spec, chunk_points=1_000_000):
    """A chunked reader for ``spec``: ``.count``, ``.chunks()``, ``.files``, ``.is_las``."""
    if _is_las_spec(spec):
        las_files(spec)  # FileNotFoundError naming the spec if nothing matches
        src = LasSource(spec, chunk_points=chunk_points)
        src.is_las = True
        return src
    p = Path(spec)
    if not p.exists():
        raise FileNotFoundError(2, "No such file", str(p))
    if p.suffix.lower() == ".npy":
        arr = np.load(p, mmap_mode="r")
        if arr.dtype.names:  # our own structured output
            arr = np.stack([arr["x"], arr["y"], arr["z"]], axis=1)
        else:
            arr = read_points(p) if arr.ndim != 2 or arr.shape[1] < 3 else arr
        return ArraySource(arr, chunk_points, files=[p])
    return ArraySource(read_points(p), chunk_points, files=[p])
