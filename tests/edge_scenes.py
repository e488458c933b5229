"""Scenes and steps 1-2 of the edge fits, shared by their tests (``test_edge_fit``,
``test_two_planes``, ``test_edge_lines``, ``test_thin_walls``)."""

import numpy as np

from tiledsimplify import synthetic
from tiledsimplify.core import edge_fit, two_ring
from tiledsimplify.core.simplify import neighbourhoods, scale_of
from tiledsimplify.io import read_mesh


def roof(rng, n, angle_deg=90.0, noise=0.0):
    """Two planes meeting along x = 0 at the given dihedral opening; z up."""
    xy = rng.random((n, 2)) * 2 - 1
    slope = np.tan(np.deg2rad(90.0 - angle_deg / 2.0))
    X = np.c_[xy, -slope * np.abs(xy[:, 0])]
    return X + noise * rng.normal(size=X.shape)


def localise_candidates(X, st, candidate, min_angle=edge_fit.MIN_ANGLE, width=1.0, rim=None,
              filled=False):
    """``edge_fit.localise`` of the ``candidate`` points of centred ``X`` (neighbourhoods
    ``st``): ``(nn, dist, angle, line, local, corner, bend, narrowed)``; the rim fits into
    ``rim`` (a bool array of ``len(X)``) if given."""
    n = len(X)
    nn = np.empty(n)
    two_ring.nearest_distances(X, st.start, st.cnt, st.pool, nn)
    dist, angle, line, local = np.empty(n), np.empty(n), np.empty((n, 6)), np.empty(n)
    corner, bend, narrowed = np.empty(n, bool), np.empty(n), np.empty(n, bool)
    edge_fit.localise(X, st.normals, st.dn, st.dn_cnt, nn, candidate, dist, angle, line, local,
                      min_angle, width, corner, bend, narrowed,
                      np.empty(n, bool) if rim is None else rim, filled)
    return nn, dist, angle, line, local, corner, bend, narrowed


def localise_all(X, min_angle=edge_fit.MIN_ANGLE):
    X = X - X.mean(0)
    nn, out, angle, *_ = localise_candidates(X, neighbourhoods(X, scale_of(X)), np.ones(len(X), bool),
                                   min_angle)
    return out, nn, angle


def fitted_scan(data_dir, n_points=6000):
    """The Fandisk scanned (noise 0.1 spacing), centred, with steps 1-2 of every candidate:
    ``(X, st, cand, dist, ang, line, local, corner)``."""
    V, F = read_mesh(data_dir / "meshes" / "cad_classic" / "fandisk.obj")
    s = synthetic.spacing(synthetic.scan(V, F, n_points=n_points, seed=0)[0])
    X, _ = synthetic.scan(V, F, n_points=n_points, noise=0.1 * s, seed=0)
    return steps_1_2(X - X.mean(0))[:8]


def steps_1_2(X, width=1.0):
    """Steps 1-2 of every candidate of centred ``X``: ``(X, st, cand, dist, ang, line, local,
    corner, nn, bend)``."""
    st = neighbourhoods(X, scale_of(X))
    n = len(X)
    dev, smooth = np.empty(n), np.empty((n, 3))
    two_ring.smoothed_deviations(X, st.dn, st.dn_cnt, smooth, dev)
    cand = dev > edge_fit.CANDIDATE
    nn, dist, ang, line, local, corner, bend, _ = localise_candidates(X, st, cand, width=width)
    return X, st, cand, dist, ang, line, local, corner, nn, bend


def two_ring_ids(dn, dn_cnt, p):
    one = set(dn[p, :dn_cnt[p]].tolist())
    two = set(one)
    for q in one:
        two.update(dn[q, :dn_cnt[q]].tolist())
    two.discard(p)
    return two
