"""``run``: the tiled pipeline, from input file(s) to one simplified output.

    input → tile store (zarr: count-balanced tiles, halos) → neighbourhoods of every tile and
    one global boundary threshold → per-tile simplification with the halo frozen, down to a
    floor (dask) → one global budget (tiles it reaches past their floor run deeper) → gap
    refinement of every tile's kept points at the cut (mode "coverage") → output

Stages are resumable: an existing, complete store for the same input and settings is reused,
finished tiles are not recomputed, and the output is rewritten from the stored results.

Beside this module: the checks of the output before the work (:mod:`.output_checks`), the
stages' progress lines (:mod:`.progress`) and the output's writer (:mod:`.output`).
"""

import collections
import collections.abc
import concurrent.futures
import contextlib
import contextvars
import hashlib
import json
import logging
import math
import numbers
import os
import shutil
import socket
import sys
import tempfile
import time
import uuid
from dataclasses import asdict, dataclass, field
from pathlib import Path

import dask
import numpy as np
from dask.callbacks import Callback

from .. import __version__, machine
from ..core import SimplifyOptions, compile_cache, edge_fit, prethin
from ..core.refine import edge_cover_radius
from ..core.result import nothing_kept, resolve_target, short_message
from ..errors import InputError, TiledSimplifyError
from ..io.las import LAS_SUFFIXES
from ..io.points_out import cannot_write_in, check_not_input, check_output
from ..io.sources import degrees_message, open_source
from ..tiles import IncompleteStoreError, TileStore
from .budget import merge_passes, plan_cut, store_pass, store_sequences
from .output import write_output
from .output_checks import (
    bytes_per_point,
    check_grid,
    check_layout,
    check_room,
    guard_limit,
    is_empty_dir,
    regrids,
    warn_leftovers,
    warn_read_back,
    warn_regrid,
)
from .per_file import check_outputs, per_file_outputs, write_per_file
from .progress import IngestProgress, Progress, refine_line, threshold_line, tile_line
from .tile_refine import (
    MAX_WIDTH,
    clear_kept,
    cut_hausdorff,
    gaps_expected_within,
    is_refined,
    refine_phases,
    refine_tile,
    refine_width,
    refined_gap,
)
from .tile_task import (
    TILE_RESULTS,
    deviation_histogram,
    missing_classification,
    simplify_tile,
    threshold_from_histogram,
)
from .workers import (
    WORKER_BASE_MB,
    check_workers,
    input_unreadable,
    killed_message,
    no_worker_message,
    tile_memory_mb,
)

log = logging.getLogger("tiledsimplify")

SCHEDULERS = ("threads", "processes", "synchronous")
#: the default tile size (:func:`default_tile_points`): ``n / MIN_TILES`` points, within these
MIN_TILES = 8
MIN_TILE_POINTS = 100_000
MAX_TILE_POINTS = 500_000
#: ``run`` warns below this: the halo is 10 spacings wide whatever the tile, and Bunny tiles of
#: at most 6,000 points already carried 0.3-1.1x their core in halo
SMALL_TILE_POINTS = 5_000


@dataclass
class RunSummary:
    """What a run did: counts, the boundary threshold and point spacing used, tiles run
    deeper, whether the kept points were refined after the global cut, seconds per stage.

    ``seconds``: wall time per stage and ``total``; ``cpu_seconds``: CPU time of this process
    per stage (all its threads; not the work of other processes or cluster workers);
    ``workers``: the local workers (threads or processes) the run used, None on a cluster.
    ``peak_rss_mb``: this process's peak resident memory so far (on local threads the run's
    own, whose size follows the tiles'; not that of worker processes), NaN where the system
    does not say. ``max_spacing``: the bound a ``max_spacing`` guard kept (no input point
    farther from a kept one; None without a guard) — with no count asked, ``target`` is the
    count it reached. ``outputs``: where ``output`` was a pattern with ``{stem}``
    (:mod:`.per_file`), the files written, one per input file in its order, each a
    ``{"path", "points", "boundary"}``; empty for one output.
    """

    n_input: int
    n_output: int
    target: int
    n_boundary: int
    n_tiles: int
    threshold: float
    spacing: float
    n_deeper: int
    store: str
    output: str
    reached: bool
    outputs: list = field(default_factory=list)
    message: str = ""
    refined: bool = False
    seconds: dict = field(default_factory=dict)
    cpu_seconds: dict = field(default_factory=dict)
    peak_rss_mb: float = float("nan")
    workers: int | None = None
    max_spacing: float | None = None

    def to_dict(self):
        return asdict(self)


def _peak_rss_mb():
    """This process's peak resident memory in MB, or NaN: Linux's ``VmHWM`` (the high-water
    mark of its own address space) where ``/proc`` has it, else ``ru_maxrss``.

    Not ``ru_maxrss`` on Linux: the kernel folds the old address space's peak into it at
    ``exec``, so a run started by fork and exec from a larger process (a Python orchestrator,
    a benchmark that made its input first) reported its parent's size: 1,318 MB for a 10M-point
    run where the same run started from a shell peaked at 785 MB (2026-12-03).
    """
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:  # no /proc: not Linux
        pass
    try:
        import resource
    except ImportError:  # not on a POSIX system
        return float("nan")
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb / (1024 * 1024) if sys.platform == "darwin" else kb / 1024  # macOS: bytes


def _fingerprint(source, settings):
    h = hashlib.sha256(json.dumps(settings, sort_keys=True, default=str).encode())
    for f in getattr(source, "files", []):
        st = Path(f).stat()
        h.update(f"{Path(f).resolve()}|{st.st_size}|{st.st_mtime_ns}".encode())
    return h.hexdigest()[:20]


def _store_differences(config, settings):
    """What differs between a store's saved ``config`` and this run's ``settings`` (the two
    parts of :func:`_fingerprint` but the input files), for the error that refuses the
    store: ``"options.edge_angle: 35 here, 40 in the store; …"``, or that the input differs."""
    def flat(d, prefix=""):
        out = {}
        for key, value in d.items():
            if isinstance(value, dict):
                out.update(flat(value, f"{prefix}{key}."))
            else:
                out[f"{prefix}{key}"] = value
        return out
    here = flat(json.loads(json.dumps(settings, default=str)))  # as the store saved them
    there = flat({k: v for k, v in config.items() if k != "fingerprint"})
    def say(d, key):  # a setting one side lacks (a store of an older version): say so
        return f"{d[key]}" if key in d else "absent"
    diffs = [f"{key}: {say(here, key)} here, {say(there, key)} in the store"
             for key in sorted(set(here) | set(there))
             if key not in here or key not in there or here[key] != there[key]]
    return "; ".join(diffs) if diffs else (
        "the same settings, but the input files differ in name, size or modification time")


#: a parallel ingest cuts the input in parts of at least this many points (whole chunks)
INGEST_PART_POINTS = 1_000_000
#: ... and only with at least this many worker threads: an ingest in this process already
#: keeps 1.1-1.3 cores busy (LAZ decompression and chunk compression run in threads), and on 2
#: cores 3 parts at once took as long (2026-12-03, docs/measurements.md "Ingest in parts")
INGEST_PARTS_FROM = 4


def _ingest_parts(source, n, scheduler, workers, client):
    """The parts of the input an ingest reads at once, one task each on the run's scheduler
    (:meth:`.TileStore.create`), or None to read it in this process: a source that cannot be
    cut (anything read whole: gzipped files, meshes, structured NPY), the synchronous
    scheduler, fewer than :data:`INGEST_PARTS_FROM` worker threads, cluster workers that cannot
    read the input files as the client does. About four parts per worker thread, each of at
    least :data:`INGEST_PART_POINTS`, within files (a LAZ file is read from any point by its
    chunk table, one of chunks of varying size — COPC — from any of its chunks, NPY and binary
    PLY are mapped, text is read from a line's byte offset)."""
    if not hasattr(source, "parts") or (client is None and scheduler == "synchronous"):
        return None
    if client is not None:
        slots = sum(client.nthreads().values())
    else:
        slots = int(workers or machine.cpus())
    if slots < INGEST_PARTS_FROM:
        return None
    parts = source.parts(max(INGEST_PART_POINTS, math.ceil(n / (4 * slots))))
    if parts is None or len(parts) < 2:
        return None
    if client is not None:
        why = input_unreadable(client, source.files)
        if why:
            log.info("ingest in this client: %s", why)
            return None
    return parts


def _parts_mapper(scheduler, workers, client, ingest):
    """``map_parts`` of :meth:`.TileStore.create` on the run's scheduler: a pass is one task
    per part, reported to ``ingest`` (:class:`IngestProgress`) as each part ends; "pass"
    0, the store's layout in batches of tiles, is not reported."""

    def run(func, args, pass_number):
        token = uuid.uuid4().hex
        name = func.__name__.strip("_").replace("_", "-")
        last = len(args) - 1
        tasks = [dask.delayed(func, pure=False)(
            *a, dask_key_name=f"ingest-{name}-{last - i:05d}-{token}")  # first parts first
            for i, a in enumerate(args)]
        if not pass_number:  # the store's layout, between the passes: no points to report
            return _compute(tasks, scheduler, workers, client, False, "ingest layout")
        read = [0]

        def line(result, done, total, pace=""):
            read[0] += result["points"]
            ingest(pass_number, read[0])

        ingest(pass_number, 0)
        return _compute(tasks, scheduler, workers, client, False, f"ingest {pass_number}/2",
                        line)

    return run


def _no_edge_classes(classes, input, source):
    """``no_edge_classes`` as a sorted tuple of distinct codes 0-255 (empty: none), or an error
    naming the fix; refused at once for LAS/LAZ files without a classification dimension
    (other inputs are checked after the ingest, which finds their dimensions)."""
    if classes is None:
        return ()
    if isinstance(classes, (str, bytes, numbers.Number)):
        classes = [classes]
    try:
        codes = sorted({_whole(c, "no_edge_classes") for c in classes})
    except (TypeError, InputError):
        raise InputError(f"no_edge_classes must be classification codes (whole numbers 0-255), "
                         f"got {classes!r}; e.g. [3, 4, 5, 7, 18]: vegetation and noise.") from None
    if codes and not 0 <= codes[0] <= codes[-1] <= 255:
        raise InputError(f"no_edge_classes must be classification codes 0-255, got {codes}.")
    if codes and getattr(source, "is_las", False) and \
            "classification" not in source.attribute_names:  # (the files' common dimensions)
        raise missing_classification(input, source.attribute_names)
    return tuple(codes)


def _whole(value, name):
    """``value`` as an int if it is a whole number (``1e6`` from a config file too), else an
    error naming the parameter; None stays None."""
    if value is None:
        return None
    if not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, np.integer, float,
                                                                       np.floating)):
        if float(value).is_integer():
            return int(value)
    raise InputError(f"{name} must be a whole number, got {value!r}.")


@contextlib.contextmanager
def _exclusive(store_path):
    """Hold the tile store for this run alone: an exclusive lock on a file beside it
    (``.NAME.lock``, which names the holder), released when the run ends or its process
    dies. Two runs on one ``--store`` (an overlapping retry of a scheduled job) would write
    the same tiles at once; the second is refused instead. Cluster workers write tiles
    under the run's lock and take none themselves."""
    try:
        import fcntl
    except ImportError:  # not on a POSIX system: no lock
        yield
        return
    # beside the store's real path: one store spelled through a symlink (``/scratch`` ->
    # ``/lustre/scratch``, a link to the store) must not get a second lock of its own
    real = store_path.resolve()
    lock = real.with_name(f".{real.name}.lock")
    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
        fh = open(lock, "a+")  # noqa: SIM115 - closed below
    except PermissionError:  # a linked store whose real parent is not ours: as before
        lock = store_path.with_name(f".{store_path.name}.lock")
        lock.parent.mkdir(parents=True, exist_ok=True)
        fh = open(lock, "a+")  # noqa: SIM115
    with fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.seek(0)
            holder = fh.read().strip() or "another process"
            raise InputError(f"{store_path}: another run is using this tile store ({holder}); "
                             "wait for it to end, or give another --store.") from None
        fh.seek(0)
        fh.truncate()
        fh.write(f"pid {os.getpid()} on {socket.gethostname()}\n")
        fh.flush()
        yield


#: what ``--store`` takes, for the errors that refuse another path
STORE_FIX = ("a new or empty directory, or the store of an earlier run of this command to "
             "resume it")


def _check_store_writable(store_path):
    """A ``--store`` this process cannot write is an error before any work: a store directory
    made beforehand but not writable failed after the ingest's first pass over the input
    (``…/store: Operation not permitted.``, exit 1), a resumed one at its first tile."""
    where = next((p for p in (store_path, *store_path.parents) if p.exists()), None)
    if where is not None and not where.is_dir():
        if where == store_path:
            raise InputError(f"{store_path}: is a file, not a tile store directory; give "
                             f"--store {STORE_FIX}.")
        return  # a file on the way: the lock's mkdir names it
    why = None if where is None else cannot_write_in(where)
    if why:
        raise InputError(f"{store_path}: the tile store's directory {where} is not writable "
                         f"({why}); give --store a directory you can write to.")


#: seconds beyond dask's connect timeout (``distributed.comm.timeouts.connect``) that a run
#: waits for a scheduler's address to answer: dask's client waits forever on a port where
#: something else listens (the dashboard's, 8787, for the scheduler's 8786: 4 min and on)
CONNECT_SLACK = 10.0


def _connect(address):
    """A dask.distributed client of the scheduler at ``address``, or an error saying how to
    start one: checked before any work, so a wrong address does not fail after the ingest."""
    import threading

    from dask.utils import parse_timedelta
    from distributed import Client
    got = {}

    def connect():
        try:
            got["client"] = Client(address)
        except BaseException as exc:  # noqa: BLE001 - raised below, in the caller's thread
            got["error"] = exc
    limit = parse_timedelta(dask.config.get("distributed.comm.timeouts.connect"), "s") \
        + CONNECT_SLACK
    thread = threading.Thread(target=connect, name="tiledsimplify-connect", daemon=True)
    thread.start()
    thread.join(limit)
    if thread.is_alive():  # something listens there, but not a dask scheduler
        raise TiledSimplifyError(
            f"{address}: no dask scheduler answered within {limit:.0f} s, though something "
            "accepts connections there (the dashboard's port, 8787 by default, rather than the "
            "scheduler's, 8786?). Give the address `dask scheduler` prints (\"Scheduler at: "
            "tcp://…\"); --scheduler threads runs on this machine alone.")
    exc = got.get("error")
    if isinstance(exc, (OSError, TimeoutError)):
        raise TiledSimplifyError(
            f"{address}: no dask scheduler answered ({exc}). Start one (`dask scheduler`, then "
            f"`dask worker {address}` on each machine) or give the address it prints; "
            "--scheduler threads runs on this machine alone.") from None
    if exc is not None:
        raise exc
    return got["client"]


def _start_compile(client, scheduler, workers):
    """``(thread, compiling)``: on a cold kernel cache with local workers, every kernel
    compiled in ``workers`` processes while the input is ingested
    (:func:`..core.compile_cache.start`); on a warm one, with tiles run in this process
    (threads, synchronous), the kernels loaded from it meanwhile
    (:func:`..core.compile_cache.start_loading`). ``(None, False)`` for a cluster, whose
    workers compile or load their own cache (``tiledsimplify compile`` on each node or in its
    image spares them that)."""
    if client is not None or scheduler not in SCHEDULERS:
        return None, False
    thread = compile_cache.start(
        1 if scheduler == "synchronous" else workers or machine.cpus())
    if thread is not None:
        return thread, True
    if scheduler == "processes":  # the pool's processes load their own
        return None, False
    return compile_cache.start_loading(), False


def _compute(tasks, scheduler, workers, client, progress, stage="tiles", describe=None,
             points=None):
    """Run dask delayed ``tasks`` on the chosen scheduler; returns their results in order.

    ``describe(result, done, total, pace)`` is called in this process as each task finishes
    (any scheduler); ``pace`` is :meth:`Progress.pace` when ``points``, the stage's core
    points (the sum of the results' ``n_core``), is given. ``progress`` adds a bar on a
    terminal.
    """
    if client is None and isinstance(scheduler, str) and scheduler.startswith("tcp://"):
        from distributed import Client
        with Client(scheduler) as c:
            return _compute(tasks, None, workers, c, progress, stage, describe, points)
    report = Progress(stage, len(tasks), describe, progress, points=points)
    if report.bar:
        report.draw()
    try:
        if client is not None:
            from distributed import as_completed
            from distributed.scheduler import KilledWorker, NoWorkerError
            futures = client.compute(tasks)
            try:
                for fut in as_completed(futures):
                    report(fut.result())
            except KilledWorker as exc:  # dask's message names the task, not the likely cause
                raise TiledSimplifyError(killed_message(exc, stage)) from None
            except NoWorkerError as exc:  # the scheduler's no-workers-timeout: say what to do
                raise TiledSimplifyError(no_worker_message(exc, stage)) from None
            return client.gather(futures)
        _check_scheduler(scheduler)
        kw = {"scheduler": _local_get(scheduler)}
        if workers and scheduler != "synchronous":
            kw["num_workers"] = int(workers)
        keys = {t.key for t in tasks}

        def posttask(key, result, dsk, state, worker_id):
            if key in keys:
                report(result)

        run_pool = _RUN_POOL.get() if scheduler == "processes" else None
        with contextlib.ExitStack() as stack:
            if scheduler == "processes":
                kw["pool"] = (run_pool.get() if run_pool is not None
                              else stack.enter_context(_process_pool(workers)))
                # a task at a time: dask's default sends 6 to a process at once, so 10 tiles
                # went out as two batches whose largest ran last (the 1M scan's tile stage 10.0
                # s, its tasks' own times summing to 7.5 s a process)
                kw["chunksize"] = 1
            stack.enter_context(Callback(posttask=posttask))
            try:
                return list(dask.compute(*tasks, **kw))
            except BaseException as exc:
                if run_pool is not None:  # a failed or stopped stage ends its processes
                    run_pool.end(exc)
                raise
    finally:
        report.close()


class _RunPool:
    """The "processes" scheduler's pool for every stage of one run (:func:`_process_pool`,
    made at the first :meth:`get`). Until 2026-12-05 each stage made a pool of its own, whose
    processes spawned, imported the package, loaded the kernels and grew a tile's memory again
    at every stage: the 1M scan's two refinement stages took 4.8 s against 1.9 with threads.
    :meth:`start` spawns the processes before the ingest, so that they start while the input
    is read."""

    def __init__(self, workers):
        self.workers = workers
        self._made = None  # the pool's context manager, entered
        self.pool = None

    def get(self):
        if self.pool is None:
            self._made = _process_pool(self.workers)
            self.pool = self._made.__enter__()
        return self.pool

    def start(self):
        """Spawn the processes now, without waiting for them (a no-op task each)."""
        pool = self.get()
        for _ in range(self.workers or machine.cpus()):
            pool.submit(int)

    def end(self, exc=None):
        """Shut the pool down: terminated if ``exc`` (a failed or stopped stage, re-raised by
        the caller), else once its tasks are done (the run's end)."""
        made, self._made, self.pool = self._made, None, None
        if made is None:
            return
        if exc is None:
            made.__exit__(None, None, None)
        else:
            with contextlib.suppress(BaseException):
                made.__exit__(type(exc), exc, exc.__traceback__)


#: the run in progress's :class:`_RunPool` (None: each "processes" stage makes its own)
_RUN_POOL = contextvars.ContextVar("tiledsimplify_run_pool", default=None)


def _local_get(scheduler):
    """dask's own function for a local scheduler's name. Passed by name, ``dask.compute``
    first imports dask.distributed to look for a client (0.1-0.3 s of a run's tile stage,
    2026-12-05): the run gives its cluster's client explicitly (``client``), never through a
    global one."""
    if scheduler == "threads":
        import dask.threaded
        return dask.threaded.get
    if scheduler == "processes":
        import dask.multiprocessing
        return dask.multiprocessing.get
    import dask.local
    return dask.local.get_sync


def _check_scheduler(scheduler):
    """Refuse a scheduler that is none of :data:`SCHEDULERS` nor a ``tcp://`` address."""
    if not (scheduler in SCHEDULERS or (isinstance(scheduler, str)
                                        and scheduler.startswith("tcp://"))):
        raise InputError(f"scheduler must be one of {SCHEDULERS} or tcp://HOST:PORT, "
                         f"got {scheduler!r}.")


def _pool_process(run_pid=None):
    """Initializer of a :func:`_process_pool` process: dask's, and on Linux the process ends
    with its parent (``PR_SET_PDEATHSIG``). A run killed outright (SIGKILL: the OOM killer, a
    batch system past its grace period) left its pool's processes behind, orphaned: they ran
    every queued tile on, writing into the store no run held, and then idled on.

    ``run_pid``: the run's process, which started this one (spawn, fork; None for a
    forkserver's). A run killed while its pool's processes still started (importing the
    package, seconds on a slow file system) left them orphaned before this ran, and the
    parent then seen was the orphans' reaper."""
    if run_pid is not None and os.getppid() != run_pid:
        os._exit(1)  # the run died before this process got here
    from dask.multiprocessing import initialize_worker_process
    initialize_worker_process()
    machine.cap_malloc_arenas(1)  # one tile at a time here (see the threads' cap in run)
    _end_with_parent()
    compile_cache.load()  # the kernels the cache holds, before the first task needs them


def _end_with_parent():
    """On Linux, this process ends with its parent (``PR_SET_PDEATHSIG``); at once if the
    parent is already gone."""
    if sys.platform.startswith("linux"):
        parent = os.getppid()  # the run's process (or a forkserver: then its death counts)
        try:
            import ctypes
            import signal
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # 1: PR_SET_PDEATHSIG
        except (OSError, AttributeError):  # no prctl to call: as before
            return
        if os.getppid() != parent:  # the parent died before prctl
            os._exit(1)


@contextlib.contextmanager
def _process_pool(workers):
    """The pool of the "processes" scheduler, made as dask makes its own (a
    ``ProcessPoolExecutor`` with its context and worker initializer: a worker that dies, say
    of the OOM killer, fails the stage with ``BrokenProcessPool`` instead of losing its task),
    but ours to end: a failed or stopped stage terminates the processes. dask shuts its own
    down waiting for the tiles running in it, so a run stopped by SIGTERM went on for another
    42 s (3M-point scan, 2 processes)."""
    from concurrent.futures import ProcessPoolExecutor

    from dask.multiprocessing import get_context
    if os.environ.get("PYTHONHASHSEED") in (None, "0"):
        os.environ["PYTHONHASHSEED"] = "6640"  # as dask sets it for the pools it makes
    context = get_context()
    pool = ProcessPoolExecutor(workers or machine.cpus(), mp_context=context,
                               initializer=_pool_process, initargs=(
                                   os.getpid() if context.get_start_method() in ("spawn", "fork")
                                   else None,))
    try:
        yield pool
    except BaseException:
        running = getattr(pool, "_processes", None) or {}  # Python 3.14: terminate_workers()
        for proc in list(running.values()):
            proc.terminate()
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def _tile_tasks(func, tiles, weight, args, after=None):
    """One dask task ``func(*args(i))`` per tile, named so that the heaviest start first.

    Ready tasks of equal standing run in reverse order of their keys (``dask.order``, which
    the local schedulers and dask.distributed both follow: ``tests/test_pipeline.py`` checks
    the threaded scheduler; a one-worker ``LocalCluster`` ran ten tasks highest key first,
    dask 2026.8), so each key counts up with the tile's ``weight``. Tiles of unequal size
    then finish together: the last one to run is a small one, not a large one started last
    while the other workers idle (longest processing time first). ``after(i)``: tasks that
    tile ``i``'s must follow (passed as the keyword ``after``, which ``func`` ignores).
    """
    tiles = [int(i) for i in tiles]
    rank = np.argsort(np.argsort([weight(i) for i in tiles], kind="stable"), kind="stable")
    token = uuid.uuid4().hex  # fresh keys: a cluster never reuses another run's results
    name = func.__name__.replace("_", "-")
    tasks = {}
    for i, r in zip(tiles, rank.tolist()):
        kw = {} if after is None else {"after": [tasks[j] for j in after(i) if j in tasks]}
        tasks[i] = dask.delayed(func, pure=False)(
            *args(i), **kw, dask_key_name=f"{name}-{r:07d}-{i}-{token}")
    return list(tasks.values())


def default_tile_points(n):
    """The default tile size for ``n`` input points: ``n / MIN_TILES``, within
    ``[MIN_TILE_POINTS, MAX_TILE_POINTS]``.

    A function of the input alone, so the tiles (and the output) do not depend on the worker
    count. At least eight tiles keep two workers busy to the end — a 1M-point scan in 3 tiles of
    at most 500k left one idle for the last tile and ran its refinement's phases one after
    another (2 workers: 40.9 / 44.6 s, peak 0.8 GB, against 38.4 / 36.6 s and 0.52-0.63 GB in 12
    tiles of at most 125k); below 100k points a tile's halo grows large beside its core.
    """
    return int(min(MAX_TILE_POINTS, max(MIN_TILE_POINTS, math.ceil(n / MIN_TILES))))


#: memory (MB) a local run keeps free beside its tiles: the kernels it has yet to load, the
#: ingest's chunks, the cut and the output's buffers
LOCAL_SPARE_MB = 300


#: seconds a stopped run tries to delete its temporary tile store while writes in flight
#: (zarr's I/O thread) still fill it
REMOVE_WAIT = 5.0
#: seconds the deleted store of a stopped run must stay deleted (else it is deleted again):
#: writes in flight make its directories anew
REMOVE_QUIET = 0.2


@contextlib.contextmanager
def _temporary_directory():
    """A temporary directory (under ``TMPDIR``), deleted at the end however the run ends.

    A stop (Ctrl-C, SIGTERM) that interrupts the main thread while it waits on zarr's writes
    (the ingest lays out and fills the store from zarr's own I/O thread) leaves those writes
    running: they refill the directory while it is deleted, and ``TemporaryDirectory`` then
    raised ``OSError: Directory not empty`` in place of the stop — exit 1 instead of 143, and
    the store left in ``TMPDIR``. Here the deletion is tried again until the writes are
    over, and never replaces the run's own exception."""
    path = tempfile.mkdtemp(prefix="tiledsimplify-")
    failed = True
    try:
        yield path
        failed = False
    finally:
        _remove_tree(path, quiet=REMOVE_QUIET if failed else 0.0)


def _remove_tree(path, quiet=0.0):
    """Delete ``path`` until it stays deleted for ``quiet`` s (after a failure, writes in
    flight can make it anew: each time it is deleted again), for up to :data:`REMOVE_WAIT` s;
    a warning if it cannot."""
    deadline = time.monotonic() + REMOVE_WAIT
    while True:
        shutil.rmtree(path, ignore_errors=True)
        gone = time.monotonic()
        while not os.path.lexists(path) and time.monotonic() - gone < quiet:
            time.sleep(0.02)
        if not os.path.lexists(path):
            return True
        if time.monotonic() > deadline:
            log.warning("%s: could not delete this temporary tile store; delete it by hand",
                        path)
            return False
        time.sleep(0.05)


def local_workers(scheduler, workers, client, tile_points, room=None):
    """The local worker count: ``workers`` if given, else one per CPU this process may use
    (:func:`..machine.cpus`: its affinity and cgroup quota, not the host's core count) — fewer
    if that many tiles of ``tile_points`` would not fit in the memory left
    (:func:`..machine.available_memory`, or ``room`` bytes), with a warning; a warning too if
    the given ``workers`` would not fit. ``workers`` unchanged for a cluster (its workers'
    memory limits are checked there, :func:`.workers.check_workers`).

    Each thread holds one tile (:func:`.workers.tile_memory_mb`); a process of the
    "processes" scheduler its own interpreter and kernels as well. The output does not
    depend on the count, so capping it only changes the time.
    """
    if client is not None or scheduler not in SCHEDULERS:
        return workers
    if scheduler == "synchronous":
        return 1
    # MB a worker adds: its tile, and for a process its own interpreter and kernels too
    per = tile_memory_mb(tile_points) - (0 if scheduler == "processes" else WORKER_BASE_MB)
    if room is None:
        room = machine.available_memory()
    usable = machine.cpus()
    if room is None:
        return workers or usable
    room_mb = room / 1e6 - LOCAL_SPARE_MB
    fits = max(int(room_mb // per), 0)
    want = workers or usable
    if want <= fits:
        return want

    def what(w):  # "2 threads with tiles of up to … need about 0.9 GB but …"
        noun = ("worker process", "worker processes") if scheduler == "processes" else (
            "thread", "threads")
        need = machine.gb((w * per + LOCAL_SPARE_MB) * 1e6)
        return (f"{w} {noun[w > 1]} with tiles of up to {tile_points:,} points "
                f"need{'' if w > 1 else 's'} about {need} but {machine.gb(room)} of memory is "
                "available")
    if workers is None and fits >= 1:
        log.warning("%s: running %d instead of one per CPU; a smaller --tile-points runs more "
                    "(the output does not depend on the worker count)", what(want), fits)
        return fits
    want = workers or 1
    smaller = max(int(room_mb / want / (per / tile_points)), 0)
    log.warning("%s; the run may be killed for memory. Give %s--tile-points %s (the output "
                "does not depend on the worker count; the tile size changes it slightly)",
                what(want), f"--workers {max(fits, 1)} or " if want > 1 else "", f"{smaller:,}")
    return want


def run(input, output, *, ratio=None, count=None, options=None, client=None,
        scheduler="threads", workers=None, store=None, tile_points=None, halo=None,
        floor=0.5, chunk_points=1_000_000, progress=False, no_edge_classes=None):
    """Simplify a cloud of any size tile by tile and write one output (or one per input
    file).

    Parameters
    ----------
    input : str or Path or list
        A LAS/LAZ file, a folder or glob of LAS/LAZ tiles (read as one cloud), an E57 file
        (or a folder, glob or list of them), or a PLY, XYZ/CSV/TXT or NPY file.
    output : str or Path
        ``.las``/``.laz`` (from LAS input it keeps every dimension, scales, offsets and VLRs;
        from other input it is LAS 1.4 point format 6 at scales of a thousandth of the
        spacing; both add ``sharp_edge``, ``importance``, ``simplify_rank``), or
        ``.ply``/``.npy``/``.xyz``/``.csv``. A LAS/LAZ name with ``{stem}``
        (``"out/{stem}.laz"``) writes one output per input LAS/LAZ file instead, each with its
        file's header and kept points (:mod:`.per_file`; the summary's ``outputs``).
    ratio, count : exactly one — the fraction or number of points to keep overall; or
        neither, with ``options.guard="max_spacing"``: as few as that limit allows (the
        summary's ``target`` is then the count reached).
    options : SimplifyOptions or dict, optional
        Core options. Mode ``"paper"`` finds one boundary threshold for all tiles in a
        first pass (a fixed ``boundary_threshold`` skips it); every mode gets one point
        spacing for all tiles (``options.spacing``, else the store's estimate).
    client : dask.distributed.Client, optional
        Run tiles on this cluster (``scheduler`` is then ignored).
    scheduler : {"threads", "processes", "synchronous"} or "tcp://HOST:PORT"
    workers : int, optional
        Local worker count.
    store : path, optional
        The zarr tile store; a temporary one (deleted at the end) by default. Give one to
        resume an interrupted run.
    tile_points : int, optional
        Points per tile core, at most. Default :func:`default_tile_points`: an eighth of the
        input, but at least 100,000 and at most 500,000 points.
    halo : float, optional
        Halo width in model units; 10 x the estimated point spacing by default.
    floor : float in (0, 1)
        How far each tile runs first: until it keeps ``floor`` x the overall kept fraction of
        its core points (default 0.5: half the target ratio). Tiles the global cut reaches
        beyond that (flat ones) are run again, deeper, exactly as far as the cut needs; the
        output does not depend on ``floor``, only the time does. A run of one tile runs it
        to the target (no other tile can move the cut). The end of a tile's removal
        sequence is wasted work (and in mode "paper", with its unbounded neighbourhoods, slow:
        points around emptied flat faces gain hundreds of Voronoi neighbours), which is why
        tiles do not simply run to the end.
    chunk_points : int
        Points read per input chunk (bounds ingest memory).
    progress : bool
        Show a progress bar.
    no_edge_classes : sequence of int, optional
        Classification codes (the input's ``classification`` dimension, as LAS has it) whose
        points are never edge points — neither flagged nor kept like edges, and lending no
        edge line to their neighbours: e.g. ``[3, 4, 5, 7, 18]``, vegetation and noise, in
        which edge fits find two planes as readily as on a roof. Simplified as any point.

    Returns
    -------
    RunSummary
    """
    t_start = time.perf_counter()
    seconds, cpu_seconds = {}, {}
    clock = [time.perf_counter(), time.process_time()]

    def stage(name):  # wall and CPU time of the stage that ends now
        now = [time.perf_counter(), time.process_time()]
        seconds[name], cpu_seconds[name] = now[0] - clock[0], now[1] - clock[1]
        clock[:] = now
    if options is None:
        options = SimplifyOptions()
    elif isinstance(options, collections.abc.Mapping):
        options = SimplifyOptions.from_mapping(options)
    elif not isinstance(options, SimplifyOptions):  # was an AttributeError on .guard
        raise InputError(f"options must be a SimplifyOptions, a dict of its fields or None, "
                         f"got {options!r}; e.g. options=SimplifyOptions(mode='paper') or "
                         "options={'mode': 'paper'}.")
    if halo is not None and (isinstance(halo, (bool, np.bool_, str))
                             or not isinstance(halo, numbers.Real)):  # 'wide': ValueError
        raise InputError(f"halo must be a distance in the input's units (a number), got "
                         f"{halo!r}; leave it out for the default (10 x the estimated "
                         "spacing).")
    chunk_points = _whole(chunk_points, "chunk_points")
    if chunk_points is None or chunk_points < 1:  # 0: "range() arg 3 must not be zero"
        raise InputError(f"chunk_points must be at least 1, got {chunk_points!r}; leave it "
                         "out for the default (1,000,000 points a chunk).")
    output = Path(output)
    source = open_source(input, chunk_points=chunk_points)
    n = source.count
    if n == 0:
        raise InputError(f"{input}: the input has no points; nothing to simplify. Check that it "
                         "is the file (or glob) you meant.")
    target = resolve_target(n, ratio, count, options.guard)
    empty = nothing_kept(n, ratio, target)
    if empty:
        log.warning("%s: %s", input, empty)
    by_guard = target is None  # the max_spacing guard alone sets the count
    if by_guard:
        target = 0
    if client is None:
        _check_scheduler(scheduler)  # before the ingest, not at the first stage
    if not 0.0 < float(floor) < 1.0:
        raise InputError(f"floor must be in (0, 1) (a fraction of the target ratio each tile "
                         f"first runs down to), got {floor!r}; the default is 0.5.")
    no_edge = _no_edge_classes(no_edge_classes, input, source)
    outputs = per_file_outputs(output, source)  # {stem}: one output per input file
    if outputs is None:
        check_output(output, LAS_SUFFIXES)
        check_not_input(output, source.files)
        warn_leftovers(output)
    else:
        check_outputs(outputs, source.files)
    first_output = output if outputs is None else outputs[0]
    warn_read_back(input, first_output, source)  # (a pattern's outputs go where its first does)
    check_layout(output, source, per_file=outputs is not None)
    if outputs is None:  # (each file's output keeps its file's grid)
        warn_regrid(output, source)
    check_room(first_output, target * bytes_per_point(output, source), store, n)
    tile_points, workers = _whole(tile_points, "tile_points"), _whole(workers, "workers")
    if workers is not None and workers < 1:
        raise InputError(f"workers must be at least 1 (local threads or processes), got "
                         f"{workers}; leave it out for one per core.")
    if tile_points is None:
        tile_points = default_tile_points(n)
    elif tile_points < 1:
        raise InputError(f"tile_points must be at least 1, got {tile_points}; leave it out for "
                         f"the default ({default_tile_points(n):,} points for this input).")
    elif tile_points < SMALL_TILE_POINTS and n > tile_points:
        log.warning("tile_points=%s cuts %s points into about %s tiles: tiles this small are "
                    "mostly halo and run slowly; the default for this input is %s points",
                    f"{tile_points:,}", f"{n:,}", f"{math.ceil(n / tile_points):,}",
                    f"{default_tile_points(n):,}")
    workers = local_workers(scheduler, workers, client, int(tile_points))
    if client is None and scheduler in ("threads", "synchronous"):  # the peak memory steady
        machine.cap_malloc_arenas(workers)  # and lower: one C allocator arena per worker
    opts = asdict(options)
    # as the store keeps them (JSON): an unbounded option (reach, edge_share = inf) by name
    saved = {k: repr(v) if isinstance(v, float) and not math.isfinite(v) else v
             for k, v in opts.items()}
    settings = {"tile_points": int(tile_points), "halo": halo, "options": saved,
                "version": __version__,
                # what a tile's results hold (the refinement reads its ``fixed`` points)
                "tile_results": TILE_RESULTS}
    if options.prethin_factor:  # the tiles' sequences then depend on the target: a resumed
        settings["target"] = int(target)  # run must ask for the same, thinned the same way
        settings["prethin"] = {"factor": options.prethin_factor, "scheme": prethin.SCHEME}
        if options.guard == "max_spacing":  # the disks are a share of the limit
            settings["prethin"]["guard_radius"] = prethin.GUARD_RADIUS
    if no_edge:  # the tiles' flags and sequences depend on them
        settings["no_edge_classes"] = list(no_edge)
    if options.guard == "max_spacing" and outputs is None and regrids(output, source):
        settings["max_spacing_less"] = "the LAS output grid's move"  # less it (guard_limit)
    fp = _fingerprint(source, settings)

    held = contextlib.ExitStack()  # closed at the end: the lock, the temporary store, a client
    failure = None  # the exception the run ends with, which the contexts are told of
    try:
        if client is None and isinstance(scheduler, str) and scheduler.startswith("tcp://"):
            client = held.enter_context(_connect(scheduler))  # one connection for every stage
        warming, compiling = _start_compile(client, scheduler, workers)
        if store is None:
            store_path = Path(held.enter_context(_temporary_directory())) / "store.zarr"
        else:  # absolute: workers elsewhere (another directory, another machine) open it
            store_path = Path(store).absolute()
            _check_store_writable(store_path)
            held.enter_context(_exclusive(store_path))
        if client is None and scheduler == "processes":  # one pool for the whole run,
            run_pool = _RunPool(workers)  # its processes started while the input is read
            held.callback(_RUN_POOL.reset, _RUN_POOL.set(run_pool))
            held.callback(run_pool.end)
            run_pool.start()
        if client is not None:  # before the ingest: can every worker reach the store?
            log.info("%d dask worker(s) at %s can use %s", check_workers(
                client, store_path.parent, temporary=store is None,
                tile_points=int(tile_points)),
                getattr(client.scheduler, "address", "the scheduler"), store_path.parent)
        ts, again = None, False
        if is_empty_dir(store_path):  # made beforehand (mkdir -p): a new store goes there
            pass
        elif store_path.exists() and not (store_path / "zarr.json").is_file():
            # (a file was refused before the lock); TileStore.open said "no tile store at"
            raise InputError(f"{store_path}: is a directory holding no tile store; give --store "
                             f"{STORE_FIX}.")
        elif store_path.exists():
            def other(config):
                return InputError(
                    f"{store_path}: this tile store was made for another input or other "
                    f"settings ({_store_differences(config, settings)}); give a new --store "
                    "directory (or delete this one) to start over.")
            try:
                ts = TileStore.open(store_path)
            except IncompleteStoreError:  # its ingest was stopped: no tile was done yet
                config = TileStore.stored_attributes(store_path).get("config") or {}
                if config.get("fingerprint") != fp:
                    raise other(config) from None
                log.info("%s: its ingest was interrupted; ingesting again", store_path)
                again = True
            else:
                if ts.config.get("fingerprint") != fp:
                    raise other(ts.config)
                log.info("resuming from %s: %d of %d tiles done", store_path,
                         len(ts.done_tiles()), ts.n_tiles)
        if ts is None:
            ingest = IngestProgress(n, progress)
            parts = _ingest_parts(source, n, scheduler, workers, client)
            try:
                ts = TileStore.create(
                    store_path, source.chunks, tile_points=int(tile_points), halo=halo,
                    n_total=n, config={"fingerprint": fp, **settings},
                    provenance={"input": [str(f) for f in getattr(source, "files", [])],
                                "output": str(output)}, progress=ingest, overwrite=again,
                    parts=parts, map_parts=None if parts is None else _parts_mapper(
                        scheduler, workers, client, ingest))
            finally:
                ingest.close()
            log.info("ingested %s points into %s tiles (halo %.4g, spacing %.4g) in %.1f s%s",
                     f"{n:,}", f"{ts.n_tiles:,}", ts.halo, ts.spacing,
                     time.perf_counter() - clock[0],
                     "" if parts is None else f", {len(parts)} parts read at once")
        stage("ingest")
        if outputs is None:  # (each file's output keeps the grid its points were read from)
            check_grid(output, source, ts)
        if no_edge and "classification" not in ts.attribute_names:
            raise missing_classification(input, ts.attribute_names)
        degrees = degrees_message(input, *ts.root_attrs["bounds"])
        if degrees:
            log.warning("%s", degrees)
        if warming is not None:  # the kernels' first compile (or their loading), started
            warming.join()  # before the ingest
            if compiling:
                stage("compile")

        # one spacing for every tile: the coverage measure's scale and the Voronoi reach
        spacing = options.spacing
        if spacing is None and ts.spacing > 0:
            spacing = ts.spacing
        if spacing is not None:
            opts = {**opts, "spacing": spacing}
        if options.guard == "max_spacing" and outputs is None:  # less what a LAS output's
            # grid moves a point (each file's own output moves none)
            opts = {**opts, "max_spacing": guard_limit(options.max_spacing, output, source, ts)}

        # mode "paper": neighbourhoods of every tile (saved for the tile pass), one threshold
        # for all tiles (mode "coverage" flags edges by a fixed candidate angle and a local
        # edge fit: nothing global to find)
        threshold = options.boundary_threshold
        if threshold is None and options.mode != "paper":
            threshold = edge_fit.CANDIDATE
        if threshold is None:
            threshold = ts.run_attrs.get("threshold")
        if threshold is None and options.detect_boundary and options.mode == "paper":
            done = _compute(_tile_tasks(deviation_histogram, range(ts.n_tiles), ts.count,
                                        lambda i: (str(store_path), i, opts, no_edge)),
                            scheduler, workers, client, progress, "neighbours", threshold_line,
                            points=n)
            threshold = threshold_from_histogram(np.sum([d["hist"] for d in done], axis=0),
                                                 options.boundary_k, options.boundary_floor)
            ts.set_run_attrs({"threshold": threshold})
            log.info("boundary threshold %.4g from %d tiles in %.1f s", threshold, ts.n_tiles,
                     time.perf_counter() - clock[0])
        stage("neighbours")

        # per tile down to the floor
        pending = ts.pending_tiles()
        thr = threshold if options.detect_boundary else None
        # one tile alone sets the cut: its first n - target steps, so it runs to the target
        # (no floor's margin: on 100k scan points the tile 3.0-3.5 -> 2.9 s, the run 3.6-4.1 ->
        # 3.4 s, same output; floor 0.5 against ~1 alternating in one process, 2 pairs)
        share = target / n if n else 0.0  # the pre-thinning's aim in every pass over a tile
        keep_fraction = (1.0 if ts.n_tiles == 1 else float(floor)) * share
        if pending:
            _compute(_tile_tasks(simplify_tile, pending, ts.count, lambda i: (
                str(store_path), i, opts, thr, ("keep", math.ceil(keep_fraction * ts.count(i))),
                share, no_edge)),
                scheduler, workers, client, progress, "tiles", tile_line,
                points=sum(ts.count(i) for i in pending))
            log.info("simplified %d tiles in %.1f s", len(pending), time.perf_counter() - clock[0])
        stage("tiles")

        # one global budget; tiles it reaches past their floor run deeper (once suffices)
        n_deeper = 0
        for _ in range(3):  # the sequences are read from the store a tile at a time
            seqs, exhausted, known = store_sequences(ts)
            # at most a step a point; a cluster's passes count on its workers instead of
            # sending every key to this client
            prefix, need = plan_cut(seqs, n - target, exhausted, known,
                                    _cut_scan(str(store_path), sorted(seqs), client),
                                    n if client is None else None)
            if not need:
                break
            n_deeper += len(need)
            log.info("the global cut reaches past the floor of %d tile(s): running them deeper",
                     len(need))
            _compute(_tile_tasks(simplify_tile, sorted(need), ts.count, lambda i: (
                str(store_path), i, opts, thr, ("level", need[i]), share, no_edge)),
                scheduler, workers, client, progress, "deeper", tile_line,
                points=sum(ts.count(i) for i in need))
        else:
            raise TiledSimplifyError(
                f"{store_path}: the tiles' removal sequences do not agree between passes (the "
                "global cut still needs deeper tiles after three passes); delete the store and "
                "run again, and report this as a bug if it persists.")
        stage("deeper")
        n_removed = sum(prefix.values())
        for i in range(ts.n_tiles):  # the saved neighbourhoods are no longer needed
            ts.delete_state(i)
        stage("budget")
        refined = False
        if options.refines and target > 0 and 0 < n_removed == n - target:  # something to swap
            radius = edge_cover_radius(opts.get("spacing"), target / n)
            try:
                refined = _refine(ts, store_path, prefix, scheduler, workers, client,
                                  progress, radius)
            finally:  # the passes' cache of kept flags in this process (a cluster's
                clear_kept()  # workers keep theirs, at most KEPT_CACHE_BYTES, to their end)
        stage("refine")
        if outputs is None:
            n_out, n_boundary = write_output(ts, source, output, prefix, refined, client)
        else:
            n_out, n_boundary, files = write_per_file(ts, source, outputs, prefix, refined,
                                                      client)
        stage("output")
    except concurrent.futures.CancelledError as exc:  # distributed's FutureCancelledError
        failure = exc
        if client is None or getattr(exc, "reason", None) != "scheduler-connection-lost":
            raise
        # was a traceback (and, being no error of ours, no --summary for a pipeline to read)
        address = getattr(client.scheduler, "address", None) or "the dask scheduler"
        raise TiledSimplifyError(
            f"{address}: the connection to the dask scheduler was lost during the run; no "
            "output written. " + (
                "Give --store DIR to make a long run resumable." if store is None else
                f"The finished tiles stay in {store_path}: run the same command once the "
                "scheduler is back to go on from them.")) from None
    except BaseException as exc:
        failure = exc
        raise
    finally:
        if failure is None:
            held.close()
        else:  # the contexts are told: ``close()`` told them the run ended well, so a stopped
            # run's temporary store went at once, and writes in flight made it anew (until
            # 2026-12-07; :func:`_temporary_directory`)
            held.__exit__(type(failure), failure, failure.__traceback__)
    seconds["total"] = time.perf_counter() - t_start
    cpu_seconds["total"] = sum(cpu_seconds.values())
    if by_guard:
        target = n - n_removed  # what the limit allows is the count asked for
    reached = n - n_removed == target
    # short: every tile ran to its end, so what is left is boundary points and vetoed ones —
    # with no guard none vetoed: the sure points beyond the flags are smooth folds' (features,
    # :func:`..core.simplify.boundary_flags`), counted with them
    vetoed = n_out - n_boundary if options.guard != "none" else 0
    message = "" if reached else short_message(target, n, n_out, n_out, n_out - vetoed,
                                               vetoed, options.guard)
    if message:
        log.warning("%s", message)
    summary = RunSummary(n_input=n, n_output=n_out, target=target, n_boundary=n_boundary,
                         n_tiles=ts.n_tiles, threshold=float(threshold or float("nan")),
                         spacing=float(spacing or float("nan")),
                         n_deeper=n_deeper,
                         store="" if store is None else str(store_path), output=str(output),
                         outputs=[] if outputs is None else files,
                         reached=reached, message=message, refined=refined, seconds=seconds,
                         cpu_seconds=cpu_seconds, peak_rss_mb=_peak_rss_mb(),
                         workers=None if client is not None else workers,
                         max_spacing=(None if options.max_spacing is None  # no guard
                                      else float(options.max_spacing)))
    log.info("kept %d of %d points (%d boundary) from %d tiles (%d run deeper) in %.1f s "
             "(%.0f input points/s): %s", n_out, n, n_boundary, ts.n_tiles, n_deeper,
             seconds["total"], n / seconds["total"] if seconds["total"] else 0.0,
             ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items() if k != "total"))
    return summary


def _refine(ts, store_path, prefix, scheduler, workers, client, progress, edge_radius):
    """The gap refinement stage (:mod:`.tile_refine`); True if the tiles were refined.

    One task per tile for the cut's Hausdorff distance per tile, measured in views the halo
    wide (their maximum is ``G``, or beyond the halo a bound of it, which sets the views'
    width), then the refinement in phases (:func:`refine_phases`): one graph in which each
    tile waits for its neighbours of earlier phases, whose refined flags it reads; the rest
    run in parallel, largest first (:func:`_tile_tasks`). Where the cut's gaps are expected
    within the halo (:func:`~.tile_refine.gaps_expected_within`) the first stage is folded
    into the second: each tile measures its own gap before it refines, and ``G`` is their
    maximum if every one lies within the halo; else the gaps not measured so are, and every
    tile refined again in views as wide as their maximum. The cut, its key and ``G`` are
    saved in the store, and each tile's refined flags with the key, the view's width and its
    gap, so a resumed run refines only the tiles still missing for this cut (flags are a
    fixed function of the cut and the width, so those saved stay valid). ``edge_radius``:
    the flags' cover (:func:`~tiledsimplify.core.refine.edge_cover_radius`).
    """
    t0 = time.perf_counter()
    cut = [int(prefix[i]) for i in range(ts.n_tiles)]
    key = hashlib.sha256(json.dumps(cut).encode()).hexdigest()[:20]
    if ts.run_attrs.get("cut_key") != key:
        ts.set_run_attrs({"cut": cut, "cut_key": key, "cut_hausdorff": None,
                          "cut_hausdorff_bound": False})
    g = ts.run_attrs.get("cut_hausdorff")

    def refine(hausdorff, width):
        phase = refine_phases(ts.plan, width)
        # a tile waits for its neighbours of earlier phases alone, not for every earlier tile
        earlier = {i: [int(j) for j in ts.neighbours(i, width) if phase[j] < phase[i]]
                   for i in range(ts.n_tiles)}
        pending = [i for i in range(ts.n_tiles) if not is_refined(ts, i, key, width)]
        done = []
        if pending:
            done = _compute(_tile_tasks(refine_tile, sorted(pending, key=lambda i: phase[i]),
                                        ts.count, lambda i: (str(store_path), i, hausdorff,
                                                             earlier[i], width, edge_radius),
                                        earlier.get),
                            scheduler, workers, client, progress, "refine", refine_line,
                            points=sum(ts.count(i) for i in pending))
        return done, pending, int(phase.max()) + 1 if len(phase) else 0

    share = 1.0 - sum(cut) / max(ts.n_total, 1)
    at = {}  # each tile's gap under the cut in a view the halo wide, where measured
    if g is None and gaps_expected_within(ts.halo, ts.spacing, share):
        done, pending, n_phases = refine(None, ts.halo)  # each tile measures its own gap
        at = {d["tile"]: d["gap"] for d in done if d["gap"] is not None}
        at.update((i, refined_gap(ts, i)) for i in set(range(ts.n_tiles)) - set(pending))
        if all(at.get(i) is not None and at[i] <= ts.halo for i in range(ts.n_tiles)):
            g = max(at.values(), default=0.0)
            ts.set_run_attrs({"cut_hausdorff": g})
            log.info("refined %d tiles in %d phases (cut Hausdorff %.4g) in %.1f s",
                     len(pending), n_phases, g, time.perf_counter() - t0)
            return True
        log.info("a tile's gap under the cut lies beyond the halo (%.4g): measuring the cut's "
                 "gaps, then refining every tile again", ts.halo)
    if g is None:
        def gaps(tiles, width):
            done = _compute(_tile_tasks(cut_hausdorff, tiles, ts.count,
                                        lambda i: (str(store_path), i, width)),
                            scheduler, workers, client, progress, "gaps")
            return {d["tile"]: d["hausdorff"] for d in done}
        at = {i: x for i, x in at.items() if x is not None}  # those the tiles measured
        at.update(gaps([i for i in range(ts.n_tiles) if i not in at], None))
        # G, or where a gap lies beyond the halo a bound of it: such a gap, measured in a view
        # the halo wide, may be overstated (its nearest kept point beyond the view), never
        # understated — and G itself lies beyond the halo then. Views as wide as the bound
        # are safe; measuring G exactly in views that wide first cost more than the views'
        # extra width (cut_hausdorff_bound in the store)
        g = max(at.values(), default=0.0)
        bound = g > ts.halo
        if not g <= MAX_WIDTH * ts.halo:  # measured again in the widest view read: each
            wide = MAX_WIDTH * ts.halo  # distance up to its width is exact, so a largest
            g = max(gaps(range(ts.n_tiles), wide).values(), default=0.0)  # one within is G
            bound = False
            if not g <= wide:  # inf: tiles whose view holds no kept point at all
                far = (f"points {g:.4g} from the nearest kept point, farther than"
                       if math.isfinite(g) else "points with no kept point within")
                log.warning("no gap refinement: the cut leaves %s %g halos (%.4g); give a "
                            "wider --halo to refine", far, MAX_WIDTH, MAX_WIDTH * ts.halo)
                return False
        if g > ts.halo:
            log.info("the cut leaves points %s%.4g from the nearest kept point, beyond the halo "
                     "(%.4g): the tiles refine in views that wide", "up to " if bound else "",
                     g, ts.halo)
        ts.set_run_attrs({"cut_hausdorff": g, "cut_hausdorff_bound": bound})
    _, pending, n_phases = refine(g, refine_width(ts.halo, g))
    log.info("refined %d tiles in %d phases (cut Hausdorff %s%.4g) in %.1f s", len(pending),
             n_phases, "at most " if ts.run_attrs.get("cut_hausdorff_bound") else "", g,
             time.perf_counter() - t0)
    return True


#: tasks per worker thread in each pass of the global cut on a cluster (:func:`_cut_scan`)
CUT_TASKS = 4


def _cut_scan(store_path, tiles, client):
    """How the global cut's passes (:func:`.budget.count_pass`) read the tiles: on a cluster,
    in batches of tiles on its workers (:func:`.budget.store_pass`, ``CUT_TASKS`` per
    thread), merged here; else None — here, a tile at a time (zarr's reads go through one
    event loop, so local threads would not read faster; the output stage measured so)."""
    if client is None or not tiles:
        return None
    size = -(-len(tiles) // (CUT_TASKS * max(1, sum(client.nthreads().values()))))
    batches = [tiles[i:i + size] for i in range(0, len(tiles), size)]

    def scan(lo, bits, final):
        return merge_passes(client.gather(client.map(
            store_pass, [store_path] * len(batches), batches, lo=lo, bits=bits, final=final,
            pure=False)))
    return scan

