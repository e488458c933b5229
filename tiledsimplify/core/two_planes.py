"""Two planes through a two-ring: the plane fits, their seeds and the line where they meet
(step 2 of :mod:`.edge_fit`).

:func:`.edge_fit.edge_distance` splits a candidate's two-ring into two planes, seeded by the
two most different one-ring normals (:func:`seed_by_normals`) or, when that fit fails, by the
**line sweep** (:func:`seed_by_sweep`: the split of the neighbours by a straight line in their
mean plane, ``NDIR`` directions and every offset, whose halves lie nearest two planes), then
assigns each point to the nearer plane and refits (:func:`plane_fits`). The edge is the two
planes' line of intersection (:func:`edge_line`); :func:`line_distance` measures a point's
distance from it.
"""

import numpy as np

from ._jit import jit, jit_inline, jit_leaf
from .linalg import (NO_MOMENTS, add_moments, moments_covariance, smallest_axis, sym3_eigvals,
                     tangent_basis)


#: each side of a fitted edge needs at least this many points
MIN_SIDE = 3
#: line directions the sweep split tries (3, 4, 6, 8 and 12 measured, before ``SWEEP_SIDE`` and
#: ``MIN_SPREAD`` existed: median F1 over the 12 even and 12 noise-0.1 scan CAD cases the same
#: within 0.002, as the k-means rounds after the sweep correct the direction)
NDIR = 4
#: each side of a sweep split holds at least this fraction of the neighbours (and ``MIN_SIDE``):
#: three points always fit a plane exactly, so unbounded, the least-squares sweep would cut
#: tiny exact sides off a noisy plane. (Geometry, not measured: a disc cut at 0.4 of its radius
#: from the centre leaves a quarter on the far side, about where a point one spacing from an
#: edge has its two-ring.)
SWEEP_SIDE = 0.2


@jit_leaf
def plane_fit(X, idx, c, side, which, centre, normal, work):
    """PCA plane of the points ``idx[j]`` with ``side[j] == which``; returns their number.

    Also ``work[0]``: the points' RMS distance to the plane, ``work[1]``: their RMS spread
    across their principal axis (small: nearly on a line, the plane's tilt about it is noise).
    """
    k = 0
    sx = sy = sz = 0.0
    for j in range(c):
        if side[j] == which:
            q = idx[j]
            sx += X[q, 0]
            sy += X[q, 1]
            sz += X[q, 2]
            k += 1
    if k < MIN_SIDE:
        return k
    mx, my, mz = sx / k, sy / k, sz / k
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    for j in range(c):
        if side[j] == which:
            q = idx[j]
            x, y, z = X[q, 0] - mx, X[q, 1] - my, X[q, 2] - mz
            c00 += x * x
            c01 += x * y
            c02 += x * z
            c11 += y * y
            c12 += y * z
            c22 += z * z
    work[0], work[1] = _plane_of(c00, c01, c02, c11, c12, c22, k, mx, my, mz, centre, normal,
                                 work)
    return k


@jit_leaf
def _plane_of(c00, c01, c02, c11, c12, c22, k, mx, my, mz, centre, normal, work):
    """The PCA plane of ``k`` points with mean ``(mx, my, mz)`` and scatter ``c..`` into
    ``centre`` and ``normal`` (``work``: scratch); returns the points' RMS distance to it and
    their RMS spread across their principal axis."""
    l0, l1, _ = smallest_axis(c00, c01, c02, c11, c12, c22, normal, work)
    centre[0], centre[1], centre[2] = mx, my, mz
    return np.sqrt(max(l0, 0.0) / k), np.sqrt(max(l1, 0.0) / k)


@jit_leaf
def plane_fits(X, idx, c, side, c1, n1, c2, n2, work):
    """:func:`plane_fit` of sides 0 and 1 at once, into ``c1, n1`` and ``c2, n2``: one pass
    over the points for both sides' means and one for their scatters, each side's sums taken
    in the same order as alone (so the same planes to the last bit). Returns ``(k0, k1, rms0,
    spread0)``: the sides' counts and side 0's RMS and spread; side 1's are left in ``work[0]``
    and ``work[1]``. Where a side holds fewer than ``MIN_SIDE`` points, no plane is fitted."""
    k0 = k1 = 0
    sx0 = sy0 = sz0 = sx1 = sy1 = sz1 = 0.0
    for j in range(c):
        q = idx[j]
        if side[j] == 0:
            sx0 += X[q, 0]
            sy0 += X[q, 1]
            sz0 += X[q, 2]
            k0 += 1
        elif side[j] == 1:
            sx1 += X[q, 0]
            sy1 += X[q, 1]
            sz1 += X[q, 2]
            k1 += 1
    if k0 < MIN_SIDE or k1 < MIN_SIDE:
        return k0, k1, 0.0, 0.0
    mx0, my0, mz0 = sx0 / k0, sy0 / k0, sz0 / k0
    mx1, my1, mz1 = sx1 / k1, sy1 / k1, sz1 / k1
    a00 = a01 = a02 = a11 = a12 = a22 = 0.0
    b00 = b01 = b02 = b11 = b12 = b22 = 0.0
    for j in range(c):
        q = idx[j]
        if side[j] == 0:
            x, y, z = X[q, 0] - mx0, X[q, 1] - my0, X[q, 2] - mz0
            a00 += x * x
            a01 += x * y
            a02 += x * z
            a11 += y * y
            a12 += y * z
            a22 += z * z
        elif side[j] == 1:
            x, y, z = X[q, 0] - mx1, X[q, 1] - my1, X[q, 2] - mz1
            b00 += x * x
            b01 += x * y
            b02 += x * z
            b11 += y * y
            b12 += y * z
            b22 += z * z
    rms0, spread0 = _plane_of(a00, a01, a02, a11, a12, a22, k0, mx0, my0, mz0, c1, n1, work)
    work[0], work[1] = _plane_of(b00, b01, b02, b11, b12, b22, k1, mx1, my1, mz1, c2, n2, work)
    return k0, k1, rms0, spread0


@jit_leaf
def plane_distance(X, q, c, n):
    """Distance from ``X[q]`` to the plane through ``c`` with unit normal ``n``."""
    return abs((X[q, 0] - c[0]) * n[0] + (X[q, 1] - c[1]) * n[1] + (X[q, 2] - c[2]) * n[2])


@jit_leaf
def row_dot(a, i, b, j):
    """``a[i] . b[j]`` of two (n, 3) arrays."""
    return a[i, 0] * b[j, 0] + a[i, 1] * b[j, 1] + a[i, 2] * b[j, 2]


@jit_leaf
def least_parallel(normals, idx, c, ref):
    """The point of ``idx[:c]`` whose normal is least parallel to ``ref``'s (ties: first)."""
    arg = ref
    best = 2.0
    for j in range(c):
        q = idx[j]
        d = abs(row_dot(normals, ref, normals, q))
        if d < best:
            best = d
            arg = q
    return arg


@jit_leaf
def seed_by_normals(normals, idx, c, side):
    """Initial split: each point to the nearer in direction of two seed normals — the one
    least parallel to ``idx[0]``'s, then the one least parallel to that."""
    a = least_parallel(normals, idx, c, idx[0])
    b = least_parallel(normals, idx, c, a)
    for j in range(c):
        q = idx[j]
        da, db = abs(row_dot(normals, a, normals, q)), abs(row_dot(normals, b, normals, q))
        side[j] = 0 if da >= db else 1


@jit_inline
def _scatter(m, k):
    """The scatter matrix ``(a00, a01, a02, a11, a12, a22)`` of ``k`` points with running
    moments ``m`` (:data:`.linalg.NO_MOMENTS`)."""
    sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = m
    return (sxx - sx * sx / k, sxy - sx * sy / k, sxz - sx * sz / k,
            syy - sy * sy / k, syz - sy * sz / k, szz - sz * sz / k)


@jit_inline
def _scatter_by(m, r):
    """:func:`_scatter` with the division by the count ``k`` as a product by ``r = 1 / k``:
    the same matrix but for the last bits, for the bounds (:func:`seed_by_sweep`)."""
    sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = m
    return (sxx - sx * sx * r, sxy - sx * sy * r, sxz - sx * sz * r,
            syy - sy * sy * r, syz - sy * sz * r, szz - sz * sz * r)


@jit
def _smallest_scatter(a00, a01, a02, a11, a12, a22):
    """Least eigenvalue of a scatter matrix (:func:`_scatter`): the points' sum of squared
    distances to their best plane."""
    l0, _, _ = sym3_eigvals(a00, a01, a02, a11, a12, a22)
    return max(l0, 0.0)


#: :func:`seed_by_sweep` computes a split's eigenvalues only if its lower bound
#: (:func:`_scatter_floor`) falls short of the best so far plus this fraction of the whole
#: two-ring's trace (at least the two halves' traces). Estimated, not measured: that is far
#: above the rounding of the bound (see there) and of the trigonometric eigenvalues (about
#: sqrt(machine epsilon), 1e-8, of the trace where two of them nearly tie), so the split
#: chosen is the same
FLOOR_MARGIN = 1e-6
#: Newton steps :func:`_scatter_floor` takes after its first bound
FLOOR_STEPS = 2


@jit
def _scatter_floor(a00, a01, a02, a11, a12, a22):
    """A lower bound on :func:`_smallest_scatter` without eigenvalues.

    ``λ0`` is the least root of the characteristic polynomial ``p(λ) = det − M λ + T λ² − λ³``
    (``T`` the trace, ``M`` the sum of the principal 2x2 minors). On ``[0, λ0]`` it is
    decreasing and convex (``p'' = 2T − 6λ > 0`` for ``λ < T / 3``, and ``λ0 <= T / 3``), so
    Newton's steps from 0 stay below ``λ0`` and climb towards it: the first is ``det / M``
    (the bound the sweep used alone until 2026-12, ``λ0 = det / (λ1 λ2) >= det / M``), and
    ``FLOOR_STEPS`` more make it nearly tight where the points are not flat as well — a
    two-ring in vegetation (LiDAR), whose splits the first bound rarely ruled out. No step
    may pass ``λ0``: a step is taken only while ``p`` stays positive, the iterate ``x`` below
    the root. Where the minors are below ``1e-6`` of the squared trace (the points nearly on a
    line) their rounding could make the quotient anything: the bound is 0 there. Elsewhere
    each step's rounding (a few machine epsilons of ``T³`` over ``|p'| >= M - 2Tx`` with ``x``
    below ``λ0``) stays near 1e-9 of the trace (an estimate), far inside ``FLOOR_MARGIN``.
    """
    m00 = a11 * a22 - a12 * a12
    m11 = a00 * a22 - a02 * a02
    m22 = a00 * a11 - a01 * a01
    minors = m00 + m11 + m22
    det = a00 * m00 - a01 * (a01 * a22 - a12 * a02) + a02 * (a01 * a12 - a11 * a02)
    trace = a00 + a11 + a22
    if det <= 0.0 or not minors > 1e-6 * trace * trace:
        return 0.0
    x = det / minors
    for _ in range(FLOOR_STEPS):
        value = det - x * (minors - x * (trace - x))
        slope = minors - x * (2.0 * trace - 3.0 * x)  # -p'(x)
        if not (value > 0.0 and slope > 0.0):
            break
        x += value / slope
    return x


@jit_leaf
def seed_by_sweep(X, idx, c, side, proj, normal, t1, t2, work, order):
    """Initial split by a straight line in the neighbours' mean plane (where a sharp edge
    projects): of ``NDIR`` directions and every offset, the one whose two halves lie closest
    to two planes (least total squared plane distance, from running moments in sorted order),
    each half holding ``SWEEP_SIDE`` of the points or more. ``idx[0]`` is the point itself;
    ``proj`` (float) and ``order`` (int64): work arrays of length ``c`` or more
    (:func:`_sort_order`). Returns False if ``c`` is too small for two such halves.

    Each half's least eigenvalue is monotone along a direction: the left half only gains
    points, so its scatter matrix only grows (in the positive semi-definite order) and that
    eigenvalue with it; the right half's only shrinks. A split is skipped where a lower bound
    (:func:`_scatter_floor`) of the right half's alone, or of both, clears the best so far by
    ``FLOOR_MARGIN`` of the whole two-ring's trace, and a direction's sweep stops where the
    left half's alone does: no later split of it could be chosen. The margin covers the
    rounding of the bounds and of every split's eigenvalues, whose halves' traces sum to at
    most the whole's. The split is the same as with every split's eigenvalues; on lone-star's
    failed fits the stop skips 32 % of the splits (6.5 of 20.5 million), and the sweep takes
    0.73× the time it did (docs/measurements.md "The line sweep stops early")."""
    least = max(MIN_SIDE, int(np.ceil(SWEEP_SIDE * c)))
    if c < 2 * least:
        return False
    p = idx[0]
    px, py, pz = X[p, 0], X[p, 1], X[p, 2]
    total = NO_MOMENTS  # of idx[1:c] about p (p itself adds nothing)
    for j in range(1, c):
        total = add_moments(total, X, idx[j], px, py, pz)
    smallest_axis(*moments_covariance(total, c - 1), normal, work)  # the mean plane
    tangent_basis(normal, t1, t2)
    whole = _scatter(total, c)
    # no split's two halves scatter more than the whole two-ring (their traces sum to its
    # trace less the scatter between the halves' means): a margin for every split at once
    margin = FLOOR_MARGIN * max(whole[0] + whole[3] + whole[5], 0.0)
    best = np.inf
    best_d = 0
    best_k = least
    for d in range(NDIR):
        _project(X, idx, c, p, t1, t2, np.pi * d / NDIR, proj)
        _sort_order(proj, c, order)
        left = NO_MOMENTS
        for k in range(1, c - least + 1):
            left = add_moments(left, X, idx[order[k - 1]], px, py, pz)
            if k < least:
                continue
            right = (total[0] - left[0], total[1] - left[1], total[2] - left[2],
                     total[3] - left[3], total[4] - left[4], total[5] - left[5],
                     total[6] - left[6], total[7] - left[7], total[8] - left[8])
            # most splits cannot beat the best: a bound without eigenvalues rules them out,
            # from scatters by reciprocals (two divisions, not twelve; their rounding is far
            # inside the margin), often the right half's alone at the start (it only shrinks)
            # and the left half's alone at the end (it only grows)
            bar = best + margin
            low_r = _scatter_floor(*_scatter_by(right, 1.0 / (c - k)))
            if low_r >= bar:
                continue
            low_l = _scatter_floor(*_scatter_by(left, 1.0 / k))
            if low_l >= bar:
                break  # the left half only grows from here, and its least eigenvalue with it
            if low_l + low_r >= bar:
                continue
            scatter_l = _scatter(left, k)
            scatter_r = _scatter(right, c - k)
            sse = _smallest_scatter(*scatter_l) + _smallest_scatter(*scatter_r)
            if sse < best:
                best, best_d, best_k = sse, d, k
        if best_d == d:  # the best split so far is this direction's (or none is, at d = 0)
            for i in range(c):
                side[order[i]] = 0 if i < best_k else 1
    return True


@jit_leaf
def _sort_order(a, c, order):
    """``order[:c]``: the positions of ``a[:c]`` in ascending order, equal values in their
    positions' order; ``a[:c]`` is sorted too, in place (an insertion sort moving each value
    with its position, so that it compares values side by side rather than through
    ``order``: the sweep's two-rings hold at most ``MAX_RING`` + 1 points, and
    ``np.argsort`` allocated its result for each of them)."""
    for i in range(c):
        v = a[i]
        j = i - 1
        while j >= 0 and a[j] > v:
            a[j + 1] = a[j]
            order[j + 1] = order[j]
            j -= 1
        a[j + 1] = v
        order[j + 1] = i


@jit_leaf
def _project(X, idx, c, p, t1, t2, angle, proj):
    """``proj[j]``: offset of ``idx[j]`` from ``p`` along the tangent direction at ``angle``."""
    ca, sa = np.cos(angle), np.sin(angle)
    dx, dy, dz = ca * t1[0] + sa * t2[0], ca * t1[1] + sa * t2[1], ca * t1[2] + sa * t2[2]
    for j in range(c):
        q = idx[j]
        proj[j] = (X[q, 0] - X[p, 0]) * dx + (X[q, 1] - X[p, 1]) * dy + (X[q, 2] - X[p, 2]) * dz


@jit_leaf
def edge_line(c1, n1, c2, n2, line):
    """The line where the planes through ``c1`` and ``c2`` with unit normals ``n1`` and ``n2``
    (not parallel) meet: ``line[:3]`` its point nearest the origin, ``line[3:]`` its unit
    direction ``n1 × n2 / |n1 × n2|``."""
    cs = n1[0] * n2[0] + n1[1] * n2[1] + n1[2] * n2[2]
    ux = n1[1] * n2[2] - n1[2] * n2[1]
    uy = n1[2] * n2[0] - n1[0] * n2[2]
    uz = n1[0] * n2[1] - n1[1] * n2[0]
    d1 = c1[0] * n1[0] + c1[1] * n1[1] + c1[2] * n1[2]
    d2 = c2[0] * n2[0] + c2[1] * n2[1] + c2[2] * n2[2]
    det = 1.0 - cs * cs
    ga = (d1 - cs * d2) / det
    gb = (d2 - cs * d1) / det
    un = np.sqrt(ux * ux + uy * uy + uz * uz)
    line[0] = ga * n1[0] + gb * n2[0]
    line[1] = ga * n1[1] + gb * n2[1]
    line[2] = ga * n1[2] + gb * n2[2]
    line[3], line[4], line[5] = ux / un, uy / un, uz / un


@jit_leaf
def point_line_distance(x, line):
    """Distance from the point ``x`` to the line ``line`` (:func:`edge_line`):
    ``|(x - a) × u|``."""
    vx, vy, vz = x[0] - line[0], x[1] - line[1], x[2] - line[2]
    ux, uy, uz = line[3], line[4], line[5]
    cx, cy, cz = vy * uz - vz * uy, vz * ux - vx * uz, vx * uy - vy * ux
    return np.sqrt(cx * cx + cy * cy + cz * cz)


@jit_leaf
def line_distance(X, p, line):
    """Distance from ``X[p]`` to the line ``line``."""
    return point_line_distance(X[p], line)
