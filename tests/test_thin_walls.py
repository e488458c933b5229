"""Thin walls, steps, rims and borders (:mod:`tiledsimplify.core.thin_walls`)."""

import numpy as np
import pytest

from tiledsimplify import SimplifyOptions, metrics, simplify_points, synthetic
from tiledsimplify.core import edge_fit, thin_walls, two_ring
from tiledsimplify.core.simplify import boundary_flags, neighbourhoods, scale_of
from tiledsimplify.io import read_mesh

from edge_scenes import localise_candidates


def _own_layer(X, p=0):
    """``thin_walls.own_layer`` on all of ``X`` with ``X[p]`` first: the indices it keeps."""
    c = len(X)
    idx = np.empty(two_ring.MAX_RING + 1, np.int64)
    idx[:c] = np.r_[p, np.delete(np.arange(c), p)]
    nn = np.sort(np.linalg.norm(X[:, None] - X[None], axis=2), axis=1)[:, 1]
    m = thin_walls.own_layer(X, idx, c, float(np.median(nn)), np.empty(c), np.empty(3),
                           np.empty(3))
    assert idx[0] == p
    return idx[:m]


@pytest.mark.parametrize("gap", [0.8, 1.5, 2.5])
def test_own_layer_keeps_the_points_sheet_of_a_thin_wall(gap):
    """Two parallel sheets ``gap`` grid pitches apart (a thin wall's faces, jittered): each
    point keeps its own sheet, whichever it is on; one sheet, a curved cap or the two faces
    of a 90-degree edge are one layer, kept whole."""
    rng = np.random.default_rng(0)
    g = np.stack(np.meshgrid(np.arange(-3.0, 3.5), np.arange(-3.0, 3.5)), -1).reshape(-1, 2)
    top = np.c_[g + 0.1 * rng.random(g.shape), 0.05 * rng.random(len(g))]
    bottom = np.c_[g + 0.5 + 0.1 * rng.random(g.shape), -gap + 0.05 * rng.random(len(g))]
    X = np.vstack([top, bottom])
    for p, sheet in ((0, np.arange(len(g))), (len(g) + 3, len(g) + np.arange(len(g)))):
        assert sorted(_own_layer(X, p)) == list(sheet)
    assert len(_own_layer(top)) == len(top)
    cap = np.c_[g, 0.1 * (g ** 2).sum(1)]  # heights 0-1.8 pitches: no gap between them
    assert len(_own_layer(cap, 24)) == len(cap)
    roof = np.c_[g, np.abs(g[:, 0])]  # a 90-degree fold along x = 0
    assert len(_own_layer(roof, 24)) == len(roof)
    far = np.vstack([top, bottom - [0, 0, 4.0]])  # farther than LAYER_GAP_MAX: two surfaces
    assert len(_own_layer(far)) == len(far)


def _thin_plate():
    """A unit plate 1.2 pitches of an even sampling thick, sampled evenly on both faces and its
    rim (6,000 points): ``(X, d)``, ``d`` each point's distance to the nearest edge in
    spacings."""
    n, thick = 6000, 1.2 * np.sqrt(2.0 / 6000)
    V = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, thick)], float)
    F = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                  [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]])
    X, _ = synthetic.sample_surface_even(V, F, n, seed=1, tol=0.001)
    return X, metrics.distance_to_segments(X, V[synthetic.sharp_edges(V, F)]) / synthetic.spacing(X)


def test_the_rim_of_a_thin_plate_is_flagged():
    """A plate 1.2 spacings thick, sampled evenly on both faces and its rim: the local mesh
    joins the faces, whose two-plane fits found parallel planes (no edge) or wedges across
    the wall (false edges inside). Before each point's own sheet was fitted alone, F1 0.17
    and 80 flags more than 3 spacings from the rim; then 0.68 and 1; with the rim fits
    (``thin_walls.fit_rim``) 0.87 and 2 (24 without ``_rim_clear``: two interior points whose
    local mesh lies to one side)."""
    X, d = _thin_plate()
    flags = np.asarray(simplify_points(X, ratio=0.2).boundary, bool)
    truth = d <= 1
    precision = (flags & truth).sum() / flags.sum()
    recall = (flags & truth).sum() / truth.sum()
    assert 2 * precision * recall / (precision + recall) > 0.8
    assert (flags & (d > 3)).sum() <= 5


def test_a_rims_line_makes_features_but_not_the_core_band():
    """On the thin plate the rims' lines add features (within a spacing of an edge: 241 of its
    516 points before the rim fits, 421 with them), but the core band, sure of being kept,
    stays as it was (135 / 136; 283 with the rims' lines in it): in the band, rims took the
    tray scans' budget from their faces."""
    X, d = _thin_plate()
    X = X - X.mean(0)
    _, band, features, _, _, _ = boundary_flags(X, neighbourhoods(X, scale_of(X)),
                                                SimplifyOptions())
    truth = d <= 1
    assert (features & truth).sum() > 0.75 * truth.sum()
    assert band.sum() < 0.35 * truth.sum()


@pytest.mark.parametrize("noise", [None, 0.1, 0.2])
def test_a_thin_plates_rim_is_fitted_where_both_sheets_end(data_dir, noise):
    """The tray (a plate 3.18 mm thick) sampled evenly at a 2.63 mm spacing, and scanned in
    lines: every candidate fitted. Evenly, its 316 rim fits (312 until a face needed two points
    off its line, ``MIN_OFF``) all lie within a spacing of an
    edge. On the scans a point's local mesh may join the lines on one side of its own only,
    and so end like a rim: without ``_rim_clear`` 88 of 198 and 143 of 226 rim fits lay more
    than 3 spacings from any edge, with it 19 of 121 and 27 of 93."""
    V, F = read_mesh(data_dir / "meshes" / "trimesh_cad" / "1002_tray_bottom.STL.gz")
    if noise is None:
        X, _ = synthetic.sample_surface_even(V, F, 20_000, seed=0, tol=0.001)
        s = synthetic.spacing(X)
    else:
        s = synthetic.spacing(synthetic.scan(V, F, n_points=20_000, seed=0)[0])
        X, _ = synthetic.scan(V, F, n_points=20_000, noise=noise * s, seed=0)
    d = metrics.distance_to_segments(X, V[synthetic.sharp_edges(V, F)]) / s
    Xc = X - X.mean(0)
    rim = np.empty(len(X), bool)
    _, out, angle, *_ = localise_candidates(Xc, neighbourhoods(Xc, scale_of(Xc)), np.ones(len(X), bool),
                                  rim=rim)
    assert (out[rim] <= thin_walls.RIM_REACH).all() and (angle[rim] == 90.0).all()
    if noise is None:
        assert rim.sum() > 250 and (d[rim] <= 1).all()
    else:
        assert rim.sum() > 60 and (d[rim] > 3).sum() < 0.3 * rim.sum()
    # the border test (an empty angle about the point) runs where the sampling fills its
    # tangent planes: evenly, 116 borders more (432 in all), every one within a spacing of an
    # edge; the scans' lines leave empty angles everywhere, and it does not run there
    st = neighbourhoods(Xc, scale_of(Xc))
    gap = thin_walls.median_ring_gap(Xc, st.normals, st.dn, st.dn_cnt, synthetic.spacing(Xc),
                                   512)
    assert (gap < thin_walls.FILLED_GAP) == (noise is None)
    if noise is None:
        border = np.empty(len(X), bool)
        _, out, angle, *_ = localise_candidates(Xc, st, np.ones(len(X), bool), rim=border, filled=True)
        assert (rim & ~border).sum() == 0 and (border & ~rim).sum() > 50
        assert (d[border] <= 1).all() and (out[border & ~rim] == 0.0).all()


def _two_sheets(rng, points, gap=1.2):
    """A plate ``gap`` thick (z = 0 and z = gap), each sheet sampled at ``points`` (x, y)."""
    other = points + 0.2 * rng.normal(size=points.shape)
    return np.vstack([np.c_[points, np.zeros(len(points))], np.c_[other, np.full(len(other), gap)]])


@pytest.mark.parametrize("where, found", [(0.0, True), (-3.0, False)])
def test_a_border_is_an_empty_angle_about_the_point(where, found):
    # a plate's half (x <= 0), evenly sampled at spacing 1: at its border, the points within
    # BORDER_REACH leave half the circle empty; inside, no angle is empty
    rng = np.random.default_rng(3)
    g = np.mgrid[-8:0.5:1.0, -6:6.5:1.0].reshape(2, -1).T.astype(float)
    g[:, 1] += 0.5 * (np.round(g[:, 0]) % 2)  # hexagonal rows
    g += 0.1 * rng.normal(size=g.shape)
    g = g[g[:, 0] <= 0.1]
    p = np.argmin(np.abs(g[:, 0] - where) + np.abs(g[:, 1]))
    X = _two_sheets(rng, g)
    line = np.empty(6)
    ring = np.array([q for q in range(len(X)) if q != p])
    d = thin_walls.border_gap(X, p, ring, len(ring), 1.0, np.array([0.0, 0.0, 1.0]),
                             np.empty(len(ring)), line, np.empty(3), np.empty(3))
    if found:
        assert d == 0.0 and np.allclose(line[:3], X[p]) and abs(line[4]) > 0.95  # along y
    else:
        assert d == np.inf


def test_a_line_scan_shows_no_border_and_does_not_fill_its_planes():
    # scan lines 4 apart (x), points 1 apart along them (y): within BORDER_REACH a point sees
    # its own line only, two empty half circles; the sampling's median empty angle is 180°
    rng = np.random.default_rng(4)
    g = np.mgrid[-16:16.5:4.0, -20:20.5:1.0].reshape(2, -1).T.astype(float)
    g += 0.05 * rng.normal(size=g.shape)
    X = np.c_[g, 0.05 * rng.normal(size=len(g))]
    p = np.argmin(np.abs(X[:, 0]) + np.abs(X[:, 1]))
    ring = np.array([q for q in range(len(X)) if q != p])
    assert thin_walls.border_gap(X, p, ring, len(ring), 1.0, np.array([0.0, 0.0, 1.0]),
                                np.empty(len(ring)), np.empty(6), np.empty(3),
                                np.empty(3)) == np.inf
    st = neighbourhoods(X, scale_of(X))
    gap = thin_walls.median_ring_gap(X, st.normals, st.dn, st.dn_cnt, 1.0, 256)
    assert gap > thin_walls.FILLED_GAP
    even = np.mgrid[-16:16.5:1.0, -20:20.5:1.0].reshape(2, -1).T
    even = even + 0.2 * rng.normal(size=even.shape)
    Xe = np.c_[even, 0.05 * rng.normal(size=len(even))]
    st = neighbourhoods(Xe, scale_of(Xe))
    gap = thin_walls.median_ring_gap(Xe, st.normals, st.dn, st.dn_cnt, 1.0, 256)
    assert gap < thin_walls.FILLED_GAP


def _scanned_step(rng, height=5.0, pitch=0.01, lines=4.0, noise=0.1):
    """A step scanned in lines across it, ``(X, edges)``: a top face (z = 0, x < 0), a wall
    ``height`` pitches tall (x = 0) and a floor (x > 0), sampled every ``pitch`` along the
    profile on lines ``lines`` pitches apart along the edges (y), with range noise of
    ``noise`` pitches; ``edges``: the two edges' (x, z)."""
    h = height * pitch
    t = np.arange(0.0, 0.6 + h, pitch) + rng.random() * pitch
    x = np.where(t < 0.3, t - 0.3, np.where(t < 0.3 + h, 0.0, t - 0.3 - h))
    z = np.where(t < 0.3, 0.0, np.where(t < 0.3 + h, 0.3 - t, -h))
    y = np.arange(0.0, 1.0, lines * pitch)
    X = np.array([(xi, yi, zi) for yi in y for xi, zi in zip(x, z)])
    X[:, 1] += 0.05 * pitch * rng.normal(size=len(X))
    return X + noise * pitch * rng.normal(size=X.shape), np.array([[0.0, 0.0], [0.0, -h]])


def _whole_ring_fits(X, st, nn, points):
    """The edge distance (local spacings) of each of ``points`` fitted over its whole two-ring,
    as ``localise`` fits it first (its own sheet, then the normal seeds and the sweep)."""
    mark = np.zeros(len(X), np.int64)
    idx, side = np.empty(two_ring.MAX_RING + 1, np.int64), np.empty(two_ring.MAX_RING + 1, np.int64)
    proj, line = np.empty(two_ring.MAX_RING + 1), np.empty(6)
    order = np.empty(two_ring.MAX_RING + 1, np.int64)
    c1, n1, c2, n2, work = (np.empty(3) for _ in range(5))
    max_cos = np.cos(np.deg2rad(edge_fit.MIN_ANGLE))
    out = np.empty(len(points))
    for i, p in enumerate(points):
        idx[0] = p
        c = 1 + two_ring.gather_rings(p, st.dn, st.dn_cnt, two_ring.FIT_RINGS, mark, idx[1:])
        s = np.median(nn[idx[:c]])
        c = thin_walls.own_layer(X, idx, c, s, proj, c1, work)
        d, _ = edge_fit.edge_distance(X, st.normals, idx, c, side, c1, n1, c2, n2, work, s,
                                      proj, line, max_cos, order)
        out[i] = d / s
    return out


def test_a_scanned_step_is_fitted_on_the_near_part_of_its_two_ring():
    """Scan lines four pitches apart: the two-ring reaches some eight local spacings across
    them, and on a step five pitches tall past the wall to the other face. Over four scans,
    the fits over the whole two-ring place 145 of the edges' 301 points within a spacing of
    a line (8-58 of 64-81 a scan), with the near part (``NEAR_RING`` local spacings) where
    those fail 267; no face point more than 3 spacings from the edges fits a line."""
    found = whole = total = 0
    for seed in range(4):
        rng = np.random.default_rng(seed)
        X, edges = _scanned_step(rng)
        mean = X.mean(0)
        X = X - mean
        st = neighbourhoods(X, scale_of(X))
        nn, out, _, _, _, _, _, narrowed = localise_candidates(X, st, np.ones(len(X), bool))
        s = np.median(nn)
        inner = np.abs(X[:, 1]) < 0.4  # away from the open ends of the edges
        d = np.min([np.hypot(X[:, 0] + mean[0] - ex, X[:, 2] + mean[2] - ez)
                    for ex, ez in edges], axis=0) / s
        near = np.flatnonzero(inner & (d <= 1.0))
        first = _whole_ring_fits(X, st, nn, near)
        # the near part is tried only where the whole two-ring fits no edge
        assert not (narrowed[near] & np.isfinite(first)).any()
        np.testing.assert_array_equal(out[near][np.isfinite(first)], first[np.isfinite(first)])
        found += (out[near] <= 1.0).sum()
        whole += (first <= 1.0).sum()
        total += len(near)
        assert not (out[inner & (d > 3.0)] <= 1.0).any()
    assert found / total > 0.75 and found - whole > 0.2 * total


def _jittered_grid(rng, n_side, pitch):
    """Points on a jittered square grid of ``n_side`` x ``n_side`` cells in the xy-plane,
    centred on the origin (an even sampling with no scan lines)."""
    g = (np.arange(n_side) - n_side / 2 + 0.5) * pitch
    xy = np.array([(x, y) for x in g for y in g])
    return xy + (rng.random(xy.shape) - 0.5) * 0.6 * pitch


@pytest.mark.parametrize("height", [0.5, 0.7, 1.0])
def test_a_step_lower_than_the_spacing_is_an_edge(height):
    """A face stepping up by less than a spacing along x = 0 (a rib on counter's underside is
    0.67 spacings tall): its wall holds no points and its two-rings' PCA planes tilt across
    it, so no two-plane fit finds it; the step fit does (the points within half a spacing of
    the step, at mid height, within a spacing of a line), and no point of a flat face farther
    than 3 spacings from it. Two sheets this far apart lying one over the other (a thin wall)
    are no step: of their 2,454 inner points 7 fit a step at 0.5 pitches (where the
    jittered sheets lie side by side), none at 0.7 or 1.0 (one other fit at 0.7)."""
    rng = np.random.default_rng(7)
    pitch = 0.02
    xy = _jittered_grid(rng, 50, pitch)
    X = np.c_[xy, np.where(xy[:, 0] > 0, height * pitch, 0.0)]
    mean = X.mean(0)
    X = X - mean
    nn, out, angle, _, _, _, _, narrowed = localise_candidates(X, neighbourhoods(X, scale_of(X)),
                                                     np.ones(len(X), bool))
    s = np.median(nn)
    x = X[:, 0] + mean[0]  # the step at x = 0
    inner = np.abs(X[:, 1]) < 0.35
    near = inner & (np.abs(x) <= 0.5 * s)
    assert (out[near] <= 1.0).mean() > 0.8
    assert (narrowed[near] & (angle[near] == 90.0)).mean() > 0.5
    assert not (out[inner & (np.abs(x) > 3 * s)] <= 1.0).any()
    # two sheets this far apart, one over the other: a thin wall, no step
    top = _jittered_grid(rng, 50, pitch)
    Y = np.r_[np.c_[xy, np.zeros(len(xy))], np.c_[top, np.full(len(top), height * pitch)]]
    Y = Y - Y.mean(0)
    _, out_y, _, *_ = localise_candidates(Y, neighbourhoods(Y, scale_of(Y)), np.ones(len(Y), bool))
    assert (out_y[(np.abs(Y[:, :2]) < 0.35).all(axis=1)] <= 1.0).sum() <= 10
