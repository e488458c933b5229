"""``run``: the tiled pipeline, from input file(s) to one simplified output.

    input → tile store (zarr: count-balanced tiles, halos) → neighbourhoods of every tile and
    one global boundary threshold → per-tile simplification with the halo frozen, down to a
    floor (dask) → one global budget (tiles it reaches past their floor run deeper) → gap
    refinement of every tile's kept points at the cut (mode "coverage") → output

Stages are resumable: an existing, complete store for the same input and settings is reused,
finished tiles are not recomputed, and the output is rewritten from the stored results.
"""

import collections
import collections.abc
import concurrent.futures
import contextlib
import contextvars
import dataclasses
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
from ..core.result import resolve_target, short_message
from ..errors import InputError, TiledSimplifyError
from ..io import points_out
from ..io.las import LAS_SUFFIXES
from ..io.points_out import (
    PointsAt,
    cannot_write_in,
    check_not_input,
    check_output,
    check_space,
    record_bytes,
)
from ..io.sources import degrees_message, open_source
from ..tiles import IncompleteStoreError, TileStore
from .budget import kept_in_tile, merge_passes, plan_cut, store_pass, store_sequences
from .input_order import InputRanks
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
    NORMAL_DTYPE,
    TILE_RESULTS,
    deviation_histogram,
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
    count it reached.
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


def _is_empty_dir(path):
    return path.is_dir() and not any(path.iterdir())


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


class _Progress:
    """Per-task progress of one stage: a log line per finished tile (from the calling
    process, so it is not lost in worker processes) and, on a terminal or in a notebook, a bar
    redrawn below the log lines (not in log files: cron and Airflow logs get the lines only)."""

    def __init__(self, stage, total, describe, bar, out=None, unit="tiles", points=None):
        self.stage, self.total, self.describe, self.unit = stage, total, describe, unit
        self.points_total, self.points = points, 0
        self.out = sys.stderr if out is None else out
        interactive = "ipykernel" in sys.modules or (
            hasattr(self.out, "isatty") and self.out.isatty())
        self.bar = bool(bar) and interactive
        self.done = 0
        self.t0 = time.perf_counter()

    def __call__(self, result):
        self.done += 1
        if isinstance(result, dict):
            self.points += result.get("n_core", 0)
        if self.bar:
            self.out.write("\r\033[K")
        if self.describe is not None:
            self.describe(result, self.done, self.total, self.pace())
        if self.bar:
            self.draw()

    def pace(self):
        """``"; 12 % of points in 3.2 min, ~23 min left"`` for a log line: the share of the
        stage's points in the tiles done so far, and the time left at that rate (by points, not
        tiles: the largest tiles run first, so a count of tiles would overstate the time left);
        empty when the stage's points are not known."""
        if not self.points_total or not self.points:
            return ""
        frac = min(self.points / self.points_total, 1.0)
        elapsed = time.perf_counter() - self.t0
        left = f", ~{_duration(elapsed * (1 - frac) / frac)} left" if frac < 1 else ""
        return f"; {100 * frac:.0f} % of points in {_duration(elapsed)}{left}"

    def draw(self):
        frac = self.done / self.total if self.total else 1.0
        elapsed = time.perf_counter() - self.t0
        left = elapsed * (1 - frac) / frac if frac else float("nan")
        width = 30
        fill = int(round(width * frac))
        self.out.write(f"\r{self.stage} [{'#' * fill}{' ' * (width - fill)}] {self.done:,}/"
                       f"{self.total:,} {self.unit} {100 * frac:3.0f}% | {elapsed:.0f} s"
                       + (f", ~{left:.0f} s left" if 0 < frac < 1 else ""))
        self.out.flush()

    def close(self):
        if self.bar:
            self.out.write("\n")
            self.out.flush()


#: the output stage logs its progress (every tenth of the kept points written) only once it
#: has run this long: a short one stays one line in the run's summary
OUTPUT_QUIET = 10.0


class _Written:
    """The output stage's progress: ``written(points so far)`` logs a line at every tenth of
    the ``total`` kept points, once it has run :data:`OUTPUT_QUIET` seconds (writing 200M kept
    points of a billion takes minutes, with no task per point to count); ``verb`` says what
    was done to them (text outputs are formatted at the end, ~5 µs a point)."""

    def __init__(self, total, verb="written"):
        self.total, self.verb, self.tenths, self.t0 = int(total), verb, 0, time.perf_counter()

    def __call__(self, done):
        tenths = 10 * done // self.total if self.total else 10
        if tenths <= self.tenths:
            return
        elapsed = time.perf_counter() - self.t0
        if elapsed < OUTPUT_QUIET:
            return
        self.tenths = tenths
        frac = done / self.total if self.total else 1.0
        left = f", ~{_duration(elapsed * (1 - frac) / frac)} left" if 0 < frac < 1 else ""
        log.info("output: %d %% (%s of %s points) %s in %s%s", 100 * frac, f"{done:,}",
                 f"{self.total:,}", self.verb, _duration(elapsed), left)


def _duration(seconds):
    """``41 s``, ``12.3 min`` or ``2.1 h``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


class _IngestProgress:
    """``TileStore.create``'s ``progress(pass, points)``: a log line at every tenth of each of
    its two passes over the input (100M points took 90 s) and, on a terminal, a bar."""

    PASSES = {1: "bounds and sample", 2: "points to tiles"}

    def __init__(self, n, bar, out=None):
        self.n, self.bar, self.out = n, bar, out
        self.report, self.pass_number, self.tenths = None, None, 0

    def __call__(self, pass_number, points):
        if pass_number != self.pass_number:
            # between the passes: the plan and the store's layout (5 s at 100M points)
            gap = None if self.report is None else time.perf_counter() - self.report.last
            self.close()
            if gap is not None:
                log.info("ingest: tiles planned and the store laid out in %.1f s (spacing and "
                         "kd split from the sample, a zarr group a tile)", gap)
            self.report = _Progress(f"ingest {pass_number}/2", self.n, None, self.bar,
                                    out=self.out, unit="points")
            self.pass_number, self.tenths = pass_number, 0
        r = self.report
        r.done = points
        r.last = time.perf_counter()
        tenths = 10 * points // self.n if self.n else 10
        if tenths > self.tenths:
            self.tenths = tenths
            if r.bar:
                r.out.write("\r\033[K")
            log.info("ingest pass %d of 2 (%s): %d %% (%s of %s points) in %.1f s",
                     pass_number, self.PASSES[pass_number], 100 * points // max(self.n, 1),
                     f"{points:,}", f"{self.n:,}", time.perf_counter() - r.t0)
        if r.bar:
            r.draw()

    def close(self):
        if self.report is not None:
            self.report.close()
            self.report = None


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
    chunk table, NPY and binary PLY are mapped, text is read from a line's byte offset)."""
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
    per part, reported to ``ingest`` (:class:`_IngestProgress`) as each part ends; "pass"
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
    (any scheduler); ``pace`` is :meth:`_Progress.pace` when ``points``, the stage's core
    points (the sum of the results' ``n_core``), is given. ``progress`` adds a bar on a
    terminal.
    """
    if client is None and isinstance(scheduler, str) and scheduler.startswith("tcp://"):
        from distributed import Client
        with Client(scheduler) as c:
            return _compute(tasks, None, workers, c, progress, stage, describe, points)
    report = _Progress(stage, len(tasks), describe, progress, points=points)
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


def _tile_line(result, done, total, pace=""):
    log.info("tile %d (%d/%d): %d core + %d halo points, %d boundary, %d removals%s, %.1f s%s",
             result["tile"], done, total, result["n_core"], result["n_halo"],
             result["n_boundary"], result["steps"],
             " (all)" if result["exhausted"] else f" (up to level {result['level']:.3g})",
             result["seconds"], pace)


def _refine_line(result, done, total, pace=""):
    if result["beyond"]:
        log.info("tile %d (%d/%d): its gap under the cut, or an earlier neighbour's, lies "
                 "beyond the halo; refined once the cut's gaps are measured%s",
                 result["tile"], done, total, pace)
        return
    log.info("refined tile %d (%d/%d): %d core + %d halo points, %d kept fixed, %d swaps, "
             "Hausdorff %.4g -> %.4g, %.1f s%s", result["tile"], done, total,
             result["n_core"], result["n_halo"], result["n_fixed"], result["swaps"],
             result["hausdorff_before"], result["hausdorff_after"], result["seconds"], pace)


def _threshold_line(result, done, total, pace=""):
    log.info("neighbourhoods of tile %d (%d/%d): %d points in %.1f s%s", result["tile"], done,
             total, result["n_points"], result["seconds"], pace)


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
        _remove_tree(path, settle=0.2 if failed else 0.0)


def _remove_tree(path, settle=0.0):
    """Delete ``path``; after a failure, wait ``settle`` s and look again (writes in flight
    can make it anew), up to :data:`REMOVE_WAIT` s; a warning if it cannot."""
    deadline = time.monotonic() + REMOVE_WAIT
    while True:
        shutil.rmtree(path, ignore_errors=True)
        if settle:
            time.sleep(settle)
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
        floor=0.5, chunk_points=1_000_000, progress=False):
    """Simplify a cloud of any size tile by tile and write one output.

    Parameters
    ----------
    input : str or Path or list
        A LAS/LAZ file, a folder or glob of LAS/LAZ tiles (read as one cloud), an E57 file
        (or a folder, glob or list of them), or a PLY, XYZ/CSV/TXT or NPY file.
    output : str or Path
        ``.las``/``.laz`` (from LAS input it keeps every dimension, scales, offsets and VLRs;
        from other input it is LAS 1.4 point format 6 at scales of a thousandth of the
        spacing; both add ``sharp_edge``, ``importance``, ``simplify_rank``), or
        ``.ply``/``.npy``/``.xyz``/``.csv``.
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
    by_guard = target is None  # the max_spacing guard alone sets the count
    if by_guard:
        target = 0
    if client is None:
        _check_scheduler(scheduler)  # before the ingest, not at the first stage
    if not 0.0 < float(floor) < 1.0:
        raise InputError(f"floor must be in (0, 1) (a fraction of the target ratio each tile "
                         f"first runs down to), got {floor!r}; the default is 0.5.")
    check_output(output, LAS_SUFFIXES)
    check_not_input(output, source.files)
    _warn_read_back(input, output, source)
    _warn_leftovers(output)
    _check_layout(output, source)
    _warn_regrid(output, source)
    _check_room(output, target * _record_bytes(output, source), store, n)
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
    if options.guard == "max_spacing" and regrids(output, source):  # the tiles' limit is
        settings["max_spacing_less"] = "the LAS output grid's move"  # less it (guard_limit)
    fp = _fingerprint(source, settings)

    held = contextlib.ExitStack()  # closed at the end: the lock, the temporary store, a client
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
        if _is_empty_dir(store_path):  # made beforehand (mkdir -p): a new store goes there
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
            ingest = _IngestProgress(n, progress)
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
        _check_grid(output, source, ts)
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
        if options.guard == "max_spacing":  # less what a LAS output's grid moves a point
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
                                        lambda i: (str(store_path), i, opts)),
                            scheduler, workers, client, progress, "neighbours", _threshold_line,
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
                share)),
                scheduler, workers, client, progress, "tiles", _tile_line,
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
                str(store_path), i, opts, thr, ("level", need[i]), share)),
                scheduler, workers, client, progress, "deeper", _tile_line,
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
        n_out, n_boundary = _write_output(ts, source, output, prefix, refined, client)
        stage("output")
    except concurrent.futures.CancelledError as exc:  # distributed's FutureCancelledError
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
    finally:
        held.close()
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
                            scheduler, workers, client, progress, "refine", _refine_line,
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
            if not g <= wide:
                log.warning("no gap refinement: the cut leaves points %.4g from the nearest kept "
                            "point, farther than %g halos (%.4g); give a wider --halo to refine",
                            g, MAX_WIDTH, MAX_WIDTH * ts.halo)
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


#: the columns of a non-LAS output after x, y, z (normals as the tile store keeps them)
OUTPUT_COLUMNS = {"sharp_edge": np.uint8, "nx": NORMAL_DTYPE, "ny": NORMAL_DTYPE,
                  "nz": NORMAL_DTYPE}


#: bytes a new tile store takes on disk per input point, at least: its compressed
#: coordinates, input indices and per-point results took 43 B a point for the 1M scan of
#: ``benchmarks/pipeline_speed.py`` and lone-star.laz, 51 B for autzen_trim.laz
STORE_BYTES = 20


def _warn_read_back(input, output, source):
    """Warn when the output goes where the input names its files (a folder or pattern of
    LAS/LAZ tiles): a later run on the same input would read it as one more tile; and when
    it is named as a COPC file, which it is not."""
    if output.name.lower().endswith(".copc.laz"):
        log.warning("%s: written as a plain LAZ file, not as COPC (no octree); name it "
                    "*.laz, or make COPC from it with `pdal translate %s out.copc.laz`.",
                    output, output.name)
    if source.is_las:
        from ..io.las import lists_path
        if lists_path(input, output):  # (an input file itself: refused before)
            log.warning("%s: the output goes where the input %s names its files; a later run "
                        "on the same input will read it as one more input file. Write it to "
                        "another folder.", output, input)


def _warn_leftovers(output):
    """Warn of the temporary files a killed run writing ``output`` left beside it: the
    output's ``.NAME.*.partial`` and a text output's ``.NAME.*.records`` are removed when a run
    fails or is stopped, but not after SIGKILL (the OOM killer, a batch system past its grace
    period), and a rerun wrote new ones beside them: a killed run's kept points, whole, per
    file. Not deleted here: another run may be writing the same output."""
    try:
        left = sorted(p for pattern in (f".{output.name}.*.partial", f".{output.name}.*.records")
                      for p in output.parent.glob(pattern) if p.is_file())
    except OSError:
        return
    if left:
        size = sum(p.stat().st_size for p in left)
        log.warning("%s: %d temporary file(s) of an earlier run that was killed while writing "
                    "it take %.1f MB beside it (%s); delete them unless another run is writing "
                    "%s now.", output, len(left), size / 1e6, ", ".join(p.name for p in left),
                    output.name)


def _warn_regrid(output, source):
    """Warn when a LAS/LAZ output moves points of input files on another grid than the
    first file's, which it takes (:func:`regrids`): a file of finer scales, or offsets off
    the first file's steps, has its kept points rounded to that grid — up to half a step on
    each axis — where a folder merging two deliveries lost their precision silently."""
    if output.suffix.lower() not in LAS_SUFFIXES or not source.is_las:
        return
    steps, origin = source.scales, source.offsets
    moved = _off_grid_files(source)
    if moved:
        log.warning(
            "%s: %d input file(s) are on another grid than the first file's (%s: scales %s, "
            "offsets %s), which the output takes: their kept points move by up to half a step "
            "on each axis (%s: scales %s, offsets %s%s). Give the files one scale and offset "
            "first (e.g. `pdal translate in.laz out.laz --writers.las.scale_x=… "
            "--writers.las.offset_x=…`).", output, len(moved), source.infos[0].path.name,
            steps.tolist(), origin.tolist(), moved[0].path.name,
            np.asarray(moved[0].scales).tolist(), np.asarray(moved[0].offsets).tolist(),
            "" if len(moved) == 1 else f"; and {len(moved) - 1} more")


def _check_layout(output, source):
    """Refuse now, not after the work, a LAS/LAZ output the writer would refuse at the end:
    input files of different point formats or dimensions (no one layout holds them), or an
    input dimension that clashes with one the output adds (:func:`.las.output_header`)."""
    if output.suffix.lower() in LAS_SUFFIXES and source.is_las:
        from ..io.las import output_header
        output_header(source.template_header(), path=output)


def _check_grid(output, source, ts):
    """After the ingest, before the tiles: refuse a LAS/LAZ output whose grid (the first
    file's scales and offsets) cannot hold the input's coordinates — files far apart with
    their own offsets. The bounds are those the ingest read from the points (headers' bounds
    may be wrong or zero)."""
    if output.suffix.lower() in LAS_SUFFIXES and source.is_las:
        from ..io.las_pieces import fits_grid, off_grid
        lo, hi = ts.root_attrs["bounds"]
        if not fits_grid(lo, hi, source.scales, source.offsets):  # the template's
            raise off_grid(output, lo, hi, source.scales, source.offsets)


def _off_grid_files(source):
    """The files of a LAS ``source`` whose points the first file's grid (the output's) moves
    by up to half a step: finer scales, or offsets off its steps (a coarser multiple at whole
    steps moves them by rounding only)."""
    steps, origin = source.scales, source.offsets
    moved = []
    for info in source.infos[1:]:
        ratio = np.asarray(info.scales, dtype=np.float64) / steps
        shift = (np.asarray(info.offsets, dtype=np.float64) - origin) / steps
        if not (np.allclose(ratio, np.round(ratio), rtol=0, atol=1e-6) and np.all(ratio >= 1)
                and np.allclose(shift, np.round(shift), rtol=0, atol=1e-6)):
            moved.append(info)
    return moved


def regrids(output, source):
    """Whether the output puts the kept points on a grid they were not read from: a LAS/LAZ
    output of a non-LAS input, or of LAS files on other scales or offsets than the first's
    (whose grid the output takes); a LAS input's records are otherwise kept as read. Stricter
    than :func:`_off_grid_files` (which warns of visible moves): a file on a coarser multiple
    of the grid is re-quantised too, and its points move by rounding — what the guard's bound
    (:func:`guard_limit`) must allow for."""
    if output.suffix.lower() not in LAS_SUFFIXES:
        return False
    return not source.is_las or not all(
        np.array_equal(i.scales, source.scales) and np.array_equal(i.offsets, source.offsets)
        for i in source.infos)


def guard_limit(limit, output, source, ts):
    """The distance the tiles' ``max_spacing`` guard works to: ``limit``, less the most a
    LAS/LAZ output's quantisation moves a kept point where it puts points on a grid they
    were not read from — a non-LAS input (:func:`.las.new_header`: a thousandth of the
    spacing) or LAS files on other scales or offsets than the first's, whose grid the output
    takes. Half a step on each axis, and the rounding of ``X * scale + offset`` read back:
    the points of the file then still lie within ``limit`` of every input point (on the
    Bunny at 2 spacings, 2 points were 2.4e-7 beyond it, the step 1e-6). A limit that
    move alone could break is refused."""
    if not regrids(output, source):
        return limit
    lo, hi = (np.asarray(b, dtype=np.float64) for b in ts.root_attrs["bounds"])
    if source.is_las:
        scales = source.scales
    else:
        from ..io.las import new_header
        scales = np.asarray(new_header(lo, hi, ts.spacing).scales, dtype=np.float64)
    move = float(0.5 * np.linalg.norm(scales)
                 + 4 * np.linalg.norm(np.spacing(np.maximum(np.abs(lo), np.abs(hi)))))
    if not limit > move:
        raise InputError(
            f"{output}: --max-spacing {limit:g} (options.max_spacing) is within what the LAS "
            f"output's grid (scales {scales.tolist()}) moves a kept point ({move:.3g}); write "
            ".ply, .npy, .xyz or .csv (coordinates as read), or give a larger distance.")
    log.info("the max_spacing guard works to %.9g: the LAS output's grid moves a kept point "
             "by up to %.3g", limit - move, move)
    return limit - move


def _check_room(output, output_bytes, store, n):
    """Refuse now, not hours in, if the output's directory or a new tile store's (the
    temporary directory by default) cannot hold a lower bound of what they will take; on
    one file system, of both."""
    check_space(output, output_bytes)
    if store is not None and Path(store).exists() and not _is_empty_dir(Path(store)):
        return  # a resumed store: already (mostly) written
    at = Path(store) if store is not None else Path(tempfile.gettempdir()) / "store"
    need = n * STORE_BYTES
    same = os.stat(points_out.existing_parent(at)).st_dev == os.stat(
        points_out.existing_parent(output)).st_dev
    what = f"the {'' if store is not None else 'temporary '}tile store of {n:,} points"
    if same:
        need += output_bytes
        what += " (with the output, on the same file system)"
    fix = ("give --store a directory with room" if store is not None else
           "set TMPDIR (or give --store) to a directory with room")
    check_space(at, need, what, fix, name=None if store is not None else at.parent)


def _record_bytes(output, source):
    """A lower bound of the output's bytes per kept point: its record (LAS: the input's
    point record, before compression — none is assumed for LAZ)."""
    suffix = output.suffix.lower()
    if suffix == ".laz":
        return 0
    if suffix in LAS_SUFFIXES:  # a non-LAS input gets point format 6 (30 bytes) and 17 more
        return source.template_header().point_format.size if source.is_las else 30 + 17
    return record_bytes(OUTPUT_COLUMNS)


def _keep(ts, tile, prefix, refined):
    return ts.read_refined(tile)[0] if refined else kept_in_tile(ts, tile, prefix)


def _kept(ts, tile, prefix, refined):
    return _keep(ts, tile, prefix, refined), ts.read_result(tile, "boundary")


def _tile_piece(store_path, tile, prefix, refined, layout, is_las, start=None, expect=None):
    """What a LAS/LAZ output takes from one tile: ``(piece, boundary count)`` — its kept core
    points packed as the output's point records (:meth:`.LasLayout.pack`: quantised, checked,
    with the three added dimensions; a non-LAS input's points get the dimensions it carried,
    else :data:`~tiledsimplify.io.las.NEW_POINT_DEFAULTS`) — or None if it keeps none. Made
    wherever this runs: on a cluster, a worker. With ``start``, the file's point where the
    tile's first kept point goes (a LAZ output on a cluster, :func:`_write_laz_chunks`), the
    piece is cut at the file's chunk boundaries and its whole chunks compressed
    (:meth:`.LasLayout.chunked`); it must then keep ``expect`` points."""
    from ..io.las import NEW_POINT_DEFAULTS
    ts = TileStore.open(store_path)
    keep, boundary = _kept(ts, tile, prefix, refined)
    if expect is not None and int(keep.sum()) != expect:
        raise TiledSimplifyError(
            f"{store_path}: tile {tile} keeps {int(keep.sum())} points, not the {expect} its "
            "cut says (a bug: the output's LAZ chunks would be misplaced)")
    if not keep.any():
        return None
    xyz = ts.core_xyz(tile)[keep]
    boundary = boundary[keep]
    k = len(xyz)
    if is_las:
        attrs = {name: values[keep] for name, values in ts.attrs(tile).items()}
    else:  # a new LAS 1.4 layout: the dimensions the input carried (E57 intensity, colour)
        stored = ts.attrs(tile, [name for name in layout.attribute_names
                                 if name in ts.attribute_names])
        attrs = {name: stored[name][keep] if name in stored
                 else np.full(k, NEW_POINT_DEFAULTS.get(name, 0))
                 for name in layout.attribute_names}
    piece = layout.pack(xyz, attrs, {"sharp_edge": boundary.astype(np.uint8),
                                     "importance": np.full(k, np.nan),
                                     "simplify_rank": np.full(k, -1, dtype=np.int64)})
    if start is not None:
        piece = layout.chunked(piece, start)
    return piece, int(boundary.sum())


def _piece_part(got, part):
    """A part of a cut piece (:func:`_tile_piece` with ``start``): ``"head"`` or ``"tail"``
    (records, for a chunk that straddles pieces), or ``"body"``: the piece without them and
    its boundary count (what the client writes)."""
    if got is None:
        return b"" if part == "head" else None
    piece, boundary = got
    if part != "body":
        return getattr(piece, part)
    # a copy: the same object may be the head's or tail's task's input in this worker
    return dataclasses.replace(piece, head=b"", tail=None), boundary


#: tiles read ahead of the one being written, per worker (each a tile's kept records)
READ_AHEAD = 2


def _in_tile_order(func, args, n, client):
    """``func(*args(i))`` for ``i`` in ``0..n-1``, yielded in that order: on a cluster computed
    by its workers, at most ``READ_AHEAD`` per worker ahead of the consumer, so the client only
    writes; else here, one after another (read ahead in threads here, the output stage of the
    3M-point scan was within noise of this: zarr's reads go through one event loop)."""
    if client is None:
        for i in range(n):
            yield func(*args(i))
        return
    ahead = READ_AHEAD * max(1, sum(client.nthreads().values()))
    pending = collections.deque(client.submit(func, *args(i), pure=False)
                                for i in range(min(ahead, n)))
    for i in range(n):
        fut = pending.popleft()
        if i + ahead < n:
            pending.append(client.submit(func, *args(i + ahead), pure=False))
        yield fut.result()
        del fut


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


def _write_output(ts, source, output, prefix, refined=False, client=None):
    """Write the kept core points of every tile: the refined flags if ``refined``, else the
    cut's. LAS/LAZ tile by tile, the other formats in input order at each point's rank
    (:class:`.input_order.InputRanks`, :class:`~tiledsimplify.io.points_out.PointsAt`), in
    memory bounded by a tile; on a cluster the tiles' kept records are read — and for
    LAS/LAZ packed as point records (:func:`_tile_piece`) — ahead by its workers
    (:func:`_in_tile_order`), which also compress a LAZ output's chunks
    (:func:`_write_laz_chunks`)."""
    n_out = n_boundary = 0
    path = str(ts.path)
    # a tile keeps its core count less its cut (the refinement swaps at equal count)
    counts = [ts.count(t) - int(prefix[t]) for t in range(ts.n_tiles)]
    written = _Written(sum(counts))
    if output.suffix.lower() in LAS_SUFFIXES:
        from ..io.las import LasOutput, new_header
        if source.is_las:
            template = source.template_header()
        else:  # a new LAS 1.4 layout: the input had no point records to keep
            lo, hi = ts.root_attrs["bounds"]
            template = new_header(lo, hi, ts.spacing, colour=all(
                c in ts.attribute_names for c in ("red", "green", "blue")))
        with LasOutput(output, template) as out:
            if client is not None and output.suffix.lower() == ".laz":
                return _write_laz_chunks(ts, out, prefix, refined, source.is_las, client,
                                         counts, written)
            for got in _in_tile_order(
                    _tile_piece, lambda i: (path, i, prefix, refined, out.layout, source.is_las),
                    ts.n_tiles, client):
                if got is None:
                    continue
                piece, boundary = got
                out.write_piece(piece)
                n_out += piece.count
                n_boundary += boundary
                written(n_out)
        return n_out, n_boundary
    # in input order, a tile at a time
    ranks = InputRanks(ts.n_total)
    for index in _in_tile_order(_tile_kept_index, lambda i: (path, i, prefix, refined),
                                ts.n_tiles, client):
        ranks.add(index)
    n_out = len(ranks)
    done = 0
    with PointsAt(output, n_out, OUTPUT_COLUMNS, progress=_Written(n_out, "formatted as text")
                  ) as out:
        for idx, xyz, boundary, nrm in _in_tile_order(
                _tile_points, lambda i: (path, i, prefix, refined), ts.n_tiles, client):
            out.write(ranks.rank(idx), xyz, {
                "sharp_edge": boundary.astype(np.uint8),
                "nx": nrm[:, 0], "ny": nrm[:, 1], "nz": nrm[:, 2]})
            n_boundary += int(boundary.sum())
            done += len(idx)
            written(done)
    return n_out, n_boundary


def _write_laz_chunks(ts, out, prefix, refined, is_las, client, counts, written):
    """A LAZ output on a cluster, compressed by its workers: each tile's kept points
    (``counts``) are packed and cut at the file's chunk boundaries there (:func:`_tile_piece`
    with the file's point where they start), its whole chunks compressed; each chunk that
    straddles tiles is compressed by a task from the tail of one and the heads of the next
    (:meth:`.LasLayout.compress`). The client writes the chunks in order and grows the header
    by each tile's summary: the file laspy would write (:class:`.las_pieces.ChunkWriter`). ``READ_AHEAD`` tiles per worker
    thread are in flight. Returns ``(points, boundary points)``."""
    from ..io.las_pieces import straddles
    n = ts.n_tiles
    starts, span = straddles(counts, out.layout.vlr().chunk_size())
    path = str(ts.path)
    ahead = READ_AHEAD * max(1, sum(client.nthreads().values()))
    pieces, bodies, spans = {}, {}, {}
    straddling = sorted(span)
    made = [0, 0]  # pieces submitted, straddling chunks submitted

    def submit(upto):
        while made[0] < min(upto, n):
            t = made[0]
            pieces[t] = client.submit(_tile_piece, path, t, prefix, refined, out.layout,
                                      is_las, int(starts[t]), counts[t], pure=False)
            bodies[t] = client.submit(_piece_part, pieces[t], "body", pure=False)
            made[0] += 1
        while made[1] < len(straddling) and span[straddling[made[1]]].stop <= made[0]:
            t = straddling[made[1]]
            parts = [client.submit(_piece_part, pieces[t], "tail", pure=False)]
            parts += [client.submit(_piece_part, pieces[u], "head", pure=False)
                      for u in span[t]]
            spans[t] = client.submit(out.layout.compress, parts, pure=False)
            made[1] += 1

    n_out = n_boundary = 0
    for t in range(n):
        submit(t + ahead)
        got = bodies.pop(t).result()
        if got is not None:
            piece, boundary = got
            out.write_chunks(piece.data, piece.chunks)
            out.grow(piece)
            n_out += piece.count
            n_boundary += boundary
            written(n_out)
        if t in span:
            submit(span[t].stop)
            out.write_chunks(*spans.pop(t).result())
        del pieces[t]  # its parts are asked for: dask keeps what they still need
    return n_out, n_boundary


def _tile_kept_index(store_path, tile, prefix, refined):
    """The input indices of a tile's kept core points (read where this runs)."""
    ts = TileStore.open(store_path)
    return ts.core_index(tile)[_keep(ts, tile, prefix, refined)]


def _tile_points(store_path, tile, prefix, refined):
    """A tile's kept core points for a non-LAS output: ``(index, xyz, boundary, normals)``
    (read where this runs)."""
    ts = TileStore.open(store_path)
    keep, boundary = _kept(ts, tile, prefix, refined)
    xyz, idx = ts.core(tile)
    return idx[keep], xyz[keep], boundary[keep], ts.read_result(tile, "normal")[keep]


