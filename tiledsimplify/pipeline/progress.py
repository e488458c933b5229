"""Progress of a run's long stages: a log line per finished task (a tile simplified, refined,
its deviations counted) with the share of points done and the time left at that pace
(:class:`Progress`, a dask callback, and the lines :func:`tile_line`, :func:`refine_line`,
:func:`threshold_line`), the ingest's two passes (:class:`IngestProgress`) and the output's
points written (:class:`Written`); on a terminal a bar below the lines."""

import logging
import sys
import time

log = logging.getLogger("tiledsimplify")


class Progress:
    """Per-task progress of one stage: a log line per finished tile (from the calling
    process, so it is not lost in worker processes) and, on a terminal or in a notebook, a bar
    redrawn below the log lines (not in log files: cron and Airflow logs get the lines only)."""

    def __init__(self, stage, total, describe, bar, out=None, unit="tiles", points=None):
        self.stage, self.total, self.describe, self.unit = stage, total, describe, unit
        self.points_total, self.points = points, 0
        self.out = sys.stderr if out is None else out
        interactive = "ipykernel" in sys.modules or (
            hasattr(self.out, "isatty") and self.out.isatty())
        self.bar = bool(bar) and interactive
        self.done = 0
        self.t0 = time.perf_counter()

    def __call__(self, result):
        self.done += 1
        if isinstance(result, dict):
            self.points += result.get("n_core", 0)
        if self.bar:
            self.out.write("\r\033[K")
        if self.describe is not None:
            self.describe(result, self.done, self.total, self.pace())
        if self.bar:
            self.draw()

    def pace(self):
        """``"; 12 % of points in 3.2 min, ~23 min left"`` for a log line: the share of the
        stage's points in the tiles done so far, and the time left at that rate (by points, not
        tiles: the largest tiles run first, so a count of tiles would overstate the time left);
        empty when the stage's points are not known."""
        if not self.points_total or not self.points:
            return ""
        frac = min(self.points / self.points_total, 1.0)
        elapsed = time.perf_counter() - self.t0
        left = f", ~{duration(elapsed * (1 - frac) / frac)} left" if frac < 1 else ""
        return f"; {100 * frac:.0f} % of points in {duration(elapsed)}{left}"

    def draw(self):
        frac = self.done / self.total if self.total else 1.0
        elapsed = time.perf_counter() - self.t0
        left = elapsed * (1 - frac) / frac if frac else float("nan")
        width = 30
        fill = int(round(width * frac))
        self.out.write(f"\r{self.stage} [{'#' * fill}{' ' * (width - fill)}] {self.done:,}/"
                       f"{self.total:,} {self.unit} {100 * frac:3.0f}% | {elapsed:.0f} s"
                       + (f", ~{left:.0f} s left" if 0 < frac < 1 else ""))
        self.out.flush()

    def close(self):
        if self.bar:
            self.out.write("\n")
            self.out.flush()


#: the output stage logs its progress (every tenth of the kept points written) only once it
#: has run this long: a short one stays one line in the run's summary
OUTPUT_QUIET = 10.0


class Written:
    """The output stage's progress: ``written(points so far)`` logs a line at every tenth of
    the ``total`` kept points, once it has run :data:`OUTPUT_QUIET` seconds (writing 200M kept
    points of a billion takes minutes, with no task per point to count); ``verb`` says what
    was done to them (text outputs are formatted at the end, ~5 µs a point)."""

    def __init__(self, total, verb="written"):
        self.total, self.verb, self.tenths, self.t0 = int(total), verb, 0, time.perf_counter()

    def __call__(self, done):
        tenths = 10 * done // self.total if self.total else 10
        if tenths <= self.tenths:
            return
        elapsed = time.perf_counter() - self.t0
        if elapsed < OUTPUT_QUIET:
            return
        self.tenths = tenths
        frac = done / self.total if self.total else 1.0
        left = f", ~{duration(elapsed * (1 - frac) / frac)} left" if 0 < frac < 1 else ""
        log.info("output: %d %% (%s of %s points) %s in %s%s", 100 * frac, f"{done:,}",
                 f"{self.total:,}", self.verb, duration(elapsed), left)


def duration(seconds):
    """``41 s``, ``12.3 min`` or ``2.1 h``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


class IngestProgress:
    """``TileStore.create``'s ``progress(pass, points)``: a log line at every tenth of each of
    its two passes over the input (100M points took 90 s) and, on a terminal, a bar."""

    PASSES = {1: "bounds and sample", 2: "points to tiles"}

    def __init__(self, n, bar, out=None):
        self.n, self.bar, self.out = n, bar, out
        self.report, self.pass_number, self.tenths = None, None, 0

    def __call__(self, pass_number, points):
        if pass_number != self.pass_number:
            # between the passes: the plan and the store's layout (5 s at 100M points)
            gap = None if self.report is None else time.perf_counter() - self.report.last
            self.close()
            if gap is not None:
                log.info("ingest: tiles planned and the store laid out in %.1f s (spacing and "
                         "kd split from the sample, a zarr group a tile)", gap)
            self.report = Progress(f"ingest {pass_number}/2", self.n, None, self.bar,
                                    out=self.out, unit="points")
            self.pass_number, self.tenths = pass_number, 0
        r = self.report
        r.done = points
        r.last = time.perf_counter()
        tenths = 10 * points // self.n if self.n else 10
        if tenths > self.tenths:
            self.tenths = tenths
            if r.bar:
                r.out.write("\r\033[K")
            log.info("ingest pass %d of 2 (%s): %d %% (%s of %s points) in %.1f s",
                     pass_number, self.PASSES[pass_number], 100 * points // max(self.n, 1),
                     f"{points:,}", f"{self.n:,}", time.perf_counter() - r.t0)
        if r.bar:
            r.draw()

    def close(self):
        if self.report is not None:
            self.report.close()
            self.report = None


def tile_line(result, done, total, pace=""):
    log.info("tile %d (%d/%d): %d core + %d halo points, %d boundary, %d removals%s, %.1f s%s",
             result["tile"], done, total, result["n_core"], result["n_halo"],
             result["n_boundary"], result["steps"],
             " (all)" if result["exhausted"] else f" (up to level {result['level']:.3g})",
             result["seconds"], pace)


def refine_line(result, done, total, pace=""):
    if result["beyond"]:
        log.info("tile %d (%d/%d): its gap under the cut, or an earlier neighbour's, lies "
                 "beyond the halo; refined once the cut's gaps are measured%s",
                 result["tile"], done, total, pace)
        return
    log.info("refined tile %d (%d/%d): %d core + %d halo points, %d kept fixed, %d swaps, "
             "Hausdorff %.4g -> %.4g, %.1f s%s", result["tile"], done, total,
             result["n_core"], result["n_halo"], result["n_fixed"], result["swaps"],
             result["hausdorff_before"], result["hausdorff_after"], result["seconds"], pace)


def threshold_line(result, done, total, pace=""):
    log.info("neighbourhoods of tile %d (%d/%d): %d points in %.1f s%s", result["tile"], done,
             total, result["n_points"], result["seconds"], pace)
