"""The core algorithm on one in-memory point set: pure functions of arrays, no I/O, no dask.

One module per step of the paper (Song & Feng): :mod:`.voronoi` (Voronoi neighbours, seeded by
the triangulation of :mod:`.delaunay`), :mod:`.local_mesh` (local Voronoi mesh),
:mod:`.normals`, :mod:`.boundary` (sharp-edge points), :mod:`.importance` (Eq. (1)),
:mod:`.removal` (progressive removal); :mod:`.simplify` chains them.
"""

from .options import SimplifyOptions
from .result import SimplifyResult
from .simplify import simplify_points

__all__ = ["SimplifyOptions", "SimplifyResult", "simplify_points"]
