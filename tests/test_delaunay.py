"""The compiled Delaunay triangulation against its definition and against Qhull."""

import itertools

import numpy as np
import pytest
from scipy.spatial import ConvexHull, cKDTree

from tiledsimplify.core import adjacency, delaunay, voronoi

import naive


def _cloud(kind, rng, jitter=True):
    if kind == "cube":
        return rng.random((3000, 3))
    if kind == "sphere":  # a surface: the shape of a scan
        v = rng.normal(size=(3000, 3))
        return v / np.linalg.norm(v, axis=1)[:, None] + 1e-3 * rng.normal(size=v.shape)
    # LAS-like: coordinates on a 1e-3 grid, full of co-spherical ties (jittered as the core does)
    v = rng.normal(size=(3000, 3))
    X = np.unique(np.round(v / np.linalg.norm(v, axis=1)[:, None] * 30) * 1e-3, axis=0)
    return X + 1e-10 * rng.uniform(-1, 1, X.shape) if jitter else X


@pytest.mark.parametrize("jitter", [True, False])
@pytest.mark.parametrize("kind", ["cube", "sphere", "quantised"])
def test_tetrahedra_are_positive_empty_and_fill_the_hull(kind, jitter):
    """Also without the core's jitter: exact ties on the quantised grid must not break it
    (face orientations are evaluated in one canonical order, so walks cannot cycle)."""
    rng = np.random.default_rng(3)
    X = _cloud(kind, rng, jitter)
    T = delaunay.delaunay_tets(X)
    vol = _check_valid(X, T, flat=not jitter)
    # the tetrahedra fill the convex hull, but for hull slivers the super-tetrahedron hides
    assert vol.sum() == pytest.approx(ConvexHull(X).volume, rel=2e-3)


@pytest.mark.parametrize("kind", ["cube", "sphere"])
def test_edges_are_qhulls_but_for_hull_edges(kind):
    rng = np.random.default_rng(5)
    X = _cloud(kind, rng)[:1500]
    got = {tuple(e) for e in voronoi._simplex_edges(delaunay.delaunay_tets(X)).tolist()}
    ref = naive.delaunay_edges(X)
    hull = set(ConvexHull(X).vertices.tolist())
    assert got <= ref
    assert {e for e in ref - got if not (e[0] in hull and e[1] in hull)} == set()


def _lists(start, cnt, pool):
    return [set(s) for s in adjacency.to_sets(start, cnt, pool)]


def test_reach_neighbours_equal_those_from_qhull_on_a_quantised_scan():
    """With a finite reach the core builds on this triangulation; filtered, its edges must be
    exactly those of Qhull's full triangulation (a superset of candidates, no guard points)."""
    rng = np.random.default_rng(8)
    n = 4000
    face = np.c_[rng.random((n, 2)) * 0.08, rng.normal(0.0, 1e-4, n)]
    face[:, 2] = np.round(face[:, 2] / 5e-4) * 5e-4  # a flat face in three exact layers
    X = np.vstack([face, np.c_[rng.random((n, 2)) * 0.08, np.full(n, -0.004)]])
    X = np.unique(np.round(X / 1e-4) * 1e-4, axis=0)
    X -= X.mean(0)
    reach = 20 * np.median(cKDTree(X).query(X, k=2)[0][:, 1])
    D = voronoi.scale_of(X)
    (start, cnt, cap, pool, meta), how = voronoi.voronoi_neighbours(X, reach=reach)
    assert how == "delaunay"
    E = np.array(sorted(naive.delaunay_edges(X)), dtype=np.int64)
    s0, c0, _, p0, _ = adjacency.from_edges(len(X), E, slack=0)
    kept = voronoi.filter_candidates(X, s0, c0, p0, voronoi.BOX_FACTOR * D,
                                     voronoi.TOL_FACTOR * D, reach)
    s1, c1, _, p1, _ = adjacency.from_edges(len(X), kept, slack=0)
    assert _lists(start, cnt, pool) == _lists(s1, c1, p1)


def test_a_failed_triangulation_falls_back_to_qhull(monkeypatch):
    rng = np.random.default_rng(9)
    X = rng.random((500, 3))
    (s0, c0, _, p0, _), how0 = voronoi.voronoi_neighbours(X, reach=0.3)
    monkeypatch.setattr(voronoi, "delaunay_tets", lambda C: None)
    (s1, c1, _, p1, _), how1 = voronoi.voronoi_neighbours(X, reach=0.3)
    assert (how0, how1) == ("delaunay", "qhull (compiled Delaunay failed)")
    assert _lists(s0, c0, p0) == _lists(s1, c1, p1)


def test_brio_order_is_a_permutation_in_rounds_of_doubling_size():
    P = np.random.default_rng(1).random((5000, 3))
    order = delaunay.brio_order(P)
    assert np.array_equal(np.sort(order), np.arange(5000))
    # the last round is the second half of a fixed random permutation, Morton-sorted
    perm = np.random.default_rng(0).permutation(5000)
    assert set(order[2500:].tolist()) == set(perm[2500:].tolist())


def _naive_brio(P, seed=0):
    """The order by its definition: Morton codes interleaved bit by bit, each round of the
    random permutation sorted by them (ties in permutation order)."""
    n = len(P)
    perm = np.random.default_rng(seed).permutation(n)
    lo, hi = P.min(axis=0), P.max(axis=0)
    q = np.minimum(((P - lo) / max(float((hi - lo).max()), 1e-300) * 1023.0).astype(np.int64),
                   1023)
    code = [sum(((int(q[i, d]) >> b) & 1) << (3 * b + d) for b in range(10) for d in range(3))
            for i in range(n)]
    sizes = [n]
    while sizes[-1] > 1000:
        sizes.append(sizes[-1] // 2)
    cuts = [0, *sizes[::-1]]
    out = []
    for r0, r1 in itertools.pairwise(cuts):
        out += sorted(perm[r0:r1].tolist(), key=lambda i: code[i])  # stable: perm order
    return np.array(out)


@pytest.mark.parametrize("cloud", ["random", "plane", "grid", "same"])
def test_brio_order_equals_its_definition(cloud):
    rng = np.random.default_rng(7)
    P = {"random": rng.normal(size=(3000, 3)) * [1e3, 1.0, 1e-3],
         "plane": np.c_[rng.random((2500, 2)), np.zeros(2500)],
         "grid": np.stack(np.meshgrid(*[np.arange(14.0)] * 3), -1).reshape(-1, 3),
         "same": np.ones((1200, 3))}[cloud]
    np.testing.assert_array_equal(delaunay.brio_order(P), _naive_brio(P))


def _check_valid(X, T, max_radius=1e3, flat=False):
    """Positive tetrahedra, no face shared by more than two, no point inside a circumsphere.
    ``flat``: exact ties (unjittered grid points) may leave tetrahedra of zero volume."""
    a, b, c, d = (X[T[:, i]] for i in range(4))
    vol = np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a)) / 6.0
    assert (vol >= 0).all() if flat else (vol > 0).all()
    faces = np.sort(np.concatenate([T[:, [1, 2, 3]], T[:, [0, 2, 3]], T[:, [0, 1, 3]],
                                    T[:, [0, 1, 2]]]), axis=1)
    assert np.unique(faces, axis=0, return_counts=True)[1].max() == 2
    if flat:
        return vol
    A = 2.0 * np.stack([b - a, c - a, d - a], axis=1)
    rhs = np.stack([(b * b).sum(1) - (a * a).sum(1), (c * c).sum(1) - (a * a).sum(1),
                    (d * d).sum(1) - (a * a).sum(1)], axis=1)
    centre = np.linalg.solve(A, rhs[..., None])[..., 0]
    radius = np.linalg.norm(centre - a, axis=1)
    ok = radius < max_radius  # slivers on the hull have huge spheres, badly conditioned
    inside = cKDTree(X).query_ball_point(centre[ok], radius[ok] * (1.0 - 1e-7),
                                         return_length=True)
    assert inside.max() == 0
    return vol


def test_quadratic_worst_case_grows_every_buffer():
    """Points near two skew lines: almost every pair across the lines is a Delaunay edge, so
    the tetrahedra (~n²/4) outgrow the initial 8 n slots and cavities reach hundreds of
    tetrahedra (the growth paths of every scratch buffer). Nearly every point is on the hull
    here, so edges whose empty spheres are huge are hidden by the super-tetrahedron (in the
    core, guard points keep them away from the edges that matter): the result must be a valid
    Delaunay complex whose edges are Qhull's."""
    rng = np.random.default_rng(4)
    m = 300  # largest cavity 545 tetrahedra with 594 boundary facets (first buffers: 256)
    t = np.sort(rng.random(m))
    X = np.concatenate([np.c_[t, np.zeros(m), np.zeros(m)],
                        np.c_[np.full(m, 0.5), rng.random(m) - 0.5, np.full(m, 0.3)]])
    X = X + 1e-6 * rng.uniform(-1, 1, X.shape)
    T = delaunay.delaunay_tets(X)
    assert T is not None and len(T) > 8 * len(X)
    _check_valid(X, T)
    got = {tuple(e) for e in voronoi._simplex_edges(T).tolist()}
    assert got <= naive.delaunay_edges(X)
    assert len([e for e in got if (e[0] < m) != (e[1] < m)]) > 0.85 * m * m


def test_restarting_a_point_for_room_builds_the_same_triangulation():
    """Full arrays stop :func:`delaunay._insert` before the point that needs room and it
    starts that point again after they grow: with 8 tetrahedron slots and cavity buffers of 2
    (dozens of stops) the tetrahedra come out exactly as with room enough from the start."""
    X = _cloud("sphere", np.random.default_rng(2))
    n = len(X)
    C = np.concatenate([X, 50.0 * np.array([[1.0, 1, 1], [1, -1, -1], [-1, 1, -1],
                                            [-1, -1, 1]])])
    order = delaunay.brio_order(X).astype(np.int64)
    roomy, ok0 = delaunay._build(C, order, n, 8 * n + 64, 256)
    tight, ok1 = delaunay._build(C, order, n, 8, 2)
    assert ok0 and ok1
    assert np.array_equal(roomy, tight)
