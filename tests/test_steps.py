"""Paper steps 2-4 on one point set: local mesh, normals, boundary measure, importance."""

import numpy as np
import pytest

from tiledsimplify.core import adjacency, boundary, importance
from tiledsimplify.core.simplify import neighbourhoods
from tiledsimplify.core.voronoi import scale_of

import naive


def _wavy(rng, n, noise=0.0):
    xy = rng.random((n, 2)) * 4
    z = 0.3 * np.sin(xy[:, 0] * 1.5) * np.cos(xy[:, 1])
    X = np.c_[xy, z]
    return X + noise * rng.normal(size=X.shape)


def _roof(rng, n):
    """Two planes meeting at a 90-degree ridge along x = 0 (a sharp edge)."""
    xy = rng.random((n, 2)) * 2 - 1
    return np.c_[xy, -np.abs(xy[:, 0])]


@pytest.fixture(scope="module")
def wavy():
    X = _wavy(np.random.default_rng(0), 3000)
    X = X - X.mean(0)
    return X, neighbourhoods(X, scale_of(X))


def test_local_mesh_equals_2d_voronoi_of_projection(wavy):
    X, st = wavy
    vn = adjacency.to_sets(st.start, st.cnt, st.pool)
    checked = 0
    for p in range(0, len(X), 7):
        ref = naive.local_mesh(X, p, vn[p])
        if ref is None:
            continue
        got = set(st.dn[p, : st.dn_cnt[p]].tolist())
        assert got == ref, p
        assert got <= vn[p]
        checked += 1
    assert checked > 300
    # a one-ring on a smooth surface: about six neighbours
    assert 5.5 < st.dn_cnt.mean() < 6.5


def test_normals_are_pca_of_local_mesh(wavy):
    X, st = wavy
    for p in range(0, len(X), 11):
        dn = st.dn[p, : st.dn_cnt[p]]
        assert abs(abs(st.normals[p] @ naive.normal(X, p, dn, st.plane_normals[p])) - 1) < 1e-9
    # and close to the true normal of z = f(x, y)
    x, y = X[:, 0] - X[:, 0].min(), X[:, 1] - X[:, 1].min()
    fx = 0.45 * np.cos(x * 1.5) * np.cos(y)
    fy = -0.3 * np.sin(x * 1.5) * np.sin(y)
    true = np.c_[-fx, -fy, np.ones_like(fx)]
    true /= np.linalg.norm(true, axis=1)[:, None]
    cos = np.abs(np.sum(true * st.normals, axis=1))
    assert np.median(cos) > 0.999


def test_deviation_and_importance_match_naive(wavy):
    X, st = wavy
    dev = np.zeros(len(X))
    boundary.all_deviations(X, st.normals, st.dn, st.dn_cnt, dev)
    flags = np.zeros(len(X), bool)
    flags[::5] = True
    imp = np.zeros(len(X))
    importance.all_importance(0, X, st.normals, flags, st.dn, st.dn_cnt, 0.0, imp)
    for p in range(0, len(X), 13):
        dn = st.dn[p, : st.dn_cnt[p]].tolist()
        assert dev[p] == pytest.approx(naive.deviation(X, st.normals, p, dn), abs=1e-9)
        assert imp[p] == pytest.approx(naive.importance(X, st.normals, flags, p, dn), rel=1e-9)
    # the coverage measure (beyond the paper): Eq. (1) + w * mean squared neighbour distance
    flags[:] = False
    flags[st.dn[7, : st.dn_cnt[7]]] = True  # point 7: every neighbour a boundary point
    importance.all_importance(1, X, st.normals, flags, st.dn, st.dn_cnt, 2.5, imp)
    for p in [7, *range(0, len(X), 13)]:
        dn = st.dn[p, : st.dn_cnt[p]].tolist()
        ref = naive.coverage_importance(X, st.normals, flags, p, dn, 2.5)
        assert imp[p] == pytest.approx(ref, rel=1e-9)
    assert np.isfinite(imp[7]) and imp[7] > 0


def test_boundary_flags_the_ridge_and_only_near_it():
    rng = np.random.default_rng(1)
    X = _roof(rng, 4000)
    X -= X.mean(0)
    st = neighbourhoods(X, scale_of(X))
    dev = np.zeros(len(X))
    boundary.all_deviations(X, st.normals, st.dn, st.dn_cnt, dev)
    flags, t = boundary.detect(dev)
    spacing = np.sqrt(4.0 * np.sqrt(2) / len(X))
    dist = np.abs(X[:, 0] - X[:, 0][np.argmax(X[:, 2])])  # distance from the ridge, in x
    on_edge = dist < spacing
    assert flags[on_edge].mean() > 0.9        # the ridge is found
    assert not flags[dist > 4 * spacing].any()  # and nothing far from it
    # the deviation is curvature-compensated: a smooth curved surface has no outliers
    W = _wavy(rng, 3000)
    W -= W.mean(0)
    sw = neighbourhoods(W, scale_of(W))
    devw = np.zeros(len(W))
    boundary.all_deviations(W, sw.normals, sw.dn, sw.dn_cnt, devw)
    assert np.quantile(devw, 0.99) < 0.2 * np.median(dev[on_edge])


def test_automatic_threshold_is_robust_outlier_rule():
    v = np.r_[np.full(90, 0.1), np.full(10, 1.0)]
    v[:45] = 0.08
    med = np.median(v)
    mad = np.median(np.abs(v - med))
    assert boundary.automatic_threshold(v, k=3, floor=0) == pytest.approx(med + 3 * 1.4826 * mad)
    assert boundary.automatic_threshold(np.zeros(50), floor=0.05) == 0.05
    flags, t = boundary.detect(v, threshold=0.5)
    assert t == 0.5 and flags.sum() == 10
