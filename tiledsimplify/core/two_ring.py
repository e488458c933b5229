"""A point's two-ring in the local Voronoi mesh, and the smoothed deviation over it (step 1
of :mod:`.edge_fit`).

The edge fits work on the two-ring ``DN_p ∪ DN(DN_p)`` of the local Voronoi mesh (about 19
points instead of the one-ring's 7), which :func:`gather_rings` collects. The **smoothed
measure** (:func:`smoothed_deviations`) is the paper's curvature-compensated normal deviation
(:func:`.boundary.deviation_at`) over it, with normals fitted to it: noise averages out, edges
still stand out. :func:`nearest_distances` and :func:`median_in_place` give the local spacing
the fits measure in.
"""

import numpy as np

from ._jit import jit, jit_leaf
from .boundary import deviation_at
from .linalg import covariance_about, orient_canonical, smallest_axis


#: rings of the local mesh the two-plane fit uses (3 measured: Fandisk F1 0.91 -> 0.86)
FIT_RINGS = 2
#: most points gathered in a neighbourhood
MAX_RING = 128


@jit_leaf
def sort_in_place(a, m):
    """Sorts ``a[:m]`` in place, by insertion: the few dozen values of a two- or three-ring,
    without the copy ``np.sort`` or ``np.median`` makes, and quicker to compile."""
    for i in range(1, m):
        v = a[i]
        j = i - 1
        while j >= 0 and a[j] > v:
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = v


@jit_leaf
def median_in_place(a, c):
    """``np.median(a[:c])`` (``c`` >= 1, no NaN), sorting ``a[:c]`` in place
    (:func:`sort_in_place`): the middle value, or the mean ``(a + b) / 2`` of the middle two
    as numpy's."""
    sort_in_place(a, c)
    half = c >> 1
    if c & 1 == 0:
        return (a[half - 1] + a[half]) / 2
    return a[half]


@jit_leaf
def gather_rings(p, dn, dn_cnt, rings, mark, out):
    """``p``'s local-mesh neighbours up to ``rings`` rings away, without ``p``, into ``out``.

    Returns the count (at most ``len(out)``). ``mark`` is an int64 work array of length n,
    zero-initialised once; it is stamped with ``p + 1`` so that no clearing is needed between
    points (each point is gathered once per pass).
    """
    stamp = p + 1
    mark[p] = stamp
    c = 0
    cap = out.shape[0]
    for j in range(dn_cnt[p]):
        q = dn[p, j]
        if mark[q] != stamp and c < cap:
            mark[q] = stamp
            out[c] = q
            c += 1
    lo = 0
    for _ in range(rings - 1):
        hi = c
        for i in range(lo, hi):
            r = out[i]
            for j in range(dn_cnt[r]):
                q = dn[r, j]
                if mark[q] != stamp and c < cap:
                    mark[q] = stamp
                    out[c] = q
                    c += 1
        lo = hi
    return c


@jit
def smoothed_deviations(X, dn, dn_cnt, normals_out, out):
    """Step 1: two-ring normals (PCA) and the paper's deviation measure over the two-ring."""
    n = X.shape[0]
    mark = np.zeros(n, dtype=np.int64)
    ring = np.empty(MAX_RING, dtype=np.int64)
    work = np.empty(3)
    for p in range(n):
        c = gather_rings(p, dn, dn_cnt, 2, mark, ring)
        c00, c01, c02, c11, c12, c22 = covariance_about(X, p, ring, c)
        smallest_axis(c00, c01, c02, c11, c12, c22, normals_out[p], work)
        orient_canonical(normals_out[p])
    A = np.empty((3, 3))
    b = np.empty(3)
    frame = np.empty((2, 3))
    mark[:] = 0
    for p in range(n):
        c = gather_rings(p, dn, dn_cnt, 2, mark, ring)
        out[p] = deviation_at(X, normals_out, p, ring, c, A, b, frame)


@jit
def nearest_distances(X, start, cnt, pool, out):
    """Distance from every point to its nearest Voronoi neighbour (its nearest neighbour)."""
    for p in range(X.shape[0]):
        best = np.inf
        for j in range(cnt[p]):
            q = pool[start[p] + j]
            d = ((X[q, 0] - X[p, 0]) ** 2 + (X[q, 1] - X[p, 1]) ** 2
                 + (X[q, 2] - X[p, 2]) ** 2)
            if d < best:
                best = d
        out[p] = np.sqrt(best)
