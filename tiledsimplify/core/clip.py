"""Convex polygon clipping by half-planes, with the label of the constraint behind each edge.

Both Voronoi constructions of the core reduce to this one primitive:

* the 3-D Voronoi facet shared by two points is their bisector plane clipped by the half-spaces
  of every other nearby point (:mod:`.voronoi`), and
* the 2-D Voronoi cell of a point among its neighbours projected to the tangent plane is a
  square clipped by the neighbours' bisectors (:mod:`.local_mesh`).

Sutherland & Hodgman, "Reentrant polygon clipping", CACM 17(1), 1974, specialised to convex
polygons and one half-plane at a time.
"""

import math

from ._jit import jit_leaf


@jit_leaf
def square(half, xs, ys, labels):
    """Write the square ``[-half, half]^2`` (counter-clockwise, edges labelled -1); return 4."""
    xs[0], ys[0] = -half, -half
    xs[1], ys[1] = half, -half
    xs[2], ys[2] = half, half
    xs[3], ys[3] = -half, half
    for i in range(4):
        labels[i] = -1
    return 4


@jit_leaf
def clip(n, xs, ys, labels, gx, gy, h, label, ox, oy, olabels):
    """Clip the convex polygon ``(xs, ys)[:n]`` to ``gx*x + gy*y <= h``.

    ``labels[i]`` names the constraint that made the edge from vertex ``i`` to vertex ``i+1``;
    the new edge along the clipping line gets ``label``.

    Returns
    -------
    int
        ``-1`` if the polygon is inside the half-plane (keep the input; the output buffers
        may have been written), otherwise the number of vertices written to
        ``(ox, oy, olabels)`` (0 = empty).

    Notes
    -----
    One pass: each vertex's signed distance is computed once and the output is written as if
    the polygon were cut; whether it was is known only at the end (about a third of the
    calls in the removal loop keep the polygon whole).
    """
    x0, y0 = xs[0], ys[0]
    d0 = gx * x0 + gy * y0 - h
    xi, yi, di = x0, y0, d0
    inside = True
    m = 0
    for i in range(n):
        if i + 1 < n:
            xj, yj = xs[i + 1], ys[i + 1]
            dj = gx * xj + gy * yj - h
        else:
            xj, yj, dj = x0, y0, d0
        if di > 0.0:
            inside = False
        if di <= 0.0:
            ox[m], oy[m], olabels[m] = xi, yi, labels[i]
            m += 1
            if dj > 0.0:
                t = di / (di - dj)
                ox[m], oy[m], olabels[m] = xi + t * (xj - xi), yi + t * (yj - yi), label
                m += 1
        elif dj <= 0.0:
            t = di / (di - dj)
            ox[m], oy[m], olabels[m] = xi + t * (xj - xi), yi + t * (yj - yi), labels[i]
            m += 1
        xi, yi, di = xj, yj, dj
    if inside:
        return -1
    return m


@jit_leaf
def area(n, xs, ys):
    """Signed area of the polygon ``(xs, ys)[:n]`` (positive when counter-clockwise)."""
    s = 0.0
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        s += xs[i] * ys[j] - xs[j] * ys[i]
    return 0.5 * s


@jit_leaf
def origin_distance2(n, xs, ys):
    """Squared distance from the origin to the convex counter-clockwise polygon
    ``(xs, ys)[:n]`` (0 if the origin lies inside or on it)."""
    best = math.inf
    inside = True
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        ex, ey = xs[j] - xs[i], ys[j] - ys[i]
        if ex * (-ys[i]) - ey * (-xs[i]) < 0.0:  # the origin is right of edge i -> outside
            inside = False
        ee = ex * ex + ey * ey
        t = 0.0
        if ee > 0.0:
            t = -(xs[i] * ex + ys[i] * ey) / ee
            t = min(max(t, 0.0), 1.0)
        px, py = xs[i] + t * ex, ys[i] + t * ey
        d = px * px + py * py
        if d < best:
            best = d
    return 0.0 if inside else best
