"""Progressive removal: the maintained state equals a from-scratch recomputation (paper §3.3)."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tiledsimplify.core import adjacency, boundary, heap, importance
from tiledsimplify.core.removal import remove_points
from tiledsimplify.core.simplify import neighbourhoods
from tiledsimplify.core.voronoi import BOX_FACTOR, TOL_FACTOR, scale_of


def _cloud(kind, n, seed=0):
    rng = np.random.default_rng(seed)
    if kind == "wavy":
        xy = rng.random((n, 2)) * 3
        X = np.c_[xy, 0.4 * np.sin(2 * xy[:, 0]) * np.cos(1.5 * xy[:, 1])]
    elif kind == "box":  # the surface of a box: planes and sharp edges
        face = rng.integers(0, 6, n)
        uv = rng.random((n, 2))
        X = np.zeros((n, 3))
        axis, side = face // 2, face % 2
        for a in range(3):
            m = axis == a
            others = [b for b in range(3) if b != a]
            X[m, a] = side[m]
            X[m, others[0]] = uv[m, 0]
            X[m, others[1]] = uv[m, 1]
        X *= [2.0, 1.0, 0.7]
    else:  # LAS-like quantised terrain
        xy = rng.random((n, 2)) * 20
        X = np.c_[xy, np.sin(xy[:, 0] / 3) + 0.1 * xy[:, 1]]
        X = np.unique(np.round(X * 1000) / 1000, axis=0)
    return X - X.mean(0)


#: (importance code, weight): the paper's Eq. (1), and Eq. (1) + w rho^2 with a weight that
#: makes both terms matter on these clouds (unit spacing ~0.5)
MEASURES = [(0, 0.0), (1, 0.3)]


#: Voronoi reach, in spacings: the paper's unbounded rule, and a bounded one that the
#: removals outgrow (gaps wider than twice the reach; isolated points)
REACHES = [np.inf, 4.0]


def _reach(X, spacings):
    return spacings * np.median(cKDTree(X).query(X, k=2)[0][:, 1]) if np.isfinite(spacings) \
        else np.inf


def _no_guard(X):
    """``covers``, ``owners`` and ``cover_xyz`` of :func:`remove_points` for a run without a
    guard (never read)."""
    return np.ones(0, dtype=bool), np.full((2, 0), -1, dtype=np.int64), np.empty((0, 3))


def _state(X, code=0, weight=0.0, reach=np.inf):
    D = scale_of(X)
    st = neighbourhoods(X, D, reach)
    dev = np.zeros(len(X))
    boundary.all_deviations(X, st.normals, st.dn, st.dn_cnt, dev)
    flags, _ = boundary.detect(dev)
    imp = np.zeros(len(X))
    importance.all_importance(code, X, st.normals, flags, st.dn, st.dn_cnt, weight, imp)
    return D, st, flags, imp


@pytest.mark.parametrize("update", [True, False])
@pytest.mark.parametrize("reach", REACHES)
@pytest.mark.parametrize("measure", MEASURES)
@pytest.mark.parametrize("kind", ["wavy", "box", "quantised"])
def test_maintained_state_equals_recomputation(kind, measure, reach, update):
    """``update`` False: the normals stay the whole cloud's, everything else is exact."""
    code, weight = measure
    X = _cloud(kind, 1500)
    reach = _reach(X, reach)
    D, st, flags, imp = _state(X, code, weight, reach)
    normals0 = st.normals.copy()
    frozen = np.zeros(len(X), bool)
    frozen[::17] = True
    removable = ~flags & ~frozen
    steps = int(removable.sum()) * 3 // 4
    order, at, st.pool = remove_points(
        X, st.start, st.cnt, st.cap, st.pool, st.meta, st.dn, st.dn_cnt, st.plane_normals,
        st.normals, st.stable, flags, removable.copy(), imp, heap.coordinate_hash(X), code,
        weight, 0, 0.0, *_no_guard(X), steps, BOX_FACTOR * D, TOL_FACTOR * D, reach, update)
    assert len(order) == steps == len(set(order.tolist()))
    assert not (flags[order] | frozen[order]).any()
    alive = np.ones(len(X), bool)
    alive[order] = False
    keep = np.flatnonzero(alive)
    fresh = neighbourhoods(X[keep], D, reach)
    vn_m = adjacency.to_sets(st.start, st.cnt, st.pool)
    vn_f = adjacency.to_sets(fresh.start, fresh.cnt, fresh.pool)
    if not update:
        np.testing.assert_array_equal(st.normals, normals0)
        fresh.normals[:] = normals0[keep]
    imp_f = np.zeros(len(keep))
    importance.all_importance(code, X[keep], fresh.normals, flags[keep], fresh.dn, fresh.dn_cnt,
                              weight, imp_f)
    for i, p in enumerate(keep):
        assert vn_m[p] == {int(keep[j]) for j in vn_f[i]}, p
        if flags[p]:
            continue  # a boundary point's one-ring and normal are not kept up to date: no
            # importance reads them (Eq. (1) skips boundary neighbours), and the whole order
            # equals the naive greedy's, which recomputes them (test below)
        # the lists stay sorted nearest first, ties by index (local_mesh sorts in place, a
        # removal keeps the order): what keeps the sorts in the loop cheap
        lst = st.pool[st.start[p]:st.start[p] + st.cnt[p]].tolist()
        e = X[lst] - X[p]
        d2 = e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1] + e[:, 2] * e[:, 2]
        assert lst == [q for _, q in sorted(zip(d2.tolist(), lst))], p
        dn_m = st.dn[p, : st.dn_cnt[p]].tolist()
        dn_f = keep[fresh.dn[i, : fresh.dn_cnt[i]]].tolist()
        assert dn_m == dn_f, p
        np.testing.assert_array_equal(st.plane_normals[p], fresh.plane_normals[i])
        np.testing.assert_array_equal(st.normals[p], fresh.normals[i])
        assert st.stable[p] == fresh.stable[i], p  # kept right where recomputation was skipped
        if removable[p]:
            assert imp[p] == imp_f[i], p


def _naive_greedy(X, flags, frozen, steps, D, code, weight, reach, normals=None):
    """Recompute everything from scratch before every removal (but the ``normals``, if
    given: the whole cloud's, kept)."""
    tie = heap.coordinate_hash(X)
    alive = np.ones(len(X), bool)
    order, at = [], []
    for _ in range(steps):
        keep = np.flatnonzero(alive)
        st = neighbourhoods(X[keep], D, reach)
        if normals is not None:
            st.normals[:] = normals[keep]
        imp = np.zeros(len(keep))
        importance.all_importance(code, X[keep], st.normals, flags[keep], st.dn, st.dn_cnt, weight,
                                  imp)
        cand = [(imp[i], tie[keep[i]], int(keep[i])) for i in range(len(keep))
                if not flags[keep[i]] and not frozen[keep[i]]]
        if not cand:
            break
        v, _, p = min(cand)
        order.append(p)
        at.append(v)
        alive[p] = False
    return order, at


@pytest.mark.parametrize("update", [True, False])
@pytest.mark.parametrize("reach", REACHES)
@pytest.mark.parametrize("measure", MEASURES)
@pytest.mark.parametrize("kind", ["wavy", "box"])
def test_greedy_order_equals_naive_from_scratch(kind, measure, reach, update):
    code, weight = measure
    X = _cloud(kind, 160, seed=1)
    reach = _reach(X, reach)
    D, st, flags, imp = _state(X, code, weight, reach)
    normals0 = st.normals.copy()
    frozen = np.zeros(len(X), bool)
    frozen[:10] = True
    removable = ~flags & ~frozen
    steps = int(removable.sum()) - 5
    order, at, _ = remove_points(
        X, st.start, st.cnt, st.cap, st.pool, st.meta, st.dn, st.dn_cnt, st.plane_normals,
        st.normals, st.stable, flags, removable.copy(), imp, heap.coordinate_hash(X), code,
        weight, 0, 0.0, *_no_guard(X), steps, BOX_FACTOR * D, TOL_FACTOR * D, reach, update)
    ref_order, ref_at = _naive_greedy(X, flags, frozen, steps, D, code, weight, reach,
                                      None if update else normals0)
    assert order.tolist() == ref_order
    np.testing.assert_array_equal(at, ref_at)



def test_room_grown_between_removals_gives_the_same_sequence(monkeypatch):
    """The removal loop (removal._run) never grows an array: before each removal it checks
    the room the removal needs and, if short, returns; remove_points grows the pool or the
    buffers and goes on. Points near two skew lines (Voronoi degrees in the hundreds, past the
    first buffers of 64) with lists packed without slack (each list's first new neighbour
    moves it, the pool grows again and again) give exactly the sequence of roomy lists."""
    from tiledsimplify.core import simplify as simplify_mod

    rng = np.random.default_rng(4)
    m = 150
    t = np.sort(rng.random(m))
    X = np.concatenate([np.c_[t, np.zeros(m), np.zeros(m)],
                        np.c_[np.full(m, 0.5), rng.random(m) - 0.5, np.full(m, 0.3)]])
    X = X + 1e-4 * rng.uniform(-1, 1, X.shape)
    runs = []
    for slack in (8, 0):
        packed_lists = simplify_mod.voronoi_neighbours
        monkeypatch.setattr(simplify_mod, "voronoi_neighbours",
                            lambda *a, _s=slack, _f=packed_lists, **k: _f(*a, **{**k,
                                                                              "slack": _s}))
        D, st, flags, imp = _state(X)
        monkeypatch.undo()
        assert st.cnt.max() > 64
        if slack == 0:
            assert (st.cap == st.cnt).all()
        removable = ~flags
        sizes = st.pool.size
        runs.append(remove_points(
            X, st.start, st.cnt, st.cap, st.pool, st.meta, st.dn, st.dn_cnt, st.plane_normals,
            st.normals, st.stable, flags, removable, imp, heap.coordinate_hash(X), 0, 0.0, 0,
            0.0, *_no_guard(X), int(removable.sum()) - 10, BOX_FACTOR * D, TOL_FACTOR * D,
            np.inf, False))
    (o1, a1, p1), (o2, a2, p2) = runs
    assert len(o1) > 200 and p2.size > p1.size // 4
    assert p2.size > sizes  # the packed run's pool was grown between removals
    np.testing.assert_array_equal(o1, o2)
    np.testing.assert_array_equal(a1, a2)


def _farthest(X, keep):
    """The largest distance from a point of ``X`` to the nearest point of ``X[keep]``."""
    return float(cKDTree(X[keep]).query(X)[0].max())


@pytest.mark.parametrize("kind", ["bunny", "scan"])
def test_max_spacing_leaves_no_point_farther_than_the_limit(kind, data_dir):
    """The ``max_spacing`` guard (issue #5: "users may set a maximum spacing in model units"):
    at the count asked and at every count of the sequence (``keep_at``), no input point lies
    farther than the limit from a kept point — checked by a kd-tree over all of them. The rule
    until 2026-12-04 (a remaining neighbour of the removed point within the limit) left Bunny
    points 7 spacings from every kept one at a limit of 5. Duplicates and frozen points too."""
    from tiledsimplify import SimplifyOptions, simplify_points
    from tiledsimplify.io import read_mesh, read_points
    from tiledsimplify.synthetic import scan, spacing
    if kind == "bunny":
        X = read_points(data_dir / "meshes" / "stanford_bunny" / "bun_zipper_res2.ply.gz")
        X = np.concatenate([X, X[:50]])  # exact duplicates
    else:
        V, F = read_mesh(data_dir / "meshes" / "cad_classic" / "fandisk.obj")
        X, _ = scan(V, F, n_points=8000, seed=0)
        X, _ = scan(V, F, n_points=8000, noise=0.1 * spacing(X), seed=0)
    s = spacing(X)
    frozen = np.zeros(len(X), bool)
    frozen[::97] = True
    for factor in (2.0, 5.0):
        limit = factor * s
        with pytest.warns(UserWarning, match="vetoed by the max_spacing guard"):
            res = simplify_points(X, 0.01, frozen=frozen, options=SimplifyOptions(
                guard="max_spacing", max_spacing=limit))
        kept = int(res.keep.sum())
        assert kept > 0.01 * len(X) and _farthest(X, res.keep) <= limit
        for count in (kept + 1, kept + (len(X) - kept) // 3, len(X) // 2):
            assert _farthest(X, res.keep_at(count=count)) <= limit, (factor, count)
        # and it binds: the same greedy without it leaves wider gaps at that count
        free = simplify_points(X, count=kept, frozen=frozen,
                               options=SimplifyOptions(prethin=0, refine=False))
        assert _farthest(X, free.keep) > limit, factor


def test_a_guard_that_never_vetoes_changes_nothing():
    """A limit no gap reaches: the default's output exactly (its pre-thinning's disks are
    capped at half the limit: no cap here; the refinement runs as without a guard), with the
    same removal sequence until the last few points, which no remaining point can cover;
    without the pre-thinning too."""
    from tiledsimplify import SimplifyOptions, simplify_points
    X = _cloud("wavy", 1500)
    for prethin in (0, None):
        guarded = simplify_points(X, 0.1, options=SimplifyOptions(
            guard="max_spacing", max_spacing=1e6, prethin=prethin))
        free = simplify_points(X, 0.1, options=SimplifyOptions(prethin=prethin))
        assert ("n_prethin_subset" in guarded.stats) == (prethin is None)
        assert guarded.reached and len(free.order) - 10 < len(guarded.order) < len(free.order)
        np.testing.assert_array_equal(guarded.order[:1400], free.order[:1400])
        np.testing.assert_array_equal(guarded.keep, free.keep)
        assert guarded.stats["refine_swaps"] == free.stats["refine_swaps"] > 0


@pytest.mark.parametrize("limit", [1e200, 1e300])
def test_a_limit_whose_square_overflows_still_keeps_a_cover(limit):
    """A limit past ~1.3e154 squares to inf: the guard compared a removed point's distance to
    no cover (inf) with it, found inf > inf false and let the last points go — 0 kept of 2000,
    every point infinitely far from a kept one — and handed the point to cover -1 (the cover
    lists' last slot). A point with no cover is kept whatever the limit."""
    from tiledsimplify import SimplifyOptions, simplify_points
    X = _cloud("wavy", 1500)
    for prethin in (0, None):
        res = simplify_points(X, options=SimplifyOptions(guard="max_spacing", max_spacing=limit,
                                                         prethin=prethin))
        assert 1 <= res.count <= 10 and _farthest(X, res.keep) <= limit


def test_a_limit_that_is_not_a_finite_distance_is_refused():
    """``max_spacing = inf`` (valid TOML) bounded nothing; the command line refused it."""
    import math

    from tiledsimplify import SimplifyOptions
    from tiledsimplify.errors import InputError
    for bad in (math.inf, math.nan, 0.0, -1.0):
        with pytest.raises(InputError, match=r"positive \(finite\) distance in model units"):
            SimplifyOptions(guard="max_spacing", max_spacing=bad)
