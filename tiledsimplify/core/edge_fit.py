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
   two faces the local mesh joins — only the point's own sheet is fitted
   (:func:`.thin_walls.own_layer`).
   **Wide two-rings** (since 2026-12-06, stop 57): where neither seed gives an edge, the fit
   is tried once more over the two-ring's points within ``NEAR_RING`` local spacings
   (:func:`near_part`) — a line scan's two-ring reaches some eight local spacings across its
   lines, past a narrow face or over a curved one; such a fit stands only where another fit's
   line confirms it (:func:`.simplify.boundary_flags`).
   **Steps** (since 2026-12-06, stop 57): where no two-plane fit gives an edge, a step lower
   than the spacing — two parallel layers side by side, its wall holding few points or none
   (counter's rib, 0.67 spacings tall) — is fitted (:func:`.thin_walls.fit_step`), confirmed
   likewise.
   **Thin walls' rims** (since 2026-12-06, stop 59): where all of that finds nothing and the
   two-ring holds two sheets, a plate thinner than about two spacings may end there: both
   sheets end together along a line, past which nothing lies (:func:`.thin_walls.fit_rim`,
   :func:`.thin_walls.rim_clear`). The rim's edge on the point's own sheet is its line; it lends
   flags, and makes features but not the core band (:func:`.simplify.boundary_flags`).
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
   (:func:`.edge_lines.borrow`).
4. **The whole band** — steps 2-3 give the **core band**: the points nearest each fitted line,
   narrower beside soft edges and for borrowed lines (tuned when every flagged point was kept:
   each is budget taken from the faces); a simplification samples it first for the points
   kept for certain, and its refinement never swaps them out. The **features** add every
   point within ``width`` spacings of the line of a sharp fitted neighbour
   (:func:`.edge_lines.line_distances`), candidate or not: a point one spacing from a 50° fold
   deviates too little to be a candidate.
5. **The flags** (``SimplifyResult.boundary``, the ``sharp_edge`` dimension; since
   2026-12-06) — every point within ``width`` cloud spacings of the line of one of its
   ``FLAG_FITS`` nearest **lenders** (the fits on a sharp edge or a crease within ``width``
   of their own line, or within ``FAR_FIT`` widths where a second fit's line confirms theirs:
   :func:`.edge_lines.confirmed_lines`), and the points their own corner fit flags
   (:func:`.edge_lines.nearest_line_distances`): the nearest fits' lines stand for the edge beside
   the point, which the ground truth measures in cloud spacings.

So flags are the points "on or within about one spacing of a sharp edge" — the ground truth of
DESIGN.md §4 — whatever the noise and the scan-line anisotropy.

Where the steps live: step 1 in :mod:`.two_ring` (the two-ring, the smoothed measure); step 2
here (:func:`localise` and its fits), with :mod:`.two_planes` (the plane fits, their seeds, the
line sweep) and :mod:`.thin_walls` (sheets, steps, rims, borders); steps 3-5 in
:mod:`.edge_lines`. (One module of 1,926 lines until 2026-12-07.)
"""

import numpy as np

from ._jit import jit, jit_leaf
from .linalg import covariance_about, smallest_axis, solve_small, tangent_basis
from .thin_walls import border_gap, fit_rim, fit_step, own_layer, rim_clear
from .two_planes import (MIN_SIDE, edge_line, least_parallel, line_distance, plane_distance,
                         plane_fit, plane_fits, row_dot, seed_by_normals, seed_by_sweep)
from .two_ring import FIT_RINGS, MAX_RING, gather_rings, median_in_place


#: default candidate threshold on the smoothed deviation (radians, ~4.6°)
CANDIDATE = 0.08
#: default: flag candidates within this many local spacings of the fitted edge
WIDTH = 1.0
#: default of the option ``edge_angle``, passed to :func:`localise` as ``min_angle``: planes
#: meeting at less than this angle (degrees) give no sharp edge (truth: > 30°). At an
#: ordinary edge that angle is the faces' **fold** (the angle between their outward normals:
#: 180° less the angle between the two half-planes); a wedge, whose faces meet at less than
#: 90°, folds by 180° less it. The fold is what :func:`band` and :func:`.edge_lines.borrow` see (a
#: 50° wedge folds by 130°: sharp, not soft; :func:`_fit_edge`); wedges of less than this angle
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
#: edge's does (:func:`fold_kinds`, :func:`.edge_lines.nearest_line_distances`). Soft folds lend no
#: flags otherwise: most used to be fillets. The features (what is kept) do not change. Measured on
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
#: a two-plane fit that finds no edge is tried once more over the two-ring's points within this
#: many local spacings of the point (:func:`near_part`; measured on the 36 CAD quality cases,
#: docs/measurements.md "Scans: the near part of the two-ring": 4, 5 and 6)
NEAR_RING = 5.0
#: a candidate that no two-plane fit gives an edge is tried as a step (:func:`.thin_walls.fit_step`)
#: over its two-ring's points within this many local spacings ...
STEP_RING = 2.5
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
def edge_distance(X, normals, idx, c, side, c1, n1, c2, n2, work, spacing, proj, line,
                  max_cos, order):
    """Step 2: ``(distance, angle)`` — the distance from ``idx[0]`` to the edge of a two-plane
    fit of ``idx[:c]`` and the faces' fold there (degrees, 0-180, see ``MIN_ANGLE``; planes
    whose angle has a cosine above ``max_cos`` in absolute value give no edge).

    ``normals`` are one-ring normals (sharper across the edge than smoothed ones). The fit
    starts from the normal seeds; if that fails, once more from the line sweep
    (:func:`.two_planes.seed_by_sweep`). ``proj`` and ``order`` (int64) are work arrays of length
    ``c`` or more. The distance is ``inf`` when the points are not two planes meeting at a sharp
    edge (see :func:`_fit_edge`); otherwise ``line`` holds the edge (:func:`.two_planes.edge_line`).
    """
    seed_by_normals(normals, idx, c, side)
    d, angle = _fit_edge(X, idx, c, side, c1, n1, c2, n2, work, spacing, line, max_cos)
    if d < np.inf:
        return d, angle
    # c1, n1, c2 serve as the sweep's frame (normal, t1, t2): the fit overwrites them anyway
    if not seed_by_sweep(X, idx, c, side, proj, c1, n1, c2, work, order):
        return np.inf, 0.0
    return _fit_edge(X, idx, c, side, c1, n1, c2, n2, work, spacing, line, max_cos)


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
        k0, k1, rms0, spread0 = plane_fits(X, idx, c, side, c1, n1, c2, n2, work)
        if k0 < MIN_SIDE or k1 < MIN_SIDE:
            return np.inf, 0.0
        changed = False
        for j in range(c):
            q = idx[j]
            s = 0 if plane_distance(X, q, c1, n1) <= plane_distance(X, q, c2, n2) else 1
            if s != side[j]:
                side[j] = s
                changed = True
        if not changed:
            break
    if changed:  # the sides moved in the last round: their planes again
        k0, k1, rms0, spread0 = plane_fits(X, idx, c, side, c1, n1, c2, n2, work)
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
    edge_line(c1, n1, c2, n2, line)
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
    return line_distance(X, p, line), fold


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
    a = least_parallel(normals, outer, m, p)
    b = least_parallel(normals, outer, m, a)
    t = -1
    best = 2.0
    for j in range(m):
        q = outer[j]
        v = max(abs(row_dot(normals, a, normals, q)), abs(row_dot(normals, b, normals, q)))
        if v < best:
            best = v
            t = q
    if t < 0 or best > max_cos or abs(row_dot(normals, a, normals, b)) > max_cos:
        return np.inf, 0.0
    for j in range(c):
        q = idx[j]
        da = abs(row_dot(normals, a, normals, q))
        db = abs(row_dot(normals, b, normals, q))
        dt = abs(row_dot(normals, t, normals, q))
        side[j] = 0 if da >= db and da >= dt else (1 if db >= dt else 2)
    for _ in range(ROUNDS):
        for which in range(3):
            if plane_fit(X, idx, c, side, which, cen[which], nrm[which], work) < MIN_SIDE:
                return np.inf, 0.0
        changed = False
        for j in range(c):
            q = idx[j]
            s = 0
            r = np.inf
            for which in range(3):
                d = plane_distance(X, q, cen[which], nrm[which])
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
        if (plane_fit(X, idx, c, side, which, cen[which], nrm[which], work) < MIN_SIDE
                or work[0] > max_rms or work[1] < min_spread):
            return np.inf, 0.0
    for i in range(3):  # a corner: no two of the faces near parallel (a thin wall's are)
        for k in range(i + 1, 3):
            if abs(row_dot(nrm, i, nrm, k)) > max_cos:
                return np.inf, 0.0
    best_d = np.inf
    best_fold = 0.0
    for i in range(3):
        for k in range(i + 1, 3):
            cs = row_dot(nrm, i, nrm, k)
            edge_line(cen[i], nrm[i], cen[k], nrm[k], tmp)
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
                    gap = min(gap, line_distance(X, q, tmp))
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
            d = line_distance(X, p, tmp)
            if d < best_d:
                best_d = d
                best_fold = fold
                for e in range(6):
                    line[e] = tmp[e]
    return best_d, best_fold


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
        d = (plane_distance(X, idx[j], c1, n1) if side[j] == 0
             else plane_distance(X, idx[j], c2, n2))
        sse += d * d
    return sse


@jit
def localise(X, normals, dn, dn_cnt, nn, candidate, out, angle, line, local, min_angle, width,
             corner, bend, narrowed, rim, filled):
    """Step 2 for every candidate: ``out[p]`` = edge distance / local spacing (inf: no edge),
    ``angle[p]`` = the fold of the fitted faces (degrees, 0-180, see ``MIN_ANGLE``; 0 where no
    edge),
    ``line[p]`` = the fitted edge line where there is one (:func:`.two_planes.edge_line`; undefined
    elsewhere), ``local[p]`` = the local spacing (0 for points that are not candidates),
    ``corner[p]``: whether that line is a corner's (:func:`_fit_corner`), ``bend[p]``: the
    squared error of one quadric height field over the two-ring over that of the two planes
    (:func:`_quadric_sse`, :func:`_two_plane_sse`; NaN where no two-plane fit found an edge
    within ``width`` local spacings — a farther line's bend is not measured:
    :func:`.edge_lines.borrow` and :func:`.edge_lines.line_distances` take only lines within
    ``width``, a farther soft fit lends no flags and a farther sharp one lends unclassified
    (:func:`.edge_lines.confirmed_lines`), and so where a corner's line replaced it
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
    its nearest neighbour, :func:`.two_ring.nearest_distances`).

    Where the two-ring holds two parallel sheets (a thin wall's faces,
    :func:`.thin_walls.own_layer`), the fit takes the point's own sheet alone (its local spacing
    still over the whole two-ring). Where the fit finds no edge, it is tried once more over the
    two-ring's points within ``NEAR_RING`` local spacings (:func:`near_part`, then
    :func:`.thin_walls.own_layer` of those). Where that finds none either, a step lower than the
    spacing is tried over the two-ring's points within ``STEP_RING`` local spacings
    (:func:`.thin_walls.fit_step`: the fold reads 90°, and no bend is measured). ``narrowed[p]``:
    whether ``p``'s fit is one of those two, which :func:`.simplify.boundary_flags` keeps only where
    another fit confirms its line. Where none of them finds one either and the two-ring holds two
    sheets, a thin wall's rim is tried (:func:`.thin_walls.fit_rim`, :func:`.thin_walls.rim_clear`:
    the fold reads 90°, no bend is measured); ``rim[p]``: whether ``p``'s fit is a rim's, whose line
    makes features but not the core band (:func:`.simplify.boundary_flags`). Where no rim fits
    either and the sampling fills its tangent planes (``filled``:
    :func:`.thin_walls.median_ring_gap` below ``FILLED_GAP``), a border is tried
    (:func:`.thin_walls.border_gap`: an empty angle about the point), a rim's kind for ``rim``.

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
        s = median_in_place(vals, c)
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
            d = fit_step(X, normals, idx, c, s, proj, vals, line[p], n1, n2, work)
            if d < np.inf:
                angle[p] = 90.0
                narrowed[p] = layers = True
        if d == np.inf and sheets:  # a thin wall's rim, where both its sheets end
            idx[:c_whole] = whole[:c_whole]
            c = c_whole
            d = fit_rim(X, idx, c, s, proj, sheet_n, line[p], across)
            if d < np.inf or filled:  # both tests read the three-ring
                if mark3.shape[0] == 0:
                    mark3 = np.zeros(n, dtype=np.int64)
                k = gather_rings(p, dn, dn_cnt, FIT_RINGS + 1, mark3, ring3)
                if d < np.inf and not rim_clear(X, p, ring3, k, d, s, across, sheet_n):
                    d = np.inf
                if d == np.inf and filled:  # a border where no rim fits: an empty angle
                    d = border_gap(X, p, ring3, k, s, sheet_n, ang3, line[p], bu, bv)
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
