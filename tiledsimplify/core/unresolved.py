"""Detail finer than the sampling: points whose neighbourhood no plane through them holds.

Beyond the paper. The edge fits (:mod:`.edge_fit`) find an edge where two planes, a step or a
rim explain a point's two-ring. Detail finer than the point spacing — a thread, a gear's
teeth, a stack of discs a spacing apart — shows no such shape: its points scatter about any
plane, and its smoothed deviation can be as low as a face's (0.007 rad near counter's threads,
where candidates need 0.08; docs/measurements.md "Counter's threaded holes"). Every such
point lies within a spacing or so of the edges of that detail, so it is flagged
(:func:`.simplify.boundary_flags`). Where such points that no fit explains make a region
(:func:`regions`: a threaded hole), the simplification keeps them covered as it does the
edges, if the count has room for it (:func:`.simplify._detail_cover`); scattered ones, where
facets or fillets meet, are flagged only.

A point is **unresolved** where its :data:`NEAREST` nearest points in its two-ring of the
local Voronoi mesh (:func:`.two_ring.gather_rings`) spread off their best plane (surface
variation ``λ0 / (λ0 + λ1 + λ2)`` above :data:`MIN_VARIATION`; Pauly, Gross & Kobbelt 2002)
and no plane through the point and two of them holds :data:`MIN_ON_PLANE` of them within
:data:`ON_PLANE` spacings. (The Voronoi lists ``VN_p`` themselves reach across a part's inside
and far along its faces: their variation is high everywhere, 0.07 in the median on counter.)
A point on a face holds its own plane; a point at a resolved sharp edge lies on one of its two
faces and holds that face's plane; a point of a thin wall holds its own sheet's plane.

The test runs only on **exact, even samplings** (:func:`exact`; even:
:func:`.thin_walls.median_ring_gap`, as for the thin walls' borders) — a CAD model or mesh
sampled, as the benchmark's even parts. Elsewhere what scatters finer than the spacing is
mostly not a part's detail: on the Autzen LiDAR tile (even by the ring gap) the test flagged
13,637 more points of 110,000, their median 19.5 m above the ground — trees; and on a scan,
noise passes for detail (Fandisk with noise of 0.1 spacings added: F1 0.919 -> 0.893 at a
tolerance of 0.1 spacings; docs/measurements.md "Unresolved detail flagged").
"""

import math

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ._jit import jit, jit_leaf
from .linalg import covariance_about, sym3_eigvals
from .local_mesh import sort_by_distance
from .two_ring import MAX_RING, gather_rings

#: the neighbourhood: this many nearest points of the two-ring (the point itself not counted)
NEAREST = 11
#: least surface variation of an unresolved point's neighbourhood (in a prototype over the 12
#: nearest points, 0.04 and 0.08 gave F1 within 0.004 of this on counter, cycloidal, the tray
#: and ADIS16480)
MIN_VARIATION = 0.06
#: a plane through the point holding at least this many of its neighbours (the two that fix
#: it included) within ``ON_PLANE`` spacings resolves it
MIN_ON_PLANE = 5
#: a point lies on a plane within this many cloud spacings
ON_PLANE = 0.07
#: the sampling is exact where the quietest ``NOISE_PERCENTILE`` % of the points lie within
#: this many spacings (RMS) of their neighbourhood's plane: 0 on the CAD parts sampled evenly,
#: 0.026 on the Bunny, 0.028 on the Autzen tile, 0.056 on Fandisk with noise of 0.1 spacings
MAX_NOISE = 0.01
NOISE_PERCENTILE = 5.0
#: ... of about this many points spread through the cloud (every ``n // EXACT_SAMPLE``-th, as
#: :func:`.thin_walls.median_ring_gap` samples): a sampling that is not exact costs no pass
#: over every point
EXACT_SAMPLE = 4096
#: two neighbours fix a plane with the point only where the sine of their angle seen from it
#: is at least this
MIN_SINE = 0.2
#: unresolved points this many cloud spacings apart or closer are of one region (:func:`regions`)
REGION_LINK = 1.5
#: where the sampling is not exact, points whose smoothed deviation exceeds this (radians)
#: and that no fitted line explains are detail (:func:`rough_regions`). Lower thresholds find
#: regions where a part has no detail finer than the spacing: Fandisk's noise-0.1 scan held
#: 430 such points at 0.25 and 57 at 0.30, none at 0.35; at 0.25 ADIS16480's noise-0.1 scan
#: lost its Hausdorff bound (1.21x the best peer's)
ROUGH_DEVIATION = 0.35
#: ... linked within this many cloud spacings (a line scan's lines lie up to four apart)
ROUGH_LINK = 2.5
#: a region of detail holds at least this many points (:func:`regions`; counter's five threaded
#: holes hold 58-73 each at 20k points, featuretype's largest group of unresolved points 24;
#: at 30 counter's coverage is the same and ADIS16480's mean error 1.3 % higher)
MIN_REGION = 50


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
def variations(X, dn, dn_cnt, ids, var, rms):
    """Per point ``p`` of ``ids``: the surface variation of ``p`` and its neighbourhood (see the
    module notes) into ``var[p]``, and the RMS distance of those points from their best plane,
    ``sqrt(λ0)``, into ``rms[p]`` (``inf`` with fewer than three neighbours); the other
    entries are left as they are."""
    mark, ring, idx, d2 = _buffers(X.shape[0])
    for p in ids:
        k = _nearest(X, p, dn, dn_cnt, mark, ring, idx, d2)
        if k < 3:  # no neighbourhood: not a quiet point of a face either
            var[p] = 0.0
            rms[p] = np.inf
            continue
        l0, l1, l2 = sym3_eigvals(*covariance_about(X, p, idx, k))
        l0 = max(l0, 0.0)
        total = l0 + max(l1, 0.0) + max(l2, 0.0)
        var[p] = l0 / total if total > 0.0 else 0.0
        rms[p] = math.sqrt(l0)


def exact(rms, spacing):
    """Whether the sampling is exact: the ``NOISE_PERCENTILE``-th percentile of ``rms``
    (:func:`variations`) at most ``MAX_NOISE`` spacings. The quietest points lie on faces,
    where their RMS is ~0.55 of the noise (0.56 and 0.59 on Fandisk with noise of 0.1 and
    0.3 spacings added). Not the median: on a part of thin walls (the tray, walls 1.2 spacings
    thick at 20k points) most neighbourhoods span both faces of a wall, and so do the quietest
    (0.48 spacings): there the test does not run."""
    return rms.size > 0 and float(np.percentile(rms, NOISE_PERCENTILE)) <= MAX_NOISE * spacing


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


def exact_sampling(X, dn, dn_cnt, spacing):
    """Whether the points ``X`` (distinct, with local meshes ``dn, dn_cnt``) are an exact
    sampling (:func:`exact`), judged on about ``EXACT_SAMPLE`` of them; ``spacing``: the
    cloud's."""
    n = X.shape[0]
    if n == 0 or not spacing > 0:
        return False
    var = np.zeros(n)
    rms = np.full(n, np.inf)
    sample = np.arange(0, n, max(1, n // EXACT_SAMPLE), dtype=np.int64)
    variations(X, dn, dn_cnt, sample, var, rms)
    return exact(rms[sample], spacing)


def unresolved(X, dn, dn_cnt, spacing, exact=None):
    """Points of ``X`` (distinct, with local meshes ``dn, dn_cnt``) whose neighbourhood no
    plane through them holds, if the sampling is exact (:func:`exact_sampling`, unless the
    caller already knows it: ``exact``; see the module notes; none else); ``spacing``: the
    cloud's."""
    n = X.shape[0]
    out = np.zeros(n, dtype=bool)
    if exact is None:
        exact = exact_sampling(X, dn, dn_cnt, spacing)
    if not exact or n == 0 or not spacing > 0:
        return out
    var = np.zeros(n)
    rms = np.full(n, np.inf)
    variations(X, dn, dn_cnt, np.arange(n, dtype=np.int64), var, rms)
    unresolved_points(X, dn, dn_cnt, var, ON_PLANE * spacing, out)
    return out


def regions(X, unresolved_mask, spacing, link=None):
    """The unresolved points (``unresolved_mask``, of :func:`unresolved`) that lie in regions of
    detail: groups of at least :data:`MIN_REGION` of them, linked where two lie within
    ``link`` (default :data:`REGION_LINK`) ``spacing`` of each other. A threaded hole is one
    such region (counter's five, 58-73 points each at 20k points); a few unresolved points
    where facets or fillets meet are not (featuretype's 269 fall into 88 groups, the largest of
    24)."""
    out = np.zeros(X.shape[0], dtype=bool)
    ids = np.flatnonzero(unresolved_mask)
    if ids.size < MIN_REGION or not spacing > 0:
        return out
    link = REGION_LINK if link is None else link
    pairs = cKDTree(X[ids]).query_pairs(link * spacing, output_type="ndarray")
    links = coo_matrix((np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])),
                       shape=(ids.size, ids.size))
    _, label = connected_components(links, directed=False)
    size = np.bincount(label)
    out[ids[size[label] >= MIN_REGION]] = True
    return out


def rough_regions(X, deviation, features, spacing):
    """Regions of detail where :func:`unresolved` does not run (a sampling that is not exact,
    or does not fill its tangent planes: a scan, LiDAR): the points whose
    smoothed deviation (:func:`.two_ring.smoothed_deviations`) exceeds
    :data:`ROUGH_DEVIATION` and which no fitted line explains (not ``features``), in groups of
    at least :data:`MIN_REGION` linked within :data:`ROUGH_LINK` ``spacing`` (:func:`regions`).

    Beyond the paper. On a scan, noise passes for detail finer than the spacing
    (:func:`unresolved` does not run), but detail that the scanner resolves — counter's
    threaded holes, seen as rows of scan lines — turns the normals of its two-rings far more
    than noise or any face does: the points near counter's densest edges have a median
    deviation of 0.45 rad on its noise-0.1 scan, the points away from every edge 0.02. They
    are not flagged (no fit places a line in them) and, like the regions of an exact sampling,
    are kept covered where their cover fits within ``edge_share``
    (:func:`.simplify._detail_cover`): counter's scans' edge coverage 0.457 -> 0.511 and
    0.450 -> 0.519 (CGAL hierarchy's 0.490 and 0.471; docs/measurements.md "Regions of detail
    on scans"). The link is wider than an exact sampling's: a line scan's lines lie up to
    four spacings apart, and at 1.5 spacings a thread's points fall into groups of one line
    each, too small to count (counter's noise-0.1 scan: 50 points in regions at 0.35 rad,
    194 at 0.25 and its coverage 0.478).
    """
    return regions(X, (np.asarray(deviation) > ROUGH_DEVIATION) & ~np.asarray(features),
                   spacing, ROUGH_LINK)
