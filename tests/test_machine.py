"""What a run may use of the machine: CPUs by affinity and quota, memory by cgroup limits, and
the checks built on them (local worker count, the in-memory command)."""

import importlib
import logging
import os
import subprocess
import sys

import numpy as np
import pytest

from tiledsimplify import machine
from tiledsimplify.cli import EXIT_INPUT, EXIT_OK, check_memory, main
from tiledsimplify.core.simplify import PEAK_BYTES_PER_POINT
from tiledsimplify.errors import InputError

run_mod = importlib.import_module("tiledsimplify.pipeline.run")


def _proc(tmp_path, cgroup_lines, available_kb=8_000_000):
    proc = tmp_path / "proc"
    (proc / "self").mkdir(parents=True)
    (proc / "meminfo").write_text(f"MemTotal:       16000000 kB\nMemFree:         100 kB\n"
                                  f"MemAvailable:   {available_kb} kB\n")
    (proc / "self" / "cgroup").write_text("\n".join(cgroup_lines) + "\n")
    return proc


def _files(d, **files):
    d.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (d / name.replace("_", ".", 1)).write_text(text)


def test_available_memory_is_meminfos_without_a_cgroup_limit(tmp_path):
    proc = _proc(tmp_path, ["0::/"])
    root = tmp_path / "cg"
    _files(root, memory_max="max\n", memory_current="123\n")
    assert machine.available_memory(proc, root) == 8_000_000 * 1024
    # cgroup v1 says "no limit" with a huge number
    proc = _proc(tmp_path / "v1", ["4:memory:/job", "0::/"])
    _files(root / "memory" / "job", memory_limit_in_bytes="9223372036854771712\n",
           memory_usage_in_bytes="5000\n")
    assert machine.available_memory(proc, root) == 8_000_000 * 1024


def test_available_memory_takes_the_tightest_cgroup_limit(tmp_path):
    # a job's cgroup (v2) under a parent with a tighter limit; the inactive file cache is
    # reclaimed before the OOM killer acts, so it does not count as used
    proc = _proc(tmp_path, ["0::/batch/job"])
    root = tmp_path / "cg"
    _files(root / "batch" / "job", memory_max="4000000000\n", memory_current="1500000000\n",
           memory_stat="anon 1000000000\ninactive_file 500000000\n")
    assert machine.available_memory(proc, root) == 4_000_000_000 - 1_000_000_000
    _files(root / "batch", memory_max="2000000000\n", memory_current="1800000000\n",
           memory_stat="inactive_file 0\n")
    assert machine.available_memory(proc, root) == 200_000_000
    # cgroup v1: limit_in_bytes and usage_in_bytes, total_inactive_file in memory.stat
    proc = _proc(tmp_path / "v1", ["9:cpu,cpuacct:/x", "4:memory:/slurm/job_7"])
    _files(root / "memory" / "slurm" / "job_7", memory_limit_in_bytes="3000000000\n",
           memory_usage_in_bytes="2500000000\n", memory_stat="total_inactive_file 1000000000\n")
    assert machine.available_memory(proc, root) == 1_500_000_000
    # the host has less than the limit allows: the host's
    proc = _proc(tmp_path / "small", ["4:memory:/slurm/job_7"], available_kb=1000)
    assert machine.available_memory(proc, root) == 1000 * 1024


def test_available_memory_is_none_where_nothing_can_be_read(tmp_path):
    assert machine.available_memory(tmp_path / "none", tmp_path / "none") is None


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="needs CPU affinity and 2 CPUs")
def test_a_process_pinned_to_one_cpu_runs_one_worker():
    # os.cpu_count() counts the host's cores (a Slurm job given 4 of 64 saw 64)
    code = ("import os, importlib; os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]});"
            "from tiledsimplify import machine;"
            "r = importlib.import_module('tiledsimplify.pipeline.run');"
            "print(os.cpu_count(), machine.cpus(),"
            " r.local_workers('threads', None, None, 100000, room=10**12),"
            " r.local_workers('processes', None, None, 100000, room=10**12))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert int(out[0]) >= 2
    assert out[1:] == ["1", "1", "1"]


def test_local_workers_fit_the_memory_left(caplog, monkeypatch):
    cpus = 4  # more than fit below, whatever the machine (on 2 CPUs the cap was never asked)
    monkeypatch.setattr(machine, "cpus", lambda: cpus)
    tile = 500_000  # ~300 MB a thread by workers.tile_memory_mb
    per = run_mod.tile_memory_mb(tile) - run_mod.WORKER_BASE_MB
    plenty = 10 ** 12
    with caplog.at_level(logging.WARNING, logger="tiledsimplify"):
        assert run_mod.local_workers("threads", None, None, tile, room=plenty) == cpus
        assert run_mod.local_workers("threads", 3, None, tile, room=plenty) == 3
        assert run_mod.local_workers("synchronous", None, None, tile, room=1) == 1
        client = object()  # a cluster's workers are checked by check_workers
        assert run_mod.local_workers("threads", 5, client, tile, room=1) == 5
    assert caplog.text == ""
    # room for two threads' tiles (and the spare): the default runs two, warned
    room = (run_mod.LOCAL_SPARE_MB + 2.5 * per) * 1e6
    with caplog.at_level(logging.WARNING, logger="tiledsimplify"):
        got = run_mod.local_workers("threads", None, None, tile, room=room)
    assert got == min(cpus, 2)
    if cpus > 2:
        assert "running 2 instead of one per CPU" in caplog.text
    caplog.clear()
    # given workers are kept (the user asked), warned with what would fit
    with caplog.at_level(logging.WARNING, logger="tiledsimplify"):
        assert run_mod.local_workers("threads", 8, None, tile, room=room) == 8
    assert "8 threads with tiles of up to 500,000 points need about" in caplog.text
    assert "Give --workers 2 or --tile-points" in caplog.text
    caplog.clear()
    # processes: each holds an interpreter and the kernels too
    room = (run_mod.LOCAL_SPARE_MB + 1.5 * (per + run_mod.WORKER_BASE_MB)) * 1e6
    assert run_mod.local_workers("processes", None, None, tile, room=room) == 1
    # not even one tile fits: one worker, and a tile size that would
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="tiledsimplify"):
        assert run_mod.local_workers("threads", None, None, tile,
                                     room=(run_mod.LOCAL_SPARE_MB + 100) * 1e6) == 1
    assert "1 thread with tiles" in caplog.text and "needs about" in caplog.text
    smaller = int(caplog.text.split("--tile-points ")[1].split()[0].replace(",", ""))
    assert 0 < smaller < tile
    assert run_mod.tile_memory_mb(smaller) - run_mod.WORKER_BASE_MB <= 100 + 1e-6


def test_check_memory_names_the_file_and_the_tiled_command():
    check_memory("a.laz", 1000, room=10 ** 9)
    with pytest.raises(InputError) as err:
        check_memory("big.laz", 30_000_000, room=8 * 10 ** 9)
    msg = str(err.value)
    assert msg.startswith("big.laz: simplifying 30,000,000 points in memory needs about 27.7 GB")
    assert "8.0 GB of memory is available" in msg and "tiledsimplify run big.laz" in msg


def test_simplify_refuses_a_cloud_too_big_for_the_memory_left(tmp_path, monkeypatch, caplog):
    rng = np.random.default_rng(3)
    path = tmp_path / "in.npy"
    np.save(path, rng.random((2000, 3)))
    out = tmp_path / "out.npy"
    need = 2000 * (PEAK_BYTES_PER_POINT + 24)
    monkeypatch.setattr(machine, "available_memory", lambda *a, **k: need // 2)
    assert main(["simplify", str(path), str(out), "--ratio", "0.5", "-q"]) == EXIT_INPUT
    assert "tiledsimplify run" in caplog.text and str(path) in caplog.text
    assert not out.exists()
    monkeypatch.setattr(machine, "available_memory", lambda *a, **k: need * 2)
    assert main(["simplify", str(path), str(out), "--ratio", "0.5", "-q"]) == EXIT_OK
    assert len(np.load(out)) == 1000


def test_a_run_short_of_memory_runs_fewer_workers_for_the_same_output(tmp_path, monkeypatch,
                                                                       caplog):
    rng = np.random.default_rng(4)
    xy = rng.random((6000, 2)) * 10
    path = tmp_path / "in.npy"
    np.save(path, np.c_[xy, np.sin(xy[:, 0])])
    per = run_mod.tile_memory_mb(1500) - run_mod.WORKER_BASE_MB
    outs = []
    for name, room in (("plenty", 10 ** 12), ("one", (run_mod.LOCAL_SPARE_MB + 1.5 * per) * 1e6)):
        monkeypatch.setattr(machine, "available_memory", lambda *a, r=room, **k: r)
        monkeypatch.setattr(machine, "cpus", lambda: 4)
        capped = []  # the C allocator's arenas: one per worker thread the run starts
        monkeypatch.setattr(machine, "cap_malloc_arenas", capped.append)
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="tiledsimplify"):
            summary = run_mod.run(path, tmp_path / f"{name}.npy", ratio=0.2, tile_points=1500)
        outs.append(np.load(tmp_path / f"{name}.npy"))
        assert ("running 1 instead of one per CPU" in caplog.text) == (name == "one")
        assert summary.workers == (1 if name == "one" else 4)
        assert capped == [summary.workers]
    np.testing.assert_array_equal(outs[0], outs[1])


def test_evaluate_refuses_clouds_too_big_for_the_memory_left(tmp_path, monkeypatch, caplog,
                                                            capsys):
    from tiledsimplify import metrics
    rng = np.random.default_rng(5)
    X = rng.random((3000, 3))
    orig, kept = tmp_path / "orig.npy", tmp_path / "kept.npy"
    np.save(orig, X)
    np.save(kept, X[::4])
    need = (3000 + 750) * (metrics.EVALUATE_BYTES_PER_POINT + 24)
    monkeypatch.setattr(machine, "available_memory", lambda *a, **k: need - 1)
    assert main(["evaluate", str(orig), str(kept)]) == EXIT_INPUT
    assert f"{orig} and {kept}: evaluating 3,750 points in memory needs about" in caplog.text
    assert "crop both clouds to the same region" in caplog.text
    monkeypatch.setattr(machine, "available_memory", lambda *a, **k: need)
    assert main(["evaluate", str(orig), str(kept)]) == EXIT_OK
    assert "hausdorff" in capsys.readouterr().out

    # report holds both too
    out = tmp_path / "rep"
    monkeypatch.setattr(machine, "available_memory", lambda *a, **k: need - 1)
    assert main(["report", str(orig), str(kept), "-o", str(out)]) == EXIT_INPUT
    assert f"{orig} and {kept}: reporting on 3,750 points in memory needs about" in caplog.text
    assert "Report on a part: crop both clouds" in caplog.text and not out.exists()


_ARENAS = """
import ctypes, re, sys, tempfile, threading
import numpy as np
from tiledsimplify import machine
print(machine.cap_malloc_arenas(int(sys.argv[1])))
gate = threading.Barrier(6)
def work():  # six threads alive at once, each allocating: glibc gives each its own arena
    gate.wait()
    for _ in range(20):
        np.ones(50_000).sum()
    gate.wait()
threads = [threading.Thread(target=work) for _ in range(6)]
for t in threads:
    t.start()
for t in threads:
    t.join()
libc = ctypes.CDLL(None)
libc.fopen.restype = ctypes.c_void_p
with tempfile.NamedTemporaryFile(suffix=".xml") as f:
    fp = ctypes.c_void_p(libc.fopen(f.name.encode(), b"w"))
    libc.malloc_info(0, fp)
    libc.fclose(fp)
    print(len(re.findall("<heap nr=", open(f.name).read())))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux") or not hasattr(os, "confstr")
                    or "glibc" not in (os.confstr("CS_GNU_LIBC_VERSION") or ""),
                    reason="glibc's malloc arenas")
def test_the_c_allocator_keeps_at_most_one_arena_per_worker():
    def arenas(n, **env):
        env = {**{k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}, **env}
        out = subprocess.run([sys.executable, "-c", _ARENAS, str(n)], capture_output=True,
                             text=True, check=True, env=env).stdout
        asked, heaps = out.split()
        return asked, int(heaps)

    asked, capped = arenas(2)
    assert asked == "True" and 1 <= capped <= 2
    # the user's choice wins: 0 is glibc's own default, an arena for each of the six threads
    asked, free = arenas(2, MALLOC_ARENA_MAX="0")
    assert asked == "False" and free > 2


class _Libc:
    def __init__(self, glibc=True):
        self.calls = []
        if glibc:
            self.gnu_get_libc_version = lambda: b"2.36"

    def mallopt(self, param, value):
        self.calls.append((param, value))
        return 1


def test_the_arena_cap_asks_glibc_alone_and_only_where_the_user_did_not():
    libc = _Libc()
    assert machine.cap_malloc_arenas(3, environ={}, libc=libc)
    assert libc.calls == [(machine.M_ARENA_MAX, 3)] and machine.M_ARENA_MAX == -8
    libc = _Libc()
    assert not machine.cap_malloc_arenas(3, environ={"MALLOC_ARENA_MAX": "4"}, libc=libc)
    assert not machine.cap_malloc_arenas(0, environ={}, libc=libc)
    assert libc.calls == []
    libc = _Libc(glibc=False)  # musl has mallopt too, without arenas to cap
    assert not machine.cap_malloc_arenas(3, environ={}, libc=libc)
    assert libc.calls == []
