"""E57 input: scans read in chunks, invalid points left out, poses and spherical coordinates
applied, and the same simplification as from the same points in another format."""

import importlib
import sys
import uuid

import laspy
import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from tiledsimplify.cli import EXIT_INPUT, EXIT_OK, main
from tiledsimplify.errors import FileFormatError, InputError
from tiledsimplify.io.sources import open_source, read_xyz

pye57 = pytest.importorskip("pye57")
libe57 = pye57.libe57
run_mod = importlib.import_module("tiledsimplify.pipeline.run")


def write_e57(path, scans):
    """An E57 file of ``scans``: each ``{"fields": {name: array}, "rotation": (w, x, y, z),
    "translation": (x, y, z), "limits": {group: {name: value}}}`` (pose and limits optional),
    floats in double precision, their prototype bounds the data's (pye57's own writer stores
    coordinates as float32 and Cartesian only)."""
    f = pye57.E57(str(path), mode="w")
    imf = f.image_file
    for i, sc in enumerate(scans):
        fields = sc["fields"]
        node = libe57.StructureNode(imf)
        node.set("guid", libe57.StringNode(imf, f"{{{uuid.uuid4()}}}"))
        node.set("name", libe57.StringNode(imf, f"scan {i}"))
        if "rotation" in sc or "translation" in sc:
            pose = libe57.StructureNode(imf)
            node.set("pose", pose)
            for key, names, default in (("rotation", "wxyz", (1.0, 0.0, 0.0, 0.0)),
                                        ("translation", "xyz", (0.0, 0.0, 0.0))):
                part = libe57.StructureNode(imf)
                for k, v in zip(names, sc.get(key, default)):
                    part.set(k, libe57.FloatNode(imf, float(v)))
                pose.set(key, part)
        for group, values in sc.get("limits", {}).items():
            limits = libe57.StructureNode(imf)
            for key, v in values.items():
                limits.set(key, libe57.FloatNode(imf, float(v)))
            node.set(group, limits)
        proto = libe57.StructureNode(imf)
        for name, arr in fields.items():
            lo, hi = arr.min(), arr.max()
            proto.set(name, libe57.FloatNode(imf, float(lo), libe57.E57_DOUBLE, float(lo),
                                             float(hi)) if arr.dtype.kind == "f"
                      else libe57.IntegerNode(imf, int(lo), int(lo), int(hi)))
        points = libe57.CompressedVectorNode(imf, proto, libe57.VectorNode(imf, True))
        node.set("points", points)
        f.data3d.append(node)
        n = len(next(iter(fields.values())))
        buffers = libe57.VectorSourceDestBuffer()
        keep = []
        for name, arr in fields.items():  # as float64, converted by libE57Format (pye57's
            # int64 buffers write zeros; integers are exact to 2**53)
            arr = np.ascontiguousarray(arr, dtype="d")
            keep.append(arr)
            buffers.append(libe57.SourceDestBuffer(imf, name, arr, n, True, True))
        writer = points.writer(buffers)
        writer.write(n)
        writer.close()
    f.close()


def cartesian(P, state=None):
    out = {"cartesianX": P[:, 0], "cartesianY": P[:, 1], "cartesianZ": P[:, 2]}
    if state is not None:
        out["cartesianInvalidState"] = state
    return out


@pytest.fixture()
def bunny(data_dir):
    return read_xyz(data_dir / "meshes" / "stanford_bunny" / "bun_zipper.ply.gz")[0]


def test_scans_are_read_in_chunks_in_the_files_frame(tmp_path):
    rng = np.random.default_rng(0)
    A, B = rng.random((1000, 3)) * 5, rng.random((700, 3)) * 5
    state = np.zeros(len(A), dtype=np.int8)
    state[::7] = 2  # no return
    state[3::11] = 1  # a direction only
    A_stored = A.copy()
    A_stored[state != 0] = 1e6  # what a scanner leaves there is no position
    rot = Rotation.from_euler("zyx", [30, -20, 75], degrees=True)
    x, y, z, w = rot.as_quat()
    t = np.array([100.0, -20.0, 3.5])
    path = tmp_path / "two.e57"
    write_e57(path, [{"fields": cartesian(A_stored, state)},
                     {"fields": cartesian(B), "rotation": (w, x, y, z), "translation": t}])
    expect = np.concatenate([A[state == 0], rot.apply(B) + t])
    for chunk in (1, 97, 1000, 10 ** 6):
        src = open_source(path, chunk_points=chunk)
        assert src.count == len(expect) and not src.is_las and src.files == [path]
        got = list(src.chunks())
        assert all(len(xyz) <= chunk for _, xyz, _ in got)
        assert [s for s, _, _ in got] == list(np.cumsum([0] + [len(c) for _, c, _ in got])[:-1])
        np.testing.assert_allclose(np.concatenate([c for _, c, _ in got]), expect, rtol=0,
                                   atol=1e-12)


def test_spherical_scans_become_cartesian(tmp_path):
    rng = np.random.default_rng(1)
    P = rng.normal(size=(500, 3)) * 10
    r = np.linalg.norm(P, axis=1)
    fields = {"sphericalRange": r, "sphericalAzimuth": np.arctan2(P[:, 1], P[:, 0]),
              "sphericalElevation": np.arcsin(P[:, 2] / r),
              "sphericalInvalidState": np.r_[np.zeros(499, dtype=np.int8), 2]}
    path = tmp_path / "sph.e57"
    write_e57(path, [{"fields": fields, "translation": (1.0, 2.0, 3.0)}])
    xyz, src = read_xyz(path)
    assert src.count == 499
    np.testing.assert_allclose(xyz, P[:499] + [1.0, 2.0, 3.0], rtol=0, atol=1e-9)


def test_an_e57_simplifies_as_the_same_points_in_npy(bunny, tmp_path):
    # the Bunny in two scans, the second stored in its scanner's frame with a pose
    rot = Rotation.from_euler("xyz", [10, 40, -65], degrees=True)
    t = np.array([0.3, -0.1, 0.05])
    half = len(bunny) // 2
    x, y, z, w = rot.as_quat()
    e57 = tmp_path / "bunny.e57"
    write_e57(e57, [{"fields": cartesian(bunny[:half])},
                    {"fields": cartesian(rot.inv().apply(bunny[half:] - t)),
                     "rotation": (w, x, y, z), "translation": t}])
    xyz = read_xyz(e57)[0]
    np.testing.assert_allclose(xyz, bunny, rtol=0, atol=1e-12)
    npy = tmp_path / "bunny.npy"
    np.save(npy, xyz)  # the same coordinates, bit for bit
    outs = []
    for src in (e57, npy):
        out = tmp_path / f"{src.suffix[1:]}_out.npy"
        run_mod.run(src, out, ratio=0.1, tile_points=12000, workers=2)
        outs.append(np.load(out))
    assert len(outs[0]) == round(0.1 * len(bunny))
    assert outs[0].tobytes() == outs[1].tobytes()  # bit for bit (NaN importance of kept)
    for src in (e57, npy):
        assert main(["simplify", str(src), str(tmp_path / f"s_{src.suffix[1:]}.npy"),
                     "--ratio", "0.1", "-q"]) == EXIT_OK
    assert np.load(tmp_path / "s_e57.npy").tobytes() == np.load(tmp_path / "s_npy.npy").tobytes()


def test_a_broken_or_unreadable_e57_is_named(tmp_path, monkeypatch, caplog):
    bad = tmp_path / "bad.e57"
    bad.write_bytes(b"ASTM-E57" + bytes(5000))
    with pytest.raises(FileFormatError, match=r"bad\.e57: not a readable E57 file"):
        open_source(bad)
    good = tmp_path / "good.e57"
    write_e57(good, [{"fields": cartesian(np.random.default_rng(2).random((5000, 3)))}])
    cut = tmp_path / "cut.e57"
    cut.write_bytes(good.read_bytes()[:3000])  # a copy that stopped part-way
    with pytest.raises(FileFormatError, match=r"cut\.e57: not a readable E57 file"):
        list(open_source(cut).chunks())
    assert main(["run", str(bad), str(tmp_path / "o.laz"), "--ratio", "0.5", "-q"]) == EXIT_INPUT
    assert "bad.e57: not a readable E57 file" in caplog.text
    monkeypatch.setitem(sys.modules, "pye57", None)  # not installed
    with pytest.raises(InputError, match=r"good\.e57: reading E57 files needs the pye57 "
                                         r"package: pip install 'tiledsimplify\[e57\]'"):
        open_source(good)


def test_intensity_and_colour_reach_a_las_output(tmp_path):
    rng = np.random.default_rng(5)
    A, B = rng.random((3000, 3)), rng.random((2000, 3)) + [0.0, 0.0, 1.5]
    # intensities as float32 values (pye57 reads and writes intensity through float32 buffers)
    ia = (rng.random(3000) * 2.0).astype(np.float32).astype(np.float64)
    ib = (rng.random(2000) * 7.0 + 3.0).astype(np.float32).astype(np.float64)
    rgb = rng.integers(0, 256, (3000, 3)).astype(np.uint8)
    state = np.zeros(3000, dtype=np.int8)
    state[::5] = 2
    path = tmp_path / "rgb.e57"
    write_e57(path, [
        {"fields": {**cartesian(A, state), "intensity": ia, "colorRed": rgb[:, 0],
                    "colorGreen": rgb[:, 1], "colorBlue": rgb[:, 2]},
         "limits": {"intensityLimits": {"intensityMinimum": 0.0, "intensityMaximum": 2.0},
                    "colorLimits": {f"color{c}{m}": v for c in ("Red", "Green", "Blue")
                                    for m, v in (("Minimum", 0), ("Maximum", 255))}}},
        {"fields": {**cartesian(B), "intensity": ib}}])  # no limits: its bounds; no colour
    src = open_source(path, chunk_points=700)
    assert list(src.attributes) == ["intensity", "red", "green", "blue"]
    ok = state == 0
    want = {"intensity": np.r_[np.rint(ia[ok] * (65535 / 2.0)),
                               np.rint((ib - ib.min()) * (65535 / (ib.max() - ib.min())))],
            "red": np.r_[rgb[ok, 0].astype(float) * 257, np.zeros(2000)],
            "green": np.r_[rgb[ok, 1].astype(float) * 257, np.zeros(2000)],
            "blue": np.r_[rgb[ok, 2].astype(float) * 257, np.zeros(2000)]}
    chunks = list(src.chunks())
    for name, values in want.items():
        got = np.concatenate([a[name] for _, _, a in chunks])
        assert got.dtype == np.uint16
        np.testing.assert_array_equal(got, values)
    out = tmp_path / "out.laz"
    run_mod.run(path, out, ratio=0.3, tile_points=1500)
    las = laspy.read(out)
    assert las.header.point_format.id == 7 and len(las.points) == round(0.3 * src.count)
    xyz = np.concatenate([c for _, c, _ in chunks])
    d, i = cKDTree(xyz).query(np.c_[las.x, las.y, las.z])
    assert d.max() < 1e-3 * 0.02  # each output point is an input point, quantised
    for name, values in want.items():
        np.testing.assert_array_equal(np.asarray(las[name]), values[i])
    assert set(np.flatnonzero(i >= ok.sum())) and not np.asarray(las.red)[i >= ok.sum()].any()


def test_a_scans_other_fields_come_through(tmp_path):
    """E57's other point fields reach the output: ``returnIndex`` / ``returnCount`` as LAS's
    ``return_number`` (from 1) and ``number_of_returns``, ``rowIndex``, ``columnIndex`` and
    ``timeStamp`` under their own names (extra bytes in a LAS output), typed by the widest
    scan's bounds, 0 where a scan lacks the field (1 for its returns: one a point); their
    values the input's at the kept points. They were dropped."""
    from scipy.spatial import cKDTree
    rng = np.random.default_rng(6)
    A, B = rng.random((3000, 3)), rng.random((2000, 3)) + [0.0, 0.0, 1.5]
    rows_a, cols_a = np.divmod(np.arange(3000), 60)
    count_a = rng.integers(1, 4, 3000)
    index_a = rng.integers(0, 3, 3000) % count_a
    time_a = np.sort(rng.random(3000)) * 1e3
    rows_b = np.arange(2000) * 100_000  # up to 2e8: int32
    path = tmp_path / "fields.e57"
    write_e57(path, [
        {"fields": {**cartesian(A), "rowIndex": rows_a, "columnIndex": cols_a,
                    "returnIndex": index_a, "returnCount": count_a, "timeStamp": time_a}},
        {"fields": {**cartesian(B), "rowIndex": rows_b}}])
    src = open_source(path, chunk_points=700)
    assert src.attributes == {"return_number": np.int8, "number_of_returns": np.int8,
                              "rowIndex": np.int32, "columnIndex": np.int8,
                              "timeStamp": np.float64}
    want = {"return_number": np.r_[index_a + 1, np.ones(2000)],
            "number_of_returns": np.r_[count_a, np.ones(2000)],
            "rowIndex": np.r_[rows_a, rows_b], "columnIndex": np.r_[cols_a, np.zeros(2000)],
            "timeStamp": np.r_[time_a, np.zeros(2000)]}
    chunks = list(src.chunks())
    for name, values in want.items():
        got = np.concatenate([a[name] for _, _, a in chunks])
        assert got.dtype == src.attributes[name]
        np.testing.assert_array_equal(got, values)
    xyz = np.r_[A, B]
    run_mod.run(path, tmp_path / "out.laz", ratio=0.3, tile_points=1500)
    las = laspy.read(tmp_path / "out.laz")
    assert list(las.point_format.extra_dimension_names)[:3] == [
        "rowIndex", "columnIndex", "timeStamp"]
    d, i = cKDTree(xyz).query(np.c_[las.x, las.y, las.z])
    assert d.max() < float(np.linalg.norm(las.header.scales))
    for name, values in want.items():
        np.testing.assert_array_equal(np.asarray(las[name]), values[i], err_msg=name)
    run_mod.run(path, tmp_path / "out.npy", ratio=0.3, tile_points=1500)
    table = np.load(tmp_path / "out.npy")
    assert table.dtype.names[3:8] == tuple(want)
    d, i = cKDTree(xyz).query(np.c_[table["x"], table["y"], table["z"]])
    assert d.max() == 0
    for name, values in want.items():
        np.testing.assert_array_equal(table[name], values[i], err_msg=name)


def test_sixteen_bit_colour_is_read_whole(tmp_path):
    # pye57's own buffers hold colour as uint8: a scan of 16-bit colour overflowed them
    rng = np.random.default_rng(6)
    P = rng.random((400, 3))
    rgb = rng.integers(0, 65536, (400, 3)).astype(np.uint16)
    path = tmp_path / "c16.e57"
    write_e57(path, [{"fields": {**cartesian(P), "colorRed": rgb[:, 0], "colorGreen": rgb[:, 1],
                                 "colorBlue": rgb[:, 2]},
                      "limits": {"colorLimits": {f"color{c}{m}": v
                                                 for c in ("Red", "Green", "Blue")
                                                 for m, v in (("Minimum", 0),
                                                              ("Maximum", 65535))}}}])
    src = open_source(path, chunk_points=128)
    assert list(src.attributes) == ["red", "green", "blue"]
    got = list(src.chunks())
    for j, name in enumerate(("red", "green", "blue")):
        np.testing.assert_array_equal(np.concatenate([a[name] for _, _, a in got]), rgb[:, j])


def test_a_project_exported_scan_by_scan_reads_as_one_cloud(bunny, tmp_path, data_dir):
    # one registered project, one E57 file a scan station: a folder, a glob or a list of them
    half = len(bunny) // 2
    rot = Rotation.from_euler("z", 120, degrees=True)
    x, y, z, w = rot.as_quat()
    t = np.array([0.0, 0.2, 0.0])
    folder = tmp_path / "project"
    folder.mkdir()
    write_e57(folder / "st01.e57", [{"fields": cartesian(bunny[:half])}])
    write_e57(folder / "st02.e57", [{"fields": cartesian(rot.inv().apply(bunny[half:] - t)),
                                     "rotation": (w, x, y, z), "translation": t}])
    (folder / "notes.txt").write_text("station log")
    for spec in (folder, str(folder / "*.e57"), [folder / "st01.e57", folder / "st02.e57"]):
        xyz, src = read_xyz(spec)
        assert [p.name for p in src.files] == ["st01.e57", "st02.e57"]
        np.testing.assert_allclose(xyz, bunny, rtol=0, atol=1e-12)
    out = tmp_path / "out.npy"
    run_mod.run(folder, out, ratio=0.1, tile_points=12000)
    assert len(np.load(out)) == round(0.1 * len(bunny))
    # a folder that holds LAS/LAZ tiles is read as LAS tiles, as before
    import shutil
    shutil.copy(data_dir / "lidar" / "autzen_trim.laz", folder / "tile.laz")
    assert open_source(folder).is_las
    # a broken file among them is named
    (folder / "tile.laz").unlink()
    (folder / "st03.e57").write_bytes(b"ASTM-E57" + bytes(4000))
    with pytest.raises(FileFormatError, match=r"st03\.e57: not a readable E57 file"):
        open_source(folder)
