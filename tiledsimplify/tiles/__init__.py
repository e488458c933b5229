"""Tile store: stream a huge point cloud into count-balanced, overlapping spatial tiles.

:func:`plan_tiles` / :class:`TilePlan` partition space into kd-tree boxes holding similar
numbers of points; :class:`TileStore` streams the input into a zarr v3 group of per-tile arrays,
serves each tile's core and halo points, and records per-tile results so an interrupted run can
resume.
"""

from .partition import TilePlan, plan_tiles
from .store import (
    ChunkSource,
    IncompleteStoreError,
    ResultExistsError,
    StoreError,
    StoreExistsError,
    TileStore,
)
from .sampling import estimate_spacing

__all__ = [
    "ChunkSource",
    "IncompleteStoreError",
    "ResultExistsError",
    "StoreError",
    "StoreExistsError",
    "TilePlan",
    "TileStore",
    "estimate_spacing",
    "plan_tiles",
]
