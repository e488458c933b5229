"""The tiled pipeline: exact global count, agreement with the untiled core, the same output for
every scheduler, resume, LAS/LAZ end to end, and the command line."""

import json
import time
from pathlib import Path

import laspy
import numpy as np
import pytest

from tiledsimplify import simplify_points
from tiledsimplify.cli import EXIT_OK, main
from tiledsimplify.core import edge_fit
from tiledsimplify.core.refine import PROTECT
from tiledsimplify.errors import InputError
from tiledsimplify.io import read_points
from tiledsimplify.pipeline import run
from tiledsimplify.pipeline.budget import deeper_tiles, global_cut, kept_mask, store_cut
from tiledsimplify.pipeline.tile_refine import refined_mask
from tiledsimplify.pipeline.tile_task import BINS, threshold_from_histogram
from tiledsimplify.pipeline.tile_task import _tile_cloud as tile_cloud
from tiledsimplify.tiles import TileStore


@pytest.fixture(scope="module")
def bunny(data_dir, tmp_path_factory):
    X = read_points(data_dir / "meshes" / "stanford_bunny" / "bun_zipper_res2.ply.gz")
    path = tmp_path_factory.mktemp("in") / "bunny.npy"
    np.save(path, X)
    return X, path


def test_a_cut_that_leaves_tiles_empty_says_so(tmp_path, caplog):
    """One point kept of a strip 200 long in several tiles: the views of the tiles far from
    it (ten halos, 22 wide) hold no kept point, whose distance is inf. The run writes its
    point and says in words why it does not refine (it printed "points inf from the nearest
    kept point")."""
    rng = np.random.default_rng(3)
    X = np.c_[rng.random((4000, 2)) * [200.0, 1.0], np.zeros(4000)]
    path = tmp_path / "strip.npy"
    np.save(path, X)
    with caplog.at_level("WARNING", logger="tiledsimplify"):
        s = run(path, tmp_path / "one.npy", count=1, tile_points=1000, progress=False)
    assert s.n_output == 1 and s.n_tiles >= 4 and not s.refined
    assert len(np.load(tmp_path / "one.npy")) == 1
    warned = [r.getMessage() for r in caplog.records if "no gap refinement" in r.getMessage()]
    assert len(warned) == 1 and "points with no kept point within 10 halos" in warned[0]
    assert "inf" not in warned[0]


def test_global_cut_is_exact_and_prefers_flat_tiles():
    flat = np.linspace(0.0, 0.1, 100)
    curved = np.linspace(0.0, 10.0, 100)
    noisy = np.array([0.0, 5.0, 0.1, 0.2, 0.3])  # running max 5 from step 1 on
    cut = global_cut({0: flat, 1: curved, 2: noisy}, 120)
    assert sum(cut.values()) == 120
    assert cut[0] == 100 and cut[2] == 1 and cut[1] == 19
    assert sum(global_cut({0: flat}, 1000).values()) == 100


@pytest.mark.parametrize("collect", [1 << 22, 3, 0])
def test_global_cut_matches_sorting_every_step(monkeypatch, collect):
    """The radix selection against the cut's definition (sort every (running max, tile, step)),
    on ties, plateaus, -0.0, inf and empty tiles; ``collect`` 0 forces all four passes down to a
    single key, 3 a mixture of collected and counted ranges; and the same with each pass run
    over separate sets of tiles and merged."""
    from naive import global_cut_by_sorting

    from tiledsimplify.pipeline import budget
    monkeypatch.setattr(budget, "COLLECT", collect)
    rng = np.random.default_rng(7)
    kinds = [lambda n: rng.random(n), lambda n: rng.integers(0, 3, n).astype(float),
             lambda n: np.where(rng.random(n) < 0.3, np.inf, rng.random(n)),
             lambda n: rng.choice([-0.0, 0.0, 1e-300, -1e-5, 2.0], n),
             lambda n: np.sort(rng.normal(size=n)) * 1e6]
    for _ in range(60):
        seqs = {int(t): kinds[rng.integers(len(kinds))](int(rng.integers(0, 40)))
                for t in rng.choice(50, rng.integers(1, 7), replace=False)}
        total = sum(len(q) for q in seqs.values())
        tiles = sorted(seqs)
        batches = [tiles[:1], tiles[1:3], tiles[3:]]  # passes over separate sets of tiles,
        # as a cluster's workers run them (run._cut_scan), merged

        def scan(lo, bits, final, seqs=seqs, batches=batches):
            return budget.merge_passes(budget.count_pass(seqs, b, lo, bits, final)
                                       for b in batches)
        for n_remove in {0, 1, total // 3, total // 2, total - 1, total, total + 5}:
            want = global_cut_by_sorting(seqs, n_remove)
            assert global_cut(seqs, n_remove) == want
            assert budget.plan_cut(seqs, n_remove, dict.fromkeys(seqs, True),
                                   scan=scan)[0] == want
            passes = []  # with a bound of the steps: one pass where it is within COLLECT

            def counted(lo, bits, final, scan=scan, passes=passes):
                passes.append(final)
                return scan(lo, bits, final)
            assert budget.plan_cut(seqs, n_remove, dict.fromkeys(seqs, True), scan=counted,
                                   most=total)[0] == want
            if total <= collect:
                assert passes == [True]
            else:
                assert passes[0] is False and (len(passes) >= 2 or min(n_remove, total) == 0)


def test_global_cut_holds_one_tile_at_a_time(monkeypatch):
    """Memory bounded by a tile, not the input (DESIGN §5): over sequences read lazily, the
    cut's peak allocation stays within a few tiles' sequences (plus the keys it collects,
    at most ``COLLECT``: here 1,000), far below all of them."""
    import tracemalloc
    from collections.abc import Mapping

    from tiledsimplify.pipeline import budget
    monkeypatch.setattr(budget, "COLLECT", 1000)

    class Lazy(Mapping):  # like budget.StoreSequences: made when asked for, not kept
        def __getitem__(self, t):
            return np.sort(np.random.default_rng(t).random(20_000)) * (t % 7 + 1)

        def __iter__(self):
            return iter(range(60))

        def __len__(self):
            return 60

    tile_bytes = 20_000 * 8
    tracemalloc.start()
    try:
        cut = global_cut(Lazy(), 500_000)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert sum(cut.values()) == 500_000
    assert peak < 12 * tile_bytes + 2 * 8 * (1 << 16)  # 60 tiles' sequences would be 60x


def test_deeper_tiles_names_the_tiles_that_stop_short_of_the_cut():
    rng = np.random.default_rng(1)
    full = {t: np.sort(rng.random(50)) * (t + 1) for t in range(4)}
    full[4] = np.r_[np.zeros(30), np.linspace(0, 1, 20)]  # ties at level 0 with tile 5
    full[5] = np.zeros(40)
    for n_remove in (0, 10, 35, 60, 100, 150, 230, 290, 331):
        want = global_cut(full, n_remove)
        for known in (5, 20, 45):
            seqs = {t: f[:known] for t, f in full.items()}
            done = {t: len(f) <= known for t, f in full.items()}
            need = deeper_tiles(seqs, n_remove, done)
            if not need:  # the cut over the known prefixes is the cut over the full sequences
                assert global_cut(seqs, n_remove) == want
                continue
            # run the named tiles past their level (as the pipeline does): then it is exact
            deeper = dict(seqs)
            for t, level in need.items():
                runmax = np.maximum.accumulate(full[t])
                k = int(np.searchsorted(runmax, level, side="right")) + 1
                deeper[t] = full[t][:k]
                done[t] = k >= len(full[t])
            assert not deeper_tiles(deeper, n_remove, done)
            assert global_cut(deeper, n_remove) == want


def test_threshold_from_histogram_matches_exact_rule():
    from tiledsimplify.core.boundary import automatic_threshold
    rng = np.random.default_rng(0)
    v = np.r_[rng.gamma(2.0, 0.02, 20000), rng.uniform(0.5, 1.5, 2000)]
    hist = np.histogram(v, bins=BINS)[0]
    assert threshold_from_histogram(hist, 3.0, 0.0) == pytest.approx(
        automatic_threshold(v, 3.0, 0.0), rel=0.01)


def test_tiled_run_exact_count_and_agrees_with_untiled(bunny, tmp_path):
    X, path = bunny
    store = tmp_path / "store"
    out = tmp_path / "out.npy"
    s = run(path, out, ratio=0.2, tile_points=1200, store=store)
    assert s.n_tiles >= 8 and s.reached
    t = np.load(out)
    assert len(t) == s.target == round(0.2 * len(X))
    # kept points are input points, in input order, each once
    kept = np.stack([t["x"], t["y"], t["z"]], 1)
    idx = np.flatnonzero((X[:, None, :] == kept[None, :, :]).all(-1).any(1))
    assert len(idx) == len(kept)
    np.testing.assert_array_equal(X[idx], kept)
    # and they are the ones the refinement keeps, each tile as many as the global cut
    ts = TileStore.open(store)
    assert s.refined
    np.testing.assert_array_equal(np.flatnonzero(refined_mask(ts)), idx)
    cut = kept_mask(ts, store_cut(ts, len(X) - s.target))
    for i in range(ts.n_tiles):
        gi = ts.core(i)[1]
        assert cut[gi].sum() == len(np.intersect1d(gi, idx))
    # boundary flags and normals of core points, with the same threshold, equal the untiled
    # run wherever the halo covers the neighbourhoods (all but a few points)
    untiled = simplify_points(X, ratio=0.2, options={"boundary_threshold": s.threshold,
                                                     "spacing": s.spacing})
    # and so do the points the refinement keeps fixed (the band and the protected points)
    agree = same_fixed = n = 0
    fixed_untiled = untiled.band | untiled.protected
    for i in range(ts.n_tiles):
        _, gi = ts.core(i)
        b = ts.read_result(i, "boundary")
        agree += int((b == untiled.boundary[gi]).sum())
        same_fixed += int((ts.read_result(i, "fixed") == fixed_untiled[gi]).sum())
        n += len(gi)
        nrm = ts.read_result(i, "normal")
        cos = np.abs(np.sum(nrm * untiled.normals[gi], axis=1))
        assert np.median(cos) > 0.9999
    assert agree / n > 0.99 and same_fixed / n > 0.99
    assert untiled.protected.sum() > 0
    assert s.threshold == edge_fit.CANDIDATE


def test_tiles_protect_what_the_core_protects_inside_a_rough_patch(tmp_path):
    """A rough patch in a plane: most of its points are above the protection level, and
    inside it the core protects only those with a point below the level within two Voronoi
    steps (:func:`~tiledsimplify.core.refine.protected`). Each tile stores the core's rule
    (``res.protected``) as its fixed points, so a tiled run agrees with the untiled core on
    99 % of the points or more — where the level alone would differ on more than 5 %."""
    rng = np.random.default_rng(3)
    n = 8000
    X = np.c_[rng.random((n, 2)), np.zeros(n)]
    rough = np.linalg.norm(X[:, :2] - 0.5, axis=1) < 0.3
    X[rough, 2] = 0.02 * rng.standard_normal(rough.sum())
    np.save(tmp_path / "in.npy", X)
    s = run(tmp_path / "in.npy", tmp_path / "out.npy", ratio=0.2, tile_points=2000,
            store=tmp_path / "store")
    ts = TileStore.open(tmp_path / "store")
    assert ts.n_tiles >= 4
    untiled = simplify_points(X, ratio=0.2, options={"boundary_threshold": s.threshold,
                                                     "spacing": s.spacing})
    fixed = untiled.band | untiled.protected
    level_alone = untiled.band | (untiled.deviation > PROTECT * untiled.threshold)
    assert (fixed != level_alone).mean() > 0.05
    same = 0
    for i in range(ts.n_tiles):
        _, gi = ts.core(i)
        same += int((ts.read_result(i, "fixed") == fixed[gi]).sum())
    assert same / n > 0.99


def _corrugated_in_tiles(tmp_path):
    """A plane sampled exactly and evenly (a jittered grid, 8,100 points) with a corrugated
    band finer than the spacing, run in tiles of about 2,000 points at 20 %: the points, the
    store, and the untiled core's result with the run's threshold and spacing (and those
    options)."""
    rng = np.random.default_rng(5)
    side = 90
    g = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2) * 1.0
    g += rng.uniform(-0.25, 0.25, g.shape)
    X = np.c_[g, np.zeros(len(g))]
    band = (X[:, 0] > 20) & (X[:, 0] < 70)
    X[band, 2] = 0.6 * np.sin(X[band, 0] * 2 * np.pi / 1.6)
    np.save(tmp_path / "in.npy", X)
    s = run(tmp_path / "in.npy", tmp_path / "out.npy", ratio=0.2, tile_points=2000,
            store=tmp_path / "store")
    ts = TileStore.open(tmp_path / "store")
    assert ts.n_tiles >= 4
    opts = {"boundary_threshold": s.threshold, "spacing": s.spacing}
    return X, ts, simplify_points(X, ratio=0.2, options=opts), opts


def _tiles_agree(ts, name, untiled):
    """The share of the points whose saved tile result ``name`` equals ``untiled`` (a mask
    over the input)."""
    same = 0
    for i in range(ts.n_tiles):
        _, gi = ts.core(i)
        same += int((ts.read_result(i, name) == untiled[gi]).sum())
    return same / len(untiled)


def test_tiles_flag_unresolved_detail_as_the_core_does(tmp_path, monkeypatch):
    """A plane sampled exactly and evenly, with a corrugated band finer than the spacing
    (:mod:`tiledsimplify.core.unresolved`): each tile decides on its own whether its sampling
    is exact and flags the band as the untiled core does (99 % of the points agree), where
    the test alone changes the flags of more than a fifth of them."""
    X, ts, untiled, opts = _corrugated_in_tiles(tmp_path)
    assert _tiles_agree(ts, "boundary", untiled.boundary) > 0.99
    import tiledsimplify.core.simplify as simplify_mod
    monkeypatch.setattr(simplify_mod, "unresolved", lambda X, *a: np.zeros(len(X), bool))
    plain = simplify_points(X, ratio=0.2, options=opts)
    assert (plain.boundary != untiled.boundary).mean() > 0.2


def test_tiles_keep_regions_of_detail_covered_as_the_core_does(tmp_path, monkeypatch):
    """The corrugated band of the test above, its groups of unresolved points taken as regions
    from 10 points (they hold up to ~30 here): each tile makes them features where their cover
    fits its share, as the untiled core does (the features agree on 99 % of the points; all of
    them when measured), where the regions alone change the features of nearly a tenth."""
    from tiledsimplify.core import unresolved as unresolved_mod
    monkeypatch.setattr(unresolved_mod, "MIN_REGION", 10)
    X, ts, untiled, opts = _corrugated_in_tiles(tmp_path)
    agree = _tiles_agree(ts, "feature", untiled.features)
    monkeypatch.setattr(unresolved_mod, "MIN_REGION", 10 ** 9)
    plain = simplify_points(X, ratio=0.2, options=opts)
    print(f"features agree {agree:.4f}, regions change "
          f"{(plain.features != untiled.features).mean():.4f}")
    assert agree > 0.99
    assert (plain.features != untiled.features).mean() > 0.05


def _hausdorff(X, out):
    from scipy.spatial import cKDTree
    t = np.load(out)
    return float(cKDTree(np.stack([t["x"], t["y"], t["z"]], 1)).query(X)[0].max())


def test_refinement_after_the_cut_lowers_hausdorff_at_the_same_count(bunny, tmp_path):
    X, path = bunny
    s0 = run(path, tmp_path / "cut.npy", ratio=0.2, tile_points=1200, options={"refine": False})
    s1 = run(path, tmp_path / "ref.npy", ratio=0.2, tile_points=1200)
    assert not s0.refined and s1.refined and s1.n_tiles >= 8
    assert "refine" in s1.seconds and "refine" in s1.cpu_seconds
    assert s0.n_output == s1.n_output == s1.target == len(np.load(tmp_path / "ref.npy"))
    h0, h1 = _hausdorff(X, tmp_path / "cut.npy"), _hausdorff(X, tmp_path / "ref.npy")
    print(f"tiled Hausdorff: cut {h0:.5g}, refined {h1:.5g}")
    assert h1 < 0.95 * h0
    # mode "paper" does not refine
    assert not run(path, tmp_path / "p.npy", ratio=0.2, tile_points=1200,
                   options={"mode": "paper"}).refined


def test_paper_mode_tiles_share_the_untiled_automatic_threshold(bunny, tmp_path):
    X, path = bunny
    s = run(path, tmp_path / "out.npy", ratio=0.2, tile_points=1200,
            options={"mode": "paper"})
    assert s.n_tiles >= 8 and s.reached
    untiled = simplify_points(X, ratio=1.0, options={"mode": "paper"})
    assert s.threshold == pytest.approx(untiled.threshold, rel=0.01)


def test_flat_tile_runs_deeper_than_its_floor_and_the_cut_stays_exact(tmp_path):
    # half the cloud nearly flat, half bumpy: the global cut takes far more than the floor
    # allows from the flat tiles, which must run again, deeper
    rng = np.random.default_rng(5)
    xy = rng.random((6000, 2)) * [4.0, 1.0]
    z = np.where(xy[:, 0] < 2.0, 1e-4 * rng.standard_normal(len(xy)),
                 0.15 * np.sin(6 * xy[:, 0]) * np.cos(6 * xy[:, 1]))
    X = np.c_[xy, z]
    path = tmp_path / "in.npy"
    np.save(path, X)
    store = tmp_path / "store"
    s = run(path, tmp_path / "out.npy", ratio=0.2, tile_points=1000, floor=0.5, store=store,
            workers=2, options={"mode": "paper"})
    assert s.reached and s.n_deeper >= 1
    t = np.load(tmp_path / "out.npy")
    assert len(t) == s.target == 1200
    # the cut over every tile run to the end of its sequence, with the same threshold
    ts = TileStore.open(store)
    full, floor_steps = {}, {}
    for i in range(ts.n_tiles):
        xyz, frozen, n_core = tile_cloud(ts, i)
        res = simplify_points(xyz, count=len(xyz), frozen=frozen,
                              options={"boundary_threshold": s.threshold, "mode": "paper"})
        full[i] = res.order_importance
        floor_steps[i] = n_core - int(np.ceil(0.5 * 0.2 * n_core))
        # what the pipeline stored is a prefix of that sequence
        known = ts.read_result(i, "step") >= 0
        np.testing.assert_array_equal(np.sort(ts.read_result(i, "step")[known]),
                                      np.arange(known.sum()))
        order = np.argsort(ts.read_result(i, "step")[known])
        np.testing.assert_array_equal(np.flatnonzero(known)[order], res.order[:known.sum()])
    cut = global_cut(full, len(X) - s.target)
    assert any(cut[i] > floor_steps[i] for i in cut)  # some tile had to go past its floor
    keep = kept_mask(ts, cut)
    kept = np.stack([t["x"], t["y"], t["z"]], 1)
    np.testing.assert_array_equal(X[keep], kept)


def test_coverage_mode_floor_changes_the_time_never_the_output(tmp_path, monkeypatch):
    # mode "coverage" simplifies the halo with the core; tiles stopped at the target share
    # (floor 0.99) must be run deeper by the global cut and give the bytes of a deep first pass
    # — the deeper pass rebuilding the neighbourhoods, which no pass saves in this mode
    saved = []
    write_state = TileStore.write_state
    monkeypatch.setattr(TileStore, "write_state",
                        lambda self, tile, *a, **k: (saved.append(tile),
                                                     write_state(self, tile, *a, **k)))
    rng = np.random.default_rng(6)
    xy = rng.random((5000, 2)) * [4.0, 1.0]
    X = np.c_[xy, np.where(xy[:, 0] < 2.0, 0.0, 0.1 * np.sin(5 * xy[:, 0]))]
    path = tmp_path / "in.npy"
    np.save(path, X)
    a = run(path, tmp_path / "a.npy", ratio=0.2, tile_points=900, floor=0.99)
    b = run(path, tmp_path / "b.npy", ratio=0.2, tile_points=900, floor=0.05)
    assert a.reached and b.reached and a.n_tiles >= 4
    assert a.n_deeper >= 1
    assert saved == []
    # mode "paper" builds every tile's state in its threshold pass and saves it for the others
    p = run(path, tmp_path / "p.npy", ratio=0.2, tile_points=900, options={"mode": "paper"})
    assert sorted(saved) == list(range(p.n_tiles))
    assert (tmp_path / "a.npy").read_bytes() == (tmp_path / "b.npy").read_bytes()


def test_prethinned_tiles_agree_between_passes(tmp_path, monkeypatch):
    """At 10 % the tiles are pre-thinned (core/prethin.py) aiming at the global target's share
    in every pass: tiles first run far (floor 0.05) or stopped at their share (floor 0.99, then
    deeper passes) give the same bytes; a resume with another target is refused."""
    from tiledsimplify.core import prethin
    thinned = []
    subset = prethin.subset

    def counted(*args, **kwargs):
        mask = subset(*args, **kwargs)
        thinned.append(mask is not None)
        return mask

    monkeypatch.setattr(prethin, "subset", counted)
    rng = np.random.default_rng(6)
    xy = rng.random((6000, 2)) * [4.0, 1.0]
    X = np.c_[xy, np.where(xy[:, 0] < 2.0, 0.0, 0.1 * np.sin(5 * xy[:, 0]))]
    path = tmp_path / "in.npy"
    np.save(path, X)
    a = run(path, tmp_path / "a.npy", ratio=0.1, tile_points=1000, floor=0.99,
            store=tmp_path / "store")
    b = run(path, tmp_path / "b.npy", ratio=0.1, tile_points=1000, floor=0.05)
    assert a.reached and b.reached and a.n_tiles >= 4 and a.n_deeper >= 1
    assert any(thinned)
    assert (tmp_path / "a.npy").read_bytes() == (tmp_path / "b.npy").read_bytes()
    off = run(path, tmp_path / "off.npy", ratio=0.1, tile_points=1000,
              options={"prethin": 0})
    assert off.reached and (tmp_path / "off.npy").read_bytes() != (
        tmp_path / "a.npy").read_bytes()
    with pytest.raises(ValueError, match="new --store"):
        run(path, tmp_path / "x.npy", ratio=0.08, tile_points=1000, floor=0.99,
            store=tmp_path / "store")


def test_a_single_tile_runs_exactly_to_the_target(tmp_path):
    # one tile alone sets the global cut: it stops at the target, and no deeper pass is needed
    X = np.random.default_rng(8).random((3000, 3)) * [1.0, 1.0, 0.05]
    np.save(tmp_path / "in.npy", X)
    s = run(tmp_path / "in.npy", tmp_path / "out.npy", ratio=0.2, store=tmp_path / "store",
            workers=1)
    ts = TileStore.open(tmp_path / "store")
    assert ts.n_tiles == 1 and s.reached and s.n_deeper == 0
    assert ts.result_attrs(0)["steps"] == len(X) - s.target
    assert len(np.load(tmp_path / "out.npy")) == s.target == 600


def test_max_spacing_holds_across_tiles(bunny, tmp_path):
    """A tiled run with the max_spacing guard leaves no input point farther than the limit
    from a kept one, at tile faces too: a tile's points are covered by its own points only
    (its halo's points are kept or removed by their own tiles). Before, covers from the halo
    counted, and the rule itself bounded nothing: 1,700 Bunny points beyond 5 spacings."""
    from scipy.spatial import cKDTree

    from tiledsimplify import SimplifyOptions
    from tiledsimplify.synthetic import spacing
    X, path = bunny
    limit = 3 * spacing(X)
    s = run(path, tmp_path / "o.npy", ratio=0.01, tile_points=2500, workers=2, progress=False,
            options=SimplifyOptions(guard="max_spacing", max_spacing=limit))
    out = np.load(tmp_path / "o.npy")
    K = np.c_[out["x"], out["y"], out["z"]]
    assert not s.reached and "vetoed by the max_spacing guard" in s.message
    assert s.n_tiles >= 3 and len(K) == s.n_output > 0.01 * len(X)
    assert cKDTree(K).query(X)[0].max() <= limit
    # no count asked: as few as the limit allows (about as many), and that is the count
    alone = run(path, tmp_path / "a.npy", tile_points=2500, workers=2, progress=False,
                options=SimplifyOptions(guard="max_spacing", max_spacing=limit))
    out = np.load(tmp_path / "a.npy")
    K = np.c_[out["x"], out["y"], out["z"]]
    assert alone.reached and alone.target == alone.n_output == len(K) and not alone.message
    assert abs(alone.n_output - s.n_output) < 0.05 * s.n_output
    assert cKDTree(K).query(X)[0].max() <= limit
    # a count it reaches is refined, as without a guard, and the bound holds (the tiles'
    # refinement never raises the cut's Hausdorff distance)
    r = run(path, tmp_path / "r.npy", ratio=0.2, tile_points=2500, workers=2, progress=False,
            options=SimplifyOptions(guard="max_spacing", max_spacing=limit))
    out = np.load(tmp_path / "r.npy")
    assert r.reached and r.refined and len(out) == r.target
    assert cKDTree(np.c_[out["x"], out["y"], out["z"]]).query(X)[0].max() <= limit


def test_max_spacing_holds_after_a_las_outputs_quantisation(bunny, tmp_path):
    """A LAS/LAZ output of a non-LAS input puts the kept points on a grid (a thousandth of the
    spacing): a kept point moves by up to half a step on each axis. The tiles' guard works to
    the limit less that move, so the file read back still leaves no input point farther than
    the limit: the Bunny at 2 spacings had 2 points 2.4e-7 beyond it (the step 1e-6). A
    store is resumed only for an output that moves points as its tiles assumed."""
    from scipy.spatial import cKDTree

    from tiledsimplify import SimplifyOptions
    from tiledsimplify.synthetic import spacing
    X, path = bunny
    limit = 2 * spacing(X)
    out = tmp_path / "o.las"
    s = run(path, out, tile_points=3000, workers=1, progress=False,
            options=SimplifyOptions(guard="max_spacing", max_spacing=limit))
    las = laspy.read(out)
    assert s.reached and len(las.points) == s.n_output and las.header.scales[0] == 1e-6
    assert cKDTree(np.c_[las.x, las.y, las.z]).query(X)[0].max() <= limit
    # a store made for a .npy output (the limit as given) is not resumed for a LAS one
    run(path, tmp_path / "o.npy", tile_points=3000, workers=1, store=tmp_path / "st",
        options=SimplifyOptions(guard="max_spacing", max_spacing=limit))
    with pytest.raises(InputError, match="max_spacing_less: the LAS output grid's move here, "
                                         "absent in the store"):
        run(path, out, tile_points=3000, workers=1, store=tmp_path / "st",
            options=SimplifyOptions(guard="max_spacing", max_spacing=limit))
    # a limit the grid's step could break on its own is refused, naming the way out
    with pytest.raises(InputError, match=r"--max-spacing 5e-07 .* \.ply, \.npy"):
        run(path, tmp_path / "p.las", options=SimplifyOptions(guard="max_spacing",
                                                              max_spacing=5e-7))


def test_a_short_run_says_why_as_the_core_does(bunny, tmp_path):
    """A run that cannot reach its count says what it had to keep: boundary points, and
    points the max_spacing guard vetoed — it blamed boundary points alone, even where there
    were none (a plate under the guard: 1,204 kept for 300, 0 boundary); the advice names
    what kept the most first, and nothing for a cause that kept none."""
    from tiledsimplify import SimplifyOptions
    rng = np.random.default_rng(7)
    plate = np.c_[rng.random((30000, 2)) * 30, np.zeros(30000)]
    np.save(tmp_path / "plate.npy", plate)
    s = run(tmp_path / "plate.npy", tmp_path / "o.npy", count=300, tile_points=5000,
            options=SimplifyOptions(guard="max_spacing", max_spacing=0.6))
    assert not s.reached and s.n_tiles >= 4 and s.n_boundary == 0
    assert s.message == (f"asked to keep 300 of 30000 points, but {s.n_output} must be kept (0 "
                         f"boundary; {s.n_output} vetoed by the max_spacing guard): kept "
                         f"{s.n_output}. Raise the target, or raise options.max_spacing.")
    X, path = bunny
    s = run(path, tmp_path / "b.npy", count=10, tile_points=3000,
            options=SimplifyOptions(edge_share=float("inf")))  # every flagged point kept
    # (and the smooth folds' points: features, sure as the flags are, not flagged)
    assert not s.reached and s.n_output >= s.n_boundary > 10
    assert s.message == (f"asked to keep 10 of {len(X)} points, but {s.n_output} must be kept "
                         f"({s.n_output} boundary): kept {s.n_output}. Raise the target, or "
                         "give options.edge_share a share of the count (such as 0.5) to keep "
                         "only that many boundary points for certain, or raise "
                         "options.boundary_threshold to flag fewer.")
    # by default the flagged points are sure of 0.4 of the count at most: it is reached
    s = run(path, tmp_path / "c.npy", count=10, tile_points=3000)
    assert s.reached and s.n_output == 10 and s.message == ""


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as c, distributed.Client(c) as client:
        yield client


def test_same_output_for_every_scheduler(bunny, tmp_path, cluster, caplog):
    X, path = bunny
    outs = {}
    for name, kw in [("threads", {"scheduler": "threads", "workers": 2}),
                     ("synchronous", {"scheduler": "synchronous"}),
                     ("processes", {"scheduler": "processes", "workers": 2}),
                     ("cluster", {"client": cluster}),
                     ("address", {"scheduler": cluster.scheduler.address})]:
        out = tmp_path / f"{name}.npy"
        caplog.clear()
        with caplog.at_level("INFO", logger="tiledsimplify"):
            s = run(path, out, ratio=0.15, tile_points=1500, **kw)
        assert s.refined
        outs[name] = out.read_bytes()
        # one log line per finished tile, in this process whatever runs the tiles; a summary
        # only our own records: distributed logs at INFO too, from its own threads, and a
        # "Close client connection" line can land after the summary
        lines = [r.getMessage() for r in caplog.records
                 if r.name.startswith("tiledsimplify")]
        tiles = [m for m in lines if m.startswith("tile ")]
        assert len(tiles) == s.n_tiles + s.n_deeper, (name, lines)
        assert lines[-1].startswith(f"kept {s.n_output} of {s.n_input} points"), lines[-1]
    assert len(set(outs.values())) == 1


@pytest.mark.parametrize("workers, scheduler", [(1, "threads"), (2, "threads"),
                                               (1, "processes")])
def test_tiles_start_largest_first_and_refine_after_their_earlier_neighbours(
        bunny, tmp_path, caplog, workers, scheduler):
    # longest processing time first: with one worker the tiles finish in the order they
    # start, which must be largest first (the key names steer dask's order); a refined tile
    # is logged after every neighbour of an earlier phase, whose flags it reads
    from tiledsimplify.pipeline.tile_refine import refine_phases
    X, path = bunny
    store = tmp_path / "store"
    with caplog.at_level("INFO", logger="tiledsimplify"):
        s = run(path, tmp_path / "out.npy", ratio=0.2, tile_points=700, store=store,
                workers=workers, scheduler=scheduler)
    ts = TileStore.open(store)
    counts = ts.tile_counts
    assert s.refined and ts.n_tiles >= 8 and len(set(counts.tolist())) > 2
    lines = [r.getMessage() for r in caplog.records]
    done = [int(m.split()[1]) for m in lines if m.startswith("tile ")]
    refined = [int(m.split()[2]) for m in lines if m.startswith("refined tile ")]
    assert sorted(done) == sorted(refined) == list(range(ts.n_tiles))
    if workers == 1:
        assert list(counts[done]) == sorted(counts[done], reverse=True), (done, counts)
    phase = refine_phases(ts.plan, ts.halo)
    at = {t: k for k, t in enumerate(refined)}
    for i in range(ts.n_tiles):
        for j in ts.neighbours(i):
            if phase[j] < phase[i]:
                assert at[j] < at[i], (i, j, refined)


def test_cut_hausdorff_is_the_largest_core_gap_under_the_cut(bunny, tmp_path):
    # each tile's gap under the global cut, against brute force over its core and halo
    from tiledsimplify.pipeline import tile_refine
    _, path = bunny
    store = tmp_path / "store"
    assert run(path, tmp_path / "out.npy", ratio=0.2, tile_points=1500, store=store).refined
    ts = TileStore.open(store)
    cut, _ = tile_refine._cut(ts)
    gaps = []
    for i in range(ts.n_tiles):
        xyz, keep, n_core = tile_refine._view(ts, i, cut)
        d = np.linalg.norm(xyz[:n_core, None, :] - xyz[keep][None, :, :], axis=2).min(axis=1)
        got = tile_refine.cut_hausdorff(str(store), i)["hausdorff"]
        assert got == pytest.approx(d.max(), rel=1e-12)
        gaps.append(got)
    assert max(gaps) == ts.run_attrs["cut_hausdorff"] > 0


def test_tiles_measure_their_own_gaps_while_refining(bunny, tmp_path, monkeypatch, caplog):
    # where the cut's gaps are expected within the halo each tile measures its own gap under
    # the cut in the refinement (no pass of gap tasks before it): the same output and G as
    # the two passes, each tile's saved gap that of cut_hausdorff; a resumed run with tiles
    # and G missing measures the missing ones again
    import importlib

    from tiledsimplify.pipeline import tile_refine
    run_module = importlib.import_module("tiledsimplify.pipeline.run")
    _, path = bunny
    calls = []
    real = run_module.cut_hausdorff
    monkeypatch.setattr(run_module, "cut_hausdorff",
                        lambda *a, **k: calls.append(a[1]) or real(*a, **k))
    for ratio in (0.2, 0.1):
        kw = {"ratio": ratio, "tile_points": 700, "progress": False}
        monkeypatch.setattr(tile_refine, "GAP_SPACINGS", 1e9)  # never expected: two passes
        run(path, tmp_path / "two.npy", store=tmp_path / f"two{ratio}", **kw)
        assert len(calls) >= 8
        calls.clear()
        monkeypatch.setattr(tile_refine, "GAP_SPACINGS", 3.0)
        store = tmp_path / f"one{ratio}"
        with caplog.at_level("INFO", logger="tiledsimplify"):
            s = run(path, tmp_path / "one.npy", store=store, **kw)
        assert s.refined and not calls
        assert not [r for r in caplog.records if "beyond the halo" in r.getMessage()]
        assert (tmp_path / "one.npy").read_bytes() == (tmp_path / "two.npy").read_bytes()
        ts, two = TileStore.open(store), TileStore.open(tmp_path / f"two{ratio}")
        g = ts.run_attrs["cut_hausdorff"]
        assert g == two.run_attrs["cut_hausdorff"] > 0 and ts.n_tiles >= 8
        phase = tile_refine.refine_phases(ts.plan, ts.halo)
        assert phase.max() >= 2  # tiles with earlier neighbours: gaps from a band of faces
        gaps = [tile_refine.refined_gap(ts, i) for i in range(ts.n_tiles)]
        assert gaps == [real(str(store), i)["hausdorff"] for i in range(ts.n_tiles)]
        assert max(gaps) == g
    # resumed: two tiles' flags and G missing
    import zarr
    for t in (1, 2):
        del zarr.open_group(str(store), mode="r+")[f"tiles/{t}/refined"]
    ts.set_run_attrs({"cut_hausdorff": None})
    caplog.clear()
    with caplog.at_level("INFO", logger="tiledsimplify"):
        run(path, tmp_path / "again.npy", store=store, **kw)
    assert sorted(int(r.getMessage().split()[2]) for r in caplog.records
                  if r.getMessage().startswith("refined tile ")) == [1, 2]
    assert (tmp_path / "again.npy").read_bytes() == (tmp_path / "one.npy").read_bytes()
    assert TileStore.open(store).run_attrs["cut_hausdorff"] == g and not calls
    # expected within a default halo (10 spacings) from 9 % kept
    assert tile_refine.gaps_expected_within(10.0, 1.0, 0.2)
    assert tile_refine.gaps_expected_within(10.0, 1.0, 0.09)
    assert not tile_refine.gaps_expected_within(10.0, 1.0, 0.05)
    assert not tile_refine.gaps_expected_within(10.0, 0.0, 0.2)


def test_each_tiles_kept_flags_are_read_once_per_cut(bunny, tmp_path, monkeypatch):
    # both passes read a tile's kept flags for its own view and its neighbours' views; a
    # process reads each once per cut, and a run leaves no cached flags behind
    from tiledsimplify.pipeline import tile_refine
    _, path = bunny
    store = tmp_path / "store"
    assert run(path, tmp_path / "out.npy", ratio=0.2, tile_points=1500, store=store).refined
    assert not tile_refine._kept_cache
    reads = []
    real = TileStore.read_result
    monkeypatch.setattr(TileStore, "read_result",
                        lambda self, t, name: reads.append((t, name)) or real(self, t, name))
    ts = TileStore.open(store)
    cut, _ = tile_refine._cut(ts)
    for i in range(ts.n_tiles):
        tile_refine._view(ts, i, cut)
    assert ts.n_tiles >= 8 and sorted(reads) == [(i, "step") for i in range(ts.n_tiles)]
    for i in range(ts.n_tiles):
        step = real(ts, i, "step")
        got = tile_refine._kept(ts, i, cut)
        np.testing.assert_array_equal(got, (step < 0) | (step >= cut[i]))
        assert not got.flags.writeable
    assert len(reads) == ts.n_tiles
    ts.set_run_attrs({"cut_key": "another cut"})  # another cut: read again
    tile_refine._kept(TileStore.open(store), 0, cut)
    assert len(reads) == ts.n_tiles + 1
    # the least recently used go beyond the byte limit (here: one tile's flags)
    tile_refine.clear_kept()
    monkeypatch.setattr(tile_refine, "KEPT_CACHE_BYTES", 1)
    for i in (0, 1, 0):
        tile_refine._kept(ts, i, cut)
    assert len(tile_refine._kept_cache) == 1 and len(reads) == ts.n_tiles + 4
    tile_refine.clear_kept()


def test_a_cut_wider_than_the_halo_is_refined_in_views_that_wide(bunny, tmp_path,
                                                                  monkeypatch, caplog):
    """At small ratios the cut leaves gaps wider than the halo (by default 10 spacings; the
    1M-point scan of benchmarks/speed.py at 5 %: 12.2), and the run skipped the gap refinement
    with a warning — at 5 % its Hausdorff distance was 0.0423 instead of 0.0295 refined. Now
    each tile refines in a view as wide as the cut's Hausdorff distance G or a bound of it (the
    largest gap measured in views the halo wide, read from the neighbours' cores): refined,
    never above G, the same for any scheduler. Here a halo of 2.5 spacings stands for the
    small ratio."""
    from scipy.spatial import cKDTree

    from tiledsimplify.pipeline import tile_refine
    from tiledsimplify.synthetic import spacing
    X, path = bunny
    halo = 2.5 * spacing(X)
    kw = {"ratio": 0.2, "tile_points": 1500, "halo": halo, "progress": False}
    store = tmp_path / "st"
    s = run(path, tmp_path / "a.npy", store=store, **kw)
    ts = TileStore.open(store)
    g = ts.run_attrs["cut_hausdorff"]
    assert s.reached and s.refined and ts.n_tiles >= 4 and ts.halo < g
    assert g < tile_refine.MAX_WIDTH * ts.halo

    def gap(name):
        out = np.load(tmp_path / name)
        return cKDTree(np.c_[out["x"], out["y"], out["z"]]).query(X)[0].max()
    cut = run(path, tmp_path / "cut.npy", options={"refine": False}, **kw)
    assert cut.n_output == s.n_output and not cut.refined
    assert ts.run_attrs["cut_hausdorff_bound"]
    assert ts.halo < gap("cut.npy") <= g * (1 + 1e-12)  # G, or a bound of it: never below
    assert gap("a.npy") < 0.9 * gap("cut.npy")
    run(path, tmp_path / "b.npy", scheduler="synchronous", **kw)
    assert (tmp_path / "a.npy").read_bytes() == (tmp_path / "b.npy").read_bytes()
    # views read with their points by owner and row (TileStore.near_points), as before by
    # global index: the same output
    def by_index(store, tile, width=None):
        halo_xyz, _, owner, row = store.halo_points(tile, width, owners=True)
        core_xyz = store.core_xyz(tile)
        return np.concatenate([core_xyz, halo_xyz]), len(core_xyz), owner, row
    with monkeypatch.context() as m:
        m.setattr(tile_refine, "_view_points", by_index)
        run(path, tmp_path / "d.npy", scheduler="synchronous", **kw)
    assert (tmp_path / "a.npy").read_bytes() == (tmp_path / "d.npy").read_bytes()
    # the gaps expected within the halo, wrongly: the tiles measure them while refining, find
    # some beyond, and the run measures G and refines every tile again, as above
    # (the gaps the tiles measured are not measured again)
    monkeypatch.setattr(tile_refine, "GAP_SPACINGS", 0.0)
    import importlib
    run_module = importlib.import_module("tiledsimplify.pipeline.run")
    real, measured = run_module.cut_hausdorff, []
    monkeypatch.setattr(run_module, "cut_hausdorff",
                        lambda *a: measured.append(a[1]) or real(*a))
    for scheduler in ("threads", "processes"):
        caplog.clear()
        measured.clear()
        with caplog.at_level("INFO", logger="tiledsimplify"):
            run(path, tmp_path / "c.npy", store=tmp_path / scheduler, scheduler=scheduler,
                **kw)
        assert (tmp_path / "a.npy").read_bytes() == (tmp_path / "c.npy").read_bytes()
        lines = [r.getMessage() for r in caplog.records]
        assert [m for m in lines if "lies beyond the halo (" in m], lines
        assert TileStore.open(tmp_path / scheduler).run_attrs["cut_hausdorff"] == g
        if scheduler == "threads":  # (the processes' calls are not seen here)
            assert 0 < len(measured) < ts.n_tiles and len(set(measured)) == len(measured)
    # no view wider than MAX_WIDTH halos is read: then no refinement, as before
    assert tile_refine.refine_width(1.0, 0.5) == 1.0 and tile_refine.refine_width(1.0, 2.5) == 2.5
    assert tile_refine.refine_width(1.0, tile_refine.MAX_WIDTH + 0.1) is None
    assert tile_refine.refine_width(1.0, np.inf) is None


def test_resume_finishes_the_remaining_tiles(bunny, tmp_path, caplog):
    X, path = bunny
    store = tmp_path / "store"
    full = tmp_path / "full.npy"
    assert run(path, full, ratio=0.2, tile_points=1500, store=store).refined
    # a second run on the finished store refines nothing again and writes the same output
    again = tmp_path / "again.npy"
    with caplog.at_level("INFO", logger="tiledsimplify"):
        run(path, again, ratio=0.2, tile_points=1500, store=store)
    assert not [r for r in caplog.records if r.getMessage().startswith("refined tile")]
    assert again.read_bytes() == full.read_bytes()
    # interrupted during the refinement: some tiles have no refined flags yet
    import zarr
    for t in (1, 2):
        del zarr.open_group(str(store), mode="r+")[f"tiles/{t}/refined"]
    run(path, again, ratio=0.2, tile_points=1500, store=store)
    assert again.read_bytes() == full.read_bytes()
    # an interrupted run: some tiles have no (finished) result
    for t in (0, 3, 5):
        del zarr.open_group(str(store), mode="r+")[f"tiles/{t}/result"]
    assert len(TileStore.open(store).pending_tiles()) == 3
    resumed = tmp_path / "resumed.npy"
    run(path, resumed, ratio=0.2, tile_points=1500, store=store)
    assert resumed.read_bytes() == full.read_bytes()
    # the same store for other settings is refused, with the fix in the message
    with pytest.raises(ValueError, match="new --store"):
        run(path, tmp_path / "x.npy", ratio=0.2, tile_points=999, store=store)


def test_las_end_to_end_keeps_every_dimension(data_dir, tmp_path):
    src = data_dir / "lidar" / "autzen_trim.laz"
    out = tmp_path / "out.laz"
    s = run(src, out, ratio=0.5, tile_points=30000)
    assert s.reached
    a, b = laspy.read(src), laspy.read(out)
    assert len(b.points) == round(0.5 * len(a.points))
    assert b.header.point_format.id == a.header.point_format.id
    np.testing.assert_array_equal(b.header.scales, a.header.scales)
    np.testing.assert_array_equal(b.header.offsets, a.header.offsets)
    names = set(b.point_format.dimension_names)
    assert set(a.point_format.dimension_names) <= names
    assert {"sharp_edge", "importance", "simplify_rank"} <= names
    # every output record is an input record, attributes intact
    ka = np.stack([a.X, a.Y, a.Z, a.gps_time * 1e6], 1)
    kb = np.stack([b.X, b.Y, b.Z, b.gps_time * 1e6], 1)
    ia = {tuple(r): i for i, r in enumerate(ka)}
    rows = [ia[tuple(r)] for r in kb]
    for dim in ("intensity", "classification", "red", "green", "blue", "return_number"):
        np.testing.assert_array_equal(np.asarray(b[dim]), np.asarray(a[dim])[rows])
    assert int(np.asarray(b["sharp_edge"]).sum()) == s.n_boundary


def test_las_ingested_in_parts_by_the_workers_gives_the_same_output(data_dir, tmp_path,
                                                                   cluster, caplog,
                                                                   monkeypatch):
    import importlib
    run_module = importlib.import_module("tiledsimplify.pipeline.run")
    src = data_dir / "lidar" / "autzen_trim.laz"
    kw = dict(ratio=0.3, tile_points=30000, chunk_points=20_000)
    base = run(src, tmp_path / "one.laz", scheduler="synchronous", **kw)
    monkeypatch.setattr(run_module, "INGEST_PART_POINTS", 20_000)
    monkeypatch.setattr(run_module, "INGEST_PARTS_FROM", 2)
    for name, extra in [("threads", {"scheduler": "threads", "workers": 4}),
                        ("cluster", {"client": cluster})]:
        caplog.clear()
        with caplog.at_level("INFO", logger="tiledsimplify"):
            s = run(src, tmp_path / f"{name}.laz", **kw, **extra)
        assert any("6 parts read at once" in r.getMessage() for r in caplog.records), name
        assert s.n_output == base.n_output
        assert (tmp_path / f"{name}.laz").read_bytes() == (tmp_path / "one.laz").read_bytes()


def test_laz_compressed_by_the_workers_is_the_synchronous_runs_file(data_dir, tmp_path,
                                                                    cluster):
    """On a cluster the workers pack and compress the LAZ output's chunks, those straddling
    tiles too (``output._write_laz_chunks``): 55,000 points kept from tiles of ~15,000, so
    chunks of 50,000 span several tiles; the file is the synchronous run's, byte for byte."""
    src = data_dir / "lidar" / "autzen_trim.laz"
    kw = {"ratio": 0.5, "tile_points": 30000}
    base = run(src, tmp_path / "one.laz", scheduler="synchronous", **kw)
    s = run(src, tmp_path / "cluster.laz", client=cluster, **kw)
    assert s.n_tiles >= 4 and s.n_output == base.n_output == 55_000
    assert (tmp_path / "cluster.laz").read_bytes() == (tmp_path / "one.laz").read_bytes()
    with laspy.open(tmp_path / "cluster.laz") as reader:
        reader.seek(50_001)  # in the second chunk
        assert len(reader.read_points(10)) == 10


def test_npy_ingested_in_parts_gives_the_same_output(bunny, tmp_path, caplog, monkeypatch):
    import importlib
    run_module = importlib.import_module("tiledsimplify.pipeline.run")
    X, path = bunny  # a plain (n, 3) NPY: memory-mapped, cut in parts
    kw = dict(ratio=0.15, tile_points=1500, chunk_points=1000)
    run(path, tmp_path / "one.npy", scheduler="synchronous", **kw)
    monkeypatch.setattr(run_module, "INGEST_PART_POINTS", 2000)
    monkeypatch.setattr(run_module, "INGEST_PARTS_FROM", 2)
    with caplog.at_level("INFO", logger="tiledsimplify"):
        run(path, tmp_path / "parts.npy", scheduler="processes", workers=2, **kw)
    assert any(f"{-(-len(X) // 2000)} parts read at once" in r.getMessage()
               for r in caplog.records)
    assert (tmp_path / "parts.npy").read_bytes() == (tmp_path / "one.npy").read_bytes()


@pytest.mark.parametrize("suffix", [".laz", ".las"])
def test_las_output_of_a_non_las_input(bunny, tmp_path, suffix):
    from scipy.spatial import cKDTree
    X, path = bunny
    kw = dict(ratio=0.15, tile_points=3000)
    s = run(path, tmp_path / f"out{suffix}", **kw)
    run(path, tmp_path / "out.npy", **kw)
    las = laspy.read(tmp_path / f"out{suffix}")
    assert (las.header.version.major, las.header.version.minor) == (1, 4)
    assert las.header.point_format.id == 6 and len(las.points) == s.n_output
    ref = np.load(tmp_path / "out.npy")  # the same kept points, in input order
    got = np.c_[las.x, las.y, las.z]
    scale = float(las.header.scales[0])
    spacing = np.median(cKDTree(X).query(X, k=2)[0][:, 1])
    assert 1e-4 * spacing < scale <= 1e-3 * spacing  # a power of ten
    d, j = cKDTree(np.c_[ref["x"], ref["y"], ref["z"]]).query(got)
    assert d.max() <= scale and np.array_equal(np.sort(j), np.arange(len(ref)))
    np.testing.assert_array_equal(np.asarray(las["sharp_edge"]), ref["sharp_edge"][j])
    assert int(np.asarray(las["sharp_edge"]).sum()) == s.n_boundary
    assert (np.asarray(las.return_number) == 1).all()
    assert (np.asarray(las["simplify_rank"]) == -1).all()


def test_a_text_inputs_whole_columns_are_written_as_integers(tmp_path):
    """A text file's columns are read as float64 (their type is a guess); a PLY or NPY output
    writes one whose values are all whole numbers as the smallest integer type that holds
    them (``Classification`` 0..19 as uint8, ``Label`` -5..299 as int16), the tiled run and
    the in-memory ``simplify`` alike, each value the input's; one beyond int32 (``Big``) or
    with a fraction (``Deviation``) stays float64, and so does an ASCII PLY's declared double
    property of whole numbers. They were all float64 before."""
    from scipy.spatial import cKDTree
    from tiledsimplify.io.points_out import whole_type
    from tiledsimplify.io.sources import read_ply_vertices
    assert [whole_type(*r) for r in [(0, 255), (-1, 127), (0, 256), (-129, 0), (0, 2**32 - 1),
                                     (-1, 2**31 - 1), (0, 2**32)]] == [
        np.uint8, np.int8, np.uint16, np.int16, np.uint32, np.int32, None]
    rng = np.random.default_rng(7)
    n = 4000
    xyz = np.round(np.c_[rng.random((n, 2)), 0.2 * np.abs(rng.random(n) - 0.5)], 6)
    cols = {"Classification": rng.integers(0, 20, n), "Label": rng.integers(-5, 300, n),
            "Big": rng.integers(0, 5_000_000_000, n), "Deviation": np.round(rng.normal(size=n), 4)}
    cols["Label"][:2] = -5, 299
    path = tmp_path / "cc.txt"
    path.write_text("//X,Y,Z," + ",".join(cols) + "\n" + "".join(
        "%.6f,%.6f,%.6f,%d,%d,%d,%.4f\n" % (*p, *v) for p, *v in zip(xyz, *cols.values())))
    want = {"Classification": np.uint8, "Label": np.int16, "Big": np.float64,
            "Deviation": np.float64}
    outputs = [tmp_path / "run.ply", tmp_path / "run.npy", tmp_path / "mem.npy"]
    run(path, outputs[0], ratio=0.2, tile_points=1500)
    run(path, outputs[1], ratio=0.2, tile_points=1500)
    assert main(["simplify", str(path), str(outputs[2]), "--ratio", "0.2", "-q"]) == EXIT_OK
    tree = cKDTree(xyz)
    for out in outputs:
        table = read_ply_vertices(out) if out.suffix == ".ply" else np.load(out)
        d, rows = tree.query(np.c_[table["x"], table["y"], table["z"]])
        assert d.max() == 0 and len(table) == 800, out
        for name, dtype in want.items():
            assert table.dtype[name] == dtype, (out, name)
            np.testing.assert_array_equal(table[name], cols[name][rows])
    # an ASCII PLY's double property holds whole numbers: its declared type stays
    ply = tmp_path / "declared.ply"
    ply.write_text("ply\nformat ascii 1.0\nelement vertex %d\nproperty double x\nproperty "
                   "double y\nproperty double z\nproperty double Classification\nend_header"
                   "\n" % n + "".join("%.6f %.6f %.6f %d\n" % (*p, c)
                                      for p, c in zip(xyz, cols["Classification"])))
    run(ply, tmp_path / "declared.npy", ratio=0.2, tile_points=1500)
    assert np.load(tmp_path / "declared.npy").dtype["Classification"] == np.float64


def test_a_las_output_keeps_every_column_of_a_text_input(tmp_path, cluster):
    """A text file's columns reach a LAS output (:func:`.las_output.carried_layout`): its
    colour as LAS colour (point format 7); its ``Intensity`` and ``Classification`` columns
    of whole numbers (read as float64) in LAS's own, as PDAL would put them, and its
    fractional ``Deviation`` as float64 extra bytes, each value the input's at the kept
    points; here and on a cluster, whose workers pack and compress the LAZ
    (``output._write_laz_chunks``), the same bytes; a ``Classification`` with a -1, which
    LAS's cannot hold, beside it as ``Classification_float64``. Only the colour came through
    before."""
    from scipy.spatial import cKDTree
    rng = np.random.default_rng(5)
    n = 6000
    xyz = np.round(np.c_[rng.random((n, 2)), 0.2 * np.abs(rng.random(n) - 0.5)], 6)
    rgb = rng.integers(0, 256, (n, 3))
    inten, cls = rng.integers(0, 1000, n), rng.integers(0, 20, n)
    dev = np.round(rng.normal(size=n), 4)
    path = tmp_path / "cc.txt"
    path.write_text("//X,Y,Z,R,G,B,Intensity,Classification,Deviation\n" + "".join(
        "%.6f,%.6f,%.6f,%d,%d,%d,%d,%d,%.4f\n" % (*p, *c, i, k, d)
        for p, c, i, k, d in zip(xyz, rgb, inten, cls, dev)))
    kw = dict(ratio=0.2, tile_points=2000)
    run(path, tmp_path / "here.laz", **kw)
    run(path, tmp_path / "cluster.laz", client=cluster, **kw)
    assert (tmp_path / "here.laz").read_bytes() == (tmp_path / "cluster.laz").read_bytes()
    las = laspy.read(tmp_path / "here.laz")
    assert las.header.point_format.id == 7 and len(las.points) == 1200
    assert list(las.point_format.extra_dimension_names) == [
        "Deviation", "sharp_edge", "importance", "simplify_rank"]
    d, rows = cKDTree(xyz).query(np.c_[las.x, las.y, las.z])
    assert d.max() < float(np.linalg.norm(las.header.scales))  # quantised to the grid
    assert len(np.unique(rows)) == 1200
    for j, c in enumerate(("red", "green", "blue")):
        np.testing.assert_array_equal(np.asarray(las[c]), 257 * rgb[rows, j])
    np.testing.assert_array_equal(np.asarray(las.intensity), inten[rows])
    np.testing.assert_array_equal(np.asarray(las.classification), cls[rows])
    np.testing.assert_array_equal(las["Deviation"], dev[rows])
    # one value that LAS's classification cannot hold: the column keeps its own type
    lines = path.read_text().splitlines()
    first = lines[1].split(",")
    first[7] = "-1"
    path.write_text("\n".join([lines[0], ",".join(first)] + lines[2:]) + "\n")
    run(path, tmp_path / "minus.laz", ratio=1.0, tile_points=2000)
    las = laspy.read(tmp_path / "minus.laz")
    assert list(las.point_format.extra_dimension_names)[:2] == [
        "Classification_float64", "Deviation"]
    d, rows = cKDTree(xyz).query(np.c_[las.x, las.y, las.z])
    want = cls[rows].astype(float)
    want[rows == 0] = -1
    np.testing.assert_array_equal(las["Classification_float64"], want)
    assert not np.asarray(las.classification).any()


def test_integers_a_las_dimension_cannot_hold_keep_their_own_type(tmp_path):
    """A structured NPY's int32 ``classification`` of -1 .. 40 in a LAS output: LAS's uint8
    classification cannot hold -1, so the values go to ``classification_int32`` (by the
    range the ingest recorded, :attr:`.TileStore.attribute_range`) and the standard one
    stays 0; its uint16 ``intensity`` fits and goes there. The run used to fail at its very
    end, the work done: "dimension 'classification' (uint8) cannot hold values -1 .. 40"."""
    from scipy.spatial import cKDTree
    rng = np.random.default_rng(3)
    n = 5000
    t = np.zeros(n, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("classification", "i4"),
                           ("intensity", "u2")])
    t["x"], t["y"] = rng.random(n), rng.random(n)
    t["z"] = 0.1 * np.sin(6 * t["x"])
    t["classification"] = rng.integers(-1, 41, n)
    t["intensity"] = rng.integers(0, 60000, n)
    np.save(tmp_path / "in.npy", t)
    s = run(tmp_path / "in.npy", tmp_path / "out.laz", ratio=0.2, tile_points=2000)
    las = laspy.read(tmp_path / "out.laz")
    assert len(las.points) == s.n_output == 1000
    assert list(las.point_format.extra_dimension_names)[0] == "classification_int32"
    xyz = np.c_[t["x"], t["y"], t["z"]]
    d, rows = cKDTree(xyz).query(np.c_[las.x, las.y, las.z])
    assert d.max() < float(np.linalg.norm(las.header.scales))
    np.testing.assert_array_equal(las["classification_int32"], t["classification"][rows])
    np.testing.assert_array_equal(np.asarray(las.intensity), t["intensity"][rows])
    assert not np.asarray(las.classification).any()


def test_more_dimensions_than_las_holds_are_refused_before_the_tiles(tmp_path, caplog):
    """A structured NPY of 400 float32 features (an ML pipeline's) to LAZ: a LAS file
    describes at most 341 extra-bytes dimensions (its Extra Bytes VLR holds 65,535 bytes),
    and laspy failed only when writing the file, after every tile. Now the run stops after
    the ingest, naming the output and the fix, before any tile runs; a .npy output takes
    them all."""
    import logging
    rng = np.random.default_rng(8)
    n = 3000
    t = np.zeros(n, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")]
                 + [(f"feature_{i}", "f4") for i in range(400)])
    t["x"], t["y"] = rng.random(n), rng.random(n)
    for i in range(400):
        t[f"feature_{i}"] = i
    np.save(tmp_path / "in.npy", t)
    caplog.set_level(logging.INFO, logger="tiledsimplify")
    with pytest.raises(InputError, match=r"out\.laz: a LAS file describes at most 341 "
                                         r"extra-bytes dimensions.*would need 403"):
        run(tmp_path / "in.npy", tmp_path / "out.laz", ratio=0.2, tile_points=1000)
    assert not (tmp_path / "out.laz").exists()
    assert not any(" removals (up to level" in r.getMessage() for r in caplog.records)
    run(tmp_path / "in.npy", tmp_path / "out.npy", ratio=0.2, tile_points=1000)
    out = np.load(tmp_path / "out.npy")
    assert out.dtype.names[3:403] == t.dtype.names[3:] and (out["feature_399"] == 399).all()


def test_cli_run_with_config(bunny, tmp_path, caplog):
    X, path = bunny
    cfg = tmp_path / "c.toml"
    cfg.write_text("[run]\nratio = 0.3\ntile_points = 2000\nfloor = 0.3\n"
                   "[simplify]\nmode = 'paper'\n")
    out = tmp_path / "o.npy"
    assert main(["run", str(path), str(out), "--config", str(cfg), "--no-progress", "-q"]) \
        == EXIT_OK
    assert len(np.load(out)) == round(0.3 * len(X))
    assert main(["run", str(path), str(out), "--count", "4000", "--no-progress", "-q",
                 "--tile-points", "3000", "--floor", "0.9"]) == EXIT_OK
    assert len(np.load(out)) == 4000
    assert main(["run", str(path), str(out), "--count", "4000", "-q", "--floor", "1.5"]) == 2
    bad = tmp_path / "bad.toml"
    bad.write_text("[runn]\nratio = 0.3\n")
    assert main(["run", str(path), str(out), "--config", str(bad), "-q"]) == 2
    bad.write_text("[simplify]\nedge_width = 'wide'\n")  # a wrong type names file and key
    with caplog.at_level("ERROR", logger="tiledsimplify"):
        assert main(["run", str(path), str(out), "--ratio", "0.3", "--config", str(bad),
                     "-q"]) == 2
    assert "bad.toml: [simplify] options.edge_width must be a number, got 'wide'" in caplog.text
    bad.write_text("[run]\nworkers = 'two'\n")
    with caplog.at_level("ERROR", logger="tiledsimplify"):
        assert main(["run", str(path), str(out), "--ratio", "0.3", "--config", str(bad),
                     "-q"]) == 2
    assert "bad.toml: [run] workers must be a number, got 'two'" in caplog.text
    with pytest.raises(InputError, match="tile_points must be a whole number, got 2.5"):
        run(path, out, ratio=0.3, tile_points=2.5)  # not 2-point tiles


@pytest.mark.parametrize("kw,message", [
    ({"options": "paper"}, "options must be a SimplifyOptions, a dict"),  # AttributeError
    ({"options": [("mode", "paper")]}, "options must be a SimplifyOptions"),
    ({"chunk_points": 0}, "chunk_points must be at least 1"),  # range() arg 3 must not be 0
    ({"chunk_points": -1}, "chunk_points must be at least 1"),  # "the input has no points"
    ({"chunk_points": float("nan")}, "chunk_points must be a whole number"),  # ValueError
    ({"halo": "wide"}, "halo must be a distance"),  # could not convert string to float
    ({"halo": "1"}, "halo must be a distance"),  # ran, a str in the store's settings
])
def test_run_names_a_bad_argument(tmp_path, kw, message):
    """``run``'s options, chunk_points and halo were used unchecked: a string for options failed
    with "'str' object has no attribute 'guard'", chunk_points=0 with "range() arg 3 must not
    be zero" and -1 with "the input has no points" — nothing naming the argument."""
    path = tmp_path / "in.npy"
    np.save(path, np.random.default_rng(0).random((300, 3)))
    with pytest.raises(InputError, match=message):
        run(path, tmp_path / "out.npy", ratio=0.3, scheduler="synchronous", **kw)
    assert not (tmp_path / "out.npy").exists()


@pytest.mark.parametrize("case", ["bunny", "fandisk_scan"])
def test_tiles_do_not_show(case, bunny, data_dir, tmp_path):
    from tiledsimplify import metrics, synthetic
    from tiledsimplify.io import read_mesh
    if case == "bunny":
        X, path = read_points(data_dir / "meshes" / "stanford_bunny" / "bun_zipper.ply.gz"), None
        ratio, tile_points = 0.1, 6000
    else:
        V, F = read_mesh(data_dir / "meshes" / "cad_classic" / "fandisk.obj")
        P, _ = synthetic.scan(V, F, n_points=40000, seed=1)
        X = synthetic.scan(V, F, n_points=40000, noise=0.1 * synthetic.spacing(P), seed=1)[0]
        ratio, tile_points = 0.3, 6000
    path = tmp_path / "in.npy"
    np.save(path, X)
    store = tmp_path / "store"
    s = run(path, tmp_path / "out.npy", ratio=ratio, tile_points=tile_points, store=store)
    assert s.n_tiles >= 8
    ts = TileStore.open(store)
    assert s.refined
    keep_c = kept_mask(ts, store_cut(ts, len(X) - s.target))  # the global cut
    keep_t = refined_mask(ts)  # the output: the cut refined
    opts = {"boundary_threshold": s.threshold, "spacing": s.spacing}
    keep_u = simplify_points(X, ratio=ratio, options=opts).keep  # refined too
    keep_uc = simplify_points(X, ratio=ratio, options={**opts, "refine": False}).keep
    assert keep_t.sum() == keep_c.sum() == keep_u.sum()
    band = ts.plan.face_distance(X) < 2 * metrics.spacing(X)
    density_cut = keep_c[band].mean() / keep_uc[band].mean()
    density = keep_t[band].mean() / keep_u[band].mean()
    err_t = metrics.surface_error(X, keep_t)[0]
    err_u = metrics.surface_error(X, keep_u)[0]
    from scipy.spatial import cKDTree
    haus_t = float(cKDTree(X[keep_t]).query(X)[0].max())
    haus_u = float(cKDTree(X[keep_u]).query(X)[0].max())  # both refined
    print(f"{case}: band density tiled/untiled cut {density_cut:.3f}, refined {density:.3f}; "
          f"mean error {err_t / err_u:.3f}, Hausdorff {haus_t / haus_u:.3f}")
    assert 0.9 <= density_cut <= 1.1
    # refined in phases, a gap across a face is filled once and faces are thinned like the
    # interior (refined concurrently with a frozen band at faces: Bunny 1.17)
    assert 0.9 <= density <= 1.1
    assert err_t <= 1.05 * err_u
    if case == "bunny":
        assert haus_t <= 1.15 * haus_u
    if case == "fandisk_scan":
        sp = metrics.spacing(X)
        edges = synthetic.sample_edges(V, F, sp)
        cov_t = metrics.edge_coverage(X, keep_t, edges, sp)
        cov_u = metrics.edge_coverage(X, keep_u, edges, sp)
        print(f"edge coverage tiled {cov_t:.3f} untiled {cov_u:.3f}")
        assert cov_t >= 0.95 * cov_u


def test_tiles_keep_their_features_within_the_edge_cover_radius(data_dir, tmp_path):
    # each tile's refinement covers its feature core points (the flags' edges and smooth
    # folds: what is kept like an edge) as the untiled core does
    from scipy.spatial import cKDTree

    from tiledsimplify import synthetic
    from tiledsimplify.core.refine import edge_cover_radius
    from tiledsimplify.io import read_mesh
    V, F = read_mesh(data_dir / "meshes" / "cad_classic" / "fandisk.obj")
    X, _ = synthetic.sample_surface_even(V, F, 16475, seed=0, tol=0.001)
    path = tmp_path / "in.npy"
    np.save(path, X)
    store = tmp_path / "store"
    s = run(path, tmp_path / "out.npy", ratio=0.2, tile_points=3000, store=store)
    ts = TileStore.open(store)
    assert s.refined and ts.n_tiles >= 8
    flags = np.zeros(len(X), dtype=bool)
    for i in range(ts.n_tiles):
        flags[ts.core(i)[1]] = ts.read_result(i, "feature")
    radius = edge_cover_radius(s.spacing, 0.2)
    near = {name: np.mean(cKDTree(X[keep]).query(X[flags])[0] <= radius)
            for name, keep in (("tiled", refined_mask(ts)),
                               ("cut", kept_mask(ts, store_cut(ts, len(X) - s.target))))}
    print(f"flags within the cover radius: {near}")  # 2026-12-05: 1.0 and 0.991
    assert near["tiled"] == 1.0 and near["cut"] < 1.0


def test_killed_run_resumes_to_the_same_output(bunny, tmp_path):
    import signal
    import subprocess
    import sys
    import time

    from tiledsimplify.tiles import StoreError
    X, path = bunny
    args = [str(path), None, "--ratio", "0.2", "--tile-points", "800", "--scheduler",
            "synchronous", "--no-progress", "-q"]
    clean = tmp_path / "clean.npy"
    assert main(["run", *[str(clean) if a is None else a for a in args]]) == EXIT_OK
    store = tmp_path / "store"
    out = tmp_path / "resumed.npy"
    cmd = [sys.executable, "-m", "tiledsimplify", "run",
           *[str(out) if a is None else a for a in args], "--store", str(store)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.time() + 300
        while time.time() < deadline and proc.poll() is None:
            try:
                if len(TileStore.open(store).done_tiles()) >= 2:
                    break
            except (StoreError, FileNotFoundError, ValueError, KeyError):
                pass
            time.sleep(0.2)
        assert proc.poll() is None, "the run finished before it could be killed"
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
    ts = TileStore.open(store)
    assert 0 < len(ts.done_tiles()) < ts.n_tiles and not out.exists()
    assert subprocess.run(cmd).returncode == EXIT_OK
    assert out.read_bytes() == clean.read_bytes()


def test_refine_phases_never_put_neighbours_together():
    from tiledsimplify.pipeline.tile_refine import refine_phases
    from tiledsimplify.tiles.partition import plan_tiles
    rng = np.random.default_rng(3)
    X = rng.random((20000, 3)) * [4.0, 2.0, 1.0]
    plan = plan_tiles(X, len(X), 500, halo=0.05)
    phase = refine_phases(plan, 0.05)
    assert plan.n_tiles >= 30 and len(phase) == plan.n_tiles
    degree = np.array([len(plan.neighbours(i, 0.05)) for i in range(plan.n_tiles)])
    first = np.lexsort((np.arange(plan.n_tiles), -degree))  # most neighbours first, by index
    at = np.empty(plan.n_tiles, dtype=np.int64)
    at[first] = np.arange(plan.n_tiles)
    assert degree.min() < degree.max() and phase[first[0]] == 0
    for i in range(plan.n_tiles):
        nbrs = plan.neighbours(i, 0.05)
        assert (phase[nbrs] != phase[i]).all()
        # greedy in that order: each tile takes the lowest phase its neighbours coloured
        # before it leave free
        used = set(phase[nbrs[at[nbrs] < at[i]]].tolist())
        assert phase[i] == min(set(range(len(used) + 1)) - used)
    assert phase.max() + 1 < plan.n_tiles / 2  # phases stay few: tiles refine in parallel
    np.testing.assert_array_equal(phase, refine_phases(plan, 0.05))


def test_default_tile_size_is_an_eighth_of_the_input_within_bounds(bunny, tmp_path):
    from tiledsimplify.pipeline.run import default_tile_points
    assert default_tile_points(1_000_000) == 125_000
    assert default_tile_points(999_999) == 125_000
    assert default_tile_points(50_000) == 100_000
    assert default_tile_points(10_000_000) == 500_000
    X, path = bunny
    store = tmp_path / "store"
    s = run(path, tmp_path / "out.npy", ratio=0.2, store=store)  # small: one tile
    ts = TileStore.open(store)
    assert s.n_tiles == 1 and ts.config["tile_points"] == 100_000


def test_ingest_logs_its_progress(bunny, tmp_path, caplog):
    """A line each time a pass over the input crosses a tenth (chunks of 1,000 of the 8,171
    points: nine chunks a pass, each crossing one), naming the pass, the share read (floored,
    so 100 % only once every point is in) and the points."""
    _, path = bunny
    with caplog.at_level("INFO", logger="tiledsimplify"):
        run(path, tmp_path / "o.npy", ratio=0.2, tile_points=3_000, chunk_points=1_000)
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("ingest pass")]
    for k in (1, 2):
        mine = [line for line in lines if line.startswith(f"ingest pass {k} of 2")]
        shares = [int(line.split(": ")[1].split(" %")[0]) for line in mine]
        assert shares == [12, 24, 36, 48, 61, 73, 85, 97, 100], mine  # 1k, 2k, ... of 8,171
        assert mine[-1].split(" in ")[0].endswith("(8,171 of 8,171 points)"), mine[-1]
    assert lines[:9] == [line for line in lines if line.startswith("ingest pass 1")]
    # the plan and the store's layout between the passes have a line of their own, in order
    every = [r.getMessage() for r in caplog.records if r.getMessage().startswith("ingest")]
    planned = [i for i, m in enumerate(every) if m.startswith("ingest: tiles planned and the "
                                                              "store laid out in ")]
    assert planned == [9], every


def test_stage_lines_give_the_share_of_points_done_and_the_time_left(bunny, tmp_path, caplog,
                                                                     monkeypatch):
    import importlib
    P = importlib.import_module("tiledsimplify.pipeline.progress")
    assert [P.duration(s) for s in (0.4, 89, 90, 738, 5399, 5400, 7560)] == [
        "0 s", "89 s", "1.5 min", "12.3 min", "90.0 min", "1.5 h", "2.1 h"]
    clock = iter([100.0, 130.0, 190.0, 250.0])  # the stage starts at 100 s
    monkeypatch.setattr(P.time, "perf_counter", lambda: next(clock))
    said = []
    p = P.Progress("tiles", 3, lambda r, done, total, pace: said.append(pace), False,
                   points=400)
    for n_core in (100, 200, 100):  # the largest tiles first: 1/3 of the tiles, 1/4 of points
        p({"n_core": n_core})
    assert said == ["; 25 % of points in 30 s, ~1.5 min left",
                    "; 75 % of points in 1.5 min, ~30 s left", "; 100 % of points in 2.5 min"]
    monkeypatch.undo()
    # a whole run: every tile and refinement line ends with its share, the last at 100 %
    with caplog.at_level("INFO", logger="tiledsimplify"):
        run(bunny[1], tmp_path / "o.npy", ratio=0.2, tile_points=3_000, workers=2)
    for head in ("tile ", "refined tile "):
        mine = [r.getMessage() for r in caplog.records if r.getMessage().startswith(head)]
        shares = [int(m.split("; ")[1].split(" %")[0]) for m in mine]
        assert len(mine) > 1 and shares == sorted(shares) and shares[-1] == 100, mine
        assert all(" left" in m for m in mine[:-1]) and " left" not in mine[-1], mine


def test_a_target_of_zero_points_keeps_none_without_a_refinement_warning(tmp_path, caplog):
    path = tmp_path / "few.npy"
    np.save(path, np.random.default_rng(3).random((4, 3)))
    with caplog.at_level("INFO", logger="tiledsimplify"):
        summary = run(path, tmp_path / "out.npy", ratio=0.1, workers=1, progress=False)
    assert summary.target == 0 and summary.n_output == 0
    assert len(np.load(tmp_path / "out.npy")) == 0
    # the one warning says the ratio keeps no point; none from the refinement
    warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert warned == [f"{path}: ratio 0.1 of 4 points keeps no point (0.4 rounds to 0): the "
                      "output is empty; ask a larger ratio, or a count"]


def test_a_killed_runs_temporary_files_are_named(tmp_path, caplog):
    # SIGKILL while writing the output left .NAME.*.partial (and .records for text) beside it,
    # as large as the output, and a rerun said nothing of them
    path = tmp_path / "few.npy"
    np.save(path, np.random.default_rng(3).random((40, 3)))
    for name in (".out.xyz.ab12cd.partial", ".out.xyz.ef34gh.records", ".other.xyz.x.partial"):
        (tmp_path / name).write_bytes(b"\0" * 1000)
    with caplog.at_level("INFO", logger="tiledsimplify"):
        run(path, tmp_path / "out.xyz", ratio=0.5, workers=1, progress=False)
    warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert warned == [(f"{tmp_path / 'out.xyz'}: 2 temporary file(s) of an earlier run that "
                       "was killed while writing it take 0.0 MB beside it "
                       "(.out.xyz.ab12cd.partial, .out.xyz.ef34gh.records); delete them unless "
                       "another run is writing out.xyz now.")]
    assert (tmp_path / ".out.xyz.ab12cd.partial").exists()  # not ours to delete


def test_an_unreachable_scheduler_fails_before_any_work(bunny, tmp_path):
    import dask

    from tiledsimplify.errors import TiledSimplifyError
    X, path = bunny
    store = tmp_path / "store.zarr"
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        with pytest.raises(TiledSimplifyError, match=r"tcp://127.0.0.1:9: no dask scheduler "
                                                     r"answered.*dask worker"):
            run(path, tmp_path / "out.npy", ratio=0.2, scheduler="tcp://127.0.0.1:9",
                store=store)
    assert not store.exists() and not (tmp_path / "out.npy").exists()


def test_an_address_where_no_scheduler_speaks_fails_in_bounded_time(bunny, tmp_path,
                                                                    monkeypatch):
    # dask's client waited forever on a port where something else listens (the dashboard's
    # 8787 given for the scheduler's 8786: a run hung, silent, for minutes and on)
    import http.server
    import importlib
    import threading
    import time

    import dask

    from tiledsimplify.errors import TiledSimplifyError
    R = importlib.import_module("tiledsimplify.pipeline.run")
    monkeypatch.setattr(R, "CONNECT_SLACK", 1.0)
    _, path = bunny
    store = tmp_path / "store.zarr"
    class Quiet(http.server.BaseHTTPRequestHandler):
        def log_message(self, *args):  # dask's bytes are a bad request: not in the test output
            pass
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    address = f"tcp://127.0.0.1:{server.server_address[1]}"
    try:
        t = time.perf_counter()
        with dask.config.set({"distributed.comm.timeouts.connect": "1s"}), pytest.raises(
                TiledSimplifyError, match=rf"{address}: no dask scheduler answered within 2 s, "
                                          r"though something accepts connections there"):
            run(path, tmp_path / "out.npy", ratio=0.2, scheduler=address, store=store)
        assert time.perf_counter() - t < 30
    finally:
        server.shutdown()
    assert not store.exists() and not (tmp_path / "out.npy").exists()


@pytest.mark.parametrize("scheduler", ["127.0.0.1:8786", "thread", "tls://127.0.0.1:8786"])
def test_an_unknown_scheduler_fails_before_the_ingest(bunny, tmp_path, caplog, scheduler):
    # it failed at the first tile stage, after the whole input was tiled (90 s at 100M points)
    _, path = bunny
    store = tmp_path / "store.zarr"
    with caplog.at_level("INFO", logger="tiledsimplify"), pytest.raises(
            InputError, match=r"scheduler must be one of .* or tcp://HOST:PORT, got "):
        run(path, tmp_path / "out.npy", ratio=0.2, scheduler=scheduler, store=store)
    assert "ingest" not in caplog.text
    assert not store.exists() and not (tmp_path / "out.npy").exists()


def test_a_lost_scheduler_is_an_error_saying_how_to_go_on(bunny, tmp_path, cluster,
                                                         monkeypatch):
    # distributed cancels every future when the client loses its scheduler: that was a
    # traceback (FutureCancelledError is no error of ours), and so no --summary was written
    import importlib

    from distributed.client import FutureCancelledError

    from tiledsimplify.errors import TiledSimplifyError
    R = importlib.import_module("tiledsimplify.pipeline.run")
    _, path = bunny
    store = tmp_path / "s.zarr"

    def lost(*args, **kwargs):
        raise FutureCancelledError("tile-piece-3", "scheduler-connection-lost")
    monkeypatch.setattr(R, "write_output", lost)
    with pytest.raises(TiledSimplifyError, match=r"the connection to the dask scheduler was "
                                                 r"lost during the run; no output written\. The "
                                                 r"finished tiles stay in .*s\.zarr"):
        run(path, tmp_path / "o.npy", ratio=0.2, client=cluster, store=store, tile_points=3000)
    assert not (tmp_path / "o.npy").exists()

    def other(*args, **kwargs):  # any other cancellation is not taken for a lost scheduler
        raise FutureCancelledError("tile-piece-3", "unknown")
    monkeypatch.setattr(R, "write_output", other)
    with pytest.raises(FutureCancelledError):
        run(path, tmp_path / "o.npy", ratio=0.2, client=cluster, store=store, tile_points=3000)


def test_a_store_that_cannot_be_written_fails_before_the_ingest(bunny, tmp_path, caplog,
                                                               monkeypatch):
    # a store directory made beforehand but not writable failed after the ingest's first pass
    # over the input, with "…/store: Operation not permitted." (exit 1)
    import importlib
    import os
    R = importlib.import_module("tiledsimplify.pipeline.run")
    _, path = bunny
    store = tmp_path / "made" / "s.zarr"
    store.mkdir(parents=True)
    locked = {store, tmp_path / "made"}  # as for another user (the root of a test bypasses modes)
    access = os.access
    monkeypatch.setattr(R.os, "access", lambda p, mode: Path(p) not in locked
                        and access(p, mode))
    for where, bad in ((store, store), (store / "deeper", store),
                       (tmp_path / "made" / "t", tmp_path / "made")):
        with caplog.at_level("INFO", logger="tiledsimplify"), pytest.raises(
                InputError, match=rf"{where.name}: the tile store's directory {bad} is not "
                                  r"writable \(permission denied\); give --store a directory you can write to"):
            run(path, tmp_path / "o.npy", ratio=0.2, store=where, tile_points=3000)
        assert "ingest" not in caplog.text and not (tmp_path / "o.npy").exists()
    with pytest.raises(InputError, match=r"bunny.npy: is a file, not a tile store directory"):
        run(path, tmp_path / "o.npy", ratio=0.2, store=path, tile_points=3000)


def test_a_store_in_use_by_another_run_is_refused(bunny, tmp_path):
    from tiledsimplify.pipeline.run import _exclusive
    X, path = bunny
    store = tmp_path / "s.zarr"
    with _exclusive(store):  # as a run in another process would hold it
        with pytest.raises(InputError, match=r"s.zarr: another run is using this tile store "
                                             r"\(pid \d+ on "):
            run(path, tmp_path / "o.npy", ratio=0.2, store=store, tile_points=3000)
        assert not store.exists() and not (tmp_path / "o.npy").exists()
    s = run(path, tmp_path / "o.npy", ratio=0.2, store=store, tile_points=3000)  # released
    assert s.n_output == round(0.2 * len(X))


def test_a_store_in_use_is_refused_however_its_path_is_spelled(bunny, tmp_path):
    """The lock follows the store's real path: the same store reached through a linked
    directory, or through a link to the store itself, is refused too (each spelling took a
    lock of its own, and two runs wrote the same tiles: one then failed with ``tile 9 has no
    finished result yet``)."""
    from tiledsimplify.pipeline.run import _exclusive
    _, path = bunny
    (tmp_path / "real").mkdir()
    store = tmp_path / "real" / "s.zarr"
    store.mkdir()  # made beforehand (mkdir -p): a new store goes there
    (tmp_path / "linked").symlink_to(tmp_path / "real")
    (tmp_path / "real" / "t.zarr").symlink_to(store)
    with _exclusive(store):  # as a run in another process would hold it
        for other in (tmp_path / "linked" / "s.zarr", tmp_path / "real" / "t.zarr"):
            with pytest.raises(InputError, match=r"another run is using this tile store"):
                run(path, tmp_path / "o.npy", ratio=0.2, store=other, tile_points=3000)
    assert not any(store.iterdir()) and not (tmp_path / "o.npy").exists()


@pytest.mark.skipif(not __import__("sys").platform.startswith("linux"), reason="prctl")
@pytest.mark.parametrize("slow_start", [False, True])
def test_a_killed_run_leaves_no_worker_processes(tmp_path, slow_start):
    # SIGKILL (the OOM killer, a batch system past its grace period) gives no stage a chance
    # to end its pool: its processes lived on as orphans, ran every queued tile into the store
    # and then idled; now they end with the run. slow_start: the pool's processes reach their
    # initializer only after the run was killed (imports on a slow file system: this test
    # failed 3 times in 6 from a worktree on /work, never from /tmp) -- they lived on too
    import os
    import subprocess
    import sys
    import time
    env = dict(os.environ)
    if slow_start:
        site = tmp_path / "site"
        site.mkdir()
        (site / "sitecustomize.py").write_text(
            "import sys, time\n"
            "if '--multiprocessing-fork' in sys.argv:\n"
            "    time.sleep(4)\n")
        env["PYTHONPATH"] = os.pathsep.join(
            [str(site), *filter(None, [os.environ.get("PYTHONPATH")])])
    script = tmp_path / "killed.py"
    script.write_text(
        "import importlib, os, signal, time\n"
        "R = importlib.import_module('tiledsimplify.pipeline.run')\n"
        "if __name__ == '__main__':\n"
        "    with R._process_pool(2) as pool:\n"
        "        jobs = [pool.submit(time.sleep, 120) for _ in range(4)]\n"
        "        time.sleep(2)\n"
        "        print(' '.join(str(p) for p in pool._processes), flush=True)\n"
        "        os.kill(os.getpid(), signal.SIGKILL)\n")
    with open(tmp_path / "pids", "w") as out:  # a file: survivors would hold a pipe open
        got = subprocess.run([sys.executable, str(script)], stdout=out, timeout=120,
                             check=False, env=env)
    assert got.returncode == -9
    pids = [int(p) for p in (tmp_path / "pids").read_text().split()]
    assert len(pids) == 2

    def alive(pid):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return True
    t = time.perf_counter()
    while any(alive(p) for p in pids) and time.perf_counter() - t < 20:
        time.sleep(0.1)
    left = [p for p in pids if alive(p)]
    for p in left:  # not to leave them to the machine when this fails
        os.kill(p, 9)
    assert not left


def test_a_stopped_stage_ends_its_worker_processes():
    # the "processes" scheduler's pool is ours: a stop terminates its processes instead of
    # waiting for the tiles running in them (dask's own pool waited: 42 s on a 3M-point scan)
    import importlib
    import multiprocessing
    import os
    import time
    from concurrent.futures.process import BrokenProcessPool

    import dask
    R = importlib.import_module("tiledsimplify.pipeline.run")
    others = set(multiprocessing.active_children())  # a cluster fixture's, say
    t = time.perf_counter()
    with pytest.raises(KeyboardInterrupt), R._process_pool(2) as pool:
        jobs = [pool.submit(time.sleep, 120) for _ in range(2)]
        time.sleep(0.5)
        raise KeyboardInterrupt
    assert time.perf_counter() - t < 60 and set(multiprocessing.active_children()) <= others
    assert not any(j.done() and not j.cancelled() and j.exception() is None for j in jobs)
    with R._process_pool(1) as pool:  # and a stage that ends well returns its results
        assert pool.submit(abs, -3).result() == 3
    # a worker that dies (the OOM killer) fails the stage instead of losing its task
    with pytest.raises(BrokenProcessPool):
        R._compute([dask.delayed(os._exit)(1)], "processes", 1, None, False)


def test_a_stop_while_writes_are_in_flight_still_removes_the_temporary_store(
        tmp_path, monkeypatch):
    """A stop in the ingest leaves zarr's writes running in its I/O thread; they refilled the
    temporary store while it was deleted, and the stop became ``OSError: Directory not
    empty`` (exit 1, the store left in TMPDIR; seen with SIGTERM ~1 s into a 519k-point LAZ
    run). The stop must come through and the store must go."""
    import importlib
    import tempfile
    import threading
    R = importlib.import_module("tiledsimplify.pipeline.run")
    xy = np.random.default_rng(3).random((12_000, 2))
    path = tmp_path / "in.npy"
    np.save(path, np.c_[xy, 0.1 * np.sin(6 * xy[:, 0])])
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    real = R.IngestProgress.__call__
    writers = []

    def write_on(store, seconds=0.6):  # a write in flight: makes its directories anew
        end = time.monotonic() + seconds
        i = 0
        while time.monotonic() < end:
            try:
                d = store / f"t{i % 7}" / "c"
                d.mkdir(parents=True, exist_ok=True)
                (d / f"{i}").write_bytes(b"x" * 64)
            except OSError:
                pass
            i += 1

    def stop_in_pass_2(self, pass_number, points):
        if pass_number == 2 and points > 0 and not writers:
            store = next(tmp.glob("tiledsimplify-*/store.zarr"))
            writers.append(threading.Thread(target=write_on, args=(store,)))
            writers[0].start()
            time.sleep(0.05)
            raise KeyboardInterrupt
        return real(self, pass_number, points)

    monkeypatch.setattr(R.IngestProgress, "__call__", stop_in_pass_2)
    with pytest.raises(KeyboardInterrupt):
        run(path, tmp_path / "o.npy", ratio=0.2, tile_points=3000, chunk_points=1000)
    writers[0].join()
    assert list(tmp.iterdir()) == [] and not (tmp_path / "o.npy").exists()


def test_the_temporary_store_knows_how_the_run_ended(bunny, tmp_path, monkeypatch):
    """A stopped or failed run deletes its temporary store until it stays deleted for
    ``REMOVE_QUIET`` s (writes in flight make it anew); a run that ends well at once. Until
    2026-12-07 the run closed its contexts as if it had ended well whatever happened, so a
    stopped run never waited: the test above failed on a loaded machine (1 of 8 runs beside
    three busy processes on two cores), the store left in TMPDIR without a warning."""
    import importlib
    import tempfile
    R = importlib.import_module("tiledsimplify.pipeline.run")
    _, path = bunny
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    windows = []  # the quiet window each run's deletion asks for
    real_remove = R._remove_tree

    def remove(store, quiet=0.0):
        windows.append(quiet)
        return real_remove(store, quiet=quiet)
    monkeypatch.setattr(R, "_remove_tree", remove)
    run(path, tmp_path / "ok.npy", ratio=0.2, tile_points=3000)
    real = R.IngestProgress.__call__

    def stop_in_pass_2(self, pass_number, points):
        if pass_number == 2 and points > 0:
            raise KeyboardInterrupt
        return real(self, pass_number, points)
    monkeypatch.setattr(R.IngestProgress, "__call__", stop_in_pass_2)
    with pytest.raises(KeyboardInterrupt):
        run(path, tmp_path / "stopped.npy", ratio=0.2, tile_points=3000)
    assert windows == [0.0, R.REMOVE_QUIET] and R.REMOVE_QUIET > 0
    assert list(tmp.iterdir()) == [] and not (tmp_path / "stopped.npy").exists()


def test_a_run_stopped_in_its_ingest_ingests_again_and_an_empty_store_dir_is_used(
        bunny, tmp_path, monkeypatch, caplog):
    import importlib
    R = importlib.import_module("tiledsimplify.pipeline.run")
    X, path = bunny
    store = tmp_path / "st.zarr"
    real = R.IngestProgress.__call__

    def stop_in_pass_2(self, pass_number, points):
        if pass_number == 2 and points > 0:
            raise KeyboardInterrupt  # Ctrl-C or SIGTERM half-way through the tiles' points
        return real(self, pass_number, points)

    monkeypatch.setattr(R.IngestProgress, "__call__", stop_in_pass_2)
    with pytest.raises(KeyboardInterrupt):
        run(path, tmp_path / "o.npy", ratio=0.2, tile_points=3000, chunk_points=1000,
            store=store)
    monkeypatch.undo()
    with pytest.raises(Exception, match="incomplete"):
        TileStore.open(store)
    # another input's incomplete store is refused, not overwritten
    np.save(tmp_path / "other.npy", X[::2])
    with pytest.raises(InputError, match="made for another input"):
        run(tmp_path / "other.npy", tmp_path / "x.npy", ratio=0.2, tile_points=3000,
            chunk_points=1000, store=store)
    with caplog.at_level("INFO", logger="tiledsimplify"):
        s = run(path, tmp_path / "o.npy", ratio=0.2, tile_points=3000, chunk_points=1000,
                store=store)
    assert "its ingest was interrupted; ingesting again" in caplog.text
    assert s.reached and TileStore.open(store).n_tiles == s.n_tiles
    # a store directory made beforehand, empty, takes a new store
    (tmp_path / "made").mkdir()
    run(path, tmp_path / "fresh.npy", ratio=0.2, tile_points=3000, chunk_points=1000,
        store=tmp_path / "made")
    assert (tmp_path / "o.npy").read_bytes() == (tmp_path / "fresh.npy").read_bytes()


def test_a_store_that_is_a_file_or_a_foreign_folder_is_refused_with_the_fix(bunny, tmp_path):
    """``--store`` naming a file, or a folder of other things (a project's data folder): it
    said "no tile store at DIR (no zarr.json there)", without what to give instead."""
    _, path = bunny
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "mine.txt").write_text("keep me\n")
    (tmp_path / "f.zarr").write_text("a file\n")
    for store, what in [("data", "is a directory holding no tile store"),
                        ("f.zarr", "is a file, not a tile store directory")]:
        with pytest.raises(InputError, match=rf"{store}: {what}; give --store a new or empty "
                                             "directory"):
            run(path, tmp_path / "o.npy", ratio=0.2, store=tmp_path / store)
    assert (tmp_path / "data" / "mine.txt").read_text() == "keep me\n"
    assert not (tmp_path / "o.npy").exists()


def test_a_long_output_logs_its_progress(bunny, tmp_path, caplog, monkeypatch):
    """The output stage logs every tenth of the kept points written (and, for text, formatted)
    once it has run ``OUTPUT_QUIET`` seconds (0 here); a run's count is the last line's."""
    import importlib
    progress = importlib.import_module("tiledsimplify.pipeline.progress")
    from tiledsimplify.io import points_out
    monkeypatch.setattr(progress, "OUTPUT_QUIET", 0.0)
    monkeypatch.setattr(points_out, "TEXT_CHUNK", 1000)
    _, path = bunny
    for suffix, verbs in [(".laz", ["written"]), (".npy", ["written"]),
                          (".xyz", ["written", "formatted as text"])]:
        caplog.clear()
        with caplog.at_level("INFO", logger="tiledsimplify"):
            s = run(path, tmp_path / f"out{suffix}", ratio=0.15, tile_points=1500,
                    workers=2)
        lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("output:")]
        for verb in verbs:
            mine = [m for m in lines if m.split(" points) ")[1].startswith(verb)]
            shares = [int(m.split()[1]) for m in mine]
            assert shares == sorted(set(shares)) and shares[-1] == 100, (suffix, verb, lines)
            assert f"({s.n_output:,} of {s.n_output:,} points)" in mine[-1]
        assert len(lines) <= 10 * len(verbs)
    monkeypatch.setattr(progress, "OUTPUT_QUIET", 3600.0)  # a short output stays quiet
    caplog.clear()
    with caplog.at_level("INFO", logger="tiledsimplify"):
        run(path, tmp_path / "quiet.npy", ratio=0.15, tile_points=1500, workers=2)
    assert not any(r.getMessage().startswith("output:") for r in caplog.records)


def test_a_store_for_other_settings_is_refused_naming_what_differs(bunny, tmp_path):
    """The refusal named no setting: a batch user changing one flag could not tell which."""
    import os

    from tiledsimplify import SimplifyOptions
    X, _ = bunny
    path = tmp_path / "in.npy"
    np.save(path, X)
    store = tmp_path / "st.zarr"
    run(path, tmp_path / "o.npy", ratio=0.2, tile_points=3000, store=store, progress=False)
    with pytest.raises(InputError, match=r"st.zarr: this tile store was made for another input "
                                         r"or other settings \(options.edge_angle: 35.0 here, "
                                         r"40.0 in the store; target: 3268 here, 1634 in the "
                                         r"store\); give a new --store"):
        run(path, tmp_path / "o.npy", ratio=0.4, tile_points=3000, store=store, progress=False,
            options=SimplifyOptions(edge_angle=35.0))
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))  # the input, touched
    with pytest.raises(InputError, match=r"\(the same settings, but the input files differ"):
        run(path, tmp_path / "o.npy", ratio=0.2, tile_points=3000, store=store, progress=False)
    # a store of an older version, which had no such option: named, not "the same settings"
    # (a setting the store lacks compared equal to one set to None here)
    import zarr
    root = zarr.open_group(str(store), mode="r+")
    made = json.loads(json.dumps(root.attrs["config"]))
    config = json.loads(json.dumps(made))
    del config["options"]["edge_share"]
    root.attrs["config"] = {**config, "fingerprint": "of an older version"}
    with pytest.raises(InputError, match=r"\(options.edge_share: None here, absent in the "
                                         r"store\)"):
        run(path, tmp_path / "o.npy", ratio=0.2, tile_points=3000, store=store, progress=False)
    # ... and one whose tiles saved other results (before 2026-12-05: no ``fixed`` points for
    # the refinement, which would have failed reading them): refused, naming it
    config = json.loads(json.dumps(made))
    del config["tile_results"]
    root.attrs["config"] = {**config, "fingerprint": "of an older version"}
    with pytest.raises(InputError, match=r"\(tile_results: step, importance, boundary, "
                                         r"feature, fixed, normal here, absent in the store\)"):
        run(path, tmp_path / "o.npy", ratio=0.2, tile_points=3000, store=store, progress=False)


def test_unbounded_options_are_saved_in_the_store_by_name(tmp_path, caplog):
    """``reach = inf`` (the paper's unbounded neighbourhoods) and ``edge_share = inf`` (every
    flagged point kept) are valid options, but a tiled run failed with them before any work:
    the store keeps its settings as JSON, which has no infinity ("config must be
    JSON-serialisable"). Now they are saved by name, and a resumed run with the same options
    finds its store."""
    from tiledsimplify import SimplifyOptions
    rng = np.random.default_rng(1)
    path = tmp_path / "plate.npy"
    np.save(path, np.c_[rng.random((3000, 2)), 0.01 * rng.random(3000)])
    options = SimplifyOptions(reach=float("inf"), edge_share=float("inf"))
    with caplog.at_level("INFO", logger="tiledsimplify"):
        s = run(path, tmp_path / "a.npy", ratio=0.3, options=options, store=tmp_path / "st",
                tile_points=1000, progress=False)
    assert s.reached and s.n_output == 900
    assert [r for r in caplog.records if r.getMessage().startswith("tile ")]
    saved = TileStore.open(tmp_path / "st").config["options"]
    assert saved["reach"] == saved["edge_share"] == "inf"
    caplog.clear()
    with caplog.at_level("INFO", logger="tiledsimplify"):
        run(path, tmp_path / "b.npy", ratio=0.3, options=options, store=tmp_path / "st",
            tile_points=1000, progress=False)
    assert not [r for r in caplog.records if r.getMessage().startswith("tile ")]  # resumed
    assert np.array_equal(np.load(tmp_path / "a.npy"), np.load(tmp_path / "b.npy"))


def test_edge_share_in_tiles_agrees_between_passes(tmp_path):
    """Where a tile flags more points than ``edge_share`` of its share of the count, its sure
    flags are an even sample of them, the same in every pass over it (the global target's
    share, as the pre-thinning aims at): tiles first run far (floor 0.05) or stopped at their
    share (floor 0.99, then deeper passes) give the same bytes, and the count is met — with
    every feature point kept it could not be."""
    rng = np.random.default_rng(8)
    xy = rng.random((12000, 2)) * [2.0, 3.0] - [1.0, 0.0]
    X = np.c_[xy, -np.abs(xy[:, 0])]  # a roof folding by 90° along x = 0
    path = tmp_path / "roof.npy"
    np.save(path, X)
    a = run(path, tmp_path / "a.npy", ratio=0.01, tile_points=2000, floor=0.99)
    b = run(path, tmp_path / "b.npy", ratio=0.01, tile_points=2000, floor=0.05)
    assert a.reached and b.reached and a.n_tiles >= 4 and a.n_output == 120
    assert a.n_deeper >= 1  # some tile ran again, deeper, with the same sure flags
    assert (tmp_path / "a.npy").read_bytes() == (tmp_path / "b.npy").read_bytes()
    every = run(path, tmp_path / "c.npy", ratio=0.01, tile_points=2000,
                options={"edge_share": float("inf")})
    # every feature point kept: the flagged ones and the band's few a little farther
    assert not every.reached and every.n_output > 120
    assert 0.8 * every.n_output <= every.n_boundary <= every.n_output
    assert 0 < a.n_boundary < 0.6 * 120  # flagged points kept: at most the share, and a few


_LOCAL_RUN = """
import sys
from tiledsimplify.pipeline import run
run(sys.argv[1], sys.argv[2], ratio=0.2, tile_points=1500, scheduler=sys.argv[3], workers=2)
print(",".join(sorted({m.split(".")[0] for m in sys.modules} & {"distributed", "tornado"})))
"""


@pytest.mark.parametrize("scheduler", ["threads", "synchronous", "processes"])
def test_a_local_run_never_imports_dask_distributed(bunny, tmp_path, scheduler):
    # dask.compute given a scheduler's name imports dask.distributed to look for a client
    # (0.1-0.3 s); a local run names dask's function instead
    import subprocess
    import sys
    X, path = bunny
    out = subprocess.run([sys.executable, "-c", _LOCAL_RUN, str(path), str(tmp_path / "o.npy"),
                          scheduler], check=True, capture_output=True, text=True).stdout
    assert out.strip() == ""
    assert len(np.load(tmp_path / "o.npy")) == round(0.2 * len(X))


def test_kernels_load_while_the_input_is_read(bunny, tmp_path, monkeypatch):
    # on a warm cache the kernels load in a thread started before the ingest and joined
    # before the first tile (threads, synchronous); the processes' pool and a cluster's
    # workers load their own; a cold cache compiles instead, as a stage of its own
    import importlib
    import threading
    R = importlib.import_module("tiledsimplify.pipeline.run")
    from tiledsimplify.core import compile_cache
    events = []

    class Loader:
        def join(self):
            events.append("joined")

    real_simplify = R.simplify_tile

    def simplify_tile(*args, **kw):
        events.append("tile")
        return real_simplify(*args, **kw)

    monkeypatch.setattr(compile_cache, "start", lambda jobs: None)
    monkeypatch.setattr(compile_cache, "start_loading",
                        lambda: events.append("started") or Loader())
    monkeypatch.setattr(R, "simplify_tile", simplify_tile)
    _, path = bunny
    s = run(path, tmp_path / "o.npy", ratio=0.2, tile_points=1500, workers=2)
    assert events[:3] == ["started", "joined", "tile"] and events.count("started") == 1
    assert "compile" not in s.seconds
    for scheduler in ("threads", "synchronous"):
        assert isinstance(R._start_compile(None, scheduler, 2)[0], Loader)
    assert R._start_compile(None, "processes", 2) == (None, False)
    assert R._start_compile(object(), "threads", 2) == (None, False)
    compiling = threading.Thread(target=lambda: None)
    monkeypatch.setattr(compile_cache, "start", lambda jobs: compiling)
    assert R._start_compile(None, "threads", 2) == (compiling, True)


def test_processes_run_every_stage_in_one_pool_a_task_at_a_time(bunny, tmp_path, monkeypatch):
    # one pool for the run (a pool a stage spawned its processes, imported the package and
    # loaded the kernels again at every stage), handed one task per free process: dask's
    # default batches of 6 ran the largest tiles last
    import importlib

    from dask.callbacks import Callback
    R = importlib.import_module("tiledsimplify.pipeline.run")
    made = []
    real_pool = R._process_pool

    def counting_pool(workers):
        made.append(workers)
        return real_pool(workers)

    monkeypatch.setattr(R, "_process_pool", counting_pool)
    out = {"now": 0, "most": 0}

    def pretask(key, dsk, state):
        out["now"] += 1
        out["most"] = max(out["most"], out["now"])

    def posttask(key, result, dsk, state, worker_id):
        out["now"] -= 1

    _, path = bunny
    with Callback(pretask=pretask, posttask=posttask):
        s = run(path, tmp_path / "p.npy", ratio=0.2, tile_points=1500, scheduler="processes",
                workers=2)
    assert s.refined and s.n_tiles >= 6 and made == [2]
    assert out["most"] == 2
    assert R._RUN_POOL.get() is None  # the run's pool is gone with the run
    threads = run(path, tmp_path / "t.npy", ratio=0.2, tile_points=1500, workers=2)
    assert threads.n_output == s.n_output
    assert np.array_equal(np.load(tmp_path / "p.npy"), np.load(tmp_path / "t.npy"))


def test_one_output_per_file_is_the_same_on_a_cluster(data_dir, tmp_path, cluster):
    """An output per input file (``{stem}``): the pieces packed on the cluster's workers for
    each file's layout make the files a synchronous run writes, byte for byte."""
    src = laspy.read(data_dir / "lidar" / "autzen_trim.laz")
    (tmp_path / "in").mkdir()
    west = np.asarray(src.x) < np.median(src.x)
    for name, m in (("west", west), ("east", ~west)):
        las = laspy.LasData(src.header)
        las.points = src.points[m]
        las.write(tmp_path / "in" / f"{name}.laz")
    kw = {"ratio": 0.3, "tile_points": 30000}
    outs = {}
    for how, extra in (("one", {"scheduler": "synchronous"}), ("cluster", {"client": cluster})):
        (tmp_path / how).mkdir()
        s = run(str(tmp_path / "in" / "*.laz"), str(tmp_path / how / "{stem}.laz"), **kw,
                **extra)
        assert s.n_tiles >= 3 and s.n_output == 33_000
        outs[how] = [Path(o["path"]).read_bytes() for o in s.outputs]
    assert outs["cluster"] == outs["one"] and all(len(b) > 1000 for b in outs["one"])


def test_no_edges_on_classes(data_dir, tmp_path):
    """``no_edge_classes``: the points of those classes are never flagged (the ALS tile's
    vegetation, classes 3-5, carries flags otherwise), in every tile and halo; the other
    classes keep theirs; the count is the same. Refused without a classification dimension,
    and for codes that are not codes."""
    src = laspy.read(data_dir / "lidar" / "las_with_several_extra_byte_bloc.laz")
    cls = np.asarray(src.classification)
    veg = np.isin(cls, [3, 4, 5])
    # a corner of the tile, with its trees: 40,000 points nearest the densest vegetation
    c = np.c_[src.x, src.y][veg].mean(axis=0)
    near = np.argsort(np.hypot(src.x - c[0], src.y - c[1]))[:40_000]
    las = laspy.LasData(src.header)
    las.points = src.points[np.sort(near)]
    las.write(tmp_path / "in.laz")
    kw = {"ratio": 0.2, "tile_points": 12_000}
    base = run(tmp_path / "in.laz", tmp_path / "base.laz", store=tmp_path / "st", **kw)
    # each tile's mask: its core's classes and its halo's, read from their own tiles
    from tiledsimplify.pipeline.tile_task import edge_ok
    from tiledsimplify.tiles import TileStore
    ts = TileStore.open(tmp_path / "st")
    classes = np.asarray(las.classification)
    for t in range(ts.n_tiles):
        index = np.concatenate([ts.core_index(t), ts.tile_halo(t)[1]])
        np.testing.assert_array_equal(edge_ok(ts, t, (3, 4, 5)),
                                      ~np.isin(classes[index], [3, 4, 5]))
        assert edge_ok(ts, t, ()) is None
    s = run(tmp_path / "in.laz", tmp_path / "veg.laz", no_edge_classes=[5, 3, 4], **kw)
    assert s.n_tiles >= 3 and s.n_output == base.n_output
    a, b = laspy.read(tmp_path / "base.laz"), laspy.read(tmp_path / "veg.laz")
    va, vb = np.isin(a.classification, [3, 4, 5]), np.isin(b.classification, [3, 4, 5])
    assert a.sharp_edge[va].sum() > 20 and b.sharp_edge[vb].sum() == 0
    assert b.sharp_edge[~vb].sum() > 0.5 * a.sharp_edge[~va].sum()
    # mode "paper": its threshold from the histogram of the points that may be edge points
    s = run(tmp_path / "in.laz", tmp_path / "paper.laz", no_edge_classes=[3, 4, 5],
            options={"mode": "paper", "reach": 12}, **kw)
    c = laspy.read(tmp_path / "paper.laz")
    vc = np.isin(c.classification, [3, 4, 5])
    assert c.sharp_edge[vc].sum() == 0 < c.sharp_edge[~vc].sum() and s.n_output == base.n_output
    np.save(tmp_path / "xyz.npy", np.c_[las.x, las.y, las.z])
    with pytest.raises(InputError, match="no classification dimension"):
        run(tmp_path / "xyz.npy", tmp_path / "o.npy", no_edge_classes=[3], **kw)
    with pytest.raises(InputError, match="classification codes 0-255"):
        run(tmp_path / "in.laz", tmp_path / "o.laz", no_edge_classes=[300], **kw)
    with pytest.raises(InputError, match="whole numbers 0-255"):
        run(tmp_path / "in.laz", tmp_path / "o.laz", no_edge_classes=["trees"], **kw)
