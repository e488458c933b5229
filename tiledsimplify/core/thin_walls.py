"""Thin walls, steps and rims: two-rings in two parallel sheets (step 2 of :mod:`.edge_fit`,
since 2026-12-06).

- **Thin walls**: where a two-ring's heights over its mean plane fall into two sheets
  ``LAYER_GAP_MIN`` to ``LAYER_GAP_MAX`` local spacings apart (a wall thinner than the
  two-ring, whose two faces the local mesh joins), only the point's own sheet is fitted
  (:func:`own_layer`).
- **Steps** lower than the spacing: two parallel layers side by side, the wall between them
  holding few points or none (counter's rib, :func:`fit_step`).
- **Rims**: a plate thinner than about two spacings ends where both sheets end together along
  a line past which nothing lies (:func:`fit_rim`, :func:`rim_clear`). Where no rim fits and
  the sampling fills its tangent planes (:func:`median_ring_gap`), a **border**: an empty angle
  about the point (:func:`border_gap`).
"""

import numpy as np

from ._jit import jit, jit_leaf
from .cell_grid import sq_dist
from .linalg import covariance_about, smallest_axis, tangent_basis
from .two_planes import MIN_SIDE
from .two_ring import MAX_RING, gather_rings, sort_in_place


#: a two-ring whose heights over its mean plane fall into two layers at least this many local
#: spacings apart (:func:`own_layer`) ...
LAYER_GAP_MIN = 0.5
#: ... and at most this many (farther layers are two surfaces the local mesh rarely joins) ...
LAYER_GAP_MAX = 3.0
#: ... each layer's RMS height about its mean at most this fraction of the gap, is two sheets —
#: a thin wall's faces, the faces two scan views saw of it — and the fit takes the point's own
#: (measured on the 36 CAD quality cases, docs/measurements.md "Thin walls: each sheet fitted
#: alone": 0.25 against 0.3, whose layers are also the two faces of some edges)
LAYER_RMS = 0.25
#: ... two parallel layers, their heights' means this many local spacings apart at least ...
STEP_GAP_MIN = 0.45
#: ... and at most (a taller step has a wall the two-plane fits see) ...
STEP_GAP_MAX = 1.5
#: ... each layer's RMS height about its mean at most this fraction of the gap ...
STEP_RMS = 0.25
#: ... each layer's own plane within this cosine of the other's and of the heights' normal ...
STEP_PARALLEL = 0.99
#: ... and the layers side by side: at most this share of the points on the wrong side of the
#: best line between them in the layers' plane (a thin wall's faces overlap; measured on
#: counter's rib and the 36 CAD quality cases, docs/measurements.md "Steps lower than a
#: spacing")
STEP_MIXED = 0.1
#: a candidate in two sheets that no other fit gives an edge is tried as a thin wall's rim
#: (:func:`fit_rim`): its two-ring's mean offset in the sheets' plane at least this many local
#: spacings from the point (the two-ring lies to one side of it) ...
RIM_OFFSET = 0.6
#: ... both sheets reaching within this many local spacings of the farther one's border ...
RIM_TOGETHER = 1.0
#: ... the point within this many local spacings of that border ...
RIM_REACH = 1.0
#: ... and no point of its three-ring beyond the border by more than this many local spacings,
#: as far as the three-ring reaches behind the point (:func:`rim_clear`; measured on the 36
#: CAD quality cases, docs/measurements.md "Thin walls' rims")
RIM_CLEAR = 0.5
#: a thin wall's border where no rim fits (:func:`border_gap`; measured on the 39 quality
#: cases, docs/measurements.md "A thin wall's border"): the points of the three-ring within
#: ``BORDER_REACH`` local spacings, projected on the sheets' plane, leave an empty angle of at
#: least ``BORDER_GAP`` degrees about the point (100 / 140: the tray's F1 0.720 / 0.714, at
#: precision 0.733 / 0.816; 0.713 at 0.795 with 120) ...
BORDER_REACH = 2.5
BORDER_GAP = 120.0
#: ... and none other wider than ``BORDER_SECOND`` degrees, among ``BORDER_MIN`` points or more
BORDER_SECOND = 75.0
BORDER_MIN = 6
#: the border test needs a sampling that fills the tangent plane: a line scan leaves empty
#: angles of 180° between its lines everywhere. Filled: the median empty angle of the points'
#: two-rings (:func:`median_ring_gap`) below this many degrees: 52-60° on the 12 evenly
#: sampled CAD parts of the quality cases, 177-181° on their 24 line scans; the Bunny 53°,
#: Autzen's LiDAR 82°, the Bunny's ten range scans 110°
FILLED_GAP = 90.0


@jit_leaf
def _two_means(h, c):
    """A 1-D 2-means of ``h[:c]`` (Lloyd's rounds from the midrange, at most 8):
    ``(ok, cut, m0, m1, k0, k1, v0, v1)`` — the cut, each layer's mean, count and sum of
    squared deviations from its mean (``h > cut``: layer 1); ``ok`` False where a layer
    holds fewer than ``MIN_SIDE`` points."""
    lo = np.inf
    hi = -np.inf
    for j in range(c):
        lo = min(lo, h[j])
        hi = max(hi, h[j])
    cut = 0.5 * (lo + hi)
    m0 = m1 = 0.0
    k0 = k1 = 0
    for _ in range(8):  # Lloyd's rounds in 1-D: the cut halfway between the layers' means
        m0 = m1 = 0.0
        k0 = k1 = 0
        for j in range(c):
            if h[j] > cut:
                m1 += h[j]
                k1 += 1
            else:
                m0 += h[j]
                k0 += 1
        if k0 < MIN_SIDE or k1 < MIN_SIDE:
            return False, cut, 0.0, 0.0, k0, k1, 0.0, 0.0
        m0 /= k0
        m1 /= k1
        if 0.5 * (m0 + m1) == cut:
            break
        cut = 0.5 * (m0 + m1)
    v0 = v1 = 0.0
    for j in range(c):
        if h[j] > cut:
            v1 += (h[j] - m1) ** 2
        else:
            v0 += (h[j] - m0) ** 2
    return True, cut, m0, m1, k0, k1, v0, v1


@jit
def fit_step(X, normals, idx, c, spacing, h, a, line, t1, t2, work):
    """A step lower than the spacing at ``idx[0]``: ``distance`` from it to the step's edge
    (``inf`` where ``idx[:c]`` is no step), the edge into ``line`` (:func:`.two_planes.edge_line`'s
    form).

    Beyond the paper. A face that steps up by less than a spacing — counter's rib, 1.5 mm tall
    at a 2.25 mm spacing — has a wall with few or no points, so no two-plane fit finds its
    edges, and the two-ring's PCA plane tilts across the step, mixing the levels' heights.
    Here the heights are taken along each point's one-ring normal in turn (``normals``) and
    split by a 1-D 2-means (:func:`_two_means`); the normal whose two layers lie
    ``STEP_GAP_MIN``-``STEP_GAP_MAX`` local ``spacing``s apart with the least RMS height
    about their means (at most ``STEP_RMS`` of the gap) is the step's. Both layers' own
    planes must be parallel to it and to each other (``STEP_PARALLEL``: a curved face split
    by height is not), and the layers must lie side by side in that plane: a line
    separates them with at most ``STEP_MIXED`` of the points on its wrong side (a thin wall's
    two faces lie one over the other). The edge runs along that line at the layers' mid
    height, across ``u``, the direction from the lower layer's centre to the upper's; both of
    the step's edges lie within half its height of it. ``h``, ``a``: work arrays of length
    ``c`` or more; ``t1``, ``t2``, ``work``: length 3.
    """
    p = idx[0]
    if c < 2 * MIN_SIDE + 1:
        return np.inf
    best = np.inf
    bq = -1
    for jq in range(c):
        q = idx[jq]
        for j in range(c):
            r = idx[j]
            h[j] = ((X[r, 0] - X[p, 0]) * normals[q, 0] + (X[r, 1] - X[p, 1]) * normals[q, 1]
                    + (X[r, 2] - X[p, 2]) * normals[q, 2])
        ok, cut, m0, m1, k0, k1, v0, v1 = _two_means(h, c)
        if not ok:
            continue
        gap = m1 - m0
        if gap < STEP_GAP_MIN * spacing or gap > STEP_GAP_MAX * spacing:
            continue
        score = max(v0 / k0, v1 / k1) / (gap * gap)
        if score < best:
            best = score
            bq = q
    if bq < 0 or best > STEP_RMS * STEP_RMS:
        return np.inf
    nx, ny, nz = normals[bq, 0], normals[bq, 1], normals[bq, 2]
    for j in range(c):
        r = idx[j]
        h[j] = (X[r, 0] - X[p, 0]) * nx + (X[r, 1] - X[p, 1]) * ny + (X[r, 2] - X[p, 2]) * nz
    ok, cut, m0, m1, k0, k1, v0, v1 = _two_means(h, c)
    # each layer's own plane parallel to the other's and to the heights' normal
    n0 = np.empty(3)
    n1 = np.empty(3)
    sub = np.empty(c, dtype=np.int64)
    for which in range(2):
        k = 0
        for j in range(c):
            if (h[j] > cut) == (which == 1):
                sub[k] = idx[j]
                k += 1
        out = n0 if which == 0 else n1
        smallest_axis(*covariance_about(X, sub[0], sub[1:k], k - 1), out, work)
        if abs(out[0] * nx + out[1] * ny + out[2] * nz) < STEP_PARALLEL:
            return np.inf
    if abs(n0[0] * n1[0] + n0[1] * n1[1] + n0[2] * n1[2]) < STEP_PARALLEL:
        return np.inf
    # side by side: the best cut along the direction between the layers' centres
    work[0], work[1], work[2] = nx, ny, nz
    tangent_basis(work, t1, t2)
    u1 = u2 = 0.0
    for j in range(c):
        r = idx[j]
        x1 = (X[r, 0] - X[p, 0]) * t1[0] + (X[r, 1] - X[p, 1]) * t1[1] + (X[r, 2] - X[p, 2]) * t1[2]
        x2 = (X[r, 0] - X[p, 0]) * t2[0] + (X[r, 1] - X[p, 1]) * t2[1] + (X[r, 2] - X[p, 2]) * t2[2]
        if h[j] > cut:
            u1 += x1 / k1
            u2 += x2 / k1
        else:
            u1 -= x1 / k0
            u2 -= x2 / k0
    un = np.sqrt(u1 * u1 + u2 * u2)
    if not un > 0.0:
        return np.inf
    u1 /= un
    u2 /= un
    ux = u1 * t1[0] + u2 * t2[0]  # u in space
    uy = u1 * t1[1] + u2 * t2[1]
    uz = u1 * t1[2] + u2 * t2[2]
    for j in range(c):
        r = idx[j]
        a[j] = (X[r, 0] - X[p, 0]) * ux + (X[r, 1] - X[p, 1]) * uy + (X[r, 2] - X[p, 2]) * uz
    order = np.argsort(a[:c])
    wrong = k0  # cut before the first point: every lower point on the upper side
    least = wrong
    at = 0
    for i in range(c):
        if h[order[i]] > cut:
            wrong += 1
        else:
            wrong -= 1
        if wrong < least:
            least = wrong
            at = i + 1
    if least > STEP_MIXED * c:
        return np.inf
    lo_a = a[order[at - 1]] if at > 0 else a[order[0]]
    hi_a = a[order[at]] if at < c else a[order[c - 1]]
    off = 0.5 * (lo_a + hi_a)
    mid = 0.5 * (m0 + m1)
    line[0] = X[p, 0] + off * ux + mid * nx
    line[1] = X[p, 1] + off * uy + mid * ny
    line[2] = X[p, 2] + off * uz + mid * nz
    dx, dy, dz = ny * uz - nz * uy, nz * ux - nx * uz, nx * uy - ny * ux
    dn = np.sqrt(dx * dx + dy * dy + dz * dz)
    line[3], line[4], line[5] = dx / dn, dy / dn, dz / dn
    return np.sqrt(off * off + mid * mid)


@jit
def fit_rim(X, idx, c, spacing, h, normal, line, out_dir):
    """A thin wall's rim at ``idx[0]``: the distance from it to the rim's edge on its own sheet
    (``inf`` where ``idx[:c]`` shows no rim), the edge into ``line``
    (:func:`.two_planes.edge_line`'s form), the direction from the point across the edge, in the
    sheets' plane, into ``out_dir``. ``normal``: the two-ring's PCA normal, as :func:`own_layer`
    left it.

    Beyond the paper. Where a plate is thinner than about two spacings (the tray, 3.18 mm at a
    2.63 mm spacing) its rim face holds a point or two across, and each sheet of its two-ring
    (:func:`own_layer`) is a plane that ends: no two-plane fit, step or corner finds the edge
    (876 of the tray's 1,013 missed edge points had no fit). Here the two-ring
    ``idx[:c]`` — both sheets — is taken in its PCA plane: it lies to one side of the point
    where its mean offset in that plane is ``RIM_OFFSET`` local spacings (``spacing``) or
    more, and the border runs across that offset, through the farthest point the other way.
    Both sheets (a 1-D 2-means of the heights, :func:`_two_means`) must reach within
    ``RIM_TOGETHER`` of that border — a wall's faces end together — and the point must lie
    within ``RIM_REACH`` of it. The edge is the border's line in the point's own sheet.
    ``h``: work array of length ``c`` or more.
    """
    p = idx[0]
    if c < 2 * MIN_SIDE + 1:
        return np.inf
    nx, ny, nz = normal[0], normal[1], normal[2]
    gx = gy = gz = 0.0
    for j in range(c):
        q = idx[j]
        dx, dy, dz = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
        hj = dx * nx + dy * ny + dz * nz
        h[j] = hj
        gx += dx - hj * nx
        gy += dy - hj * ny
        gz += dz - hj * nz
    g = np.sqrt(gx * gx + gy * gy + gz * gz)
    if g < RIM_OFFSET * spacing * c:
        return np.inf
    bx, by, bz = -gx / g, -gy / g, -gz / g  # across the border, away from the two-ring
    ok, cut, m0, m1, k0, k1, v0, v1 = _two_means(h, c)
    if not ok:
        return np.inf
    d0 = d1 = -np.inf
    for j in range(c):
        q = idx[j]
        a = (X[q, 0] - X[p, 0]) * bx + (X[q, 1] - X[p, 1]) * by + (X[q, 2] - X[p, 2]) * bz
        if h[j] > cut:
            d1 = max(d1, a)
        else:
            d0 = max(d0, a)
    d = max(d0, d1)
    if min(d0, d1) < d - RIM_TOGETHER * spacing or d > RIM_REACH * spacing:
        return np.inf
    out_dir[0], out_dir[1], out_dir[2] = bx, by, bz
    line[0] = X[p, 0] + d * bx
    line[1] = X[p, 1] + d * by
    line[2] = X[p, 2] + d * bz
    line[3] = ny * bz - nz * by  # normal × out_dir: both unit and orthogonal
    line[4] = nz * bx - nx * bz
    line[5] = nx * by - ny * bx
    return d


@jit_leaf
def rim_clear(X, p, ring, k, d, spacing, out_dir, normal):
    """Whether nothing lies beyond the rim :func:`fit_rim` found ``d`` from ``X[p]`` across
    ``out_dir``: no point of ``ring[:k]`` (the point's three-ring) within ``LAYER_GAP_MAX``
    local spacings (``spacing``) of its sheet's plane (``normal``) lies more than ``RIM_CLEAR``
    spacings past the border and nearer to it than the farthest point lies behind.

    Beyond the paper. On a line scan a point's local mesh may join the lines on one side of
    its own only, and so its two-ring ends one spacing past it, like a rim's (the tray's
    scans: 37 of 104 such fits at 8-27 spacings from any edge, on both faces' lines); the
    next line lies some four local spacings on, within the three-ring. ``ring``: the point's
    three-ring (:func:`.two_ring.gather_rings`)."""
    back = 0.0
    for j in range(k):
        q = ring[j]
        a = ((X[q, 0] - X[p, 0]) * out_dir[0] + (X[q, 1] - X[p, 1]) * out_dir[1]
             + (X[q, 2] - X[p, 2]) * out_dir[2])
        back = max(back, -a)
    for j in range(k):
        q = ring[j]
        dx, dy, dz = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
        a = dx * out_dir[0] + dy * out_dir[1] + dz * out_dir[2]
        hq = dx * normal[0] + dy * normal[1] + dz * normal[2]
        if d + RIM_CLEAR * spacing < a < d + back and abs(hq) <= LAYER_GAP_MAX * spacing:
            return False
    return True


@jit_leaf
def _largest_gap(ang, m):
    """``(largest, second, start)``: the two widest empty angles between the angles
    ``ang[:m]`` (radians, m >= 2; sorted here, in place: :func:`.two_ring.sort_in_place`), the
    widest's start angle."""
    sort_in_place(ang, m)
    largest = second = 0.0
    start = 0.0
    for i in range(m):
        g = (ang[i + 1] if i + 1 < m else ang[0] + 2.0 * np.pi) - ang[i]
        if g > largest:
            second = largest
            largest = g
            start = ang[i]
        elif g > second:
            second = g
    return largest, second, start


@jit
def border_gap(X, p, ring, k, spacing, normal, ang, line, u, v):
    """A thin wall's border at ``X[p]``: 0 with the border's line through the point into
    ``line`` where ``ring[:k]`` (its three-ring) leaves an empty angle about it, ``inf``
    where it does not. The points within ``LAYER_GAP_MAX`` local spacings (``spacing``) of
    the sheets' plane (``normal``: both sheets, a hole passes through both) and within
    ``BORDER_REACH`` of the point, projected on that plane, must leave one empty angle of
    ``BORDER_GAP`` or more and no other of ``BORDER_SECOND``; the line runs in the plane across
    the empty angle's bisector. ``ang``: work array of length ``k`` or more; ``u``, ``v``:
    work vectors (the plane's basis).

    Beyond the paper. A rim (:func:`fit_rim`) needs the whole two-ring to one side of the
    point, both sheets ending together within a spacing. The empty angle about a point is the
    classic border test of an open surface's sampling (PCL's boundary estimation takes 90°):
    inside the tray's faces, evenly sampled, the widest is 48-78° (10th-90th percentile); it
    exceeds 100° at 85 % of the points within half a spacing of an edge (both measured on the
    point's own sheet, docs/measurements.md "A thin wall's border"). In ``simplify_points``
    it adds 99 to the tray's 303 rim fits, all 402 within a spacing of an edge, along its outer rim
    and slot where :func:`fit_rim`'s tests fail: F1 0.682 -> 0.713. Not its small holes (3.8
    spacings across at 20k points): a hole's wall projects onto its circle, whose points fill
    all but some 100° about a point on it. On line scans the angle reads 180° everywhere:
    :func:`.edge_fit.localise` tries it only on samplings that fill the plane (``FILLED_GAP``).
    """
    nx, ny, nz = normal[0], normal[1], normal[2]
    tangent_basis(normal, u, v)
    r2 = (BORDER_REACH * spacing) ** 2
    hmax = LAYER_GAP_MAX * spacing
    m = 0
    for j in range(k):
        q = ring[j]
        if q == p:
            continue
        dx, dy, dz = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
        h = dx * nx + dy * ny + dz * nz
        if abs(h) > hmax:
            continue
        tx, ty, tz = dx - h * nx, dy - h * ny, dz - h * nz
        t2 = tx * tx + ty * ty + tz * tz
        if t2 > r2 or t2 <= 0.0:
            continue
        ang[m] = np.arctan2(tx * v[0] + ty * v[1] + tz * v[2], tx * u[0] + ty * u[1] + tz * u[2])
        m += 1
    if m < BORDER_MIN:
        return np.inf
    largest, second, start = _largest_gap(ang, m)
    if largest < np.deg2rad(BORDER_GAP) or second >= np.deg2rad(BORDER_SECOND):
        return np.inf
    mid = start + 0.5 * largest
    bx = np.cos(mid) * u[0] + np.sin(mid) * v[0]
    by = np.cos(mid) * u[1] + np.sin(mid) * v[1]
    bz = np.cos(mid) * u[2] + np.sin(mid) * v[2]
    line[0], line[1], line[2] = X[p, 0], X[p, 1], X[p, 2]
    line[3] = ny * bz - nz * by  # normal × the bisector: both unit and orthogonal
    line[4] = nz * bx - nx * bz
    line[5] = nx * by - ny * bx
    return 0.0


@jit
def median_ring_gap(X, normals, dn, dn_cnt, spacing, n_sample):
    """The median, over about ``n_sample`` points spread through ``X`` (every
    ``len(X) // n_sample``-th), of the widest empty angle (degrees) about each point among its
    two-ring's points within ``BORDER_REACH`` cloud ``spacing``s, projected on its tangent
    plane (``normals``): whether a sampling fills its tangent planes (below ``FILLED_GAP``), as
    :func:`border_gap` needs. 360 where fewer than two points are in reach.
    """
    n = X.shape[0]
    if n < 3:
        return 360.0
    step = max(1, n // max(1, n_sample))
    mark = np.zeros(n, dtype=np.int64)
    idx = np.empty(MAX_RING, dtype=np.int64)
    ang = np.empty(MAX_RING)
    u = np.empty(3)
    v = np.empty(3)
    r2 = (BORDER_REACH * spacing) ** 2
    gaps = np.empty(n // step + 1)
    g = 0
    for p in range(0, n, step):
        c = gather_rings(p, dn, dn_cnt, 2, mark, idx)
        if c < 3:
            gaps[g] = 360.0
            g += 1
            continue
        tangent_basis(normals[p], u, v)
        m = 0
        for j in range(c):
            q = idx[j]
            d2 = sq_dist(X, q, X[p])
            if d2 > r2 or d2 <= 0.0:
                continue
            dx, dy, dz = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
            ang[m] = np.arctan2(dx * v[0] + dy * v[1] + dz * v[2],
                                dx * u[0] + dy * u[1] + dz * u[2])
            m += 1
        if m < 2:
            gaps[g] = 360.0
        else:
            gaps[g] = np.rad2deg(_largest_gap(ang, m)[0])
        g += 1
    return np.median(gaps[:g])


@jit_leaf
def own_layer(X, idx, c, spacing, h, normal, work):
    """The points of ``idx[:c]`` in ``idx[0]``'s own layer, where they lie in two: compacts
    ``idx`` (``idx[0]`` stays first) and returns the new count; ``c`` where they do not.

    Beyond the paper. Where a wall is thinner than about two spacings — a sheet, the tray's 3.18
    mm plate sampled at 2.63 mm, the faces of a scanned plate that two views saw — the local
    mesh joins both faces, and a two-plane fit sees two parallel planes (no edge: 612 of the 813
    candidates among the tray's 920 missed edge points) or a wedge across them (false edges
    along the lines where the views' scan lines cross). The heights ``h[j]`` of the points over
    their mean plane (the PCA plane of ``idx[:c]``, its normal into ``normal``) are split in two
    by a 1-D 2-means; two layers are two sheets where their means lie
    ``LAYER_GAP_MIN``-``LAYER_GAP_MAX`` local ``spacing``s apart, each holds ``MIN_SIDE`` points
    or more, and each one's RMS height about its mean is at most ``LAYER_RMS`` of the gap: one
    face split by height — curved, or the two faces of an edge — mostly spreads over the gap.
    Not always: some two-rings at edges pass (a sharp 90° roof of random points, noise 0.1: 40
    fits within a spacing, 43 without this), and part of idler_riser's and plate_holes' gains
    came from such splits (docs/measurements.md "Thin walls: each sheet fitted alone"). ``h``:
    work array of length ``c`` or more; ``work``: length 3.
    """
    p = idx[0]
    smallest_axis(*covariance_about(X, p, idx[1:], c - 1), normal, work)
    lo = np.inf
    hi = -np.inf
    for j in range(c):
        q = idx[j]
        h[j] = ((X[q, 0] - X[p, 0]) * normal[0] + (X[q, 1] - X[p, 1]) * normal[1]
                + (X[q, 2] - X[p, 2]) * normal[2])
        lo = min(lo, h[j])
        hi = max(hi, h[j])
    if hi - lo < LAYER_GAP_MIN * spacing:
        return c
    ok, cut, m0, m1, k0, k1, v0, v1 = _two_means(h, c)
    if not ok:
        return c
    gap = m1 - m0
    if gap < LAYER_GAP_MIN * spacing or gap > LAYER_GAP_MAX * spacing:
        return c
    limit = (LAYER_RMS * gap) ** 2
    if v0 > limit * k0 or v1 > limit * k1:
        return c
    upper = h[0] > cut
    m = 0
    for j in range(c):
        if (h[j] > cut) == upper:
            idx[m] = idx[j]
            m += 1
    return m
