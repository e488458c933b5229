"""One output per input file (an output name with ``{stem}``): a folder of LAS/LAZ tiles
simplified as one cloud, its kept points written back to one file per input file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

laspy = pytest.importorskip("laspy")

from tiledsimplify import run  # noqa: E402
from tiledsimplify.errors import InputError  # noqa: E402

AUTZEN = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "lidar" / \
    "autzen_trim.laz"
ADDED = ("sharp_edge", "importance", "simplify_rank")


def _records(las, names=None):
    """Each point's record as one row of a structured array (sortable, comparable)."""
    names = names or [n for n in las.point_format.dimension_names if n not in ADDED]
    out = np.empty(len(las.points), dtype=[(n, np.asarray(las[n]).dtype) for n in names])
    for n in names:
        out[n] = np.asarray(las[n])
    return np.sort(out)


@pytest.fixture(scope="module")
def tiles(tmp_path_factory):
    """autzen_trim.laz cut into three files by x, the middle one on another grid (scales of
    a hundredth, not a thousandth, other offsets) and counting GPS time otherwise: a single
    LAS output could hold them only on the first file's grid, and not with both times."""
    if not AUTZEN.is_file():
        pytest.skip(f"test data {AUTZEN} not found")
    src = laspy.read(AUTZEN)
    d = tmp_path_factory.mktemp("tiles")
    x = np.asarray(src.x)
    cuts = np.quantile(x, [1 / 3, 2 / 3])
    parts = {"a_west": x < cuts[0], "b_middle": (x >= cuts[0]) & (x < cuts[1]),
             "c_east": x >= cuts[1]}
    for name, m in parts.items():
        header = laspy.LasHeader(point_format=src.header.point_format,
                                 version=src.header.version)
        header.scales = src.header.scales * (10 if name == "b_middle" else 1)
        header.offsets = src.header.offsets + (1000.0 if name == "b_middle" else 0.0)
        header.vlrs.extend(src.header.vlrs)
        las = laspy.LasData(header)
        for dim in src.point_format.dimension_names:
            if dim not in ("X", "Y", "Z"):
                las[dim] = src[dim][m]
        las.x, las.y, las.z = src.x[m], src.y[m], src.z[m]
        if name == "b_middle":
            las.header.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
        las.write(d / f"{name}.laz")
    return d


def test_each_output_holds_its_files_kept_points_on_its_files_grid(tiles, tmp_path):
    """Each input file gets an output with its own header's scales, offsets and GPS time
    type, holding exactly the kept points read from it — records as read, the added
    dimensions beside them; together the kept points of one run over the folder: the same
    points, at the same count, as a single (NPY) output of the same run keeps."""
    inputs = sorted(tiles.glob("*.laz"))
    single = run(str(tiles / "*.laz"), tmp_path / "one.npy", ratio=0.2, tile_points=30_000)
    (tmp_path / "out").mkdir()
    with pytest.raises(Exception, match="count gps_time differently"):  # one LAS output
        run(str(tiles / "*.laz"), tmp_path / "one.laz", ratio=0.2, tile_points=30_000)
    s = run(str(tiles / "*.laz"), str(tmp_path / "out" / "{stem}.laz"), ratio=0.2,
            tile_points=30_000)
    assert [o["path"] for o in s.outputs] == [str(tmp_path / "out" / f"{p.stem}.laz")
                                              for p in inputs]
    assert s.n_output == single.n_output == s.target and s.n_boundary == single.n_boundary
    kept = np.load(tmp_path / "one.npy")
    total = 0
    for p, out in zip(inputs, s.outputs):
        src, got = laspy.read(p), laspy.read(out["path"])
        assert out["points"] == len(got.points) and out["boundary"] == int(got.sharp_edge.sum())
        for key in ("scales", "offsets"):
            np.testing.assert_array_equal(getattr(got.header, key), getattr(src.header, key))
        assert got.header.global_encoding.gps_time_type == src.header.global_encoding.gps_time_type
        assert set(ADDED) <= set(got.point_format.dimension_names)
        assert np.all(got.simplify_rank == -1)
        # every kept record is one of its file's records, as read
        recs, mine = _records(got), _records(src)
        assert np.all(np.isin(recs, mine))
        assert len(np.unique(recs)) == len(recs) == got.header.point_count
        # ... and the single output's points inside the file's x range are exactly these
        lo, hi = src.header.mins[0], src.header.maxs[0]
        inside = (kept["x"] >= lo) & (kept["x"] <= hi)
        assert inside.sum() == len(recs)
        np.testing.assert_allclose(np.sort(kept["x"][inside]), np.sort(np.asarray(got.x)),
                                   rtol=0, atol=0.5 * src.header.scales[0] + 1e-9)
        assert int(got.sharp_edge.sum()) == int(kept["sharp_edge"][inside].sum())
        total += len(recs)
    assert total == s.n_output


def test_a_file_with_no_kept_point_gets_an_empty_output(tiles, tmp_path):
    """A file of three copies of another file's ground points (read after it: copies are
    removed first) loses every point at 5 %: its output holds none, and is a valid LAS file;
    a pattern's folders are per file too."""
    src = laspy.read(tiles / "a_west.laz")
    few = laspy.LasData(src.header)
    few.points = src.points[np.flatnonzero(np.asarray(src.classification) == 2)[:3]]
    d = tmp_path / "in"
    d.mkdir()
    few.write(d / "z_few.laz")
    src.write(d / "many.laz")
    for name in ("z_few", "many"):
        (tmp_path / name).mkdir()
    s = run(str(d / "*.laz"), str(tmp_path / "{stem}" / "kept.las"), ratio=0.05,
            tile_points=20_000)
    got = laspy.read(tmp_path / "z_few" / "kept.las")
    assert got.header.point_count == 0 == len(got.points)
    assert laspy.read(tmp_path / "many" / "kept.las").header.point_count == s.n_output
    assert [(Path(o["path"]).parent.name, o["points"]) for o in s.outputs] == [
        ("many", s.n_output), ("z_few", 0)]


def test_outputs_that_cannot_be_made_are_refused_before_the_work(tiles, tmp_path):
    (tmp_path / "x" / "a_west.laz").parent.mkdir()
    (tmp_path / "x" / "a_west.laz").write_bytes((tiles / "a_west.laz").read_bytes())
    cases = [
        (str(tiles / "*.laz"), tmp_path / "{stem}.ply", r"\{stem}\) is written as LAS/LAZ"),
        (str(tiles / "*.laz"), tmp_path / "{name}_{stem}.laz", r"the only placeholder"),
        ([tiles / "a_west.laz", tmp_path / "x" / "a_west.laz"], tmp_path / "{stem}.laz",
         r"a_west.laz and .*a_west.laz would both be written to"),
        (str(tiles / "*.laz"), tiles / "{stem}.laz", r"is the input file"),
    ]
    for inputs, output, message in cases:
        with pytest.raises(InputError, match=message):
            run(inputs, str(output), ratio=0.2)
    np.save(tmp_path / "cloud.npy", np.random.default_rng(0).random((500, 3)))
    with pytest.raises(InputError, match=r"needs LAS/LAZ input files"):
        run(tmp_path / "cloud.npy", str(tmp_path / "{stem}.laz"), ratio=0.2)
    assert not list(tmp_path.glob("*.la[sz]"))


def test_a_failed_run_leaves_no_partial_output(tiles, tmp_path, monkeypatch):
    """A run that fails while writing leaves every output whole or absent: no temporary
    file, nothing half-written under an output's name."""
    from tiledsimplify.pipeline import per_file
    real = per_file._tile_file_pieces
    calls = []

    def failing(*args):
        calls.append(args[1])
        if len(calls) == 3:
            raise OSError("disk gone")
        return real(*args)
    monkeypatch.setattr(per_file, "_tile_file_pieces", failing)
    (tmp_path / "out").mkdir()
    with pytest.raises(OSError, match="disk gone"):
        run(str(tiles / "*.laz"), str(tmp_path / "out" / "{stem}.laz"), ratio=0.2,
            tile_points=20_000)
    left = list((tmp_path / "out").iterdir())
    assert not [p for p in left if p.name.endswith(".partial")]
    for p in left:  # finished before the failure: whole
        assert laspy.read(p).header.point_count > 0


def test_command_line_summary_names_every_output(tiles, tmp_path):
    from tiledsimplify.cli import main
    (tmp_path / "out").mkdir()
    code = main(["run", str(tiles / "*.laz"), str(tmp_path / "out" / "{stem}.laz"),
                 "--ratio", "0.1", "--no-progress", "--summary", str(tmp_path / "s.json")])
    assert code == 0
    summary = json.loads((tmp_path / "s.json").read_text())
    assert [Path(o["path"]).name for o in summary["outputs"]] == ["a_west.laz", "b_middle.laz",
                                                                  "c_east.laz"]
    for o in summary["outputs"]:
        assert laspy.read(o["path"]).header.point_count == o["points"] > 0
    assert sum(o["points"] for o in summary["outputs"]) == summary["n_output"]


def test_a_killed_runs_leftovers_are_named(tiles, tmp_path, caplog):
    """A killed run's temporary file beside one of the outputs is named, as for one output."""
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / ".b_middle.laz.x1y2.partial").write_bytes(b"0" * 1000)
    with caplog.at_level("WARNING", logger="tiledsimplify"):
        run(str(tiles / "*.laz"), str(tmp_path / "out" / "{stem}.laz"), ratio=0.2,
            tile_points=30_000)
    text = [r.getMessage() for r in caplog.records if "temporary file(s)" in r.getMessage()]
    assert len(text) == 1 and "b_middle.laz" in text[0] and ".b_middle.laz.x1y2.partial" in text[0]


def test_output_names_from_a_pattern(tmp_path):
    """``{stem}`` is the file's name less its suffix, and less ``.copc`` (the output is plain
    LAZ); anywhere in the pattern, folders too; a name without it is one output."""
    from types import SimpleNamespace

    from tiledsimplify.pipeline.per_file import per_file_outputs
    src = SimpleNamespace(is_las=True, files=[Path("a/x.laz"), Path("b/Y.COPC.LAZ"),
                                              Path("c/z.las")])
    assert per_file_outputs("out/{stem}_s.laz", src) == [
        Path("out/x_s.laz"), Path("out/Y_s.laz"), Path("out/z_s.laz")]
    assert per_file_outputs("{stem}/kept.las", src) == [
        Path("x/kept.las"), Path("Y/kept.las"), Path("z/kept.las")]
    assert per_file_outputs(tmp_path / "one.laz", src) is None
