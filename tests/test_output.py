"""Outputs written in pieces: records at positions (NPY/PLY) against the whole-array writer,
and the input-order ranks of a tiled run's kept points against a sort."""

import numpy as np
import pytest

from tiledsimplify.io.points_out import PointsAt, write_points
from tiledsimplify.pipeline.input_order import InputRanks


@pytest.mark.parametrize("suffix", [".npy", ".ply", ".xyz", ".csv"])
@pytest.mark.parametrize("n", [0, 1, 2_000])
def test_points_at_writes_the_bytes_write_points_writes(tmp_path, monkeypatch, suffix, n):
    from tiledsimplify.io import points_out
    monkeypatch.setattr(points_out, "TEXT_CHUNK", 300)  # text lines formatted in 7 chunks
    rng = np.random.default_rng(n)
    xyz = rng.normal(size=(n, 3))
    cols = {"sharp_edge": rng.integers(0, 2, n).astype(np.uint8),
            "nx": rng.random(n).astype(np.float32), "rank": rng.integers(-1, 9, n)}
    write_points(tmp_path / ("whole" + suffix), xyz, cols)
    with PointsAt(tmp_path / ("parts" + suffix), n, {k: v.dtype for k, v in cols.items()}) as out:
        for part in np.array_split(rng.permutation(n), 5):  # any order, in pieces
            out.write(part, xyz[part], {k: v[part] for k, v in cols.items()})
    assert ((tmp_path / ("parts" + suffix)).read_bytes()
            == (tmp_path / ("whole" + suffix)).read_bytes())


@pytest.mark.parametrize("suffix", [".npy", ".csv"])
def test_points_at_leaves_nothing_on_failure(tmp_path, suffix):
    path = tmp_path / ("out" + suffix)
    with pytest.raises(RuntimeError), PointsAt(path, 10, {"sharp_edge": np.uint8}) as out:
        out.write([0, 1], np.zeros((2, 3)), {"sharp_edge": np.zeros(2, np.uint8)})
        raise RuntimeError("a tile failed")
    assert list(tmp_path.iterdir()) == []


def test_input_ranks_are_positions_in_the_sorted_subset():
    rng = np.random.default_rng(3)
    for n in (1, 63, 64, 65, 1000, 100_003):
        subset = np.flatnonzero(rng.random(n) < rng.random())
        ranks = InputRanks(n)
        pieces = np.array_split(rng.permutation(subset), 4)  # tiles: any order, disjoint
        for piece in pieces:
            ranks.add(piece)
        assert len(ranks) == len(subset)
        for piece in pieces:
            assert np.array_equal(ranks.rank(piece), np.searchsorted(subset, piece))


def test_points_at_full_disk_is_an_error_naming_the_output(tmp_path, monkeypatch):
    """The records' space is reserved up front: a full disk fails there, clearly, not as a
    SIGBUS on a memory-mapped write; nothing is left behind."""
    import errno
    import os

    from tiledsimplify.errors import InputError

    def full(fd, offset, size):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(os, "posix_fallocate", full, raising=False)
    with (pytest.raises(InputError, match=r"out\.ply: cannot reserve .*No space left"),
          PointsAt(tmp_path / "out.ply", 1000, {}) as out):
        out.write([0], np.zeros((1, 3)), {})
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", [".npy", ".xyz", ".laz"])
def test_outputs_get_the_permissions_of_a_new_file(tmp_path, suffix):
    """Not mkstemp's owner-only 0600: 0666 less the umask, as any new file."""
    import os
    import stat

    from tiledsimplify.io.las import LAS_SUFFIXES
    mask = os.umask(0o022)
    try:
        path = tmp_path / ("out" + suffix)
        xyz = np.random.default_rng(0).random((50, 3))
        if suffix in LAS_SUFFIXES:
            import laspy

            from tiledsimplify.io.las_output import write_las
            header = laspy.LasHeader(point_format=0, version="1.2")
            header.scales, header.offsets = [1e-6] * 3, [0.0] * 3
            dims = [d for d in header.point_format.dimension_names if d not in ("X", "Y", "Z")]
            write_las(path, header, xyz, {d: np.zeros(len(xyz), np.uint8) for d in dims},
                      extra_dims={})
        else:
            write_points(path, xyz)
        assert stat.S_IMODE(path.stat().st_mode) == 0o644
        with PointsAt(tmp_path / ("at" + suffix if suffix != ".laz" else "at.ply"), 1, {}) as out:
            out.write([0], xyz[:1], {})
        assert stat.S_IMODE(next(tmp_path.glob("at.*")).stat().st_mode) == 0o644
    finally:
        os.umask(mask)


def test_a_full_disk_names_the_output(tmp_path, monkeypatch, caplog):
    """numpy reports a short write as "N requested and M written" (no file, no errno) and
    lazrs as "IoError: Failed to call write": both become errors naming the output and the
    fix; the command line exits 1 (not an input problem), nothing is left behind."""
    import laspy

    from tiledsimplify.cli import EXIT_ERROR, main
    from tiledsimplify.errors import FileFormatError
    from tiledsimplify.io.las_output import write_las

    def short(*args, **kwargs):
        raise OSError("17974 requested and 248 written")
    monkeypatch.setattr(np, "save", short)
    with pytest.raises(OSError, match=r"writing the output failed \(17974 requested.*free "
                                      r"space") as info:
        write_points(tmp_path / "out.npy", np.zeros((5, 3)))
    assert info.value.filename == str(tmp_path / "out.npy")
    pts = tmp_path / "in.xyz"
    pts.write_text("\n".join(f"{i} {i * i % 7} {i % 3}" for i in range(200)) + "\n")
    assert main(["simplify", str(pts), str(tmp_path / "o.npy"), "--ratio", "0.5", "-q"]) \
        == EXIT_ERROR
    assert "o.npy: writing the output failed" in caplog.text
    monkeypatch.undo()
    las_in = tmp_path / "in.las"
    las = laspy.LasData(laspy.LasHeader(point_format=0, version="1.2"))
    las.x, las.y, las.z = (np.arange(300.0), np.arange(300.0) % 7, np.arange(300.0) % 3)
    las.write(las_in)

    def lazrs_fails(self):
        raise RuntimeError("IoError: Failed to call write")
    monkeypatch.setattr(laspy.LasWriter, "close", lazrs_fails)
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales, header.offsets = [1e-6] * 3, [0.0] * 3
    dims = [d for d in header.point_format.dimension_names if d not in ("X", "Y", "Z")]
    with pytest.raises(OSError, match=r"writing the output failed .*Failed to call write.*"
                                      r"free space") as info:
        write_las(tmp_path / "out.laz", header, np.zeros((5, 3)),
                  {d: np.zeros(5, np.uint8) for d in dims}, extra_dims={})
    assert info.value.filename == str(tmp_path / "out.laz")
    assert not isinstance(info.value, FileFormatError)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.las", "in.xyz"]
    # the same exit code as the NPY output's: the machine failed, not the input
    caplog.clear()
    assert main(["run", str(las_in), str(tmp_path / "o.laz"), "--ratio", "0.5", "-q",
                 "--no-progress"]) == EXIT_ERROR
    assert "o.laz: writing the output failed (RuntimeError: IoError: Failed to call write)" \
        in caplog.text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.las", "in.xyz"]


def test_run_checks_the_space_for_its_output_before_the_work(tmp_path, monkeypatch):
    """An NPY output of `target` records cannot fit in less: refused before the ingest (no
    store, no output), not after hours of work."""
    import shutil
    from collections import namedtuple

    from tiledsimplify.errors import InputError
    from tiledsimplify.pipeline import run
    X = np.random.default_rng(0).random((2000, 3))
    np.save(tmp_path / "in.npy", X)
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**6, 10**6 - 4096, 4096))
    with pytest.raises(InputError, match=r"out\.npy: the output needs at least 36 KB but .* has "
                                         r"4 KB free"):
        run(tmp_path / "in.npy", tmp_path / "out.npy", ratio=0.5, store=tmp_path / "store")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.npy"]


@pytest.mark.parametrize("given", [True, False])
def test_run_checks_the_space_for_a_new_tile_store_before_the_work(tmp_path, monkeypatch,
                                                                   given):
    """Room for the output (36 KB) but not for it and the store's 20 B a point (2,000 points,
    one file system): refused before the ingest, naming the store and how to move it."""
    import shutil
    import tempfile
    from collections import namedtuple

    from tiledsimplify.errors import InputError
    from tiledsimplify.pipeline import run
    X = np.random.default_rng(0).random((2000, 3))
    np.save(tmp_path / "in.npy", X)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr(tempfile, "tempdir", None)  # read TMPDIR again
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**6, 10**6 - 50_000, 50_000))
    store = tmp_path / "runs" / "store" if given else None  # its folder made by the run
    fix = "give --store a directory with room" if given else "set TMPDIR"
    with pytest.raises(InputError, match=r"tile store of 2,000 points \(with the output, "
                                         r"on the same file system\) needs at least 75 KB but "
                                         rf"{tmp_path} has 49 KB free; free disk space or {fix}"):
        run(tmp_path / "in.npy", tmp_path / "out.npy", ratio=0.5, store=store)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.npy"]
    # with the room it runs; a resumed store is not checked again
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**6, 0, 10**6))
    run(tmp_path / "in.npy", tmp_path / "out.npy", ratio=0.5, store=store)
    if given:
        monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**6, 10**6 - 40_000, 40_000))
        (tmp_path / "out.npy").unlink()
        run(tmp_path / "in.npy", tmp_path / "out.npy", ratio=0.5, store=store)
        assert len(np.load(tmp_path / "out.npy")) == 1000


def _unwritable_dir(tmp_path):
    """A directory in which no file can be made, though ``os.access`` may say yes (root)."""
    import os
    from pathlib import Path
    if os.geteuid() != 0:
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o555)
        return locked
    if not Path("/proc").is_dir():
        pytest.skip("no /proc to stand for a directory root cannot write in")
    return Path("/proc")


def test_an_output_directory_access_calls_writable_is_refused_before_the_work(
        tmp_path, monkeypatch):
    """``os.access`` says yes to root — a container's usual user — where a write then fails
    (a read-only or SELinux-labelled bind mount, /proc, /sys): `run … /sys/out.laz` did the
    whole run and then failed, exit 1, naming a hidden temporary file; so did a --summary
    or --store there. Now a file is made and removed in the directory first."""
    import importlib
    import os

    from tiledsimplify.errors import InputError
    from tiledsimplify.io import points_out
    from tiledsimplify.io.points_out import check_output, check_writable
    R = importlib.import_module("tiledsimplify.pipeline.run")
    where = _unwritable_dir(tmp_path)
    monkeypatch.setattr(os, "access", lambda p, mode: True)
    for check in (check_output, check_writable):
        with pytest.raises(InputError, match=rf"out\.npy: the output directory {where} is not "
                                             r"writable \(.+\); choose a directory"):
            check(where / "out.npy")
    with pytest.raises(InputError, match=rf"the tile store's directory {where} is not "
                                         r"writable \(.+\); give --store"):
        R._check_store_writable(where / "store")
    assert points_out.cannot_write_in(tmp_path) is None
    assert [p.name for p in tmp_path.iterdir()] == (["locked"] if where.parent == tmp_path
                                                    else [])


def test_colour_is_written_8_bit():
    """16-bit LAS colour in a points file: v >> 8, so 8-bit colour read as 257 v or written as
    256 v comes back as v; an input whose colour never exceeds 255 held 8-bit values."""
    from tiledsimplify.io.points_out import attribute_columns, attribute_dtypes, colour_8bit
    v = np.array([0, 1, 127, 128, 254, 255])
    assert np.array_equal(colour_8bit(257 * v), v) and np.array_equal(colour_8bit(256 * v), v)
    assert np.array_equal(colour_8bit(v, colour_max=255), v)
    assert np.array_equal(colour_8bit(np.array([65535, 300]), colour_max=65535), [255, 1])
    attrs = {"red": (257 * v).astype(np.uint16), "intensity": np.arange(6, dtype=np.uint16),
             "flag": np.ones(6, dtype=bool), "rgb": np.zeros((6, 3), dtype=np.uint16),
             "sharp_edge": np.ones(6, dtype=np.uint8), "odd name": np.zeros(6, dtype=np.int32)}
    cols = attribute_columns(attrs, reserved={"sharp_edge"})
    spec = {k: (a.dtype, a.shape[1:]) for k, a in attrs.items()}
    dtypes = attribute_dtypes(spec, reserved={"sharp_edge"})
    assert list(cols) == list(dtypes) == ["red", "intensity", "flag", "rgb_0", "rgb_1",
                                          "rgb_2", "odd_name"]
    assert all(cols[k].dtype == dtypes[k] and cols[k].shape == (6,) for k in cols)
    assert np.array_equal(cols["red"], v) and dtypes["flag"] == np.uint8
    # a lone float "red" (a PLY property, not the LAS colour) is written as it is
    lone = {"red": np.array([0.25, 0.5], dtype=np.float32)}
    assert attribute_columns(lone)["red"].dtype == np.float32
    assert attribute_dtypes({"red": (np.dtype(np.float32), ())}) == {"red": np.float32}


def _rows_of(xyz, X):
    """The row of ``X`` each point of ``xyz`` is (the same coordinates, bit for bit)."""
    at = {tuple(p): i for i, p in enumerate(X.tolist())}
    return np.array([at[tuple(p)] for p in xyz.tolist()])


@pytest.mark.parametrize("suffix", [".npy", ".ply", ".csv"])
def test_a_points_file_carries_every_dimension_of_a_las_input(data_dir, tmp_path, suffix):
    """LAS in, NPY / PLY / CSV out, by `run` and by `simplify`: every dimension of the input
    is a column, its values the input's at the kept points, then the simplifier's. They wrote
    x, y, z, sharp_edge and normals only. (autzen's colour is 8-bit in 16-bit fields, so
    it is written as it is; 16-bit colour, v >> 8: above.)"""
    laspy = pytest.importorskip("laspy")
    from tiledsimplify.cli import main
    from tiledsimplify.io.columns import read_columns
    las = laspy.read(data_dir / "lidar" / "autzen_trim.laz")
    small = laspy.LasData(las.header)
    small.points = las.points[:12_000]
    path = tmp_path / "autzen.laz"
    small.write(path)
    las = laspy.read(path)
    X = np.c_[las.x, las.y, las.z]
    names = [d for d in las.point_format.dimension_names if d not in ("X", "Y", "Z")]
    assert {"intensity", "classification", "gps_time", "red"} <= set(names)
    top = max(int(las[c].max()) for c in ("red", "green", "blue"))
    assert top <= 255  # this file holds 8-bit colour in its 16-bit fields: written as it is
    for command in ("run", "simplify"):
        out = tmp_path / f"{command}{suffix}"
        assert main([command, str(path), str(out), "--ratio", "0.2", "-q"]) == 0
        xyz, cols = read_columns(out)
        assert list(cols)[:len(names)] == names
        assert list(cols)[len(names):][:1] == ["sharp_edge"]
        rows = _rows_of(xyz, X)
        assert len(rows) == round(0.2 * len(X))
        for name in names:
            want = np.asarray(las[name])[rows]
            np.testing.assert_array_equal(cols[name], want, err_msg=f"{command} {name}")


@pytest.mark.parametrize("suffix", [".ply", ".csv"])
def test_a_coloured_ply_keeps_its_colour(tmp_path, suffix):
    """A PLY with 8-bit colour, through `run` and `simplify` to PLY or CSV: the same 8-bit
    colour at every kept point (the PLY output's properties uchar)."""
    from tiledsimplify.cli import main
    from tiledsimplify.io.columns import read_columns
    rng = np.random.default_rng(2)
    n = 6000
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"),
                   ("blue", "u1")])
    v = np.empty(n, dt)
    v["x"], v["y"] = rng.random(n), rng.random(n)
    v["z"] = 0.2 * np.abs(v["x"] - 0.5)  # a fold: flags too
    for c in ("red", "green", "blue"):
        v[c] = rng.integers(0, 256, n)
    path = tmp_path / "coloured.ply"
    head = ["ply", "format binary_little_endian 1.0", f"element vertex {n}"]
    head += [f"property float {a}" for a in "xyz"]
    head += [f"property uchar {c}" for c in ("red", "green", "blue")] + ["end_header\n"]
    path.write_bytes("\n".join(head).encode() + v.tobytes())
    X = np.c_[v["x"], v["y"], v["z"]].astype(np.float64)
    for command in ("run", "simplify"):
        out = tmp_path / f"{command}{suffix}"
        assert main([command, str(path), str(out), "--ratio", "0.1", "-q"]) == 0
        xyz, cols = read_columns(out)
        rows = _rows_of(xyz, X)
        assert len(rows) == n // 10
        for c in ("red", "green", "blue"):
            np.testing.assert_array_equal(cols[c], v[c][rows])
        if suffix == ".ply":
            assert b"property uchar red" in out.read_bytes()[:400]


def _ply_with_properties(path, fmt, n=5000, seed=4):
    """A PLY of ``n`` vertices on a folded sheet with colour, normals, a float ``confidence``
    and a uint16 ``quality``, binary or ASCII; returns the vertex table."""
    rng = np.random.default_rng(seed)
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"),
                   ("nz", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1"),
                   ("confidence", "<f4"), ("quality", "<u2")])
    v = np.zeros(n, dt)
    v["x"], v["y"] = rng.random(n), rng.random(n)
    v["z"] = 0.2 * np.abs(v["x"] - 0.5)
    v["nz"] = 1.0
    for c in ("red", "green", "blue"):
        v[c] = rng.integers(0, 256, n)
    v["confidence"] = rng.random(n).astype(np.float32)
    v["quality"] = rng.integers(0, 65536, n)
    types = {"f4": "float", "u1": "uchar", "u2": "ushort"}
    head = ["ply", f"format {fmt} 1.0", f"element vertex {n}"]
    head += [f"property {types[dt[name].str[1:]]} {name}" for name in dt.names]
    head += ["end_header"]
    if fmt == "ascii":
        lines = [" ".join(repr(float(x)) if dt[k].kind == "f" else str(int(x))
                          for k, x in zip(dt.names, row)) for row in v.tolist()]
        path.write_text("\n".join(head + lines) + "\n")
    else:
        path.write_bytes("\n".join(head).encode() + b"\n" + v.tobytes())
    return v


@pytest.mark.parametrize("fmt", ["binary_little_endian", "ascii"])
def test_a_ply_keeps_every_vertex_property(tmp_path, fmt):
    """A PLY's vertex properties, not only its colour, come through `run` and `simplify` to a
    points file with their own names, types and values; its normals are replaced by the
    simplifier's (one nx column)."""
    from tiledsimplify.cli import main
    from tiledsimplify.io.columns import read_columns
    path = tmp_path / "props.ply"
    v = _ply_with_properties(path, fmt)
    X = np.c_[v["x"], v["y"], v["z"]].astype(np.float64)
    for command in ("run", "simplify"):
        out = tmp_path / f"{command}.npy"
        assert main([command, str(path), str(out), "--ratio", "0.1", "-q"]) == 0
        table = np.load(out)
        assert table.dtype.names[:8] == ("x", "y", "z", "red", "green", "blue", "confidence",
                                         "quality")
        assert table.dtype.names.count("nx") == 1
        assert table["confidence"].dtype == np.float32 and table["quality"].dtype == np.uint16
        rows = _rows_of(np.c_[table["x"], table["y"], table["z"]], X)
        assert len(rows) == 500
        for name in ("red", "green", "blue", "confidence", "quality"):
            np.testing.assert_array_equal(table[name], v[name][rows], err_msg=name)
        assert not np.array_equal(table["nz"], np.ones(500, np.float32))  # the fold's
    xyz, cols = read_columns(tmp_path / "run.npy")
    assert "quality" in cols


def test_the_bunnys_confidence_and_intensity_come_through(data_dir, tmp_path):
    """The Stanford Bunny (a gzipped ASCII PLY mesh, read whole) keeps its vertices'
    ``confidence`` and ``intensity`` in a points file and in a LAS output, as extra bytes of
    their own type there: the float intensity (0..1) is not cast into LAS's 16-bit intensity
    (0 there, as before) but kept beside it as ``intensity_float32``. The LAS output had
    neither."""
    laspy = pytest.importorskip("laspy")
    from tiledsimplify.cli import main
    from tiledsimplify.io.mesh import read_ply_vertices
    src = data_dir / "meshes" / "stanford_bunny" / "bun_zipper.ply.gz"
    v = read_ply_vertices(src)
    assert v.dtype.names == ("x", "y", "z", "confidence", "intensity")
    X = np.c_[v["x"], v["y"], v["z"]]
    out = tmp_path / "b.ply"
    assert main(["run", str(src), str(out), "--ratio", "0.1", "--tile-points", "6000",
                 "-q"]) == 0
    from tiledsimplify.io.columns import read_columns
    xyz, cols = read_columns(out)
    rows = _rows_of(xyz, X)
    assert len(rows) == 3595 and list(cols)[:2] == ["confidence", "intensity"]
    for name in ("confidence", "intensity"):
        np.testing.assert_array_equal(cols[name], v[name][rows])
    assert main(["run", str(src), str(tmp_path / "b.laz"), "--ratio", "0.1", "-q"]) == 0
    las = laspy.read(tmp_path / "b.laz")
    assert not las.intensity.any()
    assert list(las.point_format.extra_dimension_names) == [
        "confidence", "intensity_float32", "sharp_edge", "importance", "simplify_rank"]
    from scipy.spatial import cKDTree
    d, rows = cKDTree(X).query(np.c_[las.x, las.y, las.z])  # quantised to the LAS grid
    assert d.max() < float(np.linalg.norm(las.header.scales)) and len(np.unique(rows)) == 3595
    for name, got in (("confidence", "confidence"), ("intensity", "intensity_float32")):
        assert las[got].dtype == np.float32
        np.testing.assert_array_equal(las[got], v[name][rows])


def test_text_rows_give_every_value_back(monkeypatch):
    """The text writer (``points_out._write_text``, formatting a block of rows at a time):
    every value read back exactly as its type — integers as integers (a uint64 beyond 2**53
    too: they went through a float64), float64 as the shortest text that gives it back
    (``repr``: a LAS coordinate ``0.5396``, not ``0.53960000000000008``), float32 (the
    normals) with 9 significant digits (``0.300000012``, not ``0.30000001192092896``) —
    across blocks, against a naive writer, for every column type a points file has."""
    import io

    from tiledsimplify.io import points_out
    monkeypatch.setattr(points_out, "TEXT_BLOCK", 7)
    rng = np.random.default_rng(9)
    n = 40
    table = np.zeros(n, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("red", "u1"),
                               ("i", "i4"), ("flag", "?"), ("nx", "f4"), ("t", "f8"),
                               ("id", "u8"), ("intensity", "f8")])
    for name in ("x", "y", "t"):
        table[name] = rng.normal(size=n) * 10.0 ** rng.integers(-8, 9, n)
    table["z"] = np.round(rng.random(n), 4)  # a LAS grid's
    table["red"], table["i"] = rng.integers(0, 256, n), rng.integers(-5000, 5000, n)
    table["flag"], table["nx"] = rng.random(n) < 0.5, rng.normal(size=n)
    table["t"][:4] = [0.0, -0.0, 1e300, 5e-324]
    table["nx"][:2] = [np.float32(0.3), np.finfo(np.float32).tiny]
    table["id"] = 2**64 - 1 - np.arange(n, dtype=np.uint64)
    table["intensity"] = rng.integers(0, 65536, n)  # a text file's integers, read as float64
    table["intensity"][20] = 0.5  # one block not whole
    table["intensity"][30] = -0.0

    def naive(row, k, block):
        v = row[k]
        if table.dtype[k] == np.float32:
            return "%.9g" % float(v)
        if table.dtype[k] == np.float64:
            whole = all(float(u).is_integer() and abs(u) < 2**53 and not (u == 0 and
                        np.signbit(u)) for u in block[k])
            return str(int(v)) if whole else repr(float(v))
        return str(int(v))

    for sep in (",", " "):
        got = io.BytesIO()
        points_out._write_text(got, table, sep)
        lines = [sep.join(table.dtype.names)] + [
            sep.join(naive(row, k, table[i // 7 * 7:i // 7 * 7 + 7]) for k in table.dtype.names)
            for i, row in enumerate(table)]
        assert got.getvalue().decode() == "\n".join(lines) + "\n"
        text = got.getvalue().decode().splitlines()[1:]
        for j, name in enumerate(table.dtype.names):
            values = [line.split(sep)[j] for line in text]
            back = np.array([int(v) for v in values] if table.dtype[name].kind in "biu"
                            else [float(v) for v in values]).astype(table.dtype[name])
            np.testing.assert_array_equal(back, table[name], err_msg=name)
    assert "0.300000012" in text[0] and "0.30000001192" not in got.getvalue().decode()
    assert len(text[0].split(sep)[2]) <= 6  # the z of the LAS grid: 0.xxxx
    intensity = [line.split(sep)[-1] for line in text]
    assert "." not in "".join(intensity[:14]) and intensity[20] == "0.5"  # 123, not 123.0
    assert intensity[30] == "-0.0" and "." in intensity[29]  # its block is not whole
