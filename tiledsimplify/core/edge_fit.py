"""Thin, noise-robust boundary flags: locate the sharp edge near each candidate (beyond the paper).

The paper's normal-deviation measure (:mod:`.boundary`) is high wherever a point's neighbourhood
straddles a sharp edge, so its outliers form a band several spacings wide, and on a noisy scan
the one-ring normals it uses are too noisy to separate edges from noise. Two steps fix both:

1. **Smoothed measure** — the same curvature-compensated deviation, computed over the two-ring
   ``DN_p ∪ DN(DN_p)`` of the local Voronoi mesh with normals fitted to that two-ring (about 19
   points instead of 7): noise averages out, edges still stand out. Points above ``CANDIDATE``
   (0.08 rad, a fixed, scale-free angle) are the **candidates**. The paper's automatic
   threshold (median + 3 robust deviations) is not used here: when edge bands hold a quarter
   or more of the points (small parts, pockets) the median itself lies in the band — measured
   on the octagonal pocket scan: threshold 0.57, recall 0.01. Step 2 does the selecting.
2. **Edge localisation** — for each candidate, the two-ring (plus the point) is split into two
   planes (seeded by the two most different one-ring normals, then a few rounds of assigning
   each point to the nearer plane and refitting, a 2-plane k-means). One-ring normals are
   noisy on a scan (three to five neighbours on anisotropic scan lines), and a bad seed leaves
   the k-means in a wrong split; when the fit fails, it is tried once more from a **line
   sweep**: the split of the neighbours by a straight line in their mean plane (``NDIR``
   directions, every offset) with the least total squared distance to the two planes, which
   is where a sharp edge projects. If the faces fold by more than ``MIN_ANGLE`` (the option
   ``edge_angle``; a wedge's fold is more than 90°: its faces meet at less than 90°) and each
   has at least ``MIN_SIDE`` points, the edge is the planes' line of intersection and the
   candidate is flagged only
   when it lies within ``width`` local spacings of that line (local spacing: the median
   nearest-neighbour distance over the two-ring) — ``SOFT_WIDTH`` of that where the faces
   fold by less than ``SOFT_ANGLE`` (:func:`band`).
   **Thin walls** (since 2026-12-06): where the two-ring's heights over its mean plane fall
   into two parallel sheets 0.5-3 local spacings apart — a wall thinner than the two-ring, whose
   two faces the local mesh joins — only the point's own sheet is fitted (:func:`own_layer`).
   **Wide two-rings** (since 2026-12-06, stop 57): where neither seed gives an edge, the fit
   is tried once more over the two-ring's points within ``NEAR_RING`` local spacings
   (:func:`near_part`) — a line scan's two-ring reaches some eight local spacings across its
   lines, past a narrow face or over a curved one; such a fit stands only where another fit's
   line confirms it (:func:`.simplify.boundary_flags`).
   **Steps** (since 2026-12-06, stop 57): where no two-plane fit gives an edge, a step lower
   than the spacing — two parallel layers side by side, its wall holding few points or none
   (counter's rib, 0.67 spacings tall) — is fitted (:func:`_fit_step`), confirmed likewise.
   **Thin walls' rims** (since 2026-12-06, stop 59): where all of that finds nothing and the
   two-ring holds two sheets, a plate thinner than about two spacings may end there: both
   sheets end together along a line, past which nothing lies (:func:`_fit_rim`,
   :func:`_rim_clear`). The rim's edge on the point's own sheet is its line; it lends flags,
   and makes features but not the core band (:func:`.simplify.boundary_flags`).
   **Corners** (since 2026-12-05): where that fit flags no point (no edge within ``width``,
   or a farther one) but flags one in its two-ring, the two-ring is split into three planes
   (:func:`_fit_corner`) — where an edge bends (a polygonal hole's rim), where three faces
   meet, where an edge ends on a face, two planes fit no two-ring — and the nearest line of
   two of them that fold sharply, meet and are not a thin wall's parallel faces is the
   point's. Points so flagged are flags, not the core band (step 4), and lend no line (steps
   3-4): a corner's line ends at the corner.
   **Smooth folds** (since 2026-12-05): two planes also fit a fillet or a small cylinder a
   few spacings across, whose normals turn 40-80° over a two-ring — most of the false flags
   on the even CAD parts (plate_holes: 453 of the 1,025 points their own fit flagged, a
   median 5.3 spacings from any sharp edge). Where one quadric height field over the
   two-ring fits it with less than ``SMOOTH_RATIO`` of the two planes' squared error
   (:func:`_quadric_sse`), the fold is **smooth**: at a sharp edge the planes fit exactly
   and the quadric cannot bend that fast. A smooth fold's line still makes **features** — the
   sure points are sampled from them and the core band holds them (at the kept spacing a
   narrow fillet is an edge too: without them plate_holes' mean surface error rose 3.68 ->
   4.43), and the refinement keeps them covered — but not **flags**
   (:func:`.simplify.boundary_flags`). The other way, a soft fold (less than ``SOFT_ANGLE``)
   whose two planes fit at least ``SHARP_RATIO`` times better than the quadric is a
   **crease**, whose line lends flags (step 4) as a sharp edge's does (:func:`fold_kinds`).
   So the flags change no kept point: the features decide.
3. **Borrowed edges** — a candidate that its own fit does not flag (the fit failed, or found
   another, farther edge) is located by the line of a flagged neighbour on a sharp edge
   (:func:`borrow`).
4. **The whole band** — steps 2-3 give the **core band**: the points nearest each fitted line,
   narrower beside soft edges and for borrowed lines (tuned when every flagged point was kept:
   each is budget taken from the faces); a simplification samples it first for the points
   kept for certain, and its refinement never swaps them out. The **features** add every
   point within ``width`` spacings of the line of a sharp fitted neighbour
   (:func:`line_distances`), candidate or not: a point one spacing from a 50° fold deviates
   too little to be a candidate.
5. **The flags** (``SimplifyResult.boundary``, the ``sharp_edge`` dimension; since
   2026-12-06) — every point within ``width`` cloud spacings of the line of one of its
   ``FLAG_FITS`` nearest **lenders** (the fits on a sharp edge or a crease within ``width``
   of their own line, or within ``FAR_FIT`` widths where a second fit's line confirms theirs:
   :func:`confirmed_lines`), and the points their own corner fit flags
   (:func:`nearest_line_distances`): the nearest fits' lines stand for the edge beside the
   point, which the ground truth measures in cloud spacings.

So flags are the points "on or within about one spacing of a sharp edge" — the ground truth of
DESIGN.md §4 — whatever the noise and the scan-line anisotropy.
"""

import numpy as np

from ._jit import jit, jit_inline, jit_leaf
from .boundary import deviation_at
from .cell_grid import sq_dist
from .linalg import (NO_MOMENTS, add_moments, covariance_about, moments_covariance,
                     orient_canonical, smallest_axis, solve_small, sym3_eigvals, tangent_basis)

#: default candidate threshold on the smoothed deviation (radians, ~4.6°)
CANDIDATE = 0.08
#: default: flag candidates within this many local spacings of the fitted edge
WIDTH = 1.0
#: default of the option ``edge_angle``, passed to :func:`localise` as ``min_angle``: planes
#: meeting at less than this angle (degrees) give no sharp edge (truth: > 30°). At an
#: ordinary edge that angle is the faces' **fold** (the angle between their outward normals:
#: 180° less the angle between the two half-planes); a wedge, whose faces meet at less than
#: 90°, folds by 180° less it. The fold is what :func:`band` and :func:`borrow` see (a 50°
#: wedge folds by 130°: sharp, not soft; :func:`_fit_edge`); wedges of less than this angle
#: are not found. 40 against 45, measured on the 38 quality cases (coverage mode, edge coverage
#: by arc length): edge coverage above every peer's on 29 of 36 CAD cases, not 28 (rocker-arm
#: 0.924 against CGAL hierarchy's 0.923: 64 % of its sharp-edge length folds by 30-40°),
#: geometric means mean surface error -0.6 %, coverage +0.3 %, boundary F1 +0.6 % (idler_riser
#: scans 0.44 -> 0.49 and 0.41 -> 0.43, plate_holes 0.70 -> 0.67: fillets), Hausdorff +0.5 %;
#: the Bunny 17.04 -> 17.23 (best peer 17.27) with 1,420 flags, not 1,272. 35 (on the first 11
#: cases): F1 -1.4 %, Hausdorff +1.2 %.
#: (Before the coverage sampled by arc length, 40 lost ADIS16480's coverage to a peer.)
MIN_ANGLE = 40.0
#: edges whose faces fold by less than this angle (degrees) are **soft**: flagged only within
#: ``SOFT_WIDTH`` times the band width (see :func:`band`)
SOFT_ANGLE = 60.0
#: band width of soft edges, as a fraction of the ``width`` of sharper ones
SOFT_WIDTH = 0.7
#: band width of borrowed edges (:func:`borrow`), as a fraction of ``width``: only the points
#: right on the edge, where fits fail most (0.5 against 1.0 on the 37 quality cases: Hausdorff
#: within 1.2x the best peer's on 28 against 22, featuretype flags 3,064 against 3,468 of its
#: 4,000 budget)
BORROW_WIDTH = 0.5
#: each side of a fitted edge needs at least this many points
MIN_SIDE = 3
#: a side of the fit may deviate from its plane by at most this RMS (local spacings). Measured
#: on the 37 quality cases (``benchmarks/quality.py``, coverage mode) against 0.4: at 0.8 mean
#: surface error -1.2 % (geometric mean; below every peer's on 32 cases, not 30: plate_holes-
#: scan0.1 11.33 vs 11.44, cycloidal 44.25 vs 44.45), edge coverage +0.6 %, Hausdorff +0.2 %,
#: boundary F1 median 0.500 -> 0.507 (scans), 0.716 -> 0.713 (even). Rougher sides than 0.4
#: are mostly real edges on a noisy scan or beside a fillet; the ``MAX_MIXED`` and
#: ``MIN_ANGLE`` tests reject the wrong splits. 0.6: mean -1.1 %; 1.2 and no limit: the same
#: as 0.8 within 0.1 %.
MAX_RMS = 0.8
#: a side's points must spread at least this much (RMS, local spacings) across their principal
#: axis: a single row of points (one scan line, a strip cut off a noisy plane) fixes no plane
MIN_SPREAD = 0.25
#: at most this fraction of a side's points may lie on the wrong side of the fitted edge
MAX_MIXED = 0.1
#: each side of a two-plane fit holds at least this many points farther than half a spacing
#: from the fitted line: on a scan, a side of one scan line along the line and one point far
#: off it fits its plane exactly at whatever tilt that point gives (Fandisk's scans: creases
#: folding 45-60° along a scan line on a smooth face). Measured on the 39 quality cases
#: (docs/measurements.md "A face needs two points off its line"): boundary F1 geometric mean
#: on the 24 scans +0.9 % (Fandisk's 0.767 -> 0.784 and 0.737 -> 0.759, plate_holes' noise-0.1
#: scan 0.868 -> 0.901), on the 12 even parts -0.2 %; 3 trades recall for precision
#: (8 cases: ADIS16480's noise-0.1 scan 0.613 -> 0.597, plate_holes 0.872 -> 0.866)
MIN_OFF = 2
#: rounds of assign-and-refit in the two-plane fit
ROUNDS = 4
#: rings of the local mesh the two-plane fit uses (3 measured: Fandisk F1 0.91 -> 0.86)
FIT_RINGS = 2
#: most points gathered in a neighbourhood
MAX_RING = 128
#: line directions the sweep split tries (3, 4, 6, 8 and 12 measured, before ``SWEEP_SIDE`` and
#: ``MIN_SPREAD`` existed: median F1 over the 12 even and 12 noise-0.1 scan CAD cases the same
#: within 0.002, as the k-means rounds after the sweep correct the direction)
NDIR = 4
#: each side of a sweep split holds at least this fraction of the neighbours (and ``MIN_SIDE``):
#: three points always fit a plane exactly, so unbounded, the least-squares sweep would cut
#: tiny exact sides off a noisy plane. (Geometry, not measured: a disc cut at 0.4 of its radius
#: from the centre leaves a quarter on the far side, about where a point one spacing from an
#: edge has its two-ring.)
SWEEP_SIDE = 0.2
#: a two-plane fit is a smooth fold, not a sharp edge, where one quadric height field
#: (:func:`_quadric_sse`) fits the two-ring with less than this fraction of the two planes'
#: squared error: a fillet or small cylinder, curved, not folded. Measured on the 38 quality
#: cases (coverage mode, flags only; docs/measurements.md "Smooth folds"): boundary F1 of the
#: even CAD parts +2.8 % (geometric mean; plate_holes 0.692 -> 0.793, featuretype 0.760 ->
#: 0.830, ADIS16480 0.662 -> 0.725), of the scans +0.2 %; idler_riser 0.872 -> 0.868, its
#: noise-0.1 scan 0.572 -> 0.545 (its true edges beside curved faces fit a quadric nearly as
#: well). 0.36: +2.6 % / +0.3 % (plate_holes 0.780, idler_riser 0.874); 1.0: plate_holes
#: 0.823 but idler_riser 0.832 (recall 0.810 -> 0.732)
SMOOTH_RATIO = 0.5
#: a soft fold (less than ``SOFT_ANGLE``) whose two planes fit its two-ring with at most 1 / this
#: of one quadric height field's squared error is a **crease**: its line lends flags as a sharp
#: edge's does (:func:`fold_kinds`, :func:`nearest_line_distances`). Soft folds lend no flags
#: otherwise: most used to be fillets. The features (what is kept) do not change. Measured on
#: the 38 quality cases (flags only; docs/measurements.md "Creases"): boundary F1 geometric
#: mean +1.2 % (idler_riser 0.868 -> 0.935, its noise-0.1 scan 0.545 -> 0.639, counter's 0.453
#: -> 0.534; plate_holes 0.793 -> 0.767); 2: +2.1 % but octagonal_pocket 0.856 -> 0.848 and
#: plate_holes 0.690; every soft fold (0): +1.5 %, plate_holes 0.571. Again with the flags of
#: the nearest lines (2026-12-06), F1 geometric mean of the 12 even / 24 scanned CAD cases: 4
#: 0.643 / 0.627, 8: 0.645 / 0.617 (plate_holes 0.812 -> 0.853, idler_riser's noise-0.1 scan
#: 0.566 -> 0.487), 20: 0.643 / 0.609, none: 0.635 / 0.610
SHARP_RATIO = 4.0
#: ... or whose quadric's squared error exceeds the two planes' by this many squared local
#: spacings a point of the two-ring: scanner noise adds to both errors alike, so their ratio
#: falls towards 1 on a noisy scan while their difference stays. Measured on the 36 CAD quality
#: cases (flags only; docs/measurements.md "Creases by the quadric's excess error"): boundary
#: F1 geometric mean of the 12 even / 24 scanned parts 0.676 / 0.633 -> 0.677 / 0.647
#: (idler_riser's scans 0.570 -> 0.632 and 0.473 -> 0.583, counter's 0.674 -> 0.733 and 0.559 ->
#: 0.637; plate_holes' noise-0.2 scan 0.800 -> 0.774, featuretype 0.863 -> 0.858); 0.008:
#: 0.676 / 0.649 but plate_holes 0.818 -> 0.803
CREASE_EXCESS = 0.012
#: the flags (:func:`nearest_line_distances`): the points within ``width`` cloud spacings of
#: the line of one of their ``FLAG_FITS`` nearest lenders within ``FLAG_REACH`` spacings
FLAG_FITS = 3
#: how far (cloud spacings) a lender's line reaches for the flags
FLAG_REACH = 4.0
#: most points a lender's line reaches (a dense patch: the nearest by the local mesh's rings)
MAX_REACH_POINTS = 512
#: a fit whose own point lies beyond ``width`` of its line, but within this many widths, lends
#: flags where another fit confirms its line (:func:`confirmed_lines`): the edges whose own
#: points fit no line near them (cycloidal's teeth, counter's threads, the noisy scans' rows)
FAR_FIT = 2.0
#: ... a fit within this many cloud spacings of it, through the local mesh, ...
CONFIRM_REACH = 3.0
#: ... whose line passes within this many cloud spacings of the foot of its point on its line
CONFIRM_OFFSET = 0.3
#: ... and runs within this angle (degrees) of it
CONFIRM_ANGLE = 20.0
#: a two-ring whose heights over its mean plane fall into two layers at least this many local
#: spacings apart (:func:`own_layer`) ...
LAYER_GAP_MIN = 0.5
#: ... and at most this many (farther layers are two surfaces the local mesh rarely joins) ...
LAYER_GAP_MAX = 3.0
#: ... each layer's RMS height about its mean at most this fraction of the gap, is two sheets —
#: a thin wall's faces, the faces two scan views saw of it — and the fit takes the point's own
#: (measured on the 36 CAD quality cases, docs/measurements.md "Thin walls: each sheet fitted
#: alone": 0.25 against 0.3, whose layers are also the two faces of some edges)
LAYER_RMS = 0.25
#: a two-plane fit that finds no edge is tried once more over the two-ring's points within this
#: many local spacings of the point (:func:`near_part`; measured on the 36 CAD quality cases,
#: docs/measurements.md "Scans: the near part of the two-ring": 4, 5 and 6)
NEAR_RING = 5.0
#: a candidate that no two-plane fit gives an edge is tried as a step (:func:`_fit_step`) over
#: its two-ring's points within this many local spacings ...
STEP_RING = 2.5
#: ... two parallel layers, their heights' means this many local spacings apart at least ...
STEP_GAP_MIN = 0.45
#: ... and at most (a taller step has a wall the two-plane fits see) ...
STEP_GAP_MAX = 1.5
#: ... each layer's RMS height about its mean at most this fraction of the gap ...
STEP_RMS = 0.25
#: ... each layer's own plane within this cosine of the other's and of the heights' normal ...
STEP_PARALLEL = 0.99
#: ... and the layers side by side: at most this share of the points on the wrong side of the
#: best line between them in the layers' plane (a thin wall's faces overlap; measured on
#: counter's rib and the 36 CAD quality cases, docs/measurements.md "Steps lower than a
#: spacing")
STEP_MIXED = 0.1
#: a candidate in two sheets that no other fit gives an edge is tried as a thin wall's rim
#: (:func:`_fit_rim`): its two-ring's mean offset in the sheets' plane at least this many local
#: spacings from the point (the two-ring lies to one side of it) ...
RIM_OFFSET = 0.6
#: ... both sheets reaching within this many local spacings of the farther one's border ...
RIM_TOGETHER = 1.0
#: ... the point within this many local spacings of that border ...
RIM_REACH = 1.0
#: ... and no point of its three-ring beyond the border by more than this many local spacings,
#: as far as the three-ring reaches behind the point (:func:`_rim_clear`; measured on the 36
#: CAD quality cases, docs/measurements.md "Thin walls' rims")
RIM_CLEAR = 0.5
#: a thin wall's border where no rim fits (:func:`_border_gap`; measured on the 39 quality
#: cases, docs/measurements.md "A thin wall's border"): the points of the three-ring within
#: ``BORDER_REACH`` local spacings, projected on the sheets' plane, leave an empty angle of at
#: least ``BORDER_GAP`` degrees about the point (100 / 140: the tray's F1 0.720 / 0.714, at
#: precision 0.733 / 0.816; 0.713 at 0.795 with 120) ...
BORDER_REACH = 2.5
BORDER_GAP = 120.0
#: ... and none other wider than ``BORDER_SECOND`` degrees, among ``BORDER_MIN`` points or more
BORDER_SECOND = 75.0
BORDER_MIN = 6
#: the border test needs a sampling that fills the tangent plane: a line scan leaves empty
#: angles of 180° between its lines everywhere. Filled: the median empty angle of the points'
#: two-rings (:func:`median_ring_gap`) below this many degrees: 52-60° on the 12 evenly
#: sampled CAD parts of the quality cases, 177-181° on their 24 line scans; the Bunny 53°,
#: Autzen's LiDAR 82°, the Bunny's ten range scans 110°
FILLED_GAP = 90.0
#: a crease whose faces, each fitted by a parabola across its line, fold by less than this
#: there (degrees) is a fillet's tangent edge, not a crease (:func:`_fold_at_line`)
LINE_FOLD = 21.0


@jit_leaf
def near_part(X, idx, c, radius):
    """The points of ``idx[:c]`` within ``radius`` of ``X[idx[0]]``: compacts ``idx``
    (``idx[0]`` stays first) and returns their count.

    Beyond the paper. On a line scan the local spacing is the spacing along a line, and the
    lines lie about four of them apart (:func:`.synthetic.scan`'s ``line_spacing_ratio``), so
    a two-ring reaches some eight local spacings across the lines — past a narrow face to the
    next one, or over a curved face that is no plane that far out. Its two-plane fit then
    fails (sides interleaved, planes near parallel) on edges a two-ring half as wide fits:
    374 of the 482 missed edge points of octagonal_pocket's noise-0.1 scan (edges seen from
    both sides) had no fit, and 99 of them fit a sharp edge within a spacing over the points
    within 6 spacings (61 within 4). On an even sampling the two-ring lies within that
    radius.
    """
    p = idx[0]
    r2 = radius * radius
    m = 0
    for j in range(c):
        q = idx[j]
        dx, dy, dz = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
        if dx * dx + dy * dy + dz * dz <= r2:
            idx[m] = q
            m += 1
    return m


@jit_leaf
def _two_means(h, c):
    """A 1-D 2-means of ``h[:c]`` (Lloyd's rounds from the midrange, at most 8):
    ``(ok, cut, m0, m1, k0, k1, v0, v1)`` — the cut, each layer's mean, count and sum of
    squared deviations from its mean (``h > cut``: layer 1); ``ok`` False where a layer
    holds fewer than ``MIN_SIDE`` points."""
    lo = np.inf
    hi = -np.inf
    for j in range(c):
        lo = min(lo, h[j])
        hi = max(hi, h[j])
    cut = 0.5 * (lo + hi)
    m0 = m1 = 0.0
    k0 = k1 = 0
    for _ in range(8):  # Lloyd's rounds in 1-D: the cut halfway between the layers' means
        m0 = m1 = 0.0
        k0 = k1 = 0
        for j in range(c):
            if h[j] > cut:
                m1 += h[j]
                k1 += 1
            else:
                m0 += h[j]
                k0 += 1
        if k0 < MIN_SIDE or k1 < MIN_SIDE:
            return False, cut, 0.0, 0.0, k0, k1, 0.0, 0.0
        m0 /= k0
        m1 /= k1
        if 0.5 * (m0 + m1) == cut:
            break
        cut = 0.5 * (m0 + m1)
    v0 = v1 = 0.0
    for j in range(c):
        if h[j] > cut:
            v1 += (h[j] - m1) ** 2
        else:
            v0 += (h[j] - m0) ** 2
    return True, cut, m0, m1, k0, k1, v0, v1


@jit
def _fit_step(X, normals, idx, c, spacing, h, a, line, t1, t2, work):
    """A step lower than the spacing at ``idx[0]``: ``distance`` from it to the step's edge
    (``inf`` where ``idx[:c]`` is no step), the edge into ``line`` (:func:`_edge_line`'s form).

    Beyond the paper. A face that steps up by less than a spacing — counter's rib, 1.5 mm tall
    at a 2.25 mm spacing — has a wall with few or no points, so no two-plane fit finds its
    edges, and the two-ring's PCA plane tilts across the step, mixing the levels' heights.
    Here the heights are taken along each point's one-ring normal in turn (``normals``) and
    split by a 1-D 2-means (:func:`_two_means`); the normal whose two layers lie
    ``STEP_GAP_MIN``-``STEP_GAP_MAX`` local ``spacing``s apart with the least RMS height
    about their means (at most ``STEP_RMS`` of the gap) is the step's. Both layers' own
    planes must be parallel to it and to each other (``STEP_PARALLEL``: a curved face split
    by height is not), and the layers must lie side by side in that plane: a line
    separates them with at most ``STEP_MIXED`` of the points on its wrong side (a thin wall's
    two faces lie one over the other). The edge runs along that line at the layers' mid
    height, across ``u``, the direction from the lower layer's centre to the upper's; both of
    the step's edges lie within half its height of it. ``h``, ``a``: work arrays of length
    ``c`` or more; ``t1``, ``t2``, ``work``: length 3.
    """
    p = idx[0]
    if c < 2 * MIN_SIDE + 1:
        return np.inf
    best = np.inf
    bq = -1
    for jq in range(c):
        q = idx[jq]
        for j in range(c):
            r = idx[j]
            h[j] = ((X[r, 0] - X[p, 0]) * normals[q, 0] + (X[r, 1] - X[p, 1]) * normals[q, 1]
                    + (X[r, 2] - X[p, 2]) * normals[q, 2])
        ok, cut, m0, m1, k0, k1, v0, v1 = _two_means(h, c)
        if not ok:
            continue
        gap = m1 - m0
        if gap < STEP_GAP_MIN * spacing or gap > STEP_GAP_MAX * spacing:
            continue
        score = max(v0 / k0, v1 / k1) / (gap * gap)
        if score < best:
            best = score
            bq = q
    if bq < 0 or best > STEP_RMS * STEP_RMS:
        return np.inf
    nx, ny, nz = normals[bq, 0], normals[bq, 1], normals[bq, 2]
    for j in range(c):
        r = idx[j]
        h[j] = (X[r, 0] - X[p, 0]) * nx + (X[r, 1] - X[p, 1]) * ny + (X[r, 2] - X[p, 2]) * nz
    ok, cut, m0, m1, k0, k1, v0, v1 = _two_means(h, c)
    # each layer's own plane parallel to the other's and to the heights' normal
    n0 = np.empty(3)
    n1 = np.empty(3)
    sub = np.empty(c, dtype=np.int64)
    for which in range(2):
        k = 0
        for j in range(c):
            if (h[j] > cut) == (which == 1):
                sub[k] = idx[j]
                k += 1
        out = n0 if which == 0 else n1
        smallest_axis(*covariance_about(X, sub[0], sub[1:k], k - 1), out, work)
        if abs(out[0] * nx + out[1] * ny + out[2] * nz) < STEP_PARALLEL:
            return np.inf
    if abs(n0[0] * n1[0] + n0[1] * n1[1] + n0[2] * n1[2]) < STEP_PARALLEL:
        return np.inf
    # side by side: the best cut along the direction between the layers' centres
    work[0], work[1], work[2] = nx, ny, nz
    tangent_basis(work, t1, t2)
    u1 = u2 = 0.0
    for j in range(c):
        r = idx[j]
        x1 = (X[r, 0] - X[p, 0]) * t1[0] + (X[r, 1] - X[p, 1]) * t1[1] + (X[r, 2] - X[p, 2]) * t1[2]
        x2 = (X[r, 0] - X[p, 0]) * t2[0] + (X[r, 1] - X[p, 1]) * t2[1] + (X[r, 2] - X[p, 2]) * t2[2]
        if h[j] > cut:
            u1 += x1 / k1
            u2 += x2 / k1
        else:
            u1 -= x1 / k0
            u2 -= x2 / k0
    un = np.sqrt(u1 * u1 + u2 * u2)
    if not un > 0.0:
        return np.inf
    u1 /= un
    u2 /= un
    ux = u1 * t1[0] + u2 * t2[0]  # u in space
    uy = u1 * t1[1] + u2 * t2[1]
    uz = u1 * t1[2] + u2 * t2[2]
    for j in range(c):
        r = idx[j]
        a[j] = (X[r, 0] - X[p, 0]) * ux + (X[r, 1] - X[p, 1]) * uy + (X[r, 2] - X[p, 2]) * uz
    order = np.argsort(a[:c])
    wrong = k0  # cut before the first point: every lower point on the upper side
    least = wrong
    at = 0
    for i in range(c):
        if h[order[i]] > cut:
            wrong += 1
        else:
            wrong -= 1
        if wrong < least:
            least = wrong
            at = i + 1
    if least > STEP_MIXED * c:
        return np.inf
    lo_a = a[order[at - 1]] if at > 0 else a[order[0]]
    hi_a = a[order[at]] if at < c else a[order[c - 1]]
    off = 0.5 * (lo_a + hi_a)
    mid = 0.5 * (m0 + m1)
    line[0] = X[p, 0] + off * ux + mid * nx
    line[1] = X[p, 1] + off * uy + mid * ny
    line[2] = X[p, 2] + off * uz + mid * nz
    dx, dy, dz = ny * uz - nz * uy, nz * ux - nx * uz, nx * uy - ny * ux
    dn = np.sqrt(dx * dx + dy * dy + dz * dz)
    line[3], line[4], line[5] = dx / dn, dy / dn, dz / dn
    return np.sqrt(off * off + mid * mid)


@jit
def _fit_rim(X, idx, c, spacing, h, normal, line, out_dir):
    """A thin wall's rim at ``idx[0]``: the distance from it to the rim's edge on its own sheet
    (``inf`` where ``idx[:c]`` shows no rim), the edge into ``line`` (:func:`_edge_line`'s
    form), the direction from the point across the edge, in the sheets' plane, into
    ``out_dir``. ``normal``: the two-ring's PCA normal, as :func:`own_layer` left it.

    Beyond the paper. Where a plate is thinner than about two spacings (the tray, 3.18 mm at a
    2.63 mm spacing) its rim face holds a point or two across, and each sheet of its two-ring
    (:func:`own_layer`) is a plane that ends: no two-plane fit, step or corner finds the edge
    (876 of the tray's 1,013 missed edge points had no fit). Here the two-ring
    ``idx[:c]`` — both sheets — is taken in its PCA plane: it lies to one side of the point
    where its mean offset in that plane is ``RIM_OFFSET`` local spacings (``spacing``) or
    more, and the border runs across that offset, through the farthest point the other way.
    Both sheets (a 1-D 2-means of the heights, :func:`_two_means`) must reach within
    ``RIM_TOGETHER`` of that border — a wall's faces end together — and the point must lie
    within ``RIM_REACH`` of it. The edge is the border's line in the point's own sheet.
    ``h``: work array of length ``c`` or more.
    """
    p = idx[0]
    if c < 2 * MIN_SIDE + 1:
        return np.inf
    nx, ny, nz = normal[0], normal[1], normal[2]
    gx = gy = gz = 0.0
    for j in range(c):
        q = idx[j]
        dx, dy, dz = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
        hj = dx * nx + dy * ny + dz * nz
        h[j] = hj
        gx += dx - hj * nx
        gy += dy - hj * ny
        gz += dz - hj * nz
    g = np.sqrt(gx * gx + gy * gy + gz * gz)
    if g < RIM_OFFSET * spacing * c:
        return np.inf
    bx, by, bz = -gx / g, -gy / g, -gz / g  # across the border, away from the two-ring
    ok, cut, m0, m1, k0, k1, v0, v1 = _two_means(h, c)
    if not ok:
        return np.inf
    d0 = d1 = -np.inf
    for j in range(c):
        q = idx[j]
        a = (X[q, 0] - X[p, 0]) * bx + (X[q, 1] - X[p, 1]) * by + (X[q, 2] - X[p, 2]) * bz
        if h[j] > cut:
            d1 = max(d1, a)
        else:
            d0 = max(d0, a)
    d = max(d0, d1)
    if min(d0, d1) < d - RIM_TOGETHER * spacing or d > RIM_REACH * spacing:
        return np.inf
    out_dir[0], out_dir[1], out_dir[2] = bx, by, bz
    line[0] = X[p, 0] + d * bx
    line[1] = X[p, 1] + d * by
    line[2] = X[p, 2] + d * bz
    line[3] = ny * bz - nz * by  # normal × out_dir: both unit and orthogonal
    line[4] = nz * bx - nx * bz
    line[5] = nx * by - ny * bx
    return d


@jit_leaf
def _rim_clear(X, p, ring, k, d, spacing, out_dir, normal):
    """Whether nothing lies beyond the rim :func:`_fit_rim` found ``d`` from ``X[p]`` across
    ``out_dir``: no point of ``ring[:k]`` (the point's three-ring) within ``LAYER_GAP_MAX``
    local spacings (``spacing``) of its sheet's plane (``normal``) lies more than ``RIM_CLEAR``
    spacings past the border and nearer to it than the farthest point lies behind.

    Beyond the paper. On a line scan a point's local mesh may join the lines on one side of
    its own only, and so its two-ring ends one spacing past it, like a rim's (the tray's
    scans: 37 of 104 such fits at 8-27 spacings from any edge, on both faces' lines); the
    next line lies some four local spacings on, within the three-ring. ``ring``: the point's
    three-ring (:func:`gather_rings`)."""
    back = 0.0
    for j in range(k):
        q = ring[j]
        a = ((X[q, 0] - X[p, 0]) * out_dir[0] + (X[q, 1] - X[p, 1]) * out_dir[1]
             + (X[q, 2] - X[p, 2]) * out_dir[2])
        back = max(back, -a)
    for j in range(k):
        q = ring[j]
        dx, dy, dz = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
        a = dx * out_dir[0] + dy * out_dir[1] + dz * out_dir[2]
        hq = dx * normal[0] + dy * normal[1] + dz * normal[2]
        if d + RIM_CLEAR * spacing < a < d + back and abs(hq) <= LAYER_GAP_MAX * spacing:
            return False
    return True


@jit_leaf
def _sort_in_place(a, m):
    """Sorts ``a[:m]`` in place, by insertion: the few dozen values of a two- or three-ring,
    without the copy ``np.sort`` or ``np.median`` makes, and quicker to compile."""
    for i in range(1, m):
        v = a[i]
        j = i - 1
        while j >= 0 and a[j] > v:
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = v


@jit_leaf
def _largest_gap(ang, m):
    """``(largest, second, start)``: the two widest empty angles between the angles
    ``ang[:m]`` (radians, m >= 2; sorted here, in place: :func:`_sort_in_place`), the widest's
    start angle."""
    _sort_in_place(ang, m)
    largest = second = 0.0
    start = 0.0
    for i in range(m):
        g = (ang[i + 1] if i + 1 < m else ang[0] + 2.0 * np.pi) - ang[i]
        if g > largest:
            second = largest
            largest = g
            start = ang[i]
        elif g > second:
            second = g
    return largest, second, start


@jit
def _border_gap(X, p, ring, k, spacing, normal, ang, line, u, v):
    """A thin wall's border at ``X[p]``: 0 with the border's line through the point into
    ``line`` where ``ring[:k]`` (its three-ring) leaves an empty angle about it, ``inf``
    where it does not. The points within ``LAYER_GAP_MAX`` local spacings (``spacing``) of
    the sheets' plane (``normal``: both sheets, a hole passes through both) and within
    ``BORDER_REACH`` of the point, projected on that plane, must leave one empty angle of
    ``BORDER_GAP`` or more and no other of ``BORDER_SECOND``; the line runs in the plane across
    the empty angle's bisector. ``ang``: work array of length ``k`` or more; ``u``, ``v``:
    work vectors (the plane's basis).

    Beyond the paper. A rim (:func:`_fit_rim`) needs the whole two-ring to one side of the
    point, both sheets ending together within a spacing. The empty angle about a point is the
    classic border test of an open surface's sampling (PCL's boundary estimation takes 90°):
    inside the tray's faces, evenly sampled, the widest is 48-78° (10th-90th percentile); it
    exceeds 100° at 85 % of the points within half a spacing of an edge (both measured on the
    point's own sheet, docs/measurements.md "A thin wall's border"). In ``simplify_points``
    it adds 99 to the tray's 303 rim fits, all 402 within a spacing of an edge, along its outer rim
    and slot where :func:`_fit_rim`'s tests fail: F1 0.682 -> 0.713. Not its small holes (3.8
    spacings across at 20k points): a hole's wall projects onto its circle, whose points fill
    all but some 100° about a point on it. On line scans the angle reads 180° everywhere:
    :func:`localise` tries it only on samplings that fill the plane (``FILLED_GAP``).
    """
    nx, ny, nz = normal[0], normal[1], normal[2]
    tangent_basis(normal, u, v)
    r2 = (BORDER_REACH * spacing) ** 2
    hmax = LAYER_GAP_MAX * spacing
    m = 0
    for j in range(k):
        q = ring[j]
        if q == p:
            continue
        dx, dy, dz = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
        h = dx * nx + dy * ny + dz * nz
        if abs(h) > hmax:
            continue
        tx, ty, tz = dx - h * nx, dy - h * ny, dz - h * nz
        t2 = tx * tx + ty * ty + tz * tz
        if t2 > r2 or t2 <= 0.0:
            continue
        ang[m] = np.arctan2(tx * v[0] + ty * v[1] + tz * v[2], tx * u[0] + ty * u[1] + tz * u[2])
        m += 1
    if m < BORDER_MIN:
        return np.inf
    largest, second, start = _largest_gap(ang, m)
    if largest < np.deg2rad(BORDER_GAP) or second >= np.deg2rad(BORDER_SECOND):
        return np.inf
    mid = start + 0.5 * largest
    bx = np.cos(mid) * u[0] + np.sin(mid) * v[0]
    by = np.cos(mid) * u[1] + np.sin(mid) * v[1]
    bz = np.cos(mid) * u[2] + np.sin(mid) * v[2]
    line[0], line[1], line[2] = X[p, 0], X[p, 1], X[p, 2]
    line[3] = ny * bz - nz * by  # normal × the bisector: both unit and orthogonal
    line[4] = nz * bx - nx * bz
    line[5] = nx * by - ny * bx
    return 0.0


@jit
def median_ring_gap(X, normals, dn, dn_cnt, spacing, n_sample):
    """The median, over about ``n_sample`` points spread through ``X`` (every
    ``len(X) // n_sample``-th), of the widest empty angle (degrees) about each point among its
    two-ring's points within ``BORDER_REACH`` cloud ``spacing``s, projected on its tangent
    plane (``normals``): whether a sampling fills its tangent planes (below ``FILLED_GAP``), as
    :func:`_border_gap` needs. 360 where fewer than two points are in reach.
    """
    n = X.shape[0]
    if n < 3:
        return 360.0
    step = max(1, n // max(1, n_sample))
    mark = np.zeros(n, dtype=np.int64)
    idx = np.empty(MAX_RING, dtype=np.int64)
    ang = np.empty(MAX_RING)
    u = np.empty(3)
    v = np.empty(3)
    r2 = (BORDER_REACH * spacing) ** 2
    gaps = np.empty(n // step + 1)
    g = 0
    for p in range(0, n, step):
        c = gather_rings(p, dn, dn_cnt, 2, mark, idx)
        if c < 3:
            gaps[g] = 360.0
            g += 1
            continue
        tangent_basis(normals[p], u, v)
        m = 0
        for j in range(c):
            q = idx[j]
            d2 = sq_dist(X, q, X[p])
            if d2 > r2 or d2 <= 0.0:
                continue
            dx, dy, dz = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
            ang[m] = np.arctan2(dx * v[0] + dy * v[1] + dz * v[2],
                                dx * u[0] + dy * u[1] + dz * u[2])
            m += 1
        if m < 2:
            gaps[g] = 360.0
        else:
            gaps[g] = np.rad2deg(_largest_gap(ang, m)[0])
        g += 1
    return np.median(gaps[:g])


@jit_leaf
def own_layer(X, idx, c, spacing, h, normal, work):
    """The points of ``idx[:c]`` in ``idx[0]``'s own layer, where they lie in two: compacts
    ``idx`` (``idx[0]`` stays first) and returns the new count; ``c`` where they do not.

    Beyond the paper. Where a wall is thinner than about two spacings — a sheet, the tray's 3.18
    mm plate sampled at 2.63 mm, the faces of a scanned plate that two views saw — the local
    mesh joins both faces, and a two-plane fit sees two parallel planes (no edge: 612 of the
    813 candidates among the tray's 920 missed edge points) or a wedge across them (false edges along the lines where
    the views' scan lines cross). The heights ``h[j]`` of the points over their mean plane (the
    PCA plane of ``idx[:c]``, its normal into ``normal``) are split in two by a 1-D 2-means;
    two layers are two sheets where their means lie ``LAYER_GAP_MIN``-``LAYER_GAP_MAX`` local
    ``spacing``s apart, each holds ``MIN_SIDE`` points or more, and each one's RMS height about
    its mean is at most ``LAYER_RMS`` of the gap: one face split by height — curved, or the two
    faces of an edge — mostly spreads over the gap. Not always: some two-rings at edges pass
    (a sharp 90° roof of random points, noise 0.1: 40 fits within a spacing, 43 without this),
    and part of idler_riser's and plate_holes' gains came from such splits (docs/measurements.md
    "Thin walls: each sheet fitted alone"). ``h``: work array of length ``c`` or more;
    ``work``: length 3.
    """
    p = idx[0]
    smallest_axis(*covariance_about(X, p, idx[1:], c - 1), normal, work)
    lo = np.inf
    hi = -np.inf
    for j in range(c):
        q = idx[j]
        h[j] = ((X[q, 0] - X[p, 0]) * normal[0] + (X[q, 1] - X[p, 1]) * normal[1]
                + (X[q, 2] - X[p, 2]) * normal[2])
        lo = min(lo, h[j])
        hi = max(hi, h[j])
    if hi - lo < LAYER_GAP_MIN * spacing:
        return c
    ok, cut, m0, m1, k0, k1, v0, v1 = _two_means(h, c)
    if not ok:
        return c
    gap = m1 - m0
    if gap < LAYER_GAP_MIN * spacing or gap > LAYER_GAP_MAX * spacing:
        return c
    limit = (LAYER_RMS * gap) ** 2
    if v0 > limit * k0 or v1 > limit * k1:
        return c
    upper = h[0] > cut
    m = 0
    for j in range(c):
        if (h[j] > cut) == upper:
            idx[m] = idx[j]
            m += 1
    return m


@jit_leaf
def _median_in_place(a, c):
    """``np.median(a[:c])`` (``c`` >= 1, no NaN), sorting ``a[:c]`` in place
    (:func:`_sort_in_place`): the middle value, or the mean ``(a + b) / 2`` of the middle two
    as numpy's."""
    _sort_in_place(a, c)
    half = c >> 1
    if c & 1 == 0:
        return (a[half - 1] + a[half]) / 2
    return a[half]


@jit_leaf
def gather_rings(p, dn, dn_cnt, rings, mark, out):
    """``p``'s local-mesh neighbours up to ``rings`` rings away, without ``p``, into ``out``.

    Returns the count (at most ``len(out)``). ``mark`` is an int64 work array of length n,
    zero-initialised once; it is stamped with ``p + 1`` so that no clearing is needed between
    points (each point is gathered once per pass).
    """
    stamp = p + 1
    mark[p] = stamp
    c = 0
    cap = out.shape[0]
    for j in range(dn_cnt[p]):
        q = dn[p, j]
        if mark[q] != stamp and c < cap:
            mark[q] = stamp
            out[c] = q
            c += 1
    lo = 0
    for _ in range(rings - 1):
        hi = c
        for i in range(lo, hi):
            r = out[i]
            for j in range(dn_cnt[r]):
                q = dn[r, j]
                if mark[q] != stamp and c < cap:
                    mark[q] = stamp
                    out[c] = q
                    c += 1
        lo = hi
    return c


@jit
def smoothed_deviations(X, dn, dn_cnt, normals_out, out):
    """Step 1: two-ring normals (PCA) and the paper's deviation measure over the two-ring."""
    n = X.shape[0]
    mark = np.zeros(n, dtype=np.int64)
    ring = np.empty(MAX_RING, dtype=np.int64)
    work = np.empty(3)
    for p in range(n):
        c = gather_rings(p, dn, dn_cnt, 2, mark, ring)
        c00, c01, c02, c11, c12, c22 = covariance_about(X, p, ring, c)
        smallest_axis(c00, c01, c02, c11, c12, c22, normals_out[p], work)
        orient_canonical(normals_out[p])
    A = np.empty((3, 3))
    b = np.empty(3)
    frame = np.empty((2, 3))
    mark[:] = 0
    for p in range(n):
        c = gather_rings(p, dn, dn_cnt, 2, mark, ring)
        out[p] = deviation_at(X, normals_out, p, ring, c, A, b, frame)


@jit_leaf
def _plane_fit(X, idx, c, side, which, centre, normal, work):
    """PCA plane of the points ``idx[j]`` with ``side[j] == which``; returns their number.

    Also ``work[0]``: the points' RMS distance to the plane, ``work[1]``: their RMS spread
    across their principal axis (small: nearly on a line, the plane's tilt about it is noise).
    """
    k = 0
    sx = sy = sz = 0.0
    for j in range(c):
        if side[j] == which:
            q = idx[j]
            sx += X[q, 0]
            sy += X[q, 1]
            sz += X[q, 2]
            k += 1
    if k < MIN_SIDE:
        return k
    mx, my, mz = sx / k, sy / k, sz / k
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    for j in range(c):
        if side[j] == which:
            q = idx[j]
            x, y, z = X[q, 0] - mx, X[q, 1] - my, X[q, 2] - mz
            c00 += x * x
            c01 += x * y
            c02 += x * z
            c11 += y * y
            c12 += y * z
            c22 += z * z
    work[0], work[1] = _plane_of(c00, c01, c02, c11, c12, c22, k, mx, my, mz, centre, normal,
                                 work)
    return k


@jit_leaf
def _plane_of(c00, c01, c02, c11, c12, c22, k, mx, my, mz, centre, normal, work):
    """The PCA plane of ``k`` points with mean ``(mx, my, mz)`` and scatter ``c..`` into
    ``centre`` and ``normal`` (``work``: scratch); returns the points' RMS distance to it and
    their RMS spread across their principal axis."""
    l0, l1, _ = smallest_axis(c00, c01, c02, c11, c12, c22, normal, work)
    centre[0], centre[1], centre[2] = mx, my, mz
    return np.sqrt(max(l0, 0.0) / k), np.sqrt(max(l1, 0.0) / k)


@jit_leaf
def _plane_fits(X, idx, c, side, c1, n1, c2, n2, work):
    """:func:`_plane_fit` of sides 0 and 1 at once, into ``c1, n1`` and ``c2, n2``: one pass
    over the points for both sides' means and one for their scatters, each side's sums taken
    in the same order as alone (so the same planes to the last bit). Returns ``(k0, k1, rms0,
    spread0)``: the sides' counts and side 0's RMS and spread; side 1's are left in ``work[0]``
    and ``work[1]``. Where a side holds fewer than ``MIN_SIDE`` points, no plane is fitted."""
    k0 = k1 = 0
    sx0 = sy0 = sz0 = sx1 = sy1 = sz1 = 0.0
    for j in range(c):
        q = idx[j]
        if side[j] == 0:
            sx0 += X[q, 0]
            sy0 += X[q, 1]
            sz0 += X[q, 2]
            k0 += 1
        elif side[j] == 1:
            sx1 += X[q, 0]
            sy1 += X[q, 1]
            sz1 += X[q, 2]
            k1 += 1
    if k0 < MIN_SIDE or k1 < MIN_SIDE:
        return k0, k1, 0.0, 0.0
    mx0, my0, mz0 = sx0 / k0, sy0 / k0, sz0 / k0
    mx1, my1, mz1 = sx1 / k1, sy1 / k1, sz1 / k1
    a00 = a01 = a02 = a11 = a12 = a22 = 0.0
    b00 = b01 = b02 = b11 = b12 = b22 = 0.0
    for j in range(c):
        q = idx[j]
        if side[j] == 0:
            x, y, z = X[q, 0] - mx0, X[q, 1] - my0, X[q, 2] - mz0
            a00 += x * x
            a01 += x * y
            a02 += x * z
            a11 += y * y
            a12 += y * z
            a22 += z * z
        elif side[j] == 1:
            x, y, z = X[q, 0] - mx1, X[q, 1] - my1, X[q, 2] - mz1
            b00 += x * x
            b01 += x * y
            b02 += x * z
            b11 += y * y
            b12 += y * z
            b22 += z * z
    rms0, spread0 = _plane_of(a00, a01, a02, a11, a12, a22, k0, mx0, my0, mz0, c1, n1, work)
    work[0], work[1] = _plane_of(b00, b01, b02, b11, b12, b22, k1, mx1, my1, mz1, c2, n2, work)
    return k0, k1, rms0, spread0


@jit_leaf
def _plane_distance(X, q, c, n):
    """Distance from ``X[q]`` to the plane through ``c`` with unit normal ``n``."""
    return abs((X[q, 0] - c[0]) * n[0] + (X[q, 1] - c[1]) * n[1] + (X[q, 2] - c[2]) * n[2])


@jit_leaf
def _dot(a, i, b, j):
    """``a[i] . b[j]`` of two (n, 3) arrays."""
    return a[i, 0] * b[j, 0] + a[i, 1] * b[j, 1] + a[i, 2] * b[j, 2]


@jit_leaf
def _least_parallel(normals, idx, c, ref):
    """The point of ``idx[:c]`` whose normal is least parallel to ``ref``'s (ties: first)."""
    arg = ref
    best = 2.0
    for j in range(c):
        q = idx[j]
        d = abs(_dot(normals, ref, normals, q))
        if d < best:
            best = d
            arg = q
    return arg


@jit_leaf
def _seed_by_normals(normals, idx, c, side):
    """Initial split: each point to the nearer in direction of two seed normals — the one
    least parallel to ``idx[0]``'s, then the one least parallel to that."""
    a = _least_parallel(normals, idx, c, idx[0])
    b = _least_parallel(normals, idx, c, a)
    for j in range(c):
        q = idx[j]
        da, db = abs(_dot(normals, a, normals, q)), abs(_dot(normals, b, normals, q))
        side[j] = 0 if da >= db else 1


@jit_inline
def _scatter(m, k):
    """The scatter matrix ``(a00, a01, a02, a11, a12, a22)`` of ``k`` points with running
    moments ``m`` (:data:`.linalg.NO_MOMENTS`)."""
    sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = m
    return (sxx - sx * sx / k, sxy - sx * sy / k, sxz - sx * sz / k,
            syy - sy * sy / k, syz - sy * sz / k, szz - sz * sz / k)


@jit_inline
def _scatter_by(m, r):
    """:func:`_scatter` with the division by the count ``k`` as a product by ``r = 1 / k``:
    the same matrix but for the last bits, for the bounds (:func:`_seed_by_sweep`)."""
    sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = m
    return (sxx - sx * sx * r, sxy - sx * sy * r, sxz - sx * sz * r,
            syy - sy * sy * r, syz - sy * sz * r, szz - sz * sz * r)


@jit
def _smallest_scatter(a00, a01, a02, a11, a12, a22):
    """Least eigenvalue of a scatter matrix (:func:`_scatter`): the points' sum of squared
    distances to their best plane."""
    l0, _, _ = sym3_eigvals(a00, a01, a02, a11, a12, a22)
    return max(l0, 0.0)


#: :func:`_seed_by_sweep` computes a split's eigenvalues only if its lower bound
#: (:func:`_scatter_floor`) falls short of the best so far plus this fraction of the whole
#: two-ring's trace (at least the two halves' traces). Estimated, not measured: that is far
#: above the rounding of the bound (see there) and of the trigonometric eigenvalues (about
#: sqrt(machine epsilon), 1e-8, of the trace where two of them nearly tie), so the split
#: chosen is the same
FLOOR_MARGIN = 1e-6
#: Newton steps :func:`_scatter_floor` takes after its first bound
FLOOR_STEPS = 2


@jit
def _scatter_floor(a00, a01, a02, a11, a12, a22):
    """A lower bound on :func:`_smallest_scatter` without eigenvalues.

    ``λ0`` is the least root of the characteristic polynomial ``p(λ) = det − M λ + T λ² − λ³``
    (``T`` the trace, ``M`` the sum of the principal 2x2 minors). On ``[0, λ0]`` it is
    decreasing and convex (``p'' = 2T − 6λ > 0`` for ``λ < T / 3``, and ``λ0 <= T / 3``), so
    Newton's steps from 0 stay below ``λ0`` and climb towards it: the first is ``det / M``
    (the bound the sweep used alone until 2026-12, ``λ0 = det / (λ1 λ2) >= det / M``), and
    ``FLOOR_STEPS`` more make it nearly tight where the points are not flat as well — a
    two-ring in vegetation (LiDAR), whose splits the first bound rarely ruled out. No step
    may pass ``λ0``: a step is taken only while ``p`` stays positive, the iterate ``x`` below
    the root. Where the minors are below ``1e-6`` of the squared trace (the points nearly on a
    line) their rounding could make the quotient anything: the bound is 0 there. Elsewhere
    each step's rounding (a few machine epsilons of ``T³`` over ``|p'| >= M - 2Tx`` with ``x``
    below ``λ0``) stays near 1e-9 of the trace (an estimate), far inside ``FLOOR_MARGIN``.
    """
    m00 = a11 * a22 - a12 * a12
    m11 = a00 * a22 - a02 * a02
    m22 = a00 * a11 - a01 * a01
    minors = m00 + m11 + m22
    det = a00 * m00 - a01 * (a01 * a22 - a12 * a02) + a02 * (a01 * a12 - a11 * a02)
    trace = a00 + a11 + a22
    if det <= 0.0 or not minors > 1e-6 * trace * trace:
        return 0.0
    x = det / minors
    for _ in range(FLOOR_STEPS):
        value = det - x * (minors - x * (trace - x))
        slope = minors - x * (2.0 * trace - 3.0 * x)  # -p'(x)
        if not (value > 0.0 and slope > 0.0):
            break
        x += value / slope
    return x


@jit_leaf
def _seed_by_sweep(X, idx, c, side, proj, normal, t1, t2, work, order):
    """Initial split by a straight line in the neighbours' mean plane (where a sharp edge
    projects): of ``NDIR`` directions and every offset, the one whose two halves lie closest
    to two planes (least total squared plane distance, from running moments in sorted order),
    each half holding ``SWEEP_SIDE`` of the points or more. ``idx[0]`` is the point itself;
    ``proj`` (float) and ``order`` (int64): work arrays of length ``c`` or more
    (:func:`_sort_order`). Returns False if ``c`` is too small for two such halves.

    Each half's least eigenvalue is monotone along a direction: the left half only gains
    points, so its scatter matrix only grows (in the positive semi-definite order) and that
    eigenvalue with it; the right half's only shrinks. A split is skipped where a lower bound
    (:func:`_scatter_floor`) of the right half's alone, or of both, clears the best so far by
    ``FLOOR_MARGIN`` of the whole two-ring's trace, and a direction's sweep stops where the
    left half's alone does: no later split of it could be chosen. The margin covers the
    rounding of the bounds and of every split's eigenvalues, whose halves' traces sum to at
    most the whole's. The split is the same as with every split's eigenvalues; on lone-star's
    failed fits the stop skips 32 % of the splits (6.5 of 20.5 million), and the sweep takes
    0.73× the time it did (docs/measurements.md "The line sweep stops early")."""
    least = max(MIN_SIDE, int(np.ceil(SWEEP_SIDE * c)))
    if c < 2 * least:
        return False
    p = idx[0]
    px, py, pz = X[p, 0], X[p, 1], X[p, 2]
    total = NO_MOMENTS  # of idx[1:c] about p (p itself adds nothing)
    for j in range(1, c):
        total = add_moments(total, X, idx[j], px, py, pz)
    smallest_axis(*moments_covariance(total, c - 1), normal, work)  # the mean plane
    tangent_basis(normal, t1, t2)
    whole = _scatter(total, c)
    # no split's two halves scatter more than the whole two-ring (their traces sum to its
    # trace less the scatter between the halves' means): a margin for every split at once
    margin = FLOOR_MARGIN * max(whole[0] + whole[3] + whole[5], 0.0)
    best = np.inf
    best_d = 0
    best_k = least
    for d in range(NDIR):
        _project(X, idx, c, p, t1, t2, np.pi * d / NDIR, proj)
        _sort_order(proj, c, order)
        left = NO_MOMENTS
        for k in range(1, c - least + 1):
            left = add_moments(left, X, idx[order[k - 1]], px, py, pz)
            if k < least:
                continue
            right = (total[0] - left[0], total[1] - left[1], total[2] - left[2],
                     total[3] - left[3], total[4] - left[4], total[5] - left[5],
                     total[6] - left[6], total[7] - left[7], total[8] - left[8])
            # most splits cannot beat the best: a bound without eigenvalues rules them out,
            # from scatters by reciprocals (two divisions, not twelve; their rounding is far
            # inside the margin), often the right half's alone at the start (it only shrinks)
            # and the left half's alone at the end (it only grows)
            bar = best + margin
            low_r = _scatter_floor(*_scatter_by(right, 1.0 / (c - k)))
            if low_r >= bar:
                continue
            low_l = _scatter_floor(*_scatter_by(left, 1.0 / k))
            if low_l >= bar:
                break  # the left half only grows from here, and its least eigenvalue with it
            if low_l + low_r >= bar:
                continue
            scatter_l = _scatter(left, k)
            scatter_r = _scatter(right, c - k)
            sse = _smallest_scatter(*scatter_l) + _smallest_scatter(*scatter_r)
            if sse < best:
                best, best_d, best_k = sse, d, k
        if best_d == d:  # the best split so far is this direction's (or none is, at d = 0)
            for i in range(c):
                side[order[i]] = 0 if i < best_k else 1
    return True


@jit_leaf
def _sort_order(a, c, order):
    """``order[:c]``: the positions of ``a[:c]`` in ascending order, equal values in their
    positions' order; ``a[:c]`` is sorted too, in place (an insertion sort moving each value
    with its position, so that it compares values side by side rather than through
    ``order``: the sweep's two-rings hold at most ``MAX_RING`` + 1 points, and
    ``np.argsort`` allocated its result for each of them)."""
    for i in range(c):
        v = a[i]
        j = i - 1
        while j >= 0 and a[j] > v:
            a[j + 1] = a[j]
            order[j + 1] = order[j]
            j -= 1
        a[j + 1] = v
        order[j + 1] = i


@jit_leaf
def _project(X, idx, c, p, t1, t2, angle, proj):
    """``proj[j]``: offset of ``idx[j]`` from ``p`` along the tangent direction at ``angle``."""
    ca, sa = np.cos(angle), np.sin(angle)
    dx, dy, dz = ca * t1[0] + sa * t2[0], ca * t1[1] + sa * t2[1], ca * t1[2] + sa * t2[2]
    for j in range(c):
        q = idx[j]
        proj[j] = (X[q, 0] - X[p, 0]) * dx + (X[q, 1] - X[p, 1]) * dy + (X[q, 2] - X[p, 2]) * dz


@jit_leaf
def edge_distance(X, normals, idx, c, side, c1, n1, c2, n2, work, spacing, proj, line,
                  max_cos, order):
    """Step 2: ``(distance, angle)`` — the distance from ``idx[0]`` to the edge of a two-plane
    fit of ``idx[:c]`` and the faces' fold there (degrees, 0-180, see ``MIN_ANGLE``; planes
    whose angle has a cosine above ``max_cos`` in absolute value give no edge).

    ``normals`` are one-ring normals (sharper across the edge than smoothed ones). The fit
    starts from the normal seeds; if that fails, once more from the line sweep
    (:func:`_seed_by_sweep`). ``proj`` and ``order`` (int64) are work arrays of length ``c`` or
    more. The distance is ``inf`` when the points are not two planes meeting at a sharp edge
    (see :func:`_fit_edge`); otherwise ``line`` holds the edge (:func:`_edge_line`).
    """
    _seed_by_normals(normals, idx, c, side)
    d, angle = _fit_edge(X, idx, c, side, c1, n1, c2, n2, work, spacing, line, max_cos)
    if d < np.inf:
        return d, angle
    # c1, n1, c2 serve as the sweep's frame (normal, t1, t2): the fit overwrites them anyway
    if not _seed_by_sweep(X, idx, c, side, proj, c1, n1, c2, work, order):
        return np.inf, 0.0
    return _fit_edge(X, idx, c, side, c1, n1, c2, n2, work, spacing, line, max_cos)


@jit_leaf
def _edge_line(c1, n1, c2, n2, line):
    """The line where the planes through ``c1`` and ``c2`` with unit normals ``n1`` and ``n2``
    (not parallel) meet: ``line[:3]`` its point nearest the origin, ``line[3:]`` its unit
    direction ``n1 × n2 / |n1 × n2|``."""
    cs = n1[0] * n2[0] + n1[1] * n2[1] + n1[2] * n2[2]
    ux = n1[1] * n2[2] - n1[2] * n2[1]
    uy = n1[2] * n2[0] - n1[0] * n2[2]
    uz = n1[0] * n2[1] - n1[1] * n2[0]
    d1 = c1[0] * n1[0] + c1[1] * n1[1] + c1[2] * n1[2]
    d2 = c2[0] * n2[0] + c2[1] * n2[1] + c2[2] * n2[2]
    det = 1.0 - cs * cs
    ga = (d1 - cs * d2) / det
    gb = (d2 - cs * d1) / det
    un = np.sqrt(ux * ux + uy * uy + uz * uz)
    line[0] = ga * n1[0] + gb * n2[0]
    line[1] = ga * n1[1] + gb * n2[1]
    line[2] = ga * n1[2] + gb * n2[2]
    line[3], line[4], line[5] = ux / un, uy / un, uz / un


@jit_leaf
def _point_line_distance(x, line):
    """Distance from the point ``x`` to the line ``line`` (:func:`_edge_line`):
    ``|(x - a) × u|``."""
    vx, vy, vz = x[0] - line[0], x[1] - line[1], x[2] - line[2]
    ux, uy, uz = line[3], line[4], line[5]
    cx, cy, cz = vy * uz - vz * uy, vz * ux - vx * uz, vx * uy - vy * ux
    return np.sqrt(cx * cx + cy * cy + cz * cz)


@jit_leaf
def _line_distance(X, p, line):
    """Distance from ``X[p]`` to the line ``line``."""
    return _point_line_distance(X[p], line)


@jit_leaf
def _fit_edge(X, idx, c, side, c1, n1, c2, n2, work, spacing, line, max_cos):
    """Two-plane k-means from the split ``side``, then ``(distance, angle)``: the distance from
    ``idx[0]`` to the planes' line of intersection and the faces' fold there (degrees, 0-180):
    180° less the angle between the half-planes the two sides span from the line, each side's
    direction given by the sign of its points' mean offset from the line. At an ordinary edge
    this is the angle between the planes; at a wedge (faces meeting at less than 90°) it is
    more than 90°, where the planes' angle would read a 50° wedge as a 50° fold (a soft edge).

    The distance is ``inf`` when the points are not two planes meeting at a sharp edge: a side
    with fewer than ``MIN_SIDE`` points or spread less than ``MIN_SPREAD`` spacings across (a
    row, not a face), planes nearer parallel than the least fold (``|cos|`` of their angle
    above ``max_cos``, the cosine of ``MIN_ANGLE`` by default), a side whose RMS distance to its
    plane exceeds ``MAX_RMS`` spacings (a curved or rough patch, not two faces), sides that do
    not lie each on its own side of the line (more than ``MAX_MIXED`` of a side's points
    farther than half a spacing from the line on the wrong side: a noisy surface split in two
    interleaved halves, not two faces meeting), a side with fewer than ``MIN_OFF`` points
    farther than half a spacing from the line (a scan line along it and one far point: the
    plane's tilt is that point's alone), or a wedge with no point within a spacing of
    its line (two halves of one noisy face whose planes meet far off, both on one side).
    """
    max_rms = MAX_RMS * spacing
    p = idx[0]
    changed = True  # False: the last round's planes fit the sides as they are now
    rms0 = spread0 = 0.0
    for _ in range(ROUNDS):
        k0, k1, rms0, spread0 = _plane_fits(X, idx, c, side, c1, n1, c2, n2, work)
        if k0 < MIN_SIDE or k1 < MIN_SIDE:
            return np.inf, 0.0
        changed = False
        for j in range(c):
            q = idx[j]
            s = 0 if _plane_distance(X, q, c1, n1) <= _plane_distance(X, q, c2, n2) else 1
            if s != side[j]:
                side[j] = s
                changed = True
        if not changed:
            break
    if changed:  # the sides moved in the last round: their planes again
        k0, k1, rms0, spread0 = _plane_fits(X, idx, c, side, c1, n1, c2, n2, work)
        if k0 < MIN_SIDE or k1 < MIN_SIDE:
            return np.inf, 0.0
    # side 1's RMS and spread are in work
    min_spread = MIN_SPREAD * spacing
    if rms0 > max_rms or spread0 < min_spread or work[0] > max_rms or work[1] < min_spread:
        return np.inf, 0.0
    cs = n1[0] * n2[0] + n1[1] * n2[1] + n1[2] * n2[2]
    if abs(cs) > max_cos:
        return np.inf, 0.0  # the fold is the planes' angle or 180° less it: below the least
    # each side on its own side of the line: offsets along t_i = u x n_i, u = n1 x n2 (unit
    # vectors, t_1 . t_2 = n1 . n2); the sign s_i of a side's mean offset gives the direction
    # s_i t_i from the line into its half-plane, so the half-planes' angle has cosine
    # s_1 s_2 cs: a wedge where that is positive
    _edge_line(c1, n1, c2, n2, line)
    lx, ly, lz, ux, uy, uz = line[0], line[1], line[2], line[3], line[4], line[5]
    signs = 1.0
    gap = np.inf  # the least distance of a point from the line (within its plane)
    for which in range(2):
        nx, ny, nz = (n1[0], n1[1], n1[2]) if which == 0 else (n2[0], n2[1], n2[2])
        tx, ty, tz = uy * nz - uz * ny, uz * nx - ux * nz, ux * ny - uy * nx
        tn = np.sqrt(tx * tx + ty * ty + tz * tz)
        pos = 0
        neg = 0
        total = 0.0
        for j in range(c):
            if side[j] != which:
                continue
            q = idx[j]
            o = ((X[q, 0] - lx) * tx + (X[q, 1] - ly) * ty + (X[q, 2] - lz) * tz) / tn
            total += o
            gap = min(gap, abs(o))
            if o > 0.5 * spacing:
                pos += 1
            elif o < -0.5 * spacing:
                neg += 1
        if min(pos, neg) > MAX_MIXED * (pos + neg) or pos + neg < MIN_OFF:
            return np.inf, 0.0
        if total < 0.0:
            signs = -signs
    fold = np.rad2deg(np.arccos(min(abs(cs), 1.0)))  # the planes' angle
    if signs * cs > 0.0:  # a wedge
        if gap > spacing:
            return np.inf, 0.0  # a wedge's faces start at its line; a noisy face's halves do not
        fold = 180.0 - fold
    return _line_distance(X, p, line), fold


#: a face of a three-plane fit (:func:`_fit_corner`) may deviate from its plane by at most this
#: RMS (local spacings): a curved patch of a few spacings' radius (a small hole, a boss) fits
#: three planes folding by more than the least fold within ``MAX_RMS``; 0.3 measured on the
#: 38 quality cases (docs/measurements.md, "Corners: three faces in a two-ring")
CORNER_RMS = 0.3


@jit
def _fit_corner(X, normals, idx, c, side, cen, nrm, work, spacing, line, tmp, max_cos, proj,
                outer):
    """Three-plane k-means of ``idx[:c]``: ``(distance, angle)`` from ``idx[0]`` to the nearest
    line where two of three fitted faces meet at a sharp edge, ``line`` holding it (``inf``
    and ``line`` untouched where there is none).

    Beyond the paper. At a corner — where an edge bends (a polygonal hole's rim), where three
    faces meet, where an edge ends on a face — a two-ring holds three faces, and the two-plane
    fit of :func:`_fit_edge` finds no edge (no two planes fit it) or the edge of the two largest
    faces, farther than the point's own. Seeds, among the outer half of the two-ring (by
    distance from ``idx[0]``: nearer the corner every one-ring normal mixes faces): the normal
    least parallel to ``idx[0]``'s, the one least parallel to that, and the one least
    parallel to both (none if that is within the least fold of either); ``ROUNDS`` of
    assigning each point to the nearest plane and refitting. Each face needs ``MIN_SIDE``
    points, an RMS distance of at most ``CORNER_RMS`` spacings to its plane and a spread of
    ``MIN_SPREAD``; no two of the planes may be nearer parallel than the least fold (a thin
    wall's two faces and its rim are two edges, the two-plane fit's, not a corner); a pair of
    faces makes an edge where each has a point within a spacing of their line (faces that meet
    there, not two faces the third separates), its fold taken as :func:`_fit_edge` takes it.
    ``cen``, ``nrm``: (3, 3) work arrays; ``tmp``: a work line; ``proj``, ``outer``: work
    arrays of length ``c`` or more (float, int).
    """
    p = idx[0]
    # seeds from the outer half of the two-ring: near the corner every normal mixes faces
    for j in range(c):
        dx, dy, dz = X[idx[j], 0] - X[p, 0], X[idx[j], 1] - X[p, 1], X[idx[j], 2] - X[p, 2]
        proj[j] = dx * dx + dy * dy + dz * dz
    half = np.median(proj[:c])
    m = 0
    for j in range(c):
        if proj[j] >= half:
            outer[m] = idx[j]
            m += 1
    a = _least_parallel(normals, outer, m, p)
    b = _least_parallel(normals, outer, m, a)
    t = -1
    best = 2.0
    for j in range(m):
        q = outer[j]
        v = max(abs(_dot(normals, a, normals, q)), abs(_dot(normals, b, normals, q)))
        if v < best:
            best = v
            t = q
    if t < 0 or best > max_cos or abs(_dot(normals, a, normals, b)) > max_cos:
        return np.inf, 0.0
    for j in range(c):
        q = idx[j]
        da = abs(_dot(normals, a, normals, q))
        db = abs(_dot(normals, b, normals, q))
        dt = abs(_dot(normals, t, normals, q))
        side[j] = 0 if da >= db and da >= dt else (1 if db >= dt else 2)
    for _ in range(ROUNDS):
        for which in range(3):
            if _plane_fit(X, idx, c, side, which, cen[which], nrm[which], work) < MIN_SIDE:
                return np.inf, 0.0
        changed = False
        for j in range(c):
            q = idx[j]
            s = 0
            r = np.inf
            for which in range(3):
                d = _plane_distance(X, q, cen[which], nrm[which])
                if d < r:
                    r = d
                    s = which
            if s != side[j]:
                side[j] = s
                changed = True
        if not changed:
            break
    max_rms = CORNER_RMS * spacing
    min_spread = MIN_SPREAD * spacing
    for which in range(3):
        if (_plane_fit(X, idx, c, side, which, cen[which], nrm[which], work) < MIN_SIDE
                or work[0] > max_rms or work[1] < min_spread):
            return np.inf, 0.0
    for i in range(3):  # a corner: no two of the faces near parallel (a thin wall's are)
        for k in range(i + 1, 3):
            if abs(_dot(nrm, i, nrm, k)) > max_cos:
                return np.inf, 0.0
    best_d = np.inf
    best_fold = 0.0
    for i in range(3):
        for k in range(i + 1, 3):
            cs = _dot(nrm, i, nrm, k)
            _edge_line(cen[i], nrm[i], cen[k], nrm[k], tmp)
            # each face has a point within a spacing of the line; the sign of its points' mean
            # offset from the line gives its half-plane (the fold, as in _fit_edge)
            signs = 1.0
            meets = True
            for which in (i, k):
                nx, ny, nz = nrm[which, 0], nrm[which, 1], nrm[which, 2]
                tx, ty = tmp[4] * nz - tmp[5] * ny, tmp[5] * nx - tmp[3] * nz
                tz = tmp[3] * ny - tmp[4] * nx
                tn = np.sqrt(tx * tx + ty * ty + tz * tz)
                gap = np.inf
                total = 0.0
                for j in range(c):
                    if side[j] != which:
                        continue
                    q = idx[j]
                    gap = min(gap, _line_distance(X, q, tmp))
                    total += ((X[q, 0] - tmp[0]) * tx + (X[q, 1] - tmp[1]) * ty
                              + (X[q, 2] - tmp[2]) * tz) / tn
                if gap > spacing:
                    meets = False
                if total < 0.0:
                    signs = -signs
            if not meets:
                continue
            fold = np.rad2deg(np.arccos(min(abs(cs), 1.0)))
            if signs * cs > 0.0:
                fold = 180.0 - fold
            d = _line_distance(X, p, tmp)
            if d < best_d:
                best_d = d
                best_fold = fold
                for e in range(6):
                    line[e] = tmp[e]
    return best_d, best_fold


@jit
def nearest_distances(X, start, cnt, pool, out):
    """Distance from every point to its nearest Voronoi neighbour (its nearest neighbour)."""
    for p in range(X.shape[0]):
        best = np.inf
        for j in range(cnt[p]):
            q = pool[start[p] + j]
            d = ((X[q, 0] - X[p, 0]) ** 2 + (X[q, 1] - X[p, 1]) ** 2
                 + (X[q, 2] - X[p, 2]) ** 2)
            if d < best:
                best = d
        out[p] = np.sqrt(best)


@jit_leaf
def _quadric_sse(X, idx, c, spacing, normal, t1, t2, work, M, r):
    """Sum of squared residuals of the least-squares quadric height field
    ``w = a u² + b uv + c v² + d u + e v + f`` over the points ``idx[:c]`` (``idx[0]`` the point
    itself), in the frame of their PCA plane (``normal``, ``t1``, ``t2``: work vectors, as are
    ``work`` (3), ``M`` (6, 6), ``r`` (6)); ``inf`` for fewer than six points or a singular
    fit. Residuals are along the plane's normal, in model units squared."""
    if c < 6:
        return np.inf
    p = idx[0]
    smallest_axis(*covariance_about(X, p, idx[1:], c - 1), normal, work)
    tangent_basis(normal, t1, t2)
    px, py, pz = X[p, 0], X[p, 1], X[p, 2]
    inv = 1.0 / spacing
    M[:, :] = 0.0
    r[:] = 0.0
    ww = 0.0
    for j in range(c):
        q = idx[j]
        x, y, z = (X[q, 0] - px) * inv, (X[q, 1] - py) * inv, (X[q, 2] - pz) * inv
        u = x * t1[0] + y * t1[1] + z * t1[2]
        v = x * t2[0] + y * t2[1] + z * t2[2]
        w = x * normal[0] + y * normal[1] + z * normal[2]
        a0, a1, a2, a3, a4 = u * u, u * v, v * v, u, v
        for i, ai in enumerate((a0, a1, a2, a3, a4, 1.0)):
            M[i, 0] += ai * a0
            M[i, 1] += ai * a1
            M[i, 2] += ai * a2
            M[i, 3] += ai * a3
            M[i, 4] += ai * a4
            M[i, 5] += ai
            r[i] += ai * w
        ww += w * w
    b0, b1, b2, b3, b4, b5 = r[0], r[1], r[2], r[3], r[4], r[5]
    if not solve_small(M, r, 6):
        return np.inf
    sse = ww - (r[0] * b0 + r[1] * b1 + r[2] * b2 + r[3] * b3 + r[4] * b4 + r[5] * b5)
    return max(sse, 0.0) * spacing * spacing


@jit_leaf
def _face_tangent(X, idx, c, side, which, n, line, spacing, M, r, tangent):
    """The tangent at the fitted ``line`` of face ``which`` of a two-plane split (``side``,
    its plane's normal ``n``), pointing away from the line: its points' heights over the
    plane fitted by a parabola across the line (in ``spacing`` units; ``M``, ``r``: 3 x 3 and
    3 work arrays), into ``tangent``; False where the face has fewer than 4 points or fits no
    parabola."""
    ax, ay, az = line[0], line[1], line[2]
    ux, uy, uz = line[3], line[4], line[5]
    dx, dy, dz = n[1] * uz - n[2] * uy, n[2] * ux - n[0] * uz, n[0] * uy - n[1] * ux
    dn = np.sqrt(dx * dx + dy * dy + dz * dz)
    if not dn > 0.0:
        return False
    dx, dy, dz = dx / dn, dy / dn, dz / dn  # across the line in the plane, either sense
    M[:3, :3] = 0.0
    r[:3] = 0.0
    for j in range(c):
        if side[j] != which:
            continue
        q = idx[j]
        ex, ey, ez = X[q, 0] - ax, X[q, 1] - ay, X[q, 2] - az
        t = (ex * dx + ey * dy + ez * dz) / spacing
        h = (ex * n[0] + ey * n[1] + ez * n[2]) / spacing
        tt = t * t
        M[0, 0] += 1.0
        M[0, 1] += t
        M[0, 2] += tt
        M[1, 2] += tt * t
        M[2, 2] += tt * tt
        r[0] += h
        r[1] += t * h
        r[2] += tt * h
    if M[0, 0] < 4.0:
        return False
    if M[0, 1] < 0.0:  # towards the face's points: t -> -t flips the odd sums (exactly)
        dx, dy, dz = -dx, -dy, -dz
        M[0, 1] = -M[0, 1]
        M[1, 2] = -M[1, 2]
        r[1] = -r[1]
    M[1, 0] = M[0, 1]
    M[1, 1] = M[0, 2]
    M[2, 0] = M[0, 2]
    M[2, 1] = M[1, 2]
    if not solve_small(M, r, 3):
        return False
    tangent[0], tangent[1], tangent[2] = dx + r[1] * n[0], dy + r[1] * n[1], dz + r[1] * n[2]
    return True


@jit_leaf
def _fold_at_line(X, idx, c, side, n1, n2, line, spacing, M, r, t1, t2):
    """The fold at the fitted ``line`` of the faces of a two-plane split (``side``, the
    planes' normals ``n1``, ``n2``): the angle between their tangents there
    (:func:`_face_tangent`, into the work vectors ``t1``, ``t2``); degrees, 0-180 (180 where
    a face fits no parabola)."""
    if not (_face_tangent(X, idx, c, side, 0, n1, line, spacing, M, r, t1)
            and _face_tangent(X, idx, c, side, 1, n2, line, spacing, M, r, t2)):
        return 180.0
    l1 = t1[0] * t1[0] + t1[1] * t1[1] + t1[2] * t1[2]
    l2 = t2[0] * t2[0] + t2[1] * t2[1] + t2[2] * t2[2]
    cs = (t1[0] * t2[0] + t1[1] * t2[1] + t1[2] * t2[2]) / np.sqrt(l1 * l2)
    return 180.0 - np.degrees(np.arccos(min(1.0, max(-1.0, cs))))


@jit_leaf
def _two_plane_sse(X, idx, c, side, c1, n1, c2, n2):
    """Sum of squared distances of the points of a two-plane split to their planes: the planes
    :func:`_fit_edge` leaves in ``c1, n1`` (side 0) and ``c2, n2`` (side 1)."""
    sse = 0.0
    for j in range(c):
        d = (_plane_distance(X, idx[j], c1, n1) if side[j] == 0
             else _plane_distance(X, idx[j], c2, n2))
        sse += d * d
    return sse


@jit
def localise(X, normals, dn, dn_cnt, nn, candidate, out, angle, line, local, min_angle, width,
             corner, bend, narrowed, rim, filled):
    """Step 2 for every candidate: ``out[p]`` = edge distance / local spacing (inf: no edge),
    ``angle[p]`` = the fold of the fitted faces (degrees, 0-180, see ``MIN_ANGLE``; 0 where no
    edge),
    ``line[p]`` = the fitted edge line where there is one (:func:`_edge_line`; undefined
    elsewhere), ``local[p]`` = the local spacing (0 for points that are not candidates),
    ``corner[p]``: whether that line is a corner's (:func:`_fit_corner`), ``bend[p]``: the
    squared error of one quadric height field over the two-ring over that of the two planes
    (:func:`_quadric_sse`, :func:`_two_plane_sse`; NaN where no two-plane fit found an edge
    within ``width`` local spacings — a farther line's bend is not measured: :func:`borrow`
    and :func:`line_distances` take only lines within ``width``, a farther soft fit lends no
    flags and a farther sharp one lends unclassified (:func:`confirmed_lines`), and so where a
    corner's line replaced it
    — ``inf`` where the planes fit exactly and the quadric does not; at least ``SHARP_RATIO``
    where the quadric's squared error exceeds the planes' by ``CREASE_EXCESS`` squared local
    spacings a point; 1 where a soft fit's faces, each fitted by a parabola across its line,
    fold there by less than ``LINE_FOLD``, :func:`_fold_at_line`: a fillet's facets, no
    crease): below ``SMOOTH_RATIO`` a smooth fold, at or above ``SHARP_RATIO`` a crease
    (:func:`fold_kinds`).
    ``min_angle``: the least fold of a sharp edge, in degrees (``MIN_ANGLE`` by default, the
    option ``edge_angle``; at most 90: the test is on the planes' angle, so wedges whose faces
    meet at less than it are not found either).

    Local spacing: the median over ``p`` and its two-ring of ``nn`` (each point's distance to
    its nearest neighbour, :func:`nearest_distances`).

    Where the two-ring holds two parallel sheets (a thin wall's faces, :func:`own_layer`), the
    fit takes the point's own sheet alone (its local spacing still over the whole two-ring).
    Where the fit finds no edge, it is tried once more over the two-ring's points within
    ``NEAR_RING`` local spacings (:func:`near_part`, then :func:`own_layer` of those).
    Where that finds none either, a step lower than the spacing is tried over the two-ring's
    points within ``STEP_RING`` local spacings (:func:`_fit_step`: the fold reads 90°, and no
    bend is measured). ``narrowed[p]``: whether ``p``'s fit is one of those two, which
    :func:`.simplify.boundary_flags` keeps only where another fit confirms its line.
    Where none of them finds one either and the two-ring holds two sheets, a thin wall's rim
    is tried (:func:`_fit_rim`, :func:`_rim_clear`: the fold reads 90°, no bend is measured);
    ``rim[p]``: whether ``p``'s fit is a rim's, whose line makes features but not the core
    band (:func:`.simplify.boundary_flags`). Where no rim fits either and the sampling fills
    its tangent planes (``filled``: :func:`median_ring_gap` below ``FILLED_GAP``), a border is
    tried (:func:`_border_gap`: an empty angle about the point), a rim's kind for ``rim``.

    Beyond the paper, a second pass: a candidate whose two-plane fit finds no edge within
    ``width`` local spacings of it (none, or a farther one) is fitted with three planes
    (:func:`_fit_corner`); a nearer line found so replaces its own only where its two-ring
    holds a point that its own two-plane fit flags (within ``width``): a corner ends edges that
    fit, and a curved patch three planes fit (a small hole or boss, a fillet) has none.
    """
    n = X.shape[0]
    max_cos = np.cos(np.deg2rad(min_angle))
    mark = np.zeros(n, dtype=np.int64)
    idx = np.empty(MAX_RING + 1, dtype=np.int64)
    whole = np.empty(MAX_RING + 1, dtype=np.int64)
    side = np.empty(MAX_RING + 1, dtype=np.int64)
    vals = np.empty(MAX_RING + 1)
    proj = np.empty(MAX_RING + 1)
    order = np.empty(MAX_RING + 1, dtype=np.int64)  # the sweep's sort
    c1 = np.empty(3)
    c2 = np.empty(3)
    n1 = np.empty(3)
    n2 = np.empty(3)
    work = np.empty(3)
    M6 = np.empty((6, 6))
    r6 = np.empty(6)
    across = np.empty(3)
    sheet_n = np.empty(3)  # the whole two-ring's PCA normal, own_layer's: a rim's sheets'
    qt = np.empty(3)
    mark3 = np.zeros(0, dtype=np.int64)  # the three-rings' marks, made where a rim is tried
    ring3 = np.empty(4 * MAX_RING, dtype=np.int64)
    ang3 = np.empty(4 * MAX_RING)
    bu = np.empty(3)  # the border's plane basis
    bv = np.empty(3)
    for p in range(n):
        bend[p] = np.nan
        narrowed[p] = False
        rim[p] = False
        out[p] = np.inf
        angle[p] = 0.0
        local[p] = 0.0
        corner[p] = False
        if not candidate[p]:
            continue
        idx[0] = p
        c = 1 + gather_rings(p, dn, dn_cnt, FIT_RINGS, mark, idx[1:])
        for j in range(c):
            vals[j] = nn[idx[j]]
        s = _median_in_place(vals, c)
        local[p] = s
        if s <= 0.0:
            continue
        whole[:c] = idx[:c]
        c_whole = c
        c = own_layer(X, idx, c, s, proj, sheet_n, work)  # a thin wall: the point's own sheet
        sheets = c < c_whole
        d, angle[p] = edge_distance(X, normals, idx, c, side, c1, n1, c2, n2, work, s, proj,
                                    line[p], max_cos, order)
        if d == np.inf:  # a scan's two-ring reaching too far across its lines: the near part
            m = near_part(X, idx, c, NEAR_RING * s)
            if MIN_SIDE * 2 <= m < c:
                c = own_layer(X, idx, m, s, proj, c1, work)
                d, angle[p] = edge_distance(X, normals, idx, c, side, c1, n1, c2, n2, work, s,
                                            proj, line[p], max_cos, order)
                narrowed[p] = d < np.inf
        layers = False  # a step's or a rim's fit: no bend measured
        if d == np.inf:  # a step lower than the spacing: its own two-ring, near the point
            idx[:c_whole] = whole[:c_whole]
            c = near_part(X, idx, c_whole, STEP_RING * s)
            d = _fit_step(X, normals, idx, c, s, proj, vals, line[p], n1, n2, work)
            if d < np.inf:
                angle[p] = 90.0
                narrowed[p] = layers = True
        if d == np.inf and sheets:  # a thin wall's rim, where both its sheets end
            idx[:c_whole] = whole[:c_whole]
            c = c_whole
            d = _fit_rim(X, idx, c, s, proj, sheet_n, line[p], across)
            if d < np.inf or filled:  # both tests read the three-ring
                if mark3.shape[0] == 0:
                    mark3 = np.zeros(n, dtype=np.int64)
                k = gather_rings(p, dn, dn_cnt, FIT_RINGS + 1, mark3, ring3)
                if d < np.inf and not _rim_clear(X, p, ring3, k, d, s, across, sheet_n):
                    d = np.inf
                if d == np.inf and filled:  # a border where no rim fits: an empty angle
                    d = _border_gap(X, p, ring3, k, s, sheet_n, ang3, line[p], bu, bv)
                if d < np.inf:
                    angle[p] = 90.0
                    rim[p] = layers = True
        # a farther line's bend is not measured: measured, far smooth folds stopped lending
        # and far soft ones became creases, F1 mixed (docs/measurements.md "Creases by the
        # quadric's excess error")
        if d <= width * s and not layers:
            sse2 = _two_plane_sse(X, idx, c, side, c1, n1, c2, n2)
            sq = _quadric_sse(X, idx, c, s, c1, c2, qt, work, M6, r6)  # n1, n2 stay
            bend[p] = sq / sse2 if sse2 > 0.0 else (np.inf if sq > 0.0 else np.nan)
            if sq - sse2 >= CREASE_EXCESS * c * s * s:  # noise raises both alike
                bend[p] = max(bend[p], SHARP_RATIO)
            if (bend[p] >= SHARP_RATIO and angle[p] < SOFT_ANGLE
                    and _fold_at_line(X, idx, c, side, n1, n2, line[p], s, M6, r6, c1, c2)
                    < LINE_FOLD):
                bend[p] = 1.0  # a crease by its bend whose faces do not fold at its line
        out[p] = d / s
    # the corners: after every two-plane fit, which they need beside them
    mark[:] = 0
    cen = np.empty((3, 3))
    nrm = np.empty((3, 3))
    tmp = np.empty(6)
    found = np.empty(6)
    outer = np.empty(MAX_RING + 1, dtype=np.int64)
    for p in range(n):
        s = local[p]
        if not (s > 0.0 and out[p] > width):
            continue
        idx[0] = p
        c = 1 + gather_rings(p, dn, dn_cnt, FIT_RINGS, mark, idx[1:])
        beside = False
        for j in range(1, c):
            q = idx[j]
            if out[q] <= width and not corner[q]:
                beside = True
                break
        if not beside:
            continue
        d, a = _fit_corner(X, normals, idx, c, side, cen, nrm, work, s, found, tmp, max_cos,
                           proj, outer)
        if d / s < out[p]:
            out[p] = d / s
            angle[p] = a
            line[p, :] = found
            corner[p] = True


@jit
def line_distances(X, dn, dn_cnt, fitted, angle, line, local, width, spacing, corner, out):
    """Step 4: ``out[p]`` lowered (in place) to ``p``'s distance to the fitted line of any point
    ``q`` whose two-ring holds it, where ``q`` lies within ``width`` of its own line on an edge
    of ``SOFT_ANGLE`` or more and that line is not a corner's (``corner[q]``: it ends at the
    corner) — the lenders of :func:`borrow` — in units of ``max(local[q],
    spacing)``: the larger of ``q``'s local spacing and the cloud's.

    Beyond the paper; the features' reach (the flags' until 2026-12-06, when this was measured
    on them; now :func:`nearest_line_distances`). The core band (:func:`band` of steps 2-3)
    misses the points a little off the line whose own measure stays below ``CANDIDATE`` (idler_riser's 45-70° folds: 770 of
    its 4,304 points within one spacing of an edge) and, on scans, the rows beyond a local
    spacing that overlapping views shrink (the tray scan's lenders: 0.22 of the cloud's median
    nearest-neighbour distance). Measured on the 36 CAD quality cases (flags
    ``band | (out <= width)`` against the band alone, ``benchmarks/quality.py``): boundary F1
    geometric mean 0.512 -> 0.589 on the even parts (idler_riser 0.747 -> 0.872, rocker-arm
    0.533 -> 0.633, counter 0.462 -> 0.556; Fandisk 0.944 -> 0.943, block 0.936 -> 0.932) and
    0.462 -> 0.598 on the scans (plate_holes 0.529 -> 0.839, the tray 0.221 -> 0.477). In units
    of the local spacing alone the scans gained less than half as much (0.526); lenders of
    40-60° folds took plate_holes to 0.539 (fillets); within 0.85 widths, not 1, the even
    parts' mean is 0.577.
    """
    n = X.shape[0]
    mark = np.zeros(n, dtype=np.int64)
    ring = np.empty(MAX_RING, dtype=np.int64)
    for q in range(n):
        if not (fitted[q] <= width and angle[q] >= SOFT_ANGLE) or corner[q]:
            continue
        c = gather_rings(q, dn, dn_cnt, FIT_RINGS, mark, ring)
        unit = max(local[q], spacing)
        for j in range(c):
            p = ring[j]
            out[p] = min(out[p], _line_distance(X, p, line[q]) / unit)


@jit_leaf
def _reach(X, dn, dn_cnt, q, r2, mark, ring):
    """The points within ``sqrt(r2)`` of ``X[q]`` reached from it through the local mesh
    (``dn``), breadth first, at most ``MAX_REACH_POINTS``, into ``ring``; returns their count.
    ``mark[s] == q + 1`` marks a point this walk has seen (``mark`` is shared by the walks of
    every ``q``)."""
    mark[q] = q + 1
    ring[0] = q
    c = 1
    i = 0
    while i < c:
        r = ring[i]
        i += 1
        for j in range(dn_cnt[r]):
            s = dn[r, j]
            if mark[s] == q + 1 or c >= MAX_REACH_POINTS:
                continue
            mark[s] = q + 1
            if sq_dist(X, s, X[q]) <= r2:
                ring[c] = s
                c += 1
    return c


@jit
def nearest_line_distances(X, dn, dn_cnt, lender, line, reach, spacing, out):
    """The flags' measure: ``out[p]`` = ``p``'s least distance, in cloud ``spacing``s, to the
    fitted lines of its ``FLAG_FITS`` nearest lenders (``lender[q]``; their lines ``line[q]``)
    that reach it — those within ``reach`` (model units) of it through the local mesh
    (``dn``: a breadth-first walk from each lender over points within ``reach`` of it, at most
    ``MAX_REACH_POINTS``); ``inf`` where none does. Nearer lenders win ties by lower index.

    Beyond the paper. Each lender's line is the edge as its two-ring saw it; the nearest
    lenders' lines are the best local estimate of the edge beside ``p``, and their least
    distance stands for ``p``'s distance to the edge, what the ground truth (DESIGN.md §4:
    within one spacing of an edge) measures. Farther lenders' lines are straight where the edge
    curves and add false flags; fewer than three miss the edges a noisy fit mislocates.
    Measured on the 36 CAD quality cases (docs/measurements.md "Flags from the nearest fitted
    lines"), boundary F1 geometric mean of the 12 even / 24 scanned parts: 0.643 / 0.627,
    against 0.615 / 0.609 for the flags before (the core band, borrowed lines, and every
    point within a width of a lender's line in its two-ring, in units of the larger of the
    lender's local spacing and the cloud's); every lender within 3 spacings 0.627 / 0.608,
    within 4 0.637 / 0.630 (but featuretype 0.827, octagonal_pocket 0.840); the nearest 1 or 2
    within 4: 0.631 / 0.613, 0.641 / 0.623; the nearest 3 within 5: 0.648 / 0.636
    (plate_holes 0.812 -> 0.781).
    """
    n = X.shape[0]
    k = FLAG_FITS
    # each point's nearest lenders so far, nearest first (-1: none); int32 as ``dn``'s ids,
    # their distances measured again where compared: the flags' peak memory is 16 bytes a
    # point more than the boundary stage's own
    best = np.full((n, k), -1, dtype=np.int32)
    mark = np.zeros(n, dtype=np.int32)
    ring = np.empty(MAX_REACH_POINTS, dtype=np.int64)
    r2 = reach * reach
    for q in range(n):
        if not lender[q]:
            continue
        for i in range(_reach(X, dn, dn_cnt, q, r2, mark, ring)):
            r = ring[i]
            d2 = sq_dist(X, r, X[q])
            # q's place among r's k nearest lenders (after any as near: lower index first)
            j = k
            while j > 0 and (best[r, j - 1] < 0 or d2 < sq_dist(X, r, X[best[r, j - 1]])):
                j -= 1
            if j < k:
                for t in range(k - 1, j, -1):
                    best[r, t] = best[r, t - 1]
                best[r, j] = q
    for p in range(n):
        d = np.inf
        for j in range(k):
            q = best[p, j]
            if q >= 0:
                d = min(d, _line_distance(X, p, line[q]))
        out[p] = d / spacing


@jit
def confirmed_lines(X, dn, dn_cnt, fit, sure, line, reach, offset, min_cos, out):
    """``out[q]``: whether fit ``q``'s line lends flags — where ``sure[q]`` (its own point lies
    within a width of it), or where another fit (``fit[r]``, ``r != q``) within ``reach`` of
    it through the local mesh (a breadth-first walk over ``dn``, at most
    ``MAX_REACH_POINTS`` points) has a line within ``offset`` of the foot of ``X[q]`` on
    ``q``'s line and within ``acos(min_cos)`` of its direction (the lines' unit vectors,
    either sense). ``fit`` must hold ``sure``.

    Beyond the paper. A fit whose own point lies a spacing or two off its line still saw an
    edge in its two-ring; where a second fit places the edge there too, the line is the edge's
    and not noise's. Edges whose points fit no line near them — cycloidal's teeth, counter's
    threads, rows a noisy scan displaces — had no lender at all. Measured on the 36 CAD
    quality cases (docs/measurements.md "Far fits confirmed by a second"): boundary F1
    geometric mean of the 12 even / 24 scanned parts 0.643 / 0.627 -> 0.676 / 0.633 with fits
    within ``FAR_FIT`` = 2 widths (cycloidal 0.176 -> 0.269, ADIS16480 0.709 -> 0.735,
    angle_block 0.906 -> 0.925, counter's noise-0.1 scan 0.634 -> 0.674; Fandisk 0.970 ->
    0.966, the tray's noise-0.2 scan 0.649 -> 0.632); unconfirmed, 0.681 / 0.636 but
    plate_holes' scans 0.879 -> 0.779 and 0.803 -> 0.698 (lines several spacings off its
    edges) and featuretype 0.861 -> 0.828; confirmed within 0.5 spacings, plate_holes' noise-0.1
    scan 0.847; within 3 widths, 0.693 / 0.637 but that scan 0.834.
    """
    n = X.shape[0]
    mark = np.zeros(n, dtype=np.int32)
    ring = np.empty(MAX_REACH_POINTS, dtype=np.int64)
    foot = np.empty(3)
    r2 = reach * reach
    for q in range(n):
        out[q] = sure[q]
        if sure[q] or not fit[q]:
            continue
        # the foot of X[q] on its own line
        ux, uy, uz = line[q, 3], line[q, 4], line[q, 5]
        t = ((X[q, 0] - line[q, 0]) * ux + (X[q, 1] - line[q, 1]) * uy
             + (X[q, 2] - line[q, 2]) * uz)
        foot[0], foot[1], foot[2] = line[q, 0] + t * ux, line[q, 1] + t * uy, line[q, 2] + t * uz
        for i in range(_reach(X, dn, dn_cnt, q, r2, mark, ring)):
            r = ring[i]
            if (r != q and fit[r]
                    and abs(ux * line[r, 3] + uy * line[r, 4] + uz * line[r, 5]) >= min_cos
                    and _point_line_distance(foot, line[r]) <= offset):
                out[q] = True
                break


@jit
def borrow(X, dn, dn_cnt, distance, angle, line, local, width, flagged, corner, out,
           angle_out):
    """Step 3: candidates that their own fit does not flag take the edge of a flagged sharp
    neighbour.

    ``out[p]``, ``angle_out[p]``: for a candidate (a point with a positive ``local`` spacing,
    :func:`localise`) that its own fit does not flag (``flagged``: :func:`band` of
    ``distance``, ``angle`` and ``width`` — no fit, or a fitted line farther than the band),
    the distance in its local spacings to the nearest fitted line (``line``) among the points
    of its two-ring that lie within ``width`` of their own line on an edge of ``SOFT_ANGLE``
    or more, not a corner's (``corner``, :func:`_fit_corner`: its line ends at the corner),
    and that line's angle — if within ``BORROW_WIDTH * width`` and nearer than its own line;
    every other point keeps ``distance`` and ``angle``.

    Beyond the paper. Right on a scanned edge a two-ring can split into two planes badly (three
    to five one-ring neighbours on anisotropic scan lines, a seed across the noise) while the
    fits a spacing or two along the edge find it to within a tenth of a spacing; so a point on
    the same edge is located by their line. Measured on the 37 quality cases against no
    borrowing: boundary F1 median 0.681 -> 0.716 (even CAD parts), 0.460 -> 0.500 (scans);
    mean surface error lower on 32 of 36 CAD cases (geometric mean -3.8 %; Fandisk scan 8.90
    -> 8.47, angle_block scan 8.30 -> 7.54), edge coverage up on 31 (featuretype 0.836 ->
    0.902, now above every peer); Hausdorff +1.9 % (more flags, less budget for the faces).
    Only sharp edges lend: borrowed crease flags cost the Bunny its mean-error lead (17.50
    with, 17.17 without the angle rule, at full width; 17.00 now, best peer 17.27).

    A fit that succeeds can find the wrong edge too: a two-plane fit finds one edge per
    two-ring, and where two edges are closer than that (a step a few spacings high, a chamfer
    or fillet narrower than the spacing — ADIS16480's edges are 0.1-0.2 spacings from the
    next, octagonal_pocket's 0.55 — a thread) it finds the dominant one and misses the nearer.
    So fitted candidates outside their own band borrow as well. Measured on the 37 quality
    cases against borrowing for failed fits only (``benchmarks/quality.py``, coverage mode):
    boundary F1 up on 34 (median 0.713 -> 0.722 even, 0.507 -> 0.525 scans; F1 >= 0.85 on 4
    even parts, not 2: angle_block 0.852, octagonal_pocket 0.854), mean surface error lower on
    27 (geometric mean -0.8 %; Fandisk scan 8.30 -> 8.07, counter scan 11.01 -> 10.51), edge
    coverage up on 30 (+0.9 %); Hausdorff +1.2 % (higher on 34). Where the flags already take
    most of the budget it costs: featuretype mean 21.7 -> 24.2 and Hausdorff 1.60 -> 1.73x the
    best peer's, octagonal_pocket 29.6 -> 32.1 and 1.71 -> 1.89x; below every peer's mean
    error on 31 cases, not 32 (cycloidal 44.54 against 44.45), Hausdorff within 1.2x on 30, not
    31 (tray_bottom scan 1.205x). Borrowing within 0.7 widths instead: F1 median 0.730 / 0.544,
    but Hausdorff +3.2 %, mean error best on 29.
    """
    n = X.shape[0]
    mark = np.zeros(n, dtype=np.int64)
    ring = np.empty(MAX_RING, dtype=np.int64)
    for p in range(n):
        out[p] = distance[p]
        angle_out[p] = angle[p]
        if local[p] <= 0.0 or flagged[p]:
            continue  # not a candidate, or flagged by its own fit
        c = gather_rings(p, dn, dn_cnt, FIT_RINGS, mark, ring)
        for j in range(c):
            q = ring[j]
            if not (distance[q] <= width and angle[q] >= SOFT_ANGLE) or corner[q]:
                continue
            d = _line_distance(X, p, line[q]) / local[p]
            if d < out[p] and d <= BORROW_WIDTH * width:
                out[p] = d
                angle_out[p] = angle[q]


def fold_kinds(bend, angle):
    """``(smooth, crease)`` masks of :func:`localise`'s fits from its ``bend`` and ``angle``
    outputs: smooth folds (a quadric fits better: ``bend < SMOOTH_RATIO``) and soft folds that
    two planes fit far better (``bend >= SHARP_RATIO``, as :func:`localise` also sets it where
    the quadric's excess error reaches ``CREASE_EXCESS``, and ``angle < SOFT_ANGLE``)."""
    bend = np.asarray(bend)
    with np.errstate(invalid="ignore"):
        return bend < SMOOTH_RATIO, (bend >= SHARP_RATIO) & (np.asarray(angle) < SOFT_ANGLE)


def band(distance, angle, width):
    """The flags: candidates within ``width`` local spacings of their fitted edge, or within
    ``SOFT_WIDTH * width`` where the faces fold by less than ``SOFT_ANGLE`` (a soft edge).

    Beyond the paper. Flags are kept (up to ``edge_share`` of the count: until 2026-12-05,
    when this was measured, all of them), so every flagged row is budget taken from the
    faces. A row beside a soft edge (a crease, a fillet edge) buys less than one beside a
    sharp one: the faces there differ less from one plane. Measured on the 37 quality cases
    (soft angle 60°, width 0.7 against no soft band; ``benchmarks/quality.py``): Bunny flags
    1,439 -> 1,209 and mean surface error 17.43 -> 16.90 (best peer 17.27), idler_riser
    12.82 -> 11.32 (Hausdorff 1.53 -> 1.39 x the best peer's), featuretype 20.71 -> 20.29;
    edge coverage down 0.935 -> 0.912 on angle_block, counter-scan0.2's mean 15.94 -> 16.88
    (best peer 16.05). Widths 0.5-0.8 and angles 50-70° trade the Bunny against the counter
    scans; none wins both.
    """
    distance = np.asarray(distance)
    soft = np.asarray(angle) < SOFT_ANGLE
    return distance <= width * np.where(soft, SOFT_WIDTH, 1.0)
