"""``run``: the tiled pipeline, from input file(s) to one simplified output.

    input → tile store (zarr: count-balanced tiles, halos) → global boundary threshold →
    per-tile simplification with the halo frozen (dask) → one global budget → output

Stages are resumable: an existing, complete store for the same input and settings is reused,
finished tiles are not recomputed, and the output is rewritten from the stored results.
"""

import hashlib
import json
import logging
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import dask
import numpy as np

from .. import __version__
from ..core import SimplifyOptions, edge_fit
from ..core.result import resolve_target
from ..errors import InputError
from ..io.points_out import write_points
from ..io.sources import open_source
from ..tiles import TileStore
from .budget import kept_in_tile, store_cut
from .tile_task import deviation_histogram, simplify_tile, threshold_from_histogram

log = logging.getLogger("tiledsimplify")

SCHEDULERS = ("threads", "processes", "synchronous")


@dataclass
class RunSummary:
    """What a run did: counts, the boundary threshold and point spacing used, seconds per
    stage."""

    n_input: int
    n_output: int
    target: int
    n_boundary: int
    n_tiles: int
    threshold: float
    spacing: float
    store: str
    output: str
    reached: bool
    message: str = ""
    seconds: dict = field(default_factory=dict)

    def to_dict(self):
        return asdict(self)


def _fingerprint(source, settings):
    h = hashlib.sha256(json.dumps(settings, sort_keys=True, default=str).encode())
    for f in getattr(source, "files", []):
        st = Path(f).stat()
        h.update(f"{Path(f).resolve()}|{st.st_size}|{st.st_mtime_ns}".encode())
    return h.hexdigest()[:20]


def _compute(tasks, scheduler, workers, client, progress):
    """Run dask delayed ``tasks`` on the chosen scheduler; returns their results in order."""
    if client is None and isinstance(scheduler, str) and scheduler.startswith("tcp://"):
        from distributed import Client
        with Client(scheduler) as c:
            return _compute(tasks, None, workers, c, progress)
    if client is not None:
        futures = client.compute(tasks)
        if progress:
            from distributed import progress as dprogress
            dprogress(futures)
        return client.gather(futures)
    if scheduler not in SCHEDULERS:
        raise InputError(f"scheduler must be one of {SCHEDULERS} or tcp://HOST:PORT, got "
                         f"{scheduler!r}.")
    kw = {"scheduler": scheduler}
    if workers and scheduler != "synchronous":
        kw["num_workers"] = int(workers)
    if progress:
        import sys

        from dask.diagnostics import ProgressBar
        with ProgressBar(out=sys.stderr):
            return list(dask.compute(*tasks, **kw))
    return list(dask.compute(*tasks, **kw))


def run(input, output, *, ratio=None, count=None, options=None, client=None,
        scheduler="threads", workers=None, store=None, tile_points=500_000, halo=None,
        chunk_points=1_000_000, progress=False):
    """Simplify a cloud of any size tile by tile and write one output.

    Parameters
    ----------
    input : str or Path or list
        A LAS/LAZ file, a folder or glob of LAS/LAZ tiles (read as one cloud), or a PLY,
        XYZ/CSV/TXT or NPY file.
    output : str or Path
        ``.las``/``.laz`` (LAS input only: keeps every dimension, scales, offsets and VLRs, and
        adds ``sharp_edge``, ``importance``, ``simplify_rank``), or ``.ply``/``.npy``/``.xyz``/
        ``.csv``.
    ratio, count : exactly one — the fraction or number of points to keep overall.
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
    tile_points : int
        Points per tile core, at most.
    halo : float, optional
        Halo width in model units; 10 x the estimated point spacing by default.
    chunk_points : int
        Points read per input chunk (bounds ingest memory).
    progress : bool
        Show a progress bar.

    Returns
    -------
    RunSummary
    """
    t_start = time.perf_counter()
    seconds = {}
    if options is None:
        options = SimplifyOptions()
    elif isinstance(options, dict):
        options = SimplifyOptions.from_mapping(options)
    output = Path(output)
    source = open_source(input, chunk_points=chunk_points)
    n = source.count
    target = resolve_target(n, ratio, count)
    if output.suffix.lower() in (".las", ".laz") and not source.is_las:
        raise InputError(f"{output}: LAS/LAZ output needs LAS/LAZ input (it keeps the input's "
                         "point records); write .ply, .npy, .xyz or .csv instead.")
    opts = asdict(options)
    settings = {"tile_points": int(tile_points), "halo": halo, "options": opts,
                "version": __version__}
    fp = _fingerprint(source, settings)

    tmp = None
    if store is None:
        tmp = tempfile.TemporaryDirectory(prefix="tiledsimplify-")
        store_path = Path(tmp.name) / "store.zarr"
    else:
        store_path = Path(store)
    try:
        t = time.perf_counter()
        ts = None
        if store_path.exists():
            ts = TileStore.open(store_path)
            if ts.config.get("fingerprint") != fp:
                raise InputError(
                    f"{store_path}: this tile store was made for another input or other "
                    "settings; give a new --store directory (or delete this one) to start over.")
            log.info("resuming from %s: %d of %d tiles done", store_path, len(ts.done_tiles()),
                     ts.n_tiles)
        else:
            ts = TileStore.create(
                store_path, source.chunks, tile_points=int(tile_points), halo=halo,
                n_total=n, config={"fingerprint": fp, **settings},
                provenance={"input": [str(f) for f in getattr(source, "files", [])],
                            "output": str(output)})
            log.info("ingested %d points into %d tiles (halo %.4g, spacing %.4g) in %.1f s",
                     n, ts.n_tiles, ts.halo, ts.spacing, time.perf_counter() - t)
        seconds["ingest"] = time.perf_counter() - t

        # mode "paper": one global boundary threshold for every tile (mode "coverage" flags
        # edges by a fixed candidate angle and a local edge fit: nothing global to find)
        t = time.perf_counter()
        threshold = options.boundary_threshold
        if threshold is None and options.mode != "paper":
            threshold = edge_fit.CANDIDATE
        if threshold is None:
            threshold = ts.run_attrs.get("threshold")
        if threshold is None and options.detect_boundary and options.mode == "paper":
            hist = _compute([dask.delayed(deviation_histogram)(str(store_path), i, opts)
                             for i in range(ts.n_tiles)], scheduler, workers, client, progress)
            threshold = threshold_from_histogram(np.sum(hist, axis=0), options.boundary_k,
                                                 options.boundary_floor)
            ts.set_run_attrs({"threshold": threshold})
        seconds["threshold"] = time.perf_counter() - t

        # per tile, halo frozen; one spacing for the coverage measure of every tile
        spacing = options.spacing
        if spacing is None and ts.spacing > 0:
            spacing = ts.spacing
        if spacing is not None:
            opts = {**opts, "spacing": spacing}
        t = time.perf_counter()
        pending = ts.pending_tiles()
        thr = threshold if options.detect_boundary else None
        if pending:
            done = _compute([dask.delayed(simplify_tile)(str(store_path), i, opts, thr)
                             for i in pending], scheduler, workers, client, progress)
            log.info("simplified %d tiles in %.1f s", len(done), time.perf_counter() - t)
        seconds["tiles"] = time.perf_counter() - t

        # one global budget, then the output
        t = time.perf_counter()
        prefix = store_cut(ts, n - target)
        n_removed = sum(prefix.values())
        seconds["budget"] = time.perf_counter() - t
        t = time.perf_counter()
        n_out, n_boundary = _write_output(ts, source, output, prefix)
        seconds["output"] = time.perf_counter() - t
    finally:
        if tmp is not None:
            tmp.cleanup()
    seconds["total"] = time.perf_counter() - t_start
    reached = n - n_removed == target
    message = "" if reached else (
        f"asked to keep {target} of {n} points, but boundary points alone number more: kept "
        f"{n_out}. Raise the target or options.boundary_threshold.")
    if message:
        log.warning("%s", message)
    summary = RunSummary(n_input=n, n_output=n_out, target=target, n_boundary=n_boundary,
                         n_tiles=ts.n_tiles, threshold=float(threshold or float("nan")),
                         spacing=float(spacing or float("nan")),
                         store=str(store_path) if tmp is None else "", output=str(output),
                         reached=reached, message=message, seconds=seconds)
    log.info("kept %d of %d points (%d boundary) in %.1f s: %s", n_out, n,
             n_boundary, seconds["total"],
             ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items() if k != "total"))
    return summary


def _kept(ts, tile, prefix):
    return kept_in_tile(ts, tile, prefix), ts.read_result(tile, "boundary")


def _write_output(ts, source, output, prefix):
    """Write the kept core points of every tile, tile by tile (memory bounded by a tile)."""
    n_out = n_boundary = 0
    if output.suffix.lower() in (".las", ".laz"):
        from ..io.las import LasOutput
        with LasOutput(output, source.template_header()) as out:
            for i in range(ts.n_tiles):
                keep, boundary = _kept(ts, i, prefix)
                if not keep.any():
                    continue
                xyz, _ = ts.core(i)
                attrs = {k: v[keep] for k, v in ts.attrs(i).items()}
                k = int(keep.sum())
                out.write(xyz[keep], attrs, {
                    "sharp_edge": boundary[keep].astype(np.uint8),
                    "importance": np.full(k, np.nan),
                    "simplify_rank": np.full(k, -1, dtype=np.int64)})
                n_out += k
                n_boundary += int(boundary[keep].sum())
        return n_out, n_boundary
    parts, flags, normals, index = [], [], [], []
    for i in range(ts.n_tiles):
        keep, boundary = _kept(ts, i, prefix)
        xyz, idx = ts.core(i)
        parts.append(xyz[keep])
        flags.append(boundary[keep])
        normals.append(ts.read_result(i, "normal")[keep])
        index.append(idx[keep])
    xyz = np.concatenate(parts) if parts else np.empty((0, 3))
    order = np.argsort(np.concatenate(index), kind="stable")  # input order
    b = np.concatenate(flags)[order]
    nrm = np.concatenate(normals)[order]
    write_points(output, xyz[order], {
        "sharp_edge": b.astype(np.uint8), "nx": nrm[:, 0], "ny": nrm[:, 1], "nz": nrm[:, 2]})
    return len(xyz), int(b.sum())


