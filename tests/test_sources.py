"""Chunked input readers equal whole reads (PLY binary/ASCII, XYZ, CSV, NPY)."""


import numpy as np
import pytest

from tiledsimplify.errors import FileFormatError, InputError
from tiledsimplify.io import read_points
from tiledsimplify.io.points_out import write_points
from tiledsimplify.io.sources import ArraySource, ColumnsSource, TextSource, open_source


def _chunked(path, chunk):
    src = open_source(path, chunk_points=chunk)
    parts = list(src.chunks())
    starts = [s for s, _, _ in parts]
    xyz = np.concatenate([x for _, x, _ in parts])
    assert starts == list(range(0, src.count, chunk))
    assert len(xyz) == src.count
    return src, xyz


@pytest.fixture()
def cloud():
    return np.random.default_rng(0).random((1003, 3)) * [100.0, 50.0, 10.0] - 20.0


@pytest.mark.parametrize("suffix,kind", [(".ply", ColumnsSource), (".xyz", TextSource),
                                         (".csv", TextSource), (".npy", ArraySource)])
def test_chunked_equals_whole(tmp_path, cloud, suffix, kind):
    path = tmp_path / f"c{suffix}"
    write_points(path, cloud, {"importance": np.arange(len(cloud), dtype=float)})
    src, xyz = _chunked(path, 100)
    assert isinstance(src, kind)
    np.testing.assert_array_equal(xyz, read_points(path))
    np.testing.assert_allclose(xyz, cloud, rtol=1e-15)


def test_files_cut_in_parts_read_as_the_whole(tmp_path, cloud):
    import pickle
    np.save(tmp_path / "a.npy", cloud)
    write_points(tmp_path / "b.ply", cloud, {"importance": np.arange(len(cloud), dtype=float)})
    write_points(tmp_path / "c.xyz", cloud)  # a header line, then a line a point
    write_points(tmp_path / "d.csv", cloud)
    (tmp_path / "e.txt").write_bytes(b"".join(b"%.17g %.17g %.17g\r\n" % tuple(p) for p in cloud))
    for name in ("a.npy", "b.ply", "c.xyz", "d.csv", "e.txt"):
        src = open_source(tmp_path / name, chunk_points=100)
        whole = list(src.chunks())
        parts = src.parts(250)  # two chunks a part
        assert [(p.lo, p.hi) for p in parts] == [(0, 200), (200, 400), (400, 600), (600, 800),
                                                 (800, 1000), (1000, 1003)]
        got = [c for p in parts for c in pickle.loads(pickle.dumps(p))()]  # as a worker reads
        assert [g[0] for g in got] == [w[0] for w in whole]
        for (_, x1, _), (_, x2, _) in zip(whole, got):
            np.testing.assert_array_equal(x1, x2)
        assert len(pickle.dumps(parts[0])) < 2000  # the file's layout, not its points
    np.save(tmp_path / "f.npy", np.asfortranarray(cloud))  # not mapped as rows: read here
    assert open_source(tmp_path / "f.npy").parts(250) is None
    write_points(tmp_path / "c.npy", cloud, {})  # our structured output: read whole
    assert open_source(tmp_path / "c.npy").parts(250) is None


def test_ascii_ply_and_plain_xyz(tmp_path, cloud, data_dir):
    lines = ["ply", "format ascii 1.0", f"element vertex {len(cloud)}", "property float x",
             "property float y", "property float z", "property uchar red", "element face 0",
             "property list uchar int vertex_indices", "end_header"]
    body = [f"{x:.6f} {y:.6f} {z:.6f} 7" for x, y, z in cloud]
    path = tmp_path / "a.ply"
    path.write_text("\n".join(lines + body) + "\n")
    src, xyz = _chunked(path, 333)
    assert isinstance(src, TextSource)
    np.testing.assert_array_equal(xyz, read_points(path))
    got = np.concatenate([c[1] for p in src.parts(700) for c in p()])  # 2 chunks a part
    np.testing.assert_array_equal(got, xyz)  # from inside the vertex block, header skipped
    plain = tmp_path / "p.xyz"
    np.savetxt(plain, cloud)  # no header, no trailing delimiter
    _, xyz = _chunked(plain, 1000)
    np.testing.assert_array_equal(xyz, cloud)
    # a real raw scan (gzipped: read whole, still chunked)
    raw = data_dir / "scans" / "stanford_bunny_range" / "bun000.ply.gz"
    _, xyz = _chunked(raw, 10000)
    assert len(xyz) == 40256


def test_truncated_inputs_fail_naming_the_file(tmp_path, cloud):
    path = tmp_path / "t.ply"
    write_points(path, cloud)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 100])
    with pytest.raises(FileFormatError, match="t.ply.*truncated"):
        open_source(path)
    bad = tmp_path / "b.xyz"
    bad.write_text("x y z\n1 2 3\n4 five 6\n")
    with pytest.raises(FileFormatError, match="b.xyz"):
        list(open_source(bad).chunks())


def test_a_bad_text_line_is_named_by_its_line_in_the_file(tmp_path):
    """In the second chunk, past a header: the file's line number, the point and the text."""
    bad = tmp_path / "b.xyz"
    rows = [f"{i} {i} {i}" for i in range(10)]
    rows[7] = "7 seven 7"
    bad.write_text("x y z\n" + "\n".join(rows) + "\n")
    with pytest.raises(FileFormatError) as err:
        list(open_source(bad, chunk_points=4).chunks())
    assert "line 9 (point 7): '7 seven 7' (could not convert string 'seven'" in str(err.value)
    bad.write_text("1 2 3\n4 5\n")
    with pytest.raises(FileFormatError, match=r"line 2 \(point 1\): '4 5'"):
        list(open_source(bad, chunk_points=4).chunks())


def test_broken_npy_files_fail_naming_the_file(tmp_path, cloud):
    """An empty .npy raised numpy's EOFError (exit 1 and a traceback); a truncated one, text
    renamed .npy, an object array or a structured array without x, y, z gave numpy's words
    without the file's name ("mmap length is greater than file size", "no field of name x")."""
    np.save(tmp_path / "ok.npy", cloud)
    data = (tmp_path / "ok.npy").read_bytes()
    cases = {"empty.npy": (b"", "not a NumPy .npy file \\(an empty file\\)"),
             "text.npy": (b"1 2 3\n4 5 6\n", ".*does not start with the .npy signature"),
             "cut.npy": (data[:1000], "not a readable .npy file .*truncated")}
    for name, (body, match) in cases.items():
        (tmp_path / name).write_bytes(body)
        with pytest.raises(FileFormatError, match=rf"{name}: {match}.*numpy.save"):
            open_source(tmp_path / name)
    np.save(tmp_path / "obj.npy", np.array([{"a": 1}], dtype=object))
    np.save(tmp_path / "rec.npy", np.zeros(5, dtype=[("a", "f8"), ("b", "f8")]))
    for name in ("obj.npy", "rec.npy"):
        with pytest.raises(FileFormatError, match=rf"{name}: .*numpy.save"):
            open_source(tmp_path / name)
    from tiledsimplify.cli import main
    assert main(["simplify", str(tmp_path / "empty.npy"), str(tmp_path / "o.npy"),
                 "--ratio", "0.5"]) == 2
    assert not (tmp_path / "o.npy").exists()


def test_blank_and_comment_lines_are_not_points(tmp_path, cloud):
    """Blank lines (a file's last ones, most often; CRLF too) and ``#`` comment lines are
    skipped, not counted: the count was that of the lines, the reader skipped them, and a
    ``run`` failed with 'n_total was given as 1005 but the chunks hold 1003 points' (one
    chunk) or misplaced every later chunk. An empty file has no points (its count was -1)."""
    rows = [f"{x!r} {y!r} {z!r}" for x, y, z in cloud.tolist()]
    texts = {"trail.xyz": "\n".join(rows) + "\n\n\n",
             "mid.xyz": "x y z\n" + "\n".join(rows[:500]) + "\n  \n# a comment\n\n"
                        + "\n".join(rows[500:]) + "\n",
             "crlf.txt": "# exported\r\n" + "\r\n".join(rows[:333]) + "\r\n\r\n"
                         + "\r\n".join(rows[333:]),  # no newline at the end
             "c.csv": "x,y,z\n" + "\n".join(r.replace(" ", ",") for r in rows) + "\n\n"}
    for name, text in texts.items():
        path = tmp_path / name
        path.write_bytes(text.encode())
        for chunk in (100, 1003, 10_000):
            src, xyz = _chunked(path, chunk)
            assert src.count == len(cloud), name
            np.testing.assert_array_equal(xyz, cloud)
            got = np.concatenate([c[1] for p in src.parts(2 * chunk) for c in p()])
            np.testing.assert_array_equal(got, cloud)
    bad = tmp_path / "b.xyz"
    bad.write_text("x y z\n1 2 3\n\n# c\n4 five 6\n")
    with pytest.raises(FileFormatError, match=r"line 5 \(point 1\): '4 five 6'"):
        list(open_source(bad, chunk_points=4).chunks())
    for text in ("", "x y z\n", "\n\n"):
        (tmp_path / "e.xyz").write_text(text)
        assert open_source(tmp_path / "e.xyz").count == 0


def test_a_header_after_comment_lines_is_a_header(tmp_path, cloud):
    """The header and the delimiter come from the first line that is neither blank nor a
    ``#`` comment, as in the in-memory reader (``read_points``): only the file's first line
    was looked at, so a header after a comment ('# exported by …' then 'x y z') failed as
    'unreadable point line at line 2', and a comment with a comma made the whitespace-separated
    numbers unreadable."""
    from tiledsimplify.io.columns import read_columns
    rows = [f"{x!r} {y!r} {z!r}" for x, y, z in cloud.tolist()]
    texts = {"h.xyz": "# exported by a scanner\nX Y Z\n" + "\n".join(rows) + "\n",
             "comma.xyz": "# units: mm, frame: part\n" + "\n".join(rows) + "\n",
             "blank.txt": "\n\n# c\n\tx\ty\tz\n" + "\n".join(rows) + "\n",
             "h.csv": "# c\nx,y,z,sharp_edge\n"
                      + "\n".join(r.replace(" ", ",") + ",1" for r in rows) + "\n"}
    for name, text in texts.items():
        path = tmp_path / name
        path.write_text(text)
        for chunk in (100, 10_000):
            src, xyz = _chunked(path, chunk)
            assert src.count == len(cloud), name
            np.testing.assert_array_equal(xyz, cloud)
        np.testing.assert_array_equal(read_points(path), cloud)
    xyz, cols = read_columns(tmp_path / "h.csv")
    np.testing.assert_array_equal(xyz, cloud)
    assert set(cols) == {"sharp_edge"} and (cols["sharp_edge"] == 1).all()


def test_a_run_on_text_with_blank_last_lines_keeps_the_count(tmp_path, cloud):
    from tiledsimplify.pipeline import run
    path = tmp_path / "t.xyz"
    path.write_text("".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in cloud.tolist()) + "\n\n")
    summary = run(path, tmp_path / "o.npy", count=500)
    assert summary.n_input == len(cloud) and len(np.load(tmp_path / "o.npy")) == 500


@pytest.mark.parametrize("suffix", [".ply", ".xyz", ".npy"])
def test_non_finite_points_fail_naming_the_file_and_the_point(tmp_path, cloud, suffix):
    bad = cloud.copy()
    bad[257, 1] = np.nan
    bad[900, 2] = np.inf
    path = tmp_path / f"n{suffix}"
    if suffix == ".npy":
        np.save(path, bad)
    else:
        write_points(path, bad)
    src = open_source(path, chunk_points=100)
    chunks = src.chunks()
    assert next(chunks)[0] == 0 and next(chunks)[0] == 100  # points before the bad one pass
    head = int(not path.read_bytes()[:1].isdigit()) if suffix == ".xyz" else 0  # a header
    where = f"line {257 + head + 1} \\(point 257\\)" if suffix == ".xyz" else "point 257"
    with pytest.raises(InputError, match=rf"n\{suffix}: {where} has a NaN or infinite"):
        next(chunks)  # a text file's error names the line (since 2026-12-04)
    more = r"\(2 such lines in lines" if suffix == ".xyz" else r"\(2 in points 0-999\)"
    with pytest.raises(InputError, match=rf"point 257\)? .*{more}"):
        list(open_source(path, chunk_points=1000).chunks())


def test_coordinates_that_look_like_degrees_are_named():
    """x, y within +-180, +-90 and spanning under a hundredth of the heights' span look like
    longitude and latitude (an airborne tile of 0.003 deg with 60 m of heights); a CAD part in
    metres, a survey in UTM metres, a building in local metres do not."""
    from tiledsimplify.io.sources import degrees_message
    got = degrees_message("t.laz", [-123.070, 44.050, 120.0], [-123.067, 44.0515, 180.0])
    assert got.startswith("t.laz: x and y look like degrees of longitude and latitude (x "
                          "-123.07 .. -123.067, y 44.05 .. 44.0515; z spans 20,000 times more)")
    assert "Reproject to a projected CRS first" in got
    for lo, hi in [([0, 0, 0], [1, 1, 0.3]),                          # a CAD part
                   ([515368, 4918340, 2322], [515401, 4918381, 2338]),  # UTM
                   ([0, 0, 0], [40, 60, 25]),                         # a building
                   ([-123.07, 44.05, 120.0], [-123.07, 44.05, 180.0]),  # no horizontal span
                   ([10.0, 50.0, 0.0], [10.5, 50.5, 40.0])]:           # heights span less
        assert degrees_message("t", lo, hi) is None, (lo, hi)
    assert degrees_message("t", [0, 0, np.nan], [1, 1, 1]) is None


def test_a_run_on_degrees_warns(tmp_path, caplog):
    from tiledsimplify.pipeline import run
    rng = np.random.default_rng(0)
    X = np.c_[-123.07 + 0.003 * rng.random(3000), 44.05 + 0.002 * rng.random(3000),
              100.0 + 60.0 * rng.random(3000)]
    np.save(tmp_path / "deg.npy", X)
    with caplog.at_level("WARNING", logger="tiledsimplify"):
        run(tmp_path / "deg.npy", tmp_path / "o.npy", ratio=0.5)
    assert "deg.npy: x and y look like degrees" in caplog.text
    caplog.clear()
    X[:, :2] = (X[:, :2] - X[:, :2].min(axis=0)) * 111_000  # the same, in metres
    np.save(tmp_path / "m.npy", X)
    with caplog.at_level("WARNING", logger="tiledsimplify"):
        run(tmp_path / "m.npy", tmp_path / "o.npy", ratio=0.5)
    assert "degrees" not in caplog.text


def _coloured_ply(path, X, rgb, fmt, code="uchar"):
    """A PLY of ``X`` with red/green/blue properties of type ``code``, and a normal between
    (the colours' columns are not next to x, y, z)."""
    n = len(X)
    kind = {"uchar": "u1", "ushort": "<u2", "float": "<f4"}[code]
    head = (f"ply\nformat {fmt} 1.0\nelement vertex {n}\nproperty double x\nproperty double y\n"
            f"property double z\nproperty float nx\nproperty {code} red\nproperty {code} green\n"
            f"property {code} blue\nend_header\n").encode()
    if fmt == "ascii":
        body = "".join(f"{x!r} {y!r} {z!r} 0.5 {r} {g} {b}\n" for (x, y, z), (r, g, b)
                       in zip(X.tolist(), rgb.tolist())).encode()
    else:
        rec = np.zeros(n, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("nx", "<f4"),
                                 ("red", kind), ("green", kind), ("blue", kind)])
        rec["x"], rec["y"], rec["z"] = X.T
        rec["red"], rec["green"], rec["blue"] = rgb.T
        body = rec.tobytes()
    path.write_bytes(head + body)


@pytest.mark.parametrize("fmt,code", [("binary_little_endian", "uchar"), ("ascii", "uchar"),
                                      ("binary_little_endian", "ushort"),
                                      ("binary_little_endian", "float")])
def test_ply_colours_are_read_as_las_colour(tmp_path, cloud, fmt, code):
    rng = np.random.default_rng(3)
    if code == "float":
        rgb = rng.random((len(cloud), 3)).astype(np.float32)
        want = np.clip(np.rint(rgb.astype(np.float64) * 65535), 0, 65535)
    else:
        top = 255 if code == "uchar" else 65535
        rgb = rng.integers(0, top + 1, (len(cloud), 3))
        want = rgb * (257 if code == "uchar" else 1)
    path = tmp_path / "c.ply"
    _coloured_ply(path, cloud, rgb, fmt, code)
    src, xyz = _chunked(path, 100)
    np.testing.assert_array_equal(xyz, cloud)
    got = list(src.chunks())
    for j, name in enumerate(("red", "green", "blue")):
        values = np.concatenate([a[name] for _, _, a in got])
        assert values.dtype == np.uint16
        np.testing.assert_array_equal(values, want[:, j])
    # parts read apart (another process) carry them too
    parts = [c for part in src.parts(300) for c in part()]
    for j, name in enumerate(("red", "green", "blue")):
        np.testing.assert_array_equal(np.concatenate([a[name] for _, _, a in parts]),
                                      want[:, j])


def test_a_coloured_ply_keeps_its_colour_in_a_las_output(tmp_path):
    import importlib

    import laspy
    from scipy.spatial import cKDTree
    run = importlib.import_module("tiledsimplify.pipeline.run").run
    rng = np.random.default_rng(4)
    X = rng.random((5000, 3))
    rgb = rng.integers(0, 256, (5000, 3))
    path = tmp_path / "c.ply"
    _coloured_ply(path, X, rgb, "binary_little_endian")
    out = tmp_path / "out.laz"
    run(path, out, ratio=0.25, tile_points=1500)
    las = laspy.read(out)
    assert las.header.point_format.id == 7 and len(las.points) == 1250
    d, i = cKDTree(X).query(np.c_[las.x, las.y, las.z])
    assert d.max() < 1e-4
    for j, name in enumerate(("red", "green", "blue")):
        np.testing.assert_array_equal(np.asarray(las[name]), rgb[i, j] * 257)
    plain = tmp_path / "plain.ply"  # no colour: point format 6, as before
    write_points(plain, X)
    run(plain, tmp_path / "plain.laz", ratio=0.25, tile_points=1500)
    assert laspy.read(tmp_path / "plain.laz").header.point_format.id == 6


def test_semicolon_csv_reads_as_comma_csv(tmp_path, cloud):
    """CSV with semicolons (CloudCompare's export option, spreadsheets in many locales), with
    and without a header, reads as the comma file does (it was a header line, then 'could not
    convert'); decimal commas are named; a NaN is named by its line, not a point index."""
    rows = [";".join(repr(v) for v in p) for p in cloud.tolist()]
    for name, text in {"s.csv": "\n".join(rows) + "\n",
                       "h.csv": "x;y;z\n" + "\n".join(rows) + "\n"}.items():
        (tmp_path / name).write_text(text)
        for chunk in (100, 10_000):
            src, xyz = _chunked(tmp_path / name, chunk)
            assert src.count == len(cloud)
            np.testing.assert_array_equal(xyz, cloud)
    (tmp_path / "d.csv").write_text("x;y;z\n1,5;2,5;3,5\n")
    with pytest.raises(FileFormatError, match=r"line 2 \(point 0\).*decimal commas are not read"):
        list(open_source(tmp_path / "d.csv").chunks())
    (tmp_path / "n.xyz").write_text("x y z\n1 2 3\n\n4 nan 6\n7 8 inf\n")
    with pytest.raises(InputError, match=r"n.xyz: line 4 \(point 1\) has a NaN or infinite "
                                         r"coordinate: '4 nan 6' \(2 such lines"):
        list(open_source(tmp_path / "n.xyz", chunk_points=10).chunks())


def test_a_list_of_non_las_files_says_to_give_one_or_merge(tmp_path, cloud):
    """A list of two PLY files was refused with 'Convert other formats first (e.g. `pdal
    translate in.e57 out.laz`)': E57 is read natively, and one PLY is too — the fix is one
    file or a merge."""
    paths = []
    for name in ("a.ply", "b.ply"):
        write_points(tmp_path / name, cloud)
        paths.append(str(tmp_path / name))
    with pytest.raises(FileFormatError, match=r"a\.ply: unsupported suffix '\.ply' among LAS "
                       r"input.*Give one file of another format.*pdal merge") as err:
        open_source(paths)
    assert "in.e57" not in str(err.value)


def _text_cloud(n=3000, seed=1):
    rng = np.random.default_rng(seed)
    xyz = np.round(np.c_[rng.random((n, 2)), 0.2 * np.abs(rng.random(n) - 0.5)], 6)
    return xyz, rng.integers(0, 256, (n, 3)), rng.integers(0, 1000, n)


def test_a_text_header_names_the_columns_it_carries(tmp_path):
    """A text file's header names its columns: x, y, z found by name (any order, any case),
    colour (R G B or red green blue, 0..255 or 0..1) read as the LAS colour, every other
    column but the normals as float64 under its name — CloudCompare's ``//X,Y,Z,R,G,B``
    header, a PTS file's count line and its ``x y z i r g b``. No header, or one that does not
    match the columns: positions only, as before. They were positions only, whatever the
    header said."""
    xyz, rgb, inten = _text_cloud()
    lines = ["%.6f,%.6f,%.6f,%d,%d,%d,%d" % (*p, *c, i) for p, c, i in zip(xyz, rgb, inten)]
    (tmp_path / "cc.txt").write_text("//X,Y,Z,R,G,B,Intensity\n" + "\n".join(lines) + "\n")
    lines = ["%.6f %.6f %.6f %d %d %d %d" % (*p, i - 500, *c) for p, c, i in zip(xyz, rgb, inten)]
    (tmp_path / "scan.pts").write_text(f"{len(xyz)}\n" + "\n".join(lines) + "\n")
    lines = ["%d;%.6f;%.6f;%.6f;0;0;1" % (i, p[2], p[1], p[0]) for p, i in zip(xyz, inten)]
    (tmp_path / "reord.csv").write_text("Quality;z;y;x;nx;ny;nz\n" + "\n".join(lines) + "\n")
    lines = ["%.6f %.6f %.6f %.4f %.4f %.4f" % (*p, *(c / 255)) for p, c in zip(xyz, rgb)]
    (tmp_path / "float.xyz").write_text("x y z red green blue\n" + "\n".join(lines) + "\n")
    (tmp_path / "short.xyz").write_text("x y z red\n" + "\n".join(lines) + "\n")
    (tmp_path / "none.xyz").write_text("\n".join(lines) + "\n")
    lines = ["%.6f %.6f %.6f part%d %d" % (*p, i, i) for p, i in zip(xyz, inten)]
    (tmp_path / "label.xyz").write_text("x y z label id\n" + "\n".join(lines) + "\n")
    colour = {c: 257 * rgb[:, j] for j, c in enumerate(("red", "green", "blue"))}
    want = {
        "cc.txt": {**colour, "Intensity": inten.astype(float)},
        "scan.pts": {"intensity": inten - 500.0, **colour},
        "reord.csv": {"Quality": inten.astype(float)},
        "float.xyz": {c: np.rint(np.round(v / 257 / 255, 4) * 65535) for c, v in colour.items()},
        "short.xyz": {},
        "none.xyz": {},
        "label.xyz": {"id": inten.astype(float)},  # a column of words is not read
    }
    for name, dims in want.items():
        src = open_source(tmp_path / name, chunk_points=700)
        chunks = list(src.chunks())
        got = np.concatenate([x for _, x, _ in chunks])
        np.testing.assert_array_equal(got, xyz, err_msg=name)
        for part in src.parts(1400):  # as a worker reads them
            for start, x, a in part():
                assert sorted(a) == sorted(dims), name
        attrs = {k: np.concatenate([a[k] for _, _, a in chunks]) for k in dims}
        assert list(chunks[0][2]) == list(dims), name
        for k, v in dims.items():
            np.testing.assert_array_equal(attrs[k], v, err_msg=f"{name} {k}")


def test_a_run_on_a_cloudcompare_text_export_keeps_colour_and_intensity(tmp_path):
    from tiledsimplify.cli import main
    from tiledsimplify.io.columns import read_columns
    xyz, rgb, inten = _text_cloud()
    lines = ["%.6f,%.6f,%.6f,%d,%d,%d,%d" % (*p, *c, i) for p, c, i in zip(xyz, rgb, inten)]
    (tmp_path / "cc.txt").write_text("//X,Y,Z,R,G,B,Intensity\n" + "\n".join(lines) + "\n")
    at = {tuple(p): i for i, p in enumerate(xyz.tolist())}
    for command in ("run", "simplify"):
        out = tmp_path / f"{command}.csv"
        assert main([command, str(tmp_path / "cc.txt"), str(out), "--ratio", "0.1", "-q"]) == 0
        got, cols = read_columns(out)
        rows = np.array([at[tuple(p)] for p in got.tolist()])
        assert len(rows) == 300 and list(cols)[:4] == ["red", "green", "blue", "Intensity"]
        for j, c in enumerate(("red", "green", "blue")):
            np.testing.assert_array_equal(cols[c], rgb[rows, j])
        np.testing.assert_array_equal(cols["Intensity"], inten[rows])


def test_a_structured_npy_carries_its_fields(tmp_path):
    """A structured NPY (our own points file, read back) carries its fields but the normals,
    its colour as the LAS colour — so a PLY's colour survives PLY -> NPY -> PLY — and its old
    flags are replaced by the new run's. Fields other than x, y, z were dropped."""
    from tiledsimplify.cli import main
    xyz, rgb, inten = _text_cloud(2000)
    table = np.zeros(len(xyz), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("red", "u1"),
                                      ("green", "u1"), ("blue", "u1"), ("quality", "f4"),
                                      ("sharp_edge", "u1"), ("nx", "f4")])
    table["x"], table["y"], table["z"] = xyz.T
    for j, c in enumerate(("red", "green", "blue")):
        table[c] = rgb[:, j]
    table["quality"] = inten
    table["sharp_edge"] = 7
    np.save(tmp_path / "in.npy", table)
    _, _, attrs = next(iter(open_source(tmp_path / "in.npy").chunks()))
    assert list(attrs) == ["red", "green", "blue", "quality", "sharp_edge"]
    np.testing.assert_array_equal(attrs["red"], 257 * rgb[:, 0])
    assert main(["run", str(tmp_path / "in.npy"), str(tmp_path / "out.npy"), "--ratio",
                 "0.25", "-q"]) == 0
    out = np.load(tmp_path / "out.npy")
    assert out.dtype.names == ("x", "y", "z", "red", "green", "blue", "quality",
                               "sharp_edge", "nx", "ny", "nz")
    at = {tuple(p): i for i, p in enumerate(xyz.tolist())}
    rows = np.array([at[tuple(p)] for p in np.c_[out["x"], out["y"], out["z"]].tolist()])
    assert len(rows) == 500
    for name in ("red", "green", "blue", "quality"):
        np.testing.assert_array_equal(out[name], table[name][rows], err_msg=name)
    assert set(np.unique(out["sharp_edge"])) <= {0, 1}  # the run's flags, not the old 7
