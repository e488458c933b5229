"""What a run checks of its output before the work, so that it fails in seconds, not hours in:
room on disk for the output and the tile store (:func:`check_room`), a LAS/LAZ layout and grid
the writer can take (:func:`check_layout`, :func:`check_grid`), the distance a ``max_spacing``
guard works to on the output's grid (:func:`guard_limit`), and warnings of an output the input
would read back, of a killed run's leftovers and of points moved to another grid."""

import logging
import os
import tempfile
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import points_out
from ..io.las import LAS_SUFFIXES
from ..io.points_out import check_space, record_bytes
from .output import OUTPUT_COLUMNS

log = logging.getLogger("tiledsimplify")


def is_empty_dir(path):
    return path.is_dir() and not any(path.iterdir())


#: bytes a new tile store takes on disk per input point, at least: its compressed
#: coordinates, input indices and per-point results took 43 B a point for the 1M scan of
#: ``benchmarks/pipeline_speed.py`` and lone-star.laz, 51 B for autzen_trim.laz
STORE_BYTES = 20


def warn_read_back(input, output, source):
    """Warn when the output goes where the input names its files (a folder or pattern of
    LAS/LAZ tiles): a later run on the same input would read it as one more tile; and when
    it is named as a COPC file, which it is not."""
    if output.name.lower().endswith(".copc.laz"):
        log.warning("%s: written as a plain LAZ file, not as COPC (no octree); name it "
                    "*.laz, or make COPC from it with `pdal translate %s out.copc.laz`.",
                    output, output.name)
    if source.is_las:
        from ..io.las import lists_path
        if lists_path(input, output):  # (an input file itself: refused before)
            log.warning("%s: the output goes where the input %s names its files; a later run "
                        "on the same input will read it as one more input file. Write it to "
                        "another folder.", output, input)


def warn_leftovers(output):
    """Warn of the temporary files a killed run writing ``output`` left beside it: the
    output's ``.NAME.*.partial`` and a text output's ``.NAME.*.records`` are removed when a run
    fails or is stopped, but not after SIGKILL (the OOM killer, a batch system past its grace
    period), and a rerun wrote new ones beside them: a killed run's kept points, whole, per
    file. Not deleted here: another run may be writing the same output."""
    try:
        left = sorted(p for pattern in (f".{output.name}.*.partial", f".{output.name}.*.records")
                      for p in output.parent.glob(pattern) if p.is_file())
    except OSError:
        return
    if left:
        size = sum(p.stat().st_size for p in left)
        log.warning("%s: %d temporary file(s) of an earlier run that was killed while writing "
                    "it take %.1f MB beside it (%s); delete them unless another run is writing "
                    "%s now.", output, len(left), size / 1e6, ", ".join(p.name for p in left),
                    output.name)


def warn_regrid(output, source):
    """Warn when a LAS/LAZ output moves points of input files on another grid than the
    first file's, which it takes (:func:`regrids`): a file of finer scales, or offsets off
    the first file's steps, has its kept points rounded to that grid — up to half a step on
    each axis — where a folder merging two deliveries lost their precision silently."""
    if output.suffix.lower() not in LAS_SUFFIXES or not source.is_las:
        return
    steps, origin = source.scales, source.offsets
    moved = _off_grid_files(source)
    if moved:
        log.warning(
            "%s: %d input file(s) are on another grid than the first file's (%s: scales %s, "
            "offsets %s), which the output takes: their kept points move by up to half a step "
            "on each axis (%s: scales %s, offsets %s%s). Give the files one scale and offset "
            "first (e.g. `pdal translate in.laz out.laz --writers.las.scale_x=… "
            "--writers.las.offset_x=…`).", output, len(moved), source.infos[0].path.name,
            steps.tolist(), origin.tolist(), moved[0].path.name,
            np.asarray(moved[0].scales).tolist(), np.asarray(moved[0].offsets).tolist(),
            "" if len(moved) == 1 else f"; and {len(moved) - 1} more")


def check_layout(output, source, per_file=False):
    """Refuse now, not after the work, a LAS/LAZ output the writer would refuse at the end:
    input files of different point formats or dimensions (no one layout holds them), or an
    input dimension that clashes with one the output adds (:func:`.las_output.output_header`).
    ``per_file``: one output per input file (:mod:`.per_file`), each of its file's header —
    files that count ``gps_time`` differently are then no error."""
    if output.suffix.lower() in LAS_SUFFIXES and source.is_las:
        from ..io.las_output import output_header
        template = source.file_header(0) if per_file else source.template_header()
        output_header(template, path=output)


def check_grid(output, source, ts):
    """After the ingest, before the tiles: refuse a LAS/LAZ output whose grid (the first
    file's scales and offsets) cannot hold the input's coordinates — files far apart with
    their own offsets. The bounds are those the ingest read from the points (headers' bounds
    may be wrong or zero). For a non-LAS input, whose dimensions are known only now, refuse
    a layout LAS cannot hold (:func:`.las_output.output_header`: too many dimensions)."""
    if output.suffix.lower() in LAS_SUFFIXES and not source.is_las:
        from ..io.las_output import output_header
        from .output import new_las_header
        output_header(new_las_header(ts)[0], path=output)
    if output.suffix.lower() in LAS_SUFFIXES and source.is_las:
        from ..io.las_pieces import fits_grid, off_grid
        lo, hi = ts.root_attrs["bounds"]
        if not fits_grid(lo, hi, source.scales, source.offsets):  # the template's
            raise off_grid(output, lo, hi, source.scales, source.offsets)


def _off_grid_files(source):
    """The files of a LAS ``source`` whose points the first file's grid (the output's) moves
    by up to half a step: finer scales, or offsets off its steps (a coarser multiple at whole
    steps moves them by rounding only)."""
    steps, origin = source.scales, source.offsets
    moved = []
    for info in source.infos[1:]:
        ratio = np.asarray(info.scales, dtype=np.float64) / steps
        shift = (np.asarray(info.offsets, dtype=np.float64) - origin) / steps
        if not (np.allclose(ratio, np.round(ratio), rtol=0, atol=1e-6) and np.all(ratio >= 1)
                and np.allclose(shift, np.round(shift), rtol=0, atol=1e-6)):
            moved.append(info)
    return moved


def regrids(output, source):
    """Whether the output puts the kept points on a grid they were not read from: a LAS/LAZ
    output of a non-LAS input, or of LAS files on other scales or offsets than the first's
    (whose grid the output takes); a LAS input's records are otherwise kept as read. Stricter
    than :func:`_off_grid_files` (which warns of visible moves): a file on a coarser multiple
    of the grid is re-quantised too, and its points move by rounding — what the guard's bound
    (:func:`guard_limit`) must allow for."""
    if output.suffix.lower() not in LAS_SUFFIXES:
        return False
    return not source.is_las or not all(
        np.array_equal(i.scales, source.scales) and np.array_equal(i.offsets, source.offsets)
        for i in source.infos)


def guard_limit(limit, output, source, ts):
    """The distance the tiles' ``max_spacing`` guard works to: ``limit``, less the most a
    LAS/LAZ output's quantisation moves a kept point where it puts points on a grid they
    were not read from — a non-LAS input (:func:`.las_output.new_header`: a thousandth of the
    spacing) or LAS files on other scales or offsets than the first's, whose grid the output
    takes. Half a step on each axis, and the rounding of ``X * scale + offset`` read back:
    the points of the file then still lie within ``limit`` of every input point (on the
    Bunny at 2 spacings, 2 points were 2.4e-7 beyond it, the step 1e-6). A limit that
    move alone could break is refused."""
    if not regrids(output, source):
        return limit
    lo, hi = (np.asarray(b, dtype=np.float64) for b in ts.root_attrs["bounds"])
    if source.is_las:
        scales = source.scales
    else:
        from ..io.las_output import new_header
        scales = np.asarray(new_header(lo, hi, ts.spacing).scales, dtype=np.float64)
    move = float(0.5 * np.linalg.norm(scales)
                 + 4 * np.linalg.norm(np.spacing(np.maximum(np.abs(lo), np.abs(hi)))))
    if not limit > move:
        raise InputError(
            f"{output}: --max-spacing {limit:g} (options.max_spacing) is within what the LAS "
            f"output's grid (scales {scales.tolist()}) moves a kept point ({move:.3g}); write "
            ".ply, .npy, .xyz or .csv (coordinates as read), or give a larger distance.")
    log.info("the max_spacing guard works to %.9g: the LAS output's grid moves a kept point "
             "by up to %.3g", limit - move, move)
    return limit - move


def check_room(output, output_bytes, store, n):
    """Refuse now, not hours in, if the output's directory or a new tile store's (the
    temporary directory by default) cannot hold a lower bound of what they will take; on
    one file system, of both."""
    check_space(output, output_bytes)
    if store is not None and Path(store).exists() and not is_empty_dir(Path(store)):
        return  # a resumed store: already (mostly) written
    at = Path(store) if store is not None else Path(tempfile.gettempdir()) / "store"
    need = n * STORE_BYTES
    same = os.stat(points_out.existing_parent(at)).st_dev == os.stat(
        points_out.existing_parent(output)).st_dev
    what = f"the {'' if store is not None else 'temporary '}tile store of {n:,} points"
    if same:
        need += output_bytes
        what += " (with the output, on the same file system)"
    fix = ("give --store a directory with room" if store is not None else
           "set TMPDIR (or give --store) to a directory with room")
    check_space(at, need, what, fix, name=None if store is not None else at.parent)


def bytes_per_point(output, source):
    """A lower bound of the output's bytes per kept point: its record (LAS: the input's
    point record, before compression — none is assumed for LAZ)."""
    suffix = output.suffix.lower()
    if suffix == ".laz":
        return 0
    if suffix in LAS_SUFFIXES:  # a non-LAS input gets point format 6 (30 bytes) and 17 more
        return source.template_header().point_format.size if source.is_las else 30 + 17
    return record_bytes(OUTPUT_COLUMNS)
