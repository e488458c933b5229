"""Point importance, paper Eq. (1), and the registry of importance measures.

``i(p) = Σ_l |(p − q_l) · n_l| / K`` over the ``K`` local-mesh neighbours ``q_l`` of ``p`` that
are not boundary points: the mean distance from ``p`` to its neighbours' tangent planes.
Boundary neighbours are ignored "as their associated normal vectors are not reliable" (§3.2).
A point whose neighbours are all boundary points has no defined importance; it gets ``+inf``
and so is removed only after every point that has one.

Measures are selected by name and dispatched by a small integer inside the removal kernel, so
new measures plug in without touching the loop.
"""

import math

from ._jit import jit

#: name -> code of the importance measures the removal kernel knows
MEASURES = {"paper": 0}


@jit
def eq1(X, normals, boundary, p, dn, c):
    """Eq. (1) for point ``p`` with local-mesh neighbours ``dn[:c]``."""
    total = 0.0
    k = 0
    px, py, pz = X[p, 0], X[p, 1], X[p, 2]
    for j in range(c):
        q = dn[j]
        if boundary[q]:
            continue
        total += abs((px - X[q, 0]) * normals[q, 0]
                     + (py - X[q, 1]) * normals[q, 1]
                     + (pz - X[q, 2]) * normals[q, 2])
        k += 1
    if k == 0:
        return math.inf
    return total / k


@jit
def importance_of(code, X, normals, boundary, p, dn, c):
    """Dispatch to the measure with the given code (see :data:`MEASURES`)."""
    # code 0: the paper's Eq. (1); later measures add branches here
    return eq1(X, normals, boundary, p, dn, c)


@jit
def all_importance(code, X, normals, boundary, dn, dn_cnt, out):
    """Importance of every point."""
    for p in range(X.shape[0]):
        out[p] = importance_of(code, X, normals, boundary, p, dn[p], dn_cnt[p])
