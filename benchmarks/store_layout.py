"""The tile store's layout at a cluster's scale: what it costs before and while parts write.

An ingest lays out every tile's groups and empty arrays (a ``zarr.json`` per node: two groups
and, for a LAS input with 14 dimensions, 16 arrays a tile) in the client, serial before any
worker starts; then each part of the input writes its points into the tiles' arrays on a
worker. This times, for ``--tiles`` tiles (2,000: a billion points at the default 500k-point
tiles), in this process:

- laying the nodes out with ``zarr.create_hierarchy`` (concurrent writes); and, to compare,
  writing each node's ``zarr.json`` with ``mkdir`` and ``write_bytes`` (the same bytes);
- getting every tile's arrays in a part of the input that touches every tile (a scan-ordered
  file): each opened from its ``zarr.json`` (until 2026-12-03) against made from the
  metadata of tile 0 (``tiles.layout.array_at``, what a part does now).

    python benchmarks/store_layout.py [--tiles 2000] [--attrs 14]
"""

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np


def _write_files(path, nodes, proto):
    encoded = {}
    for name, meta in nodes.items():
        if id(meta) not in encoded:
            encoded[id(meta)] = meta.to_buffer_dict(proto)["zarr.json"].to_bytes()
        (path / name).mkdir(parents=True, exist_ok=True)
        (path / name / "zarr.json").write_bytes(encoded[id(meta)])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tiles", type=int, default=2000)
    ap.add_argument("--attrs", type=int, default=14)
    args = ap.parse_args(argv)

    import zarr
    from zarr.core.buffer import default_buffer_prototype
    from zarr.core.group import GroupMetadata
    from zarr.storage import LocalStore

    from tiledsimplify.tiles.layout import array_at, array_templates

    spec = {f"dim{i}": (np.dtype("uint16"), ()) for i in range(args.attrs)}
    templates = array_templates(spec, 1_000_000, 4_000_000)
    keys = list(templates)
    group = GroupMetadata()
    nodes = {"tiles": group}
    for t in range(args.tiles):
        nodes[f"tiles/{t}"] = group
        nodes[f"tiles/{t}/attrs"] = group
        for key, meta in templates.items():
            nodes[f"tiles/{t}/{key}"] = meta
    rows = []

    def timed(what, how, func):
        t, c = time.perf_counter(), time.process_time()
        func()
        rows.append((what, how, time.perf_counter() - t, time.process_time() - c))

    with tempfile.TemporaryDirectory() as tmp:
        for how in ("zarr.create_hierarchy", "zarr.json written directly"):
            path = Path(tmp) / "store"
            shutil.rmtree(path, ignore_errors=True)
            store = LocalStore(path)
            zarr.open_group(store, mode="w")
            if how.startswith("zarr."):
                timed("lay out", how, lambda store=store: dict(zarr.create_hierarchy(
                    store=store, nodes=nodes)))
            else:
                timed("lay out", how, lambda path=path: _write_files(
                    path, nodes, default_buffer_prototype()))
        root = zarr.open_group(store, mode="r+")
        timed("a part gets every tile's arrays", "opened (zarr.json read)",
              lambda: [root[f"tiles/{t}/{key}"] for t in range(args.tiles) for key in keys])
        meta = {key: root[f"tiles/0/{key}"].metadata for key in keys}
        timed("a part gets every tile's arrays", "made from tile 0's metadata",
              lambda: [array_at(store, f"tiles/{t}/{key}", meta[key])
                       for t in range(args.tiles) for key in keys])
    print(f"\n{args.tiles:,} tiles, {len(nodes):,} nodes ({len(keys)} arrays a tile)\n")
    print("| step | how | wall s | CPU s |")
    print("|---|---|---:|---:|")
    for what, how, wall, cpu in rows:
        print(f"| {what} | {how} | {wall:.2f} | {cpu:.2f} |")


if __name__ == "__main__":
    main()
