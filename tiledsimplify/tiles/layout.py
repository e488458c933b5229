"""How a tile's arrays lie in the store: the codec, the packed attribute rows and the
arrays' metadata.

Format 3 packs every per-point attribute of a tile in one ``uint8`` array of rows
(:func:`attribute_layout`, :func:`pack_attributes`, :func:`unpack_attribute`). The arrays'
metadata is made once in memory (:func:`array_templates`) and the tiles' nodes are laid out
from it at once (:func:`tile_nodes`); a part of the ingest opens an array from known metadata
without reading its ``zarr.json`` (:func:`array_at`). The layout of the whole store is in
:mod:`tiledsimplify.tiles.store`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

import numpy as np
import zarr
from zarr.codecs import BloscCodec
from zarr.core.array import AsyncArray
from zarr.core.group import GroupMetadata
from zarr.storage import LocalStore, MemoryStore, StorePath

#: a name usable as a store key (an attribute's, a result array's)
NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.\-]*$")


def codec() -> BloscCodec:
    # lz4 with byte shuffle: ~3x faster to write than the default zstd for float64 at about
    # the same size; shuffle groups the slowly varying high bytes of coordinates.
    return BloscCodec(cname="lz4", clevel=5, shuffle="shuffle")


def attribute_layout(spec) -> tuple[dict[str, tuple[int, int, np.dtype, tuple]], int]:
    """Where each attribute of ``spec`` (name -> dtype, trailing shape) lies in a point's
    packed row of bytes (format 3): ``({name: (offset, size, dtype, trail)}, row width)``.

    One array of rows instead of an array per attribute: the 1M LAS scan's twelve attributes
    were twelve zarr arrays a tile to lay out, write and read (each array ~1.5-2 ms of zarr's
    own work), and twelve gathers a chunk in the ingest."""
    out, off = {}, 0
    for name, (dtype, trail) in spec.items():
        dt = np.dtype(dtype)
        size = dt.itemsize * int(np.prod(tuple(trail), dtype=np.int64))
        out[name] = (off, size, dt, tuple(trail))
        off += size
    return out, off


def pack_attributes(attrs: Mapping[str, np.ndarray], layout, width: int, m: int) -> np.ndarray:
    """The rows of bytes (m, width) of ``m`` points' ``attrs`` (:func:`attribute_layout`)."""
    rec = np.empty((m, width), dtype=np.uint8)
    if m:
        for name, (off, size, dt, _) in layout.items():
            v = np.ascontiguousarray(attrs[name], dtype=dt).reshape(m, -1)
            rec[:, off:off + size] = v.view(np.uint8)
    return rec


def unpack_attribute(rec: np.ndarray, entry) -> np.ndarray:
    """One attribute's values (k, ...) from packed rows (:func:`pack_attributes`)."""
    off, size, dt, trail = entry
    col = np.ascontiguousarray(rec[:, off:off + size])
    return col.view(dt).reshape((rec.shape[0],) + trail)


def array_templates(spec, chunk_rows: int, rows: int = 0) -> dict[str, Any]:
    """Metadata of the per-tile arrays of ``rows`` rows (none written yet), made once in
    memory and reused."""
    mem = zarr.open_group(MemoryStore(), mode="w")
    out = {}

    def make(key, dtype, trail):
        arr = mem.create_array(key.replace("/", "_"), shape=(rows,) + tuple(trail),
                               dtype=dtype, chunks=(chunk_rows,) + tuple(trail),
                               compressors=codec(), fill_value=0)
        out[key] = arr.metadata

    make("xyz", np.float64, (3,))
    make("index", np.int64, ())
    if spec:
        make("attributes", np.uint8, (attribute_layout(spec)[1],))
    return out


def tile_nodes(tiles, templates) -> dict[str, Any]:
    """The zarr nodes of ``tiles``: each one's group and its arrays
    (``templates``, :func:`array_templates`)."""
    group = GroupMetadata()
    nodes: dict[str, Any] = {}
    for t in tiles:
        nodes[f"tiles/{t}"] = group
        for key, meta in templates.items():
            nodes[f"tiles/{t}/{key}"] = meta
    return nodes


def array_at(store: LocalStore, name: str, metadata) -> zarr.Array:
    """The array ``name`` of ``store`` whose metadata is known (as laid out): no read. A part
    of the input that writes to every tile (a scan-ordered file) opened each tile's arrays
    from their ``zarr.json`` before: 0.6 ms an array, 20 s a part for 2,000 tiles of LAS
    input on this machine against 0.8 s so (``benchmarks/store_layout.py``)."""
    return zarr.Array(AsyncArray(metadata=metadata, store_path=StorePath(store, name)))
