"""Unit normals from the local Voronoi mesh (paper §3.1, after OuYang & Feng 2005).

The normal at ``p`` is the direction of least variance (PCA) of ``p`` and its local-mesh
neighbours ``DN_p``; where those are nearly collinear, the reference-plane normal of
:mod:`.local_mesh` (fitted to more neighbours) is used instead. Signs are canonical (largest component positive): every use in the core
(Eq. (1), normal deviation) is insensitive to the sign.
"""

import numpy as np

from ._jit import jit, jit_leaf
from .linalg import covariance_about, orient_canonical, smallest_axis
from .local_mesh import SPREAD


@jit_leaf
def normal_at(X, p, dn, c, fallback, out, work):
    """PCA normal of ``p`` and ``dn[:c]``; ``fallback`` when they do not span a plane.

    "Do not span a plane" uses the local mesh's collinearity test (middle eigenvalue below
    ``SPREAD`` of the largest): at the open border of a scan the one-ring can be a few points
    along the border, whose least-variance direction is arbitrary around the border line.
    """
    c00, c01, c02, c11, c12, c22 = covariance_about(X, p, dn, c)
    l0, l1, l2 = smallest_axis(c00, c01, c02, c11, c12, c22, out, work)
    if c < 2 or l1 <= SPREAD * l2:
        out[0], out[1], out[2] = fallback[0], fallback[1], fallback[2]
    orient_canonical(out)


@jit
def all_normals(X, dn, dn_cnt, plane_normals, normals):
    """Normals of every point (see :func:`normal_at`)."""
    work = np.empty(3)
    for p in range(X.shape[0]):
        normal_at(X, p, dn[p], dn_cnt[p], plane_normals[p], normals[p], work)
