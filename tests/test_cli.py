"""The command line and the point writer: formats round-trip, exit codes, no half files."""

from pathlib import Path

import numpy as np
import pytest

from tiledsimplify.cli import EXIT_BUDGET, EXIT_INPUT, EXIT_OK, main
from tiledsimplify.errors import FileFormatError
from tiledsimplify.io import read_points
from tiledsimplify.io.points_out import write_points


@pytest.fixture()
def cloud(tmp_path):
    rng = np.random.default_rng(0)
    xy = rng.random((1200, 2)) * 3
    X = np.c_[xy, np.sin(xy[:, 0])]
    path = tmp_path / "in.xyz"
    np.savetxt(path, X)
    return X, path


@pytest.mark.parametrize("suffix", [".npy", ".ply", ".xyz", ".csv"])
def test_write_points_round_trips(tmp_path, suffix):
    rng = np.random.default_rng(1)
    X = rng.random((50, 3)) * 1000
    cols = {"sharp_edge": (rng.random(50) > 0.5).astype(np.uint8),
            "simplify_rank": rng.integers(-1, 100, 50), "importance": rng.random(50)}
    path = tmp_path / f"out{suffix}"
    write_points(path, X, cols)
    np.testing.assert_array_equal(read_points(path), X)
    if suffix == ".npy":
        t = np.load(path)
        np.testing.assert_array_equal(t["simplify_rank"], cols["simplify_rank"])
        np.testing.assert_array_equal(t["importance"], cols["importance"])
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_failed_write_leaves_nothing(tmp_path, monkeypatch):
    path = tmp_path / "out.npy"

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(np, "save", boom)
    with pytest.raises(OSError, match="disk full"):
        write_points(path, np.zeros((3, 3)))
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(FileFormatError, match="cannot write '.las'"):
        write_points(tmp_path / "out.las", np.zeros((3, 3)))


def test_cli_simplifies_and_writes_flags(cloud, tmp_path):
    X, path = cloud
    out = tmp_path / "out.npy"
    assert main(["simplify", str(path), str(out), "--ratio", "0.25", "-q"]) == EXIT_OK
    t = np.load(out)
    assert len(t) == 300
    assert (t["simplify_rank"] == -1).all() and np.isnan(t["importance"]).all()
    out_all = tmp_path / "all.npy"
    assert main(["simplify", str(path), str(out_all), "--count", "300", "--all-points",
                 "-q"]) == EXIT_OK
    t_all = np.load(out_all)
    assert len(t_all) == 1200 and (t_all["simplify_rank"] >= 0).sum() == 900


def test_cli_exit_codes(cloud, tmp_path, caplog, capsys):
    X, path = cloud
    out = tmp_path / "out.ply"
    assert main(["simplify", str(tmp_path / "missing.ply"), str(out), "--ratio", "0.5"]) \
        == EXIT_INPUT
    assert "missing.ply" in caplog.text
    for bad in ("2", "0", "-0.1", "nan", "half"):  # refused by the parser, naming the option
        with pytest.raises(SystemExit) as stop:
            main(["simplify", str(path), str(out), "--ratio", bad])
        assert stop.value.code == EXIT_INPUT
        assert "argument --ratio: expected a fraction of the points in (0, 1]" in \
            capsys.readouterr().err
    bad = tmp_path / "bad.xyz"
    bad.write_text("1 2 3\n4 five 6\n")
    assert main(["simplify", str(bad), str(out), "--ratio", "0.5"]) == EXIT_INPUT
    assert "bad.xyz" in caplog.text
    # every point flagged as boundary: the count cannot be reached, the file is still written
    assert main(["simplify", str(path), str(out), "--ratio", "0.1",
                 "--boundary-threshold", "0", "--mode", "paper"]) == EXIT_BUDGET
    assert "on the command line, --boundary-threshold T sets options.boundary_threshold" \
        in caplog.text  # the budget message names the API's option
    assert len(read_points(out)) > 120
    assert not (tmp_path / "missing.ply").exists()
    assert main(["simplify", str(path), str(out)]) == EXIT_INPUT  # no --ratio, --count
    assert "or --max-spacing DISTANCE alone" in caplog.text  # (or --max-spacing)
    assert main(["run", str(path), str(tmp_path / "r.npy")]) == EXIT_INPUT  # nor for run
    assert "give --ratio R (a fraction of the points, in (0, 1]) or --count N" in caplog.text
    assert main(["simplify", str(path), str(tmp_path / "out.laz"), "--ratio", "0.5"]) \
        == EXIT_INPUT  # LAS/LAZ output is run's: said before any reading
    assert f"tiledsimplify run {path} {tmp_path / 'out.laz'} --ratio R" in caplog.text


def test_counts_read_as_whole_numbers_and_run_settings_are_checked(cloud, tmp_path, caplog,
                                                                    capsys):
    """``--count 3e2`` and ``3_00`` are 300; ``3.5`` is refused by the parser; workers and
    tile_points below 1 fail before the work naming the setting; tiny tiles warn."""
    X, path = cloud
    for text in ("3e2", "3_00"):
        out = tmp_path / f"c{text}.npy"
        assert main(["simplify", str(path), str(out), "--count", text, "-q"]) == EXIT_OK
        assert len(np.load(out)) == 300
    with pytest.raises(SystemExit):
        main(["simplify", str(path), str(out), "--count", "3.5"])
    assert "expected a whole number" in capsys.readouterr().err
    out = tmp_path / "r.npy"
    assert main(["run", str(path), str(out), "--count", "300", "--workers", "0"]) == EXIT_INPUT
    assert "workers must be at least 1" in caplog.text and not out.exists()
    assert main(["run", str(path), str(out), "--count", "300", "--tile-points", "0"]) \
        == EXIT_INPUT
    assert "tile_points must be at least 1" in caplog.text and not out.exists()
    caplog.clear()
    assert main(["run", str(path), str(out), "--count", "300", "--tile-points", "600",
                 "--no-progress"]) == EXIT_OK
    assert "cuts 1,200 points into about 2 tiles" in caplog.text and len(np.load(out)) == 300


def test_cli_evaluate(cloud, tmp_path, capsys, caplog, data_dir):
    import json
    X, path = cloud
    out = tmp_path / "k.xyz"
    assert main(["simplify", str(path), str(out), "--ratio", "0.3", "-q"]) == EXIT_OK
    capsys.readouterr()
    with caplog.at_level("WARNING", logger="tiledsimplify"):
        assert main(["evaluate", str(path), str(out), "--json"]) == EXIT_OK
        assert "swapped" not in caplog.text
        assert main(["evaluate", str(out), str(path), "--json"]) == EXIT_OK  # swapped: warned
    assert f"{path} holds more points (1,200) than {out} (360)" in caplog.text
    capsys.readouterr()
    assert main(["evaluate", str(path), str(out), "--json"]) == EXIT_OK
    got = json.loads(capsys.readouterr().out)
    from tiledsimplify import metrics
    ref = metrics.evaluate(X, read_points(out))
    assert got["n_kept"] == 360 and got["hausdorff"] == pytest.approx(ref["hausdorff"])
    # with a mesh: sharp-edge coverage; the original itself covers its edges fully
    mesh = data_dir / "meshes" / "trimesh_cad" / "angle_block.STL"
    from tiledsimplify import synthetic
    from tiledsimplify.io import read_mesh
    V, F = read_mesh(mesh)
    P, _ = synthetic.sample_surface_even(V, F, 3000, seed=0)
    pts = tmp_path / "block.npy"
    np.save(pts, P)
    assert main(["evaluate", str(pts), str(pts), "--mesh", str(mesh), "--json"]) == EXIT_OK
    got = json.loads(capsys.readouterr().out)
    assert got["edge_coverage"] > 0.95 and got["hausdorff"] == 0.0
    assert main(["evaluate", str(pts), str(tmp_path / "nope.xyz")]) == EXIT_INPUT


@pytest.mark.parametrize("suffix", [".npy", ".ply", ".csv"])
def test_evaluate_an_all_points_output_measures_its_kept_points(cloud, tmp_path, capsys,
                                                                 suffix):
    """``evaluate`` measured an ``--all-points`` output as if every point were kept:
    Hausdorff 0, n_kept the whole input. It reads the kept points from ``simplify_rank``
    (-1), as ``report`` does, and scores what the kept-only output scores."""
    import json
    _, path = cloud
    kept, every = tmp_path / f"k{suffix}", tmp_path / f"all{suffix}"
    assert main(["simplify", str(path), str(kept), "--ratio", "0.3", "-q"]) == EXIT_OK
    assert main(["simplify", str(path), str(every), "--ratio", "0.3", "--all-points",
                 "-q"]) == EXIT_OK
    capsys.readouterr()
    got = []
    for result in (kept, every):
        assert main(["evaluate", str(path), str(result), "--json", "-q"]) == EXIT_OK
        got.append(json.loads(capsys.readouterr().out))
    assert got[1]["n_kept"] == 360 and got[1]["hausdorff"] > 0
    assert got[1] == got[0]


def test_bad_output_fails_before_the_work(cloud, tmp_path, caplog, monkeypatch):
    """A missing output directory, a directory or an unknown suffix as the output is reported
    before any point is read or simplified (a long run must not fail only at the end)."""
    import importlib

    from tiledsimplify import cli
    run_mod = importlib.import_module("tiledsimplify.pipeline.run")  # the module, not run()

    _, path = cloud

    def no_work(*a, **k):
        raise AssertionError("the work started before the output was checked")

    monkeypatch.setattr(cli, "open_source", no_work)
    monkeypatch.setattr(cli, "read_all", no_work)
    monkeypatch.setattr(run_mod.TileStore, "create", no_work)
    missing = tmp_path / "no_such_dir" / "out.ply"
    for command in ("simplify", "run"):
        caplog.clear()
        assert main([command, str(path), str(missing), "--ratio", "0.5"]) == EXIT_INPUT
        assert "no_such_dir does not exist" in caplog.text
        caplog.clear()
        assert main([command, str(path), str(tmp_path), "--ratio", "0.5"]) == EXIT_INPUT
        assert "is a directory" in caplog.text
        caplog.clear()
        assert main([command, str(path), str(tmp_path / "out.foo"), "--ratio", "0.5"]) \
            == EXIT_INPUT
        assert "cannot write '.foo'" in caplog.text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.xyz"]


def test_empty_input_is_an_error(tmp_path, caplog):
    """A file with no points is reported (naming it), not simplified into an empty output."""
    empty = tmp_path / "empty.ply"  # a valid PLY with no vertices
    empty.write_text("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                     "property float y\nproperty float z\nend_header\n")
    for command in ("simplify", "run"):
        caplog.clear()
        out = tmp_path / f"out_{command}.ply"
        assert main([command, str(empty), str(out), "--ratio", "0.5"]) == EXIT_INPUT
        assert "empty.ply: the input has no points" in caplog.text
        assert not out.exists()


def test_a_corrupt_laz_is_reported_once(tmp_path, caplog):
    import laspy
    las = laspy.LasData(laspy.LasHeader(point_format=0, version="1.2"))
    xyz = np.random.default_rng(0).random((3000, 3))
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    good = tmp_path / "good.laz"
    las.write(good)
    bad = tmp_path / "cut.laz"
    bad.write_bytes(good.read_bytes()[:2000])
    with caplog.at_level("INFO"):
        assert main(["run", str(bad), str(tmp_path / "out.laz"), "--ratio", "0.5",
                     "--no-progress"]) == EXIT_INPUT
    errors = [r for r in caplog.records if r.levelname == "ERROR"]
    assert len(errors) == 1 and errors[0].name == "tiledsimplify"  # not laspy's own line too
    assert "cut.laz" in errors[0].getMessage() and "corrupt" in errors[0].getMessage()


def test_non_finite_points_are_named_by_file_and_row(cloud, tmp_path, caplog):
    X, path = cloud
    bad = X.copy()
    bad[7, 2] = np.inf
    nan_path = tmp_path / "holes.npy"
    np.save(nan_path, bad)
    with caplog.at_level("ERROR", logger="tiledsimplify"):
        assert main(["simplify", str(nan_path), str(tmp_path / "o.ply"), "--ratio", "0.5",
                     "-q"]) == EXIT_INPUT
        assert main(["evaluate", str(path), str(nan_path)]) == EXIT_INPUT
    assert caplog.text.count("holes.npy: point 7 has a NaN or infinite coordinate") == 2


def test_run_writes_a_json_summary_for_pipelines(cloud, tmp_path):
    import json
    X, path = cloud
    out, summary = tmp_path / "o.npy", tmp_path / "run.json"
    assert main(["run", str(path), str(out), "--ratio", "0.25", "--summary", str(summary),
                 "--no-progress", "-q"]) == EXIT_OK
    got = json.loads(summary.read_text())
    assert got["exit_code"] == EXIT_OK and got["input"] == str(path)
    assert got["n_input"] == len(X) and got["n_output"] == len(np.load(out)) == got["target"]
    assert got["seconds"]["total"] > 0 and not list(tmp_path.glob(".run.json.*"))
    import resource
    assert 50 < got["peak_rss_mb"] == pytest.approx(
        resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, rel=0.5)
    missing = tmp_path / "no_such_dir" / "run.json"
    assert main(["run", str(path), str(out), "--ratio", "0.25", "--summary", str(missing),
                 "-q"]) == EXIT_INPUT
    # the bound a --max-spacing run meets: with it alone the target is the count reached,
    # which the summary did not tell from a count asked for
    assert got["max_spacing"] is None
    assert main(["run", str(path), str(out), "--max-spacing", "0.25", "--summary",
                 str(summary), "-q"]) == EXIT_OK
    got = json.loads(summary.read_text())
    assert got["max_spacing"] == 0.25 and got["target"] == got["n_output"] == len(np.load(out))


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs Linux /proc")
def test_the_summarys_peak_memory_is_the_runs_not_its_parents(cloud, tmp_path):
    """A run started (fork and exec) by a process holding 600 MB reports its own peak, not
    the parent's: Linux folds the parent's size into ``ru_maxrss`` at exec, which the summary
    reported before (1,318 MB for a run whose own peak was 785 MB)."""
    import json
    import subprocess
    import sys
    _, path = cloud
    held = np.ones(75_000_000)  # 600 MB, touched: resident in this process at the fork
    summary = tmp_path / "run.json"
    subprocess.run([sys.executable, "-m", "tiledsimplify", "run", str(path),
                    str(tmp_path / "o.npy"), "--ratio", "0.25", "--summary", str(summary), "-q",
                    "--no-progress"], check=True)
    del held
    assert 50 < json.loads(summary.read_text())["peak_rss_mb"] < 450


def test_a_failed_run_still_writes_its_summary(tmp_path):
    import json

    from tiledsimplify import __version__
    summary, missing = tmp_path / "run.json", tmp_path / "none.xyz"
    assert main(["run", str(missing), str(tmp_path / "o.npy"), "--ratio", "0.25",
                 "--summary", str(summary), "-q"]) == EXIT_INPUT
    assert json.loads(summary.read_text()) == {
        "input": str(missing), "output": str(tmp_path / "o.npy"), "version": __version__,
        "exit_code": EXIT_INPUT, "error": f"{missing}: file not found. Check the path."}


@pytest.mark.parametrize("bad", [["--ratio", "0"], ["--ratio", "0.5", "--bogus"]])
def test_a_run_refused_by_its_arguments_still_writes_its_summary(tmp_path, bad):
    """A usage error (argparse's own, exit 2) left the summary of the run before in place —
    exit code 0 to a pipeline that reads the file."""
    import json

    summary = tmp_path / "run.json"
    summary.write_text(json.dumps({"exit_code": 0}))  # an earlier run's
    with pytest.raises(SystemExit) as stopped:
        main(["run", str(tmp_path / "in.laz"), str(tmp_path / "o.laz"), *bad,
              "--summary", str(summary)])
    assert stopped.value.code == EXIT_INPUT
    got = json.loads(summary.read_text())
    assert got["exit_code"] == EXIT_INPUT
    assert got["error"].startswith("tiledsimplify") and "error: " in got["error"]
    assert bad[-1] in got["error"]


def test_evaluate_an_empty_cloud_names_the_file(cloud, tmp_path, caplog):
    """It said "`kept` must contain at least 1 point(s); got 0. Fix: pass a non-empty point
    set." (the Python API's words), naming neither file nor side."""
    empty = tmp_path / "empty.xyz"
    empty.write_text("")
    assert main(["evaluate", str(cloud[1]), str(empty), "-q"]) == EXIT_INPUT
    assert "empty.xyz: the simplified cloud has no points" in caplog.text
    assert main(["evaluate", str(empty), str(cloud[1]), "-q"]) == EXIT_INPUT
    assert "empty.xyz: the original cloud has no points" in caplog.text


def test_an_unforeseen_failure_still_writes_its_summary(cloud, tmp_path, monkeypatch):
    """An error no handler foresaw (a bug, a dask error such as a lost scheduler's) keeps its
    traceback and exit code 1, and the summary says so: it was not written, so a pipeline read
    the summary of the run before, exit code 0, for a run that failed."""
    import json

    import tiledsimplify.pipeline
    _, path = cloud
    summary = tmp_path / "run.json"
    summary.write_text(json.dumps({"exit_code": 0}))  # an earlier run's

    def broken(*args, **kwargs):
        raise RuntimeError("something unforeseen")
    monkeypatch.setattr(tiledsimplify.pipeline, "run", broken)
    with pytest.raises(RuntimeError, match="something unforeseen"):
        main(["run", str(path), str(tmp_path / "o.npy"), "--ratio", "0.25",
              "--summary", str(summary), "-q"])
    got = json.loads(summary.read_text())
    assert got["exit_code"] == 1 and got["error"] == "unexpected error: RuntimeError: something unforeseen"


@pytest.mark.parametrize("name, resumable", [("SIGTERM", False), ("SIGINT", True)])
def test_a_stopped_run_cleans_up_says_how_to_go_on_and_resumes(tmp_path, name, resumable):
    """SIGTERM (a scheduler's timeout, a cancelled job) stops a run as Ctrl-C does: no output,
    no temporary store left, exit code 128 + the signal, a summary saying so; with --store,
    the same command then goes on from the finished tiles to the same output."""
    import json
    import os
    import signal
    import subprocess
    import sys

    from tiledsimplify.pipeline import run
    rng = np.random.default_rng(5)
    xy = rng.random((60_000, 2))
    path = tmp_path / "in.npy"
    np.save(path, np.c_[xy, 0.1 * np.sin(6 * xy[:, 0])])
    out, summary, store, tmp = (tmp_path / "o.npy", tmp_path / "run.json", tmp_path / "st.zarr",
                                tmp_path / "tmp")
    tmp.mkdir()
    # the command line as `tiledsimplify` runs it, with Ctrl-C's handler even where this
    # process was started with SIGINT ignored (a shell's background job)
    script = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
              "from tiledsimplify.cli import main; sys.exit(main(sys.argv[1:]))")
    cmd = [sys.executable, "-c", script, "run", str(path), str(out), "--ratio", "0.2",
           "--tile-points", "8000", "--workers", "1", "--summary", str(summary),
           "--no-progress"] + (["--store", str(store)] if resumable else [])
    sig = getattr(signal, name)
    p = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, env={**os.environ,
                         "TMPDIR": str(tmp)}, cwd=tmp_path)
    for line in p.stderr:  # the first of 8 tiles is done: 7 to go, and the refinement
        if " INFO tile " in line:
            p.send_signal(sig)
            break
    rest = p.stderr.read()
    assert p.wait(timeout=120) == 128 + sig, rest
    said = f"stopped by {name} after"
    assert said in rest and ("run the same command (same --store)" in rest) == resumable, rest
    got = json.loads(summary.read_text())
    assert got["exit_code"] == 128 + sig and got["error"].startswith(said)
    assert not out.exists() and list(tmp.iterdir()) == []  # no output, no temporary store
    assert store.exists() == resumable
    if resumable:
        assert main(["run", str(path), str(out), "--ratio", "0.2", "--tile-points", "8000",
                     "--workers", "1", "--store", str(store), "--no-progress", "-q"]) == EXIT_OK
        run(path, tmp_path / "whole.npy", ratio=0.2, tile_points=8000, workers=1)
        assert out.read_bytes() == (tmp_path / "whole.npy").read_bytes()


@pytest.mark.parametrize("command", ["simplify", "run"])
def test_a_stop_during_a_kernel_is_a_stop_not_a_bug(cloud, tmp_path, monkeypatch, caplog, command):
    """A signal that arrives while a numba kernel runs is handled when the kernel returns its
    arrays, and numba raises SystemError ("... returned a result with an exception set") from
    the handler's Stopped: still exit 128 + the signal and the stop's message (was exit 1 and
    a traceback; seen with SIGTERM/SIGHUP during simplify's Delaunay on 519k LAZ points)."""
    import json
    import signal

    import tiledsimplify.pipeline
    from tiledsimplify import cli

    def kernel_stopped(*args, **kwargs):
        try:
            raise cli.Stopped(signal.SIGHUP)
        except cli.Stopped as stop:
            raise SystemError("CPUDispatcher(<function _build>) returned a result with an "
                              "exception set") from stop
    monkeypatch.setattr(cli, "simplify_points", kernel_stopped)
    monkeypatch.setattr(tiledsimplify.pipeline, "run", kernel_stopped)
    _, path = cloud
    out, summary = tmp_path / "o.npy", tmp_path / "run.json"
    extra = ["--summary", str(summary)] if command == "run" else []
    assert main([command, str(path), str(out), "--ratio", "0.25", "-q"] + extra) == 129
    assert "stopped by SIGHUP after" in caplog.text and not out.exists()
    if command == "run":
        got = json.loads(summary.read_text())
        assert got["exit_code"] == 129 and got["error"].startswith("stopped by SIGHUP after")


def test_a_stop_signal_is_taken_once():
    # a second SIGTERM while the first one's clean-up runs is ignored, not a second exception
    import signal

    from tiledsimplify import cli
    before = {s: signal.getsignal(s) for s in cli.STOP_SIGNALS}
    try:
        with pytest.raises(cli.Stopped) as got:
            cli._stop(signal.SIGTERM, None)
        assert got.value.signum == signal.SIGTERM and str(got.value) == "SIGTERM"
        assert all(signal.getsignal(s) == signal.SIG_IGN for s in cli.STOP_SIGNALS)
    finally:
        for s, h in before.items():
            signal.signal(s, h)


@pytest.mark.parametrize("halo", ["-1", "nan", "inf"])
def test_a_bad_halo_is_named_with_its_default(cloud, tmp_path, caplog, halo):
    _, path = cloud
    with caplog.at_level("ERROR", logger="tiledsimplify"):
        assert main(["run", str(path), str(tmp_path / "o.npy"), "--ratio", "0.5", "--halo", halo,
                     "-q", "--no-progress"]) == EXIT_INPUT
    assert "halo must be a finite distance >= 0 in the input's units, got" in caplog.text
    assert "leave it out for the default (10 x the estimated spacing)" in caplog.text
    assert not (tmp_path / "o.npy").exists()


def test_evaluate_and_simplify_read_las_as_run_does(data_dir, tmp_path, capsys):
    """``evaluate`` and ``simplify`` read LAS/LAZ as ``run`` does (they refused it: "unsupported
    point file type '.laz'", though evaluate's help said any input format): the same numbers
    and the same kept points as from the same coordinates in NPY."""
    import json

    import laspy
    src = data_dir / "lidar" / "autzen_trim.laz"
    las = laspy.read(src)
    X = np.c_[las.x, las.y, las.z][:20000]
    small = tmp_path / "small.laz"
    out = laspy.LasData(las.header)
    out.points = las.points[:20000]
    out.write(small)
    np.save(tmp_path / "small.npy", X)
    assert main(["simplify", str(small), str(tmp_path / "a.npy"), "--ratio", "0.3", "-q"]) \
        == EXIT_OK
    assert main(["simplify", str(tmp_path / "small.npy"), str(tmp_path / "b.npy"), "--ratio",
                 "0.3", "-q"]) == EXIT_OK
    a, b = np.load(tmp_path / "a.npy"), np.load(tmp_path / "b.npy")
    assert len(a) == 6000 and len(b) == 6000
    for name in b.dtype.names:  # NaN importance: compare bytes
        assert a[name].tobytes() == b[name].tobytes(), name
    # and the LAS file's dimensions before the simplifier's columns
    dims = [d for d in las.point_format.dimension_names if d not in ("X", "Y", "Z")]
    assert a.dtype.names == b.dtype.names[:3] + tuple(dims) + b.dtype.names[3:]
    assert main(["run", str(small), str(tmp_path / "r.laz"), "--ratio", "0.3", "-q",
                 "--no-progress"]) == EXIT_OK
    kept = laspy.read(tmp_path / "r.laz")
    np.save(tmp_path / "r.npy", np.c_[kept.x, kept.y, kept.z])
    capsys.readouterr()
    got = []
    for original, result in [(small, tmp_path / "r.laz"),
                             (tmp_path / "small.npy", tmp_path / "r.npy")]:
        assert main(["evaluate", str(original), str(result), "--json"]) == EXIT_OK
        got.append(json.loads(capsys.readouterr().out))
    assert got[0] == got[1] and got[0]["n_kept"] == 6000 and got[0]["n_original"] == 20000
    assert type(got[0]["n_kept"]) is int and type(got[0]["n_original"]) is int  # not 6000.0


def test_a_folder_without_las_files_says_what_it_holds(tmp_path, caplog):
    """A folder is read as LAS/LAZ tiles; one of PLY files used to be reported as "file not
    found", which it is not: the message now says what the folder holds and what to do."""
    folder = tmp_path / "scans"
    folder.mkdir()
    (folder / "notes.txt").write_text("scan log")
    for name in ("a.ply", "b.ply"):
        write_points(folder / name, np.random.default_rng(0).random((50, 3)))
    with caplog.at_level("ERROR", logger="tiledsimplify"):
        assert main(["run", str(folder), str(tmp_path / "o.ply"), "--ratio", "0.5", "-q",
                     "--no-progress"]) == EXIT_INPUT
    assert f"no .las/.laz files in folder {folder} (it holds 3 other file(s), e.g. a.ply: a " \
        "folder is read as LAS/LAZ tiles; give one file of another format" in caplog.text
    assert "file not found" not in caplog.text


def _roof(tmp_path, fold):
    """8,000 points of a roof folding by ``fold`` degrees along x = 0, saved as roof.npy."""
    rng = np.random.default_rng(6)
    xy = rng.random((8000, 2)) * 2 - 1
    X = np.c_[xy, -np.tan(np.deg2rad(fold / 2)) * np.abs(xy[:, 0])]
    path = tmp_path / "roof.npy"
    np.save(path, X)
    return path


def _refused(caplog, command, path, out, ratio, flag, value, message):
    """``command`` with ``flag value`` fails before any work (exit 2), naming the option."""
    with caplog.at_level("ERROR", logger="tiledsimplify"):
        assert main([command, str(path), str(out), "--ratio", ratio, "-q", flag, value]) \
            == EXIT_INPUT
    assert message in caplog.text
    assert not out.exists()


def test_edge_angle_reaches_both_commands(tmp_path, caplog):
    """``--edge-angle``: a 35° ridge is flagged at 30 and not at the default 40, by simplify
    and by run; a value outside (0, 90] fails before any work, naming the option."""
    path = _roof(tmp_path, 35.0)
    for command in ("simplify", "run"):
        flagged = {}
        for angle in (None, "30"):
            out = tmp_path / f"{command}_{angle}.npy"
            extra = [] if angle is None else ["--edge-angle", angle]
            assert main([command, str(path), str(out), "--ratio", "0.3", "-q", *extra]) \
                == EXIT_OK
            flagged[angle] = int(np.load(out)["sharp_edge"].sum())
        assert flagged[None] == 0 and flagged["30"] > 10, (command, flagged)
        _refused(caplog, command, path, tmp_path / f"{command}_bad.npy", "0.3", "--edge-angle",
                 "95", "options.edge_angle must be a fold in degrees")


def test_edge_share_reaches_both_commands(tmp_path, caplog):
    """``--edge-share``: on a roof whose ridge flags more points than a 0.5 % count, the default
    keeps the count (exit 0) with some flagged points; ``inf`` keeps every feature point (most
    of them flagged) and misses it (exit 3); a share outside (0, 1] fails before any work, naming the option."""
    path = _roof(tmp_path, 90.0)
    for command in ("simplify", "run"):
        got = {}
        for share, code in ((None, EXIT_OK), ("inf", EXIT_BUDGET)):
            out = tmp_path / f"{command}_{share}.npy"
            extra = [] if share is None else ["--edge-share", share]
            assert main([command, str(path), str(out), "--ratio", "0.005", "-q", *extra]) \
                == code, (command, share)
            got[share] = np.load(out)
        assert len(got[None]) == 40 and 0 < got[None]["sharp_edge"].sum() <= 16, command
        # every feature point kept: the flagged ones and the band's few a little farther
        assert len(got["inf"]) > 40 and got["inf"]["sharp_edge"].sum() >= 0.8 * len(got["inf"])
        _refused(caplog, command, path, tmp_path / f"{command}_bad.npy", "0.005",
                 "--edge-share", "2", "options.edge_share must be a share of the count")


def test_max_spacing_reaches_both_commands(cloud, tmp_path, caplog, capsys):
    """``--max-spacing D``: no input point is left farther than D from a kept one, by simplify
    and by run (more than the count is kept: exit 3, with the flag in the advice); alone, the
    same points and exit 0; a distance that is not positive is refused by the parser."""
    from scipy.spatial import cKDTree
    X, path = cloud
    limit = 0.25
    for command in ("simplify", "run"):
        out = tmp_path / f"{command}.npy"
        caplog.clear()
        assert main([command, str(path), str(out), "--ratio", "0.01", "--max-spacing",
                     str(limit), "--no-boundary" if command == "simplify" else "-q"]) \
            == EXIT_BUDGET
        K = np.load(out)
        assert len(K) > 12 and cKDTree(np.c_[K["x"], K["y"], K["z"]]).query(X)[0].max() <= limit
        assert "--max-spacing DISTANCE options.max_spacing" in caplog.text
        with pytest.raises(SystemExit):
            main([command, str(path), str(out), "--ratio", "0.01", "--max-spacing", "0"])
        assert "expected a positive distance" in capsys.readouterr().err
        # alone: as few points as the limit allows, and that is the count asked for
        alone = tmp_path / f"{command}_alone.npy"
        assert main([command, str(path), str(alone), "--max-spacing", str(limit),
                     "--no-boundary" if command == "simplify" else "-q"]) == EXIT_OK
        A = np.load(alone)
        for name in ("x", "y", "z", "sharp_edge"):
            np.testing.assert_array_equal(A[name], K[name])
        caplog.clear()
        assert main([command, str(path), str(alone), "-q"]) == EXIT_INPUT
        assert "or --max-spacing DISTANCE alone" in caplog.text


def test_a_config_max_spacing_without_its_guard_says_so(cloud, tmp_path, caplog):
    """A config with ``max_spacing`` but no ``guard = "max_spacing"`` (one of the presets'
    two commented lines switched on) ran without the bound, or, with no ratio, was told to
    give --ratio; it is refused naming the file and the missing line."""
    _, path = cloud
    for run_table in ("", "[run]\nratio = 0.1\n"):
        cfg = tmp_path / "c.toml"
        cfg.write_text(run_table + "[simplify]\nmax_spacing = 0.25\n")
        caplog.clear()
        with caplog.at_level("ERROR", logger="tiledsimplify"):
            assert main(["run", str(path), str(tmp_path / "o.npy"), "--config", str(cfg),
                         "-q"]) == EXIT_INPUT
        assert (f"{cfg}: [simplify] options.max_spacing=0.25 is a bound only with "
                "options.guard='max_spacing'") in caplog.text
        assert not (tmp_path / "o.npy").exists()


@pytest.mark.parametrize("command, said, not_said", [
    ("report", "6 x dpi pixels on its longer side", "square"),  # panels follow the view
    ("simplify", "0.08 rad on the two-ring measure in coverage", "(default: automatic)"),
])
def test_help_says_the_defaults_the_readme_gives(capsys, command, said, not_said):
    """`--help` agrees with the README: a report panel is 6 in on its longer side, shaped as
    the view within 3:1 (it said "square"); --boundary-threshold's default is the mode's,
    0.08 rad in the default mode (it said "automatic", true of mode paper only)."""
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert said in text and not_said not in text


@pytest.mark.parametrize("preset", sorted((Path(__file__).resolve().parents[1]
                                           / "configs").glob("*.toml")))
def test_presets_load_with_and_without_their_commented_options(preset, tmp_path):
    """Every preset in configs/ is valid as shipped, and with its commented-out options
    (``# key = value`` lines) switched on: a typo there would fail only on a user's run."""
    from tiledsimplify.cli import RUN_KEYS, _load_config
    from tiledsimplify.core import SimplifyOptions
    on = tmp_path / preset.name
    on.write_text("".join(line[2:] if line.startswith("# ") and " = " in line else line
                          for line in preset.read_text().splitlines(keepends=True)))
    for path in (preset, on):
        run_cfg, simplify_cfg = _load_config(path)
        assert set(run_cfg) <= set(RUN_KEYS) and run_cfg
        SimplifyOptions.from_mapping(simplify_cfg)
    assert SimplifyOptions.from_mapping(_load_config(on)[1]).guard == "max_spacing"


def test_no_edges_on_from_the_flag_and_the_config(tmp_path, monkeypatch):
    """``--no-edges-on 3,4,5`` and ``[run] no_edge_classes`` reach ``run`` as codes (the flag
    wins); bad codes are refused by the parser and by the config's check."""
    from tiledsimplify import cli
    import tiledsimplify.pipeline as pipeline
    got = []

    def fake_run(*args, **kwargs):
        got.append(kwargs["no_edge_classes"])
        raise SystemExit(0)
    monkeypatch.setattr(pipeline, "run", fake_run)
    cfg = tmp_path / "c.toml"
    cfg.write_text("[run]\nratio = 0.2\nno_edge_classes = [7, 18]\n")
    for argv, want in [(["--ratio", "0.2", "--no-edges-on", "3,4, 5"], [3, 4, 5]),
                       (["--config", str(cfg)], [7, 18]),
                       (["--config", str(cfg), "--no-edges-on", "2"], [2]),
                       (["--ratio", "0.2"], None)]:
        with pytest.raises(SystemExit):
            cli.main(["run", "in.laz", "out.laz", *argv])
        assert got.pop() == want, argv
    with pytest.raises(SystemExit) as exc:
        cli.main(["run", "in.laz", "out.laz", "--ratio", "0.2", "--no-edges-on", "trees"])
    assert exc.value.code == 2
    cfg.write_text("[run]\nratio = 0.2\nno_edge_classes = 3\n")
    assert cli.main(["run", "in.laz", "out.laz", "--config", str(cfg)]) != 0


def test_simplify_no_edges_on_classes(data_dir, tmp_path):
    """The in-memory command takes ``--no-edges-on`` too: no point of those classes flagged
    (some are without it), the count the same; refused for an input without classes."""
    import laspy
    from tiledsimplify import cli
    src = laspy.read(data_dir / "lidar" / "las_with_several_extra_byte_bloc.laz")
    veg = np.isin(np.asarray(src.classification), [3, 4, 5])
    c = np.c_[src.x, src.y][veg].mean(axis=0)
    near = np.argsort(np.hypot(src.x - c[0], src.y - c[1]))[:15_000]
    las = laspy.LasData(src.header)
    las.points = src.points[np.sort(near)]
    las.write(tmp_path / "in.laz")
    got = {}
    for name, extra in (("all", []), ("veg", ["--no-edges-on", "3,4,5"])):
        assert cli.main(["simplify", str(tmp_path / "in.laz"), str(tmp_path / f"{name}.npy"),
                         "--ratio", "0.2", "-q", *extra]) == 0
        got[name] = np.load(tmp_path / f"{name}.npy")
    for name, out in got.items():
        v = np.isin(out["classification"], [3, 4, 5])
        flagged = int(out["sharp_edge"][v].sum())
        assert (flagged == 0) if name == "veg" else (flagged > 10), (name, flagged)
    assert len(got["all"]) == len(got["veg"])
    np.save(tmp_path / "xyz.npy", np.c_[las.x, las.y, las.z])
    assert cli.main(["simplify", str(tmp_path / "xyz.npy"), str(tmp_path / "o.npy"),
                     "--ratio", "0.2", "--no-edges-on", "3"]) != 0
