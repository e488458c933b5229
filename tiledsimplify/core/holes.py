"""Small holes through thin walls: their rims flagged and kept covered (beyond the paper).

A hole a few spacings across drilled through a plate thinner than about two spacings (the
tray's 23 holes in a plate 1.2 spacings thick at 20k points: their widest empty circles 0.8-3
spacings in radius, docs/measurements.md "Small holes through thin walls") shows no
edge to the fits of :mod:`.edge_fit`: the two-ring of a point on its rim holds both faces of
the plate and a wall too short and too curved to fit a plane, and the border test
(:func:`.thin_walls.border_gap`) needs an empty angle of 120° about the point, where a hole
this small leaves some 60-100°. Yet the hole is plain in the plate's plane: an empty circle
wider than any the even sampling leaves between its points.

A point's **empty circle** is the widest circle through it, in the plane of its two-ring's
two sheets (:func:`.thin_walls.own_layer`; the own sheet's plane within 10° of theirs: two
layers by height at an edge are its two faces), that holds none of the points within
``2 HOLE_MAX + 1`` local spacings of it projected there (both sheets: a hole passes through
both). A circle of centre ``t·d`` (``d`` a unit direction in the plane, the point at the
origin) holds ``q`` where ``q·d > |q|² / (2t)``, so the widest in direction ``d`` has ``t =
min |q|² / (2 q·d)`` over the points ahead (``q·d > 0``); the empty circle is the widest over
:data:`DIRECTIONS` directions, refined by a ternary search about the best.

A point is on a **hole's rim** (:func:`hole_rims`) where its empty circle's radius is
:data:`HOLE_MIN` to :data:`HOLE_MAX` local spacings, the circle is closed (a point ahead in
every direction, the circle within the points gathered) and points lie all round its centre
(no empty angle of :data:`SURROUND` or more among those within its radius and a spacing: an
open border is no hole), and where :data:`HOLE_VOTES` such points nearby agree on the centre
(:func:`agreeing_rims`: an even sampling's widest empty circle passes through three points,
but they are rarely this wide). The points within the flags' width of the circle in the
plate's plane, and within ``LAYER_GAP_MAX`` local spacings of it across, are flagged and
made features (:func:`hole_flags`, :func:`.simplify.boundary_flags`): the refinement keeps
them covered as it does the edges.

Measured on the tray (docs/measurements.md "Small holes through thin walls"): inside its
faces the widest empty circle through a point is 0.77 spacings in the median and 1.17 at
most; through its holes' rims 1.2-3 spacings for 12 of the 23 holes, 0.83-1.02 for the
others (no wider than the sampling's own). A point finds a hole only where it lies on the hole's
circle (a point a little outside it sees the wall's points in the way), so a hole is found
by the few sampled points that fall on its rim: 20 points on 4 of the tray's holes (1.6-1.7
spacings in radius), whose flags add 81 points, 79 within a spacing of an edge. The tray's
boundary F1 0.713 -> 0.757, edge coverage 0.947 -> 0.951; counter's edge coverage 0.942 ->
0.944; no other quality case changes.
At a least radius of 1.1 or 1.2 spacings the tray gains more (F1 0.782 / 0.768) but
plate_holes and featuretype get 11-36 false flags; without the two sheets, every even
part's sampling passes for holes (Fandisk F1 0.968 -> 0.785 at 1.2).

The test runs where the thin walls' border test does: on samplings that fill their tangent
planes (:func:`.thin_walls.median_ring_gap`).
"""

import numpy as np

from ._jit import jit, jit_leaf
from .cell_grid import sq_dist
from .edge_lines import MAX_REACH_POINTS, _reach
from .linalg import covariance_about, smallest_axis, tangent_basis
from .thin_walls import LAYER_GAP_MAX, _largest_gap, own_layer
from .two_ring import FIT_RINGS, MAX_RING, gather_rings, median_in_place

#: a hole's rim: the empty circle through the point at least this many local spacings wide
#: (radius; 1.1 and 1.2 found more of the tray's holes but false ones on plate_holes and
#: featuretype, see the module notes) ...
HOLE_MIN = 1.3
#: ... and at most this many (wider holes leave the empty angle of 120° the border test sees);
#: the circle must be empty of the points within twice this and a spacing, reached through
#: the local mesh
HOLE_MAX = 3.0
#: directions tried in the plane for the circle's centre, then steps of a ternary search
#: about the best (the widest lies where two points' bounds cross: a kink, not a smooth top)
DIRECTIONS = 72
REFINE = 24
#: the three-ring's widest circle over ``COARSE_DIRECTIONS`` directions below this share of
#: ``HOLE_MIN`` rules a hole out (fewer points leave wider circles; the coarse directions find
#: the widest within some 10 %)
COARSE_DIRECTIONS = 24
COARSE = 0.75
#: the own sheet's normal within this cosine of the two sheets' (about 10°)
SHEETS_COS = 0.985
#: a hole's rim: at least this many rim points whose circles' centres agree ...
HOLE_VOTES = 3
#: ... within this many cloud spacings
AGREE = 0.5
#: no empty angle this wide (degrees) about the circle's centre among the points near its rim
SURROUND = 120.0


@jit_leaf
def _widest_ahead(pu, pv, m, cx, cy):
    """The radius of the widest circle through the origin, centred in the unit direction
    ``(cx, cy)``, that holds none of the 2-D points ``(pu, pv)[:m]``: ``min |q|² / (2 q·d)``
    over the points ahead (``q·d > 0``); ``inf`` where none is ahead."""
    t = np.inf
    for j in range(m):
        dot = pu[j] * cx + pv[j] * cy
        if dot > 0.0:
            t = min(t, (pu[j] * pu[j] + pv[j] * pv[j]) / (2.0 * dot))
    return t


@jit_leaf
def _project(X, p, ring, k, hmax, normal, u, v, pu, pv):
    """The points of ``ring[:k]`` but ``p`` within ``hmax`` of the plane of ``normal`` through
    ``X[p]``, in the plane's basis (``u``, ``v``, made here) relative to ``X[p]``, into ``pu``,
    ``pv``; returns their count and the largest squared distance among them."""
    tangent_basis(normal, u, v)
    m = 0
    far2 = 0.0
    for j in range(k):
        q = ring[j]
        if q == p:
            continue
        dx, dy, dz = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
        h = dx * normal[0] + dy * normal[1] + dz * normal[2]
        if abs(h) > hmax:
            continue
        a = dx * u[0] + dy * u[1] + dz * u[2]
        b = dx * v[0] + dy * v[1] + dz * v[2]
        if a * a + b * b <= 0.0:
            continue
        pu[m] = a
        pv[m] = b
        far2 = max(far2, a * a + b * b)
        m += 1
    return m, far2


@jit_leaf
def _coarse_widest(pu, pv, m, dirs):
    """The widest of the circles through the origin centred in the directions ``dirs``
    (:func:`_directions`) that hold none of ``(pu, pv)[:m]`` (``inf`` if a direction has no
    point ahead)."""
    best = 0.0
    for i in range(dirs.shape[0]):
        best = max(best, _widest_ahead(pu, pv, m, dirs[i, 0], dirs[i, 1]))
    return best


def _directions(count=DIRECTIONS):
    """``count`` unit directions in the plane, evenly spaced from angle 0, as ``(count, 2)``
    float64."""
    th = 2.0 * np.pi * np.arange(count) / count
    return np.ascontiguousarray(np.c_[np.cos(th), np.sin(th)])


@jit_leaf
def empty_circle(X, p, ring, k, spacing, normal, u, v, pu, pv, ang, centre, dirs):
    """The radius of ``X[p]``'s empty circle among ``ring[:k]`` in the plane of ``normal``
    (see the module notes), its centre into ``centre``; 0 where the circle is not closed —
    a direction with no point ahead, or a circle reaching past the points gathered — or not
    surrounded (an empty angle of ``SURROUND`` or more about its centre among the points
    within its radius plus a ``spacing``). ``u``, ``v``: work vectors (the plane's basis);
    ``pu``, ``pv``, ``ang``: work arrays of length ``k`` or more; ``dirs``: :func:`_directions`."""
    m, far2 = _project(X, p, ring, k, LAYER_GAP_MAX * spacing, normal, u, v, pu, pv)
    if m < 3:
        return 0.0
    best = 0.0
    at = 0.0
    step = 2.0 * np.pi / DIRECTIONS
    for i in range(DIRECTIONS):
        t = _widest_ahead(pu, pv, m, dirs[i, 0], dirs[i, 1])
        if t == np.inf:
            return 0.0  # no point ahead: an open border, not a hole
        if t > best:
            best, at = t, i * step
    # the widest lies where two points' bounds cross: a ternary search about the best direction
    lo, hi = at - step, at + step
    for _ in range(REFINE):
        a, b = lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0
        if (_widest_ahead(pu, pv, m, np.cos(a), np.sin(a))
                < _widest_ahead(pu, pv, m, np.cos(b), np.sin(b))):
            lo = a
        else:
            hi = b
    mid = 0.5 * (lo + hi)
    t = _widest_ahead(pu, pv, m, np.cos(mid), np.sin(mid))
    if t > best:
        best, at = t, mid
    bx, by = np.cos(at), np.sin(at)
    if 2.0 * best + spacing > np.sqrt(far2):
        return 0.0  # the circle reaches past what was gathered
    # surrounded: the points near the circle's rim, seen from its centre
    ccu, ccv = best * bx, best * by
    lim2 = (best + spacing) ** 2
    n = 0
    for j in range(m):
        a, b = pu[j] - ccu, pv[j] - ccv
        if a * a + b * b <= lim2:
            ang[n] = np.arctan2(b, a)
            n += 1
    if n < 3 or _largest_gap(ang, n)[0] >= np.deg2rad(SURROUND):
        return 0.0
    for i in range(3):
        centre[i] = X[p, i] + ccu * u[i] + ccv * v[i]
    return best


@jit
def hole_rims(X, dn, dn_cnt, nn, dirs, coarse, centre, normal, radius):
    """Per point ``p``: ``radius[p]`` the radius of the hole whose rim it is on (model
    units; 0 where it is on none), ``centre[p]`` and ``normal[p]`` the hole's centre and the
    plate's normal (see the module notes). ``nn``: each point's distance to its nearest
    neighbour (:func:`.two_ring.nearest_distances`), whose median over the two-ring is the
    local spacing; ``dirs``: the directions tried (:func:`_directions`), ``coarse``: the fewer
    of the first look (``_directions(COARSE_DIRECTIONS)``)."""
    n = X.shape[0]
    mark = np.zeros(n, dtype=np.int64)
    mark_near = np.zeros(n, dtype=np.int64)
    mark_far = np.zeros(n, dtype=np.int32)
    idx = np.empty(MAX_RING + 1, dtype=np.int64)
    vals = np.empty(MAX_RING + 1)
    h = np.empty(MAX_RING + 1)
    ring = np.empty(MAX_REACH_POINTS, dtype=np.int64)
    pu = np.empty(MAX_REACH_POINTS)
    pv = np.empty(MAX_REACH_POINTS)
    ang = np.empty(MAX_REACH_POINTS)
    work = np.empty(3)
    u = np.empty(3)
    v = np.empty(3)
    for p in range(n):
        radius[p] = 0.0
        idx[0] = p
        c = 1 + gather_rings(p, dn, dn_cnt, FIT_RINGS, mark, idx[1:])
        if c < 6:
            continue
        for j in range(c):
            vals[j] = nn[idx[j]]
        s = median_in_place(vals, c)
        if not s > 0.0:
            continue
        own = own_layer(X, idx, c, s, h, normal[p], work)
        if own == c or own < 4:
            continue  # not two sheets: no thin wall here
        # a plate's two sheets are parallel: the own sheet's plane that of the two together
        # (two layers by height at an edge are its two faces, each tilted off their mean)
        smallest_axis(*covariance_about(X, p, idx[1:], own - 1), u, work)
        if abs(u[0] * normal[p, 0] + u[1] * normal[p, 1] + u[2] * normal[p, 2]) < SHEETS_COS:
            continue
        # a first look over the three-ring: most points' leave no circle wide enough
        k = gather_rings(p, dn, dn_cnt, FIT_RINGS + 1, mark_near, ring)
        m, _ = _project(X, p, ring, k, LAYER_GAP_MAX * s, normal[p], u, v, pu, pv)
        if m >= 3 and _coarse_widest(pu, pv, m, coarse) < COARSE * HOLE_MIN * s:
            continue
        reach = (2.0 * HOLE_MAX + 1.0) * s
        k = _reach(X, dn, dn_cnt, p, reach * reach, mark_far, ring)
        if k >= ring.shape[0]:
            continue  # the walk stopped short of its reach: the circle cannot be judged
        r = empty_circle(X, p, ring, k, s, normal[p], u, v, pu, pv, ang, centre[p], dirs)
        if HOLE_MIN * s <= r <= HOLE_MAX * s:
            radius[p] = r


@jit
def agreeing_rims(X, dn, dn_cnt, centre, radius, spacing, out):
    """``out[p]``: whether rim point ``p`` (``radius[p] > 0``, :func:`hole_rims`) has at least
    ``HOLE_VOTES`` rim points (itself included) within its circle's diameter and a
    ``spacing`` whose circles' centres lie within ``AGREE`` cloud spacings of its own: a
    hole's rim is a ring of such points, an even sampling's widest empty circle one alone."""
    n = X.shape[0]
    mark = np.zeros(n, dtype=np.int32)
    ring = np.empty(MAX_REACH_POINTS, dtype=np.int64)
    tol2 = (AGREE * spacing) ** 2
    for p in range(n):
        out[p] = False
        r = radius[p]
        if not r > 0.0:
            continue
        reach = 2.0 * r + spacing
        votes = 0
        for i in range(_reach(X, dn, dn_cnt, p, reach * reach, mark, ring)):
            q = ring[i]
            if radius[q] > 0.0 and sq_dist(centre, q, centre[p]) <= tol2:
                votes += 1
        out[p] = votes >= HOLE_VOTES


@jit
def hole_flags(X, dn, dn_cnt, centre, normal, radius, width, spacing, out):
    """``out[q]`` set for the points within ``width`` cloud ``spacing``s of a hole's rim
    (:func:`hole_rims`: the circle of ``centre``, ``normal`` and ``radius`` of a point on
    it), in the plate's plane, and within ``LAYER_GAP_MAX`` spacings of it across; the points
    searched are those within the circle's diameter and a width of the rim point, reached
    through the local mesh (``dn``). Other entries are left as they are."""
    n = X.shape[0]
    mark = np.zeros(n, dtype=np.int32)
    ring = np.empty(MAX_REACH_POINTS, dtype=np.int64)
    band = width * spacing
    hmax = LAYER_GAP_MAX * spacing
    for p in range(n):
        r = radius[p]
        if not r > 0.0:
            continue
        reach = 2.0 * r + band
        nx, ny, nz = normal[p, 0], normal[p, 1], normal[p, 2]
        for i in range(_reach(X, dn, dn_cnt, p, reach * reach, mark, ring)):
            q = ring[i]
            dx = X[q, 0] - centre[p, 0]
            dy = X[q, 1] - centre[p, 1]
            dz = X[q, 2] - centre[p, 2]
            h = dx * nx + dy * ny + dz * nz
            if abs(h) > hmax:
                continue
            ex, ey, ez = dx - h * nx, dy - h * ny, dz - h * nz
            if abs(np.sqrt(ex * ex + ey * ey + ez * ez) - r) <= band:
                out[q] = True


def hole_rims_near(X, dn, dn_cnt, nn, width, spacing):
    """The points within ``width`` cloud ``spacing``s of the rim of a small hole through a thin
    wall (bool, one per point of ``X``): :func:`hole_rims`, the rims whose points agree on
    the hole (:func:`agreeing_rims`), then :func:`hole_flags`. ``nn``: each point's distance
    to its nearest neighbour (:func:`.two_ring.nearest_distances`)."""
    m = X.shape[0]
    centre, normal, radius = np.empty((m, 3)), np.empty((m, 3)), np.empty(m)
    hole_rims(X, dn, dn_cnt, nn, _directions(), _directions(COARSE_DIRECTIONS), centre, normal,
              radius)
    agree = np.zeros(m, dtype=bool)
    agreeing_rims(X, dn, dn_cnt, centre, radius, spacing, agree)
    radius[~agree] = 0.0
    out = np.zeros(m, dtype=bool)
    hole_flags(X, dn, dn_cnt, centre, normal, radius, width, spacing, out)
    return out
