"""Tests for tiledsimplify.synthetic: sharp edges, surface/edge sampling, simulated scans."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tiledsimplify.errors import InputError
from tiledsimplify.io.mesh import read_mesh
from tiledsimplify.synthetic import (
    sample_edges,
    sample_surface,
    sample_surface_even,
    scan,
    sharp_edges,
    spacing,
)

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def data_mesh(rel: str):
    path = DATA / rel
    if not path.exists():
        pytest.skip(f"test data {path} not found")
    return read_mesh(path)


# unit cube [0, 1]^3, outward-oriented triangles (each quad split along a diagonal)
CUBE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
                  dtype=np.float64)
_QUADS = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
CUBE_F = np.array([[q[0], q[1], q[2]] for q in _QUADS] + [[q[0], q[2], q[3]] for q in _QUADS], dtype=np.int64)


def on_face(points, vertices, faces, face_index, tol):
    """Distance of each point to the plane of its face, and whether it projects inside."""
    a, b, c = (vertices[faces[face_index, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    d = np.einsum("ij,ij->i", points - a, n)
    q = points - d[:, None] * n
    # barycentric coordinates of the projection
    v0, v1, v2 = b - a, c - a, q - a
    d00, d01, d11 = (np.einsum("ij,ij->i", x, y) for x, y in ((v0, v0), (v0, v1), (v1, v1)))
    d20, d21 = np.einsum("ij,ij->i", v2, v0), np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01 * d01
    bv = (d11 * d20 - d01 * d21) / den
    bw = (d00 * d21 - d01 * d20) / den
    inside = (bv >= -tol) & (bw >= -tol) & (bv + bw <= 1 + tol)
    return np.abs(d), inside


def cube_surface_distance(p):
    """Distance of points to the surface of the unit cube (inside or outside)."""
    inside = np.all((p >= 0) & (p <= 1), axis=1)
    d_in = np.minimum(p, 1 - p).min(axis=1)
    d_out = np.linalg.norm(np.maximum(0, np.maximum(-p, p - 1)), axis=1)
    return np.where(inside, d_in, d_out)


# --------------------------------------------------------------------------------------
# sharp_edges
# --------------------------------------------------------------------------------------


def test_cube_has_12_sharp_edges():
    e = sharp_edges(CUBE_V, CUBE_F)
    assert e.shape == (12, 2) and e.dtype == np.int64
    assert np.all(e[:, 0] < e[:, 1])
    lengths = np.linalg.norm(CUBE_V[e[:, 0]] - CUBE_V[e[:, 1]], axis=1)
    np.testing.assert_allclose(lengths, 1.0)  # no face diagonal
    assert len(sharp_edges(CUBE_V, CUBE_F, angle_deg=89.0)) == 12
    assert len(sharp_edges(CUBE_V, CUBE_F, angle_deg=91.0)) == 0


def test_open_box_boundary_is_not_sharp():
    top = [1, 7]  # the two triangles of the top quad (z = 1)
    faces = np.delete(CUBE_F, top, axis=0)
    e = sharp_edges(CUBE_V, faces)
    assert len(e) == 8
    z = CUBE_V[e].reshape(-1, 3)[:, 2].reshape(-1, 2)
    assert not np.any(np.all(z == 1, axis=1))  # the 4 rim edges are boundary, not sharp


def test_flat_and_degenerate_and_nonmanifold():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1.0], [2, 0, 0]], dtype=float)
    flat = np.array([[0, 1, 2], [0, 2, 3]])
    assert len(sharp_edges(v, flat)) == 0
    # zero-area faces (repeated vertex, collinear) sharing edge (0, 2) are ignored
    degenerate = np.vstack([flat, [[0, 2, 2], [0, 1, 5]]])
    assert len(sharp_edges(v, degenerate)) == 0
    # a fin on the diagonal (0, 2): three faces on one edge, one pair at 90 degrees
    fin = np.vstack([flat, [[0, 2, 4]]])
    assert sharp_edges(v, fin).tolist() == [[0, 2]]


def test_real_sharp_edge_counts():
    # counts from SOURCES.md ("sharp>30"), computed there with trimesh
    v, f = data_mesh("meshes/cad_classic/fandisk.obj")
    assert len(sharp_edges(v, f)) == 722
    v, f = data_mesh("meshes/trimesh_cad/featuretype.STL")
    assert len(sharp_edges(v, f)) == 1723
    v, f = data_mesh("meshes/trimesh_cad/counter.unitsmm.STL.gz")
    assert len(sharp_edges(v, f)) == 31565


def test_nonmanifold_edges_count_as_sharp_on_real_mesh():
    # cycloidal.ply has 242 edges with 4 faces; SOURCES.md (trimesh) skips them and
    # reports 17,838; here they count when any face pair exceeds the angle
    v, f = data_mesh("meshes/trimesh_cad/cycloidal.ply.gz")
    e = sharp_edges(v, f)
    all_e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    uniq, cnt = np.unique(all_e, axis=0, return_counts=True)
    nonmanifold = uniq[cnt > 2]
    key = lambda a: a[:, 0] * len(v) + a[:, 1]  # noqa: E731
    n_nm = int(np.isin(key(e), key(nonmanifold)).sum())
    assert len(e) - n_nm == 17838
    assert n_nm == len(nonmanifold) == 242


# --------------------------------------------------------------------------------------
# sample_surface
# --------------------------------------------------------------------------------------


def test_sample_surface_on_faces_and_deterministic():
    v, f = data_mesh("meshes/cad_classic/fandisk.obj")
    p, fi = sample_surface(v, f, 20000, seed=3)
    assert p.shape == (20000, 3) and fi.shape == (20000,) and fi.dtype == np.int64
    dist, inside = on_face(p, v, f, fi, 1e-9)
    assert dist.max() < 1e-9 * np.ptp(v)
    assert inside.all()
    p2, fi2 = sample_surface(v, f, 20000, seed=3)
    np.testing.assert_array_equal(p, p2)
    np.testing.assert_array_equal(fi, fi2)
    p3, _ = sample_surface(v, f, 20000, seed=4)
    assert not np.array_equal(p, p3)


def test_sample_surface_is_area_weighted():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [10, 0, 0], [13, 0, 0], [10, 1, 0]], dtype=float)
    f = np.array([[0, 1, 2], [3, 4, 5]])  # areas 0.5 and 1.5
    _, fi = sample_surface(v, f, 40000)
    assert abs(np.mean(fi == 1) - 0.75) < 0.01
    p, _ = sample_surface(CUBE_V, CUBE_F, 60000)
    assert cube_surface_distance(p).max() < 1e-12
    # each of the 6 sides gets ~1/6 (binomial std ~0.0015)
    side = np.argmin(np.hstack([p, 1 - p]), axis=1)
    np.testing.assert_allclose(np.bincount(side, minlength=6) / len(p), 1 / 6, atol=0.008)


def test_sample_surface_rejects_bad_input():
    with pytest.raises(InputError):
        sample_surface(CUBE_V, CUBE_F + 10, 5)
    with pytest.raises(InputError):
        sample_surface(CUBE_V[:, :2], CUBE_F, 5)
    with pytest.raises(InputError):
        sample_surface(np.zeros((3, 3)), [[0, 1, 2]], 5)  # zero area


# --------------------------------------------------------------------------------------
# sample_surface_even
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [500, 16475])
def test_sample_surface_even_count_spacing_and_determinism(n):
    v, f = data_mesh("meshes/cad_classic/fandisk.obj")
    p, fi = sample_surface_even(v, f, n, seed=1)
    assert abs(len(p) - n) <= 0.03 * n
    dist, inside = on_face(p, v, f, fi, 1e-9)
    assert dist.max() < 1e-9 * np.ptp(v) and inside.all()
    # blue noise: no close pairs, unlike uniform random sampling
    d_even = cKDTree(p).query(p, k=2)[0][:, 1]
    pu, _ = sample_surface(v, f, len(p), seed=1)
    d_unif = cKDTree(pu).query(pu, k=2)[0][:, 1]
    assert d_even.min() > 0.6 * np.median(d_even)
    assert np.percentile(d_unif, 5) < 0.45 * np.median(d_unif)
    assert spacing(p) > 1.3 * spacing(pu)
    p2, fi2 = sample_surface_even(v, f, n, seed=1)
    np.testing.assert_array_equal(p, p2)
    np.testing.assert_array_equal(fi, fi2)


# --------------------------------------------------------------------------------------
# sample_edges
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("step,expected", [(0.1, 8 + 12 * 9), (0.3, 8 + 12 * 3), (0.25, 8 + 12 * 3), (2.0, 8)])
def test_sample_edges_cube_counts(step, expected):
    p = sample_edges(CUBE_V, CUBE_F, step)
    assert p.shape == (expected, 3)
    # every point lies on a cube edge: at least two coordinates are 0 or 1
    on01 = np.isclose(p, 0, atol=1e-12) | np.isclose(p, 1, atol=1e-12)
    assert np.all(on01.sum(axis=1) >= 2)
    assert len(np.unique(p, axis=0)) == len(p)
    if step < 1:
        d = cKDTree(p).query(p, k=2)[0][:, 1]
        assert d.max() <= step + 1e-12


def test_sample_edges_real_mesh_on_sharp_edges():
    v, f = data_mesh("meshes/trimesh_cad/featuretype.STL")
    step = 0.02 * np.ptp(v, axis=0).max()
    p = sample_edges(v, f, step)
    e = sharp_edges(v, f)
    # distance of every sample to the nearest sharp edge segment is ~0
    a, b = v[e[:, 0]], v[e[:, 1]]
    ab = b - a
    # check a subset against all segments (vectorised, 300 x 1723)
    sub = p[:: max(1, len(p) // 300)]
    t = np.clip(np.einsum("pkj,kj->pk", sub[:, None] - a[None], ab) / np.einsum("kj,kj->k", ab, ab), 0, 1)
    d = np.linalg.norm(a[None] + t[..., None] * ab[None] - sub[:, None], axis=2).min(axis=1)
    assert d.max() < 1e-9 * np.ptp(v)
    # every point of every sharp edge lies within half a step of a sample (along its polyline,
    # so in space too): points at a tenth of the step along every segment
    L = np.linalg.norm(ab, axis=1)
    k = np.maximum(np.ceil(L / (0.1 * step)), 1).astype(int)
    owner = np.repeat(np.arange(len(e)), k + 1)
    t = (np.arange(owner.size) - np.repeat(np.cumsum(k + 1) - (k + 1), k + 1)) / k[owner]
    dense = a[owner] + t[:, None] * ab[owner]
    assert cKDTree(p).query(dense)[0].max() <= 0.5 * step * (1 + 1e-9)
    # by arc length, not once per vertex (this part's rims are finely tessellated: 1,700 edge
    # vertices for ~1,226 steps of edge; 1,241 samples)
    assert len(p) < 1.1 * L.sum() / step + 20 < len(np.unique(e))


# --------------------------------------------------------------------------------------
# scan
# --------------------------------------------------------------------------------------


def test_scan_cube_points_on_surface_and_deterministic():
    p, fi = scan(CUBE_V, CUBE_F, n_points=6000, seed=5)
    assert abs(len(p) - 6000) < 0.1 * 6000
    assert cube_surface_distance(p).max() < 1e-9
    dist, inside = on_face(p, CUBE_V, CUBE_F, fi, 1e-9)
    assert dist.max() < 1e-9 and inside.all()
    # several views: points on all 6 sides
    side = np.argmin(np.hstack([p, 1 - p]), axis=1)
    assert len(np.unique(side)) == 6
    p2, fi2 = scan(CUBE_V, CUBE_F, n_points=6000, seed=5)
    np.testing.assert_array_equal(p, p2)
    np.testing.assert_array_equal(fi, fi2)
    p3, _ = scan(CUBE_V, CUBE_F, n_points=6000, seed=6)
    assert not np.array_equal(p, p3)


def test_scan_noise_along_rays():
    sigma = 0.002
    p, _ = scan(CUBE_V, CUBE_F, n_points=20000, noise=sigma, seed=0)
    d = cube_surface_distance(p)
    assert d.max() < 6 * sigma
    assert 0.2 * sigma < np.median(d) < 1.0 * sigma
    p0, _ = scan(CUBE_V, CUBE_F, n_points=20000, noise=0.0, seed=0)
    assert len(p0) == len(p)  # same rays, only moved along them


def test_scan_keeps_first_hit_only():
    # two parallel unit squares, z = 0 and z = 1, seen from above
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    v = np.vstack([sq, sq + [0, 0, 1]])
    f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    p, fi = scan(v, f, n_points=3000, direction=[0, 0, -1])
    assert len(p) > 2000
    np.testing.assert_allclose(p[:, 2], 1.0, atol=1e-12)
    assert set(np.unique(fi)) == {2, 3}
    # from below, only the bottom one; with two directions both
    p, _ = scan(v, f, n_points=3000, direction=[0, 0, 1])
    np.testing.assert_allclose(p[:, 2], 0.0, atol=1e-12)
    p, _ = scan(v, f, n_points=3000, direction=[[0, 0, 1], [0, 0, -1]])
    assert np.isclose(p[:, 2], 0).sum() > 1000 and np.isclose(p[:, 2], 1).sum() > 1000


def test_scan_line_spacing_ratio_is_anisotropic():
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    p1, _ = scan(sq, f, n_points=4000, direction=[0, 0, -1], line_spacing_ratio=1.0)
    p4, _ = scan(sq, f, n_points=4000, direction=[0, 0, -1], line_spacing_ratio=4.0)
    assert abs(len(p1) - 4000) < 400 and abs(len(p4) - 4000) < 400
    # same density, samples 2x closer along the lines and 2x farther apart across them
    assert 0.4 < spacing(p4) / spacing(p1) < 0.6
    # the nearest neighbour of a point is along its line: one direction dominates
    _, idx = cKDTree(p4).query(p4, k=2)
    step = np.abs(p4[idx[:, 1]] - p4)
    dominant = np.argmax(step[:, :2], axis=1)
    assert max(np.mean(dominant == 0), np.mean(dominant == 1)) > 0.9


def test_scan_real_mesh_speed_and_accuracy():
    v, f = data_mesh("meshes/stanford_bunny/bun_zipper_res2.ply.gz")  # 16,301 faces
    t0 = time.perf_counter()
    p, fi = scan(v, f, n_points=50000, seed=2)
    elapsed = time.perf_counter() - t0
    assert elapsed < 5.0
    assert abs(len(p) - 50000) < 0.1 * 50000
    dist, inside = on_face(p, v, f, fi, 1e-6)
    assert dist.max() < 1e-9 * np.ptp(v) and inside.all()


def test_scan_rejects_bad_input():
    with pytest.raises(InputError):
        scan(CUBE_V, CUBE_F, n_points=0)
    with pytest.raises(InputError):
        scan(CUBE_V, CUBE_F, n_points=10, distance=0.5)
    with pytest.raises(InputError):
        scan(CUBE_V, CUBE_F, n_points=10, direction=[0, 0, 0])


# --------------------------------------------------------------------------------------
# spacing
# --------------------------------------------------------------------------------------


def test_spacing_of_grid():
    g = np.stack(np.meshgrid(np.arange(10), np.arange(10), np.arange(3), indexing="ij"), -1).reshape(-1, 3)
    assert spacing(g * 0.1) == pytest.approx(0.1)
    with pytest.raises(InputError):
        spacing(np.zeros((1, 3)))


def test_scan_max_incidence_drops_grazing_hits():
    p_all, _ = scan(CUBE_V, CUBE_F, n_points=6000, seed=1)
    p, _ = scan(CUBE_V, CUBE_F, n_points=6000, seed=1, max_incidence_deg=50.0)
    assert 0 < len(p) < len(p_all)
    # the kept hits are a subset of the unfiltered ones (same rays)
    kept = {tuple(x) for x in np.round(p, 12)}
    assert kept <= {tuple(x) for x in np.round(p_all, 12)}
