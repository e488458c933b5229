"""Quality measures for judging a simplified point cloud against its original.

Every function takes the *original* cloud and the *kept* set.  ``kept`` may be
given in either of two forms (both give identical results):

* a boolean mask of shape ``(n,)`` over the original points (``True`` = kept);
* an ``(m, 3)`` array with the coordinates of the kept points.

A 1-D array is only accepted as a mask if its dtype is boolean; integer index
arrays are rejected (pass ``original[idx]`` or build a mask instead).

Conventions used throughout
---------------------------
* All distance-type results (surface error, Chamfer, Hausdorff) are divided by
  the length of the diagonal of the axis-aligned bounding box of the
  *original* cloud, ``||max(original) - min(original)||``, so they are
  dimensionless and comparable between models.
* "Spacing" ``s`` is the median nearest-neighbour distance of the original
  cloud (see :func:`spacing`), unless given explicitly.
* Thresholds are inclusive: "within r" means distance ``<= r``.

Only numpy and :class:`scipy.spatial.cKDTree` are used.

References
----------
.. [1] M. Pauly, M. Gross, L. P. Kobbelt, "Efficient simplification of
   point-sampled surfaces", Proceedings of IEEE Visualization 2002,
   pp. 163-170.  DOI: 10.1109/VISUAL.2002.1183771
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from tiledsimplify.errors import InputError

__all__ = [
    "adaptivity",
    "bbox_diagonal",
    "boundary_detection",
    "chamfer_distance",
    "curvature_regions",
    "distance_to_segments",
    "edge_coverage",
    "edge_ground_truth",
    "evaluate",
    "hausdorff_distance",
    "sample_segments",
    "spacing",
    "surface_distances",
    "surface_error",
]

#: Default number of query points handled per batch in the batched PCA code.
#: Memory per batch is about ``chunk_size * k * 3 * 8`` bytes (12 MiB for k=8).
DEFAULT_CHUNK_SIZE = 65536

_WORKERS = -1  # cKDTree queries use all cores

#: A neighbourhood counts as collinear when its middle covariance eigenvalue is
#: at most this fraction of the largest (i.e. thickness/length <~ 1e-6).
_DEGENERATE_RATIO = 1e-12


# ---------------------------------------------------------------------------
# input validation
# ---------------------------------------------------------------------------


def _check_points(points: Any, name: str, *, min_points: int = 1) -> np.ndarray:
    """Return ``points`` as a C-contiguous float64 ``(n, 3)`` array or raise InputError."""
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"`{name}` must be an (n, 3) array of finite coordinates; got an object of type "
            f"{type(points).__name__} that cannot be converted to floats ({exc}). "
            f"Fix: pass a numeric array of shape (n, 3)."
        ) from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(
            f"`{name}` must be an (n, 3) array of xyz coordinates; got shape {arr.shape}. "
            f"Fix: pass one row per point with exactly 3 columns (x, y, z)."
        )
    if arr.shape[0] < min_points:
        raise InputError(
            f"`{name}` must contain at least {min_points} point(s); got {arr.shape[0]}. "
            f"Fix: pass a non-empty point set."
        )
    finite = np.isfinite(arr).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise InputError(
            f"`{name}` must contain only finite coordinates; found {bad.size} row(s) with "
            f"NaN or inf (first rows: {bad[:5].tolist()}). "
            f"Fix: remove or repair those points before evaluating."
        )
    return np.ascontiguousarray(arr)


def _check_mask(mask: Any, n: int, name: str) -> np.ndarray:
    arr = np.asarray(mask)
    if arr.dtype != np.bool_ or arr.shape != (n,):
        raise InputError(
            f"`{name}` must be a boolean array of shape ({n},), one entry per original point; "
            f"got dtype {arr.dtype} and shape {arr.shape}. "
            f"Fix: pass a numpy bool array with the same length as the original cloud."
        )
    return arr


def _check_positive(value: Any, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(
            f"`{name}` must be a positive finite number; got {value!r}. Fix: pass a float > 0."
        ) from None
    if not np.isfinite(v) or v <= 0.0:
        raise InputError(
            f"`{name}` must be a positive finite number; got {v}. Fix: pass a float > 0."
        )
    return v


def _check_k(k: Any, name: str = "k", minimum: int = 3) -> int:
    if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)) or k < minimum:
        raise InputError(
            f"`{name}` must be an integer >= {minimum} (a plane needs at least 3 points); "
            f"got {k!r}. Fix: pass e.g. {name}=8."
        )
    return int(k)


def _check_segments(segments: Any, name: str = "edge_segments") -> np.ndarray:
    try:
        arr = np.asarray(segments, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(
            f"`{name}` must be a (k, 2, 3) array of segment end points; got an object of type "
            f"{type(segments).__name__} that cannot be converted to floats. "
            f"Fix: pass segments[i] = [[x0, y0, z0], [x1, y1, z1]]."
        ) from None
    if arr.ndim != 3 or arr.shape[1:] != (2, 3) or arr.shape[0] == 0:
        raise InputError(
            f"`{name}` must be a non-empty (k, 2, 3) array (k segments, 2 end points, xyz); "
            f"got shape {arr.shape}. Fix: pass segments[i] = [[x0, y0, z0], [x1, y1, z1]]."
        )
    if not np.isfinite(arr).all():
        bad = np.flatnonzero(~np.isfinite(arr).all(axis=(1, 2)))
        raise InputError(
            f"`{name}` must contain only finite coordinates; found {bad.size} segment(s) with "
            f"NaN or inf (first: {bad[:5].tolist()}). Fix: remove or repair those segments."
        )
    return np.ascontiguousarray(arr)


def _diag(original: np.ndarray) -> float:
    d = float(np.linalg.norm(original.max(axis=0) - original.min(axis=0)))
    if not d > 0.0:
        raise InputError(
            "the original cloud must have a non-zero bounding box to normalise distances; "
            f"got {original.shape[0]} point(s) that all coincide. "
            "Fix: evaluate on a cloud with at least two distinct points."
        )
    return d


def _resolve_kept(original: np.ndarray, kept: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """Return ``(kept_points, kept_mask_or_None)``; raise InputError if unusable or empty."""
    arr = np.asarray(kept)
    n = original.shape[0]
    if arr.ndim == 1:
        if arr.dtype != np.bool_:
            raise InputError(
                f"`kept` must be a boolean mask of shape ({n},) or an (m, 3) array of kept "
                f"points; got a 1-D array of dtype {arr.dtype} and shape {arr.shape}. "
                f"Fix: if these are indices, pass `original[idx]` or a mask "
                f"(mask = np.zeros({n}, bool); mask[idx] = True)."
            )
        if arr.shape[0] != n:
            raise InputError(
                f"`kept` given as a boolean mask must have one entry per original point, "
                f"shape ({n},); got shape {arr.shape}. "
                f"Fix: build the mask over the same original cloud that is passed in."
            )
        if not arr.any():
            raise InputError(
                "`kept` must select at least one point; got a mask with no True entries. "
                "Fix: pass a non-empty kept set."
            )
        return original[arr], arr
    if arr.dtype == np.bool_:
        raise InputError(
            f"`kept` as a boolean mask must be 1-D of shape ({n},); got shape {arr.shape}. "
            f"Fix: pass a flat mask over the original points."
        )
    pts = _check_points(arr, "kept", min_points=1)
    return pts, None


def _resolve_spacing(original: np.ndarray, spacing_value: Any) -> float:
    if spacing_value is None:
        s = _median_nn_distance(original)
        if not s > 0.0:
            raise InputError(
                "the default spacing (median nearest-neighbour distance of the original) is 0, "
                "because more than half of the points have an exact duplicate. "
                "Fix: pass `spacing=` explicitly or remove duplicate points."
            )
        return s
    return _check_positive(spacing_value, "spacing")


def _kept_region_counts(
    original: np.ndarray, kept: Any, region: np.ndarray, match_tol: float | None
) -> tuple[int, int]:
    """Number of kept points inside ``region`` and outside it."""
    kept_pts, mask = _resolve_kept(original, kept)
    if mask is not None:
        return int(np.count_nonzero(mask & region)), int(np.count_nonzero(mask & ~region))
    diag = _diag(original)
    tol = 1e-9 * diag if match_tol is None else float(match_tol)
    if not (np.isfinite(tol) and tol >= 0.0):
        raise InputError(
            f"`match_tol` must be a finite number >= 0; got {match_tol!r}. "
            f"Fix: pass e.g. match_tol=1e-6 or leave it as None."
        )
    dist, idx = cKDTree(original).query(kept_pts, k=1, workers=_WORKERS)
    far = dist > tol
    if far.any():
        raise InputError(
            "`kept` given as points must be a subset of the original points for this measure; "
            f"{int(far.sum())} of {kept_pts.shape[0]} kept point(s) lie farther than "
            f"match_tol={tol:.3g} from every original point (largest gap {dist.max():.3g}). "
            "Fix: pass `kept` as a boolean mask over the original, or raise `match_tol`."
        )
    inside = region[idx]
    return int(np.count_nonzero(inside)), int(np.count_nonzero(~inside))


# ---------------------------------------------------------------------------
# basic quantities
# ---------------------------------------------------------------------------


def _median_nn_distance(points: np.ndarray) -> float:
    d, _ = cKDTree(points).query(points, k=2, workers=_WORKERS)
    return float(np.median(d[:, 1]))


def spacing(points: Any) -> float:
    """Median nearest-neighbour distance of a point cloud.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Point coordinates, n >= 2, all finite.

    Returns
    -------
    float
        ``median_i min_{j != i} ||p_i - p_j||``.

    Notes
    -----
    Exact duplicates count as neighbours at distance 0, so a cloud in which
    most points are duplicated has spacing 0.
    """
    pts = _check_points(points, "points", min_points=2)
    return _median_nn_distance(pts)


def bbox_diagonal(points: Any) -> float:
    """Length of the diagonal of the axis-aligned bounding box of ``points``.

    This is the normalisation length of every distance measure in this module.

    Parameters
    ----------
    points : array_like, shape (n, 3)

    Returns
    -------
    float
        ``||max(points, axis=0) - min(points, axis=0)||`` (may be 0).
    """
    pts = _check_points(points, "points")
    return float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))


# ---------------------------------------------------------------------------
# surface error (Pauly et al. 2002)
# ---------------------------------------------------------------------------


def _batched_pca(neigh: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """PCA of stacked neighbourhoods.

    ``neigh`` has shape (c, k, 3).  Returns ``(centroid (c,3), eigenvalues (c,3)
    ascending, eigenvectors (c,3,3) as columns)`` of the covariance matrices.
    """
    centroid = neigh.mean(axis=1)
    centred = neigh - centroid[:, None, :]
    cov = np.einsum("cki,ckj->cij", centred, centred) / neigh.shape[1]
    evals, evecs = np.linalg.eigh(cov)
    return centroid, evals, evecs


def _surface_distances(
    original: np.ndarray,
    kept_pts: np.ndarray,
    k: int,
    chunk_size: int,
    kept_tree: cKDTree | None = None,
) -> np.ndarray:
    m = kept_pts.shape[0]
    if m < 3:
        raise InputError(
            f"the surface error fits a plane to the nearest kept points and needs at least 3 "
            f"kept points; got {m}. Fix: keep at least 3 points (or skip this measure)."
        )
    k_eff = min(k, m)
    tree = cKDTree(kept_pts) if kept_tree is None else kept_tree
    out = np.empty(original.shape[0], dtype=np.float64)
    for start in range(0, original.shape[0], chunk_size):
        q = original[start : start + chunk_size]
        _, idx = tree.query(q, k=k_eff, workers=_WORKERS)
        centroid, evals, evecs = _batched_pca(kept_pts[idx])
        rel = q - centroid
        normal = evecs[:, :, 0]  # eigenvector of the smallest eigenvalue
        dist = np.abs(np.einsum("ci,ci->c", rel, normal))
        # (numerically) collinear or coincident neighbours: the plane is not
        # determined, use the distance to their line / their point instead
        lam1, lam2 = evals[:, 1], evals[:, 2]
        line = lam1 <= _DEGENERATE_RATIO * lam2
        if line.any():
            r = rel[line]
            along = np.einsum("ci,ci->c", r, evecs[line, :, 2])
            to_line = np.sqrt(np.maximum(np.einsum("ci,ci->c", r, r) - along**2, 0.0))
            to_point = np.linalg.norm(r, axis=1)
            dist[line] = np.where(lam2[line] > 0.0, to_line, to_point)
        out[start : start + q.shape[0]] = dist
    return out


def surface_distances(
    original: Any, kept: Any, k: int = 8, *, chunk_size: int = DEFAULT_CHUNK_SIZE
) -> np.ndarray:
    """Per-point distance of each original point to the plane of its k nearest kept points.

    Parameters
    ----------
    original : array_like, shape (n, 3)
        The original cloud.
    kept : array_like, shape (n,) bool or (m, 3) float
        The kept set, as a mask over ``original`` or as coordinates.
    k : int, default 8
        Number of nearest kept points used for the plane fit (>= 3).  If fewer
        than ``k`` points are kept, all kept points are used.
    chunk_size : int, default 65536
        Number of original points processed per batch (bounds memory).

    Returns
    -------
    numpy.ndarray, shape (n,)
        Absolute (not normalised) point-to-plane distances.

    Notes
    -----
    For each original point ``p`` the k nearest kept points ``q_1..q_k`` are
    found with a KD-tree; the least-squares plane through them passes through
    their centroid ``c`` with normal ``n`` = eigenvector of the smallest
    eigenvalue of the covariance ``(1/k) sum (q_i - c)(q_i - c)^T``.  The
    distance is ``|(p - c) . n|``.  The neighbourhoods are gathered in chunks
    into a ``(chunk, k, 3)`` array and all 3x3 covariances are diagonalised at
    once with :func:`numpy.linalg.eigh`.

    Degenerate neighbourhoods (an extension of [1]_, which assumes a plane
    exists): if the neighbours are collinear up to round-off (middle
    eigenvalue ``<= 1e-12`` times the largest) the plane is not determined,
    and the distance to their least-squares line is used instead (the largest
    distance over all planes containing that line); if they all coincide, the
    distance to that point.  This keeps the result deterministic, e.g. when
    the nearest kept points all lie on one straight sharp edge.

    References
    ----------
    .. [1] M. Pauly, M. Gross, L. P. Kobbelt, "Efficient simplification of
       point-sampled surfaces", IEEE Visualization 2002 (Sec. on error
       measurement).
    """
    orig = _check_points(original, "original")
    kept_pts, _ = _resolve_kept(orig, kept)
    k = _check_k(k)
    chunk_size = _check_k(chunk_size, "chunk_size", minimum=1)
    return _surface_distances(orig, kept_pts, k, chunk_size)


def surface_error(
    original: Any, kept: Any, k: int = 8, *, chunk_size: int = DEFAULT_CHUNK_SIZE
) -> tuple[float, float]:
    """Mean and maximum surface error of the kept set, normalised by the bbox diagonal.

    Parameters
    ----------
    original : array_like, shape (n, 3)
        The original cloud.
    kept : array_like, shape (n,) bool or (m, 3) float
        The kept set, as a mask over ``original`` or as coordinates (>= 3 points).
    k : int, default 8
        Number of nearest kept points for the plane fit (all if fewer are kept).
    chunk_size : int, default 65536
        Number of original points processed per batch.

    Returns
    -------
    (float, float)
        ``(mean_i d_i / D, max_i d_i / D)`` where ``d_i`` is the distance of
        original point ``i`` to the least-squares plane of its k nearest kept
        points (see :func:`surface_distances`) and ``D`` the bounding-box
        diagonal of the original.

    Notes
    -----
    This is the sampled one-sided error of Pauly et al. [1]_: the simplified
    surface is represented locally by the plane through the nearest kept
    samples, and the error is measured at every original sample.  For
    (numerically) collinear or coincident neighbours the distance to their
    line or point is used, see :func:`surface_distances`.

    References
    ----------
    .. [1] M. Pauly, M. Gross, L. P. Kobbelt, "Efficient simplification of
       point-sampled surfaces", IEEE Visualization 2002, pp. 163-170.
    """
    orig = _check_points(original, "original")
    kept_pts, _ = _resolve_kept(orig, kept)
    k = _check_k(k)
    chunk_size = _check_k(chunk_size, "chunk_size", minimum=1)
    diag = _diag(orig)
    d = _surface_distances(orig, kept_pts, k, chunk_size)
    return float(d.mean() / diag), float(d.max() / diag)


# ---------------------------------------------------------------------------
# Chamfer / Hausdorff
# ---------------------------------------------------------------------------


def _nn_both_ways(
    orig: np.ndarray,
    kept_pts: np.ndarray,
    kept_tree: cKDTree | None = None,
    orig_tree: cKDTree | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    kt = cKDTree(kept_pts) if kept_tree is None else kept_tree
    ot = cKDTree(orig) if orig_tree is None else orig_tree
    d_ok, _ = kt.query(orig, k=1, workers=_WORKERS)
    d_ko, _ = ot.query(kept_pts, k=1, workers=_WORKERS)
    return d_ok, d_ko


def chamfer_distance(original: Any, kept: Any) -> float:
    """Symmetric Chamfer distance between original and kept, normalised by the bbox diagonal.

    Parameters
    ----------
    original : array_like, shape (n, 3)
    kept : array_like, shape (n,) bool or (m, 3) float

    Returns
    -------
    float
        ``( mean_{p in O} min_{q in K} ||p - q||  +  mean_{q in K} min_{p in O} ||q - p|| ) / D``

        i.e. the **sum of the two one-directional mean nearest-neighbour
        distances** (plain, not squared, Euclidean distances; no factor 1/2),
        divided by the bounding-box diagonal ``D`` of the original.

    Notes
    -----
    When ``kept`` is a subset of ``original`` the second term is 0 and the
    value reduces to the mean original-to-kept distance.
    """
    orig = _check_points(original, "original")
    kept_pts, _ = _resolve_kept(orig, kept)
    diag = _diag(orig)
    d_ok, d_ko = _nn_both_ways(orig, kept_pts)
    return float((d_ok.mean() + d_ko.mean()) / diag)


def hausdorff_distance(original: Any, kept: Any) -> float:
    """One-sided Hausdorff distance original -> kept, normalised by the bbox diagonal.

    Parameters
    ----------
    original : array_like, shape (n, 3)
    kept : array_like, shape (n,) bool or (m, 3) float

    Returns
    -------
    float
        ``max_{p in O} min_{q in K} ||p - q|| / D`` with ``D`` the bounding-box
        diagonal of the original.

    Notes
    -----
    Only the direction original -> kept is measured (how far the worst
    original point is from the simplified set); for a kept subset the other
    direction is 0 anyway.
    """
    orig = _check_points(original, "original")
    kept_pts, _ = _resolve_kept(orig, kept)
    diag = _diag(orig)
    d_ok, _ = cKDTree(kept_pts).query(orig, k=1, workers=_WORKERS)
    return float(d_ok.max() / diag)


# ---------------------------------------------------------------------------
# sharp edges: coverage and detection
# ---------------------------------------------------------------------------


#: a vertex where the edge turns by more than this (degrees) ends a polyline (a corner)
CORNER_DEG = 30.0


def sample_segments(edge_segments: Any, spacing: float) -> np.ndarray:
    """Sample the edge lines the segments form at (at most) the given spacing, by arc length.

    Segments are joined into polylines at the vertices (equal coordinates) that exactly two
    segments share and where the line turns by at most :data:`CORNER_DEG`; every other vertex
    (an end, a junction, a corner) ends a polyline. A polyline of length ``L`` gets
    ``ceil(L / spacing) + 1`` evenly spaced samples along it, its ends included. So a curved
    edge tessellated into segments much shorter than the spacing (a hole's rim, a thread, an
    engraving) is sampled at the spacing like a straight one — DESIGN §4's "sample the true
    sharp edges at the original spacing" — and not once per segment end, which weighted such
    edges by their tessellation (the counter part's 31,565 segments gave 33,952 samples for
    6,898 spacings of edge).

    Parameters
    ----------
    edge_segments : array_like, shape (k, 2, 3)
        Segment end points.
    spacing : float
        Maximum distance between consecutive samples along a polyline (> 0).

    Returns
    -------
    numpy.ndarray, shape (p, 3)
        Unique sample points.
    """
    seg = _check_segments(edge_segments)
    s = _check_positive(spacing, "spacing")
    pos, vid = np.unique(seg.reshape(-1, 3), axis=0, return_inverse=True)
    vid = vid.reshape(-1, 2)
    vid = vid[vid[:, 0] != vid[:, 1]]  # zero-length segments join nothing
    nbrs = [[] for _ in range(len(pos))]
    for i, (u, w) in enumerate(vid):
        nbrs[u].append((w, i))
        nbrs[w].append((u, i))
    cos_corner = np.cos(np.deg2rad(CORNER_DEG))

    def passes(v):  # a polyline runs on through v
        if len(nbrs[v]) != 2:
            return False
        d1 = pos[v] - pos[nbrs[v][0][0]]
        d2 = pos[nbrs[v][1][0]] - pos[v]
        return float(d1 @ d2) > cos_corner * float(np.linalg.norm(d1) * np.linalg.norm(d2))

    used = np.zeros(len(vid), dtype=bool)
    lines = []
    ends = [v for v in range(len(pos)) if nbrs[v] and not passes(v)]
    for start in ends + list(range(len(pos))):  # then the closed loops with no end
        for nxt, i in nbrs[start]:
            if used[i]:
                continue
            used[i] = True
            line = [start, nxt]
            while nxt != start and passes(nxt):
                step = [(w, j) for w, j in nbrs[nxt] if not used[j]]
                if not step:
                    break
                nxt, j = step[0]
                used[j] = True
                line.append(nxt)
            lines.append(pos[line])
    pts = []
    for line in lines:
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
        t = np.linspace(0.0, arc[-1], int(max(np.ceil(arc[-1] / s - 1e-9), 1)) + 1)
        pts.append(np.column_stack([np.interp(t, arc, line[:, c]) for c in range(3)]))
    return np.unique(np.concatenate(pts), axis=0) if pts else np.zeros((0, 3))


def edge_coverage(
    original: Any,
    kept: Any,
    edge_samples: Any,
    spacing: float | None = None,
    *,
    factor: float = 1.5,
) -> float:
    """Fraction of sharp-edge samples that have a kept point nearby.

    Parameters
    ----------
    original : array_like, shape (n, 3)
        The original cloud (used to resolve a mask ``kept`` and the default spacing).
    kept : array_like, shape (n,) bool or (m, 3) float
    edge_samples : array_like, shape (p, 3)
        Points sampled along the true sharp edges (e.g. of the CAD mesh) at
        about the original spacing.
    spacing : float, optional
        Sampling spacing ``s``; default: median nearest-neighbour distance of
        the original (:func:`spacing`).
    factor : float, default 1.5
        Coverage radius in units of ``s``.

    Returns
    -------
    float
        ``#{e : min_q ||e - q|| <= factor * s} / #edge_samples``, in [0, 1].
    """
    orig = _check_points(original, "original")
    kept_pts, _ = _resolve_kept(orig, kept)
    samples = _check_points(edge_samples, "edge_samples")
    s = _resolve_spacing(orig, spacing)
    f = _check_positive(factor, "factor")
    return _edge_coverage(kept_pts, samples, f * s)


def _edge_coverage(
    kept_pts: np.ndarray, samples: np.ndarray, radius: float, kept_tree: cKDTree | None = None
) -> float:
    tree = cKDTree(kept_pts) if kept_tree is None else kept_tree
    d, _ = tree.query(samples, k=1, distance_upper_bound=radius * (1 + 1e-12), workers=_WORKERS)
    return float(np.count_nonzero(d <= radius) / samples.shape[0])


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise exact distance of p[i] to segment [a[i], b[i]] (handles zero-length segments)."""
    ab = b - a
    ap = p - a
    den = np.einsum("ij,ij->i", ab, ab)
    num = np.einsum("ij,ij->i", ap, ab)
    t = np.clip(num / np.where(den > 0.0, den, 1.0), 0.0, 1.0)
    return np.linalg.norm(ap - t[:, None] * ab, axis=1)


def _subdivide(seg: np.ndarray, max_len: float) -> tuple[np.ndarray, np.ndarray]:
    """Split segments longer than max_len into equal pieces; return piece end points a, b."""
    a, b = seg[:, 0], seg[:, 1]
    if not max_len > 0.0:
        return a, b
    length = np.linalg.norm(b - a, axis=1)
    pieces = np.maximum(np.ceil(length / max_len), 1).astype(np.int64)
    if np.all(pieces == 1):
        return a, b
    owner = np.repeat(np.arange(seg.shape[0]), pieces)
    starts = np.cumsum(pieces) - pieces
    local = np.arange(owner.size) - np.repeat(starts, pieces)
    t0 = (local / pieces[owner])[:, None]
    t1 = ((local + 1) / pieces[owner])[:, None]
    pa = a[owner] * (1.0 - t0) + b[owner] * t0
    pb = a[owner] * (1.0 - t1) + b[owner] * t1
    return pa, pb


def _min_over_pairs(
    n: int, i: np.ndarray, d: np.ndarray, init: np.ndarray | None = None
) -> np.ndarray:
    out = np.full(n, np.inf) if init is None else init
    if i.size:
        np.minimum.at(out, i, d)
    return out


def distance_to_segments(
    points: Any,
    edge_segments: Any,
    *,
    max_distance: float | None = None,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
) -> np.ndarray:
    """Exact distance from every point to the nearest of a set of segments.

    Parameters
    ----------
    points : array_like, shape (n, 3)
    edge_segments : array_like, shape (k, 2, 3)
        Segment end points (zero-length segments are allowed and act as points).
    max_distance : float, optional
        If given, only distances ``<= max_distance`` are computed; every point
        farther than that from all segments gets ``inf``.  This is much cheaper
        when only a threshold test is needed.
    chunk_size : int, default 65536
        Number of points handled per batch.

    Returns
    -------
    numpy.ndarray, shape (n,)
        ``min_j dist(p_i, segment_j)`` (or ``inf`` beyond ``max_distance``).

    Notes
    -----
    Segments longer than a target length ``L`` (the median segment length, or
    ``max_distance`` if that is larger) are split into equal pieces, which does
    not change the distance to their union.  A KD-tree is built on the piece
    midpoints ``m_j``; with ``h`` the largest half-length,
    ``dist(p, seg_j) >= ||p - m_j|| - h``, so every piece within distance ``r``
    of ``p`` has its midpoint within ``r + h``.  Candidates are found with a
    radius query (``r = max_distance``, or for the unbounded case
    ``r`` = exact distance to the piece with the nearest midpoint, an upper
    bound of the true distance) and exact point-to-segment distances are
    evaluated only for those candidate pairs, vectorised.
    """
    pts = _check_points(points, "points")
    seg = _check_segments(edge_segments)
    chunk_size = _check_k(chunk_size, "chunk_size", minimum=1)
    if max_distance is not None:
        max_distance = _check_positive(max_distance, "max_distance")
    return _distance_to_segments(pts, seg, max_distance, chunk_size)


def _distance_to_segments(
    pts: np.ndarray, seg: np.ndarray, max_distance: float | None, chunk_size: int
) -> np.ndarray:
    length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    positive = length[length > 0.0]
    target = float(np.median(positive)) if positive.size else 0.0
    if max_distance is not None:
        target = max(target, max_distance)
    a, b = _subdivide(seg, target)
    mid = 0.5 * (a + b)
    half = 0.5 * float(np.linalg.norm(b - a, axis=1).max())
    tree = cKDTree(mid)
    n = pts.shape[0]
    out = np.empty(n, dtype=np.float64)
    slack = 1e-9 * (1.0 + half)  # guards the radius tests against rounding
    for start in range(0, n, chunk_size):
        q = pts[start : start + chunk_size]
        c = q.shape[0]
        if max_distance is not None:
            qtree = cKDTree(q)
            sdm = qtree.sparse_distance_matrix(
                tree, max_distance + half + slack, output_type="ndarray"
            )
            i = sdm["i"].astype(np.intp)
            j = sdm["j"].astype(np.intp)
            d = _point_segment_distance(q[i], a[j], b[j])
            res = _min_over_pairs(c, i, d)
            res[res > max_distance] = np.inf
        else:
            _, j0 = tree.query(q, k=1, workers=_WORKERS)
            upper = _point_segment_distance(q, a[j0], b[j0])
            lists = tree.query_ball_point(
                q, upper + half + slack, workers=_WORKERS, return_sorted=False
            )
            lens = np.fromiter((len(x) for x in lists), dtype=np.intp, count=c)
            j = np.fromiter(
                (v for x in lists for v in x), dtype=np.intp, count=int(lens.sum())
            )
            i = np.repeat(np.arange(c), lens)
            d = _point_segment_distance(q[i], a[j], b[j])
            res = _min_over_pairs(c, i, d, init=upper.copy())
        out[start : start + c] = res
    return out


def edge_ground_truth(
    points: Any,
    *,
    edge_samples: Any = None,
    edge_segments: Any = None,
    spacing: float | None = None,
    factor: float = 1.0,
) -> np.ndarray:
    """Boolean mask of the points that truly lie on/near a sharp edge.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        The original cloud.
    edge_samples : array_like, shape (p, 3), optional
        Dense samples along the true sharp edges; the distance to the edge
        polyline is approximated by the distance to the nearest sample.
    edge_segments : array_like, shape (k, 2, 3), optional
        The true sharp edges as segments; if given, exact point-to-segment
        distances are used (preferred; ``edge_samples`` is then ignored).
    spacing : float, optional
        Spacing ``s``; default: median nearest-neighbour distance of ``points``.
    factor : float, default 1.0
        A point is positive if its edge distance is ``<= factor * s``.

    Returns
    -------
    numpy.ndarray of bool, shape (n,)
    """
    pts = _check_points(points, "points")
    s = _resolve_spacing(pts, spacing)
    f = _check_positive(factor, "factor")
    return _edge_ground_truth(pts, edge_samples, edge_segments, f * s)


def _edge_ground_truth(
    pts: np.ndarray, edge_samples: Any, edge_segments: Any, radius: float
) -> np.ndarray:
    if edge_segments is not None:
        seg = _check_segments(edge_segments)
        d = _distance_to_segments(pts, seg, radius, DEFAULT_CHUNK_SIZE)
        return d <= radius
    if edge_samples is not None:
        samples = _check_points(edge_samples, "edge_samples")
        d, _ = cKDTree(samples).query(
            pts, k=1, distance_upper_bound=radius * (1 + 1e-12), workers=_WORKERS
        )
        return d <= radius
    raise InputError(
        "the true sharp edges are needed to judge edge detection; got neither "
        "`edge_samples` nor `edge_segments`. Fix: pass one of them."
    )


def boundary_detection(
    points: Any,
    flagged: Any,
    *,
    edge_samples: Any = None,
    edge_segments: Any = None,
    spacing: float | None = None,
    factor: float = 1.0,
) -> dict[str, float]:
    """Precision, recall and F1 of the points flagged as lying on a sharp edge.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        The original cloud.
    flagged : array_like of bool, shape (n,)
        Points the method flagged as on/near a sharp edge.
    edge_samples, edge_segments :
        The true sharp edges, see :func:`edge_ground_truth` (segments give exact
        distances and take precedence).
    spacing : float, optional
        Spacing ``s``; default: median nearest-neighbour distance of ``points``.
    factor : float, default 1.0
        Ground-truth positives are the points within ``factor * s`` of an edge.

    Returns
    -------
    dict
        ``precision = TP / #flagged``, ``recall = TP / #positives``,
        ``f1 = 2 P R / (P + R)``, plus the counts ``n_flagged``,
        ``n_positive``, ``n_true_positive`` (as floats).

    Notes
    -----
    A ratio with a zero denominator is reported as 0.0 (as scikit-learn's
    ``zero_division=0``): nothing flagged -> precision 0; no positives ->
    recall 0; ``P + R = 0`` -> F1 0.
    """
    pts = _check_points(points, "points")
    flag = _check_mask(flagged, pts.shape[0], "flagged")
    s = _resolve_spacing(pts, spacing)
    f = _check_positive(factor, "factor")
    truth = _edge_ground_truth(pts, edge_samples, edge_segments, f * s)
    return _prf(flag, truth)


def _prf(flag: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    n_flag = int(np.count_nonzero(flag))
    n_pos = int(np.count_nonzero(truth))
    tp = int(np.count_nonzero(flag & truth))
    precision = tp / n_flag if n_flag else 0.0
    recall = tp / n_pos if n_pos else 0.0
    f1 = 2.0 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return {
        "precision": float(precision),
        "recall": float(recall),
        "f1": float(f1),
        "n_flagged": float(n_flag),
        "n_positive": float(n_pos),
        "n_true_positive": float(tp),
    }


# ---------------------------------------------------------------------------
# adaptivity
# ---------------------------------------------------------------------------


def curvature_regions(
    points: Any,
    k: int = 16,
    quantile: float = 0.5,
    *,
    min_variation: float = 1e-9,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
) -> np.ndarray:
    """Mark the points of a cloud that lie in curved / feature regions.

    Parameters
    ----------
    points : array_like, shape (n, 3)
    k : int, default 16
        Neighbourhood size (the point itself included; all points if n < k).
    quantile : float, default 0.5
        A point is "curved" if its surface variation is strictly above this
        quantile (in [0, 1]) of all surface variations of the cloud.
    min_variation : float, default 1e-9
        ... and also strictly above this floor, so that round-off on exactly
        planar parts (variation ~1e-17) is never classified as curved.
    chunk_size : int, default 65536
        Number of points per PCA batch.

    Returns
    -------
    numpy.ndarray of bool, shape (n,)
        ``True`` for curved/feature points, ``False`` for flat points.

    Notes
    -----
    The surface variation of Pauly et al. [1]_ is
    ``sigma = l0 / (l0 + l1 + l2)`` with ``l0 <= l1 <= l2`` the eigenvalues of
    the covariance matrix of the k nearest neighbours.  It is 0 on a plane and
    at most 1/3 (isotropic neighbourhood); it grows with curvature and near
    sharp edges and corners.  Neighbourhoods with zero total variance (all
    neighbours coincide) get ``sigma = 0``.

    References
    ----------
    .. [1] M. Pauly, M. Gross, L. P. Kobbelt, "Efficient simplification of
       point-sampled surfaces", IEEE Visualization 2002, pp. 163-170.
    """
    pts = _check_points(points, "points")
    k = _check_k(k, "k", minimum=1)
    chunk_size = _check_k(chunk_size, "chunk_size", minimum=1)
    try:
        q = float(quantile)
    except (TypeError, ValueError):
        q = float("nan")
    if not 0.0 <= q <= 1.0:
        raise InputError(
            f"`quantile` must be a number in [0, 1]; got {quantile!r}. Fix: pass e.g. 0.5."
        )
    try:
        floor = float(min_variation)
    except (TypeError, ValueError):
        floor = float("nan")
    if not np.isfinite(floor):
        raise InputError(
            f"`min_variation` must be a finite number; got {min_variation!r}. Fix: pass e.g. 1e-9."
        )
    k_eff = min(k, pts.shape[0])
    tree = cKDTree(pts)
    sigma = np.empty(pts.shape[0], dtype=np.float64)
    for start in range(0, pts.shape[0], chunk_size):
        chunk = pts[start : start + chunk_size]
        _, idx = tree.query(chunk, k=k_eff, workers=_WORKERS)
        idx = np.asarray(idx).reshape(chunk.shape[0], k_eff)
        _, evals, _ = _batched_pca(pts[idx])
        evals = np.clip(evals, 0.0, None)
        total = evals.sum(axis=1)
        sigma[start : start + chunk.shape[0]] = np.where(
            total > 0.0, evals[:, 0] / np.where(total > 0.0, total, 1.0), 0.0
        )
    threshold = float(np.quantile(sigma, q))
    return (sigma > threshold) & (sigma > floor)


def adaptivity(
    original: Any, kept: Any, feature_region: Any, *, match_tol: float | None = None
) -> float:
    """Ratio of the kept fraction in the feature region to the kept fraction elsewhere.

    Parameters
    ----------
    original : array_like, shape (n, 3)
    kept : array_like, shape (n,) bool or (m, 3) float
        If given as points they must coincide (within ``match_tol``) with
        original points; each is attributed to the region of its nearest
        original point.
    feature_region : array_like of bool, shape (n,)
        ``True`` for original points in the curved/feature region (e.g. from
        :func:`curvature_regions`), ``False`` for the flat region.  Both
        regions must be non-empty.
    match_tol : float, optional
        Matching tolerance for ``kept`` given as points; default
        ``1e-9 * bbox diagonal``.

    Returns
    -------
    float
        ``(K_f / N_f) / (K_r / N_r)`` where ``N_f, N_r`` are the numbers of
        original points in the feature region and in the rest, and
        ``K_f, K_r`` the numbers of kept points in each.  > 1 means the
        simplification keeps relatively more points where the surface is
        curved.  ``inf`` if no flat point is kept.
    """
    orig = _check_points(original, "original")
    region = _check_mask(feature_region, orig.shape[0], "feature_region")
    n_f = int(np.count_nonzero(region))
    n_r = orig.shape[0] - n_f
    if n_f == 0 or n_r == 0:
        raise InputError(
            "adaptivity compares the feature region with the rest and needs both to be "
            f"non-empty; got {n_f} feature point(s) and {n_r} other point(s). "
            "Fix: pass a `feature_region` mask with both True and False entries."
        )
    k_f, k_r = _kept_region_counts(orig, kept, region, match_tol)
    return _ratio(k_f, n_f, k_r, n_r)


def _ratio(k_f: int, n_f: int, k_r: int, n_r: int) -> float:
    frac_f = k_f / n_f
    frac_r = k_r / n_r
    if frac_r == 0.0:
        return float("inf")
    return float(frac_f / frac_r)


# ---------------------------------------------------------------------------
# everything at once
# ---------------------------------------------------------------------------


#: the peak memory of :func:`evaluate` per point of the two clouds beyond the points themselves,
#: rounded up (bytes): 342 / 145 measured at 300k / 1M original points with 20 % kept
#: (2026-12-03, the LAZ scan of ``benchmarks/pipeline_speed.py``, ``VmHWM`` less the RSS
#: before the call). What the ``evaluate`` command checks against the memory left.
EVALUATE_BYTES_PER_POINT = 400


#: the keys of :func:`evaluate` that count points (floats in its dict, like every value)
COUNT_KEYS = ("n_original", "n_kept")


def as_json(result):
    """:func:`evaluate`'s dict for a JSON file: the counts as integers (``110000``, not
    ``110000.0``, which JSON readers take for a float), every other value as it is."""
    return {k: int(v) if k in COUNT_KEYS else v for k, v in result.items()}


def evaluate(
    original: Any,
    kept: Any,
    *,
    edge_samples: Any = None,
    edge_segments: Any = None,
    spacing: float | None = None,
    flagged: Any = None,
    k: int = 8,
    feature_region: Any = None,
) -> dict[str, float]:
    """Compute every applicable quality measure of a simplification.

    Parameters
    ----------
    original : array_like, shape (n, 3)
        The original cloud (at least 2 distinct points).
    kept : array_like, shape (n,) bool or (m, 3) float
        The kept set, as a boolean mask over ``original`` or as coordinates.
    edge_samples : array_like, shape (p, 3), optional
        Points sampled along the true sharp edges at about the original spacing.
    edge_segments : array_like, shape (k, 2, 3), optional
        The true sharp edges as segments (exact distances for the boundary
        ground truth; sampled at ``spacing`` for the coverage if
        ``edge_samples`` is not given).
    spacing : float, optional
        Spacing ``s``; default: median nearest-neighbour distance of ``original``.
    flagged : array_like of bool, shape (n,), optional
        Points flagged by the method as on/near a sharp edge.
    k : int, default 8
        Neighbourhood size of the surface error.
    feature_region : array_like of bool, shape (n,), optional
        Curved/feature region for the adaptivity; default
        ``curvature_regions(original)``.

    Returns
    -------
    dict of str to float
        Always: ``n_original``, ``n_kept``, ``chamfer``, ``hausdorff``, and
        ``hausdorff_model_units``: the same distance in the input's units (what
        ``max_spacing`` bounds), with ``diagonal``, the diagonal the others are divided by.
        ``surface_error_mean``, ``surface_error_max``: if at least 3 points are kept.
        ``edge_coverage``: if edge samples or segments are given (radius 1.5 s).
        ``boundary_precision``, ``boundary_recall``, ``boundary_f1``: if
        ``flagged`` and edge samples or segments are given (radius 1.0 s).
        ``adaptivity``: if both the feature region and the rest are non-empty
        (and, for ``kept`` given as points, they all match original points).
        Keys that cannot be computed are omitted.

    Notes
    -----
    Distances are normalised by the bounding-box diagonal of the original;
    the Chamfer distance is the sum of the two mean nearest-neighbour
    distances (see :func:`chamfer_distance`); the Hausdorff distance is
    one-sided, original -> kept.

    References
    ----------
    .. [1] M. Pauly, M. Gross, L. P. Kobbelt, "Efficient simplification of
       point-sampled surfaces", IEEE Visualization 2002, pp. 163-170.
    """
    orig = _check_points(original, "original", min_points=2)
    kept_pts, kept_mask = _resolve_kept(orig, kept)
    k = _check_k(k)
    diag = _diag(orig)
    flag = _check_mask(flagged, orig.shape[0], "flagged") if flagged is not None else None
    samples = _check_points(edge_samples, "edge_samples") if edge_samples is not None else None
    seg = _check_segments(edge_segments) if edge_segments is not None else None
    region = (
        _check_mask(feature_region, orig.shape[0], "feature_region")
        if feature_region is not None
        else None
    )
    have_edges = samples is not None or seg is not None
    s = _resolve_spacing(orig, spacing) if have_edges else None

    kept_tree = cKDTree(kept_pts)
    result: dict[str, float] = {
        "n_original": float(orig.shape[0]),
        "n_kept": float(kept_pts.shape[0]),
    }
    if kept_pts.shape[0] >= 3:
        d = _surface_distances(orig, kept_pts, k, DEFAULT_CHUNK_SIZE, kept_tree)
        result["surface_error_mean"] = float(d.mean() / diag)
        result["surface_error_max"] = float(d.max() / diag)
    d_ok, d_ko = _nn_both_ways(orig, kept_pts, kept_tree=kept_tree)
    result["chamfer"] = float((d_ok.mean() + d_ko.mean()) / diag)
    result["hausdorff"] = float(d_ok.max() / diag)
    result["hausdorff_model_units"] = float(d_ok.max())
    result["diagonal"] = float(diag)

    if have_edges:
        assert s is not None
        cov_samples = samples if samples is not None else sample_segments(seg, s)
        result["edge_coverage"] = _edge_coverage(kept_pts, cov_samples, 1.5 * s, kept_tree)
        if flag is not None:
            truth = _edge_ground_truth(orig, samples, seg, 1.0 * s)
            prf = _prf(flag, truth)
            result["boundary_precision"] = prf["precision"]
            result["boundary_recall"] = prf["recall"]
            result["boundary_f1"] = prf["f1"]

    if region is None:
        region = curvature_regions(orig)
    n_f = int(np.count_nonzero(region))
    n_r = orig.shape[0] - n_f
    if n_f > 0 and n_r > 0:
        try:
            k_f, k_r = _kept_region_counts(
                orig, kept_mask if kept_mask is not None else kept_pts, region, None
            )
        except InputError:
            pass  # kept points are not a subset of the original: adaptivity undefined
        else:
            result["adaptivity"] = _ratio(k_f, n_f, k_r, n_r)
    return result
