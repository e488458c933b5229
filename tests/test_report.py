"""The report command: figures that show something, and metrics equal to metrics.evaluate."""

import json
import re
import sys

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tiledsimplify import metrics, synthetic
from tiledsimplify.cli import EXIT_INPUT, EXIT_OK, main
from tiledsimplify.io.columns import read_columns
from tiledsimplify.io.points_out import write_points

mpimg = pytest.importorskip("matplotlib.image")

from tiledsimplify.report import (  # noqa: E402
    DPI, PANEL_INCHES, MissingDependencyError, make_report, view_rotation)

# a stepped block: flat faces and sharp edges, a few thousand points
_V = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0],
               [0, 0, 1], [2, 0, 1], [2, 1, 1], [0, 1, 1]], float)
_F = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
               [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])


@pytest.fixture(scope="module")
def block(tmp_path_factory):
    """A box sampled evenly, its OFF mesh, and a tiledsimplify result with sharp_edge flags."""
    d = tmp_path_factory.mktemp("report")
    X, _ = synthetic.sample_surface_even(_V, _F, 3000, seed=0)
    src = d / "box.xyz"
    np.savetxt(src, X)
    mesh = d / "box.off"
    mesh.write_text("OFF\n8 12 0\n" + "".join(f"{a} {b} {c}\n" for a, b, c in _V)
                    + "".join(f"3 {a} {b} {c}\n" for a, b, c in _F))
    res = d / "box_40.ply"
    assert main(["simplify", str(src), str(res), "--ratio", "0.4", "-q"]) in (0, 3)
    return X, src, mesh, res, d


def _table(md):
    """{key: value} of the metrics table of report.md."""
    out = {}
    for line in md.splitlines():
        m = re.match(r"\|[^|]*\| `(\w+)` \| ([^|]+) \|$", line)
        if m:
            out[m.group(1)] = float(m.group(2))
    return out


def _ink(img):
    """Fraction of pixels that are not (near) white."""
    rgb = img[..., :3]
    return float(np.mean(rgb.min(axis=2) < 0.9))


def _red(img):
    rgb = img[..., :3]
    return int(np.count_nonzero((rgb[..., 0] > 0.7) & (rgb[..., 1] < 0.3) & (rgb[..., 2] < 0.3)))


def test_report_files_images_and_metrics(block):
    X, src, mesh, res, d = block
    out = d / "rep"
    assert main(["report", str(src), str(res), "-o", str(out), "--mesh", str(mesh), "-q"]) \
        == EXIT_OK
    names = ["original.png", "boundary.png", "simplified.png", "overview.png", "report.md",
             "metrics.json"]
    assert sorted(p.name for p in out.iterdir()) == sorted(names)

    side = int(round(PANEL_INCHES * DPI))
    title = round(0.4 * DPI)
    images = {n: mpimg.imread(out / f"{n}.png") for n in
              ("original", "boundary", "simplified", "overview")}
    h, w = images["original"].shape[:2]  # the panel takes the view's shape, longer side fixed
    assert max(w, h - title) == side and min(w, h - title) >= side / 3 - 1
    for name in ("boundary", "simplified"):
        assert images[name].shape[:2] == (h, w), name
    oh, ow = images["overview"].shape[:2]  # three panels of 0.75 the size, one title line
    assert abs(ow - 3 * 0.75 * w) <= 3 and abs((oh - title) - 0.75 * (h - title)) <= 2
    for name, img in images.items():
        assert 0.01 < _ink(img) < 0.8, name  # something is drawn, and not a solid block
    # the boundary points are drawn in red on the boundary panel only
    assert _red(images["original"]) == 0
    assert _red(images["boundary"]) > 200
    assert _red(images["overview"]) > 200

    kept_xyz, cols = read_columns(res)
    keep = np.zeros(len(X), bool)
    idx = cKDTree(X).query(kept_xyz)[1]
    keep[idx] = True
    flagged = np.zeros(len(X), bool)
    flagged[idx[cols["sharp_edge"].astype(bool)]] = True
    s = metrics.spacing(X)
    want = metrics.evaluate(X, keep, edge_segments=_V[synthetic.sharp_edges(_V, _F)],
                            spacing=s, flagged=flagged)
    got = _table((out / "report.md").read_text())
    assert set(got) == set(want)
    for key, value in want.items():
        assert got[key] == pytest.approx(value, rel=1e-5), key
    saved = json.loads((out / "metrics.json").read_text())
    assert saved == pytest.approx(want, rel=1e-12)
    assert type(saved["n_kept"]) is int and type(saved["n_original"]) is int  # not 6000.0
    assert {"edge_coverage", "boundary_f1", "adaptivity"} <= set(got)
    md = (out / "report.md").read_text()
    assert f"in the result: {int(flagged.sum()):,} (" in md
    # the flags of a kept-only result are the kept points' (edge_share may keep fewer): said
    assert "sharp_edge flags are the kept points' only" in md


def test_a_wide_cloud_gets_a_wide_panel(tmp_path):
    """An airborne-like strip (300 x 100 x 10) fills a wide panel instead of a third of a
    square one: the panel's shape follows the view, within 3:1; a tower gets a high one."""
    from tiledsimplify.report import draw_figures
    X = np.random.default_rng(0).random((20000, 3)) * [300.0, 100.0, 10.0]
    img = mpimg.imread(draw_figures(tmp_path, X, X[::5], None, None)["original"])
    h, w = img.shape[:2]
    assert w == round(PANEL_INCHES * DPI) and h - round(0.4 * DPI) < 0.6 * w
    assert _ink(img) > 0.15  # 0.27; 0.10 in the square panel used before
    (tmp_path / "tower").mkdir()
    tower = X[:, [2, 1, 0]] * [1.0, 0.1, 10.0]  # 10 x 10 x 3,000
    img = mpimg.imread(draw_figures(tmp_path / "tower", tower, tower[::5], None, None)[
        "original"])
    assert img.shape[0] > img.shape[1]


def test_all_points_output_and_foreign_result(block, tmp_path):
    X, src, _, res, _ = block
    every = tmp_path / "all.npy"
    assert main(["simplify", str(src), str(every), "--ratio", "0.4", "--all-points", "-q"]) \
        in (0, 3)
    kept_xyz, _ = read_columns(res)
    rep = make_report(src, every, tmp_path / "a", dpi=40)
    assert rep.subset and rep.n_kept == len(kept_xyz)
    assert rep.metrics["n_kept"] == len(kept_xyz)

    # points that are not input points (e.g. another tool's centroids): measured as points
    moved = kept_xyz + 1e-3
    foreign = tmp_path / "foreign.xyz"
    np.savetxt(foreign, moved)
    rep = make_report(src, foreign, tmp_path / "b", dpi=40)
    assert not rep.subset and rep.n_boundary is None
    assert "adaptivity" not in rep.metrics
    assert "boundary" not in rep.files
    assert rep.metrics["hausdorff"] == pytest.approx(metrics.hausdorff_distance(X, moved))
    assert "not all input points" in (tmp_path / "b" / "report.md").read_text()

    # a result with a NaN point: named with its file and row, not matplotlib's complaint
    broken = tmp_path / "broken.xyz"
    moved[3, 0] = np.nan
    np.savetxt(broken, moved)
    with pytest.raises(ValueError, match=r"broken.xyz: point 3 has a NaN"):
        make_report(src, broken, tmp_path / "c", dpi=40)


def test_read_columns_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    X = rng.random((40, 3))
    cols = {"sharp_edge": (rng.random(40) > 0.5).astype(np.uint8),
            "simplify_rank": rng.integers(-1, 50, 40)}
    for suffix in (".ply", ".npy", ".csv", ".xyz"):
        path = tmp_path / f"c{suffix}"
        write_points(path, X, cols)
        xyz, got = read_columns(path)
        np.testing.assert_array_equal(xyz, X)
        np.testing.assert_array_equal(got["sharp_edge"], cols["sharp_edge"])
        np.testing.assert_array_equal(got["simplify_rank"], cols["simplify_rank"])


def test_an_ascii_ply_result_without_vertices_is_named(tmp_path, caplog):
    """An ASCII PLY with ``element vertex 0`` (an export of an empty selection): np.loadtxt
    gave a (0, 1) table and read_columns an IndexError, so ``report`` ended in a traceback
    (exit 1) instead of naming the file."""
    empty = tmp_path / "e.ply"
    empty.write_text("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                     "property float y\nproperty float z\nproperty uchar sharp_edge\n"
                     "end_header\n")
    xyz, got = read_columns(empty)
    assert xyz.shape == (0, 3) and got["sharp_edge"].shape == (0,)
    src = tmp_path / "s.npy"
    np.save(src, np.random.default_rng(0).random((50, 3)))
    assert main(["report", str(src), str(empty), "-o", str(tmp_path / "r"), "-q"]) == EXIT_INPUT
    assert "e.ply: the simplified cloud has no points" in caplog.text
    assert not (tmp_path / "r").exists()  # refused before the report's directory is made
    from tiledsimplify.report import make_report
    with pytest.raises(Exception, match="e.ply: the result has no points"):
        make_report(src, empty, tmp_path / "r2", dpi=40)


def test_report_into_a_file_is_refused(tmp_path, caplog):
    """``-o`` naming an existing file: exit 1 with "File exists." (mkdir's words) before."""
    src = tmp_path / "s.npy"
    np.save(src, np.random.default_rng(0).random((50, 3)))
    taken = tmp_path / "taken.txt"
    taken.write_text("mine\n")
    assert main(["report", str(src), str(src), "-o", str(taken), "-q"]) == EXIT_INPUT
    assert "taken.txt: exists and is not a directory; give -o a directory" in caplog.text
    assert taken.read_text() == "mine\n"


def test_read_columns_las_extra_dimensions(tmp_path):
    import laspy

    from tiledsimplify.io.las_output import write_las
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales = np.array([0.001] * 3)
    header.offsets = np.zeros(3)
    X = np.round(np.random.default_rng(1).random((30, 3)) * 10, 3)
    flags = (np.arange(30) % 3 == 0).astype(np.uint8)
    dims = [d.name for d in header.point_format.dimensions if d.name not in ("X", "Y", "Z")]
    rec = laspy.ScaleAwarePointRecord.zeros(30, header=header)
    zeros = {name: np.array(rec[name]) for name in dims}
    path = write_las(tmp_path / "r.las", header, X, zeros,
                     extra={"sharp_edge": flags, "importance": np.linspace(0, 1, 30),
                            "simplify_rank": np.arange(30) - 1})
    xyz, got = read_columns(path)
    np.testing.assert_allclose(xyz, X, atol=1e-9)
    np.testing.assert_array_equal(got["sharp_edge"], flags)


def test_view_rotation_is_a_rotation_and_puts_up_on_top():
    for up in "xyz":
        R = view_rotation(up, 20, -60)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        u = np.zeros(3)
        u["xyz".index(up)] = 1
        assert (R @ u)[1] == pytest.approx(np.cos(np.radians(20)))  # screen-up component


def test_missing_matplotlib_says_what_to_install(block, tmp_path, monkeypatch, caplog):
    _, src, _, res, _ = block
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib -> ImportError
    with pytest.raises(MissingDependencyError, match=r"tiledsimplify\[report\]"):
        make_report(src, res, tmp_path / "x")
    assert main(["report", str(src), str(res), "-o", str(tmp_path / "y")]) == EXIT_INPUT
    assert "tiledsimplify[report]" in caplog.text
