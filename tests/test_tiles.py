"""Tests for tiledsimplify.tiles: count-balanced tile planning and the zarr v3 tile store."""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
import zarr

from tiledsimplify.errors import InputError, TiledSimplifyError
from tiledsimplify.tiles import (
    IncompleteStoreError,
    ResultExistsError,
    StoreError,
    StoreExistsError,
    TilePlan,
    TileStore,
    estimate_spacing,
    plan_tiles,
)

CONFIG = {"target": 0.1, "features": {"angle": 30}}
PROVENANCE = {"input": "synthetic.las", "points": 1}


# ---------------------------------------------------------------------------- data
def sphere_plane(n=200_000, seed=1):
    """Points on a unit sphere plus a 6x6 plane below it, shuffled, with attributes."""
    rng = np.random.default_rng(seed)
    ns = n // 2
    v = rng.normal(size=(ns, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    plane = np.c_[rng.uniform(-3, 3, (n - ns, 2)), np.full(n - ns, -1.5)]
    xyz = np.concatenate([v, plane])[rng.permutation(n)]
    attrs = {
        "intensity": rng.integers(0, 65535, n).astype(np.uint16),
        "classification": rng.integers(0, 20, n).astype(np.uint8),
        "gps_time": rng.random(n),
        "rgb": rng.integers(0, 65535, (n, 3)).astype(np.uint16),
    }
    return xyz, attrs


def clustered(n=100_000, seed=2):
    """A few tight blobs and a thin wall in a 1000-unit box: mostly empty space."""
    rng = np.random.default_rng(seed)
    centres = np.array([[0, 0, 0], [1000, 0, 0], [0, 1000, 1000], [500, 500, 500],
                        [900, 100, 800]], dtype=float)
    k = n - n // 5
    sizes = rng.multinomial(k, [0.4, 0.25, 0.15, 0.15, 0.05])
    blobs = [c + rng.normal(scale=s, size=(m, 3))
             for c, m, s in zip(centres, sizes, [5, 1, 20, 2, 0.5], strict=True)]
    wall_n = n - k
    wall = np.c_[rng.uniform(0, 1000, wall_n), np.full(wall_n, 300.0),
                 rng.uniform(0, 50, wall_n)]
    xyz = np.concatenate(blobs + [wall])
    return xyz[rng.permutation(n)]


def make_chunks(xyz, attrs=None, size=50_000, shuffle_order=False, seed=0):
    """A re-iterable chunk source over arrays (as the LAS reader will provide)."""
    attrs = attrs or {}
    n = xyz.shape[0]
    starts = list(range(0, n, size))
    if shuffle_order:
        np.random.default_rng(seed).shuffle(starts)

    def source():
        for s in starts:
            yield s, xyz[s:s + size], {k: v[s:s + size] for k, v in attrs.items()}

    return source


def all_cores(store):
    xs, js, ts = [], [], []
    for t in range(store.n_tiles):
        x, j = store.core(t)
        xs.append(x)
        js.append(j)
        ts.append(np.full(j.shape, t))
    return np.concatenate(xs), np.concatenate(js), np.concatenate(ts)


def check_partition(store, xyz):
    x, j, t = all_cores(store)
    n = xyz.shape[0]
    assert j.shape == (n,)
    assert np.array_equal(np.sort(j), np.arange(n)), "every index exactly once"
    assert np.array_equal(x, xyz[j])
    assert np.array_equal(store.plan.assign(x), t)
    assert np.array_equal(store.tile_counts, np.bincount(t, minlength=store.n_tiles))


@pytest.fixture(scope="module")
def sp_data():
    return sphere_plane()


@pytest.fixture(scope="module")
def sp_store(sp_data, tmp_path_factory):
    xyz, attrs = sp_data
    path = tmp_path_factory.mktemp("sp") / "store"
    return TileStore.create(path, make_chunks(xyz, attrs, 30_000), tile_points=20_000,
                            config=CONFIG, provenance=PROVENANCE, sample_size=50_000)


# ---------------------------------------------------------------------------- plan
def test_plan_leaves_partition_all_of_space():
    xyz = clustered(20_000)
    plan = plan_tiles(xyz, len(xyz), 1000)
    rng = np.random.default_rng(5)
    probe = np.concatenate([xyz[:2000], rng.uniform(-1e6, 1e6, (3000, 3)),
                            plan.lo[np.isfinite(plan.lo).all(axis=1)]])  # points on faces
    tid = plan.assign(probe)
    inside = ((probe[:, None, :] >= plan.lo[None]) & (probe[:, None, :] < plan.hi[None])).all(-1)
    assert np.array_equal(inside.sum(axis=1), np.ones(len(probe)))
    assert np.array_equal(np.argmax(inside, axis=1), tid)
    assert np.isneginf(plan.lo).any() and np.isposinf(plan.hi).any()


def test_plan_count_balanced_on_clustered_cloud():
    xyz = clustered()
    n, tp = len(xyz), 5_000
    plan = plan_tiles(xyz, n, tp)  # the sample is the whole cloud: exact counts
    counts = np.bincount(plan.assign(xyz), minlength=plan.n_tiles)
    assert counts.max() <= tp
    assert np.median(counts) >= tp / 4
    assert counts.min() > 0
    # A uniform grid with as many cells as tiles leaves most cells empty and overfills others.
    g = int(np.ceil(plan.n_tiles ** (1 / 3)))
    lo, hi = xyz.min(0), xyz.max(0)
    cell = np.minimum(((xyz - lo) / (hi - lo) * g).astype(int), g - 1)
    grid_counts = np.bincount(np.ravel_multi_index(cell.T, (g, g, g)), minlength=g ** 3)
    assert (grid_counts == 0).mean() > 0.5 and grid_counts.max() > 5 * tp


def test_plan_from_subsample_stays_under_tile_points():
    xyz = clustered()
    rng = np.random.default_rng(0)
    sample = xyz[rng.choice(len(xyz), 10_000, replace=False)]
    plan = plan_tiles(sample, len(xyz), 5_000)
    counts = np.bincount(plan.assign(xyz), minlength=plan.n_tiles)
    assert counts.max() <= 5_000
    assert np.median(counts) >= 5_000 / 4
    plain = plan_tiles(sample, len(xyz), 5_000, safety=0)  # the unmargined criterion
    assert plain.n_tiles <= plan.n_tiles


def test_plan_does_not_cut_through_a_flat_face():
    # a scanned floor, and a wall across x at the floor's median: a median cut runs through
    # the wall, so each tile's halo would hold half of it
    rng = np.random.default_rng(2)
    floor = np.c_[rng.random(40_000), 0.6 * rng.random(40_000), np.zeros(40_000)]
    wall = np.c_[0.5 + 1e-4 * rng.standard_normal(4000), 0.6 * rng.random(4000),
                 0.3 * rng.random(4000)]
    xyz = np.r_[floor, wall]
    halo = 0.01
    median_cut = plan_tiles(xyz, len(xyz), 30_000)
    plan = plan_tiles(xyz, len(xyz), 30_000, halo=halo)
    assert median_cut.n_tiles == plan.n_tiles == 2
    assert (median_cut.face_distance(wall) < halo).mean() > 0.3
    assert (plan.face_distance(wall) >= halo).all()
    counts = np.bincount(plan.assign(xyz))
    assert counts.min() >= 0.4 * len(xyz) - 1  # still balanced within the 40-60 % window
    with pytest.raises(InputError):
        plan_tiles(xyz, len(xyz), 30_000, halo=-1.0)


def test_ingest_buffers_do_not_keep_input_chunks_alive():
    # a buffered remainder must not be a view of the whole input chunk: with many tiles
    # holding remainders, ingest memory grew with the number of chunks (measured at 10M)
    from tiledsimplify.tiles.ingest import TileBuffer
    chunk = np.arange(3000.0).reshape(1000, 3)
    buf = TileBuffer(lambda: {"xyz": object()}, chunk_rows=64, keys=["xyz"])
    buf.add({"xyz": chunk[10:110]})
    assert not np.shares_memory(buf.pieces["xyz"][0], chunk)
    n, jobs = buf.flush(aligned=True)
    assert n == 64 and not np.shares_memory(buf.pieces["xyz"][0], jobs[0][3])
    np.testing.assert_array_equal(buf.pieces["xyz"][0], chunk[74:110])


def test_plan_deterministic_and_serialisable():
    xyz = clustered(30_000)
    a = plan_tiles(xyz, 10 * len(xyz), 20_000, bounds=[xyz.min(0), xyz.max(0)])
    b = plan_tiles(xyz.copy(), 10 * len(xyz), 20_000, bounds=[xyz.min(0), xyz.max(0)])
    assert a == b
    d = json.loads(json.dumps(a.to_dict(), allow_nan=False))
    c = TilePlan.from_dict(d)
    assert c == a and np.array_equal(c.lo, a.lo) and np.array_equal(c.hi, a.hi)
    assert np.array_equal(c.assign(xyz), a.assign(xyz))
    with pytest.raises(InputError):
        TilePlan.from_dict({"format": "something else"})


def test_plan_degenerate_inputs():
    same = np.ones((500, 3))
    plan = plan_tiles(same, 500, 10)  # identical points cannot be split: one tile
    assert plan.n_tiles == 1 and np.array_equal(plan.assign(same), np.zeros(500))
    ties = np.zeros((1000, 3))
    ties[:, 0] = np.repeat([0.0, 1.0, 2.0, 3.0], 250)
    plan = plan_tiles(ties, 1000, 250)
    counts = np.bincount(plan.assign(ties))
    assert plan.n_tiles == 4 and counts.max() == 250
    with pytest.raises(InputError):
        plan_tiles(np.zeros((0, 3)), 10, 5)
    with pytest.raises(InputError):
        plan_tiles(np.full((3, 3), np.nan), 10, 5)
    with pytest.raises(InputError):
        plan.assign(np.zeros((2, 2)))


def test_neighbours_match_box_gaps():
    xyz = clustered(20_000)
    bounds = np.stack([xyz.min(0), xyz.max(0)])
    plan = plan_tiles(xyz, len(xyz), 800, bounds=bounds)
    halo = 15.0
    lo = np.clip(plan.lo, bounds[0], bounds[1])
    hi = np.clip(plan.hi, bounds[0], bounds[1])
    for t in range(plan.n_tiles):
        nb = plan.neighbours(t, halo)
        expect = [j for j in range(plan.n_tiles) if j != t and
                  all(max(lo[j, a] - hi[t, a], lo[t, a] - hi[j, a]) <= halo for a in range(3))]
        assert nb.tolist() == expect
        for j in nb:
            assert t in plan.neighbours(j, halo)


# ---------------------------------------------------------------------------- store: layout
def test_every_point_in_exactly_one_core(sp_data, sp_store):
    xyz, _ = sp_data
    check_partition(sp_store, xyz)
    assert sp_store.tile_counts.max() <= 20_000
    for t in range(sp_store.n_tiles):  # the points alone, as the tile passes read them
        assert np.array_equal(sp_store.core_xyz(t), sp_store.core(t)[0])
        assert np.array_equal(sp_store.core_index(t), sp_store.core(t)[1])


@pytest.mark.parametrize("tile_points,chunk", [(3_000, 7_001), (25_000, 100_000), (200_000, 999)])
def test_partition_for_tile_and_chunk_sizes(tmp_path, tile_points, chunk):
    xyz = clustered(40_000, seed=tile_points)
    store = TileStore.create(tmp_path / "s", make_chunks(xyz, size=chunk),
                             tile_points=tile_points, config={}, provenance={},
                             sample_size=10_000)
    check_partition(store, xyz)
    assert store.n_tiles == 1 if tile_points >= len(xyz) else store.n_tiles > 1


def test_create_reports_progress_of_both_passes(tmp_path):
    """Each pass reports its start (0 points) and the points read so far after every chunk,
    ending at all of them."""
    xyz = clustered(25_000, seed=3)
    calls = []
    TileStore.create(tmp_path / "s", make_chunks(xyz, size=7_000), tile_points=5_000,
                     config={}, provenance={}, sample_size=5_000,
                     progress=lambda k, points: calls.append((k, points)))
    for k in (1, 2):
        points = [c for kk, c in calls if kk == k]
        assert points == [0, 7_000, 14_000, 21_000, 25_000], k
    assert [k for k, _ in calls] == [1] * 5 + [2] * 5  # pass 1 ends before pass 2 starts


def test_an_input_that_fits_the_buffer_is_read_once(tmp_path):
    # the ingest's second pass is handed the first pass's chunks when they hold at most
    # buffer_points points together (no second read and decompression); a larger input is
    # read again; the store is the same either way
    from tiledsimplify.tiles.ingest import ReadOnce
    xyz = clustered(25_000, seed=5)
    attrs = {"i": np.arange(25_000, dtype=np.int32)}
    reads = []

    def counted(source):
        def read():
            reads.append(1)
            yield from source()
        return read

    once = TileStore.create(tmp_path / "once", counted(make_chunks(xyz, attrs, 7_000)),
                            tile_points=5_000, config={}, provenance={}, sample_size=5_000)
    assert len(reads) == 1
    twice = TileStore.create(tmp_path / "twice", counted(make_chunks(xyz, attrs, 7_000)),
                             tile_points=5_000, config={}, provenance={}, sample_size=5_000,
                             buffer_points=24_999)
    assert len(reads) == 3
    check_partition(once, xyz)
    assert once.n_tiles == twice.n_tiles > 1
    for t in range(once.n_tiles):
        for a, b in zip(once.core(t), twice.core(t), strict=True):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(once.attrs(t)["i"], twice.attrs(t)["i"])
    # a first pass that did not end keeps nothing; the kept chunks are handed out once
    source = ReadOnce(make_chunks(xyz, size=7_000), 10 ** 6)
    first = source()
    next(first)
    first.close()
    assert source._kept is None
    assert sum(len(c[1]) for c in source()) == 25_000
    assert [c[0] for c in source()] == [0, 7_000, 14_000, 21_000]  # the kept ones
    assert source._kept is None


def check_random_case(n, tile_frac, chunk, seed, dup):
    # tile_points from n/40 (at most ~80 tiles, to keep the test fast) to 2 n (one tile)
    tile_points = max(1, int(round(n * tile_frac)))
    rng = np.random.default_rng(seed)
    xyz = rng.normal(size=(n, 3)) * rng.uniform(0.01, 100, 3)
    if dup:  # many exact duplicates and ties
        xyz = np.round(xyz[rng.integers(0, max(1, n // 3), n)], 1)
    with tempfile.TemporaryDirectory() as d:
        store = TileStore.create(Path(d) / "s", make_chunks(xyz, {"i": np.arange(n)}, chunk),
                                 tile_points=tile_points, config={}, provenance={},
                                 sample_size=max(2, n // 2), seed=seed % 7)
        check_partition(store, xyz)
        j = store.core(store.n_tiles - 1)[1]
        assert np.array_equal(store.attrs(store.n_tiles - 1, ["i"])["i"], j)


@pytest.mark.parametrize("case", range(8))
def test_partition_random_cases(case):
    rng = np.random.default_rng(1000 + case)
    check_random_case(n=int(rng.integers(1, 3000)), tile_frac=float(rng.uniform(1 / 40, 2)),
                      chunk=int(rng.integers(1, 3500)), seed=int(rng.integers(0, 2 ** 32)),
                      dup=bool(case % 2))


try:  # hypothesis is optional (not in the [test] extra): shrinking search when available
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st
except ImportError:  # pragma: no cover
    pass
else:
    @settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(n=st.integers(1, 3000), tile_frac=st.floats(1 / 40, 2),
           chunk=st.integers(1, 3500), seed=st.integers(0, 2 ** 32), dup=st.booleans())
    def test_partition_property(n, tile_frac, chunk, seed, dup):
        check_random_case(n, tile_frac, chunk, seed, dup)


def test_ingest_writes_run_a_batch_behind_and_never_two_at_once_on_an_array():
    # the second pass writes a chunk's rows while it reads the next one; two writes to one
    # array (a partial zarr chunk, then the rest of it) must not overlap
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from tiledsimplify.tiles.ingest import Writes
    log, lock = [], threading.Lock()

    class Slow:
        def __init__(self, name, fail=False):
            self.name, self.fail = name, fail

        def __setitem__(self, key, data):
            with lock:
                log.append(("start", self.name, key.start))
            time.sleep(0.05)
            with lock:
                log.append(("end", self.name, key.start))
            if self.fail:
                raise OSError(f"{self.name}: disk full")

    a, b = Slow("a"), Slow("b")
    held = threading.Event()

    class Held(Slow):
        def __setitem__(self, key, data):
            assert held.wait(30)
            super().__setitem__(key, data)

    with ThreadPoolExecutor(4) as pool:
        writes = Writes(pool)
        first = threading.Thread(target=writes.submit, args=([(Held("h"), 0, 10, None)],))
        first.start()
        first.join(10)
        assert not first.is_alive() and not log  # returned with its write still held
        held.set()
        writes.submit([(a, 0, 10, None), (b, 0, 10, None)])  # waits for the held batch
        assert ("end", "h", 0) in log
        writes.submit([(a, 10, 20, None)])  # waits for a's first write, then for batch 2
        assert ("end", "a", 0) in log and ("end", "b", 0) in log
        writes.drain()
    assert log.index(("end", "a", 0)) < log.index(("start", "a", 10))
    assert ("end", "a", 10) in log
    with ThreadPoolExecutor(2) as pool, pytest.raises(OSError, match="c: disk full"):
        writes = Writes(pool)
        writes.submit([(Slow("c", fail=True), 0, 10, None)])
        writes.drain()


def test_chunks_are_read_one_ahead_in_order_with_errors_and_early_stops():
    # the ingest reads the next chunk while it sorts this one: same items in the same order,
    # never more than one read ahead, the reader's error raised in its place, and a caller
    # that stops early stops the reader and closes the source
    import threading

    from tiledsimplify.tiles.ingest import read_ahead
    state = {"read": 0, "done": 0, "closed": False}
    lock = threading.Lock()

    def source(n, fail_at=None):
        try:
            for i in range(n):
                if i == fail_at:
                    raise OSError(f"chunk {i}: truncated file")
                with lock:
                    state["read"] += 1
                    assert state["read"] - state["done"] <= 2  # handed out + one read ahead
                yield i
        finally:
            state["closed"] = True

    got = []
    for item in read_ahead(source(20)):
        time.sleep(0.005)  # the reader gets ahead if it may
        got.append(item)
        with lock:
            state["done"] += 1
    assert got == list(range(20)) and state["closed"]
    state.update(read=0, done=0, closed=False)
    with pytest.raises(OSError, match="chunk 3: truncated file"):
        for _ in read_ahead(source(10, fail_at=3)):
            state["done"] += 1
    state.update(read=0, done=0, closed=False)
    gen = read_ahead(source(10))
    assert next(gen) == 0
    gen.close()
    assert state["closed"] and state["read"] <= 2


def test_chunked_ingest_equals_whole_ingest(tmp_path):
    xyz, attrs = sphere_plane(60_000, seed=3)
    kw = dict(tile_points=8_000, config={}, provenance={}, sample_size=20_000, seed=4)
    whole = TileStore.create(tmp_path / "whole", make_chunks(xyz, attrs, 60_000), **kw)
    small = TileStore.create(tmp_path / "small", make_chunks(xyz, attrs, 997), chunk_rows=1000,
                             buffer_points=3_000, **kw)
    shuffled = TileStore.create(tmp_path / "shuf", make_chunks(xyz, attrs, 4_321,
                                                               shuffle_order=True), **kw)
    assert whole.plan == small.plan == shuffled.plan
    assert whole.spacing == small.spacing == shuffled.spacing
    assert np.array_equal(whole.tile_counts, small.tile_counts)
    assert np.array_equal(whole.tile_counts, shuffled.tile_counts)
    for t in range(whole.n_tiles):
        wx, wj = whole.core(t)
        sx, sj = small.core(t)
        assert np.array_equal(wx, sx) and np.array_equal(wj, sj)  # same order, too
        hx, hj = shuffled.core(t)
        o = np.argsort(hj)
        assert np.array_equal(hj[o], wj) and np.array_equal(hx[o], wx)
        wa, ha = whole.attrs(t), shuffled.attrs(t)
        for k in attrs:
            assert np.array_equal(ha[k][o], wa[k])


def part_chunks(xyz, attrs, lo, hi, size):
    """A chunk source over points lo..hi-1 only (one part of the input)."""
    def source():
        for s in range(lo, hi, size):
            e = min(s + size, hi)
            yield s, xyz[s:e], {k: v[s:e] for k, v in attrs.items()}
    return source


def thread_map(func, args, pass_number):
    """``map_parts`` running every part at once, in threads (as dask would)."""
    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(len(args)) as pool:
        return [f.result() for f in [pool.submit(func, *a) for a in args]]


@pytest.mark.parametrize("n_total", [None, 60_000])  # 60,000: each part samples below a key
def test_ingest_in_parts_holds_what_one_ingest_holds(tmp_path, n_total):
    xyz, attrs = sphere_plane(60_000, seed=3)
    kw = dict(tile_points=8_000, config={}, provenance={}, sample_size=5_000, seed=4,
              chunk_rows=1000, n_total=n_total)
    whole = TileStore.create(tmp_path / "whole", make_chunks(xyz, attrs, 997), **kw)
    # parts of unequal sizes, one empty, a small write buffer: partial chunks mid-part
    cuts = [0, 997 * 7, 997 * 7, 997 * 30, 60_000]
    parts = [part_chunks(xyz, attrs, lo, hi, 997) for lo, hi in zip(cuts[:-1], cuts[1:])]
    split = TileStore.create(tmp_path / "parts", make_chunks(xyz, attrs, 997), parts=parts,
                             map_parts=thread_map, buffer_points=2_500, **kw)
    assert whole.plan == split.plan and whole.spacing == split.spacing
    assert np.array_equal(whole.tile_counts, split.tile_counts)
    # the least and largest value of each numeric attribute, over every part, and whether
    # all are whole numbers (a points file's colour; which values a LAS dimension holds)
    want = {k: (v.min().item(), v.max().item(), v.dtype.kind in "iu") for k, v in attrs.items()}
    assert whole.attribute_stats == split.attribute_stats == want
    assert whole.attribute_max == {k: hi for k, (_, hi, _) in want.items() if k != "gps_time"}
    # a store made before the ingest recorded them (a run resumed): read from its tiles
    root = zarr.open_group(tmp_path / "whole", mode="r+")
    del root.attrs["attribute_stats"]
    old = TileStore.open(tmp_path / "whole")
    assert "attribute_stats" not in old.root_attrs and old.attribute_stats == want
    a = split.root_attrs
    assert a["ingest_parts"] == 4 and len(a["part_starts"]) == 4
    assert np.array_equal(np.sum(a["part_counts"], axis=0), split.tile_counts)
    assert not any(a["part_counts"][1])  # the empty part wrote nothing
    for t in range(whole.n_tiles):
        wx, wj = whole.core(t)
        sx, sj = split.core(t)
        assert np.array_equal(wx, sx) and np.array_equal(wj, sj)  # the same order too
        assert np.array_equal(split.core_index(t), wj)
        wa, sa = whole.attrs(t), split.attrs(t)
        for k in attrs:
            assert np.array_equal(wa[k], sa[k])
        for got, want in zip(split.halo_points(t, owners=True),
                             whole.halo_points(t, owners=True)):
            assert np.array_equal(got, want)
    check_partition(split, xyz)


def test_a_part_samples_below_a_key_the_whole_sample_lies_under():
    from tiledsimplify.tiles.sampling import key_limit, sample_keys
    for n, k, seed in [(10_000, 500, 0), (1_000_000, 200_000, 3), (123_457, 1, 9)]:
        limit = key_limit(k, n)
        assert limit is not None
        keys = np.sort(sample_keys(np.arange(n), seed))
        assert keys[k - 1] < np.uint64(limit)          # the k smallest lie below it
        assert (keys < np.uint64(limit)).sum() < 2 * k + 200  # and it keeps few more
    assert key_limit(1000, 1000) is None and key_limit(10, None) is None


def test_the_sample_is_the_k_smallest_keys_however_the_input_is_chunked():
    # bottom-k by a hash of the global index: every chunking (and a part's key limit) gives
    # the sample that sorting all the keys gives
    from tiledsimplify.tiles.sampling import BottomK, key_limit, sample_keys
    rng = np.random.default_rng(5)
    n = 40_000
    xyz = rng.random((n, 3))
    for k, seed in [(1_000, 0), (39_999, 2), (50_000, 1), (1, 7)]:
        want = np.sort(np.argsort(sample_keys(np.arange(n), seed), kind="stable")[:k])
        for cuts in ([n], [1, 2, n], sorted(rng.choice(n, 9, replace=False).tolist()) + [n]):
            for limit in (None, key_limit(k, n)):
                sampler = BottomK(k, seed, limit)
                start = 0
                for end in cuts:
                    sampler.add(start, xyz[start:end])
                    start = end
                got = np.sort(sampler.index)
                assert np.array_equal(got, want), (k, cuts, limit)
                assert np.array_equal(sampler.result(), xyz[want])


def test_halo_points_match_brute_force(sp_data, sp_store):
    xyz, _ = sp_data
    _, j_all, t_all = all_cores(sp_store)
    tile_of = np.empty(len(xyz), dtype=np.int64)
    tile_of[j_all] = t_all
    plan = sp_store.plan
    for halo in (None, 0.05):
        h = sp_store.halo if halo is None else halo
        for t in range(sp_store.n_tiles):
            hx, hj = sp_store.halo_points(t, halo)
            near = ((xyz >= plan.lo[t] - h) & (xyz <= plan.hi[t] + h)).all(axis=1)
            expect = np.flatnonzero(near & (tile_of != t))
            assert np.array_equal(hj, expect)
            assert np.array_equal(hx, xyz[expect])
    assert sp_store.halo_points(0)[1].size > 0


def test_near_points_are_the_halo_points_by_owner_and_row(sp_data, sp_store):
    """near_points (a wide view of the refinement) holds what halo_points does — the same
    points, owners and rows, by brute force too — ordered by owner, then row, without the
    neighbours' indices."""
    xyz, _ = sp_data
    plan = sp_store.plan
    for width in (sp_store.halo, 0.05, 0.2):
        for t in range(sp_store.n_tiles):
            got_xyz, owner, row = sp_store.near_points(t, width)
            hx, _, ho, hr = sp_store.halo_points(t, width, owners=True)
            order = np.lexsort((hr, ho))
            assert np.array_equal(owner, ho[order]) and np.array_equal(row, hr[order])
            assert np.array_equal(got_xyz, hx[order])
            for j in np.unique(owner):
                at = owner == j
                assert np.array_equal(sp_store.core_xyz(int(j))[row[at]], got_xyz[at])
            near = ((xyz >= plan.lo[t] - width) & (xyz <= plan.hi[t] + width)).all(axis=1)
            assert len(got_xyz) == int(near.sum()) - sp_store.count(t)


def test_tile_halo_is_saved_once_and_read_back_the_same(sp_data, tmp_path):
    # a store of its own: the module's store must stay free of saved halos for the others
    xyz, attrs = sp_data
    store = TileStore.create(tmp_path / "store", make_chunks(xyz, attrs, 30_000),
                             tile_points=20_000, config=CONFIG, provenance=PROVENANCE,
                             sample_size=50_000)
    for t in range(store.n_tiles):
        want = store.halo_points(t, owners=True)
        first = store.tile_halo(t)
        again = TileStore.open(store.path).tile_halo(t)  # from the saved group
        for w, f, a in zip(want, first, again):
            assert np.array_equal(w, f) and np.array_equal(w, a) and w.dtype == a.dtype
        # each point is the owner's core point at that row
        xyz_t, idx_t, owner, row = again
        for j in np.unique(owner):
            cx, ci = store.core(int(j))
            at = owner == j
            assert np.array_equal(cx[row[at]], xyz_t[at]) and np.array_equal(ci[row[at]],
                                                                              idx_t[at])
    # saved for another halo width: not used
    store._write_group(0, "halo", {k: v[:1] for k, v in zip(
        ("xyz", "index", "owner", "row"), store.halo_points(0, owners=True))},
        {"halo": store.halo * 2})
    assert np.array_equal(store.tile_halo(0)[1], store.halo_points(0)[1])


def test_attributes_round_trip(sp_data, sp_store):
    xyz, attrs = sp_data
    assert sp_store.attribute_names == list(attrs)
    assert sp_store.attribute_dtypes == {k: v.dtype for k, v in attrs.items()}
    for t in range(sp_store.n_tiles):
        _, j = sp_store.core(t)
        got = sp_store.attrs(t)
        for k, v in attrs.items():
            assert got[k].dtype == v.dtype and np.array_equal(got[k], v[j])
    assert list(sp_store.attrs(0, ["rgb"])) == ["rgb"]
    with pytest.raises(InputError):
        sp_store.attrs(0, ["nope"])


def test_a_format_2_store_reads_its_attributes_an_array_each(sp_data, tmp_path):
    """Stores written before format 3 (one zarr array per attribute and tile) still open and
    give the same attributes: made here from a format 3 store by rewriting its layout."""
    import shutil

    import zarr

    from tiledsimplify.tiles.layout import attribute_layout, unpack_attribute
    xyz, attrs = sp_data
    path = tmp_path / "old"
    small = {k: v[:20_000] for k, v in attrs.items()}
    new = TileStore.create(path, make_chunks(xyz[:20_000], small, 7_000), tile_points=5_000,
                           config=CONFIG, provenance=PROVENANCE, sample_size=5_000)
    want = [new.attrs(t) for t in range(new.n_tiles)]
    root = zarr.open_group(str(path), mode="r+")
    for t in range(new.n_tiles):
        packed = root[f"tiles/{t}/attributes"]
        rows = packed[:]
        g = root.require_group(f"tiles/{t}/attrs")
        spec = {k: (v["dtype"], tuple(v["shape"])) for k, v in root.attrs["attributes"].items()}
        layout, _ = attribute_layout(spec)
        for name in spec:
            g.create_array(name, data=unpack_attribute(rows, layout[name]),
                           chunks=(packed.chunks[0],) + layout[name][3])
        shutil.rmtree(path / "tiles" / str(t) / "attributes")
    root.update_attributes({"format_version": 2})
    old = TileStore.open(path)
    for t in range(old.n_tiles):
        got = old.attrs(t)
        assert list(got) == list(want[t])
        for k in got:
            assert got[k].dtype == want[t][k].dtype
            np.testing.assert_array_equal(got[k], want[t][k])


def test_root_attributes(sp_data, sp_store):
    xyz, _ = sp_data
    a = sp_store.root_attrs
    assert a["complete"] is True and a["n_total"] == len(xyz) == sp_store.n_total
    assert sp_store.config == CONFIG
    prov = sp_store.provenance
    assert prov["input"] == "synthetic.las" and prov["tiledsimplify_version"]
    assert prov["zarr_version"].startswith("3") and "T" in prov["created_utc"]
    assert a["attributes"]["rgb"] == {"dtype": "<u2", "shape": [3]}
    assert sp_store.tile_points == 20_000
    assert TilePlan.from_dict(a["plan"]) == sp_store.plan
    # default halo is ten spacings; the spacing estimate is of the right size for this cloud
    assert a["halo_is_default"] is True
    assert sp_store.halo == pytest.approx(10 * sp_store.spacing)
    sub = np.random.default_rng(0).choice(len(xyz), 50_000, replace=False)
    full_spacing, _ = estimate_spacing(xyz, len(xyz))
    assert sp_store.spacing == pytest.approx(full_spacing, rel=0.35)
    assert estimate_spacing(xyz[sub], len(xyz))[1] > full_spacing  # the sample is sparser
    np.testing.assert_array_equal(sp_store.plan.bounds, [xyz.min(0), xyz.max(0)])
    # reopen: same facts
    again = TileStore.open(sp_store.path)
    assert again.plan == sp_store.plan and again.halo == sp_store.halo


def test_given_halo_is_stored(tmp_path):
    xyz = clustered(5_000)
    s = TileStore.create(tmp_path / "s", make_chunks(xyz), tile_points=1000, halo=2.5,
                         config={"p": np.float32(1.5), "path": tmp_path}, provenance={})
    assert s.halo == 2.5 and s.root_attrs["halo_is_default"] is False
    assert s.config == {"p": 1.5, "path": str(tmp_path)}


# ---------------------------------------------------------------------------- store: failures
def test_interrupted_ingest_is_detected(tmp_path):
    xyz = clustered(20_000)
    calls = {"n": 0}

    def source():
        calls["n"] += 1
        for s in range(0, len(xyz), 5_000):
            if calls["n"] == 2 and s >= 10_000:
                raise KeyboardInterrupt  # killed during the writing pass
            yield s, xyz[s:s + 5_000], {}

    path = tmp_path / "s"
    with pytest.raises(KeyboardInterrupt):  # (an input larger than the buffer is read twice)
        TileStore.create(path, source, tile_points=2_000, config={}, provenance={},
                         buffer_points=10_000)
    with pytest.raises(IncompleteStoreError, match="(?s)incomplete.*[Dd]elete.*--store"):
        TileStore.open(path)
    assert issubclass(IncompleteStoreError, (TiledSimplifyError, OSError))
    with pytest.raises(StoreExistsError):
        TileStore.create(path, make_chunks(xyz), tile_points=2_000, config={}, provenance={})
    calls["n"] = 10
    s = TileStore.create(path, make_chunks(xyz), tile_points=2_000, config={}, provenance={},
                         overwrite=True)
    check_partition(s, xyz)


def test_store_path_errors(tmp_path):
    with pytest.raises(StoreError):
        TileStore.open(tmp_path / "missing")
    other = tmp_path / "other"
    other.mkdir()
    (other / "keep.txt").write_text("precious")
    with pytest.raises(StoreExistsError):
        TileStore.create(other, make_chunks(np.zeros((5, 3))), tile_points=2, config={},
                         provenance={}, overwrite=True)
    assert (other / "keep.txt").read_text() == "precious"
    zarr.open_group(str(tmp_path / "plain"), mode="w")
    with pytest.raises(StoreError, match="not a tiledsimplify tile store"):
        TileStore.open(tmp_path / "plain")


@pytest.mark.parametrize("bad, msg", [
    ("gap", "gap"), ("overlap", "overlap"), ("nan", "NaN"), ("attrs", "attributes"),
    ("dtype", "int64"), ("n_total", "n_total"), ("second_pass", "second pass"),
    ("empty", "no points"), ("shape", "shape"),
])
def test_bad_input(tmp_path, bad, msg):
    xyz = np.random.default_rng(0).random((1000, 3))
    parts = [(0, xyz[:500], {"a": np.zeros(500, np.int16)}),
             (500, xyz[500:], {"a": np.zeros(500, np.int16)})]
    kw = {}
    if bad == "gap":
        parts[1] = (501, xyz[501:], {"a": np.zeros(499, np.int16)})
    elif bad == "overlap":
        parts[1] = (499, xyz[500:], {"a": np.zeros(500, np.int16)})
    elif bad == "nan":
        parts[1][1][3] = np.nan
    elif bad == "attrs":
        parts[1] = (500, xyz[500:], {"b": np.zeros(500, np.int16)})
    elif bad == "dtype":
        parts[1] = (500, xyz[500:], {"a": np.zeros(500, np.int64)})
    elif bad == "n_total":
        kw["n_total"] = 999
    elif bad == "empty":
        parts = [(0, np.zeros((0, 3)), {})]
    elif bad == "shape":
        parts[1] = (500, xyz[500:, :2], {"a": np.zeros(500, np.int16)})
    passes = {"n": 0}
    if bad == "second_pass":  # an input that fits in buffer_points is read once
        kw["buffer_points"] = 999

    def source():
        passes["n"] += 1
        if bad == "second_pass" and passes["n"] == 2:
            return iter(parts[:1])
        return iter(parts)

    with pytest.raises(InputError, match=msg):
        TileStore.create(tmp_path / "s", source, tile_points=100, config={}, provenance={},
                         **kw)


# ---------------------------------------------------------------------------- results
def test_results_write_read_and_resume(tmp_path, monkeypatch):
    xyz, attrs = sphere_plane(30_000, seed=9)
    path = tmp_path / "s"
    store = TileStore.create(path, make_chunks(xyz, attrs, 10_000), tile_points=5_000,
                             config={}, provenance={})
    assert store.n_tiles >= 4 and store.done_tiles() == []
    keep = {}
    for t in (0, 2):
        k = store.count(t)
        keep[t] = np.arange(k) % 3 == 0
        store.write_result(t, {"keep": keep[t], "score": np.linspace(0, 1, k)})
    assert store.done_tiles() == [0, 2] and store.is_done(2) and not store.is_done(1)
    assert np.array_equal(store.read_result(0, "keep"), keep[0])
    assert store.read_result(2, "keep").dtype == bool
    assert store.result_names(0) == ["keep", "score"]

    # writing a done tile again needs overwrite; overwrite replaces all arrays
    with pytest.raises(ResultExistsError):
        store.write_result(0, {"keep": keep[0]})
    store.write_result(0, {"keep": ~keep[0]}, overwrite=True)
    assert np.array_equal(store.read_result(0, "keep"), ~keep[0])
    assert store.result_names(0) == ["keep"]
    with pytest.raises(InputError):
        store.read_result(0, "score")

    # a crash between the data and the done mark leaves the tile not done
    real = zarr.Group.create_array
    calls = {"n": 0}

    def flaky(self, name, **kw):
        calls["n"] += 1
        if calls["n"] == 2:
            raise OSError("disk full")
        return real(self, name, **kw)

    monkeypatch.setattr(zarr.Group, "create_array", flaky)
    with pytest.raises(OSError, match="disk full"):
        store.write_result(1, {"keep": np.ones(store.count(1), bool),
                               "score": np.zeros(store.count(1))})
    monkeypatch.undo()
    assert not store.is_done(1)
    with pytest.raises(InputError, match="no finished result"):
        store.read_result(1, "keep")

    # resume: a fresh handle sees exactly the finished tiles, and the rest can be written
    reopened = TileStore.open(path)
    assert reopened.done_tiles() == [0, 2]
    assert reopened.pending_tiles() == [t for t in range(store.n_tiles) if t not in (0, 2)]
    for t in reopened.pending_tiles():
        reopened.write_result(t, {"keep": np.ones(reopened.count(t), bool)})
    assert reopened.done_tiles() == list(range(store.n_tiles))
    assert store.is_done(1)  # the first handle reads the mark from disk, too

    with pytest.raises(InputError, match="core points"):
        store.write_result(3, {"keep": np.ones(3, bool)}, overwrite=True)
    with pytest.raises(InputError):
        store.write_result(3, {"a/b": np.ones(store.count(3), bool)}, overwrite=True)
    with pytest.raises(InputError):
        store.core(store.n_tiles)


def test_arrays_made_from_known_metadata_write_what_zarr_reads(tmp_path):
    """A part of the input makes each tile's arrays from tile 0's metadata, without reading
    their zarr.json (``array_at``): what it writes there, zarr reads back — the attributes
    packed in rows of bytes and unpacked again."""
    import zarr
    from zarr.core.group import GroupMetadata
    from zarr.storage import LocalStore

    from tiledsimplify.tiles.layout import (
        array_at,
        array_templates,
        attribute_layout,
        pack_attributes,
        unpack_attribute,
    )
    spec = {"intensity": (np.dtype("uint16"), ()), "rgb": (np.dtype("uint16"), (3,))}
    templates = array_templates(spec, 1000, 5000)
    assert sorted(templates) == ["attributes", "index", "xyz"]
    nodes = {"tiles": GroupMetadata()}
    for t in range(3):
        nodes[f"tiles/{t}"] = GroupMetadata()
        for key, meta in templates.items():
            nodes[f"tiles/{t}/{key}"] = meta
    store = LocalStore(tmp_path)
    zarr.open_group(store, mode="w")
    dict(zarr.create_hierarchy(store=store, nodes=nodes))
    meta = zarr.open_group(store, mode="r")["tiles/0/attributes"].metadata
    layout, width = attribute_layout(spec)
    assert width == 8
    rgb = np.arange(15, dtype=np.uint16).reshape(5, 3)
    intensity = np.array([1, 2, 65535, 0, 7], dtype=np.uint16)
    rows = pack_attributes({"rgb": rgb, "intensity": intensity}, layout, width, 5)
    array_at(store, "tiles/2/attributes", meta)[1000:1005] = rows
    back = zarr.open_group(store, mode="r")["tiles/2/attributes"]
    assert back.shape == (5000, 8) and back.dtype == np.uint8
    np.testing.assert_array_equal(unpack_attribute(back[1000:1005], layout["rgb"]), rgb)
    np.testing.assert_array_equal(unpack_attribute(back[1000:1005], layout["intensity"]),
                                  intensity)
    assert not back[:1000].any() and not back[1005:].any()


def test_packed_attributes_come_back_as_they_went_in():
    from tiledsimplify.tiles.layout import (
        attribute_layout,
        pack_attributes,
        unpack_attribute,
    )
    rng = np.random.default_rng(8)
    spec = {"flag": (np.dtype(bool), ()), "gps_time": (np.dtype("float64"), ()),
            "pair": (np.dtype("int32"), (2,)), "c": (np.dtype("uint8"), ()),
            "f": (np.dtype("float32"), (3,))}
    layout, width = attribute_layout(spec)
    assert width == 1 + 8 + 8 + 1 + 12
    for m in (0, 1, 1000):
        attrs = {"flag": rng.random(m) < 0.5, "gps_time": rng.normal(size=m) * 1e9,
                 "pair": rng.integers(-2**31, 2**31, (m, 2)).astype(np.int32),
                 "c": rng.integers(0, 256, m).astype(np.uint8),
                 "f": rng.random((m, 3)).astype(np.float32)[:, ::-1]}  # not contiguous
        rec = pack_attributes(attrs, layout, width, m)
        assert rec.shape == (m, width)
        for name, values in attrs.items():
            got = unpack_attribute(rec, layout[name])
            assert got.dtype == values.dtype and got.shape == values.shape
            np.testing.assert_array_equal(got, values)
