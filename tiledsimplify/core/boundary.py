"""Boundary (sharp-edge) points: a curvature-compensated normal-deviation measure (paper §3.1).

Measure
    On a smooth surface the normal turns linearly with the offset from ``p`` (to first order:
    ``n(q) ≈ n(p) + W (q − p)``, ``W`` the symmetric shape operator); across a sharp edge it
    jumps. For each point we express the local-mesh neighbours' normals (oriented to ``n_p``'s
    side) in ``p``'s tangent frame, fit ``g_q ≈ W u_q`` by least squares (``u_q``: the tangent
    offset of ``q``, ``g_q``: the tangent part of ``n_q``; three unknowns for a symmetric 2x2
    ``W``), and take the RMS residual. The fitted ``W`` absorbs the deviation caused by smooth
    curvature, however strong; what remains is the part a smooth surface cannot explain — the
    tangential discontinuity of a sharp edge (and noise). The value is dimensionless (roughly an
    angle in radians).

Threshold
    Smooth-region values form the bulk of the distribution; sharp edges are its outliers. The
    automatic threshold is ``median + k · 1.4826 · MAD`` of all values (a robust "k standard
    deviations above the trend"), but never below ``FLOOR`` — on exact CAD planes the residual
    is rounding noise and its MAD is ~0. ``threshold=`` overrides it (useful to share one value
    across tiles).
"""

import numpy as np

from ._jit import jit, jit_leaf
from .linalg import solve_small, tangent_basis

#: default number of robust standard deviations above the median for an outlier
K_SIGMA = 3.0
#: the automatic threshold is never below this (radians)
FLOOR = 0.05


@jit_leaf
def deviation_at(X, normals, p, dn, c, A, b, frame):
    """The curvature-compensated normal deviation of ``p`` (see module docstring)."""
    if c < 3:
        return 0.0
    n0, n1, n2 = normals[p, 0], normals[p, 1], normals[p, 2]
    t1 = frame[0]
    t2 = frame[1]
    tangent_basis(normals[p], t1, t2)
    px, py, pz = X[p, 0], X[p, 1], X[p, 2]
    # scale offsets by their RMS so the system is well conditioned whatever the units
    s2 = 0.0
    for j in range(c):
        q = dn[j]
        dx, dy, dz = X[q, 0] - px, X[q, 1] - py, X[q, 2] - pz
        s2 += dx * dx + dy * dy + dz * dz
    scale = np.sqrt(s2 / c)
    if scale == 0.0:
        return 0.0
    inv = 1.0 / scale
    for i in range(3):
        b[i] = 0.0
        for j in range(3):
            A[i, j] = 0.0
    gg = 0.0
    for j in range(c):
        q = dn[j]
        dx, dy, dz = (X[q, 0] - px) * inv, (X[q, 1] - py) * inv, (X[q, 2] - pz) * inv
        u = dx * t1[0] + dy * t1[1] + dz * t1[2]
        v = dx * t2[0] + dy * t2[1] + dz * t2[2]
        m0, m1, m2 = normals[q, 0], normals[q, 1], normals[q, 2]
        if m0 * n0 + m1 * n1 + m2 * n2 < 0.0:
            m0, m1, m2 = -m0, -m1, -m2
        g1 = m0 * t1[0] + m1 * t1[1] + m2 * t1[2]
        g2 = m0 * t2[0] + m1 * t2[1] + m2 * t2[2]
        gg += g1 * g1 + g2 * g2
        # rows of the design matrix for W = [[a, w], [w, d]]: g1 = a u + w v, g2 = w u + d v
        # unknowns (a, w, d); accumulate normal equations
        # row 1: (u, v, 0) -> g1 ; row 2: (0, u, v) -> g2
        A[0, 0] += u * u
        A[0, 1] += u * v
        A[1, 1] += v * v + u * u
        A[1, 2] += u * v
        A[2, 2] += v * v
        b[0] += u * g1
        b[1] += v * g1 + u * g2
        b[2] += v * g2
    A[1, 0] = A[0, 1]
    A[2, 1] = A[1, 2]
    A[0, 2] = 0.0
    A[2, 0] = 0.0
    ridge = 1e-9 * (A[0, 0] + A[1, 1] + A[2, 2])
    for i in range(3):
        A[i, i] += ridge
    b0, b1, b2 = b[0], b[1], b[2]
    if not solve_small(A, b, 3):
        return np.sqrt(gg / (2.0 * c))
    # residual sum of squares = gg - 2 x.b + x.A x = gg - x.b0 at the least-squares optimum
    rss = gg - (b[0] * b0 + b[1] * b1 + b[2] * b2)
    if rss < 0.0:
        rss = 0.0
    return np.sqrt(rss / (2.0 * c))


@jit
def all_deviations(X, normals, dn, dn_cnt, out):
    """The deviation measure of every point."""
    A = np.empty((3, 3))
    b = np.empty(3)
    frame = np.empty((2, 3))
    for p in range(X.shape[0]):
        out[p] = deviation_at(X, normals, p, dn[p], dn_cnt[p], A, b, frame)


def automatic_threshold(values, k=K_SIGMA, floor=FLOOR):
    """``max(median + k * 1.4826 * MAD, floor)`` of the finite ``values``."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float(floor)
    med = float(np.median(v))
    mad = float(np.median(np.abs(v - med)))
    return max(med + k * 1.4826 * mad, float(floor))


def detect(deviation, *, threshold=None, k=K_SIGMA, floor=FLOOR):
    """Flag boundary points: ``deviation > threshold`` (automatic when ``threshold`` is None).

    Returns ``(flags, threshold_used)``.
    """
    t = automatic_threshold(deviation, k, floor) if threshold is None else float(threshold)
    return deviation > t, t
