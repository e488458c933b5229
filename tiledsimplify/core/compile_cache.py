"""Compile every kernel into numba's on-disk cache at once, in parallel processes.

The first call on a machine compiles the kernels it reaches, one after another, in the calling
process: ~40 s on one core, most of it numba's type inference (the LLVM level hardly matters:
``NUMBA_OPT`` 1-3 gave 36-40 s). Threads cannot share that work (numba compiles under one
lock). But the top-level kernels are independent: given their argument types, each compiles
on its own, and numba's cache, written atomically, lets every process load what another one
compiled. So :func:`compile_all` hands the kernels to ``jobs`` fresh interpreter processes,
largest first, from the signatures recorded in ``kernel_signatures.txt`` beside this module.

The recorded file is the list of every top-level kernel the package calls, with the argument
types it calls it with (numba's type ``repr``, which ``eval`` in numba's ``types`` namespace
turns back into the type) and the seconds it took to compile on its own; ``python -m
tiledsimplify.warmup --record`` rewrites it after running the workloads there (small runs of
the core and the pipeline that reach every kernel); a test checks that the file matches what
they call. A stale or unreadable entry is
only skipped: the kernel then compiles on its first call as before, so this module changes
when kernels compile, never what they compute.

Subprocesses (``python -m tiledsimplify.core.compile_cache --worker``), not a multiprocessing
pool: a spawned pool re-imports the caller's ``__main__``, which re-runs a user's script
that has no ``if __name__ == "__main__"`` guard.
"""

import importlib
import logging
import os
import subprocess
import sys
import time
from pathlib import Path

import numba
from numba.core import types
from numba.core.registry import CPUDispatcher

from .. import machine

log = logging.getLogger("tiledsimplify")

#: the recorded kernels: ``module:function<TAB>seconds<TAB>signature repr`` per line
SIGNATURES = Path(__file__).with_name("kernel_signatures.txt")

_TYPES = {name: getattr(types, name) for name in dir(types) if not name.startswith("_")}


def parse_signature(text):
    """A signature's ``repr`` back as a tuple of numba types, or None if it does not read back
    (a literal type, another numba version)."""
    try:
        sig = eval(text, {"__builtins__": {}}, _TYPES)
    except Exception:  # noqa: BLE001
        return None
    return sig if isinstance(sig, tuple) and repr(sig) == text else None


def read_signatures(path=SIGNATURES):
    """``[(kernel, seconds, signature)]`` from the recorded file (signature: a tuple of numba
    types); entries that do not parse (another numba version) are left out."""
    out = []
    try:
        lines = Path(path).read_text().splitlines()
    except OSError:
        return out
    for line in lines:
        if not line.strip() or line.startswith("#"):
            continue
        try:
            kernel, seconds, text = line.split("\t")
            seconds = float(seconds)
        except ValueError:
            continue
        sig = parse_signature(text)
        if sig is not None:  # a stale entry only compiles lazily
            out.append((kernel, seconds, sig))
    return out


def cache_dir():
    """Where numba's cache for this package's kernels lives (see :mod:`._jit`)."""
    return numba.config.CACHE_DIR


def _dispatcher(kernel):
    module, name = kernel.split(":")
    return getattr(importlib.import_module(module), name)


def _cached_signatures(dispatcher):
    """The signatures numba's on-disk cache holds for ``dispatcher`` (empty if none)."""
    try:
        index = dispatcher._cache._cache_file._load_index()
    except Exception:  # noqa: BLE001 - numba internals; unknown means "not cached"
        return set()
    return {key[0] for key in index}


def missing(entries=None):
    """The recorded entries that numba's cache does not hold yet."""
    entries = read_signatures() if entries is None else entries
    out = []
    for kernel, seconds, sig in entries:
        try:
            cached = _cached_signatures(_dispatcher(kernel))
        except Exception:  # noqa: BLE001
            continue
        if sig not in cached:
            out.append((kernel, seconds, sig))
    return out


def partition(entries, jobs):
    """The kernels of ``entries``, longest to compile first, each onto the least loaded of
    ``jobs`` lists (LPT scheduling): ``[[kernel, ...], ...]``, empty lists left out."""
    cost = {}
    for kernel, seconds, _ in entries:
        cost[kernel] = cost.get(kernel, 0.0) + seconds
    jobs = max(1, int(jobs))
    loads = [0.0] * jobs
    parts = [[] for _ in range(jobs)]
    for kernel in sorted(cost, key=lambda k: (-cost[k], k)):
        j = min(range(jobs), key=lambda i: (loads[i], i))
        parts[j].append(kernel)
        loads[j] += cost[kernel]
    return [p for p in parts if p]


def compile_all(jobs=None, path=SIGNATURES, timeout=900.0):
    """Compile every recorded kernel (``path``) not cached yet, in up to ``jobs`` processes
    (default: one per core).

    Returns ``{"compiled": n, "seconds": wall, "jobs": j, "failed": [kernel, ...]}``; ``n`` is
    0 (and nothing starts) when the cache already holds everything. Never raises for a kernel
    that fails: it compiles on its first call instead.
    """
    t0 = time.perf_counter()
    todo = missing(read_signatures(path))
    if not todo:
        return {"compiled": 0, "seconds": 0.0, "jobs": 0, "failed": []}
    jobs = jobs or machine.cpus()
    parts = partition(todo, jobs)
    log.info("compiling %d kernels into the cache (%s) in %d process(es); once per machine",
             len(todo), cache_dir(), len(parts))
    procs = []
    for part in parts:
        try:
            procs.append(subprocess.Popen(
                [sys.executable, "-m", __name__, "--worker", str(path), *part],
                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE))
        except OSError as exc:  # no interpreter to start: the kernels compile lazily
            log.warning("could not start a compile process (%s); kernels compile on first use",
                        exc)
    errors = []
    for proc in procs:
        try:
            errors.append(proc.communicate(timeout=timeout)[1])
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
    failed = sorted({kernel for kernel, _, _ in missing(todo)})
    for err in errors:
        if err:
            log.debug("compile process: %s", err.decode(errors="replace").strip())
    if failed:
        log.warning("%d kernel(s) did not compile ahead (%s); they compile on first use",
                    len(failed), ", ".join(k.split(":")[1] for k in failed))
    seconds = time.perf_counter() - t0
    log.info("compiled %d kernels in %.1f s", len(todo) - len(failed), seconds)
    return {"compiled": len(todo) - len(failed), "seconds": seconds, "jobs": len(parts),
            "failed": failed}


#: a file in the cache directory that :func:`start` holds locked while it compiles, so that
#: other processes of the machine (cluster workers) wait in :func:`wait` and then load the
#: kernels instead of each compiling them all on its first tile
LOCK_NAME = ".compiling.lock"


def _lock_file():
    try:
        import fcntl  # noqa: F401 - POSIX only
        path = Path(cache_dir()) / LOCK_NAME
        path.parent.mkdir(parents=True, exist_ok=True)
        return open(path, "a+")
    except (ImportError, OSError):  # no POSIX locks or no writable cache: nobody waits
        return None


def start(jobs):
    """:func:`compile_all` in a background thread if the cache lacks a kernel and ``jobs`` is
    at least 2 (one process compiles no faster than the caller would on first use): the
    caller reads its input meanwhile and joins the thread before its first kernel; other
    processes of the machine wait for it in :func:`wait`. Returns the thread, or None when
    there is nothing to do."""
    import threading
    if int(jobs) < 2 or not missing():
        return None
    fh = _lock_file()
    if fh is not None:  # taken before returning, so no tile task of this machine runs unwarned
        import fcntl
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # another process of the machine is compiling them: wait() waits
            fh.close()
            return None

    def work():
        try:
            compile_all(int(jobs))
        finally:
            if fh is not None:
                fh.close()  # releases the lock

    thread = threading.Thread(target=work, name="tiledsimplify-compile", daemon=True)
    thread.start()
    return thread


def load(entries=None):
    """Load every recorded kernel (``entries``, by default :func:`read_signatures`) that
    numba's cache holds into this process; returns how many loaded.

    A kernel's first call loads it from the cache otherwise: ~0.25 s for all of them, under
    numba's one lock, so a run's first tiles waited for it on every thread (each of the 1M
    scan's first two tiles 0.2-0.4 s slower, 2026-12-05). A kernel the cache lacks is left to
    its first call (or to :func:`start`'s processes), never compiled here."""
    entries = read_signatures() if entries is None else entries
    done = 0
    for kernel, _, sig in entries:
        try:
            dispatcher = _dispatcher(kernel)
            if sig in _cached_signatures(dispatcher):
                dispatcher.compile(sig)  # from the cache: its index holds the signature
                done += 1
        except Exception as exc:  # noqa: BLE001 - numba internals: its first call loads it
            log.debug("kernel %s not loaded ahead: %s", kernel, exc)
    return done


def start_loading():
    """:func:`load` in a background thread, returned: the caller reads its input meanwhile
    and joins it before its first tile (the loading is ~0.25 s of one core; the ingest of 1M
    points ~1 s with a core to spare)."""
    import threading
    thread = threading.Thread(target=load, name="tiledsimplify-load", daemon=True)
    thread.start()
    return thread


def wait():
    """Return once no process of this machine is compiling the kernels ahead (:func:`start`
    holds its lock); at once when none is. Tile tasks call it before their first kernel."""
    fh = _lock_file()
    if fh is None:
        return
    import fcntl
    with fh:
        fcntl.flock(fh, fcntl.LOCK_SH)


def _compile(path, kernels):
    wanted = set(kernels)
    for kernel, _, sig in read_signatures(path):
        if kernel in wanted:
            try:
                _dispatcher(kernel).compile(sig)
            except Exception as exc:  # noqa: BLE001 - reported by the parent as not cached
                print(f"{kernel}: {exc}", file=sys.stderr)


def used_signatures():
    """``{kernel: {signature, ...}}`` of every top-level kernel this process has called."""
    import pkgutil

    from .. import core
    out = {}
    for info in pkgutil.iter_modules(core.__path__, core.__name__ + "."):
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if (isinstance(obj, CPUDispatcher) and obj.__module__ == info.name
                    and obj.signatures):
                out[f"{info.name}:{name}"] = set(obj.signatures)
    return out


def write_signatures(used, path=SIGNATURES):
    """Write ``used`` (:func:`used_signatures`) with each kernel's seconds to compile alone,
    timed as a fresh process with an empty cache per signature (so ~0.5-1 s of interpreter
    start and imports each; only their order matters, for :func:`partition`). Returns
    ``[(kernel, seconds)]``."""
    import tempfile
    lines = ["# kernel\tseconds to start a process and compile it alone\tsignature (numba "
             "types); written by python -m tiledsimplify.warmup --record"]
    timed = []
    for kernel in sorted(used):
        for sig in sorted(used[kernel], key=repr):
            with tempfile.TemporaryDirectory() as cache:
                t = time.perf_counter()
                subprocess.run([sys.executable, "-c", _ALONE, kernel, repr(sig)], check=True,
                               env={**os.environ, "NUMBA_CACHE_DIR": cache})
                seconds = time.perf_counter() - t
            lines.append(f"{kernel}\t{seconds:.1f}\t{sig!r}")
            timed.append((kernel, seconds))
    Path(path).write_text("\n".join(lines) + "\n")
    return timed


_ALONE = """import sys
from tiledsimplify.core import compile_cache as c
c._dispatcher(sys.argv[1]).compile(c.parse_signature(sys.argv[2]))
"""


if __name__ == "__main__":
    if sys.argv[1:2] == ["--worker"] and len(sys.argv) > 3:
        _compile(sys.argv[2], sys.argv[3:])
    else:
        sys.exit("usage: python -m tiledsimplify.core.compile_cache --worker SIGNATURES "
                 "KERNEL...")
