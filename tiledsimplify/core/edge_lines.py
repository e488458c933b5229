"""The fitted lines' reach: borrowed lines, features and flags (steps 3-5 of :mod:`.edge_fit`).

After :func:`.edge_fit.localise` has fitted a line to each candidate, the lines reach the
points around them:

3. a candidate its own fit does not flag takes the line of a flagged neighbour on a sharp edge
   (:func:`borrow`);
4. the features: every point within ``width`` spacings of a sharp fitted neighbour's line
   (:func:`line_distances`);
5. the flags: every point within ``width`` cloud spacings of the line of one of its
   ``FLAG_FITS`` nearest lenders (:func:`nearest_line_distances`); the lenders include the
   fits whose own point lies a little off their line where a second fit's line confirms theirs
   (:func:`confirmed_lines`).
"""

import numpy as np

from ._jit import jit, jit_leaf
from .cell_grid import sq_dist
from .edge_fit import SOFT_ANGLE
from .two_planes import line_distance, point_line_distance
from .two_ring import FIT_RINGS, MAX_RING, gather_rings


#: band width of borrowed edges (:func:`borrow`), as a fraction of ``width``: only the points
#: right on the edge, where fits fail most (0.5 against 1.0 on the 37 quality cases: Hausdorff
#: within 1.2x the best peer's on 28 against 22, featuretype flags 3,064 against 3,468 of its
#: 4,000 budget)
BORROW_WIDTH = 0.5
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


@jit
def line_distances(X, dn, dn_cnt, fitted, angle, line, local, width, spacing, corner, out):
    """Step 4: ``out[p]`` lowered (in place) to ``p``'s distance to the fitted line of any point
    ``q`` whose two-ring holds it, where ``q`` lies within ``width`` of its own line on an edge
    of ``SOFT_ANGLE`` or more and that line is not a corner's (``corner[q]``: it ends at the
    corner) — the lenders of :func:`borrow` — in units of ``max(local[q],
    spacing)``: the larger of ``q``'s local spacing and the cloud's.

    Beyond the paper; the features' reach (the flags' until 2026-12-06, when this was measured
    on them; now :func:`nearest_line_distances`). The core band (:func:`.edge_fit.band` of steps
    2-3) misses the points a little off the line whose own measure stays below ``CANDIDATE``
    (idler_riser's 45-70° folds: 770 of its 4,304 points within one spacing of an edge) and, on
    scans, the rows beyond a local spacing that overlapping views shrink (the tray scan's
    lenders: 0.22 of the cloud's median nearest-neighbour distance). Measured on the 36 CAD
    quality cases (flags ``band | (out <= width)`` against the band alone,
    ``benchmarks/quality.py``): boundary F1 geometric mean 0.512 -> 0.589 on the even parts
    (idler_riser 0.747 -> 0.872, rocker-arm 0.533 -> 0.633, counter 0.462 -> 0.556; Fandisk
    0.944 -> 0.943, block 0.936 -> 0.932) and 0.462 -> 0.598 on the scans (plate_holes 0.529 ->
    0.839, the tray 0.221 -> 0.477). In units of the local spacing alone the scans gained less
    than half as much (0.526); lenders of 40-60° folds took plate_holes to 0.539 (fillets);
    within 0.85 widths, not 1, the even parts' mean is 0.577.
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
            out[p] = min(out[p], line_distance(X, p, line[q]) / unit)


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
                d = min(d, line_distance(X, p, line[q]))
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
                    and point_line_distance(foot, line[r]) <= offset):
                out[q] = True
                break


@jit
def borrow(X, dn, dn_cnt, distance, angle, line, local, width, flagged, corner, out,
           angle_out):
    """Step 3: candidates that their own fit does not flag take the edge of a flagged sharp
    neighbour.

    ``out[p]``, ``angle_out[p]``: for a candidate (a point with a positive ``local`` spacing,
    :func:`.edge_fit.localise`) that its own fit does not flag (``flagged``: :func:`.edge_fit.band`
    of ``distance``, ``angle`` and ``width`` — no fit, or a fitted line farther than the band),
    the distance in its local spacings to the nearest fitted line (``line``) among the points
    of its two-ring that lie within ``width`` of their own line on an edge of ``SOFT_ANGLE``
    or more, not a corner's (``corner``, :func:`.edge_fit._fit_corner`: its line ends at the
    corner), and that line's angle — if within ``BORROW_WIDTH * width`` and nearer than its own
    line; every other point keeps ``distance`` and ``angle``.

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
            d = line_distance(X, p, line[q]) / local[p]
            if d < out[p] and d <= BORROW_WIDTH * width:
                out[p] = d
                angle_out[p] = angle[q]
