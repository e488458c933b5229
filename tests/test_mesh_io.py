"""Tests for tiledsimplify.io.mesh: read_mesh and read_points."""

from __future__ import annotations

import gzip
import struct
from pathlib import Path

import numpy as np
import pytest

from tiledsimplify.errors import FileFormatError
from tiledsimplify.io.mesh import read_mesh, read_points

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def data_file(rel: str) -> Path:
    path = DATA / rel
    if not path.exists():
        pytest.skip(f"test data {path} not found")
    return path


# --------------------------------------------------------------------------------------
# real files: counts from /work/shared/data/SOURCES.md
# --------------------------------------------------------------------------------------

MESHES = [
    ("meshes/cad_classic/fandisk.obj", 6475, 12946),
    ("meshes/cad_classic/fandisk_libigl.off", 7229, 14454),
    ("meshes/cad_classic/rocker-arm.obj.gz", 10044, 20088),
    ("meshes/cad_classic/block.obj", 2132, 4272),
    ("meshes/stanford_bunny/bun_zipper.ply.gz", 35947, 69451),
    ("meshes/stanford_bunny/bun_zipper_res2.ply.gz", 8171, 16301),
    ("meshes/stanford_bunny/bun_zipper_res3.ply", 1889, 3851),
    ("meshes/stanford_bunny/bun_zipper_res4.ply", 453, 948),
    ("meshes/trimesh_cad/featuretype.STL", 1722, 3476),  # binary STL
    ("meshes/trimesh_cad/angle_block.STL", 352, 704),  # binary, header starts with "solid"
    ("meshes/trimesh_cad/idler_riser.STL", 782, 1572),
    ("meshes/trimesh_cad/octagonal_pocket.stl", 1631, 3262),
    ("meshes/trimesh_cad/plate_holes.STL", 618, 1252),
    ("meshes/trimesh_cad/ADIS16480.STL.gz", 3672, 7436),  # ASCII STL, gzipped
    ("meshes/trimesh_cad/1002_tray_bottom.STL.gz", 2216, 4520),  # ASCII STL, gzipped
    ("meshes/trimesh_cad/counter.unitsmm.STL.gz", 41837, 83750),  # binary STL, gzipped
    ("meshes/trimesh_cad/cycloidal.ply.gz", 21384, 43368),  # binary little-endian PLY
]


@pytest.mark.parametrize("rel,nv,nf", MESHES, ids=[m[0].rsplit("/", 1)[1] for m in MESHES])
def test_real_mesh_counts(rel, nv, nf):
    v, f = read_mesh(data_file(rel))
    assert v.shape == (nv, 3) and v.dtype == np.float64
    assert f.shape == (nf, 3) and f.dtype == np.int64
    assert f.min() >= 0 and f.max() < nv
    assert np.isfinite(v).all()
    # every vertex is used by some face, except in the zippered bunnies, which keep
    # unreferenced vertices (35,947 vertices, only 34,834 used by faces)
    unused = {"bun_zipper.ply.gz": 1113, "bun_zipper_res2.ply.gz": 25, "bun_zipper_res3.ply": 2}
    assert len(np.unique(f)) == nv - unused.get(Path(rel).name, 0)


SCANS = [
    ("bun000", 40256), ("bun045", 40097), ("bun090", 30379), ("bun180", 40251), ("bun270", 31701),
    ("bun315", 35336), ("chin", 37738), ("ear_back", 32193), ("top2", 38298), ("top3", 36023),
]


@pytest.mark.parametrize("name,n", SCANS, ids=[s[0] for s in SCANS])
def test_raw_scan_counts(name, n):
    # ASCII PLY with a variable-length 'range_grid' list element after the vertices
    p = read_points(data_file(f"scans/stanford_bunny_range/{name}.ply.gz"))
    assert p.shape == (n, 3) and p.dtype == np.float64
    # scanner-frame metres: the bunny is ~0.15 m across
    assert np.ptp(p, axis=0).max() < 0.3


def test_raw_scan_first_and_last_vertex():
    p = read_points(data_file("scans/stanford_bunny_range/bun000.ply.gz"))
    np.testing.assert_allclose(p[0], [-0.06325, 0.0359793, 0.0420873], rtol=1e-6)
    np.testing.assert_allclose(p[-1], [-0.018, 0.18794, -0.0197253], rtol=1e-6)


def test_raw_scan_as_mesh_has_no_faces():
    v, f = read_mesh(data_file("scans/stanford_bunny_range/bun000.ply.gz"))
    assert v.shape == (40256, 3) and f.shape == (0, 3) and f.dtype == np.int64


def test_fandisk_obj_and_off_have_same_shape():
    v1, _ = read_mesh(data_file("meshes/cad_classic/fandisk.obj"))
    v2, _ = read_mesh(data_file("meshes/cad_classic/fandisk_libigl.off"))
    np.testing.assert_allclose(v1.min(axis=0), v2.min(axis=0), atol=1e-3)
    np.testing.assert_allclose(v1.max(axis=0), v2.max(axis=0), atol=1e-3)


def test_read_points_of_mesh_is_vertices():
    path = data_file("meshes/stanford_bunny/bun_zipper_res4.ply")
    v, _ = read_mesh(path)
    np.testing.assert_array_equal(read_points(path), v)
    np.testing.assert_allclose(v[0], [-0.0312216, 0.126304, 0.00514924], rtol=1e-6)
    obj = data_file("meshes/cad_classic/block.obj")
    np.testing.assert_array_equal(read_points(obj), read_mesh(obj)[0])


def test_stl_exact_merge_keeps_near_duplicates():
    # featuretype.STL writes some zeros as ~1e-16: exact merging leaves 2010 vertices,
    # the default tolerance merge gives the 1722 of a closed mesh
    path = data_file("meshes/trimesh_cad/featuretype.STL")
    v0, f0 = read_mesh(path, merge_tol=0)
    v1, f1 = read_mesh(path)
    assert len(v0) == 2010 and len(v1) == 1722
    assert len(f0) == len(f1) == 3476
    # same triangles geometrically
    np.testing.assert_allclose(v0[f0], v1[f1], atol=1e-12)


def test_binary_and_ascii_stl_agree(tmp_path):
    v, f = read_mesh(data_file("meshes/trimesh_cad/ADIS16480.STL.gz"))
    tri = v[f].astype("<f4")
    rec = np.zeros(len(f), dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = tri
    header = b"solid but actually binary".ljust(80, b" ")
    out = tmp_path / "adis_binary.stl"
    out.write_bytes(header + struct.pack("<I", len(f)) + rec.tobytes())
    vb, fb = read_mesh(out)
    assert vb.shape == v.shape and fb.shape == f.shape
    np.testing.assert_allclose(vb[fb], v[f], rtol=1e-6, atol=1e-9)


# --------------------------------------------------------------------------------------
# PLY round trips on a small mesh
# --------------------------------------------------------------------------------------

CUBE_V = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=np.float64
) * 0.5 - 0.25
CUBE_QUADS = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]


def fan(polys):
    return np.array([[p[0], p[i], p[i + 1]] for p in polys for i in range(1, len(p) - 1)], dtype=np.int64)


def write_ply(path, fmt, vertices, polys, *, count_type="uchar", index_type="int", pre_element=False,
              face_extra=False, post_element=False):
    """Write a PLY with extra vertex properties (double x,y,z; uchar colour; float quality)."""
    endian = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}[fmt]
    codes = {"uchar": "u1", "char": "i1", "ushort": "u2", "short": "i2", "int": "i4", "uint": "u4",
             "float": "f4", "double": "f8"}
    lines = ["ply", f"format {fmt} 1.0", "comment written by test_mesh_io"]
    if pre_element:
        lines += ["element material 2", "property float shine", "property list uchar ushort ids"]
    lines += [f"element vertex {len(vertices)}", "property double x", "property uchar red",
              "property double y", "property double z", "property float quality",
              f"element face {len(polys)}", f"property list {count_type} {index_type} vertex_indices"]
    if face_extra:
        lines += ["property uchar red", "property list uchar float uv"]
    if post_element:
        lines += ["element edge 1", "property int vertex1", "property int vertex2"]
    lines.append("end_header")
    head = ("\n".join(lines) + "\n").encode("ascii")
    rows = []
    if pre_element:
        rows += [[("f4", 0.5), ("u1", 2), ("u2", 7), ("u2", 8)], [("f4", 1.5), ("u1", 0)]]
    for i, p in enumerate(vertices):
        rows.append([("f8", p[0]), ("u1", i % 256), ("f8", p[1]), ("f8", p[2]), ("f4", 0.25 * i)])
    for k, poly in enumerate(polys):
        row = [(codes[count_type], len(poly))] + [(codes[index_type], i) for i in poly]
        if face_extra:
            row += [("u1", 9)] + [("u1", k % 3)] + [("f4", 0.5)] * (k % 3)
        rows.append(row)
    if post_element:
        rows.append([("i4", 0), ("i4", 1)])
    if endian is None:
        body = "".join(" ".join(repr(float(x)) if c[0] == "f" else str(int(x)) for c, x in row) + "\n"
                       for row in rows).encode()
    else:
        body = b"".join(np.array(x, dtype=endian + c).tobytes() for row in rows for c, x in row)
    Path(path).write_bytes(head + body)


PLY_FORMATS = ["ascii", "binary_little_endian", "binary_big_endian"]


@pytest.mark.parametrize("fmt", PLY_FORMATS)
def test_ply_round_trip_quads(tmp_path, fmt):
    path = tmp_path / f"cube_{fmt}.ply"
    write_ply(path, fmt, CUBE_V, CUBE_QUADS)
    v, f = read_mesh(path)
    np.testing.assert_array_equal(v, CUBE_V)
    np.testing.assert_array_equal(f, fan(CUBE_QUADS))
    np.testing.assert_array_equal(read_points(path), CUBE_V)


@pytest.mark.parametrize("fmt", PLY_FORMATS)
@pytest.mark.parametrize("count_type,index_type", [("uchar", "uint"), ("int", "int"), ("ushort", "short"),
                                                   ("uchar", "ushort")])
def test_ply_mixed_polygons_and_extra_elements(tmp_path, fmt, count_type, index_type):
    # variable list lengths (general row walk), an element before 'vertex', extra face
    # properties after the index list (one of them a variable list) and an element after
    polys = [[0, 1, 2], [0, 2, 3, 4], [4, 5, 6, 7, 0], [1, 7, 3]]
    path = tmp_path / f"mixed_{fmt}.ply"
    write_ply(path, fmt, CUBE_V, polys, count_type=count_type, index_type=index_type,
              pre_element=True, face_extra=True, post_element=True)
    v, f = read_mesh(path)
    np.testing.assert_array_equal(v, CUBE_V)
    np.testing.assert_array_equal(f, fan(polys))
    np.testing.assert_array_equal(read_points(path), CUBE_V)


@pytest.mark.parametrize("fmt", PLY_FORMATS)
def test_ply_ascii_and_binary_agree_on_real_mesh(tmp_path, fmt):
    v, f = read_mesh(data_file("meshes/stanford_bunny/bun_zipper_res4.ply"))
    path = tmp_path / f"bunny_{fmt}.ply.gz"
    write_ply(path, fmt, v, f.tolist(), face_extra=True)
    path.write_bytes(gzip.compress(path.read_bytes()))
    v2, f2 = read_mesh(path)
    np.testing.assert_array_equal(v2, v)
    np.testing.assert_array_equal(f2, f)


def test_ply_without_faces_and_vertex_index_name(tmp_path):
    path = tmp_path / "pts.ply"
    body = "1 2 3\n4 5 6\n"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                    "property float z\nend_header\n" + body)
    v, f = read_mesh(path)
    assert v.tolist() == [[1, 2, 3], [4, 5, 6]] and f.shape == (0, 3)
    path2 = tmp_path / "tri.PLY"
    path2.write_text("ply\r\nformat ascii 1.0\r\nelement vertex 3\r\nproperty float x\r\nproperty float y\r\n"
                     "property float z\r\nelement face 1\r\nproperty list uchar int vertex_index\r\n"
                     "end_header\r\n0 0 0\r\n1 0 0\r\n0 1 0\r\n3 0 1 2\r\n")
    v, f = read_mesh(path2)
    assert f.tolist() == [[0, 1, 2]]


# --------------------------------------------------------------------------------------
# OBJ / OFF / STL text variants
# --------------------------------------------------------------------------------------


def test_obj_variants(tmp_path):
    text = """# comment
o thing
v 0 0 0
v 1 0 0 0.5 0.5 0.5
v 1 1 0
v 0 1 0
vt 0 0
vn 0 0 1
f 1/1/1 2/1/1 3/1/1 4/1/1
v 0 0 1
f -1 1//1 -4
f 5/1 2 3
"""
    path = tmp_path / "quad.OBJ"
    path.write_text(text)
    v, f = read_mesh(path)
    assert v.shape == (5, 3)
    assert f.tolist() == [[0, 1, 2], [0, 2, 3], [4, 0, 1], [4, 1, 2]]
    gz = tmp_path / "quad.obj.GZ"
    gz.write_bytes(gzip.compress(text.encode()))
    v2, f2 = read_mesh(gz)
    np.testing.assert_array_equal(v2, v)
    np.testing.assert_array_equal(f2, f)


def test_off_variants(tmp_path):
    path = tmp_path / "t.off"
    path.write_text("COFF 4 2 0\n# a comment\n0 0 0 255 0 0 255\n1 0 0 255 0 0 255\n"
                    "1 1 0 0 0 0 255 # trailing\n0 1 0 0 0 0 255\n\n4 0 1 2 3 10 20 30\n3 0 2 1\n")
    v, f = read_mesh(path)
    assert v.shape == (4, 3)
    assert f.tolist() == [[0, 1, 2], [0, 2, 3], [0, 2, 1]]


def test_ascii_stl_merges_vertices(tmp_path):
    facet = "facet normal 0 0 1\n outer loop\n  vertex {} \n  vertex {}\n  vertex {}\n endloop\nendfacet\n"
    text = ("solid two\n" + facet.format("0 0 0", "1 0 0", "1 1 0") + facet.format("0 0 0", "1 1 0", "-0.0 1 0")
            + "endsolid two\n")
    path = tmp_path / "two.stl"
    path.write_text(text)
    v, f = read_mesh(path)
    assert v.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    assert f.tolist() == [[0, 1, 2], [0, 2, 3]]


# --------------------------------------------------------------------------------------
# point files
# --------------------------------------------------------------------------------------

PTS = np.array([[0.5, -1.25, 3.0], [1e-3, 2.0, -4.5], [7.0, 8.0, 9.0]])


def test_csv_with_header_and_extra_columns(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("x,y,z,intensity\n" + "".join(f"{a},{b},{c},17\n" for a, b, c in PTS))
    np.testing.assert_array_equal(read_points(path), PTS)


def test_xyz_whitespace_no_header(tmp_path):
    path = tmp_path / "p.xyz"
    path.write_text("".join(f"  {a}\t{b}   {c} 1 2 3\n" for a, b, c in PTS) + "\n")
    np.testing.assert_array_equal(read_points(path), PTS)


def test_txt_comma_and_pts_count_line(tmp_path):
    path = tmp_path / "p.txt"
    path.write_text("# exported\n" + "".join(f"{a}, {b}, {c}\n" for a, b, c in PTS))
    np.testing.assert_array_equal(read_points(path), PTS)
    path = tmp_path / "p.pts"
    path.write_text("3\n" + "".join(f"{a} {b} {c} 100 1 2 3\n" for a, b, c in PTS))
    np.testing.assert_array_equal(read_points(path), PTS)


def test_single_point_text(tmp_path):
    path = tmp_path / "one.xyz"
    path.write_text("1 2 3\n")
    assert read_points(path).shape == (1, 3)


def test_npy_and_gz(tmp_path):
    arr = np.column_stack([PTS, np.ones((3, 3))]).astype(np.float32)
    path = tmp_path / "p.npy"
    np.save(path, arr)
    out = read_points(path)
    assert out.dtype == np.float64
    np.testing.assert_array_equal(out, arr[:, :3].astype(np.float64))
    gz = tmp_path / "p.npy.gz"
    gz.write_bytes(gzip.compress(path.read_bytes()))
    np.testing.assert_array_equal(read_points(gz), out)
    npz = tmp_path / "p.npz"
    np.savez(npz, points=PTS, other=np.zeros(2))
    np.testing.assert_array_equal(read_points(npz), PTS)


# --------------------------------------------------------------------------------------
# errors
# --------------------------------------------------------------------------------------

HEADER = "ply\nformat {} 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n" \
         "element face 1\nproperty list uchar int vertex_indices\nend_header\n"

BAD_FILES = {
    "truncated_binary.ply": HEADER.format("binary_little_endian").encode() + b"\0" * 30,
    "truncated_ascii.ply": (HEADER.format("ascii") + "0 0 0\n1 0 0\n0 1 0\n3 0 1\n").encode(),
    "bad_index.ply": (HEADER.format("ascii") + "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").encode(),
    "no_end_header.ply": b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",
    "no_xyz.ply": b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float a\nend_header\n1\n",
    "bad_type.ply": b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n1\n",
    "not_a_ply.ply": b"hello world\n",
    "text_in_ascii.ply": (HEADER.format("ascii") + "0 0 zero\n1 0 0\n0 1 0\n3 0 1 2\n").encode(),
    "bad_face.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n",
    "zero_index.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
    "out_of_range.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
    "short_v.obj": b"v 0 0\n",
    "truncated.off": b"OFF\n4 2 0\n0 0 0\n1 0 0\n",
    "nooff.off": b"4 2 0\n0 0 0\n",
    "truncated_binary.stl": b"\0" * 80 + struct.pack("<I", 10) + b"\0" * 100,
    "wrong_vertex_count.stl": b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                              b"endloop\nendfacet\nendsolid x\n",
    "letters.csv": b"x,y,z\n1,2,3\n4,five,6\n",
    "two_columns.xyz": b"1 2\n3 4\n",
    "empty.xyz": b"",
    "wrong_shape.npy": None,  # written below
    "not_gzip.ply.gz": b"ply\nformat ascii 1.0\n",
    "unknown.abc": b"1 2 3\n",
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_malformed_file_raises_file_format_error(tmp_path, name):
    path = tmp_path / name
    if name.endswith(".npy"):
        np.save(path, np.zeros((4, 2)))
    else:
        path.write_bytes(BAD_FILES[name])
    reader = read_points if name.endswith((".csv", ".xyz", ".npy", ".abc")) else read_mesh
    with pytest.raises(FileFormatError) as info:
        reader(path)
    assert name in str(info.value)
    assert isinstance(info.value, ValueError)


def test_missing_file_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_mesh(tmp_path / "nope.ply")
    with pytest.raises(FileNotFoundError):
        read_points(tmp_path / "nope.xyz")
