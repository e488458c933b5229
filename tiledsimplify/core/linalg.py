"""Closed-form 3x3 symmetric eigen-solves and small dense solves for the kernels.

Every point's plane fit in the paper's steps (neighbour selection, normals, boundary measure)
needs the eigenvalues of a 3x3 covariance. Calling ``np.linalg.eigh`` per point costs
microseconds in allocation alone; these run allocation-free inside numba kernels.
"""

import math

from ._jit import jit, jit_inline


@jit
def sym3_eigvals(a00, a01, a02, a11, a12, a22):
    """Eigenvalues (ascending) of a symmetric 3x3 matrix, trigonometric closed form.

    Notes
    -----
    Smith, "Eigenvalues of a symmetric 3x3 matrix", CACM 4(4), 1961. Exact up to rounding for
    any symmetric input, including repeated eigenvalues.
    """
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    if p1 == 0.0:
        l0, l1, l2 = a00, a11, a22
        # sort three values
        if l0 > l1:
            l0, l1 = l1, l0
        if l1 > l2:
            l1, l2 = l2, l1
        if l0 > l1:
            l0, l1 = l1, l0
        return l0, l1, l2
    b00 = a00 - q
    b11 = a11 - q
    b22 = a22 - q
    p2 = b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1
    p = math.sqrt(p2 / 6.0)
    if p == 0.0:
        return q, q, q
    inv = 1.0 / p
    c00 = b00 * inv
    c11 = b11 * inv
    c22 = b22 * inv
    c01 = a01 * inv
    c02 = a02 * inv
    c12 = a12 * inv
    det = (c00 * (c11 * c22 - c12 * c12)
           - c01 * (c01 * c22 - c12 * c02)
           + c02 * (c01 * c12 - c11 * c02))
    r = det / 2.0
    if r <= -1.0:
        phi = math.pi / 3.0
    elif r >= 1.0:
        phi = 0.0
    else:
        phi = math.acos(r) / 3.0
    l2 = q + 2.0 * p * math.cos(phi)
    l0 = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    l1 = 3.0 * q - l0 - l2
    return l0, l1, l2


@jit
def sym3_eigvec(a00, a01, a02, a11, a12, a22, lam, out):
    """Unit eigenvector of a symmetric 3x3 matrix for eigenvalue ``lam``, written to ``out``.

    The eigenvector spans the null space of ``A - lam I``: the largest cross product of two of
    its rows. Returns False when that null space is more than one-dimensional (a repeated
    eigenvalue), in which case ``out`` is left unchanged.
    """
    r0x, r0y, r0z = a00 - lam, a01, a02
    r1x, r1y, r1z = a01, a11 - lam, a12
    r2x, r2y, r2z = a02, a12, a22 - lam
    # three candidate cross products
    c0x = r0y * r1z - r0z * r1y
    c0y = r0z * r1x - r0x * r1z
    c0z = r0x * r1y - r0y * r1x
    c1x = r0y * r2z - r0z * r2y
    c1y = r0z * r2x - r0x * r2z
    c1z = r0x * r2y - r0y * r2x
    c2x = r1y * r2z - r1z * r2y
    c2y = r1z * r2x - r1x * r2z
    c2z = r1x * r2y - r1y * r2x
    n0 = c0x * c0x + c0y * c0y + c0z * c0z
    n1 = c1x * c1x + c1y * c1y + c1z * c1z
    n2 = c2x * c2x + c2y * c2y + c2z * c2z
    scale = (abs(a00) + abs(a11) + abs(a22) + abs(a01) + abs(a02) + abs(a12) + abs(lam))
    if scale == 0.0:
        return False
    if n0 >= n1 and n0 >= n2:
        best, x, y, z = n0, c0x, c0y, c0z
    elif n1 >= n2:
        best, x, y, z = n1, c1x, c1y, c1z
    else:
        best, x, y, z = n2, c2x, c2y, c2z
    if best <= (1e-12 * scale * scale) ** 2:
        return False
    s = 1.0 / math.sqrt(best)
    out[0] = x * s
    out[1] = y * s
    out[2] = z * s
    return True


@jit_inline
def any_perpendicular(vx, vy, vz, out):
    """A unit vector perpendicular to (vx, vy, vz), written to ``out``."""
    ax, ay, az = abs(vx), abs(vy), abs(vz)
    if ax <= ay and ax <= az:
        x, y, z = 0.0, -vz, vy
    elif ay <= az:
        x, y, z = vz, 0.0, -vx
    else:
        x, y, z = -vy, vx, 0.0
    n = math.sqrt(x * x + y * y + z * z)
    if n == 0.0:
        out[0], out[1], out[2] = 1.0, 0.0, 0.0
        return
    out[0], out[1], out[2] = x / n, y / n, z / n


@jit
def tangent_basis(n, t1, t2):
    """Orthonormal (t1, t2) completing the unit vector ``n`` to a right-handed frame."""
    any_perpendicular(n[0], n[1], n[2], t1)
    t2[0] = n[1] * t1[2] - n[2] * t1[1]
    t2[1] = n[2] * t1[0] - n[0] * t1[2]
    t2[2] = n[0] * t1[1] - n[1] * t1[0]


@jit
def smallest_axis(c00, c01, c02, c11, c12, c22, out, work):
    """Unit eigenvector of the smallest eigenvalue of a 3x3 covariance (a plane normal).

    Returns ``(l0, l1, l2)``, the ascending eigenvalues. When the smallest eigenvalue is
    repeated (points on a line, or a single point) the normal is any unit vector perpendicular
    to the principal axis, or (0, 0, 1) if there is no principal axis either.
    """
    l0, l1, l2 = sym3_eigvals(c00, c01, c02, c11, c12, c22)
    smallest_axis_given(c00, c01, c02, c11, c12, c22, l0, l2, out, work)
    return l0, l1, l2


@jit_inline
def smallest_axis_given(c00, c01, c02, c11, c12, c22, l0, l2, out, work):
    """:func:`smallest_axis` when the smallest and largest eigenvalues ``l0``, ``l2`` (from
    :func:`sym3_eigvals` on the same matrix) are already known."""
    if sym3_eigvec(c00, c01, c02, c11, c12, c22, l0, out):
        return
    # l0 == l1: the null space of A - l0 I is a plane; the principal axis is defined by l2
    if sym3_eigvec(c00, c01, c02, c11, c12, c22, l2, work):
        any_perpendicular(work[0], work[1], work[2], out)
    else:
        out[0], out[1], out[2] = 0.0, 0.0, 1.0


@jit
def orient_canonical(v):
    """Flip ``v`` so that its largest-magnitude component is positive (a deterministic sign)."""
    ax, ay, az = abs(v[0]), abs(v[1]), abs(v[2])
    if ax >= ay and ax >= az:
        s = v[0]
    elif ay >= az:
        s = v[1]
    else:
        s = v[2]
    if s < 0.0:
        v[0] = -v[0]
        v[1] = -v[1]
        v[2] = -v[2]


@jit
def solve_small(A, b, n):
    """Solve the dense ``n x n`` system ``A x = b`` in place (partial pivoting); x in ``b``.

    Returns False if the matrix is numerically singular. ``A`` and ``b`` are overwritten.
    """
    for k in range(n):
        piv = k
        best = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > best:
                best = abs(A[i, k])
                piv = i
        if best <= 1e-300:
            return False
        if piv != k:
            for j in range(n):
                A[k, j], A[piv, j] = A[piv, j], A[k, j]
            b[k], b[piv] = b[piv], b[k]
        inv = 1.0 / A[k, k]
        for i in range(k + 1, n):
            f = A[i, k] * inv
            if f != 0.0:
                for j in range(k, n):
                    A[i, j] -= f * A[k, j]
                b[i] -= f * b[k]
    for k in range(n - 1, -1, -1):
        s = b[k]
        for j in range(k + 1, n):
            s -= A[k, j] * b[j]
        b[k] = s / A[k, k]
    return True


#: running moments ``(sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)`` of no point
NO_MOMENTS = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@jit_inline
def add_moments(m, X, q, px, py, pz):
    """The running moments ``m`` (see :data:`NO_MOMENTS`) with point ``q`` added, its
    coordinates taken relative to ``(px, py, pz)``."""
    sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = m
    x, y, z = X[q, 0] - px, X[q, 1] - py, X[q, 2] - pz
    return (sx + x, sy + y, sz + z, sxx + x * x, sxy + x * y, sxz + x * z, syy + y * y,
            syz + y * z, szz + z * z)


@jit_inline
def moments_covariance(m, k):
    """Covariance (c00, c01, c02, c11, c12, c22) of a reference point (the origin of the
    moments) and the ``k`` points summed in ``m``."""
    sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = m
    cnt = k + 1.0
    mx, my, mz = sx / cnt, sy / cnt, sz / cnt
    return (sxx / cnt - mx * mx, sxy / cnt - mx * my, sxz / cnt - mx * mz,
            syy / cnt - my * my, syz / cnt - my * mz, szz / cnt - mz * mz)


@jit
def covariance_about(X, p, idx, k):
    """Covariance (c00, c01, c02, c11, c12, c22) of ``p`` and the points ``idx[:k]``.

    Offsets are taken from ``p`` before summing, so the result keeps its precision far from the
    origin (LAS coordinates).
    """
    px, py, pz = X[p, 0], X[p, 1], X[p, 2]
    m = NO_MOMENTS
    for j in range(k):
        m = add_moments(m, X, idx[j], px, py, pz)
    return moments_covariance(m, k)
