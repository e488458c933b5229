"""What this machine gives a run: the CPUs it may use and the memory it can still take.

``os.cpu_count()`` counts the host's cores, not the ones a process may run on: in a Slurm job
given 4 of a node's 64 cores (CPU affinity), or a container with a CPU quota (cgroups), it
says 64. A run that sized its threads, compile processes or process pool by it started 64 of
each on 4 cores — and 64 tiles in memory at once. Likewise ``/proc/meminfo`` describes the
host, while a container or a batch job's cgroup may allow far less; the kernel's OOM killer
then ends the run without a message. Both are read here, once, for every layer.

A leaf module: nothing of the package is imported here.
"""

import os
from pathlib import Path


def cpus() -> int:
    """CPUs this process may use: the host's, less what its CPU affinity and a cgroup CPU
    quota leave out (``dask.system.cpu_count``, which dask's own schedulers use)."""
    from dask.system import cpu_count
    return max(int(cpu_count()), 1)


def _read_int(path):
    try:
        text = Path(path).read_text().strip()
    except (OSError, ValueError):
        return None
    if text == "max":
        return None
    try:
        return int(text)
    except ValueError:
        return None


def _stat_value(path, key):
    try:
        for line in Path(path).read_text().splitlines():
            name, _, value = line.partition(" ")
            if name == key:
                return int(value)
    except (OSError, ValueError):
        pass
    return 0


def _mem_available(proc):
    """``MemAvailable`` of ``proc/meminfo`` in bytes (None if not there)."""
    try:
        for line in (Path(proc) / "meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _cgroup_dirs(proc, cgroup_root):
    """The memory cgroup directories of this process and its ancestors, with their version:
    ``[(dir, 2 or 1), ...]``. Inside a container the cgroup namespace usually makes the
    process's own cgroup the mount's root, so the root is always looked at too."""
    out = []
    try:
        lines = (Path(proc) / "self" / "cgroup").read_text().splitlines()
    except OSError:
        return out
    root = Path(cgroup_root)
    for line in lines:
        hid, _, rest = line.partition(":")
        controllers, _, rel = rest.partition(":")
        if hid == "0" and controllers == "":  # v2, unified
            base, version = root, 2
        elif "memory" in controllers.split(","):
            base, version = root / "memory", 1
        else:
            continue
        parts = [p for p in rel.split("/") if p]
        for k in range(len(parts), -1, -1):
            d = base.joinpath(*parts[:k])
            if d.is_dir() and (d, version) not in out:
                out.append((d, version))
    return out


def _cgroup_room(proc, cgroup_root):
    """Bytes the tightest memory cgroup limit over this process still allows (None if no
    limit): limit less usage, usage less the inactive file cache the kernel reclaims first."""
    room = None
    for d, version in _cgroup_dirs(proc, cgroup_root):
        if version == 2:
            limit, usage = _read_int(d / "memory.max"), _read_int(d / "memory.current")
            cache = _stat_value(d / "memory.stat", "inactive_file")
        else:
            limit, usage = (_read_int(d / "memory.limit_in_bytes"),
                            _read_int(d / "memory.usage_in_bytes"))
            cache = _stat_value(d / "memory.stat", "total_inactive_file")
        if limit is None or usage is None or limit >= 2 ** 60:  # v1 "no limit": ~2**63
            continue
        left = max(limit - max(usage - cache, 0), 0)
        room = left if room is None else min(room, left)
    return room


def available_memory(proc="/proc", cgroup_root="/sys/fs/cgroup"):
    """Bytes this process can still allocate without swapping or meeting the OOM killer:
    the host's ``MemAvailable``, or less under a cgroup memory limit (a container, a Slurm or
    Kubernetes job). None where neither can be read (not Linux): callers then check nothing.
    """
    found = [v for v in (_mem_available(proc), _cgroup_room(proc, cgroup_root))
             if v is not None]
    return min(found) if found else None


def gb(nbytes):
    """``nbytes`` for a message: ``"1.5 GB"``."""
    return f"{nbytes / 1e9:,.1f} GB"


#: glibc's ``mallopt`` parameter for the most malloc arenas a process keeps (``M_ARENA_MAX``)
M_ARENA_MAX = -8


def cap_malloc_arenas(n, environ=None, libc=None):
    """Let this process's C allocator keep at most ``n`` arenas (glibc ``mallopt(M_ARENA_MAX,
    n)``; a run passes its worker thread count). Returns True if it was asked.

    glibc gives each thread an arena of its own at its first allocation, up to eight per core
    (then threads share them), and memory freed in one arena serves only the threads that
    allocate from it: the ingest's decoder and writer threads, zarr's event loop and each
    worker thread keep what their earlier tiles freed. A run's peak memory thus depended on
    which thread had run which tile: the 1M-point LAZ scan, 150k-point tiles, 2 worker
    threads, 510-538 or 627-654 MB from run to run (1 worker 558-566 MB). Capped at the
    worker count: 473-513 MB with 2 workers, 379-391 with 1, at the same wall time; the 10M
    scan 592-633 MB against 787-798 (alternating runs, 2026-12-05, ``docs/measurements.md``).
    One arena for 2 workers: 400-437 MB but 6 % slower (the threads wait on its lock).

    Left alone where the user chose (``MALLOC_ARENA_MAX`` in the environment; ``0`` is
    glibc's own default) and where the C library is not glibc (macOS; musl, whose
    ``mallopt`` does nothing). glibc fixes the cap the first time a thread needs an arena
    beyond its eighth, so in a process that had already made that many it has no effect;
    within one process the first cap set counts for later runs too.
    """
    environ = os.environ if environ is None else environ
    if "MALLOC_ARENA_MAX" in environ or n < 1:
        return False
    if libc is None:
        try:
            import ctypes
            libc = ctypes.CDLL(None)
        except (OSError, TypeError):  # no C library loaded by name (Windows)
            return False
    mallopt = getattr(libc, "mallopt", None)
    if mallopt is None or not _is_glibc(libc):
        return False
    return bool(mallopt(M_ARENA_MAX, int(n)))


def _is_glibc(libc):
    """Whether ``libc`` (a ``ctypes`` library) is GNU libc (it has ``gnu_get_libc_version``)."""
    return getattr(libc, "gnu_get_libc_version", None) is not None
