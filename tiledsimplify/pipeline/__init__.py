"""Scheduling: the tiled pipeline on dask (local threads/processes or a dask.distributed
cluster), one global budget across tiles, and the stitched output."""

from .run import RunSummary, run

__all__ = ["RunSummary", "run"]
