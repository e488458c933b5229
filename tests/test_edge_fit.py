"""Mode "coverage": thin boundary flags located by a two-plane fit, and no emptied faces."""

import numpy as np
import pytest

from tiledsimplify import SimplifyOptions, metrics, simplify_points, synthetic
from tiledsimplify.core import edge_fit
from tiledsimplify.core.simplify import neighbourhoods, scale_of
from tiledsimplify.io import read_mesh


def _roof(rng, n, angle_deg=90.0, noise=0.0):
    """Two planes meeting along x = 0 at the given dihedral opening; z up."""
    xy = rng.random((n, 2)) * 2 - 1
    slope = np.tan(np.deg2rad(90.0 - angle_deg / 2.0))
    X = np.c_[xy, -slope * np.abs(xy[:, 0])]
    return X + noise * rng.normal(size=X.shape)


def _localise_all(X):
    X = X - X.mean(0)
    st = neighbourhoods(X, scale_of(X))
    nn = np.empty(len(X))
    edge_fit.nearest_distances(X, st.start, st.cnt, st.pool, nn)
    out = np.empty(len(X))
    edge_fit.localise(X, st.normals, st.dn, st.dn_cnt, nn, np.ones(len(X), bool), out)
    return out, nn


def test_nearest_distances_equal_kdtree():
    from scipy.spatial import cKDTree
    X = _roof(np.random.default_rng(3), 800)
    X -= X.mean(0)
    st = neighbourhoods(X, scale_of(X))
    nn = np.empty(len(X))
    edge_fit.nearest_distances(X, st.start, st.cnt, st.pool, nn)
    np.testing.assert_allclose(nn, cKDTree(X).query(X, k=2)[0][:, 1], rtol=1e-12)


def test_fitted_edge_distance_is_the_true_distance_near_a_ridge():
    X = _roof(np.random.default_rng(0), 4000)
    est, nn = _localise_all(X)
    spacing = np.median(nn)
    # true distance to the ridge x = 0 within the face: |x| / cos(45°)
    true = np.abs(X[:, 0]) / np.cos(np.deg2rad(45.0)) / spacing
    near = (true < 1.5) & (np.abs(X[:, 1]) < 0.8)  # away from the open ends of the ridge
    found = near & np.isfinite(est)
    assert found.sum() > 0.9 * near.sum()
    # est is in local spacings; local ≈ global spacing on this even-density patch
    assert np.median(np.abs(est[found] - true[found])) < 0.15
    # no point far from the ridge (or from the open border of the patch) is put near an edge
    inner = (np.abs(X[:, 0]) < 0.85) & (np.abs(X[:, 1]) < 0.85)
    assert not (est[inner & (true > 3)] <= 1.5).any()


def test_no_edge_on_a_noisy_plane_or_a_shallow_fold():
    rng = np.random.default_rng(1)
    P = np.c_[rng.random((3000, 2)), np.zeros(3000)]
    P[:, 2] += 0.1 * 0.015 * rng.normal(size=3000)  # noise 0.1 x spacing
    est, _ = _localise_all(P)
    assert np.isfinite(est).mean() < 0.01
    shallow = _roof(rng, 3000, angle_deg=170.0)  # a 10° crease is not a sharp edge
    est, _ = _localise_all(shallow)
    assert not np.isfinite(est).any()


@pytest.mark.parametrize("noise", [0.0, 0.1])
def test_boundary_is_thin_on_fandisk(data_dir, noise):
    V, F = read_mesh(data_dir / "meshes" / "cad_classic" / "fandisk.obj")
    X, _ = synthetic.sample_surface_even(V, F, 12000, seed=0)
    s = synthetic.spacing(X)
    X = X + noise * s * np.random.default_rng(0).normal(size=X.shape)
    seg = V[synthetic.sharp_edges(V, F)]
    res = simplify_points(X, ratio=0.2, options=SimplifyOptions(progressive=False))
    bd = metrics.boundary_detection(X, res.boundary, edge_segments=seg, spacing=s)
    assert bd["f1"] >= 0.8, bd
    paper = simplify_points(X, ratio=0.2, options=SimplifyOptions(mode="paper",
                                                                  progressive=False))
    assert res.boundary.sum() < 0.6 * paper.boundary.sum()


def test_coverage_mode_leaves_no_holes_on_a_plate():
    rng = np.random.default_rng(2)
    X, _ = synthetic.sample_surface_even(
        np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]), np.array([[0, 1, 2], [0, 2, 3]]),
        6000, seed=0)
    X[:, 2] += 1e-4 * rng.normal(size=len(X))
    ratio = 0.1
    out = {}
    for mode in ("coverage", "paper"):
        res = simplify_points(X, ratio=ratio, options=SimplifyOptions(mode=mode,
                                                                      progressive=False))
        out[mode] = metrics.hausdorff_distance(X, res.keep) * metrics.bbox_diagonal(X)
    ideal = synthetic.spacing(X) / np.sqrt(ratio)  # spacing of an even 10 % subset
    assert out["coverage"] < 1.5 * ideal
    assert out["paper"] > 2.0 * out["coverage"]
