"""Tests of tiledsimplify.metrics: hand-computed values, a naive reference, input checks."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree
import pytest

from tiledsimplify import metrics as M
from tiledsimplify.errors import InputError

# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def grid_plane(nx: int, ny: int, step: float = 1.0, z: float = 0.0) -> np.ndarray:
    xs, ys = np.meshgrid(np.arange(nx) * step, np.arange(ny) * step, indexing="ij")
    return np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, z)])


def naive_surface_distances(original: np.ndarray, kept: np.ndarray, k: int) -> np.ndarray:
    """Loop reference: per point, brute-force kNN among kept + SVD plane fit."""
    k = min(k, len(kept))
    out = np.empty(len(original))
    for i, p in enumerate(original):
        d = np.linalg.norm(kept - p, axis=1)
        nb = kept[np.argsort(d, kind="stable")[:k]]
        c = nb.mean(axis=0)
        _, _, vt = np.linalg.svd(nb - c)
        out[i] = abs(np.dot(p - c, vt[-1]))
    return out


def naive_segment_distance(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    out = np.empty(len(points))
    for i, p in enumerate(points):
        best = np.inf
        for a, b in segments:
            ab = b - a
            den = ab @ ab
            t = 0.0 if den == 0 else min(max((p - a) @ ab / den, 0.0), 1.0)
            best = min(best, np.linalg.norm(p - (a + t * ab)))
        out[i] = best
    return out


# ---------------------------------------------------------------------------
# spacing / diagonal
# ---------------------------------------------------------------------------


def test_spacing_of_grid_is_step():
    assert M.spacing(grid_plane(5, 4, step=0.5)) == pytest.approx(0.5)


def test_spacing_median_not_mean():
    pts = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [5, 0, 0]], float)
    # NN distances 1, 1, 1, 3 -> median 1
    assert M.spacing(pts) == pytest.approx(1.0)


def test_bbox_diagonal():
    pts = np.array([[0, 0, 0], [3, 4, 12]], float)
    assert M.bbox_diagonal(pts) == pytest.approx(13.0)


# ---------------------------------------------------------------------------
# surface error
# ---------------------------------------------------------------------------


def test_surface_error_zero_on_plane():
    rng = np.random.default_rng(1)
    pts = np.column_stack([rng.random((300, 2)) * 10, np.zeros(300)])
    mask = np.zeros(300, bool)
    mask[rng.choice(300, 40, replace=False)] = True
    mean, mx = M.surface_error(pts, mask)
    assert mean < 1e-14 and mx < 1e-14


def test_surface_error_zero_on_tilted_plane():
    rng = np.random.default_rng(2)
    uv = rng.random((200, 2)) * 5
    e1 = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    e2 = np.cross(e1, [0.3, 0.1, 0.9])
    e2 /= np.linalg.norm(e2)
    pts = 100.0 + uv[:, :1] * e1 + uv[:, 1:] * e2
    mean, mx = M.surface_error(pts, pts[::7])
    assert mx < 1e-10


def test_surface_error_lifted_point_exact():
    # 8 kept points: 3x3 grid in z=0 without its centre; the original adds
    # the centre lifted by h.  k=8 -> every plane is z=0.
    kept = np.array([p for p in grid_plane(3, 3) if not (p[0] == 1 and p[1] == 1)])
    h = 0.5
    original = np.vstack([kept, [[1.0, 1.0, h]]])
    diag = math.sqrt(2**2 + 2**2 + h**2)
    mean, mx = M.surface_error(original, kept, k=8)
    assert mx == pytest.approx(h / diag, rel=1e-12)
    assert mean == pytest.approx(h / diag / 9, rel=1e-12)
    d = M.surface_distances(original, kept, k=8)
    np.testing.assert_allclose(d, [0] * 8 + [h], atol=1e-14)


def test_surface_error_uses_all_kept_if_fewer_than_k():
    kept = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    original = np.vstack([kept, [[5.0, 5.0, 2.0]]])  # far away, but plane is z=0
    d = M.surface_distances(original, kept, k=8)
    np.testing.assert_allclose(d, [0, 0, 0, 2.0], atol=1e-14)


def test_surface_error_collinear_and_coincident_neighbours():
    # collinear kept points: plane undetermined -> distance to their line
    kept = np.column_stack([np.arange(5.0), np.zeros(5), np.zeros(5)])
    original = np.vstack([kept, [[2.0, 3.0, 4.0]]])
    d = M.surface_distances(original, kept, k=8)
    np.testing.assert_allclose(d, [0, 0, 0, 0, 0, 5.0], atol=1e-12)
    # coincident kept points -> distance to that point
    kept = np.zeros((3, 3))
    original = np.array([[0.0, 0, 0], [3.0, 4.0, 0]])
    np.testing.assert_allclose(M.surface_distances(original, kept), [0.0, 5.0], atol=1e-12)
    assert M.surface_error(original, kept) == pytest.approx((0.5, 1.0))


def test_surface_error_uses_nearest_plane():
    # two planes: z=0 (x<5) and z=1 (x>=20); point near the first plane at z=0.25
    a = grid_plane(4, 4)
    b = grid_plane(4, 4) + [20.0, 0.0, 1.0]
    kept = np.vstack([a, b])
    original = np.vstack([kept, [[1.5, 1.5, 0.25]]])
    d8 = M.surface_distances(original, kept, k=8)
    assert d8[-1] == pytest.approx(0.25, abs=1e-12)


@pytest.mark.parametrize("k", [3, 8, 15])
def test_surface_error_matches_naive_loop(k):
    rng = np.random.default_rng(10 + k)
    original = rng.normal(size=(400, 3)) * [3.0, 2.0, 0.5]
    mask = rng.random(400) < 0.3
    kept = original[mask]
    ref = naive_surface_distances(original, kept, k)
    got = M.surface_distances(original, mask, k=k)
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)
    diag = np.linalg.norm(original.max(0) - original.min(0))
    mean, mx = M.surface_error(original, mask, k=k)
    assert mean == pytest.approx(ref.mean() / diag, rel=1e-9)
    assert mx == pytest.approx(ref.max() / diag, rel=1e-9)


def test_surface_error_chunking_invariant():
    rng = np.random.default_rng(3)
    original = rng.random((500, 3))
    kept = original[::5]
    a = M.surface_distances(original, kept, chunk_size=7)
    b = M.surface_distances(original, kept)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-15)


# ---------------------------------------------------------------------------
# Chamfer / Hausdorff
# ---------------------------------------------------------------------------


def test_hausdorff_and_chamfer_subset():
    original = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0], [3, 4, 0]], float)
    kept = np.array([True, False, False, False, False])
    # distances to kept (0,0,0): 0,1,2,3,5; diag = |(3,4,0)| = 5
    assert M.hausdorff_distance(original, kept) == pytest.approx(5 / 5)
    assert M.chamfer_distance(original, kept) == pytest.approx((11 / 5 + 0.0) / 5)


def test_chamfer_non_subset_hand_computed():
    original = np.array([[0, 0, 0], [4, 0, 0], [0, 3, 0]], float)
    kept = np.array([[0, 0, 1.0]])
    # orig -> kept: 1, sqrt(17), sqrt(10); kept -> orig: 1; diag = 5
    expected = ((1 + math.sqrt(17) + math.sqrt(10)) / 3 + 1.0) / 5
    assert M.chamfer_distance(original, kept) == pytest.approx(expected, rel=1e-12)
    assert M.hausdorff_distance(original, kept) == pytest.approx(math.sqrt(17) / 5, rel=1e-12)


def test_chamfer_both_terms():
    original = np.array([[0, 0, 0], [2, 0, 0]], float)
    kept = np.array([[0, 0, 0], [0, 0, 0.5], [3, 0, 0]])
    # orig->kept: 0, 1 -> mean 0.5; kept->orig: 0, 0.5, 1 -> mean 0.5; diag = 2
    assert M.chamfer_distance(original, kept) == pytest.approx((0.5 + 0.5) / 2)
    assert M.hausdorff_distance(original, kept) == pytest.approx(1 / 2)


def test_identity_gives_zero():
    rng = np.random.default_rng(4)
    pts = rng.random((100, 3))
    assert M.chamfer_distance(pts, pts) == 0.0
    assert M.hausdorff_distance(pts, np.ones(100, bool)) == 0.0


# ---------------------------------------------------------------------------
# edge coverage
# ---------------------------------------------------------------------------


def test_edge_coverage_just_inside_outside():
    s = 0.1
    original = np.array([[0, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    kept = np.array([True, False, False])
    samples = np.array([[0.0, 0, 0], [0.149, 0, 0], [0.151, 0, 0], [0.3, 0, 0]])
    assert M.edge_coverage(original, kept, samples, s) == pytest.approx(2 / 4)
    assert M.edge_coverage(original, kept, samples, s, factor=1.55) == pytest.approx(3 / 4)
    assert M.edge_coverage(original, kept, samples, s, factor=3.5) == pytest.approx(1.0)
    assert M.edge_coverage(original, kept, samples, s, factor=1.0) == pytest.approx(1 / 4)


def test_edge_coverage_default_spacing():
    original = grid_plane(6, 6, step=0.2)  # spacing 0.2 -> radius 0.3
    kept = original[:1]  # (0,0,0)
    samples = np.array([[0.29, 0, 0], [0.31, 0, 0]])
    assert M.edge_coverage(original, kept, samples) == pytest.approx(0.5)


def test_sample_segments():
    seg = np.array([[[0, 0, 0], [1, 0, 0]], [[1, 0, 0], [1, 0.25, 0]]], float)
    pts = M.sample_segments(seg, 0.3)
    # first: ceil(1/0.3)=4 pieces -> 5 points; second: 1 piece -> 2 points; shared vertex once
    assert pts.shape == (6, 3)
    np.testing.assert_allclose(np.sort(pts[:, 0])[:5], [0, 0.25, 0.5, 0.75, 1.0])


def test_sample_segments_follows_polylines_by_arc_length():
    # a circle of radius 1 in 1,000 segments, and a chord-tessellated arc meeting a straight
    # edge at a corner: the circle gets ceil(2 pi / 0.1) = 63 samples, not 1,000 (one per
    # vertex); the corner ends both lines and is sampled
    th = np.linspace(0, 2 * np.pi, 1001)[:-1]
    ring = np.c_[np.cos(th), np.sin(th), np.zeros_like(th)]
    circle = np.stack([ring, np.roll(ring, -1, axis=0)], axis=1)
    pts = M.sample_segments(circle, 0.1)
    assert pts.shape == (63, 3)
    np.testing.assert_allclose(np.linalg.norm(pts[:, :2], axis=1), 1.0, atol=2e-5)
    gaps = cKDTree(pts).query(pts, k=2)[0][:, 1]
    assert gaps.max() <= 0.1 and gaps.min() > 0.099
    arc = ring[:251] + [3, 0, 0]  # a quarter circle about (3, 0, 0), from (4, 0) to (3, 1)
    lines = np.r_[np.stack([arc[:-1], arc[1:]], axis=1),
                  [[arc[-1], arc[-1] + [0, 0.5, 0]]]]  # then straight, turning by 90 degrees
    pts = M.sample_segments(lines, 0.1)
    assert len(pts) == 1 + 16 + 5  # ceil((pi / 2) / 0.1) = 16 pieces, ceil(0.5 / 0.1) = 5
    assert np.min(np.linalg.norm(pts - arc[-1], axis=1)) < 1e-12  # the corner itself


def test_sample_segments_of_zero_length():
    point = np.array([[[1.0, 2, 3], [1.0, 2, 3]]])  # no line at all
    assert M.sample_segments(point, 0.1).shape == (0, 3)


# ---------------------------------------------------------------------------
# segment distances / boundary detection
# ---------------------------------------------------------------------------


def test_distance_to_segments_hand_values():
    seg = np.array([[[0, 0, 0], [1, 0, 0]]], float)
    pts = np.array([[0.5, 0.3, 0], [1.05, 0, 0], [-0.3, 0.4, 0], [0.2, 0, 0]])
    d = M.distance_to_segments(pts, seg)
    np.testing.assert_allclose(d, [0.3, 0.05, 0.5, 0.0], atol=1e-15)
    d = M.distance_to_segments(pts, seg, max_distance=0.31)
    np.testing.assert_allclose(d, [0.3, 0.05, np.inf, 0.0], atol=1e-15)


def test_distance_to_segments_matches_brute_force():
    rng = np.random.default_rng(5)
    seg = rng.random((60, 2, 3))
    seg[0] = [[0, 0, 0], [10, 10, 10]]  # one very long segment
    seg[1, 1] = seg[1, 0]  # one degenerate segment
    seg[2] *= 0.01  # one very short segment
    pts = rng.random((300, 3)) * 1.2 - 0.1
    ref = naive_segment_distance(pts, seg)
    np.testing.assert_allclose(M.distance_to_segments(pts, seg), ref, atol=1e-13)
    r = 0.04
    d = M.distance_to_segments(pts, seg, max_distance=r, chunk_size=50)
    inside = ref <= r
    assert inside.any() and (~inside).any()
    np.testing.assert_allclose(d[inside], ref[inside], atol=1e-13)
    assert np.isinf(d[~inside]).all()


def _boundary_case():
    ys = np.array([0.0, 0.05, 0.09, 0.11, 0.2, 0.5])
    pts = np.column_stack([np.full(6, 0.3), ys, np.zeros(6)])
    flagged = np.array([True, False, True, True, True, False])
    seg = np.array([[[-1, 0, 0], [1, 0, 0]]], float)
    return pts, flagged, seg


def test_boundary_detection_segments():
    pts, flagged, seg = _boundary_case()
    # positives: y <= 0.1 -> rows 0,1,2 ; flagged rows 0,2,3,4 -> TP = 2
    r = M.boundary_detection(pts, flagged, edge_segments=seg, spacing=0.1)
    assert r["n_positive"] == 3 and r["n_flagged"] == 4 and r["n_true_positive"] == 2
    assert r["precision"] == pytest.approx(0.5)
    assert r["recall"] == pytest.approx(2 / 3)
    assert r["f1"] == pytest.approx(4 / 7)


def test_boundary_detection_samples_and_factor():
    pts, flagged, seg = _boundary_case()
    samples = np.column_stack([np.linspace(-1, 1, 201), np.zeros(201), np.zeros(201)])
    r = M.boundary_detection(pts, flagged, edge_samples=samples, spacing=0.1)
    assert (r["precision"], r["recall"]) == pytest.approx((0.5, 2 / 3))
    # factor 2.5 -> radius 0.25: positives rows 0..4, TP = 3 (0,2,3,4 flagged -> 4)
    r = M.boundary_detection(pts, flagged, edge_segments=seg, spacing=0.1, factor=2.5)
    assert r["precision"] == pytest.approx(1.0)
    assert r["recall"] == pytest.approx(4 / 5)


def test_boundary_detection_segments_exact_beyond_samples():
    # a point just off the segment's end: sampled edges at coarse spacing miss
    # the exact answer, segments do not
    seg = np.array([[[0, 0, 0], [1, 0, 0]]], float)
    pts = np.array([[1.09, 0, 0], [0.5, 0.0999, 0], [0.5, 0, 0.1001], [3, 3, 3]])
    truth = M.edge_ground_truth(pts, edge_segments=seg, spacing=0.1)
    np.testing.assert_array_equal(truth, [True, True, False, False])


def test_boundary_detection_zero_division():
    pts, _, seg = _boundary_case()
    r = M.boundary_detection(pts, np.zeros(6, bool), edge_segments=seg, spacing=0.1)
    assert r == {
        "precision": 0.0, "recall": 0.0, "f1": 0.0,
        "n_flagged": 0.0, "n_positive": 3.0, "n_true_positive": 0.0,
    }


# ---------------------------------------------------------------------------
# adaptivity / curvature regions
# ---------------------------------------------------------------------------


def test_adaptivity_hand_computed():
    original = np.arange(30, dtype=float).reshape(10, 3)
    region = np.array([True] * 4 + [False] * 6)
    kept = np.zeros(10, bool)
    kept[[0, 1, 3]] = True  # 3 of 4 in feature region
    kept[[5, 8]] = True  # 2 of 6 in flat region
    expected = (3 / 4) / (2 / 6)
    assert M.adaptivity(original, kept, region) == pytest.approx(expected)
    assert M.adaptivity(original, original[kept], region) == pytest.approx(expected)
    # no flat point kept -> inf
    assert M.adaptivity(original, original[[0, 1]], region) == math.inf


def test_adaptivity_points_must_be_subset():
    original = np.arange(30, dtype=float).reshape(10, 3)
    region = np.array([True] * 4 + [False] * 6)
    with pytest.raises(InputError, match="subset"):
        M.adaptivity(original, original[:3] + 0.01, region)
    assert M.adaptivity(original, original[[0, 5]] + 0.01, region, match_tol=0.1) == pytest.approx(
        (1 / 4) / (1 / 6)
    )


def test_adaptivity_needs_two_regions():
    original = np.arange(30, dtype=float).reshape(10, 3)
    with pytest.raises(InputError):
        M.adaptivity(original, original[:3], np.ones(10, bool))


def test_curvature_regions_sphere_vs_plane():
    plane = grid_plane(25, 25, step=0.1)  # 625 flat points, far from the sphere
    rng = np.random.default_rng(6)
    v = rng.normal(size=(500, 3))
    sphere = v / np.linalg.norm(v, axis=1, keepdims=True) + [10.0, 10.0, 10.0]
    pts = np.vstack([plane, sphere])
    curved = M.curvature_regions(pts, k=16, quantile=0.5)
    # median falls on the (round-off) plane values; the floor keeps plane points out
    assert not curved[:625].any()
    assert curved[625:].all()
    # with the floor disabled and a high quantile only part of the sphere is marked
    curved = M.curvature_regions(pts, k=16, quantile=0.9, min_variation=0.0)
    assert not curved[:625].any()
    assert 0 < curved[625:].sum() <= 0.1 * len(pts) + 1


# ---------------------------------------------------------------------------
# evaluate
# ---------------------------------------------------------------------------


def _scene():
    rng = np.random.default_rng(7)
    plane = grid_plane(20, 20, step=0.05)
    ridge = np.column_stack(
        [rng.random(200) * 0.95, np.full(200, 0.5), rng.random(200) * 0.1]
    )
    original = np.vstack([plane, ridge])
    mask = rng.random(len(original)) < 0.3
    seg = np.array([[[0, 0.5, 0], [0.95, 0.5, 0]]], float)
    samples = M.sample_segments(seg, 0.05)
    flagged = np.abs(original[:, 1] - 0.5) < 0.06
    return original, mask, seg, samples, flagged


def test_evaluate_keys_and_values():
    original, mask, seg, samples, flagged = _scene()
    r = M.evaluate(original, mask, edge_samples=samples, edge_segments=seg, flagged=flagged)
    assert set(r) == {
        "n_original", "n_kept", "surface_error_mean", "surface_error_max", "chamfer",
        "hausdorff", "hausdorff_model_units", "diagonal", "edge_coverage",
        "boundary_precision", "boundary_recall", "boundary_f1", "adaptivity",
    }
    assert all(isinstance(v, float) for v in r.values())
    assert r["n_original"] == len(original) and r["n_kept"] == mask.sum()
    assert (r["surface_error_mean"], r["surface_error_max"]) == pytest.approx(
        M.surface_error(original, mask)
    )
    assert r["chamfer"] == pytest.approx(M.chamfer_distance(original, mask))
    assert r["hausdorff"] == pytest.approx(M.hausdorff_distance(original, mask))
    s = M.spacing(original)
    assert r["edge_coverage"] == pytest.approx(M.edge_coverage(original, mask, samples, s))
    b = M.boundary_detection(original, flagged, edge_segments=seg, spacing=s)
    assert r["boundary_precision"] == pytest.approx(b["precision"])
    assert r["boundary_recall"] == pytest.approx(b["recall"])
    assert r["boundary_f1"] == pytest.approx(b["f1"])
    region = M.curvature_regions(original)
    assert r["adaptivity"] == pytest.approx(M.adaptivity(original, mask, region))


def test_evaluate_mask_equals_points():
    original, mask, seg, samples, flagged = _scene()
    kw = dict(edge_samples=samples, edge_segments=seg, flagged=flagged)
    a = M.evaluate(original, mask, **kw)
    b = M.evaluate(original, original[mask], **kw)
    assert a.keys() == b.keys()
    for key in a:
        assert a[key] == pytest.approx(b[key], rel=1e-12, abs=1e-15), key


def test_metrics_mask_equals_points_individually():
    rng = np.random.default_rng(8)
    original = rng.random((300, 3))
    mask = rng.random(300) < 0.2
    pts = original[mask]
    assert M.surface_error(original, mask) == M.surface_error(original, pts)
    assert M.chamfer_distance(original, mask) == M.chamfer_distance(original, pts)
    assert M.hausdorff_distance(original, mask) == M.hausdorff_distance(original, pts)
    samples = rng.random((50, 3))
    assert M.edge_coverage(original, mask, samples, 0.05) == M.edge_coverage(
        original, pts, samples, 0.05
    )


def test_evaluate_omits_what_cannot_be_computed():
    plane = grid_plane(5, 5)
    r = M.evaluate(plane, plane[:2])  # 2 kept: no plane fit; flat: no adaptivity; no edges
    assert set(r) == {"n_original", "n_kept", "chamfer", "hausdorff", "hausdorff_model_units",
                      "diagonal"}
    far = max(min(np.linalg.norm(p - q) for q in plane[:2]) for p in plane)  # brute force
    assert r["hausdorff_model_units"] == pytest.approx(far, rel=1e-12)
    assert r["hausdorff"] * r["diagonal"] == pytest.approx(far, rel=1e-12)
    r = M.evaluate(plane, plane[::3], edge_samples=plane[:3])  # no flagged -> no P/R
    assert "edge_coverage" in r and "boundary_f1" not in r
    assert r["surface_error_max"] < 1e-14


def test_evaluate_explicit_feature_region():
    original = grid_plane(4, 5)
    region = np.zeros(20, bool)
    region[:5] = True
    mask = np.zeros(20, bool)
    mask[[0, 1, 10]] = True
    r = M.evaluate(original, mask, feature_region=region)
    assert r["adaptivity"] == pytest.approx((2 / 5) / (1 / 15))


# ---------------------------------------------------------------------------
# bad inputs
# ---------------------------------------------------------------------------

GOOD = grid_plane(4, 4)


@pytest.mark.parametrize(
    "call",
    [
        lambda: M.surface_error(GOOD[:, :2], GOOD[:4]),  # (n,2)
        lambda: M.surface_error(GOOD.ravel(), GOOD[:4]),  # 1-D
        lambda: M.chamfer_distance(np.vstack([GOOD, [[np.nan, 0, 0]]]), GOOD[:3]),  # NaN
        lambda: M.chamfer_distance(GOOD, np.array([[np.inf, 0, 0]])),  # inf in kept
        lambda: M.chamfer_distance(GOOD, np.zeros(16, bool)),  # empty mask
        lambda: M.chamfer_distance(GOOD, np.zeros((0, 3))),  # empty points
        lambda: M.chamfer_distance(GOOD, np.ones(15, bool)),  # mask wrong length
        lambda: M.chamfer_distance(GOOD, np.arange(4)),  # index array
        lambda: M.chamfer_distance(GOOD, GOOD[:, :2]),  # kept wrong width
        lambda: M.chamfer_distance(np.zeros((0, 3)), GOOD[:2]),  # empty original
        lambda: M.chamfer_distance(np.ones((5, 3)), np.ones((1, 3))),  # zero bbox
        lambda: M.surface_error(GOOD, GOOD[:2]),  # fewer than 3 kept
        lambda: M.surface_error(GOOD, GOOD, k=2),
        lambda: M.edge_coverage(GOOD, GOOD[:3], GOOD[:2], spacing=-1.0),
        lambda: M.edge_coverage(GOOD, GOOD[:3], GOOD[:2], spacing=0.1, factor=0.0),
        lambda: M.edge_coverage(GOOD, GOOD[:3], np.zeros((2, 2)), spacing=0.1),
        lambda: M.boundary_detection(GOOD, np.ones(3, bool), edge_samples=GOOD[:2]),
        lambda: M.boundary_detection(GOOD, np.ones(16, int), edge_samples=GOOD[:2]),
        lambda: M.boundary_detection(GOOD, np.ones(16, bool)),  # no edges at all
        lambda: M.boundary_detection(GOOD, np.ones(16, bool), edge_segments=np.zeros((3, 3))),
        lambda: M.distance_to_segments(GOOD, np.zeros((0, 2, 3))),
        lambda: M.curvature_regions(GOOD, quantile=1.5),
        lambda: M.evaluate(GOOD, GOOD[:3], flagged=np.ones(2, bool)),
        lambda: M.spacing(GOOD[:1]),
        lambda: M.spacing("abc"),
    ],
)
def test_bad_inputs_raise_input_error(call):
    with pytest.raises(InputError):
        call()


def test_input_error_is_value_error_with_helpful_message():
    with pytest.raises(ValueError) as info:
        M.chamfer_distance(GOOD[:, :2], GOOD[:3])
    msg = str(info.value)
    assert "(n, 3)" in msg and "(16, 2)" in msg and "Fix" in msg
