"""3-D Delaunay tetrahedralisation by incremental insertion (Bowyer–Watson), compiled.

Proposes the candidate edges of the Voronoi neighbourhoods (paper §3.1, :mod:`.voronoi`) when
the reach is finite. Qhull builds the same triangulation as a 4-D convex hull and took 27–30
µs per point on a 100k-point scan — as long as the whole removal loop; this takes a fraction of
that. Qhull stays in use for the paper's unbounded neighbourhoods (whose hull edges need the
exact convex hull), planar and tiny clouds, and as the fallback if anything here fails.

Method (Bowyer 1981; Watson 1981), as in CGAL and Geogram:

* insertion order: BRIO (Amenta, Choi & Rote 2003) — random rounds of doubling size, each
  sorted along a Morton curve — so a walk from the last new tetrahedron finds the next point
  in a few steps;
* a super-tetrahedron far outside the points starts the triangulation; its corners' edges are
  dropped at the end. Edges near the convex hull of the input can therefore differ from the
  true Delaunay triangulation's, which is why the caller surrounds the cloud with guard points
  (:func:`.voronoi.guard_points`): every edge whose Voronoi facet comes within the reach has an
  empty witness ball of radius at most the reach inside the guard shell, which no corner of the
  super-tetrahedron can enter, so it is an edge here too;
* location by a visibility walk with a random first face (Devillers, Pion & Teillaud 2002);
* the cavity of a new point: the tetrahedra whose circumsphere contains it, grown until every
  boundary facet is strictly visible from the point (floating-point predicates can make a
  cavity that is not star-shaped; growing it keeps the triangulation valid, at worst not
  exactly Delaunay in near-degenerate spots).

Predicates are plain floating point: the caller shifts the points by a tiny pseudo-random
jitter, so exact degeneracies (quantised scans) do not occur, and every candidate edge is then
checked exactly by :func:`.voronoi.filter_candidates` — an extra edge costs a test, never a
wrong neighbour. A face's orientation is always evaluated in one corner order, so the two
tetrahedra sharing it agree bit for bit and a walk cannot bounce between them; raw quantised
LAS tiles build even without the jitter. Tests compare the edges with Qhull's.
"""

import numpy as np

from ._jit import jit, jit_inline
from .bounds import box

#: vertices of face ``i`` (the face opposite vertex ``i``), ordered so that vertex ``i`` lies on
#: the positive side of the face (:func:`_orient` > 0) in a positively oriented tetrahedron
FACES = np.array([[1, 3, 2], [0, 2, 3], [0, 3, 1], [0, 1, 2]], dtype=np.int64)
#: a walk longer than this many steps per point means broken geometry: give up (fall back)
MAX_WALK = 100_000
#: tetrahedron ids are int32 (8 slots per point to start with): larger clouds go to Qhull
MAX_POINTS = 200_000_000


@jit_inline
def _orient(X, a, b, c, d):
    """``det[b - a, c - a, d - a]``: positive if ``d`` lies on the side of plane ``abc``
    that ``(b - a) x (c - a)`` points to."""
    bx, by, bz = X[b, 0] - X[a, 0], X[b, 1] - X[a, 1], X[b, 2] - X[a, 2]
    cx, cy, cz = X[c, 0] - X[a, 0], X[c, 1] - X[a, 1], X[c, 2] - X[a, 2]
    dx, dy, dz = X[d, 0] - X[a, 0], X[d, 1] - X[a, 1], X[d, 2] - X[a, 2]
    return (bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx))


@jit_inline
def _orient_face(X, a, b, c, d):
    """:func:`_orient` evaluated with the face's corners in increasing order (sign fixed by
    the permutation's parity): the two tetrahedra sharing a face then get bit-identical
    answers, so rounding cannot make a walk bounce between them forever."""
    flip = False
    if a > b:
        a, b = b, a
        flip = not flip
    if b > c:
        b, c = c, b
        flip = not flip
    if a > b:
        a, b = b, a
        flip = not flip
    o = _orient(X, a, b, c, d)
    return -o if flip else o


@jit_inline
def _insphere(X, a, b, c, d, e):
    """Positive if ``e`` lies inside the circumsphere of the positively oriented (by
    :func:`_orient`) tetrahedron ``abcd``; coordinates taken relative to ``e``."""
    ax, ay, az = X[a, 0] - X[e, 0], X[a, 1] - X[e, 1], X[a, 2] - X[e, 2]
    bx, by, bz = X[b, 0] - X[e, 0], X[b, 1] - X[e, 1], X[b, 2] - X[e, 2]
    cx, cy, cz = X[c, 0] - X[e, 0], X[c, 1] - X[e, 1], X[c, 2] - X[e, 2]
    dx, dy, dz = X[d, 0] - X[e, 0], X[d, 1] - X[e, 1], X[d, 2] - X[e, 2]
    la = ax * ax + ay * ay + az * az
    lb = bx * bx + by * by + bz * bz
    lc = cx * cx + cy * cy + cz * cz
    ld = dx * dx + dy * dy + dz * dz
    ab = ax * by - bx * ay
    bc = bx * cy - cx * by
    cd = cx * dy - dx * cy
    da = dx * ay - ax * dy
    ac = ax * cy - cx * ay
    bd = bx * dy - dx * by
    abc = az * bc - bz * ac + cz * ab
    bcd = bz * cd - cz * bd + dz * bc
    cda = cz * da + dz * ac + az * cd
    dab = dz * ab + az * bd + bz * da
    # Shewchuk's insphere is positive for e inside when orient3d(a,b,c,d) > 0 in his
    # convention, which is the negative of ours: hence the sign
    return -((ld * abc - lc * dab) + (lb * cda - la * bcd))


def _spread_bits():
    """``table[v]``: the 10 bits of ``v`` spread three apart (bit ``i`` to bit ``3 i``)."""
    v = np.arange(1024, dtype=np.int64)
    table = np.zeros(1024, dtype=np.int64)
    for bit in range(10):
        table |= ((v >> bit) & 1) << (3 * bit)
    return table


#: a Morton code's three interleaved 10-bit coordinates by table, not bit by bit: 3 gathers
#: instead of 30 passes over the points (140k points: 3.0 ms against 9.9, the same codes)
_SPREAD = _spread_bits()


def brio_order(P, seed=0):
    """Insertion order: rounds of doubling size drawn at random, each sorted along a Morton
    curve (biased randomised insertion order, Amenta, Choi & Rote 2003)."""
    n = P.shape[0]
    rng = np.random.default_rng(seed)
    perm = rng.permutation(n)
    lo, hi = box(P)
    ext = max(float((hi - lo).max()), 1e-300)
    q = np.minimum(((P - lo) / ext * 1023.0).astype(np.int64), 1023)
    code = _SPREAD[q[:, 0]] | (_SPREAD[q[:, 1]] << 1) | (_SPREAD[q[:, 2]] << 2)
    bounds = [n]
    while bounds[-1] > 1000:
        bounds.append(bounds[-1] // 2)
    bounds.append(0)
    bounds = bounds[::-1]
    parts = []
    for r0, r1 in zip(bounds[:-1], bounds[1:]):
        if r1 > r0:
            ids = perm[r0:r1]
            parts.append(ids[np.argsort(code[ids], kind="stable")])
    return np.concatenate(parts) if parts else perm


#: :func:`_insert` statuses: every point inserted; a buffer or the tetrahedron arrays must grow
#: first (nothing of the current point was written); broken geometry (fall back to Qhull)
DONE, GROW_WORK, GROW_TETS, FAILED = 0, 1, 2, 3
#: slots of :func:`_insert`'s ``state``: next step, tetrahedra used, free slots, last new
#: tetrahedron, the cavity mark, the work-buffer size needed
STEP, N_TETS, N_FREE, LAST, MARK, NEED = range(6)


@jit
def _build(X, order, n_real, cap, work):
    """Insert ``X[order]`` into the super-tetrahedron whose corners are ``X[n_real:n_real+4]``.

    Returns ``(tets, ok)``: the live tetrahedra (``(m, 4)`` int32, corner ids included) and
    whether the construction succeeded (``False``: a walk got lost, a cavity grew out of the
    super-tetrahedron or did not close — broken geometry, e.g. a duplicate point; the caller
    then uses Qhull). ``cap`` tetrahedron slots and ``work`` cavity and boundary slots to
    start with (both grow as needed).

    The insertions run in :func:`_insert`, which never replaces an array: when a buffer or
    the tetrahedron arrays are full it returns before writing anything of the current point,
    they grow here, and it goes on from that point. Growing them inside its loops made every
    array a loop-carried variable, whose every use numba's reference counting wrapped in an
    atomic increment and decrement: 35-40 % of the build's perf samples on 100k scan points;
    the build took 0.50 s there before, 0.40 s since.

    A tetrahedron's corners and neighbours share one 32-byte record (``tets`` and ``nbr`` are
    views of it), and one array tells whether it is in the cavity or was tested outside it:
    the cavity search reads both for each neighbour it meets, from four arrays before (the
    lines with the most perf samples). Build 0.91x the time (median of 8 alternating pairs,
    0.75-1.0, 100k scan points; the same tetrahedra).
    """
    rec = np.empty((cap, 8), dtype=np.int32)  # int32: half the memory traffic of int64
    rec[:, 4:] = -1
    tets, nbr = rec[:, :4], rec[:, 4:]
    alive = np.zeros(cap, dtype=np.bool_)
    flag = np.zeros(cap, dtype=np.int32)  # 2 mark: in the current cavity; 2 mark + 1: tested,
    # outside it (one array: one load tells both)
    free = np.empty(cap, dtype=np.int32)
    s0, s1, s2, s3 = n_real, n_real + 1, n_real + 2, n_real + 3
    if _orient(X, s0, s1, s2, s3) < 0.0:
        s2, s3 = s3, s2
    tets[0, 0], tets[0, 1], tets[0, 2], tets[0, 3] = s0, s1, s2, s3
    alive[0] = True
    cavity, stack, bt, bf, fv, hstamp, hx, hy, ht, hf = _work_buffers(work)
    state = np.zeros(6, dtype=np.int64)
    state[N_TETS] = 1
    rnd = np.full(1, 88172645463325252, dtype=np.uint64)
    while True:
        status = _insert(X, order, tets, nbr, alive, flag, free, cavity, stack, bt, bf,
                         fv, hstamp, hx, hy, ht, hf, state, rnd)
        if status == DONE:
            break
        if status == FAILED:
            return tets[:0], False
        if status == GROW_TETS:
            rec, alive, flag, free = _grow_all(rec, alive, flag, free)
            tets, nbr = rec[:, :4], rec[:, 4:]
        else:  # GROW_WORK: room for twice what the point needs
            while work < 2 * state[NEED]:
                work *= 2
            cavity, stack, bt, bf, fv, hstamp, hx, hy, ht, hf = _work_buffers(work)
    n_tets = state[N_TETS]
    return tets[:n_tets][alive[:n_tets]], True


@jit
def _work_buffers(work):
    """Scratch of one insertion for cavities and boundaries of up to ``work`` tetrahedra and
    facets: ``cavity``, ``stack``, ``bt``/``bf`` (boundary facets: the tetrahedron inside the
    cavity, the face index), ``fv`` (facet corners a, b, c, the outer tetrahedron, its face),
    and an open-addressing hash of the new tetrahedra's open faces, keyed by their edge on the
    cavity boundary (x < y), at most 3/8 full (3 faces a facet): ``hstamp`` (== mark: slot used
    for this point), ``hx``/``hy`` (the edge), ``ht``/``hf`` (the tetrahedron and face waiting
    for a partner)."""
    return (np.empty(work, dtype=np.int64), np.empty(work, dtype=np.int64),
            np.empty(work, dtype=np.int64), np.empty(work, dtype=np.int64),
            np.empty((work, 5), dtype=np.int64), np.zeros(8 * work, dtype=np.int64),
            np.empty(8 * work, dtype=np.int64), np.empty(8 * work, dtype=np.int64),
            np.empty(8 * work, dtype=np.int64), np.empty(8 * work, dtype=np.int64))


@jit
def _insert(X, order, tets, nbr, alive, flag, free, cavity, stack, bt, bf, fv, hstamp,
            hx, hy, ht, hf, state, rnd_state):
    """Insert ``X[order[state[STEP]:]]`` until done or an array is full (see :func:`_build`).

    ``state`` (:data:`STEP` ...) and ``rnd_state`` (the walk's xorshift state) are saved
    after every completed point, so a point stopped for room starts again exactly as before;
    its marks in ``flag`` are left behind under a mark not used again.
    """
    n_tets, n_free, last = state[N_TETS], state[N_FREE], state[LAST]
    mark = state[MARK]
    work = cavity.size
    cap = tets.shape[0]
    hmask = hstamp.size - 1
    rnd = rnd_state[0]
    for step in range(state[STEP], order.size):
        p = order[step]
        # -- locate: visibility walk from the last new tetrahedron
        t = last
        walked = 0
        while True:
            rnd ^= rnd << np.uint64(13)
            rnd ^= rnd >> np.uint64(7)
            rnd ^= rnd << np.uint64(17)
            r = np.int64(rnd & np.uint64(3))
            moved = False
            for k in range(4):
                i = (r + k) & 3
                a = tets[t, FACES[i, 0]]
                b = tets[t, FACES[i, 1]]
                c = tets[t, FACES[i, 2]]
                if _orient_face(X, a, b, c, p) < 0.0:
                    u = nbr[t, i]
                    if u >= 0:
                        t = u
                        moved = True
                        break
            if not moved:
                break
            walked += 1
            if walked > MAX_WALK:
                return FAILED
        # -- cavity: tetrahedra whose circumsphere holds p, grown until star-shaped from p
        mark += 1
        state[MARK] = mark
        n_cav = 1
        cavity[0] = t
        flag[t] = 2 * mark
        n_st = 1
        stack[0] = t
        while True:
            while n_st > 0:
                n_st -= 1
                T = stack[n_st]
                for i in range(4):
                    u = nbr[T, i]
                    if u < 0 or flag[u] >= 2 * mark:  # in the cavity or tested
                        continue
                    if _insphere(X, tets[u, 0], tets[u, 1], tets[u, 2], tets[u, 3], p) > 0.0:
                        if n_cav == work:  # the stack never holds more than the cavity
                            state[NEED] = n_cav + 1
                            return GROW_WORK
                        flag[u] = 2 * mark
                        cavity[n_cav] = u
                        n_cav += 1
                        stack[n_st] = u
                        n_st += 1
                    else:
                        flag[u] = 2 * mark + 1
            # boundary facets; any not strictly visible from p: take its outer tetrahedron in
            n_b = 0
            bad = -1
            for j in range(n_cav):
                T = cavity[j]
                for i in range(4):
                    u = nbr[T, i]
                    if u >= 0 and flag[u] == 2 * mark:
                        continue
                    if n_b == work:
                        state[NEED] = n_b + 1
                        return GROW_WORK
                    bt[n_b] = T
                    bf[n_b] = i
                    n_b += 1
                    if bad < 0:
                        a = tets[T, FACES[i, 0]]
                        b = tets[T, FACES[i, 1]]
                        c = tets[T, FACES[i, 2]]
                        if _orient_face(X, a, b, c, p) <= 0.0:
                            bad = u
                            if u < 0:
                                return FAILED  # p outside the super-tetrahedron
            if bad < 0:
                break
            if n_cav == work:
                state[NEED] = n_cav + 1
                return GROW_WORK
            flag[bad] = 2 * mark
            cavity[n_cav] = bad
            n_cav += 1
            stack[0] = bad
            n_st = 1
        # -- room for the new tetrahedra: the cavity's slots, the free list, then new slots
        if n_tets + max(0, n_b - n_free - n_cav) > cap:
            return GROW_TETS
        # -- new tetrahedra: one per boundary facet, joined to p. Read every facet before any
        # cavity slot is reused (a new tetrahedron may take the slot of one not read yet)
        for j in range(n_b):
            T = bt[j]
            i = bf[j]
            fv[j, 0] = tets[T, FACES[i, 0]]
            fv[j, 1] = tets[T, FACES[i, 1]]
            fv[j, 2] = tets[T, FACES[i, 2]]
            u = nbr[T, i]
            fv[j, 3] = u
            fv[j, 4] = -1
            if u >= 0:
                for q in range(4):
                    if nbr[u, q] == T:
                        fv[j, 4] = q
                        break
        for j in range(n_cav):
            T = cavity[j]
            alive[T] = False
            free[n_free] = T
            n_free += 1
        n_open = 0
        for j in range(n_b):
            a, b, c, u, q = fv[j, 0], fv[j, 1], fv[j, 2], fv[j, 3], fv[j, 4]
            if n_free > 0:
                n_free -= 1
                N = free[n_free]
            else:
                N = n_tets
                n_tets += 1
            tets[N, 0], tets[N, 1], tets[N, 2], tets[N, 3] = a, b, c, p
            alive[N] = True
            flag[N] = 0
            nbr[N, 3] = u
            if u >= 0:
                nbr[u, q] = N
            # faces 0, 1, 2 hold p and the edges (b, c), (a, c), (a, b)
            for f in range(3):
                if f == 0:
                    x, y = b, c
                elif f == 1:
                    x, y = a, c
                else:
                    x, y = a, b
                if x > y:
                    x, y = y, x
                h = ((x * 73856093) ^ (y * 19349663)) & hmask
                while True:
                    if hstamp[h] != mark:  # free: wait here for the partner face
                        hstamp[h] = mark
                        hx[h] = x
                        hy[h] = y
                        ht[h] = N
                        hf[h] = f
                        n_open += 1
                        break
                    if hx[h] == x and hy[h] == y:  # the partner: join, leave a tombstone
                        M = ht[h]
                        nbr[N, f] = M
                        nbr[M, hf[h]] = N
                        hx[h] = -1
                        n_open -= 1
                        break
                    h = (h + 1) & hmask
            last = N
        if n_open != 0:
            return FAILED  # the cavity was not a ball
        state[STEP] = step + 1
        state[N_TETS] = n_tets
        state[N_FREE] = n_free
        state[LAST] = last
        rnd_state[0] = rnd
    return DONE


@jit
def _grow_all(rec, alive, flag, free):
    """The tetrahedron arrays at twice their length (new slots: no neighbours, not alive)."""
    m = rec.shape[0]
    r2 = np.empty((2 * m, 8), dtype=np.int32)
    r2[:m] = rec
    r2[m:, 4:] = -1
    a2 = np.zeros(2 * m, dtype=np.bool_)
    a2[:m] = alive
    g2 = np.zeros(2 * m, dtype=np.int32)
    g2[:m] = flag
    f2 = np.empty(2 * m, dtype=np.int32)
    f2[:m] = free
    return r2, a2, g2, f2


@jit
def _real_tets(tets, n):
    """The rows of ``tets`` whose four corners are all below ``n`` (no super-tetrahedron
    corner), in order: ``tets[(tets < n).all(axis=1)]`` in two passes, not numpy's four
    (0.2-0.4 s of a 1M-point core run, ~6.5M tetrahedra)."""
    keep = 0
    for t in range(tets.shape[0]):
        if tets[t, 0] < n and tets[t, 1] < n and tets[t, 2] < n and tets[t, 3] < n:
            keep += 1
    out = np.empty((keep, 4), dtype=tets.dtype)
    k = 0
    for t in range(tets.shape[0]):
        if tets[t, 0] < n and tets[t, 1] < n and tets[t, 2] < n and tets[t, 3] < n:
            for j in range(4):
                out[k, j] = tets[t, j]
            k += 1
    return out


def delaunay_tets(P, seed=0):
    """Tetrahedra of the Delaunay triangulation of ``P`` (n, 3) as int32 point ids, or
    ``None`` if the construction failed (the caller then uses Qhull).

    Tetrahedra with a corner of the super-tetrahedron are dropped; near the convex hull the
    result can therefore miss hull tetrahedra (see the module notes).
    """
    P = np.ascontiguousarray(P, dtype=np.float64)
    n = P.shape[0]
    if n < 4 or n > MAX_POINTS:
        return None
    lo, hi = box(P)
    c = 0.5 * (lo + hi)
    r = max(float(np.linalg.norm(hi - lo)), 1e-300)
    M = 50.0 * r  # corners of a regular tetrahedron containing the ball of radius ~16 r
    corners = c + M * np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0],
                                [-1.0, -1.0, 1.0]])
    X = np.concatenate([P, corners])
    tets, ok = _build(X, brio_order(P, seed).astype(np.int64), n, 8 * n + 64, 256)
    if not ok:
        return None
    return _real_tets(tets, n)  # int32, as built: half the memory of int64
