"""Compiling the kernels ahead, in parallel processes (core/compile_cache.py, warmup.py)."""

import json
import os
import subprocess
import sys

import numba
import numpy as np
import pytest

from tiledsimplify import cli, warmup
from tiledsimplify.core import compile_cache


def test_recorded_signatures_are_what_the_package_calls():
    """The recorded file lists exactly the top-level kernels the workloads call, with their
    argument types: a kernel whose arguments changed would otherwise compile twice."""
    called = warmup.called_kernels()
    recorded = {}
    for kernel, seconds, sig in compile_cache.read_signatures():
        assert seconds > 0
        recorded.setdefault(kernel, set()).add(repr(sig))
    assert recorded == called, (
        "core/kernel_signatures.txt is stale: run python -m tiledsimplify.warmup --record")


def test_signatures_read_back():
    sig = (numba.typeof(np.zeros((3, 3))), numba.typeof(np.zeros(3, np.int32)), numba.int64,
           numba.float64, numba.typeof(np.zeros(2, bool)))
    assert compile_cache.parse_signature(repr(sig)) == sig
    assert compile_cache.parse_signature("(Literal[int](0),)") is None
    assert compile_cache.parse_signature("__import__('os')") is None
    assert compile_cache.parse_signature("float64") is None  # not a tuple of arguments


def test_unreadable_entries_are_skipped(tmp_path):
    good = (numba.typeof(np.zeros(3)),)
    path = tmp_path / "sigs.txt"
    path.write_text("# comment\n"
                    f"a.b:c\t1.5\t{good!r}\n"
                    "a.b:d\tnot-a-number\t(int64,)\n"
                    "a.b:e\t2.0\t(NoSuchType(1),)\n"
                    "too\tfew\n")
    assert compile_cache.read_signatures(path) == [("a.b:c", 1.5, good)]
    assert compile_cache.read_signatures(tmp_path / "absent.txt") == []


def test_partition_is_longest_first_onto_the_least_loaded():
    entries = [("k:a", 10.0, ()), ("k:b", 6.0, ()), ("k:c", 5.0, ()), ("k:d", 4.0, ()),
               ("k:e", 1.0, ()), ("k:b", 1.0, ())]  # two signatures of b: one kernel, 7 s
    parts = compile_cache.partition(entries, 2)
    assert parts == [["k:a", "k:d"], ["k:b", "k:c", "k:e"]]  # loads 14 and 13
    assert compile_cache.partition(entries, 1) == [["k:a", "k:b", "k:c", "k:d", "k:e"]]
    assert len(compile_cache.partition(entries, 9)) == 5  # no empty process
    assert compile_cache.partition([], 4) == []


_IN_FRESH_CACHE = """
import json, sys
from tiledsimplify.core import compile_cache as c
print(json.dumps([c.compile_all(2, sys.argv[1]), c.cache_dir()]))
"""


def test_compile_all_fills_a_cold_cache_once(tmp_path):
    """Two cheap kernels compiled in two processes into an empty cache: both are then cached
    (a second call starts nothing), in the directory the package's kernels load from."""
    keep = {"tiledsimplify.core.zorder:_keys", "tiledsimplify.core.adjacency:_is_sorted_upper"}
    lines = [line for line in compile_cache.SIGNATURES.read_text().splitlines()
             if line.split("\t")[0] in keep]
    assert len(lines) == 2
    sigs = tmp_path / "sigs.txt"
    sigs.write_text("\n".join(lines) + "\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def once():
        out = subprocess.run([sys.executable, "-c", _IN_FRESH_CACHE, str(sigs)], env=env,
                             check=True, capture_output=True, text=True).stdout
        return json.loads(out)

    first, where = once()
    assert first["compiled"] == 2 and first["jobs"] == 2 and first["failed"] == []
    assert where.startswith(str(tmp_path / "cache"))
    index = sorted(p.name for p in (tmp_path / "cache").rglob("*.nbi"))
    assert any(name.startswith("zorder._keys-") for name in index)
    assert any(name.startswith("adjacency._is_sorted_upper-") for name in index)
    second, _ = once()
    assert second == {"compiled": 0, "seconds": 0.0, "jobs": 0, "failed": []}


def test_cli_compile_rejects_no_jobs(caplog):
    assert cli.main(["compile", "--jobs", "0"]) == cli.EXIT_INPUT
    assert "--jobs must be at least 1" in caplog.text


@pytest.mark.parametrize("argv", [[], ["--worker"], ["--worker", "only-a-path"]])
def test_worker_usage(argv):
    done = subprocess.run([sys.executable, "-m", "tiledsimplify.core.compile_cache", *argv],
                          capture_output=True, text=True)
    assert done.returncode != 0 and "usage" in done.stderr


def test_a_compile_ahead_holds_a_lock_that_tile_tasks_wait_on(tmp_path, monkeypatch):
    """start() takes the machine's compile lock before it returns and drops it when done;
    wait() blocks while any process (here another open file of this one) holds it; a second
    start() while one compiles does not block and starts nothing."""
    import fcntl
    import threading
    monkeypatch.setattr(compile_cache, "cache_dir", lambda: str(tmp_path))
    lock = tmp_path / compile_cache.LOCK_NAME
    other = open(lock, "a+")  # noqa: SIM115 - held across the checks below
    fcntl.flock(other, fcntl.LOCK_EX)  # a compile elsewhere on this machine
    waiter = threading.Thread(target=compile_cache.wait)
    waiter.start()
    waiter.join(0.5)
    assert waiter.is_alive()  # waits for it
    monkeypatch.setattr(compile_cache, "missing", lambda *a: ["a kernel"])
    assert compile_cache.start(2) is None  # someone compiles already: nothing to start
    fcntl.flock(other, fcntl.LOCK_UN)
    other.close()
    waiter.join(10)
    assert not waiter.is_alive()
    # our own compile: the lock is held from start() until compile_all returns
    release = threading.Event()
    monkeypatch.setattr(compile_cache, "compile_all", lambda jobs: release.wait(10))
    thread = compile_cache.start(2)
    assert thread is not None
    probe = open(lock, "a+")  # noqa: SIM115
    with pytest.raises(BlockingIOError):
        fcntl.flock(probe, fcntl.LOCK_SH | fcntl.LOCK_NB)
    release.set()
    thread.join(10)
    fcntl.flock(probe, fcntl.LOCK_SH | fcntl.LOCK_NB)  # free again
    probe.close()
    compile_cache.wait()  # at once when nobody compiles


_LOAD = """
import json, sys
from tiledsimplify.core import compile_cache as c
entries = c.read_signatures(sys.argv[1])
loaded = c.load(entries)
out = {"loaded": loaded}
for kernel, _, sig in entries:
    d = c._dispatcher(kernel)
    out[kernel] = {"has": sig in d.signatures, "hits": sum(d.stats.cache_hits.values()),
                   "misses": sum(d.stats.cache_misses.values())}
print(json.dumps(out))
"""


def test_load_takes_the_cached_kernels_and_compiles_none(tmp_path):
    """load() brings every recorded kernel the cache holds into the process from the cache (a
    cache hit, no compile) and leaves one it lacks to its first call (not compiled)."""
    cached = {"tiledsimplify.core.zorder:_keys", "tiledsimplify.core.adjacency:_is_sorted_upper"}
    absent = "tiledsimplify.core.adjacency:_fill_sorted"
    lines = compile_cache.SIGNATURES.read_text().splitlines()
    pick = [line for line in lines if line.split("\t")[0] in cached]
    other = [line for line in lines if line.split("\t")[0] == absent][:1]
    assert len(pick) == 2 and len(other) == 1
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    warm = tmp_path / "warm.txt"
    warm.write_text("\n".join(pick) + "\n")
    subprocess.run([sys.executable, "-c", _IN_FRESH_CACHE, str(warm)], env=env, check=True,
                   capture_output=True)
    every = tmp_path / "all.txt"
    every.write_text("\n".join(pick + other) + "\n")
    out = json.loads(subprocess.run([sys.executable, "-c", _LOAD, str(every)], env=env,
                                    check=True, capture_output=True, text=True).stdout)
    assert out["loaded"] == 2
    for kernel in cached:
        assert out[kernel] == {"has": True, "hits": 1, "misses": 0}
    assert out[absent] == {"has": False, "hits": 0, "misses": 0}
