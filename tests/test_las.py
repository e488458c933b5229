"""Tests for tiledsimplify.io.las and .las_output: LAS/LAZ files, chunked reading, streaming
LasOutput."""

from __future__ import annotations

import itertools
import pickle
import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

laspy = pytest.importorskip("laspy")

from laspy.vlrs.vlrlist import VLRList  # noqa: E402

from tiledsimplify.errors import FileFormatError, InputError  # noqa: E402
from tiledsimplify.io.las import LasSource, las_files  # noqa: E402
from tiledsimplify.io.las_output import SIMPLIFY_DIMS, LasOutput, write_las  # noqa: E402

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
LIDAR = DATA / "lidar"

AUTZEN = "autzen_trim.laz"        # LAS 1.2, point format 3, 110,000 points
LONE_STAR = "lone-star.laz"       # LAS 1.1, point format 1, 518,862 points
EXTRA = "las_with_several_extra_byte_bloc.laz"  # LAS 1.4, PF 8, 697,721 points, 2 EB VLRs
COUNTS = {AUTZEN: 110_000, LONE_STAR: 518_862, EXTRA: 697_721}
CHUNK = 77_777  # divides none of the counts


def lidar_file(name: str) -> Path:
    path = LIDAR / name
    if not path.is_file():
        pytest.skip(f"test data {path} not found")
    return path


_CACHE: dict = {}


def chunked(name: str):
    """(source, list of (start, xyz, attrs)) read once per test session with CHUNK."""
    if name not in _CACHE:
        src = LasSource(lidar_file(name), chunk_points=CHUNK)
        _CACHE[name] = (src, list(src.chunks()))
    return _CACHE[name]


def whole(name: str):
    src, parts = chunked(name)
    xyz = np.concatenate([p[1] for p in parts])
    attrs = {k: np.concatenate([p[2][k] for p in parts]) for k in src.attribute_names}
    return src, xyz, attrs


def small_las(path: Path, name: str, sl: slice, *, offsets=None) -> np.ndarray:
    """Write points ``sl`` of a data file to ``path`` with laspy; return their xyz."""
    las = laspy.read(lidar_file(name))
    xyz = np.c_[las.x[sl], las.y[sl], las.z[sl]]
    out = laspy.LasData(las.header)
    out.points = las.points[sl]
    if offsets is not None:
        out.change_scaling(offsets=offsets)
    out.write(path)
    return xyz


def vlr_payloads(vlrs):
    keep = []
    for v in vlrs:
        if type(v).__name__ in ("LasZipVlr", "ExtraBytesVlr"):
            continue
        keep.append((v.user_id, v.record_id, bytes(v.record_data_bytes())))
    return keep


# --------------------------------------------------------------------------------------
# description from the headers
# --------------------------------------------------------------------------------------

def test_description_from_headers():
    src = LasSource(lidar_file(AUTZEN))
    assert src.count == len(src) == 110_000
    assert src.point_format_id == 3 and src.version == "1.2"
    assert np.allclose(src.scales, 0.01) and np.allclose(src.offsets, 0)
    mins, maxs = src.bounds
    assert np.allclose(mins, [636001.76, 848935.20, 406.26])
    assert np.allclose(maxs, [637179.22, 849497.90, 520.51])
    assert src.crs.startswith('PROJCS["NAD_1983_HARN_Lambert_Conformal_Conic"')  # WKT, no EPSG
    assert src.dimension_names[:3] == ("X", "Y", "Z") and "red" in src.dimension_names
    assert "X" not in src.attribute_names and "gps_time" in src.attribute_names
    assert src.extra_dimension_names == ()

    lone = LasSource(lidar_file(LONE_STAR))
    assert (lone.count, lone.point_format_id, lone.version) == (518_862, 1, "1.1")
    assert lone.crs == "EPSG:4326"  # what the GeoTIFF keys say (coordinates look like UTM)

    extra = LasSource(lidar_file(EXTRA))
    assert (extra.count, extra.point_format_id, extra.version) == (697_721, 8, "1.4")
    assert extra.crs == "EPSG:2154"
    # two Extra Bytes VLRs: laspy alone would call the second "ExtraBytes"
    assert extra.extra_dimension_names == ("Deviation", "confidence")
    assert extra.infos[0].extra_dimensions[1] == ("confidence", "uint8", "confidence values")


# --------------------------------------------------------------------------------------
# chunked reading
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", [AUTZEN, LONE_STAR, EXTRA])
def test_chunked_read_equals_whole_read(name):
    src, parts = chunked(name)
    starts = [p[0] for p in parts]
    sizes = [len(p[1]) for p in parts]
    assert starts == list(np.cumsum([0] + sizes[:-1]))
    assert sum(sizes) == COUNTS[name] and max(sizes) == CHUNK and sizes[-1] < CHUNK

    las = laspy.read(lidar_file(name))  # the whole file in one go, by laspy itself
    _, xyz, attrs = whole(name)
    assert xyz.dtype == np.float64 and xyz.shape == (COUNTS[name], 3)
    np.testing.assert_array_equal(xyz, np.c_[las.x, las.y, las.z])
    assert set(attrs) == set(src.attribute_names)
    raw = las.points.array  # laspy's names differ only for the merged extra bytes
    for dim in las.point_format.dimension_names:
        if dim in ("X", "Y", "Z") or dim == "ExtraBytes":
            continue
        np.testing.assert_array_equal(attrs[dim], np.array(las[dim]), err_msg=dim)
    if name == EXTRA:
        np.testing.assert_array_equal(attrs["confidence"], raw["ExtraBytes"].reshape(-1))
        assert set(np.unique(attrs["confidence"])) <= {1, 2, 5, 6, 9, 65}

    one = LasSource(lidar_file(name), chunk_points=10**7)
    (start, xyz1, attrs1), = list(one.chunks())
    assert start == 0
    np.testing.assert_array_equal(xyz1, xyz)
    for dim in attrs:
        np.testing.assert_array_equal(attrs1[dim], attrs[dim], err_msg=dim)


def test_parts_read_as_the_whole_from_any_point_of_a_laz(tmp_path):
    files = [lidar_file(AUTZEN), lidar_file(LONE_STAR)]
    with pytest.warns(UserWarning, match="different CRS"):
        src = LasSource(files, chunk_points=CHUNK)
    whole = list(src.chunks())
    parts = src.parts(2 * CHUNK + 5)  # two chunks a part; LAZ read from inside the file
    assert [(p.path.name, p.lo, p.hi) for p in parts][:3] == [
        (AUTZEN, 0, COUNTS[AUTZEN]), (LONE_STAR, 0, 2 * CHUNK),
        (LONE_STAR, 2 * CHUNK, 4 * CHUNK)]
    assert parts[-1].hi == COUNTS[LONE_STAR] and src.parts(1)[1].lo == CHUNK
    got = [c for p in parts for c in pickle.loads(pickle.dumps(p))()]  # as a worker reads
    assert len(got) == len(whole)
    for (s1, x1, a1), (s2, x2, a2) in zip(whole, got):
        assert s1 == s2 and np.array_equal(x1, x2)
        assert a1.keys() == a2.keys() and all(np.array_equal(a1[k], a2[k]) for k in a1)
    assert [len(p.chunks().__next__()[1]) for p in src.parts()] == [CHUNK, CHUNK]


def variable_chunk_laz(path, monkeypatch, sizes):
    """autzen_trim.laz rewritten as LAZ of chunks of varying size, as COPC files are (LASzip
    chunk size 2**32 - 1): lazrs told to compress so, a chunk ended after each of ``sizes``
    points (the rest in a last chunk)."""
    import lazrs
    make = lazrs.LazVlr.new_for_compression
    monkeypatch.setattr(lazrs.LazVlr, "new_for_compression",
                        lambda pf, eb, use_variable_size_chunks=False: make(pf, eb, True))
    src = laspy.read(lidar_file(AUTZEN))
    ends = [*np.cumsum(sizes).tolist(), len(src.points)]
    with laspy.open(path, mode="w", header=src.header, do_compress=True,
                    laz_backend=laspy.LazBackend.Lazrs) as w:
        for lo, hi in itertools.pairwise([0, *ends]):
            if lo:
                w.point_writer.compressor.finish_current_chunk()
            w.write_points(src.points[lo:hi])
    monkeypatch.undo()
    return src


def _read_parts(parts):
    """Every chunk of ``parts``, each part pickled first (as a worker reads it)."""
    return [c for p in parts for c in pickle.loads(pickle.dumps(p))()]


def test_laz_of_variable_chunks_is_cut_at_its_chunks(tmp_path, monkeypatch):
    """A LAZ file whose chunks vary in size (COPC) is cut at its own chunks, and a part that
    does not start it decompresses its chunks from their bytes: lazrs seeks such files into
    the wrong chunk (other points or zeros, no error), so a part read by seeking got wrong
    points. Read in parts of any size, and in chunks of any size, its points and attributes
    are the original's, with the right start indices."""
    from tiledsimplify.io.las import variable_chunks
    sizes = [7_000, 23_000, 1_000, 41_000]  # and a last chunk of 38,000
    src = variable_chunk_laz(tmp_path / "var.laz", monkeypatch, sizes)
    expected = np.c_[src.x, src.y, src.z]
    with laspy.open(tmp_path / "var.laz") as r:
        assert variable_chunks(r.header)
    with laspy.open(lidar_file(AUTZEN)) as r:
        assert not variable_chunks(r.header)
    info = LasSource(tmp_path / "var.laz").infos[0]
    assert not info.seekable
    assert info.laz_chunks.points.tolist() == [*sizes, 38_000]
    with laspy.open(tmp_path / "var.laz") as r:  # what this reader would have read
        r.seek(30_000)
        assert not np.array_equal(r.read_points(5).X, src.points.X[30_000:30_005])
    for max_points, chunk_points, cuts in [
            (None, 9_000, [0]), (1, 9_000, [0, 7_000, 30_000, 31_000, 72_000]),
            (30_000, 100_000, [0, 30_000, 31_000, 72_000]), (40_000, 16_000, [0, 31_000, 72_000]),
            (10 ** 9, 5_000, [0])]:
        source = LasSource(tmp_path / "var.laz", chunk_points=chunk_points)
        parts = source.parts(max_points)
        assert [p.lo for p in parts] == cuts and parts[-1].hi == COUNTS[AUTZEN]
        got = _read_parts(parts)
        assert max(len(c[1]) for c in got) <= chunk_points
        assert [s for s, _, _ in got] == np.cumsum([0] + [len(c[1]) for c in got])[:-1].tolist()
        np.testing.assert_array_equal(np.concatenate([c[1] for c in got]), expected)
        for name in source.attribute_names:
            np.testing.assert_array_equal(np.concatenate([c[2][name] for c in got]),
                                          np.asarray(src.points[name]), err_msg=name)
    # with a file of fixed chunks after it, the running index goes on
    with pytest.warns(UserWarning, match="different CRS"):
        both = LasSource([tmp_path / "var.laz", lidar_file(LONE_STAR)], chunk_points=CHUNK)
    assert [p.seekable for p in both.infos] == [False, True]
    parts = both.parts(CHUNK)
    assert [(p.first, p.lo, p.hi) for p in parts[:4]] == [
        (0, 0, 72_000), (0, 72_000, COUNTS[AUTZEN]), (COUNTS[AUTZEN], 0, CHUNK),
        (COUNTS[AUTZEN], CHUNK, 2 * CHUNK)]
    assert _read_parts(parts[1:3])[1][0] == COUNTS[AUTZEN]
    # a run that ingests in parts (4 threads, parts of 20,000 points) writes what a run
    # reading it in one process writes, as for a file of fixed chunks
    import importlib
    run_module = importlib.import_module("tiledsimplify.pipeline.run")
    kw = {"ratio": 0.3, "tile_points": 30000, "chunk_points": 20_000}
    run_module.run(tmp_path / "var.laz", tmp_path / "one.laz", scheduler="synchronous", **kw)
    monkeypatch.setattr(run_module, "INGEST_PART_POINTS", 20_000)
    monkeypatch.setattr(run_module, "INGEST_PARTS_FROM", 2)
    run_module.run(tmp_path / "var.laz", tmp_path / "parts.laz", scheduler="threads",
                   workers=4, **kw)
    assert (tmp_path / "parts.laz").read_bytes() == (tmp_path / "one.laz").read_bytes()


def test_laz_chunk_table_that_disagrees_or_is_cut_off(tmp_path, monkeypatch):
    """A chunk table whose points do not add up to the header's count, and a file cut off
    inside a chunk a part reads, are errors naming the file (no wrong points)."""
    variable_chunk_laz(tmp_path / "var.laz", monkeypatch, [50_000])
    import lazrs
    read = lazrs.read_chunk_table
    monkeypatch.setattr(lazrs, "read_chunk_table",
                        lambda fh, vlr: [(m - 1, size) for m, size in read(fh, vlr)])
    with pytest.raises(FileFormatError, match=r"var\.laz: its LAZ chunk table holds 109998"):
        LasSource(tmp_path / "var.laz")
    monkeypatch.undo()
    source = LasSource(tmp_path / "var.laz")
    parts = source.parts(1)
    cut = tmp_path / "cut.laz"
    data = (tmp_path / "var.laz").read_bytes()
    table = source.infos[0].laz_chunks
    cut.write_bytes(data[:table.start + int(table.sizes[0]) + 100])  # inside the 2nd chunk
    parts[1].path = cut
    parts[1].expect = parts[0].expect
    with pytest.raises(FileFormatError, match=r"cut\.laz: truncated: .* points 50000 to 109999"):
        list(parts[1]())


def test_a_copc_inputs_octree_records_are_not_copied(tmp_path, caplog):
    """The "copc" VLR and EVLR describe a COPC file's octree; an output that kept them would
    be taken for a COPC file. They are dropped from the output's template; others stay. An
    output named *.copc.laz gets a warning: it is plain LAZ."""
    from tiledsimplify.pipeline import run
    src = laspy.read(lidar_file(AUTZEN))
    las = laspy.convert(src, point_format_id=7, file_version="1.4")
    las.header.vlrs.insert(0, laspy.VLR("copc", 1, "copc info", bytes(160)))
    las.header.vlrs.append(laspy.VLR("ours", 7, "kept", b"hello"))
    las.header.evlrs = laspy.vlrs.vlrlist.VLRList([laspy.VLR("copc", 1000, "EPT hierarchy", bytes(32)),
                                      laspy.VLR("ours", 8, "kept too", b"world")])
    las.points = las.points[:4000]
    las.write(tmp_path / "in.laz")
    with laspy.open(tmp_path / "in.laz") as r:  # as written: the records are there
        assert "copc" in {v.user_id for v in r.header.vlrs}
    header = LasSource(tmp_path / "in.laz").template_header()
    assert [(v.user_id, v.record_id) for v in header.vlrs if v.user_id in ("copc", "ours")] == \
        [("ours", 7)]
    assert [(v.user_id, v.record_id) for v in header.evlrs] == [("ours", 8)]
    with caplog.at_level("WARNING", logger="tiledsimplify"):
        run(tmp_path / "in.laz", tmp_path / "out.laz", ratio=0.5)
        assert "COPC" not in caplog.text
        run(tmp_path / "in.laz", tmp_path / "out.copc.laz", ratio=0.5)
    assert "out.copc.laz: written as a plain LAZ file, not as COPC" in caplog.text
    with laspy.open(tmp_path / "out.laz") as r:
        assert "copc" not in {v.user_id for v in r.header.vlrs}
        assert [(v.user_id, v.record_id) for v in r.header.evlrs] == [("ours", 8)]
        assert r.header.point_count == 2000


def test_folder_and_glob_read_as_one_cloud(tmp_path):
    folder = tmp_path / "tiles"
    folder.mkdir()
    a = small_las(folder / "a.las", AUTZEN, slice(0, 1000))
    # different offsets in the second file: coordinates still come back as the same floats
    b = small_las(folder / "b.LAS", AUTZEN, slice(1000, 2500), offsets=[636000.0, 848900.0, 400.0])
    (folder / "notes.txt").write_text("not a point cloud")
    expected = np.concatenate([a, b])

    for spec in (folder, str(folder / "*.[lL][aA][sS]"), [folder / "a.las", folder / "b.LAS"]):
        assert [p.name for p in las_files(spec)] == ["a.las", "b.LAS"]
        src = LasSource(spec, chunk_points=700)
        assert src.count == 2500
        parts = list(src.chunks())
        assert [p[0] for p in parts] == [0, 700, 1000, 1700, 2400]  # chunks stop at file ends
        xyz = np.concatenate([p[1] for p in parts])
        np.testing.assert_allclose(xyz, expected, rtol=0, atol=1e-9)
        src.template_header()  # same point format and dimensions: writable
    mins, maxs = LasSource(folder).bounds
    np.testing.assert_allclose(mins, expected.min(axis=0))
    np.testing.assert_allclose(maxs, expected.max(axis=0))


def test_files_with_and_without_crs_records_are_warned_of(tmp_path):
    """A folder whose first file has no CRS records (its tiles' others have) gave an output
    without a CRS, silently: only CRS descriptions that both existed were compared."""
    small_las(tmp_path / "b.las", AUTZEN, slice(0, 300))
    las = laspy.read(tmp_path / "b.las")
    las.header.vlrs.clear()
    las.write(tmp_path / "a.las")
    with pytest.warns(UserWarning, match=r"different CRS .*takes the first file's CRS, here "
                                         r"none\): a\.las: no CRS records; b\.las: PROJCS"):
        src = LasSource(tmp_path)
    assert src.crs is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        LasSource(tmp_path / "b.las")
        LasSource([tmp_path / "a.las", tmp_path / "a.las"])


def test_mixed_point_formats_read_but_do_not_write(tmp_path):
    small_las(tmp_path / "a.las", AUTZEN, slice(0, 300))      # PF 3 (with RGB)
    small_las(tmp_path / "b.las", LONE_STAR, slice(0, 200))   # PF 1
    with pytest.warns(UserWarning, match=r"different CRS .*\(not reprojected; a LAS/LAZ output "
                                         r"takes the first file's CRS\): a\.las: .*; b\.las: "
                                         r"EPSG:4326\. Reproject"):
        src = LasSource(tmp_path)
    assert "red" not in src.attribute_names and "gps_time" in src.attribute_names
    xyz, attrs = src.read_all()
    assert len(xyz) == 500 and all(len(v) == 500 for v in attrs.values())
    with pytest.raises(FileFormatError, match=r"b\.las.*a\.las.*PDAL|b\.las.*a\.las.*pdal"):
        src.template_header()


def test_files_that_count_gps_time_differently_do_not_write(tmp_path):
    """Two files of one layout, one in GPS week time and one in adjusted standard time: one
    output has one encoding, so their times would mix; refused, as differing formats are."""
    from laspy.header import GpsTimeType
    small_las(tmp_path / "a.las", AUTZEN, slice(0, 300))
    las = laspy.read(tmp_path / "a.las")
    las.header.global_encoding.gps_time_type = GpsTimeType.STANDARD
    las.write(tmp_path / "b.las")
    src = LasSource(tmp_path)
    assert src.count == 600 and "gps_time" in src.attribute_names  # reading is fine
    with pytest.raises(FileFormatError, match=r"b\.las \(adjusted standard GPS time\) and .*"
                                              r"a\.las \(week GPS time\) count gps_time "
                                              r"differently"):
        src.template_header()
    las.header.global_encoding.gps_time_type = GpsTimeType.WEEK_TIME
    las.write(tmp_path / "b.las")
    LasSource(tmp_path).template_header()  # the same encoding: writable


@pytest.mark.parametrize("case", ["formats", "dimension"])
def test_run_refuses_an_output_layout_before_the_work(tmp_path, case):
    """What the LAS writer would refuse at the end of a run — files of two point formats, or
    an input dimension named as one the output adds but of another type — is refused before
    the ingest: no tile store, no output (it used to fail after the whole run)."""
    from tiledsimplify.pipeline import run
    folder = tmp_path / "in"
    folder.mkdir()
    small_las(folder / "a.las", AUTZEN, slice(0, 3000))
    if case == "formats":
        small_las(folder / "b.las", LONE_STAR, slice(0, 2000))
        error, match = FileFormatError, r"b\.las.*a\.las.*same point format"
    else:
        las = laspy.read(folder / "a.las")
        las.add_extra_dim(laspy.ExtraBytesParams(name="importance", type=np.float32))
        las.write(folder / "a.las")
        error, match = InputError, (r"out\.laz: the template already has an extra dimension "
                                    r"of that name of type float32")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # different CRS
        with pytest.raises(error, match=match):
            run(folder, tmp_path / "out.laz", ratio=0.5, store=tmp_path / "store")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]
    if case == "dimension":  # the same input to a non-LAS output keeps no such dimension: runs
        run(folder, tmp_path / "out.npy", ratio=0.5)
        assert len(np.load(tmp_path / "out.npy")) == 1500


def test_run_refuses_files_off_the_output_grid_before_the_tiles(tmp_path, caplog):
    """Two files of one layout, the second 1e8 m away with its own offsets: the output takes
    the first file's grid (scale 0.01, int32), which cannot hold both. Refused right after the
    ingest (from the bounds it read), before any tile runs, naming the output; no output."""
    import logging

    from tiledsimplify.pipeline import run
    folder = tmp_path / "in"
    folder.mkdir()
    small_las(folder / "a.las", AUTZEN, slice(0, 3000))
    las = laspy.read(folder / "a.las")
    far = laspy.LasData(las.header)
    far.points = las.points[:]
    with np.errstate(invalid="ignore"):  # the old x overflow the new grid until set again
        far.change_scaling(offsets=np.asarray(las.header.offsets) + [1e8, 0.0, 0.0])
    far.x = las.x + 1e8
    far.write(folder / "b.las")
    with caplog.at_level(logging.INFO, logger="tiledsimplify"), pytest.raises(
            InputError, match=r"out\.laz: coordinates .* do not fit the output's int32 grid "
                              r"\(scales \[0\.01 0\.01 0\.01\]"):
        run(folder, tmp_path / "out.laz", ratio=0.5, store=tmp_path / "store")
    assert "ingested 6,000 points" in caplog.text and "tile 0" not in caplog.text
    assert sorted(p.name for p in tmp_path.iterdir()) == [".store.lock", "in", "store"]


def test_run_warns_of_files_on_another_grid_than_the_first(tmp_path, caplog):
    """A folder merging files of another scale or offset: the LAS/LAZ output takes the first
    file's grid and rounds the others' kept points to it (up to half a step) — silently
    until now. Offsets a whole number of steps away and coarser multiples move nothing."""
    import logging

    from tiledsimplify.pipeline import run
    folder = tmp_path / "in"
    folder.mkdir()
    small_las(folder / "a.las", AUTZEN, slice(0, 1500))
    small_las(folder / "b.las", AUTZEN, slice(1500, 3000), offsets=[1000.0, -20.0, 3.0])
    with caplog.at_level(logging.WARNING, logger="tiledsimplify"):
        run(folder, tmp_path / "same.laz", ratio=0.5, progress=False)
    assert "another grid" not in caplog.text
    fine = laspy.read(lidar_file(AUTZEN))
    header = laspy.LasHeader(point_format=fine.header.point_format, version=fine.header.version)
    header.scales, header.offsets = np.array([0.001] * 3), np.array([636000.0, 849000.0, 0.0])
    header.vlrs.extend(fine.header.vlrs)  # the same CRS
    c = laspy.LasData(header)
    c.points = laspy.ScaleAwarePointRecord.zeros(1500, header=header)
    for name in fine.point_format.dimension_names:
        if name not in ("X", "Y", "Z"):
            c[name] = fine[name][3000:4500]
    c.x, c.y, c.z = (getattr(fine, a)[3000:4500] + 0.003 for a in "xyz")
    c.write(folder / "c.las")
    with caplog.at_level(logging.WARNING, logger="tiledsimplify"):
        run(folder, tmp_path / "moved.laz", ratio=0.5, progress=False)
    assert re.search(r"moved\.laz: 1 input file\(s\) are on another grid than the first "
                     r"file's \(a\.las: scales \[0\.01, 0\.01, 0\.01\].*move by up to half a "
                     r"step on each axis \(c\.las: scales \[0\.001, 0\.001, 0\.001\]",
                     caplog.text)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="tiledsimplify"):
        run(folder, tmp_path / "moved.npy", ratio=0.5, progress=False)  # coordinates as read
    assert "another grid" not in caplog.text


def test_run_refuses_to_write_over_its_input(tmp_path, monkeypatch):
    """The output named as the input — the same path, or another spelling of it (``..``, a
    linked directory) — is refused before the work, and the input is left as it was (it used
    to be replaced by the output at the end of the run). The in-memory command refuses it
    too. A link to the input is another name: writing it replaces the link, not the input."""
    from tiledsimplify.cli import main
    from tiledsimplify.pipeline import run
    src = small_las(tmp_path / "a.las", AUTZEN, slice(0, 2000))
    before = (tmp_path / "a.las").read_bytes()
    (tmp_path / "sub").mkdir()
    (tmp_path / "dirlink").symlink_to(tmp_path, target_is_directory=True)
    (tmp_path / "link.las").symlink_to(tmp_path / "a.las")
    monkeypatch.chdir(tmp_path)
    for out in (tmp_path / "a.las", "./a.las", tmp_path / "sub" / ".." / "a.las",
                tmp_path / "dirlink" / "a.las"):
        with pytest.raises(InputError, match=r"a\.las: is the input file .*a\.las; the output "
                                             r"would replace it"):
            run(tmp_path / "a.las" if out != "./a.las" else "a.las", out, ratio=0.5)
    assert (tmp_path / "a.las").read_bytes() == before
    run(tmp_path / "a.las", tmp_path / "link.las", ratio=0.5)
    assert (tmp_path / "a.las").read_bytes() == before
    assert not (tmp_path / "link.las").is_symlink()
    assert laspy.read(tmp_path / "link.las").header.point_count == 1000
    np.save(tmp_path / "p.npy", src)
    assert main(["simplify", "p.npy", "p.npy", "--ratio", "0.5", "-q"]) == 2
    np.testing.assert_array_equal(np.load(tmp_path / "p.npy"), src)


def test_lists_path_and_the_warning_for_an_output_among_the_inputs(tmp_path, caplog):
    """An output written into the folder (or under the pattern) the input names would be read
    as one more input file by a later run on the same input: ``lists_path`` says so before it
    exists, and a run warns."""
    from tiledsimplify.io.las import lists_path
    from tiledsimplify.pipeline import run
    folder = tmp_path / "tiles"
    folder.mkdir()
    small_las(folder / "a.las", AUTZEN, slice(0, 2000))
    assert lists_path(folder, folder / "out.laz") and lists_path(str(folder), folder / "o.LAS")
    assert lists_path(str(folder / "*.la?"), folder / "out.laz")
    assert lists_path(str(tmp_path / "**" / "*.laz"), folder / "deep" / "out.laz")
    assert lists_path([folder / "a.las", folder], folder / "out.laz")
    assert not lists_path(folder, folder / "out.npy")          # not a LAS file
    assert not lists_path(folder, tmp_path / "out.laz")        # beside the folder
    assert not lists_path(folder / "a.las", folder / "out.laz")  # one file named
    assert not lists_path(str(folder / "*.las"), folder / "out.laz")
    with caplog.at_level("WARNING", logger="tiledsimplify"):
        run(folder / "a.las", folder / "out.laz", ratio=0.5)
        assert "read it as one more input file" not in caplog.text
        (folder / "out.laz").unlink()
        run(folder, tmp_path / "out.laz", ratio=0.5)
        assert "read it as one more input file" not in caplog.text
        run(folder, folder / "out.laz", ratio=0.5)
    assert "out.laz: the output goes where the input" in caplog.text
    assert laspy.read(folder / "out.laz").header.point_count == 1000


# --------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------

def new_dims(n: int, start: int):
    rank = np.arange(start, start + n, dtype=np.int64)
    rank[::5] = -1
    importance = np.sin(rank.astype(np.float64))
    importance[rank < 0] = np.nan
    return {"sharp_edge": (rank % 3 == 0).astype(np.uint8), "importance": importance,
            "simplify_rank": rank}


@pytest.mark.parametrize("suffix", [".laz", ".las"])
@pytest.mark.parametrize("name", [AUTZEN, LONE_STAR, EXTRA])
def test_round_trip(tmp_path, name, suffix):
    src, xyz, attrs = whole(name)
    sel = np.arange(0, len(xyz), 7)
    sub_xyz = xyz[sel]
    sub = {k: v[sel] for k, v in attrs.items()}
    extra = new_dims(len(sel), 0)
    out_path = tmp_path / f"out{suffix}"
    cuts = [0, len(sel) // 3, len(sel) // 3 * 2 + 17, len(sel)]
    with LasOutput(out_path, src.template_header()) as out:
        for lo, hi in zip(cuts[:-1], cuts[1:]):
            out.write(sub_xyz[lo:hi], {k: v[lo:hi] for k, v in sub.items()},
                      {k: v[lo:hi] for k, v in extra.items()})
    assert out.count == len(sel)
    assert sorted(p.name for p in tmp_path.iterdir()) == [out_path.name]

    back = laspy.read(out_path)
    src_header = src.infos[0].header
    h = back.header
    assert h.are_points_compressed == (suffix == ".laz")
    assert h.point_format.id == src.point_format_id and str(h.version) == src.version
    np.testing.assert_array_equal(h.scales, src.scales)
    np.testing.assert_array_equal(h.offsets, src.offsets)
    assert vlr_payloads(h.vlrs) == vlr_payloads(src_header.vlrs)
    assert len(h.vlrs.get("ExtraBytesVlr")) == 1
    assert LasSource(out_path).crs == src.crs
    assert h.point_count == len(sel)
    np.testing.assert_allclose(h.mins, sub_xyz.min(axis=0))
    np.testing.assert_allclose(h.maxs, sub_xyz.max(axis=0))

    np.testing.assert_array_equal(np.c_[back.x, back.y, back.z], sub_xyz)
    for dim in src.attribute_names:  # every standard and extra-bytes dimension of the input
        np.testing.assert_array_equal(np.array(back[dim]), sub[dim], err_msg=dim)
    assert list(back.point_format.extra_dimension_names) == \
        list(src.extra_dimension_names) + [d[0] for d in SIMPLIFY_DIMS]
    for dim, values in extra.items():
        got = np.array(back[dim])
        assert got.dtype == values.dtype, dim
        np.testing.assert_array_equal(got, values, err_msg=dim)
    for struct in h.vlrs.get("ExtraBytesVlr")[0].extra_bytes_structs:
        if struct.format_name() == "importance":
            assert struct.description.rstrip(b"\0") == b"Importance at removal; NaN=kept"
            assert struct.min[0] == np.nanmin(extra["importance"])
            assert struct.max[0] == np.nanmax(extra["importance"])
        if struct.format_name() == "simplify_rank":
            assert (struct.min[0], struct.max[0]) == (-1, extra["simplify_rank"].max())

    # and our own reader agrees, the new dimensions included
    again_xyz, again = LasSource(out_path, chunk_points=5000).read_all()
    np.testing.assert_array_equal(again_xyz, sub_xyz)
    np.testing.assert_array_equal(again["simplify_rank"], extra["simplify_rank"])


@pytest.mark.parametrize("suffix", [".laz", ".las"])
@pytest.mark.parametrize("name", [AUTZEN, EXTRA])
def test_pieces_packed_elsewhere_write_what_laspy_writes(tmp_path, name, suffix):
    """Pieces packed by a pickled copy of the layout (as a cluster worker would) make the
    file LasOutput.write makes, and its header holds what laspy's own writer (which grows the
    header from the points: bounds, points by return) gives the same records."""
    src, xyz, attrs = whole(name)
    sel = np.arange(3, len(xyz), 11)
    sub_xyz, sub = xyz[sel], {k: v[sel] for k, v in attrs.items()}
    extra = new_dims(len(sel), 0)
    cuts = [0, 1, len(sel) // 2, len(sel)]
    parts = [(sub_xyz[lo:hi], {k: v[lo:hi] for k, v in sub.items()},
              {k: v[lo:hi] for k, v in extra.items()}) for lo, hi in itertools.pairwise(cuts)]
    with LasOutput(tmp_path / f"whole{suffix}", src.template_header()) as out:
        for part in parts:
            out.write(*part)
    with LasOutput(tmp_path / f"pieces{suffix}", src.template_header()) as out:
        remote = pickle.loads(pickle.dumps(out.layout))
        for part in parts:
            out.write_piece(pickle.loads(pickle.dumps(remote.pack(*part))))
        out.write_piece(remote.pack(np.empty((0, 3)), {k: v[:0] for k, v in sub.items()},
                                    {k: v[:0] for k, v in extra.items()}))
    assert (tmp_path / f"pieces{suffix}").read_bytes() == (tmp_path / f"whole{suffix}").read_bytes()

    back = laspy.read(tmp_path / f"pieces{suffix}")
    ref = laspy.LasHeader(point_format=back.header.point_format, version=back.header.version)
    ref.scales, ref.offsets = back.header.scales, back.header.offsets
    ref.partial_reset()
    ref.grow(back.points)
    h = back.header
    assert h.point_count == ref.point_count == len(sel)
    np.testing.assert_array_equal(h.mins, ref.mins)
    np.testing.assert_array_equal(h.maxs, ref.maxs)
    assert list(h.number_of_points_by_return) == list(ref.number_of_points_by_return)
    assert sum(h.number_of_points_by_return) == len(sel)


def test_chunks_compressed_piece_by_piece_make_the_file_laspy_makes(tmp_path):
    """LAZ compressed away from the file (a cluster's workers): pieces of any size — empty,
    inside one chunk, spanning several, ending on a boundary — cut at the file's chunk
    boundaries, their whole chunks compressed, the chunks that straddle pieces compressed
    from a tail and the next heads (``straddles``): the file ``write`` makes, and the one
    laspy's own writer makes of the same points."""

    from tiledsimplify.io.las_pieces import straddles
    src, xyz, attrs = whole(LONE_STAR)
    counts = [0, 61_409, 30_000, 5_000, 0, 3_591, 50_000, 1, 49_999, 120_000, 7, 0, 9_000]
    cuts = np.concatenate([[0], np.cumsum(counts)])
    extra = new_dims(int(cuts[-1]), 0)
    parts = [(xyz[lo:hi], {k: v[lo:hi] for k, v in attrs.items()},
              {k: v[lo:hi] for k, v in extra.items()}) for lo, hi in itertools.pairwise(cuts)]
    with LasOutput(tmp_path / "whole.laz", src.template_header()) as out:
        for part in parts:
            out.write(*part)
    with LasOutput(tmp_path / "chunks.laz", src.template_header()) as out:
        layout = pickle.loads(pickle.dumps(out.layout))
        chunk = layout.vlr().chunk_size()
        starts, span = straddles(counts, chunk)
        # boundaries at 50k (piece 1), 100k and 150k (the first points of pieces 6 and 7),
        # 200k (piece 9's first), 250k and 300k (inside 9)
        assert {t: list(r) for t, r in span.items()} == {
            1: [2, 3, 4, 5, 6], 6: [7], 7: [8, 9], 9: [10, 11, 12]}
        pieces = [layout.chunked(layout.pack(*part), int(starts[t]))
                  for t, part in enumerate(parts)]
        for t, piece in enumerate(pieces):
            out.write_chunks(piece.data, piece.chunks)
            out.grow(piece)
            if t in span:
                out.write_chunks(*layout.compress([piece.tail]
                                                  + [pieces[u].head for u in span[t]]))
    data = (tmp_path / "chunks.laz").read_bytes()
    assert data == (tmp_path / "whole.laz").read_bytes()
    back = laspy.read(tmp_path / "chunks.laz")
    assert len(back.points) == cuts[-1]
    np.testing.assert_array_equal(np.c_[back.x, back.y, back.z], xyz[:cuts[-1]])
    with laspy.open(tmp_path / "chunks.laz") as reader:  # seeks by its chunk table
        reader.seek(150_003)
        np.testing.assert_array_equal(np.asarray(reader.read_points(4).X),
                                      np.asarray(back.X[150_003:150_007]))
    header = laspy.open(tmp_path / "chunks.laz").header
    plain = laspy.LasData(header)
    plain.points = back.points
    plain.write(tmp_path / "laspy.laz")  # laspy's own writer, the same points
    theirs = (tmp_path / "laspy.laz").read_bytes()
    other = laspy.open(tmp_path / "laspy.laz").header.offset_to_point_data
    # the chunks and the chunk table, byte for byte (the 8 bytes before them locate the
    # table, whose offset follows the header's length)
    assert data[header.offset_to_point_data + 8:] == theirs[other + 8:]


def test_a_piece_of_another_layout_and_ranges_without_values(tmp_path):
    src, xyz, attrs = whole(AUTZEN)
    other, oxyz, oattrs = whole(EXTRA)
    foreign = LasOutput(tmp_path / "b.laz", other.template_header())
    piece = foreign.layout.pack(oxyz[:10], {k: v[:10] for k, v in oattrs.items()},
                                new_dims(10, 0))
    foreign.abort()
    with (pytest.raises(ValueError, match="another layout"),
          LasOutput(tmp_path / "a.laz", src.template_header()) as out):
        out.write_piece(piece)
    assert not list(tmp_path.iterdir())
    # an added dimension with no valid value (every importance NaN) claims no min/max and
    # stores zeros there
    extra = new_dims(50, 0)
    extra["importance"][:] = np.nan
    write_las(tmp_path / "c.laz", src.template_header(), xyz[:50],
              {k: v[:50] for k, v in attrs.items()}, extra=extra)
    for struct in laspy.open(tmp_path / "c.laz").header.vlrs.get(
            "ExtraBytesVlr")[0].extra_bytes_structs:
        if struct.format_name() == "importance":
            assert struct.options & (struct.MIN_BIT_MASK | struct.MAX_BIT_MASK) == 0
            assert not any(bytes(struct._min)) and not any(bytes(struct._max))


def test_evlrs_and_reused_dims_are_kept(tmp_path):
    src, xyz, attrs = whole(EXTRA)
    header = src.template_header()
    header.evlrs = VLRList([laspy.VLR("tiledsimplify", 7, "test evlr", b"x" * 1000)])
    n = 2000
    extra = new_dims(n, 0)
    first = write_las(tmp_path / "a.laz", header, xyz[:n], {k: v[:n] for k, v in attrs.items()},
                      extra=extra)
    back = laspy.read(first)
    assert [(v.user_id, v.record_id, v.record_data) for v in back.evlrs] == \
        [("tiledsimplify", 7, b"x" * 1000)]

    # simplifying our own output again: the three dimensions already exist and are reused
    again = LasSource(first)
    xyz2, attrs2 = again.read_all()
    extra2 = new_dims(n, 100)
    with LasOutput(tmp_path / "b.las", again.template_header()) as out:
        out.write(xyz2, attrs2, extra2)
    back2 = laspy.read(tmp_path / "b.las")
    assert list(back2.point_format.extra_dimension_names).count("importance") == 1
    np.testing.assert_array_equal(np.array(back2["simplify_rank"]), extra2["simplify_rank"])
    assert len(back2.evlrs) == 1


def test_failed_write_leaves_nothing(tmp_path):
    src, xyz, attrs = whole(AUTZEN)
    n = 1000
    part = {k: v[:n] for k, v in attrs.items()}
    for suffix in (".laz", ".las"):
        target = tmp_path / f"out{suffix}"
        with pytest.raises(RuntimeError, match="boom"):
            with LasOutput(target, src.template_header()) as out:
                out.write(xyz[:n], part, new_dims(n, 0))
                assert len(list(tmp_path.iterdir())) == 1  # the temporary file
                raise RuntimeError("boom")
        assert list(tmp_path.iterdir()) == []

    # a bad chunk (a missing dimension) fails the same way
    with pytest.raises(InputError, match="importance"):
        with LasOutput(tmp_path / "out.laz", src.template_header()) as out:
            out.write(xyz[:n], part, {"sharp_edge": np.zeros(n, np.uint8),
                                      "simplify_rank": np.zeros(n, np.int64)})
    assert list(tmp_path.iterdir()) == []

    # an existing output is replaced only by a successful write
    existing = tmp_path / "keep.las"
    existing.write_bytes(b"previous")
    with pytest.raises(RuntimeError):
        with LasOutput(existing, src.template_header()) as out:
            out.write(xyz[:n], part, new_dims(n, 0))
            raise RuntimeError("boom")
    assert existing.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.las"]


def test_write_rejects_bad_chunks(tmp_path):
    src, xyz, attrs = whole(AUTZEN)
    n = 10
    part = {k: v[:n] for k, v in attrs.items()}
    with LasOutput(tmp_path / "o.las", src.template_header()) as out:
        with pytest.raises(InputError, match="unknown"):
            out.write(xyz[:n], {**part, "colour": np.zeros(n)}, new_dims(n, 0))
        with pytest.raises(InputError, match="integers"):
            out.write(xyz[:n], {**part, "intensity": np.zeros(n)}, new_dims(n, 0))
        with pytest.raises(InputError, match="cannot hold"):
            out.write(xyz[:n], {**part, "user_data": np.full(n, 300)}, new_dims(n, 0))
        with pytest.raises(InputError, match="NaN"):
            out.write(np.full((n, 3), np.nan), part, new_dims(n, 0))
        with pytest.raises(InputError, match="int32"):
            out.write(xyz[:n] + 1e9, part, new_dims(n, 0))
        with pytest.raises(InputError, match="values for"):
            out.write(xyz[:n], {**part, "gps_time": np.zeros(n + 1)}, new_dims(n, 0))
        out.write(xyz[:n], part, new_dims(n, 0))
    assert laspy.read(tmp_path / "o.las").header.point_count == n


# --------------------------------------------------------------------------------------
# bad inputs
# --------------------------------------------------------------------------------------

def test_missing_and_unsupported_inputs(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere.laz"):
        LasSource(tmp_path / "nowhere.laz")
    with pytest.raises(FileNotFoundError, match="no .las/.laz files in folder"):
        las_files(tmp_path)
    (tmp_path / "cloud.xyz").write_text("0 0 0\n")
    with pytest.raises(FileNotFoundError, match=r"\*\.laz"):
        las_files(str(tmp_path / "*.laz"))
    with pytest.raises(FileNotFoundError, match="none is a .las/.laz"):
        las_files(str(tmp_path / "*"))
    with pytest.raises(FileFormatError, match=r"cloud\.xyz.*unsupported suffix"):
        las_files(tmp_path / "cloud.xyz")
    src = LasSource(lidar_file(AUTZEN))
    with pytest.raises(FileFormatError, match=r"out\.ply"):
        LasOutput(tmp_path / "out.ply", src.template_header())
    with pytest.raises(FileNotFoundError, match="missing_dir"):
        LasOutput(tmp_path / "missing_dir" / "out.laz", src.template_header())


def test_corrupt_and_truncated_files(tmp_path):
    raw = lidar_file(AUTZEN).read_bytes()

    junk = tmp_path / "junk.las"
    junk.write_bytes(b"this is not a LAS file" * 20)
    with pytest.raises(FileFormatError, match=r"junk\.las.*signature"):
        LasSource(junk)

    empty = tmp_path / "empty.laz"
    empty.write_bytes(b"")
    with pytest.raises(FileFormatError, match=r"empty\.laz"):
        LasSource(empty)

    cut_laz = tmp_path / "cut.laz"
    cut_laz.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(FileFormatError, match=r"cut\.laz.*truncated or corrupt"):
        LasSource(cut_laz)

    head_only = tmp_path / "head.laz"
    head_only.write_bytes(raw[:150])
    with pytest.raises(FileFormatError, match=r"head\.laz"):
        LasSource(head_only)

    las = tmp_path / "small.las"
    small_las(las, AUTZEN, slice(0, 5000))
    full = las.read_bytes()
    cut_las = tmp_path / "cut.las"
    cut_las.write_bytes(full[: len(full) - 1234])
    with pytest.raises(FileFormatError, match=r"cut\.las: truncated LAS file.*5000 points"):
        LasSource(cut_las)

    # a file cut after it was opened: found while reading, with the file named
    src = LasSource(las, chunk_points=1000)
    las.write_bytes(full[: len(full) - 34 * 2500])
    with pytest.raises(FileFormatError, match=r"small\.las: truncated.*5000 points.*2500"):
        for _ in src.chunks():
            pass


def test_points_far_outside_the_header_box_are_refused(tmp_path):
    """A LAZ file damaged in its middle (a block of zeros: bit rot, a partial copy) decodes
    without an error to points far from the cloud; they used to be simplified into the output
    (exit 0). Points far outside the header's bounding box are refused, naming the file;
    a stale header (points a little outside) and an unset one (all zero) still read."""
    raw = bytearray(lidar_file(AUTZEN).read_bytes())
    middle = len(raw) // 2
    raw[middle:middle + 5000] = bytes(5000)
    bad = tmp_path / "damaged.laz"
    bad.write_bytes(bytes(raw))
    src = LasSource(bad)  # the headers and chunk table are fine
    with pytest.raises(FileFormatError, match=r"damaged\.laz: .* of its points .* lie far "
                                              r"outside the bounding box its header gives"):
        src.read_all()

    las = tmp_path / "small.las"
    xyz = small_las(las, AUTZEN, slice(0, 5000))
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)

    def with_header_box(path, mins, maxs):
        data = bytearray(las.read_bytes())
        for axis in range(3):  # max x, min x, max y, min y, max z, min z from byte 179
            data[179 + 16 * axis:187 + 16 * axis] = np.float64(maxs[axis]).tobytes()
            data[187 + 16 * axis:195 + 16 * axis] = np.float64(mins[axis]).tobytes()
        path.write_bytes(bytes(data))
        return path

    stale = with_header_box(tmp_path / "stale.las", lo + 0.3 * (hi - lo), hi)
    np.testing.assert_array_equal(LasSource(stale).read_all()[0], xyz)
    unset = with_header_box(tmp_path / "unset.las", np.zeros(3), np.zeros(3))
    np.testing.assert_array_equal(LasSource(unset).read_all()[0], xyz)
    far = with_header_box(tmp_path / "far.las", lo + 1e4, hi + 1e4)
    with pytest.raises(FileFormatError, match=r"far\.las: 5,000 of its points 0 to 4,999"):
        LasSource(far).read_all()


def test_folder_reads_every_laz(tmp_path):
    # several real files in a folder (symlinks keep it cheap): one cloud, consecutive indices
    for name in (AUTZEN, LONE_STAR):
        try:
            (tmp_path / name).symlink_to(lidar_file(name))
        except OSError:
            shutil.copy(lidar_file(name), tmp_path / name)
    with pytest.warns(UserWarning, match="different CRS"):
        src = LasSource(str(tmp_path / "*.laz"), chunk_points=200_000)
    assert [p.name for p in src.files] == sorted([AUTZEN, LONE_STAR])
    assert src.count == COUNTS[AUTZEN] + COUNTS[LONE_STAR]
    ends = [(s, len(x)) for s, x, _ in src.chunks()]
    assert ends[0] == (0, COUNTS[AUTZEN])
    assert ends[1][0] == COUNTS[AUTZEN]
    assert ends[-1][0] + ends[-1][1] == src.count


def test_a_non_las_inputs_dimensions_find_a_place_in_a_las_output():
    """:func:`carried_layout`: every numeric dimension of a non-LAS input has a place in a LAS
    output — the standard dimension of its name (in PDAL's or CloudCompare's spelling too)
    where its values fit it: integers within its range, a float column of whole numbers
    within it, any number into a float dimension — else extra bytes of its own type under its
    own name, or with its type added where that name is taken in any case; LAS's types for
    bool and float16; one per element of a trailing shape; names cut to LAS's 32 bytes and
    kept apart; the simplifier's own left out."""
    from tiledsimplify.io.las_output import carried_layout
    attrs = {"intensity": ("f4", ()), "classification": ("u1", ()), "red": ("u2", ()),
             "gps_time": ("f8", ()), "user_data": ("f8", ()), "Intensity": ("i4", ()),
             "confidence": ("f4", ()), "flag": ("?", ()), "half": ("f2", ()),
             "normal_guess": ("f8", (3,)), "sharp_edge": ("u1", ()), "label": ("U4", ()),
             "a" * 40: ("i2", ()), "a" * 35: ("u4", ())}
    # no stats: integers go into the standard dimension of their name, floats do not
    params, plan = carried_layout(attrs, laspy.PointFormat(7), reserved={"sharp_edge"})
    types = {p.name: np.dtype(p.type) for p in params}
    assert types == {
        "intensity_float32": np.float32, "user_data_float64": np.float64,
        "confidence": np.float32, "flag": np.uint8,
        "half": np.float32, "normal_guess_0": np.float64, "normal_guess_1": np.float64,
        "normal_guess_2": np.float64, "a" * 32: np.int16, "a" * 30 + "_1": np.uint32}
    assert plan == {
        "intensity_float32": ("intensity", None), "classification": ("classification", None),
        "red": ("red", None), "gps_time": ("gps_time", None),
        "user_data_float64": ("user_data", None), "intensity": ("Intensity", None),
        "confidence": ("confidence", None), "flag": ("flag", None), "half": ("half", None),
        "normal_guess_0": ("normal_guess", 0), "normal_guess_1": ("normal_guess", 1),
        "normal_guess_2": ("normal_guess", 2), "a" * 32: ("a" * 40, None),
        "a" * 30 + "_1": ("a" * 35, None)}
    header = laspy.LasHeader(point_format=7, version="1.4")
    header.add_extra_dims(params)  # LAS takes them all
    assert set(plan) <= set(header.point_format.dimension_names)
    # by the input's stats: values that do not fit the standard dimension keep their own type
    dims = {"classification": ("i4", ()), "return_number": ("i8", ()),
            "point_source_id": ("u4", ()), "user_data": ("u1", ()),
            "Intensity": ("f8", ()), "NumberOfReturns": ("f8", ()), "Scan Angle": ("f8", ()),
            "GpsTime": ("f8", ()), "Withheld": ("f8", ()), "Overlap": ("f8", ())}
    params, plan = carried_layout(dims, laspy.PointFormat(6), stats={
        "classification": (-1, 40, True), "return_number": (1, 3, True),
        "point_source_id": (0, 70_000, True), "Intensity": (0.0, 999.0, True),
        "NumberOfReturns": (1.0, 3.0, True), "Scan Angle": (-90.0, 90.0, True),
        "GpsTime": (0.5, 1e6, False), "Withheld": (0.0, 1.5, False),
        "Overlap": (None, None, False)})
    assert {p.name: np.dtype(p.type) for p in params} == {
        "classification_int32": np.int32, "point_source_id_uint32": np.uint32,
        "Withheld_float64": np.float64, "Overlap_float64": np.float64}
    assert plan == {"classification_int32": ("classification", None),
                    "return_number": ("return_number", None),
                    "point_source_id_uint32": ("point_source_id", None),
                    "user_data": ("user_data", None),  # no stats: as it is
                    "intensity": ("Intensity", None),
                    "number_of_returns": ("NumberOfReturns", None),
                    "scan_angle": ("Scan Angle", None), "gps_time": ("GpsTime", None),
                    "Withheld_float64": ("Withheld", None),
                    "Overlap_float64": ("Overlap", None)}


def test_a_layout_las_cannot_describe_is_refused_before_the_work(tmp_path):
    """:func:`output_header` (what a run checks before the work): a template of 340
    extra-bytes dimensions plus the simplifier's 3 is more than the 341 a LAS file's Extra
    Bytes VLR describes; laspy took the header and failed only when the file was written."""
    from tiledsimplify.io.las_output import EXTRA_BYTES_MAX, output_header
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.add_extra_dims([laspy.ExtraBytesParams(name=f"f{i}", type=np.uint8)
                           for i in range(EXTRA_BYTES_MAX - 1)])
    with pytest.raises(InputError, match=r"big\.laz: a LAS file describes at most 341 "
                                         r"extra-bytes dimensions.*would need 343"):
        output_header(header, path=tmp_path / "big.laz")
    fewer = laspy.LasHeader(point_format=6, version="1.4")
    fewer.add_extra_dims([laspy.ExtraBytesParams(name=f"f{i}", type=np.uint8)
                          for i in range(EXTRA_BYTES_MAX - 3)])
    out, _ = output_header(fewer)  # 341 described: written and read back
    write_las(tmp_path / "ok.las", out, np.zeros((2, 3)),
              {n: np.zeros(2, np.uint8) for n in out.point_format.dimension_names
               if n not in ("X", "Y", "Z")}, extra_dims=())
    assert len(list(laspy.read(tmp_path / "ok.las").point_format.extra_dimension_names)) == 341
