"""Voronoi neighbours ``VN_p``: 3-D Delaunay adjacency, built once and maintained under removal.

Paper §3.1: ``VN_p`` is the set of points whose Voronoi cell shares a *facet* with the cell of
``p``. We take that literally: ``q`` is a Voronoi neighbour of ``p`` when their shared facet has
positive area. Co-spherical points (common in quantised LAS coordinates) make some Delaunay
edges degenerate — their Voronoi facet shrinks to a segment or a point — and Qhull then picks
one diagonal arbitrarily; the positive-area rule drops all of those, so the neighbourhood does
not depend on Qhull's tie-breaking.

Construction
    A 3-D Delaunay triangulation proposes candidate edges; each is kept only if
    :func:`facet_positive` finds a facet of positive area. With a finite reach it is built by
    :mod:`.delaunay` (incremental insertion, compiled; the cloud is closed by guard points),
    else — and if that fails — by ``scipy.spatial.Delaunay`` (Qhull, ``Qbb Qc Qz Q12``). Both
    are given the points shifted by a deterministic pseudo-random ``JITTER`` (1e-10 of the
    extent): on CAD scans with exactly flat faces Qhull otherwise merges facets for minutes (35
    s for 40k Fandisk points, 2 s with the shift), and the floating-point predicates of
    :mod:`.delaunay` meet no exact ties. The shift can only change edges whose facet is
    thinner than ~1e-10 of the diagonal, and those count as degenerate anyway (``TOL_FACTOR``
    = 1e-8).
    Clouds of affine rank 2 (a flat plate) use the 2-D Delaunay of the plane, rank 1 the chain
    along the line, and tiny or Qhull-rejected clouds all pairs or a joggled (``QJ``)
    triangulation as candidates; the positive-area filter then decides on the exact
    coordinates in every case. Most candidates are accepted without clipping: a point of the
    bisector plane found by :func:`facet_witness` (the midpoint, moved once past each
    constraint it violates) that lies well inside every constraint proves the facet positive
    (56-65 % of the candidates of a scan, the Bunny and a flat cloud; the filter 0.53 -> 0.29
    s on 100k scan points, the same edges on all 37 quality cases in both modes).

Maintenance (paper §3.3)
    When ``p`` is removed, the cells of its Voronoi neighbours grow into the space ``p`` owned.
    No existing facet shrinks, so old edges stay; new edges can only join two points of
    ``VN_p``. The new cell of ``a`` is bounded by ``VN_a`` and ``VN_p`` alone (the nearest
    remaining point to anything in ``p``'s old cell is a Voronoi neighbour of ``p``), so each
    candidate pair ``(a, b)`` of ``VN_p`` is decided exactly by clipping its bisector plane with
    the half-spaces of ``VN_a ∪ VN_p`` (:func:`remove_point`). Tests compare the maintained
    lists against a from-scratch construction on the remaining points.

Facets are clipped to a square of half-size ``100 x`` the cloud's diagonal around the pair's
midpoint; facets that lie entirely farther away (only possible between far-apart points on the
convex hull) are ignored. A facet thinner than ``1e-8 x`` the diagonal counts as degenerate.

Reach (beyond the paper)
    With a finite ``reach`` only the part of a facet within ``reach`` of both points counts:
    the disc of radius ``sqrt(reach² - |ab|²/4)`` around the midpoint, where the two balls of
    radius ``reach`` meet the bisector plane — the edges of an alpha complex. The unbounded
    rule joins points through the far ends of their cells: across the inside of a closed
    part, and, on the outside of a flat face of a quantised scan (a few exact layers), each
    point of the sparse outermost layer to hundreds or thousands of face points — the
    maintenance then costs O(degree²) per removal. The maintenance above stays exact: a new
    facet within reach of ``a`` is reached from ``a`` through ``p``'s old cell, so ``a`` and
    ``b`` are within-reach neighbours of ``p``, and inside the ball around ``a`` its cell is
    bounded by its within-reach neighbours alone (tested against rebuilding).
"""

import math

import numpy as np
from scipy.spatial import Delaunay, QhullError

from . import adjacency, cell_grid
from ._jit import jit, jit_leaf
from .bounds import box, extent
from .clip import area, clip, origin_distance2, square
from .delaunay import delaunay_tets
from .linalg import any_perpendicular
from .local_mesh import sort_by_distance

#: half-size of the clipping square, in units of the cloud's bounding-box diagonal
BOX_FACTOR = 100.0
#: facets thinner than this (in units of the diagonal) are degenerate (co-spherical ties)
TOL_FACTOR = 1e-8
#: Qhull sees the points shifted by up to this much (relative to the largest coordinate)
JITTER = 1e-10
#: the length the tolerances above are relative to is at most this many point spacings
#: (:func:`scale_of`): relative to the diagonal alone, one far outlier (a point at the origin
#: of a georeferenced cloud) made every thin facet "degenerate" — the Bunny (0.25 m across,
#: spacings of 1-2 mm) with a point 1e6 m away kept a mean Voronoi degree of 0 instead of
#: 12.7, and lost its edge flags. Clouds up to 1e5 spacings across (every benchmark case)
#: are unchanged
SCALE_SPACINGS = 1e5


#: every this many constraints, :func:`facet_positive` (in the removal loop) tries the
#: clipped polygon's vertex mean as a witness against every constraint, without clipping
CENTROID_AFTER = 6


@jit_leaf
def _vertex_mean(n, xs, ys):
    """The mean of the vertices of the polygon ``(xs, ys)[:n]`` (inside it: it is convex)."""
    sx = 0.0
    sy = 0.0
    for i in range(n):
        sx += xs[i]
        sy += ys[i]
    return sx / n, sy / n


@jit_leaf
def _beyond_by(X, a, b, cand, lo, hi, cx, cy, cz, tol):
    """True if ``c`` (relative to ``a``) lies nearer to ``a`` than to every ``s`` of
    ``cand[lo:hi]`` (not ``a``, ``b``), by at least ``4 tol`` in distance to their bisector
    (``h = |s|² - 2 s·c`` is ``2 |s|`` times that distance)."""
    ax, ay, az = X[a, 0], X[a, 1], X[a, 2]
    for k in range(lo, hi):
        q = cand[k]
        if q == a or q == b:
            continue
        sx, sy, sz = X[q, 0] - ax, X[q, 1] - ay, X[q, 2] - az
        s2 = sx * sx + sy * sy + sz * sz
        h = s2 - 2.0 * (sx * cx + sy * cy + sz * cz)
        if h < 0.0 or h * h < 64.0 * tol * tol * s2:
            return False
    return True


@jit_leaf
def _deep_inside(X, a, b, cand, first, ncand, inside, cx, cy, cz, tol):
    """True if ``c`` (relative to ``a``) lies at least ``4 tol`` inside every constraint of
    :func:`facet_positive`: nearer to ``a`` than to each ``s`` of ``cand[:ncand]`` and nearer
    to ``inside`` than to ``a``. The constraints from ``first`` on (not yet clipped, so the
    likeliest to fail) are checked first."""
    if not _beyond_by(X, a, b, cand, first, ncand, cx, cy, cz, tol):
        return False
    if not _beyond_by(X, a, b, cand, 0, first, cx, cy, cz, tol):
        return False
    ax, ay, az = X[a, 0], X[a, 1], X[a, 2]
    sx, sy, sz = X[inside, 0] - ax, X[inside, 1] - ay, X[inside, 2] - az
    s2 = sx * sx + sy * sy + sz * sz
    h = 2.0 * (sx * cx + sy * cy + sz * cz) - s2
    return h >= 0.0 and h * h >= 64.0 * tol * tol * s2


@jit_leaf
def facet_positive(X, a, b, cand, ncand, half, tol, reach, xa, ya, la, xb, yb, lb, e1, e2,
                   inside):
    """True if points ``a`` and ``b`` share a Voronoi facet of positive area within ``reach``.

    The facet is the bisector plane of ``a`` and ``b`` clipped by the half-space
    ``|x - a| <= |x - s|`` of every ``s`` in ``cand[:ncand]`` (entries equal to ``a`` or ``b``
    are skipped). Each half-space is shrunk by ``tol`` so that a facet of zero width (four or
    more co-spherical points) comes out empty. Only the part of the facet within ``reach`` of
    ``a`` and ``b`` counts — the disc of radius ``sqrt(reach² - |ab|²/4)`` around their
    midpoint, shrunk by ``tol`` too (``inf``: the whole facet, as the paper). If
    ``inside >= 0``, the facet is first clipped to ``|x - inside| <= |x - a|``: after the
    removal of ``inside`` a new facet lies entirely in its former cell, and this one cut
    usually leaves little for the others to empty.

    With ``inside >= 0`` (the removal loop), after every ``CENTROID_AFTER`` constraints the
    mean of the clipped polygon's vertices is tried as a witness, as :func:`facet_witness`
    tries the midpoint: if it lies ``4 tol`` inside every constraint (checked by one dot
    product each, no clipping) and within ``half - 5 tol`` of the midpoint, a disc of radius
    ``3 tol`` around it survives all the clipping, so the facet is positive. No try after the
    last constraint: the area test is cheaper then. The answer is the clipping's (tested
    against the clipping alone on tie-rich grids). The tries made the removal loop's facet
    tests 9-13 % cheaper when a test clipped ~20-24 constraints; with the link-only
    constraints of :func:`remove_point` (~11-14) on against off measured within noise
    (positive tests 1.72k vs 1.74-1.83k TSC ticks on 100k scan points, 2 paired runs), so
    they stay only because they cost nothing either (docs/measurements.md, "Removal loop").
    In the initial filter the polygon is still the whole reach disc after six cuts and the
    tries saved nothing: off there.

    ``xa, ya, la, xb, yb, lb`` are scratch buffers of length at least ``ncand + 5``; ``e1``
    and ``e2`` of length 3 (the facet's frame). A caller that counts references (not a leaf)
    should make them once, outside its loops: it counts every view made in a loop.
    """
    ax, ay, az = X[a, 0], X[a, 1], X[a, 2]
    dx, dy, dz = X[b, 0] - ax, X[b, 1] - ay, X[b, 2] - az
    L = math.sqrt(dx * dx + dy * dy + dz * dz)
    if L == 0.0:
        return False
    r2 = math.inf  # squared radius of the disc the facet must reach into
    if reach < math.inf:
        r = math.sqrt(max(reach * reach - 0.25 * L * L, 0.0)) - tol
        if r <= 0.0:
            return False
        r2 = r * r
        if r < half:
            half = r  # the square around the disc
    u0, u1, u2 = dx / L, dy / L, dz / L
    any_perpendicular(u0, u1, u2, e1)
    e2[0] = u1 * e1[2] - u2 * e1[1]
    e2[1] = u2 * e1[0] - u0 * e1[2]
    e2[2] = u0 * e1[1] - u1 * e1[0]
    mx, my, mz = 0.5 * dx, 0.5 * dy, 0.5 * dz
    rw = half - 5.0 * tol  # a witness this near the midpoint is inside the square and disc
    # (none if the reach disc is thinner than that: a, b almost twice the reach apart)
    until = CENTROID_AFTER if inside >= 0 else -1  # constraints left before the next try
    n = square(half, xa, ya, la)
    cur = 0  # which buffer holds the polygon
    if inside >= 0:
        # |x - inside| <= |x - a|  <=>  -2 s.x' <= -|s|^2 with s = inside - a, x' = x - a
        sx, sy, sz = X[inside, 0] - ax, X[inside, 1] - ay, X[inside, 2] - az
        gx = -2.0 * (sx * e1[0] + sy * e1[1] + sz * e1[2])
        gy = -2.0 * (sx * e2[0] + sy * e2[1] + sz * e2[2])
        h = -(sx * sx + sy * sy + sz * sz) + 2.0 * (sx * mx + sy * my + sz * mz)
        gn = math.sqrt(gx * gx + gy * gy)
        if gn <= 1e-14 * (abs(h) / L + L):
            if h < tol * L:
                return False
        else:
            m = clip(n, xa, ya, la, gx / gn, gy / gn, h / gn - tol, inside, xb, yb, lb)
            if m >= 0:
                n = m
                cur = 1
            if n < 3:
                return False
    for k in range(ncand):
        s = cand[k]
        if s == a or s == b:
            continue
        sx, sy, sz = X[s, 0] - ax, X[s, 1] - ay, X[s, 2] - az
        gx = 2.0 * (sx * e1[0] + sy * e1[1] + sz * e1[2])
        gy = 2.0 * (sx * e2[0] + sy * e2[1] + sz * e2[2])
        h = sx * sx + sy * sy + sz * sz - 2.0 * (sx * mx + sy * my + sz * mz)
        gn = math.sqrt(gx * gx + gy * gy)
        if gn <= 1e-14 * (abs(h) / L + L):
            # s lies on the line ab: it blocks the facet iff it lies between a and b
            if h < tol * L:
                return False
            continue
        gx /= gn
        gy /= gn
        h = h / gn - tol
        if cur == 0:
            m = clip(n, xa, ya, la, gx, gy, h, s, xb, yb, lb)
            if m >= 0:
                n = m
                cur = 1
        else:
            m = clip(n, xb, yb, lb, gx, gy, h, s, xa, ya, la)
            if m >= 0:
                n = m
                cur = 0
        if n < 3:
            return False
        until -= 1
        if until == 0 and k + 1 < ncand:
            until = CENTROID_AFTER
            if cur == 0:
                cx, cy = _vertex_mean(n, xa, ya)
            else:
                cx, cy = _vertex_mean(n, xb, yb)
            if rw > 0.0 and cx * cx + cy * cy < rw * rw and _deep_inside(
                    X, a, b, cand, k + 1, ncand, inside, mx + cx * e1[0] + cy * e2[0],
                    my + cx * e1[1] + cy * e2[1], mz + cx * e1[2] + cy * e2[2], tol):
                return True
    if cur == 0:
        return area(n, xa, ya) > 0.0 and (r2 == math.inf or origin_distance2(n, xa, ya) < r2)
    return area(n, xb, yb) > 0.0 and (r2 == math.inf or origin_distance2(n, xb, yb) < r2)


#: rounds of projections :func:`facet_witness` tries before the clipping decides
WITNESS_ROUNDS = 1


@jit_leaf
def facet_witness(X, a, b, cand, ncand, half, tol, reach):
    """True if a point found without clipping proves the facet of ``a``, ``b`` positive.

    A cheap sufficient test for :func:`facet_positive` (``inside < 0``). A point ``c`` of the
    bisector plane that lies at least ``4 tol`` inside every constraint of ``cand[:ncand]``
    (closer to ``a`` than to ``s`` by that distance to their bisector), and within ``ρ - 5 tol``
    of the midpoint ``m`` — ``ρ`` the radius of the reach disc, ``sqrt(reach² - |ab|²/4)``, or
    the clipping square's ``half`` if smaller — keeps a disc of radius ``3 tol`` around it in
    every shrunk half-plane (the distance within the plane is at least the distance in space)
    and in the square, so the clipped facet has positive area and reaches the reach disc.
    ``c`` starts at ``m`` (a Gabriel edge passes at once: about a third of the Delaunay edges
    of a scan) and is projected, within the bisector plane, past each violated constraint for
    ``WITNESS_ROUNDS`` rounds. False means nothing: the clipping decides.
    """
    ax, ay, az = X[a, 0], X[a, 1], X[a, 2]
    mx, my, mz = 0.5 * (X[b, 0] - ax), 0.5 * (X[b, 1] - ay), 0.5 * (X[b, 2] - az)
    L2 = 4.0 * (mx * mx + my * my + mz * mz)
    if L2 == 0.0:
        return False
    L = math.sqrt(L2)
    r = half  # the clipping square holds the disc of radius half
    if reach < math.inf:
        r = min(r, math.sqrt(max(reach * reach - 0.25 * L2, 0.0)))
    r -= 5.0 * tol
    if r <= 0.0:
        return False
    ux, uy, uz = 2.0 * mx / L, 2.0 * my / L, 2.0 * mz / L
    cx, cy, cz = mx, my, mz  # the witness, relative to a
    for rnd in range(WITNESS_ROUNDS + 1):
        ok = True
        for k in range(ncand):
            q = cand[k]
            if q == a or q == b:
                continue
            sx, sy, sz = X[q, 0] - ax, X[q, 1] - ay, X[q, 2] - az
            s2 = sx * sx + sy * sy + sz * sz
            h = s2 - 2.0 * (sx * cx + sy * cy + sz * cz)  # 2|s| x (distance of c inside)
            if h >= tol * L and h * h >= 64.0 * tol * tol * s2:
                continue
            ok = False
            if rnd == WITNESS_ROUNDS:
                break
            # move c along the in-plane part of s until it is 8 tol inside
            su = sx * ux + sy * uy + sz * uz
            px, py, pz = sx - su * ux, sy - su * uy, sz - su * uz
            p2 = px * px + py * py + pz * pz
            if p2 <= 1e-24 * s2:
                return False  # s on the line ab, blocking it
            t = (16.0 * tol * math.sqrt(s2) - h) / (2.0 * p2)
            cx, cy, cz = cx - t * px, cy - t * py, cz - t * pz
        if ok:
            dx, dy, dz = cx - mx, cy - my, cz - mz
            return dx * dx + dy * dy + dz * dz < r * r
    return False


@jit
def filter_candidates(X, start, cnt, pool, half, tol, reach):
    """Keep the candidate edges whose facet has positive area; returns a (k, 2) edge array.

    The cell of ``a`` is bounded by its candidate neighbours (a superset of its true Voronoi
    neighbours), so they are the constraints for every pair ``(a, b)``, ``a < b``.
    """
    n = start.size
    maxdeg = 0
    for i in range(n):
        if cnt[i] > maxdeg:
            maxdeg = cnt[i]
    size = maxdeg + 5
    xa = np.empty(size)
    ya = np.empty(size)
    la = np.empty(size, dtype=np.int64)
    xb = np.empty(size)
    yb = np.empty(size)
    lb = np.empty(size, dtype=np.int64)
    e1 = np.empty(3)
    e2 = np.empty(3)
    total = 0
    for i in range(n):
        total += cnt[i]
    out = np.empty((total // 2 + 1, 2), dtype=np.int64)
    k = 0
    for a in range(n):
        s = start[a]
        cand = pool[s:s + cnt[a]]
        for j in range(cnt[a]):
            b = cand[j]
            if b <= a:
                continue
            if (facet_witness(X, a, b, cand, cnt[a], half, tol, reach)
                    or facet_positive(X, a, b, cand, cnt[a], half, tol, reach, xa, ya, la, xb,
                                      yb, lb, e1, e2, -1)):
                out[k, 0] = a
                out[k, 1] = b
                k += 1
    return out[:k]


@jit
def _unique_edges(simplices, n):
    """Unique undirected edges ``(i, j)``, ``i < j < n``, of ``simplices``, sorted by
    ``(i, j)`` (edges with an end at ``n`` or above — the guard points — are left out).

    Buckets each edge by its smaller end, then deduplicates and sorts each (short) bucket in
    place: one linear pass instead of ``np.unique`` on all ``d(d-1)/2`` edges of every
    simplex. The buckets are int32 (ids fit: at most ``delaunay.MAX_POINTS``) and the output
    is allocated at its final size — a tetrahedralisation has ~6.6 tetrahedra and ~40 edge
    slots per point, so these arrays set the neighbour stage's peak memory.
    """
    t_n, d = simplices.shape
    count = np.zeros(n + 1, dtype=np.int64)
    for t in range(t_n):
        for i in range(d):
            for j in range(i + 1, d):
                if max(simplices[t, i], simplices[t, j]) < n:
                    count[min(simplices[t, i], simplices[t, j]) + 1] += 1
    for i in range(n):
        count[i + 1] += count[i]
    fill = count[:-1].copy()
    other = np.empty(count[n], dtype=np.int32)
    for t in range(t_n):
        for i in range(d):
            for j in range(i + 1, d):
                u, v = simplices[t, i], simplices[t, j]
                if u > v:
                    u, v = v, u
                if v >= n:
                    continue
                other[fill[u]] = v
                fill[u] += 1
    mark = np.full(n, -1, dtype=np.int64)
    k = 0  # unique edges so far, compacted to the front of ``other``; count[a] becomes the
    # first of a's (count[a + 1] is read before it is overwritten)
    for a in range(n):
        k0 = k
        for t in range(count[a], count[a + 1]):
            b = other[t]
            if mark[b] != a:
                mark[b] = a
                other[k] = b
                k += 1
        for t in range(k0 + 1, k):  # sort the bucket in place (a few entries; no allocation)
            b = other[t]
            j = t
            while j > k0 and other[j - 1] > b:
                other[j] = other[j - 1]
                j -= 1
            other[j] = b
        count[a] = k0
    count[n] = k
    out = np.empty((k, 2), dtype=np.int64)
    for a in range(n):
        for t in range(count[a], count[a + 1]):
            out[t, 0] = a
            out[t, 1] = other[t]
    return out


def _simplex_edges(simplices, n=None):
    """Unique undirected edges (i < j) of a simplicial complex, sorted by (i, j); only those
    between points below ``n`` if given (the real points, not the guards: gathering all
    7.4M edges of the 1M-point scan and filtering them after took 0.1 + 0.15 s more)."""
    simplices = np.asarray(simplices)
    if simplices.dtype not in (np.int32, np.int64):
        simplices = simplices.astype(np.int64)
    simplices = np.ascontiguousarray(simplices)
    if not simplices.size:
        return np.empty((0, 2), np.int64)
    return _unique_edges(simplices, int(simplices.max()) + 1 if n is None else int(n))


def _all_pairs(n):
    i, j = np.triu_indices(n, k=1)
    return np.stack([i, j], axis=1)


def affine_rank(X, rtol=1e-9):
    """Affine dimension of a point set (0 to 3) from the singular values of centred coordinates."""
    if X.shape[0] <= 1:
        return 0
    s = np.linalg.svd(X - X.mean(axis=0), compute_uv=False)
    if s[0] == 0.0:
        return 0
    return int(np.sum(s > rtol * s[0]))


def guard_points(X, reach, rng_seed=54321):
    """Points on a jittered grid (pitch ``2 · reach``) filling the bounding box of ``X``
    grown by ``3 · reach``, each farther than ``2 · reach`` from every point of ``X``.

    Added to the Delaunay triangulation that proposes candidates, they end every cell within a
    few reaches of its point, so Qhull does not build the unbounded cells' far facets (a point
    of the outermost layer of a quantised flat face had 84,372 Delaunay neighbours in one
    142k-point tile; Qhull took 51 s instead of 4). They cannot change an edge within
    ``reach``: for ``y`` within ``reach`` of a point ``a``, a guard ``g`` has
    ``|y - g| >= |a - g| - |y - a| > 2 reach - reach >= |y - a|``, so no guard owns any part
    of a facet the reach rule looks at.
    """
    lo, hi = box(X)
    lo, hi = lo - 3.0 * reach, hi + 3.0 * reach
    pitch = 2.0 * reach
    shape = np.maximum(np.ceil((hi - lo) / pitch).astype(np.int64) + 1, 1)
    while np.prod(shape.astype(float)) > 2.0 * X.shape[0] + 1000:  # at most ~2 per point
        pitch *= 1.5
        shape = np.maximum(np.ceil((hi - lo) / pitch).astype(np.int64) + 1, 1)
    axes = [lo[d] + pitch * np.arange(shape[d]) for d in range(3)]
    G = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    G += np.random.default_rng(rng_seed).uniform(-0.25 * pitch, 0.25 * pitch, G.shape)
    radius = 2.0 * reach * (1.0 + 1e-9)
    # cells of side >= radius: a point within it lies in one of the 27 cells around a guard's
    h = max(pitch, radius) * (1.0 + 1e-6)
    dims = np.ceil((hi + pitch - lo) / h).astype(np.int64) + 2
    return G[far_from_points(X, G, lo - h, h, dims, radius * radius)]


def far_from_points(X, G, lo, h, dims, r2):
    """Whether each of ``G`` is at least ``sqrt(r2)`` from every point of ``X``.

    The points are sorted into cubic cells of side ``h`` (``dims`` cells from ``lo``; ``h`` at
    least the radius, so only the 27 cells around a guard's can hold points within it) by
    :func:`.cell_grid.bucket`, and each guard checks those cells' points until one is within
    the radius (:func:`_far_kernel`). The cKDTree over ``X`` this replaced took 0.13-0.15 s on a
    300k-point tile (a build for one query of ~50k guards); this, ~0.02 s.
    """
    X = np.ascontiguousarray(X, dtype=np.float64)
    ijk = np.clip(((X - lo) / h).astype(np.int64), 0, dims - 1)  # truncation: floor above lo
    cell = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    start, order = cell_grid.bucket(cell, np.arange(X.shape[0]), int(np.prod(dims)))
    return _far_kernel(np.ascontiguousarray(X[order]), start,
                       np.ascontiguousarray(G, dtype=np.float64), lo, h, dims, r2)


@jit_leaf
def _any_within(xyz, start, c, gx, gy, gz, r2):
    """Whether a point of cell ``c`` (``xyz[start[c]:start[c + 1]]``) lies within the radius."""
    for t in range(start[c], start[c + 1]):
        dx, dy, dz = xyz[t, 0] - gx, xyz[t, 1] - gy, xyz[t, 2] - gz
        if dx * dx + dy * dy + dz * dz < r2:
            return True
    return False


@jit
def _far_kernel(xyz, start, G, lo, h, dims, r2):
    """:func:`far_from_points` over points ``xyz`` sorted by cell (CSR ``start``)."""
    far = np.ones(G.shape[0], dtype=np.bool_)
    for g in range(G.shape[0]):
        gx, gy, gz = G[g, 0], G[g, 1], G[g, 2]
        ci = np.int64(np.floor((gx - lo[0]) / h))
        cj = np.int64(np.floor((gy - lo[1]) / h))
        ck = np.int64(np.floor((gz - lo[2]) / h))
        for a in range(max(ci - 1, 0), min(ci + 2, dims[0])):
            for b in range(max(cj - 1, 0), min(cj + 2, dims[1])):
                for k in range(max(ck - 1, 0), min(ck + 2, dims[2])):
                    if far[g] and _any_within(xyz, start, (a * dims[1] + b) * dims[2] + k,
                                              gx, gy, gz, r2):
                        far[g] = False
    return far


def candidate_edges(X, reach=math.inf, scale=None):
    """Candidate Voronoi-neighbour pairs of distinct points ``X`` (a superset of the true ones
    within ``reach``; of all of them if ``reach`` is infinite).

    ``scale`` (:func:`scale_of`): the shift the triangulation sees is ``JITTER`` of it at most
    (of the largest centred coordinate otherwise): a far outlier no longer shifts the others by
    a sizeable share of their spacing. Where ``scale`` is below the diagonal (the cloud spans
    more than ``SCALE_SPACINGS`` spacings) and ``reach`` is finite, points with no other point
    within twice the reach — no facet of theirs can lie within the reach of both its points —
    are left out of the triangulation: with a point 1e9 m away (1e12 of its 1 mm spacings)
    the Bunny spans 2.5e-10 of the unit the predicates work in, and (with the tolerances
    capped alone) kept 49k of its ~250k candidate edges (mean Voronoi degree 1.9) after 10 s.

    Returns ``(edges, how)`` where ``how`` names the construction used.
    """
    n = X.shape[0]
    if n <= 1:
        return np.empty((0, 2), dtype=np.int64), "trivial"
    if n > 5 and math.isfinite(reach) and scale is not None and scale < scale_of(X):
        alone = cell_grid.nearest_other(X) > 2.0 * reach
        if alone.any():
            rest = np.flatnonzero(~alone)
            edges, how = candidate_edges(X[rest], reach, scale)
            return rest[edges], how
    if n <= 5:
        return _all_pairs(n), "all pairs"
    rank = affine_rank(X)
    C = X - X.mean(axis=0)
    extent = np.abs(C).max()
    C = C / extent
    jitter = JITTER if scale is None or scale >= extent else JITTER * (scale / extent)
    C += jitter * np.random.default_rng(12345).uniform(-1.0, 1.0, C.shape)
    if rank <= 1:
        # points on a line: the chain along it
        _, _, vt = np.linalg.svd(C, full_matrices=False)
        order = np.argsort(C @ vt[0], kind="stable")
        return np.stack([order[:-1], order[1:]], axis=1), "line"
    if rank == 2:
        _, _, vt = np.linalg.svd(C, full_matrices=False)
        P = C @ vt[:2].T
        try:
            simplices = Delaunay(P, qhull_options="Qbb Qc Qz Q12").simplices
            how = "plane"
        except QhullError:
            simplices = Delaunay(P, qhull_options="QJ").simplices
            how = "plane, joggled"
    else:
        simplices, how, fallback = None, "delaunay", ""
        if math.isfinite(reach):  # end the far cells (see guard_points)
            G = guard_points(X, reach)
            if G.shape[0]:
                C = np.concatenate([C, (G - X.mean(axis=0)) / extent])
            simplices = delaunay_tets(C)  # ~5x faster than Qhull; None if it failed
            fallback = " (compiled Delaunay failed)"
        if simplices is None:
            try:
                simplices = Delaunay(C, qhull_options="Qbb Qc Qz Q12").simplices
                how = "qhull" + fallback
            except QhullError:
                simplices = Delaunay(C, qhull_options="QJ").simplices
                how = "qhull, joggled" + fallback
    return _simplex_edges(simplices, n), how


def scale_of(X):
    """The length scale the facet tolerances are relative to: the bounding-box diagonal (the
    core caps it at :data:`SCALE_SPACINGS` spacings, ``simplify._scale``)."""
    if X.shape[0] == 0:
        return 1.0
    d = float(np.linalg.norm(extent(X)))
    return d if d > 0.0 else 1.0


def voronoi_neighbours(X, slack=8, scale=None, reach=math.inf):
    """Build the Voronoi-neighbour lists of distinct points ``X`` (n, 3).

    Parameters
    ----------
    X : ndarray (n, 3) float64
        Distinct, finite points (the public wrapper removes exact duplicates first).
    slack : int
        Spare slots per list, for the edges that removals add.
    scale : float, optional
        Length the facet tolerances are relative to; the bounding-box diagonal by default.
    reach : float
        Only facets within this distance of both points count (model units; ``inf``: all).

    Returns
    -------
    (start, cnt, cap, pool, meta) : the :mod:`.adjacency` lists, and ``how``, the name of the
    candidate construction used.
    """
    X = np.ascontiguousarray(X, dtype=np.float64)
    n = X.shape[0]
    D = scale_of(X) if scale is None else float(scale)
    edges, how = candidate_edges(X, reach, D)
    start, cnt, cap, pool, meta = adjacency.from_edges(n, edges, slack=0, room=1)  # read only
    kept = filter_candidates(X, start, cnt, pool, BOX_FACTOR * D, TOL_FACTOR * D, float(reach))
    return adjacency.from_edges(n, kept, slack=slack), how


@jit_leaf
def _nearest_to_midpoint_first(X, a, b, cand, k):
    """Swap the point of ``cand[:k]`` (not ``a`` or ``b``) nearest to the midpoint of ``a`` and
    ``b`` into ``cand[0]``.

    The order of the constraints does not change whether a facet is empty, only how soon the
    clipping finds out: a point near the midpoint (above all one inside the ball with
    diameter ``ab``, nearer to the midpoint than ``a`` and ``b`` are) cuts the facet's middle
    away, usually leaving little for the rest. With the link sorted nearest to ``p`` first as
    well, a pair with no facet is rejected after 4.7 / 4.2 constraints on average instead of
    6.7 / 6.2, and a pair with one is decided after 23.5 / 21.7 instead of 24.3 / 22.2: 21-22 %
    fewer clipping steps (removal loop, ratio 0.2, on 36k points of the Bunny range scans / of
    the Fandisk line scan; 870k / 810k pairs with no facet, 124k / 115k with one). The edges
    found are the same.
    """
    mx = 0.5 * (X[a, 0] + X[b, 0])
    my = 0.5 * (X[a, 1] + X[b, 1])
    mz = 0.5 * (X[a, 2] + X[b, 2])
    best = math.inf
    jb = -1
    for j in range(k):
        c = cand[j]
        if c == a or c == b:
            continue
        ex, ey, ez = X[c, 0] - mx, X[c, 1] - my, X[c, 2] - mz
        e2 = ex * ex + ey * ey + ez * ez
        if e2 < best:
            best = e2
            jb = j
    if jb > 0:
        c = cand[jb]
        cand[jb] = cand[0]
        cand[0] = c


@jit_leaf
def removal_room(start, cnt, pool, p):
    """Free pool slots :func:`remove_point` may need to remove ``p``: each of the ``k`` former
    neighbours gains at most ``k - 1`` entries, and a full list moves to a new place twice
    its capacity (at least 8), so a list ending with ``c`` entries takes at most ``4 c +
    16`` new slots in all."""
    s = start[p]
    k = cnt[p]
    room = 0
    for j in range(k):
        room += 4 * (cnt[pool[s + j]] + k) + 16
    return room


@jit_leaf
def remove_point(X, p, start, cnt, cap, pool, meta, half, tol, reach, link, cand, bufs, lbufs,
                 frame, mark):
    """Remove ``p`` from the Voronoi-neighbour lists and add the facets its removal opens.

    Paper §3.3: "by updating the Voronoi diagram of P" — done exactly and locally. After the
    call ``link[:k]`` holds the former neighbours of ``p``, nearest first (``k`` is
    returned). The pool must have :func:`removal_room` free slots past its used part
    (:func:`.adjacency.with_room`); the lists grow within it. Without them ``-1`` is
    returned, with the lists left half updated.

    ``cand`` must have room for ``cnt[p]`` entries (the constraints: the link); ``bufs``
    (4, m) and ``lbufs`` (2, m) are clipping scratch with ``m >= cnt[p] + 5``. ``mark``
    (int64, one entry per point, all ``-1``) is scratch too; it is left all ``-1``.

    A leaf (:data:`._jit.jit_leaf`: no reference counting): it never allocates, the pool
    included; the caller grows the pool between removals.
    """
    s = start[p]
    k = cnt[p]
    for j in range(k):
        link[j] = pool[s + j]
    cnt[p] = 0
    for j in range(k):
        adjacency.remove(start, cnt, pool, link[j], p)
    # constraints: the former link of p alone. A new facet of a and b lies in p's old cell
    # (the `inside` cut), and there the nearest remaining point is always one of the link: for
    # x in that cell within the reach, with q its nearest point other than p, the ball about
    # x through q holds p and no other point; shrunk towards q it meets p, so p and q share a
    # facet within the reach. The current neighbours of a beyond the link cut nothing there
    # (exactly so; with the tolerances they could only matter in a tie that thin);
    # a test that found a facet used to clip them too (~20-24 constraints instead of the
    # link's ~11-14; 10-17 % cheaper). Same ranks on 14 quality cases in both modes, and the
    # maintained lists equal fresh ones in the tests (quantised, tie-rich clouds too).
    # Most pairs have no facet: the link goes nearest to p first, and for each pair the link
    # point nearest to its midpoint is moved to the front (see _nearest_to_midpoint_first),
    # so the clipped polygon empties after a few constraints.
    # the scratch rows, as views made once
    xa, ya, xb, yb = bufs[0], bufs[1], bufs[2], bufs[3]
    la, lb = lbufs[0], lbufs[1]
    e1, e2 = frame[0], frame[1]
    sort_by_distance(X, p, link, k, link, xa)
    for j in range(k):
        cand[j] = link[j]
    for ia in range(k):
        a = link[ia]
        # mark[q] == a flags the neighbours of a, for the "already neighbours" test
        sa = start[a]
        for j in range(cnt[a]):
            mark[pool[sa + j]] = a
        for ib in range(ia + 1, k):
            b = link[ib]
            if mark[b] == a:
                continue
            if reach < math.inf:  # farther apart than twice the reach: no facet within it
                dx, dy, dz = X[b, 0] - X[a, 0], X[b, 1] - X[a, 1], X[b, 2] - X[a, 2]
                if dx * dx + dy * dy + dz * dz >= 4.0 * reach * reach:
                    continue
            _nearest_to_midpoint_first(X, a, b, cand, k)
            if facet_positive(X, a, b, cand, k, half, tol, reach, xa, ya, la, xb, yb, lb, e1,
                              e2, p):
                if not (adjacency.append_in_place(start, cnt, cap, pool, meta, a, b)
                        and adjacency.append_in_place(start, cnt, cap, pool, meta, b, a)):
                    return -1
                mark[b] = a
        sa = start[a]  # a's list as it is now (it may have moved as it grew)
        for j in range(cnt[a]):
            mark[pool[sa + j]] = -1
    return k
