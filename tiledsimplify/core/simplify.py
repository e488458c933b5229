"""``simplify_points``: Song & Feng's simplification of one in-memory point set.

The public front door of the core: validates and converts once, then chains the paper's steps,
each in its own module — :mod:`.voronoi` (``VN_p``), :mod:`.local_mesh` (``DN_p``),
:mod:`.normals`, :mod:`.boundary` (+ :mod:`.edge_fit` beyond the paper), :mod:`.importance`
(Eq. (1)) and :mod:`.removal`.
"""

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import BudgetWarning, InputError
from . import adjacency
from . import boundary as boundary_mod
from . import cell_grid
from . import edge_fit, edge_lines, thin_walls, two_ring
from . import holes as holes_mod
from . import unresolved as unresolved_mod
from .unresolved import unresolved
from . import prethin as prethin_mod
from .bounds import box, finite_rows
from .heap import coordinate_hash
from .importance import MEASURES, all_importance, coverage_weight
from .local_mesh import MAX_DN, all_local_meshes
from .normals import all_normals
from .options import SimplifyOptions
from .refine import edge_cover_radius, protected, refine_coverage
from .removal import GUARDS, remove_points
from .result import SimplifyResult, nothing_kept, resolve_target, short_message
from .voronoi import (BOX_FACTOR, SCALE_SPACINGS, TOL_FACTOR, scale_of,
                      voronoi_neighbours)
from .zorder import distinct

#: the peak memory of :func:`simplify_points` per input point beyond the points themselves,
#: rounded up (bytes). Measured 2026-12-03, default call at ratio 0.2, the first 100k / 300k /
#: 1M / 3M points of the 10M-point LAZ scan of ``benchmarks/pipeline_speed.py`` (the process's
#: ``VmHWM`` less its RSS just before the call, peak reset by ``clear_refs``): 688 / 681 / 809 /
#: 681 bytes a point. What the ``simplify`` command checks against the memory left.
PEAK_BYTES_PER_POINT = 900
#: points sampled for :func:`.thin_walls.median_ring_gap`, whether the sampling fills its
#: tangent planes (the thin walls' border test, :func:`.thin_walls.border_gap`, needs it)
GAP_SAMPLE = 512


def _validate(xyz, frozen):
    X = np.asarray(xyz)
    if X.ndim != 2 or X.shape[1] != 3:
        raise InputError(f"points must be an array of shape (n, 3), got shape {X.shape}.")
    if not np.issubdtype(X.dtype, np.number) or np.issubdtype(X.dtype, np.complexfloating):
        raise InputError(f"points must be real numbers, got dtype {X.dtype}.")
    X = np.ascontiguousarray(X, dtype=np.float64)
    bad = ~finite_rows(X)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise InputError(f"points contain {int(bad.sum())} row(s) with NaN or infinite "
                         f"coordinates (first at index {first}: {X[first].tolist()}); drop or "
                         "repair them before simplifying.")
    n = X.shape[0]
    return X, (np.zeros(n, dtype=bool) if frozen is None else _mask(frozen, n, "frozen"))


def _mask(mask, n, name):
    """A copy of the boolean mask ``mask`` of ``n`` points, or an error naming it."""
    M = np.asarray(mask)
    if M.shape != (n,) or M.dtype != np.bool_:
        raise InputError(f"{name} must be a boolean mask of shape ({n},), got dtype "
                         f"{M.dtype} and shape {M.shape}.")
    return M.copy()


@dataclass
class Neighbourhoods:
    """Voronoi neighbours (adjacency lists), local meshes and normals of one point set.

    Built by :func:`neighbourhoods`; the removal mutates it in place. :meth:`to_arrays` and
    :meth:`from_arrays` save and restore a freshly built one exactly (to share it between
    the passes of a tiled run, see :func:`neighbourhood_state`).
    """

    start: np.ndarray
    cnt: np.ndarray
    cap: np.ndarray
    pool: np.ndarray
    meta: np.ndarray
    dn: np.ndarray
    dn_cnt: np.ndarray
    plane_normals: np.ndarray
    normals: np.ndarray
    initial_normals: np.ndarray
    #: per point, :func:`.local_mesh.local_mesh`'s ``stable[0]`` (0: always recompute)
    stable: np.ndarray
    how: str
    reach: float = math.inf

    def to_arrays(self):
        """Compact arrays of a freshly built state: ``(arrays, how)``.

        Lists lose their spare capacity and ids become int32 (~134 bytes per point);
        :meth:`from_arrays` rebuilds the identical state, so a run from it gives the same
        result bit for bit.
        """
        used = np.arange(MAX_DN) < self.dn_cnt[:, None]
        return {"reach": np.array([self.reach]),
                "vn_count": self.cnt.astype(np.int32),
                "vn": adjacency.to_flat(self.start, self.cnt, self.pool),
                "dn_count": self.dn_cnt.astype(np.int8),
                "dn": self.dn[used].astype(np.int32),
                "plane_normals": self.plane_normals,
                "normals": self.normals,
                "stable": self.stable.astype(np.int32)}, self.how

    @classmethod
    def from_arrays(cls, arrays, how):
        """The state saved by :meth:`to_arrays`."""
        start, cnt, cap, pool, meta = adjacency.from_lists(arrays["vn_count"], arrays["vn"])
        dn_cnt = np.asarray(arrays["dn_count"], dtype=np.int64)
        dn = np.zeros((dn_cnt.size, MAX_DN), dtype=np.int32)
        dn[np.arange(MAX_DN) < dn_cnt[:, None]] = arrays["dn"]
        normals = np.ascontiguousarray(arrays["normals"], dtype=np.float64)
        reach = float(np.asarray(arrays.get("reach", [math.inf])).reshape(-1)[0])
        stable = (np.asarray(arrays["stable"], dtype=np.int64) if "stable" in arrays
                  else np.zeros(dn_cnt.size, dtype=np.int64))  # a state saved before it: 0
        return cls(start, cnt, cap, pool, meta, dn, dn_cnt,
                   np.ascontiguousarray(arrays["plane_normals"], dtype=np.float64), normals,
                   normals.copy(), stable, str(how), reach)


def neighbourhoods(Xu, scale, reach=math.inf, normals=None):
    """Paper steps 1-2 on distinct points ``Xu``: ``VN_p`` (facets within ``reach``, see
    :func:`.voronoi.facet_positive`), ``DN_p`` and normals — or ``normals`` (m, 3) given
    (the pre-thinned subset takes the whole cloud's: its own were not computed, ~8 ms on
    57k points)."""
    m = Xu.shape[0]
    (start, cnt, cap, pool, meta), how = voronoi_neighbours(Xu, scale=scale, reach=reach)
    dn = np.zeros((m, MAX_DN), dtype=np.int32)  # ids < 2**31: half the memory of int64
    dn_cnt = np.zeros(m, dtype=np.int64)
    plane_normals = np.zeros((m, 3))
    stable = np.zeros(m, dtype=np.int64)
    all_local_meshes(Xu, start, cnt, pool, dn, dn_cnt, plane_normals, stable)
    if normals is None:
        normals = np.zeros((m, 3))
        all_normals(Xu, dn, dn_cnt, plane_normals, normals)
    else:
        normals = np.array(normals, dtype=np.float64, order="C")
    return Neighbourhoods(start, cnt, cap, pool, meta, dn, dn_cnt, plane_normals, normals,
                          normals.copy(), stable, how, float(reach))


def median_spacing(Xu):
    """Median distance from a point to its nearest neighbour (0 for fewer than 2 points)."""
    if Xu.shape[0] < 2:
        return 0.0
    return float(np.median(cell_grid.nearest_other(Xu)))


def _spacing(Xu, options):
    """The spacing that scales the coverage term and the reach: the option, else measured."""
    return options.spacing if options.spacing is not None else median_spacing(Xu)


def _working_spacing(Xu, options):
    """:func:`_spacing` where the options use one (the coverage measure, a finite reach),
    else None (mode "paper": unbounded neighbourhoods, Eq. (1) alone)."""
    if options.importance == "coverage" or math.isfinite(options.reach_spacings):
        return _spacing(Xu, options)
    return None


def reach_length(Xu, options, spacing=None):
    """``VN_p``'s reach in model units: ``options.reach_spacings`` x the spacing (or ``inf``)."""
    factor = options.reach_spacings
    if not math.isfinite(factor):
        return math.inf
    if spacing is None:
        spacing = _spacing(Xu, options)
    return factor * spacing if spacing > 0 else math.inf


def boundary_flags(Xu, st, options, distance_out=None, spacing=None, allowed=None):
    """Paper step 3: ``(deviation, core band, features, flags, threshold, detail)`` as the
    options' mode says.

    ``features`` are the points near every fitted line, which the simplification keeps like
    edges; ``flags`` the points reported on or near a sharp edge, which change no kept point.
    The features include the narrow smooth folds (:func:`.edge_fit.fold_kinds`: a fillet a few
    spacings across, which two planes fit but one quadric fits better — at the kept spacing an
    edge too, but not a sharp one); the flags do not. The ``core band`` (a subset of the
    features) holds the points nearest each line, sampled first for the points kept for
    certain (up to ``edge_share``), which the refinement never swaps out. ``distance_out``
    (optional, length m): filled in mode ``"coverage"`` with each point's distance to its
    fitted (or borrowed) line in local spacings (``inf``: none), what
    :func:`.prethin.edge_sample` orders by; ``inf`` everywhere in mode ``"paper"``.
    ``spacing``: the cloud's point spacing (None: measured), the flags' unit. ``allowed``
    (bool (m,), None: all): the points that may be edge points; the others are no candidates
    of the fits (they lend no line) and none of the masks holds them.

    ``"paper"``: the one-ring measure with the automatic threshold (§3.1); band, features and
    flags are the same. ``"coverage"``: the two-ring measure, candidates above the threshold,
    a fitted line each (:func:`.edge_fit.localise`), then the band and features of every line
    (:func:`_features_of_fits`) and the flags of the sharp ones and the creases
    (:func:`_flags`: within ``edge_width`` cloud spacings of the nearest of them); on an even
    sampling (``thin_walls.median_ring_gap`` below ``FILLED_GAP``) the points near the rims of
    small holes through thin walls too, as features and flags (:mod:`.holes`), and where that
    sampling is also exact (a CAD model sampled) the points of detail finer than the spacing,
    which no fit explains (:func:`.unresolved.unresolved`). ``detail``: those of them in
    regions of such detail and not among the features (:func:`.unresolved.regions`) — on
    other samplings (a scan, LiDAR), the regions of points whose smoothed deviation
    is far above any face's and which no fit explains (:func:`.unresolved.rough_regions`,
    not flagged) — which :func:`simplify_points` makes features where their cover fits within
    ``edge_share`` (:func:`_detail_cover`); none in mode ``"paper"``.
    """
    m = Xu.shape[0]
    deviation = np.zeros(m)
    if distance_out is not None:
        distance_out[:] = np.inf
    none = np.zeros(m, dtype=bool)
    if options.mode == "paper":
        boundary_mod.all_deviations(Xu, st.normals, st.dn, st.dn_cnt, deviation)
        if not options.detect_boundary:
            return deviation, none, none, none, float("inf"), none
        flags, threshold = boundary_mod.detect(
            deviation, threshold=options.boundary_threshold, k=options.boundary_k,
            floor=options.boundary_floor)
        if allowed is not None:
            flags = flags & allowed
        return deviation, flags, flags, flags, threshold, none
    smooth_normals = np.zeros((m, 3))
    two_ring.smoothed_deviations(Xu, st.dn, st.dn_cnt, smooth_normals, deviation)
    if not options.detect_boundary:
        return deviation, none, none, none, float("inf"), none
    threshold = (edge_fit.CANDIDATE if options.boundary_threshold is None
                 else float(options.boundary_threshold))
    nn = np.empty(m)
    two_ring.nearest_distances(Xu, st.start, st.cnt, st.pool, nn)
    fitted, fitted_angle, line, local = np.empty(m), np.empty(m), np.empty((m, 6)), np.empty(m)
    corner = np.empty(m, dtype=bool)
    bend = np.empty(m)
    narrowed = np.empty(m, dtype=bool)
    rim = np.empty(m, dtype=bool)
    width = float(options.edge_width)
    spacing = float(median_spacing(Xu) if spacing is None else spacing)
    gap = thin_walls.median_ring_gap(Xu, st.normals, st.dn, st.dn_cnt, spacing, GAP_SAMPLE)
    filled = bool(gap < thin_walls.FILLED_GAP)  # the thin walls' border test needs it
    candidate = deviation > threshold
    if allowed is not None:  # the others lend no line: no fit of theirs
        candidate &= allowed
    edge_fit.localise(Xu, st.normals, st.dn, st.dn_cnt, nn, candidate, fitted,
                      fitted_angle, line, local, float(options.edge_angle), width, corner,
                      bend, narrowed, rim, filled)
    _confirm_narrowed(Xu, st, fitted, fitted_angle, line, width, spacing, corner, bend,
                      narrowed)
    distance = np.empty(m) if distance_out is None else distance_out
    own = edge_fit.band(fitted, fitted_angle, width)  # the candidates their own fit flags
    band, features = _features_of_fits(Xu, st, fitted, fitted_angle, line, local, width,
                                       spacing, corner, distance, own, rim)
    flags = _flags(Xu, st, fitted, fitted_angle, line, width, spacing, corner, bend,
                   own & corner, narrowed)
    exact = filled and unresolved_mod.exact_sampling(Xu, st.dn, st.dn_cnt, spacing)
    if filled:  # small holes through thin walls: their rims flagged and kept covered
        rims = holes_mod.hole_rims_near(Xu, st.dn, st.dn_cnt, nn, width, spacing)
        flags |= rims
        features |= rims
    if exact:  # detail finer than the sampling (:mod:`.unresolved`; it checks the spacing)
        fine = unresolved(Xu, st.dn, st.dn_cnt, spacing, True)
        flags |= fine
        detail = unresolved_mod.regions(Xu, fine & ~features, spacing)
    else:  # a scan's detail: its two-rings' normals turn far more than noise turns them
        detail = unresolved_mod.rough_regions(Xu, deviation, features, spacing)
    if allowed is not None:
        band, features, flags, detail = (a & allowed for a in (band, features, flags, detail))
    return deviation, band, features, flags, threshold, detail


def _detail_cover(Xu, st, detail, tie, radius):
    """What a cover of the ``detail`` points within ``radius`` costs, in kept points: the
    count of a disk sample of them at that radius along the Voronoi graph
    (:func:`.prethin.disk_sample`, in the order of ``tie``); 0 without detail or radius.

    Beyond the paper. Regions of detail finer than the spacing (:func:`.unresolved.regions`:
    a threaded hole) are flagged, but no fit places a line in them, so they draw none of the
    points sure of being kept. Where this cost fits within the sure points' share
    (``edge_share``), :func:`simplify_points` makes them features — the refinement keeps each
    within ``radius`` of a kept point, as it does the edges' (:func:`.refine.refine_coverage`)
    — and the sure points give way by that many: counter (20 % of 19,999 points) 314 detail
    points in its five threaded holes cost 116, its edge coverage 0.835 -> 0.942 (docs/
    measurements.md, "Regions of detail kept covered").
    """
    if not detail.any() or not radius > 0:
        return 0
    order = np.flatnonzero(detail)
    order = order[np.argsort(tie[order], kind="stable")].astype(np.int64)
    m = Xu.shape[0]
    keep = np.zeros(m, dtype=bool)
    stamp, stack = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64)
    return int(prethin_mod.disk_sample(Xu, st.start, st.cnt, st.pool, np.zeros(m, dtype=bool),
                                       order, radius, keep, stamp, stack))


def _lending_fits(fitted, fitted_angle, width, corner, bend):
    """The fits whose lines may lend flags: within ``FAR_FIT`` widths of their own point, on
    a sharp edge (a fold of ``SOFT_ANGLE`` or more) or a crease, not a smooth fold nor a
    corner (:func:`.edge_fit.fold_kinds`)."""
    smooth, crease = edge_fit.fold_kinds(bend, fitted_angle)
    return ((fitted <= edge_lines.FAR_FIT * width) & ~smooth & ~corner
            & ((fitted_angle >= edge_fit.SOFT_ANGLE) | crease))


def _confirmed(Xu, st, fit, sure, line, spacing):
    """:func:`.edge_lines.confirmed_lines` at the cloud ``spacing``'s reach and offset."""
    out = np.empty(Xu.shape[0], dtype=bool)
    edge_lines.confirmed_lines(Xu, st.dn, st.dn_cnt, fit, sure, line,
                               edge_lines.CONFIRM_REACH * spacing,
                               edge_lines.CONFIRM_OFFSET * spacing,
                               math.cos(math.radians(edge_lines.CONFIRM_ANGLE)), out)
    return out


def _confirm_narrowed(Xu, st, fitted, fitted_angle, line, width, spacing, corner, bend,
                      narrowed):
    """Drops (in place) the fits over the near part of a two-ring and the steps (``narrowed``,
    see :func:`.edge_fit.near_part` and :func:`.thin_walls.fit_step`) that no other fit
    confirms: each is kept only where another lending fit's line runs beside its own
    (:func:`.edge_lines.confirmed_lines`). A few points fit two
    planes by chance; alone, such a line made features and flags along it (measured on the 36
    CAD quality cases, docs/measurements.md "Scans: the near part of the two-ring": every
    narrowed fit standing, at 6 local spacings, plate_holes' noise-0.2 scan's F1 0.780 ->
    0.704; confirmed for the flags only, at 5, the tray scans' Hausdorff 1.22x and 1.21x the
    best peer's, beyond the 1.2x of issue 5). The corner fits (:func:`.edge_fit.localise`'s
    second pass) that a dropped fit's line allowed stay."""
    if not narrowed.any() or not spacing > 0:
        return
    fit = _lending_fits(fitted, fitted_angle, width, corner, bend)
    drop = narrowed & ~_confirmed(Xu, st, fit, fit & ~narrowed, line, spacing)
    fitted[drop] = np.inf
    fitted_angle[drop] = 0.0
    bend[drop] = np.nan


def _flags(Xu, st, fitted, fitted_angle, line, width, spacing, corner, bend, at_corner,
           narrowed):
    """The flags of :func:`.edge_fit.localise`'s fits: the points within ``width`` cloud
    ``spacing``s of the line of one of their nearest lenders
    (:func:`.edge_lines.nearest_line_distances`) — the fits on a sharp edge (a fold of
    ``SOFT_ANGLE`` or more) or a crease (:func:`.edge_fit.fold_kinds`), not smooth folds nor
    corners, within ``width`` of their own line, or within ``FAR_FIT`` widths where another
    fit's line confirms theirs (:func:`.edge_lines.confirmed_lines`), as every ``narrowed``
    fit (over the near part of its two-ring, or a step: kept by :func:`_confirm_narrowed`
    beside another fit, it is confirmed again among the fits left) — and the points their own
    corner fit flags (``at_corner``)."""
    if not spacing > 0:
        return at_corner
    fit = _lending_fits(fitted, fitted_angle, width, corner, bend)
    lender = _confirmed(Xu, st, fit, fit & (fitted <= width) & ~narrowed, line, spacing)
    near = np.empty(Xu.shape[0])
    edge_lines.nearest_line_distances(Xu, st.dn, st.dn_cnt, lender, line,
                                      edge_lines.FLAG_REACH * spacing, spacing, near)
    return at_corner | (near <= width)


def _features_of_fits(Xu, st, fitted, fitted_angle, line, local, width, spacing, corner,
                      distance, own, rim):
    """``(core band, features)`` of the fitted lines (:func:`.edge_fit.localise`'s outputs).

    The core band: the candidates within ``width`` local spacings of a fitted line — their own
    or, where that does not flag them (no fit, or a farther line), a flagged neighbour's
    (:func:`.edge_lines.borrow`; each point's distance to it into ``distance``) — less beside a
    soft edge (:func:`.edge_fit.band`). The features add the points their own corner fit flags
    and every point within ``width`` spacings of a sharp fitted line near it
    (:func:`.edge_lines.line_distances`). ``own``: the candidates their own fit flags
    (:func:`.edge_fit.band` of ``fitted``).

    A thin wall's rim (``rim``: :func:`.thin_walls.fit_rim`) makes features but not the core
    band: in the band, sure of being kept, its points took the tray scans' budget from their
    faces (Hausdorff 1.19x -> 1.24x the best peer's on the noise-0.2 scan; as features only
    1.16x, docs/measurements.md "Thin walls' rims").
    """
    m = Xu.shape[0]
    angle = np.empty(m)
    edge_lines.borrow(Xu, st.dn, st.dn_cnt, fitted, fitted_angle, line, local, width, own,
                      corner, distance, angle)
    # points their own corner fit flags are features, not the core band: the band is sure of
    # being kept and never swapped out, and a corner's line ends at the corner
    at_corner = own & corner
    band = edge_fit.band(distance, angle, width) & ~at_corner
    near = np.full(m, np.inf)
    edge_lines.line_distances(Xu, st.dn, st.dn_cnt, fitted, fitted_angle, line, local, width,
                              spacing, corner, near)
    features = band | at_corner | (near <= width)
    if rim.any():  # the band again without the rims' lines
        edge_lines.borrow(Xu, st.dn, st.dn_cnt, np.where(rim, np.inf, fitted), fitted_angle,
                          line, local, width, own & ~rim, corner, distance, angle)
        band = edge_fit.band(distance, angle, width) & ~at_corner
    return band, features


def _options(options):
    if options is None:
        return SimplifyOptions()
    if isinstance(options, dict):
        return SimplifyOptions.from_mapping(options)
    if not isinstance(options, SimplifyOptions):
        raise InputError(f"options must be a SimplifyOptions or a dict, got {type(options)}.")
    return options


def _swap(keep, rank, importance, rep, keep_u, order, order_importance, cut):
    """Apply a refined kept set of the representatives (:mod:`.refine`) to ``keep`` in place;
    returns ``rank`` and ``importance`` renumbered: the greedy's removals that stay removed keep
    their relative order, the points swapped out follow them (with their importance in the
    progressive order where it reached them, else NaN)."""
    out = rep[keep[rep] & ~keep_u]
    back = rep[~keep[rep] & keep_u]
    keep[out] = False
    keep[back] = True
    n = keep.size
    pos = np.full(n, order.size, dtype=np.int64)
    pos[order] = np.arange(order.size)
    removed = order[:cut][~keep[order[:cut]]]
    removed = np.concatenate([removed, out[np.argsort(pos[out], kind="stable")]])
    rank = np.full(n, -1, dtype=np.int64)
    rank[removed] = np.arange(removed.size)
    at = np.append(order_importance, np.nan)
    importance = np.full(n, np.nan)
    importance[removed] = at[pos[removed]]
    return rank, importance


def _prepare(X, frozen):
    """Distinct points, centred: ``(rep, inverse, Xu, D)`` — the representatives of the
    exact-duplicate groups (a frozen member if any, else the lowest index) along the Z-order
    curve (:func:`.zorder.distinct`: neighbours close in memory), the group of every input
    point, their centred coordinates (what every step runs on) and the cloud's scale."""
    rep, inverse = distinct(X, frozen)
    m = rep.size
    P = X[rep]
    lo, hi = box(P) if m else (np.zeros(3), np.zeros(3))
    Xu = np.ascontiguousarray(P - 0.5 * (lo + hi))
    return rep, inverse, Xu, scale_of(Xu)


def _scale(Xu, D, spacing):
    """The length the Voronoi tolerances are relative to (:func:`.voronoi.scale_of`): the
    diagonal ``D``, at most ``SCALE_SPACINGS`` spacings (``spacing``, else measured), so that
    a far outlier does not make the other points' facets degenerate."""
    if D <= SCALE_SPACINGS * (spacing or 0.0):
        return D  # (no need to measure the spacing: the diagonal is below the cap)
    s = spacing if spacing is not None else median_spacing(Xu)
    return min(D, SCALE_SPACINGS * s) if s > 0 else D


def neighbourhood_state(xyz, frozen=None, options=None):
    """Paper steps 1-2 (``VN_p``, ``DN_p``, normals) and the boundary measure, once.

    For callers that need the boundary measure of many point sets before they can simplify
    any of them — a tiled run takes one threshold over all tiles. Pass the state to
    ``simplify_points(xyz, ..., frozen=frozen, state=state)`` on the same points and the
    neighbourhood stage (the Delaunay triangulation and the local meshes, most of the cost
    before removal) is not computed twice. The result is identical to a run without ``state``.

    Parameters
    ----------
    xyz, frozen, options : as for :func:`simplify_points` (the options' ``reach`` and
        ``spacing`` shape the neighbourhoods; pass the same options to the run).

    Returns
    -------
    state : Neighbourhoods
        Over the distinct points; :meth:`Neighbourhoods.to_arrays` saves it compactly.
    deviation : float64 (n,)
        The boundary measure of every input point (:mod:`.boundary`).
    """
    options = _options(options)
    X, frozen = _validate(xyz, frozen)
    _, inverse, Xu, D = _prepare(X, frozen)
    spacing = _working_spacing(Xu, options)
    st = neighbourhoods(Xu, _scale(Xu, D, spacing), reach_length(Xu, options, spacing))
    deviation_u = np.zeros(Xu.shape[0])
    boundary_mod.all_deviations(Xu, st.normals, st.dn, st.dn_cnt, deviation_u)
    return st, deviation_u[inverse]


#: the extent of a cloud, in point spacings, past which the triangulation's floating point
#: can lose neighbours. Facet tolerances are capped at ``voronoi.SCALE_SPACINGS`` spacings and
#: a lone far outlier is left out of the triangulation (the Bunny, 0.25 m across at a 1 mm
#: spacing, with a point 1e9 m away: mean Voronoi degree 12.18 against 12.20 alone), but two
#: parts that far apart each keep almost none (two quarter-Bunnies 1e9 m apart: 0.83; 1e6 m
#: apart: 12.88, as one)
EXTENT_SPACINGS = 0.01 / TOL_FACTOR
#: ... and the share of points left without a Voronoi neighbour above which that is said
LOST_SHARE = 0.01


def _warn_lost_neighbours(Xu, D, options, spacing, degree, lonely):
    """Warn where the Voronoi neighbourhoods of ``Xu`` (bounding-box diagonal ``D``) lose
    their neighbours, rather than simplify silently without them: a ``spacing`` option far
    below the points' (the wrong units), or an extent of more than :data:`EXTENT_SPACINGS`
    spacings with more than :data:`LOST_SHARE` of the points (``lonely``) left without a
    neighbour (far-apart parts)."""
    m = Xu.shape[0]
    if m < 10:
        return
    if options.spacing is not None and degree < 1:
        s = median_spacing(Xu)
        if options.spacing < 0.1 * s:
            warnings.warn(f"options.spacing={options.spacing!r} is far below these points' "
                          f"spacing (the median nearest-neighbour distance is {s:.6g}): "
                          f"within the reach of {options.reach_spacings:g} spacings the "
                          f"points have {degree:.3g} neighbours on average, so no sharp edge "
                          "is found and the removal order is arbitrary. Give the spacing in "
                          "the points' units, or leave it out (None) to measure it.",
                          UserWarning, stacklevel=3)
            return
    if not lonely > LOST_SHARE:
        return
    s = spacing if spacing is not None else median_spacing(Xu)  # ("paper": not measured yet)
    if s > 0 and D > EXTENT_SPACINGS * s:
        warnings.warn(f"the points span {D:.6g} (bounding-box diagonal), {D / s:.3g} times "
                      f"their spacing ({s:.6g}), and {lonely:.0%} of them were left without "
                      f"a Voronoi neighbour (mean Voronoi degree {degree:.3g}; a surface has "
                      "10-15): parts that far apart are beyond the triangulation's floating "
                      "point, and without neighbours no edge is flagged and the removal order "
                      "is arbitrary. Simplify far-apart parts separately (or remove the far "
                      "points, if they are outliers).",
                      UserWarning, stacklevel=3)


def simplify_points(xyz, ratio=None, *, count=None, frozen=None, options=None, state=None,
                    prethin_target=None, covered=None, edge_ok=None):
    """Simplify a point cloud, flagging every point on or near a sharp edge and keeping them
    (up to ``options.edge_share`` of the count; beyond it an even sample along the edges, the
    points nearest each edge line first).

    Parameters
    ----------
    xyz : array_like (n, 3)
        Point coordinates. Exact duplicates are allowed: the algorithm runs on one copy (a
        frozen one if any), the other copies share its flags and normal and are removed first,
        with importance 0 — unless they are frozen or edge points sure of being kept
        (``options.edge_share``), which are always kept.
        NaN or infinite coordinates are an error.
    ratio : float in (0, 1], optional
        Fraction of the points to keep. Give this or ``count`` — or neither, with
        ``options.guard="max_spacing"``: then as few as that limit allows (the result's
        ``target`` is the count reached).
    count : int, optional
        Number of points to keep.
    frozen : bool array (n,), optional
        Points that are never removed but act as neighbours (a tile's halo).
    options : SimplifyOptions or dict, optional
        Algorithm options; mode "coverage" by default (``mode="paper"``: as published).
    state : Neighbourhoods, optional
        From :func:`neighbourhood_state` on the same ``xyz`` and ``frozen`` (or restored with
        :meth:`Neighbourhoods.from_arrays`): skips steps 1-2. It is consumed (the removal
        updates it in place).
    prethin_target : int, optional
        The count the pre-thinning (``options.prethin``) multiplies instead of the target: a
        tiled run passes its global target's share of the tile, so that every pass over a
        tile thins it the same way whatever count that pass asks for.
    covered : bool array (n,), optional
        With ``options.guard="max_spacing"``: the points that must stay within
        ``options.max_spacing`` of a kept point, and the only ones that may keep others
        covered (default: all). A tiled run passes a tile's own points: its halo points are
        decided by their own tiles, so they cannot vouch for a gap.
    edge_ok : bool array (n,), optional
        The points that may be edge points (default: all). The others are never flagged nor
        features, and lend no edge line to their neighbours (they are no candidates of the
        edge fits): simplified as any point of a face. A tiled run of LAS points passes the
        points not of the classes ``no_edge_classes`` names (vegetation, noise: a fit through
        a tree's returns finds two planes as readily as a roof's).

    Returns
    -------
    SimplifyResult
        ``keep``, ``boundary``, ``normals``, ``rank``, ``importance`` and the full progressive
        order (see :class:`SimplifyResult`). If the points sure of being kept (frozen ones, and
        flagged ones up to ``options.edge_share`` of the count) exceed the target, all of them
        are kept, ``res.reached`` is False, ``res.message`` says why, and a
        :class:`~tiledsimplify.errors.BudgetWarning` is issued.

    Notes
    -----
    Cost: one 3-D Delaunay triangulation (:mod:`.delaunay`; Qhull in mode "paper") to seed the
    Voronoi neighbours, then per removed point an exact local update of the neighbourhoods,
    normals and importance of two rings of points around it (paper §3.3, Fig. 1). In mode
    "coverage" the smooth points are first thinned to ``options.prethin`` times the target
    (:mod:`.prethin`), and the greedy runs on that subset with a triangulation of its own.

    References
    ----------
    Song, H. & Feng, H.-Y., "A point cloud simplification algorithm for mechanical part
    inspection", in *Information Technology for Balanced Manufacturing Systems*, Springer 2006.

    Examples
    --------
    >>> import numpy as np
    >>> from tiledsimplify import simplify_points
    >>> rng = np.random.default_rng(0)
    >>> xyz = rng.random((2000, 3)) * [1, 1, 0.01]
    >>> res = simplify_points(xyz, ratio=0.25)
    >>> int(res.keep.sum())
    500
    """
    options = _options(options)
    X, frozen = _validate(xyz, frozen)
    n = X.shape[0]
    covered = None if covered is None else _mask(covered, n, "covered")
    edge_ok = None if edge_ok is None else _mask(edge_ok, n, "edge_ok")
    target = resolve_target(n, ratio, count, options.guard)
    empty = nothing_kept(n, ratio, target)
    if empty:
        warnings.warn(empty, BudgetWarning, stacklevel=2)
    by_guard = target is None  # the max_spacing guard alone sets the count
    if by_guard:
        target = 0
    stats = {"n_input": n}
    clock = time.perf_counter()

    def lap(name):
        nonlocal clock
        now = time.perf_counter()
        stats[f"seconds_{name}"] = now - clock
        clock = now

    rep, inverse, Xu, D = _prepare(X, frozen)
    m = rep.size
    stats["n_duplicates"] = n - m
    lap("prepare")

    spacing = _working_spacing(Xu, options)
    reach = reach_length(Xu, options, spacing)
    diagonal, D = D, _scale(Xu, D, spacing)
    if state is None:
        st = neighbourhoods(Xu, D, reach)
    elif state.cnt.size != m:
        raise InputError(f"state was built for {state.cnt.size} distinct points, but these "
                         f"points have {m}; build it with neighbourhood_state on the same "
                         "points and frozen mask.")
    elif state.reach != reach:
        raise InputError(f"state was built with a Voronoi reach of {state.reach:.6g}, but these "
                         f"options give {reach:.6g}; build it with neighbourhood_state and the "
                         "same options (reach, spacing).")
    else:
        st = state
    stats["reach"] = float(reach)
    stats["neighbours"] = st.how
    stats["mean_voronoi_degree"] = float(st.cnt.mean()) if m else 0.0
    stats["mean_local_mesh_degree"] = float(st.dn_cnt.mean()) if m else 0.0
    _warn_lost_neighbours(Xu, diagonal, options, spacing, stats["mean_voronoi_degree"],
                          float((st.cnt == 0).mean()) if m else 0.0)
    lap("neighbours_normals")
    edge_distance = np.empty(m)
    # ``flags_u``: every point on or near a sharp edge (reported only); ``features_u``: the
    # points near every fitted line (smooth folds too), what the sure points are drawn from and
    # the refinement keeps covered; ``band_u`` the features nearest their lines, sampled first
    # for the sure points and never swapped out by the refinement
    deviation_u, band_u, features_u, flags_u, threshold, detail_u = boundary_flags(
        Xu, st, options, edge_distance, spacing, None if edge_ok is None else edge_ok[rep])
    lap("boundary")
    code = MEASURES[options.importance]
    weight = 0.0
    if options.importance == "coverage":
        weight = coverage_weight(spacing, options.coverage) if spacing > 0 else 0.0
        stats["spacing"] = float(spacing)

    tie = coordinate_hash(X[rep])
    # beyond the paper: the feature points sure of being kept, at most ``edge_share`` of the
    # count (of the tile's share of the global one in a tiled run, as every pass over it
    # asks): all of them if they fit; else an even sample of them, the band's points nearest
    # their line first — of the band alone where the band does not fit. The other feature
    # points (flagged or not) compete with the rest. Regions of detail finer than the spacing
    # join the features where their cover fits within that share, the sure points giving way
    anchor_u = features_u
    share = options.edge_share_value
    stats["n_detail"] = int(detail_u.sum())
    if math.isfinite(share) and not by_guard and (features_u.any() or detail_u.any()):
        asked = target if prethin_target is None else prethin_target
        goal = math.floor(share * asked)
        if spacing is None:  # mode "paper" (not measured yet): once, for the pre-thinning too
            spacing = median_spacing(Xu)
        need = _detail_cover(Xu, st, detail_u, tie, edge_cover_radius(spacing, asked / m))
        stats["n_detail_cover"] = need
        sure_from = features_u
        if detail_u.any() and need <= goal:
            goal -= need
            features_u = features_u | detail_u
        anchor_u = prethin_mod.edge_sample(Xu, st.start, st.cnt, st.pool,
                                           band_u if band_u.sum() > goal else sure_from,
                                           edge_distance, tie, goal, spacing)
    stats["n_edge_sure"] = int(anchor_u.sum())

    # 5. progressive removal: duplicate copies first (importance 0), then the greedy sequence
    boundary = flags_u[inverse]
    is_rep = np.zeros(n, dtype=bool)
    is_rep[rep] = True
    # a copy adds nothing to what its representative keeps, flagged or sure of being kept:
    # every copy but a frozen one goes first (a sure point's copies were kept with it, up to
    # a fifth of the count on a cloud whose points were all doubled)
    anchor = np.zeros(n, dtype=bool)
    anchor[rep] = anchor_u
    dup_order = np.flatnonzero(~is_rep & ~frozen)
    never_u = anchor_u | frozen[rep]  # never removed
    n_remove = n - target
    to_target = max(0, n_remove - dup_order.size)
    normals_u = st.initial_normals
    # never swapped out by the refinement: a point of the band the cut kept stays, sure or not;
    # the other flagged points may go, sure or not
    protected_u = protected(deviation_u, threshold, st.start, st.cnt, st.pool)
    fixed_u = frozen[rep] | band_u | protected_u

    # 4b. beyond the paper: thin the smooth points to a multiple of the target first
    thinned = np.zeros(0, dtype=np.int64)
    sub = None
    guarded = options.guard == "max_spacing"
    covers_u = covered[rep] if guarded and covered is not None else None
    P = X[rep] if guarded else None  # the guard measures in the input's own coordinates
    # the distinct points kept: the pre-thinned subset holds at least this many (with
    # ``prethin_target`` the same for every count asked: the passes over one tile agree), and
    # the refinement's edge cover grows as it shrinks
    aim = m - to_target if prethin_target is None else int(prethin_target)
    if options.prethin_factor and (to_target > 0 or prethin_target is not None):
        # sure band and frozen points all stay; the ones the refinement protects (and the
        # rest of the band) are drawn first but thinned like the rest (28 % of the noisy
        # tray scan, see prethin). With a max_spacing guard the disk is at most a share of
        # the limit (and just that with no count to aim at), so that every thinned point
        # starts covered
        cap = prethin_mod.GUARD_RADIUS * options.max_spacing if guarded else math.inf
        sub = prethin_mod.subset(Xu, st.start, st.cnt, st.pool, never_u,
                                 math.ceil(options.prethin_factor * aim)
                                 if aim > 0 or not guarded else None,
                                 spacing if spacing is not None else median_spacing(Xu), tie,
                                 least=aim, first=fixed_u & ~never_u, max_radius=cap)
        if sub is not None and guarded:
            owner_u = prethin_mod.covered_by(P, sub, covers_u, options.max_spacing)
    if sub is not None:
        thinned = np.flatnonzero(~sub)
        thinned = thinned[np.argsort(tie[thinned], kind="stable")]
        keep_ids = np.flatnonzero(sub)
        stats["n_prethin_subset"] = int(keep_ids.size)
        st = state = None  # the whole cloud's lists (~0.4 KB a point) before the subset's
        Xg = np.ascontiguousarray(Xu[keep_ids])
        # with the whole cloud's normals, as without thinning
        st = neighbourhoods(Xg, D, reach, normals_u[keep_ids])
        boundary_g, tie_g = anchor_u[keep_ids], tie[keep_ids]
        alive = ~never_u[keep_ids]
    else:
        Xg, boundary_g, tie_g, alive = Xu, anchor_u, tie, ~never_u
    lap("prethin")
    # the max_spacing guard's cover lists (removal.guard_allows; empty, unread, without it):
    # the subset's points, then the thinned ones, each already handed to its nearest cover.
    # Their distances are measured in the input's coordinates, not the centred ones the
    # other steps run on: ``x - c`` rounds, and a cover at the limit there (a grid's
    # neighbour at one spacing) was up to an ulp beyond it where a user checks the bound
    m_guard = Xg.shape[0] if guarded else 0
    covers_g = (np.ones(m_guard, dtype=bool) if covers_u is None or not m_guard
                else covers_u if sub is None else covers_u[keep_ids])
    owners = np.full((2, m_guard + (thinned.size if guarded else 0)), -1, dtype=np.int64)
    cover_xyz = (np.empty((0, 3)) if not guarded else P if sub is None
                 else np.concatenate([P[keep_ids], P[thinned]]))
    if guarded and thinned.size:
        slot = np.full(m, -1, dtype=np.int64)  # a point's index among the subset's
        slot[keep_ids] = np.arange(keep_ids.size)
        cover_of = owner_u[thinned]
        prethin_mod.link_covers(owners, m_guard + np.arange(thinned.size),
                                np.where(cover_of >= 0, slot[cover_of], -1))
    imp_u = np.zeros(Xg.shape[0])
    all_importance(code, Xg, st.normals, boundary_g, st.dn, st.dn_cnt, weight, imp_u)
    lap("importance")

    greedy_target = max(0, to_target - thinned.size)  # the greedy's steps to the target

    def remove(n_steps, stop_above):
        order_k, at_k, st.pool = remove_points(
            Xg, st.start, st.cnt, st.cap, st.pool, st.meta, st.dn, st.dn_cnt, st.plane_normals,
            st.normals, st.stable, boundary_g, alive, imp_u, tie_g, code, weight,
            GUARDS[options.guard], float(options.max_spacing or 0.0), covers_g, owners,
            cover_xyz, n_steps, BOX_FACTOR * D,
            TOL_FACTOR * D, st.reach, options.update_normals, stop_above)
        return (order_k if sub is None else keep_ids[order_k]), at_k

    if not options.progressive:
        order_u, at_u = remove(greedy_target, np.inf)
    elif options.progressive_until is None:
        order_u, at_u = remove(m, np.inf)
    else:  # to the target, then on until the level is passed (the sequence is the same)
        level = float(options.progressive_until)
        order_u, at_u = remove(greedy_target, np.inf)
        if not (at_u.size and at_u.max() > level):
            o2, a2 = remove(m, level)
            order_u, at_u = np.concatenate([order_u, o2]), np.concatenate([at_u, a2])
    if thinned.size:  # first, with importance 0, as exact duplicates
        order_u = np.concatenate([thinned, order_u])
        at_u = np.concatenate([np.zeros(thinned.size), at_u])
    lap("removal")

    del st, state  # the lists, meshes and normals (~0.4 KB a point) are not needed from here:
    # released before the refinement, whose searches would otherwise set the peak memory
    order = np.concatenate([dup_order, rep[order_u]])
    order_importance = np.concatenate([np.zeros(dup_order.size), at_u])
    cut = min(n_remove, order.size)
    keep = np.ones(n, dtype=bool)
    keep[order[:cut]] = False
    rank = np.full(n, -1, dtype=np.int64)
    rank[order[:cut]] = np.arange(cut)
    importance = np.full(n, np.nan)
    importance[order[:cut]] = order_importance[:cut]
    if options.refines and cut == n_remove and to_target > 0:
        keep_u, info = refine_coverage(Xu, keep[rep], fixed_u, tie=tie, edges=features_u,
                                       edge_radius=edge_cover_radius(spacing, aim / m))
        rank, importance = _swap(keep, rank, importance, rep, keep_u, order, order_importance,
                                 cut)
        stats.update({f"refine_{key}": value for key, value in info.items()})
        lap("refine")
    message = ""
    if by_guard:
        target = n - cut  # what the limit allows is the count asked for
    elif cut < n_remove:
        n_b = int(anchor.sum())
        n_f = int(frozen.sum())
        n_g = n - order.size - int((anchor | frozen).sum())  # never removed, yet removable
        message = short_message(target, n, n - order.size, n - cut, n_b, n_g, options.guard,
                                frozen=n_f)
        warnings.warn(message, BudgetWarning, stacklevel=2)
    band = band_u[inverse]
    features = features_u[inverse]
    stats["n_boundary"] = int(boundary.sum())
    stats["n_edge_band"] = int(band.sum())
    stats["n_features"] = int(features.sum())
    stats["threshold"] = threshold
    return SimplifyResult(
        keep=keep, boundary=boundary, normals=normals_u[inverse], rank=rank,
        importance=importance, deviation=deviation_u[inverse], threshold=threshold,
        order=order, order_importance=order_importance, target=target, message=message,
        stats=stats, band=band, features=features, protected=protected_u[inverse])
