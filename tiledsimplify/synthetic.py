"""Synthetic point clouds with known sharp edges, sampled from triangle meshes.

Used to build test and benchmark inputs whose ground truth is known: the sharp edges of
a CAD mesh (dihedral angle above a threshold) are exact, and every sampled point knows
the face it came from.

Public functions
----------------
sharp_edges(vertices, faces, angle_deg=30.0) -> (k, 2) int64 vertex pairs
sample_surface(vertices, faces, n, *, seed=0) -> (points, face_index)
sample_surface_even(vertices, faces, n, *, seed=0, oversample=6, tol=0.01) -> (points, face_index)
sample_edges(vertices, faces, spacing, angle_deg=30.0) -> (k, 3) points on sharp edges
scan(vertices, faces, *, n_points, ...) -> (points, face_index), simulated line scanner
spacing(points) -> median nearest-neighbour distance

Only numpy and scipy are used. All random draws come from
``numpy.random.default_rng(seed)``, so results are deterministic for a seed.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from tiledsimplify.errors import InputError
from tiledsimplify.metrics import sample_segments

__all__ = [
    "sharp_edges",
    "sample_surface",
    "sample_surface_even",
    "sample_edges",
    "scan",
    "scan_lines",
    "spacing",
]


# --------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------


def _check_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(f"vertices must have shape (n, 3), found {v.shape}; pass an (n, 3) float array")
    if f.ndim != 2 or f.shape[1] != 3:
        raise InputError(f"faces must have shape (m, 3), found {f.shape}; triangulate polygons first")
    if f.size and f.dtype.kind not in "iu":
        raise InputError(f"faces must be integer vertex indices, found dtype {f.dtype}")
    f = f.astype(np.int64, copy=False)
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise InputError(
            f"faces refer to vertex indices {int(f.min())}..{int(f.max())} but there are {len(v)} "
            "vertices; indices must be 0-based and < len(vertices)"
        )
    if not np.all(np.isfinite(v)):
        raise InputError("vertices contain NaN or infinite coordinates; remove or fix them first")
    return np.ascontiguousarray(v), np.ascontiguousarray(f)


def _face_cross(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Unnormalised face normals (cross products, length = 2 * area)."""
    a = v[f[:, 0]]
    return np.cross(v[f[:, 1]] - a, v[f[:, 2]] - a)


def _nondegenerate(v: np.ndarray, f: np.ndarray, cross: np.ndarray) -> np.ndarray:
    """Mask of faces whose area is not zero relative to their longest edge."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    longest2 = np.maximum.reduce(
        [np.einsum("ij,ij->i", b - a, b - a), np.einsum("ij,ij->i", c - b, c - b), np.einsum("ij,ij->i", a - c, a - c)]
    )
    norm = np.linalg.norm(cross, axis=1)
    return norm > 1e-12 * longest2


def _rng(seed) -> np.random.Generator:
    return np.random.default_rng(seed)


# --------------------------------------------------------------------------------------
# sharp edges
# --------------------------------------------------------------------------------------


def sharp_edges(vertices, faces, angle_deg: float = 30.0) -> np.ndarray:
    """Mesh edges whose dihedral angle exceeds a threshold.

    Parameters
    ----------
    vertices : array_like, shape (n, 3)
    faces : array_like of int, shape (m, 3)
    angle_deg : float, default 30
        An edge is sharp if the angle between the normals of two faces sharing it is
        greater than ``angle_deg`` degrees (0 = flat, 180 = folded back on itself).

    Returns
    -------
    edges : ndarray, int64, shape (k, 2)
        Vertex index pairs ``(a, b)`` with ``a < b``, sorted lexicographically.

    Notes
    -----
    * Face normals follow the vertex order of each face, so the mesh should be
      consistently oriented; a flipped face makes its edges look folded (180 degrees).
    * Boundary edges (one face) are not sharp.
    * Non-manifold edges (more than two faces) are sharp if any pair of their faces
      exceeds the angle.
    * Degenerate faces (zero area relative to their longest edge) are ignored, so an
      edge shared by one real face and one sliver of zero area counts as a boundary.
    * Edges are identified by vertex index, not position: duplicated vertices (e.g. an
      STL read without merging) split the mesh into separate faces with no shared edges.
    """
    v, f = _check_mesh(vertices, faces)
    cross = _face_cross(v, f)
    keep = _nondegenerate(v, f, cross)
    f = f[keep]
    normals = cross[keep] / np.linalg.norm(cross[keep], axis=1)[:, None]
    m = len(f)
    if m < 2:
        return np.zeros((0, 2), dtype=np.int64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    e.sort(axis=1)
    face_of = np.tile(np.arange(m, dtype=np.int64), 3)
    key = e[:, 0] * np.int64(len(v)) + e[:, 1]
    order = np.argsort(key, kind="stable")
    key, e, face_of = key[order], e[order], face_of[order]
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    count = np.diff(np.r_[start, len(key)])
    cos_t = math.cos(math.radians(angle_deg))

    sharp = np.zeros(len(start), dtype=bool)
    two = count == 2
    s2 = start[two]
    dots = np.einsum("ij,ij->i", normals[face_of[s2]], normals[face_of[s2 + 1]])
    sharp[two] = dots < cos_t
    for g in np.flatnonzero(count > 2):
        nn = normals[face_of[start[g]:start[g] + count[g]]]
        sharp[g] = bool((nn @ nn.T).min() < cos_t)
    return np.ascontiguousarray(e[start[sharp]], dtype=np.int64)


# --------------------------------------------------------------------------------------
# surface sampling
# --------------------------------------------------------------------------------------


def _sample_uniform(v, f, n, rng):
    cross = _face_cross(v, f)
    area = 0.5 * np.linalg.norm(cross, axis=1)
    total = float(area.sum())
    if not total > 0:
        raise InputError("the mesh has zero total area; cannot sample points on it")
    cdf = np.cumsum(area)
    cdf /= cdf[-1]
    face_index = np.searchsorted(cdf, rng.random(n), side="right")
    face_index = np.minimum(face_index, len(f) - 1).astype(np.int64)
    uv = rng.random((n, 2))
    flip = uv.sum(axis=1) > 1.0
    uv[flip] = 1.0 - uv[flip]
    a = v[f[face_index, 0]]
    points = a + uv[:, :1] * (v[f[face_index, 1]] - a) + uv[:, 1:] * (v[f[face_index, 2]] - a)
    return points, face_index, total


def sample_surface(vertices, faces, n: int, *, seed=0) -> tuple[np.ndarray, np.ndarray]:
    """Uniform random points on a triangle mesh (area-weighted).

    Parameters
    ----------
    vertices : array_like, shape (nv, 3)
    faces : array_like of int, shape (m, 3)
    n : int
        Number of points.
    seed : int or None, default 0
        Seed for ``numpy.random.default_rng``; equal seeds give equal results.

    Returns
    -------
    points : ndarray, float64, shape (n, 3)
    face_index : ndarray, int64, shape (n,)
        Face each point lies on.

    Notes
    -----
    A face is chosen with probability proportional to its area, then a point uniform in
    the triangle from two uniform numbers ``(u, v)`` reflected into ``u + v <= 1``.
    """
    v, f = _check_mesh(vertices, faces)
    n = int(n)
    if n < 0:
        raise InputError(f"n must be >= 0, found {n}")
    points, face_index, _ = _sample_uniform(v, f, n, _rng(seed))
    return points, face_index


def _greedy_disk_selection(n_nodes: int, pairs: np.ndarray, priority: np.ndarray) -> np.ndarray:
    """Lexicographically-first maximal independent set of a graph, in priority order.

    Equivalent to visiting nodes by increasing ``priority`` and keeping a node if none of
    its neighbours was kept, but computed in rounds (Luby-style): every undecided node
    whose undecided neighbours all have larger priority is kept, its neighbours dropped.
    """
    state = np.zeros(n_nodes, dtype=np.int8)  # 0 undecided, 1 kept, 2 dropped
    i = np.concatenate([pairs[:, 0], pairs[:, 1]])
    j = np.concatenate([pairs[:, 1], pairs[:, 0]])
    while True:
        und = state == 0
        if not und.any():
            break
        m = und[i] & und[j]
        i, j = i[m], j[m]
        blocked = np.zeros(n_nodes, dtype=bool)
        blocked[i[priority[j] < priority[i]]] = True
        keep = und & ~blocked
        state[keep] = 1
        drop = j[keep[i]]
        state[drop] = 2
    return state == 1


def sample_surface_even(
    vertices, faces, n: int, *, seed=0, oversample: float = 6.0, tol: float = 0.01
) -> tuple[np.ndarray, np.ndarray]:
    """Near-uniformly spaced ("blue noise") points on a triangle mesh.

    Parameters
    ----------
    vertices : array_like, shape (nv, 3)
    faces : array_like of int, shape (m, 3)
    n : int
        Wanted number of points (approximate, see Notes).
    seed : int or None, default 0
        Seed for ``numpy.random.default_rng``; equal seeds give equal results.
    oversample : float, default 6
        Number of uniform candidates per wanted point.
    tol : float, default 0.01
        Relative tolerance on the point count at which the radius search stops.

    Returns
    -------
    points : ndarray, float64, shape (k, 3)
        ``k`` is usually within ``tol * n`` of ``n`` (a few percent in the worst case).
    face_index : ndarray, int64, shape (k,)

    Notes
    -----
    Poisson-disk elimination: ``oversample * n`` candidates are drawn with
    :func:`sample_surface`, given a random order, and a candidate is kept when no kept
    candidate earlier in that order lies within Euclidean distance ``r`` (greedy dart
    throwing restricted to the candidates; computed in vectorised rounds with a
    ``cKDTree`` neighbour list). The radius starts from the random-sequential-adsorption
    estimate ``r = sqrt(0.7 * area / n)`` and is corrected by secant steps on
    ``log(count)`` versus ``log(r)`` until the count is within ``tol``; the closest
    result is returned. Distances are straight-line, not geodesic, so thin walls
    closer than ``r`` thin each other out slightly.
    """
    v, f = _check_mesh(vertices, faces)
    n = int(n)
    if n < 0:
        raise InputError(f"n must be >= 0, found {n}")
    if oversample < 1.5:
        raise InputError(f"oversample must be >= 1.5, found {oversample}")
    if n == 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    rng = _rng(seed)
    m = max(int(math.ceil(oversample * n)), n + 1)
    cand, cand_face, area = _sample_uniform(v, f, m, rng)
    priority = rng.permutation(m)
    tree = cKDTree(cand)

    r = math.sqrt(0.7 * area / n)
    cap = 0.0
    pairs = dist = None
    best = None
    history: list[tuple[float, int]] = []
    for _ in range(12):
        if r > cap:
            cap = r * 1.3
            pairs = tree.query_pairs(cap, output_type="ndarray")
            d = cand[pairs[:, 0]] - cand[pairs[:, 1]]
            dist = np.sqrt(np.einsum("ij,ij->i", d, d))
        kept = _greedy_disk_selection(m, pairs[dist < r], priority)
        count = int(kept.sum())
        if best is None or abs(count - n) < abs(best[1] - n):
            best = (kept, count)
        if abs(count - n) <= tol * n:
            break
        history.append((math.log(r), math.log(max(count, 1))))
        # count ~ r**slope; slope ~ -2 on a surface
        slope = -2.0
        if len(history) >= 2:
            (x0, y0), (x1, y1) = history[-2], history[-1]
            if x1 != x0 and (y1 - y0) / (x1 - x0) < -0.5:
                slope = max((y1 - y0) / (x1 - x0), -4.0)
        r = math.exp(history[-1][0] + (math.log(n) - history[-1][1]) / slope)
    kept = best[0]  # points stay in candidate order (random, area-weighted)
    return cand[kept], cand_face[kept]


# --------------------------------------------------------------------------------------
# sharp-edge sampling
# --------------------------------------------------------------------------------------


def sample_edges(vertices, faces, spacing: float, angle_deg: float = 30.0) -> np.ndarray:
    """Points along the sharp edges of a mesh at a regular spacing.

    Parameters
    ----------
    vertices : array_like, shape (nv, 3)
    faces : array_like of int, shape (m, 3)
    spacing : float
        Maximum distance between consecutive points along an edge (> 0).
    angle_deg : float, default 30
        Dihedral-angle threshold passed to :func:`sharp_edges`.

    Returns
    -------
    points : ndarray, float64, shape (k, 3)
        Unique points (no point repeated), sorted lexicographically.

    Notes
    -----
    The sharp edges are joined into polylines and sampled by arc length
    (:func:`tiledsimplify.metrics.sample_segments`): a polyline of length ``L`` is split into
    ``max(1, ceil(L / spacing))`` equal pieces; the piece ends are the points, the polyline
    ends (its end vertices: corners, junctions, open ends) included, so a curved edge
    tessellated finer than the spacing is sampled at the spacing, not at every vertex. A unit
    cube with ``spacing=0.1`` gives 8 corners + 12 * 9 interior points = 116.
    """
    v, f = _check_mesh(vertices, faces)
    spacing = float(spacing)
    if not spacing > 0 or not math.isfinite(spacing):
        raise InputError(f"spacing must be a positive finite number, found {spacing}")
    edges = sharp_edges(v, f, angle_deg)
    if len(edges) == 0:
        return np.zeros((0, 3))
    return sample_segments(v[edges], spacing)


# --------------------------------------------------------------------------------------
# simulated line scanner
# --------------------------------------------------------------------------------------


def _frame(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(helper, d)
    u /= np.linalg.norm(u)
    w = np.cross(d, u)
    return u, w


def _fibonacci_directions(k: int) -> np.ndarray:
    """k viewing directions (towards the object) spread over the sphere."""
    i = np.arange(k) + 0.5
    z = 1.0 - 2.0 * i / k
    rho = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 0.3 + i * math.pi * (3.0 - math.sqrt(5.0))
    s = np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)
    return -s


def _cast_grid(v, f, origin, d, u, w, xs, ys, chunk_pairs=2_000_000):
    """First hit of every ray origin -> (d + xs[i] u + ys[j] w), all i, j.

    Candidate (ray, triangle) pairs come from the triangle's bounding box in the
    tangent plane (a perspective projection, exact since every vertex is in front of
    the origin); each pair is then tested exactly with Moller-Trumbore (two-sided).
    Returns (t, face, ray direction) per ray, t = inf and face = -1 for misses; the
    directions are unit vectors, ray id = i * len(ys) + j.
    """
    L, S = len(xs), len(ys)
    dirs = d[None, None, :] + xs[:, None, None] * u[None, None, :] + ys[None, :, None] * w[None, None, :]
    dirs = dirs.reshape(-1, 3)
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]

    rel = v - origin
    z = rel @ d
    px = (rel @ u) / z
    py = (rel @ w) / z
    tx, ty = px[f], py[f]
    eps_x = 1e-9 * (xs[-1] - xs[0] + 1e-300)
    eps_y = 1e-9 * (ys[-1] - ys[0] + 1e-300)
    i0 = np.searchsorted(xs, tx.min(axis=1) - eps_x, side="left")
    i1 = np.searchsorted(xs, tx.max(axis=1) + eps_x, side="right")
    j0 = np.searchsorted(ys, ty.min(axis=1) - eps_y, side="left")
    j1 = np.searchsorted(ys, ty.max(axis=1) + eps_y, side="right")
    ni = np.maximum(i1 - i0, 0)
    nj = np.maximum(j1 - j0, 0)
    cnt = ni * nj
    tri = np.flatnonzero(cnt)

    best_t = np.full(L * S, np.inf)
    best_f = np.full(L * S, -1, dtype=np.int64)
    if len(tri) == 0:
        return best_t, best_f, dirs
    v0 = v[f[:, 0]]
    e1 = v[f[:, 1]] - v0
    e2 = v[f[:, 2]] - v0
    tvec_all = origin - v0
    qvec_all = np.cross(tvec_all, e1)

    csum = np.cumsum(cnt[tri])
    start = 0
    while start < len(tri):
        # chunk of triangles with at most chunk_pairs candidate pairs (at least one triangle)
        base = csum[start - 1] if start else 0
        stop = int(np.searchsorted(csum, base + chunk_pairs, side="right"))
        stop = max(stop, start + 1)
        tt = tri[start:stop]
        c = cnt[tt]
        pf = np.repeat(tt, c)
        off = np.zeros(len(tt), dtype=np.int64)
        np.cumsum(c[:-1], out=off[1:])
        k = np.arange(int(c.sum()), dtype=np.int64) - np.repeat(off, c)
        njr = nj[pf]
        ray = (i0[pf] + k // njr) * S + (j0[pf] + k % njr)
        D = dirs[ray]
        E1, E2 = e1[pf], e2[pf]
        pvec = np.cross(D, E2)
        det = np.einsum("ij,ij->i", E1, pvec)
        ok = np.abs(det) > 1e-300
        inv = np.zeros_like(det)
        inv[ok] = 1.0 / det[ok]
        bu = np.einsum("ij,ij->i", tvec_all[pf], pvec) * inv
        qv = qvec_all[pf]
        bv = np.einsum("ij,ij->i", D, qv) * inv
        t = np.einsum("ij,ij->i", E2, qv) * inv
        eps = 1e-10
        hit = ok & (bu >= -eps) & (bv >= -eps) & (bu + bv <= 1.0 + eps) & (t > 0)
        ray, t, pf = ray[hit], t[hit], pf[hit]
        if len(ray):
            order = np.lexsort((t, ray))
            ray, t, pf = ray[order], t[order], pf[order]
            firsts = np.r_[True, ray[1:] != ray[:-1]]
            ray, t, pf = ray[firsts], t[firsts], pf[firsts]
            better = t < best_t[ray]
            best_t[ray[better]] = t[better]
            best_f[ray[better]] = pf[better]
        start = stop
    return best_t, best_f, dirs


def scan(
    vertices,
    faces,
    *,
    n_points: int,
    direction=None,
    views: int = 3,
    line_spacing_ratio: float = 4.0,
    noise: float = 0.0,
    seed=0,
    distance: float = 3.0,
    max_incidence_deg: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Simulated line scanner: first hits of a grid of rays from several viewpoints.

    Parameters
    ----------
    vertices : array_like, shape (nv, 3)
    faces : array_like of int, shape (m, 3)
    n_points : int
        Approximate total number of points wanted (split evenly over the views).
    direction : array_like, shape (3,) or (k, 3), optional
        Viewing directions (from the scanner towards the object). If given, one view
        per row and ``views`` is ignored. By default ``views`` directions are spread
        over the sphere (Fibonacci lattice, fixed, not axis-aligned).
    views : int, default 3
        Number of scanner positions when ``direction`` is None.
    line_spacing_ratio : float, default 4
        Angular spacing between scan lines divided by the spacing between samples along
        a line (>= 1 gives lines denser along than across, as in real line scanners).
    noise : float, default 0
        Standard deviation of Gaussian range noise along each ray, in model units.
    seed : int or None, default 0
        Seed for ``numpy.random.default_rng``: range noise and a sub-sample shift of each
        view's ray grid. Equal seeds give equal results.
    distance : float, default 3
        Scanner distance from the centre of the bounding box, in bounding-sphere radii
        (> 1).
    max_incidence_deg : float, optional
        If given, hits where the ray meets the surface at more than this angle from the
        face normal are dropped (grazing returns).

    Returns
    -------
    points : ndarray, float64, shape (k, 3)
        Hits of all views, view after view; ``k`` is close to ``n_points`` (the grid
        size comes from a pilot scan's hit ratio, typically within a few percent).
    face_index : ndarray, int64, shape (k,)
        Face hit by each ray (before noise is added).

    Notes
    -----
    Each view is a pinhole scanner at ``centre - distance * R * d`` looking along ``d``.
    Its rays form a grid of angles: ``L`` lines at evenly spaced angles across the
    field of view (which just covers the bounding sphere), each with ``S =
    line_spacing_ratio * L`` samples at evenly spaced angles along the line, ray
    direction ``d + tan(a_line) u + tan(a_sample) w``. Each ray keeps its first hit
    (two-sided Moller-Trumbore, so open or inconsistently oriented meshes work); the
    candidate triangles of a ray are found by rasterising the projected triangles'
    bounding boxes onto the ray grid, so the cost is about (rays hitting the object x
    depth complexity + faces), not rays x faces. Noise moves a point along its ray by
    ``noise * N(0, 1)``. No occlusion by the scanner's second eye, no reflectance and no
    mixed pixels are simulated.
    """
    v, f = _check_mesh(vertices, faces)
    n_points = int(n_points)
    if n_points < 1:
        raise InputError(f"n_points must be >= 1, found {n_points}")
    if not line_spacing_ratio > 0:
        raise InputError(f"line_spacing_ratio must be > 0, found {line_spacing_ratio}")
    if not distance > 1.0:
        raise InputError(f"distance must be > 1 (bounding-sphere radii), found {distance}")
    if noise < 0:
        raise InputError(f"noise must be >= 0, found {noise}")
    if direction is None:
        views = int(views)
        if views < 1:
            raise InputError(f"views must be >= 1, found {views}")
        dirs = _fibonacci_directions(views)
    else:
        dirs = np.asarray(direction, dtype=np.float64).reshape(-1, 3)
        norms = np.linalg.norm(dirs, axis=1)
        if not np.all(norms > 0) or not np.all(np.isfinite(dirs)):
            raise InputError("direction must be non-zero finite 3-vectors")
        dirs = dirs / norms[:, None]
    cross = _face_cross(v, f)
    if not np.any(np.linalg.norm(cross, axis=1) > 0):
        raise InputError("the mesh has zero total area; cannot scan it")
    unit_n = cross / np.maximum(np.linalg.norm(cross, axis=1), 1e-300)[:, None]

    rng = _rng(seed)
    lo, hi = v[np.unique(f)].min(axis=0), v[np.unique(f)].max(axis=0)
    centre = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-300)
    half = math.asin(1.0 / distance) * 1.02
    per_view = np.full(len(dirs), n_points // len(dirs))
    per_view[: n_points % len(dirs)] += 1

    shifts = rng.random((len(dirs), 2))  # drawn first: the ray grids do not depend on noise
    all_pts, all_face = [], []
    for vi, d in enumerate(dirs):
        origin = centre - distance * radius * d
        u, w = _frame(d)
        shift = shifts[vi]

        def grid(n_lines, shift=shift):
            n_lines = max(int(n_lines), 2)
            n_samp = max(int(round(line_spacing_ratio * n_lines)), 2)
            step_l = 2 * half / n_lines
            step_s = 2 * half / n_samp
            al = -half + (np.arange(n_lines) + shift[0]) * step_l
            as_ = -half + (np.arange(n_samp) + shift[1]) * step_s
            return np.tan(al), np.tan(as_)

        # pilot scan (about 20k rays) for the hit ratio, then the real grid
        pilot_lines = max(8, int(round(math.sqrt(20000.0 / line_spacing_ratio))))
        xs, ys = grid(pilot_lines)
        t, _, _ = _cast_grid(v, f, origin, d, u, w, xs, ys)
        ratio = np.isfinite(t).mean()
        if ratio == 0:
            continue
        rays = per_view[vi] / ratio
        xs, ys = grid(round(math.sqrt(rays / line_spacing_ratio)))
        t, face, rdir = _cast_grid(v, f, origin, d, u, w, xs, ys)
        hit = np.isfinite(t)
        if max_incidence_deg is not None:
            cos_inc = np.abs(np.einsum("ij,ij->i", unit_n[np.maximum(face, 0)], rdir))
            hit &= cos_inc >= math.cos(math.radians(max_incidence_deg))
        t, face, rdir = t[hit], face[hit], rdir[hit]
        if noise > 0:
            t = t + noise * rng.standard_normal(len(t))
        all_pts.append(origin + t[:, None] * rdir)
        all_face.append(face)
    if not all_pts:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    return np.concatenate(all_pts), np.concatenate(all_face)


#: Alias of :func:`scan`.
scan_lines = scan


# --------------------------------------------------------------------------------------
# spacing
# --------------------------------------------------------------------------------------


def spacing(points) -> float:
    """Median nearest-neighbour distance of a point set.

    Parameters
    ----------
    points : array_like, shape (n, 3)

    Returns
    -------
    float
        Median over all points of the distance to the closest other point
        (``cKDTree``). Duplicated points contribute 0.

    Raises
    ------
    tiledsimplify.errors.InputError
        Fewer than two points, or not an (n, 3) array.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"points must have shape (n, 3), found {p.shape}")
    if len(p) < 2:
        raise InputError(f"spacing needs at least 2 points, found {len(p)}")
    d, _ = cKDTree(p).query(p, k=2)
    return float(np.median(d[:, 1]))
