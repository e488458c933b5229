"""dask.distributed workers are checked before any work: they must reach the tile store by
its path, write in its directory and run this client's code; a scheduler without workers is
named instead of waited on forever. Workers that cannot see the store run in a mount namespace
of their own (``unshare -m``, a tmpfs over the store's directory), as on another machine."""

import importlib
import os
import shutil
import subprocess
import sys
import tempfile
import time
from types import SimpleNamespace

import numpy as np
import pytest

from tiledsimplify.errors import InputError, TiledSimplifyError
from tiledsimplify.io import read_points
from tiledsimplify.pipeline import run
from tiledsimplify.pipeline import workers as W

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def bunny(data_dir, tmp_path_factory):
    X = read_points(data_dir / "meshes" / "stanford_bunny" / "bun_zipper_res2.ply.gz")
    path = tmp_path_factory.mktemp("in") / "bunny.npy"
    np.save(path, X)
    return path


@pytest.fixture
def scheduler():
    """A scheduler with no workers, and a client of it."""
    with distributed.LocalCluster(n_workers=0, processes=True, dashboard_address=":0") as c, \
            distributed.Client(c) as client:
        yield client


def _namespaces(tmp_path):
    """Whether this process may mount a tmpfs and a read-only bind in a namespace of its own."""
    if shutil.which("unshare") is None:
        return False
    d = tmp_path / "probe"
    d.mkdir()
    cmd = f"mount -t tmpfs tmpfs '{d}' && mount --bind '{d}' '{d}' && mount -o remount,ro,bind '{d}'"
    return subprocess.run(["unshare", "-m", "--propagation", "private", "sh", "-c", cmd],
                          capture_output=True, check=False).returncode == 0


@pytest.fixture
def worker_elsewhere(scheduler, tmp_path):
    """Start a worker of ``scheduler`` in a mount namespace of its own; ``start(hide, how)``
    mounts a fresh tmpfs over ``hide`` ("hidden") or remounts it read-only ("read-only")."""
    if not _namespaces(tmp_path):
        pytest.skip("needs `unshare -m` (a mount namespace) to stand in for another machine")
    procs = []

    def start(hide, how):
        mount = (f"mount -t tmpfs tmpfs '{hide}'" if how == "hidden" else
                 f"mount --bind '{hide}' '{hide}' && mount -o remount,ro,bind '{hide}'")
        cmd = (f"{mount} && cd / && exec '{sys.executable}' -m distributed.cli.dask_worker "
               f"{scheduler.scheduler.address} --nthreads 1 --no-dashboard")
        procs.append(subprocess.Popen(["unshare", "-m", "--propagation", "private", "sh", "-c",
                                       cmd], stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL))
        scheduler.wait_for_workers(1, timeout=60)
    yield start
    for p in procs:
        p.terminate()
        p.wait(timeout=30)


def test_a_worker_that_cannot_see_the_store_is_named_before_any_work(bunny, tmp_path,
                                                                      scheduler,
                                                                      worker_elsewhere,
                                                                      monkeypatch):
    path = bunny
    shared = tmp_path / "not_shared"
    shared.mkdir()
    worker_elsewhere(shared, "hidden")
    store = shared / "st.zarr"
    with pytest.raises(InputError, match=r"not_shared: 1 of 1 dask workers cannot see the tile "
                                         r"store's directory \(tcp://.*\).* file system every "
                                         r"worker mounts"):
        run(path, tmp_path / "out.npy", ratio=0.2, client=scheduler, store=store)
    assert not store.exists() and not (tmp_path / "out.npy").exists()
    assert [p.name for p in shared.iterdir()] == [".st.zarr.lock"]  # no marker left behind
    # the temporary store: made under TMPDIR on this machine, and the message says so
    monkeypatch.setattr(tempfile, "tempdir", str(shared))
    with pytest.raises(InputError, match=r"temporary tile store is made in .*not_shared.* "
                                         r"or set TMPDIR"):
        run(path, tmp_path / "out.npy", ratio=0.2, client=scheduler)
    assert [p.name for p in shared.iterdir()] == [".st.zarr.lock"]


def test_a_worker_that_cannot_write_beside_the_store_is_named(bunny, tmp_path, scheduler,
                                                             worker_elsewhere):
    path = bunny
    shared = tmp_path / "ro"
    shared.mkdir()
    worker_elsewhere(shared, "read-only")
    with pytest.raises(InputError, match=r"ro: 1 of 1 dask workers cannot write in the tile "
                                         r"store's directory \(tcp://.*OSError: Read-only"):
        run(path, tmp_path / "out.npy", ratio=0.2, client=scheduler, store=shared / "s.zarr")
    assert not (shared / "s.zarr").exists()


def test_a_scheduler_without_workers_is_named_not_waited_on(bunny, tmp_path, scheduler,
                                                             monkeypatch):
    path = bunny
    monkeypatch.setattr(W, "WORKER_WAIT", 0.5)
    t = time.perf_counter()
    with pytest.raises(TiledSimplifyError, match=r"tcp://.*: the dask scheduler has no workers "
                                                 r"\(none joined within 0 s\)\. Start them "
                                                 r"\(`dask worker tcp://"):
        run(path, tmp_path / "out.npy", ratio=0.2, client=scheduler,
            store=tmp_path / "s.zarr")
    assert time.perf_counter() - t < 30
    assert not (tmp_path / "s.zarr").exists() and not (tmp_path / "out.npy").exists()


def test_a_relative_store_is_found_by_workers_in_another_directory(bunny, tmp_path,
                                                                   monkeypatch):
    # `--store st.zarr`: the workers run elsewhere (here: another working directory), so the
    # path they are given is absolute
    path = bunny
    monkeypatch.chdir(tmp_path)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as c, \
            distributed.Client(c) as client:
        client.run(os.chdir, "/")
        s = run(path, "out.npy", ratio=0.2, client=client, store="st.zarr")
    assert s.store == str(tmp_path / "st.zarr")
    assert len(np.load(tmp_path / "out.npy")) == s.target == s.n_output


class _Remote:
    """A client of one worker whose answer to the check is ``reply(function, *args)``."""
    scheduler = SimpleNamespace(address="tcp://10.0.0.1:8786")

    def __init__(self, reply):
        self.reply = reply

    def scheduler_info(self):
        return {"workers": {"tcp://10.0.0.2:40000": {}}}

    def run(self, function, *args, on_error="raise", workers=None, wait=True):
        if function is W.load_kernels:  # after the check, not waited for
            assert workers == ["tcp://10.0.0.2:40000"] and wait is False
            return None
        return {"tcp://10.0.0.2:40000": self.reply(function, *args)}


def test_a_worker_running_other_code_is_named(tmp_path):
    ok = _Remote(lambda f, *a: f(*a))  # the real probe, in this process: same code
    assert W.check_workers(ok, tmp_path, temporary=False) == 1
    other = _Remote(lambda f, *a: {**f(*a), "version": "0.0.9", "code": "0123456789ab"})
    with pytest.raises(InputError, match=r"tcp://10.0.0.1:8786: 1 of 1 dask workers run other "
                                         r"tiledsimplify code than this client \(tiledsimplify "
                                         r".*, sources [0-9a-f]{12}\): tcp://10.0.0.2:40000 on "
                                         r".* \(tiledsimplify 0.0.9, sources 0123456789ab\)"):
        W.check_workers(other, tmp_path, temporary=False)
    missing = _Remote(lambda f, *a: ModuleNotFoundError("No module named 'tiledsimplify'"))
    with pytest.raises(InputError, match=r"cannot run tiledsimplify's check: tcp://10.0.0.2:40000 "
                                         r"\(ModuleNotFoundError: No module named 'tiledsimplify'"
                                         r"\)\. Install tiledsimplify in the workers'"):
        W.check_workers(missing, tmp_path, temporary=False)
    assert list(tmp_path.iterdir()) == []  # the marker is removed whatever the answer


def test_code_id_follows_the_sources(tmp_path, monkeypatch):
    a = W.code_id()
    assert a == W.code_id() and len(a) == 12
    # a copy of the package with one byte changed hashes differently
    import tiledsimplify
    pkg = tmp_path / "tiledsimplify"
    shutil.copytree(os.path.dirname(tiledsimplify.__file__), pkg,
                    ignore=shutil.ignore_patterns("__pycache__"))
    fake = pkg / "pipeline" / "workers.py"
    monkeypatch.setattr(W, "__file__", str(fake))
    assert W.code_id() == a
    with open(pkg / "core" / "heap.py", "a") as fh:
        fh.write("\n")
    assert W.code_id() != a


@pytest.fixture(scope="module")
def small_worker():
    """One worker process with a 400 MB memory limit, on a scheduler that gives a task up the
    first time its worker dies."""
    import dask
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}), \
            distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                     memory_limit="400MB", dashboard_address=":0") as c, \
            distributed.Client(c) as client:
        yield client


def test_workers_short_of_memory_for_a_tile_are_warned_of(small_worker, tmp_path, caplog):
    with caplog.at_level("WARNING", logger="tiledsimplify"):
        assert W.check_workers(small_worker, tmp_path, temporary=False, tile_points=40_000) == 1
    assert not caplog.records  # 300 MB + 24 MB fits in 400 MB
    with caplog.at_level("WARNING", logger="tiledsimplify"):
        W.check_workers(small_worker, tmp_path, temporary=False, tile_points=500_000)
    (got,) = [r.getMessage() for r in caplog.records]
    assert got.startswith("1 dask worker(s) may run out of memory: tcp://")
    assert "has 400 MB for 1 thread(s), needs ~600" in got
    assert "--tile-points 166,666 or less" in got


def test_a_tile_that_kills_its_workers_is_named_with_the_likely_cause(small_worker):
    import importlib

    import dask
    R = importlib.import_module("tiledsimplify.pipeline.run")
    # a tile task's key ends with its tile and the run's token (run._tile_tasks)
    task = dask.delayed(os._exit, pure=False)(1, dask_key_name="simplify-tile-0000003-7-f00d")
    with pytest.raises(TiledSimplifyError, match=r"^tile 7 \(tiles\): the 1 dask worker\(s\) "
                                                 r"that ran it all died \(the last tcp://.*\), "
                                                 r"most likely out of memory.*--memory-limit.*"
                                                 r"--tile-points"):
        R._compute([task], None, None, small_worker, False, "tiles")


def test_cold_workers_compile_once_a_machine_while_the_input_is_read(bunny, tmp_path, caplog):
    # two workers with an empty kernel cache: one of them compiles every kernel ahead in two
    # processes, both wait for it (55-66 s against 30-38 s for the Bunny, README), same output
    path = bunny
    cache = tmp_path / "cache"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0",
                                  env={"NUMBA_CACHE_DIR": str(cache)}) as c, \
            distributed.Client(c) as client:
        with caplog.at_level("INFO", logger="tiledsimplify"):
            run(path, tmp_path / "cold.npy", ratio=0.2, client=client, tile_points=3000)
        cold = client.run(lambda: bool(importlib.import_module(
            "tiledsimplify.core.compile_cache").missing()))  # by value: runs on the workers
        assert cold and not any(cold.values())
    assert "compiling the kernels ahead on " in caplog.text and "(2 processes)" in caplog.text
    assert any(cache.rglob("*.nbi"))
    run(path, tmp_path / "warm.npy", ratio=0.2, tile_points=3000, workers=2)
    assert (tmp_path / "cold.npy").read_bytes() == (tmp_path / "warm.npy").read_bytes()


def test_warm_workers_load_the_kernels_while_the_input_is_read(tmp_path):
    # a worker whose cache holds the kernels loads them all once checked, before any task
    from tiledsimplify.core import compile_cache
    compile_cache.compile_all(2)  # this machine's cache, which the worker shares: warm

    def loaded():
        from tiledsimplify.core import compile_cache as c
        return [sig in c._dispatcher(kernel).signatures for kernel, _, sig in
                c.read_signatures()]

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as c, \
            distributed.Client(c) as client:
        assert not any(next(iter(client.run(loaded).values())))  # a fresh worker: none yet
        assert W.check_workers(client, tmp_path, temporary=False) == 1
        deadline = time.monotonic() + 60
        while not all(got := next(iter(client.run(loaded).values()))):
            assert time.monotonic() < deadline, got
            time.sleep(0.2)
        assert len(got) == len(compile_cache.read_signatures()) > 20


def test_an_input_the_workers_cannot_read_is_ingested_by_the_client(tmp_path, caplog):
    from tiledsimplify.io.sources import open_source
    run_module = importlib.import_module("tiledsimplify.pipeline.run")
    X = np.random.default_rng(0).random((5000, 3))
    np.save(tmp_path / "a.npy", X)
    src = open_source(tmp_path / "a.npy", chunk_points=500)
    size = (tmp_path / "a.npy").stat().st_size
    path = str((tmp_path / "a.npy").absolute())
    # what a worker answers: a file it reads as the client does, one of another size, none
    assert W.unreadable([(path, size)]) == []
    assert W.unreadable([(path, size + 1), (path + ".gone", 3)]) == [path, path + ".gone"]

    class Client:  # two workers of 2 threads; the second cannot read the input
        def __init__(self, blind):
            self.blind = blind

        def nthreads(self):
            return {"tcp://a:1": 2, "tcp://b:2": 2}

        def run(self, func, files):
            return {"tcp://a:1": func(files),
                    "tcp://b:2": func([(p + ".elsewhere", s) for p, s in files]
                                      if self.blind else files)}

    old = run_module.INGEST_PART_POINTS
    run_module.INGEST_PART_POINTS = 500
    try:
        parts = run_module._ingest_parts(src, 5000, None, None, Client(blind=False))
        assert len(parts) == 10 and parts[0].mapped[0] == path
        with caplog.at_level("INFO", logger="tiledsimplify"):
            assert run_module._ingest_parts(src, 5000, None, None, Client(blind=True)) is None
    finally:
        run_module.INGEST_PART_POINTS = old
    assert any("ingest in this client: 1 of 2 dask workers cannot read the input" in
               r.getMessage() and "tcp://b:2" in r.getMessage() for r in caplog.records)


def test_tasks_left_without_workers_fail_saying_what_to_do():
    """With the scheduler's ``no-workers-timeout`` set, a stage whose workers are all gone
    fails with what to do (dask's NoWorkerError names a task key), not a traceback; without
    it dask waits for new workers (README, "Cluster workers")."""
    import dask

    from tiledsimplify.pipeline.run import _compute
    with dask.config.set({"distributed.scheduler.no-workers-timeout": "1s"}), \
            distributed.LocalCluster(n_workers=0, processes=False, dashboard_address=None) as c, \
            distributed.Client(c) as client, \
            pytest.raises(TiledSimplifyError, match=r"tiles: no dask worker was left to run the "
                                                    r"tasks .*with --store it goes on"):
        _compute([dask.delayed(sum)([1, 2])], None, None, client, False)
