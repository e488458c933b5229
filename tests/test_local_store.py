"""The tile store's files written and read inline are zarr's own, byte for byte."""

import asyncio
from pathlib import Path

import numpy as np
import zarr
from zarr.abc.store import RangeByteRequest
from zarr.core.buffer import default_buffer_prototype
from zarr.storage import LocalStore

from tiledsimplify.tiles.local_store import InlineStore


def _files(root):
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(Path(root).rglob("*"))
            if p.is_file()}


def test_inline_store_writes_the_files_zarr_writes_and_reads_them_back(tmp_path):
    rng = np.random.default_rng(0)
    arrays = {"xyz": rng.random((5000, 3)), "step": np.arange(5000) - 7,
              "flag": rng.random(5000) < 0.3}
    for name, make in (("zarr", LocalStore), ("inline", InlineStore)):
        g = zarr.open_group(make(tmp_path / name), mode="w")
        sub = g.create_group("tile", attributes={"done": False})
        for key, a in arrays.items():
            sub.create_array(key, data=a, chunks=(1024,) + a.shape[1:])
        sub.update_attributes({"done": True})
    assert _files(tmp_path / "zarr") == _files(tmp_path / "inline")
    assert not list((tmp_path / "inline").rglob("*.partial"))
    back = zarr.open_group(InlineStore(tmp_path / "zarr"), mode="r")
    for key, a in arrays.items():
        np.testing.assert_array_equal(back[f"tile/{key}"][:], a)
    assert back["tile"].attrs["done"] is True


def test_inline_store_missing_keys_and_byte_ranges(tmp_path):
    store = InlineStore(tmp_path)
    proto = default_buffer_prototype()

    async def go():
        assert await store.get("nothing/here", proto) is None
        await store.set("a/b", proto.buffer.from_bytes(b"0123456789"))
        assert (await store.get("a/b", proto)).to_bytes() == b"0123456789"
        assert await store.get("a", proto) is None  # a directory
        part = await store.get("a/b", proto, RangeByteRequest(2, 5))
        assert part.to_bytes() == b"234"
        await store.set("a/b", proto.buffer.from_bytes(b"x"))  # replaced whole
        assert (await store.get("a/b", proto)).to_bytes() == b"x"
    asyncio.run(go())
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["b"]
