"""File input for tiledsimplify: triangle meshes and point files.

See :mod:`tiledsimplify.io.mesh` for :func:`read_mesh` and :func:`read_points`.
"""

from .mesh import read_mesh, read_points

__all__ = ["read_mesh", "read_points"]
