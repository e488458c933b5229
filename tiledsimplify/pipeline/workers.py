"""What a run needs of dask.distributed workers, checked before any work.

Tile tasks open the tile store by its path on the worker and write their results into it, so
on a cluster the store must sit on a file system every worker mounts at the same path, and
every worker must run the same tiledsimplify (and numba) as the client. Neither shows until a
tile task runs: a store under the client's ``/tmp`` failed after the whole ingest with
``no tile store at …`` from a worker, and a worker without the package with a traceback. Here
the client writes a marker file beside the store and asks every worker (``Client.run``) to
read it, to write a file of its own there, and to say which code it runs; a scheduler with no
worker is waited for a while and then named, instead of a run that waits forever.
"""

import logging
import os
import secrets
import socket
from pathlib import Path

from .. import __version__, machine
from ..errors import InputError, TiledSimplifyError

log = logging.getLogger("tiledsimplify")

#: seconds a run waits for a first worker to join a scheduler that has none
WORKER_WAIT = 60.0

#: what a one-thread dask.distributed worker needs for a tile, rounded up: its own process with
#: the kernels loaded (MB) and bytes per core point of its largest tile (the halo included).
#: Measured 2026-12-03 (a ``LocalCluster`` of one one-thread worker, its peak RSS by
#: ``Client.run`` after a whole run; the 3M-point LAZ scan of ``benchmarks/pipeline_speed.py``
#: at ratio 0.2): 147 MB before any tile; largest tiles of 93,729 / 244,782 / 461,448 core
#: points (caps 100k / 250k / 500k) gave 321 / 421 / 489 MB, i.e. ~280 MB + ~460 B a point.
WORKER_BASE_MB = 300
WORKER_BYTES_PER_POINT = 600


def code_id() -> str:
    """A digest of this tiledsimplify's sources and numba's version: equal on two machines
    when they run the same code (what a tile computes depends on nothing else installed)."""
    from ..core._jit import sources_digest
    return sources_digest(Path(__file__).resolve().parents[1], "**/*.py")[:12]


def probe(directory: str, token: str) -> dict:
    """Run on a worker: whether it sees the marker ``token`` in ``directory`` and can write a
    file there, its host and its code (:func:`code_id`)."""
    d = Path(directory)
    try:
        sees = (d / f".tiledsimplify-probe-{token}").read_text() == token
    except OSError:
        sees = False
    write_error = ""
    if sees:
        mine = d / f".tiledsimplify-probe-{token}-{os.getpid()}-{secrets.token_hex(4)}"
        try:
            mine.write_text(token)
            mine.unlink()
        except OSError as exc:
            write_error = f"{type(exc).__name__}: {exc.strerror or exc}"
    from ..core import compile_cache
    return {"host": socket.gethostname(), "sees": sees, "write_error": write_error,
            "version": __version__, "code": code_id(), "cpus": machine.cpus(),
            "cache": str(compile_cache.cache_dir()), "cold": bool(compile_cache.missing())}


def warm(jobs: int) -> bool:
    """Run on one worker of a machine: compile the kernels into its cache ahead, in ``jobs``
    processes, in the background (:func:`..core.compile_cache.start`); the machine's tile
    tasks wait for it (:func:`..core.compile_cache.wait`). True if it started."""
    from ..core import compile_cache
    return compile_cache.start(jobs) is not None


def _warm_cold_machines(client, replies: dict, info: dict) -> None:
    """Start compiling the kernels on every machine (host and cache directory) whose workers
    lack them, once a machine, with as many processes as its workers have threads (at most
    its cores), while this client reads the input. Without it each worker compiled every
    kernel itself on its first tile: a cold ``LocalCluster`` of two one-thread workers ran the
    Bunny in 61.8-65.9 s, with this 30.3-37.6 s, warm 2.4-2.8 s (README, "Compile ahead").
    ``info``: the scheduler's record of each worker (its ``nthreads``)."""
    machines: dict = {}
    for worker, got in sorted(replies.items()):
        if got.get("cold"):
            machines.setdefault((got["host"], got["cache"]), []).append(worker)
    started = []
    for (host, _), workers in sorted(machines.items()):
        threads = sum(max(int(info.get(w, {}).get("nthreads") or 1), 1) for w in workers)
        jobs = min(threads, replies[workers[0]]["cpus"])
        if client.run(warm, jobs, workers=workers[:1], on_error="return").get(workers[0]) \
                is True:
            started.append(f"{host} ({jobs} processes)")
    if started:
        log.info("compiling the kernels ahead on %s while the input is read; its workers wait "
                 "for it instead of each compiling on its first tile", ", ".join(started))


def _wait_for_workers(client, address):
    if client.scheduler_info().get("workers"):
        return
    log.info("waiting up to %.0f s for a dask worker to join %s", WORKER_WAIT, address)
    try:
        client.wait_for_workers(1, timeout=WORKER_WAIT)
    except TimeoutError:
        raise TiledSimplifyError(
            f"{address}: the dask scheduler has no workers (none joined within "
            f"{WORKER_WAIT:.0f} s). Start them (`dask worker {address}` on each machine) and "
            "run again; --scheduler threads runs on this machine alone.") from None


def tile_memory_mb(tile_points: int, threads: int = 1) -> float:
    """About the memory (MB) a worker running ``threads`` tiles of ``tile_points`` at once
    needs (:data:`WORKER_BASE_MB`, :data:`WORKER_BYTES_PER_POINT`)."""
    return WORKER_BASE_MB + threads * WORKER_BYTES_PER_POINT * tile_points / 1e6


def killed_message(exc, stage: str) -> str:
    """The error for dask's ``KilledWorker``: the tile (its task key ends ``-TILE-TOKEN``, see
    ``run._tile_tasks``), and what most likely killed its workers."""
    parts = str(exc.task).split("-")
    tile = parts[-2] if len(parts) >= 3 and parts[-2].isdigit() else str(exc.task)
    worker = getattr(exc.last_worker, "address", exc.last_worker)
    return (f"tile {tile} ({stage}): the {exc.allowed_failures + 1} dask worker(s) that ran it "
            f"all died (the last {worker}), most likely out of memory: a tile needs about "
            f"{WORKER_BYTES_PER_POINT:,} bytes a point besides the worker's own "
            f"~{WORKER_BASE_MB} MB. Give the workers more memory (`dask worker --memory-limit`) or "
            "a smaller --tile-points; with --store, the same command goes on from the finished "
            "tiles.")


def no_worker_message(exc, stage: str) -> str:
    """The error for dask's ``NoWorkerError``: a task waited longer than the scheduler's
    ``distributed.scheduler.no-workers-timeout`` with no worker to run it (every worker gone;
    without that setting the run waits for new ones, however long)."""
    return (f"{stage}: no dask worker was left to run the tasks ({exc}). Start workers "
            "(`dask worker ADDRESS`) and run the same command again: with --store it goes on "
            "from the finished tiles.")


def _memory_warning(info: dict, tile_points: int) -> None:
    """Warn about workers whose memory limit is below what their threads' tiles need."""
    short = []
    for worker, w in sorted(info.items()):
        limit, threads = (w.get("memory_limit") or 0) / 1e6, max(int(w.get("nthreads") or 1), 1)
        need = tile_memory_mb(tile_points, threads)
        if limit and limit < need:
            fits = int((limit - WORKER_BASE_MB) / threads / WORKER_BYTES_PER_POINT * 1e6)
            short.append((worker, limit, threads, need, fits))
    if short:
        log.warning(
            "%d dask worker(s) may run out of memory: %s. Tiles of up to %s points need about "
            "%.0f MB a thread; dask retries a tile whose worker dies, then gives up. Give the "
            "workers more memory (`dask worker --memory-limit`) or --tile-points %s or less.",
            len(short), "; ".join(f"{w} has {lim:.0f} MB for {t} thread(s), needs ~{need:.0f}"
                                  for w, lim, t, need, _ in short),
            f"{tile_points:,}", tile_memory_mb(tile_points) - WORKER_BASE_MB,
            f"{max(min(f for *_, f in short), 0):,}")


def check_workers(client, directory, *, temporary: bool, tile_points: int | None = None) -> int:
    """Check, before any work, that every worker of ``client`` can read and write files in
    ``directory`` (the tile store's) and runs this client's code; returns the worker count.

    ``temporary``: the store is the run's temporary one (the fix named differs). Raises
    :class:`~tiledsimplify.errors.InputError` naming each worker that cannot, with its host,
    and what to do. With ``tile_points``, warns of workers whose memory limit is below what
    their threads' tiles need (:func:`tile_memory_mb`). Workers that join later are not
    checked.
    """
    address = getattr(client.scheduler, "address", "the dask scheduler")
    _wait_for_workers(client, address)
    directory = Path(directory)
    token = secrets.token_hex(8)
    marker = directory / f".tiledsimplify-probe-{token}"
    marker.write_text(token)
    try:
        replies = client.run(probe, str(directory), token, on_error="return")
    finally:
        marker.unlink(missing_ok=True)
    mine = code_id()
    broken, blind, readonly, other = [], [], [], []
    for worker, got in sorted(replies.items()):
        if isinstance(got, BaseException):
            broken.append(f"{worker} ({type(got).__name__}: {got})")
        elif not got["sees"]:
            blind.append(f"{worker} on {got['host']}")
        elif got["write_error"]:
            readonly.append(f"{worker} on {got['host']} ({got['write_error']})")
        elif got["code"] != mine:
            other.append(f"{worker} on {got['host']} (tiledsimplify {got['version']}, "
                         f"sources {got['code']})")
    n = len(replies)
    if broken:
        raise InputError(
            f"{address}: {len(broken)} of {n} dask workers cannot run tiledsimplify's check: "
            f"{', '.join(broken)}. Install tiledsimplify in the workers' environment (the "
            "same version as here) and run again.")
    if blind:
        where = (f"the run's temporary tile store is made in {directory} on this machine "
                 f"({socket.gethostname()}); give --store DIR on a file system every worker "
                 "mounts at the same path (NFS, Lustre, …), or set TMPDIR to one"
                 if temporary else
                 "give --store on a file system every worker mounts at the same path (NFS, "
                 "Lustre, …)")
        raise InputError(
            f"{directory}: {len(blind)} of {n} dask workers cannot see the tile store's "
            f"directory ({', '.join(blind)}): tiles are read and written there by the "
            f"workers. {where[0].upper()}{where[1:]}.")
    if readonly:
        raise InputError(
            f"{directory}: {len(readonly)} of {n} dask workers cannot write in the tile "
            f"store's directory ({', '.join(readonly)}); let the workers' user write there, or "
            "give --store elsewhere.")
    if other:
        raise InputError(
            f"{address}: {len(other)} of {n} dask workers run other tiledsimplify code than "
            f"this client (tiledsimplify {__version__}, sources {mine}): {', '.join(other)}. "
            "Install the same tiledsimplify and numba on every worker and here: tiles computed "
            "by other code would not fit together.")
    info = client.scheduler_info().get("workers", {})
    if tile_points:
        _memory_warning(info, tile_points)
    _warm_cold_machines(client, replies, info)
    warm = sorted(worker for worker, got in replies.items() if not got.get("cold"))
    if warm:  # not waited for: they load while the input is read
        client.run(load_kernels, workers=warm, wait=False)
    return n


async def load_kernels() -> int:
    """Run on a worker whose kernel cache is warm: load every kernel it holds
    (:func:`..core.compile_cache.load`), in a thread beside the worker's event loop, before
    the first tile needs them. A worker's first tile loaded them itself, under numba's lock,
    its other threads waiting (the local threads' first tiles were 0.2-0.4 s slower each,
    2026-12-05). A coroutine: ``Client.run`` does not wait for one (``wait=False``)."""
    import asyncio

    from ..core import compile_cache
    return await asyncio.to_thread(compile_cache.load)


def unreadable(files) -> list[str]:
    """Run on a worker: those of ``files`` (``(path, size)`` as the client sees them) that it
    cannot read, or sees with another size (another file under the same path)."""
    bad = []
    for path, size in files:
        try:
            ok = os.stat(path).st_size == size and os.access(path, os.R_OK)
        except OSError:
            ok = False
        if not ok:
            bad.append(path)
    return bad


def input_unreadable(client, paths) -> str:
    """Why the workers cannot read the input themselves ('' if every worker reads every file
    in ``paths`` as this client does): an ingest in parts runs on them, and an input on the
    client's own disk is then read by the client instead."""
    files = [(str(Path(p).absolute()), os.stat(p).st_size) for p in paths]
    if not files:
        return "no input files to name"
    replies = client.run(unreadable, files)
    bad = {worker: missed for worker, missed in replies.items() if missed}
    if not bad:
        return ""
    worker, missed = next(iter(bad.items()))
    more = f" and {len(missed) - 1} more" if len(missed) > 1 else ""
    return (f"{len(bad)} of {len(replies)} dask workers cannot read the input as this client "
            f"does ({worker}: {missed[0]}{more})")
