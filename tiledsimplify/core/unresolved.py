"""Detail finer than the sampling: points whose neighbourhood no plane through them holds.

Beyond the paper. The edge fits (:mod:`.edge_fit`) find an edge where two planes, a step or a
rim explain a point's two-ring. Detail finer than the point spacing — a thread, a gear's
teeth, a stack of discs a spacing apart — shows no such shape: its points scatter about any
plane, and its smoothed deviation can be as low as a face's (0.007 rad near counter's threads,
where candidates need 0.08; docs/measurements.md "Counter's threaded holes"). Every such
point lies within a spacing or so of the edges of that detail, so it is flagged
(:func:`.simplify.boundary_flags`: the flags only; what is kept does not change).

A point is **unresolved** where its :data:`NEAREST` nearest points in its two-ring of the
local Voronoi mesh (:func:`.two_ring.gather_rings`) spread off their best plane (surface
variation ``λ0 / (λ0 + λ1 + λ2)`` above :data:`MIN_VARIATION`; Pauly, Gross & Kobbelt 2002)
and no plane through the point and two of them holds :data:`MIN_ON_PLANE` of them within a
tolerance. (The Voronoi lists ``VN_p`` themselves reach across a part's inside and far along
its faces: their variation is high everywhere, 0.07 in the median on counter.) A point on a face holds its own plane; a
point at a resolved sharp edge lies on one of its two faces and holds that face's plane; a
point of a thin wall holds its own sheet's plane. The tolerance follows the scanner's noise
(:func:`tolerance`), so that noise alone never makes a point unresolved; it is meant for
even samplings, where faces are sampled all over (:func:`.thin_walls.median_ring_gap`): on a
line scan a point's neighbours lie along its own line and the next, and a face there holds
few of them in one plane with the point.
"""

import math

import numpy as np

from ._jit import jit, jit_leaf
from .linalg import covariance_about, sym3_eigvals
from .local_mesh import sort_by_distance
from .two_ring import MAX_RING, gather_rings

#: the neighbourhood: this many nearest points of the two-ring (the point itself not counted)
NEAREST = 11
#: least surface variation of an unresolved point's neighbourhood. On a plane sampled evenly
#: with noise of 0.3 / 0.4 grid steps (0.34 / 0.44 of the measured spacing) the median is
#: 0.029 / 0.049 and 4 % / 31 % of the points lie above this: the tolerance holds those
#: (``tests/test_unresolved.py``)
MIN_VARIATION = 0.06
#: a plane through the point holding at least this many of its neighbours (the two that fix
#: it included) within the tolerance resolves it
MIN_ON_PLANE = 5
#: the tolerance: this many cloud spacings at least ...
ON_PLANE = 0.07
#: ... or this many times the noise (:func:`tolerance`), if more
NOISE_TIMES = 5.0
#: the noise: this percentile of the points' RMS distances from their neighbourhood's plane
NOISE_PERCENTILE = 5.0
#: two neighbours fix a plane with the point only where the sine of their angle seen from it
#: is at least this
MIN_SINE = 0.2


@jit
def _buffers(n):
    """Scratch of :func:`_nearest`: the two-ring's marks (n), the ring, its order, distances."""
    return (np.zeros(n, dtype=np.int64), np.empty(MAX_RING, dtype=np.int64),
            np.empty(MAX_RING, dtype=np.int64), np.empty(MAX_RING))


@jit_leaf
def _nearest(X, p, dn, dn_cnt, mark, ring, idx, d2):
    """``p``'s ``NEAREST`` nearest points of its two-ring into ``idx``; returns their count."""
    c = gather_rings(p, dn, dn_cnt, 2, mark, ring)
    sort_by_distance(X, p, ring, c, idx, d2)
    return min(c, NEAREST)


@jit
def variations(X, dn, dn_cnt, var, rms):
    """Per point ``p``: the surface variation of ``p`` and its neighbourhood (see the module
    notes) into ``var``, and the RMS distance of those points from their best plane,
    ``sqrt(λ0)``, into ``rms``."""
    n = X.shape[0]
    mark, ring, idx, d2 = _buffers(n)
    for p in range(n):
        k = _nearest(X, p, dn, dn_cnt, mark, ring, idx, d2)
        if k < 3:
            var[p] = 0.0
            rms[p] = 0.0
            continue
        l0, l1, l2 = sym3_eigvals(*covariance_about(X, p, idx, k))
        l0 = max(l0, 0.0)
        total = l0 + max(l1, 0.0) + max(l2, 0.0)
        var[p] = l0 / total if total > 0.0 else 0.0
        rms[p] = math.sqrt(l0)


def tolerance(rms, spacing):
    """How far off a plane a point may lie and still be on it: ``ON_PLANE`` spacings, or
    ``NOISE_TIMES`` times the noise if more. The noise is the ``NOISE_PERCENTILE``-th
    percentile of ``rms`` (:func:`variations`): the quietest points lie on faces, where their
    RMS is ~0.6 of the scanner's noise (0.56 and 0.59 on Fandisk with noise of 0.1 and 0.3
    spacings added). Not the median: on a part of thin walls (the tray, walls 1.2 spacings
    thick) most neighbourhoods span both faces of a wall."""
    noise = float(np.percentile(rms, NOISE_PERCENTILE)) if rms.size else 0.0
    return max(ON_PLANE * spacing, NOISE_TIMES * noise)


@jit_leaf
def _holds_a_plane(X, p, nb, k, tol):
    """Whether a plane through ``p`` and two of ``nb[:k]`` holds ``MIN_ON_PLANE`` of them
    within ``tol``."""
    px, py, pz = X[p, 0], X[p, 1], X[p, 2]
    for i in range(k):
        ax, ay, az = X[nb[i], 0] - px, X[nb[i], 1] - py, X[nb[i], 2] - pz
        a2 = ax * ax + ay * ay + az * az
        for j in range(i + 1, k):
            bx, by, bz = X[nb[j], 0] - px, X[nb[j], 1] - py, X[nb[j], 2] - pz
            nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
            n2 = nx * nx + ny * ny + nz * nz
            if n2 <= MIN_SINE * MIN_SINE * a2 * (bx * bx + by * by + bz * bz):
                continue
            inv = 1.0 / math.sqrt(n2)
            nx, ny, nz = nx * inv, ny * inv, nz * inv
            on = 2
            for t in range(k):
                if t == i or t == j:
                    continue
                q = nb[t]
                h = (X[q, 0] - px) * nx + (X[q, 1] - py) * ny + (X[q, 2] - pz) * nz
                if abs(h) < tol:
                    on += 1
                    if on >= MIN_ON_PLANE:
                        return True
    return False


@jit
def unresolved_points(X, dn, dn_cnt, var, tol, out):
    """``out[p]``: ``p`` is unresolved — ``var[p]`` (:func:`variations`) above
    ``MIN_VARIATION`` and no plane through ``p`` and two of its neighbourhood holds
    ``MIN_ON_PLANE`` of it within ``tol`` (model units)."""
    n = X.shape[0]
    mark, ring, idx, d2 = _buffers(n)
    for p in range(n):
        out[p] = False
        if var[p] <= MIN_VARIATION:
            continue
        k = _nearest(X, p, dn, dn_cnt, mark, ring, idx, d2)
        out[p] = not _holds_a_plane(X, p, idx, k, tol)


def unresolved(X, dn, dn_cnt, spacing):
    """Points of ``X`` (distinct, with local meshes ``dn, dn_cnt``) whose neighbourhood no
    plane through them holds (see the module notes); ``spacing``: the cloud's."""
    n = X.shape[0]
    var = np.empty(n)
    rms = np.empty(n)
    variations(X, dn, dn_cnt, var, rms)
    out = np.empty(n, dtype=bool)
    unresolved_points(X, dn, dn_cnt, var, tolerance(rms, spacing), out)
    return out
