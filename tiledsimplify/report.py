"""A visual report of one simplification: figures like the paper's Figs. 2-3 and the metrics.

``tiledsimplify report INPUT RESULT -o DIR`` writes

* ``original.png``   the input cloud;
* ``boundary.png``   the input with the points flagged on sharp edges (``sharp_edge``) in red;
* ``simplified.png`` the kept points (flagged ones in red);
* ``overview.png``   the three side by side (the paper's (a), (b), (c));
* ``report.md``      counts and the quality measures of :func:`tiledsimplify.metrics.evaluate`;
* ``metrics.json``   the same numbers at full precision.

The clouds are drawn with matplotlib as an orthographic view, far points first so that near
ones cover them, shaded darker towards the viewer; huge inputs are subsampled for drawing only
(``max_plot_points``). matplotlib is an optional dependency: ``pip install
tiledsimplify[report]``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from .errors import TiledSimplifyError
from .io.columns import read_columns
from .io.sources import check_finite, read_xyz

PANEL_INCHES = 6.0
DPI = 150
BOUNDARY_COLOUR = "#d62728"  # red, against grey points
FIGURES = ("original", "boundary", "simplified", "overview")

#: metric key -> (label, is a distance normalised by the bounding-box diagonal)
METRIC_LABELS = {
    "n_original": ("original points", False),
    "n_kept": ("kept points", False),
    "surface_error_mean": ("mean surface error (Pauly et al. 2002)", True),
    "surface_error_max": ("max surface error", True),
    "hausdorff": ("Hausdorff, original -> kept", True),
    "hausdorff_model_units": ("Hausdorff in the input's units (what --max-spacing bounds)",
                              False),
    "diagonal": ("bounding-box diagonal, input's units", False),
    "chamfer": ("Chamfer", True),
    "edge_coverage": ("sharp-edge coverage (1.5 spacings)", False),
    "boundary_precision": ("boundary precision", False),
    "boundary_recall": ("boundary recall", False),
    "boundary_f1": ("boundary F1", False),
    "adaptivity": ("adaptivity (kept fraction curved / flat)", False),
}


class MissingDependencyError(TiledSimplifyError, ImportError):
    """An optional dependency needed for this feature is not installed."""


def _pyplot():
    try:
        import matplotlib
        matplotlib.use("Agg", force=True)
        import matplotlib.pyplot as plt
    except ImportError:
        raise MissingDependencyError(
            "the report draws its figures with matplotlib, which is not installed. "
            "Fix: pip install 'tiledsimplify[report]' (or pip install matplotlib).") from None
    return plt


@dataclass
class Report:
    """What :func:`make_report` wrote and measured."""

    directory: Path
    files: dict[str, Path]
    metrics: dict[str, float]
    n_input: int
    n_kept: int
    n_boundary: int | None
    subset: bool
    notes: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------------------------
# reading and matching
# ---------------------------------------------------------------------------------------------


def _read_input(path):
    xyz, src = read_xyz(path)
    if not len(xyz):
        raise TiledSimplifyError(f"{path}: the input has no points; nothing to report.")
    return xyz, src.is_las


def _match(original, kept_xyz):
    """Index into ``original`` of every kept point, or None if they are not a subset.

    Exact duplicates are matched to distinct copies.
    """
    diag = float(np.linalg.norm(original.max(0) - original.min(0))) or 1.0
    tol = 1e-9 * diag
    tree = cKDTree(original)
    k = min(8, len(original))
    d, idx = tree.query(kept_xyz, k=k)
    d, idx = d.reshape(len(kept_xyz), k), idx.reshape(len(kept_xyz), k)
    if np.any(d[:, 0] > tol):
        return None
    out = idx[:, 0].copy()
    used = np.zeros(len(original), bool)
    order = np.argsort(out, kind="stable")
    dup = np.zeros(len(out), bool)
    dup[order[1:]] = out[order[1:]] == out[order[:-1]]
    used[out[~dup]] = True
    for i in np.flatnonzero(dup):  # a kept copy of a duplicated input point
        free = [j for j, dj in zip(idx[i], d[i]) if dj <= tol and not used[j]]
        if not free:
            return None
        out[i] = free[0]
        used[free[0]] = True
    return out


def _resolve(original, result_xyz, cols):
    """(kept mask or None, kept points, boundary mask over the original or None, notes)."""
    notes = []
    n = len(original)
    flags = cols.get("sharp_edge")
    rank = cols.get("simplify_rank")
    if rank is not None and len(result_xyz) == n and np.array_equal(result_xyz, original):
        keep = np.asarray(rank) == -1  # an --all-points output: every point with its rank
        boundary = np.asarray(flags).astype(bool) if flags is not None else None
        return keep, original[keep], boundary, notes
    idx = _match(original, result_xyz)
    if idx is None:
        notes.append("The result's points are not all input points (another tool, or a "
                     "different input): measured on the result's own coordinates; adaptivity "
                     "needs a subset.")
        boundary = None
        if flags is not None:
            notes.append("sharp_edge flags are shown on the result's points only.")
        return None, result_xyz, boundary, notes
    keep = np.zeros(n, bool)
    keep[idx] = True
    boundary = None
    if flags is not None:
        boundary = np.zeros(n, bool)
        boundary[idx[np.asarray(flags).astype(bool)]] = True
        if len(result_xyz) < n:  # flagged points the count did not keep are not in the file
            notes.append("sharp_edge flags are the kept points' only: flagged points the "
                         "count did not keep (where the flags are more than edge_share of the "
                         "count, or those off the edge line that the gap refinement traded "
                         "for fills) are not in the result, and boundary recall counts the "
                         "kept ones; `tiledsimplify simplify --all-points` writes every "
                         "point's flag.")
    return keep, original[keep], boundary, notes


# ---------------------------------------------------------------------------------------------
# drawing
# ---------------------------------------------------------------------------------------------


def view_rotation(up="z", elev=20.0, azim=-60.0):
    """3x3 rotation: rows are screen-right, screen-up and towards-the-viewer, in model axes.

    ``up`` is the model axis drawn upwards; the camera sits ``elev`` degrees above the
    horizontal plane, ``azim`` degrees around ``up`` (matplotlib's convention).
    """
    axes = {"x": 0, "y": 1, "z": 2}
    if up not in axes:
        raise TiledSimplifyError(f"up must be one of x, y, z; got {up!r}.")
    u = np.zeros(3)
    u[axes[up]] = 1.0
    a = np.roll(np.eye(3), -(axes[up] + 1), axis=0)[:2]  # the two horizontal axes, cyclic
    e, z = math.radians(elev), math.radians(azim)
    towards = (math.cos(e) * (math.cos(z) * a[0] + math.sin(z) * a[1])) + math.sin(e) * u
    right = np.cross(u, towards)
    right /= np.linalg.norm(right)
    screen_up = np.cross(towards, right)
    return np.vstack([right, screen_up, towards])


def _marker_size(n_drawn, panel_inches=PANEL_INCHES, dpi=DPI):
    """Marker area in points^2 so that a surface of n points is covered about once."""
    pixels = (panel_inches * dpi) ** 2 * 0.35  # the object fills about a third of the panel
    px_per_point = math.sqrt(pixels / max(n_drawn, 1))
    pts = px_per_point * 72.0 / dpi
    return float(np.clip(pts * pts * 0.8, 0.1, 6.0))


def _draw(ax, xyz, R, centre, half, highlight=None, base="grey", dpi=DPI):
    """Orthographic projection of ``xyz``; far points first; near points darker."""
    q = (xyz - centre) @ R.T
    order = np.argsort(q[:, 2], kind="stable")  # far (small towards) first
    q = q[order]
    depth = (q[:, 2] - q[:, 2].min()) / max(np.ptp(q[:, 2]), 1e-300)
    shade = 0.72 - 0.55 * depth  # grey level: far light, near dark
    if base == "grey":
        colours = np.repeat(shade[:, None], 3, axis=1)
    else:  # the simplified cloud: a dark blue-grey
        colours = np.c_[0.15 + 0.5 * (1 - depth), 0.25 + 0.45 * (1 - depth),
                        0.45 + 0.35 * (1 - depth)] * 0.8
    colours = np.c_[colours, np.ones(len(q))]
    size = np.full(len(q), _marker_size(len(q), dpi=dpi))
    if highlight is not None:
        h = highlight[order]
        colours[h] = (0.84, 0.15, 0.16, 1.0)
        size[h] = max(size[0] * (1.6 if base == "grey" else 1.0), 0.6)
    ax.scatter(q[:, 0], q[:, 1], s=size, c=colours, marker="o", linewidths=0,
               rasterized=True)
    ax.set_xlim(-half[0], half[0])
    ax.set_ylim(-half[1], half[1])
    ax.set_aspect("equal")
    ax.set_axis_off()


#: a panel is at most this many times wider than high, or higher than wide
MAX_PANEL_STRETCH = 3.0


def _frame(original, R):
    """Centre and half-extents (screen units) that fit the whole input, with a margin: as
    wide and high as the view of the input, within :data:`MAX_PANEL_STRETCH` of square (an
    airborne tile seen from the side is a wide strip; in a square frame it filled a third)."""
    centre = 0.5 * (original.min(0) + original.max(0))
    q = (original - centre) @ R.T
    half = np.maximum(np.abs(q[:, :2]).max(0) * 1.04, 1e-300)
    return centre, np.maximum(half, half.max() / MAX_PANEL_STRETCH)


def _panel_inches(half, longest):
    """(width, height) of a panel whose longer side is ``longest`` inches, shaped as the
    frame's half-extents ``half``."""
    aspect = float(half[1] / half[0])
    return (longest, longest * aspect) if aspect <= 1.0 else (longest / aspect, longest)


def _subsample(n, limit, seed=0):
    if n <= limit:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, limit, replace=False))


def draw_figures(directory, original, kept_xyz, boundary, kept_boundary, *, up="z", elev=20.0,
                 azim=-60.0, max_plot_points=200_000, titles=None, dpi=DPI):
    """Write the PNG figures (``PANEL_INCHES`` x ``dpi`` pixels a panel); ``{name: path}``."""
    plt = _pyplot()
    directory = Path(directory)
    R = view_rotation(up, elev, azim)
    centre, half = _frame(original, R)
    sel = _subsample(len(original), max_plot_points)
    orig_draw = original[sel]
    bnd_draw = boundary[sel] if boundary is not None else None
    ksel = _subsample(len(kept_xyz), max_plot_points, seed=1)
    kept_draw = kept_xyz[ksel]
    kb_draw = kept_boundary[ksel] if kept_boundary is not None else None
    titles = titles or {}
    panels = {
        "original": lambda ax: _draw(ax, orig_draw, R, centre, half, dpi=dpi),
        "boundary": lambda ax: _draw(ax, orig_draw, R, centre, half, highlight=bnd_draw,
                                     dpi=dpi),
        "simplified": lambda ax: _draw(ax, kept_draw, R, centre, half, highlight=kb_draw,
                                       base="blue", dpi=dpi),
    }
    files = {}
    for name, paint in panels.items():
        if name == "boundary" and boundary is None:
            continue
        width, height = _panel_inches(half, PANEL_INCHES)
        fig = plt.figure(figsize=(width, height + 0.4), dpi=dpi)  # and a title line
        ax = fig.add_axes((0.0, 0.0, 1.0, height / (height + 0.4)))
        paint(ax)
        fig.suptitle(titles.get(name, name), y=1.0 - 0.05 / (height + 0.4), va="top",
                     fontsize=11)
        files[name] = directory / f"{name}.png"
        fig.savefig(files[name], dpi=dpi)
        plt.close(fig)
    names = [n for n in ("original", "boundary", "simplified") if n in files]
    width, height = _panel_inches(half, PANEL_INCHES * 0.75)
    fig = plt.figure(figsize=(width * len(names), height + 0.4), dpi=dpi)
    for i, name in enumerate(names):
        ax = fig.add_axes((i / len(names), 0.0, 1.0 / len(names), height / (height + 0.4)))
        panels[name](ax)
        ax.set_title(f"({'abc'[i]}) {titles.get(name, name)}", fontsize=10, y=1.0)
    files["overview"] = directory / "overview.png"
    fig.savefig(files["overview"], dpi=dpi)
    plt.close(fig)
    return files


# ---------------------------------------------------------------------------------------------
# the report
# ---------------------------------------------------------------------------------------------


def _fmt(value):
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    if float(value).is_integer() and abs(value) < 1e15:
        return f"{int(value):d}"
    return f"{value:.6g}"


def _markdown(input_path, result_path, rep, files, mesh):
    ratio = rep.n_kept / rep.n_input
    lines = [
        "# tiledsimplify report", "",
        f"- input: `{input_path}` — {rep.n_input:,} points",
        f"- result: `{result_path}` — {rep.n_kept:,} points ({ratio:.1%} of the input)",
    ]
    if rep.n_boundary is not None:
        lines.append(f"- points flagged on sharp edges (`sharp_edge`) in the result: "
                     f"{rep.n_boundary:,} ({rep.n_boundary / rep.n_input:.1%} of the input)")
    else:
        lines.append("- the result carries no `sharp_edge` flags: no boundary figure")
    if mesh:
        lines.append(f"- sharp-edge truth: mesh `{mesh}` (dihedral angle > 30°)")
    lines += [f"- {note}" for note in rep.notes]
    lines += ["", "![(a) original, (b) sharp-edge points, (c) simplified](overview.png)", ""]
    lines += ["## Quality", "",
              "Distances are divided by the input's bounding-box diagonal "
              "(`tiledsimplify.metrics.evaluate`), but where the input's units are said.", "",
              "| measure | key | value |", "|---|---|---:|"]
    for key, value in rep.metrics.items():
        label, _ = METRIC_LABELS.get(key, (key, False))
        lines.append(f"| {label} | `{key}` | {_fmt(value)} |")
    lines += ["", "## Figures", ""]
    lines += [f"- [{name}]({path.name})" for name, path in files.items()]
    return "\n".join(lines) + "\n"


def make_report(input_path, result_path, out_dir, *, mesh=None, spacing=None, up=None,
                elev=20.0, azim=-60.0, max_plot_points=200_000, dpi=DPI):
    """Figures and a Markdown summary of how RESULT simplifies INPUT.

    Parameters
    ----------
    input_path : str or Path
        The original cloud (any input format of ``tiledsimplify run``).
    result_path : str or Path
        The simplified cloud, ideally an output of tiledsimplify (its ``sharp_edge`` column is
        drawn); any point file works (then without the boundary figure). An ``--all-points``
        output (every input point with ``simplify_rank``) is understood too.
    out_dir : str or Path
        Created if missing.
    mesh : str or Path, optional
        CAD mesh of the part: adds sharp-edge coverage and boundary precision/recall.
    spacing : float, optional
        Original point spacing for the edge measures (default: median nearest-neighbour
        distance).
    up : {"x", "y", "z"}, optional
        Model axis drawn upwards; default ``z`` for LAS/LAZ input, ``y`` otherwise (the usual
        convention of PLY/OBJ models such as the Stanford Bunny).
    elev, azim : float
        Camera elevation above the horizontal plane and azimuth around ``up``, degrees.
    max_plot_points : int
        Draw at most this many points per panel (random subsample, for drawing only).
    dpi : int
        Pixels per inch of the PNGs: a panel is ``6 * dpi`` pixels on its longer side (900
        by default), shaped as the view within :data:`MAX_PANEL_STRETCH` of square, plus a
        title line of ``0.4 * dpi``; the overview's three panels ``4.5 * dpi`` on their longer
        side.

    Returns
    -------
    Report
    """
    from . import metrics, synthetic
    from .io import read_mesh

    _pyplot()  # fail early and clearly if matplotlib is missing
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    original, is_las = _read_input(input_path)
    result_xyz, cols = read_columns(result_path)
    check_finite(result_xyz, 0, [result_path])
    if len(result_xyz) == 0:
        raise TiledSimplifyError(f"{result_path}: the result has no points; nothing to report.")
    keep, kept_xyz, boundary, notes = _resolve(original, result_xyz, cols)
    kw = {}
    if mesh is not None:
        V, F = read_mesh(mesh)
        s = spacing or metrics.spacing(original)
        kw.update(edge_segments=V[synthetic.sharp_edges(V, F)], spacing=s)
        if boundary is not None:
            kw["flagged"] = boundary
    m = metrics.evaluate(original, keep if keep is not None else kept_xyz, **kw)
    flags = cols.get("sharp_edge")
    if boundary is not None:
        n_boundary = int(boundary.sum())
        kept_boundary = boundary[keep] if keep is not None else None
    elif flags is not None:
        n_boundary = int(np.count_nonzero(flags))
        kept_boundary = np.asarray(flags).astype(bool)
    else:
        n_boundary, kept_boundary = None, None
    rep = Report(out, {}, m, len(original), len(kept_xyz), n_boundary, keep is not None, notes)
    titles = {"original": f"original, {len(original):,} points",
              "boundary": f"sharp-edge points, {n_boundary or 0:,}",
              "simplified": f"simplified, {len(kept_xyz):,} points"}
    rep.files = draw_figures(out, original, kept_xyz, boundary, kept_boundary,
                             up=up or ("z" if is_las else "y"), elev=elev, azim=azim,
                             max_plot_points=max_plot_points, titles=titles, dpi=dpi)
    (out / "metrics.json").write_text(json.dumps(metrics.as_json(m), indent=2) + "\n")
    rep.files["metrics"] = out / "metrics.json"
    md = _markdown(input_path, result_path, rep, {k: v for k, v in rep.files.items()}, mesh)
    (out / "report.md").write_text(md)
    rep.files["report"] = out / "report.md"
    return rep
